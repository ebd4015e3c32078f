#!/usr/bin/env bash
# ./bench.sh phases: where omp's step loop goes, phase by phase (its --stats line), as medians over
# REPEATS runs of each input and thread count. With BASE_REV=REV (or BASE_DIR=DIR, an earlier tree's
# sources) that tree's omp too, each of its runs right after this tree's: on a machine whose speed
# drifts from minute to minute, a change of a few percent in one phase shows in medians of runs taken
# in turn, where a best of N of each build taken apart moves by more.
#   BASE_REV=REV ./bench.sh phases --threads "1 2" --repeats 9
#   INPUTS="a.in b.in" OPTIONS="--lanes 8" ./bench.sh phases
# INPUTS: the input files (default: the assignment's random scene at N = 1e3 and 1e4, written to WORK);
# OPTIONS: more options for every run. One CSV row per build, input and thread count, in seconds.
set -euo pipefail
cd "$(dirname "$0")/../.."
die() { echo "bench.sh phases: $*" >&2; exit 1; }
. bench/cmd/lib.sh

REPEATS=${REPEATS:-5}
THREADS=${THREADS:-"2"}
WORK=${WORK:-bench/tmp}
OPTIONS=${OPTIONS:-}
integer "$REPEATS" > /dev/null

make -s omp >/dev/null
mkdir -p "$WORK"
if [ -z "${INPUTS:-}" ]; then
    printf '1000\n20000\n1\n1000\nperf\n' > "$WORK/random_1000.in"
    printf '10000\n20000\n1\n100\nperf\n' > "$WORK/random_10000.in"
    INPUTS="$WORK/random_1000.in $WORK/random_10000.in"
fi
for f in $INPUTS; do [ -r "$f" ] || die "cannot read input $f"; done
machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)"
base_omp "$WORK"
echo "# REPEATS=$REPEATS OPTIONS=${OPTIONS:-none}; each value the median of REPEATS runs, seconds"

PHASES="plan binning pairs choice move waiting output_and_final_order"
echo "input,program,threads,$(echo "$PHASES" | tr ' ' ','),all"

# phases_of FILE: the seconds of the step loop's phases in FILE (omp's stderr), then their sum, one
# line, space-separated; empty where the run printed no phases
phases_of() {
    sed -n "s/^omp: the step loop's phases, mean of [0-9]* threads*: //p" "$1" | tr ',(' '\n\n' |
        awk 'match($0, /[0-9][0-9.e+-]* s/) { printf "%s%s", n++ ? " " : "", substr($0, RSTART, RLENGTH - 2) }
             END { if (n) print "" }'
}

# medians ROWS: per column, the median of the space-separated rows (one run a row), comma-separated
medians() {
    awk '{ for (k = 1; k <= NF; k++) v[k, NR] = $k; nf = NF }
         END { for (k = 1; k <= nf; k++) {
                   n = 0; for (r = 1; r <= NR; r++) a[++n] = v[k, r]
                   for (i = 2; i <= n; i++) for (j = i; j > 1 && a[j - 1] > a[j]; j--) { t = a[j]; a[j] = a[j - 1]; a[j - 1] = t }
                   printf "%s%.4f", (k > 1 ? "," : ""), (n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2) } print "" }' <<< "$1"
}

for input in $INPUTS; do
    for t in $(words "$THREADS"); do
        # shellcheck disable=SC2206
        args=("$input" --stats --threads "$t" $OPTIONS)
        echo "# ./omp ${args[*]}"
        mine="" base=""
        for ((k = 0; k <= REPEATS; k++)); do # run 0: a warm-up of each build, not counted
            ./omp "${args[@]}" > "$WORK/phases.out" 2> "$WORK/phases.err" || die "omp failed on $input"
            line=$(phases_of "$WORK/phases.err")
            [ -n "$line" ] || die "omp printed no phases on $input"
            [ "$k" -gt 0 ] && mine+="$line"$'\n'
            [ -n "$BASE_OMP" ] || continue
            "$BASE_OMP" "${args[@]}" > "$WORK/phases_base.out" 2> "$WORK/phases_base.err" ||
                die "the base's omp failed on $input"
            cmp -s "$WORK/phases.out" "$WORK/phases_base.out" || die "the base's omp ($BASE_NAME) printed other bytes"
            line=$(phases_of "$WORK/phases_base.err")
            [ -n "$line" ] || die "the base's omp printed no phases on $input"
            [ "$k" -gt 0 ] && base+="$line"$'\n'
        done
        echo "$input,omp,$t,$(medians "${mine%$'\n'}")"
        [ -z "$BASE_OMP" ] || echo "$input,omp_base,$t,$(medians "${base%$'\n'}")"
    done
done
