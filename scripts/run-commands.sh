#!/bin/bash
# Runs every command that writes an output folder (run --report, reproduce, run --budgets
# --report, replay with and without truth, run --shard + merge --report, report) with two
# hushfuse binaries into WORK/old and WORK/new, for scripts/compare-output-trees.py: the
# output path is shared by all of them, so a change to it shows here.
# Usage: scripts/run-commands.sh OLD_BIN NEW_BIN WORK
old=$1; new=$2; work=$3; rm -rf "$work"; mkdir -p "$work"
for side in old new; do bin=${!side}; o=$work/$side; mkdir -p "$o" "$work/data-$side"
 run() { "$bin" "$@" >/dev/null 2>&1 || echo "$side: $* failed"; }
 run run default --trials 8 --threads 2 --report --out "$o/run-report"
 run reproduce dormann-fig1 --trials 8 --threads 2 --out "$o/reproduce" --write-trial 3 "$work/data-$side"
 run run arena-1d --budgets 12,48 --budget-axis payload --trials 20 --pilot-trials 10 --threads 2 --report --out "$o/arena"
 run replay dormann-fig1 --measurements "$work/data-$side/measurements.csv" --truth "$work/data-$side/truth.csv" --trial 3 --out "$o/replay-truth"
 run replay dormann-fig1 --measurements "$work/data-$side/measurements.csv" --trial 3 --out "$o/replay-estimates"
 for i in 1 2 3; do run run zheng-fig1 --trials 40 --threads 2 --shard $i/3 --out "$work/shards-$side"; done
 run merge "$work/shards-$side" --report --out "$o/merged"
 run run zheng-fig1 --trials 40 --threads 2 --out "$o/report-later"
 run report "$o/report-later"
done
echo done
