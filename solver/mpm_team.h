/*
 * mpm_team.h - the thread team that runs a simulation's passes
 * (mpm_team.c): its barrier (mpm_bar), starting and stopping the team,
 * running a phase on it, and mpm_team_sync(), the barrier between the
 * passes of a phase.  The barrier's type and the even split of n items
 * among the threads (mpm_slice()) are in mpm_team_types.h, which struct
 * mpm_sim needs.
 */
#ifndef MPM_TEAM_H
#define MPM_TEAM_H

#include "mpm_internal.h"
#include "mpm_team_types.h"

/* 0, or -1 when the mutex or the condition variable cannot be made. */
int mpm_bar_init(mpm_bar *b, unsigned n);
void mpm_bar_destroy(mpm_bar *b);
void mpm_bar_wait(mpm_bar *b);

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

/* A barrier between the passes of one phase. */
static inline void mpm_team_sync(mpm_sim *s)
{
    if (s->nthreads > 1) mpm_bar_wait(&s->bar_end);
}

#endif
