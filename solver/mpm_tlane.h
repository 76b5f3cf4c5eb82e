/*
 * mpm_tlane.h - MPM tents four particles at a time, one particle per lane.
 *
 * A fragment of the kernel templates, included once by mpm_kernels.c
 * after mpm_gather.h; AVX builds only (MPM_V4), 2D and 3D (1D keeps
 * gather_tent(), whose bits these would not give).  Particles sorted by
 * cell come in runs that share one cell and so its 2^D corners.
 * gather_tent() loads the corners, and for USF's strain multiplies them by
 * 1/m, once per particle; here four particles of one run take the corners
 * once, as broadcasts, and each lane does gather_tent()'s operations for
 * its particle in the same order (so the same bits: the products that the
 * pairs' sums add are kept out of fused multiply-adds, as dot2()'s are).
 * el_block() takes USF's stress pass of a one-material linear-elastic
 * job run by run from strain to stress.  Used by USF's stress pass (the strain gather and, in 2D,
 * the force scatter, whose terms each lane forms as trun_add() does before they are added particle
 * by particle), USL's moving pass and, in 3D, USF's moving pass.  The moving passes' lanes read the
 * block's positions and velocities from a copy (tlcopy), since the particle arrays' 32-byte loads
 * overlapped the last group's stores in part.  2D USF's moving pass stays one particle at a time:
 * by lanes it ran slower, with the copy too (docs/performance.md).  Everything is static and
 * inline.
 */
#ifndef MPM_TLANE_H
#define MPM_TLANE_H
#include "mpm_trun.h" /* tl_force2() adds to a trun */
#if MPM_V4

/* Four particles p .. p + 3 along each axis: the weights of the cell's
 * nodes c (1 - f) and c + 1 (f), lane j particle p + j; the first lane's
 * cell (its first corner) and how many lanes from the first share it. */
typedef struct {
    v4d w0[3], w1[3];
    size_t base;
    unsigned k; /* 1 .. 4 */
} tlane;

/* tent_block4()'s weights, lane by lane, of the positions x[d][p .. p +
 * 3] (the particle arrays, or a block's copy: tlcopy); base and k from
 * tl_groups(). */
INLINE void tlane_weights(const wgeo *G, double *const x[3], size_t p, int D, size_t base,
                          unsigned k, tlane *t)
{
    for (int d = 0; d < D; d++) {
        v4d xv = *(const v4du *)(x[d] + p);
        v4d r = (xv - G->x0[d]) * G->ih[d];
        v4d cd = __builtin_convertvector(__builtin_convertvector(r, v4i), v4d);
        v4d f = r - cd;
        t->w0[d] = 1.0 - f;
        t->w1[d] = f;
    }
    t->base = base;
    t->k = k;
}

/* How many of base[i .. i + 3] (i + 4 <= n) from the first share its cell:
 * k[i], 1 .. 4.  The loops step by these, loaded, rather than by a count
 * each group computes from its own positions, whose chain of latencies
 * the next group's loads would wait on. */
INLINE void tl_counts(const size_t *base, size_t n, unsigned char *k)
{
    for (size_t i = 0; i + 4 <= n; i++) {
        unsigned e1 = base[i + 1] == base[i], e2 = e1 & (base[i + 2] == base[i]),
                 e3 = e2 & (base[i + 3] == base[i]);
        k[i] = (unsigned char)(1 + e1 + e2 + e3);
    }
}

/* A block's positions and velocities as they were before the moving pass
 * (tl_groups()): the lanes read them there, not from the particle arrays,
 * where a 32-byte load overlapping the last group's store in part would
 * wait for it to leave the store buffer (runs shorter than four). */
typedef struct {
    double x[3][MPM_BLOCK], v[3][MPM_BLOCK];
} tlcopy;

/* The cells of particles b0 .. b0 + nb - 1 into base[] (tent_block4()'s
 * bases, four by lanes, the last one by one), and their counts k[]
 * (tl_counts()). */
INLINE void tl_groups(const mpm_sim *s, const wgeo *G, size_t b0, size_t nb, int D, size_t *base,
                      unsigned char *k, tlcopy *cp)
{
    size_t i = 0;
    for (; i + 4 <= nb; i += 4) {
        v4d bd = {0, 0, 0, 0};
        for (int d = 0; d < D; d++) {
            const double *x = s->P.x[d] + b0 + i;
            v4d xv = {x[0], x[1], x[2], x[3]};
            *(v4du *)(cp->x[d] + i) = xv;
            *(v4du *)(cp->v[d] + i) = *(const v4du *)(s->P.v[d] + b0 + i);
            v4d r = (xv - G->x0[d]) * G->ih[d];
            bd += __builtin_convertvector(__builtin_convertvector(r, v4i), v4d) * G->st_f[d];
        }
        for (int j = 0; j < 4; j++) base[i + (size_t)j] = (size_t)(long long)bd[j];
    }
    for (; i < nb; i++) {
        size_t b = 0;
        for (int d = 0; d < D; d++) {
            cp->x[d][i] = s->P.x[d][b0 + i];
            cp->v[d][i] = s->P.v[d][b0 + i];
            b += (size_t)(int)((cp->x[d][i] - G->x0[d]) * G->ih[d]) * G->st[d];
        }
        base[i] = b;
    }
    tl_counts(base, nb, k);
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

/* The velocity gradient of the four particles, rows a < D, from the
 * momentum qg over the mass (tl_grad() of each component's corners). */
INLINE void tl_vgrad(const mpm_sim *s, double *const qg[3], const tlane *t, int D, v4d L[3][3])
{
    for (int a = 0; a < D; a++) {
        tlcorner c;
        v4d Y[2][2], Z[2];
        tl_corners(s, qg[a], t->base, D, 0, &c);
        tl_grad(s, &c, t, D, Y, Z, L[a]);
    }
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
    tl_vgrad(s, qg, t, D, L);
    tl_strain_of(s, L, D, deps, i);
}

/* USF's force scatter in 2D: the internal forces of the first k of
 * particles p .. p + 3 (one cell's run, weights t) into the run's sums r
 * (trun_add()'s WF terms: each lane forms its particle's pair of terms
 * as trun_add() does, gx (sigma A) fused, wx (sigma B) rounded, and the
 * pairs are added to the run's sums particle by particle, in order). */
INLINE void tl_force2_of(const mpm_sim *s, trun *r, mpm_gridbuf *gb, const tlane *t, v4d V, v4d sxx,
                         v4d syy, v4d sxy)
{
    IH(s);
    if (t->base != r->base) {
        trun_flush(s, r, gb, 2, 0, 1);
        r->base = t->base;
        trun_zero(r, 2);
    }
    const v4d s0 = V * sxx, s1 = V * syy, s3 = V * sxy;
    const unsigned k = t->k;
    for (int ky = 0; ky < 2; ky++) {
        const v4d A = ky ? t->w1[1] : t->w0[1];
        const double B = ky ? ih_[1] : -ih_[1];
        /* f_x: gx (s_xx A) + wx (s_xy B); f_y: gx (s_xy A) + wx (s_yy B) */
        const v4d X[2] = {s0 * A, s3 * A}, Y[2] = {s3 * B, s1 * B};
        for (int c = 0; c < 2; c++) {
            v4d u0 = t->w0[0] * Y[c], u1 = t->w1[0] * Y[c];
            __asm__("" : "+x"(u0), "+x"(u1));
            v4d T0 = -ih_[0] * X[c] + u0, T1 = ih_[0] * X[c] + u1;
            v4d lo = __builtin_shufflevector(T0, T1, 0, 4, 2, 6); /* particles 0, 2 */
            v4d hi = __builtin_shufflevector(T0, T1, 1, 5, 3, 7); /* particles 1, 3 */
            v2d acc = r->b[4 + c][ky] + __builtin_shufflevector(lo, lo, 0, 1);
            if (k > 1) acc = acc + __builtin_shufflevector(hi, hi, 0, 1);
            if (k > 2) acc = acc + __builtin_shufflevector(lo, lo, 2, 3);
            if (k > 3) acc = acc + __builtin_shufflevector(hi, hi, 2, 3);
            r->b[4 + c][ky] = acc;
        }
    }
}

/* the same, with the particles' volumes and stresses as stored */
INLINE void tl_force2(const mpm_sim *s, trun *r, mpm_gridbuf *gb, const tlane *t, size_t p)
{
    const mpm_particles *P = &s->P;
    tl_force2_of(s, r, gb, t, *(const v4du *)(P->vol + p), *(const v4du *)(P->sig[0] + p),
                 *(const v4du *)(P->sig[1] + p), *(const v4du *)(P->sig[3] + p));
}

/* lanes below k: a; the others: b */
INLINE v4d tl_keep(v4d a, v4d b, unsigned k)
{
    const v4l lane = {0, 1, 2, 3};
    v4l m = lane < (long long)k;
    return (v4d)(((v4l)a & m) | ((v4l)b & ~m));
}

/* 2D USF's stress pass for one run of k particles p .. p + 3 (block slot
 * i, weights t, no phantom corner) of a job whose one material is linear
 * elastic, no strain record and no sigma_zz kept (mpm_sim.plan.el_lanes): tl_strain()'s
 * strain increments, elastic_2d()'s stress update and block_update()'s
 * volume, each lane in their order and roundings (the products kept out
 * of fused multiply-adds, as mpm_model.c, built without them, forms
 * them), stored for the first k lanes only; then tl_force2()'s forces
 * from the same registers.  The same bits as those three in turn, without
 * the strain increments' and stresses' round trip through memory. */
INLINE void tl_stress_force2(mpm_sim *s, trun *r, mpm_gridbuf *gb, const tlane *t, size_t p,
                             double la, double m2)
{
    v4d L[3][3];
    tl_vgrad(s, s->g.q, t, 2, L);
    const double dt = s->dt;
    v4d e0 = L[0][0] * dt, e1 = L[1][1] * dt, e3 = 0.5 * (L[0][1] + L[1][0]) * dt;
    __asm__("" : "+x"(e0), "+x"(e1), "+x"(e3)); /* stored, in the general pass */
    mpm_particles *P = &s->P;
    const unsigned k = t->k;
    v4d lt = la * (e0 + e1), p0 = m2 * e0, p1 = m2 * e1, p3 = m2 * e3;
    __asm__("" : "+x"(lt), "+x"(p0), "+x"(p1), "+x"(p3)); /* no fused multiply-add */
    const v4d sxx0 = *(const v4du *)(P->sig[0] + p), syy0 = *(const v4du *)(P->sig[1] + p),
              sxy0 = *(const v4du *)(P->sig[3] + p), V0 = *(const v4du *)(P->vol + p);
    const v4d sxx = sxx0 + (lt + p0), syy = syy0 + (lt + p1), sxy = sxy0 + p3;
    const v4d V = V0 * (1.0 + (e0 + e1));
    *(v4du *)(P->sig[0] + p) = tl_keep(sxx, sxx0, k);
    *(v4du *)(P->sig[1] + p) = tl_keep(syy, syy0, k);
    *(v4du *)(P->sig[3] + p) = tl_keep(sxy, sxy0, k);
    *(v4du *)(P->vol + p) = tl_keep(V, V0, k);
    tl_force2_of(s, r, gb, t, V, sxx, syy, sxy);
}

/* 3D USF's stress pass for one run of k particles p .. p + 3 (weights t,
 * no phantom corner) of a job with mpm_sim.plan.el_lanes: tl_strain()'s strain
 * increments, elastic_3d()'s stress update and block_update()'s volume,
 * each lane in their order and roundings, stored for the first k lanes
 * only (the forces follow particle by particle, trun_add()). */
INLINE void tl_stress3(mpm_sim *s, const tlane *t, size_t p, double la, double m2)
{
    v4d L[3][3];
    tl_vgrad(s, s->g.q, t, 3, L);
    const double dt = s->dt;
    v4d e[6] = {L[0][0] * dt,
                L[1][1] * dt,
                L[2][2] * dt,
                0.5 * (L[0][1] + L[1][0]) * dt,
                0.5 * (L[1][2] + L[2][1]) * dt,
                0.5 * (L[0][2] + L[2][0]) * dt};
    for (int c = 0; c < 6; c++) __asm__("" : "+x"(e[c])); /* stored, in the general pass */
    v4d lt = la * (e[0] + e[1] + e[2]);
    __asm__("" : "+x"(lt));
    mpm_particles *P = &s->P;
    const unsigned k = t->k;
    for (int c = 0; c < 6; c++) {
        v4d pc = m2 * e[c];
        __asm__("" : "+x"(pc)); /* no fused multiply-add */
        const v4d s0 = *(const v4du *)(P->sig[c] + p);
        *(v4du *)(P->sig[c] + p) = tl_keep(c < 3 ? s0 + (lt + pc) : s0 + pc, s0, k);
    }
    const v4d V0 = *(const v4du *)(P->vol + p);
    *(v4du *)(P->vol + p) = tl_keep(V0 * (1.0 + (e[0] + (e[1] + e[2]))), V0, k);
}

/* Eqs. 30-31, x += dt dx and v += dt dv (BL: the blend), for the first
 * k lanes of axis a; the other lanes are stored as they were. */
INLINE void tl_update(mpm_sim *s, int a, size_t p, const tlcopy *cp, size_t i, v4d dx, v4d dv,
                      unsigned k, int BL, double al, double bl)
{
    const double dt = s->dt;
    double *x = s->P.x[a] + p, *v = s->P.v[a] + p;
    v4d x0 = *(const v4du *)(cp->x[a] + i), v0 = *(const v4du *)(cp->v[a] + i), x1 = x0 + dt * dx,
        v1;
    if (BL)
        v1 = bl * (v0 + dt * dv) + al * dx;
    else
        v1 = v0 + dt * dv;
    *(v4du *)x = tl_keep(x1, x0, k);
    *(v4du *)v = tl_keep(v1, v0, k);
}

/* The moving pass for particles p .. p + 3 (block index i, i + 4 <= the
 * block's count), the first k in the cell at base: the k particles moved
 * and, ST (USL), the strain increments from the updated velocity (one set
 * of corners for both) into deps.  Returns 0, having written nothing,
 * when the cell has a phantom corner, else 1. */
INLINE int tl_move(mpm_sim *s, const wgeo *G, size_t p, size_t base, unsigned k, int D, int BL,
                   double al, double bl, int ST, double *const deps[9], tlcopy *cp, size_t i)
{
    if (__builtin_expect(tl_phantom(s, base, D), 0)) return 0;
    tlane t;
    double *const xc[3] = {cp->x[0], cp->x[1], cp->x[2]};
    tlane_weights(G, xc, i, D, base, k, &t);
    v4d L[3][3];
    for (int a = 0; a < D; a++) {
        tlcorner c;
        v4d Y[2][2], Z[2];
        tl_corners(s, s->g.q[a], t.base, D, 1, &c);
        if (ST)
            tl_grad(s, &c, &t, D, Y, Z, L[a]);
        else
            tl_yz(&c, &t, D, Y, Z);
        v4d dx = tl_dot(Z[0], t.w0[0], Z[1], t.w1[0]), dv = tl_interp(s, s->g.f[a], &t, D, 1);
        tl_update(s, a, p, cp, i, dx, dv, k, BL, al, bl);
    }
    if (ST) tl_strain_of(s, L, D, deps, i);
    return 1;
}

/* Block slot i of USF's stress pass one particle at a time: the strain
 * increment (gather_tent()), the model's update and the volume
 * (block_update()'s, for that slot). */
INLINE void el_one(mpm_sim *s, mpm_thread_out *o, const pw *W, size_t b0, size_t i, int D)
{
    gather(s, s->g.q, W, D, 2, o->deps, i, 1, 0, NULL, NULL, 0, NULL, 0, NULL, NULL, 0);
    double *d[6];
    for (int c = 0; c < 6; c++) d[c] = o->deps[c] ? o->deps[c] + i : NULL;
    s->model->update[D - 1](s->mats, &s->P, b0 + i, 1, d);
    double tr = d[0][0];
    if (D == 2) tr += d[1][0];
    if (D > 2) tr += d[1][0] + d[2][0];
    s->P.vol[b0 + i] *= 1.0 + tr;
}

/* USF's stress pass over a block (weights in o->wblk) of a job with
 * mpm_sim.plan.el_lanes (2D and 3D tents): each run of one cell four particles
 * at a time from its strain to its stress and volume in registers
 * (tl_stress_force2() in 2D, which takes the forces from them too;
 * tl_stress3() in 3D, whose forces then follow particle by particle); a
 * run with a phantom corner and the block's last particles one by one
 * (el_one(), then the forces as the general path adds them).  The forces
 * reach the run sums in particle order, as in the general path (every
 * strain, then every stress, then every force): the same bits, in one
 * pass over the block instead of three, the strain increments (and in
 * 2D the stresses) not stored and loaded back. */
INLINE void el_block(mpm_sim *s, mpm_thread_out *o, mpm_gridbuf *gb, const wgeo *G, trun *r,
                     size_t b0, size_t nb, int D)
{
    const pw *Wb = o->wblk;
    const double la = s->mats[0].lambda, m2 = 2.0 * s->mats[0].mu;
    size_t bb[MPM_BLOCK], i = 0;
    unsigned char kk[MPM_BLOCK];
    for (size_t j = 0; j < nb; j++) bb[j] = Wb[j].base;
    tl_counts(bb, nb, kk);
    while (i + 4 <= nb) {
        unsigned k = kk[i];
        tlane t;
        tlane_weights(G, s->P.x, b0 + i, D, Wb[i].base, k, &t);
        int ph = tl_phantom(s, Wb[i].base, D);
        if (__builtin_expect(ph, 0))
            for (unsigned j = 0; j < k; j++) el_one(s, o, &Wb[i + j], b0, i + j, D);
        if (D == 2) {
            if (ph)
                tl_force2(s, r, gb, &t, b0 + i);
            else
                tl_stress_force2(s, r, gb, &t, b0 + i, la, m2);
        } else {
            if (!ph) tl_stress3(s, &t, b0 + i, la, m2);
            for (unsigned j = 0; j < k; j++) trun_add(s, r, gb, &Wb[i + j], b0 + i + j, D, 0, 1);
        }
        i += k;
    }
    for (; i < nb; i++) {
        el_one(s, o, &Wb[i], b0, i, D);
        trun_add(s, r, gb, &Wb[i], b0 + i, D, 0, 1);
    }
}

#endif /* MPM_V4 */
#endif /* MPM_TLANE_H */
