#!/usr/bin/env bash
# Fault runs -> docs/bench/faults.md. Runs the fault tests of tests/faults/ with longer and
# more cases, collects their REPORT lines (bench/faults/out/report.jsonl) and lets
# bench/faults/report.py write the figures.
#
#   bench/faults/run.sh [netns] [restart] [hostile]     (default: all three)
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
# Every cargo command runs under `nice -n 19` (the machine is shared with trainings).
set -euo pipefail
cd "$(dirname "$0")/../.."
sel=("$@")
[ ${#sel[@]} -eq 0 ] && sel=(netns restart hostile)
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
        restart|hostile) ;;
        *) echo "unknown selection $s (netns|restart|hostile)" >&2; exit 2 ;;
    esac
done
nice -n 19 cargo build --release -p tending --bin tending
nice -n 19 cargo build --release -p sim-bridge -p robot-node --bins
start=$(date +%s)
for s in "${sel[@]}"; do
    case "$s" in
        netns) t=faults_netns
            n=$(( $(tr ',' '\n' <<<"$TENDING_NETNS_CASES" | wc -l) * $(tr ',' '\n' <<<"$TENDING_NETNS_SEEDS" | wc -l) ))
            echo "netns: $n runs of $TENDING_NETNS_S s (cases $TENDING_NETNS_CASES; seeds $TENDING_NETNS_SEEDS)" ;;
        restart) t=faults_bridge_restart ;;
        hostile) t=faults_hostile ;;
    esac
    echo "== $t ($(( $(date +%s) - start )) s)"
    nice -n 19 cargo test --release -p sim-bridge --test "$t" -- --nocapture 2>&1 \
        | tee "$out/$t.log" | grep --line-buffered -E "^RUN |^test result|panicked" || true
done
python3 bench/faults/report.py "$rep" docs/bench/faults.md "$out"
echo "done in $(( $(date +%s) - start )) s"
