/*
 * checkpoint.c - `mpmbench --checkpoint`: the size and the speed of the
 * solver's checkpoints (mpm_checkpoint.c).  Three blocks of ~N
 * particles (a 2D GIMP linear elastic one, a 2D GIMP Drucker-Prager one,
 * a 3D CPDI linear elastic one) under gravity on a fixed floor (the lean
 * build: drifting, no gravity or walls), each run four steps, then: the
 * blob's bytes per particle, the median wall time
 * of 3 saves into a buffer and of 3 loads into a fresh simulation of the
 * same case (memory only: no file, no fsync), against the time of one
 * step; and the check that the loaded simulation saves the very same
 * blob.  It measures and reports; nothing here is a timed assertion.
 */
#include "perf.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double median3(double a, double b, double c)
{
    return a > b ? (b > c ? b : (a > c ? c : a)) : (a > c ? a : (b > c ? c : b));
}

typedef struct {
    const char *name;
    int dim;
    mpm_method method;
    mpm_model_kind model;
} ck_scene;

/* A block of nb cells per axis (2 points per cell per axis) on a grid of nb
 * + 8 cells, resting on the fixed floor, under gravity. */
static void ck_case(const ck_scene *sc, long particles, int threads, mpm_case *c,
                    mpm_material_desc *m, mpm_body_desc *b)
{
    int dim = sc->dim, per = dim == 2 ? 4 : 8;
    int nb = (int)lround(pow((double)particles / per, 1.0 / dim));
    if (nb < 4) nb = 4;
    double h = 1.0 / nb;
    memset(c, 0, sizeof *c);
    memset(m, 0, sizeof *m);
    memset(b, 0, sizeof *b);
    m->model = sc->model;
    m->youngs_modulus = 1e6;
    m->poisson_ratio = 0.3;
    m->density = 2000;
    m->friction_angle = 30;
    m->dilatancy_angle = 0;
    m->cohesion = 100;
    m->tension_cutoff = HUGE_VAL;
    c->grid.dim = dim;
    for (int d = 0; d < dim; d++) {
        c->grid.h[d] = h;
        c->grid.nodes[d] = nb + 9;
        b->lo[d] = d == 1 ? 0 : 4 * h;
        b->hi[d] = b->lo[d] + nb * h;
    }
    b->ppc = 2;
    b->shape = MPM_SHAPE_BOX;
    c->method = sc->method;
    c->update = MPM_USF;
#if PB_LEAN /* no gravity or walls in the lean solver: the block drifts */
    b->velocity[0] = 0.1;
#else
    c->gravity[1] = -9.81;
    c->bc.face_mask[2] = 7;
#endif
    c->n_materials = 1;
    c->materials = m;
    c->n_bodies = 1;
    c->bodies = b;
    c->threads = threads;
}

static int ck_scene_run(const ck_scene *sc, long particles, int threads)
{
    mpm_case c;
    mpm_material_desc m;
    mpm_body_desc b;
    mpm_error err;
    ck_case(sc, particles, threads, &c, &m, &b);
    c.kernels = pb_kernels();
    mpm_sim *s = mpm_sim_new(&c, NULL, &err), *r = NULL;
    void *blob = NULL, *again = NULL;
    int rc = 1;
    if (!s) {
        fprintf(stderr, "mpmbench: %s: %s\n", sc->name, err.message);
        return 1;
    }
    double t0 = 0;
    for (int k = 0; k < 4; k++) { /* two to warm up (first touches), two timed */
        if (k == 2) t0 = now_s();
        if (mpm_sim_step(s)) {
            fprintf(stderr, "mpmbench: %s: %s\n", sc->name, mpm_sim_error(s)->message);
            goto out;
        }
    }
    double tstep = (now_s() - t0) / 2;
    size_t n = mpm_sim_checkpoint_size(s), np = mpm_sim_particles(s);
    blob = malloc(n);
    again = malloc(n);
    if (!blob || !again) goto out;
    double ts[3], tl[3];
    for (int k = 0; k < 3; k++) {
        t0 = now_s();
        if (mpm_sim_checkpoint_save(s, blob, n)) goto out;
        ts[k] = now_s() - t0;
    }
    if (!(r = mpm_sim_new(&c, NULL, &err))) goto out;
    for (int k = 0; k < 3; k++) {
        t0 = now_s();
        if (mpm_sim_checkpoint_load(r, blob, n, &err)) {
            fprintf(stderr, "mpmbench: %s: load: %s\n", sc->name, err.message);
            goto out;
        }
        tl[k] = now_s() - t0;
    }
    int same = mpm_sim_checkpoint_size(r) == n && !mpm_sim_checkpoint_save(r, again, n) &&
               !memcmp(blob, again, n);
    double tsave = median3(ts[0], ts[1], ts[2]), tload = median3(tl[0], tl[1], tl[2]);
    printf("%-22s %9zu %8.1f %10.1f %9.1f %9.1f %9.1f  %s\n", sc->name, np, (double)n / (double)np,
           (double)n / 1e6, 1e3 * tsave, 1e3 * tload, 1e3 * tstep,
           same ? "same blob" : "DIFFERENT BLOB");
    rc = same ? 0 : 1;
out:
    mpm_sim_destroy(&s);
    mpm_sim_destroy(&r);
    free(blob);
    free(again);
    return rc;
}

int pb_checkpoint_bench(long particles, int threads)
{
    static const ck_scene scenes[] = {
        {"2D GIMP elastic", 2, MPM_METHOD_GIMP, MPM_MODEL_LINEAR_ELASTIC},
        {"2D GIMP Drucker-Prager", 2, MPM_METHOD_GIMP, MPM_MODEL_DRUCKER_PRAGER},
        {"3D CPDI elastic", 3, MPM_METHOD_CPDI, MPM_MODEL_LINEAR_ELASTIC}};
    int fails = 0;
    printf("checkpoints, ~%ld particles, %d thread%s (median of 3; in memory, no file)\n",
           particles, threads, threads > 1 ? "s" : "");
    printf("%-22s %9s %8s %10s %9s %9s %9s\n", "scene", "particles", "B/part", "blob MB", "save ms",
           "load ms", "step ms");
    for (size_t i = 0; i < sizeof scenes / sizeof *scenes; i++)
        fails += ck_scene_run(&scenes[i], particles, threads);
    return fails ? 1 : 0;
}
