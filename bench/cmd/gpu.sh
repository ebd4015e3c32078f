#!/usr/bin/env bash
# ./bench.sh gpu-*: on a machine with an NVIDIA GPU, builds everything, checks cuda against seq and
# times cuda against omp on the same inputs. Logs and a CSV go to $OUT (default bench/tmp).
#   ./bench.sh gpu-check   build, make test, compute-sanitizer memcheck on small scenes
#   ./bench.sh gpu-memcheck  only the memcheck part; exit status 1 where a run had errors or leaks or
#                            printed other bytes than seq
#   ./bench.sh gpu-perf    timings: fixed-density gas (N = 1e6, 1e7) and the assignment's random scene;
#                            BASE=DIR also times DIR/cuda (an earlier build) on the same inputs, and
#                            BASE_REV=REV builds revision REV's cuda beside this tree as that BASE
#   ./bench.sh gpu-host    the host-side work around the steps at N = 1e8 (random placement, writing
#                            step 0 and the final state), timed stage by stage, seq (one thread) and cuda
#   ./bench.sh gpu-big     the gas at N = 1e8 (input generated on one core, minutes; the run takes
#                            about 110 s, nearly all of it parsing the input)
#   ./bench.sh gpu-profile device time per phase (cuda --stats)
#   ./bench.sh gpu-kernels device time per kernel under Nsight Compute (ncu) on the random scene at N =
#                            KERNELS_N (default 32000), per step, beside the step loop's own time per step
#                            (the difference is the cost of launching); then ncu's full report of the
#                            binning, placement and search kernels (kernels_full.txt)
#   ./bench.sh gpu-targets the GPU machine's targets of the fast scenes: cuda on the assignment's random
#                            scene at N = 32000 (200 steps), 1e5 and 3e5 (20 steps), 1e6 (10 steps) and
#                            the gas at 1e7 (50 steps), two runs each and one with one time window a step
#                            (SIM_CUDA_WINDOW=0); omp on the random scene at N = 1e5 on 1 and 16 threads
#                            (./bench.sh targets); BASE_SRC=FILE also times an earlier tree's cuda.cu (say
#                            from `git show REV:cuda.cu`; its cuda_*.cuh beside it), built against this tree's
#                            objects, beside each run;
#                            OMP_TOO=0 leaves omp out
#   ./bench.sh gpu-goals   each of cuda's goals with its figure, one line `# goal: ...` each: the step
#                            loop on the gas of 1e7 and (GOALS_BIG=1) of 1e8, the dense gas of 1e7, the
#                            random scene at 32000 (200 steps) and 1e6 (10 steps); device memory a disk
#                            (nvidia-smi's peak during the run less its reading before) at 1e7 and 1e8;
#                            a run too large for the GPU refused (too_big); the whole process on the gas
#                            of 1e7 with S = 50 (text in and out). BASE_SRC=FILE times an earlier cuda.cu
#                            beside each run; GOALS_SCENES picks scenes (GOALS_SCENES=none: the refusal
#                            alone; with GOALS_BIG=1, and the gas of 1e8)
#   ./bench.sh gpu-bytes   DRAM bytes a particle-step, kernel by kernel and step by step, under Nsight
#                            Compute, on the goals' gas of 1e7 (BYTES_N) over 20 steps, beside the 80-byte
#                            floor: the launches from the first (BYTES_SKIP) to the 260th (BYTES_COUNT), the
#                            whole steps among them (a gather at steps 1 and 10)
#   ./bench.sh gpu-streams the memory streams of cuda's move of a gas alone (bench/cmd/streams.cu, N = 1e7):
#                            the time its bytes take, the move's floor
#   ./bench.sh gpu-all     check, then perf
set -euo pipefail
cd "$(dirname "$0")/../.."
. bench/cmd/lib.sh
OUT=${OUT:-bench/tmp}
mkdir -p "$OUT"
THREADS=${THREADS:-16}
GAS_STEPS=${GAS_STEPS:-50}
RANDOM_STEPS=${RANDOM_STEPS:-200}
CSV=$OUT/timings.csv
DATA=${DATA:-/tmp/gpu_run}
mkdir -p "$DATA"


# time_one LABEL N PROGRAM ARGS...: one run, step-loop time from the program's own stderr line. The
# program is named by its file name, or NAME=... in the environment (an earlier build: cuda_base).
time_one() {
    local label=$1 n=$2 prog=$3
    shift 3
    local err=$DATA/err name=${NAME:-$(basename "$prog")}
    if ! "$prog" "$@" > "$DATA/$label.$name.out" 2> "$err"; then
        echo "$label,$name,$n,FAILED: $(head -c 200 "$err")" | tee -a "$CSV"
        return
    fi
    local line secs ps
    line=$(grep -E " s step loop, .* particle-steps/s" "$err" | tail -1)
    secs=$(echo "$line" | sed -E 's/.* ([0-9.]+) s step loop.*/\1/')
    ps=$(echo "$line" | sed -E 's/.* ([0-9.e+]+) particle-steps\/s.*/\1/')
    echo "$label,$name,$n,$secs,$ps,$(grep -E 'pair tests' "$err" | sed -E 's/.*: //' || true)" \
        | tee -a "$CSV"
}

same() { # same LABEL: the outputs of the two programs of LABEL agree
    if cmp -s "$DATA/$1.cuda.out" "$DATA/$1.$2.out"; then echo "$1: cuda == $2"; else echo "$1: cuda != $2 DIFFER"; fi
}

do_check() {
    make -j"$(nproc)" all seq_san 2>&1 | tail -3
    nvidia-smi -L
    set +e
    make test 2>&1 | tee "$OUT/test.log" | grep -vE '^PASS'
    set -e
    do_memcheck
}

# compute-sanitizer memcheck of cuda and cuda_f32 (and mpi_cuda, where built) on small scenes, outputs
# compared with seq. Fails (exit 1) where a run had errors or leaks or printed other bytes than seq.
do_memcheck() {
    local san failed=0
    san=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
    if [ ! -x "$san" ]; then
        echo "compute-sanitizer not found"
        return
    fi
    # checked LABEL LOG EXPECTED PROGRAM ARGS...: PROGRAM under memcheck (the caller's variables set before the
    # call reach it), then its output against EXPECTED
    checked() {
        local label=$1 log=$2 expected=$3
        shift 3
        "$san" --tool memcheck --leak-check full --error-exitcode 9 --log-file "$log" "$@" > "$DATA/checked.out" \
            && echo "memcheck $label: clean" \
            || { echo "memcheck $label: ERRORS"; tail -20 "$log"; failed=$((failed + 1)); }
        cmp -s "$expected" "$DATA/checked.out" && echo "memcheck $label: output == seq" \
            || { echo "memcheck $label: output DIFFERS"; failed=$((failed + 1)); }
    }
    tools/gen 3000 --fraction 0.3 --speed 2 --steps 5 --seed 11 > "$DATA/san.in"
    printf '2000\n20000\n1\n4\nprint\n' > "$DATA/san_random.in"
    ./seq_f32 "$DATA/san.in" --quiet > "$DATA/san.seq_f32"
    checked "san cuda_f32 (against seq_f32)" "$OUT/memcheck_san_f32.log" "$DATA/san.seq_f32" ./cuda_f32 \
        "$DATA/san.in" --quiet
    for f in san san_random; do
        ./seq "$DATA/$f.in" --quiet > "$DATA/$f.seq"
        checked "$f" "$OUT/memcheck_$f.log" "$DATA/$f.seq" ./cuda "$DATA/$f.in" --quiet
    done
    # the periodic box: one slice a step, several, and the windows
    tools/gen 3000 --periodic --fraction 0.3 --speed 2 --steps 5 --seed 13 > "$DATA/san_periodic.in"
    tools/gen 1500 --periodic --assignment --fraction 0.05 --steps 4 --seed 14 > "$DATA/san_pfast.in"
    for f in san_periodic san_pfast; do
        ./seq "$DATA/$f.in" --quiet --periodic > "$DATA/$f.seq"
        for w in "" 1; do
            SIM_CUDA_WINDOW=$w checked "$f${w:+ windows}" "$OUT/memcheck_$f$w.log" "$DATA/$f.seq" ./cuda \
                "$DATA/$f.in" --quiet --periodic
        done
    done
    # a gas of one slice a step, whose moves key the cells of the next step (cuda_move.cuh, MoveBin); the same
    # with every cell table scanned by cub, so counted in 8 bits (count_add)
    tools/gen 3000 --fraction 0.2 --speed 0.5 --steps 12 --seed 15 > "$DATA/san_gas.in"
    ./seq "$DATA/san_gas.in" --quiet > "$DATA/gas.seq" # seq's bytes once, for cuda and mpi_cuda below
    checked san_gas "$OUT/memcheck_gas.log" "$DATA/gas.seq" ./cuda "$DATA/san_gas.in" --quiet
    SIM_CUDA_SCAN_TILES=0 checked "san_gas, 8-bit counts" "$OUT/memcheck_gas8.log" "$DATA/gas.seq" ./cuda \
        "$DATA/san_gas.in" --quiet
    # every keyed step's table sorted in buckets (cuda_rows.cuh); and the ring scene (tests/lib.sh), whose
    # bucket past its room refuses its step
    SIM_CUDA_ROWS=1 checked "san_gas, buckets" "$OUT/memcheck_gas_rows.log" "$DATA/gas.seq" ./cuda \
        "$DATA/san_gas.in" --quiet
    (TMP=$DATA/tests && . tests/lib.sh && crowd_scene ring perf) > "$DATA/san_ring.in"
    ./seq "$DATA/san_ring.in" --quiet > "$DATA/san_ring.seq"
    SIM_CUDA_ROWS=1 checked "ring, a bucket past its room" "$OUT/memcheck_ring.log" "$DATA/san_ring.seq" ./cuda \
        "$DATA/san_ring.in" --quiet
    # mpi_cuda at 3 ranks, where it is built: halos GPU to GPU and through host memory, moves done again
    # (their leavers beyond the room), searches done again (their events beyond the list), 8-bit counts
    if [ -x ./mpi_cuda ] && command -v mpirun > /dev/null; then
        for e in SIM_MPI_CUDA_HOST=0 SIM_MPI_CUDA_HOST=1 SIM_MPI_CUDA_LEAVERS_ROOM=0 SIM_MPI_CUDA_EVENTS=2 \
            SIM_CUDA_SCAN_TILES=0; do
            local log="$OUT/memcheck_mpi_cuda_${e#SIM_MPI_CUDA_}"
            env "$e" OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 mpirun -np 3 --oversubscribe \
                "$san" --tool memcheck --leak-check full --error-exitcode 9 --log-file "$log.%p.log" \
                ./mpi_cuda "$DATA/san_gas.in" --quiet > "$DATA/mpi_gas.out" \
                && echo "memcheck san_gas, mpi_cuda at 3 ranks, $e: clean" \
                || {
                    echo "memcheck san_gas, mpi_cuda at 3 ranks, $e: ERRORS"
                    tail -n 20 "$log".*.log
                    failed=$((failed + 1))
                }
            cmp -s "$DATA/gas.seq" "$DATA/mpi_gas.out" && echo "memcheck san_gas, mpi_cuda, $e: output == seq" \
                || { echo "memcheck san_gas, mpi_cuda, $e: output DIFFERS"; failed=$((failed + 1)); }
        done
    fi
    # the time windows, forced from one slice (a scene this small gets one window otherwise)
    SIM_CUDA_WINDOW=1 checked "san_random, windows" "$OUT/memcheck_windows.log" "$DATA/san_random.seq" ./cuda \
        "$DATA/san_random.in" --quiet
    if [ "$failed" -gt 0 ]; then
        echo "memcheck: $failed checks FAILED"
        return 1
    fi
    echo "memcheck: every run clean, every output == seq"
}

# cuda, and BASE/cuda where given, on one input; BASE's output must be the same bytes.
time_cuda() { # LABEL N INPUT
    time_one "$1" "$2" ./cuda "$3" --stats
    time_one "$1" "$2" ./cuda "$3" --stats
    if [ -n "${BASE:-}" ]; then
        NAME=cuda_base time_one "$1" "$2" "$BASE/cuda" "$3" --stats
        NAME=cuda_base time_one "$1" "$2" "$BASE/cuda" "$3" --stats
        same "$1" cuda_base
    fi
}

do_perf() {
    if [ -n "${BASE_REV:-}" ] && [ -z "${BASE:-}" ]; then
        BASE=$DATA/base
        build_revision "$BASE_REV" "$BASE" "$OUT/base_build.log" || { tail -5 "$OUT/base_build.log"; exit 1; }
    fi
    machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)" >> "$CSV"
    echo "label,program,N,seconds,particle_steps_per_s,stats" >> "$CSV"
    for n in 1000000 10000000; do
        [ -s "$DATA/gas_$n.in" ] || tools/gen $n --fraction 0.2 --speed 0.5 --steps $GAS_STEPS > "$DATA/gas_$n.in"
        ./cuda "$DATA/gas_$n.in" > /dev/null 2>&1 # warm-up, discarded
        time_cuda gas_$n $n "$DATA/gas_$n.in"
        if [ "${OMP_TOO:-1}" = 1 ]; then
            time_one gas_$n $n ./omp "$DATA/gas_$n.in" --threads "$THREADS" --stats
            same gas_$n omp
        fi
    done
    # omp beside cuda on a small gas
    tools/gen 20000 --fraction 0.2 --speed 0.5 --steps 20 > "$DATA/gas_20000.in"
    time_one gas_20000 20000 ./omp "$DATA/gas_20000.in" --threads "$THREADS" --stats
    time_one gas_20000 20000 ./cuda "$DATA/gas_20000.in" --stats
    same gas_20000 omp
    for n in 32000 1000000; do
        local s=$RANDOM_STEPS
        [ $n -gt 100000 ] && s=10
        printf '%s\n20000\n1\n%s\nperf\n' $n $s > "$DATA/random_$n.in"
        time_cuda random_$n $n "$DATA/random_$n.in"
        if [ "${OMP_TOO:-1}" = 1 ] && [ $n -le 100000 ]; then # omp takes ~50 s at 1e6
            time_one random_$n $n ./omp "$DATA/random_$n.in" --threads "$THREADS" --stats
            same random_$n omp
        fi
    done
    printf '32000\n20000\n1\n10\nperf\n' > "$DATA/random10_32000.in"
    time_one random10_32000 32000 ./omp "$DATA/random10_32000.in" --threads "$THREADS" --stats
    time_one random10_32000 32000 ./cuda "$DATA/random10_32000.in" --stats
    same random10_32000 omp
    printf '32000\n20000\n1\n20\nprint\n' > "$DATA/random_print.in"
    time_one random_print 32000 ./cuda "$DATA/random_print.in"
}

# host_stages PROGRAM NAME ARGS...: each stderr line with the wall time at which it came (the
# placement's line, the timing line after the steps), and the time of the exit; stdout to /dev/null.
host_stages() {
    local prog=$1 name=$2 t0 line
    shift 2
    t0=$(date +%s.%N)
    "$prog" "$@" 2>&1 > /dev/null | while IFS= read -r line; do
        echo "$(awk -v a="$(date +%s.%N)" -v b="$t0" 'BEGIN { printf "%.1f", a - b }') s $name: $line"
    done
    echo "$(awk -v a="$(date +%s.%N)" -v b="$t0" 'BEGIN { printf "%.1f", a - b }') s $name: exit"
}

# The host work of a 1e8 run with the built-in placement: placement, then step 0 and the final state
# (S = 0: no steps, so the time after placement is the two writes). seq writes them on one thread, as
# every backend did before backend_write_state; the placement is the same code in both.
do_host() {
    printf '100000000\n6324555\n1\n0\nperf\n' > "$DATA/host.in"
    host_stages ./seq seq "$DATA/host.in" | tee -a "$OUT/host.log"
    host_stages ./cuda cuda "$DATA/host.in" | tee -a "$OUT/host.log"
}

# N = 1e8: generating (~5 min on one core), parsing and formatting the two printed states run on the
# host and take far longer than the steps; each stage is logged as it ends.
do_big() {
    local n=100000000 t0
    machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)" >> "$CSV"
    t0=$(date +%s)
    [ -s "$DATA/big.in" ] || tools/gen $n --fraction 0.2 --speed 0.5 --steps 10 > "$DATA/big.in"
    echo "big: input ready after $(( $(date +%s) - t0 )) s"
    host_stages ./cuda cuda "$DATA/big.in" --stats > "$DATA/big.err"
    cat "$DATA/big.err"
    echo "big: done after $(( $(date +%s) - t0 )) s"
    echo "gas_$n,cuda,$n,$(grep 'step loop' "$DATA/big.err" | sed -E 's/.* ([0-9.]+) s step loop, ([0-9.e+]+).*/\1,\2/')" >> "$CSV"
}

# Device time per phase (cuda --stats times each phase with events), for the gas and the random scene.
do_profile() {
    [ -s "$DATA/gas_10000000.in" ] || tools/gen 10000000 --fraction 0.2 --speed 0.5 --steps $GAS_STEPS > "$DATA/gas_10000000.in"
    printf '32000\n20000\n1\n%s\nperf\n' $RANDOM_STEPS > "$DATA/random_32000.in"
    for f in gas_10000000 random_32000; do
        echo "$f:"
        ./cuda "$DATA/$f.in" --stats 2>&1 > /dev/null | tee "$OUT/phases_$f.log"
    done
}

do_kernels() {
    local n=${KERNELS_N:-32000} ncu
    ncu=$(command -v ncu || echo /usr/local/cuda/bin/ncu)
    [ -x "$ncu" ] || { echo "ncu not found"; return 1; }
    printf '%s\n20000\n1\n200\nperf\n' "$n" > "$DATA/random_k$n.in"
    printf '%s\n20000\n1\n30\nperf\n' "$n" > "$DATA/random_k30_$n.in"
    ./cuda "$DATA/random_k$n.in" > /dev/null 2>&1 # warm-up, discarded
    time_one "random_$n" "$n" ./cuda "$DATA/random_k$n.in" --stats
    time_one "random_$n" "$n" ./cuda "$DATA/random_k$n.in" --stats
    ./cuda "$DATA/random_k$n.in" --stats 2>&1 > /dev/null | grep -E 'phase' | sed "s/^/# random_$n: /" >> "$CSV"
    "$ncu" --csv --page raw --cache-control none --clock-control none \
        --metrics gpu__time_duration.sum,sm__throughput.avg.pct_of_peak_sustained_elapsed,gpu__compute_memory_throughput.avg.pct_of_peak_sustained_elapsed,l1tex__t_sector_hit_rate.pct,lts__t_sector_hit_rate.pct,sm__warps_active.avg.pct_of_peak_sustained_active,launch__grid_size \
        --log-file "$DATA/kernels.raw" ./cuda "$DATA/random_k30_$n.in" --quiet > /dev/null 2> "$OUT/kernels_ncu.err" \
        || { tail -5 "$OUT/kernels_ncu.err" "$DATA/kernels.raw"; return 1; }
    sed -n '/"ID"/,$p' "$DATA/kernels.raw" > "$OUT/kernels_raw.csv"
    python3 tools/ncu_kernels.py "$OUT/kernels_raw.csv" | tee "$OUT/kernels.csv"
    "$ncu" --set full --cache-control none --clock-control none \
        --kernel-name regex:'detect_kernel|gather_entries|place_kernel|bin_kernel' --launch-skip 20 --launch-count 4 \
        --log-file "$OUT/kernels_full.txt" ./cuda "$DATA/random_k30_$n.in" --quiet > /dev/null 2>&1 \
        || tail -5 "$OUT/kernels_full.txt"
}

# DRAM bytes a particle-step, kernel by kernel, under Nsight Compute on the gas of 1e7 (BYTES_N):
# every kernel of steps 3 and 4 (kernel by kernel, SIM_CUDA_GRAPH=0; caches flushed before each, so
# each kernel's reads come from DRAM as in a step whose state outgrows L2), beside the 80-byte floor
# (a disk's 40 bytes read and written once a step).
do_bytes() {
    local n=${BYTES_N:-10000000} ncu
    ncu=$(command -v ncu || echo /usr/local/cuda/bin/ncu)
    [ -x "$ncu" ] || { echo "ncu not found"; return 1; }
    [ -s "$DATA/bytes20_$n.in" ] || tools/gen "$n" --fraction 0.2 --speed 0.5 --steps 20 > "$DATA/bytes20_$n.in"
    SIM_CUDA_GRAPH=0 "$ncu" --csv --page raw --cache-control all --clock-control none \
        --metrics gpu__time_duration.sum,dram__bytes_read.sum,dram__bytes_write.sum \
        --launch-skip "${BYTES_SKIP:-0}" --launch-count "${BYTES_COUNT:-260}" \
        --log-file "$DATA/bytes.raw" ./cuda "$DATA/bytes20_$n.in" --quiet > /dev/null 2> "$OUT/bytes_ncu.err" \
        || { tail -5 "$OUT/bytes_ncu.err" "$DATA/bytes.raw"; return 1; }
    sed -n '/"ID"/,$p' "$DATA/bytes.raw" > "$OUT/bytes_raw.csv"
    python3 tools/ncu_kernels.py "$OUT/bytes_raw.csv" "$n" | tee "$OUT/bytes.csv"
}

# BASE_SRC=FILE: an earlier cuda.cu built as $DATA/base/cuda (build_source).
build_base_source() {
    BASE=$DATA/base
    build_source "$BASE_SRC" "$BASE/cuda" "$OUT/base_build.log" || { tail -5 "$OUT/base_build.log"; exit 1; }
}

do_targets() {
    [ -n "${BASE_SRC:-}" ] && build_base_source
    machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)" >> "$CSV"
    [ -n "${BASE_SRC:-}" ] && echo "# cuda_base: $BASE_SRC, sha256 $(sha256sum < "$BASE_SRC" | cut -c1-16)" >> "$CSV"
    echo "label,program,N,seconds,particle_steps_per_s,stats" >> "$CSV"
    printf '32000\n20000\n1\n200\nperf\n' > "$DATA/random_32000.in"
    printf '100000\n20000\n1\n20\nperf\n' > "$DATA/random_100000.in"
    printf '300000\n20000\n1\n20\nperf\n' > "$DATA/random_300000.in"
    printf '1000000\n20000\n1\n10\nperf\n' > "$DATA/random_1000000.in"
    [ -s "$DATA/gas_10000000.in" ] || tools/gen 10000000 --fraction 0.2 --speed 0.5 --steps 50 > "$DATA/gas_10000000.in"
    for f in random_32000 random_100000 random_300000 random_1000000 gas_10000000; do
        n=${f#*_}
        ./cuda "$DATA/$f.in" > /dev/null 2>&1 # warm-up, discarded
        for round in 1 2; do # alternately with the earlier build, where given
            time_one "$f" "$n" ./cuda "$DATA/$f.in" --stats
            [ -n "${BASE:-}" ] && NAME=cuda_base time_one "$f" "$n" "$BASE/cuda" "$DATA/$f.in" --stats
        done
        [ -n "${BASE:-}" ] && same "$f" cuda_base | sed 's/^/# /' >> "$CSV"
        ./cuda "$DATA/$f.in" --stats 2>&1 > /dev/null | grep -E 'phase|round|window|refused' | sed "s/^/# $f: /" >> "$CSV"
        # the same in one time window a step (the choice waits for no window: cuda_state.cuh, window_start)
        SIM_CUDA_WINDOW=0 NAME=cuda_one_window time_one "$f" "$n" ./cuda "$DATA/$f.in" --stats
    done
    if [ "${OMP_TOO:-1}" = 1 ]; then
        THREADS="1 16" CASES=random1e5 REPEATS=2 ./bench.sh targets > "$OUT/omp_random1e5.log" 2>&1
        grep -E '^# target' "$OUT/omp_random1e5.log" >> "$CSV"
    fi
}


# peak_memory COMMAND...: runs COMMAND (stdout to /dev/null, stderr to $DATA/err) while nvidia-smi
# samples the device's used memory every 20 ms; prints the peak less the reading before the run, MB
peak_memory() {
    local idle peak pid
    idle=$(nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits -i 0)
    nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits -i 0 -lms 20 > "$DATA/mem.log" &
    pid=$!
    "$@" > /dev/null 2> "$DATA/err"
    kill "$pid" 2> /dev/null
    wait "$pid" 2> /dev/null || true
    peak=$(sort -n "$DATA/mem.log" | tail -1)
    echo $((peak - idle))
}

# goal WHAT FIGURE TARGET OP: one line, met or missed (OP: ge or le)
goal() {
    local verdict
    verdict=$(awk -v f="$2" -v t="$3" -v op="$4" 'BEGIN { ok = op == "ge" ? f >= t : f <= t; print ok ? "met" : "MISSED" }')
    echo "# goal: $1: $2 (target $([ "$4" = ge ] && echo ">=" || echo "<=") $3): $verdict" | tee -a "$CSV"
}

# best_rate LABEL N PROGRAM ARGS...: the best step-loop rate of three runs after a warm-up; then a run with
# --stats into $DATA/err (its phases)
best_rate() {
    local label=$1 n=$2 prog=$3 best=0 r
    shift 3
    "$prog" "$@" > /dev/null 2>&1 || true
    for _ in 1 2 3; do # without --stats, which times each phase and so launches no graphs
        time_one "$label" "$n" "$prog" "$@" > /dev/null
        r=$(tail -1 "$CSV" | cut -d, -f5)
        best=$(awk -v a="$best" -v b="${r:-0}" 'BEGIN { print (b + 0 > a + 0) ? b : a }')
    done
    "$prog" "$@" --stats > /dev/null 2> "$DATA/err" || true # the phases, for the log
    echo "$best"
}

do_goals() {
    [ -n "${BASE_SRC:-}" ] && build_base_source
    machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)" >> "$CSV"
    echo "label,program,N,seconds,particle_steps_per_s,stats" >> "$CSV"
    local scenes=${GOALS_SCENES:-gas_10000000 dense_10000000 random_32000 random_1000000} f n rate mem
    [ -s "$DATA/gas_10000000.in" ] || tools/gen 10000000 --fraction 0.2 --speed 0.5 --steps 20 > "$DATA/gas_10000000.in"
    [ -s "$DATA/dense_10000000.in" ] || tools/gen 10000000 --fraction 0.4 --speed 0.5 --steps 20 > "$DATA/dense_10000000.in"
    printf '32000\n20000\n1\n200\nperf\n' > "$DATA/random_32000.in"
    printf '1000000\n20000\n1\n10\nperf\n' > "$DATA/random_1000000.in"
    if [ "${GOALS_BIG:-0}" = 1 ]; then
        [ -s "$DATA/gas_100000000.in" ] || tools/gen 100000000 --fraction 0.2 --speed 0.5 --steps 10 > "$DATA/gas_100000000.in"
        scenes="$scenes gas_100000000"
    fi
    for f in $scenes; do
        [ "$f" = none ] && continue
        n=${f#*_}
        if [ "$n" -ge 100000000 ]; then # one run, output to /dev/null: its text alone is some 15 GB
            ./cuda "$DATA/$f.in" --stats > /dev/null 2> "$DATA/err" || true
            rate=$(sed -nE 's/.* ([0-9.e+]+) particle-steps\/s.*/\1/p' "$DATA/err")
        else
            rate=$(best_rate "$f" "$n" ./cuda "$DATA/$f.in")
        fi
        grep -E 'phase|round|window|refused|memory|keyed' "$DATA/err" | sed "s/^/# $f: /" >> "$CSV"
        case $f in
        gas_*) goal "$f step loop, particle-steps/s" "$rate" 1.2e10 ge ;;
        dense_*) goal "$f step loop, particle-steps/s" "$rate" 1e10 ge ;;
        random_32000) goal "$f (200 steps) step loop, particle-steps/s" "$rate" 3e8 ge ;;
        random_1000000) goal "$f (10 steps) step loop, particle-steps/s" "$rate" 5e8 ge ;;
        esac
        if [ -n "${BASE:-}" ] && [ "$n" -lt 100000000 ]; then
            NAME=cuda_base best_rate "$f" "$n" "$BASE/cuda" "$DATA/$f.in" | sed "s/^/# $f cuda_base best: /" >> "$CSV"
        fi
        case $f in gas_*)
            mem=$(peak_memory ./cuda "$DATA/$f.in" --quiet)
            goal "$f device memory, bytes a disk" "$(awk -v m="$mem" -v n="$n" 'BEGIN { printf "%.0f", m * 1048576 / n }')" 200 le ;;
        esac
    done
    too_big
    [ "${GOALS_SCENES:-}" = none ] && return
    # the whole process with text in and out: the gas of 1e7, 50 steps
    [ -s "$DATA/gas50_10000000.in" ] || tools/gen 10000000 --fraction 0.2 --speed 0.5 --steps 50 > "$DATA/gas50_10000000.in"
    ./cuda "$DATA/gas50_10000000.in" > /dev/null 2>&1
    local best # whole_best's, by bash's dynamic scope
    whole_best ./cuda
    goal "gas_10000000 S = 50, whole process with text in and out, seconds" "$best" 1.0 le
    if [ -n "${BASE:-}" ]; then
        whole_best "$BASE/cuda"
        echo "# gas_10000000 S = 50, whole process, cuda_base best: $best s" | tee -a "$CSV"
    fi
}

# A run the GPU cannot hold, 2e9 disks (some 300 GB) placed at random: refused as its input is read, with the
# size it needs (cuda_prepare). The placement alone would take minutes: the seconds to the refusal show it
# came first. Missed where the message, or an empty stdout, is not there.
too_big() {
    local t0 t1 secs
    printf '2000000000\n1000000\n1\n10\nperf\n' > "$DATA/too_big.in"
    t0=$(date +%s.%N)
    timeout 300 ./cuda "$DATA/too_big.in" --quiet > "$DATA/too_big.out" 2> "$DATA/err" || true
    t1=$(date +%s.%N)
    secs=$(awk -v t0="$t0" -v t1="$t1" 'BEGIN { printf "%.2f", t1 - t0 }')
    echo "# too_big: $(head -c 300 "$DATA/err")" | tee -a "$CSV"
    grep -q "disks need at least .* GB of GPU memory" "$DATA/err" && [ ! -s "$DATA/too_big.out" ] || secs=999
    goal "2e9 disks placed at random, refused with the size they need, seconds" "$secs" 10 le
}

# best: the best of 3 whole-process runs of PROG on the gas of 1e7 with S = 50, its 1.27 GB of output to a
# file (set, not printed: a failing run then stops the script, as set -e does outside a substitution).
# Each run writes a new file, the last one removed and the disk synced before the clock starts: the
# shell's truncation of the last run's file had been timed with the run (one H200 host, the same tree:
# 1.5 to 1.75 s over an old file, 0.79 s to a new one; bench/gpu_h100_goals.log)
whole_best() {
    local t0 t1
    best=999
    for _ in 1 2 3; do
        rm -f "$DATA/gas50.out"
        sync
        t0=$(date +%s.%N)
        "$1" "$DATA/gas50_10000000.in" --quiet > "$DATA/gas50.out"
        t1=$(date +%s.%N)
        best=$(awk -v a="$best" -v t0="$t0" -v t1="$t1" 'BEGIN { b = t1 - t0; printf "%.3f", (b < a) ? b : a }')
    done
}

# The move's memory streams alone (bench/cmd/streams.cu).
do_streams() {
    local nvcc=${NVCC:-nvcc}
    "$nvcc" -O2 ${CUDA_ARCH:--arch=native} bench/cmd/streams.cu -o "$OUT/streams" > "$OUT/streams_build.log" 2>&1 \
        || { tail -5 "$OUT/streams_build.log"; return 1; }
    machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)" | tee "$OUT/streams.log"
    "$OUT/streams" "${STREAMS_N:-10000000}" | tee -a "$OUT/streams.log"
}

case ${1:-all} in
check) do_check ;;
streams) do_streams ;;
goals) do_goals ;;
bytes) do_bytes ;;
memcheck) do_memcheck ;;
perf) do_perf ;;
profile) do_profile ;;
kernels) do_kernels ;;
targets) do_targets ;;
host) do_host ;;
big) do_big ;;
all) timeout 300 bash "$0" check || true; timeout 240 bash "$0" perf ;;
*) echo "usage: $0 check|memcheck|perf|host|big|profile|kernels|targets|goals|bytes|all" >&2; exit 2 ;;
esac
[ -f "$CSV" ] && tail -30 "$CSV" || true
