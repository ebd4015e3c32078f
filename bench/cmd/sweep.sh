#!/usr/bin/env bash
# bench.sh: measures the backends over thread counts, input sizes and scenes; writes one CSV row per
# timed run and a summary CSV (min and median per point), both headed by '#' provenance lines.
# bench/README.md explains the scenes, the columns and how to reproduce the committed results.
set -euo pipefail
export LC_ALL=C
cd "$(dirname "$0")/../.."

# ---- knobs (environment variables of the same name override them; options override both) ----------
BACKENDS=${BACKENDS:-"seq omp cuda"}                  # those without a runnable binary are skipped
SCENES=${SCENES:-"random gas05 gas20 gas40 dilute"}   # see scene_make below
SIZES_CPU=${SIZES_CPU:-"1000 3000 10000 30000 100000 300000 1000000"}
SIZES_GPU=${SIZES_GPU:-"$SIZES_CPU 3000000 10000000 30000000 100000000"}
FILE_MAX_N=${FILE_MAX_N:-100000000} # scenes with particle lines take ~60 bytes per disk on disk
THREADS=${THREADS:-""}              # omp thread counts; empty: 1, 2, 4, ... and the core count
REPEATS=${REPEATS:-3}               # timed runs per point, after one discarded warm-up run
TARGET_S=${TARGET_S:-1.0}           # aimed step-loop time of one run; steps are chosen per point
CALIBRATE_S=${CALIBRATE_S:-}       # probe runs grow their steps until the loop takes this long
                                    # (default TARGET_S / 5)
MAX_STEP_S=${MAX_STEP_S:-3.0}       # skip a point (and larger N) whose single step would take longer
MAX_STEPS=${MAX_STEPS:-1000000}
STEPS_FIXED=${STEPS_FIXED:-}        # steps of every run; empty: chosen per point by probe runs
RUN_TIMEOUT=${RUN_TIMEOUT:-300}     # seconds before one run counts as hung
SEED=${SEED:-1}
RANDOM_L0=${RANDOM_L0:-20000}       # random scene: box side at RANDOM_N0 disks of radius 1 ...
RANDOM_N0=${RANDOM_N0:-1000}        # ... and L grows as sqrt(N) above RANDOM_N0 (constant area fraction)
OUTPUT=${OUTPUT:-bench/results.csv}
TMP_DIR=${TMP_DIR:-bench/tmp}
export OMP_PROC_BIND=${OMP_PROC_BIND:-close}
export OMP_PLACES=${OMP_PLACES:-cores}

usage() {
    cat <<EOF
usage: ./bench.sh [options]
Times seq, omp and cuda (where built and a GPU answers) on seeded scenes and writes
  OUTPUT            one row per timed run (default $OUTPUT)
  OUTPUT minus .csv plus .summary.csv: min and median per point
Each point (backend, threads, scene, N) gets probe runs that choose its steps so that a run's step loop
takes about TARGET_S, one discarded warm-up run, then REPEATS timed runs.

options (lists are space- or comma-separated; sizes accept 1e5 notation):
  --quick            CI-sized sweep, under a minute on 2 cores: N = 1000 and 3000, threads 1 and all,
                     3 timed runs of about 0.05 s, output bench/tmp/quick.csv unless -o is given
  --backends LIST    from: seq omp cuda (default: $BACKENDS)
  --scenes LIST      from: random gas05 gas20 gas40 dilute (default: all)
  --sizes LIST       N values for every backend (default: $SIZES_CPU on CPU, up to 1e8 for cuda)
  --threads LIST     omp thread counts (default: 1 2 4 ... and the number of cores)
  --repeats K        timed runs per point (default $REPEATS)
  --target S         step-loop seconds aimed at per run (default $TARGET_S)
  --max-step S       skip points whose single step would take longer (default $MAX_STEP_S)
  --summarize FILE   only write FILE's summary again from its rows (a sweep stopped before its end)
  --prepare          only generate the scene files of the sweep (cached under $TMP_DIR), run nothing
  --steps S          S steps in every run, no probe runs (the warm-up run is the probe): for large N,
                     where each run spends seconds reading the input and writing the final state
  -o, --output FILE  runs CSV (default $OUTPUT)
  --help             this text
Scenes: random = the assignment's generated input (r = 1, L = $RANDOM_L0 up to N = $RANDOM_N0, then
L = $RANDOM_L0 * sqrt(N / $RANDOM_N0)); gasFF = tools/gen N --fraction 0.FF --speed 0.5 (fine steps);
dilute = tools/gen N --fraction 0.001 --speed 0.5 (almost no collisions).
Knobs at the top of this file can also be set as environment variables (e.g. OMP_PROC_BIND).
EOF
}

die() { echo "bench.sh: $*" >&2; exit 1; }
[ -n "${EPOCHREALTIME:-}" ] || die "needs bash 5 or later (EPOCHREALTIME)"
. bench/cmd/lib.sh

# ---- summary: min and median of the timed runs of each point (its rows are consecutive) ------------
summarize() { # RUNS_CSV [EXTRA_HEADER_LINE]: writes RUNS_CSV minus .csv plus .summary.csv
    local runs=$1
    {
    grep '^#' "$runs"
    [ -z "${2:-}" ] || echo "$2"
    echo "backend,threads,scene,n,steps,runs,min_seconds,median_seconds,min_ns_per_particle_step,median_ns_per_particle_step,min_wall_seconds,median_wall_seconds,pair_tests_per_particle_step,events_per_particle_step,L,r,area_fraction"
    grep -v -e '^#' -e '^backend,' "$runs" | awk -F, -v OFS=, '
        function median(a, k,   h) { h = int((k + 1) / 2); return k % 2 ? a[h] : (a[h] + a[h + 1]) / 2 }
        function sorted(a, k,   i, j, v) {
            for (i = 2; i <= k; i++) { v = a[i]; for (j = i - 1; j >= 1 && a[j] > v; j--) a[j + 1] = a[j]; a[j + 1] = v }
        }
        function flush(   ps) {
            if (!k) return
            sorted(sec, k); sorted(wall, k)
            ps = n * s
            printf "%s,%d,%d,%.6f,%.6f,%.6g,%.6g,%.6f,%.6f,%s,%s,%s\n", key, s, k, sec[1], median(sec, k),
                   sec[1] * 1e9 / ps, median(sec, k) * 1e9 / ps, wall[1], median(wall, k), tests, ev, geo
            k = 0
        }
        {
            id = $1 "," $2 "," $3 "," $4
            if (id != key) { flush(); key = id }
            n = $4; s = $5; k++; sec[k] = $7 + 0; wall[k] = $8 + 0; tests = $10; ev = $11
            geo = $14 "," $15 "," $16
        }
        END { flush() }'
    } > "${runs%.csv}.summary.csv"
}

# ---- options --------------------------------------------------------------------------------------
QUICK=0 PREPARE=0 SIZES="" OUTPUT_GIVEN=0 GIVEN=""
COMMAND_LINE="./bench.sh $*"
while [ $# -gt 0 ]; do
    case $1 in
        --help | -h) usage; exit 0 ;;
        --quick) QUICK=1 ;;
        --prepare) PREPARE=1 ;;
        --summarize) summarize "${2?--summarize needs a runs CSV}" "# summary written afterwards by ./bench.sh --summarize"; echo "bench.sh: ${2%.csv}.summary.csv" >&2; exit 0 ;;
        --backends) BACKENDS=$(words "${2?--backends needs a list}"); shift ;;
        --scenes) SCENES=$(words "${2?--scenes needs a list}"); shift ;;
        --sizes) SIZES=$(words "${2?--sizes needs a list}"); shift ;;
        --threads) THREADS=$(words "${2?--threads needs a list}"); shift ;;
        --repeats) REPEATS=$(integer "${2?--repeats needs a number}"); GIVEN="$GIVEN repeats"; shift ;;
        --target) TARGET_S=${2?--target needs seconds}; GIVEN="$GIVEN target"; shift ;;
        --max-step) MAX_STEP_S=${2?--max-step needs seconds}; GIVEN="$GIVEN max-step"; shift ;;
        --steps) STEPS_FIXED=$(integer "${2?--steps needs a number}"); shift ;;
        -o | --output) OUTPUT=${2?--output needs a file}; OUTPUT_GIVEN=1; shift ;;
        *) die "unknown option '$1' (see --help)" ;;
    esac
    shift
done

CORES=$(nproc)
if [ "$QUICK" = 1 ]; then
    SIZES=${SIZES:-"1000 3000"}
    THREADS=${THREADS:-"1 $CORES"}
    [[ $GIVEN == *repeats* ]] || REPEATS=3
    [[ $GIVEN == *target* ]] || TARGET_S=0.05
    [[ $GIVEN == *max-step* ]] || MAX_STEP_S=0.5
    [ "$OUTPUT_GIVEN" = 1 ] || OUTPUT=$TMP_DIR/quick.csv
fi
if [ -z "$THREADS" ]; then
    for ((t = 1; t < CORES; t *= 2)); do THREADS="$THREADS $t"; done
    THREADS="$THREADS $CORES"
fi
[ "$REPEATS" -ge 1 ] || die "--repeats must be at least 1"
seconds_ok() { [[ $1 =~ ^[0-9]*\.?[0-9]+([eE][-+]?[0-9]+)?$ ]] && awk -v s="$1" 'BEGIN { exit !(s > 0) }'; }
seconds_ok "$TARGET_S" || die "--target must be positive seconds (found '$TARGET_S')"
seconds_ok "$MAX_STEP_S" || die "--max-step must be positive seconds (found '$MAX_STEP_S')"
CALIBRATE_S=${CALIBRATE_S:-$(awk -v t="$TARGET_S" 'BEGIN { print t / 5 }')}
integers() { local n out=""; for n in "$@"; do out="$out $(integer "$n")" || exit 1; done; echo $out; }
SIZES=$(integers $SIZES)
SIZES_CPU=$(integers $SIZES_CPU)
SIZES_GPU=$(integers $SIZES_GPU)
THREADS=$(integers $THREADS)
SUMMARY=${OUTPUT%.csv}.summary.csv

# ---- what can run here ----------------------------------------------------------------------------
have_gpu() { [ -x ./cuda ] && command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; }
RUNNABLE=""
for b in $BACKENDS; do
    case $b in
        seq | omp) [ -x "./$b" ] || die "./$b not built (run make)" ;;
        cuda) have_gpu || { echo "bench.sh: cuda skipped (no ./cuda or no GPU)" >&2; continue; } ;;
        *) die "unknown backend '$b'" ;;
    esac
    RUNNABLE="${RUNNABLE:+$RUNNABLE }$b"
done
[ -n "$RUNNABLE" ] || die "no backend to run"
[ -x tools/gen ] || die "tools/gen not built (run make)"
make -q all >/dev/null 2>&1 || echo "bench.sh: warning: binaries older than their sources (run make)" >&2
mkdir -p "$TMP_DIR" "$(dirname "$OUTPUT")"

# ---- scenes: each writes an input file for N disks; add new ones here ------------------------------
# scene_make NAME N FILE: the input for N disks. Its steps line has STEPS_WIDTH digits, so that runs
# can rewrite it in place (with_steps) instead of copying gigabytes per run at N = 1e8.
STEPS_WIDTH=10
STEPS_PLACEHOLDER=1000000000
scene_make() {
    local name=$1 n=$2 file=$3 s=$STEPS_PLACEHOLDER
    case $name in
        random)
            awk -v n="$n" -v l0="$RANDOM_L0" -v n0="$RANDOM_N0" -v s="$s" \
                'BEGIN { L = n > n0 ? l0 * sqrt(n / n0) : l0; printf "%d\n%.10g\n1\n%s\nperf\n", n, L, s }' \
                > "$file" ;;
        gas05) tools/gen "$n" --fraction 0.05 --speed 0.5 --steps $s --seed "$SEED" > "$file" ;;
        gas20) tools/gen "$n" --fraction 0.2 --speed 0.5 --steps $s --seed "$SEED" > "$file" ;;
        gas40) tools/gen "$n" --fraction 0.4 --speed 0.5 --steps $s --seed "$SEED" > "$file" ;;
        dilute) tools/gen "$n" --fraction 0.001 --speed 0.5 --steps $s --seed "$SEED" > "$file" ;;
        *) die "unknown scene '$name'" ;;
    esac
}
scene_lists_disks() { [ "$1" != random ]; }

# The cached input of a scene; generated once and reused across backends and invocations.
scene_file() {
    local name=$1 n=$2 file="$TMP_DIR/$1-n$2-seed$SEED.in"
    if [ ! -s "$file" ] || [ tools/gen -nt "$file" ] || [ "$0" -nt "$file" ]; then
        scene_make "$name" "$n" "$file.$$.part" || die "cannot generate scene $name with N = $n"
        mv "$file.$$.part" "$file"
    fi
    echo "$file"
}

# ---- running one program --------------------------------------------------------------------------
# per invocation, so that a sweep and the test suite can share bench/tmp
RUN_IN=$TMP_DIR/run.$$.in
RUN_ERR=$TMP_DIR/run.$$.err
trap 'rm -f "$RUN_IN" "$RUN_ERR"' EXIT
# with_steps BASE S: the base input with its steps line replaced, as $RUN_IN: copied once per base,
# then only the steps line (line 4, STEPS_WIDTH digits, leading zeros allowed) is overwritten.
RUN_BASE=""
with_steps() {
    if [ "$RUN_BASE" != "$1" ]; then
        cp "$1" "$RUN_IN"
        RUN_BASE=$1
        RUN_OFFSET=$(head -n 3 "$1" | wc -c)
        [ "$(sed -n 4p "$1" | tr -d '\n' | wc -c)" -eq "$STEPS_WIDTH" ] || die "$1: line 4 is not $STEPS_WIDTH digits"
    fi
    printf "%0${STEPS_WIDTH}d" "$2" | dd of="$RUN_IN" bs=1 seek="$RUN_OFFSET" conv=notrunc status=none
}

# run_once BACKEND THREADS: runs $RUN_IN; sets SECONDS_LOOP, WALL, PAIR_TESTS, EVENTS.
run_once() {
    local b=$1 t=$2 args=("$RUN_IN" --stats --seed "$SEED") env=() t0 t1
    if [ "$b" = omp ]; then
        args+=(--threads "$t")
        env=("OMP_NUM_THREADS=$t")
    fi
    t0=$EPOCHREALTIME
    if ! env "${env[@]}" timeout "$RUN_TIMEOUT" "./$b" "${args[@]}" > /dev/null 2> "$RUN_ERR"; then
        cat "$RUN_ERR" >&2
        die "./$b ${args[*]} failed"
    fi
    t1=$EPOCHREALTIME
    WALL=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.6f", b - a }')
    SECONDS_LOOP=$(loop_seconds "$RUN_ERR")
    PAIR_TESTS=$(sed -n 's/^[a-z]*: \([0-9]*\) pair tests.*/\1/p' "$RUN_ERR" | tail -n 1)
    EVENTS=$(sed -n 's/.* \([0-9]*\) events$/\1/p' "$RUN_ERR" | tail -n 1)
    [ -n "$SECONDS_LOOP" ] && [ -n "$PAIR_TESTS" ] && [ -n "$EVENTS" ] ||
        die "./$b: no timing or stats line on stderr: $(tail -n 2 "$RUN_ERR")"
}

# calibrate BACKEND THREADS BASE: probe runs with growing steps; sets STEPS for about TARGET_S, and
# PER_STEP (seconds of one step).
calibrate() {
    local b=$1 t=$2 base=$3 s=1
    while :; do
        with_steps "$base" "$s"
        run_once "$b" "$t"
        if awk -v x="$SECONDS_LOOP" -v c="$CALIBRATE_S" -v s="$s" -v m="$MAX_STEPS" \
            'BEGIN { exit !(x >= c || s >= m) }'; then
            break
        fi
        s=$(awk -v x="$SECONDS_LOOP" -v c="$CALIBRATE_S" -v s="$s" -v m="$MAX_STEPS" 'BEGIN {
            g = x > 0 ? 2 * c / x : 100; if (g < 2) g = 2; if (g > 100) g = 100
            s = int(s * g); print s < m ? s : m }')
    done
    PER_STEP=$(awk -v x="$SECONDS_LOOP" -v s="$s" 'BEGIN { printf "%.9g", (x > 1e-6 ? x : 1e-6) / s }')
    STEPS=$(awk -v p="$PER_STEP" -v g="$TARGET_S" -v m="$MAX_STEPS" 'BEGIN {
        s = int(g / p + 0.5); if (s < 1) s = 1; if (s > m) s = m; print s }')
}

# warm_up BACKEND THREADS BASE: the discarded run, with STEPS; a probe can be slowed by thread start-up,
# so while the warm-up finishes in under a third of TARGET_S the steps are scaled up and it is run again.
warm_up() {
    local b=$1 t=$2 base=$3 k
    for ((k = 0; k < 3; k++)); do
        with_steps "$base" "$STEPS"
        run_once "$b" "$t"
        awk -v x="$SECONDS_LOOP" -v g="$TARGET_S" -v s="$STEPS" -v m="$MAX_STEPS" \
            'BEGIN { exit !(x < g / 3 && s < m) }' || return 0
        STEPS=$(awk -v x="$SECONDS_LOOP" -v g="$TARGET_S" -v s="$STEPS" -v m="$MAX_STEPS" 'BEGIN {
            s = int(s * g / (x > 1e-6 ? x : 1e-6) + 0.5); print s < m ? s : m }')
    done
    with_steps "$base" "$STEPS"
}

# ---- provenance -----------------------------------------------------------------------------------
provenance() {
    local nvcc gpu
    nvcc=$(make_var NVCC)
    echo "# bench.sh results (bench/README.md explains the columns)"
    echo "# command: $COMMAND_LINE"
    machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null)" "$CORES"
    if command -v "$nvcc" >/dev/null 2>&1; then
        echo "# nvcc: $("$nvcc" --version | grep -i release | head -n 1)"
        echo "# NVCCFLAGS: $(make_var NVCCFLAGS)"
    else
        echo "# nvcc: none"
    fi
    if have_gpu; then
        gpu=$(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | head -n 1)
        echo "# gpu: ${gpu%%,*}; driver:${gpu#*,}"
    else
        echo "# gpu: none"
    fi
    echo "# OMP_PROC_BIND=$OMP_PROC_BIND OMP_PLACES=$OMP_PLACES; omp threads: $THREADS"
    echo "# backends: $RUNNABLE; scenes: $SCENES; seed: $SEED; repeats: $REPEATS after 1 warm-up;" \
        "target: $TARGET_S s per run; max step: $MAX_STEP_S s${STEPS_FIXED:+; steps: $STEPS_FIXED per run}"
    echo "# random scene: r = 1, L = $RANDOM_L0 * sqrt(max(N, $RANDOM_N0) / $RANDOM_N0)"
}

RUN_COLUMNS="backend,threads,scene,n,steps,run,seconds,wall_seconds,ns_per_particle_step"
RUN_COLUMNS+=",pair_tests_per_particle_step,events_per_particle_step,pair_tests,events,L,r,area_fraction"
HEADER=$(provenance)
{ echo "$HEADER"; echo "$RUN_COLUMNS"; } > "$OUTPUT"

# ---- the sweep ------------------------------------------------------------------------------------
declare -A SIZES_OF LAST_N LAST_STEP PREV_N PREV_STEP SKIPPED
for b in $RUNNABLE; do
    list=$SIZES
    [ -n "$list" ] || { [ "$b" = cuda ] && list=$SIZES_GPU || list=$SIZES_CPU; }
    SIZES_OF[$b]=" $list "
done
ALL_SIZES=$(for b in $RUNNABLE; do echo "${SIZES_OF[$b]}"; done | tr -s ' ' '\n' | sort -n -u)
# thread counts of a backend: omp's list; seq runs 1; cuda has none and is written as 0
threads_of() {
    case $1 in
        omp) echo "$THREADS" ;;
        cuda) echo 0 ;;
        *) echo 1 ;;
    esac
}

# forecast KEY N: exit 0 when one step at N would take longer than MAX_STEP_S, judged from the last two
# sizes measured (growth exponent between 1 and 2; 2 when only one is known, so seq is never run for
# minutes).
forecast_too_slow() {
    local key=$1 n=$2
    [ -n "${LAST_N[$key]:-}" ] || return 1
    awk -v p="${LAST_STEP[$key]}" -v a="${LAST_N[$key]}" -v q="${PREV_STEP[$key]:-}" \
        -v c="${PREV_N[$key]:-}" -v n="$n" -v m="$MAX_STEP_S" 'BEGIN {
        e = 2
        if (c != "" && q > 0 && a > c) e = log(p / q) / log(a / c)
        if (e < 1) e = 1; if (e > 2) e = 2
        exit !(p * (n / a) ^ e > m) }'
}

START=$EPOCHREALTIME
for scene in $SCENES; do
    for n in $ALL_SIZES; do
        if scene_lists_disks "$scene" && [ "$n" -gt "$FILE_MAX_N" ]; then continue; fi
        if [ "$PREPARE" = 1 ]; then # every N here is some backend's to run
            scene_file "$scene" "$n" > /dev/null
            echo "bench.sh: scene $scene N = $n ready" >&2
            continue
        fi
        base=""
        geometry=""
        for b in $RUNNABLE; do
            [[ ${SIZES_OF[$b]} == *" $n "* ]] || continue
            for t in $(threads_of "$b"); do
                key="$b/$t/$scene"
                [ -z "${SKIPPED[$key]:-}" ] || continue
                if forecast_too_slow "$key" "$n"; then
                    SKIPPED[$key]=1
                    echo "bench.sh: $key: N >= $n skipped (one step would take over $MAX_STEP_S s)" >&2
                    continue
                fi
                if [ -z "$base" ]; then
                    base=$(scene_file "$scene" "$n")
                    geometry=$(awk 'NR == 2 { L = $1 } NR == 3 { r = $1 } NR == 1 { n = $1 } NR == 3 {
                        printf "%.10g,%.10g,%.6g", L, r, n * 3.141592653589793 * r * r / (L * L); exit }' "$base")
                fi
                if [ -n "$STEPS_FIXED" ]; then
                    STEPS=$STEPS_FIXED
                    with_steps "$base" "$STEPS"
                    run_once "$b" "$t" # the warm-up, discarded; it also measures the step
                    PER_STEP=$(awk -v x="$SECONDS_LOOP" -v s="$STEPS" 'BEGIN { printf "%.9g", x / s }')
                else
                    calibrate "$b" "$t" "$base"
                fi
                PREV_N[$key]=${LAST_N[$key]:-}
                PREV_STEP[$key]=${LAST_STEP[$key]:-}
                LAST_N[$key]=$n
                LAST_STEP[$key]=$PER_STEP
                if awk -v p="$PER_STEP" -v m="$MAX_STEP_S" 'BEGIN { exit !(p > m) }'; then
                    SKIPPED[$key]=1
                    echo "bench.sh: $key: N >= $n skipped (one step takes $PER_STEP s)" >&2
                    continue
                fi
                [ -n "$STEPS_FIXED" ] || warm_up "$b" "$t" "$base"
                for ((k = 1; k <= REPEATS; k++)); do
                    run_once "$b" "$t"
                    awk -v OFS=, -v b="$b" -v t="$t" -v sc="$scene" -v n="$n" -v s="$STEPS" -v k="$k" \
                        -v x="$SECONDS_LOOP" -v w="$WALL" -v p="$PAIR_TESTS" -v e="$EVENTS" -v g="$geometry" \
                        'BEGIN { ps = n * s; printf "%s,%s,%s,%s,%s,%s,%s,%s,%.6g,%.6g,%.6g,%s,%s,%s\n",
                                 b, t, sc, n, s, k, x, w, x * 1e9 / ps, p / ps, e / ps, p, e, g }' >> "$OUTPUT"
                done
                printf 'bench.sh: %-5s %3s threads  %-7s N = %-9s %7s steps  %s s\n' \
                    "$b" "$t" "$scene" "$n" "$STEPS" "$SECONDS_LOOP" >&2
            done
        done
    done
done

# ---- summary: min and median of the timed runs of each point (its rows are consecutive) ------------
summarize "$OUTPUT" "# load average at end (1, 5, 15 min): $(cut -d' ' -f1-3 /proc/loadavg 2>/dev/null)"

echo "bench.sh: $(grep -c -v -e '^#' -e '^backend,' "$OUTPUT") runs in" \
    "$(awk -v a="$START" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.0f", b - a }') s: $OUTPUT, $SUMMARY" >&2
