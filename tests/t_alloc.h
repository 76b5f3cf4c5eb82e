/*
 * t_alloc.h - allocation-failure injection for the tests (tests/t_alloc.c).
 * mpmtest is linked with -Wl,--wrap for malloc, calloc, realloc,
 * aligned_alloc, strdup and free (the Makefile's TEST_WRAP), so those calls
 * from every object linked into it (the solver, the store, the tests) pass
 * through wrappers.  Disarmed, the wrappers only pass the call on.  Armed,
 * they count the allocations of every thread, make the nth one return
 * NULL, and keep the blocks allocated meanwhile until they are freed, so a
 * test can tell that a failed call left nothing behind.  Allocations made
 * inside shared libraries (libc, SQLite, libzmq) are not seen: ASan's leak
 * checker covers those.  Used by tests/solver/t_alloc_fail.c and
 * tests/store/t_store_alloc_fail.c.
 */
#ifndef T_ALLOC_H
#define T_ALLOC_H

#include <stddef.h>

/* Starts counting; the nth allocation from now on fails (n == 0: none
 * does, the count only).  Forgets the blocks kept by an earlier arming. */
void t_alloc_arm(size_t n);
/* Stops counting and failing.  Returns the number of blocks allocated
 * since t_alloc_arm() and not freed since (SIZE_MAX if there were more
 * than the wrappers can keep track of). */
size_t t_alloc_disarm(void);
/* Allocations counted since t_alloc_arm() (the failed one included). */
size_t t_alloc_count(void);
/* 1 when the armed failure has happened. */
int t_alloc_failed(void);

#endif
