/*
 * mpm_model_types.h - the constitutive models' types: the per-material
 * constants (mpm_mat_params), a block update's arguments (mpm_model_blk)
 * and a model's operations (struct mpm_model_ops, one object per model
 * in mpm_model.c, mpm_material_ops.h).  struct mpm_sim holds them
 * (mpm_internal.h); the models' functions are in mpm_model.h.  This
 * header declares no function, so that mpm_internal.h can include it
 * without a circle.
 */
#ifndef MPM_MODEL_TYPES_H
#define MPM_MODEL_TYPES_H

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

#endif
