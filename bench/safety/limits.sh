#!/usr/bin/env bash
# Issue 10's closing figures and table, from the committed evaluation files (no new runs):
#   docs/safety/limits.png   every method's parts / the best script's, per setup, with the
#                            1.1x target and the parts bound's ceiling (`tending plot limits`);
#   docs/safety/limits.md    the same as a table (bench/safety/limits_table.py);
#   docs/safety/pareto28.png parts vs contacts per robot-step on all 28 setups
#                            (`tending plot pareto`).
# Methods: greedy, greedy-ORCA, greedy-ORCA with the filter's 0.15 s obstacle horizon
# (docs/adr/0030; not a target script), matching-ORCA (the always-"matched" script) and
# the bundled policy, seeds 0-2 x 50 episodes each (docs/RESULTS.md 7.18).
set -euo pipefail
cd "$(dirname "$0")/../.."
bin="${TENDING_BIN:-target/release/tending}"
s=docs/safety
groups=(eval eval_extra eval_wide)
files=()
for m in greedy greedy-orca; do
    for g in "${groups[@]}"; do files+=("$s/$g/$m/results.csv"); done
done
files+=("$s/obstacles/greedy-orca-0.15/results.csv" "$s/matching/matching-orca/results.csv")
for g in "${groups[@]}"; do files+=("$s/$g/targets/results.csv"); done
bounds=()
for g in "${groups[@]}"; do bounds+=("$s/$g/bound.csv"); done
"$bin" plot limits "${files[@]}" --bound "${bounds[@]}" --out "$s/limits.png"
python3 bench/safety/limits_table.py "$s/eval" "$s/eval_extra" "$s/eval_wide" \
    --compare "matching-ORCA=$s/matching/matching-orca/results.csv" \
    --compare "greedy-ORCA obstacles 0.15 s=$s/obstacles/greedy-orca-0.15/results.csv" > "$s/limits.md"
"$bin" plot pareto "${files[@]}" --out "$s/pareto28.png" \
    --title "parts vs contacts per robot-step, 28 setups (seeds 0-2 x 50 episodes)"
echo "wrote $s/limits.png $s/limits.md $s/pareto28.png"
