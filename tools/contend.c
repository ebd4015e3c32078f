/* tools/contend.c: how much of a core one process keeps when others run beside it (./bench.sh mpi,
 * part contention). Weak scaling compares a rank among P with one alone; what the ranks share (memory
 * bandwidth, the last-level cache, the clock the package allows) bounds it whatever the program does.
 *
 * usage: tools/contend compute|issue|cache|memory
 *   compute  two chains of dependent floating-point operations: registers only, bound by the latency of
 *            each operation, so a second hardware thread on the same core barely slows it
 *   issue    twelve independent chains: bound by how many operations a core issues per cycle, so it
 *            loses about half its speed to a second hardware thread on the same core
 *   cache    a sweep over a 256 KB array, 400000 times: from the core's own L2
 *   memory   a sweep reading one double per 64-byte line of a 512 MB array, 10 times: all from DRAM
 * Prints the seconds the loop took (and a checksum that keeps the compiler from dropping it).
 */
#define _POSIX_C_SOURCE 200809L

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* n doubles 0, 1, 2, ...; exits when memory runs out */
static double *filled(size_t n)
{
    double *x = malloc(n * sizeof *x);
    if (!x) {
        fprintf(stderr, "contend: out of memory\n");
        exit(1);
    }
    for (size_t i = 0; i < n; i++) x[i] = (double)i;
    return x;
}

int main(int argc, char **argv)
{
    const char *kind = argc == 2 ? argv[1] : "";
    if (strcmp(kind, "compute") != 0 && strcmp(kind, "issue") != 0 && strcmp(kind, "cache") != 0 &&
        strcmp(kind, "memory") != 0) {
        fprintf(stderr, "usage: tools/contend compute|issue|cache|memory\n");
        return 2;
    }
    double t0, sum;
    if (strcmp(kind, "compute") == 0) {
        double a = 1, b = 1;
        t0 = now();
        for (long i = 0; i < 400000000L; i++) {
            a = a * 1.0000001 + 1e-9;
            b = b * 0.9999999 - 1e-9;
        }
        sum = a + b;
    } else if (strcmp(kind, "issue") == 0) {
        double c[12];
        for (int j = 0; j < 12; j++) c[j] = 1 + 1e-3 * j;
        t0 = now();
        for (long i = 0; i < 220000000L; i++)
            for (int j = 0; j < 12; j++) c[j] = c[j] * 0.9999999 + 1e-9;
        sum = 0;
        for (int j = 0; j < 12; j++) sum += c[j];
    } else if (strcmp(kind, "cache") == 0) {
        size_t n = (size_t)32 << 10; /* doubles: 256 KB */
        double *x = filled(n);
        double s4[4] = {0, 0, 0, 0};
        t0 = now();
        for (int r = 0; r < 400000; r++)
            for (size_t i = 0; i < n; i += 32) { /* four lines a turn, four chains */
                s4[0] += x[i];
                s4[1] += x[i + 8];
                s4[2] += x[i + 16];
                s4[3] += x[i + 24];
            }
        sum = s4[0] + s4[1] + s4[2] + s4[3];
        free(x);
    } else {
        size_t n = (size_t)64 << 20; /* doubles: 512 MB, beyond any cache */
        double *x = filled(n);
        sum = 0;
        t0 = now();
        for (int r = 0; r < 10; r++)
            for (size_t i = 0; i < n; i += 8) sum += x[i];
        free(x);
    }
    printf("%.4f %g\n", now() - t0, sum);
    return 0;
}
