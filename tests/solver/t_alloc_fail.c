/*
 * t_alloc_fail.c - the solver's out-of-memory paths (test alloc_fail_solver).
 * For each of a few cases that between them reach every allocation of
 * mpm_sim_new() (1D, 2D, 3D; MPM, GIMP, CPDI, BSPLINE2; USF, USL, MUSL;
 * APIC; elastic, von Mises, Drucker-Prager, neo-Hookean with DET_F volumes;
 * two bodies of two materials; gravity, fixed faces, a fixed node set,
 * friction, prescribed velocities on a face and on a node set, tractions
 * and a point force with time functions, damping; 1 and 2 threads), the
 * test counts the allocations of creating the simulation, stepping it and
 * switching it to per-particle forces, then runs the same again once per
 * allocation with that one failing (tests/t_alloc.h).  Each time the
 * failing call must report MPM_ENOMEM (mpm_sim_new() NULL with err,
 * mpm_sim_set_particle_forces() a code and the simulation still stepping),
 * and every block allocated must be freed by mpm_sim_destroy() or the
 * failing call itself; ASan's leak checker then looks for anything else.
 */
#include "mpm.h"
#include "t.h"
#include "t_alloc.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/lsan_interface.h>
#endif

#define AF_STEPS 3

/* A case and the storage behind it. */
typedef struct {
    mpm_case c;
    mpm_material_desc mat[2];
    mpm_body_desc body[2];
    mpm_traction_desc trac[2];
    mpm_timefn ramp, table;
    double tt[3], tv[3];
    mpm_prescribed_desc pres[2];
    mpm_friction_desc fric;
    int fix_ijk[3], pres_ijk[3];
    unsigned fix_mask;
    int forces; /* mpm_sim_set_particle_forces() after the first steps */
} af_case;

enum { AF_1D, AF_2D_MPM, AF_2D_CPDI, AF_2D_BSPLINE, AF_3D_GIMP, AF_NCASES };
static const char *const af_name[AF_NCASES] = {"1D MPM USF", "2D MPM USF, 2 threads",
                                               "2D CPDI USL, two materials",
                                               "2D BSPLINE2 MUSL, 2 threads", "3D GIMP MUSL APIC"};

static void af_material(mpm_material_desc *m, mpm_model_kind kind)
{
    m->model = kind;
    m->youngs_modulus = 1e5;
    m->poisson_ratio = 0.3;
    m->density = 1000;
    m->yield_stress = 1500;
    m->hardening_modulus = 1e4;
    m->friction_angle = 30;
    m->dilatancy_angle = 5;
    m->cohesion = 200;
    m->tension_cutoff = HUGE_VAL;
    m->mc_match = MPM_MC_COMPRESSION;
}

/* A block in the middle of a box of 8 cells of 0.125 per axis, resting on
 * the bottom (y_lo; 1D: x_lo), with the features of case k. */
static void af_build(af_case *a, int k)
{
    memset(a, 0, sizeof *a);
    mpm_case *c = &a->c;
    int dim = k == AF_1D ? 1 : k == AF_3D_GIMP ? 3 : 2, up = dim == 1 ? 0 : 1;
    c->grid.dim = dim;
    for (int d = 0; d < dim; d++) {
        c->grid.h[d] = 0.125;
        c->grid.nodes[d] = 9;
    }
    c->method = k == AF_3D_GIMP      ? MPM_METHOD_GIMP
                : k == AF_2D_CPDI    ? MPM_METHOD_CPDI
                : k == AF_2D_BSPLINE ? MPM_METHOD_BSPLINE2
                                     : MPM_METHOD_MPM;
    c->update = k == AF_2D_CPDI                           ? MPM_USL
                : (k == AF_2D_BSPLINE || k == AF_3D_GIMP) ? MPM_MUSL
                                                          : MPM_USF;
    c->transfer = k == AF_3D_GIMP ? MPM_TRANSFER_APIC : MPM_TRANSFER_FLIP;
    c->threads = (k == AF_2D_MPM || k == AF_2D_BSPLINE) ? 2 : 1;
    c->dt = 1e-4;
    af_material(&a->mat[0], k == AF_3D_GIMP      ? MPM_MODEL_DRUCKER_PRAGER
                            : k == AF_2D_CPDI    ? MPM_MODEL_VON_MISES
                            : k == AF_2D_BSPLINE ? MPM_MODEL_NEO_HOOKEAN
                                                 : MPM_MODEL_LINEAR_ELASTIC);
    af_material(&a->mat[1], MPM_MODEL_LINEAR_ELASTIC);
    if (k == AF_2D_BSPLINE) c->volume_update = MPM_VOLUME_DET_F;
    c->materials = a->mat;
    c->n_materials = k == AF_2D_CPDI ? 2 : 1;
    c->bodies = a->body;
    c->n_bodies = k == AF_2D_CPDI ? 2 : 1;
    for (size_t b = 0; b < c->n_bodies; b++) {
        mpm_body_desc *y = &a->body[b];
        y->material = (int)b;
        y->ppc = 2;
        y->shape = MPM_SHAPE_BOX;
        for (int d = 0; d < dim; d++) {
            y->lo[d] = d == up ? 0.0 : 0.25 + 0.25 * (double)b;
            y->hi[d] = d == up ? 0.5 : 0.5 + 0.25 * (double)b;
            y->velocity[d] = d == 0 ? 0.2 : -0.1;
        }
    }
    c->gravity[up] = -9.81;
    if (dim == 1) {
        c->bc.face_mask[0] = 1;
        a->forces = 1;
        return;
    }
    /* the bottom a roller driven along x by a ramp, friction on the top, a
     * fixed node near the top left */
    c->bc.face_mask[2 * up] = 1u << up;
    a->fric.face = 2 * up + 1;
    a->fric.mu = 0.3;
    c->bc.n_friction = 1;
    c->bc.friction = &a->fric;
    if (c->method != MPM_METHOD_BSPLINE2) {
        a->fix_ijk[0] = 1;
        a->fix_ijk[1] = 7;
        a->fix_mask = 3u;
        c->bc.n_nodes = 1;
        c->bc.node_ijk = a->fix_ijk;
        c->bc.node_mask = &a->fix_mask;
    }
    a->ramp = (mpm_timefn){MPM_TF_RAMP, 1.0, 0.0, 0.01, 0, NULL, NULL};
    a->tt[0] = 0, a->tt[1] = 0.002, a->tt[2] = 0.005;
    a->tv[0] = 0, a->tv[1] = 1, a->tv[2] = 0.5;
    a->table = (mpm_timefn){MPM_TF_TABLE, 0.0, 0, 0, 3, a->tt, a->tv};
    a->pres[0].face = 2 * up;
    a->pres[0].mask = 1u;
    a->pres[0].value[0] = 0.05;
    a->pres[0].time_function = &a->ramp;
    c->prescribed = a->pres;
    c->n_prescribed = 1;
    /* one node of x_hi driven along x by a table */
    if (c->method == MPM_METHOD_MPM || c->method == MPM_METHOD_CPDI) {
        a->pres_ijk[0] = 8;
        a->pres_ijk[1] = 4;
        a->pres[1].face = -1;
        a->pres[1].n_nodes = 1;
        a->pres[1].node_ijk = a->pres_ijk;
        a->pres[1].mask = 1u;
        a->pres[1].value[0] = -0.05;
        a->pres[1].time_function = &a->table;
        c->n_prescribed = 2;
    }
    /* a traction on the block's top (ramped) and a point force */
    mpm_traction_desc *t = &a->trac[0];
    for (int d = 0; d < dim; d++) {
        t->lo[d] = a->body[0].lo[d];
        t->hi[d] = a->body[0].hi[d];
    }
    t->lo[up] = 0.44;
    t->hi[up] = 0.5;
    t->normal = up;
    t->value[up] = -2000;
    /* tractions with time functions, or particle forces set later */
    a->forces = k == AF_2D_CPDI || k == AF_3D_GIMP;
    t->time_function = a->forces ? NULL : &a->ramp;
    t = &a->trac[1];
    for (int d = 0; d < dim; d++) {
        t->lo[d] = a->body[0].lo[d];
        t->hi[d] = a->body[0].lo[d] + 0.07;
    }
    t->is_force = 1;
    t->value[0] = 5;
    t->time_function = a->forces ? NULL : &a->table;
    c->tractions = a->trac;
    c->n_tractions = 2;
    c->damping = k == AF_2D_CPDI ? MPM_DAMPING_VISCOUS : MPM_DAMPING_LOCAL;
    c->damping_coef = k == AF_2D_CPDI ? 5.0 : 0.2;
}

/* Particle forces (creation order): f_p = (0.5, -0.5, 0.25).  The array's
 * own allocation is counted too, and fails the same way. */
static int af_forces(mpm_sim *s)
{
    size_t n = mpm_sim_particles(s) * (size_t)mpm_sim_dim(s);
    double *f = malloc(n * sizeof *f);
    if (!f) return MPM_ENOMEM;
    for (size_t i = 0; i < n; i++) f[i] = i % 3 == 0 ? 0.5 : i % 3 == 1 ? -0.5 : 0.25;
    int rc = mpm_sim_set_particle_forces(s, f);
    free(f);
    return rc;
}

/* One pass over the case with allocation n failing (0: none).  Returns
 * the test's verdict: 0, or -1 with the failure reported. */
static int af_pass(const af_case *a, const char *name, size_t n, size_t *count)
{
    mpm_error err;
    t_alloc_arm(n);
    mpm_sim *s = mpm_sim_new(&a->c, NULL, &err);
    int new_failed = t_alloc_failed(), made = s != NULL;
    int rc = 0, step_rc = 0;
    if (s) {
        for (int i = 0; i < AF_STEPS && !step_rc; i++) step_rc = mpm_sim_step(s);
        if (!step_rc && a->forces) rc = af_forces(s);
        for (int i = 0; i < AF_STEPS && !step_rc; i++) step_rc = mpm_sim_step(s);
    }
    int failed = t_alloc_failed();
    *count = t_alloc_count();
    mpm_sim_destroy(&s);
    size_t live = t_alloc_disarm();

    if (new_failed && made) {
        t_fail(__FILE__, __LINE__, "%s: allocation %zu failed, mpm_sim_new() succeeded", name, n);
        return -1;
    }
    if (!new_failed && !made) {
        t_fail(__FILE__, __LINE__, "%s: allocation %zu: mpm_sim_new() failed: %s", name, n,
               err.message);
        return -1;
    }
    if (new_failed && err.code != MPM_ENOMEM) {
        t_fail(__FILE__, __LINE__, "%s: allocation %zu: mpm_sim_new() code %d, not MPM_ENOMEM",
               name, n, err.code);
        return -1;
    }
    if (!new_failed && (failed ? rc != MPM_ENOMEM : rc != 0)) {
        t_fail(__FILE__, __LINE__, "%s: allocation %zu (%s): mpm_sim_set_particle_forces() %d",
               name, n, failed ? "failed" : "not failed", rc);
        return -1;
    }
    if (step_rc) {
        t_fail(__FILE__, __LINE__, "%s: allocation %zu: a step returned %d", name, n, step_rc);
        return -1;
    }
    if (n && !failed) {
        t_fail(__FILE__, __LINE__, "%s: allocation %zu never came (%zu made)", name, n, *count);
        return -1;
    }
    if (live) {
        t_fail(__FILE__, __LINE__, "%s: allocation %zu failed: %zu block(s) left allocated", name,
               n, live);
        return -1;
    }
    return 0;
}

TEST(alloc_fail_solver)
{
    size_t total = 0;
    for (int k = 0; k < AF_NCASES; k++) {
        af_case a;
        af_build(&a, k);
        mpm_error err;
        mpm_case_info info;
        char why[512];
        CHECKF(mpm_case_check(&a.c, &info, &err) == 0, "%s: %s", af_name[k],
               mpm_error_text(&err, MPM_FIELD_PROTO, why, sizeof why));
        size_t count = 0, c;
        if (af_pass(&a, af_name[k], 0, &count)) return;
        CHECKF(count > 10, "%s: only %zu allocations counted", af_name[k], count);
        for (size_t n = 1; n <= count; n++)
            if (af_pass(&a, af_name[k], n, &c)) return;
        TLOG("%-28s %zu allocations, each failed once: MPM_ENOMEM, nothing left", af_name[k],
             count);
        total += count;
    }
    TLOG("%zu allocations failed in all", total);
#if defined(__SANITIZE_ADDRESS__)
    CHECKF(!__lsan_do_recoverable_leak_check(), "ASan's leak checker found leaks (report above)");
#endif
}
