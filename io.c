/* io.c: the driver every backend runs through: the command line and --help, the run from input to
 * final state (io_main), and the report on stderr (timing, --stats, --pressure).
 */
#define _POSIX_C_SOURCE 200809L

#include "io_internal.h"
#include "exact.h"

#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define DEFAULT_SEED 1u

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
            "               stderr (with --periodic: the pressure of the collision virial)\n"
            "  --periodic   the periodic box: no walls, opposite edges joined, nearest images\n"
            "               (SPEC.md 7); centres in [0, L), L > 4r\n"
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
            sim_program, DEFAULT_SEED, io_backend->options);
}

static long long option_value(int argc, char **argv, int *k, long long lo, long long hi)
{
    const char *name = argv[*k];
    if (*k + 1 >= argc) sim_fail("%s needs a value (see --help)", name);
    const char *val = argv[++*k];
    long long v;
    if (input_parse_int(val, &v) || v < lo || v > hi)
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
    unsigned has = io_backend->features;
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
            if (opt->substeps > 1 && !(has & SIM_FEATURE_SUBSTEPS))
                sim_fail("--substeps is not supported by %s", sim_program);
        } else if (strcmp(a, "--pressure") == 0) {
            opt->pressure = 1;
            if (!(has & SIM_FEATURE_PRESSURE))
                sim_fail("--pressure is not supported by %s", sim_program);
        } else if (strcmp(a, "--periodic") == 0) {
            opt->periodic = 1;
            if (!(has & SIM_FEATURE_PERIODIC))
                sim_fail("--periodic is not supported by %s", sim_program);
        } else if (strcmp(a, "--exact") == 0) {
            opt->exact = 1;
            if (!(has & SIM_FEATURE_EXACT))
                sim_fail("--exact is not supported by %s", sim_program);
        } else if ((has & SIM_FEATURE_THREADS) && strcmp(a, "--threads") == 0) {
            opt->threads = (int)option_value(argc, argv, &k, 1, 4096);
        } else if ((has & SIM_FEATURE_THREADS) && strcmp(a, "--check") == 0) {
            opt->check = 1;
        } else if ((has & SIM_FEATURE_THREADS) && strcmp(a, "--broad") == 0) {
            if (k + 1 >= argc) sim_fail("--broad needs a value (see --help)");
            const char *val = argv[++k];
            if (strcmp(val, "grid") == 0) opt->broad = SIM_BROAD_GRID;
            else if (strcmp(val, "paths") == 0) opt->broad = SIM_BROAD_PATHS;
            else if (strcmp(val, "mixed") == 0) opt->broad = SIM_BROAD_MIXED;
            else if (strcmp(val, "auto") == 0) opt->broad = SIM_BROAD_AUTO;
            else sim_fail("--broad must be grid, paths, mixed or auto (found '%s')", val);
        } else if ((has & SIM_FEATURE_LANES) && strcmp(a, "--lanes") == 0) {
            opt->lanes = (int)option_value(argc, argv, &k, 1, 16);
            if (opt->lanes != 1 && opt->lanes != 4 && opt->lanes != 8 && opt->lanes != 16)
                sim_fail("--lanes must be 1, 4, 8 or 16 (found %d)", opt->lanes);
        } else if ((has & SIM_FEATURE_LANES) && strcmp(a, "--keep") == 0) {
            opt->keep = (int)option_value(argc, argv, &k, 0, SIM_KEEP_MOST);
        } else if ((has & SIM_FEATURE_BALANCE) && strcmp(a, "--balance") == 0) {
            opt->balance = option_value(argc, argv, &k, 0, SIM_MAX_STEPS);
        } else if (strcmp(a, "--checkpoint") == 0) {
            if (k + 1 >= argc) sim_fail("--checkpoint needs a file name");
            opt->checkpoint = argv[++k];
        } else if (strcmp(a, "--output") == 0) {
            if (!(has & SIM_FEATURE_OUTPUT))
                sim_fail("--output is not supported by %s (redirect its standard output)", sim_program);
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
    if ((opt->checkpoint || opt->resume) && !(has & SIM_FEATURE_CHECKPOINT))
        sim_fail("--checkpoint and --resume are not supported by %s yet", sim_program);
    if (opt->checkpoint_every && !opt->checkpoint) sim_fail("--checkpoint-every needs --checkpoint FILE");
    if (!opt->checkpoint_every) opt->checkpoint_every = 1000;
    if (opt->resume) {
        /* the run is the checkpoint's: these would change it */
        if (opt->path) sim_fail("--resume reads no input file ('%s' given)", opt->path);
        if (substeps_given || opt->pressure || opt->dump17 || opt->seed_given || opt->exact || opt->periodic)
            sim_fail("--resume takes --substeps, --exact, --pressure, --periodic, --dump17 and --seed from the "
                    "checkpoint: leave them out");
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

/* ==== --pressure in the periodic box (SPEC.md 7a) ======================================================== */

static int64_t virial_blocks(int64_t steps)
{
    return steps < VIRIAL_BLOCKS ? steps : VIRIAL_BLOCKS;
}

/* The block that ends after step `step` (0: step 0), or -1 if none does. */
static int virial_block(int64_t steps, int64_t step)
{
    int64_t B = virial_blocks(steps);
    if (step == 0) return 0;
    for (int64_t b = 1; b <= B; b++)
        if (b * steps / B == step) return (int)b;
    return -1;
}

int io_virial_ends_block(const Params *par, const Options *opt, int64_t step)
{
    return par->periodic && opt->pressure && step > 0 && step < par->steps && virial_block(par->steps, step) > 0;
}

int io_virial_due(const Output *out, int64_t step)
{
    return step > out->first && io_virial_ends_block(out->par, out->opt, step);
}

void io_virial_sums(Output *out, int64_t step, double w, double k)
{
    int b = virial_block(out->steps, step);
    if (!out->par->periodic || !out->opt->pressure || b < 0) return;
    double f = (double)io_velocity_scale(); /* the run's velocities are v / K: K is a power of two */
    out->virial.w[b] = w * f;
    out->virial.k[b] = k * (f * f);
}

void io_virial(Output *out, const Sim *sim, int64_t step)
{
    if (!out->par->periodic || !out->opt->pressure) return;
    double w = 0, k = 0;
    for (int64_t i = 0; i < out->par->n; i++) {
        w += sim->wi ? sim->wi[i] : 0;
        k += (double)sim->vx[i] * (double)sim->vx[i] + (double)sim->vy[i] * (double)sim->vy[i];
    }
    io_virial_sums(out, step, w, k);
}

/* The pressure line of the periodic box: for block b of T_b steps, kT_b = (k_(b-1) + k_b) / (4 N)
 * (the mean kinetic energy of a disk at its two ends; 2D, unit masses), its virial V_b = (sigma / 2)
 * (w_b - w_(b-1)) (each collision's sigma |dp|, counted by both disks) and Z_b = 1 + V_b / (2 N kT_b
 * T_b); over the run kT is the T_b-weighted mean of the kT_b, V = (sigma / 2) w_B, Z = 1 + V / (2 N kT
 * S) and P = Z N kT / L^2; the error is the standard error of the mean of the Z_b. */
static void report_virial(const Output *out, const Params *par)
{
    const Virial *v = &out->virial;
    int64_t S = par->steps, B = virial_blocks(S);
    double n = (double)par->n, sigma = 2 * (double)par->r, kt = B > 0 ? 0 : v->k[0] / (2 * n), zsum = 0, z2 = 0;
    double zb[VIRIAL_BLOCKS + 1];
    for (int64_t b = 1; b <= B; b++) {
        double tb = (double)(b * S / B - (b - 1) * S / B), ktb = (v->k[b - 1] + v->k[b]) / (4 * n);
        double vb = sigma / 2 * (v->w[b] - v->w[b - 1]);
        zb[b] = 1 + vb / (2 * n * ktb * tb);
        kt += tb * ktb / (double)S;
        zsum += zb[b];
    }
    for (int64_t b = 1; b <= B; b++) z2 += (zb[b] - zsum / (double)B) * (zb[b] - zsum / (double)B);
    double vir = sigma / 2 * v->w[B], z = S > 0 ? 1 + vir / (2 * n * kt * (double)S) : 1;
    double err = B >= 2 ? sqrt(z2 / (double)(B * (B - 1))) : NAN;
    fprintf(stderr,
            "%s: pressure (periodic box, collision virial): N kT = %.17g, virial %.17g over %lld time "
            "units: P = %.17g, Z = P L^2 / (N kT) = %.17g +- %.2g (standard error of %lld block means)\n",
            sim_program, n * kt, vir, (long long)S, z * n * kt / ((double)par->L * (double)par->L), z, err,
            (long long)B);
}

void io_report(Output *out, const Params *par, const Options *opt, const RunStats *st, double run_s, double impulse)
{
    if (out->shown) fputc('\n', stderr); /* end the progress line */
    out->shown = 0;
    if (!opt->quiet) {
        double ps = (double)par->n * (double)(par->steps - par->first_step); /* a resumed run: the steps it ran */
        fprintf(stderr, "%s: %lld particles, %lld steps, %s: %.6f s step loop, %.4g particle-steps/s\n",
                sim_program, (long long)par->n, (long long)(par->steps - par->first_step), par->print ? "print" : "perf",
                st->seconds, st->seconds > 0 ? ps / st->seconds : 0.0);
    }
    if (opt->stats) {
        const IoTimes *io = &out->io;
        fprintf(stderr, "%s: %llu pair tests (%.4g per particle-step), %llu events\n", sim_program,
                (unsigned long long)st->pair_tests,
                par->steps > par->first_step ? (double)st->pair_tests / ((double)par->n * (double)(par->steps - par->first_step)) : 0.0,
                (unsigned long long)st->events);
        /* the text: the input read and parsed; step 0 and the final state formatted and written */
        if (out->io_known)
            fprintf(stderr, "%s: input %.1f MB: read %.4f s, parsed %.4f s (%.0f MB/s); step 0 and final state "
                    "%.1f MB: formatted and written %.4f s (%.0f MB/s)\n", sim_program, (double)io->in_bytes / 1e6,
                    io->read_s, io->parse_s, io->parse_s > 0 ? (double)io->in_bytes / 1e6 / io->parse_s : 0.0,
                    (double)io->out_bytes / 1e6, io->write_s, io->write_s > 0 ? (double)io->out_bytes / 1e6 / io->write_s : 0.0);
        if (out->ck_count)
            fprintf(stderr, "%s: %lld checkpoints of %.1f MB: written %.4f s (%.0f MB/s)\n", sim_program,
                    (long long)out->ck_count, (double)out->ck_bytes / 1e6 / (double)out->ck_count, out->ck_s,
                    out->ck_s > 0 ? (double)out->ck_bytes / 1e6 / out->ck_s : 0.0);
        fprintf(stderr, "%s: the run %.4f s, its step loop %.4f s; %.4f s since the start\n", sim_program, run_s,
                st->seconds, sim_clock() - (out->io_known ? io->start : out->start));
    }
    if (opt->pressure && par->periodic) {
        report_virial(out, par);
    } else if (opt->pressure) {
        impulse *= (double)opt->substeps; /* the run's velocities were v / K */
        double span = (double)par->steps * 4 * (double)par->L;
        fprintf(stderr,
                "%s: pressure: wall impulse %.17g over %lld time units on 4 walls of length %.17g: "
                "P = %.17g\n",
                sim_program, impulse, (long long)par->steps, (double)par->L,
                span > 0 ? impulse / span : 0.0);
    }
}

void io_use_backend(const Backend *b)
{
    io_backend = b;
    sim_program = b->name;
}

int io_main(int argc, char **argv, const Backend *b)
{
    Options opt;
    Params par;
    Sim sim;
    Virial vir;
    memset(&vir, 0, sizeof vir);
    io_use_backend(b);
    io_parse_args(argc, argv, &opt);
    if (opt.checkpoint) io_checkpoint_probe(opt.checkpoint);
    IoTimes io;
    memset(&io, 0, sizeof io);
    io.start = sim_clock();
    if (opt.resume) {
        memset(&par, 0, sizeof par);
        memset(&sim, 0, sizeof sim);
        checkpoint_read(&opt, &par, &sim, &vir);
        if (io_backend->prepare) io_backend->prepare(&par, opt.resume);
    } else {
        input_read(&opt, &par, &sim, &io, 1);
        par.first_step = 0;
    }

    Output *out = io_output_open(&par, &opt);
    out->virial = vir;
    /* runs that cannot finish are refused before the first byte of output */
    if (opt.exact) exact_check_speeds(&sim, &par);
    if (par.steps * (int64_t)opt.substeps > INT32_MAX)
        sim_fail("--substeps %d with S = %lld steps could count more than %d collisions of one disk "
                "(S x K must be <= %d)",
                opt.substeps, (long long)par.steps, INT32_MAX, INT32_MAX);
    /* a resumed run's step 0 is out already; cuda writes it beside its steps, where the host is idle */
    out->step0_pending = !opt.resume && !par.print && par.steps > 0 && (b->features & SIM_FEATURE_STEP0);
    if (!opt.resume && !out->step0_pending) io_write_step0(out, &sim);

    /* --substeps K: a sub-step of length 1/K is a SPEC.md step at velocities v / K */
    par.substeps = opt.substeps;
    real k = (real)opt.substeps;
    scale_velocities(&sim, par.n, 1 / k);
    io_set_velocity_scale(k);
    if (opt.pressure && !sim.wi) sim.wi = sim_calloc((size_t)par.n, sizeof *sim.wi);
    if (!opt.resume) io_virial(out, &sim, 0);

    RunStats st;
    memset(&st, 0, sizeof st);
    out->start = sim_clock();
    out->next_show = out->start + 2.0;
    if (io_backend->run(&sim, &par, &opt, out, &st)) return 1;
    double run_s = sim_clock() - out->start;
    if (out->step0_pending) sim_fail("internal error: %s did not write step 0", sim_program);
    io.write_s = out->step0_s;
    io.out_bytes = out->step0_bytes;
    if (out->shown) fputc('\n', stderr);
    out->shown = 0;
    io_virial(out, &sim, par.steps);
    scale_velocities(&sim, par.n, k);
    io_set_velocity_scale(1);

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
