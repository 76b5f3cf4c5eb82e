/*
 * srv_grow.h - growing an array (srv_grow.c), the one loop the daemon's
 * tables (the reply queues' connections, the disk budgets' owners, the
 * key lists) share.
 */
#ifndef SRV_GROW_H
#define SRV_GROW_H

#include <stddef.h>

/* Room for need elements of size bytes in the array v of *cap elements:
 * v itself when it has it, else v grown (doubling from 16, at most max
 * elements; 0: no limit) with *cap updated, or NULL when out of memory or
 * over max (v unchanged and still the caller's). */
void *srv_grow(void *v, size_t *cap, size_t need, size_t size, size_t max);

#endif
