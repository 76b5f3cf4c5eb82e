/*
 * mpm_bspline.c - the B-spline shape functions' cold part: the polynomial
 * pieces of the spans next to the grid's ends, made once per axis at
 * creation.
 *
 * B-spline MPM (BSPLINE2, BSPLINE3) starts, per axis of n cells and degree
 * p, from the open (clamped) knot vector with knots at the grid nodes, in
 * cell units t_k = clamp(k - p, 0, n), k = 0 .. n + 2p: p + 1 knots at
 * each end, one at every interior node, n + p basis functions (control
 * points), of which a particle in span (cell) c touches c .. c + p.  Span
 * c is uniform (the translated uniform B-splines, which mpm_kernels.inc
 * evaluates in closed form) when the 2p knots around it are distinct, p -
 * 1 <= c <= n - p; the p - 1 spans at each end are not, and their pieces
 * come from here: Cox-de Boor's recursion carried out on polynomials in
 * the local coordinate f = r - c, exact up to the rounding of the knot
 * ratios (the knots are small integers).  Partition of unity holds on
 * every span, and at a grid end only the end function is nonzero (value
 * 1): the face's node interpolates, which keeps BC1/BC2 exact there.
 *
 * BSPLINE2 uses the control points as its nodes.  BSPLINE3 uses the
 * natural end basis: the particles integrate a function's gradient exactly
 * (for a uniform stress, the force sum_p V_p grad N equals the integral)
 * when the gradient is at most linear on every cell, or, for the cubic's
 * quadratic gradients, when the midpoint rule's error, (d^2/24) [N''] over
 * the body for sub-cells of width d, vanishes: N'' = 0 where the body ends.
 * The clamped cubics have N'' = 6, -9, 3 at the grid's end (a uniform
 * stress between rollers lost 10-27 % of itself at any resolution).
 * Tying control point 1 to its neighbours by s''(0) = 6 c0 - 9 c1 + 3 c2 =
 * 0, c1 = (2 c0 + c2) / 3 (and the mirror at the top), leaves n + 1
 * functions, nonnegative, a partition of unity that reproduces x with the
 * grid points as abscissae, interpolatory at the faces, and with N'' = 0
 * at both ends (t_bspline.c bspline3_natural_ends,
 * t_verified.c verified_patch_test).
 */
#include "mpm_grid.h"

#include <string.h>

static int knot(int p, int n, int k)
{
    int t = k - p;
    return t < 0 ? 0 : t > n ? n : t;
}

void mpm_bspline_span(int p, int n, int c, double C[4][4])
{
    /* N[j - c][i]: coefficient of f^i of N_{j,k} at the current degree k,
     * j = c .. c + p + 1 (the last one stays zero) */
    double N[5][4];
    memset(N, 0, sizeof N);
    N[p][0] = 1.0; /* N_{c+p,0} = 1 on span c = [t_{c+p}, t_{c+p+1}) */
    for (int k = 1; k <= p; k++) {
        double M[5][4];
        memset(M, 0, sizeof M);
        for (int j = c + p - k; j <= c + p; j++) {
            const double *A = N[j - c], *B = N[j + 1 - c];
            double *R = M[j - c];
            int tj = knot(p, n, j), tjk = knot(p, n, j + k);
            int tj1 = knot(p, n, j + 1), tjk1 = knot(p, n, j + k + 1);
            if (tjk > tj) { /* (x - t_j)/(t_{j+k} - t_j) N_{j,k-1}, x = c + f */
                double inv = 1.0 / (tjk - tj), a = (c - tj) * inv;
                for (int i = 3; i >= 0; i--) R[i] += a * A[i] + (i ? inv * A[i - 1] : 0.0);
            }
            if (tjk1 > tj1) { /* (t_{j+k+1} - x)/(t_{j+k+1} - t_{j+1}) N_{j+1,k-1} */
                double inv = 1.0 / (tjk1 - tj1), a = (tjk1 - c) * inv;
                for (int i = 3; i >= 0; i--) R[i] += a * B[i] - (i ? inv * B[i - 1] : 0.0);
            }
        }
        memcpy(N, M, sizeof N);
    }
    for (int k = 0; k < 4; k++)
        for (int i = 0; i < 4; i++) C[k][i] = k <= p ? N[k][i] : 0.0;
}

/* Natural node and weight pairs of control point k of BSPLINE3 on n
 * cells: 0 -> node 0; 1 -> 2/3 node 0 + 1/3 node 1; k = 2 .. n -> node
 * k - 1; n + 1 -> 1/3 node n - 1 + 2/3 node n; n + 2 -> node n.  Returns
 * the number of pairs. */
static int natural_of(int n, int k, int node[2], double w[2])
{
    if (k == 1 || k == n + 1) {
        node[0] = k - 1 - (k == 1 ? 0 : 1);
        node[1] = node[0] + 1;
        w[0] = k == 1 ? 2.0 / 3.0 : 1.0 / 3.0;
        w[1] = 1.0 - w[0];
        return 2;
    }
    node[0] = k == 0 ? 0 : k == n + 2 ? n : k - 1;
    w[0] = 1.0;
    return 1;
}

/* BSPLINE3's natural pieces of span c into N (node start + k), *start */
static void natural_span(int n, int c, double N[4][4], int *start)
{
    double C[4][4];
    int s0 = c - 1 < 0 ? 0 : c - 1 > n - 3 ? n - 3 : c - 1;
    mpm_bspline_span(3, n, c, C);
    memset(N, 0, 16 * sizeof(double));
    for (int k = 0; k < 4; k++) {
        int node[2];
        double w[2];
        int m = natural_of(n, c + k, node, w);
        for (int j = 0; j < m; j++)
            for (int i = 0; i < 4; i++) N[node[j] - s0][i] += w[j] * C[k][i];
    }
    *start = s0;
}

void mpm_bspline_axis_init(mpm_bspline_axis *ax, int p, int n)
{
    memset(ax, 0, sizeof *ax);
    ax->p = p;
    ax->n = n;
    ax->off = p == 3 ? 1 : 0;
    for (int e = 0; e < p - 1 && e < MPM_BS_EDGE; e++) {
        int clo = e, chi = n - p + 1 + e; /* the e-th span next to each end */
        if (p == 3) {
            if (clo < n) natural_span(n, clo, ax->lo[e], &ax->lo_start[e]);
            if (chi >= 0 && chi < n) natural_span(n, chi, ax->hi[e], &ax->hi_start[e]);
            continue;
        }
        ax->lo_start[e] = clo;
        ax->hi_start[e] = chi;
        if (clo < n) mpm_bspline_span(p, n, clo, ax->lo[e]);
        if (chi >= 0 && chi < n) mpm_bspline_span(p, n, chi, ax->hi[e]);
    }
}
