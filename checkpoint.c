/* checkpoint.c: --checkpoint and --resume: the whole state saved every K steps into a file that is
 * always whole (FILE.tmp synced, then renamed over FILE), and read back with every check before a
 * byte of output. A backend whose processes each hold a part of the state (mpi) writes and reads the
 * same file in parts: each its block of indices at its offsets, one process the checksum's chain.
 */
#define _POSIX_C_SOURCE 200809L

#include "io_internal.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* A checkpoint file: "DISKSCKP", format version, bytes of a real (8: double, 4: float), then the run
 * (n, L, r, S, the step reached, K, print, exact, pressure, dump17; from format 2 on also periodic and
 * the periodic box's virial sums so far), then x, y, vx, vy (velocities per step, as in the output),
 * the counts p and w, the wall (or virial) impulses (with --pressure), the partners of the disks' last
 * events (--exact), and a checksum of everything before it. Native byte order: it is read back by the
 * same programs on the same kind of machine. Format 1 (no periodic box) is still read. */
#define CK_MAGIC "DISKSCKP"
#define CK_VERSION 2u

typedef struct {
    char magic[8];
    uint32_t version, real_bytes;
    int64_t n, steps, step, substeps;
    double L, r;
    int32_t print, exact, pressure, dump17;
} CkHeader1; /* format 1, the start of every later one */

typedef struct {
    CkHeader1 h;
    int32_t periodic, pad;
    Virial virial;
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
    const char *err = output_write_fd(w->fd, w->buf, w->len);
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

int io_checkpoint_at(const Params *par, const Options *opt, int64_t step)
{
    return opt->checkpoint && step % opt->checkpoint_every == 0 && step > par->first_step && step < par->steps;
}

int io_checkpoint_due(const Output *out, int64_t step)
{
    return io_checkpoint_at(out->par, out->opt, step);
}

int64_t io_checkpoint_next(const Output *out, int64_t step)
{
    if (!out->ck_path) return 0;
    int64_t due = (step + out->ck_every - 1) / out->ck_every * out->ck_every;
    while (due <= out->first) due += out->ck_every;
    return io_checkpoint_due(out, due) ? due : 0;
}

/* The header of the checkpoint of step `step` (pressure: the state holds wall or virial impulses). */
static void ck_header(const Output *out, int64_t step, int pressure, CkHeader *hd)
{
    const Params *par = out->par;
    CkHeader1 *h = &hd->h;
    memset(hd, 0, sizeof *hd);
    memcpy(h->magic, CK_MAGIC, 8);
    h->version = CK_VERSION;
    h->real_bytes = (uint32_t)sizeof(real);
    h->n = par->n, h->steps = par->steps, h->step = step, h->substeps = par->substeps;
    h->L = (double)par->L, h->r = (double)par->r;
    h->print = par->print, h->exact = out->opt->exact, h->pressure = pressure, h->dump17 = out->dump17;
    hd->periodic = par->periodic;
    hd->virial = out->virial;
}

/* fd, FILE.tmp whole (checksum included), synced and closed, renamed over FILE; the directory synced
 * too, so that the rename itself survives a crash. t0: when the checkpoint began (--stats). */
static void ck_commit(Output *out, int fd, const char *tmp, int64_t step, uint64_t bytes, double t0)
{
    if (fsync(fd) != 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    close(fd);
    if (rename(tmp, out->ck_path) != 0)
        sim_fail("cannot replace the checkpoint %s: %s", out->ck_path, strerror(errno));
    size_t plen = strlen(out->ck_path);
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
    out->ck_count++;
    out->ck_step = step;
    out->ck_bytes += bytes;
    out->ck_s += sim_clock() - t0;
}

void io_checkpoint(Output *out, const Sim *sim, int64_t step)
{
    output_flush(out); /* stdout holds every line through this step before the checkpoint says so */
    double t0 = sim_clock();
    const Params *par = out->par;
    char *tmp = ck_tmp_name(out->ck_path);
    CkWriter *w = sim_calloc(1, sizeof *w);
    w->path = tmp;
    w->fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (w->fd < 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    CkHeader hd;
    ck_header(out, step, sim->wi != NULL, &hd);
    ck_put(w, &hd, sizeof hd);
    ck_put_reals(w, sim->x, par->n, 1);
    ck_put_reals(w, sim->y, par->n, 1);
    ck_put_reals(w, sim->vx, par->n, io_velocity_scale());
    ck_put_reals(w, sim->vy, par->n, io_velocity_scale());
    ck_put(w, sim->pc, (size_t)par->n * sizeof *sim->pc);
    ck_put(w, sim->wc, (size_t)par->n * sizeof *sim->wc);
    if (sim->wi) ck_put(w, sim->wi, (size_t)par->n * sizeof *sim->wi);
    if (hd.h.exact) ck_put(w, sim->last, (size_t)par->n * sizeof *sim->last);
    uint64_t hash = ck_hash_end(&w->hash);
    ck_put(w, &hash, sizeof hash);
    ck_flush(w);
    ck_commit(out, w->fd, tmp, step, w->bytes, t0);
    free(tmp);
    free(w);
}

/* ---- a checkpoint written in parts (mpi: each process its block of indices) ------------------------ */

/* The arrays of a checkpoint in file order, their bytes per disk; NULL where the file has none. */
#define CK_ARRAYS 8
static void ck_arrays(const Sim *s, void *a[CK_ARRAYS], size_t size[CK_ARRAYS])
{
    void *arrays[CK_ARRAYS] = {s->x, s->y, s->vx, s->vy, s->pc, s->wc, s->wi, s->last};
    size_t sizes[CK_ARRAYS] = {sizeof(real), sizeof(real), sizeof(real), sizeof(real), 4, 4, 8, 4};
    memcpy(a, arrays, sizeof arrays);
    memcpy(size, sizes, sizeof sizes);
}

/* Transfers len bytes at off of fd (pwrite when out, else pread); NULL, or what went wrong. */
static const char *ck_transfer(int fd, void *bytes, size_t len, uint64_t off, int out)
{
    char *b = bytes;
    while (len) {
        ssize_t got = out ? pwrite(fd, b, len, (off_t)off) : pread(fd, b, len, (off_t)off);
        if (got < 0 && errno == EINTR) continue;
        if (got < 0) return strerror(errno);
        if (got == 0) return out ? "no progress" : "cut short";
        b += got, len -= (size_t)got, off += (uint64_t)got;
    }
    return NULL;
}

void io_checkpoint_begin(Output *out, int64_t step, int pressure)
{
    output_flush(out);
    out->ck_t0 = sim_clock();
    char *tmp = ck_tmp_name(out->ck_path);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    CkHeader hd;
    ck_header(out, step, pressure, &hd);
    const char *err = ck_transfer(fd, &hd, sizeof hd, 0, 1);
    if (err) sim_fail("cannot write the checkpoint %s: %s", tmp, err);
    close(fd);
    free(tmp);
}

void io_checkpoint_part(const Options *opt, const Params *par, const Sim *blk, int64_t lo, int64_t m)
{
    char *tmp = ck_tmp_name(opt->checkpoint);
    int fd = open(tmp, O_WRONLY);
    if (fd < 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    void *a[CK_ARRAYS];
    size_t size[CK_ARRAYS];
    ck_arrays(blk, a, size);
    uint64_t n = (uint64_t)par->n, at = sizeof(CkHeader);
    real f = io_velocity_scale(), chunk[1024];
    for (int k = 0; k < CK_ARRAYS; k++) {
        if (!a[k] || (k == 6 && !opt->pressure) || (k == 7 && !opt->exact)) continue;
        const char *err = NULL;
        uint64_t off = at + (uint64_t)lo * size[k];
        if (k == 2 || k == 3) { /* velocities per step, as ck_put_reals writes them */
            const real *v = a[k];
            for (int64_t i = 0; i < m && !err; i += 1024) {
                int64_t c = m - i < 1024 ? m - i : 1024;
                for (int64_t j = 0; j < c; j++) chunk[j] = v[i + j] * f;
                err = ck_transfer(fd, chunk, (size_t)c * sizeof(real), off + (uint64_t)i * sizeof(real), 1);
            }
        } else {
            err = ck_transfer(fd, a[k], (size_t)m * size[k], off, 1);
        }
        if (err) sim_fail("cannot write the checkpoint %s: %s", tmp, err);
        at += n * size[k];
    }
    /* every part on disk before the checksum is taken (another machine's writes included) */
    if (fsync(fd) != 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    close(fd);
    free(tmp);
}

void io_checkpoint_end(Output *out, int64_t step)
{
    char *tmp = ck_tmp_name(out->ck_path);
    int fd = open(tmp, O_RDWR);
    if (fd < 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    /* the file's bytes in order, through the one chain of ck_hash */
    uint64_t len = (uint64_t)st.st_size, off = 0;
    CkHash hash = {0, {0}, 0};
    char *buf = sim_calloc(1, 1 << 20);
    while (off < len) {
        size_t part = len - off < (1u << 20) ? (size_t)(len - off) : (1u << 20);
        const char *err = ck_transfer(fd, buf, part, off, 0);
        if (err) sim_fail("cannot read back the checkpoint %s: %s", tmp, err);
        ck_hash(&hash, buf, part);
        off += part;
    }
    free(buf);
    uint64_t h = ck_hash_end(&hash);
    const char *err = ck_transfer(fd, &h, sizeof h, len, 1);
    if (err) sim_fail("cannot write the checkpoint %s: %s", tmp, err);
    ck_commit(out, fd, tmp, step, len + sizeof h, out->ck_t0);
    free(tmp);
}

/* --checkpoint FILE is tried before the run starts: a run of hours should not learn at its first
 * checkpoint that FILE cannot be written. */
void io_checkpoint_probe(const char *path)
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

/* ---- --resume --------------------------------------------------------------------------------------- */

/* Opens the checkpoint opt->resume and checks what needs no pass over its state: the header, the
 * file's size, what the backend supports. Returns the descriptor, positioned after the header. */
static int ck_open(const char *path, CkHeader *hd, size_t *hsize)
{
    int fd = open(path, O_RDONLY);
    if (fd < 0) sim_fail("%s: cannot open the checkpoint (%s)", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) sim_fail("%s: not a checkpoint (not a regular file)", path);
    CkHeader1 h;
    memset(hd, 0, sizeof *hd);
    if (read(fd, &h, sizeof h) != (ssize_t)sizeof h || memcmp(h.magic, CK_MAGIC, 8) != 0)
        sim_fail("%s: not a checkpoint (it does not start with %s)", path, CK_MAGIC);
    if (h.version != CK_VERSION && h.version != 1)
        sim_fail("%s: a checkpoint of format %u; this program reads formats 1 and %u", path, h.version, CK_VERSION);
    *hsize = h.version == 1 ? sizeof h : sizeof *hd; /* format 1: no periodic box */
    hd->h = h;
    if (*hsize > sizeof h &&
        read(fd, (char *)hd + sizeof h, *hsize - sizeof h) != (ssize_t)(*hsize - sizeof h))
        sim_fail("%s: a checkpoint cut short in its header", path);
    if (h.real_bytes != sizeof(real))
        sim_fail("%s: a checkpoint of %s precision; %s computes in %s", path, h.real_bytes == 8 ? "double" : "single",
                sim_program, sizeof(real) == 8 ? "double" : "single");
    if (h.n < 1 || h.n > SIM_MAX_N || h.steps < 0 || h.step < 1 || h.step >= h.steps || h.substeps < 1 ||
        h.substeps > 1024 || (h.substeps & (h.substeps - 1)) || !(h.L > 0) || !(h.r > 0) ||
        (hd->periodic != 0 && hd->periodic != 1))
        sim_fail("%s: a checkpoint with impossible values (N = %lld, step %lld of %lld, K = %lld)", path,
                (long long)h.n, (long long)h.step, (long long)h.steps, (long long)h.substeps);
    uint64_t n = (uint64_t)h.n;
    uint64_t want = *hsize + n * (4 * sizeof(real) + 2 * sizeof(int32_t)) + (h.pressure ? n * sizeof(double) : 0) +
                    (h.exact ? n * sizeof(int32_t) : 0) + 8;
    if ((uint64_t)st.st_size != want)
        sim_fail("%s: a checkpoint of %lld bytes, where its header calls for %llu (cut short or extended)", path,
                (long long)st.st_size, (unsigned long long)want);
    if (h.exact && !(io_backend->features & SIM_FEATURE_EXACT))
        sim_fail("%s: a checkpoint of an --exact run, which %s does not support", path, sim_program);
    if (h.pressure && !(io_backend->features & SIM_FEATURE_PRESSURE))
        sim_fail("%s: a checkpoint of a --pressure run, which %s does not support", path, sim_program);
    if (h.substeps > 1 && !(io_backend->features & SIM_FEATURE_SUBSTEPS))
        sim_fail("%s: a checkpoint of a --substeps run, which %s does not support", path, sim_program);
    if (hd->periodic && !(io_backend->features & SIM_FEATURE_PERIODIC))
        sim_fail("%s: a checkpoint of a --periodic run, which %s does not support", path, sim_program);
    return fd;
}

/* The first of disks [0, m) of s (disk base + k at position k) whose centre SPEC.md 1 or, in the
 * periodic box, 7 does not allow or whose counts are impossible, as a disk index; -1 if none. */
static int64_t ck_bad_disk(const CkHeader *hd, const Sim *s, int64_t base, int64_t m)
{
    const CkHeader1 *h = &hd->h;
    real lo = hd->periodic ? 0 : (real)h->r, hi = hd->periodic ? (real)h->L : (real)h->L - (real)h->r;
    for (int64_t k = 0; k < m; k++)
        if (!(s->x[k] >= lo && s->y[k] >= lo && (hd->periodic ? s->x[k] < hi && s->y[k] < hi
                                                              : s->x[k] <= hi && s->y[k] <= hi) &&
              s->pc[k] >= 0 && s->wc[k] >= 0 &&
              (!s->last || (s->last[k] >= -1 && s->last[k] < h->n && s->last[k] != base + k))))
            return base + k;
    return -1;
}

static void ck_refuse_disk(const char *path, int64_t i)
{
    sim_fail("%s: disk %lld of the checkpoint is outside the box or has impossible counts", path, (long long)i);
}

/* The run of a checked header into par and opt: the options that shape the dynamics (K, exact,
 * pressure, periodic) and the output (print, dump17) come from the checkpoint. */
static void ck_apply(const CkHeader *hd, Options *opt, Params *par)
{
    const CkHeader1 *h = &hd->h;
    par->n = h->n;
    par->L = (real)h->L;
    par->r = (real)h->r;
    par->steps = h->steps;
    par->print = h->print;
    par->periodic = hd->periodic;
    params_derive(par);
    par->first_step = h->step;
    opt->substeps = (int)h->substeps;
    opt->exact = h->exact;
    opt->pressure = h->pressure;
    opt->periodic = hd->periodic;
    opt->dump17 = h->dump17;
}

static void ck_said(const Options *opt, const CkHeader *hd)
{
    if (!opt->quiet)
        fprintf(stderr, "%s: resuming %s at step %lld of %lld\n", sim_program, opt->resume, (long long)hd->h.step,
                (long long)hd->h.steps);
}

/* The run and the state of a checkpoint, for --resume: anything wrong with the file is refused before
 * a byte of output. */
void checkpoint_read(Options *opt, Params *par, Sim *sim, Virial *vir)
{
    const char *path = opt->resume;
    CkHeader hd;
    size_t hsize;
    int fd = ck_open(path, &hd, &hsize);
    const CkHeader1 *h = &hd.h;
    uint64_t n = (uint64_t)h->n;
    if (sim_alloc(sim, h->n)) sim_fail("%s: not enough memory for the particles (N = %lld)", path, (long long)h->n);
    if (h->pressure) sim->wi = sim_calloc(n, sizeof *sim->wi);
    if (h->exact) sim->last = sim_calloc(n, sizeof *sim->last);
    CkHash hash = {0, {0}, 0};
    ck_hash(&hash, &hd, hsize);
    void *arrays[CK_ARRAYS];
    size_t sizes[CK_ARRAYS];
    ck_arrays(sim, arrays, sizes);
    for (int a = 0; a < CK_ARRAYS; a++) {
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
    int64_t bad = ck_bad_disk(&hd, sim, 0, h->n);
    if (bad >= 0) ck_refuse_disk(path, bad);
    ck_apply(&hd, opt, par);
    *vir = hd.virial;
    ck_said(opt, &hd);
}

void io_resume_check(Options *opt, Params *par)
{
    const char *path = opt->resume;
    CkHeader hd;
    size_t hsize;
    int fd = ck_open(path, &hd, &hsize);
    /* the checksum's chain over the file in order, a MB at a time */
    uint64_t left = (uint64_t)lseek(fd, 0, SEEK_END) - hsize - 8, off = hsize;
    CkHash hash = {0, {0}, 0};
    ck_hash(&hash, &hd, hsize);
    char *buf = sim_calloc(1, 1 << 20);
    while (left) {
        size_t part = left < (1u << 20) ? (size_t)left : (1u << 20);
        const char *err = ck_transfer(fd, buf, part, off, 0);
        if (err) sim_fail("%s: cannot read the checkpoint (%s)", path, err);
        ck_hash(&hash, buf, part);
        off += part, left -= part;
    }
    free(buf);
    uint64_t stored;
    if (ck_transfer(fd, &stored, sizeof stored, off, 0) || stored != ck_hash_end(&hash))
        sim_fail("%s: the checkpoint's checksum does not match its contents (damaged)", path);
    close(fd);
    ck_apply(&hd, opt, par);
}

int64_t io_resume_part(const Options *opt, const Params *par, Sim *blk, int64_t lo, int64_t m)
{
    const char *path = opt->resume;
    CkHeader hd;
    size_t hsize;
    int fd = ck_open(path, &hd, &hsize);
    if (sim_alloc(blk, m ? m : 1)) sim_fail("%s: not enough memory for the particles (N = %lld)", path, (long long)m);
    if (opt->pressure) blk->wi = sim_calloc((size_t)(m ? m : 1), sizeof *blk->wi);
    if (opt->exact) blk->last = sim_calloc((size_t)(m ? m : 1), sizeof *blk->last);
    void *a[CK_ARRAYS];
    size_t size[CK_ARRAYS];
    ck_arrays(blk, a, size);
    uint64_t n = (uint64_t)par->n, at = hsize;
    for (int k = 0; k < CK_ARRAYS; k++) {
        if (!a[k]) continue;
        const char *err = ck_transfer(fd, a[k], (size_t)m * size[k], at + (uint64_t)lo * size[k], 0);
        if (err) sim_fail("%s: cannot read the checkpoint (%s)", path, err);
        at += n * size[k];
    }
    close(fd);
    return ck_bad_disk(&hd, blk, lo, m);
}

void io_resume_refuse(const Options *opt, int64_t i)
{
    ck_refuse_disk(opt->resume, i);
}

void io_resume_begin(Output *out)
{
    CkHeader hd;
    size_t hsize;
    int fd = ck_open(out->opt->resume, &hd, &hsize);
    close(fd);
    out->virial = hd.virial;
    ck_said(out->opt, &hd);
}
