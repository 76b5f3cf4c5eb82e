/*
 * mpm_error.c - the shared error value (see mpm_error.h): filling it, its
 * structured field path, and rendering the path in the proto or the JSON
 * spelling at the edge.
 */
#include "mpm_error.h"

#include <ctype.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void mpm_error_clear(mpm_error *e)
{
    if (e) memset(e, 0, sizeof *e);
}

static void set_elem(mpm_path_elem *p, const char *name, size_t len, long index)
{
    if (len >= sizeof p->name) len = sizeof p->name - 1;
    memcpy(p->name, name, len);
    p->name[len] = 0;
    p->index = index;
}

void mpm_error_push(mpm_error *e, const char *name, long index)
{
    if (!e || e->depth >= MPM_PATH_MAX) return;
    set_elem(&e->path[e->depth++], name, strlen(name), index);
}

void mpm_error_prefix(mpm_error *e, const char *name, long index)
{
    if (!e) return;
    if (e->depth == MPM_PATH_MAX) e->depth--; /* the innermost is cut */
    memmove(&e->path[1], &e->path[0], (size_t)e->depth * sizeof e->path[0]);
    e->depth++;
    set_elem(&e->path[0], name, strlen(name), index);
}

/* "a[1].b.c[2]" -> elements; an element whose [...] is not a number keeps
 * its bracket text in the name. */
static void parse_field(mpm_error *e, const char *f)
{
    while (f && *f && e->depth < MPM_PATH_MAX) {
        size_t len = strcspn(f, ".[");
        long index = -1;
        const char *next = f + len;
        if (*next == '[') {
            char *end;
            long v = strtol(next + 1, &end, 10);
            if (end != next + 1 && *end == ']' && v >= 0) {
                index = v;
                next = end + 1;
            } else {
                const char *close = strchr(next, ']');
                len = close ? (size_t)(close + 1 - f) : strlen(f);
                next = f + len;
            }
        }
        set_elem(&e->path[e->depth++], f, len, index);
        f = *next == '.' ? next + 1 : next;
    }
}

int mpm_fail(mpm_error *e, int code, const char *field, const char *fmt, ...)
{
    if (!e) return code;
    memset(e, 0, sizeof *e);
    e->code = code;
    parse_field(e, field);
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(e->message, sizeof e->message, fmt, ap);
    va_end(ap);
    return code;
}

void mpm_camel_case(const char *snake, char *out, size_t n)
{
    size_t k = 0;
    int up = 0;
    if (!n) return;
    for (const char *s = snake; *s && k + 1 < n; s++) {
        if (*s == '_' && s[1] && isalpha((unsigned char)s[1])) {
            up = 1;
            continue;
        }
        out[k++] = up ? (char)toupper((unsigned char)*s) : *s;
        up = 0;
    }
    out[k] = 0;
}

char *mpm_error_field(const mpm_error *e, mpm_field_style style, char *buf, size_t n)
{
    size_t k = 0;
    if (!n) return buf;
    buf[0] = 0;
    for (int i = 0; e && i < e->depth && k < n; i++) {
        char name[MPM_PATH_NAME_MAX];
        if (style == MPM_FIELD_JSON)
            mpm_camel_case(e->path[i].name, name, sizeof name);
        else
            snprintf(name, sizeof name, "%s", e->path[i].name);
        int w = e->path[i].index >= 0
                    ? snprintf(buf + k, n - k, "%s%s[%ld]", i ? "." : "", name, e->path[i].index)
                    : snprintf(buf + k, n - k, "%s%s", i ? "." : "", name);
        if (w < 0) break;
        k += (size_t)w;
    }
    if (k >= n) buf[n - 1] = 0;
    return buf;
}

char *mpm_error_text(const mpm_error *e, mpm_field_style style, char *buf, size_t n)
{
    char field[256];
    if (!n) return buf;
    mpm_error_field(e, style, field, sizeof field);
    const char *msg = e && e->message[0] ? e->message : mpm_strerror(e ? e->code : 0);
    if (field[0])
        snprintf(buf, n, "%s: %s", field, msg);
    else
        snprintf(buf, n, "%s", msg);
    return buf;
}

const char *mpm_strerror(int code)
{
    switch (code) {
    case MPM_OK: return "success";
    case MPM_EINVAL: return "invalid input";
    case MPM_ENOMEM: return "out of memory";
    case MPM_ELEFTGRID: return "a particle left the grid";
    case MPM_EDIVERGED: return "the simulation diverged";
    case MPM_ECANCELLED: return "cancelled";
    case MPM_ECFL: return "time step above the CFL limit";
    case MPM_ESTATE: return "not allowed in this state";
    case MPM_ETOOBIG: return "above a limit";
    case MPM_ESYNTAX: return "does not decode";
    case MPM_EVERSION: return "unsupported schema version";
    case MPM_ENOTFOUND: return "not found";
    case MPM_ECONFLICT: return "conflict with the current state";
    case MPM_EFULL: return "queue full";
    case MPM_EUNAVAIL: return "unavailable";
    case MPM_EIO: return "input/output error";
    case MPM_ELOCKED: return "in use by another process";
    case MPM_ESCHEMA: return "not an mpmd database, or a newer schema";
    case MPM_EREQUEST: return "bad request";
    case MPM_EINTERNAL: return "internal error";
    case MPM_EFORBIDDEN: return "forbidden";
    default: return "unknown error";
    }
}
