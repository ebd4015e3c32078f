/* mpi_cuda_kernels.cuh: the device code of a GPU rank beyond cuda's kernels: records in and out, the halo's
 * count and pack, the keys that cross ranks, the copies' marks, the fill of the move's holes.
 * Part of mpi_cuda.cu, which includes it after cuda.cu and mpi_cuda.h. */

/* Records into slots at..at + n, with their counts where pc; their event keys started (slot_init). */
__global__ void rank_put_kernel(const double *rec, int64_t n, DevState st, int32_t *pc, int32_t *wc, int64_t at,
                                Params par, uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo, int32_t *partner)
{
    int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    const double *d = rec + i * D_LEN;
    real2 pos, vel;
    pos.x = (real)d[D_X], pos.y = (real)d[D_Y], vel.x = (real)d[D_VX], vel.y = (real)d[D_VY];
    st.d[at + i].pos = pos;
    st.d[at + i].vel = vel;
    int32_t id = (int32_t)d[D_ID];
    st.id[at + i] = id;
    if (pc) pc[id] = (int32_t)d[D_PC], wc[id] = (int32_t)d[D_WC];
    slot_init(at + i, wall_key(pos.x, pos.y, vel.x, vel.y, par), wall_hi, best_hi, best_lo, partner);
}

/* Slots slot[i] (first + i where slot is NULL), i < n, as records. */
__global__ void rank_pack_kernel(DevState st, const int32_t *pc, const int32_t *wc, const int32_t *slot, int64_t first,
                                 int64_t n, double *rec)
{
    int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    int64_t s = slot ? slot[i] : first + i;
    int32_t id = st.id[s];
    write_record(rec + i * D_LEN, st.d[s].pos, st.d[s].vel, id, pc[id], wc[id]);
}

/* The own disks that go to other ranks (h's arrays on the device): how many to each rank into count[0 ..
 * np), their slots listed in cand (count[np] of them); count[np + 1] counts disks whose span reaches
 * beyond the neighbours, which never happens. The slots looked at: list[0 .. nlist), then first to own. */
__global__ void rank_halo_count_kernel(DevState st, const int32_t *list, int64_t nlist, int64_t first, int64_t own,
                                       HaloView h, int32_t *cand, unsigned long long *count)
{
    int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= nlist + own - first) return;
    int64_t s = i < nlist ? list[i] : first + i - nlist;
    if (i < nlist && s >= first) return; /* moved below first since it was listed (rank_fill_kernel) */
    double x = (double)st.d[s].pos.x;
    if (halo_inside(&h, x)) return;
    int lo, hi, n = 0;
    if (!halo_span(&h, x, &lo, &hi)) {
        atomicAdd(&count[h.np + 1], 1ull);
        return;
    }
    for (int k = lo; k <= hi; k++)
        if (halo_takes(&h, x, k)) atomicAdd(&count[k], 1ull), n++;
    if (n) cand[list_append(&count[h.np])] = (int32_t)s;
}

/* The listed disks as records, in rank order (rank k's after the counts of the ranks before it), in any
 * order within a rank's; send[] the slot of each record. fill: np places, cleared. */
__global__ void rank_halo_pack_kernel(DevState st, const int32_t *pc, const int32_t *wc, HaloView h,
                                      const int32_t *cand, const unsigned long long *count, unsigned long long *fill,
                                      int32_t *send, double *rec, int mark)
{
    int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= (int64_t)count[h.np]) return;
    int32_t s = cand[i], id = st.id[s]; /* cand holds a slot once (rank_halo_count_kernel looks at each once) */
    if (mark) st.id[s] = (int32_t)((uint32_t)id | ID_SENT); /* for the gather (where) */
    real2 pos = st.d[s].pos;
    double x = (double)pos.x;
    int lo, hi;
    (void)halo_span(&h, x, &lo, &hi);
    for (int k = lo; k <= hi; k++) {
        if (!halo_takes(&h, x, k)) continue;
        unsigned long long at = atomicAdd(&fill[k], 1ull);
        for (int q = 0; q < k; q++) at += count[q];
        send[at] = s;
        write_record(rec + at * D_LEN, pos, st.d[s].vel, id, pc[id], wc[id]);
    }
}

__global__ void rank_keys_out_kernel(const int32_t *send, int64_t nsend, const uint32_t *where, const uint64_t *best_hi,
                                     const uint64_t *best_lo, const int32_t *partner, GpuKey *keys)
{
    int64_t k = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= nsend) return;
    uint32_t p = where ? where[send[k]] : (uint32_t)send[k]; /* NULL: a step in the slots */
    GpuKey key = {best_hi[p], best_lo[p], partner[p] >= 0};
    keys[k] = key;
}

/* The copies' keys from their owners, over what this rank found for them; a decided copy takes itself as
 * partner (any partner drops its events from the lists; the move leaves copies alone). */
__global__ void rank_keys_in_kernel(const GpuKey *keys, int64_t halo, int64_t own, const uint32_t *where,
                                    uint64_t *best_hi, uint64_t *best_lo, int32_t *partner)
{
    int64_t k = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= halo) return;
    uint32_t p = where ? where[own + k] : (uint32_t)(own + k); /* NULL: a step in the slots */
    GpuKey key = keys[k];
    best_hi[p] = key.hi;
    best_lo[p] = key.lo;
    if (key.decided && partner[p] < 0) partner[p] = (int32_t)p;
}

/* A step that settles (GpuRank.settle): each copy's partner lowered by two tallies after the search, so that
 * settle_kernel takes every event of a copy as contested. A copy's tally counts only the events this rank
 * found, not those of its owner's other neighbours; its owner, whose search finds each of the copy's events
 * (the halo reaches every disk near enough), settles it or leaves it to the rounds, and the rounds' keys bring
 * its decision here. Its low two bits stay (tally_base). */
__global__ void rank_tally_copies_kernel(const uint32_t *where, int64_t own, int64_t halo, int32_t *partner)
{
    int64_t k = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (k < halo) partner[where ? where[own + k] : own + k] -= 2 * PARTNER_TALLY;
}

/* After the rounds: the copies' places (where after the own slots; NULL: in the slots) marked for the
 * move, which leaves them be (their partners are of no use after the rounds). */
__global__ void rank_mark_copies_kernel(const uint32_t *where, int64_t own, int64_t halo, int32_t *partner)
{
    int64_t k = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (k < halo) partner[where ? where[own + k] : own + k] = PARTNER_COPY;
}

/* A step in the slots: each slot's event keys started, as the gather starts them (slot_init), where the
 * move and the puts since have not (GpuRank's started: the search done again after a list too short). */
__global__ void rank_slot_init_kernel(DevState st, int64_t n, Params par, uint64_t *wall_hi, uint64_t *best_hi,
                                      uint64_t *best_lo, int32_t *partner)
{
    after_previous();
    int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x;
    if (s >= n) return;
    real2 pos = st.d[s].pos, vel = st.d[s].vel;
    slot_init(s, wall_key(pos.x, pos.y, vel.x, vel.y, par), wall_hi, best_hi, best_lo, partner);
}

/* After a move (RankMove) that kept own - count[1] disks: the slots below that count that no kept disk
 * holds (the leavers' and the copies', at where[own + k] after a gather, else above the own disks) into
 * to (count[0]), and the kept disks at or above it into from (count[5]); as many of each. Nothing where
 * the leavers overflowed their room (the move again first). */
__global__ void rank_holes_kernel(DevState out, int64_t own, int64_t halo, const uint32_t *where,
                                  const int32_t *holes, int64_t room, unsigned long long *count, int32_t *to,
                                  int32_t *from)
{
    int64_t left = (int64_t)count[1];
    if (left > room) return;
    int64_t kept = own - left, step = (int64_t)gridDim.x * blockDim.x;
    for (int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x; i < left + halo; i += step) {
        int64_t s = i < left ? holes[i] : where ? where[own + i - left] : own + i - left;
        if (s < kept) to[list_append(&count[0])] = (int32_t)s;
        if (out.id[kept + i] != RANK_HOLE) from[list_append(&count[5])] = (int32_t)(kept + i);
    }
}

/* The holes below the kept count filled from the slots above it (rank_holes_kernel), each moved disk's
 * event keys started and its cell key (keys, where the move keyed them) moved with it; those within
 * reach of the cuts listed for the next halo, as the move lists them. The move kept a wall key only where
 * the partner it started says there is one (GATED_WALLS): elsewhere the key is an older step's (without
 * GATED_WALLS every key is the move's, and with WALL_PENDING 0 no partner says so). */
__global__ void rank_fill_kernel(DevState out, const int32_t *to, const int32_t *from, int64_t room, RankMove rm,
                                 uint64_t *wall_hi, uint64_t *best_hi, uint64_t *best_lo, int32_t *partner,
                                 uint32_t *keys)
{
    if ((int64_t)rm.count[1] > room) return;
    /* as many of each, always (the host checks): the fewer, so that no unlisted slot is read */
    int64_t m = (int64_t)(rm.count[0] < rm.count[5] ? rm.count[0] : rm.count[5]);
    int64_t step = (int64_t)gridDim.x * blockDim.x;
    for (int64_t i = (int64_t)blockIdx.x * blockDim.x + threadIdx.x; i < m; i += step) {
        int32_t a = to[i], b = from[i];
        Disk disk = out.d[b];
        out.d[a] = disk;
        out.id[a] = out.id[b];
        slot_init(a, !GATED_WALLS || wall_pending(partner[b]) ? wall_hi[b] : NO_EVENT, wall_hi, best_hi, best_lo,
                  partner);
        if (keys) keys[a] = keys[b];
        rank_list_near(rm, (double)disk.pos.x, a);
    }
}
