//! MAPPO's critic input, factored per environment-step.
//!
//! A MAPPO critic row is `[own obs (d_own) ++ every robot's obs of its env (d_sh) ++ zero
//! padding]` (`d_in` in all). The middle block is the same for the `group` rows of one
//! env-step, and at 100 robots it is 99 % of the row: fed to [`MlpBase::forward`] as
//! concatenated rows, the first Linear costs 2.7 M multiply-adds per row and the input
//! itself 166 kB. Here the first layer (feature LayerNorm, then Linear) is rewritten so the
//! shared block goes through the weights once per group:
//!
//! ```text
//! xhat_r = (x_r - mu_r) * rstd_r * gamma + beta
//! W xhat_r + b = rstd_r * (W_own (gamma.own_r) + W_sh (gamma.shared_g))
//!                - mu_r * rstd_r * (W gamma) + (W beta + b)
//! ```
//!
//! and the backward pass likewise sums each row's gradient into its group before touching
//! the shared block (derivation in the comments of [`MlpBase::backward_factored`]). The
//! function is the same as the concatenated one; only the summation order differs (tested
//! against it). The row statistics are combined from per-block means and centred sums of
//! squares (Chan et al.'s pairwise update), so no E[x^2] - E[x]^2 cancellation is added.

use crate::factored_cache::FactoredCache;
use crate::mlp_base::{MlpBase, MlpCache};
use nn::gemm::{gemm, rm, View};
use nn::sized;

/// Critic rows given as their own block plus one shared block per group of rows.
#[derive(Debug, Clone, Copy)]
pub struct FactoredRows<'a> {
    /// rows x `d_own`
    pub own: &'a [f32],
    pub d_own: usize,
    /// (rows / group) x `d_sh`
    pub shared: &'a [f32],
    pub d_sh: usize,
    /// consecutive rows sharing one shared block
    pub group: usize,
}

/// Mean and centred sum of squares of `x`.
fn mean_m2(x: &[f32]) -> (f32, f32) {
    if x.is_empty() {
        return (0.0, 0.0);
    }
    let m = x.iter().sum::<f32>() / x.len() as f32;
    (m, x.iter().map(|v| (v - m) * (v - m)).sum())
}

/// Chan et al.'s pairwise combination of (count, mean, M2).
fn combine(a: (f32, f32, f32), b: (f32, f32, f32)) -> (f32, f32, f32) {
    let n = a.0 + b.0;
    if n == 0.0 {
        return (0.0, 0.0, 0.0);
    }
    let delta = b.1 - a.1;
    (
        n,
        a.1 + delta * b.0 / n,
        a.2 + b.2 + delta * delta * a.0 * b.0 / n,
    )
}

impl FactoredRows<'_> {
    fn groups(&self, n: usize) -> usize {
        n / self.group
    }

    fn check(&self, d_in: usize, n: usize) {
        assert!(
            self.group > 0 && n.is_multiple_of(self.group),
            "rows per group"
        );
        assert!(
            self.d_own + self.d_sh <= d_in,
            "blocks wider than the input"
        );
        assert!(self.own.len() >= n * self.d_own, "own block too short");
        assert!(
            self.shared.len() >= n / self.group * self.d_sh,
            "shared block too short"
        );
    }
}

impl MlpBase {
    /// [`MlpBase::forward`] on the rows `[own_r ++ shared_(r / group) ++ zeros]`.
    pub fn forward_factored(&self, p: &[f32], x: FactoredRows, n: usize, c: &mut MlpCache) {
        let (h, d) = (self.hidden, self.d_in);
        x.check(d, n);
        let (d_own, d_sh) = (x.d_own, x.d_sh);
        let groups = n / x.group;
        c.n = n;
        let gm = &p[self.feat_ln.gamma.r()];
        let bt = &p[self.feat_ln.beta.r()];
        let w = &p[self.fc[0].w.r()];
        let b = &p[self.fc[0].b.r()];
        let eps = self.feat_ln.cfg.eps;
        let f = &mut c.fac;

        // Row statistics from the blocks' statistics.
        let zeros = (d - d_own - d_sh) as f32;
        let mean = sized(&mut c.m0, n);
        let rstd = sized(&mut c.s0, n);
        for gi in 0..groups {
            let (ms, m2s) = mean_m2(&x.shared[gi * d_sh..(gi + 1) * d_sh]);
            let sh = combine((d_sh as f32, ms, m2s), (zeros, 0.0, 0.0));
            for r in gi * x.group..(gi + 1) * x.group {
                let (mo, m2o) = mean_m2(&x.own[r * d_own..(r + 1) * d_own]);
                let (_, m, m2) = combine((d_own as f32, mo, m2o), sh);
                mean[r] = m;
                rstd[r] = 1.0 / (m2 / d as f32 + eps).sqrt();
            }
        }

        // gamma-scaled blocks, then one GEMM each: rows x d_own and groups x d_sh.
        let g_own = sized(&mut f.g_own, n * d_own);
        for (row, src) in g_own
            .chunks_exact_mut(d_own.max(1))
            .zip(x.own.chunks_exact(d_own.max(1)))
        {
            for ((o, s), g) in row.iter_mut().zip(src).zip(&gm[..d_own]) {
                *o = s * g;
            }
        }
        let g_sh = sized(&mut f.g_sh, groups * d_sh);
        for (row, src) in g_sh
            .chunks_exact_mut(d_sh.max(1))
            .zip(x.shared.chunks_exact(d_sh.max(1)))
        {
            for ((o, s), g) in row.iter_mut().zip(src).zip(&gm[d_own..d_own + d_sh]) {
                *o = s * g;
            }
        }
        // W is row-major hidden x d_in: (W block)^T is the view rs = 1, cs = d_in.
        let a = sized(&mut c.act[0], n * h);
        gemm(
            n,
            d_own,
            h,
            1.0,
            rm(g_own, d_own),
            View {
                data: w,
                rs: 1,
                cs: d,
            },
            0.0,
            a,
            h,
        );
        let s_out = sized(&mut f.sh_out, groups * h);
        gemm(
            groups,
            d_sh,
            h,
            1.0,
            rm(g_sh, d_sh),
            View {
                data: &w[d_own..],
                rs: 1,
                cs: d,
            },
            0.0,
            s_out,
            h,
        );
        let wg = sized(&mut f.w_gamma, h);
        let wb = sized(&mut f.w_beta, h);
        for o in 0..h {
            let wr = &w[o * d..(o + 1) * d];
            wg[o] = wr.iter().zip(gm).map(|(a, b)| a * b).sum();
            wb[o] = wr.iter().zip(bt).map(|(a, b)| a * b).sum::<f32>() + b[o];
        }
        for r in 0..n {
            let (m, rs) = (mean[r], rstd[r]);
            let sg = &s_out[(r / x.group) * h..(r / x.group + 1) * h];
            for (o, v) in a[r * h..(r + 1) * h].iter_mut().enumerate() {
                *v = rs * (*v + sg[o]) - m * rs * wg[o] + wb[o];
            }
        }
        self.forward_tail(p, n, c);
    }

    /// Backward of [`MlpBase::forward_factored`] (same `x`); the input gradient is not
    /// needed (raw observations).
    pub fn backward_factored(
        &self,
        p: &[f32],
        g: &mut [f32],
        x: FactoredRows,
        c: &mut MlpCache,
        dout: &[f32],
    ) {
        self.backward_tail(p, g, c, dout);
        let rows = BackRows {
            x,
            n: c.n,
            da: &c.d_a,
            mean: &c.m0,
            rstd: &c.s0,
        };
        let f = &mut c.fac;
        rows.group_sums(self.hidden, f);
        self.first_linear_grads(p, g, &rows, f);
        self.feature_ln_grads(p, g, &rows, f);
    }

    /// The first Linear's gradients: bias `S`; `dW[:, own] += da^T xhat_own` (the own
    /// block of xhat is per row); `dW[:, shared] += sum_g U_g (gamma.shared_g)^T`; and for
    /// every column past the own block (shared and padding), xhat = (x - mu) rstd gamma +
    /// beta contributes `-V gamma^T + S beta^T`.
    fn first_linear_grads(&self, p: &[f32], g: &mut [f32], r: &BackRows, f: &mut FactoredCache) {
        let (n, h, d) = (r.n, self.hidden, self.d_in);
        let (d_own, d_sh) = (r.x.d_own, r.x.d_sh);
        let gm = &p[self.feat_ln.gamma.r()];
        let bt = &p[self.feat_ln.beta.r()];
        let (u, v_mu, s) = (&f.u_group, &f.u_mu, &f.da_sum);
        for (gb, sv) in g[self.fc[0].b.r()].iter_mut().zip(s.iter()) {
            *gb += sv;
        }
        let xo = sized(&mut f.xhat_own, n * d_own);
        for i in 0..n {
            let (m, rs) = (r.mean[i], r.rstd[i]);
            for j in 0..d_own {
                xo[i * d_own + j] = (r.x.own[i * d_own + j] - m) * rs * gm[j] + bt[j];
            }
        }
        let gw = &mut g[self.fc[0].w.r()];
        gemm(
            h,
            n,
            d_own,
            1.0,
            transposed(r.da, h),
            rm(xo, d_own),
            1.0,
            gw,
            d,
        );
        gemm(
            h,
            r.x.groups(n),
            d_sh,
            1.0,
            transposed(u, h),
            rm(&f.g_sh, d_sh),
            1.0,
            &mut gw[d_own..],
            d,
        );
        for o in 0..h {
            let row = &mut gw[o * d + d_own..(o + 1) * d];
            for (j, v) in row.iter_mut().enumerate() {
                *v += -v_mu[o] * gm[d_own + j] + s[o] * bt[d_own + j];
            }
        }
    }

    /// The feature LayerNorm's gradients, with dxhat_r = W^T da_r:
    ///   dbeta  = sum_r dxhat_r = W^T S (every column);
    ///   dgamma = sum_r dxhat_r . (x_r - mu_r) rstd_r: own columns per row
    ///   (dxhat_own = da W_own); past the own block: sum_g shared_g . (U_g W_sh) - W^T V.
    fn feature_ln_grads(&self, p: &[f32], g: &mut [f32], r: &BackRows, f: &mut FactoredCache) {
        let (n, h, d) = (r.n, self.hidden, self.d_in);
        let (d_own, d_sh) = (r.x.d_own, r.x.d_sh);
        let w = &p[self.fc[0].w.r()];
        let (u, v_mu, s) = (&f.u_group, &f.u_mu, &f.da_sum);
        let dcol = sized(&mut f.dcol, 2 * d);
        dcol.iter_mut().for_each(|v| *v = 0.0);
        let (dgamma, dbeta) = dcol.split_at_mut(d);
        for o in 0..h {
            let wr = &w[o * d..(o + 1) * d];
            for j in 0..d {
                dbeta[j] += wr[j] * s[o];
            }
            for j in d_own..d {
                dgamma[j] -= wr[j] * v_mu[o];
            }
        }
        // W row-major hidden x d_in read as d_in x hidden (rs = d, cs = 1).
        let w_own = View {
            data: w,
            rs: d,
            cs: 1,
        };
        let dxo = sized(&mut f.d_own, n * d_own);
        gemm(n, h, d_own, 1.0, rm(r.da, h), w_own, 0.0, dxo, d_own);
        for i in 0..n {
            let (m, rs) = (r.mean[i], r.rstd[i]);
            for j in 0..d_own {
                dgamma[j] += dxo[i * d_own + j] * (r.x.own[i * d_own + j] - m) * rs;
            }
        }
        let groups = r.x.groups(n);
        let t = sized(&mut f.t_sh, groups * d_sh);
        let w_sh = View {
            data: &w[d_own..],
            rs: d,
            cs: 1,
        };
        gemm(groups, h, d_sh, 1.0, rm(u, h), w_sh, 0.0, t, d_sh);
        for gi in 0..groups {
            let sh = &r.x.shared[gi * d_sh..(gi + 1) * d_sh];
            let tg = &t[gi * d_sh..(gi + 1) * d_sh];
            for j in 0..d_sh {
                dgamma[d_own + j] += sh[j] * tg[j];
            }
        }
        for (a, v) in g[self.feat_ln.gamma.r()].iter_mut().zip(dgamma.iter()) {
            *a += v;
        }
        for (a, v) in g[self.feat_ln.beta.r()].iter_mut().zip(dbeta.iter()) {
            *a += v;
        }
    }
}

/// What the backward phases read: the rows, the first Linear's output gradient and the
/// feature LayerNorm's row statistics.
struct BackRows<'a> {
    x: FactoredRows<'a>,
    n: usize,
    /// rows x hidden
    da: &'a [f32],
    mean: &'a [f32],
    rstd: &'a [f32],
}

impl BackRows<'_> {
    /// Per-row sums the shared block needs: `U_g = sum_(r in g) da_r rstd_r`,
    /// `V = sum_r da_r mu_r rstd_r`, `S = sum_r da_r`.
    fn group_sums(&self, h: usize, f: &mut FactoredCache) {
        let u = sized(&mut f.u_group, self.x.groups(self.n) * h);
        u.iter_mut().for_each(|v| *v = 0.0);
        let v_mu = sized(&mut f.u_mu, h);
        v_mu.iter_mut().for_each(|v| *v = 0.0);
        let s = sized(&mut f.da_sum, h);
        s.iter_mut().for_each(|v| *v = 0.0);
        for r in 0..self.n {
            let (m, rs) = (self.mean[r], self.rstd[r]);
            let gi = r / self.x.group;
            let ug = &mut u[gi * h..(gi + 1) * h];
            for o in 0..h {
                let dv = self.da[r * h + o];
                ug[o] += dv * rs;
                v_mu[o] += dv * m * rs;
                s[o] += dv;
            }
        }
    }
}

/// `a` (rows x cols, row-major) read as its transpose.
fn transposed(a: &[f32], cols: usize) -> View<'_> {
    View {
        data: a,
        rs: 1,
        cs: cols,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nn::gradcheck::rand_vec;
    use nn::ParamStore;
    use rand::SeedableRng;

    /// The concatenated rows the factored ones stand for.
    fn concat(x: &FactoredRows, d_in: usize, n: usize) -> Vec<f32> {
        let mut out = vec![0.0; n * d_in];
        for r in 0..n {
            let row = &mut out[r * d_in..(r + 1) * d_in];
            row[..x.d_own].copy_from_slice(&x.own[r * x.d_own..(r + 1) * x.d_own]);
            let gi = r / x.group;
            row[x.d_own..x.d_own + x.d_sh]
                .copy_from_slice(&x.shared[gi * x.d_sh..(gi + 1) * x.d_sh]);
        }
        out
    }

    fn max_rel(a: &[f32], b: &[f32]) -> f32 {
        let scale = b.iter().fold(1e-6f32, |m, v| m.max(v.abs()));
        a.iter()
            .zip(b)
            .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()))
            / scale
    }

    /// Same outputs and the same parameter gradients as the concatenated rows, with and
    /// without zero padding, one and several groups, perturbed gamma/beta.
    #[test]
    fn matches_the_concatenated_input() {
        for (d_own, group, padding, groups) in [(7, 3, 2, 4), (5, 4, 0, 1), (9, 2, 5, 3)] {
            let d_sh = d_own * group;
            let d_in = d_own * (1 + group + padding);
            let n = group * groups;
            let mut store = ParamStore::new();
            let mut rng = rand::rngs::StdRng::seed_from_u64(3);
            let mlp = MlpBase::new(d_in, 16, &mut store, "base", &mut rng);
            let noise = rand_vec(store.data.len(), 4);
            for (v, e) in store.data.iter_mut().zip(&noise) {
                *v += 0.2 * e;
            }
            // observation-like values: offsets, so the row means are far from zero
            let own: Vec<f32> = rand_vec(n * d_own, 5).iter().map(|v| 2.0 + v).collect();
            let shared: Vec<f32> = rand_vec(groups * d_sh, 6).iter().map(|v| 1.5 * v).collect();
            let x = FactoredRows {
                own: &own,
                d_own,
                shared: &shared,
                d_sh,
                group,
            };
            let full = concat(&x, d_in, n);
            let dout = rand_vec(n * 16, 7);

            let (mut c1, mut c2) = (MlpCache::default(), MlpCache::default());
            mlp.forward(&store.data, &full, n, &mut c1);
            mlp.forward_factored(&store.data, x, n, &mut c2);
            assert!(
                max_rel(c2.out(), c1.out()) < 1e-4,
                "outputs differ: {}",
                max_rel(c2.out(), c1.out())
            );
            let mut g1 = vec![0.0; store.data.len()];
            let mut g2 = vec![0.0; store.data.len()];
            mlp.backward(&store.data, &mut g1, &full, &mut c1, &dout);
            mlp.backward_factored(&store.data, &mut g2, x, &mut c2, &dout);
            for (name, slot) in [
                ("feature_norm.weight", mlp.feat_ln.gamma),
                ("feature_norm.bias", mlp.feat_ln.beta),
                ("fc1.weight", mlp.fc[0].w),
                ("fc1.bias", mlp.fc[0].b),
                ("fc2.weight", mlp.fc[1].w),
                ("ln1.weight", mlp.ln[0].gamma),
            ] {
                let e = max_rel(&g2[slot.r()], &g1[slot.r()]);
                assert!(e < 1e-4, "{name} gradient differs by {e} (d_own {d_own})");
            }
        }
    }
}
