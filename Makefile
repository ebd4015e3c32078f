# Builds the three backends of the particle-collision simulator and runs the test suite.
# make            seq and omp (and cuda where nvcc exists)
# make test       the whole suite (tests/run.sh); ends with "N passed, N failed"
# make golden     regenerate outputs/ from seq (on purpose only)
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
PROGRAMS = seq omp $(if $(and $(HAVE_NVCC),$(wildcard cuda.cu)),cuda) $(if $(HAVE_MPICC),mpi)
PROGRAMS_F32 = seq_f32 omp_f32 $(if $(and $(HAVE_NVCC),$(wildcard cuda.cu)),cuda_f32)
TOOLS = $(patsubst %.c,%,$(wildcard tools/*.c))

.PHONY: all test golden bench accuracy plots clean tools demo
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

# the layers below the backends: state.c (messages, memory, the state's arrays), io.c (the driver)
io.o: io.c io.h common.h exact.h Makefile
	$(CC) $(CFLAGS) -c io.c -o $@

io_f32.o: io.c io.h common.h exact.h Makefile
	$(CC) $(CFLAGS) -DSIM_FLOAT -c io.c -o $@

state.o: state.c common.h Makefile
	$(CC) $(CFLAGS) -c state.c -o $@

state_f32.o: state.c common.h Makefile
	$(CC) $(CFLAGS) -DSIM_FLOAT -c state.c -o $@

BASE = io.o state.o
BASE_F32 = io_f32.o state_f32.o
HEADERS = common.h io.h exact.h
OMP_SRC = omp.c omp_broad.c omp_paths.c omp_exact.c omp_team.c
OMP_H = omp_step.h omp_lanes.h omp_team.h

seq_f32: seq.c $(BASE_F32) $(HEADERS) Makefile
	$(CC) $(CFLAGS) -DSIM_FLOAT seq.c $(BASE_F32) -o $@ $(LDLIBS)

omp_f32: $(OMP_SRC) $(BASE_F32) $(HEADERS) $(OMP_H) Makefile
	$(CC) $(CFLAGS) $(OMPFLAGS) -DSIM_FLOAT $(OMP_SRC) $(BASE_F32) -o $@ $(LDLIBS)

cuda_f32: cuda.cu $(BASE_F32) common.h io.h Makefile
	$(NVCC) $(NVCCFLAGS) -DSIM_FLOAT -Xcompiler -ffp-contract=off cuda.cu $(BASE_F32) -o $@ $(LDLIBS)

seq: seq.c $(BASE) $(HEADERS) Makefile
	$(CC) $(CFLAGS) seq.c $(BASE) -o $@ $(LDLIBS)

omp: $(OMP_SRC) $(BASE) $(HEADERS) $(OMP_H) Makefile
	$(CC) $(CFLAGS) $(OMPFLAGS) $(OMP_SRC) $(BASE) -o $@ $(LDLIBS)

# the MPI backend, run as mpirun -np P ./mpi INPUT (its own objects: mpicc may be another compiler);
# omp's broad phase inside each rank
MPI_SRC = mpi.c mpi_io.c omp_broad.c omp_paths.c omp_team.c io.c state.c
mpi: $(MPI_SRC) $(HEADERS) $(OMP_H) mpi.h Makefile
	$(MPICC) $(CFLAGS) $(OMPFLAGS) $(MPI_SRC) -o $@ $(LDLIBS)

cuda: cuda.cu $(BASE) common.h io.h Makefile
	$(NVCC) $(NVCCFLAGS) -Xcompiler -ffp-contract=off cuda.cu $(BASE) -o $@ $(LDLIBS)

# seq with address and undefined-behaviour checks, for the hard cases
seq_san: seq.c io.c state.c $(HEADERS) Makefile
	$(CC) $(SANFLAGS) seq.c io.c state.c -o $@ $(LDLIBS)

# omp under ThreadSanitizer (tests/t_62_tsan.sh), built by clang with LLVM's OpenMP runtime (libomp),
# whose Archer tool tells the sanitizer about OpenMP's own synchronisation (gcc's libgomp would give
# false reports); needs clang and libomp-dev
TSAN_CC ?= clang
omp_tsan: $(OMP_SRC) io.c state.c $(HEADERS) $(OMP_H) Makefile
	$(TSAN_CC) -std=c99 -O1 -g -ffp-contract=off -fsanitize=thread -fopenmp $(OMP_SRC) io.c state.c -o $@ $(LDLIBS)

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
tools/fmtcheck: tools/fmtcheck.c $(BASE) common.h io.h Makefile
	$(CC) $(CFLAGS) tools/fmtcheck.c $(BASE) -o $@ $(LDLIBS)

test: all seq_san
	@bash tests/run.sh

golden: seq
	@for f in inputs/*.in; do ./seq "$$f" --quiet > outputs/$$(basename "$$f" .in).out || exit 1; done
	@echo "outputs/ regenerated from seq"

bench: all
	./bench.sh --quick

# the accuracy ladder against the hard-disk equation of state (REPORT.md 7); about 5 minutes on 2 cores
accuracy: all
	./bench.sh accuracy

# figures from the committed bench/*.summary.csv and bench/accuracy.csv (needs gnuplot: apt-get install
# gnuplot-nox)
# sweeps run in parts (the CPU's N = 1e6 again with longer runs; the H100's in ./bench.sh gpu-sweep): a
# point in several files is taken from the later one
GPU_SUMMARIES = bench/gpu_h100.summary.csv \
    $(patsubst %,bench/gpu_h100_%.summary.csv,threads cuda 1e7_random 1e7 1e8 1e8b)
plots:
	@./bench.sh plots --merge bench/cpu bench/cpu.summary.csv bench/cpu_1e6.summary.csv
	@./bench.sh plots --merge bench/gpu_h100 $(GPU_SUMMARIES)
	@if [ -f bench/accuracy.csv ]; then ./bench.sh accuracy --plot bench/accuracy.csv; fi

# the viewer's demo: a gas whose few fast disks heat it, every step printed (viewer/demo.out, 33 MB)
demo: omp
	./omp viewer/demo.in --quiet > viewer/demo.out
	@echo "viewer/demo.out: 300 steps of 2000 disks. To watch them, open viewer/index.html in a browser"
	@echo "and choose (or drop on it) viewer/demo.in and viewer/demo.out; or, in one command:"
	@echo "  chromium --allow-file-access-from-files 'file://$(CURDIR)/viewer/index.html?in=demo.in&src=demo.out'"
	@echo "  python3 -m http.server 8000   # in this folder; then http://localhost:8000/viewer/index.html?in=demo.in&src=demo.out"

clean:
	rm -f seq omp cuda mpi seq_san omp_tsan $(BASE) $(BASE_F32) $(PROGRAMS_F32) $(TOOLS) viewer/demo.out
