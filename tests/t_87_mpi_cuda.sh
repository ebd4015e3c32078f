# mpi_cuda (mpi.c built with MPI_CUDA, mpi_cuda.cu): mpi's ranks, each stepping its strip on a GPU
# with cuda's kernels, print seq's bytes at 1 to 4 ranks (ranks share a GPU where there are fewer
# GPUs than ranks; each takes its node-local rank's GPU modulo the GPUs):
# - the bundled inputs (walled and periodic), the worked examples and the hard cases;
# - the omp and mpi tests' generated scenes (tests/omp_scenes.txt): slow, fast, dense, overlapping,
#   deep rounds of the choice, a few fast disks among slow ones crossing the strips;
# - random placement (--seed), --substeps 2, --dump17, --output FILE, a gas crowded in one corner;
# - halos and keys GPU to GPU (ranks of one node, as above) and through host memory (SIM_MPI_CUDA_HOST=1);
#   the regions the ranks share grown step after step (SIM_MPI_CUDA_REGION_SLACK=1);
# - the moves keying the kept disks' cells for the next step: taken (--stats), and with the grid ahead
#   at the step's own speed or with no keying (SIM_CUDA_BIN_AHEAD=1, 0); the halos taken from the moves'
#   lists of own disks near the cuts (--stats); moves done twice, their leavers overflowing the device's
#   room (SIM_MPI_CUDA_LEAVERS_ROOM=0), their collisions counted once; searches done twice, their events
#   overflowing the list (SIM_MPI_CUDA_EVENTS=2); the lone events settled before the rounds (--stats),
#   always, with searches done twice, and never (SIM_CUDA_SETTLE=1e30, 0); 8-bit cell counts where cub
#   scans a table (SIM_CUDA_SCAN_TILES=0), a crowded cell's search done again in 32 bits (SIM_CUDA_NARROW=0);
# - --checkpoint: seq's file byte for byte; resumed across backends (seq's by mpi_cuda, mpi_cuda's by
#   seq and by mpi at another rank count); kill trials: the job killed with SIGKILL at 2 and 3 ranks
#   and resumed by mpi_cuda at another rank count, by mpi and by seq (CK_SEED=N repeats a run's moments);
# - options it does not take (--pressure, --threads) refused with one line.
# SKIP without a GPU, mpirun or ./mpi_cuda (make builds it where nvcc and mpicc both exist). Everywhere:
# make says it left mpi_cuda out where nvcc is missing.
G=$TMP/gpu
mkdir -p "$G"
if out=$(make -s --no-print-directory NVCC=/nonexistent/nvcc all 2>&1) &&
    grep -q "^mpi_cuda skipped: it needs both /nonexistent/nvcc and" <<< "$out" && grep -q "^cuda skipped" <<< "$out"; then
    pass "make without nvcc: says it skipped cuda and mpi_cuda"
else
    fail "make without nvcc" "$(head -c 300 <<< "$out")"
fi
if ! command -v mpirun > /dev/null 2>&1 || [ ! -x ./mpi_cuda ] || ! have_gpu; then
    skip "mpi_cuda" "no GPU, no mpirun or no ./mpi_cuda (it needs nvcc and mpicc)"
else
    mpi_env
    pick() { if all_suite; then echo "$1"; else echo "$2"; fi; }
    run_gpu() { # P ARGS...: mpi_cuda on P ranks
        local p=$1
        shift
        "${MPIRUN[@]}" -np "$p" --oversubscribe ./mpi_cuda "$@"
    }
    gpu_ranks() { # NAME EXPECTED "P..." ARGS...: mpi_cuda at each rank count prints EXPECTED's bytes
        local name=$1 expected=$2 counts=$3 p bad=""
        shift 3
        for p in $counts; do
            if ! run_gpu "$p" "$@" --quiet > "$G/out" 2> "$G/err" < /dev/null; then
                bad="$bad $p:exit($(head -c 150 "$G/err"))"
            elif ! cmp -s "$G/out" "$expected"; then
                bad="$bad $p:differs($(cmp "$G/out" "$expected" 2>&1 | head -1))"
            fi
        done
        if [ -z "$bad" ]; then pass "mpi_cuda $name: seq's bytes at $counts ranks"; else fail "mpi_cuda $name" "$bad"; fi
    }
    for f in inputs/*.in; do
        b=$(basename "$f" .in)
        gpu_ranks "inputs/$b" "outputs/$b.out" "$(pick "1 2 3 4" "2 3")" "$f"
    done
    for f in inputs/periodic/*.in; do
        b=$(basename "$f" .in)
        gpu_ranks "periodic/$b" "outputs/periodic/$b.out" "$(pick "1 2 3 4" "2 4")" "$f" --periodic
    done
    k=0
    for f in tests/cases/*.in; do
        k=$((k + 1))
        all_suite || [ $((k % 2)) = 1 ] || continue
        gpu_ranks "cases/$(basename "$f" .in)" "${f%.in}.out" "$(pick "1 3 4" "3")" "$f"
    done
    k=0
    for f in tests/hard/*.in; do
        [ -f "${f%.in}.out" ] || continue
        k=$((k + 1))
        all_suite || [ $((k % 3)) = 1 ] || continue
        gpu_ranks "hard/$(basename "$f" .in)" "${f%.in}.out" "$(pick "2 4" "2")" "$f"
    done
    combos=("1 3" "2 4" "3 4" "4 2")
    k=0
    while read -r name args; do
        # shellcheck disable=SC2086
        tools/gen $args > "$G/$name.in"
        ./seq "$G/$name.in" --quiet > "$G/$name.ref"
        gpu_ranks "$name" "$G/$name.ref" "$(pick "1 2 3 4" "${combos[k % 4]}")" "$G/$name.in"
        k=$((k + 1))
    done < <(grep -v '^#' tests/omp_scenes.txt)

    # random placement, --substeps, --dump17, --output, a mixed scene, fast disks crossing the strips
    printf '300\n400\n1\n15\nprint\n' > "$G/random.in"
    ./seq "$G/random.in" --quiet --seed 7 > "$G/random.ref"
    gpu_ranks "random placement --seed 7" "$G/random.ref" "3" "$G/random.in" --seed 7
    tools/gen 400 --assignment --L 2000 --steps 20 > "$G/sub.in"
    ./seq "$G/sub.in" --quiet --substeps 2 > "$G/sub.ref"
    gpu_ranks "--substeps 2" "$G/sub.ref" "$(pick "2 3" "3")" "$G/sub.in" --substeps 2
    ./seq "$G/overlap_print.in" --quiet --dump17 > "$G/dump17.ref"
    gpu_ranks "--dump17" "$G/dump17.ref" "2" "$G/overlap_print.in" --dump17
    if run_gpu 3 "$G/slow_print.in" --quiet --output "$G/file.out" > "$G/out" 2> "$G/err" &&
        cmp -s "$G/file.out" "$G/slow_print.ref" && [ ! -s "$G/out" ]; then
        pass "mpi_cuda --output FILE: seq's bytes in FILE at 3 ranks, nothing on stdout"
    else
        fail "mpi_cuda --output FILE" "$(head -c 200 "$G/err")"
    fi
    tools/gen 1500 --fraction 0.2 --speed 0.5 --fast 0.02 --steps 10 > "$G/mixed.in"
    ./seq "$G/mixed.in" --quiet > "$G/mixed.ref"
    gpu_ranks "mixed scene" "$G/mixed.ref" "$(pick "2 4" "4")" "$G/mixed.in"
    tools/gen 400 --speed 0.5 --fast 0.005 --steps 200 --mode print > "$G/fast_few.in"
    ./seq "$G/fast_few.in" --quiet > "$G/fast_few.ref"
    gpu_ranks "two fast disks crossing the strips" "$G/fast_few.ref" "3" "$G/fast_few.in"
    awk 'NR == 2 { $1 = 4 * $1 } { print }' "$G/mid_dense.in" > "$G/corner.in"
    ./seq "$G/corner.in" --quiet > "$G/corner.ref"
    gpu_ranks "a gas in one corner of the box" "$G/corner.ref" "4" "$G/corner.in"
    tools/gen 20000 --fraction 0.3 --speed 0.5 --steps 10 --seed 11 > "$G/gas.in"
    ./seq "$G/gas.in" --quiet > "$G/gas.ref"
    gpu_ranks "gas of 20000" "$G/gas.ref" "$(pick "1 2 3 4" "4")" "$G/gas.in"

    # the two paths of halos and keys: GPU to GPU where the ranks share a node (every run above, unless
    # SIM_MPI_CUDA_HOST=1 was set for the whole file), and through host memory, as between nodes
    for path in "GPU to GPU" "through host memory"; do
        (if [ "$path" = "GPU to GPU" ]; then unset SIM_MPI_CUDA_HOST; else export SIM_MPI_CUDA_HOST=1; fi
            run_gpu 3 "$G/gas.in" --quiet --stats > "$G/out" 2> "$G/err" < /dev/null)
        rc=$?
        said=$(grep -o "halos and keys [a-zA-Z ]*$" "$G/err")
        if [ "$rc" = 0 ] && cmp -s "$G/out" "$G/gas.ref" && [ "$said" = "halos and keys $path" ]; then
            pass "mpi_cuda halos and keys $path: said under --stats, seq's bytes at 3 ranks"
        elif [ "$rc" = 0 ] && cmp -s "$G/out" "$G/gas.ref" && [ "$path" = "GPU to GPU" ]; then
            skip "mpi_cuda halos and keys GPU to GPU" \
                "these GPUs cannot map each other's memory (${said:-nothing said})"
        else
            fail "mpi_cuda halos and keys $path" "exit $rc; ${said:-nothing said}; $(head -c 200 "$G/err")"
        fi
    done
    # the own disks a move keeps keyed by it for the next step's cells: counted only, where the grid it
    # keyed them on fits the step's (in most steps of a gas); with that grid fitted to the step's own
    # speed (SIM_CUDA_BIN_AHEAD=1) it fits less often, and with no keying (0) every step bins them
    (unset SIM_CUDA_BIN_AHEAD; run_gpu 3 "$G/gas.in" --quiet --stats > "$G/out" 2> "$G/err" < /dev/null)
    keyed=$(sed -nE 's/.*the move before keyed for their cells: ([0-9]+),.*/\1/p' "$G/err")
    if cmp -s "$G/out" "$G/gas.ref" && [ "${keyed:-0}" -gt 0 ]; then
        pass "mpi_cuda moves key the next step's cells: $keyed rank-steps took them (--stats), seq's bytes at 3 ranks"
    else
        fail "mpi_cuda moves keying the next step's cells" "${keyed:-nothing said}; $(head -c 200 "$G/err")"
    fi
    # the same run: the halos that looked only at the own disks the move before listed near the cuts
    listed=$(sed -nE 's/.*listed near the cuts: ([0-9]+), at every own disk: ([0-9]+);.*/\1 \2/p' "$G/err")
    if cmp -s "$G/out" "$G/gas.ref" && [ "${listed%% *}" -gt 0 ] 2> /dev/null; then
        pass "mpi_cuda halos from the moves' lists near the cuts: ${listed% *} rank-steps (and ${listed#* } over every own disk), seq's bytes at 3 ranks"
    else
        fail "mpi_cuda halos from the moves' lists" "${listed:-nothing said}; $(head -c 200 "$G/err")"
    fi
    # a move whose leavers overflow the device's room moves again, its collisions counted once
    (export SIM_MPI_CUDA_LEAVERS_ROOM=0; run_gpu 3 "$G/gas.in" --quiet --stats > "$G/out" 2> "$G/err" < /dev/null)
    again=$(sed -nE 's/.*moves done twice \(more leavers than room\): ([0-9]+).*/\1/p' "$G/err")
    if cmp -s "$G/out" "$G/gas.ref" && [ "${again:-0}" -gt 0 ]; then
        pass "mpi_cuda moves done twice (SIM_MPI_CUDA_LEAVERS_ROOM=0): $again, seq's bytes at 3 ranks"
    else
        fail "mpi_cuda moves done twice" "${again:-nothing said}; $(head -c 200 "$G/err")"
    fi
    # a search whose events overflow the list is done again with a longer one, the slots' keys started
    # anew: every step's list cut back to 2 events (SIM_MPI_CUDA_EVENTS=2), so all 30 rank-steps
    (export SIM_MPI_CUDA_EVENTS=2; run_gpu 3 "$G/gas.in" --quiet --stats > "$G/out" 2> "$G/err" < /dev/null)
    twice=$(sed -nE 's/.*searches done twice \(more events than the list held\): ([0-9]+).*/\1/p' "$G/err")
    if cmp -s "$G/out" "$G/gas.ref" && [ "${twice:-0}" = 30 ]; then
        pass "mpi_cuda searches done twice (SIM_MPI_CUDA_EVENTS=2): all $twice rank-steps, seq's bytes at 3 ranks"
    else
        fail "mpi_cuda searches done twice" "${twice:-nothing said} of 30; $(head -c 200 "$G/err")"
    fi
    # the lone events (the only one of both their disks) settled before the rounds, as cuda's steps of one
    # slice settle them, wherever a disk has fewer than SIM_CUDA_SETTLE events a step (a copy's events never:
    # its owner settles them); always (1e30), with a search done twice (its tallies started anew), and never
    (export SIM_CUDA_SETTLE=1e30; run_gpu 3 "$G/gas.in" --quiet --stats > "$G/out" 2> "$G/err" < /dev/null)
    settled=$(sed -nE 's/.*settled first found ([0-9]+) pair events and left ([0-9]+) of them.*/\1 \2/p' "$G/err")
    if cmp -s "$G/out" "$G/gas.ref" && [ "${settled%% *}" -gt "${settled#* }" ] 2> /dev/null; then
        pass "mpi_cuda settles lone events first: ${settled%% *} found, ${settled#* } left to the rounds$(
            ) (--stats), seq's bytes at 3 ranks"
    else
        fail "mpi_cuda settling lone events" "${settled:-nothing said}; $(head -c 200 "$G/err")"
    fi
    (export SIM_CUDA_SETTLE=1e30 SIM_MPI_CUDA_EVENTS=2
        run_gpu 3 "$G/gas.in" --quiet > "$G/out" 2> "$G/err" < /dev/null)
    if cmp -s "$G/out" "$G/gas.ref"; then
        pass "mpi_cuda settling with every search done twice (SIM_MPI_CUDA_EVENTS=2): seq's bytes at 3 ranks"
    else
        fail "mpi_cuda settling with every search done twice" "$(head -c 200 "$G/err")"
    fi
    # 8-bit cell counts (count_add) where cub scans a rank's table (SIM_CUDA_SCAN_TILES=0 sends every table
    # there, as in cuda): the gas counted so throughout; "point" and "ring" (crowd_scene), whose crowded cell
    # (in a step's first binning, and in one the move before keyed) has the search done again in 32 bits
    # (--stats), and "point" in 32 bits throughout (SIM_CUDA_NARROW=0). Timed out: a fallback that never took
    # would search the same step forever.
    narrow_run() { # NAME EXPECTED P CROWDINGS ARGS...: seq's bytes, and --stats' searches for a crowded cell
        local name=$1 expected=$2 p=$3 want=$4 rc=0 got # NARROW=0: SIM_CUDA_NARROW=0 (else 8 bits allowed)
        shift 4
        # (run_gpu, a function, cannot run under timeout)
        (export SIM_CUDA_SCAN_TILES=0 SIM_CUDA_NARROW=${NARROW:-1}
            timeout 120 "${MPIRUN[@]}" -np "$p" --oversubscribe ./mpi_cuda "$@" --quiet --stats > "$G/out" \
                2> "$G/err" < /dev/null) || rc=$?
        got=$(sed -nE 's/.*searches done again for a cell past 255 disks \(8-bit counts\): ([0-9]+).*/\1/p' "$G/err")
        if [ "$rc" = 0 ] && cmp -s "$G/out" "$expected" && { [ "$want" = some ] && [ "${got:-0}" -gt 0 ] ||
            [ "$want" = "${got:-x}" ]; }; then
            pass "mpi_cuda 8-bit cell counts, $name: $got searches done again for a crowded cell,$(
                ) seq's bytes at $p ranks"
        else
            fail "mpi_cuda 8-bit cell counts, $name" "exit $rc, ${got:-nothing said} searches done again (want $want)$(
                ); $(head -c 200 "$G/err")"
        fi
    }
    narrow_run "gas of 20000" "$G/gas.ref" 3 0 "$G/gas.in"
    for name in point ring; do
        crowd_scene "$name" perf > "$G/crowd_$name.in"
        ./seq "$G/crowd_$name.in" --quiet > "$G/crowd_$name.ref"
        narrow_run "$name" "$G/crowd_$name.ref" "$([ $name = point ] && echo 2 || echo 3)" some "$G/crowd_$name.in"
    done
    NARROW=0 narrow_run "point, SIM_CUDA_NARROW=0" "$G/crowd_point.ref" 2 0 "$G/crowd_point.in"
    caller_settle=${SIM_CUDA_SETTLE-unset}
    for e in 1e30 0; do
        export SIM_CUDA_SETTLE=$e
        gpu_ranks "SIM_CUDA_SETTLE=$e: mixed scene" "$G/mixed.ref" "$(pick "2 4" "4")" "$G/mixed.in"
        gpu_ranks "SIM_CUDA_SETTLE=$e: a gas in one corner of the box" "$G/corner.ref" "$(pick "1 3" "3")" \
            "$G/corner.in"
    done
    export SIM_CUDA_SETTLE=1e30
    pin=$(ls inputs/periodic/*.in | head -1) # a periodic input, for the runs below too
    gpu_ranks "SIM_CUDA_SETTLE=1e30: periodic/$(basename "$pin" .in)" "outputs/periodic/$(basename "$pin" .in).out" \
        "$(pick "2 4" "2")" "$pin" --periodic
    if [ "$caller_settle" = unset ]; then unset SIM_CUDA_SETTLE; else export SIM_CUDA_SETTLE=$caller_settle; fi
    caller_ahead=${SIM_CUDA_BIN_AHEAD-unset}
    for s in 1 0; do
        export SIM_CUDA_BIN_AHEAD=$s
        gpu_ranks "SIM_CUDA_BIN_AHEAD=$s: gas of 20000" "$G/gas.ref" "$(pick "2 3 4" "2")" "$G/gas.in"
        gpu_ranks "SIM_CUDA_BIN_AHEAD=$s: mixed scene" "$G/mixed.ref" "3" "$G/mixed.in"
    done
    export SIM_CUDA_BIN_AHEAD=1
    gpu_ranks "SIM_CUDA_BIN_AHEAD=1: periodic/$(basename "$pin" .in)" "outputs/periodic/$(basename "$pin" .in).out" \
        "3" "$pin" --periodic
    if [ "$caller_ahead" = unset ]; then unset SIM_CUDA_BIN_AHEAD; else export SIM_CUDA_BIN_AHEAD=$caller_ahead; fi
    caller_host=${SIM_MPI_CUDA_HOST-unset}
    export SIM_MPI_CUDA_HOST=1
    gpu_ranks "through host memory: mixed scene" "$G/mixed.ref" "$(pick "2 4" "2")" "$G/mixed.in"
    for f in inputs/periodic/*.in; do
        all_suite || break
        b=$(basename "$f" .in)
        gpu_ranks "through host memory: periodic/$b" "outputs/periodic/$b.out" "2 3" "$f" --periodic
    done
    if [ "$caller_host" = unset ]; then unset SIM_MPI_CUDA_HOST; else export SIM_MPI_CUDA_HOST=$caller_host; fi
    # the ranks' regions grown step after step (a record of slack each time), each growth mapped anew
    export SIM_MPI_CUDA_REGION_SLACK=1
    gpu_ranks "regions grown step after step: gas of 20000" "$G/gas.ref" "$(pick "2 3 4" "4")" "$G/gas.in"
    gpu_ranks "regions grown step after step: mixed scene" "$G/mixed.ref" "3" "$G/mixed.in"
    gpu_ranks "regions grown step after step: periodic/$(basename "$pin" .in)" \
        "outputs/periodic/$(basename "$pin" .in).out" "2" "$pin" --periodic
    unset SIM_MPI_CUDA_REGION_SLACK

    # --checkpoint: seq's file; resumed across backends
    tools/gen 500 --fraction 0.3 --steps 40 --mode print --seed 7 > "$G/ck.in"
    tools/gen 300 --periodic --assignment --L 300 --steps 40 --seed 8 > "$G/pck.in"
    for scene in ck pck; do
        args=()
        [ "$scene" = pck ] && args=(--periodic --substeps 2)
        rm -f "$G/seq.ck" "$G/gpu.ck"
        ./seq "$G/$scene.in" "${args[@]}" --quiet --checkpoint "$G/seq.ck" --checkpoint-every 13 > "$G/seq.out"
        if run_gpu 3 "$G/$scene.in" "${args[@]}" --quiet --checkpoint "$G/gpu.ck" --checkpoint-every 13 > "$G/out" 2> "$G/err" &&
            cmp -s "$G/out" "$G/seq.out" && cmp -s "$G/gpu.ck" "$G/seq.ck"; then
            pass "mpi_cuda --checkpoint ($scene): seq's file and output at 3 ranks"
        else
            fail "mpi_cuda --checkpoint ($scene)" "$(head -c 200 "$G/err") $(cmp "$G/gpu.ck" "$G/seq.ck" 2>&1 | head -1)"
        fi
        ./seq --resume "$G/seq.ck" > "$G/resumed.ref" 2> /dev/null
        bad=""
        run_gpu 2 --resume "$G/seq.ck" > "$G/r1" 2> /dev/null && cmp -s "$G/r1" "$G/resumed.ref" || bad="$bad mpi_cuda(seq's)"
        ./seq --resume "$G/gpu.ck" > "$G/r2" 2> /dev/null && cmp -s "$G/r2" "$G/resumed.ref" || bad="$bad seq(mpi_cuda's)"
        if have_mpi; then
            run_mpi 2 1 --resume "$G/gpu.ck" > "$G/r3" 2> /dev/null && cmp -s "$G/r3" "$G/resumed.ref" || bad="$bad mpi(mpi_cuda's)"
        fi
        if [ -z "$bad" ]; then pass "mpi_cuda --resume ($scene): seq's output across backends"; else fail "mpi_cuda --resume ($scene)" "$bad"; fi
    done

    # kill trials (ck_trial, tests/lib.sh): the job killed with SIGKILL while it writes a checkpoint
    # every step or every few, resumed by mpi_cuda at another rank count, by mpi and by seq; through
    # --output FILE, as t_88's (a killed mpirun loses the stdout it had not passed on)
    C=$G/kill
    mkdir -p "$C"
    CK_SEED=${CK_SEED:-$(($(date +%s) % 32768))}
    RANDOM=$CK_SEED
    CK_KILLS=0
    gpu="${MPIRUN[*]} --oversubscribe -np"
    tools/gen 150 --speed 0.5 --steps 1500 --mode print --seed 3 > "$C/kill.in"
    tools/gen 150 --periodic --speed 0.5 --steps 1500 --mode print --seed 9 > "$C/pkill.in"
    ./seq "$C/kill.in" --quiet > "$C/kill.ref"
    ./seq "$C/pkill.in" --periodic --quiet > "$C/pkill.ref"
    ck_trial "kill: mpi_cuda 2 ranks print every step, resumed by mpi_cuda 3 ranks" "$C/kill.ref" 150 print 1 0.5 \
        "$gpu 2 ./mpi_cuda $C/kill.in --output @OUT@" "$gpu 3 ./mpi_cuda --output @OUT@"
    ck_trial "kill: mpi_cuda 3 ranks print, resumed by mpi_cuda 2 ranks, killed, then by seq" "$C/kill.ref" 150 \
        print 7 0.4 "$gpu 3 ./mpi_cuda $C/kill.in --output @OUT@" "$gpu 2 ./mpi_cuda --output @OUT@" "./seq"
    ck_trial "kill: mpi_cuda 2 ranks --periodic print every step, resumed by mpi_cuda 4 ranks" "$C/pkill.ref" \
        150 print 1 0.5 "$gpu 2 ./mpi_cuda $C/pkill.in --periodic --output @OUT@" "$gpu 4 ./mpi_cuda --output @OUT@"
    min_kills=4
    if have_mpi; then
        ck_trial "kill: mpi_cuda 3 ranks print, resumed by mpi 2 ranks" "$C/kill.ref" 150 print 3 0.4 \
            "$gpu 3 ./mpi_cuda $C/kill.in --output @OUT@" "$gpu 2 ./mpi --output @OUT@"
        min_kills=5
    fi
    if [ "$CK_KILLS" -ge "$min_kills" ]; then
        pass "kill: $CK_KILLS mpi_cuda jobs killed with SIGKILL and resumed (seed $CK_SEED)"
    else
        fail "kill: mpi_cuda trials" "only $CK_KILLS jobs were killed (at least $min_kills wanted; seed $CK_SEED)"
    fi

    # what it does not take
    for opt in "--pressure" "--threads 2" "--balance 2"; do
        # shellcheck disable=SC2086
        if run_gpu 2 "$G/sub.in" $opt > "$G/out" 2> "$G/err" < /dev/null; then
            fail "mpi_cuda $opt refused" "it ran"
        elif [ -s "$G/out" ] || ! grep -q "mpi_cuda: .*${opt%% *}" "$G/err"; then
            fail "mpi_cuda $opt refused" "stdout $(wc -c < "$G/out") bytes; $(head -c 200 "$G/err")"
        else
            pass "mpi_cuda $opt refused with its line, nothing on stdout"
        fi
    done
fi
