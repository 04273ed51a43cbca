#!/usr/bin/env bash
# What a lossy link costs a whole `hushfuse run`, as a user meets it: arena-1d as shipped against
# the same file with a Bernoulli link that draws its fates but loses (almost) nothing
# (loss = 1e-12: the generic loop and the link layer run, no packet is lost), one thread,
# alternating rounds, user CPU seconds of the whole command.
# Usage: scripts/channel-cost.sh [ROUNDS]   (default 5; uses target/release/hushfuse)
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-5}
bin=${HUSHFUSE:-target/release/hushfuse}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp scenarios/arena-1d.toml "$work/plain.toml"
{ cat scenarios/arena-1d.toml; printf '\n[channel]\nkind = "bernoulli"\nloss = 1e-12\n'; } >"$work/link.toml"
for r in $(seq "$rounds"); do
    line="round $r:"
    for f in plain link; do
        rm -rf "$work/out-$f"
        /usr/bin/time -o "$work/t" -f "%U" "$bin" run "$work/$f.toml" --threads 1 --out "$work/out-$f" >/dev/null 2>&1
        line="$line $f $(cat "$work/t") s"
    done
    echo "$line"
done
