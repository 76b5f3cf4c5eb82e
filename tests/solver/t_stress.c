/*
 * t_stress.c - the stability stress suite.  Every case ends in
 * one of two outcomes, and the test asserts which: a result within
 * tolerance, or a failure the solver (or the daemon) recorded with a clear
 * reason ("diverged at step N", "particle P left the grid at step N", "dt
 * above the CFL limit", a step limit).  None may crash, hang (every run has
 * a step budget) or leave a NaN behind.
 * How it works: the notes after the includes.
 */
#include "t_stress.h"
#include "mpm.h"
#include "mpm_paper.h"
#include "t.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/*
 *  stress_cfl_sweep        Courant factor 0.05..1.5 per method (MPM, GIMP,
 *                          BSPLINE2, BSPLINE3) and update on
 *                          the 1D bar (full mode: also 2D and 3D standing
 *                          waves, and the paper's amplitude, where points
 *                          cross cells); stable = finished, mean energy over
 *                          the last of 10 periods <= 1.01 x the first's; the
 *                          largest stable factor (and the largest without a
 *                          blow-up) against the solver's refusal of cfl > 1
 *                          and of a given dt above the limit.
 *  stress_long_runs        energy drift per period of the bar and of the
 *                          disks in a box, USF/USL/MUSL (full mode: 10^6
 *                          steps, and 10^5 of the fine disks).
 *  stress_cell_crossing    a 2D block translating across many cells, rigid
 *                          and carrying a standing wave, beside a copy at
 *                          rest: the spurious stress, MPM against GMPM.
 *  (stress_extremes, stress_daemon_extremes: t_stress_extremes.c)
 *
 * `make test` runs the quick form (a few seconds under the sanitizers);
 * `make stress` sets MPM_STRESS=full for the whole sweep.  Each test prints
 * the figures it measured (TLOG); docs/accuracy.md quotes them.
 */

static const char *mname(mpm_method m)
{
    return m == MPM_METHOD_GIMP       ? "GIMP"
           : m == MPM_METHOD_BSPLINE2 ? "BSP2"
           : m == MPM_METHOD_BSPLINE3 ? "BSP3"
                                      : "MPM";
}

static const char *upd_name(mpm_update u)
{
    return u == MPM_USL ? "USL" : u == MPM_MUSL ? "MUSL" : "USF";
}

/* ---- standing waves for the CFL sweep ---- */

/* A case with explicit points that owns its arrays. */
typedef struct {
    mpm_case c;
    mpm_material_desc mat;
    mpm_body_desc b;
    double *x, *vol, *v;
    double period;
} wave;

static void wave_free(wave *w)
{
    free(w->x);
    free(w->vol);
    free(w->v);
    memset(w, 0, sizeof *w);
}

/* dim 1: the paper's bar (E = 10, fixed at x = 0, free end, first mode)
 * with 16 cells of 2 points.  dim 2, 3: the unit square/cube, 16 (2D) or
 * 4 (3D) cells of 2x2(x2) points, rollers on every face, v_d = v0
 * sin(pi x_d) (period 2 / c), E = 1, nu = 0.3.  Plus a 1e-6 v0
 * pseudo-random perturbation so that an unstable mode has something to
 * grow from.  Automatic dt with Courant factor C.  v0 = 1e-3: no particle
 * crosses a cell boundary (the linear stability limit); v0 = 0.1 (the
 * paper's amplitude): displacements of 0.3-0.4 h, so points cross. */
static int wave_case(wave *w, int dim, mpm_method m, mpm_update u, double C, int allow, double v0)
{
    memset(w, 0, sizeof *w);
    int cells = dim == 1 ? 16 : dim == 2 ? 16 : 4, ppc = 2, per = cells * ppc;
    size_t n = (size_t)per * (dim > 1 ? per : 1) * (dim > 2 ? per : 1);
    double h = 1.0 / cells;
    w->x = malloc(n * dim * sizeof *w->x);
    w->vol = malloc(n * sizeof *w->vol);
    w->v = malloc(n * dim * sizeof *w->v);
    if (!w->x || !w->vol || !w->v) {
        wave_free(w);
        return -1;
    }
    uint64_t rng = 88172645463325252ull;
    for (size_t p = 0; p < n; p++) {
        size_t rest = p;
        w->vol[p] = pow(h / ppc, dim);
        for (int d = 0; d < dim; d++) {
            double X = ((double)(rest % (size_t)per) + 0.5) / per;
            rest /= (size_t)per;
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            double noise = 1e-6 * v0 * ((double)(rng >> 11) / 9007199254740992.0 - 0.5);
            w->x[p * dim + d] = X;
            w->v[p * dim + d] = (dim == 1 ? v0 * sin(M_PI / 2 * X) : v0 * sin(M_PI * X)) + noise;
        }
    }
    w->mat = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                 .youngs_modulus = dim == 1 ? 10.0 : 1.0,
                                 .poisson_ratio = dim == 1 ? 0 : 0.3,
                                 .density = 1.0};
    w->b.n_points = n;
    w->b.x = w->x;
    w->b.volume = w->vol;
    w->b.v = w->v;
    w->c.grid.dim = dim;
    for (int d = 0; d < dim; d++) {
        w->c.grid.h[d] = h;
        w->c.grid.nodes[d] = cells + 1 + (dim == 1 ? 2 : 0);
        w->c.bc.face_mask[2 * d] = 1u << d;
        if (dim > 1) w->c.bc.face_mask[2 * d + 1] = 1u << d;
    }
    w->c.method = m;
    w->c.update = u;
    w->c.cfl = C;
    w->c.allow_unstable_dt = allow;
    w->c.n_materials = 1;
    w->c.materials = &w->mat;
    w->c.n_bodies = 1;
    w->c.bodies = &w->b;
    double c = mpm_material_wave_speed(&w->mat, dim);
    w->period = dim == 1 ? 2 * M_PI / (M_PI / 2 * c) : 2.0 / c;
    return 0;
}

typedef struct {
    int rc;      /* 0 or MPM_E* */
    int stable;  /* the definition: finished, growth <= 1% */
    int bounded; /* finished and never above 2 E0: no blow-up */
    long steps;
    double growth; /* mean E over the last period / over the first - 1 */
    double end;    /* E at the end / E0 */
    char msg[300];
} cfl_out;

static void cfl_run(int dim, mpm_method m, mpm_update u, double C, double v0, cfl_out *o)
{
    wave w;
    mpm_error err;
    memset(o, 0, sizeof *o);
    if (wave_case(&w, dim, m, u, C, 1, v0)) {
        o->rc = MPM_ENOMEM;
        snprintf(o->msg, sizeof o->msg, "out of memory");
        return;
    }
    mpm_sim *s = mpm_sim_new(&w.c, NULL, &err);
    double period = w.period, tend = 10 * period;
    wave_free(&w);
    if (!s) {
        o->rc = MPM_EINVAL;
        snprintf(o->msg, sizeof o->msg, "%s", TERR(&err));
        return;
    }
    mpm_energy e0, e;
    mpm_sim_energy(s, &e0);
    /* budget: 3x the steps the initial dt needs; an unstable run's dt
     * collapses as its speed grows, and that must not become a hang */
    long budget = 3 * (long)ceil(tend / mpm_sim_dt(s)) + 10, every = budget / 3000 + 1;
    /* growth: the mean energy over the last period against the first, so
     * that the bounded O(omega dt) oscillation of K + S within a period is
     * not taken for growth; a sample above 2 E0 counts as blown up */
    double first = e0.total, last = 0, peak = e0.total;
    long nfirst = 1, nlast = 0;
    while (mpm_sim_time(s) < tend) {
        if (mpm_sim_steps(s) >= budget) {
            o->rc = MPM_EDIVERGED;
            snprintf(o->msg, sizeof o->msg,
                     "step budget %ld spent at t = %.4g of %.4g (dt fell to "
                     "%.3g: the speed grew)",
                     budget, mpm_sim_time(s), tend, mpm_sim_dt(s));
            break;
        }
        if ((o->rc = mpm_sim_step(s))) {
            snprintf(o->msg, sizeof o->msg, "%s", TERR(mpm_sim_error(s)));
            break;
        }
        if (mpm_sim_steps(s) % every == 0) {
            double t = mpm_sim_time(s);
            mpm_sim_energy(s, &e);
            if (!(e.total <= peak)) peak = e.total; /* NaN sticks */
            if (t <= period) {
                first += e.total;
                nfirst++;
            } else if (t >= tend - period) {
                last += e.total;
                nlast++;
            }
        }
    }
    /* as the daemon does before it reports a run finished */
    if (!o->rc && (o->rc = mpm_sim_check(s)))
        snprintf(o->msg, sizeof o->msg, "%s", TERR(mpm_sim_error(s)));
    mpm_sim_energy(s, &e);
    o->end = e.total / e0.total;
    o->growth = nlast ? (last / nlast) / (first / nfirst) - 1 : 0;
    o->bounded = o->rc == 0 && peak <= 2 * e0.total;
    if (!o->bounded && !o->rc) o->growth = peak / e0.total - 1;
    o->steps = mpm_sim_steps(s);
    o->stable = o->bounded && o->growth <= 0.01;
    mpm_sim_destroy(&s);
}

TEST(stress_cfl_sweep)
{
    static const double full_c[] = {0.05, 0.1,  0.2, 0.3,  0.4, 0.5, 0.6, 0.7, 0.8,
                                    0.9,  0.95, 1.0, 1.05, 1.1, 1.2, 1.3, 1.4, 1.5};
    static const double quick_c[] = {0.1, 0.5, 0.9, 1.0, 1.1, 1.5};
    int full = t_stress_full(), nc = full ? 18 : 6, maxdim = full ? 3 : 1;
    const double *cs = full ? full_c : quick_c;
    TLOG(
        "Courant factor C of the automatic dt = C h / (c + |v|max) over 10 periods.  Stable "
        "(the issue's definition): finished, mean energy of the last period <= 1.01 x that of "
        "the first.  '.' stable; 'g' finished, grew by more than 1%% but stayed below 2 E0 "
        "(drift); 'b' finished below 2 E0 but went above it on the way; 'X' finished above 2 "
        "E0 (a blow-up the solver did not flag: asserted never); "
        "'D' diverged (the divergence guard or a NaN) or its dt collapsed; 'L' a particle left the grid");
    char hdr[256] = "", *hp = hdr;
    for (int k = 0; k < nc; k++) hp += snprintf(hp, sizeof hdr - (size_t)(hp - hdr), "%5g", cs[k]);
    for (int big = 0; big <= full; big++) {
        double v0 = big ? 0.1 : 1e-3;
        TLOG("v0 = %g (%s):", v0,
             big ? "the paper's amplitude, points cross cells" : "no cell crossing");
        TLOG("%-14s %s   largest stable C / without blow-up", "", hdr);
        for (int dim = 1; dim <= maxdim; dim++)
            for (int m = 0; m < 4; m++) /* MPM, GIMP, BSPLINE2, BSPLINE3 */
                for (int u = 0; u < 3; u++) {
                    mpm_method meth = (mpm_method)m;
                    char row[128] = "", *rp = row, first_fail[400] = "";
                    double largest = 0, largest_b = 0;
                    int all_stable_so_far = 1, all_bounded_so_far = 1, default_ok = 1;
                    for (int k = 0; k < nc; k++) {
                        cfl_out o;
                        cfl_run(dim, meth, (mpm_update)u, cs[k], v0, &o);
                        /* never anything but a finished run or a recorded failure */
                        CHECKF(o.rc == 0 || o.rc == MPM_EDIVERGED || o.rc == MPM_ELEFTGRID,
                               "%dD %s %s C=%g: rc %d (%s)", dim, mname(meth),
                               upd_name((mpm_update)u), cs[k], o.rc, o.msg);
                        CHECKF(o.rc == 0 || strlen(o.msg) > 10, "failure without a reason");
                        char mark = o.stable                ? '.'
                                    : o.rc == MPM_ELEFTGRID ? 'L'
                                    : o.rc                  ? 'D'
                                    : o.end > 2             ? 'X'
                                    : o.bounded             ? 'g'
                                                            : 'b';
                        rp += snprintf(rp, sizeof row - (size_t)(rp - row), "%5c", mark);
                        /* the divergence guard: a blow-up is a recorded failure */
                        CHECKF(mark != 'X',
                               "%dD %s %s C=%g finished at %.3g E0 without a failure (%ld steps)",
                               dim, mname(meth), upd_name((mpm_update)u), cs[k], o.end, o.steps);
                        if (o.stable && all_stable_so_far) largest = cs[k];
                        if (o.bounded && all_bounded_so_far) largest_b = cs[k];
                        all_bounded_so_far &= o.bounded;
                        if (!o.stable && all_stable_so_far) {
                            all_stable_so_far = 0;
                            snprintf(first_fail, sizeof first_fail, "first unstable C=%g: %s",
                                     cs[k], o.rc ? o.msg : "energy grew");
                            if (!o.rc)
                                snprintf(first_fail, sizeof first_fail,
                                         "first unstable C=%g: energy +%.3g%%", cs[k],
                                         100 * o.growth);
                        }
                        if (cs[k] == MPM_DEFAULT_CFL) default_ok = o.stable;
                    }
                    TLOG("%dD %-4s %-4s   %s   %g / %g%s%s", dim, mname(meth),
                         upd_name((mpm_update)u), row, largest, largest_b,
                         first_fail[0] ? "; " : "", first_fail);
                    /* the solver's default (0.5) must be safe wherever the
                     * scheme is stable at all (without cell crossing) */
                    /* Not asserted: 3D B-splines with USF.  The 3D wave has 4
                     * cells, the B-splines' coarsest (the clamped spans are half
                     * the grid), and the mean energy of the last period grows
                     * +1.9% over the first's from C = 0.2 (MPM and GIMP: from
                     * 0.7); a drift, not an instability: over 40 periods at
                     * C = 0.5 BSPLINE2 reaches +5.0% against GIMP's +7.0%, and
                     * with 8 cells +2.1% against GIMP's +2.2% (docs/solver.md). */
                    int bs3usf = dim == 3 && u == MPM_USF &&
                                 (meth == MPM_METHOD_BSPLINE2 || meth == MPM_METHOD_BSPLINE3);
                    if (!big && !(meth == MPM_METHOD_MPM && u == MPM_USL) && !bs3usf)
                        CHECKF(default_ok, "%dD %s %s is not stable at the default C = 0.5", dim,
                               mname(meth), upd_name((mpm_update)u));
                }
    }
    /* the refusal: cfl > 1 and a given dt above the limit, unless allowed */
    for (int dim = 1; dim <= 2; dim++) {
        wave w;
        mpm_error err;
        CHECK(wave_case(&w, dim, MPM_METHOD_MPM, MPM_USF, 1.05, 0, 1e-3) == 0);
        int rc = mpm_case_check(&w.c, NULL, &err);
        CHECKF(rc == MPM_ECFL && strstr(TERR(&err), "cfl: 1.05 is above the stability limit 1"),
               "rc %d: %s", rc, TERR(&err));
        w.c.cfl = 1.0;
        CHECK(mpm_case_check(&w.c, NULL, &err) == 0);
        mpm_sim *s = mpm_sim_new(&w.c, NULL, &err);
        CHECKF(s, "%s", TERR(&err));
        double lim = mpm_sim_dt_limit(s);
        mpm_sim_destroy(&s);
        w.c.cfl = 0;
        w.c.dt = 1.01 * lim;
        rc = mpm_case_check(&w.c, NULL, &err);
        CHECKF(rc == MPM_ECFL && strstr(TERR(&err), "above the CFL limit"), "rc %d: %s", rc,
               TERR(&err));
        TLOG("%dD refusal: cfl 1.05 -> \"cfl: 1.05 is above the stability limit 1; ...\"; "
             "dt = 1.01 x limit -> \"%.60s...\"",
             dim, TERR(&err));
        w.c.dt = 0.99 * lim;
        CHECK(mpm_case_check(&w.c, NULL, &err) == 0);
        wave_free(&w);
    }
    /* USL: the sweep finds it unstable from C = 0.6, so the refusal starts
     * above MPM_USL_MAX_CFL = 0.5, for a Courant factor and a given dt */
    {
        wave w;
        mpm_error err;
        CHECK(wave_case(&w, 1, MPM_METHOD_GIMP, MPM_USL, 0.6, 0, 1e-3) == 0);
        int rc = mpm_case_check(&w.c, NULL, &err);
        CHECKF(rc == MPM_ECFL &&
                   strstr(TERR(&err), "cfl: 0.6 is above the stability limit 0.5 of USL"),
               "rc %d: %s", rc, TERR(&err));
        w.c.cfl = 0.5;
        CHECKF(mpm_case_check(&w.c, NULL, &err) == 0, "%s", TERR(&err));
        mpm_sim *s = mpm_sim_new(&w.c, NULL, &err);
        CHECKF(s, "%s", TERR(&err));
        double lim = mpm_sim_dt_limit(s);
        mpm_sim_destroy(&s);
        w.c.cfl = 0;
        w.c.dt = 0.51 * lim;
        rc = mpm_case_check(&w.c, NULL, &err);
        CHECKF(rc == MPM_ECFL && strstr(TERR(&err), "(USL)"), "rc %d: %s", rc, TERR(&err));
        TLOG("USL refusal: cfl 0.6 -> \"cfl: 0.6 is above the stability limit 0.5 of USL; ...\"; "
             "dt = 0.51 x h/(c+|v|) -> \"%.80s...\"",
             TERR(&err));
        w.c.dt = 0.49 * lim;
        CHECKF(mpm_case_check(&w.c, NULL, &err) == 0, "%s", TERR(&err));
        w.c.allow_unstable_dt = 1;
        w.c.dt = 0;
        w.c.cfl = 0.9;
        CHECKF(mpm_case_check(&w.c, NULL, &err) == 0, "%s", TERR(&err));
        wave_free(&w);
    }
}

/* ---- long runs ---- */

typedef struct {
    int rc;
    long steps;
    double t, e0, emin, emax;
    double first, last; /* mean energy over the first and the last window */
    char msg[300];
} long_out;

/* nsteps steps; the energy is sampled about 32 times per window of
 * `window` steps, and averaged over the first and the last window (so the
 * bounded oscillation within a period does not read as drift). */
static void long_run(mpm_sim *s, long nsteps, long window, long_out *o)
{
    memset(o, 0, sizeof *o);
    mpm_energy e;
    mpm_sim_energy(s, &e);
    o->e0 = o->emin = o->emax = e.total;
    long every = window / 32 > 1 ? window / 32 : 1, nf = 0, nl = 0;
    for (long i = 0; i < nsteps; i += every) {
        long k = i + every <= nsteps ? every : nsteps - i;
        if ((o->rc = mpm_sim_run(s, k))) {
            snprintf(o->msg, sizeof o->msg, "%s", TERR(mpm_sim_error(s)));
            break;
        }
        mpm_sim_energy(s, &e);
        o->emin = fmin(o->emin, e.total);
        o->emax = fmax(o->emax, e.total);
        long at = mpm_sim_steps(s);
        if (at <= window) {
            o->first += e.total;
            nf++;
        }
        if (at > nsteps - window) {
            o->last += e.total;
            nl++;
        }
    }
    o->first = nf ? o->first / nf : o->e0;
    o->last = nl ? o->last / nl : NAN;
    o->steps = mpm_sim_steps(s);
    o->t = mpm_sim_time(s);
}

TEST(stress_long_runs)
{
    int full = t_stress_full();
    long nbar = full ? 1000000 : 20000, ndisk = full ? 100000 : 3000;
    double T = 2 * M_PI / mpm_paper_bar_omega();
    long wbar = lround(T / 1e-3);
    TLOG("bar (the paper's: MPM 7 cells, GMPM 13 cells, 1 point each, v0 = 0.1, dt = 1e-3), "
         "%ld steps = %.0f periods; drift = mean E over the last period / over the first - 1:",
         nbar, nbar * 1e-3 / T);
    for (int m = 0; m < 2; m++)
        for (int u = 0; u < 3; u++) {
            mpm_paper t;
            mpm_error err;
            mpm_method meth = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
            CHECK(mpm_paper_bar(&t, meth, (mpm_update)u, m ? 13 : 7, 1, 1, 1e-3, 0.1) == 0);
            mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
            mpm_paper_free(&t);
            CHECKF(s, "%s", TERR(&err));
            long_out o;
            long_run(s, nbar, wbar, &o);
            mpm_sim_destroy(&s);
            double periods = o.t / T - 1, drift = o.last / o.first - 1;
            if (o.rc)
                TLOG("  %-4s %-4s FAILED after %.0f periods, E in [%.4f, %.4f] E0: %s", mname(meth),
                     upd_name((mpm_update)u), periods, o.emin / o.e0, o.emax / o.e0, o.msg);
            else
                TLOG("  %-4s %-4s ok: drift %+.3e, per period %+.3e; E in [%.4f, %.4f] E0",
                     mname(meth), upd_name((mpm_update)u), drift, drift / fmax(periods, 1e-300),
                     o.emin / o.e0, o.emax / o.e0);
            CHECKF(o.rc == 0 || strlen(o.msg) > 10, "failure without a reason");
            /* finished, or a recorded failure (measured: GMPM + USL's free
             * end point drifts off the grid after 172 periods, at 16% of
             * E0); a finished run never doubles its energy */
            CHECKF(o.rc == 0 || o.rc == MPM_ELEFTGRID || o.rc == MPM_EDIVERGED, "rc %d", o.rc);
            CHECKF(o.rc || (isfinite(o.last) && o.emax < 2 * o.e0), "%s %s: E max %g E0",
                   mname(meth), upd_name((mpm_update)u), o.emax / o.e0);
            /* over the quick run (16 periods) USF and MUSL keep the energy
             * within 1%; over 791 periods GMPM + MUSL does not (measured
             * +64%, growing from period 500 on): reported, not asserted */
            if (!full && u != MPM_USL)
                CHECKF(o.rc == 0 && drift < 0.01, "%s %s: drift %g %s", mname(meth),
                       upd_name((mpm_update)u), drift, o.msg);
            if (full && !o.rc && drift > 0.01)
                TLOG("    ^ KNOWN ISSUE (not asserted): the energy grew by %.3g%% over the run",
                     100 * drift);
        }
    double h = full ? 0.025 : 0.1;
    TLOG("disks (%s, the paper's, dt = 1e-3) in a box with roller walls, %ld steps (t = %g); "
         "drift = mean E over the last time unit / over the first - 1:",
         full ? "fine, 392 points each" : "coarse, 24 points each", ndisk, ndisk * 1e-3);
    for (int m = 0; m < 2; m++)
        for (int u = 0; u < 3; u++) {
            mpm_paper t;
            mpm_error err;
            mpm_method meth = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
            mpm_paper_disks(&t, meth, (mpm_update)u, h);
            t.c.dt = 1e-3;
            for (int f = 0; f < 4; f++) t.c.bc.face_mask[f] = 1u << (f / 2);
            mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
            mpm_paper_free(&t);
            CHECKF(s, "%s", TERR(&err));
            long_out o;
            long_run(s, ndisk, 1000, &o);
            mpm_sim_destroy(&s);
            double drift = o.last / o.first - 1;
            if (o.rc)
                TLOG("  %-4s %-4s FAILED at t = %.4g, E in [%.4f, %.4f] E0: %.150s", mname(meth),
                     upd_name((mpm_update)u), o.t, o.emin / o.e0, o.emax / o.e0, o.msg);
            else
                TLOG("  %-4s %-4s ok: drift %+.3e, per unit time %+.3e; E in [%.4f, %.4f] E0",
                     mname(meth), upd_name((mpm_update)u), drift, drift / fmax(o.t - 1, 1e-300),
                     o.emin / o.e0, o.emax / o.e0);
            if (full && !o.rc && drift > 0.01)
                TLOG("    ^ KNOWN ISSUE (not asserted): the energy grew by %.3g%% over the run",
                     100 * drift);
            CHECKF(o.rc == 0 || o.rc == MPM_EDIVERGED || o.rc == MPM_ELEFTGRID, "rc %d", o.rc);
            CHECKF(o.rc == 0 || strlen(o.msg) > 10, "failure without a reason");
            CHECK(isfinite(o.emax));
        }
}

/* ---- cell-crossing noise ---- */

/* A 2D block of L x H = 8h x 4h, nu = 0 (uniaxial: the free-free 1D bar
 * is exact), ppc x ppc points per cell, no boundary conditions.  Two
 * copies are stepped in lockstep with the same dt: one at rest, one moving
 * at (V, V/2), V = 0.2 c, across 20 cells; both carry the free-free first
 * mode v = v0 cos(pi X / L) cos(omega t) along x, omega = pi c / L, so
 * sigma_xx = -rho c v0 sin(pi X / L) sin(omega t), smooth in time.  The
 * spurious stress is the time noise of each point's sigma_xx (noise()):
 * at rest it is the smooth (omega dt)^2 part, and what the moving copy adds
 * is what crossing cells does.  With v0 = 0 the moving copy is a rigid
 * translation whose exact stress is zero (reported as max |sigma|).
 * Stresses are divided by rho c v0 (or rho c V when v0 = 0); maxima over
 * time. */
typedef struct {
    int rc;
    double rest;  /* time noise of sigma_xx of the copy at rest */
    double cross; /* the same for the copy that crosses cells (rigid: max |sigma|) */
    double amp;   /* RMS |sigma_xx - exact| at rest (the mode's phase and amplitude error) */
    double other; /* max |sigma_yy|, |sigma_xy| of the moving copy */
    double moved; /* cells travelled */
    char msg[300];
} cross_out;

/* Time noise of sigma_xx: the RMS over particles of the second difference
 * sigma(t + dt) - 2 sigma(t) + sigma(t - dt).  A smooth history gives
 * (omega dt)^2 sigma; a stress that jumps when a point crosses a cell
 * boundary gives the jump. */
static double noise(const double *s0, const double *s1, const double *s2, size_t n)
{
    double r2 = 0;
    for (size_t p = 0; p < n; p++) {
        double d = s2[6 * p] - 2 * s1[6 * p] + s0[6 * p];
        r2 += d * d;
    }
    return sqrt(r2 / (double)n);
}

static mpm_sim *block_sim(mpm_method m, mpm_update u, double V, double v0, int ppc, double dt,
                          mpm_error *err)
{
    const int nx = 8, ny = 4, travel = 20;
    double h = 1.0 / 32, L = nx * h;
    int px = nx * ppc, py = ny * ppc;
    size_t n = (size_t)px * py;
    double *x = malloc(2 * n * sizeof *x), *vol = malloc(n * sizeof *vol),
           *v = malloc(2 * n * sizeof *v);
    mpm_sim *s = NULL;
    if (!x || !vol || !v) {
        mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
        goto out;
    }
    for (int j = 0; j < py; j++)
        for (int i = 0; i < px; i++) {
            size_t p = (size_t)j * px + i;
            double X = (i + 0.5) * h / ppc;
            x[2 * p] = 2 * h + X;
            x[2 * p + 1] = 2 * h + (j + 0.5) * h / ppc;
            vol[p] = h * h / (ppc * ppc);
            v[2 * p] = V + v0 * cos(M_PI * X / L);
            v[2 * p + 1] = 0.5 * V;
        }
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 1.0,
                             .poisson_ratio = 0.0,
                             .density = 1.0};
    mpm_body_desc b = {0};
    b.n_points = n;
    b.x = x;
    b.volume = vol;
    b.v = v;
    mpm_case cs = {0};
    cs.grid = (mpm_grid_desc){2, {0, 0}, {h, h}, {nx + travel + 6, ny + travel / 2 + 6}};
    cs.method = m;
    cs.update = u;
    cs.dt = dt;
    cs.n_materials = 1;
    cs.materials = &mat;
    cs.n_bodies = 1;
    cs.bodies = &b;
    s = mpm_sim_new(&cs, NULL, err);
out:
    free(x);
    free(vol);
    free(v);
    return s;
}

static void crossing(mpm_method m, mpm_update u, double v0, int ppc, cross_out *o)
{
    memset(o, 0, sizeof *o);
    const double h = 1.0 / 32, L = 8 * h, c = 1.0, V = 0.2 * c, w = M_PI * c / L;
    double dt = 0.4 * h / (c + 1.2 * V), tend = 20 * h / V, scale = c * (v0 > 0 ? v0 : V);
    mpm_error err;
    mpm_sim *a = block_sim(m, u, 0.0, v0, ppc, dt, &err),
            *b = a ? block_sim(m, u, V, v0, ppc, dt, &err) : NULL;
    size_t n = a ? mpm_sim_particles(a) : 0;
    /* stress histories: sa[k], sb[k] hold steps i - 2 + k (ring of 3) */
    double *sa[3], *sb[3], *x0 = malloc(2 * n * sizeof *x0 + 1),
                           *x1 = malloc(2 * n * sizeof *x1 + 1);
    int okm = x0 && x1;
    for (int k = 0; k < 3; k++) {
        sa[k] = calloc(6 * n + 1, sizeof(double));
        sb[k] = calloc(6 * n + 1, sizeof(double));
        okm &= sa[k] && sb[k];
    }
    if (!a || !b || !okm) {
        o->rc = MPM_EINVAL;
        snprintf(o->msg, sizeof o->msg, "%s", a && b ? "out of memory" : TERR(&err));
        goto out;
    }
    mpm_sim_snapshot(b, &(mpm_snapshot){.x = x0});
    while (mpm_sim_time(b) < tend) {
        int ra = mpm_sim_step(a), rb = mpm_sim_step(b);
        if (ra || rb) {
            o->rc = ra ? ra : rb;
            snprintf(o->msg, sizeof o->msg, "%s%s", ra ? "at rest: " : "",
                     TERR(mpm_sim_error(ra ? a : b)));
            break;
        }
        double *ta = sa[0], *tb = sb[0];
        sa[0] = sa[1], sa[1] = sa[2], sa[2] = ta;
        sb[0] = sb[1], sb[1] = sb[2], sb[2] = tb;
        mpm_sim_snapshot(a, &(mpm_snapshot){.stress = sa[2]});
        mpm_sim_snapshot(b, &(mpm_snapshot){.stress = sb[2], .x = x1});
        long k = mpm_sim_steps(a);
        double t = mpm_sim_time(a), r2 = 0, oth = 0, big = 0;
        for (size_t p = 0; p < n; p++) {
            double X = x0[2 * p] - 2 * h, ex = -c * v0 * sin(M_PI * X / L) * sin(w * t);
            r2 += (sa[2][6 * p] - ex) * (sa[2][6 * p] - ex);
            oth = fmax(oth, fmax(fabs(sb[2][6 * p + 1]), fabs(sb[2][6 * p + 3])));
            big = fmax(big, fabs(sb[2][6 * p]));
        }
        o->amp = fmax(o->amp, sqrt(r2 / (double)n) / scale);
        if (v0 == 0) {
            o->cross = fmax(o->cross, big / scale);
        } else if (k >= 3) {
            o->rest = fmax(o->rest, noise(sa[0], sa[1], sa[2], n) / scale);
            o->cross = fmax(o->cross, noise(sb[0], sb[1], sb[2], n) / scale);
        }
        o->other = fmax(o->other, oth / scale);
        o->moved = (x1[0] - x0[0]) / h;
    }
    if (!(o->cross < INFINITY) && !o->rc) {
        o->rc = MPM_EDIVERGED;
        snprintf(o->msg, sizeof o->msg, "stress not finite");
    }
out:
    mpm_sim_destroy(&a);
    mpm_sim_destroy(&b);
    for (int k = 0; k < 3; k++) {
        free(sa[k]);
        free(sb[k]);
    }
    free(x0);
    free(x1);
}

TEST(stress_cell_crossing)
{
    int full = t_stress_full();
    TLOG("2D block 8h x 4h, nu = 0, 2x2 points per cell, one copy at rest and one moving at "
         "(0.2 c, 0.1 c) across 20 cells, same dt; spurious sigma_xx = RMS over points of its "
         "second difference in time, over rho c v0; max over time");
    TLOG("%-9s | %-20s | %-10s %-10s %-9s | %-9s %-9s", "", "rigid translation", "at rest",
         "crossing", "ratio", "mode err", "yy, xy");
    for (int m = 0; m < 2; m++)
        for (int u = 0; u < 3; u++) {
            mpm_method meth = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
            mpm_update up = (mpm_update)u;
            cross_out r, tr;
            crossing(meth, up, 0.0, 2, &r);   /* rigid translation: exact stress 0 */
            crossing(meth, up, 1e-3, 2, &tr); /* the wave, at rest and crossing */
            char a[64], b[64];
            snprintf(a, sizeof a, r.rc ? "FAILED" : "|sigma| <= %.1e", fmax(r.cross, r.other));
            snprintf(b, sizeof b, tr.rc ? "FAILED" : "%.3e", tr.cross);
            TLOG("%-4s %-4s | %-20s | %-10.3e %-10s %-9.1f | %-9.3e %-9.1e%s%.140s", mname(meth),
                 upd_name(up), a, tr.rest, b, tr.rc ? 0.0 : tr.cross / tr.rest, tr.amp, tr.other,
                 r.rc || tr.rc ? " : " : "", r.rc ? r.msg : tr.msg);
            for (const cross_out *q = &r; q; q = q == &r ? &tr : NULL) {
                CHECKF(q->rc == 0 || q->rc == MPM_EDIVERGED || q->rc == MPM_ELEFTGRID, "rc %d %s",
                       q->rc, q->msg);
                CHECKF(q->rc == 0 || strlen(q->msg) > 10, "failure without a reason");
            }
            /* rigid translation is exact to round-off with every method and
             * update, as docs/accuracy.md states (measured <= 5.1e-15: phantom
             * nodes take the interpolated velocity in the gradient) */
            CHECKF(r.rc == 0 && r.cross < 1e-14 && r.other < 1e-14, "%s %s translation: %g %g %s",
                   mname(meth), upd_name(up), r.cross, r.other, r.msg);
            /* GMPM's point: crossing cells adds little noise (measured
             * 1.1x the smooth level at rest; MPM 3-7x, USL 119x) */
            if (meth == MPM_METHOD_GIMP)
                CHECKF(tr.rc == 0 && tr.cross < 2 * tr.rest,
                       "GIMP %s: crossing noise %g, at rest %g", upd_name(up), tr.cross, tr.rest);
        }
    if (full)
        for (int ppc = 1; ppc <= 4; ppc++)
            for (int m = 0; m < 2; m++)
                for (int u = 0; u < 3; u += 2) {
                    cross_out tr;
                    mpm_method meth = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
                    crossing(meth, (mpm_update)u, 1e-3, ppc, &tr);
                    TLOG("  ppc %d %-4s %-4s: noise at rest %.3e, crossing %.3e (%.1fx)%s%s", ppc,
                         mname(meth), upd_name((mpm_update)u), tr.rest, tr.cross,
                         tr.cross / tr.rest, tr.rc ? " FAILED: " : "", tr.msg);
                }
}
