/* tools/gen.c: deterministic scene generator for tests and benchmarks.
 *
 * Writes an input file (SPEC.md 1) with explicit particle lines to stdout. Scenes are described by what
 * matters to the cost of a step: N, the area fraction (or the box side), how far a disk moves per step,
 * and whether disks may start overlapped. Reals are printed with 10 significant digits, which keeps
 * files small and parsing fast; the overlap test runs on the printed values, so "no overlap" holds for
 * the file as read. Above BAND_DISKS disks the box is cut into horizontal bands, each with its own
 * random stream, filled in parallel (even bands, then odd ones); the file depends on N and the seed,
 * never on the thread count.
 *
 * --periodic writes a scene for the periodic box (SPEC.md 7): centres in [0, L), no two disks
 * overlapping by the nearest image (the simulator then needs --periodic too). --lattice writes a
 * triangular crystal filling the periodic box at the given area fraction: nx disks a row, ny rows (ny
 * even, so that the offset rows repeat across the edge), N = nx ny. No triangular lattice is periodic
 * in a square exactly (its rows are sqrt(3)/2 of its columns apart), so the pair (nx, ny) whose ratio
 * ny / nx is nearest 2 / sqrt(3) is chosen and the lattice stretched by that little (0.07% for N = 780,
 * 0.28% for 418) to fill the L x L box exactly; N without such a pair within 0.5% is refused with the
 * nearest counts that have one. Positions and velocities are printed with 17 digits (the crystal is
 * exact to rounding), the velocities with their mean taken off (zero total momentum, to rounding).
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
    "  --fast-speed K speed of the fast disks: K*L per step (default 0.25, a quarter of the box)\n"
    "  --periodic     for the periodic box (SPEC.md 7): centres in [0, L), no overlaps by the\n"
    "                 nearest image\n"
    "  --lattice      a triangular crystal filling the periodic box at --fraction (N = nx * ny,\n"
    "                 ny rows of nx, ny even, ny / nx near 2 / sqrt(3)); speeds as --speed,\n"
    "                 zero total momentum\n";

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
    int periodic; /* centres in [lo, hi) = [0, L), overlaps by the nearest image, cells that wrap */
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

/* A difference of two coordinates: in the periodic box its nearest image. */
static double nearest(const Scene *sc, double d)
{
    double L = sc->hi;
    if (!sc->periodic) return d;
    return d > L / 2 ? d - L : (d < -L / 2 ? d + L : d);
}

/* --lattice: the crystal of n = nx ny disks in ny rows (ny even) whose ratio ny / nx lies nearest
 * 2 / sqrt(3), stretched to fill the L x L box (see the top); die where no pair comes within 0.5%. */
static void lattice(int64_t n, double L, double speed, uint64_t seed, const char *header)
{
    const double ideal = 2 / sqrt(3.0);
    int64_t nx = 0, ny = 0;
    for (int64_t c = 1; c * c <= 2 * n; c++) {
        if (n % c || (n / c) % 2) continue;
        if (!nx || fabs((double)(n / c) / (double)c / ideal - 1) < fabs((double)ny / (double)nx / ideal - 1))
            nx = c, ny = n / c;
    }
    double stretch = nx ? (double)ny / (double)nx / ideal - 1 : 1;
    if (fabs(stretch) > 0.005) {
        fprintf(stderr, "gen: --lattice: no %lld = nx * ny (ny even) with ny / nx within 0.5%% of 2 / sqrt(3); "
                "counts that have one:", (long long)n);
        for (int64_t c = 2, shown = 0; shown < 8 && c < 1000; c++)
            for (int64_t r = 2; r < 1200; r += 2)
                if (fabs((double)r / (double)c / ideal - 1) <= 0.003 && shown < 8 && llabs(c * r - n) < n + 1000)
                    fprintf(stderr, " %lld (%lld x %lld)", (long long)(c * r), (long long)c, (long long)r), shown++;
        fputc('\n', stderr);
        exit(1);
    }
    double ax = L / (double)nx, by = L / (double)ny, *v = malloc(2 * (size_t)n * sizeof *v), mx = 0, my = 0;
    if (!v) die("out of memory", NULL);
    fputs(header, stdout);
    uint64_t state = seed;
    for (int64_t i = 0; i < n; i++) {
        double s = speed * rng_unit(&state), a = 6.283185307179586 * rng_unit(&state);
        v[2 * i] = s * cos(a), v[2 * i + 1] = s * sin(a);
        mx += v[2 * i] / (double)n, my += v[2 * i + 1] / (double)n;
    }
    for (int64_t j = 0, i = 0; j < ny; j++)
        for (int64_t k = 0; k < nx; k++, i++)
            printf("%lld %.17g %.17g %.17g %.17g\n", (long long)i, ((double)k + (j % 2 ? 0.75 : 0.25)) * ax,
                   ((double)j + 0.5) * by, v[2 * i] - mx, v[2 * i + 1] - my);
    fprintf(stderr, "gen: --lattice: %lld rows of %lld, stretched %+.3f%% from equilateral; neighbours %.17g and "
            "%.17g apart\n", (long long)ny, (long long)nx, 100 * stretch, ax, sqrt(ax * ax / 4 + by * by));
    free(v);
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
            if (sc->periodic && (sc->x[i] >= hi || sc->y[i] >= hi)) continue; /* [0, L) as printed */
            cx = (int64_t)(sc->x[i] / sc->cell);
            cy = (int64_t)(sc->y[i] / sc->cell);
            if (cx >= cells) cx = cells - 1;
            if (cy >= cells) cy = cells - 1;
            int clear = 1;
            for (int64_t ny = cy - 1; ny <= cy + 1 && clear && !sc->overlap; ny++)
                for (int64_t nx = cx - 1; nx <= cx + 1 && clear; nx++) {
                    int64_t ux = sc->periodic ? (nx + cells) % cells : nx, uy = sc->periodic ? (ny + cells) % cells : ny;
                    if (ux < 0 || uy < 0 || ux >= cells || uy >= cells) continue;
                    for (int32_t j = sc->head[uy * cells + ux]; j >= 0 && clear; j = sc->next[j]) {
                        double dx = nearest(sc, sc->x[j] - sc->x[i]), dy = nearest(sc, sc->y[j] - sc->y[i]);
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
    int assignment = 0, overlap = 0, periodic = 0, crystal = 0;
    const char *mode = "perf";
    for (int k = 2; k < argc; k++) {
        const char *a = argv[k];
        int has = k + 1 < argc;
        if (strcmp(a, "--assignment") == 0) assignment = 1;
        else if (strcmp(a, "--overlap") == 0) overlap = 1;
        else if (strcmp(a, "--periodic") == 0) periodic = 1;
        else if (strcmp(a, "--lattice") == 0) crystal = periodic = 1;
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
    if (crystal) { /* the side as printed fixes the crystal: every digit */
        snprintf(text[0], 32, "%.17g", L);
        snprintf(text[1], 32, "%.17g", r);
    }
    L = crystal ? strtod(text[0], NULL) : printed(L, text[0]);
    r = crystal ? strtod(text[1], NULL) : printed(r, text[1]);
    if (!(r > 0 && 2 * r < L)) die("radius does not fit the box", NULL);
    if (periodic && !(4 * r < L)) die("--periodic needs 4r < L", NULL);
    if (crystal) {
        char header[160];
        snprintf(header, sizeof header, "%lld\n%s\n%s\n%lld\n%s\n", (long long)n, text[0], text[1], steps, mode);
        lattice(n, L, speed * r, seed, header);
        return fflush(stdout) == 0 && !ferror(stdout) ? 0 : 1;
    }

    Scene sc;
    memset(&sc, 0, sizeof sc);
    sc.n = n;
    sc.lo = periodic ? 0 : r;
    sc.hi = periodic ? L : L - r;
    sc.periodic = periodic;
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
    if (periodic && sc.bands > 1 && sc.bands % 2) sc.bands--; /* the first and last bands meet: parities differ */
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
