# ThreadSanitizer on omp (make omp_tsan: clang -fsanitize=thread with LLVM's OpenMP runtime, whose
# Archer tool tells the sanitizer about OpenMP's barriers and locks): at 3 threads, on fast, mixed,
# dense, print, --substeps and --exact scenes (--exact: strips, merged bands, windows stopped and run
# again, the periodic box's strips that wrap), with each broad phase forced as well as chosen, the
# random placement and checkpoints every step (make test leaves out seven of the scenes); any
# report of a race fails, and so does a changed output (it must stay seq's). SKIP only where clang,
# libomp or Archer is missing (.ci/run installs them).
T=$TMP/tsan
mkdir -p "$T"
tsan_skip=""
if ! command -v "${TSAN_CC:-clang}" >/dev/null 2>&1; then
    tsan_skip="no clang"
elif ! make -s omp_tsan > "$T/build.log" 2>&1; then
    tsan_skip="omp_tsan does not build (libomp-dev missing?): $(head -c 200 "$T/build.log")"
else
    resource=$("${TSAN_CC:-clang}" -print-resource-dir)
    archer=${resource%/clang/*}/libarcher.so
    [ -f "$archer" ] || tsan_skip="no Archer library at $archer"
fi

# tsan_run NAME INPUT BROAD [OPTIONS]: omp_tsan at 3 threads with --broad BROAD and OPTIONS (and
# $OMP_ONLY, options seq has not) must print seq's bytes (seq with OPTIONS) and report nothing
tsan_run() {
    local name=$1 in=$2 broad=$3
    shift 3
    if ! ./seq "$in" --quiet "$@" > "$T/ref" 2> "$T/err"; then
        fail "tsan/$name seq" "$(head -c 200 "$T/err")"
        return
    fi
    # shellcheck disable=SC2086
    OMP_TOOL_LIBRARIES=$archer TSAN_OPTIONS="ignore_noninstrumented_modules=1 halt_on_error=1 exitcode=66" \
        ./omp_tsan "$in" --quiet --threads 3 --broad "$broad" ${OMP_ONLY:-} "$@" > "$T/out" 2> "$T/err"
    local rc=$?
    if grep -q "ThreadSanitizer" "$T/err"; then
        fail "tsan/$name" "$(grep -m1 -A3 "WARNING: ThreadSanitizer" "$T/err" | tr '\n' ' ' | head -c 300)"
    elif [ "$rc" -ne 0 ]; then
        fail "tsan/$name" "exit $rc: $(head -c 200 "$T/err")"
    elif ! cmp -s "$T/out" "$T/ref"; then
        fail "tsan/$name" "output differs from seq"
    else
        pass "tsan/$name: no race at 3 threads, seq's bytes"
    fi
}

if [ -n "$tsan_skip" ]; then
    skip "tsan" "$tsan_skip"
else
    tools/gen 400 --assignment --L 2000 --steps 6 > "$T/fast.in"
    tools/gen 1500 --fraction 0.2 --speed 0.5 --fast 0.02 --steps 5 > "$T/mixed.in"
    tools/gen 600 --r 5 --fraction 0.3 --speed 4 --steps 6 > "$T/dense.in"
    tools/gen 300 --fraction 0.2 --speed 2 --steps 6 --mode print > "$T/print.in"
    tools/gen 1200 --fraction 2 --overlap --speed 0.5 --steps 2 > "$T/rounds.in"
    tools/gen 3000 --assignment --L 6000 --steps 3 > "$T/aside.in" # chooses beside the moves (choose_move)
    tsan_run fast "$T/fast.in" auto
    all_suite && tsan_run "fast --broad grid" "$T/fast.in" grid
    all_suite && tsan_run mixed "$T/mixed.in" auto
    tsan_run "mixed --broad paths" "$T/mixed.in" paths
    tsan_run "dense --broad mixed" "$T/dense.in" mixed
    tsan_run "the choice beside the moves" "$T/aside.in" auto
    OMP_ONLY="--keep 1" tsan_run "mixed --keep 1 (steps found again)" "$T/mixed.in" auto
    all_suite && tsan_run dense "$T/dense.in" auto
    all_suite && tsan_run print "$T/print.in" auto
    tsan_run "print --substeps 4" "$T/print.in" auto --substeps 4
    all_suite && tsan_run "print --exact" "$T/print.in" auto --exact
    tools/gen 1000 --fraction 0.5 --speed 1 --steps 3 --periodic > "$T/periodic.in"
    tsan_run "periodic --exact --pressure (strips that wrap, the band over the edge)" "$T/periodic.in" auto \
        --periodic --exact --pressure
    all_suite && tsan_run "periodic --broad paths" "$T/periodic.in" paths --periodic
    tsan_run "rounds --exact --pressure (bands merged)" "$T/rounds.in" auto --exact --pressure
    diag_lattice 24 3 > "$T/lattice.in"
    tsan_run "lattice --exact (windows stopped and run again)" "$T/lattice.in" auto --exact
    tsan_run "rounds of the parallel choice" "$T/rounds.in" auto
    # the random placement's windows on all threads (20000 disks: windows of several tasks)
    printf '20000\n20000\n1\n2\nperf\n' > "$T/placed.in"
    tsan_run "random placement in windows" "$T/placed.in" auto
    # a checkpoint inside the parallel region, every step, in print and perf mode
    tsan_run "print --checkpoint every step" "$T/print.in" auto --checkpoint "$T/ck" --checkpoint-every 1
    all_suite && tsan_run "dense --checkpoint every step" "$T/dense.in" auto --checkpoint "$T/ck" --checkpoint-every 1
fi
