/*
 * hashes.c - `mpmbench --hashes`: the same-bits harness of the solver's
 * refactors.  A fixed matrix of short runs (the paper's disks in 2D, a
 * box falling onto a floor in 1D, 2D and 3D, elastic and plastic; every
 * method, update scheme and transfer, the PIC/FLIP blend, both kernel
 * sets, 1 to 3 threads) each prints one line: its name and an FNV-1a hash
 * over the particles' arrays after the run (position, velocity, stress,
 * volume, and the plastic strain and F where the run has them) and over
 * the energy series (the in-step sums every 10 steps, the energy pass at
 * the end).  A refactor that keeps every bit prints the same lines: diff
 * the output of two builds (docs/performance.md, "Same bits").  A run the
 * solver refuses prints its error code in place of the hash, so the lines
 * stay comparable.  It asserts nothing and times nothing.
 */
#include "perf.h"

#include "mpm_paper.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define FNV0 1469598103934665603ull

static uint64_t fnv(uint64_t h, const void *p, size_t n)
{
    const unsigned char *b = p;
    for (size_t i = 0; i < n; i++) h = (h ^ b[i]) * 1099511628211ull;
    return h;
}

/* The scenes: the disks (2D), a box falling onto a fixed floor. */
enum { HS_DISKS, HS_BOX };

typedef struct {
    int scene, dim;
    mpm_method method;
    mpm_update update;
    mpm_transfer transfer;
    double pic;
    mpm_model_kind model;
    mpm_volume_update volume;
    int threads;
    mpm_kernels_isa kernels;
    int steps;
} hs_run;

/* The box: a block of 4 cells per axis (1D: 50 cells), 2-6 particles per
 * cell per axis, dropped at 0.3 m/s under gravity onto a wall at the low
 * face of the last axis, rollers on the others; enough particles per grid page that the steps
 * fuse (mpm_rows.c fuse_pays()). */
static void box_case(const hs_run *r, mpm_case *c, mpm_material_desc *mat, mpm_body_desc *b)
{
    int D = r->dim;
    memset(c, 0, sizeof *c);
    memset(mat, 0, sizeof *mat);
    memset(b, 0, sizeof *b);
    c->grid.dim = D;
    for (int d = 0; d < D; d++) {
        c->grid.h[d] = 0.1;
        c->grid.nodes[d] = D == 1 ? 60 : D == 2 ? 12 : 8;
        c->grid.origin[d] = 0;
        b->lo[d] = D == 1 ? 0.5 : 0.3;
        b->hi[d] = D == 1 ? 5.5 : 0.7;
        c->bc.face_mask[2 * d] = c->bc.face_mask[2 * d + 1] = 1u << d; /* rollers */
    }
    b->ppc = D == 1 ? 8 : D == 2 ? 6 : 4;
    b->shape = MPM_SHAPE_BOX;
    b->velocity[D - 1] = -0.3;
    c->gravity[D - 1] = -9.81;
    c->bc.face_mask[2 * (D - 1)] = 7;
    mat->model = r->model;
    mat->youngs_modulus = 1e5;
    mat->poisson_ratio = 0.3;
    mat->density = 100;
    mat->yield_stress = 200;
    mat->hardening_modulus = 100;
    mat->friction_angle = 30;
    mat->dilatancy_angle = 5;
    mat->cohesion = 50;
    mat->tension_cutoff = 10;
    c->n_materials = 1;
    c->materials = mat;
    c->n_bodies = 1;
    c->bodies = b;
}

/* Runs r: returns its step's code (0 or the MPM_E* that stopped it) and
 * *h its hash; 1 when the solver refuses the case, with *refused its
 * code. */
static int run_hash(const hs_run *r, uint64_t *h, int *refused)
{
    mpm_case c;
    mpm_material_desc mat;
    mpm_body_desc body;
    mpm_paper t;
    int paper = r->scene == HS_DISKS;
    if (paper)
        mpm_paper_disks(&t, r->method, r->update, 0.05);
    else
        box_case(r, &c, &mat, &body);
    mpm_case *cp = paper ? &t.c : &c;
    cp->method = r->method;
    cp->update = r->update;
    cp->transfer = r->transfer;
    cp->pic_fraction = r->pic;
    cp->volume_update = r->volume;
    cp->threads = r->threads;
    cp->kernels = r->kernels;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(cp, NULL, &err);
    if (paper) mpm_paper_free(&t);
    if (!s) {
        *refused = err.code;
        return 1;
    }
    uint64_t k = FNV0;
    int rc = 0;
    mpm_energy e;
    for (int i = 0; i < r->steps && !rc; i++) {
        if (i % 10 == 9) mpm_sim_want_energy(s);
        rc = mpm_sim_step(s);
        if (!rc && i % 10 == 9) {
            mpm_sim_energy(s, &e);
            k = fnv(k, &e, sizeof e);
        }
    }
    k = fnv(k, &rc, sizeof rc);
    size_t n = mpm_sim_particles(s);
    int D = mpm_sim_dim(s);
    double *x = calloc(n * D + 1, sizeof *x), *v = calloc(n * D + 1, sizeof *v);
    double *sig = calloc(n * 6 + 1, sizeof *sig), *vol = calloc(n + 1, sizeof *vol);
    double *ep = calloc(n + 1, sizeof *ep), *F = calloc(n * 9 + 1, sizeof *F);
    int pl = mpm_sim_has_field(s, MPM_FIELD_PLASTIC_STRAIN);
    int hf = mpm_sim_has_field(s, MPM_FIELD_DEFORMATION_GRADIENT);
    if (x && v && sig && vol && ep && F) {
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = x,
                                            .v = v,
                                            .stress = sig,
                                            .volume = vol,
                                            .plastic_strain = pl ? ep : NULL,
                                            .deformation_gradient = hf ? F : NULL});
        k = fnv(k, x, n * D * sizeof *x);
        k = fnv(k, v, n * D * sizeof *v);
        k = fnv(k, sig, n * 6 * sizeof *sig);
        k = fnv(k, vol, n * sizeof *vol);
        if (pl) k = fnv(k, ep, n * sizeof *ep);
        if (hf) k = fnv(k, F, n * 9 * sizeof *F);
        mpm_sim_energy(s, &e);
        k = fnv(k, &e, sizeof e);
    } else {
        rc = MPM_ENOMEM;
    }
    free(x);
    free(v);
    free(sig);
    free(vol);
    free(ep);
    free(F);
    mpm_sim_destroy(&s);
    *h = k;
    return rc;
}

static const mpm_method methods[] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_CPDI,
                                     MPM_METHOD_BSPLINE2, MPM_METHOD_BSPLINE3};
#define NMETH 5

static int nruns, nrefused;

static hs_run mk(int scene, int dim, mpm_method m, int u, int tr)
{
    return (hs_run){.scene = scene, .dim = dim, .method = m, .update = u, .transfer = tr};
}

static void one(hs_run r)
{
    uint64_t h = 0;
    int refused = 0;
    if (!r.steps) r.steps = r.scene == HS_DISKS ? 120 : 80;
    if (!r.threads) r.threads = 1;
    int rc = run_hash(&r, &h, &refused);
    static const char *models[] = {"el", "nh", "j2", "dp", "mc"};
    static const char *isa[] = {"auto", "portable", "avx2"};
    printf("%-5s %dd %-8s %-4s %-4s pic=%-4g %-2s vol=%d t=%d %-8s steps=%d  ",
           r.scene == HS_DISKS ? "disks" : "box", r.dim, mpm_method_key(r.method),
           mpm_update_key(r.update), mpm_transfer_key(r.transfer), r.pic, models[r.model], r.volume,
           r.threads, isa[r.kernels], r.steps);
    if (rc == 1) {
        printf("refused %d\n", refused);
        nrefused++;
    } else {
        if (rc)
            printf("%016llx (failed: %d)\n", (unsigned long long)h, rc);
        else
            printf("%016llx\n", (unsigned long long)h);
    }
    fflush(stdout);
    nruns++;
}

int pb_hashes(void)
{
    hs_run r;
    /* the disks: every method, scheme and transfer, on the default kernels */
    for (int m = 0; m < NMETH; m++)
        for (int u = 0; u < 3; u++)
            for (int tr = 0; tr < 2; tr++) {
                r = mk(HS_DISKS, 2, methods[m], u, tr);
                one(r);
            }
    /* the blend */
    for (int m = 0; m < NMETH; m++)
        for (int u = 0; u < 3; u += 2) {
            r = mk(HS_DISKS, 2, methods[m], u, MPM_TRANSFER_FLIP);
            r.pic = 0.25;
            one(r);
        }
    /* the portable kernels */
    for (int m = 0; m < NMETH; m++)
        for (int u = 0; u < 3; u++) {
            r = mk(HS_DISKS, 2, methods[m], u, 0);
            r.kernels = MPM_KERNELS_PORTABLE;
            one(r);
        }
    for (int m = 0; m < NMETH; m++) {
        r = mk(HS_DISKS, 2, methods[m], MPM_MUSL, MPM_TRANSFER_APIC);
        r.kernels = MPM_KERNELS_PORTABLE;
        one(r);
    }
    /* 2 and 3 threads */
    for (int m = 0; m < NMETH; m++)
        for (int u = 0; u < 3; u += 2)
            for (int t = 2; t <= 3; t++) {
                r = mk(HS_DISKS, 2, methods[m], u, 0);
                r.threads = t;
                one(r);
            }
    for (int m = 0; m < NMETH; m++) {
        r = mk(HS_DISKS, 2, methods[m], MPM_USL, MPM_TRANSFER_APIC);
        r.threads = 2;
        one(r);
    }
    /* the falling box, 1D to 3D: every method and scheme, 1-3 threads */
    for (int D = 1; D <= 3; D++)
        for (int m = 0; m < NMETH; m++)
            for (int u = 0; u < 3; u++) {
                r = mk(HS_BOX, D, methods[m], u, 0);
                r.threads = 1 + (m + u + D) % 3;
                one(r);
            }
    /* APIC and the blend on the box */
    for (int D = 1; D <= 3; D++) {
        r = mk(HS_BOX, D, MPM_METHOD_BSPLINE2, MPM_MUSL, MPM_TRANSFER_APIC);
        r.threads = D;
        one(r);
        r = mk(HS_BOX, D, MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_APIC);
        one(r);
        r = mk(HS_BOX, D, MPM_METHOD_GIMP, MPM_USL, MPM_TRANSFER_FLIP);
        r.pic = 0.5;
        r.threads = 2;
        one(r);
    }
    /* plastic and large-deformation materials on the box */
    for (int D = 2; D <= 3; D++) {
        static const mpm_method pm[] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2};
        for (int m = 0; m < 3; m++)
            for (int u = 0; u < 3; u += 2)
                for (int isa = 0; isa < 2; isa++) {
                    r = mk(HS_BOX, D, pm[m], u, 0);
                    r.model = MPM_MODEL_DRUCKER_PRAGER;
                    r.kernels = isa ? MPM_KERNELS_PORTABLE : MPM_KERNELS_AUTO;
                    r.threads = 1 + (m + u) % 2;
                    one(r);
                }
        r = mk(HS_BOX, D, MPM_METHOD_MPM, MPM_USL, 0);
        r.model = MPM_MODEL_VON_MISES;
        one(r);
        r = mk(HS_BOX, D, MPM_METHOD_GIMP, MPM_MUSL, 0);
        r.model = MPM_MODEL_NEO_HOOKEAN;
        r.volume = MPM_VOLUME_DET_F;
        r.threads = 2;
        one(r);
        r = mk(HS_BOX, D, MPM_METHOD_BSPLINE2, MPM_USF, 0);
        r.model = MPM_MODEL_MOHR_COULOMB;
        one(r);
        r = mk(HS_BOX, D, MPM_METHOD_CPDI, MPM_USL, 0);
        r.model = MPM_MODEL_DRUCKER_PRAGER;
        one(r);
    }
    r = mk(HS_BOX, 1, MPM_METHOD_MPM, MPM_USF, 0);
    r.model = MPM_MODEL_VON_MISES;
    one(r);
    r = mk(HS_BOX, 1, MPM_METHOD_GIMP, MPM_USF, 0);
    r.volume = MPM_VOLUME_CONSTANT;
    one(r);
    fprintf(stderr, "mpmbench --hashes: %d runs (%d refused by the solver)\n", nruns, nrefused);
    return 0;
}
