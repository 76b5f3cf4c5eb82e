/*
 * problems.c - the accuracy benchmark's problems (see bench.h): builds one
 * configuration, runs it with the solver, samples its error against the
 * known answer about a hundred times a run (outside the timed blocks), and
 * times only the stepping.
 *
 * The manufactured solution.  For u_i = A sin(2 pi X_i) s_i(t) (axis
 * aligned: u_i depends on X_i only), F is diagonal with
 * F_i = 1 + du_i/dX_i and the spin is zero, so the solver's incremental
 * linear elasticity (stress rate = lambda tr(D) I + 2 mu D, volume
 * V <- V (1 + tr de)) integrates exactly to the Hencky law
 *     sigma_ii = lambda sum_j ln F_j + 2 mu ln F_i      (1D: E ln F)
 * with V = J V0.  The first Piola stress is P_ii = J sigma_ii / F_i =
 * (prod_{j != i} F_j) sigma_ii, and since F_j depends on X_j only,
 *     dP_ii/dX_i = (prod_{j != i} F_j) M (dF_i/dX_i) / F_i,
 * M = lambda + 2 mu (E in 1D).  Balance of momentum in the reference
 * configuration, rho0 u_i'' = dP_ii/dX_i + rho0 b_i, then gives the body
 * force per unit mass that makes u exact:
 *     b_i = u_i'' - (M / rho0) (prod_{j != i} F_j) (d2u_i/dX_i2) / F_i.
 * With s_i(t) = +-sin(omega t), omega = pi c (c^2 = M / rho0, as
 * Wallstedt & Guilkey 2008 choose it) this is
 *     b_i = A sin(2 pi X_i) s_i(t) pi^2 c^2 (4 prod_{j != i} F_j / F_i - 1).
 * The force m_p b(X_p, t_n) is given to every particle before each step
 * through bench_force_set() (mpm_sim_set_particle_forces).  u = 0 on every face, where rollers hold
 * the normal velocity; initial u = 0, v_i = A omega sin(2 pi X_i) (+-1), stress 0.
 */
#include "bench.h"
#include "mpm_paper.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define SAMPLES 100
#define BAR_V0 1e-3
#define POINT_V0 0.1
#ifndef MMS_A
#define MMS_A 0.02 /* -DMMS_A=... to study another amplitude */
#endif
#define MMS_E 1.0
#define MMS_NU 0.3
#define DISK_TEND 4.0

double bench_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

const char *bench_problem_name(bench_problem pb)
{
    static const char *const names[BP_COUNT] = {"point", "bar", "mms1d", "mms2d", "mms3d", "disks"};
    return (unsigned)pb < BP_COUNT ? names[pb] : "?";
}

const char *bench_method_name(mpm_method m)
{
    return m == MPM_METHOD_GIMP ? "GIMP" : "MPM";
}

const char *bench_update_name(mpm_update u)
{
    return u == MPM_USL ? "USL" : u == MPM_MUSL ? "MUSL" : "USF";
}

int bench_problem_dim(bench_problem pb)
{
    return pb == BP_MMS2 || pb == BP_DISKS ? 2 : pb == BP_MMS3 ? 3 : 1;
}

double bench_scale(bench_problem pb)
{
    switch (pb) {
    case BP_POINT: return 0.5 * POINT_V0 / (2 * M_PI); /* x0 v0 / (L omega) */
    case BP_BAR: return BAR_V0 / mpm_paper_bar_omega();
    case BP_DISKS: return 0.14;
    default: return MMS_A;
    }
}

double bench_rms_diff(const double *a, const double *b, size_t n, int dim, double scale)
{
    double s = 0;
    for (size_t i = 0; i < n * (size_t)dim; i++) s += (a[i] - b[i]) * (a[i] - b[i]);
    return n ? sqrt(s / (double)n) / scale : 0;
}

void bench_res_free(bench_res *r)
{
    free(r->xf);
    r->xf = NULL;
}

/* dt = T / ceil(T / (cfl h / c)): at most cfl h / c, ending exactly at T. */
static long steps_for(double tend, double cfl, double h, double c, double *dt)
{
    long n = (long)ceil(tend / (cfl * h / c) - 1e-9);
    if (n < 1) n = 1;
    *dt = tend / (double)n;
    return n;
}

/* Runs k steps and adds the wall time; records a failure in r. */
static int timed_run(mpm_sim *s, long k, bench_res *r)
{
    double t0 = bench_now();
    int rc = mpm_sim_run(s, k);
    r->wall += bench_now() - t0;
    if (rc) {
        r->rc = rc;
        mpm_error_text(mpm_sim_error(s), MPM_FIELD_PROTO, r->msg, sizeof r->msg);
    }
    return rc;
}

static int keep_positions(mpm_sim *s, bench_res *r)
{
    size_t n = mpm_sim_particles(s);
    r->xf = malloc(n * (size_t)r->dim * sizeof *r->xf);
    if (!r->xf) {
        snprintf(r->msg, sizeof r->msg, "out of memory");
        return -1;
    }
    mpm_sim_snapshot(s, &(mpm_snapshot){.x = r->xf});
    return 0;
}

static mpm_sim *make_sim(const mpm_case *c, bench_res *r)
{
    mpm_error err;
    mpm_sim *s = mpm_sim_new(c, NULL, &err);
    if (s)
        r->particles = mpm_sim_particles(s);
    else
        mpm_error_text(&err, MPM_FIELD_PROTO, r->msg, sizeof r->msg);
    return s;
}

/* ---- point ---- */

static int run_point(const bench_cfg *cf, int keep, bench_res *r)
{
    mpm_paper t;
    double dt, c = 2 * M_PI, tend = 3.0;
    long n = steps_for(tend, cf->cfl, 1.0, c, &dt);
    mpm_paper_point(&t, cf->update, dt, POINT_V0);
    t.c.method = cf->method;
    t.c.allow_unstable_dt = 1;
    mpm_sim *s = make_sim(&t.c, r);
    mpm_paper_free(&t);
    if (!s) return -1;
    r->dt = dt;
    mpm_energy e0, e;
    mpm_sim_energy(s, &e0);
    /* Eq. 38 is a maximum over time: sample every step, time in blocks of
     * steps between samples so the clock is read rarely */
    long every = n / 2000 > 1 ? n / 2000 : 1;
    for (long i = 0; i < n && !r->rc; i += every) {
        long k = i + every <= n ? every : n - i;
        if (timed_run(s, k, r)) break;
        double v;
        mpm_sim_snapshot(s, &(mpm_snapshot){.v = &v});
        double va = mpm_paper_point_v(POINT_V0, mpm_sim_time(s));
        r->err = fmax(r->err, fabs(va - v) / (1 + fabs(va)));
    }
    mpm_sim_energy(s, &e);
    r->err2 = fabs(e.total - e0.total) / e0.total;
    r->steps = mpm_sim_steps(s);
    int rc = keep && !r->rc ? keep_positions(s, r) : 0;
    mpm_sim_destroy(&s);
    return rc;
}

/* ---- bar ---- */

static int run_bar(const bench_cfg *cf, int keep, bench_res *r)
{
    mpm_paper t;
    double dt, h = 1.0 / cf->cells, w = mpm_paper_bar_omega(), tend = 2 * 2 * M_PI / w;
    long n = steps_for(tend, cf->cfl, h, sqrt(10.0), &dt);
    if (mpm_paper_bar(&t, cf->method, cf->update, cf->cells, cf->ppc, 2, dt, BAR_V0)) {
        snprintf(r->msg, sizeof r->msg, "out of memory");
        return -1;
    }
    t.c.allow_unstable_dt = 1;
    size_t np = t.body[0].n_points;
    double *X = malloc(np * sizeof *X), *x = malloc(np * sizeof *x);
    if (!X || !x) {
        free(X);
        free(x);
        mpm_paper_free(&t);
        snprintf(r->msg, sizeof r->msg, "out of memory");
        return -1;
    }
    memcpy(X, t.x, np * sizeof *X);
    mpm_sim *s = make_sim(&t.c, r);
    mpm_paper_free(&t);
    int rc = -1;
    if (!s) goto out;
    r->dt = dt;
    double amp_u = BAR_V0 / w, amp_v = 2 * BAR_V0 / M_PI;
    long every = n / SAMPLES > 1 ? n / SAMPLES : 1;
    for (long i = 0; i < n && !r->rc; i += every) {
        long k = i + every <= n ? every : n - i;
        if (timed_run(s, k, r)) break;
        double tt = mpm_sim_time(s), se = 0;
        mpm_energy e;
        mpm_sim_energy(s, &e);
        r->err2 =
            fmax(r->err2, fabs(e.momentum[0] / e.mass - mpm_paper_bar_vcm(BAR_V0, tt)) / amp_v);
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = x});
        for (size_t p = 0; p < np; p++) {
            double d = x[p] - X[p] - amp_u * sin(w * tt) * sin(M_PI / 2 * X[p]);
            se += d * d;
        }
        r->err = fmax(r->err, sqrt(se / (double)np) / amp_u);
    }
    r->steps = mpm_sim_steps(s);
    rc = keep && !r->rc ? keep_positions(s, r) : 0;
    mpm_sim_destroy(&s);
out:
    free(X);
    free(x);
    return rc;
}

/* ---- manufactured solution ---- */

typedef struct {
    int dim;
    size_t n;
    double A, omega, c2, sign[3];
    double *X, *sx, *cx, *m; /* n*dim, n*dim, n*dim, n */
    double *f, *x;           /* n*dim forces, positions */
} mms;

static void mms_free(mms *p)
{
    free(p->X);
    free(p->sx);
    free(p->cx);
    free(p->m);
    free(p->f);
    free(p->x);
    memset(p, 0, sizeof *p);
}

/* forces m_p b(X_p, t) into p->f */
static void mms_forces(mms *p, double t)
{
    int D = p->dim;
    double st = sin(p->omega * t), k = M_PI * M_PI * p->c2 * p->A, twopiA = 2 * M_PI * p->A;
    for (size_t q = 0; q < p->n; q++) {
        const double *sx = p->sx + q * D, *cx = p->cx + q * D;
        double F[3] = {1, 1, 1}, prod = 1;
        for (int d = 0; d < D; d++) {
            F[d] = 1 + twopiA * cx[d] * p->sign[d] * st;
            prod *= F[d];
        }
        for (int d = 0; d < D; d++) {
            double others = prod / F[d];
            p->f[q * D + d] = p->m[q] * k * sx[d] * p->sign[d] * st * (4 * others / F[d] - 1);
        }
    }
}

/* RMS and max over particles of |x - x_exact(t)| / A */
static void mms_error(const mms *p, double t, double *rms, double *mx)
{
    int D = p->dim;
    double st = sin(p->omega * t), s2 = 0, m = 0;
    for (size_t q = 0; q < p->n; q++) {
        double d2 = 0;
        for (int d = 0; d < D; d++) {
            double ex = p->X[q * D + d] + p->A * p->sx[q * D + d] * p->sign[d] * st;
            double e = p->x[q * D + d] - ex;
            d2 += e * e;
        }
        s2 += d2;
        m = fmax(m, sqrt(d2));
    }
    *rms = sqrt(s2 / (double)p->n) / p->A;
    *mx = m / p->A;
}

static int run_mms(const bench_cfg *cf, int keep, bench_res *r)
{
    int D = bench_problem_dim(cf->pb), N = cf->cells, P = cf->ppc, per = N * P;
    double h = 1.0 / N;
    mpm_material_desc mat = {MPM_MODEL_LINEAR_ELASTIC, MMS_E, D == 1 ? 0.0 : MMS_NU, 1.0};
    double c = mpm_material_wave_speed(&mat, D);
    mms p = {0};
    p.dim = D;
    p.n = (size_t)per * (D > 1 ? per : 1) * (D > 2 ? per : 1);
    p.A = MMS_A;
    p.omega = M_PI * c;
    p.c2 = c * c;
    for (int d = 0; d < 3; d++) p.sign[d] = d % 2 ? -1.0 : 1.0;
    size_t nd = p.n * (size_t)D;
    double *vol = malloc(p.n * sizeof *vol), *v = malloc(nd * sizeof *v),
           *hl = malloc(nd * sizeof *hl);
    p.X = malloc(nd * sizeof *p.X);
    p.sx = malloc(nd * sizeof *p.sx);
    p.cx = malloc(nd * sizeof *p.cx);
    p.m = malloc(p.n * sizeof *p.m);
    p.f = malloc(nd * sizeof *p.f);
    p.x = malloc(nd * sizeof *p.x);
    mpm_sim *s = NULL;
    int rc = -1;
    if (!vol || !v || !hl || !p.X || !p.sx || !p.cx || !p.m || !p.f || !p.x) {
        snprintf(r->msg, sizeof r->msg, "out of memory");
        goto out;
    }
    for (size_t q = 0; q < p.n; q++) {
        size_t rest = q;
        double V = 1;
        for (int d = 0; d < D; d++) {
            int k = (int)(rest % (size_t)per);
            rest /= (size_t)per;
            double X = (k + 0.5) / per;
            p.X[q * D + d] = X;
            p.sx[q * D + d] = sin(2 * M_PI * X);
            p.cx[q * D + d] = cos(2 * M_PI * X);
            v[q * D + d] = p.A * p.omega * p.sx[q * D + d] * p.sign[d];
            hl[q * D + d] = 0.5 * h / P;
            V *= h / P;
        }
        vol[q] = V;
        p.m[q] = mat.density * V;
    }
    double dt, tend = 2.0 / c;
    long n = steps_for(tend, cf->cfl, h, c, &dt);
    mpm_body_desc b = {0};
    b.n_points = p.n;
    b.x = p.X;
    b.volume = vol;
    b.mass = p.m;
    b.v = v;
    b.half_length = hl;
    mpm_case cs = {0};
    cs.grid.dim = D;
    for (int d = 0; d < D; d++) {
        cs.grid.h[d] = h;
        cs.grid.nodes[d] = N + 1;
        cs.bc.face_mask[2 * d] = cs.bc.face_mask[2 * d + 1] = 1u << d; /* rollers */
    }
    cs.method = cf->method;
    cs.update = cf->update;
    cs.dt = dt;
    cs.allow_unstable_dt = 1;
    cs.n_materials = 1;
    cs.materials = &mat;
    cs.n_bodies = 1;
    cs.bodies = &b;
    if (!(s = make_sim(&cs, r))) goto out;
    r->dt = dt;
    long every = n / SAMPLES > 1 ? n / SAMPLES : 1;
    for (long i = 0; i < n && !r->rc; i += every) {
        long k = i + every <= n ? every : n - i;
        double t0 = bench_now();
        for (long j = 0; j < k; j++) {
            mms_forces(&p, mpm_sim_time(s));
            if ((r->rc = bench_force_set(s, p.f))) {
                mpm_error_text(mpm_sim_error(s), MPM_FIELD_PROTO, r->msg, sizeof r->msg);
                goto out;
            }
            if ((r->rc = mpm_sim_step(s))) {
                mpm_error_text(mpm_sim_error(s), MPM_FIELD_PROTO, r->msg, sizeof r->msg);
                break;
            }
        }
        r->wall += bench_now() - t0;
        if (r->rc) break;
        double rms, mx;
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = p.x});
        mms_error(&p, mpm_sim_time(s), &rms, &mx);
        r->err = fmax(r->err, rms);
        r->err2 = fmax(r->err2, mx);
    }
    r->steps = mpm_sim_steps(s);
    rc = keep && !r->rc ? keep_positions(s, r) : 0;
out:
    mpm_sim_destroy(&s);
    free(vol);
    free(v);
    free(hl);
    mms_free(&p);
    return rc;
}

/* ---- disks ---- */

static int run_disks(const bench_cfg *cf, int keep, bench_res *r)
{
    mpm_paper t;
    double h = 1.0 / cf->cells, dt;
    mpm_paper_disks(&t, cf->method, cf->update, h);
    double c = mpm_material_wave_speed(&t.mat[0], 2);
    long n = steps_for(DISK_TEND, cf->cfl, h, c, &dt);
    t.c.dt = dt;
    t.c.allow_unstable_dt = 1;
    t.body[0].ppc = t.body[1].ppc = cf->ppc;
    mpm_sim *s = make_sim(&t.c, r);
    mpm_paper_free(&t);
    if (!s) return -1;
    r->dt = dt;
    mpm_energy e0, e;
    mpm_sim_energy(s, &e0);
    e = e0;
    double pscale = e0.mass * 0.1, sum = 0;
    long every = n / SAMPLES > 1 ? n / SAMPLES : 1, ns = 0;
    for (long i = 0; i < n && !r->rc; i += every) {
        long k = i + every <= n ? every : n - i;
        if (timed_run(s, k, r)) break;
        mpm_sim_energy(s, &e);
        sum += fabs(e.total - e0.total) / e0.total;
        ns++;
        r->err3 = fmax(r->err3, hypot(e.momentum[0], e.momentum[1]) / pscale);
    }
    if (!r->rc) {
        r->err = sum / (double)ns;
        r->err2 = fabs(e.total - e0.total) / e0.total;
    }
    r->steps = mpm_sim_steps(s);
    int rc = keep && !r->rc ? keep_positions(s, r) : 0;
    mpm_sim_destroy(&s);
    return rc;
}

int bench_run(const bench_cfg *c, int keep_final, bench_res *r)
{
    memset(r, 0, sizeof *r);
    r->dim = bench_problem_dim(c->pb);
    int rc;
    switch (c->pb) {
    case BP_POINT: rc = run_point(c, keep_final, r); break;
    case BP_BAR: rc = run_bar(c, keep_final, r); break;
    case BP_DISKS: rc = run_disks(c, keep_final, r); break;
    default: rc = run_mms(c, keep_final, r); break;
    }
    if (r->rc) {
        r->err = r->err2 = r->err3 = INFINITY;
    } else if (!isfinite(r->err) || !isfinite(r->err2) || !isfinite(r->err3)) {
        r->err = r->err2 = r->err3 = INFINITY;
        r->rc = MPM_EDIVERGED;
        snprintf(r->msg, sizeof r->msg, "error measure not finite");
    }
    return rc;
}
