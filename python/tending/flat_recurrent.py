"""The networks of :mod:`tending.smappo_torch` on the flat per-robot observation of
:class:`tending.torchrl.TendingEnv`, stepped the way TorchRL and BenchMARL step recurrent
models: what :mod:`tending.benchmarl_rust` runs, kept apart so that it needs torch alone
(and is tested without BenchMARL).

- :func:`split_flat`: the flat observation (self, machines, storages, peers concatenated)
  back into the four groups, the inverse of ``smappo_torch.flatten_obs`` at the setup's
  counts (no padding).
- :func:`recurrent_forward`: one collection step (a GRU state given: zeroed where
  ``is_init``) or a training pass over (B, T) sequences (no state: zero at the start,
  reset where ``is_init``).
"""

from __future__ import annotations

from typing import Mapping

import torch

from . import smappo_torch as st


def setup_counts(setup: str) -> tuple[int, int, int]:
    """(robots, machines, storages) of ``N.M_K`` (or ``tending/N.M_K``)."""
    name = str(setup).split("/")[-1]
    try:
        n, rest = name.split(".", 1)
        m, k = (int(v) for v in rest.split("_"))
        return int(n), m, k
    except ValueError:
        raise ValueError(f"setup {setup!r}: expected N.M_K, e.g. 6.4_2") from None


def split_flat(x: torch.Tensor, machines: int, storages: int, peers: int) -> dict[str, torch.Tensor]:
    """(..., 3 + 3M + 2K + 3P) -> {"self": (..., 3), "machines": (..., M, 3), "storages":
    (..., K, 2), "peers": (..., P, 3)}."""
    want = st.SELF_DIM + machines * st.MACHINE_DIM + storages * st.STORAGE_DIM + peers * st.PEER_DIM
    if x.shape[-1] != want:
        raise ValueError(f"observation has {x.shape[-1]} features, (machines, storages, peers) = "
                         f"{(machines, storages, peers)} give {want}")
    lead = x.shape[:-1]
    out, off = {"self": x[..., : st.SELF_DIM]}, st.SELF_DIM
    for g, c, d in zip(st.GROUPS, (machines, storages, peers), st.GROUP_DIMS):
        out[g] = x[..., off : off + c * d].reshape(*lead, c, d)
        off += c * d
    return out


def _features(net, obs: Mapping[str, torch.Tensor], robots_apart: bool) -> torch.Tensor:
    """(..., N) rows -> (..., N, hidden). A Critic reads the last batch axis as the robots
    of one environment (centralised); ``robots_apart``: each robot an environment alone."""
    if isinstance(net, st.Critic) and robots_apart:
        return net.features({g: v.unsqueeze(-2 if g == "self" else -3) for g, v in obs.items()})[..., 0, :]
    return net.features(obs)


def recurrent_forward(net, obs: Mapping[str, torch.Tensor], h0: torch.Tensor | None, is_init: torch.Tensor,
                      robots_apart: bool = False):
    """``net`` (an Actor or a Critic of :mod:`tending.smappo_torch`) on observation groups
    with leading shape (..., N), N the robots of an environment.

    - ``h0`` given (collection): one step. Leading shape (E, N) or (N,); ``h0`` (E, N,
      hidden) or (N, hidden); ``is_init`` (E, 1) or (1,), True where an episode starts (the
      state is zeroed first). Returns outputs (E, N, out) and the next state.
    - ``h0`` None (training): leading shape (B, T, N), ``is_init`` (B, T, 1); every
      sequence starts from a zero state, reset where ``is_init``. Returns outputs (B, T, N,
      out) and the last state (B, N, hidden).

    Outputs: logits for an Actor, values (out = 1) for a Critic."""
    feat = _features(net, obs, robots_apart)
    hd = feat.shape[-1]
    keep = 1.0 - is_init.to(feat.dtype)
    if h0 is not None:
        lead = feat.shape[:-1]
        h = h0.to(feat.dtype) * keep.unsqueeze(-1)
        y, h = net._head(feat.reshape(1, -1, hd), h.reshape(-1, hd), None)
        return y[0].reshape(*lead, y.shape[-1]), h.reshape(*lead, hd)
    b, t, n = feat.shape[:3]
    masks = keep.expand(b, t, n).permute(1, 0, 2).reshape(t, b * n)
    y, h = net._head(feat.permute(1, 0, 2, 3).reshape(t, b * n, hd), None, masks)
    return y.reshape(t, b, n, -1).transpose(0, 1), h.reshape(b, n, hd)
