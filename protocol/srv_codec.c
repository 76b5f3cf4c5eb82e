/*
 * srv_codec.c - the one place that knows the generated mpmd.pb-c.h types.
 *
 * It turns JSON or protobuf bytes into an Mpmd__Case (JSON through the
 * generic srv_json walker), converts an Mpmd__Case into a self-contained
 * srv_case holding an mpm_case for the solver, and packs / unpacks the
 * Request, Reply and StreamMsg envelopes for the daemon, which sees only
 * the plain structs of srv_codec.h.  Case conversion checks everything the
 * schema cannot (dimensions, array lengths, indices, enum values, value
 * ranges, size limits) and names the offending field by its JSON path
 * before handing the case to mpm_case_check() for the physics checks.
 */
#include "srv_codec.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mpmd.pb-c.h"
#include "srv_json.h"

_Static_assert(SRV_SCHEMA_VERSION == MPMD__SCHEMA_VERSION__SCHEMA_VERSION,
               "SRV_SCHEMA_VERSION must match proto/mpmd.proto");
#define SAME(a, b) ((int)(a) == (int)(b))
_Static_assert(SAME(SRV_STATUS_QUEUED, MPMD__RUN_STATUS__QUEUED) &&
               SAME(SRV_STATUS_RUNNING, MPMD__RUN_STATUS__RUNNING) &&
               SAME(SRV_STATUS_FINISHED, MPMD__RUN_STATUS__FINISHED) &&
               SAME(SRV_STATUS_FAILED, MPMD__RUN_STATUS__FAILED) &&
               SAME(SRV_STATUS_CANCELLED, MPMD__RUN_STATUS__CANCELLED) &&
               SAME(SRV_STATUS_INTERRUPTED, MPMD__RUN_STATUS__INTERRUPTED),
               "srv_status must match mpmd.RunStatus");
_Static_assert(SAME(SRV_ERR_INTERNAL, MPMD__ERROR__CODE__INTERNAL) &&
               SAME(SRV_ERR_BAD_REQUEST, MPMD__ERROR__CODE__BAD_REQUEST) &&
               SAME(SRV_ERR_BAD_SCHEMA, MPMD__ERROR__CODE__BAD_SCHEMA) &&
               SAME(SRV_ERR_INVALID_CASE, MPMD__ERROR__CODE__INVALID_CASE) &&
               SAME(SRV_ERR_NOT_FOUND, MPMD__ERROR__CODE__NOT_FOUND) &&
               SAME(SRV_ERR_QUEUE_FULL, MPMD__ERROR__CODE__QUEUE_FULL) &&
               SAME(SRV_ERR_TOO_LARGE, MPMD__ERROR__CODE__TOO_LARGE) &&
               SAME(SRV_ERR_CONFLICT, MPMD__ERROR__CODE__CONFLICT) &&
               SAME(SRV_ERR_UNAVAILABLE, MPMD__ERROR__CODE__UNAVAILABLE),
               "srv_err_code must match mpmd.Error.Code");
_Static_assert(SAME(MPM_METHOD_MPM, MPMD__CASE__METHOD__MPM) &&
               SAME(MPM_METHOD_GIMP, MPMD__CASE__METHOD__GIMP) &&
               SAME(MPM_USF, MPMD__CASE__UPDATE__USF) && SAME(MPM_USL, MPMD__CASE__UPDATE__USL) &&
               SAME(MPM_MUSL, MPMD__CASE__UPDATE__MUSL),
               "mpm_method / mpm_update must match mpmd.Case.Method / Update");
#undef SAME

#define PI_ 3.14159265358979323846

/* Protobuf wire types: varint, 64-bit, length-delimited, 32-bit (3 and 4,
 * groups, are not in this schema). */
enum { WT_VARINT = 0, WT_I64 = 1, WT_LEN = 2, WT_I32 = 5 };

/* Writes a formatted message into err and returns code. */
__attribute__((format(printf, 4, 5)))
static int bad(char *err, size_t errlen, int code, const char *fmt, ...)
{
    if (err && errlen) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err, errlen, fmt, ap);
        va_end(ap);
    }
    return code;
}

#define EINV(...) bad(err, errlen, SRV_CODEC_EINVAL, __VA_ARGS__)
#define ENOMEM_() bad(err, errlen, SRV_CODEC_ENOMEM, "out of memory")

static int from_json_code(int rc)
{
    switch (rc) {
    case SRV_JSON_OK: return 0;
    case SRV_JSON_ESYNTAX: return SRV_CODEC_ESYNTAX;
    case SRV_JSON_ENOMEM: return SRV_CODEC_ENOMEM;
    default: return SRV_CODEC_EINVAL;
    }
}

/* ------------------------------------------------------------------------ */
/* Generic pack / unpack                                                    */

static int pack_msg(const ProtobufCMessage *m, uint8_t **buf, size_t *len)
{
    size_t n = protobuf_c_message_get_packed_size(m);
    uint8_t *b = malloc(n ? n : 1);
    *buf = NULL;
    *len = 0;
    if (!b) return SRV_CODEC_ENOMEM;
    if (protobuf_c_message_pack(m, b) != n) {
        free(b);
        return SRV_CODEC_ENOMEM;
    }
    *buf = b;
    *len = n;
    return 0;
}

static int unpack_msg(const ProtobufCMessageDescriptor *d, const void *buf, size_t len,
                      size_t max, ProtobufCMessage **out, char *err, size_t errlen)
{
    static const uint8_t empty[1];
    *out = NULL;
    if (!max) max = SRV_MSG_MAX;
    if (len > max)
        return bad(err, errlen, SRV_CODEC_ETOOBIG, "%s message of %zu bytes: more than the limit of %zu",
                   d->name, len, max);
    *out = protobuf_c_message_unpack(d, NULL, len, buf ? buf : empty);
    if (!*out)
        return bad(err, errlen, SRV_CODEC_ESYNTAX, "not a valid %s message (%zu bytes)", d->name, len);
    return 0;
}

static const ProtobufCMessageDescriptor *kind_desc(srv_msg_kind kind)
{
    switch (kind) {
    case SRV_MSG_CASE: return &mpmd__case__descriptor;
    case SRV_MSG_REQUEST: return &mpmd__request__descriptor;
    case SRV_MSG_REPLY: return &mpmd__reply__descriptor;
    case SRV_MSG_STREAM: return &mpmd__stream_msg__descriptor;
    }
    return NULL;
}

int srv_msg_json_to_bytes(srv_msg_kind kind, const char *json, size_t len,
                          uint8_t **buf, size_t *n, char *err, size_t errlen)
{
    const ProtobufCMessageDescriptor *d = kind_desc(kind);
    ProtobufCMessage *m;
    int rc;
    *buf = NULL;
    *n = 0;
    if (!d) return EINV("unknown message kind %d", (int)kind);
    rc = srv_json_to_pb(d, json, len, &m, err, errlen);
    if (rc) return from_json_code(rc);
    rc = pack_msg(m, buf, n);
    protobuf_c_message_free_unpacked(m, NULL);
    return rc ? ENOMEM_() : 0;
}

int srv_msg_bytes_to_json(srv_msg_kind kind, const void *buf, size_t n,
                          size_t max, unsigned flags, char **json, char *err,
                          size_t errlen)
{
    const ProtobufCMessageDescriptor *d = kind_desc(kind);
    ProtobufCMessage *m;
    int rc;
    *json = NULL;
    if (!d) return EINV("unknown message kind %d", (int)kind);
    rc = unpack_msg(d, buf, n, max, &m, err, errlen);
    if (rc) return rc;
    rc = srv_json_from_pb(m, flags, json, err, errlen);
    protobuf_c_message_free_unpacked(m, NULL);
    return from_json_code(rc);
}

/* ------------------------------------------------------------------------ */
/* Case message <-> JSON / bytes                                            */

int srv_case_from_json(const char *json, size_t len, Mpmd__Case **out,
                       char *err, size_t errlen)
{
    ProtobufCMessage *m;
    int rc = srv_json_to_pb(&mpmd__case__descriptor, json, len, &m, err, errlen);
    *out = rc ? NULL : (Mpmd__Case *)m;
    return from_json_code(rc);
}

int srv_case_unpack(const void *buf, size_t len, size_t max, Mpmd__Case **out,
                    char *err, size_t errlen)
{
    ProtobufCMessage *m;
    int rc = unpack_msg(&mpmd__case__descriptor, buf, len, max, &m, err, errlen);
    *out = (Mpmd__Case *)m;
    return rc;
}

int srv_case_pack(const Mpmd__Case *pb, uint8_t **buf, size_t *len)
{
    return pack_msg(&pb->base, buf, len);
}

int srv_case_to_json(const Mpmd__Case *pb, unsigned flags, char **json,
                     char *err, size_t errlen)
{
    return from_json_code(srv_json_from_pb(&pb->base, flags, json, err, errlen));
}

void srv_case_pb_free(Mpmd__Case **pb)
{
    if (!pb || !*pb) return;
    protobuf_c_message_free_unpacked(&(*pb)->base, NULL);
    *pb = NULL;
}

void srv_case_pin_defaults(Mpmd__Case *pb)
{
    if (!pb) return;
    pb->has_method = 1;  /* an absent field holds the schema's default */
    pb->has_update = 1;
}

/* The solver's checks name fields by their C names (snake_case): turns the
 * path an error message starts with ("bodies[0].points.half_length[3]: ...")
 * into the JSON mapping's lowerCamelCase, as the codec's own errors are. */
static void camel_error_path(char *err)
{
    char *end = err ? strstr(err, ": ") : NULL, *w = err;
    if (!end || memchr(err, ' ', (size_t)(end - err))) return;
    for (char *r = err; r < end; r++) {
        if (r[0] == '_' && r + 1 < end && r[1] >= 'a' && r[1] <= 'z' && r > err && r[-1] != '.' &&
            r[-1] != '[') {
            *w++ = (char)(r[1] - 'a' + 'A');
            r++;
        } else {
            *w++ = *r;
        }
    }
    if (w != end) memmove(w, end, strlen(end) + 1);
}

/* ------------------------------------------------------------------------ */
/* Case message -> srv_case                                                 */

/* An axis vector: exactly dim finite values (or none, giving zeros, when
 * optional).  path is the field's JSON path. */
static int get_vec(const char *path, const double *v, size_t n, int dim, int optional,
                   double out[MPM_MAX_DIM], char *err, size_t errlen)
{
    for (int d = 0; d < MPM_MAX_DIM; d++) out[d] = 0;
    if (n == 0 && optional) return 0;
    if (n == 0) return EINV("%s: missing (%d values, one per axis)", path, dim);
    if (n != (size_t)dim)
        return EINV("%s: expected %d values (one per axis), got %zu", path, dim, n);
    for (size_t i = 0; i < n; i++) {
        if (!isfinite(v[i])) return EINV("%s[%zu]: must be a finite number", path, i);
        out[i] = v[i];
    }
    return 0;
}

/* A per-point array of `want` values (n points times a width), or none
 * when optional; values finite, and > 0 when positive is set. */
static int chk_points(const char *path, const double *v, size_t n, size_t want, int optional,
                      int positive, char *err, size_t errlen)
{
    if (n == 0 && optional) return 0;
    if (n != want)
        return EINV("%s: expected %zu values (%s), got %zu", path, want,
                    optional ? "per point, or none" : "per point", n);
    for (size_t i = 0; i < n; i++) {
        if (!isfinite(v[i])) return EINV("%s[%zu]: must be a finite number", path, i);
        if (positive && !(v[i] > 0)) return EINV("%s[%zu]: must be > 0 (got %g)", path, i, v[i]);
    }
    return 0;
}

static int conv_grid(const Mpmd__Grid *g, srv_case *sc, char *err, size_t errlen)
{
    mpm_grid_desc *gd = &sc->c.grid;
    double total = 1;
    int rc;
    if (!g) return EINV("grid: missing");
    if (!g->has_dim) return EINV("grid.dim: missing (1, 2 or 3)");
    if (g->dim < 1 || g->dim > MPM_MAX_DIM) return EINV("grid.dim: must be 1, 2 or 3 (got %u)", g->dim);
    gd->dim = (int)g->dim;
    if ((rc = get_vec("grid.origin", g->origin, g->n_origin, gd->dim, 1, gd->origin, err, errlen)))
        return rc;
    if ((rc = get_vec("grid.spacing", g->spacing, g->n_spacing, gd->dim, 0, gd->h, err, errlen)))
        return rc;
    for (int d = 0; d < gd->dim; d++)
        if (!(gd->h[d] > 0)) return EINV("grid.spacing[%d]: must be > 0 (got %g)", d, gd->h[d]);
    if (g->n_nodes == 0) return EINV("grid.nodes: missing (%d values, one per axis)", gd->dim);
    if (g->n_nodes != (size_t)gd->dim)
        return EINV("grid.nodes: expected %d values (one per axis), got %zu", gd->dim, g->n_nodes);
    for (int d = 0; d < gd->dim; d++) {
        if (g->nodes[d] < 2) return EINV("grid.nodes[%d]: must be >= 2 (got %u)", d, g->nodes[d]);
        total *= g->nodes[d];
        gd->nodes[d] = g->nodes[d] > (uint32_t)SRV_CASE_MAX_NODES ? (int)SRV_CASE_MAX_NODES : (int)g->nodes[d];
    }
    if (total > SRV_CASE_MAX_NODES)
        return bad(err, errlen, SRV_CODEC_ETOOBIG, "grid.nodes: %.0f nodes, more than the limit of %u",
                   total, SRV_CASE_MAX_NODES);
    return 0;
}

static int conv_materials(const Mpmd__Case *pb, srv_case *sc, char *err, size_t errlen)
{
    size_t n = pb->n_materials;
    if (n == 0) return EINV("materials: at least one material is required");
    if (n > SRV_CASE_MAX_ITEMS)
        return bad(err, errlen, SRV_CODEC_ETOOBIG, "materials: %zu, more than the limit of %u", n,
                   SRV_CASE_MAX_ITEMS);
    sc->materials = calloc(n, sizeof *sc->materials);
    if (!sc->materials) return ENOMEM_();
    sc->c.materials = sc->materials;
    sc->c.n_materials = n;
    for (size_t i = 0; i < n; i++) {
        const Mpmd__Material *m = pb->materials[i];
        mpm_material_desc *md = &sc->materials[i];
        switch (m->model) {
        case MPMD__MATERIAL__MODEL__LINEAR_ELASTIC: md->model = MPM_MODEL_LINEAR_ELASTIC; break;
        default: return EINV("materials[%zu].model: unknown value %d", i, (int)m->model);
        }
        if (!m->has_youngs_modulus) return EINV("materials[%zu].youngsModulus: missing", i);
        if (!isfinite(m->youngs_modulus) || !(m->youngs_modulus > 0))
            return EINV("materials[%zu].youngsModulus: must be > 0 (got %g)", i, m->youngs_modulus);
        if (m->has_poisson_ratio && !(m->poisson_ratio > -1 && m->poisson_ratio < 0.5))
            return EINV("materials[%zu].poissonRatio: must be in (-1, 0.5) (got %g)", i, m->poisson_ratio);
        if (!m->has_density) return EINV("materials[%zu].density: missing", i);
        if (!isfinite(m->density) || !(m->density > 0))
            return EINV("materials[%zu].density: must be > 0 (got %g)", i, m->density);
        md->youngs_modulus = m->youngs_modulus;
        md->poisson_ratio = m->has_poisson_ratio ? m->poisson_ratio : 0;
        md->density = m->density;
    }
    return 0;
}

/* Upper estimate of the particles a box/sphere body generates. */
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

static int conv_points(const Mpmd__Points *p, size_t bi, srv_case *sc, double *total,
                       char *err, size_t errlen)
{
    mpm_body_desc *b = &sc->bodies[bi];
    size_t dim = (size_t)sc->c.grid.dim, n = p->n_volume, off = 0;
    char path[64];
    double *blk;
    int rc;
    if (n == 0) return EINV("bodies[%zu].points.volume: at least one point is required", bi);
    if (n > SRV_CASE_MAX_PARTICLES || *total + (double)n > SRV_CASE_MAX_PARTICLES)
        return bad(err, errlen, SRV_CODEC_ETOOBIG,
                   "bodies[%zu].points: %zu points, more than the limit of %u particles in a case",
                   bi, n, SRV_CASE_MAX_PARTICLES);
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
        {"halfLength", p->half_length, p->n_half_length, n * dim, 1, 1},
    };
    for (size_t a = 0; a < sizeof arrays / sizeof arrays[0]; a++) {
        snprintf(path, sizeof path, "bodies[%zu].points.%s", bi, arrays[a].name);
        if ((rc = chk_points(path, arrays[a].v, arrays[a].n, arrays[a].want, arrays[a].optional,
                             arrays[a].positive, err, errlen)))
            return rc;
    }

    blk = malloc((p->n_x + p->n_volume + p->n_mass + p->n_v + p->n_stress + p->n_half_length) *
                 sizeof *blk);
    if (!blk) return ENOMEM_();
    sc->point_blocks[bi] = blk;
#define TAKE(dst, field)                                                        \
    do {                                                                        \
        if (p->n_##field) {                                                     \
            memcpy(blk + off, p->field, p->n_##field * sizeof *blk);            \
            b->dst = blk + off;                                                 \
            off += p->n_##field;                                                \
        }                                                                       \
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
    sc->explicit_points += n;
    return 0;
}

static int conv_bodies(const Mpmd__Case *pb, srv_case *sc, char *err, size_t errlen)
{
    size_t n = pb->n_bodies;
    int dim = sc->c.grid.dim, rc;
    double total = 0;
    char path[64];
    if (n == 0) return EINV("bodies: at least one body is required");
    if (n > SRV_CASE_MAX_ITEMS)
        return bad(err, errlen, SRV_CODEC_ETOOBIG, "bodies: %zu, more than the limit of %u", n,
                   SRV_CASE_MAX_ITEMS);
    sc->bodies = calloc(n, sizeof *sc->bodies);
    sc->point_blocks = calloc(n, sizeof *sc->point_blocks);
    if (!sc->bodies || !sc->point_blocks) return ENOMEM_();
    sc->c.bodies = sc->bodies;
    sc->c.n_bodies = n;
    for (size_t i = 0; i < n; i++) {
        const Mpmd__Body *pbb = pb->bodies[i];
        mpm_body_desc *b = &sc->bodies[i];
        if (pbb->material >= pb->n_materials)
            return EINV("bodies[%zu].material: no material %u (the case has %zu)", i, pbb->material,
                        pb->n_materials);
        b->material = (int)pbb->material;
        snprintf(path, sizeof path, "bodies[%zu].velocity", i);
        if ((rc = get_vec(path, pbb->velocity, pbb->n_velocity, dim, 1, b->velocity, err, errlen)))
            return rc;
        b->ppc = 2;
        if (pbb->geometry_case == MPMD__BODY__GEOMETRY_BOX ||
            pbb->geometry_case == MPMD__BODY__GEOMETRY_SPHERE) {
            if (pbb->ppc < 1 || pbb->ppc > 8) return EINV("bodies[%zu].ppc: must be 1..8 (got %u)", i, pbb->ppc);
            b->ppc = (int)pbb->ppc;
        }
        switch (pbb->geometry_case) {
        case MPMD__BODY__GEOMETRY_BOX:
            b->shape = MPM_SHAPE_BOX;
            snprintf(path, sizeof path, "bodies[%zu].box.lo", i);
            if ((rc = get_vec(path, pbb->box->lo, pbb->box->n_lo, dim, 0, b->lo, err, errlen))) return rc;
            snprintf(path, sizeof path, "bodies[%zu].box.hi", i);
            if ((rc = get_vec(path, pbb->box->hi, pbb->box->n_hi, dim, 0, b->hi, err, errlen))) return rc;
            for (int d = 0; d < dim; d++)
                if (!(b->hi[d] > b->lo[d]))
                    return EINV("bodies[%zu].box.hi[%d]: must be > lo[%d] (%g <= %g)", i, d, d, b->hi[d],
                                b->lo[d]);
            break;
        case MPMD__BODY__GEOMETRY_SPHERE:
            b->shape = MPM_SHAPE_SPHERE;
            snprintf(path, sizeof path, "bodies[%zu].sphere.center", i);
            if ((rc = get_vec(path, pbb->sphere->center, pbb->sphere->n_center, dim, 0, b->center, err,
                              errlen)))
                return rc;
            if (!pbb->sphere->has_radius) return EINV("bodies[%zu].sphere.radius: missing", i);
            if (!isfinite(pbb->sphere->radius) || !(pbb->sphere->radius > 0))
                return EINV("bodies[%zu].sphere.radius: must be > 0 (got %g)", i, pbb->sphere->radius);
            b->radius = pbb->sphere->radius;
            break;
        case MPMD__BODY__GEOMETRY_POINTS:
            if ((rc = conv_points(pbb->points, i, sc, &total, err, errlen))) return rc;
            continue;
        default:
            return EINV("bodies[%zu]: needs one of box, sphere or points", i);
        }
        total += est_generated(b, &sc->c.grid);
        if (total > SRV_CASE_MAX_PARTICLES)
            return bad(err, errlen, SRV_CODEC_ETOOBIG,
                       "bodies[%zu]: about %.0f particles up to this body, more than the limit of %u",
                       i, total, SRV_CASE_MAX_PARTICLES);
    }
    sc->est_particles = (size_t)total;
    return 0;
}

static int conv_tractions(const Mpmd__Case *pb, srv_case *sc, char *err, size_t errlen)
{
    size_t n = pb->n_tractions;
    int dim = sc->c.grid.dim, rc;
    char path[64];
    if (n == 0) return 0;
    if (n > SRV_CASE_MAX_ITEMS)
        return bad(err, errlen, SRV_CODEC_ETOOBIG, "tractions: %zu, more than the limit of %u", n,
                   SRV_CASE_MAX_ITEMS);
    sc->tractions = calloc(n, sizeof *sc->tractions);
    if (!sc->tractions) return ENOMEM_();
    sc->c.tractions = sc->tractions;
    sc->c.n_tractions = n;
    for (size_t i = 0; i < n; i++) {
        const Mpmd__Traction *t = pb->tractions[i];
        mpm_traction_desc *td = &sc->tractions[i];
        snprintf(path, sizeof path, "tractions[%zu].lo", i);
        if ((rc = get_vec(path, t->lo, t->n_lo, dim, 0, td->lo, err, errlen))) return rc;
        snprintf(path, sizeof path, "tractions[%zu].hi", i);
        if ((rc = get_vec(path, t->hi, t->n_hi, dim, 0, td->hi, err, errlen))) return rc;
        for (int d = 0; d < dim; d++)
            if (td->hi[d] < td->lo[d])
                return EINV("tractions[%zu].hi[%d]: must be >= lo[%d] (%g < %g)", i, d, d, td->hi[d], td->lo[d]);
        if (t->normal >= (uint32_t)dim)
            return EINV("tractions[%zu].normal: must be an axis below dim %d (got %u)", i, dim, t->normal);
        td->normal = (int)t->normal;
        td->is_force = t->is_force ? 1 : 0;
        snprintf(path, sizeof path, "tractions[%zu].value", i);
        if ((rc = get_vec(path, t->value, t->n_value, dim, 0, td->value, err, errlen))) return rc;
    }
    return 0;
}

static int conv_boundary(const Mpmd__Boundary *bd, srv_case *sc, char *err, size_t errlen)
{
    static const char *const face[6] = {"xLo", "xHi", "yLo", "yHi", "zLo", "zHi"};
    const mpm_grid_desc *g = &sc->c.grid;
    uint32_t mask[6];
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
            return EINV("boundary.%s: mask %u has bits other than 1 (x), 2 (y), 4 (z)", face[f], mask[f]);
        if (mask[f] && f / 2 >= g->dim)
            return EINV("boundary.%s: the grid has no axis %d (dim %d)", face[f], f / 2, g->dim);
        sc->c.bc.face_mask[f] = mask[f];
    }
    n = bd->n_nodes;
    if (n == 0) return 0;
    if (n > SRV_CASE_MAX_NODE_FIXES)
        return bad(err, errlen, SRV_CODEC_ETOOBIG, "boundary.nodes: %zu, more than the limit of %u", n,
                   SRV_CASE_MAX_NODE_FIXES);
    sc->node_ijk = calloc(n * 3, sizeof *sc->node_ijk);
    sc->node_mask = calloc(n, sizeof *sc->node_mask);
    if (!sc->node_ijk || !sc->node_mask) return ENOMEM_();
    for (size_t i = 0; i < n; i++) {
        const Mpmd__NodeFix *nf = bd->nodes[i];
        if (nf->n_ijk != (size_t)g->dim)
            return EINV("boundary.nodes[%zu].ijk: expected %d indices (one per axis), got %zu", i, g->dim,
                        nf->n_ijk);
        for (int d = 0; d < g->dim; d++) {
            if (nf->ijk[d] >= (uint32_t)g->nodes[d])
                return EINV("boundary.nodes[%zu].ijk[%d]: %u is outside the grid (nodes[%d] = %d)", i, d,
                            nf->ijk[d], d, g->nodes[d]);
            sc->node_ijk[3 * i + (size_t)d] = (int)nf->ijk[d];
        }
        if (nf->mask > 7)
            return EINV("boundary.nodes[%zu].mask: %u has bits other than 1 (x), 2 (y), 4 (z)", i, nf->mask);
        sc->node_mask[i] = nf->mask;
    }
    sc->c.bc.n_nodes = n;
    sc->c.bc.node_ijk = sc->node_ijk;
    sc->c.bc.node_mask = sc->node_mask;
    return 0;
}

static int conv_run(const Mpmd__Case *pb, srv_case *sc, char *err, size_t errlen)
{
    const Mpmd__Output *o = pb->output;
    switch (pb->stop_case) {
    case MPMD__CASE__STOP_END_TIME:
        if (!isfinite(pb->end_time) || !(pb->end_time > 0))
            return EINV("endTime: must be > 0 (got %g)", pb->end_time);
        sc->has_end_time = 1;
        sc->end_time = pb->end_time;
        break;
    case MPMD__CASE__STOP_STEPS:
        if (pb->steps < 1 || pb->steps > SRV_CASE_MAX_STEPS)
            return EINV("steps: must be 1..%lld (got %lld)", (long long)SRV_CASE_MAX_STEPS,
                        (long long)pb->steps);
        sc->steps = pb->steps;
        break;
    default:
        return EINV("endTime: missing (a case needs endTime or steps)");
    }
    if (pb->has_threads && pb->threads > MPM_MAX_THREADS)
        return EINV("threads: must be 0..%d (got %u)", MPM_MAX_THREADS, pb->threads);
    sc->c.threads = pb->has_threads ? (int)pb->threads : 0;
    sc->snapshot_fields = SRV_SNAP_ALL;
    if (!o) return 0;
    sc->energy_every = o->has_energy_every ? o->energy_every : 0;
    sc->snapshot_every = o->has_snapshot_every ? o->snapshot_every : 0;
    sc->record_snapshots = o->has_record_snapshots && o->record_snapshots;
    if (o->n_snapshot_fields) sc->snapshot_fields = 0;
    for (size_t i = 0; i < o->n_snapshot_fields; i++) {
        switch (o->snapshot_fields[i]) {
        case MPMD__OUTPUT__FIELD__X: sc->snapshot_fields |= SRV_SNAP_X; break;
        case MPMD__OUTPUT__FIELD__V: sc->snapshot_fields |= SRV_SNAP_V; break;
        case MPMD__OUTPUT__FIELD__STRESS: sc->snapshot_fields |= SRV_SNAP_STRESS; break;
        case MPMD__OUTPUT__FIELD__PRESSURE: sc->snapshot_fields |= SRV_SNAP_PRESSURE; break;
        case MPMD__OUTPUT__FIELD__VOLUME: sc->snapshot_fields |= SRV_SNAP_VOLUME; break;
        default:
            return EINV("output.snapshotFields[%zu]: unknown value %d", i, (int)o->snapshot_fields[i]);
        }
    }
    return 0;
}

static int conv_case(const Mpmd__Case *pb, srv_case *sc, char *err, size_t errlen)
{
    mpm_case *c = &sc->c;
    const char *name = pb->name ? pb->name : "";
    size_t nl = strlen(name);
    int rc;
    if (!srv_json_utf8_valid(name)) return EINV("name: not valid UTF-8");
    sc->name = malloc(nl + 1);
    if (!sc->name) return ENOMEM_();
    memcpy(sc->name, name, nl + 1);

    if ((rc = conv_grid(pb->grid, sc, err, errlen))) return rc;
    switch (pb->method) {
    case MPMD__CASE__METHOD__MPM: c->method = MPM_METHOD_MPM; break;
    case MPMD__CASE__METHOD__GIMP: c->method = MPM_METHOD_GIMP; break;
    default: return EINV("method: unknown value %d", (int)pb->method);
    }
    switch (pb->update) {
    case MPMD__CASE__UPDATE__USF: c->update = MPM_USF; break;
    case MPMD__CASE__UPDATE__USL: c->update = MPM_USL; break;
    case MPMD__CASE__UPDATE__MUSL: c->update = MPM_MUSL; break;
    default: return EINV("update: unknown value %d", (int)pb->update);
    }
    if (pb->has_dt && (!isfinite(pb->dt) || pb->dt < 0))
        return EINV("dt: must be >= 0 (0: automatic; got %g)", pb->dt);
    if (pb->has_cfl && (!isfinite(pb->cfl) || pb->cfl < 0))
        return EINV("cfl: must be >= 0 (0: default; got %g)", pb->cfl);
    if (pb->has_mass_tol && (!isfinite(pb->mass_tol) || pb->mass_tol < 0))
        return EINV("massTol: must be >= 0 (0: default; got %g)", pb->mass_tol);
    c->dt = pb->has_dt ? pb->dt : 0;
    c->cfl = pb->has_cfl ? pb->cfl : 0;
    c->mass_tol = pb->has_mass_tol ? pb->mass_tol : 0;
    c->allow_unstable_dt = pb->has_allow_unstable_dt && pb->allow_unstable_dt;
    if ((rc = get_vec("gravity", pb->gravity, pb->n_gravity, c->grid.dim, 1, c->gravity, err, errlen)))
        return rc;
    if ((rc = conv_materials(pb, sc, err, errlen))) return rc;
    if ((rc = conv_bodies(pb, sc, err, errlen))) return rc;
    if ((rc = conv_tractions(pb, sc, err, errlen))) return rc;
    if ((rc = conv_boundary(pb->boundary, sc, err, errlen))) return rc;
    return conv_run(pb, sc, err, errlen);
}

int srv_case_from_pb(const Mpmd__Case *pb, srv_case **out, char *err, size_t errlen)
{
    srv_case *sc;
    int rc;
    *out = NULL;
    if (err && errlen) err[0] = 0;
    if (!pb) return EINV("case: missing");
    sc = calloc(1, sizeof *sc);
    if (!sc) return ENOMEM_();
    rc = conv_case(pb, sc, err, errlen);
    if (!rc) {
        mpm_error me;
        switch (mpm_case_check(&sc->c, &sc->info, &me)) {
        case MPM_OK: break;
        case MPM_ECFL: rc = SRV_CODEC_ECFL; break;
        case MPM_ENOMEM: rc = SRV_CODEC_ENOMEM; break;
        case MPM_ETOOBIG: rc = SRV_CODEC_ETOOBIG; break;
        default: rc = SRV_CODEC_EINVAL; break;
        }
        if (rc && err && errlen) camel_error_path(mpm_error_text(&me, MPM_FIELD_PROTO, err, errlen));
    }
    if (rc) {
        srv_case_destroy(&sc);
        return rc;
    }
    *out = sc;
    return 0;
}

int srv_case_load(const char *json, size_t len, srv_case **out, char *err, size_t errlen)
{
    Mpmd__Case *pb;
    int rc = srv_case_from_json(json, len, &pb, err, errlen);
    *out = NULL;
    if (rc) return rc;
    rc = srv_case_from_pb(pb, out, err, errlen);
    srv_case_pb_free(&pb);
    return rc;
}

void srv_case_destroy(srv_case **scp)
{
    srv_case *sc;
    if (!scp || !*scp) return;
    sc = *scp;
    if (sc->point_blocks)
        for (size_t i = 0; i < sc->c.n_bodies; i++) free(sc->point_blocks[i]);
    free(sc->point_blocks);
    free(sc->bodies);
    free(sc->materials);
    free(sc->tractions);
    free(sc->node_ijk);
    free(sc->node_mask);
    free(sc->name);
    free(sc);
    *scp = NULL;
}

/* ------------------------------------------------------------------------ */
/* Envelopes                                                                */

static const char *const status_names[] = {
    NULL, "QUEUED", "RUNNING", "FINISHED", "FAILED", "CANCELLED", "INTERRUPTED"};

const char *srv_status_name(int status)
{
    if (status < 1 || status > SRV_STATUS_INTERRUPTED) return NULL;
    return status_names[status];
}

int srv_status_from_name(const char *name)
{
    for (int s = 1; s <= SRV_STATUS_INTERRUPTED; s++)
        if (name && !strcmp(name, status_names[s])) return s;
    return 0;
}

/* Request body: the id field of a body, which must be present. */
#define NEED_ID(body, field, path)                                        \
    do {                                                                  \
        if (!r->body->has_##field) {                                      \
            rc = EINV(path ": missing");                                  \
            goto out;                                                     \
        }                                                                 \
        rq->id = r->body->field;                                          \
    } while (0)

int srv_request_decode(const void *buf, size_t len, size_t max, srv_request *rq,
                       char *err, size_t errlen)
{
    ProtobufCMessage *m;
    Mpmd__Request *r;
    int rc;
    memset(rq, 0, sizeof *rq);
    rc = unpack_msg(&mpmd__request__descriptor, buf, len, max, &m, err, errlen);
    if (rc) return rc;
    r = (Mpmd__Request *)m;
    rq->schema_version = r->has_schema_version ? r->schema_version : 0;
    if (rq->schema_version != SRV_SCHEMA_VERSION) {
        rc = bad(err, errlen, SRV_CODEC_EVERSION, "schemaVersion: %s%u; this server speaks %d",
                 r->has_schema_version ? "" : "missing, taken as ", rq->schema_version,
                 SRV_SCHEMA_VERSION);
        goto out;
    }
    switch (r->body_case) {
    case MPMD__REQUEST__BODY_SUBMIT:
        rq->kind = SRV_REQ_SUBMIT;
        if (!r->submit->case_) {
            rc = EINV("submit.case: missing");
            goto out;
        }
        rq->case_pb = r->submit->case_;
        r->submit->case_ = NULL;
        break;
    case MPMD__REQUEST__BODY_CANCEL:
        rq->kind = SRV_REQ_CANCEL;
        NEED_ID(cancel, job_id, "cancel.jobId");
        break;
    case MPMD__REQUEST__BODY_STATUS:
        rq->kind = SRV_REQ_STATUS;
        NEED_ID(status, job_id, "status.jobId");
        break;
    case MPMD__REQUEST__BODY_LIST_RUNS:
        rq->kind = SRV_REQ_LIST_RUNS;
        if (r->list_runs->has_status) {
            if (!srv_status_name(r->list_runs->status)) {
                rc = EINV("listRuns.status: unknown value %d", (int)r->list_runs->status);
                goto out;
            }
            rq->status = r->list_runs->status;
        }
        rq->limit = r->list_runs->has_limit ? r->list_runs->limit : 0;
        break;
    case MPMD__REQUEST__BODY_GET_RUN:
        rq->kind = SRV_REQ_GET_RUN;
        NEED_ID(get_run, run_id, "getRun.runId");
        rq->with_case = r->get_run->has_with_case && r->get_run->with_case;
        break;
    case MPMD__REQUEST__BODY_GET_ENERGY:
        rq->kind = SRV_REQ_GET_ENERGY;
        NEED_ID(get_energy, run_id, "getEnergy.runId");
        rq->from_seq = r->get_energy->has_from_seq ? r->get_energy->from_seq : 0;
        rq->limit = r->get_energy->has_limit ? r->get_energy->limit : 0;
        break;
    case MPMD__REQUEST__BODY_GET_SNAPSHOT:
        rq->kind = SRV_REQ_GET_SNAPSHOT;
        NEED_ID(get_snapshot, run_id, "getSnapshot.runId");
        rq->has_step = r->get_snapshot->has_step;
        rq->step = r->get_snapshot->has_step ? r->get_snapshot->step : 0;
        break;
    case MPMD__REQUEST__BODY_PING: rq->kind = SRV_REQ_PING; break;
    case MPMD__REQUEST__BODY_VERSION: rq->kind = SRV_REQ_VERSION; break;
    default:
        rc = EINV("request: no body (one of submit, cancel, status, listRuns, getRun, "
                  "getEnergy, getSnapshot, ping, version)");
        break;
    }
out:
    protobuf_c_message_free_unpacked(m, NULL);
    return rc;
}
#undef NEED_ID

void srv_request_clear(srv_request *rq)
{
    if (!rq) return;
    srv_case_pb_free(&rq->case_pb);
    memset(rq, 0, sizeof *rq);
}

static void fill_energy(Mpmd__EnergySample *es, const srv_energy_sample *s)
{
    mpmd__energy_sample__init(es);
    es->has_step = es->has_t = es->has_kinetic = es->has_strain = 1;
    es->has_potential = es->has_external_work = es->has_total = es->has_mass = 1;
    es->has_seq = 1;
    es->step = s->step;
    es->t = s->t;
    es->kinetic = s->e.kinetic;
    es->strain = s->e.strain;
    es->potential = s->e.potential;
    es->external_work = s->e.external_work;
    es->total = s->e.total;
    es->mass = s->e.mass;
    es->seq = s->seq;
    es->n_momentum = s->dim < 0 ? 0 : s->dim > MPM_MAX_DIM ? MPM_MAX_DIM : (size_t)s->dim;
    es->momentum = (double *)s->e.momentum;
}

static void fill_snapshot(Mpmd__Snapshot *ps, const srv_snapshot *s)
{
    size_t nd = s->n * (size_t)(s->dim > 0 ? s->dim : 0);
    mpmd__snapshot__init(ps);
    ps->has_step = ps->has_t = ps->has_n = ps->has_dim = 1;
    ps->step = s->step;
    ps->t = s->t;
    ps->n = s->n;
    ps->dim = (uint32_t)(s->dim > 0 ? s->dim : 0);
    ps->n_x = s->x ? nd : 0;
    ps->x = (double *)s->x;
    ps->n_v = s->v ? nd : 0;
    ps->v = (double *)s->v;
    ps->n_stress = s->stress ? 6 * s->n : 0;
    ps->stress = (double *)s->stress;
    ps->n_pressure = s->pressure ? s->n : 0;
    ps->pressure = (double *)s->pressure;
    ps->n_volume = s->volume ? s->n : 0;
    ps->volume = (double *)s->volume;
}

/* Fills ri into pi (es: storage for its last energy).  Unpacks the case
 * bytes into pi->case_ (free with protobuf_c_message_free_unpacked). */
static int fill_run(Mpmd__RunInfo *pi, Mpmd__EnergySample *es, const srv_run_info *ri)
{
    mpmd__run_info__init(pi);
    pi->has_run_id = pi->has_job_id = pi->has_status = 1;
    pi->has_steps = pi->has_steps_total = pi->has_t = pi->has_wall_s = 1;
    pi->has_particles = pi->has_nodes = pi->has_dim = pi->has_energy_samples = 1;
    pi->run_id = ri->run_id;
    pi->job_id = ri->job_id;
    pi->name = (char *)ri->name;
    pi->status = (Mpmd__RunStatus)ri->status;
    pi->error = (char *)ri->error;
    pi->has_submitted_at = ri->submitted_at > 0;
    pi->submitted_at = ri->submitted_at;
    pi->has_started_at = ri->started_at > 0;
    pi->started_at = ri->started_at;
    pi->has_finished_at = ri->finished_at > 0;
    pi->finished_at = ri->finished_at;
    pi->steps = ri->steps;
    pi->steps_total = ri->steps_total;
    pi->t = ri->t;
    pi->wall_s = ri->wall_s;
    pi->particles = ri->particles;
    pi->nodes = ri->nodes;
    pi->dim = (uint32_t)(ri->dim > 0 ? ri->dim : 0);
    if (ri->last_energy) {
        fill_energy(es, ri->last_energy);
        pi->last_energy = es;
    }
    pi->energy_samples = ri->energy_samples;
    pi->n_snapshot_steps = ri->snapshot_steps ? ri->n_snapshot_steps : 0;
    pi->snapshot_steps = (int64_t *)ri->snapshot_steps;
    pi->has_method = pi->has_update = 1;
    pi->method = (Mpmd__Case__Method)ri->method;
    pi->update = (Mpmd__Case__Update)ri->update;
    if (ri->case_bytes) {
        ProtobufCMessage *cm;
        if (unpack_msg(&mpmd__case__descriptor, ri->case_bytes, ri->case_len, (size_t)-1, &cm, NULL, 0))
            return SRV_CODEC_ESYNTAX;
        pi->case_ = (Mpmd__Case *)cm;
        /* what the run used, also for a case stored without the two fields
         * under other defaults */
        pi->case_->has_method = pi->case_->has_update = 1;
        pi->case_->method = pi->method;
        pi->case_->update = pi->update;
    }
    return 0;
}

static int pack_reply(Mpmd__Reply *r, uint8_t **buf, size_t *len)
{
    r->has_schema_version = 1;
    r->schema_version = SRV_SCHEMA_VERSION;
    return pack_msg(&r->base, buf, len);
}

int srv_reply_error(int code, const char *message, const char *field, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__Error e = MPMD__ERROR__INIT;
    e.has_code = 1;
    e.code = (Mpmd__Error__Code)code;
    e.message = (char *)message;
    e.field = (char *)field;
    r.body_case = MPMD__REPLY__BODY_ERROR;
    r.error = &e;
    return pack_reply(&r, buf, len);
}

int srv_reply_submit_ok(uint64_t job_id, uint64_t run_id, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__SubmitOk s = MPMD__SUBMIT_OK__INIT;
    s.has_job_id = s.has_run_id = 1;
    s.job_id = job_id;
    s.run_id = run_id;
    r.body_case = MPMD__REPLY__BODY_SUBMIT_OK;
    r.submit_ok = &s;
    return pack_reply(&r, buf, len);
}

int srv_reply_run(const srv_run_info *ri, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__RunInfo pi;
    Mpmd__EnergySample es;
    int rc = fill_run(&pi, &es, ri);
    *buf = NULL;
    *len = 0;
    if (!rc) {
        r.body_case = MPMD__REPLY__BODY_RUN;
        r.run = &pi;
        rc = pack_reply(&r, buf, len);
    }
    if (pi.case_) protobuf_c_message_free_unpacked(&pi.case_->base, NULL);
    return rc;
}

int srv_reply_runs(const srv_run_info *ri, size_t n, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__RunList rl = MPMD__RUN_LIST__INIT;
    Mpmd__RunInfo *pis = calloc(n ? n : 1, sizeof *pis);
    Mpmd__RunInfo **ptrs = calloc(n ? n : 1, sizeof *ptrs);
    Mpmd__EnergySample *ess = calloc(n ? n : 1, sizeof *ess);
    size_t filled = 0;
    int rc = 0;
    *buf = NULL;
    *len = 0;
    if (!pis || !ptrs || !ess) rc = SRV_CODEC_ENOMEM;
    for (; !rc && filled < n; filled++) {
        rc = fill_run(&pis[filled], &ess[filled], &ri[filled]);
        ptrs[filled] = &pis[filled];
    }
    if (!rc) {
        rl.n_runs = n;
        rl.runs = ptrs;
        r.body_case = MPMD__REPLY__BODY_RUNS;
        r.runs = &rl;
        rc = pack_reply(&r, buf, len);
    }
    for (size_t i = 0; pis && i < filled; i++)
        if (pis[i].case_) protobuf_c_message_free_unpacked(&pis[i].case_->base, NULL);
    free(pis);
    free(ptrs);
    free(ess);
    return rc;
}

int srv_reply_energy(uint64_t run_id, const srv_energy_sample *s, size_t n, int more,
                     uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__EnergySeries es = MPMD__ENERGY_SERIES__INIT;
    Mpmd__EnergySample *smp = calloc(n ? n : 1, sizeof *smp);
    Mpmd__EnergySample **ptrs = calloc(n ? n : 1, sizeof *ptrs);
    int rc;
    *buf = NULL;
    *len = 0;
    if (!smp || !ptrs) {
        free(smp);
        free(ptrs);
        return SRV_CODEC_ENOMEM;
    }
    for (size_t i = 0; i < n; i++) {
        fill_energy(&smp[i], &s[i]);
        ptrs[i] = &smp[i];
    }
    es.has_run_id = es.has_more = 1;
    es.run_id = run_id;
    es.more = more != 0;
    es.n_samples = n;
    es.samples = ptrs;
    r.body_case = MPMD__REPLY__BODY_ENERGY;
    r.energy = &es;
    rc = pack_reply(&r, buf, len);
    free(smp);
    free(ptrs);
    return rc;
}

int srv_reply_snapshot(const srv_snapshot *s, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__Snapshot ps;
    fill_snapshot(&ps, s);
    r.body_case = MPMD__REPLY__BODY_SNAPSHOT;
    r.snapshot = &ps;
    return pack_reply(&r, buf, len);
}

int srv_reply_pong(const char *server_version, const char *stream_endpoint, uint8_t **buf,
                   size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__Pong p = MPMD__PONG__INIT;
    p.server_version = (char *)server_version;
    p.stream_endpoint = (char *)stream_endpoint;
    p.has_schema_version = 1;
    p.schema_version = SRV_SCHEMA_VERSION;
    r.body_case = MPMD__REPLY__BODY_PONG;
    r.pong = &p;
    return pack_reply(&r, buf, len);
}

int srv_reply_version(const char *server_version, const char *const *names,
                      const char *const *versions, size_t n, uint8_t **buf, size_t *len)
{
    Mpmd__Reply r = MPMD__REPLY__INIT;
    Mpmd__VersionInfo vi = MPMD__VERSION_INFO__INIT;
    Mpmd__VersionInfo__Component *cs = calloc(n ? n : 1, sizeof *cs);
    Mpmd__VersionInfo__Component **ptrs = calloc(n ? n : 1, sizeof *ptrs);
    int rc;
    *buf = NULL;
    *len = 0;
    if (!cs || !ptrs) {
        free(cs);
        free(ptrs);
        return SRV_CODEC_ENOMEM;
    }
    for (size_t i = 0; i < n; i++) {
        mpmd__version_info__component__init(&cs[i]);
        cs[i].name = (char *)names[i];
        cs[i].version = (char *)versions[i];
        ptrs[i] = &cs[i];
    }
    vi.server_version = (char *)server_version;
    vi.has_schema_version = 1;
    vi.schema_version = SRV_SCHEMA_VERSION;
    vi.n_components = n;
    vi.components = ptrs;
    r.body_case = MPMD__REPLY__BODY_VERSION;
    r.version = &vi;
    rc = pack_reply(&r, buf, len);
    free(cs);
    free(ptrs);
    return rc;
}

static int pack_stream(Mpmd__StreamMsg *m, uint64_t job_id, uint64_t seq, uint8_t **buf, size_t *len)
{
    m->has_job_id = m->has_seq = 1;
    m->job_id = job_id;
    m->seq = seq;
    return pack_msg(&m->base, buf, len);
}

int srv_stream_progress(uint64_t job_id, uint64_t seq, const srv_progress *p, uint8_t **buf,
                        size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__Progress pp = MPMD__PROGRESS__INIT;
    pp.has_step = pp.has_t = pp.has_dt = pp.has_steps_total = pp.has_wall_s = 1;
    pp.step = p->step;
    pp.t = p->t;
    pp.dt = p->dt;
    pp.steps_total = p->steps_total;
    pp.wall_s = p->wall_s;
    m.body_case = MPMD__STREAM_MSG__BODY_PROGRESS;
    m.progress = &pp;
    return pack_stream(&m, job_id, seq, buf, len);
}

int srv_stream_energy(uint64_t job_id, uint64_t seq, const srv_energy_sample *s, uint8_t **buf,
                      size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__EnergySample es;
    fill_energy(&es, s);
    m.body_case = MPMD__STREAM_MSG__BODY_ENERGY;
    m.energy = &es;
    return pack_stream(&m, job_id, seq, buf, len);
}

int srv_stream_snapshot(uint64_t job_id, uint64_t seq, const srv_snapshot *s, uint8_t **buf,
                        size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__Snapshot ps;
    fill_snapshot(&ps, s);
    m.body_case = MPMD__STREAM_MSG__BODY_SNAPSHOT;
    m.snapshot = &ps;
    return pack_stream(&m, job_id, seq, buf, len);
}

int srv_stream_finished(uint64_t job_id, uint64_t seq, const srv_finished *f, uint8_t **buf,
                        size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__Finished pf = MPMD__FINISHED__INIT;
    Mpmd__EnergySample es;
    pf.has_status = pf.has_steps = pf.has_t = pf.has_wall_s = 1;
    pf.status = (Mpmd__RunStatus)f->status;
    pf.error = (char *)f->error;
    pf.steps = f->steps;
    pf.t = f->t;
    pf.wall_s = f->wall_s;
    if (f->energy) {
        fill_energy(&es, f->energy);
        pf.energy = &es;
    }
    m.body_case = MPMD__STREAM_MSG__BODY_FINISHED;
    m.finished = &pf;
    return pack_stream(&m, job_id, seq, buf, len);
}

/* ------------------------------------------------------------------------ */
/* Request encoder (clients: mpmctl and the daemon tests)                   */

/* Appends a varint; returns the bytes written (at most 10). */
static size_t put_varint(uint8_t *p, uint64_t v)
{
    size_t k = 0;
    do {
        p[k++] = (uint8_t)((v & 0x7f) | (v > 0x7f ? 0x80 : 0));
        v >>= 7;
    } while (v);
    return k;
}

/* A Submit request around case bytes packed beforehand: Request {
 * schema_version, submit = Submit { case = <the bytes> } }, written
 * directly (the bytes are copied, not decoded). */
static int submit_bytes(uint32_t version, const void *cb, size_t cn, uint8_t **buf, size_t *len)
{
    const ProtobufCFieldDescriptor *fv =
        protobuf_c_message_descriptor_get_field_by_name(&mpmd__request__descriptor, "schema_version");
    const ProtobufCFieldDescriptor *fs =
        protobuf_c_message_descriptor_get_field_by_name(&mpmd__request__descriptor, "submit");
    const ProtobufCFieldDescriptor *fc =
        protobuf_c_message_descriptor_get_field_by_name(&mpmd__request__submit__descriptor, "case");
    uint8_t head[64], tmp[10];
    size_t h = 0, inner;
    if (!fv || !fs || !fc) return SRV_CODEC_EINVAL;
    h += put_varint(head + h, (uint64_t)fv->id << 3 | WT_VARINT);
    h += put_varint(head + h, version);
    inner = put_varint(tmp, (uint64_t)fc->id << 3 | WT_LEN) + put_varint(tmp, cn) + cn;
    h += put_varint(head + h, (uint64_t)fs->id << 3 | WT_LEN);
    h += put_varint(head + h, inner);
    h += put_varint(head + h, (uint64_t)fc->id << 3 | WT_LEN);
    h += put_varint(head + h, cn);
    if (cn > SIZE_MAX - h) return SRV_CODEC_ENOMEM;
    uint8_t *b = malloc(h + cn);
    if (!b) return SRV_CODEC_ENOMEM;
    memcpy(b, head, h);
    if (cn) memcpy(b + h, cb, cn);
    *buf = b;
    *len = h + cn;
    return 0;
}

int srv_request_encode(const srv_request *rq, uint8_t **buf, size_t *len)
{
    Mpmd__Request r = MPMD__REQUEST__INIT;
    Mpmd__Request__Submit sub = MPMD__REQUEST__SUBMIT__INIT;
    Mpmd__Request__Cancel can = MPMD__REQUEST__CANCEL__INIT;
    Mpmd__Request__Status sta = MPMD__REQUEST__STATUS__INIT;
    Mpmd__Request__ListRuns lr = MPMD__REQUEST__LIST_RUNS__INIT;
    Mpmd__Request__GetRun gr = MPMD__REQUEST__GET_RUN__INIT;
    Mpmd__Request__GetEnergy ge = MPMD__REQUEST__GET_ENERGY__INIT;
    Mpmd__Request__GetSnapshot gs = MPMD__REQUEST__GET_SNAPSHOT__INIT;
    Mpmd__Request__Ping pi = MPMD__REQUEST__PING__INIT;
    Mpmd__Request__Version ve = MPMD__REQUEST__VERSION__INIT;
    *buf = NULL;
    *len = 0;
    r.has_schema_version = 1;
    r.schema_version = rq->schema_version ? rq->schema_version : SRV_SCHEMA_VERSION;
    switch (rq->kind) {
    case SRV_REQ_SUBMIT:
        if (!rq->case_pb && rq->case_bytes)
            return submit_bytes(r.schema_version, rq->case_bytes, rq->case_len, buf, len);
        if (!rq->case_pb) return SRV_CODEC_EINVAL;
        sub.case_ = rq->case_pb;
        r.body_case = MPMD__REQUEST__BODY_SUBMIT;
        r.submit = &sub;
        break;
    case SRV_REQ_CANCEL:
        can.has_job_id = 1;
        can.job_id = rq->id;
        r.body_case = MPMD__REQUEST__BODY_CANCEL;
        r.cancel = &can;
        break;
    case SRV_REQ_STATUS:
        sta.has_job_id = 1;
        sta.job_id = rq->id;
        r.body_case = MPMD__REQUEST__BODY_STATUS;
        r.status = &sta;
        break;
    case SRV_REQ_LIST_RUNS:
        if (rq->status) {
            lr.has_status = 1;
            lr.status = (Mpmd__RunStatus)rq->status;
        }
        if (rq->limit) {
            lr.has_limit = 1;
            lr.limit = rq->limit;
        }
        r.body_case = MPMD__REQUEST__BODY_LIST_RUNS;
        r.list_runs = &lr;
        break;
    case SRV_REQ_GET_RUN:
        gr.has_run_id = 1;
        gr.run_id = rq->id;
        if (rq->with_case) gr.has_with_case = gr.with_case = 1;
        r.body_case = MPMD__REQUEST__BODY_GET_RUN;
        r.get_run = &gr;
        break;
    case SRV_REQ_GET_ENERGY:
        ge.has_run_id = 1;
        ge.run_id = rq->id;
        if (rq->from_seq) {
            ge.has_from_seq = 1;
            ge.from_seq = rq->from_seq;
        }
        if (rq->limit) {
            ge.has_limit = 1;
            ge.limit = rq->limit;
        }
        r.body_case = MPMD__REQUEST__BODY_GET_ENERGY;
        r.get_energy = &ge;
        break;
    case SRV_REQ_GET_SNAPSHOT:
        gs.has_run_id = 1;
        gs.run_id = rq->id;
        if (rq->has_step) {
            gs.has_step = 1;
            gs.step = rq->step;
        }
        r.body_case = MPMD__REQUEST__BODY_GET_SNAPSHOT;
        r.get_snapshot = &gs;
        break;
    case SRV_REQ_PING:
        r.body_case = MPMD__REQUEST__BODY_PING;
        r.ping = &pi;
        break;
    case SRV_REQ_VERSION:
        r.body_case = MPMD__REQUEST__BODY_VERSION;
        r.version = &ve;
        break;
    default:
        return SRV_CODEC_EINVAL;
    }
    return pack_msg(&r.base, buf, len);
}

const char *srv_codec_protobuf_c_version(void)
{
    return protobuf_c_version();
}

/* ------------------------------------------------------------------------ */
/* Decoding for clients: replies and stream messages into plain structs     */

_Static_assert((int)SRV_STREAM_PROGRESS == (int)MPMD__STREAM_MSG__BODY_PROGRESS &&
               (int)SRV_STREAM_ENERGY == (int)MPMD__STREAM_MSG__BODY_ENERGY &&
               (int)SRV_STREAM_SNAPSHOT == (int)MPMD__STREAM_MSG__BODY_SNAPSHOT &&
               (int)SRV_STREAM_FINISHED == (int)MPMD__STREAM_MSG__BODY_FINISHED,
               "srv_stream_kind must match the StreamMsg.body field numbers");
_Static_assert((int)SRV_REPLY_ERROR == (int)MPMD__REPLY__BODY_ERROR &&
               (int)SRV_REPLY_SUBMIT_OK == (int)MPMD__REPLY__BODY_SUBMIT_OK &&
               (int)SRV_REPLY_RUN == (int)MPMD__REPLY__BODY_RUN && (int)SRV_REPLY_RUNS == (int)MPMD__REPLY__BODY_RUNS &&
               (int)SRV_REPLY_ENERGY == (int)MPMD__REPLY__BODY_ENERGY &&
               (int)SRV_REPLY_SNAPSHOT == (int)MPMD__REPLY__BODY_SNAPSHOT &&
               (int)SRV_REPLY_PONG == (int)MPMD__REPLY__BODY_PONG &&
               (int)SRV_REPLY_VERSION == (int)MPMD__REPLY__BODY_VERSION,
               "srv_reply_kind must match the Reply.body field numbers");

/* The protobuf wire format, read just enough to find the fields of a
 * message without decoding its big arrays (wire types: WT_* above). */

typedef struct {
    uint32_t num;           /* field number */
    int wt;                 /* wire type */
    uint64_t v;             /* WT_VARINT, WT_I64, WT_I32: the value */
    const uint8_t *data;    /* WT_LEN: the payload */
    size_t len;
} wire_field;

static int wire_varint(const uint8_t **p, const uint8_t *end, uint64_t *v)
{
    uint64_t x = 0;
    for (int shift = 0; shift < 70; shift += 7) {
        if (*p >= end) return -1;
        uint8_t c = *(*p)++;
        if (shift == 63 && c > 1) return -1;  /* beyond 64 bits */
        x |= (uint64_t)(c & 0x7f) << shift;
        if (!(c & 0x80)) {
            *v = x;
            return 0;
        }
    }
    return -1;
}

/* The next field at *p (which must be < end); -1 when it is malformed. */
static int wire_next(const uint8_t **p, const uint8_t *end, wire_field *f)
{
    uint64_t tag, v = 0;
    if (wire_varint(p, end, &tag) || tag >> 3 == 0 || tag >> 3 > 0x1fffffff) return -1;
    f->num = (uint32_t)(tag >> 3);
    f->wt = (int)(tag & 7);
    f->data = NULL;
    f->len = 0;
    switch (f->wt) {
    case WT_VARINT:
        return wire_varint(p, end, &f->v);
    case WT_I64:
    case WT_I32: {
        size_t k = f->wt == WT_I64 ? 8 : 4;
        if ((size_t)(end - *p) < k) return -1;
        for (size_t i = 0; i < k; i++) v |= (uint64_t)(*p)[i] << (8 * i);
        *p += k;
        f->v = v;
        return 0;
    }
    case WT_LEN:
        if (wire_varint(p, end, &v) || v > (uint64_t)(end - *p)) return -1;
        f->data = *p;
        f->len = (size_t)v;
        *p += v;
        return 0;
    default:
        return -1;
    }
}

static double wire_double(uint64_t v)
{
    double d;
    memcpy(&d, &v, sizeof d);
    return d;
}

/* Adds the fields of one occurrence of a Snapshot message to *s (fields
 * that occur again override, arrays add up, as protobuf merges them). */
static int peek_snapshot(const uint8_t *p, size_t n, srv_snapshot_info *s)
{
    const uint8_t *end = p + n;
    size_t *count[10] = {[5] = &s->n_x, [6] = &s->n_v, [7] = &s->n_stress, [8] = &s->n_pressure,
                         [9] = &s->n_volume};
    wire_field f;
    while (p < end) {
        if (wire_next(&p, end, &f)) return -1;
        switch (f.num) {
        case 1:
        case 3:
        case 4:
            if (f.wt != WT_VARINT) return -1;
            if (f.num == 1) s->step = (int64_t)f.v;
            else if (f.num == 3) s->n = f.v;
            else s->dim = (uint32_t)f.v;
            break;
        case 2:
            if (f.wt != WT_I64) return -1;
            s->t = wire_double(f.v);
            break;
        case 5: case 6: case 7: case 8: case 9:
            if (f.wt == WT_LEN && f.len % 8 == 0) *count[f.num] += f.len / 8;  /* packed */
            else if (f.wt == WT_I64) *count[f.num] += 1;                          /* unpacked */
            else return -1;
            break;
        default:
            break;  /* unknown: skipped */
        }
    }
    return 0;
}

/* Walks the top level of a StreamMsg or Reply: ids (StreamMsg) or the
 * schema version (Reply), and which body comes last (the one a oneof
 * keeps).  A Snapshot body (snap_num) is read on the way: a run of its
 * occurrences merges, another body in between starts it afresh. */
static int peek_top(const uint8_t *p, size_t n, int stream, uint32_t snap_num, uint32_t *body,
                    uint64_t ids[2], int has[2], srv_snapshot_info *snap)
{
    const uint8_t *end = p + n;
    wire_field f;
    *body = 0;
    while (p < end) {
        if (wire_next(&p, end, &f)) return -1;
        if (stream ? f.num <= 2 : f.num == 1) {
            if (f.wt != WT_VARINT) return -1;
            ids[f.num - 1] = f.v;
            has[f.num - 1] = 1;
        } else if (f.num >= (stream ? 3u : 2u) && f.num <= (stream ? 6u : 9u)) {
            if (f.wt != WT_LEN) return -1;
            if (f.num == snap_num) {
                if (*body != snap_num) memset(snap, 0, sizeof *snap);
                if (peek_snapshot(f.data, f.len, snap)) return -1;
            }
            *body = f.num;
        }
    }
    return 0;
}

/* Copies a string into a fixed buffer (cut to fit). */
static void copy_str(char *dst, size_t cap, const char *src)
{
    snprintf(dst, cap, "%s", src ? src : "");
}

static void take_energy(srv_energy_sample *s, const Mpmd__EnergySample *e)
{
    memset(s, 0, sizeof *s);
    if (!e) return;
    s->step = e->step;
    s->t = e->t;
    s->e.kinetic = e->kinetic;
    s->e.strain = e->strain;
    s->e.potential = e->potential;
    s->e.external_work = e->external_work;
    s->e.total = e->total;
    s->e.mass = e->mass;
    s->dim = e->n_momentum > MPM_MAX_DIM ? MPM_MAX_DIM : (int)e->n_momentum;
    for (int d = 0; d < s->dim; d++) s->e.momentum[d] = e->momentum[d];
    s->seq = e->seq;
}

int srv_stream_peek(const void *buf, size_t len, srv_stream_info *out, char *err, size_t errlen)
{
    static const uint8_t empty[1];
    const uint8_t *b = buf ? buf : empty;
    uint64_t ids[2] = {0, 0};
    int has[2] = {0, 0};
    uint32_t body;
    memset(out, 0, sizeof *out);
    if (!buf) len = 0;
    if (peek_top(b, len, 1, MPMD__STREAM_MSG__BODY_SNAPSHOT, &body, ids, has, &out->snapshot))
        return bad(err, errlen, SRV_CODEC_ESYNTAX, "not a valid mpmd.StreamMsg message (%zu bytes)",
                   len);
    out->has_job_id = has[0];
    out->job_id = ids[0];
    out->has_seq = has[1];
    out->seq = ids[1];
    out->kind = (srv_stream_kind)body;
    if (body == 0 || body == MPMD__STREAM_MSG__BODY_SNAPSHOT) return 0;
    /* a small body: decoded in full, with protobuf-c's own checks */
    ProtobufCMessage *m;
    int rc = unpack_msg(&mpmd__stream_msg__descriptor, b, len, (size_t)-1, &m, err, errlen);
    if (rc) {
        memset(out, 0, sizeof *out);
        return rc;
    }
    const Mpmd__StreamMsg *sm = (const Mpmd__StreamMsg *)m;
    switch (sm->body_case) {
    case MPMD__STREAM_MSG__BODY_PROGRESS:
        out->progress.step = sm->progress->step;
        out->progress.t = sm->progress->t;
        out->progress.dt = sm->progress->dt;
        out->progress.steps_total = sm->progress->steps_total;
        out->progress.wall_s = sm->progress->wall_s;
        break;
    case MPMD__STREAM_MSG__BODY_ENERGY:
        take_energy(&out->energy, sm->energy);
        break;
    case MPMD__STREAM_MSG__BODY_FINISHED: {
        const Mpmd__Finished *f = sm->finished;
        out->status = f->has_status ? (int)f->status : 0;
        copy_str(out->error, sizeof out->error, f->error);
        out->steps = f->steps;
        out->t = f->t;
        out->wall_s = f->wall_s;
        out->has_energy = f->energy != NULL;
        take_energy(&out->energy, f->energy);
        break;
    }
    default:
        break;
    }
    protobuf_c_message_free_unpacked(m, NULL);
    return 0;
}

int srv_reply_peek(const void *buf, size_t len, srv_reply_info *out, char *err, size_t errlen)
{
    static const uint8_t empty[1];
    const uint8_t *b = buf ? buf : empty;
    uint64_t ids[2] = {0, 0};
    int has[2] = {0, 0};
    uint32_t body;
    memset(out, 0, sizeof *out);
    if (!buf) len = 0;
    if (peek_top(b, len, 0, MPMD__REPLY__BODY_SNAPSHOT, &body, ids, has, &out->snapshot))
        return bad(err, errlen, SRV_CODEC_ESYNTAX, "not a valid mpmd.Reply message (%zu bytes)", len);
    out->schema_version = (uint32_t)ids[0];
    out->kind = (srv_reply_kind)body;
    if (body == 0 || body == MPMD__REPLY__BODY_SNAPSHOT) return 0;
    ProtobufCMessage *m;
    int rc = unpack_msg(&mpmd__reply__descriptor, b, len, 0, &m, err, errlen);
    if (rc) {
        memset(out, 0, sizeof *out);
        return rc;
    }
    const Mpmd__Reply *r = (const Mpmd__Reply *)m;
    switch (r->body_case) {
    case MPMD__REPLY__BODY_ERROR:
        out->err_code = (int)r->error->code;  /* the schema's default when absent */
        copy_str(out->err_message, sizeof out->err_message, r->error->message);
        copy_str(out->err_field, sizeof out->err_field, r->error->field);
        break;
    case MPMD__REPLY__BODY_SUBMIT_OK:
        out->has_job_id = r->submit_ok->has_job_id;
        out->job_id = r->submit_ok->job_id;
        out->has_run_id = r->submit_ok->has_run_id;
        out->run_id = r->submit_ok->run_id;
        break;
    case MPMD__REPLY__BODY_RUN: {
        const Mpmd__RunInfo *ri = r->run;
        out->has_job_id = ri->has_job_id;
        out->job_id = ri->job_id;
        out->has_run_id = ri->has_run_id;
        out->run_id = ri->run_id;
        copy_str(out->name, sizeof out->name, ri->name);
        copy_str(out->run_error, sizeof out->run_error, ri->error);
        out->status = ri->has_status ? (int)ri->status : 0;
        out->steps = ri->steps;
        out->steps_total = ri->steps_total;
        out->t = ri->t;
        out->wall_s = ri->wall_s;
        out->particles = ri->particles;
        out->nodes = ri->nodes;
        out->energy_samples = ri->energy_samples;
        out->dim = (int)ri->dim;
        break;
    }
    case MPMD__REPLY__BODY_RUNS:
        out->n_runs = r->runs->n_runs;
        break;
    case MPMD__REPLY__BODY_ENERGY:
        out->has_run_id = r->energy->has_run_id;
        out->run_id = r->energy->run_id;
        out->n_samples = r->energy->n_samples;
        out->more = r->energy->has_more && r->energy->more;
        break;
    case MPMD__REPLY__BODY_PONG:
        copy_str(out->server_version, sizeof out->server_version, r->pong->server_version);
        copy_str(out->stream_endpoint, sizeof out->stream_endpoint, r->pong->stream_endpoint);
        out->server_schema = r->pong->schema_version;
        break;
    case MPMD__REPLY__BODY_VERSION:
        copy_str(out->server_version, sizeof out->server_version, r->version->server_version);
        out->server_schema = r->version->schema_version;
        out->n_components = r->version->n_components;
        break;
    default:
        break;
    }
    protobuf_c_message_free_unpacked(m, NULL);
    return 0;
}

int srv_reply_energy_decode(const void *buf, size_t len, size_t max, uint64_t *run_id,
                            srv_energy_sample **samples, size_t *n, int *more, char *err,
                            size_t errlen)
{
    ProtobufCMessage *m;
    *samples = NULL;
    *n = 0;
    *run_id = 0;
    *more = 0;
    int rc = unpack_msg(&mpmd__reply__descriptor, buf, len, max, &m, err, errlen);
    if (rc) return rc;
    const Mpmd__Reply *r = (const Mpmd__Reply *)m;
    if (r->body_case != MPMD__REPLY__BODY_ENERGY) {
        rc = EINV("not an energy series (reply body %d)", (int)r->body_case);
    } else {
        const Mpmd__EnergySeries *es = r->energy;
        *run_id = es->run_id;
        *more = es->has_more && es->more;
        if (es->n_samples) {
            *samples = malloc(es->n_samples * sizeof **samples);
            if (!*samples) {
                rc = ENOMEM_();
            } else {
                for (size_t i = 0; i < es->n_samples; i++) take_energy(&(*samples)[i], es->samples[i]);
                *n = es->n_samples;
            }
        }
    }
    protobuf_c_message_free_unpacked(m, NULL);
    return rc;
}

int srv_stream_snapshot_into(uint64_t job_id, uint64_t seq, const srv_snapshot *s, uint8_t *buf,
                             size_t cap, size_t *len)
{
    Mpmd__StreamMsg m = MPMD__STREAM_MSG__INIT;
    Mpmd__Snapshot ps;
    fill_snapshot(&ps, s);
    m.body_case = MPMD__STREAM_MSG__BODY_SNAPSHOT;
    m.snapshot = &ps;
    m.has_job_id = m.has_seq = 1;
    m.job_id = job_id;
    m.seq = seq;
    *len = protobuf_c_message_get_packed_size(&m.base);
    if (!buf || cap < *len) return SRV_CODEC_ETOOBIG;
    if (protobuf_c_message_pack(&m.base, buf) != *len) return SRV_CODEC_ENOMEM;
    return 0;
}
