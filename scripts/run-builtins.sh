#!/bin/bash
# Runs every built-in with two hushfuse binaries into WORK/old and WORK/new (8 trials; 2 for
# zheng-fig8/9/10, 2 threads), for scripts/compare-output-trees.py.
# Usage: scripts/run-builtins.sh OLD_BIN NEW_BIN WORK
old=$1; new=$2; work=$3; rm -rf $work; mkdir -p $work
for side in old new; do bin=${!side}
 for id in $($bin list | awk '{print $1}'); do
  args=(--threads 2 --trials 8)
  case $id in zheng-fig8|zheng-fig9|zheng-fig10-table3) args=(--threads 2 --trials 2);; esac
  $bin reproduce $id "${args[@]}" --out $work/$side/$id >/dev/null 2>&1 || echo "$side $id failed"
 done
done
echo done
