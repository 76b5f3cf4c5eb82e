/*
 * srv_grow.h - growing an array by doubling: the overflow-checked realloc
 * the daemon's tables share (srv_outq.c's connections, srv_budget.c's
 * owners, srv_auth.c's key lists).  Inline, so that gcc -fanalyzer
 * follows the realloc into the callers.
 */
#ifndef SRV_GROW_H
#define SRV_GROW_H

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

/* Room for need elements of size bytes in the array v of *cap elements:
 * v itself when it has it, else v grown (doubling from 16, at most max
 * elements; 0: no limit) with *cap updated, or NULL when out of memory or
 * over max (v unchanged and still the caller's). */
static inline void *srv_grow(void *v, size_t *cap, size_t need, size_t size, size_t max)
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

#endif
