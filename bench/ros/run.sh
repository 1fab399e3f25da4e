#!/usr/bin/env bash
# robot_node ROS 2 benchmarks: latency (lockstep state -> cmd_vel vs bare DDS round trip),
# fleets of robot_node processes at 10 Hz (missed ticks, CPU, RSS), several robots in one
# process. Loopback only (private ROS_DOMAIN_IDs 150-230), every run bounded in count and time.
# Results: bench/ros/out/{latency,fleet}.jsonl; tables: python3 bench/ros/report.py
#   bash bench/ros/run.sh            # everything, ~30 min on 2 cores
#   REPS=1 SIZES=5,10 bash bench/ros/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
REPS=${REPS:-3}
SIZES=${SIZES:-5,10,20,30}
MULTI=${MULTI:-20,50,100}
cargo build --release -j 2 -p robot-node -p sim-bridge -p ros-bench
POLICY=policy/pretrained/smappo_6.4_2.safetensors
if [ ! -f "$POLICY" ]; then
  POLICY=bench/ros/out/random_smappo.safetensors
  [ -f "$POLICY" ] || target/release/ros_bench mkpolicy "$POLICY"
  echo "no trained checkpoint: using random-weights SMAPPO $POLICY (same compute per decision)"
fi
uptime
# 1. latency, 6.4_2-sized state (own + 4 machines + 2 storages + 5 peers = 22 samples), 10 Hz
python3 bench/ros/bench.py latency --reps "$REPS" --n 200 --interval-ms 100 --policy "$POLICY"
# back to back (a state every 2 ms), for comparison with back-to-back round-trip figures
python3 bench/ros/bench.py latency --reps "$REPS" --n 500 --interval-ms 2 --policy "$POLICY"
# state-size scaling (greedy): 1 machine + 1 storage, no peers (6 samples); 20.12_4-sized (68 samples)
python3 bench/ros/bench.py latency --reps "$REPS" --n 200 --interval-ms 100 --greedy-only --peers 0 --machines 1 --storages 1
python3 bench/ros/bench.py latency --reps "$REPS" --n 200 --interval-ms 100 --greedy-only --peers 19 --machines 12 --storages 4
# 2./3. fleets at 10 Hz: one process per robot, then all robots in one process
python3 bench/ros/bench.py fleet --sizes "$SIZES" --reps "$REPS" --secs 30 --policy "$POLICY"
python3 bench/ros/bench.py fleet --sizes "$MULTI" --reps "$REPS" --secs 30 --policy "$POLICY" --multi
uptime
python3 bench/ros/report.py
