/* cuda_state.cuh: the device's state and grid: the disks' buffers, the speed levels, the time windows, the grid
 * fitted to a step's speed, the event keys.
 * Part of cuda.cu, which includes it after its constants and the files before it (cuda.cu's list). */

/* ==== device state ======================================================================================= */

/* A position (x, y) or a velocity (vx, vy) as one vector: one 16-byte load (8 in float) instead of two. */
#ifdef SIM_FLOAT
typedef float2 real2;
#else
typedef double2 real2;
#endif

/* A disk's position (x, y) and velocity (vx, vy), side by side: a disk read at a scattered slot (the pair
 * search's candidates, a pair's partner, the gather) takes one 32-byte sector in double, where a position and a
 * velocity kept apart took two. Random scene, N = 1e6, on one H200: 4.91e8 -> 5.07e8 particle-steps/s; but the
 * gas of 1e7's search, whose probes' coalesced loads of their own disks now each touch twice the sectors they
 * use, 20.68 -> 21.24 ms over 50 steps: the gas 8.75e9 -> 8.69e9, the dense gas 6.59e9 -> 6.50e9
 * (bench/gpu_h100_variants.log 26c; again at f7e4121, 40a). Apart, a move rewriting each disk in its own slot
 * would write a free disk's position alone, 16 of its 32 bytes; but a pair's two threads must then meet before
 * either disk is written, and that move took more than twice as long (40a, 40b). */
typedef struct {
    real2 pos, vel;
} Disk;

/* One copy of the disks in slot order; id maps a slot to the disk's original index. The collision
 * counts stay in original order outside it (Cuda.pc, Cuda.wc): only the few disks with an event touch
 * them, so they are not carried along when the disks change places. */
typedef struct {
    Disk *d;
    int32_t *id;
} DevState;

/* A pair event: hi = time_key(t) | 1 (kind 1; at time 0, zero_pair_key), lo = (i << 31) | j with i < j
 * original indices; a is i's slot, b is j's. Wall events are kept per disk, hi = time_key(t) (kind 0).
 * Event times are never negative nor -0 (wall_time, pair_time), and the bits of non-negative IEEE numbers,
 * double or float, order like their values: comparing (hi, lo) as integers is event_before. */
typedef struct {
    uint64_t hi, lo;
    int32_t a, b;
} PairEvent;

/* One step's counters, cleared by its gate. */
typedef struct {
    unsigned long long vmax;   /* bits of the largest |vx| or |vy| after the step (>= 0, so ordered) */
    unsigned long long found[WMAX];  /* pair events detected per window (beyond the list's length, the step is
                                        refused) */
    unsigned long long active[WMAX]; /* disks still free at each window's start (the first: all) */
    unsigned long long level[WMAX][LEVELS]; /* levels > 1: of those, the disks of each speed level */
    unsigned long long events; /* accepted events */
    unsigned long long tests;  /* narrow-phase pair tests */
    unsigned long long faster; /* 1: the disks are faster than the plan's speed */
    unsigned long long outside; /* a slab grid's (GridLimits): disks binned outside its rows (never) */
    unsigned long long crowded; /* CROWDED_CELL: a cell of a table of 8-bit counts (count_add) passed 255 keys;
                                   CROWDED_BUCKET: a bucket its room (bucket_fill_kernel). The step is refused,
                                   and the run counts in 32 bits, or cell by cell, from then on */
    unsigned long long ahead[2]; /* 1 in [0]: the step takes the keys the move before it gave; in [1]: it
                                    bins anew, their cells being too fine for its speed */
    unsigned int ties; /* LO_IF_TIED: 1, the search met a disk's smallest first key twice (StepInfo is cleared by
                          the gate, so a window's tie holds for the step's later windows too) */
} StepInfo;
#define CROWDED_CELL 1
#define CROWDED_BUCKET 2

/* What the host reads back once per batch. Steps commit in order, so `steps` also says where a refused
 * step is: steps + 1. A step is refused only when its pair events overflow the list, or a cell its 8-bit
 * count or a bucket its room (StepInfo.crowded). */
typedef struct {
    unsigned long long vmax;     /* bits of the largest |vx| or |vy| of the current state (double) */
    unsigned long long steps;    /* steps committed */
    unsigned long long refused;  /* 1: a step was refused; no step launched after it commits */
    unsigned long long overflow; /* pair events the refused step found, when they overflowed the list */
    unsigned long long crowded;  /* the refused step's StepInfo.crowded */
    unsigned long long faster;   /* steps whose disks were faster than their plan's speed */
    unsigned long long tests, events;             /* sums over committed steps */
    unsigned long long left[MAX_ROUNDS];          /* pair events undecided before each grid-wide round */
    unsigned long long wfound[WMAX], wactive[WMAX]; /* per window: pair events found, disks still free */
    unsigned long long ahead[2];                    /* sums of StepInfo.ahead */
    unsigned long long settling[2]; /* pair events of the steps that settle (SETTLE): found, left to the rounds */
} Control;

/* Binning of one step. */
typedef struct {
    int K;          /* time slices */
    int64_t g;      /* cells per side */
    double cs;      /* cell side, length */
    double inv_cs;  /* 1 / cs */
    uint32_t ncell; /* gx * g */
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
    int sx;         /* K > 1 in the walled box: each cell cut into sx columns (SUB_X), so that a probe's
                       runs reach sx of them to each side, cs wide in all, not a whole cell and the rest of
                       its own; else 1 */
    int64_t gx;     /* cells per row: g sx */
    double inv_csx; /* gx / L (inv_cs where sx = 1) */
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

/* The first slice of the kl-th slice of level l in a window from slice k0 (a multiple of 2^l). */
static __device__ __forceinline__ int64_t level_slice_first(int k0, int l, uint32_t kl)
{
    return (int64_t)(((uint32_t)k0 >> l) + kl) << l;
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
 * against pair tests (about 4.5 n density (2r + vmax/K)^2 per slice), an entry costing less below
 * SLICE_COST_SMALL_N disks and more from SLICE_COST_N up. */
static __host__ __device__ int grid_slices(const GridLimits *lim, double vmax)
{
    double dens = (double)lim->n / (lim->L * lim->L);
    double cost = lim->n >= SLICE_COST_N ? SLICE_COST_BIG : lim->n < SLICE_COST_SMALL_N ? SLICE_COST_SMALL : SLICE_COST;
    double kf = vmax * sqrt(4.5 * dens / cost);
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

/* The columns of lim's x0 and x1 on a grid of g cells a side (inv_cs: g / L), as bin_kernel's cell_of
 * finds them: returns x0's, and into *span how many more to x1's (around the box where periodic). */
static __host__ __device__ int64_t slab_columns(const GridLimits *lim, double inv_cs, int64_t g, int64_t *span)
{
    double a = lim->x0, b = lim->x1, L = lim->L;
    if (lim->periodic) a -= L * floor(a / L), b -= L * floor(b / L);
    int64_t ca = cell_of(a, inv_cs, g);
    *span = cell_of(b, inv_cs, g) - ca;
    if (*span < 0) *span += g; /* periodic: around the box */
    return ca;
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
    int sx = K > 1 && !lim->periodic && !lim->slab ? SUB_X : 1;
    double gmax = floor(sqrt(per_slice / sx));
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
    gr.sx = sx;
    gr.gx = gr.g * sx;
    gr.inv_csx = (double)gr.gx / L;
    gr.ncell = (uint32_t)(gr.gx * gr.g);
    gr.slab = 0, gr.xoff = 0, gr.rows = gr.g;
    if (lim->slab && gr.g >= 4) {
        int64_t span, ca = slab_columns(lim, gr.inv_cs, gr.g, &span);
        if (span + 2 < gr.g) { /* else the whole table, as without a slab */
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

/* Slots in a list shared by the whole grid for k items of each thread of the block, one atomic on the list's
 * count per block: every thread of the block calls it, at the same point; returns the first of this thread's.
 * A grid-wide pass that appends by warps (list_append) puts thousands of atomics a step on the one count, each
 * waiting for the one before it. */
static __device__ __forceinline__ unsigned long long block_append(unsigned long long *count, unsigned k)
{
    __shared__ unsigned taken;
    __shared__ unsigned long long base;
    if (threadIdx.x == 0) taken = 0;
    __syncthreads();
    unsigned at = k ? atomicAdd(&taken, k) : 0;
    __syncthreads();
    if (threadIdx.x == 0 && taken) base = atomicAdd(count, (unsigned long long)taken);
    __syncthreads();
    return base + at;
}

/* This thread's k events e[u] where keep[u], appended to the list out (count, cap) with the block's others at
 * once (block_append): every thread of the block calls it. Past cap an event is counted and not stored. */
template <int ILP>
static __device__ __forceinline__ void block_put(PairEvent *out, unsigned long long *count, int64_t cap,
                                                 const PairEvent (&e)[ILP], const bool (&keep)[ILP], unsigned k)
{
    unsigned long long at = block_append(count, k);
#pragma unroll
    for (int u = 0; u < ILP; u++)
        if (keep[u]) {
            if ((int64_t)at < cap) out[at] = e[u];
            at++;
        }
}

/* As block_put, each event appended by its warp (list_append): for passes whose threads do not all call one
 * point alike (the finish's one block; BLOCK_APPEND 0). */
template <int ILP>
static __device__ __forceinline__ void warp_put(PairEvent *out, unsigned long long *count, int64_t cap,
                                                const PairEvent (&e)[ILP], const bool (&keep)[ILP])
{
#pragma unroll
    for (int u = 0; u < ILP; u++)
        if (keep[u]) {
            unsigned long long at = list_append(count);
            if ((int64_t)at < cap) out[at] = e[u];
        }
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

/* An event's first key (PairEvent.hi) after time 0: the time's bits, which order like its values, above bit 0 (the
 * kind), with bit 63 set (a time in [0, 1] leaves it clear). At time 0, a wall event's key is 0 and a pair
 * event's its second key's bits above the kind (zero_pair_key), so that the first keys alone order the events
 * of time 0 too. Those are common: a disk that collided flies on through others for the rest of its step, and
 * starts the next one overlapping them, where pair_time finds their events at time 0; with one first key for
 * them all, some disk of a gas held two events of its smallest key in nearly every step, and the choice's
 * first round had to compare second keys (LO_IF_TIED; bench/gpu_h100_variants.log 52b, 54). ZERO_KEYS 0: a
 * pair event's first key at time 0 is 1, whatever its disks. */
#define KEY_LATER (1ull << 63)
#ifndef ZERO_KEYS
#define ZERO_KEYS 1
#endif
/* A time's bits, and back (real: float or double) */
#ifdef SIM_FLOAT
static __device__ __forceinline__ uint64_t time_bits(real t)
{
    return (uint64_t)__float_as_uint(t);
}

static __device__ __forceinline__ real bits_time(uint64_t b)
{
    return __uint_as_float((unsigned)b);
}
#else
static __device__ __forceinline__ uint64_t time_bits(real t)
{
    return (uint64_t)__double_as_longlong(t);
}

static __device__ __forceinline__ real bits_time(uint64_t b)
{
    return __longlong_as_double((long long)b);
}
#endif

static __device__ __forceinline__ uint64_t time_key(real t)
{
    return ZERO_KEYS ? (t > 0 ? time_bits(t) << 1 | KEY_LATER : 0) : time_bits(t) << 1;
}

static __device__ __forceinline__ real key_time(uint64_t hi)
{
    return ZERO_KEYS ? (hi & KEY_LATER ? bits_time((hi & ~KEY_LATER) >> 1) : 0) : bits_time(hi >> 1);
}

/* A pair event's first key at time 0 (time_key), from its second (lo < 2^62: two 31-bit indices). */
static __device__ __forceinline__ uint64_t zero_pair_key(uint64_t lo)
{
    return ZERO_KEYS ? lo << 1 | 1 : 1;
}

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
    /* most disks reach no wall within the step: no division (wall_beyond) */
    if (wall_beyond(x, vx, 1, lo, hi) && wall_beyond(y, vy, 1, lo, hi)) return NO_EVENT;
    real tw = min_time(wall_time(x, vx, lo, hi), wall_time(y, vy, lo, hi));
    return tw <= 1 ? time_key(tw) : NO_EVENT;
}

/* The level-l slice of a disk's wall event (its slice of the K >> l slices of level l), or INT64_MAX
 * where it has none by t = 1. A pair event at or after the wall event is never accepted (the wall event
 * comes first in the order of 3.3 and takes the disk, unless something earlier did), so the binning keys
 * the disk out of every later level slice (bin_kernel); slice_of(t) <= slice_of(tw) for t < tw, so that
 * test is exact. */
static __device__ __forceinline__ int64_t wall_level_slice(uint64_t wall, int l, int K)
{
    return wall != NO_EVENT ? slice_of(key_time(wall), K) >> l : INT64_MAX;
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

/* The speed level of item u of a window whose levels' items begin at first[l] (entries: d.base; the
 * binning's chunks, chunk_items): the last level beginning at or before u (a level with none, and those
 * beyond d.levels, begin where the next ones do, and are passed over); where its items begin, its disks
 * (nl) and where its entries begin (base). Constant indices only, or d would go to local memory. */
typedef struct {
    int l;
    uint32_t first;
    int64_t nl, base;
} ItemLevel;

static __device__ __forceinline__ ItemLevel item_level(const WindowDisks &d, const uint32_t *first, uint32_t u)
{
    ItemLevel v = {0, first[0], d.nl[0], 0}; /* d.base[0] is 0 */
#pragma unroll
    for (int m = 1; m < LEVELS; m++)
        if (u >= first[m] && d.nl[m] > 0) v.l = m, v.first = first[m], v.nl = d.nl[m], v.base = d.base[m];
    return v;
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
    const ItemLevel v = item_level(d, d.base, (uint32_t)e);
    const int l = v.l;
    const uint32_t nl = (uint32_t)v.nl, j = (uint32_t)e - v.first, kl = j / nl, i = j - kl * nl;
    x.s = d.lev[(int64_t)l * d.n + i];
    x.l = l;
    x.k = level_slice_first(d.k0, l, kl);
    x.row = level_base(d.k0, d.k0 + d.kw, l) + kl;
    return x;
}
