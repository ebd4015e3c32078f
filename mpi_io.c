/* mpi_io.c: the MPI backend's input and output, spread over the ranks as its steps are (mpi.h).
 *
 * Two ways of sharing out the disks: by strip (mpi_owner: whom a disk belongs to during the steps) and
 * by index block (rank q answers for the indices [q N / P, (q + 1) N / P): the duplicate check of the
 * input, the formatting of the output and the order of the pressure's sum). Everything that crosses
 * between the two goes through one exchange (MPI_Alltoallv), so that each rank holds about its share.
 *
 * Messages: io.c alone words them. Whatever a rank finds wrong with the input, every rank learns that
 * something is, and rank 0 reads the whole input once more with io.c's own reader, which prints seq's
 * line and exits; the other ranks wait in a collective rank 0 never joins, until mpirun ends the job.
 */
#define _POSIX_C_SOURCE 200809L

#include "mpi.h"

#include <errno.h>
#include <fcntl.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define HEAD_BYTES 65536          /* bytes rank 0 reads first for the header (doubled until it is whole) */
#define SCATTER_DISKS (1 << 20)   /* disks rank 0 sends out per round when it holds the whole state */
#define TEXT_PIECE 8192           /* output lines formatted per task and sent per message (< 13 MB) */
#define TAG_TEXT 71
#define TAG_SUM 72

/* A disk between ranks (wi: --pressure's impulse, for checkpoints; 0 elsewhere). */
typedef struct {
    real x, y, vx, vy;
    int64_t id;
    int32_t pc, wc;
    double wi;
} Disk;

/* ---- sharing out ------------------------------------------------------------------------------------ */

/* The rank's threads for the passes over its disks below (--threads; mpi_read_input and
 * mpi_read_checkpoint set it): each pass a loop over the disks in contiguous shares, which keeps
 * one thread's order. */
static int pass_threads = 1;

static int pass_nt(int64_t m)
{
    return mpi_pass_threads(pass_threads, m);
}

/* The first index of rank q's block (q = np: n) */
static int64_t block_lo(int64_t n, int q)
{
    return n * q / mpi_np;
}

static int block_of(int64_t n, int64_t i)
{
    int q = (int)(i * mpi_np / n);
    while (q + 1 < mpi_np && block_lo(n, q + 1) <= i) q++;
    while (q > 0 && block_lo(n, q) > i) q--;
    return q;
}

/* Sends item k of m (each `size` bytes) to rank dest[k]; returns what arrives, rank by rank, and its
 * count in *got. */
static void *exchange_packed(const void *items, size_t size, const int *dest, int64_t m, int64_t *got,
                             void (*pack)(const void *ctx, int64_t k, void *to),
                             void (*own_put)(const void *ctx, int64_t k, int64_t place), const void *ctx);

static void *exchange(const void *items, size_t size, const int *dest, int64_t m, int64_t *got)
{
    return exchange_packed(items, size, dest, m, got, NULL, NULL, NULL);
}

/* exchange, item k written straight into its place by pack(ctx, k, place) where pack is not NULL
 * (items unused): no copy of the items in index order first. The rank's own items are packed straight
 * into the buffer that receives the others' (a copy fewer: all of them on one rank), and that buffer's
 * other pages are touched by the threads first: a fresh buffer faults in its pages as it is first
 * written, which one thread inside MPI did at a fraction of the memory's speed (a third of mpi's whole
 * process at 4e6 disks on one rank). Where own_put is not NULL the rank's own items are not packed:
 * own_put(ctx, k, place) hands item k, the place-th of them in index order, to the caller, and the buffer
 * returned holds only the others' (a buffer and a copy fewer again: all of them on one rank). */
static void *exchange_packed(const void *items, size_t size, const int *dest, int64_t m, int64_t *got,
                             void (*pack)(const void *ctx, int64_t k, void *to),
                             void (*own_put)(const void *ctx, int64_t k, int64_t place), const void *ctx)
{
    int np = mpi_np, me = mpi_me, nt = pass_nt(m);
    int *sc = sim_calloc((size_t)np, sizeof *sc), *rc = sim_calloc((size_t)np, sizeof *rc);
    int *sd = sim_calloc((size_t)np, sizeof *sd), *rd = sim_calloc((size_t)np, sizeof *rd);
    /* by thread and rank: its share's items for the rank, then where they go (in rank order, a
     * rank's items in index order: one thread's order) */
    int64_t *at = sim_calloc((size_t)nt * (size_t)np, sizeof *at);
    int shares = 1; /* the items' shares, one a thread of the counting team */
#pragma omp parallel num_threads(nt)
    {
        int t = omp_get_thread_num(), w = omp_get_num_threads();
        int64_t k0 = m * t / w, k1 = m * (t + 1) / w, *mine = at + (size_t)t * (size_t)np;
        for (int64_t k = k0; k < k1; k++) mine[dest[k]]++;
#pragma omp barrier
#pragma omp single
        {
            (void)mpi_thread_places(at, w, sc);
            shares = w;
        }
    }
    MPI_Alltoall(sc, 1, MPI_INT, rc, 1, MPI_INT, MPI_COMM_WORLD);
    int64_t total = mpi_displacements(sc, rc, sd, rd), own = sc[me], kept = own_put ? 0 : own;
    if (own_put) { /* no room for the own items among the others' */
        for (int q = me + 1; q < np; q++) rd[q] -= (int)own;
        total -= own;
    }
    char *in = sim_realloc(NULL, (size_t)(total ? total : 1), size);
    char *out = sim_realloc(NULL, (size_t)(m - own ? m - own : 1), size); /* the others' items */
    char *own_to = in + (size_t)rd[me] * size, *gap = out + (size_t)sd[me] * size;
    size_t own0 = (size_t)rd[me] * size, own1 = own0 + (size_t)kept * size, all = (size_t)total * size;
    int64_t pieces = (int64_t)(all >> 21) + 1; /* 2 MB each */
#pragma omp parallel num_threads(nt)
    {
#pragma omp for schedule(static)
        for (int64_t k = 0; k < pieces; k++) { /* the received items' pages, not the own ones' */
            size_t a = all * (size_t)k / (size_t)pieces, b = all * (size_t)(k + 1) / (size_t)pieces;
            if (a < own0) memset(in + a, 0, (b < own0 ? b : own0) - a);
            if (b > own1) memset(in + (a > own1 ? a : own1), 0, b - (a > own1 ? a : own1));
        }
#pragma omp for schedule(static)
        for (int u = 0; u < shares; u++) { /* the counting team's shares, whatever this team's size */
            int64_t k0 = m * u / shares, k1 = m * (u + 1) / shares, *mine = at + (size_t)u * (size_t)np;
            for (int64_t k = k0; k < k1; k++) {
                int q = dest[k];
                int64_t place = mine[q]++;
                if (q == me && own_put) {
                    own_put(ctx, k, place - sd[me]);
                    continue;
                }
                /* the own items' places in out are taken out of it: those after them move down */
                char *to = q == me          ? own_to + (size_t)(place - sd[me]) * size
                           : place < sd[me] ? out + (size_t)place * size
                                            : gap + (size_t)(place - sd[me] - own) * size;
                if (pack) pack(ctx, k, to);
                else memcpy(to, (const char *)items + (size_t)k * size, size);
            }
        }
    }
    for (int q = me + 1; q < np; q++) sd[q] -= own;
    sc[me] = rc[me] = 0;
    mpi_alltoallv_into(out, sc, sd, in, rc, rd, size);
    free(out), free(sc), free(rc), free(sd), free(rd), free(at);
    *got = total;
    return in;
}

/* How many of m items go to this rank (dest[k] == mpi_me), on nt threads. */
static int64_t own_count(const int *dest, int64_t m, int nt)
{
    int64_t c = 0;
#pragma omp parallel for schedule(static) num_threads(nt) reduction(+ : c)
    for (int64_t k = 0; k < m; k++) c += dest[k] == mpi_me;
    return c;
}

/* Adds m disks to l's own. */
static void local_append(Local *l, const Disk *d, int64_t m)
{
    local_reserve(l, l->own + m);
    Slots *s = &l->s;
    int nt = pass_nt(m);
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int64_t k = 0; k < m; k++) {
        int64_t at = l->own + k;
        s->x[at] = d[k].x, s->y[at] = d[k].y, s->vx[at] = d[k].vx, s->vy[at] = d[k].vy;
        s->id[at] = (int32_t)d[k].id;
        s->pc[at] = d[k].pc, s->wc[at] = d[k].wc;
        if (l->with_wi) s->wi[at] = d[k].wi;
    }
    l->own += m;
}

/* Disks as arrays, for exchange_packed: disk k's x, y, vx, vy at k, its index idx[k] (idx NULL: id0 + k),
 * its counts and wall impulse at k where pc, wc, wi are not NULL (else 0). */
typedef struct {
    const real *x, *y, *vx, *vy;
    const int32_t *idx;
    int64_t id0;
    const int32_t *pc, *wc;
    const double *wi;
} Sources;

/* Disk k of Sources ctx as a Disk at to. */
static void pack_source(const void *ctx, int64_t k, void *to)
{
    const Sources *c = ctx;
    Disk e = {c->x[k], c->y[k], c->vx[k], c->vy[k], c->idx ? c->idx[k] : c->id0 + k, c->pc ? c->pc[k] : 0,
              c->wc ? c->wc[k] : 0, c->wi ? c->wi[k] : 0};
    memcpy(to, &e, sizeof e);
}

/* Where exchange_packed's own_put puts a rank's own disks of Sources src: by index into blk (from lo
 * on), or after l's own disks (l not NULL). */
typedef struct {
    Sources src; /* first: the context of pack_source too */
    Sim *blk;
    int64_t lo;
    Local *l;
} Put;

static void put_in_block(const void *ctx, int64_t k, int64_t place)
{
    (void)place;
    const Put *p = ctx;
    const Sources *c = &p->src;
    Sim *b = p->blk;
    int64_t at = c->idx[k] - p->lo;
    b->x[at] = c->x[k], b->y[at] = c->y[k], b->vx[at] = c->vx[k], b->vy[at] = c->vy[k];
    b->pc[at] = c->pc[k], b->wc[at] = c->wc[k];
    if (b->wi) b->wi[at] = c->wi[k];
}

static void put_in_local(const void *ctx, int64_t k, int64_t place)
{
    const Put *p = ctx;
    const Sources *c = &p->src;
    Slots *s = &p->l->s;
    int64_t at = p->l->own + place;
    s->x[at] = c->x[k], s->y[at] = c->y[k], s->vx[at] = c->vx[k], s->vy[at] = c->vy[k];
    s->id[at] = (int32_t)(c->idx ? c->idx[k] : c->id0 + k);
    s->pc[at] = c->pc ? c->pc[k] : 0, s->wc[at] = c->wc ? c->wc[k] : 0;
    if (p->l->with_wi) s->wi[at] = c->wi ? c->wi[k] : 0;
}

/* Each rank's disks of its index block, from wherever they are: position k holds disk lo + k (wi
 * too where l has it). */
static void gather_block(const Params *par, const Local *l, Sim *blk, int64_t *lo, int64_t *m)
{
    int64_t n = par->n, own = l->own;
    const Slots *s = &l->s;
    int *dest = sim_realloc(NULL, (size_t)(own ? own : 1), sizeof *dest);
    int nt = pass_nt(own);
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int64_t k = 0; k < own; k++) dest[k] = block_of(n, s->id[k]);
    *lo = block_lo(n, mpi_me);
    *m = block_lo(n, mpi_me + 1) - *lo;
    if (sim_alloc(blk, *m ? *m : 1)) sim_fail("out of memory for %lld disks", (long long)*m);
    if (l->with_wi) blk->wi = sim_calloc((size_t)(*m ? *m : 1), sizeof *blk->wi);
    int64_t got, kept = own_count(dest, own, nt);
    Put put = {{s->x, s->y, s->vx, s->vy, s->id, 0, s->pc, s->wc, l->with_wi ? s->wi : NULL}, blk, *lo, NULL};
    Disk *in = exchange_packed(NULL, sizeof(Disk), dest, own, &got, pack_source, put_in_block, &put);
    free(dest);
    if (got + kept != *m)
        sim_fail("internal error: %lld disks of block %d, not %lld", (long long)(got + kept), mpi_me,
                 (long long)*m);
    nt = pass_nt(got);
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int64_t k = 0; k < got; k++) {
        int64_t at = in[k].id - *lo;
        blk->x[at] = in[k].x, blk->y[at] = in[k].y, blk->vx[at] = in[k].vx, blk->vy[at] = in[k].vy;
        blk->pc[at] = in[k].pc, blk->wc[at] = in[k].wc;
        if (blk->wi) blk->wi[at] = in[k].wi;
    }
    free(in);
}

/* ---- input --------------------------------------------------------------------------------------- */

enum { HEAD_FILE, HEAD_ROOT };

/* What rank 0 learns before the particle lines, for every rank. */
typedef struct {
    Params par;
    int64_t body, size; /* HEAD_FILE: the particle lines are bytes [body, size) of the file */
    int32_t mode;       /* HEAD_FILE: each rank reads its share; HEAD_ROOT: rank 0 holds every disk */
} Head;

/* Reads up to len bytes at off; returns the count (short at the end of the file), or -1 (errno). */
static int64_t read_at(int fd, char *buf, size_t len, int64_t off)
{
    size_t done = 0;
    while (done < len) {
        ssize_t got = pread(fd, buf + done, len - done, (off_t)(off + (int64_t)done));
        if (got < 0 && errno == EINTR) continue;
        if (got < 0) return -1;
        if (got == 0) break;
        done += (size_t)got;
    }
    return (int64_t)done;
}

/* read_at on the rank's threads, in pieces of 16 MB at least: one thread's copies out of the page
 * cache, and the faults of buf's fresh pages, ran at a fraction of the memory's speed. */
static int64_t read_at_threads(int fd, char *buf, size_t len, int64_t off)
{
    int64_t pieces = (int64_t)(len >> 24) + 1, got = 0, bad = 0;
    int nt = pieces < pass_threads ? (int)pieces : pass_threads;
#pragma omp parallel for schedule(static) num_threads(nt) reduction(+ : got, bad)
    for (int64_t k = 0; k < pieces; k++) {
        size_t a = len * (size_t)k / (size_t)pieces, b = len * (size_t)(k + 1) / (size_t)pieces;
        int64_t r = read_at(fd, buf + a, b - a, off + (int64_t)a);
        if (r < 0) bad++;
        else got += r;
    }
    return bad ? -1 : got; /* short only at the end of the file, where the last pieces stop */
}

/* Rank 0: the header of the regular file fd, from as much of the file's start as holds it whole. */
static void read_head(const Options *opt, int fd, Head *h)
{
    size_t cap = HEAD_BYTES, got = 0, span = 0;
    char *buf = NULL;
    for (;;) {
        buf = sim_realloc(buf, cap + 1, 1);
        int64_t r = read_at(fd, buf + got, cap - got, (int64_t)got);
        if (r < 0) sim_fail("%s: cannot read the input (%s)", opt->label, strerror(errno));
        got += (size_t)r;
        span = io_header_span(buf, got);
        if (span || got < cap) break; /* whole, or the whole file */
        cap *= 2;
    }
    size_t body;
    long body_line;
    h->par.periodic = opt->periodic;
    io_read_header(opt->label, buf, span ? span : got, &h->par, &body, &body_line);
    h->body = (int64_t)body;
    free(buf);
}

/* Every rank but rank 0 after bad input: rank 0 prints seq's message (io.c's reader finds it again) and
 * exits, which ends the job; the others wait for it in a barrier it never joins. */
static void input_failed(const Options *opt)
{
    if (mpi_me == 0) {
        Params p;
        Sim all;
        io_read_input(opt, &p, &all);
        sim_fail("%s: the input changed while it was read", opt->label);
    }
    MPI_Barrier(MPI_COMM_WORLD);
    exit(1);
}

double mpi_input_seconds[INPUT_PHASES];

/* This rank's share of the particle lines: the lines that start in [a, b) of the file, where a and b
 * cut [body, size) in np parts. Returns the buffer (NULL: no lines) and sets *text, *len to the lines
 * (text[len] writable), or sets *err to an errno. */
static char *read_share(const Options *opt, const Head *h, char **text, size_t *len, int *err)
{
    int64_t span = h->size - h->body, np = mpi_np, me = mpi_me;
    int64_t a = h->body + span / np * me + span % np * me / np;
    int64_t b = h->body + span / np * (me + 1) + span % np * (me + 1) / np;
    *text = NULL, *len = 0, *err = 0;
    if (a >= b) return NULL;
    int fd = open(opt->path, O_RDONLY);
    if (fd < 0) {
        *err = errno;
        return NULL;
    }
    /* from the byte before a, which says whether a line starts at a */
    int64_t lo = a > h->body ? a - 1 : a, cap = b - lo, got;
    char *buf = sim_realloc(NULL, (size_t)cap + 1, 1);
    if ((got = read_at_threads(fd, buf, (size_t)cap, lo)) < 0) goto fail;
    int64_t s = a; /* the first line start >= a */
    if (a > h->body) {
        char *nl = memchr(buf, '\n', (size_t)got);
        s = nl ? lo + (nl - buf) + 1 : b;
    }
    if (s >= b) { /* no line starts in [a, b) */
        close(fd);
        free(buf);
        return NULL;
    }
    /* the lines end before the first line start >= b: after the first newline from b - 1 on */
    int64_t from = b - 1 - lo, e = -1;
    for (;;) {
        char *nl = from < got ? memchr(buf + from, '\n', (size_t)(got - from)) : NULL;
        if (nl) {
            e = lo + (nl - buf) + 1;
            break;
        }
        if (got < cap) { /* the end of the file */
            e = lo + got;
            break;
        }
        from = got;
        int64_t more = cap < HEAD_BYTES ? HEAD_BYTES : cap;
        buf = sim_realloc(buf, (size_t)(cap + more) + 1, 1);
        int64_t r = read_at(fd, buf + cap, (size_t)more, lo + cap);
        if (r < 0) goto fail;
        got = cap + r;
        cap += more;
    }
    close(fd);
    *text = buf + (s - lo);
    *len = (size_t)(e - s);
    return buf;
fail:
    *err = errno ? errno : EIO;
    close(fd);
    free(buf);
    return NULL;
}

/* Every rank's m disks d (of the whole state, in any order) to the ranks of their strips, the cuts
 * placed at equal counts of disks first. Each disk is packed from d's arrays straight into the
 * exchange's buffers: with a copy of them as Disks first, mpi's whole process on a gas of 1e7 disks
 * took 4.88 s against 4.45 on a rank of 2 threads, 4.44 against 4.29 on 2 ranks (medians, 2-core
 * EPYC, bench/io_mpi_epyc.log). */
static void to_strips(const Params *par, const Sources *d, int64_t m, Local *l)
{
    int nt = pass_nt(m);
    int64_t bins = mpi_cut_bins();
    double *hist = sim_calloc((size_t)bins * (size_t)nt, sizeof *hist); /* a histogram a thread, then summed */
#pragma omp parallel num_threads(nt)
    {
        int t = omp_get_thread_num(), w = omp_get_num_threads();
        double *mine = hist + (size_t)bins * (size_t)t;
        for (int64_t k = m * t / w; k < m * (t + 1) / w; k++) mpi_cut_add(mine, d->x[k], par->L, 1);
    }
    for (int t = 1; t < nt; t++) /* counts: exact in any order */
        for (int64_t b = 0; b < bins; b++) hist[b] += hist[(size_t)bins * (size_t)t + (size_t)b];
    mpi_place_cuts(hist, (double)m, par->L, 0);
    free(hist);
    int *dest = sim_realloc(NULL, (size_t)(m ? m : 1), sizeof *dest);
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int64_t k = 0; k < m; k++) dest[k] = mpi_owner(d->x[k]);
    int64_t got, kept = own_count(dest, m, nt);
    local_reserve(l, l->own + kept);
    Put put = {*d, NULL, 0, l};
    Disk *mine = exchange_packed(NULL, sizeof(Disk), dest, m, &got, pack_source, put_in_local, &put);
    free(dest);
    l->own += kept;
    local_append(l, mine, got);
    free(mine);
}

/* The piece's records (its lines but blank ones) moved to its first lines, in order; returns their count.
 * A record moves only down, so one pass in order does it, from the first blank line on (usually none, or
 * only at the end). */
static int64_t piece_records(IoPiece *pc)
{
    int64_t k = 0, m;
    while (k < pc->lines && pc->idx[k] >= 0) k++;
    for (m = k; k < pc->lines; k++) {
        if (pc->idx[k] < 0) continue;
        Sim *s = &pc->disks;
        s->x[m] = s->x[k], s->y[m] = s->y[k], s->vx[m] = s->vx[k], s->vy[m] = s->vy[k];
        pc->idx[m++] = pc->idx[k];
    }
    return m;
}

/* A regular file, every rank its share: parsed, checked together (record count, then duplicates at
 * the index blocks' ranks), and sent to the strips' ranks. Returns 0, or 1 where the input lists no
 * disks (random placement). */
static int read_particles(const Options *opt, const Head *h, const Params *par, Local *l)
{
    char *text;
    size_t len;
    int err;
    double *sec = mpi_input_seconds, t = sim_clock();
    char *buf = read_share(opt, h, &text, &len, &err);
    sec[INPUT_READ] = sim_clock() - t;
    IoPiece pc;
    memset(&pc, 0, sizeof pc);
    t = sim_clock();
    if (buf) io_parse_piece(par, text, len, opt->threads, &pc);
    free(buf);
    int64_t records = pc.bad ? 0 : piece_records(&pc);
    sec[INPUT_PARSE] = sim_clock() - t;
    int64_t mine[3] = {err, pc.bad, records}, all[3];
    MPI_Allreduce(mine, all, 3, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD); /* waits for the slowest rank */
    t = sim_clock();
    if (all[0]) {
        int64_t worst;
        MPI_Allreduce(&mine[0], &worst, 1, MPI_INT64_T, MPI_MAX, MPI_COMM_WORLD);
        if (mpi_me == 0)
            sim_fail("%s: cannot read the input on every rank (%s)", opt->label, strerror((int)worst));
        MPI_Barrier(MPI_COMM_WORLD);
        exit(1);
    }
    if (all[1] || (all[2] && all[2] != par->n)) input_failed(opt);
    if (!all[2]) {
        io_piece_free(&pc);
        return 1;
    }

    /* each index once: rank q marks the indices of its block */
    int64_t n = par->n, got;
    const int32_t *ids = pc.idx;
    int *dest = sim_realloc(NULL, (size_t)records, sizeof *dest);
    int nt = pass_nt(records);
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int64_t k = 0; k < records; k++) dest[k] = block_of(n, ids[k]);
    int32_t *in = exchange(ids, sizeof *ids, dest, records, &got);
    int64_t lo = block_lo(n, mpi_me);
    uint64_t *have = sim_calloc((size_t)((block_lo(n, mpi_me + 1) - lo) / 64 + 1), sizeof *have);
    int dup = 0;
    nt = pass_nt(got);
#pragma omp parallel for schedule(static) num_threads(nt) reduction(| : dup)
    for (int64_t k = 0; k < got; k++) {
        int64_t i = in[k] - lo;
        uint64_t bit = (uint64_t)1 << (i % 64), old;
#pragma omp atomic capture
        {
            old = have[i / 64];
            have[i / 64] |= bit;
        }
        dup |= (old & bit) != 0;
    }
    free(have), free(in);
    int any;
    MPI_Allreduce(&dup, &any, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    if (any) input_failed(opt);

    free(dest);
    sec[INPUT_CHECK] = sim_clock() - t;
    t = sim_clock();
    const Sim *p = &pc.disks;
    Sources src = {p->x, p->y, p->vx, p->vy, pc.idx, 0, NULL, NULL, NULL};
    to_strips(par, &src, records, l);
    io_piece_free(&pc);
    sec[INPUT_STRIPS] = sim_clock() - t;
    return 0;
}

/* Rank 0 holds every disk (all; the other ranks NULL) and sends each to its strip's rank, a round of
 * SCATTER_DISKS at a time. */
static void scatter(const Params *par, const Sim *all, Local *l)
{
    int np = mpi_np;
    double *h = sim_calloc((size_t)mpi_cut_bins(), sizeof *h); /* the cuts at equal counts of disks */
    if (mpi_me == 0)
        for (int64_t i = 0; i < par->n; i++) mpi_cut_add(h, all->x[i], par->L, 1);
    mpi_place_cuts(h, (double)(mpi_me == 0 ? par->n : 0), par->L, 0);
    free(h);
    int *count = sim_calloc((size_t)np, sizeof *count), *displ = sim_calloc((size_t)np, sizeof *displ);
    int *dest = NULL;
    Disk *d = NULL;
    Sources src = {all->x, all->y, all->vx, all->vy, NULL, 0, NULL, NULL, NULL}; /* rank 0's */
    if (mpi_me == 0) {
        dest = sim_realloc(NULL, SCATTER_DISKS, sizeof *dest);
        d = sim_realloc(NULL, SCATTER_DISKS, sizeof *d);
    }
    MPI_Datatype t;
    MPI_Type_contiguous((int)sizeof(Disk), MPI_BYTE, &t);
    MPI_Type_commit(&t);
    for (int64_t first = 0; first < par->n; first += SCATTER_DISKS) {
        int64_t m = par->n - first < SCATTER_DISKS ? par->n - first : SCATTER_DISKS;
        if (mpi_me == 0) {
            memset(count, 0, (size_t)np * sizeof *count);
            for (int64_t k = 0; k < m; k++) count[dest[k] = mpi_owner(all->x[first + k])]++;
            for (int q = 1; q < np; q++) displ[q] = displ[q - 1] + count[q - 1];
            for (int64_t k = 0; k < m; k++) pack_source(&src, first + k, &d[displ[dest[k]]++]);
            for (int q = 0; q < np; q++) displ[q] -= count[q];
        }
        int got;
        MPI_Scatter(count, 1, MPI_INT, &got, 1, MPI_INT, 0, MPI_COMM_WORLD);
        Disk *in = sim_realloc(NULL, (size_t)got, sizeof *in);
        MPI_Scatterv(d, count, displ, t, in, got, t, 0, MPI_COMM_WORLD);
        local_append(l, in, got);
        free(in);
    }
    MPI_Type_free(&t);
    free(count), free(displ), free(dest), free(d);
}

void mpi_read_input(const Options *opt, Params *par, Local *l)
{
    pass_threads = opt->threads > 0 ? opt->threads : 1;
    Head h;
    memset(&h, 0, sizeof h);
    Sim all; /* HEAD_ROOT: the whole state, on rank 0 only */
    memset(&all, 0, sizeof all);
    if (mpi_me == 0) {
        struct stat st;
        int fd = strcmp(opt->path, "-") == 0 ? -1 : open(opt->path, O_RDONLY);
        if (fd >= 0 && fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) {
            h.mode = HEAD_FILE;
            h.size = (int64_t)st.st_size;
            read_head(opt, fd, &h);
        } else {
            /* standard input, a pipe, or what cannot be opened: io.c reads it whole or says why not */
            h.mode = HEAD_ROOT;
            io_read_input(opt, &h.par, &all);
        }
        if (fd >= 0) close(fd);
    }
    MPI_Bcast(&h, (int)sizeof h, MPI_BYTE, 0, MPI_COMM_WORLD);
    *par = h.par;
    par->substeps = opt->substeps;
    par->first_step = 0;
    l->own = l->halo = 0;
    if (h.mode == HEAD_FILE && read_particles(opt, &h, par, l)) {
        /* no particle lines: rank 0 places the disks as io.c does (and says so) */
        h.mode = HEAD_ROOT;
        if (mpi_me == 0) {
            Params p;
            io_read_input(opt, &p, &all);
        }
    }
    if (h.mode == HEAD_ROOT) {
        memset(mpi_input_seconds, 0, sizeof mpi_input_seconds);
        scatter(par, &all, l); /* the one case where rank 0 holds the whole state */
        sim_free(&all);
    }
}

/* ---- output ----------------------------------------------------------------------------------------- */

static int out_fd = -1;     /* --output's file, on every rank; -1: rank 0's stdout */
static int64_t out_size;    /* its bytes so far (the same on every rank) */

void mpi_output_file(const char *path)
{
    int err = 0;
    if (mpi_me == 0) {
        int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0666);
        if (fd < 0) sim_fail("%s: cannot create the output (%s)", path, strerror(errno));
        close(fd);
    }
    MPI_Barrier(MPI_COMM_WORLD);
    out_fd = open(path, O_WRONLY);
    if (out_fd < 0) err = errno;
    int worst;
    MPI_Allreduce(&err, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    if (worst) {
        if (mpi_me == 0) sim_fail("%s: cannot open the output on every rank (%s)", path, strerror(worst));
        MPI_Barrier(MPI_COMM_WORLD); /* rank 0 never joins: mpirun ends the job */
    }
}

/* This rank's pieces t[0, pieces) into the output file at its offset among the ranks' lines. */
static void write_at_offset(const TextBlock *t, int64_t pieces)
{
    int64_t mine = 0, before = 0, all;
    for (int64_t k = 0; k < pieces; k++) mine += (int64_t)t[k].len;
    MPI_Exscan(&mine, &before, 1, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD);
    if (mpi_me == 0) before = 0; /* MPI_Exscan leaves rank 0's undefined */
    int64_t at = out_size + before;
    for (int64_t k = 0; k < pieces; k++) {
        for (size_t done = 0; done < t[k].len;) {
            ssize_t w = pwrite(out_fd, t[k].buf + done, t[k].len - done, (off_t)at);
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0) sim_fail("cannot write the output (%s)", w < 0 ? strerror(errno) : "no progress");
            done += (size_t)w;
            at += w;
        }
    }
    MPI_Allreduce(&mine, &all, 1, MPI_INT64_T, MPI_SUM, MPI_COMM_WORLD);
    out_size += all;
}

typedef struct {
    TextBlock *t;
    const Sim *blk;
    int64_t step, lo, m;
    int with_counts, dump17;
} Format;

static void format_task(void *ctx, int64_t k)
{
    Format *f = ctx;
    int64_t from = k * TEXT_PIECE, to = from + TEXT_PIECE < f->m ? from + TEXT_PIECE : f->m;
    io_format_block(&f->t[k], f->step, f->blk, from, to, f->lo, f->with_counts, f->dump17);
}

void mpi_write_state(Output *out, const Params *par, const Local *l, int64_t step, int with_counts)
{
    int how[2] = {0, 0}; /* rank 0's --dump17 and --threads */
    if (mpi_me == 0) how[0] = io_dump17(out), how[1] = io_threads(out);
    MPI_Bcast(how, 2, MPI_INT, 0, MPI_COMM_WORLD);
    Sim blk;
    int64_t lo, m;
    gather_block(par, l, &blk, &lo, &m);
    int64_t pieces = (m + TEXT_PIECE - 1) / TEXT_PIECE;
    Format f = {sim_calloc((size_t)pieces, sizeof(TextBlock)), &blk, step, lo, m, with_counts, how[0]};
    mpi_parallel(how[1], pieces, format_task, &f);
    sim_free(&blk);
    if (out_fd >= 0) {
        write_at_offset(f.t, pieces);
        for (int64_t k = 0; k < pieces; k++) free(f.t[k].buf);
        free(f.t);
        return;
    }
    for (int64_t k = 0; k < pieces; k++) {
        if (mpi_me == 0) io_write_bytes(out, f.t[k].buf, f.t[k].len);
        else MPI_Send(f.t[k].buf, (int)f.t[k].len, MPI_CHAR, 0, TAG_TEXT, MPI_COMM_WORLD);
        free(f.t[k].buf);
    }
    free(f.t);
    if (mpi_me != 0) return;
    /* the other blocks in rank order, a piece at a time */
    char *buf = NULL;
    size_t cap = 0;
    for (int q = 1; q < mpi_np; q++) {
        int64_t qm = block_lo(par->n, q + 1) - block_lo(par->n, q);
        for (int64_t k = 0; k < (qm + TEXT_PIECE - 1) / TEXT_PIECE; k++) {
            MPI_Status st;
            int len;
            MPI_Probe(q, TAG_TEXT, MPI_COMM_WORLD, &st);
            MPI_Get_count(&st, MPI_CHAR, &len);
            if ((size_t)len + 1 > cap) {
                cap = (size_t)len + 1;
                free(buf);
                buf = sim_realloc(NULL, cap, 1);
            }
            MPI_Recv(buf, len, MPI_CHAR, q, TAG_TEXT, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
            io_write_bytes(out, buf, (size_t)len);
        }
    }
    free(buf);
}

void mpi_index_sums(const Params *par, const Local *l, double *w, double *k)
{
    typedef struct {
        int64_t id;
        double wi, v2;
    } Term;
    int64_t n = par->n, own = l->own, got;
    Term *t = sim_realloc(NULL, (size_t)own, sizeof *t);
    int *dest = sim_realloc(NULL, (size_t)own, sizeof *dest);
    for (int64_t q = 0; q < own; q++) {
        double vx = l->s.vx[q], vy = l->s.vy[q];
        t[q].id = l->s.id[q];
        t[q].wi = l->s.wi ? l->s.wi[q] : 0;
        t[q].v2 = vx * vx + vy * vy;
        dest[q] = block_of(n, t[q].id);
    }
    Term *in = exchange(t, sizeof *t, dest, own, &got);
    free(t), free(dest);
    int64_t lo = block_lo(n, mpi_me);
    double *blk = sim_realloc(NULL, 2 * (size_t)(got ? got : 1), sizeof *blk);
    for (int64_t q = 0; q < got; q++) blk[2 * (in[q].id - lo)] = in[q].wi, blk[2 * (in[q].id - lo) + 1] = in[q].v2;
    free(in);
    if (got != block_lo(n, mpi_me + 1) - lo)
        sim_fail("internal error: %lld terms of block %d", (long long)got, mpi_me);
    /* seq's loop over the indices, passed along the blocks: rank 0, 1, ..., np - 1, back to 0 */
    double sum[2] = {0, 0};
    if (mpi_me > 0) MPI_Recv(sum, 2, MPI_DOUBLE, mpi_me - 1, TAG_SUM, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    for (int64_t q = 0; q < got; q++) sum[0] += blk[2 * q], sum[1] += blk[2 * q + 1];
    free(blk);
    if (mpi_np > 1) {
        MPI_Send(sum, 2, MPI_DOUBLE, (mpi_me + 1) % mpi_np, TAG_SUM, MPI_COMM_WORLD);
        if (mpi_me == 0) MPI_Recv(sum, 2, MPI_DOUBLE, mpi_np - 1, TAG_SUM, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    }
    *w = mpi_me == 0 ? sum[0] : 0;
    *k = mpi_me == 0 ? sum[1] : 0;
}

/* ---- checkpoints ------------------------------------------------------------------------------------ */

void mpi_checkpoint(Output *out, const Params *par, const Options *opt, const Local *l, int64_t step)
{
    Sim blk;
    int64_t lo, m;
    gather_block(par, l, &blk, &lo, &m);
    /* rank 0's stdout is flushed through this step (with --output every rank's lines are in the file
     * already: write_at_offset writes them before it returns) and FILE.tmp holds the header */
    if (mpi_me == 0) io_checkpoint_begin(out, step, l->with_wi);
    MPI_Barrier(MPI_COMM_WORLD);
    io_checkpoint_part(opt, par, &blk, lo, m);
    sim_free(&blk);
    MPI_Barrier(MPI_COMM_WORLD);
    if (mpi_me == 0) io_checkpoint_end(out, step);
}

void mpi_read_checkpoint(Options *opt, Params *par, Local *l)
{
    pass_threads = opt->threads > 0 ? opt->threads : 1;
    int32_t o[5] = {0, 0, 0, 0, 0};
    if (mpi_me == 0) {
        io_resume_check(opt, par);
        o[0] = opt->substeps, o[1] = opt->exact, o[2] = opt->pressure, o[3] = opt->periodic, o[4] = opt->dump17;
    }
    MPI_Bcast(par, (int)sizeof *par, MPI_BYTE, 0, MPI_COMM_WORLD);
    MPI_Bcast(o, 5, MPI_INT32_T, 0, MPI_COMM_WORLD);
    opt->substeps = o[0], opt->exact = o[1], opt->pressure = o[2], opt->periodic = o[3], opt->dump17 = o[4];
    l->own = l->halo = 0;
    l->with_wi = opt->pressure;
    /* each rank its index block, then the disks to their strips as after reading an input */
    int64_t n = par->n, lo = block_lo(n, mpi_me), m = block_lo(n, mpi_me + 1) - lo;
    Sim blk;
    int64_t bad = io_resume_part(opt, par, &blk, lo, m), first;
    if (bad < 0) bad = INT64_MAX;
    MPI_Allreduce(&bad, &first, 1, MPI_INT64_T, MPI_MIN, MPI_COMM_WORLD);
    if (first != INT64_MAX) { /* io.c's message, as for bad input: rank 0 says it, the job ends */
        if (mpi_me == 0) io_resume_refuse(opt, first);
        MPI_Barrier(MPI_COMM_WORLD);
        exit(1);
    }
    Sources src = {blk.x, blk.y, blk.vx, blk.vy, NULL, lo, blk.pc, blk.wc, blk.wi};
    to_strips(par, &src, m, l);
    sim_free(&blk);
}
