/*
 * ceiling.h - the lean 2D MPM USF step of bin/mpmceiling (tests:
 * tests/bench/t_ceiling.c): the paper's two disks with nothing but a
 * step's arithmetic, to measure how fast a double-precision step runs on
 * this CPU without the solver's generality.  Not part of mpmd and not a
 * solver: no checks, no energies, no boundary conditions, no materials but
 * one linear-elastic one, 1 thread.  ceiling.c holds the scene, the step
 * and the portable kernels, ceiling_avx2.c the four-lane kernels,
 * mpmceiling.c the command line; tests/bench/t_ceiling.c checks the step against
 * the solver and the two kernel sets against each other.
 */
#ifndef CEILING_H
#define CEILING_H

#include <stddef.h>
#include <stdint.h>

/* a sort when a step took more runs of one cell than this many per
 * particle (a 2 x 2 lattice in place: 1/4; once its particles straddle
 * cell lines: 1/2) */
#define CL_RUNS_SORT 0.3

/* Slack after every array: the four-lane kernels load four particles at
 * a time past the last one. */
#define CL_SLACK 8

/* The particles, struct of arrays (9 doubles: x, v, sigma, m, V). */
typedef struct {
    size_t n;
    double *x, *y, *vx, *vy, *sxx, *syy, *sxy, *m, *vol;
} cl_parts;

/* The grid: nodes j * nx + i; this step's mass and momentum (q becomes
 * the velocity in the node pass) with 1/m, the force (becomes the
 * acceleration), the next step's mass and momentum, and each row's
 * extent of active nodes, this step's and the next one's. */
typedef struct {
    int nx, ny;
    double ih, dt, lambda, mu2;
    double *m, *qx, *qy, *fx, *fy, *mi;
    double *nm, *nqx, *nqy;
    int *rlo, *rhi, *nlo, *nhi;
} cl_grid;

/* The two particle passes of a step: the stress and the internal force
 * (from this step's grid velocity q/m), then the move and the next step's
 * mass and momentum.  Each returns how many runs of one cell it took (a
 * run being up to four particles in the four-lane kernels). */
typedef struct {
    const char *name;
    size_t (*stress_force)(cl_parts *P, cl_grid *g);
    size_t (*move_p2g)(cl_parts *P, cl_grid *g);
} cl_kernels;

/* Adds node n's cell (nodes n, n + 1 and a row up) to the next step's
 * row extents. */
static inline void cl_extent(cl_grid *g, size_t n)
{
    int j = (int)(n / (size_t)g->nx), i = (int)(n % (size_t)g->nx);
    for (int r = j; r <= j + 1; r++) {
        if (i < g->nlo[r]) g->nlo[r] = i;
        if (i + 1 > g->nhi[r]) g->nhi[r] = i + 1;
    }
}

/* The portable kernels (ceiling.c: one particle at a time, a run of one
 * cell summed in locals), and the four-lane ones (ceiling_avx2.c), NULL
 * where not built or where the CPU lacks AVX2 or FMA. */
const cl_kernels *cl_kernels_portable(void);
const cl_kernels *cl_kernels_avx2(void);

/* The scene and its grid, the sort's scratch, the time the sorts took. */
typedef struct {
    cl_parts P;
    cl_grid g;
    uint32_t *key;   /* the sort's cell keys, then slots */
    size_t *count;   /* its histogram, nx * ny + 1 */
    double *scratch; /* one array's copy */
    double t_sort;   /* seconds in the sorts */
    long sorts;
} cl_case;

/* Cells per axis that give about `want` particles (bin/mpmbench's
 * disks2d: two disks of radius 0.14 at 2 x 2 per cell). */
int cl_disks_cells(long want);

/* The disks on a grid of `cells` cells per axis (0: cl_disks_cells(want)),
 * sorted by cell, the first step's mass and momentum scattered: 0, or
 * -ENOMEM (then cl_case_free() what was made). */
int cl_case_new(cl_case *c, long want, int cells);
void cl_case_free(cl_case *c);

/* `steps` steps with kernels k, each followed by a sort when the moving
 * pass took more than CL_RUNS_SORT runs per particle. */
void cl_run(cl_case *c, const cl_kernels *k, long steps);

/* Kinetic energy and momentum of the particles. */
void cl_totals(const cl_parts *P, double *ek, double *px, double *py);

/* Seconds on the monotonic clock. */
double cl_now(void);

/* Two kernel sets run from one start to t_end (the steps that reach it):
 * the largest differences between their particles, positions absolute
 * (the unit square), velocities and stresses over the largest magnitude
 * of their field in the first run; the sorts each made; the kinetic
 * energies at the end. */
typedef struct {
    size_t n;
    long steps, sorts[2];
    double t, dx, dv, ds, ek[2];
} cl_diff;

/* 0, or -ENOMEM. */
int cl_compare(const cl_kernels *ka, const cl_kernels *kb, long want, double t_end, cl_diff *d);

#endif
