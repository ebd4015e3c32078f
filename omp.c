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

/* An event of the sequential finish: the key of SPEC.md 3.3 and the slots of its disks. */
typedef struct {
    real t;
    int kind;     /* 0: wall, 1: pair */
    int32_t i, j; /* original indices */
    int32_t a, b; /* slots */
} SeqEvent;

/* Per-thread state of the choice and the moves, padded so that threads never share a cache line. */
typedef struct {
    int64_t n_active; /* undecided disks of this thread's range, at active + range start */
    int64_t partial;  /* this thread's part of a prefix sum */
    size_t ev_off;    /* where this thread's events go in the gathered list */
    uint64_t events;
    char pad[64];
} Thread;

typedef struct {
    Sim *sim;         /* the caller's state, original order: filled for printing and at the end */
    Broad b;          /* the broad phase, and the disks in slot order (b.s) */
    const Params *p;
    const Options *opt;
    Output *out;
    TextJob text;     /* print mode: the state being formatted and written */
    int nt;           /* threads in the parallel region */
    Thread *th;
    /* the rest is indexed by slot */
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

/* ==== slots ========================================================================================= */

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
    const Slots *s = &w->b.s;
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
            total += w->b.th[t].found.len;
        }
        w->n_ev = total;
        w->ev = omp_grow(w->ev, &w->ev_cap, total, sizeof *w->ev);
        w->adj = omp_grow(w->adj, &w->adj_cap, 2 * total, sizeof *w->adj);
        w->off[n] = (int64_t)(2 * total);
    }
    Thread *th = &w->th[tid];
    const Found *f = &w->b.th[tid].found;
    if (f->len) memcpy(w->ev + th->ev_off, f->ev, f->len * sizeof *w->ev);
    range_of(n, tid, nt, &from, &to);
    for (int64_t q = from; q < to; q++) {
        w->off[q] = 0;
        w->taken[q] = 0;
        w->acc_p[q] = -1;
    }
#pragma omp barrier
    for (size_t e = th->ev_off; e < th->ev_off + f->len; e++) {
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
        } else if (w->b.wall_t[q] >= 0) {
            w->taken[q] = 1;
            w->acc_p[q] = (int32_t)q;
            w->acc_t[q] = w->b.wall_t[q];
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
    for (size_t e = th->ev_off; e < th->ev_off + f->len; e++) {
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
        const Found *f = &w->b.th[t].found;
        w->fin = omp_grow(w->fin, &w->fin_cap, len + 3 * f->len, sizeof *w->fin);
        for (size_t k = 0; k < f->len; k++) {
            const PairEvent *pe = &f->ev[k];
            SeqEvent e = {pe->t, 1, pe->i, pe->j, pe->a, pe->b};
            w->fin[len++] = e;
            int32_t ends[2] = {pe->a, pe->b};
            for (int u = 0; u < 2; u++) {
                int32_t q = ends[u];
                if (w->taken[q] || w->b.wall_t[q] < 0) continue;
                w->taken[q] = 1; /* marks the wall event as listed; cleared before the walk */
                SeqEvent x = {w->b.wall_t[q], 0, w->b.s.id[q], w->b.s.id[q], q, q};
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
    const Slots *s = &w->b.s;
    size_t len = 0;
    for (int t = 0; t < w->nt; t++) {
        int64_t from, to;
        range_of(w->p->n, t, w->nt, &from, &to);
        for (int64_t k = 0; k < w->th[t].n_active; k++) {
            int32_t q = w->active[from + k];
            w->fin = omp_grow(w->fin, &w->fin_cap, len + 1, sizeof *w->fin);
            if (w->b.wall_t[q] >= 0) {
                SeqEvent e = {w->b.wall_t[q], 0, s->id[q], s->id[q], q, q};
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
    const int32_t *id = w->b.s.id;
    Thread *th = &w->th[tid];
    int64_t from, to;
    range_of(w->p->n, tid, w->nt, &from, &to);
    int32_t *act = w->active + from;
    int64_t na = th->n_active;
    for (;;) {
        for (int64_t k = 0; k < na; k++) {
            int32_t q = act[k], bp = -1, bi = 0, bj = 0, bk = 0;
            real bt = 0;
            if (w->b.wall_t[q] >= 0) {
                bp = q;
                bi = bj = id[q];
                bt = w->b.wall_t[q];
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
        w->acc_p[q] = w->b.wall_t[q] >= 0 ? (int32_t)q : -1;
        w->acc_t[q] = w->b.wall_t[q];
    }
}

/* ==== moving (SPEC.md 3.4, 3.5) ======================================================================= */

/* Moves the disks of this thread's range (a pair from its lower original index, both disks) and
 * notes the largest velocity component it leaves and the disks' next steps, for the next step's
 * plan. */
static void move_range(Work *w, int tid)
{
    Slots *s = &w->b.s;
    real lo = w->p->lo, hi = w->p->hi, vm = 0;
    double inv_span = 1 / ((double)hi - (double)lo);
    BroadThread *th = &w->b.th[tid];
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
    w->th[tid].events += events;
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

    /* wall events (3.1) and pair events (3.2): a broad phase, its surviving pairs through the
     * narrow phase; reordered every few steps, and on a run's first step too (a resumed run starts
     * from the original order) */
    int first = step == p->first_step * p->substeps + 1;
    broad_find(&w->b, tid, step, step % REORDER_EVERY == 1 || first);

    /* the greedy choice (3.3): on one thread when there are few pair events, else in rounds (every
     * thread counts the events itself, so all take the same branch) */
    size_t total = 0;
    for (int t = 0; t < w->nt; t++) total += w->b.th[t].found.len;
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
    Slots *s = &w->b.s;
    BroadThread *th = &w->b.th[tid];
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
    broad_init(&w.b, par, opt, n, nt_max, sim->wi != NULL);
    w.th = sim_calloc((size_t)nt_max, sizeof *w.th);
    w.off = sim_calloc((size_t)n + 1, sizeof *w.off);
    w.active = sim_calloc((size_t)n, sizeof *w.active);
    w.best_p = sim_calloc((size_t)n, sizeof *w.best_p);
    w.best_t = sim_calloc((size_t)n, sizeof *w.best_t);
    w.acc_p = sim_calloc((size_t)n, sizeof *w.acc_p);
    w.acc_t = sim_calloc((size_t)n, sizeof *w.acc_t);
    w.taken = sim_calloc((size_t)n, sizeof *w.taken);

    double t0 = 0;
#pragma omp parallel
    {
#pragma omp single
        w.nt = w.b.nt = omp_get_num_threads();
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
        visits += w.b.th[t].found.visits;
        overlaps += w.b.th[t].found.overlaps;
        st->pair_tests += w.b.th[t].found.tests;
        st->events += w.th[t].events;
    }
    int64_t steps = par->steps * par->substeps;
    if (opt->stats) {
        double ps = (double)(w.b.path_steps + w.b.mixed_steps) * (double)n;
        fprintf(stderr,
                "%s: broad phase: grid in %lld, paths in %lld, mixed in %lld of %lld steps; paths: "
                "%.4g cells visited and %.4g pairs of visits overlapping in time per particle-step\n",
                backend_name, (long long)(steps - w.b.path_steps - w.b.mixed_steps),
                (long long)w.b.path_steps, (long long)w.b.mixed_steps, (long long)steps,
                ps > 0 ? visits / ps : 0.0, ps > 0 ? overlaps / ps : 0.0);
    }
    broad_free(&w.b);
    free(w.th);
    free(w.ev);
    free(w.off);
    free(w.adj);
    free(w.active);
    free(w.best_p);
    free(w.best_t);
    free(w.acc_p);
    free(w.acc_t);
    free(w.taken);
    free(w.fin);
    free(w.fin_tmp);
    return 0;
}

int main(int argc, char **argv)
{
    return io_main(argc, argv);
}
