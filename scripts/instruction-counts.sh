#!/usr/bin/env bash
# Instructions executed by whole `hushfuse run` commands (valgrind's callgrind), one thread: the
# same on a busy or a quiet machine, so a change of a few percent shows where wall time is noise.
# Compare two builds by running it with HUSHFUSE pointing at each binary.
#
# Usage: scripts/instruction-counts.sh [SCENARIO@TRIALS ...]
#   default: the peers' KF Monte Carlo (kfmc.toml of ../shared/peers, or benches/peers if absent,
#   at 10,000 trials) and default, zheng-fig1, zhang-fig5 at 8 trials.
# Uses target/release/hushfuse (HUSHFUSE overrides). Needs valgrind.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${HUSHFUSE:-target/release/hushfuse}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
runs=("$@")
if [ ${#runs[@]} -eq 0 ]; then
    peers=../shared/peers/kfmc.toml
    if [ -f "$peers" ]; then
        sed 's/^trials = .*/trials = 10000/' "$peers" >"$work/kfmc10k.toml"
        runs+=("$work/kfmc10k.toml@10000")
    fi
    runs+=(default@8 zheng-fig1@8 zhang-fig5@8)
fi
for r in "${runs[@]}"; do
    scenario=${r%@*}
    trials=${r##*@}
    rm -rf "$work/out"
    valgrind --tool=callgrind --callgrind-out-file="$work/cg.out" \
        "$bin" run "$scenario" --trials "$trials" --threads 1 --out "$work/out" >/dev/null 2>"$work/err"
    echo "$(basename "$scenario") trials $trials: $(grep -o 'Collected : [0-9]*' "$work/err" | awk '{print $3}') instructions"
done
