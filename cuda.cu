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
 *            than the fastest disk in a slice, so the same cells hold it, with fewer entries
 *   place    with K = 1 the disks themselves move into cell order, for locality; with K > 1 a copy of
 *            each disk per entry does
 *   detect   every pair in the 3x3 neighbouring cells of the same slice (wall events were computed in
 *            place), and each entry against the slower levels' slices that contain its own, screened
 *            by whether their paths come within 2r (and margins) during the slice; a pair is kept
 *            only in the slice of its faster disk that holds its event time, so it is found once;
 *            each block appends its events to the step's list together
 *   choose   rounds of "accept every event that is the smallest remaining one of each of its disks"
 *            (SPEC.md 3.3); the last rounds run in one block
 *   windows  with K > 1 and disks enough, bin, place, detect and choose run once per time window (a
 *            run of slices, window_start), in time order: disks the choice of a window takes are left
 *            out of the later ones, so a dense fast scene, where most disks collide early in the step,
 *            bins and tests few disks after its first slices
 *   move     each disk from the old buffers into the new ones; the pair physics is computed by both
 *            partners with the lower original index as i, so both see the same arithmetic
 * Event keys compare by value only (t, kind, i, j), so nothing depends on thread order.
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
#define ENTRY_BYTES (16 + 3 * 8 + 2 * sizeof(real2) + 16 + sizeof(float4)) /* an entry's share (cuda_open) */
#define EVENTS_PER_DISK 4         /* the first event list holds n / 4 (+ 4096) where steps have one slice
                                     (cuda_run; a gas of fraction 0.4 finds some n / 4.4 a step); a step that
                                     finds more is run again with room for them all */
#define GROWTH 1.25               /* buffers grown to a plan's need are grown this much beyond it */
#define SLICES_AHEAD 2.0          /* the first entries of a scene of several slices: for twice its first
                                     plan's (its fastest disks speed up as collisions spread the speeds) */
#define MAX_ROUNDS 8              /* choice rounds run over the whole grid, at most, before the one-block finish */
#define FINISH_EVENTS 16384.0     /* pair events a step may leave to the one-block finish, about */
#ifndef SLICE_COST
#define SLICE_COST 80.0           /* cost of one entry, in pair tests (candidates): sets K. Of 28, 40, 56, 80 with
                                     near_path, random scene: N = 32000 alike, 3e5 and 1e6 7% and 12% faster at
                                     80 than 40, 1e5 2% slower */
#endif
#define PHASES 7                  /* phases timed under --stats */
#define WMAX 10                   /* time windows of a step at most (see window_start) */
#ifndef WINDOW_ENTRIES
#define WINDOW_ENTRIES 1048576.0  /* entries a window should have to fill the device (first_window) */
#endif
#define CELLS_PER_DISK 2.0        /* cells per slice at most: in a dilute scene a finer grid costs more in
                                     clearing and scanning cells than it saves in pair tests */
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


/* ==== device state ======================================================================================= */

/* A position (x, y) or a velocity (vx, vy) as one vector: one 16-byte load (8 in float) instead of two. */
#ifdef SIM_FLOAT
typedef float2 real2;
#else
typedef double2 real2;
#endif

/* One copy of the disks in slot order; id maps a slot to the disk's original index. The collision
 * counts stay in original order outside it (Cuda.pc, Cuda.wc): only the few disks with an event touch
 * them, so they are not carried along when the disks change places. */
typedef struct {
    real2 *pos, *vel; /* (x, y) and (vx, vy) */
    int32_t *id;
} DevState;

/* A pair event: hi = (t bits << 1) | 1 (kind 1), lo = (i << 31) | j with i < j original indices;
 * a is i's slot, b is j's. Wall events are kept per disk, hi = t bits << 1 (kind 0). Event times are
 * never negative nor -0 (wall_time, pair_time), and the bits of non-negative IEEE numbers, double or
 * float, order like their values: comparing (hi, lo) as integers is event_before. */
typedef struct {
    uint64_t hi, lo;
    int32_t a, b;
} PairEvent;

/* One step's counters, cleared by its gate. */
typedef struct {
    unsigned long long vmax;   /* bits of the largest |vx| or |vy| after the step (>= 0, so ordered) */
    unsigned long long found[WMAX];  /* pair events detected per window (beyond the list's length the step is refused) */
    unsigned long long active[WMAX]; /* disks still free at each window's start (the first: all) */
    unsigned long long level[WMAX][LEVELS]; /* levels > 1: of those, the disks of each speed level */
    unsigned long long events; /* accepted events */
    unsigned long long tests;  /* narrow-phase pair tests */
    unsigned long long faster; /* 1: the disks are faster than the plan's speed */
    unsigned long long outside; /* a slab grid's (GridLimits): disks binned outside its rows (never) */
    unsigned long long ahead[2]; /* 1 in [0]: the step takes the keys the move before it gave; in [1]: it
                                    bins anew, their cells being too fine for its speed */
} StepInfo;

/* What the host reads back once per batch. Steps commit in order, so `steps` also says where a refused
 * step is: steps + 1. A step is refused only when its pair events overflow the list. */
typedef struct {
    unsigned long long vmax;     /* bits of the largest |vx| or |vy| of the current state (double) */
    unsigned long long steps;    /* steps committed */
    unsigned long long refused;  /* 1: a step was refused; no step launched after it commits */
    unsigned long long overflow; /* pair events the refused step found, when they overflowed the list */
    unsigned long long faster;   /* steps whose disks were faster than their plan's speed */
    unsigned long long tests, events;             /* sums over committed steps */
    unsigned long long left[MAX_ROUNDS];          /* pair events undecided before each grid-wide round */
    unsigned long long wfound[WMAX], wactive[WMAX]; /* per window: pair events found, disks still free */
    unsigned long long ahead[2];                    /* sums of StepInfo.ahead */
} Control;

/* Binning of one step. */
typedef struct {
    int K;          /* time slices */
    int64_t g;      /* cells per side */
    double cs;      /* cell side, length */
    double inv_cs;  /* 1 / cs */
    uint32_t ncell; /* g * g */
    int64_t cells;  /* the first window's cells: window_rows x ncell (set by gate_kernel, with the levels) */
    float pad;      /* K > 1: the distance within which near_path keeps two paths */
    int levels;     /* speed levels (disk_level): 1 where K = 1 */
    double vlev;    /* the largest velocity component the grid is fitted to, which sets the levels */
    int wb[WMAX + 1]; /* window w holds slices wb[w] to wb[w + 1] - 1 (window_start) */
    int periodic;   /* --periodic: the cells wrap (1 or at least 3 a side, so no cell neighbours
                       another twice), and so do the differences between disks (wrap_delta) */
    real Lw, halfw; /* L and L / 2 as Params holds them */
    int slab;       /* GridLimits' slab: the cells are keyed column first, of the columns from xoff on
                       (around the box where periodic), rows of them, the last one empty */
    int64_t xoff, rows;
    int keyed;      /* one slice: the move of the step before keyed the disks on this grid (move_kernel's
                       MoveBin), so the step's own binning only counts them */
} Grid;

/* Speed levels. A disk whose velocity components are at most vmax / 2^l (vmax: the largest component
 * of any disk) is of level l: its slices are 2^l of the K slices long, level slice j covering slices
 * j 2^l to (j + 1) 2^l - 1 (the last one ends at K). Over one of them it moves no farther per axis than
 * the fastest disk over one of the K, so grid_fit's cells hold its pairs as they hold theirs: a pair
 * with its event in slice k is found by the faster disk's entry of the slice of its level containing
 * k, against the slower disk's entry of the slice of its own level containing k. In the assignment's
 * random scene, once collisions have spread the speeds, the fastest disk is 2.5 times the initial
 * fastest, 19 disks in 20 are at least twice as slow as it and half at least four times: 3 levels take
 * 38% of the entries and 47% of the pair tests of one (the scene at N = 32000 after 200 steps). Every window
 * boundary is a multiple of 2^(levels - 1) (plan_for), so no level slice straddles two windows. */
static __host__ __device__ __forceinline__ int disk_level(double vx, double vy, double vlev, int levels)
{
    double m = fmax(fabs(vx), fabs(vy));
    int l = 0;
    while (l + 1 < levels && m * (double)(2 << l) <= vlev) l++; /* exact: a power of two */
    return l;
}

/* Level l's slice j of K: its first slice and the one after it (the last one ends at K). */
static __host__ __device__ __forceinline__ int2 level_span(uint32_t l, uint32_t j, int K)
{
    int k = (int)(j << l), ke = k + (1 << l);
    return make_int2(k, ke < K ? ke : K);
}

/* The level slice of level l that starts at slice k (a multiple of 2^l), of K: the fraction of the step
 * at its middle. bin_kernel keys an entry by the disk there, gather_entries_kernel copies it from
 * there, and near_path times the search from there. */
static __device__ __forceinline__ double slice_mid(int64_t k, int l, int K)
{
    int2 span = level_span((uint32_t)l, (uint32_t)(k >> l), K);
    return (double)(span.x + span.y) / (double)(2 * K);
}

/* The slices of level l in a window of slices k0 to k1 - 1 (k0 a multiple of 2^l). */
static __host__ __device__ __forceinline__ int level_rows(int k0, int k1, int l)
{
    return ((k1 + (1 << l) - 1) >> l) - (k0 >> l);
}

/* Cells come in rows of ncell, one per slice of each level, level by level: the first row of level l. */
static __host__ __device__ __forceinline__ int level_base(int k0, int k1, int l)
{
    int rows = 0;
    for (int m = 0; m < l; m++) rows += level_rows(k0, k1, m);
    return rows;
}

/* The inverse of level_base: the level of row kl of a window of slices k0 to k1 - 1, and into *base
 * that level's first row. */
static __device__ __forceinline__ uint32_t row_level(uint32_t kl, uint32_t k0, uint32_t k1, int levels,
                                                     uint32_t *base)
{
    uint32_t lv = 0, b = 0;
    for (; lv + 1 < (uint32_t)levels; lv++) {
        uint32_t rows = (uint32_t)level_rows((int)k0, (int)k1, (int)lv);
        if (kl < b + rows) break;
        b += rows;
    }
    *base = b;
    return lv;
}

static __host__ __device__ __forceinline__ int window_rows(int k0, int k1, int levels)
{
    return level_base(k0, k1, levels);
}

#define KEY_OUT UINT32_MAX /* the cell key of an entry left out */

/* The first slice of window w of a step of K slices cut into W windows, the first F slices long and
 * each later one twice as long as the one before, the last ending at K. The choice between two windows
 * waits for all of the first one's events, and disks it takes leave the later windows: the events of
 * window w all come before those of window w + 1 (slices hold event times in order, slice_of), so the
 * greedy walk of SPEC.md 3.3 over window w's events among the disks still free is the walk itself. In a
 * dense fast scene most disks are taken in the first slices, and later windows bin and test few. */
static __host__ __device__ int window_start(int w, int F, int W, int K)
{
    if (w <= 0) return 0;
    if (w >= W) return K;
    int64_t b = (int64_t)F << (w - 1);
    return b < K ? (int)b : K;
}

/* What bounds a grid: the scene and the memory for entries and cells. */
typedef struct {
    int64_t n;
    double L, r;
    int max_slices;   /* K never exceeds this: what the device holds entries for, capped */
    int64_t cell_cap; /* cells (slices x g^2) count and start hold */
    int periodic;     /* --periodic */
    /* slab (one slice a step, mpi_cuda): every disk binned lies in x0 <= x <= x1 (around the box where
     * periodic), a strip of the box; the grid is the box's, but its table holds the strip's columns
     * only, keyed column first so that they are one run of cells. A pair search reads the cells of a
     * column and of the next, so the cells are the box's as the search sees them. */
    int slab;
    double x0, x1;
} GridLimits;

/* Time slices for a step whose largest velocity component is vmax: K trades binning work (n K entries)
 * against pair tests (about 4.5 n density (2r + vmax/K)^2 per slice). */
static __host__ __device__ int grid_slices(const GridLimits *lim, double vmax)
{
    double dens = (double)lim->n / (lim->L * lim->L);
    double kf = vmax * sqrt(4.5 * dens / SLICE_COST);
    int K = kf >= 1 ? (kf < lim->max_slices ? (int)(kf + 0.5) : lim->max_slices) : 1;
    return K < 1 ? 1 : K;
}

/* Cell coordinate of a midpoint coordinate; clamping is a contraction, so neighbours stay neighbours.
 * c g / L is within a few units of 1e-16 of c / cs, far inside the slack that SIM_REL_MARGIN leaves
 * in grid_fit's cells, and a division fewer: the binning was bound by its divisions. */
static __host__ __device__ __forceinline__ int64_t cell_of(double c, double inv_cs, int64_t g)
{
    double q = floor(c * inv_cs);
    if (!(q >= 0)) q = 0;
    if (q > (double)(g - 1)) q = (double)(g - 1);
    return (int64_t)q;
}

/* The binning of a step in K slices whose largest velocity component is at most vmax, with at most gcap
 * cells per side. A pair with an event at t in slice k is, at t, at most 2r apart per axis (plus
 * rounding, covered by the margin), and each midpoint of slice k is within |v| / (2K) of the disk at t,
 * so midpoints are at most 2r + vmax / K + margin apart: with cells at least that wide the pair is in
 * neighbouring cells. The margin is omp's: the rounding of positions and times (SIM_REL_MARGIN of the
 * coordinates' scale), and pair_time near a graze, where D > 0 can hold while the exact paths miss
 * contact by up to about eps dd / r, with dd <= reach^2 for a pair with an event. Fewer cells than
 * that allows are as exact, only slower. */
static __host__ __device__ Grid grid_fit(const GridLimits *lim, double vmax, int K, int64_t gcap)
{
    double n = (double)lim->n, L = lim->L, r = lim->r;
    Grid gr;
    gr.K = K;
    double scale = L + 2 * vmax, reach = 6 * vmax + 2 * r;
    double margin = broad_margin(r, scale, reach, SIM_REL_MARGIN);
    double cell_min = (2 * r + 2 * margin + vmax / K) * (1 + SIM_REL_MARGIN) + SIM_REL_MARGIN * scale;
    double per_slice = (double)lim->cell_cap / K;
    if (per_slice > CELLS_PER_DISK * n + 1024) per_slice = CELLS_PER_DISK * n + 1024;
    double gmax = floor(sqrt(per_slice));
    if (gmax > (double)gcap) gmax = (double)gcap;
    double gf = floor(L / cell_min);
    if (gf > gmax) gf = gmax;
    if (!(gf >= 1)) gf = 1;
    if (lim->periodic && gf == 2) gf = 1; /* two cells a side would neighbour each other twice */
    gr.g = (int64_t)gf;
    gr.periodic = lim->periodic;
    gr.Lw = (real)L;
    gr.halfw = gr.Lw / 2;
    gr.cs = L / (double)gr.g;
    gr.inv_cs = (double)gr.g / L;
    gr.ncell = (uint32_t)(gr.g * gr.g);
    gr.slab = 0, gr.xoff = 0, gr.rows = gr.g;
    if (lim->slab && gr.g >= 4) { /* the columns of x0 and x1 as bin_kernel's cell_of finds them */
        double a = lim->x0, b = lim->x1;
        if (lim->periodic) a -= L * floor(a / L), b -= L * floor(b / L);
        int64_t ca = cell_of(a, gr.inv_cs, gr.g), span = cell_of(b, gr.inv_cs, gr.g) - ca;
        if (span < 0) span += gr.g; /* periodic: around the box */
        if (span + 2 < gr.g) {       /* else the whole table, as without a slab */
            gr.slab = 1, gr.xoff = ca, gr.rows = span + 2;
            gr.ncell = (uint32_t)(gr.rows * gr.g);
        }
    }
    /* float midpoints and sums round by a few units of 6e-8 of the scale: 1e-5 of it covers them */
    gr.pad = (float)(2 * r + 2 * margin + 1e-5 * scale);
    return gr;
}

/* The first statement of every kernel of a step: waits until the kernel before it in the stream has
 * finished and its writes are visible, then lets the next one start launching, whose blocks take the
 * places this kernel's last ones leave and wait there in turn. Both do nothing unless the kernel came
 * by a programmatic dependent launch (step_kernel), which lets the device start launching a kernel
 * while the one before it drains instead of after. */
static __device__ __forceinline__ void after_previous(void)
{
#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900
    asm volatile("griddepcontrol.wait;" ::: "memory");
    asm volatile("griddepcontrol.launch_dependents;" ::: "memory");
#endif
}

/* A slot in a list shared by the whole grid: one atomic per group of threads that append together. */
static __device__ __forceinline__ unsigned long long list_append(unsigned long long *count)
{
    cooperative_groups::coalesced_group g = cooperative_groups::coalesced_threads();
    unsigned long long base = 0;
    if (g.thread_rank() == 0) base = atomicAdd(count, (unsigned long long)g.size());
    return g.shfl(base, 0) + g.thread_rank();
}

#define GRID_LOOP(i, len) \
    for (int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x; i < (len); i += (int64_t)gridDim.x * blockDim.x)

/* GRID_LOOP where LOOP, else one item per thread (a launch with a thread per item): the compiler then
 * drops the loop, which in the gas's one-slice steps cost 5% of the binning. */
#define ENTRY_LOOP(LOOP, i, len)                                                                 \
    for (int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x; i < (len);                 \
         i = (LOOP) ? i + (int64_t)gridDim.x * blockDim.x : (len))

/* After a refusal, the kernels that write what outlives a step (the state, the collision counts, the
 * control record, the print copy) do nothing; the others write only scratch buffers, which the step
 * run again rewrites. The gather of K = 1 writes a state buffer: it checks too. */
static __device__ __forceinline__ bool refused(const Control *ctl)
{
    return *(const volatile unsigned long long *)&ctl->refused != 0;
}

#ifdef SIM_FLOAT
static __device__ __forceinline__ uint64_t time_key(real t)
{
    return (uint64_t)__float_as_uint(t) << 1;
}

static __device__ __forceinline__ real key_time(uint64_t hi)
{
    return __uint_as_float((unsigned)(hi >> 1));
}
#else
static __device__ __forceinline__ uint64_t time_key(real t)
{
    return (uint64_t)__double_as_longlong(t) << 1;
}

static __device__ __forceinline__ real key_time(uint64_t hi)
{
    return __longlong_as_double((long long)(hi >> 1));
}
#endif

/* The slice of an event time t (0 <= t <= 1), K slices. bin_kernel and detect_kernel both use this
 * rounding of t K, which is monotone in t: an event before a disk's wall event is never in a later
 * slice than the wall event. */
static __device__ __forceinline__ int64_t slice_of(real t, int K)
{
    int64_t k = (int64_t)(t * (real)K);
    return k < K - 1 ? k : K - 1;
}

static __device__ __forceinline__ uint64_t wall_key(real x, real y, real vx, real vy, const Params &par)
{
    if (par.periodic) return NO_EVENT; /* no walls */
    real lo = par.lo, hi = par.hi;
    real tw = min_time(wall_time(x, vx, lo, hi), wall_time(y, vy, lo, hi));
    return tw <= 1 ? time_key(tw) : NO_EVENT;
}

/* A disk's wall event as the choice of a window that ends before slice `end` sees it: there only if its
 * slice is in the window (a later window may still find an earlier pair event of the disk). */
static __device__ __forceinline__ uint64_t window_wall(uint64_t wall, int K, int end)
{
    return wall != NO_EVENT && slice_of(key_time(wall), K) < end ? wall : NO_EVENT;
}

/* The disks window w bins: slots 0 to n - 1 in the first window, the list act of those still free in a
 * later one; kw slices from k0. With one speed level, entry e = (slice - k0) * na + (place in the
 * list). With more, the window's disks are listed by level (lev, level_lists), and the entries of
 * level l, one per slice of that level, follow those of the faster levels: from base[l], (level slice
 * - k0 / 2^l) * nl[l] + (place in level l's list). Bin, place and gather then go over the entries
 * there are, not over every disk in every slice. */
typedef struct {
    const int32_t *act; /* NULL: slot = place */
    int64_t na;
    int k0, kw;
    int levels;
    const int32_t *lev;        /* levels > 1: level l's list at l n */
    int64_t n;
    uint32_t nl[LEVELS];       /* disks of each level */
    uint32_t base[LEVELS + 1]; /* entries before each level's; base[levels]: all (32 bits: cuda_open's limits) */
} WindowDisks;

/* Entry e of a window: its disk's slot, its level, its first slice (a multiple of 2^l), its row of
 * cells (level_base). */
typedef struct {
    int64_t s, k, row;
    int l;
} WindowEntry;

/* (Kernels copy the Grid's scalars and read its window bounds through the pointer: a copy indexed by w
 * would be put in local memory.) WINDOWS false: a step of one window, all disks and slices. */
template <bool WINDOWS>
static __device__ __forceinline__ WindowDisks window_disks(const Grid *grid, int w, int64_t n, const int32_t *act,
                                                           const int32_t *lev, const StepInfo *info)
{
    WindowDisks d;
    if (!WINDOWS) {
        d.act = NULL;
        d.na = n;
        d.k0 = 0;
        d.kw = grid->wb[1]; /* K, or 0 after a refusal (gate_kernel) */
    } else {
        d.act = w > 0 ? act : NULL;
        d.na = w > 0 ? (int64_t)info->active[w] : n;
        d.k0 = grid->wb[w];
        d.kw = grid->wb[w + 1] - d.k0;
    }
    d.levels = lev ? grid->levels : 1;
    d.lev = lev;
    d.n = n;
    if (d.levels == 1) return d; /* the tables below unset: the gas's one-slice steps bin 1e7 disks a thread each */
    d.base[0] = 0;
    for (int l = 0; l < LEVELS; l++) {
        d.nl[l] = l < d.levels ? (uint32_t)info->level[w][l] : 0;
        d.base[l + 1] = d.base[l] + d.nl[l] * (uint32_t)level_rows(d.k0, d.k0 + d.kw, l);
    }
    return d;
}

/* The window's entries. */
static __device__ __forceinline__ int64_t window_entries(const WindowDisks &d)
{
    if (d.levels == 1) return d.na * d.kw;
    int64_t e = 0;
    for (int l = 0; l < LEVELS; l++)
        if (l < d.levels) e = d.base[l + 1];
    return e;
}

static __device__ __forceinline__ WindowEntry window_entry(const WindowDisks &d, int64_t e)
{
    WindowEntry x;
    if (d.levels == 1) {
        /* a 32-bit division (entries below 2^31), and none for one slice */
        int64_t kl = d.kw == 1 ? 0 : (int64_t)((uint32_t)e / (uint32_t)d.na), i = e - kl * d.na;
        x.s = d.act ? d.act[i] : i;
        x.l = 0;
        x.k = d.k0 + kl;
        x.row = kl;
        return x;
    }
    /* the last level whose entries begin at or before e (a level with none, and those beyond d.levels,
     * begin where the next ones do, and are passed over); constant indices only, or d would go to local
     * memory */
    int l = 0;
    uint32_t b = d.base[0], nl = d.nl[0];
#pragma unroll
    for (int m = 1; m < LEVELS; m++)
        if ((uint32_t)e >= d.base[m] && d.nl[m] > 0) {
            l = m;
            b = d.base[m];
            nl = d.nl[m];
        }
    uint32_t j = (uint32_t)e - b, kl = j / nl, i = j - kl * nl;
    x.s = d.lev[(int64_t)l * d.n + i];
    x.l = l;
    x.k = (int64_t)(((uint32_t)d.k0 >> l) + kl) << l;
    x.row = level_base(d.k0, d.k0 + d.kw, l) + kl;
    return x;
}

/* ==== bin ================================================================================================ */

/* The first kernel of a step (one thread): fits the step's grid to the largest speed of its disks,
 * within the plan's slices and cells per side (the host's plan comes from a speed a batch or two old),
 * and clears the step's counters. */
static __device__ Grid gate_grid(const GridLimits *lim, double vmax, int K, int64_t gcap, int F, int W, int levels)
{
    int k = grid_slices(lim, vmax);
    Grid gr = grid_fit(lim, vmax, k < K ? k : K, gcap);
    int windows = gr.K > 1 ? W : 1;
    for (int w = 0; w <= WMAX; w++) gr.wb[w] = w <= windows ? window_start(w, F, windows, gr.K) : gr.K;
    /* the plan's levels: its windows keep their slices, and its cells hold their rows */
    gr.levels = gr.K > 1 ? levels : 1;
    gr.vlev = vmax;
    gr.cells = (int64_t)window_rows(0, gr.wb[1], gr.levels) * gr.ncell;
    gr.keyed = 0;
    return gr;
}

/* ahead: the grid the step's move is to key the disks on for the next step (ahead_slack > 0), in one
 * slice, fitted to ahead_slack times the step's largest speed (its own grid would leave no room for the
 * speed to grow); keyed: the move before did, and the step takes that grid if its cells are at least as
 * wide as the step's speed needs (their number per side no larger), else it bins anew (bin_place_launch). */
__global__ void gate_kernel(Control *ctl, StepInfo *info, unsigned long long *counts, GridLimits lim,
                            unsigned long long plan_vmax, int K, int64_t gcap, int F, int W, int levels, Grid *grid,
                            Grid *ahead, int keyed, double ahead_slack)
{
    after_previous();
    /* after a refusal, an empty grid: the steps launched behind the refused one then bin, place and
     * search nothing (their state buffers may hold anything, even memory never written, whose disks
     * could all fall into one cell); the counters are cleared all the same */
    double vmax = __longlong_as_double((long long)ctl->vmax);
    Grid gr = gate_grid(&lim, vmax, K, gcap, F, W, levels);
    info->ahead[0] = info->ahead[1] = 0;
    if (keyed && !ctl->refused) {
        if (gr.K == 1 && ahead->g <= gr.g) gr = *ahead;
        info->ahead[gr.keyed ? 0 : 1] = 1;
    }
    if (ahead_slack > 0) {
        Grid next = gate_grid(&lim, vmax * ahead_slack, 1, gcap, F, W, levels);
        next.keyed = 1;
        *ahead = next;
    }
    if (ctl->refused) {
        gr.cells = 0;
        for (int w = 0; w <= WMAX; w++) gr.wb[w] = 0;
    }
    *grid = gr;
    info->vmax = 0;
    for (int w = 0; w < WMAX; w++) {
        info->found[w] = info->active[w] = 0;
        for (int l = 0; l < LEVELS; l++) info->level[w][l] = 0;
    }
    info->active[0] = ctl->refused ? 0 : lim.n;
    info->events = 0;
    info->tests = 0;
    info->outside = 0;
    for (int r = 0; r < WMAX * (MAX_ROUNDS + 1); r++) counts[r] = 0;
    info->faster = ctl->vmax > plan_vmax; /* counted when the step commits */
}

/* The last kernel of a step (one warp): the step's state is now the current one. A thread per round
 * and window: one thread's read-add-write chain took 15 us, a twentieth of a step at N = 32000. (Done
 * by the move's last block instead, it cost the gas of 1e7 6%: its 39000 blocks each counted themselves
 * on one address.) */
__global__ void commit_kernel(Control *ctl, const StepInfo *info, const unsigned long long *counts)
{
    after_previous();
    static_assert(MAX_ROUNDS <= 32 && WMAX <= 32, "a thread each");
    if (ctl->refused) return;
    int t = threadIdx.x;
    if (t < MAX_ROUNDS) {
        unsigned long long sum = 0;
        for (int w = 0; w < WMAX; w++) sum += t == 0 ? info->found[w] : counts[w * (MAX_ROUNDS + 1) + t];
        ctl->left[t] += sum;
    }
    if (t < WMAX) {
        ctl->wfound[t] += info->found[t];
        ctl->wactive[t] += info->active[t];
    }
    if (t == 0) {
        ctl->vmax = info->vmax;
        ctl->steps++;
        ctl->tests += info->tests;
        ctl->events += info->events;
        ctl->faster += info->faster;
        ctl->ahead[0] += info->ahead[0];
        ctl->ahead[1] += info->ahead[1];
    }
}

/* The cell key of a disk at pos with velocity vel, at the fraction f of the step, in row `row` (info: where
 * a slab's key outside its rows is counted, or NULL). */
static __device__ __forceinline__ uint32_t cell_key(const Grid &gr, real2 pos, real2 vel, double f, int64_t row,
                                                    const StepInfo *info)
{
    double mx = (double)pos.x + (double)vel.x * f, my = (double)pos.y + (double)vel.y * f;
    if (gr.periodic) { /* into [0, L): the cells wrap with the box */
        double L = (double)gr.Lw;
        mx = mx - L * floor(mx / L);
        my = my - L * floor(my / L);
    }
    int64_t cx = cell_of(mx, gr.inv_cs, gr.g), cy = cell_of(my, gr.inv_cs, gr.g);
    if (gr.slab) { /* column first: the column's place in the slab is the row */
        int64_t col = cx - gr.xoff;
        if (col < 0) col += gr.g;
        if (col >= gr.rows - 1) { /* never (the caller's bounds): counted, and kept in the table */
            if (info) atomicAdd(&((StepInfo *)info)->outside, 1ull);
            col = gr.rows - 2;
        }
        cx = cy, cy = col;
    }
    return (uint32_t)(row * gr.ncell + cy * gr.g + cx);
}

/* Entry e of window w (window_entry): a disk in slice k, keyed by the cell of its position at the slice's
 * middle; a disk of level l (disk_level) has an entry for each slice of its level, which starts at a
 * slice k that is a multiple of 2^l.
 * A pair event at or after a disk's wall event is never accepted (the wall event comes first in the
 * order of 3.3 and takes the disk, unless something earlier did), so slices that start after the
 * disk's wall time get no entry (key KEY_OUT): disks flying through a wall would otherwise pile up in
 * the border cells. slice_of(t) <= slice_of(tw) for t < tw, so the slice test is exact. Midpoints are
 * computed in double whatever real is: less rounding for the margin to cover. The rank of an entry
 * within its cell comes from an atomic counter: the order inside a cell changes from run to run, which
 * changes where disks sit in memory and nothing else (every decision compares values). */
template <bool WINDOWS, bool LEVELS_LISTED>
__global__ void bin_kernel(DevState st, int64_t n, const Grid *grid, int w, const int32_t *act,
                           const int32_t *lev, const StepInfo *info, const uint64_t *wall_hi, uint32_t *keys,
                           uint32_t *rank, uint32_t *count)
{
    after_previous();
    const Grid gr = *grid;
    if (gr.keyed) return; /* by the move before: count_kernel counts them */
    /* !LEVELS_LISTED: the compiler drops the lists' decoding (one-slice steps: 44 registers against 52,
     * 5 blocks a multiprocessor against 4) */
    const WindowDisks d = window_disks<WINDOWS>(grid, w, n, act, LEVELS_LISTED ? lev : NULL, info);
    ENTRY_LOOP(WINDOWS, e, window_entries(d)) {
        const WindowEntry x = window_entry(d, e);
        const int64_t s = x.s, k = x.k;
        const int l = x.l;
        real2 vel = st.vel[s];
        if (k > 0) { /* the wall event as init_kernel keyed it: the time wall_time gives, or none by t = 1 */
            uint64_t wall = wall_hi[s];
            if (wall != NO_EVENT && (k >> l) > (slice_of(key_time(wall), gr.K) >> l)) {
                keys[e] = KEY_OUT;
                continue;
            }
        }
        uint32_t key = cell_key(gr, st.pos[s], vel, slice_mid(k, l, gr.K), x.row, info);
        keys[e] = key;
        rank[e] = atomicAdd(&count[key], 1u);
    }
}

/* Per-disk start of the choice: its wall event is its best event so far, and it has none accepted. */
static __device__ __forceinline__ void slot_init(int64_t s, uint64_t w, uint64_t *wall_hi, uint64_t *best_hi,
                                                 uint64_t *best_lo, int32_t *partner)
{
    wall_hi[s] = w;
    best_hi[s] = w;
    best_lo[s] = NO_EVENT;
    partner[s] = -1;
}

/* K = 1: the disks move into cell order (slot p takes the disk of sorted entry p), with coalesced writes.
 * (Scattering them straight from slot order, saving the entry order, measured 1.5x slower.) */
__global__ void gather_state_kernel(DevState in, DevState out, const uint32_t *order, int64_t n, Params par,
                                    uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo, int32_t *partner,
                                    const Control *ctl, uint32_t *where)
{
    after_previous();
    int64_t p = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (p >= n) return;
    /* After a refusal the empty grid places nothing, so order may hold an older step's entries (< n
     * K): kept in bounds here, and nothing is written, since out can then be the last committed
     * state (each step with K > 1 launched behind the refused one moves the state to the other buffer
     * in the host's reckoning, so an odd number of them before a K = 1 step leaves it one off). */
    uint32_t s = order[p];
    if (s >= n) s = 0;
    real2 pos = in.pos[s], vel = in.vel[s];
    int32_t id = in.id[s];
    if (refused(ctl)) return;
    out.pos[p] = pos;
    out.vel[p] = vel;
    out.id[p] = id;
    slot_init(p, wall_key(pos.x, pos.y, vel.x, vel.y, par), wall_hi, best_hi, best_lo, partner);
    if (where) where[s] = (uint32_t)p; /* a GPU rank's: where each slot went (mpi_cuda.cu) */
}

/* Where each entry goes in cell order (start[] is the exclusive sum of the counts). Only the 4-byte
 * entry index is scattered (and its key, where keys_sorted: in steps of one slice the search keys each
 * disk itself); the disks, or their copies, are then gathered with coalesced writes. */
template <bool WINDOWS, bool LEVELS_LISTED>
__global__ void place_kernel(const Grid *grid, int w, int64_t n, const int32_t *lev, const StepInfo *info,
                             const uint32_t *keys, const uint32_t *rank, const uint32_t *start, uint32_t *keys_sorted,
                             uint32_t *order)
{
    after_previous();
    const WindowDisks d = window_disks<WINDOWS>(grid, w, n, NULL, LEVELS_LISTED ? lev : NULL, info);
    ENTRY_LOOP(WINDOWS, e, window_entries(d)) {
        uint32_t key = keys[e];
        if (key == KEY_OUT) continue;
        int64_t p = (int64_t)start[key] + rank[e];
        if (keys_sorted) keys_sorted[p] = key;
        order[p] = (uint32_t)e;
    }
}

/* A step whose gate took the keys the move before it gave (MoveBin): their ranks in their cells. */
__global__ void count_kernel(const Grid *grid, int64_t n, const uint32_t *keys, uint32_t *rank, uint32_t *count)
{
    after_previous();
    if (!grid->keyed) return;
    ENTRY_LOOP(false, e, n) rank[e] = atomicAdd(&count[keys[e]], 1u);
}

/* The exclusive sum of a short cell table (SCAN_TILES tiles at most) in two kernels of a step (with
 * programmatic launches, step_kernel), in place of cub's: the tile sums, then each tile's sum from those
 * before it; the second clears the counts behind it for the next binning, which then needs no clearing
 * of its own. Random scene, N = 32000: 1.74e8 against 1.72e8 particle-steps/s with cub's scan and the
 * clearing (bench/gpu_h100_variants.log 10c). */
#define SCAN_ITEMS 8
#define SCAN_TILE (THREADS * SCAN_ITEMS)
#ifndef SCAN_TILES
#define SCAN_TILES 1024 /* the longest table scanned so: 2M cells (each block adds up to SCAN_TILES sums) */
#endif

__global__ void tile_sum_kernel(const uint32_t *count, int64_t len, uint32_t *sums)
{
    after_previous();
    typedef cub::BlockReduce<uint32_t, THREADS> Reduce;
    __shared__ typename Reduce::TempStorage tmp;
    int64_t base = (int64_t)blockIdx.x * SCAN_TILE;
    uint32_t sum = 0;
    for (int i = 0; i < SCAN_ITEMS; i++) {
        int64_t j = base + i * THREADS + threadIdx.x;
        if (j < len) sum += count[j];
    }
    sum = Reduce(tmp).Sum(sum);
    if (threadIdx.x == 0) sums[blockIdx.x] = sum;
}

__global__ void tile_scan_kernel(uint32_t *count, int64_t len, const uint32_t *sums, uint32_t *start)
{
    after_previous();
    typedef cub::BlockLoad<uint32_t, THREADS, SCAN_ITEMS, cub::BLOCK_LOAD_TRANSPOSE> Load;
    typedef cub::BlockStore<uint32_t, THREADS, SCAN_ITEMS, cub::BLOCK_STORE_TRANSPOSE> Store;
    typedef cub::BlockReduce<uint32_t, THREADS> Reduce;
    typedef cub::BlockScan<uint32_t, THREADS> Scan;
    __shared__ union {
        typename Load::TempStorage load;
        typename Store::TempStorage store;
        typename Reduce::TempStorage reduce;
        typename Scan::TempStorage scan;
    } tmp;
    __shared__ uint32_t before;
    int64_t base = (int64_t)blockIdx.x * SCAN_TILE;
    int valid = len - base < SCAN_TILE ? (int)(len - base) : SCAN_TILE;
    uint32_t sum = 0;
    for (uint32_t i = threadIdx.x; i < blockIdx.x; i += THREADS) sum += sums[i];
    sum = Reduce(tmp.reduce).Sum(sum);
    if (threadIdx.x == 0) before = sum;
    __syncthreads();
    uint32_t items[SCAN_ITEMS];
    Load(tmp.load).Load(count + base, items, valid, 0u);
    __syncthreads();
    Scan(tmp.scan).ExclusiveSum(items, items);
    for (int i = 0; i < SCAN_ITEMS; i++) items[i] += before;
    __syncthreads();
    Store(tmp.store).Store(start + base, items, valid);
    for (int i = 0; i < SCAN_ITEMS; i++) { /* read above by this block alone */
        int64_t j = base + i * THREADS + threadIdx.x;
        if (j < len) count[j] = 0;
    }
}

/* Copies of the disks, one per entry, in cell order: the pair tests then read neighbours contiguously. */
typedef struct {
    real2 *pos, *vel;
    int32_t *id, *slot;
    uint64_t *wall;
    float4 *mid; /* K > 1: the disk at its level slice's middle, and its velocity (near_path); else NULL */
} Entries;

/* The entries of window w's cells (window_rows rows of ncell cells), once placed. */
static __device__ __forceinline__ uint32_t window_end(const Grid *grid, int w, const uint32_t *start)
{
    return start[(int64_t)window_rows(grid->wb[w], grid->wb[w + 1], grid->levels) * grid->ncell];
}

/* K > 1: the disks stay in place; entry p of the cell order gets a copy of its disk. */
__global__ void gather_entries_kernel(DevState st, int64_t n, int w, const int32_t *act, const int32_t *lev,
                                      const StepInfo *info, const uint32_t *order, const uint32_t *start,
                                      const Grid *grid, const uint64_t *wall_hi, Entries en)
{
    after_previous();
    const WindowDisks d = window_disks<true>(grid, w, n, act, lev, info);
    const int K = grid->K;
    GRID_LOOP(p, (int64_t)window_end(grid, w, start)) {
        const WindowEntry x = window_entry(d, order[p]);
        const int64_t s = x.s;
        real2 pos = st.pos[s], vel = st.vel[s];
        en.pos[p] = pos;
        en.vel[p] = vel;
        en.id[p] = st.id[s];
        en.slot[p] = (int32_t)s;
        en.wall[p] = wall_hi[s];
        /* the midpoint as bin_kernel computes it, and the velocity */
        double f = slice_mid(x.k, x.l, K);
        en.mid[p] = make_float4((float)((double)pos.x + (double)vel.x * f), (float)((double)pos.y + (double)vel.y * f),
                                (float)vel.x, (float)vel.y);
    }
}

/* Window w's disks by speed level (levels > 1, WindowDisks): disk s, of level l, gets a place in level
 * l's list where live. Every thread of the block calls this: the block counts its disks of each
 * level in shared memory, then takes their places with one atomic per level. The lists' order changes
 * from run to run, and with it where entries sit in memory, nothing else. */
static __device__ __forceinline__ void level_lists(int32_t *lev, int64_t n, unsigned long long *count, int levels,
                                                   bool live, int64_t s, int l)
{
    __shared__ unsigned int block_count[LEVELS];
    __shared__ unsigned long long block_base[LEVELS];
    if (threadIdx.x < LEVELS) block_count[threadIdx.x] = 0;
    __syncthreads();
    unsigned int r = live ? atomicAdd(&block_count[l], 1u) : 0;
    __syncthreads();
    if (threadIdx.x < (unsigned)levels && block_count[threadIdx.x] > 0)
        block_base[threadIdx.x] = atomicAdd(&count[threadIdx.x], (unsigned long long)block_count[threadIdx.x]);
    __syncthreads();
    if (live) lev[(int64_t)l * n + (int64_t)(block_base[l] + r)] = (int32_t)s;
}

/* K > 1, the first window: every disk free, its wall event computed, and seen by this window's choice
 * if it falls in it; with speed levels, the disk's level (level_of) and its place in the lists. */
__global__ void init_kernel(DevState st, int64_t n, const Grid *grid, Params par, uint64_t *wall_hi,
                            uint64_t *wall_win, uint64_t *best_hi, uint64_t *best_lo, int32_t *partner,
                            uint8_t *level_of, int32_t *lev, StepInfo *info)
{
    after_previous();
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    const int levels = grid->levels;
    int l = 0;
    if (s < n) {
        real2 pos = st.pos[s], vel = st.vel[s];
        uint64_t wall = wall_key(pos.x, pos.y, vel.x, vel.y, par);
        slot_init(s, wall, wall_hi, best_hi, best_lo, partner);
        uint64_t seen = window_wall(wall, grid->K, grid->wb[1]);
        wall_win[s] = seen;
        best_hi[s] = seen;
        if (levels > 1) {
            l = disk_level((double)vel.x, (double)vel.y, grid->vlev, levels);
            level_of[s] = (uint8_t)l;
        }
    }
    if (levels > 1) level_lists(lev, n, info->level[0], levels, s < n, s, l); /* block-uniform */
}

/* A later window w: the disks that no earlier window took (by a pair event, or by a wall event in an
 * earlier window's slices, which no remaining event can precede) are listed in act; the choice state of
 * each restarts with the wall event as this window sees it. The list's order changes from run to run,
 * and with it where entries sit in memory, nothing else. */
__global__ void activate_kernel(int64_t n, const Grid *grid, int w, const int32_t *prev, int32_t *act,
                                StepInfo *info, const int32_t *partner, const uint64_t *wall_hi,
                                uint64_t *wall_win, uint64_t *best_hi, uint64_t *best_lo,
                                const uint8_t *level_of, int32_t *lev)
{
    after_previous();
    const int K = grid->K, k0 = grid->wb[w], end = grid->wb[w + 1], levels = grid->levels;
    if (k0 >= end) return; /* an empty window: so are the later ones */
    int64_t np = w == 1 ? n : (int64_t)info->active[w - 1];
    /* block-uniform turns (level_lists) */
    for (int64_t i0 = (int64_t)blockIdx.x * blockDim.x; i0 < np; i0 += (int64_t)gridDim.x * blockDim.x) {
        int64_t i = i0 + threadIdx.x, s = 0;
        bool live = i < np;
        if (live) {
            s = w == 1 ? i : prev[i];
            uint64_t wall = wall_hi[s];
            live = partner[s] < 0 && !(wall != NO_EVENT && slice_of(key_time(wall), K) < k0);
            if (live) {
                act[list_append(&info->active[w])] = (int32_t)s;
                uint64_t seen = window_wall(wall, K, end);
                wall_win[s] = seen;
                best_hi[s] = seen;
                best_lo[s] = NO_EVENT;
            }
        }
        if (levels > 1) level_lists(lev, n, info->level[w], levels, live, s, live ? level_of[s] : 0);
    }
}

/* ==== detect ============================================================================================= */

/* Sorted entry p tests every later entry q > p of the same slice in the 3x3 cells around its own. Cell
 * order is row by row, so the row above lies wholly before p: what is left is the rest of p's own row
 * (from p + 1 to the end of the cell to its right) and the three cells of the row below, two contiguous
 * runs of entries. en.slot == NULL means entry == slot (K = 1). Entry and cell indices fit in 32 bits
 * (cuda_open's limits).
 *
 * A dense scene gives each entry many candidates, and each thread walks its own, screening them with
 * near_path where K > 1 (the warp then tests those passed together). A sparse one (the gas)
 * gives a few each, 0 to 6 or so: walked per thread, most lanes of a warp would idle while the one with
 * the most finished. There the block deals its candidate pairs out evenly instead, one per thread per
 * round. */
#ifndef DETECT_MIN_BLOCKS
#define DETECT_MIN_BLOCKS 5 /* 48 registers: at 6 (40) the loops spill, random scene at N = 32000 23% slower */
#endif
#ifndef DETECT_MIN_BLOCKS_MID
#define DETECT_MIN_BLOCKS_MID 4 /* K > 1: 60 registers; at 5 (48) no faster, at 4 levels only 4 blocks fit */
#endif
#define PROBE_RUNS (1 + 3 * (LEVELS - 1)) /* a probe's runs of candidates after its first, at most (Cursor) */
static_assert(PROBE_RUNS < 256 && LEVELS <= 3, "Cursor: lv holds where 2 slower levels begin, in 8 bits each");
/* dynamic shared memory: their bounds, and the time offsets of the probe's level and the slower ones (an
 * offset beside each run would save the selects but take 4 KB more a block: random scene, N = 32000,
 * 1.90e8 against 2.05e8-2.14e8 particle-steps/s, bench/gpu_h100_variants.log 10k) */
#define RUN_BYTES ((size_t)PROBE_RUNS * THREADS * sizeof(uint2) + (size_t)LEVELS * THREADS * sizeof(float))
#ifndef DEAL_MAX
#define DEAL_MAX 8 /* candidates per thread of a block at most for dealing them out */
#endif

/* An entry p of the pair search: its disk, its slice k (K > 1: the slice of its level, with the level
 * in bits 16 and up), its cell c, and its candidates of its own level: na entries from p + 1 (the rest
 * of its own row), then nb from b0 (the row below); K > 1 adds the slower levels' cells (Cursor). (In
 * double, 80 bytes with mid: a warp reads 32 of them from shared memory without bank conflicts.) */
typedef struct {
    real2 pos, vel;
    uint64_t wall;
    int32_t id;
    uint32_t k, c, na, b0, nb;
    union {
        float4 mid; /* K > 1 */
        uint4 edge; /* K = 1 in the periodic box: two more runs across the edges (first, count twice) */
    };
} Probe;

#define PROBE_LEVEL(k) ((k) >> 16)
#define PROBE_SLICE(k) ((k) & 0xffffu)

/* 1 / a to about an ulp, subnormal results and arguments taken as 0 (one MUFU.RCP: __fdividef scales
 * subnormal divisors first, five more instructions a screen). Where a, the squared relative speed, is
 * subnormal, any time of the slice is within a^(1/2) h < 1e-19 of the closest approach, so the time
 * near_path then takes (an end of the slice) changes its squared distance by less than a 4 h^2. */
static __device__ __forceinline__ float fast_rcp(float a)
{
    float r;
    asm("rcp.approx.ftz.f32 %0, %1;" : "=f"(r) : "f"(a));
    return r;
}

/* Whether the paths of probe entry m and candidate entry c (K > 1; midpoint and velocity, mid) come
 * within pad of each other while the probe's level slice lasts: from its middle, times -h to h, c's
 * middle being dt before it. A pair is kept only when its event is in that slice, and at the event
 * the disks are 2r apart plus the broad phase's margin: pad covers both, and the float rounding of
 * positions, velocities and times (a few units of 6e-8 of the scale, grid_fit). The closest approach
 * is taken at the time the relative motion gives, clamped to the slice: a time a little off it (the
 * fast reciprocal) adds only the square of that error to the squared distance. Fused multiply-adds
 * round once where a product and a sum would round twice, so pad covers them too; the build's
 * --fmad=false keeps them out of the double-precision physics only (random scene, N = 32000: 1.77e8
 * against 1.74e8 particle-steps/s with separate operations, bench/gpu_h100_variants.log 10f). About 18
 * float operations against the pair test's dozens in double and its 40 bytes of loads: in the assignment's
 * random scene the cells are as wide as the fastest disk's travel in a slice, and most pairs in
 * neighbouring cells pass far from each other. Not finite (speeds near the float range): kept. */
static __device__ __forceinline__ float wrap_float(float d, bool periodic, float L, float half)
{
    if (periodic) d = d > half ? d - L : (d < -half ? d + L : d);
    return d;
}

static __device__ __forceinline__ bool near_path(float4 m, float4 c, float dt, float h, float pad2, bool periodic,
                                                 float L, float half)
{
    /* c - m at the probe's middle (periodic: the nearest image) */
    float dx = __fmaf_rn(c.z, dt, wrap_float(c.x - m.x, periodic, L, half));
    float dy = __fmaf_rn(c.w, dt, wrap_float(c.y - m.y, periodic, L, half));
    float ux = c.z - m.z, uy = c.w - m.w;                                         /* and its rate */
    float a = __fmaf_rn(ux, ux, uy * uy), b = __fmaf_rn(dx, ux, dy * uy);
    float tau = fminf(fmaxf(-b * fast_rcp(a), -h), h); /* a = 0: NaN, then -h (any time is closest) */
    float ex = __fmaf_rn(ux, tau, dx), ey = __fmaf_rn(uy, tau, dy);
    return !(__fmaf_rn(ex, ex, ey * ey) > pad2) || !(a < 1e30f);
}

/* The pair events a block found, appended to the step's list together: one atomic on the list's count
 * per block. One per warp that found an event, all on that one address, took most of the gas's search
 * time (64 against 27 ms per 50 steps at N = 1e7). More than BLOCK_EVENTS go straight to the list. */
#define BLOCK_EVENTS 256
typedef struct {
    PairEvent e[BLOCK_EVENTS];
    unsigned long long n; /* 64 bits: a block of a dense pile can find more than 2^32 */
    unsigned long long base;
} BlockEvents;

/* The pair test of entry p (probe pr) and entry q > p: appends the pair event if there is one.
 * PERIODIC: the grid's box is periodic (Grid.periodic), as a constant of the search's build. */
template <bool PERIODIC>
static __device__ __forceinline__ void test_pair(const Entries &en, const Grid &gr, const Probe &pr, uint32_t p,
                                                 uint32_t q, real sigma2, BlockEvents *be, PairEvent *ev,
                                                 int64_t cap, unsigned long long *found, uint64_t *best_hi)
{
    real2 pos2 = __ldg(&en.pos[q]), vel2 = __ldg(&en.vel[q]);
    int32_t id2 = __ldg(&en.id[q]);
    /* pair_time(i, j) is pair_time(j, i) bit for bit: swapping the disks negates dx, dy, dvx and dvy
     * exactly, which changes no product, sum or comparison after them. So p goes first whichever index
     * is lower, and only the event's fields below depend on the order. */
    real t = PERIODIC ? pair_time_wrap(pr.pos.x, pr.pos.y, pr.vel.x, pr.vel.y, pos2.x, pos2.y, vel2.x, vel2.y,
                                          sigma2, gr.Lw, gr.halfw, 1)
                         : pair_time(pr.pos.x, pr.pos.y, pr.vel.x, pr.vel.y, pos2.x, pos2.y, vel2.x, vel2.y, sigma2);
    if (t < 0) return;
    if (gr.K > 1 && (slice_of(t, gr.K) >> PROBE_LEVEL(pr.k)) != (int64_t)PROBE_SLICE(pr.k)) return;
    PairEvent e;
    e.hi = time_key(t) | 1;
    if (!(e.hi < pr.wall && e.hi < __ldg(&en.wall[q]))) return; /* a wall event comes first */
    bool first = pr.id < id2;
    int32_t s = en.slot ? en.slot[p] : (int32_t)p, s2 = en.slot ? en.slot[q] : (int32_t)q;
    e.a = first ? s : s2;
    e.b = first ? s2 : s;
    e.lo = first ? ((uint64_t)pr.id << 31 | (uint64_t)id2) : ((uint64_t)id2 << 31 | (uint64_t)pr.id);
    unsigned long long at = atomicAdd(&be->n, 1ull);
    if (at < BLOCK_EVENTS) {
        be->e[at] = e;
    } else {
        unsigned long long g = list_append(found);
        if ((int64_t)g < cap) ev[g] = e;
    }
    atomicMin((unsigned long long *)&best_hi[e.a], (unsigned long long)e.hi);
    atomicMin((unsigned long long *)&best_hi[e.b], (unsigned long long)e.hi);
}

/* A warp's queue of candidates that near_path passed: each turn its lanes push up to two each onto
 * fewer than 32 held, and 32 at a time are tested. */
#define QUEUE 96

/* Lane `lane`'s candidate q joins the queue of `held` if keep (every lane of the warp calls this);
 * returns the new count. */
static __device__ __forceinline__ uint32_t queue_push(uint32_t *queue, uint8_t *owner, uint32_t held, bool keep,
                                                      uint32_t q, uint32_t lane)
{
    unsigned ball = __ballot_sync(0xffffffffu, keep);
    if (keep) {
        uint32_t at = held + __popc(ball & ((1u << lane) - 1));
        queue[at] = q;
        owner[at] = (uint8_t)lane;
    }
    return held + __popc(ball);
}

/* The first 32 tested: the `left` after them (fewer than QUEUE - 32) move to the front. */
static __device__ __forceinline__ void queue_shift(uint32_t *queue, uint8_t *owner, uint32_t left, uint32_t lane)
{
    static_assert(QUEUE <= 96, "two moves a lane");
    __syncwarp();
    uint32_t q1 = queue[lane + 32], q2 = lane + 64 < QUEUE ? queue[lane + 64] : 0;
    uint8_t o1 = owner[lane + 32], o2 = lane + 64 < QUEUE ? owner[lane + 64] : 0;
    __syncwarp();
    if (lane < left) {
        queue[lane] = q1;
        owner[lane] = o1;
    }
    if (lane + 32 < left) {
        queue[lane + 32] = q2;
        owner[lane + 32] = o2;
    }
    __syncwarp();
}

/* Where a lane stands in its probe's candidates (K > 1): entries q to qe - 1 of its current run, then
 * the runs left in its column (slots r to runs - 1). Its first run is the rest of its own row (Probe:
 * na); the column holds the others that are not empty: the row below (nb), then, for each slower level,
 * the 3 rows of 3 cells around the probe's cell in the slice of that level containing the probe's slice.
 * All are loaded before the search (probe_runs) into shared memory, slot s of thread t at s THREADS + t.
 * (Loaded as each run began, a lane's search waited on them in turn: at 4 levels the search took longer
 * than at one with half the candidates.) A run ends, in some lane of a warp, on most of the warp's
 * turns, so the whole warp takes that branch: it is two shared loads and two selects, with no empty
 * run to step over and no division (the slower levels' time offsets are computed once, into dts). */
typedef struct {
    uint32_t q, qe, r, runs;
    uint32_t lv; /* the slots where the second and the third level begin, in bits 0-7 and 8-15 */
    float dt;    /* the middle of the current run's level slice, before the probe's (near_path) */
} Cursor;

/* How long before the middle of the probe's level slice the middle of level b's slice containing it is
 * (slice_mid: (k + ke) / 2K). */
static __device__ __forceinline__ float level_offset(const Probe &pr, uint32_t b, int K)
{
    uint32_t a = PROBE_LEVEL(pr.k);
    int2 p = level_span(a, PROBE_SLICE(pr.k), K), q = level_span(b, (uint32_t)p.x >> b, K);
    return (float)(p.x + p.y - q.x - q.y) / (float)(2 * K);
}

/* Probe pr's runs after its first, those not empty, into its column (thread t's: runs + t), their
 * levels' time offsets into dts (dts + t, one slot a level from its own, which is 0), and into *shape
 * the column's length (bits 16 and up) and where its levels begin (Cursor: lv); returns its
 * candidates. k0, k1: the window's slices. */
static __device__ __forceinline__ uint32_t probe_runs(const Probe &pr, const Grid &gr, int k0, int k1,
                                                      const uint32_t *__restrict__ start, uint4 edge, uint2 *runs,
                                                      float *dts, uint32_t t, uint32_t *shape)
{
    uint32_t a = PROBE_LEVEL(pr.k), j = PROBE_SLICE(pr.k), g = (uint32_t)gr.g;
    uint32_t cy = pr.c / g, cx = pr.c - cy * g;
    uint32_t x0 = cx > 0 ? cx - 1 : 0, x1 = cx + 1 < g ? cx + 1 : g - 1;
    uint32_t slots = 0, lv = 0;
    if (pr.nb > 0) runs[slots++ * THREADS + t] = make_uint2(pr.b0, pr.b0 + pr.nb);
    if (edge.y > 0) runs[slots++ * THREADS + t] = make_uint2(edge.x, edge.x + edge.y); /* periodic: one level */
    if (edge.w > 0) runs[slots++ * THREADS + t] = make_uint2(edge.z, edge.z + edge.w);
    uint32_t total = pr.na + pr.nb + edge.y + edge.w;
    dts[t] = 0;
    for (uint32_t b = a + 1; b < (uint32_t)gr.levels; b++) {
        lv |= slots << (8 * (b - a - 1));
        dts[(b - a) * THREADS + t] = level_offset(pr, b, gr.K);
        uint32_t row = (uint32_t)level_base(k0, k1, (int)b) + (j >> (b - a)) - ((uint32_t)k0 >> b);
        for (uint32_t y = cy; y <= cy + 2; y++) { /* the row above, its own, the one below: y - 1 */
            if (y < 1 || y > g) continue;
            uint32_t base = row * gr.ncell + (y - 1) * g;
            uint2 run = make_uint2(__ldg(&start[base + x0]), __ldg(&start[base + x1 + 1]));
            if (run.y > run.x) runs[slots++ * THREADS + t] = run;
            total += run.y - run.x;
        }
    }
    for (uint32_t b = (uint32_t)gr.levels; b < a + 3; b++) lv |= slots << (8 * (b - a - 1)); /* none */
    *shape = slots << 16 | lv;
    return total;
}

/* The cursor before probe entry p's first candidate, of its na and its column (shape: probe_runs');
 * where there is no probe (p at or past end), one with none, at entry p0 (cursor_take: qe - 1 is an
 * entry). */
static __device__ __forceinline__ Cursor cursor_start(uint32_t p, uint32_t na, uint32_t shape, uint32_t end,
                                                      uint32_t p0)
{
    Cursor cu;
    cu.q = p < end ? p + 1 : p0 + 1;
    cu.qe = cu.q + na;
    cu.r = 0;
    cu.runs = shape >> 16;
    cu.lv = shape & 0xffffu;
    cu.dt = 0;
    return cu;
}

/* The lane's candidates of a turn: the next two of its current run, or of the next run where the current
 * one is done. Into q0 and q1 where got, else an entry there is (the last of the lane's current run, or
 * its own, to be screened and not kept), and into dt their run's offset; the
 * second is not got where the run has only one left (a run of odd length leaves one turn half used:
 * about 5% more turns at N = 32000, for one branch a turn instead of two). col, dts: the thread's column
 * of runs and of offsets. */
static __device__ __forceinline__ void cursor_take(Cursor &cu, uint32_t &q0, uint32_t &q1, bool &got0, bool &got1,
                                                   const uint2 *col, const float *dts)
{
    if (cu.q >= cu.qe && cu.r < cu.runs) {
        uint2 run = col[cu.r * THREADS];
        cu.q = run.x;
        cu.qe = run.y;
        cu.dt = dts[((cu.r >= (cu.lv & 0xffu)) + (cu.r >= (cu.lv >> 8))) * THREADS];
        cu.r++;
    }
    got0 = cu.q < cu.qe;
    got1 = cu.q + 1 < cu.qe;
    q0 = got0 ? cu.q : cu.qe - 1;
    q1 = got1 ? cu.q + 1 : cu.qe - 1;
    cu.q = got0 ? cu.q + 2 : cu.q;
}

/* The periodic box's runs of a probe in cell cx of a row whose first cell is `row` (g >= 3 cells a
 * side), the row below it starting at `below` (row 0 below the last): the three cells below, cx - 1 to
 * cx + 1 wrapped, as the run *b0, *nb of the two that lie together and a second run of the third where
 * the row wraps (edge.x, edge.y); the cell right of the last one, the row's first (edge.z, edge.w).
 * Every pair of neighbouring cells is then searched once, as in the walled box's half of the 3x3 cells. */
static __device__ __forceinline__ uint4 edge_runs(const uint32_t *__restrict__ start, uint32_t row, uint32_t below,
                                                  uint32_t cx, uint32_t g, uint32_t *b0, uint32_t *nb)
{
    uint4 e = make_uint4(0, 0, 0, 0);
    uint32_t lo = cx == 0 ? 0 : cx - 1, hi = cx + 1 < g ? cx + 1 : g - 1; /* the cells below that lie together */
    *b0 = __ldg(&start[below + lo]);
    *nb = __ldg(&start[below + hi + 1]) - *b0;
    uint32_t w = cx == 0 ? g - 1 : (cx == g - 1 ? 0 : g); /* the cell below across the edge, g: none */
    if (w < g) {
        e.x = __ldg(&start[below + w]);
        e.y = __ldg(&start[below + w + 1]) - e.x;
    }
    if (cx == g - 1) {
        e.z = __ldg(&start[row]);
        e.w = __ldg(&start[row + 1]) - e.z;
    }
    return e;
}

/* Candidate i of probe po at entry p: its own row's rest, the row below, then the edges' runs. */
template <bool PERIODIC>
static __device__ __forceinline__ uint32_t candidate(const Probe &po, uint32_t p, uint32_t i)
{
    if (i < po.na) return p + 1 + i;
    i -= po.na;
    if (!PERIODIC) return po.b0 + i; /* no edge runs */
    if (i < po.nb) return po.b0 + i;
    i -= po.nb;
    return i < po.edge.y ? po.edge.x + i : po.edge.z + (i - po.edge.y);
}

/* Window w's entries, a tile of THREADS per block; TILES: the blocks take turns over the tiles (a later
 * window's launch is sized for all of its disks, of which few are left), else one tile each (the loop's
 * state spilled registers: 6% slower at N = 32000). PERIODIC: the box is periodic (Grid.periodic), a
 * constant of each build: with the box's wrapping in the walled box's search too, that search took
 * registers and instructions it never uses (random scene, N = 32000: its search 13.9 -> 16.0 ms, the
 * gas of 1e7's spilled). */
template <bool TILES, bool MID, bool PERIODIC>
__global__ void __launch_bounds__(THREADS, MID ? DETECT_MIN_BLOCKS_MID : DETECT_MIN_BLOCKS)
    detect_kernel(Entries en, const uint32_t *__restrict__ keys, const uint32_t *__restrict__ start,
                  const Grid *grid, int w, real sigma2, PairEvent *ev, int64_t cap, StepInfo *info,
                  uint64_t *best_hi)
{
    after_previous();
    typedef cub::BlockScan<uint32_t, THREADS> Scan;
    __shared__ typename Scan::TempStorage scan_tmp;
    __shared__ Probe probes[THREADS];
    /* !MID deals candidates out: where each thread's begin, and the thread whose entry each dealt pair is;
     * MID: each thread's column of runs (probe_runs' shape) */
    __shared__ uint32_t first[THREADS];
    static_assert(THREADS <= 256, "owner holds a thread index in 8 bits");
    __shared__ uint8_t owner[DEAL_MAX > 0 && !MID ? DEAL_MAX * THREADS : 1];
    __shared__ BlockEvents be;
    __shared__ unsigned long long tests;
    __shared__ uint32_t queue[THREADS / 32][QUEUE]; /* per warp: candidates near_path passed, and whose */
    __shared__ uint8_t queue_owner[THREADS / 32][QUEUE];
    extern __shared__ uint2 runs[]; /* MID: RUN_BYTES (Cursor), then the offsets */
    float *dts = (float *)(runs + PROBE_RUNS * THREADS);
    const Grid gr = *grid;
    /* !TILES: a step of one window (w = 0, all K slices); the constants keep the loop's registers */
    const uint32_t end = TILES ? window_end(grid, w, start) : __ldg(&start[gr.cells]);
    const uint32_t k0 = TILES ? (uint32_t)grid->wb[w] : 0;
    const uint32_t k1 = TILES ? (uint32_t)grid->wb[w + 1] : (uint32_t)grid->wb[1];
    unsigned long long *found = &info->found[TILES ? w : 0];
    for (uint32_t p0 = blockIdx.x * blockDim.x; p0 < end; p0 += gridDim.x * blockDim.x) { /* block-uniform */
        if (!TILES && p0 != blockIdx.x * blockDim.x) break;
        uint32_t p = p0 + threadIdx.x, seen = 0; /* seen: MID, the probe's candidates */
        Probe pr = {};
        if (p < end) {
            /* MID: the entry's key as placed; one slice: the disk's key as its binning found it, from the
             * disk itself (a pass of 8 bytes a disk fewer: place_kernel) */
            uint32_t key = MID ? __ldg(&keys[p])
                               : cell_key(*grid, __ldg(&en.pos[p]), __ldg(&en.vel[p]), slice_mid(0, 0, 1), 0, NULL);
            uint32_t g = (uint32_t)gr.g;
            uint32_t kl = key / gr.ncell; /* the cell row: a slice of one level */
            uint32_t c = key - kl * gr.ncell, cy = c / g, cx = c - cy * g;
            uint32_t x0 = cx > 0 ? cx - 1 : 0, x1 = cx + 1 < g ? cx + 1 : g - 1;
            uint32_t row = kl * gr.ncell + cy * g;
            if (MID) {
                uint32_t base, lv = row_level(kl, k0, k1, gr.levels, &base);
                pr.k = ((k0 >> lv) + (kl - base)) | (lv << 16);
            } else {
                pr.k = kl + k0;
            }
            pr.c = c;
            pr.na = __ldg(&start[row + x1 + 1]) - (p + 1);
            uint4 edge = make_uint4(0, 0, 0, 0); /* periodic: the runs across the box's edges */
            if (PERIODIC && g >= 3) {
                edge = edge_runs(start, row, kl * gr.ncell + (cy + 1 < g ? (cy + 1) * g : 0), cx, g, &pr.b0, &pr.nb);
            } else if (cy + 1 < g) {
                pr.b0 = __ldg(&start[row + g + x0]);
                pr.nb = __ldg(&start[row + g + x1 + 1]) - pr.b0;
            }
            pr.pos = __ldg(&en.pos[p]);
            pr.vel = __ldg(&en.vel[p]);
            pr.id = __ldg(&en.id[p]);
            pr.wall = __ldg(&en.wall[p]);
            if (MID) pr.mid = __ldg(&en.mid[p]);
            else pr.edge = edge;
            if (MID)
                seen = probe_runs(pr, gr, (int)k0, (int)k1, start, edge, runs, dts, threadIdx.x, &first[threadIdx.x]);
        } else if (MID) {
            first[threadIdx.x] = 0;
        }
        probes[threadIdx.x] = pr; /* read back from there: fewer registers held across the loops */
        if (threadIdx.x == 0) {
            be.n = 0;
            tests = 0;
        }
        if (MID) {
            /* each lane walks its own candidates (Cursor) and screens them, two a turn (their loads
             * overlap); those passed queue up in the warp, and each 32 of them take one pair test a
             * lane (tested where found, few lanes of a warp would do the work of all). The loop is
             * what the search spends its instructions on: a lane with no candidate left loads an entry
             * of its own runs rather than branch around the load, and the queue is touched only by
             * turns in which some lane passed one. */
            __syncthreads();
            const uint32_t lane = threadIdx.x & 31, warp = threadIdx.x >> 5;
            const Probe &mine = probes[threadIdx.x];
            const uint2 *col = runs + threadIdx.x;
            const float *off = dts + threadIdx.x;
            const float4 m = mine.mid;
            const int2 span = level_span(PROBE_LEVEL(mine.k), PROBE_SLICE(mine.k), gr.K);
            const float h = (float)(span.y - span.x) / (float)(2 * gr.K), pad2 = gr.pad * gr.pad;
            const bool wrap = PERIODIC;
            const float wl = (float)gr.Lw, wh = wl / 2;
            Cursor cu = cursor_start(p, mine.na, first[threadIdx.x], end, p0);
            uint32_t *wq = queue[warp];
            uint8_t *wo = queue_owner[warp];
            uint32_t held = 0;
            for (;;) {
                uint32_t q0, q1;
                bool got0, got1;
                cursor_take(cu, q0, q1, got0, got1, col, off);
                if (!__any_sync(0xffffffffu, got0)) break;
                float4 m0 = __ldg(&en.mid[q0]), m1 = __ldg(&en.mid[q1]);
                /* screened whether got or not (cursor_take: an entry there is), so no branch */
                bool keep0 = near_path(m, m0, cu.dt, h, pad2, wrap, wl, wh) & got0;
                bool keep1 = near_path(m, m1, cu.dt, h, pad2, wrap, wl, wh) & got1;
                if (!__any_sync(0xffffffffu, keep0 || keep1)) continue;
                held = queue_push(wq, wo, held, keep0, q0, lane);
                held = queue_push(wq, wo, held, keep1, q1, lane);
                for (; held >= 32; held -= 32) {
                    __syncwarp();
                    uint32_t o = warp * 32 + wo[lane];
                    test_pair<PERIODIC>(en, gr, probes[o], p0 + o, wq[lane], sigma2, &be, ev, cap, found, best_hi);
                    queue_shift(wq, wo, held - 32, lane);
                }
            }
            __syncwarp();
            if (lane < held) {
                uint32_t o = warp * 32 + wo[lane];
                test_pair<PERIODIC>(en, gr, probes[o], p0 + o, wq[lane], sigma2, &be, ev, cap, found, best_hi);
            }
            unsigned long long sum = seen; /* 64 bits: a warp's counts can pass 2^32 */
            for (int d = 16; d > 0; d /= 2) sum += __shfl_down_sync(0xffffffffu, sum, d);
            if (lane == 0 && sum) atomicAdd(&tests, sum);
        } else {
            /* counts above the dealing limit are cut to one more than it: the sum then fits in 32 bits,
             * and is exact wherever it is within the limit */
            const uint32_t deal = DEAL_MAX * THREADS;
            uint32_t count = pr.na + pr.nb + (PERIODIC ? pr.edge.y + pr.edge.w : 0), offset, total;
            Scan(scan_tmp).ExclusiveSum(count <= deal ? count : deal + 1, offset, total);
            if (total > deal) { /* block-uniform */
                __syncthreads();
                unsigned long long sum = count; /* 64 bits: a warp's counts can pass 2^32 */
                for (int d = 16; d > 0; d /= 2) sum += __shfl_down_sync(0xffffffffu, sum, d);
                if ((threadIdx.x & 31) == 0) atomicAdd(&tests, sum);
                const Probe po = probes[threadIdx.x]; /* a copy: the loop keeps it in registers */
                for (uint32_t i = 0; i < count; i++)
                    test_pair<PERIODIC>(en, gr, po, p, candidate<PERIODIC>(po, p, i), sigma2, &be, ev, cap, found,
                                        best_hi);
            } else {
                if (threadIdx.x == 0) tests = total;
                first[threadIdx.x] = offset;
                for (uint32_t i = 0; i < count; i++) owner[offset + i] = (uint8_t)threadIdx.x;
                __syncthreads();
                for (uint32_t j = threadIdx.x; j < total; j += THREADS) {
                    uint32_t o = owner[j], i = j - first[o];
                    const Probe po = probes[o];
                    test_pair<PERIODIC>(en, gr, po, p0 + o, candidate<PERIODIC>(po, p0 + o, i), sigma2, &be, ev, cap,
                                        found, best_hi);
                }
            }
        }
        __syncthreads();
        if (threadIdx.x == 0 && tests) atomicAdd(&info->tests, tests);
        unsigned kept = be.n < BLOCK_EVENTS ? (unsigned)be.n : BLOCK_EVENTS;
        if (kept > 0) { /* block-uniform */
            if (threadIdx.x == 0) be.base = atomicAdd(found, (unsigned long long)kept);
            __syncthreads();
            for (unsigned i = threadIdx.x; i < kept; i += THREADS)
                if ((int64_t)(be.base + i) < cap) ev[be.base + i] = be.e[i];
        }
        /* the shared records are rewritten by the next tile; with one tile, warps done leave at once */
        if (TILES) __syncthreads();
    }
}

/* ==== choose ============================================================================================= */
/* best_hi/best_lo of a disk: the smallest key among its remaining events (its wall event and the pair
 * events in the current list). partner: -1 none yet, itself for an accepted wall event, else the other
 * slot of its accepted pair. Each phase below is one pass over a list; the grid versions are separate
 * kernels, the one-block version separates them with __syncthreads. */

static __device__ __forceinline__ void pass_min_lo(const PairEvent *ev, int64_t i, const uint64_t *best_hi,
                                                   uint64_t *best_lo)
{
    PairEvent e = ev[i];
    if (best_hi[e.a] == e.hi) atomicMin((unsigned long long *)&best_lo[e.a], (unsigned long long)e.lo);
    if (best_hi[e.b] == e.hi) atomicMin((unsigned long long *)&best_lo[e.b], (unsigned long long)e.lo);
}

static __device__ __forceinline__ void pass_min_hi(const PairEvent *ev, int64_t i, uint64_t *best_hi)
{
    PairEvent e = ev[i];
    atomicMin((unsigned long long *)&best_hi[e.a], (unsigned long long)e.hi);
    atomicMin((unsigned long long *)&best_hi[e.b], (unsigned long long)e.hi);
}

/* Every write here stores a value that any other writer of the same place would store too. */
static __device__ __forceinline__ void pass_accept(const PairEvent *ev, int64_t i, const uint64_t *best_hi,
                                                   const uint64_t *best_lo, int32_t *partner)
{
    PairEvent e = ev[i];
    uint64_t ha = best_hi[e.a], hb = best_hi[e.b];
    if (ha == e.hi && hb == e.hi && best_lo[e.a] == e.lo && best_lo[e.b] == e.lo) {
        partner[e.a] = e.b;
        partner[e.b] = e.a;
        return;
    }
    if (!(ha & 1)) partner[e.a] = e.a; /* the wall event is the smallest: accepted */
    if (!(hb & 1)) partner[e.b] = e.b;
}

/* Keeps the events whose disks are both still free, and restarts those disks' best keys. */
static __device__ __forceinline__ void pass_compact(const PairEvent *ev, int64_t i, PairEvent *out,
                                                    unsigned long long *count_out, int64_t cap,
                                                    const int32_t *partner, const uint64_t *wall_hi,
                                                    uint64_t *best_hi, uint64_t *best_lo)
{
    PairEvent e = ev[i];
    if (partner[e.a] >= 0 || partner[e.b] >= 0) return;
    unsigned long long at = list_append(count_out); /* < cap: no list outgrows the one it came from */
    if ((int64_t)at < cap) out[at] = e;
    best_hi[e.a] = wall_hi[e.a];
    best_hi[e.b] = wall_hi[e.b];
    best_lo[e.a] = NO_EVENT;
    best_lo[e.b] = NO_EVENT;
}

static __device__ __forceinline__ int64_t list_len(const unsigned long long *count, int64_t cap)
{
    int64_t c = (int64_t)*count;
    return c < cap ? c : cap;
}

__global__ void min_lo_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              const uint64_t *best_hi, uint64_t *best_lo)
{
    after_previous();
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_min_lo(ev, i, best_hi, best_lo);
}

__global__ void min_hi_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              uint64_t *best_hi)
{
    after_previous();
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_min_hi(ev, i, best_hi);
}

__global__ void accept_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              const uint64_t *best_hi, const uint64_t *best_lo, int32_t *partner)
{
    after_previous();
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_accept(ev, i, best_hi, best_lo, partner);
}

__global__ void compact_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                               PairEvent *out, unsigned long long *count_out, const int32_t *partner,
                               const uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo)
{
    after_previous();
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_compact(ev, i, out, count_out, cap, partner, wall_hi, best_hi, best_lo);
}

/* The remaining rounds in one block, until no pair event is left. */
__global__ void finish_kernel(PairEvent *ev0, PairEvent *ev1, const unsigned long long *count, int64_t cap,
                              int32_t *partner, const uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo)
{
    after_previous();
    __shared__ unsigned long long n_out;
    PairEvent *in = ev0, *out = ev1;
    int64_t len = list_len(count, cap);
    for (;;) {
        if (threadIdx.x == 0) n_out = 0;
        __syncthreads();
        for (int64_t i = threadIdx.x; i < len; i += blockDim.x)
            pass_compact(in, i, out, &n_out, cap, partner, wall_hi, best_hi, best_lo);
        __syncthreads();
        len = (int64_t)n_out;
        if (len == 0) return;
        for (int64_t i = threadIdx.x; i < len; i += blockDim.x) pass_min_hi(out, i, best_hi);
        __syncthreads();
        for (int64_t i = threadIdx.x; i < len; i += blockDim.x) pass_min_lo(out, i, best_hi, best_lo);
        __syncthreads();
        for (int64_t i = threadIdx.x; i < len; i += blockDim.x) pass_accept(out, i, best_hi, best_lo, partner);
        __syncthreads();
        PairEvent *t = in;
        in = out;
        out = t;
    }
}

/* ==== move =============================================================================================== */

/* A GPU rank's step (mpi_cuda.cu): its slots hold its own disks and copies of other ranks' disks (the
 * halo), which the move leaves where they are; the collision counts travel with the own disks. */
typedef struct {
    const uint32_t *order;        /* cell place -> slot before the gather: copies are the slots own and up */
    int64_t own;
    const int32_t *pc_in, *wc_in; /* by slot before the gather */
    /* the own disks whose x stays in [c0, c1) (no bound below where first, above where last) go to the
     * front of the new state, with their counts in pc_out, wc_out (count[0] of them); the others
     * (count[1]) as records of mpi_cuda.h into rec, up to cap */
    double c0, c1;
    int first, last;
    int32_t *pc_out, *wc_out;
    double *rec;
    int64_t cap;
    unsigned long long *count;
} RankMove;

/* A disk as a record of mpi_cuda.h (D_LEN doubles), for another rank or the host. */
static __device__ __forceinline__ void write_record(double *d, real2 pos, real2 vel, int32_t id, int32_t pc,
                                                    int32_t wc)
{
    d[D_ID] = id, d[D_X] = pos.x, d[D_Y] = pos.y, d[D_VX] = vel.x, d[D_VY] = vel.y, d[D_PC] = pc, d[D_WC] = wc;
    d[D_WI] = 0;
}

/* A GPU rank's own disk after its move: true where it stays in the strip (the caller keeps it), else
 * packed for another rank. */
static __device__ __forceinline__ bool rank_stays(const RankMove &rm, real2 pos, real2 vel, int32_t id, int32_t pc,
                                                  int32_t wc)
{
    double x = (double)pos.x;
    if ((rm.first || x >= rm.c0) && (rm.last || x < rm.c1)) return true;
    unsigned long long k = list_append(&rm.count[1]);
    /* beyond cap the host makes room and moves the step again */
    if ((int64_t)k < rm.cap) write_record(rm.rec + k * D_LEN, pos, vel, id, pc, wc);
    return false;
}

/* One slice a step: the move also keys its disks' cells for the next step, each slot being its entry, on
 * the grid the gate fitted ahead (gate_kernel); the next step only counts them (count_kernel), and spares
 * a pass over the state. Gas of 1e7 on the H100: 5.595e9 -> 5.769e9 particle-steps/s, dense gas 4.645e9
 * -> 4.749e9 (bench/gpu_h100_goals.log, 71b5eb2's section). Counting in the move as well, with an atomic a
 * disk, cost the move more than it saved (bench/gpu_h100_variants.log 12a). */
typedef struct {
    const Grid *grid;
    uint32_t *keys;
} MoveBin;

/* Old buffers in, new buffers out. A disk with no accepted pair and a wall event within the step has
 * had that wall event accepted: no remaining pair event of it was smaller. A step whose pair events
 * overflowed the list decided on part of them only: it is refused here, before anything is written.
 * RANK: a GPU rank's step (RankMove), else pc and wc are in original order. BIN (not with RANK): the
 * disks keyed for the next step (MoveBin). */
template <bool RANK, bool BIN>
__global__ void move_kernel(DevState in, DevState out, int64_t n, Params par, const int32_t *partner,
                            const uint64_t *wall_hi, const uint64_t *best_hi, int32_t *pc, int32_t *wc,
                            StepInfo *info, int64_t cap, Control *ctl, RankMove rm, MoveBin mb)
{
    static_assert(!(RANK && BIN), "a GPU rank bins its disks with its halo");
    after_previous();
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    real2 pos = {0, 0}, vel = {0, 0};
    int32_t id = 0, o = -1;
    uint64_t wall = NO_EVENT;
    uint32_t from = 0;
    if (s < n) { /* loaded before the checks below, so that their loads overlap */
        pos = in.pos[s];
        vel = in.vel[s];
        id = in.id[s];
        o = partner[s];
        wall = wall_hi[s];
        if (RANK) from = rm.order[s];
    }
    if (refused(ctl)) return;
    unsigned long long most = 0;
    for (int w = 0; w < WMAX; w++) most = info->found[w] > most ? info->found[w] : most;
    if (most > (unsigned long long)cap) {
        if (blockIdx.x == 0 && threadIdx.x == 0) {
            ctl->overflow = most;
            ctl->refused = 1;
        }
        return;
    }
    real vabs = 0;
    unsigned long long accepted = 0;
    int dp = 0, dw = 0; /* collisions with a disk, with a wall */
    bool stays = false; /* RANK: an own disk kept at the front of out (below, with pos, vel, id, pc1, wc1) */
    int32_t pc1 = 0, wc1 = 0;
    if (s < n && (!RANK || from < rm.own)) { /* a rank's copies stay as they are */
        real lo = par.lo, hi = par.hi;
        real x = pos.x, y = pos.y, vx = vel.x, vy = vel.y;
        if (o < 0 && wall != NO_EVENT) o = (int32_t)s;
        if (o < 0) {
            x = x + vx;
            y = y + vy;
        } else if (o == s) {
            real t1 = key_time(wall);
            wall_bounce(&x, &y, &vx, &vy, t1, lo, hi);
            finish_step(&x, &y, vx, vy, t1, lo, hi);
            dw = 1;
            accepted = 1;
        } else {
            /* both partners compute the contact with the lower original index as i, then each
             * finishes its own side: the arithmetic of pair_collide */
            real t1 = key_time(best_hi[s]);
            real2 pos2 = in.pos[o], vel2 = in.vel[o];
            real x2 = pos2.x, y2 = pos2.y, vx2 = vel2.x, vy2 = vel2.y;
            int mine_first = id < in.id[o];
            real xi = mine_first ? x : x2, yi = mine_first ? y : y2;
            real vxi = mine_first ? vx : vx2, vyi = mine_first ? vy : vy2;
            real xj = mine_first ? x2 : x, yj = mine_first ? y2 : y;
            real vxj = mine_first ? vx2 : vx, vyj = mine_first ? vy2 : vy;
            if (par.periodic)
                (void)pair_contact_wrap(&xi, &yi, &vxi, &vyi, &xj, &yj, &vxj, &vyj, t1, par.L, par.half);
            else
                (void)pair_contact(&xi, &yi, &vxi, &vyi, &xj, &yj, &vxj, &vyj, t1);
            x = mine_first ? xi : xj, y = mine_first ? yi : yj;
            vx = mine_first ? vxi : vxj, vy = mine_first ? vyi : vyj;
            if (par.periodic)
                fly_rest(&x, &y, vx, vy, t1);
            else
                finish_step(&x, &y, vx, vy, t1, lo, hi);
            dp = 1;
            accepted = mine_first;
        }
        if (!RANK) {
            if (dp) pc[id]++;
            if (dw) wc[id]++;
        }
        real2 pos1, vel1;
        pos1.x = par.periodic ? wrap_coord(x, par.L) : clamp_coord(x, lo, hi);
        pos1.y = par.periodic ? wrap_coord(y, par.L) : clamp_coord(y, lo, hi);
        vel1.x = vx;
        vel1.y = vy;
        if (RANK) {
            pc1 = rm.pc_in[from] + dp, wc1 = rm.wc_in[from] + dw;
            stays = rank_stays(rm, pos1, vel1, id, pc1, wc1);
            pos = pos1, vel = vel1;
        } else {
            out.pos[s] = pos1, out.vel[s] = vel1, out.id[s] = id;
        }
        if (BIN) /* as bin_kernel keys the entry of slot s in a step of one slice */
            mb.keys[s] = cell_key(*mb.grid, pos1, vel1, slice_mid(0, 0, 1), 0, info);
        real ax = SIM_FABS(vx), ay = SIM_FABS(vy);
        vabs = ax < ay ? ay : ax;
    }
    if (RANK) {
        /* the block's kept disks in thread order after one atomic on the count: with one a warp, all on
         * one address, the moves of the 1e8 gas on 2 GPUs took 0.0675 s over 20 steps, against 0.0462
         * (4-H100 host, --stats; bench/mpi_h100_gpu_ranks.log) */
        typedef cub::BlockScan<int, THREADS> ScanK;
        __shared__ typename ScanK::TempStorage tmp_k;
        __shared__ unsigned long long kept_base;
        int at, total;
        ScanK(tmp_k).ExclusiveSum(stays ? 1 : 0, at, total);
        if (threadIdx.x == 0 && total > 0) kept_base = atomicAdd(&rm.count[0], (unsigned long long)total);
        __syncthreads();
        if (stays) {
            unsigned long long k = kept_base + (unsigned long long)at;
            out.pos[k] = pos;
            out.vel[k] = vel;
            out.id[k] = id;
            rm.pc_out[k] = pc1;
            rm.wc_out[k] = wc1;
        }
    }
    typedef cub::BlockReduce<real, THREADS> ReduceR;
    typedef cub::BlockReduce<unsigned long long, THREADS> ReduceU;
    __shared__ typename ReduceR::TempStorage tmp_r;
    __shared__ typename ReduceU::TempStorage tmp_u;
    real m = ReduceR(tmp_r).Reduce(vabs, cuda::maximum<>());
    unsigned long long a = ReduceU(tmp_u).Sum(accepted);
    if (threadIdx.x == 0) {
        atomicMax(&info->vmax, (unsigned long long)__double_as_longlong((double)m));
        if (a) atomicAdd(&info->events, a);
    }
}

/* Print mode: the state back in original index order, for the copy to the host. */
__global__ void unpermute_kernel(DevState st, int64_t n, real *x, real *y, real *vx, real *vy,
                                 const Control *ctl)
{
    if (refused(ctl)) return;
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (s >= n) return;
    int32_t i = st.id[s];
    real2 pos = st.pos[s], vel = st.vel[s];
    x[i] = pos.x;
    y[i] = pos.y;
    vx[i] = vel.x;
    vy[i] = vel.y;
}

/* The input's state, in original order, into the first state buffer (slot s holds disk s). */
__global__ void pair_up_kernel(DevState st, int64_t n, const real *x, const real *y, const real *vx, const real *vy)
{
    int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    real2 pos, vel;
    pos.x = x[i];
    pos.y = y[i];
    vel.x = vx[i];
    vel.y = vy[i];
    st.pos[i] = pos;
    st.vel[i] = vel;
    st.id[i] = (int32_t)i;
}

/* ==== host side ========================================================================================== */

#ifndef BATCH
#define BATCH 8             /* steps planned together; the host reads the control record once per batch */
#endif
#define RING (2 * BATCH)    /* steps in flight at most: two batches */
#define SPEED_SLACK 1.0625  /* plans allow cells this much finer than the last known speed needs */
#define SLICE_SLACK 1.25    /* and this many times the slices (speeds grow as collisions spread them) */
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
    int64_t scans[2];                    /* cell tables scanned by cub, and short (--stats) */
    Entries en;                          /* K > 1 only */
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
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<false, true, false>, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                    (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<true, true, false>, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                    (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<false, true, true>, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                    (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<true, true, true>, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                    (int)RUN_BYTES));
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
    /* SIM_CUDA_BIN_AHEAD=S: moves key the disks' cells for the next step of their batch on cells fitted to
     * S times the speed (0: they do not; the tests take 1, where steps often bin anew) */
    const char *bin_ahead = getenv("SIM_CUDA_BIN_AHEAD");
    c->ahead_slack = bin_ahead ? atof(bin_ahead) : BIN_AHEAD;
    if (!(c->ahead_slack >= 1)) c->ahead_slack = 0;
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
    c->ahead = (Grid *)dev_alloc(sizeof(Grid), "counters");
    CUDA_CHECK(cudaMallocHost((void **)&c->ctl_host, 2 * sizeof(Control)));
    /* The scene's plans size the entries and cells (buffers_fit, below): a gas of one slice a step
     * takes one entry and at most CELLS_PER_DISK cells a disk. What is left of the device after the
     * state bounds only the slices a plan may take: up to ENTRY_MEMORY of it for entries (per entry,
     * four 4-byte keys, three cells of count and start, and with K > 1 a copy of the disk), at most
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
    b += (double)c->copy_cap * (2 * sizeof(real2) + 4 + 4 + 8 + sizeof(float4)); /* entry copies */
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
    cudaFree(c->en.pos);
    cudaFree(c->en.vel);
    cudaFree(c->en.id);
    cudaFree(c->en.slot);
    cudaFree(c->en.wall);
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

static Plan plan_for(const Cuda *c, double vmax, const int *rounds, const double *found, int F)
{
    Plan pl;
    pl.vmax = speed_bits(vmax);
    /* room for the disks to speed up by SLICE_SLACK, or slow down by SPEED_SLACK, before the grid is
     * coarser than it could be (extra slices cost only threads that return at once) */
    pl.K = grid_slices(&c->lim, vmax * SLICE_SLACK);
    pl.gcap = grid_fit(&c->lim, vmax / SPEED_SLACK, pl.K, INT64_MAX).g;
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
            pl.wcells[w] = (int64_t)rows * pl.gcap * pl.gcap;
            most = pl.wcells[w] > most ? pl.wcells[w] : most;
        }
        if (most <= c->lim.cell_cap || pl.levels == 1) break;
        pl.levels--;
    }
    for (int w = 0; w < pl.W; w++) {
        int kw = window_start(w + 1, pl.F, pl.W, pl.K) - window_start(w, pl.F, pl.W, pl.K);
        pl.went[w] = c->n * kw;
        pl.rounds[w] = rounds[w];
        /* the rounds loop over the list's length on the device: fewer blocks only take more turns */
        double b = (2 * found[w] + 4096) / THREADS, most = 8.0 * c->sms;
        pl.choose_blocks[w] = b < most ? (int64_t)b : (int64_t)most;
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
            cudaFree(c->en.pos), cudaFree(c->en.vel), cudaFree(c->en.id), cudaFree(c->en.slot);
            cudaFree(c->en.wall), cudaFree(c->en.mid);
            size_t ne = (size_t)e;
            c->en.pos = (real2 *)dev_alloc(ne * sizeof(real2), "the entry copies");
            c->en.vel = (real2 *)dev_alloc(ne * sizeof(real2), "the entry copies");
            c->en.id = (int32_t *)dev_alloc(ne * 4, "the entry copies");
            c->en.slot = (int32_t *)dev_alloc(ne * 4, "the entry copies");
            c->en.wall = (uint64_t *)dev_alloc(ne * 8, "the entry copies");
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

/* Window w's binned entries placed in cell order: the exclusive sum of the counts (short_scan: by the
 * two short kernels, bin_clear), then each entry's place. */
template <bool WINDOWS>
static void scan_place_launch(Cuda *c, const Plan *pl, int w, const int32_t *act, const int32_t *lev, int ring,
                              bool short_scan)
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
    if (lev)
        step_kernel(c, blocks, THREADS, 0, place_kernel<WINDOWS, true>, c->grid, w, c->n, lev, c->info, c->keys,
                    c->rank, c->start, sorted, c->order);
    else
        step_kernel(c, blocks, THREADS, 0, place_kernel<WINDOWS, false>, c->grid, w, c->n, lev, c->info, c->keys,
                    c->rank, c->start, sorted, c->order);
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
        step_kernel(c, loop_blocks(c, c->n, 16), THREADS, 0, bin_kernel<true, false>, c->st[in], c->n, c->grid, 0,
                    act, lev, c->info, c->wall_hi, c->keys, c->rank, c->count);
        step_kernel(c, blocks_for(c->n), THREADS, 0, count_kernel, c->grid, c->n, c->keys, c->rank, c->count);
    } else {
        if (lev)
            step_kernel(c, blocks, THREADS, 0, bin_kernel<WINDOWS, true>, c->st[in], c->n, c->grid, w, act, lev,
                        c->info, c->wall_hi, c->keys, c->rank, c->count);
        else
            step_kernel(c, blocks, THREADS, 0, bin_kernel<WINDOWS, false>, c->st[in], c->n, c->grid, w, act, lev,
                        c->info, c->wall_hi, c->keys, c->rank, c->count);
    }
    phase_mark(c, ring, w, 1);
    scan_place_launch<WINDOWS>(c, pl, w, act, lev, ring, short_scan);
}

/* The pair search over window w's entries, placed and copied to en (with midpoints where K > 1), in the
 * build for the run's box. */
template <bool PERIODIC>
static void detect_box(Cuda *c, const Plan *pl, int w, const Entries &en)
{
    int64_t one = blocks_for(pl->went[w]), tiles = loop_blocks(c, pl->went[w], LOOP_BLOCKS * DETECT_MIN_BLOCKS);
    const uint32_t *keys = c->keys_sorted, *start = c->start;
    if (pl->K == 1)
        step_kernel(c, one, THREADS, 0, detect_kernel<false, false, PERIODIC>, en, keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else if (pl->W == 1)
        step_kernel(c, one, THREADS, RUN_BYTES, detect_kernel<false, true, PERIODIC>, en, keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else
        step_kernel(c, tiles, THREADS, RUN_BYTES, detect_kernel<true, true, PERIODIC>, en, keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
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
    step_kernel(c, 1, 1, 0, gate_kernel, c->ctl, c->info, c->counts, c->lim, pl->vmax, pl->K, pl->gcap, pl->F, pl->W,
                pl->levels, c->grid, c->ahead, (int)keyed, key_ahead ? c->ahead_slack : 0.0);
    if (pl->K == 1) {
        phase_mark(c, ring, 0, 0);
        bin_place_launch<false>(c, pl, 0, in, NULL, NULL, ring, keyed);
        step_kernel(c, blocks_for(n), THREADS, 0, gather_state_kernel, c->st[in], c->st[1 - in], c->order, n,
                    c->par, c->wall_hi, c->best_hi, c->best_lo, c->partner, c->ctl, (uint32_t *)NULL);
        in = 1 - in;
        DevState *d = &c->st[in];
        Entries en;
        en.pos = d->pos, en.vel = d->vel, en.id = d->id;
        en.slot = NULL;
        en.wall = c->wall_hi;
        en.mid = NULL;
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
            step_kernel(c, window_blocks(c, pl, w), THREADS, 0, gather_entries_kernel, c->st[in], n, w, act, lev,
                        c->info, c->order, c->start, grid, c->wall_hi, c->en);
            phase_mark(c, ring, w, 3);
            detect_launch(c, pl, w, c->en);
            choose_launch(c, pl, w, c->wall_win, ring);
        }
    }
    RankMove none = {};
    MoveBin mb = {c->ahead, c->keys}; /* read by move_kernel<false, true> alone */
    auto move = key_ahead ? move_kernel<false, true> : move_kernel<false, false>;
    step_kernel(c, blocks_for(n), THREADS, 0, move, c->st[in], c->st[1 - in], n, c->par, c->partner, c->wall_hi,
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
    /* the first plan's buffers before the clock starts, as cuda_open's; a scene of several slices a
     * step finds up to some n / 2 pair events a step (a gas some n / 15), so its event list starts so */
    Plan first = plan_for(&c, known * plan_scale[0], rounds, found, window);
    if (first.K > 1 && !(hook && atoll(hook) > 0) && c.ev_cap < par->n / 2 + 4096) {
        cudaFree(c.ev[0]);
        cudaFree(c.ev[1]);
        events_alloc(&c, par->n / 2 + 4096);
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
                "then for step 0's writing %.3f, download and final state %.3f, release %.3f\n", h1 - h0, h2 - h1, h3b - h3,
                h4 - h3b, sim_clock() - h4);
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
