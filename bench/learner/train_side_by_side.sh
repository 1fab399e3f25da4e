#!/usr/bin/env bash
# Whole-update training throughput of two train_bench binaries, alternating in one run.
# usage: train_side_by_side.sh OLD NEW [rounds] [setup] [envs] [epochs] [updates] [mini-batches]
set -euo pipefail
old=$1 new=$2 rounds=${3:-3} setup=${4:-6.4_2} envs=${5:-8} epochs=${6:-10} updates=${7:-2} mb=${8:-1}
o=(); n=()
rate() { "$1" "$setup" "$envs" "$epochs" "$updates" smappo "$mb" | sed -n 's/.*, \([0-9]*\) agent-steps\/s.*/\1/p'; }
echo "$(date -u '+%F %H:%M') UTC, load $(cut -d' ' -f1-3 /proc/loadavg), train_bench $setup $envs $epochs $updates smappo $mb"
for r in $(seq "$rounds"); do
  a=($(rate "$old")); b=($(rate "$new"))
  o+=("${a[@]}"); n+=("${b[@]}")
  echo "round $r: old ${a[*]} agent-steps/s, new ${b[*]}"
done
med() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
mo=$(med "${o[@]}"); mn=$(med "${n[@]}")
echo "median agent-steps/s: old $mo, new $mn, new/old $(echo "$mn / $mo" | bc -l | cut -c1-4) (load $(cut -d' ' -f1-3 /proc/loadavg))"
