/* state.c: the bottom layer's services: messages that end the run, memory, the clock, and the
 * state's arrays. Everything above (exact.h, io.c, the backends) may call them; they call nothing
 * of the layers above. */
#define _POSIX_C_SOURCE 200809L
#include "common.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

const char *sim_program = "sim";

/* ==== messages, memory and clocks ==================================================================== */

void sim_fail(const char *fmt, ...)
{
    va_list ap;
    fprintf(stderr, "%s: ", sim_program);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    exit(1);
}

void *sim_calloc(size_t count, size_t size)
{
    if (count == 0) count = 1;
    if (count > SIZE_MAX / size) sim_fail("out of memory (%zu x %zu bytes)", count, size);
    void *p = calloc(count, size);
    if (!p) sim_fail("out of memory (%zu x %zu bytes)", count, size);
    return p;
}

/* Where the records start decided, run to run, whether two threads' hot fields shared a line: the
 * heap's layout moved with unrelated allocations, and the sample's binning on two threads with it by
 * a tenth. */
void *sim_calloc_lines(size_t count, size_t size)
{
    if (count == 0) count = 1;
    if (count > SIZE_MAX / size) sim_fail("out of memory (%zu x %zu bytes)", count, size);
    void *p = NULL;
    if (posix_memalign(&p, 64, count * size) != 0) sim_fail("out of memory (%zu x %zu bytes)", count, size);
    memset(p, 0, count * size);
    return p;
}

void *sim_realloc(void *ptr, size_t count, size_t size)
{
    if (count == 0) count = 1;
    if (count > SIZE_MAX / size) sim_fail("out of memory (%zu x %zu bytes)", count, size);
    void *p = realloc(ptr, count * size);
    if (!p) sim_fail("out of memory (%zu x %zu bytes)", count, size);
    return p;
}

void *sim_grow(void *ptr, size_t *cap, size_t need, size_t size)
{
    if (need <= *cap) return ptr;
    size_t c = *cap ? *cap : 64;
    while (c < need) c *= 2;
    void *p = realloc(ptr, c * size);
    if (!p) sim_fail("out of memory (%zu x %zu bytes)", c, size);
    *cap = c;
    return p;
}

double sim_clock(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int sim_alloc(Sim *sim, int64_t n)
{
    size_t m = (size_t)n;
    memset(sim, 0, sizeof *sim);
    sim->x = malloc(m * sizeof(real));
    sim->y = malloc(m * sizeof(real));
    sim->vx = malloc(m * sizeof(real));
    sim->vy = malloc(m * sizeof(real));
    sim->pc = calloc(m, sizeof(int32_t));
    sim->wc = calloc(m, sizeof(int32_t));
    if (sim->x && sim->y && sim->vx && sim->vy && sim->pc && sim->wc) return 0;
    sim_free(sim);
    return -1;
}

void sim_free(Sim *sim)
{
    free(sim->x);
    free(sim->y);
    free(sim->vx);
    free(sim->vy);
    free(sim->pc);
    free(sim->wc);
    free(sim->wi);
    free(sim->last);
    memset(sim, 0, sizeof *sim);
}

