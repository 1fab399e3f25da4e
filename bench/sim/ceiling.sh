#!/usr/bin/env bash
# What two cores give two independent single-threaded workers on this machine, the ceiling
# for any split of one batch over two threads, measured beside VecEnv (issue 37's target:
# 32 envs at >= 1.8x one env's agent-steps/s).
#
#   bench/sim/ceiling.sh [SECONDS] [ROUNDS] [SETUP...]   (defaults: 2 5 6.4_2 14.10_4 100.16_2)
#
# Per setup and round, one after another: one process stepping 1 env (alone); two
# processes at once, each stepping 16 envs in a loop (the ceiling: no sharing, no
# synchronisation, their rates summed); one process stepping 32 envs by VecEnv on both
# cores. Each ratio is the median over rounds of that round's ratio to `alone` (adjacent
# measurements: on this VM the same measurement drifts by 1.5x within minutes).
# Stop other work (the campaign: kill -STOP) first. Prints a Markdown table.
set -euo pipefail
cd "$(dirname "$0")/../.."
SECS=${1:-2}
ROUNDS=${2:-5}
if [ $# -gt 2 ]; then SETUPS=("${@:3}"); else SETUPS=(6.4_2 14.10_4 100.16_2); fi
cargo build --release -q -p sim --example vec_scaling
BIN=target/release/examples/vec_scaling
rate() { VEC_SCALING_ONLY=$1 "$BIN" "$2" "$3" "$SECS" | awk '{print $(NF-1)}'; }
pair() {
    local a b
    a=$(mktemp) b=$(mktemp)
    rate loop "$1" 16 >"$a" &
    rate loop "$1" 16 >"$b" &
    wait
    awk '{s += $1} END {print s}' "$a" "$b"
    rm -f "$a" "$b"
}
median() { tr ' ' '\n' | sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
div() { awk -v a="$1" -v b="$2" 'BEGIN {printf "%.2f", a / b}'; }
echo "| setup | 1 env alone (agent-steps/s) | two 16-env processes / alone, per round | median | VecEnv 32 / alone, per round | median | VecEnv / two processes (median) |"
echo "|---|---|---|---|---|---|---|"
for s in "${SETUPS[@]}"; do
    alone=() pr=() vr=() vp=()
    for _ in $(seq "$ROUNDS"); do
        a=$(rate loop "$s" 1)
        p=$(pair "$s")
        v=$(rate vec "$s" 32)
        alone+=("$a") pr+=("$(div "$p" "$a")") vr+=("$(div "$v" "$a")") vp+=("$(div "$v" "$p")")
    done
    echo "| $s | $(echo "${alone[*]}" | median) | ${pr[*]} | $(echo "${pr[*]}" | median)x | ${vr[*]} | **$(echo "${vr[*]}" | median)x** | $(echo "${vp[*]}" | median) |"
done
