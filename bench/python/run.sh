#!/usr/bin/env bash
# The Python package's benchmark (agent-steps/s through the Python API next to
# `tending bench-sim`) and the RLlib example, written to docs/bench/python.md.
# Not CI: Ray and PyTorch are a large install. Their virtualenv lives in target/venv-rllib,
# created if missing and reinstalled only when bench/python/requirements-rllib.txt changes.
# ITERS (default 10) sets the RLlib training iterations, MINUTES (optional) caps their wall
# time, RUNNERS (default 2) the env runners.
# TORCH_SITE (optional): another venv's site-packages holding torch (e.g.
# target/venv-torchrl/lib/python3.11/site-packages), put on this venv's path with a .pth
# file so the multi-GB torch wheel is not downloaded again; pip then takes torch (and
# whatever else fits) from there. Same Python minor version only.
set -euo pipefail
cd "$(dirname "$0")/../.."
py_sys="$(command -v python3.11 || command -v python3)"
venv="target/venv-rllib"
stamp="$venv/.requirements.sha256"
want="$(sha256sum bench/python/requirements-rllib.txt | cut -d' ' -f1) $("$py_sys" -c 'import sys; print(sys.version.split()[0])')"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    rm -rf "$venv"
    "$py_sys" -m venv "$venv"
    if [ -n "${TORCH_SITE:-}" ]; then
        site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_path("purelib"))')"
        realpath "$TORCH_SITE" > "$site/zz-torch-site.pth"
    fi
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
        -r bench/python/requirements-rllib.txt
    # maturin's build hook runs the venv's own `maturin` binary: install it here even when
    # TORCH_SITE already provides the package.
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
        --ignore-installed --no-deps "$(grep '^maturin' bench/python/requirements-rllib.txt)"
    echo "$want" > "$stamp"
fi
cargo build --release --locked -j 2 --bin tending
PATH="$PWD/$venv/bin:$PATH" "$venv/bin/python" -m pip install --quiet \
    --disable-pip-version-check --no-build-isolation --force-reinstall --no-deps ./python
out="docs/bench/python.md"
"$venv/bin/python" bench/python/bench.py --tending "${CARGO_TARGET_DIR:-target}/release/tending" \
    --out "$out"
"$venv/bin/python" bench/python/rllib_example.py --iters "${ITERS:-10}" \
    ${MINUTES:+--minutes "$MINUTES"} --runners "${RUNNERS:-2}" --eval-episodes 10 --md "$out" \
    --json docs/bench/python_rllib.json --csv docs/bench/python_rllib.csv \
    --png docs/bench/python_rllib.png
