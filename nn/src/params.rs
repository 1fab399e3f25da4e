//! Flat parameter store: every parameter of a network lives in one `Vec<f32>` and every
//! gradient in a second one of the same length. Layers keep [`Slot`]s (offset + length), so
//! Adam, gradient clipping and checkpointing are loops over two slices.

use std::ops::Range;

/// Where one parameter tensor lives inside a [`ParamStore`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Slot {
    pub off: usize,
    pub len: usize,
}

impl Slot {
    #[inline]
    pub fn r(&self) -> Range<usize> {
        self.off..self.off + self.len
    }
}

/// One named tensor of the store.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamEntry {
    pub name: String,
    pub shape: Vec<usize>,
    pub slot: Slot,
}

/// All parameters (`data`) and gradients (`grad`) of one network.
#[derive(Debug, Clone, Default)]
pub struct ParamStore {
    pub data: Vec<f32>,
    pub grad: Vec<f32>,
    pub entries: Vec<ParamEntry>,
}

impl ParamStore {
    pub fn new() -> Self {
        Self::default()
    }

    /// Reserve a zero-initialised tensor. Names must be unique.
    pub fn alloc(&mut self, name: &str, shape: &[usize]) -> Slot {
        assert!(
            self.entries.iter().all(|e| e.name != name),
            "duplicate parameter name {name}"
        );
        let len: usize = shape.iter().product();
        let slot = Slot {
            off: self.data.len(),
            len,
        };
        self.data.resize(slot.off + len, 0.0);
        self.grad.resize(slot.off + len, 0.0);
        self.entries.push(ParamEntry {
            name: name.to_string(),
            shape: shape.to_vec(),
            slot,
        });
        slot
    }

    pub fn len(&self) -> usize {
        self.data.len()
    }

    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    pub fn zero_grad(&mut self) {
        self.grad.iter_mut().for_each(|g| *g = 0.0);
    }

    pub fn entry(&self, name: &str) -> Option<&ParamEntry> {
        self.entries.iter().find(|e| e.name == name)
    }

    /// (parameters, gradients) borrowed at once, as every backward pass needs.
    #[inline]
    pub fn split(&mut self) -> (&[f32], &mut [f32]) {
        (&self.data, &mut self.grad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_are_disjoint_and_sized() {
        let mut s = ParamStore::new();
        let a = s.alloc("a", &[3, 4]);
        let b = s.alloc("b", &[5]);
        assert_eq!(a, Slot { off: 0, len: 12 });
        assert_eq!(b, Slot { off: 12, len: 5 });
        assert_eq!(s.len(), 17);
        assert_eq!(s.grad.len(), 17);
        assert_eq!(s.entry("b").unwrap().shape, vec![5]);
    }

    #[test]
    #[should_panic]
    fn duplicate_names_panic() {
        let mut s = ParamStore::new();
        s.alloc("a", &[1]);
        s.alloc("a", &[1]);
    }
}
