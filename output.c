/* output.c: the output (SPEC.md 2): reals formatted exactly as printf("%.8f") does, a state's lines
 * formatted on all threads and written in order, the buffered stdout, step 0 and the final state
 * timed for --stats, and the progress line.
 */
#define _POSIX_C_SOURCE 200809L

#include "io_internal.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define OUT_BUFFER (8u << 20) /* bytes gathered before one write(2) */

const Backend *io_backend;

void io_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    io_backend->parallel(threads, tasks, task, ctx);
}

static uint64_t bytes_written; /* all of stdout, for --stats */

const char *output_write_fd(int fd, const char *bytes, size_t len)
{
    size_t done = 0;
    while (done < len) {
        ssize_t w = write(fd, bytes + done, len - done);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return w < 0 ? strerror(errno) : "short write";
        done += (size_t)w;
    }
    return NULL;
}

static void write_all(const char *bytes, size_t len)
{
    bytes_written += len;
    const char *err = output_write_fd(STDOUT_FILENO, bytes, len);
    if (err) sim_fail("cannot write output: %s", err);
}

void output_flush(Output *out)
{
    write_all(out->buf, out->len);
    out->len = 0;
}

void io_write_bytes(Output *out, const char *bytes, size_t len)
{
    if (out->len + len > OUT_BUFFER) output_flush(out);
    if (len >= OUT_BUFFER) {
        write_all(bytes, len); /* nothing pending: write straight through */
        return;
    }
    memcpy(out->buf + out->len, bytes, len);
    out->len += len;
}

int io_dump17(const Output *out)
{
    return out->dump17;
}

int io_threads(const Output *out)
{
    return out->threads;
}

/* "00" to "99": two digits per table look-up and per division (formatting is most of the output's time) */
static const char digit_pairs[201] =
    "00010203040506070809101112131415161718192021222324252627282930313233343536373839"
    "40414243444546474849505152535455565758596061626364656667686970717273747576777879"
    "8081828384858687888990919293949596979899";

/* The digits of u, of which there are `digits` (1 to 20), written backwards from their end, two at a
 * time; returns the end. */
static char *put_digits(char *p, uint64_t u, int digits)
{
    char *end = p + digits, *q = end;
    while (u >= 100) {
        unsigned d = (unsigned)(u % 100);
        u /= 100;
        q -= 2;
        memcpy(q, digit_pairs + 2 * d, 2);
    }
    if (u >= 10) {
        q -= 2;
        memcpy(q, digit_pairs + 2 * u, 2);
    } else {
        q[-1] = (char)('0' + u);
    }
    return end;
}

/* How many decimal digits u has (1 for 0): from its bit length, log10(2) ~ 1233 / 4096, one short at
 * most, which one comparison mends. */
static int digit_count(uint64_t u)
{
    static const uint64_t pow10[20] = {UINT64_C(1), UINT64_C(10), UINT64_C(100), UINT64_C(1000), UINT64_C(10000),
                                       UINT64_C(100000), UINT64_C(1000000), UINT64_C(10000000),
                                       UINT64_C(100000000), UINT64_C(1000000000), UINT64_C(10000000000),
                                       UINT64_C(100000000000), UINT64_C(1000000000000),
                                       UINT64_C(10000000000000), UINT64_C(100000000000000),
                                       UINT64_C(1000000000000000), UINT64_C(10000000000000000),
                                       UINT64_C(100000000000000000), UINT64_C(1000000000000000000),
                                       UINT64_C(10000000000000000000)};
#ifdef __GNUC__
    int t = ((64 - __builtin_clzll(u | 1)) * 1233) >> 12;
    return t + (u >= pow10[t]) + (u == 0);
#else
    int k = 1;
    while (k < 20 && u >= pow10[k]) k++;
    return k;
#endif
}

/* Writes the decimal digits of u; returns the end. (One digit: the step and counts of most lines, and
 * the whole part of a velocity below 10.) */
static char *put_uint(char *p, uint64_t u)
{
    if (u < 10) {
        *p = (char)('0' + u);
        return p + 1;
    }
    return put_digits(p, u, digit_count(u));
}

static char *put_int(char *p, int64_t v)
{
    if (v < 0) {
        *p++ = '-';
        return put_uint(p, (uint64_t)0 - (uint64_t)v);
    }
    return put_uint(p, (uint64_t)v);
}

/* The 8 digits of f < 10^8, zeros in front: its two halves of 4 digits, each two pairs (no division
 * waits on another but the first). */
static char *put_frac8(char *p, uint32_t f)
{
    uint32_t hi = f / 10000, lo = f % 10000;
    memcpy(p, digit_pairs + 2 * (hi / 100), 2);
    memcpy(p + 2, digit_pairs + 2 * (hi % 100), 2);
    memcpy(p + 4, digit_pairs + 2 * (lo / 100), 2);
    memcpy(p + 6, digit_pairs + 2 * (lo % 100), 2);
    return p + 8;
}

/* v formatted exactly as printf("%.8f", v) does: the exact binary value rounded half to even at the
 * 8th decimal, "-" on every negative value (so -0.0 and -1e-9 give "-0.00000000"). The exact value
 * m * 2^e times 10^8 fits in 128 bits whenever |v| < 2^64; larger values, inf and nan go to printf.
 * Below 2^64 / 10^8 (1.8e11: every coordinate of a box up to that side) the rounded value fits in 64
 * bits and is split into digits with 64-bit divisions, which compilers turn into multiplications. */
static char *put_fixed8(char *p, double v)
{
#ifdef __SIZEOF_INT128__
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits);
    int biased = (int)((bits >> 52) & 0x7ff);
    uint64_t m = bits & ((UINT64_C(1) << 52) - 1);
    int e = biased ? biased - 1075 : -1074;
    if (biased) m |= UINT64_C(1) << 52;
    if (e >= -64 && e <= -16) {
        /* |v| < 2^37, nearly every value a run prints: q = m 10^8 / 2^s rounded, s = -e, fits in 64
         * bits, and the shift and the rounding take no branch */
        int s = -e;
        unsigned __int128 prod = (unsigned __int128)m * 100000000u;
        uint64_t lo = (uint64_t)prod, hi = (uint64_t)(prod >> 64);
        uint64_t q = s == 64 ? hi : (lo >> s) | (hi << (64 - s));
        uint64_t rem = s == 64 ? lo : lo & ((UINT64_C(1) << s) - 1), half = UINT64_C(1) << (s - 1);
        q += (uint64_t)(rem > half) | ((uint64_t)(rem == half) & q);
        if (bits >> 63) *p++ = '-';
        p = put_uint(p, q / 100000000u);
        *p++ = '.';
        return put_frac8(p, (uint32_t)(q % 100000000u));
    }
    if (biased != 0x7ff && e <= 11) {
        unsigned __int128 q = (unsigned __int128)m * 100000000u;
        if (e >= 0) {
            q <<= e;
        } else if (-e >= 100) {
            q = 0; /* m * 10^8 < 2^80 is below half a unit: rounds to zero */
        } else {
            int s = -e;
            unsigned __int128 rem = q & (((unsigned __int128)1 << s) - 1);
            unsigned __int128 half = (unsigned __int128)1 << (s - 1);
            q >>= s;
            if (rem > half || (rem == half && (q & 1))) q++;
        }
        if (bits >> 63) *p++ = '-';
        if ((uint64_t)(q >> 64) == 0) {
            uint64_t q64 = (uint64_t)q;
            p = put_uint(p, q64 / 100000000u);
            *p++ = '.';
            return put_frac8(p, (uint32_t)(q64 % 100000000u));
        }
        p = put_uint(p, (uint64_t)(q / 100000000u));
        *p++ = '.';
        return put_frac8(p, (uint32_t)(q % 100000000u));
    }
#endif
    return p + sprintf(p, "%.8f", v);
}

/* --substeps K: the backends run with velocities divided by K; lines show them times K (both exact, K
 * being a power of two). 1 otherwise. */
static real v_unscale = 1;

static char *put_real(char *p, double v, int dump17)
{
    if (dump17) return p + sprintf(p, "%.17g", v);
    return put_fixed8(p, v);
}

void io_set_velocity_scale(real k)
{
    v_unscale = k;
}

real io_velocity_scale(void)
{
    return v_unscale;
}

size_t io_format_disk(char *dst, int64_t step, int64_t index, const Sim *sim, int64_t k, int with_counts,
                      int dump17)
{
    char *p = put_int(dst, step);
    *p++ = ' ';
    p = put_int(p, index);
    *p++ = ' ';
    p = put_real(p, sim->x[k], dump17);
    *p++ = ' ';
    p = put_real(p, sim->y[k], dump17);
    *p++ = ' ';
    p = put_real(p, sim->vx[k] * v_unscale, dump17);
    *p++ = ' ';
    p = put_real(p, sim->vy[k] * v_unscale, dump17);
    if (with_counts) {
        *p++ = ' ';
        p = put_int(p, sim->pc[k]);
        *p++ = ' ';
        p = put_int(p, sim->wc[k]);
    }
    *p++ = '\n';
    return (size_t)(p - dst);
}

size_t io_format_line(char *dst, int64_t step, int64_t i, const Sim *sim, int with_counts, int dump17)
{
    return io_format_disk(dst, step, i, sim, i, with_counts, dump17);
}

void io_format_block(TextBlock *t, int64_t step, const Sim *sim, int64_t from, int64_t to, int64_t base,
                     int with_counts, int dump17)
{
    /* in locals: the blocks' records share cache lines, and every line would move them between cores */
    char *buf = t->buf;
    size_t len = 0, cap = t->cap;
    for (int64_t k = from; k < to; k++) {
        if (len + IO_LINE_MAX > cap) { /* some 70 bytes a line as a rule, IO_LINE_MAX at most */
            cap = cap ? 2 * cap : (size_t)(to - from) * 80 + IO_LINE_MAX;
            buf = realloc(buf, cap);
            if (!buf) sim_fail("out of memory formatting the output (%zu bytes)", cap);
        }
        len += io_format_disk(buf + len, step, base + k, sim, k, with_counts, dump17);
    }
    t->buf = buf;
    t->cap = cap;
    t->len = len;
}

/* The lines of particles [from, to) of one state, on this thread. */
static void io_write_state(Output *out, int64_t step, const Sim *sim, int64_t from, int64_t to,
                           int with_counts)
{
    for (int64_t i = from; i < to; i++) {
        if (out->len + IO_LINE_MAX > OUT_BUFFER) output_flush(out);
        out->len += io_format_line(out->buf + out->len, step, i, sim, with_counts, out->dump17);
    }
}

/* ---- a state's lines, formatted in parallel and written in order --------------------------------------
 * Blocks of TEXT_LINES lines, each formatted by one task into its own buffer, go in rounds of
 * TEXT_ROUND blocks; while round r is formatted, one more task writes round r - 1 (double-buffered),
 * so that the kernel's copy of the bytes into the file, one thread's work, overlaps the formatting.
 * The caller runs the tasks: io_write_lines with the backend's parallel, omp inside its parallel region. */
#define TEXT_LINES 8192
#define TEXT_ROUND IO_TEXT_ROUND

void io_text_begin(TextJob *j, Output *out, int64_t step, const Sim *sim, int64_t n, int with_counts)
{
    memset(j, 0, sizeof *j);
    j->out = out;
    j->sim = sim;
    j->step = step;
    j->n = n;
    j->with_counts = with_counts;
    j->blocks = (n + TEXT_LINES - 1) / TEXT_LINES;
    j->rounds = (j->blocks + TEXT_ROUND - 1) / TEXT_ROUND;
}

/* Round r's tasks: the blocks of round r (if r < rounds), after a first task that writes round r - 1
 * (if r > 0); r runs from 0 to rounds. */
int64_t io_text_tasks(const TextJob *j, int64_t r)
{
    int64_t first = r * TEXT_ROUND, count = r < j->rounds ? j->blocks - first : 0;
    if (count > TEXT_ROUND) count = TEXT_ROUND;
    return count + (r > 0);
}

void io_text_task(TextJob *j, int64_t r, int64_t k)
{
    if (r > 0 && k == 0) { /* write round r - 1, in block order */
        output_flush(j->out);
        int64_t first = (r - 1) * TEXT_ROUND, last = first + TEXT_ROUND;
        if (last > j->blocks) last = j->blocks;
        for (int64_t b = first; b < last; b++) {
            TextBlock *t = &j->slot[b % (2 * TEXT_ROUND)];
            write_all(t->buf, t->len);
        }
        return;
    }
    int64_t b = r * TEXT_ROUND + k - (r > 0);
    TextBlock *t = &j->slot[b % (2 * TEXT_ROUND)];
    int64_t from = b * TEXT_LINES, to = from + TEXT_LINES < j->n ? from + TEXT_LINES : j->n;
    io_format_block(t, j->step, j->sim, from, to, 0, j->with_counts, j->out->dump17);
}

void io_text_end(TextJob *j)
{
    for (int k = 0; k < 2 * TEXT_ROUND; k++) free(j->slot[k].buf);
    memset(j, 0, sizeof *j);
}

typedef struct {
    TextJob *job;
    int64_t round;
} TextRound;

static void text_round_task(void *ctx, int64_t k)
{
    TextRound *tr = ctx;
    io_text_task(tr->job, tr->round, k);
}

/* await: NULL, or called before each round is formatted with the lines that round needs */
static void write_lines(Output *out, int64_t step, const Sim *sim, int64_t n, int with_counts,
                        void (*await)(void *ctx, int64_t lines), void *ctx)
{
    if (n <= TEXT_LINES) { /* one block: nothing to share out */
        if (await) await(ctx, n);
        io_write_state(out, step, sim, 0, n, with_counts);
        return;
    }
    TextJob j;
    io_text_begin(&j, out, step, sim, n, with_counts);
    for (int64_t r = 0; r <= j.rounds; r++) {
        int64_t upto = (r + 1) * TEXT_ROUND * TEXT_LINES;
        if (await && r < j.rounds) await(ctx, upto < n ? upto : n);
        TextRound tr = {&j, r};
        io_parallel(out->threads, io_text_tasks(&j, r), text_round_task, &tr);
    }
    io_text_end(&j);
}

void io_write_lines(Output *out, int64_t step, const Sim *sim, int64_t n, int with_counts)
{
    write_lines(out, step, sim, n, with_counts, NULL, NULL);
}

/* A whole state written and flushed, its seconds and bytes kept for --stats. */
static void write_timed(Output *out, int64_t step, const Sim *sim, int with_counts,
                        void (*await)(void *ctx, int64_t lines), void *ctx, double *secs, uint64_t *bytes)
{
    double t0 = sim_clock();
    uint64_t before = bytes_written;
    write_lines(out, step, sim, out->par->n, with_counts, await, ctx);
    output_flush(out);
    *secs = sim_clock() - t0;
    *bytes = bytes_written - before;
}

void io_write_final(Output *out, const Sim *sim, void (*await)(void *ctx, int64_t lines), void *ctx)
{
    write_timed(out, out->par->steps, sim, 1, await, ctx, &out->final_s, &out->final_bytes);
    out->final_done = 1;
}

void io_progress(Output *out, int64_t step)
{
    if (!out->progress) return;
    double now = sim_clock();
    if (now < out->next_show) return;
    out->next_show = now + 0.5;
    double spent = now - out->start;
    if (spent < 2.0) return;
    if (step <= out->first) return;
    double left = spent * (double)(out->steps - step) / (double)(step - out->first);
    fprintf(stderr, "\r%s: step %lld of %lld (%.0f%%), %.0f s left", sim_program, (long long)step,
            (long long)out->steps, 100.0 * (double)step / (double)out->steps, left);
    if (out->ck_count) fprintf(stderr, "; checkpoint of step %lld in %s", (long long)out->ck_step, out->ck_path);
    fputs("   ", stderr);
    out->shown = 1;
}

int io_step0_pending(const Output *out)
{
    return out->step0_pending;
}

void io_write_step0(Output *out, const Sim *sim)
{
    write_timed(out, 0, sim, 0, NULL, NULL, &out->step0_s, &out->step0_bytes);
    out->step0_pending = 0;
}

Output *io_output_open(const Params *par, const Options *opt)
{
    signal(SIGPIPE, SIG_IGN); /* a closed pipe becomes a write error with a message */
    Output *out = sim_calloc(1, sizeof *out);
    out->buf = sim_calloc(OUT_BUFFER, 1);
    out->dump17 = opt->dump17;
    out->threads = opt->threads;
    out->progress = isatty(STDERR_FILENO);
    out->steps = par->steps;
    out->first = par->first_step;
    out->ck_path = opt->checkpoint;
    out->ck_every = opt->checkpoint_every;
    out->par = par;
    out->opt = opt;
    out->start = sim_clock();
    out->next_show = out->start + 2.0;
    return out;
}

void io_output_close(Output *out)
{
    output_flush(out);
    free(out->buf);
    free(out);
}
