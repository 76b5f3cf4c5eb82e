/*
 * t_rows.c - the active rows and the node passes' split must not
 * change results: the active box and the rows' extents leave the grid
 * outside the particles' supports all zero after every step (2D, 3D and
 * 1D, whose one row the node passes split by nodes), and the passes that
 * reduce the private grids split their work units as mpm_rows.c says.
 * No timings here: bin/mpmbench measures those.
 */
#include "mpm.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_paper.h"
#include "mpm_rows.h"
#include "t.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* A body crossing a large grid: after every step the node masses sum to
 * the particles' mass (nothing stale is left behind the active box). */
TEST(perf_active_box_leaves_no_stale_nodes)
{
    for (int T = 1; T <= 2; T++)
        for (int m = 0; m < 2; m++) {
            mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                                     .youngs_modulus = 1000.0,
                                     .poisson_ratio = 0.3,
                                     .density = 2.0};
            mpm_body_desc b = {0};
            b.shape = MPM_SHAPE_BOX;
            b.ppc = 2;
            b.lo[0] = 0.1;
            b.hi[0] = 0.2;
            b.lo[1] = 0.3;
            b.hi[1] = 0.4;
            b.velocity[0] = 20.0;
            b.velocity[1] = 5.0;
            mpm_case c = {0};
            c.grid = (mpm_grid_desc){2, {0, 0, 0}, {0.02, 0.02, 0}, {51, 51, 0}};
            c.method = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
            c.dt = 2e-4;
            c.threads = T;
            c.n_materials = 1;
            c.materials = &mat;
            c.n_bodies = 1;
            c.bodies = &b;
            mpm_error err;
            mpm_sim *s = mpm_sim_new(&c, NULL, &err);
            CHECKF(s, "%s", TERR(&err));
            mpm_energy e;
            mpm_sim_energy(s, &e);
            double worst = 0;
            for (int step = 0; step < 150; step++) {
                CHECKF(mpm_sim_step(s) == 0, "%s", TERR(mpm_sim_error(s)));
                double mg = 0, q[3];
                for (int j = 0; j < 51; j++)
                    for (int i = 0; i < 51; i++) {
                        double mn;
                        mpm_sim_node(s, (int[3]){i, j, 0}, &mn, q);
                        mg += mn;
                    }
                worst = fmax(worst, fabs(mg - e.mass) / e.mass);
            }
            TLOG("%s T=%d: body moved %.2f cells; worst |sum node mass - mass| / mass = %.1e",
                 m ? "GIMP" : "MPM", T, 20.0 * mpm_sim_time(s) / 0.02, worst);
            mpm_sim_destroy(&s);
            CHECK(worst < 1e-12);
        }
}

/* Marks in sup (one byte per padded node) every node the supports of the
 * particles at x (creation order, dim per particle) can touch: the 2 (MPM)
 * or 4 (GMPM, reaching the ghost layers) nodes per axis from the cell. */
static void mark_supports(const mpm_sim *s, const double *x, size_t n, int dim, int m,
                          unsigned char *sup)
{
    int lo = m ? -1 : 0, cnt = m ? 4 : 2;
    memset(sup, 0, s->nn);
    for (size_t p = 0; p < n; p++) {
        int c0[3] = {0, 0, 0};
        for (int d = 0; d < dim; d++)
            c0[d] = (int)((x[p * (size_t)dim + d] - s->x0[d]) * s->inv_h[d]) + lo;
        for (int k = 0; k < (dim > 2 ? cnt : 1); k++)
            for (int j = 0; j < (dim > 1 ? cnt : 1); j++)
                for (int i = 0; i < cnt; i++) {
                    int ijk[3] = {c0[0] + i, dim > 1 ? c0[1] + j : 0, dim > 2 ? c0[2] + k : 0};
                    size_t node = 0;
                    int in = 1;
                    for (int d = 0; d < 3; d++) {
                        in &= ijk[d] >= 0 && ijk[d] < s->np[d];
                        node += (size_t)ijk[d] * s->stride[d];
                    }
                    if (in) sup[node] = 1;
                }
    }
}

/* Fails (returns -1, with a line) when a node outside sup holds mass or
 * momentum; *mg gets the grid's total mass, *checked counts the nodes
 * outside the supports. */
static int stale_nodes(const mpm_sim *s, const unsigned char *sup, int dim, int step, double *mg,
                       long *checked)
{
    int rc = 0;
    *mg = 0;
    for (size_t node = 0; node < s->nn; node++) {
        double mn = s->g.m[node], qn = 0;
        for (int d = 0; d < dim; d++) qn = fmax(qn, fabs(s->g.q[d][node]));
        *mg += mn;
        if (!sup[node] && (mn != 0 || qn != 0)) {
            TLOG("step %d: node %zu outside the supports has mass %g, |q| %g", step, node, mn, qn);
            rc = -1;
        }
        (*checked) += !sup[node];
    }
    return rc;
}

/* Shapes where one box around the particles is much larger than the nodes
 * they touch, so the active rows' extents matter: (0) a disk (sphere) and a
 * smaller box on a diagonal, moving in opposite directions along x (the
 * extents of their rows grow on one side and shrink on the other; with two
 * threads the split falls in the disk's lower half, where a row shared by
 * both threads reaches further left in the second), and (1) an L of two
 * touching boxes moving diagonally.  After every step no node
 * outside the supports of the step's particles (their positions at the
 * start of the step) holds mass or momentum, the node masses sum to the
 * particles' mass, and the extents cover fewer nodes than the box. */
static int rows_case(int dim, int shape, int m, int up, int T, double *worst, double *frac,
                     long *checked)
{
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 1000.0,
                             .poisson_ratio = 0.3,
                             .density = 2.0};
    mpm_body_desc b[2];
    memset(b, 0, sizeof b);
    double h = dim == 2 ? 0.025 : 0.05;
    for (int i = 0; i < 2; i++) {
        b[i].shape = MPM_SHAPE_BOX;
        b[i].ppc = 2;
    }
    if (shape == 0) {
        double blo[3] = {0.7, 0.65, 0.6}, bhi[3] = {0.8, 0.75, 0.7};
        double va[3] = {20, 5, 3}, vb[3] = {-20, -5, -3};
        b[0].shape = MPM_SHAPE_SPHERE;
        b[0].radius = 0.13;
        for (int d = 0; d < dim; d++) {
            b[0].center[d] = 0.25, b[0].velocity[d] = va[d];
            b[1].lo[d] = blo[d], b[1].hi[d] = bhi[d], b[1].velocity[d] = vb[d];
        }
    } else {
        double alo[3] = {0.1, 0.3, 0.3}, ahi[3] = {0.4, 0.4, 0.5};
        double blo[3] = {0.1, 0.4, 0.3}, bhi[3] = {0.2, 0.6, 0.5};
        double v[3] = {15, -10, 5};
        for (int d = 0; d < dim; d++) {
            b[0].lo[d] = alo[d], b[0].hi[d] = ahi[d], b[0].velocity[d] = v[d];
            b[1].lo[d] = blo[d], b[1].hi[d] = bhi[d], b[1].velocity[d] = v[d];
        }
    }
    mpm_case c = {0};
    c.grid.dim = dim;
    for (int d = 0; d < dim; d++) {
        c.grid.h[d] = h;
        c.grid.nodes[d] = (int)(1.0 / h + 0.5) + 1;
    }
    c.method = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
    c.update = up ? MPM_MUSL : MPM_USF;
    c.dt = 2e-4;
    c.threads = T;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 2;
    c.bodies = b;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    if (!s) {
        TLOG("mpm_sim_new: %s", TERR(&err));
        return -1;
    }
    size_t n = mpm_sim_particles(s), nn = s->nn;
    double *x = malloc(n * (size_t)dim * sizeof *x);
    unsigned char *sup = malloc(nn);
    int rc = x && sup ? 0 : -1;
    mpm_energy e;
    mpm_sim_energy(s, &e);
    *worst = 0;
    *frac = 1;
    for (int step = 0; step < 60 && !rc; step++) {
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = x});
        if (mpm_sim_step(s)) {
            TLOG("step %d: %s", step, TERR(mpm_sim_error(s)));
            rc = -1;
            break;
        }
        double mg;
        mark_supports(s, x, n, dim, m, sup);
        if (stale_nodes(s, sup, dim, step, &mg, checked)) rc = -1;
        /* the public getter sees the same masses on the real nodes */
        double mr = 0, q[3];
        int nr[3] = {c.grid.nodes[0], c.grid.nodes[1], dim > 2 ? c.grid.nodes[2] : 1};
        for (int k = 0; k < nr[2]; k++)
            for (int j = 0; j < nr[1]; j++)
                for (int i = 0; i < nr[0]; i++) {
                    double mn;
                    mpm_sim_node(s, (int[3]){i, j, k}, &mn, q);
                    mr += mn;
                }
        if (!m && fabs(mr - mg) > 1e-12 * e.mass) rc = -1; /* MPM: no ghost nodes */
        *worst = fmax(*worst, fabs(mg - e.mass) / e.mass);
        size_t act = 0, box = 1;
        for (int d = 0; d < 3; d++) box *= (size_t)(s->bhi[d] - s->blo[d] + 1);
        for (size_t r = 0; r < s->nrows; r++)
            if (s->ulo[r] <= s->uhi[r]) act += (size_t)(s->uhi[r] - s->ulo[r] + 1);
        *frac = fmin(*frac, (double)act / (double)box);
        if (step == 59) *frac = (double)act / (double)box;
    }
    free(x);
    free(sup);
    mpm_sim_destroy(&s);
    return rc;
}

TEST(perf_active_rows_leave_no_stale_nodes)
{
    static const char *const shapes[2] = {"diagonal disk + box", "L"};
    for (int dim = 2; dim <= 3; dim++)
        for (int shape = 0; shape < 2; shape++)
            for (int m = 0; m < 2; m++)
                for (int up = 0; up < 2; up++)
                    for (int T = 1; T <= 2; T++) {
                        double worst, frac;
                        long checked = 0;
                        int rc = rows_case(dim, shape, m, up, T, &worst, &frac, &checked);
                        TLOG("%dD %s, %s %s T=%d, 60 steps: %ld node checks outside the supports "
                             "all zero: %s; worst |sum node mass - mass| / mass = %.1e; active "
                             "rows' extents / box = %.2f",
                             dim, shapes[shape], m ? "GIMP" : "MPM", up ? "MUSL" : "USF", T,
                             checked, rc ? "NO" : "yes", worst, frac);
                        CHECK(rc == 0);
                        CHECK(worst < 1e-12);
                        CHECK(frac < (shape == 0 ? 0.75 : 0.9));
                    }
}

/* 1D: the one row of nodes is split among the threads by node count, not by
 * rows, so segment boundaries fall inside the threads' extents and inside
 * the gap between two bodies.  Two bars moving apart across a 1D grid, 1 to
 * 3 threads: after every step no node outside the supports of the step's
 * particles holds mass or momentum, and the node masses sum to the
 * particles' mass. */
static int split_1d_case(int m, int up, int T, double *worst, long *checked)
{
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = 1000.0,
                             .poisson_ratio = 0.3,
                             .density = 2.0};
    mpm_body_desc b[2];
    memset(b, 0, sizeof b);
    /* as many particles in each bar (40): with 2 threads each thread holds
     * one bar; the short dense bar and the long sparse one put the middle
     * of the extent, where the node split falls, inside the second bar, so
     * the first thread's nodes hold both bars and the gap between them
     * (touched by neither thread, to be zeroed by the reduction) */
    double lo[2] = {0.2, 0.3}, hi[2] = {0.25, 0.5}, v[2] = {-12.0, 15.0};
    int ppc[2] = {4, 1};
    for (int i = 0; i < 2; i++) {
        b[i].shape = MPM_SHAPE_BOX;
        b[i].ppc = ppc[i];
        b[i].lo[0] = lo[i];
        b[i].hi[0] = hi[i];
        b[i].velocity[0] = v[i];
    }
    mpm_case c = {0};
    c.grid = (mpm_grid_desc){1, {0, 0, 0}, {0.005, 0, 0}, {201, 0, 0}};
    c.method = m ? MPM_METHOD_GIMP : MPM_METHOD_MPM;
    c.update = up ? MPM_MUSL : MPM_USF;
    c.dt = 5e-5;
    c.threads = T;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 2;
    c.bodies = b;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    if (!s) {
        TLOG("mpm_sim_new: %s", TERR(&err));
        return -1;
    }
    size_t n = mpm_sim_particles(s), nn = s->nn;
    double *x = malloc(n * sizeof *x);
    unsigned char *sup = malloc(nn);
    int rc = x && sup ? 0 : -1;
    mpm_energy e;
    mpm_sim_energy(s, &e);
    *worst = 0;
    for (int step = 0; step < 120 && !rc; step++) {
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = x});
        if (mpm_sim_step(s)) {
            TLOG("step %d: %s", step, TERR(mpm_sim_error(s)));
            rc = -1;
            break;
        }
        double mg;
        mark_supports(s, x, n, 1, m, sup);
        if (stale_nodes(s, sup, 1, step, &mg, checked)) rc = -1;
        *worst = fmax(*worst, fabs(mg - e.mass) / e.mass);
    }
    free(x);
    free(sup);
    mpm_sim_destroy(&s);
    return rc;
}

TEST(perf_node_split_1d_leaves_no_stale_nodes)
{
    for (int m = 0; m < 2; m++)
        for (int up = 0; up < 2; up++)
            for (int T = 1; T <= 3; T++) {
                double worst;
                long checked = 0;
                int rc = split_1d_case(m, up, T, &worst, &checked);
                TLOG("1D two bars, %s %s T=%d, 120 steps: %ld node checks outside the supports "
                     "all zero: %s; worst |sum node mass - mass| / mass = %.1e",
                     m ? "GIMP" : "MPM", up ? "MUSL" : "USF", T, checked, rc ? "NO" : "yes", worst);
                CHECK(rc == 0);
                CHECK(checked > 0);
                CHECK(worst < 1e-12);
            }
}

/* The node passes that reduce split work units, not nodes (mpm_rows.c):
 * a node where thread 0 did not scatter, whose private values the
 * reduction copies, counts MPM_W_NODE + MPM_W_COPY, one where it did
 * MPM_W_NODE.  Recounted here from the extents and thread 0's rows: the
 * shares follow each other and cover every active node once, each
 * thread's units lie within one row's units of an even split, and on the
 * disks thread 0, whose nodes hold sums in place, takes more nodes than an
 * even split of nodes gives it. */
TEST(perf_node_split_by_work)
{
    for (int T = 2; T <= 3; T++) {
        mpm_paper t;
        mpm_paper_disks(&t, MPM_METHOD_MPM, MPM_USF, 0.01);
        t.c.threads = T;
        mpm_error err;
        mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
        mpm_paper_free(&t);
        CHECKF(s, "mpm_sim_new: %s", err.message);
        CHECK(mpm_sim_run(s, 20) == 0);
        mpm_rows_update(s); /* the split of the rows the last pass recorded */
        size_t *u = malloc((s->nact + 1) * sizeof *u); /* units before node k */
        CHECK(u != NULL);
        if (!u) {
            mpm_sim_destroy(&s);
            return;
        }
        const mpm_thread_out *o0 = &s->tout[0];
        size_t k = 0, rowmax = 0, copied = 0;
        u[0] = 0;
        for (size_t r = 0; r < mpm_box_rows(s->blo, s->bhi); r++) {
            size_t row = mpm_box_row(s, s->blo, s->bhi, r), ru = 0;
            for (int x = s->ulo[row]; x <= s->uhi[row] && k < s->nact; x++, k++) {
                int in_place = x >= o0->rlo[row] && x <= o0->rhi[row];
                size_t w = MPM_W_NODE + (in_place ? 0 : MPM_W_COPY);
                copied += !in_place;
                u[k + 1] = u[k] + w;
                ru += w;
            }
            if (ru > rowmax) rowmax = ru;
        }
        CHECK(k == s->nact);
        double even = (double)u[k] / T;
        size_t prev = 0, worst = 0;
        for (int tid = 0; tid < T; tid++) {
            size_t n0, n1;
            mpm_node_share(s, tid, 1, &n0, &n1);
            CHECK(n0 == prev && n1 >= n0 && n1 <= s->nact);
            if (!(n0 == prev && n1 >= n0 && n1 <= s->nact)) break;
            double off = fabs((double)(u[n1] - u[n0]) - even);
            if (off > (double)worst) worst = (size_t)off;
            CHECK(off <= (double)rowmax);
            prev = n1;
        }
        CHECK(prev == s->nact);
        size_t w0, w1, e0, e1;
        mpm_node_share(s, 0, 1, &w0, &w1);
        mpm_node_share(s, 0, 0, &e0, &e1);
        TLOG("disks MPM USF, %d threads, 20 steps: %zu active nodes, %zu copied, %zu units; "
             "thread 0 takes %zu nodes by work, %zu by nodes; worst share %zu units off even "
             "(a row up to %zu)",
             T, s->nact, copied, u[k], w1 - w0, e1 - e0, worst, rowmax);
        CHECK(copied > 0);
        CHECK(w0 == 0 && e0 == 0 && w1 > e1);
        free(u);
        mpm_sim_destroy(&s);
    }
}
