/* mpi_halo.h: which ranks get a copy of an own disk for a step (its halo), decided alike by mpi.c on a
 * rank's CPU and by mpi_cuda.cu on its GPU, from one view of the strips that the step's halo_reach set. A
 * disk is copied to every other rank whose strip lies within the reach of its centre x: in the box, the
 * strips from the owner of x - reach to that of x + reach; in the periodic box, around the torus, and
 * every rank whose strip holds the whole torus. Plain C, compiled by mpicc and nvcc alike. */
#ifndef MPI_HALO_H_SIM
#define MPI_HALO_H_SIM

#include "common.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    const double *cut;  /* np + 1 cuts (mpi_cut, or the GPU's copy of them) */
    const char *near;   /* the periodic box: by rank, whether a neighbour */
    const char *whole;  /* the periodic box: by rank, whether its strip holds the whole torus */
    double reach, L;
    int me, np;
    int nlo, nhi;       /* the neighbours in the box (the periodic box: every rank) */
    int periodic, any_whole;
} HaloView;

/* The rank whose strip [cut[q], cut[q + 1]) holds x: 0 below the box, np - 1 above it. */
static inline SIM_HD int strip_owner(const double *cut, int me, int np, double x)
{
    if (x >= cut[me] && x < cut[me + 1]) return me; /* most disks stay */
    int lo = 0, hi = np - 1; /* the last q with cut[q] <= x */
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (cut[mid] <= x) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

/* The distance from x to strip q around the torus of side L (0 inside it). */
static inline SIM_HD double strip_gap_torus(const double *cut, double x, int q, double L)
{
    double best = INFINITY;
    for (int k = -1; k <= 1; k++) {
        double y = x + k * L, d = y < cut[q] ? cut[q] - y : (y >= cut[q + 1] ? y - cut[q + 1] : 0);
        if (d < best) best = d;
    }
    return best;
}

/* Whether an own disk at x goes nowhere: within the strip by more than the reach (the test that
 * leaves out all but a strip's edges), and no rank holds the whole torus. */
static inline SIM_HD int halo_inside(const HaloView *h, double x)
{
    return !h->any_whole && x > h->cut[h->me] + h->reach && x < h->cut[h->me + 1] - h->reach;
}

/* The ranks *lo .. *hi among which halo_takes picks the copies of the own disk at x; returns 0 where
 * the box's span reaches beyond the neighbours, which never happens (the caller stops). */
static inline SIM_HD int halo_span(const HaloView *h, double x, int *lo, int *hi)
{
    if (h->periodic) {
        *lo = 0, *hi = h->np - 1;
        return 1;
    }
    *lo = strip_owner(h->cut, h->me, h->np, x - h->reach);
    *hi = strip_owner(h->cut, h->me, h->np, x + h->reach);
    return *lo >= h->nlo && *hi <= h->nhi;
}

/* Whether rank k of halo_span's gets a copy of the own disk at x. */
static inline SIM_HD int halo_takes(const HaloView *h, double x, int k)
{
    if (k == h->me) return 0;
    if (!h->periodic) return 1;
    return h->near[k] && (h->whole[k] || strip_gap_torus(h->cut, x, k, h->L) <= h->reach);
}

#ifdef __cplusplus
}
#endif

#endif
