/* exact.h: the event-driven model of --exact (its code in exact.c), shared by seq.c (all pairs) and
 * omp_exact.c (grid).
 *
 * SPEC.md's step lets each disk collide at most once and stops it at the next wall. --exact instead
 * runs the elastic dynamics exactly, up to rounding: within each unit step every collision happens, in
 * time order, as many per disk as there are.
 *
 * - Every disk carries a local clock t in [0, 1]: its state (x, y, vx, vy) is its state at time t of
 *   the step. A step starts with every clock at 0 and ends by flying every disk on to 1 (x += vx *
 *   (1 - t), then clamp_coord), which is the state printed.
 * - Events, each a pure function of the states of its disks:
 *   wall i:     te = t + min(tx, ty) from 3.1's wall_time; the axes that hit are set exactly to the wall
 *               and their velocity reflected (wall_bounce), the other axis flies; a corner is one event.
 *   pair i < j: both states are brought to the common clock tc = max(ti, tj) by flight, pair_time_within
 *               solves 3.2 from there for the rest of the step (1 - tc), te = tc + dt; both fly dt to
 *               contact and swap normal components: vi += q n, vj -= q n along the contact vector n,
 *               q = (vj - vi).n / n.n with n.n held exactly (exact.c exact_bounce; SPEC.md 3.4's
 *               pair_bounce, through n / |n|, gains energy on average where 2r is a power of two).
 *   An event exists if te <= 1 (events at exactly t = 1 belong to the step, as in SPEC.md). After
 *   each event the moved coordinates are clamped into [lo, hi].
 * - Order: the smallest event by the key (t, kind, i, j) of SPEC.md 3.3 is processed, then the events
 *   of its disks are predicted again from their new states; repeated until no event has te <= 1. Ties
 *   are thereby settled by kind (wall first), then indices; a disk in two tied events takes the first,
 *   and the second is predicted again from its new state (it happens if the disks still approach).
 * - Two disks whose last events were with each other do not collide again: after an elastic
 *   collision they separate, and in free flight they cannot meet until one of them has another event.
 *   (Without this rule, rounding could make a grazing pair "approach" again at the same instant.)
 * - Hard disks never overlap, so a pair that overlaps by more than rounding at tc (c < -slack, see
 *   exact_alloc; only overlapping starts get there) does not collide: it passes through until it has
 *   separated, and meets normally from then on. (SPEC.md's rule, an overlapped approaching pair
 *   collides at t = 0, would here collide again and again at one instant inside a cluster of
 *   overlapping disks.) Pairs that touch within rounding do collide.
 * - Every processed event updates the per-disk counters: p (pair) and w (wall) as in SPEC.md 3.5, now
 *   any number per step, and a version that marks the disk's older predictions stale. With --pressure
 *   each wall event adds wall_impulse (2 |v| per reflected axis) to the disk's wi, in its event order.
 *
 * - In the periodic box (SPEC.md 7a) there are no wall events; a pair is predicted from its centres
 *   at tc brought into [0, L), by the earliest of its nearest image and the images one box over that
 *   can touch within the step; coordinates are brought into [0, L) after each event and at the
 *   step's end; the rule above holds only for the image where the two still touch (they may meet
 *   again through another), and after an event the pair itself is predicted again. With --pressure
 *   each pair event adds its impulse |vni - vnj| to both disks' wi (the collision virial).
 *
 * Because each event's arithmetic reads only its own disks' states, any algorithm that processes the
 * same events in the same order prints the same bytes: seq finds the next event among all pairs, omp
 * among grid neighbours, and both take the same smallest key.
 */
#ifndef EXACT_H
#define EXACT_H

#include "common.h"

/* Events of one disk within one step beyond which the run stops: only a cascade that no longer
 * advances in time (possible from overlapping starts) gets there in practice. */
#define EXACT_MAX_STEP_EVENTS (1u << 20)

/* The disks with the per-disk state that --exact adds to Sim, all in original index order. */
typedef struct {
    Sim *sim;
    real *t;              /* local clock: the time of the step the state refers to */
    uint32_t *ver;        /* events of the disk so far, modulo 2^32: the version of its state */
    int32_t *last;        /* partner of the disk's last event; -1 after a wall event or none */
    uint32_t *step_events; /* events of the disk in this step, for EXACT_MAX_STEP_EVENTS */
    real slack;           /* overlap (-c) that still counts as touching: rounding, not an overlap */
    const int32_t *id;    /* the disk's index at each position of the arrays, for messages; NULL: the
                             position (omp_exact.c keeps the disks in an order of its own) */
} ExactDisks;

/* A predicted event: the key (t, kind, i, j) with kind 0 (wall) when i == j, and the versions of the
 * disks it was predicted from. */
typedef struct {
    real t;
    int32_t i, j;
    uint32_t vi, vj;
} ExactEvent;

/* A binary min-heap of events in key order. Stale events stay until they surface and are dropped. */
typedef struct {
    ExactEvent *e;
    size_t len, cap;
} ExactHeap;

/* ==== the disks ====================================================================================== */

/* The per-disk state of --exact for sim (sim->last kept where a checkpoint brought it), and the slack
 * that still counts as touching. */
void exact_alloc(ExactDisks *d, Sim *sim, const Params *p);
/* Stops the run before its first step if a disk alone would cross the box more often within one step
 * than EXACT_MAX_STEP_EVENTS allows (as the random placement's speeds up to L/(8r) can when L/r is
 * huge): such a step could not be run event by event. */
void exact_check_speeds(const Sim *s, const Params *p);
void exact_free(ExactDisks *d);

/* Time of disk i's next wall event, or -1 if none comes by the end of the step. */
real exact_wall_time(const ExactDisks *d, const Params *p, int64_t i);
/* Time of the pair event of disks i < j, or -1 if none comes by the end of the step. */
real exact_pair_time(const ExactDisks *d, const Params *p, int64_t i, int64_t j);
/* Whether e was predicted from its disks' current versions (else it is stale and dropped). */
int exact_valid(const ExactDisks *d, const ExactEvent *e);
/* Whether processing e (valid) would stop the run: a disk at its step's EXACT_MAX_STEP_EVENTS or a
 * count at INT32_MAX (exact_apply then fails with its message). */
int exact_stops(const ExactDisks *d, const ExactEvent *e);
/* Processes event e (valid). */
void exact_apply(ExactDisks *d, const Params *p, const ExactEvent *e);
/* The end of the step for disk i: flight to t = 1, clocks back to 0 for the next step. */
void exact_finish(ExactDisks *d, const Params *p, int64_t i);

/* ==== the event heap ================================================================================ */

/* Room for need events in h. */
void exact_heap_reserve(ExactHeap *h, size_t need);
/* Restores the heap order of an array filled in any order. */
void exact_heap_build(ExactHeap *h);
/* Adds the event (t, i, j) predicted from the disks' current versions (j == i: wall). */
void exact_heap_push(ExactHeap *h, const ExactDisks *d, real t, int64_t i, int64_t j);
/* Adds event e as it is. */
void exact_heap_add(ExactHeap *h, const ExactEvent *e);
/* Removes the smallest event into *e. */
void exact_heap_pop(ExactHeap *h, ExactEvent *e);

#endif /* EXACT_H */
