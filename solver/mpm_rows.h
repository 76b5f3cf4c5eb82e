/*
 * mpm_rows.h - the active rows and the node passes (mpm_rows.c): the
 * row extents the particles' supports touch, each thread's share of the
 * active nodes, the scatter targets and the fused steps' next-step
 * buffer, and the node pass that reduces the private grids and applies
 * the node operations (MPM_N_*, mpm_internal.h).  Used by the step
 * (mpm_sim.c), the sort and the checkpoint.  Tests: t_rows.c.
 */
#ifndef MPM_ROWS_H
#define MPM_ROWS_H

#include "mpm_internal.h"

/* Allocates the row extents (all empty) of the simulation and of each
 * thread, and the sort's row offsets.  Returns 0 or MPM_ENOMEM. */
int mpm_rows_init(mpm_sim *s);
/* Makes the active rows those the last particle pass recorded (serial). */
void mpm_rows_update(mpm_sim *s);

/* The share of the active nodes (as numbered by acc, 0 .. nact) that a
 * node pass gives thread tid: [*n0, *n1), the threads' shares in order
 * and together all of them; weighted (a pass that reduces the private
 * grids, 2 threads or more): the work units of wacc split evenly, else
 * the nodes. */
void mpm_node_share(const mpm_sim *s, int tid, int weighted, size_t *n0, size_t *n1);

/* Thread tid's scatter target, zeroed over its rows for the fields named
 * (a private buffer's P2G fields and s->tshare are all zero already). */
mpm_gridbuf *mpm_scatter_buf(mpm_sim *s, int tid, int fields);
/* Fused steps: swaps the main grid's P2G fields with thread 0's next-step
 * buffer (serial, between steps), which then holds the last grid until
 * the step's first node pass zeroes it (MPM_N_Z0). */
void mpm_rows_swap_next(mpm_sim *s);
/* Drops a next-step scatter that will not be used (the private buffers'
 * P2G fields zeroed over the rows they were scattered into); serial. */
void mpm_rows_drop_next(mpm_sim *s);
/* A node pass over thread tid's share of the active nodes: ops is MPM_F_*
 * fields to reduce | MPM_N_* operations. */
void mpm_node_pass(mpm_sim *s, int tid, int ops);
/* Phase: records the support box and row extents of the thread's slice. */
void mpm_ph_bbox(mpm_sim *s, int tid);

#endif
