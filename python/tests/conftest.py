import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def tending_bin():
    """The `tending` CLI built by tests/run_all.sh (TENDING_BIN_DIR), or target/release."""
    d = os.environ.get("TENDING_BIN_DIR") or str(ROOT / "target" / "release")
    b = Path(d) / "tending"
    if not b.is_file():
        pytest.fail(f"the tending binary is not built at {b} (cargo build --release --bins)")
    return str(b)


def rust_eval_row(tending_bin, checkpoint, tmp_path):
    """One 6.4_2 episode (seed 0) of `checkpoint` in `tending eval`, without the ORCA filter:
    its results.csv row (the Rust side of the torch/Rust deployment checks)."""
    import csv
    import subprocess

    out = tmp_path / "eval"
    p = subprocess.run([tending_bin, "eval", "--checkpoint", str(checkpoint), "--setups", "6.4_2",
                        "--seeds", "0", "--episodes", "1", "--no-orca-filter", "--out", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    with open(out / "results.csv", newline="") as fh:
        return next(csv.DictReader(fh))
