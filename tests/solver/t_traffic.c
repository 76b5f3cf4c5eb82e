/*
 * t_traffic.c - mpm_sim_traffic(), the modelled particle-array bytes
 * per particle-step that bin/mpmbench sets against the STREAM triad:
 * exact figures for a few jobs, each worked out by hand in the comments
 * from the passes of mpm_kernels.c / mpm_cpdi.c and the model's rules
 * (mpm_traffic.c: 8 B per double array per particle, mat 2 B; an array
 * read and written counts twice; grid traffic not counted).  When the
 * passes change, these figures change with them, on purpose; both the
 * fused steps (the default) and the unfused ones are checked.
 */
#include "mpm.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "t.h"

#include <string.h>

/* A box [lo, hi]^dim of 2 x 2 (x 2) particles per cell, moving at vx along
 * x, in a grid of nodes^dim nodes of spacing h, on 1 thread. */
typedef struct {
    int nodes;
    double h, lo, hi, vx;
} geom;

static mpm_sim *sim_of(int dim, mpm_method m, mpm_update u, mpm_transfer tr, mpm_model_kind model,
                       geom g)
{
    mpm_case c;
    static mpm_material_desc mat;
    static mpm_body_desc b;
    memset(&c, 0, sizeof c);
    memset(&b, 0, sizeof b);
    mat = (mpm_material_desc){
        .model = model, .youngs_modulus = 1e4, .poisson_ratio = 0.3, .density = 1.0};
    if (model == MPM_MODEL_DRUCKER_PRAGER) {
        mat.friction_angle = 30;
        mat.dilatancy_angle = 0;
        mat.cohesion = 10;
    }
    b.shape = MPM_SHAPE_BOX;
    b.ppc = 2;
    b.velocity[0] = g.vx;
    for (int d = 0; d < dim; d++) {
        b.lo[d] = g.lo;
        b.hi[d] = g.hi;
        c.grid.h[d] = g.h;
        c.grid.nodes[d] = g.nodes;
    }
    c.grid.dim = dim;
    c.method = m;
    c.update = u;
    c.transfer = tr;
    c.threads = 1;
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 1;
    c.bodies = &b;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    if (!s) {
        char e[T_ERRLEN];
        mpm_error_text(&err, MPM_FIELD_JSON, e, sizeof e);
        fprintf(stderr, "    mpm_sim_new: %s\n", e);
    }
    return s;
}

/* A small box in a 12^dim grid, its steps fused (forced: a box this small
 * would not fuse, mpm_rows.c fuse_pays()) where the family can. */
static mpm_sim *job(int dim, mpm_method m, mpm_update u, mpm_transfer tr, mpm_model_kind model)
{
    mpm_sim *s = sim_of(dim, m, u, tr, model, (geom){12, 0.1, 0.3, 0.6, 0.0});
    if (s && m != MPM_METHOD_CPDI && mpm_sim_plan_override(s, "fuse=always", NULL))
        mpm_sim_destroy(&s);
    return s;
}

/* the model's figure for a job, its passes logged; -1 on failure */
static double traffic(mpm_sim *s, const char *what, mpm_traffic *t)
{
    if (!s || mpm_sim_traffic(s, t)) return -1;
    char line[512];
    size_t k = 0;
    for (int i = 0; i < t->npass && k < sizeof line; i++)
        k += (size_t)snprintf(line + k, sizeof line - k, "%s%s r%.0f w%.0f", i ? ", " : "",
                              t->pass[i].name, t->pass[i].read, t->pass[i].write);
    TLOG("%s: %.0f B/particle-step (%s)", what, t->total, line);
    return t->total;
}

/* the job's figure unfused (plan fuse=off), then fused again
 * (forced, as job() makes it) */
static double unfused(mpm_sim *s, const char *what, mpm_traffic *t)
{
    if (!s || mpm_sim_plan_override(s, "fuse=off", NULL)) return -1;
    double r = traffic(s, what, t);
    return mpm_sim_plan_override(s, "fuse=always", NULL) ? -1 : r;
}

/* Linear elasticity from a stress-free start keeps no strain record, and
 * 2D no sigma_zz (mpm_needs and docs/solver.md): 2D sig is xx yy xy (24
 * B), 3D all six (48 B).  Fused jobs: the pass that moves the particles
 * makes the next step's first scatter, reading only what it has not
 * touched (m), in every step (a step that sorts does so after it). */
TEST(traffic_usf_mpm_elastic)
{
    mpm_traffic t;
    /* 2D unfused: p2g_mq reads x v m: 2 + 2 + 1 doubles = 40 B;
     * stress_force reads x (16), mat (2), sig (24), vol (8) = 50 and writes
     * sig vol = 32; g2p_xv reads x v (32) and writes them (32):
     * 40 + 50 + 32 + 64 = 186 (no strain record, sigma_zz derived). */
    mpm_sim *s = job(2, MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_FLIP, MPM_MODEL_LINEAR_ELASTIC);
    CHECK(unfused(s, "2D MPM USF elastic, unfused", &t) == 186);
    CHECK(t.npass == 3 && t.pass[0].read == 40 && t.pass[0].write == 0);
    CHECK(t.pass[1].read == 50 && t.pass[1].write == 32);
    CHECK(t.pass[2].read == 32 && t.pass[2].write == 32);
    /* fused: stress_force 50 + 32; g2p_xv + next p2g_mq reads x v m 40,
     * writes x v 32: 154 (156.5 while the step before a sort scattered on
     * its own, 1 step in 16) */
    CHECK(traffic(s, "2D MPM USF elastic", &t) == 154);
    CHECK(t.npass == 2 && t.pass[1].read == 40 && t.pass[1].write == 32);
    CHECK(t.read == 90 && t.write == 64);
    mpm_sim_destroy(&s);
    /* 3D unfused: p2g x v m = 56; stress reads x 24 + mat 2 + sig 48 + vol
     * 8 = 82, writes 56; g2p 48 + 48: 56 + 82 + 56 + 96 = 290.  Fused:
     * 82 + 56, g2p + next reads x v m 56 writes 48: 242 */
    s = job(3, MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_FLIP, MPM_MODEL_LINEAR_ELASTIC);
    CHECK(unfused(s, "3D MPM USF elastic, unfused", &t) == 290);
    CHECK(traffic(s, "3D MPM USF elastic", &t) == 242);
    mpm_sim_destroy(&s);
}

TEST(traffic_usl_gimp_elastic)
{
    mpm_traffic t;
    /* 2D uGIMP USL: the weights read lp too.  Unfused: p2g_mqf reads x 16,
     * lp 16, m 8, v 16, sig 24, vol 8 = 88; g2p_xv_stress reads x lp v
     * (48), mat 2, sig 24, vol 8 = 82 and writes x v (32), sig vol (32) =
     * 64: 88 + 82 + 64 = 234.  Fused: one pass reading 82 + m 8 = 90,
     * writing 64: 154 */
    mpm_sim *s = job(2, MPM_METHOD_GIMP, MPM_USL, MPM_TRANSFER_FLIP, MPM_MODEL_LINEAR_ELASTIC);
    CHECK(unfused(s, "2D GIMP USL elastic, unfused", &t) == 234);
    CHECK(t.npass == 2 && t.pass[0].read == 88 && t.pass[1].read == 82 && t.pass[1].write == 64);
    CHECK(traffic(s, "2D GIMP USL elastic", &t) == 154);
    CHECK(t.npass == 1 && t.pass[0].read == 90 && t.pass[0].write == 64);
    mpm_sim_destroy(&s);
}

TEST(traffic_musl_bspline_apic)
{
    mpm_traffic t;
    /* 2D BSPLINE2 MUSL APIC (no lp; B is 2 x 2 = 4 doubles = 32 B), unfused:
     *   p2g_mqf      reads x 16, m 8, v 16, B 32, sig 24, vol 8     = 104
     *   g2p_v        reads x 16; writes v 16, B 32 (v not read)     = 16 + 48
     *   p2g_q2       reads x 16, m 8, v 16, B 32                    = 72
     *   g2p_x_stress reads x 16, v 16 (the particle check), mat 2,
     *                sig 24, vol 8 = 66; writes x 16, sig 24, vol 8 = 48
     * 104 + 64 + 72 + 114 = 354.  Fused:
     *   g2p_v + p2g_q2  reads x 16 and m 8 (v, B: just written) = 24,
     *                   writes v B 48
     *   g2p_x_stress + next p2g_mqf  reads 66 + m 8 + B 32 = 106, writes 48
     * 72 + 154 = 226. */
    mpm_sim *s = job(2, MPM_METHOD_BSPLINE2, MPM_MUSL, MPM_TRANSFER_APIC, MPM_MODEL_LINEAR_ELASTIC);
    CHECK(unfused(s, "2D BSPLINE2 MUSL APIC elastic, unfused", &t) == 354);
    CHECK(t.npass == 4 && t.pass[1].read == 16 && t.pass[1].write == 48);
    CHECK(t.pass[3].read == 66 && t.pass[3].write == 48);
    CHECK(traffic(s, "2D BSPLINE2 MUSL APIC elastic", &t) == 226);
    CHECK(t.npass == 2 && t.pass[0].read == 24 && t.pass[0].write == 48);
    CHECK(t.pass[1].read == 106 && t.pass[1].write == 48);
    mpm_sim_destroy(&s);
    /* the same with FLIP, unfused: p2g_mqf 72, g2p_v reads x v 32 writes v
     * 16, p2g_q2 40, g2p_x_stress 66 + 48: 72 + 48 + 40 + 114 = 274.
     * Fused: g2p_v + p2g_q2 reads x v m 40 writes v 16; g2p_x_stress +
     * next reads 66 + m 8 writes 48: 56 + 122 = 178 */
    s = job(2, MPM_METHOD_BSPLINE2, MPM_MUSL, MPM_TRANSFER_FLIP, MPM_MODEL_LINEAR_ELASTIC);
    CHECK(unfused(s, "2D BSPLINE2 MUSL FLIP elastic, unfused", &t) == 274);
    CHECK(traffic(s, "2D BSPLINE2 MUSL FLIP elastic", &t) == 178);
    mpm_sim_destroy(&s);
}

TEST(traffic_usf_plastic_and_cpdi)
{
    mpm_traffic t;
    /* 2D MPM USF Drucker-Prager (the plastic models keep the strain record
     * and sig_zz: sig 32, eps 24): unfused, p2g 40; the stress pass reads
     * x 16, mat 2, sig 32, eps 24, vol 8, epsp 8 = 90 and writes sig eps
     * vol epsp yld = 80; g2p 64: 40 + 90 + 80 + 64 = 274.  Fused: 170 +
     * (40 + 32) = 242 */
    mpm_sim *s = job(2, MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_FLIP, MPM_MODEL_DRUCKER_PRAGER);
    CHECK(unfused(s, "2D MPM USF Drucker-Prager, unfused", &t) == 274);
    CHECK(t.pass[1].read == 90 && t.pass[1].write == 80);
    CHECK(traffic(s, "2D MPM USF Drucker-Prager", &t) == 242);
    mpm_sim_destroy(&s);
    /* 2D CPDI USF elastic (never fused): the weights read x 16, lp 16, F 32
     * (64 B);
     *   p2g_mq       64 + m 8 + v 16                               = 88
     *   stress_force 64 + mat 2 + sig 24 + vol 8 = 98; writes 32
     *   g2p_xv       reads 64 + v 16 = 80; writes x 16, F 32, v 16 = 64
     * 88 + 98 + 32 + 144 = 362. */
    s = job(2, MPM_METHOD_CPDI, MPM_USF, MPM_TRANSFER_FLIP, MPM_MODEL_LINEAR_ELASTIC);
    CHECK(traffic(s, "2D CPDI USF elastic", &t) == 362);
    CHECK(t.npass == 3 && t.pass[2].read == 80 && t.pass[2].write == 64);
    CHECK(mpm_sim_plan_override(s, "fuse=auto", NULL) == MPM_EINVAL);
    mpm_sim_destroy(&s);
    CHECK(mpm_sim_traffic(NULL, &t) == MPM_EINVAL);
}

/* A 2D elastic box of cells x cells cells at the origin of a nodes x nodes
 * grid of h = 0.01, moving along x. */
static mpm_sim *box2d(int nodes, int cells)
{
    return sim_of(2, MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_FLIP, MPM_MODEL_LINEAR_ELASTIC,
                  (geom){nodes, 0.01, 0.05, 0.05 + 0.01 * cells, 0.1});
}

/* Fused steps where they pay (mpm_rows.c fuse_pays()): the same body of
 * 1600 particles over 21 rows fuses in a tight grid (rows 256 B apart: 2
 * pages a field, 800 particles needed) and not in a 1024-node-wide grid
 * (every row its own page: 21 pages, 8400 needed), the sparse2d case,
 * where fusing does not pay; forced (2), it fuses there too.  Whether a step
 * fuses never changes its results (fuse_same_bits). */
TEST(fuse_where_it_pays)
{
    static const struct {
        int nodes, force, want;
    } cs[] = {{32, 0, 1}, {1024, 0, 0}, {1024, 1, 1}};
    for (size_t i = 0; i < sizeof cs / sizeof *cs; i++) {
        mpm_sim *s = box2d(cs[i].nodes, 20);
        CHECK(s != NULL);
        CHECK(mpm_sim_particles(s) == 1600);
        if (cs[i].force) CHECK(mpm_sim_plan_override(s, "fuse=always", NULL) == 0);
        CHECK(mpm_sim_step(s) == 0 && mpm_sim_step(s) == 0);
        TLOG("%4d-node-wide grid%s: %s", cs[i].nodes, cs[i].force ? ", forced" : "",
             s->gnext ? "fused" : "not fused");
        CHECKF(s->gnext == cs[i].want, "grid %d force %d: gnext %d", cs[i].nodes, cs[i].force,
               s->gnext);
        mpm_sim_destroy(&s);
    }
}
