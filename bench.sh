#!/usr/bin/env bash
# bench.sh: every measurement of this project, one entry point. `./bench.sh SUBCOMMAND [options]`; the
# subcommands live in bench/cmd/*.sh and share bench/cmd/lib.sh (one provenance header, helpers).
# README.md's Benchmarks section lists what each produces and how long it takes.
set -euo pipefail
export LC_ALL=C
cd "$(dirname "$0")"

usage() {
    cat <<'EOF'
usage: ./bench.sh [SUBCOMMAND] [common options] [the subcommand's options]

subcommands (SUBCOMMAND --help tells more where it has options of its own):
  sweep       backends x thread counts x sizes x scenes: one CSV row per run and a summary CSV
              (the default: ./bench.sh --quick is ./bench.sh sweep --quick)
  targets     omp on the scenes of its targets (the assignment's random scene, mixed, dense, gases),
              one line per target with the measured ratio or rate (BASE_REV=REV, or BASE_DIR=DIR
              of an earlier tree's sources: that omp too, each run right after this tree's)
  phases      omp's step loop phase by phase (--stats), medians of REPEATS runs; BASE_REV or
              BASE_DIR: that tree's omp too, each run right after this tree's
  io          the text path: reading, parsing, formatting and writing, whole process (MB/s);
              `io gpu` adds cuda on gases of 1e7 and 1e8 disks
  exact       --exact against the default step, seq and omp, on dense gases
  mpi         mpi's strong and weak scaling and memory per rank on gases, against omp (needs mpirun)
  accuracy    what accuracy costs in time: sub-steps, --exact and float against the hard-disk
              equation of state (--quick: CI-sized)
  dense       the periodic box's equation of state, fluid to melting, against published references
              (PARTS="fluid loop rungs"; --quick: seconds)
  gpu-check   on a GPU machine: build, make test, compute-sanitizer memcheck
  gpu-perf    on a GPU machine: cuda against omp on gases and the random scene (also gpu-host,
              gpu-big, gpu-profile, gpu-kernels, gpu-targets, gpu-goals, gpu-bytes, gpu-streams: see
              bench/cmd/gpu.sh)
  gpu-sweep   on a GPU machine: the sweeps of REPORT.md in parts of under 10 minutes (small|cuda|big)
  variants    on a GPU machine: cuda.cu's build variants timed against each other
  viewer      the viewer's frame rates in headless Chromium (N and steps as arguments)
  plots       the figures of the committed summaries (needs gnuplot)

common options (before or after the subcommand; each sets the variable its scripts read):
  --repeats K      timed runs per point (REPEATS)
  --threads LIST   omp thread counts (mpi: threads per rank), space- or comma-separated (THREADS)
  --base REV       also time revision REV's build beside this tree, row by row (BASE_REV; io, perf)
  --work DIR       scratch files (WORK; default bench/tmp)
  --help           this text
EOF
}

cmd=sweep given=0
args=()
while [ $# -gt 0 ]; do
    case $1 in
        --repeats) export REPEATS=${2?--repeats needs a value}; shift 2 ;;
        --threads) export THREADS=${2//,/ }; shift 2 ;;
        --base) export BASE_REV=${2?--base needs a revision}; shift 2 ;;
        --work) export WORK=${2?--work needs a folder}; shift 2 ;;
        -h | --help)
            if [ $given = 0 ]; then usage; exit 0; fi
            args+=("$1"); shift ;;
        sweep | targets | phases | io | exact | mpi | accuracy | dense | gpu-sweep | variants | viewer | plots | gpu-*)
            if [ $given = 0 ] && [ ${#args[@]} -eq 0 ]; then cmd=$1 given=1; else args+=("$1"); fi
            shift ;;
        *) args+=("$1"); shift ;;
    esac
done

set -- ${args[@]+"${args[@]}"}
# subcommands without options of their own: --help shows the comment that heads their script
script=bench/cmd/$cmd.sh
case $cmd in gpu-sweep) script=bench/cmd/gpu_sweep.sh ;; gpu-*) script=bench/cmd/gpu.sh ;; esac
if [ "${1:-}" = --help ] && [ "$cmd" = viewer ]; then
    python3 -c 'import ast, sys; print(ast.get_docstring(ast.parse(open(sys.argv[1]).read())))' tools/viewer_bench.py
    exit 0
fi
if [ "${1:-}" = --help ] && [ "$cmd" != sweep ] && [ "$cmd" != accuracy ]; then
    sed -n '2,/^[^#]/p' "$script" | grep '^#' | sed 's/^# \{0,1\}//'
    exit 0
fi
case $cmd in
    sweep | targets | phases | io | exact | mpi | accuracy | dense | variants | plots) exec bash "bench/cmd/$cmd.sh" "$@" ;;
    gpu-sweep) exec bash bench/cmd/gpu_sweep.sh "$@" ;;
    gpu-check | gpu-memcheck | gpu-perf | gpu-host | gpu-big | gpu-profile | gpu-kernels | gpu-targets | gpu-goals | gpu-bytes | gpu-streams | gpu-all)
        exec bash bench/cmd/gpu.sh "${cmd#gpu-}" "$@" ;;
    viewer) exec python3 tools/viewer_bench.py "$@" ;;
    *) echo "bench.sh: unknown subcommand '$cmd' (see ./bench.sh --help)" >&2; exit 1 ;;
esac
