/*
 * t_reference.c - the fast kernel families against the REFERENCE family
 * (mpm_case.kernel_family, solver/mpm_ref.c): every dimension, method,
 * update scheme and transfer (FLIP, the PIC/FLIP blend, PIC, APIC; CPDI
 * has no APIC) on a short run of two bodies that cross cells and collide
 * under gravity, the fast side on 1 and 2 threads and with the portable
 * kernels, compared particle by particle (positions relative to h,
 * velocities and stresses relative to their largest magnitude).  No
 * combination runs the same operations in the same order (the reference
 * sums in creation order node by node, divides by the nodal mass, and
 * evaluates the shape functions from their formulas; docs/solver.md,
 * "Reference kernels"), so every one is held to REF_TOL, and the largest
 * differences are printed.  Also: the reference is reproducible bit for
 * bit, with any threads (it runs one) and through a checkpoint, the field
 * is checked and mapped from JSON, and its speed against the fast families
 * is printed.
 */
#include "mpm.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_kernels_avx2.h"
#include "mpp_case.h"
#include "t.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* The tolerance of every comparison: the runs' round-off stays far below
 * it (the figures are printed), a fast weight changed by 1e-8 of itself
 * exceeds it (docs/solver.md, "Reference kernels"). */
#define REF_TOL 1e-9
#define REF_STEPS 25

enum { TR_FLIP, TR_BLEND, TR_PIC, TR_APIC, TR_N };
static const char *const tr_name[TR_N] = {"FLIP", "BLEND", "PIC", "APIC"};

/* Two bodies of one elastic material moving towards each other across
 * cells and colliding within the run, under gravity: 1D two bars, 2D two
 * disks, 3D two boxes, at a fifth of the p-wave speed each. */
typedef struct {
    mpm_case c;
    mpm_material_desc mat;
    mpm_body_desc b[2];
} rscene;

static void scene(rscene *k, int dim, mpm_method m, mpm_update up, int tr)
{
    memset(k, 0, sizeof *k);
    k->mat = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                 .youngs_modulus = 1.0,
                                 .poisson_ratio = dim > 1 ? 0.3 : 0.0,
                                 .density = 1.0};
    double c = mpm_material_wave_speed(&k->mat, dim), h = 0.1;
    k->c.grid.dim = dim;
    for (int d = 0; d < dim; d++) {
        k->c.grid.h[d] = h;
        k->c.grid.nodes[d] = dim == 1 ? 21 : dim == 2 ? 11 : 9;
    }
    for (int i = 0; i < 2; i++) {
        mpm_body_desc *b = &k->b[i];
        b->ppc = 2;
        b->velocity[0] = (i ? -0.2 : 0.2) * c;
        if (dim == 1) {
            b->shape = MPM_SHAPE_BOX;
            b->lo[0] = i ? 0.95 : 0.25;
            b->hi[0] = b->lo[0] + 0.6;
        } else if (dim == 2) {
            b->shape = MPM_SHAPE_SPHERE;
            b->center[0] = i ? 0.68 : 0.32;
            b->center[1] = i ? 0.55 : 0.45;
            b->radius = 0.16;
            b->velocity[1] = (i ? -0.05 : 0.05) * c;
        } else { /* a little off the x axis: faces do not meet grid lines together */
            static const double lo[2][3] = {{0.2, 0.3, 0.4}, {0.45, 0.35, 0.45}};
            b->shape = MPM_SHAPE_BOX;
            b->velocity[1] = (i ? -0.04 : 0.04) * c;
            b->velocity[2] = (i ? 0.03 : -0.03) * c;
            for (int d = 0; d < 3; d++) {
                b->lo[d] = lo[i][d];
                b->hi[d] = b->lo[d] + 0.2;
            }
        }
    }
    /* MPM tents with USL at the default C = 0.5 blow up in this scene's
     * cell crossings with FLIP (the MPM + USL limitation of
     * docs/accuracy.md), in the fast and the reference family alike */
    if (m == MPM_METHOD_MPM && up == MPM_USL) k->c.cfl = 0.2;
    k->c.method = m;
    k->c.update = up;
    k->c.transfer = tr == TR_APIC ? MPM_TRANSFER_APIC : MPM_TRANSFER_FLIP;
    k->c.pic_fraction = tr == TR_BLEND ? 0.5 : tr == TR_PIC ? 1.0 : 0.0;
    k->c.gravity[dim - 1] = -0.5;
    k->c.n_materials = 1;
    k->c.materials = &k->mat;
    k->c.n_bodies = 2;
    k->c.bodies = k->b;
}

/* The particles after a run, in creation order. */
typedef struct {
    size_t n;
    int dim;
    double *x, *v, *sig;
    double t, wall;
    const char *kernels;
} rstate;

static void rstate_free(rstate *r)
{
    free(r->x);
    free(r->v);
    free(r->sig);
    memset(r, 0, sizeof *r);
}

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Runs c for steps steps with the family, instruction set and threads
 * given into *r.  Returns 0, or -1 (logged). */
static int run(mpm_case *c, mpm_kernel_family fam, mpm_kernels_isa isa, int threads, long steps,
               rstate *r)
{
    memset(r, 0, sizeof *r);
    c->kernel_family = fam;
    c->kernels = isa;
    c->threads = threads;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(c, NULL, &err);
    if (!s) {
        TLOG("mpm_sim_new: %s", TERR(&err));
        return -1;
    }
    r->kernels = mpm_sim_kernels(s);
    double t0 = now();
    int rc = mpm_sim_run(s, steps);
    r->wall = now() - t0;
    r->n = mpm_sim_particles(s);
    r->dim = mpm_sim_dim(s);
    r->t = mpm_sim_time(s);
    r->x = malloc(r->n * 3 * sizeof *r->x);
    r->v = malloc(r->n * 3 * sizeof *r->v);
    r->sig = malloc(r->n * 6 * sizeof *r->sig);
    if (rc || !r->x || !r->v || !r->sig) {
        TLOG("run (%s): %d %s", r->kernels, rc, rc ? mpm_sim_error(s)->message : "no memory");
        mpm_sim_destroy(&s);
        rstate_free(r);
        return -1;
    }
    mpm_sim_snapshot(s, &(mpm_snapshot){.x = r->x, .v = r->v, .stress = r->sig});
    mpm_sim_destroy(&s);
    return 0;
}

/* The largest |a - b| over n values divided by scale, or by the largest
 * |a| when scale is 0 (NaN counts as infinite). */
static double maxdiff(const double *a, const double *b, size_t n, double scale)
{
    double d = 0, m = 0;
    for (size_t i = 0; i < n; i++) {
        double e = fabs(a[i] - b[i]);
        if (!(e <= d)) d = isnan(e) ? INFINITY : e;
        if (fabs(a[i]) > m) m = fabs(a[i]);
    }
    double s = scale > 0 ? scale : m;
    return s > 0 ? d / s : d;
}

/* The worst of positions (relative to h), velocities and stresses of b
 * against the reference a, into w[3]; returns their largest. */
static double compare(const rstate *a, const rstate *b, double h, double w[3])
{
    size_t n = a->n * (size_t)a->dim;
    w[0] = maxdiff(a->x, b->x, n, h);
    w[1] = maxdiff(a->v, b->v, n, 0);
    w[2] = maxdiff(a->sig, b->sig, a->n * 6, 0);
    if (a->n != b->n || a->t != a->t || fabs(a->t - b->t) > REF_TOL * a->t) return INFINITY;
    return fmax(w[0], fmax(w[1], w[2]));
}

static const char *const meth_name[5] = {"MPM", "GIMP", "BSPLINE2", "BSPLINE3", "CPDI"};
static const char *const upd_name[3] = {"USF", "USL", "MUSL"};

TEST(reference_matrix_against_fast)
{
    int rows = 0, fails = 0;
    double worst[3][3] = {{0}}; /* per dimension: x, v, sigma */
    /* the portable kernels as a third run where they differ from AUTO's:
     * the AVX2 families fuse multiply-adds (not in the sanitizer builds,
     * which compile them at -O1: there they give the portable bits) */
    const int have_avx2 = mpm_kernels_avx2_available() && mpm_kernels_avx2_fuses();
    TLOG("%d steps, the largest difference of positions (/h), velocities, stresses "
         "(/largest) against the reference; tolerance %g",
         REF_STEPS, REF_TOL);
    TLOG("%-3s %-8s %-4s %-5s | %-26s | %-26s | %-26s", "D", "method", "upd", "xfer",
         "fast, 1 thread", "fast, 2 threads", "portable, 1 thread");
    for (int dim = 1; dim <= 3; dim++)
        for (int m = 0; m < 5; m++)
            for (int up = 0; up < 3; up++)
                for (int tr = 0; tr < TR_N; tr++) {
                    if (m == MPM_METHOD_CPDI && tr == TR_APIC) continue; /* refused */
                    rscene k;
                    scene(&k, dim, (mpm_method)m, (mpm_update)up, tr);
                    rstate ref, f[3];
                    CHECKF(run(&k.c, MPM_KERNEL_FAMILY_REFERENCE, MPM_KERNELS_AUTO, 1, REF_STEPS,
                               &ref) == 0,
                           "reference %dD %s %s %s", dim, meth_name[m], upd_name[up], tr_name[tr]);
                    CHECK(!strcmp(ref.kernels, "reference"));
                    char cell[3][40];
                    double dmax = 0;
                    int nf = have_avx2 ? 3 : 2;
                    for (int j = 0; j < 3; j++) snprintf(cell[j], sizeof cell[j], "-");
                    for (int j = 0; j < nf; j++) {
                        mpm_kernels_isa isa = j == 2 ? MPM_KERNELS_PORTABLE : MPM_KERNELS_AUTO;
                        if (run(&k.c, MPM_KERNEL_FAMILY_FAST, isa, j == 1 ? 2 : 1, REF_STEPS,
                                &f[j])) {
                            rstate_free(&ref);
                            for (int i = 0; i < j; i++) rstate_free(&f[i]);
                            CHECKF(0, "fast %dD %s %s %s", dim, meth_name[m], upd_name[up],
                                   tr_name[tr]);
                        }
                        double w[3], d = compare(&ref, &f[j], k.c.grid.h[0], w);
                        snprintf(cell[j], sizeof cell[j], "%8.1e %8.1e %8.1e", w[0], w[1], w[2]);
                        for (int c = 0; c < 3; c++)
                            worst[dim - 1][c] = fmax(worst[dim - 1][c], w[c]);
                        dmax = fmax(dmax, d);
                    }
                    int bad = !(dmax <= REF_TOL);
                    TLOG("%dD  %-8s %-4s %-5s | %-26s | %-26s | %-26s%s", dim, meth_name[m],
                         upd_name[up], tr_name[tr], cell[0], cell[1], cell[2],
                         bad ? "  ABOVE TOLERANCE" : "");
                    fails += bad;
                    rows++;
                    rstate_free(&ref);
                    for (int j = 0; j < nf; j++) rstate_free(&f[j]);
                }
    for (int d = 0; d < 3; d++)
        TLOG("%dD worst: x %.2e h, v %.2e, sigma %.2e", d + 1, worst[d][0], worst[d][1],
             worst[d][2]);
    TLOG("%d combinations, %d above %g", rows, fails, REF_TOL);
    CHECK(rows == 3 * (5 * 3 * TR_N - 3));
    CHECKF(fails == 0, "%d of %d combinations differ from the reference by more than %g", fails,
           rows, REF_TOL);
}

/* The reference family runs one thread whatever threads asks, so its bits
 * do not depend on it, and a second run gives the same bits; a run saved
 * to a checkpoint half way and loaded into a fresh simulation ends with
 * the same bits too (the family keeps no state of its own). */
static int same_bits(const rstate *a, const rstate *b)
{
    size_t n = a->n * (size_t)a->dim;
    return a->n == b->n && !memcmp(a->x, b->x, n * sizeof *a->x) &&
           !memcmp(a->v, b->v, n * sizeof *a->v) &&
           !memcmp(a->sig, b->sig, a->n * 6 * sizeof *a->sig);
}

/* Case c on the reference, 5 steps, a checkpoint, 5 more steps in a fresh
 * simulation that loaded it, into *r.  Returns 0 or -1. */
static int run_resumed(mpm_case *c, rstate *r)
{
    mpm_error e;
    memset(r, 0, sizeof *r);
    c->kernel_family = MPM_KERNEL_FAMILY_REFERENCE;
    c->threads = 1;
    mpm_sim *s = mpm_sim_new(c, NULL, &e), *t = NULL;
    size_t n = s ? mpm_sim_checkpoint_size(s) : 0;
    void *blob = n ? malloc(n) : NULL;
    int rc = !blob || mpm_sim_run(s, 5) || mpm_sim_checkpoint_save(s, blob, n) ||
             !(t = mpm_sim_new(c, NULL, &e)) || mpm_sim_checkpoint_load(t, blob, n, &e) ||
             mpm_sim_run(t, 5);
    free(blob);
    mpm_sim_destroy(&s);
    if (!rc) {
        r->n = mpm_sim_particles(t);
        r->dim = mpm_sim_dim(t);
        r->x = malloc(r->n * 3 * sizeof *r->x);
        r->v = malloc(r->n * 3 * sizeof *r->v);
        r->sig = malloc(r->n * 6 * sizeof *r->sig);
        rc = !r->x || !r->v || !r->sig;
        if (!rc) mpm_sim_snapshot(t, &(mpm_snapshot){.x = r->x, .v = r->v, .stress = r->sig});
    }
    mpm_sim_destroy(&t);
    if (rc) rstate_free(r);
    return rc ? -1 : 0;
}

TEST(reference_bitwise_reproducible)
{
    for (int dim = 1; dim <= 3; dim++) {
        rscene k;
        scene(&k, dim, dim == 2 ? MPM_METHOD_GIMP : MPM_METHOD_BSPLINE2, MPM_MUSL, TR_APIC);
        rstate a, b, r;
        CHECK(run(&k.c, MPM_KERNEL_FAMILY_REFERENCE, MPM_KERNELS_AUTO, 1, 10, &a) == 0);
        if (run(&k.c, MPM_KERNEL_FAMILY_REFERENCE, MPM_KERNELS_PORTABLE, 2, 10, &b)) {
            rstate_free(&a);
            CHECK(0);
        }
        if (run_resumed(&k.c, &r)) {
            rstate_free(&a);
            rstate_free(&b);
            CHECKF(0, "%dD: the checkpointed reference run failed", dim);
        }
        int same = same_bits(&a, &b), resumed = same_bits(&a, &r);
        rstate_free(&a);
        rstate_free(&b);
        rstate_free(&r);
        CHECKF(same, "%dD: the reference's bits changed with threads 2", dim);
        CHECKF(resumed, "%dD: the reference's bits changed through a checkpoint", dim);
    }
}

/* kernel_family: an unknown value and REFERENCE with kernels AVX2 are
 * refused naming the field; the JSON mapping's "kernelFamily" selects it. */
TEST(reference_field_checked_and_mapped)
{
    rscene k;
    scene(&k, 2, MPM_METHOD_MPM, MPM_USF, TR_FLIP);
    mpm_case_info info;
    mpm_error e;
    k.c.kernel_family = (mpm_kernel_family)7;
    CHECK(mpm_case_check(&k.c, &info, &e) == MPM_EINVAL &&
          !strcmp(mpm_error_field(&e, MPM_FIELD_PROTO, (char[64]){0}, 64), "kernel_family"));
    TLOG("%s", TERR(&e));
    k.c.kernel_family = MPM_KERNEL_FAMILY_REFERENCE;
    k.c.kernels = MPM_KERNELS_AVX2;
    CHECK(mpm_case_check(&k.c, &info, &e) == MPM_EINVAL &&
          !strcmp(mpm_error_field(&e, MPM_FIELD_PROTO, (char[64]){0}, 64), "kernel_family"));
    TLOG("%s", TERR(&e));
    k.c.kernels = MPM_KERNELS_PORTABLE;
    CHECK(mpm_case_check(&k.c, &info, &e) == 0);

    char err[T_ERRLEN], json[512];
    for (int with = 1; with >= 0; with--) { /* the key given, then absent (FAST) */
        snprintf(json, sizeof json,
                 "{\"grid\": {\"dim\": 1, \"origin\": [0], \"spacing\": [0.1], \"nodes\": [11]},"
                 " \"method\": \"GIMP\", \"update\": \"USL\", \"steps\": 3,%s"
                 " \"materials\": [{\"youngsModulus\": 1, \"density\": 1}],"
                 " \"bodies\": [{\"box\": {\"lo\": [0.2], \"hi\": [0.6]}, \"ppc\": 2}]}",
                 with ? " \"kernelFamily\": \"REFERENCE\"," : "");
        mpp_case *mc = NULL;
        int rc = t_errtext(mpp_case_load(json, strlen(json), 0, &mc, &e), &e, err);
        CHECKF(rc == 0 && mc, "%s", err);
        int fam = mc->c.kernel_family;
        mpm_sim *s = mpm_sim_new(&mc->c, &mc->info, &e);
        const char *ran = s ? mpm_sim_kernels(s) : "";
        int ok = s && mpm_sim_run(s, 3) == 0;
        int ref = !strcmp(ran, "reference");
        mpm_sim_destroy(&s);
        mpp_case_destroy(&mc);
        CHECKF(ok && fam == (with ? MPM_KERNEL_FAMILY_REFERENCE : MPM_KERNEL_FAMILY_FAST) &&
                   ref == with,
               "kernelFamily %s: family %d, kernels %s", with ? "REFERENCE" : "absent", fam, ran);
    }
}

/* The reference's speed against the fast families on the 2D disks (MUSL,
 * FLIP; h = 1/40, 2 x 2 points per cell), one thread: printed, not
 * asserted (the two still agree to REF_TOL). */
TEST(reference_speed)
{
    static const mpm_method ms[3] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2};
    const long steps = 20;
    TLOG("2D disks, MUSL, FLIP, %ld steps, 1 thread: ns per particle-step", steps);
    TLOG("%-9s %9s %9s %9s %10s", "method", "reference", "fast", "ratio", "difference");
    for (int i = 0; i < 3; i++) {
        rscene k;
        scene(&k, 2, ms[i], MPM_MUSL, TR_FLIP);
        for (int d = 0; d < 2; d++) {
            k.c.grid.h[d] = 0.025;
            k.c.grid.nodes[d] = 41;
        }
        rstate a, b;
        CHECK(run(&k.c, MPM_KERNEL_FAMILY_REFERENCE, MPM_KERNELS_AUTO, 1, steps, &a) == 0);
        if (run(&k.c, MPM_KERNEL_FAMILY_FAST, MPM_KERNELS_AUTO, 1, steps, &b)) {
            rstate_free(&a);
            CHECK(0);
        }
        double w[3], d = compare(&a, &b, 0.025, w), ps = (double)a.n * (double)steps;
        TLOG("%-9s %9.1f %9.1f %9.1f %10.1e  (%zu particles, fast: %s)", meth_name[ms[i]],
             1e9 * a.wall / ps, 1e9 * b.wall / ps, a.wall / b.wall, d, a.n, b.kernels);
        rstate_free(&a);
        rstate_free(&b);
        CHECK(d <= REF_TOL);
    }
}
