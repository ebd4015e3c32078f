/* tools/contend.c: how much of a core one process keeps when others run beside it (./bench.sh mpi,
 * part contention). Weak scaling compares a rank among P with one alone; what the ranks share (memory
 * bandwidth, the last-level cache, the clock the package allows) bounds it whatever the program does.
 *
 * usage: tools/contend compute|memory
 *   compute  two chains of dependent floating-point operations: registers only, nothing shared
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

int main(int argc, char **argv)
{
    if (argc != 2 || (strcmp(argv[1], "compute") != 0 && strcmp(argv[1], "memory") != 0)) {
        fprintf(stderr, "usage: tools/contend compute|memory\n");
        return 2;
    }
    double t0, sum;
    if (strcmp(argv[1], "compute") == 0) {
        double a = 1, b = 1;
        t0 = now();
        for (long i = 0; i < 400000000L; i++) {
            a = a * 1.0000001 + 1e-9;
            b = b * 0.9999999 - 1e-9;
        }
        sum = a + b;
    } else {
        size_t n = (size_t)64 << 20; /* doubles: 512 MB, beyond any cache */
        double *x = malloc(n * sizeof *x);
        if (!x) {
            fprintf(stderr, "contend: out of memory\n");
            return 1;
        }
        for (size_t i = 0; i < n; i++) x[i] = (double)i;
        sum = 0;
        t0 = now();
        for (int r = 0; r < 10; r++)
            for (size_t i = 0; i < n; i += 8) sum += x[i];
        free(x);
    }
    printf("%.4f %g\n", now() - t0, sum);
    return 0;
}
