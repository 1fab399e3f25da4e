#!/usr/bin/env bash
# The paper's four experiments (section V) with `tending train` / `tending eval`.
#
#   bench/experiments/run.sh A|B|C|D|R|U|all|report|baselines
#   (report: tables and verdicts only; baselines: the scripted and shipped baselines of every
#   experiment in $RUNS, each skipped when already evaluated)
#
# Budget: SCALE (default 0.1) multiplies every episode count of the paper (2,000 initial
# episodes, 100 per curriculum step, 100 for 100.16_2), the same for SMAPPO and MAPPO so the
# comparison stays fair; SEEDS (default "0 1 2") are training seeds; EVAL_EPISODES (default
# 50) episodes per evaluation with eval seed 0. Each row of a table is mean (std) over the
# training seeds. Runs land in $RUNS/<name>/, tables in docs/experiments/<name>.md.
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
#   U  100.16_2 at 100 updates (800 x SCALE simulated episodes): the paper's 100 episodes
#      as MAPPO's reference code counts them
#
# Every experiment also evaluates the scripted greedy baseline on its setups (same episodes
# and eval seed, $RUNS/<name>/greedy/eval, skipped when already there), puts the paper's
# MU next to ours (bench/experiments/paper_mu.csv: Tables I-IV) and draws
# docs/experiments/<name>_{parts,collisions,mu,curves}.png with `tending plot`. The text
# under the table's marker line in docs/experiments/<name>.md survives regeneration.
set -euo pipefail
cd "$(dirname "$0")/../.."
SCALE="${SCALE:-0.1}"
SEEDS="${SEEDS:-0 1 2}"
EVAL_EPISODES="${EVAL_EPISODES:-50}"
# EVAL_SEEDS: evaluation seeds (comma-separated), each EVAL_EPISODES episodes.
EVAL_SEEDS="${EVAL_SEEDS:-0}"
# RUNS: where runs land. The paper-budget campaign (bench/experiments/campaign.sh) uses
# results/paper, whose small files are committed so that it resumes on any machine.
RUNS="${RUNS:-runs/exp}"
# EXTRA: also evaluate greedy-ORCA, matching-ORCA and the shipped target-menu policy beside
# greedy on every experiment's setups (1 = yes).
EXTRA="${EXTRA:-0}"
# TENDING: the binary to use (a copy keeps a long run safe from rebuilds of target/).
T="${TENDING:-target/release/tending}"
[ -x "$T" ] || cargo build --release --bin tending
eps() { python3 -c "import math,sys; print(max(8, int(math.ceil($1 * $SCALE / 8.0)) * 8))"; }
mkdir -p "$RUNS" docs/experiments

train_cfg() { # name max_robots max_machines max_storages -> path of a train TOML
    local f="$RUNS/$1.train.toml"
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
    # a finished run needs only its policy, log and evaluation: the optimiser state (MBs)
    # would only bloat the committed results
    rm -f "$out/trainer_state.safetensors"
}

has_eval() { # results.csv setups: every setup and eval seed with EVAL_EPISODES episodes?
    [ -f "$1" ] && python3 - "$1" "$2" "$EVAL_EPISODES" "$EVAL_SEEDS" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
got = {(r["setup"], r.get("seed", "0")) for r in rows if r["episodes"] == sys.argv[3]}
want = {(s, e) for s in sys.argv[2].split(",") for e in sys.argv[4].split(",")}
sys.exit(0 if want <= got else 1)
PY
}

evaluate() { # checkpoint setups out (skipped when out has them all, of this very checkpoint)
    # The checkpoint's hash is kept beside the results (checkpoint.sha256, committed): file
    # times cannot say which is newer on a fresh clone, where git sets them all at checkout.
    local sum; sum=$(sha256sum "$1" | cut -c1-64)
    if has_eval "$3/results.csv" "$2"; then
        [ "$(cat "$3/checkpoint.sha256" 2>/dev/null)" = "$sum" ] && return
        # evaluated before the hash was recorded: trust the file times once
        if [ ! -f "$3/checkpoint.sha256" ] && [ "$3/results.csv" -nt "$1" ]; then
            echo "$sum" >"$3/checkpoint.sha256"
            return
        fi
    fi
    echo "== eval $1 -> $3 ($2)"
    "$T" eval --checkpoint "$1" --setups "$2" --episodes "$EVAL_EPISODES" --seeds "$EVAL_SEEDS" --out "$3" >/dev/null
    echo "$sum" >"$3/checkpoint.sha256"
}

greedy() { # name setups: the scripted baselines on the experiment's setups (not trained)
    local out="$RUNS/$1/greedy/eval"
    if ! has_eval "$out/results.csv" "$2"; then
        echo "== eval greedy -> $out ($2)"
        "$T" eval --policy greedy --setups "$2" --episodes "$EVAL_EPISODES" --seeds "$EVAL_SEEDS" --out "$out" >/dev/null
    fi
    [ "$EXTRA" = 1 ] || return 0
    # uniform random moves: the floor a model must rise above (at 100.16_2 random walkers
    # already keep MU near 0.56)
    local p
    for p in greedy-orca matching-orca random; do
        out="$RUNS/$1/$p/eval"
        if ! has_eval "$out/results.csv" "$2"; then
            echo "== eval $p -> $out ($2)"
            "$T" eval --policy "$p" --setups "$2" --episodes "$EVAL_EPISODES" --seeds "$EVAL_SEEDS" --out "$out" >/dev/null
        fi
    done
    # the shipped target-menu policy (trained on 6.4_2 behind the ORCA filter, evaluated as
    # robot_node runs it): evaluation only, never trained here
    evaluate policy/pretrained/smappo_6.4_2.safetensors "$2" "$RUNS/$1/shipped/eval"
}

plot_bin() { # a tending that has `plot` (TENDING may be an older copy)
    if "$T" plot --help >/dev/null 2>&1; then echo "$T"; return; fi
    target/release/tending plot --help >/dev/null 2>&1 || cargo build --release --bin tending >&2
    echo target/release/tending
}

table() { # name title csv-glob... [-- training log.csv... for the paper's last-100 protocol]
    local name="$1" title="$2"; shift 2
    local files=() logs=() extra=() f
    # (a campaign in flight has no greedy results yet: only existing files are read)
    while [ $# -gt 0 ] && [ "$1" != -- ]; do [ -f "$1" ] && files+=("$1"); shift; done
    [ $# -gt 0 ] && shift && logs=("$@")
    for f in greedy-orca matching-orca shipped random; do
        [ -f "$RUNS/$name/$f/eval/results.csv" ] && extra+=("$RUNS/$name/$f/eval/results.csv")
    done
    python3 bench/experiments/table.py --exp "$name" --paper bench/experiments/paper_mu.csv \
        --eval-episodes "$EVAL_EPISODES" --eval-seeds "$EVAL_SEEDS" --out "docs/experiments/$name.md" \
        "$title" "$SCALE" "$SEEDS" "${files[@]}" ${extra[@]:+"${extra[@]}"} \
        ${logs[@]:+--logs "${logs[@]}"}  # last: --logs takes every argument after it
    echo "wrote docs/experiments/$name.md"
    # the bars draw the trained models beside greedy and greedy-ORCA (the policy column
    # names those two; matching-ORCA and the shipped policy are in the table)
    local bars=("${files[@]}")
    [ -f "$RUNS/$name/greedy-orca/eval/results.csv" ] && bars+=("$RUNS/$name/greedy-orca/eval/results.csv")
    "$(plot_bin)" plot bars --out "docs/experiments/$name" --title "$title" \
        --paper bench/experiments/paper_mu.csv --experiment "$name" "${bars[@]}" \
        || echo "!! plot bars for $name failed" >&2
}

curves() { # name title log.csv...
    local name="$1" title="$2"; shift 2
    "$(plot_bin)" plot curves --out "docs/experiments/${name}_curves.png" --title "$title" "$@" \
        || echo "!! plot curves for $name failed" >&2
}

retrain() { # name setup episodes: both models and every seed trained on setup, evaluated there
    local name="$1" s="$2" e="$3" nr nm ns seed m
    read -r nr nm ns <<<"$(counts "$s")"
    local cfg; cfg=$(train_cfg "${name}_$s" "$nr" "$nm" "$ns")
    for seed in $SEEDS; do
        for m in smappo mappo; do
            local out="$RUNS/$name/$s/$m/seed$seed"
            train "$out" "$m" "$seed" "$cfg" --setup "$s" --episodes "$e"
            evaluate "$out/policy.safetensors" "$s" "$out/eval"
        done
    done
}

A_SETUPS="6.4_2 8.6_2 10.6_4 100.16_2 14.10_4 12.8_4"  # with FULL_100; in running order
STAGES=6.4_2,12.8_4,18.12_6,24.16_8  # B's and D's curriculum stages
exp_a() {
    # cheapest verdicts first: 100.16_2's 100 episodes cost about an hour for all six runs
    # and settle the "53 % more parts" claim; 14.10_4 holds Fig. 5; 12.8_4 one Table I row
    local setups="6.4_2 8.6_2 10.6_4 14.10_4 12.8_4"
    [ "${FULL_100:-0}" = 1 ] && setups="$A_SETUPS"
    local s e
    for s in $setups; do
        e=$(eps 2000); [ "$s" = 100.16_2 ] && e=$(eps 100)
        retrain A "$s" "$e"
    done
    greedy A "${setups// /,}"
    report_a
}
report_a() {
    table A "A: full retraining" $RUNS/A/*/*/seed*/eval/results.csv $RUNS/A/greedy/eval/results.csv \
        -- $RUNS/A/*/*/seed*/log.csv
    curves A "A: full retraining, training per setup" --metrics reward,mu $RUNS/A/*/*/seed*/log.csv
    # Fig. 5: 14.10_4's team reward with the 50 % / 70 % of SMAPPO's final value marked,
    # smoothed over 5 updates as verdict.py judges it
    local glob; glob=$(shopt -p nullglob || true)  # report_all sets nullglob: restore, not unset
    shopt -s nullglob
    local f5=($RUNS/A/14.10_4/*/seed*/log.csv)
    eval "$glob"
    [ ${#f5[@]} -eq 0 ] || "$(plot_bin)" plot curves --out docs/experiments/A_fig5.png \
        --title "Fig. 5 (ours): full retraining at 14.10_4, total episode reward" \
        --metrics reward --smooth 5 --levels 0.5,0.7 "${f5[@]}" \
        || echo "!! plot Fig. 5 failed" >&2
}

# Zero-shot experiments (C, R): train on 6.4_2-sized data (MAPPO padded to 42.28_14), then
# evaluate every model on the nine zero-shot setups.
ZERO_SHOT_SETUPS=6.4_2,2.2_2,4.2_2,12.8_4,18.12_6,24.16_8,30.20_10,36.24_12,42.28_14
# BEYOND: setups past the paper's largest (same 3:2:1 ratio up to 100 robots), where
# zero-shot is expected to break; empty to skip
BEYOND="${BEYOND-60.40_20,80.52_26,100.66_33}"
zero_shot() { # name table-title curves-title train-args...
    local name="$1" title="$2" ctitle="$3"; shift 3
    local cfg; cfg=$(train_cfg "$name" 42 28 14)
    local e; e=$(eps 2000)
    for seed in $SEEDS; do
        for m in smappo mappo; do
            local out="$RUNS/$name/$m/seed$seed"
            if [ "$name" = C ] && [ "$m" = smappo ]; then
                # the paper's C evaluates A's 6.4_2 model: SMAPPO is input-size invariant,
                # so that run is the zero-shot model; linked, not trained twice
                local a="$RUNS/A/6.4_2/smappo/seed$seed"
                train "$a" smappo "$seed" "$(train_cfg A_6.4_2 6 4 2)" --setup 6.4_2 --episodes "$e"
                mkdir -p "$out"
                ln -sfn "../../../A/6.4_2/smappo/seed$seed/policy.safetensors" "$out/policy.safetensors"
                ln -sfn "../../../A/6.4_2/smappo/seed$seed/log.csv" "$out/log.csv"
            else
                train "$out" "$m" "$seed" "$cfg" "$@" --episodes "$e"
            fi
            local setups="$ZERO_SHOT_SETUPS"
            # beyond the paper's largest setup only SMAPPO runs: MAPPO's input is padded to
            # 42.28_14 and cannot take more
            [ "$m" = smappo ] && [ -n "$BEYOND" ] && setups="$setups,$BEYOND"
            evaluate "$out/policy.safetensors" "$setups" "$out/eval"
        done
    done
    greedy "$name" "$ZERO_SHOT_SETUPS${BEYOND:+,$BEYOND}"
    report_zero_shot "$name" "$title" "$ctitle"
}
report_zero_shot() { # name table-title curves-title
    table "$1" "$2" $RUNS/"$1"/*/seed*/eval/results.csv $RUNS/"$1"/greedy/eval/results.csv
    curves "$1" "$3" $RUNS/"$1"/*/seed*/log.csv
}
C_TITLES=("C: zero-shot from 6.4_2" "C: training on 6.4_2")
exp_c() { zero_shot C "${C_TITLES[@]}" --setup 6.4_2; }

curriculum() { # name initial-episodes
    local name="$1" e0; e0=$(eps "$2")
    local step; step=$(eps 100)
    local sched="6.4_2:$e0,12.8_4:$step,18.12_6:$step,24.16_8:$step"
    local cfg; cfg=$(train_cfg "$name" 24 16 8)
    for seed in $SEEDS; do
        for m in smappo mappo; do
            local out="$RUNS/$name/$m/seed$seed"
            train "$out" "$m" "$seed" "$cfg" --curriculum "$sched"
            evaluate "$out/policy.safetensors" "$STAGES" "$out/eval"
        done
    done
    greedy "$name" "$STAGES"
}

exp_b() { curriculum B 2000; report_curriculum B "B: curriculum"; }
exp_d() { curriculum D 200; report_curriculum D "D: curriculum, short initial training"; }
report_curriculum() { # name title
    table "$1" "$2" $RUNS/"$1"/*/seed*/eval/results.csv $RUNS/"$1"/greedy/eval/results.csv
    curves "$1" "$2" $RUNS/"$1"/*/seed*/log.csv
}

# Tables, plots and the verdicts from whatever has finished (a campaign in flight included).
report_all() {
    shopt -s nullglob
    local e
    for e in A B C D U; do
        [ -n "$(echo $RUNS/$e/*/seed*/eval/results.csv $RUNS/$e/*/*/seed*/eval/results.csv)" ] || continue
        case "$e" in
            A) report_a ;; C) report_zero_shot C "${C_TITLES[@]}" ;; U) report_u ;;
            B) report_curriculum B "B: curriculum" ;;
            D) report_curriculum D "D: curriculum, short initial training" ;;
        esac
    done
    python3 bench/experiments/verdict.py --runs "$RUNS" --out docs/experiments/verdict.md
    echo "wrote docs/experiments/verdict.md"
}

# Beyond the paper: one policy trained on randomized counts (drawn per update from RANGE,
# default 2-12 robots, 2-8 machines, 1-4 storages) for the same episode budget as C, then
# evaluated zero-shot on C's setups, to compare with C's single-setup (6.4_2) training.
exp_r() {
    local range="${RANGE:-2..12.2..8_1..4}"
    zero_shot R "R: randomized counts per update ($range), zero-shot" \
        "R: training on randomized counts" --randomize "$range"
}

# The paper's 100 episodes of 100.16_2 read as MAPPO's reference code counts them: one
# "episode" of marlbenchmark/on-policy's training loop is one update over
# n_rollout_threads envs. Here: 100 updates of our 8 envs (800 simulated episodes), against
# A's 13. Its own table (U.md), never mixed with A's budget (docs/RESULTS.md, "What an
# episode is").
exp_u() {
    retrain U 100.16_2 "$(eps 800)"
    greedy U 100.16_2
    report_u
}
report_u() {
    table U "U: 100.16_2 at 100 updates (800 simulated episodes)" \
        $RUNS/U/*/*/seed*/eval/results.csv $RUNS/U/greedy/eval/results.csv -- $RUNS/U/*/*/seed*/log.csv
    curves U "U: 100.16_2 at 100 updates, training" --metrics reward,mu $RUNS/U/*/*/seed*/log.csv
}

# The baselines of every experiment whose models have finished (each skipped when there):
# for a campaign that finished before a baseline was added.
baselines() {
    [ -d "$RUNS/A" ] && greedy A "${A_SETUPS// /,}"
    [ -d "$RUNS/B" ] && greedy B "$STAGES"
    [ -d "$RUNS/C" ] && greedy C "$ZERO_SHOT_SETUPS${BEYOND:+,$BEYOND}"
    [ -d "$RUNS/D" ] && greedy D "$STAGES"
    [ -d "$RUNS/U" ] && greedy U 100.16_2
    return 0
}

case "${1:-}" in
    A) exp_a ;; B) exp_b ;; R) exp_r ;; C) exp_c ;; D) exp_d ;; U) exp_u ;;
    all) exp_a; exp_b; exp_c; exp_d; exp_r ;;
    report) report_all ;;
    baselines) baselines ;;
    *) sed -n '2,26p' "$0"; exit 2 ;;
esac
