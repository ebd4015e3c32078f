/* cuda_detect.cuh: the pair search over the placed entries.
 * Part of cuda.cu, which includes it after its constants and the files before it (cuda.cu's list). */

/* ==== detect ============================================================================================= */

/* Sorted entry p tests every later entry q > p of the same slice in the 3x3 cells around its own (cells
 * keyed in sx columns, Grid.sx: the sx columns to each side of its own). Cell order is row by row, so the
 * row above lies wholly before p: what is left is the rest of p's own row (from p + 1 to the end of the
 * last column to its right) and the same columns of the row below, two contiguous runs of entries.
 * K > 1 finds each entry's slot in en.placed; K = 1, in en.slot, or where that is NULL, entry == slot.
 * Entry and cell indices fit in 32 bits (cuda_open's limits).
 *
 * A dense scene gives each entry many candidates, and each thread walks its own, screening them with
 * near_path where K > 1 (the warp then tests those passed together). A sparse one (the gas)
 * gives a few each, 0 to 6 or so: walked per thread, most lanes of a warp would idle while the one with
 * the most finished. There the block deals its candidate pairs out evenly instead, one per thread per
 * round. */
#ifndef DETECT_MIN_BLOCKS
#define DETECT_MIN_BLOCKS 5 /* the looping search's blocks a multiprocessor, times LOOP_BLOCKS (detect_box) */
#endif
#ifndef DETECT_MIN_BLOCKS_ONE
#define DETECT_MIN_BLOCKS_ONE 6 /* K = 1: 40 registers, a few spilled, against 48 at 5: gas of 1e7 on one H200,
                                   7.05e9 -> 7.21e9 particle-steps/s, dense gas 5.54e9 -> 5.68e9 (at 7, more
                                   spilled, slower; bench/gpu_h100_variants.log 13c; at 7 and 8 with room for
                                   them in shared memory, the gas no faster, the dense gas 2-3% slower: 39b) */
#endif
#ifndef DETECT_MIN_BLOCKS_MID
#define DETECT_MIN_BLOCKS_MID 4 /* K > 1: 60 registers; at 5 (48) no faster, at 4 levels only 4 blocks fit */
#endif
#ifndef PROBE_LAZY
#define PROBE_LAZY 1 /* K > 1: the probe's disk loaded by each pair test, not by the probe (test_pair): few
                        pass near_path. Random scene, N = 1e6, one H200: 4.77e8 particle-steps/s, against
                        4.55e8 loaded by the probe through its slot (bench/gpu_h100_variants.log 23) */
#endif
#ifndef PROBE_EARLY
#define PROBE_EARLY 1 /* K = 1, disks in their slots: the probe's disk loaded beside its key, not after the cells'
                         bounds, which wait on the key (gas of 1e7 on one H200: the search 20.80 -> 20.67 ms
                         over 50 steps, dense gas 32.22 -> 32.08; bench/gpu_h100_variants.log 25g) */
#endif
#ifndef DETECT_TAKE
#define DETECT_TAKE 4 /* a lane's candidates a turn (cursor_take), even: the turn's bookkeeping shared by 4
                         screens, not 2 (random scene, N = 1e6: the search 9.96 -> 9.04 ms over 10 steps;
                         at 6 no faster, at 8 spilled; bench/gpu_h100_variants.log 21) */
#endif
static_assert(DETECT_TAKE % 2 == 0, "the queue takes two pushes a lane between its flushes (QUEUE)");
#define PROBE_RUNS (1 + 3 * (LEVELS - 1)) /* a probe's runs of candidates after its first, at most (Cursor) */
static_assert(PROBE_RUNS < 256 && LEVELS <= 3, "Cursor: lv holds where 2 slower levels begin, in 8 bits each");
/* dynamic shared memory: their bounds, and the time offsets of the probe's level and the slower ones (an
 * offset beside each run would save the selects but take 4 KB more a block: random scene, N = 32000,
 * 1.90e8 against 2.05e8-2.14e8 particle-steps/s, bench/gpu_h100_variants.log 10k) */
#define RUN_BYTES ((size_t)PROBE_RUNS * THREADS * sizeof(uint2) + (size_t)LEVELS * THREADS * sizeof(float))
#ifndef SHARED_CANDIDATES
#define SHARED_CANDIDATES 1 /* K = 1: a candidate among the block's probes read from their records (test_pair):
                               with the disks in patches (PATCH_W) most of a block's candidates; alone, in the
                               rows' order, no faster (bench/gpu_h100_variants.log 27f). Gas of 1e7 on one
                               H200: 1.02e10 particle-steps/s, 9.96e9 without (39d) */
#endif
#ifndef DETECT_SCAN
#define DETECT_SCAN cub::BLOCK_SCAN_WARP_SCANS /* the dealing's block scan: a warp's by shuffles, 8 sums through
                                                 shared memory, where cub's default (BLOCK_SCAN_RAKING) passes
                                                 every count through it. Gas of 1e7 on one H200: the search 20.88
                                                 -> 20.71 ms over 50 steps, 1.027e10 -> 1.031e10-1.032e10
                                                 particle-steps/s (bench/gpu_h100_variants.log 41e) */
#endif
#ifndef LEAN_PROBES
#define LEAN_PROBES 1 /* K = 1: a probe's record written without the fields the search never reads back (its slice
                         k, 0, and its edge runs outside the periodic box), 60 bytes of 80: gas of 1e7 on one H200,
                         the search 20.82 -> 20.72 ms over 50 steps, 1.023e10-1.025e10 -> 1.025e10-1.028e10
                         particle-steps/s; dense gas 32.26 -> 31.82 ms, 7.19e9-7.20e9 -> 7.23e9-7.25e9 (each
                         field read where it is used as well: no faster; bench/gpu_h100_variants.log 42c).
                         0: the whole record */
#endif
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
#ifndef BLOCK_EVENTS
#define BLOCK_EVENTS 256 /* 64 (the gas finds about 16 a block): no faster (bench/gpu_h100_variants.log 39b) */
#endif
typedef struct {
    PairEvent e[BLOCK_EVENTS];
    unsigned long long n; /* 64 bits: a block of a dense pile can find more than 2^32 */
    unsigned long long base;
} BlockEvents;

/* The wall key of the disk in slot s: loaded, where the periodic box has none; GATED: only where its
 * partner says the move kept one (GATED_WALLS), read as the search's tallies change it. (Computed again
 * from the probe's state, which slot_init's callers key it from, the gas's search took 9% longer: gas of
 * 1e7 on one H200, 20.54 -> 22.41 ms over 50 steps; bench/gpu_h100_variants.log 25h.) */
template <bool PERIODIC, bool GATED = false>
static __device__ __forceinline__ uint64_t slot_wall(const Entries &en, uint32_t s)
{
    if (PERIODIC) return NO_EVENT;
    if (GATED) {
        int32_t p;
        asm volatile("ld.relaxed.gpu.global.s32 %0, [%1];" : "=r"(p) : "l"(en.wall_gate + s));
        if (!wall_pending(p)) return NO_EVENT;
    }
    return __ldg(&en.wall[s]);
}

/* Probe pr's disk, from slot ps. */
template <bool PERIODIC, bool GATED = false>
static __device__ __forceinline__ void probe_disk(Probe &pr, const Entries &en, uint32_t ps)
{
    pr.pos = __ldg(&en.disk[ps].pos);
    pr.vel = __ldg(&en.disk[ps].vel);
    pr.id = __ldg(&en.id[ps]);
    pr.wall = slot_wall<PERIODIC, GATED>(en, ps);
}

/* The pair test of entry p (probe pr) and entry q > p: appends the pair event if there is one.
 * PERIODIC: the grid's box is periodic (Grid.periodic), as a constant of the search's build. SLOTS: the
 * disks stay in their slots, en.slot holds each entry's (en's arrays are the slots'; K = 1), and p is
 * the probe's slot. MID (K > 1): en's arrays are the slots' too, p an entry, en.placed each entry's; with
 * PROBE_LAZY the probe's disk is loaded here, for the few candidates near_path passes. */
template <bool PERIODIC, bool SLOTS, bool MID, bool GATED = false>
static __device__ __forceinline__ void test_pair(const Entries &en, const Grid &gr, const Probe &pr, uint32_t p,
                                                 uint32_t q, real sigma2, BlockEvents *be, PairEvent *ev,
                                                 int64_t cap, unsigned long long *found, uint64_t *best_hi,
                                                 const Probe *block = NULL, uint32_t p0 = 0)
{
    const uint32_t d = MID ? __ldg(&en.placed[q].x) : SLOTS ? (uint32_t)__ldg(&en.slot[q]) : q; /* q's disk in
                                                                                                   en's arrays */
    const uint32_t ps = MID ? __ldg(&en.placed[p].x) : p; /* and p's, where MID */
    const bool lazy = MID && PROBE_LAZY;
    /* K = 1: a candidate among the block's own probes (slots p0 on), from their records (SHARED_CANDIDATES) */
    const Probe *mine = !MID && SHARED_CANDIDATES && block && d - p0 < THREADS ? &block[d - p0] : NULL;
    real2 pos2 = mine ? mine->pos : __ldg(&en.disk[d].pos), vel2 = mine ? mine->vel : __ldg(&en.disk[d].vel);
    const real2 pos1 = lazy ? __ldg(&en.disk[ps].pos) : pr.pos, vel1 = lazy ? __ldg(&en.disk[ps].vel) : pr.vel;
    /* pair_time(i, j) is pair_time(j, i) bit for bit: swapping the disks negates dx, dy, dvx and dvy
     * exactly, which changes no product, sum or comparison after them. So p goes first whichever index
     * is lower, and only the event's fields below depend on the order. */
    real t = PERIODIC ? pair_time_wrap(pos1.x, pos1.y, vel1.x, vel1.y, pos2.x, pos2.y, vel2.x, vel2.y, sigma2, gr.Lw,
                                          gr.halfw, 1)
                         : pair_time(pos1.x, pos1.y, vel1.x, vel1.y, pos2.x, pos2.y, vel2.x, vel2.y, sigma2);
    if (t < 0) return;
    /* K > 1 alone, which MID searches: a one-slice search runs where the plan, and so the gate's grid, has one
     * slice (detect_box), and its records leave k unwritten (LEAN_PROBES) */
    if (MID && gr.K > 1 && (slice_of(t, gr.K) >> PROBE_LEVEL(pr.k)) != (int64_t)PROBE_SLICE(pr.k)) return;
    PairEvent e;
    e.hi = time_key(t) | 1; /* at time 0, 1: below every wall key but time 0's, as its own key (zero_pair_key) will
                               be; that one waits on the indices, which only an event past this test loads */
    uint64_t wall1 = lazy ? slot_wall<PERIODIC>(en, ps) : pr.wall;
    if (!(e.hi < wall1 && e.hi < (mine ? mine->wall : slot_wall<PERIODIC, GATED>(en, d))))
        return; /* a wall's first */
    int32_t id1 = lazy ? __ldg(&en.id[ps]) : pr.id, id2 = mine ? mine->id : __ldg(&en.id[d]); /* only a pair
                                                                                     with an event needs */
    bool first = id1 < id2;
    int32_t s = (int32_t)ps, s2 = (int32_t)d; /* one slice without SLOTS: entries are slots */
    e.a = first ? s : s2;
    e.b = first ? s2 : s;
    e.lo = first ? ((uint64_t)id1 << 31 | (uint64_t)id2) : ((uint64_t)id2 << 31 | (uint64_t)id1);
    if (e.hi == 1) e.hi = zero_pair_key(e.lo); /* time 0: time_key(0) | 1 */
    unsigned long long at = atomicAdd(&be->n, 1ull);
    if (at < BLOCK_EVENTS) {
        be->e[at] = e;
    } else {
        unsigned long long g = list_append(found);
        if ((int64_t)g < cap) ev[g] = e;
    }
    if (en.ties) {
        /* the event that finds its own key at a disk is the later of two tied events (the key only falls):
         * each tie at a disk's smallest key raises the flag, as may a tie that a smaller key then undercuts */
        unsigned long long ha = atomicMin((unsigned long long *)&best_hi[e.a], (unsigned long long)e.hi);
        unsigned long long hb = atomicMin((unsigned long long *)&best_hi[e.b], (unsigned long long)e.hi);
        if (ha == e.hi || hb == e.hi) *en.ties = 1;
    } else { /* reductions, which nothing waits on */
        atomicMin((unsigned long long *)&best_hi[e.a], (unsigned long long)e.hi);
        atomicMin((unsigned long long *)&best_hi[e.b], (unsigned long long)e.hi);
    }
    if (en.tally) { /* reductions, their values unused: settle_kernel reads the tallies */
        atomicSub(&en.tally[e.a], PARTNER_TALLY);
        atomicSub(&en.tally[e.b], PARTNER_TALLY);
    } else if (en.best_lo) { /* every writer stores the same; the choice's first pass reads it */
        en.best_lo[e.a] = NO_EVENT;
        en.best_lo[e.b] = NO_EVENT;
    }
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
    uint32_t gx = (uint32_t)gr.gx, sx = (uint32_t)gr.sx; /* the cells' columns (Grid.sx) */
    uint32_t cy = pr.c / gx, cx = pr.c - cy * gx;
    uint32_t x0 = cx >= sx ? cx - sx : 0, x1 = cx + sx < gx ? cx + sx : gx - 1;
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
            uint32_t base = row * gr.ncell + (y - 1) * gx;
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

/* The lane's candidates of a turn: the next DETECT_TAKE of its current run, or of the next run where the
 * current one is done. Into q[i] where got[i], else an entry there is (the last of the lane's current run,
 * or its own, to be screened and not kept), and into dt their run's offset; a turn takes from one run only,
 * so a run whose length is no multiple of DETECT_TAKE leaves its last turn part used (one branch a turn
 * instead of one a candidate; taking the next run by selects, without the branch, was slower: the search
 * 11.74 -> 12.42 ms at N = 32000, section 21). col, dts: the thread's column of runs and of offsets. */
static __device__ __forceinline__ void cursor_take(Cursor &cu, uint32_t (&q)[DETECT_TAKE], bool (&got)[DETECT_TAKE],
                                                   const uint2 *col, const float *dts)
{
    if (cu.q >= cu.qe && cu.r < cu.runs) {
        uint2 run = col[cu.r * THREADS];
        cu.q = run.x;
        cu.qe = run.y;
        cu.dt = dts[((cu.r >= (cu.lv & 0xffu)) + (cu.r >= (cu.lv >> 8))) * THREADS];
        cu.r++;
    }
#pragma unroll
    for (int i = 0; i < DETECT_TAKE; i++) {
        got[i] = cu.q + i < cu.qe;
        q[i] = got[i] ? cu.q + i : cu.qe - 1;
    }
    cu.q = got[0] ? cu.q + DETECT_TAKE : cu.q;
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

/* Candidate i of probe po: its own row's rest, the row below, then the edges' runs. */
template <bool PERIODIC>
static __device__ __forceinline__ uint32_t candidate(const Probe &po, uint32_t i)
{
    if (i < po.na) return po.c + i; /* Probe.c: the entry after the probe's (K = 1) */
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
 * gas of 1e7's spilled). SLOTS (test_pair): 1, the disks in their slots; 2, a gathering step's in patches
 * (Entries.patches), a build of its own, as testing the pointer took registers the search spills; 3, as 1,
 * whose wall keys the move kept only where there is one (GATED_WALLS; cuda's steps, a GPU rank's). */
template <bool TILES, bool MID, bool PERIODIC, int SLOTS>
__global__ void __launch_bounds__(THREADS, MID ? DETECT_MIN_BLOCKS_MID : DETECT_MIN_BLOCKS_ONE)
    detect_kernel(Entries en, const uint32_t *__restrict__ keys, const uint32_t *__restrict__ start,
                  const Grid *grid, int w, real sigma2, PairEvent *ev, int64_t cap, StepInfo *info,
                  uint64_t *best_hi)
{
    after_previous();
    typedef cub::BlockScan<uint32_t, THREADS, DETECT_SCAN> Scan;
    __shared__ typename Scan::TempStorage scan_tmp;
    constexpr bool GATED = !MID && SLOTS == 3;
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
            if (!MID && SLOTS && PROBE_EARLY) probe_disk<PERIODIC, GATED>(pr, en, p);
            /* MID: the entry's key as placed; one slice: the disk's key as its binning found it, from the
             * disk itself (a pass of 8 bytes a disk fewer: place_kernel); SLOTS: p is a slot, whose key and
             * place in its cell (en.rank) the binning left (the loads of a block's slots coalesce, where
             * those of its entries' disks would scatter); every slot has an entry, as a step of one slice
             * keys no disk out (bin_kernel), so the probes are slots 0 to end - 1 */
            /* a gathering step in patches (Entries.patches): the key from the disk, its place from its slot */
            const bool patched = !MID && SLOTS == 2;
            uint32_t key = MID ? __ldg(&en.placed[p].y)
                           : SLOTS && !patched
                               ? __ldg(&keys[p])
                               : cell_key<false>(*grid, __ldg(&en.disk[p].pos), __ldg(&en.disk[p].vel),
                                                 slice_mid(0, 0, 1), 0, NULL);
            uint32_t g = (uint32_t)gr.g;
            /* the cell's columns (Grid.sx; 1 in one slice and in the periodic box): the runs reach sx of
             * them to each side */
            const uint32_t sx = MID && !PERIODIC ? (uint32_t)gr.sx : 1u, gx = MID && !PERIODIC ? (uint32_t)gr.gx : g;
            uint32_t kl = MID ? key / gr.ncell : 0; /* the cell row: a slice of one level (one slice: 0) */
            uint32_t c = key - kl * gr.ncell, cy = c / gx, cx = c - cy * gx;
            uint32_t x0 = cx >= sx ? cx - sx : 0, x1 = cx + sx < gx ? cx + sx : gx - 1;
            uint32_t row = kl * gr.ncell + cy * gx;
            if (MID) {
                uint32_t base, lv = row_level(kl, k0, k1, gr.levels, &base);
                pr.k = ((k0 >> lv) + (kl - base)) | (lv << 16);
            } /* one slice: k stays 0, read by nothing (test_pair) */
            /* after lies within its cell, but a crowded table of 8-bit counts (count_add) can put it
             * anywhere (a step then refused): the run stays between its cell's start and its row's end,
             * empty where after lies past that end */
            uint32_t after = patched ? (uint32_t)(p - patch_shift(gr.g, key, start, en.patches)) + 1
                             : SLOTS ? __ldg(&start[key]) + rank_get(en.rank, p, en.rank8) + 1
                                     : p + 1; /* its entry's next */
            if (patched) after = max(after, __ldg(&start[key]) + 1);
            pr.c = MID ? c : after;
            const uint32_t row_end = __ldg(&start[row + x1 + 1]);
            pr.na = row_end > after ? row_end - after : 0;
            uint4 edge = make_uint4(0, 0, 0, 0); /* periodic: the runs across the box's edges */
            if (PERIODIC && g >= 3) {
                edge = edge_runs(start, row, kl * gr.ncell + (cy + 1 < g ? (cy + 1) * g : 0), cx, g, &pr.b0, &pr.nb);
            } else if (cy + 1 < g) {
                pr.b0 = __ldg(&start[row + gx + x0]);
                pr.nb = __ldg(&start[row + gx + x1 + 1]) - pr.b0;
            }
            if (MID ? !PROBE_LAZY : !SLOTS || !PROBE_EARLY) /* MID: the entry's disk, in its slot */
                probe_disk<PERIODIC>(pr, en, MID ? __ldg(&en.placed[p].x) : p);
            if (MID) pr.mid = __ldg(&en.mid[p]);
            else pr.edge = edge;
            if (MID)
                seen = probe_runs(pr, gr, (int)k0, (int)k1, start, edge, runs, dts, threadIdx.x, &first[threadIdx.x]);
        } else if (MID) {
            first[threadIdx.x] = 0;
        }
        /* read back from there: fewer registers held across the loops */
        if (!MID && LEAN_PROBES) {
            Probe &me = probes[threadIdx.x];
            me.pos = pr.pos, me.vel = pr.vel, me.wall = pr.wall, me.id = pr.id;
            me.c = pr.c, me.na = pr.na, me.b0 = pr.b0, me.nb = pr.nb;
            if (PERIODIC) me.edge = pr.edge;
        } else {
            probes[threadIdx.x] = pr;
        }
        if (threadIdx.x == 0) {
            be.n = 0;
            tests = 0;
        }
        if (MID) {
            /* each lane walks its own candidates (Cursor) and screens them, DETECT_TAKE a turn (their
             * loads overlap); those passed queue up in the warp, and each 32 of them take one pair test a
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
                uint32_t q[DETECT_TAKE];
                bool got[DETECT_TAKE], keep[DETECT_TAKE], any = false;
                cursor_take(cu, q, got, col, off);
                if (!__any_sync(0xffffffffu, got[0])) break;
                float4 c[DETECT_TAKE];
#pragma unroll
                for (int i = 0; i < DETECT_TAKE; i++) c[i] = __ldg(&en.mid[q[i]]);
                /* screened whether got or not (cursor_take: an entry there is), so no branch */
#pragma unroll
                for (int i = 0; i < DETECT_TAKE; i++) {
                    keep[i] = near_path(m, c[i], cu.dt, h, pad2, wrap, wl, wh) & got[i];
                    any |= keep[i];
                }
                if (!__any_sync(0xffffffffu, any)) continue;
#pragma unroll
                for (int i = 0; i < DETECT_TAKE; i += 2) { /* two pushes, then the queue below 32 again */
                    held = queue_push(wq, wo, held, keep[i], q[i], lane);
                    held = queue_push(wq, wo, held, keep[i + 1], q[i + 1], lane);
                    for (; held >= 32; held -= 32) {
                        __syncwarp();
                        uint32_t o = warp * 32 + wo[lane];
                        test_pair<PERIODIC, SLOTS, MID>(en, gr, probes[o], p0 + o, wq[lane], sigma2, &be, ev, cap,
                                                        found, best_hi);
                        queue_shift(wq, wo, held - 32, lane);
                    }
                }
            }
            __syncwarp();
            if (lane < held) {
                uint32_t o = warp * 32 + wo[lane];
                test_pair<PERIODIC, SLOTS, MID>(en, gr, probes[o], p0 + o, wq[lane], sigma2, &be, ev, cap, found,
                                                best_hi);
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
                    test_pair<PERIODIC, SLOTS, false, GATED>(en, gr, po, p, candidate<PERIODIC>(po, i), sigma2, &be,
                                                             ev, cap, found, best_hi, probes, p0);
            } else {
                if (threadIdx.x == 0) tests = total;
                first[threadIdx.x] = offset;
                for (uint32_t i = 0; i < count; i++) owner[offset + i] = (uint8_t)threadIdx.x;
                __syncthreads();
                for (uint32_t j = threadIdx.x; j < total; j += THREADS) {
                    uint32_t o = owner[j], i = j - first[o];
                    const Probe po = probes[o];
                    test_pair<PERIODIC, SLOTS, false, GATED>(en, gr, po, p0 + o, candidate<PERIODIC>(po, i), sigma2,
                                                             &be, ev, cap, found, best_hi, probes, p0);
                }
            }
        }
        __syncthreads();
        if (threadIdx.x == 0 && tests) atomicAdd(&info->tests, tests);
        unsigned kept = be.n < BLOCK_EVENTS ? (unsigned)be.n : BLOCK_EVENTS;
        if (!TILES) {
            /* the block's last work: its first warp appends the events alone, and the others leave
             * rather than wait at a barrier for the list's count (gas of 1e7 on one H200: the search
             * 7.60 -> 7.45 ms over 20 steps, bench/gpu_h100_variants.log 15b) */
            if (threadIdx.x >= 32 || kept == 0) return;
            unsigned long long base = 0;
            if (threadIdx.x == 0) base = atomicAdd(found, (unsigned long long)kept);
            base = __shfl_sync(0xffffffffu, base, 0);
            for (unsigned i = threadIdx.x; i < kept; i += 32)
                if ((int64_t)(base + i) < cap) ev[base + i] = be.e[i];
            return;
        }
        if (kept > 0) { /* block-uniform */
            if (threadIdx.x == 0) be.base = atomicAdd(found, (unsigned long long)kept);
            __syncthreads();
            for (unsigned i = threadIdx.x; i < kept; i += THREADS)
                if ((int64_t)(be.base + i) < cap) ev[be.base + i] = be.e[i];
        }
        __syncthreads(); /* TILES (one tile returned above): the shared records are rewritten by the next tile */
    }
}
