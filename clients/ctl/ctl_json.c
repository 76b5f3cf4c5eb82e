/*
 * ctl_json.c - JSON helpers of mpmctl.  The replies a command prints as
 * records arrive as protobuf bytes and are turned into JSON text by the
 * protocol library's bridge (protobuf JSON mapping:
 * 64-bit integers and non-finite doubles as strings), then parsed with
 * jansson; the accessors here read fields under that mapping with a default
 * for absent ones.  The printer writes jansson values back out with every
 * double in its shortest form that reads back exactly (jansson itself
 * always prints 17 significant digits), compact or indented.
 */
#include "ctl.h"
#include "mpp_json.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* A string member holding a number as the JSON mapping writes it. */
static int str_num(const char *s, double *v)
{
    return mpp_json_double_text(s, v) ? -1 : 0;
}

double cj_num(const json_t *o, const char *key, double dflt)
{
    const json_t *v = o ? json_object_get(o, key) : NULL;
    double d;
    if (!v) return dflt;
    if (json_is_number(v)) return json_number_value(v);
    if (json_is_string(v) && !str_num(json_string_value(v), &d)) return d;
    return dflt;
}

long long cj_int(const json_t *o, const char *key, long long dflt)
{
    const json_t *v = o ? json_object_get(o, key) : NULL;
    if (!v) return dflt;
    if (json_is_integer(v)) return json_integer_value(v);
    if (json_is_real(v)) return (long long)json_real_value(v);
    if (json_is_string(v)) {
        const char *s = json_string_value(v);
        char *end;
        long long x;
        errno = 0;
        x = strtoll(s, &end, 10);
        if (end != s && !*end && !errno) return x;
    }
    return dflt;
}

uint64_t cj_u64(const json_t *o, const char *key, uint64_t dflt)
{
    const json_t *v = o ? json_object_get(o, key) : NULL;
    if (!v) return dflt;
    if (json_is_integer(v)) return (uint64_t)json_integer_value(v);
    if (json_is_string(v)) {
        const char *s = json_string_value(v);
        char *end;
        unsigned long long x;
        errno = 0;
        x = strtoull(s, &end, 10);
        if (end != s && !*end && !errno && *s != '-') return (uint64_t)x;
    }
    return dflt;
}

const char *cj_str(const json_t *o, const char *key, const char *dflt)
{
    const json_t *v = o ? json_object_get(o, key) : NULL;
    return json_is_string(v) ? json_string_value(v) : dflt;
}

double cj_at(const json_t *o, const char *key, size_t i, double dflt)
{
    const json_t *a = o ? json_object_get(o, key) : NULL;
    const json_t *v = json_is_array(a) ? json_array_get(a, i) : NULL;
    double d;
    if (!v) return dflt;
    if (json_is_number(v)) return json_number_value(v);
    if (json_is_string(v) && !str_num(json_string_value(v), &d)) return d;
    return dflt;
}

size_t cj_len(const json_t *o, const char *key)
{
    const json_t *a = o ? json_object_get(o, key) : NULL;
    return json_is_array(a) ? json_array_size(a) : 0;
}

int cj_status(const json_t *o, const char *key)
{
    const json_t *v = o ? json_object_get(o, key) : NULL;
    if (json_is_string(v)) return mpp_status_from_name(json_string_value(v));
    if (json_is_integer(v)) return (int)json_integer_value(v);
    return 0;
}

double cj_norm(double v)
{
    return v == 0 ? 0.0 : isnan(v) ? NAN : v;
}

void cj_fmt_double(char *buf, size_t n, double v)
{
    if (isnan(v)) {
        snprintf(buf, n, "NaN");
        return;
    }
    if (isinf(v)) {
        snprintf(buf, n, v > 0 ? "Infinity" : "-Infinity");
        return;
    }
    for (int p = 15; p <= 17; p++) {
        snprintf(buf, n, "%.*g", p, v);
        if (strtod(buf, NULL) == v) return;
    }
}

/* ---- printer ------------------------------------------------------------ */

#define CJ_MAX_DEPTH 128 /* replies nest far less (the codec stops at 64) */

static int is_scalar(const json_t *v)
{
    return !json_is_object(v) && !json_is_array(v);
}

static void indent(FILE *f, int depth)
{
    fputc('\n', f);
    for (int i = 0; i < depth; i++) fputs("  ", f);
}

static int print_value(FILE *f, const json_t *v, int pretty, int depth)
{
    char num[40];
    if (depth > CJ_MAX_DEPTH) return CTL_EPROTO;
    switch (json_typeof(v)) {
    case JSON_OBJECT: {
        const char *key;
        json_t *m;
        int first = 1;
        fputc('{', f);
        json_object_foreach((json_t *)v, key, m)
        {
            json_t *k = json_string(key);
            char *ks = k ? json_dumps(k, JSON_ENCODE_ANY) : NULL;
            json_decref(k);
            if (!ks) return CTL_ESYS;
            if (!first) fputc(',', f);
            if (pretty) indent(f, depth + 1);
            fputs(ks, f);
            fputs(pretty ? ": " : ":", f);
            free(ks);
            first = 0;
            int rc = print_value(f, m, pretty, depth + 1);
            if (rc) return rc;
        }
        if (pretty && !first) indent(f, depth);
        fputc('}', f);
        return 0;
    }
    case JSON_ARRAY: {
        size_t i, n = json_array_size(v);
        int flat = 1;
        for (i = 0; i < n && flat; i++) flat = is_scalar(json_array_get(v, i));
        fputc('[', f);
        for (i = 0; i < n; i++) {
            if (i) fputs(pretty && flat ? ", " : ",", f);
            if (pretty && !flat) indent(f, depth + 1);
            int rc = print_value(f, json_array_get(v, i), pretty, depth + 1);
            if (rc) return rc;
        }
        if (pretty && !flat && n) indent(f, depth);
        fputc(']', f);
        return 0;
    }
    case JSON_STRING: {
        char *s = json_dumps(v, JSON_ENCODE_ANY);
        if (!s) return CTL_ESYS;
        fputs(s, f);
        free(s);
        return 0;
    }
    case JSON_INTEGER: fprintf(f, "%" JSON_INTEGER_FORMAT, json_integer_value(v)); return 0;
    case JSON_REAL:
        cj_fmt_double(num, sizeof num, json_real_value(v));
        fputs(num, f);
        return 0;
    case JSON_TRUE: fputs("true", f); return 0;
    case JSON_FALSE: fputs("false", f); return 0;
    case JSON_NULL: fputs("null", f); return 0;
    }
    return CTL_EPROTO;
}

int cj_print(FILE *f, const json_t *v, int pretty)
{
    int rc = print_value(f, v, pretty, 0);
    if (rc) fprintf(stderr, "mpmctl: cannot print a reply as JSON\n");
    return rc;
}
