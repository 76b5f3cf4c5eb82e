/*
 * t_shape.c - shape functions: partition of unity (sum S = 1, sum G = 0)
 * to round-off at random positions in 1D, 2D and 3D for linear MPM and uGIMP,
 * the reference node of Eqs. 21-22, and uGIMP against a numerical quadrature
 * of Eqs. 17-18.
 */
#include "mpm.h"
#include "mpm_diag.h"
#include "t.h"

#include <stdint.h>
#include <stdlib.h>

static uint64_t rng = 88172645463325252ull;
static double urand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) / 9007199254740992.0;
}

TEST(shape_reference_node_eq21_eq22)
{
    double w[4], g[4];
    /* h = 0.5, x0 = -1: x = 0.3 lies in cell trunc(1.3/0.5) = 2 */
    CHECK(mpm_shape_1d(MPM_METHOD_MPM, 0.3, -1.0, 0.5, 0.1, 0, w, g) == 2);
    CHECK(mpm_shape_1d(MPM_METHOD_GIMP, 0.3, -1.0, 0.5, 0.1, 0, w, g) == 1);
    CHECK_NEAR(w[0], 0.0, 0.0); /* node 1: support [0.2, 0.4] misses it */
}

/* Partition of unity of the tensor-product weights at random points. */
static double pou_error(mpm_method method, int dim, int trials, double *gerr)
{
    int ns = method == MPM_METHOD_GIMP ? 4 : 2;
    double worst = 0, gworst = 0, h[3] = {0.1, 0.25, 0.07};
    for (int t = 0; t < trials; t++) {
        double w[3][4], g[3][4];
        for (int d = 0; d < dim; d++) {
            double lp = method == MPM_METHOD_GIMP ? h[d] * (0.05 + 0.95 * urand()) : 0;
            double x = 1.0 + 5.0 * urand();
            mpm_shape_1d(method, x, 0.0, h[d], lp, 0, w[d], g[d]);
        }
        double sum = 0, gsum[3] = {0, 0, 0};
        int n = 1;
        for (int d = 0; d < dim; d++) n *= ns;
        for (int r = 0; r < n; r++) {
            int k[3] = {r % ns, (r / ns) % ns, r / (ns * ns)};
            double S = 1;
            for (int d = 0; d < dim; d++) S *= w[d][k[d]];
            sum += S;
            for (int a = 0; a < dim; a++) {
                double G = 1;
                for (int d = 0; d < dim; d++) G *= d == a ? g[d][k[d]] : w[d][k[d]];
                gsum[a] += G * h[a]; /* scale-free */
            }
        }
        if (fabs(sum - 1) > worst) worst = fabs(sum - 1);
        for (int a = 0; a < dim; a++)
            if (fabs(gsum[a]) > gworst) gworst = fabs(gsum[a]);
    }
    *gerr = gworst;
    return worst;
}

TEST(shape_partition_of_unity)
{
    for (int m = 0; m < 2; m++)
        for (int dim = 1; dim <= 3; dim++) {
            double gerr, serr = pou_error(m ? MPM_METHOD_GIMP : MPM_METHOD_MPM, dim, 20000, &gerr);
            TLOG("%s %dD: max |sum S - 1| = %.2e, max |sum G| h = %.2e", m ? "GMPM" : "MPM ", dim,
                 serr, gerr);
            CHECK(serr < 1e-14);
            CHECK(gerr < 1e-14);
        }
}

/* Eqs. 17-18 by midpoint quadrature of tent * box over the support. */
TEST(shape_gimp_matches_quadrature)
{
    double worst = 0, gworst = 0;
    for (int t = 0; t < 200; t++) {
        double h = 0.2, lp = h * (0.1 + 0.9 * urand()), x = 0.6 + urand();
        double w[4], g[4];
        int ref = mpm_shape_1d(MPM_METHOD_GIMP, x, 0.0, h, lp, 0, w, g);
        for (int k = 0; k < 4; k++) {
            double xn = (ref + k) * h, acc = 0;
            int nq = 20000;
            for (int q = 0; q < nq; q++) {
                double xi = x - lp + (q + 0.5) * 2 * lp / nq;
                double s = 1 - fabs(xi - xn) / h;
                acc += (s > 0 ? s : 0) / nq;
            }
            /* gradient: difference of the tent at the support ends */
            double sp = 1 - fabs(x + lp - xn) / h, sm = 1 - fabs(x - lp - xn) / h;
            double gq = ((sp > 0 ? sp : 0) - (sm > 0 ? sm : 0)) / (2 * lp);
            if (fabs(acc - w[k]) > worst) worst = fabs(acc - w[k]);
            if (fabs(gq - g[k]) > gworst) gworst = fabs(gq - g[k]);
        }
    }
    TLOG("uGIMP vs quadrature: max |S diff| = %.2e, max |G diff| = %.2e", worst, gworst);
    CHECK(worst < 1e-8);
    CHECK(gworst < 1e-9);
}

/* lp -> 0 recovers the linear tents: GMPM generalises MPM (Eq. 5). */
TEST(shape_gimp_tends_to_mpm)
{
    double wm[4], gm[4], wg[4], gg[4];
    double x = 1.37;
    mpm_shape_1d(MPM_METHOD_MPM, x, 0.0, 0.5, 0, 0, wm, gm);
    /* away from a kink the uGIMP weight equals the tent exactly; only the
     * cancellation in F(s+a) - F(s-a), about eps/a, remains */
    mpm_shape_1d(MPM_METHOD_GIMP, x, 0.0, 0.5, 1e-3, 0, wg, gg);
    CHECK_NEAR(wg[0], 0.0, 1e-15);
    CHECK_NEAR(wg[1], wm[0], 1e-12);
    CHECK_NEAR(wg[2], wm[1], 1e-12);
    CHECK_NEAR(wg[3], 0.0, 1e-15);
    CHECK_NEAR(gg[1], gm[0], 1e-9);
    CHECK_NEAR(gg[2], gm[1], 1e-9);
}
