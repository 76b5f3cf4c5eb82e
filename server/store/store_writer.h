/*
 * store_writer.h - store_writer.c: the writer thread and its queue, as
 * the open and the close see them.  Private to server/store/.
 */
#ifndef STORE_WRITER_H
#define STORE_WRITER_H

#include "store_internal.h"

/* The writer thread's body (arg: the store). */
void *sti_writer_main(void *arg);
/* Finalizes the statements, frees the queue and the run map. */
void sti_writer_free(store *s);

#endif
