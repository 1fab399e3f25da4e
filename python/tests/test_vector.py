"""The batched API: N envs stepped in Rust in one call, equal to N single envs."""

import numpy as np
import pytest

import tending

GROUPS = ("self", "machines", "storages", "peers")


def test_vector_env_equals_single_envs_across_an_episode_boundary():
    E, seed = 3, 9
    v = tending.vector_env("6.4_2", n_envs=E, seed=seed)
    obs, _ = v.reset()
    assert obs["self"].shape == (E, 6, 3) and obs["peers"].shape == (E, 6, 5, 3)
    singles = [tending.parallel_env("6.4_2") for _ in range(E)]
    # Env e of the vector is a single env whose episodes use episode_seed(seed, e, k).
    sobs = [s._sim for s in singles]
    for e, s in enumerate(sobs):
        s.reset(tending.episode_seed(seed, e, 0))
    rng = np.random.default_rng(1)
    final_seen = False
    for t in range(260):
        acts = rng.integers(0, 5, size=(E, 6))
        obs, rew, term, trunc, infos = v.step(acts)
        assert rew.shape == (E, 6) and rew.dtype == np.float32 and not term.any()
        for e, s in enumerate(sobs):
            s.step(acts[e])
            np.testing.assert_array_equal(rew[e], s.rewards())
            if s.is_done():
                assert trunc[e].all()
                final = infos["final_obs"]
                for g, a in zip(GROUPS, s.observe()):
                    np.testing.assert_array_equal(final[g][e], a)
                assert infos["final_metrics"][e] == s.metrics()
                s.reset(tending.episode_seed(seed, e, 1))
                final_seen = True
            else:
                assert not trunc[e].any()
            for g, a in zip(GROUPS, s.observe()):
                np.testing.assert_array_equal(obs[g][e], a)
    assert final_seen


def test_vector_greedy_matches_the_single_env_greedy():
    v = tending.vector_env("14.10_4", n_envs=4, seed=0)
    obs, _ = v.reset()
    s = tending.parallel_env("14.10_4", seed=0)
    sobs, _ = s.reset()
    ga = v.greedy_actions(obs)
    assert ga.shape == (4, 14)
    want = s.greedy_actions(sobs)
    assert [int(x) for x in ga[0]] == [want[a] for a in s.agents]
    total = 0
    for _ in range(200):
        obs, rew, _, trunc, infos = v.step(v.greedy_actions(obs))
    assert trunc.all()
    delivered = [m["parts_delivered"] for m in infos["final_metrics"]]
    assert min(delivered) > 0


def test_vector_accepts_any_integer_dtype_and_flat_actions():
    v = tending.vector_env("2.2_2", n_envs=2, seed=0)
    v.reset()
    for dt in (np.uint8, np.int32, np.int64):
        v.step(np.ones((2, 2), dtype=dt))
    v.step(np.zeros(4, dtype=np.int64))
    v.step([[0, 1], [2, 3]])


def test_vector_reset_with_seed_is_deterministic():
    v = tending.vector_env("6.4_2", n_envs=2, seed=0)
    a, _ = v.reset(seed=42)
    v.step(np.full((2, 6), 2))
    b, _ = v.reset(seed=42)
    for g in GROUPS:
        np.testing.assert_array_equal(a[g], b[g])
    c, _ = v.reset(seed=43)
    assert not np.array_equal(a["self"], c["self"])
