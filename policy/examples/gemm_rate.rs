//! matrixmultiply's sgemm rate on the learner's shapes, one thread, CPU time (immune to
//! other processes' load): `cargo run --release -p policy --example gemm_rate`.

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

fn main() {
    // (m, k, n, a_rs, a_cs, b_rs, b_cs, what)
    let shapes: [(usize, usize, usize, bool, &str); 6] = [
        (9600, 64, 64, false, "x W^T (Linear 64->64, Q, out_proj)"),
        (9600, 256, 64, false, "x W^T (fc 256->64)"),
        (9600, 64, 192, false, "x W^T (GRU input gates)"),
        (9600, 16, 64, false, "Q_h Wk_h (per head, inner 16)"),
        (
            64,
            9600,
            64,
            true,
            "dY^T X (weight gradient over the batch)",
        ),
        (480, 64, 192, false, "h W_hh^T (one GRU step, 480 rows)"),
    ];
    for (m, k, n, trans_a, what) in shapes {
        let a = vec![0.5f32; m * k];
        let b = vec![0.25f32; k * n];
        let mut c = vec![0.0f32; m * n];
        let (ars, acs) = if trans_a {
            (1, m as isize)
        } else {
            (k as isize, 1)
        };
        let reps = (2e9 / (m * k * n) as f64).max(3.0) as usize;
        let t0 = cpu_secs();
        let w0 = std::time::Instant::now();
        for _ in 0..reps {
            unsafe {
                matrixmultiply::sgemm(
                    m,
                    k,
                    n,
                    1.0,
                    a.as_ptr(),
                    ars,
                    acs,
                    b.as_ptr(),
                    1,
                    k as isize,
                    0.0,
                    c.as_mut_ptr(),
                    n as isize,
                    1,
                );
            }
        }
        let cpu = cpu_secs() - t0;
        let wall = w0.elapsed().as_secs_f64();
        let flop = 2.0 * (m * k * n * reps) as f64;
        println!(
            "{m:>5} x {k:>5} x {n:>4}  {:6.1} GFLOP/s CPU time ({:6.1} wall)  {what}",
            flop / cpu.max(1e-9) / 1e9,
            flop / wall / 1e9
        );
    }
}
