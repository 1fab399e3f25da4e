#!/usr/bin/env bash
# One training update of the bundled config (target actions through the ORCA filter) with
# two `tending` binaries, alternating in one run: rollout and PPO seconds per update from
# each run's log.csv, CPU time and load. Also checks that both binaries learned the same
# weights (the speed-ups keep the bits).
# usage: update_side_by_side.sh OLD_TENDING NEW_TENDING [setup 100.16_2] [rounds 2]
set -euo pipefail
old=$1 new=$2 setup=${3:-100.16_2} rounds=${4:-2}
cfg="$(cd "$(dirname "$0")/../.." && pwd)/policy/pretrained/smappo_6.4_2.train.toml"
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
echo "$(date -u '+%F %H:%M') UTC, $setup, one update of 8 envs x 10 epochs, config $cfg"
for r in $(seq "$rounds"); do
  for side in old new; do
    bin=$old; [ "$side" = new ] && bin=$new
    d="$tmp/$side"; rm -rf "$d"
    /usr/bin/time -f "%U %S" -o "$tmp/time" "$bin" train --setup "$setup" --episodes 8 \
      --config "$cfg" --out "$d" --quiet --max-updates 1 >/dev/null 2>&1
    IFS=, read -r roll ppo <<<"$(tail -1 "$d/log.csv" | cut -d, -f17,18)"
    read -r usr sys <"$tmp/time"
    echo "round $r $side: rollout ${roll} s, PPO ${ppo} s, CPU user+sys $(echo "$usr + $sys" | bc) s, load $(cut -d' ' -f1 /proc/loadavg)"
  done
  # tensor bytes after the safetensors header (the header's metadata may differ)
  python3 - "$tmp/old/policy.safetensors" "$tmp/new/policy.safetensors" "$r" <<'PY'
import struct, sys
def data(p):
    b = open(p, "rb").read()
    return b[8 + struct.unpack("<Q", b[:8])[0]:]
same = data(sys.argv[1]) == data(sys.argv[2])
print(f"round {sys.argv[3]}: learned weights {'identical' if same else 'DIFFER'}")
PY
done
