#!/usr/bin/env bash
# Runs every fuzz target for SECONDS in parallel (one per core), each with its
# working corpus in build/fuzz/corpus_<t> seeded from fuzz/corpus_seed/<t>,
# then prints per target: executions, coverage (edges) and features.
# Usage: run_fuzz.sh BUILD_DIR SECONDS TARGET...
set -u
dir=$1; secs=$2; shift 2
here=$(cd "$(dirname "$0")" && pwd)
declare -A maxlen=([parser]=256 [core]=2048)
pids=()
for t in "$@"; do
    mkdir -p "$dir/corpus_$t" "$dir/artifacts"
    "$dir/fuzz_$t" "$dir/corpus_$t" "$here/corpus_seed/$t" \
        -max_total_time="$secs" -max_len="${maxlen[$t]:-1024}" -timeout=20 -rss_limit_mb=2048 \
        -print_final_stats=1 -artifact_prefix="$dir/artifacts/$t-" \
        > "$dir/fuzz_$t.log" 2>&1 &
    pids+=($!)
done
rc=0
i=0
for t in "$@"; do
    wait "${pids[$i]}"; trc=$?; i=$((i + 1))
    log="$dir/fuzz_$t.log"
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n1)
    last=$(grep -E '^#[0-9]+' "$log" | tail -n1)
    cov=$(sed -nE 's/.* cov: ([0-9]+).*/\1/p' <<<"$last")
    ft=$(sed -nE 's/.* ft: ([0-9]+).*/\1/p' <<<"$last")
    corp=$(sed -nE 's/.* corp: ([0-9]+\/[0-9A-Za-z]+).*/\1/p' <<<"$last")
    if [ $trc -eq 0 ]; then
        echo "fuzz_$t: OK, ${execs:-?} executions in ${secs} s, coverage ${cov:-?} edges, ${ft:-?} features, corpus ${corp:-?}"
    else
        rc=1
        echo "fuzz_$t: FAILED (exit $trc) after ${execs:-?} executions; log $log, crash input in $dir/artifacts/"
        grep -E 'ERROR|SUMMARY|runtime error|deadly signal' "$log" | head -n 10
    fi
done
exit $rc
