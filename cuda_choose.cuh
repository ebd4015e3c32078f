/* cuda_choose.cuh: the choice: rounds of accepting every event that is the smallest live one of both its disks.
 * Part of cuda.cu, which includes it after its constants and the files before it (cuda.cu's list). */

/* ==== choose ============================================================================================= */
/* best_hi/best_lo of a disk: the smallest key among its remaining events (its wall event and the pair
 * events in the current list). partner: negative none yet (-1, or PARTNER_WALL where it has a wall event
 * within the step, slot_init), itself for an accepted wall event, else the other slot of its accepted pair.
 * Each phase below is one pass over a list; the grid versions are separate kernels, the one-block version
 * separates them with __syncthreads. */

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

/* Event e's decision, its disks' best keys loaded (ha, hb; la, lb where both are e's time). Every write
 * here stores a value that any other writer of the same place would store too. */
static __device__ __forceinline__ void accept_event(const PairEvent &e, uint64_t ha, uint64_t hb, uint64_t la,
                                                    uint64_t lb, int32_t *partner)
{
    if (ha == e.hi && hb == e.hi && la == e.lo && lb == e.lo) {
        partner[e.a] = e.b;
        partner[e.b] = e.a;
        return;
    }
    if (!(ha & 1)) partner[e.a] = e.a; /* the wall event is the smallest: accepted */
    if (!(hb & 1)) partner[e.b] = e.b;
}

static __device__ __forceinline__ void pass_accept(const PairEvent *ev, int64_t i, const uint64_t *best_hi,
                                                   const uint64_t *best_lo, int32_t *partner)
{
    PairEvent e = ev[i];
    uint64_t ha = best_hi[e.a], hb = best_hi[e.b], la = NO_EVENT, lb = NO_EVENT;
    if (ha == e.hi && hb == e.hi) la = best_lo[e.a], lb = best_lo[e.b];
    accept_event(e, ha, hb, la, lb, partner);
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

/* The grid-wide passes but min_hi's (rounds after the first, on few events) take CHOOSE_ILP events a
 * thread a turn, and issue each of their loads for all of them before waiting on any: taken one after
 * another, each event waited on its own chain of loads, the list's and then its disks' keys, scattered
 * as the disks with events are. On one H200 the rounds 7.25 -> 6.87 ms over 50 steps of the gas of 1e7,
 * 8.25e9 -> 8.33e9 particle-steps/s; the random scene's (N = 32000, 200 steps) 3.38 -> 3.11 ms, and at
 * 1e6 4.77e8 -> 4.83e8 (bench/gpu_h100_variants.log 25i). Each pass's work per event is pass_min_lo's,
 * pass_accept's and pass_compact's, which the one-block finish takes an event at a time. */
#ifndef CHOOSE_ILP
#define CHOOSE_ILP 4
#endif
#define ILP_TURN(i, len)                                                                                 \
    const int64_t stride = (int64_t)gridDim.x * blockDim.x;                                              \
    for (int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x; i < (len); i += CHOOSE_ILP * stride)
#define ILP_EACH(u, i, len) \
    _Pragma("unroll") for (int u = 0; u < CHOOSE_ILP; u++) if ((i) + u * stride < (len))

__global__ void min_lo_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              const uint64_t *best_hi, uint64_t *best_lo)
{
    after_previous();
    int64_t len = list_len(count, cap);
    ILP_TURN(i, len) {
        PairEvent e[CHOOSE_ILP] = {};
        uint64_t ha[CHOOSE_ILP] = {}, hb[CHOOSE_ILP] = {};
        ILP_EACH(u, i, len) e[u] = ev[i + u * stride];
        ILP_EACH(u, i, len) ha[u] = best_hi[e[u].a], hb[u] = best_hi[e[u].b];
        ILP_EACH(u, i, len) {
            if (ha[u] == e[u].hi) atomicMin((unsigned long long *)&best_lo[e[u].a], (unsigned long long)e[u].lo);
            if (hb[u] == e[u].hi) atomicMin((unsigned long long *)&best_lo[e[u].b], (unsigned long long)e[u].lo);
        }
    }
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
    ILP_TURN(i, len) {
        PairEvent e[CHOOSE_ILP] = {};
        uint64_t ha[CHOOSE_ILP] = {}, hb[CHOOSE_ILP] = {}, la[CHOOSE_ILP], lb[CHOOSE_ILP];
        ILP_EACH(u, i, len) e[u] = ev[i + u * stride];
        ILP_EACH(u, i, len) ha[u] = best_hi[e[u].a], hb[u] = best_hi[e[u].b];
#pragma unroll
        for (int u = 0; u < CHOOSE_ILP; u++) la[u] = lb[u] = NO_EVENT;
        ILP_EACH(u, i, len) if (ha[u] == e[u].hi && hb[u] == e[u].hi) {
            la[u] = best_lo[e[u].a];
            lb[u] = best_lo[e[u].b];
        }
        ILP_EACH(u, i, len) accept_event(e[u], ha[u], hb[u], la[u], lb[u], partner);
    }
}

__global__ void compact_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                               PairEvent *out, unsigned long long *count_out, const int32_t *partner,
                               const uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo)
{
    after_previous();
    int64_t len = list_len(count, cap);
    ILP_TURN(i, len) {
        PairEvent e[CHOOSE_ILP] = {};
        bool live[CHOOSE_ILP] = {};
        uint64_t wa[CHOOSE_ILP] = {}, wb[CHOOSE_ILP] = {};
        ILP_EACH(u, i, len) e[u] = ev[i + u * stride];
        ILP_EACH(u, i, len) live[u] = partner[e[u].a] < 0 && partner[e[u].b] < 0;
        ILP_EACH(u, i, len) if (live[u]) wa[u] = wall_hi[e[u].a], wb[u] = wall_hi[e[u].b];
        ILP_EACH(u, i, len) if (live[u]) {
            unsigned long long at = list_append(count_out); /* < cap: no list outgrows the one it came from */
            if ((int64_t)at < cap) out[at] = e[u];
            best_hi[e[u].a] = wa[u];
            best_hi[e[u].b] = wb[u];
            best_lo[e[u].a] = NO_EVENT;
            best_lo[e[u].b] = NO_EVENT;
        }
    }
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
