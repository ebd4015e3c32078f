/* mpi_cuda.cu: the GPU of one rank of mpi_cuda (mpi.c built with MPI_CUDA; mpi_cuda.h lists the calls).
 * A rank holds its own disks on its GPU and, during a step, copies of the other ranks' disks within
 * reach of its strip (the halo), after them. The step is cuda's step of one time slice, by cuda.cu's
 * own kernels (that file is included here whole, its main left out):
 *   detect   bin, scan, place and the pair search over the own disks and the copies, on the grid cuda
 *            would fit to the whole box of N disks, its table of cells cut to the strip's columns
 *            (GridLimits' slab) (a copy is a disk like any other here); the search reads the disks in
 *            their slots through the cell order, and every RANK_GATHER_EVERY steps they are gathered into it; the
 *            cells counted in 8 bits, as cuda counts them, until one passes 255 disks;
 *   rounds   cuda's rounds of the choice, each with one exchange between its min and accept passes:
 *            the smallest live keys of the own disks that other ranks hold copies of go out, and the
 *            copies' keys from their owners replace those found here, which lack the copies' events
 *            with disks this rank does not see. An event with a copy is thus accepted, or not, alike by
 *            both ranks; a copy's owner decides it, and a decision reaches the copies a round late,
 *            which only delays (mpi.c, choose). The rounds end when no rank has a live event;
 *   move     cuda's move for the own disks (a pair with a copy from the copy's state at the step's
 *            start, as cuda moves both partners from the old buffer); the own disks still in the strip
 *            keep their slots and start their event keys there, as cuda's move does (writing only the
 *            keys that change: GATED_WALLS, SKIP_BEST, LO_AT_EVENT), the others
 *            (leavers) go into records for their new ranks, and the holes they and the copies leave
 *            below the kept disks' count are filled from the slots above it.
 * Event keys compare by value (t, kind, i, j), so the order of the slots and of the copies does not
 * matter: the bytes are seq's. Collision counts are kept by disk index, as cuda keeps them, on every
 * rank for all N disks (8 bytes a disk a GPU), and travel in the records of disks that change ranks.
 */
#define CUDA_LIBRARY
/* a GPU rank's rounds always compare second keys (LO_IF_TIED is cuda's step loop's), so its events of time 0
 * keep one first key (ZERO_KEYS would buy it nothing) */
#define ZERO_KEYS 0
#include "cuda.cu"
#include "mpi_cuda.h"

#define CHUNK ((int64_t)1 << 20) /* records a copy to or from the host takes at a time (64 MB pinned) */
#define COUNTERS 7              /* GpuRank's counter */
#ifndef RANK_GATHER_EVERY
#define RANK_GATHER_EVERY BATCH /* a rank's steps gather the disks into cell order once in so many (16: no
                                   faster, one rank on a gas of 1e7; bench/mpi_h100_gpu_ranks.log) */
#endif

struct GpuRank {
    Cuda c;                 /* cuda.cu's buffers; c.n: a step's slots (own + halo), c.cur: the state */
    int64_t own, halo, cap; /* slots: own disks at [0, own), copies after them; buffers for cap */
    /* the own disks' collision counts by disk index, N of them: a move adds to them in place, as cuda's
     * does, where counts by slot had to follow the slots (20 bytes a disk more in the move) */
    int32_t *pc, *wc;
    /* every slot's event keys started (slot_init) for the next search, by the move (in place, as cuda's
     * move starts them), the gather, the fill of the move's holes or the puts since (rank_put_kernel) */
    bool started;
    uint32_t *where;        /* slot before the gather -> its cell place: the halo's sent slots and the copies */
    /* this step searches the disks in their slots through the cell order, as cuda's gas does (SLOT_STEPS):
     * no gather, where is each slot itself; steps since the last gather (one in RANK_GATHER_EVERY gathers) */
    bool slots;
    int since_gather;
    int32_t *cand;          /* gpu_rank_halo_out's own slots with a copy to send (cap) */
    /* the own slots that the last move kept within its reach (hreach) of the cuts hc0, hc1 (hcand, hn of
     * them, where hvalid), and the first slot added since: the next halo looks at those alone, where its
     * cuts are the same and its reach no longer (a step of 1e7 disks on one rank spent 42 us reading every
     * own disk's x) */
    int32_t *hcand;
    int64_t hcap, hn, hkept;
    double hc0, hc1, hreach;
    bool hvalid;
    double *view_cut;       /* the HaloView's arrays on the device, for np ranks: cut (np + 1), then */
    char *view_flags;       /* near and whole (np each); their pinned host stage, and the counts by */
    double *view_host;      /* rank (np, then the candidates and the errors, then np places), */
    unsigned long long *halo_count, *halo_count_host; /* with a host copy of the first np + 2 */
    int view_np;
    int32_t *send;          /* gpu_rank_halo_out's slots, in the order their keys go out */
    int64_t nsend, send_cap;
    GpuKey *keys, *hkeys;   /* a round's keys out (nsend) and the copies' keys in (halo) */
    GpuKey *keys_host;
    int64_t hkeys_cap;
    double *rec, *rec_host; /* records in and out of the device (D_LEN doubles each): the halo's and the
                               leavers' whole, the own disks' CHUNK at a time through stage */
    double *stage;          /* pinned, CHUNK records; stage_busy: a copy from it may still run */
    bool stage_busy;
    GpuKey *hkeys_host;     /* pinned: the copies' keys as received (halo) */
    double *halo_host;      /* pinned: the halo's records as received (gpu_rank_halo_in) */
    int64_t halo_host_cap;
    int64_t rec_cap, rec_host_cap;
    /* the move's appends: [1], [2] (RankMove), the holes' fill [0], [5]; the rounds' lists: [3], [4], and
     * the settling's contested events [6] */
    unsigned long long *counter, *counter_host;
    /* the move's leavers' slots (rec_cap) and the fill's pairs of slots, holes and the kept disks above
       the kept count (fill_cap): rank_holes_kernel */
    int32_t *holes, *fill_to, *fill_from;
    int64_t fill_cap;
    StepInfo *info_host;
    double secs[GPU_CALLS]; /* the host's seconds in each call (gpu_rank_times) */
    Plan pl;
    /* the own disks binned while the halo's records travel (gpu_rank_halo_out): early, for slots of cap
     * (buffers sized for it), the counts to be scanned by the short kernels where early_short */
    bool early, early_short;
    int64_t early_cap, early_len; /* and the length of the table it counted into */
    cudaEvent_t halo_counted; /* the halo's counts are on the host */
    cudaEvent_t halo_ready;   /* the halo's records are on the host (or in the region), packed on side */
    cudaStream_t side;
    /* the own disks the last move kept, slots [0, keyed), keyed on the grid it was given ahead (c.ahead,
     * MoveBin) while c.grown was keyed_grown (a growth since reallocated the keys); the steps that took
     * those keys and those that binned anew (--stats) */
    int64_t keyed, keyed_grown;
    unsigned long long keyed_steps[2];
    unsigned long long halo_listed[2]; /* halos that looked at the move's list, and at every own disk */
    unsigned long long moved_again;    /* moves done twice, their leavers overflowing the room */
    unsigned long long searched_again; /* searches done again, their events overflowing the list */
    unsigned long long crowdings;      /* and for a cell past 255 disks (one at most: 32-bit counts after it) */
    int64_t left_last;                 /* the leavers of the last move */
    int64_t leavers_room; /* SIM_MPI_CUDA_LEAVERS_ROOM=K (tests): a move's first pass takes K leavers at most */
    int64_t events_room;  /* SIM_MPI_CUDA_EVENTS=K (tests): each step's event list K events at most at first */
    /* this step settles the events the only one of both their disks before the rounds, as cuda's steps of one
     * slice do (Plan.settle, settle_kernel), where the last step found few events a disk (found_last) */
    bool settle;
    int64_t found_last;
    unsigned long long settled[2]; /* --stats: pair events found in steps that settled, and left to the rounds */
    int list, round;        /* the rounds: the current list c.ev[list] and its length's counter */
    const unsigned long long *len;
    /* the peer path (mpi_cuda.h, GpuPeer): this rank's region, xcap records then twice xcap keys; the
     * regions it grew out of, freed at the close (another rank may have them mapped until then); the
     * other ranks' regions as mapped here (np); this step's halo by sending rank */
    bool peer, unshared; /* unshared: the device could not export the region (no peer path) */
    char *xreg;
    int64_t xcap, xgen;
    cudaIpcMemHandle_t xhandle;
    void **retired;
    int nretired;
    struct PeerMap {
        char *base;
        int64_t cap, gen;
    } *map;
    int map_np;
    struct PeerSeg {
        int q;
        int64_t offset, count, at; /* in q's region; at: the first copy's place in the halo */
    } *seg;
    int nseg, seg_cap;
};
static_assert(sizeof(cudaIpcMemHandle_t) == sizeof(((GpuPeer *)0)->handle), "GpuPeer's handle");

#include "mpi_cuda_kernels.cuh"
#include "mpi_cuda_buffers.cuh"

/* ---- the calls ------------------------------------------------------------------------------------------ */

/* A call's host seconds, added to g->secs[k] as it returns. */
struct CallClock {
    double *sum, t0;
    CallClock(GpuRank *g, int k) : sum(&g->secs[k]), t0(sim_clock()) {}
    ~CallClock() { *sum += sim_clock() - t0; }
};

const double *gpu_rank_times(const GpuRank *g)
{
    return g->secs;
}

void gpu_rank_reused(const GpuRank *g, uint64_t reused[9])
{
    reused[0] = g->keyed_steps[0], reused[1] = g->keyed_steps[1];
    reused[2] = g->halo_listed[0], reused[3] = g->halo_listed[1];
    reused[4] = g->moved_again;
    reused[5] = g->searched_again;
    reused[6] = g->settled[0], reused[7] = g->settled[1];
    reused[8] = g->crowdings;
}

GpuRank *gpu_rank_open(const Params *par, int local)
{
    int devices = 0;
    cudaError_t err = cudaGetDeviceCount(&devices);
    if (err != cudaSuccess || devices == 0)
        sim_fail("no CUDA GPU available (%s)", err != cudaSuccess ? cudaGetErrorString(err) : "no device");
    CUDA_CHECK(cudaSetDevice(local % devices));
    GpuRank *g = (GpuRank *)sim_calloc(1, sizeof *g);
    Cuda *c = &g->c;
    c->par = *par;
    int dev = 0;
    CUDA_CHECK(cudaGetDevice(&dev));
    CUDA_CHECK(cudaDeviceGetAttribute(&c->sms, cudaDevAttrMultiProcessorCount, dev));
    CUDA_CHECK(cudaStreamCreateWithFlags(&c->stream, cudaStreamNonBlocking));
    (void)cudaDeviceSetLimit(cudaLimitStackSize, 64); /* cuda_open's reason */
    cudaGetLastError();
    /* the host waits for every step: no graphs, no programmatic launches; SIM_CUDA_SCAN_TILES=-1 (one of
     * cuda's batch slots to cub) is as unset here */
    counts_env(c);
    c->rows = 0; /* a GPU rank's keyed steps count their keys (count_kernel), not in buckets (rows_sort) */
    c->settle_events = settle_events_env();
    /* the grid cuda fits to the whole box of N disks, one time slice a step: a rank's slots are a part
     * of the box's disks, wherever its strip lies; the table holds the strip's cells (gpu_rank_slab) */
    GridLimits *lim = &c->lim;
    lim->n = par->n > 0 ? par->n : 1;
    lim->L = par->L;
    lim->r = par->r;
    lim->periodic = par->periodic;
    lim->max_slices = 1;
    lim->cell_cap = 3 * lim->n > (1LL << 22) ? 3 * lim->n : (1LL << 22);
    if (lim->cell_cap > INT32_MAX - 1) lim->cell_cap = INT32_MAX - 1;
    c->tile_sums = (uint32_t *)dev_alloc(SCAN_TILES * sizeof(uint32_t), "the cell table");
    c->counts = (unsigned long long *)dev_alloc(WMAX * (MAX_ROUNDS + 1) * sizeof(unsigned long long), "counters");
    c->info = (StepInfo *)dev_alloc(sizeof(StepInfo), "counters");
    c->ctl = (Control *)dev_alloc(sizeof(Control), "counters");
    c->grid = (Grid *)dev_alloc(sizeof(Grid), "counters");
    ahead_open(c);
    CUDA_CHECK(cudaMemsetAsync(c->ctl, 0, sizeof(Control), c->stream));
    g->counter = (unsigned long long *)dev_alloc(COUNTERS * sizeof(unsigned long long), "counters");
    CUDA_CHECK(cudaMallocHost((void **)&g->counter_host, COUNTERS * sizeof(unsigned long long)));
    size_t ids = (size_t)(par->n > 0 ? par->n : 1) * sizeof(int32_t);
    g->pc = (int32_t *)dev_alloc(ids, "the collision counts");
    g->wc = (int32_t *)dev_alloc(ids, "the collision counts");
    const char *room = getenv("SIM_MPI_CUDA_LEAVERS_ROOM");
    g->leavers_room = room && *room ? atoll(room) : -1;
    room = getenv("SIM_MPI_CUDA_EVENTS");
    g->events_room = room && *room && atoll(room) > 0 ? atoll(room) : -1;
    g->since_gather = RANK_GATHER_EVERY; /* the first step gathers */
    CUDA_CHECK(cudaMallocHost((void **)&g->info_host, sizeof(StepInfo)));
    CUDA_CHECK(cudaMallocHost((void **)&g->stage, (size_t)CHUNK * D_LEN * sizeof(double)));
    CUDA_CHECK(cudaEventCreateWithFlags(&g->halo_ready, cudaEventDisableTiming));
    CUDA_CHECK(cudaEventCreateWithFlags(&g->halo_counted, cudaEventDisableTiming));
    /* the side stream first: the halo's pack, launched behind the own disks' binning, runs before the
     * binning's waiting blocks, so that the halo travels while it bins */
    int least = 0, greatest = 0;
    CUDA_CHECK(cudaDeviceGetStreamPriorityRange(&least, &greatest));
    CUDA_CHECK(cudaStreamCreateWithPriority(&g->side, cudaStreamNonBlocking, greatest));
    events_alloc(c, 4096);
    rank_reserve(g, 1024);
    rank_sync(g);
    return g;
}

void gpu_rank_close(GpuRank *g)
{
    Cuda *c = &g->c;
    rank_sync(g);
    CUDA_CHECK(cudaStreamSynchronize(g->side));
    for (int b = 0; b < 2; b++) {
        state_free(&c->st[b]);
        cudaFree(c->ev[b]);
    }
    cudaFree(g->pc), cudaFree(g->wc), cudaFree(g->hcand);
    cudaFree(c->wall_hi), cudaFree(c->best_hi), cudaFree(c->best_lo), cudaFree(c->partner);
    cudaFree(g->holes), cudaFree(g->fill_to), cudaFree(g->fill_from);
    grown_free(c);
    cudaFree(c->tile_sums);
    cudaFree(c->counts), cudaFree(c->info), cudaFree(c->ctl), cudaFree(c->grid), cudaFree(c->ahead);
    cudaFree(g->where), cudaFree(g->cand), cudaFree(g->send);
    cudaFree(g->view_cut), cudaFree(g->view_flags), cudaFree(g->halo_count);
    cudaFreeHost(g->view_host), cudaFreeHost(g->halo_count_host);
    cudaFree(g->keys), cudaFree(g->hkeys), cudaFree(g->rec), cudaFree(g->counter);
    cudaFreeHost(g->keys_host);
    cudaFreeHost(g->rec_host), cudaFreeHost(g->counter_host), cudaFreeHost(g->info_host);
    cudaFreeHost(g->stage), cudaFreeHost(g->hkeys_host), cudaFreeHost(g->halo_host);
    cudaEventDestroy(g->halo_ready), cudaEventDestroy(g->halo_counted);
    cudaStreamDestroy(g->side);
    cudaStreamDestroy(c->stream);
    gpu_rank_unmap(g);
    for (int k = 0; k < g->nretired; k++) cudaFree(g->retired[k]);
    cudaFree(g->xreg);
    free(g->retired), free(g->map), free(g->seg);
    free(g);
}

/* n records from the host into slots at..at + n (with counts where own), a chunk at a time through the
 * pinned stage (the halo's pinned buffer goes straight): the device holds a chunk of records, not all. */
static void put_records(GpuRank *g, const double *rec, int64_t n, int64_t at, int own)
{
    Cuda *c = &g->c;
    int pinned = rec == g->halo_host;
    rec_reserve(g, n < CHUNK ? n : CHUNK);
    for (int64_t k = 0; k < n; k += CHUNK) {
        int64_t m = n - k < CHUNK ? n - k : CHUNK;
        size_t bytes = (size_t)m * D_LEN * sizeof(double);
        const double *from = rec + k * D_LEN;
        if (!pinned) {
            if (g->stage_busy) rank_sync(g); /* its last copy to the device done */
            memcpy(g->stage, from, bytes), from = g->stage;
            g->stage_busy = true;
        }
        CUDA_CHECK(cudaMemcpyAsync(g->rec, from, bytes, cudaMemcpyHostToDevice, c->stream));
        rank_put_kernel<<<blocks_for(m), THREADS, 0, c->stream>>>(g->rec, m, c->st[c->cur], own ? g->pc : NULL,
                                                                  own ? g->wc : NULL, at + k, c->par, c->wall_hi,
                                                                  c->best_hi, c->best_lo, c->partner);
        CUDA_LAUNCHED();
    }
    /* no wait for the last chunk: the migration's arrivals (one chunk) then go while the host goes on
     * (the halo's buffer is rewritten only next step, after the detection's wait) */
}

void gpu_rank_add_own(GpuRank *g, const double *rec, int64_t n)
{
    CallClock clock_(g, GPU_ADD);
    rank_reserve(g, g->own + n);
    put_records(g, rec, n, g->own, 1);
    g->own += n;
}

/* The plan of a step of one time slice whose largest velocity component is vmax, and the buffers it
 * takes (the entries' follow the slots', cap of them). */
static void plan_step(GpuRank *g, Plan *pl, double vmax)
{
    Cuda *c = &g->c;
    memset(pl, 0, sizeof *pl);
    pl->vmax = speed_bits(vmax);
    pl->K = 1, pl->W = 1, pl->levels = 1;
    pl->gcap = grid_fit(&c->lim, vmax, 1, INT64_MAX).g;
    pl->gsx = 1;
    pl->wcells[0] = pl->gcap * pl->gcap;
    if (c->lim.slab) { /* grid_fit's columns of a slab, at most (x1 - x0) g / L + 4 of them, g <= gcap */
        double rows = floor((c->lim.x1 - c->lim.x0) * (double)pl->gcap / c->lim.L) + 5;
        if (rows < (double)pl->gcap) pl->wcells[0] = (int64_t)rows * pl->gcap;
    }
    pl->went[0] = g->cap;
    c->n = g->cap;
    if (!buffers_fit(c, pl)) buffers_grow(c, pl);
}

void gpu_rank_slab(GpuRank *g, int on, double x0, double x1)
{
    GridLimits *lim = &g->c.lim;
    lim->slab = on && x1 - x0 < lim->L;
    lim->x0 = x0, lim->x1 = x1;
}

void gpu_rank_ready(GpuRank *g, double vmax)
{
    Cuda *c = &g->c;
    int64_t own = g->own, some = own / 16 + 4096; /* the halo and the leavers: a strip's edges */
    rank_reserve(g, own + some);
    send_reserve(g, some);
    hkeys_reserve(g, some);
    rec_reserve(g, some);
    rec_host_reserve(g, some);
    if (c->ev_cap < own / EVENTS_PER_DISK + 4096) {
        cudaFree(c->ev[0]), cudaFree(c->ev[1]);
        events_alloc(c, own / EVENTS_PER_DISK + 4096);
    }
    Plan pl;
    plan_step(g, &pl, vmax / SPEED_SLACK); /* as cuda plans: room for slower disks */
    rank_sync(g);
}

int64_t gpu_rank_own(const GpuRank *g)
{
    return g->own;
}

void gpu_rank_get(GpuRank *g, double *rec)
{
    CallClock clock_(g, GPU_GET);
    Cuda *c = &g->c;
    rec_reserve(g, g->own < CHUNK ? g->own : CHUNK);
    for (int64_t k = 0; k < g->own; k += CHUNK) {
        int64_t m = g->own - k < CHUNK ? g->own - k : CHUNK;
        size_t bytes = (size_t)m * D_LEN * sizeof(double);
        rank_pack_kernel<<<blocks_for(m), THREADS, 0, c->stream>>>(c->st[c->cur], g->pc, g->wc, NULL, k, m, g->rec);
        CUDA_LAUNCHED();
        CUDA_CHECK(cudaMemcpyAsync(g->stage, g->rec, bytes, cudaMemcpyDeviceToHost, c->stream));
        rank_sync(g);
        memcpy(rec + k * D_LEN, g->stage, bytes);
    }
}

/* Room for the view of np ranks, and its counts. */
static void view_reserve(GpuRank *g, int np)
{
    if (np <= g->view_np) return;
    cudaFree(g->view_cut), cudaFree(g->view_flags), cudaFree(g->halo_count);
    cudaFreeHost(g->view_host), cudaFreeHost(g->halo_count_host);
    g->view_cut = (double *)dev_alloc((size_t)(np + 1) * sizeof(double), "the halo");
    g->view_flags = (char *)dev_alloc(2 * (size_t)np, "the halo");
    g->halo_count = (unsigned long long *)dev_alloc((2 * (size_t)np + 2) * sizeof(unsigned long long), "the halo");
    CUDA_CHECK(cudaMallocHost((void **)&g->view_host, (size_t)(np + 1) * sizeof(double) + 2 * (size_t)np));
    CUDA_CHECK(cudaMallocHost((void **)&g->halo_count_host, ((size_t)np + 2) * sizeof(unsigned long long)));
    g->view_np = np;
}

/* Slots first to first + n of st binned on the step's grid (keyed_before: unless the gate took the keys
 * the move before gave them, bin_kernel), into the cell counts. keyed_before: few blocks, looping, as
 * cuda's bin_place_launch, since they mostly return at once: a block a thread's slot, each returning,
 * took 49 us of a 1.7 ms step of 1e7 disks on one rank (one H200, Nsight Compute). */
static void bin_slots(GpuRank *g, DevState st, int64_t first, int64_t n, int keyed_before)
{
    Cuda *c = &g->c;
    if (n <= 0) return;
    st.d += first, st.id += first;
    unsigned long long *crowded = crowded_flag(&g->c, &g->pl, 0);
    /* 8-bit counts' ranks take a byte an entry (rank_put), which bin_kernel writes through the pointer */
    uint32_t *rank = crowded && RANK8 ? (uint32_t *)((uint8_t *)c->rank + first) : c->rank + first;
    if (keyed_before)
        step_kernel(c, loop_blocks(c, n, 16), THREADS, 0, bin_kernel<true, false, false>, st, n, c->grid, 0,
                    (const int32_t *)NULL, (const int32_t *)NULL, c->info, c->wall_hi + first, c->keys + first,
                    rank, c->count, 1, crowded);
    else
        step_kernel(c, blocks_for(n), THREADS, 0, bin_kernel<false, false, false>, st, n, c->grid, 0,
                    (const int32_t *)NULL, (const int32_t *)NULL, c->info, c->wall_hi + first, c->keys + first,
                    rank, c->count, 0, crowded);
}

/* A step's gate (gate_kernel) at its plan's speed, for one slice: ahead, keyed and ahead_slack as it
 * takes them. */
static void rank_gate(GpuRank *g, Grid *ahead, int keyed, double ahead_slack)
{
    Cuda *c = &g->c;
    const Plan *pl = &g->pl;
    CUDA_CHECK(cudaMemcpyAsync(&c->ctl->vmax, &pl->vmax, sizeof pl->vmax, cudaMemcpyHostToDevice, c->stream));
    step_kernel(c, 1, 1, 0, gate_kernel, c->ctl, c->info, c->counts, c->lim, pl->vmax, 1, pl->gcap, 0, 1, 1, c->grid,
                ahead, keyed, ahead_slack);
}

/* The gate of a step (its grid for largest velocity component vmax, and the grid ahead its move keys
 * the disks it keeps on) and the own disks binned on it, before the halo arrives: the device's work while
 * the halo's records travel (gpu_rank_detect bins the copies after them, unless the slots' buffers grew
 * meanwhile). The disks the move before kept and keyed are only counted where the gate takes their grid
 * (ahead_fits: the strip's cells may have moved); the disks that arrived since are binned. */
static void bin_early(GpuRank *g, double vmax)
{
    Cuda *c = &g->c;
    Plan *pl = &g->pl;
    plan_step(g, pl, vmax);
    c->n = g->own;
    int64_t keyed = c->grown == g->keyed_grown && g->keyed <= g->own ? g->keyed : 0;
    rank_gate(g, c->ahead, (int)(keyed > 0), c->ahead_slack);
    g->early_short = bin_clear(c, pl, 0);
    if (keyed > 0) {
        bin_slots(g, c->st[c->cur], 0, keyed, 1);
        step_kernel(c, blocks_for(keyed), THREADS, 0, count_kernel, c->grid, keyed, c->keys, c->rank, c->count,
                    crowded_flag(&g->c, &g->pl, 0));
    }
    bin_slots(g, c->st[c->cur], keyed, g->own - keyed, 0);
    g->keyed = 0;
    g->early = true;
    g->early_cap = g->cap;
    g->early_len = pl->wcells[0] + 1;
}

const double *gpu_rank_halo_out(GpuRank *g, const HaloView *h, double vmax, int *scount, int64_t *nsend)
{
    CallClock clock_(g, GPU_HALO_OUT);
    Cuda *c = &g->c;
    int np = h->np;
    view_reserve(g, np);
    /* the view's arrays through the pinned stage (the sync below ends the copies before a next call) */
    size_t cut_bytes = (size_t)(np + 1) * sizeof(double);
    char *flags = (char *)g->view_host + cut_bytes;
    memcpy(g->view_host, h->cut, cut_bytes);
    for (int q = 0; q < np; q++) {
        flags[q] = h->periodic ? h->near[q] : 0;
        flags[np + q] = h->periodic ? h->whole[q] : 0;
    }
    CUDA_CHECK(cudaMemcpyAsync(g->view_cut, g->view_host, cut_bytes, cudaMemcpyHostToDevice, c->stream));
    CUDA_CHECK(cudaMemcpyAsync(g->view_flags, flags, 2 * (size_t)np, cudaMemcpyHostToDevice, c->stream));
    CUDA_CHECK(cudaMemsetAsync(g->halo_count, 0, (2 * (size_t)np + 2) * sizeof(unsigned long long), c->stream));
    HaloView d = *h;
    d.cut = g->view_cut, d.near = g->view_flags, d.whole = g->view_flags + np;
    /* this step in the slots, or gathered (decided here: a gathered step's pack marks the slots it sends) */
    g->slots = SLOT_STEPS && g->since_gather < RANK_GATHER_EVERY - 1;
    g->since_gather = g->slots ? g->since_gather + 1 : 0;
    /* the slots to look at: the last move's list and the disks added since, where it fits this halo */
    bool listed = g->hvalid && !h->any_whole && h->cut[h->me] == g->hc0 && h->cut[h->me + 1] == g->hc1 &&
                  h->reach <= g->hreach && g->hkept <= g->own;
    g->hvalid = false;
    int64_t nlist = listed ? g->hn : 0, from = listed ? g->hkept : 0, look = nlist + g->own - from;
    g->halo_listed[listed ? 0 : 1]++;
    if (look > 0) {
        rank_halo_count_kernel<<<blocks_for(look), THREADS, 0, c->stream>>>(c->st[c->cur], g->hcand, nlist, from,
                                                                            g->own, d, g->cand, g->halo_count);
        CUDA_LAUNCHED();
    }
    CUDA_CHECK(cudaMemcpyAsync(g->halo_count_host, g->halo_count, ((size_t)np + 2) * sizeof(unsigned long long),
                               cudaMemcpyDeviceToHost, c->stream));
    CUDA_CHECK(cudaEventRecord(g->halo_counted, c->stream));
    /* the own disks binned behind the count, while the host waits for it; the copies are packed on the
     * side stream meanwhile (they read the state that the binning only reads, and their own lists) */
    bin_early(g, vmax);
    CUDA_CHECK(cudaEventSynchronize(g->halo_counted));
    const unsigned long long *count = g->halo_count_host;
    if (count[np + 1])
        sim_fail("internal error: %llu disks within reach of strips beyond the neighbours %d to %d", count[np + 1],
                 h->nlo, h->nhi);
    int64_t n = 0;
    for (int q = 0; q < np; q++) scount[q] = (int)count[q], n += (int64_t)count[q];
    send_reserve(g, n);
    g->nsend = *nsend = n;
    if (g->peer) region_reserve(g, n);
    else rec_host_reserve(g, n);
    if (n > 0) {
        double *rec = g->peer ? region_records(g->xreg) : g->rec;
        if (!g->peer) rec_reserve(g, n);
        CUDA_CHECK(cudaStreamWaitEvent(g->side, g->halo_counted, 0));
        rank_halo_pack_kernel<<<blocks_for((int64_t)count[np]), THREADS, 0, g->side>>>(
            c->st[c->cur], g->pc, g->wc, d, g->cand, g->halo_count, g->halo_count + np + 2,
            g->send, rec, (int)!g->slots);
        CUDA_LAUNCHED();
        if (!g->peer)
            CUDA_CHECK(cudaMemcpyAsync(g->rec_host, g->rec, (size_t)n * D_LEN * sizeof(double),
                                       cudaMemcpyDeviceToHost, g->side));
        CUDA_CHECK(cudaEventRecord(g->halo_ready, g->side));
        CUDA_CHECK(cudaEventSynchronize(g->halo_ready)); /* not for the binning: what follows on the
                                                            step's stream is launched after it */
    }
    return g->peer ? NULL : g->rec_host;
}

double *gpu_rank_halo_in(GpuRank *g, int64_t n)
{
    pinned_records(&g->halo_host, &g->halo_host_cap, n);
    return g->halo_host;
}

void gpu_rank_set_halo(GpuRank *g, const double *in, int64_t got)
{
    CallClock clock_(g, GPU_HALO_IN);
    rank_reserve(g, g->own + got);
    hkeys_reserve(g, got);
    put_records(g, in, got, g->own, 0);
    g->halo = got;
}

void gpu_rank_export(GpuRank *g, GpuPeer *p)
{
    if (!g->xreg) /* gpu_rank_ready's guess at the halo, unless a test asks for a region that grows */
        region_reserve(g, getenv("SIM_MPI_CUDA_REGION_SLACK") ? 0 : g->own / 16 + 4096);
    memset(p, 0, sizeof *p);
    p->cap = g->xcap;
    p->gen = g->unshared ? 0 : g->xgen;
    memcpy(p->handle, &g->xhandle, sizeof p->handle);
}

int gpu_rank_map(GpuRank *g, int q, int np, const GpuPeer *p)
{
    if (p->gen == 0 || g->unshared) return 0; /* its region, or this rank's, cannot be shared */
    if (np > g->map_np) {
        g->map = (GpuRank::PeerMap *)sim_realloc(g->map, (size_t)np, sizeof *g->map);
        memset(g->map + g->map_np, 0, (size_t)(np - g->map_np) * sizeof *g->map);
        g->map_np = np;
    }
    GpuRank::PeerMap *m = &g->map[q];
    if (m->base && m->gen == p->gen) return 1;
    if (m->base) CUDA_CHECK(cudaIpcCloseMemHandle(m->base)); /* its owner has grown out of it */
    m->base = NULL;
    cudaIpcMemHandle_t h;
    memcpy(&h, p->handle, sizeof h);
    void *base = NULL;
    if (cudaIpcOpenMemHandle(&base, h, cudaIpcMemLazyEnablePeerAccess) != cudaSuccess) {
        cudaGetLastError();
        return 0;
    }
    m->base = (char *)base, m->cap = p->cap, m->gen = p->gen;
    return 1;
}

void gpu_rank_peer(GpuRank *g, int on)
{
    g->peer = on;
    if (!on) gpu_rank_unmap(g);
}

void gpu_rank_unmap(GpuRank *g)
{
    for (int q = 0; q < g->map_np; q++)
        if (g->map[q].base) cudaIpcCloseMemHandle(g->map[q].base), g->map[q].base = NULL;
}

void gpu_rank_set_halo_peer(GpuRank *g, const int *from, const GpuPeer *p, int n)
{
    CallClock clock_(g, GPU_HALO_IN);
    Cuda *c = &g->c;
    int64_t got = 0;
    if (n > g->seg_cap) {
        g->seg = (GpuRank::PeerSeg *)sim_realloc(g->seg, (size_t)n, sizeof *g->seg);
        g->seg_cap = n;
    }
    g->nseg = 0;
    for (int k = 0; k < n; k++) {
        if (p[k].count == 0) continue;
        if (!gpu_rank_map(g, from[k], g->map_np, &p[k]))
            sim_fail("internal error: rank %d's GPU memory could not be mapped", from[k]);
        GpuRank::PeerSeg sg = {from[k], p[k].offset, p[k].count, got};
        g->seg[g->nseg++] = sg;
        got += p[k].count;
    }
    rank_reserve(g, g->own + got);
    hkeys_reserve(g, got);
    rec_reserve(g, got);
    /* the records copied over the devices' link, then put into the slots after the own disks */
    for (int k = 0; k < g->nseg; k++) {
        const GpuRank::PeerSeg *sg = &g->seg[k];
        CUDA_CHECK(cudaMemcpyAsync(g->rec + sg->at * D_LEN, region_records(g->map[sg->q].base) + sg->offset * D_LEN,
                                   (size_t)sg->count * D_LEN * sizeof(double), cudaMemcpyDeviceToDevice, c->stream));
    }
    if (got > 0) {
        rank_put_kernel<<<blocks_for(got), THREADS, 0, c->stream>>>(g->rec, got, c->st[c->cur], NULL, NULL, g->own,
                                                                    c->par, c->wall_hi, c->best_hi, c->best_lo,
                                                                    c->partner);
        CUDA_LAUNCHED();
    }
    g->halo = got;
}

/* Whether this step's wall keys are read through the partners (GATED_WALLS): a step in the slots, whose keys
 * the move before started as cuda's move does, writing a wall key only where there is one (move_kernel's
 * MoveBin). A gathering step's gather starts every slot's keys. */
static bool rank_gated(const GpuRank *g)
{
    return GATED_WALLS && g->slots;
}

/* A round's passes up to the keys that go out, and the copy of its list's length to the host (the
 * caller waits): the first round (first) over the search's list, the others over the live events the
 * last one left. */
static void round_launch(GpuRank *g, int first)
{
    Cuda *c = &g->c;
    int64_t blocks = g->pl.choose_blocks[0];
    if (first && g->settle) { /* the contested events into the other list, counted in counter[6] */
        if (g->halo > 0)
            step_kernel(c, blocks_for(g->halo), THREADS, 0, rank_tally_copies_kernel, slot_where(g), g->own, g->halo,
                        c->partner);
        CUDA_CHECK(cudaMemsetAsync(&g->counter[6], 0, sizeof g->counter[6], c->stream));
        step_kernel(c, blocks, THREADS, 0, settle_kernel, c->ev[0], g->len, c->ev_cap, c->ev[1], &g->counter[6],
                    c->partner, c->best_lo);
        g->list = 1;
        g->len = &g->counter[6];
    }
    if (!first) {
        unsigned long long *next = &g->counter[3 + (g->round & 1)];
        CUDA_CHECK(cudaMemsetAsync(next, 0, sizeof *next, c->stream));
        step_kernel(c, blocks, THREADS, 0, compact_kernel, c->ev[g->list], g->len, c->ev_cap, c->ev[1 - g->list], next,
                    c->partner, rank_gated(g) ? (const uint64_t *)NULL : c->wall_hi, c->best_hi, c->best_lo);
        g->list = 1 - g->list;
        g->len = next;
        step_kernel(c, blocks, THREADS, 0, min_hi_kernel, c->ev[g->list], g->len, c->ev_cap, c->best_hi);
    }
    /* the peer path: this round's keys into the region's half of its parity; a neighbour reads them
     * after the reduction that follows gpu_rank_round on every rank, and before its next one, while this
     * rank writes the other half */
    GpuKey *keys = g->peer ? region_keys(g->xreg, g->xcap, g->round & 1) : g->keys;
    step_kernel(c, blocks, THREADS, 0, min_lo_kernel, c->ev[g->list], g->len, c->ev_cap, c->best_hi, c->best_lo,
                (const unsigned int *)NULL);
    if (g->nsend > 0) {
        step_kernel(c, blocks_for(g->nsend), THREADS, 0, rank_keys_out_kernel, g->send, g->nsend, slot_where(g),
                    c->best_hi, c->best_lo, c->partner, keys);
        if (!g->peer)
            CUDA_CHECK(cudaMemcpyAsync(g->keys_host, g->keys, (size_t)g->nsend * sizeof(GpuKey),
                                       cudaMemcpyDeviceToHost, c->stream));
    }
    CUDA_CHECK(cudaMemcpyAsync(g->counter_host + 3, g->len, sizeof(unsigned long long), cudaMemcpyDeviceToHost,
                               c->stream));
}

/* The search is followed at once by the first round's passes, on a list of any length (their blocks
 * loop), so that the device does not wait for the host between them: the first round then only
 * returns what they found. Where the list was too short, it is made longer and both are launched again
 * (the state the step started from is intact); so too, counting in 32 bits from then on, where a cell of
 * 8-bit counts passed 255 disks (count_add). */
void gpu_rank_detect(GpuRank *g, double vmax)
{
    CallClock clock_(g, GPU_DETECT);
    Cuda *c = &g->c;
    int64_t n = g->own + g->halo;
    Plan *pl = &g->pl;
    plan_step(g, pl, vmax); /* what the gate fits, from the same speed */
    c->n = n;
    pl->went[0] = n;
    if (g->events_room > 0 && c->ev_cap > g->events_room) { /* the test's short list */
        rank_sync(g);
        cudaFree(c->ev[0]), cudaFree(c->ev[1]);
        events_alloc(c, g->events_room);
    }
    bool early = g->early && g->early_cap == g->cap; /* else the buffers grew since: all binned again */
    if (g->early && !early && c->dirty < g->early_len) c->dirty = g->early_len; /* counts to clear first */
    g->early = false;
    int in = c->cur;
    g->settle = settles(c, (double)g->found_last, (double)(n > 0 ? n : 1)); /* from the last step's events */
    for (;;) {
        if (!early) rank_gate(g, NULL, 0, 0.0); /* no keys ahead: the halo comes between two steps */
        if (n > 0 && early) { /* the copies after the own disks binned early, into the same counts */
            bin_slots(g, c->st[in], g->own, g->halo, 0);
            scan_place_launch<false>(c, pl, 0, NULL, NULL, 0, g->early_short, in);
        } else if (n > 0) {
            bin_place_launch<false>(c, pl, 0, in, NULL, NULL, 0, false);
        }
        if (n > 0) {
            /* searched where they are: their keys started by the move and the puts since, else here
             * (after a list too short, again) */
            if (g->slots && !g->started)
                step_kernel(c, blocks_for(n), THREADS, 0, rank_slot_init_kernel, c->st[in], n, c->par, c->wall_hi,
                            c->best_hi, c->best_lo, c->partner);
            else if (!g->slots)
                step_kernel(c, blocks_for(n), THREADS, 0, gather_state_kernel, c->st[in], c->st[1 - in], c->order,
                            n, c->par, c->wall_hi, c->best_hi, LO_AT_EVENT ? (uint64_t *)NULL : c->best_lo,
                            c->partner, c->ctl, g->where, g->own);
            DevState *d = &c->st[g->slots ? in : 1 - in];
            Entries en;
            en.disk = d->d, en.id = d->id;
            en.slot = g->slots ? (int32_t *)c->order : NULL;
            en.wall = c->wall_hi;
            en.wall_gate = rank_gated(g) ? c->partner : NULL; /* the move before kept some wall keys alone */
            en.mid = NULL;
            en.placed = NULL;
            en.rank = c->rank;
            en.rank8 = narrow_counts(c, pl, 0);
            en.patches = NULL;
            en.best_lo = LO_AT_EVENT ? c->best_lo : NULL; /* the search starts its events' second keys */
            en.tally = g->settle ? c->partner : NULL; /* the first round settles (round_launch) */
            en.ties = NULL;
            detect_launch(c, pl, 0, en);
        }
        g->started = false; /* the first round's passes below change them */
        CUDA_CHECK(cudaMemcpyAsync(g->info_host, c->info, sizeof(StepInfo), cudaMemcpyDeviceToHost, c->stream));
        g->list = 0;
        g->round = 0;
        g->len = &c->info->found[0];
        pl->choose_blocks[0] = choose_blocks_for(c, INFINITY);
        round_launch(g, 1);
        rank_sync(g);
        if (g->info_host->outside)
            sim_fail("internal error: %llu disks outside the slab of the grid (%g to %g)", g->info_host->outside,
                     c->lim.x0, c->lim.x1);
        if (g->info_host->crowded) { /* a cell passed 255 disks: 32-bit counts from here on, the search again */
            c->narrow = 0;
            g->crowdings++;
            early = false;
            continue;
        }
        int64_t found = (int64_t)g->info_host->found[0];
        if (found <= c->ev_cap) {
            g->keyed_steps[0] += g->info_host->ahead[0];
            g->keyed_steps[1] += g->info_host->ahead[1];
            g->found_last = found;
            if (g->settle) g->settled[0] += (unsigned long long)found, g->settled[1] += g->counter_host[3];
            pl->choose_blocks[0] = choose_blocks_for(c, (double)found);
            break;
        }
        /* a list too short: longer, and the step's search again */
        cudaFree(c->ev[0]), cudaFree(c->ev[1]);
        events_alloc(c, found + found / 4 + 4096);
        early = false;
        g->searched_again++;
    }
}

int64_t gpu_rank_round(GpuRank *g, int first, const GpuKey **out)
{
    CallClock clock_(g, GPU_ROUND);
    Cuda *c = &g->c;
    if (!first) { /* the first's passes ran behind the search (gpu_rank_detect) */
        round_launch(g, 0);
        rank_sync(g);
    }
    g->round++;
    *out = g->peer ? NULL : g->keys_host;
    int64_t live = (int64_t)g->counter_host[3];
    return live < c->ev_cap ? live : c->ev_cap;
}

GpuKey *gpu_rank_keys_in(GpuRank *g)
{
    return g->hkeys_host;
}

void gpu_rank_accept(GpuRank *g)
{
    CallClock clock_(g, GPU_ACCEPT);
    Cuda *c = &g->c;
    if (g->halo > 0) {
        if (g->peer) {
            for (int k = 0; k < g->nseg; k++) {
                const GpuRank::PeerSeg *sg = &g->seg[k];
                const GpuRank::PeerMap *m = &g->map[sg->q];
                const GpuKey *from = region_keys(m->base, m->cap, (g->round - 1) & 1) + sg->offset;
                CUDA_CHECK(cudaMemcpyAsync(g->hkeys + sg->at, from, (size_t)sg->count * sizeof(GpuKey),
                                           cudaMemcpyDeviceToDevice, c->stream));
            }
        } else {
            CUDA_CHECK(cudaMemcpyAsync(g->hkeys, g->hkeys_host, (size_t)g->halo * sizeof(GpuKey),
                                       cudaMemcpyHostToDevice, c->stream));
        }
        step_kernel(c, blocks_for(g->halo), THREADS, 0, rank_keys_in_kernel, g->hkeys, g->halo, g->own, slot_where(g),
                    c->best_hi, c->best_lo, c->partner);
    }
    step_kernel(c, g->pl.choose_blocks[0], THREADS, 0, accept_kernel, c->ev[g->list], g->len, c->ev_cap, c->best_hi,
                c->best_lo, c->partner, (const unsigned int *)NULL);
    /* no wait: the next round, which always follows, waits for this one's work before the keys' buffer
     * is received into again */
}

void gpu_rank_move(GpuRank *g, double c0, double c1, int first, int last, double reach, GpuMoved *m,
                   const double **leavers)
{
    CallClock clock_(g, GPU_MOVE);
    Cuda *c = &g->c;
    int64_t n = g->own + g->halo;
    /* in: the gathered state, out: the one it came from; a step in the slots moves from the one it
     * searched to the other */
    int in = g->slots ? c->cur : 1 - c->cur, out = 1 - in;
    memset(m, 0, sizeof *m);
    *leavers = g->rec_host;
    g->hvalid = false;
    if (n == 0) {
        g->halo = 0;
        return;
    }
    if (g->halo > 0) {
        step_kernel(c, blocks_for(g->halo), THREADS, 0, rank_mark_copies_kernel, slot_where(g), g->own, g->halo,
                    c->partner);
    }
    int64_t hcap = g->own / 64 + 4096; /* a strip's edges: beyond them, every own disk looked at */
    if (hcap > g->hcap) {
        g->hcap = grown(hcap);
        REGROW(g->hcand, 0, (size_t)g->hcap * sizeof(int32_t), "the halo");
    }
    int64_t guess = 0;
    /* the own disks kept in their slots of st[out] (the state it moves stays as it is), then the holes
     * below their count filled from above it; moved again, the leavers alone */
    for (int again = 0;; again = 1) {
        int64_t room = !again && g->leavers_room >= 0 && g->leavers_room < g->rec_cap ? g->leavers_room : g->rec_cap;
        RankMove rm = {c0, c1, c0 + reach, c1 - reach, first, last, again, g->rec, g->holes, room, g->hcand, g->hcap,
                       g->counter};
        fill_reserve(g, room + g->halo);
        if (!again) { /* moved again: the kept disks' counts stand */
            CUDA_CHECK(cudaMemsetAsync(g->counter, 0, COUNTERS * sizeof(unsigned long long), c->stream));
            CUDA_CHECK(cudaMemsetAsync(&c->info->vmax, 0, sizeof c->info->vmax, c->stream));
            CUDA_CHECK(cudaMemsetAsync(&c->info->events, 0, sizeof c->info->events, c->stream));
        } else {
            CUDA_CHECK(cudaMemsetAsync(&g->counter[1], 0, sizeof(unsigned long long), c->stream));
        }
        /* the kept disks keyed on the grid bin_early's gate fitted ahead, their event keys started in place */
        MoveBin mb = move_starts_keys(c, g->settle);
        auto move = c->ahead_slack > 0 ? (MOVE_LOOP ? move_kernel<true, true, true> : move_kernel<true, true, false>)
                                       : (MOVE_LOOP ? move_kernel<true, false, true> : move_kernel<true, false, false>);
        step_kernel(c, MOVE_LOOP ? loop_blocks(c, n, MOVE_LOOP) : blocks_for(n), THREADS, 0, move, c->st[in],
                    c->st[out], n, c->par, c->partner, c->wall_hi, c->best_hi, g->pc, g->wc, c->info, c->ev_cap,
                    c->ctl, rm, mb);
        /* the fill: few blocks, looping over the leavers and the copies */
        int64_t blocks = loop_blocks(c, room + g->halo, 1);
        step_kernel(c, blocks, THREADS, 0, rank_holes_kernel, c->st[out], g->own, g->halo, slot_where(g),
                    (const int32_t *)g->holes, room, g->counter, g->fill_to, g->fill_from);
        step_kernel(c, blocks, THREADS, 0, rank_fill_kernel, c->st[out], (const int32_t *)g->fill_to,
                    (const int32_t *)g->fill_from, room, rm, c->wall_hi, c->best_hi, c->best_lo, c->partner,
                    c->ahead_slack > 0 ? c->keys : (uint32_t *)NULL);
        CUDA_CHECK(cudaMemcpyAsync(g->counter_host, g->counter, COUNTERS * sizeof(unsigned long long),
                                   cudaMemcpyDeviceToHost, c->stream));
        CUDA_CHECK(cudaMemcpyAsync(g->info_host, c->info, sizeof(StepInfo), cudaMemcpyDeviceToHost, c->stream));
        /* the leavers' records as many as twice the last step's, before the wait: mostly all of them */
        guess = 2 * g->left_last + 1024;
        guess = guess < room ? guess : room;
        rec_host_reserve(g, guess);
        CUDA_CHECK(cudaMemcpyAsync(g->rec_host, g->rec, (size_t)guess * D_LEN * sizeof(double), cudaMemcpyDeviceToHost,
                                   c->stream));
        rank_sync(g);
        if ((int64_t)g->counter_host[1] <= room) break;
        rec_reserve(g, (int64_t)g->counter_host[1]); /* more leavers than room: the move again */
        g->moved_again++;
    }
    int64_t left = (int64_t)g->counter_host[1], kept = g->own - left;
    if (g->counter_host[0] != g->counter_host[5]) /* as many holes as kept disks above the count: always */
        sim_fail("internal error: %llu holes below the kept disks' count, %llu kept disks above it",
                 g->counter_host[0], g->counter_host[5]);
    if (g->info_host->outside) /* a kept disk's key outside the grid ahead: never (gpu_slab's reach) */
        sim_fail("internal error: %llu disks keyed outside the slab of the grid ahead", g->info_host->outside);
    g->keyed = c->ahead_slack > 0 ? kept : 0;
    g->keyed_grown = c->grown;
    g->hn = (int64_t)g->counter_host[2];
    g->hvalid = g->hn <= g->hcap;
    g->hkept = kept;
    g->hc0 = c0, g->hc1 = c1, g->hreach = reach;
    g->left_last = left;
    if (left > guess) {
        rec_host_reserve(g, left);
        CUDA_CHECK(cudaMemcpyAsync(g->rec_host, g->rec, (size_t)left * D_LEN * sizeof(double), cudaMemcpyDeviceToHost,
                                   c->stream));
        rank_sync(g);
    }
    *leavers = g->rec_host;
    c->cur = out;
    g->started = true;
    g->own = kept;
    g->halo = 0;
    m->leavers = left;
    m->vmax = bits_speed(g->info_host->vmax);
    m->events = g->info_host->events;
    m->tests = g->info_host->tests;
}
