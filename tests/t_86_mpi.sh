# mpi (mpi.c): the same bytes as seq for several rank counts, oversubscribed on this machine:
# - the bundled inputs at 2 and 3 ranks (four of them at 8), the worked examples at 1 and 4, the hard
#   cases at 3, generated scenes (fast, mixed, dense, print, overlapping, three disks) at 2, 5 and 8,
#   --substeps 2 at 3 ranks;
# - bad input and unsupported options refused with one stderr line (mpirun -q), nothing on stdout and
#   mpirun's exit status non-zero.
# SKIP where mpirun or ./mpi is missing (.ci/run installs OpenMPI).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
M=$TMP/mpi
mkdir -p "$M"
if ! command -v mpirun > /dev/null 2>&1 || [ ! -x ./mpi ]; then
    skip "mpi" "no mpirun or no ./mpi (apt-get install openmpi-bin libopenmpi-dev, then make)"
else
    ranks() { # NAME EXPECTED "P..." ARGS...: mpi at each rank count must print EXPECTED's bytes
        local name=$1 expected=$2 counts=$3 p bad=""
        shift 3
        for p in $counts; do
            if ! mpirun -q -np "$p" --oversubscribe ./mpi "$@" --quiet > "$M/out" 2> "$M/err"; then
                bad="$bad $p:exit($(head -c 150 "$M/err"))"
            elif ! cmp -s "$M/out" "$expected"; then
                bad="$bad $p:differs"
            fi
        done
        if [ -z "$bad" ]; then pass "mpi $name: seq's bytes at $counts ranks"; else fail "mpi $name" "$bad"; fi
    }
    for f in inputs/*.in; do
        b=$(basename "$f" .in)
        counts="2 3"
        case $b in random_1000_perf | dense_gas | overlapping_print | course_testcase2) counts="2 3 8" ;; esac
        ranks "inputs/$b" "outputs/$b.out" "$counts" "$f"
    done
    for f in tests/cases/*.in; do ranks "cases/$(basename "$f" .in)" "${f%.in}.out" "1 4" "$f"; done
    for f in tests/hard/*.in; do
        [ -f "${f%.in}.out" ] && ranks "hard/$(basename "$f" .in)" "${f%.in}.out" "3" "$f"
    done
    k=0
    while read -r args; do
        k=$((k + 1))
        # shellcheck disable=SC2086
        tools/gen $args > "$M/gen$k.in"
        ./seq "$M/gen$k.in" --quiet > "$M/gen$k.ref"
        ranks "tools/gen $args" "$M/gen$k.ref" "2 5 8" "$M/gen$k.in"
    done <<'SCENES'
400 --assignment --L 2000 --steps 20
1500 --fraction 0.2 --speed 0.5 --fast 0.02 --steps 10
600 --r 5 --fraction 0.3 --speed 4 --steps 10
300 --fraction 0.2 --speed 2 --steps 15 --mode print
1200 --fraction 2 --overlap --speed 0.5 --steps 3
3 --L 10 --speed 3 --steps 50 --mode print
SCENES
    ./seq "$M/gen1.in" --quiet --substeps 2 > "$M/sub.ref"
    ranks "--substeps 2" "$M/sub.ref" "3" "$M/gen1.in" --substeps 2

    printf '3\n10\n1\n5\nperf\n1 2 3\n' > "$M/bad.in"
    expect_error "mpi: bad input refused, 3 ranks" "bad.in:6: expected 5 fields" \
        mpirun -q -np 3 --oversubscribe ./mpi "$M/bad.in"
    expect_error "mpi: --pressure refused" "--pressure is not supported by mpi" \
        mpirun -q -np 2 --oversubscribe ./mpi "$M/gen1.in" --pressure
    expect_error "mpi: --checkpoint refused" "not supported by mpi" \
        mpirun -q -np 2 --oversubscribe ./mpi "$M/gen1.in" --checkpoint "$M/ck"
fi
