/*
 * t_perf.c - the throughput machinery must not change results: the
 * 3-node uGIMP kernels equal the 4-node ones (the node they leave out has
 * weight and gradient exactly zero when lp <= h/2), the family is chosen
 * from the half-widths, sorting particles by cell keeps every public
 * per-particle output in creation order, the step on the team agrees
 * across thread counts, the in-pass energies equal the energy pass, and
 * the arrays are staggered within a page.  The active rows and the node
 * passes' split are in t_rows.c.  No timings here: bin/mpmbench
 * measures those.
 */
#include "mpm.h"
#include "mpm_collapse.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_model.h"
#include "mpm_paper.h"
#include "t.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* A box of material falling onto a wall at y = 0 (gravity, a wall face,
 * an impact that loads the stress), in a grid of 21^dim nodes, h = 0.05. */
static void falling_box(mpm_case *c, mpm_material_desc *mat, mpm_body_desc *b, int dim,
                        mpm_update up)
{
    memset(c, 0, sizeof *c);
    memset(b, 0, sizeof *b);
    *mat = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                               .youngs_modulus = 1000.0,
                               .poisson_ratio = 0.3,
                               .density = 2.0};
    b->shape = MPM_SHAPE_BOX;
    b->ppc = 2;
    double v[3] = {0.3, -0.8, 0.2};
    for (int d = 0; d < dim; d++) {
        b->lo[d] = d == 1 ? 0.02 : 0.31 + 0.02 * d;
        b->hi[d] = b->lo[d] + (dim > 2 ? 0.2 : 0.33);
        b->velocity[d] = v[d];
        c->grid.h[d] = 0.05;
        c->grid.nodes[d] = 21;
    }
    c->grid.dim = dim;
    c->method = MPM_METHOD_GIMP;
    c->update = up;
    c->gravity[1] = -9.81;
    c->bc.face_mask[2] = 7; /* wall at y = 0 */
    c->dt = 2e-4;
    c->n_materials = 1;
    c->materials = mat;
    c->n_bodies = 1;
    c->bodies = b;
}

/* max |a - b| / max(max |a|, tiny) over n values */
static double rel_diff(const double *a, const double *b, size_t n)
{
    double d = 0, m = 1e-300;
    for (size_t i = 0; i < n; i++) {
        d = fmax(d, fabs(a[i] - b[i]));
        m = fmax(m, fabs(a[i]));
    }
    return d / m;
}

TEST(perf_gimp_3_nodes_equal_4_nodes)
{
    static const mpm_update ups[3] = {MPM_USF, MPM_USL, MPM_MUSL};
    for (int dim = 2; dim <= 3; dim++)
        for (int u = 0; u < 3; u++)
            for (int T = 1; T <= 2; T++) {
                mpm_case c;
                mpm_material_desc mat;
                mpm_body_desc b;
                falling_box(&c, &mat, &b, dim, ups[u]);
                c.threads = T;
                mpm_error err;
                mpm_sim *s3 = mpm_sim_new(&c, NULL, &err);
                CHECKF(s3, "%s", TERR(&err));
                mpm_sim *s4 = mpm_sim_new(&c, NULL, &err);
                CHECKF(s4, "%s", TERR(&err));
                CHECK(s3->plan.ns == 3); /* generated particles: lp = h/4 */
                CHECK(mpm_sim_plan_override(s4, "ns=4", NULL) == 0);
                CHECK(s4->plan.ns == 4);
                int rc3 = mpm_sim_run(s3, 40), rc4 = mpm_sim_run(s4, 40);
                CHECKF(rc3 == 0 && rc4 == 0, "%s / %s", TERR(mpm_sim_error(s3)),
                       TERR(mpm_sim_error(s4)));
                size_t n = mpm_sim_particles(s3);
                double *buf = malloc(2 * n * (2 * 3 + 6) * sizeof *buf);
                CHECK(buf);
                double *x3 = buf, *x4 = x3 + n * 3, *v3 = x4 + n * 3, *v4 = v3 + n * 3;
                double *s3g = v4 + n * 3, *s4g = s3g + n * 6;
                mpm_sim_snapshot(s3, &(mpm_snapshot){.x = x3, .v = v3, .stress = s3g});
                mpm_sim_snapshot(s4, &(mpm_snapshot){.x = x4, .v = v4, .stress = s4g});
                double dx = rel_diff(x3, x4, n * (size_t)dim),
                       dv = rel_diff(v3, v4, n * (size_t)dim);
                double ds = rel_diff(s3g, s4g, n * 6), smax = 0;
                for (size_t i = 0; i < n * 6; i++) smax = fmax(smax, fabs(s3g[i]));
                mpm_energy e3, e4;
                mpm_sim_energy(s3, &e3);
                mpm_sim_energy(s4, &e4);
                TLOG("GIMP %dD %s T=%d, %zu points, 40 steps: 3 vs 4 nodes: rel |dx| %.1e, |dv| "
                     "%.1e, |dsigma| %.1e (max |sigma| %.3g), energy %.17g vs %.17g",
                     dim,
                     u == 0   ? "USF"
                     : u == 1 ? "USL"
                              : "MUSL",
                     T, n, dx, dv, ds, smax, e3.total, e4.total);
                free(buf);
                mpm_sim_destroy(&s3);
                mpm_sim_destroy(&s4);
                CHECK(smax > 1.0); /* the impact loaded the body */
                CHECK(dx <= 1e-12 && dv <= 1e-12 && ds <= 1e-12);
                CHECK_NEAR(e3.total, e4.total, 1e-12 * fabs(e4.total));
            }
}

/* Explicit points: the half-widths choose the family. */
TEST(perf_gimp_family_follows_half_width)
{
    double x[4] = {0.4, 0.4, 0.6, 0.45}, vol[2] = {0.0025, 0.0025};
    double hl[2][4] = {{0.025, 0.025, 0.025, 0.025}, {0.025, 0.025, 0.025, 0.0251}};
    for (int k = 0; k < 2; k++) {
        mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                                 .youngs_modulus = 1000.0,
                                 .poisson_ratio = 0.3,
                                 .density = 2.0};
        mpm_body_desc b = {0};
        b.n_points = 2;
        b.x = x;
        b.volume = vol;
        b.half_length = hl[k];
        mpm_case c = {0};
        c.grid = (mpm_grid_desc){2, {0, 0, 0}, {0.05, 0.05, 0}, {21, 21, 0}};
        c.method = MPM_METHOD_GIMP;
        c.n_materials = 1;
        c.materials = &mat;
        c.n_bodies = 1;
        c.bodies = &b;
        mpm_error err;
        mpm_sim *s = mpm_sim_new(&c, NULL, &err);
        CHECKF(s, "%s", TERR(&err));
        int ns = s->plan.ns, rc3 = mpm_sim_plan_override(s, "ns=3", NULL);
        CHECK(mpm_sim_step(s) == 0);
        /* the other count, after a step (the same one is no change) */
        int late = mpm_sim_plan_override(s, s->plan.ns == 3 ? "ns=4" : "ns=3", NULL);
        mpm_sim_destroy(&s);
        TLOG("half-widths up to %g (h/2 = 0.025): %d nodes per axis", hl[k][3], ns);
        CHECK(ns == (k == 0 ? 3 : 4));
        CHECK(rc3 == (k == 0 ? 0 : MPM_EINVAL));
        CHECK(late == MPM_EINVAL); /* only before the first step */
    }
}

/* Explicit points given in an order far from the cells' (reversed): the
 * solver sorts them, yet snapshots and per-particle forces speak creation
 * order.  Runs points in natural (rev 0) or reversed (rev 1) order, 50 steps
 * of rigid translation then 20 steps with a force on the point at grid
 * position 560; v gets the final velocities in natural order.  Returns the
 * worst |x - (x0 + v t)| after the translation, or -1 on failure. */
enum { NX = 24, NPTS = NX * NX, PUSHED = 560 };

static double sorted_run(int rev, int T, double *vout, int *sorted)
{
    static double x[2 * NPTS], vol[NPTS], v[2 * NPTS], f[2 * NPTS], xs[2 * NPTS], vs[2 * NPTS];
    for (int i = 0; i < NPTS; i++) {
        int k = rev ? NPTS - 1 - i : i;
        x[2 * i] = 0.3 + 0.0125 * (k % NX + 0.5);
        x[2 * i + 1] = 0.3 + 0.0125 * (k / NX + 0.5);
        vol[i] = 0.0125 * 0.0125;
        v[2 * i] = 0.5;
        v[2 * i + 1] = -0.25;
        f[2 * i] = 0;
        f[2 * i + 1] = k == PUSHED ? 1e-3 : 0;
    }
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 1000.0,
                             .poisson_ratio = 0.3,
                             .density = 2.0};
    mpm_body_desc b = {0};
    b.n_points = NPTS;
    b.x = x;
    b.volume = vol;
    b.v = v;
    mpm_case c = {0};
    c.grid = (mpm_grid_desc){2, {0, 0, 0}, {0.025, 0.025, 0}, {41, 41, 0}};
    c.method = MPM_METHOD_MPM;
    c.dt = 1e-4;
    c.threads = T;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 1;
    c.bodies = &b;
    mpm_sim *s = mpm_sim_new(&c, NULL, NULL);
    if (!s) return -1;
    mpm_sim_snapshot(s, &(mpm_snapshot){.x = xs, .v = vs});
    int same = 1;
    for (int i = 0; i < 2 * NPTS; i++) same &= xs[i] == x[i] && vs[i] == v[i];
    *sorted = s->P.id[0] != 0;
    double worst = -1;
    if (same && mpm_sim_run(s, 50) == 0) {
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = xs});
        double t = mpm_sim_time(s);
        worst = 0;
        for (int i = 0; i < 2 * NPTS; i++) worst = fmax(worst, fabs(xs[i] - (x[i] + v[i] * t)));
        if (mpm_sim_set_particle_forces(s, f) || mpm_sim_run(s, 20)) worst = -1;
        mpm_sim_snapshot(s, &(mpm_snapshot){.v = vs});
        for (int i = 0; i < NPTS; i++) {
            int k = rev ? NPTS - 1 - i : i;
            vout[2 * k] = vs[2 * i];
            vout[2 * k + 1] = vs[2 * i + 1];
        }
    }
    mpm_sim_destroy(&s);
    return worst;
}

TEST(perf_sorting_keeps_creation_order)
{
    static double va[2 * NPTS], vb[2 * NPTS];
    for (int T = 1; T <= 2; T++) {
        int sa, sb;
        double wa = sorted_run(0, T, va, &sa), wb = sorted_run(1, T, vb, &sb);
        double dv = rel_diff(va, vb, 2 * NPTS), push = 0;
        for (int i = 0; i < NPTS; i++) push = fmax(push, fabs(va[2 * i + 1] + 0.25));
        TLOG("T=%d: %d points in natural / reversed order, 50 steps of rigid translation: max "
             "|x - (x0 + v t)| = %.1e / %.1e; then a force on one point: velocities differ by "
             "%.1e (relative), largest push %.2e",
             T, NPTS, wa, wb, dv, push);
        CHECK(wa >= 0 && wb >= 0);
        CHECK(sb);  /* the reversed points were sorted */
        CHECK(!sa); /* the natural ones were in cell order already */
        CHECK(wa < 1e-12 && wb < 1e-12);
        CHECK(push > 1e-6);
        CHECK(dv < 1e-12);
    }
}

/* The step on the team with everything a node pass folds in or splits
 * around: gravity, a wall (BC1, BC2), a traction (point forces scattered
 * serially between the two halves of the node pass), particles crossing
 * cells (the sort moves them), for USF, USL and MUSL.  The same thread
 * count twice gives bitwise the same state; 2 and 3 threads agree with 1
 * up to the order of the sums. */
static int loaded_box(int dim, mpm_update up, int T, double *x, double *v, double *sig, size_t *n)
{
    mpm_case c;
    mpm_material_desc mat;
    mpm_body_desc b;
    falling_box(&c, &mat, &b, dim, up);
    mpm_traction_desc tr;
    memset(&tr, 0, sizeof tr);
    for (int d = 0; d < dim; d++) {
        tr.lo[d] = 0;
        tr.hi[d] = 1.1;
    }
    tr.lo[0] = b.hi[0] - 0.04;
    tr.normal = 0;
    tr.value[0] = dim > 2 ? -2.0 : -20.0; /* the 3D box is lighter */
    tr.value[1] = dim > 2 ? 0.5 : 5.0;
    c.n_tractions = 1;
    c.tractions = &tr;
    c.threads = T;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    if (!s) {
        TLOG("mpm_sim_new: %s", TERR(&err));
        return -1;
    }
    int rc = mpm_sim_run(s, 150);
    if (rc) TLOG("%s", TERR(mpm_sim_error(s)));
    *n = mpm_sim_particles(s);
    mpm_sim_snapshot(s, &(mpm_snapshot){.x = x, .v = v, .stress = sig});
    mpm_sim_destroy(&s);
    return rc;
}

TEST(perf_team_step_threads_agree_with_loads_and_walls)
{
    static const mpm_update ups[3] = {MPM_USF, MPM_USL, MPM_MUSL};
    static const char *const un[3] = {"USF", "USL", "MUSL"};
    enum { MAXP = 4096 };
    static double x[4][MAXP * 3], v[4][MAXP * 3], sg[4][MAXP * 6];
    for (int dim = 2; dim <= 3; dim++)
        for (int u = 0; u < 3; u++) {
            size_t n[4] = {0};
            int rc = 0;
            /* 1, 2, 3 threads, then 2 again */
            for (int k = 0; k < 4; k++)
                rc |= loaded_box(dim, ups[u], k < 3 ? k + 1 : 2, x[k], v[k], sg[k], &n[k]);
            CHECK(rc == 0);
            CHECK(n[0] > 0 && n[0] <= MAXP && n[1] == n[0] && n[2] == n[0] && n[3] == n[0]);
            if (rc || n[0] == 0 || n[0] > MAXP) continue;
            size_t nx = n[0] * (size_t)dim;
            CHECK(memcmp(x[1], x[3], nx * sizeof(double)) == 0);
            CHECK(memcmp(v[1], v[3], nx * sizeof(double)) == 0);
            CHECK(memcmp(sg[1], sg[3], n[0] * 6 * sizeof(double)) == 0);
            for (int k = 1; k < 3; k++) {
                double dx = rel_diff(x[0], x[k], nx), dv = rel_diff(v[0], v[k], nx);
                double ds = rel_diff(sg[0], sg[k], n[0] * 6);
                TLOG("%dD GIMP %s, gravity, wall, traction, 150 steps: %d vs 1 thread: relative "
                     "differences x %.1e, v %.1e, stress %.1e",
                     dim, un[u], k + 1, dx, dv, ds);
                CHECK(dx < 1e-12);
                CHECK(dv < 1e-9);
                CHECK(ds < 1e-9);
            }
        }
}

/* The sort's keys, order check and permutation run on the team: the order
 * (and so every later sum) does not depend on the thread count.  Points in
 * reversed order, sorted at creation by 1, 2 and 3 threads. */
TEST(perf_sort_order_independent_of_threads)
{
    static double x[2 * NPTS], vol[NPTS];
    for (int i = 0; i < NPTS; i++) {
        int k = NPTS - 1 - i;
        x[2 * i] = 0.3 + 0.0125 * (k % NX + 0.5);
        x[2 * i + 1] = 0.3 + 0.0125 * (k / NX + 0.5);
        vol[i] = 0.0125 * 0.0125;
    }
    static uint32_t id[3][NPTS];
    static double px[3][NPTS];
    for (int T = 1; T <= 3; T++) {
        mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                                 .youngs_modulus = 1000.0,
                                 .poisson_ratio = 0.3,
                                 .density = 2.0};
        mpm_body_desc b = {0};
        b.n_points = NPTS;
        b.x = x;
        b.volume = vol;
        mpm_case c = {0};
        c.grid = (mpm_grid_desc){2, {0, 0, 0}, {0.025, 0.025, 0}, {41, 41, 0}};
        c.method = MPM_METHOD_MPM;
        c.dt = 1e-4;
        c.threads = T;
        c.n_materials = 1;
        c.materials = &mat;
        c.n_bodies = 1;
        c.bodies = &b;
        mpm_sim *s = mpm_sim_new(&c, NULL, NULL);
        CHECK(s != NULL);
        if (!s) return;
        memcpy(id[T - 1], s->P.id, sizeof id[0]);
        memcpy(px[T - 1], s->P.x[0], sizeof px[0]);
        mpm_sim_destroy(&s);
    }
    int moved = 0;
    for (int i = 0; i < NPTS; i++) moved |= id[0][i] != (uint32_t)i;
    TLOG("%d points in reversed order, sorted at creation: moved %s; 2 and 3 threads give the "
         "order of 1: %s, %s",
         NPTS, moved ? "yes" : "no", memcmp(id[0], id[1], sizeof id[0]) ? "no" : "yes",
         memcmp(id[0], id[2], sizeof id[0]) ? "no" : "yes");
    CHECK(moved);
    for (int T = 2; T <= 3; T++) {
        CHECK(memcmp(id[0], id[T - 1], sizeof id[0]) == 0);
        CHECK(memcmp(px[0], px[T - 1], sizeof px[0]) == 0);
    }
}

/* mpm_sim_want_energy(): the step sums the energies inside its own passes.
 * The same case run twice, once asking for the energies before every step
 * and once calling mpm_sim_energy() alone (the separate team pass): the
 * energies agree (the same sums in the same order) and the physics is
 * untouched (positions, velocities and stresses bitwise equal).  One more
 * step without the request then falls back to the pass: no stale sums.  The
 * angular momentum (about the origin; the falling box is off it, so it is
 * not zero in 2D and 3D) is the one expression in both (mpm_angmom_add).
 * Every sum is bitwise equal: the in-pass sums and the pass take four
 * particles at a time alike (esum_block(), es_lin4()). */
static double en_diff(const mpm_energy *a, const mpm_energy *b, int dim)
{
    double esc = fmax(fabs(a->kinetic) + fabs(a->strain) + fabs(a->potential), 1e-300);
    double msc = fmax(a->mass, 1e-300);
    double d = fabs(a->kinetic - b->kinetic) / esc;
    d = fmax(d, fabs(a->strain - b->strain) / esc);
    d = fmax(d, fabs(a->potential - b->potential) / esc);
    d = fmax(d, fabs(a->total - b->total) / esc);
    d = fmax(d, fabs(a->mass - b->mass) / msc);
    for (int k = 0; k < dim; k++) d = fmax(d, fabs(a->momentum[k] - b->momentum[k]) / msc);
    double lsc = fmax(fabs(a->angular_momentum[0]) + fabs(a->angular_momentum[1]) +
                          fabs(a->angular_momentum[2]),
                      1e-300);
    for (int k = 0; k < 3; k++)
        d = fmax(d, fabs(a->angular_momentum[k] - b->angular_momentum[k]) / lsc);
    return d;
}

static void energy_case(mpm_case *c, mpm_material_desc *mat, mpm_body_desc *b, int dim,
                        mpm_method meth, mpm_update up, int T)
{
    falling_box(c, mat, b, dim, up);
    c->method = meth;
    c->threads = T;
    if (dim == 1) { /* falling along x onto a wall at x = 0 */
        c->gravity[0] = -9.81;
        c->gravity[1] = 0;
        c->bc.face_mask[2] = 0;
        c->bc.face_mask[0] = 1;
        b->lo[0] = 0.02;
        b->hi[0] = 0.35;
        b->velocity[0] = -0.8;
    }
}

TEST(perf_step_energies_equal_energy_pass)
{
    static const mpm_update ups[3] = {MPM_USF, MPM_USL, MPM_MUSL};
    static const char *const un[3] = {"USF", "USL", "MUSL"};
    enum { STEPS = 40, MAXP = 8192 };
    static double xa[MAXP * 3], xb[MAXP * 3], va[MAXP * 3], vb[MAXP * 3];
    static double sa[MAXP * 6], sb[MAXP * 6];
    double worst = 0;
    int cases = 0;
    static const mpm_method ms[3] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_CPDI};
    static const char *const mn[3] = {"MPM", "GIMP", "CPDI"};
    for (int dim = 1; dim <= 3; dim++)
        for (int m = 0; m < 3; m++)
            for (int u = 0; u < 3; u++)
                for (int T = 1; T <= 2; T++) {
                    mpm_case c;
                    mpm_material_desc mat;
                    mpm_body_desc b;
                    energy_case(&c, &mat, &b, dim, ms[m], ups[u], T);
                    mpm_error err;
                    mpm_sim *sa_ = mpm_sim_new(&c, NULL, &err);
                    CHECKF(sa_, "%s", TERR(&err));
                    mpm_sim *sb_ = mpm_sim_new(&c, NULL, &err);
                    CHECKF(sb_, "%s", TERR(&err));
                    size_t n = mpm_sim_particles(sa_);
                    CHECK(n > 0 && n <= MAXP);
                    double cw = 0, strain = 0, lmax = 0;
                    for (int k = 0; k <= STEPS; k++) {
                        int want = k < STEPS; /* the last step: no request */
                        if (want) mpm_sim_want_energy(sa_);
                        int ra = mpm_sim_step(sa_), rb = mpm_sim_step(sb_);
                        CHECKF(ra == 0 && rb == 0, "%s / %s", TERR(mpm_sim_error(sa_)),
                               TERR(mpm_sim_error(sb_)));
                        /* a step that ends with the guard's check sums
                         * them in its passes, asked or not */
                        int guard = (k + 1) % MPM_GUARD_EVERY == 0;
                        CHECK(sa_->ecache_ok == (want || guard) && sb_->ecache_ok == guard);
                        mpm_energy ea, eb;
                        mpm_sim_energy(sa_, &ea);
                        mpm_sim_energy(sb_, &eb);
                        double d = en_diff(&eb, &ea, dim);
                        CHECKF(d == 0,
                               "%dD %s %s %d thread(s), step %d: energies differ by "
                               "%.3g relative (kinetic %.17g / %.17g, strain %.17g / %.17g, "
                               "potential %.17g / %.17g)",
                               dim, mn[m], un[u], T, k + 1, d, ea.kinetic, eb.kinetic, ea.strain,
                               eb.strain, ea.potential, eb.potential);
                        CHECKF(memcmp(ea.angular_momentum, eb.angular_momentum,
                                      sizeof ea.angular_momentum) == 0,
                               "%dD %s %s %d thread(s), step %d: angular momentum "
                               "(%.17g, %.17g, %.17g) / (%.17g, %.17g, %.17g)",
                               dim, mn[m], un[u], T, k + 1, ea.angular_momentum[0],
                               ea.angular_momentum[1], ea.angular_momentum[2],
                               eb.angular_momentum[0], eb.angular_momentum[1],
                               eb.angular_momentum[2]);
                        cw = fmax(cw, d);
                        strain = fmax(strain, fabs(eb.strain));
                        lmax = fmax(lmax, fabs(eb.angular_momentum[2]));
                    }
                    CHECK(strain > 0);                      /* the strain term is exercised */
                    CHECK(dim == 1 ? lmax == 0 : lmax > 0); /* and the angular momentum */
                    mpm_sim_snapshot(sa_, &(mpm_snapshot){.x = xa, .v = va, .stress = sa});
                    mpm_sim_snapshot(sb_, &(mpm_snapshot){.x = xb, .v = vb, .stress = sb});
                    size_t nx = n * (size_t)dim;
                    CHECK(memcmp(xa, xb, nx * sizeof(double)) == 0);
                    CHECK(memcmp(va, vb, nx * sizeof(double)) == 0);
                    CHECK(memcmp(sa, sb, n * 6 * sizeof(double)) == 0);
                    mpm_sim_destroy(&sa_);
                    mpm_sim_destroy(&sb_);
                    worst = fmax(worst, cw);
                    cases++;
                }
    TLOG(
        "%d cases (1D/2D/3D, MPM/GIMP/CPDI, USF/USL/MUSL, gravity, wall, 1 and 2 threads), %d steps: "
        "energies summed in the step vs the energy pass: worst relative difference %.3g "
        "(angular momentum bitwise equal); positions, velocities, stresses bitwise equal",
        cases, STEPS + 1, worst);
}

/* The disks through their impact (2D; MPM and GIMP USF, BSPLINE2 MUSL;
 * the portable and the AVX2+FMA kernels; 1 and 2 threads): every energy
 * the step sums in its passes (mpm_sim_want_energy()) equals, bit for bit,
 * what the energy pass sums for the same state: both take four particles
 * at a time (esum_block(), es_lin4()), and a difference in their order of
 * operations shows here as last-bit differences, in the strain energy
 * first. */
TEST(perf_step_energies_bitwise_disks)
{
    enum { STEPS = 200 };
    static const mpm_method ms[3] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2};
    static const mpm_update us[3] = {MPM_USF, MPM_USF, MPM_MUSL};
    static const char *const mn[3] = {"MPM USF", "GIMP USF", "BSPLINE2 MUSL"};
    int cases = 0;
    for (int k = 0; k < 2; k++)
        for (int m = 0; m < 3; m++)
            for (int T = 1; T <= 2; T++) {
                mpm_paper ta, tb;
                mpm_paper_disks(&ta, ms[m], us[m], 0.025);
                mpm_paper_disks(&tb, ms[m], us[m], 0.025);
                ta.c.kernels = tb.c.kernels = k ? MPM_KERNELS_AUTO : MPM_KERNELS_PORTABLE;
                ta.c.threads = tb.c.threads = T;
                mpm_error err;
                mpm_sim *a = mpm_sim_new(&ta.c, NULL, &err);
                CHECKF(a, "%s", TERR(&err));
                mpm_sim *b = mpm_sim_new(&tb.c, NULL, &err);
                CHECKF(b, "%s", TERR(&err));
                mpm_paper_free(&ta);
                mpm_paper_free(&tb);
                double smax = 0;
                for (int i = 0; i < STEPS; i++) {
                    mpm_sim_want_energy(a);
                    CHECK(mpm_sim_step(a) == 0 && mpm_sim_step(b) == 0);
                    mpm_energy ea, eb;
                    mpm_sim_energy(a, &ea);
                    mpm_sim_energy(b, &eb);
                    CHECKF(memcmp(&ea.strain, &eb.strain, sizeof ea.strain) == 0 &&
                               memcmp(&ea.kinetic, &eb.kinetic, sizeof ea.kinetic) == 0 &&
                               memcmp(&ea.potential, &eb.potential, sizeof ea.potential) == 0 &&
                               memcmp(&ea.mass, &eb.mass, sizeof ea.mass) == 0 &&
                               memcmp(ea.momentum, eb.momentum, 2 * sizeof(double)) == 0 &&
                               memcmp(ea.angular_momentum, eb.angular_momentum,
                                      sizeof ea.angular_momentum) == 0,
                           "%s kernels, %s, %d thread(s), step %d: in-pass strain %.17g / "
                           "pass %.17g, kinetic %.17g / %.17g, angular momentum %.17g / %.17g",
                           k ? "auto" : "portable", mn[m], T, i + 1, ea.strain, eb.strain,
                           ea.kinetic, eb.kinetic, ea.angular_momentum[2], eb.angular_momentum[2]);
                    smax = fmax(smax, ea.strain);
                }
                CHECK(smax > 0); /* the impact strains the disks */
                mpm_sim_destroy(&a);
                mpm_sim_destroy(&b);
                cases++;
            }
    TLOG("%d cases (portable and %s kernels, MPM/GIMP USF, BSPLINE2 MUSL, 1 and 2 threads), %d "
         "steps each: in-pass energies bitwise equal to the energy pass",
         cases, mpm_kernels_avx2_available() ? "AVX2+FMA" : "auto (portable here)", STEPS);
}

/* The energies summed one particle at a time with the scalar helpers (mpm_strain_density(),
 * whose linear-elastic case is mpm_elastic_stored(); mpm_angmom_add()),
 * slice by slice and combined in thread order: the reference for the pass
 * and the in-pass sums, which take four particles per vector (es_lin4(),
 * esum_block()) with lanes that keep these helpers' operations, so the
 * same bits. */
static void scalar_energies(const mpm_sim *s, mpm_energy *out)
{
    const mpm_particles *P = &s->P;
    int dim = s->dim;
    memset(out, 0, sizeof *out);
    for (int t = 0; t < s->nthreads; t++) {
        size_t a, b;
        mpm_particle_slice(s, t, &a, &b);
        double ek = 0, es = 0, ep = 0, mom[3] = {0, 0, 0}, ms = 0, L[3] = {0, 0, 0};
        for (size_t p = a; p < b; p++) {
            double m = P->m[p], v2 = 0;
            for (int d = 0; d < dim; d++) {
                v2 += P->v[d][p] * P->v[d][p];
                mom[d] += m * P->v[d][p];
                ep -= m * s->gravity[d] * P->x[d][p];
            }
            mpm_angmom_add(P, dim, p, m, L);
            ek += 0.5 * m * v2;
            es += 0.5 * mpm_strain_density(s->mats, P, dim, p) * P->vol[p];
            ms += m;
        }
        out->kinetic += ek;
        out->strain += es;
        out->potential += ep;
        out->mass += ms;
        for (int d = 0; d < dim; d++) out->momentum[d] += mom[d];
        for (int d = 0; d < 3; d++) out->angular_momentum[d] += L[d];
    }
}

/* The energies by the textbook formulas, summed here over the particles'
 * own arrays, against what mpm_sim_energy() returns: the energy pass (and,
 * every MPM_GUARD_EVERY steps, the step's in-pass sums, which the guard's
 * check asks for).  Both take the same four-lane functions (mpm_pass.h),
 * so the bitwise tests above cannot see a wrong formula in them; this one
 * can.  Strain energy of linear elasticity from the stress alone,
 * w = [(1 + nu) sigma:sigma - nu (tr sigma)^2] / (2E) (2D plane strain:
 * sigma_zz = nu (sigma_xx + sigma_yy); 1D: sigma^2 / 2E), kinetic
 * 1/2 m v^2, potential -m g . x, momentum, angular momentum m x cross v,
 * mass.  Within 1e-12 of each sum's scale (the order and form of the
 * arithmetic differ).  And, bit for bit, the scalar sums above
 * (scalar_energies(): what the lanes of es_lin4() and esum_block() must
 * reproduce, which the bitwise tests above compared while the energy pass
 * was scalar). */
TEST(perf_energy_pass_matches_formulas)
{
    enum { STEPS = 48 };
    int cases = 0, cached = 0;
    double worst = 0;
    for (int dim = 1; dim <= 3; dim++)
        for (int k = 0; k < 2; k++)
            for (int T = 1; T <= 2; T++) {
                mpm_case c;
                mpm_material_desc mat;
                mpm_body_desc b;
                energy_case(&c, &mat, &b, dim, MPM_METHOD_GIMP, MPM_USF, T);
                c.kernels = k ? MPM_KERNELS_AUTO : MPM_KERNELS_PORTABLE;
                mpm_error err;
                mpm_sim *s = mpm_sim_new(&c, NULL, &err);
                CHECKF(s, "%s", TERR(&err));
                double E = mat.youngs_modulus, nu = mat.poisson_ratio, smax = 0;
                for (int i = 0; i < STEPS; i++) {
                    CHECK(mpm_sim_step(s) == 0);
                    cached += s->ecache_ok;
                    mpm_energy e, r;
                    mpm_sim_energy(s, &e);
                    scalar_energies(s, &r);
                    CHECKF(memcmp(&e.kinetic, &r.kinetic, sizeof e.kinetic) == 0 &&
                               memcmp(&e.strain, &r.strain, sizeof e.strain) == 0 &&
                               memcmp(&e.potential, &r.potential, sizeof e.potential) == 0 &&
                               memcmp(&e.mass, &r.mass, sizeof e.mass) == 0 &&
                               memcmp(e.momentum, r.momentum, sizeof e.momentum) == 0 &&
                               memcmp(e.angular_momentum, r.angular_momentum,
                                      sizeof e.angular_momentum) == 0,
                           "%dD, %s kernels, %d thread(s), step %d: four-lane sums differ from "
                           "the scalar ones (strain %.17g / %.17g, kinetic %.17g / %.17g)",
                           dim, k ? "auto" : "portable", T, i + 1, e.strain, r.strain, e.kinetic,
                           r.kinetic);
                    const mpm_particles *P = &s->P;
                    double K = 0, S = 0, U = 0, M = 0, mom[3] = {0}, L[3] = {0};
                    double sK = 0, sS = 0, sU = 0, sP = 0, sL = 0;
                    for (size_t p = 0; p < P->n; p++) {
                        double m = P->m[p], x[3] = {0}, v[3] = {0}, sg[6] = {0};
                        for (int d = 0; d < dim; d++) {
                            x[d] = P->x[d][p];
                            v[d] = P->v[d][p];
                        }
                        for (int d = 0; d < dim; d++) {
                            K += 0.5 * m * v[d] * v[d];
                            mom[d] += m * v[d];
                            U -= m * c.gravity[d] * x[d];
                            sU += fabs(m * c.gravity[d] * x[d]);
                            sP += fabs(m * v[d]);
                        }
                        double lp[3] = {x[1] * v[2] - x[2] * v[1], x[2] * v[0] - x[0] * v[2],
                                        x[0] * v[1] - x[1] * v[0]};
                        for (int a = 0; a < 3; a++) {
                            L[a] += m * lp[a];
                            sL += fabs(m * lp[a]);
                        }
                        double w;
                        if (dim == 1) {
                            w = P->sig[0][p] * P->sig[0][p] / (2 * E);
                        } else {
                            sg[0] = P->sig[0][p];
                            sg[1] = P->sig[1][p];
                            sg[2] = dim == 3 ? P->sig[2][p] : nu * (sg[0] + sg[1]);
                            sg[3] = P->sig[3][p];
                            if (dim == 3) {
                                sg[4] = P->sig[4][p];
                                sg[5] = P->sig[5][p];
                            }
                            double ss = sg[0] * sg[0] + sg[1] * sg[1] + sg[2] * sg[2] +
                                        2 * (sg[3] * sg[3] + sg[4] * sg[4] + sg[5] * sg[5]);
                            double tr = sg[0] + sg[1] + sg[2];
                            w = ((1 + nu) * ss - nu * tr * tr) / (2 * E);
                        }
                        S += w * P->vol[p];
                        sS += fabs(w * P->vol[p]);
                        sK += 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
                        M += m;
                    }
                    double d = fabs(e.kinetic - K) / fmax(sK, 1e-300);
                    d = fmax(d, fabs(e.strain - S) / fmax(sS, 1e-300));
                    d = fmax(d, fabs(e.potential - U) / fmax(sU, 1e-300));
                    d = fmax(d, fabs(e.mass - M) / M);
                    for (int a = 0; a < dim; a++)
                        d = fmax(d, fabs(e.momentum[a] - mom[a]) / fmax(sP, 1e-300));
                    for (int a = 0; a < 3; a++)
                        d = fmax(d, fabs(e.angular_momentum[a] - L[a]) / fmax(sL, 1e-300));
                    CHECKF(d <= 1e-12,
                           "%dD, %s kernels, %d thread(s), step %d: energies off their "
                           "formulas by %.3g relative (strain %.17g / %.17g, kinetic %.17g / "
                           "%.17g, potential %.17g / %.17g)",
                           dim, k ? "auto" : "portable", T, i + 1, d, e.strain, S, e.kinetic, K,
                           e.potential, U);
                    worst = fmax(worst, d);
                    smax = fmax(smax, S);
                }
                CHECK(smax > 0); /* the impact strains the box */
                mpm_sim_destroy(&s);
                cases++;
            }
    CHECK(cached == cases * (STEPS / MPM_GUARD_EVERY)); /* the guard's steps: in-pass */
    TLOG("%d cases (1D/2D/3D falling box, GIMP USF, gravity, both kernel sets, 1 and 2 "
         "threads), %d steps: energy pass and in-pass sums against the formulas: worst %.3g "
         "relative, and bitwise equal to the scalar sums (%d of the steps summed in their "
         "passes for the guard)",
         cases, STEPS, worst, cached);
}

/* mpm_sim_snapshot() on the team (each thread its slice of the storage
 * slots, each particle written at its creation number): every field equals,
 * bit for bit, the particle arrays read here slot by slot through P.id, for
 * 1 to 3 threads.  A Drucker-Prager column under gravity with the DET_F
 * volume update carries every field a snapshot can hold (plastic strain,
 * yield flags, F); 40 steps, and one sort, in. */
TEST(perf_snapshot_on_team_matches_arrays)
{
    for (int T = 1; T <= 3; T++) {
        mpm_collapse_cfg cfg;
        memset(&cfg, 0, sizeof cfg);
        cfg.a = 1;
        cfg.cells = 8;
        cfg.method = MPM_METHOD_BSPLINE2;
        cfg.model = MPM_MODEL_DRUCKER_PRAGER;
        mpm_collapse_case cc;
        CHECK(mpm_collapse_setup(&cfg, &cc) == 0);
        cc.c.threads = T;
        cc.c.volume_update = MPM_VOLUME_DET_F;
        mpm_error err;
        mpm_sim *s = mpm_sim_new(&cc.c, NULL, &err);
        mpm_collapse_free(&cc);
        CHECKF(s, "%s", TERR(&err));
        CHECK(mpm_sim_run(s, 40) == 0);
        CHECK(mpm_sim_has_field(s, MPM_FIELD_PLASTIC_STRAIN) &&
              mpm_sim_has_field(s, MPM_FIELD_YIELDED) &&
              mpm_sim_has_field(s, MPM_FIELD_DEFORMATION_GRADIENT));
        const mpm_particles *P = &s->P;
        size_t n = P->n, dim = 2;
        double *x = calloc(n * dim, sizeof *x), *v = calloc(n * dim, sizeof *v),
               *sg = calloc(n * 6, sizeof *sg), *pr = calloc(n, sizeof *pr),
               *vol = calloc(n, sizeof *vol), *ep = calloc(n, sizeof *ep),
               *F = calloc(n * 4, sizeof *F);
        uint8_t *yl = calloc(n, 1);
        CHECK(x && v && sg && pr && vol && ep && F && yl);
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = x,
                                            .v = v,
                                            .stress = sg,
                                            .mean_stress = pr,
                                            .volume = vol,
                                            .plastic_strain = ep,
                                            .deformation_gradient = F,
                                            .yielded = yl});
        size_t bad = 0, moved = 0, yielded = 0;
        for (size_t p = 0; p < n; p++) {
            size_t q = P->id[p];
            moved += q != p;
            double sig[6];
            mpm_particle_stress(&s->mats[P->mat[p]], P, (int)dim, p, sig);
            int ok = memcmp(sig, sg + 6 * q, sizeof sig) == 0 && vol[q] == P->vol[p] &&
                     ep[q] == P->epsp[p] && yl[q] == (P->yld[p] != 0.0) &&
                     pr[q] == (sig[0] + (sig[1] + sig[2])) / 3.0;
            for (size_t d = 0; d < dim; d++)
                ok &= x[q * dim + d] == P->x[d][p] && v[q * dim + d] == P->v[d][p];
            for (int c = 0; c < 4; c++) ok &= F[q * 4 + (size_t)c] == P->F[c][p];
            bad += !ok;
            yielded += yl[q];
        }
        TLOG("%d thread(s): %zu particles, %zu stored away from their creation slot, %zu "
             "yielded: %zu snapshot entries differ from the arrays",
             T, n, moved, yielded, bad);
        CHECK(bad == 0);
        CHECK(yielded > 0); /* the flags are exercised */
        free(x);
        free(v);
        free(sg);
        free(pr);
        free(vol);
        free(ep);
        free(F);
        free(yl);
        mpm_sim_destroy(&s);
    }
}

/* Appends the non-NULL arrays of a grid buffer to a[] (count *n), a
 * field kept in q's storage (mpm_sim.tshare) not again. */
static void grid_arrays(const mpm_gridbuf *b, const double *a[], size_t *n)
{
    const double *f[10] = {b->m,    b->q[0], b->q[1],  b->q[2],  b->f[0],
                           b->f[1], b->f[2], b->q2[0], b->q2[1], b->q2[2]};
    for (int i = 0; i < 10; i++) {
        int again = 0;
        for (int j = 0; j < i; j++) again |= f[j] == f[i];
        if (f[i] && !again) a[(*n)++] = f[i];
    }
}

/* The particle and grid arrays are staggered (mpm_sim.c, stag_alloc()):
 * each starts on a cache line at its own offset within a 4 KiB page, so
 * that element i of the arrays a pass uses side by side neither shares
 * one L1 set nor the low 12 address bits (4K aliasing), as it would at
 * the one page offset where malloc() maps all large blocks (the
 * measurements: docs/performance.md).  Run here: the paper's
 * disks, BSPLINE2 MUSL with APIC on 2 threads (31 arrays: x, v, sigma,
 * B_p, m, V; the grid, 1/m, both threads' buffers) and 3D MPM USF on 3
 * threads; 1/m and the grid's mass are zero before the first step (the
 * blocks come zeroed), a run steps, and destroying frees each block
 * through the pointer malloc() gave (AddressSanitizer's builds check
 * that). */
TEST(perf_arrays_staggered)
{
    for (int k = 0; k < 2; k++) {
        mpm_paper t;
        mpm_sim *s = NULL;
        mpm_error err;
        if (k == 0) {
            mpm_paper_disks(&t, MPM_METHOD_BSPLINE2, MPM_MUSL, 0.05);
            t.c.transfer = MPM_TRANSFER_APIC;
            t.c.threads = 2;
            s = mpm_sim_new(&t.c, NULL, &err);
            mpm_paper_free(&t);
        } else {
            mpm_case c;
            mpm_material_desc mat;
            mpm_body_desc b;
            falling_box(&c, &mat, &b, 3, MPM_USF);
            c.method = MPM_METHOD_MPM;
            c.threads = 3;
            s = mpm_sim_new(&c, NULL, &err);
        }
        CHECKF(s, "mpm_sim_new: %s", err.message);
        const double *a[128];
        size_t n = 0;
        const mpm_particles *P = &s->P;
        for (int d = 0; d < 3; d++) {
            if (P->x[d]) a[n++] = P->x[d];
            if (P->v[d]) a[n++] = P->v[d];
        }
        for (int c = 0; c < 9; c++) {
            if (c < 6 && P->sig[c]) a[n++] = P->sig[c];
            if (P->B[c]) a[n++] = P->B[c];
        }
        a[n++] = P->m;
        a[n++] = P->vol;
        a[n++] = s->minv;
        grid_arrays(&s->g, a, &n);
        for (int t2 = 0; s->tbuf && t2 < s->nthreads; t2++) grid_arrays(&s->tbuf[t2], a, &n);
        size_t unaligned = 0, shared = 0, nonzero = 0;
        for (size_t i = 0; i < n; i++) {
            uintptr_t ai = (uintptr_t)a[i];
            unaligned += ai % 64 != 0;
            for (size_t j = 0; j < i; j++) shared += ai % 4096 == (uintptr_t)a[j] % 4096;
        }
        for (size_t i = 0; i < s->nn; i++) nonzero += s->minv[i] != 0 || s->g.m[i] != 0;
        TLOG("%s: %zu arrays, %zu not on a cache line, %zu pairs at one page offset, %zu "
             "nodes not zero before the first step",
             k ? "3D MPM USF, 3 threads" : "2D BSPLINE2 MUSL APIC, 2 threads", n, unaligned, shared,
             nonzero);
        /* 3D USF: thread 1's and 2's buffers m, q (f in q's storage); 2D
         * MUSL: thread 1's m, q, f (q2 in q's) */
        CHECK(n == (k ? 14u + 1u + 7u + 4u + 2u * 4u : 13u + 1u + 7u + 5u + 5u));
        CHECK(unaligned == 0);
        CHECK(shared == 0);
        CHECK(nonzero == 0);
        /* the private buffers' field of a pass of its own in q's storage */
        for (int t2 = 1; t2 < s->nthreads; t2++)
            CHECK(k ? s->tbuf[t2].f[0] == s->tbuf[t2].q[0] && s->tbuf[t2].q2[0] == NULL
                    : s->tbuf[t2].q2[1] == s->tbuf[t2].q[1] &&
                          s->tbuf[t2].f[1] != s->tbuf[t2].q[1]);
        CHECK(mpm_sim_run(s, 3) == 0);
        mpm_sim_destroy(&s);
        CHECK(s == NULL);
    }
}
