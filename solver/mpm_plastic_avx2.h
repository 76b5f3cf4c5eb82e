/*
 * mpm_plastic_avx2.h - Drucker-Prager's updates and elastic trials four
 * particles at a time in AVX2 lanes (mpm_plastic_avx2.c), bit for bit
 * what the scalar integrator of mpm_plastic.h gives.  Called by the
 * frictional blocks of mpm_model.c where the plan allows (plan.dp_lanes)
 * and by the lanes' test (t_dp_lanes.c).  The scalar integrator and its
 * parameters (mpm_plastic_params) are in mpm_plastic.h, which this header
 * includes; the lanes' own file depends on nothing else.
 */
#ifndef MPM_PLASTIC_AVX2_H
#define MPM_PLASTIC_AVX2_H

#include "mpm_plastic.h"

#include <stddef.h>
#include <stdint.h>

/* Drucker-Prager updates of n <= MPM_DP_LANES_MAX particles whose
 * elastic trial is not admissible (sig and de: n rows of 6, Voigt as
 * above; nc 6, or 4 where every row's components 4 and 5, yz and xz, are
 * zero, as in 1D and 2D: those are then neither read nor written), four
 * at a time in the lanes of AVX2 vectors
 * (mpm_plastic_avx2.c; only where MPM_HAVE_AVX2_KERNELS is defined and the
 * CPU has AVX2): for each particle i that takes the common paths (the
 * cone's substeps, the tension cut-off's closed form), ok[i] = 1, sig's row i the updated stress,
 * epq[i] the increment of eps_p, dis[i] the dissipation and nsub[i] the substeps, each bit for bit
 * what mpm_plastic_update() gives; ok[i] = 0 for one that takes a rarer
 * path (an unloading start, the normal drift correction, a divergence, a
 * cut-off met after the substeps) or whose trial is elastic, its row of
 * sig unchanged, for mpm_plastic_update(). */
#define MPM_DP_LANES_MAX 64
void mpm_dp_lanes(const mpm_plastic_params *P, int nc, size_t n, double *sig, const double *de,
                  double *epq, double *dis, int *nsub, unsigned char *ok);

/* Drucker-Prager's elastic trial of n <= MPM_DP_TRIAL_LANES_MAX (64: a bit
 * of the result each) plane-strain particles of one
 * material (mpm_model.c's 2D frictional block), four at a time in AVX2
 * lanes with the scalar loop's operations in its order (so its bits): e
 * the increments d_xx, d_yy, the spin w and d_xy; x the stresses xx, yy,
 * zz, xy (read, Jaumann-rotated, and for an admissible trial replaced by
 * it); q the strain record xx, yy, xy (the increment added where the trial
 * is admissible); yld the yield flag (1 where the admissible trial is on
 * the surface within ftol, else 0).  Returns the mask (bit i: particle i)
 * of the particles whose trial is not admissible (past the cut-off,
 * outside the cone or not finite): their x, q and yld are left as they
 * were, for the caller's plastic update.  Called only where the CPU has
 * AVX2 (mpm_sim.plan.dp_lanes); a build without the AVX2 kernels leaves every
 * particle. */
#define MPM_DP_TRIAL_LANES_MAX 64
uint64_t mpm_dp_trial2d_lanes(const mpm_plastic_params *P, size_t n, const double *const e[4],
                              double *const x[4], double *const q[3], double *yld);

/* The same in 3D (the 3D frictional block): e the increments xx, yy, zz,
 * xy, yz, xz and the spins w_xy, w_yz, w_xz; x the six stresses; q the six
 * strain-record components. */
uint64_t mpm_dp_trial3d_lanes(const mpm_plastic_params *P, size_t n, const double *const e[9],
                              double *const x[6], double *const q[6], double *yld);

#endif
