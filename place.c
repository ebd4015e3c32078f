/* place.c: the random placement of SPEC.md 1 (an input without particle lines): a seeded stream,
 * the same disks on every platform and for every thread count.
 */
#include "io_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* xoshiro256** seeded through splitmix64: fast, and the same numbers on every platform. */
typedef struct {
    uint64_t s[4];
} Rng;

static uint64_t splitmix64(uint64_t *state)
{
    uint64_t z = (*state += UINT64_C(0x9e3779b97f4a7c15));
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k)
{
    return (x << k) | (x >> (64 - k));
}

static uint64_t rng_next(Rng *g)
{
    uint64_t *s = g->s;
    uint64_t result = rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

/* Uniform in [0, 1) with 53 random bits. */
static double rng_unit(Rng *g)
{
    return (double)(rng_next(g) >> 11) * (1.0 / 9007199254740992.0);
}

/* Places n non-overlapping disks uniformly (in the periodic box in [0, L)^2, overlaps by the nearest
 * image), each tried up to PLACE_TRIES times, in index order: disk i
 * draws x, y until it overlaps none of the disks before it, then its speed and direction. A grid of
 * cells at least 2r wide, about one disk per cell, makes each overlap test look at 9 cells.
 *
 * In all but dense scenes nearly every disk finds its place at its first try, so the disks are placed
 * in windows, speculatively: the draws of the stream are taken in order into a queue, every disk of
 * the window takes the next four (x, y, speed, direction), and all threads test each disk's position
 * against the disks before it. The window is good up to its first disk that overlaps one before it;
 * the good disks get their velocities (cos and sin, the costly part) on all threads, the overlapping
 * disk tries again alone, drawing on from where its first try's draws ended, and the next window
 * starts after it. Each disk thereby takes the same draws as in a loop over the disks one by one, and
 * the result is that loop's, bit for bit. Returns -1, or the index of the disk that found no place. */
#define PLACE_TASK 1024    /* disks per task of a window */
#define PLACE_WINDOW 65536 /* disks per window at most */

typedef struct {
    const Params *par;
    Sim *sim;
    int32_t *head, *next; /* the grid: per cell, its disks, the latest first */
    int64_t cells;
    double cell, smin, smax;
    const double *draw; /* the window's draws: four per disk, from disk `from` on */
    int64_t from, count;
    int64_t first_bad[PLACE_WINDOW / PLACE_TASK]; /* per task: its first disk that overlaps one before
                                                     it, or from + count */
} Place;

static int64_t cell_of(double c, double cell, int64_t cells)
{
    int64_t k = (int64_t)(c / cell);
    return k >= cells ? cells - 1 : k;
}

static int64_t place_cell(const Place *pl, double x, double y)
{
    return cell_of(y, pl->cell, pl->cells) * pl->cells + cell_of(x, pl->cell, pl->cells);
}

/* The difference of two coordinates: in the periodic box its nearest image (SPEC.md 7). */
static double place_delta(const Params *par, double d)
{
    double L = (double)par->L;
    if (!par->periodic) return d;
    return d > L / 2 ? d - L : (d < -L / 2 ? d + L : d);
}

/* 1 if the disk at (x, y) overlaps one of the disks j < limit in the grid around it (in the periodic
 * box the cells wrap; a cell met twice where there are fewer than 3 a side is tested twice, harmlessly) */
static int place_overlaps(const Place *pl, double x, double y, int64_t limit)
{
    const Sim *sim = pl->sim;
    int64_t cells = pl->cells, cx = cell_of(x, pl->cell, cells), cy = cell_of(y, pl->cell, cells);
    int wrap = pl->par->periodic;
    for (int64_t ny = cy - 1; ny <= cy + 1; ny++)
        for (int64_t nx = cx - 1; nx <= cx + 1; nx++) {
            int64_t ux = wrap ? (nx + cells) % cells : nx, uy = wrap ? (ny + cells) % cells : ny;
            if (ux < 0 || uy < 0 || ux >= cells || uy >= cells) continue;
            for (int32_t j = pl->head[uy * cells + ux]; j >= 0; j = pl->next[j]) {
                if (j >= limit) continue;
                double dx = place_delta(pl->par, sim->x[j] - x), dy = place_delta(pl->par, sim->y[j] - y);
                if (dx * dx + dy * dy < pl->par->sigma2) return 1;
            }
        }
    return 0;
}

/* the position a draw gives: rounded to real first, so that the overlap tests see the stored value;
 * in the periodic box uniform in [0, L) (a product that rounds up to L is 0) */
static double place_coord(const Params *par, double u)
{
    if (par->periodic) return wrap_coord((real)(par->L * u), par->L);
    return clamp_coord((real)(par->lo + (par->hi - par->lo) * u), par->lo, par->hi);
}

static void place_velocity(const Place *pl, int64_t i, double us, double ua)
{
    double speed = pl->smin + (pl->smax - pl->smin) * us, angle = 6.283185307179586 * ua;
    pl->sim->vx[i] = (real)(speed * cos(angle));
    pl->sim->vy[i] = (real)(speed * sin(angle));
}

static void place_position_task(void *ctx, int64_t k)
{
    Place *pl = ctx;
    int64_t a = k * PLACE_TASK, b = a + PLACE_TASK < pl->count ? a + PLACE_TASK : pl->count;
    for (int64_t t = a; t < b; t++) {
        pl->sim->x[pl->from + t] = place_coord(pl->par, pl->draw[4 * t]);
        pl->sim->y[pl->from + t] = place_coord(pl->par, pl->draw[4 * t + 1]);
    }
}

static void place_check_task(void *ctx, int64_t k)
{
    Place *pl = ctx;
    int64_t a = k * PLACE_TASK, b = a + PLACE_TASK < pl->count ? a + PLACE_TASK : pl->count;
    pl->first_bad[k] = pl->from + pl->count;
    for (int64_t i = pl->from + a; i < pl->from + b; i++)
        if (place_overlaps(pl, pl->sim->x[i], pl->sim->y[i], i)) {
            pl->first_bad[k] = i;
            return;
        }
}

static void place_velocity_task(void *ctx, int64_t k)
{
    Place *pl = ctx;
    int64_t a = k * PLACE_TASK, b = a + PLACE_TASK < pl->count ? a + PLACE_TASK : pl->count;
    for (int64_t t = a; t < b; t++) place_velocity(pl, pl->from + t, pl->draw[4 * t + 2], pl->draw[4 * t + 3]);
}

/* a window's tasks: on all threads where there are enough of them to pay for waking the threads (a
 * dilute scene's first tries collide every few hundred disks at N = 1e5, so most windows are short) */
static void place_tasks(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), Place *pl)
{
    if (tasks >= 4) {
        io_parallel(threads, tasks, task, pl);
        return;
    }
    for (int64_t k = 0; k < tasks; k++) task(pl, k);
}

/* the next draw: from the queue while it lasts, then from the stream */
static double place_draw(const double *q, size_t *qpos, size_t qlen, Rng *g)
{
    return *qpos < qlen ? q[(*qpos)++] : rng_unit(g);
}

int64_t place_disks(const Params *par, uint64_t seed, Sim *sim, int threads)
{
    Rng g;
    uint64_t sm = seed;
    for (int k = 0; k < 4; k++) g.s[k] = splitmix64(&sm);
    int64_t n = par->n;
    double side = sqrt((double)n) + 1;
    double fit = par->L / (2 * par->r); /* most cells per side that stay >= 2r wide */
    int64_t cells = (int64_t)(side < fit ? side : fit);
    if (cells < 1) cells = 1;
    Place pl;
    memset(&pl, 0, sizeof pl);
    pl.par = par;
    pl.sim = sim;
    pl.cells = cells;
    pl.cell = par->L / (double)cells;
    pl.head = sim_calloc((size_t)(cells * cells), sizeof *pl.head);
    pl.next = sim_calloc((size_t)n, sizeof *pl.next);
    memset(pl.head, 0xff, (size_t)(cells * cells) * sizeof *pl.head);
    pl.smin = par->L / 4, pl.smax = par->L / (8 * par->r);
    if (pl.smax < pl.smin) {
        double t = pl.smin;
        pl.smin = pl.smax;
        pl.smax = t;
    }
#ifdef SIM_FLOAT
    /* the float build's speed limit, which keeps squared speeds finite, holds for placed disks too */
    if (pl.smax > SIM_MAX_V) pl.smax = SIM_MAX_V;
    if (pl.smin > SIM_MAX_V) pl.smin = SIM_MAX_V;
#endif
    /* the queue of draws: [qpos, qlen) taken from the stream, not yet used by a disk */
    double *q = sim_calloc(4 * PLACE_WINDOW, sizeof *q);
    size_t qpos = 0, qlen = 0;
    int64_t window = PLACE_TASK, failed = -1;
    for (int64_t k = 0; k < n && failed < 0;) {
        int64_t w = n - k < window ? n - k : window;
        memmove(q, q + qpos, (qlen - qpos) * sizeof *q);
        qlen -= qpos;
        qpos = 0;
        while (qlen < 4 * (size_t)w) q[qlen++] = rng_unit(&g);
        pl.draw = q;
        pl.from = k;
        pl.count = w;
        int64_t tasks = (w + PLACE_TASK - 1) / PLACE_TASK;
        place_tasks(threads, tasks, place_position_task, &pl);
        for (int64_t i = k; i < k + w; i++) { /* into the grid in index order */
            int64_t c = place_cell(&pl, sim->x[i], sim->y[i]);
            pl.next[i] = pl.head[c];
            pl.head[c] = (int32_t)i;
        }
        place_tasks(threads, tasks, place_check_task, &pl);
        int64_t bad = k + w;
        for (int64_t t = 0; t < tasks && bad == k + w; t++) bad = pl.first_bad[t];
        for (int64_t i = k + w - 1; i >= bad; i--) /* out of the grid again: each is its cell's latest */
            pl.head[place_cell(&pl, sim->x[i], sim->y[i])] = pl.next[i];
        pl.count = bad - k;
        place_tasks(threads, (pl.count + PLACE_TASK - 1) / PLACE_TASK, place_velocity_task, &pl);
        qpos = 4 * (size_t)(bad - k);
        if (bad == k + w) {
            if (window < PLACE_WINDOW) window *= 2;
            k = bad;
            continue;
        }
        /* disk `bad` alone: its first try (the window's draws) overlapped; it draws on in order */
        window = 2 * (bad - k) > PLACE_TASK ? 2 * (bad - k) : PLACE_TASK;
        if (window > PLACE_WINDOW) window = PLACE_WINDOW;
        double x = 0, y = 0;
        for (int tries = 1;; tries++) {
            x = place_coord(par, place_draw(q, &qpos, qlen, &g));
            y = place_coord(par, place_draw(q, &qpos, qlen, &g));
            if (!place_overlaps(&pl, x, y, bad)) break;
            if (tries == PLACE_TRIES) {
                failed = bad;
                break;
            }
        }
        if (failed >= 0) break;
        sim->x[bad] = x;
        sim->y[bad] = y;
        int64_t c = place_cell(&pl, x, y);
        pl.next[bad] = pl.head[c];
        pl.head[c] = (int32_t)bad;
        double us = place_draw(q, &qpos, qlen, &g);
        place_velocity(&pl, bad, us, place_draw(q, &qpos, qlen, &g));
        k = bad + 1;
    }
    free(q);
    free(pl.head);
    free(pl.next);
    return failed;
}
