"""Handshake times from secure_discovery debug logs (RUST_LOG=...secure_discovery=debug).

For every log file in the given directories and every remote participant X it names: the
time from the first 'Validated identity of remote participant X' to the first
'Authenticated successfully Participant X'. Prints their distribution, and how many never
completed. usage: handshake_times.py LOG_DIR...
"""
import datetime
import glob
import re
import statistics
import sys

STARTED = re.compile(r"Validated identity of remote participant ([0-9a-f]+)")
DONE = re.compile(r"Authenticated successfully Participant ([0-9a-f]+)")


def stamp(line):
    """The tracing timestamp at the start of a log line (UTC, microseconds)."""
    return datetime.datetime.fromisoformat(line[:26].replace("Z", ""))


def times(path):
    """(handshake seconds of the completed ones, number never completed) of one log."""
    start, done = {}, {}
    with open(path, errors="replace") as f:
        for line in f:
            for pattern, seen in ((STARTED, start), (DONE, done)):
                m = pattern.search(line)
                if m and m.group(1) not in seen:
                    seen[m.group(1)] = stamp(line)
    took = [(done[k] - s).total_seconds() for k, s in start.items() if k in done]
    return took, sum(k not in done for k in start)


def main(dirs):
    durations, never = [], 0
    for d in dirs:
        for path in glob.glob(d + "/*.log"):
            took, missing = times(path)
            durations += took
            never += missing
    if not durations:
        sys.exit("no handshakes found (are the logs at secure_discovery=debug?)")
    durations.sort()
    n = len(durations)
    q = lambda p: durations[min(n - 1, int(p * n))]
    print(
        f"pairs {n} never {never} median {statistics.median(durations):.2f} s "
        f"p90 {q(0.9):.2f} p99 {q(0.99):.2f} max {durations[-1]:.2f}; "
        f">2 s: {sum(d > 2 for d in durations)}, >5 s: {sum(d > 5 for d in durations)}"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
