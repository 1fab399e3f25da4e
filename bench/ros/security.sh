#!/usr/bin/env bash
# DDS Security on vs off, side by side (issue 12): every measurement runs with security
# off and then on, one after the other in the same repetition, so both see the same
# machine and the same background load. Results append to bench/ros/out/{latency,fleet}.jsonl
# (field `security`); tables: python3 bench/ros/security_report.py --since <start time>.
#   bash bench/ros/security.sh                   # ~20 min on 2 cores
#   REPS=1 SIZES=4,10 bash bench/ros/security.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
REPS=${REPS:-2}
SIZES=${SIZES:-4,10,20}
SECS=${SECS:-45}
[ -n "${NO_BUILD:-}" ] || cargo build --release -j 2 -p robot-node -p sim-bridge -p ros-bench -p tending
POLICY=policy/pretrained/smappo_6.4_2.safetensors
START=$(date +%Y-%m-%dT%H:%M:%S)
uptime
# 1. latency, lockstep state -> cmd_vel of one robot_node (6.4_2-sized state, 10 Hz) and
# the bare DDS round trip beside it; 12 s warm-up for both (a secure pair needs a few
# seconds of handshake and key exchange before its first sample)
python3 bench/ros/bench.py latency --reps "$REPS" --n 200 --interval-ms 100 --policy "$POLICY" \
  --security off,on --warmup-s 12
# 2. fleets at 10 Hz (one robot_node process per robot + sim_bridge), CPU counted after a
# 15 s warm-up (past the secure start-up)
python3 bench/ros/bench.py fleet --sizes "$SIZES" --reps "$REPS" --secs "$SECS" --warm 15 \
  --policy "$POLICY" --security off,on
uptime
python3 bench/ros/security_report.py --since "$START"
