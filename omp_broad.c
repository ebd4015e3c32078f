/* omp_broad.c: the broad phase of a step over a set of slots, on the threads of an OpenMP team: the
 * wall event of every slot (3.1) and every pair event (3.2) that the choice can accept. omp.c runs it
 * over all disks; mpi.c over each rank's own disks and their halo.
 *
 * grid (slow scenes): every disk's swept box (its path over the step, grown by r and a rounding
 * margin) is binned by its centre into square cells at least as wide as two boxes can be apart and
 * still overlap, so overlapping boxes lie in the same or neighbouring cells; a pair whose boxes
 * overlap goes to the narrow phase (pair_time). The cells cover the region where the centres lie
 * (Broad's rx0..ry1: the box for omp, a strip and its halo for a rank of mpi); a centre outside is
 * counted in the nearest cell, which keeps neighbours neighbours (clamping never separates them).
 * paths (fast scenes) and mixed (a few fast disks among slow ones): omp_paths.c, over the box.
 * The cost model chooses, step by step, whichever it expects to be cheapest (or --broad's).
 */
#include "omp_step.h"

#include <omp.h>
#include <stdlib.h>
#include <string.h>

#define SCAN_WIDTH 4 /* boxes one group of the scan tests at once */

/* Relative costs of the grid's broad phase per step, against those of the paths' (omp_paths.c):
 * binning one disk, clearing and summing one cell of one thread's histogram, testing one pair of
 * boxes. */
#define COST_BIN 1.0
#define COST_CELL 0.3
#define COST_BOX 0.25

static const Box empty_box = {-INFINITY, -INFINITY, -INFINITY, -INFINITY}; /* overlaps nothing */

/* The box swept by one disk over the step, grown by the radius and the rounding margin. */
typedef struct {
    real xlo, xhi, ylo, yhi;
} Span;

static void range_of(int64_t n, int tid, int nt, int64_t *from, int64_t *to)
{
    *from = n * tid / nt;
    *to = n * (tid + 1) / nt;
}

/* ==== buffers ========================================================================================= */

void slots_resize(Slots *s, int64_t n, int with_wi)
{
    s->x = sim_realloc(s->x, (size_t)n, sizeof *s->x);
    s->y = sim_realloc(s->y, (size_t)n, sizeof *s->y);
    s->vx = sim_realloc(s->vx, (size_t)n, sizeof *s->vx);
    s->vy = sim_realloc(s->vy, (size_t)n, sizeof *s->vy);
    s->id = sim_realloc(s->id, (size_t)n, sizeof *s->id);
    s->pc = sim_realloc(s->pc, (size_t)n, sizeof *s->pc);
    s->wc = sim_realloc(s->wc, (size_t)n, sizeof *s->wc);
    if (with_wi) s->wi = sim_realloc(s->wi, (size_t)n, sizeof *s->wi);
}

void slots_free(Slots *s)
{
    free(s->x);
    free(s->y);
    free(s->vx);
    free(s->vy);
    free(s->id);
    free(s->pc);
    free(s->wc);
    free(s->wi);
    memset(s, 0, sizeof *s);
}

void broad_init(Broad *b, const Params *p, const Options *opt, int64_t cap, int nt_max, int with_wi)
{
    memset(b, 0, sizeof *b);
    b->p = p;
    b->opt = opt;
    b->with_wi = with_wi;
    b->rx0 = b->ry0 = p->lo;
    b->rx1 = b->ry1 = p->hi;
    if (p->periodic) { /* the whole torus, wrapping both ways (mpi's strips narrow x) */
        b->rx0 = b->ry0 = 0;
        b->rx1 = b->ry1 = p->L;
        b->wrap_x = b->wrap_y = 1;
    }
    b->th = sim_calloc_lines((size_t)nt_max, sizeof *b->th);
    b->nt_max = nt_max;
    while (1 << b->name_shift < nt_max) b->name_shift++;
    b->paths = paths_new(nt_max, opt->lanes);
    broad_reserve(b, cap);
}

void broad_reserve(Broad *b, int64_t cap)
{
    if (cap < 1) cap = 1;
    if (cap <= b->cap) return;
    slots_resize(&b->s, cap, b->with_wi);
    slots_resize(&b->spare, cap, b->with_wi);
    /* at most cap cells, and per-thread histograms of at most 8 cap counts in all */
    int64_t cells = b->nt_max <= 8 ? cap : 8 * cap / b->nt_max;
    if (cells < 1) cells = 1;
    free(b->hist);
    free(b->cell_start);
    b->hist = sim_calloc((size_t)b->nt_max * (size_t)cells, sizeof *b->hist);
    b->cell_start = sim_calloc((size_t)cells + 1, sizeof *b->cell_start);
    b->max_cells = cells;
    b->cell_of = sim_realloc(b->cell_of, (size_t)cap, sizeof *b->cell_of);
    b->boxes = sim_realloc(b->boxes, (size_t)cap + SCAN_WIDTH, sizeof *b->boxes);
    for (int k = 0; k < SCAN_WIDTH; k++) b->boxes[cap + k] = empty_box; /* read by scan_range, masked off */
    b->box_slot = sim_realloc(b->box_slot, (size_t)cap, sizeof *b->box_slot);
    b->wall_t = sim_realloc(b->wall_t, (size_t)cap, sizeof *b->wall_t);
    b->cap = cap;
}

void broad_free(Broad *b)
{
    slots_free(&b->s);
    slots_free(&b->spare);
    for (int t = 0; t < b->nt_max; t++) {
        free(b->th[t].found.ev);
        free(b->th[t].found.wall);
        free(b->th[t].found.trim);
        free(b->th[t].fast);
    }
    free(b->th);
    paths_free(b->paths);
    free(b->cell_of);
    free(b->hist);
    free(b->cell_start);
    free(b->boxes);
    free(b->box_slot);
    free(b->wall_t);
    memset(b, 0, sizeof *b);
}

/* Turns each thread's partial count into the sum of the counts of the threads before it; returns the
 * total. Called by one thread between barriers. */
static int64_t scan_partials(Broad *b, int nt)
{
    int64_t acc = 0;
    for (int t = 0; t < nt; t++) {
        int64_t v = b->th[t].partial;
        b->th[t].partial = acc;
        acc += v;
    }
    return acc;
}

void broad_count_speeds(Broad *b, int tid)
{
    const Slots *s = &b->s;
    BroadThread *th = &b->th[tid];
    double inv_span = 1 / ((double)b->p->hi - (double)b->p->lo);
    int64_t from, to;
    range_of(b->p->n, tid, b->nt, &from, &to);
    memset(th->speed_n, 0, sizeof th->speed_n);
    memset(th->speed_s1, 0, sizeof th->speed_s1);
    th->vmax = 0;
    for (int64_t q = from; q < to; q++) {
        th->vmax = fastest(th->vmax, s->vx[q], s->vy[q]);
        note_speed(th->speed_n, th->speed_s1, s->vx[q], s->vy[q], inv_span, 1);
    }
#pragma omp single
    {
        memset(b->speed_n, 0, sizeof b->speed_n);
        memset(b->speed_s1, 0, sizeof b->speed_s1);
    }
}

/* ==== the plan ========================================================================================= */

/* The most cells a side of a square grid of at most max_cells. */
static int64_t grid_side_cap(const Broad *b)
{
    int64_t gcap = (int64_t)sqrt((double)b->max_cells);
    while (gcap > 1 && gcap * gcap > b->max_cells) gcap--;
    while ((gcap + 1) * (gcap + 1) <= b->max_cells) gcap++;
    return gcap;
}

/* Cells of side at least h tiling [0, L) along an axis that wraps, at most most: 3 or more, so that a
 * cell's two neighbours along it are other cells and not the same one, else 1. */
static int64_t wrap_cells(double L, double h, int64_t most)
{
    double gd = L / h;
    int64_t g = gd < (double)most ? (int64_t)gd : most;
    return g < 3 ? 1 : g;
}

/* The periodic box's grid (SPEC.md 7) of cells of side at least h: square cells tiling [0, L) along
 * y, and along x too where it wraps (omp; a rank of mpi holding the whole torus); along a strip's x
 * (mpi) as many of the same side as cover its region [rx0, rx1] with its margins. */
static void grid_cells_periodic(const Broad *b, double h, double v, double grow, Plan *pl)
{
    double L = b->p->L;
    pl->y0 = 0;
    if (b->wrap_x) {
        pl->gx = pl->gy = wrap_cells(L, h, grid_side_cap(b));
        pl->x0 = 0;
    } else {
        double ex = (b->rx1 - b->rx0) + 2 * v + 2 * grow;
        pl->x0 = b->rx0 - v - grow;
        for (pl->gy = wrap_cells(L, h, b->max_cells);; pl->gy = pl->gy > 3 ? pl->gy - 1 : 1) {
            pl->gx = (int64_t)ceil(ex * (double)pl->gy / L);
            if (pl->gx < 1) pl->gx = 1;
            if (pl->gx * pl->gy <= b->max_cells || pl->gy == 1) break;
        }
        if (pl->gx > b->max_cells) pl->gx = b->max_cells; /* the last column takes the rest (clamped) */
    }
    pl->inv_h = (double)pl->gy / L;
}

/* The grid for disks moving at most v along an axis, boxes grown by grow: square cells as wide as two
 * boxes can be apart and still overlap (so overlapping boxes lie in the same or neighbouring cells),
 * over the region of the centres, at most max_cells. Returns its cost: n disks binned, n_box of them
 * with boxes. */
static double grid_plan(const Broad *b, double v, double grow, int64_t n_box, int nt, Plan *pl)
{
    const Params *p = b->p;
    double scale = p->L + 2 * v;
    pl->grow = grow;
    double ex = (b->rx1 - b->rx0) + 2 * v + 2 * grow, ey = (b->ry1 - b->ry0) + 2 * v + 2 * grow;
    pl->x0 = b->rx0 - v - grow;
    pl->y0 = b->ry0 - v - grow;
    /* centres of two overlapping boxes are at most 2 * grow + (displacement in a step) apart */
    double h = (2 * grow + v) * (1 + SIM_REL_MARGIN) + SIM_REL_MARGIN * scale;
    if (p->periodic) {
        grid_cells_periodic(b, h, v, grow, pl);
    } else if (ex == ey) { /* the box (omp): g x g cells */
        int64_t gcap = grid_side_cap(b);
        double gd = ex / h;
        pl->gx = gd < (double)gcap ? (int64_t)gd : gcap;
        if (pl->gx < 1) pl->gx = 1;
        pl->gy = pl->gx;
        pl->inv_h = (double)pl->gx / ex;
    } else { /* a strip (mpi): cells of side h or, where they would be too many, wider */
        double side = h;
        if ((ex / side) * (ey / side) > (double)b->max_cells) side = sqrt(ex * ey / (double)b->max_cells);
        pl->gx = (int64_t)(ex / side);
        pl->gy = (int64_t)(ey / side);
        if (pl->gx < 1) pl->gx = 1; /* a strip narrower than a cell: then gy alone is bounded */
        if (pl->gy < 1) pl->gy = 1;
        if (pl->gy > b->max_cells / pl->gx) pl->gy = b->max_cells / pl->gx;
        if (pl->gx > b->max_cells / pl->gy) pl->gx = b->max_cells / pl->gy;
        double wx = ex / (double)pl->gx, wy = ey / (double)pl->gy; /* both >= side */
        pl->inv_h = 1 / (wx > wy ? wx : wy);
    }
    pl->g = pl->gx;
    double cells = (double)pl->gx * (double)pl->gy, nb = (double)n_box;
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
 * cells (omp_paths.c), for each cut between slow and fast at a bin of the disks' speeds. The paths
 * cover the whole box: over a strip (mpi) only the grid runs, and in the periodic box the paths run
 * only where each visits a cell at most once (paths_fit_periodic). */
static Plan plan_step(Broad *b, int nt)
{
    const Params *p = b->p;
    double span = (double)p->hi - (double)p->lo, unit = span / 1048576;
    real vm = 0;
    int64_t n_k[SPEED_BINS] = {0}, s1_k[SPEED_BINS] = {0}, s1 = 0;
    for (int t = 0; t < nt; t++) {
        BroadThread *th = &b->th[t];
        if (th->vmax > vm) vm = th->vmax;
        for (int k = 0; k < SPEED_BINS; k++) {
            b->speed_n[k] += th->speed_n[k];
            b->speed_s1[k] += th->speed_s1[k];
            th->speed_n[k] = th->speed_s1[k] = 0;
        }
    }
    for (int k = 0; k < SPEED_BINS; k++) {
        n_k[k] = b->speed_n[k];
        s1_k[k] = b->speed_s1[k];
        s1 += s1_k[k];
    }
    int broad = b->opt->broad;
    Plan best, pl;
    double cost = grid_plan(b, vm, grid_grow(p, vm), p->n, nt, &best);
    best.mode = MODE_GRID;
    best.v_cut = INFINITY;
    if (broad == SIM_BROAD_GRID || (p->periodic ? !b->wrap_x || b->grid_only : best.gx != best.gy)) return best;
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
        c = grid_plan(b, v, grid_grow(p, v), n_slow, nt, &pl);
        pl.reach = all.grow + (pl.grow + v / 2) * (1 + SIM_REL_MARGIN) + SIM_REL_MARGIN * p->L;
        /* the periodic box: a fast path may visit each slow cell once, in a grid of 3 or more a side */
        if (p->periodic && (pl.g < 3 || !paths_fit_periodic(p, vm, pl.reach, 1 / pl.inv_h))) continue;
        c += paths_plan_grid(p, p->n - n_slow, n_slow, vm, (double)s1_fast * unit, pl.reach,
                             1 / pl.inv_h, pl.g, b->keep, nt, &pl.paths);
        if (c < cost) {
            cost = c;
            best = pl;
            best.mode = MODE_MIXED;
            best.v_cut = v;
        }
    }
    return best;
}

/* ==== the grid ========================================================================================= */

static inline void step_span(const Slots *s, int64_t q, real grow, Span *b)
{
    real xa = s->x[q], xb = s->x[q] + s->vx[q];
    real ya = s->y[q], yb = s->y[q] + s->vy[q];
    /* a minimum and a maximum each (minsd, maxsd) rather than one comparison for both, which the
     * compiler turns into a branch that the signs of the velocities mispredict half the time */
    b->xlo = (xa < xb ? xa : xb) - grow;
    b->xhi = (xa > xb ? xa : xb) + grow;
    b->ylo = (ya < yb ? ya : yb) - grow;
    b->yhi = (ya > yb ? ya : yb) + grow;
}

/* The periodic box: the image of a disk's box that the grid bins: its centre in [0, L) along an axis
 * that wraps, else the image nearest frame_x (Broad). Whole multiples of L are added: the rounding,
 * a few units of L's, lies within the margins. */
static inline void span_frame(const Broad *b, Span *sp)
{
    double L = (double)b->p->L;
    double mx = ((double)sp->xlo + (double)sp->xhi) * 0.5, my = ((double)sp->ylo + (double)sp->yhi) * 0.5;
    double ox = b->wrap_x ? mx : mx - b->frame_x + L / 2; /* in [0, L) for the image wanted */
    if (ox >= 0 && ox < L && my >= 0 && my < L) return; /* most boxes: no division */
    double kx = floor(ox / L), ky = floor(my / L);
    if (kx != 0) {
        sp->xlo = (real)((double)sp->xlo - kx * L);
        sp->xhi = (real)((double)sp->xhi - kx * L);
    }
    if (ky != 0) {
        sp->ylo = (real)((double)sp->ylo - ky * L);
        sp->yhi = (real)((double)sp->yhi - ky * L);
    }
}

/* A coordinate in the grid's cell units from origin, rounded to float. */
static inline float grid_units(real c, double origin, double inv_h)
{
    return (float)(((double)c - origin) * inv_h);
}

static inline void span_box(const Span *a, const Plan *pl, Box *b)
{
    *b = box_of(grid_units(a->xlo, pl->x0, pl->inv_h), grid_units(a->xhi, pl->x0, pl->inv_h),
                grid_units(a->ylo, pl->y0, pl->inv_h), grid_units(a->yhi, pl->y0, pl->inv_h));
}

static inline int64_t cell_coord(double lo, double hi, double origin, double inv_h, int64_t g)
{
    double c = ((lo + hi) * 0.5 - origin) * inv_h;
    if (!(c > 0)) return 0;
    if (c > (double)(g - 1)) return g - 1;
    return (int64_t)c;
}

/* The cell of a box's centre. */
static inline int32_t span_cell(const Span *sp, const Plan *pl)
{
    return (int32_t)(cell_coord(sp->ylo, sp->yhi, pl->y0, pl->inv_h, pl->gy) * pl->gx +
                     cell_coord(sp->xlo, sp->xhi, pl->x0, pl->inv_h, pl->gx));
}

/* A fast disk's slot (as it will be) goes to this thread's list. */
static void note_fast(BroadThread *th, int32_t slot)
{
    th->fast = sim_grow(th->fast, &th->fast_cap, th->fast_len + 1, sizeof *th->fast);
    th->fast[th->fast_len++] = slot;
}

/* Whether the disk in slot q is fast in a mixed step: its box is empty then (it meets the others
 * along its path, omp_paths.c). */
static inline int is_fast(const Broad *b, int64_t q)
{
    real cut = (real)b->plan.v_cut;
    return SIM_FABS(b->s.vx[q]) >= cut || SIM_FABS(b->s.vy[q]) >= cut;
}

/* Counting sort of the slots into the cells of their boxes: per-thread histograms, a prefix sum over
 * cells and threads, a scatter (inside a cell the slots keep their order). The scatter finds each
 * box's cell again from the disk it reads anyway, which costs less than storing the cells by slot
 * and reading them back (4 bytes a disk each way, beyond the cache on large gases). The boxes go in
 * cell order with their slots; with reorder, the disks themselves move to the new order (through
 * spare). The wall events (3.1) are found on the way, and the slots that have one listed. */
static void bin_grid(Broad *b, int tid, int reorder)
{
    const Plan *pl = &b->plan;
    const Slots *s = &b->s;
    int nt = b->nt;
    int64_t cells = pl->gx * pl->gy, from, to;
    /* one thread counts into cell_start shifted by a cell, and its scatter's cursors end as the
     * cells' starts: no histogram to clear and sum (a gas has about a cell a disk) */
    int one = nt == 1;
    int32_t *h = one ? b->cell_start + 1 : b->hist + (size_t)tid * (size_t)cells;
    BroadThread *th = &b->th[tid];
    int mixed = pl->mode == MODE_MIXED;
    /* a gas's dense wall_t would be written for nothing but the rare disk near a wall */
    int wall_all = !b->wall_lists || mixed || b->opt->check, periodic = b->p->periodic;
    th->fast_len = 0;
    memset(h - one, 0, (size_t)(cells + one) * sizeof *h);
    range_of(b->p->n, tid, nt, &from, &to);
    for (int64_t q = from; q < to; q++) {
        Span sp;
        step_span(s, q, pl->grow, &sp);
        if (periodic) span_frame(b, &sp);
        h[span_cell(&sp, pl)]++;
        if (!reorder) {
            real wt = slot_wall_time(s, b->p, q);
            if (wall_all) b->wall_t[q] = wt;
            if (wt >= 0) found_wall(&th->found, wt, (int32_t)q);
        }
    }
#pragma omp barrier
    if (one) {
        int32_t acc = 0;
        for (int64_t c = 0; c < cells; c++) {
            int32_t v = h[c];
            h[c] = acc;
            acc += v;
        }
    }
    int64_t c0, c1, sum = 0;
    range_of(one ? 0 : cells, tid, nt, &c0, &c1);
    for (int64_t c = c0; c < c1; c++) {
        int32_t tot = 0;
        for (int t = 0; t < nt; t++) {
            int32_t v = b->hist[(size_t)t * (size_t)cells + (size_t)c];
            b->hist[(size_t)t * (size_t)cells + (size_t)c] = tot;
            tot += v;
        }
        b->cell_start[c] = tot;
        sum += tot;
    }
    b->th[tid].partial = sum;
#pragma omp barrier
#pragma omp single
    if (!one) b->cell_start[cells] = (int32_t)scan_partials(b, nt);
    int64_t base = b->th[tid].partial;
    for (int64_t c = c0; c < c1; c++) {
        int32_t v = b->cell_start[c];
        b->cell_start[c] = (int32_t)base;
        base += v;
    }
#pragma omp barrier
    if (reorder) {
        const Slots *d = &b->spare;
        for (int64_t q = from; q < to; q++) {
            Span sp;
            step_span(s, q, pl->grow, &sp);
            if (periodic) span_frame(b, &sp);
            int32_t c = span_cell(&sp, pl);
            int32_t pos = (one ? 0 : b->cell_start[c]) + h[c]++;
            if (mixed && is_fast(b, q)) {
                b->boxes[pos] = empty_box;
                note_fast(th, pos);
            } else {
                span_box(&sp, pl, &b->boxes[pos]);
            }
            b->box_slot[pos] = pos;
            real wt = slot_wall_time(s, b->p, q);
            if (wall_all) b->wall_t[pos] = wt;
            if (wt >= 0) found_wall(&th->found, wt, pos);
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
            Span sp;
            step_span(s, q, pl->grow, &sp);
            if (periodic) span_frame(b, &sp);
            int32_t c = span_cell(&sp, pl);
            int32_t pos = (one ? 0 : b->cell_start[c]) + h[c]++;
            if (mixed && is_fast(b, q)) {
                b->boxes[pos] = empty_box;
                note_fast(th, (int32_t)q);
            } else {
                span_box(&sp, pl, &b->boxes[pos]);
            }
            b->box_slot[pos] = (int32_t)q;
        }
    }
#pragma omp barrier
    if (reorder) {
#pragma omp single
        {
            Slots t = b->s;
            b->s = b->spare;
            b->spare = t;
        }
    }
}

/* Narrow phase for two disks whose boxes overlap. Only pairs that approach (b < 0, as in pair_time)
 * count as tested. SPEC.md makes the disk of lower original index pair_time's first, but pair_time
 * gives the same bits either way round (swapping the disks negates dx, dy, dvx and dvy exactly, and
 * only their products and squares follow), so the indices are read only for the few pairs with an
 * event; so are the wall event times, found again (wall_t need not hold them, see wall_lists). */
static SIM_INLINE void try_pair(const Broad *w, BroadThread *th, int32_t a, int32_t b, int wrap)
{
    const Slots *s = &w->s;
    const Params *p = w->p;
    real dx = s->x[b] - s->x[a], dy = s->y[b] - s->y[a];
    if (wrap) dx = wrap_delta(dx, p->L, p->half), dy = wrap_delta(dy, p->L, p->half); /* SPEC.md 7 */
    real dvx = s->vx[b] - s->vx[a], dvy = s->vy[b] - s->vy[a];
    if (!(dx * dvx + dy * dvy < 0)) return;
    th->found.tests++;
    real t = pair_time_rel(dx, dy, dvx, dvy, p->sigma2, 1);
    if (!(t >= 0 && before_walls(t, slot_wall_time(s, p, a), slot_wall_time(s, p, b)))) return;
    if (s->id[b] < s->id[a]) {
        int32_t u = a;
        a = b;
        b = u;
    }
    found_push(&th->found, t, s->id[a], s->id[b], a, b);
}

/* The pairs of box a with the boxes b + u whose bit u is set in the mask m (in the periodic box by
 * their nearest images). */
static void scan_hits(const Broad *w, BroadThread *th, int32_t a, int32_t b, unsigned m)
{
    if (w->p->periodic) {
        for (int u = 0; u < SCAN_WIDTH; u++)
            if (m >> u & 1) try_pair(w, th, w->box_slot[a], w->box_slot[b + u], 1);
        return;
    }
    for (int u = 0; u < SCAN_WIDTH; u++)
        if (m >> u & 1) try_pair(w, th, w->box_slot[a], w->box_slot[b + u], 0);
}

#ifdef SIM_SSE2
/* Whether box b overlaps the box whose probe (Box) is p: all four lanes at most b's. */
static inline unsigned box_hit(__m128 p, const Box *b)
{
    return (unsigned)(_mm_movemask_ps(_mm_cmple_ps(p, _mm_loadu_ps(&b->xhi))) == 15);
}
#endif

/* Tests box a against the boxes [b0, b1) in groups of SCAN_WIDTH, each group's overlaps a mask without
 * a branch per box: ranges hold a few boxes each, and a branch per box and per range end would be
 * mispredicted about once per box. The last group reads boxes past b1 (boxes has SCAN_WIDTH spare
 * entries) and masks them off. With SSE2 each box is one comparison of four lanes (Box). */
static SIM_INLINE void scan_range(const Broad *w, BroadThread *th, int32_t a, int32_t b0, int32_t b1)
{
    const Box *bx = w->boxes, *ba = &w->boxes[a];
#ifdef SIM_SSE2
    __m128 v = _mm_loadu_ps(&ba->xhi);
    __m128 probe = _mm_xor_ps(_mm_shuffle_ps(v, v, _MM_SHUFFLE(2, 3, 0, 1)), _mm_set1_ps(-0.0f));
#endif
    for (int32_t b = b0; b < b1; b += SCAN_WIDTH) {
#ifdef SIM_SSE2
        unsigned m = box_hit(probe, &bx[b]) | box_hit(probe, &bx[b + 1]) << 1 |
                     box_hit(probe, &bx[b + 2]) << 2 | box_hit(probe, &bx[b + 3]) << 3;
#else
        unsigned m = (unsigned)boxes_overlap(ba, &bx[b]) |
                     (unsigned)boxes_overlap(ba, &bx[b + 1]) << 1 |
                     (unsigned)boxes_overlap(ba, &bx[b + 2]) << 2 |
                     (unsigned)boxes_overlap(ba, &bx[b + 3]) << 3;
#endif
        int32_t rest = b1 - b;
        m &= rest < SCAN_WIDTH ? (1u << rest) - 1 : (1u << SCAN_WIDTH) - 1;
        if (m) scan_hits(w, th, a, b, m);
    }
}

/* Tests every box against the later boxes of its own cell and those of the cells east, north-west,
 * north and north-east: each pair of neighbouring cells once. The east cell follows the own cell in
 * memory and the three northern cells are contiguous, so two ranges cover them. */
static SIM_INLINE void scan_cell(Broad *b, BroadThread *th, int64_t cx, int64_t cy)
{
    const int32_t *cs = b->cell_start;
    int64_t gx = b->plan.gx, gy = b->plan.gy, c = cy * gx + cx;
    int32_t end1 = cs[cx + 1 < gx ? c + 2 : c + 1];
    int32_t lo2 = 0, end2 = 0;
    if (cy + 1 < gy) {
        int64_t first = (cy + 1) * gx + (cx > 0 ? cx - 1 : 0);
        int64_t last = (cy + 1) * gx + (cx + 1 < gx ? cx + 1 : cx);
        lo2 = cs[first];
        end2 = cs[last + 1];
    }
    for (int32_t a = cs[c]; a < cs[c + 1]; a++) {
        scan_range(b, th, a, a + 1, end1);
        scan_range(b, th, a, lo2, end2);
    }
}

static void scan_grid(Broad *b, int tid)
{
    const Plan *pl = &b->plan;
    BroadThread *th = &b->th[tid];
    int64_t gx = pl->gx, gy = pl->gy;
    int64_t chunk = gy / (8 * b->nt) + 1;
#pragma omp for schedule(dynamic, chunk)
    for (int64_t cy = 0; cy < gy; cy++)
        for (int64_t cx = 0; cx < gx; cx++) scan_cell(b, th, cx, cy);
}

/* The periodic box's grid: every box against the later boxes of its own cell and those of the cells
 * east, north-west, north and north-east, wrapping at the edges where the axis wraps (an axis of one
 * cell has no neighbours along it: wrap_cells never leaves 2, whose two neighbours would be one).
 * Across an edge, and everywhere where an axis that wraps has one cell, the boxes lie in frames L
 * apart: their pairs skip the screen (the few that a box straddling the edge has), but for the empty
 * boxes of a mixed step's fast disks, which the paths pair. A cell whose neighbours lie over no edge
 * takes the walled grid's two ranges (scan_cell). */
static void scan_grid_periodic(Broad *b, int tid)
{
    static const int offset[4][2] = {{1, 0}, {-1, 1}, {0, 1}, {1, 1}};
    const Plan *pl = &b->plan;
    BroadThread *th = &b->th[tid];
    const int32_t *cs = b->cell_start;
    int64_t gx = pl->gx, gy = pl->gy, chunk = gy / (8 * b->nt) + 1;
    int whole = (b->wrap_x && gx == 1) || gy == 1; /* an axis that wraps onto its one cell */
#pragma omp for schedule(dynamic, chunk)
    for (int64_t cy = 0; cy < gy; cy++) {
        for (int64_t cx = 0; cx < gx; cx++) {
            int64_t c = cy * gx + cx;
            if (!whole && cy + 1 < gy && (!b->wrap_x || (cx > 0 && cx + 1 < gx))) {
                scan_cell(b, th, cx, cy);
                continue;
            }
            for (int k = -1; k < 4; k++) {
                int64_t nx = cx, ny = cy;
                int across = 0;
                if (k >= 0) {
                    nx += offset[k][0], ny += offset[k][1];
                    if ((offset[k][0] && gx == 1) || (offset[k][1] && gy == 1)) continue;
                    if (nx < 0 || nx >= gx) {
                        if (!b->wrap_x) continue;
                        nx = (nx + gx) % gx, across = 1;
                    }
                    if (ny >= gy) ny = 0, across = 1;
                }
                int64_t d = ny * gx + nx;
                for (int32_t a = cs[c]; a < cs[c + 1]; a++) {
                    int32_t from = k < 0 ? a + 1 : cs[d];
                    if (!(across || whole)) {
                        scan_range(b, th, a, from, cs[d + 1]);
                        continue;
                    }
                    if (b->boxes[a].xhi == -INFINITY) continue; /* a fast disk's empty box */
                    for (int32_t e = from; e < cs[d + 1]; e++)
                        if (b->boxes[e].xhi != -INFINITY) try_pair(b, th, b->box_slot[a], b->box_slot[e], 1);
                }
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
    if (p->periodic) return -1;
    real tw = min_time(wall_time(s->x[q], s->vx[q], p->lo, p->hi),
                       wall_time(s->y[q], s->vy[q], p->lo, p->hi));
    return tw <= 1 ? tw : -1;
}

static int trim_cmp(const void *pa, const void *pb)
{
    const PairEvent *a = pa, *b = pb;
    return (a->a > b->a) - (a->a < b->a);
}

/* Whether the pair event (t, i, j) of the disk in slot q lies beyond that disk's trim (SlowGrid's
 * keep): among the events its broad phase may leave out. */
static int beyond_trim(const PairEvent *trims, size_t n_trims, int32_t q, real t, int32_t i, int32_t j)
{
    PairEvent key = {0, 0, 0, q, 0};
    const PairEvent *c = n_trims ? bsearch(&key, trims, n_trims, sizeof *trims, trim_cmp) : NULL;
    return c && !event_before(t, 1, i, j, c->t, 1, c->i, c->j);
}

/* The threads' pair events (trims = 0) or trims (1) in one array sorted by cmp, *len of them. */
static PairEvent *gathered(const Broad *w, int trims, int (*cmp)(const void *, const void *), size_t *len)
{
    size_t n = 0;
    for (int t = 0; t < w->nt; t++) n += trims ? w->th[t].found.trim_len : w->th[t].found.len;
    PairEvent *all = sim_calloc(n + 1, sizeof *all);
    n = 0;
    for (int t = 0; t < w->nt; t++) {
        const Found *f = &w->th[t].found;
        size_t k = trims ? f->trim_len : f->len;
        if (k) memcpy(all + n, trims ? f->trim : f->ev, k * sizeof *all);
        n += k;
    }
    if (n) qsort(all, n, sizeof *all, cmp);
    *len = n;
    return all;
}

/* Every pair event that the choice can accept (before_walls), found by testing all pairs, must be
 * among the broad phase's events, but for those beyond a trim, and nothing else. */
static void check_broad_phase(Broad *w, int64_t step)
{
    const Slots *s = &w->s;
    int64_t n = w->p->n;
    for (int64_t q = 0; q < n; q++)
        if (w->wall_t[q] != check_wall_time(s, w->p, q))
            sim_fail("--check: step %lld: disk %d has the wall event time %.17g, not %.17g",
                    (long long)step, s->id[q], (double)w->wall_t[q],
                    (double)check_wall_time(s, w->p, q));
    size_t n_ev, n_trims;
    PairEvent *mine = gathered(w, 0, pair_cmp, &n_ev), *trims = gathered(w, 1, trim_cmp, &n_trims);
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
            const Params *p = w->p;
            real t = p->periodic ? pair_time_wrap(s->x[a], s->y[a], s->vx[a], s->vy[a], s->x[b], s->y[b],
                                                  s->vx[b], s->vy[b], p->sigma2, p->L, p->half, 1)
                                 : pair_time(s->x[a], s->y[a], s->vx[a], s->vy[a], s->x[b], s->y[b], s->vx[b],
                                             s->vy[b], p->sigma2);
            if (t < 0 || !before_walls(t, w->wall_t[a], w->wall_t[b])) continue;
            PairEvent key = {t, s->id[a], s->id[b], 0, 0};
            PairEvent *hit = bsearch(&key, mine, uniq, sizeof *mine, pair_cmp);
            if (!hit && (beyond_trim(trims, n_trims, (int32_t)a, t, key.i, key.j) ||
                         beyond_trim(trims, n_trims, (int32_t)b, t, key.i, key.j)))
                continue;
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
    free(trims);
}

/* ==== the step's broad phase =========================================================================== */

/* The paths' broad phase (slow: a mixed step's slow grid, else NULL), its phases timed. */
static void paths_find(Broad *b, int tid, const SlowGrid *slow)
{
    BroadThread *th = &b->th[tid];
    paths_bin(b->paths, &b->s, b->p, b->wall_t, slow, slow ? th->fast : NULL,
              slow ? (int64_t)th->fast_len : 0, &th->found, tid, b->nt);
    phase_mark(b, tid, PHASE_BIN);
#pragma omp barrier
    phase_mark(b, tid, PHASE_WAIT);
    paths_pairs(b->paths, &b->s, b->p, b->wall_t, &th->found, tid, b->nt);
    phase_mark(b, tid, PHASE_PAIRS);
#pragma omp barrier
    phase_mark(b, tid, PHASE_WAIT);
}

/* A mixed step's slow disks as the fast disks' paths meet them (the grid's boxes, binned). */
static SlowGrid slow_grid_of(const Broad *b)
{
    const Plan *pl = &b->plan;
    SlowGrid slow = {b->boxes, b->cell_start, b->box_slot, pl->g, pl->x0, pl->inv_h, pl->reach, b->keep};
    return slow;
}

/* --check: the step's events against all pairs, once every thread has found its own. */
static void broad_checked(Broad *b, int tid, int64_t step)
{
    if (b->opt->check) {
#pragma omp single
        check_broad_phase(b, step);
        phase_mark(b, tid, PHASE_PAIRS);
    }
}

void broad_find(Broad *b, int tid, int64_t step, int reorder, int again)
{
    BroadThread *th = &b->th[tid];

    if (again) { /* a mixed step: of its events only the fast disks' with slow disks depend on keep */
        SlowGrid slow = slow_grid_of(b);
        paths_refind(b->paths, &b->s, b->p, b->wall_t, &slow, th->fast, (int64_t)th->fast_len, &th->found);
        phase_mark(b, tid, PHASE_BIN);
#pragma omp barrier
        phase_mark(b, tid, PHASE_WAIT);
        broad_checked(b, tid, step);
        return;
    }
    /* the fastest disk and the lengths of all steps (found by the last move) plan the broad phase */
    th->found.len = th->found.wall_len = th->found.trim_len = 0;
#pragma omp single
    {
        b->plan = plan_step(b, b->nt);
        if (b->plan.mode != MODE_GRID) paths_ready(b->paths, &b->plan.paths, b->nt);
    }
    phase_mark(b, tid, PHASE_PLAN);
    th->found.mark = b->plan.mode == MODE_PATHS ? b->mark : NULL;
    th->found.step = step;
    if (b->plan.mode == MODE_PATHS) {
        paths_find(b, tid, NULL);
    } else {
        bin_grid(b, tid, reorder);
        phase_mark(b, tid, PHASE_BIN);
        if (b->p->periodic) scan_grid_periodic(b, tid);
        else scan_grid(b, tid);
        phase_mark(b, tid, PHASE_PAIRS);
        if (b->plan.mode == MODE_MIXED) {
            SlowGrid slow = slow_grid_of(b);
            paths_find(b, tid, &slow);
        }
    }
    broad_checked(b, tid, step);
}
