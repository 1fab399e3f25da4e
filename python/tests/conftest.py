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
