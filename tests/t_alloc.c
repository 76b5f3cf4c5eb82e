/*
 * t_alloc.c - the allocation wrappers behind t_alloc.h.  The linker sends
 * each call of malloc, calloc, realloc, aligned_alloc, strdup and free from
 * mpmtest's own objects to __wrap_NAME here (-Wl,--wrap=NAME), and
 * __real_NAME reaches the C library's (or the sanitizer's) function.  This
 * needs no hook in the solver or the store and changes nothing in the
 * programs the tests start (mpmd, mpmctl): only mpmtest is linked so.
 *
 * Disarmed: one relaxed atomic load per call.  Armed: an atomic count
 * picks the call to fail; the blocks allocated while armed are kept in an
 * open-addressing set of pointers under a mutex, removed when freed (a
 * realloc moves its entry), so t_alloc_disarm() returns the ones still
 * live.  A failed realloc leaves p as it was; realloc(p, 0) counts as a
 * free.  In the ASan build, MPMTEST_ALLOC_TRACE=1 in the environment prints
 * the stack of each allocation made to fail.
 */
#include "t_alloc.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/common_interface_defs.h>
#endif

void *__real_malloc(size_t n);
void *__real_calloc(size_t k, size_t n);
void *__real_realloc(void *p, size_t n);
void *__real_aligned_alloc(size_t a, size_t n);
char *__real_strdup(const char *s);
void __real_free(void *p);
void *__wrap_malloc(size_t n);
void *__wrap_calloc(size_t k, size_t n);
void *__wrap_realloc(void *p, size_t n);
void *__wrap_aligned_alloc(size_t a, size_t n);
char *__wrap_strdup(const char *s);
void __wrap_free(void *p);

#define LIVE_CAP ((size_t)1 << 16) /* a power of two */

static atomic_int armed;
static atomic_size_t count, fail_at;
static atomic_int failed;
static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static void *live[LIVE_CAP]; /* NULL: empty; TOMB: removed */
static size_t nlive, nused;
static int overflow;
static char tomb_;
#define TOMB ((void *)&tomb_)

static size_t slot_of(const void *p)
{
    return (size_t)(((uintptr_t)p >> 4) * 0x9e3779b97f4a7c15u >> 16) & (LIVE_CAP - 1);
}

static void live_add(void *p)
{
    pthread_mutex_lock(&mu);
    if (2 * (nused + 1) > LIVE_CAP) {
        overflow = 1;
    } else {
        size_t i = slot_of(p);
        while (live[i] && live[i] != TOMB) i = (i + 1) & (LIVE_CAP - 1);
        if (!live[i]) nused++;
        live[i] = p;
        nlive++;
    }
    pthread_mutex_unlock(&mu);
}

static void live_remove(void *p)
{
    pthread_mutex_lock(&mu);
    for (size_t i = slot_of(p); live[i]; i = (i + 1) & (LIVE_CAP - 1))
        if (live[i] == p) {
            live[i] = TOMB;
            nlive--;
            break;
        }
    pthread_mutex_unlock(&mu);
}

/* 1: this allocation is to fail */
static int take(void)
{
    size_t k = atomic_fetch_add(&count, 1) + 1;
    if (k != atomic_load(&fail_at)) return 0;
    atomic_store(&failed, 1);
#if defined(__SANITIZE_ADDRESS__)
    if (getenv("MPMTEST_ALLOC_TRACE")) {
        fprintf(stderr, "t_alloc: allocation %zu fails here:\n", k);
        __sanitizer_print_stack_trace();
    }
#endif
    return 1;
}

void t_alloc_arm(size_t n)
{
    pthread_mutex_lock(&mu);
    memset(live, 0, sizeof live);
    nlive = nused = 0;
    overflow = 0;
    pthread_mutex_unlock(&mu);
    atomic_store(&count, 0);
    atomic_store(&failed, 0);
    atomic_store(&fail_at, n);
    atomic_store(&armed, 1);
}

size_t t_alloc_disarm(void)
{
    atomic_store(&armed, 0);
    pthread_mutex_lock(&mu);
    size_t n = overflow ? SIZE_MAX : nlive;
    pthread_mutex_unlock(&mu);
    return n;
}

size_t t_alloc_count(void)
{
    return atomic_load(&count);
}

int t_alloc_failed(void)
{
    return atomic_load(&failed);
}

static int is_armed(void)
{
    return atomic_load_explicit(&armed, memory_order_relaxed);
}

void *__wrap_malloc(size_t n)
{
    if (!is_armed()) return __real_malloc(n);
    if (take()) return NULL;
    void *p = __real_malloc(n);
    if (p) live_add(p);
    return p;
}

void *__wrap_calloc(size_t k, size_t n)
{
    if (!is_armed()) return __real_calloc(k, n);
    if (take()) return NULL;
    void *p = __real_calloc(k, n);
    if (p) live_add(p);
    return p;
}

void *__wrap_aligned_alloc(size_t a, size_t n)
{
    if (!is_armed()) return __real_aligned_alloc(a, n);
    if (take()) return NULL;
    void *p = __real_aligned_alloc(a, n);
    if (p) live_add(p);
    return p;
}

char *__wrap_strdup(const char *s)
{
    if (!is_armed()) return __real_strdup(s);
    if (take()) return NULL;
    char *p = __real_strdup(s);
    if (p) live_add(p);
    return p;
}

void *__wrap_realloc(void *p, size_t n)
{
    if (!is_armed()) return __real_realloc(p, n);
    if (p && !n) { /* frees p (glibc), or may */
        live_remove(p);
        return __real_realloc(p, n);
    }
    if (take()) return NULL;
    void *q = __real_realloc(p, n);
    if (q) {
        if (p) live_remove(p);
        live_add(q);
    }
    return q;
}

void __wrap_free(void *p)
{
    if (p && is_armed()) live_remove(p);
    __real_free(p);
}
