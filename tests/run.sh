#!/usr/bin/env bash
# tests/run.sh: the whole suite (make test). Runs every tests/t_*.sh in name order, each adding
# PASS/FAIL/SKIP lines, and ends with "N passed, N failed". Exits non-zero on any failure.
set -u
cd "$(dirname "$0")/.."
PASSED=0 FAILED=0 SKIPPED=0
. tests/lib.sh
for t in tests/t_*.sh; do
    echo "== $t"
    . "$t"
done
echo "$PASSED passed, $FAILED failed, $SKIPPED skipped"
[ "$FAILED" -eq 0 ]
