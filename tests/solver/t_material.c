/*
 * t_material.c - the material models (solver/mpm_model.c): von Mises (J2) against the closed form
 * of uniaxial strain and uniaxial stress, at the stress point and through the solver; the
 * Neo-Hookean Cauchy stress against its closed form and the derivative of
 * its stored energy, and a homogeneous stretch through the solver; the
 * Jaumann rate's objectivity; the volume updates DET_F and CONSTANT; the
 * energy balance with plastic work; the general block update giving
 * linear elasticity's bits; and linear elasticity without a strain
 * record.
 */
#include "mpm.h"
#include "mpm_internal.h"
#include "mpm_material_table.h"
#include "mpm_model.h"
#include "t.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static mpm_mat_params params(mpm_model_kind k, double E, double nu, double sy, double H, int dim)
{
    mpm_material_desc d = {.model = k,
                           .youngs_modulus = E,
                           .poisson_ratio = nu,
                           .density = 1.0,
                           .yield_stress = sy,
                           .hardening_modulus = H};
    mpm_mat_params mp;
    mpm_error err;
    memset(&mp, 0, sizeof mp);
    if (mpm_material_check(&d, dim, 0, &err))
        mp.E = -1;
    else
        mpm_model_params(&d, dim, &mp);
    return mp;
}

/* Uniaxial strain e_xx = e (the other strains 0) with J2 and linear
 * hardening, loaded monotonically to emax, then unloaded elastically to e:
 * sxx, syy and eps_p in closed form.  Elastic: sxx = (lambda + 2 mu) e,
 * syy = lambda e; yield where q = 2 mu e = sy; then p = K e, q = sy + H
 * eps_p, eps_p = 2 mu (e - e_y) / (3 mu + H) (dq = 2 mu de - 3 mu deps_p =
 * H deps_p), sxx = p + 2q/3, syy = p - q/3; unloading: q_s = q_max -
 * 2 mu (emax - e). */
static void j2_uniaxial_strain(const mpm_mat_params *mp, double e, double emax, int unload,
                               double *sxx, double *syy, double *ep)
{
    double mu = mp->mu, K = mp->K, ey = mp->sy0 / (2 * mu);
    double em = unload ? emax : e;
    double epm = em > ey ? 2 * mu * (em - ey) / (3 * mu + mp->H) : 0.0;
    double q = em > ey ? mp->sy0 + mp->H * epm : 2 * mu * em;
    if (unload) q -= 2 * mu * (emax - e);
    *sxx = K * e + 2 * q / 3;
    *syy = K * e - q / 3;
    *ep = epm;
}

/* The J2 point update (the function the solver's rate-form block calls)
 * along uniaxial strain to 6 e_y (increments 0.15 e_y, so that yield falls
 * inside one) and back by e_y: stress and plastic strain against the
 * closed form to 1e-10 relative; the plastic work against the integral
 * of q d eps_p = sy eps_p + H eps_p^2 / 2 (the return's q_{n+1} dg is a
 * first-order quadrature of it: 2 % here). */
TEST(material_j2_point_uniaxial_strain)
{
    for (int dim = 2; dim <= 3; dim++) {
        mpm_mat_params mp = params(MPM_MODEL_VON_MISES, 1000.0, 0.3, 1.0, 50.0, dim);
        CHECK(mp.E > 0);
        double ey = mp.sy0 / (2 * mp.mu), de = 0.15 * ey, sig[6] = {0}, ep = 0, wp = 0;
        double emax = 40 * de, e = 0, errmax = 0, scale = (mp.lambda + 2 * mp.mu) * emax;
        int nyield = 0;
        for (int k = 0; k < 40 + 7; k++) {
            int unload = k >= 40;
            double d[6] = {unload ? -de : de, 0, 0, 0, 0, 0};
            int y = 0;
            CHECK(mpm_j2_point(&mp, dim, sig, d, &ep, &y, &wp) == 0);
            e += d[0];
            nyield += y;
            double sxx, syy, epc;
            j2_uniaxial_strain(&mp, e, emax, unload, &sxx, &syy, &epc);
            double er = fmax(fabs(sig[0] - sxx), fmax(fabs(sig[1] - syy), fabs(sig[2] - syy)));
            er = fmax(er, fabs(sig[3]) + fabs(sig[4]) + fabs(sig[5]));
            errmax = fmax(errmax, er / scale);
            CHECKF(er <= 1e-10 * scale,
                   "dim %d step %d: sxx %.17g (closed form %.17g), syy %.17g "
                   "(%.17g)",
                   dim, k, sig[0], sxx, sig[1], syy);
            CHECK_NEAR(ep, epc, 1e-12);
            CHECK(y == (!unload && e > ey));
        }
        double epm = ep, wc = mp.sy0 * epm + 0.5 * mp.H * epm * epm;
        TLOG("dim %d: %d yielding increments, max stress error %.2e (relative); eps_p %.6g; "
             "plastic work %.6g vs integral %.6g (%.2e)",
             dim, nyield, errmax, ep, wp, wc, (wp - wc) / wc);
        CHECK(nyield == 34); /* yield at 6.67 increments: 34 of the 40 flow */
        CHECK(fabs(wp - wc) <= 0.03 * wc);
    }
}

/* 1D: uniaxial stress, sigma = E e, then sy + E H / (E + H) (e - e_y),
 * unloading with slope E. */
TEST(material_j2_point_uniaxial_stress_1d)
{
    mpm_mat_params mp = params(MPM_MODEL_VON_MISES, 200.0, 0.3, 2.0, 20.0, 1);
    CHECK(mp.E > 0);
    double ey = mp.sy0 / mp.E, de = 0.13 * ey, sig[6] = {0}, ep = 0, wp = 0, e = 0, errmax = 0;
    double emax = 30 * de;
    for (int k = 0; k < 40; k++) {
        int unload = k >= 30, y = 0;
        double d[6] = {unload ? -de : de, 0, 0, 0, 0, 0};
        CHECK(mpm_j2_point(&mp, 1, sig, d, &ep, &y, &wp) == 0);
        e += d[0];
        double em = unload ? emax : e;
        double s = em > ey ? mp.sy0 + mp.E * mp.H / (mp.E + mp.H) * (em - ey) : mp.E * em;
        if (unload) s -= mp.E * (emax - e);
        errmax = fmax(errmax, fabs(sig[0] - s) / (mp.E * emax));
        CHECK_NEAR(sig[0], s, 1e-10 * mp.E * emax);
    }
    TLOG("1D uniaxial stress: max error %.2e (relative), eps_p %.6g", errmax, ep);
    CHECK(ep > 0);
}

/* Objectivity: a pre-stressed point (elastic, inside the yield surface)
 * spun rigidly by 90 degrees in N steps of spin only (no strain): the
 * Jaumann update turns the stress with the body, sxx <-> syy, and keeps
 * the von Mises stress and the pressure to O(theta^2 / N) (explicit
 * rotation: |sigma| grows by (1 + w^2) per step; 2.5e-4 at N = 10^4);
 * without it (the small-strain update) the stress stays fixed in space,
 * off by |sxx0 - syy0| after the turn. */
TEST(material_jaumann_objectivity)
{
    for (int dim = 2; dim <= 3; dim++) {
        mpm_mat_params mp = params(MPM_MODEL_VON_MISES, 1000.0, 0.3, 100.0, 0.0, dim);
        double s0[6] = {30, -10, 5, 8, 0, 0}, sig[6], ep = 0, wp = 0;
        memcpy(sig, s0, sizeof sig);
        int N = 10000;
        double w = 0.5 * M_PI / N; /* W_xy: rotation about z */
        for (int k = 0; k < N; k++) {
            double wv[3] = {w, 0, 0}, d[6] = {0, 0, 0, 0, 0, 0};
            int y = 0;
            mpm_jaumann(sig, wv, dim);
            mpm_j2_point(&mp, dim, sig, d, &ep, &y, &wp);
            CHECK(!y);
        }
        /* a quarter turn (either sense) swaps the normal stresses and
         * reverses the shear: R sigma R^T with R = [[0, -1], [1, 0]] */
        double q0 = 0, q1 = 0, p0 = (s0[0] + s0[1] + s0[2]) / 3,
               p1 = (sig[0] + sig[1] + sig[2]) / 3;
        for (int c = 0; c < 6; c++) {
            double a = c < 3 ? s0[c] - p0 : s0[c], b = c < 3 ? sig[c] - p1 : sig[c];
            q0 += (c < 3 ? 1.0 : 2.0) * a * a;
            q1 += (c < 3 ? 1.0 : 2.0) * b * b;
        }
        q0 = sqrt(1.5 * q0);
        q1 = sqrt(1.5 * q1);
        double rot = fmax(fabs(sig[0] - s0[1]), fmax(fabs(sig[1] - s0[0]), fabs(sig[3] + s0[3])));
        TLOG("dim %d: after 90 degrees in %d steps: sxx %.6g syy %.6g sxy %.6g (rotated "
             "%.6g %.6g %.6g); von Mises %.2e, pressure %.2e relative change; "
             "non-objective error %.3g",
             dim, N, sig[0], sig[1], sig[3], s0[1], s0[0], -s0[3], (q1 - q0) / q0, (p1 - p0) / p0,
             fabs(s0[0] - s0[1]));
        CHECK(rot <= 1e-3 * q0);
        CHECK(fabs(q1 - q0) <= 1e-3 * q0);
        CHECK(fabs(p1 - p0) <= 1e-12 * fabs(p0));
        CHECK(sig[2] == s0[2]);
        CHECK(fabs(s0[0] - s0[1]) > 100 * 1e-3 * q0); /* what skipping the rotation misses */
    }
}

/* Neo-Hookean under F = diag(l, 1, 1), l in [0.5, 2]: the Cauchy stress
 * against mu/l (l^2 - 1) + lambda ln l / l (xx), lambda ln l / l (yy, zz)
 * to 1e-12 relative, and against the derivative of the stored energy,
 * sigma_xx = l dW/dl / J, by central differences (1e-7). */
TEST(material_neo_hookean_uniaxial_stretch)
{
    mpm_mat_params mp = params(MPM_MODEL_NEO_HOOKEAN, 10.0, 0.3, 0, 0, 3);
    CHECK(mp.E > 0);
    double emax = 0, efd = 0;
    for (int k = 0; k <= 30; k++) {
        double l = 0.5 + 1.5 * k / 30.0, sig[6], W;
        double F[3][3] = {{l, 0, 0}, {0, 1, 0}, {0, 0, 1}};
        mpm_neo_hookean_stress(&mp, F, sig, &W);
        double sxx = mp.mu / l * (l * l - 1) + mp.lambda * log(l) / l;
        double syy = mp.lambda * log(l) / l, sc = fabs(sxx) + fabs(syy) + mp.mu;
        double e = fmax(fabs(sig[0] - sxx), fmax(fabs(sig[1] - syy), fabs(sig[2] - syy)));
        e = fmax(e, fabs(sig[3]) + fabs(sig[4]) + fabs(sig[5]));
        emax = fmax(emax, e / sc);
        CHECKF(e <= 1e-12 * sc, "stretch %g: sxx %.17g vs %.17g", l, sig[0], sxx);
        double hd = 1e-5, Wp, Wm, sd[6];
        double Fp[3][3] = {{l + hd, 0, 0}, {0, 1, 0}, {0, 0, 1}};
        double Fm[3][3] = {{l - hd, 0, 0}, {0, 1, 0}, {0, 0, 1}};
        mpm_neo_hookean_stress(&mp, Fp, sd, &Wp);
        mpm_neo_hookean_stress(&mp, Fm, sd, &Wm);
        double sfd = (Wp - Wm) / (2 * hd) * l / l; /* l dW/dl / J, J = l */
        efd = fmax(efd, fabs(sfd - sig[0]) / sc);
        CHECK(fabs(sfd - sig[0]) <= 1e-7 * sc);
        if (k == 20) TLOG("stretch 1.5: sxx %.12g, syy %.12g, W %.12g", sig[0], sig[1], W);
    }
    TLOG("max error against the closed form %.2e, against dW/dF %.2e (relative)", emax, efd);
}

/* ---- solver-level cases ---- */

typedef struct {
    mpm_case c;
    mpm_material_desc mat[2];
    mpm_body_desc b[2];
    double *x, *v, *vol, *hl;
    size_t n;
} scene;

static void scene_free(scene *s)
{
    free(s->x);
    free(s->v);
    free(s->vol);
    free(s->hl);
}

/* A 1D bar of n particles over [0, 1] (h = 1/cells, 2 per cell) on a grid
 * over [-0.5, 1.5], velocity a (x - 1/2): every particle keeps its
 * velocity until the release waves from the free ends reach it. */
static int bar1d(scene *s, int cells, double a, mpm_model_kind k, double sy, double H)
{
    memset(s, 0, sizeof *s);
    double h = 1.0 / cells;
    size_t n = (size_t)cells * 2;
    s->x = malloc(n * sizeof(double));
    s->v = malloc(n * sizeof(double));
    s->vol = malloc(n * sizeof(double));
    s->hl = malloc(n * sizeof(double));
    if (!s->x || !s->v || !s->vol || !s->hl) return -1;
    for (size_t p = 0; p < n; p++) {
        s->x[p] = (p + 0.5) * h / 2;
        s->v[p] = a * (s->x[p] - 0.5);
        s->vol[p] = h / 2;
        s->hl[p] = h / 4;
    }
    s->n = n;
    s->mat[0] = (mpm_material_desc){.model = k,
                                    .youngs_modulus = 1.0,
                                    .density = 1.0,
                                    .yield_stress = sy,
                                    .hardening_modulus = H};
    s->b[0].n_points = n;
    s->b[0].x = s->x;
    s->b[0].v = s->v;
    s->b[0].volume = s->vol;
    s->b[0].half_length = s->hl;
    s->c.grid.dim = 1;
    s->c.grid.origin[0] = -0.5;
    s->c.grid.h[0] = h;
    s->c.grid.nodes[0] = 2 * cells + 1;
    s->c.method = MPM_METHOD_GIMP;
    s->c.update = MPM_USF;
    s->c.dt = 0.25 * h;
    s->c.n_materials = 1;
    s->c.materials = s->mat;
    s->c.n_bodies = 1;
    s->c.bodies = s->b;
    return 0;
}

/* J2 through the solver: the 1D bar stretched at a = 0.02 yields at its
 * centre at t = 0.25 (e_y = 0.005) and hardens until the ends' release
 * reaches the centre at t = 0.5.  The run carries F (volume update DET_F)
 * so that each particle's strain is known: at t = 0.45 the central
 * particle's stress against uniaxial stress's closed form at its strain
 * ln F_xx (which differs from the sum of the increments L dt by
 * sum (L dt)^2 / 2 ~ 2e-7: 4e-6 of the stress), its plastic strain, and
 * the yield flag; and F_xx against the homogeneous 1 + a t (the grid's
 * interpolation of the linear velocity field over the stretched particle
 * lattice is not exact: 1 % of the strain measured). */
TEST(material_j2_bar_solver)
{
    scene s;
    double a = 0.02, sy = 0.005, H = 0.1;
    CHECK(bar1d(&s, 100, a, MPM_MODEL_VON_MISES, sy, H) == 0);
    s.c.volume_update = MPM_VOLUME_DET_F;
    mpm_error err;
    mpm_sim *sim = mpm_sim_new(&s.c, NULL, &err);
    CHECKF(sim, "%s", err.message);
    long steps = (long)llround(0.45 / s.c.dt);
    int rc = mpm_sim_run(sim, steps);
    double *sig = calloc(s.n * 6, sizeof(double)), *eps = calloc(s.n, sizeof(double));
    double *F = calloc(s.n, sizeof(double));
    uint8_t *yl = calloc(s.n, 1);
    if (!rc && sig && eps && yl && F)
        mpm_sim_snapshot(sim, &(mpm_snapshot){.stress = sig,
                                              .plastic_strain = eps,
                                              .yielded = yl,
                                              .deformation_gradient = F});
    double t = mpm_sim_time(sim);
    CHECK(mpm_sim_has_field(sim, MPM_FIELD_PLASTIC_STRAIN) &&
          mpm_sim_has_field(sim, MPM_FIELD_YIELDED) &&
          mpm_sim_has_field(sim, MPM_FIELD_DEFORMATION_GRADIENT));
    mpm_sim_destroy(&sim);
    scene_free(&s);
    size_t pc = s.n / 2; /* the particle at x = 0.5 + h/4 */
    int ok = !rc && sig && eps && yl && F;
    double e = ok ? log(F[pc]) : 0, ey = sy, E = 1.0, Fh = 1 + a * t;
    double sc = sy + E * H / (E + H) * (e - ey), epc = (e - ey) - (sc - sy) / E;
    double ds = ok ? sig[pc * 6] - sc : 1, dep = ok ? eps[pc] - epc : 1, eF = ok ? F[pc] - Fh : 1;
    int y = ok ? yl[pc] : 0;
    free(sig);
    free(eps);
    free(yl);
    free(F);
    CHECKF(ok, "run: %d", rc);
    TLOG("t = %.4g, strain ln F %.6g (homogeneous %.6g, F error %.2e): sxx %.9g vs closed form "
         "%.9g (%.2e relative), eps_p %.6g vs %.6g (%.2e)",
         t, e, log(Fh), eF, sc + ds, sc, ds / sc, epc + dep, epc, dep / epc);
    CHECK(fabs(ds) <= 2e-5 * sc);
    CHECK(fabs(dep) <= 1e-4 * epc);
    CHECK(fabs(eF) <= 3e-4);
    CHECK(y == 1);
}

/* The energy balance with plastic dissipation: the J2 bar (a = 0.04, so
 * that most of it yields) run to t = 3, long after the release waves: the
 * kinetic + elastic stored energy + plastic work stays at the initial
 * kinetic energy (no loads) within 1 %, while plastic work is most of it. */
TEST(material_j2_energy_balance)
{
    scene s;
    CHECK(bar1d(&s, 100, 0.04, MPM_MODEL_VON_MISES, 0.005, 0.1) == 0);
    mpm_error err;
    mpm_sim *sim = mpm_sim_new(&s.c, NULL, &err);
    CHECKF(sim, "%s", err.message);
    mpm_energy e0, e1;
    mpm_sim_energy(sim, &e0);
    double worst = 0;
    int rc = 0;
    for (int k = 0; k < 30 && !rc; k++) {
        rc = mpm_sim_run(sim, (long)llround(0.1 / s.c.dt));
        mpm_sim_energy(sim, &e1);
        double bal = e1.kinetic + e1.strain + e1.plastic_work - e1.external_work;
        worst = fmax(worst, fabs(bal - e0.kinetic) / e0.kinetic);
    }
    mpm_sim_destroy(&sim);
    scene_free(&s);
    CHECK(rc == 0);
    TLOG("E0 %.6g; at t = 3: kinetic %.6g, stored %.6g, plastic work %.6g; worst balance "
         "error %.2e (relative)",
         e0.kinetic, e1.kinetic, e1.strain, e1.plastic_work, worst);
    CHECK(e1.plastic_work > 0.3 * e0.kinetic);
    CHECK(worst <= 0.01);
}

/* A 2D block [-2, 2]^2 (h = 0.2, 2 x 2 per cell) on a grid over [-4, 4]^2,
 * velocity (a x, 0). */
static int block2d(scene *s, double a, mpm_model_kind k, mpm_volume_update vu)
{
    memset(s, 0, sizeof *s);
    int nc = 20, ppc = 2;
    double h = 0.2, dp = h / ppc;
    size_t n = (size_t)(nc * ppc) * (size_t)(nc * ppc);
    s->x = malloc(2 * n * sizeof(double));
    s->v = malloc(2 * n * sizeof(double));
    s->vol = malloc(n * sizeof(double));
    if (!s->x || !s->v || !s->vol) return -1;
    size_t p = 0;
    for (int j = 0; j < nc * ppc; j++)
        for (int i = 0; i < nc * ppc; i++, p++) {
            s->x[2 * p] = -2 + (i + 0.5) * dp;
            s->x[2 * p + 1] = -2 + (j + 0.5) * dp;
            s->v[2 * p] = a * s->x[2 * p];
            s->v[2 * p + 1] = 0;
            s->vol[p] = dp * dp;
        }
    s->n = n;
    s->mat[0] = (mpm_material_desc){
        .model = k, .youngs_modulus = 1.0, .poisson_ratio = 0.3, .density = 1.0};
    s->b[0].n_points = n;
    s->b[0].x = s->x;
    s->b[0].v = s->v;
    s->b[0].volume = s->vol;
    s->c.grid.dim = 2;
    for (int d = 0; d < 2; d++) {
        s->c.grid.origin[d] = -4;
        s->c.grid.h[d] = h;
        s->c.grid.nodes[d] = 41;
    }
    s->c.method = MPM_METHOD_GIMP;
    s->c.update = MPM_USF;
    s->c.volume_update = vu;
    s->c.dt = 0.005;
    s->c.n_materials = 1;
    s->c.materials = s->mat;
    s->c.n_bodies = 1;
    s->c.bodies = s->b;
    return 0;
}

/* Neo-Hookean through the solver: the block stretched at a = 1 to
 * F_xx = 1.5 at t = 0.5 (plane strain), before the release waves reach
 * its centre (t = 1.7): the central particle's F against diag(1 + a t, 1)
 * and its stress against the closed form there; its stress against the
 * model of its own F to round-off. */
TEST(material_neo_hookean_solver_stretch)
{
    scene s;
    CHECK(block2d(&s, 1.0, MPM_MODEL_NEO_HOOKEAN, MPM_VOLUME_STRAIN_INCREMENT) == 0);
    mpm_error err;
    mpm_sim *sim = mpm_sim_new(&s.c, NULL, &err);
    CHECKF(sim, "%s", err.message);
    int rc = mpm_sim_run(sim, 100);
    double t = mpm_sim_time(sim);
    double *F = calloc(s.n * 4, sizeof(double)), *sig = calloc(s.n * 6, sizeof(double));
    if (!rc && F && sig)
        mpm_sim_snapshot(sim, &(mpm_snapshot){.stress = sig, .deformation_gradient = F});
    mpm_mat_params mp;
    mpm_model_params(&s.mat[0], 2, &mp);
    mpm_sim_destroy(&sim);
    /* the particle nearest the centre: x = (dp/2, dp/2) */
    size_t pc = 0;
    for (size_t p = 0; p < s.n; p++)
        if (fabs(s.x[2 * p] - 0.05) < 1e-9 && fabs(s.x[2 * p + 1] - 0.05) < 1e-9) pc = p;
    scene_free(&s);
    if (rc || !F || !sig) {
        free(F);
        free(sig);
        CHECKF(0, "run: %d", rc);
    }
    double l = 1 + 1.0 * t, *Fp = F + 4 * pc, *sp = sig + 6 * pc;
    double Fm[3][3] = {{Fp[0], Fp[1], 0}, {Fp[2], Fp[3], 0}, {0, 0, 1}}, own[6];
    mpm_neo_hookean_stress(&mp, Fm, own, NULL);
    double sxx = mp.mu / l * (l * l - 1) + mp.lambda * log(l) / l, syy = mp.lambda * log(l) / l;
    double eF = fmax(fmax(fabs(Fp[0] - l), fabs(Fp[3] - 1)), fmax(fabs(Fp[1]), fabs(Fp[2])));
    double es = fmax(fabs(sp[0] - sxx), fmax(fabs(sp[1] - syy), fabs(sp[2] - syy))) / sxx;
    double eo = 0;
    for (int c = 0; c < 4; c++) eo = fmax(eo, fabs(sp[c] - own[c]));
    double fxx = Fp[0], s0 = sp[0];
    free(F);
    free(sig);
    TLOG("t = %.3g: F_xx %.12g vs %.12g (max F error %.2e); sxx %.9g vs closed form %.9g, "
         "stress error %.2e relative; against its own F %.2e",
         t, fxx, l, eF, s0, sxx, es, eo);
    CHECK(eF <= 1e-2);
    CHECK(es <= 2e-2);
    CHECK(eo <= 1e-14 * sxx);
}

/* Volume updates: CONSTANT keeps every particle's volume bit for bit;
 * DET_F makes it det F V0 to round-off (the same block as above, linear
 * elastic, so that DET_F alone asks for F). */
TEST(material_volume_modes)
{
    for (int mode = 1; mode <= 2; mode++) {
        scene s;
        CHECK(block2d(&s, 0.5, MPM_MODEL_LINEAR_ELASTIC, (mpm_volume_update)mode) == 0);
        mpm_error err;
        mpm_sim *sim = mpm_sim_new(&s.c, NULL, &err);
        CHECKF(sim, "%s", err.message);
        int rc = mpm_sim_run(sim, 100);
        double *vol = calloc(s.n, sizeof(double)), *F = calloc(s.n * 4, sizeof(double));
        if (!rc && vol && F)
            mpm_sim_snapshot(sim, &(mpm_snapshot){.volume = vol, .deformation_gradient = F});
        int hasF = mpm_sim_has_field(sim, MPM_FIELD_DEFORMATION_GRADIENT);
        mpm_sim_destroy(&sim);
        size_t same = 0;
        double worst = 0, jmax = 0;
        for (size_t p = 0; !rc && vol && F && p < s.n; p++) {
            double J = F[4 * p] * F[4 * p + 3] - F[4 * p + 1] * F[4 * p + 2];
            same += memcmp(&vol[p], &s.vol[p], sizeof(double)) == 0;
            worst = fmax(worst, fabs(vol[p] - J * s.vol[p]) / vol[p]);
            jmax = fmax(jmax, J);
        }
        scene_free(&s);
        free(vol);
        free(F);
        CHECK(rc == 0);
        CHECK(hasF == (mode == 1));
        if (mode == 2) {
            TLOG("CONSTANT: %zu of %zu volumes bit-identical to the initial ones", same, s.n);
            CHECK(same == s.n);
        } else {
            TLOG("DET_F: largest |V - det F V0| / V %.2e (det F up to %.4g)", worst, jmax);
            CHECK(worst <= 1e-14);
            CHECK(jmax > 1.2);
        }
    }
}

/* The general block update reproduces linear elasticity's bits: a 2D
 * elastic impact run with a second, unused NEO_HOOKEAN material (so that
 * the job takes mpm_model_block()) gives the positions, velocities,
 * stresses and strain energy of the default path exactly; and a case
 * mixing a J2 body with an elastic one runs, with plastic strain only in
 * the J2 body. */
TEST(material_general_path_bits)
{
    double xs[2][2 * 2 * 400], vs[2][2 * 2 * 400], ss[2][6 * 2 * 400], es[2];
    for (int run = 0; run < 3; run++) {
        mpm_material_desc mat[2] = {
            {.model = MPM_MODEL_LINEAR_ELASTIC,
             .youngs_modulus = 100.0,
             .poisson_ratio = 0.3,
             .density = 1.0},
            {.model = run == 2 ? MPM_MODEL_VON_MISES : MPM_MODEL_NEO_HOOKEAN,
             .youngs_modulus = 100.0,
             .poisson_ratio = 0.3,
             .density = 1.0,
             .yield_stress = 0.5}};
        mpm_body_desc b[2] = {{0}, {0}};
        for (int k = 0; k < 2; k++) {
            b[k].material = run == 2 ? k : 0;
            b[k].shape = MPM_SHAPE_BOX;
            b[k].lo[0] = k ? 1.1 : 0.2;
            b[k].hi[0] = k ? 1.8 : 0.9;
            b[k].lo[1] = 0.2;
            b[k].hi[1] = 0.9;
            b[k].ppc = 2;
            b[k].velocity[0] = k ? -1.0 : 1.0;
        }
        mpm_case c = {0};
        c.grid.dim = 2;
        c.grid.h[0] = c.grid.h[1] = 0.1;
        c.grid.nodes[0] = 21;
        c.grid.nodes[1] = 12;
        c.method = MPM_METHOD_GIMP;
        c.update = MPM_USF;
        for (int f = 0; f < 4; f++) c.bc.face_mask[f] = 3; /* walls */
        c.n_materials = run ? 2 : 1;
        c.materials = mat;
        c.n_bodies = 2;
        c.bodies = b;
        mpm_error err;
        mpm_sim *sim = mpm_sim_new(&c, NULL, &err);
        CHECKF(sim, "%s", err.message);
        CHECK(mpm_sim_particles(sim) == 2 * 196);
        int rc = mpm_sim_run(sim, 40);
        mpm_energy e;
        mpm_sim_want_energy(sim);
        if (!rc) rc = mpm_sim_step(sim);
        mpm_sim_energy(sim, &e);
        if (run < 2) {
            mpm_sim_snapshot(sim, &(mpm_snapshot){.x = xs[run], .v = vs[run], .stress = ss[run]});
            es[run] = e.strain;
            CHECK(!mpm_sim_has_field(sim, MPM_FIELD_PLASTIC_STRAIN));
        } else {
            double ep[2 * 196] = {0};
            mpm_sim_snapshot(sim, &(mpm_snapshot){.plastic_strain = ep});
            size_t n0 = 0, n1 = 0;
            for (int p = 0; p < 196; p++) n0 += ep[p] != 0;
            for (int p = 196; p < 392; p++) n1 += ep[p] > 0;
            TLOG("mixed: %zu of 196 J2 particles yielded, %zu elastic ones carry plastic strain; "
                 "plastic work %.4g",
                 n1, n0, e.plastic_work);
            CHECK(n0 == 0 && n1 > 0 && e.plastic_work > 0);
        }
        CHECKF(rc == 0, "run %d: %s", run, mpm_sim_error(sim)->message);
        mpm_sim_destroy(&sim);
    }
    size_t n = 2 * 196;
    CHECK(memcmp(xs[0], xs[1], n * 2 * sizeof(double)) == 0);
    CHECK(memcmp(vs[0], vs[1], n * 2 * sizeof(double)) == 0);
    CHECK(memcmp(ss[0], ss[1], n * 6 * sizeof(double)) == 0);
    CHECK(memcmp(&es[0], &es[1], sizeof(double)) == 0);
    TLOG("default and general paths: the same bits after 41 steps (strain energy %.9g)", es[0]);
}

/* Linear elasticity of a block whose particles are all of one material
 * reads the parameters once and runs by pairs (mpm_model.c
 * elastic_2d(), elastic_3d()); a block of several materials goes particle by
 * particle.  Two interleaved lattices (the even and the odd points of a
 * 2D and a 3D lattice, so that every block of 64 holds both), sheared and
 * compressed, are run with one material and with two of the same
 * parameters: positions, velocities and stresses must be equal bit for bit
 * after 60 steps, with the portable and the AVX2 kernels, and with an
 * initial stress (which keeps 2D's sigma_zz and the strain record). */
TEST(material_one_material_block_bits)
{
    int runs = 0;
    for (int dim = 2; dim <= 3; dim++) {
        const int per = dim == 2 ? 24 : 10;
        size_t n = 1;
        for (int d = 0; d < dim; d++) n *= (size_t)per;
        size_t nh[2] = {(n + 1) / 2, n / 2};
        double *x[2], *vol[2], *v[2], *sg[2], *out[2][3];
        for (int k = 0; k < 2; k++) {
            x[k] = malloc(nh[k] * 3 * sizeof(double));
            vol[k] = malloc(nh[k] * sizeof(double));
            v[k] = malloc(nh[k] * 3 * sizeof(double));
            sg[k] = malloc(nh[k] * 6 * sizeof(double));
            for (int f = 0; f < 3; f++) out[k][f] = malloc(n * 6 * sizeof(double));
            CHECK(x[k] && vol[k] && v[k] && sg[k] && out[k][0] && out[k][1] && out[k][2]);
        }
        const double h = 1.0 / 16, dp = h / 2;
        size_t cnt[2] = {0, 0};
        for (size_t i = 0; i < n; i++) {
            int k = (int)(i % 2);
            size_t j = cnt[k]++, r = i;
            double xi[3] = {0, 0, 0};
            for (int d = 0; d < dim; d++) {
                xi[d] = 4 * h + (0.5 + (double)(r % (size_t)per)) * dp;
                r /= (size_t)per;
                x[k][j * (size_t)dim + (size_t)d] = xi[d];
            }
            vol[k][j] = dim == 2 ? dp * dp : dp * dp * dp;
            for (int d = 0; d < dim; d++)
                v[k][j * (size_t)dim + (size_t)d] =
                    0.05 * sin(6.0 * xi[(d + 1) % dim]) - 0.1 * (xi[d] - 0.5);
            for (int c = 0; c < 6; c++) sg[k][j * 6 + (size_t)c] = c < 3 ? -0.01 : 0.0;
        }
        for (int isa = 0; isa < 2; isa++)
            for (int st = 0; st < 2; st++) {
                for (int two = 0; two < 2; two++) {
                    mpm_material_desc mat[2];
                    for (int k = 0; k < 2; k++)
                        mat[k] = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                                     .youngs_modulus = 50.0,
                                                     .poisson_ratio = 0.3,
                                                     .density = 1.0};
                    mpm_body_desc b[2];
                    memset(b, 0, sizeof b);
                    for (int k = 0; k < 2; k++) {
                        b[k].material = two ? k : 0;
                        b[k].n_points = nh[k];
                        b[k].x = x[k];
                        b[k].volume = vol[k];
                        b[k].v = v[k];
                        b[k].stress = st ? sg[k] : NULL;
                    }
                    mpm_case c;
                    memset(&c, 0, sizeof c);
                    c.grid.dim = dim;
                    for (int d = 0; d < dim; d++) {
                        c.grid.h[d] = h;
                        c.grid.nodes[d] = 17;
                    }
                    c.method = MPM_METHOD_MPM;
                    c.update = MPM_USF;
                    c.kernels = isa ? MPM_KERNELS_AUTO : MPM_KERNELS_PORTABLE;
                    c.n_materials = two ? 2 : 1;
                    c.materials = mat;
                    c.n_bodies = 2;
                    c.bodies = b;
                    mpm_error err;
                    mpm_sim *sim = mpm_sim_new(&c, NULL, &err);
                    CHECKF(sim, "%s", err.message);
                    int rc = mpm_sim_run(sim, 60);
                    CHECKF(rc == 0, "%dD: %s", dim, mpm_sim_error(sim)->message);
                    mpm_sim_snapshot(
                        sim,
                        &(mpm_snapshot){.x = out[two][0], .v = out[two][1], .stress = out[two][2]});
                    mpm_sim_destroy(&sim);
                }
                double smax = 0;
                for (size_t i = 0; i < n * 6; i++) smax = fmax(smax, fabs(out[0][2][i]));
                TLOG("%dD, %s kernels%s: %zu particles, |sigma| up to %.3g, one and two "
                     "materials %s",
                     dim, isa ? "auto" : "portable", st ? ", initial stress" : "", n, smax,
                     memcmp(out[0][2], out[1][2], n * 6 * sizeof(double)) ? "differ" : "equal");
                CHECK(smax > 0.02);
                CHECK(memcmp(out[0][0], out[1][0], n * (size_t)dim * sizeof(double)) == 0);
                CHECK(memcmp(out[0][1], out[1][1], n * (size_t)dim * sizeof(double)) == 0);
                CHECK(memcmp(out[0][2], out[1][2], n * 6 * sizeof(double)) == 0);
                runs++;
            }
        for (int k = 0; k < 2; k++) {
            free(x[k]);
            free(vol[k]);
            free(v[k]);
            free(sg[k]);
            for (int f = 0; f < 3; f++) free(out[k][f]);
        }
    }
    CHECK(runs == 8);
}

/* Validation names the field and the limit; Drucker-Prager and
 * Mohr-Coulomb are refused in 1D and accepted in 2D (k = 3 at 30 degrees,
 * the angle converted to radians). */
TEST(material_validation)
{
    static const struct {
        mpm_material_desc m;
        const char *field, *what;
    } bad[] = {
        {{.model = MPM_MODEL_VON_MISES, .youngs_modulus = 1, .density = 1, .yield_stress = -1},
         "materials[0].yield_stress",
         "must be > 0 (got -1)"},
        {{.model = MPM_MODEL_VON_MISES,
          .youngs_modulus = 1,
          .density = 1,
          .yield_stress = 1,
          .hardening_modulus = -2},
         "materials[0].hardening_modulus",
         ">= 0"},
        {{.model = MPM_MODEL_DRUCKER_PRAGER,
          .youngs_modulus = 1,
          .density = 1,
          .friction_angle = 95},
         "materials[0].friction_angle",
         "(0, 90)"},
        {{.model = MPM_MODEL_MOHR_COULOMB,
          .youngs_modulus = 1,
          .density = 1,
          .friction_angle = 30,
          .dilatancy_angle = 40},
         "materials[0].dilatancy_angle",
         "[0, friction_angle"},
        {{.model = MPM_MODEL_DRUCKER_PRAGER,
          .youngs_modulus = 1,
          .density = 1,
          .friction_angle = 30,
          .cohesion = -1},
         "materials[0].cohesion",
         ">= 0"},
        {{.model = MPM_MODEL_DRUCKER_PRAGER,
          .youngs_modulus = 1,
          .density = 1,
          .friction_angle = 30,
          .tension_cutoff = -1},
         "materials[0].tension_cutoff",
         ">= 0"},
        {{.model = MPM_MODEL_DRUCKER_PRAGER,
          .youngs_modulus = 1,
          .density = 1,
          .friction_angle = 30,
          .mc_match = (mpm_mc_match)5},
         "materials[0].mc_match",
         "unknown value 5"},
        {{.model = MPM_MODEL_MOHR_COULOMB,
          .youngs_modulus = 1,
          .density = 1,
          .friction_angle = 30,
          .poisson_ratio = 0.5},
         "materials[0].poisson_ratio",
         "(-1, 0.5)"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        mpm_error err;
        char f[128];
        int rc = mpm_material_check(&bad[i].m, 2, 0, &err);
        mpm_error_field(&err, MPM_FIELD_PROTO, f, sizeof f);
        CHECKF(rc == MPM_EINVAL && !strcmp(f, bad[i].field) && strstr(err.message, bad[i].what),
               "case %zu: %d %s: %s", i, rc, f, err.message);
        TLOG("%s: %s", f, err.message);
    }
    /* the frictional models need 2D or 3D; in 2D they are accepted */
    mpm_material_desc mc = {.model = MPM_MODEL_MOHR_COULOMB,
                            .youngs_modulus = 1,
                            .density = 1,
                            .friction_angle = 30,
                            .tension_cutoff = HUGE_VAL};
    for (int dim = 1; dim <= 2; dim++) {
        mpm_error err;
        char f[128];
        mpm_plastic_params pl;
        int rc = mpm_material_check(&mc, dim, 0, &err);
        if (!rc) rc = mpm_model_plastic(&mc, dim, 0, &pl, &err);
        mpm_error_field(&err, MPM_FIELD_PROTO, f, sizeof f);
        if (dim == 1)
            CHECKF(rc == MPM_EINVAL && !strcmp(f, "materials[0].model") &&
                       strstr(err.message, "2D (plane strain) or 3D"),
                   "%d %s: %s", rc, f, err.message);
        else
            CHECKF(rc == 0 && pl.kind == MPM_PLASTIC_MOHR_COULOMB && fabs(pl.kphi - 3.0) < 1e-12,
                   "%d %s: %s", rc, f, err.message);
    }
    scene s;
    CHECK(block2d(&s, 0, MPM_MODEL_LINEAR_ELASTIC, (mpm_volume_update)7) == 0);
    mpm_error err;
    char f[128];
    int rc = mpm_case_check(&s.c, NULL, &err);
    scene_free(&s);
    mpm_error_field(&err, MPM_FIELD_PROTO, f, sizeof f);
    CHECKF(rc == MPM_EINVAL && !strcmp(f, "volume_update"), "%d %s", rc, f);
    TLOG("%s: %s", f, err.message);
}

/* J2 through the solver in 2D (plane strain) and 3D, in uniaxial strain:
 * a bar [-4, 4] x [-1/4, 1/4]^(dim-1) (h = 0.25, 2 particles per cell and
 * axis) between rollers on the grid's lateral faces, stretched by
 * v = (a x, 0, 0), a = 0.2, carrying F (volume update DET_F).  It yields
 * (e_y = sy / 2 mu = 0.0195) and hardens; the release waves from its ends
 * reach the centre at t = 3.4.  At t = 0.6 the central particle's stress
 * against uniaxial strain's closed form at its strain (the sum of the
 * increments L dt: ln F_xx + sum (L dt - ln(1 + L dt)), 1.2e-4, taken
 * with the homogeneous L, which matters through the bulk modulus), its
 * plastic strain likewise, F against the homogeneous 1 + a t (the grid's
 * interpolation error), and F_yy = 1. */
TEST(material_j2_block_solver_2d_3d)
{
    for (int dim = 2; dim <= 3; dim++) {
        int mx = 64, my = 4;
        double h = 0.25, dp = h / 2, a = 0.2, sy = 0.015, H = 0.05;
        size_t n = (size_t)mx * (size_t)my * (dim == 3 ? (size_t)my : 1);
        double *x = malloc(n * 3 * sizeof(double)), *v = calloc(n * 3, sizeof(double));
        double *vol = malloc(n * sizeof(double));
        CHECK(x && v && vol);
        size_t pc = 0;
        for (size_t p = 0; p < n; p++) {
            size_t q = p;
            for (int d = 0; d < dim; d++) {
                int md = d ? my : mx;
                double lo = d ? -0.25 : -4.0;
                x[p * dim + d] = lo + ((double)(q % (size_t)md) + 0.5) * dp;
                q /= (size_t)md;
            }
            v[p * dim] = a * x[p * dim];
            vol[p] = pow(dp, dim);
            int centre = 1;
            for (int d = 0; d < dim; d++) centre &= fabs(x[p * dim + d] - 0.5 * dp) < 1e-12;
            if (centre) pc = p;
        }
        mpm_material_desc mat = {.model = MPM_MODEL_VON_MISES,
                                 .youngs_modulus = 1.0,
                                 .poisson_ratio = 0.3,
                                 .density = 1.0,
                                 .yield_stress = sy,
                                 .hardening_modulus = H};
        mpm_body_desc b = {0};
        b.n_points = n;
        b.x = x;
        b.v = v;
        b.volume = vol;
        mpm_case c = {0};
        c.grid.dim = dim;
        c.grid.origin[0] = -6;
        c.grid.h[0] = h;
        c.grid.nodes[0] = 49;
        for (int d = 1; d < dim; d++) {
            c.grid.origin[d] = -0.25;
            c.grid.h[d] = h;
            c.grid.nodes[d] = 3;
            c.bc.face_mask[2 * d] = c.bc.face_mask[2 * d + 1] = 1u << d; /* rollers */
        }
        c.method = MPM_METHOD_GIMP;
        c.update = MPM_USF;
        c.volume_update = MPM_VOLUME_DET_F;
        c.dt = 0.01;
        c.n_materials = 1;
        c.materials = &mat;
        c.n_bodies = 1;
        c.bodies = &b;
        mpm_error err;
        mpm_sim *s = mpm_sim_new(&c, NULL, &err);
        int rc = s ? mpm_sim_run(s, 60) : -1;
        double *sig = calloc(n * 6, sizeof(double)), *F = calloc(n * 9, sizeof(double));
        double *ep = calloc(n, sizeof(double));
        if (!rc && sig && F && ep)
            mpm_sim_snapshot(
                s, &(mpm_snapshot){.stress = sig, .deformation_gradient = F, .plastic_strain = ep});
        double t = s ? mpm_sim_time(s) : 0;
        mpm_mat_params mp;
        mpm_model_params(&mat, dim, &mp);
        mpm_sim_destroy(&s);
        free(x);
        free(v);
        free(vol);
        int ok = !rc && sig && F && ep;
        /* the increments' sum: ln F + sum (L dt - ln(1 + L dt)), with the
         * homogeneous L_n = a / (1 + a t_n) */
        double sxx = 0, syy = 0, epc = 0, e = ok ? log(F[pc * dim * dim]) : 0;
        for (int k = 0; k < 60; k++) {
            double ld = a * c.dt / (1 + a * k * c.dt);
            e += ld - log1p(ld);
        }
        j2_uniaxial_strain(&mp, e, e, 0, &sxx, &syy, &epc);
        double *sp = sig + 6 * pc;
        double es = ok ? fmax(fabs(sp[0] - sxx), fmax(fabs(sp[1] - syy), fabs(sp[2] - syy))) : 1;
        double eF = ok ? fabs(F[pc * dim * dim] - (1 + a * t)) : 1, dep = ok ? ep[pc] - epc : 1;
        double eyy = ok ? fabs(F[pc * dim * dim + dim + 1] - 1) : 1;
        double s0 = ok ? sp[0] : 0, s1 = ok ? sp[1] : 0;
        free(sig);
        free(F);
        free(ep);
        CHECKF(ok, "dim %d: run %d", dim, rc);
        TLOG("dim %d, t = %.3g: strain %.6g (F_xx error %.2e, F_yy - 1 %.1e); sxx %.9g "
             "syy %.9g vs closed form %.9g %.9g: error %.2e of sxx; eps_p %.6g vs %.6g",
             dim, t, e, eF, eyy, s0, s1, sxx, syy, es / sxx, epc + dep, epc);
        CHECK(es <= 1e-4 * sxx);
        CHECK(fabs(dep) <= 1e-3 * epc);
        CHECK(eF <= 1e-2);
        CHECK(eyy <= 1e-12);
        CHECK(epc > 0.01);
    }
}

/* The plastic work is summed per thread and added in thread order: two
 * runs on 2 threads give the same bits, and agree with the serial run to
 * round-off (the J2 bar of material_j2_energy_balance, to t = 1). */
TEST(material_plastic_work_threads)
{
    double w[3] = {0, 0, 0};
    for (int run = 0; run < 3; run++) {
        scene s;
        CHECK(bar1d(&s, 100, 0.04, MPM_MODEL_VON_MISES, 0.005, 0.1) == 0);
        s.c.threads = run ? 2 : 1;
        mpm_error err;
        mpm_sim *sim = mpm_sim_new(&s.c, NULL, &err);
        scene_free(&s);
        CHECKF(sim, "%s", err.message);
        int rc = mpm_sim_run(sim, 400);
        mpm_energy e;
        mpm_sim_energy(sim, &e);
        w[run] = e.plastic_work;
        mpm_sim_destroy(&sim);
        CHECK(rc == 0);
    }
    TLOG("plastic work: serial %.17g, 2 threads %.17g and %.17g", w[0], w[1], w[2]);
    CHECK(memcmp(&w[1], &w[2], sizeof w[1]) == 0);
    CHECK(fabs(w[1] - w[0]) <= 1e-12 * w[0]);
    CHECK(w[0] > 0);
}

/* Linear elasticity from a zero stress keeps no strain record and,
 * in 2D, no sigma_zz array (mpm_particles.h); the same case with a second,
 * unused VON_MISES material keeps both (the plastic models' record) and
 * takes the general path, which has linear elasticity's bits.  Positions,
 * velocities and the stored stresses are the same bits after an impact; the derived
 * sigma_zz = nu (sigma_xx + sigma_yy) and the strain energy from the
 * compliance agree with the stored sum and 1/2 sigma : eps V to 1e-12 of
 * their scale. */
TEST(material_strain_record_optional)
{
    for (int dim = 2; dim <= 3; dim++) {
        enum { NMAX = 2 * 8 * 4 * 4 * 4 };
        static double xs[2][3 * NMAX], vs[2][3 * NMAX], ss[2][6 * NMAX];
        double es[2] = {0, 0};
        size_t np[2] = {0, 0};
        for (int run = 0; run < 2; run++) {
            mpm_material_desc mat[2] = {{.model = MPM_MODEL_LINEAR_ELASTIC,
                                         .youngs_modulus = 100.0,
                                         .poisson_ratio = 0.3,
                                         .density = 1.0},
                                        {.model = MPM_MODEL_VON_MISES,
                                         .youngs_modulus = 100.0,
                                         .poisson_ratio = 0.3,
                                         .density = 1.0,
                                         .yield_stress = 0.5}};
            mpm_body_desc b[2] = {{0}, {0}};
            for (int k = 0; k < 2; k++) {
                b[k].shape = MPM_SHAPE_BOX;
                b[k].ppc = 2;
                for (int d = 0; d < dim; d++) {
                    b[k].lo[d] = d ? 0.2 : k ? 0.8 : 0.2;
                    b[k].hi[d] = d ? 0.6 : k ? 1.2 : 0.6;
                }
                b[k].velocity[0] = k ? -1.0 : 1.0;
            }
            mpm_case c = {0};
            c.grid.dim = dim;
            for (int d = 0; d < dim; d++) {
                c.grid.h[d] = 0.1;
                c.grid.nodes[d] = d ? 9 : 18;
            }
            c.method = MPM_METHOD_GIMP;
            c.update = MPM_USF;
            for (int f = 0; f < 2 * dim; f++) c.bc.face_mask[f] = 7; /* walls */
            c.n_materials = run ? 2 : 1;
            c.materials = mat;
            c.n_bodies = 2;
            c.bodies = b;
            mpm_error err;
            mpm_sim *sim = mpm_sim_new(&c, NULL, &err);
            CHECKF(sim, "%s", err.message);
            const mpm_particles *P = &sim->P;
            CHECK(run ? P->eps[0] != NULL : P->eps[0] == NULL);
            if (dim == 2) CHECK(run ? P->sig[2] != NULL : P->sig[2] == NULL);
            np[run] = mpm_sim_particles(sim);
            CHECK(np[run] <= NMAX);
            int rc = mpm_sim_run(sim, 80);
            CHECKF(rc == 0, "%s", mpm_sim_error(sim)->message);
            mpm_energy e;
            mpm_sim_energy(sim, &e);
            es[run] = e.strain;
            mpm_sim_snapshot(sim, &(mpm_snapshot){.x = xs[run], .v = vs[run], .stress = ss[run]});
            mpm_sim_destroy(&sim);
        }
        CHECK(np[0] == np[1]);
        size_t n = np[0];
        CHECK(memcmp(xs[0], xs[1], n * dim * sizeof(double)) == 0);
        CHECK(memcmp(vs[0], vs[1], n * dim * sizeof(double)) == 0);
        double smax = 0, dzz = 0;
        size_t same = 0;
        for (size_t i = 0; i < n * 6; i++) smax = fmax(smax, fabs(ss[1][i]));
        for (size_t p = 0; p < n; p++)
            for (int k = 0; k < 6; k++) {
                size_t i = p * 6 + (size_t)k;
                if (dim == 2 && k == 2)
                    dzz = fmax(dzz, fabs(ss[0][i] - ss[1][i]));
                else
                    same += memcmp(&ss[0][i], &ss[1][i], sizeof(double)) == 0;
            }
        double de = fabs(es[0] - es[1]) / fabs(es[1]);
        TLOG(
            "%dD, %zu particles, 80 steps (through the impact): stored stress components bit-identical %zu of %zu; "
            "derived sigma_zz within %.1e of max |sigma|; strain energy %.9g, relative "
            "difference %.1e",
            dim, n, same, n * (dim == 2 ? 5 : 6), dzz / smax, es[0], de);
        CHECK(same == n * (dim == 2 ? 5 : 6));
        CHECK(dzz <= 1e-12 * smax);
        CHECK(es[1] > 1e-3 && de <= 1e-12); /* the bodies are in contact */
    }
}
