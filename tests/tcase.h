/*
 * tcase.h - builders for the paper's verification cases, shared by the
 * solver tests (header-only: static functions).
 */
#ifndef TCASE_H
#define TCASE_H

#include "mpm.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Owned storage behind an mpm_case built by these helpers. */
typedef struct {
    mpm_case c;
    mpm_material_desc mat[2];
    mpm_body_desc body[2];
    double *x, *vol, *v;
} tcase;

static inline void tcase_free(tcase *t)
{
    free(t->x);
    free(t->vol);
    free(t->v);
    memset(t, 0, sizeof *t);
}

/* The paper's single material point (Section 5, Eqs. 32-33): E = 4 pi^2,
 * L = 1, rho = 1, x0 = L/2, v0, two nodes with the left one fixed. */
static inline void tcase_point(tcase *t, mpm_update up, double dt, double v0)
{
    memset(t, 0, sizeof *t);
    t->x = malloc(sizeof(double));
    t->vol = malloc(sizeof(double));
    t->x[0] = 0.5;
    t->vol[0] = 1.0;
    t->mat[0] = (mpm_material_desc){MPM_MODEL_LINEAR_ELASTIC, 4 * M_PI * M_PI, 0, 1};
    t->body[0].velocity[0] = v0;
    t->body[0].n_points = 1;
    t->body[0].x = t->x;
    t->body[0].volume = t->vol;
    t->c.grid = (mpm_grid_desc){1, {0}, {1.0}, {2}};
    t->c.method = MPM_METHOD_MPM;
    t->c.update = up;
    t->c.dt = dt;
    t->c.n_materials = 1;
    t->c.materials = t->mat;
    t->c.n_bodies = 1;
    t->c.bodies = t->body;
    t->c.bc.face_mask[0] = 1; /* x = 0 fixed */
}

/* The paper's bar (Eqs. 34-37): E = 10, L = 1, rho = 1, fixed at x = 0,
 * v(x, 0) = v0 sin(beta x); n cells of one point each (7/8 MPM, 13/14
 * GMPM), or ppc points per cell; `extra` empty cells beyond x = L leave
 * room for the free end, which moves by up to v0/omega_1 = 0.02. */
static inline void tcase_bar(tcase *t, mpm_method m, mpm_update up, int ncell, int ppc,
                             int extra, double dt, double v0)
{
    memset(t, 0, sizeof *t);
    int n = ncell * ppc;
    double h = 1.0 / ncell, beta = M_PI / 2;
    t->x = malloc(n * sizeof(double));
    t->vol = malloc(n * sizeof(double));
    t->v = malloc(n * sizeof(double));
    for (int i = 0; i < n; i++) {
        t->x[i] = (i + 0.5) * h / ppc;
        t->vol[i] = h / ppc;
        t->v[i] = v0 * sin(beta * t->x[i]);
    }
    t->mat[0] = (mpm_material_desc){MPM_MODEL_LINEAR_ELASTIC, 10.0, 0, 1};
    t->body[0].n_points = (size_t)n;
    t->body[0].x = t->x;
    t->body[0].volume = t->vol;
    t->body[0].v = t->v;
    t->c.grid = (mpm_grid_desc){1, {0}, {h}, {ncell + 1 + extra}};
    t->c.method = m;
    t->c.update = up;
    t->c.dt = dt;
    t->c.n_materials = 1;
    t->c.materials = t->mat;
    t->c.n_bodies = 1;
    t->c.bodies = t->body;
    t->c.bc.face_mask[0] = 1;
}

/* Bar first mode: omega_1 and the centre-of-mass velocity (Eq. 34
 * averaged over the bar: v0 cos(w t) (1 - cos(beta L)) / (beta L)). */
static inline double bar_omega(void) { return M_PI / 2 * sqrt(10.0); }
static inline double bar_vcm(double v0, double t) { return v0 * cos(bar_omega() * t) * 2 / M_PI; }

/* The paper's two disks (Section 5.6): radius 0.14 in the unit square,
 * centres (0.25, 0.25) and (0.75, 0.75), speed 0.1 towards each other
 * along the diagonal, E = 1, nu = 0.2, rho = 1; h = 0.1 (24 points per
 * disk) or 0.025 (392), 2x2 per cell. */
static inline void tcase_disks(tcase *t, mpm_method m, mpm_update up, double h)
{
    memset(t, 0, sizeof *t);
    int n = (int)lround(1.0 / h) + 1;
    double s = 0.1 / sqrt(2.0);
    t->mat[0] = (mpm_material_desc){MPM_MODEL_LINEAR_ELASTIC, 1.0, 0.2, 1.0};
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
    t->c.n_materials = 1;
    t->c.materials = t->mat;
    t->c.n_bodies = 2;
    t->c.bodies = t->body;
}

#endif
