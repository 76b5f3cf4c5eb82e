/*
 * mpm_plan.h - the plan of a job: every switch that picks one of the
 * solver's fast paths, in one struct (mpm_sim.plan), chosen once at
 * creation from the case and the CPU (mpm_plan_choose(), mpm_plan.c) and
 * read by the step and the kernels.  Each fast path gives the bits of the
 * path it replaces, except the kernels' instruction set (kernels=avx2
 * fuses multiply-adds: docs/solver.md, "Kernels") and the nodes per axis
 * of uGIMP, which only leave out zero weights.
 *
 * The plan has a text form, one line of key=value pairs (mpm_plan_format();
 * mpm_sim_plan() in mpm.h), which the daemon logs and stores with the run
 * and mpmrun prints, and a parser (mpm_plan_parse()) through which a test
 * or a user forces a variant: mpm_sim_plan_override() (mpm_diag.h) takes
 * the keys marked "chosen" below; the derived ones follow from them and
 * the case, and a text may repeat them only with their values.
 * The keys are the table plan_keys[] in mpm_plan.c.
 */
#ifndef MPM_PLAN_H
#define MPM_PLAN_H

#include "mpm.h"

#include <stddef.h>

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

/* The longest text of a plan, its terminating NUL included (mpm.h). */
#define MPM_PLAN_TEXT_MAX MPM_PLAN_LEN

/* The text form of p into buf (n bytes, truncated); returns the length
 * the whole text takes, as snprintf(). */
int mpm_plan_format(const mpm_plan *p, char *buf, size_t n);
/* Parses text (key=value pairs separated by spaces) over *p: each key
 * given overwrites its field, and its bit (1u << its row of the table,
 * mpm_plan_key_bit()) is set in *given.  Returns 0, or MPM_EINVAL naming
 * the key (field "plan.KEY") and its values, *p then unchanged. */
int mpm_plan_parse(const char *text, mpm_plan *p, unsigned *given, mpm_error *err);
/* The bit of key in mpm_plan_parse()'s *given (0 for an unknown key). */
unsigned mpm_plan_key_bit(const char *key);
/* Whether key is one of the chosen ones. */
int mpm_plan_key_chosen(const char *key);
/* The value of the key of bit b in p (0 past the table). */
int mpm_plan_value(const mpm_plan *p, unsigned b);
/* The name of the key of bit b (NULL past the table). */
const char *mpm_plan_key_name(unsigned b);

struct mpm_sim;
/* The defaults of sim's plan: avx2 when allowed (the case's kernels not
 * PORTABLE and the CPU able; never CPDI), and every other switch from
 * the case as sim holds it (materials, particle arrays, update scheme).
 * ns_fixed nonzero keeps p->ns (an override's). */
void mpm_plan_choose(const struct mpm_sim *s, int allow_avx2, int ns_fixed, mpm_plan *p);
/* uGIMP: 3 nodes per axis suffice (every a = lp/h <= 1/2). */
int mpm_plan_gimp_fits3(const struct mpm_sim *s);

#endif
