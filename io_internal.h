/* io_internal.h: what the I/O layer's files share among themselves. Backends include io.h alone.
 *
 * The layer's files, bottom up (each calls only those before it): output.c (the exact formatter,
 * buffered and parallel writing, progress), place.c (random placement), input.c (reading and
 * validating the input), checkpoint.c (saving and resuming), io.c (the command line and the driver).
 */
#ifndef IO_INTERNAL_H
#define IO_INTERNAL_H

#include "io.h"

#define PLACE_TRIES 10000 /* random positions tried for one disk before giving up */

/* --pressure in the periodic box (SPEC.md 7a): after step 0 and after the last step of each of the
 * run's blocks b = 1 .. B (B = min(VIRIAL_BLOCKS, S); block b ends after step b S / B), the index-order
 * sums of the disks' virial impulses w_i and of their squared speeds vx^2 + vy^2, in the units of the
 * output (velocities per step). A checkpoint keeps them. */
#define VIRIAL_BLOCKS 10
typedef struct {
    double w[VIRIAL_BLOCKS + 1];
    double k[VIRIAL_BLOCKS + 1];
} Virial;

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
    double ck_t0;      /* sim_clock() when the checkpoint being written in parts began */
    double next_show;  /* sim_clock() of the next progress update */
    int shown;         /* a progress line is on the terminal */
    IoTimes io;        /* io_main's reading and writing, for --stats */
    int io_known;      /* io holds them (not so for a backend that reads and writes its own way: mpi) */
    Virial virial;     /* --pressure in the periodic box: the blocks' sums so far */
};

/* ---- output.c ---------------------------------------------------------------------------------------- */

/* The backend this process runs (io_use_backend): the I/O layer reaches it only through this. */
extern const Backend *io_backend;
/* Runs task(ctx, k) for k in [0, tasks) on the backend's threads (Backend.parallel). */
void io_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx);
/* Writes all of bytes to fd; NULL, or what went wrong. */
const char *output_write_fd(int fd, const char *bytes, size_t len);
/* Writes out's pending bytes to stdout (sim_fail on a write error). */
void output_flush(Output *out);
/* What printed velocities are multiplied by: --substeps' K around the steps, else 1. */
real io_velocity_scale(void);

/* ---- place.c ----------------------------------------------------------------------------------------- */

/* Places par->n disks without overlap in sim (SPEC.md 1), on up to `threads` threads, the same disks
 * for any thread count. Returns -1, or the index of the disk that found no place in PLACE_TRIES. */
int64_t place_disks(const Params *par, uint64_t seed, Sim *sim, int threads);

/* ---- input.c ----------------------------------------------------------------------------------------- */

/* An integer as SPEC.md 1 accepts it: 0, or non-zero (not an integer, or out of range). */
int input_parse_int(const char *s, long long *out);
/* Reads and validates the whole input of opt into par and sim, or places the disks when it lists
 * none; its seconds and bytes into io. With prepare, the backend's prepare runs once the header is
 * read. Bad input: one line on stderr, exit(1). */
void input_read(const Options *opt, Params *par, Sim *sim, IoTimes *io, int prepare);

/* ---- checkpoint.c ------------------------------------------------------------------------------------ */

/* --resume: the run and state of opt->resume into par and sim, its virial sums so far into vir; the
 * options that shape the run (K, exact, pressure, periodic, dump17) into opt. Anything wrong with the
 * file fails the run. */
void checkpoint_read(Options *opt, Params *par, Sim *sim, Virial *vir);

#endif
