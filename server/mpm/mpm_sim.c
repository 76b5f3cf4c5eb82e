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
 * Threads: a team of nthreads (the caller's thread is thread 0) runs each
 * particle pass on a fixed contiguous slice of the particles, scattering
 * into a private grid per thread; node passes then sum the private grids in
 * thread order.  The same case with the same thread count is therefore
 * bitwise reproducible; a different thread count changes the order of the
 * sums and so the last bits.  Nothing is allocated inside a step.
 */
#include "mpm_internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- allocation helpers ---- */

static double *dalloc(size_t n)
{
    return calloc(n ? n : 1, sizeof(double));
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
    for (int c = 0; c < MPM_NCOMP(dim); c++)
        if (!(P->sig[c] = dalloc(n)) || !(P->eps[c] = dalloc(n))) return MPM_ENOMEM;
    if (!(P->m = dalloc(n)) || !(P->vol = dalloc(n))) return MPM_ENOMEM;
    if (!(P->mat = calloc(n ? n : 1, sizeof *P->mat))) return MPM_ENOMEM;
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

/* The scatter target of thread tid, zeroed for the fields named. */
enum { F_M = 1, F_Q = 2, F_F = 4, F_Q2 = 8 };

static mpm_gridbuf *scatter_buf(mpm_sim *s, int tid, int fields)
{
    mpm_gridbuf *b = s->nthreads == 1 ? &s->g : &s->tbuf[tid];
    size_t bytes = s->nn * sizeof(double);
    if (fields & F_M) memset(b->m, 0, bytes);
    for (int d = 0; d < s->dim; d++) {
        if (fields & F_Q) memset(b->q[d], 0, bytes);
        if (fields & F_F) memset(b->f[d], 0, bytes);
        if (fields & F_Q2) memset(b->q2[d], 0, bytes);
    }
    return b;
}

/* Sums the private grids of the fields named into the grid (node slice of
 * thread tid), in thread order. */
static void reduce(mpm_sim *s, int tid, int fields, size_t n0, size_t n1)
{
    if (s->nthreads == 1) return;
    int T = s->nthreads;
    for (int pass = 0; pass < 4; pass++) {
        int fl = 1 << pass;
        if (!(fields & fl)) continue;
        for (int d = 0; d < (fl == F_M ? 1 : s->dim); d++) {
            double *dst = fl == F_M ? s->g.m : fl == F_Q ? s->g.q[d] : fl == F_F ? s->g.f[d] : s->g.q2[d];
            for (size_t n = n0; n < n1; n++) {
                double acc = 0;
                for (int t = 0; t < T; t++) {
                    mpm_gridbuf *b = &s->tbuf[t];
                    const double *src = fl == F_M ? b->m : fl == F_Q ? b->q[d] : fl == F_F ? b->f[d] : b->q2[d];
                    acc += src[n];
                }
                dst[n] = acc;
            }
        }
    }
    (void)tid;
}

static void particle_slice(mpm_sim *s, int tid, size_t *a, size_t *b)
{
    slice(s->P.n, s->nthreads, tid, a, b);
}

static void node_slice(mpm_sim *s, int tid, size_t *a, size_t *b)
{
    slice(s->nn, s->nthreads, tid, a, b);
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
    s->k->stress_force(s, scatter_buf(s, tid, F_F), &s->tout[tid], a, b);
}

static void ph_g2p_xv(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    reset_out(&s->tout[tid]);
    s->k->g2p_xv(s, &s->tout[tid], a, b);
}

static void ph_g2p_xv_stress(mpm_sim *s, int tid)
{
    size_t a, b;
    particle_slice(s, tid, &a, &b);
    reset_out(&s->tout[tid]);
    s->k->g2p_xv_stress(s, &s->tout[tid], a, b);
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
    s->k->g2p_x_stress(s, &s->tout[tid], a, b);
}

/* inverse mass with phantom nodes (m <= M_TOL) at 0 */
static void inv_mass(mpm_sim *s, size_t a, size_t b)
{
    for (size_t n = a; n < b; n++) {
        double m = s->g.m[n];
        s->minv[n] = m > s->mtol ? 1.0 / m : 0.0;
    }
}

static void gravity(mpm_sim *s, size_t a, size_t b)
{
    if (!s->has_gravity) return;
    for (int d = 0; d < s->dim; d++) {
        double gd = s->gravity[d];
        if (gd == 0) continue;
        for (size_t n = a; n < b; n++) s->g.f[d][n] += gd * s->g.m[n]; /* sum_p m_p b S_np */
    }
}

static void ph_node_mq(mpm_sim *s, int tid)
{
    size_t a, b;
    node_slice(s, tid, &a, &b);
    reduce(s, tid, F_M | F_Q, a, b);
    inv_mass(s, a, b);
}

static void ph_node_f(mpm_sim *s, int tid)
{
    size_t a, b;
    node_slice(s, tid, &a, &b);
    reduce(s, tid, F_F, a, b);
    gravity(s, a, b);
}

static void ph_node_mqf(mpm_sim *s, int tid)
{
    size_t a, b;
    node_slice(s, tid, &a, &b);
    reduce(s, tid, F_M | F_Q | F_F, a, b);
    inv_mass(s, a, b);
    gravity(s, a, b);
}

static void ph_node_q2(mpm_sim *s, int tid)
{
    size_t a, b;
    node_slice(s, tid, &a, &b);
    reduce(s, tid, F_Q2, a, b);
}

/* q += f dt (Eq. 13 integrated; Fig. 6 step 6) */
static void ph_node_update(mpm_sim *s, int tid)
{
    size_t a, b;
    node_slice(s, tid, &a, &b);
    for (int d = 0; d < s->dim; d++) {
        double *q = s->g.q[d];
        const double *f = s->g.f[d];
        for (size_t n = a; n < b; n++) q[n] += f[n] * s->dt;
    }
}

/* BC1 (Eq. 27) on a momentum field, BC2 (Eq. 28) on the rate of momentum. */
static void zero_fixed(mpm_sim *s, double *const field[3])
{
    for (size_t i = 0; i < s->nfixed; i++) {
        size_t n = s->fixed_node[i];
        unsigned m = s->fixed_mask[i];
        for (int d = 0; d < s->dim; d++)
            if (m & (1u << d)) field[d][n] = 0.0;
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
    s->k = mpm_kernels_select(dim, c->method);
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
    if (alloc_gridbuf(&s->g, s->nn, dim, musl)) goto nomem;
    if (!(s->minv = dalloc(s->nn))) goto nomem;
    if (s->nthreads > 1) {
        if (!(s->tbuf = calloc((size_t)s->nthreads, sizeof *s->tbuf))) goto nomem;
        for (int t = 0; t < s->nthreads; t++)
            if (alloc_gridbuf(&s->tbuf[t], s->nn, dim, musl)) goto nomem;
    }
    if (!(s->tout = calloc((size_t)s->nthreads, sizeof *s->tout))) goto nomem;
    for (int t = 0; t < s->nthreads; t++)
        for (int cc = 0; cc < 6; cc++)
            if (!(s->tout[t].deps[cc] = dalloc(MPM_BLOCK))) goto nomem;

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
    s->e_total0 = e0.total;
    s->e_floor = 1e-9 * 0.5 * e0.mass * s->cmax * s->cmax;
    s->guard_v2 = s->vmax * s->vmax;
    if (start_threads(s)) goto nomem;
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

static void loads_and_bc2(mpm_sim *s)
{
    if (s->nload) s->k->scatter_loads(s);
    zero_fixed(s, s->g.f); /* BC2 */
}

/* The divergence guard.  A blow-up need not produce a NaN: an unstable
 * scheme (USL above C = 0.5, MPM when points cross cells) can multiply the
 * energy by 1e4 and still finish.  Every MPM_GUARD_EVERY steps the kinetic
 * plus strain energy is compared with what the loads can have supplied,
 * E0 + (work of the loads) - (change of gravity's potential); it never
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

static int guard(mpm_sim *s)
{
    mpm_energy e;
    mpm_sim_energy(s, &e);
    double have = e.kinetic + e.strain;
    s->guard_v2 = s->vmax * s->vmax;
    double avail = s->e_total0 - e.potential + e.external_work;
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
                     "non-finite position or velocity", step, t, bad);
            s->failed = MPM_EDIVERGED;
        } else {
            snprintf(s->err, sizeof s->err, "particle %zu left the grid at step %ld, time %.9g: "
                     "position (%s), %c outside [%g, %g)", bad, step, t, pos, "xyz"[axis],
                     s->lo[axis], s->hi[axis]);
            s->failed = MPM_ELEFTGRID;
        }
        return s->failed;
    }
    for (size_t i = 0; i < s->nload; i++)
        for (int d = 0; d < s->dim; d++)
            s->external_work += s->load_f[d][i] * (s->P.x[d][s->load_p[i]] - s->load_xold[d][i]);
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
    for (size_t i = 0; i < s->nload; i++)
        for (int d = 0; d < s->dim; d++) s->load_xold[d][i] = s->P.x[d][s->load_p[i]];
    switch (s->update) {
    case MPM_USF:
        run(s, ph_p2g_mq);
        run(s, ph_node_mq);
        zero_fixed(s, s->g.q); /* BC1 */
        run(s, ph_stress_force);
        run(s, ph_node_f);
        loads_and_bc2(s);
        run(s, ph_node_update);
        run(s, ph_g2p_xv);
        break;
    case MPM_USL:
    case MPM_MUSL:
        run(s, ph_p2g_mqf);
        run(s, ph_node_mqf);
        zero_fixed(s, s->g.q); /* BC1 */
        loads_and_bc2(s);
        run(s, ph_node_update);
        if (s->update == MPM_USL) {
            run(s, ph_g2p_xv_stress);
        } else {
            run(s, ph_g2p_v);
            run(s, ph_p2g_q2);
            run(s, ph_node_q2);
            zero_fixed(s, s->g.q2); /* BC1 on the recomputed momentum */
            run(s, ph_g2p_x_stress);
        }
        break;
    }
    return finish_step(s);
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
            s->load_f[d][i] = s->trac_f[d][i] + (f ? f[i * (size_t)dim + d] : 0);
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

void mpm_sim_energy(const mpm_sim *s, mpm_energy *e)
{
    const mpm_particles *P = &s->P;
    int dim = s->dim, nc = MPM_NCOMP(dim);
    memset(e, 0, sizeof *e);
    for (size_t p = 0; p < P->n; p++) {
        double m = P->m[p], v2 = 0, se = 0;
        for (int d = 0; d < dim; d++) {
            v2 += P->v[d][p] * P->v[d][p];
            e->momentum[d] += m * P->v[d][p];
            e->potential -= m * s->gravity[d] * P->x[d][p];
        }
        for (int c = 0; c < nc; c++) se += (c < 3 ? 1.0 : 2.0) * P->sig[c][p] * P->eps[c][p];
        e->kinetic += 0.5 * m * v2;
        e->strain += 0.5 * se * P->vol[p];
        e->mass += m;
    }
    e->external_work = s->external_work;
    e->total = e->kinetic + e->strain + e->potential - e->external_work;
}

void mpm_sim_snapshot(const mpm_sim *s, const mpm_snapshot *o)
{
    const mpm_particles *P = &s->P;
    int dim = s->dim, nc = MPM_NCOMP(dim);
    for (size_t p = 0; p < P->n; p++) {
        for (int d = 0; d < dim; d++) {
            if (o->x) o->x[p * dim + d] = P->x[d][p];
            if (o->v) o->v[p * dim + d] = P->v[d][p];
        }
        if (o->stress)
            for (int c = 0; c < 6; c++) o->stress[p * 6 + c] = c < nc ? P->sig[c][p] : 0.0;
        if (o->pressure) {
            double tr = P->sig[0][p];
            if (dim > 1) tr += P->sig[1][p] + P->sig[2][p];
            o->pressure[p] = tr / 3.0;
        }
        if (o->volume) o->volume[p] = P->vol[p];
    }
}

void mpm_sim_node(const mpm_sim *s, const int ijk[3], double *mass, double q[MPM_MAX_DIM])
{
    size_t n = node_index(s, ijk);
    if (mass) *mass = s->g.m[n];
    for (int d = 0; d < MPM_MAX_DIM; d++) q[d] = d < s->dim ? s->g.q[d][n] : 0.0;
}

const char *mpm_strerror(int code)
{
    switch (code) {
    case MPM_OK: return "ok";
    case MPM_EINVAL: return "invalid case";
    case MPM_ENOMEM: return "out of memory";
    case MPM_ELEFTGRID: return "a particle left the grid";
    case MPM_EDIVERGED: return "diverged (NaN or Inf)";
    case MPM_ECANCELLED: return "cancelled";
    case MPM_ECFL: return "time step above the CFL limit";
    case MPM_ESTATE: return "the simulation already failed";
    }
    return "unknown error";
}
