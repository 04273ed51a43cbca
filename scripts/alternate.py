#!/usr/bin/env python3
"""Times whole commands side by side, in alternating rounds (each command once per round, in
turn), and prints each one's min / median / max wall time. The machine drifts by tens of percent
from minute to minute: compare commands timed in the same rounds, never runs from different
minutes. Speed ratios against the numpy peers in the notes and the README come from this.

Usage: scripts/alternate.py ROUNDS "command 1" "command 2" ...
Example (from ../shared/peers, one core):
  scripts/alternate.py 5 "taskset -c 0 python pf_censored.py --model 1d ..." \\
      "taskset -c 0 hushfuse run pfb.toml --threads 1 --out /tmp/pfb"
"""
import statistics
import subprocess
import sys
import time


def main() -> None:
    if len(sys.argv) < 3 or not sys.argv[1].isdigit() or int(sys.argv[1]) < 1:
        sys.exit(__doc__)
    rounds, commands = int(sys.argv[1]), sys.argv[2:]
    times = {c: [] for c in commands}
    for _ in range(rounds):
        for c in commands:
            start = time.perf_counter()
            done = subprocess.run(c, shell=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            times[c].append(time.perf_counter() - start)
            if done.returncode != 0:
                sys.exit(f"alternate: exit status {done.returncode}: {c}")
    for c in commands:
        t = sorted(times[c])
        print(f"min {t[0] * 1e3:9.1f}  median {statistics.median(t) * 1e3:9.1f}  "
              f"max {t[-1] * 1e3:9.1f} ms  {c}")


if __name__ == "__main__":
    main()
