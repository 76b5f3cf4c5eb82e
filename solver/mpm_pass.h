/*
 * mpm_pass.h - the inline pieces every particle pass shares: the MPM,
 * uGIMP and B-spline families of mpm_kernels.inc and the CPDI family of
 * mpm_cpdi.c.  A particle's cell, the runs that record the supports a pass
 * moves (rowrun) and the thread's box and row extents they merge into,
 * two doubles at once (v2d), the checks of a moved particle (check_xv,
 * check_particle), the strain increment and the constitutive update of a
 * block, the energy sums made in the pass (esum, with the
 * energy pass's arithmetic; AP: APIC's affine angular momentum), the
 * velocity update (FLIP or blended with PIC) and the sort keys.
 * Private to the solver (the particle passes of mpm_kernels.inc and
 * mpm_cpdi.c; mpm_rows.c's node loops take v2d), after mpm_internal.h; everything is static and
 * always inlined, so that each specialised loop (dimension, nodes per axis, ...) compiles as
 * before.
 */
#ifndef MPM_PASS_H
#define MPM_PASS_H

#include "mpm_internal.h"
#include "mpm_model.h"

#include <limits.h>
#include <math.h>
#include <stdint.h>

/* The passes are templates: INLINE forces them inline, so that the
 * compile-time dimension, node count and variant flags fold away.  Not in
 * the sanitizer builds (make test, make tsan): there the forced inlining of
 * the 45 kernel families cost 3.5 minutes of compile time for one file,
 * and a plain inline gives the same results (the same arithmetic, in the
 * same order), only slower. */
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define INLINE static inline
#else
#define INLINE static inline __attribute__((always_inline))
#endif

/* Two doubles at once (SSE2, the x86-64 baseline; GCC and Clang vector
 * extensions elsewhere): the scatters update nodes kx and kx + 1 of a row
 * in one operation.  Each lane does the scalar code's arithmetic in its
 * order, so the results are the same bits.  Unaligned: any node may start
 * a pair. */
typedef double v2d __attribute__((vector_size(16), aligned(8), may_alias));

typedef long long v2l __attribute__((vector_size(16))); /* v2d comparisons */

/* Four doubles at once: one AVX register in the AVX2 kernels, two SSE2
 * registers in the portable ones (the same lane arithmetic, so the same
 * bits).  Only inside inline code and structs, never passed by value to
 * a function that is not inlined. */
typedef double v4d __attribute__((vector_size(32)));
/* v4d at any 8-byte boundary (four doubles of a struct's array) */
typedef double v4du __attribute__((vector_size(32), aligned(8), may_alias));

/* 1 where four lanes are one register (AVX builds: the AVX2 kernels).
 * The code built from scalars in four lanes (a row of nodes, uGIMP's axis
 * weights, the 3D tent runs, bs_block4()) takes that form only there: the
 * portable kernels' SSE2 lowered its broadcasts through the stack (two
 * 8-byte stores read back as one 16-byte load, which the store buffer
 * cannot forward), so they write it as pairs or one particle at a time. */
#if defined(__AVX__)
#define MPM_V4 1
#else
#define MPM_V4 0
#endif

INLINE v2d v2_ld(const double *p)
{
    return *(const v2d *)p;
}

INLINE void v2_st(double *p, v2d v)
{
    *(v2d *)p = v;
}

/* Cell of p along axis d (trunc of r), clamped to the padded grid: a
 * position outside the grid (the step then fails) or not finite is
 * clamped, never converted as is. */
INLINE int cell_of(const mpm_sim *s, size_t p, int d, double *rr)
{
    double r = (s->P.x[d][p] - s->x0[d]) * s->inv_h[d];
    double rmax = s->rmax[d];
    r = r >= 0 ? (r < rmax ? r : rmax) : 0.0;
    *rr = r;
    return (int)r;
}

/* The supports of the particles a pass moves, recorded as runs: sorted
 * particles come row of cells by row of cells, so consecutive particles in
 * the same row of cells (cy, cz) share a run whose node box (x: extent,
 * y and z: rows) grows in registers, and only a finished run is merged
 * into the thread's box and row extents.  A run's rows get the run's whole
 * x extent: with 3-node uGIMP this can add a node row's worth of extent
 * to a neighbouring row (a superset is harmless: the extents only say what
 * to zero, reduce and update). */
typedef struct {
    int cy, cz;       /* row of cells of the run (cy = INT_MIN: none) */
    int lo[3], hi[3]; /* its node box, clamped to the padded grid */
    int cx;           /* cell x of the last particle (box_add()) */
    size_t nchg;      /* cell changes not yet added to o->ncell */
} rowrun;

INLINE void run_init(rowrun *a)
{
    a->cy = INT_MIN;
    a->cz = 0;
    a->cx = 0;
    a->nchg = 0;
    for (int d = 0; d < 3; d++) a->lo[d] = a->hi[d] = 0;
}

INLINE void run_flush(const mpm_sim *s, mpm_thread_out *o, rowrun *a, int D)
{
    o->ncell += a->nchg;
    a->nchg = 0;
    if (a->cy == INT_MIN) return;
    /* clamped here, once per run: the cells are, the supports may reach a
     * node beyond the padded grid only when the step fails (CPDI's corner
     * boxes come clamped already: then a no-op) */
    for (int d = 0; d < D; d++) {
        if (a->lo[d] < 0) a->lo[d] = 0;
        if (a->hi[d] > s->np[d] - 1) a->hi[d] = s->np[d] - 1;
        if (a->lo[d] < o->blo[d]) o->blo[d] = a->lo[d];
        if (a->hi[d] > o->bhi[d]) o->bhi[d] = a->hi[d];
    }
    int *restrict rlo = o->rlo, *restrict rhi = o->rhi;
    size_t ny = (size_t)s->np[1];
    int z0 = D > 2 ? a->lo[2] : 0, z1 = D > 2 ? a->hi[2] : 0;
    int y0 = D > 1 ? a->lo[1] : 0, y1 = D > 1 ? a->hi[1] : 0;
    for (int z = z0; z <= z1; z++)
        for (int y = y0; y <= y1; y++) {
            size_t r = (size_t)y + (size_t)z * ny;
            if (a->lo[0] < rlo[r]) rlo[r] = a->lo[0];
            if (a->hi[0] > rhi[r]) rhi[r] = a->hi[0];
        }
    a->cy = INT_MIN;
}

/* The strain increment of L into block slot i (Eq. 29: its symmetric part
 * times dt), with the spin dt (L_ab - L_ba)/2 for the models that rotate
 * the stress or carry F: 2D in deps[2] (always: the slot plane strain's
 * eps_zz = 0 used to take), 3D in deps[6..8] when s->spin3 (a branch
 * taken the same way for a whole job); 1D has none. */
INLINE void strain_of(const mpm_sim *s, const double L[3][3], double *const deps[9], size_t i,
                      int D)
{
    double dt = s->dt;
    deps[0][i] = L[0][0] * dt;
    if (D > 1) {
        deps[1][i] = L[1][1] * dt;
        deps[2][i] = D > 2 ? L[2][2] * dt : 0.5 * (L[0][1] - L[1][0]) * dt;
        deps[3][i] = 0.5 * (L[0][1] + L[1][0]) * dt;
    }
    if (D > 2) {
        deps[4][i] = 0.5 * (L[1][2] + L[2][1]) * dt;
        deps[5][i] = 0.5 * (L[0][2] + L[2][0]) * dt;
        if (__builtin_expect(s->spin3, 0)) {
            deps[6][i] = 0.5 * (L[0][1] - L[1][0]) * dt;
            deps[7][i] = 0.5 * (L[1][2] - L[2][1]) * dt;
            deps[8][i] = 0.5 * (L[0][2] - L[2][0]) * dt;
        }
    }
}

/* Constitutive update of a block, then the volume follows the strain
 * (2D: eps_zz = 0, deps[2] is the spin).  Any other model or volume update
 * goes through mpm_model_block(), chosen once per job (s->plan.general, one
 * test per block). */
INLINE void block_update(mpm_sim *s, mpm_thread_out *o, size_t b0, size_t nb, int D)
{
    double *const *deps = o->deps;
    if (__builtin_expect(s->plan.general, 0)) {
        mpm_model_block(s, o, b0, nb);
        return;
    }
    s->model->update[D - 1](s->mats, &s->P, b0, nb, deps);
    double *restrict vol = s->P.vol + b0;
    for (size_t i = 0; i < nb; i++) {
        double tr = deps[0][i];
        if (D == 2) tr += deps[1][i];
        if (D > 2) tr += deps[1][i] + deps[2][i];
        vol[i] *= 1.0 + tr;
    }
}

/* Energy sums of a slice: kinetic, potential, momentum, angular momentum
 * (mpm_angmom_add; ANG, which the guard's pass leaves out) and mass of
 * particle p once its position and velocity are final, strain energy of a
 * block once its stress, strain and volume are.  The energy pass
 * (mpm_energy.c) sums with these functions over a slice, and a step that
 * wants its energies (EN) inside its passes over the same particles in the
 * same order, so that the sums are the same, bit for bit. */
typedef struct {
    double ek, es, ep, mom[3], ms, L[3];
    double g[3];
} esum;

INLINE void esum_init(const mpm_sim *s, esum *e)
{
    e->ek = e->es = e->ep = e->ms = 0;
    for (int d = 0; d < 3; d++) {
        e->mom[d] = e->L[d] = 0;
        e->g[d] = s->gravity[d];
    }
}

INLINE void esum_particle(const mpm_sim *s, esum *e, size_t p, int D, int AP, int ANG)
{
    const mpm_particles *P = &s->P;
    double m = P->m[p], v2 = 0;
    for (int d = 0; d < D; d++) {
        double v = P->v[d][p];
        v2 += mpm_rn(v * v);
        e->mom[d] += mpm_rn(m * v);
        e->ep -= mpm_rn(m * e->g[d] * P->x[d][p]);
    }
    if (ANG) mpm_angmom_add(P, D, p, m, e->L);
    if (ANG && AP) mpm_angmom_add_affine(P, D, p, m, e->L);
    e->ek += mpm_rn(0.5 * m * v2);
    e->ms += m;
}

/* v4d x rounded where it stands: mpm_rn() in four lanes (the AVX2+FMA
 * kernels: no product fused into the sum it feeds; elsewhere nothing). */
#if defined(MPM_KERNELS_VARIANT) && defined(__GNUC__) && defined(__x86_64__)
#define V4RN(x) __asm__("" : "+x"(x))
#else
#define V4RN(x) ((void)0)
#endif

/* The strain energy terms 0.5 (sigma : eps) V of particles p .. p + 3
 * without a strain record (2D, 3D): twice mpm_elastic_stored() of each
 * particle's material, four lanes at once, with its operations in its
 * order, every product rounded before the sum it feeds (V4RN), so the same
 * bits, added to es one particle after the other as the loop below does.
 * One call of mpm_elastic_stored() per particle, with its three divisions
 * one at a time, was about 14 % of a step that sums its energies (2D MPM,
 * 10^6 particles). */
INLINE double es_lin4(const mpm_sim *s, double es, size_t p, int D)
{
    const mpm_particles *P = &s->P;
    const mpm_mat_params *m0 = &s->mats[P->mat[p]], *m1 = &s->mats[P->mat[p + 1]],
                         *m2 = &s->mats[P->mat[p + 2]], *m3 = &s->mats[P->mat[p + 3]];
    const v4d mu = {m0->mu, m1->mu, m2->mu, m3->mu}, K = {m0->K, m1->K, m2->K, m3->K};
    const v4d s0 = *(const v4du *)(P->sig[0] + p), s1 = *(const v4du *)(P->sig[1] + p);
    const v4d s3 = *(const v4du *)(P->sig[3] + p);
    v4d s2;
    if (P->sig[2]) {
        s2 = *(const v4du *)(P->sig[2] + p);
    } else { /* mpm_sig_zz() */
        const v4d nu = {m0->nu, m1->nu, m2->nu, m3->nu};
        s2 = nu * (s0 + s1);
        V4RN(s2);
    }
    v4d tr = s0 + s1 + s2, pm = tr / 3.0;
    v4d d0 = s0 - pm, d1 = s1 - pm, d2 = s2 - pm;
    v4d q0 = d0 * d0, q1 = d1 * d1, q2 = d2 * d2, sh = s3 * s3;
    V4RN(q0);
    V4RN(q1);
    V4RN(q2);
    V4RN(sh);
    if (D > 2) { /* 2D: sigma_yz = sigma_xz = 0, and h + 0 is h */
        v4d s4 = *(const v4du *)(P->sig[4] + p), s5 = *(const v4du *)(P->sig[5] + p);
        v4d h4 = s4 * s4, h5 = s5 * s5;
        V4RN(h4);
        V4RN(h5);
        sh = sh + h4 + h5;
    }
    sh = 2.0 * sh;
    V4RN(sh);
    v4d ss = q0 + q1 + q2 + sh, tt = tr * tr;
    V4RN(tt);
    v4d st = ss / (4.0 * mu) + tt / (18.0 * K); /* mpm_elastic_stored() */
    v4d t = 0.5 * (2.0 * st) * *(const v4du *)(P->vol + p);
    V4RN(t);
    es += t[0];
    es += t[1];
    es += t[2];
    es += t[3];
    return es;
}

/* esum_particle() of particles [b0, b1) (2D, 3D: four at a time).  Each
 * particle's terms are esum_particle()'s, four lanes at once with every
 * product rounded (V4RN, as mpm_rn()), added to the sums one particle
 * after the other in its order: the same bits.  The potential skips the
 * axes without gravity, whose terms m 0 x are zeros (adding one changes
 * no sum). */
INLINE void esum_block(const mpm_sim *s, esum *e, size_t b0, size_t b1, int D, int AP, int ANG)
{
    const mpm_particles *P = &s->P;
    size_t p = b0;
    if (D > 1)
        for (; p + 3 < b1; p += 4) {
            const v4d m = *(const v4du *)(P->m + p);
            v4d x[3], v[3], mv[3], pe[3], L[3] = {{0}}, La[3] = {{0}}, v2 = {0, 0, 0, 0};
            for (int d = 0; d < D; d++) {
                /* x is read by the potential where there is gravity and
                 * by the angular momentum */
                x[d] = (v4d){0, 0, 0, 0};
                if (ANG || e->g[d] != 0.0) x[d] = *(const v4du *)(P->x[d] + p);
                v[d] = *(const v4du *)(P->v[d] + p);
                v4d q = v[d] * v[d];
                mv[d] = m * v[d];
                pe[d] = m * e->g[d] * x[d];
                V4RN(q);
                V4RN(mv[d]);
                V4RN(pe[d]);
                v2 = v2 + q;
            }
            /* mpm_angmom_add(): 2D L[2] only */
            for (int a = (D > 2 ? 0 : 2); ANG && a < 3; a++) {
                int i = (a + 1) % 3, j = (a + 2) % 3; /* L_a = m (x_i v_j - x_j v_i) */
                v4d u = x[i] * v[j], w = x[j] * v[i];
                V4RN(u);
                V4RN(w);
                L[a] = m * (u - w);
                V4RN(L[a]);
            }
            if (ANG && AP) { /* mpm_angmom_add_affine() */
                static const int hi[3] = {7, 2, 3}, lo[3] = {5, 6, 1};
                for (int a = (D > 2 ? 0 : 2); a < 3; a++) {
                    La[a] =
                        m * (*(const v4du *)(P->B[hi[a]] + p) - *(const v4du *)(P->B[lo[a]] + p));
                    V4RN(La[a]);
                }
            }
            v4d k = 0.5 * m * v2;
            V4RN(k);
            for (int l = 0; l < 4; l++) {
                for (int d = 0; d < D; d++) {
                    e->mom[d] += mv[d][l];
                    if (e->g[d] != 0.0) e->ep -= pe[d][l];
                }
                for (int a = (D > 2 ? 0 : 2); ANG && a < 3; a++) {
                    e->L[a] += L[a][l];
                    if (AP) e->L[a] += La[a][l];
                }
                e->ek += k[l];
                e->ms += m[l];
            }
        }
    for (; p < b1; p++) esum_particle(s, e, p, D, AP, ANG);
}

INLINE void esum_strain(const mpm_sim *s, esum *e, size_t b0, size_t nb, int D)
{
    const mpm_particles *P = &s->P;
    if (__builtin_expect(s->plan.general, 0)) {
        for (size_t p = b0; p < b0 + nb; p++) e->es += mpm_model_energy(s, p);
        return;
    }
    size_t p = b0;
    if (D > 1 && !P->eps[0])
        for (; p + 3 < b0 + nb; p += 4) e->es = es_lin4(s, e->es, p, D);
    for (; p < b0 + nb; p++)
        e->es += mpm_rn(0.5 * mpm_strain_density(s->mats, P, D, p) * P->vol[p]);
}

/* the slice's sums into o: the kinematic ones (XV) and/or the strain (S) */
INLINE void esum_store(const esum *e, mpm_thread_out *o, int XV, int S)
{
    if (XV) {
        o->ekin = e->ek;
        o->epot = e->ep;
        o->emass = e->ms;
        for (int d = 0; d < 3; d++) {
            o->emom[d] = e->mom[d];
            o->eang[d] = e->L[d];
        }
    }
    if (S) o->estr = e->es;
}

/* The checks of a moved particle p, on its new position xn and velocity
 * vn in registers and the bounds lo_, hi_: x in [lo, hi) and |v| <=
 * 1.79e308 (not a NaN), axes 0 and 1 two at a time; the largest |v|^2 and
 * the first bad particle go to a chk (locals across a pass: chk_init() ..
 * chk_store()). */
typedef struct {
    double vmax2;
    size_t bad;
} chk;

INLINE void chk_init(const mpm_thread_out *o, chk *c)
{
    c->vmax2 = o->vmax2;
    c->bad = o->bad;
}

INLINE void chk_store(const chk *c, mpm_thread_out *o)
{
    o->vmax2 = c->vmax2;
    o->bad = c->bad;
}

INLINE void check_xv(const double lo_[3], const double hi_[3], chk *c, size_t p, const double xn[3],
                     const double vn[3], int D)
{
    const double big = 1.79e308;
    int ok = 1, d0 = 0;
    double v2 = 0;
    if (D > 1) {
        v2d x = {xn[0], xn[1]}, v = {vn[0], vn[1]};
        v2d lo = {lo_[0], lo_[1]}, hi = {hi_[0], hi_[1]}, bg = {big, big};
        v2l m = (x >= lo) & (x < hi) & (v <= bg) & (v >= -bg);
        ok = (m[0] & m[1]) != 0;
        v2 = v2 + vn[0] * vn[0] + vn[1] * vn[1];
        d0 = 2;
    }
    for (int d = d0; d < D; d++) {
        ok &= (xn[d] >= lo_[d]) & (xn[d] < hi_[d]) & (fabs(vn[d]) <= big);
        v2 += vn[d] * vn[d];
    }
    c->vmax2 = v2 > c->vmax2 ? v2 : c->vmax2;
    if (__builtin_expect(!ok, 0) && c->bad == SIZE_MAX) c->bad = p;
}

/* Checks the updated particle p in memory (check_xv() on its stored
 * position and velocity, the bounds of s, the sums of o). */
INLINE void check_particle(const mpm_sim *s, mpm_thread_out *o, size_t p, int D)
{
    double xn[3], vn[3];
    chk c;
    for (int d = 0; d < D; d++) {
        xn[d] = s->P.x[d][p];
        vn[d] = s->P.v[d][p];
    }
    chk_init(o, &c);
    check_xv(s->lo, s->hi, &c, p, xn, vn, D);
    chk_store(&c, o);
}

/* Empty box (axes the grid lacks: node 0), and empty rows: only those of
 * the previous box can be non-empty. */
INLINE void box_reset(const mpm_sim *s, mpm_thread_out *o, int D)
{
    if (o->blo[0] <= o->bhi[0]) {
        size_t ny = (size_t)s->np[1];
        for (int z = o->blo[2]; z <= o->bhi[2]; z++)
            for (int y = o->blo[1]; y <= o->bhi[1]; y++) {
                size_t r = (size_t)y + (size_t)z * ny;
                o->rlo[r] = INT_MAX;
                o->rhi[r] = -1;
            }
    }
    for (int d = 0; d < 3; d++) {
        o->blo[d] = d < D ? INT_MAX : 0;
        o->bhi[d] = d < D ? -1 : 0;
    }
    o->ncell = 0;
}

/* The particle velocity (Eq. 31), FLIP: v += dt sum S qdot/m; blended
 * with PIC (BL): v = (1 - al) (v + dt sum S qdot/m) + al sum S q/m, with
 * the momentum q after the nodal update, so vpic = sum S v_I^{n+1} (the
 * position increment's sum; phantom nodes: 0).  bl = 1 - al. */
INLINE void v_update(double *v, double dt, double dv, double vpic, int BL, double al, double bl)
{
    if (BL)
        *v = bl * (*v + dt * dv) + al * vpic;
    else
        *v += dt * dv;
}

/* Sort key of particle p: its cell (x, row) numbered row-major over the
 * rows' extents, rowoff[row] + x - ulo[row] (a cell's first node lies in
 * the extents of its row; clamped all the same).  The simulation's fields
 * are read into locals first: a store to key[] (uint32_t) may alias the
 * int fields, which the loop would otherwise reload for every particle
 * (cell_of()'s operations, so the same keys). */
INLINE void cell_keys_t(const mpm_sim *s, uint32_t *key, size_t p0, size_t p1, int D)
{
    const size_t ny = (size_t)s->np[1], nk = s->rowoff[s->nrows];
    const int blo1 = s->blo[1], bhi1 = s->bhi[1], blo2 = s->blo[2], bhi2 = s->bhi[2];
    const int *ulo = s->ulo, *uhi = s->uhi;
    const size_t *rowoff = s->rowoff;
    const double *x[3] = {NULL, NULL, NULL};
    double x0[3] = {0, 0, 0}, ih[3] = {0, 0, 0}, rmax[3] = {0, 0, 0};
    for (int d = 0; d < D; d++) {
        x[d] = s->P.x[d];
        x0[d] = s->x0[d];
        ih[d] = s->inv_h[d];
        rmax[d] = s->rmax[d];
    }
    for (size_t p = p0; p < p1; p++) {
        int c[3] = {0, 0, 0};
        for (int d = 0; d < D; d++) {
            double r = (x[d][p] - x0[d]) * ih[d];
            r = r >= 0 ? (r < rmax[d] ? r : rmax[d]) : 0.0;
            c[d] = (int)r;
        }
        int c1 = c[1] < blo1 ? blo1 : c[1] > bhi1 ? bhi1 : c[1];
        int c2 = c[2] < blo2 ? blo2 : c[2] > bhi2 ? bhi2 : c[2];
        size_t row = (size_t)c1 + (size_t)c2 * ny;
        int lo = ulo[row], w = uhi[row] - lo;
        int xc = c[0] - lo;
        xc = xc < 0 ? 0 : xc > w ? (w > 0 ? w : 0) : xc;
        size_t k = rowoff[row] + (size_t)xc;
        key[p] = (uint32_t)(k < nk ? k : nk - 1);
    }
}

#endif
