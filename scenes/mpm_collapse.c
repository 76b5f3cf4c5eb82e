/*
 * mpm_collapse.c - the plane-strain granular column collapse: the case (geometry, material,
 * conditions, the geostatic initial stress), the run to rest with the energy balance, the deposit's
 * measures and the experimental reference (mpm_collapse.h).
 */
#include "mpm_collapse.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define COLLAPSE_G 9.81
#define COLLAPSE_RHO 1500.0 /* bulk density of a dry quartz sand (kg/m^3) */
#define COLLAPSE_E 1e6      /* Young's modulus (Pa): elastic strain at the base <= 0.5 % */
#define COLLAPSE_NU 0.3
/* cohesion (Pa): c = 0 stops Drucker-Prager's substepping at the cone's
 * apex (the stress-free particles of the free surface); 10 Pa is 0.7 % of
 * rho g d0 at d0 = 0.1 m, a cohesive length c / (rho g) = 0.7 mm, far
 * below a cell */
#define COLLAPSE_C 10.0
/* at rest: kinetic energy below this fraction of the released potential
 * (the elastic vibrations of the deposit keep about 3e-3 without damping)
 * for COLLAPSE_REST_T seconds */
#define COLLAPSE_REST 5e-3
#define COLLAPSE_REST_T 0.1

double mpm_collapse_ref_runout(double a, double *band)
{
    double lin = 1.2 * a, pw = 1.9 * pow(a, 2.0 / 3.0);
    if (band) *band = 0;
    if (a <= 1.8) return lin;
    if (a >= 2.8) return pw;
    if (band) *band = 0.5 * fabs(pw - lin);
    return 0.5 * (lin + pw);
}

double mpm_collapse_ref_height(double a)
{
    return a <= 1.15 ? a : pow(a, 0.4);
}

void mpm_collapse_free(mpm_collapse_case *cc)
{
    free(cc->x);
    free(cc->vol);
    free(cc->stress);
    cc->x = cc->vol = cc->stress = NULL;
}

int mpm_collapse_setup(const mpm_collapse_cfg *cfg, mpm_collapse_case *cc)
{
    memset(cc, 0, sizeof *cc);
    double d0 = cfg->d0 > 0 ? cfg->d0 : 0.1, h = d0 / cfg->cells, h0 = cfg->a * d0;
    int ppc = cfg->ppc > 0 ? cfg->ppc : 2;
    double phi = cfg->phi > 0 ? cfg->phi : 30.0, dp = h / ppc;
    /* room for 1.6 times the reference run-out, and 2 cells above the column */
    double xmax = d0 * (1.0 + 1.6 * mpm_collapse_ref_runout(cfg->a, NULL)) + 2 * h;
    int nx = (int)ceil(xmax / h) + 1, ny = (int)ceil(h0 / h) + 3;
    int npx = (int)lround(d0 / dp), npy = (int)lround(h0 / dp);
    size_t n = (size_t)npx * (size_t)npy;
    cc->x = malloc(2 * n * sizeof *cc->x);
    cc->vol = malloc(n * sizeof *cc->vol);
    cc->stress = malloc(6 * n * sizeof *cc->stress);
    if (!cc->x || !cc->vol || !cc->stress) {
        mpm_collapse_free(cc);
        return -1;
    }
    /* the geostatic state of the column held by its gate: sigma_yy = -rho g
     * (h0 - y), sigma_xx = K0 sigma_yy with Jaky's K0 = 1 - sin phi, plane
     * strain sigma_zz = nu (sigma_xx + sigma_yy); inside the DP/MC cone for
     * phi >= 20 degrees, so the release alone starts the flow */
    double K0 = 1.0 - sin(phi * M_PI / 180.0);
    for (int j = 0; j < npy; j++)
        for (int i = 0; i < npx; i++) {
            size_t p = (size_t)j * (size_t)npx + (size_t)i;
            double y = (j + 0.5) * dp, syy = -COLLAPSE_RHO * COLLAPSE_G * (h0 - y);
            cc->x[2 * p] = (i + 0.5) * dp;
            cc->x[2 * p + 1] = y;
            cc->vol[p] = dp * dp;
            double *s = cc->stress + 6 * p;
            s[0] = K0 * syy;
            s[1] = syy;
            s[2] = COLLAPSE_NU * (s[0] + s[1]);
            s[3] = s[4] = s[5] = 0;
        }
    cc->mat.model = cfg->model;
    cc->mat.youngs_modulus = COLLAPSE_E;
    cc->mat.poisson_ratio = COLLAPSE_NU;
    cc->mat.density = COLLAPSE_RHO;
    cc->mat.friction_angle = phi;
    cc->mat.dilatancy_angle = 0;
    cc->mat.cohesion = COLLAPSE_C;
    cc->mat.tension_cutoff = 0;
    cc->mat.mc_match = MPM_MC_PLANE_STRAIN;
    cc->body.material = 0;
    cc->body.n_points = n;
    cc->body.x = cc->x;
    cc->body.volume = cc->vol;
    cc->body.stress = cc->stress;
    cc->fr.face = 2; /* y_lo */
    cc->fr.mu = cfg->mu > 0 ? cfg->mu : tan(phi * M_PI / 180.0);
    mpm_case *c = &cc->c;
    c->grid.dim = 2;
    c->grid.h[0] = c->grid.h[1] = h;
    c->grid.nodes[0] = nx;
    c->grid.nodes[1] = ny;
    c->method = cfg->method;
    c->update = MPM_MUSL; /* a friction face refuses USF (mpm_cond_refusals) */
    c->gravity[1] = -COLLAPSE_G;
    c->n_materials = 1;
    c->materials = &cc->mat;
    c->n_bodies = 1;
    c->bodies = &cc->body;
    c->bc.face_mask[0] = 1; /* x_lo: roller (the back wall, frictionless) */
    c->bc.face_mask[1] = 1; /* x_hi: roller (never reached) */
    c->bc.n_friction = 1;
    c->bc.friction = &cc->fr;
    c->threads = cfg->threads;
    cc->d0 = d0;
    cc->h0 = h0;
    cc->xmax = (nx - 1) * h;
    return 0;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

void mpm_collapse_measure(const double *x, size_t n, double dp, double gap, double w, double *front,
                          double *height)
{
    double *xs = malloc(n * sizeof *xs), hmax = 0, f = 0;
    for (size_t p = 0; p < n; p++) {
        if (x[2 * p] < w && x[2 * p + 1] + 0.5 * dp > hmax) hmax = x[2 * p + 1] + 0.5 * dp;
        if (xs) xs[p] = x[2 * p];
    }
    if (xs) {
        qsort(xs, n, sizeof *xs, cmp_double);
        size_t k = 0;
        while (k + 1 < n && xs[k + 1] - xs[k] <= gap) k++;
        f = n ? xs[k] + 0.5 * dp : 0;
        free(xs);
    } else { /* no memory for the sort: the furthest particle */
        for (size_t p = 0; p < n; p++)
            if (x[2 * p] + 0.5 * dp > f) f = x[2 * p] + 0.5 * dp;
    }
    *front = f;
    *height = hmax;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

int mpm_collapse_run(const mpm_collapse_cfg *cfg, mpm_collapse_res *r, mpm_error *err)
{
    memset(r, 0, sizeof *r);
    mpm_collapse_case cc;
    if (mpm_collapse_setup(cfg, &cc)) return mpm_fail(err, MPM_ENOMEM, "", "out of memory");
    mpm_sim *s = mpm_sim_new(&cc.c, NULL, err);
    if (!s) {
        mpm_collapse_free(&cc);
        return err ? err->code : MPM_EINVAL;
    }
    double t0 = now_s();
    double t_min = 2.0 * sqrt(2.0 * cc.h0 / COLLAPSE_G); /* past the fall of the column */
    double t_max = cfg->t_max > 0 ? cfg->t_max : 8.0 * sqrt(cc.h0 / COLLAPSE_G) + 0.5;
    mpm_energy e;
    mpm_sim_energy(s, &e);
    double e0 = e.kinetic + e.strain + e.potential, p0 = e.potential, emax = 0, t_rest = -1;
    int rc = 0, every = 20;
    while (mpm_sim_time(s) < t_max) {
        if (mpm_sim_steps(s) % every == every - 1) mpm_sim_want_energy(s);
        if ((rc = mpm_sim_step(s))) break;
        if (mpm_sim_steps(s) % every) continue;
        mpm_sim_energy(s, &e);
        double bal = e.kinetic + e.strain + e.potential + e.plastic_work + e.friction_work - e0;
        if (fabs(bal) > emax) emax = fabs(bal);
        double drop = p0 - e.potential;
        double t = mpm_sim_time(s);
        if (t > t_min && drop > 0 && e.kinetic < COLLAPSE_REST * drop) {
            if (t_rest < 0) t_rest = t;
            if (t - t_rest >= COLLAPSE_REST_T) {
                r->at_rest = 1;
                break;
            }
        } else {
            t_rest = -1;
        }
    }
    if (rc) {
        if (err) *err = *mpm_sim_error(s);
        mpm_sim_destroy(&s);
        mpm_collapse_free(&cc);
        return rc;
    }
    mpm_sim_energy(s, &e);
    r->seconds = now_s() - t0;
    r->t_end = mpm_sim_time(s);
    r->steps = mpm_sim_steps(s);
    r->wp = e.plastic_work;
    r->wf = e.friction_work;
    r->e_drop = p0 - e.potential;
    r->e_err = r->e_drop > 0 ? emax / r->e_drop : INFINITY;
    size_t n = mpm_sim_particles(s);
    r->particles = n;
    double *x = malloc(2 * n * sizeof *x);
    if (!x) {
        mpm_sim_destroy(&s);
        mpm_collapse_free(&cc);
        return mpm_fail(err, MPM_ENOMEM, "", "out of memory");
    }
    mpm_snapshot sn = {.x = x};
    mpm_sim_snapshot(s, &sn);
    double h = cc.c.grid.h[0], dp = h / (cfg->ppc > 0 ? cfg->ppc : 2), front, height;
    mpm_collapse_measure(x, n, dp, h, h, &front, &height);
    r->runout = (front - cc.d0) / cc.d0;
    r->height = height / cc.d0;
    free(x);
    mpm_sim_destroy(&s);
    mpm_collapse_free(&cc);
    return 0;
}
