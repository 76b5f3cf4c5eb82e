/*
 * mpm_diag.h - the solver's diagnostic interface, for tests, benchmarks and
 * tools, not for mpmd or its clients: the grid state after a step, the
 * shape weights of one axis, CPDI's weights of one particle, the
 * modelled memory traffic of a step, and forcing fast-path variants
 * (mpm_sim_plan_override()).  Implemented beside what they expose
 * (mpm_sim.c, mpm_kernels.c, mpm_cpdi.c, mpm_traffic.c); the product API
 * is mpm.h, which this extends.
 */
#ifndef MPM_DIAG_H
#define MPM_DIAG_H

#include "mpm.h"

#include <stddef.h>

/* Grid state after the last step, for tests and diagnostics: node mass and
 * momentum of real node (i, j, k) (unused indices 0): the momentum the step
 * updated (q + f dt), read back as m (q/m) where the step stored velocities
 * (every method but CPDI), 0 at phantom nodes (mass <= M_TOL:
 * no velocity, Fig. 7).  B-splines: the
 * values of node (i, j, k) of the basis, i in [0, nodes + 1) for BSPLINE2's
 * control points, [0, nodes) for BSPLINE3's natural nodes, along an axis of
 * `nodes` grid nodes; mpm_sim_nodes() counts them. */
void mpm_sim_node(const mpm_sim *sim, const int ijk[3], double *mass, double q[MPM_MAX_DIM]);

/* Shape weights along one axis (exposed for tests).  For a particle at x on
 * an axis whose first node is at x0 with spacing h, fills the nn = 2 (MPM),
 * 4 (GIMP, half-width lp), 3 (BSPLINE2) or 4 (BSPLINE3) weights and
 * gradients of consecutive nodes starting at the reference node (Eq. 21 /
 * 22; BSPLINE2: control points c .. c + 2 of cell c; BSPLINE3: natural
 * nodes c - 1 .. c + 2, clamped to the grid), and returns that node's
 * index.  nodes: the grid nodes along the axis, which the B-splines' spans
 * next to the ends need (ignored by MPM and GIMP); x must lie in [x0, x0 +
 * (nodes - 1) h] for B-splines. */
int mpm_shape_1d(mpm_method method, double x, double x0, double h, double lp, int nodes, double *w,
                 double *g);

/* CPDI1 weights of one particle (exposed for tests): centre x, deformation
 * gradient F (row-major 3x3, F[3 i + j], the first dim rows and columns
 * used) and initial half-widths lp, on grid g (no ghost layers).  Fills one
 * entry per (corner, node) pair, 4^dim in all (a node shared by corners
 * appears once per corner): real node ijk[k], weight S[k] and gradient
 * G[k]; returns 4^dim, or -1 when a corner lies outside the grid or
 * det F <= 0. */
int mpm_cpdi_shape(const mpm_grid_desc *g, const double x[3], const double F[9], const double lp[3],
                   int ijk[64][3], double S[64], double G[64][3]);

/* The modelled particle-array traffic of one step (mpm_traffic.c): for
 * each particle pass of the configured job's step, the bytes per particle
 * of particle arrays it reads and writes, and their sums.  The model: each
 * particle array a pass touches counts once per pass (8 bytes per double
 * per particle; mat 2, id 4), read when the pass loads its old value,
 * written when the pass stores it (an array both read and written counts
 * twice; one only written, once: STREAM's counting, no write-allocate).
 * Grid arrays, the per-thread scratch, the sort (4-16 steps apart), point
 * loads and the energy sums of mpm_sim_want_energy() steps are not
 * counted.  Fused steps (every method but CPDI): the moving pass also
 * makes the next step's first scatter and reads only what it has not
 * touched yet.  A lower bound on the step's memory traffic, and
 * the figure a bandwidth roof is measured against (bin/mpmbench). */
#define MPM_TRAFFIC_MAX_PASSES 8
typedef struct {
    int npass;
    struct {
        const char *name;   /* "p2g_mq", "stress_force", "g2p_xv", ... */
        double read, write; /* bytes per particle */
    } pass[MPM_TRAFFIC_MAX_PASSES];
    double read, write, total; /* per particle-step: the passes' sums */
} mpm_traffic;
/* Fills *out for sim's job; returns 0, or MPM_EINVAL (sim or out NULL). */
int mpm_sim_traffic(const mpm_sim *sim, mpm_traffic *out);

/* Forces variants of sim's plan (mpm_sim_plan()): text is key=value pairs
 * of its text form.  The chosen keys set their switch: kernels
 * (portable|avx2), ns (GIMP: 3|4, before the first step), fuse
 * (off|auto|always; off drops a next-step scatter already made), el_lanes
 * and dp_lanes (0|1; 1 only where the job's default is 1 for those
 * kernels), sort_ring (a power of 2 up to the default); a new kernels
 * value brings its own defaults of the others.  The derived keys may be
 * given with the value they have (a whole plan's text is accepted back).
 * Between steps only.  Returns 0, or MPM_EINVAL with err naming
 * "plan.KEY" (nothing changed). */
int mpm_sim_plan_override(mpm_sim *sim, const char *text, mpm_error *err);

#endif
