/*
 * t_musl.c - the 1D manufactured solution (bench/accuracy/problems.c's
 * mms1d) at the two places it pins a measured property.  MUSL at fine
 * resolution (docs/accuracy.md, "MUSL at fine resolution"): MUSL moves the
 * points with the Lagrangian grid velocity and strains them with the
 * remapped one, and once the points have crossed a few cells the two drift
 * apart; at 256 cells (ppc 2, C = 0.5, one period, displacement amplitude
 * 5 cells) MUSL with pure FLIP breaks down (relative error 0.45-0.46 for
 * GIMP and BSPL2), while USL and MUSL with a PIC blend of 0.05 stay near
 * 3e-3.  If the breakdown check fails, MUSL has changed: update the
 * section of docs/accuracy.md (and docs/features.md's limitation) with the new
 * figures rather than the bound.  And BSPLINE3's convergence at a large
 * amplitude, which its natural end basis restored.
 */
#include "mpm.h"
#include "t.h"

#include <math.h>
#include <stdlib.h>

#define MMS_PPC 2

/* The manufactured solution of bench/accuracy/problems.c (mms1d): u = A
 * sin(2 pi X) sin(pi c t), E = rho = 1, rollers at both ends, body force
 * per point through mpm_sim_set_particle_forces(), on `cells` cells.
 * Returns the largest RMS position error over 20 samples, divided by A;
 * -1 on failure. */
static double mms1d_error(mpm_method m, mpm_update up, double pic, int cells, double A)
{
    int n = cells * MMS_PPC;
    double h = 1.0 / cells;
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 1.0,
                             .poisson_ratio = 0.0,
                             .density = 1.0};
    double c = mpm_material_wave_speed(&mat, 1), om = M_PI * c;
    double *X = malloc((size_t)n * 7 * sizeof *X);
    if (!X) return -1;
    double *v = X + n, *vol = v + n, *hl = vol + n, *f = hl + n, *x = f + n, *sx = x + n;
    for (int q = 0; q < n; q++) {
        X[q] = (q + 0.5) / n;
        sx[q] = sin(2 * M_PI * X[q]);
        v[q] = A * om * sx[q];
        vol[q] = h / MMS_PPC;
        hl[q] = 0.5 * h / MMS_PPC;
    }
    double tend = 2.0 / c;
    long ns = (long)ceil(tend / (0.5 * h / c));
    mpm_body_desc b = {0};
    b.n_points = (size_t)n;
    b.x = X;
    b.volume = vol;
    b.v = v;
    b.half_length = hl;
    mpm_case cs = {0};
    cs.grid.dim = 1;
    cs.grid.h[0] = h;
    cs.grid.nodes[0] = cells + 1;
    cs.bc.face_mask[0] = cs.bc.face_mask[1] = 1;
    cs.method = m;
    cs.update = up;
    cs.pic_fraction = pic;
    cs.dt = tend / (double)ns;
    cs.allow_unstable_dt = 1;
    cs.n_materials = 1;
    cs.materials = &mat;
    cs.n_bodies = 1;
    cs.bodies = &b;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&cs, NULL, &err);
    double emax = -1, k = M_PI * M_PI * c * c * A, tw = 2 * M_PI * A;
    if (!s) goto out;
    emax = 0;
    for (long i = 0; i < ns; i++) {
        double st = sin(om * mpm_sim_time(s));
        for (int q = 0; q < n; q++) {
            double F = 1 + tw * cos(2 * M_PI * X[q]) * st;
            f[q] = vol[q] * k * sx[q] * st * (4 / F - 1);
        }
        if (mpm_sim_set_particle_forces(s, f) || mpm_sim_step(s)) {
            emax = -1;
            break;
        }
        if ((i + 1) % (ns / 20) == 0) {
            double s1 = sin(om * mpm_sim_time(s)), e2 = 0;
            mpm_sim_snapshot(s, &(mpm_snapshot){.x = x});
            for (int q = 0; q < n; q++) {
                double d = x[q] - X[q] - A * sx[q] * s1;
                e2 += d * d;
            }
            emax = fmax(emax, sqrt(e2 / n) / A);
        }
    }
    mpm_sim_destroy(&s);
out:
    free(X);
    return emax;
}

TEST(musl_mms1d_fine_grid_breakdown_and_pic_workaround)
{
    static const struct {
        mpm_method m;
        const char *name;
    } ms[] = {{MPM_METHOD_GIMP, "GIMP"}, {MPM_METHOD_BSPLINE2, "BSPL2"}};
    for (size_t i = 0; i < sizeof ms / sizeof ms[0]; i++) {
        double usl = mms1d_error(ms[i].m, MPM_USL, 0, 256, 0.02);
        double musl = mms1d_error(ms[i].m, MPM_MUSL, 0, 256, 0.02);
        double blend = mms1d_error(ms[i].m, MPM_MUSL, 0.05, 256, 0.02);
        TLOG("%s, 256 cells, ppc 2, C 0.5: USL %.3e, MUSL %.3e, MUSL pic 0.05 %.3e", ms[i].name,
             usl, musl, blend);
        CHECK(usl >= 0 && musl >= 0 && blend >= 0);
        CHECK_LT(usl, 5e-3);
        CHECK_LT(blend, 1e-2);
        /* the documented limitation (measured 0.45-0.46) */
        CHECKF(musl > 0.1,
               "%s MUSL error %.3e: MUSL no longer breaks down here; update "
               "docs/accuracy.md (MUSL at fine resolution) and this test",
               ms[i].name, musl);
    }
}

/* Large amplitude (A = 0.05, stretches 0.69-1.31) with USL on 16, 32 and
 * 64 cells: BSPLINE3's error shrinks under refinement (measured 5.5e-2,
 * 1.4e-2, 4.3e-3).  With the clamped cubic ends it grew instead (3.9e-2
 * -> 1.2e-1 on a fixed-end neo-Hookean form of the problem): the
 * particles' forces on the two clamped spans did not integrate a uniform
 * stress, and the material pulled away from the ends (mpm_bspline.c, the
 * natural end basis).  BSPLINE2 is printed, not bound: it levels off near
 * 2e-2 (docs/accuracy.md, "BSPLINE3 at the grid's ends"). */
TEST(bspline3_mms1d_large_amplitude)
{
    double e[2][3];
    for (int i = 0; i < 2; i++) {
        mpm_method m = i ? MPM_METHOD_BSPLINE3 : MPM_METHOD_BSPLINE2;
        for (int k = 0; k < 3; k++) e[i][k] = mms1d_error(m, MPM_USL, 0, 16 << k, 0.05);
        TLOG("%s USL, A 0.05: error %.3e (16 cells), %.3e (32), %.3e (64); orders %.2f, %.2f",
             i ? "BSPLINE3" : "BSPLINE2", e[i][0], e[i][1], e[i][2], log2(e[i][0] / e[i][1]),
             log2(e[i][1] / e[i][2]));
        CHECK(e[i][0] > 0 && e[i][1] > 0 && e[i][2] > 0);
    }
    CHECK(e[1][1] < 0.6 * e[1][0] && e[1][2] < 0.6 * e[1][1]);
    CHECK(e[1][2] < 1e-2);
}
