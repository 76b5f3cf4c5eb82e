/*
 * mpm_team.h - the thread team that runs a simulation's passes
 * (mpm_team.c): its barrier (mpm_bar), starting and stopping the team,
 * running a phase on it, and the even split of n items among its threads.
 * mpm_team_sync(), which needs the simulation's barrier, is in
 * mpm_internal.h.
 */
#ifndef MPM_TEAM_H
#define MPM_TEAM_H

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
/* 0, or -1 when the mutex or the condition variable cannot be made. */
int mpm_bar_init(mpm_bar *b, unsigned n);
void mpm_bar_destroy(mpm_bar *b);
void mpm_bar_wait(mpm_bar *b);

/* thread tid's share [a, b) of n items split evenly among T threads */
static inline void mpm_slice(size_t n, int T, int tid, size_t *a, size_t *b)
{
    *a = n * (size_t)tid / (size_t)T;
    *b = n * (size_t)(tid + 1) / (size_t)T;
}

/* ---- the thread team (mpm_team.c) ----
 *
 * A team of nthreads (the caller's thread is thread 0) runs a phase: every
 * thread calls fn(s, tid) once, and mpm_team_run() returns when all have.
 * Inside a phase the threads meet at mpm_team_sync(). */
typedef void (*mpm_phase_fn)(mpm_sim *, int tid);

/* Runs fn on the team (serially when there is one thread). */
void mpm_team_run(mpm_sim *s, mpm_phase_fn fn);
/* Starts threads 1..nthreads-1.  Returns 0 or MPM_ENOMEM, after which the
 * started ones have been joined and the simulation stays serial. */
int mpm_team_start(mpm_sim *s);
/* Stops and joins the team and frees its synchronisation (destroy). */
void mpm_team_stop(mpm_sim *s);

#endif
