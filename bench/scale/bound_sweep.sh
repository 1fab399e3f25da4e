#!/usr/bin/env bash
# Parts and contacts against the observation bound on grown floors (issue 46, docs/bench/scale.md):
#
#   bench/scale/bound_sweep.sh            # runs what is missing into runs/scale/, then the table
#
# Every method on 100.66_33, 300.200_100 and 1000.666_333 (grown floor, docs/adr/0037) with
# each robot observing everything or its K nearest (K = 4, 8, 16), EPISODES full 200-step
# episodes on eval seeds SEEDS. Whole-floor matching at 1,000 robots (16 ms per
# robot-decision here: an hour per episode) and the 5-move network over 999 peers are
# skipped at 1,000 robots and said so in the table.
set -euo pipefail
cd "$(dirname "$0")/../.."
T="${TENDING:-target/release/tending}"
EPISODES="${EPISODES:-2}"
SEEDS="${SEEDS:-0,1}"
OUT=runs/scale
[ -x "$T" ] || cargo build --release --bin tending
mkdir -p "$OUT"
methods=("--policy greedy-orca" "--policy matching-orca" "--checkpoint policy/pretrained/smappo_6.4_2.safetensors" "--checkpoint policy/pretrained/smappo_moves_6.4_2.safetensors")
names=(greedy-orca matching-orca shipped moves)
for setup in 100.66_33 300.200_100 1000.666_333; do
    for k in all 4 8 16; do
        for i in "${!methods[@]}"; do
            name="${names[$i]}"
            d="$OUT/$setup/$k/$name"
            [ -f "$d/results.csv" ] && continue
            if [ "$k" = all ] && [ "$setup" = 1000.666_333 ] && [ "$name" != greedy-orca ]; then
                continue # whole-floor: matching ~1 h per episode here, the 5-move network
                         # attending over 999 peers ~4 min (docs/bench/scale_decisions.md)
            fi
            bound=(); [ "$k" = all ] || bound=(--nearest "$k")
            echo "== $setup $k $name ($(date -u +%T))"
            # shellcheck disable=SC2086
            "$T" eval ${methods[$i]} --floor grown "${bound[@]}" --setups "$setup" \
                --episodes "$EPISODES" --seeds "$SEEDS" --out "$d" > /dev/null
        done
    done
done
python3 bench/scale/bound_table.py "$OUT" > docs/bench/scale_bound.md
echo "wrote docs/bench/scale_bound.md"
