#!/usr/bin/env bash
# The paper's four experiments (section V) with `tending train` / `tending eval`.
#
#   bench/experiments/run.sh A|B|C|D|R|all
#
# Budget: SCALE (default 0.1) multiplies every episode count of the paper (2,000 initial
# episodes, 100 per curriculum step, 100 for 100.16_2), the same for SMAPPO and MAPPO so the
# comparison stays fair; SEEDS (default "0 1 2") are training seeds; EVAL_EPISODES (default
# 50) episodes per evaluation with eval seed 0. Each row of a table is mean (std) over the
# training seeds. Runs land in runs/exp/<name>/, tables in docs/experiments/<name>.md.
# A 2,000-episode 6.4_2 training takes ~20 min on the 2-core dev machine, so SCALE=1 with 3
# seeds is hours per experiment; `tending train --resume` continues an interrupted run.
#
#   A  full retraining: 6.4_2 8.6_2 10.6_4 12.8_4 14.10_4 (+100.16_2 at 100 x SCALE episodes
#      when FULL_100=1), SMAPPO vs setup-specific MAPPO (input sized to the setup)
#   B  curriculum: 6.4_2 for 2,000 x SCALE, then +6 robots, +4 machines, +2 storages every
#      100 x SCALE episodes up to 24.16_8; MAPPO zero-padded to 24.16_8
#   C  zero-shot: the 6.4_2 models of A evaluated on 2.2_2 ... 42.28_14 (MAPPO padded to
#      42.28_14, trained as such)
#   D  curriculum with a short (200 x SCALE) initial training
#   R  beyond the paper: randomized counts per update (RANGE, default 2..12.2..8_1..4) for
#      C's budget, evaluated zero-shot on C's setups
#
# Every experiment also evaluates the scripted greedy baseline on its setups (same episodes
# and eval seed, runs/exp/<name>/greedy/eval, skipped when already there), puts the paper's
# MU next to ours (bench/experiments/paper_mu.csv: Tables I-IV) and draws
# docs/experiments/<name>_{parts,collisions,mu,curves}.png with `tending plot`. The text
# under the table's marker line in docs/experiments/<name>.md survives regeneration.
set -euo pipefail
cd "$(dirname "$0")/../.."
SCALE="${SCALE:-0.1}"
SEEDS="${SEEDS:-0 1 2}"
EVAL_EPISODES="${EVAL_EPISODES:-50}"
# TENDING: the binary to use (a copy keeps a long run safe from rebuilds of target/).
T="${TENDING:-target/release/tending}"
[ -x "$T" ] || cargo build --release --bin tending
eps() { python3 -c "import math,sys; print(max(8, int(math.ceil($1 * $SCALE / 8.0)) * 8))"; }
mkdir -p runs/exp docs/experiments

train_cfg() { # name max_robots max_machines max_storages -> path of a train TOML
    local f="runs/exp/$1.train.toml"
    cat > "$f" <<TOML
n_envs = 8
ppo_epoch = 10
num_mini_batch = 4
mappo_max_robots = $2
mappo_max_machines = $3
mappo_max_storages = $4
TOML
    echo "$f"
}

counts() { echo "$1" | tr '._' '  '; }

train() { # out model seed cfg args...
    local out="$1" model="$2" seed="$3" cfg="$4"; shift 4
    if [ -f "$out/policy.safetensors" ] && [ -f "$out/.done" ]; then return; fi
    local resume=(); [ -f "$out/trainer_state.safetensors" ] && resume=(--resume)
    echo "== train $model seed $seed -> $out ($*)"
    "$T" train --model "$model" --seed "$seed" --config "$cfg" --out "$out" --quiet "${resume[@]}" "$@"
    touch "$out/.done"
}

has_eval() { # results.csv setups: every setup evaluated with EVAL_EPISODES episodes?
    [ -f "$1" ] && python3 - "$1" "$2" "$EVAL_EPISODES" <<'PY'
import csv, sys
got = {r["setup"] for r in csv.DictReader(open(sys.argv[1])) if r["episodes"] == sys.argv[3]}
sys.exit(0 if set(sys.argv[2].split(",")) <= got else 1)
PY
}

evaluate() { # checkpoint setups out (skipped when out has them all, newer than checkpoint)
    [ "$3/results.csv" -nt "$1" ] && has_eval "$3/results.csv" "$2" && return
    "$T" eval --checkpoint "$1" --setups "$2" --episodes "$EVAL_EPISODES" --seeds 0 --out "$3" >/dev/null
}

greedy() { # name setups: the scripted baseline on the experiment's setups
    local out="runs/exp/$1/greedy/eval"
    has_eval "$out/results.csv" "$2" && return
    echo "== eval greedy -> $out ($2)"
    "$T" eval --policy greedy --setups "$2" --episodes "$EVAL_EPISODES" --seeds 0 --out "$out" >/dev/null
}

plot_bin() { # a tending that has `plot` (TENDING may be an older copy)
    if "$T" plot --help >/dev/null 2>&1; then echo "$T"; return; fi
    target/release/tending plot --help >/dev/null 2>&1 || cargo build --release --bin tending >&2
    echo target/release/tending
}

table() { # name title csv-glob...
    local name="$1" title="$2"; shift 2
    python3 bench/experiments/table.py --exp "$name" --paper bench/experiments/paper_mu.csv \
        --eval-episodes "$EVAL_EPISODES" --out "docs/experiments/$name.md" \
        "$title" "$SCALE" "$SEEDS" "$@"
    echo "wrote docs/experiments/$name.md"
    "$(plot_bin)" plot bars --out "docs/experiments/$name" --title "$title" \
        --paper bench/experiments/paper_mu.csv --experiment "$name" "$@" \
        || echo "!! plot bars for $name failed" >&2
}

curves() { # name title log.csv...
    local name="$1" title="$2"; shift 2
    "$(plot_bin)" plot curves --out "docs/experiments/${name}_curves.png" --title "$title" "$@" \
        || echo "!! plot curves for $name failed" >&2
}

exp_a() {
    local setups="6.4_2 8.6_2 10.6_4 12.8_4 14.10_4"
    [ "${FULL_100:-0}" = 1 ] && setups="$setups 100.16_2"
    for s in $setups; do
        local n e; read -r nr nm ns <<<"$(counts "$s")"
        e=$(eps 2000); [ "$s" = 100.16_2 ] && e=$(eps 100)
        local cfg; cfg=$(train_cfg "A_$s" "$nr" "$nm" "$ns")
        for seed in $SEEDS; do
            for m in smappo mappo; do
                local out="runs/exp/A/$s/$m/seed$seed"
                train "$out" "$m" "$seed" "$cfg" --setup "$s" --episodes "$e"
                evaluate "$out/policy.safetensors" "$s" "$out/eval"
            done
        done
    done
    greedy A "${setups// /,}"
    table A "A: full retraining" runs/exp/A/*/*/seed*/eval/results.csv runs/exp/A/greedy/eval/results.csv
    curves A "A: full retraining, training per setup" --metrics reward,mu runs/exp/A/*/*/seed*/log.csv
}

# Zero-shot experiments (C, R): train on 6.4_2-sized data (MAPPO padded to 42.28_14), then
# evaluate every model on the nine zero-shot setups.
ZERO_SHOT_SETUPS=6.4_2,2.2_2,4.2_2,12.8_4,18.12_6,24.16_8,30.20_10,36.24_12,42.28_14
zero_shot() { # name table-title curves-title train-args...
    local name="$1" title="$2" ctitle="$3"; shift 3
    local cfg; cfg=$(train_cfg "$name" 42 28 14)
    local e; e=$(eps 2000)
    for seed in $SEEDS; do
        for m in smappo mappo; do
            local out="runs/exp/$name/$m/seed$seed"
            train "$out" "$m" "$seed" "$cfg" "$@" --episodes "$e"
            evaluate "$out/policy.safetensors" "$ZERO_SHOT_SETUPS" "$out/eval"
        done
    done
    greedy "$name" "$ZERO_SHOT_SETUPS"
    table "$name" "$title" runs/exp/"$name"/*/seed*/eval/results.csv runs/exp/"$name"/greedy/eval/results.csv
    curves "$name" "$ctitle" runs/exp/"$name"/*/seed*/log.csv
}
exp_c() { zero_shot C "C: zero-shot from 6.4_2" "C: training on 6.4_2" --setup 6.4_2; }

curriculum() { # name initial-episodes
    local name="$1" e0; e0=$(eps "$2")
    local step; step=$(eps 100)
    local sched="6.4_2:$e0,12.8_4:$step,18.12_6:$step,24.16_8:$step"
    local cfg; cfg=$(train_cfg "$name" 24 16 8)
    for seed in $SEEDS; do
        for m in smappo mappo; do
            local out="runs/exp/$name/$m/seed$seed"
            train "$out" "$m" "$seed" "$cfg" --curriculum "$sched"
            evaluate "$out/policy.safetensors" 6.4_2,12.8_4,18.12_6,24.16_8 "$out/eval"
        done
    done
    greedy "$name" 6.4_2,12.8_4,18.12_6,24.16_8
}

exp_b() {
    curriculum B 2000
    table B "B: curriculum" runs/exp/B/*/seed*/eval/results.csv runs/exp/B/greedy/eval/results.csv
    curves B "B: curriculum" runs/exp/B/*/seed*/log.csv
}
exp_d() {
    curriculum D 200
    table D "D: curriculum, short initial training" runs/exp/D/*/seed*/eval/results.csv runs/exp/D/greedy/eval/results.csv
    curves D "D: curriculum, short initial training" runs/exp/D/*/seed*/log.csv
}

# Beyond the paper: one policy trained on randomized counts (drawn per update from RANGE,
# default 2-12 robots, 2-8 machines, 1-4 storages) for the same episode budget as C, then
# evaluated zero-shot on C's setups, to compare with C's single-setup (6.4_2) training.
exp_r() {
    local range="${RANGE:-2..12.2..8_1..4}"
    zero_shot R "R: randomized counts per update ($range), zero-shot" \
        "R: training on randomized counts" --randomize "$range"
}

case "${1:-}" in
    A) exp_a ;; B) exp_b ;; R) exp_r ;; C) exp_c ;; D) exp_d ;;
    all) exp_a; exp_b; exp_c; exp_d; exp_r ;;
    *) sed -n '2,26p' "$0"; exit 2 ;;
esac
