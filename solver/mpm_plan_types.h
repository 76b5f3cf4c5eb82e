/*
 * mpm_plan_types.h - the plan (mpm_plan): every fast-path switch of a
 * job, chosen once at creation from the case and the CPU, and its
 * enumerations.  struct mpm_sim holds one (mpm_internal.h); the functions
 * that choose, print and parse it are in mpm_plan.h (mpm_plan.c).  This
 * header declares no function, so that mpm_internal.h can include it
 * without a circle.
 */
#ifndef MPM_PLAN_TYPES_H
#define MPM_PLAN_TYPES_H

#include "mpm.h"

/* fuse: the moving pass also makes the next step's first scatter (G2P2G):
 * never, where the extra buffer's pages pay (mpm_rows.c fuse_pays()), or
 * always (tests) */
typedef enum { MPM_FUSE_OFF = 0, MPM_FUSE_AUTO = 1, MPM_FUSE_ALWAYS = 2 } mpm_fuse_mode;
/* the family's shape functions */
typedef enum {
    MPM_FAM_TENT = 0,
    MPM_FAM_GIMP = 1,
    MPM_FAM_BSPLINE = 2,
    MPM_FAM_CPDI = 3
} mpm_family;
/* the family's velocity transfer twin */
typedef enum { MPM_VAR_FLIP = 0, MPM_VAR_BLEND = 1, MPM_VAR_APIC = 2 } mpm_variant;

typedef struct {
    /* chosen (mpm_sim_plan_override() may set them) */
    int avx2;      /* kernels=avx2|portable: the AVX2+FMA families (mpm_kernels_*_avx2.c) */
    int ns;        /* ns=2|3|4: nodes per axis of the family (uGIMP: 3 when every
                    * particle's lp <= h/2, else 4; only before the first step) */
    int fuse;      /* fuse=off|auto|always (mpm_fuse_mode; off where the family
                    * has no fused passes: CPDI) */
    int el_lanes;  /* el_lanes=0|1: the AVX2 tents' USF stress pass takes a run
                    * of particles from strain to stress (2D: and forces) in
                    * registers (mpm_kernels.inc el_block(); one linear elastic
                    * material, no strain record, no spins, no sigma_zz array) */
    int dp_lanes;  /* dp_lanes=0|1: Drucker-Prager's plastic updates four at a
                    * time (mpm_dp_lanes(); the CPU has AVX2, kernels not PORTABLE) */
    int sort_ring; /* sort_ring=N: entries of each thread's ring of saved slots
                    * (a power of 2, at most what creation allocated; mpm_sort.c) */
    /* derived (printed; a text may repeat them with the same value) */
    int fma;      /* fma=0|1: the AVX2 build fuses a * b + c (not at -O1) */
    int dim;      /* dim=1|2|3 */
    int family;   /* shape=tent|gimp|bspline|cpdi (mpm_family) */
    int variant;  /* transfer=flip|blend|apic (mpm_variant) */
    int general;  /* block=direct|general: the block update is linear
                   * elasticity's own, or mpm_model_block() */
    int gvel;     /* gvel=0|1: the grid holds velocities for the moving passes */
    int trun;     /* trun=0|1: tents scatter by runs of one cell (mpm_trun.inc) */
    int tlanes;   /* tlanes=0|1: tents' strain gathered four particles at a
                   * time (mpm_tlane.inc; AVX2, 2D and 3D): the USF stress
                   * pass, and USL's moving pass but with APIC */
    int tlanes_x; /* tlanes_x=0|1: ... and USF's moving pass by them (3D, not
                   * APIC) */
    int rows4;    /* rows4=0|1: supports of 3 or 4 nodes scatter and gather by
                   * four-lane rows (AVX2) */
} mpm_plan;

#endif
