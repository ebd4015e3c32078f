/* cuda_choose.cuh: the choice: rounds of accepting every event that is the smallest live one of both its disks.
 * Part of cuda.cu, which includes it after its constants and the files before it (cuda.cu's list). */

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
