#!/usr/bin/env bash
# tests/run.sh: the whole suite (make test). Runs every tests/t_*.sh in name order (or only the files
# named as arguments), each adding PASS/FAIL/SKIP lines, and ends with "N passed, N failed". Exits
# non-zero on any failure.
set -u
cd "$(dirname "$0")/.."
PASSED=0 FAILED=0 SKIPPED=0
. tests/lib.sh
if [ $# -eq 0 ]; then set -- tests/t_*.sh; fi
for t in "$@"; do
    echo "== $t"
    . "$t"
done
echo "$SKIPPED skipped"
echo "$PASSED passed, $FAILED failed"
[ "$FAILED" -eq 0 ]
