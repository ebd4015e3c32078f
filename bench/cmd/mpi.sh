#!/usr/bin/env bash
# ./bench.sh mpi: the MPI backend's scaling on gases (fraction 0.2, speeds up to r/2), against omp on
# as many threads, one CSV row per measurement and a summary line per target at the end:
#   strong  a gas of STRONG_N disks (default 4e6 on 16 or more cores, 4e5 below) at each rank count
#           of RANKS x each count of THREADS per rank, and omp at the same total of threads;
#   weak    PER_RANK disks (default 2.5e5) per rank at each rank count of RANKS;
#   memory  a gas of MEM_N disks (default 2e6) at 1 and 4 ranks: the largest rank's peak memory;
#   copies  RANKS independent copies of omp on one thread each (a gas of PER_RANK disks, one core each),
#           at once: what sharing the machine alone costs, the bound of weak scaling (not in the default;
#           its rows give the slowest copy's step loop as best_loop_s, the mean as median_loop_s);
#   contention RANKS copies at once, one a core, of loops bound by latency, by issue slots, by the
#           core's L2 and by DRAM (tools/contend; CONTEND_KINDS picks): how much of a core each keeps
#           when the others run, without any program of ours; then the issue-bound loop on core 0 beside
#           one on each other core, which finds cores that are hardware threads of one physical core
#           (not in the default; rows give the slowest copy's seconds as best_loop_s, the mean as
#           median_loop_s);
#   cachesim how much memory one rank's step reads from beyond its cache: omp on one thread, then one
#           rank of mpi (./mpi alone, one thread), a gas of PER_RANK disks, under valgrind's cache simulator with a last-level cache of each size of
#           CACHE_MB (default "16 128": a sixteenth of a 300 MB L3, and most of it), run for 2 and for 6
#           steps; the difference in last-level misses over the 4 steps, in bytes a disk a step, is what
#           a step reads or writes beyond that cache (not in the default; needs valgrind; the rows give
#           those bytes as bytes_per_step, the cache's MB as largest_rank_mb);
#   turns   this tree against an earlier one (BASE_REV, or BASE_DIR: a folder holding an earlier tree's
#           Makefile and sources, for a copy without git), in turn, TURNS rounds (default 3): one copy of
#           omp on one thread alone, the slowest of P copies at once (one a core), mpi on one rank and on
#           P ranks (PER_RANK disks a rank; P the largest of RANKS) (not in the default; rows give the
#           seconds of each, the base's with program omp_base and mpi_base);
#   gpu     GPU ranks (mpi_cuda, a GPU a rank) against cuda on one GPU: a gas of GPU_N disks (default
#           1e8) on each count of GPU_RANKS (default 1 to the machine's GPUs), then GPU_PER_RANK disks
#           (default 1e8) a GPU at each count of GPU_WEAK_RANKS (default GPU_RANKS) (not in the default;
#           needs nvcc, mpicc and GPUs);
#   gpu-big a gas of BIG_N disks (default 1e9), BIG_STEPS steps (default 10), on BIG_RANKS GPU ranks
#           (default the machine's GPUs): the generator's seconds (on all cores), then one run (REPEATS,
#           no warm-up) whose output goes to MPI_SINK, its text phases and memory (not in the default;
#           needs nvcc, mpicc and GPUs);
#   balance the largest count of RANKS on a gas of PER_RANK disks a rank while a busy loop shares the
#           last rank's core: the cuts placed by count only (--balance 0) against moved by measured
#           time every 4 steps (--balance 4) (not in the default).
# Each point is REPEATS runs (default 3) after WARMUPS discarded warm-ups (default 1); rows give the best and median
# step loop (the program's own seconds) and the best whole process (wall clock: reading, steps,
# writing the output into a file: omp through its stdout, mpi with --output). mpi's rows add the bytes sent between ranks a step, the rounds of the choice a step and
# the largest rank's and all ranks' peak memory (mpi --stats).
#   ./bench.sh mpi                          all three
#   PARTS="strong" RANKS="1 4 16" ./bench.sh mpi
# Variables: PARTS ("strong weak memory"), RANKS (default: powers of two up to the cores), THREADS
# (threads per rank, default "1"), STEPS (20), STRONG_N, PER_RANK, MEM_N, REPEATS, WORK (bench/tmp).
# MPIRUN_FLAGS adds options to mpirun (default "--bind-to core" where ranks x threads fit the cores);
# MPI_ARGS adds options to mpi (e.g. "--balance 4": the cuts moved by measured time every 4 steps);
# MPI_SINK is the file mpi writes its output into (--output; default one in WORK; /dev/null: none).
set -euo pipefail
cd "$(dirname "$0")/../.."
die() { echo "bench.sh mpi: $*" >&2; exit 1; }
. bench/cmd/lib.sh

export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
CORES=$(nproc)
REPEATS=${REPEATS:-3}
WARMUPS=${WARMUPS:-1}
PARTS=${PARTS:-"strong weak memory"}
THREADS=${THREADS:-1}
STEPS=${STEPS:-20}
WORK=${WORK:-bench/tmp}
if [ -z "${RANKS:-}" ]; then
    RANKS=1
    for ((p = 2; p <= CORES; p *= 2)); do RANKS="$RANKS $p"; done
fi
if [ "$CORES" -ge 16 ]; then STRONG_N=$(integer "${STRONG_N:-4e6}"); else STRONG_N=$(integer "${STRONG_N:-4e5}"); fi
PER_RANK=$(integer "${PER_RANK:-2.5e5}")
MEM_N=$(integer "${MEM_N:-2e6}")

command -v mpirun > /dev/null || die "no mpirun (apt-get install openmpi-bin libopenmpi-dev)"
make -s omp mpi tools/gen tools/contend > /dev/null
[ -x ./mpi ] || die "./mpi was not built (no mpicc?)"
case " $PARTS " in
    *" gpu "* | *" gpu-big "*)
        make -s cuda mpi_cuda > /dev/null
        GPU_RANKS=${GPU_RANKS:-$(seq -s ' ' 1 "$(nvidia-smi -L 2> /dev/null | wc -l)")} ;;
esac
mkdir -p "$WORK"
machine_provenance "$(cut -d' ' -f1-3 /proc/loadavg)" "$CORES"
echo "# mpirun: $(mpirun --version 2>/dev/null | head -n 1); REPEATS=$REPEATS STEPS=$STEPS MPI_ARGS=${MPI_ARGS:-}"
echo "part,program,ranks,threads,n,steps,best_loop_s,median_loop_s,best_wall_s,loop_particle_steps_per_s,bytes_per_step,rounds_per_step,largest_rank_mb,all_ranks_mb,work_mean_s,work_max_s,wait_mean_s"

gas() { # N: the input of a gas of N disks (made once)
    local f=$WORK/mpi_gas_$1_$STEPS.in # the steps in its name: a gas made for other steps is not reused
    [ -s "$f" ] || tools/gen "$1" --fraction 0.2 --speed 0.5 --steps "$STEPS" --seed 3 > "$f"
    echo "$f"
}
# The wall clock around a run: bash's EPOCHREALTIME (seconds with six decimals) without its point,
# in microseconds; no process is started for it (date's start would be timed too, a few ms here).
[ -n "${EPOCHREALTIME:-}" ] || die "bash 5 or later is needed (EPOCHREALTIME)"
best_of() { printf '%s\n' "$@" | sort -g | head -1; }
median_of() { printf '%s\n' "$@" | sort -g | sed -n "$((($# + 1) / 2))p"; }
slowest_and_mean() { sort -g | awk '{ s += $1; m = $1 } END { printf "%s %.4f\n", m, s / NR }'; } # seconds on stdin
stat_of() { sed -n "s/.*$2.*/\1/p" "$1" | tail -n 1; }
loop_stdin() { sed -n 's/.* \([0-9.e+-]*\) s step loop.*/\1/p' | tail -n 1; } # loop_seconds of stdin

# run PART PROGRAM RANKS THREADS N INPUT: one CSV row; LOOP_RATE is left with its best rate
run() {
    local part=$1 prog=$2 ranks=$3 threads=$4 n=$5 input=$6 k s e walls=() loops=() cmd sink=${MPI_SINK:-$WORK/mpi_bench.out}
    if [ "$prog" = omp ]; then
        cmd=(./omp "$input" --stats --threads "$threads")
    elif [ "$prog" = cuda ]; then
        cmd=(./cuda "$input" --stats)
    elif [ "$prog" = mpi_cuda ]; then
        # shellcheck disable=SC2206
        cmd=(mpirun -np "$ranks" --bind-to none ./mpi_cuda "$input" --stats --output "$sink" ${MPI_ARGS:-})
        sink=/dev/null
    else
        local flags=${MPIRUN_FLAGS:-}
        if [ -z "${MPIRUN_FLAGS+x}" ]; then
            if [ $((ranks * threads)) -le "$CORES" ]; then
                flags="--bind-to core --map-by slot:PE=$threads"
            else
                flags="--oversubscribe --bind-to none"
            fi
        fi
        # shellcheck disable=SC2206
        cmd=(mpirun -np "$ranks" $flags ./mpi "$input" --stats --threads "$threads" --output "$sink" ${MPI_ARGS:-})
        sink=/dev/null
    fi
    echo "# ${cmd[*]}"
    for ((k = 1 - WARMUPS; k <= REPEATS; k++)); do
        s=${EPOCHREALTIME/[.,]/}
        "${cmd[@]}" > "$sink" 2> "$WORK/mpi_last.err" || die "failed: ${cmd[*]}: $(head -c 300 "$WORK/mpi_last.err")"
        e=${EPOCHREALTIME/[.,]/}
        [ "$k" -le 0 ] && continue
        walls+=("$(awk -v a="$s" -v b="$e" 'BEGIN { printf "%.4f", (b - a) / 1e6 }')")
        loops+=("$(loop_seconds "$WORK/mpi_last.err")")
    done
    local bl ml bw
    bl=$(best_of "${loops[@]}") ml=$(median_of "${loops[@]}") bw=$(best_of "${walls[@]}")
    local err=$WORK/mpi_last.err
    LOOP_RATE=$(awk -v n="$n" -v s="$STEPS" -v l="$bl" 'BEGIN { printf "%.4g", n * s / l }')
    printf '%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s\n' "$part" "$prog" "$ranks" "$threads" "$n" "$STEPS" \
        "$bl" "$ml" "$bw" "$LOOP_RATE" \
        "$(stat_of "$err" '; \([0-9.e+]*\) bytes sent between ranks a step')" \
        "$(stat_of "$err" '(\([0-9.e+]*\) a step)')" \
        "$(stat_of "$err" 'largest rank \([0-9.]*\) MB')" "$(stat_of "$err" 'all ranks \([0-9.]*\) MB')" \
        "$(stat_of "$err" 'outside MPI calls [0-9.]* to [0-9.]* s (mean \([0-9.]*\))')" \
        "$(stat_of "$err" 'outside MPI calls [0-9.]* to \([0-9.]*\) s')" \
        "$(stat_of "$err" 'inside them [0-9.]* to [0-9.]* s (mean \([0-9.]*\))')"
    # mpi: where the last run's steps went, phase by phase (the steps' slowest rank against the mean)
    case $prog in
        omp | cuda) ;;
        *) sed -n -e 's/^mpi[_a-z]*: the steps. phases/# the last run'"'"'s phases/p' \
               -e 's/^mpi_cuda: the host.s seconds in each GPU call/# the last run'"'"'s host seconds in each GPU call/p' \
               -e 's/^mpi_cuda: rank-steps whose/# the last run'"'"'s rank-steps whose/p' "$err" ;;
    esac
}

summary=()
for part in $PARTS; do
    case $part in
        strong)
            input=$(gas "$STRONG_N")
            for t in $THREADS; do
                for p in $RANKS; do
                    [ $((p * t)) -le "$CORES" ] || continue
                    run strong omp 1 $((p * t)) "$STRONG_N" "$input"
                    omp_rate=$LOOP_RATE
                    run strong mpi "$p" "$t" "$STRONG_N" "$input"
                    summary+=("strong N=$STRONG_N: mpi ${p}x$t $LOOP_RATE particle-steps/s against omp $((p * t)) threads $omp_rate: $(awk -v a="$LOOP_RATE" -v b="$omp_rate" 'BEGIN { printf "%.2f", a / b }')x")
                done
            done
            ;;
        weak)
            base=""
            for p in $RANKS; do
                n=$((PER_RANK * p))
                run weak mpi "$p" 1 "$n" "$(gas "$n")"
                [ -z "$base" ] && base=$LOOP_RATE
                summary+=("weak $PER_RANK a rank: $p ranks $LOOP_RATE particle-steps/s, efficiency $(awk -v a="$LOOP_RATE" -v b="$base" -v p="$p" 'BEGIN { printf "%.0f%%", 100 * a / (p * b) }')")
            done
            ;;
        gpu)
            [ -x ./mpi_cuda ] || die "./mpi_cuda was not built (it needs nvcc and mpicc)"
            n=$(integer "${GPU_N:-1e8}") per=$(integer "${GPU_PER_RANK:-1e8}")
            input=$(gas "$n")
            run gpu-strong cuda 1 1 "$n" "$input"
            one=$LOOP_RATE
            for p in $GPU_RANKS; do
                run gpu-strong mpi_cuda "$p" 1 "$n" "$input"
                summary+=("gpu strong N=$n: mpi_cuda on $p GPUs $LOOP_RATE particle-steps/s against cuda on one GPU $one: $(awk -v a="$LOOP_RATE" -v b="$one" 'BEGIN { printf "%.2fx", a / b }')")
            done
            base=""
            for p in ${GPU_WEAK_RANKS:-$GPU_RANKS}; do
                run gpu-weak mpi_cuda "$p" 1 $((per * p)) "$(gas $((per * p)))"
                [ -z "$base" ] && base=$LOOP_RATE
                summary+=("gpu weak $per disks a GPU: $p GPUs $LOOP_RATE particle-steps/s, efficiency $(awk -v a="$LOOP_RATE" -v b="$base" -v p="$p" 'BEGIN { printf "%.0f%%", 100 * a / (p * b) }') of one GPU's")
            done
            ;;
        gpu-big)
            [ -x ./mpi_cuda ] || die "./mpi_cuda was not built (it needs nvcc and mpicc)"
            n=$(integer "${BIG_N:-1e9}") p=${BIG_RANKS:-${GPU_RANKS##* }} steps=${BIG_STEPS:-10}
            s=${EPOCHREALTIME/[.,]/}
            input=$(STEPS=$steps gas "$n")
            e=${EPOCHREALTIME/[.,]/}
            echo "# tools/gen $n --fraction 0.2 --speed 0.5 --steps $steps --seed 3 ($(nproc) cores): $(awk -v a="$s" -v b="$e" 'BEGIN { printf "%.1f", (b - a) / 1e6 }') s, $(stat -c %s "$input") bytes (0 s: made before)"
            STEPS=$steps WARMUPS=0 run gpu-big mpi_cuda "$p" 1 "$n" "$input"
            sed -n 's/^mpi_cuda: \(input read.*\|.*peak memory.*\|the run .*\)/# \1/p' "$WORK/mpi_last.err"
            summary+=("gpu big N=$n, $steps steps, $p GPUs: step loop $LOOP_RATE particle-steps/s; $(sed -n 's/^mpi_cuda: \(input read.*\)/\1/p' "$WORK/mpi_last.err")")
            ;;
        memory)
            input=$(gas "$MEM_N")
            run memory mpi 1 1 "$MEM_N" "$input"
            one=$(stat_of "$WORK/mpi_last.err" 'largest rank \([0-9.]*\) MB')
            run memory mpi 4 1 "$MEM_N" "$input"
            four=$(stat_of "$WORK/mpi_last.err" 'largest rank \([0-9.]*\) MB')
            summary+=("memory N=$MEM_N: largest rank at 4 ranks $four MB against 1 rank $one MB: $(awk -v a="$four" -v b="$one" 'BEGIN { printf "%.0f%%", 100 * a / b }')")
            ;;
        copies)
            input=$(gas "$PER_RANK")
            one=""
            for p in $RANKS; do
                echo "# $p copies at once: taskset -c CORE ./omp $input --threads 1"
                for ((c = 0; c < p; c++)); do
                    taskset -c "$c" ./omp "$input" --threads 1 > /dev/null 2> "$WORK/mpi_copy$c.err" &
                done
                wait
                read -r worst mean < <(for ((c = 0; c < p; c++)); do loop_seconds "$WORK/mpi_copy$c.err"; done | slowest_and_mean)
                echo "copies,omp,$p,1,$PER_RANK,$STEPS,$worst,$mean,,,,,,"
                [ -z "$one" ] && one=$worst
                summary+=("copies of omp at once, $PER_RANK disks each: $p copies, slowest step loop $worst s against $one s alone: $(awk -v a="$one" -v b="$worst" 'BEGIN { printf "%.0f%%", 100 * a / b }')")
            done
            ;;
        turns)
            base=$WORK/turns_base
            if [ -n "${BASE_REV:-}" ]; then
                build_revision "$BASE_REV" "$base" "$WORK/turns_build.log" "omp mpi" || die "the build of $BASE_REV failed"
            else
                [ -n "${BASE_DIR:-}" ] || die "turns needs BASE_REV or BASE_DIR"
                rm -rf "$base" && cp -r "$BASE_DIR" "$base"
                make -C "$base" -j"$CORES" omp mpi > "$WORK/turns_build.log" 2>&1 || die "the build in $BASE_DIR failed"
            fi
            echo "# base: ${BASE_REV:-$BASE_DIR}"
            p=${RANKS##* }
            one=$(gas "$PER_RANK") all=$(gas $((PER_RANK * p)))
            for ((k = 1; k <= ${TURNS:-3}; k++)); do
                for d in . "$base"; do
                    sfx=""
                    [ "$d" = . ] || sfx=_base
                    alone=$(taskset -c 1 "$d/omp" "$one" --threads 1 2>&1 > /dev/null | loop_stdin)
                    for ((c = 0; c < p; c++)); do
                        taskset -c "$c" "$d/omp" "$one" --threads 1 > /dev/null 2> "$WORK/mpi_copy$c.err" &
                    done
                    wait
                    read -r worst mean < <(for ((c = 0; c < p; c++)); do loop_seconds "$WORK/mpi_copy$c.err"; done | slowest_and_mean)
                    m1=$(mpirun -np 1 --bind-to core "$d/mpi" "$one" --threads 1 --output "$WORK/mpi_bench.out" 2>&1 | loop_stdin)
                    mp=$(mpirun -np "$p" --bind-to core "$d/mpi" "$all" --threads 1 --output "$WORK/mpi_bench.out" 2>&1 | loop_stdin)
                    echo "turns,omp$sfx,1,1,$PER_RANK,$STEPS,$alone,,,,,,,,,,"
                    echo "turns,omp$sfx copies,$p,1,$PER_RANK,$STEPS,$worst,$mean,,,,,,,,,"
                    echo "turns,mpi$sfx,1,1,$PER_RANK,$STEPS,$m1,,,,,,,,,,"
                    echo "turns,mpi$sfx,$p,1,$((PER_RANK * p)),$STEPS,$mp,,,,,,,,,,"
                    summary+=("turns round $k, $([ -n "$sfx" ] && echo base || echo this tree): omp alone $alone s, slowest of $p copies $worst s ($(awk -v a="$alone" -v b="$worst" 'BEGIN { printf "%.0f%%", 100 * a / b }')); mpi 1 rank $m1 s, $p ranks $mp s (weak $(awk -v a="$m1" -v b="$mp" 'BEGIN { printf "%.0f%%", 100 * a / b }'))")
                done
            done
            ;;
        contention)
            for kind in ${CONTEND_KINDS:-compute issue cache memory}; do
                one=""
                for p in $RANKS; do
                    for ((c = 0; c < p; c++)); do
                        taskset -c "$c" tools/contend "$kind" > "$WORK/contend$c.out" &
                    done
                    wait
                    read -r worst mean < <(for ((c = 0; c < p; c++)); do cut -d' ' -f1 "$WORK/contend$c.out"; done | slowest_and_mean)
                    echo "contention,contend $kind,$p,1,,,$worst,$mean,,,,,,"
                    [ -z "$one" ] && one=$worst
                    summary+=("contention, $kind-bound loop: $p copies at once, slowest $worst s, mean $mean s against $one s alone: $(awk -v a="$one" -v b="$worst" -v m="$mean" 'BEGIN { printf "%.0f%% (slowest), %.0f%% (mean)", 100 * a / b, 100 * a / m }')")
                done
            done
            # which cores share one core's issue slots (hardware threads of one physical core, which a
            # virtual machine's own topology may not show): the issue-bound loop on core 0 beside core c
            one=$(taskset -c 0 tools/contend issue | cut -d' ' -f1)
            shared=""
            for ((c = 1; c < CORES; c++)); do
                taskset -c 0 tools/contend issue > "$WORK/contend0.out" &
                taskset -c "$c" tools/contend issue > "$WORK/contend$c.out" &
                wait
                t=$(cut -d' ' -f1 "$WORK/contend0.out")
                echo "contention,contend issue with core $c,2,1,,,$t,$t,,,,,,"
                awk -v a="$one" -v b="$t" 'BEGIN { exit !(a / b < 0.75) }' && shared="$shared $c"
            done
            summary+=("contention, issue-bound loop on core 0 beside one on core c: below 75% of its speed alone ($one s) for c in {${shared# }} (none: no two of these cores share a physical core)")
            ;;
        cachesim)
            command -v valgrind > /dev/null || die "cachesim needs valgrind (apt-get install valgrind)"
            for s in 2 6; do
                tools/gen "$PER_RANK" --fraction 0.2 --speed 0.5 --steps "$s" --seed 3 > "$WORK/cachesim_$s.in"
            done
            # omp, then one rank of mpi (./mpi run alone: one process, no mpirun, its strip the box)
            for mb in ${CACHE_MB:-16 128}; do
                for prog in omp mpi; do
                    misses=()
                    for s in 2 6; do
                        f=$WORK/cachesim_$s.in
                        valgrind --tool=cachegrind --cache-sim=yes --LL=$((mb << 20)),16,64 \
                            --cachegrind-out-file=/dev/null "./$prog" "$f" --threads 1 > /dev/null 2> "$WORK/cachesim.err" ||
                            die "valgrind failed: $(tail -n 3 "$WORK/cachesim.err")"
                        misses+=("$(sed -n 's/.*LL misses: *\([0-9,]*\).*/\1/p' "$WORK/cachesim.err" | tr -d ,)")
                    done
                    per=$(awk -v a="${misses[0]}" -v b="${misses[1]}" -v n="$PER_RANK" 'BEGIN { d = b > a ? b - a : 0; printf "%.1f", d * 64 / (4 * n) }')
                    echo "cachesim,$prog,1,1,$PER_RANK,4,,,,,$per,,$mb,,,,"
                    if [ "$prog" = omp ]; then
                        summary+=("cachesim, a gas of $PER_RANK disks on one thread, a $mb MB last-level cache: ${misses[0]} misses over 2 steps, ${misses[1]} over 6: $per bytes a disk a step beyond it")
                    else
                        summary+=("cachesim, mpi, one rank of $PER_RANK disks on one thread, a $mb MB last-level cache: ${misses[0]} misses over 2 steps, ${misses[1]} over 6: $per bytes a disk a step beyond it")
                    fi
                done
            done
            ;;
        balance)
            p=${RANKS##* } n=$((PER_RANK * ${RANKS##* }))
            input=$(gas "$n")
            echo "# a busy loop on core $((p - 1)) (taskset -c $((p - 1)) sh -c 'while :; do :; done')"
            taskset -c $((p - 1)) sh -c 'while :; do :; done' &
            hog=$!
            rates=()
            for k in 0 4; do
                MPI_ARGS="--balance $k" run balance mpi "$p" 1 "$n" "$input"
                rates+=("$LOOP_RATE")
            done
            kill "$hog"
            summary+=("balance, $p ranks, the last one's core shared with a busy loop: --balance 0 ${rates[0]}, --balance 4 ${rates[1]} particle-steps/s: $(awk -v a="${rates[1]}" -v b="${rates[0]}" 'BEGIN { printf "%.2f", a / b }')x")
            ;;
        *) die "unknown part '$part' (strong, weak, memory, copies, contention, cachesim, turns, balance)" ;;
    esac
done
for line in "${summary[@]}"; do echo "# $line"; done
