/*
 * store_ends.h - store_ends.c: the run ends kept off a full disk (in
 * memory and in the side file "<db>.ends") and the disk reserve
 * "<db>.reserve".  Private to server/store/.
 */
#ifndef STORE_ENDS_H
#define STORE_ENDS_H

#include "store_internal.h"

/* Opens (creating and preallocating) the side file "<db>.ends" and loads
 * the ends it holds into s->defer; a failure is logged, not fatal. */
void sti_ends_open(store *s);
void sti_ends_close(store *s);
/* Keeps the end of a run whose transaction was lost (writer thread). */
void sti_ends_keep(store *s, int64_t run_id, const store_run_end *end);
/* Forgets the first n kept ends (applied and committed; writer thread). */
void sti_ends_drop(store *s, size_t n);
/* Shows a kept end or a pending recovery in a run read back. */
void sti_ends_overlay(store *s, store_run *r);
/* The disk reserve "<db>.reserve": 1 when it is in place (allocated
 * whole), else 0; sets s->reserve_ok. */
int sti_reserve_exists(store *s);
/* Puts it in place: 0, or -1 (no room: nothing stays allocated). */
int sti_reserve_make(store *s);
/* Releases it (its space is then free for the store's writes). */
void sti_reserve_release(store *s, const char *why);

#endif
