#!/usr/bin/env bash
# Fault runs -> docs/bench/faults.md. Runs the tests of tests/faults/ with longer and more
# cases (netns: clean, 10 % and 30 % loss, 50 ms and 200 ms cmd delay, 30 s each), collects
# their REPORT lines and writes the markdown. Needs root (netns cases) and iptables.
# ~6 min on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
out="bench/faults/out"; mkdir -p "$out"
rep="$out/report.jsonl"; : > "$rep"
export TENDING_FAULTS_REPORT="$PWD/$rep"
export TENDING_NETNS_CASES="${TENDING_NETNS_CASES:-clean,loss10,loss30,delay50,delay200}"
export TENDING_NETNS_S="${TENDING_NETNS_S:-30}"
cargo build --release -j 2 -p tending --bin tending
cargo build --release -j 2 -p sim-bridge -p robot-node
for t in faults_bridge_restart faults_hostile faults_netns; do
    cargo test --release -j 2 -p sim-bridge --test "$t" -- --nocapture 2>&1 | tee "$out/$t.log" | grep -E "REPORT|test result" || true
done
python3 bench/faults/report.py "$rep" > docs/bench/faults.md
echo "wrote docs/bench/faults.md"
