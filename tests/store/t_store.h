/*
 * t_store.h - helpers shared by the store tests (t_store*.c): database
 * paths in the test's directory, log capture, sample runs and energy
 * samples with awkward values.
 */
#ifndef T_STORE_H
#define T_STORE_H

#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

#include "store.h"

/* Collects log lines (the store may log from its writer thread). */
typedef struct {
    pthread_mutex_t mu;
    int n_dropped, n_cap, n_interrupted, n_new, n_migrated, n_total;
    char migrated[200]; /* the last "schema migrated" line */
    char last[512];
} logcap;

/* The protobuf bytes of a small case, stored with the sample runs. */
extern const unsigned char case_bytes[];
extern const size_t case_bytes_len;

const char *db_path(const char *name);

void cap_log(void *ud, const char *msg);

void quiet_log(void *ud, const char *msg);

store_run sample_run(const char *name, mpp_status st);

/* A deterministic sample with awkward values; the same call gives the same
 * bits, so read-back can be compared exactly.  dim is that of sample_run()'s
 * runs (reads give the run's dim). */
mpm_energy_sample make_sample(int64_t run, int64_t i);

/* 1 if sample es[i] equals make_sample(run, seq) bit for bit. */
int sample_equals(const mpm_energy_sample *es, size_t i, int64_t run, int64_t seq);

#endif
