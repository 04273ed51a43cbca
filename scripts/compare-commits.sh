#!/usr/bin/env bash
# Byte-for-byte comparison of every built-in scenario's summary.json between two commits.
# Usage: scripts/compare-commits.sh OLD NEW [TRIALS]
#   TRIALS empty: the full trial counts of the scenario files (minutes); e.g. 8 for a quick look
#   (zheng-fig8/-fig9/-fig10-table3 then run 2 trials). Scenarios that exist in only one of the
#   two commits are reported, not compared.
set -euo pipefail
old=$1; new=$2; trials=${3:-}
work=$(mktemp -d)
cd "$(dirname "$0")/.."
for rev in "$old" "$new"; do
    git worktree add -q --detach "$work/src-$rev" "$rev"
    (cd "$work/src-$rev" && CARGO_TARGET_DIR="$work/target-$rev" cargo build --release --quiet)
    bin="$work/target-$rev/release/hushfuse"
    mkdir -p "$work/out-$rev"
    for id in $("$bin" list | awk '{print $1}'); do
        args=()
        if [ -n "$trials" ]; then
            t=$trials
            case $id in zheng-fig8|zheng-fig9|zheng-fig10-table3) t=2 ;; esac
            args=(--trials "$t")
        fi
        "$bin" reproduce "$id" "${args[@]}" --out "$work/out-$rev/$id" > /dev/null 2>&1 || echo "$rev $id: failed"
    done
    git worktree remove --force "$work/src-$rev"
done
status=0
for f in "$work/out-$old"/*/summary.json; do
    id=$(basename "$(dirname "$f")")
    g="$work/out-$new/$id/summary.json"
    if [ ! -f "$g" ]; then echo "$id: only in $old"; continue; fi
    if cmp -s "$f" "$g"; then echo "$id: identical"; else echo "$id: DIFFERS"; status=1; fi
done
for g in "$work/out-$new"/*/summary.json; do
    id=$(basename "$(dirname "$g")")
    [ -f "$work/out-$old/$id/summary.json" ] || echo "$id: only in $new"
done
echo "outputs kept in $work"
exit $status
