#!/usr/bin/env bash
# tools/bench_omp.sh: measures the omp backend on the scenes its targets name, printing every command
# it runs and one CSV row per measurement. Times are the programs' own step-loop seconds (stderr),
# best and median of REPEATS runs after one discarded warm-up.
#   tools/bench_omp.sh            all cases below
#   CASES="dense fixed" tools/bench_omp.sh
#   BIG=1 tools/bench_omp.sh      also N = 1e7 (generates a 600 MB input; minutes)
set -euo pipefail
cd "$(dirname "$0")/.."
die() { echo "bench_omp.sh: $*" >&2; exit 1; }
. tools/script_lib.sh

REPEATS=${REPEATS:-3}
THREADS=${THREADS:-"1 2"}
CASES=${CASES:-"dense fixed print assignment assignment1e5"}
WORK=${WORK:-bench/tmp}
BIG=${BIG:-0}

make -s seq omp tools/gen >/dev/null
mkdir -p "$WORK"
echo "# $(git rev-parse --short HEAD 2>/dev/null || echo unknown) $(uname -n) $(nproc) cores;" \
     "$(${CC:-cc} --version | head -1); OMP_PROC_BIND=${OMP_PROC_BIND:-unset} OMP_PLACES=${OMP_PLACES:-unset}"
echo "case,program,threads,n,steps,best_s,median_s,particle_steps_per_s,ns_per_particle_step,pair_tests,all_pairs_over_tests"

# pair tests: from a program's stderr (the step loop's seconds: loop_seconds)
pair_tests() { sed -n 's/.*: \([0-9]*\) pair tests.*/\1/p' "$1"; }

# measure CASE PROGRAM THREADS N STEPS INPUT [OPTIONS]: prints the command and a CSV row; leaves the
# output in $WORK/last.out
measure() {
    local name=$1 prog=$2 threads=$3 n=$4 steps=$5 input=$6
    shift 6
    local cmd=(./"$prog" "$input" --stats "$@")
    [ "$prog" = omp ] && cmd+=(--threads "$threads")
    echo "# ${cmd[*]}"
    local times=() k reps=$REPEATS
    [ "$prog" = seq ] && reps=1
    for ((k = 0; k <= reps; k++)); do
        "${cmd[@]}" > "$WORK/last.out" 2> "$WORK/last.err"
        [ "$k" -eq 0 ] && [ "$prog" = omp ] && continue
        times+=("$(loop_seconds "$WORK/last.err")")
    done
    local sorted best median tests
    sorted=$(printf '%s\n' "${times[@]}" | sort -g)
    best=$(echo "$sorted" | head -1)
    median=$(echo "$sorted" | sed -n "$(((${#times[@]} + 1) / 2))p")
    tests=$(pair_tests "$WORK/last.err")
    awk -v c="$name" -v p="$prog" -v t="$threads" -v n="$n" -v s="$steps" -v b="$best" -v m="$median" \
        -v pt="$tests" 'BEGIN {
            ps = n * s; all = n * (n - 1) / 2 * s
            printf "%s,%s,%s,%d,%d,%.4f,%.4f,%.4g,%.1f,%s,%.1f\n", c, p, t, n, s, b, m,
                   ps / b, 1e9 * b / ps, pt, (pt > 0 ? all / pt : 0) }'
    LAST_BEST=$best
}

same_output() { # REFERENCE: the last output must equal it
    cmp -s "$WORK/last.out" "$1" || { echo "# ERROR: output differs from $1" >&2; exit 1; }
}

ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a / b }'; }

for c in $CASES; do
    case $c in
    dense)
        in=$WORK/dense.in
        echo "# tools/gen 2000 --r 5 --fraction 0.05 --speed 4 --steps 200 > $in"
        tools/gen 2000 --r 5 --fraction 0.05 --speed 4 --steps 200 > "$in"
        measure dense seq 1 2000 200 "$in"
        cp "$WORK/last.out" "$WORK/dense.ref"
        seq_s=$LAST_BEST
        for t in $THREADS; do
            measure dense omp "$t" 2000 200 "$in"
            same_output "$WORK/dense.ref"
            echo "# dense: omp $t threads is $(ratio "$seq_s" "$LAST_BEST")x seq, same bytes"
        done
        ;;
    fixed)
        for n in 100000 400000; do
            in=$WORK/fixed$n.in
            echo "# tools/gen $n --fraction 0.2 --speed 0.5 --steps 20 > $in"
            tools/gen "$n" --fraction 0.2 --speed 0.5 --steps 20 > "$in"
            for t in $THREADS; do
                measure fixed omp "$t" "$n" 20 "$in"
                eval "fixed_${n}_$t=$LAST_BEST"
            done
        done
        for t in $THREADS; do
            eval "a=\$fixed_100000_$t b=\$fixed_400000_$t"
            echo "# fixed density, $t threads: 4x the disks costs $(ratio "$b" "$a")x the time"
        done
        ;;
    print)
        in=$WORK/print.in
        echo "# tools/gen 100000 --fraction 0.2 --speed 0.5 --steps 20 --mode print > $in"
        tools/gen 100000 --fraction 0.2 --speed 0.5 --steps 20 --mode print > "$in"
        for t in $THREADS; do
            measure print omp "$t" 100000 20 "$in"
            echo "# print: $(wc -c < "$WORK/last.out") bytes written to a file"
        done
        ;;
    assignment)
        in=$WORK/assignment.in
        printf '1000\n20000\n1\n1000\nperf\n' > "$in"
        echo "# printf '1000\\n20000\\n1\\n1000\\nperf\\n' > $in"
        measure assignment seq 1 1000 1000 "$in"
        cp "$WORK/last.out" "$WORK/assignment.ref"
        for t in $THREADS; do
            measure assignment omp "$t" 1000 1000 "$in"
            same_output "$WORK/assignment.ref"
        done
        ;;
    assignment1e5)
        in=$WORK/assignment1e5.in
        echo "# tools/gen 100000 --L 20000 --assignment --steps 3 > $in"
        tools/gen 100000 --L 20000 --assignment --steps 3 > "$in"
        for t in $THREADS; do measure assignment1e5 omp "$t" 100000 3 "$in"; done
        ;;
    *)
        echo "unknown case $c"
        exit 1
        ;;
    esac
done

if [ "$BIG" = 1 ]; then
    in=$WORK/big.in
    echo "# tools/gen 10000000 --fraction 0.2 --speed 0.5 --steps 3 > $in"
    tools/gen 10000000 --fraction 0.2 --speed 0.5 --steps 3 > "$in"
    for t in $THREADS; do
        echo "# /usr/bin/time -f '%M KiB max resident' ./omp $in --threads $t"
        /usr/bin/time -f "# %M KiB max resident" ./omp "$in" --threads "$t" --stats > /dev/null 2> "$WORK/last.err"
        grep -E 'step loop|resident' "$WORK/last.err" | sed 's/^/# /'
    done
    rm -f "$in"
fi
