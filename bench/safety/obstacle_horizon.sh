#!/usr/bin/env bash
# ADR 0030 side by side, one binary, one run: the obstacle horizon of the policy's ORCA
# filter and of greedy-ORCA.
#   1. the tuning screen: seed 7 x 20 episodes, 28 setups, the bundled policy at filter
#      horizons 0.1-0.3 s and greedy-ORCA at 0.1, 0.15 and 0.3 s;
#   2. the evaluation: seeds 0-2 x 50 episodes, 28 setups: greedy, greedy-ORCA at 0.3 s
#      and 0.15 s, the policy at 0.3 s and 0.15 s.
# Results under OUT (default runs/obstacle_horizon), then the geometric means of parts
# against the 0.3 s runs (bench/safety/horizon_ratios.py). About 30 minutes on this
# machine's two cores.
set -euo pipefail
cd "$(dirname "$0")/../.."
bin="${TENDING_BIN:-target/release/tending}"
out="${OUT:-runs/obstacle_horizon}"
ck=policy/pretrained/smappo_6.4_2.safetensors
setups=2.2_2,4.2_2,6.4_2,12.8_4,18.12_6,24.16_8,30.20_10,36.24_12,42.28_14,100.16_2,3.3_1,8.6_3,10.4_2,20.10_4,50.20_5,75.30_10,2.8_1,3.1_1,5.10_2,16.4_1,30.6_1,40.40_2,60.12_3,64.32_16,80.40_4,90.20_3,100.8_1,100.50_10
mkdir -p "$out/screen" "$out/eval"
filter() { # HORIZON -> a margins file (plan::margins) with the filter's obstacle horizon
    local f="$out/margins/filter-$1.toml"; mkdir -p "$out/margins"
    printf '[filter]\nobstacle_horizon = %s\n' "$1" > "$f"; echo "$f"
}
script() { # HORIZON -> a margins file with greedy-ORCA's
    local f="$out/margins/greedy-orca-$1.toml"; mkdir -p "$out/margins"
    printf '[greedy_orca]\nobstacle_horizon = %s\n' "$1" > "$f"; echo "$f"
}
run() { # NAME ARGS...: one evaluation into $out/NAME
    local name=$1
    shift
    echo "[$(date +%T)] $name"
    "$bin" eval --setups "$setups" "$@" --out "$out/$name" > "$out/$name.log" 2>&1
}
for h in 0.1 0.12 0.15 0.18 0.2 0.3; do
    run "screen/policy-$h" --checkpoint "$ck" --margins "$(filter "$h")" --episodes 20 --seeds 7
done
for h in 0.1 0.15 0.3; do
    run "screen/greedy-orca-$h" --policy greedy-orca --margins "$(script "$h")" --episodes 20 --seeds 7
done
run eval/greedy --policy greedy
for h in 0.15 0.3; do
    run "eval/greedy-orca-$h" --policy greedy-orca --margins "$(script "$h")"
    run "eval/policy-$h" --checkpoint "$ck" --margins "$(filter "$h")"
done
python3 bench/safety/horizon_ratios.py "$out"
