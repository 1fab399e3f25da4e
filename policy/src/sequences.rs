//! The borrowed input of one training pass: what actor and critic losses both read.

use obs::ObsBatch;

/// T steps of B rows each, step-major (row `t * B + b`), with the hidden state before the
/// first step and the episode-start masks. The actor and the critic of one mini-batch share
/// all but `h0` (see [`with_h0`](Self::with_h0)).
#[derive(Debug, Clone, Copy)]
pub struct Sequences<'a> {
    /// T*B observation rows.
    pub obs: &'a ObsBatch,
    pub t: usize,
    pub b: usize,
    /// B x hidden: the recurrent state before step 0.
    pub h0: &'a [f32],
    /// T*B entries; 0.0 = an episode starts at this step (hidden zeroed first).
    pub masks: &'a [f32],
    /// Rows of the whole mini-batch these rows are a part of: losses are means over
    /// them, so the parts' gradients add up to the mini-batch's (see
    /// [`part_of`](Self::part_of)). T*B for a whole mini-batch.
    pub total_rows: usize,
}

impl<'a> Sequences<'a> {
    /// A whole mini-batch.
    pub fn new(obs: &'a ObsBatch, t: usize, b: usize, h0: &'a [f32], masks: &'a [f32]) -> Self {
        Self {
            obs,
            t,
            b,
            h0,
            masks,
            total_rows: t * b,
        }
    }

    /// These rows as one part of a mini-batch of `total_rows` rows, so that only one
    /// part's activations are held at a time.
    pub fn part_of(self, total_rows: usize) -> Self {
        Self { total_rows, ..self }
    }

    /// The same rows with another network's initial hidden state.
    pub fn with_h0(self, h0: &'a [f32]) -> Self {
        Self { h0, ..self }
    }

    /// T*B: the number of rows.
    pub fn rows(&self) -> usize {
        self.t * self.b
    }
}
