"""Shared helpers of the bag tests: the `tending` binary, bounded subprocess runs."""

import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
# TENDING_BIN_DIR: where the cargo release binaries are (default target/release)
RELEASE = pathlib.Path(os.environ.get('TENDING_BIN_DIR') or REPO / 'target' / 'release')
TENDING = RELEASE / 'tending'

_BASE = os.getpid() % 80
_next = [0]


def next_domain_id():
    """A DDS domain of its own per test (121..200: clear of tests/interop's 1..100)."""
    d = 121 + (_BASE + _next[0]) % 80
    _next[0] += 1
    return d


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
