#!/usr/bin/env bash
# ./bench.sh io: the text path (reading and parsing the input, formatting and writing the output)
# measured as a user meets it: whole process, wall clock around the command, output to a file. Each
# row: the best and the median of REPEATS runs after a warm-up, (input + output bytes) / whole process,
# and the program's own --stats split (read, parse, format and write: their MB/s).
#   ./bench.sh io                the gas of 1e6 disks, S = 0, omp on THREADS (default "1 2"), seq
#   ./bench.sh io gpu            the same at 1, 2, 4, 8, 16 threads; cuda on the gas of 1e7 disks
#                                    (S = 0 and 50) and of 1e8 (S = 10, 2 runs; BIG=0 leaves it out)
#   ./bench.sh io mpi            the gas of 4e6 disks (IO_N), S = 0 (IO_STEPS; IO_MODE=print: every step
#                                written): omp on 2 threads, mpi (--output FILE)
#                                    on 1 rank of 2 threads and 2 ranks of 1 (no checkpoints)
#   The first two end with checkpoints: seconds and MB/s of one (omp on the gas of 1e6; gpu: cuda on 1e7), and
#   the whole process of resuming one.
#   BASE_REV=REV ./bench.sh io   also revision REV's omp (gpu: and cuda; mpi: and mpi), built in bench/tmp/base,
#                                    row by row
set -euo pipefail
cd "$(dirname "$0")/../.."
. bench/cmd/lib.sh
REPEATS=${REPEATS:-5}
WORK=${WORK:-bench/tmp}
BIG=${BIG:-1}
mode=${1:-cpu}
THREADS=${THREADS:-$([ "$mode" = gpu ] && echo "1 2 4 8 16" || echo "1 2")}
make -s seq omp tools/gen >/dev/null
[ "$mode" != gpu ] || make -s cuda >/dev/null
[ "$mode" != mpi ] || make -s mpi >/dev/null
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
mkdir -p "$WORK"
machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)"
echo "# REPEATS=$REPEATS; output to $WORK/io.out (a new file each run)"
echo "program,threads,n,steps,in_mb,out_mb,best_s,median_s,mb_per_s,stats"

# run N STEPS INPUT PROGRAM THREADS [ARGS]: one row; with BASE_REV, a row of the base build first, the two
# builds' runs alternating (a machine's state drifts: disk writeback, page cache, clocks)
run() {
    local n=$1 steps=$2 in=$3 prog=$4 threads=$5 progs=() walls=() s e k p
    shift 5
    case "${BASE_REV:+x}$prog" in xomp | xcuda | xmpi_r*) progs+=("bench/tmp/base/$prog") ;; esac
    progs+=("$prog")
    local args=("$in" --stats "$@")
    [ "$threads" = - ] || args+=(--threads "$threads")
    for p in "${progs[@]}"; do
        echo "# ./$p ${args[*]} > $WORK/io.out"
        ./"$p" "${args[@]}" > "$WORK/io.out" 2> "$WORK/io.err" || true # warm-up
        walls[${#walls[@]}]=""
    done
    for ((k = 0; k < REPEATS; k++)); do
        for ((q = 0; q < ${#progs[@]}; q++)); do
            rm -f "$WORK/io.out" # not timed: the shell's truncation of the last run's output
            s=$(date +%s%N)
            ./"${progs[q]}" "${args[@]}" > "$WORK/io.out" 2> "$WORK/io.err.$q"
            e=$(date +%s%N)
            walls[q]="${walls[q]} $(awk -v a="$s" -v b="$e" 'BEGIN { printf "%.4f", (b - a) / 1e9 }')"
        done
    done
    local best median in_mb out_mb
    in_mb=$(awk -v b="$(stat -c %s "$in")" 'BEGIN { printf "%.1f", b / 1e6 }')
    out_mb=$(awk -v b="$(stat -c %s "$WORK/io.out")" 'BEGIN { printf "%.1f", b / 1e6 }')
    for ((q = 0; q < ${#progs[@]}; q++)); do
        # shellcheck disable=SC2086
        best=$(printf '%s\n' ${walls[q]} | sort -g | head -1)
        # shellcheck disable=SC2086
        median=$(printf '%s\n' ${walls[q]} | sort -g | sed -n "$(((REPEATS + 1) / 2))p")
        echo "${progs[q]},${threads/-/1},$n,$steps,$in_mb,$out_mb,$best,$median,$(awk -v a="$in_mb" -v b="$out_mb" \
            -v t="$best" 'BEGIN { printf "%.0f", (a + b) / t }'),\"$(grep -h 'input ' "$WORK/io.err.$q" | sed 's/^[a-z_0-9]*: //')\""
    done
}

gas() { # gas N STEPS [MODE]: the file of a gas of N disks (fraction 0.2, speeds up to r/2), perf mode or MODE
    local f=$WORK/io_gas_$1_$2${3:+_$3}.in
    [ -s "$f" ] || tools/gen "$1" --fraction 0.2 --speed 0.5 --steps "$2" --mode "${3:-perf}" > "$f"
    echo "$f"
}

if [ -n "${BASE_REV:-}" ]; then
    targets=omp
    [ "$mode" != gpu ] || targets="omp cuda"
    [ "$mode" != mpi ] || targets="omp mpi"
    build_revision "$BASE_REV" bench/tmp/base "$WORK/base_build.log" "$targets" ||
        { tail -5 "$WORK/base_build.log"; exit 1; }
    echo "# bench/tmp/base/{$targets}: revision $BASE_REV's build"
fi
# mpi_rR: mpirun of R ranks around the mpi beside it (here, or the base's), its output to --output's
# file (the rows' --threads: a rank's)
mpi_wrappers() { # DIR
    local r
    for r in 1 2; do
        printf '#!/bin/sh\nexec mpirun -np %s --oversubscribe --bind-to none "$(dirname "$0")/mpi" "$@" --output %s\n' \
            "$r" "$(cd "$WORK" && pwd)/io.out" > "$1/mpi_r$r"
        chmod +x "$1/mpi_r$r"
    done
}
if [ "$mode" = mpi ]; then
    mpi_wrappers .
    [ -z "${BASE_REV:-}" ] || mpi_wrappers bench/tmp/base
    n=$(integer "${IO_N:-4000000}") steps=${IO_STEPS:-0}
    in=$(gas "$n" "$steps" "${IO_MODE:-}")
    run "$n" "$steps" "$in" omp 2
    run "$n" "$steps" "$in" mpi_r1 2
    run "$n" "$steps" "$in" mpi_r2 1
    rm -f mpi_r1 mpi_r2 "$WORK/io.out"
    exit 0
fi
in=$(gas 1000000 0)
for t in $THREADS; do run 1000000 0 "$in" omp "$t"; done
[ "$mode" = gpu ] || run 1000000 0 "$in" seq -
if [ "$mode" = gpu ]; then
    in=$(gas 10000000 0); run 10000000 0 "$in" cuda -
    in=$(gas 10000000 50); run 10000000 50 "$in" cuda -
fi

# ---- checkpoints: a run of 4 steps that saves one after steps 1, 2 and 3, against the same run
# without; and resuming the last one (its 1 step and the final state) ----
best_wall() { # COMMAND...: the best wall seconds of REPEATS runs (stdout to $WORK/io.out)
    local k s e best=""
    for ((k = 0; k < REPEATS; k++)); do
        rm -f "$WORK/io.out"
        s=$(date +%s%N)
        "$@" > "$WORK/io.out" 2> "$WORK/io.err"
        e=$(date +%s%N)
        best=$(awk -v a="$s" -v b="$e" -v m="$best" 'BEGIN { t = (b - a) / 1e9; printf "%.4f", (m == "" || t < m) ? t : m }')
    done
    echo "$best"
}
checkpoints() { # PROGRAM THREADS N
    local prog=$1 t=$2 n=$3 in plain with resume mb args=()
    in=$(gas "$n" 4)
    [ "$t" = - ] || args+=(--threads "$t")
    echo "# ./$prog $in ${args[*]} [--checkpoint $WORK/io.ck --checkpoint-every 1]; ./$prog --resume $WORK/io.ck ${args[*]}"
    ./"$prog" "$in" "${args[@]}" > /dev/null 2>&1 # warm-up
    plain=$(best_wall ./"$prog" "$in" --quiet "${args[@]}")
    with=$(best_wall ./"$prog" "$in" --quiet "${args[@]}" --checkpoint "$WORK/io.ck" --checkpoint-every 1)
    resume=$(best_wall ./"$prog" --resume "$WORK/io.ck" --quiet "${args[@]}")
    mb=$(awk -v b="$(stat -c %s "$WORK/io.ck")" 'BEGIN { printf "%.1f", b / 1e6 }')
    awk -v p="$prog" -v t="${t/-/1}" -v n="$n" -v mb="$mb" -v a="$plain" -v b="$with" -v r="$resume" \
        'BEGIN { c = (b - a) / 3; printf "checkpoint,%s,%s,%s,%s,%s,%s,%.4f,%.0f,%s\n", p, t, n, mb, a, b, c, mb / c, r }'
}
echo "kind,program,threads,n,checkpoint_mb,plain_s,with_3_checkpoints_s,s_per_checkpoint,mb_per_s,resume_s"
for t in $THREADS; do checkpoints omp "$t" 1000000; done
[ "$mode" != gpu ] || checkpoints cuda - 10000000
rm -f "$WORK/io.ck"

if [ "$mode" = gpu ] && [ "$BIG" = 1 ]; then
    REPEATS=2
    in=$(gas 100000000 10); run 100000000 10 "$in" cuda -
    rm -f "$WORK/io.out"
fi
