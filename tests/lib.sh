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
    local name=$1 pattern=$2
    shift 2
    "$@" > "$TMP/out" 2> "$TMP/err" < "${STDIN_FILE:-/dev/null}"
    refusal_verdict "$name" "$pattern" $? "$TMP/out" "$TMP/err"
}

# refusal_verdict NAME PATTERN STATUS OUT ERR: a refused run's verdict (non-zero STATUS, OUT empty, ERR
# one line matching PATTERN), for expect_error and expect_mpi_error.
refusal_verdict() {
    local name=$1 pattern=$2 rc=$3 out=$4 err=$5 problems=""
    [ "$rc" -ne 0 ] || problems="exit status 0;"
    [ ! -s "$out" ] || problems="$problems $(wc -c < "$out") bytes on stdout;"
    [ "$(wc -l < "$err")" -eq 1 ] || problems="$problems $(wc -l < "$err") stderr lines;"
    grep -Eq -e "$pattern" "$err" || problems="$problems message '$(head -c 200 "$err")';"
    if [ -z "$problems" ]; then pass "$name"; else fail "$name" "$problems"; fi
}

# exact_events ERR: the event count of a --stats run's last line ("..., N events")
exact_events() { sed -n 's/.* \([0-9]*\) events$/\1/p' "$1"; }
# exact_split ERR: omp --exact --stats' events "IN_STRIPS IN_BANDS IN_SEQUENTIAL_WINDOWS" ("x x x" if none)
exact_split() {
    local split
    split=$(sed -n 's/.*events: \([0-9]*\) in the strips .*, \([0-9]*\) among the [0-9]* disks tainted.*, \([0-9]*\) in sequential windows.*/\1 \2 \3/p' "$1")
    echo "${split:-x x x}"
}

# ---- 8-bit cell counts (t_80, t_87) ----
# crowd_scene NAME MODE: a scene whose cells pass 255 disks, its input on stdout. "point": 300 of 1500 disks
# start on one point; "ring": 1200 of 2700 tiny disks converge on one point.
crowd_scene() {
    awk -v name="$1" -v mode="$2" 'BEGIN {
        n = name == "point" ? 1500 : 2700; print n; print 200; print name == "point" ? 1 : 0.0002; print 12
        print mode; srand(name == "point" ? 21 : 5)
        for (i = 0; i < n; i++) {
            if (name == "point" && i < 300) {
                x = 100; y = 100; vx = rand() - 0.5; vy = rand() - 0.5
            } else if (name == "ring" && i < 1200) {
                a = 2 * 3.14159265358979 * i / 1200; x = 100.37 + 4.7 * cos(a); y = 100.41 + 4.7 * sin(a)
                vx = -cos(a); vy = -sin(a)
            } else {
                x = 2 + rand() * 196; y = 2 + rand() * 196; vx = rand() - 0.5; vy = rand() - 0.5
            }
            printf "%d %.9f %.9f %.9f %.9f\n", i, x, y, vx, vy
        } }'
}

# ---- mpi (t_86, t_78, t_88) ----
have_mpi() { command -v mpirun > /dev/null 2>&1 && [ -x ./mpi ]; }
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
    # a job ended by bad input (rank 0 exits, the others wait for it): its ranks killed at once, not
    # after the second Open MPI gives them to die (1.2 s against 0.2 s a refused run here)
    export OMPI_MCA_odls_base_sigkill_timeout=0
    MPIRUN=(mpirun)
    mpirun -q -np 1 true > /dev/null 2>&1 && MPIRUN+=(-q)
}

# run_mpi P T ARGS...: mpi on P ranks of T threads (after mpi_env).
run_mpi() {
    local p=$1 t=$2
    shift 2
    "${MPIRUN[@]}" -np "$p" --oversubscribe ./mpi "$@" --threads "$t"
}

# mpi_stdin FILE COMMAND...: COMMAND, an mpirun line, with its standard input from FILE, its output and
# status passed on. Open MPI 4's mpirun now and then crashes itself while it forwards a file on its
# standard input (SIGSEGV in orte_iof_hnp_read_local_handler, about 1 run in 40 on 2 busy cores; the
# program's ranks are not at fault): such a run is taken again, twice at most; any other failure stands.
mpi_stdin() {
    local in=$1 try rc
    shift
    for try in 1 2 3; do
        "$@" < "$in" > "$TMP/stdin.out" 2> "$TMP/stdin.err"
        rc=$?
        grep -q orte_iof_hnp_read_local_handler "$TMP/stdin.err" || break
    done
    cat "$TMP/stdin.out"
    cat "$TMP/stdin.err" >&2
    return "$rc"
}

# expect_mpi_error NAME PATTERN ARGS...: expect_error for mpi on 3 ranks, but for mpirun's own notice
# of the failed job, which an mpirun without -q (Open MPI 5) adds: there only the program's lines
# ("mpi: ...") are counted.
expect_mpi_error() {
    local name=$1 pattern=$2 rc
    shift 2
    "${MPIRUN[@]}" -np 3 --oversubscribe ./mpi "$@" > "$TMP/eout" 2> "$TMP/eerr" < /dev/null
    rc=$?
    [ "${#MPIRUN[@]}" -eq 2 ] || { grep '^mpi: ' "$TMP/eerr" > "$TMP/eerr1"; mv "$TMP/eerr1" "$TMP/eerr"; }
    refusal_verdict "$name" "$pattern" "$rc" "$TMP/eout" "$TMP/eerr"
}

# ---- --checkpoint kill trials (t_58, t_88): C is the file's folder, CK_KILLS counts the kills ----
# ck_start SEGMENT MAXDELAY COMMAND...: runs COMMAND (stdout $C/seg.SEGMENT, stderr .err; an argument
# @OUT@ becomes $C/seg.SEGMENT, for mpi --output) in the background in a session of its own, waits for
# its first checkpoint (a resumed run: for its "resuming" line), sleeps a random time up to MAXDELAY
# seconds and kills it with SIGKILL, with every process of its session (mpirun's ranks live in process
# groups of their own). KILLED=1 if the kill found it running; CK_STATUS: its exit status (137 where
# the kill found it; 128 + N: another signal N ended it).
ck_start() {
    local seg=$1 max=$2 pid delay others
    shift 2
    rm -f "$C/seg.$seg.err" # not an earlier trial's "resuming" line while the shell starts this one
    setsid "${@//@OUT@/$C/seg.$seg}" > "$C/seg.$seg" 2> "$C/seg.$seg.err" &
    pid=$!
    if [ "$seg" = 0 ]; then
        while kill -0 "$pid" 2> /dev/null && [ ! -e "$C/run.ck" ]; do sleep 0.01; done
    else
        while kill -0 "$pid" 2> /dev/null && ! grep -qs resuming "$C/seg.$seg.err"; do sleep 0.01; done
    fi
    delay=$(awk -v s="$RANDOM" -v m="$max" 'BEGIN { srand(s); printf "%.3f", rand() * m }')
    sleep "$delay"
    others=$(ps -o pid= -s "$pid" 2> /dev/null | grep -v "^ *$pid\$")
    if kill -9 "$pid" 2> /dev/null; then KILLED=1; else KILLED=0; fi
    # shellcheck disable=SC2086
    [ -z "$others" ] || kill -9 $others 2> /dev/null
    wait "$pid" 2> /dev/null
    CK_STATUS=$?
    # none of them may still write when the next run starts
    # shellcheck disable=SC2086
    while [ -n "$others" ] && ps -o stat= -p "$(echo $others | tr ' ' ,)" 2> /dev/null | grep -qv Z; do sleep 0.01; done
}

# ck_trial NAME REFERENCE N MODE EVERY MAXDELAY "RUN" "RESUME1" ["RESUME2" ...]: RUN (with --quiet,
# --checkpoint and --checkpoint-every EVERY added) is killed; each RESUME but the last is run with
# --resume and --checkpoint on the same file and killed too; the last runs to the end. The pieces of
# stdout (print mode: each up to its successor's checkpoint step; perf: step 0, then the last) must
# make up REFERENCE (an argument @OUT@ of a command: that piece's file). A run that ends before its
# kill is tried again with half the delay.
ck_trial() {
    local name=$1 ref=$2 n=$3 mode=$4 every=$5 max=$6 run=$7 seg try k prev=0 cmd problems=""
    shift 7
    local resumes=("$@")
    for try in 1 2 3 4 5; do
        rm -f "$C/run.ck" "$C/run.ck.tmp"
        # shellcheck disable=SC2086
        ck_start 0 "$max" $run --quiet --checkpoint "$C/run.ck" --checkpoint-every "$every"
        [ "$KILLED" = 1 ] && break
        max=$(awk -v m="$max" 'BEGIN { print m / 2 }')
    done
    if [ "$KILLED" != 1 ]; then
        fail "$name" "the run ended before each of 5 kills: $(head -c 200 "$C/seg.0.err")"
        return
    fi
    CK_KILLS=$((CK_KILLS + 1))
    : > "$C/joined"
    for seg in $(seq 1 ${#resumes[@]}); do
        cmd=${resumes[$((seg - 1))]}
        if [ "$seg" -lt ${#resumes[@]} ]; then
            # shellcheck disable=SC2086
            ck_start "$seg" "$max" $cmd --resume "$C/run.ck" --checkpoint "$C/run.ck" --checkpoint-every "$every"
            [ "$KILLED" = 1 ] && CK_KILLS=$((CK_KILLS + 1))
        else
            cmd=${cmd//@OUT@/$C/seg.$seg}
            # shellcheck disable=SC2086
            $cmd --resume "$C/run.ck" > "$C/seg.$seg" 2> "$C/seg.$seg.err"
            CK_STATUS=$?
        fi
        k=$(sed -n 's/.*resuming .* at step \([0-9]*\) of .*/\1/p' "$C/seg.$seg.err")
        if [ -z "$k" ]; then
            problems="resume $seg ($cmd, exit status $CK_STATUS): $(head -c 200 "$C/seg.$seg.err")"
            break
        fi
        # the previous piece: its lines up to step k
        if [ "$mode" = print ]; then
            head -n $(((k - prev + (seg == 1)) * n)) "$C/seg.$((seg - 1))" >> "$C/joined"
        elif [ "$seg" = 1 ]; then
            head -n "$n" "$C/seg.0" >> "$C/joined"
        fi
        problems="$problems k$seg=$k"
        prev=$k
    done
    cat "$C/seg.${#resumes[@]}" >> "$C/joined"
    if cmp -s "$C/joined" "$ref"; then
        pass "$name:$problems"
    else
        fail "$name" "$problems: the joined output differs ($(cmp "$C/joined" "$ref" 2>&1 | head -1))"
    fi
}
