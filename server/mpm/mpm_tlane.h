/*
 * mpm_tlane.h - MPM tents gathered four particles at a time, one particle
 * per lane.
 *
 * A fragment of the kernel templates, included once by mpm_kernels.c
 * after mpm_gather.h; AVX builds only (MPM_V4), the portable kernels keep
 * gather_tent() for every particle.  Particles sorted by cell come in runs
 * that share one cell and so its 2^D corners.  gather_tent() loads the
 * corners, and for USF's strain multiplies them by 1/m, once per particle;
 * here four particles of one run take the corners once, as broadcasts, and
 * each lane does gather_tent()'s operations for its particle in the same
 * order (so the same bits: the products the pairs' sums add are kept out
 * of fused multiply-adds, as dot2()'s are).  Everything is static and
 * inline.
 */
#ifndef MPM_TLANE_H
#define MPM_TLANE_H
#if MPM_V4

/* Four particles p .. p + 3 along each axis: the weights of the cell's
 * nodes c (1 - f) and c + 1 (f), lane j particle p + j; the first lane's
 * cell (its first corner) and how many lanes from the first share it. */
typedef struct {
    v4d w0[3], w1[3];
    size_t base;
    unsigned k; /* 1 .. 4 */
} tlane;

/* tent_block4()'s operations, lane by lane. */
INLINE void tlane_weights(const mpm_sim *s, const wgeo *G, size_t p, int D, tlane *t)
{
    v4d bd = {0, 0, 0, 0};
    for (int d = 0; d < D; d++) {
        const double *x = s->P.x[d] + p;
        v4d xv = {x[0], x[1], x[2], x[3]};
        v4d r = (xv - G->x0[d]) * G->ih[d];
        v4d cd = __builtin_convertvector(__builtin_convertvector(r, v4i), v4d);
        v4d f = r - cd;
        t->w0[d] = 1.0 - f;
        t->w1[d] = f;
        bd += cd * G->st_f[d];
    }
    v4l same = bd == bd[0];
    unsigned m = (unsigned)__builtin_ia32_movmskpd256((v4d)same); /* bit 0 always set */
    t->k = (unsigned)__builtin_ctz(~m);
    t->base = (size_t)(long long)bd[0];
}

/* The sum of two lanes' products, each rounded (dot2()'s order: no fused
 * multiply-add). */
INLINE v4d tl_dot(v4d a, v4d wa, v4d b, v4d wb)
{
    v4d u = a * wa, v = b * wb;
    __asm__("" : "+x"(u), "+x"(v));
    return u + v;
}

/* One field at the 2^D corners of the cell at base, as broadcasts:
 * c[kz][ky][kx] (VP: the field itself, else times 1/m of the node). */
typedef struct {
    v4d c[2][2][2];
} tlcorner;

INLINE void tl_corners(const mpm_sim *s, const double *restrict F, size_t base, int D, int VP,
                       tlcorner *o)
{
    const double *restrict minv = s->minv;
    for (int kz = 0; kz < (D > 2 ? 2 : 1); kz++)
        for (int ky = 0; ky < (D > 1 ? 2 : 1); ky++) {
            size_t n = base + (size_t)ky * s->stride[1] + (size_t)kz * s->stride[2];
            for (int kx = 0; kx < 2; kx++) {
                double v = F[n + (size_t)kx];
                if (!VP) v = v * minv[n + (size_t)kx];
                o->c[kz][ky][kx] = (v4d){v, v, v, v};
            }
        }
}

/* tent_yz() by lanes: Y[kz][kx], the corners interpolated in y per z
 * plane; returns, in Z[kx], their interpolation in z. */
INLINE void tl_yz(const tlcorner *c, const tlane *t, int D, v4d Y[2][2], v4d Z[2])
{
    for (int kz = 0; kz < (D > 2 ? 2 : 1); kz++)
        for (int kx = 0; kx < 2; kx++) {
            Y[kz][kx] = c->c[kz][0][kx];
            if (D > 1) Y[kz][kx] = Y[kz][kx] * t->w0[1] + c->c[kz][1][kx] * t->w1[1];
        }
    for (int kx = 0; kx < 2; kx++)
        Z[kx] = D < 3 ? Y[0][kx] : Y[0][kx] * t->w0[2] + Y[1][kx] * t->w1[2];
}

/* The interpolation of field F at the four particles (gather_tent()'s DX
 * and DV sums). */
INLINE v4d tl_interp(const mpm_sim *s, const double *restrict F, const tlane *t, int D, int VP)
{
    tlcorner c;
    v4d Y[2][2], Z[2];
    tl_corners(s, F, t->base, D, VP, &c);
    tl_yz(&c, t, D, Y, Z);
    return tl_dot(Z[0], t->w0[0], Z[1], t->w1[0]);
}

/* Whether a corner of the cell at base is a phantom node (1/m = 0). */
INLINE int tl_phantom(const mpm_sim *s, size_t base, int D)
{
    const double *restrict minv = s->minv;
    int ph = 0;
    for (int kz = 0; kz < (D > 2 ? 2 : 1); kz++)
        for (int ky = 0; ky < (D > 1 ? 2 : 1); ky++) {
            size_t n = base + (size_t)ky * s->stride[1] + (size_t)kz * s->stride[2];
            ph |= (minv[n] == 0.0) | (minv[n + 1] == 0.0);
        }
    return ph;
}

/* Row a of the velocity gradient from one field's corners c, with its
 * y (Y) and z (Z) interpolations (tl_yz()): gather_tent()'s DS sums. */
INLINE void tl_grad(const mpm_sim *s, const tlcorner *c, const tlane *t, int D, v4d Y[2][2],
                    v4d Z[2], v4d La[3])
{
    IH(s);
    tl_yz(c, t, D, Y, Z);
    La[0] = (Z[1] - Z[0]) * ih_[0];
    if (D > 1) {
        v4d dY[2];
        for (int kx = 0; kx < 2; kx++) {
            dY[kx] = c->c[0][1][kx] - c->c[0][0][kx];
            if (D > 2) dY[kx] = dY[kx] * t->w0[2] + (c->c[1][1][kx] - c->c[1][0][kx]) * t->w1[2];
        }
        La[1] = tl_dot(dY[0], t->w0[0], dY[1], t->w1[0]) * ih_[1];
    }
    if (D > 2) La[2] = tl_dot(Y[1][0] - Y[0][0], t->w0[0], Y[1][1] - Y[0][1], t->w1[0]) * ih_[2];
    /* gather_tent()'s L joins its phantom branch before strain_of() reads
     * it: no product of L fused into strain_of()'s sums */
    for (int b = 0; b < D; b++) __asm__("" : "+x"(La[b]));
}

/* strain_of(), lane by lane, into deps[.][i .. i + 3]. */
INLINE void tl_strain_of(const mpm_sim *s, v4d L[3][3], int D, double *const deps[9], size_t i)
{
    const double dt = s->dt;
#define TL_ST(k, v) (*(v4du *)(deps[k] + i) = (v))
    TL_ST(0, L[0][0] * dt);
    if (D > 1) {
        TL_ST(1, L[1][1] * dt);
        TL_ST(2, D > 2 ? L[2][2] * dt : 0.5 * (L[0][1] - L[1][0]) * dt);
        TL_ST(3, 0.5 * (L[0][1] + L[1][0]) * dt);
    }
    if (D > 2) {
        TL_ST(4, 0.5 * (L[1][2] + L[2][1]) * dt);
        TL_ST(5, 0.5 * (L[0][2] + L[2][0]) * dt);
        if (__builtin_expect(s->spin3, 0)) {
            TL_ST(6, 0.5 * (L[0][1] - L[1][0]) * dt);
            TL_ST(7, 0.5 * (L[1][2] - L[2][1]) * dt);
            TL_ST(8, 0.5 * (L[0][2] - L[2][0]) * dt);
        }
    }
#undef TL_ST
}

/* USF: the strain increments of the four particles into deps[.][i .. i +
 * 3] from the momentum over the mass, with no phantom corner
 * (tl_phantom()). */
INLINE void tl_strain(const mpm_sim *s, double *const qg[3], const tlane *t, int D,
                      double *const deps[9], size_t i)
{
    v4d L[3][3];
    for (int a = 0; a < D; a++) {
        tlcorner c;
        v4d Y[2][2], Z[2];
        tl_corners(s, qg[a], t->base, D, 0, &c);
        tl_grad(s, &c, t, D, Y, Z, L[a]);
    }
    tl_strain_of(s, L, D, deps, i);
}

/* lanes below k: a; the others: b */
INLINE v4d tl_keep(v4d a, v4d b, unsigned k)
{
    const v4l lane = {0, 1, 2, 3};
    v4l m = lane < (long long)k;
    return (v4d)(((v4l)a & m) | ((v4l)b & ~m));
}

/* Eqs. 30-31, x += dt dx and v += dt dv (BL: the blend), for the first
 * k lanes of axis a; the other lanes are stored as they were. */
INLINE void tl_update(mpm_sim *s, int a, size_t p, v4d dx, v4d dv, unsigned k, int BL, double al,
                      double bl)
{
    const double dt = s->dt;
    double *x = s->P.x[a] + p, *v = s->P.v[a] + p;
    v4d x0 = *(v4du *)x, v0 = *(v4du *)v, x1 = x0 + dt * dx, v1;
    if (BL)
        v1 = bl * (v0 + dt * dv) + al * dx;
    else
        v1 = v0 + dt * dv;
    *(v4du *)x = tl_keep(x1, x0, k);
    *(v4du *)v = tl_keep(v1, v0, k);
}

/* USF's moving pass for the first k (<= kmax) of particles p .. p + 3,
 * which share a cell; p + 3 is one of the thread's particles.  Returns
 * k. */
INLINE unsigned tl_move(mpm_sim *s, const wgeo *G, size_t p, size_t kmax, int D, int BL, double al,
                        double bl)
{
    tlane t;
    tlane_weights(s, G, p, D, &t);
    unsigned k = t.k < kmax ? t.k : (unsigned)kmax;
    for (int a = 0; a < D; a++) {
        v4d dx = tl_interp(s, s->g.q[a], &t, D, 1), dv = tl_interp(s, s->g.f[a], &t, D, 1);
        tl_update(s, a, p, dx, dv, k, BL, al, bl);
    }
    return k;
}

/* USL's moving pass for particles p .. p + 3 (block index i, i + 4 <=
 * the block's count): the strain increments from the updated velocity
 * (one set of corners for both) into deps, and the first k lanes
 * moved.  Returns k, or 0, having written nothing, when the cell has a
 * phantom corner. */
INLINE unsigned tl_move_strain(mpm_sim *s, const wgeo *G, size_t p, int D, int BL, double al,
                               double bl, double *const deps[9], size_t i)
{
    tlane t;
    tlane_weights(s, G, p, D, &t);
    if (__builtin_expect(tl_phantom(s, t.base, D), 0)) return 0;
    v4d L[3][3];
    for (int a = 0; a < D; a++) {
        tlcorner c;
        v4d Y[2][2], Z[2];
        tl_corners(s, s->g.q[a], t.base, D, 1, &c);
        tl_grad(s, &c, &t, D, Y, Z, L[a]);
        v4d dx = tl_dot(Z[0], t.w0[0], Z[1], t.w1[0]), dv = tl_interp(s, s->g.f[a], &t, D, 1);
        tl_update(s, a, p, dx, dv, t.k, BL, al, bl);
    }
    tl_strain_of(s, L, D, deps, i);
    return t.k;
}

#endif /* MPM_V4 */
#endif /* MPM_TLANE_H */
