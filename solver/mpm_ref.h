/*
 * mpm_ref.h - the REFERENCE kernel family (mpm_ref.c), private to the
 * solver: the check of mpm_case.kernel_family, the switch a simulation
 * makes at creation to run it, and its step.  mpm_sim.c calls these at its
 * two dispatch points (mpm_sim_new(), mpm_sim_step()), mpm_case.c the
 * check; nothing else knows the family.  After mpm_internal.h.
 */
#ifndef MPM_REF_H
#define MPM_REF_H

#include "mpm_internal.h"

/* 0 when c->kernel_family is FAST or REFERENCE (REFERENCE runs every case
 * the fast families run), else MPM_EINVAL naming "kernel_family". */
int mpm_ref_check(const mpm_case *c, mpm_error *err);

/* Makes a simulation being created run the reference family: one thread,
 * a grid of momenta (not velocities), and every fast-path switch off (the
 * AVX2 kernels, fused steps, Drucker-Prager lanes, elastic lanes).  Called
 * by mpm_sim_new() before it allocates the per-thread buffers. */
void mpm_ref_init(mpm_sim *s);

/* One explicit step of s with the reference family: P2G, the grid update
 * with the boundary conditions and loads, G2P and the stress update of
 * s->update and s->transfer.  Fills tout[0]'s checks (first bad particle,
 * largest |v|^2) and work sums as the fast passes do; mpm_sim_step() does
 * the rest (time, guard, failure). */
void mpm_ref_step(mpm_sim *s);

#endif
