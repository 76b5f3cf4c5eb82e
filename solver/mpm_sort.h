/*
 * mpm_sort.h - sorting the particles by cell (mpm_sort.c): the serial
 * sort, the team's sort inside a phase, and the count of cell changes
 * that decides when the step sorts again (the intervals, MPM_SORT_*, are
 * in mpm_internal.h beside the state they govern).  Used by the step
 * (mpm_sim.c).  Tests: t_sort.c.
 */
#ifndef MPM_SORT_H
#define MPM_SORT_H

#include "mpm_internal.h"

/* Sorts the particles by cell over the active rows (stable; nothing moves
 * when they are in order already).  The rows stay valid. */
void mpm_sort_particles(mpm_sim *s);
/* The same inside a team phase, called by every thread: the keys and the
 * moves on the team, the counting sort on thread 0 between barriers; then
 * each thread records its slice's support box and rows (mpm_ph_bbox()).
 * Returns after a barrier. */
void mpm_sort_team(mpm_sim *s, int tid);
/* The cell changes along all the particles (a particle in another cell
 * than the one before it, the first one included) as the last moving pass
 * or mpm_ph_bbox() recorded them in mpm_thread_out.ncell, the same for
 * every thread count.  Serial. */
size_t mpm_sort_cell_changes(const mpm_sim *s);

#endif
