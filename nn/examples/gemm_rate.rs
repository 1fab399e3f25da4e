//! GEMM rate on the learner's per-call shapes (the most multiply-adds of a 6.4_2 update,
//! bundled config), one thread, CPU time (immune to other processes' load): `nn::gemm::gemm`
//! (the non-packing kernel where the CPU has AVX-512F) against `matrixmultiply::sgemm`,
//! alternating in one run. `cargo run --release -p policy --example gemm_rate`.

use nn::gemm::{gemm, View};

fn cpu_secs() -> f64 {
    let s = std::fs::read_to_string("/proc/thread-self/stat").unwrap_or_default();
    let f: Vec<&str> = s
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let tick = 100.0;
    let u: f64 = f.get(11).and_then(|x| x.parse().ok()).unwrap_or(0.0);
    let k: f64 = f.get(12).and_then(|x| x.parse().ok()).unwrap_or(0.0);
    (u + k) / tick
}

/// One shape: C (m x n) = alpha A (m x k) B (k x n), A/B row strides and column strides.
struct Shape {
    m: usize,
    k: usize,
    n: usize,
    a: (usize, usize),
    b: (usize, usize),
    alpha: f32,
    what: &'static str,
}

fn main() {
    let s = |m, k, n, a, b, alpha, what| Shape {
        m,
        k,
        n,
        a,
        b,
        alpha,
        what,
    };
    // Per-call shapes after `gemm`'s 256-row / 1,024-inner splits, from an instrumented
    // 6.4_2 update (share of the update's GEMM multiply-adds in brackets).
    let shapes = [
        s(256, 64, 64, (64, 1), (1, 64), 1.0, "x W^T, 64 -> 64 (8 %)"),
        s(
            64,
            1024,
            64,
            (1, 64),
            (64, 1),
            1.0,
            "dY^T X weight gradient (7 %)",
        ),
        s(192, 1024, 64, (1, 192), (64, 1), 1.0, "GRU dW (7 %)"),
        s(
            256,
            256,
            64,
            (256, 1),
            (1, 256),
            1.0,
            "x W^T, 256 -> 64 (5 %)",
        ),
        s(
            256,
            64,
            256,
            (64, 1),
            (256, 1),
            1.0,
            "dY W, 64 -> 256 (5 %)",
        ),
        s(64, 1024, 256, (1, 64), (256, 1), 1.0, "fc dW (5 %)"),
        s(240, 64, 192, (64, 1), (1, 64), 1.0, "h W_hh^T (4 %)"),
        s(
            256,
            64,
            16,
            (256, 1),
            (1, 64),
            1.0,
            "per head, out 16 (8 %)",
        ),
        s(
            256,
            16,
            64,
            (64, 1),
            (64, 1),
            0.25,
            "per head, inner 16 (8 %)",
        ),
        s(16, 1024, 64, (1, 64), (256, 1), 1.0, "per head dW (7 %)"),
        s(32, 16, 64, (64, 1), (64, 1), 0.25, "U_h per 32-row chunk"),
        s(32, 64, 16, (256, 1), (16, 1), 1.0, "O_h per 32-row chunk"),
    ];
    println!("GFLOP/s in CPU time, one thread: nn::gemm::gemm vs matrixmultiply::sgemm");
    for sh in shapes {
        let (m, k, n) = (sh.m, sh.k, sh.n);
        let alen = (m - 1) * sh.a.0 + (k - 1) * sh.a.1 + 1;
        let blen = (k - 1) * sh.b.0 + (n - 1) * sh.b.1 + 1;
        let a: Vec<f32> = (0..alen).map(|i| (i % 7) as f32 * 0.1).collect();
        let b: Vec<f32> = (0..blen).map(|i| (i % 5) as f32 * 0.2).collect();
        let mut c = vec![0.0f32; m * n];
        let reps = (1e10 / (m * k * n) as f64).max(3.0) as usize;
        let flop = 2.0 * (m * k * n * reps) as f64;
        let (mut ours, mut theirs) = (Vec::new(), Vec::new());
        for _round in 0..3 {
            let t0 = cpu_secs();
            for _ in 0..reps {
                let av = View {
                    data: &a,
                    rs: sh.a.0,
                    cs: sh.a.1,
                };
                let bv = View {
                    data: &b,
                    rs: sh.b.0,
                    cs: sh.b.1,
                };
                gemm(m, k, n, sh.alpha, av, bv, 0.0, &mut c, n);
            }
            ours.push(flop / (cpu_secs() - t0).max(1e-9) / 1e9);
            let t0 = cpu_secs();
            for _ in 0..reps {
                // SAFETY: the vectors hold every element the strides reach.
                unsafe {
                    matrixmultiply::sgemm(
                        m,
                        k,
                        n,
                        sh.alpha,
                        a.as_ptr(),
                        sh.a.0 as isize,
                        sh.a.1 as isize,
                        b.as_ptr(),
                        sh.b.0 as isize,
                        sh.b.1 as isize,
                        0.0,
                        c.as_mut_ptr(),
                        n as isize,
                        1,
                    );
                }
            }
            theirs.push(flop / (cpu_secs() - t0).max(1e-9) / 1e9);
        }
        let med = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (o, t) = (med(&mut ours), med(&mut theirs));
        println!(
            "{m:>4} x {k:>5} x {n:>4}  {o:6.1} vs {t:6.1}  ({:4.2}x)  {}",
            o / t,
            sh.what
        );
    }
}
