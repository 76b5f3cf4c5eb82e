/*
 * t_plastic.h - what the two test files of the plastic stress-point
 * integrators share (t_plastic.c, t_plastic_prop.c): a material's
 * parameters and the mixed-control driver (axial strain prescribed, the
 * lateral stress held at -p0 by a Newton iteration on the lateral strain).
 */
#ifndef T_MPM_PLASTIC_H
#define T_MPM_PLASTIC_H

#include "mpm_plastic.h"
#include "t.h"

#define TP_E 1e8 /* Pa */
#define TP_NU 0.3

/* One material point under the driver. */
typedef struct {
    double sig[6], eps[6]; /* stress, total strain */
    mpm_plastic_state st;
    double dis;     /* summed dissipation */
    double dl_prev; /* the last step's lateral strain increment (the next guess) */
    int nsteps, maxsub;
    long subs; /* summed substeps */
} tp_point;

/* Fills *p (E = TP_E, nu = TP_NU, angles in degrees) and runs
 * mpm_plastic_init(); its return. */
int tp_params(mpm_plastic_params *p, mpm_plastic_kind kind, mpm_dp_match match, double phi_deg,
              double psi_deg, double c, double tension);

/* An isotropic stress -p0 at rest. */
void tp_iso(tp_point *x, double p0);

/* One step: axial (xx) strain dea; sigma_yy held at -p0 by the lateral
 * strain, which is also applied to zz (triaxial: sigma_zz = sigma_yy by
 * symmetry) unless plane (deps_zz = 0).  0, or the update's error, or
 * < -99 when the Newton iteration fails. */
int tp_mixed_step(const mpm_plastic_params *P, tp_point *x, double dea, double p0, int plane);

#endif
