/*
 * mpm_paper.c - builders for the GMPM paper's verification cases and their
 * analytic solutions (see mpm_paper.h).
 */
#include "mpm_paper.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void mpm_paper_free(mpm_paper *t)
{
    free(t->x);
    free(t->vol);
    free(t->v);
    memset(t, 0, sizeof *t);
}

static void one_body(mpm_paper *t, int nbodies)
{
    t->c.n_materials = 1;
    t->c.materials = t->mat;
    t->c.n_bodies = (size_t)nbodies;
    t->c.bodies = t->body;
}

void mpm_paper_point(mpm_paper *t, mpm_update up, double dt, double v0)
{
    memset(t, 0, sizeof *t);
    static const double x = 0.5, vol = 1.0;
    t->mat[0] = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                    .youngs_modulus = 4 * M_PI * M_PI,
                                    .poisson_ratio = 0,
                                    .density = 1};
    t->body[0].velocity[0] = v0;
    t->body[0].n_points = 1;
    t->body[0].x = &x;
    t->body[0].volume = &vol;
    t->c.grid = (mpm_grid_desc){1, {0}, {1.0}, {2}};
    t->c.method = MPM_METHOD_MPM;
    t->c.update = up;
    t->c.dt = dt;
    t->c.bc.face_mask[0] = 1; /* x = 0 fixed */
    one_body(t, 1);
}

double mpm_paper_point_v(double v0, double t)
{
    return v0 * cos(2 * M_PI * t); /* Eq. 32, omega = sqrt(E/rho)/L = 2 pi */
}

double mpm_paper_point_x(double v0, double t)
{
    return 0.5 * exp(v0 / (2 * M_PI) * sin(2 * M_PI * t)); /* Eq. 33 */
}

int mpm_paper_bar(mpm_paper *t, mpm_method m, mpm_update up, int ncell, int ppc, int extra,
                  double dt, double v0)
{
    memset(t, 0, sizeof *t);
    size_t n = (size_t)ncell * (size_t)ppc;
    double h = 1.0 / ncell, beta = M_PI / 2;
    t->x = malloc(n * sizeof(double));
    t->vol = malloc(n * sizeof(double));
    t->v = malloc(n * sizeof(double));
    if (!t->x || !t->vol || !t->v) {
        mpm_paper_free(t);
        return -1;
    }
    for (size_t i = 0; i < n; i++) {
        t->x[i] = (i + 0.5) * h / ppc;
        t->vol[i] = h / ppc;
        t->v[i] = v0 * sin(beta * t->x[i]);
    }
    t->mat[0] = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                    .youngs_modulus = 10.0,
                                    .poisson_ratio = 0,
                                    .density = 1};
    t->body[0].n_points = n;
    t->body[0].x = t->x;
    t->body[0].volume = t->vol;
    t->body[0].v = t->v;
    t->c.grid = (mpm_grid_desc){1, {0}, {h}, {ncell + 1 + extra}};
    t->c.method = m;
    t->c.update = up;
    t->c.dt = dt;
    t->c.bc.face_mask[0] = 1;
    one_body(t, 1);
    return 0;
}

double mpm_paper_bar_omega(void)
{
    return M_PI / 2 * sqrt(10.0);
}

double mpm_paper_bar_vcm(double v0, double t)
{
    /* Eq. 34 averaged over the bar: (1 - cos(beta L)) / (beta L) = 2 / pi */
    return v0 * cos(mpm_paper_bar_omega() * t) * 2 / M_PI;
}

void mpm_paper_disks(mpm_paper *t, mpm_method m, mpm_update up, double h)
{
    memset(t, 0, sizeof *t);
    int n = (int)lround(1.0 / h) + 1;
    double s = 0.1 / sqrt(2.0);
    t->mat[0] = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                    .youngs_modulus = 1.0,
                                    .poisson_ratio = 0.2,
                                    .density = 1.0};
    for (int b = 0; b < 2; b++) {
        mpm_body_desc *d = &t->body[b];
        d->shape = MPM_SHAPE_SPHERE;
        d->center[0] = d->center[1] = b ? 0.75 : 0.25;
        d->radius = 0.14;
        d->ppc = 2;
        d->velocity[0] = d->velocity[1] = b ? -s : s;
    }
    t->c.grid = (mpm_grid_desc){2, {0, 0}, {h, h}, {n, n}};
    t->c.method = m;
    t->c.update = up;
    one_body(t, 2);
}
