#!/usr/bin/env bash
# Alternate two ppo_step binaries in one run and print medians and the ratio.
# usage: side_by_side.sh OLD NEW [rounds] [steps] [actor|critic]
set -euo pipefail
old=$1 new=$2 rounds=${3:-4} steps=${4:-8} what=${5:-actor}
o=(); n=()
for _ in $(seq "$rounds"); do
  o+=($("$old" "$steps" "$what" | grep -v cpu_ms | tail -n +3))
  n+=($("$new" "$steps" "$what" | grep -v cpu_ms | tail -n +3))
done
med() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
mo=$(med "${o[@]}"); mn=$(med "${n[@]}")
echo "$what step median: old $mo ms, new $mn ms, new/old $(echo "$mn / $mo" | bc -l | cut -c1-5) (load $(cut -d' ' -f1-3 /proc/loadavg))"
