/*
 * mpm_model.c - constitutive models behind the mpm_model_ops interface.
 *
 * The kernels compute strain increments for a block of particles (Eq. 29,
 * Fig. 7) and hand them to the model's update for the job's dimension; the
 * model adds them to the particle strain and updates the stress.  Today the
 * one model is small-strain, incremental linear elasticity: uniaxial in 1D,
 * plane strain in 2D (sigma_zz kept for the mean pressure), isotropic in 3D.
 * An elastoplastic model with Sloan-style substepping plugs in as another
 * mpm_model_ops without touching the kernels.
 */
#include "mpm_internal.h"

#include <math.h>
#include <stdio.h>

static void elastic_1d(const mpm_mat_params *mats, mpm_particles *P, size_t p0, size_t n,
                       double *const deps[6])
{
    const uint16_t *mat = P->mat + p0;
    double *sxx = P->sig[0] + p0, *exx = P->eps[0] + p0;
    for (size_t i = 0; i < n; i++) {
        double d = deps[0][i];
        exx[i] += d;
        sxx[i] += mats[mat[i]].E * d;
    }
}

static void elastic_2d(const mpm_mat_params *mats, mpm_particles *P, size_t p0, size_t n,
                       double *const deps[6])
{
    const uint16_t *mat = P->mat + p0;
    double *s0 = P->sig[0] + p0, *s1 = P->sig[1] + p0, *s2 = P->sig[2] + p0, *s3 = P->sig[3] + p0;
    double *e0 = P->eps[0] + p0, *e1 = P->eps[1] + p0, *e3 = P->eps[3] + p0;
    for (size_t i = 0; i < n; i++) {
        const mpm_mat_params *mp = &mats[mat[i]];
        double dxx = deps[0][i], dyy = deps[1][i], dxy = deps[3][i];
        double lt = mp->lambda * (dxx + dyy), m2 = 2.0 * mp->mu;
        e0[i] += dxx;
        e1[i] += dyy;
        e3[i] += dxy;
        s0[i] += lt + m2 * dxx;
        s1[i] += lt + m2 * dyy;
        s2[i] += lt; /* plane strain: eps_zz = 0 */
        s3[i] += m2 * dxy;
    }
}

static void elastic_3d(const mpm_mat_params *mats, mpm_particles *P, size_t p0, size_t n,
                       double *const deps[6])
{
    const uint16_t *mat = P->mat + p0;
    double *restrict s[6], *restrict e[6];
    const double *restrict de[6];
    for (int c = 0; c < 6; c++) {
        s[c] = P->sig[c] + p0;
        e[c] = P->eps[c] + p0;
        de[c] = deps[c];
    }
    for (size_t i = 0; i < n; i++) {
        const mpm_mat_params *mp = &mats[mat[i]];
        double d0 = de[0][i], d1 = de[1][i], d2 = de[2][i], d3 = de[3][i], d4 = de[4][i],
               d5 = de[5][i];
        double lt = mp->lambda * (d0 + d1 + d2), m2 = 2.0 * mp->mu;
        e[0][i] += d0;
        e[1][i] += d1;
        e[2][i] += d2;
        e[3][i] += d3;
        e[4][i] += d4;
        e[5][i] += d5;
        s[0][i] += lt + m2 * d0;
        s[1][i] += lt + m2 * d1;
        s[2][i] += lt + m2 * d2;
        s[3][i] += m2 * d3;
        s[4][i] += m2 * d4;
        s[5][i] += m2 * d5;
    }
}

static const mpm_model_ops linear_elastic = {"linear_elastic",
                                             {elastic_1d, elastic_2d, elastic_3d}};

const mpm_model_ops *mpm_model_get(mpm_model_kind kind)
{
    return kind == MPM_MODEL_LINEAR_ELASTIC ? &linear_elastic : NULL;
}

int mpm_model_params(const mpm_material_desc *d, int dim, size_t i, mpm_mat_params *out,
                     mpm_error *err)
{
    char path[64];
    if (!mpm_model_get(d->model)) {
        snprintf(path, sizeof path, "materials[%zu].model", i);
        return mpm_fail(err, MPM_EINVAL, path, "unknown model %d", (int)d->model);
    }
    if (!(d->youngs_modulus > 0) || !isfinite(d->youngs_modulus)) {
        snprintf(path, sizeof path, "materials[%zu].youngs_modulus", i);
        return mpm_fail(err, MPM_EINVAL, path, "must be finite and > 0 (got %g)",
                        d->youngs_modulus);
    }
    if (!(d->density > 0) || !isfinite(d->density)) {
        snprintf(path, sizeof path, "materials[%zu].density", i);
        return mpm_fail(err, MPM_EINVAL, path, "must be finite and > 0 (got %g)", d->density);
    }
    double nu = dim == 1 ? 0.0 : d->poisson_ratio;
    if (dim > 1 && !(nu > -1.0 && nu < 0.5)) {
        snprintf(path, sizeof path, "materials[%zu].poisson_ratio", i);
        return mpm_fail(err, MPM_EINVAL, path, "must be in (-1, 0.5) (got %g)", d->poisson_ratio);
    }
    out->E = d->youngs_modulus;
    out->nu = nu;
    out->rho = d->density;
    out->lambda = out->E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    out->mu = out->E / (2.0 * (1.0 + nu));
    out->c = mpm_material_wave_speed(d, dim);
    return 0;
}

double mpm_material_wave_speed(const mpm_material_desc *m, int dim)
{
    if (dim == 1) return sqrt(m->youngs_modulus / m->density);
    double nu = m->poisson_ratio, E = m->youngs_modulus;
    double M = E * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)); /* lambda + 2 mu */
    return sqrt(M / m->density);
}
