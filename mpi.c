/* mpi.c: the MPI backend, a first version (branch mpi-start): the box cut into P vertical strips, each
 * rank holding the disks whose centres lie in its strip and, each step, copies of the disks of other
 * strips within reach of its own (the halo). Every rank finds the events of its own disks, the ranks
 * choose among them in rounds that equal SPEC.md 3.3's greedy walk, each moves its own disks, and disks
 * that left a strip go to their new rank.
 *
 * Not yet done: rank 0 reads the input and writes the output through io.c (so it holds the whole state
 * at those moments); no threads inside a rank; no --pressure, --exact or checkpoints.
 */
#include "io.h"

#include <mpi.h>
#include <stdlib.h>
#include <string.h>

const char backend_name[] = "mpi" SIM_SUFFIX;
const char backend_options[] = "";
const unsigned backend_features = SIM_FEATURE_SUBSTEPS;

static int me, np;

/* A disk as it travels between ranks: seven doubles (ids and counts are exact in a double). */
enum { D_ID, D_X, D_Y, D_VX, D_VY, D_PC, D_WC, D_LEN };

typedef struct {
    double *d;    /* D_LEN doubles a disk: own disks first, then the halo */
    int64_t own, halo, cap;
} Disks;

typedef struct {
    real t;
    int kind;
    int64_t i, j; /* original indices, i < j (i == j: a wall) */
    int64_t a, b; /* local indices: a own; b own or halo (a for a wall) */
} Ev;

typedef struct {
    Ev *e;
    int64_t len, cap;
} EvList;

static void *grow(void *p, int64_t *cap, int64_t need, size_t size)
{
    if (need <= *cap) return p;
    int64_t c = *cap ? *cap : 1024;
    while (c < need) c *= 2;
    void *q = realloc(p, (size_t)c * size);
    if (!q) sim_fail("out of memory (%lld x %zu bytes)", (long long)c, size);
    *cap = c;
    return q;
}

static void disks_reserve(Disks *s, int64_t n)
{
    int64_t cap = s->cap;
    s->d = grow(s->d, &cap, n, D_LEN * sizeof(double));
    s->cap = cap;
}

static int owner_of(double x, double L)
{
    int q = (int)(x / (L / np));
    return q < 0 ? 0 : q >= np ? np - 1 : q;
}

/* ---- exchanges ------------------------------------------------------------------------------------ */

/* Sends count[q] records of `width` doubles to each rank q (packed in rank order in `out`) and returns
 * what arrives, in rank order; *got is the number of records. */
static double *exchange(const double *out, const int *count, int width, int64_t *got, int *rcount)
{
    int *sd = calloc((size_t)np, sizeof *sd), *rd = calloc((size_t)np, sizeof *rd);
    int *sc = calloc((size_t)np, sizeof *sc), *rc = calloc((size_t)np, sizeof *rc);
    MPI_Alltoall(count, 1, MPI_INT, rcount, 1, MPI_INT, MPI_COMM_WORLD);
    int64_t total = 0, off = 0;
    for (int q = 0; q < np; q++) {
        sc[q] = count[q] * width;
        sd[q] = (int)off;
        off += sc[q];
        rc[q] = rcount[q] * width;
        rd[q] = (int)(total * width);
        total += rcount[q];
    }
    double *in = malloc((size_t)(total ? total : 1) * (size_t)width * sizeof *in);
    if (!in) sim_fail("out of memory receiving %lld records", (long long)total);
    MPI_Alltoallv(out, sc, sd, MPI_DOUBLE, in, rc, rd, MPI_DOUBLE, MPI_COMM_WORLD);
    free(sd), free(rd), free(sc), free(rc);
    *got = total;
    return in;
}

/* The halo: every own disk within `reach` of another rank's strip, copied there. send[] gets the own
 * disks sent, rank by rank (scount[q] each), for the choice's exchanges. */
static void halo_exchange(Disks *s, double L, double reach, int64_t **send, int *scount, int *rcount)
{
    double w = L / np;
    int64_t nsend = 0, cap = 0;
    int64_t *list = NULL;
    for (int q = 0; q < np; q++) {
        scount[q] = 0;
        if (q == me) continue;
        double lo = q * w - reach, hi = (q + 1) * w + reach;
        for (int64_t k = 0; k < s->own; k++) {
            double x = s->d[k * D_LEN + D_X];
            if (x >= lo && x <= hi) {
                list = grow(list, &cap, nsend + 1, sizeof *list);
                list[nsend++] = k;
                scount[q]++;
            }
        }
    }
    double *out = malloc((size_t)(nsend ? nsend : 1) * D_LEN * sizeof *out);
    for (int64_t k = 0; k < nsend; k++) memcpy(out + k * D_LEN, s->d + list[k] * D_LEN, D_LEN * sizeof *out);
    int64_t got;
    double *in = exchange(out, scount, D_LEN, &got, rcount);
    disks_reserve(s, s->own + got);
    memcpy(s->d + s->own * D_LEN, in, (size_t)got * D_LEN * sizeof *in);
    s->halo = got;
    free(in);
    free(out);
    *send = list;
}

/* ---- one step (SPEC.md 3) -------------------------------------------------------------------------- */

typedef struct {
    real x, y, vx, vy;
} Kin;

static Kin kin(const Disks *s, int64_t k)
{
    const double *d = s->d + k * D_LEN;
    Kin r = {(real)d[D_X], (real)d[D_Y], (real)d[D_VX], (real)d[D_VY]};
    return r;
}

static void push(EvList *l, real t, int kind, int64_t i, int64_t j, int64_t a, int64_t b)
{
    l->e = grow(l->e, &l->cap, l->len + 1, sizeof *l->e);
    Ev e = {t, kind, i, j, a, b};
    l->e[l->len++] = e;
}

/* The events of the own disks: walls, and pairs with own or halo disks, found in cells as wide as the
 * reach (no pair farther apart can meet within the step). */
static void find_events(const Disks *s, const Params *p, double reach, EvList *l)
{
    int64_t nl = s->own + s->halo;
    /* cells at least `reach` wide, and about as many as disks (a huge box needs no more) */
    int64_t side = (int64_t)((double)p->L / reach), most = (int64_t)sqrt((double)nl) + 1;
    if (side > most) side = most;
    if (side < 1) side = 1;
    double cell = (double)p->L / (double)side;
    int64_t *head = malloc((size_t)(side * side) * sizeof *head), *next = malloc((size_t)(nl ? nl : 1) * sizeof *next);
    for (int64_t c = 0; c < side * side; c++) head[c] = -1;
    for (int64_t k = nl - 1; k >= 0; k--) {
        int64_t cx = (int64_t)(s->d[k * D_LEN + D_X] / cell), cy = (int64_t)(s->d[k * D_LEN + D_Y] / cell);
        if (cx >= side) cx = side - 1;
        if (cy >= side) cy = side - 1;
        next[k] = head[cy * side + cx];
        head[cy * side + cx] = k;
    }
    l->len = 0;
    for (int64_t a = 0; a < s->own; a++) {
        Kin u = kin(s, a);
        int64_t ia = (int64_t)s->d[a * D_LEN + D_ID];
        real tw = min_time(wall_time(u.x, u.vx, p->lo, p->hi), wall_time(u.y, u.vy, p->lo, p->hi));
        if (tw <= 1) push(l, tw, 0, ia, ia, a, a);
        int64_t cx = (int64_t)(u.x / cell), cy = (int64_t)(u.y / cell);
        if (cx >= side) cx = side - 1;
        if (cy >= side) cy = side - 1;
        for (int64_t ny = cy - 1; ny <= cy + 1; ny++)
            for (int64_t nx = cx - 1; nx <= cx + 1; nx++) {
                if (nx < 0 || ny < 0 || nx >= side || ny >= side) continue;
                for (int64_t b = head[ny * side + nx]; b >= 0; b = next[b]) {
                    int64_t ib = (int64_t)s->d[b * D_LEN + D_ID];
                    if (b == a || (b < s->own && ib < ia)) continue; /* own pairs once, from the lower */
                    Kin v = kin(s, b);
                    int lower = ia < ib;
                    const Kin *ki = lower ? &u : &v, *kj = lower ? &v : &u;
                    real t = pair_time(ki->x, ki->y, ki->vx, ki->vy, kj->x, kj->y, kj->vx, kj->vy, p->sigma2);
                    if (t >= 0) push(l, t, 1, lower ? ia : ib, lower ? ib : ia, a, b);
                }
            }
    }
    free(head);
    free(next);
}

/* A key as four doubles for the exchanges: t, kind, i, j; t = 2 (later than any event) for none. */
static int key_less(const double *x, const double *y)
{
    return event_before((real)x[0], (int)x[1], (int64_t)x[2], (int64_t)x[3], (real)y[0], (int)y[1],
                        (int64_t)y[2], (int64_t)y[3]);
}

/* SPEC.md 3.3 in rounds: an event is accepted when it is the smallest live event of each of its disks
 * (live: both disks undecided). The owners' smallest keys and decisions reach the halo copies every
 * round. chosen[a] gets the event of own disk a, or -1. */
static void choose(const Disks *s, EvList *l, const int64_t *send, const int *scount, int64_t *chosen)
{
    int64_t nl = s->own + s->halo, nsend = 0;
    for (int q = 0; q < np; q++) nsend += scount[q];
    /* per local disk: the smallest live key (4 doubles) and decided (1 double) */
    double *st = malloc((size_t)(nl ? nl : 1) * 5 * sizeof *st);
    double *out = malloc((size_t)(nsend ? nsend : 1) * 5 * sizeof *out);
    for (int64_t k = 0; k < nl; k++) st[k * 5 + 4] = 0;
    for (int64_t a = 0; a < s->own; a++) chosen[a] = -1;
    for (;;) {
        for (int64_t k = 0; k < s->own; k++) st[k * 5] = 2, st[k * 5 + 1] = 0, st[k * 5 + 2] = 0, st[k * 5 + 3] = 0;
        int64_t live = 0;
        for (int64_t k = 0; k < l->len; k++) {
            const Ev *e = &l->e[k];
            if (st[e->a * 5 + 4] != 0 || st[e->b * 5 + 4] != 0) continue;
            live++;
            double key[4] = {(double)e->t, e->kind, (double)e->i, (double)e->j};
            int64_t ends[2] = {e->a, e->b};
            for (int m = 0; m < (e->a == e->b ? 1 : 2); m++) {
                int64_t d = ends[m];
                if (d < s->own && key_less(key, st + d * 5)) memcpy(st + d * 5, key, sizeof key);
            }
        }
        int64_t all;
        MPI_Allreduce(&live, &all, 1, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD);
        if (all == 0) break;
        for (int64_t k = 0; k < nsend; k++) memcpy(out + k * 5, st + send[k] * 5, 5 * sizeof *out);
        int64_t got;
        int *rc = calloc((size_t)np, sizeof *rc);
        double *in = exchange(out, scount, 5, &got, rc);
        memcpy(st + s->own * 5, in, (size_t)got * 5 * sizeof *in);
        free(in);
        free(rc);
        for (int64_t k = 0; k < l->len; k++) {
            const Ev *e = &l->e[k];
            if (st[e->a * 5 + 4] != 0 || st[e->b * 5 + 4] != 0) continue;
            double key[4] = {(double)e->t, e->kind, (double)e->i, (double)e->j};
            if (memcmp(key, st + e->a * 5, sizeof key) != 0 || memcmp(key, st + e->b * 5, sizeof key) != 0)
                continue;
            chosen[e->a] = k;
            if (e->b < s->own) chosen[e->b] = k;
        }
        for (int64_t a = 0; a < s->own; a++)
            if (chosen[a] >= 0) st[a * 5 + 4] = 1;
        for (int64_t k = 0; k < l->len; k++) { /* a halo partner of an accepted event is decided too */
            const Ev *e = &l->e[k];
            if (e->b >= s->own && chosen[e->a] == k) st[e->b * 5 + 4] = 1;
        }
    }
    free(st);
    free(out);
}

/* SPEC.md 3.4 and 3.5 for the own disks, from the state at the start of the step. */
static void move(Disks *s, const Params *p, const EvList *l, const int64_t *chosen)
{
    real lo = p->lo, hi = p->hi;
    double *next = malloc((size_t)(s->own ? s->own : 1) * 4 * sizeof *next);
    for (int64_t a = 0; a < s->own; a++) {
        Kin u = kin(s, a);
        double *d = s->d + a * D_LEN;
        if (chosen[a] < 0) {
            u.x = u.x + u.vx;
            u.y = u.y + u.vy;
        } else {
            const Ev *e = &l->e[chosen[a]];
            if (e->kind == 0) {
                wall_bounce(&u.x, &u.y, &u.vx, &u.vy, e->t, lo, hi);
                finish_step(&u.x, &u.y, u.vx, u.vy, e->t, lo, hi);
                d[D_WC] += 1;
            } else {
                int64_t b = e->a == a ? e->b : e->a;
                Kin v = kin(s, b);
                int lower = (int64_t)d[D_ID] == e->i;
                Kin *ki = lower ? &u : &v, *kj = lower ? &v : &u;
                pair_contact(&ki->x, &ki->y, &ki->vx, &ki->vy, &kj->x, &kj->y, &kj->vx, &kj->vy, e->t);
                finish_step(&u.x, &u.y, u.vx, u.vy, e->t, lo, hi);
                d[D_PC] += 1;
            }
        }
        next[a * 4] = u.x, next[a * 4 + 1] = u.y, next[a * 4 + 2] = u.vx, next[a * 4 + 3] = u.vy;
    }
    for (int64_t a = 0; a < s->own; a++) {
        double *d = s->d + a * D_LEN;
        d[D_X] = clamp_coord((real)next[a * 4], lo, hi);
        d[D_Y] = clamp_coord((real)next[a * 4 + 1], lo, hi);
        d[D_VX] = next[a * 4 + 2];
        d[D_VY] = next[a * 4 + 3];
    }
    free(next);
}

/* Disks that left the strip go to the rank of their new strip. */
static void migrate(Disks *s, double L)
{
    int *count = calloc((size_t)np, sizeof *count), *rcount = calloc((size_t)np, sizeof *rcount);
    int64_t moving = 0;
    for (int64_t a = 0; a < s->own; a++) {
        int q = owner_of(s->d[a * D_LEN + D_X], L);
        if (q != me) count[q]++, moving++;
    }
    double *out = malloc((size_t)(moving ? moving : 1) * D_LEN * sizeof *out);
    int64_t *at = calloc((size_t)np, sizeof *at), keep = 0;
    for (int q = 1; q < np; q++) at[q] = at[q - 1] + count[q - 1];
    for (int64_t a = 0; a < s->own; a++) {
        int q = owner_of(s->d[a * D_LEN + D_X], L);
        if (q != me) memcpy(out + (at[q]++) * D_LEN, s->d + a * D_LEN, D_LEN * sizeof *out);
        else memmove(s->d + (keep++) * D_LEN, s->d + a * D_LEN, D_LEN * sizeof *out);
    }
    int64_t got;
    double *in = exchange(out, count, D_LEN, &got, rcount);
    disks_reserve(s, keep + got);
    memcpy(s->d + keep * D_LEN, in, (size_t)got * D_LEN * sizeof *in);
    s->own = keep + got;
    s->halo = 0;
    free(in), free(out), free(at), free(count), free(rcount);
}

/* ---- the run: rank 0 scatters the disks, all ranks step, rank 0 gathers the states to print ---- */

static void gather(const Disks *s, Sim *sim, int64_t n)
{
    int mine = (int)(s->own * D_LEN), *counts = NULL, *displ = NULL;
    double *all = NULL;
    if (me == 0) {
        counts = calloc((size_t)np, sizeof *counts);
        displ = calloc((size_t)np, sizeof *displ);
        all = malloc((size_t)n * D_LEN * sizeof *all);
    }
    MPI_Gather(&mine, 1, MPI_INT, counts, 1, MPI_INT, 0, MPI_COMM_WORLD);
    if (me == 0)
        for (int q = 1; q < np; q++) displ[q] = displ[q - 1] + counts[q - 1];
    MPI_Gatherv(s->d, mine, MPI_DOUBLE, all, counts, displ, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    if (me == 0) {
        for (int64_t k = 0; k < n; k++) {
            const double *d = all + k * D_LEN;
            int64_t i = (int64_t)d[D_ID];
            sim->x[i] = (real)d[D_X], sim->y[i] = (real)d[D_Y];
            sim->vx[i] = (real)d[D_VX], sim->vy[i] = (real)d[D_VY];
            sim->pc[i] = (int32_t)d[D_PC], sim->wc[i] = (int32_t)d[D_WC];
        }
        free(all), free(counts), free(displ);
    }
}

static double run_steps(Disks *s, const Params *p, Sim *sim, Output *out)
{
    EvList l = {NULL, 0, 0};
    int *scount = calloc((size_t)np, sizeof *scount), *rcount = calloc((size_t)np, sizeof *rcount);
    int64_t k = p->substeps, last = p->steps * k;
    double t0 = MPI_Wtime();
    for (int64_t sub = 1; sub <= last; sub++) {
        double vmax = 0, all;
        for (int64_t a = 0; a < s->own; a++) {
            double vx = fabs(s->d[a * D_LEN + D_VX]), vy = fabs(s->d[a * D_LEN + D_VY]);
            vmax = vmax > vx ? vmax : vx;
            vmax = vmax > vy ? vmax : vy;
        }
        MPI_Allreduce(&vmax, &all, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
        /* two disks close in by at most 2 sqrt(2) vmax in a step; margins for rounding */
        double reach = (2 * (double)p->r + 2.83 * all) * (1 + 1e-6) + 1e-9 * (double)p->L;
        int64_t *send = NULL;
        halo_exchange(s, (double)p->L, reach, &send, scount, rcount);
        find_events(s, p, reach, &l);
        int64_t *chosen = malloc((size_t)(s->own ? s->own : 1) * sizeof *chosen);
        choose(s, &l, send, scount, chosen);
        move(s, p, &l, chosen);
        free(chosen);
        free(send);
        s->halo = 0;
        migrate(s, (double)p->L);
        if (sub % k == 0 && p->print && sub < last) {
            gather(s, sim, p->n);
            if (me == 0) io_write_lines(out, sub / k, sim, p->n, 0);
        }
        if (me == 0 && sub % k == 0) io_progress(out, sub / k);
    }
    free(l.e), free(scount), free(rcount);
    return MPI_Wtime() - t0;
}

static void scatter(Disks *s, const Sim *sim, int64_t n, double L)
{
    int *count = calloc((size_t)np, sizeof *count), *rcount = calloc((size_t)np, sizeof *rcount);
    double *out = NULL;
    if (me == 0) {
        for (int64_t i = 0; i < n; i++) count[owner_of(sim->x[i], L)]++;
        out = malloc((size_t)n * D_LEN * sizeof *out);
        int64_t *at = calloc((size_t)np, sizeof *at);
        for (int q = 1; q < np; q++) at[q] = at[q - 1] + count[q - 1];
        for (int64_t i = 0; i < n; i++) {
            double *d = out + (at[owner_of(sim->x[i], L)]++) * D_LEN;
            d[D_ID] = (double)i, d[D_X] = sim->x[i], d[D_Y] = sim->y[i], d[D_VX] = sim->vx[i];
            d[D_VY] = sim->vy[i], d[D_PC] = sim->pc[i], d[D_WC] = sim->wc[i];
        }
        free(at);
    }
    int mine;
    MPI_Scatter(count, 1, MPI_INT, &mine, 1, MPI_INT, 0, MPI_COMM_WORLD);
    int *sc = NULL, *sd = NULL;
    if (me == 0) {
        sc = calloc((size_t)np, sizeof *sc);
        sd = calloc((size_t)np, sizeof *sd);
        for (int q = 0; q < np; q++) sc[q] = count[q] * D_LEN;
        for (int q = 1; q < np; q++) sd[q] = sd[q - 1] + sc[q - 1];
    }
    disks_reserve(s, mine);
    MPI_Scatterv(out, sc, sd, MPI_DOUBLE, s->d, mine * D_LEN, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    s->own = mine;
    s->halo = 0;
    free(out), free(sc), free(sd), free(count), free(rcount);
}

/* All ranks: the run of Params p (rank 0's, broadcast to the others as it is: the same machines, the
 * same build). */
static void distributed(Params p, Sim *sim, Output *out, RunStats *st)
{
    MPI_Bcast(&p, (int)sizeof p, MPI_BYTE, 0, MPI_COMM_WORLD);
    Disks s = {NULL, 0, 0, 0};
    scatter(&s, sim, p.n, (double)p.L);
    double secs = run_steps(&s, &p, sim, out);
    gather(&s, sim, p.n);
    if (st) st->seconds = secs;
    free(s.d);
}

int backend_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *stats)
{
    (void)opt;
    distributed(*par, sim, out, stats);
    return 0;
}

void backend_prepare(const Params *par)
{
    (void)par;
}

void backend_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    (void)threads;
    for (int64_t k = 0; k < tasks; k++) task(ctx, k);
}

int main(int argc, char **argv)
{
    MPI_Init(&argc, &argv);
    MPI_Comm_rank(MPI_COMM_WORLD, &me);
    MPI_Comm_size(MPI_COMM_WORLD, &np);
    int rc = 0;
    if (me == 0) {
        rc = io_main(argc, argv);
    } else {
        Params p;
        memset(&p, 0, sizeof p);
        distributed(p, NULL, NULL, NULL);
    }
    MPI_Finalize();
    return rc;
}
