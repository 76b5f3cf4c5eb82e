/*
 * t_daemon_bounds.c - a real mpmd's bounds and smaller promises: a
 * stalled watcher on a snapshot-every-step job leaves the daemon's memory
 * within --stream-buffer-mb (RSS and the job's wall time measured against
 * no watcher), a watcher subscribed before its job starts gets the
 * snapshots, tcp://localhost and tcp://[::1] endpoints bind, runs
 * listings page with a cursor, `show` of a run that stopped early prints
 * the steps done and the steps planned, and a full disk (RLIMIT_FSIZE on
 * the daemon) ends the running job FAILED with its watchers told while the
 * finished runs stay readable.
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zmq.h>

DTEST(daemon_stalled_watcher_bounded)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--verbose", NULL};
    char dir[300], path[400];
    td_daemon d;
    td_out o;
    void *zctx = NULL, *sub = NULL;
    snprintf(dir, sizeof dir, "%s/stall", tmp);
    /* the dropped snapshots fill ASan's quarantine at a pace that depends
     * on the machine's load (248 MB with no watcher on a loaded machine):
     * td_start_measured() keeps it small */
    if (td_start_measured(&d, dir, extra)) return;
    CHECK(write_case(snap_case("stall", 200), dir, "snap.json", path, sizeof path) == 0);

    /* job 1 alone, then job 2 with a watcher that subscribed before it
     * was submitted and never reads */
    double wall[2];
    long hwm[2];
    for (unsigned long long job = 1; job <= 2; job++) {
        if (job == 2) {
            zctx = zmq_ctx_new();
            sub = zctx ? subscribe(zctx, &d, 2, 1) : NULL;
            if (!sub || wait_watched(&d, 2, 20)) {
                t_fail(__FILE__, __LINE__, "job 2's stream never watched");
                goto out;
            }
        }
        if (td_ctl(&d, 30, &o, "submit", path, NULL) || o.status || job_of(o.out) != job) {
            t_fail(__FILE__, __LINE__, "submit %llu: %s%s", job, o.out, o.err);
            td_out_free(&o);
            goto out;
        }
        td_out_free(&o);
        if (td_job_peak(&d, job, &wall[job - 1], &hwm[job - 1])) goto out;
    }
    TLOG("57600 particles, 200 snapshots of 5.5 MB: no watcher %.2f s, mpmd VmHWM %ld kB; "
         "stalled watcher %.2f s, VmHWM %ld kB, VmRSS after %ld kB",
         wall[0], hwm[0], wall[1], hwm[1], proc_kb(d.pid, "VmRSS:"));
    /* the bound: the job's own memory + --stream-buffer-mb (64) + one
     * message; unbounded it took 1.1 GB (200 x 5.5 MB).  Under ASan the
     * daemon carries shadow memory and a quarantine of freed blocks (job
     * 1's solver among them): 110 MB with no watcher, 284 MB measured;
     * TSan's shadow takes several times the memory it watches: 70 MB with
     * no watcher, 422 MB measured (unbounded: over 1.1 GB either way) */
#if defined(__SANITIZE_ADDRESS__)
    const long bound_mb = 400;
#elif defined(__SANITIZE_THREAD__)
    const long bound_mb = 640;
#else
    const long bound_mb = 200;
#endif
    if (!(hwm[1] > 0 && hwm[1] < bound_mb * 1024))
        t_fail(__FILE__, __LINE__, "mpmd VmHWM %ld kB with a stalled watcher (bound %ld MB)",
               hwm[1], bound_mb);
    /* the stalled watcher still gets what was queued for it, the first
     * snapshots, but not all 200: the rest were dropped for it */
    {
        int snaps = 0, msgs = 0;
        zmq_pollitem_t it = {sub, 0, ZMQ_POLLIN, 0};
        while (zmq_poll(&it, 1, msgs ? 1000 : 5000) == 1) {
            zmq_msg_t part[2];
            int n = td_recv_parts(sub, part, 2);
            if (n == 2 && zmq_msg_size(&part[1]) > 1000000) snaps++;
            for (int i = 0; i < n && i < 2; i++) zmq_msg_close(&part[i]);
            if (!n || ++msgs > 100000) break;
        }
        TLOG("the stalled watcher then reads %d messages, %d of them snapshots", msgs, snaps);
        if (!snaps) t_fail(__FILE__, __LINE__, "the stalled watcher has no snapshot queued");
        if (snaps >= 200) t_fail(__FILE__, __LINE__, "no snapshot dropped for the stalled watcher");
    }
out:
    if (sub) zmq_close(sub);
    if (zctx) zmq_ctx_term(zctx);
}

/* A watcher that subscribes before its job is submitted gets its
 * snapshots (before: its energies only). */
DTEST(daemon_watch_before_start_gets_snapshots)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--verbose", NULL};
    char dir[300], path[400];
    td_daemon d;
    td_out o;
    void *zctx = NULL, *sub = NULL;
    long snaps = 0, energies = 0, finished = 0;
    snprintf(dir, sizeof dir, "%s/early", tmp);
    if (td_start(&d, dir, extra)) return;
    json_t *c = block2d(40, 1, "early");
    CHECK(c);
    set_output(c, "snapshotEvery", json_integer(10));
    CHECK(write_case(c, dir, "early.json", path, sizeof path) == 0);
    zctx = zmq_ctx_new();
    CHECK(zctx);
    sub = subscribe(zctx, &d, 1, 10000);
    if (!sub || wait_watched(&d, 1, 20)) {
        t_fail(__FILE__, __LINE__, "job 1's stream never watched");
        goto out;
    }
    if (td_ctl(&d, 30, &o, "submit", path, NULL) || o.status || job_of(o.out) != 1) {
        t_fail(__FILE__, __LINE__, "submit: %s%s", o.out, o.err);
        td_out_free(&o);
        goto out;
    }
    td_out_free(&o);
    for (double end = td_now() + 60; !finished && td_now() < end;) {
        zmq_pollitem_t it = {sub, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, 1000) != 1) continue;
        zmq_msg_t part[2];
        int n = td_recv_parts(sub, part, 2);
        if (n == 2) {
            mpp_stream m;
            mpm_error e;
            if (mpp_stream_decode(zmq_msg_data(&part[1]), zmq_msg_size(&part[1]), 0, &m, &e) == 0) {
                snaps += m.kind == MPP_STREAM_SNAPSHOT;
                energies += m.kind == MPP_STREAM_ENERGY;
                finished += m.kind == MPP_STREAM_FINISHED;
                mpp_stream_clear(&m);
            }
        }
        for (int i = 0; i < n && i < 2; i++) zmq_msg_close(&part[i]);
    }
    TLOG("subscribed before the submission: %ld snapshots, %ld energy samples, finished %ld", snaps,
         energies, finished);
    /* steps 0 (the initial state), 10, 20, 30, 40 */
    if (!(finished == 1 && snaps == 5 && energies == 41))
        t_fail(__FILE__, __LINE__, "want 5 snapshots, 41 samples and the end; got %ld, %ld, %ld",
               snaps, energies, finished);
out:
    if (sub) zmq_close(sub);
    if (zctx) zmq_ctx_term(zctx);
}

/* tcp://localhost:PORT and tcp://[::1]:PORT bind (the stream on PORT + 1). */
DTEST(daemon_binds_localhost_and_ipv6_loopback)
{
    const char *tmp = t_tmpdir();
    const char *eps[2] = {"localhost", "[::1]"};
    for (int k = 0; k < 2; k++) {
        char dir[300], ep[64];
        td_daemon d;
        td_out o;
        int port = td_tcp_port(5003) + 2 * k;
        snprintf(dir, sizeof dir, "%s/tcp%d", tmp, k);
        snprintf(ep, sizeof ep, "tcp://%s:%d", eps[k], port);
        if (td_start_ep(&d, dir, ep, NULL)) return;
        CHECK(td_ctl(&d, 30, &o, "ping", NULL) == 0);
        CHECKF(o.status == 0, "ping %s: %s%s", ep, o.out, o.err);
        TLOG("%s: %s", ep, o.out);
        td_out_free(&o);
        CHECK(td_stop(&d) == 0);
    }
}

/* runs --limit N pages with a cursor; --all walks every page; the help
 * and the server agree on the cap. */
DTEST(daemon_runs_paging)
{
    const char *tmp = t_tmpdir();
    char dir[300], path[400], st[32];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/paging", tmp);
    if (td_start(&d, dir, NULL)) return;
    CHECK(write_case(bar_steps(10, 5), dir, "bar.json", path, sizeof path) == 0);
    for (int i = 1; i <= 5; i++) {
        CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
        CHECKF(o.status == 0, "submit: %s", o.err);
        td_out_free(&o);
    }
    CHECK(td_wait_status(&d, 5, "FINISHED", 60, st, sizeof st) == 0);

    CHECK(td_ctl(&d, 30, &o, "runs", "--limit", "2", NULL) == 0);
    CHECKF(o.status == 0 && count_lines(o.out) == 3 && strstr(o.err, "--before 4"),
           "runs --limit 2: %s%s", o.out, o.err);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "runs", "--limit", "2", "--before", "4", "--json", NULL) == 0);
    CHECKF(o.status == 0 && count_lines(o.out) == 2 && strstr(o.out, "\"runId\":\"3\"") &&
               strstr(o.out, "\"runId\":\"2\"") && strstr(o.err, "--before 2"),
           "runs --before 4: %s%s", o.out, o.err);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "runs", "--limit", "2", "--before", "2", NULL) == 0);
    CHECKF(o.status == 0 && count_lines(o.out) == 2 && !*o.err, "last page: %s%s", o.out, o.err);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "runs", "--limit", "2", "--all", "--json", NULL) == 0);
    CHECKF(o.status == 0 && count_lines(o.out) == 5 && !*o.err, "runs --all: %s%s", o.out, o.err);
    td_out_free(&o);
    /* the cap: mpmctl refuses what the server would */
    CHECK(td_ctl(&d, 30, &o, "runs", "--limit", "10001", NULL) == 0);
    CHECKF(o.status == 2 && strstr(o.err, "10000"), "--limit 10001: %d %s", o.status, o.err);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "runs", "--help", NULL) == 0);
    CHECKF(strstr(o.out, "10000") && !strstr(o.out, "1000000"), "help: %s", o.out);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "runs", "--limit", "10000", NULL) == 0);
    CHECKF(o.status == 0 && count_lines(o.out) == 6, "--limit 10000: %s%s", o.out, o.err);
    td_out_free(&o);
}

/* show of a run stopped early: steps done, then the steps its case
 * planned (not the steps done twice). */
DTEST(daemon_show_failed_run_steps)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--max-wall-s", "0.5", NULL};
    char dir[300], path[400], st[32], want[128];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/showfail", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(long_case(1000), dir, "long.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "FAILED|FINISHED", 30, st, sizeof st) == 0);
    CHECKF(!strcmp(st, "FAILED"), "job 1: %s", st);
    json_t *r = show_json(&d, 1);
    CHECK(r);
    long long steps = jint(r, "steps");
    json_decref(r);
    CHECK(steps > 0 && steps < LONG_STEPS);
    snprintf(want, sizeof want, "steps       %lld of %lld\n", steps, LONG_STEPS);
    CHECK(td_ctl(&d, 30, &o, "show", "1", NULL) == 0);
    CHECKF(o.status == 0 && strstr(o.out, want), "show 1 (want '%s'):\n%s", want, o.out);
    TLOG("show of a FAILED run: %s", want);
    td_out_free(&o);
}

/* Size of a file, 0 if absent. */
static long long file_size(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0 ? (long long)sb.st_size : 0;
}

/* A full disk, simulated by a file-size limit on the daemon (its writes
 * then fail with EFBIG, as with ENOSPC): the running job that records
 * snapshots ends FAILED with the reason, its watcher gets the Finished
 * with it, Status says so, the finished run stays intact, and the daemon
 * keeps answering and starts again. */
void disk_full_scenario(const char *name)
{
    const char *tmp = t_tmpdir();
    /* no disk budget: job 2 records until the disk, not a budget, stops it */
    const char *extra[] = {"--workers", "1", "--verbose", "--job-max-disk-mb", "0", NULL};
    char dir[300], path[400], wal[420], st[32];
    td_daemon d;
    td_out o;
    void *zctx = NULL, *sub = NULL;
    snprintf(dir, sizeof dir, "%s/%s", tmp, name);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(bar_steps(10, 1), dir, "bar.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "FINISHED|FAILED", 30, st, sizeof st) == 0);
    CHECKF(!strcmp(st, "FINISHED"), "run 1: %s", st);
    td_msleep(200); /* its last writes committed */

    /* the disk is full: no file may grow more than 64 kB beyond today */
    snprintf(wal, sizeof wal, "%s-wal", d.db);
    long long lim = file_size(d.db);
    if (file_size(wal) > lim) lim = file_size(wal);
    lim += 64 * 1024;
    struct rlimit rl = {(rlim_t)lim, (rlim_t)lim};
    CHECKF(prlimit(d.pid, RLIMIT_FSIZE, &rl, NULL) == 0, "prlimit: %s", strerror(errno));

    /* job 2 records a 820 kB snapshot every 10 steps until it is stopped */
    json_t *c = block2d(LONG_STEPS, 100, "full");
    CHECK(c);
    json_object_set_new(json_object_get(c, "grid"), "spacing", json_pack("[f,f]", 0.005, 0.005));
    json_object_set_new(json_object_get(c, "grid"), "nodes", json_pack("[i,i]", 201, 201));
    json_object_del(json_array_get(json_object_get(c, "bodies"), 0), "velocity");
    set_output(c, "snapshotEvery", json_integer(10));
    set_output(c, "snapshotFields", json_pack("[s,s]", "X", "V"));
    set_output(c, "recordSnapshots", json_true());
    CHECK(write_case(c, dir, "full.json", path, sizeof path) == 0);
    zctx = zmq_ctx_new();
    sub = zctx ? subscribe(zctx, &d, 2, 100000) : NULL;
    if (!sub || wait_watched(&d, 2, 20)) {
        t_fail(__FILE__, __LINE__, "job 2's stream never watched");
        goto out;
    }
    if (td_ctl(&d, 30, &o, "submit", path, NULL) || o.status || job_of(o.out) != 2) {
        t_fail(__FILE__, __LINE__, "submit 2: %s%s", o.out, o.err);
        td_out_free(&o);
        goto out;
    }
    td_out_free(&o);
    char error[600] = "";
    int ended = 0;
    for (double end = td_now() + 60; !ended && td_now() < end;) {
        zmq_pollitem_t it = {sub, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, 1000) != 1) continue;
        zmq_msg_t part[2];
        int n = td_recv_parts(sub, part, 2);
        mpp_stream m;
        mpm_error e;
        if (n == 2 &&
            mpp_stream_decode(zmq_msg_data(&part[1]), zmq_msg_size(&part[1]), 0, &m, &e) == 0) {
            if (m.kind == MPP_STREAM_FINISHED) {
                ended = m.finished.status;
                snprintf(error, sizeof error, "%s", m.finished.error);
            }
            mpp_stream_clear(&m);
        }
        for (int i = 0; i < n && i < 2; i++) zmq_msg_close(&part[i]);
    }
    TLOG("job 2 on a full disk: %s: %s", ended ? mpp_status_name(ended) : "no end", error);
    if (ended != MPP_STATUS_FAILED || !strstr(error, "disk full or I/O error")) {
        t_fail(__FILE__, __LINE__, "the watcher got %s '%s'", ended ? mpp_status_name(ended) : "-",
               error);
        goto out;
    }
    /* Status says it too (its end may not be in the store), run 1 is
     * intact, and the daemon answers */
    if (td_job_status(&d, 2, st, sizeof st, NULL) || strcmp(st, "FAILED")) {
        t_fail(__FILE__, __LINE__, "Status(2): %s", st);
        goto out;
    }
    json_t *r = show_json(&d, 1);
    int intact = r && !strcmp(jstr(r, "status"), "FINISHED") && jint(r, "steps") == 10 &&
                 jint(r, "energySamples") == 11;
    json_decref(r);
    if (!intact) {
        t_fail(__FILE__, __LINE__, "run 1 is not intact");
        goto out;
    }
    if (td_ctl(&d, 30, &o, "runs", NULL) || o.status || !strstr(o.out, "FINISHED"))
        t_fail(__FILE__, __LINE__, "runs on a full disk: %s%s", o.out, o.err);
    td_out_free(&o);

    /* a restart (the disk freed): run 1 as it was, run 2 not left running */
    td_stop(&d);
    if (td_start(&d, dir, extra)) goto out;
    r = show_json(&d, 1);
    intact = r && !strcmp(jstr(r, "status"), "FINISHED") && jint(r, "energySamples") == 11;
    json_decref(r);
    /* run 2: ended, or without a record at all when the full disk lost
     * its insert too */
    r = show_json(&d, 2);
    int stopped =
        r ? !strcmp(jstr(r, "status"), "FAILED") || !strcmp(jstr(r, "status"), "INTERRUPTED")
          : td_job_status(&d, 2, st, sizeof st, NULL) != 0;
    TLOG("after a restart: run 1 %s, run 2 %s (%s)", intact ? "intact" : "DAMAGED",
         r ? jstr(r, "status") : "not recorded (its insert was lost)", r ? jstr(r, "error") : "");
    json_decref(r);
    if (!intact || !stopped) t_fail(__FILE__, __LINE__, "after the restart");
out:
    if (sub) zmq_close(sub);
    if (zctx) zmq_ctx_term(zctx);
}

DTEST(daemon_disk_full)
{
    disk_full_scenario("full");
}
