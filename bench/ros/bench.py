#!/usr/bin/env python3
"""robot_node ROS 2 benchmarks (see docs/bench/ros.md). Loopback only, every run bounded.

  bench.py latency --reps 3 --n 200 --policy CKPT      state-in -> cmd_vel-out (lockstep), bare RTT
  bench.py fleet --sizes 5,10,20 --reps 3 --secs 30     N robot_node processes + sim_bridge, realtime 10 Hz
  bench.py report                                       markdown tables from out/*.jsonl

Results append to bench/ros/out/{latency,fleet}.jsonl, one JSON object per run, each with
the load average of the machine before and after the run.
"""
import argparse, json, os, signal, statistics, subprocess, sys, time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
REL = os.path.join(ROOT, "target", "release")
OUT = os.path.join(ROOT, "bench", "ros", "out")
TCK = os.sysconf("SC_CLK_TCK")


def loadavg():
    with open("/proc/loadavg") as f:
        return [float(x) for x in f.read().split()[:3]]


def cpu_ticks(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            s = f.read()
        rest = s[s.rfind(")") + 2:].split()
        return int(rest[11]) + int(rest[12])
    except (OSError, IndexError, ValueError):
        return None


def rss_kb(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def append(name, obj):
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, name), "a") as f:
        f.write(json.dumps(obj) + "\n")


def latency(a):
    ctrls = [("greedy", "")]
    if a.policy and not a.greedy_only:
        ctrls.append(("policy", a.policy))
    modes = a.security.split(",")
    for rep in range(a.reps):
        for name, pol, mode in [(n, p, m) for n, p in ctrls for m in modes]:
            la0 = loadavg()
            rn = os.path.join(ROOT, a.robot_node) if a.robot_node else os.path.join(REL, "robot_node")
            cmd = [os.path.join(REL, "ros_bench"), "latency", "--robot-node", rn,
                   "--n", str(a.n), "--interval-ms", str(a.interval_ms), "--domain", str(150 + rep * 4 + len(name) % 4)]
            if pol:
                cmd += ["--policy", pol]
            cmd += ["--peers", str(a.peers), "--machines", str(a.machines), "--storages", str(a.storages)]
            if mode == "on":
                # a fresh keystore per run (ros_bench creates it)
                ks = os.path.join(OUT, "logs", "keystores", f"latency-{os.getpid()}-{rep}-{name}")
                subprocess.run(["rm", "-rf", ks], check=True)
                cmd += ["--keystore", ks, "--warmup-s", str(a.warmup_s)]
            elif a.security != "off":
                cmd += ["--warmup-s", str(a.warmup_s)]
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=a.n * a.interval_ms / 1000 * 2 + 90)
            line = [l for l in r.stdout.splitlines() if l.startswith("{")]
            if r.returncode != 0 or not line:
                print(f"latency {name} rep {rep}: failed rc={r.returncode}\n{r.stderr[-2000:]}", file=sys.stderr)
                continue
            v = json.loads(line[-1])
            v.update(kind=name, rep=rep, interval_ms=a.interval_ms, loadavg_before=la0, loadavg_after=loadavg(),
                     variant=a.variant or None, robot_node=os.path.relpath(rn, ROOT), security=mode,
                     time=time.strftime("%Y-%m-%dT%H:%M:%S"))
            append("latency.jsonl", v)
            print(f"latency {name:6} {a.variant or ''} security {mode} rep {rep} int {a.interval_ms} ms: state->cmd p50 {v['state_first_write_to_cmd_us']['p50']:.0f} us "
                  f"p99 {v['state_first_write_to_cmd_us']['p99']:.0f} us | bare RTT p50 {v['bare_round_trip_us']['p50']:.0f} us "
                  f"p99 {v['bare_round_trip_us']['p99']:.0f} us | load {la0[0]:.2f}", flush=True)


STATS_PERIOD = 5  # periodic stats lines: missed ticks after the start-up phase
STEADY_AFTER = 10  # s of robot uptime: the "steady" counts start at the first stats line past this

SETUPS = {5: "5.4_2", 6: "6.4_2", 10: "10.6_4", 20: "20.12_4", 30: "30.18_4", 40: "40.24_4", 50: "50.16_4", 100: "100.16_2", 200: "200.16_2"}


def secure_env(env, keystore):
    return dict(env, ROS_SECURITY_KEYSTORE=keystore, ROS_SECURITY_ENABLE="true",
                ROS_SECURITY_STRATEGY="Enforce")


def fleet_run(n, secs, warm, policy, domain, tag, multi=False, robot_node=None, variant=None,
              secure=False):
    """n robots at 10 Hz on a realtime sim_bridge: one robot_node process per robot, or
    (multi) one robot_node process hosting all n robots (-p robots:=robot_0..n-1).
    robot_node: the binary (default target/release/robot_node); variant: its label."""
    robot_node = robot_node or os.path.join(REL, "robot_node")
    setup = SETUPS.get(n, f"{n}.{max(2, n // 6)}_{max(2, n // 25)}")
    logdir = os.path.join(OUT, "logs", f"fleet-{tag}")
    os.makedirs(logdir, exist_ok=True)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), RUST_LOG="info,rustdds=warn,ros2_client=warn")
    groups = [["robot_0..%d" % (n - 1)]] if multi else [[f"__ns:=/robot_{i}"] for i in range(n)]
    ks = None
    if secure:
        # a fresh keystore with the fleet's enclaves (robot_<i>, sim_bridge), Enforce
        ks = os.path.join(logdir, "keystore")
        subprocess.run(["rm", "-rf", ks], check=True)
        subprocess.run([os.path.join(REL, "tending"), "security", "create", ks, "--fleet", str(n)],
                       check=True, capture_output=True)
        if multi:
            subprocess.run([os.path.join(REL, "tending"), "security", "enclave", ks, "/tending/all_robots",
                            "--role", "robots:" + ",".join(f"robot_{i}" for i in range(n))],
                           check=True, capture_output=True)
    nodes = []
    for gi, g in enumerate(groups):
        args = [robot_node, "--ros-args"]
        if multi:
            args += ["-p", f"robots:={g[0]}"]
        else:
            args += ["-r", g[0]]
        args += ["-p", "control_rate_hz:=10", "-p", "stale_timeout_s:=2.0", "-p", "stats_json:=true",
                 "-p", f"stats_period_s:={STATS_PERIOD}"]
        if policy:
            args += ["-p", f"policy:={policy}"]
        if ks:
            args += ["--enclave", "/tending/all_robots" if multi else f"/tending/robot_{gi}"]
        out = open(os.path.join(logdir, f"node_{gi}.jsonl"), "w")
        err = open(os.path.join(logdir, f"node_{gi}.log"), "w")
        nodes.append((subprocess.Popen(args, env=secure_env(env, ks) if ks else env, stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                       start_new_session=True), out, err))
    bout = open(os.path.join(logdir, "sim_bridge.jsonl"), "w")
    berr = open(os.path.join(logdir, "sim_bridge.log"), "w")
    bridge = subprocess.Popen([os.path.join(REL, "sim_bridge"), "--ros-args", "-p", f"setup:={setup}",
                               "-p", "mode:=realtime", "-p", "rate_hz:=10", "-p", "seed:=0"]
                              + (["--enclave", "/tending/sim_bridge"] if ks else []),
                              env=secure_env(env, ks) if ks else env, stdout=bout, stderr=berr, stdin=subprocess.DEVNULL, start_new_session=True)
    la0 = loadavg()
    time.sleep(warm)
    pids = [p.pid for p, _, _ in nodes]
    c0 = {pid: cpu_ticks(pid) for pid in pids + [bridge.pid]}
    t0 = time.monotonic()
    time.sleep(secs - warm)
    dt = time.monotonic() - t0
    c1 = {pid: cpu_ticks(pid) for pid in pids + [bridge.pid]}
    rss = [rss_kb(pid) for pid in pids]
    la1 = loadavg()
    alive = sum(1 for p, _, _ in nodes if p.poll() is None)
    # stop: robots and bridge get SIGINT, bounded wait, then SIGKILL
    for p in [bridge] + [p for p, _, _ in nodes]:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    deadline = time.monotonic() + 15
    killed = 0
    for p in [bridge] + [p for p, _, _ in nodes]:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
            killed += 1
    for _, o, e in nodes:
        o.close(); e.close()
    bout.close(); berr.close()

    def pct(pid):
        a, b = c0.get(pid), c1.get(pid)
        return None if a is None or b is None else (b - a) / TCK / dt * 100.0

    fin = []
    base = {}  # robot -> first periodic line past STEADY_AFTER
    for gi in range(len(nodes)):
        with open(os.path.join(logdir, f"node_{gi}.jsonl")) as f:
            for line in f:
                try:
                    v = json.loads(line)
                except ValueError:
                    continue
                if v.get("final"):
                    fin.append(v)
                elif v.get("uptime_s", 0) >= STEADY_AFTER and v["robot"] not in base:
                    base[v["robot"]] = v
    steady = [(r["ticks"] - base[r["robot"]]["ticks"], r["ticks_missed"] - base[r["robot"]]["ticks_missed"])
              for r in fin if r["robot"] in base]
    s_ticks = sum(t for t, _ in steady)
    s_missed = sum(m for _, m in steady)
    s_worst = max((m / max(1, t + m) * 100 for t, m in steady), default=None)
    metrics = None
    with open(os.path.join(logdir, "sim_bridge.jsonl")) as f:
        for line in f:
            if line.startswith("{"):
                metrics = json.loads(line)
    ticks = sum(r["ticks"] for r in fin)
    missed = sum(r["ticks_missed"] for r in fin)
    per_node = [r["ticks_missed"] / max(1, r["ticks"] + r["ticks_missed"]) * 100 for r in fin]
    cpus = [pct(pid) for pid in pids]
    cpus = [c for c in cpus if c is not None]
    per_robot_cpu = [c / (n if multi else 1) for c in cpus]
    return dict(robots_n=n, multi=multi, variant=variant, robot_node=os.path.relpath(robot_node, ROOT),
                security="on" if secure else "off", warm_s=warm,
                processes=len(nodes), setup=setup, secs=secs, cpu_window_s=dt,
                policy=policy, alive_at_end=alive, killed=killed,
                finals=len(fin), ticks=ticks, ticks_missed=missed,
                missed_pct=missed / max(1, ticks + missed) * 100, missed_pct_worst_node=max(per_node) if per_node else None,
                steady_robots=len(steady), steady_ticks=s_ticks, steady_missed=s_missed,
                steady_missed_pct=s_missed / max(1, s_ticks + s_missed) * 100 if steady else None,
                steady_missed_pct_worst=s_worst,
                tick_late_max_us=max((r["tick_late_max_us"] for r in fin), default=None),
                commands=sum(r["commands"] for r in fin), zero_own_stale=sum(r["zero"]["own_stale"] for r in fin),
                subscriptions_median=statistics.median([r["subscriptions"] for r in fin]) if fin else None,
                cpu_pct_per_robot_median=statistics.median(per_robot_cpu) if per_robot_cpu else None,
                cpu_pct_nodes_total=sum(cpus), cpu_pct_bridge=pct(bridge.pid),
                rss_kb_per_process_median=statistics.median([r for r in rss if r]) if any(rss) else None,
                bridge_metrics=metrics, finals_detail=fin, cpu_pct_per_process=cpus, rss_kb=rss,
                loadavg_before=la0, loadavg_after=la1, time=time.strftime("%Y-%m-%dT%H:%M:%S"))


def fleet(a):
    # variants: label=binary pairs, run side by side (same rep, same size, one after the
    # other) so that both see the same background load
    variants = [(None, None)]
    if a.variants:
        variants = [tuple(v.split("=", 1)) for v in a.variants.split(",")]
    for rep in range(a.reps):
        for n in [int(x) for x in a.sizes.split(",")]:
            for vi, (label, binary, mode) in enumerate(
                    [(l, b, m) for l, b in variants for m in a.security.split(",")]):
                vtag = (f"-{label}" if label else "") + ("-secure" if mode == "on" else "")
                tag = f"{n}-{'multi' if a.multi else 'procs'}{vtag}-r{rep}"
                # ROS_DOMAIN_ID must stay <= 232
                domain = (100 + vi * 30 if a.multi else 170) + rep * 8 + n % 8
                v = fleet_run(n, a.secs, a.warm, a.policy, domain, tag, a.multi,
                              os.path.join(ROOT, binary) if binary else None, label, mode == "on")
                v["rep"] = rep
                append("fleet.jsonl", v)
                f = lambda x, d=1: "-" if x is None else f"{x:.{d}f}"
                bm = v["bridge_metrics"] or {}
                print(f"fleet {n:3} {'1 proc' if a.multi else 'procs '} {label or ''} security {mode} rep {rep}: missed {v['ticks_missed']}/{v['ticks']} "
                      f"({f(v['missed_pct'], 2)}%, worst robot {f(v['missed_pct_worst_node'], 2)}%) after {STEADY_AFTER} s: "
                      f"{v['steady_missed']}/{v['steady_ticks']} ({f(v['steady_missed_pct'], 2)}%, worst {f(v['steady_missed_pct_worst'], 2)}%, "
                      f"{v['steady_robots']} robots) late_max {v['tick_late_max_us']} us | "
                      f"cpu/robot {f(v['cpu_pct_per_robot_median'])}% nodes {f(v['cpu_pct_nodes_total'], 0)}% bridge "
                      f"{f(v['cpu_pct_bridge'], 0)}% | rss/proc {v['rss_kb_per_process_median']} kB | finals {v['finals']}/{n} "
                      f"subs {v['subscriptions_median']} own_stale {v['zero_own_stale']} cmds {v['commands']} | "
                      f"bridge robots {bm.get('robots')} step {bm.get('step')} parts {bm.get('parts_delivered')} | "
                      f"load {v['loadavg_before'][0]:.2f}->{v['loadavg_after'][0]:.2f}", flush=True)


def main():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    l = sub.add_parser("latency")
    l.add_argument("--reps", type=int, default=3)
    l.add_argument("--n", type=int, default=200)
    l.add_argument("--interval-ms", type=int, default=100)
    l.add_argument("--policy", default="")
    l.add_argument("--peers", type=int, default=5)
    l.add_argument("--machines", type=int, default=4)
    l.add_argument("--storages", type=int, default=2)
    l.add_argument("--greedy-only", action="store_true")
    l.add_argument("--robot-node", default="", help="robot_node binary (path from the repo root)")
    l.add_argument("--variant", default="", help="label of that binary in the results")
    l.add_argument("--security", default="off", choices=["off", "on", "off,on", "on,off"],
                   help="DDS Security (Enforce) off, on, or both alternately (same rep, one after the other)")
    l.add_argument("--warmup-s", type=float, default=5.0, help="ros_bench warm-up (with --security)")
    f = sub.add_parser("fleet")
    f.add_argument("--sizes", default="5,10,20")
    f.add_argument("--reps", type=int, default=3)
    f.add_argument("--secs", type=float, default=30)
    f.add_argument("--warm", type=float, default=5)
    f.add_argument("--policy", default="")
    f.add_argument("--multi", action="store_true", help="all robots in one robot_node process")
    f.add_argument("--variants", default="",
                   help="label=binary[,label=binary...] (paths from the repo root), run side by side")
    f.add_argument("--security", default="off", choices=["off", "on", "off,on", "on,off"],
                   help="DDS Security (Enforce, fresh keystore per run) off, on, or both alternately")
    a = ap.parse_args()
    {"latency": latency, "fleet": fleet}[a.cmd](a)


if __name__ == "__main__":
    main()
