/*
 * mpm_method.h - what the solver's code needs to know of a shape function
 * (method) beyond its kernels: how many nodes per axis a particle
 * touches, the ghost layers the grid carries, the B-spline degree, the
 * fewest grid nodes per axis, and which features it has.  One row per
 * method, beside its names in mpm_names.c; the case check, the build of a
 * simulation, the conditions and the traffic model read these rows rather
 * than the method's value (docs/architecture.md, "Adding a shape
 * function").
 */
#ifndef MPM_METHOD_H
#define MPM_METHOD_H

#include "mpm.h"

/* HALF_WIDTHS: particles carry half-widths lp (a domain: uGIMP, CPDI).
 * DOMAIN_F: the particle passes deform each domain by F themselves (CPDI:
 * F always carried, grid stores momenta rather than velocities, sorts by
 * time alone).  AVX2: AVX2+FMA kernel families exist.  APIC: the APIC
 * transfer is implemented.  NODE_BC: explicit boundary nodes mean grid
 * nodes (not B-spline control points). */
enum {
    MPM_METH_HALF_WIDTHS = 1,
    MPM_METH_DOMAIN_F = 2,
    MPM_METH_AVX2 = 4,
    MPM_METH_APIC = 8,
    MPM_METH_NODE_BC = 16
};

typedef struct {
    int support;     /* nodes per axis a particle (a CPDI corner) touches */
    int ghost;       /* ghost layers per side of the grid */
    int bspline;     /* B-spline degree, 0 for none */
    int min_nodes;   /* grid nodes per axis, at least */
    double apic_cfl; /* APIC's default and largest Courant factor, 0: the usual */
    unsigned flags;  /* MPM_METH_* */
} mpm_method_props;

/* The method's row, or NULL for a value outside mpm_method. */
const mpm_method_props *mpm_method_props_of(mpm_method m);

/* Appends name, the k-th (from 0) of count, to the list "A, B or C" in
 * list (n bytes, a string), for the messages that name every value. */
void mpm_names_append(char *list, size_t n, const char *name, int k, int count);

#endif
