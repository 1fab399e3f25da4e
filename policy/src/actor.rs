//! Actors: SMAPPO (attention encoder) and MAPPO (padded flat MLP), both followed by
//! GRU -> LayerNorm -> Linear(5). One code path serves training chunks (T steps x B rows),
//! rollout steps (T = 1) and on-robot inference, so they compute the same function.

use crate::config::{ArchConfig, ModelKind};
use crate::encoder::{EncoderCache, SmappoEncoder};
use crate::error::{check_len, PolicyError};
use crate::head::{HeadCache, RecurrentHead};
use crate::mlp_base::{MlpBase, MlpCache};
use crate::sequences::Sequences;
use nn::{categorical, sized, Adam, AdamConfig, ParamStore};
use obs::{FlatLayout, ObsBatch, ObsError};
use rand::SeedableRng;

#[derive(Debug, Clone, Copy)]
#[allow(clippy::large_enum_variant)]
pub(crate) enum Base {
    Smappo(SmappoEncoder),
    Mappo(MlpBase, FlatLayout),
}

#[derive(Debug, Clone, Default)]
pub(crate) struct BaseCache {
    pub enc: EncoderCache,
    pub mlp: MlpCache,
    pub flat: Vec<f32>,
}

impl Base {
    pub fn new(arch: &ArchConfig, store: &mut ParamStore, rng: &mut rand::rngs::StdRng) -> Self {
        match arch.kind {
            ModelKind::Smappo => Base::Smappo(SmappoEncoder::new(
                arch.d_model,
                arch.heads,
                arch.hidden,
                store,
                "encoder",
                rng,
            )),
            ModelKind::Mappo => {
                let flat: FlatLayout = arch.flat.expect("MAPPO needs a flat layout").into();
                Base::Mappo(
                    MlpBase::new(flat.dim(), arch.hidden, store, "base", rng),
                    flat,
                )
            }
        }
    }

    pub fn forward(&self, p: &[f32], obs: &ObsBatch, c: &mut BaseCache) -> Result<(), PolicyError> {
        match self {
            Base::Smappo(e) => e.forward(p, obs, &mut c.enc),
            Base::Mappo(m, flat) => {
                write_flat(flat, obs, &mut c.flat)?;
                m.forward(p, &c.flat, obs.rows, &mut c.mlp);
            }
        }
        Ok(())
    }

    pub fn out<'a>(&self, c: &'a BaseCache) -> &'a [f32] {
        match self {
            Base::Smappo(_) => &c.enc.out,
            Base::Mappo(..) => c.mlp.out(),
        }
    }

    pub fn backward(
        &self,
        p: &[f32],
        g: &mut [f32],
        obs: &ObsBatch,
        c: &mut BaseCache,
        dout: &[f32],
    ) {
        match self {
            Base::Smappo(e) => e.backward(p, g, obs, &mut c.enc, dout),
            Base::Mappo(m, _) => m.backward(p, g, &c.flat, &mut c.mlp, dout),
        }
    }
}

/// Pad `obs` with `flat`, turning an overflow into a clear error.
pub(crate) fn write_flat(
    flat: &FlatLayout,
    obs: &ObsBatch,
    out: &mut Vec<f32>,
) -> Result<(), PolicyError> {
    flat.write(obs, out).map_err(|e| match e {
        ObsError::WrongLength {
            field,
            got,
            expected,
        } => PolicyError::TooMany {
            field,
            got,
            max: expected,
        },
        other => PolicyError::Obs(other),
    })
}

/// Copy `src` into `dst` reusing `dst`'s allocations.
pub(crate) fn copy_obs(dst: &mut ObsBatch, src: &ObsBatch) {
    dst.rows = src.rows;
    dst.counts = src.counts;
    for (d, s) in [
        (&mut dst.own, &src.own),
        (&mut dst.machines, &src.machines),
        (&mut dst.storages, &src.storages),
        (&mut dst.peers, &src.peers),
    ] {
        d.clear();
        d.extend_from_slice(s);
    }
}

#[derive(Debug, Clone, Default)]
struct ActorCache {
    obs: ObsBatch,
    t: usize,
    b: usize,
    base: BaseCache,
    head: HeadCache,
    d_feat: Vec<f32>,
    logp: Vec<f32>,
    dlogits: Vec<f32>,
}

/// Statistics of one PPO actor loss evaluation (means over the rows).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ActorLossStats {
    /// -mean(min(r A, clip(r) A))
    pub policy_loss: f32,
    pub entropy: f32,
    /// policy_loss - ent_coef * entropy (what the gradient is of).
    pub loss: f32,
    /// mean(old_logp - logp)
    pub approx_kl: f32,
    /// fraction of rows whose ratio left [1 - clip, 1 + clip]
    pub clip_frac: f32,
}

/// PPO hyper-parameters of the actor loss.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PpoActorConfig {
    pub clip: f32,
    pub ent_coef: f32,
}

impl Default for PpoActorConfig {
    fn default() -> Self {
        Self {
            clip: 0.2,
            ent_coef: 0.01,
        }
    }
}

/// Name prefix of the output layer's parameters.
const ACTION_OUT: &str = "action_out";

/// The policy network with its parameters, Adam state and activation caches.
#[derive(Debug, Clone)]
pub struct Actor {
    pub arch: ArchConfig,
    pub params: ParamStore,
    pub opt: Adam,
    pub(crate) base: Base,
    pub(crate) head: RecurrentHead,
    cache: ActorCache,
}

impl Actor {
    /// Fresh weights (MAPPO initialisation) from `seed`; Adam with MAPPO's defaults.
    pub fn new(arch: ArchConfig, seed: u64) -> Self {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let mut params = ParamStore::new();
        let base = Base::new(&arch, &mut params, &mut rng);
        let head = RecurrentHead::new(
            arch.hidden,
            arch.hidden,
            arch.n_actions,
            0.01,
            ACTION_OUT,
            &mut params,
            &mut rng,
        );
        let opt = Adam::new(AdamConfig::default(), params.len());
        Self {
            arch,
            params,
            opt,
            base,
            head,
            cache: ActorCache::default(),
        }
    }

    pub fn hidden(&self) -> usize {
        self.arch.hidden
    }

    /// Add `delta` to the output bias of action `a` (a prior over actions for a fresh
    /// actor, e.g. `TrainConfig::target_greedy_bias`). Out-of-range `a` is ignored.
    pub fn add_action_bias(&mut self, a: usize, delta: f32) {
        if a < self.arch.n_actions {
            let off = self.head.out.b.off;
            self.params.data[off + a] += delta;
        }
    }

    /// This actor with one more output, a copy of output `copy_of` (weights and bias), and
    /// a fresh Adam: both outputs get equal logits, so the argmax (which keeps the lower
    /// index on ties) acts as before, sampling splits the old output's probability evenly,
    /// and training can learn where the new one is better. For a target-action actor
    /// trained on an older, shorter menu (`plan::targets::N_TARGET_ACTIONS_V1`) whose new
    /// entry refines an old one. Refused for an index outside the outputs.
    pub fn with_copied_output(&self, copy_of: usize) -> Result<Self, String> {
        let n = self.arch.n_actions;
        if copy_of >= n {
            return Err(format!("output {copy_of} does not exist ({n} outputs)"));
        }
        let mut arch = self.arch;
        arch.n_actions = n + 1;
        let mut wide = Actor::new(arch, 0);
        let out_w = format!("{}.weight", ACTION_OUT);
        let out_b = format!("{}.bias", ACTION_OUT);
        for e in &wide.params.entries {
            let old = self
                .params
                .entry(&e.name)
                .ok_or_else(|| format!("parameter {} missing", e.name))?;
            let src = &self.params.data[old.slot.r()];
            let dst = &mut wide.params.data[e.slot.r()];
            if e.name == out_w || e.name == out_b {
                // [n, d_in] -> [n + 1, d_in]: old rows, then a copy of row `copy_of`.
                let row = src.len() / n;
                dst[..src.len()].copy_from_slice(src);
                dst[src.len()..].copy_from_slice(&src[copy_of * row..(copy_of + 1) * row]);
            } else if old.shape == e.shape {
                dst.copy_from_slice(src);
            } else {
                return Err(format!(
                    "parameter {} has shape {:?}, expected {:?}",
                    e.name, old.shape, e.shape
                ));
            }
        }
        Ok(wide)
    }

    /// Forward over a chunk: `obs` has T*B rows, step-major (row t*B + b); `h0` B x H;
    /// `masks` T*B (0.0 = episode starts at this step: hidden zeroed first).
    /// Returns logits (T*B) x n_actions; activations are kept for [`backward`](Self::backward).
    pub fn forward_seq(
        &mut self,
        obs: &ObsBatch,
        t: usize,
        b: usize,
        h0: &[f32],
        masks: &[f32],
    ) -> Result<&[f32], PolicyError> {
        check_len("obs rows", obs.rows, t * b)?;
        check_len("h0", h0.len(), b * self.arch.hidden)?;
        check_len("masks", masks.len(), t * b)?;
        let c = &mut self.cache;
        copy_obs(&mut c.obs, obs);
        c.t = t;
        c.b = b;
        let p = &self.params.data;
        self.base.forward(p, &c.obs, &mut c.base)?;
        let feat = self.base.out(&c.base);
        self.head.forward(p, feat, t, b, h0, masks, &mut c.head);
        Ok(&c.head.y)
    }

    /// Hidden state after the last step of the last forward (B x H).
    pub fn last_hidden(&self) -> &[f32] {
        self.head
            .last_hidden(&self.cache.head, self.cache.t, self.cache.b)
    }

    /// One step for B rows: logits B x n_actions; `h` (B x H) is replaced by the new state.
    pub fn forward_step(
        &mut self,
        obs: &ObsBatch,
        h: &mut [f32],
        masks: &[f32],
    ) -> Result<&[f32], PolicyError> {
        let b = obs.rows;
        self.forward_seq(obs, 1, b, h, masks)?;
        h.copy_from_slice(self.head.last_hidden(&self.cache.head, 1, b));
        Ok(&self.cache.head.y)
    }

    /// Backward of the last forward given dL/dlogits; accumulates into `params.grad`.
    pub fn backward(&mut self, dlogits: &[f32]) {
        let c = &mut self.cache;
        let (t, b) = (c.t, c.b);
        let (p, g) = (&self.params.data, &mut self.params.grad);
        let d_feat = sized(&mut c.d_feat, t * b * self.arch.hidden);
        let feat = self.base.out(&c.base);
        self.head
            .backward(p, g, feat, t, b, &mut c.head, dlogits, d_feat);
        self.base.backward(p, g, &c.obs, &mut c.base, d_feat);
    }

    /// Forward + PPO clipped surrogate with entropy bonus + backward (gradients accumulate).
    /// `actions`, `old_logp`, `adv` have T*B entries; losses, statistics and gradients are
    /// these rows' share of the mean over `seq.total_rows`.
    pub fn ppo_grads(
        &mut self,
        seq: Sequences,
        actions: &[u8],
        old_logp: &[f32],
        adv: &[f32],
        cfg: PpoActorConfig,
    ) -> Result<ActorLossStats, PolicyError> {
        self.ppo_grads_biased(seq, actions, old_logp, adv, &[], cfg)
    }

    /// [`ppo_grads`](Self::ppo_grads) with `logit_bias` (T*B*n_actions entries, or empty
    /// for none) added to the logits before the softmax: the action shield's masks, so
    /// that the update scores actions under the distribution the rollout sampled from.
    pub fn ppo_grads_biased(
        &mut self,
        seq: Sequences,
        actions: &[u8],
        old_logp: &[f32],
        adv: &[f32],
        logit_bias: &[f32],
        cfg: PpoActorConfig,
    ) -> Result<ActorLossStats, PolicyError> {
        let n = seq.rows();
        if !logit_bias.is_empty() {
            check_len("logit_bias", logit_bias.len(), n * self.arch.n_actions)?;
        }
        check_len("actions", actions.len(), n)?;
        check_len("old_logp", old_logp.len(), n)?;
        check_len("adv", adv.len(), n)?;
        let k = self.arch.n_actions;
        if let Some(&a) = actions.iter().find(|&&a| a as usize >= k) {
            return Err(PolicyError::Shape {
                what: "action index",
                got: a as usize,
                expected: k,
            });
        }
        self.forward_seq(seq.obs, seq.t, seq.b, seq.h0, seq.masks)?;
        let c = &mut self.cache;
        let logp = sized(&mut c.logp, n * k);
        let dl = sized(&mut c.dlogits, n * k);
        let mut st = ActorLossStats::default();
        let inv = 1.0 / seq.total_rows.max(1) as f32;
        let mut biased = Vec::with_capacity(if logit_bias.is_empty() { 0 } else { k });
        for r in 0..n {
            let lp = &mut logp[r * k..(r + 1) * k];
            let y = &c.head.y[r * k..(r + 1) * k];
            if logit_bias.is_empty() {
                categorical::log_softmax(y, lp);
            } else {
                biased.clear();
                biased.extend(y.iter().zip(&logit_bias[r * k..]).map(|(a, b)| a + b));
                categorical::log_softmax(&biased, lp);
            }
            let a = actions[r] as usize;
            let ratio = (lp[a] - old_logp[r]).exp();
            let clipped = ratio.clamp(1.0 - cfg.clip, 1.0 + cfg.clip);
            let (s1, s2) = (ratio * adv[r], clipped * adv[r]);
            st.policy_loss -= s1.min(s2) * inv;
            let ent = categorical::entropy(lp);
            st.entropy += ent * inv;
            st.approx_kl += (old_logp[r] - lp[a]) * inv;
            if (ratio - 1.0).abs() > cfg.clip {
                st.clip_frac += inv;
            }
            // d(-min)/dlogp = -ratio * A when the unclipped term is the minimum
            let w_logp = if s1 <= s2 { -ratio * adv[r] * inv } else { 0.0 };
            categorical::backward_row(
                lp,
                a,
                w_logp,
                -cfg.ent_coef * inv,
                &mut dl[r * k..(r + 1) * k],
            );
        }
        st.loss = st.policy_loss - cfg.ent_coef * st.entropy;
        let dl = std::mem::take(&mut c.dlogits);
        self.backward(&dl);
        self.cache.dlogits = dl;
        Ok(st)
    }

    /// [`Adam::step_clipped`] of the parameters; returns the pre-clip gradient norm.
    pub fn step(&mut self, max_grad_norm: f32) -> f32 {
        self.opt.step_clipped(&mut self.params, max_grad_norm)
    }
}
