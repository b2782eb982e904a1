#!/bin/sh
# Regenerates fuzz/corpus/<target>/ seed files from host-tests/fixtures/frames.txt
# and generated position-stream frames (deterministic: fixed PRNG seed).
# The corpus is not committed; run this before the first fuzzing session.
set -eu
exec python3 "$(dirname "$0")/seed.py"
