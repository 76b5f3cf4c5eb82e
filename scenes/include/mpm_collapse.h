/*
 * mpm_collapse.h - the plane-strain granular column collapse as a
 * ready-made run: a column of width d0 and height
 * h0 = a d0 against a frictionless back wall (x_lo roller: the symmetry
 * plane of Lube et al. 2005's half-column set-up, where the column stands
 * against the tank's end wall and a gate is lifted), on a rough base
 * (Coulomb friction on y_lo), under gravity, with a Drucker-Prager
 * (plane-strain match) or Mohr-Coulomb material, run until the deposit is
 * at rest; it measures the run-out and the final height and compares them
 * with the experimental fits of Lube et al. 2005 (Phys. Rev. E 72, 041301).
 * Shared by the test (tests/solver/t_collapse.c), the accuracy bench
 * (bench/accuracy/) and the throughput bench (bench/perf/); docs/accuracy.md,
 * "Granular column collapse".
 */
#ifndef MPM_COLLAPSE_H
#define MPM_COLLAPSE_H

#include "mpm.h"

typedef struct {
    double a;             /* aspect ratio h0 / d0 */
    double d0;            /* column width (m); 0: 0.1 */
    int cells;            /* cells across d0 (h = d0 / cells) */
    int ppc;              /* particles per cell per axis; 0: 2 */
    mpm_method method;    /* shape functions */
    mpm_model_kind model; /* DRUCKER_PRAGER or MOHR_COULOMB (LINEAR_ELASTIC for the
                             throughput bench's reference scene) */
    double phi;           /* friction angle (degrees); 0: 30 */
    double mu;            /* base friction coefficient; 0: tan(phi) */
    double t_max;         /* end time cap (s); 0: 8 sqrt(h0 / g) + 0.5 s */
    int threads;
} mpm_collapse_cfg;

typedef struct {
    double runout; /* (d_inf - d0) / d0 */
    double height; /* h_inf / d0 */
    double t_end;  /* when the run stopped (s) */
    long steps;
    int at_rest;   /* 1: K stayed below 5e-3 of the released potential for 0.1 s */
    double e_err;  /* max over the run of |K + S + P + W_p + W_f - E0| / (P0 - P_end) */
    double wp, wf; /* plastic and friction work at the end (J/m) */
    double e_drop; /* P0 - P_end (J/m) */
    size_t particles;
    double seconds; /* wall-clock time of the run */
} mpm_collapse_res;

/* The experimental fits of Lube et al. 2005 for the 2D (channel)
 * collapse, as quoted by Lagree, Staron & Popinet 2011 (J. Fluid Mech.
 * 686, 378, Eqs. 3.1-3.2): (d_inf - d0)/d0 = 1.2 a (a < 1.8),
 * 1.9 a^(2/3) (a > 2.8); h_inf/d0 = a (a < 1.15), a^(2/5) above.  In the
 * transition 1.8 < a < 2.8 the run-out is the mean of the two fits
 * (*band, if not NULL, receives half their difference). */
double mpm_collapse_ref_runout(double a, double *band);
double mpm_collapse_ref_height(double a);

/* Fills a case for cfg (arrays in the storage behind *buf, released with
 * mpm_collapse_free()).  Returns 0, or -1 when out of memory. */
typedef struct {
    mpm_case c;
    mpm_material_desc mat;
    mpm_body_desc body;
    mpm_friction_desc fr;
    double *x, *vol, *stress;
    double d0, h0, xmax;
} mpm_collapse_case;
int mpm_collapse_setup(const mpm_collapse_cfg *cfg, mpm_collapse_case *cc);
void mpm_collapse_free(mpm_collapse_case *cc);

/* Runs cfg to rest (or t_max) and measures.  Returns 0, or the solver's
 * negative MPM_E* code with err filled (NULL allowed); -MPM_ENOMEM style
 * codes pass through. */
int mpm_collapse_run(const mpm_collapse_cfg *cfg, mpm_collapse_res *r, mpm_error *err);

/* The deposit's run-out front and the height at the back wall of the n
 * particle positions x (2 per particle), particles of initial spacing dp:
 * the front is the largest x_p + dp/2 of the particles reached from the
 * wall without a gap wider than gap along x (particles thrown ahead of
 * the deposit do not count); the height is the largest y_p + dp/2 of the
 * particles with x_p < w. */
void mpm_collapse_measure(const double *x, size_t n, double dp, double gap, double w, double *front,
                          double *height);

#endif
