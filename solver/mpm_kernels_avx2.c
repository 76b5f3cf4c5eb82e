/*
 * mpm_kernels_avx2.c - the kernel families of mpm_kernels.c built a second
 * time for x86-64 CPUs with AVX2 and FMA.
 *
 * The Makefile compiles this file alone with -mavx2 -mfma and
 * -ffp-contract=fast (and every solver file with MPM_HAVE_AVX2_KERNELS on
 * x86-64), so the same source runs with 256-bit registers where the
 * compiler finds them useful and with a * b + c fused into one rounding.
 * mpm_sim_new() takes these families when mpm_case.kernels allows it and
 * mpm_kernels_avx2_available() finds the CPU able; they are reached only
 * through mpm_kernels_select_avx2(), and no other symbol of mpm_kernels.c
 * is built twice.  The fused roundings make their results differ from the
 * portable families' in the last bits (docs/solver.md, "Kernels").
 */
#ifdef MPM_HAVE_AVX2_KERNELS
#if !defined(__AVX2__) || !defined(__FMA__)
#error "mpm_kernels_avx2.c needs -mavx2 -mfma (the Makefile gives them)"
#endif
#define MPM_KERNELS_VARIANT 1
#include "mpm_kernels.c"
#else
typedef int mpm_kernels_avx2_none; /* not x86-64: nothing here (ISO C wants a declaration) */
#endif
