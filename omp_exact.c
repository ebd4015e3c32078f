/* omp_exact.c: omp's --exact engine (exact.h): seq's events, found among grid neighbours, processed on
 * all threads so that every disk has seq's events in seq's order.
 *
 * Windows. Each step is cut into time windows [T0, T1]. At a window's start every disk's position is
 * projected to T0 by flight (x + vx * (T0 - t): for binning only, never written back) and binned into
 * square cells wider than any distance from which two disks can touch within the window: 2r + 2 *
 * vbound * (T1 - T0) plus rounding margins, where vbound bounds every velocity component during the
 * window (wall reflections keep the components' sizes; a collision that leaves one above vbound ends
 * the window). Only disks in neighbouring cells can meet before T1. A window also ends after a disk's
 * WINDOW_EVENTS-th event in it, which bounds the rounding the margins cover. Windows never change a
 * disk's arithmetic, so where they end does not change the bytes.
 *
 * The sequential window (one thread, a grid too narrow to cut, the instant after a stop, see below):
 * every disk's events up to T1 are predicted in parallel into one heap, then seq.c's loop processes
 * the smallest valid event by key and predicts the changed disks again against their neighbour cells.
 * Every valid event with te <= T1 is in the heap, so this is seq's loop.
 *
 * The parallel window. Within a window seq repeatedly processes the smallest event predicted from the
 * disks' current states, and an event reads and writes its own two disks only: any schedule that
 * processes the same events, each disk's in seq's order, leaves the same state. The grid's columns are
 * cut into one strip a thread; each disk belongs to the strip of its cell.
 * - Phase 1, the strips concurrently: each runs seq's loop over its own disks and their pairs, and
 *   keeps for each disk z a taint time tau_z before which no disk whose motion the strip does not know
 *   can touch z. Unknown are the disks of the other strips from T0 on, and a strip's own disk y from
 *   tau_y on. Every disk moves no faster than sbound during the window (else the window stops, below),
 *   so an unknown disk known to be at p at time t0 is within sbound (t - t0) of p at t >= t0, and z,
 *   at q at time now and moving at speed |v_z| until its next event, cannot touch it before now + (|q -
 *   p| - 2r - margins - sbound (now - t0)) / (sbound + |v_z|). tau_z is the least such bound over its
 *   unknown neighbours, lowered as they become unknown (a taint event at tau_y, processed before the
 *   real events at its time: a Dijkstra beside the event loop) and computed again after each of z's
 *   events (its motion changes). The strip processes an event only if it comes before the taus of
 *   both its disks, and leaves the others. By induction in the order of the strip's loop, each event
 *   it processes has, in seq, the same two states (an earlier event of either disk in seq would be with
 *   a disk the strip knows, hence processed, or with an unknown one, hence after its tau), so it is
 *   seq's event, and every event of seq before both taus is found. An event of seq at t >= tau of one
 *   disk has t >= tau of the other (they touch at t), so what remains of the window is among the
 *   tainted disks (tau <= T1) alone, each of which has had every event before its tau.
 * - Phase 2, the bands concurrently: the tainted disks lie near the cuts. A column of a strip without a
 *   tainted disk separates the cut to its left from the cut to its right (disks two columns apart
 *   cannot touch within the window), so each band between two such columns runs seq's loop over its
 *   tainted disks alone, from the states phase 1 left (a disk's phase-1 events all come before its tau,
 *   its phase-2 events after it). A strip with no clean column merges the bands on either side.
 * - Stops. An event that would stop the run (exact_stops), leave a component above vbound or a speed
 *   above sbound, or be a disk's WINDOW_EVENTS-th, is not processed in parallel: its strip or band
 *   stops there, the others at that time, and every disk's state as it was before its first event in
 *   the window is put back. The window runs again up to the time just before the earliest such event
 *   (where phase 2 may meet an earlier one: again, up to that), and the next window is that event's
 *   instant alone, run sequentially: there the event stops the run or ends the window exactly as in
 *   seq's loop, and the windows after it plan with the velocities it left. A deferred pair whose other
 *   disk is not tainted (the margins not covering rounding, which they must) puts the states back too,
 *   and the window runs sequentially. So every window is seq's, at every thread count.
 * The periodic box: the grid tiles [0, L) and wraps (a cell's neighbours across an edge are those of
 * the other side; a grid under 3 cells a side is one cell), distances are the nearest image's, the
 * first and last strips are neighbours across the edge (one more cut), and the band that holds the
 * edge wraps (plan_bands). As in seq, after a pair's event the pair is predicted again (it may meet
 * through another image).
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

#define VBOUND_FACTOR 1.5 /* vbound over the fastest component, sbound over the fastest speed, at the
                             window's start */
#define WINDOW_CHOICES 24 /* window lengths tried: the rest of the step over 1, 2, 4, ... */

/* Relative costs for choosing the window length: binning one disk, one pair prediction, the heap
 * work of one event. */
#define COST_BIN 1.0
#define COST_PAIR 1.0
#define COST_EVENT 4.0

#define STRIPS_PER_THREAD 1 /* strips of a parallel window per thread (phase 2 has one band fewer) */
#define STRIP_MIN_COLS 6    /* narrowest strip, in columns: room for a clean column between two bands */

/* A taint event: from tau on, disk i's motion is no longer known to its strip. */
typedef struct {
    double tau;
    int32_t i;
} XTaint;

/* A slot's state before its first event in a parallel window, to put back if the window stops. */
typedef struct {
    real x, y, vx, vy, t;
    double wi;
    uint32_t ver, step_events;
    int32_t i, last, pc, wc;
} XSaved;

typedef struct {
    ExactHeap buf;   /* sequential start: this thread's predictions (unordered); parallel: the heap of
                        the strip or band at hand */
    XTaint *taint;   /* the strip's taint events, a min-heap by tau */
    size_t taint_len, taint_cap;
    XSaved *saved;   /* states put aside in this window */
    size_t saved_len, saved_cap;
    int32_t *list;   /* a band's tainted disks */
    size_t list_cap;
    uint64_t tests;
    uint64_t ev1, ev2, tainted; /* this parallel window's events by phase, tainted disks */
    double stop_t;   /* the time of the first event this thread found that stops the window, or inf */
    double busy1, busy2; /* for --stats: seconds in strips and in bands */
    char pad[64];
} XThread;

typedef struct {
    ExactDisks d;         /* the disks in slot order (on ss) */
    Sim *sim;             /* the run's state, in index order */
    Sim ss;               /* the state in slot order; its last holds slots */
    int32_t *id;          /* n: each slot's disk */
    int32_t *slot_of;     /* n: each disk's slot */
    void *spare[16];      /* reorder_slots' second copy of each array it moves */
    const Params *p;
    int nt;
    int check;            /* --check: all pairs after every window (check_window) */
    XThread *th;
    ExactHeap heap;       /* the sequential window's events */
    /* the window's grid: cells in column-major order (c = cx * g + cy), so that a strip of columns is
       one range of cells */
    int64_t g, max_cells; /* cells per side; most cells allowed */
    double origin, inv_w; /* lower corner (both axes) and 1 / cell width */
    int32_t *cell_of;     /* n: each slot's cell */
    int32_t *cell_start;  /* max_cells + 1: first entry of each cell in members */
    int32_t *members;     /* n: the slots in cell order */
    int32_t *by_strip;    /* n: the slots in strip order (binning's first pass) */
    uint32_t *win_events; /* n: events of each slot in the window */
    double vbound;        /* bound on |vx|, |vy| within the window */
    double sbound;        /* bound on the speed within a parallel window */
    double rate;          /* events per time unit, estimated from the last window */
    /* the strips and bands of a parallel window */
    int strips, max_strips;
    int32_t *col_lo;      /* max_strips + 1: each strip's first column */
    int32_t *strip_of;    /* g: each column's strip */
    int64_t *strip_count; /* nt * max_strips: binning's counts, then offsets, by thread and strip */
    int64_t *strip_first; /* max_strips + 1: each strip's first entry in by_strip */
    double *tau;          /* n: each slot's taint time (phase 1) */
    double *x0, *y0;      /* n: each slot's position at the window's start */
    unsigned char *cell_tainted; /* max_cells: whether a cell holds a disk whose taint time has come */
    unsigned char *col_tainted; /* g: whether a column holds a tainted disk after phase 1 */
    int bands;
    int32_t *band_lo;     /* 2 max_strips + 2: each band's first column and its end */
    int32_t wrap_lo;      /* the periodic box: band 0 also holds the columns from wrap_lo to g */
    double touch;         /* the taint bound's contact distance: 2r and cell_width's margins */
    double stop_t;        /* the earliest event found so far that stops the parallel window, or inf */
    int bound_failed;     /* a deferred pair whose other disk was not tainted: the window runs again
                             sequentially */
    real instant;         /* >= 0: the next window is the events at this one instant, sequentially */
    int reorder;          /* the next window's binning puts the slots in its cells' order */
    /* for --stats */
    uint64_t windows, par_windows, retried, redone, instants, merged;
    uint64_t ev_seq, ev1, ev2, tainted;
    double bin_s, start_s, loop_s, phase1_s, phase2_s;
} XWork;

/* ==== the window's plan and grid ==================================================================== */

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

/* The strips of the window: max_strips of equal width, fewer where the grid is narrow; one strip
 * (the sequential window) on one thread or where parallel is 0. */
static void plan_strips(XWork *w, int parallel)
{
    int64_t s = w->g / STRIP_MIN_COLS;
    if (s > w->max_strips) s = w->max_strips;
    if (!parallel || w->nt < 2 || s < 2) s = 1;
    w->strips = (int)s;
    for (int k = 0; k <= w->strips; k++) w->col_lo[k] = (int32_t)(w->g * k / w->strips);
    for (int k = 0; k < w->strips; k++)
        for (int32_t c = w->col_lo[k]; c < w->col_lo[k + 1]; c++) w->strip_of[c] = k;
}

/* Chooses the end of the window starting at t0 and its grid, trading the window's start-up (binning
 * and predicting every disk) against the neighbours each event tests; instant: the window is the
 * instant t0 alone, sequential. Both parts run on all threads in a parallel window; in a sequential
 * one only the start-up does, and the windows are shorter. */
static real plan_window(XWork *w, real t0, double vmax, double smax, int instant)
{
    const Params *p = w->p;
    double n = (double)p->n, rest = 1 - (double)t0;
    w->vbound = VBOUND_FACTOR * vmax;
    w->sbound = VBOUND_FACTOR * smax;
    double margin = REL_MARGIN * (double)(p->L + p->r), extent = (double)(p->hi - p->lo) + 2 * margin;
    if (p->periodic) extent = (double)p->L; /* cells tiling [0, L), wrapping */
    double best = -1, h = rest;
    int parallel = w->nt > 1; /* (unless the grid turns out too narrow for strips) */
    for (int k = 0; k < WINDOW_CHOICES && !instant; k++) {
        double hk = ldexp(rest, -k);
        int64_t g = cells_per_side(w, cell_width(p, w->vbound, hk), extent);
        double near = 9 * n / ((double)g * (double)g);
        double start = n * (COST_BIN + COST_PAIR * near / 2) / hk;
        double loop = w->rate * (COST_EVENT + 2 * COST_PAIR * near);
        double cost = parallel ? start + loop : start / w->nt + loop;
        if (best < 0 || cost < best) {
            best = cost;
            h = hk;
        }
        if (w->vbound * hk < 1e-3 * (double)p->r) break; /* shorter windows no longer shrink the cells */
    }
    real t1 = h == rest ? 1 : t0 + (real)h;
    if (!(t1 > t0) || t1 > 1) t1 = 1;
    if (instant) t1 = t0;
    double len = (double)t1 - (double)t0;
    w->g = cells_per_side(w, cell_width(p, w->vbound, len), extent);
    w->origin = (double)p->lo - margin;
    if (p->periodic) {
        if (w->g < 3) w->g = 1; /* a cell's neighbours along an axis are two other cells, or none */
        w->origin = 0;
    }
    w->inv_w = (double)w->g / extent;
    plan_strips(w, !instant);
    double reach = 2 * (double)p->r + 2 * w->vbound * len;
    w->touch = 2 * (double)p->r + 2 * broad_margin(p->r, (double)p->L + 2 * w->vbound * len, reach,
                                                   REL_MARGIN);
    return t1;
}

static inline int32_t cell_coord(const XWork *w, double c)
{
    double u = (c - w->origin) * w->inv_w;
    if (!(u > 0)) return 0;
    if (u > (double)(w->g - 1)) return (int32_t)(w->g - 1);
    return (int32_t)u;
}

/* Bins the disks by their positions projected to t0, on all threads: each thread counts its range of
 * disks by strip, the disks go to their strips in index order, and each strip sorts its own by cell
 * (a counting sort). Clears the window's per-disk counts and taint times on the way. */
static void bin_disks(XWork *w, real t0)
{
    const Sim *s = w->d.sim;
    int64_t n = w->p->n, g = w->g;
    int strips = w->strips;
#pragma omp parallel
    {
        int tid = omp_get_thread_num(), nth = omp_get_num_threads();
        int64_t from = n * tid / nth, to = n * (tid + 1) / nth;
        int64_t *count = w->strip_count + (size_t)tid * (size_t)w->max_strips;
        for (int k = 0; k < strips; k++) count[k] = 0;
        for (int64_t i = from; i < to; i++) {
            double dt = (double)t0 - (double)w->d.t[i];
            double x = (double)s->x[i] + (double)s->vx[i] * dt, y = (double)s->y[i] + (double)s->vy[i] * dt;
            if (w->p->periodic) { /* the image in [0, L) */
                double L = (double)w->p->L;
                x -= floor(x / L) * L;
                y -= floor(y / L) * L;
            }
            int32_t cx = cell_coord(w, x);
            w->cell_of[i] = cx * (int32_t)g + cell_coord(w, y);
            w->x0[i] = x;
            w->y0[i] = y;
            w->win_events[i] = 0;
            w->tau[i] = INFINITY;
            count[w->strip_of[cx]]++;
        }
#pragma omp barrier
#pragma omp single
        {
            int64_t at = 0;
            for (int k = 0; k < strips; k++) {
                w->strip_first[k] = at;
                for (int t = 0; t < nth; t++) {
                    int64_t *c = &w->strip_count[(size_t)t * (size_t)w->max_strips + (size_t)k];
                    int64_t v = *c;
                    *c = at;
                    at += v;
                }
            }
            w->strip_first[strips] = at;
        }
        for (int64_t i = from; i < to; i++) w->by_strip[count[w->strip_of[w->cell_of[i] / g]]++] = (int32_t)i;
#pragma omp barrier
#pragma omp for schedule(dynamic, 1)
        for (int k = 0; k < strips; k++) {
            int32_t *start = w->cell_start;
            int64_t c0 = (int64_t)w->col_lo[k] * g, c1 = (int64_t)w->col_lo[k + 1] * g;
            int64_t f0 = w->strip_first[k], f1 = w->strip_first[k + 1];
            for (int64_t c = c0; c < c1; c++) start[c] = 0;
            for (int64_t m = f0; m < f1; m++) start[w->cell_of[w->by_strip[m]]]++;
            int64_t at = f0;
            for (int64_t c = c0; c < c1; c++) {
                int64_t v = start[c];
                start[c] = (int32_t)at;
                at += v;
            }
            for (int64_t m = f0; m < f1; m++) {
                int32_t i = w->by_strip[m];
                w->members[start[w->cell_of[i]]++] = i;
            }
            for (int64_t c = c1 - 1; c > c0; c--) start[c] = start[c - 1];
            start[c0] = (int32_t)f0;
        }
    }
    w->cell_start[g * g] = (int32_t)n;
}

/* ==== the slots ====================================================================================== */

/* The disks live in slots, an order of omp_exact.c's own: at each step's first window the slots take the
 * order of the window's cells (reorder_slots), so that a strip's disks lie together in memory, apart
 * from the other threads' (no cache line written by two threads) and a cell's neighbours near it.
 * Events keep seq's keys, the disks' indices; exact.c's arithmetic runs on slots, each pair's lower
 * index first as in seq. */

/* One per-slot array and the size of its elements (4 or 8 bytes). */
typedef struct {
    void **a;
    size_t size;
} XArray;

/* The per-disk arrays of state s (x, y, vx, vy, pc, wc, last, and wi where --pressure keeps it) into
 * a; returns how many. */
static int state_arrays(Sim *s, XArray *a)
{
    XArray all[] = {
        {(void **)&s->x, sizeof(real)},     {(void **)&s->y, sizeof(real)},
        {(void **)&s->vx, sizeof(real)},    {(void **)&s->vy, sizeof(real)},
        {(void **)&s->pc, sizeof(int32_t)}, {(void **)&s->wc, sizeof(int32_t)},
        {(void **)&s->last, sizeof(int32_t)}, {(void **)&s->wi, sizeof(double)},
    };
    int count = 8 - (s->wi ? 0 : 1);
    memcpy(a, all, (size_t)count * sizeof *a);
    return count;
}

/* dst[k] = src[from[k]] (or, scatter, dst[from[k]] = src[k]) for k < n, on the calling team. */
static void permute(const XArray *dst, const XArray *src, const int32_t *from, int scatter, int64_t n)
{
    if (dst->size == 8) {
        uint64_t *d = *dst->a;
        const uint64_t *q = *src->a;
#pragma omp for schedule(static) nowait
        for (int64_t k = 0; k < n; k++) {
            if (scatter) d[from[k]] = q[k];
            else d[k] = q[from[k]];
        }
    } else {
        uint32_t *d = *dst->a;
        const uint32_t *q = *src->a;
#pragma omp for schedule(static) nowait
        for (int64_t k = 0; k < n; k++) {
            if (scatter) d[from[k]] = q[k];
            else d[k] = q[from[k]];
        }
    }
}

/* Puts the slots in the order of the window's cells (members): slot k takes the disk of slot
 * members[k]. Every per-slot array moves; last is renumbered. */
static void reorder_slots(XWork *w)
{
    int64_t n = w->p->n;
    XArray moved[16] = {
        {(void **)&w->d.t, sizeof(real)},       {(void **)&w->d.ver, sizeof(uint32_t)},
        {(void **)&w->d.step_events, sizeof(uint32_t)}, {(void **)&w->cell_of, sizeof(int32_t)},
        {(void **)&w->id, sizeof(int32_t)},     {(void **)&w->x0, sizeof(double)},
        {(void **)&w->y0, sizeof(double)},
    };
    int count = 7 + state_arrays(&w->ss, moved + 7);
    XArray spare[16];
    for (int k = 0; k < count; k++) {
        if (!w->spare[k]) w->spare[k] = sim_calloc((size_t)n, moved[k].size);
        spare[k].a = &w->spare[k];
        spare[k].size = moved[k].size;
    }
    const int32_t *from = w->members;
    int32_t *slot_now = w->by_strip; /* binning is done with it: each old slot's new slot */
#pragma omp parallel
    {
        for (int k = 0; k < count; k++) permute(&spare[k], &moved[k], from, 0, n);
#pragma omp for schedule(static)
        for (int64_t k = 0; k < n; k++) slot_now[from[k]] = (int32_t)k;
    }
    for (int k = 0; k < count; k++) {
        void *old = *moved[k].a;
        *moved[k].a = w->spare[k];
        w->spare[k] = old;
    }
    w->d.last = w->ss.last;
    w->d.id = w->id;
#pragma omp parallel for schedule(static)
    for (int64_t k = 0; k < n; k++) {
        int32_t l = w->ss.last[k];
        if (l >= 0) w->ss.last[k] = slot_now[l];
        w->slot_of[w->id[k]] = (int32_t)k;
        w->members[k] = (int32_t)k;
    }
}

/* The run's state in index order from the slots (for output, checkpoints and the end). */
static void slots_to_sim(XWork *w)
{
    XArray to[8], from[8];
    int count = state_arrays(w->sim, to);
    state_arrays(&w->ss, from);
    int32_t *last = w->sim->last;
#pragma omp parallel
    {
        for (int k = 0; k < count; k++) permute(&to[k], &from[k], w->id, 1, w->p->n);
#pragma omp barrier
#pragma omp for schedule(static)
        for (int64_t i = 0; i < w->p->n; i++)
            if (last[i] >= 0) last[i] = w->id[last[i]];
    }
}

/* The slots, in index order, from the run's state (its last partners -1 where none came with it). */
static void slots_from_sim(XWork *w, Sim *sim)
{
    int64_t n = w->p->n;
    if (!sim->last) {
        sim->last = sim_calloc((size_t)n, sizeof *sim->last);
        for (int64_t i = 0; i < n; i++) sim->last[i] = -1;
    }
    w->sim = sim;
    w->ss.wi = sim->wi; /* (for state_arrays' count) */
    XArray to[8], from[8];
    int count = state_arrays(&w->ss, to);
    state_arrays(sim, from);
    for (int k = 0; k < count; k++) *to[k].a = sim_calloc((size_t)n, to[k].size);
    w->id = sim_calloc((size_t)n, sizeof *w->id);
    w->slot_of = sim_calloc((size_t)n, sizeof *w->slot_of);
    for (int64_t i = 0; i < n; i++) w->id[i] = w->slot_of[i] = (int32_t)i; /* last needs no renumbering */
#pragma omp parallel
    for (int k = 0; k < count; k++) permute(&to[k], &from[k], w->id, 0, n);
}

/* ==== prediction ===================================================================================== */

/* The event at t of slots a and b (a == b: a wall event; else a's disk has the lower index), keyed by
 * the disks' indices as seq keys it, with the slots' versions. */
static inline ExactEvent slot_event(const XWork *w, real t, int64_t a, int64_t b)
{
    ExactEvent e = {t, w->id[a], w->id[b], w->d.ver[a], w->d.ver[b]};
    return e;
}

/* Event e (keyed by disk indices) in slots, as exact.c processes it; 1 if it was predicted from the
 * slots' current versions. */
static inline int event_slots(const XWork *w, const ExactEvent *e, ExactEvent *s)
{
    s->t = e->t;
    s->i = w->slot_of[e->i];
    s->j = w->slot_of[e->j];
    s->vi = e->vi;
    s->vj = e->vj;
    return w->d.ver[s->i] == e->vi && w->d.ver[s->j] == e->vj;
}

static inline void add_event(ExactHeap *b, const ExactEvent *e, int unordered)
{
    if (!unordered) {
        exact_heap_add(b, e);
        return;
    }
    exact_heap_reserve(b, b->len + 1);
    b->e[b->len++] = *e;
}

/* The 3 x 3 cells around cell (cx, cy): up to 3 columns and, in each, the rows as up to two runs
 * [lo, hi] of cells (the walls cut the neighbourhood short; the periodic grid wraps, which splits the
 * run at the edge; its grid of one cell is the cell alone). */
typedef struct {
    int cols, runs;
    int64_t col[3], lo[2], hi[2];
} XNear;

static inline void near_cells(const XWork *w, int64_t cx, int64_t cy, XNear *nb)
{
    int64_t g = w->g;
    nb->cols = 0;
    nb->runs = 1;
    if (!w->p->periodic) {
        for (int64_t nx = cx - 1; nx <= cx + 1; nx++)
            if (nx >= 0 && nx < g) nb->col[nb->cols++] = nx;
        nb->lo[0] = cy > 0 ? cy - 1 : 0;
        nb->hi[0] = cy + 1 < g ? cy + 1 : cy;
        return;
    }
    if (g == 1) {
        nb->col[nb->cols++] = 0;
        nb->lo[0] = nb->hi[0] = 0;
        return;
    }
    for (int64_t nx = cx - 1; nx <= cx + 1; nx++) nb->col[nb->cols++] = (nx + g) % g;
    nb->lo[0] = cy > 0 ? cy - 1 : 0;
    nb->hi[0] = cy + 1 < g ? cy + 1 : cy;
    if (cy == 0 || cy == g - 1) { /* the row across the edge */
        nb->runs = 2;
        nb->lo[1] = nb->hi[1] = cy == 0 ? g - 1 : 0;
    }
}

/* Which neighbours predict_near pairs a disk with: all, those of strip `part` (phase 1), or the
 * tainted ones (phase 2). */
enum { NEAR_ALL, NEAR_STRIP, NEAR_TAINTED };

/* Slot i's events up to t1: its wall event and its pair events with the slots of the 3 x 3 cells
 * around its own that `near` admits, except skip, and (from_lower) except lower slots (each pair
 * once). Into the heap, or (from_lower) appended to b. Returns the pair predictions made. */
static inline uint64_t predict_near(XWork *w, int64_t i, int64_t skip, int from_lower, real t1,
                                    ExactHeap *b, int near, int part)
{
    const ExactDisks *d = &w->d;
    const Params *p = w->p;
    uint64_t tests = 0;
    real t = exact_wall_time(d, p, i);
    if (t >= 0 && t <= t1) {
        ExactEvent e = slot_event(w, t, i, i);
        add_event(b, &e, from_lower);
    }
    int32_t id = w->id[i];
    int64_t g = w->g, c = w->cell_of[i];
    XNear nb;
    near_cells(w, c / g, c % g, &nb);
    for (int u = 0; u < nb.cols; u++) {
        int64_t nx = nb.col[u];
        if (near == NEAR_STRIP && w->strip_of[nx] != part) continue;
        for (int v = 0; v < nb.runs; v++) {
            int32_t m0 = w->cell_start[nx * g + nb.lo[v]], m1 = w->cell_start[nx * g + nb.hi[v] + 1];
            for (int32_t m = m0; m < m1; m++) {
                int64_t k = w->members[m];
                if (k == i || k == skip || (from_lower && k < i)) continue;
                if (near == NEAR_TAINTED && !(w->tau[k] <= (double)t1)) continue;
                int lower = w->id[k] < id;
                int64_t a = lower ? k : i, bb = lower ? i : k;
                tests++;
                t = exact_pair_time(d, p, a, bb);
                if (t < 0 || t > t1) continue;
                ExactEvent e = slot_event(w, t, a, bb);
                add_event(b, &e, from_lower);
            }
        }
    }
    return tests;
}

/* The disk predict_near skips for the first disk of an event with disk j: j, or none in the periodic
 * box, where the pair may meet again through another image (as in seq.c). */
static inline int64_t again(const XWork *w, int64_t j)
{
    return w->p->periodic ? -1 : j;
}

/* --check: after a window that ended at t1, no disk or pair may have an event before t1 (or at t1,
 * when the window ran to its planned end): the grid would have missed it. All pairs, so slow. */
static void check_window(const XWork *w, real t0, real t1, int early)
{
    const ExactDisks *d = &w->d;
    const Params *p = w->p;
    for (int64_t i = 0; i < p->n; i++) {
        int64_t a = w->slot_of[i];
        real t = exact_wall_time(d, p, a);
        if (t >= 0 && (t < t1 || (!early && t == t1)))
            sim_fail("--check: window [%.17g, %.17g] left the wall event of disk %lld at t = %.17g",
                    (double)t0, (double)t1, (long long)i, (double)t);
        for (int64_t j = i + 1; j < p->n; j++) {
            t = exact_pair_time(d, p, a, w->slot_of[j]);
            if (t >= 0 && (t < t1 || (!early && t == t1)))
                sim_fail("--check: window [%.17g, %.17g] missed the event of disks %lld and %lld at "
                        "t = %.17g",
                        (double)t0, (double)t1, (long long)i, (long long)j, (double)t);
        }
    }
}

/* ==== the sequential window ========================================================================== */

/* One more event of disk i in this window; 1 if the window must end after it. */
static inline int window_ends(XWork *w, int64_t i)
{
    const Sim *s = w->d.sim;
    return ++w->win_events[i] >= WINDOW_EVENTS || fabs((double)s->vx[i]) > w->vbound ||
           fabs((double)s->vy[i]) > w->vbound;
}

/* Runs the window [t0, t1] as seq.c's loop on the grid; returns where it ended and sets *early when
 * that is before its plan's end. */
static real run_sequential(XWork *w, real t0, real t1, int *early, RunStats *st)
{
    const Params *p = w->p;
    int64_t n = p->n;
    double clock0 = sim_clock();

    /* every disk's events in the window, each pair once, in parallel */
#pragma omp parallel
    {
        XThread *th = &w->th[omp_get_thread_num()];
        th->buf.len = 0;
#pragma omp for schedule(dynamic, 256)
        for (int64_t i = 0; i < n; i++) {
            w->win_events[i] = 0;
            th->tests += predict_near(w, i, -1, 1, t1, &th->buf, NEAR_ALL, 0);
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
    *early = 0;
    (void)t0;
    while (w->heap.len && w->heap.e[0].t <= t1) {
        ExactEvent key, e;
        exact_heap_pop(&w->heap, &key);
        if (!event_slots(w, &key, &e)) continue;
        exact_apply(&w->d, p, &e);
        events++;
        int end = window_ends(w, e.i);
        if (e.j != e.i) end |= window_ends(w, e.j);
        if (end) {
            t1 = e.t;
            *early = 1;
            break;
        }
        st->pair_tests += predict_near(w, e.i, again(w, e.j), 0, t1, &w->heap, NEAR_ALL, 0);
        if (e.j != e.i) st->pair_tests += predict_near(w, e.j, e.i, 0, t1, &w->heap, NEAR_ALL, 0);
    }
    st->events += events;
    w->ev_seq += events;
    w->start_s += clock1 - clock0;
    w->loop_s += sim_clock() - clock1;
    return t1;
}

/* ==== the parallel window ============================================================================ */

/* Event e stops the parallel window (see parallel_apply): the earliest such time is kept. */
static void stop_at(XWork *w, XThread *th, real t)
{
    if ((double)t < th->stop_t) th->stop_t = (double)t;
#pragma omp critical(exact_stop)
    if ((double)t < w->stop_t) w->stop_t = (double)t;
}

/* Whether events at time t are past an event that stops the window (or the window runs again
 * sequentially): no use processing them. */
static inline int past_stop(XWork *w, real t)
{
    double stop;
    int failed;
#pragma omp atomic read
    stop = w->stop_t;
#pragma omp atomic read
    failed = w->bound_failed;
    return failed || (double)t >= stop;
}

static void taint_push(XThread *th, double tau, int32_t i)
{
    if (th->taint_len == th->taint_cap)
        th->taint = sim_grow(th->taint, &th->taint_cap, th->taint_len + 1, sizeof *th->taint);
    XTaint x = {tau, i};
    size_t k = th->taint_len++;
    while (k > 0) {
        size_t up = (k - 1) / 2;
        if (!(tau < th->taint[up].tau)) break;
        th->taint[k] = th->taint[up];
        k = up;
    }
    th->taint[k] = x;
}

static XTaint taint_pop(XThread *th)
{
    XTaint top = th->taint[0], x = th->taint[--th->taint_len];
    size_t k = 0, len = th->taint_len;
    for (;;) {
        size_t c = 2 * k + 1;
        if (c >= len) break;
        if (c + 1 < len && th->taint[c + 1].tau < th->taint[c].tau) c++;
        if (!(th->taint[c].tau < x.tau)) break;
        th->taint[k] = th->taint[c];
        k = c;
    }
    if (len) th->taint[k] = x;
    return top;
}

/* Disk i's position at time t by flight (for the taint bound only). */
static inline void flown(const XWork *w, int64_t i, double t, double *x, double *y)
{
    const Sim *s = w->d.sim;
    double dt = t - (double)w->d.t[i];
    *x = (double)s->x[i] + (double)s->vx[i] * dt;
    *y = (double)s->y[i] + (double)s->vy[i] * dt;
}

/* The earliest time after now at which disk z, at (zx, zy) at now and moving at speed zs until its
 * next event, can touch a disk that was at (px, py) at time from <= now and has moved no faster than
 * sbound since. */
static inline double taint_bound(const XWork *w, double now, double zx, double zy, double zs, double px,
                                 double py, double from)
{
    double dx = px - zx, dy = py - zy;
    if (w->p->periodic) { /* the nearest image */
        double L = (double)w->p->L;
        dx -= L * nearbyint(dx / L);
        dy -= L * nearbyint(dy / L);
    }
    double gap = sqrt(dx * dx + dy * dy) - w->touch - w->sbound * (now - from) * (1 + REL_MARGIN);
    return gap > 0 ? now + gap / ((w->sbound + zs) * (1 + REL_MARGIN)) : now;
}

static inline double speed_of(const XWork *w, int64_t i)
{
    const Sim *s = w->d.sim;
    double vx = (double)s->vx[i], vy = (double)s->vy[i];
    return sqrt(vx * vx + vy * vy);
}

/* Disk z's taint time bounded by the disks of the column next to strip k's edge column cx (the
 * neighbour strip's, unknown from t0 on), z being at (zx, zy) at now. */
static double edge_bound(const XWork *w, int k, int64_t cx, int64_t cy, double now, double zx, double zy,
                         double zs, real t0)
{
    int64_t g = w->g;
    XNear nb;
    near_cells(w, cx, cy, &nb);
    double tau = INFINITY;
    for (int side = 0; side < 2; side++) {
        int64_t ox = side ? cx + 1 : cx - 1;
        if (w->p->periodic) ox = (ox + g) % g; /* across the edge: the last strip or the first */
        if (ox < 0 || ox >= g || w->strip_of[ox] == k) continue; /* the wall, or the strip's own */
        for (int v = 0; v < nb.runs; v++)
            for (int32_t q = w->cell_start[ox * g + nb.lo[v]]; q < w->cell_start[ox * g + nb.hi[v] + 1]; q++) {
                int32_t o = w->members[q];
                double b = taint_bound(w, now, zx, zy, zs, w->x0[o], w->y0[o], (double)t0);
                if (b < tau) tau = b;
            }
    }
    return tau;
}

/* Strip k's disks at t0: the taint times that its edge columns get from the neighbour strips (from
 * their positions at t0, which no strip writes). */
static void edge_taint(XWork *w, int k, real t0)
{
    int64_t g = w->g;
    for (int32_t c = w->col_lo[k]; c < w->col_lo[k + 1]; c++) {
        memset(w->cell_tainted + (int64_t)c * g, 0, (size_t)g);
        if (c != w->col_lo[k] && c != w->col_lo[k + 1] - 1) continue;
        for (int64_t cy = 0; cy < g; cy++)
            for (int32_t m = w->cell_start[c * g + cy]; m < w->cell_start[c * g + cy + 1]; m++) {
                int32_t z = w->members[m];
                w->tau[z] = edge_bound(w, k, c, cy, (double)t0, w->x0[z], w->y0[z], speed_of(w, z), t0);
            }
    }
}

/* Disk z's taint time again after its event at now, from its new motion: bounded by the disks of
 * the strip whose taint time has come and by those of the neighbour strips. */
static double renew_bound(const XWork *w, int k, int32_t z, double now, real t0)
{
    int64_t g = w->g, c = w->cell_of[z], cx = c / g, cy = c % g;
    XNear nb;
    near_cells(w, cx, cy, &nb);
    double zx, zy, zs = speed_of(w, z), tau = INFINITY;
    int edge = cx == w->col_lo[k] || cx == w->col_lo[k + 1] - 1;
    int near = 0;
    for (int u = 0; u < nb.cols; u++) {
        int64_t nx = nb.col[u];
        if (w->strip_of[nx] != k) continue;
        for (int v = 0; v < nb.runs; v++)
            for (int64_t ny = nb.lo[v]; ny <= nb.hi[v]; ny++) near |= w->cell_tainted[nx * g + ny];
    }
    if (!edge && !near) return INFINITY;
    flown(w, z, now, &zx, &zy);
    if (edge) tau = edge_bound(w, k, cx, cy, now, zx, zy, zs, t0);
    if (!near) return tau;
    for (int u = 0; u < nb.cols; u++) {
        int64_t nx = nb.col[u];
        if (w->strip_of[nx] != k) continue;
        for (int v = 0; v < nb.runs; v++)
            for (int32_t m = w->cell_start[nx * g + nb.lo[v]]; m < w->cell_start[nx * g + nb.hi[v] + 1]; m++) {
                int32_t y = w->members[m];
                double ty = w->tau[y];
                if (y == z || !(ty <= now)) continue;
                double px, py;
                flown(w, y, ty, &px, &py);
                double b = taint_bound(w, now, zx, zy, zs, px, py, ty);
                if (b < tau) tau = b;
            }
    }
    return tau;
}

/* From tau on, disk y's motion is unknown to strip k: the bound for each of its neighbours in the
 * strip (their states are those at tau: every event before tau is processed). */
static void taint_spread(XWork *w, XThread *th, int k, int32_t y, double tau, real t1)
{
    int64_t g = w->g, c = w->cell_of[y];
    XNear nb;
    near_cells(w, c / g, c % g, &nb);
    double px, py;
    flown(w, y, tau, &px, &py);
    w->cell_tainted[c] = 1;
    for (int u = 0; u < nb.cols; u++) {
        int64_t nx = nb.col[u];
        if (w->strip_of[nx] != k) continue;
        for (int v = 0; v < nb.runs; v++)
            for (int32_t m = w->cell_start[nx * g + nb.lo[v]]; m < w->cell_start[nx * g + nb.hi[v] + 1]; m++) {
                int32_t z = w->members[m];
                if (z == y || w->tau[z] <= tau) continue;
                double zx, zy;
                flown(w, z, tau, &zx, &zy);
                double b = taint_bound(w, tau, zx, zy, speed_of(w, z), px, py, tau);
                if (b < w->tau[z]) {
                    w->tau[z] = b;
                    if (b <= (double)t1) taint_push(th, b, z);
                }
            }
    }
}

/* Puts disk i's state aside before its first event in the window. */
static void save_disk(XWork *w, XThread *th, int32_t i)
{
    if (w->win_events[i]) return;
    if (th->saved_len == th->saved_cap)
        th->saved = sim_grow(th->saved, &th->saved_cap, th->saved_len + 1, sizeof *th->saved);
    const Sim *s = w->d.sim;
    XSaved *v = &th->saved[th->saved_len++];
    v->x = s->x[i];
    v->y = s->y[i];
    v->vx = s->vx[i];
    v->vy = s->vy[i];
    v->t = w->d.t[i];
    v->wi = s->wi ? s->wi[i] : 0;
    v->ver = w->d.ver[i];
    v->step_events = w->d.step_events[i];
    v->i = i;
    v->last = w->d.last[i];
    v->pc = s->pc[i];
    v->wc = s->wc[i];
}

static void restore_disks(XWork *w)
{
    Sim *s = w->d.sim;
    for (int t = 0; t < w->nt; t++) {
        XThread *th = &w->th[t];
#pragma omp parallel for schedule(static)
        for (size_t k = 0; k < th->saved_len; k++) {
            const XSaved *v = &th->saved[k];
            int32_t i = v->i;
            s->x[i] = v->x;
            s->y[i] = v->y;
            s->vx[i] = v->vx;
            s->vy[i] = v->vy;
            w->d.t[i] = v->t;
            if (s->wi) s->wi[i] = v->wi;
            w->d.ver[i] = v->ver;
            w->d.step_events[i] = v->step_events;
            w->d.last[i] = v->last;
            s->pc[i] = v->pc;
            s->wc[i] = v->wc;
        }
    }
}

/* One more event of slot i in a parallel window; 1 if the window stops at it (the sequential window
 * would end here, or the taint bound's speed no longer holds). */
static inline int outruns(XWork *w, int64_t i)
{
    const Sim *s = w->d.sim;
    double vx = (double)s->vx[i], vy = (double)s->vy[i];
    return ++w->win_events[i] >= WINDOW_EVENTS || fabs(vx) > w->vbound || fabs(vy) > w->vbound ||
           vx * vx + vy * vy > w->sbound * w->sbound;
}

/* Processes valid event e (in slots) in a parallel window; 1 if the window stops at it (and e was not
 * processed where it would stop the run). */
static int parallel_apply(XWork *w, XThread *th, const ExactEvent *e)
{
    if (exact_stops(&w->d, e)) return 1;
    save_disk(w, th, e->i);
    if (e->j != e->i) save_disk(w, th, e->j);
    exact_apply(&w->d, w->p, e);
    int bad = outruns(w, e->i);
    if (e->j != e->i) bad |= outruns(w, e->j);
    return bad;
}

/* Phase 1 of strip k: seq's loop over the strip's disks, each event before both its disks' taus. */
static void strip_events(XWork *w, XThread *th, int k, real t0, real t1)
{
    int64_t g = w->g;
    int32_t m0 = w->cell_start[(int64_t)w->col_lo[k] * g], m1 = w->cell_start[(int64_t)w->col_lo[k + 1] * g];
    ExactHeap *h = &th->buf;
    h->len = 0;
    th->taint_len = 0;
    edge_taint(w, k, t0);
    for (int32_t m = m0; m < m1; m++) {
        int32_t i = w->members[m];
        th->tests += predict_near(w, i, -1, 1, t1, h, NEAR_STRIP, k);
        if (w->tau[i] <= (double)t1) taint_push(th, w->tau[i], i);
    }
    exact_heap_build(h);
    uint64_t events = 0;
    int check = 0;
    for (;;) {
        int real_next = h->len && h->e[0].t <= t1;
        if (th->taint_len && (!real_next || th->taint[0].tau <= (double)h->e[0].t)) {
            XTaint x = taint_pop(th);
            if (x.tau == w->tau[x.i]) taint_spread(w, th, k, x.i, x.tau, t1);
            continue;
        }
        if (!real_next) break;
        if (++check % 64 == 0 && past_stop(w, h->e[0].t)) return;
        ExactEvent key, e;
        exact_heap_pop(h, &key);
        if (!event_slots(w, &key, &e)) continue;
        double te = (double)e.t;
        if (te >= w->tau[e.i] || te >= w->tau[e.j]) { /* phase 2's */
            if (!(w->tau[e.i] <= te && w->tau[e.j] <= te)) {
#pragma omp atomic write
                w->bound_failed = 1;
                return;
            }
            continue;
        }
        if (parallel_apply(w, th, &e)) {
            stop_at(w, th, e.t);
            return;
        }
        events++;
        th->tests += predict_near(w, e.i, again(w, e.j), 0, t1, h, NEAR_STRIP, k);
        if (e.j != e.i) th->tests += predict_near(w, e.j, e.i, 0, t1, h, NEAR_STRIP, k);
        for (int d = 0; d < 1 + (e.j != e.i); d++) { /* a new motion: a new bound */
            int32_t z = d ? e.j : e.i;
            double tau = renew_bound(w, k, z, te, t0);
            if (tau != w->tau[z]) {
                w->tau[z] = tau;
                if (tau <= (double)t1) taint_push(th, tau, z);
            }
        }
    }
    th->ev1 += events;
    for (int32_t c = w->col_lo[k]; c < w->col_lo[k + 1]; c++) {
        unsigned char any = 0;
        for (int32_t m = w->cell_start[c * g]; m < w->cell_start[(c + 1) * g]; m++) {
            int tainted = w->tau[w->members[m]] <= (double)t1;
            any |= tainted;
            th->tainted += tainted;
        }
        w->col_tainted[c] = any;
    }
}

/* The bands of phase 2: the columns between consecutive clean columns, one chosen in each strip
 * (nearest its middle); a strip without one joins the bands on either side. */
static void plan_bands(XWork *w)
{
    int b = 0;
    w->band_lo[0] = 0;
    for (int k = 0; k < w->strips; k++) {
        int32_t lo = w->col_lo[k], hi = w->col_lo[k + 1], mid = lo + (hi - lo) / 2, clean = -1;
        for (int32_t d = 0; clean < 0 && (mid - d >= lo || mid + d < hi); d++) {
            if (mid - d >= lo && !w->col_tainted[mid - d]) clean = mid - d;
            else if (mid + d < hi && !w->col_tainted[mid + d]) clean = mid + d;
        }
        if (clean < 0) {
            w->merged++;
            continue;
        }
        w->band_lo[++b] = clean; /* band b - 1 ends before it; band b starts after it */
        w->band_lo[++b] = clean + 1;
    }
    w->band_lo[++b] = (int32_t)w->g;
    w->bands = b / 2 + 1; /* pairs (band_lo[2a], band_lo[2a + 1]): each band's columns */
    w->wrap_lo = (int32_t)w->g;
    if (w->p->periodic && b > 1) { /* the last band goes on across the edge into the first */
        w->bands--;
        w->wrap_lo = w->band_lo[b - 1];
    }
}

/* Phase 2 of band b: seq's loop over its tainted disks. */
static void band_events(XWork *w, XThread *th, int b, real t1)
{
    int64_t g = w->g;
    size_t len = 0;
    for (int piece = 0; piece < 1 + (b == 0); piece++) { /* band 0's columns from wrap_lo to the edge */
        int32_t c0 = piece ? w->wrap_lo : w->band_lo[2 * b], c1 = piece ? (int32_t)g : w->band_lo[2 * b + 1];
        for (int32_t m = w->cell_start[(int64_t)c0 * g]; m < w->cell_start[(int64_t)c1 * g]; m++) {
            int32_t i = w->members[m];
            if (!(w->tau[i] <= (double)t1)) continue;
            if (len == th->list_cap) th->list = sim_grow(th->list, &th->list_cap, len + 1, sizeof *th->list);
            th->list[len++] = i;
        }
    }
    if (!len) return;
    ExactHeap *h = &th->buf;
    h->len = 0;
    for (size_t k = 0; k < len; k++) th->tests += predict_near(w, th->list[k], -1, 1, t1, h, NEAR_TAINTED, 0);
    exact_heap_build(h);
    uint64_t events = 0;
    int check = 0;
    while (h->len && h->e[0].t <= t1) {
        if (++check % 64 == 0 && past_stop(w, h->e[0].t)) return;
        ExactEvent key, e;
        exact_heap_pop(h, &key);
        if (!event_slots(w, &key, &e)) continue;
        if (parallel_apply(w, th, &e)) {
            stop_at(w, th, e.t);
            return;
        }
        events++;
        th->tests += predict_near(w, e.i, again(w, e.j), 0, t1, h, NEAR_TAINTED, 0);
        if (e.j != e.i) th->tests += predict_near(w, e.j, e.i, 0, t1, h, NEAR_TAINTED, 0);
    }
    th->ev2 += events;
}

/* The window's taint times and counts as at its start (a window run again after a stop). */
static void clear_window(XWork *w)
{
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < w->p->n; i++) {
        w->win_events[i] = 0;
        w->tau[i] = INFINITY;
    }
}

enum { PARALLEL_DONE, PARALLEL_STOPPED, PARALLEL_FAILED };

/* Runs the window [t0, t1] in strips and bands. PARALLEL_DONE: it is done. Otherwise every disk's state
 * is as at t0 again, and PARALLEL_STOPPED sets *stop to the earliest event found that stops it (every
 * strip runs to its first, so that the next try, which ends before it, finds none in phase 1; phase 2
 * likewise), PARALLEL_FAILED means it must run sequentially. */
static int run_parallel(XWork *w, real t0, real t1, real *stop, RunStats *st)
{
    double clock0 = sim_clock(), clock1 = 0;
    w->stop_t = INFINITY;
    w->bound_failed = 0;
    for (int t = 0; t < w->nt; t++) {
        XThread *th = &w->th[t];
        th->saved_len = 0;
        th->ev1 = th->ev2 = th->tainted = 0;
        th->stop_t = INFINITY;
    }
#pragma omp parallel
    {
        XThread *th = &w->th[omp_get_thread_num()];
#pragma omp for schedule(dynamic, 1)
        for (int k = 0; k < w->strips; k++) {
            double c = sim_clock();
            strip_events(w, th, k, t0, t1);
            th->busy1 += sim_clock() - c;
        }
#pragma omp single
        {
            clock1 = sim_clock();
            w->bands = 0;
            if (w->stop_t == INFINITY && !w->bound_failed) plan_bands(w);
        }
#pragma omp for schedule(dynamic, 1)
        for (int b = 0; b < w->bands; b++) {
            double c = sim_clock();
            band_events(w, th, b, t1);
            th->busy2 += sim_clock() - c;
        }
    }
    w->phase1_s += clock1 - clock0;
    w->phase2_s += sim_clock() - clock1;
    if (w->stop_t < INFINITY || w->bound_failed) {
        restore_disks(w);
        *stop = (real)w->stop_t;
        return w->bound_failed ? PARALLEL_FAILED : PARALLEL_STOPPED;
    }
    uint64_t ev1 = 0, ev2 = 0;
    for (int t = 0; t < w->nt; t++) {
        ev1 += w->th[t].ev1;
        ev2 += w->th[t].ev2;
        w->tainted += w->th[t].tainted;
    }
    w->ev1 += ev1;
    w->ev2 += ev2;
    st->events += ev1 + ev2;
    w->par_windows++;
    return PARALLEL_DONE;
}

/* ==== the step ======================================================================================= */

/* The largest time before t. */
static inline real time_below(real t)
{
#ifdef SIM_FLOAT
    return nextafterf(t, -INFINITY);
#else
    return nextafter(t, -INFINITY);
#endif
}

/* Runs the window starting at t0; returns where it ended and sets *done when the step is over.
 *
 * A parallel window that meets an event it may not process (parallel_apply) at time ts runs again,
 * up to the time just before ts, where it finds no such event unless phase 2 meets an earlier one
 * (then again, up to that). The next window is then the events at the instant ts alone, run
 * sequentially: it processes the event as seq does (ending the window after it, or stopping the
 * run), and the windows after it plan with the velocities it left. */
static real run_window(XWork *w, real t0, int *done, RunStats *st)
{
    int64_t n = w->p->n;
    real instant = w->instant;
    w->instant = -1;
    if (instant >= 0) {
        t0 = instant;
        w->instants++;
    }
    double vmax = 0, smax2 = 0, clock0 = sim_clock();
#pragma omp parallel for schedule(static) reduction(max : vmax, smax2)
    for (int64_t i = 0; i < n; i++) {
        double vx = (double)w->d.sim->vx[i], vy = (double)w->d.sim->vy[i];
        double ax = fabs(vx), ay = fabs(vy), s2 = vx * vx + vy * vy;
        if (ax > vmax) vmax = ax;
        if (ay > vmax) vmax = ay;
        if (s2 > smax2) smax2 = s2;
    }
    real t1 = plan_window(w, t0, vmax, sqrt(smax2), instant >= 0);
    bin_disks(w, t0);
    if (w->reorder) {
        reorder_slots(w);
        w->reorder = 0;
    }
    w->bin_s += sim_clock() - clock0;
    uint64_t events0 = st->events;
    int early = 0, sequential = w->strips < 2;
    while (!sequential) {
        real stop;
        int r = run_parallel(w, t0, t1, &stop, st);
        if (r == PARALLEL_DONE) break;
        if (r == PARALLEL_FAILED) {
            w->redone++;
            sequential = 1;
            break;
        }
        w->retried++;
        if (stop <= t0) { /* at the window's first instant: that instant alone, sequentially */
            t1 = t0;
            sequential = 1;
            break;
        }
        t1 = time_below(stop);
        w->instant = stop;
        clear_window(w);
    }
    if (sequential) t1 = run_sequential(w, t0, t1, &early, st);
    w->windows++;
    double len = (double)t1 - (double)t0;
    if (len > 0) w->rate = 0.5 * w->rate + 0.5 * (double)(st->events - events0) / len;
    if (w->check) check_window(w, t0, t1, early);
    *done = !early && t1 == 1 && w->instant < 0;
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
    slots_from_sim(&w, sim);
    exact_alloc(&w.d, &w.ss, par);
    w.d.id = w.id;
    w.th = sim_calloc_lines((size_t)w.nt, sizeof *w.th);
    w.max_cells = n;
    int64_t max_g = (int64_t)sqrt((double)n) + 2;
    w.max_strips = w.nt * STRIPS_PER_THREAD;
    w.cell_of = sim_calloc((size_t)n, sizeof *w.cell_of);
    w.cell_start = sim_calloc((size_t)w.max_cells + 1, sizeof *w.cell_start);
    w.members = sim_calloc((size_t)n, sizeof *w.members);
    w.by_strip = sim_calloc((size_t)n, sizeof *w.by_strip);
    w.win_events = sim_calloc((size_t)n, sizeof *w.win_events);
    w.tau = sim_calloc((size_t)n, sizeof *w.tau);
    w.x0 = sim_calloc((size_t)n, sizeof *w.x0);
    w.y0 = sim_calloc((size_t)n, sizeof *w.y0);
    w.cell_tainted = sim_calloc((size_t)w.max_cells, 1);
    w.col_lo = sim_calloc((size_t)w.max_strips + 1, sizeof *w.col_lo);
    w.strip_of = sim_calloc((size_t)max_g, sizeof *w.strip_of);
    w.strip_count = sim_calloc((size_t)w.nt * (size_t)w.max_strips, sizeof *w.strip_count);
    w.strip_first = sim_calloc((size_t)w.max_strips + 1, sizeof *w.strip_first);
    w.col_tainted = sim_calloc((size_t)max_g, sizeof *w.col_tainted);
    w.band_lo = sim_calloc(2 * (size_t)w.max_strips + 2, sizeof *w.band_lo);
    w.rate = (double)n;
    w.instant = -1;

    double t0 = sim_clock();
    for (int64_t step = par->first_step + 1; step <= par->steps; step++) {
        int done = 0;
        real from = 0;
        w.reorder = 1;
        while (!done) from = run_window(&w, from, &done, st);
#pragma omp parallel for schedule(static)
        for (int64_t i = 0; i < n; i++) exact_finish(&w.d, par, i);
        int print = par->print && step < par->steps, checkpoint = io_checkpoint_due(out, step);
        int virial = io_virial_due(out, step);
        if (print || checkpoint || virial) slots_to_sim(&w); /* (the virial sums in index order) */
        if (print) io_write_lines(out, step, sim, n, 0);
        if (virial) io_virial(out, sim, step);
        if (checkpoint) io_checkpoint(out, sim, step);
        io_progress(out, step);
    }
    slots_to_sim(&w);
    st->seconds = sim_clock() - t0;
    if (opt->stats) {
        double busy1 = 0, busy2 = 0;
        for (int t = 0; t < w.nt; t++) {
            busy1 += w.th[t].busy1;
            busy2 += w.th[t].busy2;
        }
        fprintf(stderr, "%s: --exact: %llu windows: %llu in strips on all threads, %llu sequential (%llu "
                "at one instant after a parallel window stopped before it, %llu run again sequentially); "
                "%llu parallel tries stopped and run again to just before the stop; binning %.6f s\n",
                sim_program, (unsigned long long)w.windows, (unsigned long long)w.par_windows,
                (unsigned long long)(w.windows - w.par_windows), (unsigned long long)w.instants,
                (unsigned long long)w.redone, (unsigned long long)w.retried, w.bin_s);
        fprintf(stderr, "%s: --exact: events: %llu in the strips (phase 1, %.6f s, the threads busy %.0f%% "
                "of it), %llu among the %llu disks tainted near the cuts (phase 2, %.6f s, busy %.0f%%; "
                "%llu strips without a clean column), %llu in sequential windows (start %.6f s, loop %.6f "
                "s)\n",
                sim_program, (unsigned long long)w.ev1, w.phase1_s,
                w.phase1_s > 0 ? 100 * busy1 / (w.nt * w.phase1_s) : 0, (unsigned long long)w.ev2,
                (unsigned long long)w.tainted, w.phase2_s, w.phase2_s > 0 ? 100 * busy2 / (w.nt * w.phase2_s) : 0,
                (unsigned long long)w.merged, (unsigned long long)w.ev_seq, w.start_s, w.loop_s);
    }

    for (int t = 0; t < w.nt; t++) {
        st->pair_tests += w.th[t].tests;
        free(w.th[t].buf.e);
        free(w.th[t].taint);
        free(w.th[t].saved);
        free(w.th[t].list);
    }
    exact_free(&w.d);
    free(w.ss.x);
    free(w.ss.y);
    free(w.ss.vx);
    free(w.ss.vy);
    free(w.ss.pc);
    free(w.ss.wc);
    free(w.ss.wi);
    free(w.ss.last);
    free(w.id);
    free(w.slot_of);
    for (size_t k = 0; k < sizeof w.spare / sizeof *w.spare; k++) free(w.spare[k]);
    free(w.th);
    free(w.cell_of);
    free(w.cell_start);
    free(w.members);
    free(w.by_strip);
    free(w.win_events);
    free(w.tau);
    free(w.x0);
    free(w.y0);
    free(w.cell_tainted);
    free(w.col_lo);
    free(w.strip_of);
    free(w.strip_count);
    free(w.strip_first);
    free(w.col_tainted);
    free(w.band_lo);
    free(w.heap.e);
    return 0;
}
