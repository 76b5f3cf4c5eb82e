/*
 * mpm_kernels.c - the particle loops of one explicit step, specialised by
 * dimension and nodes per axis.
 *
 * Each loop is written once as an always-inline template taking the
 * dimension D, the nodes per axis NS and the shape kind BS as compile-time
 * constants, and instantiated for fifteen (D, NS, BS) families:
 *   NS = 2: linear MPM tents;
 *   NS = 3: uGIMP when every particle's half-width lp <= h/2 (always true
 *           for generated particles): the support |x - x_i| < h + lp then
 *           covers at most 3 nodes per axis;
 *   NS = 4: uGIMP with wider particles (explicit points, lp up to h);
 *   BS = 1: B-splines of degree NS - 1 (BSPLINE2: NS = 3, BSPLINE3:
 *           NS = 4) on the open knot vector, control points c .. c + p.
 * BS only changes the per-axis weights (weights(), bs_axis(), in
 * mpm_shape.h) and the support's first node (box_add()); the node loops
 * are shared.
 * mpm_kernels_select() picks the family once per job, so no particle loop
 * branches on dimension, method, update scheme or features.  A PIC/FLIP
 * blend (mpm_case.pic_fraction > 0) selects the family's blend twin, whose
 * velocity updates alone differ; pure FLIP runs the code it always ran.
 * APIC (mpm_case.transfer) selects the family's APIC twin: its scatters of
 * momentum carry the particles' affine matrices B_p and its velocity
 * updates are PIC's plus B_p (docs/solver.md, "APIC").  The 3-node
 * family evaluates the same weights of the same nodes as the 4-node one and
 * only leaves out a node whose weight and gradient are exactly zero, so
 * both give the same results.
 *
 * MPM tents gather axis by axis (gather_tent(): the multilinear
 * interpolation of the 2^D corners and its differences, about half the
 * operations of the node-by-node sums, in another order).
 * Per particle, the weights and gradients of each axis are computed once
 * into small arrays and the tensor products of Eqs. 19-20 are formed inside
 * the node loops, row by row, never stored (the paper's S_pr and G_pr
 * arrays of Eqs. 23-24 cost up to 2 KB a particle in 3D GMPM).  The USF
 * stress pass keeps the per-axis weights of a block of particles between
 * the strain gather and the force scatter.
 *
 * Shape functions along one axis, with r = (x - x_min)/h, cell c = trunc(r)
 * and f = r - c:
 *   MPM  (Eq. 21):  nodes c, c+1; S = 1-f, f;  G = -1/h, 1/h.
 *   GMPM (Eq. 22):  nodes c-1 .. c+2 (NS = 4), or the three of them
 *     starting at c-1 (f < 1/2) or c (f >= 1/2) (NS = 3); with a = lp/h
 *     and s = r - node,
 *     S_bar = (F(s+a) - F(s-a)) / (2a)      (Eq. 17, exact integral)
 *     G_bar = (N(s+a) - N(s-a)) / (2 lp)    (Eq. 18)
 *   where N is the unit tent and F its antiderivative, so that sum S_bar = 1
 *   and sum G_bar = 0 telescope exactly.
 *   B-splines: control points c .. c + p; the uniform B-splines in the
 *     interior spans, the clamped spans' pieces (mpm_bspline.c) in the p - 1
 *     cells at each end; G = dN/df / h.
 *
 * The passes that move the particles also record, per thread, the box of
 * padded nodes that the new positions' supports touch and, for each row of
 * nodes along x, the first and last node touched; the step zeroes, reduces
 * and updates only those rows' extents (mpm_rows.c).
 */
/* the fixed-trip node loops want complete unrolling (the -O3 kind); not in
 * the sanitizer builds, where -O3 on these 45 families costs minutes of
 * compile time and buys nothing (the results are the same: no fast-math,
 * no contraction) */
#if defined(__GNUC__) && !defined(__clang__) && !defined(__SANITIZE_ADDRESS__) && \
    !defined(__SANITIZE_THREAD__)
#pragma GCC optimize("O3")
#endif

#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_pass.h"
#include "mpm_shape.h"

#include <limits.h>
#include <math.h>
#include <stdint.h>

#ifndef MPM_KERNELS_VARIANT /* once, in the portable build of this file */
int mpm_shape_1d(mpm_method method, double x, double x0, double h, double lp, int nodes, double *w,
                 double *g)
{
    double inv_h = 1.0 / h, r = (x - x0) * inv_h;
    if (method == MPM_METHOD_BSPLINE2 || method == MPM_METHOD_BSPLINE3) {
        int p = method == MPM_METHOD_BSPLINE2 ? 2 : 3;
        mpm_bspline_axis ax;
        mpm_bspline_axis_init(&ax, p, nodes - 1);
        return p == 2 ? bs_axis(&ax, r, inv_h, 3, w, g) : bs_axis(&ax, r, inv_h, 4, w, g);
    }
    if (method == MPM_METHOD_GIMP) return axis(r, inv_h, lp, 4, w, g);
    return axis(r, inv_h, lp, 2, w, g);
}

size_t mpm_kernels_scratch(void)
{
    return MPM_BLOCK * sizeof(pw);
}

#endif /* MPM_KERNELS_VARIANT */

/* Constants of box_add() and check_xv()'s bounds, in locals so that the stores to
 * the particles do not make the loop reload them. */
typedef struct {
    double x0[3], ih[3], rmax[3], lo[3], hi[3];
} boxc;

INLINE void boxc_init(const mpm_sim *s, boxc *b)
{
    for (int d = 0; d < 3; d++) {
        b->x0[d] = s->x0[d];
        b->ih[d] = s->inv_h[d];
        b->rmax[d] = s->rmax[d];
        b->lo[d] = s->lo[d];
        b->hi[d] = s->hi[d];
    }
}

/* The support of a particle at x, added to the current run (or starting a
 * new one).  The cell is clamped to the padded grid as in cell_of(); the
 * support's first and last nodes (n0 - 1 .. n0 + 2 at most) are clamped
 * when the run is flushed.  Within a run the rows of the support change
 * only with 3-node uGIMP.  B-splines (BS): the callers pass the cell c,
 * clamped to the last one as in bs_axis(), and the support is bs_first()
 * .. + NS - 1. */
INLINE void box_cell(const mpm_sim *s, mpm_thread_out *o, rowrun *a, const int c[3],
                     const int n0[3], int D, int NS, int BS);

INLINE void box_add(const mpm_sim *s, const boxc *b, mpm_thread_out *o, rowrun *a,
                    const double x[3], int D, int NS, int BS)
{
    int c[3] = {0, 0, 0}, n0[3] = {0, 0, 0};
    for (int d = 0; d < D; d++) {
        double r = (x[d] - b->x0[d]) * b->ih[d];
        r = r >= 0 ? (r < b->rmax[d] ? r : b->rmax[d]) : 0.0;
        c[d] = (int)r;
        n0[d] = NS == 2 || BS ? c[d] : NS == 4 ? c[d] - 1 : c[d] - 1 + (r - c[d] >= 0.5);
    }
    box_cell(s, o, a, c, n0, D, NS, BS);
}

/* box_add() from the cell c and the support's first nodes n0. */
INLINE void box_cell(const mpm_sim *s, mpm_thread_out *o, rowrun *a, const int c[3],
                     const int nc[3], int D, int NS, int BS)
{
    int n0[3] = {nc[0], nc[1], nc[2]};
    if (BS)
        for (int d = 0; d < D; d++) n0[d] = bs_first(&s->bs[d], nc[d]);
    if (c[1] != a->cy || (D > 2 && c[2] != a->cz)) {
        run_flush(s, o, a, D);
        a->cy = c[1];
        a->cz = c[2];
        a->cx = c[0];
        a->nchg = 1;
        for (int d = 0; d < D; d++) {
            a->lo[d] = n0[d];
            a->hi[d] = n0[d] + NS - 1;
        }
        return;
    }
    a->nchg += c[0] != a->cx; /* the sort's measure (begin_step()) */
    a->cx = c[0];
    for (int d = 0; d < (NS == 3 && !BS ? D : 1); d++) {
        a->lo[d] = n0[d] < a->lo[d] ? n0[d] : a->lo[d];
        a->hi[d] = n0[d] + NS - 1 > a->hi[d] ? n0[d] + NS - 1 : a->hi[d];
    }
}

/* Gradient weight k of axis d: MPM's are the constants -1/h, 1/h. */
#define GRAD(s, W, NS, d, k) ((NS) == 2 ? ((k) ? ih_[d] : -ih_[d]) : (W).g[d][k])
/* MPM's gradient constants in locals, read before the loops store into the
 * grid (a store through a double pointer could otherwise change s->inv_h
 * as far as the compiler knows, and each node would load them again) */
#define IH(s) const double ih_[3] = {(s)->inv_h[0], (s)->inv_h[1], (s)->inv_h[2]}

/* Loop over the support of one particle row by row: for each (ky, kz) the
 * body sees row (flat index of node kx = 0), A = wy wz, B = gy wz and
 * C = wy gz (the factors of S, G_y and G_z apart from the x axis). */
#define ROWS(D, NS, W, s, ...)                                                                    \
    do {                                                                                          \
        const size_t sy_ = (s)->stride[1], sz_ = (s)->stride[2];                                  \
        for (int kz = 0; kz < ((D) > 2 ? (NS) : 1); kz++) {                                       \
            double wz = (D) > 2 ? (W).w[2][kz] : 1.0, gz = (D) > 2 ? GRAD(s, W, NS, 2, kz) : 0.0; \
            for (int ky = 0; ky < ((D) > 1 ? (NS) : 1); ky++) {                                   \
                double wy = (D) > 1 ? (W).w[1][ky] : 1.0;                                         \
                double gy = (D) > 1 ? GRAD(s, W, NS, 1, ky) : 0.0;                                \
                double A = wy * wz, B = gy * wz, C = wy * gz;                                     \
                size_t row =                                                                      \
                    (W).base + (D > 1 ? (size_t)ky * sy_ : 0) + (D > 2 ? (size_t)kz * sz_ : 0);   \
                (void)B;                                                                          \
                (void)C;                                                                          \
                __VA_ARGS__                                                                       \
            }                                                                                     \
        }                                                                                         \
    } while (0)

/* Scatters by four-lane rows (AVX builds, NS 3 and 4): a row's nodes as
 * lanes, one load, multiply-add and store per row and field where the
 * pairs and the odd node took two of each (docs/performance.md).  With
 * NS 3 the fourth lane adds 0 (0 times the row's factors) to the node
 * after the row: in the thread's own buffer, where a sum started from +0
 * is never -0, so x + 0 = x bit for bit; the grid arrays have
 * MPM_GRID_SLACK doubles past their end for the row that ends one.  Each
 * lane does the pairs' arithmetic, so the same bits (MPM_V4: AVX builds). */
#define V4_ADD(ptr, v) (*(v4du *)(ptr) = *(v4du *)(ptr) + (v))
#define V4_SUB(ptr, v) (*(v4du *)(ptr) = *(v4du *)(ptr) - (v))
/* row k of a particle's weights (pw) or offsets (aoff), NS 3 or 4, whole:
 * a 3-node row's lane 3 is 0 there */
#define V4_ROW(W, k, NS) ((void)(NS), (v4d)(*(const v4du *)(W)[k]))

/* The rows of a support of 3 or 4 nodes per axis as ROWS(), with the y
 * factors of one z layer as lanes: Ay, By, Cy hold A, B, C of row ky in
 * lane ky (Wy wz, Gy wz, Wy gz: each lane ROWS()'s product; 1D's one row
 * has A 1 and B, C 0, as ROWS() gives it), and PRE,
 * run once a layer, forms the products of them that the rows use; the
 * body takes row ky's lane of each with V4_LANE(v, ky).  One vector
 * multiply a layer and a lane broadcast (vpermpd) per row where a scalar
 * multiply and a broadcast were (same bits; broadcast loads of A, B, C
 * with a multiply per row were slower: docs/performance.md). */
#define V4_LANE(v, k)                                           \
    ((k) == 0   ? __builtin_shufflevector((v), (v), 0, 0, 0, 0) \
     : (k) == 1 ? __builtin_shufflevector((v), (v), 1, 1, 1, 1) \
     : (k) == 2 ? __builtin_shufflevector((v), (v), 2, 2, 2, 2) \
                : __builtin_shufflevector((v), (v), 3, 3, 3, 3))
#define ROWS4(D, NS, W, s, PRE, ...)                                                         \
    do {                                                                                     \
        const size_t sy_ = (s)->stride[1], sz_ = (s)->stride[2];                             \
        const v4d Wy = (D) > 1 ? V4_ROW((W).w, 1, NS) : (v4d){1, 1, 1, 1};                   \
        const v4d Gy = (D) > 1 ? V4_ROW((W).g, 1, NS) : (v4d){0, 0, 0, 0};                   \
        for (int kz = 0; kz < ((D) > 2 ? (NS) : 1); kz++) {                                  \
            const double wz = (D) > 2 ? (W).w[2][kz] : 1.0;                                  \
            const double gz = (D) > 2 ? (W).g[2][kz] : 0.0;                                  \
            const v4d Ay = (D) > 2 ? Wy * wz : Wy, By = (D) > 2 ? Gy * wz : Gy;              \
            const v4d Cy = Wy * gz;                                                          \
            (void)By;                                                                        \
            (void)Cy;                                                                        \
            PRE;                                                                             \
            UNROLL                                                                           \
            for (int ky = 0; ky < (NS); ky++) {                                              \
                if ((D) == 1 && ky > 0) break; /* 1D: one row */                             \
                size_t row = (W).base + (size_t)ky * sy_ + ((D) > 2 ? (size_t)kz * sz_ : 0); \
                __VA_ARGS__                                                                  \
            }                                                                                \
        }                                                                                    \
    } while (0)

/* Mass and momentum (Eqs. 25-26: momentum extrapolated directly). */
INLINE void scatter_mq(const mpm_sim *s, mpm_gridbuf *gb, const pw *W0, size_t p, int D, int NS)
{
    const pw Wc = *W0, *W = &Wc; /* locals: the stores below cannot change them */
    IH(s);
    double *restrict m = gb->m;
    double *restrict q0 = gb->q[0], *restrict q1 = gb->q[1], *restrict q2 = gb->q[2];
    double mp = s->P.m[p];
    double mv0 = mp * s->P.v[0][p];
    double mv1 = D > 1 ? mp * s->P.v[1][p] : 0.0, mv2 = D > 2 ? mp * s->P.v[2][p] : 0.0;
    if (MPM_V4 && NS > 2) {
        const v4d S = V4_ROW(W->w, 0, NS);
        v4d am, a0, a1, a2;
        ROWS4(D, NS, *W, s, (am = Ay * mp, a0 = Ay * mv0, a1 = Ay * mv1, a2 = Ay * mv2), {
            V4_ADD(m + row, S * V4_LANE(am, ky));
            V4_ADD(q0 + row, S * V4_LANE(a0, ky));
            if (D > 1) V4_ADD(q1 + row, S * V4_LANE(a1, ky));
            if (D > 2) V4_ADD(q2 + row, S * V4_LANE(a2, ky));
        });
        return;
    }
    ROWS(D, NS, *W, s, {
        double am = A * mp, a0 = A * mv0, a1 = A * mv1, a2 = A * mv2;
        UNROLL
        for (int kx = 0; kx + 1 < NS; kx += 2) {
            v2d S = {W->w[0][kx], W->w[0][kx + 1]};
            size_t n = row + (size_t)kx;
            v2_st(m + n, v2_ld(m + n) + S * am);
            v2_st(q0 + n, v2_ld(q0 + n) + S * a0);
            if (D > 1) v2_st(q1 + n, v2_ld(q1 + n) + S * a1);
            if (D > 2) v2_st(q2 + n, v2_ld(q2 + n) + S * a2);
        }
        if (NS & 1) {
            double S = W->w[0][NS - 1];
            size_t n = row + (size_t)(NS - 1);
            m[n] += S * am;
            q0[n] += S * a0;
            if (D > 1) q1[n] += S * a1;
            if (D > 2) q2[n] += S * a2;
        }
    });
}

/* APIC: the matrix the scatter applies, times the particle mass mp.
 * NS = 2 (MPM tents): B_p itself, scattered with the gradient as
 * mp B_p grad S_ip (Jiang's multilinear form: D_p grad S_ip = S_ip
 * (x_i - x_p) for tents, so it equals mp S_ip B_p D_p^-1 (x_i - x_p)
 * wherever D_p is invertible, and it stays defined on grid lines, where
 * D_p is singular).  Otherwise: C_p = B_p D_p^-1 with D_p diagonal (a
 * tensor-product shape with linear precision), D_dd = sum_k S_dk r_dk^2
 * per axis, > 0 for uGIMP (lp > 0 spreads every particle over two nodes
 * or more). */
INLINE void affine_matrix(const mpm_sim *s, const pw *W, const aoff *R, size_t p, double mp, int D,
                          int NS, double Cm[3][3])
{
    double dinv[3] = {mp, mp, mp};
    if (NS != 2)
        for (int d = 0; d < D; d++) {
            double dd = 0;
            for (int k = 0; k < NS; k++) dd += W->w[d][k] * R->r[d][k] * R->r[d][k];
            dinv[d] = mp / dd;
        }
    for (int a = 0; a < D; a++)
        for (int b = 0; b < D; b++) Cm[a][b] = s->P.B[3 * a + b][p] * dinv[b];
}

/* APIC momentum (and mass into m when WM) of particle p into q:
 * sum_i S_ip mp (v_p + C_p (x_i - x_p)), or for MPM tents
 * mp (S_ip v_p + B_p grad S_ip) (affine_matrix()).  Row by row, with
 * (x_i - x_p) = (r0[kx], r1[ky], r2[kz]) and grad S = (gx A, wx B, wx C):
 * q_a += wx t_a + e u_a, e = wx r0[kx] (or gx), u_a = A Cm_a0. */
INLINE void scatter_affine(const mpm_sim *s, double *restrict m, double *const q[3], const pw *W,
                           const aoff *R, size_t p, int D, int NS, int WM)
{
    IH(s);
    double *restrict q0 = q[0], *restrict q1 = q[1], *restrict q2 = q[2];
    double mp = s->P.m[p], Cm[3][3];
    double mv[3] = {0, 0, 0};
    for (int a = 0; a < D; a++) mv[a] = mp * s->P.v[a][p];
    affine_matrix(s, W, R, p, mp, D, NS, Cm);
    ROWS(D, NS, *W, s, {
        double t[3] = {0, 0, 0}, u[3] = {0, 0, 0};
        for (int a = 0; a < D; a++) {
            double ta = mv[a];
            if (NS == 2) {
                ta *= A;
                if (D > 1) ta += B * Cm[a][1];
                if (D > 2) ta += C * Cm[a][2];
            } else {
                if (D > 1) ta += Cm[a][1] * R->r[1][ky];
                if (D > 2) ta += Cm[a][2] * R->r[2][kz];
                ta *= A;
            }
            t[a] = ta;
            u[a] = A * Cm[a][0];
        }
        double am = A * mp;
        if (MPM_V4 && NS > 2) {
            const v4d S = V4_ROW(W->w, 0, NS), e = S * V4_ROW(R->r, 0, NS);
            if (WM) V4_ADD(m + row, S * am);
            V4_ADD(q0 + row, S * t[0] + e * u[0]);
            if (D > 1) V4_ADD(q1 + row, S * t[1] + e * u[1]);
            if (D > 2) V4_ADD(q2 + row, S * t[2] + e * u[2]);
            continue; /* the next row */
        }
        /* nodes in pairs, each lane the scalar tail's operations */
        UNROLL
        for (int kx = 0; kx + 1 < NS; kx += 2) {
            v2d S = {W->w[0][kx], W->w[0][kx + 1]}, e;
            if (NS == 2) {
                v2d g = {GRAD(s, *W, NS, 0, 0), GRAD(s, *W, NS, 0, 1)};
                e = g;
            } else {
                v2d r = {R->r[0][kx], R->r[0][kx + 1]};
                e = S * r;
            }
            size_t n = row + (size_t)kx;
            if (WM) v2_st(m + n, v2_ld(m + n) + S * am);
            v2_st(q0 + n, v2_ld(q0 + n) + (S * t[0] + e * u[0]));
            if (D > 1) v2_st(q1 + n, v2_ld(q1 + n) + (S * t[1] + e * u[1]));
            if (D > 2) v2_st(q2 + n, v2_ld(q2 + n) + (S * t[2] + e * u[2]));
        }
        if (NS & 1) {
            const int kx = NS - 1;
            double S = W->w[0][kx], e = S * R->r[0][kx];
            size_t n = row + (size_t)kx;
            if (WM) m[n] += S * am;
            q0[n] += S * t[0] + e * u[0];
            if (D > 1) q1[n] += S * t[1] + e * u[1];
            if (D > 2) q2[n] += S * t[2] + e * u[2];
        }
    });
}

/* Internal force of particle p onto its nodes: f -= V sigma . G (Eq. 15).
 * With G = (gx A, wx B, wx C): f_a -= gx (V s_a0 A) + wx (V s_a1 B + V s_a2 C). */
INLINE void scatter_force(const mpm_sim *s, mpm_gridbuf *gb, const pw *W0, size_t p, int D, int NS)
{
    const pw Wc = *W0, *W = &Wc; /* locals: the stores below cannot change them */
    IH(s);
    double *restrict f0 = gb->f[0], *restrict f1 = gb->f[1], *restrict f2 = gb->f[2];
    const mpm_particles *P = &s->P;
    double V = P->vol[p];
    double sxx = V * P->sig[0][p];
    double syy = D > 1 ? V * P->sig[1][p] : 0.0, sxy = D > 1 ? V * P->sig[3][p] : 0.0;
    double szz = D > 2 ? V * P->sig[2][p] : 0.0, syz = D > 2 ? V * P->sig[4][p] : 0.0;
    double sxz = D > 2 ? V * P->sig[5][p] : 0.0;
    if (MPM_V4 && NS > 2) {
        const v4d gx = V4_ROW(W->g, 0, NS), wx = V4_ROW(W->w, 0, NS);
        v4d P0, P1, P2, Q0, Q1, Q2;
        ROWS4(D, NS, *W, s,
              (P0 = Ay * sxx, P1 = Ay * sxy, P2 = Ay * sxz,
               Q0 = D > 2 ? By * sxy + Cy * sxz : By * sxy,
               Q1 = D > 2 ? By * syy + Cy * syz : By * syy, Q2 = By * syz + Cy * szz),
              {
                  if (D == 1)
                      V4_SUB(f0 + row, gx * V4_LANE(P0, ky));
                  else
                      V4_SUB(f0 + row, gx * V4_LANE(P0, ky) + wx * V4_LANE(Q0, ky));
                  if (D > 1) V4_SUB(f1 + row, gx * V4_LANE(P1, ky) + wx * V4_LANE(Q1, ky));
                  if (D > 2) V4_SUB(f2 + row, gx * V4_LANE(P2, ky) + wx * V4_LANE(Q2, ky));
              });
        return;
    }
    ROWS(D, NS, *W, s, {
        double P0 = sxx * A, P1 = sxy * A, P2 = sxz * A;
        /* 2D: no z terms (C is 0 there, and 0 * C is not folded away) */
        double Q0 = D > 2 ? sxy * B + sxz * C : sxy * B;
        double Q1 = D > 2 ? syy * B + syz * C : syy * B, Q2 = syz * B + szz * C;
        UNROLL
        for (int kx = 0; kx + 1 < NS; kx += 2) {
            v2d gx = {GRAD(s, *W, NS, 0, kx), GRAD(s, *W, NS, 0, kx + 1)};
            v2d wx = {W->w[0][kx], W->w[0][kx + 1]};
            size_t n = row + (size_t)kx;
            if (D == 1)
                v2_st(f0 + n, v2_ld(f0 + n) - gx * P0);
            else
                v2_st(f0 + n, v2_ld(f0 + n) - (gx * P0 + wx * Q0));
            if (D > 1) v2_st(f1 + n, v2_ld(f1 + n) - (gx * P1 + wx * Q1));
            if (D > 2) v2_st(f2 + n, v2_ld(f2 + n) - (gx * P2 + wx * Q2));
        }
        if (NS & 1) {
            double gx = GRAD(s, *W, NS, 0, NS - 1), wx = W->w[0][NS - 1];
            size_t n = row + (size_t)(NS - 1);
            if (D == 1)
                f0[n] -= gx * P0;
            else
                f0[n] -= gx * P0 + wx * Q0;
            if (D > 1) f1[n] -= gx * P1 + wx * Q1;
            if (D > 2) f2[n] -= gx * P2 + wx * Q2;
        }
    });
}

#include "mpm_gather.inc" /* the gathers (phantom_grad, gather_tent, gather_rows) */
#include "mpm_tlane.inc"  /* the tents' gathers by lanes (AVX builds) */
#include "mpm_trun.inc"   /* the tents' run scatter (trun) */

/* MPM tents gathered four particles at a time (mpm_tlane.inc) */
#define TL(D, NS, BS, AP) (MPM_V4 && (D) > 1 && (NS) == 2 && !(BS) && !(AP))
/* ... and USF's moving pass by them, in 3D only (in 2D it was slower:
 * docs/performance.md) */
#define TLM(D, NS, BS, AP) (TL(D, NS, BS, AP) && (D) > 2)

/* APIC's scatter weights: MPM tents scatter with the gradients and need
 * no node offsets (affine_matrix()). */
INLINE void p2g_weights(const mpm_sim *s, size_t p, int D, int NS, int BS, pw *W, aoff *R)
{
    if (NS == 2)
        weights(s, p, D, NS, 0, W);
    else
        weights_ap(s, p, D, NS, BS, W, R);
}

/* The first scatter of one particle: mass and momentum (AP: APIC, the
 * momentum with the affine part, scatter_affine()) and, WF, the internal
 * force.  Also what the fused passes scatter for the next step. */
INLINE void p2g_one(mpm_sim *s, mpm_gridbuf *gb, size_t p, int D, int NS, int BS, int AP, int WF)
{
    pw W;
    aoff R;
    if (AP) {
        p2g_weights(s, p, D, NS, BS, &W, &R);
        scatter_affine(s, gb->m, gb->q, &W, &R, p, D, NS, 1);
    } else {
        weights(s, p, D, NS, BS, &W);
        scatter_mq(s, gb, &W, p, D, NS);
    }
    if (WF) scatter_force(s, gb, &W, p, D, NS);
}

/* Tents without APIC scatter by runs (trun). */
#define TR(NS, BS, AP) ((NS) == 2 && !(BS) && !(AP))

/* The first scatter of particles [p0, p1) (WF: with the force). */
INLINE void p2g_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D, int NS, int BS, int AP,
                  int WF)
{
    if (TR(NS, BS, AP)) {
        trun r;
        pw W;
        trun_init(&r, D);
        for (size_t p = p0; p < p1; p++) {
            weights(s, p, D, NS, BS, &W);
            trun_add(s, &r, gb, &W, p, D, 1, WF);
        }
        trun_flush(s, &r, gb, D, 1, WF);
        return;
    }
    for (size_t p = p0; p < p1; p++) p2g_one(s, gb, p, D, NS, BS, AP, WF);
}

INLINE void p2g_mq_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D, int NS, int BS,
                     int AP)
{
    p2g_t(s, gb, p0, p1, D, NS, BS, AP, 0);
}

INLINE void p2g_mqf_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D, int NS, int BS,
                      int AP)
{
    p2g_t(s, gb, p0, p1, D, NS, BS, AP, 1);
}

/* The next step's scatter from a moving pass, particles [b0, b1) at their
 * new positions (WF: with the force); tents by runs into r (flushed by
 * the caller after the last block), with the block's weight slots Wb as
 * scratch. */
INLINE void next_scatter(mpm_sim *s, mpm_gridbuf *nx, trun *r, pw *Wb, size_t b0, size_t b1, int D,
                         int NS, int BS, int AP, int WF)
{
    if (BS && !AP && (WF || D > 2)) {
        /* B-splines with the force (USL, MUSL) and 3D USF: the block's
         * weights first, four at a time */
        weights_block(s, b0, b1 - b0, D, NS, BS, Wb);
        for (size_t p = b0; p < b1; p++) {
            scatter_mq(s, nx, &Wb[p - b0], p, D, NS);
            if (WF) scatter_force(s, nx, &Wb[p - b0], p, D, NS);
        }
        return;
    }
    if (!BS && !AP && NS > 2 && WF) {
        /* uGIMP with the force (USL, MUSL): the block's weights first, as
         * B-splines */
        weights_block(s, b0, b1 - b0, D, NS, BS, Wb);
        for (size_t p = b0; p < b1; p++) {
            scatter_mq(s, nx, &Wb[p - b0], p, D, NS);
            if (WF) scatter_force(s, nx, &Wb[p - b0], p, D, NS);
        }
        return;
    }
    if (!TR(NS, BS, AP)) {
        for (size_t p = b0; p < b1; p++) p2g_one(s, nx, p, D, NS, BS, AP, WF);
        return;
    }
    weights_block(s, b0, b1 - b0, D, NS, BS, Wb);
    for (size_t p = b0; p < b1; p++) trun_add(s, r, nx, &Wb[p - b0], p, D, 1, WF);
}

/* MUSL: momentum of the updated velocity of particle p into q (weights W). */
INLINE void scatter_q2(const mpm_sim *s, double *const q[3], const pw *W0, size_t p, int D, int NS)
{
    const pw Wc = *W0, *W = &Wc; /* locals: the stores below cannot change them */
    IH(s);
    double *restrict q0 = q[0], *restrict q1 = q[1], *restrict q2 = q[2];
    double mp = s->P.m[p];
    double mv0 = mp * s->P.v[0][p];
    double mv1 = D > 1 ? mp * s->P.v[1][p] : 0.0, mv2 = D > 2 ? mp * s->P.v[2][p] : 0.0;
    if (MPM_V4 && NS > 2) {
        const v4d S = V4_ROW(W->w, 0, NS);
        v4d a0, a1, a2;
        ROWS4(D, NS, *W, s, (a0 = Ay * mv0, a1 = Ay * mv1, a2 = Ay * mv2), {
            V4_ADD(q0 + row, S * V4_LANE(a0, ky));
            if (D > 1) V4_ADD(q1 + row, S * V4_LANE(a1, ky));
            if (D > 2) V4_ADD(q2 + row, S * V4_LANE(a2, ky));
        });
        return;
    }
    ROWS(D, NS, *W, s, {
        double a0 = A * mv0, a1 = A * mv1, a2 = A * mv2;
        UNROLL
        for (int kx = 0; kx < NS; kx++) {
            double S = W->w[0][kx];
            size_t n = row + (size_t)kx;
            q0[n] += S * a0;
            if (D > 1) q1[n] += S * a1;
            if (D > 2) q2[n] += S * a2;
        }
    });
}

/* USF: strain and stress from the grid velocity, then internal forces with
 * the new stress; the weights of the block are kept between the two. */
INLINE void stress_force_t(mpm_sim *s, mpm_gridbuf *gb, mpm_thread_out *o, size_t p0, size_t p1,
                           int D, int NS, int BS, int EN)
{
    pw *Wb = o->wblk;
    esum e;
    trun r;
    trun_init(&r, D);
    if (EN) esum_init(s, &e);
#if MPM_V4
    wgeo G;
    if (TL(D, NS, BS, 0)) wgeo_init(s, D, NS, BS, &G);
#endif
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        weights_block(s, b0, nb, D, NS, BS, Wb);
        size_t i = 0;
#if MPM_V4
        if (TL(D, NS, BS, 0) && !EN && s->plan.el_lanes) {
            el_block(s, o, gb, &G, &r, b0, nb, D);
            continue;
        }
#endif
#if MPM_V4
        /* tents: the runs' strains by lanes, four particles of a run at a
         * time (the lanes past the run are written and then overwritten
         * by the particles that own them); a cell with a phantom corner,
         * and the block's last particles, one by one */
        unsigned char kk[MPM_BLOCK];
        if (TL(D, NS, BS, 0)) {
            size_t bb[MPM_BLOCK];
            for (size_t j = 0; j < nb; j++) bb[j] = Wb[j].base;
            tl_counts(bb, nb, kk);
            while (i + 4 <= nb) {
                unsigned k = kk[i];
                if (__builtin_expect(tl_phantom(s, Wb[i].base, D), 0)) {
                    for (unsigned j = 0; j < k; j++, i++)
                        gather(s, &Wb[i], D, NS,
                               (gather_req){.strain = 1, .qg = s->g.q, .deps = o->deps, .i = i});
                    continue;
                }
                tlane t;
                tlane_weights(&G, s->P.x, b0 + i, D, Wb[i].base, k, &t);
                tl_strain(s, s->g.q, &t, D, o->deps, i);
                i += k;
            }
        }
#endif
        for (; i < nb; i++)
            gather(s, &Wb[i], D, NS,
                   (gather_req){.strain = 1, .qg = s->g.q, .deps = o->deps, .i = i});
        block_update(s, o, b0, nb, D);
        if (EN) esum_strain(s, &e, b0, nb, D);
        i = 0;
#if MPM_V4
        /* 2D tents: the forces by lanes too (a run's four at a time) */
        if (TL(D, NS, BS, 0) && D == 2)
            while (i + 4 <= nb) {
                tlane t;
                tlane_weights(&G, s->P.x, b0 + i, D, Wb[i].base, kk[i], &t);
                tl_force2(s, &r, gb, &t, b0 + i);
                i += kk[i];
            }
#endif
        for (; i < nb; i++)
            if (TR(NS, BS, 0))
                trun_add(s, &r, gb, &Wb[i], b0 + i, D, 0, 1);
            else
                scatter_force(s, gb, &Wb[i], b0 + i, D, NS);
    }
    if (TR(NS, BS, 0)) trun_flush(s, &r, gb, D, 0, 1);
    if (EN) esum_store(&e, o, 0, 1);
}

/* APIC's velocity update: the PIC velocity vpic = sum S v_I^{n+1} (the
 * position increment's sum) and the affine matrix Bm into B_p. */
INLINE void ap_store(mpm_sim *s, size_t p, int D, const double vpic[3], double Bm[3][3])
{
    for (int a = 0; a < D; a++) {
        s->P.v[a][p] = vpic[a];
        for (int b = 0; b < D; b++) s->P.B[3 * a + b][p] = Bm[a][b];
    }
}

/* The second loop over a block of moved particles [b0, b1): the checks,
 * the energy sums (EN) and the supports.  The moving passes update a block
 * first and then run this: two small loops rather than one large one that
 * runs out of registers. */
INLINE void moved_block(mpm_sim *s, mpm_thread_out *o, const boxc *bc, chk *ck, esum *e, rowrun *a,
                        size_t b0, size_t b1, int D, int NS, int BS, int EN, int AP)
{
    size_t p = b0;
#if MPM_V4
    /* four particles at a time when all four pass the checks (else the
     * loop below takes them, to find the first bad one): the checks and
     * cells by lanes, each lane check_xv()'s and box_add()'s operations */
    for (; p + 4 <= b1; p += 4) {
        const v4d big = {1.79e308, 1.79e308, 1.79e308, 1.79e308}, zero = {0, 0, 0, 0};
        v4d v2 = zero, r[3];
        v4l ok = {-1, -1, -1, -1};
        for (int d = 0; d < D; d++) {
            v4d x = *(const v4du *)(s->P.x[d] + p), v = *(const v4du *)(s->P.v[d] + p);
            ok &= (x >= bc->lo[d]) & (x < bc->hi[d]) & (v <= big) & (v >= -big);
            v2 = v2 + v * v;
            v4d rd = (x - bc->x0[d]) * bc->ih[d], rm = zero + bc->rmax[d];
            v4l lt = rd < rm, ge = rd >= zero;
            r[d] = (v4d)((((v4l)rd & lt) | ((v4l)rm & ~lt)) & ge);
        }
        if (!v4l_all(ok)) break;
        double m01 = v2[0] > v2[1] ? v2[0] : v2[1], m23 = v2[2] > v2[3] ? v2[2] : v2[3];
        double m = m01 > m23 ? m01 : m23;
        ck->vmax2 = m > ck->vmax2 ? m : ck->vmax2;
        v4i c[3], n0[3];
        for (int d = 0; d < D; d++) {
            c[d] = __builtin_convertvector(r[d], v4i);
            n0[d] = c[d];
            if (NS == 4 && !BS) n0[d] = c[d] - 1;
            if (NS == 3 && !BS) {
                v4l up = (r[d] - __builtin_convertvector(c[d], v4d)) >= 0.5;
                n0[d] = c[d] - 1 - __builtin_convertvector(up, v4i);
            }
        }
        /* a lane in the cell of the lane before it (and with its first
         * nodes) adds nothing: box_cell() of one cell twice in a row
         * leaves the run as the first call left it (its row, cx and node
         * box), so only the lanes that start a cell are added; sorted
         * particles come in runs of a cell */
        v4i same = {0, -1, -1, -1};
        for (int d = 0; d < D; d++) {
            same &= c[d] == __builtin_shufflevector(c[d], c[d], 0, 0, 1, 2);
            if (NS == 3 && !BS) same &= n0[d] == __builtin_shufflevector(n0[d], n0[d], 0, 0, 1, 2);
        }
        unsigned starts =
            ~(unsigned)__builtin_ia32_movmskps((__attribute__((vector_size(16))) float)same) & 15u;
        for (int j = 0; j < 4; j++) {
            if (!(starts >> j & 1u)) continue;
            int cj[3] = {0, 0, 0}, nj[3] = {0, 0, 0};
            for (int d = 0; d < D; d++) {
                cj[d] = c[d][j];
                nj[d] = n0[d][j];
            }
            box_cell(s, o, a, cj, nj, D, NS, BS);
        }
    }
#endif
    for (; p < b1; p++) {
        double xn[3], vn[3];
        for (int d = 0; d < D; d++) {
            xn[d] = s->P.x[d][p];
            vn[d] = s->P.v[d][p];
        }
        check_xv(bc->lo, bc->hi, ck, p, xn, vn, D);
        box_add(s, bc, o, a, xn, D, NS, BS);
    }
    if (EN) esum_block(s, e, b0, b1, D, AP, 1);
}

/* Eqs. 30-31: x += dt sum S q/m, v += dt sum S qdot/m (phantom nodes: 0);
 * BL: the velocity blended with PIC (v_update()); AP: APIC, v = sum S q/m
 * and B_p = sum S q/m (x_I - x_p)^T (ap_store()). */
INLINE void g2p_xv_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int NS, int BS,
                     int EN, int BL, int AP, mpm_gridbuf *nx)
{
    pw W, *Wb = o->wblk;
    aoff R;
    rowrun a;
    boxc bc;
    chk ck;
    esum e;
    double dt = s->dt, al = BL ? s->pic : 0.0, bl = 1.0 - al;
    if (EN) esum_init(s, &e);
    box_reset(s, o, D);
    run_init(&a);
    boxc_init(s, &bc);
    chk_init(o, &ck);
    trun nr;
    trun_init(&nr, D);
#if MPM_V4
    wgeo G;
    if (TLM(D, NS, BS, AP)) wgeo_init(s, D, NS, BS, &G);
#endif
    /* by blocks: the update, then the checks and supports, then the next
     * step's scatter, three small loops rather than one that spills */
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t b1 = p1 - b0 < MPM_BLOCK ? p1 : b0 + MPM_BLOCK;
        /* the block's weights first: tents, B-splines and 2D uGIMP (3D
         * uGIMP's are taken where they are used: no gain there); tents
         * by lanes (AVX builds) take theirs there */
        const int BW = !AP && !TLM(D, NS, BS, AP) && (NS == 2 || BS || D < 3);
        if (BW) weights_block(s, b0, b1 - b0, D, NS, BS, Wb);
#if MPM_V4
        size_t bb[MPM_BLOCK];
        unsigned char kk[MPM_BLOCK];
        tlcopy cp;
        if (TLM(D, NS, BS, AP)) tl_groups(s, &G, b0, b1 - b0, D, bb, kk, &cp);
#endif
        for (size_t p = b0; p < b1; p++) {
            double dx[3], dv[3], Bm[3][3];
#if MPM_V4
            /* tents: four particles of a run at a time (the block's last,
             * and a cell with a phantom corner, one by one) */
            size_t i = p - b0;
            if (TLM(D, NS, BS, AP) && p + 4 <= b1 &&
                tl_move(s, &G, p, bb[i], kk[i], D, BL, al, bl, 0, NULL, &cp, i)) {
                p += kk[i] - 1u;
                continue;
            }
#endif
            if (AP) {
                weights_ap(s, p, D, NS, BS, &W, &R);
                gather(
                    s, &W, D, NS,
                    (gather_req){
                        .pos = 1, .affine = 1, .qx = s->g.q, .dx = dx, .R = &R, .Bo = Bm, .vp = 1});
                ap_store(s, p, D, dx, Bm);
            } else {
                const pw *Wp = &W;
                if (BW)
                    Wp = &Wb[p - b0];
                else
                    weights(s, p, D, NS, BS, &W);
                gather(s, Wp, D, NS,
                       (gather_req){.pos = 1, .qx = s->g.q, .dx = dx, .vel = 1, .dv = dv, .vp = 1});
            }
            for (int d = 0; d < D; d++) {
                s->P.x[d][p] += dt * dx[d];
                if (!AP) v_update(&s->P.v[d][p], dt, dv[d], dx[d], BL, al, bl);
            }
        }
        moved_block(s, o, &bc, &ck, &e, &a, b0, b1, D, NS, BS, EN, AP);
        if (nx && ck.bad == SIZE_MAX) next_scatter(s, nx, &nr, Wb, b0, b1, D, NS, BS, AP, 0);
    }
    if (nx && TR(NS, BS, AP)) trun_flush(s, &nr, nx, D, 1, 0);
    chk_store(&ck, o);
    run_flush(s, o, &a, D);
    if (EN) esum_store(&e, o, 1, 0);
}

/* USL (Fig. 6 step 7, then Fig. 7 with the updated grid momentum): the
 * weights of the step's start positions serve both, in one gather. */
INLINE void g2p_xv_stress_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int NS,
                            int BS, int EN, int BL, int AP, mpm_gridbuf *nx)
{
    pw W, *Wb = o->wblk;
    aoff R;
    rowrun a;
    boxc bc;
    chk ck;
    esum e;
    double dt = s->dt, al = BL ? s->pic : 0.0, bl = 1.0 - al;
    if (EN) esum_init(s, &e);
    box_reset(s, o, D);
    run_init(&a);
    boxc_init(s, &bc);
    chk_init(o, &ck);
    trun nr;
    trun_init(&nr, D);
#if MPM_V4
    wgeo G;
    if (TL(D, NS, BS, AP)) wgeo_init(s, D, NS, BS, &G);
#endif
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        /* the block's weights first (uGIMP too); tents by lanes (AVX
         * builds) take theirs there */
        const int BW = !AP && !TL(D, NS, BS, AP);
        if (BW) weights_block(s, b0, nb, D, NS, BS, Wb);
#if MPM_V4
        size_t bb[MPM_BLOCK];
        unsigned char kk[MPM_BLOCK];
        tlcopy cp;
        if (TL(D, NS, BS, AP)) tl_groups(s, &G, b0, nb, D, bb, kk, &cp);
#endif
        for (size_t i = 0; i < nb; i++) {
            size_t p = b0 + i;
            double dx[3], dv[3], Bm[3][3];
#if MPM_V4
            /* tents: four particles of a run at a time (the block's last,
             * and a cell with a phantom corner, one by one) */
            if (TL(D, NS, BS, AP) && i + 4 <= nb &&
                tl_move(s, &G, p, bb[i], kk[i], D, BL, al, bl, 1, o->deps, &cp, i)) {
                i += kk[i] - 1u;
                continue;
            }
#endif
            if (AP) {
                weights_ap(s, p, D, NS, BS, &W, &R);
                gather(s, &W, D, NS,
                       (gather_req){.strain = 1,
                                    .qg = s->g.q,
                                    .deps = o->deps,
                                    .i = i,
                                    .pos = 1,
                                    .affine = 1,
                                    .qx = s->g.q,
                                    .dx = dx,
                                    .R = &R,
                                    .Bo = Bm,
                                    .vp = 1});
                ap_store(s, p, D, dx, Bm);
            } else {
                const pw *Wp = &W;
                if (BW)
                    Wp = &Wb[i];
                else
                    weights(s, p, D, NS, BS, &W);
                gather(s, Wp, D, NS,
                       (gather_req){.strain = 1,
                                    .qg = s->g.q,
                                    .deps = o->deps,
                                    .i = i,
                                    .pos = 1,
                                    .qx = s->g.q,
                                    .dx = dx,
                                    .vel = 1,
                                    .dv = dv,
                                    .vp = 1});
            }
            for (int d = 0; d < D; d++) {
                s->P.x[d][p] += dt * dx[d];
                if (!AP) v_update(&s->P.v[d][p], dt, dv[d], dx[d], BL, al, bl);
            }
        }
        moved_block(s, o, &bc, &ck, &e, &a, b0, b0 + nb, D, NS, BS, EN, AP);
        block_update(s, o, b0, nb, D);
        if (EN) esum_strain(s, &e, b0, nb, D);
        if (nx && ck.bad == SIZE_MAX) next_scatter(s, nx, &nr, Wb, b0, b0 + nb, D, NS, BS, AP, 1);
    }
    if (nx && TR(NS, BS, AP)) trun_flush(s, &nr, nx, D, 1, 1);
    chk_store(&ck, o);
    run_flush(s, o, &a, D);
    if (EN) esum_store(&e, o, 1, 1);
}

/* MUSL: the velocity only (BL: blended with PIC; AP: APIC's velocity and
 * B_p) and, q2b not NULL, with the same weights, what p2g_q2 maps back to
 * the grid: the momentum of the updated velocity (and B_p) into q2b. */
INLINE void g2p_v_t(mpm_sim *s, mpm_gridbuf *q2b, size_t p0, size_t p1, int D, int NS, int BS,
                    int BL, int AP)
{
    pw W;
    aoff R;
    double dt = s->dt, al = BL ? s->pic : 0.0, bl = 1.0 - al;
    if (BS && !AP) { /* B-splines: a block's weights first, four at a time */
        enum { NB = 16 };
        pw Wl[NB];
        for (size_t b0 = p0; b0 < p1; b0 += NB) {
            size_t nb = p1 - b0 < NB ? p1 - b0 : NB;
            weights_block(s, b0, nb, D, NS, BS, Wl);
            for (size_t i = 0; i < nb; i++) {
                size_t p = b0 + i;
                double dv[3], vp[3] = {0, 0, 0};
                gather(
                    s, &Wl[i], D, NS,
                    (gather_req){.pos = BL, .qx = s->g.q, .dx = vp, .vel = 1, .dv = dv, .vp = 1});
                for (int d = 0; d < D; d++) v_update(&s->P.v[d][p], dt, dv[d], vp[d], BL, al, bl);
                if (q2b) scatter_q2(s, q2b->q2, &Wl[i], p, D, NS);
            }
        }
        return;
    }
    for (size_t p = p0; p < p1; p++) {
        double dv[3], vp[3] = {0, 0, 0}, Bm[3][3];
        if (AP) {
            weights_ap(s, p, D, NS, BS, &W, &R);
            gather(s, &W, D, NS,
                   (gather_req){
                       .pos = 1, .affine = 1, .qx = s->g.q, .dx = vp, .R = &R, .Bo = Bm, .vp = 1});
            ap_store(s, p, D, vp, Bm);
            if (q2b) scatter_affine(s, NULL, q2b->q2, &W, &R, p, D, NS, 0);
            continue;
        }
        weights(s, p, D, NS, BS, &W);
        gather(s, &W, D, NS,
               (gather_req){.pos = BL, .qx = s->g.q, .dx = vp, .vel = 1, .dv = dv, .vp = 1});
        for (int d = 0; d < D; d++) v_update(&s->P.v[d][p], dt, dv[d], vp[d], BL, al, bl);
        if (q2b) scatter_q2(s, q2b->q2, &W, p, D, NS);
    }
}

/* MUSL: positions from the updated grid momentum, strain from the momentum
 * of the updated particle velocities (q2).  AP: the in-pass angular
 * momentum counts B_p. */
INLINE void g2p_x_stress_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int NS,
                           int BS, int EN, int AP, mpm_gridbuf *nx)
{
    pw *Wb = o->wblk;
    rowrun a;
    boxc bc;
    chk ck;
    esum e;
    double dt = s->dt;
    if (EN) esum_init(s, &e);
    box_reset(s, o, D);
    run_init(&a);
    boxc_init(s, &bc);
    chk_init(o, &ck);
    trun nr;
    trun_init(&nr, D);
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        weights_block(s, b0, nb, D, NS, BS, Wb);
        for (size_t i = 0; i < nb; i++) {
            size_t p = b0 + i;
            double dx[3];
            gather(s, &Wb[i], D, NS,
                   (gather_req){.strain = 1,
                                .qg = s->g.q2,
                                .deps = o->deps,
                                .i = i,
                                .pos = 1,
                                .qx = s->g.q,
                                .dx = dx,
                                .vp = 1});
            for (int d = 0; d < D; d++) s->P.x[d][p] += dt * dx[d];
        }
        moved_block(s, o, &bc, &ck, &e, &a, b0, b0 + nb, D, NS, BS, EN, AP);
        block_update(s, o, b0, nb, D);
        if (EN) esum_strain(s, &e, b0, nb, D);
        if (nx && ck.bad == SIZE_MAX) next_scatter(s, nx, &nr, Wb, b0, b0 + nb, D, NS, BS, AP, 1);
    }
    if (nx && TR(NS, BS, AP)) trun_flush(s, &nr, nx, D, 1, 1);
    chk_store(&ck, o);
    run_flush(s, o, &a, D);
    if (EN) esum_store(&e, o, 1, 1);
}

/* The support box of particles [p0, p1) without moving them. */
INLINE void bbox_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int NS, int BS)
{
    rowrun a;
    boxc bc;
    box_reset(s, o, D);
    run_init(&a);
    boxc_init(s, &bc);
    for (size_t p = p0; p < p1; p++) {
        double x[3] = {0, 0, 0};
        for (int d = 0; d < D; d++) x[d] = s->P.x[d][p];
        box_add(s, &bc, o, &a, x, D, NS, BS);
    }
    run_flush(s, o, &a, D);
}

#ifndef MPM_LEAN
/* Point forces of the loaded particles (tractions), f += S f_p (Eq. 14). */
INLINE void scatter_loads_t(mpm_sim *s, int D, int NS, int BS)
{
    IH(s);
    pw W;
    for (size_t i = 0; i < s->nload; i++) {
        weights(s, s->load_p[i], D, NS, BS, &W);
        double l0 = s->load_f[0][i], l1 = D > 1 ? s->load_f[1][i] : 0.0;
        double l2 = D > 2 ? s->load_f[2][i] : 0.0;
        ROWS(D, NS, W, s, {
            UNROLL
            for (int kx = 0; kx < NS; kx++) {
                double S = W.w[0][kx] * A;
                size_t n = row + (size_t)kx;
                s->g.f[0][n] += S * l0;
                if (D > 1) s->g.f[1][n] += S * l1;
                if (D > 2) s->g.f[2][n] += S * l2;
            }
        });
    }
}
#define LOADS(D, NS, BS)                                    \
    static void scatter_loads_##D##_##NS##_##BS(mpm_sim *s) \
    {                                                       \
        scatter_loads_t(s, D, NS, BS);                      \
    }
#else
#define LOADS(D, NS, BS)                                    \
    static void scatter_loads_##D##_##NS##_##BS(mpm_sim *s) \
    {                                                       \
        (void)s;                                            \
    }
#endif

/* Family (D, NS, BS): D dimensions, NS nodes per axis, BS 0 for tents (NS
 * 2) and uGIMP (NS 3, 4), 1 for B-splines of degree NS - 1.  Template
 * arguments after them: EN (energies), BL (PIC/FLIP blend), AP (APIC). */
#define K(name, D, NS, BS) name##_##D##_##NS##_##BS

/* The passes that move the particles, of variant V (empty: FLIP, _bl:
 * the blend, _ap: APIC) of family (D, NS, BS): only the fused ones (_nx,
 * with the next step's target, or NULL for a step that does not fuse),
 * and MUSL's velocity pass with its q2 scatter; the plain entries of the
 * table (mpm_kernels: g2p_xv, ..., p2g_q2) are CPDI's alone. */
#define MOVERS(V, D, NS, BS, BL, AP)                                                              \
    static void K(g2p_xv_nx##V, D, NS, BS)(mpm_sim * s, mpm_gridbuf * nx, mpm_thread_out * o,     \
                                           size_t a, size_t b, int en)                            \
    {                                                                                             \
        if (en)                                                                                   \
            g2p_xv_t(s, o, a, b, D, NS, BS, 1, BL, AP, nx);                                       \
        else                                                                                      \
            g2p_xv_t(s, o, a, b, D, NS, BS, 0, BL, AP, nx);                                       \
    }                                                                                             \
    static void K(g2p_xv_stress_nx##V, D, NS, BS)(mpm_sim * s, mpm_gridbuf * nx,                  \
                                                  mpm_thread_out * o, size_t a, size_t b, int en) \
    {                                                                                             \
        if (en)                                                                                   \
            g2p_xv_stress_t(s, o, a, b, D, NS, BS, 1, BL, AP, nx);                                \
        else                                                                                      \
            g2p_xv_stress_t(s, o, a, b, D, NS, BS, 0, BL, AP, nx);                                \
    }                                                                                             \
    static void K(g2p_v_q2##V, D, NS, BS)(mpm_sim * s, mpm_gridbuf * q2b, size_t a, size_t b)     \
    {                                                                                             \
        g2p_v_t(s, q2b, a, b, D, NS, BS, BL, AP);                                                 \
    }

/* MUSL's last pass: the blend shares FLIP's (the velocity is final). */
#define XSTRESS(V, D, NS, BS, AP)                                                                \
    static void K(g2p_x_stress_nx##V, D, NS, BS)(mpm_sim * s, mpm_gridbuf * nx,                  \
                                                 mpm_thread_out * o, size_t a, size_t b, int en) \
    {                                                                                            \
        if (en)                                                                                  \
            g2p_x_stress_t(s, o, a, b, D, NS, BS, 1, AP, nx);                                    \
        else                                                                                     \
            g2p_x_stress_t(s, o, a, b, D, NS, BS, 0, AP, nx);                                    \
    }

/* The table of variant V; P (empty or _ap) names its scatters of momentum
 * and X (empty or _ap) its MUSL last pass; the plain moving passes and
 * p2g_q2 are NULL (the fused ones with no target do their work). */
#define TABLE_OF(V, P, X, D, NS, BS)                                                       \
    static const mpm_kernels K(family##V, D, NS, BS) = {K(p2g_mq##P, D, NS, BS),           \
                                                        K(p2g_mqf##P, D, NS, BS),          \
                                                        NULL,                              \
                                                        K(stress_force, D, NS, BS),        \
                                                        NULL,                              \
                                                        NULL,                              \
                                                        NULL,                              \
                                                        NULL,                              \
                                                        K(scatter_loads, D, NS, BS),       \
                                                        K(bbox, D, NS, BS),                \
                                                        K(cell_keys, D, NS, BS),           \
                                                        K(g2p_xv_nx##V, D, NS, BS),        \
                                                        K(g2p_xv_stress_nx##V, D, NS, BS), \
                                                        K(g2p_x_stress_nx##X, D, NS, BS),  \
                                                        K(g2p_v_q2##V, D, NS, BS)};

/* The PIC/FLIP blend of family (D, NS, BS): its own velocity updates,
 * every other pass shared. */
#define BLEND(D, NS, BS)         \
    MOVERS(_bl, D, NS, BS, 1, 0) \
    TABLE_OF(_bl, , , D, NS, BS)

/* The APIC family of (D, NS, BS): its own scatters of momentum and
 * velocity updates, and the in-pass angular momentum with B_p; the stress
 * pass, loads, boxes and sort keys shared. */
#define APIC(D, NS, BS)                                                                     \
    static void K(p2g_mq_ap, D, NS, BS)(mpm_sim * s, mpm_gridbuf * gb, size_t a, size_t b)  \
    {                                                                                       \
        p2g_mq_t(s, gb, a, b, D, NS, BS, 1);                                                \
    }                                                                                       \
    static void K(p2g_mqf_ap, D, NS, BS)(mpm_sim * s, mpm_gridbuf * gb, size_t a, size_t b) \
    {                                                                                       \
        p2g_mqf_t(s, gb, a, b, D, NS, BS, 1);                                               \
    }                                                                                       \
    MOVERS(_ap, D, NS, BS, 0, 1)                                                            \
    XSTRESS(_ap, D, NS, BS, 1)                                                              \
    TABLE_OF(_ap, _ap, _ap, D, NS, BS)

#define FAMILY(D, NS, BS)                                                                     \
    static void K(p2g_mq, D, NS, BS)(mpm_sim * s, mpm_gridbuf * gb, size_t a, size_t b)       \
    {                                                                                         \
        p2g_mq_t(s, gb, a, b, D, NS, BS, 0);                                                  \
    }                                                                                         \
    static void K(p2g_mqf, D, NS, BS)(mpm_sim * s, mpm_gridbuf * gb, size_t a, size_t b)      \
    {                                                                                         \
        p2g_mqf_t(s, gb, a, b, D, NS, BS, 0);                                                 \
    }                                                                                         \
    static void K(stress_force, D, NS, BS)(mpm_sim * s, mpm_gridbuf * gb, mpm_thread_out * o, \
                                           size_t a, size_t b, int en)                        \
    {                                                                                         \
        if (en)                                                                               \
            stress_force_t(s, gb, o, a, b, D, NS, BS, 1);                                     \
        else                                                                                  \
            stress_force_t(s, gb, o, a, b, D, NS, BS, 0);                                     \
    }                                                                                         \
    MOVERS(, D, NS, BS, 0, 0)                                                                 \
    XSTRESS(, D, NS, BS, 0)                                                                   \
    LOADS(D, NS, BS)                                                                          \
    static void K(bbox, D, NS, BS)(mpm_sim * s, mpm_thread_out * o, size_t a, size_t b)       \
    {                                                                                         \
        bbox_t(s, o, a, b, D, NS, BS);                                                        \
    }                                                                                         \
    static void K(cell_keys, D, NS, BS)(const mpm_sim *s, uint32_t *key, size_t a, size_t b)  \
    {                                                                                         \
        cell_keys_t(s, key, a, b, D);                                                         \
    }                                                                                         \
    TABLE_OF(, , , D, NS, BS)                                                                 \
    BLEND(D, NS, BS)                                                                          \
    APIC(D, NS, BS)

FAMILY(1, 2, 0)
FAMILY(1, 3, 0)
FAMILY(1, 4, 0)
FAMILY(2, 2, 0)
FAMILY(2, 3, 0)
FAMILY(2, 4, 0)
FAMILY(3, 2, 0)
FAMILY(3, 3, 0)
FAMILY(3, 4, 0)
/* B-splines: quadratic (NS 3) and cubic (NS 4) */
FAMILY(1, 3, 1)
FAMILY(1, 4, 1)
FAMILY(2, 3, 1)
FAMILY(2, 4, 1)
FAMILY(3, 3, 1)
FAMILY(3, 4, 1)

/* tables[variant][dim - 1][ns - 2 + 3 bspline]: variant 0 FLIP, 1 blend,
 * 2 APIC; the B-spline columns are ns 3 and 4 (ns - 2 + 3: 4, 5) */
#define ROW(V, D)                                                                            \
    {                                                                                        \
        &K(V, D, 2, 0), &K(V, D, 3, 0), &K(V, D, 4, 0), NULL, &K(V, D, 3, 1), &K(V, D, 4, 1) \
    }
#define TABLE(V)                        \
    {                                   \
        ROW(V, 1), ROW(V, 2), ROW(V, 3) \
    }

#ifdef MPM_KERNELS_VARIANT
/* 1 when this build of the families fuses a * b + c: the exact product
 * 1 - 2^-60 rounds to 1, so only a fused operation leaves -2^-60.  (GCC
 * forms FMAs from -O2 on: the sanitizer builds, at -O1, run these families
 * without them, and so with the portable kernels' bits.) */
int mpm_kernels_avx2_fuses(void)
{
    volatile double va = 1.0 + 0x1p-30, vb = 1.0 - 0x1p-30, vc = -1.0;
    double a = va, b = vb, c = vc;
    return a * b + c != 0.0;
}

const mpm_kernels *mpm_kernels_select_avx2(int dim, int ns, int bspline, int blend, int apic)
#else
const mpm_kernels *mpm_kernels_select(int dim, int ns, int bspline, int blend, int apic)
#endif
{
    static const mpm_kernels *const tables[3][3][6] = {TABLE(family), TABLE(family_bl),
                                                       TABLE(family_ap)};
    int v = apic ? 2 : blend ? 1 : 0;
    return tables[v][dim - 1][ns - 2 + (bspline ? 3 : 0)];
}
