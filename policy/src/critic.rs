//! Centralized critics (one value per agent).
//!
//! SMAPPO (paper Fig. 2): every robot's observation through an encoder of the actor's
//! design (own weights) -> enc_i; an MHA with a LEARNABLE query over all enc_j of the same
//! environment -> g; per agent [g, enc_i] -> Linear -> Tanh -> LayerNorm -> GRU ->
//! LayerNorm -> Linear(1).
//!
//! MAPPO: per agent [own flat obs ++ every robot's flat obs of the env, padded with zero
//! rows to `max_robots`] -> MAPPO MLP base -> GRU -> LayerNorm -> Linear(1).
//!
//! Rows are step-major and grouped per environment inside a step: row
//! `t * B + e * n + i` is robot i of env e at step t (B = envs * n).

use crate::actor::{copy_obs, write_flat};
use crate::config::{ArchConfig, ModelKind};
use crate::encoder::{EncoderCache, SmappoEncoder};
use crate::error::{check_len, PolicyError};
use crate::factored_input::FactoredRows;
use crate::head::{HeadCache, RecurrentHead};
use crate::mlp_base::{MlpBase, MlpCache};
use crate::sequences::Sequences;
use nn::{
    sized, tanh, Adam, AdamConfig, Init, Kv, LayerNorm, LayerNormConfig, Linear, LinearConfig,
    MhaCache, MhaConfig, MultiHeadAttention, ParamStore, Slot,
};
use obs::{FlatLayout, ObsBatch};
use rand::{Rng, SeedableRng};

#[derive(Debug, Clone, Copy)]
#[allow(clippy::large_enum_variant)]
enum CriticBase {
    Smappo {
        enc: SmappoEncoder,
        query: Slot,
        att: MultiHeadAttention,
        fc: Linear,
        ln: LayerNorm,
    },
    Mappo {
        mlp: MlpBase,
        flat: FlatLayout,
        max_robots: usize,
    },
}

#[derive(Debug, Clone, Default)]
struct CriticCache {
    obs: ObsBatch,
    t: usize,
    b: usize,
    n: usize,
    enc: EncoderCache,
    q_in: Vec<f32>,
    att: MhaCache,
    g: Vec<f32>,
    cat: Vec<f32>,
    fc: Vec<f32>,
    mean: Vec<f32>,
    rstd: Vec<f32>,
    feat: Vec<f32>,
    mlp: MlpCache,
    flat: Vec<f32>,
    head: HeadCache,
    d_feat: Vec<f32>,
    d_fc: Vec<f32>,
    d_cat: Vec<f32>,
    d_g: Vec<f32>,
    d_q: Vec<f32>,
    d_enc: Vec<f32>,
    d_enc2: Vec<f32>,
    dv: Vec<f32>,
}

/// Statistics of one value loss evaluation.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ValueLossStats {
    /// mean(max(huber(clipped error), huber(error)))
    pub value_loss: f32,
    /// mean value prediction
    pub mean_value: f32,
}

/// MAPPO value-loss hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueLossConfig {
    pub clip: f32,
    pub huber_delta: f32,
    pub coef: f32,
}

impl Default for ValueLossConfig {
    fn default() -> Self {
        Self {
            clip: 0.2,
            huber_delta: 10.0,
            coef: 1.0,
        }
    }
}

fn huber(e: f32, d: f32) -> (f32, f32) {
    if e.abs() <= d {
        (0.5 * e * e, e)
    } else {
        (d * (e.abs() - 0.5 * d), d * e.signum())
    }
}

#[derive(Debug, Clone)]
pub struct Critic {
    pub arch: ArchConfig,
    pub params: ParamStore,
    pub opt: Adam,
    base: CriticBase,
    head: RecurrentHead,
    cache: CriticCache,
}

impl Critic {
    pub fn new(arch: ArchConfig, seed: u64) -> Self {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let mut params = ParamStore::new();
        let (d, h) = (arch.d_model, arch.hidden);
        let base = match arch.kind {
            ModelKind::Smappo => {
                let enc = SmappoEncoder::new(d, arch.heads, d, &mut params, "encoder", &mut rng);
                let query = params.alloc("global_query", &[d]);
                for x in &mut params.data[query.r()] {
                    *x = rng.gen_range(-1.0..1.0);
                }
                let att = MultiHeadAttention::new(
                    MhaConfig {
                        dim: d,
                        heads: arch.heads,
                    },
                    &mut params,
                    "global_att",
                    &mut rng,
                );
                let fc = Linear::new(
                    LinearConfig {
                        d_in: 2 * d,
                        d_out: h,
                        init: Init::Orthogonal { gain: 5.0 / 3.0 },
                    },
                    &mut params,
                    "fc",
                    &mut rng,
                );
                let ln = LayerNorm::new(LayerNormConfig::new(h), &mut params, "ln");
                CriticBase::Smappo {
                    enc,
                    query,
                    att,
                    fc,
                    ln,
                }
            }
            ModelKind::Mappo => {
                let flat: FlatLayout = arch.flat.expect("MAPPO needs a flat layout").into();
                let max_robots = arch.max_robots.expect("MAPPO critic needs max_robots");
                let mlp = MlpBase::new(
                    flat.dim() * (1 + max_robots),
                    h,
                    &mut params,
                    "base",
                    &mut rng,
                );
                CriticBase::Mappo {
                    mlp,
                    flat,
                    max_robots,
                }
            }
        };
        let head = RecurrentHead::new(h, h, 1, 1.0, "value_out", &mut params, &mut rng);
        let opt = Adam::new(AdamConfig::default(), params.len());
        Self {
            arch,
            params,
            opt,
            base,
            head,
            cache: CriticCache::default(),
        }
    }

    /// Values for T*B rows (B = envs * n robots per env); see the module doc for the layout.
    pub fn forward_seq(
        &mut self,
        obs: &ObsBatch,
        t: usize,
        b: usize,
        n: usize,
        h0: &[f32],
        masks: &[f32],
    ) -> Result<&[f32], PolicyError> {
        check_len("obs rows", obs.rows, t * b)?;
        check_len("h0", h0.len(), b * self.arch.hidden)?;
        check_len("masks", masks.len(), t * b)?;
        if n == 0 || !b.is_multiple_of(n) {
            return Err(PolicyError::NotPerEnv { rows: b, n });
        }
        let c = &mut self.cache;
        copy_obs(&mut c.obs, obs);
        (c.t, c.b, c.n) = (t, b, n);
        let p = &self.params.data;
        let rows = t * b;
        let envs = rows / n;
        let h = self.arch.hidden;
        let feat: &[f32] = match &self.base {
            CriticBase::Smappo {
                enc,
                query,
                att,
                fc,
                ln,
            } => {
                let d = enc.out_dim;
                enc.forward(p, &c.obs, &mut c.enc);
                let q_in = sized(&mut c.q_in, envs * d);
                for row in q_in.chunks_exact_mut(d) {
                    row.copy_from_slice(&p[query.r()]);
                }
                let g = sized(&mut c.g, envs * d);
                att.forward(p, q_in, Kv::Rows(&c.enc.out), envs, n, &mut c.att, g);
                let cat = sized(&mut c.cat, rows * 2 * d);
                for r in 0..rows {
                    let e = r / n;
                    cat[r * 2 * d..r * 2 * d + d].copy_from_slice(&g[e * d..(e + 1) * d]);
                    cat[r * 2 * d + d..(r + 1) * 2 * d]
                        .copy_from_slice(&c.enc.out[r * d..(r + 1) * d]);
                }
                let f = sized(&mut c.fc, rows * h);
                fc.forward(p, cat, rows, f);
                tanh::forward(f);
                let out = sized(&mut c.feat, rows * h);
                ln.forward(
                    p,
                    f,
                    rows,
                    out,
                    sized(&mut c.mean, rows),
                    sized(&mut c.rstd, rows),
                );
                &c.feat
            }
            CriticBase::Mappo {
                mlp,
                flat,
                max_robots,
            } => {
                if n > *max_robots {
                    return Err(PolicyError::TooMany {
                        field: "robots",
                        got: n,
                        max: *max_robots,
                    });
                }
                write_flat(flat, &c.obs, &mut c.flat)?;
                // Row r's input is [own ++ its env's n robots ++ zeros to max_robots]: the
                // env block is shared by the env's n rows, so it is never copied per row
                // (`factored_input`).
                let fd = flat.dim();
                mlp.forward_factored(p, Self::factored(&c.flat, fd, n), rows, &mut c.mlp);
                c.mlp.out()
            }
        };
        self.head.forward(p, feat, t, b, h0, masks, &mut c.head);
        Ok(&c.head.y)
    }

    /// The MAPPO critic's rows over flat observations (`fd` floats per robot, envs of `n`
    /// consecutive rows).
    fn factored(flat: &[f32], fd: usize, n: usize) -> FactoredRows<'_> {
        FactoredRows {
            own: flat,
            d_own: fd,
            shared: flat,
            d_sh: fd * n,
            group: n,
        }
    }

    /// Hidden state after the last step of the last forward (B x H).
    pub fn last_hidden(&self) -> &[f32] {
        self.head
            .last_hidden(&self.cache.head, self.cache.t, self.cache.b)
    }

    /// One rollout step: values for B rows; `h` replaced by the new state.
    pub fn forward_step(
        &mut self,
        obs: &ObsBatch,
        n: usize,
        h: &mut [f32],
        masks: &[f32],
    ) -> Result<&[f32], PolicyError> {
        let b = obs.rows;
        self.forward_seq(obs, 1, b, n, h, masks)?;
        h.copy_from_slice(self.head.last_hidden(&self.cache.head, 1, b));
        Ok(&self.cache.head.y)
    }

    /// Backward of the last forward given dL/dvalues ((T*B) entries).
    pub fn backward(&mut self, dvalues: &[f32]) {
        let c = &mut self.cache;
        let (t, b, n) = (c.t, c.b, c.n);
        let rows = t * b;
        let h = self.arch.hidden;
        let (p, g) = (&self.params.data, &mut self.params.grad);
        let d_feat = sized(&mut c.d_feat, rows * h);
        match &self.base {
            CriticBase::Smappo {
                enc,
                query,
                att,
                fc,
                ln,
            } => {
                self.head
                    .backward(p, g, &c.feat, t, b, &mut c.head, dvalues, d_feat);
                let d = enc.out_dim;
                let envs = rows / n;
                let d_fc = sized(&mut c.d_fc, rows * h);
                ln.backward(p, g, &c.fc, d_feat, rows, &c.mean, &c.rstd, d_fc);
                tanh::backward(&c.fc, d_fc);
                let d_cat = sized(&mut c.d_cat, rows * 2 * d);
                fc.backward(p, g, &c.cat, d_fc, rows, Some(d_cat), false);
                let d_g = sized(&mut c.d_g, envs * d);
                d_g.iter_mut().for_each(|v| *v = 0.0);
                let d_enc = sized(&mut c.d_enc, rows * d);
                for r in 0..rows {
                    let e = r / n;
                    for k in 0..d {
                        d_g[e * d + k] += d_cat[r * 2 * d + k];
                    }
                    d_enc[r * d..(r + 1) * d]
                        .copy_from_slice(&d_cat[r * 2 * d + d..(r + 1) * 2 * d]);
                }
                let d_q = sized(&mut c.d_q, envs * d);
                d_q.iter_mut().for_each(|v| *v = 0.0);
                let d_enc2 = sized(&mut c.d_enc2, rows * d);
                att.backward(
                    p,
                    g,
                    &c.q_in,
                    Kv::Rows(&c.enc.out),
                    envs,
                    n,
                    &mut c.att,
                    d_g,
                    d_q,
                    Some(d_enc2),
                );
                let gq = &mut g[query.r()];
                for row in d_q.chunks_exact(d) {
                    for (a, v) in gq.iter_mut().zip(row) {
                        *a += v;
                    }
                }
                for (a, v) in d_enc.iter_mut().zip(d_enc2.iter()) {
                    *a += v;
                }
                enc.backward(p, g, &c.obs, &mut c.enc, d_enc);
            }
            CriticBase::Mappo { mlp, flat, .. } => {
                self.head
                    .backward(p, g, c.mlp.out(), t, b, &mut c.head, dvalues, d_feat);
                let x = Self::factored(&c.flat, flat.dim(), n);
                mlp.backward_factored(p, g, x, &mut c.mlp, d_feat);
            }
        }
    }

    /// Forward + MAPPO clipped Huber value loss + backward (gradients accumulate), `n`
    /// robots per environment (a part of a mini-batch holds whole environments).
    /// `old_values` and `returns` have T*B entries (already normalised if a value
    /// normaliser is used); loss, statistics and gradients are these rows' share of the
    /// mean over `seq.total_rows`.
    pub fn value_grads(
        &mut self,
        seq: Sequences,
        n: usize,
        old_values: &[f32],
        returns: &[f32],
        cfg: ValueLossConfig,
    ) -> Result<ValueLossStats, PolicyError> {
        let rows = seq.rows();
        check_len("old_values", old_values.len(), rows)?;
        check_len("returns", returns.len(), rows)?;
        self.forward_seq(seq.obs, seq.t, seq.b, n, seq.h0, seq.masks)?;
        let c = &mut self.cache;
        let dv = sized(&mut c.dv, rows);
        let inv = 1.0 / seq.total_rows.max(1) as f32;
        let mut st = ValueLossStats::default();
        for r in 0..rows {
            let v = c.head.y[r];
            let delta = v - old_values[r];
            let vc = old_values[r] + delta.clamp(-cfg.clip, cfg.clip);
            let (lc, gc) = huber(returns[r] - vc, cfg.huber_delta);
            let (lo, go) = huber(returns[r] - v, cfg.huber_delta);
            st.mean_value += v * inv;
            if lc > lo {
                st.value_loss += lc * inv;
                // d/dv of huber(ret - vc): -huber'(.) * dvc/dv, dvc/dv = 1 inside the clip
                let inside = delta.abs() < cfg.clip;
                dv[r] = if inside { -gc * inv * cfg.coef } else { 0.0 };
            } else {
                st.value_loss += lo * inv;
                dv[r] = -go * inv * cfg.coef;
            }
        }
        let dv = std::mem::take(&mut c.dv);
        self.backward(&dv);
        self.cache.dv = dv;
        Ok(st)
    }

    /// [`Adam::step_clipped`] of the parameters; returns the pre-clip gradient norm.
    pub fn step(&mut self, max_grad_norm: f32) -> f32 {
        self.opt.step_clipped(&mut self.params, max_grad_norm)
    }
}
