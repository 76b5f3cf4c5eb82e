/*
 * t_store_alloc_fail.c - the store's out-of-memory paths (test
 * alloc_fail_store), on real SQLite files.  A database is made holding one
 * run left RUNNING (as a killed daemon leaves it); then the test counts
 * the allocations of a session on it: store_open() (with its crash
 * recovery), a run inserted, its status, energy samples, a snapshot and
 * its end written, a flush, every kind of read, store_close().  It runs
 * the same session again once per allocation, on a fresh copy of the
 * database, with that one failing (tests/t_alloc.h).  A call during which
 * the allocation failed must return MPM_ENOMEM with store_error() saying
 * so, or succeed with a right result; every other call must succeed; what
 * was written and reported done must read back; and store_close() must
 * leave no block allocated.  ASan's leak checker then looks for anything
 * else (SQLite's own allocations included).
 */
#include "store.h"
#include "t.h"
#include "t_alloc.h"
#include "t_store.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#if defined(__SANITIZE_ADDRESS__)
#include <sanitizer/lsan_interface.h>
#endif

#define SA_SAMPLES 5

static const store_options sa_quiet = {.log = quiet_log};

/* A database holding run 1, RUNNING, at path. */
static int sa_make_template(const char *path)
{
    store *s = NULL;
    if (store_open(path, &sa_quiet, &s)) return -1;
    store_run r = sample_run("left running", MPP_STATUS_RUNNING);
    int64_t id = 0;
    int rc = store_run_insert(s, &r, &id);
    if (!rc) rc = store_flush(s);
    store_close(&s);
    return rc || id != 1 ? -1 : 0;
}

/* path made a fresh copy of the template (closed: no -wal or -shm). */
static int sa_copy(const char *from, const char *path)
{
    static const char *const suffix[] = {"", "-wal", "-shm", ".ends"};
    for (size_t k = 0; k < sizeof suffix / sizeof suffix[0]; k++) {
        char f[4200];
        snprintf(f, sizeof f, "%s%s", path, suffix[k]);
        unlink(f);
    }
    FILE *in = fopen(from, "rb"), *out = in ? fopen(path, "wb") : NULL;
    char buf[8192];
    size_t n;
    int rc = in && out ? 0 : -1;
    while (!rc && (n = fread(buf, 1, sizeof buf, in)) > 0)
        if (fwrite(buf, 1, n, out) != n) rc = -1;
    if (in && ferror(in)) rc = -1;
    if (out && fclose(out)) rc = -1;
    if (in) fclose(in);
    return rc;
}

/* The state of one pass. */
typedef struct {
    size_t n;   /* the allocation that fails (0: none) */
    int before; /* t_alloc_failed() before the current call */
    const char *what;
} sa_pass;

static void sa_begin(sa_pass *p, const char *what)
{
    p->before = t_alloc_failed();
    p->what = what;
}

/* The verdict on a call's rc: 1 when the call is to be taken as done, 0
 * when it failed as it should (the armed allocation failed during it, rc
 * MPM_ENOMEM and store_error() saying so), -1 (reported) when wrong. */
static int sa_end(sa_pass *p, int rc)
{
    int hit = !p->before && t_alloc_failed();
    if (!rc) {
        if (hit) TLOG("allocation %zu failed in %s, which succeeded", p->n, p->what);
        return 1;
    }
    if (hit && rc == MPM_ENOMEM && store_error()->code == MPM_ENOMEM) return 0;
    t_fail(__FILE__, __LINE__, "allocation %zu%s: %s returned %d: %s", p->n,
           hit ? " failed in it" : " not in it", p->what, rc, store_error()->message);
    return -1;
}

#define SA_CALL(p, what, call)              \
    do {                                    \
        sa_begin(p, what);                  \
        if ((ok = sa_end(p, (call))) < 0) { \
            rc = -1;                        \
            goto out;                       \
        }                                   \
    } while (0)

#define SA_EXPECT(p, cond)                                                                        \
    do {                                                                                          \
        if (!(cond)) {                                                                            \
            t_fail(__FILE__, __LINE__, "allocation %zu: after %s: %s", (p)->n, (p)->what, #cond); \
            rc = -1;                                                                              \
            goto out;                                                                             \
        }                                                                                         \
    } while (0)

/* One session with allocation n failing.  0 or -1 (reported). */
static int sa_session(const char *tmpl, const char *path, size_t n, size_t *count)
{
    sa_pass p = {.n = n};
    int rc = 0, ok;
    store *s = NULL;
    store_run r;
    memset(&r, 0, sizeof r);
    store_run *runs = NULL;
    size_t nruns = 0;
    mpm_energy_sample *es = NULL;
    size_t nes = 0;
    store_snapshot snap;
    memset(&snap, 0, sizeof snap);
    store_run_extra x;
    memset(&x, 0, sizeof x);
    store_owner_total *tot = NULL;
    size_t ntot = 0;
    if (sa_copy(tmpl, path)) {
        t_fail(__FILE__, __LINE__, "cannot copy %s to %s", tmpl, path);
        return -1;
    }

    t_alloc_arm(n);
    SA_CALL(&p, "store_open", store_open(path, &sa_quiet, &s));
    SA_EXPECT(&p, ok ? s != NULL : s == NULL);
    if (!ok) goto out;

    store_run in = sample_run("second", MPP_STATUS_QUEUED);
    in.owner = "someone";
    int64_t id = 0;
    SA_CALL(&p, "store_run_insert", store_run_insert(s, &in, &id));
    int inserted = ok;
    SA_EXPECT(&p, !inserted || id == 2);
    int running = 0, nsamples = 0, snapped = 0, finished = 0;
    if (inserted) {
        SA_CALL(&p, "store_run_set_status",
                store_run_set_status(s, 2, MPP_STATUS_RUNNING, 1700000001.0, NULL));
        running = ok;
        mpm_energy_sample e[SA_SAMPLES];
        for (int i = 0; i < SA_SAMPLES; i++) e[i] = make_sample(2, i);
        SA_CALL(&p, "store_energy_append", store_energy_append(s, 2, e, SA_SAMPLES));
        nsamples = ok ? SA_SAMPLES : 0;
        static const unsigned char blob[64] = {1, 2, 3, 4, 5, 6, 7, 8};
        store_snapshot sp = {2, 40, 0.04, 8, 2, 3u, blob, sizeof blob};
        SA_CALL(&p, "store_snapshot_put", store_snapshot_put(s, &sp));
        snapped = ok;
        store_run_end end = {.status = MPP_STATUS_FINISHED,
                             .finished_at = 1700000002.0,
                             .steps = 50,
                             .wall_s = 1.5,
                             .warning = "a warning"};
        SA_CALL(&p, "store_run_finish", store_run_finish(s, 2, &end));
        finished = ok; /* a queued run may end too */
    }
    SA_CALL(&p, "store_flush", store_flush(s));

    SA_CALL(&p, "store_run_get", store_run_get(s, 1, &r));
    if (ok)
        SA_EXPECT(&p, r.status == MPP_STATUS_INTERRUPTED && !strcmp(r.name, "left running") &&
                          r.case_len == case_bytes_len &&
                          !memcmp(r.case_pb, case_bytes, case_bytes_len) && r.error &&
                          !strcmp(r.error, STORE_INTERRUPTED_RUNNING));
    store_run_clear(&r);
    SA_CALL(&p, "store_run_list", store_run_list(s, NULL, &runs, &nruns));
    if (ok)
        SA_EXPECT(&p, nruns == (size_t)(1 + inserted) && runs[nruns - 1].id == 1 &&
                          (!inserted || (runs[0].id == 2 &&
                                         runs[0].status == (finished  ? MPP_STATUS_FINISHED
                                                            : running ? MPP_STATUS_RUNNING
                                                                      : MPP_STATUS_QUEUED) &&
                                         !strcmp(runs[0].owner, "someone"))));
    store_run_list_free(runs, nruns);
    runs = NULL;
    if (inserted) {
        SA_CALL(&p, "store_energy_read", store_energy_read(s, 2, 0, 0, &es, &nes));
        if (ok) {
            SA_EXPECT(&p, nes == (size_t)nsamples);
            for (size_t i = 0; i < nes; i++) SA_EXPECT(&p, sample_equals(es, i, 2, (int64_t)i));
        }
        free(es);
        es = NULL;
        if (snapped) {
            SA_CALL(&p, "store_snapshot_get", store_snapshot_get(s, 2, -1, &snap));
            if (ok)
                SA_EXPECT(&p, snap.step == 40 && snap.size == 64 &&
                                  ((const unsigned char *)snap.data)[7] == 8);
            store_snapshot_clear(&snap);
        }
        SA_CALL(&p, "store_run_extras", store_run_extras(s, 2, &x));
        if (ok)
            SA_EXPECT(&p, x.energy_count == nsamples && x.n_snapshots == (size_t)snapped &&
                              (!snapped || x.snapshot_steps[0] == 40));
        store_run_extra_clear(&x);
    }
    SA_CALL(&p, "store_owner_totals", store_owner_totals(s, &tot, &ntot));
    if (ok) SA_EXPECT(&p, ntot == (size_t)(1 + inserted));
    store_owner_totals_free(tot, ntot);
    tot = NULL;

out:
    store_run_clear(&r);
    store_run_list_free(runs, nruns);
    free(es);
    store_snapshot_clear(&snap);
    store_run_extra_clear(&x);
    store_owner_totals_free(tot, ntot);
    store_close(&s);
    *count = t_alloc_count();
    int failed = t_alloc_failed();
    size_t live = t_alloc_disarm();
    if (rc) return rc;
    if (n && !failed) {
        t_fail(__FILE__, __LINE__, "allocation %zu never came (%zu made)", n, *count);
        return -1;
    }
    if (live) {
        t_fail(__FILE__, __LINE__, "allocation %zu failed: %zu block(s) left allocated", n, live);
        return -1;
    }
    return 0;
}

TEST(alloc_fail_store)
{
    char tmpl[4096], path[4096];
    snprintf(tmpl, sizeof tmpl, "%s", db_path("template.db"));
    snprintf(path, sizeof path, "%s", db_path("alloc.db"));
    CHECKF(sa_make_template(tmpl) == 0, "cannot make %s: %s", tmpl, store_error()->message);
    size_t count = 0, c;
    if (sa_session(tmpl, path, 0, &count)) return;
    CHECKF(count > 10, "only %zu allocations counted", count);
    for (size_t n = 1; n <= count; n++)
        if (sa_session(tmpl, path, n, &c)) return;
    TLOG("a store session: %zu allocations, each failed once: MPM_ENOMEM or a right result, "
         "nothing left",
         count);
#if defined(__SANITIZE_ADDRESS__)
    CHECKF(!__lsan_do_recoverable_leak_check(), "ASan's leak checker found leaks (report above)");
#endif
}
