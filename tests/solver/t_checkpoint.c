/*
 * t_checkpoint.c - the solver's checkpoints (mpm_checkpoint.c): a run
 * stopped after K steps, saved, its simulation destroyed, a
 * fresh one made from the same case and loaded, then run to step N, ends
 * with the same bits as the run taken straight through (every snapshot
 * field, t, dt, steps, the energy sample with its balance error, the
 * budget's final and worst errors, the plastic counters), over a matrix
 * that covers each feature at least once (1D/2D/3D; MPM, GIMP, BSPLINE2,
 * BSPLINE3, CPDI; USF, USL, MUSL; FLIP, PIC blend, APIC; the five models;
 * gravity, tractions with time functions, point loads, prescribed
 * velocities, friction, damping, geostatic stress, the volume updates,
 * fixed and automatic dt, particle forces; 1 and 2 threads; K a multiple
 * of the sort interval and not).  Also: the refusals (a flipped byte, a
 * truncated or padded blob, another version, another case), a failed load
 * leaving the simulation as it was, and a 2-thread blob continued on 1
 * thread within round-off.
 */
#include "t.h"
#include "mpm.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_material.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* features of a case */
enum {
    F_GRAV = 1,
    F_TRAC_TF = 2,   /* a traction on the top with a RAMP time function */
    F_POINT = 4,     /* a point force */
    F_PRES = 8,      /* a prescribed velocity on the bottom face (x, TABLE) */
    F_FRIC = 16,     /* friction on the bottom face */
    F_DAMP_L = 32,   /* local damping until half the run */
    F_DAMP_V = 64,   /* viscous damping */
    F_GEO = 128,     /* geostatic initial stress */
    F_PFORCES = 256, /* mpm_sim_set_particle_forces() (changed at step 10) */
    F_FIXED_DT = 512
};

typedef struct {
    const char *name;
    int dim;
    mpm_method method;
    mpm_update update;
    mpm_transfer transfer;
    double pic;
    mpm_model_kind model;
    mpm_volume_update volume;
    unsigned feat;
    int threads;
    int K; /* save after K of N steps */
} ck_spec;

#define CK_N 40

/* A case and the storage behind it. */
typedef struct {
    mpm_case c;
    mpm_material_desc mat;
    mpm_body_desc body;
    mpm_traction_desc trac[2];
    mpm_timefn ramp, table;
    double tt[3], tv[3];
    mpm_prescribed_desc pres;
    mpm_friction_desc fric;
} ck_case;

/* A block x in [0.25, 0.75] (1D: [0, 0.5]), y in [0, 0.5], z in [0.25,
 * 0.75] on a grid of 8 cells of 0.125 per axis, 2 points per cell per
 * axis, moving at (0.2, -0.1, 0.05), the bottom face (1D: x_lo) fixed in
 * the vertical direction (all directions without friction or a
 * prescribed velocity). */
static void ck_build(ck_case *k, const ck_spec *sp)
{
    memset(k, 0, sizeof *k);
    int dim = sp->dim, up = dim == 1 ? 0 : 1; /* the vertical axis */
    mpm_case *c = &k->c;
    c->grid.dim = dim;
    for (int d = 0; d < dim; d++) {
        c->grid.h[d] = 0.125;
        c->grid.nodes[d] = 9;
    }
    c->method = sp->method;
    c->update = sp->update;
    c->transfer = sp->transfer;
    c->pic_fraction = sp->pic;
    c->volume_update = sp->volume;
    c->threads = sp->threads;
    if (sp->feat & F_FIXED_DT) c->dt = 1e-3;
    k->mat.model = sp->model;
    k->mat.youngs_modulus = 1e5;
    k->mat.poisson_ratio = 0.3;
    k->mat.density = 1000;
    k->mat.yield_stress = 1500;
    k->mat.hardening_modulus = 1e4;
    k->mat.friction_angle = 30;
    k->mat.dilatancy_angle = 5;
    k->mat.cohesion = 200;
    k->mat.tension_cutoff = HUGE_VAL;
    k->mat.mc_match = MPM_MC_COMPRESSION;
    c->n_materials = 1;
    c->materials = &k->mat;
    mpm_body_desc *b = &k->body;
    b->ppc = 2;
    b->shape = MPM_SHAPE_BOX;
    for (int d = 0; d < dim; d++) {
        b->lo[d] = d == up ? 0.0 : 0.25;
        b->hi[d] = d == up ? 0.5 : 0.75;
        b->velocity[d] = d == 0 ? 0.2 : d == 1 ? -0.1 : 0.05;
    }
    if (dim == 1) b->lo[0] = 0, b->hi[0] = 0.5;
    c->n_bodies = 1;
    c->bodies = b;
    if (sp->feat & (F_GRAV | F_GEO)) c->gravity[up] = -9.81;
    if (sp->feat & F_GEO) {
        b->geostatic = 1;
        b->free_surface = 0.5;
    }
    c->bc.face_mask[2 * up] = (sp->feat & (F_FRIC | F_PRES)) ? 1u << up : 7u;
    if (sp->feat & F_FRIC) {
        k->fric.face = 2 * up;
        k->fric.mu = 0.3;
        c->bc.n_friction = 1;
        c->bc.friction = &k->fric;
    }
    if (sp->feat & F_PRES) {
        k->tt[0] = 0, k->tt[1] = 0.02, k->tt[2] = 0.05;
        k->tv[0] = 0, k->tv[1] = 1, k->tv[2] = 0.5;
        k->table.kind = MPM_TF_TABLE;
        k->table.n = 3;
        k->table.t = k->tt;
        k->table.v = k->tv;
        k->pres.face = 2 * up;
        k->pres.mask = 1u; /* x, tangential to the bottom */
        k->pres.value[0] = 0.1;
        k->pres.time_function = &k->table;
        c->n_prescribed = 1;
        c->prescribed = &k->pres;
    }
    size_t nt = 0;
    if (sp->feat & F_TRAC_TF) {
        mpm_traction_desc *t = &k->trac[nt++];
        k->ramp.kind = MPM_TF_RAMP;
        k->ramp.value = 1;
        k->ramp.t0 = 0;
        k->ramp.t1 = 0.05;
        for (int d = 0; d < dim; d++) {
            t->lo[d] = b->lo[d];
            t->hi[d] = b->hi[d];
        }
        t->lo[up] = 0.44;
        t->hi[up] = 0.5;
        t->normal = up;
        t->value[up] = -2000;
        if (dim > 1) t->value[0] = 300;
        t->time_function = &k->ramp;
    }
    if (sp->feat & F_POINT) {
        mpm_traction_desc *t = &k->trac[nt++];
        for (int d = 0; d < dim; d++) {
            t->lo[d] = b->lo[d];
            t->hi[d] = b->lo[d] + 0.07;
        }
        t->normal = 0;
        t->is_force = 1;
        t->value[0] = 5;
        if (dim > 1) t->value[1] = -3;
    }
    c->n_tractions = nt;
    c->tractions = nt ? k->trac : NULL;
    if (sp->feat & (F_DAMP_L | F_DAMP_V)) {
        c->damping = sp->feat & F_DAMP_L ? MPM_DAMPING_LOCAL : MPM_DAMPING_VISCOUS;
        c->damping_coef = sp->feat & F_DAMP_L ? 0.2 : 5.0;
        c->damping_until = sp->feat & F_DAMP_L ? 0.04 : 0;
    }
    c->energy_budget = 0.5;
}

/* Particle forces (creation order): f_p = (a + 0.001 p, -a, a/2). */
static int ck_forces(mpm_sim *s, double a)
{
    size_t n = mpm_sim_particles(s);
    int dim = mpm_sim_dim(s);
    double *f = malloc(n * (size_t)dim * sizeof *f);
    if (!f) return MPM_ENOMEM;
    for (size_t p = 0; p < n; p++)
        for (int d = 0; d < dim; d++)
            f[p * (size_t)dim + (size_t)d] = d == 0 ? a + 0.001 * (double)p : d == 1 ? -a : a / 2;
    int rc = mpm_sim_set_particle_forces(s, f);
    free(f);
    return rc;
}

/* Runs s from its step to step `to`, with the case's particle forces
 * changed at step 10 and the energies asked of step 20 (mpm_sim_energy()
 * right after it: the in-pass sums and the balance's worst error). */
static int ck_run(mpm_sim *s, const ck_spec *sp, long to)
{
    while (mpm_sim_steps(s) < to) {
        long st = mpm_sim_steps(s);
        if ((sp->feat & F_PFORCES) && st == 10) {
            int rc = ck_forces(s, 0.5);
            if (rc) return rc;
        }
        if (st == 19) mpm_sim_want_energy(s);
        int rc = mpm_sim_step(s);
        if (rc) return rc;
        if (st == 19) {
            mpm_energy e;
            mpm_sim_energy(s, &e);
        }
    }
    return 0;
}

/* Everything a run's results are read from. */
typedef struct {
    size_t n;
    int dim;
    double *x, *v, *stress, *pressure, *volume, *epsp, *F;
    uint8_t *yld;
    double t, dt;
    long steps;
    mpm_energy_sample es;
    double bal_final, bal_worst;
    mpm_plastic_stats pl;
} ck_state;

static void ck_state_free(ck_state *r)
{
    free(r->x);
    free(r->v);
    free(r->stress);
    free(r->pressure);
    free(r->volume);
    free(r->epsp);
    free(r->F);
    free(r->yld);
    memset(r, 0, sizeof *r);
}

static int ck_state_get(const mpm_sim *s, ck_state *r)
{
    memset(r, 0, sizeof *r);
    size_t n = r->n = mpm_sim_particles(s);
    int dim = r->dim = mpm_sim_dim(s);
    r->x = calloc(n * (size_t)dim, sizeof(double));
    r->v = calloc(n * (size_t)dim, sizeof(double));
    r->stress = calloc(n * 6, sizeof(double));
    r->pressure = calloc(n, sizeof(double));
    r->volume = calloc(n, sizeof(double));
    r->epsp = calloc(n, sizeof(double));
    r->F = calloc(n * 9, sizeof(double));
    r->yld = calloc(n, 1);
    if (!r->x || !r->v || !r->stress || !r->pressure || !r->volume || !r->epsp || !r->F || !r->yld)
        return MPM_ENOMEM;
    mpm_snapshot o = {.x = r->x,
                      .v = r->v,
                      .stress = r->stress,
                      .volume = r->volume,
                      .mean_stress = r->pressure,
                      .plastic_strain = r->epsp,
                      .deformation_gradient = r->F,
                      .yielded = r->yld};
    mpm_sim_snapshot(s, &o);
    r->t = mpm_sim_time(s);
    r->dt = mpm_sim_dt(s);
    r->steps = mpm_sim_steps(s);
    mpm_sim_energy_sample(s, &r->es);
    (void)mpm_sim_budget(s, &r->bal_final, &r->bal_worst, NULL, 0);
    mpm_sim_plastic_stats(s, &r->pl);
    return 0;
}

/* The first field that differs between a and b ("" when none). */
static const char *ck_state_diff(const ck_state *a, const ck_state *b)
{
    size_t n = a->n, nd = n * (size_t)a->dim;
    if (a->n != b->n || a->dim != b->dim) return "count";
    if (memcmp(a->x, b->x, nd * sizeof(double))) return "x";
    if (memcmp(a->v, b->v, nd * sizeof(double))) return "v";
    if (memcmp(a->stress, b->stress, n * 6 * sizeof(double))) return "stress";
    if (memcmp(a->pressure, b->pressure, n * sizeof(double))) return "pressure";
    if (memcmp(a->volume, b->volume, n * sizeof(double))) return "volume";
    if (memcmp(a->epsp, b->epsp, n * sizeof(double))) return "plastic_strain";
    if (memcmp(a->F, b->F, n * 9 * sizeof(double))) return "deformation_gradient";
    if (memcmp(a->yld, b->yld, n)) return "yielded";
    if (memcmp(&a->t, &b->t, sizeof a->t)) return "t";
    if (memcmp(&a->dt, &b->dt, sizeof a->dt)) return "dt";
    if (a->steps != b->steps) return "steps";
    if (memcmp(&a->es, &b->es, sizeof a->es)) return "energy sample";
    if (memcmp(&a->bal_final, &b->bal_final, sizeof(double)) ||
        memcmp(&a->bal_worst, &b->bal_worst, sizeof(double)))
        return "budget";
    if (memcmp(&a->pl, &b->pl, sizeof a->pl)) return "plastic stats";
    return "";
}

/* Saves s into a new blob (*len its size); NULL when out of memory. */
static void *ck_save(const mpm_sim *s, size_t *len)
{
    *len = mpm_sim_checkpoint_size(s);
    void *blob = malloc(*len);
    if (blob && mpm_sim_checkpoint_save(s, blob, *len)) {
        free(blob);
        return NULL;
    }
    return blob;
}

/* The spec's run straight through and with a checkpoint at K into a fresh
 * simulation: 0 when both end with the same bits, else a message in msg. */
static int ck_roundtrip(const ck_spec *sp, char *msg, size_t nmsg, size_t *blob_bytes,
                        long *yielded)
{
    ck_case k;
    ck_build(&k, sp);
    mpm_error err;
    ck_state ref = {0}, got = {0};
    void *blob = NULL;
    int ok = 0;
    mpm_sim *a = mpm_sim_new(&k.c, NULL, &err), *b = NULL;
    if (!a) {
        char t[512];
        snprintf(msg, nmsg, "%s: mpm_sim_new: %s", sp->name,
                 mpm_error_text(&err, MPM_FIELD_PROTO, t, sizeof t));
        return -1;
    }
    /* the energies read at step K, as the checkpointed run reads them */
    int rc = (sp->feat & F_PFORCES) ? ck_forces(a, 0.2) : 0;
    if (!rc) rc = ck_run(a, sp, sp->K);
    if (!rc) {
        mpm_energy_sample es;
        mpm_sim_energy_sample(a, &es);
        rc = ck_run(a, sp, CK_N);
    }
    if (rc) {
        char t[512];
        snprintf(msg, nmsg, "%s: the straight run failed (%d): %s", sp->name, rc,
                 mpm_error_text(mpm_sim_error(a), MPM_FIELD_PROTO, t, sizeof t));
        goto out;
    }
    if (ck_state_get(a, &ref)) goto nomem;
    *yielded = 0;
    for (size_t p = 0; p < ref.n; p++) *yielded += ref.epsp[p] > 0;
    mpm_sim_destroy(&a);

    /* K steps, save, a fresh simulation, load, the rest */
    if (!(a = mpm_sim_new(&k.c, NULL, &err))) goto nomem;
    rc = (sp->feat & F_PFORCES) ? ck_forces(a, 0.2) : 0;
    if (!rc) rc = ck_run(a, sp, sp->K);
    size_t len = 0;
    ck_state before = {0}, after = {0};
    if (!rc && ck_state_get(a, &before)) {
        ck_state_free(&before);
        goto nomem;
    }
    if (rc || !(blob = ck_save(a, &len))) {
        snprintf(msg, nmsg, "%s: the first part or the save failed (%d)", sp->name, rc);
        ck_state_free(&before);
        goto out;
    }
    *blob_bytes = len;
    mpm_sim_destroy(&a);
    if (!(b = mpm_sim_new(&k.c, NULL, &err))) {
        ck_state_free(&before);
        goto nomem;
    }
    if ((rc = mpm_sim_checkpoint_load(b, blob, len, &err))) {
        char t[512];
        snprintf(msg, nmsg, "%s: load: %s", sp->name,
                 mpm_error_text(&err, MPM_FIELD_PROTO, t, sizeof t));
        ck_state_free(&before);
        goto out;
    }
    /* the loaded state reads back as the saved one */
    rc = ck_state_get(b, &after);
    const char *d0 = rc ? "memory" : ck_state_diff(&before, &after);
    ck_state_free(&before);
    ck_state_free(&after);
    if (*d0) {
        snprintf(msg, nmsg, "%s: right after the load, %s differs", sp->name, d0);
        goto out;
    }
    if ((rc = ck_run(b, sp, CK_N))) {
        snprintf(msg, nmsg, "%s: the resumed run failed (%d)", sp->name, rc);
        goto out;
    }
    if (ck_state_get(b, &got)) goto nomem;
    const char *d = ck_state_diff(&ref, &got);
    if (*d) {
        snprintf(msg, nmsg, "%s: after %d + %d steps, %s differs from the straight run", sp->name,
                 sp->K, CK_N - sp->K, d);
        goto out;
    }
    ok = 1;
    goto out;
nomem:
    snprintf(msg, nmsg, "%s: out of memory", sp->name);
out:
    mpm_sim_destroy(&a);
    mpm_sim_destroy(&b);
    ck_state_free(&ref);
    ck_state_free(&got);
    free(blob);
    return ok ? 0 : -1;
}

#define LE MPM_MODEL_LINEAR_ELASTIC
#define NH MPM_MODEL_NEO_HOOKEAN
#define J2 MPM_MODEL_VON_MISES
#define DP MPM_MODEL_DRUCKER_PRAGER
#define MC MPM_MODEL_MOHR_COULOMB
#define SI MPM_VOLUME_STRAIN_INCREMENT
#define DF MPM_VOLUME_DET_F
#define CV MPM_VOLUME_CONSTANT
#define FL MPM_TRANSFER_FLIP
#define AP MPM_TRANSFER_APIC

static int ck_matrix(const ck_spec *specs, size_t n)
{
    int fails = 0;
    for (size_t i = 0; i < n; i++) {
        char msg[768] = "";
        size_t bytes = 0;
        long yielded = 0;
        if (ck_roundtrip(&specs[i], msg, sizeof msg, &bytes, &yielded)) {
            t_fail(__FILE__, __LINE__, "%s", msg);
            fails++;
        } else {
            TLOG("%-38s same bits after %d + %d steps (blob %zu bytes, %ld particles "
                 "yielded)",
                 specs[i].name, specs[i].K, CK_N - specs[i].K, bytes, yielded);
        }
    }
    return fails;
}

static const ck_spec ck_1d[] = {
    {"1D MPM USF elastic gravity", 1, MPM_METHOD_MPM, MPM_USF, FL, 0, LE, SI, F_GRAV, 1, 21},
    {"1D GIMP MUSL neo-Hookean traction(t)", 1, MPM_METHOD_GIMP, MPM_MUSL, FL, 0, NH, SI,
     F_TRAC_TF | F_FIXED_DT, 2, 21},
    {"1D BSPLINE2 USL J2 PIC-blend", 1, MPM_METHOD_BSPLINE2, MPM_USL, FL, 0.3, J2, SI, F_GRAV, 1,
     32},
    {"1D BSPLINE3 USF elastic point load", 1, MPM_METHOD_BSPLINE3, MPM_USF, FL, 0, LE, CV,
     F_POINT | F_GRAV, 2, 17},
    {"1D CPDI USF elastic viscous damping", 1, MPM_METHOD_CPDI, MPM_USF, FL, 0, LE, DF,
     F_DAMP_V | F_GRAV, 2, 21},
};

static const ck_spec ck_2d[] = {
    {"2D GIMP USF elastic gravity K=32", 2, MPM_METHOD_GIMP, MPM_USF, FL, 0, LE, SI, F_GRAV, 1, 32},
    {"2D MPM MUSL APIC forces+point", 2, MPM_METHOD_MPM, MPM_MUSL, AP, 0, LE, SI,
     F_POINT | F_PFORCES, 2, 21},
    {"2D BSPLINE2 USL DP geostatic", 2, MPM_METHOD_BSPLINE2, MPM_USL, FL, 0, DP, SI, F_GEO, 2, 21},
    {"2D BSPLINE3 MUSL MC friction", 2, MPM_METHOD_BSPLINE3, MPM_MUSL, FL, 0, MC, SI,
     F_GRAV | F_FRIC, 1, 21},
    {"2D CPDI USF neo-Hookean DET_F", 2, MPM_METHOD_CPDI, MPM_USF, FL, 0, NH, DF,
     F_POINT | F_FIXED_DT, 2, 21},
    {"2D GIMP USL J2 prescribed(t) CONSTANT", 2, MPM_METHOD_GIMP, MPM_USL, FL, 0, J2, CV,
     F_GRAV | F_PRES, 1, 21},
    {"2D GIMP USF APIC DP local damping", 2, MPM_METHOD_GIMP, MPM_USF, AP, 0, DP, SI,
     F_GEO | F_DAMP_L, 2, 21},
    {"2D MPM MUSL MC prescribed traction(t)", 2, MPM_METHOD_MPM, MPM_MUSL, FL, 0.2, MC, DF,
     F_GRAV | F_PRES | F_TRAC_TF | F_FIXED_DT, 2, 32},
};

static const ck_spec ck_3d[] = {
    {"3D GIMP MUSL elastic traction(t)", 3, MPM_METHOD_GIMP, MPM_MUSL, FL, 0, LE, SI,
     F_GRAV | F_TRAC_TF, 2, 21},
    {"3D CPDI USL MC friction", 3, MPM_METHOD_CPDI, MPM_USL, FL, 0, MC, SI, F_GRAV | F_FRIC, 2, 21},
    {"3D MPM USF J2 PIC-blend forces", 3, MPM_METHOD_MPM, MPM_USF, FL, 0.5, J2, SI,
     F_GRAV | F_PFORCES, 1, 21},
    {"3D BSPLINE2 MUSL DP viscous damping", 3, MPM_METHOD_BSPLINE2, MPM_MUSL, FL, 0, DP, SI,
     F_GEO | F_DAMP_V, 2, 32},
};

#define NSPEC(a) (sizeof(a) / sizeof *(a))

TEST(ckpt_same_bits_1d)
{
    CHECK(ck_matrix(ck_1d, NSPEC(ck_1d)) == 0);
}

TEST(ckpt_same_bits_2d)
{
    CHECK(ck_matrix(ck_2d, NSPEC(ck_2d)) == 0);
}

TEST(ckpt_same_bits_3d)
{
    CHECK(ck_matrix(ck_3d, NSPEC(ck_3d)) == 0);
}

/* ---- refusals ---- */

static const ck_spec ck_small = {
    "2D GIMP USF elastic", 2, MPM_METHOD_GIMP, MPM_USF, FL, 0, LE, SI, F_GRAV | F_POINT, 1, 21};

/* A flipped byte anywhere in the payload is a checksum mismatch
 * (MPM_ESYNTAX), one in the header is refused too (some code); a truncated
 * or padded blob is MPM_ESYNTAX, another format version MPM_EVERSION, a
 * buffer too small for the save MPM_ETOOBIG; and the refused loads leave
 * the simulation as it was (its state reads back the same, and it then
 * runs to the same bits as one never offered them). */
TEST(ckpt_refuses_corrupt)
{
    ck_case k;
    ck_build(&k, &ck_small);
    mpm_error err;
    mpm_sim *a = mpm_sim_new(&k.c, NULL, &err), *b = NULL, *r = NULL;
    CHECK(a);
    CHECK(ck_run(a, &ck_small, ck_small.K) == 0);
    size_t len = 0;
    unsigned char *blob = ck_save(a, &len), *bad = malloc(len + 8);
    ck_state s0 = {0}, s1 = {0}, ref = {0};
    CHECK(blob && bad);
    CHECK(mpm_sim_checkpoint_save(a, bad, len - 1) == MPM_ETOOBIG);
    CHECK(mpm_sim_checkpoint_save(a, NULL, len) == MPM_ETOOBIG);
    b = mpm_sim_new(&k.c, NULL, &err);
    CHECK(b);
    CHECK(ck_run(b, &ck_small, 3) == 0); /* not fresh: it has a state to keep */
    CHECK(ck_state_get(b, &s0) == 0);
    /* the header's first 32 bytes (magic, version, header size, byte
     * order, payload size) are refused by their own checks; every later
     * byte, header or payload, by the checksum */
    size_t nsyntax = 0;
    for (size_t i = 0; i < len; i++) {
        memcpy(bad, blob, len);
        bad[i] ^= (unsigned char)(1u << (i % 8));
        int rc = mpm_sim_checkpoint_load(b, bad, len, &err);
        CHECKF(rc != 0, "byte %zu flipped: loaded", i);
        if (i < 32) continue;
        CHECKF(rc == MPM_ESYNTAX && strstr(err.message, "checksum"),
               "byte %zu flipped: code %d, %s", i, rc, err.message);
        nsyntax++;
    }
    TLOG("%zu-byte blob: every flipped byte refused, %zu of them by the checksum", len, nsyntax);
    /* truncated, padded, empty */
    size_t cuts[] = {0, 7, 64, len / 2, len - 8, len - 1};
    for (size_t i = 0; i < sizeof cuts / sizeof *cuts; i++) {
        CHECKF(mpm_sim_checkpoint_load(b, blob, cuts[i], &err) == MPM_ESYNTAX, "cut at %zu",
               cuts[i]);
    }
    memcpy(bad, blob, len);
    memset(bad + len, 0, 8);
    CHECK(mpm_sim_checkpoint_load(b, bad, len + 8, &err) == MPM_ESYNTAX);
    CHECK(mpm_sim_checkpoint_load(b, NULL, len, &err) == MPM_ESYNTAX);
    /* another format version (the field after the 8-byte magic) */
    memcpy(bad, blob, len);
    uint32_t ver;
    memcpy(&ver, bad + 8, sizeof ver);
    ver++;
    memcpy(bad + 8, &ver, sizeof ver);
    CHECK(mpm_sim_checkpoint_load(b, bad, len, &err) == MPM_EVERSION);
    TLOG("another version: %s", err.message);
    /* a flipped bit in each of the header's 32 checked bytes, named */
    memcpy(bad, blob, len);
    bad[0] ^= 1;
    CHECK(mpm_sim_checkpoint_load(b, bad, len, &err) == MPM_ESYNTAX);
    CHECK(strstr(err.message, "not a checkpoint"));
    /* b as it was */
    CHECK(ck_state_get(b, &s1) == 0);
    CHECKF(!*ck_state_diff(&s0, &s1), "a refused load changed %s", ck_state_diff(&s0, &s1));
    CHECK(ck_run(b, &ck_small, CK_N) == 0);
    ck_state_free(&s1);
    CHECK(ck_state_get(b, &s1) == 0);
    r = mpm_sim_new(&k.c, NULL, &err);
    CHECK(r);
    CHECK(ck_run(r, &ck_small, 3) == 0);
    {
        ck_state e;
        CHECK(ck_state_get(r, &e) == 0); /* the same reads as b had */
        ck_state_free(&e);
    }
    CHECK(ck_run(r, &ck_small, CK_N) == 0);
    CHECK(ck_state_get(r, &ref) == 0);
    CHECKF(!*ck_state_diff(&ref, &s1), "after refused loads, %s differs", ck_state_diff(&ref, &s1));
    /* and the good blob still loads into it, although it has run on to
     * step N: it then goes on as the saved run does */
    CHECK(mpm_sim_checkpoint_load(b, blob, len, &err) == 0);
    CHECK(mpm_sim_steps(b) == ck_small.K);
    CHECK(ck_run(b, &ck_small, CK_N) == 0);
    CHECK(ck_run(a, &ck_small, CK_N) == 0);
    ck_state_free(&s0);
    ck_state_free(&s1);
    CHECK(ck_state_get(a, &s0) == 0);
    CHECK(ck_state_get(b, &s1) == 0);
    CHECKF(!*ck_state_diff(&s0, &s1), "loaded into a used simulation: %s differs",
           ck_state_diff(&s0, &s1));
    ck_state_free(&s0);
    ck_state_free(&s1);
    ck_state_free(&ref);
    mpm_sim_destroy(&a);
    mpm_sim_destroy(&b);
    mpm_sim_destroy(&r);
    free(blob);
    free(bad);
}

/* A blob of another case: another particle count, method, update,
 * dimension or model is refused (MPM_EINVAL) naming what differs; the same
 * layout with another Young's modulus by the fingerprint. */
TEST(ckpt_refuses_other_case)
{
    ck_case k;
    ck_build(&k, &ck_small);
    mpm_error err;
    mpm_sim *a = mpm_sim_new(&k.c, NULL, &err);
    CHECK(a);
    CHECK(ck_run(a, &ck_small, 5) == 0);
    size_t len = 0;
    void *blob = ck_save(a, &len);
    mpm_sim_destroy(&a);
    CHECK(blob);
    struct {
        const char *what, *expect;
        int variant;
    } v[] = {{"ppc 3", "particles", 0},
             {"method MPM", "method", 1},
             {"update MUSL", "update", 2},
             {"model J2", "per-particle arrays", 3},
             {"3D", "dim", 4},
             {"E 2e5", "another case of the same layout", 5},
             {"no gravity", "gravity", 6},
             {"fixed dt", "same layout", 7},
             {"APIC", "transfer", 8},
             {"no point load", "point forces", 9}};
    for (size_t i = 0; i < sizeof v / sizeof *v; i++) {
        ck_spec sp = ck_small;
        switch (v[i].variant) {
        case 1: sp.method = MPM_METHOD_MPM; break;
        case 2: sp.update = MPM_MUSL; break;
        case 3: sp.model = J2; break;
        case 4: sp.dim = 3; break;
        case 6: sp.feat &= ~(unsigned)F_GRAV; break;
        case 7: sp.feat |= F_FIXED_DT; break;
        case 8: sp.transfer = AP; break;
        case 9: sp.feat &= ~(unsigned)F_POINT; break;
        default: break;
        }
        ck_case o;
        ck_build(&o, &sp);
        if (v[i].variant == 0) o.body.ppc = 3;
        if (v[i].variant == 5) o.mat.youngs_modulus = 2e5;
        mpm_sim *b = mpm_sim_new(&o.c, NULL, &err);
        CHECKF(b, "%s: %s", v[i].what, err.message);
        int rc = mpm_sim_checkpoint_load(b, blob, len, &err);
        int steps = (int)mpm_sim_steps(b);
        mpm_sim_destroy(&b);
        CHECKF(rc == MPM_EINVAL, "%s: code %d", v[i].what, rc);
        CHECKF(strstr(err.message, v[i].expect), "%s: %s", v[i].what, err.message);
        CHECK(steps == 0);
        TLOG("%-14s refused: %s", v[i].what, err.message);
    }
    free(blob);
}

/* Another value of a parameter p of material d within its bounds (the
 * material table's check passes), written into d; 0 when none is found. */
static int ck_other_value(mpm_material_desc *d, const mpm_material_param *p)
{
    double v = mpm_material_get(d, p);
    double cand[] = {v * 1.25, v * 0.8, v + 0.1, v - 0.1, v + 1, 0.25, 1, 0};
    mpm_error err;
    for (size_t i = 0; i < sizeof cand / sizeof *cand; i++) {
        if (cand[i] == v || (p->type == MPM_PARAM_ENUM && cand[i] != floor(cand[i]))) continue;
        mpm_material_set(d, p, cand[i]);
        if (mpm_material_check(d, 2, 0, &err) == 0) return 1;
    }
    mpm_material_set(d, p, v);
    return 0;
}

/* Every parameter a model's row of the material table reads is in the
 * checkpoint's fingerprint: for each model, the blob of a 2D case loads
 * into the same case and is refused, as another case of the same layout,
 * by the case with one of the model's parameters changed to another
 * valid value; Mohr-Coulomb with Drucker-Prager's parameters (the same
 * layout) is refused too. */
TEST(ckpt_fingerprint_every_material_param)
{
    int nparam = 0, nmodel = 0;
    void *dp_blob = NULL;
    size_t dp_len = 0;
    for (int mk = 0; mpm_material_model_of((mpm_model_kind)mk); mk++) {
        const mpm_material_model *row = mpm_material_model_of((mpm_model_kind)mk);
        ck_spec sp = ck_small;
        sp.model = (mpm_model_kind)mk;
        ck_case k;
        ck_build(&k, &sp);
        mpm_error err;
        mpm_sim *a = mpm_sim_new(&k.c, NULL, &err);
        CHECKF(a, "%s: %s", row->name, err.message);
        if (!a) continue;
        CHECK(ck_run(a, &sp, 3) == 0);
        size_t len = 0;
        void *blob = ck_save(a, &len);
        mpm_sim_destroy(&a);
        CHECK(blob);
        if (!blob) continue;
        mpm_sim *b = mpm_sim_new(&k.c, NULL, &err);
        CHECK(b && mpm_sim_checkpoint_load(b, blob, len, &err) == 0);
        mpm_sim_destroy(&b);
        for (int j = 0; j < mpm_material_n_params(); j++) {
            if (!(row->params >> j & 1u)) continue;
            const mpm_material_param *p = mpm_material_param_at(j);
            ck_case o;
            ck_build(&o, &sp);
            CHECKF(ck_other_value(&o.mat, p), "%s.%s: no other valid value", row->name, p->name);
            b = mpm_sim_new(&o.c, NULL, &err);
            CHECKF(b, "%s.%s: %s", row->name, p->name, err.message);
            int rc = b ? mpm_sim_checkpoint_load(b, blob, len, &err) : 0;
            mpm_sim_destroy(&b);
            CHECKF(rc == MPM_EINVAL && strstr(err.message, "another case of the same layout"),
                   "%s.%s = %g: code %d %s", row->name, p->name, mpm_material_get(&o.mat, p), rc,
                   rc ? err.message : "loaded");
            nparam++;
        }
        nmodel++;
        if (mk == MPM_MODEL_DRUCKER_PRAGER) {
            dp_blob = blob;
            dp_len = len;
        } else {
            free(blob);
        }
    }
    ck_spec mc = ck_small;
    mc.model = MPM_MODEL_MOHR_COULOMB;
    ck_case o;
    ck_build(&o, &mc);
    mpm_error err;
    mpm_sim *b = mpm_sim_new(&o.c, NULL, &err);
    int rc = b && dp_blob ? mpm_sim_checkpoint_load(b, dp_blob, dp_len, &err) : 0;
    mpm_sim_destroy(&b);
    free(dp_blob);
    CHECKF(rc == MPM_EINVAL && strstr(err.message, "another case of the same layout"),
           "a DRUCKER_PRAGER blob into MOHR_COULOMB: code %d", rc);
    CHECK(nmodel == 5);
    TLOG("%d parameters of %d models: each one's change refused by the fingerprint", nparam,
         nmodel);
}

/* Saved with 2 threads, loaded into a 1-thread simulation of the same case:
 * the run goes on, within round-off (1e-12 of each field's scale) of the
 * 2-thread run, in an elastic case and a J2 one. */
TEST(ckpt_threads_2_to_1)
{
    static const ck_spec specs[] = {
        {"2D GIMP MUSL elastic", 2, MPM_METHOD_GIMP, MPM_MUSL, FL, 0, LE, SI, F_GRAV | F_POINT, 2,
         21},
        {"3D MPM USF APIC elastic", 3, MPM_METHOD_MPM, MPM_USF, AP, 0, LE, SI, F_GRAV, 2, 21}};
    for (size_t i = 0; i < sizeof specs / sizeof *specs; i++) {
        const ck_spec *sp = &specs[i];
        ck_case k;
        ck_build(&k, sp);
        mpm_error err;
        mpm_sim *a = mpm_sim_new(&k.c, NULL, &err), *b = NULL;
        CHECK(a);
        CHECK(ck_run(a, sp, sp->K) == 0);
        size_t len = 0;
        void *blob = ck_save(a, &len);
        CHECK(blob);
        CHECK(ck_run(a, sp, CK_N) == 0);
        ck_state r2, r1;
        CHECK(ck_state_get(a, &r2) == 0);
        mpm_sim_destroy(&a);
        k.c.threads = 1;
        b = mpm_sim_new(&k.c, NULL, &err);
        CHECK(b);
        CHECK(mpm_sim_checkpoint_load(b, blob, len, &err) == 0);
        free(blob);
        CHECK(ck_run(b, sp, CK_N) == 0);
        CHECK(ck_state_get(b, &r1) == 0);
        mpm_sim_destroy(&b);
        size_t nd = r1.n * (size_t)r1.dim;
        const double *fa[] = {r2.x, r2.v, r2.stress}, *fb[] = {r1.x, r1.v, r1.stress};
        size_t cnt[] = {nd, nd, r1.n * 6};
        double worst = 0;
        int bitdiff = 0;
        for (int f = 0; f < 3; f++) {
            double scale = 0, diff = 0;
            for (size_t j = 0; j < cnt[f]; j++) {
                scale = fmax(scale, fabs(fa[f][j]));
                diff = fmax(diff, fabs(fa[f][j] - fb[f][j]));
                bitdiff |= fa[f][j] != fb[f][j];
            }
            CHECKF(diff <= 1e-12 * scale, "%s field %d: |diff| %.3g, scale %.3g", sp->name, f, diff,
                   scale);
            worst = fmax(worst, scale > 0 ? diff / scale : 0);
        }
        CHECK(r1.steps == r2.steps);
        CHECK(fabs(r1.t - r2.t) <= 1e-12 * r2.t);
        TLOG("%s: 2-thread blob continued on 1 thread: largest difference %.2g of the field's "
             "scale (%s)",
             sp->name, worst, bitdiff ? "not bitwise: the sums' order differs" : "bitwise equal");
        ck_state_free(&r1);
        ck_state_free(&r2);
    }
}

/* A run that failed (a particle left the grid) saves its failure: loaded
 * into a fresh simulation, it is failed too (every step MPM_ESTATE) with
 * the same error. */
TEST(ckpt_failed_run_stays_failed)
{
    static const ck_spec sp = {"1D MPM thrown", 1, MPM_METHOD_MPM, MPM_USF, FL, 0, LE, SI, 0, 1, 0};
    ck_case k;
    ck_build(&k, &sp);
    k.body.velocity[0] = 50; /* out of the 1 m grid in ~0.01 s */
    k.c.bc.face_mask[0] = 0;
    mpm_error err;
    mpm_sim *a = mpm_sim_new(&k.c, NULL, &err), *b = NULL;
    CHECK(a);
    int rc = mpm_sim_run(a, 1000);
    CHECK(rc == MPM_ELEFTGRID);
    size_t len = 0;
    void *blob = ck_save(a, &len);
    CHECK(blob);
    b = mpm_sim_new(&k.c, NULL, &err);
    CHECK(b);
    CHECK(mpm_sim_checkpoint_load(b, blob, len, &err) == 0);
    free(blob);
    CHECK(mpm_sim_step(b) == MPM_ESTATE);
    CHECK(mpm_sim_steps(b) == mpm_sim_steps(a));
    CHECK(mpm_sim_error(b)->code == MPM_ELEFTGRID);
    CHECK(!strcmp(mpm_sim_error(b)->message, mpm_sim_error(a)->message));
    TLOG("loaded failed run: %s", mpm_sim_error(b)->message);
    mpm_sim_destroy(&a);
    mpm_sim_destroy(&b);
}

/* ---- fused steps ----
 *
 * A step's moving pass also scatters the next step's first grid fields
 * (G2P2G), before a step that sorts the particles too (the sort comes
 * after that scatter has been reduced).  The same spec run straight to
 * CK_N with fusion off (plan fuse=off: every step scatters on
 * its own, as every release before) and on must end with the same bits:
 * the fused scatter does the same arithmetic in the same order into the
 * same per-thread sums.  The fused run must have fused: after steps 16
 * and 17 the next scatter is made (step 16's next step sorts); CPDI has
 * no fused passes and refuses to fuse.  *moved counts the runs whose
 * sorts moved particles (mpm_sim.sort_moved) after creation, so that the
 * caller can check that sorts that reorder were compared. */
static int fu_compare(const ck_spec *sp, char *msg, size_t nmsg, int *moved)
{
    ck_case k;
    ck_build(&k, sp);
    mpm_error err;
    ck_state st[2];
    memset(st, 0, sizeof st);
    int ok = 0, cpdi = sp->method == MPM_METHOD_CPDI;
    for (int fused = 0; fused < 2; fused++) {
        mpm_sim *s = mpm_sim_new(&k.c, NULL, &err);
        if (!s) {
            snprintf(msg, nmsg, "%s: mpm_sim_new failed", sp->name);
            goto out;
        }
        /* always: even where it would not pay */
        int rc = mpm_sim_plan_override(s, fused ? "fuse=always" : "fuse=off", NULL);
        if (fused && cpdi ? rc != MPM_EINVAL : rc != 0) {
            snprintf(msg, nmsg, "%s: plan fuse %d returned %d", sp->name, fused, rc);
            mpm_sim_destroy(&s);
            goto out;
        }
        rc = (sp->feat & F_PFORCES) ? ck_forces(s, 0.2) : 0;
        long m0 = s->sort_moved; /* creation's sort */
        if (!rc) rc = ck_run(s, sp, 16);
        int g16 = s->gnext;
        if (!rc) rc = ck_run(s, sp, 17);
        int g17 = s->gnext;
        if (!rc) rc = ck_run(s, sp, CK_N);
        if (rc || ck_state_get(s, &st[fused])) {
            snprintf(msg, nmsg, "%s: the %s run failed (%d)", sp->name, fused ? "fused" : "unfused",
                     rc);
            mpm_sim_destroy(&s);
            goto out;
        }
        if (fused) *moved += s->sort_moved > m0;
        mpm_sim_destroy(&s);
        int want = fused && !cpdi;
        if (g16 != want || g17 != want) {
            snprintf(msg, nmsg,
                     "%s: %s run: next scatter made after step 16: %d, 17: %d (want %d, %d)",
                     sp->name, fused ? "fused" : "unfused", g16, g17, want, want);
            goto out;
        }
    }
    const char *d = ck_state_diff(&st[0], &st[1]);
    if (*d) {
        snprintf(msg, nmsg, "%s: after %d steps, %s differs between fused and unfused steps",
                 sp->name, CK_N, d);
        goto out;
    }
    ok = 1;
out:
    ck_state_free(&st[0]);
    ck_state_free(&st[1]);
    return ok ? 0 : -1;
}

/* the transfers and updates the checkpoint matrix lacks */
static const ck_spec fu_more[] = {
    {"1D MPM USL elastic gravity", 1, MPM_METHOD_MPM, MPM_USL, FL, 0, LE, SI, F_GRAV, 2, 0},
    {"2D MPM USF elastic 3 threads", 2, MPM_METHOD_MPM, MPM_USF, FL, 0, LE, SI, F_GRAV, 3, 0},
    {"2D BSPLINE2 MUSL APIC gravity", 2, MPM_METHOD_BSPLINE2, MPM_MUSL, AP, 0, LE, SI, F_GRAV, 2,
     0},
    {"2D BSPLINE2 USL APIC point load", 2, MPM_METHOD_BSPLINE2, MPM_USL, AP, 0, LE, SI, F_POINT, 1,
     0},
    {"3D BSPLINE3 USL APIC elastic", 3, MPM_METHOD_BSPLINE3, MPM_USL, AP, 0, LE, SI, F_GRAV, 2, 0},
    {"3D GIMP MUSL PIC-blend", 3, MPM_METHOD_GIMP, MPM_MUSL, FL, 0.3, LE, SI, F_GRAV, 2, 0},
};

TEST(fuse_same_bits)
{
    const ck_spec *lists[] = {ck_1d, ck_2d, ck_3d, fu_more};
    size_t counts[] = {NSPEC(ck_1d), NSPEC(ck_2d), NSPEC(ck_3d), NSPEC(fu_more)};
    int n = 0, moved = 0;
    for (int l = 0; l < 4; l++)
        for (size_t i = 0; i < counts[l]; i++) {
            char msg[768] = "";
            int mv = 0;
            if (fu_compare(&lists[l][i], msg, sizeof msg, &mv)) {
                t_fail(__FILE__, __LINE__, "%s", msg);
                continue;
            }
            n++;
            moved += mv;
            TLOG("%-38s fused = unfused, bit for bit, after %d steps%s", lists[l][i].name, CK_N,
                 mv ? " (a sort moved particles)" : "");
        }
    CHECK(n == (int)(counts[0] + counts[1] + counts[2] + counts[3]));
    TLOG("%d of %d runs sorted with moves after creation", moved, n);
    CHECK(moved >= 3);
}
