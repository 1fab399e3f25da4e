#!/usr/bin/env bash
# Lay out an ament install prefix for the `tending` package from the cargo release build:
#
#   PREFIX/lib/tending/robot_node, PREFIX/lib/tending/sim_bridge      (the binaries)
#   PREFIX/share/ament_index/resource_index/packages/tending          (the ament marker)
#   PREFIX/share/tending/package.xml
#   PREFIX/share/tending/launch/fleet.launch.py
#   PREFIX/share/tending/configs/*.toml                               (if any)
#
# Then, with PREFIX on AMENT_PREFIX_PATH (e.g. `export AMENT_PREFIX_PATH=PREFIX:$AMENT_PREFIX_PATH`),
# `ros2 run tending robot_node --ros-args -r __ns:=/robot_3` and
# `ros2 launch tending fleet.launch.py robots:=4` find them.
#
# usage: launch-scripts/install.sh [--symlink] [--allow-missing] PREFIX
#   --symlink        symlink the binaries instead of copying them
#   --allow-missing  skip a binary that is not built yet (with a warning) instead of failing
# environment: TENDING_BIN_DIR (default: <repo>/target/release)
set -euo pipefail

usage() { sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//'; }

symlink=0
allow_missing=0
prefix=""
while [ $# -gt 0 ]; do
    case "$1" in
        --symlink) symlink=1 ;;
        --allow-missing) allow_missing=1 ;;
        -h|--help) usage; exit 0 ;;
        -*) echo "install.sh: unknown option $1" >&2; usage >&2; exit 2 ;;
        *)
            if [ -n "$prefix" ]; then echo "install.sh: one PREFIX only" >&2; exit 2; fi
            prefix="$1" ;;
    esac
    shift
done
if [ -z "$prefix" ]; then usage >&2; exit 2; fi

here="$(cd "$(dirname "$0")" && pwd)"
repo="$(cd "$here/.." && pwd)"
bin_dir="${TENDING_BIN_DIR:-$repo/target/release}"
# Absolute, so that --symlink links do not dangle when TENDING_BIN_DIR is relative.
if [ -d "$bin_dir" ]; then bin_dir="$(cd "$bin_dir" && pwd)"; fi

mkdir -p "$prefix"
prefix="$(cd "$prefix" && pwd)"
lib="$prefix/lib/tending"
share="$prefix/share/tending"
index="$prefix/share/ament_index/resource_index/packages"
mkdir -p "$lib" "$share/launch" "$index"

installed=0
for b in robot_node sim_bridge; do
    src="$bin_dir/$b"
    if [ ! -x "$src" ] || [ ! -f "$src" ]; then
        if [ "$allow_missing" = 1 ]; then
            echo "install.sh: warning: $src not built (cargo build --release); skipped" >&2
            continue
        fi
        echo "install.sh: error: $src not built: run \`cargo build --release\` first (or pass --allow-missing)" >&2
        exit 1
    fi
    rm -f "$lib/$b"
    if [ "$symlink" = 1 ]; then
        ln -s "$src" "$lib/$b"
    else
        install -m 0755 "$src" "$lib/$b"
    fi
    installed=$((installed + 1))
done
if [ "$installed" = 0 ]; then
    echo "install.sh: error: no binary installed from $bin_dir" >&2
    exit 1
fi

install -m 0644 "$here/package.xml" "$share/package.xml"
install -m 0644 "$here/fleet.launch.py" "$share/launch/fleet.launch.py"
shopt -s nullglob
configs=("$repo"/configs/*.toml)
if [ ${#configs[@]} -gt 0 ]; then
    mkdir -p "$share/configs"
    install -m 0644 "${configs[@]}" "$share/configs/"
fi
# the ament resource index marker: an empty file named after the package
: > "$index/tending"

echo "installed tending ($installed binaries) into $prefix"
echo "use: export AMENT_PREFIX_PATH=$prefix\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}"
