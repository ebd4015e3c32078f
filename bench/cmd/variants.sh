#!/usr/bin/env bash
# ./bench.sh variants: on a machine with an NVIDIA GPU, builds cuda.cu once per variant (VARIANTS: a list
# of NAME=FLAGS, the flags being -D macros of cuda.cu, commas for spaces) and, with BASE_REV, that
# revision's cuda (or with BASE_SRC=FILE, an earlier cuda.cu built on this tree's objects, where the copy
# has no git); times each on the same inputs (gas at area fraction 0.2, N = 1e7, 50 steps; with DENSE=1
# also at 0.4; the assignment's random scene at N = 32000, 200 steps, and at each N of RANDOM_N, 10
# steps; the gas at each N of GAS_N, 1000 steps below 1e6 disks, else 100), each program in turn RUNS
# times, checks that all print the same bytes, and keeps each one's phase times (--stats). SCENES replaces
# the first two (gas random; "random" alone, say). Results go to $OUT (default bench/tmp/variants).
set -euo pipefail
cd "$(dirname "$0")/../.."
. bench/cmd/lib.sh
OUT=${OUT:-bench/tmp/variants}
DATA=${DATA:-/tmp/gpu_variants}
RUNS=${RUNS:-2}
mkdir -p "$OUT" "$DATA/bin"
make -j"$(nproc)" cuda tools/gen > "$OUT/build.log" 2>&1 || { tail -20 "$OUT/build.log"; exit 1; }
machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$(nproc)"
progs=(./cuda)
objects=$(make_var BASE)
for v in ${VARIANTS:-}; do
    name=${v%%=*} flags=${v#*=}
    # shellcheck disable=SC2086
    nvcc -O2 --fmad=false -std=c++17 -gencode arch=compute_90,code=sm_90 -Xcompiler -ffp-contract=off \
        ${flags//,/ } cuda.cu $objects -o "$DATA/bin/$name" -lm > "$OUT/build_$name.log" 2>&1 &
    progs+=("$DATA/bin/$name")
done
if [ -n "${BASE_REV:-}" ]; then
    build_revision "$BASE_REV" "$DATA/base" "$OUT/build_base.log" &
    progs+=("$DATA/base/cuda")
elif [ -n "${BASE_SRC:-}" ]; then
    build_source "$BASE_SRC" "$DATA/base/cuda" "$OUT/build_base.log" &
    progs+=("$DATA/base/cuda")
    echo "# base: $BASE_SRC, sha256 $(sha256sum < "$BASE_SRC" | cut -c1-16)"
fi
wait
scenes=${SCENES:-gas random}
case " $scenes " in *" gas "*)
    [ -s "$DATA/gas.in" ] || tools/gen 10000000 --fraction 0.2 --speed 0.5 --steps 50 > "$DATA/gas.in" ;;
esac
printf '32000\n20000\n1\n200\nperf\n' > "$DATA/random.in"
if [ "${DENSE:-0}" = 1 ]; then
    [ -s "$DATA/dense.in" ] || tools/gen 10000000 --fraction 0.4 --speed 0.5 --steps 50 > "$DATA/dense.in"
    scenes="${scenes/gas/gas dense}"
    case " $scenes " in *" dense "*) ;; *) scenes="dense $scenes" ;; esac
fi
for n in ${GAS_N:-}; do # smaller gases, where a step's launches weigh more than its passes over memory
    steps=$(awk -v n="$n" 'BEGIN { print n < 1e6 ? 1000 : 100 }')
    [ -s "$DATA/gas_$n.in" ] || tools/gen "$n" --fraction 0.2 --speed 0.5 --steps "$steps" > "$DATA/gas_$n.in"
    scenes="$scenes gas_$n"
done
for n in ${RANDOM_N:-}; do
    printf '%s\n20000\n1\n10\nperf\n' "$n" > "$DATA/random_$n.in"
    scenes="$scenes random_$n"
done
for scene in $scenes; do
    for _ in $(seq "$RUNS"); do # the programs in turn, so that the machine's drift falls on all alike
        for p in "${progs[@]}"; do
            name=$(basename "$(dirname "$p")")/$(basename "$p")
            [ -x "$p" ] || continue
            "$p" "$DATA/$scene.in" > "$DATA/out" 2> "$DATA/err" || echo "$scene $name: FAILED: $(head -c 200 "$DATA/err")"
            echo "$scene $name: $(grep 'step loop' "$DATA/err" | sed -E 's/.*perf: //')"
        done
    done
    for p in "${progs[@]}"; do
        name=$(basename "$(dirname "$p")")/$(basename "$p")
        if [ ! -x "$p" ]; then
            echo "$scene $name: NOT BUILT (see $OUT/build_*.log)"
            continue
        fi
        "$p" "$DATA/$scene.in" --stats > "$DATA/out_$scene" 2> "$DATA/err"
        grep -E 'phase|pair tests|faster|undecided|one slice found|device memory' "$DATA/err" | sed "s|^|$scene $name: |" >> "$OUT/phases.log"
        if [ "$p" = ./cuda ]; then cp "$DATA/out_$scene" "$DATA/ref_$scene"; fi
        cmp -s "$DATA/out_$scene" "$DATA/ref_$scene" || echo "$scene $name: OUTPUT DIFFERS from ./cuda"
    done
done | tee "$OUT/timings.log"
cat "$OUT/phases.log"
