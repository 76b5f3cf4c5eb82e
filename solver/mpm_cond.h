/*
 * mpm_cond.h - prescribed velocities and Coulomb friction on grid faces
 * (mpm_cond.c): their check in the case, their node lists, and the node
 * passes that apply them (BC1 on q and q2, BC2 on f) summing their work.
 * The friction node's states (MPM_FRIC_*) are in mpm_internal.h beside
 * mpm_sim.fric_stick.  Used by the case check (mpm_case.c), the step
 * (mpm_sim.c), the node passes (mpm_rows.c) and mpm_ref.c.
 */
#ifndef MPM_COND_H
#define MPM_COND_H

#include "mpm_internal.h"

/* Checks c->prescribed and c->bc.friction (and that no direction is both
 * prescribed and fixed, prescribed twice, or on a friction face).  0 or
 * MPM_EINVAL naming the field. */
int mpm_cond_check(const mpm_case *c, mpm_error *err);
/* Builds the prescribed and friction node lists (after mpm_bc_build()).
 * 0 or MPM_ENOMEM. */
int mpm_cond_build(mpm_sim *s, const mpm_case *c);
void mpm_cond_free(mpm_sim *s);
/* Before a step (serial): the prescribed velocities at t^n and t^{n+1},
 * the per-thread work sums cleared. */
void mpm_cond_begin_step(mpm_sim *s);
/* After a step (serial): the per-thread work sums into the totals. */
void mpm_cond_end_step(mpm_sim *s);
/* Node passes over the flat nodes first..last: BC1 (q = m v(t^n)), BC1 on
 * MUSL's q2 (q2 = m v(t^{n+1}); a pressing friction node's tangential q2 =
 * its q^{n+1}), and BC2 (friction on the free rate of momentum, then f = m
 * (v(t^{n+1}) - v(t^n)) / dt), summing the work into tout[tid]; each
 * before the fixed DOFs' zeroing of the same field. */
void mpm_cond_bc1(const mpm_sim *s, size_t first, size_t last);
void mpm_cond_bc1q2(const mpm_sim *s, size_t first, size_t last);
void mpm_cond_bc2(mpm_sim *s, int tid, size_t first, size_t last);
/* whether flat node n lies on face f (2 d + side) as a face condition
 * covers it (ghost layers behind and beside the face included) */
int mpm_node_on_face(const mpm_sim *s, size_t n, int face);

#endif
