#!/usr/bin/env bash
# ./bench.sh exact: --exact, two parts (PART, or the first argument):
# - compare (default): --exact against the default step, seq and omp, on dense gases of N disks (speeds
#   uniform in [0, 0.5 r] per step). Prints every command and one CSV row per run: the programs' own
#   step-loop seconds (best of REPEATS after a discarded warm-up; seq once), ns per particle-step and
#   events per particle-step. omp --exact must print the same bytes as seq --exact, or the script stops.
# - threads: omp --exact's event loop on all cores: one gas (N = 1e5 disks at area fraction 0.5, speeds
#   uniform in [0, r] per step, 10 steps, placed with SEED 2: random placement jams near 0.547 and the
#   first seed fails at 0.5) in the periodic box (BOX=walled: between walls), omp --exact at each of
#   THREADS in turn, REPEATS rounds after a discarded warm-up round; with BASE_REV (or --base REV) that revision's omp too, at the same thread counts, in
#   the same rounds. One CSV row per run, then per program and thread count the best and median
#   step-loop seconds and the speedup over the first of THREADS (best over best, median over median),
#   and each program's last --stats lines (windows, events in strips, bands and sequential windows).
#   Every run must print the first run's bytes, or the script stops.
#   ./bench.sh exact
#   N=20000 FRACTIONS="0.4" STEPS=5 THREADS="1 2 4" ./bench.sh exact
#   THREADS="1 2" REPEATS=7 ./bench.sh exact threads
#   THREADS="1 16" ./bench.sh exact threads --base afddc93
set -euo pipefail
cd "$(dirname "$0")/../.."
die() { echo "bench_exact.sh: $*" >&2; exit 1; }
. bench/cmd/lib.sh

PART=${1:-${PART:-compare}}
THREADS=${THREADS:-"1 2"}
WORK=${WORK:-bench/tmp}

make -s seq omp tools/gen >/dev/null
mkdir -p "$WORK"
machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)"

if [ "$PART" = threads ]; then
    N=$(integer "${N:-1e5}")
    FRACTION=${FRACTION:-0.5}
    SPEED=${SPEED:-1}
    STEPS=${STEPS:-10}
    SEED=${SEED:-2}
    REPEATS=${REPEATS:-5}
    BOX=${BOX:-periodic}
    case $BOX in
        periodic) box=--periodic ;;
        walled) box="" ;;
        *) die "BOX must be periodic or walled (found '$BOX')" ;;
    esac
    in=$WORK/exact_threads_${N}_${FRACTION}_${SPEED}_${STEPS}_${SEED}_$BOX.in
    # shellcheck disable=SC2086
    [ -s "$in" ] || tools/gen "$N" --fraction "$FRACTION" --speed "$SPEED" --steps "$STEPS" --seed "$SEED" $box > "$in" ||
        die "tools/gen could not place the disks (another SEED?)"
    base_omp "$WORK"
    programs="omp${BASE_OMP:+ omp_base}"
    echo "# scene: tools/gen $N --fraction $FRACTION --speed $SPEED --steps $STEPS --seed $SEED $box; omp --exact $box" \
        "at THREADS=\"$THREADS\", $REPEATS rounds in turn after a warm-up round"
    echo "program,threads,n,steps,round,loop_s"
    rm -f "$WORK/threads.ref" "$WORK/threads.rows"
    for ((round = 0; round <= REPEATS; round++)); do
        for prog in $programs; do
            exe=./omp
            [ "$prog" = omp_base ] && exe=$BASE_OMP
            for t in $THREADS; do
                # shellcheck disable=SC2086
                "$exe" "$in" --exact $box --stats --threads "$t" > "$WORK/threads.out" 2> "$WORK/threads_${prog}.err"
                if [ ! -e "$WORK/threads.ref" ]; then
                    mv "$WORK/threads.out" "$WORK/threads.ref"
                elif ! cmp -s "$WORK/threads.out" "$WORK/threads.ref"; then
                    echo "# ERROR: $prog --threads $t differs from the first run" >&2
                    exit 1
                fi
                [ "$round" -eq 0 ] && continue
                echo "$prog,$t,$N,$STEPS,$round,$(loop_seconds "$WORK/threads_${prog}.err")" | tee -a "$WORK/threads.rows"
            done
        done
    done
    first=${THREADS%% *}
    echo "# summary: program,threads,best_s,median_s,speedup_best,speedup_median (over $first threads)"
    for prog in $programs; do
        sort -t, -k2,2n -k6,6g "$WORK/threads.rows" | awk -F, -v p="$prog" -v first="$first" '
            $1 == p { v[$2, ++c[$2]] = $6; if (!($2 in seen)) { seen[$2] = 1; order[++k] = $2 } }
            END {
                for (i = 1; i <= k; i++) {
                    t = order[i]; m = c[t]
                    best[t] = v[t, 1]; med[t] = m % 2 ? v[t, (m + 1) / 2] : (v[t, m / 2] + v[t, m / 2 + 1]) / 2
                }
                for (i = 1; i <= k; i++) {
                    t = order[i]
                    printf "# %s,%s,%.4f,%.4f,%.2f,%.2f\n", p, t, best[t], med[t], best[first] / best[t], med[first] / med[t]
                }
            }'
        sed -n 's/^[a-z_0-9]*: --exact: /# '"$prog"' --threads '"${THREADS##* }"', last run: /p' "$WORK/threads_${prog}.err"
    done
    exit 0
fi
[ "$PART" = compare ] || die "unknown part '$PART' (compare or threads)"

N=${N:-10000}
FRACTIONS=${FRACTIONS:-"0.2 0.4"}
STEPS=${STEPS:-10}
REPEATS=${REPEATS:-3}
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
