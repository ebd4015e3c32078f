/* cuda_bin.cuh: a step's gate and binning: the grid fitted to the step's disks, each disk's slices binned by
 * cell, counted, scanned and placed in cell order.
 * Part of cuda.cu, which includes it after its constants and the files before it (cuda.cu's list). */

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

/* Whether the disks keyed on grid a may be searched on it in a step whose own grid is gr, fitted to the
 * limits lim: its cells at least as wide as the step's speed needs (their number per side no larger),
 * its table no longer than the step's, and, where a keeps only a slab's columns (a GPU rank's, whose
 * strip may have moved or widened since), those columns holding all of lim's, as grid_fit takes them. */
static __device__ bool ahead_fits(const Grid &a, const Grid &gr, const GridLimits &lim)
{
    if (gr.K != 1 || a.g > gr.g || a.ncell > gr.ncell || a.periodic != gr.periodic) return false;
    if (!a.slab) return true;
    if (!lim.slab) return false;
    int64_t span, off = slab_columns(&lim, a.inv_cs, a.g, &span) - a.xoff;
    if (off < 0 && lim.periodic) off += a.g;
    return off >= 0 && off + span <= a.rows - 2;
}

/* ahead: the grid the step's move is to key the disks on for the next step (ahead_slack > 0), in one
 * slice, fitted to ahead_slack times the step's largest speed (its own grid would leave no room for the
 * speed to grow); keyed: the move before did, and the step takes that grid where it fits (ahead_fits),
 * else it bins anew (bin_place_launch). */
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
        if (ahead_fits(*ahead, gr, lim)) gr = *ahead;
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
    info->ties = 0;
    info->outside = 0;
    info->crowded = 0;
    for (int r = 0; r < WMAX * (MAX_ROUNDS + 1); r++) counts[r] = 0;
    info->faster = ctl->vmax > plan_vmax; /* counted when the step commits */
}

/* The last kernel of a step (one warp): the step's state is now the current one (settled: its choice
 * settled the events the only one of both disks first, and counts[0] holds the others). A thread per round
 * and window: one thread's read-add-write chain took 15 us, a twentieth of a step at N = 32000. (Done
 * by the move's last block instead, it cost the gas of 1e7 6%: its 39000 blocks each counted themselves
 * on one address.) */
__global__ void commit_kernel(Control *ctl, const StepInfo *info, const unsigned long long *counts, int settled)
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
        if (settled) { /* a step of one slice: a window */
            ctl->settling[0] += info->found[0];
            ctl->settling[1] += counts[0];
        }
    }
}

/* The cell key of a disk at pos with velocity vel, at the fraction f of the step, in row `row` (info: where
 * a slab's key outside its rows is counted, or NULL). COLUMNS: the grid's cells may be cut into columns
 * (Grid.sx, K > 1); else a grid of one slice, whose keys take none of those fields (the move and the
 * one-slice search, which key every disk of a gas each step). */
template <bool COLUMNS>
static __device__ __forceinline__ uint32_t cell_key(const Grid &gr, real2 pos, real2 vel, double f, int64_t row,
                                                    const StepInfo *info)
{
    double mx = (double)pos.x + (double)vel.x * f, my = (double)pos.y + (double)vel.y * f;
    if (gr.periodic) { /* into [0, L): the cells wrap with the box */
        double L = (double)gr.Lw;
        mx = mx - L * floor(mx / L);
        my = my - L * floor(my / L);
    }
    int64_t gx = COLUMNS ? gr.gx : gr.g;
    int64_t cx = cell_of(mx, COLUMNS ? gr.inv_csx : gr.inv_cs, gx), cy = cell_of(my, gr.inv_cs, gr.g);
    if (gr.slab) { /* column first: the column's place in the slab is the row */
        int64_t col = cx - gr.xoff;
        if (col < 0) col += gr.g;
        if (col >= gr.rows - 1) { /* never (the caller's bounds): counted, and kept in the table */
            if (info) atomicAdd(&((StepInfo *)info)->outside, 1ull);
            col = gr.rows - 2;
        }
        cx = cy, cy = col;
    }
    return (uint32_t)(row * gr.ncell + cy * gx + cx);
}

/* The windows' binning (K > 1) takes BIN_CHUNK entries of a disk a thread, its slices one after another: the
 * disk's state and wall key are loaded once for them, where one entry a thread loaded them for each, and
 * their counts' atomics are issued together. A work item is a disk and a chunk of its level's slices in the
 * window, chunk by chunk over the window's disks (a list's neighbours in neighbouring threads); the entries
 * keep their indices (window_entry). Random scene on one H200: N = 1e6, the binning 3.65 -> 3.41 ms over 10
 * steps, 4.84e8 -> 4.92e8 particle-steps/s; N = 32000, 3.54 -> 3.33 ms over 200 steps; at 8 alike, at 2
 * between. The fused placement (place_kernel's ENTRIES) chunked so was slower: N = 32000, 4.03 -> 4.59 ms
 * (bench/gpu_h100_variants.log 25k). 1: an entry a thread. */
#ifndef BIN_CHUNK
#define BIN_CHUNK 4
#endif

/* The work items of a window's binning (WindowDisks): from ib[l], level l's, nl[l] a chunk of its slices. */
static __device__ __forceinline__ int64_t chunk_items(const WindowDisks &d, uint32_t *ib)
{
    if (d.levels == 1) return d.na * (int64_t)((d.kw + BIN_CHUNK - 1) / BIN_CHUNK);
    ib[0] = 0;
#pragma unroll
    for (int l = 0; l < LEVELS; l++) {
        uint32_t rows = l < d.levels ? (uint32_t)level_rows(d.k0, d.k0 + d.kw, l) : 0;
        ib[l + 1] = ib[l] + d.nl[l] * ((rows + BIN_CHUNK - 1) / BIN_CHUNK);
    }
    return ib[LEVELS];
}

/* Work item u of a window's binning (chunk_items): its disk (slot s, level l, place i in its
 * list of nl), and its entries: slices kl0 to kl0 + BIN_CHUNK - 1 of the level's rows in the window, those
 * below rows, entry base + kl nl + i in row row0 + kl. */
typedef struct {
    int64_t s, i, nl, base;
    int l, kl0, rows, row0;
} ChunkItem;

static __device__ __forceinline__ ChunkItem chunk_item(const WindowDisks &d, const uint32_t *ib, int64_t u)
{
    ChunkItem c;
    c.l = 0, c.base = 0;
    int64_t j;
    if (d.levels == 1) {
        j = (uint32_t)u / (uint32_t)d.na, c.i = u - j * d.na; /* 32 bits: entries below 2^31 */
        c.s = d.act ? d.act[c.i] : c.i;
        c.nl = d.na, c.rows = d.kw, c.row0 = 0;
    } else {
        const ItemLevel v = item_level(d, ib, (uint32_t)u);
        c.l = v.l, c.nl = v.nl, c.base = v.base;
        uint32_t at = (uint32_t)u - v.first;
        j = at / (uint32_t)c.nl, c.i = at - j * c.nl;
        c.s = d.lev[(int64_t)c.l * d.n + c.i];
        c.rows = level_rows(d.k0, d.k0 + d.kw, c.l), c.row0 = level_base(d.k0, d.k0 + d.kw, c.l);
    }
    c.kl0 = (int)j * BIN_CHUNK;
    return c;
}

/* A cell's count raised by `add`, returning the count before. crowded NULL: 32-bit counts, count[key]. Else
 * (narrow_counts) 8-bit counts, four to a word of count: a gas's table of 1.5 cells a disk then takes a
 * quarter of the bytes to clear, count and scan, and stays in L2 while counted. Gas of 1e7 on one H200: the
 * counting 5.84 -> 4.80 ms over 50 steps, the scan 2.39 -> 2.13; 9.53e9-9.55e9 -> 9.78e9-9.79e9
 * particle-steps/s, over 20 steps 9.21e9-9.26e9 -> 9.46e9-9.50e9; dense gas 6.88e9-6.90e9 -> 6.94e9
 * (bench/gpu_h100_variants.log 35a). A cell passing 255 keys carries into the next cell's count of its
 * word; it sets *crowded, and that step is refused (move_kernel) before it writes the state. What reads the
 * table before (the placements, the patches' pieces, the gather, the search) keeps within its arrays
 * whatever the table holds. */
#ifndef NARROW_COUNTS
#define NARROW_COUNTS 1 /* 0: 32-bit cell counts throughout */
#endif
static __device__ __forceinline__ uint32_t count_add(uint32_t *count, uint32_t key, uint32_t add,
                                                     unsigned long long *crowded)
{
    if (!crowded) return atomicAdd(&count[key], add);
    const unsigned shift = (key & 3u) * 8u;
    uint32_t before = (atomicAdd(&count[key >> 2], add << shift) >> shift) & 0xffu;
    if (before + add > 0xffu) *(volatile unsigned long long *)crowded = CROWDED_CELL;
    return before;
}

/* An entry's rank in its cell, kept in rank's words or, where the counts are 8-bit (narrow: count_add's crowded
 * given), in a byte each: the counting writes, and the placement and the search read, 3 bytes an entry fewer.
 * Gas of 1e7 on one H200: the counting 4.71 -> 4.48 ms over 50 steps, the placement 4.91 -> 4.72, 1.01e10 ->
 * 1.02e10 particle-steps/s (bench/gpu_h100_variants.log 38a). A crowded table's ranks lose their high bits; its
 * step is refused, and the readers keep within their arrays whatever the ranks hold (place_kernel,
 * detect_kernel). */
#ifndef RANK8
#define RANK8 1 /* 0: 32-bit ranks throughout */
#endif
static __device__ __forceinline__ void rank_put(uint32_t *rank, int64_t e, uint32_t r, bool narrow)
{
    if (RANK8 && narrow)
        ((uint8_t *)rank)[e] = (uint8_t)r;
    else
        rank[e] = r;
}

static __device__ __forceinline__ uint32_t rank_get(const uint32_t *rank, int64_t e, bool narrow)
{
    return RANK8 && narrow ? (uint32_t)__ldg((const uint8_t *)rank + e) : __ldg(rank + e);
}

template <bool COLUMNS>
static __device__ __forceinline__ void bin_chunk(const DevState &st, const Grid &gr, const WindowDisks &d,
                                                 const uint32_t *ib, int64_t u, const uint64_t *wall_hi,
                                                 uint32_t *keys, uint32_t *rank, uint32_t *count,
                                                 const StepInfo *info, unsigned long long *crowded)
{
    const ChunkItem c = chunk_item(d, ib, u);
    const real2 pos = st.d[c.s].pos, vel = st.d[c.s].vel;
    const int64_t wslice = wall_level_slice(wall_hi[c.s], c.l, gr.K);
    uint32_t key[BIN_CHUNK], r[BIN_CHUNK];
#pragma unroll
    for (int t = 0; t < BIN_CHUNK; t++) {
        int kl = c.kl0 + t;
        int64_t k = level_slice_first(d.k0, c.l, (uint32_t)kl); /* window_entry's k */
        key[t] = KEY_OUT;
        /* no entry in a slice after the wall event's (wall_level_slice) */
        if (kl < c.rows && !(k > 0 && (k >> c.l) > wslice))
            key[t] = cell_key<COLUMNS>(gr, pos, vel, slice_mid(k, c.l, gr.K), c.row0 + kl, info);
    }
#pragma unroll
    for (int t = 0; t < BIN_CHUNK; t++)
        if (key[t] != KEY_OUT && count) r[t] = count_add(count, key[t], 1u, crowded);
#pragma unroll
    for (int t = 0; t < BIN_CHUNK; t++) {
        int kl = c.kl0 + t;
        if (kl >= c.rows) continue;
        int64_t e = c.base + (int64_t)kl * c.nl + c.i;
        keys[e] = key[t];
        if (key[t] != KEY_OUT && count) rank_put(rank, e, r[t], crowded != NULL);
    }
}

/* Entry e of window w (window_entry): a disk in slice k, keyed by the cell of its position at the slice's
 * middle; a disk of level l (disk_level) has an entry for each slice of its level, which starts at a
 * slice k that is a multiple of 2^l.
 * Slices that start after the disk's wall event get no entry (key KEY_OUT, wall_level_slice): disks
 * flying through a wall would otherwise pile up in the border cells. Midpoints are
 * computed in double whatever real is: less rounding for the margin to cover. The rank of an entry
 * within its cell comes from an atomic counter: the order inside a cell changes from run to run, which
 * changes where disks sit in memory and nothing else (every decision compares values). count NULL: the keys
 * alone, which a keyed step's buckets sort (cuda_rows.cuh). */
template <bool WINDOWS, bool LEVELS_LISTED, bool COLUMNS>
__global__ void bin_kernel(DevState st, int64_t n, const Grid *grid, int w, const int32_t *act,
                           const int32_t *lev, const StepInfo *info, const uint64_t *wall_hi, uint32_t *keys,
                           uint32_t *rank, uint32_t *count, int keyed_before, unsigned long long *crowded)
{
    after_previous();
    const Grid gr = *grid;
    if (gr.keyed && keyed_before) return; /* by the move before: count_kernel counts them (a GPU rank's
                                              arrivals and copies, keyed by none, are binned: 0) */
    /* !LEVELS_LISTED: the compiler drops the lists' decoding, !COLUMNS the columns' fields (one-slice
     * steps: 47 registers, 5 blocks a multiprocessor; 53 and 4 with the columns' fields) */
    const WindowDisks d = window_disks<WINDOWS>(grid, w, n, act, LEVELS_LISTED ? lev : NULL, info);
    if constexpr (WINDOWS && BIN_CHUNK > 1) {
        uint32_t ib[LEVELS + 1];
        GRID_LOOP(u, chunk_items(d, ib)) bin_chunk<COLUMNS>(st, gr, d, ib, u, wall_hi, keys, rank, count, info,
                                                                       crowded);
    } else ENTRY_LOOP(WINDOWS, e, window_entries(d)) {
        const WindowEntry x = window_entry(d, e);
        const int64_t s = x.s, k = x.k;
        const int l = x.l;
        real2 vel = st.d[s].vel;
        /* no entry in a slice after the wall event's (wall_level_slice); the wall key as init_kernel keyed
         * it, loaded only where a slice can be after it */
        if (k > 0 && (k >> l) > wall_level_slice(wall_hi[s], l, gr.K)) {
            keys[e] = KEY_OUT;
            continue;
        }
        uint32_t key = cell_key<COLUMNS>(gr, st.d[s].pos, vel, slice_mid(k, l, gr.K), x.row, info);
        keys[e] = key;
        if (count) rank_put(rank, e, count_add(count, key, 1u, crowded), crowded != NULL);
    }
}

/* A disk's partner before the choice: none, and a wall event within the step (PARTNER_WALL) or none (-1).
 * A disk the choice leaves so (or so less two tallies, where a settling marked it: settle_kernel) has had
 * its wall event accepted, if it has one (cuda's move then needs no wall key, move_kernel; the low two
 * bits tell the two apart). Every "taken" test of the choice is partner >= 0. */
#define PARTNER_WALL (-3)
#define PARTNER_TALLY 4 /* a disk's partner lowered by this for each of its events (SETTLE, settle_kernel) */

/* Whether a partner that is no disk says its wall event is pending: PARTNER_WALL, less the search's tallies
 * or a settling's mark, which keep its two low bits (the search's gated wall keys, slot_wall; the move). */
static __device__ __forceinline__ bool wall_pending(int32_t p)
{
    return p < 0 && (p & 3) == (PARTNER_WALL & 3);
}
/* Steps of one slice accept the events that are the only one of both their disks before the grid-wide
 * rounds (settle_kernel), where a disk has fewer than SETTLE_EVENTS events a step on average (Plan.settle):
 * on one H200 the gas of 1e7 (0.14 events a disk, 14% of them contested) 8.84e9 -> 9.38e9 particle-steps/s,
 * its choice 6.82 -> 3.67 ms over 50 steps; the dense gas (0.47, 43% contested) would lose, 6.52e9 -> 6.32e9,
 * its choice 13.05 -> 15.54 ms, so it does not settle (bench/gpu_h100_variants.log 27a). */
#ifndef SETTLE
#define SETTLE 1
#endif
#ifndef SETTLE_EVENTS
#define SETTLE_EVENTS 0.3
#endif
#ifndef WALL_PENDING
#define WALL_PENDING 1 /* 0: -1 for both, and cuda's move loads every disk's wall key (move_load) */
#endif

/* cuda's move writes only what the next step would not find already there (a gas's move: 104 -> 88-90 DRAM
 * bytes a disk):
 * - a wall key only where the disk has a wall event within the next step (most disks of a large box have
 *   none). That step's readers tell a kept key from an older one by the partner the move starts,
 *   PARTNER_WALL or -1 (slot_init; the search's tallies keep its two low bits), and its choice restarts a
 *   live disk's best key from NO_EVENT rather than its wall key: the search keeps only pair events before
 *   both disks' wall events, so a wall key is never the smallest key of a disk with an event;
 * - a partner only where it changes (before: the one the move loaded), as most disks' -1 does not;
 * - after a step that settled (Plan.settle; SKIP_BEST), whose partners mark every disk that had an event
 *   (settle_kernel), no best key where the partner is -1: no wall event and no pair event, so the key is
 *   still the NO_EVENT it was started with.
 * Gas of 1e7 on one H200: 9.84e9 -> 1.006e10 particle-steps/s, the move 14.87 -> 13.88 ms over 50 steps;
 * dense gas 6.97e9 -> 7.10e9 (bench/gpu_h100_variants.log 37b, 37c); the best keys: the move 13.93 -> 13.72
 * ms (37d). No wall keys at all, the search computing a found pair's from the states, lost more in the
 * search than the move gained (37a). 0: every key and partner written, every wall key read. */
#ifndef GATED_WALLS
#define GATED_WALLS 1
#endif
static_assert(WALL_PENDING || !GATED_WALLS, "GATED_WALLS: a disk with a wall event is told by its partner");
#ifndef SKIP_BEST
#define SKIP_BEST 1 /* 0: the best keys written after settled steps too (GATED_WALLS' last part) */
#endif

/* Per-disk start of the choice: its wall event is its best event so far, and it has none accepted. best_lo
 * NULL: the search starts the second keys of the disks it finds events of (LO_AT_EVENT, Entries). gated:
 * the wall key written only where there is one, the partner where it is not already before, the best key
 * where it is not already NO_EVENT (marked: before is a settled step's partner; GATED_WALLS). */
static __device__ __forceinline__ void slot_init(int64_t s, uint64_t w, uint64_t *wall_hi, uint64_t *best_hi,
                                                 uint64_t *best_lo, int32_t *partner, bool gated = false,
                                                 int32_t before = 0, bool marked = false)
{
    if (!gated || w != NO_EVENT) wall_hi[s] = w;
    if (!(gated && marked && before == -1 && w == NO_EVENT)) best_hi[s] = w;
    if (best_lo) best_lo[s] = NO_EVENT;
    int32_t p = WALL_PENDING && w != NO_EVENT ? PARTNER_WALL : -1;
    if (!gated || p != before) partner[s] = p;
}

/* K = 1 (cuda's step, not a GPU rank's): a batch's first step gathers the disks in patches of PATCH_W x
 * PATCH_H cells rather than in the cell table's rows across the box: each patch row by row, the bands of
 * PATCH_H rows one after another and the patches of a band from left to right. A block of the search's
 * probes then covers a few rows of a patch, and finds most of its candidates in the row below among its own
 * probes (test_pair), not among another block's; the choice and the move meet partners in nearby slots.
 * Bands, not whole columns: a wave of blocks across every row scattered the counting's atomics and the
 * move's accesses over all of L2. Gas of 1e7 on one H200 9.40e9 -> 9.45e9 particle-steps/s, dense gas
 * 6.52e9 -> 6.72e9: over 50 steps the search 21.36 -> 20.78 ms (dense 33.25 -> 31.88), the choice's rounds
 * 3.67 -> 3.40 (13.03 -> 12.10), the placement 5.70 -> 6.31 (bench/gpu_h100_variants.log 27f to 27h).
 * 0: the rows' order. */
#ifndef PATCH_W
#define PATCH_W 32
#endif
#ifndef PATCH_H
#define PATCH_H 64
#endif
#define PATCH_COLS (PATCH_W > 0 ? PATCH_W : 1) /* for the arithmetic, where PATCH_W is 0 */

/* The patches across a grid of g cells a side (the last one narrower where PATCH_W does not divide g). */
static __host__ __device__ __forceinline__ int64_t patches_across(int64_t g)
{
    return (g + PATCH_COLS - 1) / PATCH_COLS;
}

/* The patches' pieces of a grid of g cells a side (patch_count_kernel): PATCH_H a patch, in bands of PATCH_H rows. */
static __host__ __device__ __forceinline__ int64_t patch_pieces(int64_t g)
{
    return (g + PATCH_H - 1) / PATCH_H * PATCH_H * patches_across(g);
}

/* The patches' pieces: piece j, row j % PATCH_H of patch j / PATCH_H, holds the entries of that row's cells
 * in the patch; their exclusive sum (patch_at) is where each begins in the gathered order. */
static __device__ __forceinline__ int64_t patch_piece(int64_t g, int64_t y, int64_t x0)
{
    return (y / PATCH_H * patches_across(g) + x0 / PATCH_COLS) * PATCH_H + y % PATCH_H;
}

/* The entries of each piece, from the cell table. len: a bound of the plan's (patch_pieces); pieces past the
 * grid's hold none. */
__global__ void patch_count_kernel(const Grid *grid, const uint32_t *start, int64_t len, uint32_t *pieces)
{
    after_previous();
    int64_t j = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (j >= len) return;
    /* patch_piece's inverse */
    int64_t g = grid->g, across = patches_across(g), patch = j / PATCH_H, band = patch / across;
    int64_t y = band * PATCH_H + (j - patch * PATCH_H);
    int64_t x0 = (patch - band * across) * PATCH_COLS, x1 = x0 + PATCH_COLS < g ? x0 + PATCH_COLS : g;
    /* after a refusal the table is empty: every start 0 (the gather writes nothing) */
    pieces[j] = y < g && grid->cells > 0 ? start[y * g + x1] - start[y * g + x0] : 0;
}

/* K = 1: the disks move into cell order (slot p takes the disk of sorted entry p), with coalesced writes.
 * (Scattering them straight from slot order, saving the entry order, measured 1.5x slower.)
 * Or in patches, where the placement wrote order so (place_patches_kernel).
 * where: a GPU rank's (mpi_cuda.cu), where each slot its halo sent went (their ids marked with ID_SENT,
 * cleared here) and each slot from where_from up (its copies): those alone, a write a disk costing 4% of
 * the gather. */
#define ID_SENT 0x80000000u /* disk indices are below 2^31 (SIM_MAX_N) */
__global__ void gather_state_kernel(DevState in, DevState out, const uint32_t *order, int64_t n, Params par,
                                    uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo, int32_t *partner,
                                    const Control *ctl, uint32_t *where, int64_t where_from)
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
    Disk disk = in.d[s];
    int32_t id = in.id[s];
    if (refused(ctl)) return;
    out.d[p] = disk;
    real2 pos = disk.pos, vel = disk.vel;
    bool sent = ((uint32_t)id & ID_SENT) != 0;
    out.id[p] = (int32_t)((uint32_t)id & ~ID_SENT);
    slot_init(p, wall_key(pos.x, pos.y, vel.x, vel.y, par), wall_hi, best_hi, best_lo, partner);
    if (where && (sent || s >= where_from)) where[s] = (uint32_t)p;
}

/* A step whose gate took the keys the move before it gave (MoveBin): their ranks in their cells, a
 * thread a key. The keys lie nearly in cell order (the disks were gathered so a few steps before), so
 * neighbouring lanes often share a cell: each run of equal keys in a warp takes its ranks with one atomic,
 * its first lane's. With 8-bit counts (crowded given, count_add) a run is one of equal count words, four
 * cells: its first lane adds each cell's lanes in their bytes of the word at once, and a lane's rank is its
 * cell's byte before plus its cell's lanes before it in the run (cells of the same word are the same cell
 * where their low two bits agree). In a gas of about 1.5 cells a disk most lanes have a cell of their own, and
 * a word's four cells hold about 2.7 disks: the warp takes about a third of the atomics. Gas of 1e7 on one H200: the
 * counting 4.49 -> 4.25 ms over 50 steps, 1.020e10 -> 1.024e10 particle-steps/s (bench/gpu_h100_variants.log
 * 38b). */
#ifndef COUNT_WORDS
#define COUNT_WORDS 1 /* 0: a run of equal keys takes an atomic, with 8-bit counts too */
#endif
__global__ void count_kernel(const Grid *grid, int64_t n, const uint32_t *keys, uint32_t *rank, uint32_t *count,
                             unsigned long long *crowded)
{
    after_previous();
    if (!grid->keyed) return;
    int64_t e = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    /* the lanes with a key, 0 to some last one: taken with every lane present (a launch of whole warps),
     * as __activemask would not promise */
    unsigned live = __ballot_sync(0xffffffffu, e < n), lane = threadIdx.x & 31;
    if (e >= n) return;
    const bool words = COUNT_WORDS && crowded;
    uint32_t key = keys[e], unit = words ? key >> 2 : key, before = __shfl_up_sync(live, unit, 1);
    unsigned heads = __ballot_sync(live, lane == 0 || before != unit); /* the lanes that begin a run */
    unsigned upto = 0xffffffffu >> (31 - lane), later = heads & ~upto;
    unsigned head = 31 - __clz(heads & upto), next = later ? __ffs(later) - 1 : 32 - __clz(live);
    uint32_t base = 0;
    if (!words) {
        if (head == lane) base = count_add(count, key, next - lane, crowded);
        rank_put(rank, e, __shfl_sync(live, base, head) + (lane - head), crowded != NULL);
        return;
    }
    const unsigned run = (next < 32 ? (1u << next) - 1 : 0xffffffffu) & ~((1u << head) - 1), byte = key & 3u;
    unsigned cell[4];
#pragma unroll
    for (unsigned b = 0; b < 4; b++) cell[b] = __ballot_sync(live, byte == b) & run; /* the run's lanes by cell */
    if (head == lane) {
        uint32_t add = 0;
#pragma unroll
        for (unsigned b = 0; b < 4; b++) add |= (uint32_t)__popc(cell[b]) << (8 * b);
        base = atomicAdd(&count[unit], add);
#pragma unroll
        for (unsigned b = 0; b < 4; b++) /* a cell past 255 carries into the next: the step is refused */
            if (((base >> (8 * b)) & 0xffu) + (uint32_t)__popc(cell[b]) > 0xffu)
                *(volatile unsigned long long *)crowded = CROWDED_CELL;
    }
    const unsigned mine = byte == 0 ? cell[0] : byte == 1 ? cell[1] : byte == 2 ? cell[2] : cell[3];
    base = __shfl_sync(live, base, head);
    rank_put(rank, e, ((base >> (8 * byte)) & 0xffu) + (uint32_t)__popc(mine & ((1u << lane) - 1)), true);
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

/* What the pair search reads of the disks: their state and wall keys (disk to wall), and where K > 1 one
 * entry a disk and slice in cell order, its slot, key and mid, so that the screens read neighbours
 * contiguously (the few pairs they pass read the state through the slot). */
typedef struct {
    Disk *disk;
    int32_t *id, *slot; /* slot: K = 1, each place's slot (the disks in their slots, or a gathering step's
                           new slots in patches: en.patches); else NULL */
    uint64_t *wall;
    const int32_t *wall_gate; /* steps in the slots (cuda's, a GPU rank's): the partners, by which a slot's wall
                                 key is read only where the move kept it (GATED_WALLS); else NULL */
    float4 *mid; /* K > 1: the disk at its level slice's middle, and its velocity (near_path); else NULL */
    const uint32_t *rank; /* K = 1 with the disks in their slots (slot != NULL): each slot's place in its cell */
    int rank8;            /* and those ranks are 8-bit (rank_get) */
    const uint32_t *patches; /* K = 1, a gathering step in patches (PATCH_W): where each piece begins in the
                                slots (patch_at), from which a slot's place comes (patch_shift); else NULL */
    uint64_t *best_lo;    /* cuda's steps of one slice: the choice's second keys, started for each event's disks
                             here (the move leaves them, MoveBin); else NULL */
    int32_t *tally;       /* SETTLE: the disks' partners, each event's two lowered by PARTNER_TALLY (settle_kernel);
                             best_lo is then started by the settling, for the contested events' disks alone */
    uint2 *placed; /* K > 1: each entry's slot and cell key side by side, which the placement scatters in one
                      store where two arrays took two (random scene on one H200, N = 32000: the placement 4.00 ->
                      3.15 ms over 200 steps, 2.54e8 -> 2.63e8 particle-steps/s; at 1e6, 3.03 -> 2.46 ms over
                      10, 5.05e8 -> 5.22e8; bench/gpu_h100_variants.log 29a); else NULL */
    unsigned int *ties; /* LO_IF_TIED: StepInfo.ties, raised where a first key the search lowers was already the
                           event's; else NULL (the search's minima then return nothing) */
} Entries;

/* The entries of window w's cells (window_rows rows of ncell cells), once placed. */
static __device__ __forceinline__ uint32_t window_end(const Grid *grid, int w, const uint32_t *start)
{
    return start[(int64_t)window_rows(grid->wb[w], grid->wb[w + 1], grid->levels) * grid->ncell];
}

/* Entry p of the cell order (K > 1): its disk's slot and cell key, and its midpoint in its slice as
 * bin_kernel computes it, with its velocity. */
static __device__ __forceinline__ void put_entry(const DevState &st, const Entries &en, int64_t p, const WindowEntry &x,
                                                 int K, uint32_t key)
{
    real2 pos = st.d[x.s].pos, vel = st.d[x.s].vel;
    en.placed[p] = make_uint2((uint32_t)x.s, key);
    double f = slice_mid(x.k, x.l, K);
    en.mid[p] = make_float4((float)((double)pos.x + (double)vel.x * f), (float)((double)pos.y + (double)vel.y * f),
                            (float)vel.x, (float)vel.y);
}

/* K > 1: the disks stay in place; entry p of the cell order, placed as its entry's index and key, gets its
 * disk's slot in place of the index, and its midpoint. */
__global__ void gather_entries_kernel(DevState st, int64_t n, int w, const int32_t *act, const int32_t *lev,
                                      const StepInfo *info, const uint32_t *start, const Grid *grid, Entries en)
{
    after_previous();
    const WindowDisks d = window_disks<true>(grid, w, n, act, lev, info);
    const int K = grid->K;
    GRID_LOOP(p, (int64_t)window_end(grid, w, start)) {
        const uint2 e = en.placed[p];
        put_entry(st, en, p, window_entry(d, e.x), K, e.y);
    }
}

/* A gathering step in patches (PATCH_W): how far the disks of cell `key` move from their places in the
 * cell order to their slots, the same for every disk of the cell's piece (x0 to x0 + PATCH_W - 1 of its row
 * y): where the piece begins in the patches (patch_at) less where its first cell begins (start). A disk at
 * place p goes to slot p + shift (place_patches_kernel); the disk in slot t came from place t - shift (the
 * search's probe, detect_kernel). */
static __device__ __forceinline__ int64_t patch_shift(int64_t g, uint32_t key, const uint32_t *start,
                                                    const uint32_t *patch_at)
{
    int64_t y = key / g, x0 = key - y * g;
    x0 -= x0 % PATCH_COLS;
    return (int64_t)__ldg(&patch_at[patch_piece(g, y, x0)]) - (int64_t)__ldg(&start[y * g + x0]);
}

/* The placement of a gathering step in patches: the disk of slot e, at place p of the cell order, goes to
 * slot p + patch_shift (order[that slot] = e, for gather_state_kernel), and slot_of[p] is that slot (the search's
 * Entries.slot, as the keyed steps' order). Both scattered, where the rows' placement scatters one: the
 * gather after it then writes in order. (The gather writing each disk to its patch slot itself took 436
 * against 293 us a batch: bench/gpu_h100_variants.log 27g.) After a refusal the grid is empty, and
 * nothing is written. */
__global__ void place_patches_kernel(const Grid *grid, int64_t n, const uint32_t *keys, const uint32_t *rank,
                                   const uint32_t *start, const uint32_t *patch_at, uint32_t *order,
                                   uint32_t *slot_of, int rank8)
{
    after_previous();
    int64_t e = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (e >= n || grid->cells == 0) return;
    uint32_t key = keys[e];
    int64_t p = (int64_t)start[key] + rank_get(rank, e, rank8);
    int64_t to = p + patch_shift(grid->g, key, start, patch_at);
    if ((uint64_t)p >= (uint64_t)n || (uint64_t)to >= (uint64_t)n) return; /* a crowded table's (count_add) */
    order[to] = (uint32_t)e;
    slot_of[p] = (uint32_t)to;
}

/* Where each entry goes in cell order (start[] is the exclusive sum of the counts). Only the 4-byte
 * entry index is scattered (in steps of one slice, to order[]; else with its key, one 8-byte store to
 * en.placed: the search keys each probe by it); the disks, or the entries' slots and midpoints, are then
 * gathered with coalesced writes (gather_state_kernel, gather_entries_kernel). ENTRIES (K > 1 below
 * PLACE_FUSED_N disks, cuda_launch.cuh's place_fused): the gather of the entries (gather_entries_kernel) done here
 * too, each entry's slot, key and midpoint scattered to its place, the disk read in entry order (a
 * level list's order) rather than in cell order: a kernel and a pass over the entries fewer, the midpoints'
 * 16 bytes an entry scattered. */
template <bool WINDOWS, bool LEVELS_LISTED, bool ENTRIES>
__global__ void place_kernel(DevState st, const Grid *grid, int w, int64_t n, const int32_t *act, const int32_t *lev,
                             const StepInfo *info, const uint32_t *keys, const uint32_t *rank, const uint32_t *start,
                             uint32_t *order, Entries en, int rank8)
{
    after_previous();
    const WindowDisks d = window_disks<WINDOWS>(grid, w, n, ENTRIES ? act : NULL, LEVELS_LISTED ? lev : NULL, info);
    const int K = ENTRIES ? grid->K : 0; /* once: the loop's stores may alias grid for all the compiler knows */
    ENTRY_LOOP(WINDOWS, e, window_entries(d)) {
        uint32_t key = keys[e];
        if (key == KEY_OUT) continue;
        int64_t p = (int64_t)start[key] + rank_get(rank, e, rank8);
        if (ENTRIES)
            put_entry(st, en, p, window_entry(d, e), K, key);
        else if (en.placed)
            en.placed[p] = make_uint2((uint32_t)e, key);
        else if (p < n) /* else a crowded table's (count_add) */
            order[p] = (uint32_t)e;
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
        real2 pos = st.d[s].pos, vel = st.d[s].vel;
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
