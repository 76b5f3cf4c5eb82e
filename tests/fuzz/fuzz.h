/*
 * fuzz.h - what the libFuzzer targets in tests/fuzz/ share: libFuzzer's
 * entry point (declared here, as -Wmissing-prototypes wants every extern
 * function declared), the limits the targets decode under, and the check
 * that a failure is an honest one (a negative MPM_E* code with a message).
 * The targets are built with clang into build/fuzz (`make fuzz`); each is
 * one file fuzz_<target>.c, its corpus tests/fuzz/corpus/<target>/.
 */
#ifndef FUZZ_H
#define FUZZ_H

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include "mpm_error.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* The daemon's defaults for a request's size (--max-request-bytes), and a
 * particle limit well below the daemon's so that a fuzzed box of many
 * particles costs little to count (the count stops at the limit whatever
 * it is; a lower one keeps the executions fast, not the code different). */
#define FUZZ_MAX_REQUEST ((size_t)8 << 20)
#define FUZZ_MAX_PARTICLES ((size_t)200000)

/* A failed decode or check must say what failed: a code among the MPM_E*
 * values, a message.  Anything else is a bug the fuzzer reports (abort). */
static inline void fuzz_check_error(int rc, const mpm_error *e)
{
    if (rc == 0) return;
    if (rc > 0 || rc != e->code || !e->message[0]) abort();
}

#endif
