/* tools/xyz.c: a simulator output as extended XYZ, one frame per printed step, for ASE, OVITO or VMD.
 *
 * usage: tools/xyz [--periodic] INPUT [OUTPUT|-]
 *
 * INPUT is the simulator input (its header gives N, L, r, S and print|perf; particle lines are not read);
 * OUTPUT (default: standard input) is what a program printed for it: step 0, then (print mode) steps
 * 1..S-1, then step S with the counts p and w, exactly as SPEC.md 2 lays them out, with %.8f or --dump17
 * reals. Each printed step becomes one frame:
 *   N
 *   Lattice="L 0 0 0 L 0 0 0 T" Properties=id:I:1:pos:R:3:velo:R:3:radius:R:1 Time=K pbc="F F F"
 *   i x y 0 vx vy 0 r                      (N lines, i = 0..N-1)
 * and the final step's frame adds the counts as two more columns, declared as
 * ":collisions:I:1:wall_collisions:I:1" at the end of its Properties, so that nothing is lost.
 * With --periodic (the output of a --periodic run: the input's format has no mark of it) the frames
 * say pbc="T T F": the box wraps along x and y (SPEC.md 7), and a reader draws the disks across the
 * edges and measures distances by the nearest image.
 * x, y, vx and vy are copied as the bytes the program printed (never read back into doubles and printed
 * again), so the frames hold exactly what the output held; L, r and T are printed in the fewest digits
 * that read back as the same double.
 *
 * The conversion streams: each line is checked and written as it arrives (a frame's two header lines
 * when its first disk does), so memory stays constant whatever the number of steps. Every line must be
 * the one SPEC.md 2 puts there (the expected step, index i in order, 6 fields or 8 on the final step,
 * finite reals, plain integers, '\n' at the end); anything else, or an output that ends early, stops the
 * conversion with one line "xyz: FILE:LINE: problem" on stderr and exit status 1. The frames before it
 * (and the start of the frame being written) are then on stdout already: a streaming filter cannot take
 * them back, so the exit status is what tells a caller that the file is incomplete.
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char usage_text[] =
    "usage: tools/xyz [--periodic] INPUT [OUTPUT|-] > frames.xyz\n"
    "  INPUT   the simulator input file (N, L, r, S and print|perf are read from its header)\n"
    "  OUTPUT  the program's stdout for it, print or perf mode, %.8f or --dump17 (default or -: stdin)\n"
    "Writes extended XYZ, one frame per printed step (step 0, each printed step, step S):\n"
    "  N\n"
    "  Lattice=\"L 0 0 0 L 0 0 0 2r\" Properties=id:I:1:pos:R:3:velo:R:3:radius:R:1 Time=STEP pbc=\"F F F\"\n"
    "  i x y 0 vx vy 0 r          (N lines, x y vx vy copied byte for byte from OUTPUT)\n"
    "The final frame (step S) also has the collision counts p and w as two more columns, declared by\n"
    "appending :collisions:I:1:wall_collisions:I:1 to its Properties. The third axis is a slab 2r\n"
    "thick (a disk's diameter) with every centre at z = 0; pbc is off (the walls reflect).\n"
    "--periodic: OUTPUT is a --periodic run's (SPEC.md 7): pbc=\"T T F\", the box wraps along x, y.\n"
    "Streams in constant memory. A malformed or mismatched OUTPUT or a bad INPUT header: one line\n"
    "\"xyz: FILE:LINE: problem\" on stderr and exit status 1 (frames before it may have been written);\n"
    "a missing file or a failed write: exit status 1; bad usage: exit status 2.\n";

#define TOOL_NAME "xyz"
#include "output_error.h"

#define FIELDS_MAX 8 /* "t i x y vx vy p w" */
#define TOKEN_SHOWN 40 /* at most this many bytes of a bad token go into a message */

/* ---- tokens ---------------------------------------------------------------------------------------- */

typedef struct {
    const char *s; /* first byte */
    size_t len;
} Token;

static int is_space(char c)
{
    return c == ' ' || c == '\t' || c == '\r';
}

/* Splits s (NUL-terminated, no '\n') at spaces, tabs and CRs into at most max tokens; returns the count,
 * or max + 1 when there are more. */
static int split(const char *s, Token *tok, int max)
{
    int n = 0;
    for (const char *p = s;;) {
        while (is_space(*p)) p++;
        if (!*p) return n;
        if (n == max) return max + 1;
        tok[n].s = p;
        while (*p && !is_space(*p)) p++;
        tok[n].len = (size_t)(p - tok[n].s);
        n++;
    }
}

static int shown(const Token *t)
{
    return t->len < TOKEN_SHOWN ? (int)t->len : TOKEN_SHOWN;
}

/* A plain non-negative integer as the simulator prints one: digits, no sign, no leading zero, at most 18
 * digits (so it fits a long long). Returns -1 for anything else. */
static long long plain_int(const Token *t)
{
    if (t->len == 0 || t->len > 18 || (t->len > 1 && t->s[0] == '0')) return -1;
    long long v = 0;
    for (size_t k = 0; k < t->len; k++) {
        if (t->s[k] < '0' || t->s[k] > '9') return -1;
        v = v * 10 + (t->s[k] - '0');
    }
    return v;
}

/* A finite real as %.8f or %.17g prints one: [-]digits[.digits][(e|E)[+|-]digits]. Fixed notation with
 * at most 300 integer digits is below 1e300 and so finite by its shape alone; only the rest is read by
 * strtod, so that long outputs are not dominated by it. */
static int finite_real(const Token *t)
{
    const char *s = t->s, *end = t->s + t->len, *p = s;
    if (p < end && *p == '-') p++;
    const char *d = p;
    while (p < end && *p >= '0' && *p <= '9') p++;
    size_t int_digits = (size_t)(p - d);
    if (int_digits == 0) return 0;
    if (p < end && *p == '.') {
        const char *f = ++p;
        while (p < end && *p >= '0' && *p <= '9') p++;
        if (p == f) return 0;
    }
    int exponent = 0;
    if (p < end && (*p == 'e' || *p == 'E')) {
        exponent = 1;
        p++;
        if (p < end && (*p == '+' || *p == '-')) p++;
        const char *e = p;
        while (p < end && *p >= '0' && *p <= '9') p++;
        if (p == e) return 0;
    }
    if (p != end) return 0;
    if (!exponent && int_digits <= 300) return 1;
    char *copy = malloc(t->len + 1), *stop;
    if (!copy) die("out of memory");
    memcpy(copy, s, t->len);
    copy[t->len] = '\0';
    double v = strtod(copy, &stop);
    free(copy);
    return isfinite(v);
}

/* The shortest of %.15g, %.16g, %.17g that reads back as v (%.17g always does). */
static void shortest(char *buf, size_t size, double v)
{
    for (int digits = 15; digits <= 17; digits++) {
        snprintf(buf, size, "%.*g", digits, v);
        if (strtod(buf, NULL) == v) return;
    }
}

/* ---- the input's header ---------------------------------------------------------------------------- */

typedef struct {
    long long n;       /* disks */
    double L, r;       /* box side, radius */
    long long steps;   /* S */
    int print;         /* print mode: every step printed */
    char L_text[32];   /* L, r and the slab thickness 2r as written in every frame */
    char r_text[32];
    char T_text[32];
} Header;

/* One header record (a line of one token; blank lines before it are skipped) into tok, or dies. */
static void header_record(FILE *in, char **line, size_t *cap, Token *tok, const char *what)
{
    ssize_t len;
    for (;;) {
        errno = 0;
        len = getline(line, cap, in);
        if (len < 0) {
            output_line++;
            if (ferror(in)) die("read error (%s)", strerror(errno));
            die("the header ends before %s (N, L, r, S and print|perf expected)", what);
        }
        output_line++;
        if ((*line)[len - 1] == '\n') (*line)[--len] = '\0';
        if (memchr(*line, '\0', (size_t)len)) die("NUL byte in the line");
        Token t[2];
        int nf = split(*line, t, 1);
        if (nf == 0) continue;
        if (nf > 1) die("%s: expected one token on the line, found more", what);
        *tok = t[0];
        return;
    }
}

/* An integer token of the header: [+]digits, within [lo, hi]. */
static long long header_int(const Token *t, long long lo, long long hi, const char *what)
{
    const char *p = t->s, *end = t->s + t->len;
    if (p < end && *p == '+') p++;
    if (p == end || end - p > 18) die("%s is not an integer (found '%.*s')", what, shown(t), t->s);
    long long v = 0;
    for (; p < end; p++) {
        if (*p < '0' || *p > '9') die("%s is not an integer (found '%.*s')", what, shown(t), t->s);
        v = v * 10 + (*p - '0');
    }
    if (v < lo || v > hi) die("%s must lie in %lld .. %lld (found '%.*s')", what, lo, hi, shown(t), t->s);
    return v;
}

/* A real token of the header: decimal digits, sign, point and exponent only (no inf, nan or hex). */
static double header_real(const Token *t, const char *what)
{
    char buf[128], *stop;
    if (t->len >= sizeof buf || strspn(t->s, "+-.0123456789eE") < t->len)
        die("%s is not a real (found '%.*s')", what, shown(t), t->s);
    memcpy(buf, t->s, t->len);
    buf[t->len] = '\0';
    double v = strtod(buf, &stop);
    if (stop == buf || *stop || !isfinite(v)) die("%s is not a finite real (found '%s')", what, buf);
    return v;
}

/* Reads N, L, r, S and the mode from INPUT, checked as SPEC.md 1 states them. */
static void header_read(const char *name, Header *h)
{
    FILE *in = fopen(name, "r");
    if (!in) {
        fprintf(stderr, "xyz: cannot open %s (%s)\n", name, strerror(errno));
        exit(1);
    }
    output_name = name;
    output_line = 0;
    char *line = NULL;
    size_t cap = 0;
    Token t;
    header_record(in, &line, &cap, &t, "N");
    h->n = header_int(&t, 1, INT_MAX, "N");
    header_record(in, &line, &cap, &t, "L");
    h->L = header_real(&t, "L");
    if (!(h->L > 0 && h->L <= 1e50)) die("L must lie in (0, 1e50] (found '%.*s')", shown(&t), t.s);
    header_record(in, &line, &cap, &t, "r");
    h->r = header_real(&t, "r");
    if (!(h->r >= 1e-50 && 2 * h->r < h->L))
        die("r must be at least 1e-50 with 2r < L (found '%.*s')", shown(&t), t.s);
    header_record(in, &line, &cap, &t, "S");
    h->steps = header_int(&t, 0, INT_MAX, "S");
    header_record(in, &line, &cap, &t, "the mode");
    if (t.len == 5 && memcmp(t.s, "print", 5) == 0) h->print = 1;
    else if (t.len == 4 && memcmp(t.s, "perf", 4) == 0) h->print = 0;
    else die("the mode must be print or perf (found '%.*s')", shown(&t), t.s);
    free(line);
    fclose(in);
    shortest(h->L_text, sizeof h->L_text, h->L);
    shortest(h->r_text, sizeof h->r_text, h->r);
    /* The frames are 2D; XYZ readers want a 3D cell. Its third axis is a slab as thick as a disk (2r):
     * non-zero, so the cell matrix stays invertible (ASE's scaled positions, OVITO's cell), and in scale
     * with the disks, so that a viewer draws a thin plate around them rather than a cube or a plane.
     * With pbc off the axis has no physical meaning; every centre sits at z = 0. 2r is exact in
     * double (r <= L/2 <= 5e49). */
    shortest(h->T_text, sizeof h->T_text, 2 * h->r);
}

/* ---- writing ---------------------------------------------------------------------------------------- */

static void write_failed(void)
{
    fprintf(stderr, "xyz: cannot write standard output (%s)\n", strerror(errno));
    exit(1);
}

static void put(const char *s, size_t len)
{
    if (fwrite(s, 1, len, stdout) != len) write_failed();
}

static int periodic; /* --periodic: the box wraps along x and y */

/* A frame's two header lines. */
static void frame_header(const Header *h, long long step, int counted)
{
    if (printf("%lld\nLattice=\"%s 0 0 0 %s 0 0 0 %s\" Properties=id:I:1:pos:R:3:velo:R:3:radius:R:1%s "
               "Time=%lld pbc=\"%s\"\n",
               h->n, h->L_text, h->L_text, h->T_text,
               counted ? ":collisions:I:1:wall_collisions:I:1" : "", step, periodic ? "T T F" : "F F F") < 0)
        write_failed();
}

/* ---- main ------------------------------------------------------------------------------------------- */

int main(int argc, char **argv)
{
    const char *names[2] = {NULL, NULL};
    int named = 0;
    for (int k = 1; k < argc; k++) {
        if (strcmp(argv[k], "--help") == 0) {
            fputs(usage_text, stdout);
            return 0;
        } else if (strcmp(argv[k], "--periodic") == 0 && named == 0) {
            periodic = 1;
        } else if ((argv[k][0] == '-' && argv[k][1] != '\0') || named == 2) {
            fputs(usage_text, stderr);
            return 2;
        } else {
            names[named++] = argv[k];
        }
    }
    if (named < 1) {
        fputs(usage_text, stderr);
        return 2;
    }
    Header h;
    header_read(names[0], &h);

    FILE *out = stdin;
    output_name = "-";
    output_line = 0;
    if (named == 2 && strcmp(names[1], "-") != 0) {
        output_name = names[1];
        out = fopen(output_name, "r");
        if (!out) {
            fprintf(stderr, "xyz: cannot open %s (%s)\n", output_name, strerror(errno));
            return 1;
        }
    }
    static char stdout_buffer[1 << 16];
    setvbuf(stdout, stdout_buffer, _IOFBF, sizeof stdout_buffer);

    /* The printed steps, as SPEC.md 2 and tools/check count them: step 0, steps 1..S-1 in print mode,
     * and step S with counts last (also when S is 0 or 1: step 0 is then printed twice, or 0 and 1). */
    long long frames = h.print && h.steps > 1 ? h.steps + 1 : 2, frame = 0, i = 0;
    char *line = NULL, *row = NULL;
    size_t cap = 0, row_cap = 0, r_len = strlen(h.r_text);
    ssize_t len;
    for (;;) {
        errno = 0;
        len = getline(&line, &cap, out);
        if (len < 0) break;
        output_line++;
        if (frame == frames)
            die("more lines than the %lld states of %lld disks expected (S = %lld, %s mode)", frames, h.n,
                h.steps, h.print ? "print" : "perf");
        if (line[len - 1] != '\n') die("the last line does not end in a newline (output cut short?)");
        line[--len] = '\0';
        if (memchr(line, '\0', (size_t)len)) die("NUL byte in the line");
        int last = frame == frames - 1, want = last ? 8 : 6;
        long long step = last ? h.steps : frame;
        Token f[FIELDS_MAX];
        int nf = split(line, f, FIELDS_MAX);
        if (nf != want)
            die("expected %d fields (%s), found %s%d", want, last ? "t i x y vx vy p w" : "t i x y vx vy",
                nf > FIELDS_MAX ? "more than " : "", nf > FIELDS_MAX ? FIELDS_MAX : nf);
        if (plain_int(&f[0]) != step)
            die("expected step %lld, found '%.*s' (lines missing, or the output of another input?)", step,
                shown(&f[0]), f[0].s);
        if (plain_int(&f[1]) != i)
            die("expected disk %lld, found '%.*s' (lines missing, or the output of another input?)", i,
                shown(&f[1]), f[1].s);
        for (int k = 2; k < 6; k++)
            if (!finite_real(&f[k]))
                die("field %d '%.*s' is not a finite real", k + 1, shown(&f[k]), f[k].s);
        for (int k = 6; k < nf; k++)
            if (plain_int(&f[k]) < 0)
                die("field %d '%.*s' is not a plain integer count", k + 1, shown(&f[k]), f[k].s);

        /* "i x y 0 vx vy 0 r[ p w]\n": at most the line's own bytes plus " 0", " 0", " r", '\n' and
         * the separators that replace runs of spaces */
        size_t need = (size_t)len + r_len + 16;
        if (need > row_cap) {
            free(row);
            row_cap = 2 * need;
            row = malloc(row_cap);
            if (!row) die("out of memory");
        }
        char *q = row;
#define APPEND(s, n) (memcpy(q, (s), (n)), q += (n))
        APPEND(f[1].s, f[1].len);
        *q++ = ' ';
        APPEND(f[2].s, f[2].len);
        *q++ = ' ';
        APPEND(f[3].s, f[3].len);
        APPEND(" 0 ", 3);
        APPEND(f[4].s, f[4].len);
        *q++ = ' ';
        APPEND(f[5].s, f[5].len);
        APPEND(" 0 ", 3);
        APPEND(h.r_text, r_len);
        for (int k = 6; k < nf; k++) {
            *q++ = ' ';
            APPEND(f[k].s, f[k].len);
        }
        *q++ = '\n';
#undef APPEND
        if (i == 0) frame_header(&h, step, last);
        put(row, (size_t)(q - row));
        if (++i == h.n) {
            i = 0;
            frame++;
            if (ferror(stdout)) write_failed();
        }
    }
    output_line++;
    if (ferror(out)) die("read error (%s)", strerror(errno));
    if (i != 0)
        die("the output ends inside step %lld (%lld of %lld lines): cut short, or from another input",
            frame == frames - 1 ? h.steps : frame, i, h.n);
    if (frame != frames)
        die("the output ends after %lld of %lld states (S = %lld, %s mode): cut short, or from another input",
            frame, frames, h.steps, h.print ? "print" : "perf");
    free(line);
    free(row);
    if (out != stdin) fclose(out);
    if (fflush(stdout) != 0 || ferror(stdout)) write_failed();
    return 0;
}
