//! Runtime CPU-feature dispatch for the hand-written loops.
//!
//! The crate is built for baseline x86-64 (SSE2), because CI's CPU and a robot's CPU may
//! differ from the build machine's. Hot loops are written once as plain Rust in an
//! `#[inline(always)]` body and compiled a second time inside a
//! `#[target_feature(enable = "avx2")]` (and `avx512f`) wrapper, picked at run time.
//!
//! Results do not depend on the variant: Rust never contracts `a * b + c` into an FMA, and
//! the vectoriser may not reorder floating-point sums, so a wider vector only executes the
//! same operations in the same order (tests below and in each kernel check bit equality).

use std::sync::atomic::{AtomicU8, Ordering};

/// Instruction-set level chosen for the dispatched loops.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    Baseline = 1,
    Avx2 = 2,
    Avx512 = 3,
}

static LEVEL: AtomicU8 = AtomicU8::new(0);

fn detect() -> Level {
    #[cfg(target_arch = "x86_64")]
    {
        if std::env::var_os("TENDING_NO_SIMD").is_some() {
            return Level::Baseline;
        }
        if is_x86_feature_detected!("avx512f") && std::env::var_os("TENDING_NO_AVX512").is_none() {
            return Level::Avx512;
        }
        if is_x86_feature_detected!("avx2") {
            return Level::Avx2;
        }
    }
    Level::Baseline
}

/// The level in use (detected once; `TENDING_NO_SIMD` / `TENDING_NO_AVX512` in the
/// environment force a lower one, for benchmarks and equality tests).
#[inline]
pub fn level() -> Level {
    match LEVEL.load(Ordering::Relaxed) {
        1 => Level::Baseline,
        2 => Level::Avx2,
        3 => Level::Avx512,
        _ => {
            let l = detect();
            LEVEL.store(l as u8, Ordering::Relaxed);
            l
        }
    }
}

/// Force a level (tests compare variants); returns the previous one. A level the CPU lacks
/// is lowered to what it has.
#[cfg(test)]
pub fn set_level(l: Level) -> Level {
    let prev = level();
    let l = l.min(detect_max());
    LEVEL.store(l as u8, Ordering::Relaxed);
    prev
}

#[cfg(test)]
fn detect_max() -> Level {
    #[cfg(target_arch = "x86_64")]
    {
        if is_x86_feature_detected!("avx512f") {
            return Level::Avx512;
        }
        if is_x86_feature_detected!("avx2") {
            return Level::Avx2;
        }
    }
    Level::Baseline
}

/// Define `pub fn $name(args) -> ret` that runs `$body` compiled for the best available
/// instruction set (see the module doc).
macro_rules! dispatch {
    ($(#[$m:meta])* $vis:vis fn $name:ident($($a:ident : $t:ty),* $(,)?) $(-> $r:ty)? $body:block) => {
        $(#[$m])*
        #[allow(clippy::too_many_arguments)]
        $vis fn $name($($a: $t),*) $(-> $r)? {
            #[inline(always)]
            #[allow(clippy::too_many_arguments)]
            fn body($($a: $t),*) $(-> $r)? $body
            #[cfg(target_arch = "x86_64")]
            {
                #[target_feature(enable = "avx2")]
                #[allow(clippy::too_many_arguments)]
                unsafe fn avx2($($a: $t),*) $(-> $r)? { body($($a),*) }
                #[target_feature(enable = "avx512f")]
                #[allow(clippy::too_many_arguments)]
                unsafe fn avx512($($a: $t),*) $(-> $r)? { body($($a),*) }
                match $crate::simd::level() {
                    // SAFETY: the level is only this high when the CPU reports the feature.
                    $crate::simd::Level::Avx512 => return unsafe { avx512($($a),*) },
                    $crate::simd::Level::Avx2 => return unsafe { avx2($($a),*) },
                    $crate::simd::Level::Baseline => {}
                }
            }
            body($($a),*)
        }
    };
}
pub(crate) use dispatch;

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::sync::Mutex;

    /// Tests that switch the level hold this lock (the level is process-wide).
    pub static LEVEL_LOCK: Mutex<()> = Mutex::new(());

    /// Run `f` at every level the CPU has and return the results, baseline first.
    pub fn at_every_level<T>(mut f: impl FnMut() -> T) -> Vec<T> {
        let _g = LEVEL_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let prev = level();
        let out = [Level::Baseline, Level::Avx2, Level::Avx512]
            .into_iter()
            .filter(|l| *l <= detect_max())
            .map(|l| {
                set_level(l);
                f()
            })
            .collect();
        set_level(prev);
        out
    }

    dispatch! {
        fn sum_sq(x: &[f32]) -> f32 {
            let mut acc = [0.0f32; 8];
            for c in x.chunks_exact(8) {
                for i in 0..8 {
                    acc[i] += c[i] * c[i];
                }
            }
            acc.iter().sum()
        }
    }

    #[test]
    fn every_level_gives_the_same_bits() {
        let x = crate::gradcheck::rand_vec(1024, 3);
        let r = at_every_level(|| sum_sq(&x).to_bits());
        assert!(r.windows(2).all(|w| w[0] == w[1]), "{r:?}");
    }
}
