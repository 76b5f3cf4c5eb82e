/*
 * mpm_cpdi.h - CPDI1's kernel families (mpm_cpdi.c): the family of a
 * dimension and its per-thread scratch.  The passes' types are in
 * mpm_kernels_types.h.  Used by the simulation's creation.
 */
#ifndef MPM_CPDI_H
#define MPM_CPDI_H

#include "mpm_kernels_types.h"

/* CPDI1's family of dimension dim (mpm_cpdi.c), blend as above, and its
 * weight scratch (wblk holds the larger of the two). */
const mpm_kernels *mpm_cpdi_select(int dim, int blend);
size_t mpm_cpdi_scratch(void);

#endif
