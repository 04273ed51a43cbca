#!/usr/bin/env bash
# Steps per second of a live arena-1d (every scheme, STEPS steps, center and node processes on
# this machine) unsecured and at two security levels, in alternated rounds (issue 41: a secured
# run keeps at least 90% of the unsecured steps per second).
#   scripts/live-security-speed.sh [ROUNDS] [STEPS]
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-7}
steps=${2:-200}
bin=target/release/hushfuse
cargo build --release --quiet
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for level in enc-mic-64 mic-32; do
    { cat scenarios/arena-1d.toml; printf '\n[security]\nlevel = "%s"\n' "$level"; } > "$work/$level.toml"
done
for _ in $(seq "$rounds"); do
    for s in arena-1d "$work/enc-mic-64.toml" "$work/mic-32.toml"; do
        rm -rf "$work/out"
        t0=$(date +%s.%N)
        "$bin" live "$s" --steps "$steps" --out "$work/out" > /dev/null 2>&1
        t1=$(date +%s.%N)
        echo "$(basename "$s" .toml) $(awk "BEGIN { print $t1 - $t0 }")"
    done
done > "$work/times.txt"
python3 - "$work/times.txt" "$steps" <<'PY'
import collections, statistics, sys
times = collections.defaultdict(list)
for line in open(sys.argv[1]):
    name, t = line.split()
    times[name].append(float(t))
steps = int(sys.argv[2]) * 17  # arena-1d runs 17 schemes live
base = statistics.median(times["arena-1d"])
for name, v in times.items():
    v.sort()
    m = statistics.median(v)
    print(f"{name:12} min {v[0]:.3f} median {m:.3f} max {v[-1]:.3f} s   "
          f"{steps / m:.0f} steps/s   {100 * base / m:.1f}% of unsecured")
PY
