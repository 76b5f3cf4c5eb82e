/*
 * store_read.h - store_read.c's part that the close uses: the pool of
 * read connections.  (Its reads are store.h's.)  Private to server/store/.
 */
#ifndef STORE_READ_H
#define STORE_READ_H

#include "store_internal.h"

/* Closes the idle read connections. */
void sti_readers_close(store *s);

#endif
