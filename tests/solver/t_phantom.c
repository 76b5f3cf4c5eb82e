/*
 * t_phantom.c - a uniform velocity stays uniform when particles land on
 * grid lines (no gradient weight from a phantom node).
 *
 * A particle on a grid line, exactly or to within round-off, gives the node
 * across the line a weight of zero or ~1e-16 but, with linear MPM tents, a
 * gradient weight of +-1/h.  At the leading face of a body that node gets
 * no other mass, falls below M_TOL and is phantom (velocity 0 in the
 * strain, Fig. 7): before the fix its gradient weight still entered the
 * strain, and a rigidly translating cube built up sigma/E ~ 8e-3.  Every
 * case here moves a stress-free body at a uniform velocity and asserts
 * max |sigma| / E <= 1e-12 over every step, plus the rigid motion itself.
 */
#include "mpm.h"
#include "t.h"

#include <stdlib.h>
#include <string.h>

#define E_MOD 100.0

typedef struct {
    double smax; /* max |sigma| / E over all steps and particles */
    double dx;   /* max |x - x0 - v t| at the end */
    int rc;      /* mpm_sim_run()'s result */
} tr_result;

/* Steps a stress-free body at uniform velocity v, checking the stress after
 * every step. */
static void translate(const mpm_case *c, const double v[3], long steps, tr_result *r)
{
    memset(r, 0, sizeof *r);
    mpm_error err;
    mpm_sim *s = mpm_sim_new(c, NULL, &err);
    if (!s) {
        r->rc = -1;
        TLOG("%s", TERR(&err));
        return;
    }
    int dim = c->grid.dim;
    size_t n = mpm_sim_particles(s);
    double *x0 = malloc(n * 3 * sizeof *x0), *x1 = malloc(n * 3 * sizeof *x1),
           *sig = malloc(n * 6 * sizeof *sig);
    if (!x0 || !x1 || !sig) {
        r->rc = -1;
    } else {
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = x0});
        for (long k = 0; k < steps && !r->rc; k++) {
            r->rc = mpm_sim_step(s);
            mpm_sim_snapshot(s, &(mpm_snapshot){.stress = sig});
            for (size_t i = 0; i < n * 6; i++) r->smax = fmax(r->smax, fabs(sig[i]) / E_MOD);
        }
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = x1});
        double T = mpm_sim_time(s);
        for (size_t p = 0; p < n; p++)
            for (int d = 0; d < dim; d++)
                r->dx = fmax(r->dx, fabs(x1[p * dim + d] - x0[p * dim + d] - v[d] * T));
        if (r->rc) TLOG("%s", TERR(mpm_sim_error(s)));
    }
    free(x0);
    free(x1);
    free(sig);
    mpm_sim_destroy(&s);
}

static const char *mname(mpm_method m)
{
    return m == MPM_METHOD_GIMP       ? "GIMP"
           : m == MPM_METHOD_BSPLINE2 ? "BSPLINE2"
           : m == MPM_METHOD_BSPLINE3 ? "BSPLINE3"
           : m == MPM_METHOD_CPDI     ? "CPDI"
                                      : "MPM ";
}

/* the methods every case runs: MPM, GIMP, the B-splines and CPDI (whose
 * corners meet grid lines as the centres do) */
static const mpm_method methods[5] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2,
                                      MPM_METHOD_BSPLINE3, MPM_METHOD_CPDI};

static const char *uname(int up)
{
    return up == MPM_USF ? "USF " : up == MPM_USL ? "USL " : "MUSL";
}

/* The issue's case: a cube of 8^3 = 512 generated points (2 per cell per
 * axis, h = 0.1) at v = (0.3, 0.2, -0.1), dt = 0.002, 500 steps: it
 * crosses 3 cells along x, and its points pass the grid lines to within
 * round-off (x = 0.425 + k 6e-4 is a grid line for k = 125 up to
 * round-off).  Measured before the fix (mpm_kernels.c, gather()): MPM
 * sigma/E 8.3e-3 (USF), 8.5e-3 (MUSL), USL diverged at step 131; GIMP
 * 4.2e-13.  After: at most 5.2e-15 (MPM USL), 2.2e-16 otherwise.  The
 * B-splines (BSPLINE2, BSPLINE3) run the same cases. */
TEST(phantom_issue_cube_translates_without_stress)
{
    for (int m = 0; m < 5; m++)
        for (int up = 0; up < 3; up++) {
            mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                                     .youngs_modulus = E_MOD,
                                     .poisson_ratio = 0.3,
                                     .density = 2.0};
            double v[3] = {0.3, 0.2, -0.1};
            mpm_body_desc b = {0};
            b.shape = MPM_SHAPE_BOX;
            b.ppc = 2;
            for (int d = 0; d < 3; d++) {
                b.lo[d] = 0.4;
                b.hi[d] = 0.8;
                b.velocity[d] = v[d];
            }
            mpm_case c = {0};
            c.grid = (mpm_grid_desc){3, {0, 0, 0}, {0.1, 0.1, 0.1}, {16, 16, 16}};
            c.method = methods[m];
            c.update = (mpm_update)up;
            c.dt = 0.002;
            c.n_materials = 1;
            c.materials = &mat;
            c.n_bodies = 1;
            c.bodies = &b;
            tr_result r;
            translate(&c, v, 500, &r);
            TLOG("3D %s %s 512 points, 500 steps: max |sigma|/E = %.2e, max |x - x0 - v t| = "
                 "%.2e",
                 mname(c.method), uname(up), r.smax, r.dx);
            CHECKF(r.rc == 0, "%s %s: run failed", mname(c.method), uname(up));
            CHECKF(r.smax <= 1e-12, "%s %s: sigma/E %.3e", mname(c.method), uname(up), r.smax);
            CHECKF(r.dx <= 1e-12, "%s %s: drift %.3e", mname(c.method), uname(up), r.dx);
        }
}

/* Explicit points, n per axis at spacing h/2 starting on a grid line, so
 * that half of them sit exactly on grid lines at t = 0 (the nodes ahead of
 * the leading face get mass exactly 0 and gradient weight 1/h); h = 1/8 and
 * power-of-two velocity components with dt = 1/256 bring them back onto
 * grid lines (to round-off) every few dozen steps.  Before the fix: MPM
 * sigma/E 7.8e-3 .. 2.0e-2 with USF and MUSL (USL diverged), GIMP 3D
 * 1.1e-12 on the diagonal; after: at most 1.5e-15. */
static void lines_case(mpm_case *c, mpm_body_desc *b, mpm_material_desc *mat, double *x,
                       double *vol, int dim, int n, const double v[3])
{
    const double h = 0.125;
    memset(c, 0, sizeof *c);
    memset(b, 0, sizeof *b);
    *mat = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                               .youngs_modulus = E_MOD,
                               .poisson_ratio = 0.25,
                               .density = 1.0};
    size_t np = 0;
    int ext[3] = {n, dim > 1 ? n : 1, dim > 2 ? n : 1};
    for (int k = 0; k < ext[2]; k++)
        for (int j = 0; j < ext[1]; j++)
            for (int i = 0; i < ext[0]; i++) {
                int ijk[3] = {i, j, k};
                for (int d = 0; d < dim; d++) x[np * dim + d] = 2.0 + 0.5 * h * ijk[d];
                vol[np] = pow(0.5 * h, dim);
                np++;
            }
    for (int d = 0; d < dim; d++) {
        c->grid.h[d] = h;
        c->grid.nodes[d] = 41; /* [0, 5] */
        b->velocity[d] = v[d];
    }
    c->grid.dim = dim;
    b->n_points = np;
    b->x = x;
    b->volume = vol;
    c->n_materials = 1;
    c->materials = mat;
    c->n_bodies = 1;
    c->bodies = b;
}

/* MPM + USL is held to the bound only for the skew velocity with the
 * non-dyadic dt.  With the power-of-two velocities and dt = 1/256 a whole
 * face of points reaches a grid line together, to within ~1e-13..1e-11 of
 * a cell, the nodes ahead get small masses that are not phantom (above
 * M_TOL), and USL's strain from the updated grid velocity (q + f dt)/m
 * multiplies round-off stress by ~(c dt / h)^2 m_p / m: the MPM + USL
 * limitation of t_invariants.c and docs/accuracy.md, not the phantom
 * gradient.  Measured: 2D v0 diverges (step 386), 2D v1 2.1e-12, 2D v2
 * 1.7e-11, 3D v2 3.6e-11, the others <= 4.3e-13; with M_TOL = 1e-9 the 2D
 * v0 run holds but reaches 8.4e-12.  Those runs are logged, not asserted. */
TEST(phantom_uniform_velocity_on_grid_lines)
{
    /* directions: along an axis, against it, a diagonal, a skew one; with
     * dyadic and non-dyadic dt */
    static const double vs[][3] = {
        {0.25, 0, 0}, {-0.125, 0, 0}, {0.25, 0.25, 0.25}, {0.3, -0.7, 0.45}, {0, 0, -0.5}};
    static const double dts[] = {1.0 / 256, 0.00173, 1.0 / 256, 0.0021, 1.0 / 256};
    static double x[6 * 6 * 6 * 3], vol[6 * 6 * 6];
    double worst = 0;
    int runs = 0;
    for (int dim = 1; dim <= 3; dim++)
        for (int m = 0; m < 5; m++)
            for (int up = 0; up < 3; up++)
                for (int iv = 0; iv < 5; iv++) {
                    if (dim < 3 && iv == 4) continue; /* only z moves */
                    mpm_case c;
                    mpm_body_desc b;
                    mpm_material_desc mat;
                    lines_case(&c, &b, &mat, x, vol, dim, 6, vs[iv]);
                    c.method = methods[m];
                    c.update = (mpm_update)up;
                    c.dt = dts[iv];
                    tr_result r;
                    long steps = dim == 3 ? 300 : 600;
                    translate(&c, vs[iv], steps, &r);
                    if (m == 0 && up == MPM_USL && iv != 3) {
                        TLOG("%dD MPM  USL  v%d (not asserted): %s, max |sigma|/E = %.2e", dim, iv,
                             r.rc ? "diverged" : "ran", r.smax);
                        continue;
                    }
                    worst = fmax(worst, r.smax);
                    runs++;
                    CHECKF(r.rc == 0, "%dD %s %s v%d: run failed", dim, mname(c.method), uname(up),
                           iv);
                    CHECKF(r.smax <= 1e-12, "%dD %s %s v%d: sigma/E %.3e", dim, mname(c.method),
                           uname(up), iv, r.smax);
                    CHECKF(r.dx <= 1e-12, "%dD %s %s v%d: drift %.3e", dim, mname(c.method),
                           uname(up), iv, r.dx);
                    if (iv == 3)
                        TLOG("%dD %s %s v = (0.3, -0.7, 0.45), dt 0.0021, %ld steps: "
                             "max |sigma|/E = %.2e, drift %.2e",
                             dim, mname(c.method), uname(up), steps, r.smax, r.dx);
                }
    TLOG("worst max |sigma|/E over %d asserted runs: %.2e", runs, worst);
}
