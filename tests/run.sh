#!/usr/bin/env bash
# tests/run.sh [--all] [FILE...]: the test suites. Without --all the quick one (make test): every
# backend and feature at small sizes; with --all everything (make test-all). Runs every tests/t_*.sh
# (or only the files named), each in a process of its own with a scratch folder of its own
# (tests/tmp/NAME), one more at once than the machine has cores (TEST_JOBS=N sets it); prints each
# file's PASS/FAIL/SKIP lines in name order once it ends, with its seconds, then "N passed, N failed".
# Exits non-zero on any failure.
set -u
cd "$(dirname "$0")/.."
SUITE=quick
if [ "${1:-}" = --all ]; then
    SUITE=all
    shift
fi
export SUITE
# OpenMP threads sleep at a barrier rather than spin: the files run several at once, at up to 16 threads,
# on as few as 2 cores, where a spinning thread takes the core another file's work needs (the quick suite
# on 2 cores: 68 to 76 s against 81 to 88 s spinning). The programs' bytes do not depend on it.
export OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive}
if [ $# -eq 0 ]; then set -- tests/t_*.sh; fi
# one file more than the cores: the files spend part of their time starting processes and mpirun's jobs
# (the quick suite on 2 cores: 73 to 76 s at 3 files at once, 79 to 85 s at 2)
jobs=${TEST_JOBS:-$(($(nproc 2> /dev/null || echo 1) + 1))}
logs=tests/tmp/logs
rm -rf "$logs"
mkdir -p "$logs"

run_file() { # FILE: its lines into $logs/NAME.log, its totals (passed failed skipped) into $logs/NAME.n
    local name
    name=$(basename "$1" .sh)
    rm -rf "tests/tmp/$name"
    # TMP is the file's own (not exported: Open MPI would take it for its session folder)
    bash -c 'TMP=$3; start=$SECONDS; . tests/lib.sh; . "$1"; echo "$PASSED $FAILED $SKIPPED $((SECONDS - start))" > "$2"' \
        run "$1" "$logs/$name.n" "tests/tmp/$name" > "$logs/$name.log" 2>&1
}

# start the files that took longest last time first (tests/tmp/times; a file not timed yet counts
# as long), at most $jobs at a time, so that no long file starts last
times=tests/tmp/times
order=$(for t in "$@"; do
    echo "$(awk -v n="$(basename "$t" .sh)" '$1 == n { s = $2 } END { print (s == "" ? 999 : s) }' "$times" 2> /dev/null || echo 999) $t"
done | sort -s -k1,1nr | cut -d' ' -f2-)
running=0
for t in $order; do
    if [ "$running" -ge "$jobs" ]; then
        wait -n
        running=$((running - 1))
    fi
    run_file "$t" &
    running=$((running + 1))
done
wait

PASSED=0 FAILED=0 SKIPPED=0
for t in "$@"; do
    name=$(basename "$t" .sh)
    secs=""
    [ -f "$logs/$name.n" ] && read -r p f s secs < "$logs/$name.n"
    echo "== $t${secs:+ ($secs s)}"
    cat "$logs/$name.log"
    if [ -n "$secs" ]; then
        PASSED=$((PASSED + p)) FAILED=$((FAILED + f)) SKIPPED=$((SKIPPED + s))
    else
        FAILED=$((FAILED + 1))
        echo "FAIL $t: ended before its last check (see the lines above)"
    fi
done
# this run's seconds a file, beside the other files' last
{
    for t in "$@"; do
        name=$(basename "$t" .sh)
        [ -f "$logs/$name.n" ] && echo "$name $(awk '{ print $4 }' "$logs/$name.n")"
    done
    awk -v names=" $(for t in "$@"; do printf '%s ' "$(basename "$t" .sh)"; done)" \
        'index(names, " " $1 " ") == 0' "$times" 2> /dev/null
} > "$times.new"
mv "$times.new" "$times"
echo "$SKIPPED skipped ($SUITE suite)"
echo "$PASSED passed, $FAILED failed"
[ "$FAILED" -eq 0 ]
