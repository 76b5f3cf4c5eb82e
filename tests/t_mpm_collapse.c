/*
 * t_mpm_collapse.c - the plane-strain granular column collapse of issue 11
 * (validation 5, tools/mpm_collapse.h) in its fast configuration: a = 1,
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
#include "t.h"

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
