/*
 * mpm_plastic.h - stress-point integrators of the two perfectly plastic
 * pressure-dependent models: Drucker-Prager (non-associated,
 * with a tension cut-off and the three usual matchings to Mohr-Coulomb) and
 * Mohr-Coulomb (non-associated, tension cut-off, corners and apex).  Pure
 * functions of one material point: the solver calls mpm_plastic_update()
 * per particle per step with the strain increment of the step; nothing here
 * allocates, locks or keeps global state, so calls are thread-safe.
 *
 * Sign convention: the solver's, tension positive (compression negative).
 * Soil mechanics' formulas (compression positive) are written here with the
 * sign flipped: p = tr(sigma)/3 is the mean stress, tension positive; the
 * principal stresses are ordered s1 >= s2 >= s3, so s3 is the most
 * compressive.  Voigt order xx yy zz xy yz xz; stress components are the
 * tensor's; strain increments use TENSOR shear, deps_xy = (L_xy + L_yx) dt
 * / 2 (not the engineering gamma_xy = 2 deps_xy).
 *
 * Drucker-Prager (perfect plasticity, no hardening):
 *   f = sqrt(J2) + eta p - xi c,     g = sqrt(J2) + etag p  (potential),
 * with, for the matching to Mohr-Coulomb (phi friction, psi dilatancy):
 *   compression (outer cone, exact at triaxial compression):
 *     eta = 6 sin(phi) / (sqrt3 (3 - sin phi)),  xi = 6 cos(phi) / (sqrt3 (3 - sin phi)),
 *     etag = 6 sin(psi) / (sqrt3 (3 - sin psi));
 *   extension (inner cone, exact at triaxial extension): the same with 3 + sin;
 *   plane strain (exact at plane-strain failure for any psi, where the
 *     plastic strain rate out of plane vanishes):
 *     etag = sqrt3 sin(psi) / sqrt(3 + sin^2 psi),
 *     eta  = sin(phi) / (sqrt(1 - etag^2/3) + etag sin(phi)/3),
 *     xi   = cos(phi) (1 - eta etag/3) / sqrt(1 - etag^2/3);
 *     for psi = phi this is the familiar eta = 3 tan(phi)/sqrt(9 + 12 tan^2 phi),
 *     xi = 3/sqrt(9 + 12 tan^2 phi); the dilatancy ratio at failure is then
 *     MC's, d eps_v^p / d gamma^p = sin(psi).
 * The tension cut-off is a second surface p <= pt with pt = min(tension,
 * xi c / eta) (the cone's apex caps it), associated (purely volumetric
 * plastic flow).  An increment whose elastic trial has p > pt returns in
 * closed form: p = pt and the deviator kept, scaled back to the cone's
 * radius at pt when it lies outside (the corner of the two surfaces; at
 * pt = apex that is the apex).  Otherwise the cone is integrated by the
 * explicit scheme of Sloan, Abbo & Sheng 2001 (Engng Comput 18(1/2)
 * 121-194), in the order of its algorithms (its equation numbers were not
 * at hand; the steps are named instead): the elastic fraction alpha of the
 * increment by the Pegasus method; when the increment starts on the
 * surface, the elastic-plastic unloading check cos theta = a : D deps /
 * (|a| |D deps|) < -LTOL (1e-6) and then the search over NSUB = 10
 * subintervals before Pegasus; then the modified Euler scheme with local
 * error control on the plastic part: each substep takes two forward-Euler
 * estimates (dlam = a : D de / a : D b, 0 when unloading), accepts when the
 * relative error R = |dsig2 - dsig1| / (2 |sig|) <= tol, sizes the next
 * substep by q = 0.9 sqrt(tol/R) clamped to [0.1, 1.1] (to at most 1 right
 * after a rejection, dT >= dT_min = 1e-6); after each accepted substep the
 * yield-surface drift is corrected: the consistent correction along D b,
 * or the normal correction along a when the consistent one does not reduce
 * |f|, repeated until |f| <= ftol
 * (relative to the sum of the magnitudes of f's terms).  The dissipation
 * is summed by the trapezoidal rule on the multipliers, dlam sig : b(sig)
 * at both ends of a substep (>= 0 by construction).  An increment of about
 * a thousand yield strains or more (where explicit substepping is stiff)
 * may exhaust max_substeps: MPM_EDIVERGED, the stress untouched.
 *
 * Mohr-Coulomb (perfect plasticity):
 *   f = k s1 - s3 - sigc,  k = (1 + sin phi)/(1 - sin phi),  sigc = 2 c sqrt(k),
 *   g = m s1 - s3,         m = (1 + sin psi)/(1 - sin psi),
 * i.e. compression positive sigma_1' = k sigma_3' + 2 c sqrt(k); tension
 * cut-off s1 <= pt, pt = min(tension, sigc / (k - 1)) (the apex caps it).
 * It is NOT substepped: the return is in principal stress space (Clausen,
 * Damkilde & Andersen 2006/2007): the spectral decomposition of the elastic
 * trial, then the return to the plane, to an edge (the triaxial compression
 * corner s1 = s2 with the flows of the two planes k s1 - s3 and k s2 - s3;
 * the extension corner s2 = s3 with k s1 - s3 and k s1 - s2; the edges
 * with the cut-off planes), or to a point (the apex, the cut-off's
 * corners), whichever set of active surfaces gives non-negative
 * multipliers and an admissible, still ordered stress.  For perfect
 * plasticity with linear surfaces and fixed principal axes this closed form
 * IS the exact solution of the rate equations for the increment (the
 * multiplier is linear in the strain), so substepping would change nothing
 * but the cost; corners and apex are exact, not rounded.  The rotation of
 * the principal axes within an increment is, as in any return mapping,
 * taken at the trial's axes.  The closed-form returns (MC, the DP cut-off)
 * sum the dissipation by the trapezoidal rule between the first yield
 * point on the elastic trial path (Pegasus) and the returned stress, each
 * end's sig : deps_p clamped at 0 (exact on one plane with fixed axes).
 *
 * Left out: hardening/softening, a smoothed MC, a cap, rate dependence.
 */
#ifndef MPM_PLASTIC_H
#define MPM_PLASTIC_H

#include "mpm_error.h"

#include <math.h>
#include <stddef.h>
#include <stdint.h>

typedef enum { MPM_PLASTIC_DRUCKER_PRAGER = 0, MPM_PLASTIC_MOHR_COULOMB = 1 } mpm_plastic_kind;
typedef enum { MPM_DP_COMPRESSION = 0, MPM_DP_EXTENSION = 1, MPM_DP_PLANE_STRAIN = 2 } mpm_dp_match;

/* A material's parameters (the caller fills the first block) and the
 * constants mpm_plastic_init() derives from them (the second block). */
typedef struct {
    mpm_plastic_kind kind;
    double E, nu;       /* isotropic elasticity: E > 0, -1 < nu < 0.5 */
    double phi, psi, c; /* friction 0 <= phi < pi/2, dilatancy 0 <= psi <= phi (radians), cohesion
                           c >= 0; c > 0 or phi > 0 */
    double tension;     /* tension cut-off >= 0 (largest mean stress for DP, largest principal
                           stress for MC), capped at the apex; HUGE_VAL: the apex only */
    mpm_dp_match match; /* DP's matching to Mohr-Coulomb */
    double tol;         /* Sloan's relative error tolerance (DP), 0 < tol < 1; 0: 1e-4 */
    double ftol;        /* yield-surface tolerance (drift), relative; 0: 1e-8 */
    int max_substeps;   /* accepted + rejected substeps per update (DP); 0: 1000 */
    /* derived by mpm_plastic_init(): */
    double K, G, lam;       /* bulk, shear modulus, Lame's lambda */
    double eta, etag, xi;   /* DP: f = sqrt(J2) + eta p - xi c, g = sqrt(J2) + etag p */
    double kphi, mpsi, sgc; /* MC: k, m, sigc = 2 c sqrt(k) */
    double pt;              /* the tension cut-off, capped at the apex */
} mpm_plastic_params;

/* Checks the parameters and fills the derived constants: 0, or MPM_EINVAL
 * naming the field (youngs_modulus, poisson_ratio, friction_angle,
 * dilatancy_angle, cohesion, tension_cutoff, ...; the caller prefixes
 * materials[i] with mpm_error_prefix()) and its limit.  Call once per
 * material. */
int mpm_plastic_init(mpm_plastic_params *p, mpm_error *err);

/* Per-point state. */
typedef struct {
    double eps_p; /* accumulated equivalent deviatoric plastic strain sqrt(2/3 e^p : e^p) */
    int substeps; /* substeps the last update took: 0 elastic, 1 a closed-form return (MC, the
                     DP cut-off), else Sloan's accepted substeps (DP) */
    int yielded;  /* on the yield surface after the update */
} mpm_plastic_state;

/* Integrates the strain increment deps (Voigt, tensor shear) from the
 * stress sig (Voigt, tension positive; updated in place) and the state st.
 * Returns 0, or MPM_EDIVERGED (substeps exhausted, or a non-finite trial
 * stress; sig and st are then unchanged).  *dissip (may be NULL) receives
 * sigma : deps_p per unit volume for the increment, >= 0 up to round-off.
 * p must have been through mpm_plastic_init(). */
int mpm_plastic_update(const mpm_plastic_params *p, double sig[6], const double deps[6],
                       mpm_plastic_state *st, double *dissip);

/* Drucker-Prager's elastic trial: the first test of its update, here so
 * that a caller's particle loop takes the elastic case without a call (the
 * same operations in the same order as mpm_plastic_update(), so the same
 * bits).  De = D deps, tr = sig + De and *ftr = f(tr).  Returns
 * MPM_DP_ELASTIC when tr is admissible (finite, at or below the cut-off,
 * f(tr) <= ftol scale; *on_surface: f(tr) within ftol of 0), else what the
 * update must do: MPM_DP_TENSION (past the cut-off), MPM_DP_CONE (outside
 * the cone) or MPM_DP_NONFINITE (refuse). */
enum { MPM_DP_ELASTIC, MPM_DP_CONE, MPM_DP_TENSION, MPM_DP_NONFINITE };
static inline int mpm_dp_trial(const mpm_plastic_params *P, const double sig[6],
                               const double deps[6], double De[6], double tr[6], double *ftr,
                               int *on_surface)
{
    double etr = deps[0] + deps[1] + deps[2];
    for (int i = 0; i < 3; i++) De[i] = P->lam * etr + 2 * P->G * deps[i];
    for (int i = 3; i < 6; i++) De[i] = 2 * P->G * deps[i];
    int fin = 1;
    for (int i = 0; i < 6; i++) {
        tr[i] = sig[i] + De[i];
        fin &= isfinite(tr[i]) != 0;
    }
    if (!fin) return MPM_DP_NONFINITE;
    /* the mean stress, sqrt(J2) from the deviator, f and its scale */
    double p = (tr[0] + tr[1] + tr[2]) / 3, d[3];
    for (int i = 0; i < 3; i++) d[i] = tr[i] - p;
    double dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2] +
                2 * (tr[3] * tr[3] + tr[4] * tr[4] + tr[5] * tr[5]);
    double r = sqrt(0.5 * dd);
    double scale = r + fabs(P->eta * p) + P->xi * P->c;
    double f = r + P->eta * p - P->xi * P->c;
    *ftr = f;
    if (p > P->pt + P->ftol * (fabs(P->pt) + fabs(p))) return MPM_DP_TENSION;
    if (!(f <= P->ftol * scale)) return MPM_DP_CONE;
    *on_surface = f > -P->ftol * scale;
    return MPM_DP_ELASTIC;
}

/* The yield function at sig (the largest of the model's surfaces, in
 * stress units: <= 0 admissible) and the scale its tolerance is relative
 * to (*scale may be NULL): admissible within ftol means
 * f <= ftol * scale.  For tests and diagnostics. */
double mpm_plastic_yield(const mpm_plastic_params *p, const double sig[6], double *scale);

/* Principal stresses of the symmetric tensor sig (Voigt), descending, and
 * (vec may be NULL) the unit eigenvectors as vec[i][0..2] for value i. */
void mpm_plastic_principal(const double sig[6], double val[3], double vec[3][3]);

#endif
