/*
 * t_conditions.c - the boundary conditions: Coulomb friction on grid
 * faces (the sliding block on an inclined plane: the acceleration g (sin
 * theta - mu cos theta) while sliding, rest below the friction angle, and
 * the energy balance with the friction dissipation), prescribed velocities
 * (a bar driven at one face: the face's velocity, the wave speed and the
 * stress behind the front rho c v0, and the prescribed work against the
 * kinetic + strain energy; RAMP and TABLE histories), a ramped traction
 * (quasi-static end displacement and external work), and the errors of
 * bad conditions.  The measured figures are printed (TLOG) and quoted in
 * docs/solver.md.
 */
#include "mpm.h"
#include "mpm_diag.h"
#include "mpm_timefn.h"
#include "mpp_case.h"
#include "t.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static const mpm_material_desc block_mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                                            .youngs_modulus = 1e6,
                                            .poisson_ratio = 0.3,
                                            .density = 1000.0};

/* ---- the sliding block ---- */

typedef struct {
    double a;      /* fitted acceleration of the centre of mass along x */
    double dx;     /* displacement of the centre of mass along x at the end */
    double e_err;  /* max |K + S + P + friction_work - E0| / |P(end) - P0| */
    double wf;     /* friction work at the end */
    double e_drop; /* P0 - P(end) */
    int warned;    /* mpm_sim_warnings() at the end */
} slide_res;

/* A 0.5 x 0.2 block (E 1 MPa, nu 0.3, rho 1000, 2 x 2 points per cell of
 * h = 0.1 / refine: 2, 4 or 8 cells across its height) resting on the y_lo face with friction mu,
 * under gravity g = 10 rotated by theta: (g sin theta, -g cos theta).  The block starts in the
 * geostatic state of its weight (sigma_yy = -rho g cos theta (H - y),
 * sigma_xx = K0 sigma_yy, K0 = nu / (1 - nu), plane strain sigma_zz):
 * dropped stress-free it would bounce on the face, and the vibrating
 * normal force lets it creep below the friction angle.  The
 * centre-of-mass velocity is fitted by least squares over [t_fit,
 * t_end]; USL runs at C = 0.25 (its limit is 0.5, and the friction's
 * stiff shear layer needs the margin). */
static int slide_r(mpm_method m, mpm_update up, double theta_deg, double mu, double t_end,
                   double t_fit, int threads, int refine, slide_res *r)
{
    double th = theta_deg * M_PI / 180, g = 10, H = 0.2, nu = block_mat.poisson_ratio;
    double h = 0.1 / refine, ds = h / 2;
    int NX = 10 * refine, NY = 4 * refine, NP = NX * NY;
    double *X = malloc(sizeof(double) * 9 * (size_t)NP);
    if (!X) return -1;
    double *V = X + 2 * NP, *S6 = V + NP;
    for (int j = 0; j < NY; j++)
        for (int i = 0; i < NX; i++) {
            int p = j * NX + i;
            X[2 * p] = 0.3 + (i + 0.5) * ds;
            X[2 * p + 1] = (j + 0.5) * ds;
            V[p] = ds * ds;
            double syy = -block_mat.density * g * cos(th) * (H - X[2 * p + 1]);
            double sxx = nu / (1 - nu) * syy;
            double st[6] = {sxx, syy, nu * (sxx + syy), 0, 0, 0};
            memcpy(S6 + 6 * p, st, sizeof st);
        }
    mpm_body_desc b = {0};
    b.n_points = (size_t)NP;
    b.x = X;
    b.volume = V;
    b.stress = S6;
    mpm_friction_desc fr = {2, mu};
    mpm_case c = {0};
    c.grid.dim = 2;
    c.grid.h[0] = c.grid.h[1] = h;
    c.grid.nodes[0] = 80 * refine + 1; /* 8 m: 1.5 s of sliding at up to 4 m/s^2 */
    c.grid.nodes[1] = 7 * refine + 1;
    c.method = m;
    c.update = up;
    c.cfl = up == MPM_USL ? 0.25 : 0;
    c.gravity[0] = g * sin(th);
    c.gravity[1] = -g * cos(th);
    c.n_materials = 1;
    c.materials = &block_mat;
    c.n_bodies = 1;
    c.bodies = &b;
    c.bc.n_friction = 1;
    c.bc.friction = &fr;
    c.threads = threads;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    free(X);
    if (!s) {
        TLOG("%s", TERR(&err));
        return -1;
    }
    mpm_energy e;
    mpm_sim_energy(s, &e);
    double e0 = e.kinetic + e.strain + e.potential, p0 = e.potential, M = e.mass;
    double x0 = 0;
    {
        size_t n = mpm_sim_particles(s);
        double *x = malloc(n * 2 * sizeof *x);
        if (!x) return -1;
        mpm_snapshot sn = {.x = x};
        mpm_sim_snapshot(s, &sn);
        for (size_t p = 0; p < n; p++) x0 += x[2 * p];
        x0 /= (double)n;
        free(x);
    }
    double st = 0, sv = 0, stt = 0, stv = 0, cnt = 0, emax = 0;
    while (mpm_sim_time(s) < t_end) {
        if (mpm_sim_step(s)) {
            TLOG("%s", TERR(mpm_sim_error(s)));
            mpm_sim_destroy(&s);
            return -1;
        }
        mpm_sim_energy(s, &e);
        double t = mpm_sim_time(s), v = e.momentum[0] / M;
        double bal = e.kinetic + e.strain + e.potential + e.friction_work - e0;
        if (fabs(bal) > emax) emax = fabs(bal);
        if (t >= t_fit) {
            st += t;
            sv += v;
            stt += t * t;
            stv += t * v;
            cnt += 1;
        }
    }
    r->a = (cnt * stv - st * sv) / (cnt * stt - st * st);
    r->wf = e.friction_work;
    r->e_drop = p0 - e.potential;
    r->e_err = emax / fabs(r->e_drop);
    size_t n = mpm_sim_particles(s);
    double *x = malloc(n * 2 * sizeof *x), xm = 0;
    if (!x) return -1;
    mpm_snapshot sn = {.x = x};
    mpm_sim_snapshot(s, &sn);
    for (size_t p = 0; p < n; p++) xm += x[2 * p];
    r->dx = xm / (double)n - x0;
    free(x);
    r->warned = mpm_sim_warnings(s, NULL, 0);
    mpm_sim_destroy(&s);
    return 0;
}

static int slide(mpm_method m, mpm_update up, double theta_deg, double mu, double t_end,
                 double t_fit, int threads, slide_res *r)
{
    return slide_r(m, up, theta_deg, mu, t_end, t_fit, threads, 1, r);
}

static const char *mname(mpm_method m)
{
    return m == MPM_METHOD_MPM        ? "MPM"
           : m == MPM_METHOD_GIMP     ? "GIMP"
           : m == MPM_METHOD_BSPLINE2 ? "BSPLINE2"
           : m == MPM_METHOD_BSPLINE3 ? "BSPLINE3"
                                      : "CPDI";
}

/* Sliding, over a long run: 1.5 s, in which the block slides 2.2-4.2 m
 * (22-42 cells).  The acceleration fitted over t in [0.3, 1.5] s against
 * g (sin theta - mu cos theta), for each method a friction face accepts
 * (GIMP, BSPLINE2, CPDI) with MUSL and USL (MPM and USF are refused:
 * mpm_cond_refusals): within 1e-3 (measured <= 5.8e-5 with MUSL, <=
 * 3.1e-4 with USL), 2e-3 for CPDI USL at mu 0.2 (measured 1.5e-3); the
 * energy balance K + S + P + W_friction - E0 within 1 % of
 * the potential energy released (measured <= 1.3e-3).  Before MUSL's
 * remap took the face nodes' post-friction momentum, the default method's
 * block slowed from 0.1 s on and moved at 0.37 m/s at 1.5 s where 4.9 m/s
 * is exact.  On finer grids an elastic block's sliding turns unstable
 * (docs/accuracy.md, "Friction faces"): these rows are at h = H / 2. */
TEST(mpm_cond_sliding_long)
{
    typedef struct {
        mpm_method m;
        double th, mu, tol;
    } row;
    static const row rows[] = {
        {MPM_METHOD_BSPLINE2, 25, 0.15, 1e-3}, {MPM_METHOD_BSPLINE2, 25, 0.25, 1e-3},
        {MPM_METHOD_BSPLINE2, 30, 0.25, 1e-3}, {MPM_METHOD_BSPLINE2, 30, 0.4, 1e-3},
        {MPM_METHOD_BSPLINE2, 35, 0.4, 1e-3},  {MPM_METHOD_GIMP, 25, 0.15, 1e-3},
        {MPM_METHOD_GIMP, 30, 0.15, 1e-3},     {MPM_METHOD_GIMP, 30, 0.2, 1e-3},
        {MPM_METHOD_CPDI, 25, 0.15, 1e-3},     {MPM_METHOD_CPDI, 30, 0.15, 1e-3},
        {MPM_METHOD_CPDI, 30, 0.2, 2e-3},
    };
    double g = 10;
    mpm_update us[] = {MPM_MUSL, MPM_USL};
    for (size_t k = 0; k < sizeof rows / sizeof rows[0]; k++)
        for (int u = 0; u < 2; u++) {
            const row *w = &rows[k];
            double a_ex = g * (sin(w->th * M_PI / 180) - w->mu * cos(w->th * M_PI / 180));
            slide_res r;
            CHECK(slide(w->m, us[u], w->th, w->mu, 1.5, 0.3, 1, &r) == 0);
            TLOG("%-8s %s theta %.0f mu %.2f: a = %.5f (exact %.5f, rel err %.2e), balance "
                 "error %.2e of the released %.4g J",
                 mname(w->m), u == 0 ? "MUSL" : "USL ", w->th, w->mu, r.a, a_ex,
                 fabs(r.a - a_ex) / a_ex, r.e_err, r.e_drop);
            CHECK_NEAR(r.a, a_ex, w->tol * a_ex);
            CHECK_LT(r.e_err, 0.01);
            CHECK(r.wf > 0);
        }
}

/* Finer grids: with 4 and 8 cells across the block, BSPLINE2 at mu 0.15
 * still slides at g (sin theta - mu cos theta) within 1e-3 and carries no
 * warning; at mu 0.25 with 4 cells, and with GIMP at mu 0.15 and 8 cells,
 * the sliding feeds a vibration (contact chatters, the strain energy grows)
 * that adds friction: the acceleration ends 4-33 % low (measured in the
 * log), and mpm_sim_warnings() flags an elastic body on a friction face
 * outside BSPLINE2 with mu <= 0.15 (docs/accuracy.md, "Friction faces"). */
TEST(mpm_cond_friction_fine_grids)
{
    static const struct {
        mpm_method m;
        double mu;
        int refine, ok;
    } rows[] = {
        {MPM_METHOD_BSPLINE2, 0.15, 2, 1},
        {MPM_METHOD_BSPLINE2, 0.15, 4, 1},
        {MPM_METHOD_BSPLINE2, 0.25, 2, 0},
        {MPM_METHOD_GIMP, 0.15, 4, 0},
    };
    double g = 10, th = 30;
    for (size_t k = 0; k < sizeof rows / sizeof rows[0]; k++) {
        double a_ex = g * (sin(th * M_PI / 180) - rows[k].mu * cos(th * M_PI / 180));
        slide_res r;
        CHECK(slide_r(rows[k].m, MPM_MUSL, th, rows[k].mu, 1.5, 0.3, 1, rows[k].refine, &r) == 0);
        double err = fabs(r.a - a_ex) / a_ex;
        TLOG("%-8s MUSL mu %.2f, %d cells across: a = %.5f (exact %.5f, rel err %.2e), %s",
             mname(rows[k].m), rows[k].mu, 2 * rows[k].refine, r.a, a_ex, err,
             r.warned ? "warned" : "no warning");
        if (rows[k].ok) {
            CHECK_LT(err, 1e-3);
            CHECK(!r.warned);
        } else {
            CHECK(r.warned);
        }
    }
}

/* The combinations a friction face refuses at submit (mpm_case_verified()),
 * each naming its field: USF (the block, dropped on the face, slowed to
 * 1.2 m/s at 1.5 s where 4.3 m/s is exact), MPM's tents (it diverged at
 * 0.16 s), BSPLINE3 (not in the sliding tests); the others pass. */
TEST(mpm_cond_refusals)
{
    mpm_material_desc mat = block_mat;
    mpm_body_desc b = {0};
    b.shape = MPM_SHAPE_BOX;
    b.lo[0] = 0.3;
    b.hi[0] = 0.8;
    b.hi[1] = 0.2;
    b.ppc = 2;
    mpm_friction_desc fr = {2, 0.2};
    mpm_case c = {0};
    c.grid.dim = 2;
    c.grid.h[0] = c.grid.h[1] = 0.1;
    c.grid.nodes[0] = 31;
    c.grid.nodes[1] = 8;
    c.gravity[0] = 5;
    c.gravity[1] = -8.66;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 1;
    c.bodies = &b;
    c.bc.n_friction = 1;
    c.bc.friction = &fr;
    static const struct {
        mpm_method m;
        mpm_update u;
        const char *field; /* NULL: accepted */
    } rows[] = {
        {MPM_METHOD_BSPLINE2, MPM_MUSL, NULL},     {MPM_METHOD_BSPLINE2, MPM_USL, NULL},
        {MPM_METHOD_GIMP, MPM_MUSL, NULL},         {MPM_METHOD_CPDI, MPM_USL, NULL},
        {MPM_METHOD_BSPLINE2, MPM_USF, "update"},  {MPM_METHOD_GIMP, MPM_USF, "update"},
        {MPM_METHOD_MPM, MPM_MUSL, "method"},      {MPM_METHOD_MPM, MPM_USL, "method"},
        {MPM_METHOD_BSPLINE3, MPM_MUSL, "method"},
    };
    for (size_t i = 0; i < sizeof rows / sizeof rows[0]; i++) {
        c.method = rows[i].m;
        c.update = rows[i].u;
        mpm_case_info info;
        mpm_error err;
        CHECK(mpm_case_check(&c, &info, &err) == 0);
        int rc = mpm_case_verified(&c, &info, &err);
        const char *txt = TERR(&err);
        TLOG("%-8s %d: %s", mname(rows[i].m), (int)rows[i].u, rc ? txt : "(accepted)");
        if (!rows[i].field) {
            CHECK(rc == 0);
            continue;
        }
        CHECK(rc == MPM_EINVAL);
        CHECK(strncmp(txt, rows[i].field, strlen(rows[i].field)) == 0);
        CHECK(strstr(txt, "; use ") != NULL); /* names an alternative */
    }
}

/* 3D: the same block, 0.5 deep in z, on y_lo with mu = 0.2, gravity's
 * tangential part pointing 30 deg off x towards z: (g sin theta cos 30,
 * -g cos theta, g sin theta sin 30).  The friction opposes the sliding
 * direction as a vector: the centre of mass accelerates along the
 * tangential gravity with g (sin theta - mu cos theta) within 1 %, and
 * stays on that line (its z/x acceleration ratio tan 30 within 1 %).
 * GIMP, MUSL; geostatic start as in 2D. */
TEST(mpm_cond_sliding_block_3d)
{
    double th = 30 * M_PI / 180, ph = 30 * M_PI / 180, g = 10, mu = 0.2, H = 0.2, nu = 0.3;
    enum { NX = 10, NY = 4, NZ = 10, NP = NX * NY * NZ };
    double *X = malloc(sizeof(double) * (3 * NP + NP + 6 * NP));
    CHECK(X);
    double *V = X + 3 * NP, *S6 = V + NP;
    for (int k = 0; k < NZ; k++)
        for (int j = 0; j < NY; j++)
            for (int i = 0; i < NX; i++) {
                int p = (k * NY + j) * NX + i;
                X[3 * p] = 0.3 + (i + 0.5) * 0.05;
                X[3 * p + 1] = (j + 0.5) * 0.05;
                X[3 * p + 2] = 0.3 + (k + 0.5) * 0.05;
                V[p] = 0.05 * 0.05 * 0.05;
                double syy = -block_mat.density * g * cos(th) * (H - X[3 * p + 1]);
                double sxx = nu / (1 - nu) * syy;
                double st[6] = {sxx, syy, sxx, 0, 0, 0};
                memcpy(S6 + 6 * p, st, sizeof st);
            }
    mpm_body_desc b = {0};
    b.n_points = NP;
    b.x = X;
    b.volume = V;
    b.stress = S6;
    mpm_friction_desc fr = {2, mu};
    mpm_case c = {0};
    c.grid.dim = 3;
    c.grid.h[0] = c.grid.h[1] = c.grid.h[2] = 0.1;
    c.grid.nodes[0] = 31;
    c.grid.nodes[1] = 8;
    c.grid.nodes[2] = 21;
    c.method = MPM_METHOD_GIMP;
    c.update = MPM_MUSL;
    c.gravity[0] = g * sin(th) * cos(ph);
    c.gravity[1] = -g * cos(th);
    c.gravity[2] = g * sin(th) * sin(ph);
    c.n_materials = 1;
    c.materials = &block_mat;
    c.n_bodies = 1;
    c.bodies = &b;
    c.bc.n_friction = 1;
    c.bc.friction = &fr;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    free(X);
    CHECKF(s, "%s", TERR(&err));
    double st = 0, stt = 0, sv[3] = {0, 0, 0}, stv[3] = {0, 0, 0}, cnt = 0;
    int rc = 0;
    while (!rc && mpm_sim_time(s) < 0.4) {
        rc = mpm_sim_step(s);
        mpm_energy e;
        mpm_sim_energy(s, &e);
        double t = mpm_sim_time(s);
        if (t < 0.1) continue;
        st += t;
        stt += t * t;
        cnt += 1;
        for (int d = 0; d < 3; d++) {
            sv[d] += e.momentum[d] / e.mass;
            stv[d] += t * e.momentum[d] / e.mass;
        }
    }
    mpm_sim_destroy(&s);
    CHECK(rc == 0);
    double a[3];
    for (int d = 0; d < 3; d++) a[d] = (cnt * stv[d] - st * sv[d]) / (cnt * stt - st * st);
    double at = sqrt(a[0] * a[0] + a[2] * a[2]), a_ex = g * (sin(th) - mu * cos(th));
    TLOG("3D GIMP MUSL: a = (%.5f, %.2e, %.5f), |a_t| = %.5f (exact %.5f, rel err %.2e), a_z/a_x "
         "= %.5f (tan 30 = %.5f)",
         a[0], a[1], a[2], at, a_ex, fabs(at - a_ex) / a_ex, a[2] / a[0], tan(ph));
    CHECK_NEAR(at, a_ex, 0.01 * a_ex);
    CHECK_NEAR(a[2] / a[0], tan(ph), 0.01 * tan(ph));
}

/* Below the friction angle (theta 10 deg, tan 10 = 0.176 < mu = 0.3) the
 * block stays: its centre of mass moves less than 3e-4 m (h / 300; the
 * elastic shear under the suddenly applied tangential load swings the top
 * by up to ~2e-4) in 0.5 s, where sliding freely it would move 0.22 m. */
TEST(mpm_cond_block_sticks)
{
    mpm_method ms[] = {MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2, MPM_METHOD_CPDI};
    for (int i = 0; i < 3; i++) {
        slide_res r;
        CHECK(slide(ms[i], MPM_MUSL, 10, 0.3, 0.5, 0.1, 1, &r) == 0);
        TLOG("%-8s MUSL: displacement %.3e m, fitted a = %.3e, friction work %.3e J", mname(ms[i]),
             r.dx, r.a, r.wf);
        CHECK_LT(fabs(r.dx), 3e-4);
        CHECK_LT(fabs(r.a), 1e-3);
    }
}

/* ---- prescribed velocity ---- */

typedef struct {
    double vface_err; /* max |v_face - v(t)| / v0 over the steps */
    double sig;       /* mean stress over x in [0.1, 0.3] at the end */
    double front;     /* where the stress first falls below half sig, from the left */
    double wp, ks;    /* prescribed work, kinetic + strain at the end */
    double t;
} bar_res;

/* A 1D bar [0, 1] (E = rho = 1, c = 1), 100 cells, ppc 2, pushed at x_lo
 * by the velocity v0 f(t) (tf NULL: constant), to t_end. */
static int bar_push(mpm_method m, mpm_update up, double v0, const mpm_timefn *tf, double t_end,
                    int threads, bar_res *r)
{
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 1.0,
                             .poisson_ratio = 0.0,
                             .density = 1.0};
    mpm_body_desc b = {0};
    b.shape = MPM_SHAPE_BOX;
    b.lo[0] = 0.0;
    b.hi[0] = 1.0;
    b.ppc = 2;
    mpm_prescribed_desc pr = {0};
    pr.face = 0;
    pr.mask = 1;
    pr.value[0] = v0;
    pr.time_function = tf;
    mpm_case c = {0};
    c.grid.dim = 1;
    c.grid.h[0] = 0.01;
    c.grid.nodes[0] = 111;
    c.method = m;
    c.update = up;
    c.dt = 0.004;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 1;
    c.bodies = &b;
    c.n_prescribed = 1;
    c.prescribed = &pr;
    c.threads = threads;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    if (!s) {
        TLOG("%s", TERR(&err));
        return -1;
    }
    r->vface_err = 0;
    while (mpm_sim_time(s) < t_end - 1e-12) {
        if (mpm_sim_step(s)) {
            TLOG("%s", TERR(mpm_sim_error(s)));
            mpm_sim_destroy(&s);
            return -1;
        }
        int ijk[3] = {0, 0, 0};
        double mass, q[3];
        mpm_sim_node(s, ijk, &mass, q);
        double want = v0 * mpm_timefn_eval(tf, mpm_sim_time(s));
        if (mass > 0) {
            double err1 = fabs(q[0] / mass - want) / fabs(v0);
            if (err1 > r->vface_err) r->vface_err = err1;
        }
    }
    mpm_energy e;
    mpm_sim_energy(s, &e);
    r->wp = e.prescribed_work;
    r->ks = e.kinetic + e.strain;
    r->t = mpm_sim_time(s);
    size_t n = mpm_sim_particles(s);
    double *x = malloc(n * 7 * sizeof *x);
    if (!x) return -1;
    double *sg = x + n;
    mpm_snapshot sn = {.x = x, .stress = sg};
    mpm_sim_snapshot(s, &sn);
    double ssum = 0, cnt = 0;
    for (size_t p = 0; p < n; p++)
        if (x[p] > 0.1 && x[p] < 0.3) {
            ssum += sg[6 * p];
            cnt++;
        }
    r->sig = ssum / cnt;
    r->front = -1;
    for (size_t p = 0; p < n && r->front < 0; p++) /* generated left to right */
        if (fabs(sg[6 * p]) < 0.5 * fabs(r->sig)) r->front = x[p];
    free(x);
    mpm_sim_destroy(&s);
    return 0;
}

/* the continuum's work on the bar (rho = c = 1): |sigma| v0 t = v0^2 t */
static double rho_c_v0_work(double v0, double t)
{
    return v0 * v0 * t;
}

/* Pushing at constant v0 = 1e-3 (a 1-step ramp from 0, so that the FLIP
 * particles take the start too): the face node's velocity is v0 to
 * round-off (1e-12); at t = 0.5 the front stands at c t = 0.5 (within
 * 2 h), the stress behind it is -rho c v0 (within 2 %), and the
 * prescribed work equals K + S (within 2 %; exactly rho c v0^2 t in the
 * continuum). */
TEST(mpm_cond_prescribed_bar)
{
    double v0 = 1e-3;
    mpm_timefn ramp = {MPM_TF_RAMP, 1.0, 0.0, 0.004, 0, NULL, NULL};
    mpm_method ms[] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2, MPM_METHOD_BSPLINE3};
    mpm_update us[] = {MPM_MUSL, MPM_USF, MPM_USL};
    for (int i = 0; i < 4; i++)
        for (int u = 0; u < 3; u++) {
            bar_res r;
            CHECK(bar_push(ms[i], us[u], v0, &ramp, 0.5, 1, &r) == 0);
            double ex = rho_c_v0_work(v0, r.t);
            TLOG("%-8s %s: face v err %.1e, sigma %.6e (exact %.6e), front %.3f (exact %.3f), "
                 "W_p %.6e, K + S %.6e (rel diff %.2e; continuum %.6e)",
                 mname(ms[i]),
                 u == 0   ? "MUSL"
                 : u == 1 ? "USF "
                          : "USL ",
                 r.vface_err, r.sig, -v0, r.front, r.t, r.wp, r.ks, fabs(r.wp - r.ks) / r.ks, ex);
            CHECK_LT(r.vface_err, 1e-12);
            CHECK_NEAR(r.sig, -v0, 0.02 * v0);
            CHECK_NEAR(r.front, r.t, 0.02);
            CHECK_NEAR(r.wp, r.ks, 0.02 * r.ks);
        }
}

/* RAMP (0 before 0.1, 1 after 0.3) and TABLE histories: the face node's
 * velocity after each step is v0 f(t^{n+1}) to round-off (1e-12 of v0). */
TEST(mpm_cond_prescribed_history)
{
    double tt[] = {0.0, 0.1, 0.2, 0.4}, tv[] = {0.0, 1.0, -0.5, 0.25};
    mpm_timefn ramp = {MPM_TF_RAMP, 1.0, 0.1, 0.3, 0, NULL, NULL};
    mpm_timefn table = {MPM_TF_TABLE, 0.0, 0, 0, 4, tt, tv};
    CHECK_NEAR(mpm_timefn_eval(&ramp, 0.2), 0.5, 1e-15);
    CHECK_NEAR(mpm_timefn_eval(&ramp, 0.05), 0.0, 0);
    CHECK_NEAR(mpm_timefn_eval(&ramp, 0.5), 1.0, 0);
    CHECK_NEAR(mpm_timefn_eval(&table, 0.15), 0.25, 1e-15);
    CHECK_NEAR(mpm_timefn_eval(&table, 0.3), -0.125, 1e-15);
    CHECK_NEAR(mpm_timefn_eval(&table, 9.0), 0.25, 0);
    CHECK_NEAR(mpm_timefn_eval(&table, -1.0), 0.0, 0);
    const mpm_timefn *fs[] = {&ramp, &table};
    for (int k = 0; k < 2; k++)
        for (int u = 0; u < 2; u++) {
            bar_res r;
            CHECK(bar_push(MPM_METHOD_GIMP, u ? MPM_USF : MPM_MUSL, 1e-3, fs[k], 0.5, 1, &r) == 0);
            TLOG("%s %s: max face velocity error %.2e of v0; W_p %.6e, K + S %.6e",
                 k ? "TABLE" : "RAMP ", u ? "USF " : "MUSL", r.vface_err, r.wp, r.ks);
            CHECK_LT(r.vface_err, 1e-12);
        }
}

/* Two threads (the node passes split the friction and prescribed nodes
 * between them, each summing its share of the work): the sliding block's
 * acceleration, friction work and the bar's prescribed work agree with
 * one thread's to 1e-6 (the sums' order differs). */
TEST(mpm_cond_two_threads)
{
    slide_res r1, r2;
    CHECK(slide(MPM_METHOD_GIMP, MPM_MUSL, 30, 0.2, 0.3, 0.1, 1, &r1) == 0);
    CHECK(slide(MPM_METHOD_GIMP, MPM_MUSL, 30, 0.2, 0.3, 0.1, 2, &r2) == 0);
    TLOG("sliding block: a %.9f / %.9f, friction work %.9g / %.9g (1 / 2 threads)", r1.a, r2.a,
         r1.wf, r2.wf);
    CHECK_NEAR(r2.a, r1.a, 1e-6 * fabs(r1.a));
    CHECK_NEAR(r2.wf, r1.wf, 1e-6 * r1.wf);
    bar_res b1, b2;
    CHECK(bar_push(MPM_METHOD_MPM, MPM_USF, 1e-3, NULL, 0.2, 1, &b1) == 0);
    CHECK(bar_push(MPM_METHOD_MPM, MPM_USF, 1e-3, NULL, 0.2, 2, &b2) == 0);
    TLOG("pushed bar: prescribed work %.12g / %.12g", b1.wp, b2.wp);
    CHECK_NEAR(b2.wp, b1.wp, 1e-6 * b1.wp);
}

/* ---- a prescribed face that leaves the body ---- */

/* A 1 x 0.5 block between rollers (x_lo, y_lo, y_hi), compressed by face
 * x_hi moving at -v0 (ramped in over T/5) until the block is shortened by
 * `strain` at T = 1 s (quasi-static: 20 p-wave periods).  *err: the
 * largest |column-mean sigma_xx / (-M strain) - 1| over the columns of
 * width h; *warned: mpm_sim_warnings() at the end. */
static int face_press(mpm_method m, double strain, double *err, int *warned, char *msg, size_t n)
{
    double E = 1e6, nu = 0.3, M = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)), h = 0.1, T = 1;
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = E,
                             .poisson_ratio = nu,
                             .density = 1000};
    mpm_body_desc b = {0};
    b.shape = MPM_SHAPE_BOX;
    b.hi[0] = 1;
    b.hi[1] = 0.5;
    b.ppc = 2;
    mpm_timefn tf = {.kind = MPM_TF_RAMP, .value = 1, .t0 = 0, .t1 = 0.2 * T};
    mpm_prescribed_desc pr = {.face = 1, .mask = 1, .time_function = &tf};
    pr.value[0] = -strain / (0.9 * T);
    mpm_case c = {0};
    c.grid.dim = 2;
    c.grid.h[0] = c.grid.h[1] = h;
    c.grid.nodes[0] = 11;
    c.grid.nodes[1] = 6;
    c.method = m;
    c.update = MPM_MUSL;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 1;
    c.bodies = &b;
    c.bc.face_mask[0] = 1;
    c.bc.face_mask[2] = c.bc.face_mask[3] = 2;
    c.n_prescribed = 1;
    c.prescribed = &pr;
    mpm_sim *s = mpm_sim_new(&c, NULL, NULL);
    if (!s) return -1;
    int rc = 0;
    while (!rc && mpm_sim_time(s) < T) rc = mpm_sim_step(s);
    size_t np = mpm_sim_particles(s);
    double *x = malloc(np * 8 * sizeof *x), *sig = x ? x + 2 * np : NULL, sum[10] = {0};
    int cnt[10] = {0};
    if (!x) rc = -1;
    if (!rc) {
        mpm_snapshot sn = {.x = x, .stress = sig};
        mpm_sim_snapshot(s, &sn);
        for (size_t p = 0; p < np; p++) {
            int k = (int)(x[2 * p] / h);
            k = k < 0 ? 0 : k > 9 ? 9 : k;
            sum[k] += sig[6 * p];
            cnt[k]++;
        }
        *err = 0;
        for (int k = 0; k < 10; k++)
            if (cnt[k]) *err = fmax(*err, fabs(sum[k] / cnt[k] / (-M * strain) - 1));
        *warned = mpm_sim_warnings(s, msg, n);
    }
    free(x);
    mpm_sim_destroy(&s);
    return rc;
}

/* The face's normal travel against the stress next to it: 0.01 cells
 * (strain 1e-3) stays within 2 % and gives no warning; 0.3 cells (3 %)
 * is 25-45 % off next to the face (measured: GIMP 1.43, BSPLINE2 1.28 of
 * the exact stress) and the run carries a warning naming the source, the
 * face and its travel.  (Between, the error grows as about 1.2 x the
 * travel in cells: 0.05 cells 5-6 %, the warning's threshold.) */
TEST(mpm_cond_face_travel_warning)
{
    mpm_method ms[] = {MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2};
    for (int i = 0; i < 2; i++) {
        double e1, e3;
        int w1, w3;
        char m1[600], m3[600];
        CHECK(face_press(ms[i], 1e-3, &e1, &w1, m1, sizeof m1) == 0);
        CHECK(face_press(ms[i], 3e-2, &e3, &w3, m3, sizeof m3) == 0);
        TLOG("%-8s travel 0.01 cells: stress error %.3f, %s", mname(ms[i]), e1,
             w1 ? m1 : "no warning");
        TLOG("%-8s travel 0.3 cells: stress error %.3f, %s", mname(ms[i]), e3,
             w3 ? m3 : "no warning");
        CHECK(!w1 && e1 < 0.02);
        CHECK(w3 && e3 > 0.2);
        CHECK(strstr(m3, "prescribed[0] moved face x_hi 0.3") != NULL);
    }
}

/* ---- a ramped traction ---- */

/* A 1D bar [0, 1] (E = rho = 1), roller at x_lo, pulled at its end by a
 * traction T = 1e-3 ramped from 0 at t = 0 to T at t = 20 (five periods
 * 4 L / c of the bar: the ramp excites no oscillation) and held to t = 22,
 * with every accepted method (MPM, GIMP, BSPLINE2, CPDI) and update
 * (MPM without USL, refused) (measured: within 0.36 %, balance 6.6e-4).
 * Quasi-static: the last particle's displacement is T x / E (within 1 %),
 * and the external work, integrated with the force at each step's midpoint
 * time, equals K + S (within 1 %) and 1/2 T u(L) (within 2 %). */
TEST(mpm_cond_ramped_traction)
{
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 1.0,
                             .poisson_ratio = 0.0,
                             .density = 1.0};
    mpm_method ms[] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2, MPM_METHOD_BSPLINE3,
                       MPM_METHOD_CPDI};
    mpm_update us[] = {MPM_MUSL, MPM_USL, MPM_USF};
    for (int i = 0; i < 15; i++) {
        if (ms[i / 3] == MPM_METHOD_MPM && us[i % 3] == MPM_USL) continue; /* refused */
        mpm_body_desc b = {0};
        b.shape = MPM_SHAPE_BOX;
        b.lo[0] = 0.0;
        b.hi[0] = 1.0;
        b.ppc = 2;
        double T = 1e-3;
        mpm_timefn ramp = {MPM_TF_RAMP, 1.0, 0.0, 20.0, 0, NULL, NULL};
        mpm_traction_desc tr = {{0.99}, {1.0}, 0, 0, {T}, &ramp};
        mpm_case c = {0};
        c.grid.dim = 1;
        c.grid.h[0] = 0.01;
        c.grid.nodes[0] = 111;
        c.method = ms[i / 3];
        c.update = us[i % 3];
        c.dt = 0.005;
        c.n_materials = 1;
        c.materials = &mat;
        c.n_bodies = 1;
        c.bodies = &b;
        c.n_tractions = 1;
        c.tractions = &tr;
        c.bc.face_mask[0] = 1;
        mpm_error err;
        mpm_sim *s = mpm_sim_new(&c, NULL, &err);
        CHECKF(s, "%s", TERR(&err));
        size_t n = mpm_sim_particles(s);
        double *x0 = malloc(n * 2 * sizeof *x0), *x = x0 + n;
        CHECK(x0);
        mpm_snapshot sn = {.x = x0};
        mpm_sim_snapshot(s, &sn);
        int rc = mpm_sim_run(s, 4400);
        mpm_snapshot sn2 = {.x = x};
        mpm_sim_snapshot(s, &sn2);
        mpm_energy e;
        mpm_sim_energy(s, &e);
        double u = x[n - 1] - x0[n - 1], u_ex = T * x0[n - 1];
        TLOG("%-8s %-4s: t %.3f, u(L) %.6e (exact %.6e, rel err %.2e), W_ext %.6e, K + S %.6e "
             "(rel diff %.2e), 1/2 T u %.6e",
             mname(ms[i / 3]),
             us[i % 3] == MPM_MUSL  ? "MUSL"
             : us[i % 3] == MPM_USL ? "USL"
                                    : "USF",
             mpm_sim_time(s), u, u_ex, fabs(u - u_ex) / u_ex, e.external_work, e.kinetic + e.strain,
             fabs(e.external_work - e.kinetic - e.strain) / e.external_work, 0.5 * T * u);
        free(x0);
        mpm_sim_destroy(&s);
        CHECK(rc == 0);
        CHECK_NEAR(u, u_ex, 0.01 * u_ex);
        CHECK_NEAR(e.external_work, e.kinetic + e.strain, 0.01 * e.external_work);
        CHECK_NEAR(e.external_work, 0.5 * T * u, 0.02 * e.external_work);
    }
}

/* ---- errors ---- */

/* checks the case and expects MPM_EINVAL with the field path `field` */
static int expect_err(const mpm_case *c, const char *field)
{
    mpm_error err;
    int rc = mpm_case_check(c, NULL, &err);
    char txt[512];
    mpm_error_text(&err, MPM_FIELD_PROTO, txt, sizeof txt);
    TLOG("%s", rc ? txt : "(accepted)");
    return rc == MPM_EINVAL && strncmp(txt, field, strlen(field)) == 0 && txt[strlen(field)] == ':';
}

TEST(mpm_cond_errors)
{
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 1.0,
                             .poisson_ratio = 0.0,
                             .density = 1.0};
    mpm_body_desc b = {0};
    b.shape = MPM_SHAPE_BOX;
    b.lo[0] = b.lo[1] = 0.2;
    b.hi[0] = b.hi[1] = 0.6;
    b.ppc = 1;
    mpm_case c = {0};
    c.grid.dim = 2;
    c.grid.h[0] = c.grid.h[1] = 0.1;
    c.grid.nodes[0] = c.grid.nodes[1] = 11;
    c.method = MPM_METHOD_GIMP;
    c.update = MPM_MUSL;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 1;
    c.bodies = &b;
    CHECK(mpm_case_check(&c, NULL, NULL) == 0);

    /* friction */
    mpm_friction_desc fr = {4, 0.3};
    c.bc.n_friction = 1;
    c.bc.friction = &fr;
    CHECK(expect_err(&c, "boundary.friction[0].face")); /* z_lo on a 2D grid */
    fr.face = 2;
    fr.mu = -0.1;
    CHECK(expect_err(&c, "boundary.friction[0].mu"));
    fr.mu = 0.3;
    c.bc.face_mask[2] = 3; /* a wall fixes the tangential direction */
    CHECK(expect_err(&c, "boundary.friction[0].face"));
    c.bc.face_mask[2] = 2; /* a roller is fine */
    CHECK(mpm_case_check(&c, NULL, NULL) == 0);

    /* time functions */
    double tt[] = {0.0, 0.2, 0.2}, tv[] = {0, 1, 2};
    mpm_timefn tf = {MPM_TF_TABLE, 0, 0, 0, 3, tt, tv};
    mpm_prescribed_desc pr = {0};
    pr.face = 1; /* x_hi */
    pr.mask = 1;
    pr.value[0] = 0.1;
    pr.time_function = &tf;
    c.n_prescribed = 1;
    c.prescribed = &pr;
    CHECK(expect_err(&c, "prescribed[0].time_function.t[2]"));
    tt[2] = 0.3;
    tv[1] = NAN;
    CHECK(expect_err(&c, "prescribed[0].time_function.v[1]"));
    tv[1] = 1;
    mpm_timefn ramp = {MPM_TF_RAMP, 1, 0.5, 0.5, 0, NULL, NULL};
    pr.time_function = &ramp;
    CHECK(expect_err(&c, "prescribed[0].time_function.t1"));
    pr.time_function = &tf;
    /* x_hi shares its corner nodes with y_lo, a friction face: x is
     * tangential there (allowed), y its normal (refused) */
    CHECK(mpm_case_check(&c, NULL, NULL) == 0);
    pr.mask = 3;
    CHECK(expect_err(&c, "prescribed[0].face"));
    pr.mask = 1;
    c.bc.n_friction = 0;
    c.bc.face_mask[2] = 0;
    CHECK(mpm_case_check(&c, NULL, NULL) == 0);
    /* a prescribed direction that a face fixes */
    c.bc.face_mask[1] = 1;
    CHECK(expect_err(&c, "prescribed[0].face"));
    c.bc.face_mask[1] = 0;
    /* on a node set: a node a NodeFix fixes */
    int ijk[3] = {5, 5, 0}, bijk[3] = {5, 5, 0};
    unsigned bm = 3;
    c.bc.n_nodes = 1;
    c.bc.node_ijk = bijk;
    c.bc.node_mask = &bm;
    pr.face = -1;
    pr.n_nodes = 1;
    pr.node_ijk = ijk;
    CHECK(expect_err(&c, "prescribed[0].ijk[0]"));
    ijk[0] = 11;
    CHECK(expect_err(&c, "prescribed[0].ijk[0]")); /* outside the grid */
    ijk[0] = 4;
    CHECK(mpm_case_check(&c, NULL, NULL) == 0);
    pr.mask = 4;
    CHECK(expect_err(&c, "prescribed[0].mask"));
    pr.mask = 1;
    /* the same direction prescribed twice */
    mpm_prescribed_desc two[2] = {pr, pr};
    two[1].mask = 3;
    c.prescribed = two;
    c.n_prescribed = 2;
    CHECK(expect_err(&c, "prescribed[1].ijk[0]"));
    c.n_prescribed = 1;
    c.prescribed = &pr;
    /* node sets on B-splines */
    c.bc.n_nodes = 0;
    c.method = MPM_METHOD_BSPLINE2;
    CHECK(expect_err(&c, "prescribed[0].ijk"));
    /* a traction's time function */
    c.method = MPM_METHOD_GIMP;
    c.n_prescribed = 0;
    mpm_timefn bad = {(mpm_timefn_kind)7, 1, 0, 0, 0, NULL, NULL};
    mpm_traction_desc trc = {{0.2, 0.2}, {0.6, 0.6}, 0, 0, {1, 0}, &bad};
    c.n_tractions = 1;
    c.tractions = &trc;
    CHECK(expect_err(&c, "tractions[0].time_function.kind"));
}

/* ---- the wire: the conditions' fields decode into the mpm_case ---- */

TEST(mpm_cond_decode)
{
    static const char json[] =
        "{\"grid\": {\"dim\": 2, \"spacing\": [0.1, 0.1], \"nodes\": [11, 11]}, \"method\": \"GIMP\","
        " \"materials\": [{\"youngsModulus\": 1, \"density\": 1}],"
        " \"bodies\": [{\"box\": {\"lo\": [0.2, 0.2], \"hi\": [0.6, 0.6]}, \"ppc\": 1}],"
        " \"tractions\": [{\"lo\": [0.5, 0.2], \"hi\": [0.6, 0.6], \"value\": [1, 0],"
        "   \"timeFunction\": {\"kind\": \"RAMP\", \"t0\": 0.5, \"t1\": 1.5}}],"
        " \"boundary\": {\"yLo\": 2, \"friction\": [{\"face\": \"Y_LO\", \"mu\": 0.4}]},"
        " \"prescribed\": [{\"face\": \"X_HI\", \"mask\": 1, \"velocity\": [-0.1, 0],"
        "   \"timeFunction\": {\"kind\": \"TABLE\", \"t\": [0, 1, 2], \"v\": [0, 1, 0.5]}},"
        "  {\"ijk\": [3, 5, 4, 5], \"velocity\": [0, 0.2]}],"
        " \"endTime\": 1}";
    mpp_case *mc = NULL;
    mpm_error err;
    int rc = mpp_case_load(json, strlen(json), 0, &mc, &err);
    CHECKF(rc == 0, "%s", TERR(&err));
    const mpm_case *c = &mc->c;
    int ok = c->n_tractions == 1 && c->tractions[0].time_function &&
             c->tractions[0].time_function->kind == MPM_TF_RAMP &&
             c->tractions[0].time_function->value == 1 &&
             c->tractions[0].time_function->t0 == 0.5 && c->tractions[0].time_function->t1 == 1.5 &&
             c->bc.n_friction == 1 && c->bc.friction[0].face == 2 && c->bc.friction[0].mu == 0.4 &&
             c->n_prescribed == 2 && c->prescribed[0].face == 1 && c->prescribed[0].mask == 1 &&
             c->prescribed[0].value[0] == -0.1 && c->prescribed[0].time_function &&
             c->prescribed[0].time_function->n == 3 && c->prescribed[0].time_function->v[1] == 1 &&
             c->prescribed[1].face == -1 && c->prescribed[1].n_nodes == 2 &&
             c->prescribed[1].node_ijk[3] == 4 && c->prescribed[1].node_ijk[4] == 5 &&
             c->prescribed[1].mask == 3 && c->prescribed[1].value[1] == 0.2 &&
             !c->prescribed[1].time_function;
    mpp_case_destroy(&mc);
    CHECK(ok);
    /* a TABLE with fewer values than times is refused by the decoder */
    static const char bad[] =
        "{\"grid\": {\"dim\": 1, \"spacing\": [0.1], \"nodes\": [11]},"
        " \"materials\": [{\"youngsModulus\": 1, \"density\": 1}],"
        " \"bodies\": [{\"box\": {\"lo\": [0.2], \"hi\": [0.6]}, \"ppc\": 1}],"
        " \"prescribed\": [{\"face\": \"X_LO\", \"velocity\": [1],"
        "   \"timeFunction\": {\"kind\": \"TABLE\", \"t\": [0, 1], \"v\": [0]}}],"
        " \"endTime\": 1}";
    rc = mpp_case_load(bad, strlen(bad), 0, &mc, &err);
    char txt[T_ERRLEN];
    mpm_error_text(&err, MPM_FIELD_JSON, txt, sizeof txt);
    TLOG("%s", txt);
    CHECK(rc == MPM_EINVAL && strstr(txt, "prescribed[0].timeFunction.v") == txt);
    /* an empty TABLE (no t, no v; the fuzzer's find: the decoder copied from
     * a NULL array) is refused with the field's name */
    static const char empty[] =
        "{\"grid\": {\"dim\": 1, \"spacing\": [0.1], \"nodes\": [11]},"
        " \"materials\": [{\"youngsModulus\": 1, \"density\": 1}],"
        " \"bodies\": [{\"box\": {\"lo\": [0.2], \"hi\": [0.6]}, \"ppc\": 1}],"
        " \"prescribed\": [{\"face\": \"X_LO\", \"velocity\": [1],"
        "   \"timeFunction\": {\"kind\": \"TABLE\"}}],"
        " \"endTime\": 1}";
    rc = mpp_case_load(empty, strlen(empty), 0, &mc, &err);
    mpm_error_text(&err, MPM_FIELD_JSON, txt, sizeof txt);
    TLOG("%s", txt);
    CHECK(rc == MPM_EINVAL && strstr(txt, "prescribed[0].timeFunction") == txt &&
          strstr(txt, "at least 1 point"));
    mpp_case_destroy(&mc);
}
