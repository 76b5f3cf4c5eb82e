/*
 * mpm_team_types.h - the thread team's types, which struct mpm_sim
 * holds: the barrier (mpm_bar; its functions and the team's in
 * mpm_team.h, mpm_team.c) and the even split of n items among the
 * threads (mpm_slice()).  It declares no function of a module, so that
 * mpm_internal.h can include it without a circle.  Tests: t_team.c.
 */
#ifndef MPM_TEAM_TYPES_H
#define MPM_TEAM_TYPES_H

#include "mpm.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>

/* The team's barrier (mpm_team.c).  A thread that arrives before the last
 * spins on the generation for up to MPM_BAR_SPIN_NS, then sleeps on the
 * condition variable; the last to arrive starts the next generation and
 * wakes the sleepers.  pthread_barrier_wait() sleeps at once, and waking
 * a sleeping thread takes tens to hundreds of microseconds on a VM: at 5
 * or 6 barriers a step, 2-thread steps of 10-20 ms lost several per cent
 * to it.  Arrivals order memory as a barrier does (what a thread wrote
 * before it is visible to every thread after it). */
#define MPM_BAR_SPIN_NS 200000L
typedef struct {
    atomic_uint count; /* arrivals in this generation */
    atomic_uint gen;   /* the generation; changes when all have arrived */
    unsigned n;        /* threads */
    pthread_mutex_t mu;
    pthread_cond_t cv;
} mpm_bar;
/* thread tid's share [a, b) of n items split evenly among T threads */
static inline void mpm_slice(size_t n, int T, int tid, size_t *a, size_t *b)
{
    *a = n * (size_t)tid / (size_t)T;
    *b = n * (size_t)(tid + 1) / (size_t)T;
}

#endif
