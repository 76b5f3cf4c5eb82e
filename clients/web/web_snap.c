/*
 * web_snap.c - a snapshot as the monitor page draws it: positions and the
 * colour fields (pressure, speed |v|, plastic strain) in compact JSON with
 * 7 significant digits, about 9 bytes a number, several times smaller
 * than the JSON mapping's shortest exact doubles and enough for pixels.
 * Only numbers are written here (no text from the daemon), so no escaping
 * is needed; a non-finite value becomes null.
 */
#include "web.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    char *p;
    size_t n, cap;
    int oom;
} buf_t;

static void put(buf_t *b, const char *s, size_t k)
{
    if (b->oom) return;
    if (b->n + k + 1 > b->cap) {
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->n + k + 1) cap *= 2;
        char *p = realloc(b->p, cap);
        if (!p) {
            b->oom = 1;
            return;
        }
        b->p = p;
        b->cap = cap;
    }
    if (!b->p) { /* cannot happen: the first call allocates */
        b->oom = 1;
        return;
    }
    memcpy(b->p + b->n, s, k);
    b->n += k;
    b->p[b->n] = 0;
}

static void puts_(buf_t *b, const char *s)
{
    put(b, s, strlen(s));
}

static void num(buf_t *b, double v)
{
    char t[32];
    int k = isfinite(v) ? snprintf(t, sizeof t, "%.7g", v) : snprintf(t, sizeof t, "null");
    put(b, t, (size_t)k);
}

/* "name":[v0,v1,...] of n values, v[i] = at(i) */
static void array(buf_t *b, const double *v, size_t n, size_t stride, size_t off)
{
    puts_(b, "[");
    for (size_t i = 0; i < n; i++) {
        if (i) puts_(b, ",");
        num(b, v[i * stride + off]);
    }
    puts_(b, "]");
}

int web_snap_json(const mpp_snapshot *s, char **out, size_t *len)
{
    buf_t b = {0};
    char head[160];
    size_t n = s->n, d = s->dim > 0 ? (size_t)s->dim : 1;
    snprintf(head, sizeof head, "{\"step\":%lld,\"t\":", (long long)s->step);
    puts_(&b, head);
    num(&b, s->t);
    snprintf(head, sizeof head, ",\"n\":%zu,\"dim\":%d,\"x\":", n, s->dim);
    puts_(&b, head);
    if (s->x)
        array(&b, s->x, n * d, 1, 0);
    else
        puts_(&b, "null");
    puts_(&b, ",\"fields\":{");
    int first = 1;
    if (s->pressure) {
        puts_(&b, "\"pressure\":");
        array(&b, s->pressure, n, 1, 0);
        first = 0;
    }
    if (s->v) {
        puts_(&b, first ? "\"speed\":[" : ",\"speed\":[");
        for (size_t i = 0; i < n; i++) {
            double q = 0;
            for (size_t k = 0; k < d; k++) q += s->v[i * d + k] * s->v[i * d + k];
            if (i) puts_(&b, ",");
            num(&b, sqrt(q));
        }
        puts_(&b, "]");
        first = 0;
    }
    if (s->plastic_strain) {
        puts_(&b, first ? "\"plasticStrain\":" : ",\"plasticStrain\":");
        array(&b, s->plastic_strain, n, 1, 0);
    }
    puts_(&b, "}}");
    if (b.oom) {
        free(b.p);
        *out = NULL;
        *len = 0;
        fprintf(stderr, "mpmweb: out of memory for a snapshot of %zu particles\n", n);
        return CTL_ESYS;
    }
    *out = b.p;
    *len = b.n;
    return 0;
}
