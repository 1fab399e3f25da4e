"""tending's SMAPPO and MAPPO networks in torch: the Rust networks of crate `policy`, layer
for layer, reading and writing its safetensors checkpoints.

The same function as the Rust actor (`policy::Actor`, what `tending eval` and robot_node
run) and critic (`policy::Critic`), with the same parameter names and shapes, so a
checkpoint written by one loads into the other (python/tests/test_smappo_torch.py compares
the logits of both on the same observations):

- SMAPPO actor (paper Fig. 1): per entity type Linear + ReLU to ``d_model``; per group
  (machines, storages, peers) one multi-head attention with the robot's own embedding as
  the only query over the group's embeddings (``nn.MultiheadAttention``'s parameter layout;
  an empty group gives ``out_proj.bias``); ``[self, att_m, att_s, att_p]`` -> Linear ->
  Tanh -> LayerNorm; then GRU -> LayerNorm -> Linear(n_actions).
- MAPPO actor: the observation zero-padded to the checkpoint's flat layout -> LayerNorm ->
  [Linear -> ReLU -> LayerNorm] x 2 -> the same recurrent head.
- Critics: SMAPPO's encoder of every robot, an attention with a learnable query over the
  robots of an environment, ``[g, enc_i]`` -> Linear -> Tanh -> LayerNorm -> recurrent head
  -> Linear(1); MAPPO's MLP over ``[own flat ++ every robot's flat, padded to max_robots]``.

Observations are the simulator's (``tending.parallel_env`` with the default Dict layout): a
mapping ``{"self": (..., 3), "machines": (..., M, 3), "storages": (..., K, 2), "peers":
(..., P, 3)}`` of float32 arrays or tensors, any leading batch shape; every row of one call
has the same counts (as in the Rust ``ObsBatch``). The GRU state is ``(..., hidden)``, zero
at the start of an episode.

Checkpoints: a policy checkpoint (``tending-policy``, what ``tending train`` writes and
robot_node loads) holds the actor; a trainer state (``tending-trainer-state``) holds actor
and critic (``actor.param.<name>``, ``critic.param.<name>``) with their Adam moments. Read
and written here without the ``safetensors`` package (the format is a JSON header and raw
little-endian float32 data).

Needs torch (the optional extra); ``import tending`` does not import this module.
"""

from __future__ import annotations

import json
import math
import os
import struct
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

FORMAT_VERSION = 1
POLICY_FORMAT = "tending-policy"
TRAINER_FORMAT = "tending-trainer-state"
SELF_DIM, MACHINE_DIM, STORAGE_DIM, PEER_DIM = 3, 3, 2, 3
OBS_LAYOUT = {"self_dim": 3, "machine_dim": 3, "storage_dim": 2, "peer_dim": 3}
GROUPS = ("machines", "storages", "peers")
GROUP_DIMS = (MACHINE_DIM, STORAGE_DIM, PEER_DIM)
LN_EPS = 1e-5

__all__ = [
    "Actor",
    "Critic",
    "CheckpointError",
    "arch_config",
    "load_policy",
    "read_safetensors",
    "write_safetensors",
]


class CheckpointError(ValueError):
    """A checkpoint that cannot be read into these networks (the message says why)."""


# --------------------------------------------------------------------------- safetensors


def read_safetensors(path: str | os.PathLike) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """Tensors (float32 only) and ``__metadata__`` of a safetensors file."""
    data = Path(path).read_bytes()
    if len(data) < 8:
        raise CheckpointError(f"{path}: not a safetensors file (truncated?)")
    (n,) = struct.unpack("<Q", data[:8])
    if 8 + n > len(data):
        raise CheckpointError(f"{path}: header of {n} bytes past the end (truncated?)")
    try:
        header = json.loads(data[8 : 8 + n])
    except ValueError as e:
        raise CheckpointError(f"{path}: invalid header JSON: {e}") from None
    meta = header.pop("__metadata__", None) or {}
    body = memoryview(data)[8 + n :]
    out = {}
    for name, info in header.items():
        if info["dtype"] != "F32":
            raise CheckpointError(f"tensor `{name}` has dtype {info['dtype']}, expected F32")
        b, e = info["data_offsets"]
        shape = [int(s) for s in info["shape"]]
        if e - b != 4 * math.prod(shape) or e > len(body):
            raise CheckpointError(f"tensor `{name}`: data offsets {b}..{e} do not fit shape {shape}")
        arr = np.frombuffer(body[b:e], dtype="<f4").reshape(shape)
        out[name] = torch.from_numpy(arr.astype(np.float32))
    return out, meta


def write_safetensors(
    path: str | os.PathLike, tensors: Mapping[str, torch.Tensor], metadata: Mapping[str, str]
) -> None:
    """Write float32 tensors and string metadata (atomically: a temporary file renamed)."""
    header: dict[str, Any] = {"__metadata__": dict(metadata)}
    blobs, off = [], 0
    for name in sorted(tensors):
        t = tensors[name].detach().to("cpu", torch.float32).contiguous()
        raw = t.numpy().astype("<f4", copy=False).tobytes()
        header[name] = {"dtype": "F32", "shape": list(t.shape), "data_offsets": [off, off + len(raw)]}
        blobs.append(raw)
        off += len(raw)
    h = json.dumps(header, separators=(",", ":")).encode()
    h += b" " * (-len(h) % 8)  # data aligned to 8 bytes, as the Rust crate writes it
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(h)))
        f.write(h)
        for b in blobs:
            f.write(b)
    os.replace(tmp, path)


# ------------------------------------------------------------------------- configuration


def arch_config(kind: str = "smappo", **over) -> dict:
    """An ``ArchConfig`` (policy/src/config.rs) as a dict: the paper's SMAPPO (d_model 64, 4
    heads, hidden 64, 5 moves) by default; MAPPO needs ``flat={"max_machines": M,
    "max_storages": K, "max_peers": P}`` and ``max_robots``."""
    a = {
        "kind": kind,
        "d_model": 64,
        "heads": 4,
        "hidden": 64,
        "n_actions": 5,
        "actions": "moves",
        "flat": None,
        "max_robots": None,
    }
    unknown = set(over) - set(a)
    if unknown:
        raise ValueError(f"unknown ArchConfig fields {sorted(unknown)}")
    a.update(over)
    check_arch(a)
    return a


def check_arch(a: Mapping) -> None:
    """The Rust loader's refusals (policy/src/checkpoint.rs `check_arch`)."""

    def bad(m):
        raise CheckpointError(f"checkpoint architecture is not usable: {m}")

    if a.get("kind") not in ("smappo", "mappo"):
        bad(f"kind {a.get('kind')!r}")
    for k in ("d_model", "heads", "hidden", "n_actions"):
        if not isinstance(a.get(k), int) or a[k] <= 0:
            bad(f"{k} {a.get(k)!r}")
    if a["d_model"] > 4096 or a["hidden"] > 4096 or a["n_actions"] > 256 or a["heads"] > a["d_model"]:
        bad("dimension out of range")
    if a["d_model"] % a["heads"]:
        bad("d_model is not a multiple of heads")
    sizes = {"moves": (5, 9), "targets": (8, 7)}  # obs::action, plan::targets (and its v1)
    act = a.get("actions", "moves")
    if act not in sizes or a["n_actions"] not in sizes[act]:
        bad(f"{a['n_actions']} outputs do not fit the action space {act!r}")
    if a["kind"] == "mappo":
        if not a.get("flat"):
            bad("MAPPO without a flat observation layout")
        if not a.get("max_robots"):
            bad("MAPPO without max_robots")


def flat_dim(flat: Mapping) -> int:
    return SELF_DIM + flat["max_machines"] * MACHINE_DIM + flat["max_storages"] * STORAGE_DIM + flat["max_peers"] * PEER_DIM


# ---------------------------------------------------------------------------- observations


def as_obs(obs: Mapping, device=None, dtype=torch.float32) -> dict[str, torch.Tensor]:
    """The four groups as tensors (float32 unless told; ``own`` is accepted for ``self``)."""
    own = obs["self"] if "self" in obs else obs["own"]
    out = {"self": torch.as_tensor(np.asarray(own) if not torch.is_tensor(own) else own, dtype=dtype, device=device)}
    dims = dict(zip(GROUPS, GROUP_DIMS))
    lead = out["self"].shape[:-1]
    for g in GROUPS:
        x = obs.get(g)
        if x is None:
            x = torch.zeros(*lead, 0, dims[g])
        x = torch.as_tensor(np.asarray(x) if not torch.is_tensor(x) else x, dtype=dtype, device=device)
        if x.numel() == 0:  # an empty group may come as shape (..., 0) from numpy
            x = x.reshape(*lead, 0, dims[g])
        if x.shape[:-2] != lead or x.shape[-1] != dims[g]:
            raise ValueError(f"observation `{g}` has shape {tuple(x.shape)}, expected {tuple(lead)} + (count, {dims[g]})")
        out[g] = x
    if out["self"].shape[-1] != SELF_DIM:
        raise ValueError(f"observation `self` has shape {tuple(out['self'].shape)}, expected (..., {SELF_DIM})")
    return out


def flatten_obs(obs: Mapping[str, torch.Tensor], flat: Mapping) -> torch.Tensor:
    """MAPPO's padded flat vector (obs/src/flat.rs): self, machines, storages, peers, each
    group zero-padded to the layout's maximum; more entities than that is an error."""
    parts = [obs["self"]]
    lead = obs["self"].shape[:-1]
    for g, d, key in zip(GROUPS, GROUP_DIMS, ("max_machines", "max_storages", "max_peers")):
        x, mx = obs[g], flat[key]
        if x.shape[-2] > mx:
            raise ValueError(f"{x.shape[-2]} {g}, the checkpoint's flat layout holds at most {mx}")
        x = x.reshape(*lead, x.shape[-2] * d)
        parts.append(F.pad(x, (0, (mx - obs[g].shape[-2]) * d)))
    return torch.cat(parts, -1)


# ---------------------------------------------------------------------------------- layers


class Attention(nn.Module):
    """Multi-head attention with one query per row over S entities per row
    (nn/src/attention.rs), ``nn.MultiheadAttention``'s parameters: ``in_proj_weight`` [3E,
    E] = [Wq; Wk; Wv], ``in_proj_bias``, ``out_proj``. Same algebra as the Rust: per head
    U_h = Wk_h^T q_h / sqrt(dh), weights softmax_j(U_h . e_j) (the key bias shifts every
    score of a row equally, so it drops out), output Wv_h (sum_j a_j e_j) + bv_h, then
    out_proj; with S = 0 the attended vector is zero, the output ``out_proj.bias``."""

    def __init__(self, dim: int, heads: int):
        super().__init__()
        self.dim, self.heads = dim, heads
        self.in_proj_weight = nn.Parameter(torch.empty(3 * dim, dim))
        self.in_proj_bias = nn.Parameter(torch.zeros(3 * dim))
        self.out_proj = nn.Linear(dim, dim)

    def forward(self, q_in: torch.Tensor, ent: torch.Tensor) -> torch.Tensor:
        """q_in (N, E), ent (N, S, E) -> (N, E)."""
        n, s, e = ent.shape
        if s == 0:
            return self.out_proj(q_in.new_zeros(n, e))
        h, dh = self.heads, e // self.heads
        wq, wk, wv = self.in_proj_weight.chunk(3)
        bq, _bk, bv = self.in_proj_bias.chunk(3)
        q = F.linear(q_in, wq, bq).view(n, h, dh)
        u = torch.einsum("nhd,hde->nhe", q, wk.view(h, dh, e)) * (1.0 / math.sqrt(dh))
        a = torch.softmax(torch.bmm(u, ent.transpose(1, 2)), dim=-1)  # (N, H, S)
        ebar = torch.bmm(a, ent)  # (N, H, E)
        o = torch.einsum("nhe,hde->nhd", ebar, wv.view(h, dh, e)).reshape(n, e) + bv
        return self.out_proj(o)


class Encoder(nn.Module):
    """SMAPPO's observation encoder (policy/src/encoder.rs)."""

    def __init__(self, d: int, heads: int, out_dim: int):
        super().__init__()
        self.d, self.out_dim = d, out_dim
        self.self_enc = nn.Linear(SELF_DIM, d)
        self.machines_enc = nn.Linear(MACHINE_DIM, d)
        self.storages_enc = nn.Linear(STORAGE_DIM, d)
        self.peers_enc = nn.Linear(PEER_DIM, d)
        self.att_machines = Attention(d, heads)
        self.att_storages = Attention(d, heads)
        self.att_peers = Attention(d, heads)
        self.fc = nn.Linear(4 * d, out_dim)
        self.ln = nn.LayerNorm(out_dim, eps=LN_EPS)

    def forward(self, obs: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """Rows (N, ...) -> (N, out_dim)."""
        e_self = F.relu(self.self_enc(obs["self"]))
        parts = [e_self]
        for g in GROUPS:
            ent = F.relu(getattr(self, f"{g}_enc")(obs[g]))
            parts.append(getattr(self, f"att_{g}")(e_self, ent))
        return self.ln(torch.tanh(self.fc(torch.cat(parts, -1))))


class MlpBase(nn.Module):
    """MAPPO's MLP base (policy/src/mlp_base.rs): LayerNorm on the input, then [Linear ->
    ReLU -> LayerNorm] x 2."""

    def __init__(self, d_in: int, hidden: int):
        super().__init__()
        self.feature_norm = nn.LayerNorm(d_in, eps=LN_EPS)
        self.fc1 = nn.Linear(d_in, hidden)
        self.fc2 = nn.Linear(hidden, hidden)
        self.ln1 = nn.LayerNorm(hidden, eps=LN_EPS)
        self.ln2 = nn.LayerNorm(hidden, eps=LN_EPS)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.ln1(F.relu(self.fc1(self.feature_norm(x))))
        return self.ln2(F.relu(self.fc2(x)))


def _orthogonal(lin: nn.Linear, gain: float) -> None:
    nn.init.orthogonal_(lin.weight, gain)
    nn.init.zeros_(lin.bias)


def _init_attention(att: Attention) -> None:
    nn.init.xavier_uniform_(att.in_proj_weight)
    nn.init.zeros_(att.in_proj_bias)
    a = 1.0 / math.sqrt(att.dim)
    nn.init.uniform_(att.out_proj.weight, -a, a)
    nn.init.zeros_(att.out_proj.bias)


def _init_encoder(enc: Encoder) -> None:
    for g in ("self",) + GROUPS:
        _orthogonal(getattr(enc, f"{g}_enc"), math.sqrt(2.0))
    for g in GROUPS:
        _init_attention(getattr(enc, f"att_{g}"))
    _orthogonal(enc.fc, 5.0 / 3.0)


def _init_mlp(m: MlpBase) -> None:
    _orthogonal(m.fc1, math.sqrt(2.0))
    _orthogonal(m.fc2, math.sqrt(2.0))


def _init_layernorms(module: nn.Module) -> None:
    for m in module.modules():
        if isinstance(m, nn.LayerNorm):
            nn.init.ones_(m.weight)
            nn.init.zeros_(m.bias)


class _Recurrent(nn.Module):
    """GRU -> LayerNorm -> Linear (policy/src/head.rs), stepped so that a mask can zero a
    row's state at any step (0.0 = an episode starts at this step)."""

    def _head_init(self, hidden: int, d_out: int, out_name: str) -> None:
        self.gru = nn.GRU(hidden, hidden)
        self.gru_ln = nn.LayerNorm(hidden, eps=LN_EPS)
        setattr(self, out_name, nn.Linear(hidden, d_out))
        self._out_name = out_name

    def _gru_step(self, x: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
        """One step of ``self.gru`` (its weights, PyTorch's gate order r, z, n) written out:
        ``aten::gru`` has no vmap batching rule, and torchrl 0.11's GAE (BenchMARL's MAPPO)
        runs the critic under vmap. Same arithmetic as ``nn.GRU`` and ``policy/src/head.rs``."""
        g = self.gru
        gi = F.linear(x, g.weight_ih_l0, g.bias_ih_l0)
        gh = F.linear(h, g.weight_hh_l0, g.bias_hh_l0)
        i_r, i_z, i_n = gi.chunk(3, dim=-1)
        h_r, h_z, h_n = gh.chunk(3, dim=-1)
        r = torch.sigmoid(i_r + h_r)
        z = torch.sigmoid(i_z + h_z)
        n = torch.tanh(i_n + r * h_n)
        return (1.0 - z) * n + z * h

    def _head(self, feat: torch.Tensor, h0: torch.Tensor | None, masks: torch.Tensor | None):
        """feat (T, B, H) -> outputs (T, B, d_out), last state (B, H)."""
        t, b, hd = feat.shape
        h = feat.new_zeros(b, hd) if h0 is None else torch.as_tensor(h0, dtype=feat.dtype, device=feat.device)
        if masks is not None:
            masks = torch.as_tensor(masks, dtype=feat.dtype, device=feat.device).reshape(t, b)
        outs = []
        for s in range(t):
            if masks is not None:
                h = h * masks[s].unsqueeze(-1)
            h = self._gru_step(feat[s], h)
            outs.append(h)
        hs = torch.stack(outs)
        return getattr(self, self._out_name)(self.gru_ln(hs)), h


class Actor(_Recurrent):
    """The policy network of a ``tending-policy`` checkpoint (``policy::Actor``).

    ``Actor.load(path)`` / ``actor.save(path)`` read and write checkpoints that ``tending
    eval``, ``tending fleet --policy`` and robot_node load; ``state_dict()`` keys are the
    checkpoint's tensor names."""

    def __init__(self, arch: Mapping | None = None, training: Any = None):
        super().__init__()
        self.arch = dict(arch_config() if arch is None else arch)
        self.arch.setdefault("actions", "moves")
        self.arch.setdefault("max_robots", None)
        check_arch(self.arch)
        #: free-form training metadata, saved with the checkpoint (`training` in its JSON)
        self.training = training
        a = self.arch
        if a["kind"] == "smappo":
            self.encoder = Encoder(a["d_model"], a["heads"], a["hidden"])
        else:
            self.base = MlpBase(flat_dim(a["flat"]), a["hidden"])
        self._head_init(a["hidden"], a["n_actions"], "action_out")
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """MAPPO's initialisation as the Rust `Actor::new` draws it (orthogonal weights
        with the Rust gains, zero biases, LayerNorms at 1 and 0; a different random
        stream)."""
        if self.arch["kind"] == "smappo":
            _init_encoder(self.encoder)
        else:
            _init_mlp(self.base)
        for w in (self.gru.weight_ih_l0, self.gru.weight_hh_l0):
            nn.init.orthogonal_(w, 1.0)
        for b in (self.gru.bias_ih_l0, self.gru.bias_hh_l0):
            nn.init.zeros_(b)
        _orthogonal(self.action_out, 0.01)
        _init_layernorms(self)

    @property
    def hidden(self) -> int:
        return self.arch["hidden"]

    def initial_state(self, *batch: int) -> torch.Tensor:
        """Zero GRU states, shape (*batch, hidden)."""
        return torch.zeros(*batch, self.hidden, device=self.action_out.weight.device)

    def features(self, obs: Mapping) -> torch.Tensor:
        """The GRU's input for rows of any leading shape: (..., hidden)."""
        w = self.action_out.weight
        o = as_obs(obs, w.device, w.dtype)
        lead = o["self"].shape[:-1]
        o = {k: v.reshape(math.prod(lead), *v.shape[len(lead) :]) for k, v in o.items()}
        if self.arch["kind"] == "smappo":
            f = self.encoder(o)
        else:
            f = self.base(flatten_obs(o, self.arch["flat"]))
        return f.reshape(*lead, f.shape[-1])

    def forward(self, obs: Mapping, h: torch.Tensor | None = None, masks=None):
        """One step for rows of shape (B,): logits (B, n_actions) and the next state (B,
        hidden). ``h`` None = zero (a new episode); ``masks`` (B,) multiplies ``h`` first."""
        logits, h = self.forward_seq({k: v[None] for k, v in as_obs(obs, dtype=None).items()}, h, masks)
        return logits[0], h

    def forward_seq(self, obs: Mapping, h0: torch.Tensor | None = None, masks=None):
        """T steps of B rows, observations of shape (T, B, ...): logits (T, B, n_actions)
        and the state after the last step (B, hidden). ``masks`` (T, B): 0.0 zeroes a row's
        state before that step (an episode starts there), as the Rust trainer's chunks."""
        feat = self.features(obs)
        return self._head(feat, h0, masks)

    @torch.no_grad()
    def act(self, obs: Mapping, h: torch.Tensor | None = None, deterministic: bool = True):
        """Actions (B,) int64 (argmax, lowest index on ties, as the Rust; or sampled) and
        the next state."""
        logits, h = self.forward(obs, h)
        if deterministic:
            return logits.argmax(-1), h
        return torch.distributions.Categorical(logits=logits).sample(), h

    # -------------------------------------------------------------------- checkpoints

    def meta(self) -> dict:
        """The checkpoint's JSON metadata (policy/src/checkpoint.rs `CheckpointMeta`)."""
        return {
            "format_version": FORMAT_VERSION,
            "model_kind": self.arch["kind"],
            "arch": dict(self.arch),
            "obs_layout": dict(OBS_LAYOUT),
            "training": self.training,
        }

    def save(self, path: str | os.PathLike, training: Any = ...) -> None:
        """Write a ``tending-policy`` checkpoint (``training``: replaces the free-form
        training metadata; by default the loaded or given one is kept)."""
        meta = self.meta()
        if training is not ...:
            meta["training"] = training
        write_safetensors(
            path,
            self.state_dict(),
            {"format": POLICY_FORMAT, "tending": json.dumps(meta, separators=(",", ":"))},
        )

    @classmethod
    def load(cls, path: str | os.PathLike, expect_kind: str | None = None) -> "Actor":
        """A ``tending-policy`` checkpoint's actor (or a ``tending-trainer-state``'s),
        checked as the Rust loader checks it: format, version, observation layout,
        architecture, every tensor present with its shape, none extra, all finite."""
        tensors, md = read_safetensors(path)
        fmt = md.get("format", "<absent>")
        if fmt == TRAINER_FORMAT:
            meta = _parse_meta(md, TRAINER_FORMAT)
            actor = cls(meta["actor_arch"], training=meta.get("extra"))
            _load_params(actor, tensors, "actor.param.", strict=False)
            return actor
        meta = _parse_meta(md, POLICY_FORMAT)
        if expect_kind is not None and meta.get("model_kind") != expect_kind:
            raise CheckpointError(f"checkpoint holds a {meta.get('model_kind')} model, expected {expect_kind}")
        if meta.get("arch", {}).get("kind") != meta.get("model_kind"):
            raise CheckpointError("checkpoint architecture is not usable: model_kind disagrees with arch.kind")
        if meta.get("obs_layout") != OBS_LAYOUT:
            raise CheckpointError(f"observation layout {meta.get('obs_layout')} differs from {OBS_LAYOUT}")
        actor = cls(meta["arch"], training=meta.get("training"))
        _load_params(actor, tensors, "", strict=True)
        return actor


class Critic(_Recurrent):
    """The centralised critic of a trainer state (``policy::Critic``): one value per robot.

    Rows are grouped per environment: observations (..., n, ...) with the n robots of one
    environment on the second-to-last batch axis."""

    def __init__(self, arch: Mapping | None = None):
        super().__init__()
        self.arch = dict(arch_config() if arch is None else arch)
        self.arch.setdefault("actions", "moves")
        self.arch.setdefault("max_robots", None)
        check_arch(self.arch)
        a = self.arch
        d, h = a["d_model"], a["hidden"]
        if a["kind"] == "smappo":
            self.encoder = Encoder(d, a["heads"], d)
            self.global_query = nn.Parameter(torch.empty(d))
            self.global_att = Attention(d, a["heads"])
            self.fc = nn.Linear(2 * d, h)
            self.ln = nn.LayerNorm(h, eps=LN_EPS)
        else:
            self.base = MlpBase(flat_dim(a["flat"]) * (1 + a["max_robots"]), h)
        self._head_init(h, 1, "value_out")
        self.reset_parameters()

    def reset_parameters(self) -> None:
        """MAPPO's initialisation as the Rust `Critic::new` draws it."""
        if self.arch["kind"] == "smappo":
            _init_encoder(self.encoder)
            nn.init.uniform_(self.global_query, -1.0, 1.0)
            _init_attention(self.global_att)
            _orthogonal(self.fc, 5.0 / 3.0)
        else:
            _init_mlp(self.base)
        for w in (self.gru.weight_ih_l0, self.gru.weight_hh_l0):
            nn.init.orthogonal_(w, 1.0)
        for b in (self.gru.bias_ih_l0, self.gru.bias_hh_l0):
            nn.init.zeros_(b)
        _orthogonal(self.value_out, 1.0)
        _init_layernorms(self)

    def features(self, obs: Mapping) -> torch.Tensor:
        """(..., E, n, ...) observations -> (..., E, n, hidden)."""
        w = self.value_out.weight
        o = as_obs(obs, w.device, w.dtype)
        lead = o["self"].shape[:-1]
        n = lead[-1]
        o = {k: v.reshape(math.prod(lead), *v.shape[len(lead) :]) for k, v in o.items()}
        rows = o["self"].shape[0]
        if self.arch["kind"] == "smappo":
            enc = self.encoder(o)  # (rows, d)
            d = enc.shape[-1]
            ent = enc.reshape(rows // n, n, d)
            q = self.global_query.expand(rows // n, d)
            g = self.global_att(q, ent)  # (envs, d)
            cat = torch.cat([g.unsqueeze(1).expand(-1, n, -1), ent], -1).reshape(rows, 2 * d)
            f = self.ln(torch.tanh(self.fc(cat)))
        else:
            if n > self.arch["max_robots"]:
                raise ValueError(f"{n} robots, the checkpoint's critic holds at most {self.arch['max_robots']}")
            x = flatten_obs(o, self.arch["flat"])  # (rows, fd)
            fd = x.shape[-1]
            shared = x.reshape(rows // n, 1, n * fd).expand(-1, n, -1).reshape(rows, n * fd)
            x = torch.cat([x, shared, x.new_zeros(rows, (self.arch["max_robots"] - n) * fd)], -1)
            f = self.base(x)
        return f.reshape(*lead, f.shape[-1])

    def forward_seq(self, obs: Mapping, h0: torch.Tensor | None = None, masks=None):
        """Observations (T, E, n, ...): values (T, E, n) and the last state (E, n, hidden)."""
        feat = self.features(obs)
        t, e, n, hd = feat.shape
        if h0 is not None:
            h0 = torch.as_tensor(h0, dtype=feat.dtype, device=feat.device).reshape(e * n, hd)
        if masks is not None:
            masks = torch.as_tensor(masks, dtype=feat.dtype, device=feat.device).reshape(t, e * n)
        v, h = self._head(feat.reshape(t, e * n, hd), h0, masks)
        return v.reshape(t, e, n), h.reshape(e, n, hd)

    def forward(self, obs: Mapping, h: torch.Tensor | None = None, masks=None):
        """One step, observations (E, n, ...): values (E, n) and the next state."""
        v, h = self.forward_seq({k: v[None] for k, v in as_obs(obs, dtype=None).items()}, h, masks)
        return v[0], h

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Critic":
        """The critic of a ``tending-trainer-state`` file (policy checkpoints hold none)."""
        tensors, md = read_safetensors(path)
        meta = _parse_meta(md, TRAINER_FORMAT)
        critic = cls(meta["critic_arch"])
        _load_params(critic, tensors, "critic.param.", strict=False)
        return critic


def save_trainer_state(
    path: str | os.PathLike, actor: Actor, critic: Critic, extra: Any = None, adam: Mapping | None = None
) -> None:
    """A ``tending-trainer-state`` file (``tending train --resume`` reads it) with zero Adam
    moments and step count 0 unless ``adam`` gives them (``{"actor_t": .., "critic_t": ..,
    "config": {...}}``): torch's optimiser state is not carried over."""
    adam = dict(adam or {})
    cfg = adam.get("config") or {"lr": 5e-4, "beta1": 0.9, "beta2": 0.999, "eps": 1e-5}
    meta = {
        "format_version": FORMAT_VERSION,
        "actor_arch": dict(actor.arch),
        "critic_arch": dict(critic.arch),
        "actor_adam": cfg,
        "critic_adam": cfg,
        "actor_adam_t": int(adam.get("actor_t", 0)),
        "critic_adam_t": int(adam.get("critic_t", 0)),
        "extra": extra,
    }
    t = {}
    for pre, net in (("actor", actor), ("critic", critic)):
        for k, v in net.state_dict().items():
            t[f"{pre}.param.{k}"] = v
            t[f"{pre}.adam_m.{k}"] = torch.zeros_like(v)
            t[f"{pre}.adam_v.{k}"] = torch.zeros_like(v)
    write_safetensors(path, t, {"format": TRAINER_FORMAT, "tending": json.dumps(meta, separators=(",", ":"))})


def load_policy(path: str | os.PathLike) -> tuple[Actor, dict]:
    """``(actor, metadata)`` of a policy checkpoint, as ``policy::checkpoint::load_policy``."""
    actor = Actor.load(path)
    return actor, actor.meta()


def _parse_meta(md: Mapping[str, str], fmt: str) -> dict:
    found = md.get("format", "<absent>")
    if found != fmt:
        raise CheckpointError(f"checkpoint metadata: format is `{found}`, expected `{fmt}`")
    if "tending" not in md:
        raise CheckpointError("checkpoint metadata: no `tending` entry")
    try:
        meta = json.loads(md["tending"])
    except ValueError as e:
        raise CheckpointError(f"checkpoint metadata: invalid JSON: {e}") from None
    v = meta.get("format_version", 0)
    if v != FORMAT_VERSION:
        raise CheckpointError(f"checkpoint format version {v} is not supported (this reads {FORMAT_VERSION})")
    return meta


def _load_params(net: nn.Module, tensors: Mapping[str, torch.Tensor], prefix: str, strict: bool) -> None:
    """Copy ``prefix<name>`` for every parameter; with ``strict`` no other tensor may exist
    (a trainer state also holds the other network and the Adam moments)."""
    sd = net.state_dict()
    new = {}
    for name, p in sd.items():
        key = prefix + name
        if key not in tensors:
            raise CheckpointError(f"checkpoint is missing tensor `{key}`")
        t = tensors[key]
        if tuple(t.shape) != tuple(p.shape):
            raise CheckpointError(f"tensor `{key}` has shape {list(t.shape)}, expected {list(p.shape)}")
        if not torch.isfinite(t).all():
            i = int((~torch.isfinite(t)).flatten().nonzero()[0])
            raise CheckpointError(f"tensor `{key}` has a non-finite value ({t.flatten()[i].item()}) at index {i}")
        new[name] = t
    if strict:
        extra = sorted(set(tensors) - {prefix + n for n in sd})
        if extra:
            raise CheckpointError(f"checkpoint has unexpected tensor `{extra[0]}` (not part of this architecture)")
    net.load_state_dict(new, strict=True)

