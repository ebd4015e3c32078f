/* omp.c: the OpenMP backend, linear in N per step.
 *
 * Same bytes as seq.c for every input and thread count; only the search for pairs and the choice of
 * events are organised differently:
 * - layout: the disks live in slots, kept in the cell order of the grid below (a counting sort moves
 *   them every few steps), so that neighbours are neighbours in memory; each slot remembers its
 *   disk's original index, which alone decides the event order and the output order.
 * - broad phase, one of three, whichever the cost model expects to be cheapest this step:
 *   grid (slow scenes): every disk's swept box (its path over the step, grown by r and a rounding
 *   margin) is binned by its centre into square cells at least as wide as two boxes can be apart and
 *   still overlap, so overlapping boxes lie in the same or neighbouring cells; a pair whose boxes
 *   overlap goes to the narrow phase (pair_time).
 *   paths (fast scenes, omp_paths.c): every disk's path is binned into the cells it crosses with the
 *   interval of time it spends in each; pairs meet only in a shared cell at overlapping times.
 *   mixed (a few fast disks among slow ones): the slow disks in a grid for their own speed, the
 *   paths of the fast ones among themselves and across the slow grid's cells.
 *   All find exactly the pair events that the choice can accept (before_walls in omp_step.h).
 * - choice: per-disk lists of candidate events (CSR), then rounds of "accept every event that is the
 *   smallest remaining event of all its disks", finished by a sort and walk once few disks remain.
 *   That is exactly the greedy choice of SPEC.md 3.3, whatever the thread count.
 * - move, and in print mode formatting, in parallel over disks. No floating-point sums across threads
 *   anywhere; the one reduction, the fastest velocity component, is a maximum and exact.
 * All buffers are allocated once (event buffers grow geometrically when a step needs more).
 */
#include "exact.h"
#include "omp_step.h"

#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char backend_name[] = "omp" SIM_SUFFIX;
const char backend_options[] =
    "  --threads N  OpenMP threads (default: OMP_NUM_THREADS or all cores)\n"
    "  --check      also test every pair each step (with --exact: each time window; O(N^2)) and\n"
    "               stop with a message if the broad phase missed an event; for testing\n"
    "  --broad B    the broad phase: grid (cells as wide as the fastest disk's step), paths (each\n"
    "               disk's path through the cells it crosses), mixed (slow disks in a grid, the\n"
    "               paths of fast ones across it) or auto (default: the cheapest, step by step)\n";
const unsigned backend_features =
    SIM_FEATURE_SUBSTEPS | SIM_FEATURE_PRESSURE | SIM_FEATURE_EXACT | SIM_FEATURE_CHECKPOINT;

#define SEQ_FINISH 1024  /* disks still undecided at which the rounds end in a sequential walk */
#define SMALL_CHOICE 1024 /* pair events up to which a step's choice runs on one thread */
#define REORDER_EVERY 8  /* steps between reorders when disks move less than a cell per step */
#define SCAN_WIDTH 4     /* boxes one group of the scan tests at once */
#if SCAN_WIDTH != 4
#error "scan_range writes out the four box tests of a group"
#endif


/* Relative costs of the grid's broad phase per step, against those of the paths' (omp_paths.c):
 * binning one disk, clearing and summing one cell of one thread's histogram, testing one pair of
 * boxes. */
#define COST_BIN 1.0
#define COST_CELL 0.3
#define COST_BOX 0.25

/* ==== types ========================================================================================== */

/* The box swept by one disk over the step, grown by the radius and the rounding margin. */
typedef struct {
    real xlo, xhi, ylo, yhi;
} Span;

/* An event of the sequential finish: the key of SPEC.md 3.3 and the slots of its disks. */
typedef struct {
    real t;
    int kind;     /* 0: wall, 1: pair */
    int32_t i, j; /* original indices */
    int32_t a, b; /* slots */
} SeqEvent;

/* The broad phases of a step. */
enum { MODE_GRID, MODE_PATHS, MODE_MIXED };

/* The plan of one step: its broad phase and the geometry of its grid (MODE_GRID, MODE_MIXED) and
 * paths (MODE_PATHS, MODE_MIXED). */
typedef struct {
    int mode;
    double v_cut; /* MODE_MIXED: disks with a velocity component of v_cut or more are fast */
    int64_t g;    /* cells per side; g * g cells */
    double x0, y0; /* lower corner of the grid */
    double inv_h; /* 1 / cell side */
    double grow;  /* r plus the rounding margin: half the size of a box at rest */
    double reach; /* MODE_MIXED: SlowGrid's */
    PathsPlan paths;
} Plan;

/* Disks by their fastest velocity component a, for the plan: bin k (1..62) holds a / span in
 * [2^(k-48), 2^(k-47)); bin 0 the disks at rest, bins 1 and 63 everything below and above. */
#define SPEED_BINS 64
static inline int speed_bin(double a, double inv_span)
{
    double f = a * inv_span;
    if (!(f > 0)) return 0;
    uint64_t bits;
    memcpy(&bits, &f, sizeof bits); /* the binary exponent, without a call to ilogb */
    int k = (int)(bits >> 52 & 0x7ff) - 1023 + 48;
    return k < 1 ? 1 : (k > SPEED_BINS - 1 ? SPEED_BINS - 1 : k);
}

/* Per-thread state, padded so that threads never share a cache line. */
typedef struct {
    Found found;      /* pair events found by this thread this step */
    int64_t n_active; /* undecided disks of this thread's range, at active + range start */
    int64_t partial;  /* this thread's part of a prefix sum */
    size_t ev_off;    /* where this thread's events go in the gathered list */
    uint64_t events;
    real vmax;
    /* the changes this step to Work's speed_n and speed_s1 */
    int64_t speed_n[SPEED_BINS], speed_s1[SPEED_BINS];
    int32_t *fast;    /* MODE_MIXED: the fast slots this thread binned */
    size_t fast_len, fast_cap;
    char pad[64];
} Thread;

typedef struct {
    Sim *sim;         /* the caller's state, original order: filled for printing and at the end */
    Slots s, spare;   /* the disks in slot order; spare receives the next order */
    const Params *p;
    const Options *opt;
    Output *out;
    TextJob text;     /* print mode: the state being formatted and written */
    int nt;           /* threads in the parallel region */
    Plan plan;
    Thread *th;
    Paths *paths;     /* the broad phase of fast scenes */
    int32_t *cell_of; /* n: cell of each slot */
    int32_t *hist;    /* nt * max cells: per-thread cell counts, then write cursors */
    int32_t *cell_start; /* max cells + 1: first box of each cell */
    int64_t max_cells;
    Box *boxes;       /* n: the boxes in cell order */
    int32_t *box_slot; /* n: the slots of those boxes */
    /* the rest is indexed by slot */
    real *wall_t;   /* n: wall event time, or -1 */
    PairEvent *ev;    /* all pair events of the step */
    size_t n_ev, ev_cap;
    int64_t *off;     /* n + 1: CSR offsets of each disk's events in adj */
    size_t *adj;      /* 2 * n_ev: event indices */
    size_t adj_cap;
    int32_t *active;  /* n: undecided disks, each thread's in its own range */
    int32_t *best_p;  /* n: partner slot of the smallest remaining event (itself: wall; -1: none) */
    real *best_t;   /* n: time of that event */
    int32_t *acc_p;   /* n: partner of the accepted event (itself: wall; -1: none) */
    real *acc_t;    /* n: time of the accepted event */
    unsigned char *taken; /* n: 1 once the disk has an accepted event */
    int64_t undecided;   /* disks left after a round of the choice */
    /* the disks by speed_bin, for the plan: how many, and the sum of their axis speeds (each at
     * most the box) in units of the box / 2^20; kept up to date through the threads' changes, as
     * only pair collisions change the size of a velocity component */
    int64_t speed_n[SPEED_BINS], speed_s1[SPEED_BINS];
    int64_t path_steps;  /* steps that used the paths' broad phase (--stats) */
    int64_t mixed_steps; /* steps that used the mixed one (--stats) */
    SeqEvent *fin;    /* events of the sequential finish */
    size_t fin_cap;
    SeqEvent *fin_tmp; /* sort_events' buffer */
    size_t fin_tmp_cap;
} Work;

static void range_of(int64_t n, int tid, int nt, int64_t *from, int64_t *to)
{
    *from = n * tid / nt;
    *to = n * (tid + 1) / nt;
}

void *omp_grow(void *ptr, size_t *cap, size_t need, size_t size)
{
    if (need <= *cap) return ptr;
    size_t c = *cap ? *cap : 64;
    while (c < need) c *= 2;
    void *p = realloc(ptr, c * size);
    if (!p) sim_fail("out of memory (%zu x %zu bytes)", c, size);
    *cap = c;
    return p;
}

/* ==== slots ========================================================================================= */

static void slots_alloc(Slots *s, int64_t n, int with_wi)
{
    s->wi = with_wi ? sim_calloc((size_t)n, sizeof *s->wi) : NULL;
    s->x = sim_calloc((size_t)n, sizeof *s->x);
    s->y = sim_calloc((size_t)n, sizeof *s->y);
    s->vx = sim_calloc((size_t)n, sizeof *s->vx);
    s->vy = sim_calloc((size_t)n, sizeof *s->vy);
    s->id = sim_calloc((size_t)n, sizeof *s->id);
    s->pc = sim_calloc((size_t)n, sizeof *s->pc);
    s->wc = sim_calloc((size_t)n, sizeof *s->wc);
}

static void slots_free(Slots *s)
{
    free(s->x);
    free(s->y);
    free(s->vx);
    free(s->vy);
    free(s->id);
    free(s->pc);
    free(s->wc);
    free(s->wi);
}

/* Turns each thread's partial count into the sum of the counts of the threads before it; returns the
 * total. Called by one thread between barriers. */
static int64_t scan_partials(Work *w, int nt)
{
    int64_t acc = 0;
    for (int t = 0; t < nt; t++) {
        int64_t v = w->th[t].partial;
        w->th[t].partial = acc;
        acc += v;
    }
    return acc;
}

/* Copies the slots of this thread's range back to the caller's state, in original order. */
static void slots_unpermute(Work *w, int tid)
{
    const Slots *s = &w->s;
    Sim *sim = w->sim;
    int64_t from, to;
    range_of(w->p->n, tid, w->nt, &from, &to);
    for (int64_t q = from; q < to; q++) {
        int32_t i = s->id[q];
        sim->x[i] = s->x[q];
        sim->y[i] = s->y[q];
        sim->vx[i] = s->vx[q];
        sim->vy[i] = s->vy[q];
        sim->pc[i] = s->pc[q];
        sim->wc[i] = s->wc[q];
        if (s->wi) sim->wi[i] = s->wi[q];
    }
}

/* ==== broad phase ==================================================================================== */

/* The grid for disks moving at most v along an axis, boxes grown by grow: cells as wide as two boxes
 * can be apart and still overlap (so overlapping boxes lie in the same or neighbouring cells), at
 * most max_cells. Returns its cost: n disks binned, n_box of them with boxes. */
static double grid_plan(const Work *w, double v, double grow, int64_t n_box, int nt, Plan *pl)
{
    const Params *p = w->p;
    double scale = p->L + 2 * v;
    pl->grow = grow;
    double extent = (p->hi - p->lo) + 2 * v + 2 * grow;
    pl->x0 = p->lo - v - grow;
    pl->y0 = pl->x0;
    int64_t gcap = (int64_t)sqrt((double)w->max_cells);
    while (gcap > 1 && gcap * gcap > w->max_cells) gcap--;
    while ((gcap + 1) * (gcap + 1) <= w->max_cells) gcap++;
    /* centres of two overlapping boxes are at most 2 * grow + (displacement in a step) apart */
    double h = (2 * grow + v) * (1 + SIM_REL_MARGIN) + SIM_REL_MARGIN * scale;
    double gd = extent / h;
    pl->g = gd < (double)gcap ? (int64_t)gd : gcap;
    if (pl->g < 1) pl->g = 1;
    pl->inv_h = (double)pl->g / extent;
    double cells = (double)pl->g * (double)pl->g, nb = (double)n_box;
    return (double)p->n * COST_BIN + cells * nt * COST_CELL + COST_BOX * 4.5 * nb * nb / cells;
}

/* The grid's margin for disks moving at most v along an axis: it covers, with a wide factor to
 * spare, the rounding of positions (about eps * scale) and that of pair_time near a graze. A pair
 * with an event has dd <= (|dv| + |dv| + 2r)^2 (t <= 1 needs c <= -2b <= 2 |dx| |dv|), and
 * |dv| <= 2 sqrt(2) v. */
static double grid_grow(const Params *p, double v)
{
    return p->r + broad_margin(p->r, p->L + 2 * v, 6 * v + 2 * p->r, SIM_REL_MARGIN);
}

/* Chooses this step's broad phase, whichever the cost model expects to be cheapest (or the one
 * --broad names): the grid, for the fastest disk's displacement vm (slow scenes); the paths of every
 * disk (fast scenes); or mixed, slow disks in the grid and the paths of the fast ones across its
 * cells (omp_paths.c), for each cut between slow and fast at a bin of the disks' speeds. */
static Plan plan_step(Work *w, int nt)
{
    const Params *p = w->p;
    double span = (double)p->hi - (double)p->lo, unit = span / 1048576;
    real vm = 0;
    int64_t n_k[SPEED_BINS] = {0}, s1_k[SPEED_BINS] = {0}, s1 = 0;
    for (int t = 0; t < nt; t++) {
        Thread *th = &w->th[t];
        if (th->vmax > vm) vm = th->vmax;
        for (int k = 0; k < SPEED_BINS; k++) {
            w->speed_n[k] += th->speed_n[k];
            w->speed_s1[k] += th->speed_s1[k];
            th->speed_n[k] = th->speed_s1[k] = 0;
        }
    }
    for (int k = 0; k < SPEED_BINS; k++) {
        n_k[k] = w->speed_n[k];
        s1_k[k] = w->speed_s1[k];
        s1 += s1_k[k];
    }
    int broad = w->opt->broad;
    Plan best, pl;
    double cost = grid_plan(w, vm, grid_grow(p, vm), p->n, nt, &best);
    best.mode = MODE_GRID;
    best.v_cut = INFINITY;
    if (broad == SIM_BROAD_GRID) return best;
    if (broad != SIM_BROAD_AUTO) cost = INFINITY; /* the grid only where nothing else can run */
    PathsPlan all;
    double c = paths_plan(p, p->n, vm, (double)s1 * unit, nt, &all);
    if (c < cost && broad != SIM_BROAD_MIXED) {
        cost = c;
        best.mode = MODE_PATHS;
        best.paths = all;
    }
    int64_t n_slow = 0, s1_fast = s1;
    for (int k = 1; k < SPEED_BINS && broad != SIM_BROAD_PATHS; k++) {
        n_slow += n_k[k - 1];
        s1_fast -= s1_k[k - 1];
        if ((n_slow == 0 && broad == SIM_BROAD_AUTO) || n_slow == p->n) continue;
        double v = ldexp(span, k - 48);
        if (v >= vm) break;
        c = grid_plan(w, v, grid_grow(p, v), n_slow, nt, &pl);
        pl.reach = all.grow + (pl.grow + v / 2) * (1 + SIM_REL_MARGIN) + SIM_REL_MARGIN * p->L;
        c += paths_plan_grid(p, p->n - n_slow, n_slow, vm, (double)s1_fast * unit, pl.reach,
                             1 / pl.inv_h, pl.g, nt, &pl.paths);
        if (c < cost) {
            cost = c;
            best = pl;
            best.mode = MODE_MIXED;
            best.v_cut = v;
        }
    }
    return best;
}

static inline void step_span(const Slots *s, int64_t q, real grow, Span *b)
{
    real xa = s->x[q], xb = s->x[q] + s->vx[q];
    real ya = s->y[q], yb = s->y[q] + s->vy[q];
    b->xlo = (xa < xb ? xa : xb) - grow;
    b->xhi = (xa < xb ? xb : xa) + grow;
    b->ylo = (ya < yb ? ya : yb) - grow;
    b->yhi = (ya < yb ? yb : ya) + grow;
}

static inline void span_box(const Span *a, const Plan *pl, Box *b)
{
    b->xlo = (float)(((double)a->xlo - pl->x0) * pl->inv_h);
    b->xhi = (float)(((double)a->xhi - pl->x0) * pl->inv_h);
    b->ylo = (float)(((double)a->ylo - pl->y0) * pl->inv_h);
    b->yhi = (float)(((double)a->yhi - pl->y0) * pl->inv_h);
}


static inline int64_t cell_coord(double lo, double hi, double origin, double inv_h, int64_t g)
{
    double c = ((lo + hi) * 0.5 - origin) * inv_h;
    if (!(c > 0)) return 0;
    if (c > (double)(g - 1)) return g - 1;
    return (int64_t)c;
}

/* What a binning writes in cell order besides the boxes. */
enum { BIN_SLOTS, BIN_REORDER };

/* A fast disk's slot (as it will be) goes to this thread's list. */
static void note_fast(Thread *th, int32_t slot)
{
    th->fast = omp_grow(th->fast, &th->fast_cap, th->fast_len + 1, sizeof *th->fast);
    th->fast[th->fast_len++] = slot;
}

/* Whether the disk in slot q is fast in a mixed step: its box is empty then (it meets the others
 * along its path, omp_paths.c). */
static inline int is_fast(const Work *w, int64_t q)
{
    real cut = (real)w->plan.v_cut;
    return SIM_FABS(w->s.vx[q]) >= cut || SIM_FABS(w->s.vy[q]) >= cut;
}

static const Box empty_box = {INFINITY, -INFINITY, INFINITY, -INFINITY};

/* Counting sort of the slots into the cells of their boxes: per-thread histograms, a prefix sum over
 * cells and threads, a scatter (inside a cell the slots keep their order). The boxes go in cell order
 * with their slots (BIN_SLOTS); BIN_REORDER moves the disks themselves to the new order (into spare).
 * The wall events (3.1) are found on the way. */
static void bin_grid(Work *w, int tid, int mode)
{
    const Plan *pl = &w->plan;
    const Slots *s = &w->s;
    int nt = w->nt;
    int64_t cells = pl->g * pl->g, from, to;
    int32_t *h = w->hist + (size_t)tid * (size_t)cells;
    Thread *th = &w->th[tid];
    int mixed = pl->mode == MODE_MIXED;
    th->fast_len = 0;
    memset(h, 0, (size_t)cells * sizeof *h);
    range_of(w->p->n, tid, nt, &from, &to);
    for (int64_t q = from; q < to; q++) {
        Span b;
        step_span(s, q, pl->grow, &b);
        int64_t c = cell_coord(b.ylo, b.yhi, pl->y0, pl->inv_h, pl->g) * pl->g +
                    cell_coord(b.xlo, b.xhi, pl->x0, pl->inv_h, pl->g);
        w->cell_of[q] = (int32_t)c;
        h[c]++;
        if (mode == BIN_SLOTS) w->wall_t[q] = slot_wall_time(s, w->p, q);
    }
#pragma omp barrier
    int64_t c0, c1, sum = 0;
    range_of(cells, tid, nt, &c0, &c1);
    for (int64_t c = c0; c < c1; c++) {
        int32_t tot = 0;
        for (int t = 0; t < nt; t++) {
            int32_t v = w->hist[(size_t)t * (size_t)cells + (size_t)c];
            w->hist[(size_t)t * (size_t)cells + (size_t)c] = tot;
            tot += v;
        }
        w->cell_start[c] = tot;
        sum += tot;
    }
    w->th[tid].partial = sum;
#pragma omp barrier
#pragma omp single
    w->cell_start[cells] = (int32_t)scan_partials(w, nt);
    int64_t base = w->th[tid].partial;
    for (int64_t c = c0; c < c1; c++) {
        int32_t v = w->cell_start[c];
        w->cell_start[c] = (int32_t)base;
        base += v;
    }
#pragma omp barrier
    if (mode == BIN_REORDER) {
        const Slots *d = &w->spare;
        for (int64_t q = from; q < to; q++) {
            int32_t c = w->cell_of[q];
            int32_t pos = w->cell_start[c] + h[c]++;
            if (mixed && is_fast(w, q)) {
                w->boxes[pos] = empty_box;
                note_fast(th, pos);
            } else {
                Span b;
                step_span(s, q, pl->grow, &b);
                span_box(&b, pl, &w->boxes[pos]);
            }
            w->box_slot[pos] = pos;
            w->wall_t[pos] = slot_wall_time(s, w->p, q);
            d->x[pos] = s->x[q];
            d->y[pos] = s->y[q];
            d->vx[pos] = s->vx[q];
            d->vy[pos] = s->vy[q];
            d->id[pos] = s->id[q];
            d->pc[pos] = s->pc[q];
            d->wc[pos] = s->wc[q];
            if (s->wi) d->wi[pos] = s->wi[q];
        }
    } else {
        for (int64_t q = from; q < to; q++) {
            int32_t c = w->cell_of[q];
            int32_t pos = w->cell_start[c] + h[c]++;
            if (mixed && is_fast(w, q)) {
                w->boxes[pos] = empty_box;
                note_fast(th, (int32_t)q);
            } else {
                Span b;
                step_span(s, q, pl->grow, &b);
                span_box(&b, pl, &w->boxes[pos]);
            }
            w->box_slot[pos] = (int32_t)q;
        }
    }
#pragma omp barrier
    if (mode == BIN_REORDER) {
#pragma omp single
        {
            Slots t = w->s;
            w->s = w->spare;
            w->spare = t;
        }
    }
}

/* Narrow phase for two disks whose boxes overlap: the disk with the lower original index is always
 * pair_time's first. Only pairs that approach (b < 0, as in pair_time) count as tested. */
static inline void try_pair(const Work *w, Thread *th, int32_t a, int32_t b)
{
    const Slots *s = &w->s;
    real dx = s->x[b] - s->x[a], dy = s->y[b] - s->y[a];
    real dvx = s->vx[b] - s->vx[a], dvy = s->vy[b] - s->vy[a];
    if (!(dx * dvx + dy * dvy < 0)) return;
    if (s->id[b] < s->id[a]) {
        int32_t t = a;
        a = b;
        b = t;
    }
    th->found.tests++;
    real t = pair_time(s->x[a], s->y[a], s->vx[a], s->vy[a], s->x[b], s->y[b], s->vx[b], s->vy[b],
                       w->p->sigma2);
    if (t >= 0 && before_walls(t, w->wall_t[a], w->wall_t[b]))
        found_push(&th->found, t, s->id[a], s->id[b], a, b);
}

/* The pairs of box a with the boxes b + u whose bit u is set in the mask m. */
static void scan_hits(const Work *w, Thread *th, int32_t a, int32_t b, unsigned m)
{
    for (int u = 0; u < SCAN_WIDTH; u++)
        if (m >> u & 1) try_pair(w, th, w->box_slot[a], w->box_slot[b + u]);
}

/* Tests box a against the boxes [b0, b1) in groups of SCAN_WIDTH, each group's overlaps a mask without
 * a branch per box: ranges hold a few boxes each, and a branch per box and per range end would be
 * mispredicted about once per box. The last group reads boxes past b1 (boxes has SCAN_WIDTH spare
 * entries) and masks them off. */
static inline void scan_range(const Work *w, Thread *th, int32_t a, int32_t b0, int32_t b1)
{
    const Box *bx = w->boxes, *ba = &w->boxes[a];
    for (int32_t b = b0; b < b1; b += SCAN_WIDTH) {
        unsigned m = (unsigned)boxes_overlap(ba, &bx[b]) |
                     (unsigned)boxes_overlap(ba, &bx[b + 1]) << 1 |
                     (unsigned)boxes_overlap(ba, &bx[b + 2]) << 2 |
                     (unsigned)boxes_overlap(ba, &bx[b + 3]) << 3;
        int32_t rest = b1 - b;
        m &= rest < SCAN_WIDTH ? (1u << rest) - 1 : (1u << SCAN_WIDTH) - 1;
        if (m) scan_hits(w, th, a, b, m);
    }
}

/* Tests every box against the later boxes of its own cell and those of the cells east, north-west,
 * north and north-east: each pair of neighbouring cells once. The east cell follows the own cell in
 * memory and the three northern cells are contiguous, so two ranges cover them. */
static void scan_grid(Work *w, int tid)
{
    const Plan *pl = &w->plan;
    Thread *th = &w->th[tid];
    const int32_t *cs = w->cell_start;
    int64_t g = pl->g;
    int64_t chunk = g / (8 * w->nt) + 1;
#pragma omp for schedule(dynamic, chunk)
    for (int64_t cy = 0; cy < g; cy++) {
        for (int64_t cx = 0; cx < g; cx++) {
            int64_t c = cy * g + cx;
            int32_t end1 = cs[cx + 1 < g ? c + 2 : c + 1];
            int32_t lo2 = 0, end2 = 0;
            if (cy + 1 < g) {
                int64_t first = (cy + 1) * g + (cx > 0 ? cx - 1 : 0);
                int64_t last = (cy + 1) * g + (cx + 1 < g ? cx + 1 : cx);
                lo2 = cs[first];
                end2 = cs[last + 1];
            }
            for (int32_t a = cs[c]; a < cs[c + 1]; a++) {
                scan_range(w, th, a, a + 1, end1);
                scan_range(w, th, a, lo2, end2);
            }
        }
    }
}

/* ==== --check: the broad phase against all pairs ================================================ */

static int pair_cmp(const void *pa, const void *pb)
{
    const PairEvent *a = pa, *b = pb;
    if (a->i != b->i) return a->i < b->i ? -1 : 1;
    if (a->j != b->j) return a->j < b->j ? -1 : 1;
    return 0;
}

/* The wall event time of the disk in slot q straight from 3.1 (-1: none), for --check. */
static real check_wall_time(const Slots *s, const Params *p, int64_t q)
{
    real tw = min_time(wall_time(s->x[q], s->vx[q], p->lo, p->hi),
                       wall_time(s->y[q], s->vy[q], p->lo, p->hi));
    return tw <= 1 ? tw : -1;
}

/* Every pair event that the choice can accept (before_walls), found by testing all pairs, must be
 * among the broad phase's events, and nothing else. */
static void check_broad_phase(Work *w, int64_t step)
{
    const Slots *s = &w->s;
    int64_t n = w->p->n;
    for (int64_t q = 0; q < n; q++)
        if (w->wall_t[q] != check_wall_time(s, w->p, q))
            sim_fail("--check: step %lld: disk %d has the wall event time %.17g, not %.17g",
                    (long long)step, s->id[q], (double)w->wall_t[q],
                    (double)check_wall_time(s, w->p, q));
    size_t n_ev = 0;
    for (int t = 0; t < w->nt; t++) n_ev += w->th[t].found.len;
    PairEvent *mine = sim_calloc(n_ev, sizeof *mine);
    n_ev = 0;
    for (int t = 0; t < w->nt; t++) {
        const Found *f = &w->th[t].found;
        if (f->len) memcpy(mine + n_ev, f->ev, f->len * sizeof *mine);
        n_ev += f->len;
    }
    if (n_ev) qsort(mine, n_ev, sizeof *mine, pair_cmp);
    size_t uniq = 0;
    for (size_t e = 0; e < n_ev; e++)
        if (uniq == 0 || pair_cmp(&mine[uniq - 1], &mine[e]) != 0) mine[uniq++] = mine[e];
    if (uniq != n_ev)
        sim_fail("--check: step %lld: the broad phase found %zu events more than once",
                (long long)step, n_ev - uniq);
    size_t found = 0;
    for (int64_t qa = 0; qa < n; qa++)
        for (int64_t qb = qa + 1; qb < n; qb++) {
            int64_t a = s->id[qa] < s->id[qb] ? qa : qb, b = a == qa ? qb : qa;
            real t = pair_time(s->x[a], s->y[a], s->vx[a], s->vy[a], s->x[b], s->y[b], s->vx[b],
                                 s->vy[b], w->p->sigma2);
            if (t < 0 || !before_walls(t, w->wall_t[a], w->wall_t[b])) continue;
            PairEvent key = {t, s->id[a], s->id[b], 0, 0};
            PairEvent *hit = bsearch(&key, mine, uniq, sizeof *mine, pair_cmp);
            if (!hit || hit->t != t)
                sim_fail("--check: step %lld: the broad phase missed the event of disks %d and %d "
                        "at t = %.17g",
                        (long long)step, key.i, key.j, t);
            found++;
        }
    if (found != uniq)
        sim_fail("--check: step %lld: the broad phase found %zu events, all pairs %zu",
                (long long)step, uniq, found);
    free(mine);
}

/* ==== choosing the events (SPEC.md 3.3) ========================================================== */

/* Gathers the threads' pair events, builds each slot's list of them (CSR: count, prefix, fill; the
 * order inside a list does not matter, only its smallest event is ever used) and starts the choice. */
static void build_lists(Work *w, int tid)
{
    int nt = w->nt;
    int64_t n = w->p->n, from, to;
#pragma omp single
    {
        size_t total = 0;
        for (int t = 0; t < nt; t++) {
            w->th[t].ev_off = total;
            total += w->th[t].found.len;
        }
        w->n_ev = total;
        w->ev = omp_grow(w->ev, &w->ev_cap, total, sizeof *w->ev);
        w->adj = omp_grow(w->adj, &w->adj_cap, 2 * total, sizeof *w->adj);
        w->off[n] = (int64_t)(2 * total);
    }
    Thread *th = &w->th[tid];
    if (th->found.len) memcpy(w->ev + th->ev_off, th->found.ev, th->found.len * sizeof *w->ev);
    range_of(n, tid, nt, &from, &to);
    for (int64_t q = from; q < to; q++) {
        w->off[q] = 0;
        w->taken[q] = 0;
        w->acc_p[q] = -1;
    }
#pragma omp barrier
    for (size_t e = th->ev_off; e < th->ev_off + th->found.len; e++) {
#pragma omp atomic
        w->off[w->ev[e].a]++;
#pragma omp atomic
        w->off[w->ev[e].b]++;
    }
#pragma omp barrier
    /* a disk with a wall event and no pair event keeps its wall event; a disk with pair events
     * goes to the rounds of choose_events */
    int32_t *act = w->active + from;
    int64_t sum = 0, na = 0;
    for (int64_t q = from; q < to; q++) {
        int64_t c = w->off[q];
        sum += c;
        if (c > 0) {
            act[na++] = (int32_t)q;
        } else if (w->wall_t[q] >= 0) {
            w->taken[q] = 1;
            w->acc_p[q] = (int32_t)q;
            w->acc_t[q] = w->wall_t[q];
        }
    }
    th->n_active = na;
    th->partial = sum;
#pragma omp barrier
#pragma omp single
    scan_partials(w, nt);
    sum = th->partial; /* inclusive prefix: off[q] = end of slot q's list */
    for (int64_t q = from; q < to; q++) {
        sum += w->off[q];
        w->off[q] = sum;
    }
#pragma omp barrier
    for (size_t e = th->ev_off; e < th->ev_off + th->found.len; e++) {
        int64_t pos;
#pragma omp atomic capture
        pos = --w->off[w->ev[e].a];
        w->adj[pos] = e;
#pragma omp atomic capture
        pos = --w->off[w->ev[e].b];
        w->adj[pos] = e;
    }
#pragma omp barrier
}

static inline int seq_before(const SeqEvent *a, const SeqEvent *b)
{
    return event_before(a->t, a->kind, a->i, a->j, b->t, b->kind, b->i, b->j);
}

/* Sorts the events by key: runs of 16 by insertion, then merged in rounds through tmp (no function
 * pointer per comparison, as qsort would take: a step's choice sorts a few hundred events). */
static void sort_events(SeqEvent *a, size_t n, SeqEvent *tmp)
{
    for (size_t r = 0; r < n; r += 16) {
        size_t end = r + 16 < n ? r + 16 : n;
        for (size_t k = r + 1; k < end; k++) {
            SeqEvent x = a[k];
            size_t u = k;
            while (u > r && seq_before(&x, &a[u - 1])) {
                a[u] = a[u - 1];
                u--;
            }
            a[u] = x;
        }
    }
    SeqEvent *src = a, *dst = tmp;
    for (size_t width = 16; width < n; width *= 2) {
        for (size_t lo = 0; lo < n; lo += 2 * width) {
            size_t mid = lo + width < n ? lo + width : n, hi = lo + 2 * width < n ? lo + 2 * width : n;
            size_t i = lo, j = mid, k = lo;
            while (i < mid && j < hi) dst[k++] = seq_before(&src[j], &src[i]) ? src[j++] : src[i++];
            while (i < mid) dst[k++] = src[i++];
            while (j < hi) dst[k++] = src[j++];
        }
        SeqEvent *t = src;
        src = dst;
        dst = t;
    }
    if (src != a) memcpy(a, src, n * sizeof *a);
}

/* The greedy walk of SPEC.md 3.3 over the len events of w->fin, as seq.c does: sorted by key, each
 * accepted when its disks are still free. */
static void walk_events(Work *w, size_t len)
{
    w->fin_tmp = omp_grow(w->fin_tmp, &w->fin_tmp_cap, len, sizeof *w->fin_tmp);
    sort_events(w->fin, len, w->fin_tmp);
    for (size_t u = 0; u < len; u++) {
        const SeqEvent *e = &w->fin[u];
        if (w->taken[e->a] || w->taken[e->b]) continue;
        w->taken[e->a] = w->taken[e->b] = 1;
        w->acc_p[e->a] = e->b;
        w->acc_p[e->b] = e->a;
        w->acc_t[e->a] = w->acc_t[e->b] = e->t;
    }
}

/* The whole choice on one thread, for steps with few pair events (the barriers and passes over all
 * disks of the parallel rounds would cost more). Every disk starts with its wall event accepted, if
 * it has one (choice_defaults); only disks with pair events can end otherwise, so the walk takes
 * their pair events and their wall events. */
static void choose_small(Work *w)
{
    size_t len = 0;
    for (int t = 0; t < w->nt; t++) {
        const Found *f = &w->th[t].found;
        w->fin = omp_grow(w->fin, &w->fin_cap, len + 3 * f->len, sizeof *w->fin);
        for (size_t k = 0; k < f->len; k++) {
            const PairEvent *pe = &f->ev[k];
            SeqEvent e = {pe->t, 1, pe->i, pe->j, pe->a, pe->b};
            w->fin[len++] = e;
            int32_t ends[2] = {pe->a, pe->b};
            for (int u = 0; u < 2; u++) {
                int32_t q = ends[u];
                if (w->taken[q] || w->wall_t[q] < 0) continue;
                w->taken[q] = 1; /* marks the wall event as listed; cleared before the walk */
                SeqEvent x = {w->wall_t[q], 0, w->s.id[q], w->s.id[q], q, q};
                w->fin[len++] = x;
            }
        }
    }
    for (size_t u = 0; u < len; u++) w->taken[w->fin[u].a] = w->taken[w->fin[u].b] = 0;
    walk_events(w, len);
}

/* The last undecided disks: their remaining events sorted and walked, as seq.c does. */
static void finish_sequential(Work *w)
{
    const Slots *s = &w->s;
    size_t len = 0;
    for (int t = 0; t < w->nt; t++) {
        int64_t from, to;
        range_of(w->p->n, t, w->nt, &from, &to);
        for (int64_t k = 0; k < w->th[t].n_active; k++) {
            int32_t q = w->active[from + k];
            w->fin = omp_grow(w->fin, &w->fin_cap, len + 1, sizeof *w->fin);
            if (w->wall_t[q] >= 0) {
                SeqEvent e = {w->wall_t[q], 0, s->id[q], s->id[q], q, q};
                w->fin[len++] = e;
            }
            for (int64_t u = w->off[q]; u < w->off[q + 1]; u++) {
                const PairEvent *pe = &w->ev[w->adj[u]];
                if (pe->a != q || w->taken[pe->b]) continue;
                w->fin = omp_grow(w->fin, &w->fin_cap, len + 1, sizeof *w->fin);
                SeqEvent e = {pe->t, 1, pe->i, pe->j, pe->a, pe->b};
                w->fin[len++] = e;
            }
        }
    }
    walk_events(w, len);
}

/* Rounds: every undecided disk finds its smallest event among those whose disks are all free; an
 * event that is the smallest of each of its disks is accepted. The global smallest always is, so
 * every round makes progress; once few disks remain the sequential walk ends the step. */
static void choose_events(Work *w, int tid)
{
    const int32_t *id = w->s.id;
    Thread *th = &w->th[tid];
    int64_t from, to;
    range_of(w->p->n, tid, w->nt, &from, &to);
    int32_t *act = w->active + from;
    int64_t na = th->n_active;
    for (;;) {
        for (int64_t k = 0; k < na; k++) {
            int32_t q = act[k], bp = -1, bi = 0, bj = 0, bk = 0;
            real bt = 0;
            if (w->wall_t[q] >= 0) {
                bp = q;
                bi = bj = id[q];
                bt = w->wall_t[q];
            }
            for (int64_t u = w->off[q]; u < w->off[q + 1]; u++) {
                const PairEvent *e = &w->ev[w->adj[u]];
                int32_t other = e->a == q ? e->b : e->a;
                if (w->taken[other]) continue;
                if (bp < 0 || event_before(e->t, 1, e->i, e->j, bt, bk, bi, bj)) {
                    bp = other;
                    bt = e->t;
                    bk = 1;
                    bi = e->i;
                    bj = e->j;
                }
            }
            w->best_p[q] = bp;
            w->best_t[q] = bt;
        }
#pragma omp barrier
        int64_t kept = 0;
        for (int64_t k = 0; k < na; k++) {
            int32_t q = act[k], bp = w->best_p[q];
            if (bp < 0) continue;
            if (bp == q) {
                w->taken[q] = 1;
                w->acc_p[q] = q;
                w->acc_t[q] = w->best_t[q];
            } else if (w->best_p[bp] == q) {
                if (q < bp) {
                    w->taken[q] = w->taken[bp] = 1;
                    w->acc_p[q] = bp;
                    w->acc_p[bp] = q;
                    w->acc_t[q] = w->acc_t[bp] = w->best_t[q];
                }
            } else {
                act[kept++] = q;
            }
        }
        na = kept;
        th->n_active = na;
#pragma omp barrier
#pragma omp single
        {
            int64_t left = 0;
            for (int t = 0; t < w->nt; t++) left += w->th[t].n_active;
            w->undecided = left;
            if (left > 0 && left <= SEQ_FINISH) finish_sequential(w);
        }
        if (w->undecided <= SEQ_FINISH) break;
    }
}

/* Every disk of this thread's range starts the choice free, its wall event accepted if it has one. */
static void choice_defaults(Work *w, int tid)
{
    int64_t from, to;
    range_of(w->p->n, tid, w->nt, &from, &to);
    for (int64_t q = from; q < to; q++) {
        w->taken[q] = 0;
        w->acc_p[q] = w->wall_t[q] >= 0 ? (int32_t)q : -1;
        w->acc_t[q] = w->wall_t[q];
    }
}

/* ==== moving (SPEC.md 3.4, 3.5) ======================================================================= */

static inline real fastest(real vm, real vx, real vy)
{
    real ax = SIM_FABS(vx), ay = SIM_FABS(vy);
    if (ax > vm) vm = ax;
    return ay > vm ? ay : vm;
}

/* Adds a disk of velocity (vx, vy) to a histogram of speeds (sign -1: removes it): its speed_bin and
 * its axis speeds, each at most the box, in units of the box / 2^20. */
static inline void note_speed(int64_t *n, int64_t *s1, real vx, real vy, double inv_span, int sign)
{
    double ax = SIM_FABS(vx) * inv_span, ay = SIM_FABS(vy) * inv_span;
    int k = speed_bin((double)fastest(0, vx, vy), inv_span);
    n[k] += sign;
    s1[k] += sign * ((int64_t)((ax < 1 ? ax : 1) * 1048576) + (int64_t)((ay < 1 ? ay : 1) * 1048576));
}

/* Moves the disks of this thread's range (a pair from its lower original index, both disks) and
 * notes the largest velocity component it leaves and the disks' next steps, for the next step's
 * plan. */
static void move_range(Work *w, int tid)
{
    Slots *s = &w->s;
    real lo = w->p->lo, hi = w->p->hi, vm = 0;
    double inv_span = 1 / ((double)hi - (double)lo);
    Thread *th = &w->th[tid];
    uint64_t events = 0;
    int64_t from, to;
    range_of(w->p->n, tid, w->nt, &from, &to);
    for (int64_t i = from; i < to; i++) {
        int64_t j = w->acc_p[i];
        real t = w->acc_t[i];
        if (j < 0) {
            s->x[i] = s->x[i] + s->vx[i];
            s->y[i] = s->y[i] + s->vy[i];
        } else if (j == i) {
            real vx0 = s->vx[i], vy0 = s->vy[i];
            wall_bounce(&s->x[i], &s->y[i], &s->vx[i], &s->vy[i], t, lo, hi);
            if (s->wi) s->wi[i] += wall_impulse(vx0, vy0, s->vx[i], s->vy[i]);
            finish_step(&s->x[i], &s->y[i], s->vx[i], s->vy[i], t, lo, hi);
            s->wc[i]++;
            events++;
        } else if (s->id[i] < s->id[j]) {
            note_speed(th->speed_n, th->speed_s1, s->vx[i], s->vy[i], inv_span, -1);
            note_speed(th->speed_n, th->speed_s1, s->vx[j], s->vy[j], inv_span, -1);
            pair_collide(&s->x[i], &s->y[i], &s->vx[i], &s->vy[i], &s->x[j], &s->y[j], &s->vx[j],
                         &s->vy[j], t, lo, hi);
            s->pc[i]++;
            s->pc[j]++;
            events++;
            s->x[j] = clamp_coord(s->x[j], lo, hi);
            s->y[j] = clamp_coord(s->y[j], lo, hi);
            vm = fastest(vm, s->vx[j], s->vy[j]);
            note_speed(th->speed_n, th->speed_s1, s->vx[i], s->vy[i], inv_span, 1);
            note_speed(th->speed_n, th->speed_s1, s->vx[j], s->vy[j], inv_span, 1);
        } else {
            continue;
        }
        s->x[i] = clamp_coord(s->x[i], lo, hi);
        s->y[i] = clamp_coord(s->y[i], lo, hi);
        vm = fastest(vm, s->vx[i], s->vy[i]);
    }
    th->vmax = vm;
    th->events += events;
}

/* ==== print mode: each thread formats its block of lines, the blocks are written in order ======== */

static void print_state(Work *w, int tid, int64_t step)
{
    slots_unpermute(w, tid);
#pragma omp barrier
#pragma omp single
    io_text_begin(&w->text, w->out, step, w->sim, w->p->n, 0);
    for (int64_t r = 0; r <= w->text.rounds; r++) {
#pragma omp for schedule(dynamic, 1)
        for (int64_t k = 0; k < io_text_tasks(&w->text, r); k++) io_text_task(&w->text, r, k);
    }
#pragma omp single
    io_text_end(&w->text);
}

static void step_run(Work *w, int tid, int64_t step)
{
    const Params *p = w->p;
    Thread *th = &w->th[tid];

    /* the fastest disk and the lengths of all steps (found by the last move) plan the broad phase */
    th->found.len = 0;
#pragma omp single
    {
        w->plan = plan_step(w, w->nt);
        if (w->plan.mode != MODE_GRID) paths_ready(w->paths, &w->plan.paths, p->n, w->nt);
        w->path_steps += w->plan.mode == MODE_PATHS;
        w->mixed_steps += w->plan.mode == MODE_MIXED;
    }

    /* wall events (3.1) and pair events (3.2): a broad phase, its surviving pairs through the
     * narrow phase */
    if (w->plan.mode == MODE_PATHS) {
        paths_find(w->paths, &w->s, p, w->wall_t, NULL, NULL, 0, &th->found, tid, w->nt);
    } else {
        /* reordered on a run's first step too: a resumed run starts from the original order */
        int first = step == p->first_step * p->substeps + 1;
        bin_grid(w, tid, step % REORDER_EVERY == 1 || first ? BIN_REORDER : BIN_SLOTS);
        scan_grid(w, tid);
        if (w->plan.mode == MODE_MIXED) {
            const Plan *pl = &w->plan;
            SlowGrid slow = {w->boxes, w->cell_start, w->box_slot, pl->g, pl->x0, pl->inv_h,
                             pl->reach};
            paths_find(w->paths, &w->s, p, w->wall_t, &slow, th->fast, (int64_t)th->fast_len,
                       &th->found, tid, w->nt);
        }
    }
    if (w->opt->check) {
#pragma omp single
        check_broad_phase(w, step);
    }

    /* the greedy choice (3.3): on one thread when there are few pair events, else in rounds (every
     * thread counts the events itself, so all take the same branch) */
    size_t total = 0;
    for (int t = 0; t < w->nt; t++) total += w->th[t].found.len;
    if (total <= SMALL_CHOICE) {
        choice_defaults(w, tid);
#pragma omp barrier
#pragma omp single
        choose_small(w);
    } else {
        build_lists(w, tid);
        choose_events(w, tid);
#pragma omp barrier
    }

    /* the moves (3.4, 3.5) */
    move_range(w, tid);
#pragma omp barrier
    int64_t k = p->substeps;
    if (step % k) return;
    if (p->print && step < p->steps * k) print_state(w, tid, step / k);
    if (io_checkpoint_due(w->out, step / k)) {
        if (!p->print) slots_unpermute(w, tid); /* print_state has done it */
#pragma omp barrier
#pragma omp single
        io_checkpoint(w->out, w->sim, step / k);
    }
#pragma omp single
    io_progress(w->out, step / k);
}

/* The caller's state into this thread's range of slots, in original order (the first step sorts them),
 * the speeds into this thread's histogram and fastest component: each thread first touches the memory
 * it works on. */
static void slots_fill(Work *w, int tid)
{
    const Sim *sim = w->sim;
    Slots *s = &w->s;
    Thread *th = &w->th[tid];
    double inv_span = 1 / ((double)w->p->hi - (double)w->p->lo);
    int64_t from, to;
    range_of(w->p->n, tid, w->nt, &from, &to);
    for (int64_t i = from; i < to; i++) {
        s->x[i] = sim->x[i];
        s->y[i] = sim->y[i];
        s->vx[i] = sim->vx[i];
        s->vy[i] = sim->vy[i];
        s->id[i] = (int32_t)i;
        s->pc[i] = sim->pc[i];
        s->wc[i] = sim->wc[i];
        if (sim->wi) s->wi[i] = sim->wi[i];
        th->vmax = fastest(th->vmax, sim->vx[i], sim->vy[i]);
        note_speed(th->speed_n, th->speed_s1, sim->vx[i], sim->vy[i], inv_span, 1);
    }
#pragma omp barrier
}

void backend_prepare(const Params *par)
{
    (void)par;
}

void backend_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    int nt = threads > 0 ? threads : omp_get_max_threads();
#pragma omp parallel for schedule(dynamic, 1) num_threads(nt)
    for (int64_t k = 0; k < tasks; k++) task(ctx, k);
}

int backend_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *st)
{
    if (opt->threads > 0) omp_set_num_threads(opt->threads);
    omp_set_dynamic(0);
    if (opt->exact) return omp_exact_run(sim, par, opt, out, st);
    if (par->steps == 0) return 0; /* the state is the final state: nothing to set up */
    int nt_max = omp_get_max_threads();
    int64_t n = par->n;
    Work w;
    memset(&w, 0, sizeof w);
    w.sim = sim;
    w.p = par;
    w.opt = opt;
    w.out = out;
    /* at most n cells, and per-thread histograms of at most 8n counts in all */
    w.max_cells = nt_max <= 8 ? n : 8 * n / nt_max;
    if (w.max_cells < 1) w.max_cells = 1;
    slots_alloc(&w.s, n, sim->wi != NULL);
    slots_alloc(&w.spare, n, sim->wi != NULL);
    w.th = sim_calloc((size_t)nt_max, sizeof *w.th);
    w.cell_of = sim_calloc((size_t)n, sizeof *w.cell_of);
    w.hist = sim_calloc((size_t)nt_max * (size_t)w.max_cells, sizeof *w.hist);
    w.cell_start = sim_calloc((size_t)w.max_cells + 1, sizeof *w.cell_start);
    w.boxes = sim_calloc((size_t)n + SCAN_WIDTH, sizeof *w.boxes);
    w.wall_t = sim_calloc((size_t)n, sizeof *w.wall_t);
    w.off = sim_calloc((size_t)n + 1, sizeof *w.off);
    w.active = sim_calloc((size_t)n, sizeof *w.active);
    w.best_p = sim_calloc((size_t)n, sizeof *w.best_p);
    w.best_t = sim_calloc((size_t)n, sizeof *w.best_t);
    w.acc_p = sim_calloc((size_t)n, sizeof *w.acc_p);
    w.acc_t = sim_calloc((size_t)n, sizeof *w.acc_t);
    w.taken = sim_calloc((size_t)n, sizeof *w.taken);
    w.box_slot = sim_calloc((size_t)n, sizeof *w.box_slot);
    w.paths = paths_new(nt_max);

    double t0 = 0;
#pragma omp parallel
    {
#pragma omp single
        w.nt = omp_get_num_threads();
        int tid = omp_get_thread_num();
        slots_fill(&w, tid);
#pragma omp single
        t0 = sim_clock(); /* the step loop from here */
        for (int64_t step = par->first_step * par->substeps + 1; step <= par->steps * par->substeps; step++)
            step_run(&w, tid, step);
        slots_unpermute(&w, tid);
    }
    st->seconds = sim_clock() - t0;

    uint64_t visits = 0, overlaps = 0;
    for (int t = 0; t < nt_max; t++) {
        visits += w.th[t].found.visits;
        overlaps += w.th[t].found.overlaps;
        st->pair_tests += w.th[t].found.tests;
        st->events += w.th[t].events;
        free(w.th[t].found.ev);
        free(w.th[t].fast);
    }
    int64_t steps = par->steps * par->substeps;
    if (opt->stats) {
        double ps = (double)(w.path_steps + w.mixed_steps) * (double)n;
        fprintf(stderr,
                "%s: broad phase: grid in %lld, paths in %lld, mixed in %lld of %lld steps; paths: "
                "%.4g cells visited and %.4g pairs of visits overlapping in time per particle-step\n",
                backend_name, (long long)(steps - w.path_steps - w.mixed_steps),
                (long long)w.path_steps, (long long)w.mixed_steps, (long long)steps,
                ps > 0 ? visits / ps : 0.0, ps > 0 ? overlaps / ps : 0.0);
    }
    slots_free(&w.s);
    slots_free(&w.spare);
    free(w.th);
    free(w.cell_of);
    free(w.hist);
    free(w.cell_start);
    free(w.boxes);
    paths_free(w.paths);
    free(w.wall_t);
    free(w.ev);
    free(w.off);
    free(w.adj);
    free(w.active);
    free(w.best_p);
    free(w.best_t);
    free(w.acc_p);
    free(w.acc_t);
    free(w.taken);
    free(w.box_slot);
    free(w.fin);
    free(w.fin_tmp);
    return 0;
}

int main(int argc, char **argv)
{
    return io_main(argc, argv);
}
