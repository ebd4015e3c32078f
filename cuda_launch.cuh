/* cuda_launch.cuh: the host's launches: a step's kernels, phase by phase, and a batch of steps as one CUDA graph.
 * Part of cuda.cu, which includes it after its host-side types and the files before it (cuda.cu's
 * list). */

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

/* The choice among window w's pair events (wall: the wall events as it sees them); a plan that settles
 * (steps of one slice alone) settles them first. ties: the search's tie flag (LO_IF_TIED), which lets the first
 * round skip the second keys, or NULL. */
static void choose_launch(Cuda *c, const Plan *pl, int w, const uint64_t *wall, int ring, const unsigned int *ties)
{
    phase_mark(c, ring, w, 4);
    int64_t blocks = pl->choose_blocks[w];
    const unsigned long long *found = &c->info->found[w];
    unsigned long long *counts = c->counts + w * (MAX_ROUNDS + 1);
    int list = 0;
    const unsigned long long *len = found;
    if (pl->settle) { /* the contested events into the other list, counted in counts[0] */
        step_kernel(c, blocks, THREADS, 0, settle_kernel, c->ev[0], found, c->ev_cap, c->ev[1], &counts[0],
                    c->partner, c->best_lo);
        list = 1;
        len = &counts[0];
    }
    step_kernel(c, blocks, THREADS, 0, min_lo_kernel, c->ev[list], len, c->ev_cap, c->best_hi, c->best_lo, ties);
    step_kernel(c, blocks, THREADS, 0, accept_kernel, c->ev[list], len, c->ev_cap, c->best_hi, c->best_lo,
                c->partner, ties);
    for (int r = 1; r < pl->rounds[w]; r++) {
        step_kernel(c, blocks, THREADS, 0, compact_kernel, c->ev[list], len, c->ev_cap, c->ev[1 - list],
                    &counts[r], c->partner, wall, c->best_hi, c->best_lo);
        list = 1 - list;
        len = &counts[r];
        step_kernel(c, blocks, THREADS, 0, min_hi_kernel, c->ev[list], len, c->ev_cap, c->best_hi);
        step_kernel(c, blocks, THREADS, 0, min_lo_kernel, c->ev[list], len, c->ev_cap, c->best_hi, c->best_lo,
                    (const unsigned int *)NULL);
        step_kernel(c, blocks, THREADS, 0, accept_kernel, c->ev[list], len, c->ev_cap, c->best_hi, c->best_lo,
                    c->partner, (const unsigned int *)NULL);
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

/* Whether window w's table counts in 8 bits (count_add): a step of one slice whose table cub scans, in cuda's
 * run (or a GPU rank's) until a cell passes 255 disks (Cuda.narrow). */
static bool narrow_counts(const Cuda *c, const Plan *pl, int w)
{
    return c->narrow && pl->K == 1 && !scan_short(c, pl->wcells[w] + 1);
}

/* Where window w's table counts in 8 bits, the flag count_add raises for a cell past 255 disks (the binning's
 * crowded); else NULL, 32-bit counts. cuda's steps and a GPU rank's. */
static unsigned long long *crowded_flag(const Cuda *c, const Plan *pl, int w)
{
    return narrow_counts(c, pl, w) ? &c->info->crowded : NULL;
}

/* The cell counts of window w's table cleared where the last scan left them (the short scans clear the
 * counts behind them; after cub's, they are cleared before binning); returns whether the table is
 * scanned by the two short kernels. */
static bool bin_clear(Cuda *c, const Plan *pl, int w)
{
    int64_t len = pl->wcells[w] + 1, words = narrow_counts(c, pl, w) ? (len + 3) / 4 : len;
    bool short_scan = scan_short(c, len);
    c->scans[short_scan]++;
    if (!short_scan || c->dirty > 0) {
        int64_t clear = words > c->dirty ? words : c->dirty;
        CUDA_CHECK(cudaMemsetAsync(c->count, 0, (size_t)clear * sizeof(uint32_t), c->stream));
        c->dirty = 0;
    }
    return short_scan;
}

/* Whether steps of several slices place each entry's slot and midpoint with its key (place_kernel's ENTRIES)
 * rather than gather them in cell order after (gather_entries_kernel): a kernel fewer, their 20 bytes
 * scattered instead of written in order. The scatter pays while the entries are few: random scene on one
 * H200, N = 32000, 1e5 and 3e5 2 to 3% faster, but 1e6 1% and 4e6 11% slower, its placement 19.3 -> 30.4
 * ms over 10 steps (bench/gpu_h100_variants.log 24a, 24c). */
static bool place_fused(const Cuda *c)
{
    return c->n < c->fused_n;
}

/* Window w's binned entries placed in cell order: the exclusive sum of the counts (short_scan: by the
 * two short kernels, bin_clear), then each entry's place (and where place_fused, its disk's slot and
 * midpoint, from state buffer in). in_patches: a gathering step of one slice in patches (PATCH_W), whose
 * placement also gives each disk its slot in them (place_patches_kernel). */
template <bool WINDOWS>
static void scan_place_launch(Cuda *c, const Plan *pl, int w, const int32_t *act, const int32_t *lev, int ring,
                              bool short_scan, int in, bool in_patches = false)
{
    int64_t blocks = window_blocks(c, pl, w), len = pl->wcells[w] + 1, tiles = (len + SCAN_TILE - 1) / SCAN_TILE;
    if (short_scan) {
        step_kernel(c, tiles, THREADS, 0, tile_sum_kernel, c->count, len, c->tile_sums);
        step_kernel(c, tiles, THREADS, 0, tile_scan_kernel, c->count, len, c->tile_sums, c->start);
    } else if (narrow_counts(c, pl, w)) {
        CUDA_CHECK(cub::DeviceScan::ExclusiveScan(c->scan_tmp, c->scan_tmp_bytes, (const uint8_t *)c->count,
                                                  c->start, cuda::std::plus<uint32_t>(), (uint32_t)0, len,
                                                  c->stream));
        c->dirty = (len + 3) / 4;
    } else {
        CUDA_CHECK(cub::DeviceScan::ExclusiveSum(c->scan_tmp, c->scan_tmp_bytes, c->count, c->start, len,
                                                 c->stream));
        c->dirty = len;
    }
    phase_mark(c, ring, w, 2);
    if (in_patches) {
        int64_t pieces = patch_pieces(pl->gcap); /* the step's grid has at most the plan's cells a side */
        step_kernel(c, blocks_for(pieces), THREADS, 0, patch_count_kernel, c->grid, c->start, pieces, c->pieces);
        CUDA_CHECK(cub::DeviceScan::ExclusiveSum(c->scan_tmp, c->scan_tmp_bytes, c->pieces, c->patch_at, pieces,
                                                 c->stream));
        step_kernel(c, blocks_for(c->n), THREADS, 0, place_patches_kernel, c->grid, c->n, c->keys, c->rank, c->start,
                    c->patch_at, c->order, c->slot_of, (int)narrow_counts(c, pl, w));
        return;
    }
    Entries en = c->en;
    if (!act) en.placed = NULL; /* act: NULL in steps of one slice alone, which place to c->order */
    bool fused = act && place_fused(c);
    auto place = fused ? (lev ? place_kernel<WINDOWS, true, true> : place_kernel<WINDOWS, false, true>)
                       : (lev ? place_kernel<WINDOWS, true, false> : place_kernel<WINDOWS, false, false>);
    step_kernel(c, blocks, THREADS, 0, place, c->st[in], c->grid, w, c->n, act, lev, c->info, c->keys, c->rank,
                c->start, c->order, en, (int)narrow_counts(c, pl, w));
}

/* Whether a keyed step's table is sorted in buckets (cuda_rows.cuh) rather than counted cell by cell: the
 * tables cub would scan (SIM_CUDA_ROWS: 0 never, 1 every keyed step; the tests take each way). */
static bool rows_sort(const Cuda *c, const Plan *pl)
{
    if (!ROW_SORT || c->rows == 0 || !c->bucket) return false; /* buffers_grow: a plan of one slice's */
    return c->rows == 1 || !scan_short(c, pl->wcells[0] + 1);
}

/* A keyed step's table in buckets (rows_sort), once its keys are there (the move's, or binned anew where the
 * step's cells are finer, counting nothing: bin_place_launch): each slot into its bucket, the buckets scanned,
 * and sorted a bucket a block. */
static void rows_launch(Cuda *c, const Plan *pl, int ring)
{
    c->scans[2]++;
    step_kernel(c, blocks_for(bucket_slots(c->n)), THREADS, 0, bucket_fill_kernel, c->grid, c->n, c->keys,
                c->bcount, c->bucket, c->bucket_total, c->info);
    phase_mark(c, ring, 0, 1);
    step_kernel(c, 1, ROW_SCAN, 0, bucket_scan_kernel, c->grid, c->bcount, c->bstart, c->start, c->bucket_total);
    phase_mark(c, ring, 0, 2);
    step_kernel(c, row_buckets(pl->gcap), ROW_THREADS, 0, bucket_sort_kernel, c->grid, c->keys, c->bstart,
                c->bucket, c->bucket_total, c->start, c->order, c->rank, crowded_flag(c, pl, 0));
}

/* Window w's entries binned and placed in cell order (WINDOWS false: a step of one window). keyed: the
 * move before keyed the disks (step_launch), and the gate took those keys, which are then counted here (or
 * sorted in buckets, rows_launch), or bins anew where their cells are too fine for the step's speed. The
 * binning that returns at once where the keys are taken loops over its entries: few blocks to start. */
template <bool WINDOWS>
static void bin_place_launch(Cuda *c, const Plan *pl, int w, int in, const int32_t *act, const int32_t *lev,
                             int ring, bool keyed, bool in_patches = false)
{
    const bool rows = keyed && rows_sort(c, pl); /* no cell counts: the table in buckets (rows_launch) */
    int64_t blocks = window_blocks(c, pl, w);
    bool short_scan = !rows && bin_clear(c, pl, w);
    unsigned long long *crowded = rows ? NULL : crowded_flag(c, pl, w);
    if (keyed) { /* one slice */
        step_kernel(c, loop_blocks(c, c->n, 16), THREADS, 0, bin_kernel<true, false, false>, c->st[in], c->n,
                    c->grid, 0, act, lev, c->info, c->wall_hi, c->keys, rows ? NULL : c->rank,
                    rows ? NULL : c->count, 1, crowded);
        if (rows) {
            rows_launch(c, pl, ring);
            return;
        }
        step_kernel(c, blocks_for(c->n), THREADS, 0, count_kernel, c->grid, c->n, c->keys, c->rank, c->count,
                    crowded);
    } else {
        /* the gate's K is at most the plan's: a plan of one column has a grid of one */
        auto bin = lev ? (pl->gsx > 1 ? bin_kernel<WINDOWS, true, true> : bin_kernel<WINDOWS, true, false>)
                       : (pl->gsx > 1 ? bin_kernel<WINDOWS, false, true> : bin_kernel<WINDOWS, false, false>);
        step_kernel(c, blocks, THREADS, 0, bin, c->st[in], c->n, c->grid, w, act, lev, c->info, c->wall_hi, c->keys,
                    c->rank, c->count, 1, crowded);
    }
    phase_mark(c, ring, w, 1);
    scan_place_launch<WINDOWS>(c, pl, w, act, lev, ring, short_scan, in, in_patches);
}

/* The pair search over window w's entries, placed and copied to en (with midpoints where K > 1), in the
 * build for the run's box. */
template <bool PERIODIC>
static void detect_box(Cuda *c, const Plan *pl, int w, const Entries &en)
{
    int64_t one = blocks_for(pl->went[w]), tiles = loop_blocks(c, pl->went[w], LOOP_BLOCKS * DETECT_MIN_BLOCKS);
    const uint32_t *keys = c->keys, *start = c->start; /* keys: read by the slots' search alone (SLOTS 1) */
    if (pl->K == 1 && en.patches) /* a gathering step in patches (step_launch): places from the slots */
        step_kernel(c, one, THREADS, 0, detect_kernel<false, false, PERIODIC, 2>, en, keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else if (pl->K == 1 && en.slot && en.wall_gate) /* the disks in their slots, the move's gated keys */
        step_kernel(c, one, THREADS, 0, detect_kernel<false, false, PERIODIC, 3>, en, keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else if (pl->K == 1 && en.slot) /* the disks in their slots: their keys by slot */
        step_kernel(c, one, THREADS, 0, detect_kernel<false, false, PERIODIC, 1>, en, keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else if (pl->K == 1)
        step_kernel(c, one, THREADS, 0, detect_kernel<false, false, PERIODIC, 0>, en, keys, start, c->grid, w,
                    c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else if (pl->W == 1)
        step_kernel(c, one, THREADS, RUN_BYTES, detect_kernel<false, true, PERIODIC, 0>, en, keys, start, c->grid,
                    w, c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
    else
        step_kernel(c, tiles, THREADS, RUN_BYTES, detect_kernel<true, true, PERIODIC, 0>, en, keys, start,
                    c->grid, w, c->par.sigma2, c->ev[0], c->ev_cap, c->info, c->best_hi);
}

static void detect_launch(Cuda *c, const Plan *pl, int w, const Entries &en)
{
    if (c->par.periodic)
        detect_box<true>(c, pl, w, en);
    else
        detect_box<false>(c, pl, w, en);
}

/* A move's MoveBin whose kept slots start their event keys in place, as the next step in the slots reads them
 * (cuda's steps, a GPU rank's): no second keys where the search starts its events' (LO_AT_EVENT), a wall key,
 * partner or best key only where it changes (GATED_WALLS; SKIP_BEST after a step that settled). */
static MoveBin move_starts_keys(const Cuda *c, bool settled)
{
    MoveBin mb = {c->ahead, c->keys, c->wall_hi, c->best_hi, NULL, c->partner, 0, GATED_WALLS, 0};
    if (!LO_AT_EVENT) mb.best_lo = c->best_lo;
    mb.marked = SKIP_BEST && settled;
    return mb;
}

/* Whether a step of plan pl keys the disks ahead in its move (MoveBin): steps of one slice, unless
 * SIM_CUDA_BIN_AHEAD=0 */
static bool moves_key_ahead(const Cuda *c, const Plan *pl)
{
    return pl->K == 1 && c->ahead_slack > 0;
}

/* Launches one step from the current state; if the step commits, the current state is then in c->cur.
 * ring: the step's phase marks under --stats; first, last: whether it is its batch's first, last;
 * keyed_in: a first step that the batch before keyed (batch_launch); key_out: a last step that keys the
 * next batch's first. In steps of one slice where moves key ahead (MoveBin): keyed, the move of the step
 * before keyed the disks' cells for this one; key_ahead, this one's move keys them for the next. */
static void step_launch(Cuda *c, const Plan *pl, int ring, bool first, bool last, bool keyed_in = false,
                        bool key_out = false)
{
    int64_t n = c->n;
    int in = c->cur;
    const Grid *grid = c->grid;
    c->step_windows[ring] = pl->W;
    bool ahead = moves_key_ahead(c, pl);
    bool keyed = ahead && (!first || keyed_in), key_ahead = ahead && (!last || key_out);
    /* a step the move before keyed searches the disks where that move left them, through the cell
     * order (SLOT_STEPS), and that move started their event keys: no gather. A batch's first step
     * gathers, so the disks return to cell order every BATCH to GATHER_SPAN steps (between them a gas's
     * disks move a few cells at most, and the search's loads stay near each other), and a step run again
     * after a refusal starts from a gather; but a batch's first step is keyed by the batch before where
     * the batch ends within GATHER_SPAN steps of the last gather (cuda_run, keys_handed). */
    bool slots = SLOT_STEPS && keyed;
    /* a gathering step in patches (PATCH_W): its placement gives each disk its slot in them, and the step
     * searches the disks in their slots */
    bool patches = PATCH_W > 0 && SLOT_STEPS && pl->K == 1 && !slots;
    step_kernel(c, 1, 1, 0, gate_kernel, c->ctl, c->info, c->counts, c->lim, pl->vmax, pl->K, pl->gcap, pl->F, pl->W,
                pl->levels, c->grid, c->ahead, (int)keyed, key_ahead ? c->ahead_slack : 0.0);
    if (pl->K == 1) {
        phase_mark(c, ring, 0, 0);
        bin_place_launch<false>(c, pl, 0, in, NULL, NULL, ring, keyed, patches);
        if (!slots) {
            step_kernel(c, blocks_for(n), THREADS, 0, gather_state_kernel, c->st[in], c->st[1 - in], c->order, n,
                        c->par, c->wall_hi, c->best_hi, LO_AT_EVENT ? (uint64_t *)NULL : c->best_lo, c->partner,
                        c->ctl, (uint32_t *)NULL, (int64_t)0);
            in = 1 - in;
        }
        DevState *d = &c->st[in];
        Entries en;
        en.disk = d->d, en.id = d->id;
        en.slot = slots ? (int32_t *)c->order : patches ? (int32_t *)c->slot_of : NULL;
        en.rank = c->rank;
        en.rank8 = narrow_counts(c, pl, 0);
        en.patches = patches ? c->patch_at : NULL;
        en.wall = c->wall_hi;
        en.wall_gate = GATED_WALLS && slots ? c->partner : NULL; /* the move before kept some wall keys alone */
        en.mid = NULL;
        en.placed = NULL;
        en.best_lo = LO_AT_EVENT ? c->best_lo : NULL;
        en.tally = pl->settle ? c->partner : NULL;
        en.ties = LO_IF_TIED ? &c->info->ties : NULL;
        phase_mark(c, ring, 0, 3);
        detect_launch(c, pl, 0, en);
        choose_launch(c, pl, 0, en.wall_gate ? NULL : c->wall_hi, ring, en.ties);
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
            if (!place_fused(c))
                step_kernel(c, window_blocks(c, pl, w), THREADS, 0, gather_entries_kernel, c->st[in], n, w, act,
                            lev, c->info, c->start, grid, c->en);
            phase_mark(c, ring, w, 3);
            Entries en = c->en; /* the entries' slots and mids, and the disks in their slots */
            en.disk = c->st[in].d, en.id = c->st[in].id, en.wall = c->wall_hi;
            en.ties = LO_IF_TIED > 1 ? &c->info->ties : NULL; /* a tie in one window: the later ones' too */
            detect_launch(c, pl, w, en);
            choose_launch(c, pl, w, c->wall_win, ring, en.ties);
        }
    }
    RankMove none = {};
    MoveBin mb = move_starts_keys(c, pl->settle); /* the grid and keys: read by move_kernel<false, true, *> */
    if (!SLOT_STEPS) mb.wall_hi = mb.best_hi = mb.best_lo = NULL, mb.partner = NULL; /* every step gathers */
    mb.ids_alike = slots;
    auto move = MOVE_LOOP ? (key_ahead ? move_kernel<false, true, true> : move_kernel<false, false, true>)
                          : (key_ahead ? move_kernel<false, true, false> : move_kernel<false, false, false>);
    int64_t move_blocks = MOVE_LOOP ? loop_blocks(c, n, MOVE_LOOP) : blocks_for(n);
    step_kernel(c, move_blocks, THREADS, 0, move, c->st[in], c->st[1 - in], n, c->par, c->partner, c->wall_hi,
                c->best_hi, c->pc, c->wc, c->info, c->ev_cap, c->ctl, none, mb);
    phase_mark(c, ring, pl->W - 1, 7);
    step_kernel(c, 1, 32, 0, commit_kernel, c->ctl, c->info, c->counts, (int)pl->settle);
    c->cur = 1 - in;
}

/* What sets the kernels a batch launches, and in what order (step_launch): its steps, one slice or
 * several, the windows, the speed levels' lists, each window's choice rounds and way of scanning its
 * cell table, and whether a scan by cub left counts to clear. */
static uint64_t batch_shape(const Cuda *c, const Plan *pl, int64_t steps, bool keyed_in, bool key_out)
{
    uint64_t h = 1469598103934665603ull; /* FNV-1a over the fields */
    enum { HEAD = 9 }; /* the fields before the windows' */
    int64_t f[HEAD + 2 * WMAX] = {steps, pl->K > 1, pl->W, pl->levels > 1, c->dirty > 0, pl->settle,
                                  2 * keyed_in + key_out, c->narrow, rows_sort(c, pl)}; /* narrow: narrow_counts */
    for (int w = 0; w < pl->W && w < WMAX; w++) {
        f[HEAD + 2 * w] = pl->rounds[w];
        f[HEAD + 1 + 2 * w] = scan_short(c, pl->wcells[w] + 1); /* bin_place_launch */
    }
    for (int i = 0; i < HEAD + 2 * WMAX; i++) h = (h ^ (uint64_t)f[i]) * 1099511628211ull;
    return h;
}

/* Steps first to last, from the current state (cur_at: the state each starts from). A batch of BATCH
 * steps of one slice whose shape (batch_shape) is that of the last batch of its slot b is captured and
 * launched as one graph, whose kernels the device starts with less delay between them than kernels
 * launched one by one (gas of 1e5, 1000 steps, one H200: 2.15e9-2.21e9 against 1.63e9-2.08e9
 * particle-steps/s). graph[b] is updated in place (only sizes and pointers differ), made the first time;
 * slot b's last launch has finished by then (the host read its batch back). Other batches launch kernel
 * by kernel: making a graph takes milliseconds, which a run of 10 steps at N = 1e6 does not win back
 * (9h), and so do --stats runs; and a graph of steps of several slices runs slower than their kernels
 * launched one by one, as programmatic dependent launches (random scene, N = 32000: 2.29e8-2.60e8 against
 * 2.69e8-2.71e8, no graph made anew or failing its update). bench/gpu_h100_variants.log 9h, 43b. */
static void batch_launch(Cuda *c, const Plan *pl, int b, int64_t first, int64_t last, int *cur_at,
                         bool keyed_in, bool key_out)
{
    if (c->scan_alternate) c->scan_tiles = b ? SCAN_TILES : 0; /* SIM_CUDA_SCAN_TILES=-1 */
    uint64_t shape = batch_shape(c, pl, last - first + 1, keyed_in, key_out);
    int graph = c->graphs && pl->K == 1 && last - first + 1 == BATCH && shape == c->shape[b];
    c->shape[b] = shape;
    if (graph) CUDA_CHECK(cudaStreamBeginCapture(c->stream, cudaStreamCaptureModeThreadLocal));
    for (int64_t s = first; s <= last; s++) {
        cur_at[s % RING] = c->cur;
        step_launch(c, pl, (int)(s % RING), s == first, s == last, keyed_in, key_out);
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
