/*
 * accuracy.c - bin/mpmbench-accuracy: error against run time for the
 * solver, on problems with known answers (bench.h).  It sweeps method
 * (MPM, GIMP), update (USF, USL, MUSL), cells per length, particles per
 * cell and dt as a fraction of the CFL limit; times every configuration as
 * the median of repeats; and reports
 *   - a table (one line per configuration, as it finishes),
 *   - build/bench/accuracy.csv (every configuration),
 *   - the observed orders: in space (error against h at a fixed Courant
 *     number, a least-squares slope over the sweep and the last pair) and
 *     in time (distance to a run with a 4x smaller dt on the same grid,
 *     against dt),
 *   - the Pareto front of each problem (the fastest configuration at each
 *     error level), where the daemon's defaults (GIMP, MUSL, C = 0.5,
 *     2 particles per cell per axis) stand against it at each resolution,
 *     and a table of every method/update pair at ppc 2, C = 0.5 against the
 *     fronts (how much slower than the front at the same error),
 *   - build/bench/accuracy.gp, a self-contained gnuplot script (data
 *     inline) for three log-log figures: error against wall time, error
 *     against cell size, time error against dt.
 * Usage: mpmbench-accuracy [--quick] [--repeats N] [--out DIR]
 *                          [--only NAME[,NAME...]]
 * Timing assertions do not exist here; it is a measurement.
 */
#include "bench.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define MAX_ENTRIES 2048
#define DEF_CFL 0.5
#define DEF_PPC 2

typedef struct {
    bench_cfg c;
    int space; /* member of the space sweep at this C */
    int time;  /* member of a time sweep */
    int ref;   /* the time sweep's reference */
    int front; /* on its problem's Pareto front */
    bench_res r;
    double wall_med, wall_min;
    int repeats;
    double terr; /* time error: distance to the reference / scale */
} entry;

static entry *E;
static int nE;
static int quick;

static int same_cfg(const bench_cfg *a, const bench_cfg *b)
{
    return a->pb == b->pb && a->method == b->method && a->update == b->update &&
           a->cells == b->cells && a->ppc == b->ppc && a->cfl == b->cfl;
}

static entry *add(bench_problem pb, mpm_method m, mpm_update u, int cells, int ppc, double cfl,
                  int space, int time, int ref)
{
    bench_cfg c = {pb, m, u, cells, ppc, cfl};
    for (int i = 0; i < nE; i++)
        if (same_cfg(&E[i].c, &c)) {
            E[i].space |= space;
            E[i].time |= time;
            E[i].ref |= ref;
            return &E[i];
        }
    if (nE == MAX_ENTRIES) {
        fprintf(stderr, "mpmbench-accuracy: more than %d configurations\n", MAX_ENTRIES);
        exit(2);
    }
    entry *e = &E[nE++];
    memset(e, 0, sizeof *e);
    e->c = c;
    e->space = space;
    e->time = time;
    e->ref = ref;
    e->terr = NAN;
    return e;
}

/* ---- the sweeps ---- */

typedef struct {
    bench_problem pb;
    int cells[8], ncells; /* space sweep */
    int ppc[4], nppc;
    double cfl[3];           /* space sweep Courant numbers (0-terminated) */
    int extra_ppc_max_cells; /* ppc other than DEF_PPC only up to this many cells */
    int tcells, tppc;        /* time sweep grid */
    double tcfl[10];         /* time sweep (0-terminated), then the reference */
    double tref;
} sweep;

static void plan_one(const sweep *s)
{
    for (int m = 0; m < 2; m++)
        for (int u = 0; u < 3; u++) {
            mpm_method meth = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
            for (int k = 0; k < 3 && s->cfl[k] > 0; k++)
                for (int i = 0; i < s->ncells; i++)
                    for (int j = 0; j < s->nppc; j++) {
                        if (s->ppc[j] != DEF_PPC && s->cells[i] > s->extra_ppc_max_cells) continue;
                        add(s->pb, meth, (mpm_update)u, s->cells[i], s->ppc[j], s->cfl[k], 1, 0, 0);
                    }
            if (s->tcells) {
                for (int k = 0; s->tcfl[k] > 0; k++)
                    add(s->pb, meth, (mpm_update)u, s->tcells, s->tppc, s->tcfl[k], 0, 1, 0);
                add(s->pb, meth, (mpm_update)u, s->tcells, s->tppc, s->tref, 0, 0, 1);
            }
        }
}

static void plan(const int *only)
{
    /* point: no grid to refine (one cell, one point) */
    sweep pt = {BP_POINT, {1}, 1, {1}, 1,
                {0},      1,   1, 1,   {1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0},
                0.00125};
    sweep bar = {
        BP_BAR, {8, 16, 32, 64, 128},          5,     {1, 2, 4}, 3, {0.5, 0.1}, 1 << 20, 32,
        2,      {0.8, 0.4, 0.2, 0.1, 0.05, 0}, 0.0125};
    sweep m1 = {
        BP_MMS1, {8, 16, 32, 64, 128, 256},     6,     {1, 2, 4}, 3, {0.5, 0.1}, 1 << 20, 32,
        2,       {0.8, 0.4, 0.2, 0.1, 0.05, 0}, 0.0125};
    sweep m2 = {BP_MMS2, {8, 16, 32, 64},         4,    {1, 2, 3}, 3, {0.5}, 32, 16,
                2,       {0.8, 0.4, 0.2, 0.1, 0}, 0.025};
    sweep m3 = {BP_MMS3, {4, 8, 16}, 3, {1, 2}, 2, {0.5}, 16, 8, 2, {0.8, 0.4, 0.2, 0}, 0.05};
    sweep dk = {BP_DISKS, {10, 20, 40, 80},        4,    {1, 2, 3}, 3, {0.5}, 40, 20,
                2,        {0.8, 0.4, 0.2, 0.1, 0}, 0.025};
    if (quick) {
        pt.tcfl[4] = 0;
        pt.tref = 0.0125;
        bar.ncells = 3;
        bar.nppc = 2;
        bar.cfl[1] = 0;
        bar.tcfl[3] = 0;
        bar.tref = 0.025;
        m1.ncells = 4;
        m1.nppc = 2;
        m1.cfl[1] = 0;
        m1.tcfl[3] = 0;
        m1.tref = 0.025;
        m2.ncells = 2;
        m2.nppc = 1;
        m2.ppc[0] = 2;
        m2.tcells = 8;
        m2.tcfl[2] = 0;
        m2.tref = 0.1;
        m3.ncells = 2;
        m3.nppc = 1;
        m3.ppc[0] = 2;
        m3.tcells = 4;
        m3.tcfl[2] = 0;
        m3.tref = 0.1;
        dk.ncells = 2;
        dk.nppc = 1;
        dk.ppc[0] = 2;
        dk.tcells = 10;
        dk.tcfl[2] = 0;
        dk.tref = 0.1;
    }
    const sweep *all[] = {&pt, &bar, &m1, &m2, &m3, &dk};
    for (int i = 0; i < 6; i++)
        if (!only || only[all[i]->pb]) plan_one(all[i]);
}

/* ---- running ---- */

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static void cfg_label(const bench_cfg *c, char *buf, size_t n)
{
    snprintf(buf, n, "%-6s %-4s %-4s cells %3d ppc %d C %-7g", bench_problem_name(c->pb),
             bench_method_name(c->method), bench_update_name(c->update), c->cells, c->ppc, c->cfl);
}

static void run_entry(entry *e, int repeats)
{
    double walls[16];
    int keep = e->time || e->ref;
    if (bench_run(&e->c, keep, &e->r)) {
        e->r.rc = MPM_EINVAL;
        e->r.err = e->r.err2 = INFINITY;
    }
    walls[0] = e->r.wall;
    int n = 1;
    /* repeats only for timing: the runs are deterministic (one thread).
     * A failed run is not repeated; runs over 5 s are timed once more at
     * most, to keep the sweep within minutes. */
    int want = e->r.rc ? 1 : e->r.wall > 5.0 ? (repeats > 2 ? 2 : repeats) : repeats;
    for (; n < want && n < 16; n++) {
        bench_res r2;
        bench_run(&e->c, 0, &r2);
        walls[n] = r2.wall;
        bench_res_free(&r2);
    }
    qsort(walls, (size_t)n, sizeof walls[0], cmp_double);
    e->repeats = n;
    e->wall_min = walls[0];
    e->wall_med = n % 2 ? walls[n / 2] : 0.5 * (walls[n / 2 - 1] + walls[n / 2]);
}

static void print_row(const entry *e)
{
    char lab[128];
    cfg_label(&e->c, lab, sizeof lab);
    if (e->r.rc)
        printf("%s %8s %9s %9s %9s  FAILED: %.90s\n", lab, "", "", "", "", e->r.msg);
    else
        printf("%s %8ld %9.3e %9.3e %9.3e\n", lab, e->r.steps, e->r.err, e->r.err2, e->wall_med);
    fflush(stdout);
}

/* ---- analysis ---- */

static void time_errors(void)
{
    for (int i = 0; i < nE; i++) {
        entry *e = &E[i];
        if (!e->time || e->r.rc || !e->r.xf) continue;
        for (int j = 0; j < nE; j++) {
            entry *f = &E[j];
            if (!f->ref || f->r.rc || !f->r.xf || f->c.pb != e->c.pb ||
                f->c.method != e->c.method || f->c.update != e->c.update ||
                f->c.cells != e->c.cells || f->c.ppc != e->c.ppc ||
                f->r.particles != e->r.particles)
                continue;
            e->terr =
                bench_rms_diff(e->r.xf, f->r.xf, e->r.particles, e->r.dim, bench_scale(e->c.pb));
        }
    }
}

/* Errors at or above this (relative) level are no solution at all (an
 * unstable run that did not reach NaN, or one that lost the answer); they
 * are left out of the order fits. */
#define ERR_USELESS 0.5

static int fit_point(double y)
{
    return y > 0 && y < ERR_USELESS;
}

/* Least-squares slope of log y against log x over the points fit_point()
 * accepts. */
static double slope(const double *x, const double *y, int n, int *used)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int k = 0;
    for (int i = 0; i < n; i++) {
        if (!fit_point(y[i])) continue;
        double a = log(x[i]), b = log(y[i]);
        sx += a;
        sy += b;
        sxx += a * a;
        sxy += a * b;
        k++;
    }
    *used = k;
    if (k < 2) return NAN;
    return (k * sxy - sx * sy) / (k * sxx - sx * sx);
}

typedef struct {
    double x[16], y[16];
    int n;
} series;

/* The space series of (pb, m, u) at ppc and cfl: x = h, y = err (or err2). */
static void space_series(bench_problem pb, mpm_method m, mpm_update u, int ppc, double cfl,
                         int second, series *s)
{
    s->n = 0;
    for (int i = 0; i < nE && s->n < 16; i++) {
        const entry *e = &E[i];
        if (!e->space || e->c.pb != pb || e->c.method != m || e->c.update != u || e->c.ppc != ppc ||
            e->c.cfl != cfl)
            continue;
        s->x[s->n] = 1.0 / e->c.cells;
        s->y[s->n] = e->r.rc ? INFINITY : second ? e->r.err2 : e->r.err;
        s->n++;
    }
}

static void time_series(bench_problem pb, mpm_method m, mpm_update u, int analytic, series *s)
{
    s->n = 0;
    for (int i = 0; i < nE && s->n < 16; i++) {
        const entry *e = &E[i];
        if (!e->time || e->c.pb != pb || e->c.method != m || e->c.update != u) continue;
        s->x[s->n] = e->r.dt > 0 ? e->r.dt : e->c.cfl;
        s->y[s->n] = e->r.rc ? INFINITY : analytic ? e->r.err : e->terr;
        s->n++;
    }
}

static void fmt_order(const series *s, char *buf, size_t n)
{
    int used;
    double p = slope(s->x, s->y, s->n, &used);
    /* last pair: the two smallest x with finite errors */
    double lp = NAN;
    int a = -1, b = -1;
    for (int i = 0; i < s->n; i++) {
        if (!fit_point(s->y[i])) continue;
        if (a < 0 || s->x[i] < s->x[a]) {
            b = a;
            a = i;
        } else if (b < 0 || s->x[i] < s->x[b]) {
            b = i;
        }
    }
    if (a >= 0 && b >= 0) lp = log(s->y[b] / s->y[a]) / log(s->x[b] / s->x[a]);
    if (used < 2)
        snprintf(buf, n, "%-13s", "-");
    else
        snprintf(buf, n, "%5.2f [%5.2f]", p, lp);
}

static const int order_ppc = DEF_PPC;

static void print_orders(const int *only)
{
    printf(
        "\n== Observed orders ==\n"
        "space: slope of log(err) against log(h) over the sweep at ppc %d and a fixed Courant "
        "number C\n       (dt = C h / c shrinks with h), [the last pair]; time: slope of the "
        "distance to a run\n       with a 4x smaller dt on the same grid against dt; time vs exact: the error against dt\n"
        "       on that grid (it stalls at the spatial error; only the point has none).  Errors\n"
        "       >= %g (no solution) are left out.  Negative: the error grows under refinement.\n\n",
        order_ppc, ERR_USELESS);
    printf("%-6s %-4s %-4s | %-13s %-13s | %-13s | %-13s %-13s\n", "", "", "", "space C=0.5",
           "space C=0.1", "space err2", "time", "time vs exact");
    for (int pb = 0; pb < BP_COUNT; pb++) {
        if (only && !only[pb]) continue;
        for (int m = 0; m < 2; m++)
            for (int u = 0; u < 3; u++) {
                series s;
                char a[32], b[32], c2[32], d[32], f[32];
                space_series((bench_problem)pb, (mpm_method)m, (mpm_update)u, order_ppc, 0.5, 0,
                             &s);
                fmt_order(&s, a, sizeof a);
                space_series((bench_problem)pb, (mpm_method)m, (mpm_update)u, order_ppc, 0.1, 0,
                             &s);
                fmt_order(&s, b, sizeof b);
                space_series((bench_problem)pb, (mpm_method)m, (mpm_update)u, order_ppc, 0.5, 1,
                             &s);
                fmt_order(&s, c2, sizeof c2);
                time_series((bench_problem)pb, (mpm_method)m, (mpm_update)u, 0, &s);
                fmt_order(&s, d, sizeof d);
                time_series((bench_problem)pb, (mpm_method)m, (mpm_update)u, 1, &s);
                fmt_order(&s, f, sizeof f);
                printf("%-6s %-4s %-4s | %-13s %-13s | %-13s | %-13s %-13s\n",
                       bench_problem_name((bench_problem)pb), bench_method_name((mpm_method)m),
                       bench_update_name((mpm_update)u), a, b, c2, d, f);
            }
    }
}

static int is_default(const bench_cfg *c)
{
    return c->method == MPM_METHOD_GIMP && c->update == MPM_MUSL && c->cfl == DEF_CFL &&
           (c->ppc == DEF_PPC || c->pb == BP_POINT);
}

static int cmp_wall(const void *a, const void *b)
{
    const entry *x = *(entry *const *)a, *y = *(entry *const *)b;
    return x->wall_med < y->wall_med ? -1 : x->wall_med > y->wall_med;
}

static void print_pareto(const int *only)
{
    static entry *list[MAX_ENTRIES];
    printf("\n== Pareto fronts: the fastest configuration at each error level (err, median wall; "
           "runs with err >= %g left out) ==\n",
           ERR_USELESS);
    for (int pb = 0; pb < BP_COUNT; pb++) {
        if (only && !only[pb]) continue;
        int n = 0;
        /* a run whose error is ERR_USELESS or more answered nothing */
        for (int i = 0; i < nE; i++)
            if ((int)E[i].c.pb == pb && !E[i].r.rc && fit_point(E[i].r.err)) list[n++] = &E[i];
        if (!n) continue;
        qsort(list, (size_t)n, sizeof list[0], cmp_wall);
        printf("\n%s (%d configurations):\n", bench_problem_name((bench_problem)pb), n);
        double best = INFINITY;
        for (int i = 0; i < n; i++) {
            if (list[i]->r.err < best) {
                best = list[i]->r.err;
                list[i]->front = 1;
                char lab[128];
                cfg_label(&list[i]->c, lab, sizeof lab);
                printf("  %9.3e  %9.3e s  %s%s\n", list[i]->r.err, list[i]->wall_med, lab,
                       is_default(&list[i]->c) ? "  <- defaults" : "");
            }
        }
        /* the daemon's defaults against the front */
        for (int i = 0; i < n; i++) {
            entry *d = list[i];
            if (!is_default(&d->c)) continue;
            double tbest = INFINITY;
            const entry *who = NULL;
            for (int j = 0; j < n; j++)
                if (list[j]->front && list[j]->r.err <= d->r.err && list[j]->wall_med < tbest) {
                    tbest = list[j]->wall_med;
                    who = list[j];
                }
            char lab[128] = "";
            if (who && who != d) cfg_label(&who->c, lab, sizeof lab);
            if (d->front)
                printf("  defaults at %3d cells: err %.3e in %.3e s: on the front\n", d->c.cells,
                       d->r.err, d->wall_med);
            else if (who)
                printf("  defaults at %3d cells: err %.3e in %.3e s: off the front, %.1fx slower "
                       "than %s\n",
                       d->c.cells, d->r.err, d->wall_med, d->wall_med / tbest, lab);
        }
    }
}

/* Time of a configuration over that of the fastest front configuration
 * whose error is no larger (1: on the front). */
static double front_factor(const entry *d)
{
    double tbest = INFINITY;
    for (int j = 0; j < nE; j++) {
        const entry *f = &E[j];
        if (f->c.pb == d->c.pb && f->front && f->r.err <= d->r.err && f->wall_med < tbest)
            tbest = f->wall_med;
    }
    return isfinite(tbest) && tbest > 0 ? fmax(d->wall_med / tbest, 1.0) : NAN;
}

/* Every method/update pair at ppc 2 and C = 0.5 (the daemon's defaults are
 * GIMP + MUSL there) against the fronts: the geometric mean over the
 * resolutions of front_factor(), and how many runs failed. */
static void print_candidates(const int *only)
{
    printf(
        "\n== Settings against the fronts (ppc 2, C = 0.5, every resolution of the space sweep): "
        "time / time of the fastest front configuration at least as accurate, geometric mean "
        "(1.0 = on the front); (n) runs that failed ==\n%-16s",
        "");
    for (int pb = 0; pb < BP_COUNT; pb++)
        if (!only || only[pb]) printf(" %-11s", bench_problem_name((bench_problem)pb));
    printf("\n");
    for (int m = 0; m < 2; m++)
        for (int u = 0; u < 3; u++) {
            char lab[32];
            snprintf(lab, sizeof lab, "%s %s%s", bench_method_name((mpm_method)m),
                     bench_update_name((mpm_update)u), m == 1 && u == 2 ? " (dflt)" : "");
            printf("%-16s", lab);
            for (int pb = 0; pb < BP_COUNT; pb++) {
                if (only && !only[pb]) continue;
                double lsum = 0;
                int n = 0, failed = 0;
                for (int i = 0; i < nE; i++) {
                    const entry *e = &E[i];
                    if ((int)e->c.pb != pb || e->c.method != (mpm_method)m ||
                        e->c.update != (mpm_update)u || e->c.cfl != DEF_CFL ||
                        !(e->space || e->c.pb == BP_POINT) ||
                        (e->c.pb != BP_POINT && e->c.ppc != DEF_PPC))
                        continue;
                    double f = e->r.rc ? NAN : front_factor(e);
                    if (isfinite(f)) {
                        lsum += log(f);
                        n++;
                    } else {
                        failed++;
                    }
                }
                char cell[32];
                if (n)
                    snprintf(cell, sizeof cell, failed ? "%.1f (%d)" : "%.1f", exp(lsum / n),
                             failed);
                else
                    snprintf(cell, sizeof cell, failed ? "fail (%d)" : "-", failed);
                printf(" %-11s", cell);
            }
            printf("\n");
        }
}

/* ---- output files ---- */

static int write_csv(const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        fprintf(stderr, "mpmbench-accuracy: %s: %s\n", path, strerror(errno));
        return -1;
    }
    fprintf(f, "problem,method,update,cells,ppc,cfl,dt,steps,particles,err,err2,err3,time_err,"
               "wall_median_s,wall_min_s,repeats,space_sweep,time_sweep,time_ref,pareto,"
               "status,message\n");
    for (int i = 0; i < nE; i++) {
        const entry *e = &E[i];
        char msg[256];
        snprintf(msg, sizeof msg, "%s", e->r.msg);
        for (char *p = msg; *p; p++)
            if (*p == '"' || *p == ',') *p = ';';
        fprintf(f,
                "%s,%s,%s,%d,%d,%g,%.6e,%ld,%zu,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%d,%d,%d,%d,%d,"
                "%s,%s\n",
                bench_problem_name(e->c.pb), bench_method_name(e->c.method),
                bench_update_name(e->c.update), e->c.cells, e->c.ppc, e->c.cfl, e->r.dt, e->r.steps,
                e->r.particles, e->r.err, e->r.err2, e->r.err3, e->terr, e->wall_med, e->wall_min,
                e->repeats, e->space, e->time, e->ref, e->front,
                e->r.rc ? mpm_strerror(e->r.rc) : "ok", msg);
    }
    return fclose(f);
}

static const char *const series_style[6] = {"lc rgb '#1f77b4' pt 7", "lc rgb '#2ca02c' pt 5",
                                            "lc rgb '#9467bd' pt 9", "lc rgb '#d62728' pt 6",
                                            "lc rgb '#ff7f0e' pt 4", "lc rgb '#8c564b' pt 8"};

/* One panel: six series (method x update) of (x, y) pairs from the entries
 * selected by kind (0: all runs err vs wall; 1: space sweep C=0.5 ppc 2,
 * err vs h; 2: time sweep, time error vs dt), plus the front for kind 0. */
static void gp_panel(FILE *f, bench_problem pb, int kind, const char *title)
{
    int any = 0, cnt[6] = {0};
    for (int s = 0; s < 6; s++) {
        fprintf(f, "$d%d_%d_%d << EOD\n", pb, kind, s);
        series sr = {{0}, {0}, 0};
        if (kind == 1)
            space_series(pb, (mpm_method)(s / 3), (mpm_update)(s % 3), order_ppc, 0.5, 0, &sr);
        if (kind == 2) time_series(pb, (mpm_method)(s / 3), (mpm_update)(s % 3), 0, &sr);
        if (kind == 0) {
            for (int i = 0; i < nE; i++) {
                const entry *e = &E[i];
                if (e->c.pb != pb || e->c.method != (mpm_method)(s / 3) ||
                    e->c.update != (mpm_update)(s % 3) || e->r.rc || !(e->r.err > 0))
                    continue;
                fprintf(f, "%.6e %.6e\n", e->wall_med, e->r.err);
                any = cnt[s] = 1;
            }
        } else {
            for (int i = 0; i < sr.n; i++)
                if (sr.y[i] > 0 && isfinite(sr.y[i])) {
                    fprintf(f, "%.6e %.6e\n", sr.x[i], sr.y[i]);
                    any = cnt[s] = 1;
                }
        }
        fprintf(f, "EOD\n");
    }
    if (kind == 0) {
        static entry *list[MAX_ENTRIES];
        int n = 0;
        for (int i = 0; i < nE; i++)
            if (E[i].c.pb == pb && E[i].front) list[n++] = &E[i];
        qsort(list, (size_t)n, sizeof list[0], cmp_wall);
        fprintf(f, "$f%d << EOD\n", pb);
        for (int i = 0; i < n; i++) fprintf(f, "%.6e %.6e\n", list[i]->wall_med, list[i]->r.err);
        fprintf(f, "EOD\n");
    }
    fprintf(f, "set title '%s'\n", title);
    if (!any) {
        fprintf(f, "unset logscale\nset xrange [0:1]\nset yrange [0:1]\n"
                   "plot 2 notitle\nset logscale xy\nset autoscale\n");
        return;
    }
    fprintf(f, "plot ");
    for (int s = 0, first = 1; s < 6; s++) {
        if (!cnt[s]) continue;
        fprintf(f, "%s$d%d_%d_%d using 1:2 with %s %s title '%s %s'", first ? "" : ", ", pb, kind,
                s, kind ? "linespoints" : "points", series_style[s],
                bench_method_name((mpm_method)(s / 3)), bench_update_name((mpm_update)(s % 3)));
        first = 0;
    }
    if (kind == 0) fprintf(f, ", $f%d using 1:2 with steps lc rgb 'black' dt 2 title 'front'", pb);
    fprintf(f, "\n");
}

static int write_gnuplot(const char *dir, const int *only)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/accuracy.gp", dir);
    FILE *f = fopen(path, "w");
    if (!f) {
        fprintf(stderr, "mpmbench-accuracy: %s: %s\n", path, strerror(errno));
        return -1;
    }
    fprintf(f,
            "# written by mpmbench-accuracy: gnuplot %s makes accuracy_{time,space,dt}.png "
            "in %s\n",
            path, dir);
    fprintf(f, "set terminal pngcairo size 1200,760 font ',8'\nset logscale xy\n"
               "set format x '10^{%%L}'\nset format y '10^{%%L}'\nset grid\n");
    static const char *const what[3] = {"time", "space", "dt"};
    static const char *const xl[3] = {"median wall time of a run (s)", "cell size h",
                                      "time step dt"};
    static const char *const yl[3] = {"error", "error (C = 0.5, ppc 2)",
                                      "distance to the reference run"};
    for (int k = 0; k < 3; k++) {
        fprintf(f, "set output '%s/accuracy_%s.png'\n", dir, what[k]);
        fprintf(f, "set multiplot layout 2,3 title '%s'\n",
                k == 0   ? "error against run time (all configurations; dashed: Pareto front)"
                : k == 1 ? "error against cell size at a fixed Courant number"
                         : "time convergence on a fixed grid");
        /* the empty corner: fast and accurate (bottom left) does not
         * happen; coarse and accurate (top left) neither */
        fprintf(f, "set xlabel '%s'\nset ylabel '%s'\nset key %s font ',7'\n", xl[k], yl[k],
                k == 0 ? "bottom left" : "top left");
        for (int pb = 0; pb < BP_COUNT; pb++) {
            if (only && !only[pb]) continue;
            if (k == 1 && pb == BP_POINT) continue;
            char title[128];
            snprintf(title, sizeof title, "%s", bench_problem_name((bench_problem)pb));
            gp_panel(f, (bench_problem)pb, k, title);
        }
        fprintf(f, "unset multiplot\n");
    }
    return fclose(f);
}

static int parse_only(const char *s, int *only)
{
    char buf[256];
    snprintf(buf, sizeof buf, "%s", s);
    for (char *tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
        int found = 0;
        for (int pb = 0; pb < BP_COUNT; pb++)
            if (!strcmp(tok, bench_problem_name((bench_problem)pb))) only[pb] = found = 1;
        if (!found) {
            fprintf(stderr,
                    "mpmbench-accuracy: --only: unknown problem '%s' (point, bar, mms1d, "
                    "mms2d, mms3d, disks)\n",
                    tok);
            return -1;
        }
    }
    return 0;
}

int main(int argc, char **argv)
{
    const char *out = "build/bench";
    int repeats = 3, use_only = 0, only[BP_COUNT] = {0};
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--quick")) {
            quick = 1;
        } else if (!strcmp(argv[i], "--repeats") && i + 1 < argc) {
            repeats = atoi(argv[++i]);
            if (repeats < 1 || repeats > 15) {
                fprintf(stderr, "mpmbench-accuracy: --repeats: 1..15\n");
                return 2;
            }
        } else if (!strcmp(argv[i], "--out") && i + 1 < argc) {
            out = argv[++i];
        } else if (!strcmp(argv[i], "--only") && i + 1 < argc) {
            if (parse_only(argv[++i], only)) return 2;
            use_only = 1;
        } else {
            printf("usage: %s [--quick] [--repeats N] [--out DIR] [--only NAME[,NAME...]]\n"
                   "  sweeps method, update, cells, ppc and dt/CFL on problems with known answers\n"
                   "  (point, bar, mms1d, mms2d, mms3d, disks); writes DIR/accuracy.csv and\n"
                   "  DIR/accuracy.gp (default DIR: build/bench)\n",
                   argv[0]);
            return strcmp(argv[i], "--help") && strcmp(argv[i], "-h") ? 2 : 0;
        }
    }
    if (quick && repeats == 3) repeats = 1;
    if (mkdir(out, 0755) && errno != EEXIST) {
        fprintf(stderr, "mpmbench-accuracy: mkdir %s: %s\n", out, strerror(errno));
        return 1;
    }
    E = calloc(MAX_ENTRIES, sizeof *E);
    if (!E) {
        fprintf(stderr, "mpmbench-accuracy: out of memory\n");
        return 1;
    }
    char msg[256];
    int st = bench_force_selftest(msg, sizeof msg);
    printf("%s\n", msg);
    if (st) {
        fprintf(
            stderr,
            "mpmbench-accuracy: mpm_sim_set_particle_forces does not match public point loads; the "
            "manufactured solutions would be wrong\n");
        free(E);
        return 1;
    }
    const int *sel = use_only ? only : NULL;
    plan(sel);
    printf("%d configurations, %d repeats each for timing (median), one solver thread\n\n", nE,
           repeats);
    printf("%-6s %-4s %-4s %-9s %-5s %-9s %8s %9s %9s %9s\n", "", "", "", "", "", "", "steps",
           "err", "err2", "wall (s)");
    double t0 = bench_now();
    for (int i = 0; i < nE; i++) {
        run_entry(&E[i], repeats);
        print_row(&E[i]);
    }
    time_errors();
    print_orders(sel);
    print_pareto(sel);
    print_candidates(sel);
    char path[1024];
    snprintf(path, sizeof path, "%s/accuracy.csv", out);
    int rc = write_csv(path);
    if (!rc) printf("\nwrote %s", path);
    if (!rc && !(rc = write_gnuplot(out, sel))) printf(" and %s/accuracy.gp", out);
    printf(" (%.0f s in all)\n", bench_now() - t0);
    for (int i = 0; i < nE; i++) bench_res_free(&E[i].r);
    free(E);
    return rc ? 1 : 0;
}
