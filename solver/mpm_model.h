/*
 * mpm_model.h - the constitutive models' interface (mpm_model.c): the
 * per-material constants (their types in mpm_model_types.h), the
 * operations each model provides
 * (mpm_model_ops: the direct update, the block update, the stress point,
 * the stored energy) and what it needs allocated, the block update's
 * state, and the models' shared functions (Jaumann rate, det F,
 * neo-Hookean stress, the J2 point update, the elastic stored energy).
 * The frictional models' integrators are in mpm_plastic.h.
 */
#ifndef MPM_MODEL_H
#define MPM_MODEL_H

#include "mpm_model_types.h"

/* (struct mpm_thread_out: mpm_kernels_types.h) */
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

/* The integrator's parameters of a material whose model needs
 * MPM_NEED_INTEGRATOR (angles to radians, mpm_plastic_init()); 0 or
 * MPM_EINVAL naming materials[i]'s field.  The caller has checked d with
 * mpm_material_check(). */
int mpm_model_plastic(const mpm_material_desc *d, int dim, size_t i, mpm_plastic_params *pl,
                      mpm_error *err);

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
