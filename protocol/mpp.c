/*
 * mpp.c - the vocabulary of mpp.h (status and wire-code names, the one
 * MPM_E* -> Error.Code mapping, versions), checked against the generated
 * enums at compile time, and what the library's files share (mpp_internal.h):
 * pack / unpack with a size limit, any message as JSON <-> bytes, and the
 * EnergySample / Snapshot fills.
 */
#include "mpp_internal.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SAME(a, b) ((int)(a) == (int)(b))
_Static_assert(MPP_SCHEMA_VERSION == MPMD__SCHEMA_VERSION__SCHEMA_VERSION,
               "MPP_SCHEMA_VERSION must match proto/mpmd.proto");
_Static_assert(MPP_SCHEMA_MINOR == MPMD__SCHEMA_MINOR__SCHEMA_MINOR,
               "MPP_SCHEMA_MINOR must match proto/mpmd.proto");
_Static_assert(SAME(MPP_STATUS_QUEUED, MPMD__RUN_STATUS__QUEUED) &&
                   SAME(MPP_STATUS_RUNNING, MPMD__RUN_STATUS__RUNNING) &&
                   SAME(MPP_STATUS_FINISHED, MPMD__RUN_STATUS__FINISHED) &&
                   SAME(MPP_STATUS_FAILED, MPMD__RUN_STATUS__FAILED) &&
                   SAME(MPP_STATUS_CANCELLED, MPMD__RUN_STATUS__CANCELLED) &&
                   SAME(MPP_STATUS_INTERRUPTED, MPMD__RUN_STATUS__INTERRUPTED),
               "mpp_status must match mpmd.RunStatus");
_Static_assert(SAME(MPP_ERR_INTERNAL, MPMD__ERROR__CODE__INTERNAL) &&
                   SAME(MPP_ERR_BAD_REQUEST, MPMD__ERROR__CODE__BAD_REQUEST) &&
                   SAME(MPP_ERR_BAD_SCHEMA, MPMD__ERROR__CODE__BAD_SCHEMA) &&
                   SAME(MPP_ERR_INVALID_CASE, MPMD__ERROR__CODE__INVALID_CASE) &&
                   SAME(MPP_ERR_NOT_FOUND, MPMD__ERROR__CODE__NOT_FOUND) &&
                   SAME(MPP_ERR_QUEUE_FULL, MPMD__ERROR__CODE__QUEUE_FULL) &&
                   SAME(MPP_ERR_TOO_LARGE, MPMD__ERROR__CODE__TOO_LARGE) &&
                   SAME(MPP_ERR_CONFLICT, MPMD__ERROR__CODE__CONFLICT) &&
                   SAME(MPP_ERR_UNAVAILABLE, MPMD__ERROR__CODE__UNAVAILABLE) &&
                   SAME(MPP_ERR_FORBIDDEN, MPMD__ERROR__CODE__FORBIDDEN),
               "mpp_err_code must match mpmd.Error.Code");
_Static_assert(SAME(MPM_METHOD_MPM, MPMD__CASE__METHOD__MPM) &&
                   SAME(MPM_METHOD_GIMP, MPMD__CASE__METHOD__GIMP) &&
                   SAME(MPM_METHOD_BSPLINE2, MPMD__CASE__METHOD__BSPLINE2) &&
                   SAME(MPM_METHOD_BSPLINE3, MPMD__CASE__METHOD__BSPLINE3) &&
                   SAME(MPM_METHOD_CPDI, MPMD__CASE__METHOD__CPDI) &&
                   SAME(MPM_USF, MPMD__CASE__UPDATE__USF) &&
                   SAME(MPM_USL, MPMD__CASE__UPDATE__USL) &&
                   SAME(MPM_MUSL, MPMD__CASE__UPDATE__MUSL),
               "mpm_method / mpm_update must match mpmd.Case.Method / Update");
_Static_assert(SAME(MPM_VOLUME_STRAIN_INCREMENT, MPMD__CASE__VOLUME_UPDATE__STRAIN_INCREMENT) &&
                   SAME(MPM_VOLUME_DET_F, MPMD__CASE__VOLUME_UPDATE__DET_F) &&
                   SAME(MPM_VOLUME_CONSTANT, MPMD__CASE__VOLUME_UPDATE__CONSTANT) &&
                   SAME(MPM_MC_COMPRESSION, MPMD__MATERIAL__MC_MATCH__COMPRESSION) &&
                   SAME(MPM_MC_EXTENSION, MPMD__MATERIAL__MC_MATCH__EXTENSION) &&
                   SAME(MPM_MC_PLANE_STRAIN, MPMD__MATERIAL__MC_MATCH__PLANE_STRAIN),
               "mpm_volume_update / mpm_mc_match must match mpmd.Case.VolumeUpdate / "
               "Material.McMatch");
_Static_assert(SAME(MPM_TRANSFER_FLIP, MPMD__CASE__TRANSFER__FLIP) &&
                   SAME(MPM_TRANSFER_APIC, MPMD__CASE__TRANSFER__APIC),
               "mpm_transfer must match mpmd.Case.Transfer");
_Static_assert(SAME(MPM_KERNEL_FAMILY_FAST, MPMD__CASE__KERNEL_FAMILY__FAST) &&
                   SAME(MPM_KERNEL_FAMILY_REFERENCE, MPMD__CASE__KERNEL_FAMILY__REFERENCE),
               "mpm_kernel_family must match mpmd.Case.KernelFamily");
_Static_assert(SAME(MPP_STREAM_PROGRESS, MPMD__STREAM_MSG__BODY_PROGRESS) &&
                   SAME(MPP_STREAM_ENERGY, MPMD__STREAM_MSG__BODY_ENERGY) &&
                   SAME(MPP_STREAM_SNAPSHOT, MPMD__STREAM_MSG__BODY_SNAPSHOT) &&
                   SAME(MPP_STREAM_FINISHED, MPMD__STREAM_MSG__BODY_FINISHED),
               "mpp_stream_kind must match the StreamMsg.body field numbers");
_Static_assert(SAME(MPP_REPLY_ERROR, MPMD__REPLY__BODY_ERROR) &&
                   SAME(MPP_REPLY_SUBMIT_OK, MPMD__REPLY__BODY_SUBMIT_OK) &&
                   SAME(MPP_REPLY_RUN, MPMD__REPLY__BODY_RUN) &&
                   SAME(MPP_REPLY_RUNS, MPMD__REPLY__BODY_RUNS) &&
                   SAME(MPP_REPLY_ENERGY, MPMD__REPLY__BODY_ENERGY) &&
                   SAME(MPP_REPLY_SNAPSHOT, MPMD__REPLY__BODY_SNAPSHOT) &&
                   SAME(MPP_REPLY_PONG, MPMD__REPLY__BODY_PONG) &&
                   SAME(MPP_REPLY_VERSION, MPMD__REPLY__BODY_VERSION),
               "mpp_reply_kind must match the Reply.body field numbers");
#undef SAME

/* ---- names and the wire code ---------------------------------------------- */

/* The name of value v of an enum, from its descriptor. */
static const char *enum_name(const ProtobufCEnumDescriptor *d, int v)
{
    const ProtobufCEnumValue *ev = protobuf_c_enum_descriptor_get_value(d, v);
    return ev ? ev->name : NULL;
}

const char *mpp_status_name(int status)
{
    return enum_name(&mpmd__run_status__descriptor, status);
}

int mpp_status_from_name(const char *name)
{
    const ProtobufCEnumValue *ev =
        name ? protobuf_c_enum_descriptor_get_value_by_name(&mpmd__run_status__descriptor, name)
             : NULL;
    return ev ? ev->value : 0;
}

const char *mpp_err_code_name(int code)
{
    return enum_name(&mpmd__error__code__descriptor, code);
}

mpp_err_code mpp_error_wire_code(int mpm_code)
{
    switch (mpm_code) {
    case MPM_EINVAL:
    case MPM_ECFL: return MPP_ERR_INVALID_CASE;
    case MPM_EREQUEST:
    case MPM_ESYNTAX: return MPP_ERR_BAD_REQUEST;
    case MPM_EVERSION: return MPP_ERR_BAD_SCHEMA;
    case MPM_ENOTFOUND: return MPP_ERR_NOT_FOUND;
    case MPM_EFULL: return MPP_ERR_QUEUE_FULL;
    case MPM_ETOOBIG: return MPP_ERR_TOO_LARGE;
    case MPM_ECONFLICT: return MPP_ERR_CONFLICT;
    case MPM_EUNAVAIL: return MPP_ERR_UNAVAILABLE;
    case MPM_EFORBIDDEN: return MPP_ERR_FORBIDDEN;
    default: return MPP_ERR_INTERNAL;
    }
}

const char *mpp_protobuf_c_version(void)
{
    return protobuf_c_version();
}

/* ---- pack / unpack ----------------------------------------------------------- */

int mpp_pack(const ProtobufCMessage *m, uint8_t **buf, size_t *len)
{
    size_t n = protobuf_c_message_get_packed_size(m);
    uint8_t *b = malloc(n ? n : 1);
    *buf = NULL;
    *len = 0;
    if (!b) return MPM_ENOMEM;
    if (protobuf_c_message_pack(m, b) != n) {
        free(b);
        return MPM_ENOMEM;
    }
    *buf = b;
    *len = n;
    return 0;
}

/* The unpack's allocator: malloc, refused once the message has taken more
 * than its budget (so that crafted input - thousands of empty repeated
 * sub-messages, two bytes each on the wire, a hundred in memory - cannot
 * inflate memory); free is plain free(), so protobuf_c_message_free_unpacked
 * with the default allocator frees what it made. */
typedef struct {
    size_t used, budget;
    int exceeded;
} unpack_budget;

static void *budget_alloc(void *ud, size_t size)
{
    unpack_budget *b = ud;
    if (size > b->budget - b->used) {
        b->exceeded = 1;
        return NULL;
    }
    b->used += size;
    return malloc(size ? size : 1);
}

static void budget_free(void *ud, void *p)
{
    (void)ud;
    free(p);
}

size_t mpp_unpack_budget(size_t len)
{
    return len > (SIZE_MAX - MPP_UNPACK_FLOOR) / MPP_UNPACK_INFLATE
               ? SIZE_MAX
               : MPP_UNPACK_INFLATE * len + MPP_UNPACK_FLOOR;
}

/* A varint at p[*i] (len bytes in all) into *v; 0, or -1 when cut short. */
static int get_varint(const uint8_t *p, size_t len, size_t *i, uint64_t *v)
{
    *v = 0;
    for (int sh = 0; sh < 64; sh += 7) {
        if (*i >= len) return -1;
        uint8_t b = p[(*i)++];
        *v |= (uint64_t)(b & 0x7f) << sh;
        if (!(b & 0x80)) return 0;
    }
    return -1;
}

/* Messages nested deeper than this are not looked into for NULs (the
 * schema nests a few levels; protobuf-c has decoded them already). */
#define NUL_WALK_DEPTH 32

/* Whether a string field of message d (its wire bytes p, len), or of a
 * message inside it, holds a NUL byte: protobuf-c gives strings as C
 * strings, so "a\0b" would arrive as "a", silently cut.  Walks the wire
 * form after protobuf-c has accepted it.  0, or MPM_ESYNTAX (bytes this
 * decoder cannot represent) naming the field: its path from the message, or from the Case for a
 * field inside a case (the case checks' spelling: "name").  Guarded by daemon_names_nul_refused. */
static int strings_without_nul(const ProtobufCMessageDescriptor *d, const uint8_t *p, size_t len,
                               int depth, const char *path, mpm_error *err)
{
    size_t i = 0;
    while (i < len) {
        uint64_t key, v;
        if (get_varint(p, len, &i, &key)) return 0;
        switch (key & 7) {
        case 0:
            if (get_varint(p, len, &i, &v)) return 0;
            break;
        case 1: i += 8; break;
        case 5: i += 4; break;
        case 2: {
            if (get_varint(p, len, &i, &v) || v > len - i) return 0;
            const ProtobufCFieldDescriptor *f =
                key >> 3 <= UINT32_MAX
                    ? protobuf_c_message_descriptor_get_field(d, (unsigned)(key >> 3))
                    : NULL;
            char sub[MPM_PATH_MAX * MPM_PATH_NAME_MAX];
            if (f && (f->type == PROTOBUF_C_TYPE_STRING || f->type == PROTOBUF_C_TYPE_MESSAGE))
                snprintf(sub, sizeof sub, "%s%s%s", path, *path ? "." : "", f->name);
            const uint8_t *z = f && f->type == PROTOBUF_C_TYPE_STRING ? memchr(p + i, 0, v) : NULL;
            if (z)
                return mpm_fail(err, MPM_ESYNTAX, sub,
                                "contains a NUL character (\\u0000) at byte %zu: not allowed",
                                (size_t)(z - (p + i)));
            if (f && f->type == PROTOBUF_C_TYPE_MESSAGE && depth < NUL_WALK_DEPTH) {
                const ProtobufCMessageDescriptor *sd = f->descriptor;
                int rc = strings_without_nul(sd, p + i, (size_t)v, depth + 1,
                                             sd == &mpmd__case__descriptor ? "" : sub, err);
                if (rc) return rc;
            }
            i += (size_t)v;
            break;
        }
        default: return 0; /* groups: protobuf-c refuses them */
        }
    }
    return 0;
}

int mpp_unpack(const ProtobufCMessageDescriptor *d, const void *buf, size_t len, size_t max,
               ProtobufCMessage **out, mpm_error *err)
{
    static const uint8_t empty[1];
    *out = NULL;
    if (!max) max = MPP_MSG_MAX;
    if (len > max)
        return mpm_fail(err, MPM_ETOOBIG, NULL,
                        "%s message of %zu bytes: more than the limit of %zu", d->name, len, max);
    unpack_budget b = {0, mpp_unpack_budget(len), 0};
    ProtobufCAllocator a = {budget_alloc, budget_free, &b};
    *out = protobuf_c_message_unpack(d, &a, len, buf ? buf : empty);
    if (!*out && b.exceeded)
        return mpm_fail(err, MPM_ETOOBIG, NULL,
                        "%s message of %zu bytes: decoding it would take more than %zu bytes of "
                        "memory (%d times its size + %d)",
                        d->name, len, b.budget, MPP_UNPACK_INFLATE, MPP_UNPACK_FLOOR);
    if (!*out)
        return mpm_fail(err, MPM_ESYNTAX, NULL, "not a valid %s message (%zu bytes)", d->name, len);
    int rc = strings_without_nul(d, buf, len, 0, "", err);
    if (rc) {
        protobuf_c_message_free_unpacked(*out, &a);
        *out = NULL;
    }
    return rc;
}

static const ProtobufCMessageDescriptor *kind_desc(mpp_msg_kind kind)
{
    switch (kind) {
    case MPP_MSG_CASE: return &mpmd__case__descriptor;
    case MPP_MSG_REQUEST: return &mpmd__request__descriptor;
    case MPP_MSG_REPLY: return &mpmd__reply__descriptor;
    case MPP_MSG_STREAM: return &mpmd__stream_msg__descriptor;
    }
    return NULL;
}

int mpp_msg_json_to_bytes(mpp_msg_kind kind, const char *json, size_t len, uint8_t **buf, size_t *n,
                          mpm_error *err)
{
    const ProtobufCMessageDescriptor *d = kind_desc(kind);
    ProtobufCMessage *m;
    int rc;
    *buf = NULL;
    *n = 0;
    if (!d) return mpm_fail(err, MPM_EINVAL, NULL, "unknown message kind %d", (int)kind);
    rc = mpp_json_to_pb(d, json, len, &m, err);
    if (rc) return rc;
    rc = mpp_pack(m, buf, n);
    protobuf_c_message_free_unpacked(m, NULL);
    return rc ? mpm_fail(err, rc, NULL, "out of memory") : 0;
}

int mpp_msg_bytes_to_json(mpp_msg_kind kind, const void *buf, size_t n, size_t max, unsigned flags,
                          char **json, mpm_error *err)
{
    const ProtobufCMessageDescriptor *d = kind_desc(kind);
    ProtobufCMessage *m;
    int rc;
    *json = NULL;
    if (!d) return mpm_fail(err, MPM_EINVAL, NULL, "unknown message kind %d", (int)kind);
    rc = mpp_unpack(d, buf, n, max, &m, err);
    if (rc) return rc;
    rc = mpp_json_from_pb(m, flags, json, err);
    protobuf_c_message_free_unpacked(m, NULL);
    return rc;
}

/* ---- EnergySample and Snapshot ------------------------------------------------ */

void mpp_fill_energy(Mpmd__EnergySample *es, const mpm_energy_sample *s)
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
    /* 3D: x, y, z; 2D: z alone; 1D: none (see mpmd.proto) */
    es->n_angular_momentum = s->dim == 3 ? 3 : s->dim == 2 ? 1 : 0;
    es->angular_momentum =
        (double *)(s->dim == 2 ? &s->e.angular_momentum[2] : s->e.angular_momentum);
    /* sent when non-zero: absent reads 0, so a run without the features
     * sends the bytes an older daemon sent */
    es->has_plastic_work = s->e.plastic_work != 0;
    es->has_damping_work = s->e.damping_work != 0;
    es->has_friction_work = s->e.friction_work != 0;
    es->has_prescribed_work = s->e.prescribed_work != 0;
    es->has_balance_error = s->e.balance_error != 0;
    es->plastic_work = s->e.plastic_work;
    es->damping_work = s->e.damping_work;
    es->friction_work = s->e.friction_work;
    es->prescribed_work = s->e.prescribed_work;
    es->balance_error = s->e.balance_error;
}

void mpp_take_energy(mpm_energy_sample *s, const Mpmd__EnergySample *e)
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
    /* one entry: z (2D); otherwise x, y, z in order (extra entries ignored,
     * missing ones 0) */
    if (e->n_angular_momentum == 1)
        s->e.angular_momentum[2] = e->angular_momentum[0];
    else
        for (size_t d = 0; d < e->n_angular_momentum && d < 3; d++)
            s->e.angular_momentum[d] = e->angular_momentum[d];
    s->seq = e->seq;
    /* absent (an older daemon): 0 */
    s->e.plastic_work = e->plastic_work;
    s->e.damping_work = e->damping_work;
    s->e.friction_work = e->friction_work;
    s->e.prescribed_work = e->prescribed_work;
    s->e.balance_error = e->balance_error;
}

/* mpp_snapshot.yielded is protobuf-c's bool array as is */
_Static_assert(sizeof(protobuf_c_boolean) == sizeof(int), "protobuf_c_boolean must be an int");

void mpp_fill_snapshot(Mpmd__Snapshot *ps, const mpp_snapshot *s)
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
    ps->n_mean_stress = s->mean_stress ? s->n : 0;
    ps->mean_stress = (double *)s->mean_stress;
    ps->n_pressure = s->pressure ? s->n : 0;
    ps->pressure = (double *)s->pressure;
    ps->n_volume = s->volume ? s->n : 0;
    ps->volume = (double *)s->volume;
    ps->n_plastic_strain = s->plastic_strain ? s->n : 0;
    ps->plastic_strain = (double *)s->plastic_strain;
    ps->n_deformation_gradient = s->deformation_gradient ? nd * (size_t)ps->dim : 0;
    ps->deformation_gradient = (double *)s->deformation_gradient;
    ps->n_yielded = s->yielded ? s->n : 0;
    ps->yielded = (protobuf_c_boolean *)s->yielded;
}

void mpp_snapshot_pressure(const double *mean, size_t n, double *p)
{
    /* 0.0 - m, not -m: a zero mean stress gives +0 (no "-0" in outputs);
     * any other value is negated exactly */
    for (size_t i = 0; i < n; i++) p[i] = 0.0 - mean[i];
}

/* One of pressure and mean stress came without the other (a daemon before
 * schema 1.1 sends only the mean stress): the missing one, derived into an
 * array hung in the unpacked message, which frees it with the message (the
 * decoders free what they unpack with protobuf-c's default allocator, the
 * system's malloc/free, as mpp_unpack's allocator is). */
static int derive_pressure(Mpmd__Snapshot *ps, mpm_error *err)
{
    size_t *nto = ps->n_pressure ? &ps->n_mean_stress : &ps->n_pressure;
    double **to = ps->n_pressure ? &ps->mean_stress : &ps->pressure;
    const double *from = ps->n_pressure ? ps->pressure : ps->mean_stress;
    size_t n = ps->n_pressure ? ps->n_pressure : ps->n_mean_stress;
    if (!n || *nto) return 0;
    double *a = malloc(n * sizeof *a);
    if (!a) return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory for %zu pressures", n);
    mpp_snapshot_pressure(from, n, a);
    free(*to); /* an empty repeated field may still hold a pointer */
    *to = a;
    *nto = n;
    return 0;
}

int mpp_take_snapshot(mpp_snapshot *s, const Mpmd__Snapshot *ps, mpm_error *err)
{
    memset(s, 0, sizeof *s);
    if (!ps) return 0;
    s->step = ps->step;
    s->t = ps->t;
    s->n = (size_t)ps->n;
    s->dim = ps->dim <= MPM_MAX_DIM ? (int)ps->dim : 0;
    if ((ps->n_x || ps->n_v || ps->n_deformation_gradient) &&
        (ps->dim < 1 || ps->dim > MPM_MAX_DIM))
        return mpm_fail(err, MPM_ESYNTAX, "snapshot.dim",
                        "%u: must be 1, 2 or 3 with positions, velocities or F", ps->dim);
    const struct {
        const char *name;
        size_t have;
        uint64_t width;
        double *v;
        const double **dst;
    } a[] = {{"x", ps->n_x, ps->dim, ps->x, &s->x},
             {"v", ps->n_v, ps->dim, ps->v, &s->v},
             {"stress", ps->n_stress, 6, ps->stress, &s->stress},
             {"mean_stress", ps->n_mean_stress, 1, ps->mean_stress, &s->mean_stress},
             {"pressure", ps->n_pressure, 1, ps->pressure, &s->pressure},
             {"volume", ps->n_volume, 1, ps->volume, &s->volume},
             {"plastic_strain", ps->n_plastic_strain, 1, ps->plastic_strain, &s->plastic_strain},
             {"deformation_gradient", ps->n_deformation_gradient, (uint64_t)ps->dim * ps->dim,
              ps->deformation_gradient, &s->deformation_gradient}};
    for (size_t i = 0; i < sizeof a / sizeof a[0]; i++) {
        if (!a[i].have) continue;
        /* n * width without overflow: have / width == n exactly */
        if (a[i].have % a[i].width || a[i].have / a[i].width != ps->n)
            return mpm_fail(err, MPM_ESYNTAX, NULL,
                            "snapshot.%s holds %zu values, not n = %llu times %llu", a[i].name,
                            a[i].have, (unsigned long long)ps->n, (unsigned long long)a[i].width);
        *a[i].dst = a[i].v;
    }
    if ((s->pressure != NULL) != (s->mean_stress != NULL)) {
        int rc = derive_pressure((Mpmd__Snapshot *)(uintptr_t)ps, err);
        if (rc) return rc;
        s->pressure = ps->pressure;
        s->mean_stress = ps->mean_stress;
    }
    if (ps->n_yielded) {
        if (ps->n_yielded != ps->n)
            return mpm_fail(err, MPM_ESYNTAX, NULL,
                            "snapshot.yielded holds %zu values, not n = %llu", ps->n_yielded,
                            (unsigned long long)ps->n);
        s->yielded = ps->yielded;
    }
    return 0;
}
