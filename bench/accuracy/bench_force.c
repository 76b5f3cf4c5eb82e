/*
 * bench_force.c - per-particle, time-varying forces for the manufactured
 * solution, and the check that they mean what point loads mean.
 *
 * The manufactured solution needs m_p b(X_p, t) on every particle, new every
 * step.  The solver's public mpm_sim_set_particle_forces() (mpm.h) takes
 * them; bench_force_set() is a thin wrapper.  bench_force_selftest() runs a
 * small 1D problem two ways, through mpm_sim_set_particle_forces() and by
 * rebuilding the case every step from a snapshot with one public point
 * force per particle, and requires the two to agree bit for bit, for every
 * enabled method whose whole state a snapshot holds (not CPDI, whose
 * particle domains follow F) and every update, with the FLIP transfer (a
 * rebuild would lose APIC's affine matrices).
 */
#include "bench.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int bench_force_set(mpm_sim *s, const double *f)
{
    return mpm_sim_set_particle_forces(s, f);
}

/* ---- self-test ---- */

#define ST_CELLS 8
#define ST_PPC 3
#define ST_N (ST_CELLS * ST_PPC)
#define ST_STEPS 60

static void st_case(mpm_case *c, mpm_material_desc *mat, mpm_body_desc *b, mpm_method m,
                    mpm_update up)
{
    memset(c, 0, sizeof *c);
    *mat = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                               .youngs_modulus = 1.0,
                               .poisson_ratio = 0.0,
                               .density = 1.0};
    c->grid = (mpm_grid_desc){1, {0}, {1.0 / ST_CELLS}, {ST_CELLS + 1}};
    c->method = m;
    c->update = up;
    c->dt = 0.4 / ST_CELLS;
    c->allow_unstable_dt = 1;
    c->n_materials = 1;
    c->materials = mat;
    c->n_bodies = 1;
    c->bodies = b;
    c->bc.face_mask[0] = c->bc.face_mask[1] = 1;
}

static void st_forces(const double *X, const double *m, double t, double *f)
{
    for (int p = 0; p < ST_N; p++) f[p] = 0.3 * m[p] * sin(2 * M_PI * X[p]) * cos(5 * t);
}

/* One run of ST_STEPS steps; rebuild = 0: one simulation with mpm_sim_set_particle_forces;
 * 1: a new simulation every step with one public point force per particle. */
static int st_run(mpm_method meth, mpm_update up, int rebuild, double *xo, double *vo)
{
    double X[ST_N], x[ST_N], v[ST_N], vol[ST_N], m[ST_N], hl[ST_N], sig[ST_N * 6], f[ST_N];
    double h = 1.0 / ST_CELLS;
    for (int p = 0; p < ST_N; p++) {
        X[p] = x[p] = (p + 0.5) * h / ST_PPC;
        v[p] = 0.05 * sin(2 * M_PI * X[p]);
        vol[p] = h / ST_PPC;
        m[p] = vol[p];
        hl[p] = 0.5 * h / ST_PPC;
    }
    memset(sig, 0, sizeof sig);
    mpm_material_desc mat;
    mpm_body_desc b;
    mpm_case c;
    if (!rebuild) {
        memset(&b, 0, sizeof b);
        b.n_points = ST_N;
        b.x = x;
        b.volume = vol;
        b.mass = m;
        b.v = v;
        b.half_length = hl;
        st_case(&c, &mat, &b, meth, up);
        mpm_sim *s = mpm_sim_new(&c, NULL, NULL);
        if (!s) return -1;
        double t = 0;
        for (int k = 0; k < ST_STEPS; k++) {
            st_forces(X, m, t, f);
            if (bench_force_set(s, f) || mpm_sim_step(s)) {
                mpm_sim_destroy(&s);
                return -1;
            }
            t = mpm_sim_time(s);
        }
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = xo, .v = vo});
        mpm_sim_destroy(&s);
        return 0;
    }
    double t = 0;
    for (int k = 0; k < ST_STEPS; k++) {
        mpm_traction_desc tr[ST_N];
        st_forces(X, m, t, f);
        for (int p = 0; p < ST_N; p++) {
            memset(&tr[p], 0, sizeof tr[p]);
            tr[p].lo[0] = x[p] - 1e-9;
            tr[p].hi[0] = x[p] + 1e-9;
            tr[p].is_force = 1;
            tr[p].value[0] = f[p];
        }
        memset(&b, 0, sizeof b);
        b.n_points = ST_N;
        b.x = x;
        b.volume = vol;
        b.mass = m;
        b.v = v;
        b.stress = sig;
        b.half_length = hl;
        st_case(&c, &mat, &b, meth, up);
        c.tractions = tr;
        c.n_tractions = ST_N;
        mpm_sim *s = mpm_sim_new(&c, NULL, NULL);
        if (!s) return -1;
        int rc = mpm_sim_step(s);
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = x, .v = v, .stress = sig, .volume = vol});
        mpm_sim_destroy(&s);
        if (rc) return -1;
        t += c.dt;
    }
    memcpy(xo, x, sizeof x);
    memcpy(vo, v, sizeof v);
    return 0;
}

int bench_force_selftest(char *msg, size_t n)
{
    double worst = 0;
    int pairs = 0;
    for (int m = 0; m < bench_n_methods; m++)
        for (int u = 0; u < 3; u++) {
            if (!bench_methods[m].enabled || !bench_methods[m].rebuildable) continue;
            double xa[ST_N], va[ST_N], xb[ST_N], vb[ST_N];
            mpm_method meth = (mpm_method)bench_methods[m].value;
            pairs++;
            if (st_run(meth, (mpm_update)u, 0, xa, va) || st_run(meth, (mpm_update)u, 1, xb, vb)) {
                snprintf(msg, n, "particle forces: the self-test run failed (%s %s)",
                         bench_method_name(meth), bench_update_name((mpm_update)u));
                return -1;
            }
            for (int p = 0; p < ST_N; p++)
                worst = fmax(worst, fmax(fabs(xa[p] - xb[p]), fabs(va[p] - vb[p])));
        }
    snprintf(msg, n,
             "mpm_sim_set_particle_forces vs point forces rebuilt every step: max |difference| "
             "%.3g over %d steps, %d method/update pairs, FLIP (%s)",
             worst, ST_STEPS, pairs, worst == 0 ? "bitwise equal" : "DIFFERENT");
    return worst == 0 ? 0 : -1;
}
