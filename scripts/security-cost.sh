#!/usr/bin/env bash
# What the schemes' savings are worth once frames are signed (issue 41): runs the built-in
# `arena-1d` (every scheme of the registry on one system, its knobs at the file's values) with
# [security] level none, mic-32, enc-mic-64 and mic-128 (key index), and tabulates each scheme's
# frame bits and radio energy a step, and its energy saving against the all-data KF at the same
# level, in docs/security-cost.md and target/security-cost/cost.csv. The estimates do not move
# with the level (checked by the table script). About ten seconds on 2 cores.
# Usage: scripts/security-cost.sh [trials]
set -euo pipefail
cd "$(dirname "$0")/.."
trials="${1:-}"
cargo build --release --quiet
out=target/security-cost
mkdir -p "$out"
for level in none mic-32 enc-mic-64 mic-128; do
    { cat scenarios/arena-1d.toml; printf '\n[security]\nlevel = "%s"\n' "$level"; } \
        > "$out/$level.toml"
    rm -rf "$out/$level"
    ./target/release/hushfuse run "$out/$level.toml" ${trials:+--trials "$trials"} \
        --out "$out/$level" > "$out/$level.txt"
done
python3 scripts/security-cost-table.py "$out" none mic-32 enc-mic-64 mic-128 > docs/security-cost.md
echo "wrote docs/security-cost.md and $out/cost.csv" >&2
