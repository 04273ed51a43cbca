#!/usr/bin/env bash
# What a lossy link costs a whole `hushfuse run`, as a user meets it: arena-1d as shipped against
# the same file with a Bernoulli link that draws its fates but loses (almost) nothing
# (loss = 1e-12: the fate tables, the link layer of the generic loop and the fast paths' loss
# masks all run, no packet is lost) and against a link that loses 10% of the packets, one thread.
#
# Usage: scripts/channel-cost.sh [ROUNDS]          user CPU seconds of the whole command,
#                                                   alternating rounds (default 5)
#        MEASURE=instructions scripts/channel-cost.sh   instructions executed (valgrind's
#                                                   cachegrind, TRIALS trials, default 50): the
#                                                   same on a busy or a quiet machine
# Uses target/release/hushfuse (HUSHFUSE overrides).
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-5}
bin=${HUSHFUSE:-target/release/hushfuse}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp scenarios/arena-1d.toml "$work/plain.toml"
{ cat scenarios/arena-1d.toml; printf '\n[channel]\nkind = "bernoulli"\nloss = 1e-12\n'; } >"$work/link.toml"
{ cat scenarios/arena-1d.toml; printf '\n[channel]\nkind = "bernoulli"\nloss = 0.1\n'; } >"$work/loss0.1.toml"
if [ "${MEASURE:-time}" = instructions ]; then
    trials=${TRIALS:-50}
    for f in plain link loss0.1; do
        rm -rf "$work/out"
        valgrind --tool=cachegrind --cache-sim=no --cachegrind-out-file=/dev/null \
            "$bin" run "$work/$f.toml" --threads 1 --trials "$trials" --out "$work/out" \
            >/dev/null 2>"$work/vg"
        echo "$f: $(grep -o 'I *refs: *[0-9,]*' "$work/vg" | tr -s ' ') instructions"
    done
    exit 0
fi
for r in $(seq "$rounds"); do
    line="round $r:"
    for f in plain link loss0.1; do
        rm -rf "$work/out-$f"
        /usr/bin/time -o "$work/t" -f "%U" "$bin" run "$work/$f.toml" --threads 1 --out "$work/out-$f" >/dev/null 2>&1
        line="$line $f $(cat "$work/t") s"
    done
    echo "$line"
done
