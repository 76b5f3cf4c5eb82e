/*
 * t_plastic_prop.c - properties of the plastic stress-point integrators
 * (solver/mpm_plastic.c) that hold for any input: an elastic increment
 * inside the surface is Hooke's law to round-off with no dissipation; the
 * update is invariant under a rotation of the frame; and thousands of
 * random states and increments (tiny to huge, pure shear, hydrostatic
 * tension and compression) return 0 with a finite stress on or inside the
 * surface within ftol and a dissipation >= 0 up to round-off.
 */
#include "t_plastic.h"

#include <stdint.h>
#include <string.h>

static uint64_t rng = 0x9e3779b97f4a7c15ull;
static double urand(void)
{
    return t_urand(&rng);
}
static double srand1(void)
{
    return t_srand(&rng);
}

static void hooke(const mpm_plastic_params *P, const double e[6], double s[6])
{
    double tr = e[0] + e[1] + e[2];
    for (int i = 0; i < 6; i++) s[i] = 2 * P->G * e[i] + (i < 3 ? P->lam * tr : 0);
}

/* a random rotation (unit quaternion) */
static void rand_rot(double Q[3][3])
{
    double q[4], n = 0;
    for (int i = 0; i < 4; i++) {
        q[i] = srand1();
        n += q[i] * q[i];
    }
    n = sqrt(n);
    double w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
    double R[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                      {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                      {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
    memcpy(Q, R, sizeof R);
}

/* Q A Q^T for A in Voigt */
static void rotate(double Q[3][3], const double a[6], double out[6])
{
    double A[3][3] = {{a[0], a[3], a[5]}, {a[3], a[1], a[4]}, {a[5], a[4], a[2]}}, B[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double v = 0;
            for (int k = 0; k < 3; k++)
                for (int l = 0; l < 3; l++) v += Q[i][k] * A[k][l] * Q[j][l];
            B[i][j] = v;
        }
    out[0] = B[0][0];
    out[1] = B[1][1];
    out[2] = B[2][2];
    out[3] = B[0][1];
    out[4] = B[1][2];
    out[5] = B[0][2];
}

static double vnorm(const double a[6])
{
    return sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2] +
                2 * (a[3] * a[3] + a[4] * a[4] + a[5] * a[5]));
}

TEST(plastic_elastic_is_hooke)
{
    double worst = 0;
    for (int kind = 0; kind < 2; kind++) {
        mpm_plastic_params P;
        CHECK(tp_params(&P, kind, MPM_DP_COMPRESSION, 30, 10, 1e4, 5e3) == 0);
        for (int n = 0; n < 2000; n++) {
            /* well inside: isotropic compression with a small deviator */
            double sig[6], de[6], s0[6], h[6], dis = -1;
            for (int i = 0; i < 6; i++) {
                sig[i] = (i < 3 ? -1e5 : 0) + 1e3 * srand1();
                de[i] = 1e-5 * srand1();
            }
            memcpy(s0, sig, sizeof s0);
            mpm_plastic_state st = {0};
            CHECK(mpm_plastic_update(&P, sig, de, &st, &dis) == 0);
            hooke(&P, de, h);
            for (int i = 0; i < 6; i++) {
                double e = fabs(sig[i] - (s0[i] + h[i])) / 1e5;
                if (e > worst) worst = e;
            }
            CHECK(st.substeps == 0 && !st.yielded && st.eps_p == 0);
            CHECK(dis == 0);
        }
    }
    TLOG("elastic increments: max |sigma - (sigma0 + D deps)| / |sigma| = %.1e", worst);
    CHECK(worst <= 1e-15);
}

/* The same increment in a rotated frame gives the rotated stress. */
TEST(plastic_rotational_invariance)
{
    for (int kind = 0; kind < 2; kind++) {
        mpm_plastic_params P;
        CHECK(tp_params(&P, kind, MPM_DP_COMPRESSION, 30, 10, 1e4, 3e3) == 0);
        double worst = 0;
        for (int n = 0; n < 500; n++) {
            double sig[6], de[6], Q[3][3], sr[6], dr[6], out[6], dis1, dis2;
            double mag = pow(10, -5 + 3 * urand());
            for (int i = 0; i < 6; i++) {
                sig[i] = (i < 3 ? -5e4 : 0) + 2e4 * srand1();
                de[i] = mag * srand1();
            }
            mpm_plastic_state st1 = {0}, st2 = {0};
            /* start admissible: return the random state first */
            double zero[6] = {0};
            CHECK(mpm_plastic_update(&P, sig, zero, &st1, &dis1) == 0);
            rand_rot(Q);
            rotate(Q, sig, sr);
            rotate(Q, de, dr);
            CHECK(mpm_plastic_update(&P, sig, de, &st1, &dis1) == 0);
            CHECK(mpm_plastic_update(&P, sr, dr, &st2, &dis2) == 0);
            rotate(Q, sig, out);
            double d[6];
            for (int i = 0; i < 6; i++) d[i] = out[i] - sr[i];
            double e = vnorm(d) / (vnorm(out) + P.c);
            if (e > worst) worst = e;
            CHECKF(e <= 1e-9, "%s case %d: rotated differs by %.2e", kind ? "MC" : "DP", n, e);
            CHECK(fabs(dis1 - dis2) <= 1e-8 * (fabs(dis1) + 1e-3));
        }
        TLOG("%s: worst relative difference, rotated frame vs rotated result: %.1e",
             kind ? "MC" : "DP", worst);
    }
}

/* Random states (any, also outside the surface) and increments from 1e-8
 * to 10 in size, plus pure shear and hydrostatic tension and compression:
 * the update succeeds, the stress is finite and admissible within ftol, the
 * dissipation >= -1e-12 of the work scale. */
TEST(plastic_random_robustness)
{
    for (int kind = 0; kind < 2; kind++)
        for (int mat = 0; mat < 4; mat++) {
            mpm_plastic_params P;
            double phi = (double[4]){30, 0, 45, 15}[mat], psi = (double[4]){10, 0, 45, 0}[mat];
            double c = (double[4]){1e4, 5e4, 0, 1e3}[mat];
            double t = (double[4]){HUGE_VAL, 1e4, 0, 5e2}[mat];
            mpm_dp_match match = (mpm_dp_match)(mat % 3);
            CHECK(tp_params(&P, kind, match, phi, psi, c, t) == 0);
            int fails = 0, plastic = 0, maxsub = 0;
            long subs = 0;
            double worst_f = -HUGE_VAL, worst_d = 0, rho_min = HUGE_VAL;
            for (int n = 0; n < 3000; n++) {
                double sig[6], de[6], dis, sc;
                int type = n % 5;
                double smag = pow(10, 3 + 3 * urand()), emag = pow(10, -8 + 9 * urand());
                for (int i = 0; i < 6; i++) {
                    sig[i] = smag * srand1() - (i < 3 ? smag * urand() : 0);
                    de[i] = emag * srand1();
                }
                if (type == 1) /* pure shear */
                    de[0] = de[1] = de[2] = 0;
                if (type == 2 || type == 3) { /* hydrostatic extension / compression */
                    double v = (type == 2 ? 1 : -1) * emag;
                    for (int i = 0; i < 6; i++) de[i] = i < 3 ? v : 0;
                }
                mpm_plastic_state st = {0};
                double s0[6];
                memcpy(s0, sig, sizeof s0);
                int rc = mpm_plastic_update(&P, sig, de, &st, &dis);
                if (rc) {
                    /* only DP, and only for an increment of a thousand yield strains:
                     * explicit substepping is stiff there (each substep may move the
                     * stress by about the cone's radius) and runs out of substeps */
                    double h[6], m0 = (s0[0] + s0[1] + s0[2]) / 3;
                    hooke(&P, de, h);
                    double rho = vnorm(h) / (P.xi * P.c + P.eta * fabs(m0));
                    if (rho < rho_min) rho_min = rho;
                    fails++;
                    CHECK(kind == MPM_PLASTIC_DRUCKER_PRAGER && rho > 1000);
                    CHECK(rc == MPM_EDIVERGED);
                    CHECK(memcmp(s0, sig, sizeof s0) == 0);
                    continue;
                }
                for (int i = 0; i < 6; i++) CHECK(isfinite(sig[i]));
                double f = mpm_plastic_yield(&P, sig, &sc);

                /* ftol relative to the surface's scale, plus the round-off of the trial
                 * stress (absolute at a cohesionless apex, where the scale is 0) */
                double h[6];
                hooke(&P, de, h);
                double roff = 1e-14 * (vnorm(s0) + vnorm(h));
                if (sc > roff && f / sc > worst_f) worst_f = f / sc;
                CHECKF(f <= 1.01 * P.ftol * sc + roff, "%s mat %d case %d: f %.3e scale %.3e",
                       kind ? "MC" : "DP", mat, n, f, sc);
                double ss = vnorm(s0) + vnorm(sig), w = ss * (vnorm(de) + ss / P.E) + 1e-300;
                if (dis / w < worst_d) worst_d = dis / w;
                CHECKF(dis >= -1e-12 * w, "case %d: dissipation %.3e (scale %.3e)", n, dis, w);
                CHECK(isfinite(dis) && st.eps_p >= 0);
                if (st.substeps) plastic++;
                subs += st.substeps;
                if (st.substeps > maxsub) maxsub = st.substeps;
            }
            TLOG("%s phi %2.0f c %5.0f cut-off %g: %d plastic of 3000, substeps mean %.1f max %d, "
                 "worst f/scale %.1e, worst dissipation/scale %.1e",
                 kind ? "MC" : "DP", phi, c, t, plastic, plastic ? (double)subs / plastic : 0,
                 maxsub, worst_f, worst_d);
            if (fails)
                TLOG("  %d clean errors (substeps exhausted), the smallest increment among them "
                     "|D deps| = %.0f times the yield stress",
                     fails, rho_min);
            CHECK(fails < 200);
        }
}

TEST(plastic_params_checked)
{
    mpm_plastic_params P;
    mpm_error err;
    CHECK(tp_params(&P, MPM_PLASTIC_DRUCKER_PRAGER, 0, 30, 10, 1e4, 0) == 0);
    CHECK(P.tol == 1e-4 && P.ftol == 1e-8 && P.max_substeps == 1000 && P.pt == 0);
    P.psi = P.phi + 0.1;
    CHECK(mpm_plastic_init(&P, &err) == MPM_EINVAL);
    char buf[64];
    CHECK(strcmp(mpm_error_field(&err, MPM_FIELD_PROTO, buf, sizeof buf), "dilatancy_angle") == 0);
    CHECK(tp_params(&P, MPM_PLASTIC_MOHR_COULOMB, 0, 0, 0, 0, 0) == MPM_EINVAL);
    CHECK(tp_params(&P, MPM_PLASTIC_MOHR_COULOMB, 0, 30, 0, 1e4, -1) == MPM_EINVAL);
    CHECK(tp_params(&P, MPM_PLASTIC_MOHR_COULOMB, 0, 90, 0, 1e4, 0) == MPM_EINVAL);
    CHECK(tp_params(&P, MPM_PLASTIC_MOHR_COULOMB, 0, 0, 0, 1e4, HUGE_VAL) == 0);
    CHECK(isinf(P.pt)); /* Tresca: no apex, no cut-off */
}
