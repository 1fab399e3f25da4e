"""ROS domain ids for the Python tests, leased exactly as the Rust tests lease theirs
(test-domains/): an advisory lock (flock) on $TMPDIR/tending-test-domains/<id>.lock,
which the kernel drops when the holder exits. So these tests can run while the Rust
real-time tests run (tests/run_all.sh) and never meet them on DDS.

A pytest process keeps every domain it leased until it ends: no test gets a domain that
an earlier test's processes have just left (their DDS endpoints and latched samples)."""

import fcntl
import os
import tempfile

# The same pool as test-domains/src/lib.rs: 0-19 left to people, 230 the secure limit.
FIRST, END = 20, 231
_held = []


def lease():
    """A free ROS domain id, held until this process exits."""
    lock_dir = os.path.join(tempfile.gettempdir(), 'tending-test-domains')
    os.makedirs(lock_dir, exist_ok=True)
    n = END - FIRST
    start = os.getpid() % n
    for i in range(n):
        dom = FIRST + (start + i) % n
        f = open(os.path.join(lock_dir, f'{dom}.lock'), 'a')
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.close()
            continue
        _held.append(f)
        return dom
    raise RuntimeError(f'no free ROS domain in {FIRST}..{END} (locks in {lock_dir})')
