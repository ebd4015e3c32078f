/* mpi_comm.c: what the MPI backend's steps (mpi.c) and its input and output (mpi_io.c) share: the
 * ranks, the cuts between their strips and whom a disk belongs to, a rank's store of disks, the
 * collective exchange of records, and the threads of a rank.
 */
#include "mpi.h"

#include <limits.h>
#include <string.h>

int mpi_me, mpi_np;
double *mpi_cut;

#define CUT_BINS 256 /* histogram bins a rank (up to 4096 ranks) */

int64_t mpi_cut_bins(void)
{
    return (int64_t)CUT_BINS * (mpi_np < 4096 ? mpi_np : 4096);
}

void mpi_cut_add(double *h, double x, double L, double w)
{
    int64_t bins = mpi_cut_bins();
    double c = x / L * (double)bins;
    h[c > 0 ? (c < (double)bins ? (int64_t)c : bins - 1) : 0] += w;
}

int mpi_place_cuts(const double *h, double load, double L, double slack)
{
    int np = mpi_np;
    int64_t bins = mpi_cut_bins();
    double *all = NULL, most = 0, *cut = sim_calloc((size_t)np + 2, sizeof *cut);
    if (mpi_me == 0) all = sim_calloc((size_t)bins, sizeof *all);
    MPI_Reduce(h, all, (int)bins, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
    MPI_Reduce(&load, &most, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
    if (mpi_me == 0) { /* rank 0 places them: the same cuts on every rank */
        double total = 0, acc = 0;
        for (int64_t k = 0; k < bins; k++) total += all[k];
        if (!mpi_cut || (total > 0 && most > slack * total / np)) {
            cut[np + 1] = 1; /* moved */
            int q = 1;
            for (int64_t k = 0; k < bins && q < np && total > 0; k++) {
                while (q < np && acc + all[k] >= total * q / np) { /* within bin k, linearly */
                    double f = all[k] > 0 ? (total * q / np - acc) / all[k] : 0;
                    cut[q++] = ((double)k + f) * L / (double)bins;
                }
                acc += all[k];
            }
            for (; q < np; q++) cut[q] = total > 0 ? L : L * q / np; /* nothing weighed: equal strips */
            cut[np] = L;
        }
    }
    MPI_Bcast(cut, np + 2, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    int moved = cut[np + 1] != 0;
    if (moved) {
        if (!mpi_cut) mpi_cut = sim_calloc((size_t)np + 1, sizeof *mpi_cut);
        memcpy(mpi_cut, cut, (size_t)(np + 1) * sizeof *cut);
    }
    free(all), free(cut);
    return moved;
}

int mpi_owner(double x)
{
    return strip_owner(mpi_cut, mpi_me, mpi_np, x);
}

void local_reserve(Local *l, int64_t n)
{
    if (n <= l->cap) return;
    int64_t cap = l->cap ? l->cap : 1024;
    while (cap < n) cap *= 2;
    slots_resize(&l->s, cap, l->with_wi);
    l->cap = cap;
}

int64_t mpi_displacements(const int *count, const int *rcount, int *sd, int *rd)
{
    int64_t total = 0, off = 0;
    for (int q = 0; q < mpi_np; q++) {
        if (off > INT_MAX || total > INT_MAX) sim_fail("internal error: more than 2^31 records for one rank");
        sd[q] = (int)off, rd[q] = (int)total;
        off += count[q], total += rcount[q];
    }
    return total;
}

int64_t mpi_thread_places(int64_t *at, int threads, int *count)
{
    int64_t sum = 0;
    for (int q = 0; q < mpi_np; q++)
        for (int t = 0; t < threads; t++) {
            int64_t c = at[(size_t)t * (size_t)mpi_np + q];
            at[(size_t)t * (size_t)mpi_np + q] = sum;
            sum += c;
            count[q] += (int)c;
        }
    return sum;
}

void mpi_alltoallv_into(const void *out, const int *count, const int *sd, void *in, const int *rcount,
                        const int *rd, size_t size)
{
    MPI_Datatype t;
    MPI_Type_contiguous((int)size, MPI_BYTE, &t);
    MPI_Type_commit(&t);
    MPI_Alltoallv(out, count, sd, t, in, rcount, rd, t, MPI_COMM_WORLD);
    MPI_Type_free(&t);
}

void *mpi_alltoallv(const void *out, const int *count, const int *rcount, size_t size, int64_t *got)
{
    int np = mpi_np, *sd = sim_calloc((size_t)np, sizeof *sd), *rd = sim_calloc((size_t)np, sizeof *rd);
    int64_t total = mpi_displacements(count, rcount, sd, rd);
    char *in = sim_realloc(NULL, (size_t)(total ? total : 1), size);
    mpi_alltoallv_into(out, count, sd, in, rcount, rd, size);
    free(sd), free(rd);
    *got = total;
    return in;
}

int mpi_pass_threads(int threads, int64_t n)
{
    return n < 4096 || threads < 1 ? 1 : threads;
}

void mpi_parallel(int threads, int64_t tasks, void (*task)(void *ctx, int64_t k), void *ctx)
{
    int nt = threads > 0 ? threads : 1;
#pragma omp parallel for schedule(dynamic, 1) num_threads(nt)
    for (int64_t k = 0; k < tasks; k++) task(ctx, k);
}
