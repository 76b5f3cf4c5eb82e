/*
 * mpm_internal.h - the simulation's private state (struct mpm_sim) and the
 * small inline helpers and constants its modules share, for the solver's
 * files only.  It declares no module's functions: each module has its own
 * header (mpm_rows.h, mpm_sort.h, mpm_loads.h, mpm_cond.h, mpm_energy.h,
 * mpm_case.h, mpm_team.h, mpm_plan.h, mpm_kernels.h, mpm_model.h, ...),
 * which includes this one where it needs the struct, so that the includes
 * form no circle (tests/include_graph.py, make layers).  The data of each
 * concern has its own header of types, included here:
 *   mpm_particles.h  the particles' arrays;   mpm_grid.h  the grid's
 *   mpm_model_types.h  the constitutive models (mpm_model.h, mpm_plastic.h);
 *                    their rows and parameters: mpm_material.h
 *                    (mpm_material_table.c)
 *   mpm_team_types.h     the thread team's barrier (mpm_team.h)
 *   mpm_kernels_types.h  the kernel families and their per-thread output
 *   mpm_plan_types.h     the plan: the fast-path switches of a job
 * and the modules that work on it, each declared in its own header:
 *   mpm_sim.c      the public API: creation, the step, results
 *   mpm_rows.c     the active rows, the scatter targets and the node passes
 *   mpm_sort.c     the particles' sort by cell
 *   mpm_loads.c    essential boundary conditions, tractions, particle forces
 *   mpm_cond.c     prescribed velocities and Coulomb friction on grid faces
 *   mpm_energy.c   the energy sums and the divergence guard
 *   mpm_case.c     checking a case and generating its particles
 *   mpm_checkpoint.c  the solver state as a self-checking blob (save, load)
 * A file that needs only one concern includes only its header
 * (mpm_bspline.c mpm_grid.h, mpm_isa.c mpm_isa.h).
 *
 * Hot data is struct-of-arrays: particle field c of particle p is
 * P.field[c][p].  The grid is padded by two ghost layers per side for GMPM,
 * so that the 4 nodes per axis of Eq. 22 never index outside the arrays: a
 * particle in real cell c touches real nodes c-1 .. c+2 (padded c+1 ..
 * c+4), and its centre may be anywhere from the first ghost cell below the
 * grid to the first above it (c = -1 .. nodes-1).  B-splines have no
 * ghost layers: the grid's "nodes" along an axis of n cells are BSPLINE2's
 * n + 2 control points of the open knot vector (a particle in cell c
 * touches c .. c + 2) or BSPLINE3's n + 1 natural nodes at the grid points
 * (cell c touches c - 1 .. c + 2, clamped to the grid; mpm_bspline.c).
 * CPDI pads one layer: centres stay in
 * the real grid, the corners of their domains within one cell of it
 * (mpm_cpdi.c).  Nothing here is allocated inside a time step.
 */
#ifndef MPM_INTERNAL_H
#define MPM_INTERNAL_H

#include "mpm.h"
#include "mpm_grid.h"
#include "mpm_kernels_types.h"
#include "mpm_material.h"
#include "mpm_model_types.h"
#include "mpm_particles.h"
#include "mpm_plan_types.h"
#include "mpm_plastic.h"
#include "mpm_team_types.h"
#include "mpm_timefn.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>

struct mpm_sim {
    int dim;
    /* the fast paths the job takes, chosen once at creation (mpm_plan.h);
     * plan.ns: nodes per axis per particle, 2 (MPM; CPDI: per corner), 3
     * or 4 (GMPM, B-splines) */
    mpm_plan plan;
    int avx2_ok; /* the case and the CPU allow AVX2 (mpm_plan_choose()) */
    /* the REFERENCE kernel family (mpm_case.kernel_family, mpm_ref.c): the
     * step runs mpm_ref_step() on one thread, and the plan's fast paths are
     * off (mpm_ref_init()) */
    int ref;
    mpm_method method;
    mpm_update update;
    int bsp; /* B-spline degree (2 or 3), 0 otherwise */

    /* grid */
    int nreal[3];     /* real nodes per axis (1 for unused axes; B-splines:
                       * control points, nodes + p - 1) */
    int pad;          /* ghost layers per side: 0 MPM and B-splines, 2 GMPM,
                       * 1 CPDI */
    int np[3];        /* padded nodes per axis */
    size_t stride[3]; /* 1, np[0], np[0]*np[1] */
    size_t nn;        /* padded node count */
    double x0[3], h[3], inv_h[3];
    double lo[3], hi[3];    /* particle centres must stay in [lo, hi) */
    double rmax[3];         /* largest r = (x - x0)/h the support boxes and sort
                             * keys take (np - 1; B-splines: cells - 1) */
    mpm_bspline_axis bs[3]; /* B-splines: per axis */
    mpm_gridbuf g;          /* the grid */
    double *minv;           /* 1/m, or 0 for phantom nodes (m <= M_TOL) */
    unsigned stag;          /* the next slot of the staggered arrays (mpm_sim.c) */
    double *ncoord[3];      /* node coordinates per axis, np[d] each
                             * (mpm_node_coord()) */
    double mtol;
    double pic; /* PIC fraction of the velocity update (0: pure FLIP) */
    mpm_transfer transfer;

    /* fixed degrees of freedom: node (padded index) and direction mask */
    size_t nfixed;
    size_t *fixed_node;
    unsigned char *fixed_mask;

    /* loads */
    int has_gravity;
    double gravity[3];
    size_t nload; /* particles with a point force */
    size_t *load_p;
    double *load_f[3];
    double *load_xold[3];
    double external_work;
    double external_work_abs; /* sum of |f . dx|: the guard's bound */
    /* mpm_sim_set_particle_forces(): once called, one load slot per
     * particle (load_p[i] = i) and trac_f keeps the tractions' shares */
    int pforces;
    double *trac_f[3];
    /* time-varying tractions (mpm_loads.c): the constant part of each load
     * slot's force (NULL when no traction has a time function), and ntv
     * entries (slot, traction, force at f = 1); the tractions' time
     * functions (ntrac copies) */
    double *load_f0[3];
    size_t ntv, ntrac;
    size_t *tv_slot;
    uint32_t *tv_trac;
    double *tv_f[3];
    mpm_timefn_copy *trac_tf;
    /* conditions (mpm_cond.c).  has_cond: some prescribed DOF or friction
     * node exists (the node passes then run mpm_cond_*).  Prescribed
     * velocities: npres entries sorted by padded node (node, direction
     * mask, source), the sources' directions' values, time functions and
     * the velocities at t^n and t^{n+1} of the running step (3 per
     * source).  Friction: nfric entries sorted by node (node, face, mu),
     * and the node's state in this step (MPM_FRIC_*: MUSL's remap reads
     * it). */
    int has_cond;
    size_t npres, npsrc;
    size_t *pres_node;
    unsigned char *pres_mask;
    uint32_t *pres_src;
    double *pres_val, *pres_v0, *pres_v1;
    mpm_timefn_copy *pres_tf;
    int *pres_face;            /* per source: its face, or -1 (a node set) */
    unsigned char *pres_fmask; /* per source: its direction mask */
    size_t nfric;
    size_t *fric_node;
    unsigned char *fric_face, *fric_stick;
    double *fric_mu;
    /* cumulative: work of the prescribed velocities (signed) and its
     * absolute sum (the guard's bound), friction dissipation */
    double prescribed_work, prescribed_work_abs, friction_work;

    /* particles and materials */
    mpm_particles P;
    size_t nmat;
    mpm_mat_params *mats;
    mpm_material_desc *mdesc; /* the case's materials (their rows, the fingerprint) */
    const mpm_model_ops *model;
    double cmax; /* largest p-wave speed */
    /* (plan.general: the block update is mpm_model_block(), a model other
     * than linear elasticity or a volume update other than
     * STRAIN_INCREMENT; 0 keeps the linear-elastic path of every earlier
     * release.)  spin3: 3D strain_of() also writes the spins (deps[6..8]).
     * f_block: the block update carries F (F <- (I + dt L) F; CPDI's passes
     * do it themselves).  mixed: the materials' models differ (dispatch by
     * runs of particles of one model). */
    int spin3, f_block, mixed;
    mpm_volume_update volmode;
    double plastic_work; /* cumulative sigma : d eps_p V (thread order) */
    /* frictional: a material is DRUCKER_PRAGER or MOHR_COULOMB (the step
     * sums the substep counters, mpm_sim_plastic_stats()) */
    int frictional;
    mpm_plastic_stats plstats;
    mpm_plastic_params *plp; /* per material (frictional only, else NULL) */

    /* time */
    double dt_fixed; /* > 0: given */
    double cfl;
    double dt; /* dt of the next step */
    double t;
    long steps;
    double vmax; /* max particle speed after the last step */

    /* divergence guard (finish_step): total energy at creation, and the
     * floor below which an energy is noise */
    double e_total0, e_floor;
    double guard_v2; /* max |v|^2 at the last check */

    /* energy balance (mpm_energy_finish()): the total at creation, the
     * scale's constant part K_0 + |S_0| + U_0, gravity's potential at
     * creation, the balance error the last mpm_sim_energy() found and the
     * largest, the budget (0: none) */
    double bal_total0, bal_ref0, bal_pot0, bal_last, bal_worst, budget;
    int fail_on_budget;

    /* damping (mpm_case.damping): kind, coefficient, the time it stops (0:
     * never), and the energy it removed so far */
    mpm_damping_kind damp;
    int damp_on; /* the running step damps */
    double damp_coef, damp_until, damping_work;

    /* energies summed inside the step (mpm_sim_want_energy()): want asks
     * for them in the next step, step_energy says the running step sums
     * them, and ecache holds the sums (combined in thread order; external
     * work and total left out) while ecache_ok says they belong to the
     * particles as they are (cleared when a step starts) */
    int want_energy, step_energy, ecache_ok;
    mpm_energy ecache;
    /* mpm_sim_snapshot()'s request while the team copies it out */
    const mpm_snapshot *snap_out;

    /* kernels chosen once per job */
    const mpm_kernels *k;
    /* gvel: the family gathers grid velocities (every family but CPDI's):
     * the node pass that updates the momentum stores q/m and
     * f/m in place of q and f, and the one that applies BC1 to q2 stores
     * q2/m (phantom nodes: 0); gvel_now: the grid holds them (set after
     * a step, cleared when one starts; mpm_sim_node() answers momenta) */
    int gvel, gvel_now;
    /* Fused steps (G2P2G; plan.fuse: never, where it pays, always; the
     * families but CPDI's have the passes); p2g_fields, the fields the first scatter of a
     * step writes (MPM_F_M | MPM_F_Q, and MPM_F_F for USL and MUSL), kept
     * all zero in the private buffers tbuf[t] between uses (the reduction
     * zeroes what it has read); fuse_next, the running step's moving pass
     * also scatters the next step's P2G fields into tbuf[t] (never before
     * a step that sorts, nor when fuse_pays, set with the active rows,
     * says the extra buffer's pages would cost more than the pass saves,
     * unless plan.fuse is MPM_FUSE_ALWAYS); gnext, it did: the step starts
     * with them */
    int p2g_fields, fuse_next, gnext, fuse_pays;
    /* tshare: the field (MPM_F_F in USF, MPM_F_Q2 in MUSL, else 0) that
     * the private buffers tbuf[t], t >= 1, keep in q's storage: a step
     * scatters it in a pass of its own, after the reduction has read and
     * zeroed q and before the next scatter into q, so that the two never
     * hold values at once (2D MPM USF on 2 threads: 5 fields' pages of
     * thread 1 become 3); with p2g_fields, the fields kept all zero in
     * tbuf[t], t >= 1, between uses (mpm_rows.c, kept_zero()) */
    int tshare;

    /* active region: the padded nodes the particles' supports touch.  A row
     * is the run of nodes along x at fixed (y, z), row index y + z np[1],
     * first node row * np[0].  ulo/uhi[row] are the first and last x node
     * the union of the threads' supports touches in that row (empty:
     * ulo > uhi), and blo..bhi (inclusive) the box of the rows in use; the
     * main grid is all zero outside the rows' extents */
    int blo[3], bhi[3];
    size_t nrows; /* np[1] np[2] */
    int *ulo, *uhi;
    /* node passes split the nodes of the extents among the threads:
     * acc[r] is the number of nodes in the extents of the rows before row
     * r of the box blo..bhi (r = 0 .. box rows), nact their total; wacc[r]
     * the same in work units (MPM_W_*, below), which the passes that
     * reduce split evenly instead: a node that a reduction copies from a
     * private grid counts more than one whose sum is in place */
    size_t *acc, *wacc;
    size_t nact;
    /* sorting by cell (4 to MPM_SORT_EVERY steps apart, begin_step() in
     * mpm_sim.c, and at creation): a stable counting sort
     * with scratch made at creation (the keys, then the new slots, live in
     * sperm; the cells are numbered over the rows' extents only:
     * rowoff[row] is the first key of a row).  Between sorts sperm is
     * free scratch of n 32-bit words (mpm_checkpoint.c).  sort_now: the
     * running step sorts (after its first node pass); sort_go: the team's
     * sort goes on (set by thread 0 between barriers, mpm_sort_team()). */
    uint32_t *sperm, *shist;
    size_t *rowoff;
    int sort_now, sort_go;
    /* plan.sort_ring: entries of each thread's ring (a power of 2, at most
     * sort_cap, the entries allocated); sort_win: the running sort moves
     * every particle less than that far, so the arrays move by a sweep
     * through the ring (mpm_sort.c) */
    size_t sort_cap;
    int sort_win;
    long sort_moved; /* sorts that moved particles (tests read it) */
    long sort_swept; /* of those, the ones that swept (sort_win) */
    /* when to sort (begin_step()): the step of the last sort, and runs0,
     * the cell changes along the particles right after it (checkpointed) */
    long sort_last;
    size_t runs0;

    /* threads */
    int nthreads;
    mpm_gridbuf *tbuf; /* per-thread scatter buffers (thread 0 scatters
                        * into g; tbuf[0], with the P2G fields only, exists
                        * when fuse: the fused passes' target) */
    mpm_thread_out *tout;
    pthread_t *threads;
    mpm_bar bar_start, bar_end; /* bar_end also parts the passes of a
                                 * step (mpm_team_sync()) */
    void (*phase)(mpm_sim *, int tid);
    int quit;
    pthread_mutex_t gate_mu; /* start gate for the team */
    pthread_cond_t gate_cv;
    int gate;      /* 0 closed, 1 open, -1 abort */
    int sync_init; /* 1: gate made, 2: barriers made too */

    atomic_int cancel;
    int failed;    /* 0 or the MPM_E* code that froze the run */
    mpm_error err; /* mpm_sim_error() */
};

/* Stored energy of particle p by its material's model (the general path;
 * linear elasticity: 1/2 sigma : eps V, the bits of the default path). */
static inline double mpm_model_energy(const mpm_sim *s, size_t p)
{
    const mpm_mat_params *mp = &s->mats[s->P.mat[p]];
    return mp->ops->energy(mp, &s->P, s->dim, p);
}

/* ---- small shared helpers (inline: some run inside the passes) ---- */

/* thread tid's fixed contiguous slice of the particles */
static inline void mpm_particle_slice(const mpm_sim *s, int tid, size_t *a, size_t *b)
{
    mpm_slice(s->P.n, s->nthreads, tid, a, b);
}

/* flat padded index of real node ijk */
static inline size_t mpm_node_index(const mpm_sim *s, const int ijk[3])
{
    size_t n = 0;
    for (int d = 0; d < s->dim; d++) n += (size_t)(ijk[d] + s->pad) * s->stride[d];
    return n;
}

/* Position along axis d of padded node i: x0 + i h for MPM, GMPM and
 * BSPLINE3's natural end basis; for BSPLINE2 the Greville abscissa of
 * control point i, x0 + h (t_{i+1} + ... + t_{i+p}) / p, with which the
 * B-splines reproduce linear functions exactly (sum_i N_i(x) xi_i = x). */
static inline double mpm_node_coord_calc(const mpm_sim *s, int axis, int padded_index)
{
    if (s->bsp != 2) return s->x0[axis] + padded_index * s->h[axis];
    int p = s->bsp, n = s->bs[axis].n;
    double sum = 0;
    for (int k = padded_index + 1; k <= padded_index + p; k++) {
        int t = k - p;
        sum += t < 0 ? 0 : t > n ? n : t;
    }
    return s->x0[axis] + s->h[axis] * sum / p;
}

/* mpm_node_coord_calc() of padded node i along axis, from the table made at
 * creation (the one place the kernels take node coordinates from). */
static inline double mpm_node_coord(const mpm_sim *s, int axis, int padded_index)
{
    return s->ncoord[axis][padded_index];
}

/* ---- the active rows and the node passes (mpm_rows.h) ---- */

/* rows (y, z) of box lo..hi (inclusive); 0 when empty */
static inline size_t mpm_box_rows(const int lo[3], const int hi[3])
{
    if (lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]) return 0;
    return (size_t)(hi[1] - lo[1] + 1) * (size_t)(hi[2] - lo[2] + 1);
}

/* row index (y + z np[1]) of row r of box lo..hi */
static inline size_t mpm_box_row(const mpm_sim *s, const int lo[3], const int hi[3], size_t r)
{
    size_t ny = (size_t)(hi[1] - lo[1] + 1);
    size_t y = (size_t)lo[1] + r % ny, z = (size_t)lo[2] + r / ny;
    return y + z * (size_t)s->np[1];
}

/* flat index of node x of row `row` */
static inline size_t mpm_row_node(const mpm_sim *s, size_t row, int x)
{
    return row * (size_t)s->np[0] + (size_t)x;
}

/* Node operations of mpm_node_pass(), in the order applied to each node
 * (after the reduction of the fields named): inverse mass with phantom
 * nodes at 0, gravity f += m g, BC1 on q or on q2, BC2 on f, damping of
 * f, q += f dt. */
enum {
    MPM_N_MINV = 16,
    MPM_N_GRAV = 32,
    MPM_N_BC1 = 64,
    MPM_N_BC1Q2 = 128,
    MPM_N_BC2 = 256,
    MPM_N_UPD = 512,
    MPM_N_DAMP = 1024, /* damping (after BC2, before the update; mpm.h) */
    MPM_N_Z0 = 2048,   /* zero thread 0's next-step buffer (fused steps) */
    MPM_N_VQ2 = 4096   /* q2/m in place of q2, last (mpm_sim.gvel) */
};

/* Work units of a node in a pass that reduces (mpm_sim.wacc): MPM_W_NODE for
 * every node, MPM_W_COPY more where the main grid holds no sum (thread 0
 * did not scatter there), so that a private grid's values are copied there
 * and zeroed rather than added.  A copied node counts 4/3 of an added one:
 * split by nodes alone, thread 1 (whose rows are the copied ones in 2
 * threads) made the copies and thread 0 waited for it; 4/3, 3/2 and 2
 * measured alike (docs/performance.md). */
#define MPM_W_NODE 3
#define MPM_W_COPY 1

/* ---- sorting by cell (mpm_sort.h) ---- */

#define MPM_SORT_EVERY 16 /* the longest interval between sorts */
/* the shortest, when the particles' cell runs have fallen apart: more than
 * MPM_SORT_SPLIT times the cell changes right after the last sort */
#define MPM_SORT_MIN 4
/* the largest ring of saved slots a thread keeps for the sort's moves
 * (12 bytes an entry): sorts that move no particle this far or farther
 * sweep the arrays through it, the others follow the permutation's
 * cycles */
#define MPM_SORT_RING 8192
#define MPM_SORT_SPLIT 2
/* Fused steps need this many particles per page of a grid field the
 * active rows touch (mpm_rows.c fuse_pays()). */
#define MPM_FUSE_PER_PAGE 400

/* ---- prescribed velocities and face friction (mpm_cond.h) ---- */

/* A friction node's state in the running step (mpm_sim.fric_stick): it did
 * not press on its face, it pressed and stuck, it pressed and slid. */
enum { MPM_FRIC_FREE = 0, MPM_FRIC_STICK = 1, MPM_FRIC_SLIDE = 2 };

/* ---- energies and the divergence guard (mpm_energy.h) ---- */

#define MPM_GUARD_EVERY 16

#endif
