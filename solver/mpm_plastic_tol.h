/*
 * mpm_plastic_tol.h - the stress-point integrators' tolerances and limits,
 * shared by the scalar update (mpm_plastic.c) and Drucker-Prager's lanes
 * (mpm_plastic_avx2.c), which must give the same bits.  Private to those
 * two files.
 */
#ifndef MPM_PLASTIC_TOL_H
#define MPM_PLASTIC_TOL_H

#define SQRT3 1.7320508075688772935
#define LTOL 1e-6      /* Sloan's unloading tolerance on cos theta */
#define NSUB 10        /* subintervals of the unloading search */
#define DT_MIN 1e-6    /* smallest substep, as a fraction of the plastic increment */
#define PEG_MAXIT 200  /* Pegasus iterations */
#define DRIFT_MAXIT 10 /* drift corrections per substep */
#define MC_TOL 1e-10   /* the principal return's admissibility check, relative */
#define RET_TOL 1e-12  /* a multiplier this far below 0 (relative) counts as 0 */
#define TINY_REL 1e-14 /* sqrt(J2) below this (relative) is the cone's axis */
#define R_MIN 1e-16    /* Sloan's EPS: the smallest relative error estimate */
#define FY_TOL 1e-6    /* the first yield point (for the dissipation only), relative */

#endif
