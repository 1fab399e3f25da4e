"""Agent-steps/s through the Python API next to the Rust figure, in one run.

One agent-step = one robot's share of an environment step including every robot's
observation and reward (the definition of `tending bench-sim`). Random actions are drawn
before timing. Rows:

- rust VecEnv: `tending bench-sim` (run here, same machine, same minute);
- python Sim: `tending._native.Sim` step + observe (numpy arrays, no PettingZoo dicts);
- python ParallelEnv: `tending.parallel_env`, the PettingZoo API with per-agent dicts of
  observations, rewards, terminations, truncations and infos;
- python vector: `tending.vector_env`, N envs per call, numpy in and out.

Usage: python bench/python/bench.py --tending target/release/tending --out docs/bench/python.md
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import tempfile
import time

import numpy as np

import tending
from tending import _native

SETUPS = ["6.4_2", "14.10_4", "100.16_2"]


def robots(setup):
    return int(setup.split(".")[0])


def timed(step, secs):
    """Calls of `step` per second over about `secs` seconds (after a short warm-up)."""
    for _ in range(5):
        step()
    t0 = time.perf_counter()
    n = 0
    while time.perf_counter() - t0 < secs:
        for _ in range(10):
            step()
        n += 10
    return n / (time.perf_counter() - t0)


def bench_sim(setup, secs):
    s = _native.Sim(setup, 1)
    n = robots(setup)
    pool = np.random.default_rng(7).integers(0, 5, size=(64, n), dtype=np.uint8)
    it = [0]

    def step():
        if s.is_done():
            s.reset(it[0])
        s.step(pool[it[0] % 64])
        s.observe()
        s.rewards()
        it[0] += 1

    return timed(step, secs) * n


def bench_parallel(setup, secs):
    env = tending.parallel_env(setup, seed=1)
    env.reset()
    n = robots(setup)
    rng = np.random.default_rng(7)
    pool = [{f"robot_{i}": int(a) for i, a in enumerate(row)} for row in rng.integers(0, 5, size=(64, n))]
    it = [0]

    def step():
        if not env.agents:
            env.reset()
        env.step(pool[it[0] % 64])
        it[0] += 1

    return timed(step, secs) * n


def bench_vector(setup, n_envs, secs):
    v = tending.vector_env(setup, n_envs=n_envs, seed=1)
    v.reset()
    n = robots(setup)
    pool = np.random.default_rng(7).integers(0, 5, size=(64, n_envs, n), dtype=np.uint8)
    it = [0]

    def step():
        v.step(pool[it[0] % 64])
        it[0] += 1

    return timed(step, secs) * n * n_envs


def rust_figures(tending_bin, secs):
    """{(setup, envs): agent-steps/s} from `tending bench-sim`."""
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "sim.md")
        subprocess.run([tending_bin, "bench-sim", "--seconds", str(secs), "--out", out],
                       check=True, capture_output=True, text=True)
        text = open(out).read()
    figs = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 3 and cells[0] in SETUPS and cells[1].isdigit():
            figs[(cells[0], int(cells[1]))] = float(cells[2])
    return figs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tending", default="target/release/tending")
    ap.add_argument("--seconds", type=float, default=1.5)
    ap.add_argument("--envs", type=int, default=32)
    ap.add_argument("--out", default="docs/bench/python.md")
    a = ap.parse_args()

    rust = rust_figures(a.tending, a.seconds)
    rows = []
    for setup in SETUPS:
        r1, rn = rust.get((setup, 1)), rust.get((setup, a.envs))
        sim = bench_sim(setup, a.seconds)
        par = bench_parallel(setup, a.seconds)
        vec1 = bench_vector(setup, 1, a.seconds)
        vecn = bench_vector(setup, a.envs, a.seconds)
        rows.append((setup, r1, sim, par, vec1, rn, vecn))
        print(f"{setup:>9}: rust 1 env {r1:,.0f} | Sim {sim:,.0f} | ParallelEnv {par:,.0f} | "
              f"vector 1 {vec1:,.0f} | rust {a.envs} envs {rn:,.0f} | vector {a.envs} {vecn:,.0f}",
              flush=True)

    def f(x):
        return "n/a" if x is None else f"{x:,.0f}"

    def pct(x, ref):
        return "" if not ref or x is None else f" ({100 * x / ref:.0f}%)"

    md = [
        "# The Python package's throughput (`bench/python/bench.py`)",
        "",
        f"Machine: {os.cpu_count()} cores, shared with other work while measured; "
        f"{tending.num_threads()} rayon threads; Python {platform.python_version()}, "
        f"numpy {np.__version__}. Random actions drawn before timing; every step includes "
        "all robots' observations and rewards (the definition of `tending bench-sim`, whose "
        f"figures were measured in the same run). {a.seconds} s per cell. Agent-steps/s; in "
        "brackets, the share of the Rust figure with the same number of envs.",
        "",
        f"| setup | Rust, 1 env | `_native.Sim` | PettingZoo `parallel_env` | `vector_env`, 1 env | Rust, {a.envs} envs | `vector_env`, {a.envs} envs |",
        "|---|---|---|---|---|---|---|",
    ]
    for setup, r1, sim, par, vec1, rn, vecn in rows:
        md.append(f"| {setup} | {f(r1)} | {f(sim)}{pct(sim, r1)} | {f(par)}{pct(par, r1)} | "
                  f"{f(vec1)}{pct(vec1, r1)} | {f(rn)} | {f(vecn)}{pct(vecn, rn)} |")
    md += [
        "",
        "- `_native.Sim`: one env, `step` + `observe` + `rewards` per step (fresh numpy arrays "
        "written by Rust).",
        "- `parallel_env`: the full PettingZoo step: an action dict in; dicts of per-agent "
        "observations (views into the batch arrays), rewards, terminations, truncations and "
        "infos out. Per-agent Python objects dominate its cost.",
        "- `vector_env`: N envs stepped one run of envs per thread (sim::fork, ADR 0033) with the GIL released, numpy arrays in and out, "
        "no per-agent Python objects.",
        "",
    ]
    os.makedirs(os.path.dirname(a.out) or ".", exist_ok=True)
    with open(a.out, "w") as fh:
        fh.write("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
