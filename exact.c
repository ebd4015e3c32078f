/* exact.c: the event-driven model of --exact, as exact.h defines it: the disks' clocks, the events'
 * prediction and processing, and the heap of events in key order.
 */
#include "exact.h"

#include <math.h>
#include <stdlib.h>

/* ==== the disks ====================================================================================== */

/* The slack covers the rounding of c = dd - sigma2 at a contact: coordinates up to L carry errors of a
 * few eps L each, which move dd by about 2 * 2r * eps * L apiece; 64 of them are allowed. It never
 * exceeds r^2 (centres 1.73 r apart), so that deep overlaps pass through even where L / r is so large
 * that rounding swamps the radius. */
void exact_alloc(ExactDisks *d, Sim *sim, const Params *p)
{
    int64_t n = p->n;
    d->sim = sim;
    d->id = NULL;
    real slack = 64 * (real)SIM_EPS * p->L * (p->r + p->r), most = p->r * p->r;
    d->slack = slack < most ? slack : most;
    d->t = sim_calloc((size_t)n, sizeof *d->t);
    d->ver = sim_calloc((size_t)n, sizeof *d->ver);
    d->step_events = sim_calloc((size_t)n, sizeof *d->step_events);
    /* the last partners outlive a step (a checkpoint keeps them): the Sim holds them */
    if (!sim->last) {
        sim->last = sim_calloc((size_t)n, sizeof *sim->last);
        for (int64_t i = 0; i < n; i++) sim->last[i] = -1;
    }
    d->last = sim->last;
}

/* Stops the run before its first step if a disk alone would cross the box more often within one step
 * than EXACT_MAX_STEP_EVENTS allows (as the random placement's speeds up to L/(8r) can when L/r is
 * huge): such a step could not be run event by event. */
void exact_check_speeds(const Sim *s, const Params *p)
{
    if (p->periodic) return; /* no walls: a disk alone has no events */
    double span = (double)p->hi - (double)p->lo;
    for (int64_t i = 0; i < p->n; i++) {
        double crossings = (fabs((double)s->vx[i]) + fabs((double)s->vy[i])) / span;
        if (crossings > EXACT_MAX_STEP_EVENTS)
            sim_fail("--exact: disk %lld would hit the walls about %.3g times within one step (more than "
                    "%u events of one disk per step)",
                    (long long)i, crossings, EXACT_MAX_STEP_EVENTS);
    }
}

void exact_free(ExactDisks *d)
{
    free(d->t);
    free(d->ver);
    free(d->step_events);
}

/* Time of disk i's next wall event, or -1 if none comes by the end of the step. */
real exact_wall_time(const ExactDisks *d, const Params *p, int64_t i)
{
    const Sim *s = d->sim;
    if (p->periodic) return -1;
    real dt = min_time(wall_time(s->x[i], s->vx[i], p->lo, p->hi),
                       wall_time(s->y[i], s->vy[i], p->lo, p->hi));
    real te = d->t[i] + dt;
    return te <= 1 ? te : -1;
}

/* Where disks i < j stand at their common clock tc, and the flight dt from there to contact. */
typedef struct {
    real tc, dt;
    real xi, yi, xj, yj;
} ExactMeet;

/* The flight from tc until two disks whose centres differ by (dx, dy) at tc touch, within rest, or -1:
 * none where they overlap deeper than the slack, or (partners: their last events were with each other)
 * while they still touch. */
static real meet_image(const ExactDisks *d, const Params *p, real dx, real dy, real dvx, real dvy, real rest,
                       int partners)
{
    real c = dx * dx + dy * dy - p->sigma2;
    if (c < -d->slack || (partners && c < d->slack)) return -1;
    return pair_time_rel(dx, dy, dvx, dvy, p->sigma2, rest);
}

/* Returns 1 and fills m if disks i < j touch by the end of the step. In the periodic box (SPEC.md 7a)
 * the centres at tc are brought into [0, L) and the pair meets by the earliest of its images within
 * one box of the nearest (those the rest of the step can bring within 2r: for most pairs the nearest
 * alone); two disks whose last events were with each other may then meet again through another
 * image, though not where they still touch. */
static int exact_meet(const ExactDisks *d, const Params *p, int64_t i, int64_t j, ExactMeet *m)
{
    const Sim *s = d->sim;
    int partners = d->last[i] == j && d->last[j] == i;
    if (partners && !p->periodic) return 0;
    real ti = d->t[i], tj = d->t[j];
    real tc = ti < tj ? tj : ti, rest = 1 - tc;
    m->tc = tc;
    m->xi = s->x[i] + s->vx[i] * (tc - ti);
    m->yi = s->y[i] + s->vy[i] * (tc - ti);
    m->xj = s->x[j] + s->vx[j] * (tc - tj);
    m->yj = s->y[j] + s->vy[j] * (tc - tj);
    real dx = m->xj - m->xi, dy = m->yj - m->yi, dvx = s->vx[j] - s->vx[i], dvy = s->vy[j] - s->vy[i];
    if (p->periodic) {
        m->xi = wrap_coord(m->xi, p->L), m->yi = wrap_coord(m->yi, p->L);
        m->xj = wrap_coord(m->xj, p->L), m->yj = wrap_coord(m->yj, p->L);
        dx = wrap_delta(m->xj - m->xi, p->L, p->half), dy = wrap_delta(m->yj - m->yi, p->L, p->half);
    }
    m->dt = meet_image(d, p, dx, dy, dvx, dvy, rest, partners);
    /* images one box over: each axis within reach (2r plus the axis' flight, twice over: no rounding
     * can skip one that meets); the earliest, the nearest first on a tie */
    real far_x = 4 * p->r + 2 * SIM_FABS(dvx) * rest, far_y = 4 * p->r + 2 * SIM_FABS(dvy) * rest;
    for (int kx = -1; p->periodic && kx <= 1; kx++)
        for (int ky = -1; ky <= 1; ky++) {
            real ex = dx + (real)kx * p->L, ey = dy + (real)ky * p->L;
            if ((!kx && !ky) || SIM_FABS(ex) > far_x || SIM_FABS(ey) > far_y) continue;
            real t = meet_image(d, p, ex, ey, dvx, dvy, rest, partners);
            if (t >= 0 && (m->dt < 0 || t < m->dt)) m->dt = t;
        }
    return m->dt >= 0 && tc + m->dt <= 1;
}

/* Time of the pair event of disks i < j, or -1 if none comes by the end of the step. */
real exact_pair_time(const ExactDisks *d, const Params *p, int64_t i, int64_t j)
{
    ExactMeet m;
    return exact_meet(d, p, i, j, &m) ? m.tc + m.dt : -1;
}

/* One more event of disk i: its version, its step budget and the count c (p or w). */
static void exact_count(ExactDisks *d, int64_t i, int32_t *c)
{
    long long disk = d->id ? d->id[i] : i;
    d->ver[i]++;
    if (++d->step_events[i] > EXACT_MAX_STEP_EVENTS)
        sim_fail("--exact: disk %lld collided more than %u times within one step (a cascade that "
                "does not advance in time); stopping",
                disk, EXACT_MAX_STEP_EVENTS);
    if (*c == INT32_MAX) sim_fail("--exact: the collision count of disk %lld exceeds %d", disk, INT32_MAX);
    ++*c;
}

/* Disk i's centre into the box: clamped into [lo, hi], or in the periodic box into [0, L). */
static void exact_into_box(Sim *s, const Params *p, int64_t i)
{
    if (p->periodic) {
        s->x[i] = wrap_coord(s->x[i], p->L);
        s->y[i] = wrap_coord(s->y[i], p->L);
    } else {
        s->x[i] = clamp_coord(s->x[i], p->lo, p->hi);
        s->y[i] = clamp_coord(s->y[i], p->lo, p->hi);
    }
}

/* Whether processing e (valid) would stop the run: exact_count's two limits. */
int exact_stops(const ExactDisks *d, const ExactEvent *e)
{
    const Sim *s = d->sim;
    int64_t i = e->i, j = e->j;
    if (i == j) return d->step_events[i] >= EXACT_MAX_STEP_EVENTS || s->wc[i] == INT32_MAX;
    return d->step_events[i] >= EXACT_MAX_STEP_EVENTS || d->step_events[j] >= EXACT_MAX_STEP_EVENTS ||
           s->pc[i] == INT32_MAX || s->pc[j] == INT32_MAX;
}

/* a * b as hi + lo exactly (Dekker: no fused multiply-add, as the build forbids contraction) */
static void exact_two_prod(real a, real b, real *hi, real *lo)
{
#ifdef SIM_FLOAT
    const real split = 4097.0f; /* 2^12 + 1 */
#else
    const real split = 134217729.0; /* 2^27 + 1 */
#endif
    real p = a * b, ca = split * a, cb = split * b;
    real ah = ca - (ca - a), al = a - ah, bh = cb - (cb - b), bl = b - bh;
    *hi = p;
    *lo = ((ah * bh - p) + ah * bl + al * bh) + al * bl;
}

/* The response: the normal components of the velocities swapped as the impulse q n along the contact
 * vector n, q = (vj - vi).n / n.n. With n.n held exactly (hi + lo) no rounding has a sign of its own:
 * a normal of length 2r that rounds to a power of two (pair_bounce_rel's u = n / len, where len rounds
 * to 2r over a span twice as wide above as below it) adds energy a collision on average, this does
 * not. dp (where not NULL): |vni - vnj| as pair_bounce_rel computes it (the virial's impulse, SPEC.md
 * 7a), from the velocities before the response. */
static void exact_bounce(real nx, real ny, real *vxi, real *vyi, real *vxj, real *vyj, real *dp)
{
    real nn = nx * nx + ny * ny;
    if (nn == 0) { /* centres that coincide: no normal, no response */
        if (dp) *dp = 0;
        return;
    }
    if (dp) {
        real len = SIM_SQRT(nn), ux = nx / len, uy = ny / len;
        *dp = SIM_FABS((ux * *vxi + uy * *vyi) - (ux * *vxj + uy * *vyj));
    }
    real xh, xl, yh, yl;
    exact_two_prod(nx, nx, &xh, &xl);
    exact_two_prod(ny, ny, &yh, &yl);
    real s = xh + yh, z = s - xh, e = (xh - (s - z)) + (yh - z); /* xh + yh = s + e exactly */
    real lo = e + xl + yl;
    real num = (*vxj - *vxi) * nx + (*vyj - *vyi) * ny;
    real q0 = num / s, q = q0 - q0 * (lo / s); /* num / (s + lo) to first order in lo / s */
    *vxi = *vxi + q * nx;
    *vyi = *vyi + q * ny;
    *vxj = *vxj - q * nx;
    *vyj = *vyj - q * ny;
}

/* Processes event e (valid: predicted from the disks' current versions). */
void exact_apply(ExactDisks *d, const Params *p, const ExactEvent *e)
{
    Sim *s = d->sim;
    real lo = p->lo, hi = p->hi;
    int64_t i = e->i, j = e->j;
    if (i == j) {
        real dt = min_time(wall_time(s->x[i], s->vx[i], lo, hi), wall_time(s->y[i], s->vy[i], lo, hi));
        real vx0 = s->vx[i], vy0 = s->vy[i];
        wall_bounce(&s->x[i], &s->y[i], &s->vx[i], &s->vy[i], dt, lo, hi);
        if (s->wi) s->wi[i] += wall_impulse(vx0, vy0, s->vx[i], s->vy[i]);
        exact_into_box(s, p, i);
        d->t[i] = e->t;
        d->last[i] = -1;
        exact_count(d, i, &s->wc[i]);
        return;
    }
    ExactMeet m;
    exact_meet(d, p, i, j, &m);
    s->x[i] = m.xi + s->vx[i] * m.dt;
    s->y[i] = m.yi + s->vy[i] * m.dt;
    s->x[j] = m.xj + s->vx[j] * m.dt;
    s->y[j] = m.yj + s->vy[j] * m.dt;
    real nx = s->x[j] - s->x[i], ny = s->y[j] - s->y[i];
    if (p->periodic) nx = wrap_delta(nx, p->L, p->half), ny = wrap_delta(ny, p->L, p->half);
    real dp;
    int virial = s->wi && p->periodic; /* the virial's impulses (SPEC.md 7a) */
    exact_bounce(nx, ny, &s->vx[i], &s->vy[i], &s->vx[j], &s->vy[j], virial ? &dp : NULL);
    if (virial) s->wi[i] += dp, s->wi[j] += dp;
    exact_into_box(s, p, i);
    exact_into_box(s, p, j);
    d->t[i] = d->t[j] = e->t;
    d->last[i] = (int32_t)j;
    d->last[j] = (int32_t)i;
    exact_count(d, i, &s->pc[i]);
    exact_count(d, j, &s->pc[j]);
}

/* The end of the step for disk i: flight to t = 1, clocks back to 0 for the next step. */
void exact_finish(ExactDisks *d, const Params *p, int64_t i)
{
    Sim *s = d->sim;
    real rest = 1 - d->t[i];
    s->x[i] = s->x[i] + s->vx[i] * rest;
    s->y[i] = s->y[i] + s->vy[i] * rest;
    exact_into_box(s, p, i);
    d->t[i] = 0;
    d->step_events[i] = 0;
}

/* ==== the event heap ================================================================================ */

static int exact_before(const ExactEvent *a, const ExactEvent *b)
{
    return event_before(a->t, a->i != a->j, a->i, a->j, b->t, b->i != b->j, b->i, b->j);
}

int exact_valid(const ExactDisks *d, const ExactEvent *e)
{
    return d->ver[e->i] == e->vi && d->ver[e->j] == e->vj;
}

void exact_heap_reserve(ExactHeap *h, size_t need)
{
    if (need <= h->cap) return;
    size_t c = h->cap ? h->cap : 1024;
    while (c < need) c *= 2;
    ExactEvent *grown = realloc(h->e, c * sizeof *grown);
    if (!grown) sim_fail("out of memory for %zu events", c);
    h->e = grown;
    h->cap = c;
}

static void exact_heap_sift_down(ExactHeap *h, size_t k)
{
    ExactEvent x = h->e[k];
    for (;;) {
        size_t c = 2 * k + 1;
        if (c >= h->len) break;
        if (c + 1 < h->len && exact_before(&h->e[c + 1], &h->e[c])) c++;
        if (!exact_before(&h->e[c], &x)) break;
        h->e[k] = h->e[c];
        k = c;
    }
    h->e[k] = x;
}

/* Restores the heap order of an array filled in any order. */
void exact_heap_build(ExactHeap *h)
{
    for (size_t k = h->len / 2; k-- > 0;) exact_heap_sift_down(h, k);
}

/* Adds the event (t, i, j) predicted from the disks' current versions (j == i: wall). */
void exact_heap_push(ExactHeap *h, const ExactDisks *d, real t, int64_t i, int64_t j)
{
    ExactEvent x = {t, (int32_t)i, (int32_t)j, d->ver[i], d->ver[j]};
    exact_heap_add(h, &x);
}

/* Adds event e as it is. */
void exact_heap_add(ExactHeap *h, const ExactEvent *e)
{
    exact_heap_reserve(h, h->len + 1);
    ExactEvent x = *e;
    size_t k = h->len++;
    while (k > 0) {
        size_t up = (k - 1) / 2;
        if (!exact_before(&x, &h->e[up])) break;
        h->e[k] = h->e[up];
        k = up;
    }
    h->e[k] = x;
}

/* Removes the smallest event into *e. */
void exact_heap_pop(ExactHeap *h, ExactEvent *e)
{
    *e = h->e[0];
    h->e[0] = h->e[--h->len];
    if (h->len) exact_heap_sift_down(h, 0);
}

