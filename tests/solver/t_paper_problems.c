/*
 * t_paper_problems.c - the GMPM paper's verification problems against their
 * analytic solutions: the single material point (Section 5, Eqs. 32-33,
 * 38; Figs. 9-10, 15), the bar's first mode (Eqs. 34-37; Figs. 13, 18),
 * the 2D bouncing disks (Section 5.6) and a 3D bar.  Each test prints the
 * errors it measured; the tolerances are stated beside each check.
 */
#include "mpm.h"
#include "mpm_paper.h"
#include "t.h"

#include <stdlib.h>

#define V0 0.1

/* ---- 1. single material point ---- */

typedef struct {
    double verr, xerr, eq38, e0, emin, emax, eend;
} point_run;

static int run_point(mpm_update up, double dt, double tend, point_run *o)
{
    mpm_paper t;
    mpm_error err;
    mpm_paper_point(&t, up, dt, V0);
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    mpm_paper_free(&t);
    if (!s) {
        printf("    %s\n", TERR(&err));
        return -1;
    }
    double xv = 0, vv = 0;
    mpm_energy e;
    mpm_sim_energy(s, &e);
    *o = (point_run){0, 0, 0, e.total, e.total, e.total, e.total};
    long n = lround(tend / dt);
    for (long i = 0; i < n; i++) {
        if (mpm_sim_step(s)) {
            printf("    %s\n", TERR(mpm_sim_error(s)));
            mpm_sim_destroy(&s);
            return -1;
        }
        double tt = mpm_sim_time(s);
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = &xv, .v = &vv});
        double va = mpm_paper_point_v(V0, tt), xa = mpm_paper_point_x(V0, tt);
        o->verr = fmax(o->verr, fabs(vv - va));
        o->xerr = fmax(o->xerr, fabs(xv - xa));
        o->eq38 = fmax(o->eq38, fabs(va - vv) / (1 + fabs(va)));
        mpm_sim_energy(s, &e);
        o->emin = fmin(o->emin, e.total);
        o->emax = fmax(o->emax, e.total);
    }
    o->eend = e.total;
    mpm_sim_destroy(&s);
    return 0;
}

TEST(verify_point_usf_follows_analytic)
{
    point_run r;
    CHECK(run_point(MPM_USF, 1e-3, 3.0, &r) == 0);
    TLOG("MPM USF dt=1e-3, 3 periods: max |v - va| = %.3e (v0 = 0.1), max |x - xa| = %.3e", r.verr,
         r.xerr);
    /* 3% of v0 and 0.1% of x0 */
    CHECK(r.verr < 3e-3);
    CHECK(r.xerr < 5e-4);
}

TEST(verify_point_usl_loses_energy_usf_does_not_drift)
{
    point_run f, l;
    CHECK(run_point(MPM_USF, 1e-3, 3.0, &f) == 0);
    CHECK(run_point(MPM_USL, 1e-3, 3.0, &l) == 0);
    double df = (f.eend - f.e0) / f.e0, dl = (l.eend - l.e0) / l.e0;
    TLOG("E0 = %.6e; after 3 periods: USF %+.3e (oscillation %.2e), USL %+.3e (relative)", f.e0, df,
         (f.emax - f.emin) / f.e0, dl);
    /* USF: no drift beyond its bounded oscillation of O(dt); USL: a
     * monotone loss at least 10 times larger (Bardenhagen 2002) */
    CHECK(fabs(df) < 2e-3);
    CHECK(dl < -10 * fabs(df));
    CHECK(dl < -1e-2);
}

TEST(verify_point_eq38_error_falls_with_dt)
{
    point_run a, b;
    CHECK(run_point(MPM_USF, 0.1, 3.0, &a) == 0);
    CHECK(run_point(MPM_USF, 1e-4, 3.0, &b) == 0);
    TLOG("Eq. 38 error, max over 3 periods: dt=0.1 %.3e, dt=1e-4 %.3e (ratio %.0f)", a.eq38, b.eq38,
         a.eq38 / b.eq38);
    /* dt = 1e-4 leaves the error of the volume update: the analytic solution
     * holds the density constant, the solver updates the volume (about 1.6%
     * here), which shifts the frequency; hence a factor 20, not 1000 */
    CHECK(b.eq38 < a.eq38 / 20);
}

/* ---- 2. bar, first mode ---- */

static double bar_error(mpm_method m, mpm_update up, int ncell, int extra, double dt,
                        double periods, double v0)
{
    mpm_paper t;
    mpm_error err;
    if (mpm_paper_bar(&t, m, up, ncell, 1, extra, dt, v0)) return INFINITY;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    mpm_paper_free(&t);
    if (!s) {
        printf("    %s\n", TERR(&err));
        return INFINITY;
    }
    long n = lround(periods * 2 * M_PI / mpm_paper_bar_omega() / dt);
    double worst = 0;
    mpm_energy e;
    for (long i = 0; i < n; i++) {
        if (mpm_sim_step(s)) {
            printf("    %s\n", TERR(mpm_sim_error(s)));
            worst = INFINITY;
            break;
        }
        mpm_sim_energy(s, &e);
        double vcm = e.momentum[0] / e.mass;
        worst = fmax(worst, fabs(vcm - mpm_paper_bar_vcm(v0, mpm_sim_time(s))));
    }
    mpm_sim_destroy(&s);
    return worst;
}

TEST(verify_bar_first_mode)
{
    double em = bar_error(MPM_METHOD_MPM, MPM_USF, 7, 0, 1e-3, 2, V0);
    double eg = bar_error(MPM_METHOD_GIMP, MPM_USF, 13, 0, 1e-3, 2, V0);
    double amp = V0 * 2 / M_PI;
    TLOG("max |vcm - Eq.34| over 2 periods (amplitude %.4f): MPM 7/8 %.3e (%.1f%%), "
         "GMPM 13/14 %.3e (%.1f%%)",
         amp, em, 100 * em / amp, eg, 100 * eg / amp);
    /* measured 8.9% and 4.6%; the tolerance leaves a third on top */
    CHECK(em < 0.12 * amp);
    CHECK(eg < 0.06 * amp);
    CHECK(eg < em);
}

/* Refinement in the small-strain regime (v0 = 0.001, so that the linear
 * analytic solution is the limit and no particle crosses a cell), one
 * point per cell, dt = 1e-4, relative error of vcm over 2 periods. */
TEST(verify_bar_converges_under_refinement)
{
    const double v0 = 0.001, amp = v0 * 2 / M_PI;
    for (int m = 0; m < 2; m++) {
        int base = m ? 13 : 7;
        double e[4];
        for (int k = 0; k < 4; k++)
            e[k] = bar_error(m ? MPM_METHOD_GIMP : MPM_METHOD_MPM, MPM_USF, base << k, 2, 1e-4, 2,
                             v0) /
                   amp;
        for (int k = 0; k < 4; k++) {
            double order = k ? log(e[k - 1] / e[k]) / log(2.0) : 0;
            TLOG("%s %3d cells: relative vcm error %.3e  order %s%.2f", m ? "GMPM" : "MPM ",
                 base << k, e[k], k ? "" : "(n/a) ", order);
        }
        for (int k = 1; k < 4; k++) CHECK(e[k] < e[k - 1]);
        CHECK(e[3] < e[0] / 16); /* measured: about second order (1D, small strain) */
    }
}

/* ---- 3. the 2D bouncing disks (Section 5.6) ---- */

typedef struct {
    size_t n;
    double e0, kmin, semax, emin, emax, eend, kend, pmax, pscale;
} disk_run;

static int run_disks(mpm_method m, mpm_update up, double h, double dt, double tend, disk_run *o)
{
    mpm_paper t;
    mpm_error err;
    mpm_paper_disks(&t, m, up, h);
    t.c.dt = dt;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    mpm_paper_free(&t);
    if (!s) {
        printf("    %s\n", TERR(&err));
        return -1;
    }
    mpm_energy e;
    mpm_sim_energy(s, &e);
    *o = (disk_run){
        mpm_sim_particles(s) / 2, e.total, e.kinetic, 0, e.total, e.total, 0, 0, 0, e.mass * 0.1};
    while (mpm_sim_time(s) < tend) {
        if (mpm_sim_step(s)) {
            printf("    %s\n", TERR(mpm_sim_error(s)));
            mpm_sim_destroy(&s);
            return -1;
        }
        mpm_sim_energy(s, &e);
        o->kmin = fmin(o->kmin, e.kinetic);
        o->semax = fmax(o->semax, e.strain);
        o->emin = fmin(o->emin, e.total);
        o->emax = fmax(o->emax, e.total);
        o->pmax = fmax(o->pmax, hypot(e.momentum[0], e.momentum[1]));
    }
    o->eend = e.total;
    o->kend = e.kinetic;
    mpm_sim_destroy(&s);
    return 0;
}

TEST(verify_disks_coarse_and_fine)
{
    for (int fine = 0; fine < 2; fine++)
        for (int m = 0; m < 2; m++) {
            disk_run r;
            double h = fine ? 0.025 : 0.1;
            CHECK(run_disks(m ? MPM_METHOD_GIMP : MPM_METHOD_MPM, MPM_USF, h, 1e-3, 4.0, &r) == 0);
            TLOG("%s %s (%zu points/disk): |p|max/(M v0) = %.1e, KEmin/E0 = %.3f, SEmax/E0 = %.3f, "
                 "E in [%.4f, %.4f] E0, end %.4f E0, KEend/E0 = %.3f",
                 fine ? "fine  " : "coarse", m ? "GMPM" : "MPM ", r.n, r.pmax / r.pscale,
                 r.kmin / r.e0, r.semax / r.e0, r.emin / r.e0, r.emax / r.e0, r.eend / r.e0,
                 r.kend / r.e0);
            CHECK(r.n == (fine ? 392u : 24u)); /* the paper's counts */
            /* the disks' momenta cancel: total stays zero to round-off */
            CHECK(r.pmax < 1e-13 * r.pscale);
            /* kinetic energy goes into strain energy and comes back */
            CHECK(r.kmin < 0.1 * r.e0);
            CHECK(r.semax > 0.7 * r.e0);
            CHECK(r.kend > 0.85 * r.e0);
        }
}

/* GMPM + USF, fine: after the disks separate, total energy is back within
 * 1% of its start (measured +0.2% at dt = 1e-3).  During contact it dips by
 * up to 10% (measured 8%): the disks share grid nodes, and the energy the
 * particle fields carry misses what the grid momentarily holds; it is
 * returned on separation, so the dip is a measurement transient, not loss. */
TEST(verify_disks_fine_gimp_usf_energy)
{
    disk_run r;
    CHECK(run_disks(MPM_METHOD_GIMP, MPM_USF, 0.025, 1e-3, 4.0, &r) == 0);
    TLOG("GMPM USF fine: E end/E0 = %.5f, min %.4f, max %.4f", r.eend / r.e0, r.emin / r.e0,
         r.emax / r.e0);
    CHECK(fabs(r.eend / r.e0 - 1) < 0.01);
    CHECK(r.emin > 0.9 * r.e0);
    CHECK(r.emax < 1.01 * r.e0);
}

/* ---- 4. the bar in 2D and 3D ---- */

/* The bar of test 2 extruded into dim dimensions: ncell cells along x,
 * 2 cells across, ppc points per cell per axis, nu = 0, roller walls on
 * the lateral faces and x fixed at x = 0.  With nu = 0 and rollers the
 * response is exactly uniaxial, so it must reproduce the 1D run with the
 * same points along x, and the 1D frequency.  M_TOL is relative to the mean
 * particle mass, which differs between these layouts, so a sliver node at
 * the free end can be phantom in one and not in another (a 1e-9 effect);
 * the comparison runs with M_TOL off to be exact. */
static mpm_sim *bar_nd(int dim, mpm_method m, int ncell, int ppc, double v0, double mtol,
                       mpm_error *err)
{
    double h = 1.0 / ncell, beta = M_PI / 2;
    int per_x = ppc, across = 2 * ppc, nlat = dim == 1 ? 1 : dim == 2 ? across : across * across;
    size_t n = (size_t)ncell * per_x * nlat;
    double *x = malloc(n * dim * sizeof *x), *vol = malloc(n * sizeof *vol),
           *v = calloc(n * dim, sizeof *v);
    if (!x || !vol || !v) {
        free(x);
        free(vol);
        free(v);
        mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
        return NULL;
    }
    size_t p = 0;
    for (int i = 0; i < ncell * per_x; i++)
        for (int l = 0; l < nlat; l++, p++) {
            double xi = (i + 0.5) * h / ppc;
            x[p * dim] = xi;
            if (dim > 1) x[p * dim + 1] = (l % across + 0.5) * h / ppc;
            if (dim > 2) x[p * dim + 2] = (l / across + 0.5) * h / ppc;
            vol[p] = pow(h / ppc, dim);
            v[p * dim] = v0 * sin(beta * xi);
        }
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 10.0,
                             .poisson_ratio = 0.0,
                             .density = 1.0};
    mpm_body_desc b = {0};
    b.n_points = n;
    b.x = x;
    b.volume = vol;
    b.v = v;
    mpm_case c = {0};
    c.grid.dim = dim;
    c.grid.h[0] = c.grid.h[1] = c.grid.h[2] = h;
    c.grid.nodes[0] = ncell + 1;
    c.grid.nodes[1] = c.grid.nodes[2] = 3;
    c.method = m;
    c.update = MPM_USF;
    c.dt = 1e-3;
    c.mass_tol = mtol;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 1;
    c.bodies = &b;
    c.bc.face_mask[0] = 1; /* x fixed at x = 0 */
    for (int d = 1; d < dim; d++) c.bc.face_mask[2 * d] = c.bc.face_mask[2 * d + 1] = 1u << d;
    mpm_sim *s = mpm_sim_new(&c, NULL, err);
    free(x);
    free(vol);
    free(v);
    return s;
}

TEST(verify_bar_2d_3d_match_1d)
{
    for (int m = 0; m < 2; m++) {
        mpm_error err;
        mpm_method meth = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
        mpm_sim *s1 = bar_nd(1, meth, 8, 2, V0, 1e-300, &err),
                *s2 = bar_nd(2, meth, 8, 2, V0, 1e-300, &err),
                *s3 = bar_nd(3, meth, 8, 2, V0, 1e-300, &err);
        CHECKF(s1 && s2 && s3, "%s", TERR(&err));
        long n = lround(2 * 2 * M_PI / mpm_paper_bar_omega() / 1e-3);
        double d2 = 0, d3 = 0, ea = 0, amp = V0 * 2 / M_PI;
        mpm_energy e1, e2, e3;
        int rc = 0;
        for (long i = 0; i < n && !rc; i++) {
            rc = mpm_sim_step(s1) | mpm_sim_step(s2) | mpm_sim_step(s3);
            mpm_sim_energy(s1, &e1);
            mpm_sim_energy(s2, &e2);
            mpm_sim_energy(s3, &e3);
            double v1 = e1.momentum[0] / e1.mass;
            d2 = fmax(d2, fabs(e2.momentum[0] / e2.mass - v1));
            d3 = fmax(d3, fabs(e3.momentum[0] / e3.mass - v1));
            ea = fmax(ea, fabs(e3.momentum[0] / e3.mass - mpm_paper_bar_vcm(V0, mpm_sim_time(s3))));
            d3 = fmax(d3, fabs(e3.momentum[1]) + fabs(e3.momentum[2]));
        }
        TLOG("%s, 8 cells x 2 ppc, 2 periods: max |vcm 2D - 1D| = %.2e, |vcm 3D - 1D| = %.2e, "
             "|vcm 3D - Eq.34| = %.3e (%.1f%% of amplitude); %zu particles in 3D",
             m ? "GMPM" : "MPM ", d2, d3, ea, 100 * ea / amp, mpm_sim_particles(s3));
        mpm_sim_destroy(&s1);
        mpm_sim_destroy(&s2);
        mpm_sim_destroy(&s3);
        CHECK(rc == 0);
        CHECK(d2 < 1e-12);
        CHECK(d3 < 1e-12);
        /* the 1D run of this layout has the same error: measured 5.2% (MPM)
         * and 9.3% (GMPM; at v0 = 0.1 the strain reaches 3%, a geometric
         * nonlinearity that the linear Eq. 34 lacks) */
        CHECK(ea < 0.12 * amp);
    }
}
