/* streams.cu (./bench.sh gpu-streams): the memory streams of cuda's move of a gas, alone. A pass over n slots
 * reads what the move reads of a disk flying free (position, velocity: 16 bytes each; partner: 4) and writes
 * what it writes (position, velocity; cell key: 4; wall and best keys: 8 each; partner), with no other work:
 * the time the move's bytes take at the device's bandwidth, its floor. Beside it, two passes that write less
 * (the position and velocity alone; without the wall and best keys). Each is timed over 50 passes after 3,
 * at 4 blocks of 256 threads a multiprocessor (the move's) and at 8.
 * Usage: streams [N] (default 1e7). */
#include <cuda_runtime.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

typedef struct {
    double2 *pos0, *vel0, *pos1, *vel1;
    int32_t *partner;
    uint32_t *key;
    uint64_t *wall, *best;
} Streams;

/* WRITES: 0 the move's, 1 position and velocity, 2 the move's less the wall and best keys. The stores
 * depend on the loads, so that none is dropped. */
template <int WRITES>
__global__ void __launch_bounds__(256) pass_kernel(Streams st, int64_t n)
{
    for (int64_t s = (int64_t)blockIdx.x * blockDim.x + threadIdx.x; s < n; s += (int64_t)gridDim.x * blockDim.x) {
        double2 p = st.pos0[s], v = st.vel0[s];
        int32_t o = st.partner[s];
        p.x += v.x, p.y += v.y;
        st.pos1[s] = p, st.vel1[s] = v;
        if (WRITES == 1) {
            if (o == INT32_MAX) st.key[s] = 0; /* never: keeps the load */
            continue;
        }
        st.key[s] = (uint32_t)(p.x * 7.0) + (uint32_t)o;
        st.partner[s] = -1;
        if (WRITES == 0) st.wall[s] = (uint64_t)o, st.best[s] = (uint64_t)o;
    }
}

static void check(cudaError_t e, const char *what)
{
    if (e != cudaSuccess) {
        fprintf(stderr, "streams: %s: %s\n", what, cudaGetErrorString(e));
        exit(1);
    }
}

int main(int argc, char **argv)
{
    int64_t n = argc > 1 ? atoll(argv[1]) : 10000000;
    Streams st;
    check(cudaMalloc(&st.pos0, n * 16), "cudaMalloc");
    check(cudaMalloc(&st.vel0, n * 16), "cudaMalloc");
    check(cudaMalloc(&st.pos1, n * 16), "cudaMalloc");
    check(cudaMalloc(&st.vel1, n * 16), "cudaMalloc");
    check(cudaMalloc(&st.partner, n * 4), "cudaMalloc");
    check(cudaMalloc(&st.key, n * 4), "cudaMalloc");
    check(cudaMalloc(&st.wall, n * 8), "cudaMalloc");
    check(cudaMalloc(&st.best, n * 8), "cudaMalloc");
    check(cudaMemset(st.pos0, 0, n * 16), "cudaMemset");
    check(cudaMemset(st.vel0, 0, n * 16), "cudaMemset");
    check(cudaMemset(st.partner, 0, n * 4), "cudaMemset");
    int sms = 0;
    check(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, 0), "cudaDeviceGetAttribute");
    cudaEvent_t e0, e1;
    check(cudaEventCreate(&e0), "cudaEventCreate");
    check(cudaEventCreate(&e1), "cudaEventCreate");
    static const char *const name[3] = {"the move's streams (36 bytes read, 56 written a slot)",
                                        "position and velocity (36 read, 32 written)",
                                        "without the wall and best keys (36 read, 40 written)"};
    static const double bytes[3] = {92, 68, 76};
    void (*kernel[3])(Streams, int64_t) = {pass_kernel<0>, pass_kernel<1>, pass_kernel<2>};
    printf("# streams: N = %lld, %d multiprocessors\n", (long long)n, sms);
    for (int per = 4; per <= 8; per += 4)
        for (int m = 0; m < 3; m++) {
            for (int r = 0; r < 3; r++) kernel[m]<<<sms * per, 256>>>(st, n);
            check(cudaEventRecord(e0), "cudaEventRecord");
            for (int r = 0; r < 50; r++) kernel[m]<<<sms * per, 256>>>(st, n);
            check(cudaEventRecord(e1), "cudaEventRecord");
            check(cudaEventSynchronize(e1), "cudaEventSynchronize");
            float ms = 0;
            check(cudaEventElapsedTime(&ms, e0, e1), "cudaEventElapsedTime");
            double us = ms * 1000.0 / 50;
            printf("%d blocks a multiprocessor, %s: %.1f us a pass, %.2f TB/s\n", per, name[m], us,
                   bytes[m] * (double)n / us / 1e6);
        }
    return 0;
}
