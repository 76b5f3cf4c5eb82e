/*
 * store_apply.h - store_apply.c: the writer connection's prepared
 * statements and the transactions that apply queued writes.  Writer
 * thread only (and the open, before the thread starts).  Private to
 * server/store/.
 */
#ifndef STORE_APPLY_H
#define STORE_APPLY_H

#include "store_internal.h"

/* Prepares the writer's statements on s->wdb; finalizes them. */
int sti_apply_prepare(store *s);
void sti_apply_free(store *s);
/* Applies a batch of n ops (a list) in one transaction; every failure is
 * recorded (counted, logged, its enqueue numbers remembered; a lost
 * transaction keeps the batch's run ends and degrades the store). */
void sti_apply_batch(store *s, op *batch, size_t n);
/* Applies one op inside the open transaction: 0, or -1 after recording
 * the error. */
int sti_apply_op(store *s, op *o);
/* Steps one of the statements without parameters (WS_BEGIN, WS_COMMIT,
 * WS_ROLLBACK): SQLITE_OK or SQLite's code. */
int sti_ws_simple(store *s, int which);
/* Makes the notify fd readable (a commit happened). */
void sti_notify(store *s);

#endif
