/* cuda_rows.cuh: the cell table of a keyed step of one slice, sorted in buckets of a row's cells rather than
 * counted cell by cell over the whole grid.
 * Part of cuda.cu, which includes it after cuda_bin.cuh (cuda.cu's list). */

/* ==== rows ================================================================================================ */

/* A keyed step of one slice (the move before keyed each slot's cell, MoveBin) needs the same table as any
 * other: start[] over the cells in key order, order[] each place's slot, rank[] each slot's place in its cell
 * (detect_kernel's SLOTS). The counting sort builds it with an atomic a disk on cells scattered over the
 * whole grid, a scan of every cell and a scattered placement. Here each bucket, ROW_SEG cells of one row, is
 * sorted by one block in shared memory instead:
 *   bucket_fill_kernel   each slot into its bucket's room (ROW_ROOM), one atomic a warp's bucket;
 *   bucket_scan_kernel   where each bucket begins in the table (one block: a bucket holds some 1300 disks of a
 *                        gas), and its end; the counts back to 0 for the next step;
 *   bucket_sort_kernel   a block a bucket: its cells counted, scanned and placed in shared memory, start[]
 *                        written for every cell of the bucket, order[] and rank[] for its disks.
 * Buckets follow the key order (a row's ROW_SEG-cell segments left to right, the rows in turn), so the table
 * is the counting sort's but for the order inside a cell, which an atomic sets either way: the same pair
 * tests, the same bytes. A bucket past its room refuses the step (StepInfo.crowded's CROWDED_BUCKET), which
 * runs again, and the run goes on with cell-by-cell tables. Gas of 1e7 on one H200: over 50 steps the table
 * 11.09 -> 10.03 ms (counting 4.31 -> 3.87, scan 2.09 -> 0.82, placement 4.70 -> 5.34), 1.035e10 -> 1.059e10
 * particle-steps/s; dense gas 7.28e9 -> 7.33e9. With the count a pass of its own before the scan, and the slots
 * filled after it, 1.5-2.6% slower than the counting sort (bench/gpu_h100_variants.log 46a-46f). */
#ifndef ROW_SORT
#define ROW_SORT 1 /* 0: keyed steps count, scan and place cell by cell (count_kernel, place_kernel) */
#endif
#ifndef ROW_SEG
#define ROW_SEG 2048      /* cells a bucket: its counts and places in 16 KB of shared memory (1024: slower, 46c) */
#endif
#ifndef ROW_THREADS
#define ROW_THREADS 256   /* a bucket's block (512: slower, 46c) */
#endif
#define ROW_SCAN 1024     /* bucket_scan_kernel's block */
#define ROW_SCAN_ITEMS 8
static_assert(ROW_SEG % ROW_THREADS == 0, "a bucket's cells, as many to each thread");

/* Buckets a row of g cells, and in a grid of g rows. */
static __host__ __device__ __forceinline__ int64_t row_segs(int64_t g)
{
    return (g + ROW_SEG - 1) / ROW_SEG;
}

static __host__ __device__ __forceinline__ int64_t row_buckets(int64_t g)
{
    return g * row_segs(g);
}

/* The bucket of cell `key` (y g + x, one slice, no slab), within the grid's nb buckets whatever the key. */
static __device__ __forceinline__ uint32_t key_bucket(uint32_t key, uint32_t g, uint32_t segs, uint32_t nb)
{
    uint32_t y = key / g, x = key - y * g, b = y * segs + x / ROW_SEG;
    return b < nb ? b : nb - 1;
}

/* The disks of a keyed step lie in patches of the gathering step's cells, which the move's cells (Grid of
 * the move, fitted ahead) cut anew: a warp's lanes hold two to four buckets, but not in runs. Each bucket takes
 * one atomic a warp, its first lane's (group: its lanes, first: the lanes before this one). And the warps take
 * their slots from ROW_SPREAD parts of the slots in turn: consecutive ones would all hold the few buckets of one
 * band of patches, and their atomics wait on one another at those few counts. One atomic a run of equal
 * buckets, the warps in order: the counting 26.7 against 3.2 ms over 50 steps (46a, 46b). */
#ifndef ROW_SPREAD
#define ROW_SPREAD 64
#endif
#ifndef ROW_MATCH
#define ROW_MATCH 1 /* 0: the groups by a ballot a bucket (bench/gpu_h100_variants.log 46e: slower) */
#endif
static __device__ __forceinline__ void bucket_group(unsigned live, uint32_t b, unsigned *group, unsigned *first)
{
    unsigned lane = threadIdx.x & 31, mine = 0;
    if (ROW_MATCH) {
        mine = __match_any_sync(live, b);
    } else {
        for (unsigned todo = live; todo;) { /* a turn a bucket: the same for every lane */
            uint32_t lead = __shfl_sync(live, b, __ffs(todo) - 1);
            unsigned same = __ballot_sync(live, b == lead);
            if (b == lead) mine = same;
            todo &= ~same;
        }
    }
    *group = mine;
    *first = __popc(mine & ((1u << lane) - 1));
}

/* The slot of this thread (ROW_SPREAD's parts in turn; launched for bucket_slots(n)), n or more where none. */
static __host__ __device__ __forceinline__ int64_t bucket_warps(int64_t n)
{
    return (n + 31) / 32;
}

static __host__ __device__ __forceinline__ int64_t bucket_slots(int64_t n)
{
    return (bucket_warps(n) + ROW_SPREAD - 1) / ROW_SPREAD * ROW_SPREAD * 32;
}

static __device__ __forceinline__ int64_t bucket_slot(int64_t n)
{
    int64_t t = (int64_t)blockIdx.x * blockDim.x + threadIdx.x, w = t / 32;
    int64_t per = (bucket_warps(n) + ROW_SPREAD - 1) / ROW_SPREAD;
    return ((w % ROW_SPREAD) * per + w / ROW_SPREAD) * 32 + (t & 31);
}

/* Each bucket's room in the buckets' array of `total` slots: an even share, at least 1.5 times a bucket's
 * average plus 256 where the array holds ROW_ROOM's (buffers_grow): 25 standard deviations of a gas's. */
#define ROW_ROOM(n, buckets) ((n) + (n) / 2 + 256 * (buckets))
static __device__ __forceinline__ uint32_t bucket_room(int64_t total, int64_t nb)
{
    int64_t r = nb > 0 ? total / nb : 0;
    return r < (int64_t)UINT32_MAX ? (uint32_t)r : UINT32_MAX;
}

/* Each slot into its bucket's room, at a place the bucket's count gives (an atomic a warp's bucket). A bucket
 * past its room marks the step crowded (CROWDED_BUCKET), to be refused; its count stays in bounds for the
 * scan (bucket_scan_kernel clamps it). Slower on one H200: the move before filing each disk as it keys it (its
 * atomics and stores cost the move twice this pass: gas of 1e7 9.5e9 against 1.05e10 particle-steps/s), and a
 * tile of 2048 slots counted in shared memory, a global atomic a bucket (1.014e10 against 1.051e10;
 * bench/gpu_h100_variants.log 47, 48). */
__global__ void bucket_fill_kernel(const Grid *grid, int64_t n, const uint32_t *keys, uint32_t *bcount,
                                   uint32_t *bucket, int64_t total, StepInfo *info)
{
    after_previous();
    const uint32_t g = (uint32_t)grid->g, segs = (uint32_t)row_segs(g);
    if (grid->cells == 0) return; /* after a refusal: nothing */
    const uint32_t nb = g * segs, room = bucket_room(total, nb);
    int64_t e = bucket_slot(n);
    unsigned live = __ballot_sync(0xffffffffu, e < n), group, first;
    if (e >= n) return;
    uint32_t b = key_bucket(keys[e], g, segs, nb), at = 0;
    bucket_group(live, b, &group, &first);
    if (first == 0) at = atomicAdd(&bcount[b], (uint32_t)__popc(group));
    at = __shfl_sync(group, at, __ffs(group) - 1) + first;
    if (at < room)
        bucket[(int64_t)b * room + at] = (uint32_t)e;
    else
        atomicOr(&info->crowded, (unsigned long long)CROWDED_BUCKET);
}

/* The buckets' exclusive sum into bstart (nb + 1 of them), and the table's end, start[cells]; the counts cleared
 * behind it. */
__global__ void __launch_bounds__(ROW_SCAN) bucket_scan_kernel(const Grid *grid, uint32_t *bcount,
                                                               uint32_t *bstart, uint32_t *start, int64_t total)
{
    after_previous();
    typedef cub::BlockScan<uint32_t, ROW_SCAN> Scan;
    __shared__ typename Scan::TempStorage tmp;
    const Grid gr = *grid;
    const int64_t nb = gr.cells ? row_buckets(gr.g) : 0;
    const uint32_t room = bucket_room(total, nb);
    uint32_t carry = 0;
    for (int64_t base = 0; base < nb; base += ROW_SCAN * ROW_SCAN_ITEMS) {
        uint32_t v[ROW_SCAN_ITEMS], sum;
        int64_t at = base + (int64_t)threadIdx.x * ROW_SCAN_ITEMS;
#pragma unroll
        for (int i = 0; i < ROW_SCAN_ITEMS; i++) {
            v[i] = at + i < nb ? min(bcount[at + i], room) : 0;
            if (at + i < nb) bcount[at + i] = 0; /* read by this thread alone */
        }
        Scan(tmp).ExclusiveSum(v, v, sum);
#pragma unroll
        for (int i = 0; i < ROW_SCAN_ITEMS; i++)
            if (at + i < nb) bstart[at + i] = carry + v[i];
        carry += sum;
        __syncthreads(); /* tmp again */
    }
    if (threadIdx.x == 0) {
        bstart[nb] = carry;
        start[gr.cells] = carry; /* 0 in an empty grid: the search then has no probe */
    }
}

/* Slot s, in column x of its bucket: its place in the table and in its cell (narrow: 8 bits, rank_put). The
 * bucket's first ROW_STAGE places are staged in shared memory, then written side by side (46e). */
#ifndef ROW_HOLD
#define ROW_HOLD 6
#endif
#define ROW_STAGE (ROW_HOLD * ROW_THREADS)
static __device__ __forceinline__ void bucket_place(uint32_t s, uint32_t x, uint32_t lo, const uint32_t *cnt,
                                                    uint32_t *fill, uint32_t *staged, uint32_t *order, uint32_t *rank,
                                                    unsigned long long *crowded)
{
    uint32_t r = atomicAdd(&fill[x], 1u), p = cnt[x] + r - lo;
    if (p < ROW_STAGE)
        staged[p] = s;
    else
        order[lo + p] = s;
    rank_put(rank, s, r, crowded != NULL);
    if (crowded && r > 0xffu) atomicOr(crowded, (unsigned long long)CROWDED_CELL);
}

/* A block a bucket (looping where the launch has fewer): its cells' counts, their exclusive sum, then each
 * disk's place. narrow: 8-bit ranks (rank_put), a cell past 255 disks raising *crowded (the step is refused,
 * as count_add's). */
#ifndef ROW_MIN_BLOCKS
#define ROW_MIN_BLOCKS 6 /* at 64 registers, 4 blocks a multiprocessor (46d) */
#endif
__global__ void __launch_bounds__(ROW_THREADS, ROW_MIN_BLOCKS)
    bucket_sort_kernel(const Grid *grid, const uint32_t *keys, const uint32_t *bstart, const uint32_t *bucket,
                       int64_t total, uint32_t *start, uint32_t *order, uint32_t *rank, unsigned long long *crowded)
{
    after_previous();
    typedef cub::BlockScan<uint32_t, ROW_THREADS> Scan;
    constexpr int ITEMS = ROW_SEG / ROW_THREADS;
    __shared__ typename Scan::TempStorage tmp;
    __shared__ uint32_t cnt[ROW_SEG], fill[ROW_SEG], staged[ROW_STAGE];
    const Grid gr = *grid;
    if (gr.cells == 0) return;
    const uint32_t g = (uint32_t)gr.g, segs = (uint32_t)row_segs(g);
    const int64_t nb = (int64_t)g * segs;
    constexpr int HOLD = ROW_HOLD;
    for (int64_t b = blockIdx.x; b < nb; b += gridDim.x) { /* block-uniform */
        const uint32_t y = (uint32_t)(b / segs), x0 = (uint32_t)(b - (int64_t)y * segs) * ROW_SEG;
        const uint32_t cols = g - x0 < ROW_SEG ? g - x0 : ROW_SEG, first = y * g + x0;
        const uint32_t lo = bstart[b], hi = bstart[b + 1];
        const uint32_t *mine = bucket + b * bucket_room(total, nb) - lo; /* place i's slot: mine[i] */
        for (int j = threadIdx.x; j < ROW_SEG; j += ROW_THREADS) cnt[j] = 0, fill[j] = 0;
        /* the first HOLD disks of each thread held in registers through both passes, their loads issued
         * together; a bucket of more (rarely: ROW_STAGE is 1.1 times a gas's) loads the rest twice */
        uint32_t s[HOLD], x[HOLD];
#pragma unroll
        for (int k = 0; k < HOLD; k++) {
            uint32_t i = lo + threadIdx.x + k * ROW_THREADS;
            s[k] = i < hi ? mine[i] : 0;
        }
#pragma unroll
        for (int k = 0; k < HOLD; k++) {
            uint32_t i = lo + threadIdx.x + k * ROW_THREADS, v = i < hi ? keys[s[k]] - first : 0;
            x[k] = v < cols ? v : cols - 1;
        }
        __syncthreads();
#pragma unroll
        for (int k = 0; k < HOLD; k++)
            if (lo + threadIdx.x + k * ROW_THREADS < hi) atomicAdd(&cnt[x[k]], 1u);
        for (uint32_t i = lo + threadIdx.x + HOLD * ROW_THREADS; i < hi; i += ROW_THREADS) {
            uint32_t v = keys[mine[i]] - first;
            atomicAdd(&cnt[v < cols ? v : cols - 1], 1u);
        }
        __syncthreads();
        uint32_t v[ITEMS];
#pragma unroll
        for (int i = 0; i < ITEMS; i++) v[i] = cnt[threadIdx.x * ITEMS + i];
        Scan(tmp).ExclusiveSum(v, v);
#pragma unroll
        for (int i = 0; i < ITEMS; i++) cnt[threadIdx.x * ITEMS + i] = lo + v[i]; /* this thread's cells alone */
        __syncthreads();
        for (uint32_t j = threadIdx.x; j < cols; j += ROW_THREADS) start[first + j] = cnt[j];
#pragma unroll
        for (int k = 0; k < HOLD; k++)
            if (lo + threadIdx.x + k * ROW_THREADS < hi)
                bucket_place(s[k], x[k], lo, cnt, fill, staged, order, rank, crowded);
        for (uint32_t i = lo + threadIdx.x + HOLD * ROW_THREADS; i < hi; i += ROW_THREADS) {
            uint32_t t = mine[i], u = keys[t] - first;
            bucket_place(t, u < cols ? u : cols - 1, lo, cnt, fill, staged, order, rank, crowded);
        }
        __syncthreads();
        const uint32_t staged_n = hi - lo < ROW_STAGE ? hi - lo : ROW_STAGE;
        for (uint32_t j = threadIdx.x; j < staged_n; j += ROW_THREADS) order[lo + j] = staged[j];
        __syncthreads(); /* cnt, fill and staged again */
    }
}
