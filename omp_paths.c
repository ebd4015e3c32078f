/* omp_paths.c: omp's broad phase for fast scenes: every disk's path over the step is binned into the
 * cells it crosses, with the interval of time it spends in each, and two disks are tested only where
 * they share a cell at overlapping times.
 *
 * Why: in the assignment's random scenes a disk crosses up to a quarter of the box per step. A grid of
 * cells wide enough for the fastest disk prunes nothing there; binning each disk once per cell of its
 * path costs what the path needs (a slow disk one or a few cells, a fast one a cell per h of its
 * path), and the time intervals prune the pairs that cross the same cell at different times.
 *
 * A path ends at the disk's wall event. SPEC.md 3.3 orders a wall event (kind 0) before every pair
 * event of the same disk at the same or a later time, so the greedy walk takes the disk at its wall
 * event or earlier: pair events from then on are never accepted and need not be found (before_walls
 * in omp_step.h; the all-pairs --check drops them too). A disk's path is thus c + v t for t in
 * [0, T], T = min(1, wall time), and it stays inside the box: the grid covers [lo, hi]^2 alone.
 *
 * The step, on every thread of the team, with one barrier:
 * A. over the disks (static ranges): the wall event and the cells of the path, each (grown by G) with
 *    the interval of time the centre spends there: the cells of the path's bounding box where that is
 *    small, else row by row (the interval the centre spends in a row gives the row's cells). Each
 *    (cell, interval) goes to this thread's bucket of the cell's tile (a square of tc x tc cells).
 * B. over the tiles (dynamic): the tile's entries are counted into their cells, each cell's entries
 *    sorted by entry time and swept: an entry meets the later ones that enter before it leaves, 8, 4
 *    or 1 at a time (omp_lanes.h: the widest SIMD screen the processor runs, or --lanes). A pair
 *    is tested only in the cell holding the midpoint of its two centres at its time of closest
 *    approach within [0, min(T_a, T_b)] (symmetric in the two disks, bit for bit), so it is tested at
 *    most once, whatever the number of cells the two paths share.
 * Why that is enough: if the pair has an event at t < min(T_a, T_b), its distance at the time of
 * closest approach tau is at most 2r, so each centre is within r of the midpoint M(tau): both paths
 * visit M's cell grown by r at time tau. The filter asks for distance <= 2 G_TEST and the grid grows
 * cells by G > G_TEST: the difference (at least SIM_REL_MARGIN of the box) covers the rounding of
 * every position, time and cell index here, and broad_margin's graze term the rounding of pair_time.
 * Intervals are stored as floats widened by T_PAD, far more than a float's rounding of [0, 1].
 */
#include "omp_step.h"

#include <omp.h>
#include <stdlib.h>
#include <string.h>
#ifdef SIM_X86_TARGETS
#include <immintrin.h>
#define LANES_AVX2 1   /* the compiler builds AVX2 functions, run where the processor has AVX2 */
#define LANES_AVX512 1 /* and AVX-512F functions, run where the processor has AVX-512F */
#endif

#define LINE_EPS 0.0625 /* e of the squared line screen (omp_lanes.h): (1 + e) s^2 a + (1 + 1/e) c^2 */
#define T_PAD 1e-6f          /* widening of a float time interval, both ends */
#define TILE_ENTRIES 16384.0 /* entries of a tile that fit a core's cache with room to spare */
#define CELL_FEW 16          /* cells of more visits than this are sorted by time, not paired all */

/* Relative costs for the plan, in the units of omp.c's grid cost model (binning one disk = 1, about
 * 20 ns): a disk's fixed work (wall event, the path's set-up), one visit of a cell
 * (rasterised, stored, counted, placed, paired), one pair of visits that overlap in time (screened
 * in float, rarely tested further), one cell. Measured on the assignment's scenes, N = 1e3 to 1e5. */
#define COST_DISK 2.5
#define COST_ENTRY 1.5
#define COST_PAIR 0.03
#define COST_CELL 0.1
#define COST_SLOW 0.15 /* one slow disk's box tested against a fast disk's row of cells */
#define COST_ROW 1.0   /* one row of cells of a fast disk's path across the slow grid */

/* A disk as the exact tests read it: its state, its wall event time (+inf when none within the step)
 * and the end of its path, min(1, wall time). */
typedef struct {
    real x, y, vx, vy;
    real wt, cap;
    int32_t id;
} Body;

/* A path's visit of one cell as phase A writes it: where phase B counts it (the cell's index within
 * its tile, row * tc + col, then its bin of entry time), the interval of time, the disk, and its
 * state in float for the screens. The state travels with the visit so that phase B reads one stream of
 * entries in order, rather than records of the disks at random that, on two or more threads, another
 * core mostly wrote in phase A. */
typedef struct {
    int32_t key;
    float t0, t1;
    int32_t slot;
    float x, y, vx, vy;
} Entry;

/* A thread's entries of one tile. Padded to a cache line of its own: phase A bumps len entry by
 * entry, and a line shared with another thread's bucket would travel between the cores. */
typedef struct {
    Entry *e;
    size_t len, cap;
    char pad[64 - sizeof(Entry *) - 2 * sizeof(size_t)];
} Bucket;

/* A visit as phase B places it: its entry time (the sort's key) and where the entry lies. Placing
 * 16 bytes per visit writes one cache line where the visit's seven fields, placed at once, would write
 * seven lines at random; the fields are then copied in order, their entries read at random. */
typedef struct {
    float t0;
    const Entry *e;
} Item;

/* Per-thread scratch of phase B, padded so that threads never share a cache line. */
typedef struct {
    int32_t *start;      /* tc * tc + 1: first visit of each cell of the tile */
    size_t start_cap;
    Item *item;          /* the tile's visits as counted, then sorted within each cell */
    size_t item_cap;
    float *t0, *t1;      /* the tile's visits in cell order, LANES_MAX spare entries: the interval, */
    int32_t *slot;       /* the disk, */
    float *x, *y, *vx, *vy; /* and its state in float for the screens */
    size_t v_cap;
    int64_t *order;      /* the tiles in the order phase B takes them (tile_order) */
    size_t order_cap;
    char pad[64];
} Scratch;

typedef struct Visits Visits;

/* Phase B's screens of one cell's visits [lo, hi), at one width (omp_lanes.h). */
typedef void CellFn(const Paths *pp, const Visits *v, int32_t lo, int32_t hi, int64_t cx, int64_t cy,
                    const Params *p, Found *mine);
static void cell_screens(int lanes, CellFn **few, CellFn **many);

struct Paths {
    PathsPlan pl;      /* this step's */
    int32_t *tile_of;  /* g: tile coordinate of a cell coordinate */
    int32_t *in_tile;  /* g: the cell coordinate within its tile */
    size_t coord_cap;
    Bucket *bk;        /* nt_max * tiles: bk[tid * tiles + tile] */
    size_t bk_cap;
    int nt_max;
    Scratch *sc;       /* nt_max */
    int lanes;         /* phase B's screens: pairs at a time */
    CellFn *few, *many; /* and their functions (cell_screens) */
};

/* The width of phase B's screens: want (1, 4, 8 or 16), or 0: the widest this build and processor
 * run. */
static int lanes_of(int want)
{
    int widest = 1;
#ifdef SIM_SSE2
    widest = 4;
#endif
#ifdef LANES_AVX2
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("popcnt")) widest = 8;
#endif
#ifdef LANES_AVX512
    if (widest == 8 && __builtin_cpu_supports("avx512f")) widest = 16;
#endif
    if (want > widest)
        sim_fail("--lanes %d needs %s, which this processor or build lacks (at most %d here)", want,
                 want == 16 ? "AVX-512F" : want == 8 ? "AVX2" : "SSE2", widest);
    return want ? want : widest;
}

Paths *paths_new(int nt_max, int lanes)
{
    Paths *pp = sim_calloc(1, sizeof *pp);
    pp->nt_max = nt_max;
    pp->lanes = lanes_of(lanes);
    cell_screens(pp->lanes, &pp->few, &pp->many);
    pp->sc = sim_calloc_lines((size_t)nt_max, sizeof *pp->sc);
    return pp;
}

int paths_lanes(const Paths *pp)
{
    return pp->lanes;
}

void paths_free(Paths *pp)
{
    if (!pp) return;
    for (size_t k = 0; k < pp->bk_cap; k++) free(pp->bk[k].e);
    for (int t = 0; t < pp->nt_max; t++) {
        free(pp->sc[t].start);
        free(pp->sc[t].item);
        free(pp->sc[t].t0);
        free(pp->sc[t].t1);
        free(pp->sc[t].slot);
        free(pp->sc[t].x);
        free(pp->sc[t].y);
        free(pp->sc[t].vx);
        free(pp->sc[t].vy);
        free(pp->sc[t].order);
    }
    free(pp->bk);
    free(pp->sc);
    free(pp->tile_of);
    free(pp->in_tile);
    free(pp);
}

/* ==== the plan ======================================================================================= */

/* The margins of a step whose fastest velocity component is vm, and the float bounds of the screens
 * (omp_lanes.h's line: positions within X, velocity components within vm). */
static void plan_margins(const Params *p, double vm, PathsPlan *pl)
{
    double r = p->r, span = p->periodic ? p->L : p->hi - p->lo;
    double reach = 2 * r + 2 * 1.4142135623730951 * vm;
    if (reach > 1.4142135623730951 * span + 2 * r) reach = 1.4142135623730951 * span + 2 * r;
    double m = broad_margin(r, p->L, reach, SIM_REL_MARGIN);
    double g_test = r + m;
    pl->grow = r + 2 * m;
    pl->reach2 = 4 * g_test * g_test;
    double X = fabs((double)p->lo) > fabs((double)p->hi + pl->grow) ? fabs((double)p->lo)
                                                                     : fabs((double)p->hi + pl->grow);
    if (p->periodic) X = 2 * (double)p->L + pl->grow; /* the images a path's pieces take: [-L, 2L) */
    double u = 5.9604644775390625e-8; /* 2^-24, a float's unit roundoff */
    double s = 2 * g_test, c = 12 * u * g_test * vm + 64 * u * X * vm;
    pl->flt = X < 1e17 && vm < 1e17 && X * vm < 1e18 && g_test * vm < 1e18;
    pl->flt_s = pl->flt ? (float)((1 + LINE_EPS) * s * s * (1 + 1e-6)) : 0;
    pl->flt_c = pl->flt ? (float)((1 + 1 / LINE_EPS) * c * c * (1 + 1e-6) + 1e-30) : 0;
}

/* The cells (g from x0 with side h) and, for `entries` visits, the tiles: enough for dynamic
 * scheduling over the threads (two a thread or more: a path's cells that span two tiles cost phase A
 * a slower loop, and the branch between the two loops a misprediction where that is a coin toss, so
 * smaller tiles cost more than their finer balance gains), small enough for a core's cache; and up to
 * two bins of entry time per visit, so that a cell's visits come out of phase B's count nearly
 * sorted: the insertion sort's test of each item against the one before it is then mostly false, and
 * a processor predicts it (at one visit per bin it was a coin toss). More bins would cost more in
 * the count, which clears and sums them for every tile. */
static void plan_cells(PathsPlan *pl, int64_t g, double x0, double h, double entries, int nt)
{
    pl->g = g;
    pl->x0 = x0;
    pl->h = h;
    pl->inv_h = 1 / h;
    pl->last = (double)(g - 1);
    double want = entries / TILE_ENTRIES;
    if (nt > 1 && want < 2.0 * nt) want = 2.0 * nt;
    int64_t gt = (int64_t)ceil(sqrt(want));
    if (gt < 1) gt = 1;
    if (gt > g) gt = g;
    pl->tc = (g + gt - 1) / gt;
    pl->gt = (g + pl->tc - 1) / pl->tc;
    pl->tiles = pl->gt * pl->gt;
    double per_cell = entries / ((double)g * (double)g);
    pl->bins = 1;
    while (pl->bins < 256 && pl->bins < 2 * per_cell) pl->bins *= 2;
}

/* Visits and pairs of visits overlapping in time for n disks whose steps' axis lengths add up to s1,
 * on cells of side h = 1 / inv_h, g * g of them: about n q^2 + q s1 / h visits (q = 1 + 2G/h: a disk
 * at rest overlaps q^2 cells on average, and a path adds a cell per h of its axis lengths), spending
 * D = n q^2 cell-steps of time in all (*spent, where not NULL); pairs, about 0.85 E D / cells (each
 * visit meets the others' time in its cell; the factor measured), at most all pairs of each cell.
 * Multiplications by inv_h, no division: paths_plan's search runs several times a step (once more
 * per cut of a mixed plan), in a serial section. */
static double visits(double n, double s1, double inv_h, double grow, double *spent)
{
    double q = 1 + 2 * grow * inv_h, d = n * q * q;
    if (spent) *spent = d;
    return d + q * s1 * inv_h;
}

int paths_fit_periodic(const Params *p, double vm, double grow, double h)
{
    /* a cell more than the count needs: the pieces' cells are counted in two images of the box */
    return (vm + 2 * grow + 3 * h) * (1 + SIM_REL_MARGIN) < (double)p->L;
}

double paths_plan(const Params *p, int64_t n, double vm, double s1, int nt, PathsPlan *pl)
{
    double span = p->periodic ? p->L : p->hi - p->lo, nd = (double)n;
    plan_margins(p, vm, pl);
    pl->periodic = p->periodic;
    pl->L = p->L;
    /* at most 4 cells per disk and 2^26 in all */
    double gmax = sqrt(4 * nd + 16);
    if (gmax > 8192) gmax = 8192;
    double best = -1, inv_span = 1 / span;
    int64_t best_g = 1;
    for (double gd = 1; gd <= gmax; gd = gd < 8 ? gd + 1 : gd * 1.125) {
        double g = (double)(int64_t)gd, ig = 1 / g, cells = g * g, d;
        if (p->periodic && !paths_fit_periodic(p, vm, pl->grow, span / g)) continue;
        double e = visits(nd, s1, g * inv_span, pl->grow, &d);
        double pairs = (0.85 * e * d < e * e / 2 ? 0.85 * e * d : e * e / 2) * ig * ig;
        double cost = COST_ENTRY * e + COST_PAIR * pairs + COST_CELL * cells;
        if (best < 0 || cost < best) {
            best = cost;
            best_g = (int64_t)g;
        }
        /* beyond the minimum the visits and the cells only grow: no finer grid can win back twice
         * the best (the search ran to gmax every step, a few microseconds of a serial section) */
        if (cost > 2 * best) break;
    }
    if (best < 0) return INFINITY; /* the periodic box: no grid where the paths fit */
    double h = span / (double)best_g;
    plan_cells(pl, best_g, p->periodic ? 0 : p->lo, h, visits(nd, s1, 1 / h, pl->grow, NULL), nt);
    return COST_DISK * nd + best;
}

/* The fast disks of a mixed step meet each other along their paths (a plan of their own) and the
 * slow disks across the rows of the slow grid (fast_slow): about n q + s1 / (2 h) rows and
 * visits(s1, h, Gs) cells, n_slow / cells boxes each. With keep k, a walk stops after about k + 1
 * free paths among the slow disks (one per 4 r n_slow / area of its length) and a cell and the reach
 * more, and s1 counts no more than that of each path (an axis length up to sqrt 2 times a length). */
double paths_plan_grid(const Params *p, int64_t n_fast, int64_t n_slow, double vm, double s1,
                       double slow_reach, double h, int64_t g, int keep, int nt, PathsPlan *pl)
{
    double nf = (double)n_fast, cells = (double)g * (double)g, span = p->hi - p->lo;
    double cost = paths_plan(p, n_fast, vm, s1, nt, pl);
    double walk = s1, rate = 4 * p->r * (double)n_slow / (span * span);
    if (keep > 0 && rate > 0) {
        double most = nf * 1.4142135623730951 * ((keep + 1) / rate + 2 * (h + slow_reach));
        walk = walk < most ? walk : most;
    }
    double rows = nf * (1 + 2 * slow_reach / h) + walk / (2 * h);
    return cost + COST_ROW * rows + COST_SLOW * visits(nf, walk, 1 / h, slow_reach, NULL) * (double)n_slow / cells;
}

void paths_ready(Paths *pp, const PathsPlan *pl, int nt)
{
    pp->pl = *pl;
    int64_t g = pp->pl.g;
    if ((size_t)g > pp->coord_cap) {
        free(pp->tile_of);
        free(pp->in_tile);
        pp->tile_of = sim_calloc((size_t)g, sizeof *pp->tile_of);
        pp->in_tile = sim_calloc((size_t)g, sizeof *pp->in_tile);
        pp->coord_cap = (size_t)g;
    }
    for (int64_t k = 0; k < g; k++) {
        pp->tile_of[k] = (int32_t)(k / pp->pl.tc);
        pp->in_tile[k] = (int32_t)(k % pp->pl.tc);
    }
    size_t need = (size_t)nt * (size_t)pp->pl.tiles;
    if (need > pp->bk_cap) {
        Bucket *bk = sim_calloc_lines(need, sizeof *bk); /* each bucket a line of its own */
        if (pp->bk_cap) memcpy(bk, pp->bk, pp->bk_cap * sizeof *bk);
        free(pp->bk);
        pp->bk = bk;
        pp->bk_cap = need;
    }
}

/* ==== phase A: the cells of each path ================================================================= */

/* Cell coordinate of a position, the edge cells reaching out to infinity (minimum and maximum: no
 * branch). */
static inline int64_t cell_of(const Paths *pp, double c)
{
    double k = (c - pp->pl.x0) * pp->pl.inv_h;
    k = k > 0 ? k : 0;
    return (int64_t)(k < pp->pl.last ? k : pp->pl.last);
}

/* The cells [*u0, *u1] along an axis of positions [a, b] (a <= b), cut to [lo, hi]; 0 where none
 * lies there. Where the positions lie over the grid (all but the pieces of a path in the periodic
 * box) and [lo, hi] is every cell, the cells of cell_of. */
static inline int cells_within(const Paths *pp, double a, double b, int64_t lo, int64_t hi, int64_t *u0,
                               int64_t *u1)
{
    double ka = (a - pp->pl.x0) * pp->pl.inv_h, kb = (b - pp->pl.x0) * pp->pl.inv_h;
    *u0 = ka > (double)lo ? (ka < (double)(hi + 1) ? (int64_t)ka : hi + 1) : lo;
    *u1 = kb < (double)hi ? (kb >= (double)lo ? (int64_t)kb : lo - 1) : hi;
    return *u0 <= *u1;
}

/* 1 / v, or 0 when v is 0 or so small that 1 / v overflows (the disk then moves less than a
 * rounding unit of the box in a step, far inside the margins, and is binned as at rest). */
static inline double inverse(double v)
{
    double iv = v != 0 ? 1 / v : 0;
    return isinf(iv) ? 0 : iv;
}

/* The times at which a centre at c with 1 / v = iv enters and leaves cell 0 of an axis, grown by G
 * (*ea, *eb), and how both move from one cell to the next (*dt): cell k is visited during
 * [ea + k dt, eb + k dt]. A centre at rest on the axis (iv = 0) is in every cell it is in at all
 * times: (-inf, +inf). */
static inline void crossing(const Paths *pp, double c, double iv, double *ea, double *eb, double *dt)
{
    double lo = (pp->pl.x0 - pp->pl.grow - c) * iv, hi = (pp->pl.x0 + pp->pl.h + pp->pl.grow - c) * iv;
    *ea = iv > 0 ? lo : (iv < 0 ? hi : -INFINITY);
    *eb = iv > 0 ? hi : (iv < 0 ? lo : INFINITY);
    *dt = pp->pl.h * iv;
}

/* The cells of a short path, whose grown bounding box spans cells [c0[k], c1[k]] on axis k, at most
 * BOX_CELLS of them: each cell of the box with the intersection of the intervals the centre spends
 * in its column and its row, kept where that is not empty. One loop and no branch on the geometry:
 * the loops of path_lines end after one or two turns where cells are about as wide as the path is
 * long, and a processor mispredicts each of those exits, which costs more than a few empty cells. */
#define BOX_CELLS 16

/* Cell (i, j) of a box as path_box stores it in *x: the intersection of the intervals the centre
 * spends in its column and its row, cut to [0, T], and its key; whether that is not empty. */
static inline int box_cell(const Paths *pp, Entry *x, double T, int64_t i, int64_t j, const double *ea,
                           const double *eb, const double *dt)
{
    double zero = 0 * T; /* 0 (T is finite); a constant 0 would make the compiler branch on t0 > 0 */
    int32_t last = pp->pl.bins - 1;
    double a0 = ea[0] + (double)i * dt[0], a1 = eb[0] + (double)i * dt[0];
    double b0 = ea[1] + (double)j * dt[1], b1 = eb[1] + (double)j * dt[1];
    double t0 = a0 > b0 ? a0 : b0, t1 = a1 < b1 ? a1 : b1;
    t0 = t0 > zero ? t0 : zero;
    t1 = t1 < T ? t1 : T;
    /* where t0 > t1 the cell is empty and its entry is written over: its stored t0 only has to be
     * in range for its bin */
    double s0 = t0 < T ? t0 : T;
    x->t0 = (float)s0 - T_PAD;
    x->t1 = (float)t1 + T_PAD;
    int32_t bin = (int32_t)(x->t0 * (float)pp->pl.bins); /* t0 >= -T_PAD: truncates to 0 or more */
    x->key = (pp->in_tile[j] * (int32_t)pp->pl.tc + pp->in_tile[i]) * pp->pl.bins + (bin < last ? bin : last);
    return t0 <= t1;
}

/* Every entry is stored and the bucket's length grows by whether it counts: no branch. Where the box
 * lies in one tile (most boxes), that length stays in a register; else it goes through each cell's
 * bucket in memory, and each cell waits for the previous one's store. */
static SIM_INLINE void path_box(const Paths *pp, Entry x, double T, const int64_t *c0, const int64_t *c1,
                     const double *ea, const double *eb, const double *dt, Bucket *bk)
{
    int64_t gt = pp->pl.gt, m = (c1[0] - c0[0] + 1) * (c1[1] - c0[1] + 1);
    int64_t i = c0[0], j = c0[1];
    if (pp->tile_of[c0[0]] == pp->tile_of[c1[0]] && pp->tile_of[c0[1]] == pp->tile_of[c1[1]]) {
        Bucket *q = bk + (size_t)pp->tile_of[j] * (size_t)gt + (size_t)pp->tile_of[i];
        if (q->len + (size_t)m > q->cap) q->e = sim_grow(q->e, &q->cap, q->len + (size_t)m, sizeof *q->e);
        Entry *e = q->e;
        size_t len = q->len;
        for (int64_t k = 0; k < m; k++) {
            int in = box_cell(pp, &x, T, i, j, ea, eb, dt);
            e[len] = x;
            len += in;
            int wrap = i == c1[0];
            i = wrap ? c0[0] : i + 1;
            j += wrap;
        }
        q->len = len;
        return;
    }
    for (int64_t k = 0; k < m; k++) {
        int in = box_cell(pp, &x, T, i, j, ea, eb, dt);
        Bucket *q = bk + (size_t)pp->tile_of[j] * (size_t)gt + (size_t)pp->tile_of[i];
        if (q->len == q->cap) q->e = sim_grow(q->e, &q->cap, q->len + 1, sizeof *q->e);
        q->e[q->len] = x;
        q->len += in;
        int wrap = i == c1[0];
        i = wrap ? c0[0] : i + 1;
        j += wrap;
    }
}

/* The cells of a longer path: the outer loop runs over the lines of cells across the path's shorter
 * axis o, the inner one along each line: the fewer lines, the fewer loop exits, which a processor
 * mispredicts about once per line. With clip (a piece of a path in the periodic box) a line's cells
 * are cut to the piece's [c0, c1], and a line with none there is skipped; else they are those of its
 * positions, which lie over the grid. The times at which the centre crosses the grown edges of
 * consecutive cells step by h / v: each entry is a few additions, a minimum and a maximum. (The
 * steps add rounding errors of about g units of the box's, far inside the margin.) */
static SIM_INLINE void path_lines(const Paths *pp, Entry x, double T, const double *c, const double *v,
                       const int64_t *c0, const int64_t *c1, const double *ea, const double *eb,
                       const double *dt, int clip, Bucket *bk)
{
    double G = pp->pl.grow;
    float bins = (float)pp->pl.bins;
    int32_t last = pp->pl.bins - 1;
    int o = fabs(v[1]) <= fabs(v[0]), in = 1 - o; /* outer axis: 1 (rows) or 0 (columns) */
    int64_t tc = pp->pl.tc;
    int32_t si = o ? 1 : (int32_t)tc;                 /* stride of the inner axis in a tile's cells */
    int64_t so = o ? tc : 1;
    int64_t to = o ? pp->pl.gt : 1, ti = o ? 1 : pp->pl.gt; /* strides of the tile index */
    for (int64_t l = c0[o]; l <= c1[o]; l++) {
        double ta = ea[o] + (double)l * dt[o], tb = eb[o] + (double)l * dt[o];
        ta = ta > 0 ? ta : 0;
        tb = tb < T ? tb : T;
        if (ta > tb) continue;
        double ia = c[in] + v[in] * ta, ib = c[in] + v[in] * tb;
        int64_t u0, u1;
        if (!clip) {
            u0 = cell_of(pp, (ia < ib ? ia : ib) - G);
            u1 = cell_of(pp, (ia < ib ? ib : ia) + G);
        } else if (!cells_within(pp, (ia < ib ? ia : ib) - G, (ia < ib ? ib : ia) + G, c0[in], c1[in], &u0, &u1)) {
            continue;
        }
        Bucket *line = bk + (size_t)pp->tile_of[l] * (size_t)to;
        int64_t lpart = (int64_t)pp->in_tile[l] * so;
        double ua = ea[in] + (double)u0 * dt[in], ub = eb[in] + (double)u0 * dt[in];
        while (u0 <= u1) { /* a piece of the line within one tile */
            int64_t end = ((int64_t)pp->tile_of[u0] + 1) * tc - 1;
            if (end > u1) end = u1;
            Bucket *q = line + (size_t)pp->tile_of[u0] * (size_t)ti;
            size_t cnt = (size_t)(end - u0 + 1);
            if (q->len + cnt > q->cap) q->e = sim_grow(q->e, &q->cap, q->len + cnt, sizeof *q->e);
            Entry *e = q->e + q->len;
            int32_t key = (int32_t)(lpart + (int64_t)pp->in_tile[u0] * si) * pp->pl.bins;
            for (size_t k = 0; k < cnt; k++) {
                double sa = ua > ta ? ua : ta, sb = ub < tb ? ub : tb;
                x.t0 = (float)sa - T_PAD;
                x.t1 = (float)sb + T_PAD;
                int32_t bin = (int32_t)(x.t0 * bins); /* t0 >= -T_PAD: truncates to 0 or more */
                x.key = key + (bin < last ? bin : last);
                e[k] = x;
                key += si * pp->pl.bins;
                ua += dt[in];
                ub += dt[in];
            }
            q->len += cnt;
            u0 = end + 1;
        }
    }
}

#ifdef SIM_SSE2
/* path_cells' set-up of both axes at once, lane k axis k: each operation the portable loop's there
 * (inverse, cell_of, crossing), in the same order, so every value is the same. One division and one
 * chain of dependent operations for the two axes, where the loop ran two (REPORT.md 3.3: an eighth
 * off the sample's binning). */
static void path_setup(const Paths *pp, const double *c, double *v, double T, int64_t *c0, int64_t *c1,
                       double *ea, double *eb, double *dt)
{
    __m128d cv = _mm_loadu_pd(c), vv = _mm_loadu_pd(v), zero = _mm_setzero_pd();
    __m128d inf = _mm_set1_pd(INFINITY), sign = _mm_set1_pd(-0.0), G = _mm_set1_pd(pp->pl.grow);
    __m128d iv = _mm_div_pd(_mm_set1_pd(1), vv);
    __m128d finite = _mm_cmplt_pd(_mm_andnot_pd(sign, iv), inf);
    iv = _mm_and_pd(iv, finite); /* inverse(): 0 where 1 / v is infinite, and then v is 0 too */
    vv = _mm_and_pd(vv, finite);
    _mm_storeu_pd(v, vv);
    __m128d e = _mm_add_pd(cv, _mm_mul_pd(vv, _mm_set1_pd(T)));
    __m128d x0 = _mm_set1_pd(pp->pl.x0), inv_h = _mm_set1_pd(pp->pl.inv_h), last = _mm_set1_pd(pp->pl.last);
    __m128d klo = _mm_mul_pd(_mm_sub_pd(_mm_sub_pd(_mm_min_pd(cv, e), G), x0), inv_h);
    __m128d khi = _mm_mul_pd(_mm_sub_pd(_mm_add_pd(_mm_max_pd(cv, e), G), x0), inv_h);
    __m128i ilo = _mm_cvttpd_epi32(_mm_min_pd(_mm_max_pd(klo, zero), last));
    __m128i ihi = _mm_cvttpd_epi32(_mm_min_pd(_mm_max_pd(khi, zero), last));
    c0[0] = _mm_cvtsi128_si32(ilo);
    c0[1] = _mm_cvtsi128_si32(_mm_shuffle_epi32(ilo, 1));
    c1[0] = _mm_cvtsi128_si32(ihi);
    c1[1] = _mm_cvtsi128_si32(_mm_shuffle_epi32(ihi, 1));
    __m128d lo = _mm_mul_pd(_mm_sub_pd(_mm_set1_pd(pp->pl.x0 - pp->pl.grow), cv), iv);
    __m128d hi = _mm_mul_pd(_mm_sub_pd(_mm_set1_pd(pp->pl.x0 + pp->pl.h + pp->pl.grow), cv), iv);
    __m128d pos = _mm_cmpgt_pd(iv, zero), neg = _mm_cmplt_pd(iv, zero);
    _mm_storeu_pd(ea, select_pd(pos, lo, select_pd(neg, hi, _mm_xor_pd(inf, sign))));
    _mm_storeu_pd(eb, select_pd(pos, hi, select_pd(neg, lo, inf)));
    _mm_storeu_pd(dt, _mm_mul_pd(_mm_set1_pd(pp->pl.h), iv));
}
#endif

/* The cells of one path, each with the interval of time the centre spends in it (grown by G), into
 * this thread's buckets (bk: its row of tiles). The grid's edge cells need no extension: a path
 * never leaves [lo, hi] by more than a few rounding units (it ends at the wall), and G exceeds r by
 * far more. */
static void path_cells_periodic(const Paths *pp, const Body *b, int32_t slot, Bucket *bk);

/* Whether a path of the periodic box, grown by G, lies inside [0, L)^2: binned as a walled box's. */
static inline int path_inside(const Paths *pp, const Body *b)
{
    double G = pp->pl.grow, L = pp->pl.L, T = b->cap;
    double ex = (double)b->x + (double)b->vx * T, ey = (double)b->y + (double)b->vy * T;
    double xl = b->x < ex ? b->x : ex, xh = b->x < ex ? ex : b->x;
    double yl = b->y < ey ? b->y : ey, yh = b->y < ey ? ey : b->y;
    return xl - G > 0 && xh + G < L && yl - G > 0 && yh + G < L;
}

static void path_cells(const Paths *pp, const Body *b, int32_t slot, Bucket *bk)
{
    if (pp->pl.periodic && !path_inside(pp, b)) { /* most paths are inside */
        path_cells_periodic(pp, b, slot, bk);
        return;
    }
    double T = b->cap;
    Entry x = {0, 0, 0, slot, (float)b->x, (float)b->y, (float)b->vx, (float)b->vy};
    double c[2] = {b->x, b->y}, v[2] = {b->vx, b->vy}, ea[2], eb[2], dt[2];
    int64_t c0[2], c1[2];
#ifdef SIM_SSE2
    path_setup(pp, c, v, T, c0, c1, ea, eb, dt);
#else
    double G = pp->pl.grow;
    for (int k = 0; k < 2; k++) {
        double iv = inverse(v[k]);
        if (iv == 0) v[k] = 0;
        double e = c[k] + v[k] * T;
        c0[k] = cell_of(pp, (c[k] < e ? c[k] : e) - G);
        c1[k] = cell_of(pp, (c[k] < e ? e : c[k]) + G);
        crossing(pp, c[k], iv, &ea[k], &eb[k], &dt[k]);
    }
#endif
    if ((c1[0] - c0[0] + 1) * (c1[1] - c0[1] + 1) <= BOX_CELLS) path_box(pp, x, T, c0, c1, ea, eb, dt, bk);
    else path_lines(pp, x, T, c, v, c0, c1, ea, eb, dt, 0, bk);
}

/* The first image (the multiple of L) of the cells [lo, hi] counted on from the grid's, and the last:
 * at most two apart (paths_fit_periodic). */
static inline int64_t image_of(int64_t k, int64_t g)
{
    return k >= 0 ? k / g : -((-k + g - 1) / g);
}

/* path_cells in the periodic box (SPEC.md 7), where a path runs over the edges: its cells (grown by
 * G) counted on from the grid's past them, at most g an axis (paths_fit_periodic), and each piece of
 * them that lies in one image of the box binned as the path of the disk's image there: its centre
 * shifted by that multiple of L, in the entries' float state too, so that the screens see the images
 * that meet in a cell. The pieces' cells are distinct cells of the grid: a pair of disks shares at most
 * one visit of each cell. */
static void path_cells_periodic(const Paths *pp, const Body *b, int32_t slot, Bucket *bk)
{
    double T = b->cap, L = pp->pl.L, G = pp->pl.grow;
    double c[2] = {b->x, b->y}, v[2] = {b->vx, b->vy}, iv[2];
    int64_t g = pp->pl.g, lo[2], hi[2];
    for (int k = 0; k < 2; k++) {
        iv[k] = inverse(v[k]);
        if (iv[k] == 0) v[k] = 0;
        double e = c[k] + v[k] * T;
        lo[k] = (int64_t)floor(((c[k] < e ? c[k] : e) - G - pp->pl.x0) * pp->pl.inv_h);
        hi[k] = (int64_t)floor(((c[k] < e ? e : c[k]) + G - pp->pl.x0) * pp->pl.inv_h);
    }
    for (int64_t sy = image_of(lo[1], g); sy <= image_of(hi[1], g); sy++)
        for (int64_t sx = image_of(lo[0], g); sx <= image_of(hi[0], g); sx++) {
            int64_t s[2] = {sx, sy}, c0[2], c1[2];
            double cs[2], ea[2], eb[2], dt[2];
            for (int k = 0; k < 2; k++) {
                cs[k] = c[k] - (double)s[k] * L;
                c0[k] = lo[k] - s[k] * g > 0 ? lo[k] - s[k] * g : 0;
                c1[k] = hi[k] - s[k] * g < g - 1 ? hi[k] - s[k] * g : g - 1;
                crossing(pp, cs[k], iv[k], &ea[k], &eb[k], &dt[k]);
            }
            Entry x = {0, 0, 0, slot, (float)cs[0], (float)cs[1], (float)b->vx, (float)b->vy};
            if ((c1[0] - c0[0] + 1) * (c1[1] - c0[1] + 1) <= BOX_CELLS) path_box(pp, x, T, c0, c1, ea, eb, dt, bk);
            else path_lines(pp, x, T, cs, v, c0, c1, ea, eb, dt, 1, bk);
        }
}

/* The record of the disk in slot q that the exact tests read, whose wall event time is wt (-1: none). */
static inline void body_of(const Slots *s, int64_t q, real wt, Body *b)
{
    b->x = s->x[q];
    b->y = s->y[q];
    b->vx = s->vx[q];
    b->vy = s->vy[q];
    b->wt = wt < 0 ? (real)INFINITY : wt;
    b->cap = wt < 0 ? 1 : wt;
    b->id = s->id[q];
}

static void test_pair(const Body *A, const Body *B, int32_t qa, int32_t qb, const Params *p,
                      Found *mine);

/* The slow grid's cells [*u0, *u1] along an axis of positions [a, b] (a <= b), cut to the grid; 0
 * where none lies in it (only a piece of a path in the periodic box misses it). */
static inline int slow_cells(const SlowGrid *slow, double a, double b, int64_t *u0, int64_t *u1)
{
    double ka = (a - slow->x0) * slow->inv_h, kb = (b - slow->x0) * slow->inv_h, gl = (double)(slow->g - 1);
    *u0 = ka > 0 ? (ka < gl + 1 ? (int64_t)ka : slow->g) : 0;
    *u1 = kb < gl ? (kb >= 0 ? (int64_t)kb : -1) : slow->g - 1;
    return *u0 <= *u1;
}

/* A fast disk of a mixed step against the slow disks: its path is rasterised across the slow disks'
 * grid in lines of cells (cutting it across its shorter axis or, see keep below, its longer), with
 * its cells grown by the half-size of a slow box besides the paths' G (slow->reach), so that it
 * visits the cell of every slow box it can meet. In each line, the boxes of the line's run of cells
 * (together in cell order along a row; cell by cell along a column) are tested against the box of
 * the path during the line's interval of time (grown by the paths' G); survivors go through the
 * filter of meet and the exact test. Each slow box lies in one cell, which a straight path visits
 * once: each pair is tested once.
 *
 * With keep k > 0 the lines cut the path across its longer axis, taken in the order it crosses them,
 * and the walk stops at the first line that can hold no event among the k + 1 earliest: an event
 * with a disk of line l is at a time when the fast centre is within reach of l's band, so not before
 * l's entry time ta, less the graze's error in pair_time (SPEC.md 3.2), which a whole cell plus the
 * reach covers with room to spare. Once k + 1 events lie before that, every event left is later
 * than all of them: keep_first keeps the same k and notes the same trim as after the whole path. A
 * fast disk meets a gas's disks every few radii, so its first k lie within a few of the dozens of
 * lines of a step. */
static void fast_slow(const Paths *pp, const Body *A, int32_t qa, const double *c, const Slots *s,
                      const real *wall_t, const SlowGrid *slow, const Params *p, Found *mine)
{
    int64_t g = slow->g;
    double x0 = slow->x0, k = slow->inv_h, h = 1 / slow->inv_h, Gs = slow->reach;
    double Gf = pp->pl.grow, T = (double)A->cap;
    double v[2] = {(double)A->vx, (double)A->vy}, iv[2];
    for (int u = 0; u < 2; u++) {
        iv[u] = inverse(v[u]);
        if (iv[u] == 0) v[u] = 0;
    }
    /* the outer axis, 1 (rows) or 0 (columns): the longer one where the walk may stop early; else
     * the shorter, whose fewer and longer lines cost less to set up (with --keep 0, 1e5 disks 1%
     * fast, binning 0.085 s against 0.103 s on one thread) */
    int keep = slow->keep, o = keep > 0 ? fabs(v[1]) > fabs(v[0]) : fabs(v[1]) <= fabs(v[0]);
    int in = 1 - o;
    int64_t so = o ? g : 1, si = o ? 1 : g; /* strides of the cell index */
    double ob = c[o] + v[o] * T;
    int64_t l0, l1;
    if (!slow_cells(slow, (c[o] < ob ? c[o] : ob) - Gs, (c[o] < ob ? ob : c[o]) + Gs, &l0, &l1)) return;
    int64_t step = v[o] < 0 ? -1 : 1, n_lines = l1 - l0 + 1;
    /* soon: the k + 1 earliest event times so far, ascending; early: how much before a line's ta
     * they must all lie for the walk to stop there */
    int nb = 0;
    if (iv[o] == 0) keep = 0;
    double soon[SIM_KEEP_MOST + 1], early = (h + Gs) * fabs(iv[o]);
    size_t seen = mine->len;
    for (int64_t n = 0; n < n_lines; n++) {
        int64_t l = step > 0 ? l0 + n : l1 - n;
        double ta = 0, tb = T;
        if (iv[o] != 0) {
            double e0 = (x0 + (double)l * h - Gs - c[o]) * iv[o];
            double e1 = (x0 + (double)(l + 1) * h + Gs - c[o]) * iv[o];
            double lo = e0 < e1 ? e0 : e1, hi = e0 < e1 ? e1 : e0;
            ta = lo > 0 ? lo : 0;
            tb = hi < T ? hi : T;
            if (keep > 0) {
                for (; seen < mine->len; seen++) {
                    double t = (double)mine->ev[seen].t;
                    if (nb == keep + 1 && !(t < soon[keep])) continue;
                    int u = nb < keep + 1 ? nb++ : keep;
                    for (; u > 0 && t < soon[u - 1]; u--) soon[u] = soon[u - 1];
                    soon[u] = t;
                }
                if (nb == keep + 1 && soon[keep] < ta - early) return;
            }
            if (ta > tb) continue;
        }
        double ia = c[in] + v[in] * ta, ib = c[in] + v[in] * tb;
        double oa = c[o] + v[o] * ta, oc = c[o] + v[o] * tb;
        double il = ia < ib ? ia : ib, ih = ia < ib ? ib : ia;
        double ol = oa < oc ? oa : oc, oh = oa < oc ? oc : oa;
        int64_t m0, m1;
        if (!slow_cells(slow, il - Gs, ih + Gs, &m0, &m1)) continue;
        float bil = (float)((il - Gf - x0) * k), bih = (float)((ih + Gf - x0) * k);
        float bol = (float)((ol - Gf - x0) * k), boh = (float)((oh + Gf - x0) * k);
        Box vb = box_of(o ? bil : bol, o ? bih : boh, o ? bol : bil, o ? boh : bih);
        /* along a row the run's boxes lie together; along a column, cell by cell */
        int64_t runs = o ? 1 : m1 - m0 + 1, len = o ? m1 - m0 + 1 : 1;
        for (int64_t u = 0; u < runs; u++) {
            int64_t first = l * so + (m0 + u) * si;
            int32_t b1 = slow->cell_start[first + len];
            for (int32_t b = slow->cell_start[first]; b < b1; b++) {
                if (!boxes_overlap(&vb, &slow->boxes[b])) continue;
                int32_t q = slow->box_slot[b];
                double dx = (double)s->x[q] - c[0], dy = (double)s->y[q] - c[1];
                if (p->periodic) /* by the nearest image (SPEC.md 7): c is the image of this piece */
                    dx = wrap_near((double)s->x[q] - (double)A->x, p->L),
                    dy = wrap_near((double)s->y[q] - (double)A->y, p->L);
                double dvx = (double)s->vx[q] - (double)A->vx, dvy = (double)s->vy[q] - (double)A->vy;
                double bb = dx * dvx + dy * dvy, a = dvx * dvx + dvy * dvy, cr = dx * dvy - dy * dvx;
                if ((bb < 0) & (cr * cr <= pp->pl.reach2 * a)) {
                    Body B;
                    body_of(s, q, wall_t[q], &B);
                    test_pair(A, &B, qa, q, p, mine);
                }
            }
        }
    }
}

/* Keeps the k smallest by key of the pair events mine->ev[from ..] (all of the fast disk in slot q,
 * more than k of them) and notes the smallest left out as q's trim (SlowGrid's keep). The keys are
 * distinct (the pairs are); the k + 1 smallest are kept sorted on the way, so that most events cost
 * one comparison. */
static void keep_first(Found *mine, size_t from, int k, int32_t q)
{
    PairEvent best[SIM_KEEP_MOST + 1];
    int nb = 0;
    for (size_t e = from; e < mine->len; e++) {
        const PairEvent *x = &mine->ev[e];
        if (nb == k + 1 && !event_before(x->t, 1, x->i, x->j, best[k].t, 1, best[k].i, best[k].j))
            continue;
        int u = nb < k + 1 ? nb++ : k;
        while (u > 0 && event_before(x->t, 1, x->i, x->j, best[u - 1].t, 1, best[u - 1].i, best[u - 1].j)) {
            best[u] = best[u - 1];
            u--;
        }
        best[u] = *x;
    }
    memcpy(mine->ev + from, best, (size_t)k * sizeof *best);
    mine->len = from + (size_t)k;
    if (mine->trim_len == mine->trim_cap)
        mine->trim = sim_grow(mine->trim, &mine->trim_cap, mine->trim_len + 1, sizeof *mine->trim);
    PairEvent c = best[k];
    c.a = q;
    mine->trim[mine->trim_len++] = c;
    mine->trimmed++;
}

/* The fast disk A in slot q against the slow disks, its events beyond the first keep trimmed. In the
 * periodic box its path, grown by the slow reach, may run over the edges: each piece of it in one
 * image of the box walks the grid as the path of the disk's image there (path_cells_periodic), each
 * slow cell once (paths_fit_periodic). */
static void fast_slow_kept(const Paths *pp, const Body *A, int32_t q, const Slots *s, const real *wall_t,
                           const SlowGrid *slow, const Params *p, Found *mine)
{
    size_t from = mine->len;
    double c[2] = {(double)A->x, (double)A->y};
    if (!p->periodic) {
        fast_slow(pp, A, q, c, s, wall_t, slow, p, mine);
    } else {
        double v[2] = {(double)A->vx, (double)A->vy}, L = p->L;
        int64_t g = slow->g, lo[2], hi[2];
        for (int k = 0; k < 2; k++) {
            double e = c[k] + (inverse(v[k]) == 0 ? 0 : v[k]) * (double)A->cap;
            lo[k] = (int64_t)floor(((c[k] < e ? c[k] : e) - slow->reach - slow->x0) * slow->inv_h);
            hi[k] = (int64_t)floor(((c[k] < e ? e : c[k]) + slow->reach - slow->x0) * slow->inv_h);
        }
        for (int64_t sy = image_of(lo[1], g); sy <= image_of(hi[1], g); sy++)
            for (int64_t sx = image_of(lo[0], g); sx <= image_of(hi[0], g); sx++) {
                double cs[2] = {c[0] - (double)sx * L, c[1] - (double)sy * L};
                fast_slow(pp, A, q, cs, s, wall_t, slow, p, mine);
            }
    }
    if (slow->keep > 0 && mine->len - from > (size_t)slow->keep) keep_first(mine, from, slow->keep, q);
}

/* Phase A (paths_bin) for this thread's disks: those of its range of slots (slow = NULL), their wall
 * events found on the way, or those of its list of fast slots, each first against the slow disks. A
 * disk whose wall event is at t = 0 has no pair event that can be accepted: no path. */
void paths_bin(Paths *pp, const Slots *s, const Params *p, real *wall_t, const SlowGrid *slow,
               const int32_t *fast, int64_t n_fast, Found *mine, int tid, int nt)
{
    Bucket *bk = pp->bk + (size_t)tid * (size_t)pp->pl.tiles;
    for (int64_t k = 0; k < pp->pl.tiles; k++) bk[k].len = 0;
    if (!slow) {
        int64_t n = p->n, from = n * tid / nt, to = n * (tid + 1) / nt;
        for (int64_t q = from; q < to; q++) {
            real wt = slot_wall_time(s, p, q);
            wall_t[q] = wt;
            if (wt >= 0) found_wall(mine, wt, (int32_t)q);
            Body b;
            body_of(s, q, wt, &b);
            if (b.cap > 0) path_cells(pp, &b, (int32_t)q, bk);
        }
    } else {
        mine->slow_from = mine->len;
        for (int64_t k = 0; k < n_fast; k++) {
            int32_t q = fast[k];
            Body b;
            body_of(s, q, wall_t[q], &b);
            if (b.cap > 0) {
                fast_slow_kept(pp, &b, q, s, wall_t, slow, p, mine);
                path_cells(pp, &b, q, bk);
            }
        }
        mine->slow_to = mine->len;
    }
    for (int64_t k = 0; k < pp->pl.tiles; k++) mine->visits += bk[k].len;
}

void paths_refind(const Paths *pp, const Slots *s, const Params *p, const real *wall_t,
                  const SlowGrid *slow, const int32_t *fast, int64_t n_fast, Found *mine)
{
    /* the events after the range (the fast disks' with each other) move down over it, and the new
     * range follows them: the choice reads a thread's events in any order */
    size_t rest = mine->len - mine->slow_to;
    memmove(mine->ev + mine->slow_from, mine->ev + mine->slow_to, rest * sizeof *mine->ev);
    mine->len = mine->slow_from + rest;
    mine->slow_from = mine->len;
    mine->trim_len = 0;
    for (int64_t k = 0; k < n_fast; k++) {
        int32_t q = fast[k];
        Body b;
        body_of(s, q, wall_t[q], &b);
        if (b.cap > 0) fast_slow_kept(pp, &b, q, s, wall_t, slow, p, mine);
    }
    mine->slow_to = mine->len;
}

/* ==== phase B: the tiles ============================================================================= */

/* A tile's visits in cell order (Scratch), as the pairing reads them, and where the survivors of its
 * screens find their disks in full. */
struct Visits {
    const float *t0, *t1, *x, *y, *vx, *vy;
    const int32_t *slot;
    const Slots *s;
    const real *wall_t;
};

/* A pair that passed the filter: its time of closest approach within [0, tm] and the cell of its
 * midpoint then, and in that cell alone the exact test with the lower original index first. */
static void meet_near(const Paths *pp, const Body *A, const Body *B, int32_t qa, int32_t qb,
                      int64_t cx, int64_t cy, const Params *p, Found *mine)
{
    /* dx, dvx, b, a and tau: the same bits whichever disk is A (the differences negate exactly) */
    double dx = (double)B->x - (double)A->x, dy = (double)B->y - (double)A->y;
    double dvx = (double)B->vx - (double)A->vx, dvy = (double)B->vy - (double)A->vy;
    double b = dx * dvx + dy * dvy, a = dvx * dvx + dvy * dvy;
    double tm = A->cap < B->cap ? (double)A->cap : (double)B->cap;
    double tau = -b > a * tm ? tm : -b / a;
    double mx = ((double)A->x + (double)A->vx * tau + ((double)B->x + (double)B->vx * tau)) * 0.5;
    double my = ((double)A->y + (double)A->vy * tau + ((double)B->y + (double)B->vy * tau)) * 0.5;
    if (cell_of(pp, mx) != cx || cell_of(pp, my) != cy) return;
    test_pair(A, B, qa, qb, p, mine);
}

/* meet_near in the periodic box (SPEC.md 7): the differences by the nearest image, and the midpoint
 * taken from the disk of lower original index towards the other's nearest image and brought into
 * [0, L): a function of the pair alone, whichever disk is A, so that it names one cell, whose visits
 * of both disks (one each: path_cells_periodic) meet at tau. */
static void meet_near_periodic(const Paths *pp, const Body *A, const Body *B, int32_t qa, int32_t qb,
                               int64_t cx, int64_t cy, const Params *p, Found *mine)
{
    const Body *P = A->id < B->id ? A : B, *Q = P == A ? B : A;
    double L = p->L;
    double dx = wrap_near((double)Q->x - (double)P->x, L), dy = wrap_near((double)Q->y - (double)P->y, L);
    double dvx = (double)Q->vx - (double)P->vx, dvy = (double)Q->vy - (double)P->vy;
    double b = dx * dvx + dy * dvy, a = dvx * dvx + dvy * dvy;
    double tau = -b > a ? 1 : -b / a; /* within [0, 1]: no wall ends a path */
    double mx = (double)P->x + (double)P->vx * tau + (dx + dvx * tau) * 0.5;
    double my = (double)P->y + (double)P->vy * tau + (dy + dvy * tau) * 0.5;
    mx = mx - floor(mx / L) * L;
    my = my - floor(my / L) * L;
    if (cell_of(pp, mx) != cx || cell_of(pp, my) != cy) return;
    test_pair(A, B, qa, qb, p, mine);
}

/* The exact test of SPEC.md 3.2 (7 in the periodic box), the lower original index first, and the
 * event if the choice can accept it. */
static void test_pair(const Body *A, const Body *B, int32_t qa, int32_t qb, const Params *p,
                      Found *mine)
{
    if (B->id < A->id) {
        const Body *t = A;
        A = B;
        B = t;
        int32_t u = qa;
        qa = qb;
        qb = u;
    }
    mine->tests++;
    real t = p->periodic ? pair_time_wrap(A->x, A->y, A->vx, A->vy, B->x, B->y, B->vx, B->vy, p->sigma2, p->L,
                                          p->half, 1)
                         : pair_time(A->x, A->y, A->vx, A->vy, B->x, B->y, B->vx, B->vy, p->sigma2);
    if (t >= 0 && t < A->wt && t < B->wt) found_push(mine, t, A->id, B->id, qa, qb);
}

/* Two disks in cell (cx, cy) at overlapping times. The filter: they approach (b < 0, as in
 * pair_time), and the lines they move on come within 2 G_TEST of each other: the squared distance
 * of closest approach is cr^2 / a, cr = dx dvy - dy dvx (by Lagrange's identity, without the
 * cancellation of dd - b^2 / a). Whether that closest approach comes within the step is left to
 * meet_near: few pairs get that far. No branch until then: the outcome is a coin toss to a
 * processor. */
static inline void meet(const Paths *pp, const Body *A, const Body *B, int32_t qa, int32_t qb,
                        int64_t cx, int64_t cy, const Params *p, Found *mine)
{
    double dx = (double)B->x - (double)A->x, dy = (double)B->y - (double)A->y;
    if (pp->pl.periodic) dx = wrap_near(dx, pp->pl.L), dy = wrap_near(dy, pp->pl.L);
    double dvx = (double)B->vx - (double)A->vx, dvy = (double)B->vy - (double)A->vy;
    double b = dx * dvx + dy * dvy, a = dvx * dvx + dvy * dvy, cr = dx * dvy - dy * dvx;
    if (!((b < 0) & (cr * cr <= pp->pl.reach2 * a))) return;
    if (pp->pl.periodic) meet_near_periodic(pp, A, B, qa, qb, cx, cy, p, mine);
    else meet_near(pp, A, B, qa, qb, cx, cy, p, mine);
}

/* Whether the visits [lo, hi) of a cell are sorted by entry time and swept (cell_pairs), rather than
 * paired all: tile_sweep sorts exactly these cells. */
static inline int cell_swept(int32_t lo, int32_t hi)
{
    return hi - lo > CELL_FEW;
}

/* Sorts the items [lo, hi) of a cell by entry time. They arrive nearly sorted (counted into bins of
 * entry time), so insertion moves few of them, by a place or two. */
static void sort_cell(Item *it, int32_t lo, int32_t hi)
{
    for (int32_t k = lo + 1; k < hi; k++) {
        Item x = it[k];
        if (!(x.t0 < it[k - 1].t0)) continue;
        int32_t u = k;
        do {
            it[u] = it[u - 1];
            u--;
        } while (u > lo && x.t0 < it[u - 1].t0);
        it[u] = x;
    }
}

/* ---- the widths of phase B's screens (omp_lanes.h) -------------------------------------------- */

#define LANES_MAX 16 /* the widest screen: the spare entries past a tile's visits that it reads */

#define LW 1
#define LN(name) name##_1
#define LATTR
#define LV float
#define LV_LOAD(p) (*(p))
#define LV_SET(x) (x)
#define LV_SUB(a, b) ((a) - (b))
#define LV_MUL(a, b) ((a) * (b))
#define LV_ADD(a, b) ((a) + (b))
#define LV_LE(a, b) ((unsigned)((a) <= (b)))
#define LRUN(m) (m)
#define LCOUNT(m) (m)
#define LPROBES 1
#include "omp_lanes.h"

#ifdef SIM_SSE2
/* How many of the low bits of a 4-bit mask are set in a row, and how many are set. */
static const unsigned char low_ones[16] = {0, 1, 0, 2, 0, 1, 0, 3, 0, 1, 0, 2, 0, 1, 0, 4};
static const unsigned char bits_count[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};
#define LW 4
#define LN(name) name##_4
#define LATTR
#define LV __m128
#define LV_LOAD(p) _mm_loadu_ps(p)
#define LV_SET(x) _mm_set1_ps(x)
#define LV_SUB(a, b) _mm_sub_ps(a, b)
#define LV_MUL(a, b) _mm_mul_ps(a, b)
#define LV_ADD(a, b) _mm_add_ps(a, b)
#define LV_LE(a, b) ((unsigned)_mm_movemask_ps(_mm_cmple_ps(a, b)))
#define LRUN(m) low_ones[m]
#define LCOUNT(m) bits_count[m]
#define LPROBES 1
#include "omp_lanes.h"
#endif

#ifdef LANES_AVX2
#define LW 8
#define LN(name) name##_8
#define LATTR __attribute__((target("avx2,popcnt")))
#define LV __m256
#define LV_LOAD(p) _mm256_loadu_ps(p)
#define LV_SET(x) _mm256_set1_ps(x)
#define LV_SUB(a, b) _mm256_sub_ps(a, b)
#define LV_MUL(a, b) _mm256_mul_ps(a, b)
#define LV_ADD(a, b) _mm256_add_ps(a, b)
#define LV_LE(a, b) ((unsigned)_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_LE_OQ)))
#define LRUN(m) ((unsigned)__builtin_ctz(~(m)))
#define LCOUNT(m) ((unsigned)__builtin_popcount(m))
#define LPROBES 1
#include "omp_lanes.h"
#endif

#ifdef LANES_AVX512
#define LW 16
#define LN(name) name##_16
#define LATTR __attribute__((target("avx512f,popcnt")))
#define LV __m512
#define LV_LOAD(p) _mm512_loadu_ps(p)
#define LV_SET(x) _mm512_set1_ps(x)
#define LV_SUB(a, b) _mm512_sub_ps(a, b)
#define LV_MUL(a, b) _mm512_mul_ps(a, b)
#define LV_ADD(a, b) _mm512_add_ps(a, b)
#define LV_LE(a, b) ((unsigned)_mm512_cmp_ps_mask(a, b, _CMP_LE_OQ))
#define LRUN(m) ((unsigned)__builtin_ctz(~(m)))
#define LCOUNT(m) ((unsigned)__builtin_popcount(m))
#define LPROBES 2
#include "omp_lanes.h"
#endif

/* The screens of phase B at `lanes` pairs at a time: *few for a cell's visits paired all, *many for
 * those sorted and swept (cell_swept). */
static void cell_screens(int lanes, CellFn **few, CellFn **many)
{
    (void)lanes; /* where only the one-lane screens are built */
    *few = cell_pairs_1;
    *many = cell_sweep_1;
#ifdef SIM_SSE2
    if (lanes == 4) {
        *few = cell_pairs_4;
        *many = cell_sweep_4;
    }
#endif
#ifdef LANES_AVX2
    if (lanes == 8) {
        *few = cell_pairs_8;
        *many = cell_sweep_8;
    }
#endif
#ifdef LANES_AVX512
    if (lanes == 16) {
        *few = cell_pairs_16;
        *many = cell_sweep_16;
    }
#endif
}

/* The pairs of the visits [lo, hi) of cell (cx, cy): few, each against every later one; many (sorted
 * first), each against the run of later ones that enter before it leaves; at the plan's width. */
static void cell_pairs(const Paths *pp, const Visits *v, int32_t lo, int32_t hi, int64_t cx,
                       int64_t cy, const Params *p, Found *mine)
{
    (cell_swept(lo, hi) ? pp->many : pp->few)(pp, v, lo, hi, cx, cy, p, mine);
}

static void scratch_grow(Scratch *sc, size_t need)
{
    if (need <= sc->v_cap) return;
    float **f[6] = {&sc->t0, &sc->t1, &sc->x, &sc->y, &sc->vx, &sc->vy};
    for (int k = 0; k < 6; k++) {
        size_t cap = sc->v_cap;
        *f[k] = sim_grow(*f[k], &cap, need, sizeof **f[k]);
    }
    sc->slot = sim_grow(sc->slot, &sc->v_cap, need, sizeof *sc->slot);
    sc->item = sim_grow(sc->item, &sc->item_cap, need, sizeof *sc->item);
}

/* Phase B for one tile: its entries (from every thread's bucket) counted into its cells and, within
 * a cell, into bins of entry time, placed in that order with their disks' states in float; then the
 * pairs of each cell. */
static void tile_sweep(Paths *pp, int64_t tile, int nt, const Slots *s, const real *wall_t,
                       const Params *p, Scratch *sc, Found *mine)
{
    int64_t tc = pp->pl.tc, cells = tc * tc, keys = cells * pp->pl.bins;
    sc->start = sim_grow(sc->start, &sc->start_cap, (size_t)keys + 1, sizeof *sc->start);
    int32_t *start = sc->start;
    memset(start, 0, ((size_t)keys + 1) * sizeof *start);
    size_t total = 0;
    for (int t = 0; t < nt; t++) {
        const Bucket *q = &pp->bk[(size_t)t * (size_t)pp->pl.tiles + (size_t)tile];
        for (size_t k = 0; k < q->len; k++) start[q->e[k].key + 1]++;
        total += q->len;
    }
    if (total < 2) return;
    for (int64_t c = 0; c < keys; c++) start[c + 1] += start[c];
    scratch_grow(sc, total + LANES_MAX);
    for (size_t k = total; k < total + LANES_MAX; k++) { /* spare entries: read, never paired */
        sc->t0[k] = sc->t1[k] = sc->x[k] = sc->y[k] = sc->vx[k] = sc->vy[k] = 0;
        sc->slot[k] = 0;
    }
    Item *it = sc->item;
    for (int t = 0; t < nt; t++) {
        const Bucket *q = &pp->bk[(size_t)t * (size_t)pp->pl.tiles + (size_t)tile];
        for (size_t k = 0; k < q->len; k++) {
            const Entry *e = &q->e[k];
            Item *x = &it[start[e->key]++];
            x->t0 = e->t0;
            x->e = e;
        }
    }
    /* start[key] is now the end of key, which is the start of key + 1 */
    int32_t lo = 0;
    for (int64_t c = 0; c < cells; c++) {
        int32_t hi = start[(c + 1) * pp->pl.bins - 1];
        if (cell_swept(lo, hi)) sort_cell(it, lo, hi);
        lo = hi;
    }
    for (size_t k = 0; k < total; k++) {
        const Entry *e = it[k].e;
        sc->t0[k] = e->t0;
        sc->t1[k] = e->t1;
        sc->slot[k] = e->slot;
        sc->x[k] = e->x;
        sc->y[k] = e->y;
        sc->vx[k] = e->vx;
        sc->vy[k] = e->vy;
    }
    Visits v = {sc->t0, sc->t1, sc->x, sc->y, sc->vx, sc->vy, sc->slot, s, wall_t};
    int64_t ty = tile / pp->pl.gt, tx = tile % pp->pl.gt;
    lo = 0;
    for (int64_t c = 0; c < cells; c++) {
        int32_t hi = start[(c + 1) * pp->pl.bins - 1];
        int64_t cx = tx * tc + c % tc, cy = ty * tc + c / tc;
        if (hi - lo >= 2) cell_pairs(pp, &v, lo, hi, cx, cy, p, mine);
        lo = hi;
    }
}

static int load_cmp(const void *pa, const void *pb)
{
    const int64_t *a = pa, *b = pb; /* (entries, tile): most entries first, then by tile */
    if (a[0] != b[0]) return a[0] > b[0] ? -1 : 1;
    return (a[1] > b[1]) - (a[1] < b[1]);
}

/* The tiles, those with the most entries first, so that the dynamic schedule of phase B ends with
 * small tiles and the threads finish together. Every thread computes the same order for itself. */
static const int64_t *tile_order(Paths *pp, Scratch *sc, int nt)
{
    sc->order = sim_grow(sc->order, &sc->order_cap, 2 * (size_t)pp->pl.tiles, sizeof *sc->order);
    int64_t *o = sc->order;
    for (int64_t k = 0; k < pp->pl.tiles; k++) {
        int64_t load = 0;
        for (int t = 0; t < nt; t++) load += (int64_t)pp->bk[(size_t)t * (size_t)pp->pl.tiles + (size_t)k].len;
        o[2 * k] = load;
        o[2 * k + 1] = k;
    }
    qsort(o, (size_t)pp->pl.tiles, 2 * sizeof *o, load_cmp);
    for (int64_t k = 0; k < pp->pl.tiles; k++) o[k] = o[2 * k + 1];
    return o;
}

void paths_pairs(Paths *pp, const Slots *s, const Params *p, const real *wall_t, Found *mine, int tid,
                 int nt)
{
    const int64_t *order = tile_order(pp, &pp->sc[tid], nt);
#pragma omp for schedule(dynamic, 1) nowait
    for (int64_t k = 0; k < pp->pl.tiles; k++)
        tile_sweep(pp, order[k], nt, s, wall_t, p, &pp->sc[tid], mine);
}
