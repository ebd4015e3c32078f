/* seq.c: the sequential reference.
 *
 * The simplest code that is obviously SPEC.md section 3: every wall and every pair tested each step,
 * all events sorted by (t, kind, i, j), the greedy one-event-per-disk choice, the moves. O(N^2) per
 * step on purpose: clarity over speed. Every other backend must reproduce its bytes exactly. In the
 * periodic box (--periodic, SPEC.md 7) there are no wall events, pairs meet by their nearest images
 * and every coordinate is brought into [0, L) at the step's end.
 * --exact (exact.h) likewise: every pair's next contact predicted, a heap of events in key order.
 */
#include "io.h"
#include "exact.h"

#include <stdlib.h>
#include <string.h>

typedef struct {
    real t;  /* time of the event within the step, 0..1 */
    int kind;  /* 0: wall, 1: pair */
    int64_t i; /* the disk (wall) or the lower index (pair) */
    int64_t j; /* the higher index (pair); i for a wall */
} Event;

typedef struct {
    Event *ev;
    size_t len, cap;
} EventList;

static void events_push(EventList *l, real t, int kind, int64_t i, int64_t j)
{
    if (l->len == l->cap) {
        l->cap = l->cap ? 2 * l->cap : 1024;
        Event *grown = realloc(l->ev, l->cap * sizeof *grown);
        if (!grown) sim_fail("out of memory for %zu events", l->cap);
        l->ev = grown;
    }
    Event e = {t, kind, i, j};
    l->ev[l->len++] = e;
}

static int event_cmp(const void *pa, const void *pb)
{
    const Event *a = pa, *b = pb;
    if (event_before(a->t, a->kind, a->i, a->j, b->t, b->kind, b->i, b->j)) return -1;
    if (event_before(b->t, b->kind, b->i, b->j, a->t, a->kind, a->i, a->j)) return 1;
    return 0;
}

/* 3.1: every disk's wall event, if it comes within the step (none in the periodic box). */
static void detect_walls(const Sim *s, const Params *p, EventList *l)
{
    if (p->periodic) return;
    for (int64_t i = 0; i < p->n; i++) {
        real tw = min_time(wall_time(s->x[i], s->vx[i], p->lo, p->hi),
                             wall_time(s->y[i], s->vy[i], p->lo, p->hi));
        if (tw <= 1) events_push(l, tw, 0, i, i);
    }
}

/* 3.2: every pair's event, if it comes within the step (in the periodic box by the nearest image). */
static uint64_t detect_pairs(const Sim *s, const Params *p, EventList *l)
{
    for (int64_t i = 0; i < p->n; i++)
        for (int64_t j = i + 1; j < p->n; j++) {
            real t = p->periodic ? pair_time_wrap(s->x[i], s->y[i], s->vx[i], s->vy[i], s->x[j], s->y[j],
                                                  s->vx[j], s->vy[j], p->sigma2, p->L, p->half, 1)
                                 : pair_time(s->x[i], s->y[i], s->vx[i], s->vy[i], s->x[j], s->y[j], s->vx[j],
                                             s->vy[j], p->sigma2);
            if (t >= 0) events_push(l, t, 1, i, j);
        }
    return (uint64_t)p->n * (uint64_t)(p->n - 1) / 2;
}

/* 3.3: walk the events in key order, accepting each whose disks are still free. event_of[i] gets the
 * index of disk i's accepted event, or -1. */
static uint64_t choose_events(EventList *l, int64_t n, int64_t *event_of)
{
    uint64_t accepted = 0;
    if (l->len) qsort(l->ev, l->len, sizeof *l->ev, event_cmp); /* qsort(NULL, 0, ...) is undefined */
    for (int64_t i = 0; i < n; i++) event_of[i] = -1;
    for (size_t k = 0; k < l->len; k++) {
        const Event *e = &l->ev[k];
        if (event_of[e->i] >= 0 || event_of[e->j] >= 0) continue;
        event_of[e->i] = event_of[e->j] = (int64_t)k;
        accepted++;
    }
    return accepted;
}

/* 3.4 and 3.5: move every disk through the step, its accepted event included. */
static void move(Sim *s, const Params *p, const EventList *l, const int64_t *event_of)
{
    real lo = p->lo, hi = p->hi;
    for (int64_t i = 0; i < p->n; i++) {
        if (event_of[i] < 0) {
            s->x[i] = s->x[i] + s->vx[i];
            s->y[i] = s->y[i] + s->vy[i];
            continue;
        }
        const Event *e = &l->ev[event_of[i]];
        if (e->kind == 0) {
            real vx0 = s->vx[i], vy0 = s->vy[i];
            wall_bounce(&s->x[i], &s->y[i], &s->vx[i], &s->vy[i], e->t, lo, hi);
            if (s->wi) s->wi[i] += wall_impulse(vx0, vy0, s->vx[i], s->vy[i]);
            finish_step(&s->x[i], &s->y[i], s->vx[i], s->vy[i], e->t, lo, hi);
            s->wc[i]++;
        } else if (i == e->i && p->periodic) { /* the pair is handled once, from its lower index */
            int64_t j = e->j;
            real dp = pair_collide_wrap(&s->x[i], &s->y[i], &s->vx[i], &s->vy[i], &s->x[j], &s->y[j],
                                        &s->vx[j], &s->vy[j], e->t, p->L, p->half);
            if (s->wi) s->wi[i] += dp, s->wi[j] += dp; /* the virial's impulses (SPEC.md 7a) */
            s->pc[i]++;
            s->pc[j]++;
        } else if (i == e->i) {
            int64_t j = e->j;
            pair_collide(&s->x[i], &s->y[i], &s->vx[i], &s->vy[i], &s->x[j], &s->y[j], &s->vx[j],
                         &s->vy[j], e->t, lo, hi);
            s->pc[i]++;
            s->pc[j]++;
        }
    }
    for (int64_t i = 0; i < p->n; i++) { /* SPEC.md 3.4's clamp, or 7's fmod into [0, L) */
        s->x[i] = p->periodic ? wrap_coord(s->x[i], p->L) : clamp_coord(s->x[i], lo, hi);
        s->y[i] = p->periodic ? wrap_coord(s->y[i], p->L) : clamp_coord(s->y[i], lo, hi);
    }
}

/* ==== --exact (exact.h): the next event among all pairs ============================================ */

/* Pushes disk i's wall event and its pair events with every disk but i and skip; returns the pairs
 * tested. */
static uint64_t exact_predict(const ExactDisks *d, const Params *p, int64_t i, int64_t skip,
                              ExactHeap *h)
{
    uint64_t tests = 0;
    real t = exact_wall_time(d, p, i);
    if (t >= 0) exact_heap_push(h, d, t, i, i);
    for (int64_t k = 0; k < p->n; k++) {
        if (k == i || k == skip) continue;
        int64_t a = k < i ? k : i, b = k < i ? i : k;
        tests++;
        t = exact_pair_time(d, p, a, b);
        if (t >= 0) exact_heap_push(h, d, t, a, b);
    }
    return tests;
}

/* Each step: every disk's and pair's event from the step's start into the heap, then the smallest
 * valid event, processed and its disks predicted again, until none is left; then the flights to 1. */
static int exact_run(Sim *sim, const Params *par, Output *out, RunStats *st)
{
    ExactDisks d;
    ExactHeap h = {NULL, 0, 0};
    exact_alloc(&d, sim, par);
    double t0 = sim_clock();
    for (int64_t step = par->first_step + 1; step <= par->steps; step++) {
        h.len = 0;
        for (int64_t i = 0; i < par->n; i++) {
            real t = exact_wall_time(&d, par, i);
            if (t >= 0) exact_heap_push(&h, &d, t, i, i);
            for (int64_t j = i + 1; j < par->n; j++) {
                t = exact_pair_time(&d, par, i, j);
                if (t >= 0) exact_heap_push(&h, &d, t, i, j);
            }
        }
        st->pair_tests += (uint64_t)par->n * (uint64_t)(par->n - 1) / 2;
        while (h.len) {
            ExactEvent e;
            exact_heap_pop(&h, &e);
            if (!exact_valid(&d, &e)) continue;
            exact_apply(&d, par, &e);
            st->events++;
            /* its disks against every other, and each other (once) where they may meet again: in the
             * periodic box, through another image */
            st->pair_tests += exact_predict(&d, par, e.i, par->periodic ? -1 : e.j, &h);
            if (e.j != e.i) st->pair_tests += exact_predict(&d, par, e.j, e.i, &h);
        }
        for (int64_t i = 0; i < par->n; i++) exact_finish(&d, par, i);
        if (par->print && step < par->steps) io_write_lines(out, step, sim, par->n, 0);
        if (io_virial_due(out, step)) io_virial(out, sim, step);
        if (io_checkpoint_due(out, step)) io_checkpoint(out, sim, step);
        io_progress(out, step);
    }
    st->seconds = sim_clock() - t0;
    free(h.e);
    exact_free(&d);
    return 0;
}

/* One thread: the tasks in order. */
static void seq_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    (void)threads;
    for (int64_t k = 0; k < tasks; k++) task(ctx, k);
}

/* ==== the step of SPEC.md ============================================================================ */

static int seq_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *st)
{
    if (opt->exact) return exact_run(sim, par, out, st);
    EventList events = {NULL, 0, 0};
    int64_t *event_of = sim_calloc((size_t)par->n, sizeof *event_of);
    int64_t k = par->substeps, last = par->steps * k;
    double t0 = sim_clock();
    for (int64_t sub = par->first_step * k + 1; sub <= last; sub++) {
        events.len = 0;
        detect_walls(sim, par, &events);
        st->pair_tests += detect_pairs(sim, par, &events);
        st->events += choose_events(&events, par->n, event_of);
        move(sim, par, &events, event_of);
        if (sub % k) continue;
        if (par->print && sub < last) io_write_lines(out, sub / k, sim, par->n, 0);
        if (io_virial_due(out, sub / k)) io_virial(out, sim, sub / k);
        if (io_checkpoint_due(out, sub / k)) io_checkpoint(out, sim, sub / k);
        io_progress(out, sub / k);
    }
    st->seconds = sim_clock() - t0;
    free(events.ev);
    free(event_of);
    return 0;
}

static const Backend seq_backend = {
    "seq" SIM_SUFFIX, "",
    SIM_FEATURE_SUBSTEPS | SIM_FEATURE_PRESSURE | SIM_FEATURE_EXACT | SIM_FEATURE_CHECKPOINT |
        SIM_FEATURE_PERIODIC,
    seq_run, NULL, seq_parallel,
};

int main(int argc, char **argv)
{
    return io_main(argc, argv, &seq_backend);
}
