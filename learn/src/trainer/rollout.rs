//! Rollout collection: `episode_steps` steps of `n_envs` fresh environments, actions
//! sampled from the actor (behind the shield or the ORCA filter when configured), then GAE
//! and advantage normalisation.

use super::super::config::TrainConfig;
use super::super::gae::gae;
use super::{mix, TrainError, Trainer};
use nn::categorical;
use obs::ObsBatch;
use plan::orca::{FILTER_OBSTACLE_HORIZON, FILTER_REST_CLEARANCE};
use plan::pilot::{self, FilterMargins, Pilot, Row, Safety};
use policy::{ActionSpace, PolicyError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sim::{Metrics, ScenarioConfig, Setup, VecEnv};

/// Rollout storage, step-major: entry `t * B + e * n + i`.
#[derive(Debug, Default)]
pub(super) struct Rollout {
    pub(super) obs: ObsBatch,
    pub(super) masks: Vec<f32>,
    pub(super) dones: Vec<bool>,
    pub(super) actions: Vec<u8>,
    pub(super) logp: Vec<f32>,
    /// Shield logit bias, n_actions per entry (empty when the shield is off).
    pub(super) shield: Vec<f32>,
    /// critic outputs (normalised when ValueNorm is on)
    pub(super) values: Vec<f32>,
    pub(super) rewards: Vec<f32>,
    /// hidden states at chunk starts: (chunk, B, H)
    pub(super) ha: Vec<f32>,
    pub(super) hc: Vec<f32>,
    pub(super) adv: Vec<f32>,
    pub(super) ret: Vec<f32>,
}

impl Rollout {
    /// Empty every column for a new rollout (capacity kept).
    fn clear(&mut self) {
        self.obs = ObsBatch::default();
        self.obs.rows = 0;
        for v in [
            &mut self.masks,
            &mut self.logp,
            &mut self.shield,
            &mut self.values,
            &mut self.rewards,
            &mut self.ha,
            &mut self.hc,
        ] {
            v.clear();
        }
        self.dones.clear();
        self.actions.clear();
    }
}

impl Trainer {
    pub(super) fn rollout(&mut self, setup: Setup) -> Result<Vec<Metrics>, TrainError> {
        let cfg = &self.cfg;
        let (e, n) = (cfg.n_envs, setup.robots);
        let b = e * n;
        let t_len = self.scenario.world.episode_steps as usize;
        let l = cfg.data_chunk_length;
        let h = self.actor.hidden();
        let hc_dim = self.critic.arch.hidden;
        let mut venv = VecEnv::new(
            self.scenario.clone(),
            setup,
            e,
            mix(self.seed, self.update, 1),
        )?;
        let mut rng = ChaCha8Rng::seed_from_u64(mix(self.seed, self.update, 2));
        let buf = &mut self.buf;
        buf.clear();
        let mut ha = vec![0.0f32; b * h];
        let mut hc = vec![0.0f32; b * hc_dim];
        let mut masks = vec![0.0f32; b];
        let mut step_obs = ObsBatch::default();
        let mut lp = vec![0.0f32; self.actor.arch.n_actions];
        let mut acts = vec![0u8; b];
        let mut finished = vec![];
        let mut bias = vec![0.0f32; self.actor.arch.n_actions];
        let mut pilots = rollout_pilots(cfg, self.actor.arch.actions, &self.scenario, &venv, b)?;
        let mut vels = Vec::with_capacity(b);
        let lambda = if cfg.collision_budget.is_some() {
            self.lambda
        } else {
            0.0
        };
        let mut contacts_total = 0u64;
        for t in 0..t_len {
            venv.observe(&mut step_obs);
            if t % l == 0 {
                buf.ha.extend_from_slice(&ha);
                buf.hc.extend_from_slice(&hc);
            }
            buf.obs
                .extend_from(&step_obs)
                .map_err(|e| TrainError::Policy(PolicyError::Obs(e)))?;
            buf.masks.extend_from_slice(&masks);
            let (actor, critic) = (&mut self.actor, &mut self.critic);
            let (ra, rc) = rayon::join(
                || {
                    actor
                        .forward_step(&step_obs, &mut ha, &masks)
                        .map(|x| x.to_vec())
                },
                || {
                    critic
                        .forward_step(&step_obs, n, &mut hc, &masks)
                        .map(|x| x.to_vec())
                },
            );
            let (mut logits, values) = (ra?, rc?);
            let mut sampler = Sampler {
                pilots: &pilots,
                bias: &mut bias,
                lp: &mut lp,
                rng: &mut rng,
            };
            sampler.sample(&mut logits, &step_obs, &mut acts, buf);
            buf.actions.extend_from_slice(&acts);
            buf.values.extend_from_slice(&values);
            pilot::commands(&mut pilots, &step_obs, &acts, &mut vels);
            venv.step_velocities(&vels)?;
            contacts_total += venv.contacts().iter().map(|&c| c as u64).sum::<u64>();
            let start = buf.rewards.len();
            buf.rewards.extend(
                venv.rewards()
                    .iter()
                    .zip(venv.contacts())
                    .map(|(r, &c)| (r - lambda * c as f32) * cfg.reward_scale),
            );
            mix_team_reward(&mut buf.rewards[start..], n, cfg.team_reward);
            for (ei, &d) in venv.done().iter().enumerate() {
                for i in 0..n {
                    buf.dones.push(d);
                    masks[ei * n + i] = if d { 0.0 } else { 1.0 };
                }
            }
            finished.extend(venv.finished().iter().flatten().copied());
        }
        self.last_contact_rate = contacts_total as f64 / (t_len * b).max(1) as f64;
        // bootstrap values of the state after the last step (masked by done in GAE)
        venv.observe(&mut step_obs);
        let last_raw = self
            .critic
            .forward_step(&step_obs, n, &mut hc, &masks)?
            .to_vec();
        self.advantages(&last_raw, t_len, b);
        Ok(finished)
    }

    /// GAE over the rollout's rewards and (denormalised) values, bootstrapped from the
    /// critic's `last_raw` values of the state after the last step; then advantage
    /// normalisation when configured.
    fn advantages(&mut self, last_raw: &[f32], t_len: usize, b: usize) {
        let last: Vec<f32> = last_raw.iter().map(|&v| self.denorm(v)).collect();
        let values: Vec<f32> = self.buf.values.iter().map(|&v| self.denorm(v)).collect();
        let cfg = &self.cfg;
        let buf = &mut self.buf;
        buf.adv.resize(t_len * b, 0.0);
        buf.ret.resize(t_len * b, 0.0);
        gae(
            &buf.rewards,
            &values,
            &buf.dones,
            &last,
            t_len,
            b,
            cfg.gamma,
            cfg.gae_lambda,
            &mut buf.adv,
            &mut buf.ret,
        );
        if cfg.advantage_norm {
            let m = buf.adv.iter().map(|&x| x as f64).sum::<f64>() / buf.adv.len() as f64;
            let var = buf
                .adv
                .iter()
                .map(|&x| (x as f64 - m) * (x as f64 - m))
                .sum::<f64>()
                / buf.adv.len() as f64;
            let s = var.sqrt() + 1e-5;
            for a in &mut buf.adv {
                *a = ((*a as f64 - m) / s) as f32;
            }
        }
    }
}

/// Action sampling of one rollout step: the shield's logit bias (when the pilots have
/// it), then one categorical draw per row.
struct Sampler<'a> {
    pilots: &'a [Pilot],
    /// Scratch: the shield's bias of one row.
    bias: &'a mut [f32],
    /// Scratch: log-probabilities of one row.
    lp: &'a mut [f32],
    rng: &'a mut ChaCha8Rng,
}

impl Sampler<'_> {
    /// Sample `acts` from `logits` (biased in place by the shield), recording the shield
    /// bias and the log-probability of each action in `buf`.
    fn sample(
        &mut self,
        logits: &mut [f32],
        step_obs: &ObsBatch,
        acts: &mut [u8],
        buf: &mut Rollout,
    ) {
        let (bias, lp) = (&mut *self.bias, &mut *self.lp);
        let k = lp.len();
        for (r, act) in acts.iter_mut().enumerate() {
            let lg = &mut logits[r * k..(r + 1) * k];
            if let Some(safe) = self.pilots[r].safe_moves(Row::of(step_obs, r)) {
                bias.iter_mut().for_each(|x| *x = 0.0);
                plan::shield::mask_logits(bias, &safe);
                lg.iter_mut().zip(&*bias).for_each(|(l, b)| *l += b);
                buf.shield.extend_from_slice(bias);
            }
            let lg = &*lg;
            categorical::log_softmax(lg, lp);
            let a = categorical::sample(lg, self.rng.gen::<f32>());
            *act = a as u8;
            buf.logp.push(lp[a]);
        }
    }
}

/// One pilot per robot (its planner and filter keep what they saw last step); rebuilt
/// per rollout because every rollout starts fresh episodes. Behind the shield and/or the
/// ORCA filter as configured (`shield`, `orca_filter` with `orca_filter_clearance`, the
/// deployed rest clearance and obstacle horizon); a target-action actor's pilot plans its
/// velocity even without the filter.
fn rollout_pilots(
    cfg: &TrainConfig,
    actions: ActionSpace,
    scenario: &ScenarioConfig,
    venv: &VecEnv,
    b: usize,
) -> Result<Vec<Pilot>, TrainError> {
    let fleet = crate::baselines::fleet_params(venv.envs()[0].sizes(), scenario);
    let safety = Safety {
        shield: cfg.shield,
        filter: cfg.orca_filter.then_some(FilterMargins {
            clearance: cfg.orca_filter_clearance,
            rest_clearance: FILTER_REST_CLEARANCE,
            obstacle_horizon: FILTER_OBSTACLE_HORIZON,
        }),
    };
    let one = Pilot::new(&fleet, actions.outputs(), safety)
        .map_err(|reason| TrainError::Config(format!("the rollouts' pilot: {reason}")))?;
    Ok(vec![one; b])
}

/// Replace each robot's reward r by (1 - w) r + w mean(r of its env) (`team_reward`);
/// `rewards` is env-major, `n` robots per env. w = 0 leaves the bits unchanged.
fn mix_team_reward(rewards: &mut [f32], n: usize, w: f32) {
    if w == 0.0 || n == 0 {
        return;
    }
    for env in rewards.chunks_exact_mut(n) {
        let mean = env.iter().sum::<f32>() / n as f32;
        for r in env.iter_mut() {
            *r = (1.0 - w) * *r + w * mean;
        }
    }
}

#[cfg(test)]
mod team_reward_tests {
    use super::mix_team_reward;

    #[test]
    fn team_reward_mixes_within_each_env_only() {
        let mut r = [1.0, 3.0, 10.0, 30.0];
        mix_team_reward(&mut r, 2, 0.0);
        assert_eq!(r, [1.0, 3.0, 10.0, 30.0]);
        mix_team_reward(&mut r, 2, 1.0);
        assert_eq!(r, [2.0, 2.0, 20.0, 20.0]);
        let mut r = [1.0, 3.0];
        mix_team_reward(&mut r, 2, 0.5);
        assert_eq!(r, [1.5, 2.5]);
    }
}
