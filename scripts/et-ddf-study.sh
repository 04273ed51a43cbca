#!/usr/bin/env bash
# The et-ddf study at small scale (issue 40): runs the built-in `et-ddf-tree` (30 agents in a
# tree, absolute sensors on 4, the trigger delta swept in the file) at every link's drop
# probability 0, 0.2, 0.5 and 0.8, and tabulates the mean agent's steady-state MSE (± its Monte
# Carlo standard error), the worst agent's, the ANEES and the messages a step against both, in
# docs/et-ddf-study.md and target/et-ddf-study/study.csv. About half a minute on 2 cores.
# Usage: scripts/et-ddf-study.sh [trials]
set -euo pipefail
cd "$(dirname "$0")/.."
trials="${1:-}"
cargo build --release --quiet
out=target/et-ddf-study
mkdir -p "$out"
cp scenarios/et-ddf-tree.toml "$out/et-ddf-tree.toml"
for drop in 0 0.2 0.5 0.8; do
    if [ "$drop" = 0 ]; then
        channel='kind = "ideal"'
    else
        channel="kind = \"bernoulli\"\nloss = $drop"
    fi
    sed "s/^kind = \"ideal\"$/$channel/" "$out/et-ddf-tree.toml" > "$out/drop-$drop.toml"
    rm -rf "$out/drop-$drop"
    ./target/release/hushfuse run "$out/drop-$drop.toml" ${trials:+--trials "$trials"} \
        --out "$out/drop-$drop" > "$out/drop-$drop.txt"
done
python3 scripts/et-ddf-table.py "$out" > docs/et-ddf-study.md
echo "wrote docs/et-ddf-study.md and $out/study.csv" >&2
