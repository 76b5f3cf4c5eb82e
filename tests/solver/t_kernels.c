/*
 * t_kernels.c - the kernels' instruction set (mpm_case.kernels): the
 * AVX2+FMA families agree with the portable ones to round-off on every
 * method, update scheme and transfer, in 1D, 2D and 3D and with
 * Drucker-Prager; they are themselves reproducible bit for bit; the field
 * is checked.  On a CPU without AVX2 and FMA the tests assert that AVX2 is
 * refused and that AUTO runs the portable kernels.  (The sanitizer builds
 * compile the AVX2 families at -O1, where GCC forms no FMAs: there they
 * give the portable bits, which the test checks too.)
 */
#include "mpm.h"
#include "mpm_collapse.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_kernels_avx2.h"
#include "mpm_paper.h"
#include "t.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* The particles' state after a run: positions, velocities, stresses. */
typedef struct {
    size_t n;
    int dim;
    double *x, *v, *sig;
    double e; /* kinetic + strain energy */
} kstate;

static void kstate_free(kstate *k)
{
    free(k->x);
    free(k->v);
    free(k->sig);
    memset(k, 0, sizeof *k);
}

/* Runs case c for steps steps with the kernels isa into *k; names the
 * kernels that ran in *ran. Returns 0, or -1 (failure logged). */
static int run_state(mpm_case *c, mpm_kernels_isa isa, long steps, kstate *k, const char **ran)
{
    memset(k, 0, sizeof *k);
    c->kernels = isa;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(c, NULL, &err);
    if (!s) {
        char t[T_ERRLEN];
        TLOG("mpm_sim_new: %s", mpm_error_text(&err, MPM_FIELD_PROTO, t, sizeof t));
        return -1;
    }
    *ran = mpm_sim_kernels(s);
    int rc = mpm_sim_run(s, steps);
    k->n = mpm_sim_particles(s);
    k->dim = mpm_sim_dim(s);
    k->x = malloc(k->n * (size_t)k->dim * sizeof *k->x);
    k->v = malloc(k->n * (size_t)k->dim * sizeof *k->v);
    k->sig = malloc(k->n * 6 * sizeof *k->sig);
    if (rc || !k->x || !k->v || !k->sig) {
        TLOG("run: %d (%s)", rc, rc ? mpm_sim_error(s)->message : "out of memory");
        mpm_sim_destroy(&s);
        kstate_free(k);
        return -1;
    }
    mpm_sim_snapshot(s, &(mpm_snapshot){.x = k->x, .v = k->v, .stress = k->sig});
    mpm_energy en;
    mpm_sim_energy(s, &en);
    k->e = en.kinetic + en.strain;
    mpm_sim_destroy(&s);
    return 0;
}

/* The largest difference of a and b over n values, relative to the
 * largest magnitude in a (absolute when that is 0). */
static double maxrel(const double *a, const double *b, size_t n)
{
    double d = 0, m = 0;
    for (size_t i = 0; i < n; i++) {
        double e = fabs(a[i] - b[i]);
        if (e > d || e != e) d = e;
        if (fabs(a[i]) > m) m = fabs(a[i]);
    }
    return m > 0 ? d / m : d;
}

/* A cube of 6^3 cells, 2 points per cell per axis, E = 1e3, nu = 0.3, moving
 * towards the x_hi wall (rollers) at 5 % of c under gravity, resting on the
 * fixed floor: 3D contact, fixed nodes and gravity in one case. */
typedef struct {
    mpm_case c;
    mpm_material_desc mat;
    mpm_body_desc b;
} cube_case;

static void cube_build(cube_case *k, mpm_method m, mpm_update up, mpm_transfer tr)
{
    memset(k, 0, sizeof *k);
    const double h = 0.1;
    k->mat = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                 .youngs_modulus = 1e3,
                                 .poisson_ratio = 0.3,
                                 .density = 1.0};
    double c = mpm_material_wave_speed(&k->mat, 3);
    k->b.shape = MPM_SHAPE_BOX;
    for (int d = 0; d < 3; d++) {
        k->b.lo[d] = d == 2 ? 0.1 : 0.2;
        k->b.hi[d] = k->b.lo[d] + 0.6;
    }
    k->b.ppc = 2;
    k->b.velocity[0] = 0.05 * c;
    k->c.grid.dim = 3;
    for (int d = 0; d < 3; d++) {
        k->c.grid.h[d] = h;
        k->c.grid.nodes[d] = 11;
    }
    k->c.method = m;
    k->c.update = up;
    k->c.transfer = tr;
    k->c.cfl = m == MPM_METHOD_MPM && tr == MPM_TRANSFER_APIC ? MPM_APIC_MPM_MAX_CFL : 0;
    k->c.gravity[2] = -9.81;
    k->c.bc.face_mask[4] = 7; /* z_lo: a wall */
    k->c.bc.face_mask[1] = 1; /* x_hi: a roller */
    k->c.n_materials = 1;
    k->c.materials = &k->mat;
    k->c.n_bodies = 1;
    k->c.bodies = &k->b;
}

/* Both kernels on case c (steps steps): the AVX2 run against the
 * portable one within tol (positions relative to h: rel_x; velocities,
 * stresses and energy relative to their largest magnitude), and a second
 * AVX2 run giving the same bits.  *differ: the two kernels' bits differ. */
static int compare(const char *name, mpm_case *c, long steps, double tol, int *differ)
{
    kstate a, b, a2;
    const char *ra = NULL, *rb = NULL, *ra2 = NULL;
    if (run_state(c, MPM_KERNELS_PORTABLE, steps, &a, &ra)) return -1;
    if (run_state(c, MPM_KERNELS_AVX2, steps, &b, &rb)) {
        kstate_free(&a);
        return -1;
    }
    int ok = run_state(c, MPM_KERNELS_AVX2, steps, &a2, &ra2) == 0;
    size_t nd = a.n * (size_t)a.dim;
    double h = c->grid.h[0];
    double dx = 0;
    for (size_t i = 0; i < nd; i++)
        if (!(fabs(a.x[i] - b.x[i]) <= dx)) dx = fabs(a.x[i] - b.x[i]);
    dx /= h;
    double dv = maxrel(a.v, b.v, nd), ds = maxrel(a.sig, b.sig, a.n * 6);
    double de = fabs(a.e - b.e) / (fabs(a.e) > 0 ? fabs(a.e) : 1);
    int same = ok && a2.n == b.n && !memcmp(a2.x, b.x, nd * sizeof *b.x) &&
               !memcmp(a2.v, b.v, nd * sizeof *b.v) &&
               !memcmp(a2.sig, b.sig, b.n * 6 * sizeof *b.sig);
    *differ = memcmp(a.x, b.x, nd * sizeof *a.x) || memcmp(a.v, b.v, nd * sizeof *a.v) ||
              memcmp(a.sig, b.sig, a.n * 6 * sizeof *a.sig);
    TLOG("%-28s %5zu particles %4ld steps: %s vs %s: |dx|/h %.1e, dv %.1e, dsigma %.1e, "
         "denergy %.1e; bits %s; AVX2 again: %s",
         name, a.n, steps, rb, ra, dx, dv, ds, de, *differ ? "differ" : "equal",
         same ? "same bits" : "DIFFERENT");
    int rc = a.n == b.n && !strcmp(ra, "portable") && !strcmp(rb, "avx2-fma") && dx <= tol &&
                     dv <= tol && ds <= tol && de <= tol && same
                 ? 0
                 : -1;
    kstate_free(&a);
    kstate_free(&b);
    kstate_free(&a2);
    return rc;
}

/* Without AVX2: AVX2 is refused naming the field, AUTO runs portable. */
static void no_avx2(void)
{
    mpm_paper t;
    mpm_paper_disks(&t, MPM_METHOD_MPM, MPM_MUSL, 0.1);
    t.c.kernels = MPM_KERNELS_AVX2;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    char txt[T_ERRLEN];
    TLOG("no AVX2+FMA here: %s",
         s ? "(accepted)" : mpm_error_text(&err, MPM_FIELD_PROTO, txt, sizeof txt));
    mpm_sim_destroy(&s);
    CHECK(err.code == MPM_EINVAL && strstr(txt, "kernels: ") == txt);
    t.c.kernels = MPM_KERNELS_AUTO;
    s = mpm_sim_new(&t.c, NULL, &err);
    mpm_paper_free(&t);
    CHECK(s && !strcmp(mpm_sim_kernels(s), "portable"));
    mpm_sim_destroy(&s);
}

/* The tolerance: FMA changes a rounding per fused operation (relative
 * 1.1e-16), which the dynamics carry along.  Over these runs (the disks'
 * impact, the bar's 1.5 periods, the cube's wall contact, a granular
 * collapse's first steps) the measured differences are 1e-14..1e-11
 * (the log); 1e-9 leaves room and still fails any kernel that computes
 * something else (a wrong weight or a lost term moves results by far
 * more). */
#define KTOL 1e-9

TEST(kernels_avx2_matches_portable)
{
    if (!mpm_kernels_avx2_available()) {
        no_avx2();
        return;
    }
    int differ = 0, any = 0;
    static const struct {
        mpm_method m;
        mpm_update up;
        mpm_transfer tr;
        const char *name;
    } disks[] = {
        {MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_FLIP, "disks MPM USF"},
        {MPM_METHOD_MPM, MPM_USL, MPM_TRANSFER_FLIP, "disks MPM USL"},
        {MPM_METHOD_GIMP, MPM_MUSL, MPM_TRANSFER_FLIP, "disks GIMP MUSL"},
        {MPM_METHOD_BSPLINE2, MPM_MUSL, MPM_TRANSFER_FLIP, "disks BSPLINE2 MUSL (default)"},
        {MPM_METHOD_BSPLINE3, MPM_USF, MPM_TRANSFER_FLIP, "disks BSPLINE3 USF"},
        {MPM_METHOD_BSPLINE2, MPM_MUSL, MPM_TRANSFER_APIC, "disks BSPLINE2 MUSL APIC"},
    };
    for (size_t i = 0; i < sizeof disks / sizeof disks[0]; i++) {
        mpm_paper t;
        mpm_paper_disks(&t, disks[i].m, disks[i].up, 0.05);
        t.c.transfer = disks[i].tr;
        if (disks[i].tr == MPM_TRANSFER_APIC && disks[i].m == MPM_METHOD_MPM)
            t.c.cfl = MPM_APIC_MPM_MAX_CFL;
        int rc = compare(disks[i].name, &t.c, 150, KTOL, &differ);
        mpm_paper_free(&t);
        CHECKF(rc == 0, "%s", disks[i].name);
        any |= differ;
    }
    mpm_paper t;
    CHECK(mpm_paper_bar(&t, MPM_METHOD_GIMP, MPM_USL, 13, 2, 3, 1e-3, 0.1) == 0);
    int rc = compare("bar GIMP USL", &t.c, 1500, KTOL, &differ);
    mpm_paper_free(&t);
    CHECK(rc == 0);
    any |= differ;
    static cube_case cube;
    cube_build(&cube, MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_FLIP);
    CHECK(compare("cube3d MPM USF", &cube.c, 100, KTOL, &differ) == 0);
    any |= differ;
    cube_build(&cube, MPM_METHOD_BSPLINE2, MPM_MUSL, MPM_TRANSFER_FLIP);
    CHECK(compare("cube3d BSPLINE2 MUSL", &cube.c, 100, KTOL, &differ) == 0);
    any |= differ;
    cube_build(&cube, MPM_METHOD_GIMP, MPM_MUSL, MPM_TRANSFER_APIC);
    CHECK(compare("cube3d GIMP MUSL APIC", &cube.c, 100, KTOL, &differ) == 0);
    any |= differ;
    /* The mass tolerance's branch (Fig. 7: a node of mass <= M_TOL is
     * phantom): where a node's mass lands within round-off of M_TOL, two
     * runs that round differently can take different branches.  The cube
     * with GIMP USL meets one on the floor at step 7: a particle's sigma_yy
     * moves by 2e-7 Pa, 1.7e-6 of that step's largest stress (2.8e-9 of
     * it by step 100).  With a larger tolerance (1e-6) no node sits at it
     * and the kernels agree to round-off again.  Runs on other thread
     * counts, which sum in another order, can meet such a node too. */
    cube_build(&cube, MPM_METHOD_GIMP, MPM_USL, MPM_TRANSFER_APIC);
    CHECK(compare("cube3d GIMP USL APIC", &cube.c, 100, 1e-5, &differ) == 0);
    any |= differ;
    cube.c.mass_tol = 1e-6;
    CHECK(compare("  the same, mass_tol 1e-6", &cube.c, 100, KTOL, &differ) == 0);
    any |= differ;
    /* Drucker-Prager (the plastic update is portable code; the kernels
     * around it are not) */
    mpm_collapse_cfg cfg = {.a = 2,
                            .cells = 8,
                            .method = MPM_METHOD_BSPLINE2,
                            .model = MPM_MODEL_DRUCKER_PRAGER,
                            .threads = 2};
    mpm_collapse_case cc;
    CHECK(mpm_collapse_setup(&cfg, &cc) == 0);
    rc = compare("collapse DP BSPLINE2 USF", &cc.c, 300, KTOL, &differ);
    mpm_collapse_free(&cc);
    CHECK(rc == 0);
    any |= differ;
    /* the AVX2 families fuse multiply-adds in the optimised builds (not
     * at the sanitizers' -O1), and then they moved some last bits */
    int fuses = mpm_kernels_avx2_fuses();
    TLOG("this build's AVX2 kernels %s a * b + c; the bits %s", fuses ? "fuse" : "do not fuse",
         any ? "differed in some case" : "were the same in every case");
    CHECK(any == fuses);
}

/* A support whose last row ends the grid arrays.  The AVX2 kernels load
 * and store a row of a 3-node support as four lanes, so the row that ends
 * an array reaches one double past its last node: the grid fields and
 * minv have MPM_GRID_SLACK doubles there (mpm_grid.h).  A box in the
 * grid's top corner, moving into it at (1, 1) m/s (2D; 3D (1, 1, 1)):
 * the B-splines' supports reach the last node of the padded grid at once
 * (no padding), GIMP's when the body has moved into the padding (2D: step
 * 78).  Each case asserts that the last node of the arrays got mass (so
 * the row ending there was scattered and gathered), and that the AVX2 run
 * agrees with the portable one (KTOL): a fourth lane written to a real
 * node would not.  Under AddressSanitizer (make test) a grid without the
 * slack fails here: built with MPM_GRID_SLACK 0, the 2D GIMP USF case
 * stops in scatter_mq() on a 32-byte read 0 bytes past the mass array. */
TEST(kernels_support_at_grid_end)
{
    static const struct {
        int dim;
        mpm_method m;
        mpm_update up;
        int steps;
        const char *name;
    } cs[] = {
        {2, MPM_METHOD_BSPLINE2, MPM_MUSL, 5, "2D BSPLINE2 MUSL"},
        {2, MPM_METHOD_BSPLINE3, MPM_USF, 5, "2D BSPLINE3 USF"},
        {2, MPM_METHOD_GIMP, MPM_USF, 90, "2D GIMP USF"},
        {2, MPM_METHOD_GIMP, MPM_MUSL, 90, "2D GIMP MUSL"},
        {3, MPM_METHOD_BSPLINE2, MPM_USF, 5, "3D BSPLINE2 USF"},
        {3, MPM_METHOD_GIMP, MPM_USL, 90, "3D GIMP USL"},
    };
    const int avx = mpm_kernels_avx2_available();
    for (size_t i = 0; i < sizeof cs / sizeof cs[0]; i++) {
        mpm_case c;
        mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                                 .youngs_modulus = 1e3,
                                 .poisson_ratio = 0.3,
                                 .density = 1.0};
        mpm_body_desc b;
        memset(&c, 0, sizeof c);
        memset(&b, 0, sizeof b);
        b.shape = MPM_SHAPE_BOX;
        b.ppc = 2;
        c.grid.dim = cs[i].dim;
        for (int d = 0; d < cs[i].dim; d++) {
            b.lo[d] = 0.7;
            b.hi[d] = 1.0;
            b.velocity[d] = 1.0;
            c.grid.h[d] = 0.1;
            c.grid.nodes[d] = 11;
        }
        c.method = cs[i].m;
        c.update = cs[i].up;
        c.n_materials = 1;
        c.materials = &mat;
        c.n_bodies = 1;
        c.bodies = &b;
        mpm_sim *s[2] = {NULL, NULL};
        double end_m[2] = {0, 0};
        for (int k = 0; k < 2; k++) {
            mpm_error err;
            c.kernels = k && avx ? MPM_KERNELS_AVX2 : MPM_KERNELS_PORTABLE;
            s[k] = mpm_sim_new(&c, NULL, &err);
            CHECKF(s[k], "%s: %s", cs[i].name, TERR(&err));
            CHECKF(mpm_sim_run(s[k], cs[i].steps) == 0, "%s: %s", cs[i].name,
                   mpm_sim_error(s[k])->message);
            end_m[k] = s[k]->g.m[s[k]->nn - 1];
        }
        size_t n = mpm_sim_particles(s[0]), nd = n * (size_t)cs[i].dim;
        double *x[2], *v[2];
        for (int k = 0; k < 2; k++) {
            x[k] = malloc(nd * sizeof(double));
            v[k] = malloc(nd * sizeof(double));
            CHECK(x[k] && v[k]);
            mpm_sim_snapshot(s[k], &(mpm_snapshot){.x = x[k], .v = v[k]});
        }
        double dx = maxrel(x[0], x[1], nd), dv = maxrel(v[0], v[1], nd);
        TLOG("%-17s %4zu particles, %2d steps: mass at the arrays' last node %.3g (portable) "
             "%.3g (%s); %s vs portable: dx %.1e, dv %.1e",
             cs[i].name, n, cs[i].steps, end_m[0], end_m[1], mpm_sim_kernels(s[1]),
             mpm_sim_kernels(s[1]), dx, dv);
        CHECKF(end_m[0] > 0 && end_m[1] > 0, "%s: no support reached the arrays' end", cs[i].name);
        CHECKF(dx <= KTOL && dv <= KTOL, "%s", cs[i].name);
        for (int k = 0; k < 2; k++) {
            free(x[k]);
            free(v[k]);
            mpm_sim_destroy(&s[k]);
        }
    }
}

/* Grids too narrow for an interior B-spline span on an axis (quadratic:
 * fewer than 3 cells, cubic: fewer than 5).  The AVX2 kernels compute
 * four particles' weights at once from the interior spans' closed forms
 * (bs_block4()), which must not run there: every span of such an axis is
 * clamped.  Two boxes filling 1 .. 6 cells along x of a 1D, 2D and 3D
 * grid, pressed together along y (x in 1D), so that they carry stress,
 * against the portable kernels (KTOL): the closed forms on a clamped span
 * give other weights (partition of unity and the first moment broken),
 * and the runs part by far more. */
TEST(kernels_bspline_small_grids)
{
    if (!mpm_kernels_avx2_available()) {
        TLOG("no AVX2+FMA here: the four-particle B-spline weights do not run");
        return;
    }
    static const mpm_method ms[] = {MPM_METHOD_BSPLINE2, MPM_METHOD_BSPLINE3};
    int runs = 0;
    for (int dim = 1; dim <= 3; dim++)
        for (size_t m = 0; m < 2; m++)
            for (int cells = ms[m] == MPM_METHOD_BSPLINE3 ? 3 : 1; cells <= 6; cells++) {
                mpm_case c;
                mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                                         .youngs_modulus = 1e3,
                                         .poisson_ratio = 0.3,
                                         .density = 1.0};
                mpm_body_desc b[2];
                memset(&c, 0, sizeof c);
                memset(b, 0, sizeof b);
                const int a = dim > 1; /* the axis the boxes meet along */
                c.grid.dim = dim;
                for (int d = 0; d < dim; d++) {
                    c.grid.h[d] = 0.1;
                    c.grid.nodes[d] = d == 0 ? cells + 1 : 9;
                }
                for (int k = 0; k < 2; k++) {
                    b[k].shape = MPM_SHAPE_BOX;
                    b[k].ppc = 4;
                    for (int d = 0; d < dim; d++) {
                        double lo = d == 0 ? 0.0 : 0.2, hi = d == 0 ? 0.1 * cells : 0.6;
                        double mid = 0.5 * (lo + hi);
                        b[k].lo[d] = d == a && k ? mid : lo;
                        b[k].hi[d] = d == a && !k ? mid : hi;
                        b[k].velocity[d] = d == a ? (k ? -0.2 : 0.2) : 0.0;
                    }
                }
                c.method = ms[m];
                c.update = MPM_MUSL;
                c.n_materials = 1;
                c.materials = &mat;
                c.n_bodies = 2;
                c.bodies = b;
                char name[64];
                snprintf(name, sizeof name, "%dD %s, %d cell%s in x", dim,
                         ms[m] == MPM_METHOD_BSPLINE2 ? "BSPLINE2" : "BSPLINE3", cells,
                         cells > 1 ? "s" : "");
                int differ = 0;
                CHECKF(compare(name, &c, 20, KTOL, &differ) == 0, "%s", name);
                runs++;
            }
    CHECK(runs == 30); /* BSPLINE3 from 3 cells (4 nodes) */
}

/* The AVX2 kernels check the moved particles four at a time and take a
 * group with a bad particle through the one-by-one loop, which must name
 * the first bad one in storage order, as the portable kernels do.  A
 * lattice of particles (4 per cell and axis, cells 2 .. 5 of 8; 3D 2 .. 3)
 * moving uniformly at 0.1 h a step along x, so that its last layer leaves
 * the grid in one step, in 1D, 2D and 3D, MPM and GIMP, USF and USL; with
 * 0 .. 3 particles at rest in the first cell, which the sort puts before
 * the lattice, so that the first bad particle falls in each lane of its
 * group.  Both kernels must fail with MPM_ELEFTGRID at the same step and
 * with the same message, which names a particle of the last layer. */
TEST(kernels_first_bad_particle)
{
    if (!mpm_kernels_avx2_available()) {
        TLOG("no AVX2+FMA here: the four-particle checks do not run");
        return;
    }
    static const mpm_method ms[] = {MPM_METHOD_MPM, MPM_METHOD_GIMP};
    static const mpm_update us[] = {MPM_USF, MPM_USL};
    const double h = 0.125, dp = h / 4;
    int runs = 0;
    for (int dim = 1; dim <= 3; dim++) {
        int per = dim == 3 ? 8 : 16;
        size_t n = 1;
        for (int d = 0; d < dim; d++) n *= (size_t)per;
        double *x = malloc(n * 3 * sizeof *x), *vol = malloc(n * sizeof *vol);
        double *v = calloc(n * 3, sizeof *v);
        double ex[3 * 3], evol[3], ev[3 * 3] = {0};
        CHECK(x && vol && v);
        for (size_t i = 0; i < n; i++) {
            size_t r = i;
            for (int d = 0; d < dim; d++) {
                x[i * (size_t)dim + (size_t)d] = 2 * h + (0.5 + (double)(r % (size_t)per)) * dp;
                r /= (size_t)per;
            }
            v[i * (size_t)dim] = 0.1 * h / 0.005;
            vol[i] = 1.0;
            for (int d = 0; d < dim; d++) vol[i] *= dp;
        }
        for (int e = 0; e < 3; e++) {
            for (int d = 0; d < dim; d++) ex[e * dim + d] = (0.5 + e) * dp;
            evol[e] = vol[0];
        }
        for (int extra = 0; extra <= 3; extra++)
            for (size_t m = 0; m < 2; m++)
                for (size_t u = 0; u < 2; u++) {
                    mpm_case c;
                    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                                             .youngs_modulus = 1.0,
                                             .poisson_ratio = 0.3,
                                             .density = 1.0};
                    mpm_body_desc b[2];
                    memset(&c, 0, sizeof c);
                    memset(b, 0, sizeof b);
                    b[0].n_points = n;
                    b[0].x = x;
                    b[0].volume = vol;
                    b[0].v = v;
                    b[1].n_points = (size_t)extra;
                    b[1].x = ex;
                    b[1].volume = evol;
                    b[1].v = ev;
                    c.grid.dim = dim;
                    for (int d = 0; d < dim; d++) {
                        c.grid.h[d] = h;
                        c.grid.nodes[d] = 9;
                    }
                    c.method = ms[m];
                    c.update = us[u];
                    c.dt = 0.005;
                    c.n_materials = 1;
                    c.materials = &mat;
                    c.n_bodies = extra ? 2 : 1;
                    c.bodies = b;
                    int rc[2];
                    long steps[2];
                    char msg[2][MPM_ERROR_MSG_MAX];
                    for (int k = 0; k < 2; k++) {
                        mpm_error err;
                        c.kernels = k ? MPM_KERNELS_AVX2 : MPM_KERNELS_PORTABLE;
                        mpm_sim *s = mpm_sim_new(&c, NULL, &err);
                        CHECKF(s, "%dD: %s", dim, TERR(&err));
                        rc[k] = mpm_sim_run(s, 400);
                        steps[k] = mpm_sim_steps(s);
                        snprintf(msg[k], sizeof msg[k], "%s", mpm_sim_error(s)->message);
                        mpm_sim_destroy(&s);
                    }
                    if (m == 0 && u == 0) TLOG("%dD, %d at rest: %s", dim, extra, msg[1]);
                    CHECKF(rc[0] == MPM_ELEFTGRID && rc[1] == MPM_ELEFTGRID, "%dD: rc %d, %d", dim,
                           rc[0], rc[1]);
                    CHECKF(steps[0] == steps[1] && !strcmp(msg[0], msg[1]),
                           "%dD, %d at rest: portable '%s' (%ld steps), AVX2 '%s' (%ld)", dim,
                           extra, msg[0], steps[0], msg[1], steps[1]);
                    unsigned long id = 0;
                    CHECKF(sscanf(msg[1], "particle %lu left", &id) == 1 && id < n &&
                               id % (unsigned long)per == (unsigned long)per - 1,
                           "%dD: not a particle of the last layer: %s", dim, msg[1]);
                    runs++;
                }
        free(x);
        free(vol);
        free(v);
    }
    CHECK(runs == 48);
}

/* The tents by lanes (mpm_tlane.inc): four particles of one cell's run at a
 * time, the lanes past the run not moved, a cell with a phantom corner
 * and a block's last particles one by one.  Explicit particles put 1 .. 9
 * (2D) or 1 .. 8 (3D) in a cell, so that runs of every length start at
 * every lane, with a drift and a scatter of velocities that moves them
 * across cells; a layer on the grid line past the body gives its cells
 * phantom corners at the first step.  USF (its stress pass, and in 3D
 * its moving pass) and USL (its moving pass), each also with the PIC/FLIP
 * blend, on 1, 2 and 3 threads (the threads' ranges end at other lanes).  Each run: the AVX2
 * kernels against the portable ones within KTOL, and bit for bit where this build does not fuse
 * (the sanitizer builds: there a lane that took another cell's corners, or a lane past its run that
 * was moved, shows as a bit). */
static uint64_t lcg(uint64_t *st)
{
    *st = *st * 6364136223846793005ull + 1442695040888963407ull;
    return *st >> 11;
}

/* The particles of kernels_tent_lanes in dim dimensions (cells of 1 ..
 * maxper particles, the layer on a grid line); h = 0.125, nodes per axis
 * in *nodes.  Returns the count, 0 when out of memory (nothing to free). */
static size_t lanes_layout(int dim, double **xo, double **vo, double **volo, int *nodes)
{
    const double h = 0.125;
    const int lo = 3, hi = dim == 2 ? 11 : 7;
    const int span = hi - lo, maxper = dim == 2 ? 9 : 8;
    *nodes = dim == 2 ? 16 : 12;
    size_t ncell = 1, cap = 0;
    for (int d = 0; d < dim; d++) ncell *= (size_t)span;
    cap = ncell * (size_t)maxper + ncell; /* the cells, and the layer on the grid line */
    double *x = malloc(cap * 3 * sizeof *x), *vol = malloc(cap * sizeof *vol);
    double *v = malloc(cap * 3 * sizeof *v);
    if (!x || !vol || !v) {
        free(x);
        free(vol);
        free(v);
        return 0;
    }
    uint64_t st = 12345u + (uint64_t)dim;
    size_t n = 0;
    for (size_t c = 0; c < ncell; c++) {
        int ci[3] = {0, 0, 0};
        size_t r = c;
        for (int d = 0; d < dim; d++) {
            ci[d] = lo + (int)(r % (size_t)span);
            r /= (size_t)span;
        }
        int per = 1 + (int)((c * 5 + c / 3) % (size_t)maxper);
        for (int k = 0; k < per; k++, n++)
            for (int d = 0; d < dim; d++) {
                double u = (double)(lcg(&st) % 1000) / 1000.0;
                x[n * (size_t)dim + (size_t)d] = (ci[d] + 0.05 + 0.9 * u) * h;
                v[n * (size_t)dim + (size_t)d] =
                    (d == 0 ? 0.4 : 0.25) + 0.1 * ((double)(lcg(&st) % 1000) / 500.0 - 1.0);
            }
        /* the layer on the grid line x = hi h, past the body: its
         * cells' corners at x = (hi + 1) h have no mass at first */
        if (ci[0] == hi - 1) {
            x[n * (size_t)dim] = hi * h;
            for (int d = 1; d < dim; d++) x[n * (size_t)dim + (size_t)d] = (ci[d] + 0.5) * h;
            for (int d = 0; d < dim; d++) v[n * (size_t)dim + (size_t)d] = d == 0 ? 0.4 : 0.25;
            n++;
        }
    }
    for (size_t i = 0; i < n; i++) vol[i] = pow(h, dim) / 5.0;
    *xo = x;
    *vo = v;
    *volo = vol;
    return n;
}

/* A case of the lanes' particles: MPM, update up, PIC fraction pic, th
 * threads, dt 0.002, one linear-elastic material (mat, b: the caller's). */
static void lanes_case(mpm_case *c, mpm_material_desc *mat, mpm_body_desc *b, int dim, size_t n,
                       double *x, double *v, double *vol, int nodes, mpm_update up, double pic,
                       int th)
{
    *mat = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                               .youngs_modulus = 10.0,
                               .poisson_ratio = 0.3,
                               .density = 1.0};
    memset(c, 0, sizeof *c);
    memset(b, 0, sizeof *b);
    b->n_points = n;
    b->x = x;
    b->volume = vol;
    b->v = v;
    c->grid.dim = dim;
    for (int d = 0; d < dim; d++) {
        c->grid.h[d] = 0.125;
        c->grid.nodes[d] = nodes;
    }
    c->method = MPM_METHOD_MPM;
    c->update = up;
    c->pic_fraction = pic;
    c->dt = 0.002;
    c->threads = th;
    c->n_materials = 1;
    c->materials = mat;
    c->n_bodies = 1;
    c->bodies = b;
}

TEST(kernels_tent_lanes)
{
    if (!mpm_kernels_avx2_available()) {
        TLOG("no AVX2+FMA here: the tents' lanes do not run");
        return;
    }
    int any = 0, runs = 0;
    for (int dim = 2; dim <= 3; dim++) {
        double *x, *v, *vol;
        int nodes;
        size_t n = lanes_layout(dim, &x, &v, &vol, &nodes);
        CHECK(n > 0);
        static const mpm_update us[] = {MPM_USF, MPM_USL, MPM_USL, MPM_USF};
        for (int u = 0; u < 4; u++)
            for (int th = 1; th <= 3; th++) {
                mpm_case c;
                mpm_material_desc mat;
                mpm_body_desc b;
                lanes_case(&c, &mat, &b, dim, n, x, v, vol, nodes, us[u], u >= 2 ? 0.3 : 0.0, th);
                char name[64];
                snprintf(name, sizeof name, "%dD MPM %s%s, %d thr", dim,
                         us[u] == MPM_USL ? "USL" : "USF", u >= 2 ? " blend" : "", th);
                int differ = 0;
                CHECKF(compare(name, &c, 300, KTOL, &differ) == 0, "%s", name);
                any |= differ;
                runs++;
            }
        TLOG("%dD: %zu particles", dim, n);
        free(x);
        free(vol);
        free(v);
    }
    CHECK(runs == 24);
    CHECK(any == mpm_kernels_avx2_fuses());
}

/* Runs s for steps steps and snapshots x, v and sigma into k (n
 * particles, dim); 0 or -1. */
static int run_snap(mpm_sim *s, long steps, kstate *k)
{
    memset(k, 0, sizeof *k);
    k->n = mpm_sim_particles(s);
    k->dim = mpm_sim_dim(s);
    k->x = malloc(k->n * (size_t)k->dim * sizeof *k->x);
    k->v = malloc(k->n * (size_t)k->dim * sizeof *k->v);
    k->sig = malloc(k->n * 6 * sizeof *k->sig);
    if (mpm_sim_run(s, steps) || !k->x || !k->v || !k->sig) {
        kstate_free(k);
        return -1;
    }
    mpm_sim_snapshot(s, &(mpm_snapshot){.x = k->x, .v = k->v, .stress = k->sig});
    return 0;
}

/* USF's stress pass from strain to stress (2D: to force) in registers
 * (mpm_sim.plan.el_lanes, el_block() of the AVX2 kernels): the same bits as the
 * general pass (strains, stresses and forces of a block in turn), in 2D
 * and 3D, with runs of 1-9 (3D: 1-8) particles per cell, phantom corners
 * and the blend, on 1-3 threads. */
TEST(kernels_el_same_bits)
{
    if (!mpm_kernels_avx2_available()) {
        TLOG("no AVX2+FMA here: the AVX2 kernels' fused stress pass does not run");
        return;
    }
    int runs = 0;
    for (int dim = 2; dim <= 3; dim++) {
        double *x, *v, *vol;
        int nodes;
        size_t n = lanes_layout(dim, &x, &v, &vol, &nodes);
        CHECK(n > 0);
        for (int blend = 0; blend < 2; blend++)
            for (int th = 1; th <= 3; th++) {
                mpm_case c;
                mpm_material_desc mat;
                mpm_body_desc b;
                lanes_case(&c, &mat, &b, dim, n, x, v, vol, nodes, MPM_USF, blend ? 0.3 : 0.0, th);
                c.kernels = MPM_KERNELS_AVX2;
                kstate k[2];
                memset(k, 0, sizeof k);
                int ok = 1, on = 0;
                size_t nd = (size_t)dim * n;
                for (int side = 0; side < 2; side++) {
                    mpm_error err;
                    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
                    if (!s) {
                        ok = 0;
                        break;
                    }
                    if (side == 0) on = s->plan.el_lanes;
                    /* side 1: the general pass */
                    if (side == 1 && mpm_sim_plan_override(s, "el_lanes=0", NULL)) ok = 0;
                    ok &= run_snap(s, 300, &k[side]) == 0;
                    mpm_sim_destroy(&s);
                }
                if (ok) {
                    ok = !memcmp(k[0].x, k[1].x, nd * sizeof *k[0].x) &&
                         !memcmp(k[0].v, k[1].v, nd * sizeof *k[0].v) &&
                         !memcmp(k[0].sig, k[1].sig, 6 * n * sizeof *k[0].sig);
                    if (!ok)
                        TLOG("%dD %s, %d thr: differ, rel. %.3g in x, %.3g in sigma", dim,
                             blend ? "blend" : "FLIP", th, maxrel(k[0].x, k[1].x, nd),
                             maxrel(k[0].sig, k[1].sig, 6 * n));
                }
                kstate_free(&k[0]);
                kstate_free(&k[1]);
                if (!on || !ok) {
                    free(x);
                    free(vol);
                    free(v);
                }
                CHECKF(on, "%dD: the case did not take the fused stress pass (el_lanes 0)", dim);
                CHECKF(ok, "%dD MPM USF%s, %d thr: the fused stress pass and the general differ",
                       dim, blend ? " blend" : "", th);
                runs++;
            }
        TLOG("%dD: %zu particles, 6 runs of 300 steps: x, v and sigma equal bit for bit", dim, n);
        free(x);
        free(vol);
        free(v);
    }
    CHECK(runs == 12);
}

TEST(kernels_field_checked)
{
    mpm_paper t;
    mpm_paper_disks(&t, MPM_METHOD_MPM, MPM_MUSL, 0.1);
    t.c.kernels = (mpm_kernels_isa)7;
    mpm_error err;
    mpm_case_info info;
    int rc = mpm_case_check(&t.c, &info, &err);
    char txt[T_ERRLEN];
    TLOG("%s", mpm_error_text(&err, MPM_FIELD_PROTO, txt, sizeof txt));
    CHECK(rc == MPM_EINVAL && strstr(txt, "kernels: unknown value 7") == txt);
    /* mpm_sim_new() checks it too when handed a checked case */
    t.c.kernels = MPM_KERNELS_AUTO;
    CHECK(mpm_case_check(&t.c, &info, &err) == 0);
    t.c.kernels = (mpm_kernels_isa)-1;
    mpm_sim *s = mpm_sim_new(&t.c, &info, &err);
    mpm_paper_free(&t);
    mpm_error_text(&err, MPM_FIELD_PROTO, txt, sizeof txt);
    CHECK(!s && err.code == MPM_EINVAL && strstr(txt, "kernels: unknown value -1") == txt);
}
