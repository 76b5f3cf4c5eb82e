/*
 * mpm_kernels_1d_avx2.c - mpm_kernels_1d.c's families (the 1D families (tents, uGIMP, B-splines))
 * built again for AVX2+FMA: the Makefile compiles this file with -mavx2 -mfma -ffp-contract=fast;
 * mpm_kernels_avx2.c selects among these tables.
 */
#ifdef MPM_HAVE_AVX2_KERNELS
#if !defined(__AVX2__) || !defined(__FMA__)
#error "mpm_kernels_1d_avx2.c needs -mavx2 -mfma (the Makefile gives them)"
#endif
#define MPM_KERNELS_VARIANT 1
#include "mpm_kernels_1d.c"
#else
typedef int mpm_kernels_1d_avx2_none; /* not x86-64: nothing here (ISO C wants a declaration) */
#endif
