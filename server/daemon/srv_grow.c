/*
 * srv_grow.c - growing an array by doubling (see srv_grow.h): the
 * overflow-checked realloc the daemon's tables share (srv_outq.c's
 * connections, srv_budget.c's owners, srv_auth.c's key lists).
 */
#include "srv_grow.h"

#include <stdint.h>
#include <stdlib.h>

void *srv_grow(void *v, size_t *cap, size_t need, size_t size, size_t max)
{
    if (need <= *cap) return v;
    size_t nc = *cap ? *cap : 16;
    while (nc < need) {
        if (nc > SIZE_MAX / 2 / size) return NULL;
        nc *= 2;
    }
    if (max && nc > max) return NULL;
    void *nv = realloc(v, nc * size);
    if (nv) *cap = nc;
    return nv;
}
