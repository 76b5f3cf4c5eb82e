/*
 * mpm_grid.h - the grid's data: one grid's worth of scatter targets
 * (mpm_gridbuf; the main grid and each thread's private copy), the field
 * flags the scatters and the reduction name, the slack past every grid
 * array, and the B-splines' axes (mpm_bspline.c).  The grid's geometry
 * (padding, strides, node coordinates) is in struct mpm_sim
 * (mpm_internal.h); the node passes in mpm_rows.c.
 */
#ifndef MPM_GRID_H
#define MPM_GRID_H

#include <stddef.h>

/* One grid's worth of scatter targets (the main grid, or a thread's private
 * copy when several threads scatter). */
typedef struct {
    double *m;     /* mass */
    double *q[3];  /* momentum */
    double *f[3];  /* rate of momentum f_ext - f_int (Eq. 13) */
    double *q2[3]; /* MUSL: momentum of the updated particle velocities */
} mpm_gridbuf;

/* One axis of a B-spline grid: n cells (knot spans) of the open knot vector
 * t_k = clamp(k - p, 0, n), k = 0 .. n + 2p (cell units).  Span c's p + 1
 * functions belong to nodes start .. start + p, with start = c - off on
 * the interior (uniform) spans; the spans next to the ends have their own
 * start (lo_start, hi_start) and the polynomial coefficients of their
 * functions: span c < p - 1 in lo[c], span c > n - p in hi[c - (n - p +
 * 1)]; C[k][i] is the coefficient of f^i of node start + k, f = r - c.
 *
 * BSPLINE2 (p = 2): the n + 2 control points themselves (off 0).
 * BSPLINE3 (p = 3): the natural end basis, n + 1 nodes at the grid points
 * (off 1): control points 1 and n + 1 are tied to their neighbours by
 * s''(end) = 0 (c_1 = (2 c_0 + c_2) / 3, c_{n+1} = (c_n + 2 c_{n+2}) / 3),
 * so that every function's second derivative vanishes at the grid's ends;
 * mpm_bspline.c says why. */
#define MPM_BS_EDGE 2 /* clamped spans per end, at most (p - 1, p <= 3) */
typedef struct {
    int p, n, off;
    int lo_start[MPM_BS_EDGE], hi_start[MPM_BS_EDGE];
    double lo[MPM_BS_EDGE][4][4], hi[MPM_BS_EDGE][4][4];
} mpm_bspline_axis;

/* Fills ax for degree p (2 or 3) and n cells: n >= 1 for p = 2, n >= 3 for
 * p = 3 (mpm_case_check() refuses fewer). */
void mpm_bspline_axis_init(mpm_bspline_axis *ax, int p, int n);
/* The coefficients C[k][i] (f^i of function c + k, k = 0 .. p) of the
 * B-splines of degree p on span c of n cells, by Cox-de Boor on the open
 * knot vector (cold: creation and tests). */
void mpm_bspline_span(int p, int n, int c, double C[4][4]);

/* Doubles allocated (zeroed) past the end of every grid field and of
 * minv: the AVX2 kernels load and store a support's row of three nodes as
 * four lanes (gather_rows(), the scatters in mpm_kernels.inc), which reads,
 * and adds +0 to, one node past a row that ends the array. */
#define MPM_GRID_SLACK 4

/* Grid fields, for mpm_scatter_buf() and the node passes' reduction. */
enum { MPM_F_M = 1, MPM_F_Q = 2, MPM_F_F = 4, MPM_F_Q2 = 8 };

#endif
