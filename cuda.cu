/* cuda.cu: the CUDA backend.
 *
 * Every phase of a step runs on the device, and the device never waits for the host. The host launches
 * steps in batches of up to BATCH (a whole batch as one CUDA graph), two batches ahead, and reads one
 * control record per batch (the largest speed, the counters) while the next batch runs. From that
 * speed, a batch or two old, it plans the launch sizes: the most time slices and the finest grid a
 * step may use. Each step's first kernel
 * fits its grid to the largest speed of its own disks within that plan, so the grid is always valid.
 * A step whose pair events overflow the event list is refused before it writes the state; the steps
 * launched after it then get an empty grid, write only scratch buffers and commit nothing, and the
 * host runs them again with a larger list. A step:
 *   bin      each disk's path over the step is cut into K time slices; each slice is binned by its
 *            midpoint into square cells wide enough that any pair SPEC.md 3.2 finds within that slice
 *            lies in neighbouring cells (see grid_fit); a counting sort orders the (slice, cell)
 *            entries: count, exclusive scan, place. A disk 2^l times slower than the fastest takes
 *            slices 2^l times longer (speed levels, disk_level): it moves no farther in one of them
 *            than the fastest disk in a slice, so the same cells hold it, with fewer entries. With
 *            K > 1 in the walled box each cell is keyed in SUB_X columns (Grid.sx), so that a disk's
 *            neighbours lie within a cell's width to each side, not the rest of its own and one more
 *   place    with K = 1 the disks themselves move into cell order, for locality, in a batch's first
 *            step; its later steps search them where the move before left them, through the order of
 *            their cell places (SLOT_STEPS); with K > 1 each entry's slot and midpoint take that order
 *   detect   every pair in the 3x3 neighbouring cells (or columns) of the same slice (wall events
 *            were computed in place), and each entry against the slower levels' slices that contain
 *            its own, screened by whether their paths come within 2r (and margins) during the slice;
 *            a pair is kept only in the slice of its faster disk that holds its event time, so it
 *            is found once; each block appends its events to the step's list together
 *   choose   rounds of "accept every event that is the smallest remaining one of each of its disks"
 *            (SPEC.md 3.3); the last rounds run in one block
 *   windows  with K > 1 and disks enough, bin, place, detect and choose run once per time window (a
 *            run of slices, window_start), in time order: disks the choice of a window takes are left
 *            out of the later ones, so a dense fast scene, where most disks collide early in the step,
 *            bins and tests few disks after its first slices
 *   move     each disk from the old buffers into the new ones; the pair physics is computed by both
 *            partners with the lower original index as i, so both see the same arithmetic. With K = 1
 *            (a gas) it also keys each disk's cell for the next step and starts its event keys in its
 *            slot, so that the next step only counts the keys (count_kernel) before its scan
 * Event keys compare by value only (t, kind, i, j), so nothing depends on thread order.
 * This file is the host's side; the device code, included below, lies in one file a phase:
 * cuda_state.cuh (buffers, speed levels, windows, the grid's fit, event keys), cuda_bin.cuh (the step's
 * gate, bin, scan and place), cuda_detect.cuh, cuda_choose.cuh and cuda_move.cuh.
 */
#include "io.h"
#include "mpi_cuda.h" /* a GPU rank's records (the move, RankMove) */

#include <cub/cub.cuh>
#include <cuda/functional>
#include <cooperative_groups.h>
#include <cuda_runtime.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <unistd.h>
#include <utility>
#include <vector>

static void cuda_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx);

#define CUDA_CHECK(call)                                                                             \
    do {                                                                                             \
        cudaError_t err_ = (call);                                                                   \
        if (err_ != cudaSuccess)                                                                     \
            sim_fail("%s:%d: %s failed: %s", __FILE__, __LINE__, #call, cudaGetErrorString(err_));   \
    } while (0)
#define CUDA_LAUNCHED() CUDA_CHECK(cudaGetLastError())

#define THREADS 256
#define NO_EVENT UINT64_MAX
#define MAX_SLICES 256            /* time slices per step */
#define ENTRY_MEMORY 0.5          /* share of the device memory left after the state that entries may take */
#define ENTRY_BYTES (16 + 3 * 8 + 4 + sizeof(float4)) /* an entry's share (cuda_open) */
#define EVENTS_PER_DISK 4         /* the first event list holds n / 4 (+ 4096) where steps have one slice
                                     (cuda_run; a gas of fraction 0.4 finds some n / 4.4 a step); a step that
                                     finds more is run again with room for them all */
#define GROWTH 1.25               /* buffers grown to a plan's need are grown this much beyond it */
#define SLICES_AHEAD 2.0          /* the first entries of a scene of several slices: for twice its first
                                     plan's (its fastest disks speed up as collisions spread the speeds) */
#define MAX_ROUNDS 8              /* choice rounds run over the whole grid, at most, before the one-block finish */
#ifndef FINISH_EVENTS
#define FINISH_EVENTS 4096.0      /* pair events a step may leave to the one-block finish, about: random scene,
                                     one H200, 1e5 2.48e8-2.50e8 at 16384 against 2.60e8-2.63e8, 1e6 alike
                                     (bench/gpu_h100_variants.log 25d) */
#endif
#ifndef SLICE_COST
#define SLICE_COST 80.0           /* cost of one entry, in pair tests (candidates): sets K. Of 28, 40, 56, 80 with
                                     near_path, random scene: N = 32000 alike, 3e5 and 1e6 7% and 12% faster at
                                     80 than 40, 1e5 2% slower */
#endif
#ifndef SLICE_COST_BIG
#define SLICE_COST_BIG 160.0      /* the same from SLICE_COST_N disks up, where an entry's binning, placing and
                                     copying cost more against a screen: random scene, one H200, 1e6 and 4e6
                                     4.5% faster than at 80 (fewer slices, more screens), 3e5 slightly slower
                                     at 120, 1e5 and 32000 slower at 100 (bench/gpu_h100_variants.log 21b, 21c) */
#endif
#ifndef SLICE_COST_N
#define SLICE_COST_N 500000
#endif
#ifndef SLICE_COST_SMALL
#define SLICE_COST_SMALL 60.0     /* the same below SLICE_COST_SMALL_N disks, where binning and placing wait on
                                     their own loads more than on memory, so more entries cost them little: random
                                     scene, N = 32000, one H200, 2.26e8-2.36e8 at 80 against 2.34e8-2.43e8 at 60;
                                     1e5 slower at 60 (bench/gpu_h100_variants.log 24a, 25a) */
#endif
#ifndef SLICE_COST_SMALL_N
#define SLICE_COST_SMALL_N 50000
#endif
#define PHASES 7                  /* phases timed under --stats */
#define WMAX 10                   /* time windows of a step at most (see window_start) */
#ifndef PLACE_FUSED_N
#define PLACE_FUSED_N 500000      /* below this many disks a step of several slices places its entries' slots and
                                     midpoints as it places their keys (place_fused) */
#endif
#ifndef SUB_X
#define SUB_X 2                   /* columns a cell of a walled scene of several slices is cut into
                                     (Grid.sx): 17% fewer pair tests, random scene, N = 1e6, 4.46e8 ->
                                     4.57e8 particle-steps/s; at 4, 23% fewer but binning and scan cost
                                     more (bench/gpu_h100_variants.log 22) */
#endif
#ifndef WINDOW_ENTRIES
#define WINDOW_ENTRIES 1048576.0  /* entries a window should have to fill the device (first_window) */
#endif
#ifndef CELLS_PER_DISK
#define CELLS_PER_DISK 2.0        /* cells per slice at most: in a dilute scene a finer grid costs more in
                                     clearing and scanning cells than it saves in pair tests */
#endif
#ifndef GRAPHS
#define GRAPHS 1                  /* batches of BATCH steps as CUDA graphs (batch_launch) */
#endif
#ifndef PDL
#define PDL 1                     /* a step's kernels as programmatic dependent launches (step_kernel) */
#endif
#ifndef LEVELS
#define LEVELS 3                  /* speed levels at most (disk_level); 1: every disk in every slice (of 1
                                     to 4 at N = 32000, 3 the fastest) */
#endif

/* the device code, phase by phase (each file opens with what it holds) */
#include "cuda_state.cuh"
#include "cuda_bin.cuh"
#include "cuda_detect.cuh"
#include "cuda_choose.cuh"
#include "cuda_move.cuh"

/* ==== host side ========================================================================================== */

#ifndef BATCH
#define BATCH 8             /* steps planned together; the host reads the control record once per batch */
#endif
#define RING (2 * BATCH)    /* steps in flight at most: two batches */
#define SPEED_SLACK 1.0625  /* plans allow cells this much finer than the last known speed needs */
#ifndef SLICE_SLACK
#define SLICE_SLACK 1.25    /* and this many times the slices (speeds grow as collisions spread them) */
#endif
#ifndef LO_AT_EVENT
#define LO_AT_EVENT 1       /* steps of one slice: the search starts the second keys of each event's disks, not
                               the move and the gather every disk's (8 bytes a disk): gas of 1e7 on one H200,
                               8.05e9 -> 8.15e9 particle-steps/s, the move 19.46 -> 18.35 ms over 50 steps, the
                               search 20.31 -> 20.79; dense gas 6.00e9 -> 6.04e9 (bench/gpu_h100_variants.log
                               24c) */
#endif
#ifndef SLOT_STEPS
#define SLOT_STEPS 1        /* steps of one slice after a batch's first search the disks in their slots
                               (step_launch): gas of 1e7 on one H200 7.17e9 -> 7.83e9 particle-steps/s,
                               dense gas 5.67e9 -> 6.03e9, gas of 1e8 7.11e9 -> 7.61e9
                               (bench/gpu_h100_variants.log 18) */
#endif
#ifndef BIN_AHEAD
#define BIN_AHEAD 1.125     /* a move keys for the next step on cells fitted to this many times its speed */
#endif

typedef struct {
    int64_t n;
    Params par;
    DevState st[2];      /* old and new state; cur says which holds the current one */
    int cur;
    int32_t *pc, *wc;    /* collision counts, in original order */
    uint32_t *keys, *rank;               /* per entry: cell key, rank within the cell */
    uint32_t *keys_sorted, *order;       /* per place in cell order: key, entry */
    uint32_t *count, *start;             /* per cell (+1): entries, and where they begin in cell order */
    void *scan_tmp;
    size_t scan_tmp_bytes;
    uint32_t *tile_sums;                 /* SCAN_TILES: the short tables' tile sums (tile_sum_kernel) */
    int64_t scan_tiles;                  /* tables of as many tiles at most are scanned so (else cub) */
    int64_t dirty;                       /* counts left behind by cub's scans: count[0, dirty) may be non-zero */
    int scan_alternate;                  /* SIM_CUDA_SCAN_TILES=-1 (bin_place_launch) */
    int64_t fused_n;                     /* placement fused below this many disks (place_fused) */
    int64_t scans[2];                    /* cell tables scanned by cub, and short (--stats) */
    Entries en;                          /* K > 1: the entries' slots and mids alone (step_launch) */
    GridLimits lim;
    int64_t entry_cap;   /* entries the key arrays hold (buffers_grow) */
    int64_t cell_held;   /* cells the cell table holds, its last (+1) included */
    int64_t copy_cap;    /* entries the copies (en) hold: none while every step has one slice */
    int slices_held;     /* the buffers of steps of several slices are there (wall_win, act, lev, level_of) */
    int64_t grown;       /* times buffers_grow ran (--stats): after the first, each waited for the device */
    Grid *grid;          /* the current step's grid, fitted on the device */
    Grid *ahead;         /* the grid a move keys the disks on for the next step (MoveBin) */
    double ahead_slack;  /* 0: moves do not key; else the speed the ahead grid allows, over the step's */
    uint64_t *wall_hi, *best_hi, *best_lo;
    uint64_t *wall_win;  /* the wall event as the current window's choice sees it (K > 1) */
    int32_t *partner;
    int32_t *act[2];     /* the disks still free at a window's start (K > 1), windows alternating */
    int32_t *lev;        /* speed levels: the current window's disks by level, n apart (WindowDisks) */
    uint8_t *level_of;   /* speed levels: each disk's level in the current step */
    PairEvent *ev[2];
    int64_t ev_cap;
    unsigned long long *counts; /* list lengths of the parallel rounds, MAX_ROUNDS + 1 per window */
    StepInfo *info;
    Control *ctl;               /* device record */
    Control *ctl_host;          /* its pinned copies, one per batch in flight */
    cudaEvent_t batch_done[2];  /* the copy into ctl_host[b] is complete */
    real *out_dev;              /* print mode and checkpoints: 4n reals in original order */
    real *out_host[2];          /* pinned copies, one per batch in flight (checkpoints: then p, w) */
    int checkpoints;            /* --checkpoint: out_host also holds the counts */
    cudaStream_t stream;
    int graphs;                 /* batches of BATCH steps launched as one CUDA graph (batch_launch) */
    int pdl;                    /* a step's kernels as programmatic dependent launches (step_kernel) */
    cudaGraphExec_t graph[2];   /* one per batch in flight */
    uint64_t shape[2];          /* the shape of each slot's last batch (batch_shape) */
    int sms;
    int timed;                        /* --stats: time each phase with device events */
    cudaEvent_t mark[RING][WMAX][PHASES + 1]; /* per window: bin .. finish; the last window's: move */
    int step_windows[RING];
    double phase_ms[PHASES];
    int64_t refusals;                 /* steps refused: their pair events overflowed the list */
} Cuda;

static const char *const phase_names[PHASES] = {"bin", "scan", "place", "detect", "rounds", "finish", "move"};

static void phase_mark(Cuda *c, int ring, int w, int phase)
{
    if (c->timed) CUDA_CHECK(cudaEventRecord(c->mark[ring][w][phase], c->stream));
}

static int64_t blocks_for(int64_t n)
{
    return (n + THREADS - 1) / THREADS;
}

static void *dev_alloc(size_t bytes, const char *what)
{
    void *p = NULL;
    if (bytes == 0) bytes = 8;
    cudaError_t err = cudaMalloc(&p, bytes);
    if (err != cudaSuccess) {
        size_t free_b = 0, total_b = 0;
        cudaGetLastError();
        cudaMemGetInfo(&free_b, &total_b);
        sim_fail("not enough GPU memory for %s: %.1f MiB wanted, %.1f MiB free of %.1f MiB (%s)", what,
                bytes / 1048576.0, free_b / 1048576.0, total_b / 1048576.0, cudaGetErrorString(err));
    }
    return p;
}

static void state_alloc(DevState *d, int64_t n)
{
    size_t nd = (size_t)n * sizeof(real), ni = (size_t)n * sizeof(int32_t);
    d->pos = (real2 *)dev_alloc(2 * nd, "the state");
    d->vel = (real2 *)dev_alloc(2 * nd, "the state");
    d->id = (int32_t *)dev_alloc(ni, "the state");
}

static void state_free(DevState *d)
{
    cudaFree(d->pos);
    cudaFree(d->vel);
    cudaFree(d->id);
}

static void events_alloc(Cuda *c, int64_t cap)
{
    c->ev_cap = cap;
    c->ev[0] = (PairEvent *)dev_alloc((size_t)cap * sizeof(PairEvent), "the event list");
    c->ev[1] = (PairEvent *)dev_alloc((size_t)cap * sizeof(PairEvent), "the event list");
}

static unsigned long long speed_bits(double v)
{
    unsigned long long bits;
    memcpy(&bits, &v, sizeof bits);
    return bits;
}

static double bits_speed(unsigned long long bits)
{
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

typedef struct {
    const Sim *sim;
    int64_t n, parts;
    double *part_max;
} VmaxJob;

static void vmax_part(void *ctx, int64_t k)
{
    VmaxJob *j = (VmaxJob *)ctx;
    double m = 0;
    for (int64_t i = j->n * k / j->parts; i < j->n * (k + 1) / j->parts; i++) {
        m = fmax(m, fabs((double)j->sim->vx[i]));
        m = fmax(m, fabs((double)j->sim->vy[i]));
    }
    j->part_max[k] = m;
}

/* The largest velocity component of the state, on the host threads (a maximum: exact in any order). */
static double host_vmax(const Sim *sim, int64_t n)
{
    double part_max[64] = {0}, m = 0;
    VmaxJob j = {sim, n, n < 65536 ? 1 : 64, part_max};
    cuda_parallel(0, j.parts, vmax_part, &j);
    for (int64_t k = 0; k < j.parts; k++) m = fmax(m, part_max[k]);
    return m;
}

/* The moves' keying of the next step's cells (MoveBin): the ahead grid, and the speed it allows over the
 * step's. SIM_CUDA_BIN_AHEAD=S: cells fitted to S times the speed (0: moves do not key; the tests take 1,
 * where steps often bin anew). A GPU rank's too (mpi_cuda.cu). */
static void ahead_open(Cuda *c)
{
    const char *bin_ahead = getenv("SIM_CUDA_BIN_AHEAD");
    c->ahead_slack = bin_ahead ? atof(bin_ahead) : BIN_AHEAD;
    if (!(c->ahead_slack >= 1)) c->ahead_slack = 0;
    c->ahead = (Grid *)dev_alloc(sizeof(Grid), "counters");
}

/* vmax: the largest velocity component of sim (host_vmax) */
static void cuda_open(Cuda *c, const Sim *sim, const Params *par, double vmax, int timed, int64_t ev_cap,
                      int checkpoints)
{
    int devices = 0;
    cudaError_t err = cudaGetDeviceCount(&devices);
    if (err != cudaSuccess || devices == 0)
        sim_fail("no CUDA GPU available (%s)", err != cudaSuccess ? cudaGetErrorString(err) : "no device");
    memset(c, 0, sizeof *c);
    int64_t n = par->n;
    c->n = n;
    c->par = *par;
    CUDA_CHECK(cudaDeviceGetAttribute(&c->sms, cudaDevAttrMultiProcessorCount, 0));

    CUDA_CHECK(cudaStreamCreateWithFlags(&c->stream, cudaStreamNonBlocking));
    /* no kernel here keeps a stack frame (nvcc -Xptxas -v): the default 1 KB a thread reserves some
     * 270 MB of local memory on an H100 (1 KB x 2048 threads x 132 multiprocessors) */
    (void)cudaDeviceSetLimit(cudaLimitStackSize, 64);
    cudaGetLastError();
    /* the pair search's runs in shared memory beyond its static arrays (past 48 KB in all) */
    const cudaFuncAttribute smem = cudaFuncAttributeMaxDynamicSharedMemorySize;
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<false, true, false, false>, smem, (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<true, true, false, false>, smem, (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<false, true, true, false>, smem, (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<true, true, true, false>, smem, (int)RUN_BYTES));
    c->timed = timed;
    /* SIM_CUDA_GRAPH=0 (or a build with -DGRAPHS=0): every batch kernel by kernel (the tests run both
     * ways; --stats always does) */
    const char *graphs = getenv("SIM_CUDA_GRAPH");
    c->graphs = GRAPHS && !timed && !(graphs && atoi(graphs) == 0);
    /* SIM_CUDA_PDL=0 (or -DPDL=0): no programmatic dependent launches (sm_90 and later have them) */
    const char *pdl = getenv("SIM_CUDA_PDL");
    int major = 0;
    CUDA_CHECK(cudaDeviceGetAttribute(&major, cudaDevAttrComputeCapabilityMajor, 0));
    c->pdl = PDL && major >= 9 && !(pdl && atoi(pdl) == 0);
    /* SIM_CUDA_SCAN_TILES=T: cell tables of more than T tiles go to cub (0: all), -1: the batches of
     * one slot (batch_launch) to cub, of the other to the short scan (the tests take both ways) */
    const char *scan_tiles = getenv("SIM_CUDA_SCAN_TILES");
    c->scan_tiles = scan_tiles ? atoll(scan_tiles) : SCAN_TILES;
    c->scan_alternate = c->scan_tiles < 0;
    if (c->scan_tiles > SCAN_TILES || c->scan_tiles < 0) c->scan_tiles = SCAN_TILES;
    /* SIM_CUDA_FUSED_N=N: placement fused below N disks (0: never; the tests take both ways) */
    const char *fused_n = getenv("SIM_CUDA_FUSED_N");
    c->fused_n = fused_n ? atoll(fused_n) : PLACE_FUSED_N;
    ahead_open(c);
    c->checkpoints = checkpoints;
    if (timed)
        for (int s = 0; s < RING; s++)
            for (int w = 0; w < WMAX; w++)
                for (int k = 0; k <= PHASES; k++) CUDA_CHECK(cudaEventCreate(&c->mark[s][w][k]));
    for (int b = 0; b < 2; b++) CUDA_CHECK(cudaEventCreateWithFlags(&c->batch_done[b], cudaEventDisableTiming));

    state_alloc(&c->st[0], n);
    state_alloc(&c->st[1], n);
    c->pc = (int32_t *)dev_alloc((size_t)n * 4, "the state");
    c->wc = (int32_t *)dev_alloc((size_t)n * 4, "the state");
    c->wall_hi = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->best_hi = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->best_lo = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->partner = (int32_t *)dev_alloc((size_t)n * 4, "the event keys");
    events_alloc(c, ev_cap);
    c->counts = (unsigned long long *)dev_alloc(WMAX * (MAX_ROUNDS + 1) * sizeof(unsigned long long), "counters");
    c->info = (StepInfo *)dev_alloc(sizeof(StepInfo), "counters");
    c->ctl = (Control *)dev_alloc(sizeof(Control), "counters");
    c->grid = (Grid *)dev_alloc(sizeof(Grid), "counters");
    CUDA_CHECK(cudaMallocHost((void **)&c->ctl_host, 2 * sizeof(Control)));
    /* The scene's plans size the entries and cells (buffers_fit, below): a gas of one slice a step
     * takes one entry and at most CELLS_PER_DISK cells a disk. What is left of the device after the
     * state bounds only the slices a plan may take: up to ENTRY_MEMORY of it for entries (per entry,
     * four 4-byte keys, three cells of count and start, and with K > 1 a slot and a midpoint), at most
     * MAX_SLICES per disk. Entry and cell indices stay below 2^31. */
    size_t free_b = 0, total_b = 0;
    CUDA_CHECK(cudaMemGetInfo(&free_b, &total_b));
    double afford = ENTRY_MEMORY * (double)free_b / ENTRY_BYTES;
    int64_t cap = n * MAX_SLICES;
    if ((double)cap > afford) cap = (int64_t)afford;
    if (cap > INT32_MAX) cap = INT32_MAX;
    GridLimits *lim = &c->lim;
    lim->n = n;
    lim->L = par->L;
    lim->r = par->r;
    lim->periodic = par->periodic;
    lim->max_slices = cap / n >= 1 ? (int)(cap / n) : 1;
    int64_t entry_most = n * lim->max_slices;
    lim->cell_cap = 3 * entry_most > (1LL << 22) ? 3 * entry_most : (1LL << 22);
    if (lim->cell_cap > INT32_MAX - 1) lim->cell_cap = INT32_MAX - 1;
    c->tile_sums = (uint32_t *)dev_alloc(SCAN_TILES * sizeof(uint32_t), "the cell table");
    if ((par->print && par->steps > 1) || checkpoints) {
        size_t bytes = (size_t)n * (4 * sizeof(real) + (checkpoints ? 2 * sizeof(int32_t) : 0));
        c->out_dev = (real *)dev_alloc((size_t)n * 4 * sizeof(real), "the print buffer");
        for (int b = 0; b < 2; b++) CUDA_CHECK(cudaMallocHost((void **)&c->out_host[b], bytes));
    }

    /* the state as the input left it: its four arrays copied as they are into the spare state buffer,
     * then paired into positions and velocities, with ids, on the device */
    DevState *d = &c->st[0], *spare = &c->st[1];
    size_t nd = (size_t)n * sizeof(real), ni = (size_t)n * sizeof(int32_t);
    real *x = (real *)spare->pos, *vx = (real *)spare->vel;
    CUDA_CHECK(cudaMemcpy(x, sim->x, nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(x + n, sim->y, nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(vx, sim->vx, nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(vx + n, sim->vy, nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(c->pc, sim->pc, ni, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(c->wc, sim->wc, ni, cudaMemcpyHostToDevice));
    pair_up_kernel<<<blocks_for(n), THREADS, 0, c->stream>>>(*d, n, x, x + n, vx, vx + n);
    CUDA_LAUNCHED();
    CUDA_CHECK(cudaStreamSynchronize(c->stream));
    Control start;
    memset(&start, 0, sizeof start);
    start.vmax = speed_bits(vmax);
    CUDA_CHECK(cudaMemcpy(c->ctl, &start, sizeof start, cudaMemcpyHostToDevice));
    c->cur = 0;
}

/* The device memory the run's buffers hold (--stats), from their sizes. */
static double buffer_bytes(const Cuda *c)
{
    double n = (double)c->n;
    double b = n * (2 * (4 * sizeof(real) + 4) + 2 * 4 + 3 * 8 + 4);          /* states, pc, wc, keys, partner */
    b += 2.0 * (double)c->ev_cap * sizeof(PairEvent);                         /* the event lists */
    b += 16.0 * (double)c->entry_cap + 8.0 * (double)c->cell_held;            /* entries and cells */
    b += (double)c->copy_cap * (4 + sizeof(float4));                          /* entries' slots, mids */
    if (c->slices_held) b += n * (8 + 2 * 4 + LEVELS * 4 + 1);                 /* wall_win, act, lev, level_of */
    if (c->out_dev) b += n * 4 * sizeof(real);                                /* the print buffer */
    return b + (double)c->scan_tmp_bytes + SCAN_TILES * 4;
}

static void cuda_close(Cuda *c)
{
    for (int b = 0; b < 2; b++)
        if (c->graph[b]) cudaGraphExecDestroy(c->graph[b]);
    state_free(&c->st[0]);
    state_free(&c->st[1]);
    cudaFree(c->pc);
    cudaFree(c->wc);
    cudaFree(c->keys);
    cudaFree(c->rank);
    cudaFree(c->keys_sorted);
    cudaFree(c->order);
    cudaFree(c->count);
    cudaFree(c->start);
    cudaFree(c->scan_tmp);
    cudaFree(c->tile_sums);
    cudaFree(c->en.slot);
    cudaFree(c->en.mid);
    cudaFree(c->wall_hi);
    cudaFree(c->best_hi);
    cudaFree(c->best_lo);
    cudaFree(c->partner);
    cudaFree(c->wall_win);
    cudaFree(c->act[0]);
    cudaFree(c->act[1]);
    cudaFree(c->lev);
    cudaFree(c->level_of);
    cudaFree(c->ev[0]);
    cudaFree(c->ev[1]);
    cudaFree(c->counts);
    cudaFree(c->info);
    cudaFree(c->ctl);
    cudaFree(c->grid);
    cudaFree(c->ahead);
    cudaFreeHost(c->ctl_host);
    cudaFree(c->out_dev);
    for (int b = 0; b < 2; b++) {
        cudaFreeHost(c->out_host[b]);
        cudaEventDestroy(c->batch_done[b]);
    }
    if (c->timed)
        for (int s = 0; s < RING; s++)
            for (int w = 0; w < WMAX; w++)
                for (int k = 0; k <= PHASES; k++) cudaEventDestroy(c->mark[s][w][k]);
    cudaStreamDestroy(c->stream);
}

/* Adds the phase times of committed steps first..last (their marks are complete). */
static void phase_collect(Cuda *c, int64_t first, int64_t last)
{
    for (int64_t s = first; s <= last; s++) {
        int W = c->step_windows[s % RING];
        for (int w = 0; w < W; w++)
            for (int k = 0; k < PHASES; k++) {
                if (k == PHASES - 1 && w < W - 1) continue; /* the move follows the last window */
                float ms = 0;
                CUDA_CHECK(cudaEventElapsedTime(&ms, c->mark[s % RING][w][k], c->mark[s % RING][w][k + 1]));
                c->phase_ms[k] += ms;
            }
    }
}

static void phase_report(const Cuda *c, const Control *h)
{
    fprintf(stderr, "cuda: device time per phase (ms):");
    for (int k = 0; k < PHASES; k++) fprintf(stderr, " %s %.3f", phase_names[k], c->phase_ms[k]);
    fprintf(stderr, "\ncuda: pair events undecided before each grid-wide round:");
    for (int r = 0; r < MAX_ROUNDS && (r == 0 || h->left[r]); r++) fprintf(stderr, " %llu", h->left[r]);
    if (h->wactive[1]) {
        fprintf(stderr, "\ncuda: per window, disks free at its start and pair events found:");
        for (int w = 0; w < WMAX && h->wactive[w]; w++) fprintf(stderr, " %llu/%llu", h->wactive[w], h->wfound[w]);
    }
    fprintf(stderr, "\ncuda: cell tables scanned in two short kernels: %lld, by cub: %lld", (long long)c->scans[1],
            (long long)c->scans[0]);
    fprintf(stderr, "\ncuda: steps keyed by the move before them: %llu, binned anew (those cells too fine for "
            "their speed): %llu", h->ahead[0], h->ahead[1]);
    fprintf(stderr, "\ncuda: batches of up to %d steps; %llu steps faster than planned; %lld steps refused "
            "(event list now %lld)\n", BATCH, h->faster, (long long)c->refusals, (long long)c->ev_cap);
}

/* What the host decides for a batch of steps, from the largest speed it last read back: the most slices
 * and the finest grid the steps may use (the launch sizes and the cells cleared and scanned), and the
 * windows. Each step's gate fits the grid to its own disks within that. */
typedef struct {
    unsigned long long vmax; /* bits of the speed planned for */
    int K;        /* slices at most */
    int64_t gcap; /* cells per side at most */
    int gsx;      /* and the columns of each (Grid.sx) */
    int F, W;      /* windows (window_start): the first F slices long (0: one window) */
    int levels;    /* speed levels (disk_level) */
    int64_t wcells[WMAX]; /* per window: the cells it clears and scans, its rows at most x gcap^2 */
    int64_t went[WMAX];   /* and its entries at most: n x its slices */
    int rounds[WMAX];     /* grid-wide rounds of each window's choice before the one-block finish */
    int64_t choose_blocks[WMAX]; /* blocks of its grid-wide rounds: for the pair events last found */
} Plan;

/* The first window's slices: the fewest (a power of two) whose entries fill the device, n F >=
 * WINDOW_ENTRIES. A window of fewer disks leaves most of the device idle while its kernels run one
 * after another: at N = 32000 windows of one slice halved the step rate, at 1e6 they multiplied it by 10.
 * Two at least where their entries stay within 4 WINDOW_ENTRIES, so that speed levels apply (plan_for):
 * random scene on the H100, 2e6 disks: 2.12e8 particle-steps/s from one slice, 2.48e8 from 2; 4e6
 * disks: 2.46e8 from one, 2.02e8 from 2 (a first window of 8e6 entries). */
static int first_window(int64_t n)
{
    int F = 1;
    while ((double)n * F < WINDOW_ENTRIES && F < MAX_SLICES) F *= 2;
    if (LEVELS > 1 && F == 1 && (double)n * 2 <= 4 * WINDOW_ENTRIES) F = 2;
    return F;
}

/* Grid-wide rounds for steps that find `found` pair events, of which a fraction `decay` is left after
 * each round (both as the last batch had them): enough that about FINISH_EVENTS are left to the one
 * block that finishes the choice, whose time grows with them (a dense scene of 1e6 disks leaves it
 * millions after two rounds: 17 ms a step), and no more (each round costs four launches, about 10 us). */
static int rounds_for(double found, double decay)
{
    if (!(decay < 1)) return MAX_ROUNDS;
    int r = 2; /* at least two, or the next batch's decay would not be known */
    for (double left = found * decay * decay; r < MAX_ROUNDS && left > FINISH_EVENTS; r++) left *= decay;
    return r;
}

/* Blocks of a grid-wide round's passes over a list of `found` pair events (INFINITY: a length not yet
 * known): the passes loop over the list's length on the device, so fewer blocks only take more turns. */
static int64_t choose_blocks_for(const Cuda *c, double found)
{
    double b = (2 * found + 4096) / THREADS, most = 8.0 * c->sms;
    return b < most ? (int64_t)b : (int64_t)most;
}

static Plan plan_for(const Cuda *c, double vmax, const int *rounds, const double *found, int F)
{
    Plan pl;
    pl.vmax = speed_bits(vmax);
    /* room for the disks to speed up by SLICE_SLACK, or slow down by SPEED_SLACK, before the grid is
     * coarser than it could be (extra slices cost only threads that return at once) */
    pl.K = grid_slices(&c->lim, vmax * SLICE_SLACK);
    Grid most = grid_fit(&c->lim, vmax / SPEED_SLACK, pl.K, INT64_MAX);
    pl.gcap = most.g, pl.gsx = most.sx;
    pl.F = pl.K > 1 ? F : 0;
    pl.W = 1;
    if (pl.F > 0)
        while (pl.W < WMAX && ((int64_t)pl.F << (pl.W - 1)) < pl.K) pl.W++;
    /* speed levels, as many as the slices and windows allow: a window's first slice must be a multiple
     * of every level's slice length (window_start: F, 2F, 4F, ...), and its rows of cells must fit the
     * cell table (a step's gate takes these levels, with no more slices nor cells per side) */
    pl.levels = 1; /* the periodic box: one level, so that its runs across the edges fit a probe's column */
    if (pl.K > 1 && !c->par.periodic)
        while (pl.levels < LEVELS && (1 << pl.levels) < pl.K && (pl.W == 1 || pl.F % (1 << pl.levels) == 0))
            pl.levels++;
    for (;;) {
        int64_t most = 0;
        for (int w = 0; w < pl.W; w++) {
            int rows = window_rows(window_start(w, pl.F, pl.W, pl.K), window_start(w + 1, pl.F, pl.W, pl.K), pl.levels);
            pl.wcells[w] = (int64_t)rows * pl.gcap * pl.gcap * pl.gsx;
            most = pl.wcells[w] > most ? pl.wcells[w] : most;
        }
        if (most <= c->lim.cell_cap || pl.levels == 1) break;
        pl.levels--;
    }
    for (int w = 0; w < pl.W; w++) {
        int kw = window_start(w + 1, pl.F, pl.W, pl.K) - window_start(w, pl.F, pl.W, pl.K);
        pl.went[w] = c->n * kw;
        pl.rounds[w] = rounds[w];
        pl.choose_blocks[w] = choose_blocks_for(c, found[w]);
    }
    return pl;
}

/* The entries, cells and copies a plan's steps may take at most (its windows' largest). */
static void plan_needs(const Cuda *c, const Plan *pl, int64_t *entries, int64_t *cells, int64_t *copies)
{
    int64_t e = 0, cl = 0;
    for (int w = 0; w < pl->W; w++) {
        e = pl->went[w] > e ? pl->went[w] : e;
        cl = pl->wcells[w] + 1 > cl ? pl->wcells[w] + 1 : cl;
    }
    *entries = e > c->n ? e : c->n;
    *cells = cl;
    *copies = pl->K > 1 ? *entries : 0;
}

/* Whether the buffers hold what the plan's steps may take. */
static bool buffers_fit(const Cuda *c, const Plan *pl)
{
    int64_t entries, cells, copies;
    plan_needs(c, pl, &entries, &cells, &copies);
    return entries <= c->entry_cap && cells <= c->cell_held && copies <= c->copy_cap &&
           (pl->K == 1 || c->slices_held);
}

/* Grows the buffers to what the plan's steps may take (the first time exactly for steps of one slice,
 * SLICES_AHEAD beyond for several; later GROWTH beyond; within cuda_open's limits), with no step in
 * flight: the kernels of every batch launched so far are done with them. The cell table
 * comes back cleared, as the short scans keep it. A run's buffers thereby follow its scene: a gas takes
 * one entry and two cells a disk, a fast scene as many as its slices need. */
static void buffers_grow(Cuda *c, const Plan *pl)
{
    int64_t entries, cells, copies, n = c->n;
    plan_needs(c, pl, &entries, &cells, &copies);
    CUDA_CHECK(cudaStreamSynchronize(c->stream));
    c->grown++;
    int64_t most_entries = n * c->lim.max_slices, most_cells = c->lim.cell_cap + 1;
    if (entries > c->entry_cap || copies > c->copy_cap) {
        double ahead = c->entry_cap || c->copy_cap ? GROWTH : pl->K > 1 ? SLICES_AHEAD : 1;
        int64_t e = (int64_t)((double)entries * ahead);
        e = e < most_entries ? e : most_entries;
        e = e > entries ? e : entries;
        if (entries > c->entry_cap) {
            cudaFree(c->keys), cudaFree(c->rank), cudaFree(c->keys_sorted), cudaFree(c->order);
            c->keys = (uint32_t *)dev_alloc((size_t)e * 4, "the cell keys");
            c->rank = (uint32_t *)dev_alloc((size_t)e * 4, "the cell keys");
            c->keys_sorted = (uint32_t *)dev_alloc((size_t)e * 4, "the cell keys");
            c->order = (uint32_t *)dev_alloc((size_t)e * 4, "the cell keys");
            c->entry_cap = e;
        }
        if (copies > c->copy_cap) {
            cudaFree(c->en.slot), cudaFree(c->en.mid);
            size_t ne = (size_t)e;
            c->en.slot = (int32_t *)dev_alloc(ne * 4, "the entry copies");
            c->en.mid = (float4 *)dev_alloc(ne * sizeof(float4), "the entry copies");
            c->copy_cap = e;
        }
    }
    if (cells > c->cell_held) {
        double ahead = c->cell_held ? GROWTH : pl->K > 1 ? SLICES_AHEAD : 1;
        int64_t nc = (int64_t)((double)cells * ahead);
        nc = nc < most_cells ? nc : most_cells;
        nc = nc > cells ? nc : cells;
        cudaFree(c->count), cudaFree(c->start), cudaFree(c->scan_tmp);
        c->count = (uint32_t *)dev_alloc((size_t)nc * 4, "the cell table");
        c->start = (uint32_t *)dev_alloc((size_t)nc * 4, "the cell table");
        c->scan_tmp_bytes = 0;
        CUDA_CHECK(cub::DeviceScan::ExclusiveSum(NULL, c->scan_tmp_bytes, c->count, c->start, nc, c->stream));
        c->scan_tmp = dev_alloc(c->scan_tmp_bytes, "the cell table");
        CUDA_CHECK(cudaMemsetAsync(c->count, 0, (size_t)nc * 4, c->stream));
        c->dirty = 0;
        c->cell_held = nc;
    }
    if (pl->K > 1 && !c->slices_held) {
        c->wall_win = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
        c->act[0] = (int32_t *)dev_alloc((size_t)n * 4, "the event keys");
        c->act[1] = (int32_t *)dev_alloc((size_t)n * 4, "the event keys");
        c->lev = (int32_t *)dev_alloc((size_t)n * LEVELS * 4, "the event keys");
        c->level_of = (uint8_t *)dev_alloc((size_t)n, "the event keys");
        c->slices_held = 1;
    }
    CUDA_CHECK(cudaStreamSynchronize(c->stream));
}

#ifndef LOOP_BLOCKS
#define LOOP_BLOCKS 16 /* blocks per multiprocessor, at most, of the kernels that loop over a window's entries */
#endif

/* Blocks for a kernel that loops over up to `upper` items: enough to fill the device a few times over. */
static int64_t loop_blocks(const Cuda *c, int64_t upper, int per_sm)
{
    int64_t b = blocks_for(upper), most = (int64_t)per_sm * c->sms;
    b = b < most ? b : most;
    return b > 0 ? b : 1;
}

/* Blocks for window w's loops over its entries: one entry a thread in a step of one slice (the launch
 * then has no more threads than entries), else loop_blocks. The one-entry-a-thread kernels (<false>)
 * drop what lies beyond their launch: it covers the plan's entries, which bound the device's only
 * because gate_kernel never takes more slices than planned nor grid_fit more cells per side than gcap.
 * A step of one window and several slices loops too (W1_LOOP), over one wave of blocks: sized for n K
 * entries of which the speed levels leave about two fifths, most of a launch of one entry a thread
 * would be blocks with nothing to do (random scene, N = 32000: 1.79e8 against 1.77e8 particle-steps/s
 * with -DW1_LOOP=0; launches twice as large cost it 6%: bench/gpu_h100_variants.log 10i). */
#ifndef W1_LOOP
#define W1_LOOP 1
#endif
static int64_t window_blocks(const Cuda *c, const Plan *pl, int w)
{
    if (pl->W == 1 && (pl->K == 1 || !W1_LOOP)) return blocks_for(pl->went[w]);
    return loop_blocks(c, pl->went[w], pl->W == 1 ? 8 : LOOP_BLOCKS);
}

/* A kernel of a step, as a programmatic dependent launch where c->pdl (after_previous): random scene,
 * N = 32000, 1.72e8 against 1.66e8 particle-steps/s without; 1e5 and 1e6 4% to 5% faster, the gas of
 * 1e7 alike (bench/gpu_h100_variants.log 10b). */
template <typename... P, typename... A>
static void step_kernel(Cuda *c, int64_t blocks, int threads, size_t smem, void (*kernel)(P...), A &&...args)
{
    cudaLaunchConfig_t cfg = {};
    cfg.gridDim = dim3((unsigned)blocks);
    cfg.blockDim = dim3((unsigned)threads);
    cfg.dynamicSmemBytes = smem;
    cfg.stream = c->stream;
    cudaLaunchAttribute pdl;
    pdl.id = cudaLaunchAttributeProgrammaticStreamSerialization;
    pdl.val.programmaticStreamSerializationAllowed = 1;
    cfg.attrs = &pdl;
    cfg.numAttrs = c->pdl ? 1 : 0;
    CUDA_CHECK(cudaLaunchKernelEx(&cfg, kernel, std::forward<A>(args)...));
}

/* The choice among window w's pair events (wall: the wall events as it sees them). */
static void choose_launch(Cuda *c, const Plan *pl, int w, const uint64_t *wall, int ring)
{
    phase_mark(c, ring, w, 4);
    int64_t blocks = pl->choose_blocks[w];
    const unsigned long long *found = &c->info->found[w];
    unsigned long long *counts = c->counts + w * (MAX_ROUNDS + 1);
    step_kernel(c, blocks, THREADS, 0, min_lo_kernel, c->ev[0], found, c->ev_cap, c->best_hi, c->best_lo);
    step_kernel(c, blocks, THREADS, 0, accept_kernel, c->ev[0], found, c->ev_cap, c->best_hi, c->best_lo, c->partner);
    int list = 0;
    const unsigned long long *len = found;
    for (int r = 1; r < pl->rounds[w]; r++) {
        step_kernel(c, blocks, THREADS, 0, compact_kernel, c->ev[list], len, c->ev_cap, c->ev[1 - list],
                    &counts[r], c->partner, wall, c->best_hi, c->best_lo);
        list = 1 - list;
        len = &counts[r];
        step_kernel(c, blocks, THREADS, 0, min_hi_kernel, c->ev[list], len, c->ev_cap, c->best_hi);
        step_kernel(c, blocks, THREADS, 0, min_lo_kernel, c->ev[list], len, c->ev_cap, c->best_hi, c->best_lo);
        step_kernel(c, blocks, THREADS, 0, accept_kernel, c->ev[list], len, c->ev_cap, c->best_hi, c->best_lo,
                    c->partner);
    }
    phase_mark(c, ring, w, 5);
    step_kernel(c, 1, 1024, 0, finish_kernel, c->ev[list], c->ev[1 - list], len, c->ev_cap, c->partner, wall,
                c->best_hi, c->best_lo);
    phase_mark(c, ring, w, 6);
}

/* Whether a cell table of len counts is scanned by the step's two short kernels (else by cub's scan). */
static bool scan_short(const Cuda *c, int64_t len)
{
    return (len + SCAN_TILE - 1) / SCAN_TILE <= c->scan_tiles;
}

/* The cell counts of window w's table cleared where the last scan left them (the short scans clear the
 * counts behind them; after cub's, they are cleared before binning); returns whether the table is
 * scanned by the two short kernels. */
static bool bin_clear(Cuda *c, const Plan *pl, int w)
{
    int64_t len = pl->wcells[w] + 1;
    bool short_scan = scan_short(c, len);
    c->scans[short_scan]++;
    if (!short_scan || c->dirty > 0) {
        int64_t clear = len > c->dirty ? len : c->dirty;
        CUDA_CHECK(cudaMemsetAsync(c->count, 0, (size_t)clear * sizeof(uint32_t), c->stream));
        c->dirty = 0;
    }
    return short_scan;
}

/* Whether steps of several slices place each entry's slot and midpoint with its key (place_kernel's ENTRIES)
 * rather than gather them in cell order after (gather_entries_kernel): a kernel fewer, their 20 bytes
 * scattered instead of written in order. The scatter pays while the entries are few: random scene on one
 * H200, N = 32000, 1e5 and 3e5 2 to 3% faster, but 1e6 1% and 4e6 11% slower, its placement 19.3 -> 30.4
 * ms over 10 steps (bench/gpu_h100_variants.log 24a, 24c). */
static bool place_fused(const Cuda *c)
{
    return c->n < c->fused_n;
}

/* Window w's binned entries placed in cell order: the exclusive sum of the counts (short_scan: by the
 * two short kernels, bin_clear), then each entry's place (and where place_fused, its disk's slot and
 * midpoint, from state buffer in). */
template <bool WINDOWS>
static void scan_place_launch(Cuda *c, const Plan *pl, int w, const int32_t *act, const int32_t *lev, int ring,
                              bool short_scan, int in)
{
    int64_t blocks = window_blocks(c, pl, w), len = pl->wcells[w] + 1, tiles = (len + SCAN_TILE - 1) / SCAN_TILE;
    if (short_scan) {
        step_kernel(c, tiles, THREADS, 0, tile_sum_kernel, c->count, len, c->tile_sums);
        step_kernel(c, tiles, THREADS, 0, tile_scan_kernel, c->count, len, c->tile_sums, c->start);
    } else {
        CUDA_CHECK(cub::DeviceScan::ExclusiveSum(c->scan_tmp, c->scan_tmp_bytes, c->count, c->start, len,
                                                 c->stream));
        c->dirty = len;
    }
    phase_mark(c, ring, w, 2);
    uint32_t *sorted = act ? c->keys_sorted : NULL; /* act: NULL in steps of one slice alone */
    bool fused = act && place_fused(c);
    auto place = fused ? (lev ? place_kernel<WINDOWS, true, true> : place_kernel<WINDOWS, false, true>)
                       : (lev ? place_kernel<WINDOWS, true, false> : place_kernel<WINDOWS, false, false>);
    step_kernel(c, blocks, THREADS, 0, place, c->st[in], c->grid, w, c->n, act, lev, c->info, c->keys, c->rank,
                c->start, sorted, c->order, c->en);
}

/* Window w's entries binned and placed in cell order (WINDOWS false: a step of one window). keyed: the
 * move before keyed the disks (step_launch), and the gate took those keys, which are then counted here,
 * or bins anew where their cells are too fine for the step's speed. The binning that returns at once
 * where the keys are taken loops over its entries: few blocks to start. */
template <bool WINDOWS>
static void bin_place_launch(Cuda *c, const Plan *pl, int w, int in, const int32_t *act, const int32_t *lev,
                             int ring, bool keyed)
{
    int64_t blocks = window_blocks(c, pl, w);
    bool short_scan = bin_clear(c, pl, w);
    if (keyed) { /* one slice */
        step_kernel(c, loop_blocks(c, c->n, 16), THREADS, 0, bin_kernel<true, false, false>, c->st[in], c->n,
                    c->grid, 0, act, lev, c->info, c->wall_hi, c->keys, c->rank, c->count, 1);
        step_kernel(c, blocks_for(c->n), THREADS, 0, count_kernel, c->grid, c->n, c->keys, c->rank, c->count);
    } else {
        /* the gate's K is at most the plan's: a plan of one column has a grid of one */
        auto bin = lev ? (pl->gsx > 1 ? bin_kernel<WINDOWS, true, true> : bin_kernel<WINDOWS, true, false>)
                       : (pl->gsx > 1 ? bin_kernel<WINDOWS, false, true> : bin_kernel<WINDOWS, false, false>);
        step_kernel(c, blocks, THREADS, 0, bin, c->st[in], c->n, c->grid, w, act, lev, c->info, c->wall_hi, c->keys,
                    c->rank, c->count, 1);
    }
    phase_mark(c, ring, w, 1);
    scan_place_launch<WINDOWS>(c, pl, w, act, lev, ring, short_scan, in);
}

/* The pair search over window w's entries, placed and copied to en (with midpoints where K > 1), in the
 * build for the run's box. */
template <bool PERIODIC>
static void detect_box(Cuda *c, const Plan *pl, int w, const Entries &en)
{
    int64_t one = blocks_for(pl->went[w]), tiles = loop_blocks(c, pl->went[w], LOOP_BLOCKS * DETECT_MIN_BLOCKS);
    const uint32_t *keys = c->keys_sorted, *start = c->start;
    if (pl->K == 1 && en.slot) /* the disks in their slots (step_launch): their keys by slot */
        step_kernel(c, one, THREADS, 0, detect_kernel<false, false, PERIODIC, true>, en, c->keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else if (pl->K == 1)
        step_kernel(c, one, THREADS, 0, detect_kernel<false, false, PERIODIC, false>, en, keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else if (pl->W == 1)
        step_kernel(c, one, THREADS, RUN_BYTES, detect_kernel<false, true, PERIODIC, false>, en, keys, start, c->grid,
                    w, c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else
        step_kernel(c, tiles, THREADS, RUN_BYTES, detect_kernel<true, true, PERIODIC, false>, en, keys, start,
                    c->grid, w, c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
}

static void detect_launch(Cuda *c, const Plan *pl, int w, const Entries &en)
{
    if (c->par.periodic)
        detect_box<true>(c, pl, w, en);
    else
        detect_box<false>(c, pl, w, en);
}

/* Launches one step from the current state; if the step commits, the current state is then in c->cur.
 * ring: the step's phase marks under --stats; first, last: whether it is its batch's first, last. In
 * steps of one slice where moves key ahead (MoveBin): keyed, the move of the step before keyed the
 * disks' cells for this one; key_ahead, this one's move keys them for the next. */
static void step_launch(Cuda *c, const Plan *pl, int ring, bool first, bool last)
{
    int64_t n = c->n;
    int in = c->cur;
    const Grid *grid = c->grid;
    c->step_windows[ring] = pl->W;
    bool ahead = pl->K == 1 && c->ahead_slack > 0, keyed = ahead && !first, key_ahead = ahead && !last;
    /* a step the move before keyed searches the disks where that move left them, through the cell
     * order (SLOT_STEPS), and that move started their event keys: no gather. A batch's first step
     * gathers, so the disks return to cell order every BATCH steps (between them a gas's disks move a
     * few cells at most, and the search's loads stay near each other), and a step run again after a
     * refusal starts from a gather. */
    bool slots = SLOT_STEPS && keyed;
    step_kernel(c, 1, 1, 0, gate_kernel, c->ctl, c->info, c->counts, c->lim, pl->vmax, pl->K, pl->gcap, pl->F, pl->W,
                pl->levels, c->grid, c->ahead, (int)keyed, key_ahead ? c->ahead_slack : 0.0);
    if (pl->K == 1) {
        phase_mark(c, ring, 0, 0);
        bin_place_launch<false>(c, pl, 0, in, NULL, NULL, ring, keyed);
        if (!slots) {
            step_kernel(c, blocks_for(n), THREADS, 0, gather_state_kernel, c->st[in], c->st[1 - in], c->order, n,
                        c->par, c->wall_hi, c->best_hi, LO_AT_EVENT ? (uint64_t *)NULL : c->best_lo, c->partner,
                        c->ctl, (uint32_t *)NULL, (int64_t)0);
            in = 1 - in;
        }
        DevState *d = &c->st[in];
        Entries en;
        en.pos = d->pos, en.vel = d->vel, en.id = d->id;
        en.slot = slots ? (int32_t *)c->order : NULL;
        en.rank = c->rank;
        en.wall = c->wall_hi;
        en.mid = NULL;
        en.best_lo = LO_AT_EVENT ? c->best_lo : NULL;
        phase_mark(c, ring, 0, 3);
        detect_launch(c, pl, 0, en);
        choose_launch(c, pl, 0, c->wall_hi, ring);
    } else {
        for (int w = 0; w < pl->W; w++) {
            phase_mark(c, ring, w, 0);
            int32_t *act = c->act[w & 1];
            int32_t *lev = pl->levels > 1 ? c->lev : NULL; /* the device's grid may take fewer */
            if (w == 0)
                step_kernel(c, blocks_for(n), THREADS, 0, init_kernel, c->st[in], n, grid, c->par, c->wall_hi,
                            c->wall_win, c->best_hi, c->best_lo, c->partner, c->level_of, c->lev, c->info);
            else
                step_kernel(c, loop_blocks(c, n, 16), THREADS, 0, activate_kernel, n, grid, w, c->act[(w - 1) & 1],
                            act, c->info, c->partner, c->wall_hi, c->wall_win, c->best_hi, c->best_lo, c->level_of,
                            c->lev);
            if (pl->W == 1 && !W1_LOOP)
                bin_place_launch<false>(c, pl, w, in, act, lev, ring, false);
            else
                bin_place_launch<true>(c, pl, w, in, act, lev, ring, false);
            if (!place_fused(c))
                step_kernel(c, window_blocks(c, pl, w), THREADS, 0, gather_entries_kernel, c->st[in], n, w, act,
                            lev, c->info, c->order, c->start, grid, c->en);
            phase_mark(c, ring, w, 3);
            Entries en = c->en; /* the entries' slots and mids, and the disks in their slots */
            en.pos = c->st[in].pos, en.vel = c->st[in].vel, en.id = c->st[in].id, en.wall = c->wall_hi;
            detect_launch(c, pl, w, en);
            choose_launch(c, pl, w, c->wall_win, ring);
        }
    }
    RankMove none = {};
    MoveBin mb = {c->ahead, c->keys, NULL, NULL, NULL, NULL, 0}; /* read by move_kernel<false, true, *> alone */
    if (SLOT_STEPS) mb.wall_hi = c->wall_hi, mb.best_hi = c->best_hi, mb.partner = c->partner;
    if (SLOT_STEPS && !LO_AT_EVENT) mb.best_lo = c->best_lo;
    mb.ids_alike = slots;
    auto move = MOVE_LOOP ? (key_ahead ? move_kernel<false, true, true> : move_kernel<false, false, true>)
                          : (key_ahead ? move_kernel<false, true, false> : move_kernel<false, false, false>);
    int64_t move_blocks = MOVE_LOOP ? loop_blocks(c, n, MOVE_LOOP) : blocks_for(n);
    step_kernel(c, move_blocks, THREADS, 0, move, c->st[in], c->st[1 - in], n, c->par, c->partner, c->wall_hi,
                c->best_hi, c->pc, c->wc, c->info, c->ev_cap, c->ctl, none, mb);
    phase_mark(c, ring, pl->W - 1, 7);
    step_kernel(c, 1, 32, 0, commit_kernel, c->ctl, c->info, c->counts);
    c->cur = 1 - in;
}

/* What sets the kernels a batch launches, and in what order (step_launch): its steps, one slice or
 * several, the windows, the speed levels' lists, each window's choice rounds and way of scanning its
 * cell table, and whether a scan by cub left counts to clear. */
static uint64_t batch_shape(const Cuda *c, const Plan *pl, int64_t steps)
{
    uint64_t h = 1469598103934665603ull; /* FNV-1a over the fields */
    int64_t f[5 + 2 * WMAX] = {steps, pl->K > 1, pl->W, pl->levels > 1, c->dirty > 0};
    for (int w = 0; w < pl->W && w < WMAX; w++) {
        f[5 + 2 * w] = pl->rounds[w];
        f[6 + 2 * w] = scan_short(c, pl->wcells[w] + 1); /* bin_place_launch */
    }
    for (int i = 0; i < 5 + 2 * WMAX; i++) h = (h ^ (uint64_t)f[i]) * 1099511628211ull;
    return h;
}

/* Steps first to last, from the current state (cur_at: the state each starts from). A batch of BATCH
 * steps whose shape (batch_shape) is that of the last batch of its slot b is captured and launched as
 * one graph, whose kernels the device starts with less delay between them than kernels launched one
 * by one (random scene, N = 32000: 1.62e8-1.65e8 against 1.51e8-1.52e8 particle-steps/s). graph[b] is
 * updated in place (only sizes and pointers differ), made the first time; slot b's last launch has
 * finished by then (the host read its batch back). Other batches launch kernel by kernel: making a
 * graph takes milliseconds, which a run of 10 steps at N = 1e6 does not win back (2.5e8 against 2.8e8
 * when every full batch made one), and so do --stats runs. bench/gpu_h100_variants.log 9h. */
static void batch_launch(Cuda *c, const Plan *pl, int b, int64_t first, int64_t last, int *cur_at)
{
    if (c->scan_alternate) c->scan_tiles = b ? SCAN_TILES : 0; /* SIM_CUDA_SCAN_TILES=-1 */
    uint64_t shape = batch_shape(c, pl, last - first + 1);
    int graph = c->graphs && last - first + 1 == BATCH && shape == c->shape[b];
    c->shape[b] = shape;
    if (graph) CUDA_CHECK(cudaStreamBeginCapture(c->stream, cudaStreamCaptureModeThreadLocal));
    for (int64_t s = first; s <= last; s++) {
        cur_at[s % RING] = c->cur;
        step_launch(c, pl, (int)(s % RING), s == first, s == last);
    }
    if (!graph) return;
    cudaGraph_t g;
    CUDA_CHECK(cudaStreamEndCapture(c->stream, &g));
    if (c->graph[b]) {
        cudaGraphExecUpdateResultInfo info;
        if (cudaGraphExecUpdate(c->graph[b], g, &info) != cudaSuccess) {
            cudaGetLastError(); /* a graph of another shape: made anew below */
            CUDA_CHECK(cudaGraphExecDestroy(c->graph[b]));
            c->graph[b] = NULL;
        }
    }
    if (!c->graph[b]) CUDA_CHECK(cudaGraphInstantiate(&c->graph[b], g, 0));
    CUDA_CHECK(cudaGraphDestroy(g));
    CUDA_CHECK(cudaGraphLaunch(c->graph[b], c->stream));
}

/* The host threads of cuda_parallel: started once, then woken for each call (the output is written
 * in rounds of a few MB, some 800 calls for a state of 1e8 disks), up to 16 with the calling thread. */
struct HostPool {
    std::mutex lock;
    std::condition_variable wake, done;
    std::vector<std::thread> threads;
    void (*task)(void *, int64_t) = nullptr;
    void *ctx = nullptr;
    int64_t tasks = 0, busy = 0, generation = 0;
    std::atomic<int64_t> next{0};
    int workers = 0; /* threads of this call, the caller among them */

    void run_tasks()
    {
        for (int64_t k; (k = next++) < tasks;) task(ctx, k);
    }
    void worker(int me)
    {
        int64_t seen = 0;
        std::unique_lock<std::mutex> g(lock);
        for (;;) {
            wake.wait(g, [&] { return generation != seen; });
            seen = generation;
            if (me >= workers - 1) continue; /* not needed this time */
            g.unlock();
            run_tasks();
            g.lock();
            if (--busy == 0) done.notify_one();
        }
    }
};
/* never destroyed: a thread that ends the program (a failed write) must not wait for itself */
static HostPool &host_pool = *new HostPool;

static void cuda_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    unsigned hw = std::thread::hardware_concurrency();
    int64_t nt = threads > 0 ? threads : hw > 1 ? (int64_t)hw : 1;
    if (nt > 16 && threads <= 0) nt = 16;
    if (nt > tasks) nt = tasks;
    if (nt <= 1) {
        for (int64_t k = 0; k < tasks; k++) task(ctx, k);
        return;
    }
    HostPool &p = host_pool;
    std::unique_lock<std::mutex> g(p.lock);
    while ((int64_t)p.threads.size() < nt - 1) {
        int me = (int)p.threads.size();
        p.threads.emplace_back([me]() { host_pool.worker(me); });
        p.threads.back().detach();
    }
    p.task = task;
    p.ctx = ctx;
    p.tasks = tasks;
    p.next = 0;
    p.workers = (int)nt;
    p.busy = nt - 1;
    p.generation++;
    g.unlock();
    p.wake.notify_all();
    p.run_tasks();
    g.lock();
    p.done.wait(g, [&] { return p.busy == 0; });
}

/* Print mode: the current state, in original order, on its way to out_host[b]. */
static void print_enqueue(Cuda *c, int b)
{
    int64_t n = c->n;
    real *d = c->out_dev;
    unpermute_kernel<<<blocks_for(n), THREADS, 0, c->stream>>>(c->st[c->cur], n, d, d + n, d + 2 * n, d + 3 * n,
                                                               c->ctl);
    CUDA_LAUNCHED();
    CUDA_CHECK(cudaMemcpyAsync(c->out_host[b], d, (size_t)n * 4 * sizeof(real), cudaMemcpyDeviceToHost,
                               c->stream));
}

/* A checkpoint's counts, beside the state that print_enqueue has put on its way to out_host[b]. */
static void counts_enqueue(Cuda *c, int b)
{
    int64_t n = c->n;
    int32_t *counts = (int32_t *)(c->out_host[b] + 4 * n);
    CUDA_CHECK(cudaMemcpyAsync(counts, c->pc, (size_t)n * 4, cudaMemcpyDeviceToHost, c->stream));
    CUDA_CHECK(cudaMemcpyAsync(counts + n, c->wc, (size_t)n * 4, cudaMemcpyDeviceToHost, c->stream));
}

/* The state in out_host[b] (its batch complete) as a Sim: x, y, vx, vy, and with checkpoints p, w. */
static Sim host_view(const Cuda *c, int b)
{
    int64_t n = c->n;
    Sim view;
    memset(&view, 0, sizeof view);
    view.x = c->out_host[b];
    view.y = view.x + n;
    view.vx = view.x + 2 * n;
    view.vy = view.x + 3 * n;
    if (c->checkpoints) {
        view.pc = (int32_t *)(view.x + 4 * n);
        view.wc = view.pc + n;
    }
    return view;
}

/* Saves the checkpoint of whole step `step` from out_host[b]. */
static void checkpoint_state(Cuda *c, Output *out, int b, int64_t step)
{
    Sim view = host_view(c, b);
    io_checkpoint(out, &view, step);
}

/* Formats the state in out_host[b]. */
static void print_state(Cuda *c, Output *out, int b, int64_t step)
{
    Sim view = host_view(c, b);
    io_write_lines(out, step, &view, c->n, 0);
}

/* The final state into sim, in original order: put in that order on the device (into the other state
 * buffer, free by now), then copied into sim's arrays a piece at a time on a thread of its own, while
 * the host threads format and write the pieces already there (io_write_final). */
#define DOWNLOAD_PIECE (1 << 18) /* disks per piece: about 10 MB */

struct Download {
    const Cuda *c;
    Sim *sim;
    const real *x, *vx; /* the state in original order on the device */
    std::mutex lock;
    std::condition_variable more;
    int64_t ready = 0; /* disks 0 .. ready-1 are in sim */
};

static void download_run(Download *d)
{
    int64_t n = d->c->n;
    for (int64_t a = 0; a < n; a += DOWNLOAD_PIECE) {
        int64_t m = n - a < DOWNLOAD_PIECE ? n - a : DOWNLOAD_PIECE;
        size_t nd = (size_t)m * sizeof(real), ni = (size_t)m * sizeof(int32_t);
        CUDA_CHECK(cudaMemcpy(d->sim->x + a, d->x + a, nd, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->y + a, d->x + n + a, nd, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->vx + a, d->vx + a, nd, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->vy + a, d->vx + n + a, nd, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->pc + a, d->c->pc + a, ni, cudaMemcpyDeviceToHost));
        CUDA_CHECK(cudaMemcpy(d->sim->wc + a, d->c->wc + a, ni, cudaMemcpyDeviceToHost));
        std::lock_guard<std::mutex> g(d->lock);
        d->ready = a + m;
        d->more.notify_all();
    }
}

static void download_await(void *ctx, int64_t lines)
{
    Download *d = (Download *)ctx;
    std::unique_lock<std::mutex> g(d->lock);
    d->more.wait(g, [&] { return d->ready >= lines; });
}

static void state_download_and_write(Cuda *c, Sim *sim, Output *out)
{
    int64_t n = c->n;
    DevState *spare = &c->st[1 - c->cur];
    real *x = (real *)spare->pos, *vx = (real *)spare->vel;
    unpermute_kernel<<<blocks_for(n), THREADS, 0, c->stream>>>(c->st[c->cur], n, x, x + n, vx, vx + n, c->ctl);
    CUDA_LAUNCHED();
    CUDA_CHECK(cudaStreamSynchronize(c->stream));
    Download d;
    d.c = c;
    d.sim = sim;
    d.x = x;
    d.vx = vx;
    std::thread copier(download_run, &d);
    io_write_final(out, sim, download_await, &d);
    copier.join();
}

/* Steps first..last of one plan, launched together; print: the whole step printed after the last;
 * ck: the whole step saved as a checkpoint after the last. */
typedef struct {
    int64_t first, last, print, ck;
} Batch;

/* Creating CUDA's context takes a few hundred milliseconds: it is started beside the reading of the
 * input, and awaited by cuda_run (or at exit, before the thread object goes). */
static std::thread cuda_warm;

static void cuda_warm_join(void)
{
    if (cuda_warm.joinable()) cuda_warm.join();
}

static int cuda_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *stats)
{
    if (par->steps == 0) return 0;
    if (par->n > INT32_MAX / 2) sim_fail("at most %d disks on the GPU", INT32_MAX / 2);
    /* Test hooks for the paths that ordinary runs take rarely: plans for a fraction of the known speed,
     * "A" or "A,B" alternating by batch (each step's grid is then fitted to disks faster than planned;
     * "0,1" alternates plans of one slice with plans of several), a small first event list (steps
     * overflow it and are refused while batches of other plans are in flight), and the number of
     * grid-wide choice rounds (SIM_CUDA_ROUNDS, below; 1 leaves nearly everything to the one block). */
    double plan_scale[2] = {1, 1};
    const char *hook = getenv("SIM_CUDA_PLAN_SPEED");
    if (hook) {
        char *end;
        double a = strtod(hook, &end);
        if (a >= 0) plan_scale[0] = plan_scale[1] = a;
        if (*end == ',' && strtod(end + 1, NULL) >= 0) plan_scale[1] = strtod(end + 1, NULL);
    }
    int64_t batches = 0;
    hook = getenv("SIM_CUDA_EVENTS");
    double h0 = sim_clock();
    double known = host_vmax(sim, par->n); /* largest speed of the newest state read back */
    cuda_warm_join();
    /* perf mode: step 0 is formatted and written by the host threads while the device allocates,
     * uploads and runs the steps; sim is only read until state_download_and_write, and nothing else
     * uses the host threads before it. A machine without a GPU is refused before any of it is written. */
    std::thread step0;
    if (io_step0_pending(out)) {
        int devices = 0;
        if (cudaGetDeviceCount(&devices) == cudaSuccess && devices > 0)
            step0 = std::thread([out, sim]() { io_write_step0(out, sim); });
    }
    double h1 = sim_clock();
    Cuda c;
    cuda_open(&c, sim, par, known, opt->stats, hook && atoll(hook) > 0 ? atoll(hook) : par->n / EVENTS_PER_DISK + 4096,
              opt->checkpoint != NULL);
    double h2 = sim_clock();
    Control last_read, prev_read;           /* the newest control record read back, and the one before */
    memset(&last_read, 0, sizeof last_read);
    prev_read = last_read;
    int rounds[WMAX]; /* grid-wide choice rounds per window: all of them for the first step, then adapted */
    const char *rounds_hook = getenv("SIM_CUDA_ROUNDS"); /* or as many as it says (1 to MAX_ROUNDS) */
    int r0 = MAX_ROUNDS;
    if (rounds_hook && atoi(rounds_hook) >= 1 && atoi(rounds_hook) <= MAX_ROUNDS) r0 = atoi(rounds_hook);
    double found[WMAX]; /* pair events per step and window, as the last batch found them */
    for (int w = 0; w < WMAX; w++) {
        rounds[w] = r0;
        found[w] = (double)c.ev_cap;
    }
    /* the first window's slices (window_start); 0: one window. SIM_CUDA_WINDOW sets it for tests. */
    int window = first_window(par->n);
    const char *window_hook = getenv("SIM_CUDA_WINDOW");
    if (window_hook && atoi(window_hook) >= 0) window = atoi(window_hook);
    /* the first plan's buffers before the clock starts, as cuda_open's. A scene of several slices a
     * step finds up to two pair events a disk in a step (the assignment's random scene: 1.7 at N = 1e5,
     * 0.8 at 1e6 and 4e6; a gas of one slice some 1 / 15), and a list too short costs a step run again
     * (random scene, 10 steps, one H200: N = 1e6 4.09e8 particle-steps/s against 3.61e8-3.66e8 with
     * room for n / 2, bench/gpu_h100_variants.log 17): its list starts with room for 2 n, where an
     * eighth of the free memory holds both copies, and for n / 2 at least (the entries may take half). */
    Plan first = plan_for(&c, known * plan_scale[0], rounds, found, window);
    if (first.K > 1 && !(hook && atoll(hook) > 0)) {
        size_t free_b = 0, total_b = 0;
        CUDA_CHECK(cudaMemGetInfo(&free_b, &total_b));
        int64_t want = 2 * par->n + 4096, spare = (int64_t)((double)free_b / 8 / (2 * sizeof(PairEvent)));
        if (want > spare) want = spare > par->n / 2 + 4096 ? spare : par->n / 2 + 4096;
        if (c.ev_cap < want) {
            cudaFree(c.ev[0]);
            cudaFree(c.ev[1]);
            events_alloc(&c, want);
        }
    }
    buffers_grow(&c, &first);
    CUDA_CHECK(cudaDeviceSynchronize());
    double t0 = sim_clock();
    /* --substeps K: every sub-step is a SPEC.md step; states are handed out after whole steps */
    int64_t k = par->substeps, last = par->steps * k;
    int64_t base = par->first_step * k, next = base + 1; /* a resumed run starts after its checkpoint */
    Batch batch[2];
    int head = 0, flying = 0; /* batch[head] is the oldest of `flying` batches launched and not yet read */
    int cur_at[RING];         /* the state buffer each step in flight starts from */
    while (next <= last || flying > 0) {
        /* the first batch is one step, read back before the next is launched: its counts set the
         * rounds of all later batches (a dense scene's first batches would otherwise leave the
         * finish millions of events, and a dilute scene's would run rounds with nothing left) */
        bool launch = flying < (prev_read.steps ? 2 : 1) && next <= last;
        Plan pl;
        if (launch) {
            pl = plan_for(&c, known * plan_scale[batches % 2], rounds, found, window);
            /* a plan that needs larger buffers waits for the batches in flight, which use them */
            if (!buffers_fit(&c, &pl)) {
                if (flying == 0) buffers_grow(&c, &pl);
                else launch = false;
            }
        }
        if (launch) {
            int b = (head + flying) % 2;
            Batch *bt = &batch[b];
            batches++;
            bt->first = next;
            bt->last = next + BATCH - 1 < last ? next + BATCH - 1 : last;
            if (!prev_read.steps) bt->last = next;
            bt->print = 0;
            bt->ck = 0;
            int64_t shown = (next + k - 1) / k * k; /* the first whole step from next on */
            if (par->print && shown < last && shown <= bt->last) {
                bt->last = shown;
                bt->print = shown / k;
            }
            int64_t due = io_checkpoint_next(out, (next + k - 1) / k);
            if (due && due * k <= bt->last) {
                bt->last = due * k; /* a print step in this batch can only be this one */
                bt->ck = due;
            }
            batch_launch(&c, &pl, b, bt->first, bt->last, cur_at);
            if (bt->print || bt->ck) print_enqueue(&c, b);
            if (bt->ck) counts_enqueue(&c, b);
            CUDA_CHECK(cudaMemcpyAsync(&c.ctl_host[b], c.ctl, sizeof(Control), cudaMemcpyDeviceToHost,
                                       c.stream));
            CUDA_CHECK(cudaEventRecord(c.batch_done[b], c.stream));
            next = bt->last + 1;
            flying++;
            continue;
        }
        Batch *bt = &batch[head];
        CUDA_CHECK(cudaEventSynchronize(c.batch_done[head]));
        last_read = c.ctl_host[head];
        int64_t done = base + (int64_t)last_read.steps;
        known = bits_speed(last_read.vmax);
        if (c.timed) phase_collect(&c, bt->first, done < bt->last ? done : bt->last);
        if (last_read.refused) {
            /* everything launched after the refused step did nothing: run again from the last
             * committed state, with room for every pair event */
            CUDA_CHECK(cudaStreamSynchronize(c.stream));
            c.refusals++;
            {
                int64_t cap = (int64_t)last_read.overflow + (int64_t)(last_read.overflow / 2);
                cudaFree(c.ev[0]);
                cudaFree(c.ev[1]);
                events_alloc(&c, cap);
            }
            last_read.refused = 0;
            last_read.overflow = 0;
            CUDA_CHECK(cudaMemcpyAsync(c.ctl, &last_read, sizeof last_read, cudaMemcpyHostToDevice, c.stream));
            CUDA_CHECK(cudaStreamSynchronize(c.stream));
            next = done + 1;
            c.cur = cur_at[next % RING];
            flying = 0;
            head = 0;
            continue;
        }
        if (!rounds_hook && last_read.steps > prev_read.steps && last_read.left[0] > prev_read.left[0]) {
            /* the slowest decay any round showed: later rounds decay more slowly than the first */
            double decay = 0, left[MAX_ROUNDS];
            for (int r = 0; r < MAX_ROUNDS; r++) left[r] = (double)(last_read.left[r] - prev_read.left[r]);
            for (int r = 1; r < MAX_ROUNDS; r++)
                if (left[r - 1] > 0 && left[r] / left[r - 1] > decay) decay = left[r] / left[r - 1];
            double steps = (double)(last_read.steps - prev_read.steps);
            for (int w = 0; w < WMAX; w++) {
                found[w] = (double)(last_read.wfound[w] - prev_read.wfound[w]) / steps;
                rounds[w] = rounds_for(found[w], decay);
            }
        }
        prev_read = last_read;
        if (bt->print) print_state(&c, out, head, bt->print);
        if (bt->ck) {
            if (step0.joinable()) step0.join(); /* stdout holds step 0 before a checkpoint says so */
            checkpoint_state(&c, out, head, bt->ck);
        }
        io_progress(out, bt->last / k);
        head = 1 - head;
        flying--;
    }
    CUDA_CHECK(cudaStreamSynchronize(c.stream));
    stats->seconds = sim_clock() - t0;
    stats->pair_tests += last_read.tests;
    stats->events += last_read.events;
    double h3 = sim_clock();
    if (step0.joinable()) step0.join();
    double h3b = sim_clock();
    state_download_and_write(&c, sim, out);
    double h4 = sim_clock();
    if (c.timed) {
        phase_report(&c, &last_read);
        double used = buffer_bytes(&c);
        fprintf(stderr, "cuda: device memory of the run's buffers %.1f MB (%.0f bytes a disk): entries for %lld, "
                "cells %lld, entry copies %lld; grown %lld times\n", used / 1e6, used / (double)par->n,
                (long long)c.entry_cap, (long long)c.cell_held, (long long)c.copy_cap, (long long)c.grown);
    }
    cuda_close(&c);
    if (c.timed)
        fprintf(stderr, "cuda: host side (s): waiting for the context %.3f, allocations and upload %.3f, "
                "then for step 0's writing %.3f, download and final state %.3f, release %.3f\n", h1 - h0, h2 - h1,
                h3b - h3, h4 - h3b, sim_clock() - h4);
    return 0;
}

/* The device memory a run of n disks takes at the least: what cuda_open allocates, and the buffers of
 * steps of one slice (buffers_grow). Steps of several slices take more, as their plans need. */
static double bytes_needed(const Params *par, int print_buffer)
{
    double n = (double)par->n;
    double state = 2 * (4 * sizeof(real) + 4) + 2 * 4; /* two state buffers (pos, vel, id); pc, wc */
    double keys = 3 * 8 + 4;                           /* wall_hi, best_hi, best_lo; partner */
    double events = 2 * sizeof(PairEvent) * (n / EVENTS_PER_DISK + 4096) / n;
    double entries = 16 + 2 * 4 * CELLS_PER_DISK;      /* keys, rank, keys_sorted, order; count, start */
    return n * (state + keys + events + entries + (print_buffer ? 4 * sizeof(real) : 0));
}

/* With steps to run, the context is created while the particle lines are read; then a run that the
 * device cannot hold is stopped with the size it needs, as the input is still being read (nothing has
 * gone to stdout). _exit: the exit handlers would wait for this very thread. */
static void cuda_prepare(const Params *par)
{
    if (par->steps > 0 && !cuda_warm.joinable()) {
        double need = bytes_needed(par, par->print && par->steps > 1);
        cuda_warm = std::thread([need, par]() {
            size_t free_b = 0, total_b = 0;
            if (cudaFree(0) != cudaSuccess || cudaMemGetInfo(&free_b, &total_b) != cudaSuccess) return;
            if (need <= (double)free_b) return;
            fprintf(stderr, "%s: %lld disks need at least %.2f GB of GPU memory (%.0f bytes a disk); the GPU "
                    "has %.2f GB free of %.2f GB\n", sim_program, (long long)par->n, need / 1e9, need / (double)par->n,
                    (double)free_b / 1e9, (double)total_b / 1e9);
            fflush(stderr);
            _exit(1);
        });
        atexit(cuda_warm_join);
    }
}

/* The output is flushed and every device buffer freed when io_main returns: _exit leaves the context's
 * teardown to the driver, which reclaims it with the process (the runtime's own exit handlers take a
 * large part of a second on some machines). */
#ifndef CUDA_LIBRARY /* mpi_cuda.cu takes the kernels and the buffers, and has a main of its own */
/* --pressure is for the CPU backends: its per-disk impulse sums would need one more array per slot here */
static const Backend cuda_backend = {
    "cuda" SIM_SUFFIX, "",
    SIM_FEATURE_SUBSTEPS | SIM_FEATURE_CHECKPOINT | SIM_FEATURE_STEP0 | SIM_FEATURE_PERIODIC,
    cuda_run, cuda_prepare, cuda_parallel,
};

int main(int argc, char **argv)
{
    int rc = io_main(argc, argv, &cuda_backend);
    fflush(NULL);
    _exit(rc);
}
#endif
