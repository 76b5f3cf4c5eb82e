/*
 * store_upkeep.h - store_upkeep.c: the upkeep transaction (kept run ends,
 * crash recovery, or a probe; then the disk reserve).  Private to
 * server/store/.
 */
#ifndef STORE_UPKEEP_H
#define STORE_UPKEEP_H

#include "store_internal.h"

/* The upkeep, on the writer connection (at open, then by the writer
 * thread): in one transaction, the kept run ends and the pending crash
 * recovery (or, with neither, a probe write), then the disk reserve put
 * back.  0 when the transaction committed. */
int sti_upkeep(store *s);
/* 1 when the upkeep has work (under s->mu). */
int sti_upkeep_due_locked(const store *s);
/* Marks the runs below s->recover_below left 'running' or 'queued'
 * 'interrupted', inside the writer's open transaction. */
int sti_recover_rows(store *s);

#endif
