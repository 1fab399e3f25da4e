"""REPORT lines of the fault tests (JSON lines) -> the generated blocks of docs/bench/faults.md.

    python3 bench/faults/report.py REPORT.jsonl [DOC.md [OUTDIR]]

Each section the report has data for (restart, hostile, netns, kill) is rendered as markdown.
In DOC, the text between `<!-- begin generated: KEY -->` and `<!-- end generated: KEY -->`
is replaced by it; everything else in DOC (hand-written readings) stays. A section whose
block DOC lacks is written to OUTDIR/KEY.md (default bench/faults/out) and named on stderr.
Without DOC, every section goes to stdout.

netns also writes an SVG bar chart (mean and std per case, one dot per run) next to DOC:
faults_netns.svg (security off; faults_netns_secure.svg with it on).

Rows carry `secure` (DDS Security on or off, bench/faults/run.sh SECURE=both): a section with
both renders the two one after the other in its block, each under its heading, security off
first, so the figures stand side by side.
"""
import json, math, os, re, sys


def restart_md(r):
    o = []
    p = o.append
    p(f"Bridge killed after 10 s, down {r['down_s']:.1f} s, restarted (new process, new episode), "
      "watched by an independent `tending record`. robot_node stale timeout 1.0 s.\n")
    p("| robot | moving cmds in 6 s before kill | last moving cmd after kill [s] | zero cmds while down | first moving cmd after restart [s] |")
    p("|---|---|---|---|---|")
    for x in r["robots"]:
        f = x["first_moving_after_restart_s"]
        p(f"| {x['robot']} | {x['moving_before_kill']} | {x['last_moving_after_kill_s']:.2f} | "
          f"{x['zero_cmds_while_down']} | {'-' if f is None else f'{f:.2f}'} |")
    p(f"\nParts delivered by the restarted bridge in its first {r['after_s']:.0f} s: "
      f"{r['bridge2_parts_delivered_in_10s']:.0f}. Lost: the episode state (the new bridge starts a new episode).")
    return "\n".join(o)


def hostile_md(r):
    o = []
    p = o.append
    p(f"Clean: {r['clean_parts']:.0f} parts in {r['clean_s']:.1f} s. Hostile phase {r['hostile_s']:.0f} s: "
      f"{r['hostile_parts']:.0f} parts; after it ({r['after_s']:.0f} s): {r['after_parts']:.0f} parts. "
      f"Collisions {r['collisions_clean']:.0f} at the end of the clean phase, {r['collisions_end']:.0f} at the end.\n")
    p(f"Sent: NaN pose flood on /robot_0/pose {r['flood_sent']} samples ({r['flood_rate_hz']:.0f} Hz); "
      f"at 20 Hz each: NaN peer /robot_9/pose, huge /machine_7/pose (1e30), 3-byte /robot_8/pose, "
      f"3-byte /robot_2/cmd_vel, NaN /robot_2/cmd_vel, impostor valid /robot_1/pose: {r['other_sent']}.\n")
    p(f"sim_bridge rejected {r['bridge_dropped_decode']:.0f} undecodable and {r['bridge_dropped_non_finite']:.0f} "
      f"non-finite cmd_vel; bodies spawned by hostile traffic: {r['bridge_spawned']:.0f}.\n")
    p("| robot | dropped decode | dropped non-finite | dropped out of room | accepted | zero (own stale) |")
    p("|---|---|---|---|---|---|")
    for x in r["robots"]:
        p(f"| {x['robot']} | {x['dropped_decode']:.0f} | {x['dropped_non_finite']:.0f} | {x['dropped_out_of_room']:.0f} | {x['accepted']:.0f} | {x['zero_own_stale']:.0f} |")
    p("\n| process | RSS before [kB] | RSS after [kB] |\n|---|---|---|")
    for (n, b), (_, a) in zip(r["rss_kb_before"], r["rss_kb_after"]):
        p(f"| {n} | {b} | {a} |")
    return "\n".join(o)


def kill_md(rows):
    """A robot SIGKILLed in a realtime 6.4_2 fleet (tests/faults/kill.rs), per command timeout."""
    o = []
    p = o.append
    p("| bridge | kills | kills with contacts | contact steps of the killed robot (runs with any) | "
      "travel after the kill [m] | moved from 0.7-0.9 s after the kill to its removal [m] | removed after [s] | "
      "live robots' longest cmd_vel gap [s] |")
    p("|---|---|---|---|---|---|---|---|")
    groups = {}
    for r in rows:
        groups.setdefault(r.get("bridge") or f"cmd_vel_timeout_s {r.get('cmd_vel_timeout_s')}", []).append(r)
    for label, rs in groups.items():
        touched = [r["killed_robot_contact_steps"] for r in rs if r["killed_robot_contact_steps"] > 0]
        trav = [r["travelled_after_kill_m"] for r in rs]
        late = [r["moved_after_stop_m"] for r in rs]
        gone = [r["last_pose_after_kill_s"] for r in rs]
        gaps = [r["cmd_gaps_of_live_robots"]["max_s"] for r in rs if r.get("cmd_gaps_of_live_robots")]
        p(f"| {label} | {len(rs)} | {len(touched)} | {', '.join(map(str, touched)) or '-'} | "
          f"{min(trav):.2f}-{max(trav):.2f} | {max(late):.3f} | {min(gone):.2f}-{max(gone):.2f} | "
          f"{f'{max(gaps):.2f}' if gaps else '-'} |")
    return "\n".join(o)


def mean_std(xs):
    xs = [x for x in xs if x is not None and not (isinstance(x, float) and math.isnan(x))]
    if not xs:
        return float("nan"), float("nan"), 0
    m = sum(xs) / len(xs)
    s = math.sqrt(sum((x - m) ** 2 for x in xs) / (len(xs) - 1)) if len(xs) > 1 else float("nan")
    return m, s, len(xs)


# (key, label, decimals, value of one run)
NETNS_METRICS = [
    ("parts", "parts", 1, lambda r: r["parts_delivered"]),
    ("collisions", "collisions", 1, lambda r: r["collisions"]),
    ("mu", "MU", 3, lambda r: r["mu"]),
    ("stale", "own-stale zero ticks", 1, lambda r: r["robot_zero_own_stale"]),
]


def netns_stats(rows):
    cases = list(dict.fromkeys(r["case"] for r in rows))
    st = {}
    for c in cases:
        rs = [r for r in rows if r["case"] == c]
        st[c] = {k: mean_std([f(r) for r in rs]) for k, _, _, f in NETNS_METRICS}
        st[c]["runs"] = rs
    return cases, st


def vs_clean(st, c, k):
    """(ratio to clean, Delta, flag): flag '*' when |Delta| > 2 standard errors of the difference."""
    m, s, n = st[c][k]
    m0, s0, n0 = st["clean"][k]
    d = m - m0
    se = math.sqrt((s * s) / n + (s0 * s0) / n0) if n > 1 and n0 > 1 else float("nan")
    flag = "*" if se == se and abs(d) > 2 * se else ""
    ratio = m / m0 if m0 else float("nan")
    return ratio, d, flag


def netns_md(rows):
    cases, st = netns_stats(rows)
    secs = rows[0]["seconds"]
    seeds = sorted({r.get("seed", 0) for r in rows})
    o = []
    p = o.append
    p(f"{len(rows)} runs: {len(cases)} cases x {len(seeds)} bridge seeds ({', '.join(map(str, seeds))}), "
      f"{secs:.0f} s each, run seed-major (all cases of one seed, then the next seed). "
      "Table: mean (sample std) over the seeds; *vs clean*: difference of the means (and their ratio), marked * when it "
      "exceeds 2 standard errors of the difference (sqrt(s1²/n1 + s2²/n2)); with 3 runs a "
      "side that is a weak test, roughly p < 0.1. Own-stale zero ticks: robot_node ticks (summed over "
      "the 3 robots) on which the robot's own pose was older than its 1 s stale timeout, so it sent a "
      "zero command.\n")

    def cell(c, k, dec):
        m, s, n = st[c][k]
        return f"{m:.{dec}f} ({s:.{dec}f})"

    def rel(c, k):
        if c == "clean" or "clean" not in st:
            return "-"
        ratio, d, flag = vs_clean(st, c, k)
        dec = 3 if k == "mu" else 1
        return f"{d:+.{dec}f} (x{ratio:.2f}){flag}"

    p("| case | runs | parts | collisions | MU | own-stale zero ticks | ticks | crashed runs | parts vs clean | collisions vs clean | MU vs clean | own-stale vs clean |")
    p("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for c in cases:
        rs = st[c]["runs"]
        ticks = mean_std([r["robot_ticks"] for r in rs])[0]
        crashed = sum(1 for r in rs if r["crashed"])
        p(f"| {c} | {len(rs)} | {cell(c, 'parts', 1)} | {cell(c, 'collisions', 1)} | {cell(c, 'mu', 3)} | "
          f"{cell(c, 'stale', 1)} | {ticks:.0f} | {crashed} / {len(rs)} | {rel(c, 'parts')} | "
          f"{rel(c, 'collisions')} | {rel(c, 'mu')} | {rel(c, 'stale')} |")
    p("")
    # paired by seed: the bridge seed fixes the layout, which moves every case alike
    by = {(r["case"], r.get("seed", 0)): r for r in rows}
    if "clean" in st and len(seeds) > 1:
        p(f"Paired by seed (same seed: same layout): case minus clean of the same seed, seeds {', '.join(map(str, seeds))}.\n")
        p("| case | parts | collisions | MU | own-stale zero ticks |")
        p("|---|---|---|---|---|")
        for c in cases:
            if c == "clean":
                continue
            cells = []
            for k, _, dec, f in NETNS_METRICS:
                ds = [f(by[(c, sd)]) - f(by[("clean", sd)]) for sd in seeds if (c, sd) in by and ("clean", sd) in by]
                cells.append(", ".join(f"{d:+.{dec if k == 'mu' else 0}f}" for d in ds))
            p(f"| {c} | " + " | ".join(cells) + " |")
        p("")
    builds = {(r.get("robot_node_mtime"), r.get("sim_bridge_mtime")) for r in rows}
    if len(builds) > 1:
        p(f"**Warning**: the binaries changed during the bench ({len(builds)} different robot_node/sim_bridge "
          "builds, by modification time): another process rebuilt them; the runs are not like for like.\n")
    p("<details><summary>Every run</summary>\n")
    p("| case | seed | parts | collisions | MU | robots at end | cmds accepted | own-stale zero ticks / ticks | crashed |")
    p("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        p(f"| {r['case']} | {r.get('seed', 0)} | {r['parts_delivered']:.0f} | {r['collisions']:.0f} | {r['mu']:.3f} | "
          f"{r['robots']:.0f} | {r['cmds_accepted']:.0f} | {r['robot_zero_own_stale']:.0f} / {r['robot_ticks']:.0f} | "
          f"{', '.join(r['crashed']) or 'none'} |")
    p("\n</details>")
    return "\n".join(o)


def netns_svg(rows):
    """Four panels (parts, collisions, MU, own-stale zero ticks): per case a bar at the mean,
    an error bar of +- one std, a dot per run. Plain SVG, no dependencies."""
    cases, st = netns_stats(rows)
    pw, ph, ml, mt, mb = 230, 200, 40, 28, 40
    W, H = pw * len(NETNS_METRICS) + 10, ph + mt + mb
    colors = {"clean": "#4c72b0", "loss10": "#dd8452", "loss30": "#c44e52", "delay50": "#55a868", "delay200": "#2d7a3e"}
    e = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="11">',
         f'<rect width="{W}" height="{H}" fill="white"/>']
    for i, (k, label, dec, f) in enumerate(NETNS_METRICS):
        x0 = i * pw + ml
        w = pw - ml - 10
        vals = [f(r) for r in rows]
        top = max(max(vals), max(st[c][k][0] + (st[c][k][1] if st[c][k][1] == st[c][k][1] else 0) for c in cases))
        top = top * 1.1 if top > 0 else 1.0
        y = lambda v: mt + ph - ph * v / top
        e.append(f'<text x="{x0 + w / 2}" y="16" text-anchor="middle" font-weight="bold">{label}</text>')
        e.append(f'<line x1="{x0}" y1="{mt}" x2="{x0}" y2="{mt + ph}" stroke="black"/>')
        e.append(f'<line x1="{x0}" y1="{mt + ph}" x2="{x0 + w}" y2="{mt + ph}" stroke="black"/>')
        for t in range(5):
            v = top * t / 4
            e.append(f'<text x="{x0 - 3}" y="{y(v) + 4:.1f}" text-anchor="end">{v:.{dec if k == "mu" else 0}f}</text>')
            e.append(f'<line x1="{x0}" y1="{y(v):.1f}" x2="{x0 + w}" y2="{y(v):.1f}" stroke="#ddd"/>')
        bw = w / len(cases)
        for j, c in enumerate(cases):
            m, s, _ = st[c][k]
            bx = x0 + j * bw + bw * 0.15
            e.append(f'<rect x="{bx:.1f}" y="{y(m):.1f}" width="{bw * 0.7:.1f}" height="{mt + ph - y(m):.1f}" '
                     f'fill="{colors.get(c, "#888")}" opacity="0.75"/>')
            cx = bx + bw * 0.35
            if s == s:
                e.append(f'<line x1="{cx:.1f}" y1="{y(m - s):.1f}" x2="{cx:.1f}" y2="{y(m + s):.1f}" stroke="black" stroke-width="1.5"/>')
                for v in (m - s, m + s):
                    e.append(f'<line x1="{cx - 5:.1f}" y1="{y(v):.1f}" x2="{cx + 5:.1f}" y2="{y(v):.1f}" stroke="black" stroke-width="1.5"/>')
            for q, r in enumerate(st[c]["runs"]):
                e.append(f'<circle cx="{cx - 6 + 6 * (q % 3):.1f}" cy="{y(f(r)):.1f}" r="2.2" fill="black"/>')
            e.append(f'<text x="{cx:.1f}" y="{mt + ph + 14}" text-anchor="end" '
                     f'transform="rotate(-35 {cx:.1f} {mt + ph + 14})">{c}</text>')
    e.append("</svg>")
    return "\n".join(e) + "\n"


MODES = [(False, "DDS Security off"), (True, "DDS Security on (every process its own enclave, enforced)")]


def by_mode(rows, render):
    """`render` of each mode's rows; with both modes, each under its heading."""
    parts = [(title, [r for r in rows if bool(r.get("secure")) == on]) for on, title in MODES]
    parts = [(t, rs) for t, rs in parts if rs]
    if len(parts) == 1:
        return render(parts[0][1])
    return "\n\n".join(f"**{t}**\n\n{render(rs)}" for t, rs in parts)


def main():
    rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
    doc = sys.argv[2] if len(sys.argv) > 2 else None
    outdir = sys.argv[3] if len(sys.argv) > 3 else "bench/faults/out"
    sections = {}
    of = lambda fault: [r for r in rows if r["fault"] == fault]
    # restart and hostile: one run each per mode (the last one if repeated)
    if of("bridge SIGKILLed and restarted"):
        sections["restart"] = by_mode(of("bridge SIGKILLed and restarted"), lambda rs: restart_md(rs[-1]))
    if of("hostile publisher"):
        sections["hostile"] = by_mode(of("hostile publisher"), lambda rs: hostile_md(rs[-1]))
    kills = of("robot SIGKILLed in a realtime fleet")
    if kills:
        sections["kill"] = by_mode(kills, kill_md)
    netns = of("netns")
    if netns:
        sections["netns"] = by_mode(netns, netns_md)
    if doc is None:
        for k, v in sections.items():
            print(f"<!-- {k} -->\n{v}\n")
        return
    text = open(doc).read()
    for k, v in sections.items():
        pat = re.compile(rf"(<!-- begin generated: {k} -->\n).*?(<!-- end generated: {k} -->)", re.S)
        if pat.search(text):
            text = pat.sub(lambda m: m.group(1) + v + "\n" + m.group(2), text)
            print(f"{doc}: replaced the generated block `{k}`", file=sys.stderr)
        else:
            os.makedirs(outdir, exist_ok=True)
            path = os.path.join(outdir, f"{k}.md")
            open(path, "w").write(v + "\n")
            print(f"{doc} has no generated block `{k}`: wrote {path}", file=sys.stderr)
    open(doc, "w").write(text)
    for on, name in [(False, "faults_netns.svg"), (True, "faults_netns_secure.svg")]:
        rs = [r for r in netns if bool(r.get("secure")) == on]
        if rs:
            svg = os.path.join(os.path.dirname(doc) or ".", name)
            open(svg, "w").write(netns_svg(rs))
            print(f"wrote {svg}", file=sys.stderr)


if __name__ == "__main__":
    main()
