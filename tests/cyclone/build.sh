#!/usr/bin/env bash
# Build the Cyclone DDS test peer (cyclone_peer.c) into OUT (default
# target/cyclone), installing Debian's Cyclone DDS 0.10 if it is missing: libddsc0debian
# (with the DDS Security plugins libdds_security_{auth,ac,crypto}, built on OpenSSL 3),
# cyclonedds-dev (headers) and cyclonedds-tools (idlc). Prints the binary's path.
# Run by ros/tests/cyclone.rs; rebuilds only when a source is newer than the binary.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
out="${1:-$here/../../target/cyclone}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
# One build at a time: the test runner starts several Cyclone tests at once, and two
# apt-get runs or two idlc runs into one directory would trip over each other.
exec 9>"$out/.build.lock"
flock 9
need=0
command -v idlc >/dev/null || need=1
[ -f /usr/include/dds/dds.h ] || need=1
plugins="$(dpkg -L libddsc0debian 2>/dev/null | grep '/libdds_security_auth\.so$' | head -1 || true)"
[ -n "$plugins" ] || need=1
if [ "$need" = 1 ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "installing Cyclone DDS (libddsc0debian cyclonedds-dev cyclonedds-tools)" >&2
        { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
            libddsc0debian cyclonedds-dev cyclonedds-tools; } >&2
        plugins="$(dpkg -L libddsc0debian | grep '/libdds_security_auth\.so$' | head -1)"
    else
        echo "Cyclone DDS missing: apt-get install -y libddsc0debian cyclonedds-dev cyclonedds-tools" >&2
        exit 1
    fi
fi
plugin_dir="$(dirname "$plugins")"
bin="$out/cyclone_peer"
if [ ! -x "$bin" ] || [ "$here/cyclone_peer.c" -nt "$bin" ] || [ "$here/ros_msgs.idl" -nt "$bin" ] \
    || [ "$0" -nt "$bin" ]; then
    idlc -Wno-implicit-extensibility -o "$out" "$here/ros_msgs.idl" >&2 2>/dev/null \
        || idlc -o "$out" "$here/ros_msgs.idl" >&2
    cc -O1 -Wall -o "$bin.tmp" -I"$out" -DPLUGIN_DIR="\"$plugin_dir\"" \
        "$here/cyclone_peer.c" "$out/ros_msgs.c" -lddsc >&2
    mv "$bin.tmp" "$bin"
fi
echo "$bin"
