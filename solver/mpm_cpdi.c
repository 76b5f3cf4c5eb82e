/*
 * mpm_cpdi.c - the particle loops of CPDI1, the convected particle domain
 * interpolation of Sadeghirad, Brannon & Burghardt (2011), specialised by
 * dimension; the same function table (struct mpm_kernels) and contracts as
 * the MPM and uGIMP families of mpm_kernels.inc.
 *
 * A particle's domain is the parallelogram (2D), parallelepiped (3D) or
 * segment (1D) spanned about its centre x_p by the vectors r_a = F r_a0,
 * r_a0 = lp_a e_a: its initial half-widths (P.lp, the uGIMP rules:
 * h/(2 ppc) for generated particles, half_length for explicit points) carried
 * by its deformation gradient F (P.F).  With J = [r_1 .. r_D] and the 2^D
 * corners x_c = x_p + J s_c (s_c in {-1, 1}^D), the weights of node i are
 * the corner average of the linear grid tents N_i, and the gradients the
 * average over the domain of the gradient of the multilinear interpolation
 * of N_i between the corners (divergence theorem on the parametric cube):
 *   S_ip = 2^-D sum_c N_i(x_c)
 *   G_ip = 2^-D sum_c N_i(x_c) J^-T s_c
 * (in 2D the paper's Eq. for CPDI1 rewritten; in 3D the columns of J^-T are
 * (r_2 x r_3, r_3 x r_1, r_1 x r_2) / det J).  Both sums telescope:
 * sum_i S_ip = 1, sum_i G_ip = 2^-D J^-T sum_c s_c = 0 and, the tents being
 * linearly precise, sum_i G_ip x_i^T = 2^-D J^-T sum_c s_c (x_p + J s_c)^T =
 * I.  The support is the 2^D nodes of each corner's cell, 4^D (corner,
 * node) pairs in all, a node shared by corners appearing once per corner
 * (scattering and gathering are linear, so duplicates are harmless).  1D is
 * the two-corner segment x_p +- F lp, the cpGIMP-like case.
 *
 * Per particle, one cw holds each corner's first node, its per-axis tent
 * weights (axis 0's scaled by 2^-D, so that their product is the corner's
 * share of S) and its gradient vector J^-T s_c; every node loop forms
 * S = wx wy wz and G = S g_c from them.  The passes follow mpm_kernels.inc:
 * the USF stress pass keeps a block's cw between the strain gather and the
 * force scatter, the energies are summed in-pass with the energy pass's
 * arithmetic, a phantom node (m <= M_TOL) takes in the gradient the
 * velocity interpolated from the other nodes (as phantom_grad() there), and
 * a PIC/FLIP blend has its twin family.
 *
 * The deformation gradient: F <- (I + dt L) F with the full (non-symmetric)
 * velocity gradient L = sum_i v_i G_ip^T of the pass that moves the
 * particle, so that its position and its domain move together: USL and
 * MUSL take it from the gather that makes the strain increment; USF, whose
 * strain comes from the grid velocity before the nodal update, takes it in
 * the position pass from (q - dt f)/m, the same velocity to round-off, so
 * that the stress pass, the force scatter and the position pass all see
 * the domain the mass was scattered with.  The volume keeps the update of
 * every method, V <- V (1 + tr deps); the gradients above do not depend on
 * V (they are the domain's own), V is only the quadrature weight.
 *
 * Grid: one ghost layer per side; every corner must lie in the padded grid
 * (within one cell outside the real one) and det F > 0, else the moving
 * pass records the particle as bad and the step fails with MPM_ELEFTGRID.
 * Row extents and the support box are the box of all the corners' nodes;
 * sort keys are the centre's cell.
 */
/* the fixed-trip node loops want complete unrolling (the -O3 kind) */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("O3")
#endif

#include "mpm_cpdi.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_pass.h"

#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#define NCORN(D) (1 << (D))

/* Weights of one particle: corner c's first node base[c], tent weights
 * w[c][d][k] of node k along axis d (axis 0 scaled by 2^-D), gradient
 * vector g[c] = J^-T s_c. */
typedef struct {
    size_t base[8];
    double w[8][3][2];
    double g[8][3];
} cw;

size_t mpm_cpdi_scratch(void)
{
    return MPM_BLOCK * sizeof(cw);
}

/* The domain matrix J (J[d][a] = F_da lp_a: column a is r_a); returns det J. */
INLINE double domain(const mpm_particles *P, size_t p, int D, double J[3][3])
{
    for (int i = 0; i < D; i++)
        for (int a = 0; a < D; a++) J[i][a] = P->F[i * D + a][p] * P->lp[a][p];
    if (D == 1) return J[0][0];
    if (D == 2) return J[0][0] * J[1][1] - J[0][1] * J[1][0];
    return J[0][0] * (J[1][1] * J[2][2] - J[2][1] * J[1][2]) -
           J[0][1] * (J[1][0] * J[2][2] - J[2][0] * J[1][2]) +
           J[0][2] * (J[1][0] * J[2][1] - J[2][0] * J[1][1]);
}

/* J^-T (column a of it: r_{a+1} x r_{a+2} / det in 3D) */
INLINE void inv_t(const double J[3][3], double det, int D, double T[3][3])
{
    double id = 1.0 / det;
    if (D == 1) {
        T[0][0] = id;
    } else if (D == 2) {
        T[0][0] = J[1][1] * id;
        T[0][1] = -J[1][0] * id;
        T[1][0] = -J[0][1] * id;
        T[1][1] = J[0][0] * id;
    } else {
        for (int a = 0; a < 3; a++) {
            int b = (a + 1) % 3, e = (a + 2) % 3;
            T[0][a] = (J[1][b] * J[2][e] - J[2][b] * J[1][e]) * id;
            T[1][a] = (J[2][b] * J[0][e] - J[0][b] * J[2][e]) * id;
            T[2][a] = (J[0][b] * J[1][e] - J[1][b] * J[0][e]) * id;
        }
    }
}

/* The weights of particle p at its centre and domain as they are now. */
INLINE void cweights(const mpm_sim *s, size_t p, int D, cw *o)
{
    double J[3][3], T[3][3], xp[3];
    double det = domain(&s->P, p, D, J);
    inv_t(J, det, D, T);
    for (int d = 0; d < D; d++) xp[d] = s->P.x[d][p];
    const double sc = 1.0 / NCORN(D);
    for (int c = 0; c < NCORN(D); c++) {
        size_t base = 0;
        for (int d = 0; d < D; d++) {
            double xc = xp[d], gd = 0;
            for (int a = 0; a < D; a++) {
                int up = (c >> a) & 1;
                xc += up ? J[d][a] : -J[d][a];
                gd += up ? T[d][a] : -T[d][a];
            }
            double r = (xc - s->x0[d]) * s->inv_h[d];
            int k = (int)r;
            double f = r - k, sd = d == 0 ? sc : 1.0;
            o->w[c][d][0] = (1.0 - f) * sd;
            o->w[c][d][1] = f * sd;
            o->g[c][d] = gd;
            base += (size_t)k * s->stride[d];
        }
        o->base[c] = base;
    }
}

/* Loop over the 2^D nodes of corner c row by row: for each (ky, kz) the
 * body sees row (flat index of node kx = 0) and A = wy wz. */
#define CROWS(D, W, c, s, ...)                                                \
    do {                                                                      \
        const size_t sy_ = (s)->stride[1], sz_ = (s)->stride[2];              \
        for (int kz = 0; kz < ((D) > 2 ? 2 : 1); kz++) {                      \
            double wz = (D) > 2 ? (W).w[c][2][kz] : 1.0;                      \
            for (int ky = 0; ky < ((D) > 1 ? 2 : 1); ky++) {                  \
                double A = ((D) > 1 ? (W).w[c][1][ky] : 1.0) * wz;            \
                size_t row = (W).base[c] + ((D) > 1 ? (size_t)ky * sy_ : 0) + \
                             ((D) > 2 ? (size_t)kz * sz_ : 0);                \
                __VA_ARGS__                                                   \
            }                                                                 \
        }                                                                     \
    } while (0)

/* Mass and momentum (Eqs. 25-26). */
INLINE void scatter_mq(const mpm_sim *s, mpm_gridbuf *gb, const cw *W, size_t p, int D)
{
    double *restrict m = gb->m;
    double *restrict q0 = gb->q[0], *restrict q1 = gb->q[1], *restrict q2 = gb->q[2];
    double mp = s->P.m[p];
    double mv0 = mp * s->P.v[0][p];
    double mv1 = D > 1 ? mp * s->P.v[1][p] : 0.0, mv2 = D > 2 ? mp * s->P.v[2][p] : 0.0;
    for (int c = 0; c < NCORN(D); c++)
        CROWS(D, *W, c, s, {
            double am = A * mp, a0 = A * mv0, a1 = A * mv1, a2 = A * mv2;
            for (int kx = 0; kx < 2; kx++) {
                double S = W->w[c][0][kx];
                size_t n = row + (size_t)kx;
                m[n] += S * am;
                q0[n] += S * a0;
                if (D > 1) q1[n] += S * a1;
                if (D > 2) q2[n] += S * a2;
            }
        });
}

/* Internal force f -= V sigma . G (Eq. 15): per corner t = V sigma g_c,
 * then f_n -= S t over its nodes. */
INLINE void scatter_force(const mpm_sim *s, mpm_gridbuf *gb, const cw *W, size_t p, int D)
{
    double *restrict f0 = gb->f[0], *restrict f1 = gb->f[1], *restrict f2 = gb->f[2];
    const mpm_particles *P = &s->P;
    double V = P->vol[p];
    double sxx = V * P->sig[0][p];
    double syy = D > 1 ? V * P->sig[1][p] : 0.0, sxy = D > 1 ? V * P->sig[3][p] : 0.0;
    double szz = D > 2 ? V * P->sig[2][p] : 0.0, syz = D > 2 ? V * P->sig[4][p] : 0.0;
    double sxz = D > 2 ? V * P->sig[5][p] : 0.0;
    for (int c = 0; c < NCORN(D); c++) {
        const double *g = W->g[c];
        double gy = D > 1 ? g[1] : 0.0, gz = D > 2 ? g[2] : 0.0;
        double t0 = sxx * g[0] + sxy * gy + sxz * gz;
        double t1 = sxy * g[0] + syy * gy + syz * gz;
        double t2 = sxz * g[0] + syz * gy + szz * gz;
        CROWS(D, *W, c, s, {
            double a0 = A * t0, a1 = A * t1, a2 = A * t2;
            for (int kx = 0; kx < 2; kx++) {
                double S = W->w[c][0][kx];
                size_t n = row + (size_t)kx;
                f0[n] -= S * a0;
                if (D > 1) f1[n] -= S * a1;
                if (D > 2) f2[n] -= S * a2;
            }
        });
    }
}

/* The grid velocity of node n the gradient reads: q/m, or with OLD
 * (q - dt f)/m, the velocity before the nodal update (USF's position
 * pass); 0 at phantom nodes (minv 0). */
INLINE double gvel(const mpm_sim *s, double *const qg[3], int a, size_t n, double mi, int OLD)
{
    if (OLD) return (qg[a][n] - s->dt * s->g.f[a][n]) * mi;
    return qg[a][n] * mi;
}

/* Phantom nodes in the velocity gradient (as phantom_grad() of
 * mpm_gather.inc): a phantom node takes, in the gradient only, the velocity
 * interpolated at the particle from the other nodes, u_p = sum' S v /
 * sum' S, so L += u_p (sum_phantom G)^T.  Runs for the few particles whose
 * support has a phantom node; returns 0 when there is nothing to add. */
__attribute__((noinline, cold)) static int phantom_corr(const mpm_sim *s, double *const qg[3],
                                                        const cw *W, int D, int OLD, double u[3],
                                                        double gp[3])
{
    const double *restrict minv = s->minv;
    double U[3] = {0, 0, 0}, Sp = 0;
    for (int a = 0; a < 3; a++) gp[a] = u[a] = 0;
    for (int c = 0; c < NCORN(D); c++) {
        double ps = 0;
        CROWS(D, *W, c, s, {
            for (int kx = 0; kx < 2; kx++) {
                size_t n = row + (size_t)kx;
                double S = W->w[c][0][kx] * A, mi = minv[n];
                if (mi == 0.0) ps += S;
                for (int a = 0; a < D; a++) U[a] += S * gvel(s, qg, a, n, mi, OLD);
            }
        });
        Sp += ps;
        for (int a = 0; a < D; a++) gp[a] += ps * W->g[c][a];
    }
    double sa = 1.0 - Sp; /* sum' S; <= 0 only if every node is phantom */
    if (sa <= 0 || ((gp[0] == 0.0) & (gp[1] == 0.0) & (gp[2] == 0.0))) return 0;
    for (int a = 0; a < D; a++) u[a] = U[a] / sa;
    return 1;
}

/* One gather over the support: the velocity gradient L (DS) from the
 * momenta qg, the position increment sum S q/m from qx (DX) and the
 * velocity increment sum S f/m (DV).  The gradient's velocity per corner,
 * u_c = sum S v over the corner's nodes, comes from qg; or, when qg is qx
 * (SAME: USL), it is the corner's share of the position sum; or with OLD
 * (USF's position pass: the velocity before the nodal update, (q - dt
 * f)/m, qg = qx = q) the position share less dt times the velocity
 * increment's, so that neither costs a third sum per node. */
INLINE void gather(const mpm_sim *s, double *const qg[3], const cw *W, int D, int DS, int OLD,
                   int SAME, int DX, double *const qx[3], double dx[3], int DV, double dv[3],
                   double L[3][3])
{
    const double *restrict minv = s->minv;
    double X[3] = {0, 0, 0}, Vv[3] = {0, 0, 0}, dt = s->dt;
    int nph = 0, RU = DS && !OLD && !SAME; /* u_c needs its own sum */
    if (DS)
        for (int a = 0; a < 3; a++) L[a][0] = L[a][1] = L[a][2] = 0;
    for (int c = 0; c < NCORN(D); c++) {
        double u[3] = {0, 0, 0}, xc[3] = {0, 0, 0}, vc[3] = {0, 0, 0};
        CROWS(D, *W, c, s, {
            double ru[3] = {0, 0, 0}, rx[3] = {0, 0, 0}, rv[3] = {0, 0, 0};
            for (int kx = 0; kx < 2; kx++) {
                size_t n = row + (size_t)kx;
                double mi = minv[n], wx = W->w[c][0][kx], sm = wx * mi;
                if (DS) nph += mi == 0.0;
                for (int a = 0; a < D; a++) {
                    if (RU) ru[a] += sm * qg[a][n];
                    if (DX) rx[a] += sm * qx[a][n];
                    if (DV) rv[a] += sm * s->g.f[a][n];
                }
            }
            for (int a = 0; a < D; a++) {
                if (RU) u[a] += A * ru[a];
                if (DX) xc[a] += A * rx[a];
                if (DV) vc[a] += A * rv[a];
            }
        });
        for (int a = 0; a < D; a++) {
            if (DX) X[a] += xc[a];
            if (DV) Vv[a] += vc[a];
            if (DS && SAME) u[a] = xc[a];
            if (DS && OLD) u[a] = xc[a] - dt * vc[a];
        }
        if (DS)
            for (int a = 0; a < D; a++)
                for (int b = 0; b < D; b++) L[a][b] += u[a] * W->g[c][b];
    }
    for (int a = 0; a < D; a++) {
        if (DX) dx[a] = X[a];
        if (DV) dv[a] = Vv[a];
    }
    if (DS && __builtin_expect(nph != 0, 0)) {
        double up[3], gp[3];
        if (phantom_corr(s, qg, W, D, OLD, up, gp))
            for (int a = 0; a < D; a++)
                for (int b = 0; b < D; b++) L[a][b] += up[a] * gp[b];
    }
}

/* F <- (I + dt L) F for particle p. */
INLINE void f_update(mpm_sim *s, const double L[3][3], size_t p, int D)
{
    double *const *F = s->P.F, Fo[3][3], dt = s->dt;
    for (int i = 0; i < D; i++)
        for (int j = 0; j < D; j++) Fo[i][j] = F[i * D + j][p];
    for (int i = 0; i < D; i++)
        for (int j = 0; j < D; j++) {
            double a = 0;
            for (int k = 0; k < D; k++) a += L[i][k] * Fo[k][j];
            F[i * D + j][p] = Fo[i][j] + dt * a;
        }
}

/* ---- the support boxes and row extents ---- */

/* Particle p's corners (at its position and F as they are now): the box of
 * their nodes into lo..hi (clamped to the padded grid) and its centre's
 * cell into cc; returns 1 when every corner lies in the padded grid
 * (r in [0, np - 1)) and det J > 0, 0 otherwise (outside, inverted, or not
 * finite). */
INLINE int corner_box(const mpm_sim *s, size_t p, int D, int lo[3], int hi[3], int cc[3])
{
    double J[3][3];
    double det = domain(&s->P, p, D, J);
    int ok = det > 0;
    for (int d = 0; d < D; d++) {
        double ext = 0, rmax = (double)(s->np[d] - 1);
        for (int a = 0; a < D; a++) ext += fabs(J[d][a]);
        double x = s->P.x[d][p];
        double r0 = (x - ext - s->x0[d]) * s->inv_h[d], r1 = (x + ext - s->x0[d]) * s->inv_h[d];
        double rc = (x - s->x0[d]) * s->inv_h[d];
        ok &= (r0 >= 0) & (r1 < rmax);
        r0 = r0 >= 0 ? (r0 < rmax ? r0 : rmax) : 0.0;
        r1 = r1 >= 0 ? (r1 < rmax ? r1 : rmax) : 0.0;
        rc = rc >= 0 ? (rc < rmax ? rc : rmax) : 0.0;
        lo[d] = (int)r0;
        hi[d] = (int)r1 + 1;
        if (hi[d] > s->np[d] - 1) hi[d] = s->np[d] - 1;
        cc[d] = (int)rc;
    }
    return ok;
}

INLINE void box_add(const mpm_sim *s, mpm_thread_out *o, rowrun *a, const int lo[3],
                    const int hi[3], const int cc[3], int D)
{
    int cy = D > 1 ? cc[1] : 0, cz = D > 2 ? cc[2] : 0;
    if (cy != a->cy || cz != a->cz) {
        run_flush(s, o, a, D);
        a->cy = cy;
        a->cz = cz;
        for (int d = 0; d < D; d++) {
            a->lo[d] = lo[d];
            a->hi[d] = hi[d];
        }
        return;
    }
    for (int d = 0; d < D; d++) {
        a->lo[d] = lo[d] < a->lo[d] ? lo[d] : a->lo[d];
        a->hi[d] = hi[d] > a->hi[d] ? hi[d] : a->hi[d];
    }
}

/* The moved particle: centre inside [lo, hi), velocity finite, every
 * corner in the padded grid and det F > 0 (else it is the pass's first bad
 * particle); its corners' nodes join the run. */
INLINE void moved(const mpm_sim *s, mpm_thread_out *o, rowrun *a, size_t p, int D)
{
    int lo[3], hi[3], cc[3];
    check_particle(s, o, p, D);
    if (!corner_box(s, p, D, lo, hi, cc) && o->bad == SIZE_MAX) o->bad = p;
    box_add(s, o, a, lo, hi, cc, D);
}

/* ---- the passes ---- */

INLINE void p2g_mq_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D)
{
    cw W;
    for (size_t p = p0; p < p1; p++) {
        cweights(s, p, D, &W);
        scatter_mq(s, gb, &W, p, D);
    }
}

INLINE void p2g_mqf_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D)
{
    cw W;
    for (size_t p = p0; p < p1; p++) {
        cweights(s, p, D, &W);
        scatter_mq(s, gb, &W, p, D);
        scatter_force(s, gb, &W, p, D);
    }
}

INLINE void p2g_q2_t(mpm_sim *s, mpm_gridbuf *gb, size_t p0, size_t p1, int D)
{
    cw W;
    double *restrict q0 = gb->q2[0], *restrict q1 = gb->q2[1], *restrict q2 = gb->q2[2];
    for (size_t p = p0; p < p1; p++) {
        cweights(s, p, D, &W);
        double mp = s->P.m[p];
        double mv0 = mp * s->P.v[0][p];
        double mv1 = D > 1 ? mp * s->P.v[1][p] : 0.0, mv2 = D > 2 ? mp * s->P.v[2][p] : 0.0;
        for (int c = 0; c < NCORN(D); c++)
            CROWS(D, W, c, s, {
                double a0 = A * mv0, a1 = A * mv1, a2 = A * mv2;
                for (int kx = 0; kx < 2; kx++) {
                    double S = W.w[c][0][kx];
                    size_t n = row + (size_t)kx;
                    q0[n] += S * a0;
                    if (D > 1) q1[n] += S * a1;
                    if (D > 2) q2[n] += S * a2;
                }
            });
    }
}

/* USF: strain and stress from the grid velocity, then internal forces with
 * the new stress and the block's weights (F moves in the position pass). */
INLINE void stress_force_t(mpm_sim *s, mpm_gridbuf *gb, mpm_thread_out *o, size_t p0, size_t p1,
                           int D, int EN)
{
    cw *Wb = o->wblk;
    esum e;
    double L[3][3];
    if (EN) esum_init(s, &e);
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        for (size_t i = 0; i < nb; i++) {
            cweights(s, b0 + i, D, &Wb[i]);
            gather(s, s->g.q, &Wb[i], D, 1, 0, 0, 0, NULL, NULL, 0, NULL, L);
            strain_of(s, L, o->deps, i, D);
        }
        block_update(s, o, b0, nb, D);
        if (EN) esum_strain(s, &e, b0, nb, D);
        for (size_t i = 0; i < nb; i++) scatter_force(s, gb, &Wb[i], b0 + i, D);
    }
    if (EN) esum_store(&e, o, 0, 1);
}

/* USF's position pass (Eqs. 30-31), and F from the velocity before the
 * nodal update, (q - dt f)/m. */
INLINE void g2p_xv_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int EN, int BL)
{
    cw W;
    rowrun a;
    esum e;
    double dt = s->dt, al = BL ? s->pic : 0.0, bl = 1.0 - al, L[3][3];
    if (EN) esum_init(s, &e);
    box_reset(s, o, D);
    run_init(&a);
    for (size_t p = p0; p < p1; p++) {
        double dx[3], dv[3];
        cweights(s, p, D, &W);
        gather(s, s->g.q, &W, D, 1, 1, 0, 1, s->g.q, dx, 1, dv, L);
        f_update(s, L, p, D);
        for (int d = 0; d < D; d++) {
            s->P.x[d][p] += dt * dx[d];
            v_update(&s->P.v[d][p], dt, dv[d], dx[d], BL, al, bl);
        }
        moved(s, o, &a, p, D);
        if (EN) esum_particle(s, &e, p, D, 0, 1);
    }
    run_flush(s, o, &a, D);
    if (EN) esum_store(&e, o, 1, 0);
}

/* USL: position, velocity, F, strain and stress from one gather of the
 * updated grid momentum at the step's start domain. */
INLINE void g2p_xv_stress_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int EN,
                            int BL)
{
    cw W;
    rowrun a;
    esum e;
    double dt = s->dt, al = BL ? s->pic : 0.0, bl = 1.0 - al, L[3][3];
    if (EN) esum_init(s, &e);
    box_reset(s, o, D);
    run_init(&a);
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        for (size_t i = 0; i < nb; i++) {
            size_t p = b0 + i;
            double dx[3], dv[3];
            cweights(s, p, D, &W);
            gather(s, s->g.q, &W, D, 1, 0, 1, 1, s->g.q, dx, 1, dv, L);
            strain_of(s, L, o->deps, i, D);
            f_update(s, L, p, D);
            for (int d = 0; d < D; d++) {
                s->P.x[d][p] += dt * dx[d];
                v_update(&s->P.v[d][p], dt, dv[d], dx[d], BL, al, bl);
            }
            moved(s, o, &a, p, D);
            if (EN) esum_particle(s, &e, p, D, 0, 1);
        }
        block_update(s, o, b0, nb, D);
        if (EN) esum_strain(s, &e, b0, nb, D);
    }
    run_flush(s, o, &a, D);
    if (EN) esum_store(&e, o, 1, 1);
}

/* MUSL: the velocity only (BL: blended with PIC). */
INLINE void g2p_v_t(mpm_sim *s, size_t p0, size_t p1, int D, int BL)
{
    cw W;
    double dt = s->dt, al = BL ? s->pic : 0.0, bl = 1.0 - al;
    for (size_t p = p0; p < p1; p++) {
        double dv[3], vp[3] = {0, 0, 0};
        cweights(s, p, D, &W);
        gather(s, NULL, &W, D, 0, 0, 0, BL, s->g.q, vp, 1, dv, NULL);
        for (int d = 0; d < D; d++) v_update(&s->P.v[d][p], dt, dv[d], vp[d], BL, al, bl);
    }
}

/* MUSL: positions from the updated grid momentum; strain and F from the
 * momentum of the updated particle velocities (q2). */
INLINE void g2p_x_stress_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D, int EN)
{
    cw W;
    rowrun a;
    esum e;
    double dt = s->dt, L[3][3];
    if (EN) esum_init(s, &e);
    box_reset(s, o, D);
    run_init(&a);
    for (size_t b0 = p0; b0 < p1; b0 += MPM_BLOCK) {
        size_t nb = p1 - b0 < MPM_BLOCK ? p1 - b0 : MPM_BLOCK;
        for (size_t i = 0; i < nb; i++) {
            size_t p = b0 + i;
            double dx[3];
            cweights(s, p, D, &W);
            gather(s, s->g.q2, &W, D, 1, 0, 0, 1, s->g.q, dx, 0, NULL, L);
            strain_of(s, L, o->deps, i, D);
            f_update(s, L, p, D);
            for (int d = 0; d < D; d++) s->P.x[d][p] += dt * dx[d];
            moved(s, o, &a, p, D);
            if (EN) esum_particle(s, &e, p, D, 0, 1);
        }
        block_update(s, o, b0, nb, D);
        if (EN) esum_strain(s, &e, b0, nb, D);
    }
    run_flush(s, o, &a, D);
    if (EN) esum_store(&e, o, 1, 1);
}

/* The support box of particles [p0, p1) without moving them. */
INLINE void bbox_t(mpm_sim *s, mpm_thread_out *o, size_t p0, size_t p1, int D)
{
    rowrun a;
    box_reset(s, o, D);
    run_init(&a);
    for (size_t p = p0; p < p1; p++) {
        int lo[3], hi[3], cc[3];
        (void)corner_box(s, p, D, lo, hi, cc);
        box_add(s, o, &a, lo, hi, cc, D);
    }
    run_flush(s, o, &a, D);
}

#ifndef MPM_LEAN
/* Point forces of the loaded particles (tractions), f += S f_p (Eq. 14). */
INLINE void scatter_loads_t(mpm_sim *s, int D)
{
    cw W;
    for (size_t i = 0; i < s->nload; i++) {
        cweights(s, s->load_p[i], D, &W);
        double l0 = s->load_f[0][i], l1 = D > 1 ? s->load_f[1][i] : 0.0;
        double l2 = D > 2 ? s->load_f[2][i] : 0.0;
        for (int c = 0; c < NCORN(D); c++)
            CROWS(D, W, c, s, {
                for (int kx = 0; kx < 2; kx++) {
                    double S = W.w[c][0][kx] * A;
                    size_t n = row + (size_t)kx;
                    s->g.f[0][n] += S * l0;
                    if (D > 1) s->g.f[1][n] += S * l1;
                    if (D > 2) s->g.f[2][n] += S * l2;
                }
            });
    }
}
#else
INLINE void scatter_loads_t(mpm_sim *s, int D)
{
    (void)s;
    (void)D;
}
#endif

#define FAMILY(D)                                                                           \
    static void p2g_mq_##D(mpm_sim *s, mpm_gridbuf *gb, size_t a, size_t b)                 \
    {                                                                                       \
        p2g_mq_t(s, gb, a, b, D);                                                           \
    }                                                                                       \
    static void p2g_mqf_##D(mpm_sim *s, mpm_gridbuf *gb, size_t a, size_t b)                \
    {                                                                                       \
        p2g_mqf_t(s, gb, a, b, D);                                                          \
    }                                                                                       \
    static void p2g_q2_##D(mpm_sim *s, mpm_gridbuf *gb, size_t a, size_t b)                 \
    {                                                                                       \
        p2g_q2_t(s, gb, a, b, D);                                                           \
    }                                                                                       \
    static void stress_force_##D(mpm_sim *s, mpm_gridbuf *gb, mpm_thread_out *o, size_t a,  \
                                 size_t b, int en)                                          \
    {                                                                                       \
        if (en)                                                                             \
            stress_force_t(s, gb, o, a, b, D, 1);                                           \
        else                                                                                \
            stress_force_t(s, gb, o, a, b, D, 0);                                           \
    }                                                                                       \
    static void g2p_x_stress_##D(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b, int en) \
    {                                                                                       \
        if (en)                                                                             \
            g2p_x_stress_t(s, o, a, b, D, 1);                                               \
        else                                                                                \
            g2p_x_stress_t(s, o, a, b, D, 0);                                               \
    }                                                                                       \
    static void scatter_loads_##D(mpm_sim *s)                                               \
    {                                                                                       \
        scatter_loads_t(s, D);                                                              \
    }                                                                                       \
    static void bbox_##D(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b)                 \
    {                                                                                       \
        bbox_t(s, o, a, b, D);                                                              \
    }                                                                                       \
    static void cell_keys_##D(const mpm_sim *s, uint32_t *key, size_t a, size_t b)          \
    {                                                                                       \
        cell_keys_t(s, key, a, b, D);                                                       \
    }                                                                                       \
    VUPD(D, , 0)                                                                            \
    VUPD(D, bl_, 1)

/* The velocity updates of family D, pure FLIP (BL 0) or blended (BL 1),
 * and the table using them. */
#define VUPD(D, P, BL)                                                                          \
    static void g2p_xv_##P##D(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b, int en)        \
    {                                                                                           \
        if (en)                                                                                 \
            g2p_xv_t(s, o, a, b, D, 1, BL);                                                     \
        else                                                                                    \
            g2p_xv_t(s, o, a, b, D, 0, BL);                                                     \
    }                                                                                           \
    static void g2p_xv_stress_##P##D(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b, int en) \
    {                                                                                           \
        if (en)                                                                                 \
            g2p_xv_stress_t(s, o, a, b, D, 1, BL);                                              \
        else                                                                                    \
            g2p_xv_stress_t(s, o, a, b, D, 0, BL);                                              \
    }                                                                                           \
    static void g2p_v_##P##D(mpm_sim *s, mpm_thread_out *o, size_t a, size_t b)                 \
    {                                                                                           \
        (void)o;                                                                                \
        g2p_v_t(s, a, b, D, BL);                                                                \
    }                                                                                           \
    static const mpm_kernels cpdi_##P##D = {p2g_mq_##D,                                         \
                                            p2g_mqf_##D,                                        \
                                            p2g_q2_##D,                                         \
                                            stress_force_##D,                                   \
                                            g2p_xv_##P##D,                                      \
                                            g2p_xv_stress_##P##D,                               \
                                            g2p_v_##P##D,                                       \
                                            g2p_x_stress_##D,                                   \
                                            scatter_loads_##D,                                  \
                                            bbox_##D,                                           \
                                            cell_keys_##D,                                      \
                                            NULL,                                               \
                                            NULL,                                               \
                                            NULL,                                               \
                                            NULL};

FAMILY(1)
FAMILY(2)
FAMILY(3)

const mpm_kernels *mpm_cpdi_select(int dim, int blend)
{
    static const mpm_kernels *const table[2][3] = {{&cpdi_1, &cpdi_2, &cpdi_3},
                                                   {&cpdi_bl_1, &cpdi_bl_2, &cpdi_bl_3}};
    return table[blend != 0][dim - 1];
}

/* The weights of one particle for the tests (mpm.h). */
int mpm_cpdi_shape(const mpm_grid_desc *g, const double x[3], const double F[9], const double lp[3],
                   int ijk[64][3], double S[64], double G[64][3])
{
    int D = g->dim;
    if (D < 1 || D > 3) return -1;
    static mpm_sim zero;
    mpm_sim s = zero;
    double xs[3], Fs[9], ls[3];
    s.dim = D;
    size_t st = 1;
    for (int d = 0; d < 3; d++) {
        s.np[d] = d < D ? g->nodes[d] : 1;
        s.stride[d] = st;
        st *= (size_t)s.np[d];
        s.x0[d] = d < D ? g->origin[d] : 0;
        s.inv_h[d] = d < D ? 1.0 / g->h[d] : 1;
        xs[d] = x[d];
        ls[d] = lp[d];
        s.P.x[d] = &xs[d];
        s.P.lp[d] = &ls[d];
    }
    for (int i = 0; i < D; i++)
        for (int j = 0; j < D; j++) {
            Fs[i * D + j] = F[3 * i + j];
            s.P.F[i * D + j] = &Fs[i * D + j];
        }
    int lo[3], hi[3], cc[3];
    if (!corner_box(&s, 0, D, lo, hi, cc)) return -1;
    cw W;
    if (D == 1)
        cweights(&s, 0, 1, &W);
    else if (D == 2)
        cweights(&s, 0, 2, &W);
    else
        cweights(&s, 0, 3, &W);
    int k = 0;
    for (int c = 0; c < NCORN(D); c++)
        for (int r = 0; r < NCORN(D); r++) {
            int kk[3] = {r & 1, (r >> 1) & 1, (r >> 2) & 1};
            size_t n = W.base[c];
            double w = 1;
            for (int d = 0; d < D; d++) {
                n += (size_t)kk[d] * s.stride[d];
                w *= W.w[c][d][kk[d]];
            }
            size_t rest = n;
            for (int d = 0; d < 3; d++) {
                ijk[k][d] = d < D ? (int)(rest % (size_t)s.np[d]) : 0;
                rest /= (size_t)s.np[d];
                G[k][d] = d < D ? w * W.g[c][d] : 0.0;
            }
            S[k] = w;
            k++;
        }
    return k;
}
