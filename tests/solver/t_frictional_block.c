/*
 * t_frictional_block.c - the frictional models' block update
 * (solver/mpm_model.c): the 2D and 3D loops that write out
 * the Jaumann rotation, Drucker-Prager's elastic trial and the stores give
 * the same bits as the general per-particle path (rate_gather(),
 * mpm_dp_trial(), rate_put(), mpm_model_blk.general), on random states
 * that take every branch: elastic inside the cone and on it, the cone's
 * return, the tension cut-off, Mohr-Coulomb particles among them, and
 * non-finite increments that the update refuses.
 */
#include "mpm.h"
#include "mpm_material_table.h"
#include "mpm_model.h"
#include "t.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define NP 6000 /* particles */
#define B0 37   /* the block's first particle */
#define I0 5    /* its first slot */

static uint64_t rng;
static double urand(void)
{
    return t_urand(&rng);
}
static double srand1(void)
{
    return t_srand(&rng);
}

/* One set of particle arrays (the ones the frictional block reads and
 * writes) in one allocation. */
typedef struct {
    mpm_particles P;
    double *deps[9];
    double *mem;
} parts;

static int parts_new(parts *a, int dim)
{
    int nc = MPM_NCOMP(dim), nd = dim == 2 ? 4 : 9;
    memset(a, 0, sizeof *a);
    a->mem = calloc((size_t)(2 * nc + 3 + nd) * NP, sizeof(double));
    a->P.mat = calloc(NP, sizeof *a->P.mat);
    if (!a->mem || !a->P.mat) return -1;
    double *m = a->mem;
    for (int c = 0; c < nc; c++, m += NP) a->P.sig[c] = m;
    for (int c = 0; c < nc; c++, m += NP)
        if (!(dim == 2 && c == 2)) a->P.eps[c] = m; /* 2D: eps_zz has no array */
    a->P.epsp = m, m += NP;
    a->P.yld = m, m += NP;
    a->P.vol = m, m += NP;
    for (int c = 0; c < nd; c++, m += NP) a->deps[c] = m;
    return 0;
}

static void parts_free(parts *a)
{
    free(a->mem);
    free(a->P.mat);
}

/* The same values in b as in a (the same layout). */
static void parts_copy(parts *b, const parts *a, int dim)
{
    int nc = MPM_NCOMP(dim), nd = dim == 2 ? 4 : 9;
    memcpy(b->mem, a->mem, (size_t)(2 * nc + 3 + nd) * NP * sizeof(double));
    memcpy(b->P.mat, a->P.mat, NP * sizeof *a->P.mat);
}

static int parts_same(const parts *a, const parts *b, int dim)
{
    int nc = MPM_NCOMP(dim);
    return !memcmp(a->mem, b->mem, (size_t)(2 * nc + 3) * NP * sizeof(double));
}

/* Three materials: a cohesive Drucker-Prager with a tension cut-off, a
 * cohesionless one with dilatancy, and a Mohr-Coulomb. */
static int materials(int dim, mpm_mat_params mats[3], mpm_plastic_params pl[3])
{
    mpm_material_desc d[3];
    memset(d, 0, sizeof d);
    for (int k = 0; k < 3; k++) {
        d[k].youngs_modulus = 1e7 * (1 + k);
        d[k].poisson_ratio = 0.3 - 0.05 * k;
        d[k].density = 1800;
        d[k].model = k < 2 ? MPM_MODEL_DRUCKER_PRAGER : MPM_MODEL_MOHR_COULOMB;
    }
    d[0].friction_angle = 30, d[0].cohesion = 2e3, d[0].tension_cutoff = 500;
    d[1].friction_angle = 25, d[1].dilatancy_angle = 5;
    d[2].friction_angle = 35, d[2].cohesion = 1e3;
    for (size_t k = 0; k < 3; k++) {
        mpm_error err;
        if (mpm_material_check(&d[k], dim, k, &err) ||
            (mpm_model_params(&d[k], dim, &mats[k]),
             mpm_model_plastic(&d[k], dim, k, &pl[k], &err))) {
            fprintf(stderr, "    materials[%zu]: %s\n", k, err.message);
            return -1;
        }
        mats[k].pl = &pl[k];
    }
    return 0;
}

/* Random states: stresses of a few kPa (compressive on the whole, some in
 * tension), increments from 1e-9 to 1e-3 (elastic to far outside the
 * cone), the spins likewise, one particle in 500 with an infinite or NaN
 * increment. */
static void fill(parts *a, int dim, int onemat)
{
    int nc = MPM_NCOMP(dim), nd = dim == 2 ? 4 : 9;
    for (size_t p = 0; p < NP; p++) {
        a->P.mat[p] = (uint16_t)(urand() < 0.8 ? (urand() < 0.5 ? 0 : 1) : 2);
        if (onemat >= 0) a->P.mat[p] = (uint16_t)onemat;
        double pm = -5e3 * urand() + (urand() < 0.1 ? 3e3 : 0);
        for (int c = 0; c < nc; c++) {
            a->P.sig[c][p] = (c < 3 ? pm : 0) + 2e3 * srand1();
            if (a->P.eps[c]) a->P.eps[c][p] = 1e-3 * srand1();
        }
        a->P.epsp[p] = 0.01 * urand();
        a->P.yld[p] = urand() < 0.5;
        a->P.vol[p] = 1e-4 * (1 + urand());
    }
    for (size_t i = 0; i < NP; i++) {
        double mag = pow(10, -9 + 6 * urand());
        for (int c = 0; c < nd; c++) a->deps[c][i] = mag * srand1();
        if (urand() < 0.002) a->deps[(int)(urand() * nd) % nd][i] = urand() < 0.5 ? INFINITY : NAN;
    }
}

/* One comparison: the block as the solver runs it (the written-out 2D or
 * 3D loop, lanes as given) against the general path without lanes.  With
 * onemat >= 0 every particle is of that material and the block is run as
 * consecutive blocks of 1 to 150 particles (a block of one Drucker-Prager
 * material takes the elastic trials in lanes too, 64 to a call, with a
 * shorter group at a block's end). */
static void one_dim(int dim, int lanes, int onemat)
{
    mpm_mat_params mats[3];
    mpm_plastic_params pl[3];
    CHECK(materials(dim, mats, pl) == 0);
    parts a, b;
    int ok = parts_new(&a, dim) == 0 && parts_new(&b, dim) == 0;
    if (!ok) {
        parts_free(&a);
        parts_free(&b);
        CHECKF(0, "out of memory");
    }
    rng = 0x2545f4914f6cdd1dull + (uint64_t)dim;
    fill(&a, dim, onemat);
    parts_copy(&b, &a, dim);
    size_t nb = NP - B0;
    /* the same increments for both (the block reads them only) */
    mpm_model_blk fa = {mats, &a.P, a.deps, dim, 0.0, 0, 0, 0, SIZE_MAX, 0, lanes};
    mpm_model_blk fb = {mats, &b.P, a.deps, dim, 0.0, 0, 0, 0, SIZE_MAX, 1, 0};
    const mpm_model_ops *ops = mats[0].ops;
    CHECK(mats[2].ops->block == ops->block);
    if (onemat < 0) {
        ops->block(&fa, B0, I0, nb);
        ops->block(&fb, B0, I0, nb);
    }
    for (size_t i = I0, len; onemat >= 0 && i < nb; i += len) {
        len = 1 + (size_t)(urand() * 150);
        if (len > nb - i) len = nb - i;
        ops->block(&fa, B0, i, i + len);
        ops->block(&fb, B0, i, i + len);
    }
    /* how many particles took each branch (the general path's outcome) */
    long el = 0, yl = 0;
    for (size_t i = I0; i < nb; i++) {
        size_t p = B0 + i;
        el += b.P.yld[p] == 0;
        yl += b.P.yld[p] == 1;
    }
    TLOG("%dD%s%s: %zu particles, %lld plastic updates (%lld substeps, at most %d), %ld not on "
         "the surface after the update, %ld on it, first refused at %zu, plastic work %.6g",
         dim, lanes ? " (Drucker-Prager's lanes)" : "", onemat >= 0 ? ", one material" : "",
         nb - I0, fb.nupd, fb.nsub, fb.maxsub, el, yl, fb.bad, fb.wp);
    int same = parts_same(&a, &b, dim);
    long diff = 0;
    for (int c = 0; c < MPM_NCOMP(dim) && !same; c++)
        for (size_t p = 0; p < NP; p++) diff += memcmp(&a.P.sig[c][p], &b.P.sig[c][p], 8) != 0;
    parts_free(&a);
    parts_free(&b);
    CHECKF(same, "%dD: the written-out block%s differs from the general path (%ld stress entries)",
           dim, lanes ? " with lanes" : "", diff);
    CHECK(!memcmp(&fa.wp, &fb.wp, sizeof fa.wp));
    CHECK(fa.nupd == fb.nupd && fa.nsub == fb.nsub && fa.maxsub == fb.maxsub && fa.bad == fb.bad);
    /* every branch was taken */
    CHECKF(fb.nupd > (long long)nb / 10, "%lld plastic updates", fb.nupd);
    CHECKF(el > (long)nb / 10, "%ld particles off the surface", el);
    CHECKF(fb.bad != SIZE_MAX, "no refused update");
}

TEST(frictional_block_equals_general_path)
{
    one_dim(2, 0, -1);
    if (t_failed()) return;
    one_dim(3, 0, -1);
}

/* The same with Drucker-Prager's updates queued for mpm_dp_lanes() (the
 * queues flushed at Mohr-Coulomb particles and at changes of material),
 * where this CPU has AVX2; and blocks of one Drucker-Prager material, whose
 * elastic trials run four at a time (mpm_dp_trial2d_lanes(), _3d()). */
TEST(frictional_block_lanes_same_bits)
{
    if (!mpm_kernels_avx2_available()) {
        TLOG("this CPU has no AVX2: nothing to compare");
        return;
    }
    one_dim(2, 1, -1);
    if (t_failed()) return;
    one_dim(3, 1, -1);
    /* blocks of one Drucker-Prager material: the trials in lanes too */
    for (int m = 0; m < 4 && !t_failed(); m++) one_dim(2 + m / 2, 1, m % 2);
}
