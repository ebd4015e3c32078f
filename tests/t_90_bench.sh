# bench.sh --quick runs on this machine and writes well-formed CSVs: provenance lines, the column header,
# rows with the header's field count and sane numbers, and a summary with one row per point. The whole
# suite only: half a minute of benchmark runs. First, in both suites, tools/ncu_kernels.py (gpu-bytes,
# gpu-kernels) on a made-up Nsight Compute report whose window of launches starts and ends inside a step.
{
    echo '"ID","Kernel Name","gpu__time_duration.sum","dram__bytes_read.sum","dram__bytes_write.sum"'
    echo '"","","usecond","byte","byte"'
    i=0
    for k in "detect_kernel 10 100 4" "move_kernel 20 50 60" "commit_kernel 1 0 0" "gate_kernel 1 0 0" \
        "detect_kernel 10 100 4" "move_kernel 20 50 60" "commit_kernel 1 0 0" "gate_kernel 1 0 0" "detect_kernel 10 100 4"; do
        read -r name us rd wr <<< "$k"
        echo "\"$i\",\"void $name(int)\",\"$us\",\"$rd\",\"$wr\""
        i=$((i + 1))
    done
} > "$TMP/ncu_raw.csv"
ncu_rows=$(python3 tools/ncu_kernels.py "$TMP/ncu_raw.csv" 2 2>&1)
if ! command -v python3 > /dev/null 2>&1; then
    skip "ncu_kernels.py" "no python3"
elif grep -qx 'detect_kernel,1,10.0,10.00,31.2%,50.0,2.0' <<< "$ncu_rows" &&
    grep -qx 'all,4,32.0,32.00,100%,75.0,32.0' <<< "$ncu_rows" &&
    grep -qx '# step 1 of the window: 107 bytes a particle-step (detect 52 move 55)' <<< "$ncu_rows"; then
    pass "ncu_kernels.py: the whole step inside a window cut mid-step, 75 bytes read and 32 written a particle-step"
else
    fail "ncu_kernels.py: a window cut mid-step" "$(tr '\n' ' ' <<< "$ncu_rows" | head -c 400)"
fi
if ! all_suite; then
    skip "bench.sh smoke runs" "make test-all runs them"
    return
fi
bench_csv=$TMP/bench.csv
bench_sum=$TMP/bench.summary.csv
if ./bench.sh --quick -o "$bench_csv" > "$TMP/bench.log" 2>&1; then
    pass "bench.sh --quick runs"
else
    fail "bench.sh --quick runs" "$(tail -n 3 "$TMP/bench.log")"
fi
bench_problem=$(awk -F, '
    /^#/ { if (header) { print "comment after the header: " $0; exit }; prov[substr($0, 3)] = 1; next }
    !header {
        header = $0; nf = NF
        if ($0 != "backend,threads,scene,n,steps,run,seconds,wall_seconds,ns_per_particle_step,pair_tests_per_particle_step,events_per_particle_step,pair_tests,events,L,r,area_fraction") {
            print "unexpected header: " $0; exit
        }
        next
    }
    NF != nf { print "line " NR " has " NF " fields, not " nf; exit }
    $1 !~ /^(seq|omp|cuda)$/ { print "line " NR ": unknown backend " $1; exit }
    {
        for (k = 2; k <= NF; k++) if (k != 3 && $k !~ /^[0-9.e+-]+$/) { print "line " NR " field " k " not a number: " $k; exit }
        if (!($7 > 0 && $8 >= $7 && $9 > 0 && $5 >= 1)) { print "line " NR ": implausible times: " $0; exit }
        rows++; seen[$1] = 1
    }
    END {
        if (!header) { print "no header"; exit }
        split("git: date: cpu: cc: CFLAGS: OMP_PROC_BIND", need, " ")
        for (k in need) { found = 0; for (p in prov) if (index(p, need[k]) == 1) found = 1; if (!found) print "no provenance line " need[k] }
        if (!seen["seq"] || !seen["omp"]) print "no seq or no omp rows"
    }' "$bench_csv" 2>&1 | head -n 1)
bench_problem=${bench_problem:-$( [ -s "$bench_csv" ] || echo "no $bench_csv")}
if [ -z "$bench_problem" ]; then pass "bench.sh --quick CSV well formed"; else fail "bench.sh --quick CSV well formed" "$bench_problem"; fi
bench_points=$(grep -v -e '^#' -e '^backend,' "$bench_csv" 2>/dev/null | cut -d, -f1-4 | sort -u | wc -l)
bench_rows=$(grep -v -e '^#' -e '^backend,' "$bench_sum" 2>/dev/null | awk -F, 'NF == 17 && $6 >= 3 && $7 <= $8' | wc -l)
if [ "$bench_points" -gt 0 ] && [ "$bench_rows" -eq "$bench_points" ]; then
    pass "bench.sh --quick summary: one row per point"
else
    fail "bench.sh --quick summary: one row per point" "$bench_rows good rows for $bench_points points"
fi

# --summarize rebuilds the summary of the runs above from their rows alone (as for a stopped sweep)
cp "$bench_csv" "$TMP/again.csv"
rm -f "$TMP/again.summary.csv"
if ./bench.sh --summarize "$TMP/again.csv" > "$TMP/again.log" 2>&1; then
    summary_diff=$(diff <(grep -v '^#' "$bench_sum") <(grep -v '^#' "$TMP/again.summary.csv") 2>&1)
    if [ -s "$TMP/again.summary.csv" ] && [ -z "$summary_diff" ]; then
        pass "bench.sh --summarize: the sweep's summary rows"
    else
        fail "bench.sh --summarize: the sweep's summary rows" "$(echo "$summary_diff" | head -3)"
    fi
else
    fail "bench.sh --summarize: the sweep's summary rows" "exit status non-zero: $(tail -n 2 "$TMP/again.log")"
fi

# --steps S: every run has S steps in its input's steps line (rewritten in place, so the file of a
# scene keeps its other lines) and no probe runs
rm -f "$TMP/steps.csv"
./bench.sh --backends omp --threads 2 --scenes gas20,random --sizes 1000 --steps 7 --repeats 3 \
    -o "$TMP/steps.csv" > "$TMP/steps.log" 2>&1
steps_rc=$?
steps_rows=$(grep -v -e '^#' -e '^backend,' "$TMP/steps.csv" 2>/dev/null | awk -F, '$5 == 7' | wc -l)
if [ "$steps_rc" -eq 0 ] && [ "$steps_rows" -eq 6 ]; then
    pass "bench.sh --steps 7: 6 runs of 7 steps"
else
    fail "bench.sh --steps 7: 6 runs of 7 steps" "exit $steps_rc, $steps_rows rows with 7 steps: $(tail -n 2 "$TMP/steps.log")"
fi

# targets in turn with an earlier tree's omp: a row of each build per measurement (4 for the mixed
# case at one thread), and the same bytes. LABEL LOG VAR=VALUE...: the base and where the log goes.
targets_in_turn() {
    local label=$1 log=$2 rc ours base
    shift 2
    env "$@" CASES=mixed THREADS=1 REPEATS=1 ./bench.sh targets > "$log" 2>&1
    rc=$?
    ours=$(grep -c '^mixed[a-z_]*,omp,1,' "$log")
    base=$(grep -c '^mixed[a-z_]*,omp_base,1,' "$log")
    if [ "$rc" -eq 0 ] && [ "$ours" -eq 4 ] && [ "$base" -eq 4 ]; then
        pass "bench.sh targets $label: 4 rows of each build, same bytes"
    else
        fail "bench.sh targets $label" "exit $rc, rows $ours and $base: $(tail -n 2 "$log")"
    fi
}

# BASE_REV: HEAD's omp, built from git (where this folder is a git checkout's top: a copy of the tree
# inside another checkout would build that one)
if [ "$(git rev-parse --show-toplevel 2> /dev/null)" = "$(pwd -P)" ]; then
    targets_in_turn BASE_REV=HEAD "$TMP/targets.log" BASE_REV=HEAD WORK="$TMP/targets"
else
    skip "bench.sh targets BASE_REV" "this folder is not a git checkout"
fi

# BASE_DIR: a folder of sources (here a copy of this tree's), where there is no git; a folder without
# omp.c is refused
mkdir -p "$TMP/base_dir"
cp ./*.c ./*.h Makefile "$TMP/base_dir"/
targets_in_turn BASE_DIR "$TMP/targets_dir.log" BASE_DIR="$TMP/base_dir" WORK="$TMP/targets_dir"
if BASE_DIR="$TMP" CASES=mixed WORK="$TMP/targets_bad" ./bench.sh targets > /dev/null 2> "$TMP/bad_dir.err"; then
    fail "bench.sh targets BASE_DIR without omp.c" "accepted"
elif grep -q "holds no omp.c" "$TMP/bad_dir.err"; then
    pass "bench.sh targets BASE_DIR without omp.c refused with a message"
else
    fail "bench.sh targets BASE_DIR without omp.c" "$(head -c 200 "$TMP/bad_dir.err")"
fi

# phases: medians of each phase, this tree's omp and the base's in turn; every row's phases add up to
# its loop within rounding (medians of sums and sums of medians differ by a little), and the same bytes
printf '1000\n20000\n1\n100\nperf\n' > "$TMP/phases.in"
if BASE_DIR="$TMP/base_dir" INPUTS="$TMP/phases.in" THREADS="1 2" REPEATS=3 WORK="$TMP/phases" \
    ./bench.sh phases > "$TMP/phases.log" 2>&1; then
    phases_problem=$(awk -F, '
        /^#/ { next }
        !header { header = $0; if ($0 != "input,program,threads,plan,binning,pairs,choice,move,waiting,output_and_final_order,all") { print "unexpected header: " $0; exit }; next }
        NF != 11 { print "line " NR " has " NF " fields"; exit }
        {
            sum = 0
            for (k = 4; k <= 11; k++) if ($k !~ /^[0-9.]+$/) { print "line " NR " field " k " not a number: " $k; exit }
            for (k = 4; k <= 10; k++) sum += $k
            if (!($11 > 0) || sum < 0.5 * $11 || sum > 1.5 * $11) { print "line " NR ": phases add up to " sum " of " $11; exit }
            rows[$2 "," $3]++
        }
        END { if (rows["omp,1"] != 1 || rows["omp_base,1"] != 1 || rows["omp,2"] != 1 || rows["omp_base,2"] != 1) print "not one row of each build and thread count" }
    ' "$TMP/phases.log")
    if [ -z "$phases_problem" ]; then
        pass "bench.sh phases: a row of each build and thread count, phases adding up to the loop"
    else
        fail "bench.sh phases" "$phases_problem"
    fi
else
    fail "bench.sh phases" "exit status non-zero: $(tail -n 2 "$TMP/phases.log")"
fi

# exact threads: omp --exact at each thread count in turn with the base's (here a copy of this tree),
# two rounds: a row per run, a summary row per build and thread count, the same bytes
if BASE_DIR="$TMP/base_dir" N=3000 FRACTION=0.4 STEPS=2 THREADS="1 2" REPEATS=2 WORK="$TMP/exact_threads" \
    ./bench.sh exact threads > "$TMP/exact_threads.log" 2>&1; then
    rows=$(grep -Ec '^omp(_base)?,[12],3000,2,[12],[0-9.]+$' "$TMP/exact_threads.log")
    sums=$(grep -Ec '^# omp(_base)?,[12],[0-9.]+,[0-9.]+,[0-9.]+,[0-9.]+$' "$TMP/exact_threads.log")
    if [ "$rows" -eq 8 ] && [ "$sums" -eq 4 ]; then
        pass "bench.sh exact threads: 8 runs in turn with the base's, 4 summary rows, the same bytes"
    else
        fail "bench.sh exact threads" "$rows rows, $sums summary rows: $(tail -n 3 "$TMP/exact_threads.log")"
    fi
else
    fail "bench.sh exact threads" "exit status non-zero: $(tail -n 2 "$TMP/exact_threads.log")"
fi

# dense --quick: the fluid, loop and rungs parts at a few hundred disks, two points at once: a row per
# point in order (2 fluid, 8 rungs, 1 loop), each beside its reference's Z
if OUTPUT_QUICK="$TMP/dense.csv" TMP_DIR="$TMP/dense" JOBS=2 THREADS=1 ./bench.sh dense --quick > "$TMP/dense.log" 2>&1; then
    order=$(grep -v '^#' "$TMP/dense.csv" | awk -F, 'NR > 1 { printf "%s:%s:%s ", $1, $2, $3 }')
    want="fluid:exact:0.3 fluid:exact:0.65 rungs:k1:0.3 rungs:k2:0.3 rungs:k4:0.3 rungs:k8:0.3 rungs:k1:0.65 rungs:k2:0.65 rungs:k4:0.65 rungs:k8:0.65 loop:exact:0.71 "
    refs=$(grep -v '^#' "$TMP/dense.csv" | awk -F, 'NR > 1 && $10 + 0 > 0 && $8 + 0 > 0 { k++ } END { print k + 0 }')
    if [ "$order" = "$want" ] && [ "$refs" = 11 ]; then
        pass "bench.sh dense --quick: 11 points in order, each with its Z and its reference's"
    else
        fail "bench.sh dense --quick" "rows: $order; with references: $refs"
    fi
else
    fail "bench.sh dense --quick" "exit status non-zero: $(tail -n 2 "$TMP/dense.log")"
fi

# ./bench.sh io mpi: a row each for omp, mpi on 1 rank and on 2, with the input's and output's sizes
# (the same output from each) and a plausible time
if have_mpi; then
    IO_N=20000 REPEATS=1 WORK="$TMP/io" ./bench.sh io mpi > "$TMP/io_mpi.log" 2>&1
    io_rc=$?
    io_rows=$(awk -F, '/^(omp|mpi_r1|mpi_r2),/ && $5 > 0 && $6 > 0 && $7 > 0 && $9 > 0 { print $1, $6 }' "$TMP/io_mpi.log")
    if [ "$io_rc" -eq 0 ] && [ "$(wc -l <<< "$io_rows")" -eq 3 ] && [ "$(cut -d' ' -f2 <<< "$io_rows" | sort -u | wc -l)" -eq 1 ]; then
        pass "bench.sh io mpi: omp's, 1 rank's and 2 ranks' rows, the same output size"
    else
        fail "bench.sh io mpi" "exit $io_rc, rows: $(tr '\n' ';' <<< "$io_rows") $(tail -n 2 "$TMP/io_mpi.log")"
    fi
else
    skip "bench.sh io mpi" "no mpirun or no ./mpi"
fi
