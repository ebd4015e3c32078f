#!/usr/bin/env bash
# tools/gpu_run.sh: on a machine with an NVIDIA GPU, builds everything, checks cuda against seq and
# times cuda against omp on the same inputs. Logs and a CSV go to $OUT (default bench/tmp).
#   tools/gpu_run.sh check   build, make test, compute-sanitizer memcheck on a small scene
#   tools/gpu_run.sh perf    timings: fixed-density gas (N = 1e6, 1e7) and the assignment's random scene
#   tools/gpu_run.sh big     the gas at N = 1e8 (input generated and parsed on the host: minutes)
#   tools/gpu_run.sh all     check, then perf
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-bench/tmp}
mkdir -p "$OUT"
THREADS=${THREADS:-16}
GAS_STEPS=${GAS_STEPS:-50}
RANDOM_STEPS=${RANDOM_STEPS:-200}
CSV=$OUT/timings.csv
DATA=${DATA:-/tmp/gpu_run}
mkdir -p "$DATA"

provenance() {
    echo "git $(cat REVISION 2>/dev/null || git rev-parse --short HEAD 2>/dev/null || echo none), $(nvcc --version | tail -1)," \
        "$(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader), $(nproc) cores"
}

# time_one LABEL N PROGRAM ARGS...: one run, step-loop time from the program's own stderr line.
time_one() {
    local label=$1 n=$2 prog=$3
    shift 3
    local err=$DATA/err
    if ! "$prog" "$@" > "$DATA/$label.$(basename "$prog").out" 2> "$err"; then
        echo "$label,$(basename "$prog"),$n,FAILED: $(head -c 200 "$err")" | tee -a "$CSV"
        return
    fi
    local line secs ps
    line=$(grep -E "step loop" "$err" | tail -1)
    secs=$(echo "$line" | sed -E 's/.* ([0-9.]+) s step loop.*/\1/')
    ps=$(echo "$line" | sed -E 's/.* ([0-9.e+]+) particle-steps\/s.*/\1/')
    echo "$label,$(basename "$prog"),$n,$secs,$ps,$(grep -E 'pair tests' "$err" | sed -E 's/.*: //' || true)" \
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
    local san
    san=$(command -v compute-sanitizer || echo /usr/local/cuda/bin/compute-sanitizer)
    if [ -x "$san" ]; then
        tools/gen 3000 --fraction 0.3 --speed 2 --steps 5 --seed 11 > "$DATA/san.in"
        printf '2000\n20000\n1\n4\nprint\n' > "$DATA/san_random.in"
        for f in san san_random; do
            "$san" --tool memcheck --leak-check full --error-exitcode 9 --log-file "$OUT/memcheck_$f.log" \
                ./cuda "$DATA/$f.in" --quiet > "$DATA/$f.out" && echo "memcheck $f: clean" \
                || { echo "memcheck $f: ERRORS"; tail -20 "$OUT/memcheck_$f.log"; }
            ./seq "$DATA/$f.in" --quiet > "$DATA/$f.seq"
            cmp -s "$DATA/$f.seq" "$DATA/$f.out" && echo "memcheck $f output == seq" || echo "memcheck $f output DIFFERS"
        done
    else
        echo "compute-sanitizer not found"
    fi
}

do_perf() {
    echo "# $(provenance)" >> "$CSV"
    echo "label,program,N,seconds,particle_steps_per_s,stats" >> "$CSV"
    for n in 1000000 10000000; do
        [ -s "$DATA/gas_$n.in" ] || tools/gen $n --fraction 0.2 --speed 0.5 --steps $GAS_STEPS > "$DATA/gas_$n.in"
        ./cuda "$DATA/gas_$n.in" > /dev/null 2>&1 # warm-up, discarded
        time_one gas_$n $n ./cuda "$DATA/gas_$n.in" --stats
        time_one gas_$n $n ./cuda "$DATA/gas_$n.in" --stats
    done
    # omp beside cuda on a gas small enough for an all-pairs omp
    tools/gen 20000 --fraction 0.2 --speed 0.5 --steps 20 > "$DATA/gas_20000.in"
    time_one gas_20000 20000 ./omp "$DATA/gas_20000.in" --threads "$THREADS" --stats
    time_one gas_20000 20000 ./cuda "$DATA/gas_20000.in" --stats
    same gas_20000 omp
    for n in 32000 1000000; do
        local s=$RANDOM_STEPS
        [ $n -gt 100000 ] && s=10
        printf '%s\n20000\n1\n%s\nperf\n' $n $s > "$DATA/random_$n.in"
        time_one random_$n $n ./cuda "$DATA/random_$n.in" --stats
        time_one random_$n $n ./cuda "$DATA/random_$n.in" --stats
    done
    printf '32000\n20000\n1\n10\nperf\n' > "$DATA/random10_32000.in"
    time_one random10_32000 32000 ./omp "$DATA/random10_32000.in" --threads "$THREADS" --stats
    time_one random10_32000 32000 ./cuda "$DATA/random10_32000.in" --stats
    same random10_32000 omp
    printf '32000\n20000\n1\n20\nprint\n' > "$DATA/random_print.in"
    time_one random_print 32000 ./cuda "$DATA/random_print.in"
}

do_big() {
    local n=100000000
    echo "# $(provenance)" >> "$CSV"
    tools/gen $n --fraction 0.2 --speed 0.5 --steps 10 | ./cuda - --stats 2> "$DATA/big.err" | tail -c 200
    cat "$DATA/big.err"
    echo "gas_$n,cuda,$n,$(grep 'step loop' "$DATA/big.err" | sed -E 's/.* ([0-9.]+) s step loop, ([0-9.e+]+).*/\1,\2/')" >> "$CSV"
}

# Kernel time per phase (nsys), for the gas and the random scene.
do_profile() {
    local nsys
    nsys=$(command -v nsys || ls /usr/local/cuda/bin/nsys /opt/nvidia/nsight-systems/*/bin/nsys 2>/dev/null | head -1 || true)
    [ -n "$nsys" ] || { echo "nsys not found"; return; }
    tools/gen 1000000 --fraction 0.2 --speed 0.5 --steps 20 > "$DATA/prof_gas.in"
    printf '32000\n20000\n1\n100\nperf\n' > "$DATA/prof_random.in"
    for f in prof_gas prof_random; do
        "$nsys" profile -o "$DATA/$f" --force-overwrite true ./cuda "$DATA/$f.in" --quiet > /dev/null 2>&1
        "$nsys" stats --report cuda_gpu_kern_sum,cuda_gpu_mem_time_sum --format csv "$DATA/$f.nsys-rep" 2>/dev/null \
            | cut -d, -f1-4,9 | head -40 | tee "$OUT/$f.csv"
    done
}

case ${1:-all} in
check) do_check ;;
perf) do_perf ;;
profile) do_profile ;;
big) do_big ;;
all) timeout 300 bash "$0" check || true; timeout 240 bash "$0" perf ;;
*) echo "usage: $0 check|perf|big|all" >&2; exit 2 ;;
esac
[ -f "$CSV" ] && tail -30 "$CSV" || true
