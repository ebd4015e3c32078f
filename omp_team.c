/* omp_team.c: starts the OpenMP team with its threads on cores of their own.
 *
 * Linux may place a new thread on its creator's core. libgomp's creator then spins at the team's
 * first barrier (about 2 ms of spinning before it sleeps) while the new thread waits for that same
 * core, and threads that share a core take turns until the scheduler's load balancing moves one, a
 * few milliseconds later. Binding the threads (OMP_PROC_BIND) avoids it but pins them for the whole
 * run, so that two runs at once crowd onto the same cores. Here each thread of the team pins itself
 * to a core of its own once, then widens its mask again: the scheduler leaves a running thread where
 * it is. Until every thread has moved, a waiting thread yields its core instead of spinning on it.
 * The assignment's sample on 2 cores, whole process: 0.1137 s against 0.1172 s before, best of 7 in
 * turn, the step loops alike (bench/omp_cpu_turns3.log).
 */
#define _GNU_SOURCE
#include "omp_team.h"

#include <omp.h>

#ifdef __linux__
#include <sched.h>

/* the k-th core of the set, counted from 0 */
static int core_at(const cpu_set_t *set, int k)
{
    for (int c = 0; c < CPU_SETSIZE; c++)
        if (CPU_ISSET(c, set) && k-- == 0) return c;
    return -1;
}

void team_start(int threads)
{
    static int started;
    if (started) return;
    started = 1;
    cpu_set_t all;
    if (sched_getaffinity(0, sizeof all, &all) != 0) return;
    int cores = CPU_COUNT(&all);
    if (threads < 2 || cores < 2) return;
    int arrived = 0;
#pragma omp parallel num_threads(threads)
    {
        cpu_set_t one;
        CPU_ZERO(&one);
        CPU_SET(core_at(&all, omp_get_thread_num() % cores), &one);
        if (sched_setaffinity(0, sizeof one, &one) == 0) sched_setaffinity(0, sizeof all, &all);
        /* until every thread has moved, a thread gives its core up rather than spin on it (the team
         * may have fewer threads than asked for: OMP_DYNAMIC, OMP_THREAD_LIMIT) */
        int team = omp_get_num_threads();
#pragma omp atomic update
        arrived++;
        for (;;) {
            int now;
#pragma omp atomic read
            now = arrived;
            if (now >= team) break;
            sched_yield();
        }
    }
}
#else
void team_start(int threads)
{
    (void)threads;
}
#endif
