#!/usr/bin/env bash
# Every test of the project, as CI runs it (.ci/run calls exactly this).
# Rust: unit, integration and DDS loopback tests of every crate (release build: the
# trainer and simulator tests are compute-heavy and the DDS tests time real latencies).
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never
echo "== cargo test --workspace --release"
cargo test --workspace --release --locked -j 2 2>&1
