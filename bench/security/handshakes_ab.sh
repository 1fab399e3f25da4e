#!/usr/bin/env bash
# Secure start-up side by side: two secure 6.4_2 lockstep fleets started together, one on
# the binaries in BEFORE_DIR and one on those in AFTER_DIR (each a directory holding
# tending, robot_node and sim_bridge), domains swapped every run, with secure_discovery
# debug logs; then the handshake times of each (handshake_times.py) and every fleet's
# final despawned / lockstep_timeouts. docs/bench/security.md has the results.
# usage: bench/security/handshakes_ab.sh BEFORE_DIR AFTER_DIR OUT_DIR [RUNS=10]
set -euo pipefail
before="$1"; after="$2"; out="$3"; runs="${4:-10}"
here="$(cd "$(dirname "$0")" && pwd)"
export RUST_LOG="info,rustdds::discovery::secure_discovery=debug"
mkdir -p "$out"
for it in $(seq 1 "$runs"); do
    if [ $((it % 2)) = 0 ]; then da=61; db=63; else da=63; db=61; fi
    echo "run $it of $runs" >&2
    for v in before after; do
        d="$out/${v}_$it"; mkdir -p "$d"
        if [ $v = before ]; then bin="$before"; dom=$da; else bin="$after"; dom=$db; fi
        "$bin/tending" fleet --setup 6.4_2 --secure --keystore "$out/ks_$v" --duration 25 \
            --domain "$dom" --log-dir "$d" --no-stdin --mode lockstep > "$d/out.txt" 2>&1 &
    done
    wait
done
for v in before after; do
    echo "== $v: handshake times"
    python3 "$here/handshake_times.py" "$out/${v}_"*
    echo "== $v: fleets (despawned, lockstep_timeouts)"
    for d in "$out/${v}_"*; do
        grep -h -o '"despawned":[0-9]*,"done":[a-z]*,"lockstep_timeouts":[0-9]*' "$d/out.txt" || echo "no final line in $d"
    done | sort | uniq -c
done
