/*
 * mpm_loads.h - essential boundary conditions, tractions and particle
 * forces (mpm_loads.c): the fixed nodes and their zeroing in the node
 * passes, the tractions' shares and their time functions, and the work of
 * the point forces over a step.  Used by the step (mpm_sim.c), the node
 * passes (mpm_rows.c), the reference family (mpm_ref.c) and the
 * checkpoint.
 */
#ifndef MPM_LOADS_H
#define MPM_LOADS_H

#include "mpm_internal.h"

/* The fixed nodes of the face masks and the node set.  0 or MPM_ENOMEM. */
int mpm_bc_build(mpm_sim *s, const mpm_bc_desc *bc);
/* BC1 / BC2: zeroes the fixed components of field over the flat nodes
 * first..last (one segment of a row). */
void mpm_bc_zero(const mpm_sim *s, double *const field[3], size_t first, size_t last);
/* The tractions' shares of the particles in their regions.  0 or
 * MPM_ENOMEM. */
int mpm_loads_build(mpm_sim *s, const mpm_case *c);
/* Before a step: the loaded particles' positions; after it: the work of
 * their forces over the step (external_work, external_work_abs). */
void mpm_loads_begin_step(mpm_sim *s);
void mpm_loads_end_step(mpm_sim *s);
/* mpm_sim_set_particle_forces() once f is checked (f NULL: zero).  0 or
 * MPM_ENOMEM. */
int mpm_loads_set_forces(mpm_sim *s, const double *f);
/* The switch mpm_loads_set_forces() makes at its first call: one load slot
 * per particle (load_p[i] = i), the tractions' shares kept in trac_f, the
 * forces those shares (pforces = 1); nothing when already done.  0 or
 * MPM_ENOMEM (nothing changed). */
int mpm_loads_per_particle(mpm_sim *s);

/* Time-varying tractions: the loads' forces at the step's midpoint time
 * (serial, before the step). */
void mpm_loads_update(mpm_sim *s);

#endif
