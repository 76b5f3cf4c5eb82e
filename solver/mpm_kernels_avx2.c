/*
 * mpm_kernels_avx2.c - the selection of the kernel families built for
 * x86-64 CPUs with AVX2 and FMA (the units mpm_kernels_<unit>_avx2.c), and
 * whether that build fuses multiply-adds.
 *
 * The Makefile compiles this file and the AVX2 units with -mavx2 -mfma and
 * -ffp-contract=fast (and every solver file with MPM_HAVE_AVX2_KERNELS on
 * x86-64), so the same templates (mpm_kernels.inc) run with 256-bit
 * registers where the compiler finds them useful and with a * b + c fused
 * into one rounding.  mpm_sim_new() takes these families when the plan
 * says kernels=avx2 (mpm_case.kernels allows it and
 * mpm_kernels_avx2_available() finds the CPU able); they are reached only
 * through mpm_kernels_select_avx2().  The fused roundings make their
 * results differ from the portable families' in the last bits
 * (docs/solver.md, "Kernels").
 */
#ifdef MPM_HAVE_AVX2_KERNELS
#if !defined(__AVX2__) || !defined(__FMA__)
#error "mpm_kernels_avx2.c needs -mavx2 -mfma (the Makefile gives them)"
#endif
#include "mpm_kernels_avx2.h"
#include "mpm_internal.h"
#include "mpm_kernels.h"

/* 1 when this build of the families fuses a * b + c: the exact product
 * 1 - 2^-60 rounds to 1, so only a fused operation leaves -2^-60.  (GCC
 * forms FMAs from -O2 on: the sanitizer builds, at -O1, run these families
 * without them, and so with the portable kernels' bits.) */
int mpm_kernels_avx2_fuses(void)
{
    volatile double va = 1.0 + 0x1p-30, vb = 1.0 - 0x1p-30, vc = -1.0;
    double a = va, b = vb, c = vc;
    return a * b + c != 0.0;
}

const mpm_kernels *mpm_kernels_select_avx2(int dim, int ns, int bspline, int blend, int apic)
{
    static const mpm_kernel_unit *const units[3][2] = {{&mpm_ku_1d_avx2, &mpm_ku_1d_avx2},
                                                       {&mpm_ku_2d_avx2, &mpm_ku_2d_bs_avx2},
                                                       {&mpm_ku_3d_avx2, &mpm_ku_3d_bs_avx2}};
    return mpm_kernel_unit_pick(units[dim - 1][bspline != 0], ns, bspline, blend, apic);
}
#else
typedef int mpm_kernels_avx2_none; /* not x86-64: nothing here (ISO C wants a declaration) */
#endif
