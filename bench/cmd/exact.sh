#!/usr/bin/env bash
# ./bench.sh exact: --exact against the default step, seq and omp, on dense gases of N disks (speeds
# uniform in [0, 0.5 r] per step). Prints every command and one CSV row per run: the programs' own
# step-loop seconds (best of REPEATS after a discarded warm-up; seq once), ns per particle-step and
# events per particle-step. omp --exact must print the same bytes as seq --exact, or the script stops.
#   ./bench.sh exact
#   N=20000 FRACTIONS="0.4" STEPS=5 THREADS="1 2 4" ./bench.sh exact
set -euo pipefail
cd "$(dirname "$0")/../.."
die() { echo "bench_exact.sh: $*" >&2; exit 1; }
. bench/cmd/lib.sh

N=${N:-10000}
FRACTIONS=${FRACTIONS:-"0.2 0.4"}
STEPS=${STEPS:-10}
THREADS=${THREADS:-"1 2"}
REPEATS=${REPEATS:-3}
WORK=${WORK:-bench/tmp}

make -s seq omp tools/gen >/dev/null
mkdir -p "$WORK"
machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)"
echo "fraction,program,mode,threads,n,steps,best_s,ns_per_particle_step,events_per_particle_step"

run() { # FRACTION PROGRAM MODE THREADS INPUT: prints the command and a CSV row
    local f=$1 prog=$2 mode=$3 t=$4 in=$5 cmd times=() k reps=$REPEATS
    cmd=(./"$prog" "$in" --stats)
    [ "$mode" = exact ] && cmd+=(--exact)
    [ "$prog" = omp ] && cmd+=(--threads "$t")
    [ "$prog" = seq ] && reps=0
    echo "# ${cmd[*]}"
    for ((k = 0; k <= reps; k++)); do
        "${cmd[@]}" > "$WORK/last.out" 2> "$WORK/last.err"
        [ "$k" -eq 0 ] && [ "$reps" -gt 0 ] && continue
        times+=("$(loop_seconds "$WORK/last.err")")
    done
    local best events
    best=$(printf '%s\n' "${times[@]}" | sort -g | head -1)
    events=$(sed -n 's/.* \([0-9]*\) events$/\1/p' "$WORK/last.err")
    awk -v f="$f" -v p="$prog" -v m="$mode" -v t="$t" -v n="$N" -v s="$STEPS" -v b="$best" -v e="$events" \
        'BEGIN { ps = n * s; printf "%s,%s,%s,%s,%d,%d,%.4f,%.1f,%.3f\n", f, p, m, t, n, s, b, 1e9 * b / ps, e / ps }'
}

for f in $FRACTIONS; do
    in=$WORK/exact_$f.in
    tools/gen "$N" --fraction "$f" --speed 0.5 --steps "$STEPS" > "$in"
    for mode in default exact; do
        run "$f" seq "$mode" 1 "$in"
        cp "$WORK/last.out" "$WORK/ref.out"
        for t in $THREADS; do
            run "$f" omp "$mode" "$t" "$in"
            cmp -s "$WORK/last.out" "$WORK/ref.out" || { echo "# ERROR: omp $mode differs from seq" >&2; exit 1; }
        done
    done
done
