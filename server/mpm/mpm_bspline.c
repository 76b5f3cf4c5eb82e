/*
 * mpm_bspline.c - the B-spline shape functions' cold part: the polynomial
 * pieces of the clamped spans next to the grid's ends, made once per axis
 * at creation.
 *
 * B-spline MPM (BSPLINE2, BSPLINE3) uses, per axis of n cells and degree p,
 * the open (clamped) knot vector with knots at the grid nodes, in cell
 * units t_k = clamp(k - p, 0, n), k = 0 .. n + 2p: p + 1 knots at each end,
 * one at every interior node.  It has n + p basis functions (the control
 * points, the solver's "nodes" along the axis), and a particle in span
 * (cell) c touches functions c .. c + p.  Span c is uniform (the functions
 * are the translated uniform B-splines, which mpm_kernels.c evaluates in
 * closed form) when the 2p knots around it are distinct, p - 1 <= c <= n -
 * p; the p - 1 spans at each end are not, and their pieces come from here:
 * Cox-de Boor's recursion carried out on polynomials in the local
 * coordinate f = r - c, exact up to the rounding of the knot ratios (the
 * knots are small integers).  Partition of unity holds on every span, and
 * at a grid end only the end function is nonzero (value 1): the face's
 * control point interpolates, which is what keeps BC1/BC2 exact there
 * (docs/solver.md).
 */
#include "mpm_internal.h"

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

void mpm_bspline_axis_init(mpm_bspline_axis *ax, int p, int n)
{
    memset(ax, 0, sizeof *ax);
    ax->p = p;
    ax->n = n;
    for (int e = 0; e < p - 1 && e < MPM_BS_EDGE; e++) {
        int clo = e, chi = n - p + 1 + e; /* the e-th clamped span of each end */
        if (clo < n) mpm_bspline_span(p, n, clo, ax->lo[e]);
        if (chi >= 0 && chi < n) mpm_bspline_span(p, n, chi, ax->hi[e]);
    }
}
