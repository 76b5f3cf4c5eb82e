/*
 * ceiling.c - the scene and the step of bin/mpmceiling (the program
 * itself is mpmceiling.c).  The scene is
 * bin/mpmbench's disks2d: the paper's two elastic disks (E = 1, nu = 0.2,
 * rho = 1, radius 0.14, centres (0.25, 0.25) and (0.75, 0.75), 2 x 2
 * particles per cell, |v| = 0.1 towards each other) with a fixed dt =
 * 0.5 h / (c + 0.1), the solver's first dt.  The step is the solver's
 * fused MPM USF step: the node pass (1/m, 0 where m is 0), the stress pass
 * (strain increment from the grid velocity q/m, linear elasticity, the
 * volume, the internal force), the node pass (q += f dt, then q/m and f/m
 * in place), and the moving pass (x += dt S v, v += dt S a: FLIP) that
 * scatters the next step's mass and momentum; nodes by the rows' active
 * extents; a stable counting sort by cell when the runs of one cell fall
 * apart.  Left out, unlike the solver: the moved particles' checks,
 * energies, boundary conditions, gravity, the mass tolerance, other
 * materials and methods, the divergence guard, threads.  The portable
 * kernels are here: one particle at a time, the sums of a run of one cell
 * in locals, added to the grid when the cell changes.
 */
#include "ceiling.h"

#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define CL_RADIUS 0.14
#define CL_SPEED 0.1

static double *dalloc(size_t n)
{
    double *p = calloc(n + CL_SLACK, sizeof *p);
    return p;
}

double cl_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* ---- the portable kernels: one particle at a time, a cell's run in locals ---- */

static void flush_f(cl_grid *g, size_t rn, const double F[8])
{
    size_t r2 = rn + (size_t)g->nx;
    g->fx[rn] += F[0];
    g->fy[rn] += F[1];
    g->fx[rn + 1] += F[2];
    g->fy[rn + 1] += F[3];
    g->fx[r2] += F[4];
    g->fy[r2] += F[5];
    g->fx[r2 + 1] += F[6];
    g->fy[r2 + 1] += F[7];
}

static size_t sf1(cl_parts *P, cl_grid *g)
{
    const int nx = g->nx;
    const double ih = g->ih, dt = g->dt, la = g->lambda, m2 = g->mu2;
    const double *restrict qx = g->qx, *restrict qy = g->qy, *restrict mi = g->mi;
    double F[8] = {0};
    size_t rn = SIZE_MAX, runs = 0;
    for (size_t p = 0; p < P->n; p++) {
        double rx = P->x[p] * ih, ry = P->y[p] * ih;
        int i = (int)rx, j = (int)ry;
        double fx = rx - i, fy = ry - j, wx0 = 1 - fx, wy0 = 1 - fy;
        size_t n = (size_t)j * (size_t)nx + (size_t)i, n2 = n + (size_t)nx;
        double u00 = qx[n] * mi[n], u10 = qx[n + 1] * mi[n + 1], u01 = qx[n2] * mi[n2],
               u11 = qx[n2 + 1] * mi[n2 + 1];
        double v00 = qy[n] * mi[n], v10 = qy[n + 1] * mi[n + 1], v01 = qy[n2] * mi[n2],
               v11 = qy[n2 + 1] * mi[n2 + 1];
        double exx = ih * dt * (wy0 * (u10 - u00) + fy * (u11 - u01));
        double eyy = ih * dt * (wx0 * (v01 - v00) + fx * (v11 - v10));
        double exy =
            0.5 * ih * dt *
            ((wx0 * (u01 - u00) + fx * (u11 - u10)) + (wy0 * (v10 - v00) + fy * (v11 - v01)));
        double tr = exx + eyy, lt = la * tr;
        double sxx = P->sxx[p] + (m2 * exx + lt), syy = P->syy[p] + (m2 * eyy + lt),
               sxy = m2 * exy + P->sxy[p];
        double vol = P->vol[p] * (1.0 + tr);
        P->sxx[p] = sxx;
        P->syy[p] = syy;
        P->sxy[p] = sxy;
        P->vol[p] = vol;
        if (n != rn) {
            if (rn != SIZE_MAX) flush_f(g, rn, F);
            memset(F, 0, sizeof F);
            rn = n;
            runs++;
        }
        double s = vol * ih, gx0 = wy0 * s, gx1 = fy * s, gy0 = wx0 * s, gy1 = fx * s;
        F[0] += sxx * gx0 + sxy * gy0;
        F[1] += sxy * gx0 + syy * gy0;
        F[2] += sxy * gy1 - sxx * gx0;
        F[3] += syy * gy1 - sxy * gx0;
        F[4] += sxx * gx1 - sxy * gy0;
        F[5] += sxy * gx1 - syy * gy0;
        F[6] -= sxy * gy1 + sxx * gx1;
        F[7] -= syy * gy1 + sxy * gx1;
    }
    if (rn != SIZE_MAX) flush_f(g, rn, F);
    return runs;
}

static void flush_mq(cl_grid *g, size_t rn, const double M[12])
{
    size_t r2 = rn + (size_t)g->nx, at[4] = {rn, rn + 1, r2, r2 + 1};
    for (int c = 0; c < 4; c++) {
        g->nm[at[c]] += M[c];
        g->nqx[at[c]] += M[4 + c];
        g->nqy[at[c]] += M[8 + c];
    }
    cl_extent(g, rn);
}

static double interp1(double wx0, double fx, double wy0, double fy, const double *restrict u,
                      size_t n, int nx)
{
    size_t n2 = n + (size_t)nx;
    return wy0 * (wx0 * u[n] + fx * u[n + 1]) + fy * (wx0 * u[n2] + fx * u[n2 + 1]);
}

static size_t mv1(cl_parts *P, cl_grid *g)
{
    const int nx = g->nx;
    const double ih = g->ih, dt = g->dt;
    double M[12] = {0};
    size_t rn = SIZE_MAX, runs = 0, last = SIZE_MAX;
    for (size_t p = 0; p < P->n; p++) {
        double rx = P->x[p] * ih, ry = P->y[p] * ih;
        int i = (int)rx, j = (int)ry;
        double fx = rx - i, fy = ry - j, wx0 = 1 - fx, wy0 = 1 - fy;
        size_t n = (size_t)j * (size_t)nx + (size_t)i;
        if (n != last) runs++;
        last = n;
        double x = P->x[p] + dt * interp1(wx0, fx, wy0, fy, g->qx, n, nx);
        double y = P->y[p] + dt * interp1(wx0, fx, wy0, fy, g->qy, n, nx);
        double vx = P->vx[p] + dt * interp1(wx0, fx, wy0, fy, g->fx, n, nx);
        double vy = P->vy[p] + dt * interp1(wx0, fx, wy0, fy, g->fy, n, nx);
        P->x[p] = x;
        P->y[p] = y;
        P->vx[p] = vx;
        P->vy[p] = vy;
        rx = x * ih;
        ry = y * ih;
        i = (int)rx;
        j = (int)ry;
        fx = rx - i;
        fy = ry - j;
        wx0 = 1 - fx;
        wy0 = 1 - fy;
        n = (size_t)j * (size_t)nx + (size_t)i;
        if (n != rn) {
            if (rn != SIZE_MAX) flush_mq(g, rn, M);
            memset(M, 0, sizeof M);
            rn = n;
        }
        double mp = P->m[p], px = mp * vx, py = mp * vy;
        double w[4] = {wx0 * wy0, fx * wy0, wx0 * fy, fx * fy};
        for (int c = 0; c < 4; c++) {
            M[c] += w[c] * mp;
            M[4 + c] += w[c] * px;
            M[8 + c] += w[c] * py;
        }
    }
    if (rn != SIZE_MAX) flush_mq(g, rn, M);
    return runs;
}

static const cl_kernels portable = {"portable", sf1, mv1};

const cl_kernels *cl_kernels_portable(void)
{
    return &portable;
}

/* ---- the scene, the node passes, the sort ---- */

void cl_case_free(cl_case *c)
{
    double **a[] = {&c->P.x,  &c->P.y,   &c->P.vx,  &c->P.vy,  &c->P.sxx,  &c->P.syy, &c->P.sxy,
                    &c->P.m,  &c->P.vol, &c->g.m,   &c->g.qx,  &c->g.qy,   &c->g.fx,  &c->g.fy,
                    &c->g.mi, &c->g.nm,  &c->g.nqx, &c->g.nqy, &c->scratch};
    for (size_t i = 0; i < sizeof a / sizeof a[0]; i++) {
        free(*a[i]);
        *a[i] = NULL;
    }
    free(c->g.rlo);
    free(c->g.rhi);
    free(c->g.nlo);
    free(c->g.nhi);
    free(c->key);
    free(c->count);
    memset(c, 0, sizeof *c);
}

static void swapd(double **a, double **b)
{
    double *t = *a;
    *a = *b;
    *b = t;
}

static void swapi(int **a, int **b)
{
    int *t = *a;
    *a = *b;
    *b = t;
}

/* cells per axis for about `want` particles (bin/mpmbench's disks2d:
 * two disks of radius 0.14 at 2 x 2 per cell) */
int cl_disks_cells(long want)
{
    return (int)ceil(sqrt((double)want / (4.0 * 2.0 * M_PI * CL_RADIUS * CL_RADIUS)));
}

/* rows' extents, all empty (lo > hi) */
static int row_extents(int ny, int **lo, int **hi, int nx)
{
    *lo = malloc((size_t)ny * sizeof **lo);
    *hi = malloc((size_t)ny * sizeof **hi);
    if (!*lo || !*hi) return -ENOMEM;
    for (int j = 0; j < ny; j++) {
        (*lo)[j] = nx;
        (*hi)[j] = -1;
    }
    return 0;
}

int cl_case_new(cl_case *c, long want, int cells)
{
    memset(c, 0, sizeof *c);
    if (!cells) cells = cl_disks_cells(want);
    double h = 1.0 / cells, E = 1.0, nu = 0.2, rho = 1.0;
    cl_grid *g = &c->g;
    g->nx = g->ny = cells + 1;
    g->ih = 1.0 / h;
    g->lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
    g->mu2 = E / (1 + nu);
    g->dt = 0.5 * h / (sqrt((g->lambda + g->mu2) / rho) + CL_SPEED);
    size_t nn = (size_t)g->nx * (size_t)g->ny, cap = 4 * (size_t)cells * (size_t)cells;
    double **ga[] = {&g->m, &g->qx, &g->qy, &g->fx, &g->fy, &g->mi, &g->nm, &g->nqx, &g->nqy};
    for (size_t i = 0; i < sizeof ga / sizeof ga[0]; i++)
        if (!(*ga[i] = dalloc(nn))) return -ENOMEM;
    cl_parts *P = &c->P;
    double **pa[] = {&P->x,   &P->y,   &P->vx, &P->vy,  &P->sxx,
                     &P->syy, &P->sxy, &P->m,  &P->vol, &c->scratch};
    for (size_t i = 0; i < sizeof pa / sizeof pa[0]; i++)
        if (!(*pa[i] = dalloc(cap))) return -ENOMEM;
    if (row_extents(g->ny, &g->rlo, &g->rhi, g->nx) || row_extents(g->ny, &g->nlo, &g->nhi, g->nx))
        return -ENOMEM;
    if (!(c->key = malloc(cap * sizeof *c->key)) ||
        !(c->count = malloc((nn + 1) * sizeof *c->count)))
        return -ENOMEM;
    /* cell by cell, row-major: sorted from the start */
    double s = CL_SPEED / sqrt(2.0);
    size_t n = 0;
    for (int j = 0; j < cells; j++)
        for (int i = 0; i < cells; i++)
            for (int b = 0; b < 2; b++)
                for (int a = 0; a < 2; a++) {
                    double x = (i + 0.25 + 0.5 * a) * h, y = (j + 0.25 + 0.5 * b) * h;
                    double d1 = hypot(x - 0.25, y - 0.25), d2 = hypot(x - 0.75, y - 0.75);
                    if (d1 > CL_RADIUS && d2 > CL_RADIUS) continue;
                    double v = d1 <= CL_RADIUS ? s : -s;
                    P->x[n] = x;
                    P->y[n] = y;
                    P->vx[n] = P->vy[n] = v;
                    P->vol[n] = 0.25 * h * h;
                    P->m[n] = rho * P->vol[n];
                    n++;
                }
    P->n = n;
    /* the first step's mass and momentum: the moving pass with dt = 0
     * (its gathers read the zero grid), then the next grid made this one */
    double dt = g->dt;
    g->dt = 0;
    mv1(P, g);
    g->dt = dt;
    swapd(&g->m, &g->nm);
    swapd(&g->qx, &g->nqx);
    swapd(&g->qy, &g->nqy);
    swapi(&g->rlo, &g->nlo);
    swapi(&g->rhi, &g->nhi);
    return 0;
}

/* The particles in the order of their cells (row-major), by a stable
 * counting sort, each array through the scratch copy. */
static void sort_cells(cl_case *c)
{
    double t0 = cl_now();
    cl_parts *P = &c->P;
    size_t nn = (size_t)c->g.nx * (size_t)c->g.ny;
    memset(c->count, 0, (nn + 1) * sizeof *c->count);
    for (size_t p = 0; p < P->n; p++) {
        uint32_t k = (uint32_t)((int)(P->y[p] * c->g.ih) * c->g.nx + (int)(P->x[p] * c->g.ih));
        c->key[p] = k;
        c->count[k + 1]++;
    }
    for (size_t k = 0; k < nn; k++) c->count[k + 1] += c->count[k];
    for (size_t p = 0; p < P->n; p++) c->key[p] = (uint32_t)c->count[c->key[p]]++;
    double **a[] = {&P->x, &P->y, &P->vx, &P->vy, &P->sxx, &P->syy, &P->sxy, &P->m, &P->vol};
    for (size_t i = 0; i < sizeof a / sizeof a[0]; i++) {
        for (size_t p = 0; p < P->n; p++) c->scratch[c->key[p]] = (*a[i])[p];
        double *t = *a[i];
        *a[i] = c->scratch;
        c->scratch = t;
    }
    c->t_sort += cl_now() - t0;
    c->sorts++;
}

/* One step; returns the runs the moving pass took (for the sort). */
static size_t step(cl_case *c, const cl_kernels *k)
{
    cl_grid *g = &c->g;
    for (int j = 0; j < g->ny; j++) { /* 1/m (0 where m is 0), forces zeroed */
        if (g->rlo[j] > g->rhi[j]) continue;
        size_t a = (size_t)j * (size_t)g->nx + (size_t)g->rlo[j],
               w = (size_t)(g->rhi[j] - g->rlo[j] + 1);
        for (size_t n = a; n < a + w; n++) g->mi[n] = g->m[n] > 0 ? 1.0 / g->m[n] : 0.0;
        memset(g->fx + a, 0, w * sizeof *g->fx);
        memset(g->fy + a, 0, w * sizeof *g->fy);
    }
    k->stress_force(&c->P, g);
    for (int j = 0; j < g->ny; j++) { /* q += f dt; q/m and f/m in place */
        if (g->rlo[j] > g->rhi[j]) continue;
        size_t a = (size_t)j * (size_t)g->nx + (size_t)g->rlo[j],
               w = (size_t)(g->rhi[j] - g->rlo[j] + 1);
        for (size_t n = a; n < a + w; n++) {
            double mi = g->mi[n];
            g->qx[n] = (g->qx[n] + g->fx[n] * g->dt) * mi;
            g->qy[n] = (g->qy[n] + g->fy[n] * g->dt) * mi;
            g->fx[n] *= mi;
            g->fy[n] *= mi;
        }
    }
    size_t runs = k->move_p2g(&c->P, g);
    for (int j = 0; j < g->ny; j++) { /* this step's grid zeroed: the next step's next one */
        if (g->rlo[j] > g->rhi[j]) continue;
        size_t a = (size_t)j * (size_t)g->nx + (size_t)g->rlo[j],
               w = (size_t)(g->rhi[j] - g->rlo[j] + 1);
        memset(g->m + a, 0, w * sizeof *g->m);
        memset(g->qx + a, 0, w * sizeof *g->qx);
        memset(g->qy + a, 0, w * sizeof *g->qy);
        g->rlo[j] = g->nx;
        g->rhi[j] = -1;
    }
    swapd(&g->m, &g->nm);
    swapd(&g->qx, &g->nqx);
    swapd(&g->qy, &g->nqy);
    swapi(&g->rlo, &g->nlo);
    swapi(&g->rhi, &g->nhi);
    return runs;
}

void cl_run(cl_case *c, const cl_kernels *k, long steps)
{
    for (long s = 0; s < steps; s++) {
        size_t runs = step(c, k);
        if ((double)runs > CL_RUNS_SORT * (double)c->P.n) sort_cells(c);
    }
}

void cl_totals(const cl_parts *P, double *ek, double *px, double *py)
{
    *ek = *px = *py = 0;
    for (size_t p = 0; p < P->n; p++) {
        *ek += 0.5 * P->m[p] * (P->vx[p] * P->vx[p] + P->vy[p] * P->vy[p]);
        *px += P->m[p] * P->vx[p];
        *py += P->m[p] * P->vy[p];
    }
}

int cl_compare(const cl_kernels *ka, const cl_kernels *kb, long want, double t_end, cl_diff *d)
{
    cl_case a, b;
    memset(d, 0, sizeof *d);
    int rc = cl_case_new(&a, want, 0);
    if (!rc) rc = cl_case_new(&b, want, 0);
    if (!rc) {
        d->n = a.P.n;
        d->steps = (long)ceil(t_end / a.g.dt);
        d->t = (double)d->steps * a.g.dt;
        cl_run(&a, ka, d->steps);
        cl_run(&b, kb, d->steps);
        double vmax = 0, smax = 0, px, py;
        const double *sa[3] = {a.P.sxx, a.P.syy, a.P.sxy}, *sb[3] = {b.P.sxx, b.P.syy, b.P.sxy};
        for (size_t p = 0; p < a.P.n; p++) {
            d->dx = fmax(d->dx, fmax(fabs(a.P.x[p] - b.P.x[p]), fabs(a.P.y[p] - b.P.y[p])));
            d->dv = fmax(d->dv, fmax(fabs(a.P.vx[p] - b.P.vx[p]), fabs(a.P.vy[p] - b.P.vy[p])));
            vmax = fmax(vmax, fmax(fabs(a.P.vx[p]), fabs(a.P.vy[p])));
            for (int k = 0; k < 3; k++) {
                d->ds = fmax(d->ds, fabs(sa[k][p] - sb[k][p]));
                smax = fmax(smax, fabs(sa[k][p]));
            }
        }
        d->dv /= vmax > 0 ? vmax : 1;
        d->ds /= smax > 0 ? smax : 1;
        d->sorts[0] = a.sorts;
        d->sorts[1] = b.sorts;
        cl_totals(&a.P, &d->ek[0], &px, &py);
        cl_totals(&b.P, &d->ek[1], &px, &py);
    }
    cl_case_free(&a);
    cl_case_free(&b);
    return rc;
}
