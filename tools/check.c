/* tools/check.c: checks the invariants of one simulator output against its input.
 *
 * usage: tools/check [--dump17] [--exact] [--periodic] INPUT OUTPUT
 *
 * - shape: step 0, then (print mode) steps 1..S-1, then step S with counts; each line "t i x y vx vy"
 *   (+ " p w" on the last step), i = 0..N-1 in order, one space between fields, '\n' after every line;
 * - every real is finite and written as %.8f prints it (or, with --dump17, as a %.17g token);
 * - every centre lies in [r, L-r] (exactly with --dump17; within the %.8f rounding otherwise);
 * - counts: p, w >= 0, p + w <= S (one event per disk per step), the sum of p is even;
 * - with --dump17: the kinetic energy of every printed step equals that of step 0 within a few ulps per
 *   pair collision (walls only negate components, which is exact); and between consecutive printed
 *   steps, a disk whose velocity stayed the same and whose centre moved to exactly clamp(x + vx, y + vy)
 *   had no event, so each disk's count of steps that were not such a plain move is at most its p + w.
 * --exact (output of --exact, any number of events per step): instead of p + w <= S and the plain-move
 * count, with --dump17, no two disks overlap in a printed step (by more than rounding) unless two did
 * at step 0.
 * --periodic (output of the periodic box, SPEC.md 7): centres in [0, L) instead, a plain move brings
 * x + vx into [0, L) by SPEC.md 7's formula, overlaps are by the nearest image, and w stays 0.
 * Prints nothing and exits 0 when all hold; otherwise one line "check: OUTPUT:line: problem", exit 1.
 */
#define _POSIX_C_SOURCE 200809L

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ENERGY_ULPS 16.0 /* allowed energy change per pair collision, in ulps of the total energy */

#define TOOL_NAME "check"
#include "output_error.h"

/* A %.8f token: [-]digits.dddddddd */
static int is_fixed8(const char *s, size_t len)
{
    size_t k = 0;
    if (k < len && s[k] == '-') k++;
    size_t d = k;
    while (k < len && s[k] >= '0' && s[k] <= '9') k++;
    if (k == d || k + 9 != len || s[k] != '.') return 0;
    for (k++; k < len; k++)
        if (s[k] < '0' || s[k] > '9') return 0;
    return 1;
}

/* A finite %.17g token: [-]digits[.digits][e(+|-)digits] */
static int is_g17(const char *s, size_t len)
{
    size_t k = 0;
    if (k < len && s[k] == '-') k++;
    size_t d = k;
    while (k < len && s[k] >= '0' && s[k] <= '9') k++;
    if (k == d) return 0;
    if (k < len && s[k] == '.') {
        size_t f = ++k;
        while (k < len && s[k] >= '0' && s[k] <= '9') k++;
        if (k == f) return 0;
    }
    if (k < len && s[k] == 'e') {
        k++;
        if (k < len && (s[k] == '+' || s[k] == '-')) k++;
        size_t e = k;
        while (k < len && s[k] >= '0' && s[k] <= '9') k++;
        if (k == e) return 0;
    }
    return k == len;
}

/* An integer token without sign or leading zeros. */
static double clamp(double c, double lo, double hi)
{
    return c < lo ? lo : (c > hi ? hi : c);
}

static const double *sort_x; /* x, y pairs that by_x sorts indices by */

static int by_x(const void *a, const void *b)
{
    double xa = sort_x[2 * *(const long long *)a], xb = sort_x[2 * *(const long long *)b];
    return (xa > xb) - (xa < xb);
}

static int periodic; /* --periodic */

/* A difference of two coordinates; with --periodic its nearest image. */
static double nearest(double d, double L)
{
    if (!periodic) return d;
    return d > L / 2 ? d - L : (d < -L / 2 ? d + L : d);
}

/* Returns 1 if two of the n centres xy (x, y pairs) are closer than 2r, less a relative 1e-9 and the
 * rounding of coordinates up to L: a sweep over the centres sorted by x (with --periodic also from
 * each centre back across x = 0 to the last ones, by the nearest image). */
static int overlapping(const double *xy, long long n, double r, double L, long long *order)
{
    double d = 2 * r * (1 - 1e-9) - 64 * DBL_EPSILON * L, d2 = d * d;
    for (long long i = 0; i < n; i++) order[i] = i;
    sort_x = xy;
    qsort(order, (size_t)n, sizeof *order, by_x);
    for (long long a = 0; a < n; a++) {
        const double *p = xy + 2 * order[a];
        for (long long b = a + 1; b < n && xy[2 * order[b]] - p[0] < d; b++) {
            double dx = xy[2 * order[b]] - p[0], dy = nearest(xy[2 * order[b] + 1] - p[1], L);
            if (dx * dx + dy * dy < d2) return 1;
        }
        for (long long b = n - 1; periodic && b > a && p[0] + L - xy[2 * order[b]] < d; b--) {
            double dx = nearest(xy[2 * order[b]] - p[0], L), dy = nearest(xy[2 * order[b] + 1] - p[1], L);
            if (dx * dx + dy * dy < d2) return 1;
        }
    }
    return 0;
}

/* A coordinate after a plain move: clamped into [lo, hi], or with --periodic brought into [0, L). */
static double into_box(double c, double lo, double hi, double L)
{
    if (!periodic) return clamp(c, lo, hi);
    if (c >= 0 && c < L) return c;
    c = fmod(c, L);
    if (c < 0) c = c + L;
    if (c >= L) c = c - L;
    return c;
}

static long long parse_count(const char *s, size_t len, const char *what)
{
    if (len == 0 || len > 18 || (len > 1 && s[0] == '0')) die("%s is not a plain integer", what);
    long long v = 0;
    for (size_t k = 0; k < len; k++) {
        if (s[k] < '0' || s[k] > '9') die("%s is not a plain integer", what);
        v = v * 10 + (s[k] - '0');
    }
    return v;
}

int main(int argc, char **argv)
{
    int dump17 = 0, exact = 0, a = 1;
    for (; a < argc && argv[a][0] == '-' && argv[a][1] == '-'; a++) {
        if (strcmp(argv[a], "--dump17") == 0) dump17 = 1;
        else if (strcmp(argv[a], "--exact") == 0) exact = 1;
        else if (strcmp(argv[a], "--periodic") == 0) periodic = 1;
        else break;
    }
    if (argc - a != 2) {
        fprintf(stderr, "usage: tools/check [--dump17] [--exact] [--periodic] INPUT OUTPUT\n");
        return 2;
    }
    FILE *in = fopen(argv[a], "r");
    if (!in) {
        fprintf(stderr, "check: cannot open %s\n", argv[a]);
        return 2;
    }
    char tok[5][64];
    for (int k = 0; k < 5; k++)
        if (fscanf(in, "%63s", tok[k]) != 1) {
            fprintf(stderr, "check: %s: short header\n", argv[a]);
            return 2;
        }
    fclose(in);
    long long n = atoll(tok[0]), steps = atoll(tok[3]);
    double L = strtod(tok[1], NULL), r = strtod(tok[2], NULL);
    double lo = periodic ? 0 : r, hi = periodic ? L : L - r;
    int print = strcmp(tok[4], "print") == 0;
    double slack = dump17 ? 0 : 0.5e-8 + 4 * DBL_EPSILON * hi; /* %.8f rounding of a centre */

    output_name = argv[a + 1];
    FILE *out = fopen(output_name, "r");
    if (!out) {
        fprintf(stderr, "check: cannot open %s\n", output_name);
        return 2;
    }
    char *line = NULL;
    size_t cap = 0;
    ssize_t len;
    long long blocks = print && steps > 1 ? steps + 1 : 2, block = 0, i = 0;
    long long step_of_block = 0, psum = 0;
    long double e0 = 0, e = 0, worst = 0;
    double *prev = calloc((size_t)n * 4 + 1, sizeof *prev);  /* x, y, vx, vy in the last block */
    long long *moved = calloc((size_t)n + 1, sizeof *moved); /* steps that were not a plain move */
    long long prev_step = -2; /* no block before step 0 */
    double *xy = calloc((size_t)n * 2 + 1, sizeof *xy); /* centres of the block (--exact) */
    long long *order = calloc((size_t)n + 1, sizeof *order);
    int start_overlaps = 0;
    if (!prev || !moved || !xy || !order) die("out of memory");
    while ((len = getline(&line, &cap, out)) > 0) {
        output_line++;
        if (block == blocks) die("more lines than the %lld expected", blocks * n);
        if (line[len - 1] != '\n') die("last line does not end in a newline");
        line[--len] = '\0';
        if (memchr(line, '\0', (size_t)len)) die("NUL byte in the line");
        int last = block == blocks - 1;
        step_of_block = last ? steps : block;
        int want = last ? 8 : 6;
        const char *f[8];
        size_t fl[8];
        int nf = 0;
        for (char *p = line;;) {
            char *sp = strchr(p, ' ');
            if (nf == 8) die("more than %d fields", want);
            f[nf] = p;
            fl[nf] = sp ? (size_t)(sp - p) : strlen(p);
            nf++;
            if (!sp) break;
            p = sp + 1;
        }
        if (nf != want) die("expected %d fields separated by single spaces, found %d", want, nf);
        if (parse_count(f[0], fl[0], "the step") != step_of_block)
            die("expected step %lld", step_of_block);
        if (parse_count(f[1], fl[1], "the index") != i) die("expected index %lld", i);
        double v[4];
        for (int k = 0; k < 4; k++) {
            if (!(dump17 ? is_g17(f[k + 2], fl[k + 2]) : is_fixed8(f[k + 2], fl[k + 2])))
                die("field %d '%.*s' is not a finite %s real", k + 3, (int)fl[k + 2], f[k + 2],
                    dump17 ? "%.17g" : "%.8f");
            v[k] = strtod(f[k + 2], NULL);
            if (!isfinite(v[k])) die("field %d is not finite", k + 3);
        }
        for (int k = 0; k < 2; k++) {
            if (periodic && !(v[k] >= -slack && (dump17 ? v[k] < L : v[k] <= L + slack)))
                die("%c = %.17g lies outside [0, L) = [0, %.17g)", "xy"[k], v[k], L);
            if (!periodic && !(v[k] >= lo - slack && v[k] <= hi + slack))
                die("%c = %.17g lies outside [r, L-r] = [%.17g, %.17g]", "xy"[k], v[k], lo, hi);
        }
        e += (long double)v[2] * v[2] + (long double)v[3] * v[3];
        double *q = prev + 4 * i;
        if (dump17 && step_of_block == prev_step + 1 &&
            !(v[2] == q[2] && v[3] == q[3] && v[0] == into_box(q[0] + q[2], lo, hi, L) &&
              v[1] == into_box(q[1] + q[3], lo, hi, L)))
            moved[i]++;
        memcpy(q, v, sizeof v);
        xy[2 * i] = v[0];
        xy[2 * i + 1] = v[1];
        if (last) {
            long long p = parse_count(f[6], fl[6], "p"), w = parse_count(f[7], fl[7], "w");
            if (periodic && w != 0) die("w = %lld in the periodic box, which has no walls", w);
            if (!exact && p + w > steps)
                die("p + w = %lld exceeds S = %lld (one event per step)", p + w, steps);
            if (!exact && moved[i] > p + w)
                die("disk %lld had %lld steps that were not a plain move, but p + w = %lld", i,
                    moved[i], p + w);
            psum += p;
        }
        if (++i == n) {
            if (exact && dump17) {
                int o = overlapping(xy, n, r, L, order);
                if (block == 0) start_overlaps = o;
                else if (o && !start_overlaps) die("two disks overlap at step %lld", step_of_block);
            }
            if (block == 0) e0 = e;
            long double d = fabsl(e - e0);
            if (d > worst) worst = d;
            e = 0;
            i = 0;
            block++;
            prev_step = step_of_block;
        }
    }
    free(line);
    free(prev);
    free(moved);
    free(xy);
    free(order);
    fclose(out);
    output_line++;
    if (block != blocks || i != 0) die("output ends early: expected %lld lines", blocks * n);
    if (psum % 2) die("the particle-collision counts add up to an odd %lld", psum);
    long double tol = ENERGY_ULPS * DBL_EPSILON * e0 * (long double)(psum / 2);
    if (dump17 && worst > tol)
        die("kinetic energy drifts by %Lg (step 0: %Lg), more than %g ulps per collision (%lld)", worst,
            e0, ENERGY_ULPS, psum / 2);
    return 0;
}
