/*
 * mpm_kernels_avx2.h - the kernel families built for AVX2 and FMA
 * (mpm_kernels_avx2.c picks them from the units' AVX2 builds,
 * mpm_kernels_*_avx2.c) and whether that build fuses multiply-adds
 * (mpm_isa.c answers 0 in a build without them).  Used by the
 * simulation's creation and the plan.
 */
#ifndef MPM_KERNELS_AVX2_H
#define MPM_KERNELS_AVX2_H

#include "mpm_kernels_types.h"

/* The families of mpm_kernels_select() (mpm_kernels.h) built for AVX2 and FMA (the units' AVX2
 * builds, selected by mpm_kernels_avx2.c): only where mpm_kernels_avx2_available(). */
const mpm_kernels *mpm_kernels_select_avx2(int dim, int ns, int bspline, int blend, int apic);
/* 1 when that build fuses a * b + c (not in the sanitizer builds, -O1). */
int mpm_kernels_avx2_fuses(void);

#endif
