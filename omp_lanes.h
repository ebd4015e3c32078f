/* omp_lanes.h: phase B's screens of a cell's pairs of visits, LW pairs at a time. omp_paths.c
 * includes it once for each width it builds (1: plain C; 4: SSE2; 8: AVX2 and 16: AVX-512F, chosen
 * at run time where the processor has them), after defining:
 *   LW            the lanes: 1, 4, 8 or 16
 *   LN(name)      the instance's name of a function (name_4, ...)
 *   LATTR         attributes of its functions (the instruction set they may use)
 *   LV            a vector of LW floats, with LV_LOAD(p), LV_SET(x), LV_SUB, LV_MUL, LV_ADD and
 *                 LV_LE(a, b): the bit mask of the lanes where a <= b
 *   LRUN(m)       how many of the low bits of mask m are set in a row
 *   LCOUNT(m)     how many bits of m are set
 *   LPROBES       the visits a sweep takes through the later ones at a time: 1, or 2 where the
 *                 vector registers hold two probes
 * and it undefines them all at its end.
 * The widths screen the same pairs with the same float operations, so they pass the same ones: the
 * width changes how fast, never what is found. No branch per pair, whose outcome would be a coin
 * toss to a processor. A pair survives if its intervals overlap and, in float, the lines its two
 * disks move on come close enough (line); the few survivors go through meet in double. */

#define LFIRST(k) ((1u << (k)) - 1u) /* the first k bits */

/* Visit i as its pairs with LW others at a time need it, each value in every lane. */
typedef struct {
    LV t0, t1, x, y, vx, vy;
    LV s, c; /* line's bound: cr^2 <= s a + c */
} LN(Probe);

LATTR static inline void LN(probe_of)(const Paths *pp, const Visits *v, int32_t i, LN(Probe) *q)
{
    q->t0 = LV_SET(v->t0[i]);
    q->t1 = LV_SET(v->t1[i]);
    q->x = LV_SET(v->x[i]);
    q->y = LV_SET(v->y[i]);
    q->vx = LV_SET(v->vx[i]);
    q->vy = LV_SET(v->vy[i]);
    q->s = LV_SET(pp->pl.flt_s);
    q->c = LV_SET(pp->pl.flt_c);
}

/* The bits k of visits j + k whose intervals overlap the probe's. */
LATTR static inline unsigned LN(overlap)(const Visits *v, const LN(Probe) *q, int32_t j)
{
    return LV_LE(LV_LOAD(v->t0 + j), q->t1) & LV_LE(q->t0, LV_LOAD(v->t1 + j));
}

/* The bits k of visits j + k that enter no later than the probe leaves. */
LATTR static inline unsigned LN(enter)(const Visits *v, const LN(Probe) *q, int32_t j)
{
    return LV_LE(LV_LOAD(v->t0 + j), q->t1);
}

/* The bits k of visits j + k whose disk's line of motion may come within 2 G_TEST of the probe's:
 * the distance of closest approach of two lines is |cr| / sqrt(a), cr = dx dvy - dy dvx, a = |dv|^2,
 * and in float, with positions rounded (at most u X off, X the largest coordinate) and velocity
 * components (u vm), |cr| stays within 64 u X vm of its exact value and sqrt(a) within 6 u vm: every
 * pair that meets has |cr| <= s sqrt(a) + c (s = 2 G_TEST, c those terms). Squared, without the
 * square root (whose throughput bounds a wide screen): (s sqrt(a) + c)^2 <= (1 + e) s^2 a +
 * (1 + 1 / e) c^2 for any e > 0, as 2 s c sqrt(a) <= e s^2 a + c^2 / e. The plan holds those two
 * factors, rounded up and widened for the rounding of this test, and where coordinates or speeds are
 * too large for float squares, every pair goes through. */
LATTR static inline unsigned LN(line)(const Visits *v, const LN(Probe) *q, int32_t j)
{
    LV dx = LV_SUB(LV_LOAD(v->x + j), q->x), dy = LV_SUB(LV_LOAD(v->y + j), q->y);
    LV dvx = LV_SUB(LV_LOAD(v->vx + j), q->vx), dvy = LV_SUB(LV_LOAD(v->vy + j), q->vy);
    LV cr = LV_SUB(LV_MUL(dx, dvy), LV_MUL(dy, dvx));
    LV a = LV_ADD(LV_MUL(dvx, dvx), LV_MUL(dvy, dvy));
    return LV_LE(LV_MUL(cr, cr), LV_ADD(LV_MUL(q->s, a), q->c));
}

/* The survivors among the pairs (i, j + k) of mask m, through meet. */
LATTR static void LN(meet_mask)(const Paths *pp, const Visits *v, int32_t i, int32_t j, unsigned m,
                                int64_t cx, int64_t cy, const Params *p, Found *mine)
{
    Body A, B;
    int32_t qa = v->slot[i];
    body_of(v->s, qa, v->wall_t[qa], &A);
    for (; m; m &= m - 1) { /* the set bits, lowest first */
        int32_t qb = v->slot[j + __builtin_ctz(m)];
        body_of(v->s, qb, v->wall_t[qb], &B);
        meet(pp, &A, &B, qa, qb, cx, cy, p, mine);
    }
}

/* The pairs of the visits [lo, hi) of cell (cx, cy), few: each visit against the later ones, LW at
 * a time; line screens them where flt (a constant where inlined). v holds LANES_MAX spare entries
 * past hi. */
LATTR static inline void LN(pairs_of)(const Paths *pp, const Visits *v, int32_t lo, int32_t hi,
                                      int64_t cx, int64_t cy, const Params *p, Found *mine, int flt)
{
    uint64_t overlaps = 0;
    LN(Probe) q;
    for (int32_t i = lo; i + 1 < hi; i++) {
        LN(probe_of)(pp, v, i, &q);
        for (int32_t j = i + 1; j < hi; j += LW) {
            unsigned ov = LN(overlap)(v, &q, j);
            if (hi - j < LW) ov &= LFIRST(hi - j);
            unsigned m = flt ? ov & LN(line)(v, &q, j) : ov;
            overlaps += LCOUNT(ov);
            if (m) LN(meet_mask)(pp, v, i, j, m, cx, cy, p, mine);
        }
    }
    mine->overlaps += overlaps;
}

LATTR static void LN(cell_pairs)(const Paths *pp, const Visits *v, int32_t lo, int32_t hi,
                                 int64_t cx, int64_t cy, const Params *p, Found *mine)
{
    if (pp->pl.flt) LN(pairs_of)(pp, v, lo, hi, cx, cy, p, mine, 1);
    else LN(pairs_of)(pp, v, lo, hi, cx, cy, p, mine, 0);
}

/* The pairs of the visits [lo, hi) of cell (cx, cy), many, sorted by entry time: visit i overlaps
 * exactly the run of later visits that enter before it leaves, taken LW at a time; line screens
 * them where flt (a constant where inlined). */
LATTR static inline void LN(sweep_of)(const Paths *pp, const Visits *v, int32_t lo, int32_t hi,
                                      int64_t cx, int64_t cy, const Params *p, Found *mine, int flt)
{
    uint64_t overlaps = 0;
    LN(Probe) q;
    for (int32_t i = lo; i + 1 < hi; i++) {
        LN(probe_of)(pp, v, i, &q);
        for (int32_t j = i + 1; j < hi; j += LW) {
            unsigned e = LN(enter)(v, &q, j);
            if (hi - j < LW) e &= LFIRST(hi - j);
            unsigned run = LRUN(e);
            unsigned m = flt ? LFIRST(run) & LN(line)(v, &q, j) : LFIRST(run);
            overlaps += run;
            if (m) LN(meet_mask)(pp, v, i, j, m, cx, cy, p, mine);
            if (run < LW) break;
        }
    }
    mine->overlaps += overlaps;
}

#if LPROBES == 2
/* sweep_of two visits at a time, where the vector registers hold two probes (AVX-512F's 32; with
 * AVX2's 16 they spill, and the sweep ran slower than one visit at a time). Visits i and i + 1 go
 * through the later ones together: each block of LW is loaded once for both, and the loop ends
 * (which a processor mispredicts) once for both, when both runs have ended. Visit i + 1's own lane,
 * the first of the first block, counts as entering (its run goes on past it) but is never paired. */
LATTR static inline void LN(sweep2_of)(const Paths *pp, const Visits *v, int32_t lo, int32_t hi,
                                       int64_t cx, int64_t cy, const Params *p, Found *mine, int flt)
{
    uint64_t overlaps = 0;
    LN(Probe) a, b;
    int32_t i = lo;
    for (; i + 2 < hi; i += 2) {
        LN(probe_of)(pp, v, i, &a);
        LN(probe_of)(pp, v, i + 1, &b);
        unsigned live_a = 1, live_b = 1, own = 1; /* own: visit i + 1's lane in this block */
        for (int32_t j = i + 1; j < hi; j += LW) {
            unsigned ea = LN(enter)(v, &a, j), eb = LN(enter)(v, &b, j) | own;
            if (hi - j < LW) {
                ea &= LFIRST(hi - j);
                eb &= LFIRST(hi - j);
            }
            unsigned run_a = live_a ? LRUN(ea) : 0, run_b = live_b ? LRUN(eb) : 0;
            unsigned ma = LFIRST(run_a), mb = LFIRST(run_b) & ~own;
            if (flt) {
                ma &= LN(line)(v, &a, j);
                mb &= LN(line)(v, &b, j);
            }
            overlaps += run_a + run_b - (own & live_b);
            if (ma) LN(meet_mask)(pp, v, i, j, ma, cx, cy, p, mine);
            if (mb) LN(meet_mask)(pp, v, i + 1, j, mb, cx, cy, p, mine);
            live_a &= run_a == LW;
            live_b &= run_b == LW;
            own = 0;
            if (!(live_a | live_b)) break;
        }
    }
    mine->overlaps += overlaps;
    LN(sweep_of)(pp, v, i, hi, cx, cy, p, mine, flt); /* the last one or two visits */
}
#endif

LATTR static void LN(cell_sweep)(const Paths *pp, const Visits *v, int32_t lo, int32_t hi,
                                 int64_t cx, int64_t cy, const Params *p, Found *mine)
{
#if LPROBES == 2
    if (pp->pl.flt) LN(sweep2_of)(pp, v, lo, hi, cx, cy, p, mine, 1);
    else LN(sweep2_of)(pp, v, lo, hi, cx, cy, p, mine, 0);
#else
    if (pp->pl.flt) LN(sweep_of)(pp, v, lo, hi, cx, cy, p, mine, 1);
    else LN(sweep_of)(pp, v, lo, hi, cx, cy, p, mine, 0);
#endif
}

#undef LFIRST
#undef LW
#undef LN
#undef LATTR
#undef LV
#undef LV_LOAD
#undef LV_SET
#undef LV_SUB
#undef LV_MUL
#undef LV_ADD
#undef LV_LE
#undef LRUN
#undef LCOUNT
#undef LPROBES
