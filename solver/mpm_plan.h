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
#include "mpm_plan_types.h"

#include <stddef.h>

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
