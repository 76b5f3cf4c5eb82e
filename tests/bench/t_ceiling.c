/*
 * t_ceiling.c - bin/mpmceiling's lean step (bench/ceiling/) is the
 * solver's step: the ceiling it measures is only worth quoting if the lean
 * step does the same arithmetic as the solver's fused MPM USF step on the
 * same scene.  ceiling_matches_solver runs the paper's disks at h = 0.025
 * (784 particles) to t = 2.6, half a unit of time into their contact,
 * through the solver (1 thread, the same fixed dt) and through the lean
 * step, and compares order-free sums of the particles: the kinetic
 * energy, sum V sigma and the mean position of the first disk.
 * ceiling_kernels_agree runs the lean step's portable and four-lane
 * kernels from one start (10^4 particles, t = 2.6) where the CPU has the
 * latter.
 */
#include "ceiling/ceiling.h"
#include "mpm.h"
#include "mpm_paper.h"
#include "t.h"

#include <stdlib.h>
#include <string.h>

/* the disks-fine grid: 40 cells per axis */
#define CELLS 40
#define STEPS 240 /* t = 2.599: the disks touch at t = 2.1 */

/* order-free sums of a particle set: kinetic energy, V sigma, the sum of
 * x over the first disk's particles (x + y < 1) */
typedef struct {
    double ek, vs[3], x1[2];
    size_t n, n1;
} sums;

static void add_particle(sums *s, double m, const double x[2], const double v[2], double vol,
                         const double sig[3])
{
    s->ek += 0.5 * m * (v[0] * v[0] + v[1] * v[1]);
    for (int k = 0; k < 3; k++) s->vs[k] += vol * sig[k];
    if (x[0] + x[1] < 1.0) {
        s->x1[0] += x[0];
        s->x1[1] += x[1];
        s->n1++;
    }
    s->n++;
}

TEST(ceiling_matches_solver)
{
    cl_case c;
    int rc = cl_case_new(&c, 0, CELLS);
    if (rc) cl_case_free(&c);
    CHECK(rc == 0);
    double dt = c.g.dt, ek0, px, py;
    cl_totals(&c.P, &ek0, &px, &py);
    cl_run(&c, cl_kernels_portable(), STEPS);
    sums L = {0};
    for (size_t p = 0; p < c.P.n; p++) {
        double x[2] = {c.P.x[p], c.P.y[p]}, v[2] = {c.P.vx[p], c.P.vy[p]};
        double sig[3] = {c.P.sxx[p], c.P.syy[p], c.P.sxy[p]};
        add_particle(&L, c.P.m[p], x, v, c.P.vol[p], sig);
    }
    long sorts = c.sorts;
    cl_case_free(&c);

    mpm_paper t;
    mpm_paper_disks(&t, MPM_METHOD_MPM, MPM_USF, 1.0 / CELLS);
    t.c.dt = dt;
    mpm_error me;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &me);
    mpm_paper_free(&t);
    CHECK(s != NULL);
    for (int k = 0; k < STEPS && !rc; k++) rc = mpm_sim_step(s);
    size_t n = mpm_sim_particles(s);
    double *x = malloc(2 * n * sizeof *x), *v = malloc(2 * n * sizeof *v),
           *sig = malloc(6 * n * sizeof *sig), *vol = malloc(n * sizeof *vol);
    if (!rc && x && v && sig && vol) {
        mpm_snapshot snap = {.x = x, .v = v, .stress = sig, .volume = vol};
        mpm_sim_snapshot(s, &snap);
    }
    mpm_energy e;
    mpm_sim_energy(s, &e);
    double t_end = mpm_sim_time(s);
    mpm_sim_destroy(&s);
    sums S = {0};
    if (!rc && x && v && sig && vol)
        for (size_t p = 0; p < n; p++) {
            /* stress as xx, yy, zz, xy, ... (mpm.h): xy is the fourth */
            double s3[3] = {sig[6 * p], sig[6 * p + 1], sig[6 * p + 3]};
            add_particle(&S, 0, x + 2 * p, v + 2 * p, vol[p], s3); /* no masses: E_k from e */
        }
    free(x);
    free(v);
    free(sig);
    free(vol);
    CHECK(rc == 0);
    TLOG(
        "disks h = 1/%d, %d steps to t = %.4f (dt %.9g), %zu particles, lean step sorted %ld times",
        CELLS, STEPS, t_end, dt, L.n, sorts);
    TLOG("kinetic energy: lean %.12e, solver %.12e", L.ek, e.kinetic);
    TLOG("sum V sigma: lean (%.9e, %.9e, %.9e), solver (%.9e, %.9e, %.9e)", L.vs[0], L.vs[1],
         L.vs[2], S.vs[0], S.vs[1], S.vs[2]);
    TLOG("first disk's mean position: lean (%.12f, %.12f), solver (%.12f, %.12f)", L.x1[0] / L.n1,
         L.x1[1] / L.n1, S.x1[0] / S.n1, S.x1[1] / S.n1);
    CHECK(L.n == S.n && L.n1 == S.n1);
    /* the disks are in contact: the energies and stresses are far from
     * their starting values, so agreeing to 1e-9 is the same arithmetic */
    CHECK_LT(e.kinetic, 0.6 * ek0);
    CHECK_NEAR(L.ek, e.kinetic, 1e-9 * e.kinetic);
    double smax = fmax(fabs(S.vs[0]), fmax(fabs(S.vs[1]), fabs(S.vs[2])));
    CHECK_LT(1e-6, smax);
    for (int k = 0; k < 3; k++) CHECK_NEAR(L.vs[k], S.vs[k], 1e-9 * smax);
    for (int d = 0; d < 2; d++) CHECK_NEAR(L.x1[d] / L.n1, S.x1[d] / S.n1, 1e-12);
}

TEST(ceiling_kernels_agree)
{
    const cl_kernels *k4 = cl_kernels_avx2();
    if (!k4) {
        TLOG("no four-lane kernels on this CPU or build: nothing to compare");
        return;
    }
    cl_diff d;
    CHECK(cl_compare(cl_kernels_portable(), k4, 10000, 2.6, &d) == 0);
    TLOG("%zu particles, %ld steps to t = %.3f, portable against %s: largest difference in x %.2e, "
         "in v %.2e of |v|max, in sigma %.2e of |sigma|max; sorts %ld and %ld",
         d.n, d.steps, d.t, k4->name, d.dx, d.dv, d.ds, d.sorts[0], d.sorts[1]);
    CHECK(d.sorts[0] > 0 && d.sorts[0] == d.sorts[1]);
    CHECK_LT(d.dx, 1e-10);
    CHECK_LT(d.dv, 1e-10);
    CHECK_LT(d.ds, 1e-10);
    CHECK_NEAR(d.ek[0], d.ek[1], 1e-10 * d.ek[0]);
}
