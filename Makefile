# Builds the three backends of the particle-collision simulator and runs the test suite.
# make            seq and omp (and cuda where nvcc exists)
# make test       the quick suite (tests/run.sh): every backend and feature at small sizes, about a
#                 minute on 2 cores; ends with "N passed, N failed"
# make test-all   every check (tests/run.sh --all): the long matrices, 8 mpi ranks, kill trials,
#                 the bench smoke runs
# make golden     regenerate outputs/ (and outputs/periodic/, run with --periodic) from seq (on purpose only)
# make PRECISION=float   only the single-precision builds seq_f32, omp_f32 (and cuda_f32)

CC ?= cc
NVCC ?= nvcc
CFLAGS ?= -std=c99 -O2 -ffp-contract=off -Wall -Wextra
OMPFLAGS ?= -fopenmp
CUDA_ARCH ?= -gencode arch=compute_90,code=sm_90 -gencode arch=compute_80,code=sm_80
NVCCFLAGS ?= -O2 --fmad=false -std=c++17 $(CUDA_ARCH)
LDLIBS = -lm
SANFLAGS = -std=c99 -O1 -g -ffp-contract=off -fsanitize=address,undefined -fno-sanitize-recover=all

HAVE_NVCC := $(shell command -v $(NVCC) >/dev/null 2>&1 && echo yes)
MPICC ?= mpicc
HAVE_MPICC := $(shell command -v $(MPICC) >/dev/null 2>&1 && echo yes)
PROGRAMS = seq omp $(if $(and $(HAVE_NVCC),$(wildcard cuda.cu)),cuda) $(if $(HAVE_MPICC),mpi) \
	$(if $(and $(HAVE_NVCC),$(HAVE_MPICC)),mpi_cuda)
PROGRAMS_F32 = seq_f32 omp_f32 $(if $(and $(HAVE_NVCC),$(wildcard cuda.cu)),cuda_f32)
TOOLS = $(patsubst %.c,%,$(wildcard tools/*.c))

.PHONY: all test test-all golden bench accuracy plots clean tools demo
ifeq ($(PRECISION),float)
all: $(PROGRAMS_F32)
else
all: $(PROGRAMS) $(PROGRAMS_F32) $(TOOLS)
endif
ifneq ($(HAVE_NVCC),yes)
	@echo "cuda skipped: $(NVCC) not found"
endif
ifneq ($(HAVE_MPICC),yes)
	@echo "mpi skipped: $(MPICC) not found (Debian: apt-get install openmpi-bin libopenmpi-dev)"
endif
ifneq ($(and $(HAVE_NVCC),$(HAVE_MPICC)),yes)
	@echo "mpi_cuda skipped: it needs both $(NVCC) and $(MPICC)"
endif

# the layers below the backends (io.h names them): state and physics, the --exact model, the I/O layer
# and driver; every backend links them
CORE = state exact output place input checkpoint io
CORE_SRC = $(CORE:=.c)
HEADERS = common.h exact.h io.h io_internal.h
BASE = $(CORE:=.o)
BASE_F32 = $(CORE:=_f32.o)

$(BASE): %.o: %.c $(HEADERS) Makefile
	$(CC) $(CFLAGS) -c $< -o $@

$(BASE_F32): %_f32.o: %.c $(HEADERS) Makefile
	$(CC) $(CFLAGS) -DSIM_FLOAT -c $< -o $@

OMP_SRC = omp.c omp_broad.c omp_paths.c omp_exact.c omp_team.c
OMP_H = omp_step.h omp_lanes.h omp_team.h
# cuda.cu and the files it includes: the device code phase by phase, the host's parts, mpi_cuda.h
CUDA_SRC = cuda.cu cuda_state.cuh cuda_bin.cuh cuda_rows.cuh cuda_detect.cuh cuda_choose.cuh cuda_move.cuh \
	cuda_buffers.cuh cuda_plan.cuh cuda_launch.cuh cuda_output.cuh mpi_cuda.h

seq_f32: seq.c $(BASE_F32) $(HEADERS) Makefile
	$(CC) $(CFLAGS) -DSIM_FLOAT seq.c $(BASE_F32) -o $@ $(LDLIBS)

omp_f32: $(OMP_SRC) $(BASE_F32) $(HEADERS) $(OMP_H) Makefile
	$(CC) $(CFLAGS) $(OMPFLAGS) -DSIM_FLOAT $(OMP_SRC) $(BASE_F32) -o $@ $(LDLIBS)

cuda_f32: $(CUDA_SRC) $(BASE_F32) $(HEADERS) Makefile
	$(NVCC) $(NVCCFLAGS) -DSIM_FLOAT -Xcompiler -ffp-contract=off cuda.cu $(BASE_F32) -o $@ $(LDLIBS)

seq: seq.c $(BASE) $(HEADERS) Makefile
	$(CC) $(CFLAGS) seq.c $(BASE) -o $@ $(LDLIBS)

omp: $(OMP_SRC) $(BASE) $(HEADERS) $(OMP_H) Makefile
	$(CC) $(CFLAGS) $(OMPFLAGS) $(OMP_SRC) $(BASE) -o $@ $(LDLIBS)

# the MPI backend, run as mpirun -np P ./mpi INPUT (its own objects: mpicc may be another compiler);
# omp's broad phase inside each rank
MPI_SRC = mpi_comm.c mpi_io.c mpi.c omp_broad.c omp_paths.c omp_team.c $(CORE_SRC)
mpi: $(MPI_SRC) $(HEADERS) $(OMP_H) mpi.h mpi_halo.h Makefile
	$(MPICC) $(CFLAGS) $(OMPFLAGS) $(MPI_SRC) -o $@ $(LDLIBS)

# mpi with a GPU for each rank: mpi.c's steps built with MPI_CUDA, cuda.cu's kernels through
# mpi_cuda.cu (nvcc), linked by mpicc with the CUDA runtime
CUDA_LIBDIR ?= $(abspath $(dir $(shell command -v $(NVCC) 2>/dev/null))../lib64)
mpi_cuda: $(MPI_SRC) mpi_cuda.cu mpi_cuda_kernels.cuh mpi_cuda_buffers.cuh $(CUDA_SRC) mpi_halo.h $(HEADERS) $(OMP_H) \
	mpi.h Makefile
	$(NVCC) $(NVCCFLAGS) -Xcompiler -ffp-contract=off -c mpi_cuda.cu -o mpi_cuda_gpu.o
	$(MPICC) $(CFLAGS) $(OMPFLAGS) -DMPI_CUDA $(MPI_SRC) mpi_cuda_gpu.o -o $@ $(LDLIBS) \
		-L$(CUDA_LIBDIR) -Wl,-rpath,$(CUDA_LIBDIR) -lcudart -lstdc++

cuda: $(CUDA_SRC) $(BASE) $(HEADERS) Makefile
	$(NVCC) $(NVCCFLAGS) -Xcompiler -ffp-contract=off cuda.cu $(BASE) -o $@ $(LDLIBS)

# seq with address and undefined-behaviour checks, for the hard cases
seq_san: seq.c $(CORE_SRC) $(HEADERS) Makefile
	$(CC) $(SANFLAGS) seq.c $(CORE_SRC) -o $@ $(LDLIBS)

# omp under ThreadSanitizer (tests/t_62_tsan.sh), built by clang with LLVM's OpenMP runtime (libomp),
# whose Archer tool tells the sanitizer about OpenMP's own synchronisation (gcc's libgomp would give
# false reports); needs clang and libomp-dev
TSAN_CC ?= clang
omp_tsan: $(OMP_SRC) $(CORE_SRC) $(HEADERS) $(OMP_H) Makefile
	$(TSAN_CC) -std=c99 -O1 -g -ffp-contract=off -fsanitize=thread -fopenmp $(OMP_SRC) $(CORE_SRC) -o $@ $(LDLIBS)

# omp with the portable C alone (SIM_NO_SIMD: no SSE2, AVX2 or AVX-512F code, as other processors
# build it), for tests/t_72_broad.sh
omp_portable: $(OMP_SRC) $(BASE) $(HEADERS) $(OMP_H) Makefile
	$(CC) $(CFLAGS) $(OMPFLAGS) -DSIM_NO_SIMD $(OMP_SRC) $(BASE) -o $@ $(LDLIBS)

tools/%: tools/%.c common.h tools/output_error.h Makefile
	$(CC) $(CFLAGS) $< -o $@ $(LDLIBS)

# the generator fills the bands of a large scene in parallel
tools/gen: tools/gen.c Makefile
	$(CC) $(CFLAGS) $(OMPFLAGS) $< -o $@ $(LDLIBS)

# the formatter check calls io.c's own io_format_line
tools/fmtcheck: tools/fmtcheck.c $(BASE) $(HEADERS) Makefile
	$(CC) $(CFLAGS) tools/fmtcheck.c $(BASE) -o $@ $(LDLIBS)

test: all seq_san
	@bash tests/run.sh

test-all: all seq_san
	@bash tests/run.sh --all

# inputs/periodic/: scenes of the periodic box (SPEC.md 7), run with --periodic (the input format has
# no mark of it)
golden: seq
	@for f in inputs/*.in; do ./seq "$$f" --quiet > outputs/$$(basename "$$f" .in).out || exit 1; done
	@for f in inputs/periodic/*.in; do \
		./seq "$$f" --periodic --quiet > outputs/periodic/$$(basename "$$f" .in).out || exit 1; done
	@echo "outputs/ regenerated from seq"

bench: all
	./bench.sh --quick

# the accuracy ladder against the hard-disk equation of state (REPORT.md 7); about 5 minutes on 2 cores
accuracy: all
	./bench.sh accuracy

# the figures REPORT.md shows, from the committed bench/cpu*.summary.csv and bench/accuracy.csv (needs
# gnuplot: apt-get install gnuplot-nox); the CPU's N = 1e6 points come from their longer runs
plots:
	@./bench.sh plots --merge bench/cpu bench/cpu.summary.csv bench/cpu_1e6.summary.csv
	@if [ -f bench/accuracy.csv ]; then ./bench.sh accuracy --plot bench/accuracy.csv; fi

# the viewer's demo: a gas whose few fast disks heat it, every step printed (viewer/demo.out, 33 MB)
demo: omp
	./omp viewer/demo.in --quiet > viewer/demo.out
	@echo "viewer/demo.out: 300 steps of 2000 disks. To watch them, open viewer/index.html in a browser"
	@echo "and choose (or drop on it) viewer/demo.in and viewer/demo.out; or, in one command:"
	@echo "  chromium --allow-file-access-from-files 'file://$(CURDIR)/viewer/index.html?in=demo.in&src=demo.out'"
	@echo "  python3 -m http.server 8000   # in this folder; then http://localhost:8000/viewer/index.html?in=demo.in&src=demo.out"

clean:
	rm -f seq omp cuda mpi mpi_cuda seq_san omp_tsan omp_portable $(BASE) $(BASE_F32) $(PROGRAMS_F32) $(TOOLS) viewer/demo.out
