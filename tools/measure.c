/* tools/measure.c: accuracy measures of one simulator output (tools/accuracy.sh uses them).
 *
 * usage: tools/measure [--depth D] [--periodic] INPUT [OUTPUT|-]
 *
 * INPUT gives N, L and r (its first three records); OUTPUT (default: standard input) is what a program
 * printed for it, in print or perf mode, with %.8f or --dump17 reals. Each state (N lines, one step) is
 * measured as it streams past, so outputs of many gigabytes need only O(N) memory:
 * - overlaps: pairs closer than 2r (deeper than D when --depth is given). A grid of cells at least 2r
 *   wide finds them in O(N) per state; the hard-disk model allows none, so every one is an error of the
 *   dynamics (or, at the depth of a rounding error, of the arithmetic). With --periodic (an output of
 *   the periodic box, SPEC.md 7) by the nearest image, the grid's cells wrapping.
 * - kinetic energy E = sum (vx^2 + vy^2) / 2 (unit masses) of every state, its drift
 *   max |E(t) - E(0)| / E(0), and kT = <v^2> / 2 = mean E / N (2D).
 * - collisions per unit time, from the final state's counts: pair collisions sum(p) / 2, wall
 *   collisions sum(w), each divided by its step number S (nan without counts or with S = 0).
 * Prints one line of key=value pairs on stdout; a malformed output is one line
 * "measure: OUTPUT:line: problem" on stderr and exit status 1.
 */
#define _POSIX_C_SOURCE 200809L

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char usage_text[] =
    "usage: tools/measure [--depth D] [--periodic] INPUT [OUTPUT|-]\n"
    "  INPUT     the simulator input (N, L and r are read from it)\n"
    "  OUTPUT    the program's stdout, print or perf mode, %.8f or --dump17 (default: stdin)\n"
    "  --depth D count only overlaps deeper than D (default 0: every pair closer than 2r)\n"
    "  --periodic  the output of a --periodic run: overlaps by the nearest image\n"
    "Prints one line of key=value pairs: states, overlap fraction of states, overlapping pairs per\n"
    "state, mean and max penetration 2r - distance, energy drift, kT, collisions per unit time.\n";

#define TOOL_NAME "measure"
#include "output_error.h"

/* ---- parsing --------------------------------------------------------------------------------------- */

/* A real token. Plain decimals of at most 15 digits (every %.8f token of a value below 1e7) are read as
 * integer / 10^k: both are exact doubles, so the one division rounds correctly, exactly as strtod
 * would, at a fraction of its cost; anything else goes to strtod. */
static double parse_real(const char *s, const char *end, int field)
{
    static const double pow10[] = {1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10,
                                   1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17};
    const char *p = s;
    int neg = 0, digits = 0, frac = -1;
    uint64_t m = 0;
    if (p < end && *p == '-') neg = 1, p++;
    for (; p < end; p++) {
        if (*p >= '0' && *p <= '9') {
            m = m * 10 + (uint64_t)(*p - '0');
            digits++;
            if (frac >= 0) frac++;
        } else if (*p == '.' && frac < 0) {
            frac = 0;
        } else {
            break;
        }
    }
    if (p == end && digits > 0 && digits <= 15 && frac != 0) {
        double v = (double)m;
        if (frac > 0) v /= pow10[frac];
        return neg ? -v : v;
    }
    char buf[64];
    size_t len = (size_t)(end - s);
    if (len == 0 || len >= sizeof buf) die("field %d is not a real", field);
    memcpy(buf, s, len);
    buf[len] = '\0';
    char *stop;
    double v = strtod(buf, &stop);
    if (*stop || !isfinite(v)) die("field %d '%s' is not a finite real", field, buf);
    return v;
}

static long long parse_int(const char *s, const char *end, int field)
{
    if (s == end || end - s > 18) die("field %d is not an integer", field);
    long long v = 0;
    for (const char *p = s; p < end; p++) {
        if (*p < '0' || *p > '9') die("field %d is not an integer", field);
        v = v * 10 + (*p - '0');
    }
    return v;
}

/* ---- one state ----------------------------------------------------------------------------------- */

typedef struct {
    int64_t n;
    double L, r, sigma, sigma2, depth;
    int periodic;            /* --periodic: nearest images, cells that wrap (3 or more a side, else 1) */
    double *x, *y, *vx, *vy; /* the state being read, n each */
    int64_t cells;           /* grid side in cells, each at least 2r wide */
    double cell;             /* cell width */
    int64_t *start;          /* cells * cells + 1: first entry of each cell in order[] */
    int64_t *order;          /* n: disk indices sorted by cell */
    int64_t *cell_of;        /* n */
    /* totals over the states */
    long long states, first_step, overlap_states, overlap_pairs;
    double depth_sum, depth_max;
    double e0, e_last, e_sum, drift;
} Measure;

static int64_t cell_coord(const Measure *m, double c)
{
    double k = floor(c / m->cell);
    if (!(k >= 0)) return 0; /* also a centre left of the box */
    if (k >= (double)m->cells) return m->cells - 1;
    return (int64_t)k;
}

/* A difference of two coordinates; with --periodic its nearest image (SPEC.md 7). */
static double nearest(const Measure *m, double d)
{
    if (!m->periodic) return d;
    return d > m->L / 2 ? d - m->L : (d < -m->L / 2 ? d + m->L : d);
}

/* Overlapping pairs of the state: each cell against itself and its E, NE, N and NW neighbours, so
 * each pair of cells is visited once. */
static void measure_overlaps(Measure *m)
{
    int64_t n = m->n, c = m->cells, nc = c * c;
    memset(m->start, 0, (size_t)(nc + 1) * sizeof *m->start);
    for (int64_t i = 0; i < n; i++) {
        m->cell_of[i] = cell_coord(m, m->y[i]) * c + cell_coord(m, m->x[i]);
        m->start[m->cell_of[i] + 1]++;
    }
    for (int64_t k = 0; k < nc; k++) m->start[k + 1] += m->start[k];
    for (int64_t i = 0; i < n; i++) m->order[m->start[m->cell_of[i]]++] = i;
    for (int64_t k = nc; k > 0; k--) m->start[k] = m->start[k - 1];
    m->start[0] = 0;

    static const int dx[5] = {0, 1, 1, 0, -1}, dy[5] = {0, 0, 1, 1, 1};
    long long pairs = 0;
    for (int64_t cy = 0; cy < c; cy++)
        for (int64_t cx = 0; cx < c; cx++) {
            int64_t a = cy * c + cx;
            for (int k = 0; k < 5; k++) {
                int64_t nx = cx + dx[k], ny = cy + dy[k];
                if (m->periodic && k > 0 && c == 1) continue; /* one cell: its own neighbour */
                if (m->periodic) nx = (nx + c) % c, ny = ny % c;
                if (nx < 0 || nx >= c || ny >= c) continue;
                int64_t b = ny * c + nx;
                for (int64_t p = m->start[a]; p < m->start[a + 1]; p++) {
                    int64_t i = m->order[p];
                    for (int64_t q = k == 0 ? p + 1 : m->start[b]; q < m->start[b + 1]; q++) {
                        int64_t j = m->order[q];
                        double ex = nearest(m, m->x[j] - m->x[i]), ey = nearest(m, m->y[j] - m->y[i]);
                        double d2 = ex * ex + ey * ey;
                        if (!(d2 < m->sigma2)) continue;
                        double depth = m->sigma - sqrt(d2);
                        if (!(depth > m->depth)) continue;
                        pairs++;
                        m->depth_sum += depth;
                        if (depth > m->depth_max) m->depth_max = depth;
                    }
                }
            }
        }
    m->overlap_pairs += pairs;
    m->overlap_states += pairs > 0;
}

static void measure_state(Measure *m, long long step)
{
    /* per-disk energies summed in long double: the drift of interest can be a few ulps */
    long double e = 0;
    for (int64_t i = 0; i < m->n; i++)
        e += 0.5L * ((long double)m->vx[i] * m->vx[i] + (long double)m->vy[i] * m->vy[i]);
    double ed = (double)e;
    if (m->states == 0) m->e0 = ed, m->first_step = step;
    m->e_last = ed;
    m->e_sum += ed;
    double d = m->e0 > 0 ? fabs(ed - m->e0) / m->e0 : 0;
    if (d > m->drift) m->drift = d;
    measure_overlaps(m);
    m->states++;
}

/* ---- main ------------------------------------------------------------------------------------------- */

static void read_input(const char *name, Measure *m)
{
    FILE *in = fopen(name, "r");
    char tok[3][64];
    if (!in) {
        fprintf(stderr, "measure: cannot open %s\n", name);
        exit(2);
    }
    for (int k = 0; k < 3; k++)
        if (fscanf(in, "%63s", tok[k]) != 1) {
            fprintf(stderr, "measure: %s: short header (N, L, r expected)\n", name);
            exit(2);
        }
    fclose(in);
    char *e0, *e1, *e2;
    long long n = strtoll(tok[0], &e0, 10);
    m->L = strtod(tok[1], &e1);
    m->r = strtod(tok[2], &e2);
    if (*e0 || *e1 || *e2 || n < 1 || !(m->r > 0) || !(2 * m->r < m->L) || !isfinite(m->L)) {
        fprintf(stderr, "measure: %s: bad header (N %s, L %s, r %s)\n", name, tok[0], tok[1], tok[2]);
        exit(2);
    }
    m->n = n;
}

int main(int argc, char **argv)
{
    Measure m = {0};
    const char *names[2] = {NULL, NULL};
    int named = 0;
    for (int k = 1; k < argc; k++) {
        if (strcmp(argv[k], "--help") == 0) {
            fputs(usage_text, stdout);
            return 0;
        } else if (strcmp(argv[k], "--depth") == 0 && k + 1 < argc) {
            char *end;
            m.depth = strtod(argv[++k], &end);
            if (*end || !(m.depth >= 0)) {
                fprintf(stderr, "measure: bad --depth %s\n", argv[k]);
                return 2;
            }
        } else if (strcmp(argv[k], "--periodic") == 0) {
            m.periodic = 1;
        } else if (named < 2) {
            names[named++] = argv[k];
        } else {
            fputs(usage_text, stderr);
            return 2;
        }
    }
    if (named < 1) {
        fputs(usage_text, stderr);
        return 2;
    }
    read_input(names[0], &m);
    FILE *out = stdin;
    if (named == 2 && strcmp(names[1], "-") != 0) {
        output_name = names[1];
        out = fopen(output_name, "r");
        if (!out) {
            fprintf(stderr, "measure: cannot open %s\n", output_name);
            return 2;
        }
    }

    int64_t n = m.n;
    m.sigma = m.r + m.r;
    m.sigma2 = m.sigma * m.sigma;
    double fit = floor(m.L / m.sigma), side = floor(sqrt((double)n)) + 1;
    m.cells = (int64_t)(side < fit ? side : fit);
    if (m.cells < 1 || (m.periodic && m.cells < 3)) m.cells = 1;
    m.cell = m.L / (double)m.cells;
    m.x = malloc((size_t)n * sizeof(double));
    m.y = malloc((size_t)n * sizeof(double));
    m.vx = malloc((size_t)n * sizeof(double));
    m.vy = malloc((size_t)n * sizeof(double));
    m.start = malloc((size_t)(m.cells * m.cells + 1) * sizeof(int64_t));
    m.order = malloc((size_t)n * sizeof(int64_t));
    m.cell_of = malloc((size_t)n * sizeof(int64_t));
    if (!m.x || !m.y || !m.vx || !m.vy || !m.start || !m.order || !m.cell_of) die("out of memory");

    char *line = NULL;
    size_t cap = 0;
    ssize_t len;
    int64_t i = 0;
    long long step = -1, last_step = -1, psum = 0, wsum = 0;
    int counted = 0; /* the state being read has p and w columns */
    while ((len = getline(&line, &cap, out)) > 0) {
        output_line++;
        if (line[len - 1] == '\n') line[--len] = '\0';
        const char *f[8], *fe[8];
        int nf = 0;
        for (const char *p = line; *p;) {
            while (*p == ' ' || *p == '\t' || *p == '\r') p++;
            if (!*p) break;
            if (nf == 8) die("more than 8 fields");
            f[nf] = p;
            while (*p && *p != ' ' && *p != '\t' && *p != '\r') p++;
            fe[nf++] = p;
        }
        if (nf != 6 && nf != 8) die("expected 6 or 8 fields, found %d", nf);
        long long t = parse_int(f[0], fe[0], 1);
        if (parse_int(f[1], fe[1], 2) != i) die("expected disk %lld", (long long)i);
        if (i == 0) {
            if (t <= last_step && last_step >= 0) die("step %lld does not follow step %lld", t, last_step);
            step = t;
            counted = nf == 8;
        } else if (t != step) {
            die("step %lld inside the block of step %lld", t, step);
        } else if ((nf == 8) != counted) {
            die("counts on some lines of a state but not on others");
        }
        m.x[i] = parse_real(f[2], fe[2], 3);
        m.y[i] = parse_real(f[3], fe[3], 4);
        m.vx[i] = parse_real(f[4], fe[4], 5);
        m.vy[i] = parse_real(f[5], fe[5], 6);
        if (counted) {
            psum += parse_int(f[6], fe[6], 7);
            wsum += parse_int(f[7], fe[7], 8);
        }
        if (++i == n) {
            measure_state(&m, step);
            last_step = step;
            i = 0;
        }
    }
    output_line++;
    if (ferror(out)) die("read error");
    if (i != 0) die("output ends inside a state (%lld of %lld lines)", (long long)i, (long long)n);
    if (m.states == 0) die("no state");
    if (counted && psum % 2) die("the particle-collision counts add up to an odd %lld", psum);

    double nan = strtod("nan", NULL);
    double pairs = counted ? (double)psum / 2 : nan, walls = counted ? (double)wsum : nan;
    double per = counted && last_step > 0 ? 1.0 / (double)last_step : nan;
    double e_mean = m.e_sum / (double)m.states;
    printf("states=%lld n=%lld L=%.17g r=%.17g first_step=%lld last_step=%lld"
           " overlap_state_fraction=%.6g overlap_pairs_per_state=%.6g mean_penetration=%.6g"
           " max_penetration=%.6g max_penetration_over_r=%.6g"
           " energy_first=%.17g energy_last=%.17g energy_drift=%.6g kT=%.17g"
           " pair_collisions=%.17g wall_collisions=%.17g pair_collisions_per_time=%.10g"
           " wall_collisions_per_time=%.10g\n",
           m.states, (long long)n, m.L, m.r, m.first_step, last_step, (double)m.overlap_states / (double)m.states,
           (double)m.overlap_pairs / (double)m.states,
           m.overlap_pairs ? m.depth_sum / (double)m.overlap_pairs : 0.0, m.depth_max,
           m.depth_max / m.r, m.e0, m.e_last, m.drift, e_mean / (double)n, pairs, walls,
           pairs * per, walls * per);
    free(line);
    free(m.x);
    free(m.y);
    free(m.vx);
    free(m.vy);
    free(m.start);
    free(m.order);
    free(m.cell_of);
    if (out != stdin) fclose(out);
    return fflush(stdout) == 0 && !ferror(stdout) ? 0 : 1;
}
