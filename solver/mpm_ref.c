/*
 * mpm_ref.c - the REFERENCE kernel family (mpm_case.kernel_family): one
 * explicit step in plain scalar C, written the way the papers write it, to
 * check the fast families against (tests/solver/t_reference.c) and to read.
 *
 * Per particle, the support's nodes with their weights S_Ip and gradients
 * G_Ip are made from the one-dimensional shape functions, written here from
 * their formulas (nothing of mpm_shape.h, mpm_bspline.c or mpm_cpdi.c is
 * used): MPM's tents (the reference node of Eq. 21), uGIMP's tent averaged
 * over the particle (Eqs. 17-18 with the reference node of Eq. 22), the
 * B-splines by Cox-de Boor's recursion on the open knot vector (BSPLINE3
 * with the natural end basis of mpm_internal.h), their products over the
 * axes (Eqs. 19-20), and CPDI1's corner averages.  The step loops over the
 * particles and their support nodes into one grid of momenta: P2G (Eqs.
 * 25-26, the internal force of Eq. 15), the grid update node by node
 * (gravity, point loads, damping, BC1 and BC2 of Eqs. 27-28 with
 * mpm_cond.c's prescribed velocities and friction), then G2P (Eqs. 29-31,
 * the PIC/FLIP blend, APIC after Jiang et al. 2015) in the order of USF,
 * USL or MUSL, with the stress update of the solver's models
 * (block_update(), one particle at a time).  One thread, particles in
 * creation order (no sort), the whole grid (no active rows), no vectors, no
 * fused passes.  docs/solver.md, "Reference kernels", says how its results
 * compare with the fast families'.
 */
#include "mpm_ref.h"
#include "mpm_cond.h"
#include "mpm_loads.h"

#include "mpm_internal.h"
#include "mpm_pass.h" /* strain_of(), block_update(): the solver's stress update */

#include <math.h>
#include <stdint.h>
#include <string.h>

/* The most (node, weight) entries of one particle's support: 4 nodes per
 * axis in 3D (uGIMP, BSPLINE3), or CPDI's 8 corners of 8 nodes each. */
#define REF_MAXS 64

/* One particle's support: node[i] (flat padded index), its weight S[i],
 * gradient G[i] and offset dx[i] = x_I - x_p (APIC). */
typedef struct {
    int n;
    size_t node[REF_MAXS];
    double S[REF_MAXS], G[REF_MAXS][3], dx[REF_MAXS][3];
} ref_sup;

/* One axis of a tensor-product support: k nodes (padded index idx[j]),
 * their shape function N[j] and its derivative dN[j] (per unit length). */
typedef struct {
    int k;
    int idx[4];
    double N[4], dN[4];
} ref_axis;

int mpm_ref_check(const mpm_case *c, mpm_error *err)
{
    if (c->kernel_family != MPM_KERNEL_FAMILY_FAST &&
        c->kernel_family != MPM_KERNEL_FAMILY_REFERENCE)
        return mpm_fail(err, MPM_EINVAL, "kernel_family", "unknown value %d (FAST or REFERENCE)",
                        (int)c->kernel_family);
    if (c->kernel_family == MPM_KERNEL_FAMILY_REFERENCE && c->kernels == MPM_KERNELS_AVX2)
        return mpm_fail(err, MPM_EINVAL, "kernel_family",
                        "REFERENCE runs the plain scalar kernels, not the AVX2 ones asked for by "
                        "kernels (use kernels AUTO or PORTABLE with REFERENCE)");
    return 0;
}

void mpm_ref_init(mpm_sim *s)
{
    s->ref = 1;
    s->nthreads = 1;
    s->plan.avx2 = 0;
    s->plan.fma = 0;
    s->plan.dp_lanes = 0;
    s->plan.el_lanes = 0;
    s->plan.tlanes = 0;
    s->plan.tlanes_x = 0;
    s->plan.gvel = 0; /* the grid holds momenta, as the paper's (and s->gvel) */
    s->plan.fuse = MPM_FUSE_OFF;
}

/* ---- the one-dimensional shape functions ---- */

/* The unit tent N(t) = 1 - |t| on [-1, 1], and its integral from -1,
 * F(t) = int_{-1}^t N. */
static double tent(double t)
{
    double a = fabs(t);
    return a < 1 ? 1 - a : 0;
}

static double tent_int(double t)
{
    if (t <= -1) return 0;
    if (t <= 0) return 0.5 * (1 + t) * (1 + t);
    if (t < 1) return 1 - 0.5 * (1 - t) * (1 - t);
    return 1;
}

/* MPM (Eq. 21): the nodes c and c + 1 of the particle's cell c =
 * trunc((x - x_min) / h), N_I = 1 - |x - x_I| / h, and its derivative
 * within the cell, -1/h and 1/h. */
static void axis_tent(const mpm_sim *s, int d, double x, ref_axis *a)
{
    double h = s->h[d];
    int c = (int)((x - s->x0[d]) / h);
    c = c < 0 ? 0 : c > s->np[d] - 2 ? s->np[d] - 2 : c;
    a->k = 2;
    for (int j = 0; j < 2; j++) {
        a->idx[j] = c + j;
        a->N[j] = tent((x - mpm_node_coord(s, d, c + j)) / h);
        a->dN[j] = (j ? 1.0 : -1.0) / h;
    }
}

/* uGIMP (Eqs. 17-18, reference node Eq. 22): the tent averaged over the
 * particle [x - lp, x + lp]: with s = (x - x_I)/h and a = lp/h,
 * S = (F(s + a) - F(s - a)) / (2a) and G = dS/dx = (N(s + a) - N(s - a)) /
 * (2 lp), over nodes c - 1 .. c + 2. */
static void axis_gimp(const mpm_sim *s, int d, double x, double lp, ref_axis *a)
{
    double h = s->h[d], al = lp / h;
    int c = (int)((x - s->x0[d]) / h);
    a->k = 0;
    for (int i = c - 1; i <= c + 2; i++) {
        if (i < 0 || i >= s->np[d]) continue;
        double t = (x - mpm_node_coord(s, d, i)) / h;
        a->idx[a->k] = i;
        a->N[a->k] = (tent_int(t + al) - tent_int(t - al)) / (2 * al);
        a->dN[a->k] = (tent(t + al) - tent(t - al)) / (2 * lp);
        a->k++;
    }
}

/* Knot k of the open knot vector of degree p on n cells (cell units):
 * t_k = clamp(k - p, 0, n). */
static double knot(int p, int n, int k)
{
    int t = k - p;
    return t < 0 ? 0.0 : t > n ? (double)n : (double)t;
}

/* Cox-de Boor: B-spline j of degree k on that knot vector at r (cell
 * units); the last span is closed on the right (r = n belongs to it). */
static double bs_N(int p, int n, int j, int k, double r)
{
    double tj = knot(p, n, j), tj1 = knot(p, n, j + 1);
    if (k == 0) return (tj <= r && r < tj1) || (r >= n && tj < tj1 && tj1 == n) ? 1.0 : 0.0;
    double a = 0, b = 0, tjk = knot(p, n, j + k), tjk1 = knot(p, n, j + k + 1);
    if (tjk > tj) a = (r - tj) / (tjk - tj) * bs_N(p, n, j, k - 1, r);
    if (tjk1 > tj1) b = (tjk1 - r) / (tjk1 - tj1) * bs_N(p, n, j + 1, k - 1, r);
    return a + b;
}

/* dN_{j,p}/dr = p/(t_{j+p} - t_j) N_{j,p-1} - p/(t_{j+p+1} - t_{j+1}) N_{j+1,p-1} */
static double bs_dN(int p, int n, int j, double r)
{
    double tj = knot(p, n, j), tjp = knot(p, n, j + p);
    double tj1 = knot(p, n, j + 1), tjp1 = knot(p, n, j + p + 1), d = 0;
    if (tjp > tj) d += p / (tjp - tj) * bs_N(p, n, j, p - 1, r);
    if (tjp1 > tj1) d -= p / (tjp1 - tj1) * bs_N(p, n, j + 1, p - 1, r);
    return d;
}

/* B-splines of degree p on the axis' n cells: the control functions
 * j = c .. c + p of the particle's cell c.  BSPLINE2's nodes are the
 * control points; BSPLINE3's are the natural end basis' n + 1 nodes:
 * node 0 = N_0 + 2/3 N_1, node 1 = N_2 + 1/3 N_1, node i = N_{i+1} inside,
 * node n - 1 = N_n + 1/3 N_{n+1}, node n = N_{n+2} + 2/3 N_{n+1}. */
static void axis_bspline(const mpm_sim *s, int d, double x, ref_axis *a)
{
    int p = s->bsp, n = s->bs[d].n;
    double h = s->h[d], r = (x - s->x0[d]) / h;
    int c = (int)r;
    c = c < 0 ? 0 : c > n - 1 ? n - 1 : c;
    double N[4] = {0, 0, 0, 0}, dN[4] = {0, 0, 0, 0};
    int lo = p == 2 ? c : c - 1; /* the first node of the window */
    for (int j = c; j <= c + p; j++) {
        double v = bs_N(p, n, j, p, r), g = bs_dN(p, n, j, r) / h;
        int node[2] = {j, -1};
        double share[2] = {1, 0};
        if (p == 3) { /* the natural end basis */
            node[0] = j == 0 ? 0 : j == n + 2 ? n : j - 1;
            if (j == 1) {
                node[0] = 0, node[1] = 1, share[0] = 2.0 / 3.0, share[1] = 1.0 / 3.0;
            } else if (j == n + 1) {
                node[0] = n - 1, node[1] = n, share[0] = 1.0 / 3.0, share[1] = 2.0 / 3.0;
            }
        }
        for (int e = 0; e < 2; e++) {
            if (node[e] < 0) continue;
            N[node[e] - lo] += share[e] * v;
            dN[node[e] - lo] += share[e] * g;
        }
    }
    a->k = 0;
    for (int w = 0; w < 4; w++) {
        int i = lo + w;
        if (i < 0 || i >= s->np[d] || (p == 2 && w == 3)) continue;
        a->idx[a->k] = i;
        a->N[a->k] = N[w];
        a->dN[a->k] = dN[w];
        a->k++;
    }
}

/* ---- a particle's support ---- */

/* CPDI1: the domain J = [r_1 .. r_D], r_a = F lp_a e_a, its corners x_c =
 * x_p + J s_c, S_I = 2^-D sum_c N_I(x_c), G_I = 2^-D sum_c N_I(x_c) J^-T s_c,
 * N_I the tents of each corner's cell; a node shared by corners appears
 * once per corner. */
static void support_cpdi(const mpm_sim *s, size_t p, ref_sup *u)
{
    const int D = s->dim;
    double J[3][3] = {{0}}, C[3][3] = {{0}}, det;
    for (int i = 0; i < D; i++)
        for (int a = 0; a < D; a++) J[i][a] = s->P.F[i * D + a][p] * s->P.lp[a][p];
    if (D == 1) { /* cofactors: J^-T = C / det J */
        C[0][0] = 1;
        det = J[0][0];
    } else if (D == 2) {
        C[0][0] = J[1][1], C[0][1] = -J[1][0], C[1][0] = -J[0][1], C[1][1] = J[0][0];
        det = J[0][0] * J[1][1] - J[0][1] * J[1][0];
    } else {
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                C[i][j] = J[(i + 1) % 3][(j + 1) % 3] * J[(i + 2) % 3][(j + 2) % 3] -
                          J[(i + 1) % 3][(j + 2) % 3] * J[(i + 2) % 3][(j + 1) % 3];
        det = J[0][0] * C[0][0] + J[0][1] * C[0][1] + J[0][2] * C[0][2];
    }
    double wc = 1.0 / (1 << D);
    u->n = 0;
    for (int c = 0; c < (1 << D); c++) {
        double sc[3], g[3] = {0, 0, 0};
        ref_axis ax[3];
        for (int a = 0; a < D; a++) sc[a] = (c >> a) & 1 ? 1.0 : -1.0;
        for (int i = 0; i < D; i++) {
            double xc = s->P.x[i][p];
            for (int a = 0; a < D; a++) {
                xc += J[i][a] * sc[a];
                g[i] += C[i][a] / det * sc[a];
            }
            axis_tent(s, i, xc, &ax[i]);
        }
        for (int k = 0; k < (1 << D); k++) {
            double S = wc;
            size_t node = 0;
            for (int i = 0; i < D; i++) {
                int j = (k >> i) & 1;
                S *= ax[i].N[j];
                node += (size_t)ax[i].idx[j] * s->stride[i];
                u->dx[u->n][i] = mpm_node_coord(s, i, ax[i].idx[j]) - s->P.x[i][p];
            }
            u->node[u->n] = node;
            u->S[u->n] = S;
            for (int i = 0; i < 3; i++) u->G[u->n][i] = i < D ? S * g[i] : 0.0;
            u->n++;
        }
    }
}

/* The support of particle p at its position (and CPDI domain) as they are
 * now: the products of the axes' functions (Eqs. 19-20), S = N_x N_y N_z
 * and G = (N_x' N_y N_z, N_x N_y' N_z, N_x N_y N_z'). */
static void support(const mpm_sim *s, size_t p, ref_sup *u)
{
    const int D = s->dim;
    if (s->method == MPM_METHOD_CPDI) {
        support_cpdi(s, p, u);
        return;
    }
    ref_axis ax[3];
    for (int d = 0; d < 3; d++) {
        if (d >= D) {
            ax[d] = (ref_axis){1, {0, 0, 0, 0}, {1, 0, 0, 0}, {0, 0, 0, 0}};
            continue;
        }
        double x = s->P.x[d][p];
        if (s->method == MPM_METHOD_MPM)
            axis_tent(s, d, x, &ax[d]);
        else if (s->method == MPM_METHOD_GIMP)
            axis_gimp(s, d, x, s->P.lp[d][p], &ax[d]);
        else
            axis_bspline(s, d, x, &ax[d]);
    }
    u->n = 0;
    for (int kz = 0; kz < ax[2].k; kz++)
        for (int ky = 0; ky < ax[1].k; ky++)
            for (int kx = 0; kx < ax[0].k; kx++) {
                const int k[3] = {kx, ky, kz};
                size_t node = 0;
                double S = 1;
                for (int d = 0; d < D; d++) {
                    node += (size_t)ax[d].idx[k[d]] * s->stride[d];
                    S *= ax[d].N[k[d]];
                    u->dx[u->n][d] = mpm_node_coord(s, d, ax[d].idx[k[d]]) - s->P.x[d][p];
                }
                for (int d = 0; d < 3; d++) {
                    double G = d < D ? ax[d].dN[k[d]] : 0.0;
                    for (int e = 0; e < D; e++)
                        if (e != d) G *= ax[e].N[k[e]];
                    u->G[u->n][d] = G;
                }
                u->node[u->n] = node;
                u->S[u->n] = S;
                u->n++;
            }
}

/* ---- grid values ---- */

/* Node n is a phantom node: mass <= M_TOL (Section 4.4), no velocity. */
static int phantom(const mpm_sim *s, size_t n)
{
    return !(s->g.m[n] > s->mtol);
}

/* The velocity of node n along a from the momentum field q: q/m, or with
 * old (USF's CPDI position pass) the velocity before the nodal update,
 * (q - dt f)/m; 0 at a phantom node. */
static double gvel(const mpm_sim *s, double *const q[3], int old, int a, size_t n)
{
    if (phantom(s, n)) return 0.0;
    double qa = old ? q[a][n] - s->dt * s->g.f[a][n] : q[a][n];
    return qa / s->g.m[n];
}

/* The velocity gradient L_ab = sum_I v_Ia G_Ib (the strain increment of
 * Eq. 29 is dt sym(L)).  A phantom node takes, in the gradient only, the
 * velocity interpolated at the particle from the other nodes, u_p =
 * sum' S v / sum' S (docs/solver.md, "Phantom nodes in the velocity
 * gradient"): L += u_p (sum_phantom G)^T. */
static void vel_grad(const mpm_sim *s, const ref_sup *u, double *const q[3], int old,
                     double L[3][3])
{
    const int D = s->dim;
    double U[3] = {0, 0, 0}, Gp[3] = {0, 0, 0}, Sn = 0;
    int nph = 0;
    memset(L, 0, 9 * sizeof(double));
    for (int i = 0; i < u->n; i++) {
        size_t n = u->node[i];
        if (phantom(s, n)) {
            nph++;
            for (int b = 0; b < D; b++) Gp[b] += u->G[i][b];
            continue;
        }
        Sn += u->S[i];
        for (int a = 0; a < D; a++) {
            double v = gvel(s, q, old, a, n);
            U[a] += u->S[i] * v;
            for (int b = 0; b < D; b++) L[a][b] += v * u->G[i][b];
        }
    }
    if (nph && Sn > 0)
        for (int a = 0; a < D; a++)
            for (int b = 0; b < D; b++) L[a][b] += U[a] / Sn * Gp[b];
}

/* APIC: the matrix the scatter applies to a node's offset or gradient.
 * MPM tents: B_p itself, scattered as m_p B_p G_I (Jiang's multilinear
 * form, defined on grid lines where D_p is singular).  Otherwise C_p =
 * B_p D_p^-1, D_p = sum_I S_I (x_I - x_p)(x_I - x_p)^T, scattered as
 * S_I m_p C_p (x_I - x_p).  Returns 0 (nothing to scatter) for FLIP. */
static int apic_matrix(const mpm_sim *s, size_t p, const ref_sup *u, double A[3][3])
{
    const int D = s->dim;
    if (s->transfer != MPM_TRANSFER_APIC) return 0;
    double B[3][3] = {{0}};
    for (int a = 0; a < D; a++)
        for (int b = 0; b < D; b++) B[a][b] = s->P.B[3 * a + b][p];
    if (s->method == MPM_METHOD_MPM) {
        memcpy(A, B, sizeof B);
        return 1;
    }
    double M[3][3] = {{0}}, Mi[3][3] = {{0}};
    for (int i = 0; i < u->n; i++)
        for (int a = 0; a < D; a++)
            for (int b = 0; b < D; b++) M[a][b] += u->S[i] * u->dx[i][a] * u->dx[i][b];
    if (D == 1) {
        Mi[0][0] = 1 / M[0][0];
    } else if (D == 2) {
        double det = M[0][0] * M[1][1] - M[0][1] * M[1][0];
        Mi[0][0] = M[1][1] / det, Mi[1][1] = M[0][0] / det;
        Mi[0][1] = -M[0][1] / det, Mi[1][0] = -M[1][0] / det;
    } else {
        double C[3][3];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                C[i][j] = M[(i + 1) % 3][(j + 1) % 3] * M[(i + 2) % 3][(j + 2) % 3] -
                          M[(i + 1) % 3][(j + 2) % 3] * M[(i + 2) % 3][(j + 1) % 3];
        double det = M[0][0] * C[0][0] + M[0][1] * C[0][1] + M[0][2] * C[0][2];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) Mi[i][j] = C[j][i] / det; /* the adjugate */
    }
    memset(A, 0, 9 * sizeof(double));
    for (int a = 0; a < D; a++)
        for (int b = 0; b < D; b++)
            for (int k = 0; k < D; k++) A[a][b] += B[a][k] * Mi[k][b];
    return 1;
}

/* The momentum of particle p on support entry i (Eq. 26): S m_p v_p, with
 * APIC's affine part when ap (A from apic_matrix()). */
static void node_momentum(const mpm_sim *s, size_t p, const ref_sup *u, int i, int ap,
                          const double A[3][3], double out[3])
{
    const int D = s->dim;
    double mp = s->P.m[p];
    for (int a = 0; a < D; a++) {
        double v = s->P.v[a][p], aff = 0;
        if (!ap) {
            out[a] = u->S[i] * mp * v;
        } else if (s->method == MPM_METHOD_MPM) {
            for (int b = 0; b < D; b++) aff += A[a][b] * u->G[i][b];
            out[a] = mp * (u->S[i] * v + aff);
        } else {
            for (int b = 0; b < D; b++) aff += A[a][b] * u->dx[i][b];
            out[a] = u->S[i] * mp * (v + aff);
        }
    }
}

/* The stress of particle p as a 3 x 3 tensor (the in-plane part in 2D:
 * sigma_zz has no gradient to act on in plane strain). */
static void stress_of(const mpm_sim *s, size_t p, double sg[3][3])
{
    const int D = s->dim;
    memset(sg, 0, 9 * sizeof(double));
    sg[0][0] = s->P.sig[0][p];
    if (D > 1) {
        sg[1][1] = s->P.sig[1][p];
        sg[0][1] = sg[1][0] = s->P.sig[3][p];
    }
    if (D > 2) {
        sg[2][2] = s->P.sig[2][p];
        sg[1][2] = sg[2][1] = s->P.sig[4][p];
        sg[0][2] = sg[2][0] = s->P.sig[5][p];
    }
}

/* Internal force of particle p (Eq. 15): f_I -= V_p sigma_p G_I. */
static void scatter_force(mpm_sim *s, size_t p, const ref_sup *u)
{
    const int D = s->dim;
    double sg[3][3], V = s->P.vol[p];
    stress_of(s, p, sg);
    for (int i = 0; i < u->n; i++)
        for (int a = 0; a < D; a++) {
            double t = 0;
            for (int b = 0; b < D; b++) t += sg[a][b] * u->G[i][b];
            s->g.f[a][u->node[i]] -= V * t;
        }
}

/* ---- the passes ---- */

/* P2G: mass and momentum (Eqs. 25-26), and with force the internal force
 * (Eq. 15), of every particle at its position now. */
static void p2g(mpm_sim *s, int force)
{
    const int D = s->dim;
    ref_sup u;
    for (size_t p = 0; p < s->P.n; p++) {
        double A[3][3], q[3];
        support(s, p, &u);
        int ap = apic_matrix(s, p, &u, A);
        for (int i = 0; i < u.n; i++) {
            size_t n = u.node[i];
            s->g.m[n] += u.S[i] * s->P.m[p];
            node_momentum(s, p, &u, i, ap, A, q);
            for (int a = 0; a < D; a++) s->g.q[a][n] += q[a];
        }
        if (force) scatter_force(s, p, &u);
    }
}

/* MUSL: the momentum of the updated particle velocities (and APIC's
 * updated affine field) into q2. */
static void p2g_q2(mpm_sim *s)
{
    const int D = s->dim;
    ref_sup u;
    for (size_t p = 0; p < s->P.n; p++) {
        double A[3][3], q[3];
        support(s, p, &u);
        int ap = apic_matrix(s, p, &u, A);
        for (int i = 0; i < u.n; i++) {
            node_momentum(s, p, &u, i, ap, A, q);
            for (int a = 0; a < D; a++) s->g.q2[a][u.node[i]] += q[a];
        }
    }
}

/* The grid after P2G: 1/m with phantom nodes at 0 (mpm_sim.minv, which
 * the friction reads), then BC1 (Eq. 27: prescribed velocities, then the
 * fixed components of q zeroed). */
static void grid_begin(mpm_sim *s)
{
    size_t nn = s->nn;
    for (size_t n = 0; n < nn; n++) s->minv[n] = phantom(s, n) ? 0.0 : 1.0 / s->g.m[n];
    if (s->has_cond) mpm_cond_bc1(s, 0, nn - 1);
    mpm_bc_zero(s, s->g.q, 0, nn - 1);
}

/* The rate of momentum and the nodal update: gravity f += m g (Eq. 14,
 * sum_p m_p b S_Ip = m_I b), the point loads f_I += S_I f_p, damping, BC2
 * (Eq. 28: friction and prescribed velocities, then the fixed components
 * of f zeroed), and q += f dt (Eq. 13). */
static void grid_update(mpm_sim *s)
{
    const int D = s->dim;
    size_t nn = s->nn;
    double dt = s->dt;
    for (int a = 0; a < D; a++)
        if (s->gravity[a] != 0)
            for (size_t n = 0; n < nn; n++) s->g.f[a][n] += s->g.m[n] * s->gravity[a];
    ref_sup u;
    for (size_t l = 0; l < s->nload; l++) {
        support(s, s->load_p[l], &u);
        for (int i = 0; i < u.n; i++)
            for (int a = 0; a < D; a++) s->g.f[a][u.node[i]] += u.S[i] * s->load_f[a][l];
    }
    if (s->damp_on) { /* LOCAL: f_d = -alpha |f| sign(v); VISCOUS: f_d = -c q */
        double c = s->damp_coef, work = 0;
        for (int a = 0; a < D; a++)
            for (size_t n = 0; n < nn; n++) {
                if (phantom(s, n)) continue;
                double q = s->g.q[a][n], m = s->g.m[n], f = s->g.f[a][n], v = q / m, fd;
                if (s->damp == MPM_DAMPING_LOCAL)
                    fd = v > 0 ? -c * fabs(f) : v < 0 ? c * fabs(f) : 0.0;
                else
                    fd = -c * q;
                s->g.f[a][n] = f + fd;
                /* its work over the update, at the mean velocity (q + q + f dt)/2m */
                work -= fd * (q + 0.5 * (f + fd) * dt) / m * dt;
            }
        s->tout[0].edamp += work;
    }
    if (s->has_cond) mpm_cond_bc2(s, 0, 0, nn - 1);
    mpm_bc_zero(s, s->g.f, 0, nn - 1);
    for (int a = 0; a < D; a++)
        for (size_t n = 0; n < nn; n++) s->g.q[a][n] += s->g.f[a][n] * dt;
}

/* Sums over a support after the nodal update: the PIC velocity
 * vp = sum S q/m (Eq. 30's increment), the FLIP increment dv = sum S f/m
 * (Eq. 31), and APIC's B = sum S v_I (x_I - x_p)^T. */
static void gather_v(const mpm_sim *s, const ref_sup *u, double vp[3], double dv[3], double B[3][3])
{
    const int D = s->dim;
    for (int a = 0; a < 3; a++) {
        vp[a] = dv[a] = 0;
        B[a][0] = B[a][1] = B[a][2] = 0;
    }
    for (int i = 0; i < u->n; i++) {
        size_t n = u->node[i];
        for (int a = 0; a < D; a++) {
            double v = gvel(s, s->g.q, 0, a, n), acc = gvel(s, s->g.f, 0, a, n);
            vp[a] += u->S[i] * v;
            dv[a] += u->S[i] * acc;
            for (int b = 0; b < D; b++) B[a][b] += u->S[i] * v * u->dx[i][b];
        }
    }
}

/* The particle velocity: FLIP (Eq. 31) v += dt dv, blended with PIC by
 * alpha = pic_fraction, v = (1 - alpha)(v + dt dv) + alpha vp; APIC: v = vp
 * and B_p = B. */
static void set_velocity(mpm_sim *s, size_t p, const double vp[3], const double dv[3],
                         double B[3][3])
{
    const int D = s->dim;
    double al = s->pic;
    for (int a = 0; a < D; a++) {
        if (s->transfer == MPM_TRANSFER_APIC) {
            s->P.v[a][p] = vp[a];
            for (int b = 0; b < D; b++) s->P.B[3 * a + b][p] = B[a][b];
        } else {
            double flip = s->P.v[a][p] + s->dt * dv[a];
            s->P.v[a][p] = al != 0 ? (1 - al) * flip + al * vp[a] : flip;
        }
    }
}

/* CPDI: F <- (I + dt L) F. */
static void update_F(mpm_sim *s, size_t p, const double L[3][3])
{
    const int D = s->dim;
    double F[3][3];
    for (int i = 0; i < D; i++)
        for (int j = 0; j < D; j++) F[i][j] = s->P.F[i * D + j][p];
    for (int i = 0; i < D; i++)
        for (int j = 0; j < D; j++) {
            double a = 0;
            for (int k = 0; k < D; k++) a += L[i][k] * F[k][j];
            s->P.F[i * D + j][p] = F[i][j] + s->dt * a;
        }
}

/* The stress update of particle p from L (Eq. 29, then the material's
 * model and the volume): the solver's own per-particle update. */
static void stress_update(mpm_sim *s, size_t p, const double L[3][3])
{
    mpm_thread_out *o = &s->tout[0];
    strain_of(s, L, o->deps, 0, s->dim);
    block_update(s, o, p, 1, s->dim);
}

/* The checks of a moved particle: its centre in [lo, hi), a finite
 * velocity, and for CPDI every corner in the padded grid and det F > 0;
 * the first bad particle and the largest |v|^2 into tout[0]. */
static void check_moved(mpm_sim *s, size_t p)
{
    const int D = s->dim;
    mpm_thread_out *o = &s->tout[0];
    int ok = 1;
    double v2 = 0;
    for (int d = 0; d < D; d++) {
        double x = s->P.x[d][p], v = s->P.v[d][p];
        ok &= x >= s->lo[d] && x < s->hi[d] && fabs(v) <= 1.79e308;
        v2 += v * v;
    }
    if (s->method == MPM_METHOD_CPDI) {
        double J[3][3], det;
        for (int i = 0; i < D; i++)
            for (int a = 0; a < D; a++) J[i][a] = s->P.F[i * D + a][p] * s->P.lp[a][p];
        det = D == 1   ? J[0][0]
              : D == 2 ? J[0][0] * J[1][1] - J[0][1] * J[1][0]
                       : J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
                             J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
                             J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
        ok &= det > 0;
        for (int c = 0; c < (1 << D); c++)
            for (int i = 0; i < D; i++) {
                double xc = s->P.x[i][p];
                for (int a = 0; a < D; a++) xc += (c >> a & 1 ? 1 : -1) * J[i][a];
                double r = (xc - s->x0[i]) / s->h[i];
                ok &= r >= 0 && r < s->np[i] - 1;
            }
    }
    if (v2 > o->vmax2) o->vmax2 = v2;
    if (!ok && o->bad == SIZE_MAX) o->bad = p;
}

/* USF (Fig. 2): strain from the grid velocity of the P2G, the stress, and
 * the internal force with the new stress. */
static void usf_stress(mpm_sim *s)
{
    ref_sup u;
    double L[3][3];
    for (size_t p = 0; p < s->P.n; p++) {
        support(s, p, &u);
        vel_grad(s, &u, s->g.q, 0, L);
        stress_update(s, p, L);
        scatter_force(s, p, &u);
    }
}

/* USF's G2P: positions (Eq. 30) and velocities (Eq. 31); CPDI's F from the
 * velocity before the nodal update, the one its strain used. */
static void usf_move(mpm_sim *s)
{
    const int D = s->dim;
    ref_sup u;
    for (size_t p = 0; p < s->P.n; p++) {
        double vp[3], dv[3], B[3][3], L[3][3];
        support(s, p, &u);
        gather_v(s, &u, vp, dv, B);
        if (s->method == MPM_METHOD_CPDI) {
            vel_grad(s, &u, s->g.q, 1, L);
            update_F(s, p, L);
        }
        for (int a = 0; a < D; a++) s->P.x[a][p] += s->dt * vp[a];
        set_velocity(s, p, vp, dv, B);
        check_moved(s, p);
    }
}

/* USL (Fig. 3): positions and velocities, then the strain from the updated
 * grid velocity at the step's start positions, and the stress. */
static void usl_move_stress(mpm_sim *s)
{
    const int D = s->dim;
    ref_sup u;
    for (size_t p = 0; p < s->P.n; p++) {
        double vp[3], dv[3], B[3][3], L[3][3];
        support(s, p, &u);
        gather_v(s, &u, vp, dv, B);
        vel_grad(s, &u, s->g.q, 0, L);
        if (s->method == MPM_METHOD_CPDI) update_F(s, p, L);
        for (int a = 0; a < D; a++) s->P.x[a][p] += s->dt * vp[a];
        set_velocity(s, p, vp, dv, B);
        stress_update(s, p, L);
        check_moved(s, p);
    }
}

/* MUSL: the velocities first; the momentum of the new velocities into q2
 * (BC1 on it); then positions from q and the strain from q2. */
static void musl_g2p(mpm_sim *s)
{
    const int D = s->dim;
    size_t nn = s->nn;
    ref_sup u;
    for (size_t p = 0; p < s->P.n; p++) {
        double vp[3], dv[3], B[3][3];
        support(s, p, &u);
        gather_v(s, &u, vp, dv, B);
        set_velocity(s, p, vp, dv, B);
    }
    p2g_q2(s);
    if (s->has_cond) mpm_cond_bc1q2(s, 0, nn - 1);
    mpm_bc_zero(s, s->g.q2, 0, nn - 1);
    for (size_t p = 0; p < s->P.n; p++) {
        double vp[3], dv[3], B[3][3], L[3][3];
        support(s, p, &u);
        gather_v(s, &u, vp, dv, B);
        vel_grad(s, &u, s->g.q2, 0, L);
        if (s->method == MPM_METHOD_CPDI) update_F(s, p, L);
        for (int a = 0; a < D; a++) s->P.x[a][p] += s->dt * vp[a];
        stress_update(s, p, L);
        check_moved(s, p);
    }
}

void mpm_ref_step(mpm_sim *s)
{
    const int D = s->dim;
    size_t nn = s->nn;
    s->tout[0].vmax2 = 0;
    s->tout[0].bad = SIZE_MAX;
    /* the grid is discarded every step (Section 4.5) */
    memset(s->g.m, 0, nn * sizeof(double));
    for (int a = 0; a < D; a++) {
        memset(s->g.q[a], 0, nn * sizeof(double));
        memset(s->g.f[a], 0, nn * sizeof(double));
        if (s->g.q2[a]) memset(s->g.q2[a], 0, nn * sizeof(double));
    }
    if (s->update == MPM_USF) {
        p2g(s, 0);
        grid_begin(s);
        usf_stress(s);
        grid_update(s);
        usf_move(s);
        return;
    }
    p2g(s, 1);
    grid_begin(s);
    grid_update(s);
    if (s->update == MPM_USL)
        usl_move_stress(s);
    else
        musl_g2p(s);
}
