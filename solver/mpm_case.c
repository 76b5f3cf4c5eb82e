/*
 * mpm_case.c - checks a case and generates its particles.
 *
 * Every field of an mpm_case is checked here, before anything is allocated,
 * and each error names the field (a path of the .proto's names) and the
 * limit: {"bodies[1].sphere.radius", "must be finite and > 0 (got -0.1)"}.
 * Particles are produced by one iterator that either only counts them (the
 * check, mpm_case_check(): one pass giving the particle count, the largest
 * initial speed for the CFL test, and which traction regions hold
 * particles, stopping as soon as the count passes the case's limit) or
 * writes them into the solver's struct-of-arrays (mpm_case_fill(), the one
 * pass of mpm_sim_new()).  Generated bodies put
 * ppc^dim particles per cell at the sub-cell centres that fall inside the
 * shape, each with volume prod(h/ppc) and uGIMP half-width h/(2 ppc) (also
 * the initial CPDI domain).
 */
#include "mpm_case.h"
#include "mpm_cond.h"
#include "mpm_internal.h"
#include "mpm_isa.h"
#include "mpm_method.h"
#include "mpm_ref.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#define MAX_PPC 8

typedef struct {
    const mpm_case *c;
    mpm_particles *P; /* NULL: count only */
    const mpm_mat_params *mats;
    size_t n;
    size_t limit; /* the count may not exceed it (filling: P->n) */
    double vmax;
    size_t *load_count; /* per traction: particles inside its region */
} gen_ctx;

/* "bodies[%zu]..." into a field path buffer */
static const char *pathf(char *buf, size_t n, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static const char *pathf(char *buf, size_t n, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, n, fmt, ap);
    va_end(ap);
    return buf;
}
#define PATH(...) pathf(path, sizeof path, __VA_ARGS__)

/* The count passed the limit: refused at once, naming the body that did.
 * Filling, the limit is the count the check found: the case changed. */
static int too_many(const gen_ctx *g, size_t bi, mpm_error *err)
{
    char path[64];
    if (g->P)
        return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu]", bi),
                        "the case makes another number of particles than when it was checked "
                        "(%zu)",
                        g->limit);
    return mpm_fail(err, MPM_ETOOBIG, PATH("bodies[%zu]", bi),
                    "the case has more than %zu particles, the limit", g->limit);
}

static int in_region(const mpm_traction_desc *t, int dim, const double *x)
{
    for (int d = 0; d < dim; d++)
        if (!(x[d] >= t->lo[d] && x[d] <= t->hi[d])) return 0;
    return 1;
}

/* The geostatic stress of particle p of body b added to its stress
 * (mpm.h, mpm_body_desc.geostatic); the case passed check_body(), so
 * gravity has exactly one non-zero component. */
static void geostatic(gen_ctx *g, const mpm_body_desc *b, size_t p)
{
    const mpm_case *c = g->c;
    mpm_particles *P = g->P;
    int dim = c->grid.dim, a = 0;
    for (int d = 0; d < dim; d++)
        if (c->gravity[d] != 0) a = d;
    double gv = c->gravity[a];
    /* depth below the surface: gravity points from the surface into the body */
    double depth = gv < 0 ? b->free_surface - P->x[a][p] : P->x[a][p] - b->free_surface;
    if (!(depth > 0)) return;
    const mpm_mat_params *mp = &g->mats[b->material];
    double sv = -mp->rho * fabs(gv) * depth;
    double k0 = b->has_k0 ? b->k0 : mp->nu / (1 - mp->nu);
    int nn = dim == 1 ? 1 : 3; /* normal components stored (2D: xx yy zz) */
    for (int d = 0; d < nn; d++) P->sig[d][p] += d == a ? sv : k0 * sv;
}

static void emit(gen_ctx *g, const mpm_body_desc *b, const double *x, double vol, double mass,
                 const double *v, const double *stress, const double *lp)
{
    int dim = g->c->grid.dim;
    double v2 = 0;
    for (int d = 0; d < dim; d++) v2 += v[d] * v[d];
    if (sqrt(v2) > g->vmax) g->vmax = sqrt(v2);
    if (g->load_count)
        for (size_t t = 0; t < g->c->n_tractions; t++)
            if (in_region(&g->c->tractions[t], dim, x)) g->load_count[t]++;
    if (g->P && g->n < g->P->n) {
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
        if (b->geostatic) geostatic(g, b, p);
    }
    g->n++;
}

static int gen_shape(gen_ctx *g, const mpm_body_desc *b, size_t bi, mpm_error *err)
{
    const mpm_grid_desc *gr = &g->c->grid;
    int dim = gr->dim, ppc = b->ppc;
    int c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0};
    double lo[3], hi[3], vol = 1, lp[3] = {0, 0, 0};
    char path[64];
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
                    if (inside) {
                        emit(g, b, x, vol, 0, b->velocity, NULL, lp);
                        if (g->n > g->limit) return too_many(g, bi, err);
                    }
                }
    if (g->n == before)
        return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu]", bi),
                        "the %s holds no particle (no sub-cell centre at %d per cell lies "
                        "inside it); enlarge it or raise ppc",
                        b->shape == MPM_SHAPE_BOX ? "box" : "sphere", ppc);
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

static int gen_points(gen_ctx *g, const mpm_body_desc *b, size_t bi, mpm_error *err)
{
    const mpm_grid_desc *gr = &g->c->grid;
    int dim = gr->dim;
    char path[96];
    if (!b->x || !b->volume)
        return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].points.%s", bi, b->x ? "volume" : "x"),
                        "required with %zu explicit points", b->n_points);
    if (b->n_points > g->limit - g->n) return too_many(g, bi, err); /* g->n <= limit */
    for (size_t p = 0; p < b->n_points; p++) {
        const double *x = b->x + p * dim;
        double lp[3] = {0, 0, 0}, vol = b->volume[p], mass = b->mass ? b->mass[p] : 0;
        int d = check_inside(gr, x, dim);
        if (d >= 0)
            return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].points.x[%zu]", bi, p * dim + d),
                            "point at %c = %g is outside the grid [%g, %g)", "xyz"[d], x[d],
                            gr -> origin[d], gr -> origin[d] + (gr->nodes[d] - 1) * gr -> h[d]);
        if (!(vol > 0) || !isfinite(vol))
            return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].points.volume[%zu]", bi, p),
                            "must be finite and > 0 (got %g)", vol);
        if (b->mass && (!(mass > 0) || !isfinite(mass)))
            return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].points.mass[%zu]", bi, p),
                            "must be finite and > 0 (got %g)", mass);
        const double *v = b->v ? b->v + p * dim : b->velocity;
        for (int e = 0; e < dim; e++)
            if (!isfinite(v[e]))
                return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].points.v[%zu]", bi, p * dim + e),
                                "must be finite");
        if (b->stress)
            for (int e = 0; e < 6; e++)
                if (!isfinite(b->stress[p * 6 + e]))
                    return mpm_fail(err, MPM_EINVAL,
                                    PATH("bodies[%zu].points.stress[%zu]", bi, p * 6 + e),
                                    "must be finite");
        for (int e = 0; e < dim; e++) {
            lp[e] = b->half_length ? b->half_length[p * dim + e] : 0.5 * pow(vol, 1.0 / dim);
            if (g->c->method == MPM_METHOD_GIMP && !(lp[e] > 0 && lp[e] <= gr->h[e]))
                return mpm_fail(
                    err, MPM_EINVAL, PATH("bodies[%zu].points.half_length[%zu]", bi, p * dim + e),
                    "the GMPM half-width must be in (0, h] = (0, %g] (got %g)", gr->h[e], lp[e]);
            /* CPDI: the domain's corners within one (ghost) cell of the grid */
            double glo = gr->origin[e] - gr->h[e], ghi = gr->origin[e] + gr->nodes[e] * gr->h[e];
            if (g->c->method == MPM_METHOD_CPDI &&
                !(lp[e] > 0 && x[e] - lp[e] >= glo && x[e] + lp[e] < ghi))
                return mpm_fail(
                    err, MPM_EINVAL, PATH("bodies[%zu].points.half_length[%zu]", bi, p * dim + e),
                    "the CPDI half-width must be > 0 with the domain x +- half_length within one "
                    "cell of the grid, [%g, %g) (got %g at %c = %g)",
                    glo, ghi, lp[e], "xyz"[e], x[e]);
        }
        emit(g, b, x, vol, mass, v, b->stress ? b->stress + p * 6 : NULL, lp);
    }
    return 0;
}

static int check_body(const mpm_case *c, const mpm_body_desc *b, size_t bi, mpm_error *err)
{
    const mpm_grid_desc *gr = &c->grid;
    int dim = gr->dim;
    char path[64];
    if (b->material < 0 || (size_t)b->material >= c->n_materials)
        return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].material", bi),
                        "index %d out of range (%zu materials)", b->material, c->n_materials);
    for (int d = 0; d < dim; d++)
        if (!isfinite(b->velocity[d]))
            return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].velocity[%d]", bi, d),
                            "must be finite");
    if (b->geostatic) {
        int axes = 0;
        for (int d = 0; d < dim; d++) axes += c->gravity[d] != 0;
        if (axes != 1)
            return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].geostatic", bi),
                            "needs gravity along exactly one axis (got %d non-zero components)",
                            axes);
        if (!isfinite(b->free_surface))
            return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].geostatic.free_surface", bi),
                            "must be finite");
        if (b->has_k0 && !(b->k0 >= 0 && isfinite(b->k0)))
            return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].geostatic.k0", bi),
                            "must be finite and >= 0 (absent: nu / (1 - nu)) (got %g)", b->k0);
    }
    if (b->n_points > 0) return 0;
    if (b->shape != MPM_SHAPE_BOX && b->shape != MPM_SHAPE_SPHERE)
        return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu]", bi), "unknown shape %d",
                        (int)b->shape);
    if (b->ppc < 1 || b->ppc > MAX_PPC)
        return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].ppc", bi),
                        "particles per cell per axis must be in [1, %d] (got %d)", MAX_PPC, b->ppc);
    if (b->shape == MPM_SHAPE_SPHERE && (!(b->radius > 0) || !isfinite(b->radius)))
        return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].sphere.radius", bi),
                        "must be finite and > 0 (got %g)", b->radius);
    for (int d = 0; d < dim; d++) {
        double glo = gr->origin[d], ghi = gr->origin[d] + (gr->nodes[d] - 1) * gr->h[d];
        double lo, hi;
        const char *what;
        if (b->shape == MPM_SHAPE_BOX) {
            lo = b->lo[d];
            hi = b->hi[d];
            what = "box";
            if (!(lo < hi))
                return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].box.hi[%d]", bi, d),
                                "must be > lo[%d] (got %g <= %g)", d, hi, lo);
        } else {
            lo = b->center[d] - b->radius;
            hi = b->center[d] + b->radius;
            what = "sphere";
        }
        if (!(lo >= glo && hi <= ghi))
            return mpm_fail(err, MPM_EINVAL, PATH("bodies[%zu].%s", bi, what),
                            "the body spans %c in [%g, %g], outside the grid [%g, %g]", "xyz"[d],
                            lo, hi, glo, ghi);
    }
    return 0;
}

/* The particles of every body, counted or written; stops at the first
 * error or as soon as the count passes g->limit. */
static int run_gen(gen_ctx *g, mpm_error *err)
{
    const mpm_case *c = g->c;
    for (size_t bi = 0; bi < c->n_bodies; bi++) {
        const mpm_body_desc *b = &c->bodies[bi];
        int rc = b->n_points > 0 ? gen_points(g, b, bi, err) : gen_shape(g, b, bi, err);
        if (rc) return rc;
    }
    return 0;
}

static int check_grid(const mpm_case *c, mpm_error *err)
{
    const mpm_grid_desc *gr = &c->grid;
    char path[64];
    if (gr->dim < 1 || gr->dim > 3)
        return mpm_fail(err, MPM_EINVAL, "grid.dim", "must be 1, 2 or 3 (got %d)", gr->dim);
    double nn = 1;
    for (int d = 0; d < gr->dim; d++) {
        if (!(gr->h[d] > 0) || !isfinite(gr->h[d]))
            return mpm_fail(err, MPM_EINVAL, PATH("grid.spacing[%d]", d),
                            "must be finite and > 0 (got %g)", gr->h[d]);
        if (!isfinite(gr->origin[d]))
            return mpm_fail(err, MPM_EINVAL, PATH("grid.origin[%d]", d), "must be finite");
        if (gr->nodes[d] < 2)
            return mpm_fail(err, MPM_EINVAL, PATH("grid.nodes[%d]", d), "must be >= 2 (got %d)",
                            gr->nodes[d]);
        const mpm_method_props *mp = mpm_method_props_of(c->method);
        if (mp && gr->nodes[d] < mp->min_nodes)
            return mpm_fail(err, MPM_EINVAL, PATH("grid.nodes[%d]", d),
                            "must be >= %d with method %s (got %d)", mp->min_nodes,
                            mpm_method_name(c->method), gr->nodes[d]);
        nn *= gr->nodes[d] + 2.0;
    }
    if (nn > (double)MPM_MAX_NODES)
        return mpm_fail(err, MPM_EINVAL, "grid.nodes",
                        "%.0f nodes (with ghost layers) exceed the limit %zu", nn,
                        (size_t)MPM_MAX_NODES);
    return 0;
}

/* the field of face 2 d + s in the .proto (Boundary.x_lo ...) */
static const char *const face_path[2 * MPM_MAX_DIM] = {"boundary.x_lo", "boundary.x_hi",
                                                       "boundary.y_lo", "boundary.y_hi",
                                                       "boundary.z_lo", "boundary.z_hi"};

static int check_bc(const mpm_case *c, mpm_error *err)
{
    int dim = c->grid.dim;
    unsigned all = (1u << dim) - 1;
    char path[64];
    /* bits of axes the grid lacks are ignored on its faces (7 is a wall in
     * any dimension); a face of an axis it lacks must be free */
    for (int f = 2 * dim; f < 2 * MPM_MAX_DIM; f++) {
        unsigned m = c->bc.face_mask[f];
        if (m != 0)
            return mpm_fail(err, MPM_EINVAL, face_path[f],
                            "direction mask %u is not within 0 for a %dD grid", m, dim);
    }
    /* B-spline control points are not grid nodes (only the end ones lie on
     * the grid, on its faces): a node set has no meaning there */
    if (c->bc.n_nodes && !(mpm_method_props_of(c->method)->flags & MPM_METH_NODE_BC))
        return mpm_fail(
            err, MPM_EINVAL, "boundary.nodes",
            "explicit boundary nodes are not supported with BSPLINE2/BSPLINE3 (B-spline "
            "control points are not grid nodes; BSPLINE2 is the default method when a case "
            "names none): fix whole faces instead, or set method to MPM, GIMP or CPDI");
    if (c->bc.n_nodes && (!c->bc.node_ijk || !c->bc.node_mask))
        return mpm_fail(err, MPM_EINVAL, "boundary.nodes",
                        "%zu nodes given without indices or masks", c->bc.n_nodes);
    for (size_t i = 0; i < c->bc.n_nodes; i++) {
        for (int d = 0; d < dim; d++) {
            int v = c->bc.node_ijk[3 * i + d];
            if (v < 0 || v >= c->grid.nodes[d])
                return mpm_fail(err, MPM_EINVAL, PATH("boundary.nodes[%zu].ijk[%d]", i, d),
                                "%d is outside [0, %d)", v, c->grid.nodes[d]);
        }
        if (c->bc.node_mask[i] & ~all)
            return mpm_fail(err, MPM_EINVAL, PATH("boundary.nodes[%zu].mask", i),
                            "%u is not within %u", c->bc.node_mask[i], all);
    }
    return 0;
}

#ifdef MPM_LEAN
/* A build without gravity, loads and fixed boundaries refuses cases that
 * use them. */
static int lean_check(const mpm_case *c, mpm_error *err)
{
    const char *what = NULL;
    for (int d = 0; d < c->grid.dim; d++)
        if (c->gravity[d] != 0) what = "gravity";
    if (c->n_tractions) what = "tractions";
    for (int f = 0; f < 2 * c->grid.dim; f++)
        if (c->bc.face_mask[f]) what = face_path[f];
    if (c->bc.n_nodes) what = "boundary.nodes";
    if (c->bc.n_friction) what = "boundary.friction";
    if (c->n_prescribed) what = "prescribed";
    if (!what) return 0;
    return mpm_fail(err, MPM_EINVAL, what,
                    "this solver was built with MPM_LEAN (no gravity, loads or fixed boundaries)");
}
#endif

/* The particle limit of a case: max_particles, 0 and anything above
 * MPM_MAX_PARTICLES meaning MPM_MAX_PARTICLES. */
static size_t particle_limit(const mpm_case *c)
{
    return c->max_particles && c->max_particles < MPM_MAX_PARTICLES ? c->max_particles
                                                                    : MPM_MAX_PARTICLES;
}

/* The largest Courant factor of the case's scheme (mpm.h), and what sets
 * it in why ("" for the general limit). */
static double max_cfl(const mpm_case *c, char why[32])
{
    double f = MPM_MAX_CFL;
    why[0] = 0;
    if (c->update == MPM_USL) {
        f = MPM_USL_MAX_CFL;
        snprintf(why, 32, "USL");
    }
    const mpm_method_props *mp = mpm_method_props_of(c->method);
    if (c->transfer == MPM_TRANSFER_APIC && mp && mp->apic_cfl > 0 && mp->apic_cfl < f) {
        f = mp->apic_cfl;
        snprintf(why, 32, "APIC with %s", mpm_method_name(c->method));
    }
    return f;
}

int mpm_case_check(const mpm_case *c, mpm_case_info *info, mpm_error *err)
{
    char path[64];
    int rc = check_grid(c, err);
    if (rc) return rc;
    int dim = c->grid.dim;
    const mpm_method_props *meth = mpm_method_props_of(c->method);
    if (!meth) {
        char names[128] = "";
        for (int m = 0; m < MPM_N_METHODS; m++)
            mpm_names_append(names, sizeof names, mpm_method_name((mpm_method)m), m, MPM_N_METHODS);
        return mpm_fail(err, MPM_EINVAL, "method", "unknown value %d (%s)", (int)c->method, names);
    }
    if (c->update != MPM_USF && c->update != MPM_USL && c->update != MPM_MUSL)
        return mpm_fail(err, MPM_EINVAL, "update", "unknown value %d (USF, USL or MUSL)",
                        (int)c->update);
    if (!(c->dt >= 0) || !isfinite(c->dt))
        return mpm_fail(err, MPM_EINVAL, "dt", "must be finite and >= 0 (0: automatic) (got %g)",
                        c->dt);
    if (!(c->cfl >= 0) || !isfinite(c->cfl))
        return mpm_fail(err, MPM_EINVAL, "cfl", "must be finite and >= 0 (0: default %g) (got %g)",
                        MPM_DEFAULT_CFL, c->cfl);
    char why[32];
    double cmaxf = max_cfl(c, why);
    if (c->cfl > cmaxf && !c->allow_unstable_dt)
        return mpm_fail(
            err, MPM_ECFL, "cfl",
            "%g is above the stability limit %g%s%s; set allow_unstable_dt to run anyway", c->cfl,
            cmaxf, *why ? " of " : "", why);
    if (!(c->mass_tol >= 0) || !isfinite(c->mass_tol))
        return mpm_fail(err, MPM_EINVAL, "mass_tol",
                        "must be finite and >= 0 (0: default %g) (got %g)", MPM_DEFAULT_MASS_TOL,
                        c->mass_tol);
    if (!(c->pic_fraction >= 0 && c->pic_fraction <= 1))
        return mpm_fail(err, MPM_EINVAL, "pic_fraction",
                        "must be in [0, 1] (0: pure FLIP, 1: pure PIC) (got %g)", c->pic_fraction);
    if (c->transfer != MPM_TRANSFER_FLIP && c->transfer != MPM_TRANSFER_APIC)
        return mpm_fail(err, MPM_EINVAL, "transfer", "unknown value %d (FLIP or APIC)",
                        (int)c->transfer);
    if (c->transfer == MPM_TRANSFER_APIC && !(meth->flags & MPM_METH_APIC))
        return mpm_fail(err, MPM_EINVAL, "transfer",
                        "APIC is not implemented for method %s (use FLIP, or APIC with GIMP, "
                        "BSPLINE2 or BSPLINE3)",
                        mpm_method_name(c->method));
    if (c->transfer == MPM_TRANSFER_APIC && c->pic_fraction != 0)
        return mpm_fail(err, MPM_EINVAL, "pic_fraction",
                        "must be 0 (or absent) with transfer APIC, itself a PIC transfer whose "
                        "affine part keeps what PIC damps (got %g)",
                        c->pic_fraction);
    if (c->volume_update != MPM_VOLUME_STRAIN_INCREMENT && c->volume_update != MPM_VOLUME_DET_F &&
        c->volume_update != MPM_VOLUME_CONSTANT)
        return mpm_fail(err, MPM_EINVAL, "volume_update",
                        "unknown value %d (STRAIN_INCREMENT, DET_F or CONSTANT)",
                        (int)c->volume_update);
    if (c->threads < 0 || c->threads > MPM_MAX_THREADS)
        return mpm_fail(err, MPM_EINVAL, "threads", "must be in [0, %d] (got %d)", MPM_MAX_THREADS,
                        c->threads);
    int krc = mpm_kernels_check(c->kernels, err);
    if (krc) return krc;
    if ((krc = mpm_ref_check(c, err))) return krc; /* kernel_family */
    if (c->kernels == MPM_KERNELS_AVX2 && !(meth->flags & MPM_METH_AVX2))
        return mpm_fail(err, MPM_EINVAL, "kernels",
                        "AVX2 asked for, but %s has portable "
                        "kernels only (use AUTO or PORTABLE)",
                        mpm_method_name(c->method));
    for (int d = 0; d < dim; d++)
        if (!isfinite(c->gravity[d]))
            return mpm_fail(err, MPM_EINVAL, PATH("gravity[%d]", d), "must be finite");
    if (c->damping != MPM_DAMPING_NONE && c->damping != MPM_DAMPING_LOCAL &&
        c->damping != MPM_DAMPING_VISCOUS)
        return mpm_fail(err, MPM_EINVAL, "damping.kind",
                        "unknown value %d (NONE, LOCAL or VISCOUS)", (int)c->damping);
    if (c->damping == MPM_DAMPING_LOCAL && !(c->damping_coef >= 0 && c->damping_coef < 1))
        return mpm_fail(err, MPM_EINVAL, "damping.coefficient",
                        "local damping's alpha must be in [0, 1) (got %g)", c->damping_coef);
    if (c->damping == MPM_DAMPING_VISCOUS && !(c->damping_coef >= 0 && isfinite(c->damping_coef)))
        return mpm_fail(err, MPM_EINVAL, "damping.coefficient",
                        "viscous damping's rate c (1/s) must be finite and >= 0 (got %g)",
                        c->damping_coef);
    if (!(c->damping_until >= 0 && isfinite(c->damping_until)))
        return mpm_fail(err, MPM_EINVAL, "damping.until",
                        "must be finite and >= 0 (0: damping throughout) (got %g)",
                        c->damping_until);
    if (!(c->energy_budget >= 0 && isfinite(c->energy_budget)))
        return mpm_fail(err, MPM_EINVAL, "energy_budget",
                        "must be finite and >= 0 (a fraction; 0: no check) (got %g)",
                        c->energy_budget);
    if (c->n_materials < 1 || c->n_materials > 65535 || !c->materials)
        return mpm_fail(err, MPM_EINVAL, "materials", "need 1 to 65535 materials (got %zu)",
                        c->n_materials);
    double cmax = 0;
    for (size_t i = 0; i < c->n_materials; i++) {
        /* the one check of a material's parameters: its model's row */
        if ((rc = mpm_material_check(&c->materials[i], dim, i, err))) return rc;
        double ci = mpm_material_wave_speed(&c->materials[i], dim);
        if (ci > cmax) cmax = ci;
    }
    if (c->n_bodies < 1 || !c->bodies)
        return mpm_fail(err, MPM_EINVAL, "bodies", "the case has no body, so no particles");
    for (size_t i = 0; i < c->n_bodies; i++)
        if ((rc = check_body(c, &c->bodies[i], i, err))) return rc;
    if ((rc = check_bc(c, err))) return rc;
    if ((rc = mpm_cond_check(c, err))) return rc;
    for (size_t t = 0; t < c->n_tractions; t++) {
        const mpm_traction_desc *tr = &c->tractions[t];
        if (tr->normal < 0 || tr->normal >= dim)
            return mpm_fail(err, MPM_EINVAL, PATH("tractions[%zu].normal", t),
                            "axis must be in [0, %d) (got %d)", dim, tr->normal);
        for (int d = 0; d < dim; d++)
            if (!isfinite(tr->value[d]) || !(tr->lo[d] <= tr->hi[d]))
                return mpm_fail(err, MPM_EINVAL, PATH("tractions[%zu]", t),
                                "value[%d] must be finite and lo[%d] <= hi[%d]", d, d, d);
        if ((rc =
                 mpm_timefn_check(tr->time_function, PATH("tractions[%zu].time_function", t), err)))
            return rc;
    }
#ifdef MPM_LEAN
    if ((rc = lean_check(c, err))) return rc;
#endif

    size_t counts[64], *lc = NULL;
    if (c->n_tractions > 64)
        return mpm_fail(err, MPM_EINVAL, "tractions", "at most 64 (got %zu)", c->n_tractions);
    if (c->n_tractions) {
        memset(counts, 0, sizeof counts);
        lc = counts;
    }
    gen_ctx g = {c, NULL, NULL, 0, particle_limit(c), 0, lc};
    if ((rc = run_gen(&g, err))) return rc;
    for (size_t t = 0; t < c->n_tractions; t++)
        if (counts[t] == 0)
            return mpm_fail(err, MPM_EINVAL, PATH("tractions[%zu]", t),
                            "its region holds no particle centre");

    if (c->dt > 0) {
        double hmin = c->grid.h[0];
        for (int d = 1; d < dim; d++) hmin = fmin(hmin, c->grid.h[d]);
        double f = max_cfl(c, why);
        double lim = f * hmin / (cmax + g.vmax);
        if (c->dt > lim && !c->allow_unstable_dt)
            return mpm_fail(err, MPM_ECFL, "dt",
                            "%g is above the CFL limit %g = %g h_min / (c + |v|max) = "
                            "%g x %g / (%g + %g)%s%s%s; set allow_unstable_dt to run anyway",
                            c->dt, lim, f, f, hmin, cmax, g.vmax, *why ? " (" : "", why,
                            *why ? ")" : "");
    }
    if (info) {
        memset(info, 0, sizeof *info);
        info->particles = g.n;
        info->nodes = 1;
        for (int d = 0; d < dim; d++) info->nodes *= (size_t)c->grid.nodes[d];
        info->dim = dim;
        info->vmax = g.vmax;
        info->cmax = cmax;
    }
    mpm_error_clear(err);
    return 0;
}

int mpm_case_fill(const mpm_case *c, mpm_particles *P, const mpm_mat_params *mats, double *vmax,
                  mpm_error *err)
{
    gen_ctx g = {c, P, mats, 0, P->n, 0, NULL};
    int rc = run_gen(&g, err);
    if (!rc && g.n != P->n) rc = too_many(&g, c->n_bodies - 1, err);
    if (vmax) *vmax = g.vmax;
    return rc;
}
