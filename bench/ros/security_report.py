#!/usr/bin/env python3
"""Markdown tables of the DDS Security on/off runs (bench/ros/security.sh) from
bench/ros/out/{latency,fleet}.jsonl: the records that carry a `security` field, from
`--since` (ISO time, default: all).

  python3 bench/ros/security_report.py [--since 2026-12-01T00:00:00]
"""
import argparse, json, os, statistics

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "out")


def rows(name, since):
    path = os.path.join(OUT, name)
    if not os.path.exists(path):
        return []
    out = []
    with open(path) as f:
        for line in f:
            v = json.loads(line)
            if "security" in v and v.get("time", "") >= since:
                out.append(v)
    return out


def med(xs):
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else None


def f(x, d=0):
    return "-" if x is None else f"{x:.{d}f}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--since", default="")
    a = ap.parse_args()

    lat = rows("latency.jsonl", a.since)
    if lat:
        print("| controller | interval | security | runs | state->cmd p50 / p99 (us) | bare DDS RTT p50 / p99 (us) "
              "| robot_node CPU (% of one core) | lost states |")
        print("|---|---|---|---|---|---|---|---|")
        keys = sorted({(v["kind"], v["interval_ms"], v["security"]) for v in lat},
                      key=lambda k: (k[0], k[1], k[2] != "off"))
        for kind, iv, sec in keys:
            rs = [v for v in lat if (v["kind"], v["interval_ms"], v["security"]) == (kind, iv, sec)]
            s = lambda k, q: med([v[k][q] for v in rs])
            print(f"| {kind} | {iv} ms | {sec} | {len(rs)} | {f(s('state_first_write_to_cmd_us', 'p50'))} / "
                  f"{f(s('state_first_write_to_cmd_us', 'p99'))} | {f(s('bare_round_trip_us', 'p50'))} / "
                  f"{f(s('bare_round_trip_us', 'p99'))} | {f(med([v['robot_node_cpu_pct_one_core'] for v in rs]), 1)} "
                  f"| {sum(v['lost_states'] for v in rs)} |")
        print()

    fl = rows("fleet.jsonl", a.since)
    if fl:
        # "Holds 10 Hz": every process alive, < 1 % missed ticks after the first 10 s, and
        # the fleet works: the bridge still hosts every robot and all of them act on its
        # state at the end, and fewer than 10 % of the ticks sent a zero command because
        # the robot's own state was stale (missed ticks alone miss a fleet whose ticks run
        # on time but whose state arrives too late to act on).
        print("| robots | security | runs | missed ticks after 10 s (worst robot) | ticks with own state stale "
              "| CPU per robot_node (% of one core) | bridge CPU | bridge: robots / on state at end | parts "
              "| load before -> after | holds 10 Hz |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        keys = sorted({(v["robots_n"], v["multi"], v["security"]) for v in fl}, key=lambda k: (k[1], k[0], k[2] != "off"))
        for n, multi, sec in keys:
            rs = [v for v in fl if (v["robots_n"], v["multi"], v["security"]) == (n, multi, sec)]
            bms = [v.get("bridge_metrics") or {} for v in rs]
            stale = [v["zero_own_stale"] / max(1, v["ticks"]) * 100 for v in rs]

            def ok(v, bm, st):
                return (v["alive_at_end"] == v["processes"] and v["steady_missed_pct"] is not None
                        and v["steady_missed_pct"] < 1.0 and bm.get("robots") == n
                        and bm.get("robots_on_state") == n and st < 10.0)
            good = sum(ok(v, bm, st) for v, bm, st in zip(rs, bms, stale))
            runs = " ".join(f"{bm.get('robots')}/{bm.get('robots_on_state')}" for bm in bms)
            cpu = "; ".join(f(v["cpu_pct_per_robot_median"], 1) for v in rs)
            print(f"| {n}{' in 1 process' if multi else ' processes'} | {sec} | {len(rs)} | "
                  f"{f(med([v['steady_missed_pct'] for v in rs]), 2)}% ({f(max((v['steady_missed_pct_worst'] or 0) for v in rs), 2)}%) | "
                  f"{f(med(stale), 1)}% | {cpu} | {f(med([v['cpu_pct_bridge'] for v in rs]), 0)}% | {runs} | "
                  f"{' '.join(str(bm.get('parts_delivered')) for bm in bms)} | "
                  f"{'; '.join(f(v['loadavg_before'][0], 1) + '->' + f(v['loadavg_after'][0], 1) for v in rs)} | "
                  f"{good}/{len(rs)} |")


if __name__ == "__main__":
    main()
