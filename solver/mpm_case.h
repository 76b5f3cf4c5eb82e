/*
 * mpm_case.h - generating a checked case's particles (mpm_case.c, which
 * also holds the public mpm_case_check() of mpm.h).  Used by the
 * simulation's creation (mpm_sim.c).
 */
#ifndef MPM_CASE_H
#define MPM_CASE_H

#include "mpm_internal.h"

/* Writes the particles of a case that passed mpm_case_check() into P, whose
 * arrays are allocated for the count the check found (P->n), with material
 * constants mats, in one pass; *vmax (if not NULL) gets the largest initial
 * speed.  Returns 0, or MPM_EINVAL when the case no longer makes P->n
 * particles (nothing is written beyond them). */
int mpm_case_fill(const mpm_case *c, mpm_particles *P, const mpm_mat_params *mats, double *vmax,
                  mpm_error *err);

#endif
