/*
 * t_collapse.c - the plane-strain granular column collapse
 * (scenes/include/mpm_collapse.h) in its fast configuration: a = 1,
 * 8 cells across the column (256 particles), Drucker-Prager (plane-strain
 * match, phi 30, psi 0, c 10 Pa) on a base with mu = tan 30, run to rest.
 * Checked against the experimental fits of Lube et al. 2005 (Phys. Rev. E
 * 72, 041301; as quoted by Lagree, Staron & Popinet 2011): run-out
 * (d_inf - d0)/d0 = 1.2 a and final height h_inf = h0 for a < 1.15.  The
 * tolerances are the spread of the published 2D fits (Lajeunesse et al.
 * 2005's glass beads give 1.8 a where Lube's sands give 1.2 a) and the
 * measured resolution dependence (docs/accuracy.md, "Granular column
 * collapse"): run-out within 25 % of 1.2, height within 15 %.  The energy
 * balance K + S + P + W_plastic + W_friction = E0 closes within 1 % of the
 * released potential energy, the deposit comes to rest, and no particle
 * leaves the grid (the run would fail with MPM_ELEFTGRID).
 */
#include "mpm.h"
#include "mpm_collapse.h"
#include "mpp_case.h"
#include "t.h"

#include <stdio.h>
#include <stdlib.h>

static void collapse_a1(mpm_method m)
{
    mpm_collapse_cfg cfg = {.a = 1, .cells = 8, .method = m, .model = MPM_MODEL_DRUCKER_PRAGER};
    mpm_collapse_res r;
    mpm_error err = {0};
    char buf[T_ERRLEN];
    int rc = t_errtext(mpm_collapse_run(&cfg, &r, &err), &err, buf);
    CHECKF(rc == 0, "collapse run failed: %s", buf);
    double ref = mpm_collapse_ref_runout(1.0, NULL), href = mpm_collapse_ref_height(1.0);
    TLOG("a = 1, 8 cells, method %d: run-out %.3f (Lube 1.2: %+.1f %%), height %.3f (%+.1f %%), "
         "rest at t = %.3f s (%ld steps), energy balance %.2e of the released %.3g J/m "
         "(plastic %.3g, friction %.3g)",
         (int)m, r.runout, 100 * (r.runout / ref - 1), r.height, 100 * (r.height / href - 1),
         r.t_end, r.steps, r.e_err, r.e_drop, r.wp, r.wf);
    CHECK(r.at_rest);
    CHECK_NEAR(r.runout, ref, 0.25 * ref);
    CHECK_NEAR(r.height, href, 0.15 * href);
    CHECK_LT(r.e_err, 0.01);
    /* nearly all the released energy is dissipated, most of it plastically */
    CHECK_LT(0.9 * r.e_drop, r.wp + r.wf);
    CHECK_LT(r.wf, r.wp);
}

TEST(collapse_a1_bspline2)
{
    collapse_a1(MPM_METHOD_BSPLINE2);
}

TEST(collapse_a1_gimp)
{
    collapse_a1(MPM_METHOD_GIMP);
}

/* the reference fits themselves, at the aspect ratios of the sweep */
TEST(collapse_reference)
{
    double band;
    CHECK_NEAR(mpm_collapse_ref_runout(0.5, &band), 0.6, 1e-12);
    CHECK_NEAR(band, 0, 0);
    CHECK_NEAR(mpm_collapse_ref_runout(4, NULL), 1.9 * pow(4, 2.0 / 3.0), 1e-12);
    CHECK_NEAR(mpm_collapse_ref_runout(2, &band), 0.5 * (2.4 + 1.9 * pow(2, 2.0 / 3.0)), 1e-12);
    CHECK_NEAR(band, 0.5 * (1.9 * pow(2, 2.0 / 3.0) - 2.4), 1e-12);
    CHECK_NEAR(mpm_collapse_ref_height(1), 1, 0);
    CHECK_NEAR(mpm_collapse_ref_height(4), pow(4, 0.4), 1e-12);
}

/* proto/examples/collapse2d.json (a = 2, d0 = 0.1 m, 8 cells across,
 * BSPLINE2, DP; a box body, so it starts stress-free rather than
 * geostatic) through the codec, its cohesion set to c (< 0: the file's),
 * run to its end time: the run-out against Lube's a = 2 (the transition
 * between the fits: 2.40 to 3.02, their mean 2.71) within 30 %, the
 * height at the back wall within 30 % of 2^0.4, and the energy balance
 * with the plastic and friction work within 2 % of the released potential
 * energy. */
static void run_example(double c)

{
    size_t len = 0;
    mpp_case *mc = NULL;
    mpm_error e = {0};
    char err[T_ERRLEN];
    FILE *f = fopen("proto/examples/collapse2d.json", "rb");
    CHECK(f);
    char *text = malloc(1 << 16);
    if (text) len = fread(text, 1, 1 << 16, f);
    fclose(f);
    CHECK(text && len > 0);
    int rc = t_errtext(mpp_case_load(text, len, 0, &mc, &e), &e, err);
    free(text);
    CHECKF(rc == 0, "%s", err);
    if (c >= 0) ((mpm_material_desc *)mc->c.materials)[0].cohesion = c;
    mpm_sim *s = mpm_sim_new(&mc->c, NULL, &e);
    double tend = mc->end_time, h = mc->c.grid.h[0];
    mpp_case_destroy(&mc);
    CHECK(s);
    mpm_energy e0, e1;
    mpm_sim_energy(s, &e0);
    double emax = 0;
    rc = 0;
    while (!rc && mpm_sim_time(s) < tend) {
        rc = mpm_sim_step(s);
        if (mpm_sim_steps(s) % 50) continue;
        mpm_sim_energy(s, &e1);
        double bal = e1.kinetic + e1.strain + e1.potential + e1.plastic_work + e1.friction_work -
                     e0.kinetic - e0.strain - e0.potential;
        if (fabs(bal) > emax) emax = fabs(bal);
    }
    CHECKF(rc == 0, "%s", t_errtext(rc, mpm_sim_error(s), err) ? err : "");
    mpm_sim_energy(s, &e1);
    size_t n = mpm_sim_particles(s);
    double *x = malloc(2 * n * sizeof *x), front = 0, height = 0;
    CHECK(x);
    mpm_snapshot sn = {.x = x};
    mpm_sim_snapshot(s, &sn);
    mpm_sim_destroy(&s);
    mpm_collapse_measure(x, n, h / 2, h, h, &front, &height);
    free(x);
    double d0 = 0.1, runout = (front - d0) / d0, hh = height / d0,
           drop = e0.potential - e1.potential;
    double ref = mpm_collapse_ref_runout(2, NULL), href = mpm_collapse_ref_height(2);
    TLOG(
        "collapse2d, cohesion %g Pa: run-out %.3f (ref %.3f, %+.1f %%), height %.3f (ref %.3f, %+.1f %%), K at "
        "the end %.2e of the released %.3g J/m, balance %.2e",
        c < 0 ? 10 : c, runout, ref, 100 * (runout / ref - 1), hh, href, 100 * (hh / href - 1),
        e1.kinetic / drop, drop, emax / drop);
    CHECK_NEAR(runout, ref, 0.3 * ref);
    CHECK_NEAR(hh, href, 0.3 * href);
    CHECK_LT(emax / drop, 0.02);
    CHECK_LT(e1.kinetic, 0.01 * drop);
}

TEST(collapse_example)
{
    run_example(-1);
}

/* The same column of cohesionless sand (c = 0) and of c = 2 Pa: Sloan's
 * substepping could not resolve the free surface's increments near the
 * apex, and the run stopped at 0.011 s (c = 0) and 0.19 s (c = 2) with
 * "substepping exhausted"; the update now falls back on backward Euler's
 * return there (plastic_dp_near_apex), and the run meets the example's
 * tolerances (measured: run-out +17.4 % and +23.0 %, balances 2.4e-3 and
 * 2.3e-3). */
TEST(collapse_cohesionless)
{
    run_example(0);
    run_example(2);
}
