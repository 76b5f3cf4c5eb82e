/*
 * mpm_kernels_3d.c - the 3D tents and uGIMP families: one of the translation units the kernel
 * families are split over so that they compile in parallel.  The
 * templates are mpm_kernels.inc; mpm_kernels_3d_avx2.c builds the same
 * families for AVX2+FMA; mpm_kernels.c selects among the units' tables.
 */
#define MPM_KU_DIM 3
#define MPM_KU_LAGRANGE 1
#define MPM_KU_BSPLINE 0
#define MPM_KU_NAME mpm_ku_3d
#include "mpm_kernels.inc"
