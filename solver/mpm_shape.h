/*
 * mpm_shape.h - the shape functions of one axis and the per-axis weights of
 * one particle, for the particle loops of mpm_kernels.inc: MPM tents, uGIMP
 * (Eqs. 17-18: the tent integrated over the particle) and the B-splines
 * of the open knot vector; pw, a particle's weights and gradients along
 * each axis, and APIC's node offsets (aoff).  The formulas are in
 * mpm_kernels.inc's opening comment.  Private: included only by
 * mpm_kernels.inc and mpm_kernels.c, after mpm_pass.h; everything is static and always inlined
 * (INLINE), so that each (D, NS, BS) family folds its constants.
 */
#ifndef MPM_SHAPE_H
#define MPM_SHAPE_H

#include "mpm_internal.h"
#include "mpm_pass.h"

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#define UNROLL _Pragma("GCC unroll 4")

/* uGIMP weights of one axis for r = (x - x0)/h, a = lp/h and the factors
 * i2a = 1/(2a), i2lp = 1/(2 lp); returns the first node.
 *
 * With N the unit tent and F its antiderivative, a node at distance s (in
 * cells) has S = (F(s + a) - F(s - a)) / (2a) and G = (N(s + a) - N(s - a))
 * / (2 lp) (Eqs. 17-18).  Both ends clamped to [-1, 1] (cp, cm: outside,
 * N is 0 and F constant), N(t) = 1 - |c| and F(t) = 1/2 + c - c|c|/2, so
 * that S = ((cp - cm) - (cp|cp| - cm|cm|)/2) / (2a) and G = (|cm| - |cp|)
 * / (2 lp): one clamp and one |c| per end serve both, and the constants
 * cancel before rounding.  A node outside the support has cp = cm = +-1,
 * so S and G exactly 0 (the 3-node family leaves out only such nodes). */
typedef long long v4l __attribute__((vector_size(32)));

/* Four lanes: |x|, m ? x : y (m all ones or zero), and x clamped to
 * [-1, 1] into out.  Macros: a function may not take or return a 32-byte
 * vector where AVX is not enabled (the portable kernels' ABI). */
#define V4ABS(x) ((v4d)((v4l)(x) & (v4l){INT64_MAX, INT64_MAX, INT64_MAX, INT64_MAX}))
/* lanes 0-2 of x and +0 in lane 3, by a mask (a lane set to 0 made GCC
 * emit the register form of vmovq that Valgrind 3.19 cannot decode, and
 * the callgrind counts of performance.md need Valgrind) */
#define V4_KEEP3(x) ((v4d)((v4l)(x) & (v4l){-1, -1, -1, 0}))
#define V4SEL(m, x, y) ((v4d)(((v4l)(x) & (v4l)(m)) | ((v4l)(y) & ~(v4l)(m))))
#define V2SEL(m, x, y) ((v2d)(((v2l)(x) & (v2l)(m)) | ((v2l)(y) & ~(v2l)(m))))
#if defined(__AVX__)
/* one vminpd and one vmaxpd (the selects cost a compare and a two-uop
 * blend each); the same values as the selects for every number */
#define CLAMP1_4(x, out)                                                            \
    do {                                                                            \
        const v4d one_ = {1, 1, 1, 1};                                              \
        (out) = __builtin_ia32_maxpd256(__builtin_ia32_minpd256((x), one_), -one_); \
    } while (0)
#else
#define CLAMP1_4(x, out)                                                 \
    do {                                                                 \
        const v4d one_ = {1, 1, 1, 1};                                   \
        (out) = V4SEL((x) < -one_, -one_, V4SEL((x) > one_, one_, (x))); \
    } while (0)
#endif

/* Two lanes clamped to [-1, 1]: SSE2's minpd and maxpd where there is
 * SSE2 (x86-64's baseline: the portable kernels there), else the selects;
 * the same values for every number (as CLAMP1_4) */
#if defined(__SSE2__)
#define CLAMP1_2(x, out)                                                      \
    do {                                                                      \
        const v2d one_ = {1, 1};                                              \
        (out) = __builtin_ia32_maxpd(__builtin_ia32_minpd((x), one_), -one_); \
    } while (0)
#else
#define CLAMP1_2(x, out)                                                 \
    do {                                                                 \
        const v2d one_ = {1, 1};                                         \
        (out) = V2SEL((x) < -one_, -one_, V2SEL((x) > one_, one_, (x))); \
    } while (0)
#endif

INLINE int axis_gimp(double r, double a, double i2a, double i2lp, int NS, double *w, double *g)
{
    int c = (int)r;
    double f = r - c;
    int n0 = NS == 4 ? c - 1 : c - 1 + (f >= 0.5);
    /* the NS nodes' distances as lanes; the four lanes stored at once
     * (NS 3: w[3], g[3] are the fourth node's, outside the support, so
     * +0 already; set to 0 all the same, as pw promises) */
#if MPM_V4
    const v4d k4 = {0, 1, 2, 3};
    v4d sd = r - (k4 + (double)n0), cp, cm;
    CLAMP1_4(sd + a, cp);
    CLAMP1_4(sd - a, cm);
    v4d ap = V4ABS(cp), am = V4ABS(cm);
    v4d wv = ((cp - cm) - 0.5 * (cp * ap - cm * am)) * i2a, gv = (am - ap) * i2lp;
    if (NS == 3) {
        wv = V4_KEEP3(wv);
        gv = V4_KEEP3(gv);
    }
    *(v4du *)w = wv;
    *(v4du *)g = gv;
#else
    /* two pairs: SSE2 lowered the four-lane form's broadcasts through the
     * stack (two 8-byte stores read back as one 16-byte load, which the
     * store buffer cannot forward) and ran far slower than this */
    const v2d nd = {(double)n0, (double)n0}, av = {a, a};
    const v2l mag = {INT64_MAX, INT64_MAX};
    for (int h = 0; h < 4; h += 2) {
        const v2d k2 = {(double)h, (double)(h + 1)};
        v2d sd = r - (k2 + nd), sp = sd + av, sm = sd - av;
        v2d cp, cm;
        CLAMP1_2(sp, cp);
        CLAMP1_2(sm, cm);
        v2d ap = (v2d)((v2l)cp & mag), am = (v2d)((v2l)cm & mag);
        v2d wv = ((cp - cm) - 0.5 * (cp * ap - cm * am)) * i2a, gv = (am - ap) * i2lp;
        if (NS == 3 && h == 2) wv[1] = gv[1] = 0.0;
        v2_st(w + h, wv);
        v2_st(g + h, gv);
    }
#endif
    return n0;
}

/* Weights of one axis for r = (x - x0)/h; returns the first node. */
INLINE int axis(double r, double inv_h, double lp, int NS, double *w, double *g)
{
    int c = (int)r;
    double f = r - c;
    if (NS == 2) {
        w[0] = 1.0 - f;
        w[1] = f;
        if (g) { /* the kernels take the tents' gradients from inv_h (GRAD) */
            g[0] = -inv_h;
            g[1] = inv_h;
        }
        return c;
    }
    double a = lp * inv_h;
    return axis_gimp(r, a, 0.5 / a, 0.5 / lp, NS, w, g);
}

/* The uniform B-splines' weights w[k] and gradients g[k] (k < NS) in an
 * interior span at the fraction f, for T double or v4d (bs_block4(): four
 * particles as lanes): one text for both, so that each lane does exactly
 * the scalar operations (the same bits).  NS = 3: (1-f)^2/2, 1/2 + f(1-f),
 * f^2/2; NS = 4: (1-f)^3/6, 2/3 - f^2 + f^3/2, its mirror, f^3/6. */
#define BS_INTERIOR(T, f, inv_h, NS, w, g)                \
    do {                                                  \
        T a_ = 1.0 - (f);                                 \
        if ((NS) == 3) {                                  \
            (w)[0] = 0.5 * a_ * a_;                       \
            (w)[1] = 0.5 + (f)*a_;                        \
            (w)[2] = 0.5 * (f) * (f);                     \
            (g)[0] = -a_ * (inv_h);                       \
            (g)[1] = (a_ - (f)) * (inv_h);                \
            (g)[2] = (f) * (inv_h);                       \
        } else {                                          \
            T f2_ = (f) * (f), a2_ = a_ * a_;             \
            (w)[0] = a2_ * a_ * (1.0 / 6.0);              \
            (w)[1] = 2.0 / 3.0 - f2_ * (1.0 - 0.5 * (f)); \
            (w)[2] = 2.0 / 3.0 - a2_ * (1.0 - 0.5 * a_);  \
            (w)[3] = f2_ * (f) * (1.0 / 6.0);             \
            (g)[0] = -0.5 * a2_ * (inv_h);                \
            (g)[1] = (f) * (1.5 * (f)-2.0) * (inv_h);     \
            (g)[2] = -a_ * (1.5 * a_ - 2.0) * (inv_h);    \
            (g)[3] = 0.5 * f2_ * (inv_h);                 \
        }                                                 \
    } while (0)

/* The first node of span c's support (bs_axis() returns the same). */
INLINE int bs_first(const mpm_bspline_axis *ax, int c)
{
    int f = c - ax->off, hi = ax->n - 1 - 2 * ax->off;
    return f < 0 ? 0 : f > hi ? hi : f;
}

/* B-spline weights of one axis for r = (x - x0)/h in [0, n] (r = n, a
 * rounding at the top face, is taken in the last cell); returns the first
 * node, c - off on the interior spans (mpm_bspline_axis).  Interior spans:
 * the uniform B-splines in closed form; the p - 1 spans at each end (rare,
 * and contiguous once the particles are sorted by cell, so the branch
 * predicts well): Horner on the coefficients made at creation
 * (mpm_bspline.c). */
INLINE int bs_axis(const mpm_bspline_axis *ax, double r, double inv_h, int NS, double *w, double *g)
{
    int n = ax->n, c = (int)r;
    c = c < n - 1 ? c : n - 1;
    double f = r - c;
    if (__builtin_expect((c < NS - 2) | (c > n - NS + 1), 0)) {
        int lo = c < NS - 2, e = lo ? c : c - (n - NS + 2);
        const double(*C)[4] = lo ? ax->lo[e] : ax->hi[e];
        UNROLL
        for (int k = 0; k < NS; k++) {
            w[k] = ((C[k][3] * f + C[k][2]) * f + C[k][1]) * f + C[k][0];
            g[k] = ((3.0 * C[k][3] * f + 2.0 * C[k][2]) * f + C[k][1]) * inv_h;
        }
        return lo ? ax->lo_start[e] : ax->hi_start[e];
    }
    BS_INTERIOR(double, f, inv_h, NS, w, g);
    return c - ax->off;
}

/* Per-axis weights of one particle: w[d][k], g[d][k] belong to node
 * base + k stride[d] along axis d.  With NS 3, w[d][3] and g[d][3] are
 * +0 on every axis d < D (and aoff's r[d][3] too), whichever function
 * made them: the four-lane rows of the scatters and gathers load a row
 * whole (V4_ROW(), xr_row()) and need the lane past the support to be 0, as the
 * zero they built it with before was. */
typedef struct {
    size_t base;
    double w[3][4], g[3][4];
} pw;

/* A row of 3 or 4 weights w into o[0 .. 4), o[3] = 0 for 3: AVX builds
 * store the four lanes at once, since the scatters and gathers load them
 * at once (V4_ROW(), xr_row()) and a load from one store is forwarded
 * where a load from several waits for them to reach the cache. */
INLINE void row_store(double *o, const double *w, int NS)
{
#if MPM_V4
    v4d r = {w[0], w[1], w[2], NS > 3 ? w[3] : w[2]};
    *(v4du *)o = NS > 3 ? r : V4_KEEP3(r);
#else
    for (int k = 0; k < 4; k++) o[k] = k < NS ? w[k] : 0.0;
#endif
}

/* BS: B-spline family (NS = p + 1) instead of tents / uGIMP.  n0 (APIC;
 * NULL otherwise): the first node of each axis, padded index */
INLINE void weights_n0(const mpm_sim *s, size_t p, int D, int NS, int BS, pw *o, int *n0)
{
    size_t base = 0;
    if (NS > 2 && !BS) {
        /* uGIMP: the 2D quotients 1/(2a), 1/(2 lp) of all axes in one
         * four-lane division (each lane the scalar quotient, the same
         * bits; six divisions in 3D cost more than the rest of the weights) */
        double r[3], a[3] = {1, 1, 1}, lp[3] = {1, 1, 1};
        for (int d = 0; d < D; d++) {
            r[d] = (s->P.x[d][p] - s->x0[d]) * s->inv_h[d];
            lp[d] = s->P.lp[d][p];
            a[d] = lp[d] * s->inv_h[d];
        }
        const v4d half = {0.5, 0.5, 0.5, 0.5}, d0 = {a[0], a[1], a[2], lp[0]};
        const v4d d1 = {lp[1], lp[2], 1.0, 1.0};
        v4d q0 = half / d0, q1 = half / d1;
        const double i2lp[3] = {q0[3], q1[0], q1[1]};
        for (int d = 0; d < D; d++) {
            int c = axis_gimp(r[d], a[d], q0[d], i2lp[d], NS, o->w[d], o->g[d]);
            if (n0) n0[d] = c;
            base += (size_t)c * s->stride[d];
        }
        o->base = base;
        return;
    }
    for (int d = 0; d < D; d++) {
        double r = (s->P.x[d][p] - s->x0[d]) * s->inv_h[d];
        double lw[4] = {0, 0, 0, 0}, lg[4] = {0, 0, 0, 0};
        int c;
        if (BS) {
            c = bs_axis(&s->bs[d], r, s->inv_h[d], NS, lw, lg);
        } else {
            double lp = NS == 2 ? 0.0 : s->P.lp[d][p];
            c = axis(r, s->inv_h[d], lp, NS, lw, NS == 2 ? NULL : lg);
        }
        if (NS == 2) {
            o->w[d][0] = lw[0];
            o->w[d][1] = lw[1];
        } else {
            row_store(o->w[d], lw, NS);
            row_store(o->g[d], lg, NS);
        }
        if (n0) n0[d] = c;
        base += (size_t)c * s->stride[d];
    }
    o->base = base;
}

INLINE void weights(const mpm_sim *s, size_t p, int D, int NS, int BS, pw *o)
{
    weights_n0(s, p, D, NS, BS, o, NULL);
}

/* The weights of particles [b0, b0 + nb) into Wb[0..nb).  MPM tents take
 * four particles at a time in AVX builds (tent_block4()) and two in the
 * portable ones (the cell coordinates, truncations and fractions as
 * lanes: the same operations as weights(), so the same bits), B-splines
 * four at a time in AVX builds (bs_block4()); the rest, and the last odd
 * particles, one by one. */
typedef int v2i __attribute__((vector_size(8)));
typedef int v4i __attribute__((vector_size(16)));
typedef unsigned v4u __attribute__((vector_size(16)));

#if MPM_V4
/* whether every lane of a four-lane comparison's mask is set */
INLINE int v4l_all(v4l m)
{
    return __builtin_ia32_movmskpd256((v4d)m) == 15;
}
#endif

/* whether any lane of a comparison's mask is set */
INLINE int v4u_any(v4u m)
{
#ifdef __SSE2__
    return __builtin_ia32_movmskps((__attribute__((vector_size(16))) float)m) != 0;
#else
    return (m[0] | m[1] | m[2] | m[3]) != 0;
#endif
}

/* The grid's geometry as a block's weights read it, in locals: the
 * weights' stores (doubles and size_t) may alias the simulation's own
 * x0, inv_h and stride, so read through s the compiler reloads them for
 * every particle and axis. */
typedef struct {
    double x0[3], ih[3];
    size_t st[3];     /* the strides */
    double st_f[3];   /* the same as doubles: a base (< 2^53 nodes) is
                       * summed exactly in a vector and converted once */
    unsigned span[3]; /* interior first cells c - (NS - 2) run 0 .. span */
    double boff;      /* B-splines: -sum_d off stride[d] (mpm_bspline_axis) */
} wgeo;

/* Four four-lane vectors v[k] (lane j: particle j) stored transposed:
 * o_j[k] = v[k][j] */
INLINE void tr4_store(const v4d v[4], double *o0, double *o1, double *o2, double *o3)
{
    /* __builtin_shufflevector: GCC 12 and Clang both have it (Clang has
     * no __builtin_shuffle) */
    v4d t0 = __builtin_shufflevector(v[0], v[1], 0, 4, 2, 6);
    v4d t1 = __builtin_shufflevector(v[0], v[1], 1, 5, 3, 7);
    v4d t2 = __builtin_shufflevector(v[2], v[3], 0, 4, 2, 6);
    v4d t3 = __builtin_shufflevector(v[2], v[3], 1, 5, 3, 7);
    *(v4du *)o0 = __builtin_shufflevector(t0, t2, 0, 1, 4, 5);
    *(v4du *)o1 = __builtin_shufflevector(t1, t3, 0, 1, 4, 5);
    *(v4du *)o2 = __builtin_shufflevector(t0, t2, 2, 3, 6, 7);
    *(v4du *)o3 = __builtin_shufflevector(t1, t3, 2, 3, 6, 7);
}

/* B-spline weights of four particles i .. i + 3 of the block when every
 * one lies in an interior span along every axis (bs_axis()'s closed forms,
 * lane by lane the same operations, so the same bits); returns 0, having
 * written nothing, when one of them is in a clamped span.  Only for grids
 * with an interior span on every axis (weights_block()). */
INLINE int bs_block4(const mpm_sim *s, const wgeo *G, size_t p, int D, int NS, pw *W)
{
    v4d fr[3], bd = {G->boff, G->boff, G->boff, G->boff}; /* the bases, exact in doubles */
    v4u out = {0, 0, 0, 0};
    for (int d = 0; d < D; d++) {
        const double *x = s->P.x[d] + p;
        v4d xv = {x[0], x[1], x[2], x[3]};
        v4d r = (xv - G->x0[d]) * G->ih[d];
        v4i c = __builtin_convertvector(r, v4i);
        /* interior: NS - 2 <= c <= n - NS + 1, one unsigned compare (no
         * min(c, n - 1) first: for NS > 2 a c it would lower is out
         * either way, and one that is in is left as it is) */
        out |= (v4u)(c - (NS - 2)) > G->span[d];
        v4d cd = __builtin_convertvector(c, v4d);
        fr[d] = r - cd;
        bd += cd * G->st_f[d];
    }
    if (v4u_any(out)) return 0;
    for (int d = 0; d < D; d++) {
        v4d f = fr[d], w[4], g[4];
        BS_INTERIOR(v4d, f, G->ih[d], NS, w, g);
        if (NS == 3) w[3] = g[3] = (v4d){0, 0, 0, 0};
        tr4_store(w, W[0].w[d], W[1].w[d], W[2].w[d], W[3].w[d]);
        tr4_store(g, W[0].g[d], W[1].g[d], W[2].g[d], W[3].g[d]);
    }
    for (int j = 0; j < 4; j++) W[j].base = (size_t)(long long)bd[j];
    return 1;
}

#if MPM_V4
/* MPM tents' weights of four particles p .. p + 3 (the pairs' operations
 * of weights_block() lane by lane, so the same bits): each particle's
 * (1 - f, f) of an axis is one two-lane store, and the bases are summed
 * exactly in doubles, as bs_block4()'s. */
INLINE void tent_block4(const mpm_sim *s, const wgeo *G, size_t p, int D, pw *W)
{
    v4d bd = {0, 0, 0, 0};
    for (int d = 0; d < D; d++) {
        const double *x = s->P.x[d] + p;
        v4d xv = {x[0], x[1], x[2], x[3]};
        v4d r = (xv - G->x0[d]) * G->ih[d];
        v4d cd = __builtin_convertvector(__builtin_convertvector(r, v4i), v4d);
        v4d f = r - cd, a = 1.0 - f;
        v4d lo = __builtin_shufflevector(a, f, 0, 4, 2, 6); /* particles 0, 2 */
        v4d hi = __builtin_shufflevector(a, f, 1, 5, 3, 7); /* particles 1, 3 */
        v2_st(W[0].w[d], __builtin_shufflevector(lo, lo, 0, 1));
        v2_st(W[1].w[d], __builtin_shufflevector(hi, hi, 0, 1));
        v2_st(W[2].w[d], __builtin_shufflevector(lo, lo, 2, 3));
        v2_st(W[3].w[d], __builtin_shufflevector(hi, hi, 2, 3));
        bd += cd * G->st_f[d];
    }
    for (int j = 0; j < 4; j++) W[j].base = (size_t)(long long)bd[j];
}
#endif

/* The grid's geometry into G; returns, for B-splines, whether every axis
 * has an interior span (n >= 2 NS - 3), else 1. */
INLINE int wgeo_init(const mpm_sim *s, int D, int NS, int BS, wgeo *G)
{
    int inner = 1;
    G->boff = 0;
    for (int d = 0; d < D; d++) {
        G->x0[d] = s->x0[d];
        G->ih[d] = s->inv_h[d];
        G->st[d] = s->stride[d];
        G->st_f[d] = (double)s->stride[d];
        if (BS) {
            int span = s->bs[d].n - 2 * NS + 3;
            inner &= span >= 0;
            G->span[d] = (unsigned)span;
            G->boff -= (double)s->bs[d].off * G->st_f[d];
        }
    }
    return inner;
}

INLINE void weights_block(const mpm_sim *s, size_t b0, size_t nb, int D, int NS, int BS, pw *Wb)
{
    size_t i = 0;
    wgeo G;
    int inner = wgeo_init(s, D, NS, BS, &G);
    /* four particles at a time in AVX builds; the portable kernels take
     * the B-spline weights one by one (SSE2 lowers the four-lane form
     * through the stack, which was slower) */
    if (BS && MPM_V4)
        for (; inner && i + 3 < nb; i += 4)
            if (!bs_block4(s, &G, b0 + i, D, NS, Wb + i))
                for (int j = 0; j < 4; j++) weights(s, b0 + i + j, D, NS, BS, &Wb[i + j]);
    if (NS == 2 && !BS) {
#if MPM_V4
        for (; i + 3 < nb; i += 4) tent_block4(s, &G, b0 + i, D, Wb + i);
#endif
        for (; i + 1 < nb; i += 2) {
            size_t base0 = 0, base1 = 0;
            for (int d = 0; d < D; d++) {
                v2d r = (v2_ld(s->P.x[d] + b0 + i) - G.x0[d]) * G.ih[d];
                v2i c = __builtin_convertvector(r, v2i);
                v2d f = r - __builtin_convertvector(c, v2d), a = 1.0 - f;
                Wb[i].w[d][0] = a[0];
                Wb[i].w[d][1] = f[0];
                Wb[i + 1].w[d][0] = a[1];
                Wb[i + 1].w[d][1] = f[1];
                base0 += (size_t)c[0] * G.st[d];
                base1 += (size_t)c[1] * G.st[d];
            }
            Wb[i].base = base0;
            Wb[i + 1].base = base1;
        }
    }
    for (; i < nb; i++) weights(s, b0 + i, D, NS, BS, &Wb[i]);
}

/* APIC: the weights of particle p and the offsets x_i - x_p of its
 * support's nodes, r[d][k] along axis d for node k of the axis (node
 * coordinates from mpm_node_coord()). */
typedef struct {
    double r[3][4];
} aoff;

INLINE void weights_ap(const mpm_sim *s, size_t p, int D, int NS, int BS, pw *o, aoff *R)
{
    int n0[3] = {0, 0, 0};
    weights_n0(s, p, D, NS, BS, o, n0);
    for (int d = 0; d < D; d++) {
        double x = s->P.x[d][p], r[4] = {0, 0, 0, 0};
        for (int k = 0; k < NS; k++) r[k] = mpm_node_coord(s, d, n0[d] + k) - x;
        row_store(R->r[d], r, NS); /* as one store: read back as one load */
    }
}

#endif /* MPM_SHAPE_H */
