/* mpi.c: the MPI backend: the box cut into np vertical strips, one per rank (mpi.h), each rank holding
 * the disks whose centres lie in its strip and, during a step, copies of the disks of other strips
 * within reach of its own (the halo). A step (SPEC.md 3) on every rank:
 * 1. every rank knows a bound on the fastest speed (run_steps), which sets the reach: two disks
 *    farther apart than 2r + twice that speed cannot meet within the step; a rank's neighbours are
 *    the ranks whose strips lie within twice the reach of its own;
 * 2. each rank sends copies of its disks within reach of another strip to that strip's rank;
 * 3. omp's broad phase (omp_broad.c) finds the wall and pair events of the rank's disks and halo, on
 *    the rank's threads, over a grid that covers the strip and its halo;
 * 4. the ranks choose in rounds: an event is accepted once it is the smallest live event of both its
 *    disks (live: neither disk decided); after each round the owners send their disks' smallest keys
 *    and decisions to the ranks that hold copies; a rank's rounds end once none of its own disks has a
 *    live event. That is SPEC.md 3.3's greedy walk for any number of ranks and threads, and an event
 *    between disks of two ranks is decided alike on both;
 * 5. each rank moves its own disks in place (a pair of own disks together, a disk and a copy through
 *    pair_contact and finish_step for its side: copies keep the state at the start of the step), and
 *    disks that left the strip go to the rank of their new strip.
 * Within a step a rank exchanges with its neighbours only (point to point), so it waits for them and
 * not for every rank, and a step's messages do not grow with the number of ranks.
 * The choice and the move touch only the own disks with an event (nodes) and the halo's keys beyond
 * the disks themselves: a rank's step then reads and writes little more than its state, which on a
 * rank of 2.5e5 disks about fits a shared last-level cache's share.
 * The strips start with equal counts of disks (cuts placed as the input is shared out); with
 * --balance K the cuts move every K steps so that the ranks' measured work evens out (balance).
 * Input, output and the pressure's sum go through the ranks' own disks too (mpi_io.c): no rank ever
 * holds the whole state (but for standard input and random placement, read or made on rank 0).
 * Built with MPI_CUDA (mpi_cuda), the same steps run each rank's disks on a GPU (run_steps_gpu): the
 * GPU does each phase's work (mpi_cuda.cu), this file the exchanges, each round of step 4 with one
 * exchange of keys.
 */
#define _XOPEN_SOURCE 700 /* getrusage */
#include "mpi.h"
#include "mpi_cuda.h"
#include "omp_team.h"

#include <limits.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <omp.h>
#include <sys/resource.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>


static uint64_t bytes_sent; /* to other ranks, by exchange (--stats) */
enum { TAG_HALO = 1, TAG_MIGRATE }; /* the steps' messages between neighbours */
static double waited;       /* seconds in the steps' MPI calls: what the balance leaves out */

/* ---- disks on the wire: D_LEN doubles each (mpi_cuda.h) ------------------------------------------ */

static void pack(const Slots *s, int64_t q, double *d)
{
    d[D_ID] = s->id[q], d[D_X] = s->x[q], d[D_Y] = s->y[q], d[D_VX] = s->vx[q], d[D_VY] = s->vy[q];
    d[D_PC] = s->pc[q], d[D_WC] = s->wc[q], d[D_WI] = s->wi ? s->wi[q] : 0;
}

static void unpack(Slots *s, int64_t q, const double *d)
{
    s->id[q] = (int32_t)d[D_ID], s->x[q] = (real)d[D_X], s->y[q] = (real)d[D_Y];
    s->vx[q] = (real)d[D_VX], s->vy[q] = (real)d[D_VY];
    s->pc[q] = (int32_t)d[D_PC], s->wc[q] = (int32_t)d[D_WC];
    if (s->wi) s->wi[q] = d[D_WI];
}

/* Slots 0 to n - 1 of from into to (wi where both have it), on nt threads: one thread took some 30 ns a
 * disk, most of it the faults of to's fresh pages. */
static void copy_own(Slots *to, const Slots *from, int64_t n, int nt)
{
#pragma omp parallel for schedule(static) num_threads(mpi_pass_threads(nt, n))
    for (int64_t q = 0; q < n; q++) {
        to->x[q] = from->x[q], to->y[q] = from->y[q], to->vx[q] = from->vx[q], to->vy[q] = from->vy[q];
        to->id[q] = from->id[q], to->pc[q] = from->pc[q], to->wc[q] = from->wc[q];
        if (to->wi) to->wi[q] = from->wi ? from->wi[q] : 0;
    }
}

/* mpi_alltoallv of records of `width` doubles within a step, its bytes and seconds counted. */
static double *exchange_known(const double *out, const int *count, int width, int64_t *got, const int *rcount)
{
    for (int q = 0; q < mpi_np; q++)
        if (q != mpi_me) bytes_sent += (uint64_t)count[q] * (uint64_t)width * sizeof(double);
    double t0 = MPI_Wtime();
    double *in = mpi_alltoallv(out, count, rcount, (size_t)width * sizeof(double), got);
    waited += MPI_Wtime() - t0;
    return in;
}

/* exchange_known, the counts sent first (rcount[q] is set to rank q's). */
static double *exchange(const double *out, const int *count, int width, int64_t *got, int *rcount)
{
    double t0 = MPI_Wtime();
    MPI_Alltoall(count, 1, MPI_INT, rcount, 1, MPI_INT, MPI_COMM_WORLD);
    waited += MPI_Wtime() - t0;
    return exchange_known(out, count, width, got, rcount);
}

/* The neighbours of this rank's strip for a reach: the ranks lo .. hi around it (itself included)
 * whose strips lie within twice the reach of its own. Every rank finds the same relation (the gap
 * between strips a < b is cut[b] - cut[a + 1] on both), so it is symmetric; twice the reach makes it
 * hold every strip that a disk within the reach of this one's can lie in, roundings included. */
static void neighbours(double reach, int *lo, int *hi)
{
    int me = mpi_me;
    *lo = *hi = me;
    while (*lo > 0 && mpi_cut[me] - mpi_cut[*lo] <= 2 * reach) --*lo;
    while (*hi < mpi_np - 1 && mpi_cut[*hi + 1] - mpi_cut[me + 1] <= 2 * reach) ++*hi;
}

/* The periodic box (SPEC.md 7): the strips wrap, the first and the last are neighbours. The cyclic
 * gap between strips a and b, the same on both ranks (computed from the lower and the higher). */
static double cyclic_gap(int a, int b, double L)
{
    int lo = a < b ? a : b, hi = a < b ? b : a;
    double inner = mpi_cut[hi] - mpi_cut[lo + 1], outer = (L - mpi_cut[hi + 1]) + mpi_cut[lo];
    return inner < outer ? inner : outer;
}

/* Whether rank q's strip and its halo (the reach either side) would hold some disk twice, in two
 * images of the box: then q holds every disk, the whole torus, its grid wrapping along x too. With a
 * margin of a reach, so that any two disks within reach of each other in q's region are so in its
 * frame (the images nearest the strip's middle). Alike on every rank. */
static int whole_torus(int q, double reach, double L)
{
    return (mpi_cut[q + 1] - mpi_cut[q]) + 3 * reach >= L;
}

/* Whether rank q of a step's lo .. hi is a halo's partner: another rank, a neighbour (near[q], or every
 * one where near is NULL). */
static int halo_partner(int q, const char *near)
{
    return q != mpi_me && (!near || near[q]);
}

/* Sends count[q] records of `width` doubles (packed in rank order in out) to each rank q of
 * lo .. hi but this one (count is 0 elsewhere) that is a neighbour (near[q], or every one where near
 * is NULL), every one of them a message even if empty, and returns theirs in rank order (*got
 * records, rcount[q] from rank q): point to point with the neighbours only, so a rank waits for them
 * and not for every rank. */
static double *exchange_near(const double *out, const int *count, int width, int lo, int hi, const char *near,
                             int tag, int64_t *got, int *rcount, double *(*room)(void *, int64_t), void *ctx)
{
    int n = hi - lo + 1;
    MPI_Datatype t;
    MPI_Type_contiguous(width, MPI_DOUBLE, &t);
    MPI_Type_commit(&t);
    MPI_Request *req = sim_calloc(2 * (size_t)n, sizeof *req);
    int64_t off = 0, total = 0;
    for (int q = 0; q < lo; q++) off += count[q];
    for (int q = lo; q <= hi; q++) {
        req[q - lo] = MPI_REQUEST_NULL;
        if (halo_partner(q, near)) {
            MPI_Isend(out + off * width, count[q], t, q, tag, MPI_COMM_WORLD, &req[q - lo]);
            bytes_sent += (uint64_t)count[q] * (uint64_t)width * sizeof(double);
        }
        off += count[q];
    }
    double t0 = MPI_Wtime();
    memset(rcount, 0, (size_t)mpi_np * sizeof *rcount);
    for (int q = lo; q <= hi; q++) { /* the sizes first, then one buffer for all */
        if (!halo_partner(q, near)) continue;
        MPI_Status st;
        MPI_Probe(q, tag, MPI_COMM_WORLD, &st);
        MPI_Get_count(&st, t, &rcount[q]);
        total += rcount[q];
    }
    double *in = room ? room(ctx, total) : sim_calloc((size_t)(total ? total : 1) * (size_t)width, sizeof *in);
    off = 0;
    for (int q = lo; q <= hi; q++) {
        req[n + q - lo] = MPI_REQUEST_NULL;
        if (!halo_partner(q, near)) continue;
        MPI_Irecv(in + off * width, rcount[q], t, q, tag, MPI_COMM_WORLD, &req[n + q - lo]);
        off += rcount[q];
    }
    MPI_Waitall(2 * n, req, MPI_STATUSES_IGNORE);
    waited += MPI_Wtime() - t0;
    MPI_Type_free(&t);
    free(req);
    *got = total;
    return in;
}

/* ---- the run ----------------------------------------------------------------------------------------- */

/* A key of SPEC.md 3.3 on the wire and in the rounds: t = 2 (later than any event) for none. */
typedef struct {
    double t, kind, i, j, decided;
} Key;

static const Key key_none = {2, 0, 0, 0, 0};

/* An own disk with an event this step (a pair event with an own disk, or a wall event). */
typedef struct {
    Key key;          /* its smallest live key (rounds), decided once accepted */
    real wall_t;      /* its wall event time, or -1 */
    int32_t lo, cnt;  /* its pair events: adj[lo .. lo + cnt) */
    int32_t slot, id; /* id: the original index */
    int32_t pick;     /* the accepted event: an index into adj, -1 for the wall, -2 for none */
    int32_t acc;      /* accepted in this round */
} Node;

/* One of a node's pair events (found_name's name) and its other disk: its node, or -1 - k for the
 * halo's slot own + k. */
typedef struct {
    int64_t e;
    int32_t other;
} Adj;

typedef struct StepClock StepClock; /* --stats: the steps' phases (below) */

typedef struct {
    Params par;       /* the run's */
    Params lp;        /* the broad phase's: n = own + halo */
    const Options *opt;
    Output *out;      /* rank 0's */
    Broad b;          /* the rank's disks in b.s: own at [0, own), the halo after them */
    int64_t own, halo;
    int nt;
    double reach;     /* this step's */
    int nlo, nhi;     /* this step's neighbours (neighbours()) */
    char *near;       /* the periodic box: by rank, whether a neighbour (nlo .. nhi are all ranks) */
    int whole;        /* the periodic box: this rank holds the whole torus (whole_torus) */
    double halo_secs; /* GPU ranks, --stats: the host's seconds in the halo's exchange (records or headers) */
    int most_near;    /* the most neighbours in any step (--stats) */
    double speed;     /* a bound on the fastest speed at this step's start, over all ranks */
    real own_vmax;    /* a bound on the own disks' fastest velocity component */
    real vmax;        /* this step's fastest velocity component, over the own disks and the halo */
    /* the fastest speed over all ranks, a step late: sent off as each step ends, read a step later */
    MPI_Comm speed_comm;
    MPI_Request speed_req[2];
    double speed_mine[2], speed_all[2];
    MPI_Comm keys_comm; /* the choice's rounds (their tags say whether a rank has more to send) */
    Key *hbuf;        /* the halo's keys as received */
    size_t hbuf_cap;
    /* the halo exchange: the own slots sent, rank by rank (scount), and the copies received */
    int32_t *send;
    int64_t nsend;
    size_t send_cap;
    int *scount, *rcount;
    /* the choice, over the own disks with an event this step (nodes): a pass over every slot, or
     * a key for each, would be read and written beyond a large rank's cache every step */
    Node *node;
    size_t node_cap;
    Adj *adj;         /* the nodes' lists of pair events */
    size_t adj_cap;
    int32_t *active;  /* nodes still undecided with a live event */
    size_t active_cap;
    int32_t *node_of; /* cap, by own slot: its node this step, else -1 (all -1 between steps) */
    const Key *hkey;  /* the halo's keys, as their owners last sent them (NULL: none yet) */
    int64_t cap;      /* per-slot buffers allocated */
    uint64_t events, rounds, bytes_steps;
    double busy;      /* seconds of the steps since the last balance, MPI calls left out */
    double waited_steps; /* seconds of the steps inside MPI calls (--stats) */
    int64_t moves;    /* times the balance moved the cuts */
    StepClock *clock; /* --stats: the steps' phases */
    GpuRank *gpu;     /* mpi_cuda: the rank's GPU, which holds its disks during the steps */
    int locals;       /* mpi_cuda: the ranks on this rank's node */
    int peer;         /* mpi_cuda: the halos and keys between the GPUs directly (gpu_peer_start) */
    GpuPeer *pout, *pin; /* the peer path's word to and from each rank, a step's halo */
    int *pfrom;
} Run;

/* --stats: a step's phases timed on every rank, outside MPI calls and inside them. A rank waits for
 * its neighbours at every exchange, and they for theirs, so the phases' time on each step's slowest
 * rank, summed over the steps, against the ranks' mean shows what the ranks' unequal speeds can cost
 * phase by phase (the ranks are not in lockstep: the sum may exceed the step loop), and the rank that
 * was slowest in most steps points at a slower core. Rank 0 gathers the steps every CLOCK_CHUNK
 * steps: three small reductions then, none inside a step. */
enum { PART_HALO, PART_FIND, PART_CHOOSE, PART_MOVE, PART_MIGRATE, STEP_PARTS };
static const char *const part_name[STEP_PARTS] = {"halo", "broad phase", "choice", "move", "migration"};
#define CLOCK_CHUNK 64

struct StepClock {
    double at, waited_at;                      /* the running phase's start: the clock, and `waited` */
    double busy[CLOCK_CHUNK][STEP_PARTS];      /* the chunk's steps, outside MPI calls */
    int fill;                                  /* steps in the chunk */
    double inside[STEP_PARTS];                 /* this rank's seconds inside MPI calls, by phase */
    double most[STEP_PARTS], mean[STEP_PARTS]; /* rank 0: each step's slowest rank, and the mean, summed */
    int64_t *slowest;                          /* rank 0: the steps in which each rank was the slowest */
    int64_t steps;                             /* steps gathered */
};

static void clock_start(StepClock *c)
{
    c->at = MPI_Wtime();
    c->waited_at = waited;
}

/* Ends phase ph of the step and starts the next. */
static void clock_end(StepClock *c, int ph)
{
    double now = MPI_Wtime(), in = waited - c->waited_at;
    c->busy[c->fill][ph] += now - c->at - in;
    c->inside[ph] += in;
    c->at = now;
    c->waited_at = waited;
}

/* The chunk's steps to rank 0 (every rank calls it, at the same steps). */
static void clock_flush(StepClock *c)
{
    if (c->fill == 0) return;
    int n = c->fill * STEP_PARTS;
    double most[CLOCK_CHUNK * STEP_PARTS], sum[CLOCK_CHUNK * STEP_PARTS];
    struct { double t; int rank; } step[CLOCK_CHUNK], worst[CLOCK_CHUNK];
    for (int k = 0; k < c->fill; k++) {
        step[k].t = 0, step[k].rank = mpi_me;
        for (int ph = 0; ph < STEP_PARTS; ph++) step[k].t += c->busy[k][ph];
    }
    double t0 = MPI_Wtime();
    MPI_Reduce(c->busy, most, n, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    MPI_Reduce(c->busy, sum, n, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    MPI_Reduce(step, worst, c->fill, MPI_DOUBLE_INT, MPI_MAXLOC, 0, MPI_COMM_WORLD);
    waited += MPI_Wtime() - t0; /* the step loop's time inside MPI calls, if in no phase */
    if (mpi_me == 0) {
        for (int k = 0; k < n; k++)
            c->most[k % STEP_PARTS] += most[k], c->mean[k % STEP_PARTS] += sum[k] / mpi_np;
        for (int k = 0; k < c->fill; k++) c->slowest[worst[k].rank]++;
    }
    c->steps += c->fill;
    c->fill = 0;
    memset(c->busy, 0, sizeof c->busy);
}

/* The last chunk, and the ranks' waiting summed, to rank 0 (every rank calls it). */
static void clock_gather(StepClock *c)
{
    clock_flush(c);
    double inside[STEP_PARTS];
    MPI_Reduce(c->inside, inside, STEP_PARTS, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    memcpy(c->inside, inside, sizeof inside);
}

/* Rank 0's two lines of --stats. */
static void clock_report(const StepClock *c)
{
    int top = 0;
    for (int q = 1; q < mpi_np; q++)
        if (c->slowest[q] > c->slowest[top]) top = q;
    fprintf(stderr, "%s: the steps' phases outside MPI calls, on each step's slowest rank (the ranks' mean), "
            "seconds:", sim_program);
    for (int ph = 0; ph < STEP_PARTS; ph++)
        fprintf(stderr, " %s %.4f (%.4f)%s", part_name[ph], c->most[ph], c->mean[ph],
                ph + 1 < STEP_PARTS ? "," : ";");
    fprintf(stderr, " the slowest rank in most steps: rank %d (%lld of %lld steps)\n", top,
            (long long)c->slowest[top], (long long)c->steps);
    fprintf(stderr, "%s: the steps' phases inside MPI calls (the ranks' mean), seconds: halo %.4f, choice %.4f, "
            "migration %.4f\n", sim_program, c->inside[PART_HALO] / mpi_np, c->inside[PART_CHOOSE] / mpi_np,
            c->inside[PART_MIGRATE] / mpi_np);
}

static void run_reserve(Run *r, int64_t n)
{
    if (n > r->b.cap) broad_reserve(&r->b, n + n / 4);
    if (n <= r->cap) return;
    int64_t cap = n + n / 4;
    /* all -1 between steps (this is called there, or before the choice): nothing to keep */
    free(r->node_of);
    r->node_of = sim_calloc((size_t)cap, sizeof *r->node_of);
    for (int64_t q = 0; q < cap; q++) r->node_of[q] = -1;
    r->cap = cap;
}

/* The own disks' fastest velocity component into r->own_vmax, and their fastest speed. */
static double own_speeds(Run *r)
{
    const Slots *s = &r->b.s;
    real vm = 0;
    double s2 = 0;
    for (int64_t q = 0; q < r->own; q++) {
        double vx = s->vx[q], vy = s->vy[q], v2 = vx * vx + vy * vy;
        vm = fastest(vm, s->vx[q], s->vy[q]);
        if (v2 > s2) s2 = v2;
    }
    r->own_vmax = vm;
    return sqrt(s2);
}

static void halo_send(Run *r);

/* The neighbours in the periodic box: the ranks whose strips lie within twice the reach around the
 * torus, and every rank of a whole_torus strip (which is every rank's neighbour); whole[q] says which
 * those are. nlo .. nhi are all ranks. */
static void neighbours_periodic(Run *r, char *whole)
{
    int np = mpi_np, me = mpi_me, near = 0;
    double L = r->par.L;
    for (int q = 0; q < np; q++) whole[q] = (char)whole_torus(q, r->reach, L);
    r->whole = whole[me];
    for (int q = 0; q < np; q++) {
        r->near[q] = (char)(q != me && (whole[me] || whole[q] || cyclic_gap(me, q, L) <= 2 * r->reach));
        near += r->near[q];
    }
    r->nlo = 0, r->nhi = np - 1;
    if (near > r->most_near) r->most_near = near;
}

/* The view of the strips that mpi_halo.h decides the copies by, as halo_reach left them this step. */
static HaloView halo_view(const Run *r, const char *whole, int any_whole)
{
    HaloView h = {mpi_cut, r->near, whole, r->reach, r->par.L, mpi_me, mpi_np, r->nlo, r->nhi, r->par.periodic,
                  any_whole};
    return h;
}

/* The ranks but this one that get a copy of the own disk at x (into q; returns how many). */
static int halo_targets(const HaloView *h, double x, int *q)
{
    int n = 0, lo, hi;
    if (halo_inside(h, x)) return 0;
    if (!halo_span(h, x, &lo, &hi))
        sim_fail("internal error: a disk within reach of strips %d to %d, beyond the neighbours %d to %d", lo, hi,
                 h->nlo, h->nhi);
    for (int k = lo; k <= hi; k++)
        if (halo_takes(h, x, k)) q[n++] = k;
    return n;
}

/* The reach at the fastest speed `speed`: two disks close in by at most twice that. */
static double reach_at(const Run *r, double speed)
{
    return (2 * (double)r->par.r + 2 * speed) * (1 + 1e-6) + 1e-9 * (double)r->par.L;
}

static double reach_of(const Run *r)
{
    return reach_at(r, r->speed);
}

/* 1: the reach and this step's neighbours (whole: by rank, whether its strip holds the whole torus);
 * returns whether any does. */
static int halo_reach(Run *r, char *whole)
{
    int any_whole = 0;
    r->reach = reach_of(r);
    if (r->par.periodic) {
        neighbours_periodic(r, whole);
        for (int k = 0; k < mpi_np; k++) any_whole |= whole[k];
    } else {
        neighbours(r->reach, &r->nlo, &r->nhi);
        if (r->nhi - r->nlo > r->most_near) r->most_near = r->nhi - r->nlo;
    }
    return any_whole;
}

/* 2: r->send and r->scount, the own slots whose copies go to other strips' ranks (all of them
 * neighbours; halo_targets), in rank order. The rank's threads each take a contiguous share of the
 * slots, count its copies by rank, then list them where the counts before them end: the order one
 * thread would list them in. A GPU rank lists its own on its GPU (gpu_rank_halo_out). */
#ifndef HALO_THREAD_ITEMS
#define HALO_THREAD_ITEMS 16384 /* slots a thread at least: a team's start costs more than a short share */
#endif
static void halo_list(Run *r, const char *whole, int any_whole)
{
    const Slots *s = &r->b.s;
    const HaloView h = halo_view(r, whole, any_whole);
    int64_t n = r->own, share = (n + HALO_THREAD_ITEMS - 1) / HALO_THREAD_ITEMS;
    int np = mpi_np, nt = share < r->nt ? (int)share : r->nt;
    if (nt < 1) nt = 1;
    int64_t *at = sim_calloc((size_t)nt * (size_t)np, sizeof *at); /* by thread and rank: counts, then places */
    memset(r->scount, 0, (size_t)np * sizeof *r->scount);
    r->nsend = 0;
#pragma omp parallel num_threads(nt)
    {
        int t = omp_get_thread_num(), m = omp_get_num_threads(), *q = sim_calloc((size_t)np, sizeof *q);
        int64_t k0 = n * t / m, k1 = n * (t + 1) / m, *mine = at + (size_t)t * (size_t)np;
        for (int64_t k = k0; k < k1; k++) {
            int c = halo_targets(&h, (double)s->x[k], q);
            for (int u = 0; u < c; u++) mine[q[u]]++;
        }
#pragma omp barrier
#pragma omp single
        {
            r->nsend = mpi_thread_places(at, m, r->scount);
            r->send = sim_grow(r->send, &r->send_cap, (size_t)r->nsend, sizeof *r->send);
        } /* (its barrier) */
        for (int64_t k = k0; k < k1; k++) {
            int c = halo_targets(&h, (double)s->x[k], q);
            for (int u = 0; u < c; u++) r->send[mine[q[u]]++] = (int32_t)k;
        }
        free(q);
    }
    free(at);
}

/* 1 and 2 on the CPU: copies of the own disks within reach of other strips sent there. */
static void halo_exchange(Run *r)
{
    char *whole = sim_calloc((size_t)mpi_np, 1);
    int any_whole = halo_reach(r, whole);
    halo_list(r, whole, any_whole);
    free(whole);
    halo_send(r);
}

/* The copies listed in r->send to their ranks, and theirs into the halo. */
static void halo_send(Run *r)
{
    Slots *s = &r->b.s;
    double *out = sim_calloc((size_t)(r->nsend ? r->nsend : 1) * D_LEN, sizeof *out);
    for (int64_t k = 0; k < r->nsend; k++) pack(s, r->send[k], out + k * D_LEN);
    int64_t got;
    double *in = exchange_near(out, r->scount, D_LEN, r->nlo, r->nhi, r->par.periodic ? r->near : NULL, TAG_HALO,
                               &got, r->rcount, NULL, NULL);
    run_reserve(r, r->own + got);
    s = &r->b.s;
    real vm = r->own_vmax; /* the grid's, over the disks this rank sees */
    for (int64_t k = 0; k < got; k++) {
        unpack(s, r->own + k, in + k * D_LEN);
        vm = fastest(vm, s->vx[r->own + k], s->vy[r->own + k]);
    }
    r->vmax = vm;
    r->halo = got;
    free(in);
    free(out);
}

/* 3: omp's broad phase over the strip and its halo, on the rank's threads. */
static void find_events(Run *r, int64_t step)
{
    Broad *b = &r->b;
    r->lp.n = r->own + r->halo;
    double x0 = mpi_cut[mpi_me] - r->reach, x1 = mpi_cut[mpi_me + 1] + r->reach;
    b->rx0 = x0 > r->par.lo ? x0 : r->par.lo;
    b->rx1 = x1 < r->par.hi ? x1 : r->par.hi;
    if (r->par.periodic) { /* the strip and its halo in the images nearest its middle, or the torus */
        b->wrap_x = r->whole;
        b->rx0 = r->whole ? 0 : x0;
        b->rx1 = r->whole ? (double)r->par.L : x1;
        b->frame_x = (mpi_cut[mpi_me] + mpi_cut[mpi_me + 1]) / 2;
        b->grid_only = mpi_np > 1;
    }
#pragma omp parallel num_threads(r->nt)
    {
        int tid = omp_get_thread_num();
#pragma omp single
        b->nt = omp_get_num_threads();
        if (mpi_np == 1) { /* the box: the cost model weighs all three broad phases by the speeds */
            broad_count_speeds(b, tid);
        } else { /* a strip runs the grid, which needs only the fastest component */
            BroadThread *th = &b->th[tid];
            th->vmax = tid == 0 ? r->vmax : 0;
            memset(th->speed_n, 0, sizeof th->speed_n);
            memset(th->speed_s1, 0, sizeof th->speed_s1);
        }
#pragma omp barrier
        broad_find(b, tid, step, 0, 0);
    }
}

static int key_less(const Key *x, const Key *y)
{
    return event_before((real)x->t, (int)x->kind, (int64_t)x->i, (int64_t)x->j, (real)y->t, (int)y->kind,
                        (int64_t)y->i, (int64_t)y->j);
}

static int key_same(const Key *x, const Key *y)
{
    return x->t == y->t && x->kind == y->kind && x->i == y->i && x->j == y->j;
}

/* The pair event named e (found_name). */
static inline const PairEvent *event_at(const Run *r, int64_t e)
{
    return &found_of_name(&r->b, e)->ev[found_index(&r->b, e)];
}

/* The node of own slot q, made if it has none. */
static inline Node *node_for(Run *r, int32_t q, int64_t *nn)
{
    int32_t v = r->node_of[q];
    if (v < 0) {
        v = (int32_t)(*nn)++;
        Node fresh = {key_none, -1, 0, 0, q, -1, -2, 0};
        r->node[v] = fresh;
        r->node_of[q] = v;
    }
    return &r->node[v];
}

/* The nodes of the own disks with an event, each with its wall event and the list of its pair events
 * with an own disk (CSR in adj; two copies' events are their owners' to decide), from the threads'
 * lists where they found them. Returns how many. */
static int64_t build_nodes(Run *r)
{
    int64_t own = r->own, nn = 0;
    size_t ends = 0;
    for (int t = 0; t < r->b.nt; t++) ends += 2 * r->b.th[t].found.len + r->b.th[t].found.wall_len;
    if (ends > INT32_MAX) sim_fail("%zu events in one step: too many", ends);
    /* no more nodes or list entries than ends (the contents need not be kept) */
    r->node = omp_scratch_grow(r->node, &r->node_cap, ends, sizeof *r->node);
    r->adj = omp_scratch_grow(r->adj, &r->adj_cap, ends, sizeof *r->adj);
    r->active = omp_scratch_grow(r->active, &r->active_cap, ends, sizeof *r->active);
    for (int t = 0; t < r->b.nt; t++) {
        const Found *f = &r->b.th[t].found;
        for (size_t k = 0; k < f->len; k++) {
            const PairEvent *e = &f->ev[k];
            if (e->a < own) {
                Node *nd = node_for(r, e->a, &nn);
                nd->cnt++, nd->id = e->i;
            }
            if (e->b < own) {
                Node *nd = node_for(r, e->b, &nn);
                nd->cnt++, nd->id = e->j;
            }
        }
        for (size_t k = 0; k < f->wall_len; k++)
            if (f->wall[k].slot < own) node_for(r, f->wall[k].slot, &nn)->wall_t = f->wall[k].t;
    }
    int32_t pos = 0;
    for (int64_t v = 0; v < nn; v++) {
        Node *nd = &r->node[v];
        nd->lo = pos;
        pos += nd->cnt;
        nd->cnt = 0;
        if (nd->id < 0) nd->id = r->b.s.id[nd->slot]; /* a wall event alone: its key needs it */
        r->active[v] = (int32_t)v;
    }
    for (int t = 0; t < r->b.nt; t++) {
        const Found *f = &r->b.th[t].found;
        for (size_t k = 0; k < f->len; k++) {
            const PairEvent *e = &f->ev[k];
            int64_t name = found_name(&r->b, k, t);
            int32_t ends2[2] = {e->a, e->b};
            for (int u = 0; u < 2; u++) {
                int32_t q = ends2[u], o = ends2[1 - u];
                if (q >= own) continue;
                Node *nd = &r->node[r->node_of[q]];
                Adj x = {name, o < own ? r->node_of[o] : (int32_t)(-1 - (o - own))};
                r->adj[nd->lo + nd->cnt++] = x;
            }
        }
    }
    return nn;
}

/* The key of a pair event's other disk (adj's other): a node's, or a copy's as last received. */
static inline const Key *other_key(const Run *r, int32_t o)
{
    if (o >= 0) return &r->node[o].key;
    return r->hkey ? &r->hkey[-1 - o] : &key_none;
}

/* The keys of one round to the neighbours that hold copies of this rank's disks or this rank of
 * theirs, and theirs into hbuf, for those that have not sent their last (done: by neighbour). A rank
 * whose own disks are all decided or without a live event sends its last keys (tag KEYS_LAST): they
 * will not change, so its neighbours keep them and go on without it. Returns whether any came. */
enum { KEYS_MORE = 1, KEYS_LAST };
static int keys_round(Run *r, const Key *out, char *done, char *hdone, int last)
{
    int n = r->nhi - r->nlo + 1, posted = 0;
    MPI_Request *req = sim_calloc(2 * (size_t)n, sizeof *req);
    int64_t *from = sim_calloc((size_t)n, sizeof *from); /* where each one's keys land, -1: none came */
    int64_t soff = 0, roff = 0;
    for (int q = 0; q < r->nlo; q++) soff += r->scount[q], roff += r->rcount[q];
    for (int q = r->nlo; q <= r->nhi; q++) {
        int k = q - r->nlo;
        req[k] = req[n + k] = MPI_REQUEST_NULL;
        from[k] = -1;
        if (q != mpi_me && !done[k] && (r->scount[q] || r->rcount[q])) {
            MPI_Irecv(r->hbuf + roff, 5 * r->rcount[q], MPI_DOUBLE, q, MPI_ANY_TAG, r->keys_comm, &req[n + k]);
            MPI_Isend(out + soff, 5 * r->scount[q], MPI_DOUBLE, q, last ? KEYS_LAST : KEYS_MORE, r->keys_comm,
                      &req[k]);
            bytes_sent += (uint64_t)r->scount[q] * sizeof *out;
            from[k] = roff;
            posted = 1;
        }
        soff += r->scount[q], roff += r->rcount[q];
    }
    MPI_Status *st = sim_calloc(2 * (size_t)n, sizeof *st);
    double t0 = MPI_Wtime();
    MPI_Waitall(2 * n, req, st);
    waited += MPI_Wtime() - t0;
    for (int k = 0; k < n; k++)
        if (from[k] >= 0 && st[n + k].MPI_TAG == KEYS_LAST) {
            done[k] = 1;
            memset(hdone + from[k], 1, (size_t)r->rcount[r->nlo + k]); /* its copies' keys are final */
        }
    free(st), free(req), free(from);
    return posted;
}

/* 4: the rounds. Each node's pick ends as its accepted event: an index into adj, -1 for its wall
 * event, -2 for none. A rank goes on while its own disks have live events: it waits for its
 * neighbours' keys only, never for all ranks. */
static void choose(Run *r)
{
    int64_t na = build_nodes(r);
    Node *node = r->node;
    r->hkey = NULL;
    r->hbuf = omp_scratch_grow(r->hbuf, &r->hbuf_cap, (size_t)(r->halo ? r->halo : 1), sizeof *r->hbuf);
    Key *out = sim_calloc((size_t)(r->nsend ? r->nsend : 1), sizeof *out);
    char *done = sim_calloc((size_t)(r->nhi - r->nlo + 1), 1);
    char *hdone = sim_calloc((size_t)(r->halo ? r->halo : 1), 1); /* by copy: its owner sent its last */
    int64_t stuck = 0;
    for (;;) {
        /* each undecided own disk's smallest live event (a copy's decision may be a round late:
         * that only delays, as an event is accepted only when it is both disks' smallest) */
#pragma omp parallel for num_threads(r->nt) schedule(static)
        for (int64_t k = 0; k < na; k++) {
            Node *nd = &node[r->active[k]];
            Key best = key_none;
            int32_t pick = -2;
            if (nd->wall_t >= 0) {
                Key w = {(double)nd->wall_t, 0, nd->id, nd->id, 0};
                best = w, pick = -1;
            }
            for (int32_t u = nd->lo; u < nd->lo + nd->cnt; u++) {
                if (other_key(r, r->adj[u].other)->decided != 0) continue;
                const PairEvent *e = event_at(r, r->adj[u].e);
                Key c = {(double)e->t, 1, e->i, e->j, 0};
                if (key_less(&c, &best)) best = c, pick = u;
            }
            Key *kq = &nd->key; /* its decided flag, read by other threads, stays */
            kq->t = best.t, kq->kind = best.kind, kq->i = best.i, kq->j = best.j;
            nd->pick = pick;
        }
        int64_t live = 0;
        for (int64_t k = 0; k < na; k++) live += node[r->active[k]].pick != -2;
        /* the owners' keys and decisions to the copies (as many as the halo's disks: known) */
        for (int64_t k = 0; k < r->nsend; k++) {
            int32_t v = r->node_of[r->send[k]];
            out[k] = v >= 0 ? node[v].key : key_none;
        }
        if (keys_round(r, out, done, hdone, live == 0)) r->hkey = r->hbuf;
        if (live == 0) break;
        r->rounds++;
        /* accepted: the smallest live event of both its disks, decided alike by both owners */
#pragma omp parallel for num_threads(r->nt) schedule(static) reduction(+ : stuck)
        for (int64_t k = 0; k < na; k++) {
            Node *nd = &node[r->active[k]];
            int32_t p = nd->pick, o = p >= 0 ? r->adj[p].other : 0;
            nd->acc = 0;
            if (p == -1) {
                nd->acc = 1;
            } else if (p >= 0) {
                const Key *ko = other_key(r, o);
                nd->acc = ko->decided == 0 && key_same(ko, &nd->key);
                /* an undecided copy whose owner has ended its rounds had no live event there: this
                 * rank found an event that the owner did not, and would wait for it forever */
                stuck += !nd->acc && o < 0 && ko->decided == 0 && hdone[-1 - o];
            }
        }
        if (stuck)
            sim_fail("internal error: %lld events with copies that their owners did not find (the halos "
                     "disagree)", (long long)stuck);
        int64_t kept = 0;
        for (int64_t k = 0; k < na; k++) {
            Node *nd = &node[r->active[k]];
            if (nd->acc) nd->key.decided = 1;
            else if (nd->pick != -2) r->active[kept++] = r->active[k];
        }
        na = kept;
    }
    r->hkey = NULL;
    free(hdone), free(done);
    free(out);
}

/* 5: the own disks moved in place: a disk without a node moves freely; a pair of own disks both from
 * the node of its lower original index (the other's is skipped), a disk and a copy from the copy's
 * state at the start of the step (copies do not move). Every node_of entry is left -1. */
static void move(Run *r)
{
    Slots *s = &r->b.s;
    const Node *node = r->node;
    real lo = r->par.lo, hi = r->par.hi, L = r->par.L, half = r->par.half;
    int periodic = r->par.periodic;
    uint64_t events = 0;
#pragma omp parallel for num_threads(r->nt) schedule(static) reduction(+ : events)
    for (int64_t q = 0; q < r->own; q++) {
        int32_t v = r->node_of[q], p = -2;
        const PairEvent *e = NULL;
        if (v >= 0) {
            r->node_of[q] = -1;
            p = node[v].pick;
        }
        if (p >= 0) {
            e = event_at(r, r->adj[p].e);
            if (r->adj[p].other >= 0 && node[v].id != e->i) continue; /* moved with its partner */
        }
        real x = s->x[q], y = s->y[q], vx = s->vx[q], vy = s->vy[q];
        if (p == -2) {
            x = x + vx;
            y = y + vy;
        } else if (periodic) { /* SPEC.md 7: no walls, the nearest image's normal, no stop */
            real dp;
            int32_t o = r->adj[p].other;
            int64_t j = o >= 0 ? node[o].slot : r->own + (-1 - o);
            real ox = s->x[j], oy = s->y[j], ovx = s->vx[j], ovy = s->vy[j];
            if (node[v].id == e->i)
                dp = pair_contact_wrap(&x, &y, &vx, &vy, &ox, &oy, &ovx, &ovy, e->t, L, half);
            else
                dp = pair_contact_wrap(&ox, &oy, &ovx, &ovy, &x, &y, &vx, &vy, e->t, L, half);
            if (o >= 0) { /* two own disks, from the lower index */
                fly_rest(&ox, &oy, ovx, ovy, e->t);
                s->x[j] = wrap_coord(ox, L), s->y[j] = wrap_coord(oy, L), s->vx[j] = ovx, s->vy[j] = ovy;
                s->pc[j]++;
                if (s->wi) s->wi[j] += dp;
            }
            events += node[v].id == e->i; /* once a pair: from its lower index */
            fly_rest(&x, &y, vx, vy, e->t);
            s->pc[q]++;
            if (s->wi) s->wi[q] += dp; /* the virial's impulses (SPEC.md 7a) */
        } else if (p == -1) {
            real t = node[v].wall_t, vx0 = vx, vy0 = vy;
            wall_bounce(&x, &y, &vx, &vy, t, lo, hi);
            if (s->wi) s->wi[q] += wall_impulse(vx0, vy0, vx, vy);
            finish_step(&x, &y, vx, vy, t, lo, hi);
            s->wc[q]++;
            events++;
        } else {
            int32_t o = r->adj[p].other;
            if (o >= 0) { /* two own disks, from the lower index */
                int64_t j = node[o].slot;
                real ox = s->x[j], oy = s->y[j], ovx = s->vx[j], ovy = s->vy[j];
                pair_contact(&x, &y, &vx, &vy, &ox, &oy, &ovx, &ovy, e->t);
                finish_step(&ox, &oy, ovx, ovy, e->t, lo, hi);
                s->x[j] = clamp_coord(ox, lo, hi), s->y[j] = clamp_coord(oy, lo, hi), s->vx[j] = ovx, s->vy[j] = ovy;
                s->pc[j]++;
                events++;
            } else {
                int64_t j = r->own + (-1 - o);
                real ox = s->x[j], oy = s->y[j], ovx = s->vx[j], ovy = s->vy[j];
                if (node[v].id == e->i) {
                    pair_contact(&x, &y, &vx, &vy, &ox, &oy, &ovx, &ovy, e->t);
                    events++; /* once a pair: from its lower index */
                } else {
                    pair_contact(&ox, &oy, &ovx, &ovy, &x, &y, &vx, &vy, e->t);
                }
            }
            finish_step(&x, &y, vx, vy, e->t, lo, hi);
            s->pc[q]++;
        }
        if (periodic) x = wrap_coord(x, L), y = wrap_coord(y, L);
        else x = clamp_coord(x, lo, hi), y = clamp_coord(y, lo, hi);
        s->x[q] = x, s->y[q] = y, s->vx[q] = vx, s->vy[q] = vy;
    }
    r->events += events;
}

/* The leavers' records rec[0 .. moving) sent to the ranks of their new strips (mpi_owner): neighbours (a
 * disk moves less than the reach in a step), or any rank where the cuts moved (moved). Returns the
 * records that arrive, *got of them. */
static double *send_leavers(Run *r, int moved, const double *rec, int64_t moving, int64_t *got)
{
    int np = mpi_np, *count = sim_calloc((size_t)np, sizeof *count), *rcount = sim_calloc((size_t)np, sizeof *rcount);
    int *dest = sim_calloc((size_t)(moving ? moving : 1), sizeof *dest);
    for (int64_t k = 0; k < moving; k++) {
        dest[k] = mpi_owner(rec[k * D_LEN + D_X]);
        if (dest[k] == mpi_me ||
            (!moved && (dest[k] < r->nlo || dest[k] > r->nhi || (r->par.periodic && !r->near[dest[k]]))))
            sim_fail("internal error: a disk moved to strip %d, beyond the neighbours %d to %d", dest[k], r->nlo,
                     r->nhi);
        count[dest[k]]++;
    }
    double *out = sim_calloc((size_t)(moving ? moving : 1) * D_LEN, sizeof *out);
    int64_t *at = sim_calloc((size_t)np, sizeof *at);
    for (int q = 1; q < np; q++) at[q] = at[q - 1] + count[q - 1];
    for (int64_t k = 0; k < moving; k++) memcpy(out + (at[dest[k]]++) * D_LEN, rec + k * D_LEN, D_LEN * sizeof *out);
    double *in = moved ? exchange(out, count, D_LEN, got, rcount)
                       : exchange_near(out, count, D_LEN, r->nlo, r->nhi, r->par.periodic ? r->near : NULL,
                                       TAG_MIGRATE, got, rcount, NULL, NULL);
    free(out), free(at), free(dest), free(count), free(rcount);
    return in;
}

/* Disks that left the strip go to the rank of their new strip: a neighbour (a disk moves less than
 * the reach in a step), or any rank where the cuts moved (moved). The fastest speed over the moved
 * disks, leavers too, is sent off to all ranks (into slot `speed` of run_steps' two). */
static void migrate(Run *r, int moved, int speed)
{
    Slots *s = &r->b.s;
    int64_t moving = 0, keep;
    /* the leavers' slots, ascending (in cell_of, free between steps): few */
    int32_t *leaver = r->b.cell_of;
    r->speed_mine[speed] = own_speeds(r);
    MPI_Iallreduce(&r->speed_mine[speed], &r->speed_all[speed], 1, MPI_DOUBLE, MPI_MAX, r->speed_comm,
                   &r->speed_req[speed]);
    if (mpi_np > 1)
        for (int64_t q = 0; q < r->own; q++)
            if (mpi_owner(s->x[q]) != mpi_me) leaver[moving++] = (int32_t)q;
    double *out = sim_calloc((size_t)(moving ? moving : 1) * D_LEN, sizeof *out);
    for (int64_t k = 0; k < moving; k++) pack(s, leaver[k], out + k * D_LEN);
    /* the leavers' slots refilled from the end, the lowest first with the last disk that stays: the
     * rest keep their places (and their cell order) */
    keep = r->own;
    for (int64_t lo = 0, hi = moving; lo < hi;) {
        int64_t q = leaver[lo], from = --keep;
        if (leaver[hi - 1] == from) { /* the last slot leaves too */
            hi--;
            continue;
        }
        s->x[q] = s->x[from], s->y[q] = s->y[from], s->vx[q] = s->vx[from], s->vy[q] = s->vy[from];
        s->id[q] = s->id[from], s->pc[q] = s->pc[from], s->wc[q] = s->wc[from];
        if (s->wi) s->wi[q] = s->wi[from];
        lo++;
    }
    int64_t got;
    double *in = send_leavers(r, moved, out, moving, &got);
    run_reserve(r, keep + got);
    s = &r->b.s;
    real vm = r->own_vmax; /* own_speeds' over the disks before they left: still a bound */
    for (int64_t k = 0; k < got; k++) {
        unpack(s, keep + k, in + k * D_LEN);
        vm = fastest(vm, s->vx[keep + k], s->vy[keep + k]);
    }
    r->own_vmax = vm;
    r->own = keep + got;
    r->halo = 0;
    free(in), free(out);
}

/* Every few steps the own disks are put in the order of the last step's grid cells, as omp keeps its
 * slots: the broad phase's pairs are then neighbours in memory. (The broad phase's own reordering
 * would mix the halo in among them.) */
#define REORDER_EVERY 8
static void reorder_own(Run *r)
{
    Broad *b = &r->b;
    const Plan *pl = &b->plan;
    if (pl->mode != MODE_GRID) return;
    int64_t gx = pl->gx, gy = pl->gy, cells = gx * gy;
    int32_t *start = b->cell_start; /* free between steps, max_cells + 1 >= cells + 1 */
    memset(start, 0, (size_t)(cells + 1) * sizeof *start);
    const Slots *s = &b->s;
    for (int64_t q = 0; q < r->own; q++) {
        double cx = ((double)s->x[q] - pl->x0) * pl->inv_h, cy = ((double)s->y[q] - pl->y0) * pl->inv_h;
        int64_t ix = cx > 0 ? (cx < (double)(gx - 1) ? (int64_t)cx : gx - 1) : 0;
        int64_t iy = cy > 0 ? (cy < (double)(gy - 1) ? (int64_t)cy : gy - 1) : 0;
        b->cell_of[q] = (int32_t)(iy * gx + ix);
        start[b->cell_of[q] + 1]++;
    }
    for (int64_t c = 0; c < cells; c++) start[c + 1] += start[c];
    Slots *d = &b->spare;
    for (int64_t q = 0; q < r->own; q++) {
        int32_t to = start[b->cell_of[q]]++;
        d->x[to] = s->x[q], d->y[to] = s->y[q], d->vx[to] = s->vx[q], d->vy[to] = s->vy[q];
        d->id[to] = s->id[q], d->pc[to] = s->pc[q], d->wc[to] = s->wc[q];
        if (s->wi) d->wi[to] = s->wi[q];
    }
    Slots t = b->s;
    b->s = b->spare;
    b->spare = t;
}

/* ---- the balance ---------------------------------------------------------------------------------- */

#define BALANCE_SLACK 1.05 /* the cuts move when the busiest rank has this much more than the mean */

/* --balance: the cuts moved so that every strip holds an equal share of the work, a disk weighing what
 * the last steps cost its rank per disk (busy: MPI calls left out): a rank on a slower core, or with a
 * denser part of the box, gets a narrower strip. The disks that the new cuts put in another strip go
 * there in the next migrate; the events found do not depend on the cuts, so neither do the bytes. */
static int balance(Run *r)
{
    double *h = sim_calloc((size_t)mpi_cut_bins(), sizeof *h);
    double wt = r->own ? r->busy / (double)r->own : 0;
    for (int64_t q = 0; q < r->own; q++) mpi_cut_add(h, (double)r->b.s.x[q], r->par.L, wt);
    int moved = mpi_place_cuts(h, r->busy, r->par.L, BALANCE_SLACK);
    r->moves += moved;
    r->busy = 0;
    free(h);
    return moved;
}

static Local view(const Run *r)
{
    Local l = {r->b.s, r->own, 0, r->b.cap, r->b.s.wi != NULL};
    return l;
}

/* --pressure in the periodic box: the virial sums of the state after step `step`, on rank 0 (every
 * rank calls it). */
static void record_virial(Run *r, int64_t step)
{
    double w, k;
    Local l = view(r);
    mpi_index_sums(&r->par, &l, &w, &k);
    if (mpi_me == 0) io_virial_sums(r->out, step, w, k);
}

static double run_steps(Run *r, RunStats *st)
{
    int64_t k = r->par.substeps, last = r->par.steps * k, first = r->par.first_step * k;
    double t0 = MPI_Wtime();
    uint64_t bytes0 = bytes_sent;
    double waited0 = waited;
    int64_t every = r->opt->balance;
    /* the fastest speed: at the first step's start exactly; then migrate sends each step's off as it
     * ends, and the next step but one reads it. A speed grows at most by sqrt(2) in a step (two
     * disks' kinetic energy is shared between them), so the step after a known speed moves no disk
     * faster than sqrt(2) times it, and no rank waits on all ranks within a step. */
    double known = own_speeds(r);
    MPI_Allreduce(MPI_IN_PLACE, &known, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    r->speed_req[0] = r->speed_req[1] = MPI_REQUEST_NULL;
    StepClock *c = r->clock;
    for (int64_t sub = first + 1; sub <= last; sub++) {
        double ts = MPI_Wtime(), w0 = waited;
        if (c) clock_start(c);
        if (sub >= first + 3) { /* the speed at the last step's start, sent off as the step before it ended */
            int o = (int)(sub & 1);
            double tw = MPI_Wtime();
            MPI_Wait(&r->speed_req[o], MPI_STATUS_IGNORE);
            waited += MPI_Wtime() - tw;
            known = r->speed_all[o];
        }
        r->speed = sub == first + 1 ? known : known * 1.41422;
        halo_exchange(r);
        if (c) clock_end(c, PART_HALO);
        find_events(r, sub);
        if (c) clock_end(c, PART_FIND);
        choose(r);
        if (c) clock_end(c, PART_CHOOSE);
        move(r);
        if (c) clock_end(c, PART_MOVE);
        r->busy += MPI_Wtime() - ts - (waited - w0);
        int moved = every && mpi_np > 1 && sub % every == 0 && balance(r);
        migrate(r, moved, (int)(sub & 1));
        if (sub % REORDER_EVERY == 1) reorder_own(r);
        if (c) {
            clock_end(c, PART_MIGRATE);
            if (++c->fill == CLOCK_CHUNK) clock_flush(c);
        }
        if (sub % k) continue;
        if (io_virial_ends_block(&r->par, r->opt, sub / k)) record_virial(r, sub / k);
        if (r->par.print && sub < last) {
            Local l = view(r);
            mpi_write_state(r->out, &r->par, &l, sub / k, 0);
        }
        if (io_checkpoint_at(&r->par, r->opt, sub / k)) {
            Local l = view(r);
            mpi_checkpoint(r->out, &r->par, r->opt, &l, sub / k);
        }
        if (mpi_me == 0) io_progress(r->out, sub / k);
    }
    MPI_Waitall(2, r->speed_req, MPI_STATUSES_IGNORE);
    double secs = MPI_Wtime() - t0;
    r->bytes_steps = bytes_sent - bytes0; /* output's traffic aside */
    r->waited_steps = waited - waited0;
    uint64_t mine[2] = {r->events, 0}, sum[2];
    for (int t = 0; t < r->b.nt_max; t++) mine[1] += r->b.th[t].found.tests;
    MPI_Reduce(mine, sum, 2, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD);
    st->events = sum[0];
    st->pair_tests = sum[1];
    return secs;
}

#ifdef MPI_CUDA
/* ---- GPU ranks (mpi_cuda): the same step, the rank's disks on its GPU (mpi_cuda.cu) -------------- */

/* The own disks from the GPU into the slots (output, checkpoints, the end). */
static void gpu_download(Run *r)
{
    int64_t own = gpu_rank_own(r->gpu);
    run_reserve(r, own);
    double *rec = sim_realloc(NULL, (size_t)(own ? own : 1) * D_LEN, sizeof *rec);
    gpu_rank_get(r->gpu, rec);
#pragma omp parallel for schedule(static) num_threads(mpi_pass_threads(r->nt, own))
    for (int64_t q = 0; q < own; q++) unpack(&r->b.s, q, rec + q * D_LEN);
    r->own = own;
    free(rec);
}

/* exchange_near's room for the halo's records: the GPU rank's pinned buffer, straight to the device. */
static double *gpu_halo_room(void *g, int64_t n)
{
    return gpu_rank_halo_in((GpuRank *)g, n);
}

/* The peer path's halo: each neighbour told where in this rank's region its copies lie (gpu_rank_halo_out
 * packed them there, rank by rank), and where its own lie in theirs; the copies then come over the
 * GPUs' link, in the neighbours' order, as exchange_near would have put them. */
static int64_t gpu_halo_peer(Run *r)
{
    int n = r->nhi - r->nlo + 1, k = 0;
    const char *near = r->par.periodic ? r->near : NULL;
    MPI_Request *req = sim_calloc(2 * (size_t)n, sizeof *req);
    GpuPeer mine;
    gpu_rank_export(r->gpu, &mine);
    double t0 = sim_clock();
    int64_t off = 0, got = 0;
    for (int q = 0; q < r->nlo; q++) off += r->scount[q];
    memset(r->rcount, 0, (size_t)mpi_np * sizeof *r->rcount);
    for (int q = r->nlo; q <= r->nhi; q++) {
        req[q - r->nlo] = req[n + q - r->nlo] = MPI_REQUEST_NULL;
        if (halo_partner(q, near)) {
            r->pout[q] = mine;
            r->pout[q].count = r->scount[q], r->pout[q].offset = off;
            MPI_Isend(&r->pout[q], sizeof mine, MPI_BYTE, q, TAG_HALO, MPI_COMM_WORLD, &req[q - r->nlo]);
            MPI_Irecv(&r->pin[q], sizeof mine, MPI_BYTE, q, TAG_HALO, MPI_COMM_WORLD, &req[n + q - r->nlo]);
            bytes_sent += (uint64_t)r->scount[q] * D_LEN * sizeof(double);
        }
        off += r->scount[q];
    }
    double tw = MPI_Wtime();
    MPI_Waitall(2 * n, req, MPI_STATUSES_IGNORE);
    waited += MPI_Wtime() - tw;
    r->halo_secs += sim_clock() - t0;
    free(req);
    for (int q = r->nlo; q <= r->nhi; q++) {
        if (!halo_partner(q, near)) continue;
        r->rcount[q] = (int)r->pin[q].count;
        got += r->pin[q].count;
        r->pfrom[k] = q, r->pin[k] = r->pin[q]; /* k <= q: in place, in order */
        k++;
    }
    gpu_rank_set_halo_peer(r->gpu, r->pfrom, r->pin, k);
    return got;
}

/* The peer path for the run where every rank is on one node and each maps every other's GPU memory
 * (SIM_MPI_CUDA_HOST=1 on any rank: the host path, as across nodes, for testing it). */
static void gpu_peer_start(Run *r)
{
    const char *host = getenv("SIM_MPI_CUDA_HOST");
    int ok = r->locals == mpi_np && mpi_np > 1 && !(host && *host && strcmp(host, "0"));
    MPI_Allreduce(MPI_IN_PLACE, &ok, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    if (!ok) return;
    r->pout = sim_calloc((size_t)mpi_np, sizeof *r->pout);
    r->pin = sim_calloc((size_t)mpi_np, sizeof *r->pin);
    r->pfrom = sim_calloc((size_t)mpi_np, sizeof *r->pfrom);
    GpuPeer mine;
    gpu_rank_export(r->gpu, &mine);
    MPI_Allgather(&mine, sizeof mine, MPI_BYTE, r->pin, sizeof mine, MPI_BYTE, MPI_COMM_WORLD);
    for (int q = 0; q < mpi_np; q++)
        if (q != mpi_me) ok &= gpu_rank_map(r->gpu, q, mpi_np, &r->pin[q]);
    MPI_Allreduce(MPI_IN_PLACE, &ok, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    r->peer = ok;
    gpu_rank_peer(r->gpu, ok);
}

/* The strip the own disks and the copies lie in at this step's midpoints (binned there, moved half a
 * step, less than the reach): the grid's table holds its cells only, unless the rank holds the whole
 * torus. */
static void gpu_slab(Run *r)
{
    double m = 2 * r->reach;
    gpu_rank_slab(r->gpu, !r->whole, mpi_cut[mpi_me] - m, mpi_cut[mpi_me + 1] + m);
}

/* 1 and 2: the reach, and the copies of the own disks within it of other strips, as halo_exchange
 * sends them, listed and packed on the GPU (mpi_halo.h decides alike there), which bins the own disks
 * for the step (largest velocity component vm) while they travel; theirs into the GPU's halo. */
static void gpu_halo(Run *r, double vm)
{
    char *whole = sim_calloc((size_t)mpi_np, 1);
    int any_whole = halo_reach(r, whole);
    const HaloView h = halo_view(r, whole, any_whole);
    gpu_slab(r);
    const double *out = gpu_rank_halo_out(r->gpu, &h, vm, r->scount, &r->nsend);
    free(whole);
    if (r->peer) {
        r->halo = gpu_halo_peer(r);
        return;
    }
    double t0 = sim_clock();
    int64_t got;
    double *in = exchange_near(out, r->scount, D_LEN, r->nlo, r->nhi, r->par.periodic ? r->near : NULL, TAG_HALO,
                               &got, r->rcount, gpu_halo_room, r->gpu);
    r->halo_secs += sim_clock() - t0;
    gpu_rank_set_halo(r->gpu, in, got);
    r->halo = got;
}

/* A round's keys of the disks sent as copies (out, in r->send's order) to the ranks that hold them,
 * and the keys of this rank's copies from their owners into in (the halo's order). */
static void gpu_keys(Run *r, const GpuKey *out, GpuKey *in)
{
    int n = r->nhi - r->nlo + 1;
    MPI_Request *req = sim_calloc(2 * (size_t)n, sizeof *req);
    int64_t soff = 0, roff = 0;
    for (int q = 0; q < r->nlo; q++) soff += r->scount[q], roff += r->rcount[q];
    for (int q = r->nlo; q <= r->nhi; q++) {
        int k = q - r->nlo;
        req[k] = req[n + k] = MPI_REQUEST_NULL;
        /* both ranks of a pair post, or neither: q's scount to this rank is this rank's rcount */
        if (q != mpi_me && (r->scount[q] || r->rcount[q])) {
            MPI_Irecv(in + roff, 3 * r->rcount[q], MPI_UINT64_T, q, KEYS_MORE, r->keys_comm, &req[n + k]);
            MPI_Isend(out + soff, 3 * r->scount[q], MPI_UINT64_T, q, KEYS_MORE, r->keys_comm, &req[k]);
            bytes_sent += (uint64_t)r->scount[q] * sizeof *out;
        }
        soff += r->scount[q], roff += r->rcount[q];
    }
    double t0 = MPI_Wtime();
    MPI_Waitall(2 * n, req, MPI_STATUSES_IGNORE);
    waited += MPI_Wtime() - t0;
    free(req);
}

/* 4: the rounds, until no rank has a live pair event; each exchanges keys with the neighbours
 * between its min passes and its accept pass (mpi_cuda.cu). */
static void gpu_choose(Run *r)
{
    GpuKey *in = gpu_rank_keys_in(r->gpu);
    for (int64_t round = 0;; round++) {
        const GpuKey *out;
        int64_t live = gpu_rank_round(r->gpu, round == 0, &out), all;
        double t0 = MPI_Wtime();
        MPI_Allreduce(&live, &all, 1, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD);
        waited += MPI_Wtime() - t0;
        if (all == 0) break;
        /* each round accepts the smallest live event, at the latest the round after its disks' last
         * decisions arrive: a step has fewer rounds than twice its events */
        if (round > 2 * all + 64)
            sim_fail("internal error: the choice's rounds do not end (%lld live)", (long long)all);
        r->rounds++;
        if (r->peer) /* every rank's keys are in its region: each returned from its round first */
            for (int q = r->nlo; q <= r->nhi; q++) bytes_sent += (uint64_t)r->scount[q] * sizeof(GpuKey);
        else
            gpu_keys(r, out, in);
        gpu_rank_accept(r->gpu);
    }
}

/* 5: the leavers (records from the GPU's move) to the ranks of their new strips, theirs to the GPU. */
static void gpu_migrate(Run *r, int64_t moving, const double *rec)
{
    int64_t got;
    double *in = send_leavers(r, 0, rec, moving, &got);
    gpu_rank_add_own(r->gpu, in, got);
    free(in);
}

/* A bound on the next step's reach, from this step's largest velocity component vm: a collision raises
 * a disk's speed to at most sqrt(2) times the faster one's, so the next step's largest component is at
 * most 2 vm (the margin covers the rounding). */
static double reach_next(const Run *r, double vm)
{
    return reach_at(r, 2 * vm * (1 + 1e-6) * 1.41422) * (1 + 1e-6);
}

/* run_steps on the GPU: the own disks go to it first and come back for each output and at the end. The
 * fastest velocity component over all ranks is known exactly at each step's start (one reduction a
 * step), and bounds the speeds by sqrt(2) times it. */
static double run_steps_gpu(Run *r, RunStats *st)
{
    int64_t k = r->par.substeps, last = r->par.steps * k, first = r->par.first_step * k;
    uint64_t tests = 0;
    /* the records packed on the rank's threads (2.5e8 a rank in the 1e9 run) */
    double *rec = sim_realloc(NULL, (size_t)(r->own ? r->own : 1) * D_LEN, sizeof *rec);
#pragma omp parallel for schedule(static) num_threads(mpi_pass_threads(r->nt, r->own))
    for (int64_t q = 0; q < r->own; q++) pack(&r->b.s, q, rec + q * D_LEN);
    gpu_rank_add_own(r->gpu, rec, r->own);
    free(rec);
    (void)own_speeds(r);
    double vm = (double)r->own_vmax;
    MPI_Allreduce(MPI_IN_PLACE, &vm, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    r->speed = vm * 1.41422;
    r->reach = reach_of(r);
    gpu_slab(r);
    gpu_rank_ready(r->gpu, vm);
    gpu_peer_start(r);
    /* the step loop as cuda times it: from the state on the device to the last step's end */
    MPI_Barrier(MPI_COMM_WORLD);
    double t0 = MPI_Wtime(), waited0 = waited;
    uint64_t bytes0 = bytes_sent;
    StepClock *c = r->clock;
    for (int64_t sub = first + 1; sub <= last; sub++) {
        double ts = MPI_Wtime(), w0 = waited;
        if (c) clock_start(c);
        r->speed = vm * 1.41422; /* |v| <= sqrt(2) max(|vx|, |vy|) */
        gpu_halo(r, vm);
        if (c) clock_end(c, PART_HALO);
        gpu_rank_detect(r->gpu, vm);
        if (c) clock_end(c, PART_FIND);
        gpu_choose(r);
        if (c) clock_end(c, PART_CHOOSE);
        GpuMoved m;
        const double *leavers;
        gpu_rank_move(r->gpu, mpi_cut[mpi_me], mpi_cut[mpi_me + 1], mpi_me == 0, mpi_me == mpi_np - 1,
                      reach_next(r, vm), &m, &leavers);
        r->events += m.events;
        tests += m.tests;
        if (c) clock_end(c, PART_MOVE);
        r->busy += MPI_Wtime() - ts - (waited - w0);
        /* the largest component over all ranks, reduced while the leavers travel */
        double vmine = m.vmax;
        MPI_Request vreq;
        MPI_Iallreduce(&vmine, &vm, 1, MPI_DOUBLE, MPI_MAX, r->speed_comm, &vreq);
        gpu_migrate(r, m.leavers, leavers);
        double tw = MPI_Wtime();
        MPI_Wait(&vreq, MPI_STATUS_IGNORE);
        waited += MPI_Wtime() - tw;
        if (c) {
            clock_end(c, PART_MIGRATE);
            if (++c->fill == CLOCK_CHUNK) clock_flush(c);
        }
        if (sub % k) continue;
        if (r->par.print && sub < last) {
            gpu_download(r);
            Local l = view(r);
            mpi_write_state(r->out, &r->par, &l, sub / k, 0);
        }
        if (io_checkpoint_at(&r->par, r->opt, sub / k)) {
            gpu_download(r);
            Local l = view(r);
            mpi_checkpoint(r->out, &r->par, r->opt, &l, sub / k);
        }
        if (mpi_me == 0) io_progress(r->out, sub / k);
    }
    double secs = MPI_Wtime() - t0;
    gpu_download(r);
    r->bytes_steps = bytes_sent - bytes0;
    r->waited_steps = waited - waited0;
    uint64_t mine[2] = {r->events, tests}, sum[2];
    MPI_Reduce(mine, sum, 2, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD);
    st->events = sum[0];
    st->pair_tests = sum[1];
    return secs;
}
#endif

/* Scales the own disks' velocities by f (a power of two: exact), for --substeps. */
static void scale_own(Run *r, real f)
{
    for (int64_t q = 0; q < r->own; q++) r->b.s.vx[q] = r->b.s.vx[q] * f, r->b.s.vy[q] = r->b.s.vy[q] * f;
}

static int mpi_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *stats)
{
    (void)sim, (void)par, (void)opt, (void)out, (void)stats;
    sim_fail("internal error: mpi runs through its own main");
}

#ifdef MPI_CUDA
static const Backend mpi_backend = {
    "mpi_cuda" SIM_SUFFIX,
    "  --output FILE  write the output into FILE, every rank its own lines (mpirun passes the\n"
    "               ranks' standard output through itself, at some 100 MB/s)\n"
    "run as: mpirun -np P mpi_cuda INPUT [options]: each rank on a GPU of its node (its rank among\n"
    "the node's ranks, modulo the GPUs); ranks all on one node pass halos and keys from GPU to GPU,\n"
    "else (or with SIM_MPI_CUDA_HOST=1) through host memory\n",
    SIM_FEATURE_SUBSTEPS | SIM_FEATURE_OUTPUT | SIM_FEATURE_PERIODIC | SIM_FEATURE_CHECKPOINT,
    mpi_run, NULL, mpi_parallel,
};
#else
static const Backend mpi_backend = {
    "mpi" SIM_SUFFIX,
    "  --threads N  OpenMP threads per rank (default 1: one rank a core)\n"
    "  --check      also test every pair of a rank's disks and halo each step (O(N^2)); for testing\n"
    "  --broad B    the broad phase on one rank: grid, paths, mixed or auto (default); with several\n"
    "               ranks each rank's strip uses the grid\n"
    "  --output FILE  write the output into FILE, every rank its own lines (mpirun passes the\n"
    "               ranks' standard output through itself, at some 100 MB/s)\n"
    "  --balance K  every K steps, move the cuts between strips so that each rank has as much\n"
    "               work as measured (default 0: cuts placed by count at the start only)\n"
    "run as: mpirun -np P mpi INPUT [options]\n",
    SIM_FEATURE_SUBSTEPS | SIM_FEATURE_PRESSURE | SIM_FEATURE_OUTPUT | SIM_FEATURE_THREADS |
        SIM_FEATURE_BALANCE | SIM_FEATURE_PERIODIC | SIM_FEATURE_CHECKPOINT,
    mpi_run, NULL, mpi_parallel,
};
#endif

int main(int argc, char **argv)
{
    MPI_Init(&argc, &argv);
    MPI_Comm_rank(MPI_COMM_WORLD, &mpi_me);
    MPI_Comm_size(MPI_COMM_WORLD, &mpi_np);
    io_use_backend(&mpi_backend);
    /* rank 0 parses first, so that a bad option is reported once; the others then parse the same
     * arguments, which cannot fail */
    Options opt;
    int ok = 0;
    if (mpi_me == 0) {
        io_parse_args(argc, argv, &opt);
        ok = 1;
    }
    MPI_Bcast(&ok, 1, MPI_INT, 0, MPI_COMM_WORLD);
    if (mpi_me != 0) io_parse_args(argc, argv, &opt);

#ifdef MPI_CUDA
    /* the rank's place on its node: its GPU, and its share of the node's cores for the text (the host
     * has no steps to run; --threads is not an option of mpi_cuda) */
    int local = 0, locals = 1;
    {
        MPI_Comm node;
        MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
        MPI_Comm_rank(node, &local);
        MPI_Comm_size(node, &locals);
        MPI_Comm_free(&node);
        int procs = omp_get_num_procs(); /* the rank's mask: its own cores, or the node's where unbound */
        long online = sysconf(_SC_NPROCESSORS_ONLN);
        opt.threads = procs >= online && locals > 1 ? procs / locals : procs;
        if (opt.threads < 1) opt.threads = 1;
    }
#endif
    Run r;
    memset(&r, 0, sizeof r);
    r.opt = &opt;
#ifdef MPI_CUDA
    r.locals = locals;
#endif
    r.nt = opt.threads > 0 ? opt.threads : 1;
    team_start(r.nt); /* a rank's threads on cores of their own where its mask has several */
    if (opt.checkpoint && mpi_me == 0) io_checkpoint_probe(opt.checkpoint);
    Local l;
    memset(&l, 0, sizeof l);
    l.with_wi = opt.pressure;
    double t_read = MPI_Wtime();
    if (opt.resume) { /* the run, its options and its state from the checkpoint */
        mpi_read_checkpoint(&opt, &r.par, &l);
    } else {
        mpi_read_input(&opt, &r.par, &l);
        r.par.first_step = 0;
    }
    t_read = MPI_Wtime() - t_read;
    double input_most[INPUT_PHASES] = {0}; /* each phase's slowest rank (rank 0's copy), for --stats */
    if (opt.stats) /* every rank's options are rank 0's */
        MPI_Reduce(mpi_input_seconds, input_most, INPUT_PHASES, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
#ifdef __GLIBC__
    /* Print mode writes a state a step, and its buffers (the gathered block, its text) were allocated
     * anew each time, faulting in their pages afresh (mpi_io.c): malloc keeps what is freed from here
     * on, to reuse it. Perf mode would only raise its peak memory by it. */
    if (r.par.print) {
        mallopt(M_MMAP_MAX, 0);
        mallopt(M_TRIM_THRESHOLD, INT_MAX);
    }
#endif
#ifdef MPI_CUDA
    r.gpu = gpu_rank_open(&r.par, local); /* before anything is written */
#endif
    r.par.substeps = opt.substeps;
    if (opt.output) mpi_output_file(opt.output);
    if (r.par.steps * (int64_t)opt.substeps > INT32_MAX)
        sim_fail("--substeps %d with S = %lld steps could count more than %d collisions of one disk "
                 "(S x K must be <= %d)", opt.substeps, (long long)r.par.steps, INT32_MAX, INT32_MAX);
    if (mpi_me == 0) r.out = io_output_open(&r.par, &opt);
    if (mpi_me == 0 && opt.resume) io_resume_begin(r.out); /* its virial sums so far; "resuming" */
    double t_step0 = MPI_Wtime();
    if (!opt.resume) mpi_write_state(r.out, &r.par, &l, 0, 0); /* a resumed run's step 0 is out already */
    t_step0 = MPI_Wtime() - t_step0;

    /* the disks into the broad phase's slots, which hold them from here on */
    r.lp = r.par;
    broad_init(&r.b, &r.lp, &opt, l.own + 1024, r.nt, opt.pressure);
    r.b.wall_lists = 1; /* the choice reads the lists of wall events, not wall_t */
    r.own = l.own;
    run_reserve(&r, l.own + 1024);
    copy_own(&r.b.s, &l.s, l.own, r.nt);
    slots_free(&l.s);
    MPI_Comm_dup(MPI_COMM_WORLD, &r.speed_comm);
    MPI_Comm_dup(MPI_COMM_WORLD, &r.keys_comm);
    r.scount = sim_calloc((size_t)mpi_np, sizeof *r.scount);
    r.near = sim_calloc((size_t)mpi_np, 1);
    r.rcount = sim_calloc((size_t)mpi_np, sizeof *r.rcount);

    /* --substeps K: a sub-step of length 1/K is a SPEC.md step at velocities v / K */
    real k = (real)opt.substeps;
    scale_own(&r, 1 / k);
    io_set_velocity_scale(k);
    if (r.par.periodic && opt.pressure && !opt.resume) record_virial(&r, 0);
    RunStats st;
    memset(&st, 0, sizeof st);
    if (opt.stats) {
        r.clock = sim_calloc(1, sizeof *r.clock);
        r.clock->slowest = sim_calloc((size_t)mpi_np, sizeof *r.clock->slowest);
    }
    double t0 = MPI_Wtime();
#ifdef MPI_CUDA
    (void)run_steps;
    st.seconds = run_steps_gpu(&r, &st);
    double gpu_times[GPU_CALLS + 1], gpu_most[GPU_CALLS + 1]; /* and the halo's exchange (Run) */
    memcpy(gpu_times, gpu_rank_times(r.gpu), GPU_CALLS * sizeof *gpu_times);
    gpu_times[GPU_CALLS] = r.halo_secs;
    MPI_Reduce(gpu_times, gpu_most, GPU_CALLS + 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    uint64_t reused[9], reused_sum[9];
    gpu_rank_reused(r.gpu, reused);
    MPI_Reduce(reused, reused_sum, 9, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD);
    gpu_rank_unmap(r.gpu);
    MPI_Barrier(MPI_COMM_WORLD); /* no rank frees its region while another has it mapped */
    gpu_rank_close(r.gpu);
#else
    st.seconds = run_steps(&r, &st);
#endif
    double run_s = MPI_Wtime() - t0;
    if (r.par.periodic && opt.pressure) record_virial(&r, r.par.steps);
    scale_own(&r, k);
    io_set_velocity_scale(1);
    Local fin = view(&r);
    double t_final = MPI_Wtime();
    mpi_write_state(r.out, &r.par, &fin, r.par.steps, 1);
    t_final = MPI_Wtime() - t_final;
    double impulse = 0, squares;
    if (opt.pressure && !r.par.periodic) mpi_index_sums(&r.par, &fin, &impulse, &squares);
    /* --stats: the steps' traffic between ranks, and each rank's peak memory (the largest and rank 0's) */
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    uint64_t mine[5] = {r.bytes_steps, (uint64_t)ru.ru_maxrss, (uint64_t)r.own, r.rounds, (uint64_t)r.most_near};
    uint64_t sum[5], most[5], least[5];
    MPI_Reduce(mine, sum, 5, MPI_UINT64_T, MPI_SUM, 0, MPI_COMM_WORLD);
    MPI_Reduce(mine, most, 5, MPI_UINT64_T, MPI_MAX, 0, MPI_COMM_WORLD);
    MPI_Reduce(mine, least, 5, MPI_UINT64_T, MPI_MIN, 0, MPI_COMM_WORLD);
    /* the step loop split into work and waiting, per rank: the work growing with the ranks is the
     * machine shared (memory, caches); the waiting, the neighbours' slower steps and the exchanges */
    double split[2] = {st.seconds - r.waited_steps, r.waited_steps}, split_sum[2], split_most[2], split_least[2];
    MPI_Reduce(split, split_sum, 2, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    MPI_Reduce(split, split_most, 2, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    MPI_Reduce(split, split_least, 2, MPI_DOUBLE, MPI_MIN, 0, MPI_COMM_WORLD);
    if (r.clock) clock_gather(r.clock);
    if (mpi_me == 0) {
        int64_t subs = r.par.steps * r.par.substeps;
        if (opt.stats)
            fprintf(stderr,
                    "%s: %d ranks x %d threads; %llu rounds of the choice on the rank with the most (%.3g a "
                    "step); %.4g bytes sent between ranks a step; peak memory: largest rank %.1f MB, rank 0 "
                    "%.1f MB, all ranks %.1f MB\n",
                    sim_program, mpi_np, r.nt, (unsigned long long)most[3],
                    subs ? (double)most[3] / (double)subs : 0.0, subs ? (double)sum[0] / (double)subs : 0.0,
                    (double)most[1] / 1024, (double)mine[1] / 1024, (double)sum[1] / 1024);
        if (opt.stats)
            fprintf(stderr, "%s: the cuts between strips moved %lld times (--balance %lld); disks a rank at "
                    "the end %llu to %llu; neighbours a rank exchanged with in a step: up to %llu\n",
                    sim_program, (long long)r.moves, (long long)opt.balance, (unsigned long long)least[2],
                    (unsigned long long)most[2], (unsigned long long)most[4]);
        if (opt.stats)
            fprintf(stderr, "%s: a rank's step loop outside MPI calls %.4f to %.4f s (mean %.4f), inside them "
                    "%.4f to %.4f s (mean %.4f)\n", sim_program, split_least[0], split_most[0],
                    split_sum[0] / mpi_np, split_least[1], split_most[1], split_sum[1] / mpi_np);
        if (r.clock) clock_report(r.clock);
#ifdef MPI_CUDA
        if (opt.stats) {
            static const char *const name[GPU_CALLS + 1] = GPU_CALL_NAMES_AND("halo exchange");
            fprintf(stderr, "%s: the host's seconds in each GPU call, and in the halo's exchange (its waits "
                    "included), the slowest rank's (rank 0's):", sim_program);
            for (int k = 0; k < GPU_CALLS + 1; k++)
                fprintf(stderr, "%s %s %.4f (%.4f)", k ? "," : "", name[k], gpu_most[k], gpu_times[k]);
            fprintf(stderr, "; halos and keys %s\n", r.peer ? "GPU to GPU" : "through host memory");
            fprintf(stderr, "%s: rank-steps whose own disks the move before keyed for their cells: %llu, binned "
                    "anew though keyed (the grid ahead did not fit): %llu\n", sim_program,
                    (unsigned long long)reused_sum[0], (unsigned long long)reused_sum[1]);
            fprintf(stderr, "%s: rank-steps whose halo looked only at the own disks the move before listed near "
                    "the cuts: %llu, at every own disk: %llu; moves done twice (more leavers than room): %llu; "
                    "searches done twice (more events than the list held): %llu; searches done again for a cell "
                    "past 255 disks (8-bit counts): %llu\n", sim_program, (unsigned long long)reused_sum[2],
                    (unsigned long long)reused_sum[3], (unsigned long long)reused_sum[4],
                    (unsigned long long)reused_sum[5], (unsigned long long)reused_sum[8]);
            fprintf(stderr, "%s: rank-steps that settled first found %llu pair events and left %llu of them to the "
                    "rounds (the others, the only event of both disks)\n", sim_program,
                    (unsigned long long)reused_sum[6], (unsigned long long)reused_sum[7]);
        }
#endif
        if (opt.stats) {
            fprintf(stderr, "%s: input read and sent to the strips %.4f s", sim_program, t_read);
            if (input_most[INPUT_READ] + input_most[INPUT_PARSE] > 0)
                fprintf(stderr, " (each phase's slowest rank: read %.4f s, parsed %.4f, indices checked %.4f, "
                        "sent to the strips %.4f)", input_most[INPUT_READ], input_most[INPUT_PARSE],
                        input_most[INPUT_CHECK], input_most[INPUT_STRIPS]);
            fprintf(stderr, "; step 0 written %.4f s, the final state %.4f s\n", t_step0, t_final);
        }
        io_report(r.out, &r.par, &opt, &st, run_s, impulse);
        io_output_close(r.out);
    }
    broad_free(&r.b);
    free(r.send), free(r.scount), free(r.rcount), free(r.node), free(r.adj), free(r.active);
    free(r.node_of), free(r.hbuf), free(r.near), free(r.pout), free(r.pin), free(r.pfrom);
    MPI_Comm_free(&r.speed_comm);
    MPI_Comm_free(&r.keys_comm);
    if (r.clock) free(r.clock->slowest), free(r.clock);
    MPI_Finalize();
    return 0;
}
