#!/usr/bin/env bash
# Alternating wall-time comparison of two builds of the scenarios bench, in the same minutes:
# the machine drifts by tens of percent from minute to minute, so compare the best (min) of
# alternating rounds, never two runs taken at different times.
# Usage: scripts/bench-ab.sh BENCH_A BENCH_B [ROUNDS=4] [SCENARIO=kfmc@1] [REPEATS=31]
#   BENCH_x: a copy of the bench binary (`cargo bench --bench scenarios --no-run` prints its
#   path) from each build. Prints, per binary, the best min and the best median over rounds.
set -euo pipefail
a=$1; b=$2; rounds=${3:-4}; scen=${4:-kfmc@1}; rep=${5:-31}
for _ in $(seq "$rounds"); do
    for x in "$a" "$b"; do
        line=$(HUSHFUSE_BENCH_SCENARIOS=$scen HUSHFUSE_BENCH_REPEATS=$rep "$x" --bench)
        echo "$x $(echo "$line" | sed -E 's/.*min ([0-9.]+) s, median ([0-9.]+) s.*/\1 \2/')"
    done
done | awk '{ if (!($1 in m) || $2 < m[$1]) m[$1] = $2; if (!($1 in d) || $3 < d[$1]) d[$1] = $3 }
    END { for (k in m) print k ": best min " m[k] " s, best median " d[k] " s" }'
