#!/bin/sh
# Bounded fuzzing smoke run for CI: fuzz/smoke.sh SECONDS
#
# Installs nightly and cargo-fuzz when missing, seeds the corpora, builds
# every target, runs each for SECONDS (-max_total_time) and prints one line
# per target: executions, run time, crashes. Exits non-zero if any target
# crashed (its input is left in fuzz/artifacts/<target>/) or failed to run.
set -eu

SECS=${1:?usage: fuzz/smoke.sh SECONDS}
cd "$(dirname "$0")"

if ! rustup run nightly rustc --version >/dev/null 2>&1; then
    rustup toolchain install nightly --profile minimal
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    cargo install cargo-fuzz --locked
fi

sh ./seed.sh
cargo +nightly fuzz build

TARGETS=$(cargo +nightly fuzz list)
LOGS=$(mktemp -d)
trap 'rm -rf "$LOGS"' EXIT
failed=0
for t in $TARGETS; do
    mkdir -p "corpus/$t"
    rc=0
    cargo +nightly fuzz run "$t" "corpus/$t" -- -max_total_time="$SECS" \
        >"$LOGS/$t.log" 2>&1 || rc=$?
    crashes=0
    if [ -d "artifacts/$t" ]; then
        crashes=$(find "artifacts/$t" -type f -newer "$LOGS" | wc -l)
    fi
    # libFuzzer's last line: "Done N runs in S second(s)".
    done_line=$(grep -E '^Done [0-9]+ runs in [0-9]+ second' "$LOGS/$t.log" | tail -n 1 || true)
    runs=$(echo "$done_line" | sed -nE 's/^Done ([0-9]+) runs.*/\1/p')
    secs=$(echo "$done_line" | sed -nE 's/.* in ([0-9]+) second.*/\1/p')
    if [ "$rc" -ne 0 ] || [ "$crashes" -ne 0 ] || [ -z "$done_line" ]; then
        failed=1
        [ "$crashes" -eq 0 ] && crashes=1
        status=FAIL
    else
        status=ok
    fi
    printf '%-16s executions=%-10s seconds=%-4s crashes=%s %s\n' \
        "$t" "${runs:--}" "${secs:--}" "$crashes" "$status"
    if [ "$status" = FAIL ]; then
        grep -E 'panicked|ERROR|SUMMARY|Test unit written' "$LOGS/$t.log" | head -n 20 | sed 's/^/    /'
    fi
done
exit "$failed"
