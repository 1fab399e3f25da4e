#!/usr/bin/env bash
# What limits issue 10's 1.1x target (docs/RESULTS.md 7.15): the bundled policy's
# ready-part waits per machine (policy/examples/machine_waits.rs) on all 28 evaluation
# setups, seeds 0-2 x 50 episodes (the episodes `tending eval` runs), then one table
# against 1.1x greedy-ORCA and the parts bound (docs/safety/*/greedy-orca, bound.csv).
# About 26 minutes on this machine's two cores.
# Usage: bench/safety/machine_waits.sh  (EPISODES, SEEDS, OUT override)
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release -p learn --example machine_waits
bin=target/release/examples/machine_waits
ck=policy/pretrained/smappo_6.4_2.safetensors
eps="${EPISODES:-50}"
seeds="${SEEDS:-0 1 2}"
out="${OUT:-docs/safety/waits}"
mkdir -p "$out"
setups="2.2_2 4.2_2 6.4_2 12.8_4 18.12_6 24.16_8 30.20_10 36.24_12 42.28_14 100.16_2
3.3_1 8.6_3 10.4_2 20.10_4 50.20_5 75.30_10 2.8_1 3.1_1 5.10_2 16.4_1 30.6_1 40.40_2
60.12_3 64.32_16 80.40_4 90.20_3 100.8_1 100.50_10"
n=0
for s in $setups; do
    n=$((n + 1))
    echo "[$n/28] $s"
    for seed in $seeds; do
        "$bin" "$ck" "$s" "$eps" "$seed" > "$out/$s.$seed.txt"
    done
done
python3 bench/safety/waits_table.py "$out" > "$out/waits.md"
cat "$out/waits.md"
