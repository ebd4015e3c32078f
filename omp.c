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
#include "omp_team.h"

#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char omp_options[] =
    "  --threads N  OpenMP threads (default: OMP_NUM_THREADS or all cores)\n"
    "  --check      also test every pair each step (with --exact: each time window; O(N^2)) and\n"
    "               stop with a message if the broad phase missed an event; for testing\n"
    "  --broad B    the broad phase: grid (cells as wide as the fastest disk's step), paths (each\n"
    "               disk's path through the cells it crosses), mixed (slow disks in a grid, the\n"
    "               paths of fast ones across it) or auto (default: the cheapest, step by step)\n"
    "  --lanes W    pairs of visits the paths' SIMD screens take at a time: 1, 4 (SSE2), 8\n"
    "               (AVX2) or 16 (AVX-512F); default: the widest this processor runs\n"
    "  --keep K     in a mixed step, keep only a fast disk's first K events with slow disks\n"
    "               (1 to 64, 0: all; default 8); a step where that would change the outcome\n"
    "               is found again keeping twice as many\n";

#define SEQ_FINISH 1024  /* disks still undecided at which the rounds end in a sequential walk */
#define SMALL_CHOICE 1024 /* pair events up to which a step's choice runs on one thread */
#define ASIDE_MIN 256     /* pair events from which a step's choice may run beside the moves */
#define REORDER_EVERY 8  /* steps between reorders when disks move less than a cell per step */

/* An event of the sequential finish: the key of SPEC.md 3.3 and the nodes of its disks. */
typedef struct {
    real t;
    int kind;     /* 0: wall, 1: pair */
    int32_t i, j; /* original indices */
    int32_t a, b; /* nodes */
} SeqEvent;

/* Per-thread state of the choice and the moves, padded so that threads never share a cache line. */
typedef struct {
    int64_t lo, hi;   /* this owner's segment of end, node, adj and active */
    int64_t nodes;    /* this owner's nodes, at node + lo */
    int trims_hold;   /* 1: the choice took the disk of each of this thread's trims in time */
    int64_t n_active; /* undecided nodes of this owner, at active + lo */
    uint64_t events;
    char pad[64];
} Thread;

/* A disk with an event this step (a pair event, or a wall event): the choice works on these alone,
 * so that its passes touch a few bytes per event rather than arrays over all slots, which on large
 * gases are read from beyond the cache every step. Where the broad phase leaves every disk's wall
 * event time in wall_t (the paths' and mixed steps: see walls_in_nodes), a disk with a wall event
 * and no pair event has no node: it takes its wall event whatever the others do, and the move reads
 * it there (on the fast scenes, most of a step's events). */
typedef struct {
    real wall_t;      /* its wall event time, or -1 */
    real t;           /* the time of its smallest remaining event (rounds), then of the accepted one */
    int32_t lo, cnt;  /* its pair events: adj[lo .. lo + cnt) */
    int32_t slot, id; /* id: the original index (where cnt > 0: the move and the keys need it) */
    int32_t p;        /* the node of that event's other disk (itself: wall; -1: none) */
    int32_t taken;    /* 1 once it has an accepted event: p and t are that event */
} Node;

/* One of a node's pair events: its time and its other disk (its slot, then (nodes_link) its node;
 * its original index). The rounds read a node's events in one stream, never the found lists. */
typedef struct {
    real t;
    int32_t other, other_id;
} Adj;

/* An end of an event, on its way to the thread whose range of slots holds its disk, with what the
 * choice needs of it: the time, the disk (slot, original index) and a pair event's other disk
 * (slot, original index; other = -1: a wall event). */
typedef struct {
    real t;
    int32_t slot, id;
    int32_t other, other_id;
} End;

typedef struct {
    Sim *sim;         /* the caller's state, original order: filled for printing and at the end */
    Broad b;          /* the broad phase, and the disks in slot order (b.s) */
    const Params *p;
    const Options *opt;
    Output *out;
    TextJob text;     /* print mode: the state being formatted and written */
    int nt;           /* threads in the parallel region */
    Thread *th;
    int64_t *ends;    /* nt rows of nt: ends each thread sends to each owner, then where they go; */
    size_t ends_stride; /* each row on cache lines of its own (threads count into their rows) */
    int owners;       /* threads that own the slots in this step's choice: nt, or 1 (choose_alone) */
    int64_t *bound;   /* nt + 1: where each thread's range of slots starts (range_of), and n */
    double owner_scale; /* nt / n */
    End *end;         /* the ends of the step's events, by owner */
    size_t end_cap;
    Node *node;       /* the step's nodes, by owner */
    size_t node_cap;
    Adj *adj;         /* the nodes' lists of pair events */
    size_t adj_cap;
    int32_t *active;  /* undecided nodes, each owner's in its segment */
    size_t active_cap;
    int32_t *node_of; /* n, by slot: its node this step, else -1 */
    int64_t *paired;  /* n, by slot: the last paths step it had a pair event found in (Broad's mark,
                       * for choose_move: calloc's zero pages, touched only on paths steps) */
    int64_t undecided;   /* nodes left after a round of the choice */
    SeqEvent *fin;    /* events of the sequential finish */
    size_t fin_cap;
    SeqEvent *fin_tmp; /* sort_events' buffer */
    size_t fin_tmp_cap;
    int64_t refound;  /* mixed steps found again with a larger keep */
    int64_t path_steps, mixed_steps; /* steps that used the paths' or the mixed broad phase */
    int64_t aside_steps; /* steps whose choice ran beside the moves (choose_move) */
} Work;

static void range_of(int64_t n, int tid, int nt, int64_t *from, int64_t *to)
{
    *from = n * tid / nt;
    *to = n * (tid + 1) / nt;
}

/* ==== slots ========================================================================================= */

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

/* The two ends of pair event e (x[0] its disk a's, x[1] its disk b's) and the end of wall event e. */
static inline void pair_ends(const PairEvent *e, End *x)
{
    End a = {e->t, e->a, e->i, e->b, e->j}, b = {e->t, e->b, e->j, e->a, e->i};
    x[0] = a;
    x[1] = b;
}

static inline End wall_end(const WallEvent *e)
{
    End x = {e->t, e->slot, -1, -1, -1};
    return x;
}

/* Whether this step's wall events go through the nodes: only on grid steps, whose broad phase writes
 * wall_t for the rare disks near a wall alone and lists their events (wall_lists). */
static inline int walls_in_nodes(const Work *w)
{
    return w->b.plan.mode == MODE_GRID;
}

/* Which thread's range (range_of) holds slot q: a guess in floating point, set right against the
 * ranges' bounds (no division per event: a step of a fast scene has tens of thousands). */
static inline int owner_of(const Work *w, int64_t q)
{
    int u = (int)((double)q * w->owner_scale);
    if (u > w->nt - 1) u = w->nt - 1;
    while (u > 0 && q < w->bound[u]) u--;
    while (q >= w->bound[u + 1]) u++;
    return u;
}

/* Counts the ends that thread t's broad phase found (two a pair event, one a wall event where
 * walls_in_nodes) for each of nown owners (every thread its range, or thread 0 all), into row t of
 * w->ends. */
static void ends_count(Work *w, int t, int nown)
{
    const Found *f = &w->b.th[t].found;
    int64_t *row = w->ends + (size_t)t * w->ends_stride;
    size_t walls = walls_in_nodes(w) ? f->wall_len : 0;
    for (int u = 0; u < nown; u++) row[u] = 0;
    if (nown == 1) {
        row[0] = (int64_t)(2 * f->len + walls);
        return;
    }
    for (size_t k = 0; k < f->len; k++) {
        row[owner_of(w, f->ev[k].a)]++;
        row[owner_of(w, f->ev[k].b)]++;
    }
    for (size_t k = 0; k < walls; k++) row[owner_of(w, f->wall[k].slot)]++;
}

/* Where the ends go: each owner's in a segment [lo, hi) of w->end, each thread's part of it after
 * those of the threads before it (w->ends then holds where the next one goes). An owner's nodes,
 * lists and active nodes take the same segment of their arrays: there are no more of them than
 * ends. Called by one thread. */
static void ends_scan(Work *w, int nown)
{
    int nt = w->nt;
    int64_t acc = 0;
    w->owners = nown;
    for (int u = 0; u < nt; u++) {
        w->th[u].lo = acc;
        for (int t = 0; t < nt && u < nown; t++) {
            int64_t v = w->ends[(size_t)t * w->ends_stride + (size_t)u];
            w->ends[(size_t)t * w->ends_stride + (size_t)u] = acc;
            acc += v;
        }
        w->th[u].hi = acc;
        w->th[u].n_active = 0;
        w->th[u].nodes = 0;
    }
    if (acc > INT32_MAX) sim_fail("%lld events in one step: too many", (long long)acc);
    size_t need = (size_t)acc;
    if (nown > 1) w->end = omp_scratch_grow(w->end, &w->end_cap, need, sizeof *w->end);
    w->node = omp_scratch_grow(w->node, &w->node_cap, need, sizeof *w->node);
    w->adj = omp_scratch_grow(w->adj, &w->adj_cap, need, sizeof *w->adj);
    w->active = omp_scratch_grow(w->active, &w->active_cap, need, sizeof *w->active);
}

/* Thread t's ends to their owners' segments (every thread owns its range). */
static void ends_scatter(Work *w, int t)
{
    const Found *f = &w->b.th[t].found;
    int64_t *row = w->ends + (size_t)t * w->ends_stride;
    size_t walls = walls_in_nodes(w) ? f->wall_len : 0;
    for (size_t k = 0; k < f->len; k++) {
        End x[2];
        pair_ends(&f->ev[k], x);
        w->end[row[owner_of(w, x[0].slot)]++] = x[0];
        w->end[row[owner_of(w, x[1].slot)]++] = x[1];
    }
    for (size_t k = 0; k < walls; k++) w->end[row[owner_of(w, f->wall[k].slot)]++] = wall_end(&f->wall[k]);
}

/* One end for nodes_build: in its first pass a node for the slot (node_of finds it) if it has none
 * (with the disk's wall event unless walls_in_nodes), its wall event or one more pair event; in its
 * second, the pair event into the node's list (nodes_link makes its other disk's slot a node). */
static inline void node_end(Work *w, const End *x, int fill, int64_t *nn)
{
    if (fill) {
        if (x->other >= 0) {
            Node *nd = &w->node[w->node_of[x->slot]];
            Adj a = {x->t, x->other, x->other_id};
            w->adj[nd->lo + nd->cnt++] = a;
        }
        return;
    }
    int32_t v = w->node_of[x->slot];
    if (v < 0) {
        v = (int32_t)(*nn)++;
        Node fresh = {walls_in_nodes(w) ? -1 : w->b.wall_t[x->slot], 0, 0, 0, x->slot, -1, -1, 0};
        w->node[v] = fresh;
        w->node_of[x->slot] = v;
    }
    Node *nd = &w->node[v];
    if (x->other < 0) {
        nd->wall_t = x->t;
    } else {
        nd->id = x->id;
        nd->cnt++;
    }
}

/* A pass of nodes_build over owner u's ends: those ends_scatter gave it or, where one owner holds all
 * slots, the threads' lists themselves (no copy of them). */
static void nodes_pass(Work *w, int u, int fill, int64_t *nn)
{
    if (w->owners > 1) {
        for (int64_t k = w->th[u].lo; k < w->th[u].hi; k++) node_end(w, &w->end[k], fill, nn);
        return;
    }
    for (int t = 0; t < w->nt; t++) {
        const Found *f = &w->b.th[t].found;
        size_t walls = walls_in_nodes(w) && !fill ? f->wall_len : 0;
        for (size_t k = 0; k < f->len; k++) {
            End x[2];
            pair_ends(&f->ev[k], x);
            node_end(w, &x[0], fill, nn);
            node_end(w, &x[1], fill, nn);
        }
        for (size_t k = 0; k < walls; k++) {
            End x = wall_end(&f->wall[k]);
            node_end(w, &x, fill, nn);
        }
    }
}

/* Owner u's nodes from its ends: one a slot with an event, with its wall event and the list of its
 * pair events (CSR in adj). A node with a wall event and no pair event keeps its wall event; the
 * others are the owner's active nodes, which go to the rounds of choose_events. */
static void nodes_build(Work *w, int u)
{
    Thread *th = &w->th[u];
    int64_t lo = th->lo, nn = lo;
    nodes_pass(w, u, 0, &nn);
    int32_t *act = w->active + lo;
    int64_t na = 0;
    int32_t pos = (int32_t)lo;
    for (int64_t v = lo; v < nn; v++) {
        Node *nd = &w->node[v];
        nd->lo = pos;
        pos += nd->cnt;
        if (nd->cnt > 0) {
            act[na++] = (int32_t)v;
        } else {
            nd->taken = 1;
            nd->p = (int32_t)v;
            nd->t = nd->wall_t;
        }
        nd->cnt = 0;
    }
    th->n_active = na;
    th->nodes = nn - lo;
    nodes_pass(w, u, 1, &nn);
}

/* The node of the other disk of each pair event in owner u's lists, in place of its slot (once every
 * owner has built its nodes). */
static void nodes_link(Work *w, int u)
{
    const int32_t *act = w->active + w->th[u].lo;
    for (int64_t k = 0; k < w->th[u].n_active; k++) {
        const Node *nd = &w->node[act[k]];
        for (int32_t a = nd->lo; a < nd->lo + nd->cnt; a++)
            w->adj[a].other = w->node_of[w->adj[a].other];
    }
}

/* Gathers the threads' events into nodes (see Node), each thread those of its range of slots, and
 * starts the choice. */
static void build_nodes(Work *w, int tid)
{
    ends_count(w, tid, w->nt);
#pragma omp barrier
#pragma omp single
    ends_scan(w, w->nt);
    if (w->nt > 1) ends_scatter(w, tid);
#pragma omp barrier
    nodes_build(w, tid);
#pragma omp barrier
    nodes_link(w, tid);
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
    w->fin_tmp = sim_grow(w->fin_tmp, &w->fin_tmp_cap, len, sizeof *w->fin_tmp);
    sort_events(w->fin, len, w->fin_tmp);
    for (size_t u = 0; u < len; u++) {
        const SeqEvent *e = &w->fin[u];
        Node *a = &w->node[e->a], *b = &w->node[e->b];
        if (a->taken || b->taken) continue;
        a->taken = b->taken = 1;
        a->p = e->b;
        b->p = e->a;
        a->t = b->t = e->t;
    }
}

/* The last undecided nodes: their remaining events sorted and walked, as seq.c does. */
static void finish_sequential(Work *w)
{
    size_t len = 0;
    for (int t = 0; t < w->nt; t++) {
        for (int64_t k = 0; k < w->th[t].n_active; k++) {
            int32_t v = w->active[w->th[t].lo + k];
            const Node *nd = &w->node[v];
            w->fin = sim_grow(w->fin, &w->fin_cap, len + 1, sizeof *w->fin);
            if (nd->wall_t >= 0) {
                SeqEvent e = {nd->wall_t, 0, nd->id, nd->id, v, v};
                w->fin[len++] = e;
            }
            /* each pair event once, from its disk of lower original index */
            for (int32_t a = nd->lo; a < nd->lo + nd->cnt; a++) {
                const Adj *ad = &w->adj[a];
                if (ad->other_id < nd->id || w->node[ad->other].taken) continue;
                w->fin = sim_grow(w->fin, &w->fin_cap, len + 1, sizeof *w->fin);
                SeqEvent e = {ad->t, 1, nd->id, ad->other_id, v, ad->other};
                w->fin[len++] = e;
            }
        }
    }
    walk_events(w, len);
}

/* A round's first half over the undecided nodes act[0 .. na): each finds its smallest event among
 * those whose disks are all free (p: the other node, itself for its wall event; t: the time). */
static void round_best(Work *w, const int32_t *act, int64_t na)
{
    Node *node = w->node;
    for (int64_t k = 0; k < na; k++) {
        int32_t v = act[k], bp = -1, bi = 0, bj = 0, bk = 0;
        Node *nd = &node[v];
        real bt = 0;
        if (nd->wall_t >= 0) {
            bp = v;
            bi = bj = nd->id;
            bt = nd->wall_t;
        }
        for (int32_t a = nd->lo; a < nd->lo + nd->cnt; a++) {
            const Adj *ad = &w->adj[a];
            if (node[ad->other].taken) continue;
            int32_t i = nd->id < ad->other_id ? nd->id : ad->other_id;
            int32_t j = nd->id < ad->other_id ? ad->other_id : nd->id;
            if (bp < 0 || event_before(ad->t, 1, i, j, bt, bk, bi, bj)) {
                bp = ad->other;
                bt = ad->t;
                bk = 1;
                bi = i;
                bj = j;
            }
        }
        nd->p = bp;
        nd->t = bt;
    }
}

/* A round's second half, once every node has its smallest event: an event that is the smallest of
 * each of its disks is accepted (a pair marked by its node of lower index; both have its time
 * already). Keeps the nodes still undecided at the front of act; returns how many. */
static int64_t round_accept(Work *w, int32_t *act, int64_t na)
{
    Node *node = w->node;
    int64_t kept = 0;
    for (int64_t k = 0; k < na; k++) {
        int32_t v = act[k], bp = node[v].p;
        if (bp < 0) continue;
        if (bp == v) {
            node[v].taken = 1;
        } else if (node[bp].p == v) {
            if (v < bp) node[v].taken = node[bp].taken = 1;
        } else {
            act[kept++] = v;
        }
    }
    return kept;
}

/* Rounds: every undecided node finds its smallest event among those whose disks are all free; an
 * event that is the smallest of each of its disks is accepted. The global smallest always is, so
 * every round makes progress; once few disks remain the sequential walk ends the step. */
static void choose_events(Work *w, int tid)
{
    Thread *th = &w->th[tid];
    int32_t *act = w->active + th->lo;
    int64_t na = th->n_active;
    for (;;) {
        round_best(w, act, na);
#pragma omp barrier
        na = round_accept(w, act, na);
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

/* The whole choice on the calling thread, for steps with few pair events (the barriers of the
 * parallel rounds would cost more) or beside the others' moves (choose_move): thread 0 owns every
 * node, the rounds need no barrier, and the walk decides the last ones. */
static void choose_alone(Work *w)
{
    for (int t = 0; t < w->nt; t++) ends_count(w, t, 1);
    ends_scan(w, 1);
    nodes_build(w, 0);
    nodes_link(w, 0);
    Thread *th = &w->th[0];
    int32_t *act = w->active + th->lo;
    while (th->n_active > SEQ_FINISH) {
        round_best(w, act, th->n_active);
        th->n_active = round_accept(w, act, th->n_active);
    }
    finish_sequential(w);
}

/* ==== moving (SPEC.md 3.4, 3.5) ======================================================================= */

/* Which disk of an accepted pair moves both, of original indices self and other: the lower index
 * where their sum is even, else the higher. Both threads decide alike, and each thread moves about
 * half of the pairs it has disks of, whichever thread's range holds the lower indices (they are
 * unbalanced where slots keep the original order: the lower index of a random pair lies in the
 * first half of the slots three times in four). */
static inline int pair_mover(int32_t self, int32_t other)
{
    return (self ^ other) & 1 ? self > other : self < other;
}

/* What a thread's moves leave for the next step's plan: the largest velocity component, and the
 * events. */
typedef struct {
    real vm;
    uint64_t events;
} Moved;

/* What every move of a thread reads: the slots, the box, wall_t where it holds wall events (NULL
 * where walls_in_nodes), and the thread's notes for the next step's plan. */
typedef struct {
    Slots *s;
    real lo, hi;
    double inv_span;
    const real *wall_t;
    BroadThread *th;
    int periodic; /* SPEC.md 7: the coordinates into [0, L) rather than clamped */
    real L, half;
} Mover;

static Mover mover_of(Work *w, int tid)
{
    Mover c = {&w->b.s, w->p->lo, w->p->hi, 1 / ((double)w->p->hi - (double)w->p->lo),
               walls_in_nodes(w) ? NULL : w->b.wall_t, &w->b.th[tid], w->p->periodic, w->p->L, w->p->half};
    return c;
}

/* Whether the disk in slot i, whose node is v (-1: none), flies freely this step: no node, and no
 * wall event in wall_t. */
static inline int flies(const real *wall_t, int64_t i, int32_t v)
{
    return v < 0 && !(wall_t && wall_t[i] >= 0);
}

/* The move of a disk that flies freely (most of them: inline in the loops, whose box bounds stay in
 * registers); in the periodic box (wrap; lo unused, hi = L) into [0, L). */
static inline void fly(Slots *s, int64_t i, real lo, real hi, int wrap, Moved *m)
{
    if (wrap) {
        s->x[i] = wrap_coord(s->x[i] + s->vx[i], hi);
        s->y[i] = wrap_coord(s->y[i] + s->vy[i], hi);
    } else {
        s->x[i] = clamp_coord(s->x[i] + s->vx[i], lo, hi);
        s->y[i] = clamp_coord(s->y[i] + s->vy[i], lo, hi);
    }
    m->vm = fastest(m->vm, s->vx[i], s->vy[i]);
}

/* Disk i's centre into the box after its event: clamped (3.4) or into [0, L) (SPEC.md 7). */
static inline void into_box(Slots *s, int64_t i, const Mover *c)
{
    s->x[i] = c->periodic ? wrap_coord(s->x[i], c->L) : clamp_coord(s->x[i], c->lo, c->hi);
    s->y[i] = c->periodic ? wrap_coord(s->y[i], c->L) : clamp_coord(s->y[i], c->lo, c->hi);
}

/* Moves the disk in slot i that has an event or a node v (-1: none; node_of[i] is then left -1 for
 * the next step): its wall event, or a pair from the disk pair_mover names, both disks (a node
 * whose event another node's disk moves, or that has none, flies). Notes the disks' next steps for
 * the next step's plan, and adds to *m. */
static void move_event(Work *w, const Mover *c, int64_t i, int32_t v, Moved *m)
{
    Slots *s = c->s;
    const Node *node = NULL; /* read only where v has one: choose_move's chooser may be growing it */
    real lo = c->lo, hi = c->hi;
    int32_t p = -1;
    int wall = 0;
    real t = 0;
    if (v >= 0) {
        node = w->node;
        w->node_of[i] = -1;
        if (node[v].taken) {
            p = node[v].p;
            t = node[v].t;
            wall = p == v;
        }
    } else {
        wall = 1;
        t = c->wall_t[i];
    }
    if (wall) {
        real vx0 = s->vx[i], vy0 = s->vy[i];
        wall_bounce(&s->x[i], &s->y[i], &s->vx[i], &s->vy[i], t, lo, hi);
        if (s->wi) s->wi[i] += wall_impulse(vx0, vy0, s->vx[i], s->vy[i]);
        finish_step(&s->x[i], &s->y[i], s->vx[i], s->vy[i], t, lo, hi);
        s->wc[i]++;
        m->events++;
    } else if (p < 0) {
        fly(s, i, lo, c->periodic ? c->L : hi, c->periodic, m);
        return;
    } else if (pair_mover(node[v].id, node[p].id)) {
        int64_t j = node[p].slot, a = i, b = j; /* a: the lower original index */
        if (node[p].id < node[v].id) {
            a = j;
            b = i;
        }
        BroadThread *th = c->th;
        note_speed(th->speed_n, th->speed_s1, s->vx[i], s->vy[i], c->inv_span, -1);
        note_speed(th->speed_n, th->speed_s1, s->vx[j], s->vy[j], c->inv_span, -1);
        if (c->periodic) {
            real dp = pair_collide_wrap(&s->x[a], &s->y[a], &s->vx[a], &s->vy[a], &s->x[b], &s->y[b],
                                        &s->vx[b], &s->vy[b], t, c->L, c->half);
            if (s->wi) s->wi[a] += dp, s->wi[b] += dp; /* the virial's impulses (SPEC.md 7a) */
        } else {
            pair_collide(&s->x[a], &s->y[a], &s->vx[a], &s->vy[a], &s->x[b], &s->y[b], &s->vx[b],
                         &s->vy[b], t, lo, hi);
        }
        s->pc[i]++;
        s->pc[j]++;
        m->events++;
        into_box(s, j, c);
        m->vm = fastest(m->vm, s->vx[j], s->vy[j]);
        note_speed(th->speed_n, th->speed_s1, s->vx[i], s->vy[i], c->inv_span, 1);
        note_speed(th->speed_n, th->speed_s1, s->vx[j], s->vy[j], c->inv_span, 1);
    } else {
        return;
    }
    into_box(s, i, c);
    m->vm = fastest(m->vm, s->vx[i], s->vy[i]);
}

/* Moves the disks of this thread's range and notes the largest velocity component it leaves and
 * its events. node_of is left all -1 for the next step. */
/* Moves the disks of slots [from, to) but those marked with step (mark: the choice's, of paths steps
 * whose choice runs beside the moves; NULL: every disk, by its node). A loop for each box (wrap), so
 * that the walled box's flights stay as they were: move_slots is inline with wrap a constant. */
static inline void move_slots(Work *w, const Mover *c, int64_t from, int64_t to, const int64_t *mark,
                              int64_t step, int wrap, Moved *m)
{
    Slots *s = c->s;
    real lo = c->lo, hi = wrap ? c->L : c->hi;
    const real *wall_t = c->wall_t;
    for (int64_t i = from; i < to; i++) {
        if (mark && mark[i] == step) continue;
        int32_t v = mark ? -1 : w->node_of[i];
        if (flies(wall_t, i, v)) fly(s, i, lo, hi, wrap, m);
        else move_event(w, c, i, v, m);
    }
}

static inline void move_slots_in_box(Work *w, const Mover *c, int64_t from, int64_t to, const int64_t *mark,
                                     int64_t step, Moved *m)
{
    if (c->periodic) move_slots(w, c, from, to, mark, step, 1, m);
    else move_slots(w, c, from, to, mark, step, 0, m);
}

static void move_range(Work *w, int tid)
{
    Moved m = {0, 0};
    Mover c = mover_of(w, tid);
    int64_t from, to;
    range_of(w->p->n, tid, w->nt, &from, &to);
    move_slots_in_box(w, &c, from, to, NULL, 0, &m);
    c.th->vmax = m.vm;
    w->th[tid].events += m.events;
}

/* The pair events the threads found this step (every thread counts them itself, so that all take
 * the same branch on it). */
static size_t events_found(const Work *w)
{
    size_t total = 0;
    for (int t = 0; t < w->nt; t++) total += w->b.th[t].found.len;
    return total;
}

/* The choice and the moves of a paths step whose choice is small against its moves (choose_aside):
 * one thread chooses alone while the others move the disks without pair events, which need no
 * choice (the slots whose mark, found_push's, is not this step); the threads take those in chunks,
 * the chooser too once it is done. Then, the choice made, the disks of the nodes, split over the
 * threads. */
static void choose_move(Work *w, int tid, int64_t step)
{
    Moved m = {0, 0};
    Mover c = mover_of(w, tid);
    int64_t n = w->p->n, chunk = n / (8 * w->nt) + 1;
    const int64_t *mark = w->paired;
#pragma omp single nowait
    {
        choose_alone(w);
        phase_mark(&w->b, tid, PHASE_CHOICE);
    }
#pragma omp for schedule(dynamic, 1) nowait
    for (int64_t k = 0; k < (n + chunk - 1) / chunk; k++) {
        int64_t to = (k + 1) * chunk < n ? (k + 1) * chunk : n;
        move_slots_in_box(w, &c, k * chunk, to, mark, step, &m);
    }
    phase_mark(&w->b, tid, PHASE_MOVE);
#pragma omp barrier
    phase_mark(&w->b, tid, PHASE_WAIT);
    int64_t from, to;
    range_of(w->th[0].nodes, tid, w->nt, &from, &to);
    for (int64_t v = w->th[0].lo + from; v < w->th[0].lo + to; v++)
        move_event(w, &c, w->node[v].slot, (int32_t)v, &m);
    c.th->vmax = m.vm;
    w->th[tid].events += m.events;
    phase_mark(&w->b, tid, PHASE_MOVE);
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

/* The greedy choice (3.3) of the step's events: on one thread when there are few pair events, else
 * in rounds (every thread counts the events itself, so all take the same branch). */
static void choose(Work *w, int tid)
{
    if (events_found(w) <= SMALL_CHOICE) {
#pragma omp single
        choose_alone(w);
    } else {
        build_nodes(w, tid);
        choose_events(w, tid);
#pragma omp barrier
    }
}

/* Whether this step's choice may run on one thread while the others move (choose_move): a paths step
 * (no trims to check; wall_t holds every disk's wall event) on two or more threads, whose choice
 * fits in the time the other threads take to move the disks. A pair event costs the choice about
 * twice what moving a disk costs (--stats, one thread, the assignment's scene of 1e4 disks). Below
 * ASIDE_MIN pair events the choice takes a few microseconds, less than the moves' chunks and their
 * barrier cost (the assignment's sample has about 24 a step). */
static int aside_fits(const Work *w)
{
    if (w->nt < 2 || w->b.plan.mode != MODE_PATHS) return 0;
    size_t e = events_found(w);
    return e >= ASIDE_MIN && 2.0 * (double)e * (double)(w->nt - 1) <= (double)w->p->n;
}

/* choose_move needs this step's marks, which found_push writes only where the step before fitted
 * too (step_run): on steps with many pair events, as at 1e5 disks, they would cost stores to lines
 * that other cores hold, for nothing. */
static int choose_aside(const Work *w)
{
    return w->b.mark && aside_fits(w);
}

/* Whether the choice took the fast disk of each of this thread's trims (SlowGrid's keep) at a key
 * smaller than the smallest it left out: then the greedy walk rejects every event left out, and so
 * takes the same events as with them. A trimmed disk has pair events, so it has a node, and so has
 * each partner, with its original index. */
static int trims_hold(const Work *w, int tid)
{
    const Found *f = &w->b.th[tid].found;
    for (size_t k = 0; k < f->trim_len; k++) {
        const PairEvent *c = &f->trim[k];
        int32_t v = w->node_of[c->a];
        const Node *nd = &w->node[v];
        if (!nd->taken) return 0;
        int32_t i = nd->id, j = nd->id, kind = nd->p != v;
        if (kind) {
            int32_t o = w->node[nd->p].id;
            i = o < i ? o : i;
            j = o < j ? j : o;
        }
        if (!event_before(nd->t, kind, i, j, c->t, 1, c->i, c->j)) return 0;
    }
    return 1;
}

/* Every slot of owner u's nodes back to having none, for the step to be found again. */
static void nodes_clear(Work *w, int u)
{
    for (int64_t v = w->th[u].lo; v < w->th[u].lo + w->th[u].nodes; v++) w->node_of[w->node[v].slot] = -1;
}

static void step_run(Work *w, int tid, int64_t step)
{
    const Params *p = w->p;

    /* wall events (3.1) and pair events (3.2): a broad phase, its surviving pairs through the
     * narrow phase; reordered every few steps, and on a run's first step too (a resumed run starts
     * from the original order); then the choice. A mixed step whose trims do not hold is found and
     * chosen again keeping twice as many events, under the same plan (rare: the first partners of a
     * fast disk must all have been taken by earlier events). */
    int first = step == p->first_step * p->substeps + 1, reorder = step % REORDER_EVERY == 1 || first;
    phase_mark(&w->b, tid, PHASE_OTHER);
    int aside = 0, again = 0;
    for (;;) {
        broad_find(&w->b, tid, step, reorder, again);
        if (choose_aside(w)) {
            choose_move(w, tid, step);
            aside = 1;
            break;
        }
        choose(w, tid);
        phase_mark(&w->b, tid, PHASE_CHOICE);
        if (w->b.plan.mode != MODE_MIXED || w->b.keep == 0) break;
        w->th[tid].trims_hold = trims_hold(w, tid);
#pragma omp barrier
        int hold = 1;
        for (int t = 0; t < w->nt; t++) hold &= w->th[t].trims_hold;
        if (hold) break;
        nodes_clear(w, tid);
#pragma omp barrier
#pragma omp single
        {
            w->b.keep = 2 * w->b.keep > SIM_KEEP_MOST ? 0 : 2 * w->b.keep;
            w->refound++;
        }
        reorder = 0;
        again = 1;
    }
    phase_mark(&w->b, tid, PHASE_CHOICE);
    if (tid == 0) { /* read at the end of the run only */
        w->path_steps += w->b.plan.mode == MODE_PATHS;
        w->mixed_steps += w->b.plan.mode == MODE_MIXED;
        w->aside_steps += aside;
        /* the next step's broad phase marks its pair events where this one fitted choose_move (read
         * after the move's barrier; a scene's count of pair events moves little from step to step) */
        w->b.mark = aside_fits(w) ? w->paired : NULL;
    }

    /* the moves (3.4, 3.5) */
    if (!aside) move_range(w, tid);
    phase_mark(&w->b, tid, PHASE_MOVE);
#pragma omp barrier
    phase_mark(&w->b, tid, PHASE_WAIT);
    int64_t k = p->substeps;
    if (step % k) return;
    if (p->print && step < p->steps * k) print_state(w, tid, step / k);
    int ck = io_checkpoint_due(w->out, step / k), vir = io_virial_due(w->out, step / k);
    if (ck || vir) {
        if (!p->print) slots_unpermute(w, tid); /* print_state has done it */
#pragma omp barrier
#pragma omp single
        {
            if (vir) io_virial(w->out, w->sim, step / k);
            if (ck) io_checkpoint(w->out, w->sim, step / k);
        }
    }
    /* no barrier after it: the next step's plan waits for every thread anyway, and the progress
     * line reads nothing the others write */
#pragma omp single nowait
    io_progress(w->out, step / k);
}

/* --stats: where the step loop went, each phase's mean over the threads (phase_mark). */
static void print_phases(const Broad *b, int nt)
{
    static const char *name[PHASES] = {"plan", "binning", "pairs", "choice", "move",
                                       "waiting at barriers", "output and the final order"};
    double all = 0;
    fprintf(stderr, "%s: the step loop's phases, mean of %d threads:", sim_program, nt);
    for (int k = 0; k < PHASES; k++) {
        double mean = 0;
        for (int t = 0; t < nt; t++) mean += b->th[t].phase_s[k] / nt;
        all += mean;
        fprintf(stderr, "%s %s %.4f s", k ? "," : "", name[k], mean);
    }
    fprintf(stderr, " (%.4f s in all)\n", all);
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
        w->node_of[i] = -1;
        s->pc[i] = sim->pc[i];
        s->wc[i] = sim->wc[i];
        if (sim->wi) s->wi[i] = sim->wi[i];
        th->vmax = fastest(th->vmax, sim->vx[i], sim->vy[i]);
        note_speed(th->speed_n, th->speed_s1, sim->vx[i], sim->vy[i], inv_span, 1);
    }
#pragma omp barrier
}

static void omp_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    int nt = threads > 0 ? threads : omp_get_max_threads();
    team_start(nt);
#pragma omp parallel for schedule(dynamic, 1) num_threads(nt)
    for (int64_t k = 0; k < tasks; k++) task(ctx, k);
}

static int omp_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *st)
{
    if (opt->threads > 0) omp_set_num_threads(opt->threads);
    omp_set_dynamic(0);
    team_start(omp_get_max_threads());
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
    w.b.wall_lists = 1;
    w.b.timing = opt->stats;
    w.b.keep = opt->keep < 0 ? KEEP_FIRST : opt->keep;
    w.th = sim_calloc_lines((size_t)nt_max, sizeof *w.th);
    w.ends_stride = ((size_t)nt_max + 7) / 8 * 8; /* 8 counts a cache line */
    w.ends = sim_calloc_lines((size_t)nt_max * w.ends_stride, sizeof *w.ends);
    w.bound = sim_calloc((size_t)nt_max + 1, sizeof *w.bound);
    w.node_of = sim_calloc((size_t)n, sizeof *w.node_of);
    w.paired = sim_calloc((size_t)n, sizeof *w.paired);
    w.b.mark = w.paired; /* the first step marks (step_run) */

    double t0 = 0;
#pragma omp parallel
    {
#pragma omp single
    {
        w.nt = w.b.nt = omp_get_num_threads();
        for (int t = 0; t < w.nt; t++) range_of(n, t, w.nt, &w.bound[t], &w.bound[t + 1]); /* owner_of */
        w.owner_scale = (double)w.nt / (double)n;
    }
        int tid = omp_get_thread_num();
        slots_fill(&w, tid);
#pragma omp single
        t0 = sim_clock(); /* the step loop from here */
        w.b.th[tid].phase_at = sim_clock();
        for (int64_t step = par->first_step * par->substeps + 1; step <= par->steps * par->substeps; step++)
            step_run(&w, tid, step);
        slots_unpermute(&w, tid);
        phase_mark(&w.b, tid, PHASE_OTHER);
    }
    st->seconds = sim_clock() - t0;

    uint64_t visits = 0, overlaps = 0, trimmed = 0;
    for (int t = 0; t < nt_max; t++) {
        visits += w.b.th[t].found.visits;
        overlaps += w.b.th[t].found.overlaps;
        trimmed += w.b.th[t].found.trimmed;
        st->pair_tests += w.b.th[t].found.tests;
        st->events += w.th[t].events;
    }
    int64_t steps = par->steps * par->substeps;
    if (opt->stats) {
        double ps = (double)(w.path_steps + w.mixed_steps) * (double)n;
        fprintf(stderr,
                "%s: broad phase: grid in %lld, paths in %lld, mixed in %lld of %lld steps; paths: "
                "%.4g cells visited and %.4g pairs of visits overlapping in time per particle-step\n",
                sim_program, (long long)(steps - w.path_steps - w.mixed_steps),
                (long long)w.path_steps, (long long)w.mixed_steps, (long long)steps,
                ps > 0 ? visits / ps : 0.0, ps > 0 ? overlaps / ps : 0.0);
        if (ps > 0)
            fprintf(stderr, "%s: paths: pairs of visits screened %d at a time\n", sim_program,
                    paths_lanes(w.b.paths));
        if (w.path_steps > 0)
            fprintf(stderr, "%s: the choice on one thread beside the moves in %lld of %lld steps\n",
                    sim_program, (long long)w.aside_steps, (long long)steps);
        if (w.mixed_steps)
            fprintf(stderr,
                    "%s: mixed steps: %llu times a fast disk's events with slow disks trimmed to "
                    "its first %d (0: all, by the end); %lld steps found again keeping more\n",
                    sim_program, (unsigned long long)trimmed, w.b.keep, (long long)w.refound);
        print_phases(&w.b, w.nt);
    }
    broad_free(&w.b);
    free(w.th);
    free(w.ends);
    free(w.bound);
    free(w.end);
    free(w.node);
    free(w.adj);
    free(w.active);
    free(w.node_of);
    free(w.paired);
    free(w.fin);
    free(w.fin_tmp);
    return 0;
}

static const Backend omp_backend = {
    "omp" SIM_SUFFIX, omp_options,
    SIM_FEATURE_SUBSTEPS | SIM_FEATURE_PRESSURE | SIM_FEATURE_EXACT | SIM_FEATURE_CHECKPOINT |
        SIM_FEATURE_THREADS | SIM_FEATURE_LANES | SIM_FEATURE_PERIODIC,
    omp_run, NULL, omp_parallel,
};

int main(int argc, char **argv)
{
    return io_main(argc, argv, &omp_backend);
}
