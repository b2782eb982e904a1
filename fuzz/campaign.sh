#!/bin/sh
# Long fuzzing campaign, outside CI: fuzz/campaign.sh RUNS TARGET...
# (MAX_SECS=N in the environment also stops each target after N seconds,
# whichever comes first; libFuzzer's final stats say how many runs it made.)
#
# For each TARGET, one after the other, at the lowest CPU priority:
# 1. fuzzes it for RUNS executions (-runs) on fuzz/corpus/TARGET, built
#    without AddressSanitizer (-s none, target dir target/campaign): the
#    core and the harness are safe Rust, so the bounds, overflow and debug
#    assertion checks that stay on are the ones that can fire, and the
#    build runs about four times faster;
# 2. replays the whole corpus once (-runs=0) in the default build, with
#    AddressSanitizer, so every input the campaign kept also ran under ASan.
#
# Prints one line per target from libFuzzer's final lines; the full logs
# are in fuzz/artifacts/campaign/TARGET.log and TARGET.asan.log, crashes in
# fuzz/artifacts/TARGET/. Exits non-zero if a target crashed.
set -eu

RUNS=${1:?usage: fuzz/campaign.sh RUNS TARGET...}
shift
MAX_SECS=${MAX_SECS:-0}
cd "$(dirname "$0")"
mkdir -p artifacts/campaign
failed=0
for t in "$@"; do
    mkdir -p "corpus/$t" "artifacts/$t"
    log="artifacts/campaign/$t.log"
    start=$(date +%s)
    rc=0
    nice -n 19 cargo +nightly fuzz run -s none --target-dir target/campaign "$t" "corpus/$t" -- \
        -runs="$RUNS" -max_total_time="$MAX_SECS" -print_final_stats=1 >"$log" 2>&1 || rc=$?
    secs=$(($(date +%s) - start))
    done_line=$(grep -E 'DONE +cov' "$log" | tail -n 1 || true)
    rc2=0
    nice -n 19 cargo +nightly fuzz run "$t" "corpus/$t" -- -runs=0 \
        >"artifacts/campaign/$t.asan.log" 2>&1 || rc2=$?
    asan=$(grep -E 'INITED|DONE' "artifacts/campaign/$t.asan.log" | tail -n 1 || true)
    if [ "$rc" -ne 0 ] || [ "$rc2" -ne 0 ]; then
        failed=1
        status="FAIL (fuzz exit $rc, ASan replay exit $rc2)"
    else
        status=ok
    fi
    runs=$(grep -E '^stat::number_of_executed_units' "$log" | tail -n 1 | sed -E 's/.*: *//' || true)
    echo "$t: $done_line | runs ${runs:--} | wall ${secs}s | corpus $(ls "corpus/$t" | wc -l) files | ASan replay: $asan | $status"
done
exit "$failed"
