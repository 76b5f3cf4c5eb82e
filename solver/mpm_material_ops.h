/*
 * mpm_material_ops.h - the constitutive models' operations, one object per
 * model, defined in mpm_model.c beside the functions they point at
 * (struct mpm_model_ops, mpm_model_types.h: the stress update of a block, the
 * point update of the rate-form models, the stored energy) and referenced
 * by the model's row of the material table (mpm_material_table.c).  A new
 * model adds its object here and there (docs/architecture.md, "Adding a
 * material").
 */
#ifndef MPM_MATERIAL_OPS_H
#define MPM_MATERIAL_OPS_H

struct mpm_model_ops;

extern const struct mpm_model_ops mpm_ops_linear_elastic;
extern const struct mpm_model_ops mpm_ops_neo_hookean;
extern const struct mpm_model_ops mpm_ops_von_mises;
extern const struct mpm_model_ops mpm_ops_drucker_prager;
extern const struct mpm_model_ops mpm_ops_mohr_coulomb;

#endif
