#!/usr/bin/env bash
# Issue 47's runs in one queue: one training or evaluation process at a time, each run
# skipped when finished (.done) and resumed (`tending train --resume`) from its committed
# trainer_state.safetensors, so a later session continues with the same one command:
#
#   nohup nice -n 10 bench/experiments/queue47.sh >> runs/queue47.log 2>&1 &
#   bench/experiments/queue47.sh report    # T.md, AT.md, P.md, the campaign's pages, verdict.md
#
# Order (cheapest first, a pilot before each long run):
#   1. untuned reference: A's three MAPPO 6.4_2 policies on the held-out eval seeds (evals)
#   2. pilots of the paper's schedule (P, 6.4_2 seed 0, both models, 50 updates): the first
#      50 updates of the real runs, which step 5 continues; log.csv's wall_secs times them
#   3. T: MAPPO tuning at 6.4_2, one run per bench/experiments/T/<name>.toml (re-scanned
#      after every run, so configs added while the queue runs are picked up), training seed
#      10, held-out eval seeds 100-102; bench/experiments/tune.py selects once 8 have finished
#   4. AT at 6.4_2: A's MAPPO re-trained with the selected settings, seeds 0-2 (A's budget)
#   5. P at 6.4_2: one 200-step env per PPO update, 2,000 updates, 15 epochs, 1 mini-batch,
#      both models, seeds 0-2
#   6. AT at 14.10_4, then P at 14.10_4 (same)
#   6a. T-extra: one tuning run beyond T's 8-run budget, the selected settings with MAPPO's
#      hidden size 128 (`mappo_hidden`, newer than the campaign binary: run with
#      target/release/tending, T9BIN overrides), judged like T on held-out seeds
#   6a'. AT128: AT again with MAPPO's hidden size 128 (T-extra beat T's selection on the
#      held-out seeds: 0.474 against 0.441), 6.4_2 and 14.10_4, seeds 0-2, same binary as 6a
#   6b. PB: B's curriculum under the paper's schedule (Fig. 7's 400K axis: 2,000 updates of
#      one 6.4_2 env, then 100 updates per stage), both models, seeds 0-2
#   7. U's remaining runs (bench/experiments/run.sh U, as campaign.sh runs it)
# Every run lands in results/paper/{T,AT,P,U}/...; after each run (and every 25 min while
# one is in flight) the queue commits results/paper and docs/experiments with explicit
# pathspecs (COMMIT=0 to skip), the in-flight trainer_state.safetensors included.
# Start it under `nice -n 10`; RAYON_NUM_THREADS=1 is set here. It never builds: the binary
# is runs/campaign-bin/tending (copied from target/release once if missing; TENDING overrides).
# Never edit this file in place while it runs (bash reads it as it goes): write a new one
# and rename it over.
set -euo pipefail
cd "$(dirname "$0")/../.."
export RAYON_NUM_THREADS=1 SCALE=1 SEEDS="0 1 2" EVAL_EPISODES=50 EVAL_SEEDS=0,1,2 \
    RUNS=results/paper EXTRA=1 FULL_100=1
T="${TENDING:-runs/campaign-bin/tending}"
if [ ! -x "$T" ]; then mkdir -p "$(dirname "$T")"; cp target/release/tending "$T"; fi
export TENDING="$T"
R=results/paper
HELD_OUT=100,101,102   # tuning is judged here, never on the campaign's eval seeds 0-2
TUNE_SEED=10           # tuning trains on this seed, never on the campaign's 0-2
COMMIT="${COMMIT:-1}"
PATHS=(results/paper docs/experiments)  # results/paper/T-extra included

commit() { # message: the queue's own paths only, retried while another git holds the index
    [ "$COMMIT" = 1 ] || return 0
    local i
    for i in 1 2 3 4 5 6 7 8 9 10; do
        if git add -- "${PATHS[@]}" 2>/dev/null; then
            git diff --cached --quiet -- "${PATHS[@]}" && return 0
            # the message names what is staged: a skipped run's commit carries whatever
            # else changed (another run's resume state, a report), never only its own label
            local what; what=$(git diff --cached --name-only -- "${PATHS[@]}" | cut -d/ -f1-5 \
                | sort -u | head -4 | tr '\n' ' ')
            git commit -q -m "$1" -m "staged: $what" -- "${PATHS[@]}" >/dev/null 2>&1 \
                && { echo "-- committed: $1"; return 0; }
        fi
        sleep 6
    done
    echo "!! commit failed: $1" >&2
}

header() { # n_envs epochs minibatches robots machines storages -> TOML lines
    printf 'n_envs = %s\nppo_epoch = %s\nnum_mini_batch = %s\nmappo_max_robots = %s\nmappo_max_machines = %s\nmappo_max_storages = %s\n' "$@"
}

train() { # out model seed cfg args...
    local out="$1" model="$2" seed="$3" cfg="$4"; shift 4
    if [ -f "$out/policy.safetensors" ] && [ -f "$out/.done" ]; then return; fi
    local resume=(); [ -f "$out/trainer_state.safetensors" ] && resume=(--resume)
    echo "== $(date -u +%FT%TZ) train $model seed $seed -> $out ($*) ${resume[*]}"
    mkdir -p "$out"
    ( while sleep 1500; do commit "queue47: resume state of $out"; done ) &
    local ticker=$!
    "$T" train --model "$model" --seed "$seed" --config "$cfg" --out "$out" --quiet "${resume[@]}" "$@" \
        || { kill "$ticker" 2>/dev/null; return 1; }
    kill "$ticker" 2>/dev/null || true
    touch "$out/.done"
    rm -f "$out/trainer_state.safetensors"
    echo "== $(date -u +%FT%TZ) done $out: $(tail -1 "$out/log.csv" | cut -d, -f1,2,19)"
}

pilot() { # out model seed cfg updates args...: the first updates of a run, resumed later
    local out="$1" model="$2" seed="$3" cfg="$4" n="$5"; shift 5
    [ -f "$out/log.csv" ] && return 0
    echo "== $(date -u +%FT%TZ) pilot $model seed $seed -> $out ($n updates; $*)"
    mkdir -p "$out"
    "$T" train --model "$model" --seed "$seed" --config "$cfg" --out "$out" --quiet --max-updates "$n" "$@"
    echo "== pilot $out: $(tail -1 "$out/log.csv" | cut -d, -f1,2,19) (update, episodes, wall_secs)"
}

has_eval() { # results.csv setups seeds
    [ -f "$1" ] && python3 - "$1" "$2" "$EVAL_EPISODES" "$3" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
got = {(r["setup"], r.get("seed", "0")) for r in rows if r["episodes"] == sys.argv[3]}
want = {(s, e) for s in sys.argv[2].split(",") for e in sys.argv[4].split(",")}
sys.exit(0 if want <= got else 1)
PY
}

evaluate() { # checkpoint setups out eval-seeds (skipped when out has them, of this checkpoint)
    local sum; sum=$(sha256sum "$1" | cut -c1-64)
    if has_eval "$3/results.csv" "$2" "$4" && [ "$(cat "$3/checkpoint.sha256" 2>/dev/null)" = "$sum" ]; then
        return
    fi
    echo "== $(date -u +%FT%TZ) eval $1 -> $3 ($2; eval seeds $4)"
    # evaluations use the newest build when there is one: it counts collision events, and
    # evaluation is deterministic across versions (onsets.py reproduced every old column
    # of 105 evaluations); training keeps the campaign binary
    local ev="$T"; [ -x target/release/tending ] && ev=target/release/tending
    "$ev" eval --checkpoint "$1" --setups "$2" --episodes "$EVAL_EPISODES" --seeds "$4" --out "$3" >/dev/null
    echo "$sum" >"$3/checkpoint.sha256"
}

p_cfg() { # setup -> the paper's schedule: 1 env per update, reference epochs and mini-batches
    local s="$1" f="$R/P_$1.train.toml"
    header 1 15 1 $(echo "$s" | tr '._' '  ') >"$f"
    echo "$f"
}

p_runs() { # setup: P, both models, seeds 0-2
    local s="$1" cfg seed m; cfg=$(p_cfg "$s")
    for seed in $SEEDS; do
        for m in smappo mappo; do
            local out="$R/P/$s/$m/seed$seed"
            train "$out" "$m" "$seed" "$cfg" --setup "$s" --episodes 2000
            evaluate "$out/policy.safetensors" "$s" "$out/eval" "$EVAL_SEEDS"
            report >/dev/null 2>&1 || true
            commit "Queue 47, P (paper's schedule) $s: $m seed $seed finished and evaluated"
        done
    done
}

t_extra() { # the hidden-size run (6a); a failure is reported, never stops the queue
    local out="$R/T-extra/t9-ref-ent0.03-h128" bin="${T9BIN:-target/release/tending}"
    [ -f "$out/.done" ] && [ -f "$out/eval/results.csv" ] && return 0
    ( T="$bin"; train "$out" mappo "$TUNE_SEED" "$out.train.toml" --setup 6.4_2 --episodes 2000 \
        && evaluate "$out/policy.safetensors" 6.4_2 "$out/eval" "$HELD_OUT" ) \
        || { echo "!! T-extra failed (needs a tending with mappo_hidden: $bin)"; return 0; }
    commit "Queue 47, T-extra: MAPPO hidden 128 finished and evaluated on held-out seeds"
}

at128_runs() { # setup: AT128, AT's settings with mappo_hidden = 128 (6a')
    local s="$1" seed cfg="$R/AT128_$1.train.toml" bin="${T9BIN:-target/release/tending}"
    [ -f "$R/AT_$s.train.toml" ] || { echo "-- AT128 $s skipped: no AT config"; return 0; }
    { grep -v '^mappo_hidden' "$R/AT_$s.train.toml"; echo "mappo_hidden = 128"; } >"$cfg"
    for seed in $SEEDS; do
        local out="$R/AT128/$s/mappo/seed$seed"
        ( T="$bin"; train "$out" mappo "$seed" "$cfg" --setup "$s" --episodes 2000 \
            && evaluate "$out/policy.safetensors" "$s" "$out/eval" "$EVAL_SEEDS" ) \
            || { echo "!! AT128 $s seed $seed failed (needs mappo_hidden: $bin)"; return 0; }
        report >/dev/null 2>&1 || true
        commit "Queue 47, AT128 $s: MAPPO hidden 128 seed $seed finished and evaluated"
    done
}

pb_runs() { # PB: B's curriculum on the paper's schedule (stages at 400K, 420K, 440K steps)
    local cfg="$R/PB.train.toml" seed m
    header 1 15 1 24 16 8 >"$cfg"
    for seed in $SEEDS; do
        for m in smappo mappo; do
            local out="$R/PB/$m/seed$seed"
            train "$out" "$m" "$seed" "$cfg" --curriculum "6.4_2:2000,12.8_4:100,18.12_6:100,24.16_8:100"
            evaluate "$out/policy.safetensors" 6.4_2,12.8_4,18.12_6,24.16_8 "$out/eval" "$EVAL_SEEDS"
            report >/dev/null 2>&1 || true
            commit "Queue 47, PB (B on the paper's schedule): $m seed $seed finished and evaluated"
        done
    done
}

at_runs() { # setup: AT, the tuned MAPPO at A's budget, seeds 0-2
    local s="$1" seed
    [ -f "$R/T/selected.toml" ] || { echo "-- AT $s skipped: no config selected yet (T.md)"; return 0; }
    local cfg="$R/AT_$s.train.toml"
    { header 8 10 4 $(echo "$s" | tr '._' '  '); grep -v '^#' "$R/T/selected.toml"; } \
        | python3 -c "import sys
# the selected settings override the header's (last one wins: keep one line per key)
seen = {}
for l in sys.stdin:
    if '=' in l: seen[l.split('=')[0].strip()] = l
sys.stdout.write(''.join(seen.values()))" >"$cfg"
    for seed in $SEEDS; do
        local out="$R/AT/$s/mappo/seed$seed"
        train "$out" mappo "$seed" "$cfg" --setup "$s" --episodes 2000
        evaluate "$out/policy.safetensors" "$s" "$out/eval" "$EVAL_SEEDS"
        report >/dev/null 2>&1 || true
        commit "Queue 47, AT $s: tuned MAPPO seed $seed finished and evaluated"
    done
}

next_tune() { # the first tuning config without a finished, evaluated run
    local c n
    for c in bench/experiments/T/*.toml; do
        n=$(basename "$c" .toml)
        if [ ! -f "$R/T/$n/.done" ] || [ ! -f "$R/T/$n/eval/results.csv" ]; then echo "$c"; return; fi
    done
}

tune() {
    local k c n cfg
    for k in 0 1 2; do
        evaluate "$R/A/6.4_2/mappo/seed$k/policy.safetensors" 6.4_2 "$R/T/untuned-A-seed$k/eval" "$HELD_OUT"
    done
    while c=$(next_tune) && [ -n "$c" ]; do
        n=$(basename "$c" .toml); cfg="$R/T/$n.train.toml"
        { header 8 10 4 6 4 2; grep -v '^#' "$c"; } | python3 -c "import sys
seen = {}
for l in sys.stdin:
    if '=' in l: seen[l.split('=')[0].strip()] = l
sys.stdout.write(''.join(seen.values()))" >"$cfg"
        train "$R/T/$n" mappo "$TUNE_SEED" "$cfg" --setup 6.4_2 --episodes 2000
        evaluate "$R/T/$n/policy.safetensors" 6.4_2 "$R/T/$n/eval" "$HELD_OUT"
        report >/dev/null 2>&1 || true
        commit "Queue 47, T: MAPPO tuning run $n finished and evaluated on held-out seeds"
    done
    local sel; sel=$(python3 bench/experiments/tune.py)
    echo "-- tuning: selected '${sel:-none yet}'"
}

table_of() { # name title results.csv... -- logs...
    local name="$1" title="$2"; shift 2
    local files=() logs=()
    while [ $# -gt 0 ] && [ "$1" != -- ]; do [ -f "$1" ] && files+=("$1"); shift; done
    [ $# -gt 0 ] && shift && logs=("$@")
    [ ${#files[@]} -gt 0 ] || return 0
    python3 bench/experiments/table.py --exp "$name" --paper bench/experiments/paper_mu.csv \
        --eval-episodes "$EVAL_EPISODES" --eval-seeds "$EVAL_SEEDS" --out "docs/experiments/$name.md" \
        "$title" 1 "$SEEDS" "${files[@]}" ${logs[@]:+--logs "${logs[@]}"}
    "$T" plot bars --out "docs/experiments/$name" --title "$title" \
        --paper bench/experiments/paper_mu.csv --experiment A "${files[@]}" || true
    [ ${#logs[@]} -eq 0 ] || "$T" plot curves --out "docs/experiments/${name}_curves.png" \
        --title "$title, training" --metrics reward,mu "${logs[@]}" || true
}

report() {
    shopt -s nullglob
    python3 bench/experiments/tune.py >/dev/null
    local tl=($R/T/*/log.csv)
    [ ${#tl[@]} -eq 0 ] || "$T" plot curves --out docs/experiments/T_curves.png \
        --title "T: MAPPO tuning at 6.4_2 (training seed 10), one line per config" \
        --metrics reward,mu "${tl[@]}" || true
    local at_s=() s
    for s in $R/AT/*/; do at_s+=("$(basename "$s")"); done
    if [ ${#at_s[@]} -gt 0 ]; then
        local f=() l=()
        for s in "${at_s[@]}"; do
            f+=($R/AT/$s/mappo/seed*/eval/results.csv $R/A/$s/smappo/seed*/eval/results.csv)
            for x in $R/AT/$s/mappo/seed*/log.csv $R/A/$s/smappo/seed*/log.csv; do
                [ -f "$(dirname "$x")/.done" ] && l+=("$x")
            done
        done
        table_of AT "AT: A's SMAPPO against MAPPO with the tuned settings (T.md), A's budget" "${f[@]}" -- "${l[@]}"
    fi
    local a128=() a128l=()
    for s in $R/AT128/*/; do
        s=$(basename "$s")
        a128+=($R/AT128/$s/mappo/seed*/eval/results.csv $R/A/$s/smappo/seed*/eval/results.csv)
        for x in $R/AT128/$s/mappo/seed*/log.csv $R/A/$s/smappo/seed*/log.csv; do
            [ -f "$(dirname "$x")/.done" ] && a128l+=("$x")
        done
    done
    [ ${#a128[@]} -eq 0 ] || table_of AT128 "AT128: A's SMAPPO against the tuned MAPPO with hidden size 128, A's budget" \
        "${a128[@]}" -- "${a128l[@]}"
    local pl=()
    for x in $R/P/*/*/seed*/log.csv; do [ -f "$(dirname "$x")/.done" ] && pl+=("$x"); done
    table_of P "P: the paper's schedule (1 env per update, 2,000 updates, 15 epochs, 1 mini-batch)" \
        $R/P/*/*/seed*/eval/results.csv -- "${pl[@]}"
    local pbl=()
    for x in $R/PB/*/seed*/log.csv; do [ -f "$(dirname "$x")/.done" ] && pbl+=("$x"); done
    table_of PB "PB: B's curriculum on the paper's schedule (1 env per update, stages at 2,000, 2,100, 2,200 updates)" \
        $R/PB/*/seed*/eval/results.csv -- "${pbl[@]}"
    shopt -u nullglob
    bench/experiments/run.sh report
}

case "${1:-}" in
    report) report; exit ;;
    "") ;;
    *) sed -n '2,30p' "$0"; exit 2 ;;
esac

echo "=== queue47 start $(date -u +%FT%TZ) with $T"
tune_pilot_cfg=$(p_cfg 6.4_2)
pilot "$R/P/6.4_2/smappo/seed0" smappo 0 "$tune_pilot_cfg" 50 --setup 6.4_2 --episodes 2000
pilot "$R/P/6.4_2/mappo/seed0" mappo 0 "$tune_pilot_cfg" 50 --setup 6.4_2 --episodes 2000
commit "Queue 47: paper's-schedule pilots (P 6.4_2 seed 0, 50 updates each)"
tune
at_runs 6.4_2
p_runs 6.4_2
at_runs 14.10_4
t_extra
at128_runs 6.4_2
at128_runs 14.10_4
p_runs 14.10_4
pb_runs
echo "=== U at $(date -u +%FT%TZ)"
bench/experiments/run.sh U
report >/dev/null 2>&1 || true
commit "Queue 47: U's runs finished; reports"
echo "=== queue47 finished $(date -u +%FT%TZ)"
