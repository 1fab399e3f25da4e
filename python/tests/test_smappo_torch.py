"""The torch networks of tending.smappo_torch are the Rust networks of crate `policy`.

The same observations (random ones at several entity counts, empty groups included, and a
trajectory of the simulator) go through both, several steps with a GRU state per robot
and an episode restart in the middle; the logits must agree within TOL (absolute). The
Rust side is policy/examples/logits.rs (built here with cargo), by both of its routes: the
deployment one (`Policy::logits`, one robot at a time, as robot_node) and the trainer's
(`Actor::forward_seq` over all steps and robots at once). Checkpoints: the bundled ones,
fresh ones written by Rust and loaded by torch, fresh ones written by torch and loaded by
Rust; critics through trainer-state files, both ways.

torch is an optional extra that CI does not install: these tests skip, saying so, when it
is absent. `python -m pytest python/tests/test_smappo_torch.py -s` prints the measured
differences.
"""

import copy
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip(
    "torch",
    reason="torch is not installed (an optional extra: pip install './python[torch]'): "
    "the torch/Rust equality test needs it",
)
st = pytest.importorskip("tending.smappo_torch")

ROOT = Path(__file__).resolve().parents[2]
# Absolute tolerance on logits and values: |torch - Rust| <= TOL, and each of the two within
# TOL of the same network evaluated in float64 by torch. Both compute in float32 with the
# same operations in different orders (GEMM blocking, the attention's sums, Rust's
# polynomial exp/tanh against libm's), and a trained network amplifies the rounding: on the
# bundled 5-move checkpoint at 14.10_4 counts each side is 2e-5 from float64, in opposite
# directions, so they differ by up to 4e-5; elsewhere by 4e-7 to 1e-5 (python/README.md).
# A transposed weight or swapped GRU gates move the logits by 1 or more, a LayerNorm eps of
# 1e-3 instead of 1e-5 by 7e-3.
TOL = 1e-4
PRETRAINED = ROOT / "policy" / "pretrained"
T = 8  # steps per case: the GRU state carries over 7 of them
MEASURED = []  # (what, max |diff|, max |logit|), printed at the end of the module


def logits_bin():
    """policy/examples/logits.rs: built (release; a no-op when up to date) where cargo is
    on PATH, else the one beside the binaries of TENDING_BIN_DIR (or target/release)."""
    cargo = shutil.which("cargo")
    if cargo is not None:
        subprocess.run(
            [cargo, "build", "--release", "--locked", "-q", "-p", "policy", "--example", "logits"],
            cwd=ROOT, check=True, timeout=1800,
        )
        target = Path(os.environ.get("CARGO_TARGET_DIR") or ROOT / "target")
        return str((ROOT / target).resolve() / "release" / "examples" / "logits")
    d = os.environ.get("TENDING_BIN_DIR") or str(ROOT / "target" / "release")
    b = os.path.join(d, "examples", "logits")
    if not os.path.isfile(b):
        pytest.fail(f"{b} is not built and cargo is not on PATH (cargo build --release -p policy --example logits)")
    return b


@pytest.fixture(scope="module")
def rust():
    b = logits_bin()

    def run(*args, cases=None):
        inp = None if cases is None else json.dumps({"cases": cases})
        out = subprocess.run([b, *map(str, args)], input=inp, capture_output=True, text=True, timeout=600)
        if out.returncode != 0:
            raise AssertionError(f"logits {' '.join(map(str, args))}: {out.stderr}")
        return json.loads(out.stdout) if out.stdout.strip() else None

    yield run
    if MEASURED:
        print("\nmax |torch - Rust| per case (torch and Rust each against float64; max |output|):")
        for what, d, e_t, e_r, m in MEASURED:
            print(f"  {what}: {d:.2e} ({e_t:.2e}, {e_r:.2e}; {m:.2f})")


def random_case(rng, m, k, p, rows, robots=0, reset_at=3):
    """T steps of observations in the `obs` crate's layout: positions in metres (a 10 m
    room, relative positions up to 10 m), 0/1 flags; mask 0 for row 0 at step `reset_at`
    (its episode restarts there)."""
    steps = []
    for t in range(T):
        own = np.concatenate([rng.uniform(-5, 5, (rows, 2)), rng.integers(0, 2, (rows, 1))], 1)
        mach = np.concatenate([rng.uniform(-10, 10, (rows, m, 2)), rng.integers(0, 2, (rows, m, 1))], 2)
        stor = rng.uniform(-10, 10, (rows, k, 2))
        peer = np.concatenate([rng.uniform(-10, 10, (rows, p, 2)), rng.integers(0, 2, (rows, p, 1))], 2)
        masks = np.ones(rows)
        if t == reset_at:
            masks[0] = 0.0
        steps.append((own, mach, stor, peer, masks))
    return make_case(m, k, p, rows, steps, robots)


def make_case(m, k, p, rows, steps, robots=0):
    f32 = lambda a: np.asarray(a, dtype=np.float32)
    return {
        "machines": m, "storages": k, "peers": p, "rows": rows, "robots": robots,
        "steps": [
            {"own": f32(o).ravel().tolist(), "machines": f32(a).ravel().tolist(),
             "storages": f32(b).ravel().tolist(), "peers": f32(c).ravel().tolist(),
             "masks": f32(mk).tolist()}
            for o, a, b, c, mk in steps
        ],
    }


def torch_inputs(case):
    """(T, B, ...) tensors of a case, and its masks (T, B)."""
    t, b = len(case["steps"]), case["rows"]
    dims = {"own": 3, "machines": 3, "storages": 2, "peers": 3}
    counts = {"own": None, "machines": case["machines"], "storages": case["storages"], "peers": case["peers"]}
    obs = {}
    for key, d in dims.items():
        a = np.array([s[key] for s in case["steps"]], dtype=np.float32)
        shape = (t, b, d) if counts[key] is None else (t, b, counts[key], d)
        obs["self" if key == "own" else key] = torch.from_numpy(a.reshape(shape))
    masks = torch.tensor([s["masks"] for s in case["steps"]], dtype=torch.float32)
    return obs, masks


def sim_case(setup="6.4_2", seed=5, steps=T):
    """A trajectory of the simulator under the greedy script (real observations)."""
    import tending

    env = tending.parallel_env(setup, seed=seed)
    obs, _ = env.reset(seed=seed)
    agents = list(env.agents)
    recs = []
    for _ in range(steps):
        g = lambda key: np.stack([obs[a][key] for a in agents])
        recs.append((g("self"), g("machines"), g("storages"), g("peers"), np.ones(len(agents))))
        obs, *_ = env.step(env.greedy_actions(obs))
    m, k, p = (recs[0][i].shape[1] for i in (1, 2, 3))
    return make_case(m, k, p, len(agents), recs)


# (machines, storages, peers, robots): the paper's 6.4_2 and 14.10_4, a lone robot (no
# peers), empty machine and storage groups, and a robot that sees nothing at all.
SHAPES = [(4, 2, 5, 6), (10, 4, 13, 14), (3, 2, 0, 1), (0, 2, 3, 4), (2, 0, 1, 2), (0, 0, 0, 1)]


def cases_for(actor, rng):
    out = []
    for m, k, p, b in SHAPES:
        f = actor.arch.get("flat")
        if f and (m > f["max_machines"] or k > f["max_storages"] or p > f["max_peers"]):
            continue
        out.append((f"{m}.{k}.{p} x{b}", random_case(rng, m, k, p, b)))
    return out


def compare_actor(rust, path, actor, label, sim=True):
    """Torch `actor` against the Rust loading `path` on every case; returns the max diff."""
    rng = np.random.default_rng(0)
    named = cases_for(actor, rng)
    if sim:
        named.append(("simulator 6.4_2", sim_case()))
    res = rust(path, cases=[c for _, c in named])
    assert res["meta"]["arch"]["kind"] == actor.arch["kind"]
    worst = 0.0
    exact = copy.deepcopy(actor).double()  # float64: how far each side is from the function
    with torch.no_grad():
        for (name, case), r in zip(named, res["cases"]):
            obs, masks = torch_inputs(case)
            ours, _ = actor.forward_seq(obs, None, masks)
            ref, _ = exact.forward_seq(obs, None, masks)
            # one step at a time, as a robot runs it
            h, steps = None, []
            for t in range(len(case["steps"])):
                lt, h = actor({k: v[t] for k, v in obs.items()}, h, masks[t])
                steps.append(lt)
            stepped = torch.stack(steps)
            for route in ("inference", "batched"):
                theirs = torch.tensor(r[route]).reshape(ours.shape)
                d = max((ours - theirs).abs().max().item(), (stepped - theirs).abs().max().item())
                e_t, e_r = ((x.double() - ref).abs().max().item() for x in (ours, theirs))
                MEASURED.append((f"{label}, {name}, Rust {route}", d, e_t, e_r, theirs.abs().max().item()))
                worst = max(worst, d)
                assert max(d, e_t, e_r) <= TOL, (label, name, route, d, e_t, e_r)
    return worst


@pytest.mark.parametrize("name", ["smappo_6.4_2", "smappo_moves_6.4_2", "mappo_6.4_2"])
def test_bundled_checkpoint_gives_the_rust_logits(rust, name, tmp_path):
    path = PRETRAINED / f"{name}.safetensors"
    actor = st.Actor.load(path)
    compare_actor(rust, path, actor, name)
    # written back by torch: the same tensors, and Rust reads the same network from it
    again = tmp_path / "again.safetensors"
    actor.save(again)
    a2 = st.Actor.load(again)
    for k, v in actor.state_dict().items():
        assert torch.equal(v, a2.state_dict()[k]), k
    assert a2.training == actor.training
    compare_actor(rust, again, a2, f"{name} re-saved by torch", sim=False)


@pytest.mark.parametrize("kind", ["smappo", "targets", "small", "mappo"])
def test_fresh_rust_checkpoint_loads_into_torch(rust, kind, tmp_path):
    path = tmp_path / f"{kind}.safetensors"
    rust("init", kind, 7, path)
    actor = st.Actor.load(path)
    assert actor.training["written_by"].startswith("policy/examples/logits.rs")
    compare_actor(rust, path, actor, f"fresh Rust {kind}", sim=kind != "small")


def perturbed(net, seed):
    """Every parameter moved by uniform noise in [-0.2, 0.2], so that the small output
    layer and unit LayerNorms of a fresh network give logits that show a difference."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in net.parameters():
            p.add_(torch.rand(p.shape, generator=g) * 0.4 - 0.2)
    return net


ARCHS = {
    "smappo": {},
    "targets": {"n_actions": 8, "actions": "targets"},
    "small": {"d_model": 16, "heads": 2, "hidden": 24, "n_actions": 9},
    "mappo": {"kind": "mappo", "flat": {"max_machines": 4, "max_storages": 2, "max_peers": 5}, "max_robots": 6},
}


@pytest.mark.parametrize("kind", list(ARCHS))
def test_fresh_torch_checkpoint_loads_into_rust(rust, kind, tmp_path):
    torch.manual_seed(3)
    actor = perturbed(st.Actor(st.arch_config(**ARCHS[kind]), training={"by": "torch"}), 3)
    path = tmp_path / f"{kind}.safetensors"
    actor.save(path)
    compare_actor(rust, path, actor, f"fresh torch {kind}")


def compare_critic(rust, path, critic, label):
    rng = np.random.default_rng(1)
    worst = 0.0
    shapes = [(4, 2, 6, 2), (3, 2, 1, 3), (0, 1, 2, 1)]  # machines, storages, robots, envs
    cases = [random_case(rng, m, k, n - 1, n * e, robots=n) for m, k, n, e in shapes]
    res = rust("values", path, cases=cases)
    with torch.no_grad():
        for (m, k, n, e), case, r in zip(shapes, cases, res["cases"]):
            obs, masks = torch_inputs(case)
            obs = {key: v.reshape(T, e, n, *v.shape[2:]) for key, v in obs.items()}
            ours, _ = critic.forward_seq(obs, None, masks.reshape(T, e, n))
            ref, _ = copy.deepcopy(critic).double().forward_seq(obs, None, masks.reshape(T, e, n))
            theirs = torch.tensor(r["batched"]).reshape(ours.shape)
            d = (ours - theirs).abs().max().item()
            e_t, e_r = ((x.double() - ref).abs().max().item() for x in (ours, theirs))
            MEASURED.append((f"{label}, {m}.{k} x{n} robots x{e} envs", d, e_t, e_r, theirs.abs().max().item()))
            worst = max(worst, d)
            assert max(d, e_t, e_r) <= TOL, (label, m, k, n, e, d, e_t, e_r)
    return worst


@pytest.mark.parametrize("kind", ["smappo", "mappo"])
def test_critics_both_ways(rust, kind, tmp_path):
    path = tmp_path / "rust_state.safetensors"
    rust("init-state", kind, 11, path)
    critic = st.Critic.load(path)
    compare_critic(rust, path, critic, f"fresh Rust critic {kind}")
    # the actor of a trainer state loads too
    actor = st.Actor.load(path)
    assert actor.arch["kind"] == kind
    arch = st.arch_config(**ARCHS[kind])
    torch.manual_seed(5)
    a, c = perturbed(st.Actor(arch), 5), perturbed(st.Critic(arch), 6)
    path = tmp_path / "torch_state.safetensors"
    st.save_trainer_state(path, a, c, extra={"by": "torch"})
    compare_critic(rust, path, c, f"fresh torch critic {kind}")


def test_bad_checkpoints_are_refused(tmp_path):
    actor = st.Actor()
    p = tmp_path / "a.safetensors"
    actor.save(p)
    tensors, md = st.read_safetensors(p)
    for change, msg in [
        (lambda t, m: t.pop("gru.bias_hh_l0"), "missing tensor `gru.bias_hh_l0`"),
        (lambda t, m: t.__setitem__("extra", torch.zeros(1)), "unexpected tensor `extra`"),
        (lambda t, m: t.__setitem__("action_out.bias", torch.zeros(4)), "shape [4], expected [5]"),
        (lambda t, m: t.__setitem__("gru_ln.bias", torch.full((64,), float("nan"))), "non-finite"),
        (lambda t, m: m.__setitem__("format", "other"), "format is `other`"),
    ]:
        t, m = dict(tensors), dict(md)
        change(t, m)
        st.write_safetensors(p, t, m)
        with pytest.raises(st.CheckpointError, match=msg.replace("[", r"\[").replace("]", r"\]")):
            st.Actor.load(p)
