/*
 * mpm_kernels.h - the particle passes as families of kernels: the
 * selection of a portable family by dimension, nodes per axis, shape and
 * transfer (mpm_kernels.c), the units that instantiate the families
 * (mpm_kernels_*.c) and the per-thread scratch.  The families' types
 * (struct mpm_kernels, mpm_thread_out) are in mpm_kernels_types.h; the
 * AVX2 build's selection in mpm_kernels_avx2.h, CPDI's in mpm_cpdi.h;
 * the plan (mpm_plan.h) says which one a job runs.
 */
#ifndef MPM_KERNELS_H
#define MPM_KERNELS_H

#include "mpm_kernels_types.h"

#include <stddef.h>

/* The family of dimension dim with ns nodes per axis: 2 (MPM), 3 (uGIMP,
 * every lp <= h/2) or 4 (uGIMP, lp up to h); bspline nonzero: the B-spline
 * family of degree ns - 1 (ns 3 or 4); blend nonzero: the particle
 * velocity update blends PIC into FLIP by s->pic (pure FLIP, blend 0, does
 * no extra work). */
/* apic nonzero: the APIC family (mpm_case.transfer APIC), with its own
 * scatters of momentum (with the affine part) and velocity updates (PIC
 * velocity and B_p), every other pass shared; blend is then ignored. */
const mpm_kernels *mpm_kernels_select(int dim, int ns, int bspline, int blend, int apic);
extern const mpm_kernel_unit mpm_ku_1d, mpm_ku_2d, mpm_ku_2d_bs, mpm_ku_3d, mpm_ku_3d_bs;
extern const mpm_kernel_unit mpm_ku_1d_avx2, mpm_ku_2d_avx2, mpm_ku_2d_bs_avx2, mpm_ku_3d_avx2,
    mpm_ku_3d_bs_avx2;
/* Bytes of the per-thread weight scratch (mpm_thread_out.wblk). */
size_t mpm_kernels_scratch(void);
#endif
