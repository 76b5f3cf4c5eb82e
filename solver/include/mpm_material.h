/*
 * mpm_material.h - the material table: one row per constitutive model
 * (mpm_model_kind) and one row per parameter of mpm_material_desc.  A
 * model's row names it as the schema does, says what its particles carry
 * (F, the spin, a plastic state, the integrator's parameters), which
 * parameters it reads and which of them a case must give, and points at
 * its operations (private to the solver: mpm_model.c).  A parameter's row
 * gives its name (the schema's snake_case; the JSON spelling is
 * mpm_camel_case() of it), where it sits in mpm_material_desc, its bounds,
 * and the value a case that omits it gets.  The solver's case check
 * (mpm_material_check()), the codec (which fills absent fields and names
 * missing required ones), and the checkpoint's fingerprint all read this
 * table (solver/mpm_material_table.c); docs/architecture.md, "Adding a
 * material", lists what a new model touches.
 */
#ifndef MPM_MATERIAL_H
#define MPM_MATERIAL_H

#include "mpm.h"

#include <stddef.h>
#include <stdint.h>

/* What a model's particles carry, allocated only when a material of the
 * case uses the model: F the deformation gradient; SPIN the spin increment
 * beside the strain increment (rate-form models: the Jaumann rotation);
 * PLASTIC the equivalent plastic strain and the yield flag (and the strain
 * record); INTEGRATOR the stress-point integrator's parameters
 * (mpm_plastic_init()) and its substep counters (mpm_sim_plastic_stats()). */
enum { MPM_NEED_F = 1, MPM_NEED_SPIN = 2, MPM_NEED_PLASTIC = 4, MPM_NEED_INTEGRATOR = 8 };

/* A parameter's kind: a real number, or an enum value stored as an int
 * (names[0 .. n_names) its values' schema spellings). */
typedef enum { MPM_PARAM_REAL = 0, MPM_PARAM_ENUM = 1 } mpm_param_type;

/* Bounds flags: LO_OPEN, HI_OPEN exclude the bound itself; FINITE refuses
 * inf and NaN; NOT_1D: not read on a 1D grid (and not checked there). */
enum { MPM_PARAM_LO_OPEN = 1, MPM_PARAM_HI_OPEN = 2, MPM_PARAM_FINITE = 4, MPM_PARAM_NOT_1D = 8 };

typedef struct {
    const char *name; /* schema snake_case: "friction_angle" */
    size_t offset;    /* of the value in mpm_material_desc */
    mpm_param_type type;
    /* REAL: lo <= v <= hi (open ends by flags; -HUGE_VAL / HUGE_VAL: no
     * bound); hi_param >= 0: the upper bound is that parameter's value
     * instead of hi (dilatancy_angle <= friction_angle) */
    double lo, hi;
    int hi_param;
    unsigned flags;
    const char *unit; /* appended to a range in messages ("degrees"), or "" */
    double def;       /* the value when a case omits it */
    const char *const *names;
    int n_names;
} mpm_material_param;

typedef struct mpm_model_ops mpm_model_ops; /* the operations (private) */

typedef struct {
    mpm_model_kind kind;
    const char *name; /* the schema's enum spelling: "DRUCKER_PRAGER" */
    unsigned needs;   /* MPM_NEED_* */
    int min_dim;      /* the lowest grid dimension it runs in */
    /* bit k: mpm_material_param_at(k); params the model reads, required
     * those a case must give (the codec's "missing") */
    uint32_t params, required;
    const mpm_model_ops *ops; /* init, stress update, energy (mpm_model.c) */
} mpm_material_model;

/* The parameter rows: k in [0, mpm_material_n_params()), NULL outside. */
int mpm_material_n_params(void);
const mpm_material_param *mpm_material_param_at(int k);
/* The model's row, or NULL for a value outside mpm_model_kind. */
const mpm_material_model *mpm_material_model_of(mpm_model_kind kind);
/* Parameter p of d as a double (an enum's int value converted), and its
 * setter. */
double mpm_material_get(const mpm_material_desc *d, const mpm_material_param *p);
void mpm_material_set(mpm_material_desc *d, const mpm_material_param *p, double v);
/* Material i of a case with a `dim`-dimensional grid, checked against its
 * model's row: the model is known and runs in dim, and every parameter it
 * reads is within bounds.  0, or MPM_EINVAL with err naming
 * materials[i].<param> and the bound ("must be in (0, 90) degrees (got
 * 95)"). */
int mpm_material_check(const mpm_material_desc *d, int dim, size_t i, mpm_error *err);

#endif
