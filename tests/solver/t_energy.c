/*
 * t_energy.c - the extended energy balance, its budget, and damping
 * at the solver's level: the paper's GIMP MUSL bar at half the
 * CFL limit that gains energy is caught by the budget; a vibrating bar
 * under local and under viscous damping loses its energy while the balance
 * K + S + D_damping stays closed; the case fields are checked.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "mpm.h"
#include "mpm_paper.h"
#include "t.h"

#define V0 0.1

/* The bar of the paper (E 10, rho 1, L 1, first mode, v0 0.1) with ncell
 * cells of one point and 10 empty cells beyond its free end, dt a fraction of the CFL
 * limit h / (c + v0); energies every `every` steps over nsteps.  Returns
 * the simulation (NULL on failure) with *e0 the initial energies and *e
 * the last. */
static mpm_sim *bar_run(mpm_method m, mpm_update up, int ncell, double frac, long nsteps,
                        long every, double budget, mpm_damping_kind damp, double coef,
                        mpm_energy *e0, mpm_energy *e)
{
    mpm_paper t;
    mpm_error err;
    double h = 1.0 / ncell, dt = frac * h / (sqrt(10.0) + V0);
    if (mpm_paper_bar(&t, m, up, ncell, 1, 10, dt, V0)) return NULL;
    t.c.energy_budget = budget;
    t.c.damping = damp;
    t.c.damping_coef = coef;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    mpm_paper_free(&t);
    if (!s) {
        printf("    %s\n", TERR(&err));
        return NULL;
    }
    mpm_sim_energy(s, e0);
    *e = *e0;
    for (long i = 0; i < nsteps; i++) {
        if (mpm_sim_step(s)) {
            printf("    %s\n", TERR(mpm_sim_error(s)));
            mpm_sim_destroy(&s);
            return NULL;
        }
        if ((i + 1) % every == 0) mpm_sim_energy(s, e);
    }
    mpm_sim_energy(s, e);
    return s;
}

/* GIMP MUSL, 13 cells of one point, dt half the CFL limit (accepted
 * without allow_unstable_dt), 8000 steps: it runs to the end with the
 * total energy at 1.85 E0 (with the 10 empty cells here), under the
 * divergence guard's 2 E0, so only the energy balance catches it: the 5 %
 * budget is exceeded; the same bar with MPM USF, which keeps its energy, is within it. */
TEST(energy_bar_budget_catches_gimp_musl_gain)
{
    mpm_energy e0, e;
    mpm_sim *s =
        bar_run(MPM_METHOD_GIMP, MPM_MUSL, 13, 0.5, 8000, 100, 0.05, MPM_DAMPING_NONE, 0, &e0, &e);
    CHECK(s != NULL);
    double worst;
    char msg[256];
    int over = mpm_sim_budget(s, NULL, &worst, msg, sizeof msg);
    TLOG("GIMP MUSL bar, 13 cells x 1 point, C 0.5, 8000 steps: total %.4f E0, balance error "
         "%.4f at the end, %.4f at worst; %s",
         e.total / e0.total, e.balance_error, worst, over ? msg : "within budget");
    CHECK(mpm_sim_check(s) == 0); /* the guard (2 E0) lets it pass, as before */
    CHECK(e.total > 1.5 * e0.total);
    /* E_ref = E0 here (no loads, no gravity): the error is total/E0 - 1 */
    CHECK_NEAR(e.balance_error, e.total / e0.total - 1, 1e-12);
    CHECK(over == 1);
    CHECK(worst >= e.balance_error);
    CHECK(strstr(msg, "energy_budget") != NULL);
    mpm_sim_destroy(&s);

    s = bar_run(MPM_METHOD_MPM, MPM_USF, 7, 0.1, 2000, 100, 0.05, MPM_DAMPING_NONE, 0, &e0, &e);
    CHECK(s != NULL);
    over = mpm_sim_budget(s, NULL, &worst, msg, sizeof msg);
    TLOG("MPM USF bar, 7 cells, C 0.1, 2000 steps: balance error %.2e at worst", worst);
    CHECK(over == 0);
    CHECK_LT(worst, 0.05);
    CHECK(msg[0] == 0);
    mpm_sim_destroy(&s);
}

/* Damping takes the bar's energy and the balance closes with it:
 * K + S + D_damping stays E0.  Mass-proportional viscous damping at rate c
 * makes every mode's energy fall as exp(-c t) (x'' + c x' + w^2 x = 0,
 * averaged over the oscillation; c / w = 0.2 here leaves a ripple: 10 %).
 * The balance error is that of the scheme itself while the bar moves
 * (undamped, the MPM USF bar's total oscillates by 1.9 % within a period:
 * the particles' strain energy against the grid's) and must be small once
 * it is at rest: at the end, within 0.5 %. */
TEST(energy_damping_dissipates_and_balance_closes)
{
    static const struct {
        mpm_method m;
        mpm_update up;
        int ncell;
        const char *name;
    } ms[] = {{MPM_METHOD_MPM, MPM_USF, 7, "MPM USF"}, {MPM_METHOD_GIMP, MPM_USL, 13, "GIMP USL"}};
    for (size_t i = 0; i < sizeof ms / sizeof ms[0]; i++) {
        double period = 2 * M_PI / mpm_paper_bar_omega();
        double h = 1.0 / ms[i].ncell, dt = 0.2 * h / (sqrt(10.0) + V0);
        long n = lround(2 * period / dt);
        mpm_energy e0, e;
        /* viscous: c = 1/s over two periods (t = 1.6 s): E / E0 ~ exp(-1.6) */
        mpm_sim *s = bar_run(ms[i].m, ms[i].up, ms[i].ncell, 0.2, n, 10, 0.05, MPM_DAMPING_VISCOUS,
                             1.0, &e0, &e);
        CHECK(s != NULL);
        double worst, t = mpm_sim_time(s);
        mpm_sim_budget(s, NULL, &worst, NULL, 0);
        double kept = (e.kinetic + e.strain) / e0.total;
        TLOG("%s viscous c = 1/s, t = %.3f s: (K + S) / E0 = %.4f (exp(-c t) = %.4f), damping "
             "work %.4f E0, balance error %.2e at the end, %.2e at worst",
             ms[i].name, t, kept, exp(-t), e.damping_work / e0.total, e.balance_error, worst);
        CHECK(e.damping_work > 0);
        CHECK_NEAR(kept, exp(-t), 0.1 * exp(-t));
        CHECK_LT(worst, 0.03);
        CHECK_LT(e.balance_error, 0.005);
        mpm_sim_destroy(&s);

        /* local (Cundall), alpha 0.2 */
        s = bar_run(ms[i].m, ms[i].up, ms[i].ncell, 0.2, n, 10, 0.05, MPM_DAMPING_LOCAL, 0.2, &e0,
                    &e);
        CHECK(s != NULL);
        mpm_sim_budget(s, NULL, &worst, NULL, 0);
        kept = (e.kinetic + e.strain) / e0.total;
        TLOG("%s local alpha 0.2, two periods: (K + S) / E0 = %.4f, damping work %.4f E0, "
             "balance error %.2e at the end, %.2e at worst",
             ms[i].name, kept, e.damping_work / e0.total, e.balance_error, worst);
        CHECK(e.damping_work > 0.3 * e0.total);
        CHECK_LT(kept, 0.7);
        CHECK_LT(worst, 0.03);
        CHECK_LT(e.balance_error, 0.01);
        mpm_sim_destroy(&s);
    }
}

TEST(energy_case_fields_checked)
{
    mpm_paper t;
    mpm_error err;
    struct {
        mpm_damping_kind k;
        double coef, until, budget;
        const char *field;
    } bad[] = {
        {MPM_DAMPING_LOCAL, 1.0, 0, 0, "damping.coefficient"},
        {MPM_DAMPING_LOCAL, -0.1, 0, 0, "damping.coefficient"},
        {MPM_DAMPING_VISCOUS, INFINITY, 0, 0, "damping.coefficient"},
        {(mpm_damping_kind)7, 0.1, 0, 0, "damping.kind"},
        {MPM_DAMPING_VISCOUS, 1, -1, 0, "damping.until"},
        {MPM_DAMPING_NONE, 0, 0, -0.01, "energy_budget"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        CHECK(mpm_paper_bar(&t, MPM_METHOD_MPM, MPM_USF, 7, 1, 0, 1e-3, V0) == 0);
        t.c.damping = bad[i].k;
        t.c.damping_coef = bad[i].coef;
        t.c.damping_until = bad[i].until;
        t.c.energy_budget = bad[i].budget;
        int rc = mpm_case_check(&t.c, NULL, &err);
        mpm_paper_free(&t);
        char f[128];
        mpm_error_field(&err, MPM_FIELD_PROTO, f, sizeof f);
        CHECKF(rc == MPM_EINVAL && strcmp(f, bad[i].field) == 0, "case %zu: %d %s", i, rc, f);
    }
}

/* Damping on the thread team: the node passes split the nodes among the
 * threads and each sums its damping work, added in thread order, so two
 * runs with 2 threads give the same bits, and 1 thread the same values to
 * round-off (the scatter sums change order). */
TEST(energy_damping_threads)
{
    double res[3][3];
    for (int k = 0; k < 3; k++) {
        mpm_paper t;
        mpm_error err;
        mpm_paper_disks(&t, MPM_METHOD_GIMP, MPM_USF, 0.05);
        t.c.threads = k == 0 ? 1 : 2;
        t.c.damping = k == 2 ? MPM_DAMPING_VISCOUS : MPM_DAMPING_LOCAL;
        t.c.damping_coef = 0.5;
        mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
        mpm_paper_free(&t);
        CHECKF(s, "%s", TERR(&err));
        CHECK(mpm_sim_run(s, 100) == 0);
        mpm_energy e;
        mpm_sim_energy(s, &e);
        res[k][0] = e.damping_work;
        res[k][1] = e.kinetic;
        res[k][2] = e.balance_error;
        mpm_sim_destroy(&s);
        TLOG("disks, GIMP USF, %s damping, %d thread(s), 100 steps: damping work %.10e, K "
             "%.10e, balance error %.2e",
             k == 2 ? "viscous" : "local", k == 0 ? 1 : 2, res[k][0], res[k][1], res[k][2]);
        CHECK(e.damping_work > 0 && e.balance_error < 0.05);
    }
    CHECK_NEAR(res[1][0], res[0][0], 1e-12 * res[0][0]);
    CHECK_NEAR(res[1][1], res[0][1], 1e-12 * res[0][1]);
    /* a second 2-thread run: the same bits */
    mpm_paper t;
    mpm_error err;
    mpm_paper_disks(&t, MPM_METHOD_GIMP, MPM_USF, 0.05);
    t.c.threads = 2;
    t.c.damping = MPM_DAMPING_LOCAL;
    t.c.damping_coef = 0.5;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    mpm_paper_free(&t);
    CHECKF(s, "%s", TERR(&err));
    CHECK(mpm_sim_run(s, 100) == 0);
    mpm_energy e;
    mpm_sim_energy(s, &e);
    mpm_sim_destroy(&s);
    CHECK(e.damping_work == res[1][0] && e.kinetic == res[1][1]);
}
