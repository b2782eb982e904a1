#!/bin/sh
# Regenerates fuzz/corpus/<target>/ seed files from host-tests/fixtures/frames.txt.
# The corpus is not committed; run this before the first fuzzing session.
set -eu
exec python3 "$(dirname "$0")/seed.py"
