#!/usr/bin/env python3
"""Cold-start stress of `tending fleet`, two builds side by side (issue 9).

Runs `tending fleet --setup S --duration D` many times, alternating the binaries of two
target directories (e.g. the build before the rustdds fix and the one after) run by run,
and checks each run the way a user would judge it: exit code 0, parts delivered, every
robot still in the bridge at the end, no watchdog restart, and (new builds, whose bridge
reports `robots_on_state`) the wall time until every robot acts on the bridge's state.

    python3 bench/startup/stress.py --build new=target/release --build old=../wt-base/target/release \
        --setup 20.10_4:20 --setup 50.20_5:5 --duration 12 --out docs/bench/startup.md

Each run gets its own ROS domain; a run is killed after duration + 90 s (a hang).
"""
import argparse
import csv
import datetime
import json
import os
import re
import subprocess
import sys
import time


def one_run(bin_dir, setup, duration, domain, log_dir):
    n = int(setup.split('.')[0])
    cmd = [os.path.join(bin_dir, 'tending'), 'fleet', '--setup', setup, '--duration',
           str(duration), '--no-stdin', '--domain', str(domain), '--log-dir', log_dir]
    t0 = time.time()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    all_on_state_at = None
    final = None
    lines = []
    killed = False
    try:
        out, err = p.communicate(timeout=duration + 90)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        killed = True
    # the status lines carry no wall time: estimate from the order of lines (1 per second
    # of metrics) is too coarse, so take the sim time of the first line with every robot
    # acting on state (realtime: sim time ~ wall time since the bridge's first step)
    for line in out.splitlines():
        lines.append(line)
        m = re.search(r't=\s*([\d.]+)s .* on_state=\s*(\d+)', line)
        if m and all_on_state_at is None and int(m.group(2)) >= n:
            all_on_state_at = float(m.group(1))
        if line.startswith('final: '):
            final = json.loads(line[len('final: '):])
    wall = time.time() - t0
    restarts = len(re.findall(r'ended by its watchdog', out))
    parts = final['parts_delivered'] if final else 0
    robots_end = final['robots'] if final else 0
    ok = (p.returncode == 0 and not killed and parts > 0 and robots_end >= n and restarts == 0)
    # the reason: the CLI's error line (`tending: error: ...`, or `Error: ...` from builds
    # that returned the error from main with a backtrace after it), else the last line
    err_lines = err.strip().splitlines()
    last_err = next((l for l in reversed(err_lines) if l.startswith(('tending: error', 'Error:'))),
                    err_lines[-1] if err_lines else '')
    return {
        'ok': ok, 'exit': 'hung (killed)' if killed else p.returncode, 'wall_s': round(wall, 1),
        'parts': parts, 'robots_end': robots_end, 'restarts': restarts,
        'all_on_state_s': all_on_state_at, 'error': last_err[:160] if not ok else '',
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--build', action='append', required=True,
                    help='NAME=TARGET_DIR (repeat; runs alternate between builds)')
    ap.add_argument('--setup', action='append', required=True,
                    help='SETUP:RUNS, e.g. 20.10_4:20 (runs per build)')
    ap.add_argument('--only', action='append', default=[],
                    help='SETUP=NAME[,NAME]: run only these builds at this setup')
    ap.add_argument('--duration', type=float, default=12.0)
    ap.add_argument('--domain-base', type=int, default=120)
    ap.add_argument('--out', required=True, help='Markdown report')
    ap.add_argument('--csv', help='per-run rows (default: next to --out)')
    a = ap.parse_args()
    builds = [b.split('=', 1) for b in a.build]
    only = {s.split('=')[0]: s.split('=')[1].split(',') for s in a.only}
    csv_path = a.csv or os.path.splitext(a.out)[0] + '.csv'
    rows = []
    load0 = os.getloadavg()
    started = datetime.datetime.now(datetime.timezone.utc)
    k = 0
    for spec in a.setup:
        setup, runs = spec.split(':')
        names = only.get(setup, [b[0] for b in builds])
        for i in range(int(runs)):
            for name, bin_dir in builds:
                if name not in names:
                    continue
                k += 1
                log_dir = f'/tmp/tending-stress/{name}-{setup}-{i}'
                os.makedirs(log_dir, exist_ok=True)
                r = one_run(bin_dir, setup, a.duration, a.domain_base + (k % 60), log_dir)
                r.update(build=name, setup=setup, run=i, load=round(os.getloadavg()[0], 1))
                rows.append(r)
                print(f"[{k}] {name:>4} {setup:>9} run {i:>2}: {'ok ' if r['ok'] else 'FAIL'} "
                      f"exit={r['exit']} parts={r['parts']} robots_end={r['robots_end']} "
                      f"restarts={r['restarts']} all_on_state={r['all_on_state_s']} "
                      f"load={r['load']} {r['error']}", flush=True)
    with open(csv_path, 'w', newline='') as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    # report
    load1 = os.getloadavg()
    md = ['# Fleet cold-start stress (`bench/startup/stress.py`)', '',
          f'{started:%Y-%m-%d %H:%M} UTC, {len(rows)} runs of `tending fleet --setup S --duration '
          f'{a.duration:g}` alternating builds run by run; load average {load0[0]:.1f} at the start, '
          f'{load1[0]:.1f} at the end (2 cores, shared with other work). A run passes when it '
          'exits 0, delivers parts, keeps every robot in the bridge and needs no watchdog restart; '
          'a hung run is killed after duration + 90 s.', '',
          '| setup | build | runs | passed | hung (killed) | other failures | watchdog restarts '
          '| parts (mean) | every robot acting on state at (sim s, median / max) |',
          '|---|---|---|---|---|---|---|---|---|']
    for spec in a.setup:
        setup = spec.split(':')[0]
        for name, _ in builds:
            rs = [r for r in rows if r['setup'] == setup and r['build'] == name]
            if not rs:
                continue
            hung = sum(1 for r in rs if r['exit'] == 'hung (killed)')
            passed = sum(1 for r in rs if r['ok'])
            other = len(rs) - passed - hung
            on = sorted(r['all_on_state_s'] for r in rs if r['all_on_state_s'] is not None)
            on_s = (f"{on[len(on) // 2]:.1f} / {on[-1]:.1f} ({len(on)} runs)" if on
                    else 'not reported')
            md.append(f"| {setup} | {name} | {len(rs)} | {passed} | {hung} | {other} | "
                      f"{sum(r['restarts'] for r in rs)} | "
                      f"{sum(r['parts'] for r in rs) / len(rs):.1f} | {on_s} |")
    fails = [r for r in rows if not r['ok']]
    if fails:
        md += ['', 'Failed runs:', '']
        md += [f"- {r['build']} {r['setup']} run {r['run']}: exit {r['exit']}, parts {r['parts']}, "
               f"robots at the end {r['robots_end']}, restarts {r['restarts']}, load {r['load']}: "
               f"`{r['error']}`" for r in fails]
    md += ['', f'Per-run rows: `{os.path.basename(csv_path)}`.', '']
    with open(a.out, 'w') as f:
        f.write('\n'.join(md))
    print('\n'.join(md))
    return 0


if __name__ == '__main__':
    sys.exit(main())
