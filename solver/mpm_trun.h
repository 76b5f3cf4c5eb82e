/*
 * mpm_trun.h - MPM tents scattered a run of particles at a time.
 *
 * A fragment of the kernel templates, included once by mpm_kernels.c
 * (after its IH() macro and the pass helpers; mpm_kernels_avx2.c builds it
 * again through that file): the run's mass, momentum and force summed in
 * registers and added to the cell's 2^D corners once per run.  Everything
 * is static and inline.
 */
#ifndef MPM_TRUN_H
#define MPM_TRUN_H

/* MPM tents scattered a run at a time.  Particles sorted by cell come in
 * runs that share one cell, and so its 2^D corners: the run's
 * contributions are summed in registers and added to the grid once per
 * run, not once per particle (each of those adds waits on the store of the
 * one before to the same node; docs/performance.md).  Other sums than the adds particle by
 * particle, so other last bits; the runs depend only on the order of the particles, so the fused
 * and unfused scatters agree bit for bit.  3D: a[k][kz], the x pairs of
 * the corner rows ky = 0, 1 (lanes 0-1, 2-3) of plane kz of field k (m,
 * q0..q2, f0..f2), four lanes, so that the run's 14 sums fit the 16 AVX
 * registers (as 28 pairs half of them lived on the stack); 1D and 2D:
 * b[k][ky], the x pair of row ky (four lanes were slower there).  Each lane does the pair's
 * arithmetic, so the same bits. */
typedef struct {
    size_t base; /* the run's cell (its first corner); SIZE_MAX: no run yet */
#if MPM_V4
    v4d a[7][2]; /* 3D */
#else
    /* 3D in the portable kernels: a[k][kz][ky], the x pairs (SSE2 lowered
     * the four-lane sums' broadcasts through the stack) */
    v2d a[7][2][2];
#endif
    v2d b[7][2]; /* 1D, 2D */
} trun;

INLINE void trun_zero(trun *r, int D)
{
    for (int k = 0; k < 7; k++)
        for (int j = 0; j < 2; j++) {
            if (D > 2)
#if MPM_V4
                r->a[k][j] = (v4d){0, 0, 0, 0};
#else
                r->a[k][j][0] = r->a[k][j][1] = (v2d){0, 0};
#endif
            else
                r->b[k][j] = (v2d){0, 0};
        }
}

INLINE void trun_init(trun *r, int D)
{
    r->base = SIZE_MAX;
    trun_zero(r, D);
}

/* The x pair of row (ky, kz) of field k. */
#if MPM_V4
#define TPAIR(r, D, k, ky, kz)                           \
    ((D) < 3 ? (r)->b[k][ky]                             \
     : (ky)  ? (v2d){(r)->a[k][kz][2], (r)->a[k][kz][3]} \
             : (v2d){(r)->a[k][kz][0], (r)->a[k][kz][1]})
#else
#define TPAIR(r, D, k, ky, kz) ((D) < 3 ? (r)->b[k][ky] : (r)->a[k][kz][ky])
#endif

/* Adds the run's sums to the grid: WQ mass and momentum, WF force. */
INLINE void trun_flush(const mpm_sim *s, const trun *r, mpm_gridbuf *gb, int D, int WQ, int WF)
{
    if (r->base == SIZE_MAX) return;
    const size_t sy = s->stride[1], sz = s->stride[2];
    for (int kz = 0; kz < (D > 2 ? 2 : 1); kz++)
        for (int ky = 0; ky < (D > 1 ? 2 : 1); ky++) {
            size_t n = r->base + (size_t)ky * sy + (size_t)kz * sz;
            if (WQ) {
                v2_st(gb->m + n, v2_ld(gb->m + n) + TPAIR(r, D, 0, ky, kz));
                for (int c = 0; c < D; c++)
                    v2_st(gb->q[c] + n, v2_ld(gb->q[c] + n) + TPAIR(r, D, 1 + c, ky, kz));
            }
            if (WF)
                for (int c = 0; c < D; c++)
                    v2_st(gb->f[c] + n, v2_ld(gb->f[c] + n) - TPAIR(r, D, 4 + c, ky, kz));
        }
}

/* Particle p (weights W) into the run: WQ its mass and momentum
 * (scatter_mq()), WF its internal force (scatter_force()). */
INLINE void trun_add(const mpm_sim *s, trun *r, mpm_gridbuf *gb, const pw *W, size_t p, int D,
                     int WQ, int WF)
{
    IH(s);
    if (W->base != r->base) {
        trun_flush(s, r, gb, D, WQ, WF);
        r->base = W->base;
        trun_zero(r, D);
    }
    const mpm_particles *P = &s->P;
    const double w0 = W->w[0][0], w1 = W->w[0][1];
    double mp = 0, mv[3] = {0, 0, 0}, sg[6] = {0, 0, 0, 0, 0, 0};
    if (WQ) {
        mp = P->m[p];
        for (int c = 0; c < D; c++) mv[c] = mp * P->v[c][p];
    }
    if (WF) {
        double V = P->vol[p];
        /* the sig[] order: xx, yy, zz, xy, yz, xz (2D: no zz) */
        for (int c = 0; c < MPM_NCOMP(D); c++)
            if (D > 2 || c != 2) sg[c] = V * P->sig[c][p];
    }
#if !MPM_V4
    if (D > 2) {
        const v2d wx = {w0, w1}, gx = {-ih_[0], ih_[0]};
        for (int kz = 0; kz < 2; kz++) {
            double wz = W->w[2][kz], gz = kz ? ih_[2] : -ih_[2];
            for (int ky = 0; ky < 2; ky++) {
                double wy = W->w[1][ky], gy = ky ? ih_[1] : -ih_[1];
                double A = wy * wz, B = gy * wz, C = wy * gz;
                if (WQ) {
                    r->a[0][kz][ky] += wx * (A * mp);
                    for (int c = 0; c < 3; c++) r->a[1 + c][kz][ky] += wx * (A * mv[c]);
                }
                if (WF) {
                    r->a[4][kz][ky] += gx * (sg[0] * A) + wx * (sg[3] * B + sg[5] * C);
                    r->a[5][kz][ky] += gx * (sg[3] * A) + wx * (sg[1] * B + sg[4] * C);
                    r->a[6][kz][ky] += gx * (sg[5] * A) + wx * (sg[4] * B + sg[2] * C);
                }
            }
        }
        return;
    }
#else
    if (D > 2) {
        const v4d wx = {w0, w1, w0, w1}, gx = {-ih_[0], ih_[0], -ih_[0], ih_[0]};
        const double wy0 = W->w[1][0], wy1 = W->w[1][1];
        const v4d wy = {wy0, wy0, wy1, wy1}, gy = {-ih_[1], -ih_[1], ih_[1], ih_[1]};
        for (int kz = 0; kz < 2; kz++) {
            double wz = W->w[2][kz], gz = kz ? ih_[2] : -ih_[2];
            v4d A = wy * wz, B = gy * wz, C = wy * gz;
            if (WQ) {
                r->a[0][kz] += wx * (A * mp);
                for (int c = 0; c < 3; c++) r->a[1 + c][kz] += wx * (A * mv[c]);
            }
            if (WF) {
                r->a[4][kz] += gx * (sg[0] * A) + wx * (sg[3] * B + sg[5] * C);
                r->a[5][kz] += gx * (sg[3] * A) + wx * (sg[1] * B + sg[4] * C);
                r->a[6][kz] += gx * (sg[5] * A) + wx * (sg[4] * B + sg[2] * C);
            }
        }
        return;
    }
#endif
    const v2d wx = {w0, w1}, gx = {-ih_[0], ih_[0]};
    for (int ky = 0; ky < (D > 1 ? 2 : 1); ky++) {
        double wy = D > 1 ? W->w[1][ky] : 1.0;
        double gy = D > 1 ? (ky ? ih_[1] : -ih_[1]) : 0.0;
        double A = wy, B = gy;
        if (WQ) {
            r->b[0][ky] += wx * (A * mp);
            for (int c = 0; c < D; c++) r->b[1 + c][ky] += wx * (A * mv[c]);
        }
        if (WF) {
            if (D == 1) {
                r->b[4][ky] += gx * (sg[0] * A);
            } else {
                r->b[4][ky] += gx * (sg[0] * A) + wx * (sg[3] * B);
                r->b[5][ky] += gx * (sg[3] * A) + wx * (sg[1] * B);
            }
        }
    }
}

#endif /* MPM_TRUN_H */
