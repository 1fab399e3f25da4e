#!/usr/bin/env python3
"""Markdown tables (median and min-max over repetitions) from bench/ros/out/*.jsonl."""
import json, os, statistics, sys

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "out")


def rows(name):
    p = os.path.join(OUT, name)
    if not os.path.exists(p):
        return []
    with open(p) as f:
        return [json.loads(l) for l in f if l.strip()]


def ms(vals, d=0, unit=""):
    vals = [v for v in vals if v is not None]
    if not vals:
        return "-"
    m = statistics.median(vals)
    return f"{m:.{d}f}{unit} ({min(vals):.{d}f}-{max(vals):.{d}f})"


def latency():
    r = rows("latency.jsonl")
    if not r:
        return
    print("### robot_node state-in -> cmd_vel-out (lockstep, loopback), us: median over runs (min-max)\n")
    print("| controller, state size, pacing | runs | load avg (1 min) | state first write -> cmd p50 | p99 | state last write -> cmd p50 | p99 | bare DDS RTT p50 | p99 | p50 ratio state/bare | lost | robot_node CPU % of a core | RSS MB |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    key = lambda x: (x["kind"], x["samples_per_state"], x["interval_ms"], x.get("variant") or "")
    for k in sorted({key(x) for x in r}, key=lambda k: (k[1], k[2], k[3], k[0])):
        xs = [x for x in r if key(x) == k]
        e = xs[0]["entities"]
        kind = f"{k[0]}, {e['machines']} machines {e['storages']} storages {e['peers']} peers ({k[1]} samples/state), every {k[2]} ms"
        if k[3]:
            kind += f", {k[3]}"
        g = lambda k, q: [x[k][q] for x in xs]
        ratio = [x["state_first_write_to_cmd_us"]["p50"] / x["bare_round_trip_us"]["p50"] for x in xs]
        print(f"| {kind} | {len(xs)} | {ms([x['loadavg_before'][0] for x in xs], 2)} "
              f"| {ms(g('state_first_write_to_cmd_us', 'p50'))} | {ms(g('state_first_write_to_cmd_us', 'p99'))} "
              f"| {ms(g('state_last_write_to_cmd_us', 'p50'))} | {ms(g('state_last_write_to_cmd_us', 'p99'))} "
              f"| {ms(g('bare_round_trip_us', 'p50'))} | {ms(g('bare_round_trip_us', 'p99'))} | {ms(ratio, 1)} "
              f"| {sum(x['lost_states'] for x in xs)}/{sum(x['n'] for x in xs)} "
              f"| {ms([x['robot_node_cpu_pct_one_core'] for x in xs], 2)} | {ms([x['robot_node_rss_kb'] / 1024 for x in xs], 1)} |")
    print()


def fleet():
    r = rows("fleet.jsonl")
    if not r:
        return
    print("### robot_node fleets at 10 Hz (realtime sim_bridge, policy), median over runs (min-max)\n")
    print("Variant: which robot_node binary (bench.py fleet --variants); empty = the current build when the run was made.\n")
    print("| robots | processes | variant | setup | runs | load avg before | missed ticks % (all robots, whole run) | worst robot % | missed % after 10 s uptime | worst robot % after 10 s | max tick lateness ms | CPU % per robot | CPU % all robot nodes | CPU % sim_bridge | RSS MB per process | readers (`subscriptions`, median over robots) | robots reporting | zero-cmd ticks (own stale) | bridge steps in run | robots in sim at end | parts delivered |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    vkey = lambda x: x.get("variant") or ""
    keys = sorted({(x["robots_n"], x.get("multi", False), vkey(x)) for x in r}, key=lambda k: (k[1], k[2], k[0]))
    hung = []
    for n, multi, variant in keys:
        al = [x for x in r if x["robots_n"] == n and x.get("multi", False) == multi and vkey(x) == variant]
        # a run whose bridge never published (hung at start-up) measures nothing: listed apart
        xs = [x for x in al if x["bridge_metrics"] is not None]
        if len(xs) < len(al):
            hung.append(f"{n} robots{' (one process)' if multi else ''}{' ' + variant if variant else ''}: {len(al) - len(xs)} of {len(al)} runs")
        if not xs:
            continue
        readers = [x.get("subscriptions_median") for x in xs]
        bm = lambda k: [x["bridge_metrics"].get(k) for x in xs]
        print(f"| {n} | {'1' if multi else n} | {variant or '-'} | {xs[0]['setup']} | {len(xs)} | {ms([x['loadavg_before'][0] for x in xs], 2)} "
              f"| {ms([x['missed_pct'] for x in xs], 2)} | {ms([x['missed_pct_worst_node'] for x in xs], 2)} "
              f"| {ms([x.get('steady_missed_pct') for x in xs], 2)} | {ms([x.get('steady_missed_pct_worst') for x in xs], 2)} "
              f"| {ms([(x['tick_late_max_us'] or 0) / 1000 for x in xs], 0)} "
              f"| {ms([x.get('cpu_pct_per_robot_median', x.get('cpu_pct_per_node_median')) for x in xs], 1)} "
              f"| {ms([x['cpu_pct_nodes_total'] for x in xs], 0)} | {ms([x['cpu_pct_bridge'] for x in xs], 0)} "
              f"| {ms([(x.get('rss_kb_per_process_median') or x.get('rss_kb_per_node_median') or 0) / 1024 for x in xs], 1)} "
              f"| {ms(readers, 0)} "
              f"| {'/'.join(str(x['finals']) for x in xs)} of {n} | {ms([x['zero_own_stale'] for x in xs], 0)} "
              f"| {ms(bm('step'), 0)} | {ms(bm('robots'), 0)} | {ms(bm('parts_delivered'), 0)} |")
    print()
    print("Readers: the median over robots of the `subscriptions` counter. With one reader per topic per "
          "process (shared readers) that is the process's reader count; with per-robot readers it is each "
          "robot's, and a process hosting N robots had N times as many.\n")
    if hung:
        print("Runs left out because sim_bridge published nothing (hung at start-up, killed at the end): "
              + "; ".join(hung) + "\n")


if __name__ == "__main__":
    latency()
    fleet()
