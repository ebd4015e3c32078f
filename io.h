/* io.h: the I/O layer and driver as the backends see it: options, the backend interface and the
 * services of output.c, place.c, input.c, checkpoint.c and io.c.
 *
 * The layers, bottom up: common.h and state.c (state, physics, messages and memory), exact.h and
 * exact.c (the --exact model), the I/O layer (io_internal.h lists its files), then the backends
 * (seq.c; omp.c with its omp_*.c; cuda.cu; mpi.c with mpi_comm.c and mpi_io.c). Each file calls only
 * those below it: the driver reaches its backend through the Backend that the backend's main hands it.
 */
#ifndef IO_H
#define IO_H

#include "common.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- command-line options ------------------------------------------------------------------------ */

typedef struct {
    const char *path;  /* input file; "-" reads stdin */
    const char *label; /* how messages name the input: the path, or "<stdin>" */
    uint64_t seed;     /* seed of the random placement (SPEC.md 1) */
    int seed_given;    /* 1 when --seed was on the command line */
    int dump17;        /* 1: print reals with %.17g, enough to round-trip a double */
    int threads;       /* omp: threads to use; 0 leaves it to OpenMP (OMP_NUM_THREADS) */
    int quiet;         /* 1: no timing line on stderr */
    int stats;         /* 1: print event and pair-test counts on stderr */
    int check;         /* omp: check the broad phase against all pairs every step */
    int substeps;      /* --substeps K: K sub-steps of length 1/K per step (1: SPEC.md) */
    int pressure;      /* --pressure: add up wall impulses and print the pressure on stderr */
    int exact;         /* --exact: event-driven steps, every collision in time order (exact.h) */
    int periodic;      /* --periodic: the periodic box of SPEC.md 7 */
    int broad;         /* omp --broad: SIM_BROAD_AUTO (the cost model chooses each step), _GRID,
                          _PATHS, _MIXED */
    int lanes;         /* omp --lanes W: pairs a SIMD screen of the paths takes at a time (0: the
                          widest the processor runs) */
    int keep;          /* omp --keep K: a fast disk's events with slow disks kept in a mixed step
                          (0: all; -1: the backend's default) */
    const char *checkpoint;   /* --checkpoint FILE: the state written there every checkpoint_every steps */
    int64_t checkpoint_every; /* --checkpoint-every K (default 1000) */
    const char *resume;       /* --resume FILE: go on from that checkpoint instead of reading an input */
    const char *output;       /* mpi --output FILE: stdout's bytes written into FILE by every rank */
    int64_t balance;          /* mpi --balance K: steps between moves of the cuts by measured time (0: never) */
} Options;

#define SIM_BALANCE_EVERY 0 /* mpi's default --balance: by count at the start only */

#define SIM_KEEP_MOST 64 /* the largest omp --keep */

#define SIM_BROAD_AUTO 0
#define SIM_BROAD_GRID 1
#define SIM_BROAD_PATHS 2
#define SIM_BROAD_MIXED 3

/* What a backend reports about its run, printed on stderr by the driver. */
typedef struct {
    double seconds;      /* wall time of the step loop */
    uint64_t pair_tests; /* narrow-phase pair tests done (0 if not counted) */
    uint64_t events;     /* accepted events, wall and pair */
} RunStats;

typedef struct Output Output;

/* ---- the backend interface: each of seq.c, omp.c, cuda.cu and mpi.c describes itself in a Backend,
 * which its main hands to io_main (or io_use_backend); the I/O layer calls a backend only through it. */

#define SIM_FEATURE_SUBSTEPS 1u
#define SIM_FEATURE_PRESSURE 2u
#define SIM_FEATURE_EXACT 4u
#define SIM_FEATURE_CHECKPOINT 8u /* --checkpoint and --resume */
#define SIM_FEATURE_STEP0 16u     /* perf mode: the backend writes step 0 (io_write_step0) beside its steps */
#define SIM_FEATURE_OUTPUT 32u    /* --output FILE: the backend writes what stdout would get into FILE */
#define SIM_FEATURE_THREADS 64u   /* --threads, --check and --broad (omp's broad phase) */
#define SIM_FEATURE_LANES 128u    /* --lanes and --keep (omp's paths) */
#define SIM_FEATURE_BALANCE 256u  /* --balance (mpi's cuts) */
#define SIM_FEATURE_PERIODIC 512u /* --periodic (SPEC.md 7) */

typedef struct {
    const char *name;    /* program name used in messages: "seq", "omp", "cuda", "mpi" (+ SIM_SUFFIX) */
    const char *options; /* backend-specific lines for --help ("" if none) */
    unsigned features;   /* which of the SIM_FEATURE_ options the backend supports */
    /* Runs par->steps steps on sim, each as par->substeps sub-steps (the driver has divided the
     * velocities by K, so a sub-step is the SPEC.md step unchanged). In print mode it hands the state
     * after steps 1..S-1 (sub-steps K, 2K, ...) to io_write_lines. When sim->wi is set, every wall
     * reflection adds wall_impulse to the disk's wi. On return sim holds the state after the last
     * step, counts included. Returns 0, or non-zero after printing its own error message. */
    int (*run)(Sim *sim, const Params *par, const Options *opt, Output *out, RunStats *stats);
    /* NULL, or called once the input's header is read, before its particle lines: slow set-up that
     * runs beside the reading (cuda creates its context when there are steps to run). where names N's
     * source for a refusal's message, as bad input's name it: "FILE:LINE", or a checkpoint's path. */
    void (*prepare)(const Params *par, const char *where);
    /* Calls task(ctx, k) once for each k in [0, tasks), on up to threads threads (0: the backend's
     * default; seq: one, in order). The tasks must not depend on each other's order: the input's
     * pieces and chunks and the output's blocks of lines go through it. */
    void (*parallel)(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx);
} Backend;

/* ---- the I/O layer: everything untimed ------------------------------------------------------------ */

/* The whole program: options, input, step 0, b->run, final state, timing. Each backend's main is just
 * `return io_main(argc, argv, &its_backend);`. */
int io_main(int argc, char **argv, const Backend *b);
/* For a backend that drives itself (mpi): b is the backend the I/O layer's calls below serve. */
void io_use_backend(const Backend *b);

/* Upper bound on the bytes of one output line (a %.8f real can take 300+ digits). */
#define IO_LINE_MAX 1600

/* Formats output line i of a state (counts included when with_counts) at dst; returns its length. */
size_t io_format_line(char *dst, int64_t step, int64_t i, const Sim *sim, int with_counts,
                      int dump17);
/* The same for a disk held at position k of sim but printed as disk `index`: a backend that holds a
 * block of the state (mpi: a rank's block of indices) formats it without a whole-state Sim. */
size_t io_format_disk(char *dst, int64_t step, int64_t index, const Sim *sim, int64_t k, int with_counts,
                      int dump17);
/* Writes a whole state's lines (0 .. n-1), formatted on the backend's threads (Backend.parallel) while
 * the lines before are written: step 0, each printed step and the final state (with counts) of every
 * backend go through it or, inside omp's parallel region, through the TextJob below. */
void io_write_lines(Output *out, int64_t step, const Sim *sim, int64_t n, int with_counts);
/* The same in the caller's own parallel loop: for r = 0 .. rounds, run io_text_task(j, r, k) for k in
 * [0, io_text_tasks(j, r)) in any order on any threads, each round complete before the next starts. */
typedef struct {
    char *buf;
    size_t len, cap;
} TextBlock;
#define IO_TEXT_ROUND 16 /* blocks of lines formatted per round */
typedef struct {
    Output *out;
    const Sim *sim;
    int64_t step, n, blocks, rounds;
    int with_counts;
    TextBlock slot[2 * IO_TEXT_ROUND]; /* two rounds of blocks: one being formatted, one written */
} TextJob;
/* The lines of positions [from, to) of sim, position k printed as disk base + k, into t (grown as
 * needed; t->len is their length): one task of io_text_task, or of a backend's own block (mpi). */
void io_format_block(TextBlock *t, int64_t step, const Sim *sim, int64_t from, int64_t to, int64_t base,
                     int with_counts, int dump17);
void io_text_begin(TextJob *j, Output *out, int64_t step, const Sim *sim, int64_t n, int with_counts);
int64_t io_text_tasks(const TextJob *j, int64_t r);
void io_text_task(TextJob *j, int64_t r, int64_t k);
void io_text_end(TextJob *j);
void io_write_bytes(Output *out, const char *bytes, size_t len);
/* A real of the input as SPEC.md 1 accepts it, the value strtod gives: 0, -1 (not a number), -2 (out of
 * range) or -3 (nan or inf). */
int io_parse_real(const char *s, double *out);
int io_dump17(const Output *out);
/* What lines multiply velocities by: K while the state holds v / K (--substeps), else 1. io_main sets
 * it around Backend.run itself; a backend that drives itself (mpi) sets it on every rank that formats. */
void io_set_velocity_scale(real k);
int io_threads(const Output *out); /* --threads, 0 if not given */
/* Shows a progress line on a terminal once a run has taken a few seconds; cheap to call every step. */
void io_progress(Output *out, int64_t step);
/* --checkpoint: whether the state after whole step `step` is to be saved, and saving it (sim in
 * original order, velocities as the backend holds them: v / K). io_checkpoint first flushes stdout
 * through that step, then writes FILE.tmp, syncs it and renames it over FILE, so that FILE is always
 * a whole checkpoint; it fails the run with a message where it cannot. */
int io_checkpoint_due(const Output *out, int64_t step);
/* The first whole step from `step` on that is to be saved, or 0 if none is (backends that plan ahead) */
int64_t io_checkpoint_next(const Output *out, int64_t step);
void io_checkpoint(Output *out, const Sim *sim, int64_t step);
/* The same rule as io_checkpoint_due on any process of a backend that drives itself (mpi). */
int io_checkpoint_at(const Params *par, const Options *opt, int64_t step);
/* --checkpoint FILE tried before the run (fails the run where FILE cannot be written). */
void io_checkpoint_probe(const char *path);
/* A checkpoint written in parts (mpi: each rank its block of indices), the same bytes as
 * io_checkpoint's, in three phases, each complete on every process before the next begins:
 * io_checkpoint_begin (one process, with the Output: stdout flushed through the step, FILE.tmp
 * created with the header; pressure: the state holds impulses); io_checkpoint_part (every process:
 * disks [lo, lo + m) of the state, blk holding disk lo + k at k, velocities as the backend holds
 * them, written at their offsets in FILE.tmp and synced); io_checkpoint_end (the first process: the
 * checksum over FILE.tmp read back in order, appended, synced, FILE.tmp renamed over FILE). */
void io_checkpoint_begin(Output *out, int64_t step, int pressure);
void io_checkpoint_part(const Options *opt, const Params *par, const Sim *blk, int64_t lo, int64_t m);
void io_checkpoint_end(Output *out, int64_t step);
/* --resume in parts: io_resume_check (one process) refuses what io_main's --resume refuses but for the
 * disks' own values (header, size, checksum: one pass over the file) and sets par and opt from the
 * checkpoint; io_resume_part (every process, par and opt as set) reads disks [lo, lo + m) into blk
 * (allocated here; disk lo + k at k, velocities per step as in the file) and returns the first of
 * them that io_main would refuse, or -1; io_resume_refuse fails the run with io_main's message for
 * that disk; io_resume_begin (the process with the Output) takes the checkpoint's virial sums and
 * says "resuming" as io_main does. */
void io_resume_check(Options *opt, Params *par);
int64_t io_resume_part(const Options *opt, const Params *par, Sim *blk, int64_t lo, int64_t m);
void io_resume_refuse(const Options *opt, int64_t i);
void io_resume_begin(Output *out);
/* --pressure in the periodic box (SPEC.md 7a): the run's steps cut into blocks, and after the last
 * step of each block the index-order sums of the disks' virial impulses (wi) and of their squared
 * speeds. io_virial_due: whether the state after whole step `step` ends a block (the run's last step
 * aside: the driver takes that one); io_virial: those sums of sim (original order, velocities as the
 * backend holds them, v / K) recorded for `step`; io_virial_sums: the same for a backend that adds
 * them up itself (mpi), w and k as it holds them. Nothing outside a periodic --pressure run. */
int io_virial_due(const Output *out, int64_t step);
int io_virial_ends_block(const Params *par, const Options *opt, int64_t step); /* the same, any rank */
void io_virial(Output *out, const Sim *sim, int64_t step);
void io_virial_sums(Output *out, int64_t step, double w, double k);
/* SIM_FEATURE_STEP0: whether this run's step 0 is the backend's to write, and writing it (sim as the
 * backend received it, before it changes sim; any thread, while no other writes to out). */
int io_step0_pending(const Output *out);
void io_write_step0(Output *out, const Sim *sim);
/* The final state (with counts), written by a backend while it still arrives in sim: await(ctx, m)
 * returns once sim's disks 0 .. m-1 hold it. The driver then writes no final state of its own. */
void io_write_final(Output *out, const Sim *sim, void (*await)(void *ctx, int64_t lines), void *ctx);

/* ---- services for a backend that drives itself (mpi: every rank runs its own main) ---------------- */

/* io_main's pieces, so that such a backend goes through the same options, messages and report. */
/* The command line into opt (sim_fail, or exit(0) after --help, on what io_main would refuse). */
void io_parse_args(int argc, char **argv, Options *opt);
/* The output as io_main sets it up (8 MB buffer, --dump17, --threads, progress on a terminal, a
 * closed pipe a write error); par and opt must outlive it. Its clock (progress, --stats) starts here. */
Output *io_output_open(const Params *par, const Options *opt);
/* Writes what is pending (sim_fail on a write error) and frees out. */
void io_output_close(Output *out);
/* What io_main prints on stderr after a run: the timing line (unless --quiet), --stats and, with
 * --pressure, the pressure: in the walled box of impulse, the index-order sum of the disks' wi as the
 * backend holds them (velocities v / K: io_report multiplies by K); in the periodic box of the virial
 * sums recorded (io_virial), impulse unused. */
void io_report(Output *out, const Params *par, const Options *opt, const RunStats *st, double run_s,
               double impulse);
/* The whole input as io_main reads it (or the disks it places), failing with seq's one-line message on
 * bad input; Backend.prepare is left to the caller. */
void io_read_input(const Options *opt, Params *par, Sim *sim);
/* Reading a regular file in pieces (mpi: each rank its own byte range). io_header_span: the bytes of
 * text[0, size) through the newline of the header's 5th record, or 0 when they do not hold it whole
 * (read more, or all). io_read_header: the header of text[0, size) into par as io_main reads it (same
 * messages, naming label; text[size] must be writable; par->periodic set by the caller), the offset of the first particle line and
 * the number of the line before it. */
size_t io_header_span(const char *text, size_t size);
void io_read_header(const char *label, char *text, size_t size, Params *par, size_t *body, long *body_line);
/* Particle lines text[0, len) (whole lines, text[len] writable) parsed on up to `threads` threads with
 * io_main's per-line checks; the checks that need all lines (count, duplicates) are the caller's. On
 * bad input only the fact is kept: io_read_input then finds the message. */
typedef struct {
    int64_t lines; /* lines of the piece */
    int32_t *idx;  /* per line: the index its record gives, or < 0 for a blank line */
    Sim disks;     /* per line: its record's x, y, vx, vy (pc and wc unused) */
    int bad;       /* some line failed a check (idx is then incomplete) */
} IoPiece;
void io_parse_piece(const Params *par, char *text, size_t len, int threads, IoPiece *pc);
void io_piece_free(IoPiece *pc);

#ifdef __cplusplus
}
#endif

#endif
