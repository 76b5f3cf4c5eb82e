/*
 * accuracy.c - bin/mpmbench-accuracy: error against run time for the
 * solver, on problems with known answers (bench.h).  It sweeps the
 * schemes -- method (the table bench_methods[]: MPM, GIMP, and B-splines
 * and CPDI once merged), update (USF, USL, MUSL) and velocity transfer
 * (bench_transfers[]: FLIP, PIC, and APIC once merged) -- with cells per
 * length, particles per cell and dt as a fraction of the CFL limit, as deep
 * as sweep_depth() says for each scheme; times every configuration as the
 * median of repeats; and reports
 *   - a table (one line per configuration, as it finishes),
 *   - build/bench/accuracy.csv (every configuration),
 *   - the observed orders per scheme: in space (error against h at a fixed
 *     Courant number, a least-squares slope over the sweep and the last
 *     pair) and in time (distance to a run with a 4x smaller dt on the same
 *     grid, against dt), and the order of every refinement pair,
 *   - the Pareto front of each problem (the fastest configuration at each
 *     error level), where the daemon's defaults (BSPLINE2, MUSL, FLIP, C = 0.5,
 *     2 particles per cell per axis) stand against it at each resolution,
 *     a table of every scheme at ppc 2, C = 0.5 against the fronts (how
 *     much slower than the front at the same error, and its worst problem),
 *     and the defaults' ratio per problem against the aim (DEF_AIM, 1.5),
 *   - the spinning disk's angular momentum and kinetic energy changes,
 *   - build/bench/accuracy.gp, a self-contained gnuplot script (data
 *     inline) for three log-log figures: error against wall time, error
 *     against cell size, time error against dt.
 * Usage: mpmbench-accuracy [--quick] [--extended] [--repeats N] [--out DIR]
 *                          [--only PROBLEM,...] [--methods NAME,...]
 *                          [--transfers NAME,...]
 * Timing assertions do not exist here; it is a measurement.
 */
#include "bench.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#define MAX_ENTRIES 8192
#define DEF_CFL 0.5
#define DEF_PPC 2
/* the daemon's defaults (proto/mpmd.proto, MPM_DEFAULT_CFL) */
#define DEF_METHOD MPM_METHOD_BSPLINE2
#define DEF_UPDATE MPM_MUSL
#define DEF_TRANSFER BT_FLIP
/* the issue-10 aim: the defaults within this factor of the fastest
 * configuration at least as accurate, on every problem */
#define DEF_AIM 1.5

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
static int quick, extended;
/* command-line selections (0: left out) */
static int sel_method[16], sel_transfer[8];

/* ---- schemes: (method row, update, transfer row) as one index ---- */

#define MAX_SCHEMES (16 * 3 * 8)

static int n_schemes(void)
{
    return bench_n_methods * 3 * bench_n_transfers;
}

static int scheme_of(const bench_cfg *c)
{
    return (bench_method_index(c->method) * 3 + (int)c->update) * bench_n_transfers + c->transfer;
}

static void scheme_split(int s, int *mi, int *u, int *t)
{
    *t = s % bench_n_transfers;
    *u = s / bench_n_transfers % 3;
    *mi = s / bench_n_transfers / 3;
}

static void scheme_label(int s, char *buf, size_t n)
{
    int mi, u, t;
    scheme_split(s, &mi, &u, &t);
    snprintf(buf, n, "%s %s %s", bench_methods[mi].name, bench_update_name((mpm_update)u),
             bench_transfers[t].name);
}

static int scheme_is_default(int s)
{
    int mi, u, t;
    scheme_split(s, &mi, &u, &t);
    return bench_methods[mi].value == (int)DEF_METHOD && u == (int)DEF_UPDATE && t == DEF_TRANSFER;
}

static int same_cfg(const bench_cfg *a, const bench_cfg *b)
{
    return a->pb == b->pb && a->method == b->method && a->update == b->update &&
           a->transfer == b->transfer && a->cells == b->cells && a->ppc == b->ppc &&
           a->cfl == b->cfl;
}

static entry *add(const bench_cfg *proto, int cells, int ppc, double cfl, int space, int time,
                  int ref)
{
    bench_cfg c = *proto;
    c.cells = cells;
    c.ppc = ppc;
    c.cfl = cfl;
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

enum { DEPTH_NONE = 0, DEPTH_REDUCED = 1, DEPTH_FULL = 2 };

/* How deep a scheme is swept.  FULL: the whole sweep (every ppc and C of
 * the space sweep, the time sweep); REDUCED: the space sweep at ppc 2 and
 * C = 0.5 only (the orders, the pairs, the front and the defaults table
 * need no more).  The rules aim at `make bench-accuracy` within about 10
 * minutes with every method enabled (MPM and GIMP alone: about
 * 3 minutes; a GIMP-cost scheme costs about 32 s in full, 14 s reduced and
 * 4 s on the spinning disk):
 *   - FLIP: MPM and GIMP in full with every update;
 *     the new methods in full with MUSL (the defaults' update), reduced
 *     with USL, not with USF (first order in time: at C = 0.5 its space
 *     orders are time-limited);
 *   - PIC (pic_fraction = 1): MPM and GIMP, reduced, MUSL only (the blend
 *     does not depend on the shape function);
 *   - APIC: every method, reduced, MUSL;
 *   - the spinning disk (what APIC is for), its one sweep: MPM and GIMP
 *     with every update and transfer; the new methods with FLIP and APIC
 *     (USL, MUSL) and PIC (MUSL).
 * Edit here to trade time for coverage. */
static int sweep_depth(bench_problem pb, int mi, int u, int t)
{
    if (!bench_methods[mi].enabled || !bench_transfers[t].enabled || !sel_method[mi] ||
        !sel_transfer[t])
        return DEPTH_NONE;
    int classic = bench_methods[mi].value == (int)MPM_METHOD_MPM ||
                  bench_methods[mi].value == (int)MPM_METHOD_GIMP;
    if (pb == BP_SPIN) {
        if (classic) return DEPTH_FULL;
        if (t == BT_PIC) return u == MPM_MUSL ? DEPTH_FULL : DEPTH_NONE;
        return u != MPM_USF ? DEPTH_FULL : DEPTH_NONE;
    }
    switch (t) {
    case BT_FLIP:
        if (classic || u == MPM_MUSL) return DEPTH_FULL;
        return u == MPM_USL ? DEPTH_REDUCED : DEPTH_NONE;
    case BT_PIC: return classic && u == MPM_MUSL ? DEPTH_REDUCED : DEPTH_NONE;
    case BT_APIC: return u == MPM_MUSL ? DEPTH_REDUCED : DEPTH_NONE;
    default: return DEPTH_NONE;
    }
}

static void plan_one(const sweep *s)
{
    for (int mi = 0; mi < bench_n_methods; mi++)
        for (int u = 0; u < 3; u++)
            for (int t = 0; t < bench_n_transfers; t++) {
                int depth = sweep_depth(s->pb, mi, u, t);
                if (depth == DEPTH_NONE) continue;
                bench_cfg c = {s->pb, (mpm_method)bench_methods[mi].value, (mpm_update)u, t, 0, 0,
                               0};
                for (int k = 0; k < 3 && s->cfl[k] > 0; k++)
                    for (int i = 0; i < s->ncells; i++)
                        for (int j = 0; j < s->nppc; j++) {
                            if (s->ppc[j] != DEF_PPC && s->cells[i] > s->extra_ppc_max_cells)
                                continue;
                            if (depth == DEPTH_REDUCED &&
                                ((s->ppc[j] != DEF_PPC && s->pb != BP_POINT) ||
                                 s->cfl[k] != DEF_CFL))
                                continue;
                            add(&c, s->cells[i], s->ppc[j], s->cfl[k], 1, 0, 0);
                        }
                if (s->tcells && depth == DEPTH_FULL) {
                    for (int k = 0; s->tcfl[k] > 0; k++)
                        add(&c, s->tcells, s->tppc, s->tcfl[k], 0, 1, 0);
                    add(&c, s->tcells, s->tppc, s->tref, 0, 0, 1);
                }
            }
}

static void plan(const int *only)
{
    /* point: no grid to refine (one cell, one point) */
    sweep pt = {BP_POINT, {1}, 1, {1}, 1,
                {0.5},    1,   1, 1,   {1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0},
                0.00125};
    sweep bar = {
        BP_BAR, {8, 16, 32, 64, 128},          5,     {1, 2, 4}, 3, {0.5, 0.1}, 1 << 20, 32,
        2,      {0.8, 0.4, 0.2, 0.1, 0.05, 0}, 0.0125};
    /* mms1d: 128 and 256 cells are the pairs where uGIMP fails today (the
     * amplitude A = 0.02 is 2.6 and 5.1 cells there) */
    sweep m1 = {
        BP_MMS1, {8, 16, 32, 64, 128, 256},     6,     {1, 2, 4}, 3, {0.5, 0.1}, 1 << 20, 32,
        2,       {0.8, 0.4, 0.2, 0.1, 0.05, 0}, 0.0125};
    /* mms2d: GIMP MUSL's last pair 32 -> 64 went negative; --extended adds
     * 128 cells (2.6 cells of displacement) */
    sweep m2 = {BP_MMS2, {8, 16, 32, 64},         4,    {1, 2, 3}, 3, {0.5}, 32, 16,
                2,       {0.8, 0.4, 0.2, 0.1, 0}, 0.025};
    /* mms3d: 16 cells is 0.32 cells of displacement; --extended adds 32 */
    sweep m3 = {BP_MMS3, {4, 8, 16}, 3, {1, 2}, 2, {0.5}, 16, 8, 2, {0.8, 0.4, 0.2, 0}, 0.05};
    sweep dk = {BP_DISKS, {10, 20, 40, 80},        4,    {1, 2, 3}, 3, {0.5}, 40, 20,
                2,        {0.8, 0.4, 0.2, 0.1, 0}, 0.025};
    sweep sp = {BP_SPIN, {16, 32, 64}, 3, {2}, 1, {0.5}, 0, 0, 0, {0}, 0};
    /* column: cells over the height l0 = 50; the top moves 1.0 m, 1.3
     * cells at 64 cells, 5 at 256 */
    sweep col = {BP_COLUMN, {8, 16, 32, 64, 128, 256}, 6, {1, 2, 4}, 3, {0.5}, 64, 0, 0, {0}, 0};
    if (extended) {
        m2.cells[m2.ncells++] = 128;
        m3.cells[m3.ncells++] = 32;
    }
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
        sp.ncells = 2;
        col.ncells = 3;
        col.nppc = 1;
        col.ppc[0] = 2;
    }
    const sweep *all[] = {&pt, &bar, &m1, &m2, &m3, &dk, &sp, &col};
    for (int i = 0; i < (int)(sizeof all / sizeof all[0]); i++)
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
    snprintf(buf, n, "%-6s %-5s %-4s %-4s cells %3d ppc %d C %-7g", bench_problem_name(c->pb),
             bench_method_name(c->method), bench_update_name(c->update),
             bench_transfer_name(c->transfer), c->cells, c->ppc, c->cfl);
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
     * A failed run is not repeated; runs over 0.5 s are timed once more at
     * most and runs over 1 s only once, to keep the sweep within minutes
     * (the long runs, whose timing noise is smallest, dominate it). */
    int want = e->r.rc || e->r.wall > 1.0 ? 1
               : e->r.wall > 0.5          ? (repeats > 2 ? 2 : repeats)
                                          : repeats;
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
                f->c.transfer != e->c.transfer || f->c.cells != e->c.cells ||
                f->c.ppc != e->c.ppc || f->r.particles != e->r.particles)
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

/* An answer at all (fronts, the defaults table): zero counts, e.g. an
 * angular momentum conserved to the last bit. */
static int usable(double y)
{
    return y >= 0 && y < ERR_USELESS;
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

/* The space series of (pb, scheme sc) at ppc and cfl, in the order of the
 * sweep (coarse to fine): x = h, y = err (or err2). */
static void space_series(bench_problem pb, int sc, int ppc, double cfl, int second, series *s)
{
    s->n = 0;
    for (int i = 0; i < nE && s->n < 16; i++) {
        const entry *e = &E[i];
        if (!e->space || e->c.pb != pb || scheme_of(&e->c) != sc || e->c.ppc != ppc ||
            e->c.cfl != cfl)
            continue;
        s->x[s->n] = 1.0 / e->c.cells;
        s->y[s->n] = e->r.rc ? INFINITY : second ? e->r.err2 : e->r.err;
        s->n++;
    }
}

static void time_series(bench_problem pb, int sc, int analytic, series *s)
{
    s->n = 0;
    for (int i = 0; i < nE && s->n < 16; i++) {
        const entry *e = &E[i];
        if (!e->time || e->c.pb != pb || scheme_of(&e->c) != sc) continue;
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

/* Whether any entry of (pb, scheme) exists. */
static int scheme_ran(int pb, int sc)
{
    for (int i = 0; i < nE; i++)
        if ((int)E[i].c.pb == pb && scheme_of(&E[i].c) == sc) return 1;
    return 0;
}

static void print_orders(const int *only)
{
    printf(
        "\n== Observed orders ==\n"
        "space: slope of log(err) against log(h) over the sweep at ppc %d and a fixed Courant "
        "number C\n       (dt = C h / c shrinks with h), [the last pair]; time: slope of the "
        "distance to a run\n       with a 4x smaller dt on the same grid against dt; time vs "
        "exact: the error against dt\n"
        "       on that grid (it stalls at the spatial error; only the point has none).  Errors\n"
        "       >= %g (no solution) are left out.  Negative: the error grows under refinement.\n\n",
        order_ppc, ERR_USELESS);
    printf("%-6s %-15s | %-13s %-13s | %-13s | %-13s %-13s\n", "", "", "space C=0.5", "space C=0.1",
           "space err2", "time", "time vs exact");
    for (int pb = 0; pb < BP_COUNT; pb++) {
        if (only && !only[pb]) continue;
        for (int sc = 0; sc < n_schemes(); sc++) {
            if (!scheme_ran(pb, sc)) continue;
            series s;
            char a[32], b[32], c2[32], d[32], f[32], lab[48];
            space_series((bench_problem)pb, sc, order_ppc, 0.5, 0, &s);
            fmt_order(&s, a, sizeof a);
            space_series((bench_problem)pb, sc, order_ppc, 0.1, 0, &s);
            fmt_order(&s, b, sizeof b);
            space_series((bench_problem)pb, sc, order_ppc, 0.5, 1, &s);
            fmt_order(&s, c2, sizeof c2);
            time_series((bench_problem)pb, sc, 0, &s);
            fmt_order(&s, d, sizeof d);
            time_series((bench_problem)pb, sc, 1, &s);
            fmt_order(&s, f, sizeof f);
            scheme_label(sc, lab, sizeof lab);
            printf("%-6s %-15s | %-13s %-13s | %-13s | %-13s %-13s\n",
                   bench_problem_name((bench_problem)pb), lab, a, b, c2, d, f);
        }
    }
}

/* The order of every refinement pair of the space sweep (ppc 2, C = 0.5),
 * coarse to fine, and the smallest of them: the issue-10 bar is an order
 * of at least 1.5 on every pair of mms2d and mms3d for the quadratic
 * B-spline.  A pair with an error >= ERR_USELESS on either side is "x". */
static void print_pairs(const int *only)
{
    printf("\n== Orders per refinement pair (space sweep, ppc %d, C = %g; cells coarse -> fine; "
           "x: an error >= %g; exact: an error of 0) ==\n",
           order_ppc, DEF_CFL, ERR_USELESS);
    for (int pb = 0; pb < BP_COUNT; pb++) {
        if ((only && !only[pb]) || pb == BP_POINT) continue;
        int header = 0;
        for (int sc = 0; sc < n_schemes(); sc++) {
            series s;
            space_series((bench_problem)pb, sc, order_ppc, DEF_CFL, 0, &s);
            if (s.n < 2) continue;
            /* coarse to fine: x = h decreasing */
            for (int i = 1; i < s.n; i++)
                for (int j = i; j > 0 && s.x[j] > s.x[j - 1]; j--) {
                    double tx = s.x[j], ty = s.y[j];
                    s.x[j] = s.x[j - 1];
                    s.y[j] = s.y[j - 1];
                    s.x[j - 1] = tx;
                    s.y[j - 1] = ty;
                }
            if (!header) {
                printf("%-6s %-15s |", bench_problem_name((bench_problem)pb), "");
                for (int i = 1; i < s.n; i++) printf(" %3.0f>%-4.0f", 1 / s.x[i - 1], 1 / s.x[i]);
                printf(" | min\n");
                header = 1;
            }
            char lab[48];
            scheme_label(sc, lab, sizeof lab);
            printf("%-6s %-15s |", "", lab);
            double mn = INFINITY;
            for (int i = 1; i < s.n; i++) {
                if (s.y[i - 1] == 0 || s.y[i] == 0) {
                    printf(" %8s", "exact"); /* no order: an error of zero */
                    continue;
                }
                if (!fit_point(s.y[i - 1]) || !fit_point(s.y[i])) {
                    printf(" %8s", "x");
                    mn = -INFINITY;
                    continue;
                }
                double o = log(s.y[i] / s.y[i - 1]) / log(s.x[i] / s.x[i - 1]);
                printf(" %8.2f", o);
                mn = fmin(mn, o);
            }
            if (isfinite(mn))
                printf(" | %5.2f\n", mn);
            else
                printf(" | %5s\n", mn > 0 ? "exact" : "x");
        }
    }
}

/* The spinning disk: the signed relative changes of the angular momentum
 * and the kinetic energy after half a revolution, every scheme and grid. */
static void print_spin(const int *only)
{
    if (only && !only[BP_SPIN]) return;
    printf("\n== Spinning disk (radius 0.2, rim speed 0.03 c, half a revolution, ppc 2, C = 0.5): "
           "dL/L0 and dK/K0 ==\n%-15s",
           "");
    int cells[8], nc = 0;
    for (int i = 0; i < nE; i++) {
        if (E[i].c.pb != BP_SPIN) continue;
        int k = 0;
        while (k < nc && cells[k] != E[i].c.cells) k++;
        if (k == nc && nc < 8) cells[nc++] = E[i].c.cells;
    }
    for (int k = 0; k < nc; k++) printf(" | %-21d", cells[k]);
    printf("\n");
    for (int sc = 0; sc < n_schemes(); sc++) {
        if (!scheme_ran(BP_SPIN, sc)) continue;
        char lab[48];
        scheme_label(sc, lab, sizeof lab);
        printf("%-15s", lab);
        for (int k = 0; k < nc; k++) {
            const entry *e = NULL;
            for (int i = 0; i < nE; i++)
                if (E[i].c.pb == BP_SPIN && scheme_of(&E[i].c) == sc && E[i].c.cells == cells[k] &&
                    E[i].c.ppc == DEF_PPC && E[i].c.cfl == DEF_CFL)
                    e = &E[i];
            if (!e)
                printf(" | %-21s", "-");
            else if (e->r.rc)
                printf(" | %-21s", "failed");
            else
                printf(" | %+10.3e %+10.3e", e->r.dL, e->r.dK);
        }
        printf("\n");
    }
}

static int is_default(const bench_cfg *c)
{
    return c->method == DEF_METHOD && c->update == DEF_UPDATE && c->transfer == DEF_TRANSFER &&
           c->cfl == DEF_CFL && (c->ppc == DEF_PPC || c->pb == BP_POINT);
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
            if ((int)E[i].c.pb == pb && !E[i].r.rc && usable(E[i].r.err)) list[n++] = &E[i];
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

/* Whether an entry counts as "the setting at its resolution": ppc 2 (the
 * point: 1) and C = 0.5, in the space sweep (the point: its time sweep). */
static int setting_entry(const entry *e)
{
    return e->c.cfl == DEF_CFL && (e->space || e->c.pb == BP_POINT) &&
           (e->c.pb == BP_POINT || e->c.ppc == DEF_PPC);
}

/* Geometric mean and maximum over the resolutions of front_factor() for
 * scheme sc on problem pb; returns the number of runs used, *failed the
 * failed ones. */
static int setting_factor(int pb, int sc, double *gm, double *mx, int *failed)
{
    double lsum = 0;
    int n = 0;
    *failed = 0;
    *mx = 0;
    for (int i = 0; i < nE; i++) {
        const entry *e = &E[i];
        if ((int)e->c.pb != pb || scheme_of(&e->c) != sc || !setting_entry(e)) continue;
        double f = e->r.rc ? NAN : front_factor(e);
        if (isfinite(f)) {
            lsum += log(f);
            *mx = fmax(*mx, f);
            n++;
        } else {
            (*failed)++;
        }
    }
    *gm = n ? exp(lsum / n) : NAN;
    return n;
}

/* Every scheme at ppc 2 and C = 0.5 against the fronts: the geometric mean
 * over the resolutions of front_factor(), how many runs failed, and the
 * scheme's worst problem (the largest mean; "fail" when a run failed): a
 * candidate for the defaults has a worst value <= DEF_AIM. */
static void print_candidates(const int *only)
{
    printf(
        "\n== Settings against the fronts (ppc 2, C = 0.5, every resolution of the space sweep): "
        "time / time of the fastest front configuration at least as accurate, geometric mean "
        "(1.0 = on the front); (n) runs that failed; worst: the largest over the problems ==\n"
        "%-22s",
        "");
    for (int pb = 0; pb < BP_COUNT; pb++)
        if (!only || only[pb]) printf(" %-10s", bench_problem_name((bench_problem)pb));
    printf(" %-10s\n", "worst");
    for (int sc = 0; sc < n_schemes(); sc++) {
        int any = 0;
        for (int pb = 0; pb < BP_COUNT; pb++) any |= scheme_ran(pb, sc);
        if (!any) continue;
        char lab[48];
        scheme_label(sc, lab, sizeof lab);
        if (scheme_is_default(sc)) strncat(lab, " (dflt)", sizeof lab - strlen(lab) - 1);
        printf("%-22s", lab);
        double worst = 0;
        int worst_fail = 0, missing = 0;
        for (int pb = 0; pb < BP_COUNT; pb++) {
            if (only && !only[pb]) continue;
            double gm, mx;
            int failed, n = setting_factor(pb, sc, &gm, &mx, &failed);
            char cell[32];
            if (n)
                snprintf(cell, sizeof cell, failed ? "%.1f (%d)" : "%.1f", gm, failed);
            else
                snprintf(cell, sizeof cell, failed ? "fail (%d)" : "-", failed);
            printf(" %-10s", cell);
            if (n) worst = fmax(worst, gm);
            if (failed) worst_fail = 1;
            if (!n && !failed) missing = 1;
        }
        if (worst_fail)
            printf(" fail\n");
        else
            printf(" %.1f%s\n", worst, missing ? " (-)" : "");
    }
}

/* The defaults, per problem and resolution, against the fastest
 * configuration at least as accurate (any scheme, ppc, C): the ratio the
 * issue wants within DEF_AIM on every problem. */
static void print_defaults(const int *only)
{
    printf(
        "\n== The defaults (BSPLINE2 MUSL FLIP, ppc 2, C = 0.5) against the fastest configuration "
        "at least as accurate (aim: <= %.1fx on every problem) ==\n",
        DEF_AIM);
    printf("%-7s %5s %10s %10s %7s  %s\n", "problem", "cells", "err", "wall (s)", "ratio",
           "fastest at least as accurate");
    for (int pb = 0; pb < BP_COUNT; pb++) {
        if (only && !only[pb]) continue;
        double lsum = 0, mx = 0;
        int n = 0, failed = 0;
        for (int i = 0; i < nE; i++) {
            const entry *d = &E[i];
            if ((int)d->c.pb != pb || !is_default(&d->c) || !setting_entry(d)) continue;
            if (d->r.rc || !usable(d->r.err)) {
                printf("%-7s %5d %10s %10s %7s  %s\n", bench_problem_name((bench_problem)pb),
                       d->c.cells, d->r.rc ? "failed" : "useless", "", "", "");
                failed++;
                continue;
            }
            const entry *who = NULL;
            for (int j = 0; j < nE; j++) {
                const entry *f = &E[j];
                if ((int)f->c.pb == pb && f->front && f->r.err <= d->r.err &&
                    (!who || f->wall_med < who->wall_med))
                    who = f;
            }
            double ratio = who ? fmax(d->wall_med / who->wall_med, 1.0) : NAN;
            char lab[128] = "(itself)";
            if (who && who != d) cfg_label(&who->c, lab, sizeof lab);
            printf("%-7s %5d %10.3e %10.3e %6.2fx  %s\n", bench_problem_name((bench_problem)pb),
                   d->c.cells, d->r.err, d->wall_med, ratio, lab);
            if (isfinite(ratio)) {
                lsum += log(ratio);
                mx = fmax(mx, ratio);
                n++;
            }
        }
        if (n)
            printf("%-7s %5s geometric mean %.2fx, max %.2fx: %s%s\n",
                   bench_problem_name((bench_problem)pb), "", exp(lsum / n), mx,
                   exp(lsum / n) <= DEF_AIM ? "meets the aim" : "MISSES the aim",
                   failed ? " (and runs that failed)" : "");
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
    fprintf(f, "problem,method,update,transfer,pic_fraction,cells,ppc,cfl,dt,steps,particles,err,"
               "err2,err3,dL_rel,dK_rel,time_err,wall_median_s,wall_min_s,repeats,space_sweep,"
               "time_sweep,time_ref,pareto,status,message\n");
    for (int i = 0; i < nE; i++) {
        const entry *e = &E[i];
        char msg[256];
        snprintf(msg, sizeof msg, "%s", e->r.msg);
        for (char *p = msg; *p; p++)
            if (*p == '"' || *p == ',') *p = ';';
        fprintf(f,
                "%s,%s,%s,%s,%g,%d,%d,%g,%.6e,%ld,%zu,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%d,"
                "%d,%d,%d,%d,%s,%s\n",
                bench_problem_name(e->c.pb), bench_method_name(e->c.method),
                bench_update_name(e->c.update), bench_transfer_name(e->c.transfer),
                bench_transfers[e->c.transfer].pic_fraction, e->c.cells, e->c.ppc, e->c.cfl,
                e->r.dt, e->r.steps, e->r.particles, e->r.err, e->r.err2, e->r.err3, e->r.dL,
                e->r.dK, e->terr, e->wall_med, e->wall_min, e->repeats, e->space, e->time, e->ref,
                e->front, e->r.rc ? mpm_strerror(e->r.rc) : "ok", msg);
    }
    return fclose(f);
}

/* Series styles: the colour tells the method, the point type the update
 * and transfer; FLIP lines are solid, PIC dashed, APIC dotted. */
static void series_style(int sc, char *buf, size_t n)
{
    static const char *const colour[] = {"#1f77b4", "#d62728", "#2ca02c",
                                         "#9467bd", "#ff7f0e", "#8c564b"};
    int mi, u, t;
    scheme_split(sc, &mi, &u, &t);
    snprintf(buf, n, "lc rgb '%s' pt %d dt %d", colour[mi % 6], 4 + u + 3 * (t % 3),
             t == BT_FLIP  ? 1
             : t == BT_PIC ? 2
                           : 3);
}

/* One panel: a series per scheme of (x, y) pairs from the entries selected
 * by kind (0: all runs err vs wall; 1: space sweep C=0.5 ppc 2, err vs h;
 * 2: time sweep, time error vs dt), plus the front for kind 0.  Returns
 * whether the panel had data (panels without any are left out). */
static int gp_panel(FILE *f, bench_problem pb, int kind, const char *title)
{
    int any = 0;
    static int cnt[MAX_SCHEMES];
    for (int sc = 0; sc < n_schemes(); sc++) {
        cnt[sc] = 0;
        if (!scheme_ran(pb, sc)) continue;
        series sr = {{0}, {0}, 0};
        if (kind == 1) space_series(pb, sc, order_ppc, DEF_CFL, 0, &sr);
        if (kind == 2) time_series(pb, sc, 0, &sr);
        fprintf(f, "$d%d_%d_%d << EOD\n", pb, kind, sc);
        if (kind == 0) {
            for (int i = 0; i < nE; i++) {
                const entry *e = &E[i];
                if (e->c.pb != pb || scheme_of(&e->c) != sc || e->r.rc || !(e->r.err > 0)) continue;
                fprintf(f, "%.6e %.6e\n", e->wall_med, e->r.err);
                any = cnt[sc] = 1;
            }
        } else {
            for (int i = 0; i < sr.n; i++)
                if (sr.y[i] > 0 && isfinite(sr.y[i])) {
                    fprintf(f, "%.6e %.6e\n", sr.x[i], sr.y[i]);
                    any = cnt[sc] = 1;
                }
        }
        fprintf(f, "EOD\n");
    }
    if (!any) return 0;
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
    fprintf(f, "plot ");
    for (int sc = 0, first = 1; sc < n_schemes(); sc++) {
        if (!cnt[sc]) continue;
        char st[64], lab[48];
        series_style(sc, st, sizeof st);
        scheme_label(sc, lab, sizeof lab);
        fprintf(f, "%s$d%d_%d_%d using 1:2 with %s %s title '%s'", first ? "" : ", ", pb, kind, sc,
                kind ? "linespoints" : "points", st, lab);
        first = 0;
    }
    if (kind == 0) fprintf(f, ", $f%d using 1:2 with steps lc rgb 'black' dt 2 title 'front'", pb);
    fprintf(f, "\n");
    return 1;
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
    fprintf(f, "set terminal pngcairo size 1500,1100 font ',8'\nset logscale xy\n"
               "set format x '10^{%%L}'\nset format y '10^{%%L}'\nset grid\n");
    static const char *const what[3] = {"time", "space", "dt"};
    static const char *const xl[3] = {"median wall time of a run (s)", "cell size h",
                                      "time step dt"};
    static const char *const yl[3] = {"error", "error (C = 0.5, ppc 2)",
                                      "distance to the reference run"};
    for (int k = 0; k < 3; k++) {
        fprintf(f, "set output '%s/accuracy_%s.png'\n", dir, what[k]);
        fprintf(f, "set multiplot layout 3,3 title '%s'\n",
                k == 0   ? "error against run time (all configurations; dashed: Pareto front)"
                : k == 1 ? "error against cell size at a fixed Courant number"
                         : "time convergence on a fixed grid");
        /* the empty corner: fast and accurate (bottom left) does not
         * happen; coarse and accurate (top left) neither */
        fprintf(f, "set xlabel '%s'\nset ylabel '%s'\nset key %s font ',6'\n", xl[k], yl[k],
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

static void list_problems(FILE *f)
{
    for (int pb = 0; pb < BP_COUNT; pb++)
        fprintf(f, "%s%s", pb ? ", " : "", bench_problem_name((bench_problem)pb));
    fprintf(f, ", collapse");
}

static int only_collapse; /* --only names collapse (collapse.c) */

static int parse_only(const char *s, int *only)
{
    char buf[256];
    snprintf(buf, sizeof buf, "%s", s);
    for (char *tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
        int found = 0;
        if (!strcmp(tok, "collapse")) {
            only_collapse = 1;
            continue;
        }
        for (int pb = 0; pb < BP_COUNT; pb++)
            if (!strcmp(tok, bench_problem_name((bench_problem)pb))) only[pb] = found = 1;
        if (!found) {
            fprintf(stderr, "mpmbench-accuracy: --only: unknown problem '%s' (", tok);
            list_problems(stderr);
            fprintf(stderr, ")\n");
            return -1;
        }
    }
    return 0;
}

/* --methods / --transfers: a comma-separated list of row names of a table;
 * a row that exists but is not enabled (not merged yet) is an error too. */
static int parse_rows(const char *opt, const char *s, int *sel, int nrows, int transfers)
{
    char buf[256];
    snprintf(buf, sizeof buf, "%s", s);
    for (int i = 0; i < nrows; i++) sel[i] = 0;
    for (char *tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
        int found = -1;
        for (int i = 0; i < nrows; i++) {
            const char *name = transfers ? bench_transfers[i].name : bench_methods[i].name;
            if (!strcasecmp(tok, name)) found = i;
        }
        int enabled = found >= 0 &&
                      (transfers ? bench_transfers[found].enabled : bench_methods[found].enabled);
        if (found < 0 || !enabled) {
            fprintf(stderr, "mpmbench-accuracy: %s: %s '%s' (enabled:", opt,
                    found < 0 ? "unknown" : "not enabled in this build (bench.h)", tok);
            for (int i = 0; i < nrows; i++)
                if (transfers ? bench_transfers[i].enabled : bench_methods[i].enabled)
                    fprintf(stderr, " %s",
                            transfers ? bench_transfers[i].name : bench_methods[i].name);
            fprintf(stderr, ")\n");
            return -1;
        }
        sel[found] = 1;
    }
    return 0;
}

static void usage(FILE *f, const char *argv0)
{
    fprintf(f,
            "usage: %s [--quick] [--extended] [--repeats N] [--out DIR]\n"
            "          [--only PROBLEM,...] [--methods NAME,...] [--transfers NAME,...]\n"
            "  sweeps method, update, transfer, cells, ppc and dt/CFL on problems with known\n"
            "  answers and writes DIR/accuracy.csv and DIR/accuracy.gp (default DIR: "
            "build/bench).\n"
            "  --quick       a small subset (seconds)\n"
            "  --extended    also mms2d at 128 cells and mms3d at 32 (minutes more per method)\n"
            "  --repeats N   timing repeats, 1..15 (default 3; --quick: 1)\n"
            "  --only        problems: ",
            argv0);
    list_problems(f);
    fprintf(f, "\n  --methods     methods enabled in this build:");
    for (int i = 0; i < bench_n_methods; i++)
        if (bench_methods[i].enabled) fprintf(f, " %s", bench_methods[i].name);
    fprintf(f, "\n  --transfers   transfers enabled in this build:");
    for (int i = 0; i < bench_n_transfers; i++)
        if (bench_transfers[i].enabled) fprintf(f, " %s", bench_transfers[i].name);
    fprintf(f, "\n");
}

int main(int argc, char **argv)
{
    const char *out = "build/bench";
    int repeats = 3, use_only = 0, only[BP_COUNT] = {0};
    if (bench_n_methods > 16 || bench_n_transfers > 8) {
        fprintf(stderr, "mpmbench-accuracy: the method/transfer tables outgrew the sweep\n");
        return 2;
    }
    for (int i = 0; i < bench_n_methods; i++) sel_method[i] = 1;
    for (int i = 0; i < bench_n_transfers; i++) sel_transfer[i] = 1;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        int has_arg = i + 1 < argc;
        if (!strcmp(a, "--quick")) {
            quick = 1;
        } else if (!strcmp(a, "--extended")) {
            extended = 1;
        } else if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout, argv[0]);
            return 0;
        } else if (!strcmp(a, "--repeats") || !strcmp(a, "--out") || !strcmp(a, "--only") ||
                   !strcmp(a, "--methods") || !strcmp(a, "--transfers")) {
            if (!has_arg) {
                fprintf(stderr, "mpmbench-accuracy: %s needs a value (--help)\n", a);
                return 2;
            }
            const char *v = argv[++i];
            if (!strcmp(a, "--repeats")) {
                char *end;
                long r = strtol(v, &end, 10);
                if (*end || r < 1 || r > 15) {
                    fprintf(stderr, "mpmbench-accuracy: --repeats: '%s' is not in 1..15\n", v);
                    return 2;
                }
                repeats = (int)r;
            } else if (!strcmp(a, "--out")) {
                out = v;
            } else if (!strcmp(a, "--only")) {
                if (parse_only(v, only)) return 2;
                use_only = 1;
            } else if (!strcmp(a, "--methods")) {
                if (parse_rows(a, v, sel_method, bench_n_methods, 0)) return 2;
            } else if (parse_rows(a, v, sel_transfer, bench_n_transfers, 1)) {
                return 2;
            }
        } else {
            fprintf(stderr, "mpmbench-accuracy: unknown argument '%s'\n", a);
            usage(stderr, argv[0]);
            return 2;
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
    int sweeps = !use_only;
    for (int pb = 0; pb < BP_COUNT; pb++) sweeps |= only[pb];
    if (!sweeps) { /* --only collapse */
        free(E);
        return bench_collapse(quick, out) ? 1 : 0;
    }
    plan(sel);
    printf("%d configurations, %d repeats each for timing (median), one solver thread\n\n", nE,
           repeats);
    printf("%-6s %-5s %-4s %-4s %-9s %-5s %-9s %8s %9s %9s %9s\n", "", "", "", "", "", "", "",
           "steps", "err", "err2", "wall (s)");
    double t0 = bench_now();
    for (int i = 0; i < nE; i++) {
        run_entry(&E[i], repeats);
        print_row(&E[i]);
    }
    time_errors();
    print_orders(sel);
    print_pairs(sel);
    print_spin(sel);
    print_pareto(sel);
    print_candidates(sel);
    print_defaults(sel);
    char path[1024];
    snprintf(path, sizeof path, "%s/accuracy.csv", out);
    int rc = write_csv(path);
    if (!rc) printf("\nwrote %s", path);
    if (!rc && !(rc = write_gnuplot(out, sel))) printf(" and %s/accuracy.gp", out);
    printf(" (%.0f s in all)\n", bench_now() - t0);
    if ((!use_only || only_collapse) && bench_collapse(quick, out)) rc = 1;
    for (int i = 0; i < nE; i++) bench_res_free(&E[i].r);
    free(E);
    return rc ? 1 : 0;
}
