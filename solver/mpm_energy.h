/*
 * mpm_energy.h - the energy sums and the divergence guard
 * (mpm_energy.c): the team phase that sums each thread's energies, their
 * combination in thread order, the cumulative works and the balance
 * error, and the guard that stops a diverging run.  Used by the step and
 * mpm_sim_energy() (mpm_sim.c).
 */
#ifndef MPM_ENERGY_H
#define MPM_ENERGY_H

#include "mpm_internal.h"

/* Phase: the energies of the thread's slice into its tout (all of them,
 * angular momentum included). */
void mpm_ph_energy(mpm_sim *s, int tid);
/* The partial sums in tout combined in thread order (external work and
 * total left out). */
void mpm_energy_sum(const mpm_sim *s, mpm_energy *e);
/* The guard: 0, or MPM_EDIVERGED with s->err set and s->failed. */
int mpm_guard(mpm_sim *s);
/* The cumulative works of the run into e (external, damping, and the
 * other helpers' dissipations), then the total and the balance error:
 * the one place they are computed (mpm_sim_energy() and the guard). */
void mpm_energy_finish(const mpm_sim *s, mpm_energy *e);
/* The elastic energy stored by the initial stress (U0, see mpm_guard()). */
double mpm_initial_stress_energy(const mpm_sim *s);

#endif
