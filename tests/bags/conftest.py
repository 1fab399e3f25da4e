"""Shared helpers of the bag tests: the `tending` binary, bounded subprocess runs."""

import os
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
# TENDING_BIN_DIR: where the cargo release binaries are (default target/release)
RELEASE = pathlib.Path(os.environ.get('TENDING_BIN_DIR') or REPO / 'target' / 'release')
TENDING = RELEASE / 'tending'

sys.path.insert(0, str(REPO / 'tests'))
from domain_lease import lease  # noqa: E402


def next_domain_id():
    """A DDS domain of its own per test (tests/domain_lease.py)."""
    return lease()


@pytest.fixture
def tending():
    if not (TENDING.is_file() and os.access(TENDING, os.X_OK)):
        pytest.skip(f'{TENDING} is not built yet (cargo build --release --bin tending)')
    return TENDING


def run(*args, timeout=120, env=None):
    """Run to completion; fail with its output on a non-zero exit."""
    p = subprocess.run([str(a) for a in args], capture_output=True, text=True,
                       timeout=timeout, env=env)
    assert p.returncode == 0, f'{args}: exit {p.returncode}\n{p.stdout}\n{p.stderr}'
    return p.stdout + p.stderr
