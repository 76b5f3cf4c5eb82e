/*
 * bench.h - the accuracy benchmark's problems with known answers, run
 * in-process with the solver library (bin/mpmbench-accuracy, see
 * accuracy.c).  One call runs one configuration (problem, method, update,
 * cells per unit length, particles per cell per axis, time step as a
 * fraction of the CFL limit, velocity transfer: FLIP, PIC, APIC) and
 * returns its errors and the time spent
 * stepping.  The problems and their error measures:
 *
 *  point  the paper's single material point (Eqs. 32-33), 3 periods.
 *         err: max over time of Eq. 38, |va - v| / (1 + |va|).
 *         err2: |E_end - E0| / E0.
 *  bar    the bar's first mode (Eqs. 34-35), v0 = 1e-3 (small strain, so
 *         the linear solution is the limit), 2 periods.
 *         err: max over time of the RMS over particles of |u - Eq. 35|,
 *              divided by the amplitude v0 / omega_1.
 *         err2: max over time of |vcm - Eq. 34| / (2 v0 / pi).
 *  mms1/2/3  a manufactured solution in the manner of Wallstedt & Guilkey
 *         (2008): u_i = A sin(2 pi X_i) sin(pi c t + phi_i) on the unit
 *         line/square/cube, rollers on every face, A = 0.02 (strains up to
 *         13%, particles cross cells), one period, with the body force that
 *         makes it an exact solution of the solver's continuum model (see
 *         problems.c).
 *         err: max over time of the RMS position error / A.
 *         err2: max over time and particles of the position error / A.
 *  disks  the paper's two bouncing disks (Section 5.6) until t = 4, after
 *         they separate; the known answers are E = E0 and p = 0.
 *         err: the mean over the run of |E(t) - E0| / E0 (a mean of
 *              absolute values: an end value alone can cross zero by
 *              chance, a dissipative USL run meeting an energy-gaining
 *              contact);
 *         err2: |E(4) - E0| / E0;  err3: max |p| / (M v0).
 *  spin   a spinning disk: radius 0.2 at the centre of
 *         the unit square, rigid rotation with a rim speed of 3 % of the
 *         p-wave speed, half a revolution, no boundary touched.  Exact:
 *         angular momentum and kinetic energy are conserved (the disk's
 *         centripetal strain energy is ~1e-3 of K).
 *         err: |L(end) - L0| / |L0| (mpm_energy.angular_momentum[2]);
 *         err2: |K(end) - K0| / K0;  dL, dK: the signed changes.
 *  column the elastic column compacting under its own weight of Coombs &
 *         Augarde 2020 (AMPLE, Section 5.1; after Charlton, Coombs &
 *         Augarde 2017): l0 = 50, E = 1e6, nu = 0, rho0 = 80, g = 10, base
 *         on rollers, 1D (their plane-strain column one cell wide with
 *         rollers on the sides is the same problem).  The published answer
 *         sigma_yy = -rho0 g (l0 - Y) (Y the initial height) holds for any
 *         elastic law, so also for the solver's.  Loaded quasi-statically:
 *         the weight is ramped in with (1 - cos)/2 over 4 periods of the
 *         column's first mode, then the stress is averaged over one more
 *         period (all the column's modes have periods T/(2k-1)).
 *         err: sum_p V0_p |sigma_p - sigma_a(Y_p)| / (rho0 g l0 sum V0_p),
 *              the published error measure;
 *         err2: RMS over points of |u_p - u_a(Y_p)| / |u_a(l0)|, u_a the
 *              displacement of the solver's model (Cauchy sigma = E ln F,
 *              derived in problems.c; not from the paper).
 *
 * dt is fixed: dt = T / ceil(T / (cfl * h / c)) with T the end time and c
 * the p-wave speed, so every run ends exactly at T; allow_unstable_dt is
 * set, since sweeping past the limit is the point.
 */
#ifndef BENCH_H
#define BENCH_H

#include "mpm.h"

#include <stddef.h>

typedef enum {
    BP_POINT,
    BP_BAR,
    BP_MMS1,
    BP_MMS2,
    BP_MMS3,
    BP_DISKS,
    BP_SPIN,
    BP_COLUMN,
    BP_COUNT
} bench_problem;

/* ---- methods and transfers: one line each ------------------------------
 * The tables bench_methods[] and bench_transfers[] (problems.c) list every
 * shape function and every velocity transfer the benchmark knows.  A row
 * with enabled = 0 is skipped everywhere; the switches below (1 unless
 * defined otherwise, e.g. -DBENCH_HAVE_CPDI=0) set the families':
 *   BENCH_HAVE_BSPLINE  MPM_METHOD_BSPLINE2 = 2, MPM_METHOD_BSPLINE3 = 3
 *   BENCH_HAVE_CPDI     MPM_METHOD_CPDI = 4
 *   BENCH_HAVE_APIC     mpm_case.transfer (mpm_transfer, MPM_TRANSFER_APIC = 1)
 * The method values are plain integers in the table, so they compile
 * before the enumerators exist; mpm_case.transfer is only written when
 * BENCH_HAVE_APIC is 1 (bench_apply_scheme in problems.c). */
#ifndef BENCH_HAVE_BSPLINE
#define BENCH_HAVE_BSPLINE 1
#endif
#ifndef BENCH_HAVE_CPDI
#define BENCH_HAVE_CPDI 1
#endif
#ifndef BENCH_HAVE_APIC
#define BENCH_HAVE_APIC 1
#endif

typedef struct {
    const char *name; /* as in the tables and the CSV */
    int value;        /* the mpm_method value */
    int enabled;
    int cost;        /* cost per point-step relative to GIMP, times 4: documentation
                      * only, the guess behind the run-time estimate of
                      * docs/accuracy.md (the code does not read it) */
    int rebuildable; /* the state is positions, velocities, stresses and volumes
                      * only (the force self-test rebuilds the case each step) */
} bench_method_row;

typedef struct {
    const char *name;
    int value;           /* the mpm_transfer value (FLIP = 0, APIC = 1) */
    double pic_fraction; /* mpm_case.pic_fraction */
    int enabled;
} bench_transfer_row;

extern const bench_method_row bench_methods[];
extern const int bench_n_methods;
extern const bench_transfer_row bench_transfers[];
extern const int bench_n_transfers;

/* the transfer rows (indices into bench_transfers[]) */
enum { BT_FLIP = 0, BT_PIC = 1, BT_APIC = 2 };

typedef struct {
    bench_problem pb;
    mpm_method method;
    mpm_update update;
    int transfer; /* index into bench_transfers[] */
    int cells;    /* cells per unit length (point: 1; disks: 1/h) */
    int ppc;      /* particles per cell per axis (point: 1) */
    double cfl;   /* dt as a fraction of h / c */
} bench_cfg;

typedef struct {
    int rc;           /* 0, or the MPM_E* code that stopped the run */
    char msg[256];    /* the solver's message when rc != 0 */
    double err, err2; /* see above; INFINITY when the run failed */
    double err3;      /* disks: the momentum error; 0 otherwise */
    double dL, dK;    /* spin: signed relative changes of L and K; 0 otherwise */
    double wall;      /* seconds spent stepping (wall clock) */
    long steps;
    size_t particles;
    double dt;
    double *xf; /* final positions (particles * dim) when asked */
    int dim;
} bench_res;

const char *bench_problem_name(bench_problem pb);
const char *bench_method_name(mpm_method m);
const char *bench_update_name(mpm_update u);
const char *bench_transfer_name(int transfer);
/* Index of a method value in bench_methods[], or -1. */
int bench_method_index(mpm_method m);
/* Sets method, update and transfer (pic_fraction, and mpm_case.transfer
 * when BENCH_HAVE_APIC) of a case from a configuration. */
void bench_apply_scheme(mpm_case *c, const bench_cfg *cf);
int bench_problem_dim(bench_problem pb);

/* The length that position differences are divided by when two runs of the
 * problem are compared (time self-convergence): the displacement amplitude
 * (point, bar, mms) or the disk radius. */
double bench_scale(bench_problem pb);

/* Runs one configuration.  keep_final: also return the final positions in
 * r->xf (free with bench_res_free).  Returns 0 when the run could be set
 * up (r->rc tells whether it finished), -1 on a setup error (message in
 * r->msg). */
int bench_run(const bench_cfg *c, int keep_final, bench_res *r);
void bench_res_free(bench_res *r);

/* RMS over particles of |a - b| / scale (n particles, dim components). */
double bench_rms_diff(const double *a, const double *b, size_t n, int dim, double scale);

/* Monotonic seconds. */
double bench_now(void);

/* ---- per-particle body force (bench_force.c) ----
 * f: particles * dim forces in creation order, for the following steps
 * (mpm_sim_set_particle_forces).  Returns 0 or the solver's error code. */
int bench_force_set(mpm_sim *s, const double *f);
/* Returns 0 when mpm_sim_set_particle_forces() and rebuilding the case every
 * step with one public point force per particle agree bitwise on a small 1D
 * manufactured problem for every enabled, rebuildable method and every
 * update (FLIP);
 * writes a one-line summary into msg. */
int bench_force_selftest(char *msg, size_t n);

/* The granular column collapse (collapse.c): its own table, run after the
 * sweeps (or alone with --only collapse), and DIR/collapse.csv.  quick: one
 * cell size and scheme.  Returns 0, or -1 when a run failed. */
int bench_collapse(int quick, const char *out);

#endif
