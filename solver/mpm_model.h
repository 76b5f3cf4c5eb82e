/*
 * mpm_model.h - the constitutive models' interface (mpm_model.c): the
 * per-material constants, the operations each model provides
 * (mpm_model_ops: the direct update, the block update, the stress point,
 * the stored energy) and what it needs allocated, the block update's
 * state, and the models' shared functions (Jaumann rate, det F,
 * neo-Hookean stress, the J2 point update, the elastic stored energy).
 * The frictional models' integrators are in mpm_plastic.h.
 */
#ifndef MPM_MODEL_H
#define MPM_MODEL_H

#include "mpm.h"
#include "mpm_material.h" /* the models' rows; typedef mpm_model_ops */
#include "mpm_particles.h"
#include "mpm_plastic.h"

/* Per-material constants for the constitutive models. */
typedef struct {
    double E, nu, rho, lambda, mu, c; /* c: p-wave speed */
    double K;                         /* bulk modulus lambda + 2 mu / 3 */
    double sy0, H;                    /* VON_MISES: yield stress, hardening modulus */
    const mpm_model_ops *ops;         /* the material's model */
    /* DRUCKER_PRAGER, MOHR_COULOMB: mpm_plastic_init()'s parameters (in
     * mpm_sim.plp, so that this struct, which the elastic kernels index,
     * keeps its size); else NULL */
    const mpm_plastic_params *pl;
} mpm_mat_params;

/* Constitutive model interface.  A model's row of the material table
 * declares the per-particle state it needs (MPM_NEED_*), allocated at
 * creation only when a material of the case uses the model; its
 * operations:
 *   update  (linear elasticity only: the path of every earlier release,
 *           called directly when every material is linear elastic and the
 *           volume update is the default) the strain increments of
 *           particles [p0, p0 + n) in block-local arrays deps[c][0..n)
 *           update the particles' stress and strain;
 *   block   the general update of block slots [i0, i1) of the block
 *           starting at particle b0 (particle b0 + i, increments
 *           b->deps[c][i], spins as in mpm_thread_out.deps); F is already
 *           updated (mpm_model_block());
 *   point   (rate-form models) the stress-point update: stress sig (Voigt,
 *           6 entries, tensor shears; 1D: sig[0] only, uniaxial stress;
 *           2D: plane strain, sig[2] = sigma_zz, deps[2] = 0), the strain
 *           increment deps, and the state epsp (equivalent plastic strain)
 *           and *yielded (set 1 when it flowed, else 0); adds the plastic
 *           work density sigma : d eps_p to *dwp.  Returns 0 or a negative
 *           MPM_E* code (DP, MC: MPM_EDIVERGED, state unchanged).  J2's
 *           block (rate_block()) applies the Jaumann rotation and calls
 *           it per particle; DP and MC have their own block
 *           (frictional_block(), which also counts the substeps and
 *           reports a failed update) and the same point function for
 *           callers of one point;
 *   energy  the stored (elastic) energy of particle p (not a density).
 * The model's name and needs are in its row of the material table
 * (mpm_material.h). */

typedef struct {
    const mpm_mat_params *mats;
    mpm_particles *P;
    double *const *deps; /* mpm_thread_out.deps */
    int dim;
    double wp; /* plastic work added (sum of sigma : d eps_p V) */
    /* frictional models (DP, MC): plastic updates, substeps, the most in
     * one update, the first particle whose update failed (SIZE_MAX) */
    long long nupd, nsub;
    int maxsub;
    size_t bad;
    /* tests: 1 takes every frictional particle through the general
     * per-particle path (rate_gather(), mpm_dp_trial(), rate_put()) that
     * the 2D and 3D blocks write out (t_mpm_frictional_block.c) */
    int general;
    /* 1: Drucker-Prager's updates that leave the elastic trial go to
     * mpm_dp_lanes() in queues of one material (mpm_sim.plan.dp_lanes) */
    int dp_lanes;
} mpm_model_blk;

struct mpm_model_ops {
    void (*update[3])(const mpm_mat_params *mats, mpm_particles *P, size_t p0, size_t n,
                      double *const deps[6]);
    void (*block)(mpm_model_blk *b, size_t b0, size_t i0, size_t i1);
    int (*point)(const mpm_mat_params *mp, int dim, double sig[6], const double deps[6],
                 double *epsp, int *yielded, double *dwp);
    double (*energy)(const mpm_mat_params *mp, const mpm_particles *P, int dim, size_t p);
};

/* (struct mpm_thread_out: mpm_kernels.h) */
typedef struct mpm_thread_out mpm_thread_out;
/* The general block update (mpm_sim.plan.general): F (f_block), the models
 * (one call per run of particles of one model), then the volume
 * (volmode); the plastic work into o->wplast.  deps: o->deps. */
void mpm_model_block(mpm_sim *s, mpm_thread_out *o, size_t b0, size_t nb);
/* Jaumann rotation of a stress (Voigt, tensor shears) by the spin
 * increment w = dt W (w[0] = W_xy, w[1] = W_yz, w[2] = W_xz):
 * sig <- sig + w sig - sig w (dim 2: w[0] only, sigma_zz unchanged). */
void mpm_jaumann(double sig[6], const double w[3], int dim);
/* det F of particle p (2D: F_zz = 1). */
double mpm_det_f(const mpm_particles *P, int dim, size_t p);
/* Neo-Hookean Cauchy stress of F (3x3; Voigt, tensor shears) and, W not
 * NULL, the stored energy per reference volume W(F). */
void mpm_neo_hookean_stress(const mpm_mat_params *mp, const double F[3][3], double sig[6],
                            double *W);
/* The J2 point update (mpm_model_ops.point of VON_MISES): closed-form
 * radial return with linear isotropic hardening. */
int mpm_j2_point(const mpm_mat_params *mp, int dim, double sig[6], const double deps[6],
                 double *epsp, int *yielded, double *dwp);
/* Elastic stored energy density 1/2 sigma : C^-1 : sigma (1D: sigma^2/2E). */
double mpm_elastic_stored(const mpm_mat_params *mp, const double sig[6], int dim);

/* The model's operations (its row's, mpm_material_table.c), or NULL. */
const mpm_model_ops *mpm_model_get(mpm_model_kind kind);
/* The integrator's parameters of a material whose model needs
 * MPM_NEED_INTEGRATOR (angles to radians, mpm_plastic_init()); 0 or
 * MPM_EINVAL naming materials[i]'s field.  The caller has checked d with
 * mpm_material_check(). */
int mpm_model_plastic(const mpm_material_desc *d, int dim, size_t i, mpm_plastic_params *pl,
                      mpm_error *err);
/* The derived constants of material d (checked by mpm_material_check()). */
void mpm_model_params(const mpm_material_desc *d, int dim, mpm_mat_params *out);

/* sigma_zz of 2D particle p of material mp: stored, or, without the array
 * (mpm_particles.sig), plane strain linear elasticity's nu (sigma_xx +
 * sigma_yy) */
static inline double mpm_sig_zz(const mpm_mat_params *mp, const mpm_particles *P, size_t p)
{
    return P->sig[2] ? P->sig[2][p] : mp->nu * (P->sig[0][p] + P->sig[1][p]);
}

/* The 6 Voigt stress components of particle p (material mp): those not
 * stored are 0, 2D's sigma_zz is mpm_sig_zz(). */
static inline void mpm_particle_stress(const mpm_mat_params *mp, const mpm_particles *P, int dim,
                                       size_t p, double sig[6])
{
    for (int c = 0; c < 6; c++) sig[c] = c < MPM_NCOMP(dim) && P->sig[c] ? P->sig[c][p] : 0.0;
    if (dim == 2) sig[2] = mpm_sig_zz(mp, P, p);
}

/* sigma : eps of particle p (Voigt: shears twice; 2D plane strain has no
 * eps_zz array, its term is zero).  Without a strain record (P.eps NULL:
 * every material elastic from a zero stress, mpm_sim.c) the strain is
 * C^-1 sigma of the particle's material, and sigma : eps is twice
 * mpm_elastic_stored() (equal up to round-off to the record's sum). */
static inline double mpm_strain_density(const mpm_mat_params *mats, const mpm_particles *P, int dim,
                                        size_t p)
{
    if (!P->eps[0]) {
        const mpm_mat_params *mp = &mats[P->mat[p]];
        double sig[6];
        mpm_particle_stress(mp, P, dim, p, sig);
        return 2.0 * mpm_elastic_stored(mp, sig, dim);
    }
    double se = 0;
    for (int c = 0; c < MPM_NCOMP(dim); c++)
        if (P->eps[c]) se += mpm_rn((c < 3 ? 1.0 : 2.0) * P->sig[c][p] * P->eps[c][p]);
    return se;
}

#endif
