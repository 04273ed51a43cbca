#!/usr/bin/env bash
# Every output file of every built-in, byte for byte, between two hushfuse binaries (e.g. a
# copy of target/release/hushfuse from before a change and one from after).
# Usage: scripts/compare-outputs.sh OLD_BIN NEW_BIN [TRIALS] [THREADS]
#   TRIALS: per scenario (default 8; zheng-fig8/-fig9/-fig10-table3 run 2), "full" for the
#   scenario files' own counts (zheng-fig8/9/10 then skipped: hours). THREADS default 1.
#   reproduction.md is compared without its first line (the elapsed time).
set -uo pipefail
old=$1; new=$2; trials=${3:-8}; threads=${4:-1}
work=$(mktemp -d)
for side in old new; do
    bin=${!side}
    for id in $("$bin" list | awk '{print $1}'); do
        args=(--threads "$threads")
        case $trials:$id in
            full:zheng-fig8|full:zheng-fig9|full:zheng-fig10-table3) continue ;;
            full:*) ;;
            *:zheng-fig8|*:zheng-fig9|*:zheng-fig10-table3) args+=(--trials 2) ;;
            *) args+=(--trials "$trials") ;;
        esac
        "$bin" reproduce "$id" "${args[@]}" --out "$work/$side/$id" >/dev/null 2>&1 || echo "$side $id: failed"
    done
done
status=0
files=0
while IFS= read -r f; do
    files=$((files + 1))
    if [ ! -f "$work/new/$f" ]; then echo "only in old: $f"; status=1; continue; fi
    case $f in
        */reproduction.md) cmp -s <(tail -n +2 "$work/old/$f") <(tail -n +2 "$work/new/$f") ;;
        *) cmp -s "$work/old/$f" "$work/new/$f" ;;
    esac || { echo "DIFFERS: $f"; status=1; }
done < <(cd "$work/old" && find . -type f | sort)
(cd "$work/new" && find . -type f | sort) | while IFS= read -r f; do
    [ -f "$work/old/$f" ] || echo "only in new: $f"
done
[ $status = 0 ] && echo "all $files files identical"
echo "outputs kept in $work"
exit $status
