/* cuda_buffers.cuh: the host's device buffers: their sizes, the input's largest speed, cuda_open and cuda_close.
 * Part of cuda.cu, which includes it after its host-side types and the files before it (cuda.cu's
 * list). */

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
        sim_fail("not enough GPU memory for %s: %.1f MiB wanted, %.1f MiB free of %.1f MiB (%s)", what,
                bytes / 1048576.0, free_b / 1048576.0, total_b / 1048576.0, cudaGetErrorString(err));
    }
    return p;
}

static void state_alloc(DevState *d, int64_t n)
{
    d->d = (Disk *)dev_alloc((size_t)n * sizeof(Disk), "the state");
    d->id = (int32_t *)dev_alloc((size_t)n * sizeof(int32_t), "the state");
}

static void state_free(DevState *d)
{
    cudaFree(d->d);
    cudaFree(d->id);
}

/* SIM_CUDA_SETTLE=E: steps of one slice settle where a disk has fewer than E events on average (0: never; the
 * tests take both ways), in cuda and in a GPU rank (settles) */
static double settle_events_env(void)
{
    const char *settle = getenv("SIM_CUDA_SETTLE");
    return settle ? atof(settle) : SETTLE_EVENTS;
}

/* How the cell tables are counted and scanned, in cuda and in a GPU rank. SIM_CUDA_SCAN_TILES=T: tables of
 * more than T tiles go to cub (0: all), -1: the batches of one slot (batch_launch) to cub, of the other to the
 * short scan; SIM_CUDA_NARROW=0: 32-bit cell counts throughout (narrow_counts). The tests take every way. */
static void counts_env(Cuda *c)
{
    const char *scan_tiles = getenv("SIM_CUDA_SCAN_TILES");
    c->scan_tiles = scan_tiles ? atoll(scan_tiles) : SCAN_TILES;
    c->scan_alternate = c->scan_tiles < 0;
    if (c->scan_tiles > SCAN_TILES || c->scan_tiles < 0) c->scan_tiles = SCAN_TILES;
    const char *narrow = getenv("SIM_CUDA_NARROW");
    c->narrow = NARROW_COUNTS && !(narrow && atoi(narrow) == 0);
    const char *rows = getenv("SIM_CUDA_ROWS"); /* rows_sort: 0 never, 1 every keyed step */
    c->rows = rows ? (atoi(rows) != 0) : -1;
}

static void events_alloc(Cuda *c, int64_t cap)
{
    c->ev_cap = cap;
    c->ev[0] = (PairEvent *)dev_alloc((size_t)cap * sizeof(PairEvent), "the event list");
    c->ev[1] = (PairEvent *)dev_alloc((size_t)cap * sizeof(PairEvent), "the event list");
}

static unsigned long long speed_bits(double v)
{
    unsigned long long bits;
    memcpy(&bits, &v, sizeof bits);
    return bits;
}

static double bits_speed(unsigned long long bits)
{
    double v;
    memcpy(&v, &bits, sizeof v);
    return v;
}

typedef struct {
    const Sim *sim;
    int64_t n, parts;
    double *part_max;
} VmaxJob;

static void vmax_part(void *ctx, int64_t k)
{
    VmaxJob *j = (VmaxJob *)ctx;
    double m = 0;
    for (int64_t i = j->n * k / j->parts; i < j->n * (k + 1) / j->parts; i++) {
        m = fmax(m, fabs((double)j->sim->vx[i]));
        m = fmax(m, fabs((double)j->sim->vy[i]));
    }
    j->part_max[k] = m;
}

/* The largest velocity component of the state, on the host threads (a maximum: exact in any order). */
static double host_vmax(const Sim *sim, int64_t n)
{
    double part_max[64] = {0}, m = 0;
    VmaxJob j = {sim, n, n < 65536 ? 1 : 64, part_max};
    cuda_parallel(0, j.parts, vmax_part, &j);
    for (int64_t k = 0; k < j.parts; k++) m = fmax(m, part_max[k]);
    return m;
}

/* The moves' keying of the next step's cells (MoveBin): the ahead grid, and the speed it allows over the
 * step's. SIM_CUDA_BIN_AHEAD=S: cells fitted to S times the speed (0: moves do not key; the tests take 1,
 * where steps often bin anew). A GPU rank's too (mpi_cuda.cu). */
static void ahead_open(Cuda *c)
{
    const char *bin_ahead = getenv("SIM_CUDA_BIN_AHEAD");
    c->ahead_slack = bin_ahead ? atof(bin_ahead) : BIN_AHEAD;
    if (!(c->ahead_slack >= 1)) c->ahead_slack = 0;
    c->ahead = (Grid *)dev_alloc(sizeof(Grid), "counters");
}

/* vmax: the largest velocity component of sim (host_vmax) */
static void cuda_open(Cuda *c, const Sim *sim, const Params *par, double vmax, int timed, int64_t ev_cap,
                      int checkpoints)
{
    int devices = 0;
    cudaError_t err = cudaGetDeviceCount(&devices);
    if (err != cudaSuccess || devices == 0)
        sim_fail("no CUDA GPU available (%s)", err != cudaSuccess ? cudaGetErrorString(err) : "no device");
    memset(c, 0, sizeof *c);
    int64_t n = par->n;
    c->n = n;
    c->par = *par;
    CUDA_CHECK(cudaDeviceGetAttribute(&c->sms, cudaDevAttrMultiProcessorCount, 0));

    CUDA_CHECK(cudaStreamCreateWithFlags(&c->stream, cudaStreamNonBlocking));
    /* no kernel here keeps a stack frame (nvcc -Xptxas -v): the default 1 KB a thread reserves some
     * 270 MB of local memory on an H100 (1 KB x 2048 threads x 132 multiprocessors) */
    (void)cudaDeviceSetLimit(cudaLimitStackSize, 64);
    cudaGetLastError();
    /* the pair search's runs in shared memory beyond its static arrays (past 48 KB in all) */
    const cudaFuncAttribute smem = cudaFuncAttributeMaxDynamicSharedMemorySize;
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<false, true, false, false>, smem, (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<true, true, false, false>, smem, (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<false, true, true, false>, smem, (int)RUN_BYTES));
    CUDA_CHECK(cudaFuncSetAttribute(detect_kernel<true, true, true, false>, smem, (int)RUN_BYTES));
    c->timed = timed;
    /* SIM_CUDA_GRAPH=0 (or a build with -DGRAPHS=0): every batch kernel by kernel (the tests run both
     * ways; --stats always does) */
    const char *graphs = getenv("SIM_CUDA_GRAPH");
    c->graphs = GRAPHS && !timed && !(graphs && atoi(graphs) == 0);
    /* SIM_CUDA_PDL=0 (or -DPDL=0): no programmatic dependent launches (sm_90 and later have them) */
    const char *pdl = getenv("SIM_CUDA_PDL");
    int major = 0;
    CUDA_CHECK(cudaDeviceGetAttribute(&major, cudaDevAttrComputeCapabilityMajor, 0));
    c->pdl = PDL && major >= 9 && !(pdl && atoi(pdl) == 0);
    counts_env(c);
    /* SIM_CUDA_FUSED_N=N: placement fused below N disks (0: never; the tests take both ways) */
    const char *fused_n = getenv("SIM_CUDA_FUSED_N");
    c->fused_n = fused_n ? atoll(fused_n) : PLACE_FUSED_N;
    c->settle_events = settle_events_env();
    ahead_open(c);
    c->checkpoints = checkpoints;
    if (timed)
        for (int s = 0; s < RING; s++)
            for (int w = 0; w < WMAX; w++)
                for (int k = 0; k <= PHASES; k++) CUDA_CHECK(cudaEventCreate(&c->mark[s][w][k]));
    for (int b = 0; b < 2; b++) CUDA_CHECK(cudaEventCreateWithFlags(&c->batch_done[b], cudaEventDisableTiming));

    state_alloc(&c->st[0], n);
    state_alloc(&c->st[1], n);
    c->pc = (int32_t *)dev_alloc((size_t)n * 4, "the state");
    c->wc = (int32_t *)dev_alloc((size_t)n * 4, "the state");
    c->wall_hi = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->best_hi = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->best_lo = (uint64_t *)dev_alloc((size_t)n * 8, "the event keys");
    c->partner = (int32_t *)dev_alloc((size_t)n * 4, "the event keys");
    events_alloc(c, ev_cap);
    c->counts = (unsigned long long *)dev_alloc(WMAX * (MAX_ROUNDS + 1) * sizeof(unsigned long long), "counters");
    c->info = (StepInfo *)dev_alloc(sizeof(StepInfo), "counters");
    c->ctl = (Control *)dev_alloc(sizeof(Control), "counters");
    c->grid = (Grid *)dev_alloc(sizeof(Grid), "counters");
    CUDA_CHECK(cudaMallocHost((void **)&c->ctl_host, 2 * sizeof(Control)));
    /* The scene's plans size the entries and cells (buffers_fit, below): a gas of one slice a step
     * takes one entry and at most CELLS_PER_DISK cells a disk. What is left of the device after the
     * state bounds only the slices a plan may take: up to ENTRY_MEMORY of it for entries (per entry,
     * two 4-byte keys, three cells of count and start, and with K > 1 a slot, key and midpoint), at most
     * MAX_SLICES per disk. Entry and cell indices stay below 2^31. */
    size_t free_b = 0, total_b = 0;
    CUDA_CHECK(cudaMemGetInfo(&free_b, &total_b));
    double afford = ENTRY_MEMORY * (double)free_b / ENTRY_BYTES;
    int64_t cap = n * MAX_SLICES;
    if ((double)cap > afford) cap = (int64_t)afford;
    if (cap > INT32_MAX) cap = INT32_MAX;
    GridLimits *lim = &c->lim;
    lim->n = n;
    lim->L = par->L;
    lim->r = par->r;
    lim->periodic = par->periodic;
    lim->max_slices = cap / n >= 1 ? (int)(cap / n) : 1;
    int64_t entry_most = n * lim->max_slices;
    lim->cell_cap = 3 * entry_most > (1LL << 22) ? 3 * entry_most : (1LL << 22);
    if (lim->cell_cap > INT32_MAX - 1) lim->cell_cap = INT32_MAX - 1;
    c->tile_sums = (uint32_t *)dev_alloc(SCAN_TILES * sizeof(uint32_t), "the cell table");
    if ((par->print && par->steps > 1) || checkpoints) {
        size_t bytes = (size_t)n * (4 * sizeof(real) + (checkpoints ? 2 * sizeof(int32_t) : 0));
        c->out_dev = (real *)dev_alloc((size_t)n * 4 * sizeof(real), "the print buffer");
        for (int b = 0; b < 2; b++) CUDA_CHECK(cudaMallocHost((void **)&c->out_host[b], bytes));
    }

    /* the state as the input left it: its four arrays copied as they are into the spare state buffer,
     * then paired into positions and velocities, with ids, on the device */
    DevState *d = &c->st[0], *spare = &c->st[1];
    size_t nd = (size_t)n * sizeof(real), ni = (size_t)n * sizeof(int32_t);
    real *x = (real *)spare->d, *vx = x + 2 * n; /* its 4 n reals as x, y, vx, vy */
    CUDA_CHECK(cudaMemcpy(x, sim->x, nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(x + n, sim->y, nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(vx, sim->vx, nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(vx + n, sim->vy, nd, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(c->pc, sim->pc, ni, cudaMemcpyHostToDevice));
    CUDA_CHECK(cudaMemcpy(c->wc, sim->wc, ni, cudaMemcpyHostToDevice));
    pair_up_kernel<<<blocks_for(n), THREADS, 0, c->stream>>>(*d, n, x, x + n, vx, vx + n);
    CUDA_LAUNCHED();
    CUDA_CHECK(cudaStreamSynchronize(c->stream));
    Control start;
    memset(&start, 0, sizeof start);
    start.vmax = speed_bits(vmax);
    CUDA_CHECK(cudaMemcpy(c->ctl, &start, sizeof start, cudaMemcpyHostToDevice));
    c->cur = 0;
}

/* The device memory the run's buffers hold (--stats), from their sizes. */
static double buffer_bytes(const Cuda *c)
{
    double n = (double)c->n;
    double b = n * (2 * (4 * sizeof(real) + 4) + 2 * 4 + 3 * 8 + 4);          /* states, pc, wc, keys, partner */
    b += 2.0 * (double)c->ev_cap * sizeof(PairEvent);                         /* the event lists */
    b += 8.0 * (double)(c->entry_cap + c->order_cap) + 8.0 * (double)c->cell_held; /* entries, cells */
    b += 8.0 * (double)c->patch_cap;                                          /* the patches' pieces */
    b += 8.0 * (double)c->bucket_cap + 4.0 * (double)c->bucket_total;         /* rows_sort's buckets */
    b += (double)c->copy_cap * (sizeof(uint2) + sizeof(float4));              /* entries' slots, keys, mids */
    if (c->slices_held) b += n * (8 + 2 * 4 + LEVELS * 4 + 1);                 /* wall_win, act, lev, level_of */
    if (c->out_dev) b += n * 4 * sizeof(real);                                /* the print buffer */
    return b + (double)c->scan_tmp_bytes + SCAN_TILES * 4;
}

/* Frees what buffers_grow (cuda_plan.cuh) allocates. cuda_close and a GPU rank's close (mpi_cuda.cu) both
 * call it, so that a buffer added there is freed by both programs. */
static void grown_free(Cuda *c)
{
    cudaFree(c->keys);
    cudaFree(c->rank);
    cudaFree(c->en.placed);
    cudaFree(c->en.mid);
    cudaFree(c->slot_of);
    cudaFree(c->order);
    cudaFree(c->count);
    cudaFree(c->start);
    cudaFree(c->scan_tmp);
    cudaFree(c->pieces);
    cudaFree(c->patch_at);
    cudaFree(c->bcount);
    cudaFree(c->bstart);
    cudaFree(c->bucket);
    cudaFree(c->wall_win);
    cudaFree(c->act[0]);
    cudaFree(c->act[1]);
    cudaFree(c->lev);
    cudaFree(c->level_of);
}

static void cuda_close(Cuda *c)
{
    for (int b = 0; b < 2; b++)
        if (c->graph[b]) cudaGraphExecDestroy(c->graph[b]);
    state_free(&c->st[0]);
    state_free(&c->st[1]);
    cudaFree(c->pc);
    cudaFree(c->wc);
    grown_free(c);
    cudaFree(c->tile_sums);
    cudaFree(c->wall_hi);
    cudaFree(c->best_hi);
    cudaFree(c->best_lo);
    cudaFree(c->partner);
    cudaFree(c->ev[0]);
    cudaFree(c->ev[1]);
    cudaFree(c->counts);
    cudaFree(c->info);
    cudaFree(c->ctl);
    cudaFree(c->grid);
    cudaFree(c->ahead);
    cudaFreeHost(c->ctl_host);
    cudaFree(c->out_dev);
    for (int b = 0; b < 2; b++) {
        cudaFreeHost(c->out_host[b]);
        cudaEventDestroy(c->batch_done[b]);
    }
    if (c->timed)
        for (int s = 0; s < RING; s++)
            for (int w = 0; w < WMAX; w++)
                for (int k = 0; k <= PHASES; k++) cudaEventDestroy(c->mark[s][w][k]);
    cudaStreamDestroy(c->stream);
}
