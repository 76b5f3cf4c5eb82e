/*
 * mpm_gather.h - the gathers of the particle passes: grid fields to one
 * particle's strain increment, position and velocity increments and APIC
 * matrix.
 *
 * A fragment of the kernel templates, included once by mpm_kernels.c
 * (after the scatters; mpm_kernels_avx2.c builds it again
 * through that file): phantom nodes in the velocity gradient
 * (phantom_grad()), MPM tents factored axis by axis (gather_tent()), every
 * other support summed by x rows (gather_rows()), and gather(), which picks
 * one of the two at compile time.  Everything is static and inline.
 */
#ifndef MPM_GATHER_H
#define MPM_GATHER_H

/* Phantom nodes in the velocity gradient.  A phantom node (m <= M_TOL,
 * minv 0) has no velocity, but its gradient weight need not be small: with
 * MPM tents it is +-1/h however small the weight S (a particle on a grid
 * line, exactly or to round-off).  Taking its velocity as 0 breaks
 * sum_n G_n = 0, and a uniform velocity u gives L = -u sum_phantom G ~ u/h
 * (docs/solver.md, "Phantom nodes").  So a phantom node takes, in the gradient only, the velocity
 * interpolated at the particle from the other nodes, u_p = sum' S q/m /
 * sum' S (sum': non-phantom nodes): L = sum' v G + u_p sum_phantom G, the
 * gradient of the interpolation renormalised over the nodes that have a
 * velocity (up to a factor 1 + O(M_TOL)).  A uniform field stays uniform to
 * round-off, and nothing divides by a node's tiny mass (the divisor is
 * sum' S >= 1 - O(M_TOL / m_p)).  gather() only counts phantom nodes; this
 * second pass over the support runs for the few particles that have one,
 * and leaves L bit for bit as it was when their gradient weights are 0
 * (the zero-weight nodes of a GIMP support). */
typedef struct {
    double u[3], g[3]; /* L += u g^T; g = 0 when there is nothing to add */
} phantom_corr;

__attribute__((noinline, cold)) static phantom_corr
phantom_grad(const mpm_sim *s, double *const qg[3], const pw *W, int D, int NS, int VP)
{
    IH(s);
    const double *restrict minv = s->minv;
    double U[3] = {0, 0, 0}, Gp[3] = {0, 0, 0}, Sp = 0;
    ROWS(D, NS, *W, s, {
        double r1[3] = {0, 0, 0}, pg = 0, ps = 0;
        UNROLL
        for (int kx = 0; kx < NS; kx++) {
            size_t n = row + (size_t)kx;
            double mi = minv[n], gx = GRAD(s, *W, NS, 0, kx), wx = W->w[0][kx];
            double ph = mi == 0.0 ? 1.0 : 0.0;
            pg += ph * gx;
            ps += ph * wx;
            for (int a = 0; a < D; a++) r1[a] += (VP ? qg[a][n] : qg[a][n] * mi) * wx;
        }
        Gp[0] += A * pg;
        if (D > 1) Gp[1] += B * ps;
        if (D > 2) Gp[2] += C * ps;
        Sp += A * ps;
        for (int a = 0; a < D; a++) U[a] += A * r1[a];
    });
    phantom_corr c = {{0, 0, 0}, {0, 0, 0}};
    double sa = 1.0 - Sp; /* sum' S; <= 0 only if every node is phantom */
    if (sa <= 0) return c;
    for (int a = 0; a < 3; a++) {
        c.u[a] = U[a] / sa;
        c.g[a] = Gp[a];
    }
    return c;
}

/* MPM tents (NS = 2) factored: a tent support is the 2^D corners of one
 * cell, and the interpolation sum S q/m is the multilinear interpolation of
 * the corner velocities, done axis by axis (z, then y, then x), the
 * corners' x pairs two at a time.  Its gradient is the difference of the
 * interpolated x pair over h (x), and the x-interpolated difference of the
 * rows (y) or planes (z) over h.  Same sums as the node-by-node loop, in a
 * different order and about half the operations (so other last bits).
 * The velocities of one field at the 2^D corners, as x pairs: c[kz][ky]. */
typedef struct {
    v2d c[2][2];
} tcorner;

INLINE tcorner tent_corners(const double *restrict q, const v2d mi[2][2], const size_t row[2][2],
                            int D, int VP)
{
    tcorner t = {{{{0, 0}, {0, 0}}, {{0, 0}, {0, 0}}}}; /* the corners D leaves out: 0 */
    for (int kz = 0; kz < (D > 2 ? 2 : 1); kz++)
        for (int ky = 0; ky < (D > 1 ? 2 : 1); ky++) {
            v2d c = v2_ld(q + row[kz][ky]);
            if (!VP) c = c * mi[kz][ky];
            t.c[kz][ky] = c;
        }
    return t;
}

/* The x pair of one corner field, interpolated in z and y (Yz: per z
 * plane, interpolated in y). */
INLINE v2d tent_yz(const tcorner *t, const double wy[2], const double wz[2], int D, v2d Yz[2])
{
    for (int kz = 0; kz < (D > 2 ? 2 : 1); kz++) {
        Yz[kz] = t->c[kz][0];
        if (D > 1) Yz[kz] = Yz[kz] * wy[0] + t->c[kz][1] * wy[1];
    }
    if (D < 3) return Yz[0];
    return Yz[0] * wz[0] + Yz[1] * wz[1];
}

INLINE double dot2(v2d a, v2d w)
{
    v2d t = a * w;
    return t[0] + t[1];
}

INLINE void gather_tent(const mpm_sim *s, double *const qg[3], const pw *W, int D,
                        double *const deps[9], size_t i, int DS, int DX, double *const qx[3],
                        double dx[3], int DV, double dv[3], int VP)
{
    IH(s);
    const double *restrict minv = s->minv;
    const size_t sy = s->stride[1], sz = s->stride[2];
    const v2d wx = {W->w[0][0], W->w[0][1]};
    const double wy[2] = {D > 1 ? W->w[1][0] : 1.0, D > 1 ? W->w[1][1] : 0.0};
    const double wz[2] = {D > 2 ? W->w[2][0] : 1.0, D > 2 ? W->w[2][1] : 0.0};
    size_t row[2][2] = {{0, 0}, {0, 0}};
    v2d mi[2][2] = {{{0, 0}, {0, 0}}, {{0, 0}, {0, 0}}};
    v2l ph = {0, 0}; /* lanes of phantom corners (1/m = 0), or-ed */
    const v2d zero = {0, 0};
    for (int kz = 0; kz < (D > 2 ? 2 : 1); kz++)
        for (int ky = 0; ky < (D > 1 ? 2 : 1); ky++) {
            row[kz][ky] = W->base + (size_t)ky * sy + (size_t)kz * sz;
            if (DS || !VP) mi[kz][ky] = v2_ld(minv + row[kz][ky]);
            if (DS) ph |= mi[kz][ky] == zero;
        }
    for (int a = 0; a < D; a++) {
        v2d Yz[2];
        if (DX) {
            tcorner t = tent_corners(qx[a], mi, row, D, VP);
            dx[a] = dot2(tent_yz(&t, wy, wz, D, Yz), wx);
        }
        if (DV) {
            tcorner t = tent_corners(s->g.f[a], mi, row, D, VP);
            dv[a] = dot2(tent_yz(&t, wy, wz, D, Yz), wx);
        }
    }
    if (!DS) return;
    double L[3][3] = {{0}};
    for (int a = 0; a < D; a++) {
        v2d Yz[2];
        tcorner t = tent_corners(qg[a], mi, row, D, VP);
        v2d Z = tent_yz(&t, wy, wz, D, Yz);
        L[a][0] = (Z[1] - Z[0]) * ih_[0];
        if (D > 1) {
            v2d dY = t.c[0][1] - t.c[0][0];
            if (D > 2) dY = dY * wz[0] + (t.c[1][1] - t.c[1][0]) * wz[1];
            L[a][1] = dot2(dY, wx) * ih_[1];
        }
        if (D > 2) L[a][2] = dot2(Yz[1] - Yz[0], wx) * ih_[2];
    }
    if (__builtin_expect((ph[0] | ph[1]) != 0, 0)) {
        phantom_corr c = phantom_grad(s, qg, W, D, 2, VP);
        if ((c.g[0] != 0.0) | (c.g[1] != 0.0) | (c.g[2] != 0.0))
            for (int a = 0; a < D; a++)
                for (int b = 0; b < D; b++) L[a][b] += c.u[a] * c.g[b];
    }
    strain_of(s, L, deps, i, D);
}

/* One row of a support along x, node k in lane k.  AVX builds: four
 * lanes, loaded at once; lanes NS .. 3 hold whatever the grid has past
 * the row (the grid arrays have MPM_GRID_SLACK doubles past their end for
 * the row that ends one) and no sum reads them: one load and one
 * multiply-add per row and factor.
 * Portable builds: two pairs, nodes 0-1 and 2-3, the second loaded only
 * as far as NS (four-lane vectors there run as pairs anyway, and their
 * unaligned loads cost more).  Each lane does the same operations either
 * way, so the same bits. */
#if MPM_V4
typedef struct {
    v4d v;
} xrow;
typedef struct {
    v4l v;
} xmask;
#define XR_ZERO        \
    {                  \
        {              \
            0, 0, 0, 0 \
        }              \
    }
#else
typedef struct {
    v2d lo, hi;
} xrow;
typedef struct {
    v2l lo, hi;
} xmask;
#define XR_ZERO  \
    {            \
        {0, 0},  \
        {        \
            0, 0 \
        }        \
    }
#endif

INLINE void xr_ld(xrow *r, const double *restrict q, size_t n, int NS)
{
#if MPM_V4
    (void)NS;
    r->v = *(const v4du *)(q + n);
#else
    r->lo = v2_ld(q + n);
    r->hi = (v2d){0, 0};
    if (NS == 4) r->hi = v2_ld(q + n + 2);
    if (NS == 3) r->hi[0] = q[n + 2];
#endif
}

/* lane k */
INLINE double xr_get(const xrow *r, int k)
{
#if MPM_V4
    return r->v[k];
#else
    return k < 2 ? r->lo[k] : r->hi[k - 2];
#endif
}

/* the lanes a, b, c, d */
INLINE void xr_make(xrow *r, double a, double b, double c, double d)
{
#if MPM_V4
    r->v = (v4d){a, b, c, d};
#else
    r->lo = (v2d){a, b};
    r->hi = (v2d){c, d};
#endif
}

/* a weight row w[0 .. NS) of 3 or 4 nodes, the lanes past it 0: AVX
 * builds load the four lanes whole (a 3-node row's w[3] is 0, pw) */
INLINE void xr_row(xrow *r, const double *w, int NS)
{
#if MPM_V4
    (void)NS;
    r->v = *(const v4du *)w;
#else
    xr_make(r, w[0], w[1], w[2], NS > 3 ? w[3] : 0.0);
#endif
}

/* v *= m, lane by lane */
INLINE void xr_mul(xrow *v, const xrow *m)
{
#if MPM_V4
    v->v = v->v * m->v;
#else
    v->lo = v->lo * m->lo;
    v->hi = v->hi * m->hi;
#endif
}

/* acc += c v */
INLINE void xr_axpy(xrow *acc, double c, const xrow *v)
{
#if MPM_V4
    acc->v = acc->v + v->v * c;
#else
    acc->lo = acc->lo + v->lo * c;
    acc->hi = acc->hi + v->hi * c;
#endif
}

/* sum_k a_k w_k over the NS nodes, in node order */
INLINE double xr_dot(const xrow *a, const xrow *w, int NS)
{
#if MPM_V4
    v4d t = a->v * w->v;
    double r = t[0] + t[1];
    if (NS > 2) r += t[2];
    if (NS == 4) r += t[3];
#else
    v2d t = a->lo * w->lo;
    double r = t[0] + t[1];
    if (NS > 2) {
        v2d u = a->hi * w->hi;
        r += u[0];
        if (NS == 4) r += u[1];
    }
#endif
    return r;
}

/* ph |= the lanes of m that are 0 (phantom nodes: 1/m = 0) */
INLINE void xr_orzero(xmask *ph, const xrow *m)
{
#if MPM_V4
    const v4d zero = {0, 0, 0, 0};
    ph->v |= m->v == zero;
#else
    const v2d zero = {0, 0};
    ph->lo |= m->lo == zero;
    ph->hi |= m->hi == zero;
#endif
}

/* any of the support's NS lanes set */
INLINE int xr_any(const xmask *ph, int NS)
{
#if MPM_V4
    long long a = ph->v[0] | ph->v[1];
    if (NS > 2) a |= ph->v[2];
    if (NS > 3) a |= ph->v[3];
#else
    long long a = ph->lo[0] | ph->lo[1];
    if (NS > 2) a |= ph->hi[0];
    if (NS > 3) a |= ph->hi[1];
#endif
    return a != 0;
}

/* The rows of a support with their factors: rw[r] the flat index of the
 * row's node kx = 0, A, B, C as in ROWS(), and for APIC (AF) the factors
 * of B_p's y and z columns, A (x_i - x_p)_y and A (x_i - x_p)_z. */
typedef struct {
    size_t rw[16];
    double A[16], B[16], C[16], Y[16], Z[16];
} srows;

/* Everything but MPM tents without APIC, factored like gather_tent(): the
 * rows of each field are summed first with their y and z factors, as
 * x rows (a few two-lane multiply-adds per row), and the x weights applied
 * once to the sums.  The node-by-node form summed each row with its x
 * weights and added the row's scalar times its y and z factors: about
 * 40 % more operations, and sums across the lanes in every row.  The same
 * sums in another order, so other last bits than the node-by-node form
 * (docs/solver.md, "Gathers by rows"). */
INLINE void gather_rows(const mpm_sim *s, double *const qg[3], const pw *W, int D, int NS,
                        double *const deps[9], size_t i, int DS, int DX, double *const qx[3],
                        double dx[3], int DV, double dv[3], int AF, const aoff *R, double Bo[3][3],
                        int VP)
{
    IH(s);
    const double *restrict minv = s->minv;
    const int NR = D == 1 ? 1 : D == 2 ? NS : NS * NS;
    srows sr;
    int nr = 0;
    ROWS(D, NS, *W, s, {
        sr.rw[nr] = row;
        sr.A[nr] = A;
        sr.B[nr] = B;
        sr.C[nr] = C;
        if (AF) {
            sr.Y[nr] = D > 1 ? A * R->r[1][ky] : 0.0;
            sr.Z[nr] = D > 2 ? A * R->r[2][kz] : 0.0;
        }
        nr++;
    });
    xrow wx, gx;
    if (NS > 2) {
        xr_row(&wx, W->w[0], NS);
        xr_row(&gx, W->g[0], NS);
    } else {
        xr_make(&wx, W->w[0][0], W->w[0][1], 0.0, 0.0);
        xr_make(&gx, GRAD(s, *W, NS, 0, 0), GRAD(s, *W, NS, 0, 1), 0.0, 0.0);
    }
    double L[3][3] = {{0}};
    xmask ph = {0}; /* lanes of phantom nodes (1/m = 0), or-ed */
    if (DS) {
        UNROLL
        for (int r = 0; r < NR; r++) {
            xrow mi;
            xr_ld(&mi, minv, sr.rw[r], NS);
            xr_orzero(&ph, &mi);
        }
    }
    for (int a = 0; a < D; a++) {
        if (DS) {
            xrow P0 = XR_ZERO, P1 = P0, P2 = P0;
            UNROLL
            for (int r = 0; r < NR; r++) {
                xrow v;
                xr_ld(&v, qg[a], sr.rw[r], NS);
                if (!VP) {
                    xrow mi;
                    xr_ld(&mi, minv, sr.rw[r], NS);
                    xr_mul(&v, &mi);
                }
                xr_axpy(&P0, sr.A[r], &v);
                if (D > 1) xr_axpy(&P1, sr.B[r], &v);
                if (D > 2) xr_axpy(&P2, sr.C[r], &v);
            }
            L[a][0] = xr_dot(&P0, &gx, NS);
            if (D > 1) L[a][1] = xr_dot(&P1, &wx, NS);
            if (D > 2) L[a][2] = xr_dot(&P2, &wx, NS);
        }
        if (DX || AF) {
            xrow PX = XR_ZERO, PY = PX, PZ = PX;
            UNROLL
            for (int r = 0; r < NR; r++) {
                xrow v;
                xr_ld(&v, qx[a], sr.rw[r], NS);
                if (!VP) {
                    xrow mi;
                    xr_ld(&mi, minv, sr.rw[r], NS);
                    xr_mul(&v, &mi);
                }
                xr_axpy(&PX, sr.A[r], &v);
                if (AF && D > 1) xr_axpy(&PY, sr.Y[r], &v);
                if (AF && D > 2) xr_axpy(&PZ, sr.Z[r], &v);
            }
            if (DX) dx[a] = xr_dot(&PX, &wx, NS);
            if (AF) {
                /* the offsets' row (aoff, stored whole) times the weights:
                 * no lane set to 0, whose register vmovq Valgrind 3.19
                 * cannot decode */
                xrow wr;
                xr_row(&wr, R->r[0], NS);
                xr_mul(&wr, &wx);
                Bo[a][0] = xr_dot(&PX, &wr, NS);
                if (D > 1) Bo[a][1] = xr_dot(&PY, &wx, NS);
                if (D > 2) Bo[a][2] = xr_dot(&PZ, &wx, NS);
            }
        }
        if (DV) {
            xrow PV = XR_ZERO;
            UNROLL
            for (int r = 0; r < NR; r++) {
                xrow v;
                xr_ld(&v, s->g.f[a], sr.rw[r], NS);
                if (!VP) {
                    xrow mi;
                    xr_ld(&mi, minv, sr.rw[r], NS);
                    xr_mul(&v, &mi);
                }
                xr_axpy(&PV, sr.A[r], &v);
            }
            dv[a] = xr_dot(&PV, &wx, NS);
        }
    }
    if (!DS) return;
    if (__builtin_expect(xr_any(&ph, NS), 0)) {
        /* a copy, so that L never has its address taken */
        phantom_corr c = phantom_grad(s, qg, W, D, NS, VP);
        if ((c.g[0] != 0.0) | (c.g[1] != 0.0) | (c.g[2] != 0.0))
            for (int a = 0; a < D; a++)
                for (int b = 0; b < D; b++) L[a][b] += c.u[a] * c.g[b];
    }
    strain_of(s, L, deps, i, D);
}

/* Strain increment (Eq. 29) from grid momenta qg (velocity q/m, zero at
 * phantom nodes: Fig. 7) into block slot i.  Optionally (DX) also the
 * position increment sum S q/m from the momenta qx of the same nodes, and
 * (DV) the velocity increment sum S f/m; AF (APIC): B_p = sum S q/m
 * (x_i - x_p)^T into Bo.  Phantom nodes in the support go through
 * phantom_grad().
 *
 * VP: the fields hold velocities q/m and f/m already.  Every family here
 * gathers velocities in its moving passes: once the node pass has updated
 * the momentum it stores q/m and f/m in place of q and f (and q2/m in
 * place of q2; mpm_sim.gvel), so the gathers read them without the product
 * by 1/m per particle and node.  The USF stress pass gathers the momentum
 * before the update, times 1/m (VP 0). */
INLINE void gather(const mpm_sim *s, double *const qg[3], const pw *W, int D, int NS,
                   double *const deps[9], size_t i, int DS, int DX, double *const qx[3],
                   double dx[3], int DV, double dv[3], int AF, const aoff *R, double Bo[3][3],
                   int VP)
{
    if (NS == 2 && !AF)
        gather_tent(s, qg, W, D, deps, i, DS, DX, qx, dx, DV, dv, VP);
    else
        gather_rows(s, qg, W, D, NS, deps, i, DS, DX, qx, dx, DV, dv, AF, R, Bo, VP);
}

#endif /* MPM_GATHER_H */
