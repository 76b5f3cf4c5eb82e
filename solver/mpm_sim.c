/*
 * mpm_sim.c - the solver's public API: a simulation's creation from a
 * case, the explicit step, and the results.  The step's parts live in their
 * own modules (mpm_internal.h lists them): the thread team (mpm_team.c),
 * the active rows and node passes (mpm_rows.c), the sort (mpm_sort.c),
 * boundary conditions and loads (mpm_loads.c), the energies and the
 * divergence guard (mpm_energy.c), the particle loops (mpm_kernels.inc, the plan in mpm_plan.c).
 *
 * One step follows Figs. 5-7 of the GMPM paper.  With q the grid momentum
 * and f the rate of momentum (Eq. 13: f = f_ext - f_int):
 *
 *   USF:  P2G m, q | BC1 | strain+stress, P2G f | gravity, loads | BC2 |
 *         q += f dt | G2P x, v
 *   USL:  P2G m, q, f | gravity, loads | BC1 | BC2 | q += f dt |
 *         G2P x, v, then strain+stress from the updated q
 *   MUSL: as USL up to q += f dt | G2P v | P2G q2 = sum S m v_new | BC1 on
 *         q2 | G2P x from q, strain+stress from q2
 *
 * BC1 zeroes the fixed components of q at grid initialisation (Eq. 27), BC2
 * those of f before the nodal update (Eq. 28): the paper's "correct" order
 * (Fig. 21), which keeps the momentum of a fixed node exactly zero.  Nodes
 * with mass <= M_TOL are phantom: their inverse mass is stored as 0, so they
 * give no velocity (Fig. 7) and no update (Fig. 6).
 *
 * Threads: a team of nthreads (the caller's thread is thread 0) runs a
 * whole step as one team phase, the passes parted by barriers.  Each
 * particle pass runs on a fixed contiguous slice of the particles, thread 0
 * scattering into the grid and the others into a private grid each; node
 * passes split the active nodes evenly among the threads (one row in 1D is
 * split too), sum the private grids in thread order and apply everything
 * node-wise that follows (inverse mass, gravity, BC1, BC2, q += f dt) in
 * the same pass.  The divergence guard's energy sums (or the step's own,
 * summed in its last particle passes when mpm_sim_want_energy() asked for
 * them; the guard's step always does), the sort keys, the sort's
 * permutation and the snapshots run on the team too, sums combined in
 * thread order.  The
 * same case with the same thread count is therefore bitwise reproducible;
 * a different thread count changes the order of the sums and so the last
 * bits.  Nothing is allocated inside a step.
 *
 * Cost and memory follow the particles, not the grid: the particle passes
 * record, row by row (a row: the nodes along x at fixed y, z), the extent
 * of nodes their supports touch, and zeroing, reduction, node updates and
 * boundary conditions run over those extents only (the grid outside them
 * stays zero, and pages of the grids that no particle reaches are never
 * touched).  Particles are kept sorted by cell (when their runs of one cell
 * fall apart, or MPM_SORT_EVERY steps after the last sort: a stable
 * counting sort after the step's first scatter, skipped when the keys are
 * in order already), with
 * P.id mapping storage slots to creation order
 * for everything public.  Built with -DMPM_LEAN, gravity, loads and fixed
 * boundaries are compiled out and cases using them are refused.
 */
#include "mpm_case.h"
#include "mpm_cond.h"
#include "mpm_cpdi.h"
#include "mpm_diag.h"
#include "mpm_energy.h"
#include "mpm_internal.h"
#include "mpm_isa.h"
#include "mpm_kernels.h"
#include "mpm_kernels_avx2.h"
#include "mpm_loads.h"
#include "mpm_material_table.h"
#include "mpm_method.h"
#include "mpm_model.h"
#include "mpm_plan.h"
#include "mpm_ref.h"
#include "mpm_rows.h"
#include "mpm_sort.h"
#include "mpm_team.h"

#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- allocation helpers ---- */

static void *line_alloc(size_t bytes)
{
    size_t n = (bytes + 63) / 64 * 64;
    void *p = aligned_alloc(64, n ? n : 64);
    if (p) memset(p, 0, n ? n : 64);
    return p;
}

/* The particle and grid arrays, staggered: the passes use them index by
 * index side by side (x, v, sigma, m of particle p; m, q, f of node n),
 * and the large blocks malloc() maps all start at one offset in their
 * page (16 bytes in), so element i of every array would share its low 12
 * address bits: one L1 set for all of them (8 ways), and loads taken for
 * dependent on stores to another array (4K aliasing).  Slot k of a
 * simulation (*slot, counted up) starts instead at k * STAG_STEP bytes
 * modulo a page (64 slots a line apart, in an order that puts the arrays
 * allocated one after another 17 lines apart), zeroed, the block malloc()
 * gave kept just in front of it for stag_free().  Addresses only: the
 * same bits. */
#define STAG_PAGE 4096u
#define STAG_STEP (17u * 64u) /* 64 slots, neighbours 17 lines apart */

static double *stag_alloc(size_t n, unsigned *slot)
{
    size_t off = (size_t)(*slot)++ * STAG_STEP % STAG_PAGE;
    if (n > (SIZE_MAX - 2 * STAG_PAGE) / sizeof(double)) return NULL; /* as calloc() would */
    size_t bytes = (n ? n : 1) * sizeof(double);
    unsigned char *raw = calloc(1, bytes + 2 * STAG_PAGE);
    if (!raw) return NULL;
    unsigned char *p = raw + sizeof raw;
    p += (off + STAG_PAGE - (uintptr_t)p % STAG_PAGE) % STAG_PAGE; /* p % STAG_PAGE == off */
    memcpy(p - sizeof raw, &raw, sizeof raw);
    return (double *)(void *)p;
}

static void stag_free(double *p)
{
    if (!p) return;
    void *raw;
    memcpy(&raw, (unsigned char *)p - sizeof raw, sizeof raw);
    free(raw);
}

static void free_gridbuf(mpm_gridbuf *b)
{
    stag_free(b->m);
    for (int d = 0; d < 3; d++) {
        if (b->f[d] != b->q[d]) stag_free(b->f[d]); /* else q's storage (alloc_gridbuf()) */
        if (b->q2[d] != b->q[d]) stag_free(b->q2[d]);
        stag_free(b->q[d]);
    }
    memset(b, 0, sizeof *b);
}

/* fields: MPM_F_* of the buffer (m and q always); nn nodes and
 * MPM_GRID_SLACK more; slot: stag_alloc()'s.  shared: the one field of
 * fields (MPM_F_F or MPM_F_Q2, or 0 for none) that is given q's storage
 * instead of its own (mpm_sim.tshare). */
static int alloc_gridbuf(mpm_gridbuf *b, size_t nn, int dim, int fields, int shared, unsigned *slot)
{
    memset(b, 0, sizeof *b);
    nn += MPM_GRID_SLACK;
    if (!(b->m = stag_alloc(nn, slot))) return MPM_ENOMEM;
    for (int d = 0; d < dim; d++) {
        if (!(b->q[d] = stag_alloc(nn, slot))) return MPM_ENOMEM;
        if (fields & MPM_F_F) {
            b->f[d] = shared == MPM_F_F ? b->q[d] : stag_alloc(nn, slot);
            if (!b->f[d]) return MPM_ENOMEM;
        }
        if (fields & MPM_F_Q2) {
            b->q2[d] = shared == MPM_F_Q2 ? b->q[d] : stag_alloc(nn, slot);
            if (!b->q2[d]) return MPM_ENOMEM;
        }
    }
    return 0;
}

static void free_particles(mpm_particles *P)
{
    for (int d = 0; d < 3; d++) {
        stag_free(P->x[d]);
        stag_free(P->v[d]);
        stag_free(P->lp[d]);
    }
    for (int c = 0; c < 9; c++) stag_free(P->F[c]);
    for (int c = 0; c < 6; c++) {
        stag_free(P->sig[c]);
        stag_free(P->eps[c]);
    }
    for (int c = 0; c < 9; c++) stag_free(P->B[c]);
    stag_free(P->m);
    stag_free(P->vol);
    stag_free(P->epsp);
    stag_free(P->yld);
    stag_free(P->vol0);
    free(P->mat);
    free(P->id);
    memset(P, 0, sizeof *P);
}

/* What the case's models need (their rows' needs, OR-ed). */
static unsigned model_needs(const mpm_case *c)
{
    unsigned n = 0;
    for (size_t i = 0; i < c->n_materials; i++) {
        const mpm_material_model *m = mpm_material_model_of(c->materials[i].model);
        if (m) n |= m->needs;
    }
    return n;
}

/* Whether the case reads a deformation gradient per particle (P.F): the
 * one place that decides its allocation. */
static int mpm_needs_F(const mpm_case *c)
{
    return (mpm_method_props_of(c->method)->flags & MPM_METH_DOMAIN_F) ||
           c->volume_update == MPM_VOLUME_DET_F || (model_needs(c) & MPM_NEED_F);
}

/* Whether the particles keep a strain record P.eps (mpm_particles.h): the
 * plastic models' total strain (the elastic part follows from the stress,
 * the rest is plastic), and linear elasticity from an initial stress
 * (given or geostatic), where the strain energy 1/2 sigma : eps counts
 * strain from the initial state.  Otherwise nothing reads it: linear
 * elasticity's energy comes from the stress through the compliance, the
 * neo-Hookean's from F. */
static int needs_strain(const mpm_case *c)
{
    if (model_needs(c) & MPM_NEED_PLASTIC) return 1;
    for (size_t b = 0; b < c->n_bodies; b++)
        if (c->bodies[b].stress || c->bodies[b].geostatic) return 1;
    return 0;
}

/* Whether 2D particles store sigma_zz: unless every body's material is
 * linear elastic and there is no strain record, when it is nu (sigma_xx +
 * sigma_yy) (plane strain, from a zero stress) and nothing in the step
 * reads it (mpm_sig_zz()). */
static int needs_szz(const mpm_case *c)
{
    if (needs_strain(c)) return 1;
    for (size_t b = 0; b < c->n_bodies; b++)
        if (c->materials[c->bodies[b].material].model != MPM_MODEL_LINEAR_ELASTIC) return 1;
    return 0;
}

/* lp: the half-widths (GMPM, CPDI); F: the deformation gradient, set to I;
 * apic: the affine matrices B_p, set to 0; eps: the strain record; szz:
 * 2D's sigma_zz (needs_szz()) */
static int alloc_particles(mpm_particles *P, size_t n, int dim, int lp, int F, int apic, int eps,
                           int szz, unsigned *slot)
{
    memset(P, 0, sizeof *P);
    P->n = n;
    for (int d = 0; d < dim; d++) {
        if (!(P->x[d] = stag_alloc(n, slot)) || !(P->v[d] = stag_alloc(n, slot))) return MPM_ENOMEM;
        if (lp && !(P->lp[d] = stag_alloc(n, slot))) return MPM_ENOMEM;
    }
    for (int c = 0; F && c < dim * dim; c++) {
        if (!(P->F[c] = stag_alloc(n, slot))) return MPM_ENOMEM;
        if (c % (dim + 1) == 0)
            for (size_t p = 0; p < n; p++) P->F[c][p] = 1.0;
    }
    for (int c = 0; c < MPM_NCOMP(dim); c++) {
        if (dim == 2 && c == 2 && !szz) continue; /* derived (mpm_sig_zz()) */
        if (!(P->sig[c] = stag_alloc(n, slot))) return MPM_ENOMEM;
        if (eps && !(dim == 2 && c == 2) && !(P->eps[c] = stag_alloc(n, slot)))
            return MPM_ENOMEM; /* eps_zz = 0 */
    }
    for (int a = 0; a < dim && apic; a++)
        for (int b = 0; b < dim; b++)
            if (!(P->B[3 * a + b] = stag_alloc(n, slot))) return MPM_ENOMEM; /* B_p = 0 */
    if (!(P->m = stag_alloc(n, slot)) || !(P->vol = stag_alloc(n, slot))) return MPM_ENOMEM;
    if (!(P->mat = calloc(n ? n : 1, sizeof *P->mat))) return MPM_ENOMEM;
    if (!(P->id = malloc((n ? n : 1) * sizeof *P->id))) return MPM_ENOMEM;
    for (size_t p = 0; p < n; p++) P->id[p] = (uint32_t)p;
    return 0;
}

static void reset_out(mpm_thread_out *o)
{
    o->vmax2 = 0;
    o->bad = SIZE_MAX;
}

/* ---- phases ---- */

static void ph_p2g_mq(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    s->k->p2g_mq(s, mpm_scatter_buf(s, tid, MPM_F_M | MPM_F_Q), a, b);
}

static void ph_p2g_mqf(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    s->k->p2g_mqf(s, mpm_scatter_buf(s, tid, MPM_F_M | MPM_F_Q | MPM_F_F), a, b);
}

static void ph_p2g_q2(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    s->k->p2g_q2(s, mpm_scatter_buf(s, tid, MPM_F_Q2), a, b);
}

static void ph_stress_force(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    s->k->stress_force(s, mpm_scatter_buf(s, tid, MPM_F_F), &s->tout[tid], a, b, s->step_energy);
}

/* the fused passes' target of thread tid: NULL when the step does not
 * scatter the next one's fields (never when plan.fuse is off) */
static mpm_gridbuf *next_buf(mpm_sim *s, int tid)
{
    return s->fuse_next ? &s->tbuf[tid] : NULL;
}

static void ph_g2p_xv(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    reset_out(&s->tout[tid]);
    if (s->k->g2p_xv_nx)
        s->k->g2p_xv_nx(s, next_buf(s, tid), &s->tout[tid], a, b, s->step_energy);
    else
        s->k->g2p_xv(s, &s->tout[tid], a, b, s->step_energy);
}

static void ph_g2p_xv_stress(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    reset_out(&s->tout[tid]);
    if (s->k->g2p_xv_stress_nx)
        s->k->g2p_xv_stress_nx(s, next_buf(s, tid), &s->tout[tid], a, b, s->step_energy);
    else
        s->k->g2p_xv_stress(s, &s->tout[tid], a, b, s->step_energy);
}

static void ph_g2p_v(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    s->k->g2p_v(s, &s->tout[tid], a, b);
}

/* MUSL: the velocity update and the momentum q2 in one pass */
static void ph_g2p_v_q2(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    s->k->g2p_v_q2(s, mpm_scatter_buf(s, tid, MPM_F_Q2), a, b);
}

static void ph_g2p_x_stress(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    reset_out(&s->tout[tid]);
    if (s->k->g2p_x_stress_nx)
        s->k->g2p_x_stress_nx(s, next_buf(s, tid), &s->tout[tid], a, b, s->step_energy);
    else
        s->k->g2p_x_stress(s, &s->tout[tid], a, b, s->step_energy);
}

/* ---- the step on the team ----
 *
 * A step's passes run in one team phase, the threads meeting at a barrier
 * between passes (mpm_team_sync()); the point forces (tractions), scattered
 * serially into the main grid, split the node pass in two. */
/* the rate of momentum once reduced (gravity included): point forces,
 * BC2, then q += f dt */
static void forces_update(mpm_sim *s, int tid, int reduce_ops)
{
    int damp = s->damp_on ? MPM_N_DAMP : 0;
    if (!s->nload) {
        mpm_node_pass(s, tid, reduce_ops | MPM_N_BC2 | damp | MPM_N_UPD);
        return;
    }
    mpm_node_pass(s, tid, reduce_ops);
    mpm_team_sync(s);
    if (tid == 0) s->k->scatter_loads(s);
    mpm_team_sync(s);
    mpm_node_pass(s, tid, MPM_N_BC2 | damp | MPM_N_UPD);
}

/* The first scatter of a step, unless the last step's fused pass made it
 * (then its node pass zeroes thread 0's buffer, the last grid: MPM_N_Z0).
 * Returns the node pass's extra operation. */
static int first_scatter(mpm_sim *s, int tid, void (*p2g)(mpm_sim *, int))
{
    if (s->gnext) return MPM_N_Z0;
    p2g(s, tid);
    mpm_team_sync(s);
    return 0;
}

/* A step that sorts does so once its first scatter, fused into the last
 * step's moving pass or not, has been reduced (the sums of the threads'
 * buffers over the rows that scatter recorded): the order of the particles
 * only matters to the passes that follow, so the last step's moving pass
 * scatters the next step's fields in every step, a sort's too, and the
 * fused and unfused steps give the same bits.  The rows stay: they do not
 * depend on the order.  (The sort at the start of a step cost a pass: the
 * step before it could not scatter for it.) */
static void sort_after_first(mpm_sim *s, int tid)
{
    if (s->sort_now) mpm_sort_team(s, tid);
}

static void ph_step_usf(mpm_sim *s, int tid)
{
    int z0 = first_scatter(s, tid, ph_p2g_mq);
    mpm_node_pass(s, tid, MPM_F_M | MPM_F_Q | MPM_N_MINV | MPM_N_BC1 | z0);
    mpm_team_sync(s);
    sort_after_first(s, tid);
    ph_stress_force(s, tid);
    mpm_team_sync(s);
    forces_update(s, tid, MPM_F_F | MPM_N_GRAV);
    mpm_team_sync(s);
    ph_g2p_xv(s, tid);
}

static void ph_step_usl(mpm_sim *s, int tid)
{
    int z0 = first_scatter(s, tid, ph_p2g_mqf);
    forces_update(s, tid, MPM_F_M | MPM_F_Q | MPM_F_F | MPM_N_MINV | MPM_N_GRAV | MPM_N_BC1 | z0);
    mpm_team_sync(s);
    sort_after_first(s, tid);
    if (s->update == MPM_USL) {
        ph_g2p_xv_stress(s, tid);
        return;
    }
    if (s->k->g2p_v_q2) {
        ph_g2p_v_q2(s, tid);
    } else {
        ph_g2p_v(s, tid);
        mpm_team_sync(s);
        ph_p2g_q2(s, tid);
    }
    mpm_team_sync(s);
    /* BC1 on the recomputed momentum (and, gvel, q2/m in its place) */
    mpm_node_pass(s, tid, MPM_F_Q2 | MPM_N_BC1Q2 | MPM_N_VQ2);
    mpm_team_sync(s);
    ph_g2p_x_stress(s, tid);
}

/* Before a step: the active rows become those the last particle pass
 * recorded (mpm_rows_update()), and whether the step sorts the particles
 * (after its first scatter has been reduced: sort_after_first()).  A sort
 * comes MPM_SORT_EVERY steps after the last one, or sooner (but not within
 * MPM_SORT_MIN steps) when the particles' runs of one cell have fallen
 * apart: more than MPM_SORT_SPLIT times the cell changes along the
 * particles than the last sort left (runs0, mpm_sort_team()).  Particles that move together
 * cross cell lines together: the disks' lattice, at 2 x 2 per cell and
 * 1/32 of a cell per step, crosses every 16 steps, which left the runs at
 * one particle for half of the steps between fixed sorts (the gain is in
 * docs/performance.md).  CPDI's passes do not count
 * cells: its sorts stay every MPM_SORT_EVERY steps. */
static void begin_step(mpm_sim *s)
{
    mpm_rows_update(s);
    long since = s->steps - s->sort_last;
    s->sort_now = 0;
    if (s->steps == 0) return;
    if (!(mpm_method_props_of(s->method)->flags & MPM_METH_DOMAIN_F)) {
        size_t r = mpm_sort_cell_changes(s);
        s->sort_now = since >= MPM_SORT_MIN && r > MPM_SORT_SPLIT * s->runs0;
    }
    if (since >= MPM_SORT_EVERY) s->sort_now = 1;
    if (s->sort_now) s->sort_last = s->steps;
}

/* ---- creation ---- */

static double hmin(const mpm_sim *s)
{
    double h = s->h[0];
    for (int d = 1; d < s->dim; d++) h = fmin(h, s->h[d]);
    return h;
}

double mpm_sim_dt_limit(const mpm_sim *s)
{
    return hmin(s) / (s->cmax + s->vmax);
}

double mpm_case_cfl(const mpm_case *c)
{
    if (c->cfl > 0) return c->cfl;
    const mpm_method_props *mp = mpm_method_props_of(c->method);
    if (c->transfer == MPM_TRANSFER_APIC && mp && mp->apic_cfl > 0)
        return mp->apic_cfl; /* its stability limit (mpm.h) */
    return MPM_DEFAULT_CFL;
}

double mpm_case_dt_max(const mpm_case *c, const mpm_case_info *info)
{
    if (c->dt > 0) return c->dt;
    double h = c->grid.h[0];
    for (int d = 1; d < c->grid.dim; d++) h = fmin(h, c->grid.h[d]);
    return info->cmax > 0 ? mpm_case_cfl(c) * h / info->cmax : HUGE_VAL;
}

static void next_dt(mpm_sim *s)
{
    s->dt = s->dt_fixed > 0 ? s->dt_fixed : s->cfl * mpm_sim_dt_limit(s);
}

/* The kernel family of the case, chosen once per job. */
static const mpm_kernels *select_kernels(const mpm_sim *s)
{
    if (s->method == MPM_METHOD_CPDI) return mpm_cpdi_select(s->dim, s->pic != 0);
#ifdef MPM_HAVE_AVX2_KERNELS
    if (s->plan.avx2)
        return mpm_kernels_select_avx2(s->dim, s->plan.ns, s->bsp != 0, s->pic != 0,
                                       s->transfer == MPM_TRANSFER_APIC);
#endif
    return mpm_kernels_select(s->dim, s->plan.ns, s->bsp != 0, s->pic != 0,
                              s->transfer == MPM_TRANSFER_APIC);
}

/* The first box and the first sort, once the team runs. */
static void init_order(mpm_sim *s)
{
    mpm_team_run(s, mpm_ph_bbox);
    mpm_rows_update(s);
    mpm_sort_particles(s);
    mpm_team_run(s, mpm_ph_bbox);
    s->runs0 = mpm_sort_cell_changes(s);
}

/* The bounds lo[d] <= x < hi[d] of a particle centre, tightened to the
 * doubles whose cell coordinate r = (x - x0) inv_h, computed as the
 * kernels compute it, lies in [pad/2, last cell + 1): rounding could
 * otherwise put a centre just below hi in the cell past the last (its
 * support one node beyond the grid) or one just above lo in the cell below
 * the first ghost cell.  A step of at most a few ulps; nothing else moves. */
static void clamp_bounds(mpm_sim *s, int d, int nodes)
{
    double rlo = (double)(s->pad / 2), rhi = (double)(nodes - 1 + s->pad / 2 + s->pad);
    while ((s->lo[d] - s->x0[d]) * s->inv_h[d] < rlo) s->lo[d] = nextafter(s->lo[d], INFINITY);
    while ((s->hi[d] - s->x0[d]) * s->inv_h[d] >= rhi) s->hi[d] = nextafter(s->hi[d], -INFINITY);
}

/* An override's plan p against the defaults d it re-derived: 0, or
 * MPM_EINVAL naming the first key that cannot take its value (field
 * "plan.KEY"). */
static int plan_check(const mpm_sim *s, const mpm_plan *d, const mpm_plan *p, mpm_error *err)
{
    if (p->avx2 && (s->method == MPM_METHOD_CPDI || !mpm_kernels_avx2_available()))
        return mpm_fail(err, MPM_EINVAL, "plan.kernels", "avx2: %s",
                        s->method == MPM_METHOD_CPDI ? "CPDI has portable kernels only"
                                                     : "this build or CPU has no AVX2 kernels");
    if (p->ns != s->plan.ns) {
        if (s->method != MPM_METHOD_GIMP || (p->ns != 3 && p->ns != 4))
            return mpm_fail(err, MPM_EINVAL, "plan.ns", "%d: only GIMP chooses, 3 or 4 (is %d)",
                            p->ns, s->plan.ns);
        if (s->steps > 0) return mpm_fail(err, MPM_EINVAL, "plan.ns", "only before the first step");
        if (p->ns == 3 && !mpm_plan_gimp_fits3(s))
            return mpm_fail(err, MPM_EINVAL, "plan.ns", "3: a particle's lp exceeds h/2");
    }
    if (p->fuse > MPM_FUSE_ALWAYS)
        return mpm_fail(err, MPM_EINVAL, "plan.fuse", "off, auto or always");
    if (p->fuse != MPM_FUSE_OFF && (!s->k->g2p_xv_nx || !s->tbuf || !s->tbuf[0].m))
        return mpm_fail(err, MPM_EINVAL, "plan.fuse", "the family has no fused passes (CPDI)");
    if (p->el_lanes > d->el_lanes)
        return mpm_fail(err, MPM_EINVAL, "plan.el_lanes",
                        "%d: needs the AVX2 tents in 2D or 3D, one linear elastic material on "
                        "the direct path, no strain record, no spins and no sigma_zz array",
                        p->el_lanes);
    if (p->dp_lanes > d->dp_lanes)
        return mpm_fail(err, MPM_EINVAL, "plan.dp_lanes",
                        "%d: needs a Drucker-Prager material and AVX2 allowed (kernels not "
                        "PORTABLE, the CPU able)",
                        p->dp_lanes);
    if (p->sort_ring < 2 || (size_t)p->sort_ring > s->sort_cap ||
        (p->sort_ring & (p->sort_ring - 1)))
        return mpm_fail(err, MPM_EINVAL, "plan.sort_ring",
                        "%d: a power of 2 in [2, %zu] (the ring allocated)", p->sort_ring,
                        s->sort_cap);
    return 0;
}

int mpm_sim_plan_override(mpm_sim *s, const char *text, mpm_error *err)
{
    mpm_error_clear(err);
    if (!s) return mpm_fail(err, MPM_EINVAL, "plan", "no simulation");
    mpm_plan p = s->plan;
    unsigned given = 0;
    int rc = mpm_plan_parse(text, &p, &given, err);
    if (rc) return rc;
    /* the defaults of the instruction set and nodes per axis asked for
     * (the lanes' switches, fma and rows4 follow them), then the chosen
     * keys given over them */
    int allow = given & mpm_plan_key_bit("kernels") ? p.avx2 : s->avx2_ok;
    mpm_plan d = s->plan;
    d.ns = p.ns;
    mpm_plan_choose(s, allow, 1, &d);
    d.fuse = s->plan.fuse;
    d.sort_ring = s->plan.sort_ring;
    mpm_plan q = d;
    q.avx2 = p.avx2;
    if (given & mpm_plan_key_bit("fuse")) q.fuse = p.fuse;
    if (given & mpm_plan_key_bit("el_lanes")) q.el_lanes = p.el_lanes;
    if (given & mpm_plan_key_bit("dp_lanes")) q.dp_lanes = p.dp_lanes;
    if (given & mpm_plan_key_bit("sort_ring")) q.sort_ring = p.sort_ring;
    if ((rc = plan_check(s, &d, &q, err))) return rc;
    /* a derived key given: only with the value the plan has */
    for (unsigned b = 0; mpm_plan_key_name(b); b++) {
        const char *key = mpm_plan_key_name(b);
        if (!(given & (1u << b)) || mpm_plan_key_chosen(key)) continue;
        if (mpm_plan_value(&p, b) != mpm_plan_value(&q, b)) {
            char cur[MPM_PLAN_TEXT_MAX];
            mpm_plan_format(&q, cur, sizeof cur);
            return mpm_fail(err, MPM_EINVAL, "plan",
                            "%s follows from the case and the chosen keys: %s", key, cur);
        }
    }
    int reselect = q.avx2 != s->plan.avx2 || q.ns != s->plan.ns;
    if (q.fuse != s->plan.fuse) mpm_rows_drop_next(s);
    s->plan = q;
    s->avx2_ok = allow;
    if (reselect) {
        s->k = select_kernels(s);
        if (s->steps == 0) init_order(s);
    }
    return 0;
}

mpm_sim *mpm_sim_new(const mpm_case *c, const mpm_case_info *checked, mpm_error *err)
{
    mpm_case_info info;
    mpm_error_clear(err);
    if (!checked) {
        if (mpm_case_check(c, &info, err)) return NULL;
        checked = &info;
    } else if (c->threads < 0 || c->threads > MPM_MAX_THREADS) {
        mpm_fail(err, MPM_EINVAL, "threads", "must be in [0, %d] (got %d)", MPM_MAX_THREADS,
                 c->threads);
        return NULL;
    } else if (mpm_kernels_check(c->kernels, err)) {
        return NULL;
    }
    size_t np = checked->particles;

    mpm_sim *s = calloc(1, sizeof *s);
    if (!s) goto nomem;
    int dim = s->dim = c->grid.dim;
    s->method = c->method;
    s->update = c->update;
    const mpm_method_props *mp = mpm_method_props_of(c->method);
    s->bsp = mp->bspline;
    s->pad = mp->ghost;
    s->nthreads = c->threads > 1 ? c->threads : 1;
    atomic_init(&s->cancel, 0);
    s->nn = 1;
    for (int d = 0; d < 3; d++) {
        /* B-splines: n cells, n + 2 control points (BSPLINE2) or the
         * n + 1 nodes of the natural end basis (BSPLINE3); no ghost layers */
        s->nreal[d] = d < dim ? c->grid.nodes[d] + (s->bsp == 2 ? 1 : 0) : 1;
        s->np[d] = d < dim ? s->nreal[d] + 2 * s->pad : 1;
        s->stride[d] = s->nn;
        s->nn *= (size_t)s->np[d];
        s->h[d] = d < dim ? c->grid.h[d] : 1;
        s->inv_h[d] = 1.0 / s->h[d];
        /* node 0 of the padded grid sits pad cells below the origin */
        s->x0[d] = d < dim ? c->grid.origin[d] - s->pad * s->h[d] : 0;
        /* a GMPM centre may enter the first ghost cell (see mpm_bc_build()) */
        s->lo[d] = d < dim ? c->grid.origin[d] - (s->pad / 2) * s->h[d] : 0;
        s->hi[d] = d < dim ? c->grid.origin[d] + (c->grid.nodes[d] - 1 + s->pad / 2) * s->h[d] : 0;
        if (d < dim) clamp_bounds(s, d, c->grid.nodes[d]);
        /* B-splines: the last cell is nodes - 2 (bs_axis() clamps to it) */
        s->rmax[d] = s->bsp && d < dim ? (double)(c->grid.nodes[d] - 2) : (double)(s->np[d] - 1);
        if (s->bsp) mpm_bspline_axis_init(&s->bs[d], s->bsp, d < dim ? c->grid.nodes[d] - 1 : 1);
    }
    s->model = mpm_model_get(c->materials[0].model);
    s->nmat = c->n_materials;
    if (!(s->mats = calloc(s->nmat, sizeof *s->mats))) goto nomem;
    if (!(s->mdesc = malloc(s->nmat * sizeof *s->mdesc))) goto nomem;
    memcpy(s->mdesc, c->materials, s->nmat * sizeof *s->mdesc);
    for (size_t i = 0; i < s->nmat; i++) {
        mpm_model_params(&c->materials[i], dim, &s->mats[i]);
        if (s->mats[i].c > s->cmax) s->cmax = s->mats[i].c;
        if (s->mats[i].ops != s->model) s->mixed = 1;
        if (mpm_material_model_of(c->materials[i].model)->needs & MPM_NEED_INTEGRATOR)
            s->frictional = 1;
    }
    if (s->frictional) {
        if (!(s->plp = calloc(s->nmat, sizeof *s->plp))) goto nomem;
        for (size_t i = 0; i < s->nmat; i++) {
            if (!(mpm_material_model_of(c->materials[i].model)->needs & MPM_NEED_INTEGRATOR))
                continue;
            if (mpm_model_plastic(&c->materials[i], dim, i, &s->plp[i], err)) goto fail;
            s->mats[i].pl = &s->plp[i];
        }
    }
    /* the block update's path, once per job (mpm_pass.h block_update()) */
    unsigned needs = model_needs(c);
    s->volmode = c->volume_update;
    s->f_block = mpm_needs_F(c) && !(mp->flags & MPM_METH_DOMAIN_F);
    s->spin3 = dim == 3 && ((needs & MPM_NEED_SPIN) || s->f_block);

    int musl = c->update == MPM_MUSL;
    s->transfer = c->transfer;
    if (alloc_particles(&s->P, np, dim, (mp->flags & MPM_METH_HALF_WIDTHS) != 0, mpm_needs_F(c),
                        c->transfer == MPM_TRANSFER_APIC, needs_strain(c), needs_szz(c), &s->stag))
        goto nomem;
    if ((needs & MPM_NEED_PLASTIC) &&
        (!(s->P.epsp = stag_alloc(np, &s->stag)) || !(s->P.yld = stag_alloc(np, &s->stag))))
        goto nomem;
    if (s->volmode == MPM_VOLUME_DET_F && !(s->P.vol0 = stag_alloc(np, &s->stag))) goto nomem;
    if (mpm_case_fill(c, &s->P, s->mats, &s->vmax, err)) goto fail;
    if (s->P.vol0) memcpy(s->P.vol0, s->P.vol, np * sizeof *s->P.vol0);
    s->pic = c->pic_fraction;
    /* the plan: the fast paths, from the case and the CPU, once */
    s->avx2_ok = c->kernels != MPM_KERNELS_PORTABLE && mpm_kernels_avx2_available();
    mpm_plan_choose(s, s->avx2_ok, 0, &s->plan);
    /* dispatch: the REFERENCE family turns the plan's fast paths off */
    if (c->kernel_family == MPM_KERNEL_FAMILY_REFERENCE) mpm_ref_init(s);
    s->k = select_kernels(s);
    s->gvel = !(mp->flags & MPM_METH_DOMAIN_F) && !s->ref;
    if (!(s->sperm = malloc((np ? np : 1) * sizeof *s->sperm)) ||
        !(s->shist = calloc(s->nn + 1, sizeof *s->shist)))
        goto nomem;
    int gfields = MPM_F_M | MPM_F_Q | MPM_F_F | (musl ? MPM_F_Q2 : 0);
    if (alloc_gridbuf(&s->g, s->nn, dim, gfields, 0, &s->stag)) goto nomem;
    if (!(s->minv = stag_alloc(s->nn + MPM_GRID_SLACK, &s->stag))) goto nomem;
    for (int d = 0; d < 3; d++) {
        if (!(s->ncoord[d] = mpm_dalloc((size_t)s->np[d]))) goto nomem;
        for (int i = 0; d < dim && i < s->np[d]; i++)
            s->ncoord[d][i] = mpm_node_coord_calc(s, d, i);
    }
    s->p2g_fields = MPM_F_M | MPM_F_Q | (c->update == MPM_USF ? 0 : MPM_F_F);
    s->tshare = c->update == MPM_USF ? MPM_F_F : musl ? MPM_F_Q2 : 0;
    int fuse = s->plan.fuse != MPM_FUSE_OFF;
    if (s->nthreads > 1 || fuse) {
        if (!(s->tbuf = calloc((size_t)s->nthreads, sizeof *s->tbuf))) goto nomem;
        /* thread 0 scatters into the grid, and the fused passes into
         * tbuf[0] (the P2G fields) */
        if (fuse && alloc_gridbuf(&s->tbuf[0], s->nn, dim, s->p2g_fields, 0, &s->stag)) goto nomem;
        for (int t = 1; t < s->nthreads; t++)
            if (alloc_gridbuf(&s->tbuf[t], s->nn, dim, gfields, s->tshare, &s->stag)) goto nomem;
    }
    if (!(s->tout = calloc((size_t)s->nthreads, sizeof *s->tout))) goto nomem;
    s->sort_cap = (size_t)s->plan.sort_ring;
    for (int t = 0; t < s->nthreads; t++)
        if (!(s->tout[t].rval = malloc(s->sort_cap * sizeof *s->tout[t].rval)) ||
            !(s->tout[t].rtag = malloc(s->sort_cap * sizeof *s->tout[t].rtag)))
            goto nomem;
    for (int t = 0; t < s->nthreads; t++) {
        s->tout[t].plbad = SIZE_MAX;
        for (int cc = 0; cc < 9; cc++)
            if (!(s->tout[t].deps[cc] = line_alloc(MPM_BLOCK * sizeof(double)))) goto nomem;
    }
    for (int t = 0; t < s->nthreads; t++)
        if (!(s->tout[t].wblk =
                  line_alloc(mpm_kernels_scratch() > mpm_cpdi_scratch() ? mpm_kernels_scratch()
                                                                        : mpm_cpdi_scratch())))
            goto nomem;
    if (mpm_rows_init(s)) goto nomem; /* row extents, all empty */

    if (mpm_bc_build(s, &c->bc)) goto nomem;
    if (mpm_cond_build(s, c)) goto nomem;
    if (mpm_loads_build(s, c)) goto nomem;
    for (int d = 0; d < dim; d++) {
        s->gravity[d] = c->gravity[d];
        s->has_gravity |= c->gravity[d] != 0;
    }
    double msum = 0;
    for (size_t p = 0; p < s->P.n; p++) msum += s->P.m[p];
    s->mtol = (c->mass_tol > 0 ? c->mass_tol : MPM_DEFAULT_MASS_TOL) * msum / (double)s->P.n;
    s->dt_fixed = c->dt;
    s->cfl = mpm_case_cfl(c);
    next_dt(s);
    s->damp = c->damping;
    s->damp_coef = c->damping_coef;
    s->damp_until = c->damping_until;
    s->budget = c->energy_budget;
    s->fail_on_budget = c->fail_on_budget;
    mpm_energy e0;
    mpm_sim_energy(s, &e0);
    double u0 = mpm_initial_stress_energy(s);
    s->e_total0 = e0.total + 2 * u0;
    s->e_floor = 1e-9 * 0.5 * e0.mass * s->cmax * s->cmax;
    s->bal_total0 = e0.total;
    s->bal_pot0 = e0.potential;
    s->bal_ref0 = e0.kinetic + fabs(e0.strain) + u0;
    s->bal_last = s->bal_worst = 0;
    s->guard_v2 = s->vmax * s->vmax;
    if (mpm_team_start(s)) goto nomem;
    if (!s->ref) init_order(s); /* the REFERENCE family never sorts */
    return s;

nomem:
    mpm_fail(err, MPM_ENOMEM, NULL, "out of memory building a case of %zu particles", np);
fail:
    mpm_sim_destroy(&s);
    return NULL;
}

void mpm_sim_destroy(mpm_sim **sp)
{
    mpm_sim *s = sp ? *sp : NULL;
    if (!s) return;
    mpm_team_stop(s);
    free_particles(&s->P);
    free_gridbuf(&s->g);
    if (s->tbuf)
        for (int t = 0; t < s->nthreads; t++) free_gridbuf(&s->tbuf[t]);
    free(s->tbuf);
    if (s->tout)
        for (int t = 0; t < s->nthreads; t++)
            for (int c = 0; c < 9; c++) free(s->tout[t].deps[c]);
    if (s->tout)
        for (int t = 0; t < s->nthreads; t++) {
            free(s->tout[t].wblk);
            free(s->tout[t].rlo);
            free(s->tout[t].rhi);
            free(s->tout[t].rval);
            free(s->tout[t].rtag);
        }
    free(s->ulo);
    free(s->uhi);
    free(s->rowoff);
    free(s->acc);
    free(s->wacc);
    free(s->sperm);
    free(s->shist);
    free(s->tout);
    stag_free(s->minv);
    for (int d = 0; d < 3; d++) free(s->ncoord[d]);
    free(s->mats);
    free(s->mdesc);
    free(s->fixed_node);
    free(s->fixed_mask);
    mpm_cond_free(s);
    free(s->load_p);
    for (int d = 0; d < 3; d++) {
        free(s->load_f[d]);
        free(s->load_xold[d]);
        free(s->trac_f[d]);
        free(s->load_f0[d]);
        free(s->tv_f[d]);
    }
    free(s->tv_slot);
    free(s->tv_trac);
    for (size_t t = 0; s->trac_tf && t < s->ntrac; t++) mpm_timefn_copy_free(&s->trac_tf[t]);
    free(s->trac_tf);
    free(s->plp);
    free(s);
    *sp = NULL;
}

/* ---- the step ---- */

static int finish_step(mpm_sim *s)
{
    size_t bad = SIZE_MAX;
    double v2 = 0;
    for (int t = 0; t < s->nthreads; t++) {
        if (s->tout[t].bad < bad) bad = s->tout[t].bad;
        if (s->tout[t].vmax2 > v2) v2 = s->tout[t].vmax2;
    }
    long step = s->steps + 1;
    double t = s->t + s->dt;
    if (bad != SIZE_MAX) {
        int finite = 1, axis = -1;
        char pos[128] = "", *w = pos;
        for (int d = 0; d < s->dim; d++) {
            double x = s->P.x[d][bad];
            finite &= isfinite(x) && isfinite(s->P.v[d][bad]);
            if (!(x >= s->lo[d] && x < s->hi[d])) axis = d;
            w += snprintf(w, sizeof pos - (size_t)(w - pos), "%s%.9g", d ? ", " : "", x);
        }
        if (finite && axis < 0) { /* CPDI: the centre is in, a corner is not */
            s->failed = mpm_fail(&s->err, MPM_ELEFTGRID, NULL,
                                 "particle %zu's domain left the grid or turned inside out at "
                                 "step %ld, time %.9g: centre (%s); with CPDI every corner "
                                 "x_p +- F r_0 must stay within one cell of the grid and det F > 0",
                                 (size_t)s->P.id[bad], step, t, pos);
        } else if (!finite) {
            s->failed = mpm_fail(&s->err, MPM_EDIVERGED, NULL,
                                 "diverged at step %ld, time %.9g: particle %zu has a non-finite "
                                 "position or velocity",
                                 step, t, (size_t)s->P.id[bad]);
        } else {
            s->failed = mpm_fail(&s->err, MPM_ELEFTGRID, NULL,
                                 "particle %zu left the grid at step %ld, time %.9g: position "
                                 "(%s), %c outside [%g, %g) (a body pulled apart sheds particles "
                                 "so: which methods carry tension to large stretch is in "
                                 "docs/accuracy.md, \"Large stretch\")",
                                 (size_t)s->P.id[bad], step, t, pos, "xyz"[axis], s -> lo[axis],
                                 s -> hi[axis]);
        }
        return s->failed;
    }
    mpm_loads_end_step(s);
    if (s->has_cond) mpm_cond_end_step(s);
    if (s->damp_on)
        for (int th = 0; th < s->nthreads; th++) { /* in thread order */
            s->damping_work += s->tout[th].edamp;
            s->tout[th].edamp = 0;
        }
    s->vmax = sqrt(v2);
    s->t = t;
    s->steps = step;
    /* every MPM_GUARD_EVERY steps, and at once when the largest speed
     * has grown by sqrt(2) since the last check (a fast blow-up) */
    if ((step % MPM_GUARD_EVERY == 0 || v2 > 2 * s->guard_v2) && mpm_guard(s)) return s->failed;
    next_dt(s);
    return 0;
}

/* The frictional models' counters of the step, in thread order; a failed
 * stress-point update fails the run (MPM_EDIVERGED, naming the particle
 * and its material).  Returns s->failed. */
static int frictional_end_step(mpm_sim *s)
{
    size_t bad = SIZE_MAX;
    for (int t = 0; t < s->nthreads; t++) {
        mpm_thread_out *o = &s->tout[t];
        s->plstats.updates += o->plupd;
        s->plstats.substeps += o->plsub;
        if (o->plmax > s->plstats.max_substeps) s->plstats.max_substeps = o->plmax;
        if (o->plbad < bad) bad = o->plbad;
        o->plupd = o->plsub = 0;
        o->plmax = 0;
        o->plbad = SIZE_MAX;
    }
    if (bad != SIZE_MAX) {
        unsigned m = s->P.mat[bad];
        const mpm_plastic_params *pl = s->mats[m].pl;
        s->failed = mpm_fail(
            &s->err, MPM_EDIVERGED, NULL,
            "diverged at step %ld, time %.9g: the %s update of particle %zu (materials[%u]) "
            "failed: %s",
            s->steps + 1, s->t + s->dt, mpm_material_model_of(s->mdesc[m].model)->name,
            (size_t)s->P.id[bad], m,
            pl->kind == MPM_PLASTIC_DRUCKER_PRAGER
                ? "Sloan's substepping exhausted its substeps or met a non-finite stress (a "
                  "strain increment of about a thousand yield strains; reduce dt or raise "
                  "substep_tolerance)"
                : "a non-finite trial stress");
    }
    return s->failed;
}

void mpm_sim_plastic_stats(const mpm_sim *s, mpm_plastic_stats *out)
{
    *out = s->plstats;
}

int mpm_sim_step(mpm_sim *s)
{
    if (s->failed) return MPM_ESTATE;
    s->ecache_ok = 0; /* the particles change (and may be reordered) */
    begin_step(s);
    if (s->ntv) mpm_loads_update(s);
    if (s->has_cond) mpm_cond_begin_step(s);
    mpm_loads_begin_step(s);
    /* energies wanted: the passes that write each particle field for the
     * last time in the step sum them (s->step_energy, read once per pass:
     * USF stress_force and g2p_xv, USL g2p_xv_stress, MUSL g2p_x_stress).
     * A step that ends with the guard's check sums them too: in the
     * passes they cost less than the guard's own pass over the particles,
     * and they are the same sums (mpm_guard() takes them from ecache) */
    s->step_energy = s->want_energy || (s->steps + 1) % MPM_GUARD_EVERY == 0;
    s->want_energy = 0;
    s->damp_on = s->damp != MPM_DAMPING_NONE && (!(s->damp_until > 0) || s->t < s->damp_until);
    /* fused: the step starts with the grid the last one scattered, and
     * scatters the next one's (a sort comes after that scatter) */
    if (s->gnext) mpm_rows_swap_next(s);
    s->fuse_next =
        s->plan.fuse == MPM_FUSE_ALWAYS || (s->plan.fuse == MPM_FUSE_AUTO && s->fuse_pays);
    s->gvel_now = 0;
    if (s->ref) {           /* dispatch: the REFERENCE family's step (mpm_ref.c) */
        s->step_energy = 0; /* it sums no energies in its passes */
        mpm_ref_step(s);
    } else {
        mpm_team_run(s, s->update == MPM_USF ? ph_step_usf : ph_step_usl);
    }
    s->gvel_now = s->gvel;
    s->gnext = s->fuse_next;
    if (s->plan.general) /* the plastic work of the step, in thread order */
        for (int t = 0; t < s->nthreads; t++) {
            s->plastic_work += s->tout[t].wplast;
            s->tout[t].wplast = 0;
        }
    if (s->step_energy) {
        s->step_energy = 0;
        mpm_energy_sum(s, &s->ecache);
        s->ecache_ok = 1; /* the particles as they are now, even if the step failed */
    }
    if (s->frictional && frictional_end_step(s)) return s->failed;
    return finish_step(s);
}

void mpm_sim_want_energy(mpm_sim *s)
{
    s->want_energy = 1;
}

int mpm_sim_check(mpm_sim *s)
{
    if (s->failed) return s->failed;
    return mpm_guard(s);
}

int mpm_sim_run(mpm_sim *s, long nsteps)
{
    for (long i = 0; i < nsteps; i++) {
        if (atomic_load_explicit(&s->cancel, memory_order_relaxed)) {
            atomic_store(&s->cancel, 0);
            return mpm_fail(&s->err, MPM_ECANCELLED, NULL, "cancelled at step %ld, time %.9g",
                            s->steps, s->t);
        }
        int rc = mpm_sim_step(s);
        if (rc) return rc;
    }
    return 0;
}

int mpm_sim_set_particle_forces(mpm_sim *s, const double *f)
{
#ifdef MPM_LEAN
    if (f)
        return mpm_fail(&s->err, MPM_EINVAL, "particle_forces",
                        "this solver was built with MPM_LEAN (no gravity, loads or fixed "
                        "boundaries)");
#endif
    size_t n = s->P.n * (size_t)s->dim;
    char path[64];
    if (s->ntv)
        return mpm_fail(&s->err, MPM_EINVAL, "particle_forces",
                        "not available in a case whose tractions have time functions");
    if (f)
        for (size_t i = 0; i < n; i++)
            if (!isfinite(f[i])) {
                snprintf(path, sizeof path, "particle_forces[%zu]", i);
                return mpm_fail(&s->err, MPM_EINVAL, path, "must be finite (got %g)", f[i]);
            }
    if (mpm_loads_set_forces(s, f))
        return mpm_fail(&s->err, MPM_ENOMEM, NULL, "out of memory for %zu particle forces", s->P.n);
    return 0;
}

void mpm_sim_cancel(mpm_sim *s)
{
    atomic_store(&s->cancel, 1);
}

/* ---- results ---- */

long mpm_sim_steps(const mpm_sim *s)
{
    return s->steps;
}
double mpm_sim_time(const mpm_sim *s)
{
    return s->t;
}
double mpm_sim_dt(const mpm_sim *s)
{
    return s->dt;
}
size_t mpm_sim_particles(const mpm_sim *s)
{
    return s->P.n;
}
int mpm_sim_dim(const mpm_sim *s)
{
    return s->dim;
}
const char *mpm_sim_kernels(const mpm_sim *s)
{
    return s->ref ? "reference" : s->plan.avx2 ? "avx2-fma" : "portable";
}
int mpm_sim_plan(const mpm_sim *s, char *buf, size_t n)
{
    return mpm_plan_format(&s->plan, buf, n);
}
const mpm_error *mpm_sim_error(const mpm_sim *s)
{
    return &s->err;
}

size_t mpm_sim_nodes(const mpm_sim *s)
{
    size_t n = 1;
    for (int d = 0; d < s->dim; d++) n *= (size_t)s->nreal[d];
    return n;
}

/* On the thread team (mpm_ph_energy()), partial sums combined in thread order:
 * reproducible for a given thread count; or, when the last step was asked
 * to (mpm_sim_want_energy()), the same sums that step made in its passes.  The team's scratch
 * (tout) is written, nothing of the simulation's state; the object was not defined const, so the
 * cast is sound, and the team is idle between steps. */
void mpm_sim_energy(const mpm_sim *cs, mpm_energy *e)
{
    mpm_sim *s = (mpm_sim *)cs;
    if (s->ecache_ok) { /* summed by the last step (mpm_sim_want_energy()) */
        *e = s->ecache;
    } else {
        if (s->threads) {
            mpm_team_run(s, mpm_ph_energy);
        } else { /* during creation, before the team starts: the same slices */
            for (int t = 0; t < s->nthreads; t++) mpm_ph_energy(s, t);
        }
        mpm_energy_sum(s, e);
    }
    mpm_energy_finish(s, e);
    s->bal_last = e->balance_error;
    if (e->balance_error > s->bal_worst) s->bal_worst = e->balance_error;
}

void mpm_sim_energy_sample(const mpm_sim *sim, mpm_energy_sample *out)
{
    memset(out, 0, sizeof *out);
    out->step = sim->steps;
    out->t = sim->t;
    out->dim = sim->dim;
    mpm_sim_energy(sim, &out->e);
}

/* The particles [a, b) of a snapshot into o, each at its creation
 * number's place (slot p holds the particle created as number P->id[p]). */
static void snapshot_slice(const mpm_sim *s, const mpm_snapshot *o, size_t a, size_t b)
{
    const mpm_particles *P = &s->P;
    int dim = s->dim;
    for (size_t p = a; p < b; p++) {
        size_t q = P->id[p];
        for (int d = 0; d < dim; d++) {
            if (o->x) o->x[q * dim + d] = P->x[d][p];
            if (o->v) o->v[q * dim + d] = P->v[d][p];
        }
        double sig[6];
        mpm_particle_stress(&s->mats[P->mat[p]], P, dim, p, sig);
        if (o->stress)
            for (int c = 0; c < 6; c++) o->stress[q * 6 + c] = sig[c];
        if (o->mean_stress) {
            double tr = sig[0];
            if (dim > 1) tr += sig[1] + sig[2];
            o->mean_stress[q] = tr / 3.0;
        }
        if (o->volume) o->volume[q] = P->vol[p];
        if (o->plastic_strain && P->epsp) o->plastic_strain[q] = P->epsp[p];
        if (o->yielded && P->yld) o->yielded[q] = P->yld[p] != 0.0;
        if (o->deformation_gradient && P->F[0])
            for (int c = 0; c < dim * dim; c++)
                o->deformation_gradient[q * (size_t)(dim * dim) + (size_t)c] = P->F[c][p];
    }
}

static void ph_snapshot(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    snapshot_slice(s, s->snap_out, a, b);
}

/* On the thread team, each thread its slice of the particles (they write
 * disjoint entries of o: the creation numbers are a permutation), so a
 * snapshot of 10^6 particles takes the solver's threads, not the caller's
 * one alone; the values are copies, the same whatever the threads.  The
 * team is idle between steps and only snap_out is written (the object was
 * not defined const: the cast is sound, as in mpm_sim_energy()). */
void mpm_sim_snapshot(const mpm_sim *cs, const mpm_snapshot *o)
{
    mpm_sim *s = (mpm_sim *)cs;
    if (!s->threads || s->nthreads < 2) {
        snapshot_slice(s, o, 0, s->P.n);
        return;
    }
    s->snap_out = o;
    mpm_team_run(s, ph_snapshot);
    s->snap_out = NULL;
}

int mpm_case_has_field(const mpm_case *c, mpm_field f)
{
    switch (f) {
    case MPM_FIELD_PLASTIC_STRAIN:
    case MPM_FIELD_YIELDED: return (model_needs(c) & MPM_NEED_PLASTIC) != 0;
    case MPM_FIELD_DEFORMATION_GRADIENT: return mpm_needs_F(c);
    }
    return 0;
}

int mpm_sim_has_field(const mpm_sim *s, mpm_field f)
{
    switch (f) {
    case MPM_FIELD_PLASTIC_STRAIN: return s->P.epsp != NULL;
    case MPM_FIELD_DEFORMATION_GRADIENT: return s->P.F[0] != NULL;
    case MPM_FIELD_YIELDED: return s->P.yld != NULL;
    }
    return 0;
}

void mpm_sim_node(const mpm_sim *s, const int ijk[3], double *mass, double q[MPM_MAX_DIM])
{
    size_t n = mpm_node_index(s, ijk);
    if (mass) *mass = s->g.m[n];
    /* a grid of velocities (gvel_now): m v, 0 at phantom nodes */
    for (int d = 0; d < MPM_MAX_DIM; d++)
        q[d] = d >= s->dim   ? 0.0
               : s->gvel_now ? (s->minv[n] != 0.0 ? s->g.m[n] * s->g.q[d][n] : 0.0)
                             : s->g.q[d][n];
}
