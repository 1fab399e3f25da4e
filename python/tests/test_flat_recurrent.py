"""tending.flat_recurrent (what tending.benchmarl_rust runs; torch alone): the flat
observation splits back into its groups, and the collection steps and the training pass
give the logits and values of tending.smappo_torch's own sequence forward, GRU resets
included. torch is an optional extra: these tests skip, saying so, when it is absent."""

import numpy as np
import pytest

torch = pytest.importorskip(
    "torch", reason="torch is not installed (an optional extra): tending.flat_recurrent needs it")
from tending import smappo_torch as st  # noqa: E402
from tending.flat_recurrent import recurrent_forward, setup_counts, split_flat  # noqa: E402

import tending  # noqa: E402


def trajectory(setup, envs, steps, seed=0):
    """(T, E, N, ...) Dict observations of random-action episodes and their flat layout."""
    v = tending.vector_env(setup, n_envs=envs, seed=seed)
    obs, _ = v.reset()
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        out.append({g: torch.from_numpy(a.copy()) for g, a in obs.items()})
        obs, *_ = v.step(rng.integers(0, 5, (envs, v.n_robots)))
    dict_obs = {g: torch.stack([o[g] for o in out]) for g in out[0]}
    lead = dict_obs["self"].shape[:-1]
    flat = torch.cat([dict_obs["self"]] + [dict_obs[g].reshape(*lead, -1) for g in st.GROUPS], -1)
    return dict_obs, flat


def perturbed(net, seed):
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in net.parameters():
            p.add_(torch.rand(p.shape, generator=g) * 0.4 - 0.2)
    return net


@pytest.mark.parametrize("setup", ["6.4_2", "2.2_2"])
def test_split_flat_inverts_the_flat_layout(setup):
    n, m, k = setup_counts(setup)
    obs, flat = trajectory(setup, 2, 3)
    back = split_flat(flat, m, k, n - 1)
    for g in ("self",) + st.GROUPS:
        assert torch.equal(back[g], obs[g]), g
    with pytest.raises(ValueError, match="features"):
        split_flat(flat, m + 1, k, n - 1)


@pytest.mark.parametrize("which", ["actor", "critic", "critic apart"])
def test_collection_steps_and_training_pass_equal_forward_seq(which):
    torch.manual_seed(0)
    n, m, k = setup_counts("6.4_2")
    obs, flat = trajectory("6.4_2", 3, 12)  # (T, E, N, ...)
    t, e = flat.shape[:2]
    is_init = torch.zeros(t, e, 1, dtype=torch.bool)
    is_init[0] = True
    is_init[5, 1] = True  # env 1's episode restarts at step 5
    net = perturbed(st.Actor() if which == "actor" else st.Critic(), 1)
    apart = which == "critic apart"
    masks = (~is_init).float().expand(t, e, n)
    with torch.no_grad():
        if which == "actor":  # rows = every robot of every env
            ref, _ = net.forward_seq({g: v.reshape(t, e * n, *v.shape[3:]) for g, v in obs.items()},
                                     None, masks.reshape(t, e * n))
            ref = ref.reshape(t, e, n, -1)
        elif not apart:
            ref, _ = net.forward_seq(obs, None, masks)
            ref = ref.unsqueeze(-1)
        else:  # every robot an environment of its own
            o = {g: v.unsqueeze(-2 if g == "self" else -3) for g, v in obs.items()}
            ref, _ = net.forward_seq({g: v.reshape(t, e * n, *v.shape[3:]) for g, v in o.items()},
                                     None, masks.reshape(t, e * n, 1))
            ref = ref.reshape(t, e, n, 1)
        groups = split_flat(flat, m, k, n - 1)
        # collection: one step at a time, the state carried, zeroed at is_init
        h = torch.zeros(e, n, net.arch["hidden"])
        steps = []
        for s in range(t):
            y, h = recurrent_forward(net, {g: v[s] for g, v in groups.items()}, h, is_init[s], robots_apart=apart)
            steps.append(y)
        assert torch.allclose(torch.stack(steps), ref, atol=1e-5)
        # one env without its batch dimension (BenchMARL's evaluation): the same
        y0, _ = recurrent_forward(net, {g: v[0, 0] for g, v in groups.items()}, torch.zeros(n, net.arch["hidden"]),
                                  is_init[0, 0], robots_apart=apart)
        assert torch.allclose(y0, ref[0, 0], atol=1e-5)
        # training: (B, T) sequences from a zero state, reset at is_init
        y, _ = recurrent_forward(net, {g: v.transpose(0, 1) for g, v in groups.items()}, None,
                                 is_init.transpose(0, 1), robots_apart=apart)
        assert torch.allclose(y.transpose(0, 1), ref, atol=1e-5)
