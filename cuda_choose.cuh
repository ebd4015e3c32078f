/* cuda_choose.cuh: the choice: rounds of accepting every event that is the smallest live one of both its disks.
 * Part of cuda.cu, which includes it after its constants and the files before it (cuda.cu's list). */

/* ==== choose ============================================================================================= */
/* best_hi/best_lo of a disk: the smallest key among its remaining events (its wall event and the pair
 * events in the current list). partner: negative none yet (-1, or PARTNER_WALL where it has a wall event
 * within the step, slot_init), itself for an accepted wall event, else the other slot of its accepted pair.
 * Each phase below is one pass over a list; the grid versions are separate kernels, the one-block version
 * separates them with __syncthreads. */

/* The passes over a list. Each takes, at event i, the ILP events i, i + stride, ... below len, and issues
 * each of its loads for all of them before waiting on any: taken one after another, each event waited on
 * its own chain of loads, the list's and then its disks' keys, scattered as the disks with events are. The
 * grid-wide kernels take CHOOSE_ILP events a thread a turn (min_hi's, on few events after the first round,
 * one): on one H200 the rounds 7.25 -> 6.87 ms over 50 steps of the gas of 1e7, 8.25e9 -> 8.33e9
 * particle-steps/s; the random scene's (N = 32000, 200 steps) 3.38 -> 3.11 ms, and at 1e6 4.77e8 -> 4.83e8
 * (bench/gpu_h100_variants.log 25i). The one-block finish takes one; its compaction so loads the disks' wall
 * keys before it appends, not after: random scene, N = 32000, the finish 2.30 -> 2.05 ms over 200 steps;
 * dense gas of 1e7 2.71 -> 2.52 ms over 50 (25k). */
#ifndef CHOOSE_ILP
#define CHOOSE_ILP 4
#endif
#define ILP_EACH(u) _Pragma("unroll") for (int u = 0; u < ILP; u++) if (ILP == 1 || i + u * stride < len)

/* LO_IF_TIED: the first round's second keys (min_lo, a pass over the whole list) matter only where one disk has
 * two events of one first key, which ZERO_KEYS makes rare. The search's minima of the first keys return the key
 * they met, and one that met its own raises StepInfo.ties (test_pair); where the step has none, min_lo returns at
 * once and accept compares first keys alone. On one H200: dense gas of 1e7 6.84e9 -> 7.36e9 particle-steps/s,
 * its rounds 12.01 -> 6.86 ms over 50 steps; gas of 1e7 9.98e9 -> 1.002e10 (rounds 3.17 -> 2.86); random scene,
 * N = 32000, rounds 3.18 -> 2.94 ms over 200 steps (bench/gpu_h100_variants.log 54). The flag alone, with one
 * first key for all events of time 0, rose in nearly every step of a gas (12b, 27j, 52b). 2: cuda's steps,
 * 1: those of one slice, 0: never (GPU ranks, mpi_cuda.cu: never). */
#ifndef LO_IF_TIED
#define LO_IF_TIED 2
#endif

/* The events' own keys: each disk's best_lo lowered to the event's where its best_hi is the event's. */
template <int ILP>
static __device__ __forceinline__ void pass_min_lo(const PairEvent *ev, int64_t i, int64_t stride, int64_t len,
                                                   const uint64_t *best_hi, uint64_t *best_lo)
{
    PairEvent e[ILP] = {};
    uint64_t ha[ILP] = {}, hb[ILP] = {};
    ILP_EACH(u) e[u] = ev[i + u * stride];
    ILP_EACH(u) ha[u] = best_hi[e[u].a], hb[u] = best_hi[e[u].b];
    ILP_EACH(u) {
        if (ha[u] == e[u].hi) atomicMin((unsigned long long *)&best_lo[e[u].a], (unsigned long long)e[u].lo);
        if (hb[u] == e[u].hi) atomicMin((unsigned long long *)&best_lo[e[u].b], (unsigned long long)e[u].lo);
    }
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

template <int ILP>
static __device__ __forceinline__ void pass_accept(const PairEvent *ev, int64_t i, int64_t stride, int64_t len,
                                                   const uint64_t *best_hi, const uint64_t *best_lo,
                                                   int32_t *partner)
{
    PairEvent e[ILP] = {};
    uint64_t ha[ILP] = {}, hb[ILP] = {}, la[ILP], lb[ILP];
    ILP_EACH(u) e[u] = ev[i + u * stride];
    ILP_EACH(u) ha[u] = best_hi[e[u].a], hb[u] = best_hi[e[u].b];
#pragma unroll
    for (int u = 0; u < ILP; u++) la[u] = lb[u] = NO_EVENT;
    ILP_EACH(u) if (ha[u] == e[u].hi && hb[u] == e[u].hi) {
        la[u] = best_lo ? best_lo[e[u].a] : e[u].lo; /* NULL: no ties (accept_kernel) */
        lb[u] = best_lo ? best_lo[e[u].b] : e[u].lo;
    }
    ILP_EACH(u) accept_event(e[u], ha[u], hb[u], la[u], lb[u], partner);
}

/* Keeps the events whose disks are both still free, and restarts those disks' best keys: compact_take loads
 * them and restarts the keys, returning how many are kept (live), and the caller appends them to out. */
template <int ILP>
static __device__ __forceinline__ unsigned compact_take(const PairEvent *ev, int64_t i, int64_t stride, int64_t len,
                                                        const int32_t *partner, const uint64_t *wall_hi,
                                                        uint64_t *best_hi, uint64_t *best_lo, PairEvent *e, bool *live)
{
    uint64_t wa[ILP] = {}, wb[ILP] = {};
    unsigned kept = 0;
    ILP_EACH(u) e[u] = ev[i + u * stride];
    ILP_EACH(u) live[u] = partner[e[u].a] < 0 && partner[e[u].b] < 0;
    /* wall_hi NULL (GATED_WALLS): every event is before both its disks' wall events, so a live disk's best key
     * after the next min_hi is its smallest event with or without its wall key */
    ILP_EACH(u) if (live[u] && wall_hi) wa[u] = wall_hi[e[u].a], wb[u] = wall_hi[e[u].b];
    ILP_EACH(u) if (live[u] && !wall_hi) wa[u] = wb[u] = NO_EVENT;
    ILP_EACH(u) if (live[u]) {
        kept++;
        best_hi[e[u].a] = wa[u];
        best_hi[e[u].b] = wb[u];
        best_lo[e[u].a] = NO_EVENT;
        best_lo[e[u].b] = NO_EVENT;
    }
    return kept;
}

template <int ILP>
static __device__ __forceinline__ void pass_compact(const PairEvent *ev, int64_t i, int64_t stride, int64_t len,
                                                    PairEvent *out, unsigned long long *count_out, int64_t cap,
                                                    const int32_t *partner, const uint64_t *wall_hi,
                                                    uint64_t *best_hi, uint64_t *best_lo)
{
    PairEvent e[ILP] = {};
    bool live[ILP] = {};
    compact_take<ILP>(ev, i, stride, len, partner, wall_hi, best_hi, best_lo, e, live);
    warp_put<ILP>(out, count_out, cap, e, live); /* within cap: no list outgrows the one it came from */
}

static __device__ __forceinline__ int64_t list_len(const unsigned long long *count, int64_t cap)
{
    int64_t c = (int64_t)*count;
    return c < cap ? c : cap;
}

/* A grid-wide pass: event i and the CHOOSE_ILP - 1 after it, stride apart, a turn */
#define ILP_TURN(i, len)                                                                                 \
    const int64_t stride = (int64_t)gridDim.x * blockDim.x;                                              \
    for (int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x; i < (len); i += CHOOSE_ILP * stride)

/* The passes that append to a list (the settling's contested events, a later round's compaction) append a
 * block's at once (block_append): ILP_TURN then runs for every thread of a block alike (BLOCK_TURN), and each
 * thread checks its own events against the list's length (ILP_EACH, where CHOOSE_ILP > 1). On one H200 the
 * rounds of the gas of 1e7 3.53 -> 3.27 ms over 50 steps, of the dense gas 12.71 -> 12.22, 7.12e9 -> 7.17e9
 * particle-steps/s (bench/gpu_h100_variants.log 38d). 0: by warps (list_append). */
#ifndef BLOCK_APPEND
#define BLOCK_APPEND 1
#endif
static_assert(!BLOCK_APPEND || CHOOSE_ILP > 1, "BLOCK_TURN: ILP_EACH checks each event against the length");
#define BLOCK_TURN(i, len)                                                                               \
    const int64_t stride = (int64_t)gridDim.x * blockDim.x;                                              \
    for (int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;                                     \
         i - threadIdx.x < (len); i += CHOOSE_ILP * stride)
#if BLOCK_APPEND
#define APPEND_TURN BLOCK_TURN
#else
#define APPEND_TURN ILP_TURN
#endif

__global__ void min_lo_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              const uint64_t *best_hi, uint64_t *best_lo, const unsigned int *ties)
{
    after_previous();
    if (ties && !*ties) return; /* LO_IF_TIED: no disk has two events of its smallest first key */
    int64_t len = list_len(count, cap);
    ILP_TURN(i, len) pass_min_lo<CHOOSE_ILP>(ev, i, stride, len, best_hi, best_lo);
}

__global__ void min_hi_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              uint64_t *best_hi)
{
    after_previous();
    int64_t len = list_len(count, cap);
    GRID_LOOP(i, len) pass_min_hi(ev, i, best_hi);
}

__global__ void accept_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                              const uint64_t *best_hi, const uint64_t *best_lo, int32_t *partner,
                              const unsigned int *ties)
{
    after_previous();
    if (ties && !*ties) best_lo = NULL; /* LO_IF_TIED: an event holding both its disks' first keys is theirs */
    int64_t len = list_len(count, cap);
    ILP_TURN(i, len) pass_accept<CHOOSE_ILP>(ev, i, stride, len, best_hi, best_lo, partner);
}

__global__ void compact_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap,
                               PairEvent *out, unsigned long long *count_out, const int32_t *partner,
                               const uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo)
{
    after_previous();
    int64_t len = list_len(count, cap);
    if (!BLOCK_APPEND) {
        ILP_TURN(i, len) {
            pass_compact<CHOOSE_ILP>(ev, i, stride, len, out, count_out, cap, partner, wall_hi, best_hi, best_lo);
        }
        return;
    }
    BLOCK_TURN(i, len) {
        const int ILP = CHOOSE_ILP;
        PairEvent e[ILP] = {};
        bool live[ILP] = {};
        unsigned kept = compact_take<ILP>(ev, i, stride, len, partner, wall_hi, best_hi, best_lo, e, live);
        block_put<ILP>(out, count_out, cap, e, live, kept); /* within cap: no list outgrows the one it came from */
    }
}

/* SETTLE (cuda's steps of one slice, a GPU rank's steps: mpi_cuda.cu, whose copies of other ranks' disks take
 * every event as contested): an event the only one of both its disks is the smallest of both (the
 * search keeps no pair event at or after either disk's wall event), and accepted at once; the others,
 * contested, go on to the rounds. The search lowered each event's disks'
 * partners by PARTNER_TALLY (test_pair), from -1 or PARTNER_WALL, which the two low bits still tell
 * apart: a partner of -1 - 4k or PARTNER_WALL - 4k has k events. A contested event's disks get their
 * partners back less two tallies (free to the rounds, a wall event told by the low bits as before, and
 * the move told that the disk had events: MoveBin.marked) and their second keys started, for min_lo; the
 * rounds see the contested events alone, as no other event shares a disk with a settled one. An event
 * reading a tally another event's settling has already set reads 2 events, so it too is contested, as it
 * should be: a tally of one is final (the settling never sets one). */
static __device__ __forceinline__ int32_t tally_base(int32_t p)
{
    return (p & 3) == 3 ? -1 : PARTNER_WALL;
}

__global__ void settle_kernel(const PairEvent *ev, const unsigned long long *count, int64_t cap, PairEvent *out,
                              unsigned long long *count_out, int32_t *partner, uint64_t *best_lo)
{
    after_previous();
    static_assert((-1 & 3) == 3 && (PARTNER_WALL & 3) == 1 && PARTNER_TALLY == 4, "tally_base");
    int64_t len = list_len(count, cap);
    APPEND_TURN(i, len) {
        PairEvent e[CHOOSE_ILP] = {};
        int32_t pa[CHOOSE_ILP] = {}, pb[CHOOSE_ILP] = {};
        bool contested[CHOOSE_ILP] = {};
        unsigned k = 0;
        const int ILP = CHOOSE_ILP;
        ILP_EACH(u) e[u] = ev[i + u * stride];
        ILP_EACH(u) pa[u] = partner[e[u].a], pb[u] = partner[e[u].b];
        ILP_EACH(u) {
            int32_t ba = tally_base(pa[u]), bb = tally_base(pb[u]);
            if (ba - pa[u] == PARTNER_TALLY && bb - pb[u] == PARTNER_TALLY) {
                partner[e[u].a] = e[u].b;
                partner[e[u].b] = e[u].a;
            } else {
                contested[u] = true;
                k++;
                partner[e[u].a] = ba - 2 * PARTNER_TALLY;
                partner[e[u].b] = bb - 2 * PARTNER_TALLY;
                best_lo[e[u].a] = NO_EVENT;
                best_lo[e[u].b] = NO_EVENT;
            }
        }
        if (BLOCK_APPEND) /* within cap: a part of the list it came from */
            block_put<ILP>(out, count_out, cap, e, contested, k);
        else
            warp_put<ILP>(out, count_out, cap, e, contested);
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
            pass_compact<1>(in, i, 0, len, out, &n_out, cap, partner, wall_hi, best_hi, best_lo);
        __syncthreads();
        len = (int64_t)n_out;
        if (len == 0) return;
        for (int64_t i = threadIdx.x; i < len; i += blockDim.x) pass_min_hi(out, i, best_hi);
        __syncthreads();
        for (int64_t i = threadIdx.x; i < len; i += blockDim.x) pass_min_lo<1>(out, i, 0, len, best_hi, best_lo);
        __syncthreads();
        for (int64_t i = threadIdx.x; i < len; i += blockDim.x)
            pass_accept<1>(out, i, 0, len, best_hi, best_lo, partner);
        __syncthreads();
        PairEvent *t = in;
        in = out;
        out = t;
    }
}
