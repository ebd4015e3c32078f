/* cuda.cu: the CUDA backend.
 *
 * Every phase of a step runs on the device; the host reads back one 32-byte record per step (the new
 * maximum speed, which sizes the next step's grid, and the event-buffer count, which detects an
 * overflow). A step:
 *   bin      each disk's path over the step is cut into K time slices; each slice is binned by its
 *            midpoint into square cells wide enough that any pair SPEC.md 3.2 finds within that slice
 *            lies in neighbouring cells (see grid_choose); a counting sort orders the (slice, cell)
 *            entries: count, exclusive scan, place
 *   gather   with K = 1 the disks themselves move into cell order, for locality; with K > 1 a copy of
 *            each disk per entry does
 *   detect   every pair in the 3x3 neighbouring cells of the same slice (wall events were computed in
 *            gather); a pair is kept only in the slice that holds its event time, so it is found once
 *   choose   rounds of "accept every event that is the smallest remaining one of each of its disks"
 *            (SPEC.md 3.3); the last rounds run in one block
 *   move     each disk from the old buffers into the new ones; the pair physics is computed by both
 *            partners with the lower original index as i, so both see the same arithmetic
 * Event keys compare by value only (t, kind, i, j), so nothing depends on thread order.
 */
#include "common.h"

#include <cub/cub.cuh>
#include <cuda/functional>
#include <cooperative_groups.h>
#include <cuda_runtime.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <atomic>
#include <thread>
#include <vector>

extern "C" const char backend_name[] = "cuda" SIM_SUFFIX;
/* --pressure is for the CPU backends: its per-disk impulse sums would need one more array per slot here */
extern "C" const unsigned backend_features = SIM_FEATURE_SUBSTEPS;
extern "C" const char backend_options[] = "";

#define CUDA_CHECK(call)                                                                             \
    do {                                                                                             \
        cudaError_t err_ = (call);                                                                   \
        if (err_ != cudaSuccess)                                                                     \
            io_fail("%s:%d: %s failed: %s", __FILE__, __LINE__, #call, cudaGetErrorString(err_));   \
    } while (0)
#define CUDA_LAUNCHED() CUDA_CHECK(cudaGetLastError())

#define THREADS 256
#define NO_EVENT UINT64_MAX
#define MAX_SLICES 256            /* time slices per step */
#define ENTRY_MEMORY 0.5          /* share of the device memory left after the state that entries may take */
#define PARALLEL_ROUNDS 2         /* choice rounds run over the whole grid before the one-block finish */
#define SLICE_COST 64.0           /* cost of one entry, in pair tests: sets K (measured best of 4..256) */
#define PHASES 7                  /* phases timed under --stats */
#define CELLS_PER_DISK 2.0        /* cells per slice at most: in a dilute scene a finer grid costs more in
                                     clearing and scanning cells than it saves in pair tests */


/* ==== device state ======================================================================================= */

/* A position (x, y) or a velocity (vx, vy) as one vector: one 16-byte load (8 in float) instead of two. */
#ifdef SIM_FLOAT
typedef float2 real2;
#else
typedef double2 real2;
#endif

/* One copy of the disks in slot order; id maps a slot to the disk's original index. */
typedef struct {
    real2 *pos, *vel; /* (x, y) and (vx, vy) */
    int32_t *pc, *wc, *id;
} DevState;

/* A pair event: hi = (t bits << 1) | 1 (kind 1), lo = (i << 31) | j with i < j original indices;
 * a is i's slot, b is j's. Wall events are kept per disk, hi = t bits << 1 (kind 0). Event times are
 * never negative nor -0 (wall_time, pair_time), and the bits of non-negative IEEE numbers, double or
 * float, order like their values: comparing (hi, lo) as integers is event_before. */
typedef struct {
    uint64_t hi, lo;
    int32_t a, b;
} PairEvent;

/* Read back once per step. */
typedef struct {
    unsigned long long vmax;   /* bits of the largest |vx| or |vy| after the step (>= 0, so ordered) */
    unsigned long long found;  /* pair events detected (may exceed the buffer: then the step reruns) */
    unsigned long long events; /* accepted events */
    unsigned long long tests;  /* narrow-phase pair tests */
} StepInfo;

/* Binning of one step. */
typedef struct {
    int K;          /* time slices */
    int64_t g;      /* cells per side */
    double cs;      /* cell side, length */
    uint32_t ncell; /* g * g */
    int64_t m;      /* entries: n * K */
    int64_t cells;  /* K * ncell; also the key of an entry left out */
} Grid;

/* A slot in a list shared by the whole grid: one atomic per group of threads that append together. */
static __device__ __forceinline__ unsigned long long list_append(unsigned long long *count)
{
    cooperative_groups::coalesced_group g = cooperative_groups::coalesced_threads();
    unsigned long long base = 0;
    if (g.thread_rank() == 0) base = atomicAdd(count, (unsigned long long)g.size());
    return g.shfl(base, 0) + g.thread_rank();
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

/* Cell coordinate of a midpoint coordinate; clamping is a contraction, so neighbours stay neighbours. */
static __device__ __forceinline__ int64_t cell_of(double c, double cs, int64_t g)
{
    double q = floor(c / cs);
    if (!(q >= 0)) q = 0;
    if (q > (double)(g - 1)) q = (double)(g - 1);
    return (int64_t)q;
}

static __device__ __forceinline__ uint64_t wall_key(real x, real y, real vx, real vy, real lo, real hi)
{
    real tw = min_time(wall_time(x, vx, lo, hi), wall_time(y, vy, lo, hi));
    return tw <= 1 ? time_key(tw) : NO_EVENT;
}

/* ==== bin ================================================================================================ */

/* Entry e = k * n + s: slot s in slice k, keyed by the cell of its position at the slice's middle.
 * A pair event at or after a disk's wall event is never accepted (the wall event comes first in the
 * order of 3.3 and takes the disk, unless something earlier did), so slices that start after the
 * disk's wall time get no entry (key gr.cells): disks flying through a wall would otherwise pile up in
 * the border cells. slice_of(t) <= slice_of(tw) for t < tw, so the slice test is exact. Midpoints are
 * computed in double whatever real is: less rounding for the margin to cover. The rank of an entry
 * within its cell comes from an atomic counter: the order inside a cell changes from run to run, which
 * changes where disks sit in memory and nothing else (every decision compares values). */
__global__ void bin_kernel(DevState st, int64_t n, Grid gr, Params par, uint32_t *keys, uint32_t *rank,
                           uint32_t *count)
{
    int64_t e = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (e >= gr.m) return;
    int64_t k = e / n, s = e - k * n;
    real2 pos = st.pos[s], vel = st.vel[s];
    real x = pos.x, y = pos.y, vx = vel.x, vy = vel.y;
    if (k > 0) {
        real tw = min_time(wall_time(x, vx, par.lo, par.hi), wall_time(y, vy, par.lo, par.hi));
        if (tw <= 1 && k > slice_of(tw, gr.K)) {
            keys[e] = (uint32_t)gr.cells;
            return;
        }
    }
    double f = (double)(2 * k + 1) / (double)(2 * gr.K);
    double mx = (double)x + (double)vx * f, my = (double)y + (double)vy * f;
    int64_t cx = cell_of(mx, gr.cs, gr.g), cy = cell_of(my, gr.cs, gr.g);
    uint32_t key = (uint32_t)(k * gr.ncell + cy * gr.g + cx);
    keys[e] = key;
    rank[e] = atomicAdd(&count[key], 1u);
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

/* Where each entry goes in cell order (start[] is the exclusive sum of the counts). Only the 4-byte entry
 * index is scattered; the disks are then gathered with coalesced writes. */
__global__ void place_kernel(int64_t m, int64_t cells, const uint32_t *keys, const uint32_t *rank,
                             const uint32_t *start, uint32_t *keys_sorted, uint32_t *order)
{
    int64_t e = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (e >= m) return;
    uint32_t key = keys[e];
    if (key >= cells) return;
    int64_t p = (int64_t)start[key] + rank[e];
    keys_sorted[p] = key;
    order[p] = (uint32_t)e;
}

/* K = 1: the disks move into cell order (slot p takes the disk of sorted entry p). */
__global__ void gather_state_kernel(DevState in, DevState out, const uint32_t *order, int64_t n, Params par,
                                    uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo, int32_t *partner)
{
    int64_t p = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (p >= n) return;
    uint32_t s = order[p];
    real2 pos = in.pos[s], vel = in.vel[s];
    out.pos[p] = pos;
    out.vel[p] = vel;
    out.pc[p] = in.pc[s];
    out.wc[p] = in.wc[s];
    out.id[p] = in.id[s];
    slot_init(p, wall_key(pos.x, pos.y, vel.x, vel.y, par.lo, par.hi), wall_hi, best_hi, best_lo, partner);
}

/* Copies of the disks, one per entry, in cell order: the pair tests then read neighbours contiguously. */
typedef struct {
    real2 *pos, *vel;
    int32_t *id, *slot;
    uint64_t *wall;
} Entries;

/* K > 1: the disks stay in place; entry p of the cell order gets a copy of its disk. */
__global__ void gather_entries_kernel(DevState st, int64_t n, const uint32_t *order, const uint32_t *start,
                                      int64_t cells, const uint64_t *wall_hi, Entries en)
{
    int64_t p = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (p >= (int64_t)start[cells]) return;
    int64_t s = (int64_t)(order[p] % (uint64_t)n);
    en.pos[p] = st.pos[s];
    en.vel[p] = st.vel[s];
    en.id[p] = st.id[s];
    en.slot[p] = (int32_t)s;
    en.wall[p] = wall_hi[s];
}

__global__ void init_kernel(DevState st, int64_t n, Params par, uint64_t *wall_hi, uint64_t *best_hi,
                            uint64_t *best_lo, int32_t *partner)
{
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (s >= n) return;
    real2 pos = st.pos[s], vel = st.vel[s];
    slot_init(s, wall_key(pos.x, pos.y, vel.x, vel.y, par.lo, par.hi), wall_hi, best_hi, best_lo, partner);
}

/* ==== detect ============================================================================================= */

/* Sorted entry p tests every later entry q > p of the same slice in the 3x3 cells around its own. Cell
 * order is row by row, so the row above lies wholly before p: what is left is the rest of p's own row
 * (from p + 1 to the end of the cell to its right) and the three cells of the row below, two contiguous
 * runs of entries, walked as one loop. en.slot == NULL means entry == slot (K = 1). Entry and cell
 * indices fit in 32 bits (entry_cap, cell_cap). */
__global__ void detect_kernel(Entries en, const uint32_t *__restrict__ keys, const uint32_t *__restrict__ start,
                              Grid gr, real sigma2, PairEvent *ev, int64_t cap, StepInfo *info,
                              uint64_t *best_hi)
{
    uint32_t p = blockIdx.x * blockDim.x + threadIdx.x;
    unsigned long long tests = 0;
    if (p < __ldg(&start[gr.cells])) {
        uint32_t key = __ldg(&keys[p]), g = (uint32_t)gr.g;
        uint32_t k = key / gr.ncell, c = key - k * gr.ncell;
        uint32_t cy = c / g, cx = c - cy * g;
        uint32_t x0 = cx > 0 ? cx - 1 : 0, x1 = cx + 1 < g ? cx + 1 : g - 1;
        uint32_t row = k * gr.ncell + cy * g;
        uint32_t a0 = p + 1, na = __ldg(&start[row + x1 + 1]) - a0;
        uint32_t b0 = 0, nb = 0;
        if (cy + 1 < g) {
            b0 = __ldg(&start[row + g + x0]);
            nb = __ldg(&start[row + g + x1 + 1]) - b0;
        }
        real2 pos = __ldg(&en.pos[p]), vel = __ldg(&en.vel[p]);
        int32_t id = __ldg(&en.id[p]);
        uint64_t wall = __ldg(&en.wall[p]);
        for (uint32_t i = 0; i < na + nb; i++) {
            uint32_t q = i < na ? a0 + i : b0 + (i - na);
            real2 pos2 = __ldg(&en.pos[q]), vel2 = __ldg(&en.vel[q]);
            int32_t id2 = __ldg(&en.id[q]);
            tests++;
            /* the arguments are chosen first, so the warp runs one pair_time, not two branches */
            bool first = id < id2;
            real2 pi = first ? pos : pos2, vi = first ? vel : vel2;
            real2 pj = first ? pos2 : pos, vj = first ? vel2 : vel;
            real t = pair_time(pi.x, pi.y, vi.x, vi.y, pj.x, pj.y, vj.x, vj.y, sigma2);
            if (t < 0) continue;
            if (gr.K > 1 && slice_of(t, gr.K) != (int64_t)k) continue;
            PairEvent e;
            e.hi = time_key(t) | 1;
            if (!(e.hi < wall && e.hi < __ldg(&en.wall[q]))) continue; /* a wall event comes first */
            int32_t s = en.slot ? en.slot[p] : (int32_t)p, s2 = en.slot ? en.slot[q] : (int32_t)q;
            e.a = first ? s : s2;
            e.b = first ? s2 : s;
            e.lo = first ? ((uint64_t)id << 31 | (uint64_t)id2) : ((uint64_t)id2 << 31 | (uint64_t)id);
            unsigned long long at = list_append(&info->found);
            if ((int64_t)at < cap) ev[at] = e;
            atomicMin((unsigned long long *)&best_hi[e.a], (unsigned long long)e.hi);
            atomicMin((unsigned long long *)&best_hi[e.b], (unsigned long long)e.hi);
        }
    }
    typedef cub::BlockReduce<unsigned long long, THREADS> Reduce;
    __shared__ typename Reduce::TempStorage tmp;
    unsigned long long sum = Reduce(tmp).Sum(tests);
    if (threadIdx.x == 0 && sum) atomicAdd(&info->tests, sum);
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
                                                    unsigned long long *count_out, const int32_t *partner,
                                                    const uint64_t *wall_hi, uint64_t *best_hi,
                                                    uint64_t *best_lo)
{
    PairEvent e = ev[i];
    if (partner[e.a] >= 0 || partner[e.b] >= 0) return;
    out[list_append(count_out)] = e;
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

#define GRID_LOOP(i, len) \
    for (int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x; i < (len); i += (int64_t)gridDim.x * blockDim.x)

__global__ void min_lo_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              const uint64_t *best_hi, uint64_t *best_lo)
{
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_min_lo(ev, i, best_hi, best_lo);
}

__global__ void min_hi_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              uint64_t *best_hi)
{
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_min_hi(ev, i, best_hi);
}

__global__ void accept_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              const uint64_t *best_hi, const uint64_t *best_lo, int32_t *partner)
{
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_accept(ev, i, best_hi, best_lo, partner);
}

__global__ void compact_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                               PairEvent *out, unsigned long long *count_out, const int32_t *partner,
                               const uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo)
{
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_compact(ev, i, out, count_out, partner, wall_hi, best_hi, best_lo);
}

/* The remaining rounds in one block, until no pair event is left. */
__global__ void finish_kernel(PairEvent *ev0, PairEvent *ev1, const unsigned long long *count, int64_t cap,
                              int32_t *partner, const uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo)
{
    __shared__ unsigned long long n_out;
    PairEvent *in = ev0, *out = ev1;
    int64_t len = list_len(count, cap);
    for (;;) {
        if (threadIdx.x == 0) n_out = 0;
        __syncthreads();
        for (int64_t i = threadIdx.x; i < len; i += blockDim.x)
            pass_compact(in, i, out, &n_out, partner, wall_hi, best_hi, best_lo);
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

/* Old buffers in, new buffers out. A disk with no accepted pair and a wall event within the step has
 * had that wall event accepted: no remaining pair event of it was smaller. */
__global__ void move_kernel(DevState in, DevState out, int64_t n, Params par, const int32_t *partner,
                            const uint64_t *wall_hi, const uint64_t *best_hi, StepInfo *info)
{
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    real vabs = 0;
    unsigned long long accepted = 0;
    if (s < n) {
        real lo = par.lo, hi = par.hi;
        real2 pos = in.pos[s], vel = in.vel[s];
        real x = pos.x, y = pos.y, vx = vel.x, vy = vel.y;
        int32_t pc = in.pc[s], wc = in.wc[s], id = in.id[s];
        int32_t o = partner[s];
        if (o < 0 && wall_hi[s] != NO_EVENT) o = (int32_t)s;
        if (o < 0) {
            x = x + vx;
            y = y + vy;
        } else if (o == s) {
            real t1 = key_time(wall_hi[s]);
            wall_bounce(&x, &y, &vx, &vy, t1, lo, hi);
            finish_step(&x, &y, vx, vy, t1, lo, hi);
            wc++;
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
            pair_contact(&xi, &yi, &vxi, &vyi, &xj, &yj, &vxj, &vyj, t1);
            x = mine_first ? xi : xj, y = mine_first ? yi : yj;
            vx = mine_first ? vxi : vxj, vy = mine_first ? vyi : vyj;
            finish_step(&x, &y, vx, vy, t1, lo, hi);
            pc++;
            accepted = mine_first;
        }
        real2 pos1, vel1;
        pos1.x = clamp_coord(x, lo, hi);
        pos1.y = clamp_coord(y, lo, hi);
        vel1.x = vx;
        vel1.y = vy;
        out.pos[s] = pos1;
        out.vel[s] = vel1;
        out.pc[s] = pc;
        out.wc[s] = wc;
        out.id[s] = id;
        real ax = SIM_FABS(vx), ay = SIM_FABS(vy);
        vabs = ax < ay ? ay : ax;
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
__global__ void unpermute_kernel(DevState st, int64_t n, real *x, real *y, real *vx, real *vy)
{
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (s >= n) return;
    int32_t i = st.id[s];
    real2 pos = st.pos[s], vel = st.vel[s];
    x[i] = pos.x;
    y[i] = pos.y;
    vx[i] = vel.x;
    vy[i] = vel.y;
}

/* ==== host side ========================================================================================== */

typedef struct {
    int64_t n;
    Params par;
    DevState st[2];      /* old and new state; cur says which holds the current one */
    int cur;
    uint32_t *keys, *rank;               /* per entry: cell key, rank within the cell */
    uint32_t *keys_sorted, *order;       /* per place in cell order: key, entry */
    uint32_t *count, *start;             /* per cell (+1): entries, and where they begin in cell order */
    void *scan_tmp;
    size_t scan_tmp_bytes;
    Entries en;                          /* K > 1 only */
    int64_t cell_cap;    /* cells (slices x g^2) count and start hold */
    int64_t entry_cap;   /* entries the key arrays hold */
    int max_slices;      /* K never exceeds this: entry_cap / n, capped */
    uint64_t *wall_hi, *best_hi, *best_lo;
    int32_t *partner;
    PairEvent *ev[2];
    int64_t ev_cap;
    unsigned long long *counts; /* list lengths of the parallel rounds */
    StepInfo *info, *info_host; /* device record and its pinned copy */
    real *out_dev;       /* print mode: 4n reals in original order */
    real *out_host;      /* its pinned copy */
    cudaEvent_t copied;  /* the copy into out_host is complete */
    cudaStream_t stream;
    int sms;
    int timed;                        /* --stats: time each phase with device events */
    cudaEvent_t mark[PHASES + 1];
    double phase_ms[PHASES];
    unsigned long long *counts_host;  /* pinned copy of counts, for --stats */
    unsigned long long left[PARALLEL_ROUNDS]; /* pair events still undecided before each round */
} Cuda;

static const char *const phase_names[PHASES] = {"bin", "scan", "gather", "detect", "rounds", "finish", "move"};

static void phase_mark(Cuda *c, int phase)
{
    if (c->timed) CUDA_CHECK(cudaEventRecord(c->mark[phase], c->stream));
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
        io_fail("not enough GPU memory for %s: %.1f MiB wanted, %.1f MiB free of %.1f MiB (%s)", what,
                bytes / 1048576.0, free_b / 1048576.0, total_b / 1048576.0, cudaGetErrorString(err));
    }
    return p;
}

static void state_alloc(DevState *d, int64_t n)
{
    size_t nd = (size_t)n * sizeof(real), ni = (size_t)n * sizeof(int32_t);
    d->pos = (real2 *)dev_alloc(2 * nd, "the state");
    d->vel = (real2 *)dev_alloc(2 * nd, "the state");
    d->pc = (int32_t *)dev_alloc(ni, "the state");
    d->wc = (int32_t *)dev_alloc(ni, "the state");
    d->id = (int32_t *)dev_alloc(ni, "the state");
}

static void state_free(DevState *d)
{
    cudaFree(d->pos);
    cudaFree(d->vel);
    cudaFree(d->pc);
    cudaFree(d->wc);
    cudaFree(d->id);
}

static void events_alloc(Cuda *c, int64_t cap)
{
    c->ev_cap = cap;
    c->ev[0] = (PairEvent *)dev_alloc((size_t)cap * sizeof(PairEvent), "the event list");
    c->ev[1] = (PairEvent *)dev_alloc((size_t)cap * sizeof(PairEvent), "the event list");
}

static void cuda_open(Cuda *c, const Sim *sim, const Params *par, int timed)
{
    int devices = 0;
    cudaError_t err = cudaGetDeviceCount(&devices);
    if (err != cudaSuccess || devices == 0)
        io_fail("no CUDA GPU available (%s)", err != cudaSuccess ? cudaGetErrorString(err) : "no device");
    memset(c, 0, sizeof *c);
    int64_t n = par->n;
    c->n = n;
    c->par = *par;
    CUDA_CHECK(cudaDeviceGetAttribute(&c->sms, cudaDevAttrMultiProcessorCount, 0));
    CUDA_CHECK(cudaStreamCreateWithFlags(&c->stream, cudaStreamNonBlocking));
    c->timed = timed;
    if (timed) {
        for (int k = 0; k <= PHASES; k++) CUDA_CHECK(cudaEventCreate(&c->mark[k]));
        CUDA_CHECK(cudaMallocHost((void **)&c->counts_host, PARALLEL_ROUNDS * sizeof(unsigned long long)));
    }

    state_alloc(&c->st[0], n);
    state_alloc(&c->st[1], n);
    c->wall_hi = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->best_hi = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->best_lo = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->partner = (int32_t *)dev_alloc((size_t)n * 4, "the event keys");
    events_alloc(c, n / 2 + 4096);
    c->counts = (unsigned long long *)dev_alloc((PARALLEL_ROUNDS + 1) * sizeof(unsigned long long), "counters");
    c->info = (StepInfo *)dev_alloc(sizeof(StepInfo), "counters");
    CUDA_CHECK(cudaMallocHost((void **)&c->info_host, sizeof(StepInfo)));
    /* Entries take up to ENTRY_MEMORY of what is left, at most MAX_SLICES per disk: per entry, four
     * 4-byte keys, three cells of count and start, and (K > 1) a copy of the disk. More entries allow
     * more slices, hence fewer pair tests, in fast scenes of millions of disks. Entry and cell indices
     * stay below 2^31. */
    size_t free_b = 0, total_b = 0;
    CUDA_CHECK(cudaMemGetInfo(&free_b, &total_b));
    double entry_bytes = 16 + 3 * 8 + 2 * sizeof(real2) + 16;
    double afford = ENTRY_MEMORY * (double)free_b / entry_bytes;
    int64_t cap = n * MAX_SLICES;
    if ((double)cap > afford) cap = (int64_t)afford;
    if (cap > INT32_MAX) cap = INT32_MAX;
    c->max_slices = cap / n >= 1 ? (int)(cap / n) : 1;
    c->entry_cap = n * c->max_slices;
    c->cell_cap = 3 * c->entry_cap > (1LL << 22) ? 3 * c->entry_cap : (1LL << 22);
    if (c->cell_cap > INT32_MAX - 1) c->cell_cap = INT32_MAX - 1;
    size_t ne = (size_t)c->entry_cap;
    c->keys = (uint32_t *)dev_alloc(ne * 4, "the cell keys");
    c->rank = (uint32_t *)dev_alloc(ne * 4, "the cell keys");
    c->keys_sorted = (uint32_t *)dev_alloc(ne * 4, "the cell keys");
    c->order = (uint32_t *)dev_alloc(ne * 4, "the cell keys");
    size_t nc = (size_t)c->cell_cap + 1;
    c->count = (uint32_t *)dev_alloc(nc * 4, "the cell table");
    c->start = (uint32_t *)dev_alloc(nc * 4, "the cell table");
    CUDA_CHECK(cub::DeviceScan::ExclusiveSum(NULL, c->scan_tmp_bytes, c->count, c->start, (int64_t)nc, c->stream));
    c->scan_tmp = dev_alloc(c->scan_tmp_bytes, "the cell table");
    if (c->max_slices > 1) {
        c->en.pos = (real2 *)dev_alloc(ne * sizeof(real2), "the entry copies");
        c->en.vel = (real2 *)dev_alloc(ne * sizeof(real2), "the entry copies");
        c->en.id = (int32_t *)dev_alloc(ne * 4, "the entry copies");
        c->en.slot = (int32_t *)dev_alloc(ne * 4, "the entry copies");
        c->en.wall = (uint64_t *)dev_alloc(ne * 8, "the entry copies");
    }
    if (par->print && par->steps > 1) {
        c->out_dev = (real *)dev_alloc((size_t)n * 4 * sizeof(real), "the print buffer");
        CUDA_CHECK(cudaMallocHost((void **)&c->out_host, (size_t)n * 4 * sizeof(real)));
        CUDA_CHECK(cudaEventCreateWithFlags(&c->copied, cudaEventDisableTiming));
    }

    DevState *d = &c->st[0];
    size_t nd = (size_t)n * sizeof(real), ni = (size_t)n * sizeof(int32_t);
    real2 *pos = (real2 *)io_alloc((size_t)n, sizeof *pos), *vel = (real2 *)io_alloc((size_t)n, sizeof *vel);
    for (int64_t i = 0; i < n; i++) {
        pos[i].x = sim->x[i];
        pos[i].y = sim->y[i];
        vel[i].x = sim->vx[i];
        vel[i].y = sim->vy[i];
    }
    CUDA_CHECK(cudaMemcpy(d->pos, pos, 2 * nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(d->vel, vel, 2 * nd, cudaMemcpyHostToDevice));
    free(pos);
    free(vel);
    CUDA_CHECK(cudaMemcpy(d->pc, sim->pc, ni, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(d->wc, sim->wc, ni, cudaMemcpyHostToDevice));
    int32_t *ids = (int32_t *)io_alloc((size_t)n, sizeof *ids);
    for (int64_t i = 0; i < n; i++) ids[i] = (int32_t)i;
    CUDA_CHECK(cudaMemcpy(d->id, ids, ni, cudaMemcpyHostToDevice));
    free(ids);
    c->cur = 0;
}

static void cuda_close(Cuda *c)
{
    state_free(&c->st[0]);
    state_free(&c->st[1]);
    cudaFree(c->keys);
    cudaFree(c->rank);
    cudaFree(c->keys_sorted);
    cudaFree(c->order);
    cudaFree(c->count);
    cudaFree(c->start);
    cudaFree(c->scan_tmp);
    cudaFree(c->en.pos);
    cudaFree(c->en.vel);
    cudaFree(c->en.id);
    cudaFree(c->en.slot);
    cudaFree(c->en.wall);
    cudaFree(c->wall_hi);
    cudaFree(c->best_hi);
    cudaFree(c->best_lo);
    cudaFree(c->partner);
    cudaFree(c->ev[0]);
    cudaFree(c->ev[1]);
    cudaFree(c->counts);
    cudaFree(c->info);
    cudaFreeHost(c->info_host);
    cudaFree(c->out_dev);
    if (c->out_host) cudaEventDestroy(c->copied);
    cudaFreeHost(c->out_host);
    if (c->timed) {
        for (int k = 0; k <= PHASES; k++) cudaEventDestroy(c->mark[k]);
        cudaFreeHost(c->counts_host);
    }
    cudaStreamDestroy(c->stream);
}

/* After a step that counted: adds its phase times and its undecided events per round. */
static void phase_collect(Cuda *c, unsigned long long found)
{
    for (int k = 0; k < PHASES; k++) {
        float ms = 0;
        CUDA_CHECK(cudaEventElapsedTime(&ms, c->mark[k], c->mark[k + 1]));
        c->phase_ms[k] += ms;
    }
    c->left[0] += found;
    for (int r = 1; r < PARALLEL_ROUNDS; r++) c->left[r] += c->counts_host[r];
}

static void phase_report(const Cuda *c)
{
    fprintf(stderr, "cuda: device time per phase (ms):");
    for (int k = 0; k < PHASES; k++) fprintf(stderr, " %s %.3f", phase_names[k], c->phase_ms[k]);
    fprintf(stderr, "\ncuda: pair events undecided before each grid-wide round:");
    for (int r = 0; r < PARALLEL_ROUNDS; r++) fprintf(stderr, " %llu", c->left[r]);
    fprintf(stderr, "\n");
}

/* The binning of a step whose largest velocity component is vmax. A pair with an event at t in slice
 * k is, at t, at most 2r apart per axis (plus rounding, covered by the margin), and each midpoint of
 * slice k is within |v| / (2K) of the disk at t, so midpoints are at most 2r + vmax / K + margin apart:
 * with cells at least that wide the pair is in neighbouring cells. The margin is omp's: the rounding of
 * positions and times (SIM_REL_MARGIN of the coordinates' scale), and pair_time near a graze, where D > 0
 * can hold while the exact paths miss contact by up to about eps dd / r, with dd <= reach^2 for a
 * pair with an event. K trades binning work (n K entries)
 * against pair tests (about 4.5 n density (2r + vmax/K)^2 per slice). */
static Grid grid_choose(const Cuda *c, double vmax)
{
    const Params *p = &c->par;
    double n = (double)c->n, L = p->L, r = p->r;
    double dens = n / (L * L);
    double kf = vmax * sqrt(4.5 * dens / SLICE_COST);
    Grid gr;
    gr.K = kf >= 1 ? (kf < c->max_slices ? (int)(kf + 0.5) : c->max_slices) : 1;
    if (gr.K < 1) gr.K = 1;
    double scale = L + 2 * vmax, reach = 6 * vmax + 2 * r;
    double margin = broad_margin(r, scale, reach, SIM_REL_MARGIN);
    double cell_min = (2 * r + 2 * margin + vmax / gr.K) * (1 + SIM_REL_MARGIN) + SIM_REL_MARGIN * scale;
    double per_slice = (double)c->cell_cap / gr.K;
    if (per_slice > CELLS_PER_DISK * n + 1024) per_slice = CELLS_PER_DISK * n + 1024;
    double gmax = floor(sqrt(per_slice));
    double gf = floor(L / cell_min);
    if (gf > gmax) gf = gmax;
    if (!(gf >= 1)) gf = 1;
    gr.g = (int64_t)gf;
    gr.cs = L / (double)gr.g;
    gr.ncell = (uint32_t)(gr.g * gr.g);
    gr.m = c->n * gr.K;
    gr.cells = (int64_t)gr.K * gr.ncell;
    return gr;
}

/* Launches one step from state st[in]; the new state goes to the other buffer. Returns that index. */
static int step_launch(Cuda *c, const Grid *gr)
{
    cudaStream_t s = c->stream;
    int64_t n = c->n;
    int in = c->cur;
    CUDA_CHECK(cudaMemsetAsync(c->info, 0, sizeof(StepInfo), s));
    CUDA_CHECK(cudaMemsetAsync(c->counts, 0, (PARALLEL_ROUNDS + 1) * sizeof(unsigned long long), s));

    phase_mark(c, 0);
    CUDA_CHECK(cudaMemsetAsync(c->count, 0, ((size_t)gr->cells + 1) * sizeof(uint32_t), s));
    bin_kernel<<<blocks_for(gr->m), THREADS, 0, s>>>(c->st[in], n, *gr, c->par, c->keys, c->rank, c->count);
    CUDA_LAUNCHED();
    phase_mark(c, 1);
    size_t tmp = c->scan_tmp_bytes;
    CUDA_CHECK(cub::DeviceScan::ExclusiveSum(c->scan_tmp, tmp, c->count, c->start, gr->cells + 1, s));
    phase_mark(c, 2);
    Entries en;
    place_kernel<<<blocks_for(gr->m), THREADS, 0, s>>>(gr->m, gr->cells, c->keys, c->rank, c->start,
                                                       c->keys_sorted, c->order);
    CUDA_LAUNCHED();
    if (gr->K == 1) {
        gather_state_kernel<<<blocks_for(n), THREADS, 0, s>>>(c->st[in], c->st[1 - in], c->order, n, c->par,
                                                              c->wall_hi, c->best_hi, c->best_lo, c->partner);
        CUDA_LAUNCHED();
        in = 1 - in;
        DevState *d = &c->st[in];
        en.pos = d->pos, en.vel = d->vel, en.id = d->id;
        en.slot = NULL;
        en.wall = c->wall_hi;
    } else {
        init_kernel<<<blocks_for(n), THREADS, 0, s>>>(c->st[in], n, c->par, c->wall_hi, c->best_hi,
                                                      c->best_lo, c->partner);
        CUDA_LAUNCHED();
        gather_entries_kernel<<<blocks_for(gr->m), THREADS, 0, s>>>(c->st[in], n, c->order, c->start, gr->cells,
                                                                    c->wall_hi, c->en);
        CUDA_LAUNCHED();
        en = c->en;
    }
    phase_mark(c, 3);
    detect_kernel<<<blocks_for(gr->m), THREADS, 0, s>>>(en, c->keys_sorted, c->start, *gr, c->par.sigma2,
                                                        c->ev[0], c->ev_cap, c->info, c->best_hi);
    CUDA_LAUNCHED();

    phase_mark(c, 4);
    int64_t grid = blocks_for(c->ev_cap);
    if (grid > 8LL * c->sms) grid = 8LL * c->sms;
    const unsigned long long *found = &c->info->found;
    min_lo_kernel<<<grid, THREADS, 0, s>>>(c->ev[0], found, c->ev_cap, c->best_hi, c->best_lo);
    CUDA_LAUNCHED();
    accept_kernel<<<grid, THREADS, 0, s>>>(c->ev[0], found, c->ev_cap, c->best_hi, c->best_lo, c->partner);
    CUDA_LAUNCHED();
    int list = 0;
    const unsigned long long *len = found;
    for (int r = 1; r < PARALLEL_ROUNDS; r++) {
        compact_kernel<<<grid, THREADS, 0, s>>>(c->ev[list], len, c->ev_cap, c->ev[1 - list], &c->counts[r],
                                                c->partner, c->wall_hi, c->best_hi, c->best_lo);
        CUDA_LAUNCHED();
        list = 1 - list;
        len = &c->counts[r];
        min_hi_kernel<<<grid, THREADS, 0, s>>>(c->ev[list], len, c->ev_cap, c->best_hi);
        CUDA_LAUNCHED();
        min_lo_kernel<<<grid, THREADS, 0, s>>>(c->ev[list], len, c->ev_cap, c->best_hi, c->best_lo);
        CUDA_LAUNCHED();
        accept_kernel<<<grid, THREADS, 0, s>>>(c->ev[list], len, c->ev_cap, c->best_hi, c->best_lo, c->partner);
        CUDA_LAUNCHED();
    }
    phase_mark(c, 5);
    finish_kernel<<<1, 1024, 0, s>>>(c->ev[list], c->ev[1 - list], len, c->ev_cap, c->partner,
                                     c->wall_hi, c->best_hi, c->best_lo);
    CUDA_LAUNCHED();

    phase_mark(c, 6);
    move_kernel<<<blocks_for(n), THREADS, 0, s>>>(c->st[in], c->st[1 - in], n, c->par, c->partner, c->wall_hi,
                                                  c->best_hi, c->info);
    CUDA_LAUNCHED();
    phase_mark(c, 7);
    CUDA_CHECK(cudaMemcpyAsync(c->info_host, c->info, sizeof(StepInfo), cudaMemcpyDeviceToHost, s));
    if (c->timed)
        CUDA_CHECK(cudaMemcpyAsync(c->counts_host, c->counts, PARALLEL_ROUNDS * sizeof(unsigned long long),
                                   cudaMemcpyDeviceToHost, s));
    c->cur = in; /* the state this step started from, in slot order; step_finish moves on */
    return 1 - in;
}

static double host_vmax(const Sim *sim, int64_t n)
{
    double m = 0;
    for (int64_t i = 0; i < n; i++) {
        m = fmax(m, fabs((double)sim->vx[i]));
        m = fmax(m, fabs((double)sim->vy[i]));
    }
    return m;
}

/* Formats lines [0, n) of a state with up to 16 host threads, each a contiguous part into its own
 * buffer, and writes the parts in order. */
static void format_state(Output *out, int64_t step, const Sim *view, int64_t n, int with_counts)
{
    int dump17 = io_dump17(out);
    unsigned hw = std::thread::hardware_concurrency();
    int64_t parts = hw > 1 ? (int64_t)hw : 1;
    if (parts > 16) parts = 16;
    if (n < 65536) parts = 1;
    if (parts == 1) {
        io_write_state(out, step, view, 0, n, with_counts);
        return;
    }
    std::vector<std::vector<char>> text((size_t)parts);
    std::vector<std::thread> workers;
    for (int64_t t = 0; t < parts; t++) {
        workers.emplace_back([&, t]() {
            int64_t from = n * t / parts, to = n * (t + 1) / parts;
            std::vector<char> &buf = text[(size_t)t];
            buf.resize((size_t)(to - from) * 64 + IO_LINE_MAX);
            size_t len = 0;
            for (int64_t i = from; i < to; i++) {
                if (len + IO_LINE_MAX > buf.size()) buf.resize(buf.size() * 2);
                len += io_format_line(buf.data() + len, step, i, view, with_counts, dump17);
            }
            buf.resize(len);
        });
    }
    for (auto &w : workers) w.join();
    for (auto &b : text) io_write_bytes(out, b.data(), b.size());
}

/* Step 0 and the final state, on host threads. */
extern "C" void backend_write_state(Output *out, int64_t step, const Sim *sim, int64_t n, int with_counts)
{
    format_state(out, step, sim, n, with_counts);
}

/* The tasks are taken in turn from a shared counter by up to 16 host threads. */
extern "C" void backend_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    unsigned hw = std::thread::hardware_concurrency();
    int64_t nt = threads > 0 ? threads : hw > 1 ? (int64_t)hw : 1;
    if (nt > 16 && threads <= 0) nt = 16;
    if (nt > tasks) nt = tasks;
    if (nt <= 1) {
        for (int64_t k = 0; k < tasks; k++) task(ctx, k);
        return;
    }
    std::atomic<int64_t> next(0);
    std::vector<std::thread> workers;
    for (int64_t t = 0; t < nt; t++)
        workers.emplace_back([&]() {
            for (int64_t k; (k = next++) < tasks;) task(ctx, k);
        });
    for (auto &w : workers) w.join();
}

/* Formats one printed state (original order, in out_host) while the device runs the next step. */
static void print_state(Cuda *c, Output *out, int64_t step)
{
    int64_t n = c->n;
    CUDA_CHECK(cudaEventSynchronize(c->copied));
    Sim view;
    memset(&view, 0, sizeof view);
    view.x = c->out_host;
    view.y = c->out_host + n;
    view.vx = c->out_host + 2 * n;
    view.vy = c->out_host + 3 * n;
    format_state(out, step, &view, n, 0);
}

static void print_enqueue(Cuda *c)
{
    int64_t n = c->n;
    real *d = c->out_dev;
    unpermute_kernel<<<blocks_for(n), THREADS, 0, c->stream>>>(c->st[c->cur], n, d, d + n, d + 2 * n, d + 3 * n);
    CUDA_LAUNCHED();
    CUDA_CHECK(cudaMemcpyAsync(c->out_host, d, (size_t)n * 4 * sizeof(real), cudaMemcpyDeviceToHost,
                               c->stream));
    CUDA_CHECK(cudaEventRecord(c->copied, c->stream));
}

static void state_download(Cuda *c, Sim *sim)
{
    int64_t n = c->n;
    DevState *d = &c->st[c->cur];
    size_t nd = (size_t)n * sizeof(real), ni = (size_t)n * sizeof(int32_t);
    real2 *pos = (real2 *)io_alloc((size_t)n, sizeof *pos), *vel = (real2 *)io_alloc((size_t)n, sizeof *vel);
    int32_t *pc = (int32_t *)io_alloc((size_t)n, sizeof *pc), *wc = (int32_t *)io_alloc((size_t)n, sizeof *wc);
    int32_t *ids = (int32_t *)io_alloc((size_t)n, sizeof *ids);
    CUDA_CHECK(cudaMemcpy(pos, d->pos, 2 * nd, cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaMemcpy(vel, d->vel, 2 * nd, cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaMemcpy(pc, d->pc, ni, cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaMemcpy(wc, d->wc, ni, cudaMemcpyDeviceToHost));
    CUDA_CHECK(cudaMemcpy(ids, d->id, ni, cudaMemcpyDeviceToHost));
    for (int64_t s = 0; s < n; s++) {
        int32_t i = ids[s];
        sim->x[i] = pos[s].x;
        sim->y[i] = pos[s].y;
        sim->vx[i] = vel[s].x;
        sim->vy[i] = vel[s].y;
        sim->pc[i] = pc[s];
        sim->wc[i] = wc[s];
    }
    free(pos);
    free(vel);
    free(pc);
    free(wc);
    free(ids);
}

int backend_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *stats)
{
    if (par->steps == 0) return 0;
    if (par->n > INT32_MAX / 2) io_fail("at most %d disks on the GPU", INT32_MAX / 2);
    Cuda c;
    cuda_open(&c, sim, par, opt->stats);
    double vmax = host_vmax(sim, par->n);
    int64_t printing = 0; /* step whose state is on its way to out_host, or 0 */
    CUDA_CHECK(cudaDeviceSynchronize());
    double t0 = io_now();
    /* --substeps K: every sub-step is a SPEC.md step; states are handed out after whole steps */
    int64_t k = par->substeps, last = par->steps * k;
    for (int64_t sub = 1; sub <= last; sub++) {
        for (;;) {
            Grid gr = grid_choose(&c, vmax);
            int next = step_launch(&c, &gr);
            if (printing) {
                print_state(&c, out, printing);
                printing = 0;
            }
            CUDA_CHECK(cudaStreamSynchronize(c.stream));
            StepInfo *info = c.info_host;
            if ((int64_t)info->found > c.ev_cap) {
                int64_t cap = (int64_t)info->found + info->found / 2;
                cudaFree(c.ev[0]);
                cudaFree(c.ev[1]);
                events_alloc(&c, cap);
                continue; /* rerun the step from the untouched old buffers */
            }
            c.cur = next;
            if (c.timed) phase_collect(&c, info->found);
            stats->pair_tests += info->tests;
            stats->events += info->events;
            unsigned long long bits = info->vmax;
            memcpy(&vmax, &bits, sizeof vmax);
            break;
        }
        if (sub % k) continue;
        if (par->print && sub < last) {
            print_enqueue(&c);
            printing = sub / k;
        }
        io_progress(out, sub / k);
    }
    if (printing) {
        CUDA_CHECK(cudaStreamSynchronize(c.stream));
        print_state(&c, out, printing);
    }
    CUDA_CHECK(cudaStreamSynchronize(c.stream));
    stats->seconds = io_now() - t0;
    state_download(&c, sim);
    if (c.timed) phase_report(&c);
    cuda_close(&c);
    return 0;
}

int main(int argc, char **argv)
{
    return io_main(argc, argv);
}
