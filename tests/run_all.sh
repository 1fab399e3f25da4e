#!/usr/bin/env bash
# Every test of the project, as CI runs it (.ci/run calls exactly this).
# Rust: unit, integration and DDS loopback tests of every crate (release build: the
# trainer and simulator tests are compute-heavy and the DDS tests time real latencies).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never
# Elapsed time per section, so a slow suite shows where its minutes go.
section() { echo "== [$(date -u +%H:%M:%S), ${SECONDS}s] $*"; }

# System tools the fault tests use (network namespaces, packet loss): Debian packages,
# installed here so a fresh machine needs nothing by hand. (Cyclone DDS, for the secure
# interop tests in ros/tests/cyclone.rs, is installed by tests/cyclone/build.sh when the
# test first needs it.)
if ! command -v iptables >/dev/null || ! command -v ip >/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        section "apt-get install iptables iproute2 (fault tests)"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq iptables iproute2
    fi
fi
# Python test environments (virtualenvs in target/, ignored). Each is created if missing
# and rebuilt only when its requirements file or the Python version changes. On a fresh
# clone creating them is mostly downloading wheels, so it runs in the background while
# cargo builds (the two cores are cargo's; pip mostly waits on the network) and is
# waited for before the first Python section.
py_sys="$(command -v python3.11 || command -v python3)"
# ensure_venv DIR REQUIREMENTS
ensure_venv() {
    local dir="$1" req="$2" want
    want="$(sha256sum "$req" | cut -d' ' -f1) $("$py_sys" -c 'import sys; print(sys.version.split()[0])')"
    if [ ! -x "$dir/bin/python" ] || [ "$(cat "$dir/.requirements.sha256" 2>/dev/null)" != "$want" ]; then
        # `|| return 1` on each step: set -e does not apply inside an && list, and a
        # failed install must not be recorded as done.
        rm -rf "$dir" || return 1
        "$py_sys" -m venv "$dir" || return 1
        "$dir/bin/python" -m pip install --quiet --disable-pip-version-check -r "$req" || return 1
        echo "$want" > "$dir/.requirements.sha256"
    fi
}
venv="target/interop-venv"
venv_b="target/venv-bags"
venv_p="target/venv-python"
mkdir -p target
venv_log="target/venvs.log"
(
    ensure_venv "$venv" tests/interop/requirements.txt &&
        ensure_venv "$venv_b" tests/bags/requirements.txt &&
        ensure_venv "$venv_p" python/tests/requirements.txt
) >"$venv_log" 2>&1 &
venv_pid=$!
# A failed cargo step ends the script; do not leave pip running behind it.
trap 'kill "$venv_pid" 2>/dev/null || true' EXIT
# wait_venvs: the background venv job's result; its output is shown if it failed.
wait_venvs() {
    if ! wait "$venv_pid"; then
        echo "creating the Python test virtualenvs failed:"
        cat "$venv_log"
        exit 1
    fi
}

# Binaries first: the fault tests (sim-bridge/tests -> tests/faults) and the interop tests
# run the `tending`, `robot_node` and `sim_bridge` binaries of other packages, which
# `cargo test` does not build for them.
section "cargo build --release --workspace --bins"
cargo build --release --locked -j 2 --workspace --bins 2>&1

# Python: rclpy (real ROS 2 Jazzy, Fast DDS, from PyPI wheels) against the release binaries:
# tests/interop (launch-scripts install layout + launch file, robot_node and sim_bridge
# interop over DDS); then rosbag2 MCAP bags written by `tending` read back by the `rosbags`
# and `mcap` + `mcap-ros2-support` packages. The virtualenvs live in target/ (ignored),
# are created if missing and reinstalled only when their requirements file changes.
# -rsxR: print why anything was skipped, is a known failure (xfail) or was rerun.
# --reruns 1: a test that fails is run once more and the summary line says "N rerun":
# start-up discovery between RustDDS and Fast DDS failed once in ~10 full local runs
# (rclpy saw none of sim_bridge's writers in 20 s); a real regression fails both runs.
# No tests collected = pytest exit 5 = failure.
python_ros_tests() {
    echo "-- python interop tests (tests/interop)"
    timeout 900 "$venv/bin/python" -m pytest tests/interop -q -rsxR --reruns 1 --reruns-delay 1 \
        -p no:cacheprovider || return 1
    echo "-- python bag tests (tests/bags)"
    timeout 600 "$venv_b/bin/python" -m pytest tests/bags -q -rs -p no:cacheprovider
}
export TENDING_BIN_DIR="${TENDING_BIN_DIR:-$(cd "${CARGO_TARGET_DIR:-target}/release" && pwd)}"
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
unset ROS_LOCALHOST_ONLY ROS_AUTOMATIC_DISCOVERY_RANGE ROS_STATIC_PEERS FASTRTPS_DEFAULT_PROFILES_FILE

# Vendored rustdds (third_party/, ADR 0005): the start-up deadlock regression tests, the
# DATA_FRAG tests (an encrypted fragment run must survive deserialization) and the
# crypto-handle test (a re-created writer must register), the reader-cache tests (built-in
# readers must not lose unread discovery or key-exchange samples), the Cyclone DDS interop
# fixes (handshake tokens without the optional DH keys, NUL-terminated algorithm names, no
# crypto token of kind NONE, the final DATA_FRAG padded to 4 bytes; issue 38), with the
# security feature the fleet builds it with. Run from a copy outside the workspace: cargo
# refuses a nested package that is not a member. Built in the dev profile without
# debuginfo: these are logic regression tests (they pass in 2 s either way), and an
# unoptimised build of rustdds and its ~120 dependencies takes 1.5 min here against 3-4 min
# optimised. Argument: how many cargo build jobs.
rustdds_tests() {
    local rdds
    rdds="$(mktemp -d)"
    cp -r third_party/rustdds/. "$rdds"
    CARGO_TARGET_DIR="$PWD/target/third_party" cargo test --locked -j "$1" \
        --config 'profile.dev.debug=0' \
        --manifest-path "$rdds/Cargo.toml" --features security --lib -- \
        discovery::discovery::tests::announcing_a_local_writer_holds_no_lock_across_blocking_sends \
        discovery::discovery::tests::the_published_announce_code_path_deadlocks_and_the_test_sees_it \
        messages::submessages::data_frag::tests \
        security::cryptographic::cryptographic_builtin::crypto_key_factory::tests \
        structure::dds_cache::tests \
        discovery::discovery::tests::sedp_topic_caches_get_sedp_reader_limits \
        security::authentication::authentication_builtin::types::tests \
        security::cryptographic::cryptographic_builtin::key_material::tests \
        rtps::message::tests::the_final_data_frag_of_an_unaligned_sample_is_padded_to_4_bytes \
        || { rm -rf "$rdds"; return 1; }
    rm -rf "$rdds"
}
# wait_logged PID LOG WHAT: wait for a background section, show its output, stop on failure.
wait_logged() {
    local ok=0
    wait "$1" || ok=$?
    cat "$2"
    [ "$ok" = 0 ] || { echo "$3 failed (exit $ok)"; exit 1; }
}

# cargo-nextest (part of this machine kind) runs the tests several at once, each in a
# process of its own: the real-time ROS 2 tests mostly wait on wall-clock time, and one
# after another they took ~370 s of the suite (.config/nextest.toml, docs/bench/suite.md).
# The Python ROS tests (real-time too, light on CPU) run beside them once the test
# binaries are built. Every test leases ROS domains of its own (test-domains/,
# tests/domain_lease.py), so none meet on DDS. Without nextest, `cargo test` runs the
# same tests one binary at a time and the Python tests follow.
if cargo nextest --version >/dev/null 2>&1; then
    section "cargo nextest: build the test binaries"
    cargo nextest run --workspace --release --locked --build-jobs 2 --no-run 2>&1
    # The kill test counts contacts of a robot killed mid-run, which the fleet's timing
    # decides: it runs first, with nothing beside it (.config/nextest.toml says why).
    section "cargo nextest run: the kill test, alone"
    cargo nextest run --workspace --release --locked --build-jobs 2 -E 'binary(faults_kill)' 2>&1
    wait_venvs
    py_log="target/python-ros-tests.log"
    python_ros_tests >"$py_log" 2>&1 &
    py_pid=$!
    # The real-time tests leave most of a core idle: the vendored rustdds tests build
    # there, one job, in a target directory of their own.
    rdds_log="target/rustdds-tests.log"
    rustdds_tests 1 >"$rdds_log" 2>&1 &
    rdds_pid=$!
    trap 'kill "$venv_pid" "$py_pid" "$rdds_pid" 2>/dev/null || true' EXIT
    section "cargo nextest run --workspace --release (python ROS tests and the rustdds build beside it)"
    nextest_ok=0
    cargo nextest run --workspace --release --locked --build-jobs 2 --no-fail-fast \
        -E 'not binary(faults_kill)' 2>&1 || nextest_ok=$?
    if [ "$nextest_ok" != 0 ]; then
        # Show what ran beside it before stopping (the EXIT trap would kill it unseen).
        section "python ROS tests and rustdds build beside the failed nextest run"
        wait "$py_pid" || true
        cat "$py_log"
        wait "$rdds_pid" || true
        tail -n 20 "$rdds_log"
        echo "cargo nextest run failed (exit $nextest_ok)"
        exit 1
    fi
    section "cargo test --doc --workspace --release (nextest does not run doctests)"
    cargo test --workspace --release --locked -j 2 --doc 2>&1
    section "python ROS tests (tests/interop, tests/bags), run beside nextest"
    wait_logged "$py_pid" "$py_log" "python ROS tests"
    section "vendored rustdds tests, built beside nextest"
    wait_logged "$rdds_pid" "$rdds_log" "vendored rustdds tests"
else
    section "cargo test --workspace --release (cargo-nextest not installed: one binary at a time)"
    cargo test --workspace --release --locked -j 2 2>&1
    section "python ROS tests (tests/interop, tests/bags)"
    wait_venvs
    python_ros_tests
    section "vendored rustdds tests"
    rustdds_tests 2
fi

# Python: the `tending` package (python/: PyO3 + maturin) built from the checkout with
# `pip install ./python` into its own venv (same reinstall rule for the test
# requirements; the package itself is rebuilt every run, incrementally in the workspace
# target dir, and without build isolation so maturin comes from the venv, not PyPI).
# PettingZoo's API and seed tests, spaces, determinism, equality with `tending sim`.
section "python package tests (python/tests)"
# PATH: maturin's PEP 517 hook runs the `maturin` binary of the venv.
PATH="$PWD/$venv_p/bin:$PATH" "$venv_p/bin/python" -m pip install --quiet \
    --disable-pip-version-check --no-build-isolation --force-reinstall --no-deps ./python
timeout 600 "$venv_p/bin/python" -m pytest python/tests -q -rs -p no:cacheprovider
section "all tests passed"
