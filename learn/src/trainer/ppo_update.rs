//! The PPO epochs of one update: shuffled mini-batches of 10-step chunks, each gathered
//! from the rollout and run through actor and critic in parts of bounded size.

use super::memory::part_rows_for;
use super::{mix, TrainError, Trainer, UpdateStats};
use obs::ObsBatch;
use policy::{PpoActorConfig, Sequences, ValueLossConfig};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sim::Setup;

/// A mini-batch of chunks, rows `t * B' + k * n + i`.
#[derive(Debug, Default)]
pub(super) struct MiniBatch {
    obs: ObsBatch,
    masks: Vec<f32>,
    ha: Vec<f32>,
    hc: Vec<f32>,
    actions: Vec<u8>,
    logp: Vec<f32>,
    shield: Vec<f32>,
    adv: Vec<f32>,
    values: Vec<f32>,
    ret: Vec<f32>,
}

/// Rollout rows of chunk units `units` in mini-batch order: `t * B' + k * n + i` <- source
/// `(c * l + t) * b + env * n + i`.
fn chunk_rows(
    units: &[usize],
    n: usize,
    n_chunks: usize,
    l: usize,
    b: usize,
    rows: &mut Vec<usize>,
) {
    rows.clear();
    for t in 0..l {
        for &u in units {
            let (env, c) = (u / n_chunks, u % n_chunks);
            for i in 0..n {
                rows.push((c * l + t) * b + env * n + i);
            }
        }
    }
}

/// Copy rows `rows` of `src` (in order) into `dst`.
pub(crate) fn gather_rows(src: &ObsBatch, rows: &[usize], dst: &mut ObsBatch) {
    let c = src.counts;
    dst.resize(rows.len(), c);
    let ws = [
        obs::SELF_DIM,
        c.machines * obs::MACHINE_DIM,
        c.storages * obs::STORAGE_DIM,
        c.peers * obs::PEER_DIM,
    ];
    let srcs = [&src.own, &src.machines, &src.storages, &src.peers];
    let dsts = [
        &mut dst.own,
        &mut dst.machines,
        &mut dst.storages,
        &mut dst.peers,
    ];
    for ((w, s), d) in ws.into_iter().zip(srcs).zip(dsts) {
        if w == 0 {
            continue;
        }
        for (k, &r) in rows.iter().enumerate() {
            d[k * w..(k + 1) * w].copy_from_slice(&s[r * w..(r + 1) * w]);
        }
    }
}

impl Trainer {
    pub(super) fn ppo(&mut self, setup: Setup) -> Result<UpdateStats, TrainError> {
        let n = setup.robots;
        let cfg = self.cfg.clone();
        let e = cfg.n_envs;
        let b = e * n;
        let l = cfg.data_chunk_length;
        let t_len = self.scenario.world.episode_steps as usize;
        let n_chunks = t_len / l;
        let units = e * n_chunks;
        let per_mb = units.div_ceil(cfg.num_mini_batch);
        let (ha_dim, hc_dim) = (self.actor.hidden(), self.critic.arch.hidden);
        let mut rng = ChaCha8Rng::seed_from_u64(mix(self.seed, self.update, 3));
        let mut perm: Vec<usize> = (0..units).collect();
        let pcfg = PpoActorConfig {
            clip: cfg.clip_param,
            ent_coef: cfg.entropy_coef,
        };
        let vcfg = ValueLossConfig {
            clip: cfg.clip_param,
            huber_delta: cfg.huber_delta,
            coef: cfg.value_loss_coef,
        };
        let mut st = UpdateStats::default();
        let mut count = 0f32;
        let mut rows = vec![];
        let part_rows = part_rows_for(self.kind, setup, &cfg, self.part_rows);
        // Critic warm-up (`critic_warmup_updates`): the actor neither computes gradients
        // nor steps, so a trained actor is not pushed around by a fresh critic's noise.
        let train_actor = self.update >= cfg.critic_warmup_updates as u64;
        for _ in 0..cfg.ppo_epoch {
            perm.shuffle(&mut rng);
            for mb_units in perm.chunks(per_mb) {
                let mb_rows = mb_units.len() * n * l;
                // ValueNorm sees the whole mini-batch's returns first, as before splitting
                if cfg.use_valuenorm {
                    chunk_rows(mb_units, n, n_chunks, l, b, &mut rows);
                    let buf = &self.buf;
                    self.mb.ret.clear();
                    self.mb.ret.extend(rows.iter().map(|&r| buf.ret[r]));
                    self.vnorm.update(&self.mb.ret);
                }
                // Parts of at most PART_ROWS rows (whole chunks, so whole envs) go through
                // the networks one after the other, gradients accumulating: activation
                // memory is bounded by one part, not by the mini-batch (100 robots x 8 envs
                // is 160,000 rows). One part (every bundled config) is the unsplit step.
                for part in mb_units.chunks((part_rows / (n * l)).max(1)) {
                    let bu = part.len() * n;
                    chunk_rows(part, n, n_chunks, l, b, &mut rows);
                    let buf = &self.buf;
                    let mb = &mut self.mb;
                    gather_rows(&buf.obs, &rows, &mut mb.obs);
                    mb.masks.clear();
                    mb.masks.extend(rows.iter().map(|&r| buf.masks[r]));
                    mb.actions.clear();
                    mb.actions.extend(rows.iter().map(|&r| buf.actions[r]));
                    mb.logp.clear();
                    mb.logp.extend(rows.iter().map(|&r| buf.logp[r]));
                    mb.shield.clear();
                    if !buf.shield.is_empty() {
                        let k = self.actor.arch.n_actions;
                        for &r in &rows {
                            mb.shield.extend_from_slice(&buf.shield[r * k..(r + 1) * k]);
                        }
                    }
                    mb.adv.clear();
                    mb.adv.extend(rows.iter().map(|&r| buf.adv[r]));
                    mb.values.clear();
                    mb.values.extend(rows.iter().map(|&r| buf.values[r]));
                    mb.ret.clear();
                    mb.ret.extend(rows.iter().map(|&r| buf.ret[r]));
                    mb.ha.clear();
                    mb.hc.clear();
                    for &u in part {
                        let (env, c) = (u / n_chunks, u % n_chunks);
                        let r0 = c * b + env * n;
                        mb.ha
                            .extend_from_slice(&buf.ha[r0 * ha_dim..(r0 + n) * ha_dim]);
                        mb.hc
                            .extend_from_slice(&buf.hc[r0 * hc_dim..(r0 + n) * hc_dim]);
                    }
                    if cfg.use_valuenorm {
                        let vn = &self.vnorm;
                        mb.ret.iter_mut().for_each(|r| *r = vn.normalize(*r));
                    }
                    let (actor, critic, mb) = (&mut self.actor, &mut self.critic, &self.mb);
                    let seq = Sequences::new(&mb.obs, l, bu, &mb.ha, &mb.masks);
                    let seq = seq.part_of(mb_rows);
                    let (ra, rc) = rayon::join(
                        || {
                            if !train_actor {
                                return Ok(None);
                            }
                            let (acts, logp, adv) = (&mb.actions, &mb.logp, &mb.adv);
                            actor
                                .ppo_grads_biased(seq, acts, logp, adv, &mb.shield, pcfg)
                                .map(Some)
                        },
                        || {
                            let seq = seq.with_h0(&mb.hc);
                            critic.value_grads(seq, n, &mb.values, &mb.ret, vcfg)
                        },
                    );
                    let (sa, sc) = (ra?, rc?);
                    if let Some(sa) = sa {
                        st.policy_loss += sa.policy_loss;
                        st.entropy += sa.entropy;
                        st.approx_kl += sa.approx_kl;
                        st.clip_frac += sa.clip_frac;
                    }
                    st.value_loss += sc.value_loss;
                }
                if train_actor {
                    st.actor_grad_norm += self.actor.step(cfg.max_grad_norm);
                }
                st.critic_grad_norm += self.critic.step(cfg.max_grad_norm);
                count += 1.0;
            }
        }
        for v in [
            &mut st.actor_grad_norm,
            &mut st.critic_grad_norm,
            &mut st.policy_loss,
            &mut st.entropy,
            &mut st.approx_kl,
            &mut st.clip_frac,
            &mut st.value_loss,
        ] {
            *v /= count.max(1.0);
        }
        Ok(st)
    }
}
