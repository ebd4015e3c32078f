/* omp_team.h: the OpenMP team's start (omp_team.c) */
#ifndef OMP_TEAM_H
#define OMP_TEAM_H

/* Starts the team of `threads` threads, each moved to a core of its own, before the first parallel
 * region that works; once per process, later calls return at once. */
void team_start(int threads);

#endif
