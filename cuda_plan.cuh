/* cuda_plan.cuh: the host's plan of a batch of steps (slices, grid, windows, rounds) and the buffers it
 * needs, grown between batches.
 * Part of cuda.cu, which includes it after its host-side types and the files before it (cuda.cu's
 * list). */

/* What the host decides for a batch of steps, from the largest speed it last read back: the most slices
 * and the finest grid the steps may use (the launch sizes and the cells cleared and scanned), and the
 * windows. Each step's gate fits the grid to its own disks within that. */
typedef struct {
    unsigned long long vmax; /* bits of the speed planned for */
    int K;        /* slices at most */
    int64_t gcap; /* cells per side at most */
    int gsx;      /* and the columns of each (Grid.sx) */
    int F, W;      /* windows (window_start): the first F slices long (0: one window) */
    int levels;    /* speed levels (disk_level) */
    int64_t wcells[WMAX]; /* per window: the cells it clears and scans, its rows at most x gcap^2 */
    int64_t went[WMAX];   /* and its entries at most: n x its slices */
    int rounds[WMAX];     /* grid-wide rounds of each window's choice before the one-block finish */
    int64_t choose_blocks[WMAX]; /* blocks of its grid-wide rounds: for the pair events last found */
    bool settle; /* steps of one slice: the choice settles the uncontested events first (settle_kernel) */
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
 * each round (both as the last batch had them). The one block that finishes the choice first compacts
 * the last round's whole list, then takes rounds over what that round left: its time grows with both (a
 * dense scene of 1e6 disks leaves it millions after two rounds: 17 ms a step). So enough rounds that
 * the list is at most FINISH_LIST events and about FINISH_EVENTS are left, and no more (each round costs
 * four launches, about 10 us). */
static int rounds_for(double found, double decay)
{
    if (!(decay < 1)) return MAX_ROUNDS;
    int r = 2; /* at least two, or the next batch's decay would not be known */
    for (double list = found * decay; r < MAX_ROUNDS && (list > FINISH_LIST || list * decay > FINISH_EVENTS); r++)
        list *= decay;
    return r;
}

/* Blocks of a grid-wide round's passes over a list of `found` pair events (INFINITY: a length not yet
 * known): the passes loop over the list's length on the device, so fewer blocks only take more turns. */
static int64_t choose_blocks_for(const Cuda *c, double found)
{
    double b = (2 * found + 4096) / THREADS, most = 8.0 * c->sms;
    return b < most ? (int64_t)b : (int64_t)most;
}

/* Whether a step of one slice settles the lone events first (settle_kernel): where the step before found fewer
 * than c->settle_events events a disk (`found` pair events, each two disks', over n disks); cuda's plans and a
 * GPU rank's steps (mpi_cuda.cu) alike. */
static bool settles(const Cuda *c, double found, double n)
{
    return SETTLE && 2 * found < c->settle_events * n;
}

static Plan plan_for(const Cuda *c, double vmax, const int *rounds, const double *found, int F)
{
    Plan pl;
    pl.vmax = speed_bits(vmax);
    /* room for the disks to speed up by SLICE_SLACK, or slow down by SPEED_SLACK, before the grid is
     * coarser than it could be (extra slices cost only threads that return at once) */
    pl.K = grid_slices(&c->lim, vmax * SLICE_SLACK);
    Grid most = grid_fit(&c->lim, vmax / SPEED_SLACK, pl.K, INT64_MAX);
    pl.gcap = most.g, pl.gsx = most.sx;
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
            pl.wcells[w] = (int64_t)rows * pl.gcap * pl.gcap * pl.gsx;
            most = pl.wcells[w] > most ? pl.wcells[w] : most;
        }
        if (most <= c->lim.cell_cap || pl.levels == 1) break;
        pl.levels--;
    }
    for (int w = 0; w < pl.W; w++) {
        int kw = window_start(w + 1, pl.F, pl.W, pl.K) - window_start(w, pl.F, pl.W, pl.K);
        pl.went[w] = c->n * kw;
        pl.rounds[w] = rounds[w];
        pl.choose_blocks[w] = choose_blocks_for(c, found[w]);
    }
    /* settling pays where few events are contested: about 1 - exp(-e) of them, where e = 2 found / n is
     * a disk's events in a step (0.14 of 0.14 in the gas of 1e7, 0.43 of 0.47 in the dense gas) */
    pl.settle = LO_AT_EVENT && pl.K == 1 && settles(c, found[0], (double)c->n);
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
    return entries <= c->entry_cap && cells <= c->cell_held && copies <= c->copy_cap && c->n <= c->order_cap &&
           (pl->K == 1 || c->slices_held);
}

/* Grows the buffers to what the plan's steps may take (the first time exactly for steps of one slice,
 * SLICES_AHEAD beyond for several; later GROWTH beyond; within cuda_open's limits), with no step in
 * flight: the kernels of every batch launched so far are done with them. The cell table
 * comes back cleared, as the short scans keep it. A run's buffers thereby follow its scene: a gas takes
 * one entry and at most CELLS_PER_DISK cells a disk, a fast scene as many as its slices need. */
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
            cudaFree(c->keys), cudaFree(c->rank);
            c->keys = (uint32_t *)dev_alloc((size_t)e * 4, "the cell keys");
            c->rank = (uint32_t *)dev_alloc((size_t)e * 4, "the cell keys");
            c->entry_cap = e;
        }
        if (copies > c->copy_cap) {
            cudaFree(c->en.placed), cudaFree(c->en.mid);
            size_t ne = (size_t)e;
            c->en.placed = (uint2 *)dev_alloc(ne * sizeof(uint2), "the entry copies");
            c->en.mid = (float4 *)dev_alloc(ne * sizeof(float4), "the entry copies");
            c->copy_cap = e;
        }
    }
    if (n > c->order_cap) { /* a step of one slice's places: n (mpi_cuda: its slots, grown as they are) */
        cudaFree(c->slot_of), cudaFree(c->order);
        c->slot_of = (uint32_t *)dev_alloc((size_t)n * 4, "the cell keys");
        c->order = (uint32_t *)dev_alloc((size_t)n * 4, "the cell keys");
        /* slots all: a step refused for a crowded cell (count_add) may leave places unwritten */
        CUDA_CHECK(cudaMemsetAsync(c->slot_of, 0, (size_t)n * 4, c->stream));
        CUDA_CHECK(cudaMemsetAsync(c->order, 0, (size_t)n * 4, c->stream));
        c->order_cap = n;
    }
    if (cells > c->cell_held) {
        double ahead = c->cell_held ? GROWTH : pl->K > 1 ? SLICES_AHEAD : 1;
        int64_t nc = (int64_t)((double)cells * ahead);
        nc = nc < most_cells ? nc : most_cells;
        nc = nc > cells ? nc : cells;
        cudaFree(c->count), cudaFree(c->start), cudaFree(c->scan_tmp);
        c->count = (uint32_t *)dev_alloc((size_t)nc * 4, "the cell table");
        c->start = (uint32_t *)dev_alloc((size_t)nc * 4, "the cell table");
        int64_t scanned = nc;
        if (PATCH_W > 0) { /* the pieces of any grid these cells hold: g^2 <= nc cells a window */
            cudaFree(c->pieces), cudaFree(c->patch_at);
            c->patch_cap = patch_pieces((int64_t)sqrt((double)nc));
            c->pieces = (uint32_t *)dev_alloc((size_t)c->patch_cap * 4, "the cell table");
            c->patch_at = (uint32_t *)dev_alloc((size_t)c->patch_cap * 4, "the cell table");
            scanned = c->patch_cap > nc ? c->patch_cap : nc; /* cub's scratch for either sum */
        }
        /* rows_sort's buckets over any grid these cells hold, their counts cleared as bucket_scan_kernel
         * leaves them, and their rooms */
        cudaFree(c->bcount), cudaFree(c->bstart);
        c->bucket_cap = row_buckets((int64_t)sqrt((double)nc) + 1) + 1;
        c->bcount = (uint32_t *)dev_alloc((size_t)c->bucket_cap * 4, "the cell table");
        c->bstart = (uint32_t *)dev_alloc((size_t)c->bucket_cap * 4, "the cell table");
        CUDA_CHECK(cudaMemsetAsync(c->bcount, 0, (size_t)c->bucket_cap * 4, c->stream));
        cudaFree(c->bucket);
        c->bucket = NULL, c->bucket_total = 0;
        if (ROW_SORT && c->rows != 0 && pl->K == 1) { /* a run whose keyed steps may sort so (rows_sort) */
            c->bucket_total = ROW_ROOM(n, c->bucket_cap);
            c->bucket = (uint32_t *)dev_alloc((size_t)c->bucket_total * 4, "the cell table");
        }
        c->scan_tmp_bytes = 0;
        CUDA_CHECK(cub::DeviceScan::ExclusiveSum(NULL, c->scan_tmp_bytes, c->count, c->start, scanned, c->stream));
        size_t narrow_bytes = 0; /* the scan of 8-bit counts (narrow_counts) */
        CUDA_CHECK(cub::DeviceScan::ExclusiveScan(NULL, narrow_bytes, (const uint8_t *)c->count, c->start,
                                                  cuda::std::plus<uint32_t>(), (uint32_t)0, nc, c->stream));
        c->scan_tmp_bytes = narrow_bytes > c->scan_tmp_bytes ? narrow_bytes : c->scan_tmp_bytes;
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
