/*
 * t_daemon_budget.c - the disk budgets on a real mpmd (no CURVE: every run
 * is "local"'s): a case whose estimated recorded bytes pass the per-job
 * budget, the daemon's budget or the client's quota is refused at submit
 * with TOO_LARGE naming the field, the estimate and the budget; a job
 * whose automatic dt makes it record more than estimated is stopped by
 * each budget while it runs (FAILED with the budget and the figures in its
 * error and in the Finished message a watcher receives), with what it
 * recorded before intact; a restarted daemon counts what the database
 * holds already.
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

/* 256 particles, a snapshot recorded at every step of 400 (12 doubles per
 * particle: 24576 bytes each, 9.4 MiB in all) */
static json_t *recorded_case(long long steps)
{
    json_t *c = block2d(steps, 10, "recorded");
    if (!c) return NULL;
    set_output(c, "snapshotEvery", json_integer(1));
    set_output(c, "recordSnapshots", json_true());
    return c;
}

/* Automatic dt: 3136 particles (301056 bytes a snapshot) of a soft block
 * (wave speed ~0.105) moving at 0.4.  The submit estimate takes the
 * largest dt the wave speed allows: 2 steps, 3 snapshots with the initial
 * state's (0.86 MiB); the motion makes the steps ~5 times shorter, so it
 * records far more. */
static json_t *fast_case(void)
{
    json_t *c = block2d(1, 1, "fast");
    if (!c) return NULL;
    json_object_del(c, "steps");
    json_object_del(c, "dt");
    json_object_set_new(c, "endTime", json_real(0.45));
    json_t *m = json_array_get(json_object_get(c, "materials"), 0);
    json_object_set_new(m, "youngsModulus", json_real(0.01));
    json_t *b = json_array_get(json_object_get(c, "bodies"), 0);
    json_object_set_new(b, "velocity", json_pack("[f,f]", 0.4, 0.0));
    json_object_set_new(b, "ppc", json_integer(7));
    set_output(c, "snapshotEvery", json_integer(1));
    set_output(c, "recordSnapshots", json_true());
    return c;
}

DTEST(daemon_budget_submit)
{
    const char *tmp = t_tmpdir();
    static const struct {
        const char *flag, *limit, *want;
    } cases[] = {
        {"--job-max-disk-mb", "8", "per-job disk budget of 8 MiB (--job-max-disk-mb)"},
        {"--max-disk-mb", "8", "disk budget of 8 MiB (--max-disk-mb)"},
        {"--client-max-disk-mb", "8", "per-client quota of 8 MiB (--client-max-disk-mb)"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char dir[300], path[500];
        snprintf(dir, sizeof dir, "%s/submit%zu", tmp, i);
        const char *extra[] = {"--job-max-disk-mb", "0", cases[i].flag, cases[i].limit, NULL};
        td_daemon d;
        if (td_start(&d, dir, extra)) return;
        CHECK(write_case(recorded_case(400), dir, "rec.json", path, sizeof path) == 0);
        td_out o;
        CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
        int ok = o.status == 1 && strstr(o.err, "TOO_LARGE") &&
                 strstr(o.err, "output.snapshotEvery") && strstr(o.err, "9.41 MiB") &&
                 strstr(o.err, "401 snapshots of 24576 bytes") && strstr(o.err, cases[i].want);
        TLOG("%s %s: exit %d: %.300s", cases[i].flag, cases[i].limit, o.status, o.err);
        td_out_free(&o);
        CHECKF(ok, "the 9.4 MiB case was not refused naming %s", cases[i].flag);
        /* a third of it fits: it runs and records */
        CHECK(write_case(recorded_case(130), dir, "small.json", path, sizeof path) == 0);
        CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
        unsigned long long job = job_of(o.out);
        td_out_free(&o);
        CHECKF(job == 1, "the 3 MiB case was not accepted");
        char st[32];
        CHECK(td_wait_status(&d, job, "FINISHED|FAILED", 60, st, sizeof st) == 0);
        CHECKF(!strcmp(st, "FINISHED"), "the 3 MiB case ended %s", st);
        CHECK(td_stop(&d) == 0);
    }
}

/* Reads the stream of job 1 from sub until its Finished: 0 with its
 * status and error, or -1. */
static int finished_of(void *sub, int *status, char *error, size_t n)
{
    double end = td_now() + 60;
    while (td_now() < end) {
        zmq_pollitem_t it = {sub, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, 200) <= 0) continue;
        zmq_msg_t part[2];
        int nparts = td_recv_parts(sub, part, 2);
        mpp_stream si = {0};
        mpm_error pe;
        int done = 0;
        if (nparts == 2 &&
            mpp_stream_decode(zmq_msg_data(&part[1]), zmq_msg_size(&part[1]), 0, &si, &pe) == 0 &&
            si.kind == MPP_STREAM_FINISHED) {
            *status = si.finished.status;
            snprintf(error, n, "%s", si.finished.error ? si.finished.error : "");
            done = 1;
        }
        mpp_stream_clear(&si);
        for (int i = 0; i < nparts; i++) zmq_msg_close(&part[i]);
        if (done) return 0;
    }
    return -1;
}

/* One budget stopping the fast case while it runs: a watcher subscribed
 * before it started gets Finished(FAILED) naming the budget; the record
 * says the same, and the snapshots recorded before stay readable. */
static void stopped_by(const char *sub_dir, const char *flag, const char *want,
                       const char *const *more)
{
    const char *tmp = t_tmpdir();
    char dir[300], path[500], sep[400], err[ERRLEN];
    snprintf(dir, sizeof dir, "%s/%s", tmp, sub_dir);
    const char *extra[8] = {"--verbose", flag, "1"};
    size_t ne = 3;
    for (size_t i = 0; more && more[i] && ne < 7; i++) extra[ne++] = more[i];
    extra[ne] = NULL;
    td_daemon d;
    if (td_start(&d, dir, extra)) return;
    void *zctx = zmq_ctx_new(), *sub = zctx ? zmq_socket(zctx, ZMQ_SUB) : NULL;
    int linger = 0;
    snprintf(sep, sizeof sep, "%s.stream", d.ep);
    const char *topic = "job:0000000000000001:";
    int ok = sub && zmq_setsockopt(sub, ZMQ_LINGER, &linger, sizeof linger) == 0 &&
             zmq_setsockopt(sub, ZMQ_SUBSCRIBE, topic, strlen(topic)) == 0 &&
             zmq_connect(sub, sep) == 0 && wait_watched(&d, 1, 20) == 0;
    int status = 0;
    char ferr[1024] = "";
    td_out o;
    if (ok && write_case(fast_case(), dir, "fast.json", path, sizeof path) == 0 &&
        td_ctl(&d, 30, &o, "submit", path, NULL) == 0) {
        ok = o.status == 0 && job_of(o.out) == 1;
        if (!ok) TLOG("submit: %s%s", o.out, o.err);
        td_out_free(&o);
        ok = ok && finished_of(sub, &status, ferr, sizeof ferr) == 0;
    } else {
        ok = 0;
    }
    if (sub) zmq_close(sub);
    if (zctx) zmq_ctx_term(zctx);
    TLOG("%s 1: Finished %d: %s", flag, status, ferr);
    CHECKF(ok, "no Finished for job 1 under %s 1", flag);
    CHECKF(status == MPP_STATUS_FAILED && strstr(ferr, want) && strstr(ferr, "MiB"),
           "job 1 under %s 1 ended %d: %s", flag, status, ferr);
    json_t *r = show_json(&d, 1);
    const json_t *snaps = r ? json_object_get(r, "snapshotSteps") : NULL;
    size_t nsnap = json_array_size(snaps);
    ok = r && !strcmp(jstr(r, "status"), "FAILED") && strstr(jstr(r, "error"), want) &&
         nsnap >= 1 && nsnap <= 3 && jint(r, "steps") > 2;
    TLOG("recorded: %zu snapshots, %lld energy samples, %lld steps", nsnap,
         jint(r, "energySamples"), jint(r, "steps"));
    json_decref(r);
    CHECKF(ok, "the record of job 1 does not say FAILED with the budget, or kept %zu snapshots",
           nsnap);
    /* the last recorded snapshot reads back whole */
    char out[500];
    snprintf(out, sizeof out, "%s/snap.csv", dir);
    CHECK(td_ctl(&d, 30, &o, "snapshot", "1", "-o", out, NULL) == 0);
    ok = o.status == 0;
    td_out_free(&o);
    size_t len = 0;
    char *csv = ok ? td_slurp(out, &len) : NULL;
    size_t lines = csv ? count_lines(csv) : 0;
    free(csv);
    snprintf(
        err, sizeof err,
        "the recorded snapshot reads back %zu lines (want 3137: 3136 particles and the header)",
        lines);
    CHECKF(lines == 3137, "%s", err);
    CHECK(td_stop(&d) == 0);
}

DTEST(daemon_budget_running_job)
{
    stopped_by("run_job", "--job-max-disk-mb", "per-job disk budget reached", NULL);
}

DTEST(daemon_budget_running_client)
{
    stopped_by("run_client", "--client-max-disk-mb", "per-client disk quota reached", NULL);
}

/* The daemon's budget while running, then after a restart: what the
 * database holds counts at submit. */
DTEST(daemon_budget_running_daemon)
{
    stopped_by("run_daemon", "--max-disk-mb", "disk budget reached", NULL);
    if (t_failed()) return;
    const char *tmp = t_tmpdir();
    char dir[300], path[500];
    snprintf(dir, sizeof dir, "%s/run_daemon", tmp);
    const char *extra[] = {"--max-disk-mb", "1", NULL};
    td_daemon d;
    if (td_start(&d, dir, extra)) return;
    /* 21 snapshots (with the initial state's) of 24576 bytes: 0.49 MiB, which an empty
     * database takes */
    CHECK(write_case(recorded_case(20), dir, "twenty.json", path, sizeof path) == 0);
    EXPECT_CTL(&d, 1, "the runs recorded take 0.86 MiB", "submit", path);
    EXPECT_CTL(&d, 1, "disk budget of 1 MiB (--max-disk-mb)", "submit", path);
    CHECK(td_stop(&d) == 0);
}
