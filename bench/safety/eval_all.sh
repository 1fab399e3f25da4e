#!/usr/bin/env bash
# Issue 10's evaluation: every method on every setup the targets name (6.4_2, the paper's
# Table III, 100.16_2), argmax, 3 seeds x 50 episodes, then the target table and the
# Pareto plot. Usage: bench/safety/eval_all.sh [method ...] (default: all of them).
# Methods: greedy, greedy-orca, targets (the bundled target-action policy, behind the
# filter it was trained with), smappo, smappo-orca, smappo-shield (the paper's 5-move
# policy, smappo_moves_6.4_2), and any NAME=CHECKPOINT[:orca|:shield] for a new checkpoint.
# The setups issue 10 does not name (docs/RESULTS.md 7.5-7.6):
#   SETUPS=3.3_1,8.6_3,10.4_2,20.10_4,50.20_5,75.30_10 OUT=docs/safety/eval_extra \
#     TABLE=docs/safety/eval_extra/targets.md PARETO= bench/safety/eval_all.sh greedy greedy-orca targets
#   SETUPS=2.8_1,3.1_1,5.10_2,16.4_1,30.6_1,40.40_2,60.12_3,64.32_16,80.40_4,90.20_3,100.8_1,100.50_10 \
#     OUT=docs/safety/eval_wide TABLE=docs/safety/eval_wide/targets.md PARETO= bench/safety/eval_all.sh greedy greedy-orca targets
set -euo pipefail
cd "$(dirname "$0")/../.."
bin="${TENDING_BIN:-target/release/tending}"
setups="${SETUPS:-2.2_2,4.2_2,6.4_2,12.8_4,18.12_6,24.16_8,30.20_10,36.24_12,42.28_14,100.16_2}"
out="${OUT:-docs/safety/eval}"
old="${OLD_CKPT:-policy/pretrained/smappo_moves_6.4_2.safetensors}"
new="${NEW_CKPT:-policy/pretrained/smappo_6.4_2.safetensors}"
methods=("$@")
[ ${#methods[@]} -gt 0 ] || methods=(greedy greedy-orca targets smappo smappo-orca smappo-shield)
for m in "${methods[@]}"; do
    case "$m" in
        greedy|greedy-orca) args=(--policy "$m") ;;
        targets) args=(--checkpoint "$new") ;;
        smappo) args=(--checkpoint "$old") ;;
        smappo-orca) args=(--checkpoint "$old" --orca-filter) ;;
        smappo-shield) args=(--checkpoint "$old" --shield) ;;
        *=*)
            name="${m%%=*}"; spec="${m#*=}"; ck="${spec%%:*}"
            case "$spec" in
                *:orca) args=(--checkpoint "$ck" --orca-filter) ;;
                *:shield) args=(--checkpoint "$ck" --shield) ;;
                *) args=(--checkpoint "$ck") ;;
            esac
            m="$name" ;;
        *) echo "unknown method $m" >&2; exit 2 ;;
    esac
    echo "== $m: ${args[*]}"
    "$bin" eval "${args[@]}" --setups "$setups" --episodes 50 --seeds 0,1,2 --out "$out/$m"
done
# Other setup lists (OUT=docs/safety/eval_extra, docs/safety/eval_wide) get their table
# beside their results and no Pareto plot: TABLE=$OUT/targets.md PARETO=.
table="${TABLE:-docs/safety/targets.md}"
pareto="${PARETO-docs/safety/pareto.png}"
python3 bench/safety/targets.py "$out" > "$table"
echo "wrote $table"
if [ -n "$pareto" ]; then
    "$bin" plot pareto "$out"/*/results.csv --out "$pareto"
    echo "wrote $pareto"
fi
