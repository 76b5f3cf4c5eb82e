/*
 * mpp_case.c - a case from JSON text or protobuf bytes to a checked
 * mpp_case (see mpp_case.h).
 *
 * The conversion fills an mpm_case from an Mpmd__Case and checks only what
 * the schema cannot express and the solver cannot see: dimensions and
 * array lengths (the solver's vectors have a fixed size), indices and the
 * enum values that need a mapping, the run control (stop, threads, output)
 * and the size limits that guard the copies.  Method, update, dt, CFL and
 * mass tolerance go to the solver as given (the enums have the same
 * values, asserted in mpp.c); the solver's check (mpm_case_check), run once
 * at the end, judges them with the physics and counts the particles up to
 * the caller's limit; its mpm_case_info stays in the mpp_case.  Error
 * fields are written in the schema's snake_case spelling.
 */
#include "mpp_internal.h"

#include "mpm_material.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI_ 3.14159265358979323846

/* Below this many (estimated) particles a case is counted exactly before
 * the limit is applied: the count is cheap and gives the exact figure.
 * Above it, an estimate beyond the limit refuses the case before the
 * count (which would take long on an absurd case). */
#define MPP_ESTIMATE_FROM 1000000.0

/* A field path from a format: AT("bodies[%zu].ppc", i) (each function using
 * it declares a char at_[96]). */
#define AT(...) (snprintf(at_, sizeof at_, __VA_ARGS__), at_)

/* ------------------------------------------------------------------------ */
/* Case message <-> JSON / bytes                                            */

int mpp_case_from_json(const char *json, size_t len, Mpmd__Case **out, mpm_error *err)
{
    ProtobufCMessage *m;
    int rc = mpp_json_to_pb(&mpmd__case__descriptor, json, len, &m, err);
    *out = rc ? NULL : (Mpmd__Case *)m;
    return rc;
}

int mpp_case_unpack(const void *buf, size_t len, size_t max, Mpmd__Case **out, mpm_error *err)
{
    ProtobufCMessage *m;
    int rc = mpp_unpack(&mpmd__case__descriptor, buf, len, max, &m, err);
    *out = (Mpmd__Case *)m;
    return rc;
}

int mpp_case_pack(const Mpmd__Case *pb, uint8_t **buf, size_t *len)
{
    return mpp_pack(&pb->base, buf, len);
}

int mpp_case_to_json(const Mpmd__Case *pb, unsigned flags, char **json, mpm_error *err)
{
    return mpp_json_from_pb(&pb->base, flags, json, err);
}

void mpp_case_pb_free(Mpmd__Case **pb)
{
    if (!pb || !*pb) return;
    protobuf_c_message_free_unpacked(&(*pb)->base, NULL);
    *pb = NULL;
}

void mpp_case_pin_defaults(Mpmd__Case *pb)
{
    if (!pb) return;
    pb->has_method = 1; /* an absent field holds the schema's default */
    pb->has_update = 1;
}

/* ------------------------------------------------------------------------ */
/* Case message -> mpp_case                                                 */

/* An axis vector: exactly dim finite values (or none, giving zeros, when
 * optional).  path is the field's path. */
static int get_vec(const char *path, const double *v, size_t n, int dim, int optional,
                   double out[MPM_MAX_DIM], mpm_error *err)
{
    char at_[96];
    for (int d = 0; d < MPM_MAX_DIM; d++) out[d] = 0;
    if (n == 0 && optional) return 0;
    if (n == 0) return mpm_fail(err, MPM_EINVAL, path, "missing (%d values, one per axis)", dim);
    if (n != (size_t)dim)
        return mpm_fail(err, MPM_EINVAL, path, "expected %d values (one per axis), got %zu", dim,
                        n);
    for (size_t i = 0; i < n; i++) {
        if (!isfinite(v[i]))
            return mpm_fail(err, MPM_EINVAL, AT("%s[%zu]", path, i), "must be a finite number");
        out[i] = v[i];
    }
    return 0;
}

/* A per-point array of `want` values (n points times a width), or none
 * when optional; values finite, and > 0 when positive is set. */
static int chk_points(const char *path, const double *v, size_t n, size_t want, int optional,
                      int positive, mpm_error *err)
{
    char at_[96];
    if (n == 0 && optional) return 0;
    if (n != want)
        return mpm_fail(err, MPM_EINVAL, path, "expected %zu values (%s), got %zu", want,
                        optional ? "per point, or none" : "per point", n);
    for (size_t i = 0; i < n; i++) {
        if (!isfinite(v[i]))
            return mpm_fail(err, MPM_EINVAL, AT("%s[%zu]", path, i), "must be a finite number");
        if (positive && !(v[i] > 0))
            return mpm_fail(err, MPM_EINVAL, AT("%s[%zu]", path, i), "must be > 0 (got %g)", v[i]);
    }
    return 0;
}

static int conv_grid(const Mpmd__Grid *g, mpp_case *mc, mpm_error *err)
{
    mpm_grid_desc *gd = &mc->c.grid;
    double total = 1;
    char at_[96];
    int rc;
    if (!g) return mpm_fail(err, MPM_EINVAL, "grid", "missing");
    if (!g->has_dim) return mpm_fail(err, MPM_EINVAL, "grid.dim", "missing (1, 2 or 3)");
    if (g->dim < 1 || g->dim > MPM_MAX_DIM)
        return mpm_fail(err, MPM_EINVAL, "grid.dim", "must be 1, 2 or 3 (got %u)", g->dim);
    gd->dim = (int)g->dim;
    if ((rc = get_vec("grid.origin", g->origin, g->n_origin, gd->dim, 1, gd->origin, err)))
        return rc;
    if ((rc = get_vec("grid.spacing", g->spacing, g->n_spacing, gd->dim, 0, gd->h, err))) return rc;
    for (int d = 0; d < gd->dim; d++)
        if (!(gd->h[d] > 0))
            return mpm_fail(err, MPM_EINVAL, AT("grid.spacing[%d]", d), "must be > 0 (got %g)",
                            gd->h[d]);
    if (g->n_nodes == 0)
        return mpm_fail(err, MPM_EINVAL, "grid.nodes", "missing (%d values, one per axis)",
                        gd->dim);
    if (g->n_nodes != (size_t)gd->dim)
        return mpm_fail(err, MPM_EINVAL, "grid.nodes", "expected %d values (one per axis), got %zu",
                        gd->dim, g->n_nodes);
    for (int d = 0; d < gd->dim; d++) {
        if (g->nodes[d] < 2)
            return mpm_fail(err, MPM_EINVAL, AT("grid.nodes[%d]", d), "must be >= 2 (got %u)",
                            g->nodes[d]);
        total *= g->nodes[d];
        gd->nodes[d] =
            g->nodes[d] > (uint32_t)MPP_CASE_MAX_NODES ? (int)MPP_CASE_MAX_NODES : (int)g->nodes[d];
    }
    if (total > MPP_CASE_MAX_NODES)
        return mpm_fail(err, MPM_ETOOBIG, "grid.nodes", "%.0f nodes, more than the limit of %u",
                        total, MPP_CASE_MAX_NODES);
    return 0;
}

/* Material i: each parameter of the solver's material table
 * (mpm_material.h) read from the schema's field of the same name (the
 * Material descriptor's offsets), the table's default when absent, and
 * "missing" when the model's row requires it: presence is what the
 * solver cannot see.  The model (the same values as mpm_model_kind,
 * codec_material_table_matches_proto) and the values go to the solver as
 * given; mpm_case_check() judges them against the same rows. */
static int conv_material(const Mpmd__Material *m, size_t i, mpm_material_desc *md, mpm_error *err)
{
    char at_[96];
    md->model = (mpm_model_kind)m->model;
    const mpm_material_model *row = mpm_material_model_of(md->model);
    for (int k = 0; k < mpm_material_n_params(); k++) {
        const mpm_material_param *p = mpm_material_param_at(k);
        const ProtobufCFieldDescriptor *f =
            protobuf_c_message_descriptor_get_field_by_name(&mpmd__material__descriptor, p->name);
        if (!f || f->label != PROTOBUF_C_LABEL_OPTIONAL ||
            f->type != (p->type == MPM_PARAM_ENUM ? PROTOBUF_C_TYPE_ENUM : PROTOBUF_C_TYPE_DOUBLE))
            return mpm_fail(err, MPM_EINTERNAL, AT("materials[%zu].%s", i, p->name),
                            "not an optional %s field of the schema's Material",
                            p->type == MPM_PARAM_ENUM ? "enum" : "double");
        const char *at = (const char *)m;
        protobuf_c_boolean has;
        memcpy(&has, at + f->quantifier_offset, sizeof has);
        double v = p->def;
        if (has && p->type == MPM_PARAM_ENUM) {
            int e;
            memcpy(&e, at + f->offset, sizeof e);
            v = e;
        } else if (has) {
            memcpy(&v, at + f->offset, sizeof v);
        } else if (row && (row->required >> k & 1u)) {
            return mpm_fail(err, MPM_EINVAL, AT("materials[%zu].%s", i, p->name),
                            "missing (required by %s)", row->name);
        }
        mpm_material_set(md, p, v);
    }
    return 0;
}

static int conv_materials(const Mpmd__Case *pb, mpp_case *mc, mpm_error *err)
{
    size_t n = pb->n_materials;
    int rc;
    if (n == 0) return mpm_fail(err, MPM_EINVAL, "materials", "at least one material is required");
    if (n > MPP_CASE_MAX_ITEMS)
        return mpm_fail(err, MPM_ETOOBIG, "materials", "%zu, more than the limit of %u", n,
                        MPP_CASE_MAX_ITEMS);
    mc->materials = calloc(n, sizeof *mc->materials);
    if (!mc->materials) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    mc->c.materials = mc->materials;
    mc->c.n_materials = n;
    for (size_t i = 0; i < n; i++)
        if ((rc = conv_material(pb->materials[i], i, &mc->materials[i], err))) return rc;
    return 0;
}

/* Estimate of the particles a box/sphere body generates. */
static double est_generated(const mpm_body_desc *b, const mpm_grid_desc *g)
{
    double count = 1;
    for (int d = 0; d < g->dim; d++) {
        double ext = b->shape == MPM_SHAPE_BOX ? b->hi[d] - b->lo[d] : 2 * b->radius;
        count *= floor(ext / g->h[d] * b->ppc) + 1;
    }
    if (b->shape == MPM_SHAPE_SPHERE) count *= g->dim == 2 ? PI_ / 4 : g->dim == 3 ? PI_ / 6 : 1;
    return count;
}

static int conv_points(const Mpmd__Points *p, size_t bi, mpp_case *mc, double *total, size_t max,
                       mpm_error *err)
{
    mpm_body_desc *b = &mc->bodies[bi];
    size_t dim = (size_t)mc->c.grid.dim, n = p->n_volume, off = 0;
    char at_[96], path[64];
    double *blk;
    int rc;
    if (n == 0)
        return mpm_fail(err, MPM_EINVAL, AT("bodies[%zu].points.volume", bi),
                        "at least one point is required");
    if (n > max || *total + (double)n > (double)max)
        return mpm_fail(err, MPM_ETOOBIG, AT("bodies[%zu].points", bi),
                        "%zu points, more than the limit of %zu particles in a case", n, max);
    /* name, values, count, expected count, optional, must be > 0 */
    const struct {
        const char *name;
        const double *v;
        size_t n, want;
        int optional, positive;
    } arrays[] = {
        {"x", p->x, p->n_x, n * dim, 0, 0},
        {"volume", p->volume, p->n_volume, n, 0, 1},
        {"mass", p->mass, p->n_mass, n, 1, 1},
        {"v", p->v, p->n_v, n * dim, 1, 0},
        {"stress", p->stress, p->n_stress, n * 6, 1, 0},
        {"half_length", p->half_length, p->n_half_length, n * dim, 1, 1},
    };
    for (size_t a = 0; a < sizeof arrays / sizeof arrays[0]; a++) {
        snprintf(path, sizeof path, "bodies[%zu].points.%s", bi, arrays[a].name);
        if ((rc = chk_points(path, arrays[a].v, arrays[a].n, arrays[a].want, arrays[a].optional,
                             arrays[a].positive, err)))
            return rc;
    }

    blk = malloc((p->n_x + p->n_volume + p->n_mass + p->n_v + p->n_stress + p->n_half_length) *
                 sizeof *blk);
    if (!blk) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    mc->point_blocks[bi] = blk;
#define TAKE(dst, field)                                             \
    do {                                                             \
        if (p->n_##field) {                                          \
            memcpy(blk + off, p->field, p->n_##field * sizeof *blk); \
            b->dst = blk + off;                                      \
            off += p->n_##field;                                     \
        }                                                            \
    } while (0)
    TAKE(x, x);
    TAKE(volume, volume);
    TAKE(mass, mass);
    TAKE(v, v);
    TAKE(stress, stress);
    TAKE(half_length, half_length);
#undef TAKE
    b->n_points = n;
    *total += (double)n;
    mc->explicit_points += n;
    return 0;
}

static int conv_bodies(const Mpmd__Case *pb, mpp_case *mc, size_t max, mpm_error *err)
{
    size_t n = pb->n_bodies;
    int dim = mc->c.grid.dim, rc;
    double total = 0;
    char at_[96], path[64];
    if (n == 0) return mpm_fail(err, MPM_EINVAL, "bodies", "at least one body is required");
    if (n > MPP_CASE_MAX_ITEMS)
        return mpm_fail(err, MPM_ETOOBIG, "bodies", "%zu, more than the limit of %u", n,
                        MPP_CASE_MAX_ITEMS);
    mc->bodies = calloc(n, sizeof *mc->bodies);
    mc->point_blocks = calloc(n, sizeof *mc->point_blocks);
    if (!mc->bodies || !mc->point_blocks) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    mc->c.bodies = mc->bodies;
    mc->c.n_bodies = n;
    for (size_t i = 0; i < n; i++) {
        const Mpmd__Body *pbb = pb->bodies[i];
        mpm_body_desc *b = &mc->bodies[i];
        if (pbb->material >= pb->n_materials)
            return mpm_fail(err, MPM_EINVAL, AT("bodies[%zu].material", i),
                            "no material %u (the case has %zu)", pbb->material, pb->n_materials);
        b->material = (int)pbb->material;
        snprintf(path, sizeof path, "bodies[%zu].velocity", i);
        if ((rc = get_vec(path, pbb->velocity, pbb->n_velocity, dim, 1, b->velocity, err)))
            return rc;
        b->ppc = 2;
        if (pbb->geometry_case == MPMD__BODY__GEOMETRY_BOX ||
            pbb->geometry_case == MPMD__BODY__GEOMETRY_SPHERE) {
            if (pbb->ppc < 1 || pbb->ppc > 8)
                return mpm_fail(err, MPM_EINVAL, AT("bodies[%zu].ppc", i), "must be 1..8 (got %u)",
                                pbb->ppc);
            b->ppc = (int)pbb->ppc;
        }
        if (pbb->geostatic) { /* the solver checks gravity, k0 and the surface */
            b->geostatic = 1;
            b->free_surface = pbb->geostatic->free_surface;
            b->has_k0 = pbb->geostatic->has_k0;
            b->k0 = pbb->geostatic->k0;
        }
        switch (pbb->geometry_case) {
        case MPMD__BODY__GEOMETRY_BOX:
            b->shape = MPM_SHAPE_BOX;
            snprintf(path, sizeof path, "bodies[%zu].box.lo", i);
            if ((rc = get_vec(path, pbb->box->lo, pbb->box->n_lo, dim, 0, b->lo, err))) return rc;
            snprintf(path, sizeof path, "bodies[%zu].box.hi", i);
            if ((rc = get_vec(path, pbb->box->hi, pbb->box->n_hi, dim, 0, b->hi, err))) return rc;
            for (int d = 0; d < dim; d++)
                if (!(b->hi[d] > b->lo[d]))
                    return mpm_fail(err, MPM_EINVAL, AT("bodies[%zu].box.hi[%d]", i, d),
                                    "must be > lo[%d] (%g <= %g)", d, b->hi[d], b->lo[d]);
            break;
        case MPMD__BODY__GEOMETRY_SPHERE:
            b->shape = MPM_SHAPE_SPHERE;
            snprintf(path, sizeof path, "bodies[%zu].sphere.center", i);
            if ((rc = get_vec(path, pbb->sphere->center, pbb->sphere->n_center, dim, 0, b->center,
                              err)))
                return rc;
            if (!pbb->sphere->has_radius)
                return mpm_fail(err, MPM_EINVAL, AT("bodies[%zu].sphere.radius", i), "missing");
            if (!isfinite(pbb->sphere->radius) || !(pbb->sphere->radius > 0))
                return mpm_fail(err, MPM_EINVAL, AT("bodies[%zu].sphere.radius", i),
                                "must be > 0 (got %g)", pbb->sphere->radius);
            b->radius = pbb->sphere->radius;
            break;
        case MPMD__BODY__GEOMETRY_POINTS:
            if ((rc = conv_points(pbb->points, i, mc, &total, max, err))) return rc;
            continue;
        default:
            return mpm_fail(err, MPM_EINVAL, AT("bodies[%zu]", i),
                            "needs one of box, sphere or points");
        }
        total += est_generated(b, &mc->c.grid);
        if (total > (double)max && total > MPP_ESTIMATE_FROM)
            return mpm_fail(err, MPM_ETOOBIG, AT("bodies[%zu]", i),
                            "about %.0f particles up to this body, more than the limit of %zu",
                            total, max);
    }
    return 0;
}

/* ---- conditions: time functions, prescribed velocities, friction ---- */

/* the table points of a time function (0 when absent or not a TABLE) */
static size_t tf_points(const Mpmd__TimeFunction *f)
{
    return f && f->has_kind && f->kind == MPMD__TIME_FUNCTION__KIND__TABLE ? f->n_t : 0;
}

/* Time function f (path names it) into *out, its table copied to *data
 * (advanced past it).  The solver checks the values. */
static int conv_timefn(const Mpmd__TimeFunction *f, const char *path, mpm_timefn *out,
                       double **data, mpm_error *err)
{
    char at_[96];
    memset(out, 0, sizeof *out);
    out->kind = f->has_kind ? (mpm_timefn_kind)f->kind : MPM_TF_CONSTANT;
    if (out->kind != MPM_TF_CONSTANT && out->kind != MPM_TF_RAMP && out->kind != MPM_TF_TABLE)
        return mpm_fail(err, MPM_EINVAL, AT("%s.kind", path), "unknown value %d", (int)f->kind);
    out->value = f->value; /* default 1 */
    out->t0 = f->has_t0 ? f->t0 : 0;
    if (out->kind == MPM_TF_RAMP && !f->has_t1)
        return mpm_fail(err, MPM_EINVAL, AT("%s.t1", path), "missing (a RAMP needs t1 > t0)");
    out->t1 = f->t1;
    if (out->kind == MPM_TF_TABLE) {
        if (f->n_t != f->n_v)
            return mpm_fail(err, MPM_EINVAL, AT("%s.v", path),
                            "expected as many values as times (%zu), got %zu", f->n_t, f->n_v);
        out->n = f->n_t;
        if (f->n_t == 0) return 0; /* the solver names the empty table */
        memcpy(*data, f->t, f->n_t * sizeof **data);
        memcpy(*data + f->n_t, f->v, f->n_t * sizeof **data);
        out->t = *data;
        out->v = *data + f->n_t;
        *data += 2 * f->n_t;
    }
    return 0;
}

/* the time functions' storage: one per traction and prescribed velocity */
static int alloc_timefns(const Mpmd__Case *pb, mpp_case *mc, mpm_error *err)
{
    size_t n = pb->n_tractions + pb->n_prescribed, pts = 0;
    for (size_t i = 0; i < pb->n_tractions; i++) pts += tf_points(pb->tractions[i]->time_function);
    for (size_t i = 0; i < pb->n_prescribed; i++)
        pts += tf_points(pb->prescribed[i]->time_function);
    if (pts > MPP_CASE_MAX_TABLE)
        return mpm_fail(err, MPM_ETOOBIG, "prescribed",
                        "%zu time-function table points, more than the limit of %u", pts,
                        MPP_CASE_MAX_TABLE);
    if (!n) return 0;
    mc->timefns = calloc(n, sizeof *mc->timefns);
    mc->tf_data = malloc((pts ? 2 * pts : 1) * sizeof *mc->tf_data);
    if (!mc->timefns || !mc->tf_data) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    return 0;
}

static int conv_prescribed(const Mpmd__Case *pb, mpp_case *mc, double **data, mpm_error *err)
{
    size_t n = pb->n_prescribed, nodes = 0;
    int dim = mc->c.grid.dim, rc;
    unsigned all = (1u << dim) - 1;
    char at_[96], path[64];
    if (n == 0) return 0;
    if (n > MPP_CASE_MAX_ITEMS)
        return mpm_fail(err, MPM_ETOOBIG, "prescribed", "%zu, more than the limit of %u", n,
                        MPP_CASE_MAX_ITEMS);
    for (size_t i = 0; i < n; i++) {
        const Mpmd__PrescribedVelocity *p = pb->prescribed[i];
        if (p->n_ijk % (size_t)dim)
            return mpm_fail(err, MPM_EINVAL, AT("prescribed[%zu].ijk", i),
                            "%zu indices are not a whole number of nodes of %d indices", p->n_ijk,
                            dim);
        nodes += p->n_ijk / (size_t)dim;
    }
    if (nodes > MPP_CASE_MAX_NODE_FIXES)
        return mpm_fail(err, MPM_ETOOBIG, "prescribed", "%zu nodes, more than the limit of %u",
                        nodes, MPP_CASE_MAX_NODE_FIXES);
    mc->prescribed = calloc(n, sizeof *mc->prescribed);
    mc->presc_ijk = calloc(nodes ? 3 * nodes : 1, sizeof *mc->presc_ijk);
    if (!mc->prescribed || !mc->presc_ijk) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    int *ijk = mc->presc_ijk;
    for (size_t i = 0; i < n; i++) {
        const Mpmd__PrescribedVelocity *p = pb->prescribed[i];
        mpm_prescribed_desc *pd = &mc->prescribed[i];
        pd->face = p->has_face ? (int)p->face : -1;
        pd->n_nodes = p->n_ijk / (size_t)dim;
        pd->node_ijk = ijk;
        for (size_t k = 0; k < pd->n_nodes; k++, ijk += 3)
            for (int d = 0; d < dim; d++) {
                uint32_t v = p->ijk[k * (size_t)dim + (size_t)d];
                if (v >= (uint32_t)mc->c.grid.nodes[d])
                    return mpm_fail(err, MPM_EINVAL,
                                    AT("prescribed[%zu].ijk[%zu]", i, k * (size_t)dim + (size_t)d),
                                    "%u is outside the grid (nodes[%d] = %d)", v, d,
                                    mc->c.grid.nodes[d]);
                ijk[d] = (int)v;
            }
        if (p->mask > 7)
            return mpm_fail(err, MPM_EINVAL, AT("prescribed[%zu].mask", i),
                            "%u has bits other than 1 (x), 2 (y), 4 (z)", p->mask);
        pd->mask = p->mask & all; /* bits of axes the grid lacks are ignored */
        snprintf(path, sizeof path, "prescribed[%zu].velocity", i);
        if ((rc = get_vec(path, p->velocity, p->n_velocity, dim, 0, pd->value, err))) return rc;
        if (p->time_function) {
            mpm_timefn *tf = &mc->timefns[pb->n_tractions + i];
            snprintf(path, sizeof path, "prescribed[%zu].time_function", i);
            if ((rc = conv_timefn(p->time_function, path, tf, data, err))) return rc;
            pd->time_function = tf;
        }
    }
    mc->c.prescribed = mc->prescribed;
    mc->c.n_prescribed = n;
    return 0;
}

static int conv_friction(const Mpmd__Boundary *bd, mpp_case *mc, mpm_error *err)
{
    size_t n = bd->n_friction;
    char at_[96];
    if (n == 0) return 0;
    if (n > 6)
        return mpm_fail(err, MPM_EINVAL, "boundary.friction", "%zu entries for at most 6 faces", n);
    mc->friction = calloc(n, sizeof *mc->friction);
    if (!mc->friction) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    for (size_t i = 0; i < n; i++) {
        const Mpmd__FaceFriction *f = bd->friction[i];
        if (!f->has_face)
            return mpm_fail(err, MPM_EINVAL, AT("boundary.friction[%zu].face", i), "missing");
        if (!f->has_mu)
            return mpm_fail(err, MPM_EINVAL, AT("boundary.friction[%zu].mu", i), "missing");
        mc->friction[i].face = (int)f->face;
        mc->friction[i].mu = f->mu;
    }
    mc->c.bc.friction = mc->friction;
    mc->c.bc.n_friction = n;
    return 0;
}

static int conv_tractions(const Mpmd__Case *pb, mpp_case *mc, double **data, mpm_error *err)
{
    size_t n = pb->n_tractions;
    int dim = mc->c.grid.dim, rc;
    char at_[96], path[64];
    if (n == 0) return 0;
    if (n > MPP_CASE_MAX_ITEMS)
        return mpm_fail(err, MPM_ETOOBIG, "tractions", "%zu, more than the limit of %u", n,
                        MPP_CASE_MAX_ITEMS);
    mc->tractions = calloc(n, sizeof *mc->tractions);
    if (!mc->tractions) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    mc->c.tractions = mc->tractions;
    mc->c.n_tractions = n;
    for (size_t i = 0; i < n; i++) {
        const Mpmd__Traction *t = pb->tractions[i];
        mpm_traction_desc *td = &mc->tractions[i];
        snprintf(path, sizeof path, "tractions[%zu].lo", i);
        if ((rc = get_vec(path, t->lo, t->n_lo, dim, 0, td->lo, err))) return rc;
        snprintf(path, sizeof path, "tractions[%zu].hi", i);
        if ((rc = get_vec(path, t->hi, t->n_hi, dim, 0, td->hi, err))) return rc;
        for (int d = 0; d < dim; d++)
            if (td->hi[d] < td->lo[d])
                return mpm_fail(err, MPM_EINVAL, AT("tractions[%zu].hi[%d]", i, d),
                                "must be >= lo[%d] (%g < %g)", d, td->hi[d], td->lo[d]);
        if (t->normal >= (uint32_t)dim)
            return mpm_fail(err, MPM_EINVAL, AT("tractions[%zu].normal", i),
                            "must be an axis below dim %d (got %u)", dim, t->normal);
        td->normal = (int)t->normal;
        td->is_force = t->is_force ? 1 : 0;
        snprintf(path, sizeof path, "tractions[%zu].value", i);
        if ((rc = get_vec(path, t->value, t->n_value, dim, 0, td->value, err))) return rc;
        if (t->time_function) {
            snprintf(path, sizeof path, "tractions[%zu].time_function", i);
            if ((rc = conv_timefn(t->time_function, path, &mc->timefns[i], data, err))) return rc;
            td->time_function = &mc->timefns[i];
        }
    }
    return 0;
}

static int conv_boundary(const Mpmd__Boundary *bd, mpp_case *mc, mpm_error *err)
{
    static const char *const face[6] = {"x_lo", "x_hi", "y_lo", "y_hi", "z_lo", "z_hi"};
    const mpm_grid_desc *g = &mc->c.grid;
    uint32_t mask[6];
    char at_[96];
    size_t n;
    if (!bd) return 0;
    mask[0] = bd->has_x_lo ? bd->x_lo : 0;
    mask[1] = bd->has_x_hi ? bd->x_hi : 0;
    mask[2] = bd->has_y_lo ? bd->y_lo : 0;
    mask[3] = bd->has_y_hi ? bd->y_hi : 0;
    mask[4] = bd->has_z_lo ? bd->z_lo : 0;
    mask[5] = bd->has_z_hi ? bd->z_hi : 0;
    for (int f = 0; f < 6; f++) {
        if (mask[f] > 7)
            return mpm_fail(err, MPM_EINVAL, AT("boundary.%s", face[f]),
                            "mask %u has bits other than 1 (x), 2 (y), 4 (z)", mask[f]);
        if (mask[f] && f / 2 >= g->dim)
            return mpm_fail(err, MPM_EINVAL, AT("boundary.%s", face[f]),
                            "the grid has no axis %d (dim %d)", f / 2, g->dim);
        mc->c.bc.face_mask[f] = mask[f];
    }
    n = bd->n_nodes;
    if (n == 0) return conv_friction(bd, mc, err);
    if (n > MPP_CASE_MAX_NODE_FIXES)
        return mpm_fail(err, MPM_ETOOBIG, "boundary.nodes", "%zu, more than the limit of %u", n,
                        MPP_CASE_MAX_NODE_FIXES);
    mc->node_ijk = calloc(n * 3, sizeof *mc->node_ijk);
    mc->node_mask = calloc(n, sizeof *mc->node_mask);
    if (!mc->node_ijk || !mc->node_mask) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    for (size_t i = 0; i < n; i++) {
        const Mpmd__NodeFix *nf = bd->nodes[i];
        if (nf->n_ijk != (size_t)g->dim)
            return mpm_fail(err, MPM_EINVAL, AT("boundary.nodes[%zu].ijk", i),
                            "expected %d indices (one per axis), got %zu", g->dim, nf->n_ijk);
        for (int d = 0; d < g->dim; d++) {
            if (nf->ijk[d] >= (uint32_t)g->nodes[d])
                return mpm_fail(err, MPM_EINVAL, AT("boundary.nodes[%zu].ijk[%d]", i, d),
                                "%u is outside the grid (nodes[%d] = %d)", nf->ijk[d], d,
                                g->nodes[d]);
            mc->node_ijk[3 * i + (size_t)d] = (int)nf->ijk[d];
        }
        if (nf->mask > 7)
            return mpm_fail(err, MPM_EINVAL, AT("boundary.nodes[%zu].mask", i),
                            "%u has bits other than 1 (x), 2 (y), 4 (z)", nf->mask);
        mc->node_mask[i] = nf->mask;
    }
    mc->c.bc.n_nodes = n;
    mc->c.bc.node_ijk = mc->node_ijk;
    mc->c.bc.node_mask = mc->node_mask;
    return conv_friction(bd, mc, err);
}

static int conv_run(const Mpmd__Case *pb, mpp_case *mc, mpm_error *err)
{
    const Mpmd__Output *o = pb->output;
    char at_[96];
    switch (pb->stop_case) {
    case MPMD__CASE__STOP_END_TIME:
        if (!isfinite(pb->end_time) || !(pb->end_time > 0))
            return mpm_fail(err, MPM_EINVAL, "end_time", "must be > 0 (got %g)", pb->end_time);
        mc->has_end_time = 1;
        mc->end_time = pb->end_time;
        break;
    case MPMD__CASE__STOP_STEPS:
        if (pb->steps < 1 || pb->steps > MPP_CASE_MAX_STEPS)
            return mpm_fail(err, MPM_EINVAL, "steps", "must be 1..%lld (got %lld)",
                            (long long)MPP_CASE_MAX_STEPS, (long long)pb->steps);
        mc->steps = pb->steps;
        break;
    default:
        return mpm_fail(err, MPM_EINVAL, "end_time", "missing (a case needs endTime or steps)");
    }
    /* a uint32 the solver's int must hold */
    if (pb->has_threads && pb->threads > MPM_MAX_THREADS)
        return mpm_fail(err, MPM_EINVAL, "threads", "must be 0..%d (got %u)", MPM_MAX_THREADS,
                        pb->threads);
    mc->c.threads = pb->has_threads ? (int)pb->threads : 0;
    if (pb->checkpoint) {
        const Mpmd__Checkpoint *ck = pb->checkpoint;
        double w = ck->has_every_wall_s ? ck->every_wall_s : 0;
        if (!isfinite(w) || w < 0 || w > 1e9)
            return mpm_fail(err, MPM_EINVAL, "checkpoint.every_wall_s",
                            "must be 0 (off) or a time in seconds up to 1e9 (got %g)", w);
        mc->has_checkpoint = 1;
        mc->checkpoint_every_steps = ck->has_every_steps ? ck->every_steps : 0;
        mc->checkpoint_every_wall_s = w;
    }
    mc->snapshot_fields = MPP_SNAP_ALL;
    if (!o) return 0;
    mc->energy_every = o->has_energy_every ? o->energy_every : 0;
    mc->snapshot_every = o->has_snapshot_every ? o->snapshot_every : 0;
    mc->record_snapshots = o->has_record_snapshots && o->record_snapshots;
    if (o->n_snapshot_fields) mc->snapshot_fields = 0;
    for (size_t i = 0; i < o->n_snapshot_fields; i++) {
        switch (o->snapshot_fields[i]) {
        case MPMD__OUTPUT__FIELD__X: mc->snapshot_fields |= MPP_SNAP_X; break;
        case MPMD__OUTPUT__FIELD__V: mc->snapshot_fields |= MPP_SNAP_V; break;
        case MPMD__OUTPUT__FIELD__STRESS: mc->snapshot_fields |= MPP_SNAP_STRESS; break;
        case MPMD__OUTPUT__FIELD__PRESSURE: mc->snapshot_fields |= MPP_SNAP_PRESSURE; break;
        case MPMD__OUTPUT__FIELD__VOLUME: mc->snapshot_fields |= MPP_SNAP_VOLUME; break;
        case MPMD__OUTPUT__FIELD__PLASTIC_STRAIN:
            mc->snapshot_fields |= MPP_SNAP_PLASTIC_STRAIN;
            break;
        case MPMD__OUTPUT__FIELD__DEFORMATION_GRADIENT:
            mc->snapshot_fields |= MPP_SNAP_DEFORMATION_GRADIENT;
            break;
        case MPMD__OUTPUT__FIELD__YIELDED: mc->snapshot_fields |= MPP_SNAP_YIELDED; break;
        default:
            return mpm_fail(err, MPM_EINVAL, AT("output.snapshot_fields[%zu]", i),
                            "unknown value %d", (int)o->snapshot_fields[i]);
        }
    }
    return 0;
}

static int conv_case(const Mpmd__Case *pb, mpp_case *mc, size_t max, mpm_error *err)
{
    mpm_case *c = &mc->c;
    const char *name = pb->name ? pb->name : "";
    size_t nl = strlen(name);
    int rc;
    if (nl > MPP_NAME_MAX)
        return mpm_fail(err, MPM_EINVAL, "name", "%zu bytes: at most %d", nl, MPP_NAME_MAX);
    if (!mpp_json_utf8_valid(name)) return mpm_fail(err, MPM_EINVAL, "name", "not valid UTF-8");
    mc->name = malloc(nl + 1);
    if (!mc->name) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    memcpy(mc->name, name, nl + 1);

    if ((rc = conv_grid(pb->grid, mc, err))) return rc;
    /* the same values (asserted in mpp.c); the solver judges them */
    c->method = (mpm_method)pb->method;
    c->update = (mpm_update)pb->update;
    c->dt = pb->has_dt ? pb->dt : 0;
    c->cfl = pb->has_cfl ? pb->cfl : 0;
    c->mass_tol = pb->has_mass_tol ? pb->mass_tol : 0;
    c->pic_fraction = pb->has_pic_fraction ? pb->pic_fraction : 0;
    c->transfer = pb->has_transfer ? (mpm_transfer)pb->transfer : MPM_TRANSFER_FLIP;
    c->kernel_family =
        pb->has_kernel_family ? (mpm_kernel_family)pb->kernel_family : MPM_KERNEL_FAMILY_FAST;
    c->volume_update =
        pb->has_volume_update ? (mpm_volume_update)pb->volume_update : MPM_VOLUME_STRAIN_INCREMENT;
    c->allow_unstable_dt = pb->has_allow_unstable_dt && pb->allow_unstable_dt;
    if (pb->damping) {
        c->damping = (mpm_damping_kind)pb->damping->kind;
        c->damping_coef = pb->damping->coefficient;
        c->damping_until = pb->damping->until;
    }
    c->energy_budget = pb->has_energy_budget ? pb->energy_budget : 0.05; /* the .proto's default */
    c->fail_on_budget = pb->has_fail_on_budget && pb->fail_on_budget;
    if ((rc = get_vec("gravity", pb->gravity, pb->n_gravity, c->grid.dim, 1, c->gravity, err)))
        return rc;
    if ((rc = conv_materials(pb, mc, err))) return rc;
    if ((rc = conv_bodies(pb, mc, max, err))) return rc;
    if ((rc = alloc_timefns(pb, mc, err))) return rc;
    double *tf_next = mc->tf_data;
    if ((rc = conv_tractions(pb, mc, &tf_next, err))) return rc;
    if ((rc = conv_boundary(pb->boundary, mc, err))) return rc;
    if ((rc = conv_prescribed(pb, mc, &tf_next, err))) return rc;
    return conv_run(pb, mc, err);
}

int mpp_case_from_pb(const Mpmd__Case *pb, size_t max_particles, mpp_case **out, mpm_error *err)
{
    mpp_case *mc;
    size_t max = max_particles ? max_particles : MPP_DEFAULT_MAX_PARTICLES;
    int rc;
    *out = NULL;
    mpm_error_clear(err);
    if (!pb) return mpm_fail(err, MPM_EINVAL, "case", "missing");
    mc = calloc(1, sizeof *mc);
    if (!mc) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory");
    rc = conv_case(pb, mc, max, err);
    if (!rc) {
        /* the solver's check, once: it counts the particles up to the limit */
        mc->c.max_particles = max;
        rc = mpm_case_check(&mc->c, &mc->info, err);
    }
    /* only the combinations the tests show right (docs/accuracy.md) */
    if (!rc) rc = mpm_case_verified(&mc->c, &mc->info, err);
    if (rc) {
        mpp_case_destroy(&mc);
        return rc;
    }
    *out = mc;
    return 0;
}

int mpp_case_load(const char *json, size_t len, size_t max_particles, mpp_case **out,
                  mpm_error *err)
{
    Mpmd__Case *pb;
    int rc = mpp_case_from_json(json, len, &pb, err);
    *out = NULL;
    if (rc) return rc;
    rc = mpp_case_from_pb(pb, max_particles, out, err);
    mpp_case_pb_free(&pb);
    return rc;
}

void mpp_case_destroy(mpp_case **mcp)
{
    mpp_case *mc;
    if (!mcp || !*mcp) return;
    mc = *mcp;
    if (mc->point_blocks)
        for (size_t i = 0; i < mc->c.n_bodies; i++) free(mc->point_blocks[i]);
    free(mc->point_blocks);
    free(mc->bodies);
    free(mc->materials);
    free(mc->tractions);
    free(mc->node_ijk);
    free(mc->node_mask);
    free(mc->friction);
    free(mc->prescribed);
    free(mc->presc_ijk);
    free(mc->timefns);
    free(mc->tf_data);
    free(mc->name);
    free(mc);
    *mcp = NULL;
}
