/*
 * mpm_sim.c - a simulation: creation from a case, the explicit step, and
 * the results API.
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
 * them), the sort keys and
 * the sort's permutation run on the team too, sums combined in thread
 * order.  The
 * same case with the same thread count is therefore bitwise reproducible;
 * a different thread count changes the order of the sums and so the last
 * bits.  Nothing is allocated inside a step.
 *
 * Cost and memory follow the particles, not the grid: the particle passes
 * record, row by row (a row: the nodes along x at fixed y, z), the extent
 * of nodes their supports touch, and zeroing, reduction, node updates and
 * boundary conditions run over those extents only (the grid outside them
 * stays zero, and pages of the grids that no particle reaches are never
 * touched).  Particles are kept sorted by cell (every MPM_SORT_EVERY steps, a
 * stable counting sort, skipped when the keys are in order already), with
 * P.id mapping storage slots to creation order
 * for everything public.  Built with -DMPM_LEAN, gravity, loads and fixed
 * boundaries are compiled out and cases using them are refused.
 */
#include "mpm_internal.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- allocation helpers ---- */

static double *dalloc(size_t n)
{
    return calloc(n ? n : 1, sizeof(double));
}

/* Zeroed scratch of whole cache lines of its own: the threads' scratch
 * blocks, written all through a pass, share no line (no false sharing). */
static void *line_alloc(size_t bytes)
{
    size_t n = (bytes + 63) / 64 * 64;
    void *p = aligned_alloc(64, n ? n : 64);
    if (p) memset(p, 0, n ? n : 64);
    return p;
}

static void free_gridbuf(mpm_gridbuf *b)
{
    free(b->m);
    for (int d = 0; d < 3; d++) {
        free(b->q[d]);
        free(b->f[d]);
        free(b->q2[d]);
    }
    memset(b, 0, sizeof *b);
}

static int alloc_gridbuf(mpm_gridbuf *b, size_t nn, int dim, int musl)
{
    memset(b, 0, sizeof *b);
    if (!(b->m = dalloc(nn))) return MPM_ENOMEM;
    for (int d = 0; d < dim; d++) {
        if (!(b->q[d] = dalloc(nn)) || !(b->f[d] = dalloc(nn))) return MPM_ENOMEM;
        if (musl && !(b->q2[d] = dalloc(nn))) return MPM_ENOMEM;
    }
    return 0;
}

static void free_particles(mpm_particles *P)
{
    for (int d = 0; d < 3; d++) {
        free(P->x[d]);
        free(P->v[d]);
        free(P->lp[d]);
    }
    for (int c = 0; c < 6; c++) {
        free(P->sig[c]);
        free(P->eps[c]);
    }
    free(P->m);
    free(P->vol);
    free(P->mat);
    free(P->id);
    memset(P, 0, sizeof *P);
}

static int alloc_particles(mpm_particles *P, size_t n, int dim, int gimp)
{
    memset(P, 0, sizeof *P);
    P->n = n;
    for (int d = 0; d < dim; d++) {
        if (!(P->x[d] = dalloc(n)) || !(P->v[d] = dalloc(n))) return MPM_ENOMEM;
        if (gimp && !(P->lp[d] = dalloc(n))) return MPM_ENOMEM;
    }
    for (int c = 0; c < MPM_NCOMP(dim); c++) {
        if (!(P->sig[c] = dalloc(n))) return MPM_ENOMEM;
        if (!(dim == 2 && c == 2) && !(P->eps[c] = dalloc(n))) return MPM_ENOMEM; /* eps_zz = 0 */
    }
    if (!(P->m = dalloc(n)) || !(P->vol = dalloc(n))) return MPM_ENOMEM;
    if (!(P->mat = calloc(n ? n : 1, sizeof *P->mat))) return MPM_ENOMEM;
    if (!(P->id = malloc((n ? n : 1) * sizeof *P->id))) return MPM_ENOMEM;
    for (size_t p = 0; p < n; p++) P->id[p] = (uint32_t)p;
    return 0;
}

/* ---- the thread team ---- */

typedef void (*phase_fn)(mpm_sim *, int tid);

static void slice(size_t n, int T, int tid, size_t *a, size_t *b)
{
    *a = n * (size_t)tid / (size_t)T;
    *b = n * (size_t)(tid + 1) / (size_t)T;
}

typedef struct {
    mpm_sim *s;
    int tid;
} worker_arg;

static void *worker(void *arg)
{
    worker_arg wa = *(worker_arg *)arg;
    mpm_sim *s = wa.s;
    free(arg);
    /* the gate opens (1) once every thread exists, or aborts (-1) */
    pthread_mutex_lock(&s->gate_mu);
    while (s->gate == 0) pthread_cond_wait(&s->gate_cv, &s->gate_mu);
    int go = s->gate > 0;
    pthread_mutex_unlock(&s->gate_mu);
    if (!go) return NULL;
    for (;;) {
        pthread_barrier_wait(&s->bar_start);
        if (s->quit) break;
        s->phase(s, wa.tid);
        pthread_barrier_wait(&s->bar_end);
    }
    return NULL;
}

static void run(mpm_sim *s, phase_fn fn)
{
    if (s->nthreads == 1) {
        fn(s, 0);
        return;
    }
    s->phase = fn;
    pthread_barrier_wait(&s->bar_start);
    fn(s, 0);
    pthread_barrier_wait(&s->bar_end);
}

/* ---- the active rows ----
 *
 * Particle passes scatter only into the nodes their supports touch, and
 * record them row by row (a row: the nodes along x at fixed y, z): each
 * thread zeroes its private grid over its own rows' extents before
 * scattering, node passes run over the extents of the union (the rows of
 * the union box split among the threads), and the main grid outside the
 * union's extents is kept all zero.  The cost of a step, and the pages of
 * the grids ever touched, follow the particles, not the grid. */

/* rows (y, z) of box lo..hi (inclusive); 0 when empty */
static size_t box_rows(const int lo[3], const int hi[3])
{
    if (lo[0] > hi[0] || lo[1] > hi[1] || lo[2] > hi[2]) return 0;
    return (size_t)(hi[1] - lo[1] + 1) * (size_t)(hi[2] - lo[2] + 1);
}

/* row index (y + z np[1]) of row r of box lo..hi */
static size_t box_row(const mpm_sim *s, const int lo[3], const int hi[3], size_t r)
{
    size_t ny = (size_t)(hi[1] - lo[1] + 1);
    size_t y = (size_t)lo[1] + r % ny, z = (size_t)lo[2] + r / ny;
    return y + z * (size_t)s->np[1];
}

/* flat index of node x of row `row` */
static size_t row_node(const mpm_sim *s, size_t row, int x)
{
    return row * (size_t)s->np[0] + (size_t)x;
}

/* Zeroes a thread's private field over the extents of its rows. */
static void zero_rows(const mpm_sim *s, double *a, const mpm_thread_out *o)
{
    size_t nr = box_rows(o->blo, o->bhi);
    for (size_t r = 0; r < nr; r++) {
        size_t row = box_row(s, o->blo, o->bhi, r);
        int lo = o->rlo[row], hi = o->rhi[row];
        if (lo <= hi) memset(a + row_node(s, row, lo), 0, (size_t)(hi - lo + 1) * sizeof *a);
    }
}

/* the grid fields in use, as a list */
static int grid_fields(const mpm_sim *s, const mpm_gridbuf *b, double **out)
{
    int k = 0;
    out[k++] = b->m;
    for (int d = 0; d < s->dim; d++) {
        out[k++] = b->q[d];
        out[k++] = b->f[d];
        if (b->q2[d]) out[k++] = b->q2[d];
    }
    return k;
}

/* box lo..hi = the union of the threads' boxes (clamped when recorded) */
static void union_box(const mpm_sim *s, int lo[3], int hi[3])
{
    for (int d = 0; d < 3; d++) {
        lo[d] = d < s->dim ? INT_MAX : 0;
        hi[d] = d < s->dim ? -1 : 0;
    }
    for (int t = 0; t < s->nthreads; t++) {
        const mpm_thread_out *o = &s->tout[t];
        if (o->blo[0] > o->bhi[0]) continue;
        for (int d = 0; d < s->dim; d++) {
            if (o->blo[d] < lo[d]) lo[d] = o->blo[d];
            if (o->bhi[d] > hi[d]) hi[d] = o->bhi[d];
        }
    }
}

/* zeroes nodes a..b (inclusive, possibly none) of a row in the fields f */
static void zero_span(const mpm_sim *s, double *const *f, int nf, size_t row, int a, int b)
{
    if (a > b) return;
    for (int i = 0; i < nf; i++) memset(f[i] + row_node(s, row, a), 0, (size_t)(b - a + 1) * sizeof(double));
}

/* Makes the active rows the union of the threads' rows as the last
 * particle pass recorded them, and zeroes, in every field of the main
 * grid, the nodes of the old extents outside the new ones (which keeps the
 * main grid zero outside the active rows); then counts the new extents'
 * nodes row by row (acc, for the node passes' split).  Serial; the rows
 * visited are those of the old and the new box. */
static void update_rows(mpm_sim *s)
{
    int lo[3], hi[3], alo[3], ahi[3];
    union_box(s, lo, hi);
    int has_old = box_rows(s->blo, s->bhi) > 0, has_new = box_rows(lo, hi) > 0;
    for (int d = 0; d < 3; d++) {
        alo[d] = has_old && (!has_new || s->blo[d] < lo[d]) ? s->blo[d] : lo[d];
        ahi[d] = has_old && (!has_new || s->bhi[d] > hi[d]) ? s->bhi[d] : hi[d];
    }
    double *f[10];
    int nf = grid_fields(s, &s->g, f);
    size_t nr = has_old || has_new ? box_rows(alo, ahi) : 0;
    for (size_t r = 0; r < nr; r++) {
        size_t row = box_row(s, alo, ahi, r);
        int nlo = INT_MAX, nhi = -1;
        for (int t = 0; t < s->nthreads; t++) {
            const mpm_thread_out *o = &s->tout[t];
            if (o->rlo[row] < nlo) nlo = o->rlo[row];
            if (o->rhi[row] > nhi) nhi = o->rhi[row];
        }
        int olo = s->ulo[row], ohi = s->uhi[row];
        if (nlo > nhi) {
            zero_span(s, f, nf, row, olo, ohi);
        } else {
            zero_span(s, f, nf, row, olo, ohi < nlo - 1 ? ohi : nlo - 1);
            zero_span(s, f, nf, row, olo > nhi + 1 ? olo : nhi + 1, ohi);
        }
        s->ulo[row] = nlo;
        s->uhi[row] = nhi;
    }
    memcpy(s->blo, lo, sizeof lo);
    memcpy(s->bhi, hi, sizeof hi);
    size_t nb = box_rows(lo, hi), n = 0;
    for (size_t r = 0; r < nb; r++) {
        size_t row = box_row(s, lo, hi, r);
        s->acc[r] = n;
        if (s->ulo[row] <= s->uhi[row]) n += (size_t)(s->uhi[row] - s->ulo[row] + 1);
    }
    s->acc[nb] = n;
    s->nact = n;
}

/* The scatter target of thread tid, zeroed over the thread's rows for the
 * fields named: thread 0 scatters straight into the main grid (its sums
 * come first in the reduction anyway), the others into private grids.
 * While a pass scatters, nobody reads the fields it scatters into. */
enum { F_M = 1, F_Q = 2, F_F = 4, F_Q2 = 8 };

static mpm_gridbuf *scatter_buf(mpm_sim *s, int tid, int fields)
{
    mpm_gridbuf *b = tid == 0 ? &s->g : &s->tbuf[tid];
    const mpm_thread_out *o = &s->tout[tid];
    if (fields & F_M) zero_rows(s, b->m, o);
    for (int d = 0; d < s->dim; d++) {
        if (fields & F_Q) zero_rows(s, b->q[d], o);
        if (fields & F_F) zero_rows(s, b->f[d], o);
        if (fields & F_Q2) zero_rows(s, b->q2[d], o);
    }
    return b;
}

/* ---- node passes split by nodes ----
 *
 * The nodes of the active rows' extents, numbered row by row over the box
 * (acc[r]: those before row r), are split evenly among the threads, so a
 * node pass is balanced however few the rows (1D has one) or however
 * uneven their extents.  A thread's share is a run of segments, nodes
 * a..b of a row.  Every node pass computes each node from that node alone,
 * so the split changes no result. */
typedef struct {
    size_t r, nr, n, n1;
} seg_iter;

static void seg_begin(const mpm_sim *s, int tid, seg_iter *it)
{
    size_t n0, n1, lo = 0, hi = box_rows(s->blo, s->bhi);
    slice(s->nact, s->nthreads, tid, &n0, &n1);
    it->nr = hi;
    while (lo < hi) { /* the first row r with acc[r + 1] > n0 */
        size_t mid = lo + (hi - lo) / 2;
        if (s->acc[mid + 1] > n0) hi = mid;
        else lo = mid + 1;
    }
    it->r = lo;
    it->n = n0;
    it->n1 = n1;
}

static int seg_next(const mpm_sim *s, seg_iter *it, size_t *row, int *a, int *b)
{
    while (it->n < it->n1 && it->r < it->nr) {
        size_t r = it->r++, w = s->acc[r + 1] - s->acc[r];
        if (!w) continue;
        size_t off = it->n - s->acc[r], take = w - off;
        if (take > it->n1 - it->n) take = it->n1 - it->n;
        *row = box_row(s, s->blo, s->bhi, r);
        *a = s->ulo[*row] + (int)off;
        *b = *a + (int)take - 1;
        it->n += take;
        return 1;
    }
    return 0;
}

static double *field_of(const mpm_gridbuf *b, int fl, int d)
{
    return fl == F_M ? b->m : fl == F_Q ? b->q[d] : fl == F_F ? b->f[d] : b->q2[d];
}

static void span_zero(double *restrict dst, size_t a, size_t b)
{
    if (a <= b) memset(dst + a, 0, (b - a + 1) * sizeof *dst);
}

static void span_copy(double *restrict dst, const double *restrict src, size_t a, size_t b)
{
    if (a <= b) memcpy(dst + a, src + a, (b - a + 1) * sizeof *dst);
}

static void span_add(double *restrict dst, const double *restrict src, size_t a, size_t b)
{
    if (a > b) return;
    for (size_t n = a; n <= b; n++) dst[n] += src[n];
}

/* Sums the private grids of the fields named into the grid over nodes
 * a..b of a row, in thread order.  Thread 0's values are in place; each
 * further thread adds its values where an earlier thread's extent
 * (within a..b) lies, copies them where none did (0 + v = v), and any gap
 * between the two is zeroed; what no thread touched is zeroed at the
 * end.  The extents are intervals, so the nodes already summed always
 * form one interval ia..ib. */
static void reduce_seg(mpm_sim *s, int fields, size_t row, int a, int b)
{
    int T = s->nthreads;
    size_t base = row_node(s, row, 0);
    for (int pass = 0; pass < 4; pass++) {
        int fl = 1 << pass;
        if (!(fields & fl)) continue;
        for (int d = 0; d < (fl == F_M ? 1 : s->dim); d++) {
            double *dst = field_of(&s->g, fl, d) + base;
            long ia = 1, ib = 0; /* empty */
            for (int t = 0; t < T; t++) {
                const mpm_thread_out *o = &s->tout[t];
                long lo = o->rlo[row] > a ? o->rlo[row] : a, hi = o->rhi[row] < b ? o->rhi[row] : b;
                if (lo > hi) continue;
                if (t == 0) {
                    ia = lo;
                    ib = hi;
                    continue;
                }
                const double *src = field_of(&s->tbuf[t], fl, d) + base;
                if (ia > ib) {
                    span_copy(dst, src, (size_t)lo, (size_t)hi);
                    ia = lo;
                    ib = hi;
                    continue;
                }
                if (hi < ia - 1) span_zero(dst, (size_t)hi + 1, (size_t)ia - 1);
                if (lo > ib + 1) span_zero(dst, (size_t)ib + 1, (size_t)lo - 1);
                if (lo < ia) span_copy(dst, src, (size_t)lo, (size_t)(hi < ia - 1 ? hi : ia - 1));
                if (hi > ib) span_copy(dst, src, (size_t)(lo > ib + 1 ? lo : ib + 1), (size_t)hi);
                long sa = lo > ia ? lo : ia, sb = hi < ib ? hi : ib;
                if (sa <= sb) span_add(dst, src, (size_t)sa, (size_t)sb);
                if (lo < ia) ia = lo;
                if (hi > ib) ib = hi;
            }
            if (ia > ib) {
                span_zero(dst, (size_t)a, (size_t)b);
            } else {
                if (ia > a) span_zero(dst, (size_t)a, (size_t)ia - 1);
                if (ib < b) span_zero(dst, (size_t)ib + 1, (size_t)b);
            }
        }
    }
}

static void particle_slice(mpm_sim *s, int tid, size_t *a, size_t *b)
{
    slice(s->P.n, s->nthreads, tid, a, b);
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
    particle_slice(s, tid, &a, &b);
    s->k->p2g_mq(s, scatter_buf(s, tid, F_M | F_Q), a, b);
}

static void ph_p2g_mqf(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    s->k->p2g_mqf(s, scatter_buf(s, tid, F_M | F_Q | F_F), a, b);
}

static void ph_p2g_q2(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    s->k->p2g_q2(s, scatter_buf(s, tid, F_Q2), a, b);
}

static void ph_stress_force(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    s->k->stress_force(s, scatter_buf(s, tid, F_F), &s->tout[tid], a, b, s->step_energy);
}

static void ph_g2p_xv(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    reset_out(&s->tout[tid]);
    s->k->g2p_xv(s, &s->tout[tid], a, b, s->step_energy);
}

static void ph_g2p_xv_stress(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    reset_out(&s->tout[tid]);
    s->k->g2p_xv_stress(s, &s->tout[tid], a, b, s->step_energy);
}

static void ph_g2p_v(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    s->k->g2p_v(s, &s->tout[tid], a, b);
}

static void ph_g2p_x_stress(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    reset_out(&s->tout[tid]);
    s->k->g2p_x_stress(s, &s->tout[tid], a, b, s->step_energy);
}

static void ph_bbox(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    s->k->bbox(s, &s->tout[tid], a, b);
}

/* BC1 (Eq. 27) on a momentum field, BC2 (Eq. 28) on the rate of momentum,
 * over the flat nodes first..last (one segment of a row; the field is zero
 * outside the active rows' extents, and its untouched pages stay so).
 * The list of fixed nodes is in increasing node order. */
static void zero_fixed(const mpm_sim *s, double *const field[3], size_t first, size_t last)
{
#ifndef MPM_LEAN
    size_t a = 0, b = s->nfixed;
    if (!b) return;
    while (a < b) { /* first entry >= first */
        size_t mid = a + (b - a) / 2;
        if (s->fixed_node[mid] < first) a = mid + 1;
        else b = mid;
    }
    for (size_t i = a; i < s->nfixed && s->fixed_node[i] <= last; i++) {
        size_t n = s->fixed_node[i];
        unsigned m = s->fixed_mask[i];
        for (int d = 0; d < s->dim; d++)
            if (m & (1u << d)) field[d][n] = 0.0;
    }
#else
    (void)s;
    (void)field;
    (void)first;
    (void)last;
#endif
}

/* A node pass over the thread's share of the extents' nodes, each node in
 * the step's order: reduce the fields named (F_*), then inverse mass with
 * phantom nodes (m <= M_TOL) at 0 (N_MINV), gravity f += m g (N_GRAV,
 * sum_p m_p b S_np), BC1 on q (N_BC1) or on q2 (N_BC1Q2), BC2 on f
 * (N_BC2), and q += f dt (N_UPD: Eq. 13 integrated, Fig. 6 step 6). */
enum { N_MINV = 16, N_GRAV = 32, N_BC1 = 64, N_BC1Q2 = 128, N_BC2 = 256, N_UPD = 512 };

static void node_pass(mpm_sim *s, int tid, int ops)
{
    int fields = ops & (F_M | F_Q | F_F | F_Q2);
    double mtol = s->mtol, dt = s->dt;
#ifdef MPM_LEAN
    ops &= ~(N_GRAV | N_BC1 | N_BC1Q2 | N_BC2);
#endif
    if (!s->has_gravity) ops &= ~N_GRAV;
    if (!s->nfixed) ops &= ~(N_BC1 | N_BC1Q2 | N_BC2);
    seg_iter it;
    seg_begin(s, tid, &it);
    size_t row;
    int lo, hi;
    while (seg_next(s, &it, &row, &lo, &hi)) {
        if (fields && s->nthreads > 1) reduce_seg(s, fields, row, lo, hi);
        size_t base = row_node(s, row, lo), w = (size_t)(hi - lo + 1);
        if (ops & N_MINV) {
            const double *restrict m = s->g.m + base;
            double *restrict mi = s->minv + base;
            for (size_t i = 0; i < w; i++) mi[i] = m[i] > mtol ? 1.0 / m[i] : 0.0;
        }
        if (ops & N_GRAV)
            for (int d = 0; d < s->dim; d++) {
                double gd = s->gravity[d];
                if (gd == 0) continue;
                const double *restrict m = s->g.m + base;
                double *restrict f = s->g.f[d] + base;
                for (size_t i = 0; i < w; i++) f[i] += gd * m[i];
            }
        if (ops & N_BC1) zero_fixed(s, s->g.q, base, base + w - 1);
        if (ops & N_BC1Q2) zero_fixed(s, s->g.q2, base, base + w - 1);
        if (ops & N_BC2) zero_fixed(s, s->g.f, base, base + w - 1);
        if (ops & N_UPD)
            for (int d = 0; d < s->dim; d++) {
                double *restrict q = s->g.q[d] + base;
                const double *restrict f = s->g.f[d] + base;
                for (size_t i = 0; i < w; i++) q[i] += f[i] * dt;
            }
    }
}

/* ---- the step on the team ----
 *
 * A step's passes run in one team phase, the threads meeting at a barrier
 * between passes (team_sync); the point forces (tractions), scattered
 * serially into the main grid, split the node pass in two. */
static void team_sync(mpm_sim *s)
{
    if (s->nthreads > 1) pthread_barrier_wait(&s->bar_end);
}

/* the rate of momentum once reduced (gravity included): point forces,
 * BC2, then q += f dt */
static void forces_update(mpm_sim *s, int tid, int reduce_ops)
{
    if (!s->nload) {
        node_pass(s, tid, reduce_ops | N_BC2 | N_UPD);
        return;
    }
    node_pass(s, tid, reduce_ops);
    team_sync(s);
    if (tid == 0) s->k->scatter_loads(s);
    team_sync(s);
    node_pass(s, tid, N_BC2 | N_UPD);
}

static void ph_step_usf(mpm_sim *s, int tid)
{
    ph_p2g_mq(s, tid);
    team_sync(s);
    node_pass(s, tid, F_M | F_Q | N_MINV | N_BC1);
    team_sync(s);
    ph_stress_force(s, tid);
    team_sync(s);
    forces_update(s, tid, F_F | N_GRAV);
    team_sync(s);
    ph_g2p_xv(s, tid);
}

static void ph_step_usl(mpm_sim *s, int tid)
{
    ph_p2g_mqf(s, tid);
    team_sync(s);
    forces_update(s, tid, F_M | F_Q | F_F | N_MINV | N_GRAV | N_BC1);
    team_sync(s);
    if (s->update == MPM_USL) {
        ph_g2p_xv_stress(s, tid);
        return;
    }
    ph_g2p_v(s, tid);
    team_sync(s);
    ph_p2g_q2(s, tid);
    team_sync(s);
    node_pass(s, tid, F_Q2 | N_BC1Q2); /* BC1 on the recomputed momentum */
    team_sync(s);
    ph_g2p_x_stress(s, tid);
}

/* ---- sorting by cell ----
 *
 * Every MPM_SORT_EVERY steps (and at creation) the particles are put in the
 * order of their cells, row-major over the active rows, by a stable
 * counting sort, so that consecutive particles share nodes and each
 * thread's slice covers a compact region.  The cells are numbered over the
 * rows' extents only (the histogram follows the particles, not the box).
 * P.id keeps each particle's creation index: everything public (snapshots,
 * error messages, per-particle inputs) speaks creation order.  The scratch
 * is made at creation: the keys and the integer fields go through the
 * double scratch array.  The keys, the check that they are in order
 * already (then nothing moves: the common case between cell crossings)
 * and the permutation of the arrays run on the team; the histogram and the
 * permutation itself are serial.  The order does not depend on the thread
 * count. */
#define MPM_SORT_EVERY 16

/* Keys of the thread's slice, and whether the slice is in key order. */
static void ph_keys(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    uint32_t *key = (uint32_t *)(void *)s->sscr;
    s->k->cell_keys(s, key, a, b);
    mpm_thread_out *o = &s->tout[tid];
    int sorted = 1;
    for (size_t p = a + 1; p < b; p++) sorted &= key[p] >= key[p - 1];
    o->ksorted = sorted;
    o->kfirst = a < b ? key[a] : 0;
    o->klast = a < b ? key[b - 1] : 0;
}

/* The particle arrays of doubles, in a fixed order. */
static int sort_arrays(mpm_sim *s, double **arr[3 * 3 + 2 * 6 + 2])
{
    mpm_particles *P = &s->P;
    int na = 0;
    for (int d = 0; d < s->dim; d++) {
        arr[na++] = &P->x[d];
        arr[na++] = &P->v[d];
        if (P->lp[d]) arr[na++] = &P->lp[d];
    }
    for (int c = 0; c < MPM_NCOMP(s->dim); c++) {
        arr[na++] = &P->sig[c];
        if (P->eps[c]) arr[na++] = &P->eps[c];
    }
    arr[na++] = &P->m;
    arr[na++] = &P->vol;
    return na;
}

/* The permutation applied on the team, each thread gathering its slice of
 * slots (slot p takes particle perm[p]) of one array at a time through the
 * scratch: the integer fields are copied back, and each double array's
 * permuted copy goes into the scratch, the old array then being the
 * scratch of the next (sort_particles() swaps the pointers after).  Only
 * copies: the result does not depend on the thread count. */
static void ph_permute(mpm_sim *s, int tid)
{
    mpm_particles *P = &s->P;
    const uint32_t *restrict perm = s->sperm;
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    uint16_t *m16 = (uint16_t *)(void *)s->sscr;
    for (size_t p = a; p < b; p++) m16[p] = P->mat[perm[p]];
    team_sync(s);
    memcpy(P->mat + a, m16 + a, (b - a) * sizeof *P->mat);
    team_sync(s);
    uint32_t *u32 = (uint32_t *)(void *)s->sscr;
    for (size_t p = a; p < b; p++) u32[p] = P->id[perm[p]];
    team_sync(s);
    memcpy(P->id + a, u32 + a, (b - a) * sizeof *P->id);
    team_sync(s);
    if (s->nload) { /* the inverse map for the loaded particles */
        for (size_t p = a; p < b; p++) u32[perm[p]] = (uint32_t)p;
        team_sync(s);
        size_t i0, i1;
        slice(s->nload, s->nthreads, tid, &i0, &i1);
        for (size_t i = i0; i < i1; i++) s->load_p[i] = u32[s->load_p[i]];
        team_sync(s);
    }
    double **arr[3 * 3 + 2 * 6 + 2];
    int na = sort_arrays(s, arr);
    double *dst = s->sscr;
    for (int i = 0; i < na; i++) {
        const double *restrict src = *arr[i];
        double *restrict d = dst;
        for (size_t p = a; p < b; p++) d[p] = src[perm[p]];
        team_sync(s);
        dst = *arr[i];
    }
}

static void sort_particles(mpm_sim *s)
{
    mpm_particles *P = &s->P;
    size_t n = P->n;
    size_t nr = box_rows(s->blo, s->bhi);
    if (n < 2 || !nr) return;
    size_t nk = 0;
    for (size_t r = 0; r < nr; r++) {
        size_t row = box_row(s, s->blo, s->bhi, r);
        s->rowoff[row] = nk;
        if (s->ulo[row] <= s->uhi[row]) nk += (size_t)(s->uhi[row] - s->ulo[row] + 1);
    }
    s->rowoff[s->nrows] = nk;
    run(s, ph_keys);
    int sorted = 1;
    uint32_t last = 0;
    for (int t = 0; t < s->nthreads; t++) {
        size_t a, b;
        particle_slice(s, t, &a, &b);
        if (a == b) continue;
        sorted &= s->tout[t].ksorted && s->tout[t].kfirst >= last;
        last = s->tout[t].klast;
    }
    if (sorted) return;
    uint32_t *key = (uint32_t *)(void *)s->sscr, *perm = s->sperm, *h = s->shist;
    memset(h, 0, (nk + 1) * sizeof *h);
    for (size_t p = 0; p < n; p++) h[key[p] + 1]++;
    for (size_t k = 0; k < nk; k++) h[k + 1] += h[k];
    for (size_t p = 0; p < n; p++) perm[h[key[p]]++] = (uint32_t)p;
    /* the keys are spent: the scratch carries the permuted copies */
    run(s, ph_permute);
    double **arr[3 * 3 + 2 * 6 + 2];
    int na = sort_arrays(s, arr);
    for (int i = 0; i < na; i++) {
        double *old = *arr[i];
        *arr[i] = s->sscr;
        s->sscr = old;
    }
}

/* Before a step: the active rows become those the last particle pass
 * recorded (update_rows), then the particles are sorted when due. */
static void begin_step(mpm_sim *s)
{
    update_rows(s);
    if (s->steps > 0 && s->steps % MPM_SORT_EVERY == 0) {
        sort_particles(s); /* the rows stay: they do not depend on the order */
        run(s, ph_bbox);
    }
}

/* ---- creation ---- */

static size_t node_index(const mpm_sim *s, const int ijk[3])
{
    size_t n = 0;
    for (int d = 0; d < s->dim; d++) n += (size_t)(ijk[d] + s->pad) * s->stride[d];
    return n;
}

/* Builds the list of fixed nodes from the face masks and the node set.  In
 * GMPM a particle's support reaches the ghost layers, so a face condition
 * covers the whole plane of the face including its ghost extension (a
 * roller wall does not end where the real grid does) and the ghost nodes
 * behind it (material cannot flow through a wall by way of nodes outside
 * the grid).  A node set names real nodes. */
static int build_fixed(mpm_sim *s, const mpm_bc_desc *bc)
{
    int any = bc->n_nodes > 0;
    for (int f = 0; f < 2 * s->dim; f++) any |= bc->face_mask[f] != 0;
    if (!any) return 0;
    unsigned char *mask = calloc(s->nn, 1);
    unsigned all = (1u << s->dim) - 1;
    if (!mask) return MPM_ENOMEM;
    for (size_t n = 0; n < s->nn; n++) {
        size_t rest = n;
        for (int d = 0; d < s->dim; d++) {
            int r = (int)(rest % (size_t)s->np[d]) - s->pad; /* real index along d */
            rest /= (size_t)s->np[d];
            if (r <= 0) mask[n] |= bc->face_mask[2 * d] & all;
            if (r >= s->nreal[d] - 1) mask[n] |= bc->face_mask[2 * d + 1] & all;
        }
    }
    for (size_t i = 0; i < bc->n_nodes; i++) {
        int ijk[3] = {0, 0, 0};
        for (int d = 0; d < s->dim; d++) ijk[d] = bc->node_ijk[3 * i + d];
        mask[node_index(s, ijk)] |= (unsigned char)bc->node_mask[i];
    }
    size_t cnt = 0;
    for (size_t n = 0; n < s->nn; n++) cnt += mask[n] != 0;
    s->fixed_node = malloc((cnt ? cnt : 1) * sizeof *s->fixed_node);
    s->fixed_mask = malloc(cnt ? cnt : 1);
    if (!s->fixed_node || !s->fixed_mask) {
        free(mask);
        return MPM_ENOMEM;
    }
    for (size_t n = 0; n < s->nn; n++) {
        if (!mask[n]) continue;
        s->fixed_node[s->nfixed] = n;
        s->fixed_mask[s->nfixed++] = mask[n];
    }
    free(mask);
    return 0;
}

static int build_loads(mpm_sim *s, const mpm_case *c)
{
    if (!c->n_tractions) return 0;
    int dim = s->dim;
    size_t cnt = 0;
    for (size_t p = 0; p < s->P.n; p++)
        for (size_t t = 0; t < c->n_tractions; t++) {
            int in = 1;
            for (int d = 0; d < dim; d++)
                in &= s->P.x[d][p] >= c->tractions[t].lo[d] && s->P.x[d][p] <= c->tractions[t].hi[d];
            if (in) {
                cnt++;
                break;
            }
        }
    s->load_p = malloc(cnt * sizeof *s->load_p);
    if (!s->load_p) return MPM_ENOMEM;
    for (int d = 0; d < dim; d++)
        if (!(s->load_f[d] = dalloc(cnt)) || !(s->load_xold[d] = dalloc(cnt))) return MPM_ENOMEM;
    /* per traction: total volume inside, then shares */
    for (size_t t = 0; t < c->n_tractions; t++) {
        const mpm_traction_desc *tr = &c->tractions[t];
        double vsum = 0, area = 1;
        for (int d = 0; d < dim; d++)
            if (d != tr->normal) area *= tr->hi[d] - tr->lo[d];
        for (int pass = 0; pass < 2; pass++) {
            for (size_t p = 0; p < s->P.n; p++) {
                int in = 1;
                for (int d = 0; d < dim; d++)
                    in &= s->P.x[d][p] >= tr->lo[d] && s->P.x[d][p] <= tr->hi[d];
                if (!in) continue;
                if (pass == 0) {
                    vsum += s->P.vol[p];
                    continue;
                }
                size_t i = 0;
                while (i < s->nload && s->load_p[i] != p) i++;
                if (i == s->nload) s->load_p[s->nload++] = p;
                double share = s->P.vol[p] / vsum * (tr->is_force ? 1.0 : area);
                for (int d = 0; d < dim; d++) s->load_f[d][i] += tr->value[d] * share;
            }
        }
    }
    return 0;
}

static void open_gate(mpm_sim *s, int v)
{
    pthread_mutex_lock(&s->gate_mu);
    s->gate = v;
    pthread_cond_broadcast(&s->gate_cv);
    pthread_mutex_unlock(&s->gate_mu);
}

/* Starts threads 1..T-1.  On failure the started ones are released through
 * the gate and joined, and the simulation stays serial. */
static int start_threads(mpm_sim *s)
{
    int T = s->nthreads, started = 1, rc = 0;
    if (T == 1) return 0;
    if (!(s->threads = calloc((size_t)T, sizeof *s->threads))) return MPM_ENOMEM;
    if (pthread_mutex_init(&s->gate_mu, NULL)) return MPM_ENOMEM;
    if (pthread_cond_init(&s->gate_cv, NULL)) {
        pthread_mutex_destroy(&s->gate_mu);
        return MPM_ENOMEM;
    }
    s->sync_init = 1;
    if (pthread_barrier_init(&s->bar_start, NULL, (unsigned)T)) return MPM_ENOMEM;
    if (pthread_barrier_init(&s->bar_end, NULL, (unsigned)T)) {
        pthread_barrier_destroy(&s->bar_start);
        return MPM_ENOMEM;
    }
    s->sync_init = 2;
    for (; started < T; started++) {
        worker_arg *wa = malloc(sizeof *wa);
        if (!wa) {
            rc = MPM_ENOMEM;
            break;
        }
        wa->s = s;
        wa->tid = started;
        if (pthread_create(&s->threads[started], NULL, worker, wa)) {
            free(wa);
            rc = MPM_ENOMEM;
            break;
        }
    }
    if (rc) {
        open_gate(s, -1);
        for (int t = 1; t < started; t++) pthread_join(s->threads[t], NULL);
        free(s->threads);
        s->threads = NULL;
        return rc;
    }
    open_gate(s, 1);
    return 0;
}

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

static void next_dt(mpm_sim *s)
{
    s->dt = s->dt_fixed > 0 ? s->dt_fixed : s->cfl * mpm_sim_dt_limit(s);
}

/* uGIMP: 3 nodes per axis suffice when every a = lp/h <= 1/2 (the same
 * product the kernels form); lp never changes during a run. */
static int gimp_fits3(const mpm_sim *s)
{
    for (int d = 0; d < s->dim; d++) {
        const double *lp = s->P.lp[d];
        double ih = s->inv_h[d];
        for (size_t p = 0; p < s->P.n; p++)
            if (!(lp[p] * ih <= 0.5)) return 0;
    }
    return 1;
}

/* The first box and the first sort, once the team runs. */
static void init_order(mpm_sim *s)
{
    run(s, ph_bbox);
    update_rows(s);
    sort_particles(s);
    run(s, ph_bbox);
}

int mpm_sim_set_gimp_nodes(mpm_sim *s, int ns)
{
    if (s->method != MPM_METHOD_GIMP || s->steps > 0 || (ns != 3 && ns != 4) ||
        (ns == 3 && !gimp_fits3(s)))
        return MPM_EINVAL;
    s->ns = ns;
    s->k = mpm_kernels_select(s->dim, ns);
    init_order(s);
    return 0;
}

#ifdef MPM_LEAN
/* A build without gravity, loads and fixed boundaries refuses cases that
 * use them. */
static int lean_check(const mpm_case *c, char *err, size_t errlen)
{
    const char *what = NULL;
    for (int d = 0; d < c->grid.dim; d++)
        if (c->gravity[d] != 0) what = "gravity";
    if (c->n_tractions) what = "tractions";
    for (int f = 0; f < 2 * c->grid.dim; f++)
        if (c->bc.face_mask[f]) what = "bc.face_mask";
    if (c->bc.n_nodes) what = "bc.node_ijk";
    if (!what) return 0;
    snprintf(err, errlen, "%s: this solver was built with MPM_LEAN (no gravity, loads or fixed "
             "boundaries)", what);
    return MPM_EINVAL;
}
#endif

/* The elastic energy stored by the initial stress, sum 1/2 sigma0 : C^-1 :
 * sigma0 V0 (isotropic linear elasticity; 2D is plane strain with sigma_zz
 * stored).  The reported strain energy 1/2 sigma : eps counts strain from
 * the initial state, so a body released from an initial stress shows
 * kinetic + strain energy up to 2 U0 with E0 = 0; the divergence guard
 * counts 2 U0 as available (see guard()). */
static double initial_stress_energy(const mpm_sim *s)
{
    const mpm_particles *P = &s->P;
    int dim = s->dim;
    double u = 0;
    for (size_t p = 0; p < P->n; p++) {
        const mpm_mat_params *mp = &s->mats[P->mat[p]];
        double E = mp->E, nu = mp->nu, w;
        if (dim == 1) {
            w = P->sig[0][p] * P->sig[0][p] / E;
        } else {
            double xx = P->sig[0][p], yy = P->sig[1][p], zz = P->sig[2][p], sh = P->sig[3][p] * P->sig[3][p];
            if (dim == 3) sh += P->sig[4][p] * P->sig[4][p] + P->sig[5][p] * P->sig[5][p];
            w = (xx * xx + yy * yy + zz * zz - 2 * nu * (xx * yy + yy * zz + zz * xx) + 2 * (1 + nu) * sh) / E;
        }
        u += 0.5 * w * P->vol[p];
    }
    return u;
}

mpm_sim *mpm_sim_new(const mpm_case *c, char *err, size_t errlen)
{
    char dummy[8];
    if (!err || errlen == 0) {
        err = dummy;
        errlen = sizeof dummy;
    }
    err[0] = 0;
    if (mpm_case_check(c, err, errlen)) return NULL;
    long np = mpm_case_particles(c, NULL, NULL, NULL, err, errlen);
    if (np < 0) return NULL;
#ifdef MPM_LEAN
    if (lean_check(c, err, errlen)) return NULL;
#endif

    mpm_sim *s = calloc(1, sizeof *s);
    if (!s) goto nomem;
    int dim = s->dim = c->grid.dim;
    s->method = c->method;
    s->update = c->update;
    s->ns = c->method == MPM_METHOD_GIMP ? 4 : 2;
    s->pad = c->method == MPM_METHOD_GIMP ? 2 : 0;
    s->nthreads = c->threads > 1 ? c->threads : 1;
    atomic_init(&s->cancel, 0);
    s->nn = 1;
    for (int d = 0; d < 3; d++) {
        s->nreal[d] = d < dim ? c->grid.nodes[d] : 1;
        s->np[d] = d < dim ? s->nreal[d] + 2 * s->pad : 1;
        s->stride[d] = s->nn;
        s->nn *= (size_t)s->np[d];
        s->h[d] = d < dim ? c->grid.h[d] : 1;
        s->inv_h[d] = 1.0 / s->h[d];
        /* node 0 of the padded grid sits pad cells below the origin */
        s->x0[d] = d < dim ? c->grid.origin[d] - s->pad * s->h[d] : 0;
        /* a GMPM centre may enter the first ghost cell (see build_fixed) */
        s->lo[d] = d < dim ? c->grid.origin[d] - (s->pad / 2) * s->h[d] : 0;
        s->hi[d] = d < dim ? c->grid.origin[d] + (c->grid.nodes[d] - 1 + s->pad / 2) * s->h[d] : 0;
    }
    s->model = mpm_model_get(c->materials[0].model);
    s->nmat = c->n_materials;
    if (!(s->mats = calloc(s->nmat, sizeof *s->mats))) goto nomem;
    for (size_t i = 0; i < s->nmat; i++) {
        mpm_model_params(&c->materials[i], dim, i, &s->mats[i], err, errlen);
        if (s->mats[i].c > s->cmax) s->cmax = s->mats[i].c;
    }

    int musl = c->update == MPM_MUSL;
    if (alloc_particles(&s->P, (size_t)np, dim, c->method == MPM_METHOD_GIMP)) goto nomem;
    if (mpm_case_particles(c, &s->P, s->mats, &s->vmax, err, errlen) != np) goto fail;
    if (s->ns == 4 && gimp_fits3(s)) s->ns = 3;
    s->k = mpm_kernels_select(dim, s->ns);
    if (!(s->sperm = malloc((size_t)np * sizeof *s->sperm)) ||
        !(s->shist = calloc(s->nn + 1, sizeof *s->shist)) || !(s->sscr = dalloc((size_t)np)))
        goto nomem;
    if (alloc_gridbuf(&s->g, s->nn, dim, musl)) goto nomem;
    if (!(s->minv = dalloc(s->nn))) goto nomem;
    if (s->nthreads > 1) {
        if (!(s->tbuf = calloc((size_t)s->nthreads, sizeof *s->tbuf))) goto nomem;
        for (int t = 1; t < s->nthreads; t++) /* thread 0 scatters into the grid */
            if (alloc_gridbuf(&s->tbuf[t], s->nn, dim, musl)) goto nomem;
    }
    if (!(s->tout = calloc((size_t)s->nthreads, sizeof *s->tout))) goto nomem;
    for (int t = 0; t < s->nthreads; t++)
        for (int cc = 0; cc < 6; cc++)
            if (!(s->tout[t].deps[cc] = line_alloc(MPM_BLOCK * sizeof(double)))) goto nomem;
    for (int t = 0; t < s->nthreads; t++)
        if (!(s->tout[t].wblk = line_alloc(mpm_kernels_scratch()))) goto nomem;
    /* row extents, all empty */
    s->nrows = (size_t)s->np[1] * (size_t)s->np[2];
    if (!(s->ulo = malloc(s->nrows * sizeof *s->ulo)) || !(s->uhi = malloc(s->nrows * sizeof *s->uhi)) ||
        !(s->rowoff = malloc((s->nrows + 1) * sizeof *s->rowoff)) ||
        !(s->acc = calloc(s->nrows + 1, sizeof *s->acc)))
        goto nomem;
    for (int t = 0; t < s->nthreads; t++)
        if (!(s->tout[t].rlo = malloc(s->nrows * sizeof(int))) ||
            !(s->tout[t].rhi = malloc(s->nrows * sizeof(int))))
            goto nomem;
    for (size_t r = 0; r < s->nrows; r++) {
        s->ulo[r] = INT_MAX;
        s->uhi[r] = -1;
        for (int t = 0; t < s->nthreads; t++) {
            s->tout[t].rlo[r] = INT_MAX;
            s->tout[t].rhi[r] = -1;
        }
    }

    if (build_fixed(s, &c->bc)) goto nomem;
    if (build_loads(s, c)) goto nomem;
    for (int d = 0; d < dim; d++) {
        s->gravity[d] = c->gravity[d];
        s->has_gravity |= c->gravity[d] != 0;
    }
    double msum = 0;
    for (size_t p = 0; p < s->P.n; p++) msum += s->P.m[p];
    s->mtol = (c->mass_tol > 0 ? c->mass_tol : MPM_DEFAULT_MASS_TOL) * msum / (double)s->P.n;
    s->dt_fixed = c->dt;
    s->cfl = c->cfl > 0 ? c->cfl : MPM_DEFAULT_CFL;
    next_dt(s);
    mpm_energy e0;
    mpm_sim_energy(s, &e0);
    s->e_total0 = e0.total + 2 * initial_stress_energy(s);
    s->e_floor = 1e-9 * 0.5 * e0.mass * s->cmax * s->cmax;
    s->guard_v2 = s->vmax * s->vmax;
    if (start_threads(s)) goto nomem;
    init_order(s);
    return s;

nomem:
    snprintf(err, errlen, "out of memory building a case of %ld particles", np);
fail:
    mpm_sim_destroy(&s);
    return NULL;
}

void mpm_sim_destroy(mpm_sim **sp)
{
    mpm_sim *s = sp ? *sp : NULL;
    if (!s) return;
    if (s->threads) {
        s->quit = 1;
        pthread_barrier_wait(&s->bar_start);
        for (int t = 1; t < s->nthreads; t++) pthread_join(s->threads[t], NULL);
        free(s->threads);
    }
    if (s->sync_init >= 2) {
        pthread_barrier_destroy(&s->bar_start);
        pthread_barrier_destroy(&s->bar_end);
    }
    if (s->sync_init >= 1) {
        pthread_mutex_destroy(&s->gate_mu);
        pthread_cond_destroy(&s->gate_cv);
    }
    free_particles(&s->P);
    free_gridbuf(&s->g);
    if (s->tbuf)
        for (int t = 0; t < s->nthreads; t++) free_gridbuf(&s->tbuf[t]);
    free(s->tbuf);
    if (s->tout)
        for (int t = 0; t < s->nthreads; t++)
            for (int c = 0; c < 6; c++) free(s->tout[t].deps[c]);
    if (s->tout)
        for (int t = 0; t < s->nthreads; t++) {
            free(s->tout[t].wblk);
            free(s->tout[t].rlo);
            free(s->tout[t].rhi);
        }
    free(s->ulo);
    free(s->uhi);
    free(s->rowoff);
    free(s->acc);
    free(s->sperm);
    free(s->shist);
    free(s->sscr);
    free(s->tout);
    free(s->minv);
    free(s->mats);
    free(s->fixed_node);
    free(s->fixed_mask);
    free(s->load_p);
    for (int d = 0; d < 3; d++) {
        free(s->load_f[d]);
        free(s->load_xold[d]);
        free(s->trac_f[d]);
    }
    free(s);
    *sp = NULL;
}

/* ---- the step ---- */

/* The divergence guard.  A blow-up need not produce a NaN: an unstable
 * scheme (USL above C = 0.5, MPM when points cross cells) can multiply the
 * energy by 1e4 and still finish.  Every MPM_GUARD_EVERY steps the kinetic
 * plus strain energy is compared with what the loads can have supplied,
 * E0 + 2 U0 (U0: the energy stored by an initial stress, see
 * initial_stress_energy()) + (the loads' work, summed as |f . dx|) -
 * (change of gravity's potential); it never
 * exceeds that in the continuum, and the discrete schemes stay within a few
 * per cent of it on every problem of the stress suite (make stress), the
 * worst +29 % (MPM USF, one particle per cell).  Twice the available energy
 * is a blow-up, recorded as MPM_EDIVERGED.  Cost: one pass over the
 * particles every MPM_GUARD_EVERY steps, and whenever the largest particle
 * speed (known every step) has doubled its square since the last check, so
 * a fast blow-up is caught within a step or two; mpm_sim_check() runs it on
 * demand (at the end of a run). */
#define MPM_GUARD_EVERY 16
#define MPM_GUARD_FACTOR 2.0

/* The guard's energies on the team: each thread sums its slice exactly as
 * mpm_sim_energy() does, and the partial sums are added in thread order,
 * so the result is reproducible for a given thread count (and with one
 * thread equals mpm_sim_energy()'s).  A step asked for energies
 * (mpm_sim_want_energy()) makes the same per-thread sums inside its
 * kernels (mpm_kernels.c, esum_*), in the same particle order and with the
 * same arithmetic; the guard then uses those. */
static void ph_energy(mpm_sim *s, int tid)
{
    const mpm_particles *P = &s->P;
    int dim = s->dim;
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    double ek = 0, es = 0, ep = 0, mom[3] = {0, 0, 0}, ms = 0;
    for (size_t p = a; p < b; p++) {
        double m = P->m[p], v2 = 0;
        for (int d = 0; d < dim; d++) {
            v2 += P->v[d][p] * P->v[d][p];
            mom[d] += m * P->v[d][p];
            ep -= m * s->gravity[d] * P->x[d][p];
        }
        ek += 0.5 * m * v2;
        es += 0.5 * mpm_strain_density(P, dim, p) * P->vol[p];
        ms += m;
    }
    mpm_thread_out *o = &s->tout[tid];
    o->ekin = ek;
    o->estr = es;
    o->epot = ep;
    o->emass = ms;
    for (int d = 0; d < 3; d++) o->emom[d] = mom[d];
}

/* The partial sums in tout combined in thread order (external work and
 * total left out). */
static void sum_energy(const mpm_sim *s, mpm_energy *e)
{
    memset(e, 0, sizeof *e);
    for (int t = 0; t < s->nthreads; t++) {
        const mpm_thread_out *o = &s->tout[t];
        e->kinetic += o->ekin;
        e->strain += o->estr;
        e->potential += o->epot;
        e->mass += o->emass;
        for (int d = 0; d < s->dim; d++) e->momentum[d] += o->emom[d];
    }
}

static int guard(mpm_sim *s)
{
    mpm_energy e;
    if (s->ecache_ok) { /* summed by the step just taken: the same sums */
        e = s->ecache;
    } else {
        run(s, ph_energy);
        sum_energy(s, &e);
    }
    e.external_work = s->external_work;
    double have = e.kinetic + fabs(e.strain); /* a blow-up can drive 1/2 sigma:eps negative */
    s->guard_v2 = s->vmax * s->vmax;
    /* the loads' work counted as its absolute value: a bound that holds
     * however a coarse solution mis-integrates a force that does work
     * back and forth (the manufactured solutions do) */
    double avail = s->e_total0 - e.potential + s->external_work_abs;
    if (isfinite(have) && have <= MPM_GUARD_FACTOR * fmax(avail, 0) + s->e_floor) return 0;
    snprintf(s->err, sizeof s->err, "diverged at step %ld, time %.9g: kinetic + strain energy "
             "%.6g is more than %g times the energy the initial state and the loads supply (%.6g)",
             s->steps, s->t, have, MPM_GUARD_FACTOR, avail);
    s->failed = MPM_EDIVERGED;
    return s->failed;
}

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
        int finite = 1, axis = 0;
        char pos[128] = "", *w = pos;
        for (int d = 0; d < s->dim; d++) {
            double x = s->P.x[d][bad];
            finite &= isfinite(x) && isfinite(s->P.v[d][bad]);
            if (!(x >= s->lo[d] && x < s->hi[d])) axis = d;
            w += snprintf(w, sizeof pos - (size_t)(w - pos), "%s%.9g", d ? ", " : "", x);
        }
        if (!finite) {
            snprintf(s->err, sizeof s->err, "diverged at step %ld, time %.9g: particle %zu has a "
                     "non-finite position or velocity", step, t, (size_t)s->P.id[bad]);
            s->failed = MPM_EDIVERGED;
        } else {
            snprintf(s->err, sizeof s->err, "particle %zu left the grid at step %ld, time %.9g: "
                     "position (%s), %c outside [%g, %g)", (size_t)s->P.id[bad], step, t, pos, "xyz"[axis],
                     s->lo[axis], s->hi[axis]);
            s->failed = MPM_ELEFTGRID;
        }
        return s->failed;
    }
    for (size_t i = 0; i < s->nload; i++)
        for (int d = 0; d < s->dim; d++) {
            double w = s->load_f[d][i] * (s->P.x[d][s->load_p[i]] - s->load_xold[d][i]);
            s->external_work += w;
            s->external_work_abs += fabs(w);
        }
    s->vmax = sqrt(v2);
    s->t = t;
    s->steps = step;
    /* every MPM_GUARD_EVERY steps, and at once when the largest speed
     * has grown by sqrt(2) since the last check (a fast blow-up) */
    if ((step % MPM_GUARD_EVERY == 0 || v2 > 2 * s->guard_v2) && guard(s)) return s->failed;
    next_dt(s);
    return 0;
}

int mpm_sim_step(mpm_sim *s)
{
    if (s->failed) return MPM_ESTATE;
    s->ecache_ok = 0; /* the particles change (and may be reordered) */
    begin_step(s);
    for (size_t i = 0; i < s->nload; i++)
        for (int d = 0; d < s->dim; d++) s->load_xold[d][i] = s->P.x[d][s->load_p[i]];
    /* energies wanted: the passes that write each particle field for the
     * last time in the step sum them (s->step_energy, read once per pass:
     * USF stress_force and g2p_xv, USL g2p_xv_stress, MUSL g2p_x_stress) */
    s->step_energy = s->want_energy;
    s->want_energy = 0;
    run(s, s->update == MPM_USF ? ph_step_usf : ph_step_usl);
    if (s->step_energy) {
        s->step_energy = 0;
        sum_energy(s, &s->ecache);
        s->ecache_ok = 1; /* the particles as they are now, even if the step failed */
    }
    return finish_step(s);
}

void mpm_sim_want_energy(mpm_sim *s)
{
    s->want_energy = 1;
}

int mpm_sim_check(mpm_sim *s)
{
    if (s->failed) return s->failed;
    return guard(s);
}

int mpm_sim_run(mpm_sim *s, long nsteps)
{
    for (long i = 0; i < nsteps; i++) {
        if (atomic_load_explicit(&s->cancel, memory_order_relaxed)) {
            atomic_store(&s->cancel, 0);
            snprintf(s->err, sizeof s->err, "cancelled at step %ld, time %.9g", s->steps, s->t);
            return MPM_ECANCELLED;
        }
        int rc = mpm_sim_step(s);
        if (rc) return rc;
    }
    return 0;
}

int mpm_sim_set_particle_forces(mpm_sim *s, const double *f)
{
#ifdef MPM_LEAN
    if (f) {
        snprintf(s->err, sizeof s->err, "particle_forces: this solver was built with MPM_LEAN "
                 "(no gravity, loads or fixed boundaries)");
        return MPM_EINVAL;
    }
#endif
    size_t n = s->P.n;
    int dim = s->dim;
    if (f)
        for (size_t i = 0; i < n * (size_t)dim; i++)
            if (!isfinite(f[i])) {
                snprintf(s->err, sizeof s->err, "particle_forces[%zu]: must be finite (got %g)", i,
                         f[i]);
                return MPM_EINVAL;
            }
    if (!s->pforces) {
        if (!f) return 0;
        /* one slot per particle; the tractions' shares move to trac_f */
        size_t *lp = malloc((n ? n : 1) * sizeof *lp);
        double *tf[3] = {0}, *xo[3] = {0}, *lf[3] = {0};
        int ok = lp != NULL;
        for (int d = 0; d < dim; d++) {
            tf[d] = dalloc(n ? n : 1);
            xo[d] = dalloc(n ? n : 1);
            lf[d] = dalloc(n ? n : 1);
            ok &= tf[d] && xo[d] && lf[d];
        }
        if (!ok) {
            free(lp);
            for (int d = 0; d < dim; d++) {
                free(tf[d]);
                free(xo[d]);
                free(lf[d]);
            }
            snprintf(s->err, sizeof s->err, "out of memory for %zu particle forces", n);
            return MPM_ENOMEM;
        }
        for (size_t i = 0; i < n; i++) lp[i] = i;
        for (size_t i = 0; i < s->nload; i++)
            for (int d = 0; d < dim; d++) tf[d][s->load_p[i]] = s->load_f[d][i];
        free(s->load_p);
        s->load_p = lp;
        for (int d = 0; d < dim; d++) {
            free(s->load_f[d]);
            free(s->load_xold[d]);
            s->load_f[d] = lf[d];
            s->load_xold[d] = xo[d];
            s->trac_f[d] = tf[d];
        }
        s->nload = n;
        s->pforces = 1;
    }
    for (size_t i = 0; i < n; i++)
        for (int d = 0; d < dim; d++)
            s->load_f[d][i] = s->trac_f[d][i] +
                              (f ? f[(size_t)s->P.id[s->load_p[i]] * (size_t)dim + d] : 0);
    return 0;
}

void mpm_sim_cancel(mpm_sim *s)
{
    atomic_store(&s->cancel, 1);
}

/* ---- results ---- */

long mpm_sim_steps(const mpm_sim *s) { return s->steps; }
double mpm_sim_time(const mpm_sim *s) { return s->t; }
double mpm_sim_dt(const mpm_sim *s) { return s->dt; }
size_t mpm_sim_particles(const mpm_sim *s) { return s->P.n; }
int mpm_sim_dim(const mpm_sim *s) { return s->dim; }
const char *mpm_sim_error(const mpm_sim *s) { return s->err; }

size_t mpm_sim_nodes(const mpm_sim *s)
{
    size_t n = 1;
    for (int d = 0; d < s->dim; d++) n *= (size_t)s->nreal[d];
    return n;
}

/* On the thread team (ph_energy), partial sums combined in thread order:
 * reproducible for a given thread count; or, when the last step was asked
 * to (mpm_sim_want_energy()), the same sums that step made in its passes.  The team's scratch (tout) is
 * written, nothing of the simulation's state; the object was not defined
 * const, so the cast is sound, and the team is idle between steps. */
void mpm_sim_energy(const mpm_sim *cs, mpm_energy *e)
{
    mpm_sim *s = (mpm_sim *)cs;
    if (s->ecache_ok) { /* summed by the last step (mpm_sim_want_energy()) */
        *e = s->ecache;
    } else {
        if (s->threads) {
            run(s, ph_energy);
        } else { /* during creation, before the team starts: the same slices */
            for (int t = 0; t < s->nthreads; t++) ph_energy(s, t);
        }
        sum_energy(s, e);
    }
    e->external_work = s->external_work;
    e->total = e->kinetic + e->strain + e->potential - e->external_work;
}

void mpm_sim_snapshot(const mpm_sim *s, const mpm_snapshot *o)
{
    const mpm_particles *P = &s->P;
    int dim = s->dim, nc = MPM_NCOMP(dim);
    /* slot p holds the particle created as number P->id[p] */
    for (size_t p = 0; p < P->n; p++) {
        size_t q = P->id[p];
        for (int d = 0; d < dim; d++) {
            if (o->x) o->x[q * dim + d] = P->x[d][p];
            if (o->v) o->v[q * dim + d] = P->v[d][p];
        }
        if (o->stress)
            for (int c = 0; c < 6; c++) o->stress[q * 6 + c] = c < nc ? P->sig[c][p] : 0.0;
        if (o->pressure) {
            double tr = P->sig[0][p];
            if (dim > 1) tr += P->sig[1][p] + P->sig[2][p];
            o->pressure[q] = tr / 3.0;
        }
        if (o->volume) o->volume[q] = P->vol[p];
    }
}

void mpm_sim_node(const mpm_sim *s, const int ijk[3], double *mass, double q[MPM_MAX_DIM])
{
    size_t n = node_index(s, ijk);
    if (mass) *mass = s->g.m[n];
    for (int d = 0; d < MPM_MAX_DIM; d++) q[d] = d < s->dim ? s->g.q[d][n] : 0.0;
}
