/* tools/gen.c: deterministic scene generator for tests and benchmarks.
 *
 * Writes an input file (SPEC.md 1) with explicit particle lines to stdout. Scenes are described by what
 * matters to the cost of a step: N, the area fraction (or the box side), how far a disk moves per step,
 * and whether disks may start overlapped. Reals are printed with 10 significant digits, which keeps
 * files small and parsing fast; the overlap test runs on the printed values, so "no overlap" holds for
 * the file as read. Above BAND_DISKS disks the box is cut into horizontal bands, each with its own
 * random stream, filled in parallel (even bands, then odd ones); the file depends on N and the seed,
 * never on the thread count.
 */
#define _POSIX_C_SOURCE 200809L

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PLACE_TRIES 10000
#define BAND_DISKS 1048576 /* disks per band: up to this N one band, the same file as ever */

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
    "  --overlap      centres uniform, overlaps allowed\n"
    "  --fast F       a fraction F of the disks, drawn at random, moves --fast-speed instead: a\n"
    "                 mixed scene (with --fast 0 the same scene, every disk at its own speed)\n"
    "  --fast-speed K speed of the fast disks: K*L per step (default 0.25, a quarter of the box)\n";

static void die(const char *msg, const char *arg)
{
    fprintf(stderr, "gen: %s%s%s\n", msg, arg ? " " : "", arg ? arg : "");
    exit(1);
}

/* splitmix64: enough for scenes, identical on every platform. */
static uint64_t rng_next(uint64_t *state)
{
    uint64_t z = (*state += UINT64_C(0x9e3779b97f4a7c15));
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

static double rng_unit(uint64_t *state)
{
    return (double)(rng_next(state) >> 11) * (1.0 / 9007199254740992.0);
}

typedef struct {
    char *text; /* its particle lines */
    size_t len, cap;
    int failed; /* a disk found no free place */
} Band;

typedef struct {
    int64_t n, cells, bands;
    double lo, hi, sigma2, cell, smin, smax;
    int overlap;
    double fast, fast_speed; /* --fast: fraction of fast disks (-1: option not given), their speed */
    int32_t *head, *next; /* disks by cell: first disk of each cell, next disk of each disk */
    double *x, *y;
    Band *band;
} Scene;

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


static void band_append(Band *bd, const char *line)
{
    size_t len = strlen(line);
    if (bd->len + len > bd->cap) {
        size_t cap = bd->cap ? 2 * bd->cap : 1 << 16;
        while (cap < bd->len + len) cap *= 2;
        char *grown = realloc(bd->text, cap);
        if (!grown) die("out of memory", NULL);
        bd->text = grown;
        bd->cap = cap;
    }
    memcpy(bd->text + bd->len, line, len);
    bd->len += len;
}

/* Places the disks of band b, those with indices [n b / bands, n (b + 1) / bands), centres in its strip
 * of [lo, hi]; with one band: the whole box, stream seed, as the generator always did. */
static void place_band(Scene *sc, int64_t b, uint64_t seed)
{
    Band *bd = &sc->band[b];
    uint64_t state = seed;
    if (b > 0) { /* a stream of its own: the seed hashed with the band */
        state = seed ^ ((uint64_t)b * UINT64_C(0xd1b54a32d192ed03));
        state = rng_next(&state);
    }
    double lo = sc->lo, hi = sc->hi, span = hi - lo;
    double ylo = b == 0 ? lo : lo + span * (double)b / (double)sc->bands;
    double yhi = b == sc->bands - 1 ? hi : lo + span * (double)(b + 1) / (double)sc->bands;
    int64_t cells = sc->cells;
    char text[4][32], line[160];
    for (int64_t i = sc->n * b / sc->bands; i < sc->n * (b + 1) / sc->bands; i++) {
        int64_t cx = 0, cy = 0;
        for (int tries = 0;; tries++) {
            if (tries == PLACE_TRIES) {
                bd->failed = 1;
                return;
            }
            sc->x[i] = printed(fmin(hi, lo + span * rng_unit(&state)), text[0]);
            sc->y[i] = printed(fmin(yhi, ylo + (yhi - ylo) * rng_unit(&state)), text[1]);
            if (sc->x[i] < lo || sc->x[i] > hi || sc->y[i] < lo || sc->y[i] > hi) continue;
            cx = (int64_t)(sc->x[i] / sc->cell);
            cy = (int64_t)(sc->y[i] / sc->cell);
            if (cx >= cells) cx = cells - 1;
            if (cy >= cells) cy = cells - 1;
            int clear = 1;
            for (int64_t ny = cy - 1; ny <= cy + 1 && clear && !sc->overlap; ny++)
                for (int64_t nx = cx - 1; nx <= cx + 1 && clear; nx++) {
                    if (nx < 0 || ny < 0 || nx >= cells || ny >= cells) continue;
                    for (int32_t j = sc->head[ny * cells + nx]; j >= 0 && clear; j = sc->next[j]) {
                        double dx = sc->x[j] - sc->x[i], dy = sc->y[j] - sc->y[i];
                        clear = dx * dx + dy * dy >= sc->sigma2;
                    }
                }
            if (clear) break;
        }
        sc->next[i] = sc->head[cy * cells + cx];
        sc->head[cy * cells + cx] = (int32_t)i;
        double s = sc->smin + (sc->smax - sc->smin) * rng_unit(&state), a = 6.283185307179586 * rng_unit(&state);
        if (sc->fast >= 0 && rng_unit(&state) < sc->fast) s = sc->fast_speed; /* drawn only with --fast */
        printed(s * cos(a), text[2]);
        printed(s * sin(a), text[3]);
        snprintf(line, sizeof line, "%lld %s %s %s %s\n", (long long)i, text[0], text[1], text[2], text[3]);
        band_append(bd, line);
    }
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
    double r = 1, fraction = 0.2, L = 0, speed = 0.5, fast = -1, fast_speed = 0.25;
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
        else if (strcmp(a, "--fast") == 0) fast = number(argv[++k]);
        else if (strcmp(a, "--fast-speed") == 0) fast_speed = number(argv[++k]);
        else die("unknown option", a);
    }
    if (L == 0) L = sqrt((double)n * 3.141592653589793 * r * r / fraction);
    char text[2][32];
    L = printed(L, text[0]);
    r = printed(r, text[1]);
    if (!(r > 0 && 2 * r < L)) die("radius does not fit the box", NULL);

    Scene sc;
    memset(&sc, 0, sizeof sc);
    sc.n = n;
    sc.lo = r;
    sc.hi = L - r;
    sc.sigma2 = (r + r) * (r + r);
    sc.overlap = overlap;
    sc.smax = speed * r;
    if (fast != -1 && !(fast >= 0 && fast <= 1)) die("--fast must be a fraction between 0 and 1", NULL);
    sc.fast = fast;
    sc.fast_speed = fast_speed * L;
    if (assignment) {
        sc.smin = fmin(L / 4, L / (8 * r));
        sc.smax = fmax(L / 4, L / (8 * r));
    }
    /* cells at least 2r wide, about one disk each: the overlap test looks at 9 cells */
    double fit = L / (2 * r), side = sqrt((double)n) + 1;
    sc.cells = (int64_t)(side < fit ? side : fit);
    if (sc.cells < 1) sc.cells = 1;
    sc.cell = L / (double)sc.cells;
    /* a band at least 4 cell rows high, so that bands two apart never look at the same cells */
    sc.bands = n > BAND_DISKS ? (n + BAND_DISKS - 1) / BAND_DISKS : 1;
    if (sc.bands > sc.cells / 4) sc.bands = sc.cells / 4 > 1 ? sc.cells / 4 : 1;
    sc.head = malloc((size_t)(sc.cells * sc.cells) * sizeof *sc.head);
    sc.next = malloc((size_t)n * sizeof *sc.next);
    sc.x = malloc((size_t)n * sizeof *sc.x);
    sc.y = malloc((size_t)n * sizeof *sc.y);
    sc.band = calloc((size_t)sc.bands, sizeof *sc.band);
    if (!sc.head || !sc.next || !sc.x || !sc.y || !sc.band) die("out of memory", NULL);
    memset(sc.head, 0xff, (size_t)(sc.cells * sc.cells) * sizeof *sc.head);
    for (int parity = 0; parity < 2; parity++) {
#pragma omp parallel for schedule(dynamic, 1)
        for (int64_t b = parity; b < sc.bands; b += 2) place_band(&sc, b, seed);
    }
    for (int64_t b = 0; b < sc.bands; b++)
        if (sc.band[b].failed) die("cannot place the disks without overlap; lower --fraction", NULL);
    printf("%lld\n%s\n%s\n%lld\n%s\n", (long long)n, text[0], text[1], steps, mode);
    for (int64_t b = 0; b < sc.bands; b++) {
        fwrite(sc.band[b].text, 1, sc.band[b].len, stdout);
        free(sc.band[b].text);
    }
    free(sc.band);
    free(sc.head);
    free(sc.next);
    free(sc.x);
    free(sc.y);
    return fflush(stdout) == 0 && !ferror(stdout) ? 0 : 1;
}
