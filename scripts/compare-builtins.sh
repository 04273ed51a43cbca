#!/bin/sh
# Runs every built-in at its golden trial count and compares its summary.json with the
# baseline in $1 (default /work/baseline/small): pre-existing values must be unchanged.
base=${1:-/work/baseline/small}
out=$(mktemp -d)
status=0
grep -o '("[a-z0-9-]*", [0-9]*' tests/golden.rs | tr -d '("' | tr ',' ' ' | while read -r id trials; do
  target/release/hushfuse reproduce "$id" --trials "$trials" --out "$out/$id" >/dev/null 2>&1 || echo "$id: run failed"
  if python3 scripts/compare-summaries.py "$base/$id/summary.json" "$out/$id/summary.json" --ignore paper.claims > "$out/$id.diff"; then
    echo "$id: unchanged ($(grep -c ignored "$out/$id.diff") claim texts differ)"
  else
    echo "$id: CHANGED"; head -5 "$out/$id.diff"
  fi
done
