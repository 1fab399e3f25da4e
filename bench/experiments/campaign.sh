#!/usr/bin/env bash
# The paper at its own budget (issue 35): experiments C, D, B and A (with 100.16_2) at
# SCALE 1, training seeds 0 1 2, every model evaluated with 50 episodes x eval seeds 0,1,2,
# beside greedy, greedy-ORCA, matching-ORCA and the shipped target-menu policy.
#
#   bench/experiments/campaign.sh            # run (or resume) everything, in the background:
#   nohup nice -n 10 bench/experiments/campaign.sh > results/paper/campaign.log 2>&1 &
#   bench/experiments/campaign.sh report     # tables, plots, verdicts of what has finished
#   bench/experiments/campaign.sh baselines  # any baseline added after an experiment finished
#
# Order: cheapest verdicts first (C and D train at 6.4_2; B adds three 100-episode stages;
# A's large setups and 100.16_2 last), then U: 100.16_2 at 100 updates, the paper's 100
# episodes as MAPPO's reference code counts them (run.sh). Runs land in results/paper/<experiment>/...; their
# small files (policy, log.csv, eval results, the train TOML) are committed, and so is
# the trainer state of a run in flight, so a later session on a fresh machine continues
# where this one stopped: each run is skipped when done (.done) and resumed
# (`tending train --resume`) when its trainer_state.safetensors is there.
#
# The binary is copied to runs/campaign-bin/ first, so rebuilding target/ while the
# campaign runs does not swap it mid-way (same source: the copy is refreshed on each start).
set -euo pipefail
cd "$(dirname "$0")/../.."
export SCALE=1 SEEDS="${SEEDS:-0 1 2}" EVAL_EPISODES=50 EVAL_SEEDS=0,1,2 RUNS=results/paper \
    EXTRA=1 FULL_100=1
if [ "${1:-}" = report ] || [ "${1:-}" = baselines ]; then
    exec bench/experiments/run.sh "$1"
fi
cargo build --release --bin tending
mkdir -p runs/campaign-bin results/paper
cp target/release/tending runs/campaign-bin/tending
export TENDING=runs/campaign-bin/tending
for e in ${EXPERIMENTS:-C D B A U}; do
    echo "=== experiment $e at $(date -u +%FT%TZ)"
    bench/experiments/run.sh "$e"
done
echo "=== campaign finished at $(date -u +%FT%TZ)"
