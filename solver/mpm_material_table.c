/*
 * mpm_material_table.c - the material table (mpm_material.h): a row per
 * parameter of mpm_material_desc (name, place, bounds, the value a case
 * that omits it gets) and a row per constitutive model (its schema name,
 * what its particles carry, the parameters it reads and requires, the
 * lowest dimension it runs in, its operations from mpm_model.c), and the
 * one check of a material's parameters, mpm_material_check(), which the
 * case check calls.  The codec (protocol/mpp_case.c) fills absent fields
 * from the defaults and names missing required ones from the same rows;
 * the checkpoint's fingerprint hashes every parameter a model reads.
 * Tests: material_validation (the messages), codec_material_table_matches
 * _proto (a row per schema field and model), ckpt_fingerprint_every
 * _material_param (every parameter of every model is fingerprinted).
 */
#include "mpm_material_table.h"
#include "mpm_material.h"

#include "mpm_material_ops.h"
#include "mpm_method.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* The parameters' indices in params[] (bit k of a model's masks). */
enum { P_E, P_NU, P_RHO, P_SY, P_H, P_PHI, P_PSI, P_C, P_TENSION, P_MATCH, P_TOL, P_COUNT };
#define BIT(k) (1u << (k))

static const char *const mc_match_names[] = {"COMPRESSION", "EXTENSION", "PLANE_STRAIN"};

_Static_assert(MPM_MC_COMPRESSION == 0 && MPM_MC_EXTENSION == 1 && MPM_MC_PLANE_STRAIN == 2,
               "mc_match_names[] follows mpm_mc_match");
_Static_assert(sizeof(mpm_mc_match) == sizeof(int), "an enum parameter is stored as an int");

#define AT(f) offsetof(mpm_material_desc, f)
#define REAL MPM_PARAM_REAL
#define LO_OPEN MPM_PARAM_LO_OPEN
#define HI_OPEN MPM_PARAM_HI_OPEN
#define FINITE MPM_PARAM_FINITE

/* name, offset, type, lo, hi, hi_param, flags, unit, default, names, n_names
 * (every field given: clang's -Wmissing-field-initializers) */
static const mpm_material_param params[P_COUNT] = {
    [P_E] = {"youngs_modulus", AT(youngs_modulus), REAL, 0, HUGE_VAL, -1, LO_OPEN | FINITE, "", 0,
             NULL, 0},
    [P_NU] = {"poisson_ratio", AT(poisson_ratio), REAL, -1, 0.5, -1,
              LO_OPEN | HI_OPEN | MPM_PARAM_NOT_1D, "", 0, NULL, 0},
    [P_RHO] = {"density", AT(density), REAL, 0, HUGE_VAL, -1, LO_OPEN | FINITE, "", 0, NULL, 0},
    [P_SY] = {"yield_stress", AT(yield_stress), REAL, 0, HUGE_VAL, -1, LO_OPEN | FINITE, "", 0,
              NULL, 0},
    [P_H] = {"hardening_modulus", AT(hardening_modulus), REAL, 0, HUGE_VAL, -1, FINITE, "", 0, NULL,
             0},
    [P_PHI] = {"friction_angle", AT(friction_angle), REAL, 0, 90, -1, LO_OPEN | HI_OPEN, "degrees",
               0, NULL, 0},
    [P_PSI] = {"dilatancy_angle", AT(dilatancy_angle), REAL, 0, 90, P_PHI, 0, "degrees", 0, NULL,
               0},
    [P_C] = {"cohesion", AT(cohesion), REAL, 0, HUGE_VAL, -1, FINITE, "", 0, NULL, 0},
    /* absent: no cut-off below the apex (HUGE_VAL, capped there) */
    [P_TENSION] = {"tension_cutoff", AT(tension_cutoff), REAL, 0, HUGE_VAL, -1, 0, "", HUGE_VAL,
                   NULL, 0},
    [P_MATCH] = {"mc_match", AT(mc_match), MPM_PARAM_ENUM, 0, 0, -1, 0, "", MPM_MC_COMPRESSION,
                 mc_match_names, 3},
    /* 0: the integrator's default (mpm_plastic_init()) */
    [P_TOL] = {"substep_tolerance", AT(substep_tolerance), REAL, 0, 1, -1, HI_OPEN, "", 0, NULL, 0},
};

#define ELASTIC (BIT(P_E) | BIT(P_NU) | BIT(P_RHO))
#define FRICTIONAL \
    (ELASTIC | BIT(P_PHI) | BIT(P_PSI) | BIT(P_C) | BIT(P_TENSION) | BIT(P_MATCH) | BIT(P_TOL))
#define FRICTIONAL_NEEDS (MPM_NEED_SPIN | MPM_NEED_PLASTIC | MPM_NEED_INTEGRATOR)

/* Indexed by mpm_model_kind. */
static const mpm_material_model models[] = {
    {MPM_MODEL_LINEAR_ELASTIC, "LINEAR_ELASTIC", 0, 1, ELASTIC, BIT(P_E) | BIT(P_RHO),
     &mpm_ops_linear_elastic},
    {MPM_MODEL_NEO_HOOKEAN, "NEO_HOOKEAN", MPM_NEED_F, 1, ELASTIC, BIT(P_E) | BIT(P_RHO),
     &mpm_ops_neo_hookean},
    {MPM_MODEL_VON_MISES, "VON_MISES", MPM_NEED_SPIN | MPM_NEED_PLASTIC, 1,
     ELASTIC | BIT(P_SY) | BIT(P_H), BIT(P_E) | BIT(P_RHO) | BIT(P_SY), &mpm_ops_von_mises},
    /* 1D keeps one stress component: the lateral stresses of uniaxial
     * strain, which these two read, would be lost */
    {MPM_MODEL_DRUCKER_PRAGER, "DRUCKER_PRAGER", FRICTIONAL_NEEDS, 2, FRICTIONAL,
     BIT(P_E) | BIT(P_RHO) | BIT(P_PHI), &mpm_ops_drucker_prager},
    {MPM_MODEL_MOHR_COULOMB, "MOHR_COULOMB", FRICTIONAL_NEEDS, 2, FRICTIONAL,
     BIT(P_E) | BIT(P_RHO) | BIT(P_PHI), &mpm_ops_mohr_coulomb},
};
#define N_MODELS ((int)(sizeof models / sizeof models[0]))

_Static_assert(MPM_MODEL_LINEAR_ELASTIC == 0 && MPM_MODEL_NEO_HOOKEAN == 1 &&
                   MPM_MODEL_VON_MISES == 2 && MPM_MODEL_DRUCKER_PRAGER == 3 &&
                   MPM_MODEL_MOHR_COULOMB == 4 && N_MODELS == 5,
               "models[] follows mpm_model_kind");
_Static_assert(P_COUNT <= 32, "a model's parameter masks are 32 bits");

int mpm_material_n_params(void)
{
    return P_COUNT;
}

const mpm_material_param *mpm_material_param_at(int k)
{
    return k >= 0 && k < P_COUNT ? &params[k] : NULL;
}

const mpm_material_model *mpm_material_model_of(mpm_model_kind kind)
{
    return (unsigned)kind < (unsigned)N_MODELS ? &models[kind] : NULL;
}

const mpm_model_ops *mpm_model_get(mpm_model_kind kind)
{
    const mpm_material_model *m = mpm_material_model_of(kind);
    return m ? m->ops : NULL;
}

void mpm_model_params(const mpm_material_desc *d, int dim, mpm_mat_params *out)
{
    double nu = dim == 1 ? 0.0 : d->poisson_ratio;
    memset(out, 0, sizeof *out);
    out->E = d->youngs_modulus;
    out->nu = nu;
    out->rho = d->density;
    out->lambda = out->E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    out->mu = out->E / (2.0 * (1.0 + nu));
    out->K = out->lambda + 2.0 * out->mu / 3.0;
    out->c = mpm_material_wave_speed(d, dim);
    out->sy0 = d->yield_stress;
    out->H = d->hardening_modulus;
    out->ops = mpm_model_get(d->model);
}

double mpm_material_get(const mpm_material_desc *d, const mpm_material_param *p)
{
    const char *at = (const char *)d + p->offset;
    if (p->type == MPM_PARAM_ENUM) {
        int v;
        memcpy(&v, at, sizeof v);
        return v;
    }
    double v;
    memcpy(&v, at, sizeof v);
    return v;
}

void mpm_material_set(mpm_material_desc *d, const mpm_material_param *p, double v)
{
    char *at = (char *)d + p->offset;
    if (p->type == MPM_PARAM_ENUM) {
        int e = (int)v;
        memcpy(at, &e, sizeof e);
    } else {
        memcpy(at, &v, sizeof v);
    }
}

/* The one-sided bound of a parameter as text: "> 0", ">= 0". */
static void bound_text(const mpm_material_param *p, char *buf, size_t n)
{
    if (p->hi == HUGE_VAL)
        snprintf(buf, n, "%s %g", p->flags & MPM_PARAM_LO_OPEN ? ">" : ">=", p->lo);
    else
        snprintf(buf, n, "%s %g", p->flags & MPM_PARAM_HI_OPEN ? "<" : "<=", p->hi);
}

/* Parameter k of material i (model m) against its row. */
static int check_param(const mpm_material_desc *d, int k, size_t i, mpm_error *err)
{
    const mpm_material_param *p = &params[k];
    char path[96];
    snprintf(path, sizeof path, "materials[%zu].%s", i, p->name);
    double v = mpm_material_get(d, p);
    if (p->type == MPM_PARAM_ENUM) {
        int e = (int)v;
        if (e >= 0 && e < p->n_names) return 0;
        char list[128] = "";
        for (int j = 0; j < p->n_names; j++)
            mpm_names_append(list, sizeof list, p->names[j], j, p->n_names);
        return mpm_fail(err, MPM_EINVAL, path, "unknown value %d (%s)", e, list);
    }
    double hi = p->hi_param >= 0 ? mpm_material_get(d, &params[p->hi_param]) : p->hi;
    int lo_ok = p->flags & MPM_PARAM_LO_OPEN ? v > p->lo : v >= p->lo;
    int hi_ok = p->flags & MPM_PARAM_HI_OPEN ? v < hi : v <= hi;
    int fin_ok = !(p->flags & MPM_PARAM_FINITE) || isfinite(v);
    if (lo_ok && hi_ok && fin_ok) return 0;
    const char *fin = fin_ok ? "" : "finite and ";
    if (p->lo == -HUGE_VAL || (p->hi == HUGE_VAL && p->hi_param < 0)) {
        char b[64];
        bound_text(p, b, sizeof b);
        return mpm_fail(err, MPM_EINVAL, path, "must be %s%s (got %g)", fin, b, v);
    }
    char top[64];
    if (p->hi_param >= 0)
        snprintf(top, sizeof top, "%s = %g", params[p->hi_param].name, hi);
    else
        snprintf(top, sizeof top, "%g", hi);
    return mpm_fail(err, MPM_EINVAL, path, "must be %sin %c%g, %s%c%s%s (got %g)", fin,
                    p->flags & MPM_PARAM_LO_OPEN ? '(' : '[', p->lo, top,
                    p->flags & MPM_PARAM_HI_OPEN ? ')' : ']', *p->unit ? " " : "", p->unit, v);
}

int mpm_material_check(const mpm_material_desc *d, int dim, size_t i, mpm_error *err)
{
    char path[64];
    snprintf(path, sizeof path, "materials[%zu].model", i);
    const mpm_material_model *m = mpm_material_model_of(d->model);
    if (!m) {
        char list[160] = "";
        for (int k = 0; k < N_MODELS; k++)
            mpm_names_append(list, sizeof list, models[k].name, k, N_MODELS);
        return mpm_fail(err, MPM_EINVAL, path, "unknown value %d (%s)", (int)d->model, list);
    }
    if (dim < m->min_dim)
        return mpm_fail(err, MPM_EINVAL, path,
                        m->min_dim == 2 ? "%s needs a 2D (plane strain) or 3D grid (1D keeps one "
                                          "stress component, the lateral stresses of uniaxial "
                                          "strain would be lost)"
                                        : "%s needs a 3D grid",
                        m->name);
    for (int k = 0; k < P_COUNT; k++) {
        if (!(m->params & BIT(k))) continue;
        if (dim == 1 && (params[k].flags & MPM_PARAM_NOT_1D)) continue;
        int rc = check_param(d, k, i, err);
        if (rc) return rc;
    }
    return 0;
}
