/*
 * mpm_rows.c - the active rows: where the particles' supports reach, the
 * threads' scatter targets zeroed over them, and the node passes.
 *
 * Particle passes scatter only into the nodes their supports touch, and
 * record them row by row (a row: the nodes along x at fixed y, z): each
 * thread zeroes its private grid over its own rows' extents before
 * scattering, node passes run over the extents of the union (the rows of
 * the union box split among the threads), and the main grid outside the
 * union's extents is kept all zero.  The cost of a step, and the pages of
 * the grids ever touched, follow the particles, not the grid.
 */
#include "mpm_rows.h"
#include "mpm_cond.h"
#include "mpm_internal.h"
#include "mpm_loads.h"
#include "mpm_pass.h"

#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

int mpm_rows_init(mpm_sim *s)
{
    s->nrows = (size_t)s->np[1] * (size_t)s->np[2];
    if (!(s->ulo = malloc(s->nrows * sizeof *s->ulo)) ||
        !(s->uhi = malloc(s->nrows * sizeof *s->uhi)) ||
        !(s->rowoff = malloc((s->nrows + 1) * sizeof *s->rowoff)) ||
        !(s->acc = calloc(s->nrows + 1, sizeof *s->acc)) ||
        !(s->wacc = calloc(s->nrows + 1, sizeof *s->wacc)))
        return MPM_ENOMEM;
    for (int t = 0; t < s->nthreads; t++)
        if (!(s->tout[t].rlo = malloc(s->nrows * sizeof(int))) ||
            !(s->tout[t].rhi = malloc(s->nrows * sizeof(int))))
            return MPM_ENOMEM;
    for (size_t r = 0; r < s->nrows; r++) {
        s->ulo[r] = INT_MAX;
        s->uhi[r] = -1;
        for (int t = 0; t < s->nthreads; t++) {
            s->tout[t].rlo[r] = INT_MAX;
            s->tout[t].rhi[r] = -1;
        }
    }
    return 0;
}

/* Zeroes a thread's private field over the extents of its rows. */
static void zero_rows(const mpm_sim *s, double *a, const mpm_thread_out *o)
{
    size_t nr = mpm_box_rows(o->blo, o->bhi);
    for (size_t r = 0; r < nr; r++) {
        size_t row = mpm_box_row(s, o->blo, o->bhi, r);
        int lo = o->rlo[row], hi = o->rhi[row];
        if (lo <= hi) memset(a + mpm_row_node(s, row, lo), 0, (size_t)(hi - lo + 1) * sizeof *a);
    }
}

/* The fields of b named by mask (MPM_F_*) that b has, as a list of the
 * buffer's pointers (at most 10). */
static int field_ptrs(const mpm_sim *s, mpm_gridbuf *b, int mask, double **out[10])
{
    int k = 0;
    if (mask & MPM_F_M) out[k++] = &b->m;
    for (int d = 0; d < s->dim; d++) {
        if (mask & MPM_F_Q) out[k++] = &b->q[d];
        if ((mask & MPM_F_F) && b->f[d]) out[k++] = &b->f[d];
        if ((mask & MPM_F_Q2) && b->q2[d]) out[k++] = &b->q2[d];
    }
    return k;
}

/* the same, as the fields themselves */
static int field_list(const mpm_sim *s, mpm_gridbuf *b, int mask, double *out[10])
{
    double **p[10];
    int k = field_ptrs(s, b, mask, p);
    for (int i = 0; i < k; i++) out[i] = *p[i];
    return k;
}

static void swap_ptr(double **a, double **b)
{
    double *t = *a;
    *a = *b;
    *b = t;
}

void mpm_rows_swap_next(mpm_sim *s)
{
    double **g[10], **n[10];
    int k = field_ptrs(s, &s->g, s->p2g_fields, g);
    field_ptrs(s, &s->tbuf[0], s->p2g_fields, n); /* the same fields, in order */
    for (int i = 0; i < k; i++) swap_ptr(g[i], n[i]);
}

void mpm_rows_drop_next(mpm_sim *s)
{
    for (int t = 0; s->gnext && t < s->nthreads; t++) {
        double *z[10];
        int nz = field_list(s, &s->tbuf[t], s->p2g_fields, z);
        for (int i = 0; i < nz; i++) zero_rows(s, z[i], &s->tout[t]);
    }
    s->gnext = 0;
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
    for (int i = 0; i < nf; i++)
        memset(f[i] + mpm_row_node(s, row, a), 0, (size_t)(b - a + 1) * sizeof(double));
}

/* Whether fused steps pay with these active rows (rows of them, n nodes):
 * a fused step touches one more grid buffer (thread 0's next-step one),
 * page by page.  Where a grid row is a page or more apart from the next,
 * every active row costs a page of its own for each field; fusing pays
 * when the particles it saves a pass over outnumber those pages by
 * MPM_FUSE_PER_PAGE (measured: a 4096-node-wide grid with ~160 particles a
 * page ran 13 % slower fused, dense scenes with 700 and more no slower).
 * Fused and unfused steps give the same bits: this decides speed only. */
static int fuse_pays(const mpm_sim *s, size_t rows, size_t n)
{
    const size_t page = 4096;
    size_t stride = (size_t)s->np[0] * sizeof(double), pages;
    if (stride >= page)
        pages = rows + n * sizeof(double) / page;
    else
        pages = rows * stride / page + 1;
    return s->P.n >= (size_t)MPM_FUSE_PER_PAGE * pages;
}

/* Makes the active rows the union of the threads' rows as the last
 * particle pass recorded them, and zeroes, in every field of the main
 * grid, the nodes of the old extents outside the new ones (which keeps the
 * main grid zero outside the active rows); then counts the new extents'
 * nodes row by row, as nodes (acc) and as work units (wacc), for the node
 * passes' split.  Serial; the rows visited are those of the old and the
 * new box. */
void mpm_rows_update(mpm_sim *s)
{
    int lo[3], hi[3], alo[3], ahi[3];
    union_box(s, lo, hi);
    int has_old = mpm_box_rows(s->blo, s->bhi) > 0, has_new = mpm_box_rows(lo, hi) > 0;
    for (int d = 0; d < 3; d++) {
        alo[d] = has_old && (!has_new || s->blo[d] < lo[d]) ? s->blo[d] : lo[d];
        ahi[d] = has_old && (!has_new || s->bhi[d] > hi[d]) ? s->bhi[d] : hi[d];
    }
    double *f[10];
    int nf = field_list(s, &s->g, MPM_F_M | MPM_F_Q | MPM_F_F | MPM_F_Q2, f);
    size_t nr = has_old || has_new ? mpm_box_rows(alo, ahi) : 0;
    for (size_t r = 0; r < nr; r++) {
        size_t row = mpm_box_row(s, alo, ahi, r);
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
    size_t nb = mpm_box_rows(lo, hi), n = 0, rows = 0, wn = 0;
    const mpm_thread_out *o0 = &s->tout[0];
    for (size_t r = 0; r < nb; r++) {
        size_t row = mpm_box_row(s, lo, hi, r);
        s->acc[r] = n;
        s->wacc[r] = wn;
        int a = s->ulo[row], b = s->uhi[row];
        if (a <= b) {
            size_t w = (size_t)(b - a + 1);
            int ia = o0->rlo[row] > a ? o0->rlo[row] : a, ib = o0->rhi[row] < b ? o0->rhi[row] : b;
            size_t in_place = ia <= ib ? (size_t)(ib - ia + 1) : 0;
            n += w;
            wn += MPM_W_NODE * w + MPM_W_COPY * (w - in_place);
            rows++;
        }
    }
    s->acc[nb] = n;
    s->wacc[nb] = wn;
    s->nact = n;
    s->fuse_pays = fuse_pays(s, rows, n);
}

/* The fields the private grids (threads 1 and up) keep all zero between
 * uses: the P2G fields, and the one they keep in q's storage. */
static int kept_zero(const mpm_sim *s)
{
    return s->p2g_fields | s->tshare;
}

/* The scatter target of thread tid, zeroed over the thread's rows for the
 * fields named: thread 0 scatters straight into the main grid (its sums
 * come first in the reduction anyway), the others into private grids.
 * While a pass scatters, nobody reads the fields it scatters into.  The
 * private grids' P2G fields (s->p2g_fields: those of a step's first
 * scatter) are kept all zero between uses instead: the reduction zeroes
 * what it has read, so that a fused pass can scatter the next step's into
 * them before it knows the rows it will touch.  So is the field they keep
 * in q's storage (s->tshare), which q's zeros serve. */
mpm_gridbuf *mpm_scatter_buf(mpm_sim *s, int tid, int fields)
{
    mpm_gridbuf *b = tid == 0 ? &s->g : &s->tbuf[tid];
    const mpm_thread_out *o = &s->tout[tid];
    if (tid) fields &= ~kept_zero(s); /* all zero already (reduce_seg) */
    if (fields & MPM_F_M) zero_rows(s, b->m, o);
    for (int d = 0; d < s->dim; d++) {
        if (fields & MPM_F_Q) zero_rows(s, b->q[d], o);
        if (fields & MPM_F_F) zero_rows(s, b->f[d], o);
        if (fields & MPM_F_Q2) zero_rows(s, b->q2[d], o);
    }
    return b;
}

/* ---- node passes split by nodes ----
 *
 * The nodes of the active rows' extents, numbered row by row over the box
 * (acc[r]: those before row r), are split evenly among the threads, so a
 * node pass is balanced however few the rows (1D has one) or however
 * uneven their extents; a pass that reduces the private grids splits
 * their work units evenly instead (wacc, MPM_W_*).  A thread's share is a
 * run of segments, nodes a..b of a row.  Every node pass computes each
 * node from that node alone, so the split changes no result. */
typedef struct {
    size_t r, nr, n, n1;
} seg_iter;

/* The first row r of the box (0 .. nr - 1) with c[r + 1] > u, for a
 * running count c (acc or wacc); nr if there is none. */
static size_t row_of(const size_t *c, size_t nr, size_t u)
{
    size_t lo = 0, hi = nr;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (c[mid + 1] > u)
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

/* The node (as counted by acc) at which work unit u of wacc falls: the
 * row's units spread evenly over its nodes.  Only the split moves with
 * it: every node is still computed once, from itself. */
static size_t node_at_work(const mpm_sim *s, size_t u)
{
    size_t nr = mpm_box_rows(s->blo, s->bhi);
    if (u >= s->wacc[nr]) return s->nact;
    size_t r = row_of(s->wacc, nr, u);
    size_t w = s->acc[r + 1] - s->acc[r], wu = s->wacc[r + 1] - s->wacc[r];
    return s->acc[r] + (u - s->wacc[r]) * w / wu;
}

void mpm_node_share(const mpm_sim *s, int tid, int weighted, size_t *n0, size_t *n1)
{
    if (weighted) {
        size_t u0, u1;
        mpm_slice(s->wacc[mpm_box_rows(s->blo, s->bhi)], s->nthreads, tid, &u0, &u1);
        *n0 = node_at_work(s, u0);
        *n1 = tid == s->nthreads - 1 ? s->nact : node_at_work(s, u1);
    } else {
        mpm_slice(s->nact, s->nthreads, tid, n0, n1);
    }
}

static void seg_begin(const mpm_sim *s, int tid, int weighted, seg_iter *it)
{
    size_t n0, n1, nr = mpm_box_rows(s->blo, s->bhi);
    mpm_node_share(s, tid, weighted, &n0, &n1);
    it->nr = nr;
    it->r = row_of(s->acc, nr, n0);
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
        *row = mpm_box_row(s, s->blo, s->bhi, r);
        *a = s->ulo[*row] + (int)off;
        *b = *a + (int)take - 1;
        it->n += take;
        return 1;
    }
    return 0;
}

static double *field_of(const mpm_gridbuf *b, int fl, int d)
{
    return fl == MPM_F_M ? b->m : fl == MPM_F_Q ? b->q[d] : fl == MPM_F_F ? b->f[d] : b->q2[d];
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
    size_t base = mpm_row_node(s, row, 0);
    for (int pass = 0; pass < 4; pass++) {
        int fl = 1 << pass;
        if (!(fields & fl)) continue;
        for (int d = 0; d < (fl == MPM_F_M ? 1 : s->dim); d++) {
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
            if (fl & kept_zero(s)) /* read: back to zero (mpm_scatter_buf()) */
                for (int t = 1; t < T; t++) {
                    const mpm_thread_out *o = &s->tout[t];
                    long lo = o->rlo[row] > a ? o->rlo[row] : a;
                    long hi = o->rhi[row] < b ? o->rhi[row] : b;
                    if (lo <= hi)
                        span_zero(field_of(&s->tbuf[t], fl, d) + base, (size_t)lo, (size_t)hi);
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

/* support box and row extents of the thread's slice, nothing moved */
void mpm_ph_bbox(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    s->k->bbox(s, &s->tout[tid], a, b);
}

/* Damping of the rate of momentum over nodes base .. base + w - 1 (mpm.h,
 * mpm_damping_kind), after BC2 (a fixed component has f = 0 and q = 0, so
 * it is not damped) and before q += f dt; the energy removed, -f_d . v_mid
 * dt with v_mid = (q + (q + f dt)) / 2m the mean nodal velocity of the
 * update (exactly the work f_d does on the grid's kinetic energy in the
 * update), is added to the thread's edamp.  Phantom nodes (1/m stored as
 * 0) have v = 0 and are not damped. */
static void damp_seg(mpm_sim *s, int tid, size_t base, size_t w)
{
    double dt = s->dt, a = s->damp_coef, work = 0;
    int local = s->damp == MPM_DAMPING_LOCAL;
    const double *restrict mi = s->minv + base;
    for (int d = 0; d < s->dim; d++) {
        const double *restrict q = s->g.q[d] + base;
        double *restrict f = s->g.f[d] + base;
        for (size_t i = 0; i < w; i++) {
            if (mi[i] == 0) continue;
            double v = q[i] * mi[i], fd;
            if (local)
                fd = v > 0 ? -a * fabs(f[i]) : v < 0 ? a * fabs(f[i]) : 0.0;
            else
                fd = -a * q[i];
            f[i] += fd;
            work -= fd * (q[i] + 0.5 * f[i] * dt) * mi[i] * dt;
        }
    }
    s->tout[tid].edamp += work;
}

/* 1/m of w nodes into mi, 0 where m <= mtol (phantom nodes); two at a
 * time (the quotient where m is 0 is masked away): the scalar bits. */
static void minv_seg(double *restrict mi, const double *restrict m, double mtol, size_t w)
{
    const v2d one = {1.0, 1.0}, tol = {mtol, mtol};
    size_t i = 0;
    for (; i + 1 < w; i += 2) {
        v2d mm = v2_ld(m + i);
        v2_st(mi + i, (v2d)((v2l)(one / mm) & (mm > tol)));
    }
    for (; i < w; i++) mi[i] = m[i] > mtol ? 1.0 / m[i] : 0.0;
}

/* y += a x over w nodes, two at a time (the scalar bits). */
static void axpy_seg(double *restrict y, const double *restrict x, double a, size_t w)
{
    size_t i = 0;
    for (; i + 1 < w; i += 2) v2_st(y + i, v2_ld(y + i) + v2_ld(x + i) * a);
    for (; i < w; i++) y[i] += x[i] * a;
}

/* q += f dt, then q/m and f/m in their place (mpm_sim.gvel; 1/m is 0 at
 * phantom nodes), two at a time: the products the gathers took per
 * corner, the same bits. */
static void upd_vel_seg(double *restrict q, double *restrict f, const double *restrict mi,
                        double dt, size_t w)
{
    size_t i = 0;
    for (; i + 1 < w; i += 2) {
        v2d m = v2_ld(mi + i), fi = v2_ld(f + i);
        v2_st(q + i, (v2_ld(q + i) + fi * dt) * m);
        v2_st(f + i, fi * m);
    }
    for (; i < w; i++) {
        q[i] = (q[i] + f[i] * dt) * mi[i];
        f[i] *= mi[i];
    }
}

/* y *= x over w nodes, two at a time. */
static void scale_seg(double *restrict y, const double *restrict x, size_t w)
{
    size_t i = 0;
    for (; i + 1 < w; i += 2) v2_st(y + i, v2_ld(y + i) * v2_ld(x + i));
    for (; i < w; i++) y[i] *= x[i];
}

/* A node pass over the thread's share of the extents' nodes, each node in
 * the step's order: reduce the fields named (MPM_F_*), then inverse mass with
 * phantom nodes (m <= M_TOL) at 0 (MPM_N_MINV), gravity f += m g (MPM_N_GRAV,
 * sum_p m_p b S_np), BC1 on q (MPM_N_BC1) or on q2 (MPM_N_BC1Q2), BC2 on f
 * (MPM_N_BC2), damping (MPM_N_DAMP), and q += f dt (MPM_N_UPD: Eq. 13 integrated, Fig. 6 step 6),
 * for the families that gather velocities (mpm_sim.gvel) followed by q/m and
 * f/m in place of q and f; then q2/m in place of q2 (MPM_N_VQ2, gvel).
 */
void mpm_node_pass(mpm_sim *s, int tid, int ops)
{
    int fields = ops & (MPM_F_M | MPM_F_Q | MPM_F_F | MPM_F_Q2);
    double mtol = s->mtol, dt = s->dt;
#ifdef MPM_LEAN
    ops &= ~(MPM_N_GRAV | MPM_N_BC1 | MPM_N_BC1Q2 | MPM_N_BC2);
#endif
    if (!s->has_gravity) ops &= ~MPM_N_GRAV;
    if (!s->nfixed && !s->has_cond) ops &= ~(MPM_N_BC1 | MPM_N_BC1Q2 | MPM_N_BC2);
    seg_iter it;
    int reduce = fields && s->nthreads > 1; /* private grids to sum */
    seg_begin(s, tid, reduce, &it);
    size_t row;
    int lo, hi;
    while (seg_next(s, &it, &row, &lo, &hi)) {
        if (reduce) reduce_seg(s, fields, row, lo, hi);
        size_t base = mpm_row_node(s, row, lo), w = (size_t)(hi - lo + 1);
        if (ops & MPM_N_Z0) {
            double *z[10];
            int nz = field_list(s, &s->tbuf[0], s->p2g_fields, z);
            for (int i = 0; i < nz; i++) memset(z[i] + base, 0, w * sizeof(double));
        }
        if (ops & MPM_N_MINV) minv_seg(s->minv + base, s->g.m + base, mtol, w);
        if (ops & MPM_N_GRAV)
            for (int d = 0; d < s->dim; d++) {
                double gd = s->gravity[d];
                if (gd == 0) continue;
                axpy_seg(s->g.f[d] + base, s->g.m + base, gd, w);
            }
        /* prescribed velocities and friction (mpm_cond.c), then the fixed
         * DOFs' zeros (a friction face's roller: after friction read f_n).
         * Damping acts before BC2, so that the fixed and prescribed
         * directions end exactly at their values (what damping adds there
         * is taken back by BC2 and counted in the prescribed work: the
         * balance still closes) */
        if (ops & MPM_N_BC1) {
            if (s->has_cond) mpm_cond_bc1(s, base, base + w - 1);
            mpm_bc_zero(s, s->g.q, base, base + w - 1);
        }
        if (ops & MPM_N_BC1Q2) {
            if (s->has_cond) mpm_cond_bc1q2(s, base, base + w - 1);
            mpm_bc_zero(s, s->g.q2, base, base + w - 1);
        }
        if (ops & MPM_N_DAMP) damp_seg(s, tid, base, w);
        if (ops & MPM_N_BC2) {
            if (s->has_cond) mpm_cond_bc2(s, tid, base, base + w - 1);
            mpm_bc_zero(s, s->g.f, base, base + w - 1);
        }
        if ((ops & MPM_N_UPD) && s->gvel)
            for (int d = 0; d < s->dim; d++)
                upd_vel_seg(s->g.q[d] + base, s->g.f[d] + base, s->minv + base, dt, w);
        else if (ops & MPM_N_UPD)
            for (int d = 0; d < s->dim; d++) axpy_seg(s->g.q[d] + base, s->g.f[d] + base, dt, w);
        if ((ops & MPM_N_VQ2) && s->gvel)
            for (int d = 0; d < s->dim; d++) scale_seg(s->g.q2[d] + base, s->minv + base, w);
    }
}
