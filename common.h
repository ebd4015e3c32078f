/* common.h: the state, the parameters and the physics shared by every backend.
 *
 * The physics is written once, here, as static inline helpers that both C99 and CUDA compile, so that
 * seq, omp and cuda run the very same arithmetic in the very same order (SPEC.md section 3). Build with
 * -ffp-contract=off (gcc) and --fmad=false (nvcc): a fused multiply-add would change the last bit and,
 * the dynamics being chaotic, every later digit.
 *
 * Units: lengths in the input's length unit, time in steps (one step = one time unit), velocities in
 * length units per step, unit masses.
 */
#ifndef COMMON_H
#define COMMON_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __CUDACC__
#define SIM_HD __host__ __device__
#else
#define SIM_HD
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* ---- precision ------------------------------------------------------------------------------------ */

/* SPEC.md is double precision. `make PRECISION=float` builds seq_f32, omp_f32 and cuda_f32 with
 * SIM_FLOAT: the same algorithm in single precision, every operation rounded to float (no literal or
 * library call may promote an expression to double). They agree with each other byte for byte, not
 * with the double build. */
#ifdef SIM_FLOAT
typedef float real;
#define SIM_SQRT sqrtf
#define SIM_FABS fabsf
#define SIM_FMOD fmodf
#define SIM_EPS 1.1920929e-7 /* FLT_EPSILON */
#define SIM_PRECISION "float"
#define SIM_SUFFIX "_f32" /* of program names: seq_f32, omp_f32, cuda_f32 */
#else
typedef double real;
#define SIM_SQRT sqrt
#define SIM_FABS fabs
#define SIM_FMOD fmod
#define SIM_EPS 2.220446049250313e-16 /* DBL_EPSILON */
#define SIM_PRECISION "double"
#define SIM_SUFFIX ""
#endif

/* Relative margins the broad phases (omp, cuda) add for rounding: of positions and times (REL, about
 * 4.5e6 rounding units of double, 84 of float) and of pair_time near a graze (GRAZE, about 4500 and 840
 * units). Wider margins only cost pair tests; narrower ones could miss an event. */
#ifdef SIM_FLOAT
#define SIM_REL_MARGIN 1e-5
#define SIM_GRAZE_MARGIN 1e-4
#else
#define SIM_REL_MARGIN 1e-9
#define SIM_GRAZE_MARGIN 1e-12
#endif

/* ---- limits of valid input (SPEC.md section 1) -------------------------------------------------- */

#define SIM_MAX_N 2147483647LL     /* particles */
#define SIM_MAX_STEPS 2147483647LL /* steps */
#ifdef SIM_FLOAT
/* Squares of products of lengths and speeds must stay finite and normal in float (about 1e38). */
#define SIM_MAX_L 1e9
#define SIM_MIN_R 1e-9
#define SIM_MAX_V 1e9
#else
#define SIM_MAX_L 1e50 /* side of the box */
#define SIM_MIN_R 1e-50 /* radius */
#define SIM_MAX_V 1e50 /* |vx|, |vy| */
#endif

/* ---- parameters (read-only during a run) ------------------------------------------------------- */

typedef struct {
    int64_t n;     /* number of disks, 1..SIM_MAX_N */
    real L;        /* side of the square box, length */
    real r;        /* radius of every disk, length */
    int64_t steps; /* S, number of steps (time units) to simulate */
    int print;     /* 1: print the state after every step; 0: perf, first and last state only */
    real lo;       /* smallest allowed centre coordinate: r */
    real hi;       /* largest allowed centre coordinate: L - r */
    real sigma2;   /* squared contact distance: (r + r) * (r + r) */
    int64_t substeps; /* K: sub-steps per step (--substeps), a power of two; 1 is SPEC.md */
    int64_t first_step; /* steps already run: 0, or the step of the checkpoint a run resumes from */
    int periodic;  /* --periodic: no walls, opposite edges joined (SPEC.md 7); lo and hi unused */
    real half;     /* L / 2: the nearest-image bound of SPEC.md 7 */
} Params;

/* The fields of Params that follow from L and r. */
static inline void params_derive(Params *p)
{
    p->lo = p->r;
    p->hi = p->L - p->r;
    p->sigma2 = (p->r + p->r) * (p->r + p->r);
    p->half = p->L / 2;
}

/* ---- state: structure of arrays, n entries each -------------------------------------------------- */

typedef struct {
    real *x, *y;     /* centres, length */
    real *vx, *vy;   /* velocities, length per step */
    int32_t *pc;     /* collisions with other disks so far (<= S x K, checked; --exact checks its own) */
    int32_t *wc;     /* collisions with walls so far */
    double *wi;      /* --pressure: wall impulse received so far (unit mass x velocity); in the periodic
                        box the impulse of its pair collisions (the virial's, SPEC.md 7); else NULL */
    int32_t *last;   /* --exact: partner of each disk's last event, -1 for none (exact.h); else NULL */
} Sim;

/* ---- state.c: messages, memory, the clock and the state's arrays -------------------------------- */

extern const char *sim_program; /* how messages name the program ("seq", "omp", ...); io_main sets it */
#ifdef __GNUC__
#define SIM_FAILS __attribute__((noreturn, format(printf, 1, 2)))
#else
#define SIM_FAILS
#endif
void sim_fail(const char *fmt, ...) SIM_FAILS; /* "program: message" on stderr, exit status 1 */
void *sim_calloc(size_t count, size_t size); /* zeroed memory, or sim_fail */
void *sim_realloc(void *ptr, size_t count, size_t size); /* realloc to count items, or sim_fail */
/* Grows *ptr to hold need items of size bytes (geometrically, *cap the items it holds); sim_fail when
 * memory runs out. */
void *sim_grow(void *ptr, size_t *cap, size_t need, size_t size);
/* sim_calloc on a cache line's boundary (64 bytes; freed by free): for arrays of per-thread records
 * padded to whole lines, which malloc's 16-byte alignment would let straddle two lines each, so that
 * neighbouring threads' records shared one. */
void *sim_calloc_lines(size_t count, size_t size);
double sim_clock(void);                      /* monotonic clock, seconds */
int sim_alloc(Sim *sim, int64_t n);          /* 0 on success */
void sim_free(Sim *sim);

/* ---- the physics of SPEC.md section 3 ------------------------------------------------------------ */

/* Time until a centre at coordinate c with velocity v reaches lo or hi (3.1): +inf if v == 0, never
 * negative. "<= 0" rather than "< 0" also turns -0.0 into +0.0, so event times are never -0.0. */
static inline SIM_HD real wall_time(real c, real v, real lo, real hi)
{
    real t = INFINITY;
    if (v > 0) t = (hi - c) / v;
    if (v < 0) t = (lo - c) / v;
    if (t <= 0) t = 0;
    return t;
}

/* Whether a centre at c with velocity v surely reaches no wall within time t (0 <= t <= 1), so that
 * wall_time(c, v, lo, hi) > t needs no division: the distance ahead, computed as wall_time computes
 * it, exceeds |v| t with SIM_REL_MARGIN to spare, far more than the three roundings between the two
 * (the product, the margin's, the quotient). Where |v| t is tiny (or 0, or v is 0) it answers no, and
 * the caller divides: no bound on the rounding of subnormal products is needed. */
static inline SIM_HD int wall_beyond(real c, real v, real t, real lo, real hi)
{
    real ahead = v > 0 ? hi - c : c - lo;
    real reach = SIM_FABS(v) * t * (real)(1 + SIM_REL_MARGIN);
    return reach > (real)1e-30 && ahead > reach;
}

static inline SIM_HD real min_time(real a, real b)
{
    return b < a ? b : a;
}

/* Time until two disks whose centres differ by (dx, dy) (j's minus i's) and velocities by (dvx, dvy)
 * touch (3.2), or -1 when they do not within `limit` time units: 1 for the step of SPEC.md, the rest
 * of the step for --exact. The root form c / (-b + SIM_SQRT(D)) never subtracts nearly equal
 * numbers. */
static inline SIM_HD real pair_time_rel(real dx, real dy, real dvx, real dvy, real sigma2, real limit)
{
    real b = dx * dvx + dy * dvy;
    if (!(b < 0)) return -1;
    real dd = dx * dx + dy * dy;
    if (!(dd > 0)) return -1;
    real a = dvx * dvx + dvy * dvy;
    real c = dd - sigma2;
    real D = b * b - a * c;
    if (!(D > 0)) return -1;
    real t = c / (-b + SIM_SQRT(D));
    if (t <= 0) t = 0;
    if (!(t <= limit)) return -1;
    return t;
}

/* Time until disks i and j touch (3.2), or -1 when they do not within `limit` time units. */
static inline SIM_HD real pair_time_within(real xi, real yi, real vxi, real vyi, real xj,
                                           real yj, real vxj, real vyj, real sigma2, real limit)
{
    return pair_time_rel(xj - xi, yj - yi, vxj - vxi, vyj - vyi, sigma2, limit);
}

/* Time of the pair event of disks i and j (3.2), or -1 when the pair has no event this step. */
static inline SIM_HD real pair_time(real xi, real yi, real vxi, real vyi, real xj,
                                      real yj, real vxj, real vyj, real sigma2)
{
    return pair_time_within(xi, yi, vxi, vyi, xj, yj, vxj, vyj, sigma2, 1);
}

/* The event order of 3.3: (t, kind, i, j) ascending; kind 0 is a wall event (j == i), 1 a pair. */
static inline SIM_HD int event_before(real ta, int ka, int64_t ia, int64_t ja, real tb, int kb,
                                      int64_t ib, int64_t jb)
{
    if (ta != tb) return ta < tb;
    if (ka != kb) return ka < kb;
    if (ia != ib) return ia < ib;
    return ja < jb;
}

/* Moves disk i to its wall event at t1 and reflects the axes that hit (3.4). */
static inline SIM_HD void wall_bounce(real *x, real *y, real *vx, real *vy, real t1,
                                      real lo, real hi)
{
    /* an axis that surely reaches no wall by t1 did not hit: most wall events need no division */
    int hx = !wall_beyond(*x, *vx, t1, lo, hi) && wall_time(*x, *vx, lo, hi) == t1;
    int hy = !wall_beyond(*y, *vy, t1, lo, hi) && wall_time(*y, *vy, lo, hi) == t1;
    if (hx) {
        *x = *vx > 0 ? hi : lo;
        *vx = -*vx;
    } else {
        *x = *x + *vx * t1;
    }
    if (hy) {
        *y = *vy > 0 ? hi : lo;
        *vy = -*vy;
    } else {
        *y = *y + *vy * t1;
    }
}

/* Elastic response of two equal disks in contact (3.4) whose centres differ by (nx, ny) (j's minus
 * i's): the normal components swap, the tangential ones stay. Coincident centres have no normal; their
 * velocities are left alone. Returns the impulse each disk received, |vni - vnj| (unit masses), for
 * --pressure's virial (0 for coincident centres); callers that need it not let the compiler drop it. */
static inline SIM_HD real pair_bounce_rel(real nx, real ny, real *vxi, real *vyi, real *vxj, real *vyj)
{
    real len = SIM_SQRT(nx * nx + ny * ny);
    if (len == 0) return 0;
    real ux = nx / len, uy = ny / len;
    real vni = ux * *vxi + uy * *vyi, vti = ux * *vyi - uy * *vxi;
    real vnj = ux * *vxj + uy * *vyj, vtj = ux * *vyj - uy * *vxj;
    *vxi = vnj * ux - vti * uy;
    *vyi = vnj * uy + vti * ux;
    *vxj = vni * ux - vtj * uy;
    *vyj = vni * uy + vtj * ux;
    return SIM_FABS(vni - vnj);
}

static inline SIM_HD real pair_bounce(real xi, real yi, real *vxi, real *vyi, real xj, real yj,
                                      real *vxj, real *vyj)
{
    return pair_bounce_rel(xj - xi, yj - yi, vxi, vyi, vxj, vyj);
}

/* The rest of the step after an event at t1 (3.4): fly on for 1 - t1, or stop touching the first wall
 * on the way, velocity unreflected (that collision happens, and counts, next step). */
static inline SIM_HD void finish_step(real *x, real *y, real vx, real vy, real t1,
                                      real lo, real hi)
{
    real rem = 1 - t1;
    if (wall_beyond(*x, vx, rem, lo, hi) && wall_beyond(*y, vy, rem, lo, hi)) { /* most disks */
        *x = *x + vx * rem;
        *y = *y + vy * rem;
        return;
    }
    real tx = wall_time(*x, vx, lo, hi), ty = wall_time(*y, vy, lo, hi);
    real t2 = min_time(tx, ty);
    if (t2 <= rem) {
        *x = tx == t2 ? (vx > 0 ? hi : lo) : *x + vx * t2;
        *y = ty == t2 ? (vy > 0 ? hi : lo) : *y + vy * t2;
    } else {
        *x = *x + vx * rem;
        *y = *y + vy * rem;
    }
}

/* Both disks of an accepted pair event fly to contact at t1 (3.4). */
static inline SIM_HD void pair_fly(real *xi, real *yi, real vxi, real vyi, real *xj, real *yj, real vxj,
                                   real vyj, real t1)
{
    *xi = *xi + vxi * t1;
    *yi = *yi + vyi * t1;
    *xj = *xj + vxj * t1;
    *yj = *yj + vyj * t1;
}

/* The first half of an accepted pair event at t1 (3.4): both disks fly to contact and swap their
 * normal velocities; returns the impulse (pair_bounce_rel). i is the lower original index. Backends
 * where each partner updates only itself (cuda) call this and then finish_step for their own side. */
static inline SIM_HD real pair_contact(real *xi, real *yi, real *vxi, real *vyi, real *xj,
                                       real *yj, real *vxj, real *vyj, real t1)
{
    pair_fly(xi, yi, *vxi, *vyi, xj, yj, *vxj, *vyj, t1);
    return pair_bounce(*xi, *yi, vxi, vyi, *xj, *yj, vxj, vyj);
}

/* An accepted pair event at t1 (3.4): both disks fly to contact, swap their normal velocities and
 * finish the step; returns the impulse. i is the lower original index. */
static inline SIM_HD real pair_collide(real *xi, real *yi, real *vxi, real *vyi, real *xj,
                                       real *yj, real *vxj, real *vyj, real t1, real lo,
                                       real hi)
{
    real dp = pair_contact(xi, yi, vxi, vyi, xj, yj, vxj, vyj, t1);
    finish_step(xi, yi, *vxi, *vyi, t1, lo, hi);
    finish_step(xj, yj, *vxj, *vyj, t1, lo, hi);
    return dp;
}

/* The impulse (unit mass) that wall_bounce gave a disk whose velocity went from (vx0, vy0) to
 * (vx1, vy1): 2 |v| for each reflected axis. Summed per disk in its own time order for --pressure,
 * so every backend adds the same numbers in the same order. */
static inline SIM_HD double wall_impulse(real vx0, real vy0, real vx1, real vy1)
{
    double p = 0;
    if (vx1 != vx0) p += 2 * fabs((double)vx0);
    if (vy1 != vy0) p += 2 * fabs((double)vy0);
    return p;
}

/* The margin a broad phase adds to r for rounding: of positions and times (rel of the contact
 * distance and of the coordinates' scale), and of pair_time near a graze, where D > 0 can hold while
 * the exact path misses contact by up to about eps * dd / r, for pairs no farther apart than reach. */
static inline SIM_HD double broad_margin(double r, double scale, double reach, double rel)
{
    return rel * (r + r) + rel * scale + SIM_GRAZE_MARGIN * (reach / r) * reach;
}

/* Keeps a coordinate in [lo, hi]: only one-ulp rounding ever needs it. */
static inline SIM_HD real clamp_coord(real c, real lo, real hi)
{
    return c < lo ? lo : (c > hi ? hi : c);
}

/* ---- the periodic box (--periodic, SPEC.md 7): no walls, opposite edges joined ----------------- */

/* The nearest image of a difference d of two coordinates: half = L / 2. */
static inline SIM_HD real wrap_delta(real d, real L, real half)
{
    if (d > half) d = d - L;
    else if (d < -half) d = d + L;
    return d;
}

/* A coordinate brought into [0, L) as SPEC.md 7 writes it (fmod is exact); one inside already is
 * what fmod returns for it, and needs no division. */
static inline SIM_HD real wrap_coord(real c, real L)
{
    if (c >= 0 && c < L) return c;
    c = SIM_FMOD(c, L);
    if (c < 0) c = c + L;
    if (c >= L) c = c - L;
    return c;
}

/* 3.2 in the periodic box: the nearest image's difference, the rest as written (-1: no event within
 * limit). */
static inline SIM_HD real pair_time_wrap(real xi, real yi, real vxi, real vyi, real xj, real yj, real vxj,
                                         real vyj, real sigma2, real L, real half, real limit)
{
    return pair_time_rel(wrap_delta(xj - xi, L, half), wrap_delta(yj - yi, L, half), vxj - vxi, vyj - vyi,
                         sigma2, limit);
}

/* pair_contact in the periodic box: the normal from the nearest image of the moved centres. */
static inline SIM_HD real pair_contact_wrap(real *xi, real *yi, real *vxi, real *vyi, real *xj, real *yj,
                                            real *vxj, real *vyj, real t1, real L, real half)
{
    pair_fly(xi, yi, *vxi, *vyi, xj, yj, *vxj, *vyj, t1);
    return pair_bounce_rel(wrap_delta(*xj - *xi, L, half), wrap_delta(*yj - *yi, L, half), vxi, vyi, vxj,
                           vyj);
}

/* The rest of the step after an event at t1 in the periodic box: no wall, no stop. */
static inline SIM_HD void fly_rest(real *x, real *y, real vx, real vy, real t1)
{
    real rem = 1 - t1;
    *x = *x + vx * rem;
    *y = *y + vy * rem;
}

/* pair_collide in the periodic box (the coordinates are brought into [0, L) with the others'). */
static inline SIM_HD real pair_collide_wrap(real *xi, real *yi, real *vxi, real *vyi, real *xj, real *yj,
                                            real *vxj, real *vyj, real t1, real L, real half)
{
    real dp = pair_contact_wrap(xi, yi, vxi, vyi, xj, yj, vxj, vyj, t1, L, half);
    fly_rest(xi, yi, *vxi, *vyi, t1);
    fly_rest(xj, yj, *vxj, *vyj, t1);
    return dp;
}

#ifdef __cplusplus
}
#endif

#endif /* COMMON_H */
