/*
 * mpm_case.c - checks a case and generates its particles.
 *
 * Every field of an mpm_case is checked here, before anything is allocated,
 * and each error names the field and the limit ("bodies[1].sphere.radius: must be
 * > 0 (got -0.1)").  Particles are produced by one iterator that either
 * only counts them (for the check: particle count, the largest initial
 * speed for the CFL test, and which traction regions hold particles) or
 * writes them into the solver's struct-of-arrays.  Generated bodies put
 * ppc^dim particles per cell at the sub-cell centres that fall inside the
 * shape, each with volume prod(h/ppc) and uGIMP half-width h/(2 ppc).
 */
#include "mpm_internal.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#define MAX_PPC 8

typedef struct {
    const mpm_case *c;
    mpm_particles *P;     /* NULL: count only */
    const mpm_mat_params *mats;
    size_t n;
    double vmax;
    size_t *load_count;   /* per traction: particles inside its region */
} gen_ctx;

static int in_region(const mpm_traction_desc *t, int dim, const double *x)
{
    for (int d = 0; d < dim; d++)
        if (!(x[d] >= t->lo[d] && x[d] <= t->hi[d])) return 0;
    return 1;
}

static void emit(gen_ctx *g, const mpm_body_desc *b, const double *x, double vol,
                 double mass, const double *v, const double *stress, const double *lp)
{
    int dim = g->c->grid.dim;
    double v2 = 0;
    for (int d = 0; d < dim; d++) v2 += v[d] * v[d];
    if (sqrt(v2) > g->vmax) g->vmax = sqrt(v2);
    if (g->load_count)
        for (size_t t = 0; t < g->c->n_tractions; t++)
            if (in_region(&g->c->tractions[t], dim, x)) g->load_count[t]++;
    if (g->P) {
        mpm_particles *P = g->P;
        size_t p = g->n;
        for (int d = 0; d < dim; d++) {
            P->x[d][p] = x[d];
            P->v[d][p] = v[d];
            if (P->lp[d]) P->lp[d][p] = lp[d];
        }
        P->vol[p] = vol;
        P->m[p] = mass > 0 ? mass : g->mats[b->material].rho * vol;
        P->mat[p] = (uint16_t)b->material;
        if (stress) {
            /* stored components are the Voigt indices < MPM_NCOMP(dim) */
            for (int c = 0; c < MPM_NCOMP(dim); c++) P->sig[c][p] = stress[c];
        }
    }
    g->n++;
}

static int gen_shape(gen_ctx *g, const mpm_body_desc *b, size_t bi, char *err, size_t errlen)
{
    const mpm_grid_desc *gr = &g->c->grid;
    int dim = gr->dim, ppc = b->ppc;
    int c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0};
    double lo[3], hi[3], vol = 1, lp[3] = {0, 0, 0};
    for (int d = 0; d < dim; d++) {
        if (b->shape == MPM_SHAPE_BOX) {
            lo[d] = b->lo[d];
            hi[d] = b->hi[d];
        } else {
            lo[d] = b->center[d] - b->radius;
            hi[d] = b->center[d] + b->radius;
        }
        double a = (lo[d] - gr->origin[d]) / gr->h[d], z = (hi[d] - gr->origin[d]) / gr->h[d];
        c0[d] = a < 0 ? 0 : (int)floor(a);
        c1[d] = (int)ceil(z);
        if (c1[d] > gr->nodes[d] - 1) c1[d] = gr->nodes[d] - 1;
        vol *= gr->h[d] / ppc;
        lp[d] = 0.5 * gr->h[d] / ppc;
    }
    size_t before = g->n;
    int sub = 1;
    for (int d = 0; d < dim; d++) sub *= ppc;
    for (int k = c0[2]; k < (dim > 2 ? c1[2] : 1); k++)
        for (int j = c0[1]; j < (dim > 1 ? c1[1] : 1); j++)
            for (int i = c0[0]; i < c1[0]; i++)
                for (int s = 0; s < sub; s++) {
                    int cell[3] = {i, j, k}, si[3] = {s % ppc, (s / ppc) % ppc, s / (ppc * ppc)};
                    double x[3] = {0, 0, 0};
                    int inside = 1;
                    double r2 = 0;
                    for (int d = 0; d < dim; d++) {
                        x[d] = gr->origin[d] + (cell[d] + (si[d] + 0.5) / ppc) * gr->h[d];
                        if (b->shape == MPM_SHAPE_BOX)
                            inside &= x[d] >= lo[d] && x[d] <= hi[d];
                        else
                            r2 += (x[d] - b->center[d]) * (x[d] - b->center[d]);
                    }
                    if (b->shape == MPM_SHAPE_SPHERE) inside = r2 <= b->radius * b->radius;
                    if (inside) emit(g, b, x, vol, 0, b->velocity, NULL, lp);
                }
    if (g->n == before) {
        snprintf(err, errlen, "bodies[%zu]: the %s holds no particle (no sub-cell centre at "
                 "%d per cell lies inside it); enlarge it or raise ppc", bi,
                 b->shape == MPM_SHAPE_BOX ? "box" : "sphere", ppc);
        return MPM_EINVAL;
    }
    return 0;
}

static int check_inside(const mpm_grid_desc *gr, const double *x, int dim)
{
    for (int d = 0; d < dim; d++) {
        double hi = gr->origin[d] + (gr->nodes[d] - 1) * gr->h[d];
        if (!(x[d] >= gr->origin[d] && x[d] < hi)) return d;
    }
    return -1;
}

static int gen_points(gen_ctx *g, const mpm_body_desc *b, size_t bi, char *err, size_t errlen)
{
    const mpm_grid_desc *gr = &g->c->grid;
    int dim = gr->dim;
    if (!b->x || !b->volume) {
        snprintf(err, errlen, "bodies[%zu].points.%s: required with %zu explicit points", bi,
                 b->x ? "volume" : "x", b->n_points);
        return MPM_EINVAL;
    }
    for (size_t p = 0; p < b->n_points; p++) {
        const double *x = b->x + p * dim;
        double lp[3] = {0, 0, 0}, vol = b->volume[p], mass = b->mass ? b->mass[p] : 0;
        int d = check_inside(gr, x, dim);
        if (d >= 0) {
            snprintf(err, errlen, "bodies[%zu].points.x[%zu]: point at %c = %g is outside the grid "
                     "[%g, %g)", bi, p * dim + d, "xyz"[d], x[d], gr->origin[d],
                     gr->origin[d] + (gr->nodes[d] - 1) * gr->h[d]);
            return MPM_EINVAL;
        }
        if (!(vol > 0) || !isfinite(vol)) {
            snprintf(err, errlen, "bodies[%zu].points.volume[%zu]: must be finite and > 0 (got %g)",
                     bi, p, vol);
            return MPM_EINVAL;
        }
        if (b->mass && (!(mass > 0) || !isfinite(mass))) {
            snprintf(err, errlen, "bodies[%zu].points.mass[%zu]: must be finite and > 0 (got %g)",
                     bi, p, mass);
            return MPM_EINVAL;
        }
        const double *v = b->v ? b->v + p * dim : b->velocity;
        for (int e = 0; e < dim; e++)
            if (!isfinite(v[e])) {
                snprintf(err, errlen, "bodies[%zu].points.v[%zu]: must be finite", bi, p * dim + e);
                return MPM_EINVAL;
            }
        if (b->stress)
            for (int e = 0; e < 6; e++)
                if (!isfinite(b->stress[p * 6 + e])) {
                    snprintf(err, errlen, "bodies[%zu].points.stress[%zu]: must be finite", bi, p * 6 + e);
                    return MPM_EINVAL;
                }
        for (int e = 0; e < dim; e++) {
            lp[e] = b->half_length ? b->half_length[p * dim + e] : 0.5 * pow(vol, 1.0 / dim);
            if (g->c->method == MPM_METHOD_GIMP && !(lp[e] > 0 && lp[e] <= gr->h[e])) {
                snprintf(err, errlen, "bodies[%zu].points.half_length[%zu]: the GMPM half-width must be "
                         "in (0, h] = (0, %g] (got %g)", bi, p * dim + e, gr->h[e], lp[e]);
                return MPM_EINVAL;
            }
        }
        emit(g, b, x, vol, mass, v, b->stress ? b->stress + p * 6 : NULL, lp);
    }
    return 0;
}

static int check_body(const mpm_case *c, const mpm_body_desc *b, size_t bi, char *err, size_t errlen)
{
    const mpm_grid_desc *gr = &c->grid;
    int dim = gr->dim;
    if (b->material < 0 || (size_t)b->material >= c->n_materials) {
        snprintf(err, errlen, "bodies[%zu].material: index %d out of range (%zu materials)",
                 bi, b->material, c->n_materials);
        return MPM_EINVAL;
    }
    for (int d = 0; d < dim; d++)
        if (!isfinite(b->velocity[d])) {
            snprintf(err, errlen, "bodies[%zu].velocity[%d]: must be finite", bi, d);
            return MPM_EINVAL;
        }
    if (b->n_points > 0) return 0;
    if (b->shape != MPM_SHAPE_BOX && b->shape != MPM_SHAPE_SPHERE) {
        snprintf(err, errlen, "bodies[%zu].shape: unknown shape %d", bi, (int)b->shape);
        return MPM_EINVAL;
    }
    if (b->ppc < 1 || b->ppc > MAX_PPC) {
        snprintf(err, errlen, "bodies[%zu].ppc: particles per cell per axis must be in [1, %d] "
                 "(got %d)", bi, MAX_PPC, b->ppc);
        return MPM_EINVAL;
    }
    if (b->shape == MPM_SHAPE_SPHERE && (!(b->radius > 0) || !isfinite(b->radius))) {
        snprintf(err, errlen, "bodies[%zu].sphere.radius: must be finite and > 0 (got %g)", bi, b->radius);
        return MPM_EINVAL;
    }
    for (int d = 0; d < dim; d++) {
        double glo = gr->origin[d], ghi = gr->origin[d] + (gr->nodes[d] - 1) * gr->h[d];
        double lo, hi;
        const char *what;
        if (b->shape == MPM_SHAPE_BOX) {
            lo = b->lo[d];
            hi = b->hi[d];
            what = "box";
            if (!(lo < hi)) {
                snprintf(err, errlen, "bodies[%zu].box.hi[%d]: must be > lo[%d] (got %g <= %g)",
                         bi, d, d, hi, lo);
                return MPM_EINVAL;
            }
        } else {
            lo = b->center[d] - b->radius;
            hi = b->center[d] + b->radius;
            what = "sphere";
        }
        if (!(lo >= glo && hi <= ghi)) {
            snprintf(err, errlen, "bodies[%zu].%s: the body spans %c in [%g, %g], outside the "
                     "grid [%g, %g]", bi, what, "xyz"[d], lo, hi, glo, ghi);
            return MPM_EINVAL;
        }
    }
    return 0;
}

static long run_gen(gen_ctx *g, char *err, size_t errlen)
{
    const mpm_case *c = g->c;
    for (size_t bi = 0; bi < c->n_bodies; bi++) {
        const mpm_body_desc *b = &c->bodies[bi];
        int rc = b->n_points > 0 ? gen_points(g, b, bi, err, errlen)
                                 : gen_shape(g, b, bi, err, errlen);
        if (rc) return rc;
        if (g->n > MPM_MAX_PARTICLES) {
            snprintf(err, errlen, "bodies[%zu]: the case has more than %zu particles", bi,
                     (size_t)MPM_MAX_PARTICLES);
            return MPM_EINVAL;
        }
    }
    return (long)g->n;
}

static int check_grid(const mpm_case *c, char *err, size_t errlen)
{
    const mpm_grid_desc *gr = &c->grid;
    if (gr->dim < 1 || gr->dim > 3) {
        snprintf(err, errlen, "grid.dim: must be 1, 2 or 3 (got %d)", gr->dim);
        return MPM_EINVAL;
    }
    double nn = 1;
    for (int d = 0; d < gr->dim; d++) {
        if (!(gr->h[d] > 0) || !isfinite(gr->h[d])) {
            snprintf(err, errlen, "grid.spacing[%d]: must be finite and > 0 (got %g)", d, gr->h[d]);
            return MPM_EINVAL;
        }
        if (!isfinite(gr->origin[d])) {
            snprintf(err, errlen, "grid.origin[%d]: must be finite", d);
            return MPM_EINVAL;
        }
        if (gr->nodes[d] < 2) {
            snprintf(err, errlen, "grid.nodes[%d]: must be >= 2 (got %d)", d, gr->nodes[d]);
            return MPM_EINVAL;
        }
        nn *= gr->nodes[d] + 2.0;
    }
    if (nn > (double)MPM_MAX_NODES) {
        snprintf(err, errlen, "grid.nodes: %.0f nodes (with ghost layers) exceed the limit %zu",
                 nn, (size_t)MPM_MAX_NODES);
        return MPM_EINVAL;
    }
    return 0;
}

static int check_bc(const mpm_case *c, char *err, size_t errlen)
{
    int dim = c->grid.dim;
    unsigned all = (1u << dim) - 1;
    /* bits of axes the grid lacks are ignored on its faces (7 is a wall in
     * any dimension); a face of an axis it lacks must be free */
    for (int f = 2 * dim; f < 2 * MPM_MAX_DIM; f++) {
        unsigned m = c->bc.face_mask[f];
        if (m != 0) {
            snprintf(err, errlen, "boundary.faces[%c_%s]: direction mask %u is not within 0 "
                     "for a %dD grid", "xyz"[f / 2], f % 2 ? "hi" : "lo", m, dim);
            return MPM_EINVAL;
        }
    }
    if (c->bc.n_nodes && (!c->bc.node_ijk || !c->bc.node_mask)) {
        snprintf(err, errlen, "boundary.nodes: %zu nodes given without indices or masks",
                 c->bc.n_nodes);
        return MPM_EINVAL;
    }
    for (size_t i = 0; i < c->bc.n_nodes; i++) {
        for (int d = 0; d < dim; d++) {
            int v = c->bc.node_ijk[3 * i + d];
            if (v < 0 || v >= c->grid.nodes[d]) {
                snprintf(err, errlen, "boundary.nodes[%zu].ijk[%d]: %d is outside [0, %d)",
                         i, d, v, c->grid.nodes[d]);
                return MPM_EINVAL;
            }
        }
        if (c->bc.node_mask[i] & ~all) {
            snprintf(err, errlen, "boundary.nodes[%zu].mask: %u is not within %u", i,
                     c->bc.node_mask[i], all);
            return MPM_EINVAL;
        }
    }
    return 0;
}

int mpm_case_check(const mpm_case *c, char *err, size_t errlen)
{
    long n = mpm_case_count(c, err, errlen);
    return n < 0 ? (int)n : 0;
}

long mpm_case_count(const mpm_case *c, char *err, size_t errlen)
{
    int rc = check_grid(c, err, errlen);
    if (rc) return rc;
    int dim = c->grid.dim;
    if (c->method != MPM_METHOD_MPM && c->method != MPM_METHOD_GIMP) {
        snprintf(err, errlen, "method: unknown value %d (MPM or GIMP)", (int)c->method);
        return MPM_EINVAL;
    }
    if (c->update != MPM_USF && c->update != MPM_USL && c->update != MPM_MUSL) {
        snprintf(err, errlen, "update: unknown value %d (USF, USL or MUSL)", (int)c->update);
        return MPM_EINVAL;
    }
    if (!(c->dt >= 0) || !isfinite(c->dt)) {
        snprintf(err, errlen, "dt: must be finite and >= 0 (0: automatic) (got %g)", c->dt);
        return MPM_EINVAL;
    }
    if (!(c->cfl >= 0) || !isfinite(c->cfl)) {
        snprintf(err, errlen, "cfl: must be finite and >= 0 (0: default %g) (got %g)",
                 MPM_DEFAULT_CFL, c->cfl);
        return MPM_EINVAL;
    }
    double cmaxf = c->update == MPM_USL ? MPM_USL_MAX_CFL : MPM_MAX_CFL;
    if (c->cfl > cmaxf && !c->allow_unstable_dt) {
        snprintf(err, errlen, "cfl: %g is above the stability limit %g%s; set allow_unstable_dt "
                 "to run anyway", c->cfl, cmaxf, c->update == MPM_USL ? " of USL" : "");
        return MPM_ECFL;
    }
    if (!(c->mass_tol >= 0) || !isfinite(c->mass_tol)) {
        snprintf(err, errlen, "mass_tol: must be finite and >= 0 (0: default %g) (got %g)",
                 MPM_DEFAULT_MASS_TOL, c->mass_tol);
        return MPM_EINVAL;
    }
    if (c->threads < 0 || c->threads > MPM_MAX_THREADS) {
        snprintf(err, errlen, "threads: must be in [0, %d] (got %d)", MPM_MAX_THREADS, c->threads);
        return MPM_EINVAL;
    }
    for (int d = 0; d < dim; d++)
        if (!isfinite(c->gravity[d])) {
            snprintf(err, errlen, "gravity[%d]: must be finite", d);
            return MPM_EINVAL;
        }
    if (c->n_materials < 1 || c->n_materials > 65535 || !c->materials) {
        snprintf(err, errlen, "materials: need 1 to 65535 materials (got %zu)", c->n_materials);
        return MPM_EINVAL;
    }
    double cmax = 0;
    for (size_t i = 0; i < c->n_materials; i++) {
        mpm_mat_params mp;
        if ((rc = mpm_model_params(&c->materials[i], dim, i, &mp, err, errlen))) return rc;
        if (mp.c > cmax) cmax = mp.c;
    }
    if (c->n_bodies < 1 || !c->bodies) {
        snprintf(err, errlen, "bodies: the case has no body, so no particles");
        return MPM_EINVAL;
    }
    for (size_t i = 0; i < c->n_bodies; i++)
        if ((rc = check_body(c, &c->bodies[i], i, err, errlen))) return rc;
    if ((rc = check_bc(c, err, errlen))) return rc;
    for (size_t t = 0; t < c->n_tractions; t++) {
        const mpm_traction_desc *tr = &c->tractions[t];
        if (tr->normal < 0 || tr->normal >= dim) {
            snprintf(err, errlen, "tractions[%zu].normal: axis must be in [0, %d) (got %d)",
                     t, dim, tr->normal);
            return MPM_EINVAL;
        }
        for (int d = 0; d < dim; d++)
            if (!isfinite(tr->value[d]) || !(tr->lo[d] <= tr->hi[d])) {
                snprintf(err, errlen, "tractions[%zu]: value[%d] must be finite and lo[%d] <= hi[%d]",
                         t, d, d, d);
                return MPM_EINVAL;
            }
    }

    size_t counts[64], *lc = NULL;
    if (c->n_tractions > 64) {
        snprintf(err, errlen, "tractions: at most 64 (got %zu)", c->n_tractions);
        return MPM_EINVAL;
    }
    if (c->n_tractions) {
        memset(counts, 0, sizeof counts);
        lc = counts;
    }
    gen_ctx g = {c, NULL, NULL, 0, 0, lc};
    long n = run_gen(&g, err, errlen);
    if (n < 0) return (int)n;
    for (size_t t = 0; t < c->n_tractions; t++)
        if (counts[t] == 0) {
            snprintf(err, errlen, "tractions[%zu]: its region holds no particle centre", t);
            return MPM_EINVAL;
        }

    if (c->dt > 0) {
        double hmin = c->grid.h[0];
        for (int d = 1; d < dim; d++) hmin = fmin(hmin, c->grid.h[d]);
        double f = c->update == MPM_USL ? MPM_USL_MAX_CFL : MPM_MAX_CFL;
        double lim = f * hmin / (cmax + g.vmax);
        if (c->dt > lim && !c->allow_unstable_dt) {
            snprintf(err, errlen, "dt: %g is above the CFL limit %g = %g h_min / (c + |v|max) = "
                     "%g x %g / (%g + %g)%s; set allow_unstable_dt to run anyway",
                     c->dt, lim, f, f, hmin, cmax, g.vmax, f < 1 ? " (USL)" : "");
            return MPM_ECFL;
        }
    }
    return n;
}

long mpm_case_particles(const mpm_case *c, mpm_particles *P, const mpm_mat_params *mats,
                        double *vmax, char *err, size_t errlen)
{
    gen_ctx g = {c, P, mats, 0, 0, NULL};
    long n = run_gen(&g, err, errlen);
    if (vmax) *vmax = g.vmax;
    return n;
}
