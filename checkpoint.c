/* checkpoint.c: --checkpoint and --resume: the whole state saved every K steps into a file that is
 * always whole (FILE.tmp synced, then renamed over FILE), and read back with every check before a
 * byte of output.
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
    output_flush(out); /* stdout holds every line through this step before the checkpoint says so */
    double t0 = sim_clock();
    const Params *par = out->par;
    size_t plen = strlen(out->ck_path);
    char *tmp = ck_tmp_name(out->ck_path);
    CkWriter *w = sim_calloc(1, sizeof *w);
    w->path = tmp;
    w->fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (w->fd < 0) sim_fail("cannot write the checkpoint %s: %s", tmp, strerror(errno));
    CkHeader hd;
    CkHeader1 *h = &hd.h;
    memset(&hd, 0, sizeof hd);
    memcpy(h->magic, CK_MAGIC, 8);
    h->version = CK_VERSION;
    h->real_bytes = (uint32_t)sizeof(real);
    h->n = par->n, h->steps = par->steps, h->step = step, h->substeps = par->substeps;
    h->L = (double)par->L, h->r = (double)par->r;
    h->print = par->print, h->exact = out->opt->exact, h->pressure = sim->wi != NULL, h->dump17 = out->dump17;
    hd.periodic = par->periodic;
    hd.virial = out->virial;
    ck_put(w, &hd, sizeof hd);
    ck_put_reals(w, sim->x, par->n, 1);
    ck_put_reals(w, sim->y, par->n, 1);
    ck_put_reals(w, sim->vx, par->n, io_velocity_scale());
    ck_put_reals(w, sim->vy, par->n, io_velocity_scale());
    ck_put(w, sim->pc, (size_t)par->n * sizeof *sim->pc);
    ck_put(w, sim->wc, (size_t)par->n * sizeof *sim->wc);
    if (sim->wi) ck_put(w, sim->wi, (size_t)par->n * sizeof *sim->wi);
    if (h->exact) ck_put(w, sim->last, (size_t)par->n * sizeof *sim->last);
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
void checkpoint_probe(const char *path)
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
void checkpoint_read(Options *opt, Params *par, Sim *sim, Virial *vir)
{
    const char *path = opt->resume;
    int fd = open(path, O_RDONLY);
    if (fd < 0) sim_fail("%s: cannot open the checkpoint (%s)", path, strerror(errno));
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) sim_fail("%s: not a checkpoint (not a regular file)", path);
    CkHeader hd;
    CkHeader1 h;
    memset(&hd, 0, sizeof hd);
    if (read(fd, &h, sizeof h) != (ssize_t)sizeof h || memcmp(h.magic, CK_MAGIC, 8) != 0)
        sim_fail("%s: not a checkpoint (it does not start with %s)", path, CK_MAGIC);
    if (h.version != CK_VERSION && h.version != 1)
        sim_fail("%s: a checkpoint of format %u; this program reads formats 1 and %u", path, h.version, CK_VERSION);
    size_t hsize = h.version == 1 ? sizeof h : sizeof hd; /* format 1: no periodic box */
    hd.h = h;
    if (hsize > sizeof h &&
        read(fd, (char *)&hd + sizeof h, hsize - sizeof h) != (ssize_t)(hsize - sizeof h))
        sim_fail("%s: a checkpoint cut short in its header", path);
    if (h.real_bytes != sizeof(real))
        sim_fail("%s: a checkpoint of %s precision; %s computes in %s", path, h.real_bytes == 8 ? "double" : "single",
                sim_program, sizeof(real) == 8 ? "double" : "single");
    if (h.n < 1 || h.n > SIM_MAX_N || h.steps < 0 || h.step < 1 || h.step >= h.steps || h.substeps < 1 ||
        h.substeps > 1024 || (h.substeps & (h.substeps - 1)) || !(h.L > 0) || !(h.r > 0) ||
        (hd.periodic != 0 && hd.periodic != 1))
        sim_fail("%s: a checkpoint with impossible values (N = %lld, step %lld of %lld, K = %lld)", path,
                (long long)h.n, (long long)h.step, (long long)h.steps, (long long)h.substeps);
    uint64_t n = (uint64_t)h.n;
    uint64_t want = hsize + n * (4 * sizeof(real) + 2 * sizeof(int32_t)) + (h.pressure ? n * sizeof(double) : 0) +
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
    if (hd.periodic && !(io_backend->features & SIM_FEATURE_PERIODIC))
        sim_fail("%s: a checkpoint of a --periodic run, which %s does not support", path, sim_program);
    if (sim_alloc(sim, h.n)) sim_fail("%s: not enough memory for the particles (N = %lld)", path, (long long)h.n);
    if (h.pressure) sim->wi = sim_calloc(n, sizeof *sim->wi);
    if (h.exact) sim->last = sim_calloc(n, sizeof *sim->last);
    CkHash hash = {0, {0}, 0};
    ck_hash(&hash, &hd, hsize);
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
    /* the centres as SPEC.md 1 or, in the periodic box, 7 allows them */
    real lo = hd.periodic ? 0 : (real)h.r, hi = hd.periodic ? (real)h.L : (real)h.L - (real)h.r;
    for (int64_t i = 0; i < h.n; i++)
        if (!(sim->x[i] >= lo && sim->y[i] >= lo && (hd.periodic ? sim->x[i] < hi && sim->y[i] < hi
                                                                 : sim->x[i] <= hi && sim->y[i] <= hi) &&
              sim->pc[i] >= 0 && sim->wc[i] >= 0 &&
              (!sim->last || (sim->last[i] >= -1 && sim->last[i] < h.n && sim->last[i] != i))))
            sim_fail("%s: disk %lld of the checkpoint is outside the box or has impossible counts", path, (long long)i);
    par->n = h.n;
    par->L = (real)h.L;
    par->r = (real)h.r;
    par->steps = h.steps;
    par->print = h.print;
    par->periodic = hd.periodic;
    params_derive(par);
    par->first_step = h.step;
    opt->substeps = (int)h.substeps;
    opt->exact = h.exact;
    opt->pressure = h.pressure;
    opt->periodic = hd.periodic;
    opt->dump17 = h.dump17;
    *vir = hd.virial;
    if (!opt->quiet)
        fprintf(stderr, "%s: resuming %s at step %lld of %lld\n", sim_program, path, (long long)h.step,
                (long long)h.steps);
}
