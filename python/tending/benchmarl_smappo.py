"""The SMAPPO paper's observation encoder as a BenchMARL model: MAPPO with it is SMAPPO.

Needs benchmarl (``pip install './python[torchrl]'``).

::

    from tending.benchmarl_smappo import SmappoConfig
    model = SmappoConfig.for_setup("6.4_2")     # machines and storages of the setup
    Experiment(task=tending.benchmarl.task("6.4_2"), algorithm_config=MappoConfig...,
               model_config=model, ...)   # the critic: BenchMARL's copy of model

Each robot's observation (``("agents", "observation")`` of :class:`tending.torchrl.TendingEnv`:
self 3, machines 3M, storages 2K, peers 3(N-1), concatenated) is split into its entity
groups; the robot's own features, embedded, attend over each group's embedded entities
(one ``nn.MultiheadAttention`` per group, the robot as the single query); the four
vectors, concatenated, go through a small MLP head. One set of parameters for all robots,
as in the paper. As a MAPPO critic (centralised, shared parameters: one value per env) the
robots' encodings are averaged before the head.

A torch rewrite of the idea, not of our Rust network (``policy/src/nn/attention.rs``,
which also encodes each entity group with its own layer and attends with the robot as the
query): sizes and initialisation here are BenchMARL's and torch's defaults, and a
checkpoint of one does not load into the other. A model is built for one setup's entity
counts (the env gives observations at those counts); evaluating it zero-shot on another
setup needs a model rebuilt with the new counts and the same weights, which
:meth:`SmappoEncoder.load_state_dict` accepts since no weight depends on a count.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from benchmarl.models.common import Model, ModelConfig
from tensordict import TensorDictBase
from torch import nn

from ._benchmarl_model import model_args

# (name, features per entity) after the robot's own 3 features, in the observation's order
GROUPS = (("machines", 3), ("storages", 2), ("peers", 3))
SELF_DIM = 3


class SmappoEncoder(Model):
    """See the module doc. Config: :class:`SmappoConfig`."""

    def __init__(self, machines: int, storages: int, embed_dim: int, num_heads: int,
                 hidden: int, **kwargs):
        super().__init__(**model_args(kwargs))
        self.counts = {"machines": machines, "storages": storages,
                       "peers": self.n_agents - 1}
        d = self.input_leaf_spec.shape[-1]
        want = SELF_DIM + sum(self.counts[g] * w for g, w in GROUPS)
        if d != want:
            raise ValueError(
                f"observation has {d} features, but {self.counts} give {want} "
                "(build the config with SmappoConfig.for_setup(<the task's setup>))")
        e = embed_dim
        dev = self.device
        self.embed_self = nn.Linear(SELF_DIM, e, device=dev)
        self.embed = nn.ModuleDict({g: nn.Linear(w, e, device=dev) for g, w in GROUPS})
        self.attend = nn.ModuleDict({
            g: nn.MultiheadAttention(e, num_heads, batch_first=True, device=dev)
            for g, _ in GROUPS
        })
        out = self.output_leaf_spec.shape[-1]
        self.head = nn.Sequential(nn.Linear(4 * e, hidden, device=dev), nn.Tanh(),
                                  nn.Linear(hidden, out, device=dev))
        self.embed_dim = e

    def _perform_checks(self):
        super()._perform_checks()
        if not self.input_has_agent_dim:
            raise ValueError("SmappoEncoder reads each robot's observation: it needs inputs "
                             "with the agent dimension (no global state)")
        if not self.share_params:
            raise ValueError("SmappoEncoder has one set of parameters for all robots "
                             "(share_policy_params / share_param_critic must be true)")

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """(..., D) observations -> (..., 4E) encodings."""
        lead = x.shape[:-1]
        x = x.reshape(-1, x.shape[-1])
        me = torch.relu(self.embed_self(x[:, :SELF_DIM]))
        parts, off = [me], SELF_DIM
        for g, w in GROUPS:
            n = self.counts[g]
            if n == 0:  # e.g. a robot alone: no peers to attend over
                parts.append(torch.zeros_like(me))
                continue
            ent = torch.relu(self.embed[g](x[:, off:off + n * w].reshape(-1, n, w)))
            off += n * w
            a, _ = self.attend[g](me.unsqueeze(1), ent, ent, need_weights=False)
            parts.append(a.squeeze(1))
        return torch.cat(parts, dim=-1).reshape(*lead, 4 * self.embed_dim)

    def _forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        h = self.encode(tensordict.get(self.in_key))  # (..., N, 4E)
        if not self.output_has_agent_dim:
            # a centralised critic with shared parameters: one value per env
            h = h.mean(dim=-2)
        tensordict.set(self.out_key, self.head(h))
        return tensordict


@dataclass
class SmappoConfig(ModelConfig):
    """Config of :class:`SmappoEncoder`: the setup's machine and storage counts (the robot
    count comes from the agent group), embedding size, attention heads, head width."""

    machines: int = 0
    storages: int = 0
    embed_dim: int = 64
    num_heads: int = 4
    hidden: int = 64

    @staticmethod
    def associated_class():
        return SmappoEncoder

    @classmethod
    def for_setup(cls, setup: str, **kwargs) -> "SmappoConfig":
        """The config for setup ``N.M_K`` (or ``tending/N.M_K``)."""
        name = setup.split("/")[-1]
        try:
            _, rest = name.split(".", 1)
            m, k = (int(v) for v in rest.replace("_", " ").split())
        except ValueError:
            raise ValueError(f"setup {setup!r}: expected N.M_K, e.g. 6.4_2") from None
        return cls(machines=m, storages=k, **kwargs)
