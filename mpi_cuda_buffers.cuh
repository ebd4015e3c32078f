/* mpi_cuda_buffers.cuh: a GPU rank's buffers, grown to what its steps need; the layout of the region it
 * shares with the ranks of its node; the wait for its stream.
 * Part of mpi_cuda.cu, which includes it after GpuRank and the rank's kernels (mpi_cuda_kernels.cuh). */

/* A device buffer of `bytes`, the first `keep` of *p's copied in; *p freed. */
static void regrow(void **p, size_t keep, size_t bytes, const char *what, cudaStream_t s)
{
    void *q = dev_alloc(bytes, what);
    if (*p && keep) CUDA_CHECK(cudaMemcpyAsync(q, *p, keep, cudaMemcpyDeviceToDevice, s));
    CUDA_CHECK(cudaStreamSynchronize(s));
    cudaFree(*p);
    *p = q;
}
#define REGROW(p, keep, bytes, what) regrow((void **)&(p), (size_t)(keep), (size_t)(bytes), what, g->c.stream)

/* The capacity a buffer that must hold n grows to: a quarter more, so that it grows seldom. */
static int64_t grown(int64_t n)
{
    return n + n / 4 + 1024;
}

/* A pinned host buffer of `bytes` in place of *p (its contents not kept). */
static void pinned_regrow(void **p, size_t bytes)
{
    cudaFreeHost(*p);
    CUDA_CHECK(cudaMallocHost(p, bytes));
}

/* Room for n records in the pinned host buffer *p of *cap records (contents not kept). */
static void pinned_records(double **p, int64_t *cap, int64_t n)
{
    if (n <= *cap) return;
    *cap = grown(n);
    pinned_regrow((void **)p, (size_t)*cap * D_LEN * sizeof(double));
}

/* Room for n slots: the state and counts kept, the rest scratch. */
static void rank_reserve(GpuRank *g, int64_t n)
{
    if (n <= g->cap) return;
    Cuda *c = &g->c;
    int64_t cap = grown(n), used = g->own + g->halo;
    for (int b = 0; b < 2; b++) {
        size_t keep = b == c->cur ? (size_t)used : 0;
        REGROW(c->st[b].d, keep * sizeof(Disk), cap * sizeof(Disk), "the state");
        REGROW(c->st[b].id, keep * 4, cap * 4, "the state");
    }
    /* the keys kept: the own disks' were started by the move (started) when a halo or arrivals grow them */
    REGROW(c->wall_hi, used * 8, cap * 8, "the event keys");
    REGROW(c->best_hi, used * 8, cap * 8, "the event keys");
    REGROW(c->best_lo, used * 8, cap * 8, "the event keys");
    REGROW(c->partner, used * 4, cap * 4, "the event keys");
    REGROW(g->where, 0, cap * 4, "the event keys");
    REGROW(g->cand, 0, cap * 4, "the halo");
    g->cap = cap;
}

/* Device records for n (gpu_rank's rec), contents not kept. */
static void rec_reserve(GpuRank *g, int64_t n)
{
    if (n <= g->rec_cap) return;
    int64_t cap = grown(n);
    REGROW(g->rec, 0, (size_t)cap * D_LEN * sizeof(double), "the records between ranks");
    REGROW(g->holes, 0, (size_t)cap * sizeof(int32_t), "the records between ranks");
    g->rec_cap = cap;
}

/* The fill's lists for n pairs, contents not kept. */
static void fill_reserve(GpuRank *g, int64_t n)
{
    if (n <= g->fill_cap) return;
    int64_t cap = grown(n);
    REGROW(g->fill_to, 0, (size_t)cap * sizeof(int32_t), "the move's holes");
    REGROW(g->fill_from, 0, (size_t)cap * sizeof(int32_t), "the move's holes");
    g->fill_cap = cap;
}

static void rec_host_reserve(GpuRank *g, int64_t n)
{
    pinned_records(&g->rec_host, &g->rec_host_cap, n);
}

/* The halo's lists: the slots sent and their keys (nsend), the copies' keys (halo). */
static void send_reserve(GpuRank *g, int64_t nsend)
{
    if (nsend <= g->send_cap) return;
    int64_t cap = grown(nsend);
    REGROW(g->send, 0, cap * 4, "the halo");
    if (!g->peer) { /* the peer path's keys go out through the region */
        REGROW(g->keys, 0, cap * sizeof(GpuKey), "the halo");
        pinned_regrow((void **)&g->keys_host, (size_t)cap * sizeof(GpuKey));
    }
    g->send_cap = cap;
}

static void hkeys_reserve(GpuRank *g, int64_t halo)
{
    if (halo <= g->hkeys_cap) return;
    int64_t cap = grown(halo);
    REGROW(g->hkeys, 0, cap * sizeof(GpuKey), "the halo");
    if (!g->peer) pinned_regrow((void **)&g->hkeys_host, (size_t)cap * sizeof(GpuKey)); /* as received */
    g->hkeys_cap = cap;
}

/* The peer path: the region's records and its keys of round parity k. */
static double *region_records(char *base)
{
    return (double *)base;
}
static GpuKey *region_keys(char *base, int64_t cap, int k)
{
    return (GpuKey *)(base + (size_t)cap * D_LEN * sizeof(double) + (size_t)k * (size_t)cap * sizeof(GpuKey));
}

/* A region for n records (contents not kept): the one it replaces is retired, as another rank may still
 * have it mapped, and the new one's handle made. SIM_MPI_CUDA_REGION_SLACK=K (tests): K records more
 * than needed, where K is small a region that grows step after step. */
static void region_reserve(GpuRank *g, int64_t n)
{
    if (g->xreg && n <= g->xcap) return;
    const char *hook = getenv("SIM_MPI_CUDA_REGION_SLACK");
    int64_t cap = hook ? n + atoll(hook) : grown(n);
    if (cap < 1) cap = 1;
    if (g->xreg) {
        g->retired = (void **)sim_realloc(g->retired, (size_t)g->nretired + 1, sizeof *g->retired);
        g->retired[g->nretired++] = g->xreg;
    }
    size_t entry = D_LEN * sizeof(double) + 2 * sizeof(GpuKey);
    g->xreg = (char *)dev_alloc((size_t)cap * entry, "the records between ranks");
    g->xcap = cap;
    g->xgen++;
    if (cudaIpcGetMemHandle(&g->xhandle, g->xreg) != cudaSuccess) {
        cudaGetLastError();
        if (g->peer) sim_fail("internal error: the GPU's memory for other ranks could not be shared");
        g->unshared = true;
    }
}

/* The slots' map for the kernels that find a sent slot or a copy (where): NULL in a step in the slots,
 * where each is its own place. */
static const uint32_t *slot_where(const GpuRank *g)
{
    return g->slots ? NULL : g->where;
}

static void rank_sync(GpuRank *g)
{
    CUDA_CHECK(cudaStreamSynchronize(g->c.stream));
    g->stage_busy = false;
}
