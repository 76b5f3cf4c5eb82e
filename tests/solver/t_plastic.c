/*
 * t_plastic.c - the Drucker-Prager and Mohr-Coulomb stress-point
 * integrators (solver/mpm_plastic.c) against closed forms: drained
 * triaxial compression and extension and plane-strain compression driven
 * by a small mixed-control driver (axial strain prescribed, the lateral
 * stress held by a Newton iteration on the lateral strain), the failure
 * deviator q = sigma_lat - sigma_axial against Mohr-Coulomb's
 * k sigma_3' + 2 c sqrt(k) (compression positive) and the dilatancy ratio
 * at failure against the plastic potential; the tension cut-off, the apex
 * and MC's corners; the convergence of Sloan's substepping as its
 * tolerance falls.  The consistency and robustness tests are in
 * t_plastic_prop.c.  Tension positive throughout, as the solver.
 */
#include "t_plastic.h"

#include <stdlib.h>
#include <string.h>

int tp_params(mpm_plastic_params *p, mpm_plastic_kind kind, mpm_dp_match match, double phi_deg,
              double psi_deg, double c, double tension)
{
    memset(p, 0, sizeof *p);
    p->kind = kind;
    p->match = match;
    p->E = TP_E;
    p->nu = TP_NU;
    p->phi = phi_deg * M_PI / 180;
    p->psi = psi_deg * M_PI / 180;
    p->c = c;
    p->tension = tension;
    return mpm_plastic_init(p, NULL);
}

/* one update on copies (the driver's trial evaluations) */
static int try_step(const mpm_plastic_params *P, const tp_point *x, const double de[6], double s[6],
                    mpm_plastic_state *st, double *dis)
{
    memcpy(s, x->sig, sizeof x->sig);
    *st = x->st;
    return mpm_plastic_update(P, s, de, st, dis);
}

/* the increment for axial dea and lateral dl: lateral yy (and zz unless
 * plane strain, where deps_zz = 0) */
static void incr(int plane, double dea, double dl, double de[6])
{
    memset(de, 0, 6 * sizeof de[0]);
    de[0] = dea;
    de[1] = dl;
    de[2] = plane ? 0 : dl;
}

int tp_mixed_step(const mpm_plastic_params *P, tp_point *x, double dea, double p0, int plane)
{
    double dl = x->dl_prev, de[6], s[6], dis;
    mpm_plastic_state st;
    if (x->nsteps == 0) dl = -P->nu / (plane ? 1 - P->nu : 1) * dea;
    for (int it = 0; it < 60; it++) {
        incr(plane, dea, dl, de);
        int rc = try_step(P, x, de, s, &st, &dis);
        if (rc) return rc;
        double g = s[1] + p0;
        if (fabs(g) <= 1e-12 * (p0 + fabs(s[0]))) {
            memcpy(x->sig, s, sizeof s);
            x->st = st;
            for (int i = 0; i < 6; i++) x->eps[i] += de[i];
            x->dis += dis;
            x->dl_prev = dl;
            x->nsteps++;
            x->subs += st.substeps;
            if (st.substeps > x->maxsub) x->maxsub = st.substeps;
            return 0;
        }
        double h = 1e-7 * (fabs(dea) + fabs(dl)), s2[6], g2;
        incr(plane, dea, dl + h, de);
        if (try_step(P, x, de, s2, &st, &dis)) return -100;
        g2 = s2[1] + p0;
        double dg = (g2 - g) / h;
        if (!(fabs(dg) > 0)) return -101;
        dl -= g / dg;
    }
    return -102;
}

void tp_iso(tp_point *x, double p0)
{
    memset(x, 0, sizeof *x);
    x->sig[0] = x->sig[1] = x->sig[2] = -p0;
}

/* Runs n steps of axial dea from an isotropic -p0; the largest q seen;
 * the last step's dilatancy ratio deps_v / deps_axial in *ratio. */
static int triax(const mpm_plastic_params *P, double p0, double dea, int n, int plane, tp_point *x,
                 double *qmax, double *ratio)
{
    tp_iso(x, p0);
    *qmax = -HUGE_VAL;
    double e0[6] = {0};
    for (int k = 0; k < n; k++) {
        memcpy(e0, x->eps, sizeof e0);
        int rc = tp_mixed_step(P, x, dea, p0, plane);
        if (rc) return rc;
        double q = fabs(x->sig[1] - x->sig[0]);
        if (q > *qmax) *qmax = q;
    }
    double dv = (x->eps[0] - e0[0]) + (x->eps[1] - e0[1]) + (x->eps[2] - e0[2]);
    *ratio = dv / (x->eps[0] - e0[0]);
    return 0;
}

/* MC's failure deviator at triaxial compression (= plane-strain
 * compression) and triaxial extension, confining p0 (compression positive) */
static double mc_qc(double phi, double c, double p0)
{
    double k = (1 + sin(phi)) / (1 - sin(phi));
    return (k - 1) * p0 + 2 * c * sqrt(k);
}
static double mc_qe(double phi, double c, double p0)
{
    double k = (1 + sin(phi)) / (1 - sin(phi));
    return (k - 1) / k * p0 + 2 * c / sqrt(k);
}

static const struct {
    double phi, psi, c, p0;
} tri_cases[] = {{30, 10, 1e4, 1e5}, {30, 0, 1e4, 2e5}, {20, 20, 5e4, 1e5},
                 {40, 15, 0, 1e5},   {10, 5, 2e4, 5e4}, {35, 35, 1e3, 3e5}};
#define NTRI (int)(sizeof tri_cases / sizeof tri_cases[0])

/* Triaxial compression: DP's compression cone and MC reach MC's q_f; the
 * dilatancy ratio at failure is the potential's: DP etag / (etag/3 -
 * 1/sqrt3), MC (at its compression corner, both planes equally) 1 - m. */
static void check_triax(mpm_plastic_kind kind, mpm_dp_match match, int ext)
{
    double worst_q = 0, worst_r = 0;
    for (int i = 0; i < NTRI; i++) {
        mpm_plastic_params P;
        CHECK(tp_params(&P, kind, match, tri_cases[i].phi, tri_cases[i].psi, tri_cases[i].c,
                        HUGE_VAL) == 0);
        double p0 = tri_cases[i].p0;
        double qf = ext ? mc_qe(P.phi, P.c, p0) : mc_qc(P.phi, P.c, p0);
        double dea = (ext ? 1 : -1) * 6 * qf / P.E / 200, qmax, ratio;
        tp_point x;
        int rc = triax(&P, p0, dea, 200, 0, &x, &qmax, &ratio);
        CHECKF(rc == 0, "case %d: rc %d", i, rc);
        double q = fabs(x.sig[1] - x.sig[0]), rexp;
        if (kind == MPM_PLASTIC_DRUCKER_PRAGER)
            rexp =
                ext ? P.etag / (P.etag / 3 + 1 / sqrt(3.0)) : P.etag / (P.etag / 3 - 1 / sqrt(3.0));
        else
            rexp = ext ? (P.mpsi - 1) / P.mpsi : 1 - P.mpsi;
        double eq = fabs(q - qf) / qf, ep = (qmax - qf) / qf, er = fabs(ratio - rexp);
        TLOG("phi %2.0f psi %2.0f c %6.0f p0 %6.0f: q %.9g (analytic %.9g, rel err %.1e, peak "
             "%+.1e); dilatancy %.9f (analytic %.9f, err %.1e); substeps %ld in %d steps, max %d",
             tri_cases[i].phi, tri_cases[i].psi, P.c, p0, q, qf, eq, ep, ratio, rexp, er, x.subs,
             x.nsteps, x.maxsub);
        CHECK(eq <= 1e-6);
        CHECK(ep <= 1e-6);
        CHECK(er <= 1e-6 * (1 + fabs(rexp)));
        if (tri_cases[i].psi == 0) CHECK(fabs(ratio) <= 1e-6);
        CHECK(x.st.yielded && x.st.eps_p > 0 && x.dis > 0);
        if (eq > worst_q) worst_q = eq;
        if (er > worst_r) worst_r = er;
    }
    TLOG("worst: q rel err %.1e, dilatancy err %.1e (tolerances 1e-6)", worst_q, worst_r);
}

TEST(plastic_dp_triaxial_compression)
{
    check_triax(MPM_PLASTIC_DRUCKER_PRAGER, MPM_DP_COMPRESSION, 0);
}

TEST(plastic_mc_triaxial_compression)
{
    check_triax(MPM_PLASTIC_MOHR_COULOMB, MPM_DP_COMPRESSION, 0);
}

TEST(plastic_dp_triaxial_extension)
{
    check_triax(MPM_PLASTIC_DRUCKER_PRAGER, MPM_DP_EXTENSION, 1);
}

TEST(plastic_mc_triaxial_extension)
{
    check_triax(MPM_PLASTIC_MOHR_COULOMB, MPM_DP_COMPRESSION, 1);
}

/* The other cones miss MC where they are not matched: the extension cone
 * fails below MC's q in compression, the compression cone above it in
 * extension (the known bracketing; checks the matching is not symmetric
 * by accident). */
TEST(plastic_dp_cones_bracket_mc)
{
    mpm_plastic_params P;
    double p0 = 1e5, qmax, r;
    tp_point x;
    CHECK(tp_params(&P, MPM_PLASTIC_DRUCKER_PRAGER, MPM_DP_EXTENSION, 30, 10, 1e4, HUGE_VAL) == 0);
    double qc = mc_qc(P.phi, P.c, p0), qe = mc_qe(P.phi, P.c, p0);
    CHECK(triax(&P, p0, -6 * qc / P.E / 200, 200, 0, &x, &qmax, &r) == 0);
    TLOG("extension cone in compression: q %.6g < MC %.6g", qmax, qc);
    CHECK(qmax < 0.9 * qc);
    CHECK(tp_params(&P, MPM_PLASTIC_DRUCKER_PRAGER, MPM_DP_COMPRESSION, 30, 10, 1e4, HUGE_VAL) ==
          0);
    CHECK(triax(&P, p0, 6 * qe / P.E / 200, 200, 0, &x, &qmax, &r) == 0);
    TLOG("compression cone in extension: q %.6g > MC %.6g", qmax, qe);
    CHECK(qmax > 1.1 * qe);
}

/* Plane-strain compression (deps_zz = 0, sigma_yy = -p0): the plane-strain
 * matched DP and MC both fail at MC's q (sigma_zz is the intermediate
 * stress), and the dilatancy ratio deps_v / (deps_yy - deps_xx) at failure
 * is sin(psi) for both. */
TEST(plastic_plane_strain_compression)
{
    for (int kind = 0; kind < 2; kind++)
        for (int i = 0; i < NTRI; i++) {
            mpm_plastic_params P;
            CHECK(tp_params(&P, kind, MPM_DP_PLANE_STRAIN, tri_cases[i].phi, tri_cases[i].psi,
                            tri_cases[i].c, HUGE_VAL) == 0);
            double p0 = tri_cases[i].p0, qf = mc_qc(P.phi, P.c, p0), qmax, ratio;
            tp_point x;
            int rc = triax(&P, p0, -40 * qf / P.E / 400, 400, 1, &x, &qmax, &ratio);
            CHECKF(rc == 0, "rc %d", rc);
            double q = x.sig[1] - x.sig[0], dil = ratio / (ratio - 2); /* dv / (dyy - dxx) */
            double eq = fabs(q - qf) / qf, er = fabs(dil - sin(P.psi));
            TLOG("%s phi %2.0f psi %2.0f: q %.9g (MC %.9g, rel err %.1e), sigma_zz %.6g; "
                 "deps_v/dgamma %.9f (sin psi %.9f, err %.1e)",
                 kind ? "MC" : "DP", tri_cases[i].phi, tri_cases[i].psi, q, qf, eq, x.sig[2], dil,
                 sin(P.psi), er);
            CHECK(eq <= 1e-6);
            CHECK(er <= 1e-6);
            CHECK(x.sig[2] <= x.sig[1] + 1e-9 * p0 && x.sig[2] >= x.sig[0] - 1e-9 * p0);
        }
}

/* Uniaxial tension (lateral stress 0) from rest: DP's mean stress stops at
 * the cut-off (sigma_xx = 3 pt), MC's largest principal stress at pt; the
 * strain keeps growing, the stress stays. */
TEST(plastic_uniaxial_tension_cutoff)
{
    for (int kind = 0; kind < 2; kind++) {
        mpm_plastic_params P;
        double t = 2e3;
        CHECK(tp_params(&P, kind, MPM_DP_COMPRESSION, 30, 10, 1e4, t) == 0);
        CHECK(P.pt == t);
        tp_point x;
        tp_iso(&x, 0);
        double target = kind ? t : 3 * t;
        for (int k = 0; k < 100; k++)
            CHECK(tp_mixed_step(&P, &x, 4 * target / P.E / 100, 0, 0) == 0);
        double err = fabs(x.sig[0] - target) / target;
        TLOG("%s: sigma_xx %.12g (cut-off gives %.12g, rel err %.1e), lateral %.1e, eps_xx %.3g",
             kind ? "MC" : "DP", x.sig[0], target, err, x.sig[1], x.eps[0]);
        CHECK(err <= 1e-10);
        CHECK(fabs(x.sig[1]) <= 1e-10 * t && fabs(x.sig[2]) <= 1e-10 * t);
        CHECK(x.dis > 0);
    }
}

/* A pure isotropic extension, moderate or huge, from a sheared state:
 * without a cut-off (the apex caps it) both models return to the apex,
 * finite and exactly isotropic; with a cut-off pt below the apex MC returns
 * to the cut-offs' corner pt I, DP to the mean stress pt keeping its
 * deviator (inside the cone's radius at pt; the cut-off's flow is purely
 * volumetric). */
TEST(plastic_apex)
{
    for (int kind = 0; kind < 2; kind++)
        for (int cut = 0; cut < 2; cut++)
            for (int mag = 0; mag < 3; mag++) {
                mpm_plastic_params P;
                CHECK(tp_params(&P, kind, MPM_DP_COMPRESSION, 30, 10, 1e4, cut ? 1e3 : HUGE_VAL) ==
                      0);
                double apex = kind ? P.sgc / (P.kphi - 1) : P.xi * P.c / P.eta;
                double expect = cut ? 1e3 : apex, d = mag == 0 ? 1e-3 : mag == 1 ? 1e-1 : 1e3;
                double s0[6] = {-3.5e4, -3e4, -2.5e4, 2e3, -1e3, 5e2}, sig[6];
                double de[6] = {d, d, d, 0, 0, 0}, dis, m0 = (s0[0] + s0[1] + s0[2]) / 3;
                memcpy(sig, s0, sizeof sig);
                mpm_plastic_state st = {0};
                CHECK(mpm_plastic_update(&P, sig, de, &st, &dis) == 0);
                double worst = 0;
                int keep_dev = cut && !kind;
                for (int i = 0; i < 6; i++) {
                    double want = (i < 3 ? expect : 0) + (keep_dev ? s0[i] - (i < 3 ? m0 : 0) : 0);
                    double e = fabs(sig[i] - want) / expect;
                    if (e > worst) worst = e;
                }
                if (mag == 2)
                    TLOG("%s %s: apex %.9g, cut-off %.9g; returned within %.1e (relative) after "
                         "deps_v = %g",
                         kind ? "MC" : "DP", cut ? "cut-off 1e3" : "no cut-off", apex, P.pt, worst,
                         3 * d);
                CHECK(worst <= 1e-10);
                CHECK(dis >= 0 && isfinite(dis));
            }
}

/* MC's corners: a trial a little off the triaxial compression edge (s1 >
 * s2 by less than the return would move them apart) returns onto the edge
 * s1 = s2 exactly, and one near the extension edge onto s2 = s3; the frame
 * is rotated so the return goes through the spectral decomposition. */
TEST(plastic_mc_corners)
{
    mpm_plastic_params P;
    CHECK(tp_params(&P, MPM_PLASTIC_MOHR_COULOMB, 0, 30, 10, 1e4, HUGE_VAL) == 0);
    double th = 0.37, c = cos(th), s = sin(th);
    double Q[3][3] = {{c, s, 0}, {-s * 0.6, c * 0.6, 0.8}, {s * 0.8, -c * 0.8, 0.6}};
    for (int ext = 0; ext < 2; ext++) {
        /* principal strain increments in the rotated frame */
        static const double ee[2][3] = {{1.02e-3, 1e-3, -4e-3}, {4e-3, -1.02e-3, -1e-3}};
        const double *e = ee[ext];
        double de[6] = {0}, sig[6] = {-1e5, -1e5, -1e5, 0, 0, 0};
        static const int vi[6] = {0, 1, 2, 0, 1, 0}, vj[6] = {0, 1, 2, 1, 2, 2};
        for (int k = 0; k < 6; k++)
            for (int i = 0; i < 3; i++) de[k] += e[i] * Q[i][vi[k]] * Q[i][vj[k]];
        mpm_plastic_state st = {0};
        double dis, val[3], sc;
        CHECK(mpm_plastic_update(&P, sig, de, &st, &dis) == 0);
        mpm_plastic_principal(sig, val, NULL);
        double f = P.kphi * val[0] - val[2] - P.sgc;
        double gap = ext ? (val[1] - val[2]) : (val[0] - val[1]);
        double size = fabs(val[0]) + fabs(val[1]) + fabs(val[2]);
        mpm_plastic_yield(&P, sig, &sc);
        TLOG("%s corner: principal %.12g %.12g %.12g; edge gap %.1e, f %.1e (relative)",
             ext ? "extension" : "compression", val[0], val[1], val[2], gap / size, f / sc);
        CHECK(fabs(gap) <= 1e-10 * size);
        CHECK(fabs(f) <= 1e-10 * sc);
        CHECK(st.yielded && dis > 0);
        /* the trial was not on the edge: the same strain without the
         * rotation gives distinct trial principal values */
        CHECK(fabs(e[0] - e[1]) > 0 && fabs(e[1] - e[2]) > 0);
    }
}

/* Sloan's substepping converges: one large, non-proportional increment
 * from a state on the cone (shear plus compression), integrated with tol =
 * 1e-2 ... 1e-6 against a tol = 1e-11 reference: the error falls
 * monotonically with tol, the substeps grow. */
TEST(plastic_dp_substepping_converges)
{
    mpm_plastic_params P;
    double tols[] = {1e-2, 1e-3, 1e-4, 1e-5, 1e-6}, ref[6], err[5];
    int subs[5];
    for (int k = -1; k < 5; k++) {
        CHECK(tp_params(&P, MPM_PLASTIC_DRUCKER_PRAGER, MPM_DP_COMPRESSION, 30, 5, 1e4, HUGE_VAL) ==
              0);
        P.tol = k < 0 ? 1e-11 : tols[k];
        P.max_substeps = 1000000;
        /* on the cone: sqrt(J2) = xi c - eta p at p = -1e5, deviator along xx-yy */
        double p = -1e5, r = P.xi * P.c - P.eta * p, a = r / sqrt(1.0 / 2 + 1.0 / 2);
        double sig[6] = {p + a, p - a, p, 0, 0, 0};
        double de[6] = {-2e-3, 1e-3, 5e-4, 3e-3, -1e-3, 2e-3}, dis;
        mpm_plastic_state st = {0};
        CHECK(mpm_plastic_update(&P, sig, de, &st, &dis) == 0);
        if (k < 0) {
            memcpy(ref, sig, sizeof ref);
            TLOG("reference (tol 1e-11): %d substeps, dissipation %.9g", st.substeps, dis);
            continue;
        }
        double d[6];
        for (int i = 0; i < 6; i++) d[i] = sig[i] - ref[i];
        double n2 = 0, r2 = 0;
        for (int i = 0; i < 6; i++) {
            n2 += d[i] * d[i] * (i < 3 ? 1 : 2);
            r2 += ref[i] * ref[i] * (i < 3 ? 1 : 2);
        }
        err[k] = sqrt(n2 / r2);
        subs[k] = st.substeps;
        TLOG("tol %.0e: %4d substeps, relative error %.3e%s", tols[k], subs[k], err[k],
             k ? "" : " (first)");
        if (k) TLOG("  error ratio to the previous tol: %.3g", err[k - 1] / err[k]);
    }
    for (int k = 1; k < 5; k++) {
        CHECK(err[k] < err[k - 1]);
        CHECK(subs[k] >= subs[k - 1]);
    }
    CHECK(err[0] < 1e-1 && err[4] < 1e-5);
}

/* Elastic-plastic unloading (Sloan's Algorithm 3): from a state on the
 * cone, a shear increment against the deviator first unloads through the
 * elastic interior and then yields on the opposite side.  One update must
 * match the same increment cut into 20000 updates (each nearly elastic or
 * nearly a single substep), to about the substep tolerance. */
TEST(plastic_dp_unloading_then_yield)
{
    for (int k = 0; k < 3; k++) {
        mpm_plastic_params P;
        CHECK(tp_params(&P, MPM_PLASTIC_DRUCKER_PRAGER, (mpm_dp_match)k, 30, 10, 1e4, HUGE_VAL) ==
              0);
        double p = -1e5, r = P.xi * P.c - P.eta * p, a = r; /* sqrt(J2) of (a, -a, 0) is a */
        double s0[6] = {p + a, p - a, p, 0, 0, 0}, one[6], many[6], dis1, dism = 0;
        /* the elastic distance across the cone is 2 r / (2G) per unit of (1,-1,0) */
        double g = -3 * r / P.G;
        double de[6] = {g, -g, 0, 0.3 * g, 0, -0.2 * g};
        mpm_plastic_state st1 = {0}, stm = {0};
        memcpy(one, s0, sizeof one);
        memcpy(many, s0, sizeof many);
        CHECK(mpm_plastic_update(&P, one, de, &st1, &dis1) == 0);
        int n = 20000, subs = 0;
        for (int i = 0; i < n; i++) {
            double d[6], di;
            for (int c = 0; c < 6; c++) d[c] = de[c] / n;
            CHECK(mpm_plastic_update(&P, many, d, &stm, &di) == 0);
            dism += di;
            subs += stm.substeps;
        }
        double num = 0, den = 0;
        for (int c = 0; c < 6; c++) {
            num += (one[c] - many[c]) * (one[c] - many[c]) * (c < 3 ? 1 : 2);
            den += many[c] * many[c] * (c < 3 ? 1 : 2);
        }
        double err = sqrt(num / den), derr = fabs(dis1 - dism) / dism;
        TLOG("match %d: one update (%d substeps) vs 20000: stress rel diff %.2e, dissipation "
             "%.6g vs %.6g (rel %.1e), eps_p %.6g vs %.6g",
             k, st1.substeps, err, dis1, dism, derr, st1.eps_p, stm.eps_p);
        CHECK(st1.yielded && stm.yielded);
        CHECK(err <= 1e-4);
        CHECK(derr <= 1e-3);
        CHECK(fabs(st1.eps_p - stm.eps_p) <= 1e-3 * stm.eps_p);
        /* it did unload: the first fifth of the path alone is elastic */
        double half[6], dh[6];
        memcpy(half, s0, sizeof half);
        for (int c = 0; c < 6; c++) dh[c] = de[c] / 5;
        mpm_plastic_state sth = {0};
        CHECK(mpm_plastic_update(&P, half, dh, &sth, &dis1) == 0);
        CHECK(sth.substeps == 0 && dis1 == 0);
    }
}

/* The energy balance of a drained triaxial test (DP and MC): the stress
 * work sum (sig_old + sig_new)/2 : deps equals the elastic energy's change
 * plus the summed dissipation, to a small fraction of the dissipation (the
 * trapezoidal work rule's error at the elastic-plastic transition). */
TEST(plastic_triaxial_energy_balance)
{
    for (int kind = 0; kind < 2; kind++) {
        mpm_plastic_params P;
        CHECK(tp_params(&P, kind, MPM_DP_COMPRESSION, 30, 10, 1e4, HUGE_VAL) == 0);
        double p0 = 1e5, qf = mc_qc(P.phi, P.c, p0), W = 0;
        tp_point x;
        tp_iso(&x, p0);
        double s0[6], e0[6], U0, U1;
        memcpy(s0, x.sig, sizeof s0);
#define TP_U(s)                                                           \
    (((s)[0] * (s)[0] + (s)[1] * (s)[1] + (s)[2] * (s)[2]) / (2 * P.E) -  \
     P.nu / P.E * ((s)[0] * (s)[1] + (s)[1] * (s)[2] + (s)[0] * (s)[2]) + \
     ((s)[3] * (s)[3] + (s)[4] * (s)[4] + (s)[5] * (s)[5]) / (2 * P.G))
        U0 = TP_U(s0);
        for (int k = 0; k < 400; k++) {
            double so[6];
            memcpy(so, x.sig, sizeof so);
            memcpy(e0, x.eps, sizeof e0);
            CHECK(tp_mixed_step(&P, &x, -8 * qf / P.E / 400, p0, 0) == 0);
            for (int c = 0; c < 6; c++)
                W += 0.5 * (so[c] + x.sig[c]) * (x.eps[c] - e0[c]) * (c < 3 ? 1 : 2);
        }
        U1 = TP_U(x.sig);
#undef TP_U
        double gap = W - (U1 - U0) - x.dis;
        TLOG("%s: work %.9g = dU %.9g + dissipation %.9g + %.2e (%.1e of the dissipation)",
             kind ? "MC" : "DP", W, U1 - U0, x.dis, gap, gap / x.dis);
        CHECK(fabs(gap) <= 1e-3 * x.dis);
    }
}

/* MC's closed form is the exact solution of the rate equations for fixed
 * principal axes on one plane: one update of a proportional strain
 * increment (that yields) equals the same increment cut into 1000
 * updates, to round-off, dissipation included; in a rotated frame. */
TEST(plastic_mc_one_update_is_exact)
{
    mpm_plastic_params P;
    CHECK(tp_params(&P, MPM_PLASTIC_MOHR_COULOMB, 0, 30, 10, 1e4, HUGE_VAL) == 0);
    double th = 0.9, c = cos(th), s = sin(th);
    double Q[3][3] = {{c, 0, s}, {0, 1, 0}, {-s, 0, c}};
    static const int vi[6] = {0, 1, 2, 0, 1, 0}, vj[6] = {0, 1, 2, 1, 2, 2};
    double e[3] = {-3e-3, 0, 3e-3}, de[6] = {0}, worst = 0;
    for (int k = 0; k < 6; k++)
        for (int i = 0; i < 3; i++) de[k] += e[i] * Q[i][vi[k]] * Q[i][vj[k]];
    double one[6] = {-1e5, -1e5, -1e5, 0, 0, 0}, many[6], dis1, dism = 0;
    memcpy(many, one, sizeof many);
    mpm_plastic_state st1 = {0}, stm = {0};
    CHECK(mpm_plastic_update(&P, one, de, &st1, &dis1) == 0);
    for (int n = 0; n < 1000; n++) {
        double d[6], di;
        for (int k = 0; k < 6; k++) d[k] = de[k] / 1000;
        CHECK(mpm_plastic_update(&P, many, d, &stm, &di) == 0);
        dism += di;
    }
    for (int k = 0; k < 6; k++) {
        double v = fabs(one[k] - many[k]) / 1e5;
        if (v > worst) worst = v;
    }
    double val[3];
    mpm_plastic_principal(one, val, NULL);
    TLOG("one update vs 1000: stress differs by %.1e (relative), dissipation %.9g vs %.9g; "
         "principal %.6g %.6g %.6g (on the plane, off the edges)",
         worst, dis1, dism, val[0], val[1], val[2]);
    CHECK(st1.yielded && val[0] - val[1] > 1e3 && val[1] - val[2] > 1e3);
    CHECK(worst <= 1e-11);
    CHECK(fabs(st1.eps_p - stm.eps_p) <= 1e-9 * stm.eps_p);
    CHECK(fabs(dis1 - dism) <= 1e-9 * dism); /* the trapezoidal dissipation is exact here */
}

/* DP's cut-off corner: a trial beyond the cut-off with a deviator beyond
 * the cone's radius at pt returns to p = pt, sqrt(J2) = xi c - eta pt,
 * keeping the deviator's direction. */
TEST(plastic_dp_cutoff_corner)
{
    mpm_plastic_params P;
    CHECK(tp_params(&P, MPM_PLASTIC_DRUCKER_PRAGER, MPM_DP_COMPRESSION, 30, 10, 1e4, 1e3) == 0);
    double sig[6] = {0}, de[6] = {3e-3, 1e-3, 2e-3, 4e-4, -2e-4, 1e-4}, dis, d0[6], d1[6];
    double m = (de[0] + de[1] + de[2]) / 3;
    for (int i = 0; i < 6; i++) d0[i] = de[i] - (i < 3 ? m : 0);
    mpm_plastic_state st = {0};
    CHECK(mpm_plastic_update(&P, sig, de, &st, &dis) == 0);
    double p = (sig[0] + sig[1] + sig[2]) / 3, r = 0, r0 = 0, cross = 0;
    for (int i = 0; i < 6; i++) {
        d1[i] = sig[i] - (i < 3 ? p : 0);
        r += d1[i] * d1[i] * (i < 3 ? 0.5 : 1);
        r0 += d0[i] * d0[i] * (i < 3 ? 0.5 : 1);
        cross += d0[i] * d1[i] * (i < 3 ? 0.5 : 1);
    }
    r = sqrt(r);
    r0 = sqrt(r0);
    double rt = P.xi * P.c - P.eta * P.pt, align = cross / (r * r0);
    TLOG("p %.12g (pt %g), sqrt(J2) %.12g (radius at pt %.12g), direction cosine %.15f", p, P.pt, r,
         rt, align);
    CHECK(fabs(p - P.pt) <= 1e-12 * P.pt);
    CHECK(fabs(r - rt) <= 1e-12 * rt);
    CHECK(fabs(align - 1) <= 1e-12);
    CHECK(st.yielded && dis > 0);
}

/* Near the apex: cohesionless and slightly cohesive sand (c 0 and 1 Pa,
 * phi 30, psi 0, plane-strain match, cut-off at the apex) at a stress of
 * about 1 Pa, given a strain increment of 2e-3 (the granular collapse's
 * free surface, where the increment is thousands of yield strains).
 * Sloan's substepping cannot resolve it within max_substeps (the flow
 * direction turns within a substep: the error estimate stalls at 0.5 Pa,
 * measured), and the collapse stopped with "substepping exhausted"; the
 * update now ends on backward Euler's return: it succeeds, ends on or
 * inside the cone (f <= ftol scale) at or below the cut-off, and
 * dissipates >= 0. */
TEST(plastic_dp_near_apex)
{
    static const double c[2] = {0, 1};
    for (int k = 0; k < 2; k++) {
        mpm_plastic_params P;
        CHECK(tp_params(&P, MPM_PLASTIC_DRUCKER_PRAGER, MPM_DP_PLANE_STRAIN, 30, 0, c[k], 0) == 0);
        double sig[6] = {0.151056, -1.73317, -0.855162, 0.854192, 0, 0};
        double de[6] = {0.001969, -0.00196999, 0, 0.00201988, 0, 0}, dis = -1;
        mpm_plastic_state st = {0};
        int rc = mpm_plastic_update(&P, sig, de, &st, &dis);
        double p = (sig[0] + sig[1] + sig[2]) / 3, d[3] = {sig[0] - p, sig[1] - p, sig[2] - p};
        double r = sqrt(0.5 * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + sig[3] * sig[3]);
        double f = r + P.eta * p - P.xi * P.c;
        TLOG("c = %g: rc %d, substeps %d, p %.4g, sqrt(J2) %.4g, f %.3g, dissipation %.4g", c[k],
             rc, st.substeps, p, r, f, dis);
        CHECK(rc == 0);
        CHECK(st.substeps == P.max_substeps + 1); /* the fallback ran */
        CHECK(f <= 1e-8 * (r + P.eta * fabs(p) + P.xi * P.c) + 1e-12);
        CHECK(p <= P.pt + 1e-12);
        CHECK(dis >= 0);
    }
}
