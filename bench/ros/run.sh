#!/usr/bin/env bash
# robot_node ROS 2 benchmarks: latency (lockstep state -> cmd_vel vs bare DDS round trip),
# fleets of robot_node processes at 10 Hz (missed ticks, CPU, RSS), several robots in one
# process. Loopback only (private ROS_DOMAIN_IDs 150-230), every run bounded in count and time.
# Results: bench/ros/out/{latency,fleet}.jsonl; tables: python3 bench/ros/report.py
#   bash bench/ros/run.sh            # everything, ~25 min on 2 cores
#   REPS=1 SIZES=5,10 bash bench/ros/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
REPS=${REPS:-3}
SIZES=${SIZES:-5,10,20}
MULTI=${MULTI:-20,50,100}
cargo build --release -j 2 -p robot-node -p sim-bridge -p ros-bench
POLICY=policy/pretrained/smappo_6.4_2.safetensors
if [ ! -f "$POLICY" ]; then
  POLICY=bench/ros/out/random_smappo.safetensors
  [ -f "$POLICY" ] || target/release/ros_bench mkpolicy "$POLICY"
  echo "no trained checkpoint: using random-weights SMAPPO $POLICY (same compute per decision)"
fi
uptime
python3 bench/ros/bench.py latency --reps "$REPS" --n 200 --interval-ms 100 --policy "$POLICY"
python3 bench/ros/bench.py fleet --sizes "$SIZES" --reps "$REPS" --secs 30 --policy "$POLICY"
python3 bench/ros/bench.py fleet --sizes "$MULTI" --reps 1 --secs 30 --policy "$POLICY" --multi
uptime
python3 bench/ros/report.py
