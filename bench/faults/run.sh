#!/usr/bin/env bash
# Fault runs -> docs/bench/faults.md. Runs the fault tests of tests/faults/ with longer and
# more cases, collects their REPORT lines (bench/faults/out/report.jsonl) and lets
# bench/faults/report.py write the figures.
#
#   bench/faults/run.sh [netns] [restart] [hostile] [kill]     (default: all four)
#
# kill (section (d)): `kill robot_1` in a realtime 6.4_2 `tending fleet`, once per SEED:AT
# of TENDING_KILL_CASES (AT = seconds after the start; 10 cases, ~25 s each), with the
# fleet's default command timeout unless TENDING_KILL_CMD_TIMEOUT_S is set.
#
# netns (section (b)): cases clean, loss10, loss30, delay50, delay200 (delay both ways:
# sim_bridge's test_cmd_delay_ms and test_state_delay_ms), TENDING_NETNS_S seconds each
# (30), once per bridge seed of TENDING_NETNS_SEEDS (0,1,2), seed-major; mean (std) per
# case, vs clean, and an SVG chart (docs/bench/faults_netns.svg). 5 x 3 x 30 s: ~10 min.
# Needs root (ip netns, veth) and iptables. One "RUN i/n ..." line per run as it goes.
#
# report.py replaces only the generated blocks of docs/bench/faults.md (between
# `<!-- begin generated: KEY -->` and `<!-- end generated: KEY -->`); hand-written text
# around them stays. A section without such a block in the doc is written to
# bench/faults/out/KEY.md instead.
#
# SECURE=both (default) runs every selection twice, security off then on
# (TENDING_FAULTS_SECURE=1: every process with its own enclave, enforced; the hostile node
# an outsider without one), and report.py puts the two side by side; SECURE=0 or SECURE=1
# runs one mode.
#
# Every cargo command runs under `nice -n 19` (the machine is shared with trainings).
set -euo pipefail
cd "$(dirname "$0")/../.."
sel=("$@")
[ ${#sel[@]} -eq 0 ] && sel=(netns restart hostile kill)
out="bench/faults/out"; mkdir -p "$out"
rep="$out/report.jsonl"; : > "$rep"
export TENDING_FAULTS_REPORT="$PWD/$rep"
export TENDING_NETNS_CASES="${TENDING_NETNS_CASES:-clean,loss10,loss30,delay50,delay200}"
export TENDING_NETNS_S="${TENDING_NETNS_S:-30}"
export TENDING_NETNS_SEEDS="${TENDING_NETNS_SEEDS:-0,1,2}"
for s in "${sel[@]}"; do
    case "$s" in
        netns)
            [ "$(id -u)" -eq 0 ] || { echo "netns needs root (ip netns, veth, iptables)" >&2; exit 1; }
            command -v iptables >/dev/null || { echo "iptables missing: apt-get install -y iptables" >&2; exit 1; }
            ;;
        restart|hostile|kill) ;;
        *) echo "unknown selection $s (netns|restart|hostile|kill)" >&2; exit 2 ;;
    esac
done
nice -n 19 cargo build --release -p tending --bin tending
nice -n 19 cargo build --release -p sim-bridge -p robot-node --bins
start=$(date +%s)
case "${SECURE:-both}" in
    both) modes=(0 1) ;; 0|1) modes=("$SECURE") ;;
    *) echo "SECURE must be both, 0 or 1" >&2; exit 2 ;;
esac
for mode in "${modes[@]}"; do
    export TENDING_FAULTS_SECURE="$mode"
    echo "#### DDS Security $([ "$mode" = 1 ] && echo on || echo off)"
    for s in "${sel[@]}"; do
        case "$s" in
            netns) t=faults_netns
                n=$(( $(tr ',' '\n' <<<"$TENDING_NETNS_CASES" | wc -l) * $(tr ',' '\n' <<<"$TENDING_NETNS_SEEDS" | wc -l) ))
                echo "netns: $n runs of $TENDING_NETNS_S s (cases $TENDING_NETNS_CASES; seeds $TENDING_NETNS_SEEDS)" ;;
            restart) t=faults_bridge_restart ;;
            hostile) t=faults_hostile ;;
            kill)
                cases="${TENDING_KILL_CASES:-0:12,1:8,1:14,2:11,2:20,3:9,4:13,4:19,5:16,5:23}"
                echo "== faults_kill ($(( $(date +%s) - start )) s): cases $cases"
                : > "$out/faults_kill_$mode.log"
                for c in ${cases//,/ }; do
                    TENDING_KILL_SEED="${c%%:*}" TENDING_KILL_AT_S="${c##*:}" \
                        nice -n 19 cargo test --release -p sim-bridge --test faults_kill -- --nocapture 2>&1 \
                        | tee -a "$out/faults_kill_$mode.log" | grep --line-buffered -E "killed .* after the start|^test result|panicked" || true
                done
                continue ;;
        esac
        echo "== $t ($(( $(date +%s) - start )) s)"
        nice -n 19 cargo test --release -p sim-bridge --test "$t" -- --nocapture 2>&1 \
            | tee "$out/${t}_$mode.log" | grep --line-buffered -E "^RUN |^test result|panicked" || true
    done
done
python3 bench/faults/report.py "$rep" docs/bench/faults.md "$out"
echo "done in $(( $(date +%s) - start )) s"
