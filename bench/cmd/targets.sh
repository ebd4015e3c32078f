#!/usr/bin/env bash
# ./bench.sh targets: measures omp on the scenes its targets name, printing every command it runs, one
# CSV row per measurement, and at the end one line per target with the measured ratio or rate. Each
# measurement is REPEATS runs after one discarded warm-up (seq: one run); rows give the best and the
# median of the whole process (wall clock around the command: input, placement, steps, output) and of
# the step loop (the program's own seconds on stderr).
#   ./bench.sh targets                     all cases below
#   CASES="random1e3 mixed" ./bench.sh targets
#   BIG=1 ./bench.sh targets               also a gas of N = 1e7 (generates a 600 MB input; minutes)
#   BASE_REV=REV ./bench.sh targets        also revision REV's omp (built from git beside this tree), each
#                                          of its runs right after this tree's on the same input (rows
#                                          program omp_base): the two builds meet the same load of the
#                                          machine, which on a shared host drifts by a third in minutes
#   BASE_DIR=DIR ./bench.sh targets        the same with DIR, a folder holding an earlier tree's sources
#                                          (where there is no git)
set -euo pipefail
cd "$(dirname "$0")/../.."
die() { echo "bench_omp.sh: $*" >&2; exit 1; }
. bench/cmd/lib.sh

REPEATS=${REPEATS:-3}
THREADS=${THREADS:-"1 2"}
CASES=${CASES:-"random1e3 random1e4 random1e5 mixed dense fixed print"}
WORK=${WORK:-bench/tmp}
BIG=${BIG:-0}
BASE_REV=${BASE_REV:-}
BASE_DIR=${BASE_DIR:-}

make -s seq omp tools/gen >/dev/null
mkdir -p "$WORK"
machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)"
base_omp "$WORK"
echo "# OMP_PROC_BIND=${OMP_PROC_BIND:-unset} OMP_PLACES=${OMP_PLACES:-unset} REPEATS=$REPEATS"
echo "case,program,threads,n,steps,best_wall_s,median_wall_s,best_loop_s,median_loop_s,wall_particle_steps_per_s,loop_particle_steps_per_s,pair_tests"

pair_tests() { sed -n 's/.*: \([0-9]*\) pair tests.*/\1/p' "$1"; }
# The wall clock around a run: bash's EPOCHREALTIME (seconds with six decimals) without its point,
# in microseconds; no process is started for it (date's start would be timed too, a few ms here).
[ -n "${EPOCHREALTIME:-}" ] || die "bash 5 or later is needed (EPOCHREALTIME)"
best_of() { printf '%s\n' "$@" | sort -g | head -1; }
median_of() { printf '%s\n' "$@" | sort -g | sed -n "$((($# + 1) / 2))p"; }

# row CASE LABEL THREADS N STEPS WALLS LOOPS: the CSV row of one build's runs (WALLS and LOOPS: their
# seconds, space-separated)
row() {
    local w l
    read -r -a w <<< "$6"
    read -r -a l <<< "$7"
    awk -v c="$1" -v p="$2" -v t="$3" -v n="$4" -v s="$5" -v bw="$(best_of "${w[@]}")" \
        -v mw="$(median_of "${w[@]}")" -v bl="$(best_of "${l[@]}")" -v ml="$(median_of "${l[@]}")" \
        -v pt="$(pair_tests "$WORK/last.err")" 'BEGIN {
            ps = n * s
            printf "%s,%s,%s,%d,%d,%.4f,%.4f,%.4f,%.4f,%.4g,%.4g,%s\n", c, p, t, n, s, bw, mw, bl, ml,
                   ps / bw, ps / bl, pt }'
}

# timed PROGRAM OUT ARGS...: runs it, stdout into OUT.out and stderr into OUT.err; WALL: its seconds
timed() {
    local prog=$1 out=$2 s e
    shift 2
    s=${EPOCHREALTIME/[.,]/}
    "$prog" "$@" > "$out.out" 2> "$out.err"
    e=${EPOCHREALTIME/[.,]/}
    WALL=$(awk -v a="$s" -v b="$e" 'BEGIN { printf "%.4f", (b - a) / 1e6 }')
}

# measure CASE PROGRAM THREADS N STEPS INPUT [OPTIONS]: prints the command and a CSV row (and, where
# PROGRAM is omp and a base is given (BASE_REV or BASE_DIR), one for its omp, each of its runs right after this tree's);
# leaves this tree's output in $WORK/last.out and its best times in BEST_WALL and BEST_LOOP
measure() {
    local name=$1 prog=$2 threads=$3 n=$4 steps=$5 input=$6
    shift 6
    local args=("$input" --stats "$@")
    [ "${prog%_f32}" = omp ] && args+=(--threads "$threads")
    echo "# ./$prog ${args[*]}"
    local base=0 k reps=$REPEATS walls="" loops="" bwalls="" bloops=""
    [ -n "$BASE_OMP" ] && [ "$prog" = omp ] && base=1
    [ "$prog" = seq ] && reps=1
    for ((k = 0; k <= reps; k++)); do
        [ "$k" -eq 0 ] && [ "$prog" = seq ] && continue
        timed "./$prog" "$WORK/last" "${args[@]}"
        if [ "$k" -gt 0 ]; then
            walls+=" $WALL"
            loops+=" $(loop_seconds "$WORK/last.err")"
        fi
        [ "$base" = 1 ] || continue
        timed "$BASE_OMP" "$WORK/base" "${args[@]}"
        if [ "$k" -gt 0 ]; then
            bwalls+=" $WALL"
            bloops+=" $(loop_seconds "$WORK/base.err")"
        fi
    done
    local w l
    read -r -a w <<< "$walls"
    read -r -a l <<< "$loops"
    BEST_WALL=$(best_of "${w[@]}")
    BEST_LOOP=$(best_of "${l[@]}")
    row "$name" "$prog" "$threads" "$n" "$steps" "$walls" "$loops"
    sed -n "s/^omp: the step loop's phases, /# the last run's phases, /p" "$WORK/last.err"
    if [ "$base" = 1 ]; then
        row "$name" omp_base "$threads" "$n" "$steps" "$bwalls" "$bloops"
        sed -n "s/^omp: the step loop's phases, /# the base's last run's phases, /p" "$WORK/base.err"
        cmp -s "$WORK/last.out" "$WORK/base.out" || die "the base's omp ($BASE_NAME) printed other bytes"
    fi
}

same_output() { # REFERENCE: the last output must equal it
    cmp -s "$WORK/last.out" "$1" || { echo "# ERROR: output differs from $1" >&2; exit 1; }
}

ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a / b }'; }
rate() { awk -v n="$1" -v s="$2" -v t="$3" 'BEGIN { printf "%.3g", n * s / t }'; }
TARGETS=()
target() { TARGETS+=("# target: $*"); }

# random N STEPS WITH_SEQ NAME: the assignment's random scene (no particle lines) in its sample's box
# (L = 20000, r = 1): the disks cross up to a quarter of it per step, and it gets denser with N
random() {
    local n=$1 steps=$2 with_seq=$3 name=random$4 in=$WORK/random_$1.in
    printf '%s\n20000\n1\n%s\nperf\n' "$n" "$steps" > "$in"
    echo "# printf '$n\\n20000\\n1\\n$steps\\nperf\\n' > $in"
    if [ "$with_seq" = 1 ]; then
        measure "$name" seq 1 "$n" "$steps" "$in"
        cp "$WORK/last.out" "$WORK/$name.ref"
        SEQ_WALL=$BEST_WALL
    fi
    for t in $THREADS; do
        measure "$name" omp "$t" "$n" "$steps" "$in"
        [ "$with_seq" = 1 ] && same_output "$WORK/$name.ref"
        eval "${name}_$t=\$BEST_WALL ${name}_loop_$t=\$BEST_LOOP"
        # the paths' screens one width narrower than the default: 8 pairs at a time (AVX2) where the
        # default is 16 (AVX-512F), else 4 (SSE2) beside 8
        measure "${name}_lanes$NARROW" omp "$t" "$n" "$steps" "$in" --lanes "$NARROW"
    done
}

printf '2\n10\n1\n1\nperf\n' > "$WORK/lanes.in"
if ./omp "$WORK/lanes.in" --quiet --lanes 16 > /dev/null 2>&1; then NARROW=8; else NARROW=4; fi

for c in $CASES; do
    case $c in
    random1e3)
        random 1000 1000 1 1e3
        for t in $THREADS; do
            eval "w=\$random1e3_$t"
            target "random N=1e3 (1000 20000 1 1000 perf), omp $t threads: $(ratio "$SEQ_WALL" "$w")x seq," \
                "whole process ($SEQ_WALL s against $w s), same bytes (goal >= 40x on 2 threads)"
        done
        ;;
    random1e4)
        random 10000 100 0 1e4
        for t in $THREADS; do
            eval "w=\$random1e4_$t l=\$random1e4_loop_$t"
            target "random N=1e4 (10000 20000 1 100 perf), omp $t threads: $(rate 10000 100 "$w")" \
                "particle-steps/s whole process, $(rate 10000 100 "$l") step loop (goal >= 5e6 on 2 threads)"
        done
        ;;
    random1e5)
        random 100000 20 0 1e5
        for t in $THREADS; do
            eval "w=\$random1e5_$t l=\$random1e5_loop_$t"
            target "random N=1e5 (100000 20000 1 20 perf), omp $t threads: $(rate 100000 20 "$w")" \
                "particle-steps/s whole process, $(rate 100000 20 "$l") step loop (goal >= 1e6 on 2 threads)"
        done
        ;;
    mixed)
        # a gas with 1% of its disks a quarter of the box per step, and the same gas at its own speeds
        # (--fast 0 draws the same numbers); the fast disks heat the gas, so the run is short
        for f in 0.01 0; do
            in=$WORK/mixed_$f.in
            echo "# tools/gen 100000 --fraction 0.2 --speed 0.5 --fast $f --steps 5 > $in"
            tools/gen 100000 --fraction 0.2 --speed 0.5 --fast "$f" --steps 5 > "$in"
        done
        for t in $THREADS; do
            measure mixed_base omp "$t" 100000 5 "$WORK/mixed_0.in"
            base=$BEST_WALL base_loop=$BEST_LOOP
            measure mixed omp "$t" 100000 5 "$WORK/mixed_0.01.in"
            target "mixed gas (1e5 disks, 1% at L/4 per step, 5 steps), omp $t threads:" \
                "$(ratio "$BEST_WALL" "$base")x the same gas without fast disks, whole process" \
                "($BEST_WALL s against $base s; step loop $(ratio "$BEST_LOOP" "$base_loop")x) (goal <= 2x)"
            # what the cost model's choice (mixed, on these steps) saves over the paths of every disk
            measure mixed_paths omp "$t" 100000 5 "$WORK/mixed_0.01.in" --broad paths
            # what keeping a fast disk's first 8 events with slow disks saves over keeping them all
            measure mixed_keep_all omp "$t" 100000 5 "$WORK/mixed_0.01.in" --keep 0
        done
        # how the fast disks heat the gas: disks faster than 10 r per step (20x the gas's fastest)
        sed 's/^perf$/print/' "$WORK/mixed_0.01.in" > "$WORK/mixed_print.in"
        echo "# disks faster than 10 r per step after steps 0 to 5: $(./omp "$WORK/mixed_print.in" --quiet |
            awk '$5 * $5 + $6 * $6 > 100 { c[$1]++ } END { for (s = 0; s <= 5; s++) printf " %d", c[s] }')"
        ;;
    dense)
        in=$WORK/dense.in
        echo "# tools/gen 2000 --r 5 --fraction 0.05 --speed 4 --steps 200 > $in"
        tools/gen 2000 --r 5 --fraction 0.05 --speed 4 --steps 200 > "$in"
        measure dense seq 1 2000 200 "$in"
        cp "$WORK/last.out" "$WORK/dense.ref"
        seq_s=$BEST_WALL
        for t in $THREADS; do
            measure dense omp "$t" 2000 200 "$in"
            same_output "$WORK/dense.ref"
            target "dense gas (2000 disks, r = 5, fraction 0.05, speeds up to 4r), omp $t threads:" \
                "$(ratio "$seq_s" "$BEST_WALL")x seq, whole process, same bytes (goal >= 80x on 2 threads)"
        done
        ;;
    fixed)
        for n in 100000 400000; do
            in=$WORK/fixed$n.in
            echo "# tools/gen $n --fraction 0.2 --speed 0.5 --steps 20 > $in"
            tools/gen "$n" --fraction 0.2 --speed 0.5 --steps 20 > "$in"
            for t in $THREADS; do
                measure fixed omp "$t" "$n" 20 "$in"
                eval "fixed_${n}_$t=$BEST_LOOP"
            done
        done
        for t in $THREADS; do
            eval "a=\$fixed_100000_$t b=\$fixed_400000_$t"
            target "gas (fraction 0.2, speeds up to r/2), omp $t threads: 4e5 disks $(rate 400000 20 "$b")" \
                "particle-steps/s of step loop (goal >= 2e7 on 2 threads); 4x the disks costs" \
                "$(ratio "$b" "$a")x the time"
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
    *)
        die "unknown case $c"
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
for line in "${TARGETS[@]}"; do echo "$line"; done
