#!/usr/bin/env bash
# The safety margin's Pareto front (docs/RESULTS.md 7.7): the bundled policy behind the
# ORCA filter at several rest / full-speed clearances, and greedy-ORCA at several
# clearances, on the storage-bound setups and two others; then one Pareto plot.
# Usage: bench/safety/margin_sweep.sh  (EPISODES, SEEDS, SETUPS, OUT override)
set -euo pipefail
cd "$(dirname "$0")/../.."
bin="${TENDING_BIN:-target/release/tending}"
ck=policy/pretrained/smappo_6.4_2.safetensors
setups="${SETUPS:-6.4_2,30.6_1,40.40_2,42.28_14,60.12_3,80.40_4,90.20_3,100.8_1,100.16_2}"
eps="${EPISODES:-30}"
seeds="${SEEDS:-0,1,2}"
out="${OUT:-docs/safety/margin}"
margins() { # TOML text -> a margins file (plan::margins) for this point of the sweep
    local f; f="$(mktemp -t margins.XXXXXX.toml)"; printf '%b' "$1" > "$f"; echo "$f"
}
run() { # name, eval flags...
    local name=$1; shift
    echo "== $name"
    "$bin" eval "$@" --setups "$setups" --episodes "$eps" --seeds "$seeds" --out "$out/$name" | grep parts
}
for rf in 35/40 30/40 25/40 30/30 25/25 20/20; do
    rest=${rf%/*}; full=${rf#*/}
    run "policy-$rest-$full" --checkpoint "$ck" \
        --margins "$(margins "[filter]\\nrest_clearance = 0.0$rest\\nclearance = 0.0$full\\n")"
done
for c in 15 20 25 30 35 40; do
    run "greedy-orca-$c" --policy greedy-orca --margins "$(margins "[greedy_orca]\\nclearance = 0.0$c\\n")"
done
"$bin" plot pareto "$out"/*/results.csv --sweep --out "$out/pareto.png" --title "parts vs contacts: the safety margin (policy: rest/full-speed clearance; greedy-ORCA: its clearance)"
echo "wrote $out/pareto.png"
