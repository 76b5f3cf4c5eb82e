/*
 * t_dp_lanes.c - Drucker-Prager's updates four at a time
 * (mpm_dp_lanes(), solver/mpm_plastic_avx2.c) against the scalar
 * update (mpm_plastic_update()), bit for bit: on random states that reach
 * every path of the update (starts inside the cone, on it loading and
 * unloading, trials past the tension cut-off, from a start inside or on
 * the surface, increments of a thousand yield strains, non-finite
 * increments, updates that run out of substeps), in batches of every
 * size from 1 to MPM_DP_LANES_MAX.  A
 * particle the lanes take must give the scalar stress, eps_p increment,
 * dissipation and substeps; one they leave must keep its input row.
 * Every path must be reached, the lanes' and the scalar update's.
 * Skipped where the CPU has no AVX2.
 */
#include "mpm.h"
#include "mpm_plastic_avx2.h"
#include "t.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define N 20000

static uint64_t rng = 0x9e3779b97f4a7c15ull;
static double urand(void)
{
    return t_urand(&rng);
}
static double srand1(void)
{
    return t_srand(&rng);
}

/* A random start (sig) and increment (de) for material P: the deviator of
 * one start in three scaled onto the cone (f = 0 up to round-off), one in
 * six with a mean stress past the cut-off's reach, increments from 1e-8 to
 * 1e-2, one in 400 non-finite; dim 2: plane strain (no yz, xz, de_zz), taken
 * by the lanes as rows of 4 (nc = 4). */
static void state(const mpm_plastic_params *P, int dim, double sig[6], double de[6])
{
    double pm = -4e3 * urand() + (urand() < 1.0 / 6 ? 3e3 : 0);
    for (int c = 0; c < 6; c++) sig[c] = (c < 3 ? pm : 0) + 2e3 * srand1();
    if (dim == 2) sig[4] = sig[5] = 0;
    if (urand() < 1.0 / 3) {
        double p = (sig[0] + sig[1] + sig[2]) / 3, d[6], dd = 0;
        for (int c = 0; c < 6; c++) d[c] = sig[c] - (c < 3 ? p : 0);
        for (int c = 0; c < 6; c++) dd += (c < 3 ? 1 : 2) * d[c] * d[c];
        double r = sqrt(0.5 * dd), rf = P->xi * P->c - P->eta * p;
        if (r > 0 && rf > 0)
            for (int c = 0; c < 6; c++) sig[c] = d[c] * (rf / r) + (c < 3 ? p : 0);
    }
    double mag = pow(10, -8 + 6 * urand());
    for (int c = 0; c < 6; c++) de[c] = mag * srand1();
    if (dim == 2) de[2] = de[4] = de[5] = 0;
    /* in 2D not yz or xz, which the lanes' rows of 4 (nc = 4) do not read */
    if (urand() < 0.0025)
        de[(int)(urand() * 6) % (dim == 2 ? 4 : 6)] = urand() < 0.5 ? INFINITY : NAN;
}

static void one_material(const char *name, const mpm_plastic_params *P, int dim)
{
    double *sig = malloc(N * 6 * sizeof *sig), *s0 = malloc(N * 6 * sizeof *s0),
           *de = malloc(N * 6 * sizeof *de), *epq = malloc(N * sizeof *epq),
           *dis = malloc(N * sizeof *dis);
    int *nsub = malloc(N * sizeof *nsub);
    unsigned char *ok = malloc(N);
    if (!sig || !s0 || !de || !epq || !dis || !nsub || !ok) {
        free(sig), free(s0), free(de), free(epq), free(dis), free(nsub), free(ok);
        CHECKF(0, "out of memory");
    }
    for (size_t i = 0; i < N; i++) state(P, dim, s0 + 6 * i, de + 6 * i);
    memcpy(sig, s0, N * 6 * sizeof *sig);
    /* batches of 1, 2, ..., MPM_DP_LANES_MAX, 1, 2, ... */
    size_t i0 = 0, m = 1;
    while (i0 < N) {
        size_t k = N - i0 < m ? N - i0 : m;
        mpm_dp_lanes(P, dim == 3 ? 6 : 4, k, sig + 6 * i0, de + 6 * i0, epq + i0, dis + i0,
                     nsub + i0, ok + i0);
        i0 += k;
        m = m == MPM_DP_LANES_MAX ? 1 : m + 1;
    }
    long taken = 0, left = 0, left_plastic = 0, elastic = 0, bad = 0, maxsub = 0, cutoff = 0;
    for (size_t i = 0; i < N && !bad; i++) {
        double s[6], d = -1;
        memcpy(s, s0 + 6 * i, sizeof s);
        mpm_plastic_state st = {0.25, 0, 0};
        int rc = mpm_plastic_update(P, s, de + 6 * i, &st, &d);
        if (!ok[i]) {
            left++;
            if (memcmp(sig + 6 * i, s0 + 6 * i, 6 * sizeof *sig)) {
                TLOG("particle %zu: left to the scalar update, but its row changed", i);
                bad++;
            }
            if (!rc && st.substeps) left_plastic++;
            if (!rc && !st.substeps) elastic++;
            continue;
        }
        taken++;
        double De[6], tr[6], ftr;
        int on = 0;
        cutoff += mpm_dp_trial(P, s0 + 6 * i, de + 6 * i, De, tr, &ftr, &on) == MPM_DP_TENSION;
        double e2 = 0.25 + epq[i];
        if (rc || memcmp(s, sig + 6 * i, sizeof s) || memcmp(&d, dis + i, sizeof d) ||
            memcmp(&e2, &st.eps_p, sizeof e2) || st.substeps != nsub[i] || !st.yielded) {
            TLOG("particle %zu: sig_xx %.17g / %.17g, dissipation %.17g / %.17g, substeps %d / %d "
                 "(lanes / scalar)",
                 i, sig[6 * i], s[0], dis[i], d, nsub[i], st.substeps);
            bad++;
        }
        if (nsub[i] > maxsub) maxsub = nsub[i];
    }
    TLOG("%s, %dD: %d particles, %ld taken by the lanes (%ld past the cut-off; at most %ld "
         "substeps), %ld left: %ld plastic, %ld elastic, %ld refused",
         name, dim, N, taken, cutoff, maxsub, left, left_plastic, elastic,
         left - left_plastic - elastic);
    free(sig), free(s0), free(de), free(epq), free(dis), free(nsub), free(ok);
    CHECKF(!bad, "%s: %ld particles differ from the scalar update", name, bad);
    /* every path was reached: the lanes' and the scalar's */
    CHECKF(taken > N / 10, "%s: the lanes took only %ld particles", name, taken);
    long most = P->max_substeps && P->max_substeps <= 3 ? 1 : 3;
    CHECKF(maxsub > most, "%s: no update of more than %ld substeps", name, maxsub);
    CHECKF(cutoff > N / 100, "%s: only %ld particles past the cut-off taken", name, cutoff);
    CHECKF(left_plastic > N / 100, "%s: only %ld plastic particles left to the scalar update", name,
           left_plastic);
    CHECKF(left - left_plastic - elastic > 0, "%s: no refused update", name);
}

TEST(dp_lanes_same_bits)
{
    if (!mpm_kernels_avx2_available()) {
        TLOG("this CPU has no AVX2: nothing to compare");
        return;
    }
    mpm_plastic_params a, b;
    memset(&a, 0, sizeof a);
    a.kind = MPM_PLASTIC_DRUCKER_PRAGER;
    a.E = 2e7, a.nu = 0.3, a.phi = 30 * M_PI / 180, a.c = 2e3, a.tension = 500;
    a.match = MPM_DP_PLANE_STRAIN;
    b = a;
    b.phi = 25 * M_PI / 180, b.psi = 5 * M_PI / 180, b.c = 10, b.tension = HUGE_VAL;
    b.match = MPM_DP_COMPRESSION;
    CHECK(mpm_plastic_init(&a, NULL) == 0 && mpm_plastic_init(&b, NULL) == 0);
    one_material("cohesive, cut-off 500 Pa, psi 0", &a, 2);
    if (t_failed()) return;
    one_material("cohesive, cut-off 500 Pa, psi 0", &a, 3);
    if (t_failed()) return;
    one_material("c 10 Pa, apex only, psi 5", &b, 2);
    if (t_failed()) return;
    one_material("c 10 Pa, apex only, psi 5", &b, 3);
    if (t_failed()) return;
    /* few substeps allowed, a tight tolerance: many updates run out of
     * substeps, some in the very substep that would finish them (the
     * scalar update refuses those too) */
    mpm_plastic_params c = a;
    c.max_substeps = 3, c.tol = 1e-6;
    CHECK(mpm_plastic_init(&c, NULL) == 0);
    one_material("cohesive, at most 3 substeps, tol 1e-6", &c, 2);
    if (t_failed()) return;
    one_material("cohesive, at most 3 substeps, tol 1e-6", &c, 3);
}
