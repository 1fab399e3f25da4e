//! Batched per-env work split into one contiguous piece per thread, the calling thread
//! running one piece itself.
//!
//! Why not rayon here: a batched step at small setups is tens of microseconds of work
//! (32 envs of 6.4_2: about 40 us on one core), called back to back from outside any
//! pool (the Python vector API, `tending bench-sim`). Rayon entered from outside its pool
//! queues the job, puts the caller to sleep and wakes a worker, then wakes the caller:
//! two OS wake-ups per call, which on this 2-core VM cost as much as the work (32 envs
//! of 6.4_2 ran at 0.55x one env's agent-steps/s on one rayon thread, against 0.94x
//! for a plain loop: `sim/examples/vec_scaling.rs`). micropool's `join` lets the caller
//! run one side while a pool thread, spinning briefly between calls before it sleeps,
//! takes the other, and the static split keeps each env on the same thread call after
//! call (its state stays in that core's cache). Results do not depend on the split: each
//! env is stepped by exactly one thread from start to end of its step.

/// Work over a run of environments that can be cut in two at an env boundary.
pub trait Split: Sized + Send {
    /// Environments in this piece.
    fn len(&self) -> usize;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The first `mid` envs and the rest.
    fn split_at(self, mid: usize) -> (Self, Self);
}

/// Threads a batched call is split over: micropool's pool threads and the caller.
pub fn threads() -> usize {
    micropool::num_threads() + 1
}

/// Run `f` on `threads()` contiguous pieces of `work` in parallel (fewer when there are
/// fewer envs); the first error any piece returns is returned.
pub fn for_each_piece<W: Split, E: Send>(
    work: W,
    f: &(impl Fn(W) -> Result<(), E> + Sync),
) -> Result<(), E> {
    split_run(work, threads(), f)
}

fn split_run<W: Split, E: Send>(
    work: W,
    parts: usize,
    f: &(impl Fn(W) -> Result<(), E> + Sync),
) -> Result<(), E> {
    let len = work.len();
    if parts <= 1 || len <= 1 {
        return f(work);
    }
    let left_parts = parts / 2;
    let mid = len * left_parts / parts;
    let (a, b) = work.split_at(mid);
    let (ra, rb) = micropool::join(
        || split_run(a, left_parts, f),
        || split_run(b, parts - left_parts, f),
    );
    ra.and(rb)
}

/// Cut a slice of `w` values per env at env `mid` (an empty slice stays empty: a group
/// with no entities has width 0).
pub fn cut<T>(s: &mut [T], w: usize, mid: usize) -> (&mut [T], &mut [T]) {
    s.split_at_mut((w * mid).min(s.len()))
}

/// `n` consecutive blocks of `w` values (empty blocks when `w` is 0: a group with no
/// entities, where `chunks_mut` would panic).
pub fn blocks(b: &mut [f32], w: usize, n: usize) -> impl Iterator<Item = &mut [f32]> {
    let mut rest = b;
    (0..n).map(move |_| {
        let (head, tail) = std::mem::take(&mut rest).split_at_mut(w);
        rest = tail;
        head
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Piece<'a>(&'a mut [u32], usize);
    impl Split for Piece<'_> {
        fn len(&self) -> usize {
            self.0.len()
        }
        fn split_at(self, mid: usize) -> (Self, Self) {
            let (a, b) = self.0.split_at_mut(mid);
            (Piece(a, self.1), Piece(b, self.1 + mid))
        }
    }

    #[test]
    fn every_env_is_visited_once_with_its_own_index() {
        for n in [0usize, 1, 2, 3, 7, 32, 33] {
            let mut v = vec![0u32; n];
            for_each_piece(Piece(&mut v, 0), &|p: Piece| {
                for (i, x) in p.0.iter_mut().enumerate() {
                    *x += (p.1 + i) as u32 + 1;
                }
                Ok::<(), ()>(())
            })
            .unwrap();
            assert_eq!(v, (1..=n as u32).collect::<Vec<_>>(), "n = {n}");
        }
    }

    #[test]
    fn an_error_in_any_piece_is_returned() {
        let mut v = vec![0u32; 8];
        let r = for_each_piece(Piece(&mut v, 0), &|p: Piece| {
            if p.1 + p.0.len() == 8 {
                Err(format!("piece at {}", p.1))
            } else {
                Ok(())
            }
        });
        assert!(r.unwrap_err().starts_with("piece at"));
    }
}
