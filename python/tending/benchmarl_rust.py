"""tending's own SMAPPO networks (:mod:`tending.smappo_torch`, the Rust actor and critic
layer for layer) as a BenchMARL model: what BenchMARL trains with it is exported as a
``tending-policy`` checkpoint that ``tending eval``, ``tending fleet --policy`` and
robot_node load.

Needs benchmarl (``pip install './python[torchrl]'``)::

    import tending.benchmarl
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from tending.benchmarl_rust import RustSmappoConfig, export_policy

    model = RustSmappoConfig.for_setup("6.4_2")   # or checkpoint="policy/pretrained/...": fine-tune
    algo = MappoConfig.get_from_yaml()
    algo.share_param_critic = False               # per-robot values, as the Rust critic (see below)
    exp = Experiment(task=tending.benchmarl.task("6.4_2"), algorithm_config=algo,
                     model_config=model, seed=0,      # the critic: BenchMARL's copy of model
                     config=ExperimentConfig.get_from_yaml())
    exp.run()
    export_policy(exp, "mine.safetensors")        # tending eval --checkpoint mine.safetensors

Unlike :mod:`tending.benchmarl_smappo` (the paper's encoder rewritten in BenchMARL's
idiom, a checkpoint of which loads nowhere else), this model *is* the Rust network:

- As the policy: :class:`tending.smappo_torch.Actor` (encoder, GRU, LayerNorm, logits) on
  each robot's observation (``("agents", "observation")`` of
  :class:`tending.torchrl.TendingEnv`, split back into self, machines, storages and peers by
  the setup's counts), one parameter set for all robots. It is recurrent the BenchMARL way
  (``is_rnn``: the GRU state ``("agents", "_hidden_tending_<i>")`` carried by the collector,
  zeroed where ``is_init``; in training, sequences from a zero state, reset at ``is_init``).
- As MAPPO's critic: :class:`tending.smappo_torch.Critic`, the Rust centralised critic (a
  learnable query attending over every robot's encoding), one value per robot. BenchMARL
  asks a centralised critic with shared parameters (``share_param_critic=True``, MAPPO's
  default) for one value per environment: it then gets the mean of the robots' values;
  ``share_param_critic=False`` gives the per-robot values of the Rust critic (its
  parameters stay one set: this model has no per-agent copies). As IPPO's critic
  (decentralised) each robot is an environment of its own.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import torch
from benchmarl.models.common import Model, ModelConfig
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded

from . import smappo_torch as st
from ._benchmarl_model import model_args
from .flat_recurrent import recurrent_forward, setup_counts, split_flat


class RustSmappo(Model):
    """See the module doc. Config: :class:`RustSmappoConfig`."""

    def __init__(self, machines: int, storages: int, arch: dict | None, checkpoint: str | None, **kwargs):
        super().__init__(**model_args(kwargs))
        self.counts = (machines, storages, self.n_agents - 1)
        self.hidden_state_name = (self.agent_group, f"_hidden_tending_{self.model_index}")
        self.rnn_keys = ["is_init", self.hidden_state_name]
        self.in_keys += self.rnn_keys
        d = self.input_leaf_spec_obs.shape[-1]
        want = st.SELF_DIM + machines * st.MACHINE_DIM + storages * st.STORAGE_DIM + (self.n_agents - 1) * st.PEER_DIM
        if d != want:
            raise ValueError(f"observation has {d} features, but {self.counts} (machines, storages, peers) "
                             f"give {want} (build the config with RustSmappoConfig.for_setup(<the task's setup>))")
        if self.is_critic:
            if checkpoint and _format(checkpoint) == st.TRAINER_FORMAT:
                self.net = st.Critic.load(checkpoint)
            else:
                a = st.Actor.load(checkpoint).arch if checkpoint else st.arch_config(**(arch or {}))
                self.net = st.Critic(a)
            out = 1
        else:
            self.net = (st.Actor.load(checkpoint) if checkpoint
                        else st.Actor(st.arch_config(**(arch or {})), training={"trained_by": "BenchMARL (tending.benchmarl_rust)"}))
            out = self.net.arch["n_actions"]
        if self.output_leaf_spec.shape[-1] != out:
            raise ValueError(f"BenchMARL expects {self.output_leaf_spec.shape[-1]} outputs, the network gives {out}")
        self.net.to(self.device)

    @property
    def input_leaf_spec_obs(self):
        keys = [k for k in self.in_keys if k not in getattr(self, "rnn_keys", [])]
        if len(keys) != 1:
            raise ValueError(f"RustSmappo reads one observation key, got {keys}")
        return self.input_spec[keys[0]]

    def _perform_checks(self):
        super()._perform_checks()
        if not self.input_has_agent_dim:
            raise ValueError("RustSmappo reads each robot's observation: it needs inputs with the agent "
                             "dimension (no global state)")
        if not self.share_params and not self.is_critic:
            raise ValueError("RustSmappo's policy has one set of parameters for all robots "
                             "(share_policy_params must be true)")

    def _forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        obs_key = [k for k in self.in_keys if k not in self.rnn_keys][0]
        x = tensordict.get(obs_key)
        h0 = tensordict.get(self.hidden_state_name, None)
        is_init = tensordict.get("is_init")
        critic_alone = self.is_critic and not self.centralised  # IPPO: each robot an env of its own
        y, h = recurrent_forward(self.net, split_flat(x, *self.counts), h0, is_init, robots_apart=critic_alone)
        if not self.output_has_agent_dim:
            y = y.mean(-2)  # one value per env: the mean of the robots' values
        tensordict.set(self.out_key, y)
        if h0 is not None:
            tensordict.set(("next", *self.hidden_state_name), h)
        return tensordict


def _format(path) -> str:
    return st.read_safetensors(path)[1].get("format", "")


@dataclass
class RustSmappoConfig(ModelConfig):
    """Config of :class:`RustSmappo`: the setup's machine and storage counts (the robot
    count comes from the agent group); ``arch``: keyword arguments of
    :func:`tending.smappo_torch.arch_config` (default the paper's SMAPPO: d_model 64, 4
    heads, GRU 64, 5 moves); ``checkpoint``: start from a ``tending-policy`` checkpoint
    (its actor; the critic fresh) or a ``tending-trainer-state`` (both)."""

    machines: int = 0
    storages: int = 0
    arch: Any = None
    checkpoint: Any = None

    @staticmethod
    def associated_class():
        return RustSmappo

    @property
    def is_rnn(self) -> bool:
        return True

    def get_model_state_spec(self, model_index: int = 0) -> Composite:
        if self.checkpoint:
            hidden = st.Actor.load(self.checkpoint).arch["hidden"]
        else:
            hidden = st.arch_config(**(self.arch or {}))["hidden"]
        return Composite({f"_hidden_tending_{model_index}": Unbounded(shape=(hidden,))})

    @classmethod
    def for_setup(cls, setup: str, **kwargs) -> "RustSmappoConfig":
        """The config for setup ``N.M_K`` (or ``tending/N.M_K``)."""
        _, m, k = setup_counts(setup)
        if "checkpoint" in kwargs and kwargs["checkpoint"] is not None:
            kwargs["checkpoint"] = os.fspath(kwargs["checkpoint"])
        return cls(machines=m, storages=k, **kwargs)


def actor_of(module: torch.nn.Module) -> st.Actor:
    """The :class:`tending.smappo_torch.Actor` inside a BenchMARL policy (or any module)."""
    for m in module.modules():
        if isinstance(m, st.Actor):
            return m
    raise ValueError("no tending.smappo_torch.Actor in this module (was the policy built with RustSmappoConfig?)")


def export_policy(experiment_or_module, path: str | os.PathLike, training: Any = ...) -> st.Actor:
    """Write the trained policy as a ``tending-policy`` checkpoint (``tending eval
    --checkpoint``, ``tending fleet --policy``, robot_node). Takes a BenchMARL
    ``Experiment`` (its ``policy``) or any module holding the actor; returns a CPU copy."""
    module = getattr(experiment_or_module, "policy", experiment_or_module)
    a = actor_of(module)
    out = st.Actor(a.arch, training=a.training if training is ... else training)
    out.load_state_dict({k: v.detach().cpu() for k, v in a.state_dict().items()})
    out.save(path)
    return out
