/* omp_step.h: what omp.c's step shares with the broad phase of fast scenes (omp_paths.c).
 *
 * omp keeps the disks in slots (an order of its own, for locality); each slot remembers its disk's
 * original index, which alone decides the event order and the output order. A broad phase finds the
 * step's pair events into per-thread lists; omp.c then chooses among them and moves the disks.
 */
#ifndef OMP_STEP_H
#define OMP_STEP_H

#include "io.h"

#include <stdlib.h>
#include <string.h>

/* The broad phases' x86 SIMD: SSE2 where the compiler targets it (every x86-64 build), and AVX2 and
 * AVX-512F functions chosen at run time (omp_paths.c). SIM_NO_SIMD builds the portable C alone, as on
 * other processors; make test runs that build too, so that both stay tested. */
#if defined(__SSE2__) && !defined(SIM_NO_SIMD)
#define SIM_SSE2 1
#include <emmintrin.h>

static inline __m128d select_pd(__m128d mask, __m128d a, __m128d b) /* mask ? a : b, lane by lane */
{
    return _mm_or_pd(_mm_and_pd(mask, a), _mm_andnot_pd(mask, b));
}
#endif
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && !defined(SIM_NO_SIMD)
#define SIM_X86_TARGETS 1
#endif

/* A helper the compiler must inline wherever it is called: where a loop calls it from two callers (the
 * walled and the periodic box's), each gets its own copy, specialised for its constants. */
#if defined(__GNUC__) || defined(__clang__)
#define SIM_INLINE inline __attribute__((always_inline))
#else
#define SIM_INLINE inline
#endif

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

/* A wall event: its time and slot. */
typedef struct {
    real t;
    int32_t slot;
} WallEvent;

/* What one thread's broad phase finds in a step: pair events, wall events (so that the choice need
 * not look at every slot), the trims (see SlowGrid's keep), the exact tests (pair_time) done, and
 * for the paths (--stats) the cells visited and the pairs of visits that overlap in time. */
typedef struct {
    PairEvent *ev;
    size_t len, cap;
    WallEvent *wall;
    size_t wall_len, wall_cap;
    PairEvent *trim; /* a: a fast disk's slot; t, i, j: the smallest key of its events left out */
    size_t trim_len, trim_cap;
    size_t slow_from, slow_to; /* a mixed step: ev[slow_from, slow_to) are the fast disks' events
                                  with slow disks (paths_bin), those that keep bounds */
    uint64_t tests, visits, overlaps, trimmed; /* trimmed: the disks with a trim, all steps */
    int64_t *mark; /* this step's Broad's mark, or NULL: where found_push marks its slots */
    int64_t step;  /* the step being found (broad_find) */
} Found;

/* The nearest image of a difference d of two coordinates (SPEC.md 7), in double: for the broad
 * phases' filters, whose margins cover its rounding. */
static inline double wrap_near(double d, double L)
{
    return d > L / 2 ? d - L : (d < -L / 2 ? d + L : d);
}

/* sim_grow for a buffer whose contents need not be kept: no copy on the way. */
static inline void *omp_scratch_grow(void *ptr, size_t *cap, size_t need, size_t size)
{
    if (need <= *cap) return ptr;
    free(ptr);
    *cap = 0;
    return sim_grow(NULL, cap, need, size);
}

/* A pair event of disks i and j (original indices) in slots a and b, and the marks of both slots
 * (another thread may mark either one in the same step). */
static inline void found_push(Found *f, real t, int32_t i, int32_t j, int32_t a, int32_t b)
{
    if (f->len == f->cap) f->ev = sim_grow(f->ev, &f->cap, f->len + 1, sizeof *f->ev);
    PairEvent e = {t, i, j, a, b};
    f->ev[f->len++] = e;
    if (f->mark) {
        int64_t *ma = &f->mark[a], *mb = &f->mark[b], step = f->step;
        (void)step; /* gcc 12 sees no use of it in the atomic writes' right-hand sides */
#pragma omp atomic write
        *ma = step;
#pragma omp atomic write
        *mb = step;
    }
}

static inline void found_wall(Found *f, real t, int32_t q)
{
    if (f->wall_len == f->wall_cap)
        f->wall = sim_grow(f->wall, &f->wall_cap, f->wall_len + 1, sizeof *f->wall);
    WallEvent e = {t, q};
    f->wall[f->wall_len++] = e;
}

/* 3.1: the wall event time of the disk in slot q, or -1 when it has none within the step (nor ever in
 * the periodic box). Most disks
 * are farther from every wall than they move in a step (with SIM_REL_MARGIN to spare, so the quotient
 * is surely > 1): they need no division. */
static inline real slot_wall_time(const Slots *s, const Params *p, int64_t q)
{
    if (p->periodic) return -1; /* no walls (SPEC.md 7) */
    real x = s->x[q], y = s->y[q], vx = s->vx[q], vy = s->vy[q];
    double ax = fabs((double)vx) * (1 + SIM_REL_MARGIN);
    double ay = fabs((double)vy) * (1 + SIM_REL_MARGIN);
    if ((double)x - p->lo > ax && p->hi - (double)x > ax && (double)y - p->lo > ay &&
        p->hi - (double)y > ay)
        return -1;
#if defined(SIM_SSE2) && !defined(SIM_FLOAT)
    /* wall_time of both axes at once, every value its own: selects rather than its branches on the
     * signs of the velocity, which a processor cannot predict, and one division (the quotient of a
     * zero velocity is discarded) */
    __m128d c = _mm_set_pd(y, x), v = _mm_set_pd(vy, vx), zero = _mm_setzero_pd();
    __m128d pos = _mm_cmpgt_pd(v, zero), moving = _mm_cmpneq_pd(v, zero);
    __m128d t = _mm_div_pd(_mm_sub_pd(select_pd(pos, _mm_set1_pd(p->hi), _mm_set1_pd(p->lo)), c), v);
    t = select_pd(moving, t, _mm_set1_pd(INFINITY));
    t = _mm_max_pd(t, zero);                                       /* t <= 0 ? 0 : t */
    real tw = _mm_cvtsd_f64(_mm_min_sd(_mm_unpackhi_pd(t, t), t)); /* min_time(tx, ty) */
#else
    real tw = min_time(wall_time(x, vx, p->lo, p->hi), wall_time(y, vy, p->lo, p->hi));
#endif
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

/* ---- the grid of slow disks (omp.c), as the paths of fast ones meet it --------------------------- */

/* A disk's swept box in cell units of the grid ((c - x0) / h, rounded to float: spans that overlap
 * still overlap as Boxes, since subtracting, scaling by a positive factor and rounding never reverse
 * the order of two coordinates), stored as (xhi, -xlo, yhi, -ylo): box a overlaps box b where each
 * of the four lanes of (-a.nxlo, -a.xhi, -a.nylo, -a.yhi) is at most b's, one SIMD comparison
 * (negation is exact). An empty box (xlo = ylo = +inf, xhi = yhi = -inf) overlaps nothing. */
typedef struct {
    float xhi, nxlo, yhi, nylo;
} Box;

static inline Box box_of(float xlo, float xhi, float ylo, float yhi)
{
    Box b = {xhi, -xlo, yhi, -ylo};
    return b;
}

static inline int boxes_overlap(const Box *a, const Box *b)
{
    return (-a->nxlo <= b->xhi) & (-a->xhi <= b->nxlo) & (-a->nylo <= b->yhi) & (-a->yhi <= b->nylo);
}

/* The slow disks of a mixed step, binned by the centres of their boxes into g x g square cells of
 * side 1 / inv_h from (x0, x0). Fast disks are binned with empty boxes.
 *
 * keep (0: all): of a fast disk's pair events with slow disks only the keep smallest by the key of
 * SPEC.md 3.3 are kept, and the smallest key left out is noted (Found's trim). A fast disk crossing
 * a gas has an event with every disk on its path, dozens, and only its first few can matter: the
 * events left out are all rejected by the greedy walk (and change nothing) if the choice takes the
 * disk at a smaller key, which the caller must check; where it does not, the step is found again
 * keeping more. */
#define KEEP_FIRST 8 /* omp's default --keep */

typedef struct {
    const Box *boxes;          /* in cell order */
    const int32_t *cell_start; /* g * g + 1: first box of each cell */
    const int32_t *box_slot;   /* the slot of each box */
    int64_t g;
    double x0, inv_h;
    double reach; /* how far from a fast centre the centre of a box it can meet may lie (per axis) */
    int keep;
} SlowGrid;

/* ---- omp_paths.c: the broad phase of fast disks --------------------------------------------------- */

typedef struct Paths Paths;

/* The geometry of a step's paths: cells, tiles, margins. */
typedef struct {
    int64_t g;       /* cells per side */
    double x0, h;    /* lower corner (x0, x0) and side of the cells */
    double inv_h, last; /* 1 / h and g - 1 */
    double grow;     /* G: how far the cells are grown for the paths */
    double reach2;   /* (2 G_TEST)^2: meet's filter */
    int flt;         /* 1: the screens test the lines in float (the coordinates and speeds allow) */
    float flt_s, flt_c; /* its bound cr^2 <= flt_s a + flt_c (omp_lanes.h's line) */
    int64_t tc, gt, tiles; /* tile side in cells, tiles per side, tiles */
    int32_t bins;    /* bins of entry time per cell in phase B's counting sort: a power of 2 */
    int periodic;    /* the periodic box (SPEC.md 7): the cells tile [0, L) and paths run over the edges */
    double L;
} PathsPlan;

/* In the periodic box (SPEC.md 7), whether the paths of disks whose velocity components are at most
 * vm, cells grown by grow, visit each of the cells of side h tiling [0, L) at most once: a path's cells
 * span at most (vm + 2 grow) / h + 2 a side, at most the whole side. */
int paths_fit_periodic(const Params *p, double vm, double grow, double h);
/* lanes: phase B's screens, pairs at a time (1, 4 or 8; 0: the widest the processor runs) */
Paths *paths_new(int nt_max, int lanes);
int paths_lanes(const Paths *pp);
void paths_free(Paths *pp);
/* Plans the paths of all n disks of a step (fastest velocity component vm, the steps' axis lengths
 * adding up to about s1) on cells of their own, nt threads; returns the estimated cost in the units
 * of omp.c's cost model. */
double paths_plan(const Params *p, int64_t n, double vm, double s1, int nt, PathsPlan *pl);
/* The same for the n_fast fast disks of a mixed step (s1 theirs), which also meet the n_slow slow
 * disks of a grid of g x g cells of side h (SlowGrid, its reach slow_reach; keep its keep): the cost
 * of the fast disks' part. */
double paths_plan_grid(const Params *p, int64_t n_fast, int64_t n_slow, double vm, double s1,
                       double slow_reach, double h, int64_t g, int keep, int nt, PathsPlan *pl);
/* Adopts a plan and makes the buffers ready for it. */
void paths_ready(Paths *pp, const PathsPlan *pl, int nt);
/* Finds every pair event of the step that before_walls admits into mine, in two calls by every
 * thread of the team (tid of nt) after paths_ready, with a barrier between them and one after:
 * paths_bin bins the paths, paths_pairs pairs their visits, tile by tile. With slow = NULL: the paths
 * of all disks, wall_t (by slot: the wall event time, or -1) filled by paths_bin; or in a mixed step
 * with the slow disks' grid and this thread's list of fast slots, wall_t filled already: the fast
 * disks' pairs, with each other (paths_pairs) and with the slow disks (paths_bin). */
void paths_bin(Paths *pp, const Slots *s, const Params *p, real *wall_t, const SlowGrid *slow,
               const int32_t *fast, int64_t n_fast, Found *mine, int tid, int nt);
void paths_pairs(Paths *pp, const Slots *s, const Params *p, const real *wall_t, Found *mine, int tid,
                 int nt);
/* A mixed step found again keeping more (slow->keep): this thread's fast disks' events with slow
 * disks, found by paths_bin under the smaller keep, replaced in mine by those under the larger one;
 * its other events, which keep does not bound, stay. */
void paths_refind(const Paths *pp, const Slots *s, const Params *p, const real *wall_t,
                  const SlowGrid *slow, const int32_t *fast, int64_t n_fast, Found *mine);

/* ---- omp_broad.c: the broad phase of a step over a set of slots (omp.c: all disks; mpi.c: a rank's
 * own disks and halo) ------------------------------------------------------------------------------ */

/* Disks by their fastest velocity component a, for the plan: bin k (1..62) holds a / span in
 * [2^(k-48), 2^(k-47)); bin 0 the disks at rest, bins 1 and 63 everything below and above. */
#define SPEED_BINS 64
static inline int speed_bin(double a, double inv_span)
{
    double f = a * inv_span;
    if (!(f > 0)) return 0;
    uint64_t bits;
    memcpy(&bits, &f, sizeof bits); /* the binary exponent, without a call to ilogb */
    int k = (int)(bits >> 52 & 0x7ff) - 1023 + 48;
    return k < 1 ? 1 : (k > SPEED_BINS - 1 ? SPEED_BINS - 1 : k);
}

static inline real fastest(real vm, real vx, real vy)
{
    real ax = SIM_FABS(vx), ay = SIM_FABS(vy);
    if (ax > vm) vm = ax;
    return ay > vm ? ay : vm;
}

/* Adds a disk of velocity (vx, vy) to a histogram of speeds (sign -1: removes it): its speed_bin and
 * its axis speeds, each at most the box, in units of the box / 2^20. */
static inline void note_speed(int64_t *n, int64_t *s1, real vx, real vy, double inv_span, int sign)
{
    double ax = SIM_FABS(vx) * inv_span, ay = SIM_FABS(vy) * inv_span;
    int k = speed_bin((double)fastest(0, vx, vy), inv_span);
    n[k] += sign;
    s1[k] += sign * ((int64_t)((ax < 1 ? ax : 1) * 1048576) + (int64_t)((ay < 1 ? ay : 1) * 1048576));
}

/* The broad phases of a step. */
enum { MODE_GRID, MODE_PATHS, MODE_MIXED };

/* The plan of one step: its broad phase and the geometry of its grid (MODE_GRID, MODE_MIXED) and
 * paths (MODE_PATHS, MODE_MIXED). */
typedef struct {
    int mode;
    double v_cut;  /* MODE_MIXED: disks with a velocity component of v_cut or more are fast */
    int64_t gx, gy; /* cells per row and per column (equal over the box) */
    int64_t g;     /* gx: a square grid's side, for MODE_MIXED's SlowGrid */
    double x0, y0; /* lower corner of the grid */
    double inv_h;  /* 1 / cell side */
    double grow;   /* r plus the rounding margin: half the size of a box at rest */
    double reach;  /* MODE_MIXED: SlowGrid's */
    PathsPlan paths;
} Plan;

/* Where a thread's step loop spends its time (--stats): the plan; binning (the paths' phase A, the
 * grid's count and placement); the pairs (the paths' tiles, the grid's scan); the choice (its rounds'
 * barriers included); the move; waiting at the barriers after binning, the pairs and the move, for
 * the slowest thread; and the rest (printing, checkpoints, the disks back in original order at the
 * end). */
enum { PHASE_PLAN, PHASE_BIN, PHASE_PAIRS, PHASE_CHOICE, PHASE_MOVE, PHASE_WAIT, PHASE_OTHER, PHASES };

/* Per-thread state of the broad phase, padded so that threads never share a cache line. */
typedef struct {
    Found found;     /* pair events found by this thread this step */
    double phase_s[PHASES]; /* seconds in each phase (Broad's timing) */
    double phase_at;        /* when the last phase_mark was */
    int64_t partial; /* this thread's part of a prefix sum */
    real vmax;       /* the fastest velocity component of its disks (its last move) */
    /* the changes since the last plan to Broad's speed_n and speed_s1 */
    int64_t speed_n[SPEED_BINS], speed_s1[SPEED_BINS];
    int32_t *fast;   /* MODE_MIXED: the fast slots this thread binned */
    size_t fast_len, fast_cap;
    char pad[64];
} BroadThread;

typedef struct {
    Slots s, spare;   /* the disks, p->n of them; spare receives the next order */
    const Params *p;  /* p->n: the slots of this step */
    const Options *opt;
    double rx0, rx1, ry0, ry1; /* where the centres lie (the box unless the caller narrows it) */
    /* the periodic box (p->periodic): on an axis that wraps the cells tile [0, L) and the last cell's
     * neighbour is the first; on one that does not (mpi's strips along x) each box takes the image
     * nearest frame_x, the middle of the region. The narrow phase reads every disk as stored, by the
     * nearest image, whatever image its box took. */
    int wrap_x, wrap_y;
    double frame_x;
    int grid_only;    /* 1: the grid alone, whatever the cost model says (mpi's strips) */
    int nt, nt_max;   /* threads in the parallel region; BroadThreads allocated */
    int name_shift;   /* bits of a thread in the events' names (found_name) */
    int with_wi;
    int wall_lists;   /* 1: the caller reads the Found lists of wall events, and wall_t need hold
                       * every slot's time only where the paths or --check read it */
    int keep;         /* MODE_MIXED: SlowGrid's (the caller's; 0: all) */
    int timing;       /* 1: phase_mark adds up the phases' times (--stats) */
    int64_t *mark;    /* by slot, the caller's (omp.c) or NULL: on paths steps found_push marks the
                       * slots of every pair event with the step (Found's mark) */
    Plan plan;
    BroadThread *th;
    Paths *paths;     /* the broad phase of fast scenes */
    int64_t cap;      /* slots allocated */
    int64_t max_cells;
    int32_t *cell_of; /* cap entries the caller may use between steps (mpi.c) */
    int32_t *hist;    /* nt * max cells: per-thread cell counts, then write cursors */
    int32_t *cell_start; /* max cells + 1: first box of each cell */
    Box *boxes;       /* the boxes in cell order */
    int32_t *box_slot; /* the slots of those boxes */
    real *wall_t;     /* by slot: wall event time, or -1 (see wall_lists) */
    /* the disks by speed_bin, for the plan: how many, and the sum of their axis speeds (each at
     * most the box) in units of the box / 2^20; kept up to date through the threads' changes, as
     * only pair collisions change the size of a velocity component */
    int64_t speed_n[SPEED_BINS], speed_s1[SPEED_BINS];
} Broad;

/* The time since thread tid's last mark, to phase k (where b->timing). */
static inline void phase_mark(Broad *b, int tid, int k)
{
    if (!b->timing) return;
    BroadThread *th = &b->th[tid];
    double now = sim_clock();
    th->phase_s[k] += now - th->phase_at;
    th->phase_at = now;
}

/* Names of the events in the threads' Found lists, so that a choice refers to them where the threads
 * found them, without a copy: event k of thread t is (k << name_shift) + t. */
static inline int64_t found_name(const Broad *b, size_t k, int t)
{
    return ((int64_t)k << b->name_shift) + t;
}

static inline const Found *found_of_name(const Broad *b, int64_t e)
{
    return &b->th[e & ((1 << b->name_shift) - 1)].found;
}

static inline size_t found_index(const Broad *b, int64_t e)
{
    return (size_t)(e >> b->name_shift);
}

/* Slots for cap disks (grown by broad_reserve, outside a parallel region, contents of s kept), the
 * buffers of nt_max threads, the region the box. */
void broad_init(Broad *b, const Params *p, const Options *opt, int64_t cap, int nt_max, int with_wi);
void broad_reserve(Broad *b, int64_t cap);
void broad_free(Broad *b);
/* Slots reallocated to n disks (contents kept, wi only when with_wi), and freed */
void slots_resize(Slots *s, int64_t n, int with_wi);
void slots_free(Slots *s);
/* Called by every thread of the team: the speed histograms and fastest component counted afresh from
 * the slots (a caller whose set of disks changes every step; omp.c keeps them up to date instead). */
void broad_count_speeds(Broad *b, int tid);
/* Called by every thread of the team (b->nt of them): plans the step and finds every wall event into
 * b->wall_t and every pair event that before_walls admits into b->th[tid].found (reorder: the slots
 * are moved into cell order on the way; step names the step in --check's messages). again: a mixed
 * step found again keeping more (keep), under the plan it had: only the fast disks' events with
 * slow disks are found again (paths_refind), the others do not depend on keep. */
void broad_find(Broad *b, int tid, int64_t step, int reorder, int again);

/* ---- omp_exact.c ---------------------------------------------------------------------------------- */

/* omp's --exact engine: what backend_run does with --exact. */
int omp_exact_run(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *st);

#endif /* OMP_STEP_H */
