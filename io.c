/* io.c: everything outside the timed step loop, shared by every backend.
 *
 * The driver (io_main, which each backend's main calls), the command line, reading and validating the
 * input (SPEC.md 1 and 6), the seeded random placement, the exact %.8f formatter and buffered output
 * (SPEC.md 2), progress and checkpoints.
 * Every input error is found before the first byte goes to stdout.
 */
#define _POSIX_C_SOURCE 200809L

#include "io.h"
#include "exact.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define DEFAULT_SEED 1u
#define OUT_BUFFER (8u << 20) /* bytes gathered before one write(2) */
#define PLACE_TRIES 10000     /* random positions tried for one disk before giving up */

/* ==== output ============================================================================================ */

/* Seconds and bytes of the untimed parts, for --stats. */
typedef struct {
    double start; /* sim_clock() when main began */
    double read_s, parse_s, write_s;
    uint64_t in_bytes, out_bytes;
} IoTimes;

struct Output {
    char *buf;         /* pending bytes */
    size_t len;        /* bytes pending in buf */
    int dump17;        /* reals as %.17g instead of %.8f */
    int threads;       /* --threads, for backends that format on several threads; 0: their default */
    int progress;      /* stderr is a terminal */
    int64_t steps;     /* for the progress line */
    int64_t first;     /* the step the run started from (its progress counts from there) */
    const char *ck_path;  /* --checkpoint FILE, or NULL */
    int64_t ck_every;     /* --checkpoint-every */
    const Params *par;    /* what a checkpoint records of the run */
    const Options *opt;
    double start;      /* sim_clock() when the step loop began */
    int step0_pending; /* the backend is to write step 0 (SIM_FEATURE_STEP0) */
    double step0_s;    /* seconds spent writing step 0, and its bytes */
    uint64_t step0_bytes;
    int final_done;    /* the backend has written the final state (io_write_final) */
    double final_s;    /* ... in these seconds, these bytes */
    uint64_t final_bytes;
    int64_t ck_count;  /* checkpoints written, their seconds and bytes (--stats), the last one's step */
    int64_t ck_step;
    double ck_s;
    uint64_t ck_bytes;
    double next_show;  /* sim_clock() of the next progress update */
    int shown;         /* a progress line is on the terminal */
    IoTimes io;        /* io_main's reading and writing, for --stats */
    int io_known;      /* io holds them (not so for a backend that reads and writes its own way: mpi) */
};

static uint64_t bytes_written; /* all of stdout, for --stats */

/* Writes all of bytes to fd; NULL, or what went wrong. */
static const char *write_fd(int fd, const char *bytes, size_t len)
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
    const char *err = write_fd(STDOUT_FILENO, bytes, len);
    if (err) sim_fail("cannot write output: %s", err);
}

static void out_flush(Output *out)
{
    write_all(out->buf, out->len);
    out->len = 0;
}

void io_write_bytes(Output *out, const char *bytes, size_t len)
{
    if (out->len + len > OUT_BUFFER) out_flush(out);
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

/* Writes the decimal digits of u; returns the end. */
static char *put_uint(char *p, uint64_t u)
{
    char tmp[24];
    int k = 24;
    while (u >= 100) {
        unsigned d = (unsigned)(u % 100);
        u /= 100;
        tmp[--k] = digit_pairs[2 * d + 1];
        tmp[--k] = digit_pairs[2 * d];
    }
    if (u >= 10) {
        tmp[--k] = digit_pairs[2 * u + 1];
        tmp[--k] = digit_pairs[2 * u];
    } else {
        tmp[--k] = (char)('0' + u);
    }
    memcpy(p, tmp + k, (size_t)(24 - k));
    return p + (24 - k);
}

static char *put_int(char *p, int64_t v)
{
    if (v < 0) {
        *p++ = '-';
        return put_uint(p, (uint64_t)0 - (uint64_t)v);
    }
    return put_uint(p, (uint64_t)v);
}

/* The 8 digits of f < 10^8, zeros in front. */
static char *put_frac8(char *p, uint32_t f)
{
    for (int k = 6; k >= 0; k -= 2) {
        uint32_t d = f % 100;
        f /= 100;
        p[k] = digit_pairs[2 * d];
        p[k + 1] = digit_pairs[2 * d + 1];
    }
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
        if (out->len + IO_LINE_MAX > OUT_BUFFER) out_flush(out);
        out->len += io_format_line(out->buf + out->len, step, i, sim, with_counts, out->dump17);
    }
}

/* ---- a state's lines, formatted in parallel and written in order --------------------------------------
 * Blocks of TEXT_LINES lines, each formatted by one task into its own buffer, go in rounds of
 * TEXT_ROUND blocks; while round r is formatted, one more task writes round r - 1 (double-buffered),
 * so that the kernel's copy of the bytes into the file, one thread's work, overlaps the formatting.
 * The caller runs the tasks: io_write_lines with backend_parallel, omp inside its parallel region. */
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
        out_flush(j->out);
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
        backend_parallel(out->threads, io_text_tasks(&j, r), text_round_task, &tr);
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
    out_flush(out);
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
    fprintf(stderr, "\r%s: step %lld of %lld (%.0f%%), %.0f s left", backend_name, (long long)step,
            (long long)out->steps, 100.0 * (double)step / (double)out->steps, left);
    if (out->ck_count) fprintf(stderr, "; checkpoint of step %lld in %s", (long long)out->ck_step, out->ck_path);
    fputs("   ", stderr);
    out->shown = 1;
}

/* ==== checkpoints ========================================================================================= */

/* A checkpoint file: "DISKSCKP", format version, bytes of a real (8: double, 4: float), then the run
 * (n, L, r, S, the step reached, K, print, exact, pressure, dump17), then x, y, vx, vy (velocities per
 * step, as in the output), the counts p and w, the wall impulses (with --pressure), the partners of
 * the disks' last events (--exact), and a checksum of everything before it. Native byte order: it is
 * read back by the same programs on the same kind of machine. */
#define CK_MAGIC "DISKSCKP"
#define CK_VERSION 1u

typedef struct {
    char magic[8];
    uint32_t version, real_bytes;
    int64_t n, steps, step, substeps;
    double L, r;
    int32_t print, exact, pressure, dump17;
} CkHeader;

/* The checksum: the bytes as 64-bit words, each mixed in by a bijection of the running value (so any
 * one damaged word changes it), then the last 0-7 bytes one at a time. A word a step keeps it near
 * memory speed: a checkpoint of 1e7 disks is 400 MB. */
typedef struct {
    uint64_t h;
    unsigned char carry[8];
    unsigned nc;
} CkHash;

static uint64_t ck_mix(uint64_t h, uint64_t w)
{
    h ^= w;
    return ((h << 31) | (h >> 33)) * 0x9e3779b97f4a7c15u;
}

static void ck_hash(CkHash *s, const void *bytes, size_t len)
{
    const unsigned char *b = bytes;
    uint64_t w;
    while (s->nc && len) {
        s->carry[s->nc++] = *b++, len--;
        if (s->nc == 8) {
            memcpy(&w, s->carry, 8);
            s->h = ck_mix(s->h, w);
            s->nc = 0;
        }
    }
    for (; len >= 8; b += 8, len -= 8) {
        memcpy(&w, b, 8);
        s->h = ck_mix(s->h, w);
    }
    while (len) s->carry[s->nc++] = *b++, len--;
}

static uint64_t ck_hash_end(const CkHash *s)
{
    uint64_t h = s->h;
    for (unsigned k = 0; k < s->nc; k++) h = ck_mix(h, s->carry[k]);
    return h;
}

typedef struct {
    int fd;
    const char *path;
    CkHash hash;
    char buf[1 << 16];
    size_t len;
    uint64_t bytes; /* written so far */
} CkWriter;

static void ck_flush(CkWriter *w)
{
    const char *err = write_fd(w->fd, w->buf, w->len);
    if (err) sim_fail("cannot write the checkpoint %s: %s", w->path, err);
    w->bytes += w->len;
    w->len = 0;
}

static void ck_put(CkWriter *w, const void *bytes, size_t len)
{
    ck_hash(&w->hash, bytes, len);
    const char *b = bytes;
    while (len) {
        size_t part = sizeof w->buf - w->len < len ? sizeof w->buf - w->len : len;
        memcpy(w->buf + w->len, b, part);
        w->len += part, b += part, len -= part;
        if (w->len == sizeof w->buf) ck_flush(w);
    }
}

/* n reals times f (the velocities' K: exact, a power of two) */
static void ck_put_reals(CkWriter *w, const real *v, int64_t n, real f)
{
    real chunk[1024];
    for (int64_t i = 0; i < n; i += 1024) {
        int64_t m = n - i < 1024 ? n - i : 1024;
        for (int64_t k = 0; k < m; k++) chunk[k] = v[i + k] * f;
        ck_put(w, chunk, (size_t)m * sizeof(real));
    }
}

/* FILE.tmp, where a checkpoint is written before it is renamed over FILE (the caller frees it) */
static char *ck_tmp_name(const char *path)
{
    size_t len = strlen(path);
    char *tmp = sim_calloc(len + 5, 1);
    memcpy(tmp, path, len);
    memcpy(tmp + len, ".tmp", 5);
    return tmp;
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

int io_checkpoint_due(const Output *out, int64_t step)
{
    return out->ck_path && step % out->ck_every == 0 && step > out->first && step < out->steps;
}

int64_t io_checkpoint_next(const Output *out, int64_t step)
{
    if (!out->ck_path) return 0;
    int64_t due = (step + out->ck_every - 1) / out->ck_every * out->ck_every;
    while (due <= out->first) due += out->ck_every;
    return io_checkpoint_due(out, due) ? due : 0;
}

void io_checkpoint(Output *out, const Sim *sim, int64_t step)
{
    out_flush(out); /* stdout holds every line through this step before the checkpoint says so */
    double t0 = sim_clock();
    const Params *par = out->par;
    size_t plen = strlen(out->ck_path);
    char *tmp = ck_tmp_name(out->ck_path);
    CkWriter *w = sim_calloc(1, sizeof *w);
    w->path = tmp;
    w->fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (w->fd < 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    CkHeader h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, CK_MAGIC, 8);
    h.version = CK_VERSION;
    h.real_bytes = (uint32_t)sizeof(real);
    h.n = par->n, h.steps = par->steps, h.step = step, h.substeps = par->substeps;
    h.L = (double)par->L, h.r = (double)par->r;
    h.print = par->print, h.exact = out->opt->exact, h.pressure = sim->wi != NULL, h.dump17 = out->dump17;
    ck_put(w, &h, sizeof h);
    ck_put_reals(w, sim->x, par->n, 1);
    ck_put_reals(w, sim->y, par->n, 1);
    ck_put_reals(w, sim->vx, par->n, v_unscale);
    ck_put_reals(w, sim->vy, par->n, v_unscale);
    ck_put(w, sim->pc, (size_t)par->n * sizeof *sim->pc);
    ck_put(w, sim->wc, (size_t)par->n * sizeof *sim->wc);
    if (sim->wi) ck_put(w, sim->wi, (size_t)par->n * sizeof *sim->wi);
    if (h.exact) ck_put(w, sim->last, (size_t)par->n * sizeof *sim->last);
    uint64_t hash = ck_hash_end(&w->hash);
    ck_put(w, &hash, sizeof hash);
    ck_flush(w);
    if (fsync(w->fd) != 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    close(w->fd);
    if (rename(tmp, out->ck_path) != 0)
        sim_fail("cannot replace the checkpoint %s: %s", out->ck_path, strerror(errno));
    /* and the directory's entry: the rename itself survives a crash */
    char *dir = sim_calloc(plen + 2, 1);
    memcpy(dir, out->ck_path, plen + 1);
    char *slash = strrchr(dir, '/');
    if (slash) slash[slash == dir] = '\0';
    else strcpy(dir, ".");
    int dfd = open(dir, O_RDONLY);
    if (dfd >= 0) {
        (void)fsync(dfd);
        close(dfd);
    }
    free(dir);
    free(tmp);
    out->ck_count++;
    out->ck_step = step;
    out->ck_bytes += w->bytes;
    out->ck_s += sim_clock() - t0;
    free(w);
}

/* --checkpoint FILE is tried before the run starts: a run of hours should not learn at its first
 * checkpoint that FILE cannot be written. */
static void ck_probe(const char *path)
{
    struct stat st;
    if (stat(path, &st) == 0 && !S_ISREG(st.st_mode))
        sim_fail("--checkpoint %s: exists and is not a regular file", path);
    char *tmp = ck_tmp_name(path);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) sim_fail("--checkpoint %s: cannot write %s (%s)", path, tmp, strerror(errno));
    close(fd);
    unlink(tmp);
    free(tmp);
}

/* The run and the state of a checkpoint, for --resume: the options that shape the dynamics (K, exact,
 * pressure) and the output (print, dump17) come from it; anything wrong with the file is refused
 * before a byte of output. */
static void ck_read(Options *opt, Params *par, Sim *sim)
{
    const char *path = opt->resume;
    int fd = open(path, O_RDONLY);
    if (fd < 0) sim_fail("%s: cannot open the checkpoint (%s)", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) sim_fail("%s: not a checkpoint (not a regular file)", path);
    CkHeader h;
    if (read(fd, &h, sizeof h) != (ssize_t)sizeof h || memcmp(h.magic, CK_MAGIC, 8) != 0)
        sim_fail("%s: not a checkpoint (it does not start with %s)", path, CK_MAGIC);
    if (h.version != CK_VERSION)
        sim_fail("%s: a checkpoint of format %u; this program reads format %u", path, h.version, CK_VERSION);
    if (h.real_bytes != sizeof(real))
        sim_fail("%s: a checkpoint of %s precision; %s computes in %s", path, h.real_bytes == 8 ? "double" : "single",
                backend_name, sizeof(real) == 8 ? "double" : "single");
    if (h.n < 1 || h.n > SIM_MAX_N || h.steps < 0 || h.step < 1 || h.step >= h.steps || h.substeps < 1 ||
        h.substeps > 1024 || (h.substeps & (h.substeps - 1)) || !(h.L > 0) || !(h.r > 0))
        sim_fail("%s: a checkpoint with impossible values (N = %lld, step %lld of %lld, K = %lld)", path,
                (long long)h.n, (long long)h.step, (long long)h.steps, (long long)h.substeps);
    uint64_t n = (uint64_t)h.n;
    uint64_t want = sizeof h + n * (4 * sizeof(real) + 2 * sizeof(int32_t)) + (h.pressure ? n * sizeof(double) : 0) +
                    (h.exact ? n * sizeof(int32_t) : 0) + 8;
    if ((uint64_t)st.st_size != want)
        sim_fail("%s: a checkpoint of %lld bytes, where its header calls for %llu (cut short or extended)", path,
                (long long)st.st_size, (unsigned long long)want);
    if (h.exact && !(backend_features & SIM_FEATURE_EXACT))
        sim_fail("%s: a checkpoint of an --exact run, which %s does not support", path, backend_name);
    if (h.pressure && !(backend_features & SIM_FEATURE_PRESSURE))
        sim_fail("%s: a checkpoint of a --pressure run, which %s does not support", path, backend_name);
    if (h.substeps > 1 && !(backend_features & SIM_FEATURE_SUBSTEPS))
        sim_fail("%s: a checkpoint of a --substeps run, which %s does not support", path, backend_name);
    if (sim_alloc(sim, h.n)) sim_fail("%s: not enough memory for the particles (N = %lld)", path, (long long)h.n);
    if (h.pressure) sim->wi = sim_calloc(n, sizeof *sim->wi);
    if (h.exact) sim->last = sim_calloc(n, sizeof *sim->last);
    CkHash hash = {0, {0}, 0};
    ck_hash(&hash, &h, sizeof h);
    void *arrays[8] = {sim->x, sim->y, sim->vx, sim->vy, sim->pc, sim->wc, sim->wi, sim->last};
    size_t sizes[8] = {sizeof(real), sizeof(real), sizeof(real), sizeof(real), 4, 4, 8, 4};
    for (int a = 0; a < 8; a++) {
        char *b = arrays[a];
        if (!b) continue; /* no --pressure or no --exact */
        size_t len = n * sizes[a], done = 0;
        while (done < len) {
            ssize_t got = read(fd, b + done, len - done);
            if (got < 0 && errno == EINTR) continue;
            if (got <= 0) sim_fail("%s: cannot read the checkpoint (%s)", path, got < 0 ? strerror(errno) : "cut short");
            done += (size_t)got;
        }
        ck_hash(&hash, b, len);
    }
    uint64_t stored;
    if (read(fd, &stored, sizeof stored) != (ssize_t)sizeof stored || stored != ck_hash_end(&hash))
        sim_fail("%s: the checkpoint's checksum does not match its contents (damaged)", path);
    close(fd);
    for (int64_t i = 0; i < h.n; i++)
        if (!(sim->x[i] >= (real)h.r && sim->x[i] <= (real)h.L - (real)h.r && sim->y[i] >= (real)h.r &&
              sim->y[i] <= (real)h.L - (real)h.r && sim->pc[i] >= 0 && sim->wc[i] >= 0 &&
              (!sim->last || (sim->last[i] >= -1 && sim->last[i] < h.n && sim->last[i] != i))))
            sim_fail("%s: disk %lld of the checkpoint is outside the box or has impossible counts", path, (long long)i);
    par->n = h.n;
    par->L = (real)h.L;
    par->r = (real)h.r;
    par->steps = h.steps;
    par->print = h.print;
    params_derive(par);
    par->first_step = h.step;
    opt->substeps = (int)h.substeps;
    opt->exact = h.exact;
    opt->pressure = h.pressure;
    opt->dump17 = h.dump17;
    if (!opt->quiet)
        fprintf(stderr, "%s: resuming %s at step %lld of %lld\n", backend_name, path, (long long)h.step,
                (long long)h.steps);
}

/* ==== reading the input ==================================================================================== */

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
    fprintf(stderr, "%s: %s:%ld: ", backend_name, rd->label, line);
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
        backend_parallel(opt->threads, (int64_t)((cap - 2 + READ_PIECE - 1) / READ_PIECE), read_piece, &sl);
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
static int parse_int(const char *s, long long *out)
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

/* Accepts decimal reals: [+-] digits [. digits] [e [+-] digits] (at least one digit in the mantissa).
 * Returns 0, -1 (not a number), -2 (overflow) or -3 (nan or inf). Values as strtod reads them: where the
 * digits make an integer M < 2^53 and there are k <= 22 decimals and no exponent (every %.8f output of
 * a box up to 9e7 wide), M / 10^k is a single correctly rounded division of two exact doubles, which is
 * strtod's correctly rounded value; anything else goes to strtod. */
int io_parse_real(const char *s, double *out)
{
    const char *p = s;
    int neg = *p == '-';
    if (*p == '+' || *p == '-') p++;
    if ((*p | 32) == 'n' || (*p | 32) == 'i')
        if (ieq(p, "nan") || ieq(p, "inf") || ieq(p, "infinity")) return -3;
    int digits = 0, decimals = 0;
    uint64_t mant = 0;
    while (*p >= '0' && *p <= '9') {
        if (digits < 19) mant = mant * 10 + (uint64_t)(*p - '0');
        p++, digits++;
    }
    if (*p == '.') {
        p++;
        while (*p >= '0' && *p <= '9') {
            if (digits < 19) mant = mant * 10 + (uint64_t)(*p - '0');
            p++, digits++, decimals++;
        }
    }
    if (!digits) return -1;
    if (!*p && digits <= 19 && mant <= (UINT64_C(1) << 53) && decimals <= 22) {
        double v = (double)mant / exact_pow10[decimals];
        *out = neg ? -v : v;
        return 0;
    }
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
    int rc = parse_int(t, &v);
    if (rc == -1) input_error(rd, rd->line, "%s is not an integer (found '%s')", what, t);
    if (rc == -2 || v < lo || v > hi)
        input_error(rd, rd->line, "%s must be between %lld and %lld (found '%s')", what, lo, hi, t);
    return v;
}

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

/* The particle lines are parsed in chunks of whole lines, in parallel (backend_parallel), and the
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
    int rc = parse_int(tok[0], &idx);
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
    for (int k = 0; k < 2; k++)
        if (!(v[k] >= par->lo && v[k] <= par->hi)) {
            chunk_error(c, line, "%s must be within [r, L-r] = [%.17g, %.17g] (found '%s')",
                        field_name[k + 1], (double)par->lo, (double)par->hi, tok[k + 1]);
            return (int32_t)idx;
        }
    for (int k = 2; k < 4; k++)
        if (!(fabs(v[k]) <= SIM_MAX_V)) {
            chunk_error(c, line, "|%s| must be <= %g (found '%s')", field_name[k + 1], SIM_MAX_V,
                        tok[k + 1]);
            return (int32_t)idx;
        }
    /* a duplicate index writes twice here, and is then reported: the values are never used */
    int64_t at = ps->by_line ? pos : idx;
    ps->sim->x[at] = (real)v[0]; /* rounding keeps x in [lo, hi]: both are reals */
    ps->sim->y[at] = (real)v[1];
    ps->sim->vx[at] = (real)v[2];
    ps->sim->vy[at] = (real)v[3];
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
        long col = zero_byte_column(p, end);
        int32_t *idx = &ps->line_idx[c->line0 + i];
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
    backend_parallel(threads, nchunk, count_lines, ps);
    int64_t lines = 0;
    for (int64_t k = 0; k < nchunk; k++) {
        ps->chunk[k].line0 = lines;
        lines += ps->chunk[k].lines;
    }
    ps->lines = lines;
    ps->line_idx = sim_calloc((size_t)lines, sizeof *ps->line_idx);
    if (ps->by_line && sim_alloc(ps->sim, lines + 1))
        sim_fail("out of memory for %lld particle lines", (long long)lines);
    backend_parallel(threads, nchunk, parse_chunk, ps);
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

/* ==== random placement (SPEC.md 1) ========================================================================== */

/* xoshiro256** seeded through splitmix64: fast, and the same numbers on every platform. */
typedef struct {
    uint64_t s[4];
} Rng;

static uint64_t splitmix64(uint64_t *state)
{
    uint64_t z = (*state += UINT64_C(0x9e3779b97f4a7c15));
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k)
{
    return (x << k) | (x >> (64 - k));
}

static uint64_t rng_next(Rng *g)
{
    uint64_t *s = g->s;
    uint64_t result = rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

/* Uniform in [0, 1) with 53 random bits. */
static double rng_unit(Rng *g)
{
    return (double)(rng_next(g) >> 11) * (1.0 / 9007199254740992.0);
}

/* Places n non-overlapping disks uniformly, each tried up to PLACE_TRIES times, in index order: disk i
 * draws x, y until it overlaps none of the disks before it, then its speed and direction. A grid of
 * cells at least 2r wide, about one disk per cell, makes each overlap test look at 9 cells.
 *
 * In all but dense scenes nearly every disk finds its place at its first try, so the disks are placed
 * in windows, speculatively: the draws of the stream are taken in order into a queue, every disk of
 * the window takes the next four (x, y, speed, direction), and all threads test each disk's position
 * against the disks before it. The window is good up to its first disk that overlaps one before it;
 * the good disks get their velocities (cos and sin, the costly part) on all threads, the overlapping
 * disk tries again alone, drawing on from where its first try's draws ended, and the next window
 * starts after it. Each disk thereby takes the same draws as in a loop over the disks one by one, and
 * the result is that loop's, bit for bit. Returns -1, or the index of the disk that found no place. */
#define PLACE_TASK 1024    /* disks per task of a window */
#define PLACE_WINDOW 65536 /* disks per window at most */

typedef struct {
    const Params *par;
    Sim *sim;
    int32_t *head, *next; /* the grid: per cell, its disks, the latest first */
    int64_t cells;
    double cell, smin, smax;
    const double *draw; /* the window's draws: four per disk, from disk `from` on */
    int64_t from, count;
    int64_t first_bad[PLACE_WINDOW / PLACE_TASK]; /* per task: its first disk that overlaps one before
                                                     it, or from + count */
} Place;

static int64_t cell_of(double c, double cell, int64_t cells)
{
    int64_t k = (int64_t)(c / cell);
    return k >= cells ? cells - 1 : k;
}

static int64_t place_cell(const Place *pl, double x, double y)
{
    return cell_of(y, pl->cell, pl->cells) * pl->cells + cell_of(x, pl->cell, pl->cells);
}

/* 1 if the disk at (x, y) overlaps one of the disks j < limit in the grid around it */
static int place_overlaps(const Place *pl, double x, double y, int64_t limit)
{
    const Sim *sim = pl->sim;
    int64_t cells = pl->cells, cx = cell_of(x, pl->cell, cells), cy = cell_of(y, pl->cell, cells);
    for (int64_t ny = cy - 1; ny <= cy + 1; ny++)
        for (int64_t nx = cx - 1; nx <= cx + 1; nx++) {
            if (nx < 0 || ny < 0 || nx >= cells || ny >= cells) continue;
            for (int32_t j = pl->head[ny * cells + nx]; j >= 0; j = pl->next[j]) {
                if (j >= limit) continue;
                double dx = sim->x[j] - x, dy = sim->y[j] - y;
                if (dx * dx + dy * dy < pl->par->sigma2) return 1;
            }
        }
    return 0;
}

/* the position a draw gives: rounded to real first, so that the overlap tests see the stored value */
static double place_coord(const Params *par, double u)
{
    return clamp_coord((real)(par->lo + (par->hi - par->lo) * u), par->lo, par->hi);
}

static void place_velocity(const Place *pl, int64_t i, double us, double ua)
{
    double speed = pl->smin + (pl->smax - pl->smin) * us, angle = 6.283185307179586 * ua;
    pl->sim->vx[i] = (real)(speed * cos(angle));
    pl->sim->vy[i] = (real)(speed * sin(angle));
}

static void place_position_task(void *ctx, int64_t k)
{
    Place *pl = ctx;
    int64_t a = k * PLACE_TASK, b = a + PLACE_TASK < pl->count ? a + PLACE_TASK : pl->count;
    for (int64_t t = a; t < b; t++) {
        pl->sim->x[pl->from + t] = place_coord(pl->par, pl->draw[4 * t]);
        pl->sim->y[pl->from + t] = place_coord(pl->par, pl->draw[4 * t + 1]);
    }
}

static void place_check_task(void *ctx, int64_t k)
{
    Place *pl = ctx;
    int64_t a = k * PLACE_TASK, b = a + PLACE_TASK < pl->count ? a + PLACE_TASK : pl->count;
    pl->first_bad[k] = pl->from + pl->count;
    for (int64_t i = pl->from + a; i < pl->from + b; i++)
        if (place_overlaps(pl, pl->sim->x[i], pl->sim->y[i], i)) {
            pl->first_bad[k] = i;
            return;
        }
}

static void place_velocity_task(void *ctx, int64_t k)
{
    Place *pl = ctx;
    int64_t a = k * PLACE_TASK, b = a + PLACE_TASK < pl->count ? a + PLACE_TASK : pl->count;
    for (int64_t t = a; t < b; t++) place_velocity(pl, pl->from + t, pl->draw[4 * t + 2], pl->draw[4 * t + 3]);
}

/* a window's tasks: on all threads where there are enough of them to pay for waking the threads (a
 * dilute scene's first tries collide every few hundred disks at N = 1e5, so most windows are short) */
static void place_tasks(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), Place *pl)
{
    if (tasks >= 4) {
        backend_parallel(threads, tasks, task, pl);
        return;
    }
    for (int64_t k = 0; k < tasks; k++) task(pl, k);
}

/* the next draw: from the queue while it lasts, then from the stream */
static double place_draw(const double *q, size_t *qpos, size_t qlen, Rng *g)
{
    return *qpos < qlen ? q[(*qpos)++] : rng_unit(g);
}

static int64_t generate(const Params *par, uint64_t seed, Sim *sim, int threads)
{
    Rng g;
    uint64_t sm = seed;
    for (int k = 0; k < 4; k++) g.s[k] = splitmix64(&sm);
    int64_t n = par->n;
    double side = sqrt((double)n) + 1;
    double fit = par->L / (2 * par->r); /* most cells per side that stay >= 2r wide */
    int64_t cells = (int64_t)(side < fit ? side : fit);
    if (cells < 1) cells = 1;
    Place pl;
    memset(&pl, 0, sizeof pl);
    pl.par = par;
    pl.sim = sim;
    pl.cells = cells;
    pl.cell = par->L / (double)cells;
    pl.head = sim_calloc((size_t)(cells * cells), sizeof *pl.head);
    pl.next = sim_calloc((size_t)n, sizeof *pl.next);
    memset(pl.head, 0xff, (size_t)(cells * cells) * sizeof *pl.head);
    pl.smin = par->L / 4, pl.smax = par->L / (8 * par->r);
    if (pl.smax < pl.smin) {
        double t = pl.smin;
        pl.smin = pl.smax;
        pl.smax = t;
    }
#ifdef SIM_FLOAT
    /* the float build's speed limit, which keeps squared speeds finite, holds for placed disks too */
    if (pl.smax > SIM_MAX_V) pl.smax = SIM_MAX_V;
    if (pl.smin > SIM_MAX_V) pl.smin = SIM_MAX_V;
#endif
    /* the queue of draws: [qpos, qlen) taken from the stream, not yet used by a disk */
    double *q = sim_calloc(4 * PLACE_WINDOW, sizeof *q);
    size_t qpos = 0, qlen = 0;
    int64_t window = PLACE_TASK, failed = -1;
    for (int64_t k = 0; k < n && failed < 0;) {
        int64_t w = n - k < window ? n - k : window;
        memmove(q, q + qpos, (qlen - qpos) * sizeof *q);
        qlen -= qpos;
        qpos = 0;
        while (qlen < 4 * (size_t)w) q[qlen++] = rng_unit(&g);
        pl.draw = q;
        pl.from = k;
        pl.count = w;
        int64_t tasks = (w + PLACE_TASK - 1) / PLACE_TASK;
        place_tasks(threads, tasks, place_position_task, &pl);
        for (int64_t i = k; i < k + w; i++) { /* into the grid in index order */
            int64_t c = place_cell(&pl, sim->x[i], sim->y[i]);
            pl.next[i] = pl.head[c];
            pl.head[c] = (int32_t)i;
        }
        place_tasks(threads, tasks, place_check_task, &pl);
        int64_t bad = k + w;
        for (int64_t t = 0; t < tasks && bad == k + w; t++) bad = pl.first_bad[t];
        for (int64_t i = k + w - 1; i >= bad; i--) /* out of the grid again: each is its cell's latest */
            pl.head[place_cell(&pl, sim->x[i], sim->y[i])] = pl.next[i];
        pl.count = bad - k;
        place_tasks(threads, (pl.count + PLACE_TASK - 1) / PLACE_TASK, place_velocity_task, &pl);
        qpos = 4 * (size_t)(bad - k);
        if (bad == k + w) {
            if (window < PLACE_WINDOW) window *= 2;
            k = bad;
            continue;
        }
        /* disk `bad` alone: its first try (the window's draws) overlapped; it draws on in order */
        window = 2 * (bad - k) > PLACE_TASK ? 2 * (bad - k) : PLACE_TASK;
        if (window > PLACE_WINDOW) window = PLACE_WINDOW;
        double x = 0, y = 0;
        for (int tries = 1;; tries++) {
            x = place_coord(par, place_draw(q, &qpos, qlen, &g));
            y = place_coord(par, place_draw(q, &qpos, qlen, &g));
            if (!place_overlaps(&pl, x, y, bad)) break;
            if (tries == PLACE_TRIES) {
                failed = bad;
                break;
            }
        }
        if (failed >= 0) break;
        sim->x[bad] = x;
        sim->y[bad] = y;
        int64_t c = place_cell(&pl, x, y);
        pl.next[bad] = pl.head[c];
        pl.head[c] = (int32_t)bad;
        double us = place_draw(q, &qpos, qlen, &g);
        place_velocity(&pl, bad, us, place_draw(q, &qpos, qlen, &g));
        k = bad + 1;
    }
    free(q);
    free(pl.head);
    free(pl.next);
    return failed;
}

/* Reads and validates the whole input; generates the disks when the input lists none. */
static void read_input(const Options *opt, Params *par, Sim *sim, IoTimes *io, int prepare)
{
    Reader rd;
    memset(&rd, 0, sizeof rd);
    rd.label = opt->label;
    double t0 = sim_clock();
    rd.text = slurp(opt, &rd.size);
    double t1 = sim_clock();
    read_header(&rd, par);
    if (prepare) backend_prepare(par);
    if (sim_alloc(sim, par->n))
        input_error(&rd, rd.n_line, "not enough memory for the particles (N = %lld)",
                    (long long)par->n);
    int64_t lines = read_particles(&rd, par, sim, opt->threads);
    io->read_s = t1 - t0;
    io->parse_s = sim_clock() - t1;
    io->in_bytes = rd.size;
    if (lines == 0) {
        int64_t failed = generate(par, opt->seed, sim, opt->threads);
        if (failed >= 0)
            input_error(&rd, rd.n_line,
                        "cannot place %lld disks of radius %g without overlap in a box of side %g "
                        "(disk %lld failed %d tries; area fraction %.3f)",
                        (long long)par->n, (double)par->r, (double)par->L, (long long)failed,
                        PLACE_TRIES,
                        (double)par->n * 3.141592653589793 * par->r * par->r / (par->L * par->L));
        if (!opt->quiet)
            fprintf(stderr, "%s: generated %lld disks with seed %llu\n", backend_name,
                    (long long)par->n, (unsigned long long)opt->seed);
    }
    free(rd.text);
}

void io_read_input(const Options *opt, Params *par, Sim *sim)
{
    IoTimes io;
    read_input(opt, par, sim, &io, 0);
}

/* ==== command line and driver ====================================================================== */

static void usage(FILE *f)
{
    fprintf(f,
            "usage: %s [INPUT|-] [options]\n"
            "Simulates N elastic disks in an L x L box, one collision per disk per step (SPEC.md).\n"
            "INPUT is the input file; '-' or none reads standard input.\n"
            "Output (stdout): step 0, every step in print mode, and the final step with collision counts.\n"
            "Timing and messages go to stderr.\n"
            "\n"
            "options:\n"
            "  --seed N     seed of the random placement when the input lists no disks (default %u)\n"
            "  --dump17     print reals with %%.17g (round-trip precision) instead of %%.8f\n"
            "  --stats      print event and pair-test counts on stderr\n"
            "  --substeps K split each step into K sub-steps of length 1/K (K a power of two up to\n"
            "               1024; up to K collisions per disk per step); 1 is SPEC.md\n"
            "  --pressure   add up the impulse the walls give the disks and print the pressure on\n"
            "               stderr\n"
            "  --quiet      no timing line on stderr\n"
            "  --exact      event-driven: every collision in time order, any number per disk and step\n"
            "               (the exact elastic dynamics up to rounding); not with --substeps\n"
            "  --checkpoint FILE   save the whole state in FILE every --checkpoint-every steps\n"
            "               (default 1000), replacing it whole each time (FILE.tmp, then a rename)\n"
            "  --resume FILE       go on from the checkpoint FILE (no INPUT): prints what the\n"
            "               interrupted run had not printed (print mode: the steps after the\n"
            "               checkpoint's; perf: the final state); the run's options come from FILE\n"
            "  --help       this text\n"
            "%s",
            backend_name, DEFAULT_SEED, backend_options);
}

static long long option_value(int argc, char **argv, int *k, long long lo, long long hi)
{
    const char *name = argv[*k];
    if (*k + 1 >= argc) sim_fail("%s needs a value (see --help)", name);
    const char *val = argv[++*k];
    long long v;
    if (parse_int(val, &v) || v < lo || v > hi)
        sim_fail("%s must be an integer between %lld and %lld (found '%s')", name, lo, hi, val);
    return v;
}

void io_parse_args(int argc, char **argv, Options *opt)
{
    memset(opt, 0, sizeof *opt);
    opt->seed = DEFAULT_SEED;
    opt->substeps = 1;
    opt->balance = SIM_BALANCE_EVERY;
    opt->keep = -1;
    opt->path = NULL;
    /* omp and mpi (its ranks' threads) share the broad phase: its threads, --check and --broad */
    int is_mpi = strcmp(backend_name, "mpi" SIM_SUFFIX) == 0;
    int own_threads = strcmp(backend_name, "omp" SIM_SUFFIX) == 0 || is_mpi;
    int substeps_given = 0;
    for (int k = 1; k < argc; k++) {
        const char *a = argv[k];
        if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
            usage(stdout);
            if (fflush(stdout) || ferror(stdout))
                sim_fail("cannot write the help text: %s", strerror(errno));
            exit(0);
        } else if (strcmp(a, "--seed") == 0) {
            opt->seed = (uint64_t)option_value(argc, argv, &k, 0, 9223372036854775807LL);
            opt->seed_given = 1;
        } else if (strcmp(a, "--dump17") == 0) {
            opt->dump17 = 1;
        } else if (strcmp(a, "--stats") == 0) {
            opt->stats = 1;
        } else if (strcmp(a, "--quiet") == 0) {
            opt->quiet = 1;
        } else if (strcmp(a, "--substeps") == 0) {
            opt->substeps = (int)option_value(argc, argv, &k, 1, 1024);
            substeps_given = 1;
            if (opt->substeps & (opt->substeps - 1))
                sim_fail("--substeps must be a power of two, so that velocities scale exactly (found "
                        "%d)", opt->substeps);
            if (opt->substeps > 1 && !(backend_features & SIM_FEATURE_SUBSTEPS))
                sim_fail("--substeps is not supported by %s", backend_name);
        } else if (strcmp(a, "--pressure") == 0) {
            opt->pressure = 1;
            if (!(backend_features & SIM_FEATURE_PRESSURE))
                sim_fail("--pressure is not supported by %s", backend_name);
        } else if (strcmp(a, "--exact") == 0) {
            opt->exact = 1;
            if (!(backend_features & SIM_FEATURE_EXACT))
                sim_fail("--exact is not supported by %s", backend_name);
        } else if (own_threads && strcmp(a, "--threads") == 0) {
            opt->threads = (int)option_value(argc, argv, &k, 1, 4096);
        } else if (own_threads && strcmp(a, "--check") == 0) {
            opt->check = 1;
        } else if (own_threads && strcmp(a, "--broad") == 0) {
            if (k + 1 >= argc) sim_fail("--broad needs a value (see --help)");
            const char *val = argv[++k];
            if (strcmp(val, "grid") == 0) opt->broad = SIM_BROAD_GRID;
            else if (strcmp(val, "paths") == 0) opt->broad = SIM_BROAD_PATHS;
            else if (strcmp(val, "mixed") == 0) opt->broad = SIM_BROAD_MIXED;
            else if (strcmp(val, "auto") == 0) opt->broad = SIM_BROAD_AUTO;
            else sim_fail("--broad must be grid, paths, mixed or auto (found '%s')", val);
        } else if (strcmp(backend_name, "omp" SIM_SUFFIX) == 0 && strcmp(a, "--lanes") == 0) {
            opt->lanes = (int)option_value(argc, argv, &k, 1, 16);
            if (opt->lanes != 1 && opt->lanes != 4 && opt->lanes != 8 && opt->lanes != 16)
                sim_fail("--lanes must be 1, 4, 8 or 16 (found %d)", opt->lanes);
        } else if (strcmp(backend_name, "omp" SIM_SUFFIX) == 0 && strcmp(a, "--keep") == 0) {
            opt->keep = (int)option_value(argc, argv, &k, 0, SIM_KEEP_MOST);
        } else if (is_mpi && strcmp(a, "--balance") == 0) {
            opt->balance = option_value(argc, argv, &k, 0, SIM_MAX_STEPS);
        } else if (strcmp(a, "--checkpoint") == 0) {
            if (k + 1 >= argc) sim_fail("--checkpoint needs a file name");
            opt->checkpoint = argv[++k];
        } else if (strcmp(a, "--output") == 0) {
            if (!(backend_features & SIM_FEATURE_OUTPUT))
                sim_fail("--output is not supported by %s (redirect its standard output)", backend_name);
            if (k + 1 >= argc) sim_fail("--output needs a file name");
            opt->output = argv[++k];
        } else if (strcmp(a, "--checkpoint-every") == 0) {
            opt->checkpoint_every = option_value(argc, argv, &k, 1, SIM_MAX_STEPS);
        } else if (strcmp(a, "--resume") == 0) {
            if (k + 1 >= argc) sim_fail("--resume needs a checkpoint file");
            opt->resume = argv[++k];
        } else if (a[0] == '-' && a[1] != '\0') {
            sim_fail("unknown option '%s' (see --help)", a);
        } else if (opt->path) {
            sim_fail("more than one input given ('%s' and '%s')", opt->path, a);
        } else {
            opt->path = a;
        }
    }
    /* --exact already has every collision: sub-steps would only cut its steps into more windows */
    if (opt->exact && substeps_given) sim_fail("--exact and --substeps exclude each other");
    if ((opt->checkpoint || opt->resume) && !(backend_features & SIM_FEATURE_CHECKPOINT))
        sim_fail("--checkpoint and --resume are not supported by %s yet", backend_name);
    if (opt->checkpoint_every && !opt->checkpoint) sim_fail("--checkpoint-every needs --checkpoint FILE");
    if (!opt->checkpoint_every) opt->checkpoint_every = 1000;
    if (opt->resume) {
        /* the run is the checkpoint's: these would change it */
        if (opt->path) sim_fail("--resume reads no input file ('%s' given)", opt->path);
        if (substeps_given || opt->pressure || opt->dump17 || opt->seed_given || opt->exact)
            sim_fail("--resume takes --substeps, --exact, --pressure, --dump17 and --seed from the checkpoint: "
                    "leave them out");
    }
    if (!opt->path) opt->path = "-";
    opt->label = strcmp(opt->path, "-") == 0 ? "<stdin>" : opt->path;
}

/* Multiplies every velocity by f, a power of two for --substeps: exact (short of subnormals). */
static void scale_velocities(Sim *sim, int64_t n, real f)
{
    if (f == 1) return;
    for (int64_t i = 0; i < n; i++) {
        sim->vx[i] = sim->vx[i] * f;
        sim->vy[i] = sim->vy[i] * f;
    }
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
    out_flush(out);
    free(out->buf);
    free(out);
}

void io_report(Output *out, const Params *par, const Options *opt, const RunStats *st, double run_s, double impulse)
{
    if (out->shown) fputc('\n', stderr); /* end the progress line */
    out->shown = 0;
    if (!opt->quiet) {
        double ps = (double)par->n * (double)(par->steps - par->first_step); /* a resumed run: the steps it ran */
        fprintf(stderr, "%s: %lld particles, %lld steps, %s: %.6f s step loop, %.4g particle-steps/s\n",
                backend_name, (long long)par->n, (long long)(par->steps - par->first_step), par->print ? "print" : "perf",
                st->seconds, st->seconds > 0 ? ps / st->seconds : 0.0);
    }
    if (opt->stats) {
        const IoTimes *io = &out->io;
        fprintf(stderr, "%s: %llu pair tests (%.4g per particle-step), %llu events\n", backend_name,
                (unsigned long long)st->pair_tests,
                par->steps > par->first_step ? (double)st->pair_tests / ((double)par->n * (double)(par->steps - par->first_step)) : 0.0,
                (unsigned long long)st->events);
        /* the text: the input read and parsed; step 0 and the final state formatted and written */
        if (out->io_known)
            fprintf(stderr, "%s: input %.1f MB: read %.4f s, parsed %.4f s (%.0f MB/s); step 0 and final state "
                    "%.1f MB: formatted and written %.4f s (%.0f MB/s)\n", backend_name, (double)io->in_bytes / 1e6,
                    io->read_s, io->parse_s, io->parse_s > 0 ? (double)io->in_bytes / 1e6 / io->parse_s : 0.0,
                    (double)io->out_bytes / 1e6, io->write_s, io->write_s > 0 ? (double)io->out_bytes / 1e6 / io->write_s : 0.0);
        if (out->ck_count)
            fprintf(stderr, "%s: %lld checkpoints of %.1f MB: written %.4f s (%.0f MB/s)\n", backend_name,
                    (long long)out->ck_count, (double)out->ck_bytes / 1e6 / (double)out->ck_count, out->ck_s,
                    out->ck_s > 0 ? (double)out->ck_bytes / 1e6 / out->ck_s : 0.0);
        fprintf(stderr, "%s: the run %.4f s, its step loop %.4f s; %.4f s since the start\n", backend_name, run_s,
                st->seconds, sim_clock() - (out->io_known ? io->start : out->start));
    }
    if (opt->pressure) {
        impulse *= (double)opt->substeps; /* the run's velocities were v / K */
        double span = (double)par->steps * 4 * (double)par->L;
        fprintf(stderr,
                "%s: pressure: wall impulse %.17g over %lld time units on 4 walls of length %.17g: "
                "P = %.17g\n",
                backend_name, impulse, (long long)par->steps, (double)par->L,
                span > 0 ? impulse / span : 0.0);
    }
}

int io_main(int argc, char **argv)
{
    Options opt;
    Params par;
    Sim sim;
    sim_program = backend_name;
    io_parse_args(argc, argv, &opt);
    if (opt.checkpoint) ck_probe(opt.checkpoint);
    IoTimes io;
    memset(&io, 0, sizeof io);
    io.start = sim_clock();
    if (opt.resume) {
        memset(&par, 0, sizeof par);
        memset(&sim, 0, sizeof sim);
        ck_read(&opt, &par, &sim);
        backend_prepare(&par);
    } else {
        read_input(&opt, &par, &sim, &io, 1);
        par.first_step = 0;
    }

    Output *out = io_output_open(&par, &opt);
    /* runs that cannot finish are refused before the first byte of output */
    if (opt.exact) exact_check_speeds(&sim, &par);
    if (par.steps * (int64_t)opt.substeps > INT32_MAX)
        sim_fail("--substeps %d with S = %lld steps could count more than %d collisions of one disk "
                "(S x K must be <= %d)",
                opt.substeps, (long long)par.steps, INT32_MAX, INT32_MAX);
    /* a resumed run's step 0 is out already; cuda writes it beside its steps, where the host is idle */
    out->step0_pending = !opt.resume && !par.print && par.steps > 0 && (backend_features & SIM_FEATURE_STEP0);
    if (!opt.resume && !out->step0_pending) io_write_step0(out, &sim);

    /* --substeps K: a sub-step of length 1/K is a SPEC.md step at velocities v / K */
    par.substeps = opt.substeps;
    real k = (real)opt.substeps;
    scale_velocities(&sim, par.n, 1 / k);
    v_unscale = k;
    if (opt.pressure && !sim.wi) sim.wi = sim_calloc((size_t)par.n, sizeof *sim.wi);

    RunStats st;
    memset(&st, 0, sizeof st);
    out->start = sim_clock();
    out->next_show = out->start + 2.0;
    if (backend_run(&sim, &par, &opt, out, &st)) return 1;
    double run_s = sim_clock() - out->start;
    if (out->step0_pending) sim_fail("internal error: %s did not write step 0", backend_name);
    io.write_s = out->step0_s;
    io.out_bytes = out->step0_bytes;
    if (out->shown) fputc('\n', stderr);
    out->shown = 0;
    scale_velocities(&sim, par.n, k);
    v_unscale = 1;

    if (!out->final_done) io_write_final(out, &sim, NULL, NULL);
    io.write_s += out->final_s;
    io.out_bytes += out->final_bytes;
    out->io = io;
    out->io_known = 1;
    double impulse = 0; /* in index order: the same sum in every backend */
    if (opt.pressure)
        for (int64_t i = 0; i < par.n; i++) impulse += sim.wi[i];
    io_report(out, &par, &opt, &st, run_s, impulse);
    io_output_close(out);
    sim_free(&sim);
    return 0;
}
