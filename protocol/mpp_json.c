/*
 * mpp_json.c - JSON <-> protobuf-c messages by walking descriptors.
 *
 * Parsing goes through libjansson (duplicate keys rejected), then a
 * recursive walk over the JSON object and the ProtobufCMessageDescriptor of
 * the target type fills a message laid out exactly as protobuf-c's unpacker
 * would (malloc'd message, arrays and strings; has_ flags, n_ counts and
 * oneof case members set), so protobuf_c_message_free_unpacked() frees it,
 * even when an error stops the walk half-way.  A field path follows the
 * walk so every error (an mpm_error) names where it happened.  Printing writes the JSON
 * text directly into a growing buffer, so numbers keep the shortest exact
 * form and fields keep their .proto order.  The mapping rules are those of
 * the protobuf JSON mapping; see mpp_json.h for the details.
 */
#include "mpp_json.h"

#include <errno.h>
#include <float.h>
#include <inttypes.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jansson.h>

/* ------------------------------------------------------------------------ */
/* Walk context: the path of the current value (a structured mpm_error path:
 * one element per key, the index of an array element on its field's
 * element) and where an error goes.  Elements deeper than MPM_PATH_MAX are
 * counted, not kept.  Keys are kept as the input spelled them (a .proto
 * name when printing); mpm_error_field() renders them at the edge.         */

/* path_push_index() returns the old state with this bit, so that
 * path_pop() knows it undoes an index, not a key */
#define POP_INDEX ((size_t)1 << (sizeof(size_t) * 8 - 1))

typedef struct {
    mpm_error *err;
    mpm_path_elem path[MPM_PATH_MAX];
    int plen;  /* elements kept */
    int over;  /* elements beyond MPM_PATH_MAX */
    int depth; /* message nesting */
} jctx;

static void ctx_init(jctx *c, mpm_error *err)
{
    memset(c, 0, sizeof *c);
    c->err = err;
    mpm_error_clear(err);
}

/* Appends a key element; control characters are shown as '?', a long key
 * is cut.  Returns the old state for path_pop(). */
static size_t path_push_key(jctx *c, const char *key)
{
    size_t old = (size_t)(c->plen + c->over);
    if (c->plen >= MPM_PATH_MAX) {
        c->over++;
        return old;
    }
    mpm_path_elem *e = &c->path[c->plen++];
    size_t k = 0;
    for (; key[k] && k + 1 < sizeof e->name; k++) {
        unsigned char ch = (unsigned char)key[k];
        e->name[k] = (ch < 0x20 || ch == 0x7f) ? '?' : (char)ch;
    }
    e->name[k] = 0;
    e->index = -1;
    return old;
}

/* Sets the index of the innermost element (an array or map entry). */
static size_t path_push_index(jctx *c, size_t i)
{
    if (!c->over && c->plen) c->path[c->plen - 1].index = (long)i;
    return POP_INDEX;
}

static void path_pop(jctx *c, size_t old)
{
    if (old == POP_INDEX) {
        if (!c->over && c->plen) c->path[c->plen - 1].index = -1;
        return;
    }
    while ((size_t)(c->plen + c->over) > old) {
        if (c->over)
            c->over--;
        else
            c->plen--;
    }
}

/* Fills the error (code, message, the current path) and returns code. */
__attribute__((format(printf, 3, 4))) static int fail(jctx *c, int code, const char *fmt, ...)
{
    if (c->err) {
        char msg[MPM_ERROR_MSG_MAX];
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(msg, sizeof msg, fmt, ap);
        va_end(ap);
        mpm_fail(c->err, code, NULL, "%s", msg);
        c->err->depth = c->plen;
        memcpy(c->err->path, c->path, (size_t)c->plen * sizeof c->path[0]);
    }
    return code;
}

static int fail_nomem(jctx *c)
{
    return fail(c, MPM_ENOMEM, "out of memory");
}

/* A short description of a JSON value for error messages: "string \"ab\"",
 * "number 1.5", "object", ... */
static void describe(const json_t *v, char *buf, size_t len)
{
    switch (json_typeof(v)) {
    case JSON_OBJECT: snprintf(buf, len, "object"); break;
    case JSON_ARRAY: snprintf(buf, len, "array"); break;
    case JSON_INTEGER:
        snprintf(buf, len, "number %" JSON_INTEGER_FORMAT, json_integer_value(v));
        break;
    case JSON_REAL: snprintf(buf, len, "number %.17g", json_real_value(v)); break;
    case JSON_TRUE: snprintf(buf, len, "boolean true"); break;
    case JSON_FALSE: snprintf(buf, len, "boolean false"); break;
    case JSON_NULL: snprintf(buf, len, "null"); break;
    case JSON_STRING: {
        const char *s = json_string_value(v);
        size_t o = 0, k;
        o = (size_t)snprintf(buf, len, "string \"");
        for (k = 0; k < 40 && s[k] && o + 5 < len; k++) {
            unsigned char ch = (unsigned char)s[k];
            buf[o++] = (ch < 0x20 || ch == '"' || ch == '\\') ? '?' : (char)ch;
        }
        if (s[k] && o + 5 < len) {
            memcpy(buf + o, "...", 3);
            o += 3;
        }
        if (o + 1 < len) buf[o++] = '"';
        buf[o < len ? o : len - 1] = 0;
        break;
    }
    default: snprintf(buf, len, "value"); break;
    }
}

/* "expected <what>, got <value>" */
static int fail_type(jctx *c, const char *what, const json_t *v)
{
    char d[80];
    describe(v, d, sizeof d);
    return fail(c, MPM_EINVAL, "expected %s, got %s", what, d);
}

/* ------------------------------------------------------------------------ */
/* Names                                                                    */

size_t mpp_json_name(const char *proto_name, char *buf, size_t len)
{
    size_t n = 0;
    int up = 0;
    for (const char *p = proto_name; *p; p++) {
        char ch = *p;
        if (ch == '_') {
            up = 1;
            continue;
        }
        if (up && ch >= 'a' && ch <= 'z') ch = (char)(ch - 'a' + 'A');
        up = 0;
        if (n + 1 < len) buf[n] = ch;
        n++;
    }
    if (len) buf[n < len ? n : len - 1] = 0;
    return n;
}

/* Whether key is the JSON name of the .proto field name. */
static int is_json_name(const char *proto_name, const char *key)
{
    int up = 0;
    for (const char *p = proto_name; *p; p++) {
        char ch = *p;
        if (ch == '_') {
            up = 1;
            continue;
        }
        if (up && ch >= 'a' && ch <= 'z') ch = (char)(ch - 'a' + 'A');
        up = 0;
        if (*key++ != ch) return 0;
    }
    return *key == 0;
}

static int find_field(const ProtobufCMessageDescriptor *d, const char *key)
{
    for (unsigned i = 0; i < d->n_fields; i++)
        if (!strcmp(d->fields[i].name, key) || is_json_name(d->fields[i].name, key)) return (int)i;
    return -1;
}

static const ProtobufCFieldDescriptor *field_by_id(const ProtobufCMessageDescriptor *d, uint32_t id)
{
    for (unsigned i = 0; i < d->n_fields; i++)
        if (d->fields[i].id == id) return &d->fields[i];
    return NULL;
}

/* Appends the JSON names of the fields of d, comma-separated, to buf. */
static void list_fields(const ProtobufCMessageDescriptor *d, char *buf, size_t len)
{
    size_t o = strlen(buf);
    for (unsigned i = 0; i < d->n_fields && o + 1 < len; i++) {
        char name[96];
        mpp_json_name(d->fields[i].name, name, sizeof name);
        int n = snprintf(buf + o, len - o, "%s%s", i ? ", " : "", name);
        if (n < 0 || (size_t)n >= len - o) {
            if (len > 4) strcpy(buf + len - 4, "...");
            return;
        }
        o += (size_t)n;
    }
}

/* A map field: a repeated nested message <Field>Entry holding key = 1 and
 * value = 2, which is how protoc compiles `map<K, V> field`. */
static int is_map(const ProtobufCMessageDescriptor *parent, const ProtobufCFieldDescriptor *f)
{
    const ProtobufCMessageDescriptor *d = f->descriptor;
    char want[128];
    size_t pl, n;
    if (f->label != PROTOBUF_C_LABEL_REPEATED || f->type != PROTOBUF_C_TYPE_MESSAGE || !d) return 0;
    if (d->n_fields != 2 || d->fields[0].id != 1 || d->fields[1].id != 2 ||
        strcmp(d->fields[0].name, "key") || strcmp(d->fields[1].name, "value"))
        return 0;
    n = mpp_json_name(f->name, want, sizeof want);
    if (n + sizeof "Entry" > sizeof want) return 0;
    if (want[0] >= 'a' && want[0] <= 'z') want[0] = (char)(want[0] - 'a' + 'A');
    strcat(want, "Entry");
    if (strcmp(d->short_name, want)) return 0;
    pl = strlen(parent->name);
    return !strncmp(d->name, parent->name, pl) && d->name[pl] == '.' &&
           !strcmp(d->name + pl + 1, want);
}

/* ------------------------------------------------------------------------ */
/* Scalars                                                                  */

static size_t elem_size(ProtobufCType t)
{
    switch (t) {
    case PROTOBUF_C_TYPE_INT32:
    case PROTOBUF_C_TYPE_SINT32:
    case PROTOBUF_C_TYPE_SFIXED32:
    case PROTOBUF_C_TYPE_UINT32:
    case PROTOBUF_C_TYPE_FIXED32:
    case PROTOBUF_C_TYPE_ENUM: return 4;
    case PROTOBUF_C_TYPE_FLOAT: return sizeof(float);
    case PROTOBUF_C_TYPE_INT64:
    case PROTOBUF_C_TYPE_SINT64:
    case PROTOBUF_C_TYPE_SFIXED64:
    case PROTOBUF_C_TYPE_UINT64:
    case PROTOBUF_C_TYPE_FIXED64: return 8;
    case PROTOBUF_C_TYPE_DOUBLE: return sizeof(double);
    case PROTOBUF_C_TYPE_BOOL: return sizeof(protobuf_c_boolean);
    case PROTOBUF_C_TYPE_STRING: return sizeof(char *);
    case PROTOBUF_C_TYPE_BYTES: return sizeof(ProtobufCBinaryData);
    case PROTOBUF_C_TYPE_MESSAGE: return sizeof(ProtobufCMessage *);
    }
    return 0;
}

static int type_is_signed(ProtobufCType t)
{
    return t == PROTOBUF_C_TYPE_INT32 || t == PROTOBUF_C_TYPE_SINT32 ||
           t == PROTOBUF_C_TYPE_SFIXED32 || t == PROTOBUF_C_TYPE_INT64 ||
           t == PROTOBUF_C_TYPE_SINT64 || t == PROTOBUF_C_TYPE_SFIXED64;
}

static int type_is_32(ProtobufCType t)
{
    return t == PROTOBUF_C_TYPE_INT32 || t == PROTOBUF_C_TYPE_SINT32 ||
           t == PROTOBUF_C_TYPE_SFIXED32 || t == PROTOBUF_C_TYPE_UINT32 ||
           t == PROTOBUF_C_TYPE_FIXED32;
}

static const char *type_name(ProtobufCType t)
{
    switch (t) {
    case PROTOBUF_C_TYPE_INT32: return "int32";
    case PROTOBUF_C_TYPE_SINT32: return "sint32";
    case PROTOBUF_C_TYPE_SFIXED32: return "sfixed32";
    case PROTOBUF_C_TYPE_UINT32: return "uint32";
    case PROTOBUF_C_TYPE_FIXED32: return "fixed32";
    case PROTOBUF_C_TYPE_INT64: return "int64";
    case PROTOBUF_C_TYPE_SINT64: return "sint64";
    case PROTOBUF_C_TYPE_SFIXED64: return "sfixed64";
    case PROTOBUF_C_TYPE_UINT64: return "uint64";
    case PROTOBUF_C_TYPE_FIXED64: return "fixed64";
    default: return "integer";
    }
}

/* Whether s looks like a JSON number (so strtod's extras - "inf", "nan",
 * hex, leading spaces - are not accepted inside strings). */
static int numeric_text(const char *s)
{
    if (!((*s >= '0' && *s <= '9') || *s == '-' || *s == '.')) return 0;
    for (; *s; s++)
        if (!strchr("0123456789+-.eE", *s)) return 0;
    return 1;
}

/* Integral double -> int64/uint64.  0 ok, 1 not integral, 2 out of range. */
static int int_from_double(double x, int is_signed, int64_t *s, uint64_t *u)
{
    if (!isfinite(x) || floor(x) != x) return 1;
    if (is_signed) {
        if (x < -9223372036854775808.0 || x >= 9223372036854775808.0) return 2;
        *s = (int64_t)x;
    } else {
        if (x < 0 || x >= 18446744073709551616.0) return 2;
        *u = (uint64_t)x;
    }
    return 0;
}

/* Decimal integer text (or an integral number in exponent form) -> value.
 * 0 ok, 1 not an integer, 2 out of range. */
static int int_from_text(const char *t, int is_signed, int64_t *s, uint64_t *u)
{
    char *end;
    if (!numeric_text(t)) return 1;
    errno = 0;
    if (is_signed) {
        long long v = strtoll(t, &end, 10);
        if (end != t && !*end) {
            if (errno == ERANGE) return 2;
            *s = v;
            return 0;
        }
    } else if (t[0] != '-') {
        unsigned long long v = strtoull(t, &end, 10);
        if (end != t && !*end) {
            if (errno == ERANGE) return 2;
            *u = v;
            return 0;
        }
    }
    errno = 0;
    double x = strtod(t, &end);
    if (end == t || *end) return 1;
    return int_from_double(x, is_signed, s, u);
}

/* Reads an integer of protobuf type t (any integer type) into dst. */
static int parse_int(jctx *c, ProtobufCType t, const json_t *v, void *dst)
{
    int is_signed = type_is_signed(t), r;
    int64_t s = 0;
    uint64_t u = 0;
    if (json_is_integer(v)) {
        json_int_t x = json_integer_value(v);
        if (!is_signed && x < 0)
            return fail(c, MPM_EINVAL, "expected a non-negative integer, got %" JSON_INTEGER_FORMAT,
                        x);
        if (is_signed)
            s = x;
        else
            u = (uint64_t)x;
        r = 0;
    } else if (json_is_real(v)) {
        r = int_from_double(json_real_value(v), is_signed, &s, &u);
    } else if (json_is_string(v)) {
        r = int_from_text(json_string_value(v), is_signed, &s, &u);
    } else {
        return fail_type(c, "an integer", v);
    }
    if (r == 1) return fail_type(c, "an integer", v);
    if (r == 0 && type_is_32(t)) {
        if (is_signed && (s < INT32_MIN || s > INT32_MAX)) r = 2;
        if (!is_signed && u > UINT32_MAX) r = 2;
    }
    if (r == 2) {
        char d[80];
        describe(v, d, sizeof d);
        return fail(c, MPM_EINVAL, "%s out of range for %s", d, type_name(t));
    }
    if (type_is_32(t)) {
        if (is_signed)
            *(int32_t *)dst = (int32_t)s;
        else
            *(uint32_t *)dst = (uint32_t)u;
    } else {
        if (is_signed)
            *(int64_t *)dst = s;
        else
            *(uint64_t *)dst = u;
    }
    return 0;
}

int mpp_json_double_text(const char *s, double *out)
{
    char *end;
    if (!strcmp(s, "NaN")) {
        *out = NAN;
        return 0;
    }
    if (!strcmp(s, "Infinity")) {
        *out = INFINITY;
        return 0;
    }
    if (!strcmp(s, "-Infinity")) {
        *out = -INFINITY;
        return 0;
    }
    if (!numeric_text(s)) return MPM_ESYNTAX;
    errno = 0;
    double x = strtod(s, &end);
    if (end == s || *end) return MPM_ESYNTAX;
    if (errno == ERANGE && isinf(x)) return MPM_ETOOBIG;
    *out = x;
    return 0;
}

/* Reads a number (or "NaN", "Infinity", "-Infinity", numeric string). */
static int parse_double(jctx *c, const json_t *v, double *out)
{
    if (json_is_integer(v)) {
        *out = (double)json_integer_value(v);
        return 0;
    }
    if (json_is_real(v)) {
        *out = json_real_value(v);
        return 0;
    }
    if (json_is_string(v)) {
        const char *s = json_string_value(v);
        int rc = mpp_json_double_text(s, out);
        if (rc == MPM_ETOOBIG) return fail(c, MPM_EINVAL, "number \"%s\" out of range", s);
        if (!rc) return 0;
    }
    return fail_type(c, "a number", v);
}

static int parse_enum(jctx *c, const ProtobufCEnumDescriptor *ed, const json_t *v, int32_t *out)
{
    const ProtobufCEnumValue *ev = NULL;
    char names[200] = "";
    if (json_is_string(v)) {
        ev = protobuf_c_enum_descriptor_get_value_by_name(ed, json_string_value(v));
    } else if (json_is_integer(v)) {
        json_int_t x = json_integer_value(v);
        if (x >= INT32_MIN && x <= INT32_MAX) ev = protobuf_c_enum_descriptor_get_value(ed, (int)x);
    } else {
        return fail_type(c, "an enum value name", v);
    }
    if (ev) {
        *out = ev->value;
        return 0;
    }
    for (unsigned i = 0; i < ed->n_values; i++) {
        size_t o = strlen(names);
        int n = snprintf(names + o, sizeof names - o, "%s%s", i ? ", " : "", ed->values[i].name);
        if (n < 0 || (size_t)n >= sizeof names - o) {
            strcpy(names + sizeof names - 4, "...");
            break;
        }
    }
    char d[80];
    describe(v, d, sizeof d);
    return fail(c, MPM_EINVAL, "unknown value %s for enum %s (expected one of: %s)", d, ed->name,
                names);
}

/* base64 (standard or URL-safe alphabet, padding optional) -> bytes. */
static int b64_value(int ch)
{
    if (ch >= 'A' && ch <= 'Z') return ch - 'A';
    if (ch >= 'a' && ch <= 'z') return ch - 'a' + 26;
    if (ch >= '0' && ch <= '9') return ch - '0' + 52;
    if (ch == '+' || ch == '-') return 62;
    if (ch == '/' || ch == '_') return 63;
    return -1;
}

static int parse_bytes(jctx *c, const json_t *v, ProtobufCBinaryData *out)
{
    const char *s;
    size_t n, o = 0;
    unsigned acc = 0;
    int bits = 0;
    uint8_t *data;
    if (!json_is_string(v)) return fail_type(c, "a base64 string", v);
    s = json_string_value(v);
    n = strlen(s);
    while (n && s[n - 1] == '=') n--;
    if (n % 4 == 1) return fail_type(c, "a base64 string", v);
    data = malloc(n * 3 / 4 + 1);
    if (!data) return fail_nomem(c);
    for (size_t i = 0; i < n; i++) {
        int b = b64_value((unsigned char)s[i]);
        if (b < 0) {
            free(data);
            return fail_type(c, "a base64 string", v);
        }
        acc = (acc << 6) | (unsigned)b;
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            data[o++] = (uint8_t)(acc >> bits);
            acc &= (1u << bits) - 1;
        }
    }
    if (o == 0) {
        free(data);
        data = NULL;
    }
    out->data = data;
    out->len = o;
    return 0;
}

static ProtobufCMessage *new_message(const ProtobufCMessageDescriptor *d)
{
    ProtobufCMessage *m = malloc(d->sizeof_message);
    if (m) protobuf_c_message_init(d, m);
    return m;
}

/* ------------------------------------------------------------------------ */
/* JSON -> message                                                          */

static int parse_message(jctx *c, const ProtobufCMessageDescriptor *d, json_t *obj,
                         ProtobufCMessage *m);
static int parse_field(jctx *c, const ProtobufCMessageDescriptor *d,
                       const ProtobufCFieldDescriptor *f, json_t *v, ProtobufCMessage *m);

/* Parses one value of field f (a singular value or one array element)
 * into dst.  A message is allocated and linked into dst before it is
 * filled, so a failure inside leaves a freeable message behind. */
static int parse_value(jctx *c, const ProtobufCFieldDescriptor *f, json_t *v, void *dst)
{
    /* the text is read with JSON_ALLOW_NUL so that a \u0000 is refused
     * here, naming the field, not cut short as a C string would be
     * (daemon_names_nul_refused) */
    if (json_is_string(v) && strlen(json_string_value(v)) != json_string_length(v))
        return fail(c, MPM_EINVAL, "contains a NUL character (\\u0000) at byte %zu: not allowed",
                    strlen(json_string_value(v)));
    switch (f->type) {
    case PROTOBUF_C_TYPE_MESSAGE: {
        const ProtobufCMessageDescriptor *sd = f->descriptor;
        ProtobufCMessage *sm;
        if (!json_is_object(v)) return fail_type(c, "an object", v);
        sm = new_message(sd);
        if (!sm) return fail_nomem(c);
        *(ProtobufCMessage **)dst = sm;
        return parse_message(c, sd, v, sm);
    }
    case PROTOBUF_C_TYPE_STRING: {
        const char *s;
        size_t n;
        char *copy;
        if (!json_is_string(v)) return fail_type(c, "a string", v);
        s = json_string_value(v);
        n = strlen(s);
        copy = malloc(n + 1);
        if (!copy) return fail_nomem(c);
        memcpy(copy, s, n + 1);
        *(char **)dst = copy;
        return 0;
    }
    case PROTOBUF_C_TYPE_BYTES: return parse_bytes(c, v, dst);
    case PROTOBUF_C_TYPE_BOOL:
        if (!json_is_boolean(v)) return fail_type(c, "true or false", v);
        *(protobuf_c_boolean *)dst = json_is_true(v);
        return 0;
    case PROTOBUF_C_TYPE_ENUM: return parse_enum(c, f->descriptor, v, dst);
    case PROTOBUF_C_TYPE_DOUBLE: return parse_double(c, v, dst);
    case PROTOBUF_C_TYPE_FLOAT: {
        double x;
        int rc = parse_double(c, v, &x);
        if (rc) return rc;
        if (isfinite(x) && fabs(x) > FLT_MAX)
            return fail(c, MPM_EINVAL, "%g out of range for float", x);
        *(float *)dst = (float)x;
        return 0;
    }
    default: return parse_int(c, f->type, v, dst);
    }
}

/* Sets the has_ flag of a proto2 optional scalar (nothing for others). */
static void set_has(const ProtobufCFieldDescriptor *f, ProtobufCMessage *m)
{
    if (f->label == PROTOBUF_C_LABEL_OPTIONAL && !(f->flags & PROTOBUF_C_FIELD_FLAG_ONEOF) &&
        f->type != PROTOBUF_C_TYPE_MESSAGE && f->type != PROTOBUF_C_TYPE_STRING)
        *(protobuf_c_boolean *)((char *)m + f->quantifier_offset) = 1;
}

static int parse_repeated(jctx *c, const ProtobufCFieldDescriptor *f, json_t *v,
                          ProtobufCMessage *m)
{
    size_t n, es = elem_size(f->type);
    size_t *np = (size_t *)((char *)m + f->quantifier_offset);
    char **arrp = (char **)((char *)m + f->offset);
    char *arr;
    if (!json_is_array(v)) return fail_type(c, "an array", v);
    n = json_array_size(v);
    if (n == 0) return 0;
    arr = calloc(n, es);
    if (!arr) return fail_nomem(c);
    *arrp = arr;
    *np = 0;
    for (size_t i = 0; i < n; i++) {
        json_t *e = json_array_get(v, i);
        size_t old = path_push_index(c, i);
        int rc;
        if (json_is_null(e)) {
            rc = fail(c, MPM_EINVAL, "null is not allowed in an array");
        } else if (f->type == PROTOBUF_C_TYPE_MESSAGE) {
            const ProtobufCMessageDescriptor *sd = f->descriptor;
            ProtobufCMessage *sm;
            if (!json_is_object(e)) {
                rc = fail_type(c, "an object", e);
            } else if (!(sm = new_message(sd))) {
                rc = fail_nomem(c);
            } else {
                ((ProtobufCMessage **)(void *)arr)[i] = sm;
                *np = i + 1;
                rc = parse_message(c, sd, e, sm);
            }
        } else {
            rc = parse_value(c, f, e, arr + i * es);
            if (!rc) *np = i + 1;
        }
        path_pop(c, old);
        if (rc) return rc;
    }
    return 0;
}

/* A map field: a JSON object whose keys are the map keys. */
static int parse_map(jctx *c, const ProtobufCFieldDescriptor *f, json_t *v, ProtobufCMessage *m)
{
    const ProtobufCMessageDescriptor *ed = f->descriptor;
    const ProtobufCFieldDescriptor *kf = &ed->fields[0], *vf = &ed->fields[1];
    size_t *np = (size_t *)((char *)m + f->quantifier_offset);
    ProtobufCMessage ***arrp = (ProtobufCMessage ***)(void *)((char *)m + f->offset);
    ProtobufCMessage **arr;
    const char *key;
    json_t *val;
    size_t n;
    if (!json_is_object(v)) return fail_type(c, "an object (map)", v);
    n = json_object_size(v);
    if (n == 0) return 0;
    arr = calloc(n, sizeof *arr);
    if (!arr) return fail_nomem(c);
    *arrp = arr;
    *np = 0;
    json_object_foreach(v, key, val)
    {
        size_t old = path_push_key(c, key);
        ProtobufCMessage *e = new_message(ed);
        char *kdst;
        int rc = 0;
        if (!e) return fail_nomem(c);
        arr[(*np)++] = e;
        kdst = (char *)e + kf->offset;
        if (kf->type == PROTOBUF_C_TYPE_STRING) {
            size_t kl = strlen(key);
            char *copy = malloc(kl + 1);
            if (!copy) return fail_nomem(c);
            memcpy(copy, key, kl + 1);
            *(char **)kdst = copy;
        } else if (kf->type == PROTOBUF_C_TYPE_BOOL) {
            if (!strcmp(key, "true"))
                *(protobuf_c_boolean *)kdst = 1;
            else if (!strcmp(key, "false"))
                *(protobuf_c_boolean *)kdst = 0;
            else
                rc = fail(c, MPM_EINVAL, "map key must be \"true\" or \"false\"");
        } else {
            json_t *ks = json_string(key);
            if (!ks) return fail_nomem(c);
            rc = parse_int(c, kf->type, ks, kdst);
            json_decref(ks);
        }
        if (rc) return rc;
        set_has(kf, e);
        if (json_is_null(val)) return fail(c, MPM_EINVAL, "null is not allowed as a map value");
        rc = parse_field(c, ed, vf, val, e);
        if (rc) return rc;
        path_pop(c, old);
    }
    return 0;
}

/* Parses the non-null JSON value v of field f of message m. */
static int parse_field(jctx *c, const ProtobufCMessageDescriptor *d,
                       const ProtobufCFieldDescriptor *f, json_t *v, ProtobufCMessage *m)
{
    char *base = (char *)m;
    int rc;
    if (f->label == PROTOBUF_C_LABEL_REPEATED)
        return is_map(d, f) ? parse_map(c, f, v, m) : parse_repeated(c, f, v, m);
    if (f->flags & PROTOBUF_C_FIELD_FLAG_ONEOF) {
        uint32_t *cs = (uint32_t *)(base + f->quantifier_offset);
        if (*cs != 0 && *cs != f->id) {
            const ProtobufCFieldDescriptor *o = field_by_id(d, *cs);
            char on[96] = "?";
            if (o) mpp_json_name(o->name, on, sizeof on);
            return fail(c, MPM_EINVAL,
                        "only one member of a oneof may be set, and \"%s\" is set already", on);
        }
        *cs = f->id;
        return parse_value(c, f, v, base + f->offset);
    }
    rc = parse_value(c, f, v, base + f->offset);
    if (!rc) set_has(f, m);
    return rc;
}

static int parse_message(jctx *c, const ProtobufCMessageDescriptor *d, json_t *obj,
                         ProtobufCMessage *m)
{
    const char **seen;
    const char *key;
    json_t *val;
    int rc = 0;
    if (!json_is_object(obj)) return fail_type(c, "an object", obj);
    if (c->depth >= MPP_JSON_MAX_DEPTH)
        return fail(c, MPM_EINVAL, "messages nested deeper than %d", MPP_JSON_MAX_DEPTH);
    seen = calloc(d->n_fields ? d->n_fields : 1, sizeof *seen);
    if (!seen) return fail_nomem(c);
    c->depth++;
    json_object_foreach(obj, key, val)
    {
        int i = find_field(d, key);
        size_t old = path_push_key(c, key);
        if (i < 0) {
            char known[240];
            snprintf(known, sizeof known, "unknown field (%s has: ", d->short_name);
            list_fields(d, known, sizeof known - 1);
            strcat(known, ")");
            rc = fail(c, MPM_EINVAL, "%s", known);
        } else if (seen[i]) {
            rc = fail(c, MPM_EINVAL, "field given twice (as \"%s\" and \"%s\")", key, seen[i]);
        } else {
            seen[i] = key;
            if (!json_is_null(val)) rc = parse_field(c, d, &d->fields[i], val, m);
        }
        path_pop(c, old);
        if (rc) break;
    }
    for (unsigned i = 0; !rc && i < d->n_fields; i++) {
        if (d->fields[i].label != PROTOBUF_C_LABEL_REQUIRED) continue;
        if (seen[i] && !json_is_null(json_object_get(obj, seen[i]))) continue;
        size_t old = path_push_key(c, d->fields[i].name);
        rc = fail(c, MPM_EINVAL, "required field missing");
        path_pop(c, old);
    }
    c->depth--;
    free(seen);
    return rc;
}

int mpp_json_to_pb(const ProtobufCMessageDescriptor *desc, const char *text, size_t len,
                   ProtobufCMessage **out, mpm_error *err)
{
    jctx c;
    json_error_t je;
    json_t *root;
    ProtobufCMessage *m;
    int rc;
    ctx_init(&c, err);
    *out = NULL;
    root = json_loadb(text, len, JSON_REJECT_DUPLICATES | JSON_ALLOW_NUL, &je);
    if (!root) {
        if (json_error_code(&je) == json_error_out_of_memory) return fail_nomem(&c);
        return fail(&c, MPM_ESYNTAX, "invalid JSON at line %d, column %d: %s", je.line, je.column,
                    je.text);
    }
    if (!json_is_object(root)) {
        char what[64];
        snprintf(what, sizeof what, "a JSON object (%s)", desc->short_name);
        rc = fail_type(&c, what, root);
        json_decref(root);
        return rc;
    }
    m = new_message(desc);
    if (!m) {
        json_decref(root);
        return fail_nomem(&c);
    }
    rc = parse_message(&c, desc, root, m);
    json_decref(root);
    if (rc) {
        protobuf_c_message_free_unpacked(m, NULL);
        return rc;
    }
    *out = m;
    return 0;
}

/* ------------------------------------------------------------------------ */
/* message -> JSON                                                          */

typedef struct {
    jctx c;
    char *p;
    size_t n, cap;
    int oom;
    int pretty;
} ectx;

static void put(ectx *e, const char *s, size_t n)
{
    if (e->oom) return;
    if (n + 1 > e->cap - e->n) {
        size_t cap = e->cap ? e->cap : 256;
        char *q;
        while (n + 1 > cap - e->n) {
            if (cap > SIZE_MAX / 2) {
                e->oom = 1;
                return;
            }
            cap *= 2;
        }
        q = realloc(e->p, cap);
        if (!q) {
            e->oom = 1;
            return;
        }
        e->p = q;
        e->cap = cap;
    }
    memcpy(e->p + e->n, s, n);
    e->n += n;
    e->p[e->n] = 0;
}

static void puts_(ectx *e, const char *s)
{
    put(e, s, strlen(s));
}

static void newline(ectx *e, int indent)
{
    if (!e->pretty) return;
    put(e, "\n", 1);
    for (int i = 0; i < indent; i++) put(e, "  ", 2);
}

/* Shortest %g form that reads back as the same double (or float). */
static void put_double(ectx *e, double x, int is_float)
{
    char buf[40];
    if (isnan(x)) {
        puts_(e, "\"NaN\"");
        return;
    }
    if (isinf(x)) {
        puts_(e, x > 0 ? "\"Infinity\"" : "\"-Infinity\"");
        return;
    }
    for (int prec = is_float ? 6 : 15; prec <= (is_float ? 9 : 17); prec++) {
        snprintf(buf, sizeof buf, "%.*g", prec, x);
        if (is_float ? strtof(buf, NULL) == (float)x : strtod(buf, NULL) == x) break;
    }
    puts_(e, buf);
}

/* Length of the valid UTF-8 sequence at s (0 if invalid). */
static size_t utf8_len(const unsigned char *s)
{
    unsigned cp;
    size_t n;
    if (s[0] < 0x80) return 1;
    if (s[0] >= 0xc2 && s[0] <= 0xdf) {
        n = 2;
        cp = s[0] & 0x1fu;
    } else if (s[0] >= 0xe0 && s[0] <= 0xef) {
        n = 3;
        cp = s[0] & 0x0fu;
    } else if (s[0] >= 0xf0 && s[0] <= 0xf4) {
        n = 4;
        cp = s[0] & 0x07u;
    } else
        return 0;
    for (size_t i = 1; i < n; i++) {
        if ((s[i] & 0xc0) != 0x80) return 0;
        cp = (cp << 6) | (s[i] & 0x3fu);
    }
    if ((n == 3 && cp < 0x800) || (n == 4 && (cp < 0x10000 || cp > 0x10ffff)) ||
        (cp >= 0xd800 && cp <= 0xdfff))
        return 0;
    return n;
}

int mpp_json_utf8_valid(const char *s)
{
    const unsigned char *p = (const unsigned char *)s;
    while (*p) {
        size_t n = utf8_len(p);
        if (n == 0) return 0;
        p += n;
    }
    return 1;
}

static int put_string(ectx *e, const char *str)
{
    const unsigned char *s = (const unsigned char *)str;
    put(e, "\"", 1);
    while (*s) {
        size_t n = utf8_len(s);
        char esc[8];
        if (n == 0) return fail(&e->c, MPM_EINVAL, "string is not valid UTF-8");
        if (*s == '"')
            puts_(e, "\\\"");
        else if (*s == '\\')
            puts_(e, "\\\\");
        else if (*s == '\n')
            puts_(e, "\\n");
        else if (*s == '\t')
            puts_(e, "\\t");
        else if (*s == '\r')
            puts_(e, "\\r");
        else if (*s < 0x20) {
            snprintf(esc, sizeof esc, "\\u%04x", *s);
            puts_(e, esc);
        } else
            put(e, (const char *)s, n);
        s += n;
    }
    put(e, "\"", 1);
    return 0;
}

static void put_bytes(ectx *e, const ProtobufCBinaryData *b)
{
    static const char tab[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    char q[4];
    put(e, "\"", 1);
    for (size_t i = 0; i < b->len; i += 3) {
        unsigned v = (unsigned)b->data[i] << 16;
        size_t k = b->len - i;
        if (k > 1) v |= (unsigned)b->data[i + 1] << 8;
        if (k > 2) v |= b->data[i + 2];
        q[0] = tab[(v >> 18) & 63];
        q[1] = tab[(v >> 12) & 63];
        q[2] = k > 1 ? tab[(v >> 6) & 63] : '=';
        q[3] = k > 2 ? tab[v & 63] : '=';
        put(e, q, 4);
    }
    put(e, "\"", 1);
}

static void put_json_name(ectx *e, const char *proto_name)
{
    char buf[128];
    size_t n = mpp_json_name(proto_name, buf, sizeof buf);
    put(e, "\"", 1);
    if (n < sizeof buf) {
        put(e, buf, n);
    } else {
        char *big = malloc(n + 1);
        if (!big) {
            e->oom = 1;
            return;
        }
        mpp_json_name(proto_name, big, n + 1);
        put(e, big, n);
        free(big);
    }
    put(e, "\"", 1);
}

static int emit_message(ectx *e, const ProtobufCMessage *m, int indent);

/* Prints one value of field f stored at p (a singular member or an array
 * element). */
static int emit_value(ectx *e, const ProtobufCFieldDescriptor *f, const void *p, int indent)
{
    char buf[48];
    switch (f->type) {
    case PROTOBUF_C_TYPE_MESSAGE: {
        const ProtobufCMessage *sm = *(ProtobufCMessage *const *)p;
        if (!sm) return fail(&e->c, MPM_EINVAL, "NULL message");
        return emit_message(e, sm, indent);
    }
    case PROTOBUF_C_TYPE_STRING: {
        const char *s = *(char *const *)p;
        if (!s) return fail(&e->c, MPM_EINVAL, "NULL string");
        return put_string(e, s);
    }
    case PROTOBUF_C_TYPE_BYTES: put_bytes(e, p); return 0;
    case PROTOBUF_C_TYPE_BOOL:
        puts_(e, *(const protobuf_c_boolean *)p ? "true" : "false");
        return 0;
    case PROTOBUF_C_TYPE_DOUBLE: put_double(e, *(const double *)p, 0); return 0;
    case PROTOBUF_C_TYPE_FLOAT: put_double(e, *(const float *)p, 1); return 0;
    case PROTOBUF_C_TYPE_ENUM: {
        int32_t v = *(const int32_t *)p;
        const ProtobufCEnumValue *ev = protobuf_c_enum_descriptor_get_value(f->descriptor, v);
        if (ev) return put_string(e, ev->name);
        snprintf(buf, sizeof buf, "%" PRId32, v);
        break;
    }
    case PROTOBUF_C_TYPE_INT32:
    case PROTOBUF_C_TYPE_SINT32:
    case PROTOBUF_C_TYPE_SFIXED32:
        snprintf(buf, sizeof buf, "%" PRId32, *(const int32_t *)p);
        break;
    case PROTOBUF_C_TYPE_UINT32:
    case PROTOBUF_C_TYPE_FIXED32:
        snprintf(buf, sizeof buf, "%" PRIu32, *(const uint32_t *)p);
        break;
    case PROTOBUF_C_TYPE_INT64:
    case PROTOBUF_C_TYPE_SINT64:
    case PROTOBUF_C_TYPE_SFIXED64:
        snprintf(buf, sizeof buf, "\"%" PRId64 "\"", *(const int64_t *)p);
        break;
    case PROTOBUF_C_TYPE_UINT64:
    case PROTOBUF_C_TYPE_FIXED64:
        snprintf(buf, sizeof buf, "\"%" PRIu64 "\"", *(const uint64_t *)p);
        break;
    }
    puts_(e, buf);
    return 0;
}

/* Whether field f of m is present (see the printing rules in mpp_json.h). */
static int present(const ProtobufCFieldDescriptor *f, const ProtobufCMessage *m)
{
    const char *base = (const char *)m;
    const void *p = base + f->offset;
    int ptr_type = f->type == PROTOBUF_C_TYPE_MESSAGE || f->type == PROTOBUF_C_TYPE_STRING;
    if (f->label == PROTOBUF_C_LABEL_REPEATED)
        return *(const size_t *)(base + f->quantifier_offset) > 0;
    if (f->flags & PROTOBUF_C_FIELD_FLAG_ONEOF) {
        if (*(const uint32_t *)(base + f->quantifier_offset) != f->id) return 0;
        return !ptr_type || *(void *const *)p != NULL;
    }
    switch (f->label) {
    case PROTOBUF_C_LABEL_OPTIONAL:
        if (ptr_type) return *(void *const *)p != NULL && *(void *const *)p != f->default_value;
        return *(const protobuf_c_boolean *)(base + f->quantifier_offset) != 0;
    case PROTOBUF_C_LABEL_REQUIRED: return !ptr_type || *(void *const *)p != NULL;
    default: /* proto3 implicit presence: print non-default values */
        if (f->type == PROTOBUF_C_TYPE_MESSAGE) return *(void *const *)p != NULL;
        if (f->type == PROTOBUF_C_TYPE_STRING) return *(void *const *)p && **(char *const *)p;
        if (f->type == PROTOBUF_C_TYPE_BYTES) return ((const ProtobufCBinaryData *)p)->len > 0;
        for (size_t i = 0; i < elem_size(f->type); i++)
            if (((const unsigned char *)p)[i]) return 1;
        return 0;
    }
}

static int emit_map(ectx *e, const ProtobufCFieldDescriptor *f, const ProtobufCMessage *m,
                    int indent)
{
    const ProtobufCMessageDescriptor *ed = f->descriptor;
    const ProtobufCFieldDescriptor *kf = &ed->fields[0], *vf = &ed->fields[1];
    size_t n = *(const size_t *)((const char *)m + f->quantifier_offset);
    ProtobufCMessage *const *arr =
        *(ProtobufCMessage *const *const *)(const void *)((const char *)m + f->offset);
    put(e, "{", 1);
    for (size_t i = 0; i < n; i++) {
        const ProtobufCMessage *en = arr[i];
        const char *kp;
        char kb[48];
        int rc;
        size_t old = path_push_index(&e->c, i);
        if (!en) return fail(&e->c, MPM_EINVAL, "NULL map entry");
        kp = (const char *)en + kf->offset;
        if (i) put(e, ",", 1);
        newline(e, indent + 1);
        switch (kf->type) {
        case PROTOBUF_C_TYPE_STRING:
            rc = put_string(e, *(char *const *)kp ? *(char *const *)kp : "");
            if (rc) return rc;
            break;
        case PROTOBUF_C_TYPE_BOOL:
            puts_(e, *(const protobuf_c_boolean *)kp ? "\"true\"" : "\"false\"");
            break;
        default:
            if (type_is_32(kf->type) && type_is_signed(kf->type))
                snprintf(kb, sizeof kb, "\"%" PRId32 "\"", *(const int32_t *)kp);
            else if (type_is_32(kf->type))
                snprintf(kb, sizeof kb, "\"%" PRIu32 "\"", *(const uint32_t *)kp);
            else if (type_is_signed(kf->type))
                snprintf(kb, sizeof kb, "\"%" PRId64 "\"", *(const int64_t *)kp);
            else
                snprintf(kb, sizeof kb, "\"%" PRIu64 "\"", *(const uint64_t *)kp);
            puts_(e, kb);
        }
        put(e, e->pretty ? ": " : ":", e->pretty ? 2 : 1);
        if (vf->type == PROTOBUF_C_TYPE_MESSAGE &&
            !*(void *const *)((const char *)en + vf->offset)) {
            puts_(e, "{}");
        } else {
            rc = emit_value(e, vf, (const char *)en + vf->offset, indent + 1);
            if (rc) return rc;
        }
        path_pop(&e->c, old);
    }
    if (n) newline(e, indent);
    put(e, "}", 1);
    return 0;
}

static int emit_field(ectx *e, const ProtobufCMessageDescriptor *d,
                      const ProtobufCFieldDescriptor *f, const ProtobufCMessage *m, int indent)
{
    const char *base = (const char *)m;
    size_t n, es;
    const char *arr;
    int msgs = f->type == PROTOBUF_C_TYPE_MESSAGE;
    if (f->label != PROTOBUF_C_LABEL_REPEATED) return emit_value(e, f, base + f->offset, indent);
    if (is_map(d, f)) return emit_map(e, f, m, indent);
    n = *(const size_t *)(base + f->quantifier_offset);
    arr = *(const char *const *)(base + f->offset);
    es = elem_size(f->type);
    if (!arr) return fail(&e->c, MPM_EINVAL, "NULL array of %zu elements", n);
    put(e, "[", 1);
    for (size_t i = 0; i < n; i++) {
        size_t old = path_push_index(&e->c, i);
        int rc;
        if (i) put(e, e->pretty && !msgs ? ", " : ",", e->pretty && !msgs ? 2 : 1);
        if (msgs) newline(e, indent + 1);
        rc = emit_value(e, f, arr + i * es, indent + 1);
        path_pop(&e->c, old);
        if (rc) return rc;
    }
    if (msgs) newline(e, indent);
    put(e, "]", 1);
    return 0;
}

static int emit_message(ectx *e, const ProtobufCMessage *m, int indent)
{
    const ProtobufCMessageDescriptor *d = m->descriptor;
    int first = 1;
    if (!d || d->magic != PROTOBUF_C__MESSAGE_DESCRIPTOR_MAGIC)
        return fail(&e->c, MPM_EINVAL, "not a protobuf-c message");
    if (e->c.depth >= MPP_JSON_MAX_DEPTH)
        return fail(&e->c, MPM_EINVAL, "messages nested deeper than %d", MPP_JSON_MAX_DEPTH);
    e->c.depth++;
    put(e, "{", 1);
    for (unsigned i = 0; i < d->n_fields; i++) {
        const ProtobufCFieldDescriptor *f = &d->fields[i];
        size_t old;
        int rc;
        if (!present(f, m)) continue;
        if (!first) put(e, ",", 1);
        first = 0;
        newline(e, indent + 1);
        put_json_name(e, f->name);
        put(e, e->pretty ? ": " : ":", e->pretty ? 2 : 1);
        old = path_push_key(&e->c, f->name);
        rc = emit_field(e, d, f, m, indent + 1);
        path_pop(&e->c, old);
        if (rc) return rc;
    }
    if (!first) newline(e, indent);
    put(e, "}", 1);
    e->c.depth--;
    return 0;
}

int mpp_json_from_pb(const ProtobufCMessage *msg, unsigned flags, char **out, mpm_error *err)
{
    ectx e;
    int rc;
    memset(&e, 0, sizeof e);
    ctx_init(&e.c, err);
    e.pretty = (flags & MPP_JSON_PRETTY) != 0;
    *out = NULL;
    rc = emit_message(&e, msg, 0);
    if (!rc && e.pretty) put(&e, "\n", 1);
    if (!rc && e.oom) rc = fail_nomem(&e.c);
    if (rc) {
        free(e.p);
        return rc;
    }
    *out = e.p;
    return 0;
}
