# tests/lib.sh: the helpers every test file uses. Sourced by tests/run.sh, never run alone.
# Each check prints one PASS/FAIL/SKIP line; run.sh prints the totals.

TMP=${TMP:-tests/tmp}
mkdir -p "$TMP"
PASSED=0 FAILED=0 SKIPPED=0

# SUITE=quick (make test) runs each file's small cases; SUITE=all (make test-all) every case.
all_suite() { [ "${SUITE:-quick}" = all ]; }

pass() { PASSED=$((PASSED + 1)); echo "PASS $1"; }
fail() { FAILED=$((FAILED + 1)); echo "FAIL $1${2:+: $2}"; }
skip() { SKIPPED=$((SKIPPED + 1)); echo "SKIP $1${2:+: $2}"; }

# The backends this machine can run: seq and omp always, cuda where it was built and a GPU answers.
have_gpu() { [ -x ./cuda ] && command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; }

# same_bytes NAME EXPECTED_FILE COMMAND...: runs COMMAND, compares its stdout with EXPECTED_FILE.
same_bytes() {
    local name=$1 expected=$2
    shift 2
    if "$@" > "$TMP/out" 2> "$TMP/err"; then
        if cmp -s "$TMP/out" "$expected"; then
            pass "$name"
        else
            fail "$name" "output differs from $expected ($(cmp "$TMP/out" "$expected" 2>&1 | head -1))"
        fi
    else
        fail "$name" "exit $?: $(head -c 300 "$TMP/err")"
    fi
}

# on_backends NAME EXPECTED_FILE ARGS...: same_bytes for seq, omp at 1, 2, 3 and 7 threads, and cuda
# (SKIP without a GPU), each run as ./PROG ARGS --quiet.
on_backends() {
    local name=$1 expected=$2 t
    shift 2
    same_bytes "$name seq" "$expected" ./seq "$@" --quiet
    for t in 1 2 3 7; do
        same_bytes "$name omp $t threads" "$expected" ./omp "$@" --quiet --threads "$t"
    done
    if ! have_gpu; then
        skip "$name cuda" "no GPU"
    else
        same_bytes "$name cuda" "$expected" ./cuda "$@" --quiet
    fi
}

# threads_mismatch "THREADS" REF COMMAND...: runs COMMAND --threads T for each T of THREADS and prints
# " T:exit(message)" or " T:differs" for each run that fails or whose stdout is not REF (nothing if all
# match). omp's thread-count tests (t_70, t_75) build their verdicts on it.
threads_mismatch() {
    local threads=$1 ref=$2 t
    shift 2
    for t in $threads; do
        if ! "$@" --threads "$t" > "$TMP/threads.out" 2> "$TMP/threads.err"; then
            printf ' %s' "$t:exit($(head -c 200 "$TMP/threads.err"))"
        elif ! cmp -s "$TMP/threads.out" "$ref"; then
            printf ' %s' "$t:differs"
        fi
    done
}

# diag_lattice K STEPS: a print-mode scene of K x K disks of radius 1 on a jittered lattice, velocities
# (+-0.6, +-0.6): its collisions leave velocity components above the largest at the window's start,
# which stops omp --exact's parallel windows (omp_exact.c).
diag_lattice() {
    awk -v k="$1" -v steps="$2" 'BEGIN { srand(7); s = 2.6; printf "%d\n%.10g\n1\n%d\nprint\n", k * k, k * s + 0.4, steps
        for (a = 0; a < k; a++) for (b = 0; b < k; b++)
            printf "%d %.10g %.10g %.10g %.10g\n", a * k + b, 1.2 + a * s + 0.3 * rand(), 1.2 + b * s + 0.3 * rand(),
                   rand() < 0.5 ? -0.6 : 0.6, rand() < 0.5 ? -0.6 : 0.6 }'
}
# The programs that must reject bad input the same way: seq, omp, and cuda where a GPU answers.
backend_list() {
    echo seq omp
    if have_gpu; then echo cuda; fi
}

# expect_error NAME PATTERN COMMAND...: COMMAND (stdin from STDIN_FILE, else /dev/null) must exit
# non-zero with nothing on stdout and exactly one stderr line matching PATTERN (grep -E): the rule for
# every refused input or option.
expect_error() {
    local name=$1 pattern=$2 rc problems=""
    shift 2
    "$@" > "$TMP/out" 2> "$TMP/err" < "${STDIN_FILE:-/dev/null}"
    rc=$?
    [ "$rc" -ne 0 ] || problems="exit status 0;"
    [ ! -s "$TMP/out" ] || problems="$problems $(wc -c < "$TMP/out") bytes on stdout;"
    [ "$(wc -l < "$TMP/err")" -eq 1 ] || problems="$problems $(wc -l < "$TMP/err") stderr lines;"
    grep -Eq -e "$pattern" "$TMP/err" || problems="$problems message '$(head -c 200 "$TMP/err")';"
    if [ -z "$problems" ]; then pass "$name"; else fail "$name" "$problems"; fi
}

# ---- mpi (t_86, t_78) ----
# mpi_env: mpirun's settings here (as root, more ranks than cores), and MPIRUN, its command.
mpi_env() {
    export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
    # more ranks than cores: a rank waiting in MPI yields its core (Open MPI busy-polls by default, and
    # then one rank's wait takes the core its neighbour needs: 3 ranks on 2 cores 20x slower here)
    export OMPI_MCA_mpi_yield_when_idle=1
    # and the ranks' OpenMP threads sleep at a barrier rather than spin (3 ranks of 2 threads on 2
    # cores: 40x slower spinning)
    export OMP_WAIT_POLICY=passive
    # one machine: shared memory through ob1 (the default pml probes UCX's devices first, 0.2 s a launch)
    export OMPI_MCA_pml=ob1
    MPIRUN=(mpirun)
    mpirun -q -np 1 true > /dev/null 2>&1 && MPIRUN+=(-q)
}

# run_mpi P T ARGS...: mpi on P ranks of T threads (after mpi_env).
run_mpi() {
    local p=$1 t=$2
    shift 2
    "${MPIRUN[@]}" -np "$p" --oversubscribe ./mpi "$@" --threads "$t"
}

# expect_mpi_error NAME PATTERN ARGS...: expect_error for mpi on 3 ranks, but for mpirun's own notice
# of the failed job, which an mpirun without -q (Open MPI 5) adds: there only the program's lines
# ("mpi: ...") are counted.
expect_mpi_error() {
    local name=$1 pattern=$2 rc problems=""
    shift 2
    "${MPIRUN[@]}" -np 3 --oversubscribe ./mpi "$@" > "$TMP/eout" 2> "$TMP/eerr" < /dev/null
    rc=$?
    [ "${#MPIRUN[@]}" -eq 2 ] || { grep '^mpi: ' "$TMP/eerr" > "$TMP/eerr1"; mv "$TMP/eerr1" "$TMP/eerr"; }
    [ "$rc" -ne 0 ] || problems="exit status 0;"
    [ ! -s "$TMP/eout" ] || problems="$problems $(wc -c < "$TMP/eout") bytes on stdout;"
    [ "$(wc -l < "$TMP/eerr")" -eq 1 ] || problems="$problems $(wc -l < "$TMP/eerr") stderr lines;"
    grep -Eq -e "$pattern" "$TMP/eerr" || problems="$problems message '$(head -c 200 "$TMP/eerr")';"
    if [ -z "$problems" ]; then pass "$name"; else fail "$name" "$problems"; fi
}
