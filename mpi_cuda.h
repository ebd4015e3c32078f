/* mpi_cuda.h: a disk on the wire between mpi's ranks, and the GPU side of a rank of mpi_cuda (mpi.c
 * built with MPI_CUDA, its device work in mpi_cuda.cu). mpi.c does all the talking between ranks; each
 * call below is the device's share of one of its phases, in the order a step calls them:
 *   gpu_rank_halo_out, gpu_rank_set_halo              the halo (the copies of other ranks' disks)
 *   gpu_rank_detect                                   the pair events of the own disks and copies
 *   gpu_rank_round, gpu_rank_accept                   the choice's rounds, keys exchanged between
 *   gpu_rank_move                                     the own disks moved, the leavers packed
 * Plain C on both sides: mpi.c is built by mpicc, mpi_cuda.cu by nvcc. */
#ifndef MPI_CUDA_H_SIM
#define MPI_CUDA_H_SIM

#include "common.h"
#include "mpi_halo.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A disk between ranks: D_LEN doubles (indices, counts and reals are exact in a double). */
enum { D_ID, D_X, D_Y, D_VX, D_VY, D_PC, D_WC, D_WI, D_LEN };

/* A disk's smallest live event key in a round of the choice, from its owner to the ranks that hold a
 * copy: cuda's (hi, lo) (cuda_state.cuh, PairEvent), and whether the disk is decided. */
typedef struct {
    uint64_t hi, lo, decided;
} GpuKey;

typedef struct GpuRank GpuRank;

/* The peer path (ranks of one node whose GPUs map each other's memory): each rank exports one device
 * region, its halo's records for the other ranks in rank order and, after them, two rounds' keys in
 * that order (rounds alternate between the two); a rank reads its copies and their keys from their
 * owners' regions. What a rank tells each neighbour of it as a step's halo goes out: */
typedef struct {
    int64_t count, offset; /* the records for that neighbour, and the first one's place in the region */
    int64_t cap, gen;      /* the region's records (and keys of each round), and how often it grew */
    char handle[64];       /* its cudaIpcMemHandle_t */
} GpuPeer;

/* The calls below whose host seconds gpu_rank_times sums (--stats), and their names. */
enum { GPU_HALO_OUT, GPU_HALO_IN, GPU_DETECT, GPU_ROUND, GPU_ACCEPT, GPU_MOVE, GPU_ADD, GPU_GET, GPU_CALLS };
#define GPU_CALL_NAMES_AND(...) \
    {"halo out", "halo in", "detect", "rounds", "accept", "move", "add", "get", __VA_ARGS__}

/* What a step's move reports: the disks that left the strip (records), the largest velocity component
 * of the own disks after it, its accepted events and pair tests. */
typedef struct {
    int64_t leavers;
    double vmax;
    uint64_t events, tests;
} GpuMoved;

/* The GPU of node-local rank `local` (of a node's ranks: device local mod the devices), for a run of
 * par (par->n disks in all ranks). */
GpuRank *gpu_rank_open(const Params *par, int local);
void gpu_rank_close(GpuRank *g);
/* The seconds the host has spent in each call so far, by GPU_HALO_OUT .. GPU_GET (the waits for the device
 * included: a call that reads the device's results waits for its work; the halo's and the disks' puts
 * and the accept pass return once launched) */
const double *gpu_rank_times(const GpuRank *g);
/* Steps so far whose own disks kept by the move before were keyed by it for the step's cells and only
 * counted (into reused[0]), and those binned anew, the grid ahead not fitting the step's (reused[1]);
 * halos that looked only at the own disks the move before listed near the cuts (reused[2]), and those
 * that looked at every own disk (reused[3]); moves done twice, their leavers having overflowed the
 * device's room for their records (reused[4]); searches done again, their events having overflowed the
 * event list (reused[5]); the pair events found in steps that settled the lone ones first (reused[6]), and
 * those of them left to the rounds (reused[7]); searches done again for a cell past 255 disks, whose counts
 * were 8-bit (reused[8]) */
void gpu_rank_reused(const GpuRank *g, uint64_t reused[9]);
/* n records become own disks (between steps) */
void gpu_rank_add_own(GpuRank *g, const double *rec, int64_t n);
/* The disks of the steps to come lie within x0 <= x <= x1 (around the box where periodic), if `on`: the
 * grid's table then holds that strip's cells, not the box's (GridLimits' slab; else the box's). */
void gpu_rank_slab(GpuRank *g, int on, double x0, double x1);
/* The buffers a step of the own disks takes, made before the steps (their largest velocity component
 * vmax sets the grid) */
void gpu_rank_ready(GpuRank *g, double vmax);
int64_t gpu_rank_own(const GpuRank *g);
/* the own disks as records into rec (own x D_LEN doubles), in slot order */
void gpu_rank_get(GpuRank *g, double *rec);
/* The copies of the own disks that other ranks get this step (halo_inside, halo_span and halo_takes of
 * h, whose arrays are the host's), listed and packed as records on the GPU: into scount[q] how many go
 * to rank q, into *nsend all of them; returns them in rank order (the rank's pinned buffer, valid until
 * the move), or NULL on the peer path (they stay in the rank's region). The rounds send the disks' keys
 * in this order. The device then bins the own disks for the step (largest velocity component vmax, the
 * slab as gpu_rank_slab last set it) while the records travel: it returns once they are on the host (or
 * in the region). */
const double *gpu_rank_halo_out(GpuRank *g, const HaloView *h, double vmax, int *scount, int64_t *nsend);
/* Room for n received records of the halo (the rank's pinned buffer, valid until the next call):
 * gpu_rank_set_halo takes them from there to the device with no copy on the host. */
double *gpu_rank_halo_in(GpuRank *g, int64_t n);
/* The copies received (got records) put after the own disks: the halo, in this order (gpu_rank_accept). */
void gpu_rank_set_halo(GpuRank *g, const double *in, int64_t got);
/* One step's pair events over the own disks and the halo, on the box's grid for largest velocity
 * component vmax (of every rank's disks), and the first round's passes behind them */
void gpu_rank_detect(GpuRank *g, double vmax);
/* A round of the choice (first: the first of the step): returns the pair events still live here, and
 * into *out the keys of the disks gpu_rank_halo_out sent, in its order (the rank's buffer; on the peer
 * path NULL: they stay in the region, read by the others' gpu_rank_accept once every rank has returned
 * from this call). */
int64_t gpu_rank_round(GpuRank *g, int first, const GpuKey **out);
/* Where the copies' keys are received each round, as their owners send them (the halo's order; the
 * rank's pinned buffer, valid from gpu_rank_set_halo to the move). */
GpuKey *gpu_rank_keys_in(GpuRank *g);
/* The copies' keys (gpu_rank_keys_in; on the peer path, from their owners' regions) onto the device,
 * then the round's accept pass. */
void gpu_rank_accept(GpuRank *g);
/* The peer path: this rank's region as gpu_rank_map takes it (count and offset left 0), made at the
 * first call */
void gpu_rank_export(GpuRank *g, GpuPeer *p);
/* Rank q's region mapped here as p describes it (the mapping kept while its generation lasts): returns
 * 0 where it cannot be mapped (the host path must then be taken) */
int gpu_rank_map(GpuRank *g, int q, int np, const GpuPeer *p);
/* The peer path on (after every other rank's region mapped) or off for the run */
void gpu_rank_peer(GpuRank *g, int on);
/* The peer path's halo: the copies from the n ranks from[] whose p[k] say where their records lie,
 * after the own disks in this order; the rounds read their keys from the same regions. */
void gpu_rank_set_halo_peer(GpuRank *g, const int *from, const GpuPeer *p, int n);
/* Before gpu_rank_close, on every rank, then a barrier: the other ranks' regions unmapped (a region must
 * not be freed while mapped elsewhere) */
void gpu_rank_unmap(GpuRank *g);
/* The own disks moved; those whose x left [c0, c1) (no bound below for the first strip, above for the
 * last) leave: their records into *leavers (the rank's buffer). The halo is dropped. The own disks kept
 * within reach (a bound on the next step's) of c0 or c1 are listed for the next halo, which looks at
 * those alone where its cuts are c0 and c1 and its reach no longer. */
void gpu_rank_move(GpuRank *g, double c0, double c1, int first, int last, double reach, GpuMoved *m,
                   const double **leavers);

#ifdef __cplusplus
}
#endif

#endif
