/* omp_exact.c: omp's --exact engine (exact.h): seq's events, in seq's order, found among grid neighbours.
 *
 * Each step is cut into time windows [T0, T1]. At a window's start every disk's position is projected
 * to T0 by flight (x + vx * (T0 - t): for binning only, never written back) and binned into square cells
 * wider than any distance from which two disks can touch within the window: 2r + 2 * vbound * (T1 - T0)
 * plus rounding margins, where vbound bounds every velocity component during the window (wall
 * reflections keep the components' sizes; a collision that leaves one above vbound ends the window).
 * Then:
 * - in parallel: every disk's wall event and its pair events with the disks of the 3 x 3 cells around
 *   its own (each pair once, from its lower index); those with te <= T1 go into the heap;
 * - sequentially: the event loop of seq.c, processing the smallest valid event by key and predicting
 *   the changed disks again against their neighbour cells. The window ends at T1, or right after an
 *   event that leaves a velocity component above vbound or is a disk's WINDOW_EVENTS-th in the window
 *   (which bounds the rounding that the margins must cover); the next window starts there.
 * Every valid event with te <= T1 is in the heap, so the loop processes exactly seq's events in seq's
 * order, and windows never change a disk's arithmetic: the same bytes at every thread count. Only the
 * prediction at each window start and the flights at the end of a step run in parallel; the event
 * loop is sequential, since events are processed in global time order.
 */
#include "exact.h"
#include "omp_step.h"

#include <omp.h>
#include <stdio.h>
#include <string.h>

/* Relative margin for rounding of positions and times (broad_margin's rel; it covers WINDOW_EVENTS
 * events' worth of rounding of one disk, a few rounding units each). */
#ifdef SIM_FLOAT
#define REL_MARGIN 1e-4 /* ten times common.h's: 64 events of rounding per window */
#define WINDOW_EVENTS 64
#else
#define REL_MARGIN SIM_REL_MARGIN
#define WINDOW_EVENTS 4096
#endif

#define VBOUND_FACTOR 1.5 /* vbound over the fastest component at the window's start */
#define WINDOW_CHOICES 24 /* window lengths tried: the rest of the step over 1, 2, 4, ... */

/* Relative costs for choosing the window length: binning one disk, one pair prediction, the heap
 * work of one event. */
#define COST_BIN 1.0
#define COST_PAIR 1.0
#define COST_EVENT 4.0

typedef struct {
    ExactHeap buf; /* events this thread predicted at the window's start (unordered) */
    uint64_t tests;
    char pad[64];
} XThread;

typedef struct {
    ExactDisks d;
    const Params *p;
    int nt;
    int check;            /* --check: all pairs after every window (check_window) */
    XThread *th;
    ExactHeap heap;
    /* the window's grid */
    int64_t g, max_cells; /* cells per side; most cells allowed */
    double origin, inv_w; /* lower corner (both axes) and 1 / cell width */
    int32_t *cell_of;     /* n: each disk's cell */
    int32_t *cell_start;  /* max_cells + 1: first entry of each cell in members */
    int32_t *members;     /* n: disk indices in cell order */
    uint32_t *win_events; /* n: events of each disk in the window */
    double vbound;        /* bound on |vx|, |vy| within the window */
    double rate;          /* events per time unit, estimated from the last window */
    uint64_t windows;     /* for --stats: windows run, */
    double start_s, loop_s; /* seconds in their starts (parallel) and event loops (sequential) */
} XWork;

/* Width of cells from which two disks can touch within a window of length h (see the top comment).
 * The graze term is the error of pair_time's contact distance near D == 0 (omp.c plan_step). */
static double cell_width(const Params *p, double vbound, double h)
{
    double r = p->r, reach = 2 * r + 2 * vbound * h, scale = (double)p->L + 2 * vbound * h;
    double m = broad_margin(r, scale, reach, REL_MARGIN);
    return (reach + 2 * m) * (1 + REL_MARGIN);
}

static int64_t cells_per_side(const XWork *w, double width, double extent)
{
    double gd = extent / width;
    int64_t gcap = (int64_t)sqrt((double)w->max_cells);
    while (gcap > 1 && gcap * gcap > w->max_cells) gcap--;
    int64_t g = gd < (double)gcap ? (int64_t)gd : gcap;
    return g < 1 ? 1 : g;
}

/* Chooses the end of the window starting at t0 and its grid, trading the window's start-up (binning
 * and predicting every disk, in parallel) against the neighbours each event tests. */
static real plan_window(XWork *w, real t0, double vmax)
{
    const Params *p = w->p;
    double n = (double)p->n, rest = 1 - (double)t0;
    w->vbound = VBOUND_FACTOR * vmax;
    double margin = REL_MARGIN * (double)(p->L + p->r), extent = (double)(p->hi - p->lo) + 2 * margin;
    if (p->periodic) extent = (double)p->L; /* cells tiling [0, L), wrapping (periodic_cells) */
    double best = -1, h = rest;
    for (int k = 0; k < WINDOW_CHOICES; k++) {
        double hk = ldexp(rest, -k);
        int64_t g = cells_per_side(w, cell_width(p, w->vbound, hk), extent);
        double near = 9 * n / ((double)g * (double)g);
        double cost = n * (COST_BIN + COST_PAIR * near / 2) / (w->nt * hk) +
                      w->rate * (COST_EVENT + 2 * COST_PAIR * near);
        if (best < 0 || cost < best) {
            best = cost;
            h = hk;
        }
        if (w->vbound * hk < 1e-3 * (double)p->r) break; /* shorter windows no longer shrink the cells */
    }
    real t1 = h == rest ? 1 : t0 + (real)h;
    if (!(t1 > t0) || t1 > 1) t1 = 1;
    w->g = cells_per_side(w, cell_width(p, w->vbound, (double)t1 - (double)t0), extent);
    w->origin = (double)p->lo - margin;
    if (p->periodic) {
        if (w->g < 3) w->g = 1; /* a cell's neighbours along an axis are two other cells, or none */
        w->origin = 0;
    }
    w->inv_w = (double)w->g / extent;
    return t1;
}

static inline int32_t cell_coord(const XWork *w, double c)
{
    double u = (c - w->origin) * w->inv_w;
    if (!(u > 0)) return 0;
    if (u > (double)(w->g - 1)) return (int32_t)(w->g - 1);
    return (int32_t)u;
}

/* Bins the disks by their positions projected to t0: cells in parallel, a counting sort. */
static void bin_disks(XWork *w, real t0)
{
    const Sim *s = w->d.sim;
    int64_t n = w->p->n, cells = w->g * w->g;
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; i++) {
        double dt = (double)t0 - (double)w->d.t[i];
        double x = (double)s->x[i] + (double)s->vx[i] * dt, y = (double)s->y[i] + (double)s->vy[i] * dt;
        if (w->p->periodic) { /* the image in [0, L) */
            double L = (double)w->p->L;
            x = x - floor(x / L) * L;
            y = y - floor(y / L) * L;
        }
        w->cell_of[i] = cell_coord(w, y) * (int32_t)w->g + cell_coord(w, x);
    }
    memset(w->cell_start, 0, (size_t)(cells + 1) * sizeof *w->cell_start);
    for (int64_t i = 0; i < n; i++) w->cell_start[w->cell_of[i] + 1]++;
    for (int64_t c = 0; c < cells; c++) w->cell_start[c + 1] += w->cell_start[c];
    for (int64_t i = 0; i < n; i++) w->members[w->cell_start[w->cell_of[i]]++] = (int32_t)i;
    for (int64_t c = cells; c > 0; c--) w->cell_start[c] = w->cell_start[c - 1];
    w->cell_start[0] = 0;
}

static inline void buf_add(ExactHeap *b, const ExactDisks *d, real t, int64_t i, int64_t j)
{
    exact_heap_reserve(b, b->len + 1);
    ExactEvent e = {t, (int32_t)i, (int32_t)j, d->ver[i], d->ver[j]};
    b->e[b->len++] = e;
}

/* Disk i's pair events up to t1 with the members [m0, m1) of the grid, except skip, and
 * (from_lower) except those with a lower index. Into the heap, or appended to b. Returns the pair
 * predictions made. */
static uint64_t predict_members(XWork *w, int64_t i, int64_t skip, int from_lower, real t1, ExactHeap *b,
                                int32_t m0, int32_t m1)
{
    const ExactDisks *d = &w->d;
    uint64_t tests = 0;
    for (int32_t m = m0; m < m1; m++) {
        int64_t k = w->members[m];
        if (k == i || k == skip || (from_lower && k < i)) continue;
        int64_t a = k < i ? k : i, bb = k < i ? i : k;
        tests++;
        real t = exact_pair_time(d, w->p, a, bb);
        if (t < 0 || t > t1) continue;
        if (from_lower) buf_add(b, d, t, a, bb);
        else exact_heap_push(b, d, t, a, bb);
    }
    return tests;
}

/* Disk i's events up to t1: its wall event and its pair events with the disks in the 3 x 3 cells
 * around its own (in the periodic box wrapping at the edges; a grid of one cell has no others),
 * except skip, and (from_lower) except those with a lower index. Into the heap, or appended to b.
 * Returns the pair predictions made. */
static uint64_t predict_near(XWork *w, int64_t i, int64_t skip, int from_lower, real t1, ExactHeap *b)
{
    const ExactDisks *d = &w->d;
    const Params *p = w->p;
    uint64_t tests = 0;
    real t = exact_wall_time(d, p, i);
    if (t >= 0 && t <= t1) {
        if (from_lower) buf_add(b, d, t, i, i);
        else exact_heap_push(b, d, t, i, i);
    }
    int64_t g = w->g, c = w->cell_of[i], cx = c % g, cy = c / g, reach = g > 1;
    const int32_t *cs = w->cell_start;
    for (int64_t ny = cy - 1; ny <= cy + 1; ny++) {
        if (p->periodic) {
            if (ny != cy && !reach) continue;
            for (int64_t nx = cx - reach; nx <= cx + reach; nx++) {
                int64_t cell = (ny + g) % g * g + (nx + g) % g;
                tests += predict_members(w, i, skip, from_lower, t1, b, cs[cell], cs[cell + 1]);
            }
            continue;
        }
        if (ny < 0 || ny >= g) continue;
        int64_t x0 = cx > 0 ? cx - 1 : 0, x1 = cx + 1 < g ? cx + 1 : cx;
        tests += predict_members(w, i, skip, from_lower, t1, b, cs[ny * g + x0], cs[ny * g + x1 + 1]);
    }
    return tests;
}

/* One more event of disk i in this window; 1 if the window must end after it. */
static inline int window_ends(XWork *w, int64_t i)
{
    const Sim *s = w->d.sim;
    return ++w->win_events[i] >= WINDOW_EVENTS || fabs((double)s->vx[i]) > w->vbound ||
           fabs((double)s->vy[i]) > w->vbound;
}

/* --check: after a window that ended at t1, no disk or pair may have an event before t1 (or at t1,
 * when the window ran to its planned end): the grid would have missed it. All pairs, so slow. */
static void check_window(const XWork *w, real t0, real t1, int early)
{
    const ExactDisks *d = &w->d;
    const Params *p = w->p;
    for (int64_t i = 0; i < p->n; i++) {
        real t = exact_wall_time(d, p, i);
        if (t >= 0 && (t < t1 || (!early && t == t1)))
            sim_fail("--check: window [%.17g, %.17g] left the wall event of disk %lld at t = %.17g",
                    (double)t0, (double)t1, (long long)i, (double)t);
        for (int64_t j = i + 1; j < p->n; j++) {
            t = exact_pair_time(d, p, i, j);
            if (t >= 0 && (t < t1 || (!early && t == t1)))
                sim_fail("--check: window [%.17g, %.17g] missed the event of disks %lld and %lld at "
                        "t = %.17g",
                        (double)t0, (double)t1, (long long)i, (long long)j, (double)t);
        }
    }
}

/* Runs the window starting at t0; returns where it ended and sets *done when the step is over. */
static real run_window(XWork *w, real t0, int *done, RunStats *st)
{
    const Params *p = w->p;
    int64_t n = p->n;
    double vmax = 0, clock0 = sim_clock();
#pragma omp parallel for schedule(static) reduction(max : vmax)
    for (int64_t i = 0; i < n; i++) {
        double ax = fabs((double)w->d.sim->vx[i]), ay = fabs((double)w->d.sim->vy[i]);
        if (ax > vmax) vmax = ax;
        if (ay > vmax) vmax = ay;
    }
    real t1 = plan_window(w, t0, vmax);
    bin_disks(w, t0);

    /* every disk's events in the window, each pair once, in parallel */
#pragma omp parallel
    {
        XThread *th = &w->th[omp_get_thread_num()];
        th->buf.len = 0;
#pragma omp for schedule(dynamic, 256)
        for (int64_t i = 0; i < n; i++) {
            w->win_events[i] = 0;
            th->tests += predict_near(w, i, -1, 1, t1, &th->buf);
        }
    }
    size_t total = 0;
    for (int t = 0; t < w->nt; t++) total += w->th[t].buf.len;
    exact_heap_reserve(&w->heap, total);
    w->heap.len = 0;
    for (int t = 0; t < w->nt; t++) {
        if (w->th[t].buf.len)
            memcpy(w->heap.e + w->heap.len, w->th[t].buf.e, w->th[t].buf.len * sizeof *w->heap.e);
        w->heap.len += w->th[t].buf.len;
    }
    exact_heap_build(&w->heap);
    double clock1 = sim_clock();

    /* the events in key order, as seq.c processes them */
    uint64_t events = 0;
    int early = 0;
    while (w->heap.len && w->heap.e[0].t <= t1) {
        ExactEvent e;
        exact_heap_pop(&w->heap, &e);
        if (!exact_valid(&w->d, &e)) continue;
        exact_apply(&w->d, p, &e);
        events++;
        int end = window_ends(w, e.i);
        if (e.j != e.i) end |= window_ends(w, e.j);
        if (end) {
            t1 = e.t;
            early = 1;
            break;
        }
        /* as seq.c: the pair again (once) in the periodic box, where it may meet through another image */
        st->pair_tests += predict_near(w, e.i, p->periodic ? -1 : e.j, 0, t1, &w->heap);
        if (e.j != e.i) st->pair_tests += predict_near(w, e.j, e.i, 0, t1, &w->heap);
    }
    st->events += events;
    w->windows++;
    w->start_s += clock1 - clock0;
    w->loop_s += sim_clock() - clock1;
    double len = (double)t1 - (double)t0;
    if (len > 0) w->rate = 0.5 * w->rate + 0.5 * (double)events / len;
    if (w->check) check_window(w, t0, t1, early);
    *done = !early && t1 == 1;
    return t1;
}

int omp_exact_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *st)
{
    int64_t n = par->n;
    XWork w;
    memset(&w, 0, sizeof w);
    w.p = par;
    w.check = opt->check;
    w.nt = omp_get_max_threads();
    exact_alloc(&w.d, sim, par);
    w.th = sim_calloc_lines((size_t)w.nt, sizeof *w.th);
    w.max_cells = n;
    w.cell_of = sim_calloc((size_t)n, sizeof *w.cell_of);
    w.cell_start = sim_calloc((size_t)w.max_cells + 1, sizeof *w.cell_start);
    w.members = sim_calloc((size_t)n, sizeof *w.members);
    w.win_events = sim_calloc((size_t)n, sizeof *w.win_events);
    w.rate = (double)n;

    double t0 = sim_clock();
    for (int64_t step = par->first_step + 1; step <= par->steps; step++) {
        int done = 0;
        real from = 0;
        while (!done) from = run_window(&w, from, &done, st);
#pragma omp parallel for schedule(static)
        for (int64_t i = 0; i < n; i++) exact_finish(&w.d, par, i);
        if (par->print && step < par->steps) io_write_lines(out, step, sim, n, 0);
        if (io_virial_due(out, step)) io_virial(out, sim, step);
        if (io_checkpoint_due(out, step)) io_checkpoint(out, sim, step);
        io_progress(out, step);
    }
    st->seconds = sim_clock() - t0;
    if (opt->stats)
        fprintf(stderr, "%s: --exact: %llu windows; %.6f s in their starts (parallel), %.6f s in "
                "their event loops (sequential)\n", sim_program, (unsigned long long)w.windows,
                w.start_s, w.loop_s);

    for (int t = 0; t < w.nt; t++) {
        st->pair_tests += w.th[t].tests;
        free(w.th[t].buf.e);
    }
    exact_free(&w.d);
    free(w.th);
    free(w.cell_of);
    free(w.cell_start);
    free(w.members);
    free(w.win_events);
    free(w.heap.e);
    return 0;
}
