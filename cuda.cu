/* cuda.cu: the CUDA backend.
 *
 * Every phase of a step runs on the device, and the device never waits for the host. The host launches
 * steps in batches of up to BATCH (a whole batch of one-slice steps as one CUDA graph), two batches
 * ahead, and reads one control record per batch (the largest speed, the counters) while the next batch
 * runs. From that speed, a batch or two old, it plans the launch sizes: the most time slices and the
 * finest grid a step may use. Each step's first kernel fits its grid to the largest speed of its own
 * disks within that plan, so the grid is always valid.
 * A step whose pair events overflow the event list, a cell its 8-bit count or a bucket its room, is refused
 * before it writes the state; the steps launched after it then get an empty grid, write only scratch buffers
 * and commit nothing, and the host runs them again with a larger list, 32-bit counts or no buckets. A step:
 *   bin      each disk's path over the step is cut into K time slices; each slice is binned by its
 *            midpoint into square cells wide enough that any pair SPEC.md 3.2 finds within that slice
 *            lies in neighbouring cells (see grid_fit); a counting sort orders the (slice, cell)
 *            entries: count, exclusive scan, place. A disk 2^l times slower than the fastest takes
 *            slices 2^l times longer (speed levels, disk_level): it moves no farther in one of them
 *            than the fastest disk in a slice, so the same cells hold it, with fewer entries. With
 *            K > 1 in the walled box each cell is keyed in SUB_X columns (Grid.sx), so that a disk's
 *            neighbours lie within a cell's width to each side, not the rest of its own and one more
 *   place    with K = 1 the disks themselves move, for locality, in a batch's first step: into patches
 *            of cells (PATCH_W), each row by row; its later steps search them where the move before left
 *            them, through the order of their cell places (SLOT_STEPS); with K > 1 each entry's slot and
 *            midpoint take the cell order
 *   detect   every pair in the 3x3 neighbouring cells (or columns) of the same slice (wall events
 *            were computed in place), and each entry against the slower levels' slices that contain
 *            its own, screened by whether their paths come within 2r (and margins) during the slice;
 *            a pair is kept only in the slice of its faster disk that holds its event time, so it
 *            is found once; each block appends its events to the step's list together
 *   choose   rounds of "accept every event that is the smallest remaining one of each of its disks"
 *            (SPEC.md 3.3); the last rounds run in one block. In a gas an event that is the only one of
 *            both its disks is accepted first, and the rounds see the others alone (settle_kernel)
 *   windows  with K > 1 and disks enough, bin, place, detect and choose run once per time window (a
 *            run of slices, window_start), in time order: disks the choice of a window takes are left
 *            out of the later ones, so a dense fast scene, where most disks collide early in the step,
 *            bins and tests few disks after its first slices
 *   move     each disk from the old buffers into the new ones; the pair physics is computed by both
 *            partners with the lower original index as i, so both see the same arithmetic. With K = 1
 *            (a gas) it also keys each disk's cell for the next step and starts its event keys in its
 *            slot, so that the next step only counts the keys (count_kernel) before its scan; where the
 *            table is long, the next step sorts them in buckets of a row's cells instead (cuda_rows.cuh)
 * Event keys compare by value only (t, kind, i, j), so nothing depends on thread order.
 * This file holds the constants, the host's types and the run (cuda_run, main). The device code, included
 * below, lies in one file a phase: cuda_state.cuh (buffers, speed levels, windows, the grid's fit, event
 * keys), cuda_bin.cuh (the step's gate, bin, scan and place), cuda_rows.cuh (a keyed step's table in
 * buckets), cuda_detect.cuh, cuda_choose.cuh and cuda_move.cuh; the host's in cuda_buffers.cuh (the device
 * buffers, cuda_open), cuda_plan.cuh (a batch's plan, the buffers it needs), cuda_launch.cuh (a step's
 * kernels, a batch as a graph) and cuda_output.cuh (printing and checkpoints while the next batch runs).
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
#include <string>
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
#define ENTRY_BYTES (8 + 3 * 8 + sizeof(uint2) + sizeof(float4)) /* an entry's share (cuda_open) */
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
#ifndef FINISH_LIST
#define FINISH_LIST 8192.0        /* pair events of the last grid-wide round's list, at most, which the one-block
                                     finish compacts first (rounds_for): one H200, dense gas of 1e7 (39000 a step
                                     after 2 rounds; 3 rounds) 6.68e9 -> 6.84e9 particle-steps/s, at 16384 6.78e9;
                                     the gas and random scenes within their spread (bench/gpu_h100_variants.log 28) */
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
#define CELLS_PER_DISK 1.5        /* cells per slice at most: in a dilute scene a finer grid costs more in
                                     counting and scanning cells than it saves in pair tests. Gas of 1e7 on
                                     one H200, particle-steps/s: 8.53e9 at 1 cell a disk, 8.74e9 at 1.25,
                                     8.85e9 at 1.5 (2.75 pair tests a disk), 8.77e9 at 1.75, 8.74e9 at 2
                                     (2.56); gas of 1e8: 8.25e9 at 2, 8.47e9 at 1.5. The dense gas's and the
                                     random scene's cells are set by their disks' reach
                                     (bench/gpu_h100_variants.log 26f; with counts and ranks in bytes,
                                     1.5 still best: 39c) */
#endif
#ifndef GRAPHS
#define GRAPHS 1                  /* batches of BATCH one-slice steps as CUDA graphs (batch_launch) */
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
#include "cuda_rows.cuh"
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
#ifndef GATHER_SPAN
#define GATHER_SPAN (2 * BATCH + 1) /* steps of one slice a gather serves at most: a batch's first step gathers
                                     unless the batch before can key it and its last step would still be within
                                     this many steps of the last gather (keyed_on): a long run gathers every
                                     16 steps, not 8. Gas of 1e7 on one H200, 50 steps, against a span of 12:
                                     9.50e9-9.53e9 -> 9.59e9-9.60e9 particle-steps/s, dense gas 6.89e9 ->
                                     6.92e9-6.94e9 (bench/gpu_h100_variants.log 34b) */
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
    uint32_t *slot_of, *order;           /* steps of one slice: each place's entry in cell order (order); a
                                            gathering step in patches: each place's new slot, each new slot's
                                            entry (place_patches_kernel). n places: K > 1 uses neither */
    uint32_t *count, *start;             /* per cell (+1): entries, and where they begin in cell order */
    void *scan_tmp;
    size_t scan_tmp_bytes;
    uint32_t *tile_sums;                 /* SCAN_TILES: the short tables' tile sums (tile_sum_kernel) */
    uint32_t *pieces, *patch_at;         /* PATCH_W: the patches' pieces, where each begins (patch_count_kernel) */
    int64_t patch_cap;                   /* pieces they hold */
    int64_t scan_tiles;                  /* tables of as many tiles at most are scanned so (else cub) */
    int64_t dirty;                       /* words of counts left behind by cub's scans: count[0, dirty) may be
                                            non-zero */
    int narrow;                          /* 8-bit cell counts where they apply (narrow_counts); 0 with
                                            SIM_CUDA_NARROW=0, and after a crowded cell */
    int scan_alternate;                  /* SIM_CUDA_SCAN_TILES=-1 (bin_place_launch) */
    int64_t fused_n;                     /* placement fused below this many disks (place_fused) */
    double settle_events;                /* steps of one slice settle below this many events a disk (Plan) */
    int64_t scans[3];                    /* cell tables scanned by cub, short, sorted in buckets (--stats) */
    int rows;                            /* keyed steps' tables sorted in buckets (rows_sort): -1 where cub would
                                            scan them, 0 never, 1 always (SIM_CUDA_ROWS) */
    uint32_t *bcount, *bstart;           /* rows_sort: each bucket's disks (0 between steps), where it begins */
    int64_t bucket_cap;                  /* buckets they hold, the last (+1) included */
    uint32_t *bucket;                    /* rows_sort: the buckets' rooms of slots */
    int64_t bucket_total;                /* slots it holds (ROW_ROOM) */
    Entries en;                          /* K > 1: the entries' slots and mids alone (step_launch) */
    GridLimits lim;
    int64_t entry_cap;   /* entries the key arrays hold (buffers_grow) */
    int64_t order_cap;   /* places slot_of and order hold: the disks of a step of one slice */
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
    int graphs;                 /* batches of BATCH one-slice steps launched as one CUDA graph (batch_launch) */
    int pdl;                    /* a step's kernels as programmatic dependent launches (step_kernel) */
    cudaGraphExec_t graph[2];   /* one per batch in flight */
    uint64_t shape[2];          /* the shape of each slot's last batch (batch_shape) */
    int sms;
    int timed;                        /* --stats: time each phase with device events */
    cudaEvent_t mark[RING][WMAX][PHASES + 1]; /* per window: bin .. finish; the last window's: move */
    int step_windows[RING];
    double phase_ms[PHASES];
    int64_t refusals;                 /* steps refused: their pair events overflowed the list, a cell its 8-bit
                                         count or a bucket its room */
    int64_t crowdings;                /* of those, for a cell's count (one at most: 32 bits after it) */
    int64_t overfull;                 /* for a bucket past its room (one at most: cell by cell after it) */
} Cuda;

static const char *const phase_names[PHASES] = {"bin", "scan", "place", "detect", "rounds", "finish", "move"};

static void phase_mark(Cuda *c, int ring, int w, int phase)
{
    if (c->timed) CUDA_CHECK(cudaEventRecord(c->mark[ring][w][phase], c->stream));
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
    if (h->settling[0])
        fprintf(stderr, "\ncuda: steps of one slice found %llu pair events and left %llu of them to the rounds (the "
                "others, the only event of both disks, settled before)", h->settling[0], h->settling[1]);
    if (h->wactive[1]) {
        fprintf(stderr, "\ncuda: per window, disks free at its start and pair events found:");
        for (int w = 0; w < WMAX && h->wactive[w]; w++) fprintf(stderr, " %llu/%llu", h->wactive[w], h->wfound[w]);
    }
    fprintf(stderr, "\ncuda: cell tables scanned in two short kernels: %lld, by cub: %lld, sorted in buckets: %lld",
            (long long)c->scans[1], (long long)c->scans[0], (long long)c->scans[2]);
    fprintf(stderr, "\ncuda: steps keyed by the move before them: %llu, binned anew (those cells too fine for "
            "their speed): %llu", h->ahead[0], h->ahead[1]);
    fprintf(stderr, "\ncuda: batches of up to %d steps; %llu steps faster than planned; %lld steps refused "
            "(event list now %lld)", BATCH, h->faster, (long long)c->refusals, (long long)c->ev_cap);
    if (c->crowdings) fprintf(stderr, "; one for a cell past 255 disks: 32-bit cell counts since");
    if (c->overfull) fprintf(stderr, "; one for a bucket past its room: tables counted cell by cell since");
    fputc('\n', stderr);
}

/* the host's buffers, plans, launches and output, each building on the ones before */
#include "cuda_buffers.cuh"
#include "cuda_plan.cuh"
#include "cuda_launch.cuh"
#include "cuda_output.cuh"

/* Whether the batch of steps s..e runs on the gather of step g rather than gathering itself (the batch before
 * keys it, cuda_run), in a run ending at step `last`: where it ends within GATHER_SPAN steps of g, unless a
 * gather at s would serve the whole rest of the run while g cannot, so that the run's last gather does not
 * serve a short last batch alone. 20 steps so gather at 1 and 10, not at 1 and 18: the gas of 1e7 on one
 * H200 at 9.28e9-9.32e9 particle-steps/s, against 9.17e9-9.22e9 gathering at 18 (bench/gpu_h100_variants.log
 * 34a, 34b). */
static bool keyed_on(int64_t g, int64_t s, int64_t e, int64_t last)
{
    return e - g < GATHER_SPAN && (last - g < GATHER_SPAN || last - s >= GATHER_SPAN);
}

/* Steps first..last of one plan, launched together; print: the whole step printed after the last;
 * ck: the whole step saved as a checkpoint after the last. */
typedef struct {
    int64_t first, last, print, ck;
} Batch;

/* The batch of steps from `next` (sub-steps of k a step; the run's last is `last`): BATCH at most, one
 * where it is the run's first (`first`); a printed whole step or a checkpoint due ends it there. */
static Batch batch_from(const Params *par, const Output *out, int64_t next, int64_t last, int64_t k, bool first)
{
    Batch bt;
    bt.first = next;
    bt.last = next + BATCH - 1 < last ? next + BATCH - 1 : last;
    if (first) bt.last = next;
    bt.print = 0;
    bt.ck = 0;
    int64_t shown = (next + k - 1) / k * k; /* the first whole step from next on */
    if (par->print && shown < last && shown <= bt.last) {
        bt.last = shown;
        bt.print = shown / k;
    }
    int64_t due = io_checkpoint_next(out, (next + k - 1) / k);
    if (due && due * k <= bt.last) {
        bt.last = due * k; /* a print step in this batch can only be this one */
        bt.ck = due;
    }
    return bt;
}

/* Creating CUDA's context takes a few hundred milliseconds: it is started beside the reading of the
 * input, and awaited by cuda_run (or at exit, before the thread object goes). */
static std::thread cuda_warm;
/* set where the process exits before cuda_run (bad input has printed its one line): the refusal for
 * memory then stays silent, so that stderr keeps one line */
static std::atomic<bool> cuda_exiting{false};

static void cuda_warm_join(void)
{
    if (cuda_warm.joinable()) cuda_warm.join();
}

static void cuda_warm_at_exit(void)
{
    cuda_exiting = true;
    cuda_warm_join();
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
    /* a batch keys the disks for the next batch's first step, which then needs no gather of its own
     * (step_launch), where that batch runs on the last gather (keyed_on): the first batch (one step, read
     * back alone) keys the second, and in a long run every other full batch the one after it; never after a
     * refusal or a growth of the buffers, which the keys and the event keys it started live in */
    bool keys_handed = false;
    int64_t gathered_at = next; /* the step of the last gather */
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
                if (flying == 0) buffers_grow(&c, &pl), keys_handed = false;
                else launch = false;
            }
        }
        if (launch) {
            int b = (head + flying) % 2;
            Batch *bt = &batch[b];
            batches++;
            *bt = batch_from(par, out, next, last, k, !prev_read.steps);
            bool keyed_in = keys_handed;
            if (!keyed_in) gathered_at = bt->first;
            keys_handed = bt->last < last && moves_key_ahead(&c, &pl) &&
                          keyed_on(gathered_at, bt->last + 1, batch_from(par, out, bt->last + 1, last, k, false).last,
                                   last);
            batch_launch(&c, &pl, b, bt->first, bt->last, cur_at, keyed_in, keys_handed);
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
             * committed state, with room for every pair event, or counting cells in 32 bits */
            CUDA_CHECK(cudaStreamSynchronize(c.stream));
            c.refusals++;
            if (last_read.overflow) {
                int64_t cap = (int64_t)last_read.overflow + (int64_t)(last_read.overflow / 2);
                cudaFree(c.ev[0]);
                cudaFree(c.ev[1]);
                events_alloc(&c, cap);
            }
            if (last_read.crowded & CROWDED_CELL) c.narrow = 0, c.crowdings++; /* a cell past 255: 32 bits */
            if (last_read.crowded & CROWDED_BUCKET) c.rows = 0, c.overfull++; /* cell by cell (rows_sort) */
            last_read.refused = 0;
            last_read.overflow = 0;
            last_read.crowded = 0;
            keys_handed = false;
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
    double state = 2 * (4 * sizeof(real) + 4) + 2 * 4; /* two state buffers (disks, ids); pc, wc */
    double keys = 3 * 8 + 4;                           /* wall_hi, best_hi, best_lo; partner */
    double events = 2 * sizeof(PairEvent) * (n / EVENTS_PER_DISK + 4096) / n;
    double entries = 16 + 2 * 4 * CELLS_PER_DISK;      /* keys, rank, slot_of, order; count, start */
    double buckets = ROW_SORT ? 4 * ROW_ROOM(1.0, 0) : 0; /* rows_sort's rooms, less their 256 a bucket */
    return n * (state + keys + events + entries + buckets + (print_buffer ? 4 * sizeof(real) : 0));
}

/* With steps to run, the context is created while the particle lines are read; then a run that the
 * device cannot hold is stopped with the size it needs, as the input is still being read (nothing has
 * gone to stdout), its message naming where N was read, as bad input's do. _exit: the exit handlers
 * would wait for this very thread. */
static void cuda_prepare(const Params *par, const char *where)
{
    if (par->steps > 0 && !cuda_warm.joinable()) {
        double need = bytes_needed(par, par->print && par->steps > 1);
        long long n = (long long)par->n;
        std::string at(where);
        cuda_warm = std::thread([need, n, at]() {
            size_t free_b = 0, total_b = 0;
            if (cudaFree(0) != cudaSuccess || cudaMemGetInfo(&free_b, &total_b) != cudaSuccess) return;
            if (need <= (double)free_b || cuda_exiting) return;
            fprintf(stderr, "%s: %s: %lld disks need at least %.2f GB of GPU memory (%.0f bytes a disk); the GPU "
                    "has %.2f GB free of %.2f GB\n", sim_program, at.c_str(), n, need / 1e9, need / (double)n,
                    (double)free_b / 1e9, (double)total_b / 1e9);
            fflush(stderr);
            _exit(1);
        });
        atexit(cuda_warm_at_exit);
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
