/*
 * mpm_material_table.h - what the solver's files ask of the material
 * table (mpm_material_table.c) beyond its public rows (mpm_material.h):
 * a model's operations by its kind, and a material's derived constants
 * (mpm_mat_params, which point at them).  The operations themselves are
 * defined in mpm_model.c (mpm_material_ops.h) and the table points at
 * them; mpm_model.c never calls back into the table, so that the table
 * sits above the models (tests/include_graph.py checks it).
 */
#ifndef MPM_MATERIAL_TABLE_H
#define MPM_MATERIAL_TABLE_H

#include "mpm_material.h"
#include "mpm_model_types.h"

/* The model's operations (its row's), or NULL. */
const mpm_model_ops *mpm_model_get(mpm_model_kind kind);
/* The derived constants of material d (checked by mpm_material_check()). */
void mpm_model_params(const mpm_material_desc *d, int dim, mpm_mat_params *out);

#endif
