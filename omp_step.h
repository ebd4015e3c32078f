/* omp_step.h: what omp.c's step shares with the broad phase of fast scenes (omp_paths.c).
 *
 * omp keeps the disks in slots (an order of its own, for locality); each slot remembers its disk's
 * original index, which alone decides the event order and the output order. A broad phase finds the
 * step's pair events into per-thread lists; omp.c then chooses among them and moves the disks.
 */
#ifndef OMP_STEP_H
#define OMP_STEP_H

#include "common.h"

/* The disks in slot order: SoA like Sim, plus each slot's original index. */
typedef struct {
    real *x, *y, *vx, *vy;
    int32_t *id, *pc, *wc;
    double *wi; /* --pressure only, else NULL */
} Slots;

/* A pair event: its time and original indices i < j (the key of SPEC.md 3.3), and their slots. */
typedef struct {
    real t;
    int32_t i, j;
    int32_t a, b;
} PairEvent;

/* What one thread's broad phase finds in a step: pair events, the exact tests (pair_time) done, and
 * for the paths (--stats) the cells visited and the pairs of visits that overlap in time. */
typedef struct {
    PairEvent *ev;
    size_t len, cap;
    uint64_t tests, visits, overlaps;
} Found;

/* Grows *ptr to hold need items of size bytes (geometrically); io_fail when memory runs out. */
void *omp_grow(void *ptr, size_t *cap, size_t need, size_t size);

static inline void found_push(Found *f, real t, int32_t i, int32_t j, int32_t a, int32_t b)
{
    if (f->len == f->cap) f->ev = omp_grow(f->ev, &f->cap, f->len + 1, sizeof *f->ev);
    PairEvent e = {t, i, j, a, b};
    f->ev[f->len++] = e;
}

/* 3.1: the wall event time of the disk in slot q, or -1 when it has none within the step. Most disks
 * are farther from every wall than they move in a step (with SIM_REL_MARGIN to spare, so the quotient
 * is surely > 1): they need no division. */
static inline real slot_wall_time(const Slots *s, const Params *p, int64_t q)
{
    real x = s->x[q], y = s->y[q], vx = s->vx[q], vy = s->vy[q];
    double ax = fabs((double)vx) * (1 + SIM_REL_MARGIN);
    double ay = fabs((double)vy) * (1 + SIM_REL_MARGIN);
    if ((double)x - p->lo > ax && p->hi - (double)x > ax && (double)y - p->lo > ay &&
        p->hi - (double)y > ay)
        return -1;
    real tw = min_time(wall_time(x, vx, p->lo, p->hi), wall_time(y, vy, p->lo, p->hi));
    return tw <= 1 ? tw : -1;
}

/* Whether a pair event at t can be accepted at all, given the wall event times wa and wb of its
 * disks (-1: none). A disk's wall event sorts before every pair event of that disk at the same or a
 * later time (kind 0 before kind 1), so the greedy walk of SPEC.md 3.3 reaches it first and takes
 * the disk, or the disk is taken already: either way such a pair event is dropped. Leaving it out
 * changes nothing that is accepted. */
static inline int before_walls(real t, real wa, real wb)
{
    return (wa < 0 || t < wa) && (wb < 0 || t < wb);
}

/* ---- omp_paths.c: the broad phase of fast scenes ------------------------------------------------ */

typedef struct Paths Paths;

Paths *paths_new(int nt_max);
void paths_free(Paths *pp);
/* Plans a step of n disks with fastest velocity component vm whose steps' axis lengths add up to
 * about s1 (length) on nt threads; returns the estimated cost in the units of omp.c's cost model. */
double paths_plan(Paths *pp, const Params *p, int64_t n, double vm, double s1, int nt);
/* Makes the buffers ready for the plan, once it is chosen. */
void paths_ready(Paths *pp, int64_t n, int nt);
/* Finds every pair event of the step that before_walls admits, into mine, and fills wall_t (by slot:
 * the wall event time, or -1). Called by every thread of the team (tid of nt) after paths_ready. */
void paths_find(Paths *pp, const Slots *s, const Params *p, real *wall_t, Found *mine, int tid,
                int nt);

#endif /* OMP_STEP_H */
