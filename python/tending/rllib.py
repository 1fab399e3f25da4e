"""tending's SMAPPO in Ray RLlib (new API stack): an RLModule whose networks are
:mod:`tending.smappo_torch` (the Rust actor and critic, layer for layer), and the env as an
RLlib ``MultiAgentEnv``, so that what PPO trains here is exported as a ``tending-policy``
checkpoint that ``tending eval``, ``tending fleet --policy`` and robot_node load.

Needs ray[rllib] and torch (not installed by CI; bench/python has the install)::

    from ray.rllib.algorithms.ppo import PPOConfig
    from tending.rllib import TendingMultiAgentEnv, smappo_ppo_config, export_policy

    config = smappo_ppo_config("6.4_2")          # PPOConfig: env, one shared policy, this module
    algo = config.build_algo()
    algo.train()
    export_policy(algo, "mine.safetensors")      # then: tending eval --checkpoint mine.safetensors

What it is:

- **One shared policy**: every robot is an agent mapped to the module ``"shared"``
  (parameter sharing, as the paper's SMAPPO and MAPPO).
- **The actor** is :class:`tending.smappo_torch.Actor` (encoder or MLP base, GRU,
  LayerNorm, logits): RLlib's state is its GRU state ``h``, one per robot, carried by the
  env runners between steps and stored in the episodes, so training replays chunks of
  ``max_seq_len`` steps (the Rust trainer's ``data_chunk_length``, 10) from their stored
  initial state.
- **MAPPO's centralised critic, the RLlib way**: RLlib's PPO computes each agent's values
  from that agent's own batch (``ValueFunctionAPI.compute_values``), with no hook to see the
  other agents' data at the same step. So the env gives each robot, besides its own
  observation, its team's (``"team"``: every robot's observation, itself first), and the
  critic is :class:`tending.smappo_torch.Critic` (the Rust centralised one: every robot's
  encoding, a learnable query attending over them, the robot's own encoding, GRU) on that
  team, read at row 0. Its GRU state ``vh`` is carried like ``h``. The actor never reads
  ``"team"``; the exported checkpoint holds the actor alone, and
  :func:`export_trainer_state` both (``tending train --resume`` can go on from it).
  ``centralised_critic=False`` drops ``"team"``: the critic then sees the robot alone (an
  environment of one robot: IPPO's decentralised critic).

The observation is the simulator's per-group Dict (``tending.parallel_env``'s default
layout), kept as a Dict by RLlib's connectors (no flattening).
"""

from __future__ import annotations

import os
from typing import Any, Mapping

import gymnasium as gym
import numpy as np
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis.value_function_api import ValueFunctionAPI
from ray.rllib.core.rl_module.torch import TorchRLModule
from ray.rllib.env.multi_agent_env import MultiAgentEnv

from . import smappo_torch as st
from .env import TendingParallelEnv

GROUPS = ("self", "machines", "storages", "peers")
MODULE_ID = "shared"

__all__ = [
    "MODULE_ID",
    "SmappoPPOLearner",
    "SmappoRLModule",
    "TendingMultiAgentEnv",
    "export_policy",
    "export_trainer_state",
    "smappo_ppo_config",
]


class TendingMultiAgentEnv(MultiAgentEnv):
    """:func:`tending.parallel_env` as an RLlib ``MultiAgentEnv``: agents ``robot_<i>``,
    ``Discrete(5)`` moves (``diagonal_actions``: 9), Dict observations per robot, plus
    ``"team"`` (every robot's observation groups, this robot's row first) when
    ``centralised_critic`` (default True). ``env_config`` keys: ``setup`` (default 6.4_2),
    ``seed``, ``config`` (simulator config), ``diagonal_actions``, ``centralised_critic``.
    Each robot's info carries the episode's ``metrics`` (parts, contacts, MU), as in
    :class:`tending.TendingParallelEnv`. A fixed robot set: live changes are not exposed."""

    def __init__(self, config: Mapping | None = None):
        super().__init__()
        cfg = dict(config or {})
        # RLlib's EnvContext: different env runners and vector slots get different seeds
        idx = getattr(config, "worker_index", 0) * 1000 + getattr(config, "vector_index", 0)
        self.env = TendingParallelEnv(
            cfg.get("setup", "6.4_2"), seed=int(cfg.get("seed", 0)) + idx, config=cfg.get("config"),
            diagonal_actions=bool(cfg.get("diagonal_actions", False)),
        )
        self.centralised = bool(cfg.get("centralised_critic", True))
        self.possible_agents = list(self.env.possible_agents)
        self.agents = list(self.possible_agents)
        n = len(self.possible_agents)
        one = self.env.observation_space(self.possible_agents[0])
        spaces = dict(one.spaces)
        if self.centralised:
            spaces["team"] = gym.spaces.Dict({
                g: gym.spaces.Box(np.repeat(one[g].low[None], n, 0), np.repeat(one[g].high[None], n, 0),
                                  dtype=np.float32)
                for g in GROUPS
            })
        space = gym.spaces.Dict(spaces)
        self.observation_spaces = {a: space for a in self.possible_agents}
        self.action_spaces = {a: self.env.action_space(a) for a in self.possible_agents}

    def _obs(self, agents) -> dict:
        """Every robot's observation (rows in robot order, as ``agents``)."""
        arrs = dict(zip(GROUPS, self.env.observe_arrays()))
        out = {}
        for i, a in enumerate(agents):
            o = {g: arrs[g][i] for g in GROUPS}
            if self.centralised:
                o["team"] = {g: np.roll(arrs[g], -i, axis=0) for g in GROUPS}
            out[a] = o
        return out

    def reset(self, *, seed=None, options=None):
        self.env.reset(seed=seed) if seed is not None else self.env.reset()
        self.agents = list(self.env.agents)
        return self._obs(self.agents), {a: {} for a in self.agents}

    def step(self, action_dict):
        agents = list(self.env.agents)
        _, rew, term, trunc, infos = self.env.step({a: int(v) for a, v in action_dict.items()})
        done = not self.env.agents
        # after the episode's end the env lists no agents, but the simulator still holds
        # its final state: the last observation of every robot
        obs = self._obs(agents)
        self.agents = list(self.env.agents)
        return obs, rew, dict(term, __all__=False), dict(trunc, __all__=done), infos


class SmappoRLModule(TorchRLModule, ValueFunctionAPI):
    """RLlib RLModule of tending's actor and centralised critic (:mod:`tending.smappo_torch`).

    ``model_config``: ``arch`` (keyword arguments of :func:`tending.smappo_torch.arch_config`,
    default the paper's SMAPPO), or ``checkpoint``: a ``tending-policy`` checkpoint to start
    the actor from (fine-tuning a Rust-trained policy) or a ``tending-trainer-state`` (actor
    and critic); ``max_seq_len`` (default 10): the training chunks' length.

    Submodules ``actor`` and ``critic`` are the torch twins of the Rust networks:
    ``module.actor.save(path)`` writes a checkpoint that the Rust side loads."""

    def setup(self):
        cfg = self.model_config or {}
        ck = cfg.get("checkpoint")
        if ck:
            self.actor = st.Actor.load(ck)
            try:
                self.critic = st.Critic.load(ck)
            except st.CheckpointError:  # a policy checkpoint: no critic in it
                self.critic = st.Critic(self.actor.arch)
        else:
            arch = st.arch_config(**dict(cfg.get("arch") or {}))
            self.actor = st.Actor(arch, training={"trained_by": "ray.rllib PPO (tending.rllib)"})
            self.critic = st.Critic(arch)
        n = self.action_space.n
        if n != self.actor.arch["n_actions"]:
            raise ValueError(f"the env has {n} actions, the actor {self.actor.arch['n_actions']}")
        # MAPPO's ValueNorm (learn/src/valuenorm.rs): running mean, mean of squares and
        # debiasing term of the returns; the critic's head learns normalised values and
        # compute_values() gives them denormalised (what GAE needs). Updated by
        # SmappoPPOLearner once per minibatch, as MAPPO and `tending train` do.
        self.value_norm = bool(cfg.get("value_norm", False))
        self.register_buffer("vn_stats", torch.zeros(3, dtype=torch.float64))
        self._values_normalised = False  # set by the learner around its loss

    def get_initial_state(self) -> Any:
        h = self.actor.hidden
        return {"h": np.zeros(h, np.float32), "vh": np.zeros(self.critic.arch["hidden"], np.float32)}

    # ---- helpers: RLlib's batches are (B, T, ...) with the state at each sequence's start

    @staticmethod
    def _own(obs: Mapping) -> dict:
        return {g: obs[g] for g in GROUPS}

    def _actor_seq(self, batch):
        obs = self._own(batch[Columns.OBS])
        feat = self.actor.features(obs)  # (B, T, hidden)
        h0 = batch[Columns.STATE_IN]["h"]
        logits, h = self.actor._head(feat.transpose(0, 1), h0, None)
        return logits.transpose(0, 1), h

    def _critic_seq(self, batch):
        obs = batch[Columns.OBS]
        team = obs.get("team") if isinstance(obs, Mapping) else None
        if team is None:  # decentralised: an environment of this robot alone
            team = {g: v.unsqueeze(-3) for g, v in self._own(obs).items()}
        feat = self.critic.features(team)[..., 0, :]  # (B, T, n, hidden) -> this robot's row
        h0 = batch[Columns.STATE_IN]["vh"]
        v, h = self.critic._head(feat.transpose(0, 1), h0, None)
        return v[..., 0].transpose(0, 1), h

    # ---- RLModule API

    def _forward(self, batch, **kwargs):
        logits, h = self._actor_seq(batch)
        out = {Columns.ACTION_DIST_INPUTS: logits}
        if Columns.STATE_IN in batch:
            # the critic's GRU state is carried alongside the actor's, so that training
            # replays both from the states the env runners stored
            _, vh = self._critic_seq(batch)
            out[Columns.STATE_OUT] = {"h": h, "vh": vh}
        return out

    def compute_values(self, batch, embeddings=None):
        v, _ = self._critic_seq(batch)
        if self.value_norm and not self._values_normalised:
            mean, var = self.vn_mean_var()
            v = (v.double() * var.sqrt() + mean).to(v.dtype)
        return v

    # ---- ValueNorm (MAPPO's, beta 0.99999; inactive unless model_config value_norm)

    VN_BETA = 0.99999

    def vn_mean_var(self):
        m, m2, d = self.vn_stats.unbind()
        d = d.clamp(min=1e-5)
        mean = m / d
        return mean, (m2 / d - mean * mean).clamp(min=1e-2)

    @torch.no_grad()
    def vn_update(self, returns: torch.Tensor) -> None:
        x = returns.detach().double().flatten()
        if x.numel() == 0:
            return
        b = self.VN_BETA
        new = torch.stack([x.mean(), (x * x).mean(), torch.ones((), dtype=x.dtype)])
        self.vn_stats.mul_(b).add_((1.0 - b) * new.to(self.vn_stats.device))

    def vn_normalize(self, x: torch.Tensor) -> torch.Tensor:
        mean, var = self.vn_mean_var()
        return ((x.double() - mean) / var.sqrt()).to(x.dtype)


def _ppo_torch_learner():
    from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner

    return PPOTorchLearner


class SmappoPPOLearner(_ppo_torch_learner()):
    """RLlib's PPO torch learner with MAPPO's two optimizers: one Adam (eps 1e-5) for the
    actor and one for the critic, each gradient clipped on its own (RLlib clips per
    optimizer). With RLlib's single optimizer the global-norm clip is taken over actor and
    critic together, so the critic's gradient (values in return units, no ValueNorm here)
    sets the clip and scales the actor's step down with it."""

    def compute_loss_for_module(self, *, module_id, config, batch, fwd_out):
        """RLlib's PPO loss; with ValueNorm, on normalised values and value targets (the
        statistics first take in this minibatch's targets, as MAPPO's)."""
        module = self.module[module_id].unwrapped()
        if not getattr(module, "value_norm", False):
            return super().compute_loss_for_module(
                module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)
        from ray.rllib.evaluation.postprocessing import Postprocessing

        targets = batch[Postprocessing.VALUE_TARGETS]
        mask = batch.get(Columns.LOSS_MASK)
        module.vn_update(targets[mask] if mask is not None else targets)
        batch = dict(batch)
        batch[Postprocessing.VALUE_TARGETS] = module.vn_normalize(targets)
        module._values_normalised = True
        try:
            return super().compute_loss_for_module(
                module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)
        finally:
            module._values_normalised = False

    def configure_optimizers_for_module(self, module_id, config=None):
        module = self._module[module_id]
        module = module.unwrapped() if hasattr(module, "unwrapped") else module
        for name, sub in (("actor", module.actor), ("critic", module.critic)):
            params = list(sub.parameters())
            self.register_optimizer(
                module_id=module_id, optimizer_name=name, params=params,
                optimizer=torch.optim.Adam(params, eps=1e-5), lr_or_lr_schedule=config.lr,
            )


def smappo_ppo_config(setup: str = "6.4_2", *, seed: int = 0, env_runners: int = 0,
                      envs_per_runner: int = 1, centralised_critic: bool = True,
                      arch: Mapping | None = None, checkpoint: str | os.PathLike | None = None,
                      max_seq_len: int = 10, hparams: str = "mappo", value_norm: bool = True):
    """A ``PPOConfig`` (new API stack) of tending at ``setup`` with one shared
    :class:`SmappoRLModule`. ``hparams="mappo"`` sets what ``tending train`` uses (Yu et al.'s
    MAPPO: lr 5e-4, entropy 0.01, GAE lambda 0.95, gamma 0.99, clip 0.2, 10 epochs;
    separate Adam optimizers for actor and critic, eps 1e-5, each gradient clipped at norm
    10, :class:`SmappoPPOLearner`). RLlib counts the batch (``train_batch_size_per_learner``)
    in env steps but slices minibatches (``minibatch_size``) from the shared module's
    agent-steps, and refuses a minibatch larger than the batch; so the batch is 2,400 env
    steps (12 episodes) and a minibatch 2,400 agent-steps: at 6.4_2 (6 robots) 6 minibatches
    an epoch, the minibatch size and the Adam steps per sample of the paper runs' ``tending
    train`` (``results/paper/A_6.4_2.train.toml``: 8 episodes an update, 4 minibatches of
    2,400). ``"rllib"`` keeps RLlib's defaults. Change anything further on the returned
    config. ``value_norm`` (with ``"mappo"``): MAPPO's ValueNorm, as ``tending train``'s
    ``use_valuenorm`` (the critic learns normalised returns; see :class:`SmappoRLModule`)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    model_config = {"max_seq_len": int(max_seq_len), "arch": dict(arch or {}),
                    "value_norm": bool(value_norm) and hparams == "mappo"}
    if checkpoint is not None:
        model_config["checkpoint"] = os.fspath(checkpoint)
    config = (
        PPOConfig()
        .environment(TendingMultiAgentEnv, env_config={"setup": setup, "seed": seed,
                                                       "centralised_critic": centralised_critic})
        .multi_agent(policies={MODULE_ID}, policy_mapping_fn=lambda agent_id, *a, **k: MODULE_ID)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={
            MODULE_ID: RLModuleSpec(module_class=SmappoRLModule, model_config=model_config)}))
        .env_runners(num_env_runners=env_runners, num_envs_per_env_runner=envs_per_runner)
        .debugging(seed=seed)
    )
    if hparams == "mappo":
        config = config.training(
            lr=5e-4, entropy_coeff=0.01, lambda_=0.95, gamma=0.99, clip_param=0.2,
            grad_clip=10.0, grad_clip_by="global_norm", num_epochs=10,
            train_batch_size_per_learner=2400, minibatch_size=2400,
            vf_loss_coeff=1.0, use_kl_loss=False, vf_clip_param=float("inf"),
        ).learners(learner_class=SmappoPPOLearner)
    elif hparams != "rllib":
        raise ValueError(f"hparams: {hparams!r} is not 'mappo' or 'rllib'")
    return config


def _module(algo_or_module, module_id: str = MODULE_ID) -> SmappoRLModule:
    if isinstance(algo_or_module, SmappoRLModule):
        return algo_or_module
    m = algo_or_module.get_module(module_id)
    if not isinstance(m, SmappoRLModule):
        raise TypeError(f"module {module_id!r} is a {type(m).__name__}, not a SmappoRLModule")
    return m


def export_policy(algo_or_module, path: str | os.PathLike, module_id: str = MODULE_ID,
                  training: Any = None) -> st.Actor:
    """Write the trained actor as a ``tending-policy`` checkpoint (what ``tending eval
    --checkpoint``, ``tending fleet --policy`` and robot_node load); returns a CPU copy."""
    m = _module(algo_or_module, module_id)
    actor = st.Actor(m.actor.arch, training=training if training is not None else m.actor.training)
    actor.load_state_dict({k: v.detach().cpu() for k, v in m.actor.state_dict().items()})
    actor.save(path)
    return actor


def export_trainer_state(algo_or_module, path: str | os.PathLike, module_id: str = MODULE_ID,
                         extra: Any = None) -> None:
    """Write actor and critic as a ``tending-trainer-state`` (Adam moments zero). With
    ValueNorm the critic's output is a normalised value: the statistics go into ``extra``
    (``"rllib_valuenorm"``: running mean, mean of squares, debiasing term, beta), unless
    ``extra`` is given."""
    m = _module(algo_or_module, module_id)
    if extra is None and getattr(m, "value_norm", False):
        extra = {"rllib_valuenorm": [float(x) for x in m.vn_stats.tolist()] + [m.VN_BETA]}
    st.save_trainer_state(path, m.actor, m.critic, extra=extra)
