/*
 * mpm_paper.h - the GMPM paper's verification problems as ready-made cases:
 * the single material point (Section 5, Eqs. 32-33), the bar's first mode
 * (Eqs. 34-37) and the two bouncing disks (Section 5.6), with their
 * analytic solutions.  Shared by the tests, the in-process driver mpmrun
 * and the benchmarks.
 */
#ifndef MPM_PAPER_H
#define MPM_PAPER_H

#include "mpm.h"

/* A case plus the storage behind its arrays.  Fields of c may be changed
 * before mpm_sim_new(); mpm_paper_free() releases the arrays. */
typedef struct {
    mpm_case c;
    mpm_material_desc mat[2];
    mpm_body_desc body[2];
    double *x, *vol, *v;
} mpm_paper;

void mpm_paper_free(mpm_paper *t);

/* Single material point: E = 4 pi^2, L = 1, rho = 1, x0 = L/2, initial
 * velocity v0, two nodes with the left one fixed; MPM. */
void mpm_paper_point(mpm_paper *t, mpm_update up, double dt, double v0);

/* Bar: E = 10, L = 1, rho = 1, fixed at x = 0, v(x, 0) = v0 sin(pi x / 2);
 * ncell cells of ppc points each (the paper: 7 cells/8 nodes MPM, 13/14
 * GMPM, one point each), plus `extra` empty cells beyond x = L for the free
 * end, which moves by up to v0 / omega_1.  Returns 0, or -1 if out of
 * memory. */
int mpm_paper_bar(mpm_paper *t, mpm_method m, mpm_update up, int ncell, int ppc, int extra,
                  double dt, double v0);
double mpm_paper_bar_omega(void);              /* omega_1 = pi/2 sqrt(E/rho) */
double mpm_paper_bar_vcm(double v0, double t); /* centre-of-mass velocity, Eq. 34 */

/* Disks: radius 0.14 in the unit square, centres (0.25, 0.25) and
 * (0.75, 0.75), speed 0.1 towards each other along the diagonal, E = 1,
 * nu = 0.2, rho = 1, 2x2 points per cell; h = 0.1 gives 24 points per disk
 * (the paper's coarse run), h = 0.025 gives 392 (fine).  Automatic dt. */
void mpm_paper_disks(mpm_paper *t, mpm_method m, mpm_update up, double h);

/* Single-point analytic solution: velocity and position at time t. */
double mpm_paper_point_v(double v0, double t);
double mpm_paper_point_x(double v0, double t);

#endif
