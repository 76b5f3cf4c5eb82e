/*
 * mpm_isa.h - the check of a case's kernels field against the machine
 * (mpm_isa.c): AUTO, PORTABLE, or AVX2 where the build has the AVX2
 * families and the CPU runs them.  Used by the case check (mpm_case.c)
 * and the simulation's creation.
 */
#ifndef MPM_ISA_H
#define MPM_ISA_H

#include "mpm.h"

/* 0 when the case's kernels field is valid on this machine, else
 * MPM_EINVAL naming "kernels". */
int mpm_kernels_check(mpm_kernels_isa isa, mpm_error *err);

#endif
