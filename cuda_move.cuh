/* cuda_move.cuh: the move: each disk from the old buffers into the new.
 * Part of cuda.cu, which includes it after its constants and the files before it (cuda.cu's list). */

/* ==== move =============================================================================================== */

/* A GPU rank's step (mpi_cuda.cu): its slots hold its own disks and copies of other ranks' disks (the
 * halo), which the move leaves where they are (their partner PARTNER_COPY, rank_mark_copies_kernel). */
#define PARTNER_COPY (-2)
typedef struct {
    /* the own disks whose x stays in [c0, c1) (no bound below where first, above where last) keep their
     * slots in the new state, their event keys started in place, as cuda's move starts them; the others
     * (leavers, count[1]) go as records of mpi_cuda.h into rec, up to cap, each one's slot into holes at
     * the record's place, and their slots in the new state are marked RANK_HOLE (rank_fill_kernel then
     * fills the holes below the kept count from the slots above it). The kept ones not within (h0, h1),
     * which the next step's halo may take, are listed into hcand (count[2] of them, up to hcap). again:
     * the move once more for the leavers alone, theirs having overflowed rec (the kept ones are in place,
     * their keys started; the counts by disk index have this step's collisions already). */
    double c0, c1, h0, h1;
    int first, last, again;
    double *rec;
    int32_t *holes;
    int64_t cap;
    int32_t *hcand;
    int64_t hcap;
    unsigned long long *count;
} RankMove;
#define RANK_HOLE (-1) /* a leaver's or a copy's slot in the new state (its id) */

/* A disk as a record of mpi_cuda.h (D_LEN doubles), for another rank or the host. */
static __device__ __forceinline__ void write_record(double *d, real2 pos, real2 vel, int32_t id, int32_t pc,
                                                    int32_t wc)
{
    d[D_ID] = id, d[D_X] = pos.x, d[D_Y] = pos.y, d[D_VX] = vel.x, d[D_VY] = vel.y, d[D_PC] = pc, d[D_WC] = wc;
    d[D_WI] = 0;
}

/* A GPU rank's own disk in slot s after its move: true where it stays in the strip (the caller keeps
 * it), else packed for another rank, its slot noted as a hole. */
static __device__ __forceinline__ bool rank_stays(const RankMove &rm, int64_t s, real2 pos, real2 vel, int32_t id,
                                                  const int32_t *pc, const int32_t *wc)
{
    double x = (double)pos.x;
    if ((rm.first || x >= rm.c0) && (rm.last || x < rm.c1)) return true;
    unsigned long long k = list_append(&rm.count[1]);
    /* beyond cap the host makes room and moves the step again */
    if ((int64_t)k < rm.cap) {
        write_record(rm.rec + k * D_LEN, pos, vel, id, pc[id], wc[id]);
        rm.holes[k] = (int32_t)s;
    }
    return false;
}

/* A GPU rank's kept disk in slot s at x: listed for the next step's halo where it lies beyond (h0, h1),
 * as the move and the fill of its holes (mpi_cuda.cu) list them; beyond hcap the next step's halo looks
 * at every own disk. */
static __device__ __forceinline__ void rank_list_near(const RankMove &rm, double x, int64_t s)
{
    if (!(x > rm.h0 && x < rm.h1)) {
        unsigned long long h = list_append(&rm.count[2]);
        if ((int64_t)h < rm.hcap) rm.hcand[h] = (int32_t)s;
    }
}

/* One slice a step: the move also keys its disks' cells for the next step, each slot being its entry, on
 * the grid the gate fitted ahead (gate_kernel); the next step only counts them (count_kernel), and spares
 * a pass over the state. Gas of 1e7 on the H100: 5.595e9 -> 5.769e9 particle-steps/s, dense gas 4.645e9
 * -> 4.749e9 (bench/gpu_h100_goals.log, 71b5eb2's section). Counting in the move as well, with an atomic a
 * disk, cost the move more than it saved (bench/gpu_h100_variants.log 12a). A GPU rank's move keys the
 * own disks it keeps, in their slots (mpi_cuda.cu, bin_early). */
typedef struct {
    const Grid *grid;
    uint32_t *keys;
    /* the next step's disks stay in these slots (cuda's step_launch; a GPU rank's kept disks, RankMove),
     * and their event keys start here, as the gather would start them (slot_init): else NULL */
    uint64_t *wall_hi, *best_hi, *best_lo;
    int32_t *partner;
    /* this step's disks stayed in their slots: the gather before wrote out's indices and the move after
     * it in's, slot for slot, so out holds them already */
    int ids_alike;
    int gated;  /* the wall keys written only where there is one (GATED_WALLS) */
    int marked; /* the step settled, its partners marking the disks that had events (slot_init) */
} MoveBin;

/* The move (cuda's and a GPU rank's) launches MOVE_LOOP blocks a multiprocessor (as many as its registers
 * let stay), whose threads take the disks in turns, where a block of THREADS disks each left the
 * multiprocessor only once its slowest warp was done. Gas of 1e7 on one H200: cuda's move 21.0 -> 19.7 ms
 * over 50 steps, 7.84e9 -> 8.00e9 particle-steps/s; but the dense gas's 23.0 -> 23.6 ms, 6.04e9 -> 6.00e9,
 * and the gas of 1e8 7.62e9 either way; at 3 blocks slower (bench/gpu_h100_variants.log 19). 0: a block a
 * THREADS disks. */
#ifndef MOVE_LOOP
#define MOVE_LOOP 4
#endif

/* A disk's collisions counted by a reduction (atomicAdd, its value unused), which its lane issues and leaves:
 * a load and a store waited on the count's load, a third one after the state's and the partner's, at a disk
 * index scattered over the counts. Gas of 1e7 on one H200: the move 17.73 -> 14.82 ms over 50 steps, 8.33e9 ->
 * 8.75e9 particle-steps/s; dense gas 21.14 -> 16.13 ms, 6.20e9 -> 6.59e9 (bench/gpu_h100_variants.log 25x).
 * Each disk is counted by its own lane alone, so either way counts the same. 0: a load and a store. */
#ifndef COUNT_RED
#define COUNT_RED 1
#endif

/* Slot s's disk for the move: its state, its accepted partner and, where WALL (WALL_PENDING 0), its wall
 * event (its index is loaded where the move needs it, move_kernel). The move (cuda's and a GPU rank's) knows an
 * accepted wall event by the partner (PARTNER_WALL, or a settling's mark of it) and loads its key for those
 * disks alone: 8 bytes fewer for each of the others.
 * On one H200 the gas of 1e7's move 18.31 -> 17.70 ms over 50 steps, the dense gas's 21.77 -> 20.95; the key
 * computed again from the state instead, as fast there, cost the random scene's move 12%, its fast disks
 * meeting walls often (bench/gpu_h100_variants.log 25g). */
template <bool WALL>
static __device__ __forceinline__ void move_load(const DevState &in, const int32_t *partner, const uint64_t *wall_hi,
                                                 int64_t s, real2 &pos, real2 &vel, int32_t &o, uint64_t &wall)
{
    pos = in.d[s].pos;
    vel = in.d[s].vel;
    o = partner[s];
    if (WALL) wall = wall_hi[s];
}

/* Old buffers in, new buffers out. A disk with no accepted pair and a wall event within the step has
 * had that wall event accepted: no remaining pair event of it was smaller. A step whose pair events
 * overflowed the list decided on part of them only: it is refused here, before anything is written.
 * pc and wc count collisions by disk index (RANK: a GPU rank's step, RankMove's). BIN: the disks keyed for the
 * next step (MoveBin). */
template <bool RANK, bool BIN, bool LOOP>
__global__ void move_kernel(DevState in, DevState out, int64_t n, Params par, const int32_t *partner,
                            const uint64_t *wall_hi, const uint64_t *best_hi, int32_t *pc, int32_t *wc,
                            StepInfo *info, int64_t cap, Control *ctl, RankMove rm, MoveBin mb)
{
    after_previous();
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    real2 pos = {0, 0}, vel = {0, 0};
    int32_t id = 0, o = -1;
    uint64_t wall = NO_EVENT;
    if (s < n) /* loaded before the checks below, so that their loads overlap */
        move_load<!WALL_PENDING>(in, partner, wall_hi, s, pos, vel, o, wall);
    if (refused(ctl)) return;
    unsigned long long most = 0;
    for (int w = 0; w < WMAX; w++) most = info->found[w] > most ? info->found[w] : most;
    if (most > (unsigned long long)cap || info->crowded) {
        if (blockIdx.x == 0 && threadIdx.x == 0) {
            ctl->overflow = most > (unsigned long long)cap ? most : 0;
            ctl->crowded = info->crowded;
            ctl->refused = 1;
        }
        return;
    }
    real vabs = 0;
    unsigned long long accepted = 0;
    for (;;) { /* LOOP: over the grid's disks, a thread's in turn; else once */
        int dp = 0, dw = 0; /* collisions with a disk, with a wall */
        /* a rank's copies stay as they are, their slots holes in out; moved again, a rank's kept disks stay
         * too (their keys started) */
        if (RANK && s < n && o == PARTNER_COPY && !rm.again) out.id[s] = RANK_HOLE;
        if (s < n && (!RANK || (o != PARTNER_COPY && (!rm.again || out.id[s] == RANK_HOLE)))) {
            const int32_t o_in = o; /* the partner as loaded (slot_init) */
            real lo = par.lo, hi = par.hi;
            real x = pos.x, y = pos.y, vx = vel.x, vy = vel.y;
            /* a wall event left pending, by -3 or a settling's mark of it (settle_kernel) */
            if (!WALL_PENDING ? o < 0 && wall != NO_EVENT : wall_pending(o))
                o = (int32_t)s;
            /* the index counts collisions, orders a pair and goes with the disk where its slot changes:
             * a disk flying free in a step that keeps the slots needs none (4 of the move's 104 bytes) */
            if (RANK || !BIN || !mb.ids_alike || o >= 0) id = in.id[s];
            if (o < 0) {
                x = x + vx;
                y = y + vy;
            } else if (o == s) {
                if (WALL_PENDING) wall = wall_hi[s];
                real t1 = key_time(wall);
                wall_bounce(&x, &y, &vx, &vy, t1, lo, hi);
                finish_step(&x, &y, vx, vy, t1, lo, hi);
                dw = 1;
                accepted += !RANK || !rm.again;
            } else {
                /* both partners compute the contact with the lower original index as i, then each
                 * finishes its own side: the arithmetic of pair_collide */
                real t1 = key_time(best_hi[s]);
                real2 pos2 = in.d[o].pos, vel2 = in.d[o].vel;
                real x2 = pos2.x, y2 = pos2.y, vx2 = vel2.x, vy2 = vel2.y;
                int mine_first = id < in.id[o];
                real xi = mine_first ? x : x2, yi = mine_first ? y : y2;
                real vxi = mine_first ? vx : vx2, vyi = mine_first ? vy : vy2;
                real xj = mine_first ? x2 : x, yj = mine_first ? y2 : y;
                real vxj = mine_first ? vx2 : vx, vyj = mine_first ? vy2 : vy;
                if (par.periodic)
                    (void)pair_contact_wrap(&xi, &yi, &vxi, &vyi, &xj, &yj, &vxj, &vyj, t1, par.L, par.half);
                else
                    (void)pair_contact(&xi, &yi, &vxi, &vyi, &xj, &yj, &vxj, &vyj, t1);
                x = mine_first ? xi : xj, y = mine_first ? yi : yj;
                vx = mine_first ? vxi : vxj, vy = mine_first ? vyi : vyj;
                if (par.periodic)
                    fly_rest(&x, &y, vx, vy, t1);
                else
                    finish_step(&x, &y, vx, vy, t1, lo, hi);
                dp = 1;
                accepted += mine_first && (!RANK || !rm.again);
            }
            if (!RANK || !rm.again) {
#if COUNT_RED
                if (dp) atomicAdd(&pc[id], 1);
                if (dw) atomicAdd(&wc[id], 1);
#else
                if (dp) pc[id]++;
                if (dw) wc[id]++;
#endif
            }
            real2 pos1, vel1;
            pos1.x = par.periodic ? wrap_coord(x, par.L) : clamp_coord(x, lo, hi);
            pos1.y = par.periodic ? wrap_coord(y, par.L) : clamp_coord(y, lo, hi);
            vel1.x = vx;
            vel1.y = vy;
            bool stays = !RANK || rank_stays(rm, s, pos1, vel1, id, pc, wc);
            if (RANK && rm.again) { /* the leaver's record alone (rank_stays) */
            } else if (stays) {
                out.d[s].pos = pos1, out.d[s].vel = vel1;
                if (RANK || !BIN || !mb.ids_alike) out.id[s] = id;
            } else {
                out.id[s] = RANK_HOLE;
            }
            if (RANK && stays && !rm.again) rank_list_near(rm, (double)pos1.x, s);
            if ((BIN || RANK) && stays && (!RANK || !rm.again)) {
                /* as bin_kernel keys the entry of slot s in a step of one slice */
                if (BIN) mb.keys[s] = cell_key<false>(*mb.grid, pos1, vel1, slice_mid(0, 0, 1), 0, info);
                /* slot s's keys are read by this thread alone in this kernel, above */
                if (mb.wall_hi)
                    slot_init(s, wall_key(pos1.x, pos1.y, vel1.x, vel1.y, par), mb.wall_hi, mb.best_hi, mb.best_lo,
                              mb.partner, mb.gated, o_in, mb.marked);
            }
            real ax = SIM_FABS(vx), ay = SIM_FABS(vy);
            vabs = ax < ay ? (ay > vabs ? ay : vabs) : (ax > vabs ? ax : vabs);
        }
        if (!LOOP) break;
        s += (int64_t)gridDim.x * blockDim.x;
        if (s >= n) break;
        move_load<!WALL_PENDING>(in, partner, wall_hi, s, pos, vel, o, wall);
    }
    typedef cub::BlockReduce<real, THREADS> ReduceR;
    typedef cub::BlockReduce<unsigned long long, THREADS> ReduceU;
    __shared__ typename ReduceR::TempStorage tmp_r;
    __shared__ typename ReduceU::TempStorage tmp_u;
    real m = ReduceR(tmp_r).Reduce(vabs, cuda::maximum<>());
    unsigned long long a = ReduceU(tmp_u).Sum(accepted);
    if (threadIdx.x == 0) {
        atomicMax(&info->vmax, (unsigned long long)__double_as_longlong((double)m));
        if (a) atomicAdd(&info->events, a);
    }
}

/* Print mode: the state back in original index order, for the copy to the host. */
__global__ void unpermute_kernel(DevState st, int64_t n, real *x, real *y, real *vx, real *vy,
                                 const Control *ctl)
{
    if (refused(ctl)) return;
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (s >= n) return;
    int32_t i = st.id[s];
    real2 pos = st.d[s].pos, vel = st.d[s].vel;
    x[i] = pos.x;
    y[i] = pos.y;
    vx[i] = vel.x;
    vy[i] = vel.y;
}

/* The input's state, in original order, into the first state buffer (slot s holds disk s). */
__global__ void pair_up_kernel(DevState st, int64_t n, const real *x, const real *y, const real *vx, const real *vy)
{
    int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    real2 pos, vel;
    pos.x = x[i];
    pos.y = y[i];
    vel.x = vx[i];
    vel.y = vy[i];
    st.d[i].pos = pos;
    st.d[i].vel = vel;
    st.id[i] = (int32_t)i;
}
