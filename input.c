/* input.c: reading the input (SPEC.md 1 and 6): the file read in pieces and its particle lines parsed
 * in chunks on all threads, every check of a line-by-line reader with its message (the first error
 * such a reader meets, named by file and line), and the random placement where it lists no disks.
 * Every input error is found before the first byte goes to stdout.
 */
#define _POSIX_C_SOURCE 200809L

#include "io_internal.h"

#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

typedef struct {
    const char *label; /* file name for messages */
    char *text;        /* whole input, NUL-terminated */
    size_t size;
    size_t pos;  /* start of the next line */
    long line;   /* number of the line last returned, 1-based */
    long n_line; /* line of N, named by errors about N as a whole (memory, placement) */
    char *tok[8]; /* tokens of that line (NUL-terminated in place) */
    int ntok;     /* tokens found; more than 8 counts on */
} Reader;

static void input_error(const Reader *rd, long line, const char *fmt, ...)
{
    va_list ap;
    fprintf(stderr, "%s: %s:%ld: ", sim_program, rd->label, line);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    exit(1);
}

/* A large input is read in pieces of READ_PIECE bytes on the backend's threads: the kernel's copy
 * from its page cache is then shared out too. */
#define READ_PIECE ((size_t)8 << 20)
typedef struct {
    int fd;
    char *buf;
    size_t size;
    int err; /* errno of a failed piece, or -1 where the file ended early (it shrank) */
} Slurp;

static void read_piece(void *ctx, int64_t k)
{
    Slurp *sl = ctx;
    size_t from = (size_t)k * READ_PIECE, to = from + READ_PIECE < sl->size ? from + READ_PIECE : sl->size;
    while (from < to) {
        ssize_t got = pread(sl->fd, sl->buf + from, to - from, (off_t)from);
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) {
            sl->err = got < 0 ? errno : -1;
            return;
        }
        from += (size_t)got;
    }
}

static char *slurp(const Options *opt, size_t *size)
{
    FILE *f = stdin;
    if (strcmp(opt->path, "-") != 0) {
        f = fopen(opt->path, "rb");
        if (!f) sim_fail("%s: cannot open the input (%s)", opt->path, strerror(errno));
    }
    /* a regular file is read into a buffer of its size: growing by doubling copies gigabytes at N = 1e8 */
    struct stat st;
    size_t cap = 1 << 16, len = 0;
    if (fstat(fileno(f), &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0 &&
        (uint64_t)st.st_size < SIZE_MAX / 2)
        cap = (size_t)st.st_size + 2;
    char *buf = malloc(cap);
    if (!buf) sim_fail("%s: out of memory reading the input (%zu bytes)", opt->label, cap);
    if (cap > 2 * READ_PIECE) { /* a large regular file: its pieces read in parallel, then what follows */
        Slurp sl = {fileno(f), buf, cap - 2, 0};
        io_parallel(opt->threads, (int64_t)((cap - 2 + READ_PIECE - 1) / READ_PIECE), read_piece, &sl);
        if (sl.err)
            sim_fail("%s: cannot read the input (%s)", opt->label,
                    sl.err > 0 ? strerror(sl.err) : "it became shorter while it was read");
        len = cap - 2;
        if (fseeko(f, (off_t)len, SEEK_SET) != 0) sim_fail("%s: cannot read the input (%s)", opt->label, strerror(errno));
    }
    for (;;) {
        if (cap - len < 2) {
            if (cap > SIZE_MAX / 2) sim_fail("%s: input too large", opt->label);
            char *grown = realloc(buf, cap * 2);
            if (!grown) sim_fail("%s: out of memory reading the input", opt->label);
            buf = grown;
            cap *= 2;
        }
        size_t got = fread(buf + len, 1, cap - len - 1, f);
        len += got;
        if (got == 0 || feof(f)) break; /* at the first end of file: a pipe may not give a second */
    }
    if (ferror(f)) sim_fail("%s: cannot read the input (%s)", opt->label, strerror(errno));
    if (f != stdin) fclose(f);
    buf[len] = '\0';
    *size = len;
    return buf;
}

static int is_space(char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

/* Splits the line [s, end) into tokens, NUL-terminating them in place; stores up to 8 in tok and returns
 * how many there were (more than 8 counts on). */
static int split_line(char *s, char *end, char **tok)
{
    int ntok = 0;
    *end = '\0';
    for (char *p = s; p < end;) {
        while (p < end && is_space(*p)) p++;
        if (p == end) break;
        char *t = p;
        while (p < end && !is_space(*p)) p++;
        *p = '\0';
        if (ntok < 8) tok[ntok] = t;
        ntok++;
        p++;
    }
    return ntok;
}

/* A byte 0 in the line [s, end): its column (from 1), or 0 when there is none. Text with one is refused
 * before any other check of its line. */
#define ZERO_BYTE_ERROR "unexpected byte 0 in the text (found one at column %ld)"
static long zero_byte_column(const char *s, const char *end)
{
    const char *nul = memchr(s, '\0', (size_t)(end - s));
    return nul ? (long)(nul - s) + 1 : 0;
}

/* Splits the next non-blank line into tokens; returns 0 at the end of the input. */
static int next_record(Reader *rd)
{
    while (rd->pos < rd->size) {
        char *s = rd->text + rd->pos;
        char *nl = memchr(s, '\n', rd->size - rd->pos);
        char *end = nl ? nl : rd->text + rd->size;
        rd->pos = (size_t)(end - rd->text) + (nl ? 1 : 0);
        rd->line++;
        long col = zero_byte_column(s, end);
        if (col) input_error(rd, rd->line, ZERO_BYTE_ERROR, col);
        rd->ntok = split_line(s, end, rd->tok);
        if (rd->ntok > 0) return 1;
    }
    return 0;
}

/* Accepts [+-]digits, nothing else. */
int input_parse_int(const char *s, long long *out)
{
    const char *p = s;
    int neg = *p == '-';
    if (*p == '+' || *p == '-') p++;
    if (!*p) return -1;
    unsigned long long v = 0;
    for (const char *q = p; *q; q++) {
        if (*q < '0' || *q > '9') return -1;
        if (v > (ULLONG_MAX - 9) / 10) return -2; /* far beyond any index */
        v = v * 10 + (unsigned long long)(*q - '0');
    }
    if (v > (unsigned long long)LLONG_MAX + (unsigned long long)neg) return -2;
    *out = neg ? (long long)(0 - v) : (long long)v;
    return 0;
}

static int ieq(const char *a, const char *b)
{
    for (; *a && *b; a++, b++) {
        char ca = *a >= 'A' && *a <= 'Z' ? (char)(*a + 32) : *a;
        if (ca != *b) return 0;
    }
    return *a == *b;
}

/* Exact powers of ten: a double holds each of them exactly up to 10^22. */
static const double exact_pow10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                       1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

/* A real from p (below end): [-]digits[.digits] where the digits make an integer M <= 2^53 (19 digits at
 * most) and there are k <= 22 decimals (every %.8f output of a box up to 9e7 wide), followed by a field
 * separator or end: its value is M / 10^k, a single correctly rounded division of two exact doubles,
 * which is strtod's correctly rounded value. Returns where it ends, or NULL where the text is anything
 * else (io_parse_real then reads it with strtod). */
static const char *line_real(const char *p, const char *end, double *out)
{
    int neg = p < end && *p == '-';
    p += neg;
    uint64_t mant = 0;
    int digits = 0, decimals = 0;
    for (; p < end && (unsigned)(*p - '0') < 10; p++, digits++) mant = mant * 10 + (uint64_t)(*p - '0');
    if (p < end && *p == '.')
        for (p++; p < end && (unsigned)(*p - '0') < 10; p++, digits++, decimals++)
            mant = mant * 10 + (uint64_t)(*p - '0');
    if (digits == 0 || digits > 19 || mant > (UINT64_C(1) << 53) || decimals > 22) return NULL;
    if (p < end && !is_space(*p)) return NULL;
    double v = (double)mant / exact_pow10[decimals];
    *out = neg ? -v : v;
    return p;
}

/* Accepts decimal reals: [+-] digits [. digits] [e [+-] digits] (at least one digit in the mantissa).
 * Returns 0, -1 (not a number), -2 (overflow) or -3 (nan or inf). Values as strtod reads them: line_real's
 * where it reads the text, else strtod's. */
int io_parse_real(const char *s, double *out)
{
    const char *end = s + strlen(s);
    if (line_real(s, end, out) == end) return 0;
    const char *p = s;
    if (*p == '+' || *p == '-') p++;
    if ((*p | 32) == 'n' || (*p | 32) == 'i')
        if (ieq(p, "nan") || ieq(p, "inf") || ieq(p, "infinity")) return -3;
    int digits = 0;
    for (; *p >= '0' && *p <= '9'; p++) digits++;
    if (*p == '.')
        for (p++; *p >= '0' && *p <= '9'; p++) digits++;
    if (!digits) return -1;
    if (*p == 'e' || *p == 'E') {
        p++;
        if (*p == '+' || *p == '-') p++;
        if (!(*p >= '0' && *p <= '9')) return -1;
        while (*p >= '0' && *p <= '9') p++;
    }
    if (*p) return -1;
    errno = 0;
    *out = strtod(s, NULL);
    if (errno == ERANGE && (*out == HUGE_VAL || *out == -HUGE_VAL)) return -2;
    return 0; /* underflow rounds to a tiny or zero value, which is still a finite real */
}

static const char *real_problem(int rc)
{
    return rc == -3 ? "must be a finite number" : rc == -2 ? "is out of range" : "is not a number";
}

/* Reads the one-token record named what; returns its token. */
static const char *header_token(Reader *rd, const char *what)
{
    if (!next_record(rd)) input_error(rd, rd->line + 1, "missing %s (end of input)", what);
    if (rd->ntok != 1)
        input_error(rd, rd->line, "expected only %s on this line (found %d fields)", what, rd->ntok);
    return rd->tok[0];
}

static double header_real(Reader *rd, const char *what)
{
    const char *t = header_token(rd, what);
    double v;
    int rc = io_parse_real(t, &v);
    if (rc) input_error(rd, rd->line, "%s %s (found '%s')", what, real_problem(rc), t);
    return v;
}

static long long header_int(Reader *rd, const char *what, long long lo, long long hi)
{
    const char *t = header_token(rd, what);
    long long v;
    int rc = input_parse_int(t, &v);
    if (rc == -1) input_error(rd, rd->line, "%s is not an integer (found '%s')", what, t);
    if (rc == -2 || v < lo || v > hi)
        input_error(rd, rd->line, "%s must be between %lld and %lld (found '%s')", what, lo, hi, t);
    return v;
}

/* The header into par; par->periodic, set by the caller, decides the checks of SPEC.md 7. */
static void read_header(Reader *rd, Params *par)
{
    par->n = header_int(rd, "the number of particles N", 1, SIM_MAX_N);
    rd->n_line = rd->line;
    double L = header_real(rd, "the box size L");
    if (!(L > 0 && L <= SIM_MAX_L))
        input_error(rd, rd->line, "the box size L must be > 0 and <= %g (found '%s')", SIM_MAX_L,
                    rd->tok[0]);
    par->L = (real)L;
    double r = header_real(rd, "the radius r");
    if (!(r >= SIM_MIN_R))
        input_error(rd, rd->line, "the radius r must be >= %g (found '%s')", SIM_MIN_R, rd->tok[0]);
    par->r = (real)r;
    if (!(2 * par->r < par->L))
        input_error(rd, rd->line, "the radius r must satisfy 2r < L = %.17g (found '%s')", (double)par->L,
                    rd->tok[0]);
    if (par->periodic && !(4 * par->r < par->L)) /* two touching disks have one nearest image */
        input_error(rd, rd->line, "with --periodic the radius r must satisfy 4r < L = %.17g (found '%s')",
                    (double)par->L, rd->tok[0]);
    par->steps = header_int(rd, "the number of steps S", 0, SIM_MAX_STEPS);
    const char *mode = header_token(rd, "the mode 'print' or 'perf'");
    if (strcmp(mode, "print") == 0) {
        par->print = 1;
    } else if (strcmp(mode, "perf") == 0) {
        par->print = 0;
    } else {
        input_error(rd, rd->line, "the mode must be 'print' or 'perf' (found '%s')", mode);
    }
    params_derive(par);
}

size_t io_header_span(const char *text, size_t size)
{
    int records = 0;
    for (size_t pos = 0; pos < size;) {
        const char *s = text + pos, *nl = memchr(s, '\n', size - pos);
        if (!nl) return 0; /* the last line may go on past size */
        int blank = 1;
        for (const char *p = s; p < nl && blank; p++) blank = is_space(*p);
        pos = (size_t)(nl - text) + 1;
        if (!blank && ++records == 5) return pos;
    }
    return 0;
}

void io_read_header(const char *label, char *text, size_t size, Params *par, size_t *body, long *body_line)
{
    Reader rd;
    memset(&rd, 0, sizeof rd);
    rd.label = label;
    rd.text = text;
    rd.size = size;
    read_header(&rd, par);
    *body = rd.pos;
    *body_line = rd.line;
}

static const char *const field_name[5] = {"index i", "x", "y", "vx", "vy"};

/* The particle lines are parsed in chunks of whole lines, in parallel (io_parallel), and the
 * checks that need the lines before (more lines than N, an index given twice) run afterwards in one
 * pass over the index each line gave. The error reported is the one a line-by-line reader meets
 * first: the earliest line, and on that line the first check in the order of read_line below. */
#define CHUNK_BYTES 65536
#define LINE_BLANK (-1)   /* line_idx of a line without tokens (or not reached) */
#define LINE_NO_INDEX (-2) /* a record whose fields or index are wrong */
#define LINE_ZERO_BYTE (-3) /* a line holding a byte 0: its error comes before any other check */

typedef struct {
    size_t from, to; /* bytes [from, to) of the text: whole lines */
    int64_t line0;   /* index (from 0) of its first line among the particle lines */
    int64_t lines;
    long err_line;   /* first error of the chunk (0: none) and its message */
    char *err;
} Chunk;

typedef struct {
    const Params *par;
    Sim *sim;          /* where the disks go: at their index, or by_line at their line's position */
    int by_line;
    char *text;
    long line_base;   /* number of the line before the first particle line */
    Chunk *chunk;
    int64_t nchunk, lines;
    int32_t *line_idx; /* per particle line: its index, or LINE_BLANK, LINE_NO_INDEX, LINE_ZERO_BYTE */
} Parse;

static void chunk_error(Chunk *c, long line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int len = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    c->err = sim_calloc((size_t)len + 1, 1);
    va_start(ap, fmt);
    vsnprintf(c->err, (size_t)len + 1, fmt, ap);
    va_end(ap);
    c->err_line = line;
}

/* The first of a record's values x, y, vx, vy (k = 0 to 3) outside its bounds, or -1: x and y within
 * [r, L - r], or [0, L) in the periodic box as stored (a float may round up to L); |vx|, |vy| at most
 * SIM_MAX_V. */
static int out_of_bounds(const Params *par, const double v[4])
{
    for (int k = 0; k < 2; k++)
        if (par->periodic ? !(v[k] >= 0 && (real)v[k] < par->L) : !(v[k] >= par->lo && v[k] <= par->hi)) return k;
    for (int k = 2; k < 4; k++)
        if (!(fabs(v[k]) <= SIM_MAX_V)) return k;
    return -1;
}

/* A record's disk, at its index (or its line's position, by_line). A duplicate index writes twice, and
 * is then reported: the values are never used. Rounding keeps x in [lo, hi] (both are reals), or in
 * [0, L). */
static void store_disk(const Parse *ps, int64_t pos, int64_t idx, const double v[4])
{
    int64_t at = ps->by_line ? pos : idx;
    ps->sim->x[at] = (real)v[0];
    ps->sim->y[at] = (real)v[1];
    ps->sim->vx[at] = (real)v[2];
    ps->sim->vy[at] = (real)v[3];
}

/* Checks one record and stores its disk; returns its index, or LINE_NO_INDEX after an error that left
 * no valid index (an error after the index returns the index: the duplicate check comes first). */
static int32_t read_line(const Parse *ps, Chunk *c, long line, int64_t pos, char **tok, int ntok)
{
    const Params *par = ps->par;
    int64_t n = par->n;
    if (ntok != 5) {
        chunk_error(c, line, "expected 5 fields 'i x y vx vy' (found %d)", ntok);
        return LINE_NO_INDEX;
    }
    long long idx;
    int rc = input_parse_int(tok[0], &idx);
    if (rc == -1) {
        chunk_error(c, line, "index i is not an integer (found '%s')", tok[0]);
        return LINE_NO_INDEX;
    }
    if (rc == -2 || idx < 0 || idx >= n) {
        chunk_error(c, line, "index i must be between 0 and %lld (found '%s')", (long long)n - 1, tok[0]);
        return LINE_NO_INDEX;
    }
    double v[4];
    for (int k = 0; k < 4; k++) {
        rc = io_parse_real(tok[k + 1], &v[k]);
        if (rc) {
            chunk_error(c, line, "%s %s (found '%s')", field_name[k + 1], real_problem(rc), tok[k + 1]);
            return (int32_t)idx;
        }
    }
    int k = out_of_bounds(par, v);
    if (k >= 2) {
        chunk_error(c, line, "|%s| must be <= %g (found '%s')", field_name[k + 1], SIM_MAX_V, tok[k + 1]);
        return (int32_t)idx;
    }
    if (k >= 0 && par->periodic) {
        chunk_error(c, line, "%s must be within [0, L) = [0, %.17g) with --periodic (found '%s')",
                    field_name[k + 1], (double)par->L, tok[k + 1]);
        return (int32_t)idx;
    }
    if (k >= 0) {
        chunk_error(c, line, "%s must be within [r, L-r] = [%.17g, %.17g] (found '%s')", field_name[k + 1],
                    (double)par->lo, (double)par->hi, tok[k + 1]);
        return (int32_t)idx;
    }
    store_disk(ps, pos, idx, v);
    return (int32_t)idx;
}

static const char *skip_blanks(const char *p, const char *end)
{
    while (p < end && is_space(*p)) p++;
    return p;
}

/* The particle line [p, end) read in one pass, without splitting it, where it is well formed: an index
 * of plain digits and four reals as line_real reads them, between split_line's separators, none out of
 * bounds. Then its disk is stored and its index returned; else -1, and the line goes read_line's way
 * (any other form it accepts, and every error with its message). Nearly every line of a file is read
 * here: split_line and the general reader took twice as long. */
static int32_t read_line_fast(const Parse *ps, int64_t pos, const char *p, const char *end)
{
    const Params *par = ps->par;
    p = skip_blanks(p, end);
    int64_t idx = 0;
    int digits = 0;
    for (; p < end && (unsigned)(*p - '0') < 10; p++, digits++) idx = idx * 10 + (*p - '0');
    if (digits == 0 || digits > 18 || idx >= par->n || p == end || !is_space(*p)) return -1;
    double v[4];
    for (int k = 0; k < 4; k++) {
        p = skip_blanks(p, end);
        if (p == end || !(p = line_real(p, end, &v[k]))) return -1;
    }
    if (skip_blanks(p, end) != end || out_of_bounds(par, v) >= 0) return -1;
    store_disk(ps, pos, idx, v);
    return (int32_t)idx;
}

static void count_lines(void *ctx, int64_t k)
{
    Parse *ps = ctx;
    Chunk *c = &ps->chunk[k];
    int64_t lines = 0;
    for (const char *p = ps->text + c->from, *end = ps->text + c->to; p < end; lines++) {
        const char *nl = memchr(p, '\n', (size_t)(end - p));
        p = nl ? nl + 1 : end;
    }
    c->lines = lines;
}

/* Parses the lines of chunk k up to its first error. */
static void parse_chunk(void *ctx, int64_t k)
{
    Parse *ps = ctx;
    Chunk *c = &ps->chunk[k];
    char *p = ps->text + c->from, *stop = ps->text + c->to, *tok[8];
    for (int64_t i = 0; i < c->lines; i++) {
        long line = ps->line_base + 1 + (long)(c->line0 + i);
        char *nl = memchr(p, '\n', (size_t)(stop - p));
        char *end = nl ? nl : stop;
        int32_t *idx = &ps->line_idx[c->line0 + i];
        if ((*idx = read_line_fast(ps, c->line0 + i, p, end)) >= 0) {
            p = end + 1;
            continue;
        }
        long col = zero_byte_column(p, end);
        if (col) {
            chunk_error(c, line, ZERO_BYTE_ERROR, col);
            *idx = LINE_ZERO_BYTE;
            return;
        }
        int ntok = split_line(p, end, tok);
        *idx = ntok ? read_line(ps, c, line, c->line0 + i, tok, ntok) : LINE_BLANK;
        if (c->err_line) return;
        p = end + 1;
    }
}

/* Cuts ps->text's bytes [from, size) into chunks of whole lines and parses them on threads: line_idx
 * and the chunks' errors say what each line held. by_line: ps->sim is allocated here, a disk per line. */
static void parse_lines(Parse *ps, size_t from, size_t size, int threads)
{
    int64_t nchunk = (int64_t)((size - from) / CHUNK_BYTES) + 1;
    ps->nchunk = nchunk;
    ps->chunk = sim_calloc((size_t)nchunk, sizeof *ps->chunk);
    for (int64_t k = 0; k < nchunk; k++) { /* each ends after the first newline past its share */
        Chunk *c = &ps->chunk[k];
        c->from = k ? ps->chunk[k - 1].to : from;
        size_t cut = from + (size_t)((double)(size - from) * (double)(k + 1) / (double)nchunk);
        const char *nl = cut < c->from || k == nchunk - 1 ? NULL : memchr(ps->text + cut, '\n', size - cut);
        c->to = k == nchunk - 1 ? size : cut < c->from ? c->from : nl ? (size_t)(nl - ps->text) + 1 : size;
    }
    io_parallel(threads, nchunk, count_lines, ps);
    int64_t lines = 0;
    for (int64_t k = 0; k < nchunk; k++) {
        ps->chunk[k].line0 = lines;
        lines += ps->chunk[k].lines;
    }
    ps->lines = lines;
    ps->line_idx = sim_calloc((size_t)lines, sizeof *ps->line_idx);
    if (ps->by_line && sim_alloc(ps->sim, lines + 1))
        sim_fail("out of memory for %lld particle lines", (long long)lines);
    io_parallel(threads, nchunk, parse_chunk, ps);
}

void io_parse_piece(const Params *par, char *text, size_t len, int threads, IoPiece *pc)
{
    Parse ps;
    memset(&ps, 0, sizeof ps);
    memset(pc, 0, sizeof *pc);
    ps.par = par;
    ps.sim = &pc->disks;
    ps.by_line = 1;
    ps.text = text;
    parse_lines(&ps, 0, len, threads);
    for (int64_t k = 0; k < ps.nchunk; k++) {
        if (ps.chunk[k].err) pc->bad = 1;
        free(ps.chunk[k].err);
    }
    free(ps.chunk);
    pc->lines = ps.lines;
    pc->idx = ps.line_idx;
}

void io_piece_free(IoPiece *pc)
{
    sim_free(&pc->disks);
    free(pc->idx);
    memset(pc, 0, sizeof *pc);
}

/* Reads the particle lines, if any; returns how many there were (0 or n). */
static int64_t read_particles(Reader *rd, const Params *par, Sim *sim, int threads)
{
    Parse ps;
    memset(&ps, 0, sizeof ps);
    ps.par = par;
    ps.sim = sim;
    ps.text = rd->text;
    ps.line_base = rd->line;
    parse_lines(&ps, rd->pos, rd->size, threads);
    int64_t nchunk = ps.nchunk, lines = ps.lines;

    /* In file order up to the first chunk error: count the records, mark the indices seen. */
    Chunk verdict = {0, 0, 0, 0, 0, NULL};
    for (int64_t k = 0; k < nchunk && !verdict.err; k++)
        if (ps.chunk[k].err) {
            verdict = ps.chunk[k];
            ps.chunk[k].err = NULL;
        }
    int64_t last = verdict.err ? verdict.err_line - ps.line_base - 1 : lines - 1, seen = 0;
    unsigned char *have = sim_calloc((size_t)(par->n / 8 + 1), 1);
    for (int64_t i = 0; i <= last; i++) {
        int32_t idx = ps.line_idx[i];
        long line = ps.line_base + 1 + (long)i;
        if (idx == LINE_BLANK || idx == LINE_ZERO_BYTE) continue;
        if (seen == par->n) {
            free(verdict.err);
            chunk_error(&verdict, line, "more particle lines than N = %lld (found another one)", (long long)par->n);
            break;
        }
        seen++;
        if (idx < 0) continue;
        if (have[idx / 8] & (1u << (idx % 8))) {
            int64_t first = 0;
            while (ps.line_idx[first] != idx) first++;
            free(verdict.err);
            chunk_error(&verdict, line, "index %lld given twice (first on line %ld)", (long long)idx,
                        ps.line_base + 1 + (long)first);
            break;
        }
        have[idx / 8] |= (unsigned char)(1u << (idx % 8));
    }
    if (!verdict.err && seen > 0 && seen < par->n) {
        int64_t missing = 0;
        while (have[missing / 8] & (1u << (missing % 8))) missing++;
        chunk_error(&verdict, ps.line_base + (long)lines + 1,
                    "expected %lld particle lines, found %lld (index %lld is missing; end of input)",
                    (long long)par->n, (long long)seen, (long long)missing);
    }
    for (int64_t k = 0; k < nchunk; k++) free(ps.chunk[k].err);
    free(ps.chunk);
    free(ps.line_idx);
    free(have);
    if (verdict.err) {
        static char *message; /* reachable at exit, so the leak checker stays quiet */
        message = verdict.err;
        input_error(rd, verdict.err_line, "%s", message);
    }
    return seen;
}

/* Reads and validates the whole input; generates the disks when the input lists none. */
void input_read(const Options *opt, Params *par, Sim *sim, IoTimes *io, int prepare)
{
    Reader rd;
    memset(&rd, 0, sizeof rd);
    rd.label = opt->label;
    double t0 = sim_clock();
    rd.text = slurp(opt, &rd.size);
    double t1 = sim_clock();
    par->periodic = opt->periodic;
    read_header(&rd, par);
    if (prepare && io_backend->prepare) {
        char where[4096];
        snprintf(where, sizeof where, "%s:%ld", rd.label, rd.n_line);
        io_backend->prepare(par, where);
    }
    if (sim_alloc(sim, par->n))
        input_error(&rd, rd.n_line, "not enough memory for the particles (N = %lld)",
                    (long long)par->n);
    int64_t lines = read_particles(&rd, par, sim, opt->threads);
    io->read_s = t1 - t0;
    io->parse_s = sim_clock() - t1;
    io->in_bytes = rd.size;
    if (lines == 0) {
        int64_t failed = place_disks(par, opt->seed, sim, opt->threads);
        if (failed >= 0)
            input_error(&rd, rd.n_line,
                        "cannot place %lld disks of radius %g without overlap in a box of side %g "
                        "(disk %lld failed %d tries; area fraction %.3f)",
                        (long long)par->n, (double)par->r, (double)par->L, (long long)failed,
                        PLACE_TRIES,
                        (double)par->n * 3.141592653589793 * par->r * par->r / (par->L * par->L));
        if (!opt->quiet)
            fprintf(stderr, "%s: generated %lld disks with seed %llu\n", sim_program,
                    (long long)par->n, (unsigned long long)opt->seed);
    }
    free(rd.text);
}

void io_read_input(const Options *opt, Params *par, Sim *sim)
{
    IoTimes io;
    input_read(opt, par, sim, &io, 0);
}
