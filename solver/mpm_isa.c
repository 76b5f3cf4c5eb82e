/*
 * mpm_isa.c - which kernels a job may run: whether this build has the
 * AVX2+FMA kernel families (mpm_kernels_*_avx2.c) and this CPU runs them,
 * and the check of mpm_case.kernels.  The families themselves and their
 * selection are in mpm_kernels.c and mpm_kernels_avx2.c; the plan
 * (mpm_plan.c) chooses between them.
 */
#include "mpm_isa.h"
#include "mpm_kernels.h"
#include "mpm_kernels_avx2.h"

int mpm_kernels_avx2_available(void)
{
#if defined(MPM_HAVE_AVX2_KERNELS) && defined(__x86_64__) && defined(__GNUC__)
    /* libgcc's (and compiler-rt's) CPU model: the feature bits, and for
     * AVX2 also the OS's saving of the YMM state (XGETBV) */
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
    return 0;
#endif
}

#ifndef MPM_HAVE_AVX2_KERNELS
int mpm_kernels_avx2_fuses(void)
{
    return 0; /* no AVX2 families in this build */
}
#endif

int mpm_kernels_check(mpm_kernels_isa isa, mpm_error *err)
{
    if (isa != MPM_KERNELS_AUTO && isa != MPM_KERNELS_PORTABLE && isa != MPM_KERNELS_AVX2)
        return mpm_fail(err, MPM_EINVAL, "kernels", "unknown value %d (AUTO, PORTABLE or AVX2)",
                        (int)isa);
    if (isa == MPM_KERNELS_AVX2 && !mpm_kernels_avx2_available())
        return mpm_fail(err, MPM_EINVAL, "kernels", "AVX2 asked for, but %s (use AUTO or PORTABLE)",
#ifdef MPM_HAVE_AVX2_KERNELS
                        "this CPU lacks AVX2 or FMA"
#else
                        "this build has no AVX2 kernels (not x86-64)"
#endif
        );
    return 0;
}
