#!/usr/bin/env bash
# Splits a hushfuse run over a Slurm job array and merges it in a dependent job.
#
#   scripts/slurm/submit.sh [--wait] [--merge-args "ARGS"] SCENARIO N OUT [hushfuse run options...]
#
# submits an array of N tasks (task I runs `hushfuse run SCENARIO --shard I/N`, writing
# OUT/shards/), then a merge job that starts when every task has succeeded and writes
# OUT/merged/: the same bytes as `hushfuse run SCENARIO --out OUT/merged`. Logs go to OUT/logs/.
# OUT must be on a file system that every node sees. The hushfuse binary is $HUSHFUSE, or
# `hushfuse` on the nodes' PATH. Extra sbatch options (partition, time limit, account) go in
# $SBATCH_OPTS, e.g. SBATCH_OPTS="--partition=short --time=02:00:00".
# Prints the two job ids; with --wait, waits for the merge job and exits with its status.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
wait=()
merge_args=()
while [ $# -gt 0 ]; do
    case "$1" in
        --wait) wait=(--wait); shift ;;
        --merge-args) read -r -a merge_args <<<"$2"; shift 2 ;;
        *) break ;;
    esac
done
if [ $# -lt 3 ]; then
    sed -n '2,13p' "$0" >&2
    exit 2
fi
scenario=$1 n=$2 out=$3
shift 3
case "$n" in ''|*[!0-9]*|0) echo "N must be a positive integer, got '$n'" >&2; exit 2 ;; esac
mkdir -p "$out/logs" "$out/shards"
out=$(cd "$out" && pwd)
# shellcheck disable=SC2086
array=$(sbatch --parsable ${SBATCH_OPTS:-} --array="1-$n" --export=ALL \
    --output="$out/logs/shard-%A_%a.out" "$here/shard.sbatch" "$scenario" "$out" "$@")
array=${array%%;*}
echo "array job $array: $n shards of $scenario into $out/shards"
# shellcheck disable=SC2086
merge=$(sbatch --parsable ${SBATCH_OPTS:-} "${wait[@]}" --dependency="afterok:$array" \
    --kill-on-invalid-dep=yes --export=ALL --output="$out/logs/merge-%j.out" \
    "$here/merge.sbatch" "$out" "${merge_args[@]}")
merge=${merge%%;*}
echo "merge job $merge: into $out/merged once every shard has succeeded"
