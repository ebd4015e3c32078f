/* omp.c: the OpenMP backend.
 *
 * For now a thin parallel version of seq.c: the all-pairs test is split over threads, each filling its
 * own event list; the lists are merged, sorted by the same key and walked in order, so the choice is
 * exactly the sequential greedy one whatever the thread count.
 */
#include "common.h"

#include <omp.h>
#include <stdlib.h>
#include <string.h>

const char backend_name[] = "omp";
const char backend_options[] = "  --threads N  OpenMP threads (default: OMP_NUM_THREADS or all cores)\n";

typedef struct {
    double t;
    int kind;
    int64_t i, j;
} Event;

typedef struct {
    Event *ev;
    size_t len, cap;
} EventList;

static void events_push(EventList *l, double t, int kind, int64_t i, int64_t j)
{
    if (l->len == l->cap) {
        l->cap = l->cap ? 2 * l->cap : 1024;
        Event *grown = realloc(l->ev, l->cap * sizeof *grown);
        if (!grown) io_fail("out of memory for %zu events", l->cap);
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

static void detect(const Sim *s, const Params *p, EventList *mine)
{
#pragma omp for schedule(dynamic, 16)
    for (int64_t i = 0; i < p->n; i++) {
        double tw = min_time(wall_time(s->x[i], s->vx[i], p->lo, p->hi),
                             wall_time(s->y[i], s->vy[i], p->lo, p->hi));
        if (tw <= 1) events_push(mine, tw, 0, i, i);
        for (int64_t j = i + 1; j < p->n; j++) {
            double t = pair_time(s->x[i], s->y[i], s->vx[i], s->vy[i], s->x[j], s->y[j], s->vx[j],
                                 s->vy[j], p->sigma2);
            if (t >= 0) events_push(mine, t, 1, i, j);
        }
    }
}

static void move_one(Sim *s, const Params *p, const Event *e, int64_t i)
{
    double lo = p->lo, hi = p->hi;
    if (!e) {
        s->x[i] = s->x[i] + s->vx[i];
        s->y[i] = s->y[i] + s->vy[i];
    } else if (e->kind == 0) {
        wall_bounce(&s->x[i], &s->y[i], &s->vx[i], &s->vy[i], e->t, lo, hi);
        finish_step(&s->x[i], &s->y[i], s->vx[i], s->vy[i], e->t, lo, hi);
        s->wc[i]++;
    } else if (i == e->i) {
        int64_t j = e->j;
        s->x[i] = s->x[i] + s->vx[i] * e->t;
        s->y[i] = s->y[i] + s->vy[i] * e->t;
        s->x[j] = s->x[j] + s->vx[j] * e->t;
        s->y[j] = s->y[j] + s->vy[j] * e->t;
        pair_bounce(s->x[i], s->y[i], &s->vx[i], &s->vy[i], s->x[j], s->y[j], &s->vx[j], &s->vy[j]);
        finish_step(&s->x[i], &s->y[i], s->vx[i], s->vy[i], e->t, lo, hi);
        finish_step(&s->x[j], &s->y[j], s->vx[j], s->vy[j], e->t, lo, hi);
        s->pc[i]++;
        s->pc[j]++;
    }
    if (!e || i == e->i || e->kind == 0) {
        s->x[i] = clamp_coord(s->x[i], lo, hi);
        s->y[i] = clamp_coord(s->y[i], lo, hi);
    }
    if (e && e->kind == 1 && i == e->i) {
        s->x[e->j] = clamp_coord(s->x[e->j], lo, hi);
        s->y[e->j] = clamp_coord(s->y[e->j], lo, hi);
    }
}

int backend_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *st)
{
    if (opt->threads > 0) omp_set_num_threads(opt->threads);
    int nt = omp_get_max_threads();
    EventList *lists = io_alloc((size_t)nt, sizeof *lists);
    EventList all = {NULL, 0, 0};
    int64_t *event_of = io_alloc((size_t)par->n, sizeof *event_of);
    double t0 = io_now();
    for (int64_t step = 1; step <= par->steps; step++) {
#pragma omp parallel
        {
            EventList *mine = &lists[omp_get_thread_num()];
            mine->len = 0;
            detect(sim, par, mine);
        }
        all.len = 0;
        for (int k = 0; k < nt; k++)
            for (size_t e = 0; e < lists[k].len; e++)
                events_push(&all, lists[k].ev[e].t, lists[k].ev[e].kind, lists[k].ev[e].i,
                            lists[k].ev[e].j);
        qsort(all.ev, all.len, sizeof *all.ev, event_cmp);
        for (int64_t i = 0; i < par->n; i++) event_of[i] = -1;
        for (size_t k = 0; k < all.len; k++) {
            const Event *e = &all.ev[k];
            if (event_of[e->i] >= 0 || event_of[e->j] >= 0) continue;
            event_of[e->i] = event_of[e->j] = (int64_t)k;
            st->events++;
        }
        st->pair_tests += (uint64_t)par->n * (uint64_t)(par->n - 1) / 2;
#pragma omp parallel for schedule(static)
        for (int64_t i = 0; i < par->n; i++)
            move_one(sim, par, event_of[i] < 0 ? NULL : &all.ev[event_of[i]], i);
        if (par->print && step < par->steps) io_write_state(out, step, sim, 0, par->n, 0);
        io_progress(out, step);
    }
    st->seconds = io_now() - t0;
    for (int k = 0; k < nt; k++) free(lists[k].ev);
    free(lists);
    free(all.ev);
    free(event_of);
    return 0;
}

int main(int argc, char **argv)
{
    return io_main(argc, argv);
}
