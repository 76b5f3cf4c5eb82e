/*
 * mpm_kernels.c - the particle loops of one explicit step, specialised by
 * dimension and method.
 *
 * Each loop is written once as an always-inline template taking the
 * dimension D and the nodes per axis NS (2: linear MPM tents; 4: uGIMP) as
 * compile-time constants, and instantiated for the six (D, NS) pairs;
 * mpm_kernels_select() picks the family once per job, so no particle loop
 * branches on dimension, method or update scheme.  Weights are recomputed
 * from the particle position in each pass instead of being stored (the
 * paper's S_pr and G_pr arrays of Eqs. 23-24 cost up to 2 KB a particle in
 * 3D GMPM).
 *
 * Shape functions along one axis, with r = (x - x_min)/h, cell c = trunc(r)
 * and f = r - c:
 *   MPM  (Eq. 21):  nodes c, c+1; S = 1-f, f;  G = -1/h, 1/h.
 *   GMPM (Eq. 22):  nodes c-1 .. c+2; with a = lp/h and s = r - node,
 *     S_bar = (F(s+a) - F(s-a)) / (2a)      (Eq. 17, exact integral)
 *     G_bar = (N(s+a) - N(s-a)) / (2 lp)    (Eq. 18)
 *   where N is the unit tent and F its antiderivative, so that sum S_bar = 1
 *   and sum G_bar = 0 telescope exactly.  2D and 3D use the products of
 *   Eqs. 19-20.
 */
#include "mpm_internal.h"

#include <math.h>
#include <stdint.h>

#define INLINE static inline __attribute__((always_inline))
#define MAXN 64 /* 4^3 nodes */

INLINE double tent(double s)
{
    double a = 1.0 - fabs(s);
    return a > 0 ? a : 0;
}

INLINE double tent_int(double s)
{
    s = s < -1 ? -1 : s > 1 ? 1 : s;
    return 0.5 + s - 0.5 * s * fabs(s);
}

/* Weights of one axis; returns the cell index c of x relative to x0.  The
 * weights are those of nodes c, c+1 (NS = 2) or c-1 .. c+2 (NS = 4). */
INLINE int axis(double x, double x0, double inv_h, double lp, int NS, double *w, double *g)
{
    double r = (x - x0) * inv_h;
    int c = (int)r;
    double f = r - c;
    if (NS == 2) {
        w[0] = 1.0 - f;
        w[1] = f;
        g[0] = -inv_h;
        g[1] = inv_h;
    } else {
        double a = lp * inv_h, i2a = 0.5 / a, i2lp = 0.5 / lp;
        for (int k = 0; k < 4; k++) {
            double s = f + 1.0 - k; /* r - (c - 1 + k) */
            w[k] = (tent_int(s + a) - tent_int(s - a)) * i2a;
            g[k] = (tent(s + a) - tent(s - a)) * i2lp;
        }
    }
    return c;
}

int mpm_shape_1d(mpm_method method, double x, double x0, double h, double lp,
                 double *w, double *g)
{
    if (method == MPM_METHOD_GIMP) return axis(x, x0, 1.0 / h, lp, 4, w, g) - 1;
    return axis(x, x0, 1.0 / h, lp, 2, w, g);
}

/* The nodes of particle p: flat padded indices, weights S and gradient
 * weights G[d]. */
typedef struct {
    size_t idx[MAXN];
    double S[MAXN];
    double G[3][MAXN];
} shp;

INLINE void nodes(const mpm_sim *s, size_t p, int D, int NS, shp *o)
{
    double w[3][4], g[3][4];
    size_t base = 0;
    for (int d = 0; d < D; d++) {
        double lp = NS == 4 ? s->P.lp[d][p] : 0;
        int c = axis(s->P.x[d][p], s->x0[d], s->inv_h[d], lp, NS, w[d], g[d]);
        /* w[k] belongs to node c + k (MPM) or c - 1 + k (GMPM, Eq. 22) */
        base += (size_t)(NS == 4 ? c - 1 : c) * s->stride[d];
    }
    int r = 0;
    for (int kz = 0; kz < (D > 2 ? NS : 1); kz++)
        for (int ky = 0; ky < (D > 1 ? NS : 1); ky++) {
            double wy = D > 1 ? w[1][ky] : 1.0, wz = D > 2 ? w[2][kz] : 1.0;
            size_t row = base + (D > 1 ? ky * s->stride[1] : 0) + (D > 2 ? kz * s->stride[2] : 0);
            for (int kx = 0; kx < NS; kx++, r++) {
                o->idx[r] = row + kx;
                o->S[r] = w[0][kx] * wy * wz;
                o->G[0][r] = g[0][kx] * wy * wz;
                if (D > 1) o->G[1][r] = w[0][kx] * g[1][ky] * wz;
                if (D > 2) o->G[2][r] = w[0][kx] * wy * g[2][kz];
            }
        }
}

#define NR(D, NS) ((D) == 1 ? (NS) : (D) == 2 ? (NS) * (NS) : (NS) * (NS) * (NS))

/* Mass and momentum (Eqs. 25-26: momentum extrapolated directly). */
INLINE void p2g_mq_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D, int NS)
{
    shp sh;
    for (size_t p = p0; p < p1; p++) {
        nodes(s, p, D, NS, &sh);
        double mp = s->P.m[p], mv[3];
        for (int d = 0; d < D; d++) mv[d] = mp * s->P.v[d][p];
        for (int r = 0; r < NR(D, NS); r++) {
            size_t n = sh.idx[r];
            gb->m[n] += sh.S[r] * mp;
            for (int d = 0; d < D; d++) gb->q[d][n] += sh.S[r] * mv[d];
        }
    }
}

/* Full stress tensor row a of particle p. */
INLINE double sig_ab(const mpm_particles *P, size_t p, int D, int a, int b)
{
    static const int voigt[3][3] = {{0, 3, 5}, {3, 1, 4}, {5, 4, 2}};
    (void)D;
    return P->sig[voigt[a][b]][p];
}

/* Internal force of particle p onto its nodes: f -= V sigma . G (Eq. 15). */
INLINE void scatter_force(const mpm_sim *s, mpm_gridbuf *gb, size_t p, const shp *sh, int D, int NS)
{
    double vs[3][3];
    double V = s->P.vol[p];
    for (int a = 0; a < D; a++)
        for (int b = 0; b < D; b++) vs[a][b] = V * sig_ab(&s->P, p, D, a, b);
    for (int r = 0; r < NR(D, NS); r++) {
        size_t n = sh->idx[r];
        for (int a = 0; a < D; a++) {
            double fa = 0;
            for (int b = 0; b < D; b++) fa += vs[a][b] * sh->G[b][r];
            gb->f[a][n] -= fa;
        }
    }
}

INLINE void p2g_mqf_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D, int NS)
{
    shp sh;
    for (size_t p = p0; p < p1; p++) {
        nodes(s, p, D, NS, &sh);
        double mp = s->P.m[p], mv[3];
        for (int d = 0; d < D; d++) mv[d] = mp * s->P.v[d][p];
        for (int r = 0; r < NR(D, NS); r++) {
            size_t n = sh.idx[r];
            gb->m[n] += sh.S[r] * mp;
            for (int d = 0; d < D; d++) gb->q[d][n] += sh.S[r] * mv[d];
        }
        scatter_force(s, gb, p, &sh, D, NS);
    }
}

/* MUSL: momentum of the updated particle velocities. */
INLINE void p2g_q2_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D, int NS)
{
    shp sh;
    for (size_t p = p0; p < p1; p++) {
        nodes(s, p, D, NS, &sh);
        double mv[3];
        for (int d = 0; d < D; d++) mv[d] = s->P.m[p] * s->P.v[d][p];
        for (int r = 0; r < NR(D, NS); r++)
            for (int d = 0; d < D; d++) gb->q2[d][sh.idx[r]] += sh.S[r] * mv[d];
    }
}

/* Strain increment (Eq. 29) of particle p from grid momenta qg (velocity
 * q/m, zero at phantom nodes: Fig. 7) into block slot i. */
INLINE void strain_inc(const mpm_sim *s, double *const qg[3], const shp *sh, int D, int NS,
                       double *const deps[6], size_t i)
{
    double L[3][3] = {{0}};
    for (int r = 0; r < NR(D, NS); r++) {
        size_t n = sh->idx[r];
        double mi = s->minv[n];
        for (int a = 0; a < D; a++) {
            double va = qg[a][n] * mi;
            for (int b = 0; b < D; b++) L[a][b] += va * sh->G[b][r];
        }
    }
    double dt = s->dt;
    deps[0][i] = L[0][0] * dt;
    if (D > 1) {
        deps[1][i] = L[1][1] * dt;
        deps[2][i] = D > 2 ? L[2][2] * dt : 0.0;
        deps[3][i] = 0.5 * (L[0][1] + L[1][0]) * dt;
    }
    if (D > 2) {
        deps[4][i] = 0.5 * (L[1][2] + L[2][1]) * dt;
        deps[5][i] = 0.5 * (L[0][2] + L[2][0]) * dt;
    }
}

/* Constitutive update of a block, then the volume follows the strain. */
INLINE void block_update(mpm_sim *s, size_t b0, size_t nb, double *const deps[6], int D)
{
    s->model->update[D - 1](s->mats, &s->P, b0, nb, deps);
    for (size_t i = 0; i < nb; i++) {
        double tr = deps[0][i];
        if (D > 1) tr += deps[1][i] + deps[2][i];
        s->P.vol[b0 + i] *= 1.0 + tr;
    }
}

/* USF: strain and stress from the grid velocity, then internal forces with
 * the new stress. */
INLINE void stress_force_t(mpm_sim *s, mpm_gridbuf *gb, mpm_thread_out *o, size_t p0,
                           size_t p1, int D, int NS)
{
    shp sh;
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        for (size_t i = 0; i < nb; i++) {
            nodes(s, b0 + i, D, NS, &sh);
            strain_inc(s, s->g.q, &sh, D, NS, o->deps, i);
        }
        block_update(s, b0, nb, o->deps, D);
        for (size_t i = 0; i < nb; i++) {
            nodes(s, b0 + i, D, NS, &sh);
            scatter_force(s, gb, b0 + i, &sh, D, NS);
        }
    }
}

/* Checks the updated particle: inside [lo, hi) and finite; the first bad
 * particle of the pass is recorded. */
INLINE void check_particle(const mpm_sim *s, mpm_thread_out *o, size_t p, int D)
{
    int ok = 1;
    double v2 = 0;
    for (int d = 0; d < D; d++) {
        double x = s->P.x[d][p], v = s->P.v[d][p];
        ok &= (x >= s->lo[d]) & (x < s->hi[d]) & (fabs(v) <= 1.79e308);
        v2 += v * v;
    }
    if (v2 > o->vmax2) o->vmax2 = v2;
    if (!ok && o->bad == SIZE_MAX) o->bad = p;
}

/* Eqs. 30-31: x += dt sum S q/m, v += dt sum S qdot/m (phantom nodes: 0). */
INLINE void g2p_xv_one(mpm_sim *s, const shp *sh, size_t p, int D, int NS, int do_x, int do_v)
{
    double dx[3] = {0, 0, 0}, dv[3] = {0, 0, 0};
    for (int r = 0; r < NR(D, NS); r++) {
        size_t n = sh->idx[r];
        double sm = sh->S[r] * s->minv[n];
        for (int d = 0; d < D; d++) {
            if (do_x) dx[d] += sm * s->g.q[d][n];
            if (do_v) dv[d] += sm * s->g.f[d][n];
        }
    }
    for (int d = 0; d < D; d++) {
        if (do_x) s->P.x[d][p] += s->dt * dx[d];
        if (do_v) s->P.v[d][p] += s->dt * dv[d];
    }
}

INLINE void g2p_xv_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int NS)
{
    shp sh;
    for (size_t p = p0; p < p1; p++) {
        nodes(s, p, D, NS, &sh);
        g2p_xv_one(s, &sh, p, D, NS, 1, 1);
        check_particle(s, o, p, D);
    }
}

/* USL (Fig. 6 step 7, then Fig. 7 with the updated grid momentum): the
 * weights of the step's start positions serve both. */
INLINE void g2p_xv_stress_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int NS)
{
    shp sh;
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        for (size_t i = 0; i < nb; i++) {
            size_t p = b0 + i;
            nodes(s, p, D, NS, &sh);
            strain_inc(s, s->g.q, &sh, D, NS, o->deps, i);
            g2p_xv_one(s, &sh, p, D, NS, 1, 1);
            check_particle(s, o, p, D);
        }
        block_update(s, b0, nb, o->deps, D);
    }
}

INLINE void g2p_v_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int NS)
{
    shp sh;
    (void)o;
    for (size_t p = p0; p < p1; p++) {
        nodes(s, p, D, NS, &sh);
        g2p_xv_one(s, &sh, p, D, NS, 0, 1);
    }
}

/* MUSL: positions from the updated grid momentum, strain from the momentum
 * of the updated particle velocities (q2). */
INLINE void g2p_x_stress_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int NS)
{
    shp sh;
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        for (size_t i = 0; i < nb; i++) {
            size_t p = b0 + i;
            nodes(s, p, D, NS, &sh);
            strain_inc(s, s->g.q2, &sh, D, NS, o->deps, i);
            g2p_xv_one(s, &sh, p, D, NS, 1, 0);
            check_particle(s, o, p, D);
        }
        block_update(s, b0, nb, o->deps, D);
    }
}

/* Point forces of the loaded particles (tractions), f += S f_p (Eq. 14). */
INLINE void scatter_loads_t(mpm_sim *s, int D, int NS)
{
    shp sh;
    for (size_t i = 0; i < s->nload; i++) {
        nodes(s, s->load_p[i], D, NS, &sh);
        for (int r = 0; r < NR(D, NS); r++)
            for (int d = 0; d < D; d++) s->g.f[d][sh.idx[r]] += sh.S[r] * s->load_f[d][i];
    }
}

#define FAMILY(D, NS)                                                                          \
    static void p2g_mq_##D##_##NS(mpm_sim *s, mpm_gridbuf *gb, size_t a, size_t b)             \
    { p2g_mq_t(s, gb, a, b, D, NS); }                                                          \
    static void p2g_mqf_##D##_##NS(mpm_sim *s, mpm_gridbuf *gb, size_t a, size_t b)            \
    { p2g_mqf_t(s, gb, a, b, D, NS); }                                                         \
    static void p2g_q2_##D##_##NS(mpm_sim *s, mpm_gridbuf *gb, size_t a, size_t b)             \
    { p2g_q2_t(s, gb, a, b, D, NS); }                                                          \
    static void stress_force_##D##_##NS(mpm_sim *s, mpm_gridbuf *gb, mpm_thread_out *o,        \
                                        size_t a, size_t b)                                    \
    { stress_force_t(s, gb, o, a, b, D, NS); }                                                 \
    static void g2p_xv_##D##_##NS(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b)           \
    { g2p_xv_t(s, o, a, b, D, NS); }                                                           \
    static void g2p_xv_stress_##D##_##NS(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b)    \
    { g2p_xv_stress_t(s, o, a, b, D, NS); }                                                    \
    static void g2p_v_##D##_##NS(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b)            \
    { g2p_v_t(s, o, a, b, D, NS); }                                                            \
    static void g2p_x_stress_##D##_##NS(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b)     \
    { g2p_x_stress_t(s, o, a, b, D, NS); }                                                     \
    static void scatter_loads_##D##_##NS(mpm_sim *s) { scatter_loads_t(s, D, NS); }            \
    static const mpm_kernels family_##D##_##NS = {                                             \
        p2g_mq_##D##_##NS, p2g_mqf_##D##_##NS, p2g_q2_##D##_##NS, stress_force_##D##_##NS,     \
        g2p_xv_##D##_##NS, g2p_xv_stress_##D##_##NS, g2p_v_##D##_##NS,                         \
        g2p_x_stress_##D##_##NS, scatter_loads_##D##_##NS};

FAMILY(1, 2)
FAMILY(1, 4)
FAMILY(2, 2)
FAMILY(2, 4)
FAMILY(3, 2)
FAMILY(3, 4)

const mpm_kernels *mpm_kernels_select(int dim, mpm_method method)
{
    static const mpm_kernels *const table[3][2] = {
        {&family_1_2, &family_1_4}, {&family_2_2, &family_2_4}, {&family_3_2, &family_3_4}};
    return table[dim - 1][method == MPM_METHOD_GIMP];
}
