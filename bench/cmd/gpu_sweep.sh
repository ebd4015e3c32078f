#!/usr/bin/env bash
# ./bench.sh gpu-sweep: the bench.sh sweeps of REPORT.md 4.2 on a machine with an NVIDIA GPU, in two
# parts that each fit a 10-minute slot. Results (CSV, logs) go to $OUT (default bench/tmp/gpu).
#   ./bench.sh gpu-sweep small   make test (beside it: the 1e7 scene files), omp on 16 threads and cuda
#                              over all scenes up to N = 1e6, omp thread scaling, cuda at N = 1e7
#   ./bench.sh gpu-sweep cuda    cuda alone: all scenes up to N = 1e6, and N = 1e7 (after a change to cuda.cu)
#   ./bench.sh gpu-sweep big     make test (beside it: the 1e8 scene files), cuda at N = 1e8 on the four
#                              scenes with particle lines (4.5 GB each)
# Both end by packing everything into $OUT/results.tgz (few files travel back easily).
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-bench/tmp/gpu}
mkdir -p "$OUT"
export REVISION=${REVISION:-$(git rev-parse --short=12 HEAD 2>/dev/null || echo unknown)}
FILE_SCENES="gas20 gas05 gas40 dilute"

stamp() { echo "[$(date +%T)] $*"; }

build() { # TARGETS...
    make -j"$(nproc)" "$@" > "$OUT/build.log" 2>&1 || { tail -20 "$OUT/build.log"; exit 1; }
}

pack() {
    (cd "$OUT" && tar czf results.tgz --exclude results.tgz ./*.csv ./*.log)
    find "$OUT" -maxdepth 1 -type f ! -name results.tgz -delete
}

# prepare N: the scene files with particle lines at N, one generator per scene, side by side
prepare() {
    local s
    for s in $FILE_SCENES; do
        ./bench.sh --prepare --backends cuda --scenes "$s" --sizes "$1" -o "$OUT/prepare_$s.csv" 2>> "$OUT/prepare.log" &
    done
    wait
}

case ${1:-} in
small | big | cuda) trap pack EXIT ;; # also when a time limit stops the sweep: what ran comes back
esac
case ${1:-} in
small)
    build all seq_san
    stamp "make test, and the N = 1e7 scenes generated beside it"
    prepare 1e7 &
    make test > "$OUT/test.log" 2>&1 || true
    wait
    tail -3 "$OUT/test.log"
    stamp "cuda, N = 1e7"
    ./bench.sh --backends cuda --sizes 1e7 --steps 100 --scenes "$FILE_SCENES" --repeats 3 \
        -o "$OUT/gpu_h100_1e7.csv" 2> "$OUT/sweep_1e7.log"
    ./bench.sh --backends cuda --sizes 1e7 --steps 2 --scenes random --repeats 3 \
        -o "$OUT/gpu_h100_1e7_random.csv" 2>> "$OUT/sweep_1e7.log"
    stamp "omp (16 threads) and cuda, all scenes, N = 1e3 .. 1e6"
    ./bench.sh --backends omp,cuda --threads 16 --sizes 1e3,1e4,1e5,1e6 --repeats 3 --target 0.1 \
        -o "$OUT/gpu_h100.csv" 2> "$OUT/sweep_small.log"
    stamp "omp thread scaling"
    ./bench.sh --backends omp --scenes gas20,random --sizes 1e4,1e5,1e6 --threads 1,2,4,8,16 --repeats 3 \
        --target 0.2 --max-step 1 -o "$OUT/gpu_h100_threads.csv" 2> "$OUT/sweep_threads.log"
    stamp done
    ;;
big)
    build all seq_san
    stamp "make test, and the N = 1e8 scenes generated beside it"
    prepare 1e8 &
    make test > "$OUT/test.log" 2>&1 || true
    wait
    tail -3 "$OUT/test.log"
    df -h . | tail -1
    stamp "cuda, N = 1e8"
    ./bench.sh --backends cuda --sizes 1e8 --steps 20 --scenes "$FILE_SCENES" --repeats 3 \
        -o "$OUT/gpu_h100_1e8.csv" 2> "$OUT/sweep_1e8.log"
    stamp done
    ;;
cuda)
    build cuda tools/gen
    stamp "the N = 1e7 scenes"
    prepare 1e7
    stamp "cuda, all scenes, N = 1e3 .. 1e6"
    ./bench.sh --backends cuda --sizes 1e3,1e4,1e5,1e6 --repeats 3 --target 0.1 \
        -o "$OUT/gpu_h100_cuda.csv" 2> "$OUT/sweep_cuda.log"
    stamp "cuda, N = 1e7"
    ./bench.sh --backends cuda --sizes 1e7 --steps 100 --scenes "$FILE_SCENES" --repeats 3 \
        -o "$OUT/gpu_h100_1e7.csv" 2> "$OUT/sweep_1e7.log"
    stamp done
    ;;
*)
    echo "usage: $0 small|big|cuda" >&2
    exit 2
    ;;
esac
