/* tools/gen.c: deterministic scene generator for tests and benchmarks.
 *
 * Writes an input file (SPEC.md 1) with explicit particle lines to stdout. Scenes are described by what
 * matters to the cost of a step: N, the area fraction (or the box side), how far a disk moves per step,
 * and whether disks may start overlapped. Reals are printed with 10 significant digits, which keeps
 * files small and parsing fast; the overlap test runs on the printed values, so "no overlap" holds for
 * the file as read.
 */
#define _POSIX_C_SOURCE 200809L

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PLACE_TRIES 10000

static const char usage_text[] =
    "usage: tools/gen N [options] > scene.in\n"
    "  --r R          radius (default 1)\n"
    "  --fraction F   area fraction N*pi*r^2/L^2, sets L (default 0.2)\n"
    "  --L L          box side (instead of --fraction)\n"
    "  --speed K      speeds uniform in [0, K*r] per step, uniform direction (default 0.5)\n"
    "  --assignment   speeds uniform in [L/(8r), L/4] (either order), as in random inputs\n"
    "  --steps S      steps (default 100)\n"
    "  --mode M       print or perf (default perf)\n"
    "  --seed N       seed (default 1)\n"
    "  --overlap      centres uniform, overlaps allowed\n";

static void die(const char *msg, const char *arg)
{
    fprintf(stderr, "gen: %s%s%s\n", msg, arg ? " " : "", arg ? arg : "");
    exit(1);
}

static uint64_t rng_state;

/* splitmix64: enough for scenes, identical on every platform. */
static uint64_t rng_next(void)
{
    uint64_t z = (rng_state += UINT64_C(0x9e3779b97f4a7c15));
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

static double rng_unit(void)
{
    return (double)(rng_next() >> 11) * (1.0 / 9007199254740992.0);
}

/* The value as the simulator will read it back from the printed text. */
static double printed(double v, char *text)
{
    snprintf(text, 32, "%.10g", v);
    return strtod(text, NULL);
}

static double number(const char *s)
{
    char *end;
    double v = strtod(s, &end);
    if (*end || !isfinite(v)) die("not a number:", s);
    return v;
}

int main(int argc, char **argv)
{
    if (argc < 2 || strcmp(argv[1], "--help") == 0) {
        fputs(usage_text, argc < 2 ? stderr : stdout);
        return argc < 2;
    }
    double n_real = number(argv[1]);
    if (n_real < 1 || n_real > 2147483647.0 || n_real != floor(n_real)) die("bad N:", argv[1]);
    int64_t n = (int64_t)n_real;
    double r = 1, fraction = 0.2, L = 0, speed = 0.5;
    long long steps = 100;
    uint64_t seed = 1;
    int assignment = 0, overlap = 0;
    const char *mode = "perf";
    for (int k = 2; k < argc; k++) {
        const char *a = argv[k];
        int has = k + 1 < argc;
        if (strcmp(a, "--assignment") == 0) assignment = 1;
        else if (strcmp(a, "--overlap") == 0) overlap = 1;
        else if (!has) die("missing value after", a);
        else if (strcmp(a, "--r") == 0) r = number(argv[++k]);
        else if (strcmp(a, "--fraction") == 0) fraction = number(argv[++k]);
        else if (strcmp(a, "--L") == 0) L = number(argv[++k]);
        else if (strcmp(a, "--speed") == 0) speed = number(argv[++k]);
        else if (strcmp(a, "--steps") == 0) steps = (long long)number(argv[++k]);
        else if (strcmp(a, "--mode") == 0) mode = argv[++k];
        else if (strcmp(a, "--seed") == 0) seed = (uint64_t)number(argv[++k]);
        else die("unknown option", a);
    }
    if (L == 0) L = sqrt((double)n * 3.141592653589793 * r * r / fraction);
    char text[6][32];
    L = printed(L, text[0]);
    r = printed(r, text[1]);
    if (!(r > 0 && 2 * r < L)) die("radius does not fit the box", NULL);
    double lo = r, hi = L - r, sigma2 = (r + r) * (r + r);
    printf("%lld\n%s\n%s\n%lld\n%s\n", (long long)n, text[0], text[1], steps, mode);

    /* cells at least 2r wide, about one disk each: the overlap test looks at 9 cells */
    double fit = L / (2 * r), side = sqrt((double)n) + 1;
    int64_t cells = (int64_t)(side < fit ? side : fit);
    if (cells < 1) cells = 1;
    double cell = L / (double)cells;
    int32_t *head = malloc((size_t)(cells * cells) * sizeof *head);
    int32_t *next = malloc((size_t)n * sizeof *next);
    double *x = malloc((size_t)n * sizeof *x), *y = malloc((size_t)n * sizeof *y);
    if (!head || !next || !x || !y) die("out of memory", NULL);
    memset(head, 0xff, (size_t)(cells * cells) * sizeof *head);
    rng_state = seed;
    double smin = 0, smax = speed * r;
    if (assignment) {
        smin = fmin(L / 4, L / (8 * r));
        smax = fmax(L / 4, L / (8 * r));
    }
    for (int64_t i = 0; i < n; i++) {
        int64_t cx = 0, cy = 0;
        for (int tries = 0;; tries++) {
            if (tries == PLACE_TRIES) die("cannot place the disks without overlap; lower --fraction", NULL);
            x[i] = printed(fmin(hi, lo + (hi - lo) * rng_unit()), text[2]);
            y[i] = printed(fmin(hi, lo + (hi - lo) * rng_unit()), text[3]);
            if (x[i] < lo || x[i] > hi || y[i] < lo || y[i] > hi) continue;
            cx = (int64_t)(x[i] / cell);
            cy = (int64_t)(y[i] / cell);
            if (cx >= cells) cx = cells - 1;
            if (cy >= cells) cy = cells - 1;
            int clear = 1;
            for (int64_t ny = cy - 1; ny <= cy + 1 && clear && !overlap; ny++)
                for (int64_t nx = cx - 1; nx <= cx + 1 && clear; nx++) {
                    if (nx < 0 || ny < 0 || nx >= cells || ny >= cells) continue;
                    for (int32_t j = head[ny * cells + nx]; j >= 0 && clear; j = next[j]) {
                        double dx = x[j] - x[i], dy = y[j] - y[i];
                        clear = dx * dx + dy * dy >= sigma2;
                    }
                }
            if (clear) break;
        }
        next[i] = head[cy * cells + cx];
        head[cy * cells + cx] = (int32_t)i;
        double s = smin + (smax - smin) * rng_unit(), a = 6.283185307179586 * rng_unit();
        printed(s * cos(a), text[4]);
        printed(s * sin(a), text[5]);
        printf("%lld %s %s %s %s\n", (long long)i, text[2], text[3], text[4], text[5]);
    }
    free(head);
    free(next);
    free(x);
    free(y);
    return fflush(stdout) == 0 && !ferror(stdout) ? 0 : 1;
}
