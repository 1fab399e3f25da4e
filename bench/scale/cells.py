#!/usr/bin/env python3
"""Traffic per robot with and without cell topics (issue 46, docs/adr/0038-cell-topics.md).

Runs `tending fleet` in lockstep (20 steps of 10 Hz) on grown floors with the 8-nearest
bound and matching-ORCA, once reading every entity's topics and once reading cell topics
(--cell-size 3), and reads from every robot's final counters what it accepted: samples and
CDR payload bytes per control step (each robot counts what it alone would receive: the
samples of its own topics and of the cells in its window; in entity mode every entity's).
The offline episode of the same setup and seed gives the parts the fleet must deliver.

usage: bench/scale/cells.py [--bin target/release] [--runs "cells:100.66_33 ..."] \
           [--out docs/bench/cells.md]
One JSON line per run goes to runs/cells/results.jsonl as it finishes (progress); the
table is rebuilt from that file, so runs can be added one at a time.
"""
import argparse, json, os, re, resource, statistics, subprocess, sys, time

ap = argparse.ArgumentParser()
ap.add_argument('--bin', default='target/release')
ap.add_argument('--runs', default='entity:100.66_33 cells:100.66_33 entity:300.200_100 '
                'cells:300.200_100 cells:1000.666_333')
ap.add_argument('--steps', type=int, default=20)
ap.add_argument('--work', default='runs/cells')
ap.add_argument('--out', default='docs/bench/cells.md')
ap.add_argument('--table-only', action='store_true')
a = ap.parse_args()
os.makedirs(a.work, exist_ok=True)
results = os.path.join(a.work, 'results.jsonl')
tending = os.path.join(a.bin, 'tending')


def offline(setup, scen):
    out = subprocess.run([tending, 'sim', '--setup', setup, '--floor', 'grown', '--nearest', '8',
                          '--policy', 'matching-orca', '--episodes', '1', '--seed', '0',
                          '--scenario', scen], capture_output=True, text=True, check=True).stdout
    row = [l for l in out.splitlines() if l.startswith('| matching-orca')][0].split('|')
    return float(row[4].split()[0]), float(row[5].split()[0])


def run(mode, setup, scen):
    d = os.path.join(a.work, f'{mode}_{setup}')
    cmd = ['nice', '-n', '5', tending, 'fleet', '--setup', setup, '--floor', 'grown', '--nearest',
           '8', '--policy', 'matching-orca', '--mode', 'lockstep', '--duration',
           str(a.steps / 10), '--domain', 'auto', '--no-stdin', '--log-dir', d]
    if mode == 'cells':
        cmd += ['--cell-size', '3']
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.time()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.time() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    final = next((json.loads(l[7:]) for l in p.stdout.splitlines() if l.startswith('final: ')), {})
    per = []   # (accepted per tick, bytes per tick) of each robot
    subs = []  # readers per process
    wait_timeouts = 0
    for f in os.listdir(d):
        if not f.startswith('robot_'):
            continue
        for line in open(os.path.join(d, f), errors='replace'):
            m = re.search(r'final counters (robot_\d+): accepted=(\d+) bytes=(\d+) .*? ticks=(\d+)', line)
            if m and int(m.group(4)) > 0:
                per.append((int(m.group(2)), int(m.group(3))))
            m = re.search(r'final counters \(all robots\): .*subscriptions=(\d+) lockstep_wait_timeouts=(\d+)', line)
            if m:
                subs.append(int(m.group(1)))
                wait_timeouts += int(m.group(2))
    # per published state: the step's states and the bridge's resends of them (lockstep
    # publishes a state again while some robot has not answered it; each resend is traffic)
    states = (final.get('step') or 0) + 1 + (final.get('state_resends') or 0)
    per = [(a / states, b / states) for a, b in per]
    parts, contacts = offline(setup, scen)
    return {
        'mode': mode, 'setup': setup, 'robots': int(setup.split('.')[0]), 'rc': p.returncode,
        'wall_s': round(wall, 1), 'cpu_s': round(cpu, 1), 'robots_counted': len(per),
        'msgs_per_step_mean': round(statistics.mean(x[0] for x in per), 1) if per else None,
        'msgs_per_step_max': round(max(x[0] for x in per), 1) if per else None,
        'bytes_per_step_mean': round(statistics.mean(x[1] for x in per)) if per else None,
        'bytes_per_step_max': round(max(x[1] for x in per)) if per else None,
        'readers_per_process': subs, 'parts': final.get('parts_delivered'),
        'contacts': final.get('collisions'), 'steps': final.get('step'),
        'state_resends': final.get('state_resends'),
        'robot_wait_timeouts': wait_timeouts,
        'offline_parts': parts, 'offline_contacts': contacts,
        'healthy': 'health: healthy' in p.stdout, 'load': round(os.getloadavg()[0], 1),
    }


if not a.table_only:
    scen = os.path.join(a.work, f'steps{a.steps}.toml')
    cfg = subprocess.run([tending, 'config'], capture_output=True, text=True, check=True).stdout
    open(scen, 'w').write(re.sub(r'(?m)^episode_steps = .*$', f'episode_steps = {a.steps}', cfg))
    for spec in a.runs.split():
        mode, setup = spec.split(':')
        print(f'== {mode} {setup} ...', file=sys.stderr, flush=True)
        r = run(mode, setup, scen)
        print(json.dumps(r), flush=True)
        with open(results, 'a') as f:
            f.write(json.dumps(r) + '\n')

rows = {}
for line in open(results):
    r = json.loads(line)
    rows[(r['mode'], r['robots'])] = r  # the latest run of each
hz = 10
out = ['| topics | setup | robots counted | samples / robot / s (mean, max) | kB / robot / s (mean, max) | Mbit/s per robot (mean) | readers per robot process | parts (fleet / offline) | contacts (fleet / offline) | robot wait timeouts | states resent | wall s | CPU s | exit |',
       '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|']
for key in sorted(rows, key=lambda k: (k[1], k[0] != 'entity')):
    r = rows[key]
    if r['msgs_per_step_mean'] is None:
        out.append(f"| {r['mode']} | {r['setup']} | 0 | - | - | - | - | {r['parts']} / {r['offline_parts']:.0f} | - | - | - | {r['wall_s']} | {r['cpu_s']} | {r['rc']} |")
        continue
    out.append('| {mode} | {setup} | {n} | {m:.0f}, {mx:.0f} | {b:.1f}, {bx:.1f} | {mb:.2f} | {subs} | {p} / {op:.0f} | {c} / {oc:.0f} | {wt} | {rs} | {w} | {cpu} | {h} |'.format(
        mode=r['mode'], setup=r['setup'], n=r['robots_counted'], m=r['msgs_per_step_mean'] * hz,
        mx=r['msgs_per_step_max'] * hz, b=r['bytes_per_step_mean'] * hz / 1e3,
        bx=r['bytes_per_step_max'] * hz / 1e3, mb=r['bytes_per_step_mean'] * hz * 8 / 1e6,
        subs=', '.join(map(str, sorted(r['readers_per_process']))), p=r['parts'],
        op=r['offline_parts'], c=r['contacts'], oc=r['offline_contacts'],
        wt=r.get('robot_wait_timeouts', '-'), rs=r.get('state_resends', '-'), w=r['wall_s'],
        cpu=r['cpu_s'], h=r['rc']))
table = '\n'.join(out)
print(table)
if os.path.exists(a.out):
    doc = open(a.out).read()
    doc = re.sub(r'<!-- table -->.*<!-- /table -->', '<!-- table -->\n' + table + '\n<!-- /table -->', doc, flags=re.S)
    open(a.out, 'w').write(doc)
