/*
 * mpm_particles.h - the particles' arrays (struct of arrays: field c of
 * particle p is P.field[c][p]), the stress components stored per
 * dimension, the constitutive block's size, and the small inline sums
 * over one particle that the kernels and the energy pass share (mpm_rn(),
 * the angular momentum).  Allocated and sorted by mpm_sim.c and
 * mpm_sort.c, filled by mpm_case.c (mpm_case_fill(), mpm_case.h).
 */
#ifndef MPM_PARTICLES_H
#define MPM_PARTICLES_H

#include "mpm.h"

#include <stdint.h>
#include <stdlib.h>

/* Stress and strain components stored per dimension: 1D xx; 2D plane strain
 * xx yy zz xy; 3D xx yy zz xy yz xz.  Component c is the Voigt index c.  In
 * 2D plane strain eps_zz is identically zero and nothing reads it, so
 * P.eps[2] is not allocated (NULL); sigma_zz is kept for the pressure. */
#define MPM_NCOMP(dim) ((dim) == 1 ? 1 : (dim) == 2 ? 4 : 6)

/* Particle block size for the constitutive update (scratch per thread). */
#define MPM_BLOCK 64

typedef struct {
    size_t n;
    double *x[3], *v[3]; /* position, velocity (dim arrays) */
    double *m, *vol;     /* mass, current volume */
    double *lp[3];       /* GMPM / CPDI half-width per axis (NULL for MPM);
                          * CPDI: the initial domain's, r_a0 = lp_a e_a */
    /* Deformation gradient, F_ij = F[i * dim + j][p] (dim * dim arrays, the
     * rest NULL), allocated only when mpm_needs_F() says the case reads it
     * (today: CPDI), else all NULL.  Initialised to I at creation; updated
     * F <- (I + dt L) F once a step by the pass that moves the particle,
     * with the full velocity gradient L of its gather (mpm_cpdi.c: USL and
     * MUSL the gather of the strain increment; USF the position pass, from
     * the velocity before the nodal update).  Sorted with the particles. */
    double *F[9];
    /* stress, strain (MPM_NCOMP(dim) arrays; 2D: eps[2] NULL).  The strain
     * record eps exists only when something reads it (mpm_sim.c
     * needs_strain(): a rate-form model's record, or a linear elastic
     * material with an initial stress); else all NULL, and the strain
     * energy comes from the stress (mpm_strain_density()).  2D plane
     * strain without a strain record with every material linear elastic:
     * sig[2] is NULL too, sigma_zz = nu (sigma_xx + sigma_yy) being
     * derived where it is read (mpm_sig_zz(); nothing in the step reads
     * it). */
    double *sig[6], *eps[6];
    /* Model state, allocated only when a material's model declares it
     * (mpm_model_ops.needs), else NULL; sorted with the particles:
     * epsp the equivalent plastic strain, yld 1.0 when the particle flowed
     * plastically in its last update (0.0 otherwise), vol0 the initial
     * volume (volume update DET_F). */
    double *epsp, *yld, *vol0;
    uint16_t *mat; /* material index */
    uint32_t *id;  /* creation index (particles are kept sorted by cell) */
    /* APIC only (NULL with FLIP): affine matrix B_ab = sum_i S_ip v_ia
     * (x_i - x_p)_b at B[3a + b] (a, b < dim; the others NULL) */
    double *B[9];
} mpm_particles;

/* x, rounded to a double where it stands.  In the AVX2+FMA build of the
 * kernels (mpm_kernels_*_avx2.c, -ffp-contract=fast) an empty asm that the
 * compiler must assume reads and rewrites x keeps a product from being
 * fused with the sum it feeds; the energy sums below use it, so that the
 * step's in-pass sums give the bits of the energy pass (built without
 * contraction) with either kernels.  Elsewhere it is x. */
static inline double mpm_rn(double x)
{
#if defined(MPM_KERNELS_VARIANT) && defined(__GNUC__) && defined(__x86_64__)
    __asm__("" : "+x"(x));
#endif
    return x;
}

/* Adds particle p's angular momentum about the origin, m x × v, to L (D:
 * the dimension; 2D adds to L[2] only, 1D adds nothing).  The energy sums
 * (esum_particle(), mpm_pass.h) take it for single particles; esum_block()
 * is the same expression in four lanes, so all give the same bits (a
 * change here must go there too: perf_energy_pass_matches_formulas
 * compares the two bit for bit).  Likewise mpm_angmom_add_affine() below
 * (its four lanes held to APIC's conservation by
 * apic_spinning_disk_conserves_angular_momentum). */
static inline void mpm_angmom_add(const mpm_particles *P, int D, size_t p, double m, double L[3])
{
    if (D == 2) {
        L[2] += mpm_rn(m * (mpm_rn(P->x[0][p] * P->v[1][p]) - mpm_rn(P->x[1][p] * P->v[0][p])));
    } else if (D == 3) {
        double x = P->x[0][p], y = P->x[1][p], z = P->x[2][p];
        double vx = P->v[0][p], vy = P->v[1][p], vz = P->v[2][p];
        L[0] += mpm_rn(m * (mpm_rn(y * vz) - mpm_rn(z * vy)));
        L[1] += mpm_rn(m * (mpm_rn(z * vx) - mpm_rn(x * vz)));
        L[2] += mpm_rn(m * (mpm_rn(x * vy) - mpm_rn(y * vx)));
    }
}

/* APIC: the spin of particle p's affine field, m eps : B^T (mpm.h,
 * mpm_energy.angular_momentum), added to L after mpm_angmom_add() by the
 * energy pass and the step's in-pass sums alike (the same bits). */
static inline void mpm_angmom_add_affine(const mpm_particles *P, int D, size_t p, double m,
                                         double L[3])
{
    if (D == 2) {
        L[2] += mpm_rn(m * (P->B[3][p] - P->B[1][p]));
    } else if (D == 3) {
        L[0] += mpm_rn(m * (P->B[7][p] - P->B[5][p]));
        L[1] += mpm_rn(m * (P->B[2][p] - P->B[6][p]));
        L[2] += mpm_rn(m * (P->B[3][p] - P->B[1][p]));
    }
}

/* n zeroed doubles (at least one) */
static inline double *mpm_dalloc(size_t n)
{
    return calloc(n ? n : 1, sizeof(double));
}

#endif
