/*
 * t.h - the mpmd test framework: tests register themselves with TEST(name)
 * and report with CHECK* macros; tests/runner.c runs them (all, a selection
 * by name, or --list).  A failed CHECK marks the test failed and returns
 * from it.  Tests print the figures they measure with TLOG so a run's log
 * carries the numbers quoted in the README and the issue notes.
 */
#ifndef T_H
#define T_H

#include <math.h>
#include <stdint.h>
#include <stdio.h>

#include "mpm_error.h"

typedef void (*t_fn)(void);
void t_register(const char *name, t_fn fn);
void t_fail(const char *file, int line, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
int t_failed(void);
/* A fresh temporary directory for the current test (removed afterwards
 * unless the test failed); path valid until the test ends. */
const char *t_tmpdir(void);

#define TEST(name)                                              \
    static void t_##name(void);                                 \
    __attribute__((constructor)) static void t_reg_##name(void) \
    {                                                           \
        t_register(#name, t_##name);                            \
    }                                                           \
    static void t_##name(void)

#define TLOG(...)            \
    do {                     \
        printf("    ");      \
        printf(__VA_ARGS__); \
        printf("\n");        \
    } while (0)

#define CHECK(cond)                                  \
    do {                                             \
        if (!(cond)) {                               \
            t_fail(__FILE__, __LINE__, "%s", #cond); \
            return;                                  \
        }                                            \
    } while (0)
#define CHECKF(cond, ...)                            \
    do {                                             \
        if (!(cond)) {                               \
            t_fail(__FILE__, __LINE__, __VA_ARGS__); \
            return;                                  \
        }                                            \
    } while (0)
/* |a - b| <= tol, printing both values on failure */
#define CHECK_NEAR(a, b, tol)                                                                    \
    do {                                                                                         \
        double a_ = (a), b_ = (b), t_ = (tol);                                                   \
        if (!(fabs(a_ - b_) <= t_)) {                                                            \
            t_fail(__FILE__, __LINE__, "%s = %.17g, %s = %.17g, |diff| %.3g > %.3g", #a, a_, #b, \
                   b_, fabs(a_ - b_), t_);                                                       \
            return;                                                                              \
        }                                                                                        \
    } while (0)
#define CHECK_LT(a, b)                                                                  \
    do {                                                                                \
        double a_ = (a), b_ = (b);                                                      \
        if (!(a_ < b_)) {                                                               \
            t_fail(__FILE__, __LINE__, "%s = %.6g is not < %s = %.6g", #a, a_, #b, b_); \
            return;                                                                     \
        }                                                                               \
    } while (0)

/* xorshift64 (Marsaglia): a test's reproducible random numbers from the
 * state *s (never 0): t_urand() in [0, 1), t_srand() in [-1, 1). */
static inline double t_urand(uint64_t *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return (double)(*s >> 11) / 9007199254740992.0;
}
static inline double t_srand(uint64_t *s)
{
    return 2 * t_urand(s) - 1;
}

/* An mpm_error as "field: message" (the proto's spelling), in a buffer
 * that lives to the end of the enclosing block: for TLOG and CHECKF. */
/* Renders e into err (T_ERRLEN bytes) in the JSON mapping's spelling when rc
 * is an error; returns rc. */
#define T_ERRLEN 512
static inline int t_errtext(int rc, const mpm_error *e, char *err)
{
    if (rc) mpm_error_text(e, MPM_FIELD_JSON, err, T_ERRLEN);
    return rc;
}

#define TERR(e) mpm_error_text((e), MPM_FIELD_PROTO, (char[512]){0}, 512)

#endif
