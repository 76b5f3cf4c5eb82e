/*
 * t_daemon_hostile.c - a real mpmd against hostile input and a second
 * daemon: requests above the size limit refused unread, crafted messages
 * that would inflate in memory, case names (length, control bytes in the
 * log and in mpmctl's output), the single-daemon lock through a symlink,
 * an ipc:// endpoint that a live daemon owns or a dead one left, and the
 * step limit with automatic dt.
 */
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "mpp_case.h"

/* ---- oversized requests --------------------------------------------------------------- */

DTEST(daemon_oversized_request_refused_unread)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--max-request-bytes", "100000", NULL};
    char dir[300], path[400];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/big", tmp);
    if (td_start(&d, dir, extra)) return;
    long rss0 = proc_kb(d.pid, "VmHWM:");

    /* 256 MB in one frame: libzmq reads its size and drops the connection
     * (ZMQ_MAXMSGSIZE = limit + 64 KiB); nothing of it is allocated */
    size_t big = (size_t)256 << 20;
    char *buf = calloc(1, big);
    CHECK(buf);
    const void *f[2] = {"", buf};
    size_t l[2] = {0, big};
    json_t *reply = NULL;
    double t0 = td_now();
    int rc = td_frames(d.ep, f, l, 2, 3, &reply);
    free(buf);
    CHECKF(rc == 1, "a 256 MB request got %s", rc == 0 ? td_err_code(reply) : "an error");
    long rss1 = proc_kb(d.pid, "VmHWM:");
    TLOG("256 MB request: dropped (no reply) in %.2f s; mpmd VmHWM %ld kB before, %ld kB after",
         td_now() - t0, rss0, rss1);
    CHECKF(rss1 > 0 && rss1 < rss0 + 32 * 1024, "mpmd grew from %ld to %ld kB", rss0, rss1);
    CHECK(ping_ok(&d));

    /* just over the limit (within the margin): a TOO_LARGE reply */
    buf = calloc(1, 100001);
    CHECK(buf);
    f[1] = buf;
    l[1] = 100001;
    rc = td_frames(d.ep, f, l, 2, 10, &reply);
    free(buf);
    CHECKF(rc == 0 && !strcmp(td_err_code(reply), "TOO_LARGE"), "100001 bytes: %s",
           rc == 0 ? td_err_code(reply) : "no reply");
    json_decref(reply);

    /* mpmctl says why when the server drops its connection: a case of
     * 15000 explicit particles (240 kB packed) */
    {
        json_t *c = bar_steps(10, 1);
        CHECK(c);
        json_t *pts = json_object_get(json_array_get(json_object_get(c, "bodies"), 0), "points");
        json_t *x = json_array(), *vol = json_array();
        for (int i = 0; i < 15000; i++) {
            json_array_append_new(x, json_real(0.1 + 0.8 * i / 15000.0));
            json_array_append_new(vol, json_real(1e-5));
        }
        json_object_set_new(pts, "x", x);
        json_object_set_new(pts, "volume", vol);
        json_object_del(pts, "v");
        json_object_del(pts, "mass");
        json_object_del(pts, "stress");
        json_object_del(pts, "halfLength");
        CHECK(write_case(c, dir, "big.json", path, sizeof path) == 0);
    }
    t0 = td_now();
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    double secs = td_now() - t0;
    CHECKF(o.status != 0 && strstr(o.err, "may exceed the server's limit"),
           "mpmctl submit of a 240 kB case: status %d, %s%s", o.status, o.out, o.err);
    TLOG("mpmctl (%.2f s): %s", secs, o.err);
    CHECKF(secs < 10, "mpmctl took %.1f s (the timeout, not the dropped connection)", secs);
    td_out_free(&o);
    CHECK(ping_ok(&d));
}

/* ---- the unpack budget ---------------------------------------------------------------- */

DTEST(daemon_unpack_budget)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--max-request-bytes", "1000000", NULL};
    char dir[300];
    td_daemon d;
    snprintf(dir, sizeof dir, "%s/budget", tmp);
    if (td_start(&d, dir, extra)) return;

    enum { NB = 400000 };
    size_t n = 0;
    uint8_t *m = inflated_request(NB, &n);
    CHECK(m);
    /* at least: the message header protobuf-c puts in every struct (24
     * bytes), Body's fields (over 40) and the pointer to it */
    size_t would = NB * (size_t)(24 + 40 + 8);
    TLOG("crafted request: %zu bytes; unpacked it would take %zu bytes (%.0fx), budget %zu", n,
         would, (double)would / (double)n, mpp_unpack_budget(n));
    CHECK(would > mpp_unpack_budget(n));

    /* in-process: the library refuses it */
    char *json = NULL, err[ERRLEN];
    int rc = td_msg_bytes_to_json(MPP_MSG_REQUEST, m, n, 0, 0, &json, err, sizeof err);
    free(json);
    CHECKF(rc == MPM_ETOOBIG && strstr(err, "memory"), "bytes_to_json: %d %s", rc, err);

    /* the daemon: TOO_LARGE, and it keeps answering */
    const void *f[2] = {"", m};
    size_t l[2] = {0, n};
    json_t *reply = NULL;
    rc = td_frames(d.ep, f, l, 2, 20, &reply);
    free(m);
    CHECKF(rc == 0 && !strcmp(td_err_code(reply), "TOO_LARGE") &&
               strstr(td_err_msg(reply), "memory"),
           "crafted request: %s %s", rc == 0 ? td_err_code(reply) : "no reply",
           rc == 0 ? td_err_msg(reply) : "");
    TLOG("mpmd: %s %s", td_err_code(reply), td_err_msg(reply));
    json_decref(reply);
    CHECK(ping_ok(&d));

    /* an honest case still decodes: the good 2D case is accepted */
    CHECK(submit_patched(&d, "\"endTime\": 1", "\"endTime\": 0.01", &reply) == 0);
    CHECKF(json_object_get(reply, "submitOk"), "good case: %s %s", td_err_code(reply),
           td_err_msg(reply));
    json_decref(reply);
}

/* ---- names ---------------------------------------------------------------------------- */

DTEST(daemon_case_names)
{
    const char *tmp = t_tmpdir();
    char dir[300], to[1200], name[400];
    td_daemon d;
    td_out o;
    json_t *reply = NULL;
    snprintf(dir, sizeof dir, "%s/names", tmp);
    if (td_start(&d, dir, NULL)) return;

    /* 257 bytes: INVALID_CASE naming the field and the limit; 256: accepted */
    memset(name, 'n', 257);
    name[257] = 0;
    snprintf(to, sizeof to, "{\"name\": \"%s\", \"grid\"", name);
    CHECK(submit_patched(&d, "{\"grid\"", to, &reply) == 0);
    CHECKF(!strcmp(td_err_code(reply), "INVALID_CASE") && !strcmp(td_err_field(reply), "name") &&
               strstr(td_err_msg(reply), "256"),
           "257-byte name: %s field %s: %s", td_err_code(reply), td_err_field(reply),
           td_err_msg(reply));
    TLOG("257-byte name: %s %s", td_err_code(reply), td_err_msg(reply));
    json_decref(reply);
    name[256] = 0;
    snprintf(to, sizeof to, "{\"name\": \"%s\", \"grid\"", name);
    CHECK(submit_patched(&d, "{\"grid\"", to, &reply) == 0);
    CHECKF(json_object_get(reply, "submitOk"), "256-byte name: %s", td_err_msg(reply));
    json_decref(reply);

    /* a newline cannot forge a log line; ESC / OSC / a UTF-8 C1 CSI never
     * reach a terminal through runs or show */
    CHECK(submit_patched(&d, "{\"grid\"",
                         "{\"name\": \"ok\\n2001-01-01T00:00:00.000Z mpmd ERROR forged\", \"grid\"",
                         &reply) == 0);
    CHECKF(json_object_get(reply, "submitOk"), "newline name: %s", td_err_msg(reply));
    json_decref(reply);
    CHECK(submit_patched(&d, "{\"grid\"",
                         "{\"name\": \"a\\u001b]0;pwned\\u0007b\\u009b31m\", \"grid\"",
                         &reply) == 0);
    CHECKF(json_object_get(reply, "submitOk"), "ESC name: %s", td_err_msg(reply));
    /* uint64 fields are JSON strings in the protobuf JSON mapping */
    unsigned long long esc_id = strtoull(
        json_string_value(json_object_get(json_object_get(reply, "submitOk"), "runId"))
            ? json_string_value(json_object_get(json_object_get(reply, "submitOk"), "runId"))
            : "0",
        NULL, 10);
    CHECK(esc_id == 3);
    json_decref(reply);
    CHECK(td_wait_status(&d, esc_id, "FINISHED|FAILED", 60, to, sizeof to) == 0);

    size_t len = 0;
    char *log = td_slurp(d.log, &len);
    CHECK(log);
    int forged = strstr(log, "\n2001-01-01T00:00:00.000Z") != NULL;
    int escaped = strstr(log, "'ok\\n2001-01-01T00:00:00.000Z mpmd ERROR forged'") != NULL;
    int raw_esc = memchr(log, 0x1b, len) != NULL || strstr(log, "\xc2\x9b") != NULL;
    free(log);
    CHECKF(!forged && escaped && !raw_esc, "log: forged line %d, escaped name %d, raw ESC %d",
           forged, escaped, raw_esc);

    char id[32];
    snprintf(id, sizeof id, "%llu", esc_id);
    const char *cmds[2][3] = {{"runs", NULL, NULL}, {"show", id, NULL}};
    for (int k = 0; k < 2; k++) {
        CHECK(td_ctlv(&d, 30, &o, cmds[k]) == 0);
        CHECKF(o.status == 0 && !strchr(o.out, 0x1b) && !strchr(o.out, 0x07) &&
                   !strstr(o.out, "\xc2\x9b") &&
                   strstr(o.out, k ? "a\\x1b]0;pwned\\x07b\\u009b31m" : "a\\x1b]0;pwned\\x07b"),
               "mpmctl %s: status %d:\n%s", cmds[k][0], o.status, o.out);
        td_out_free(&o);
    }
    TLOG("log and mpmctl runs/show show the names escaped: a\\x1b]0;pwned\\x07b\\u009b31m");
}

/* ---- one daemon per database, per endpoint ---------------------------------------------- */

DTEST(daemon_single_through_symlink_and_ipc)
{
    const char *tmp = t_tmpdir();
    char dir[300], dir2[300], link[400], ep2[400], db2[400], path[400], st[32];
    td_daemon d, d2;
    td_out o;
    snprintf(dir, sizeof dir, "%s/lockA", tmp);
    snprintf(dir2, sizeof dir2, "%s/lockB", tmp);
    if (td_start(&d, dir, NULL)) return;
    CHECK(mkdir(dir2, 0700) == 0 || errno == EEXIST);
    CHECK(write_case(long_case(100), dir, "long.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 1, "submit: %s%s", o.out, o.err);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "RUNNING", 20, st, sizeof st) == 0);

    /* the same database through a symlink: refused, as ERROR */
    snprintf(link, sizeof link, "%s/link.db", dir2);
    CHECK(symlink(d.db, link) == 0);
    snprintf(ep2, sizeof ep2, "ipc://%s/ctl", dir2);
    {
        const char *argv[] = {"--endpoint", ep2, "--db", link, NULL};
        CHECK(td_run_mpmd(argv, 20, &o) == 0);
        CHECKF(o.status != 0 && strstr(o.err, "in use by another mpmd") &&
                   strstr(o.err, " ERROR ") && !strstr(o.err, " WARN "),
               "second mpmd through a symlink: status %d: %s", o.status, o.err);
        TLOG("symlink: %s", o.err);
        td_out_free(&o);
    }
    /* the live daemon's run is untouched */
    CHECK(td_job_status(&d, 1, st, sizeof st, NULL) == 0);
    CHECKF(!strcmp(st, "RUNNING"), "job 1 is %s", st);

    /* the live daemon's ipc endpoint, with another database: refused */
    snprintf(db2, sizeof db2, "%s/other.db", dir2);
    {
        const char *argv[] = {"--endpoint", d.ep, "--db", db2, NULL};
        CHECK(td_run_mpmd(argv, 20, &o) == 0);
        CHECKF(o.status != 0 && strstr(o.err, "another process"),
               "second mpmd on the live endpoint: status %d: %s", o.status, o.err);
        TLOG("ipc takeover: %s", o.err);
        td_out_free(&o);
    }
    CHECK(ping_ok(&d));
    CHECK(td_ctl(&d, 30, &o, "cancel", "1", NULL) == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "CANCELLED|FAILED|FINISHED|INTERRUPTED", 20, st, sizeof st) == 0);
    CHECKF(!strcmp(st, "CANCELLED"), "job 1 ended %s", st);

    /* a dead daemon's ipc file is stale: a new daemon binds it */
    td_kill9(&d);
    CHECK(access(d.ep + 6, F_OK) == 0); /* the socket file stayed */
    if (td_start_ep(&d2, dir2, d.ep, NULL)) return;
    CHECK(ping_ok(&d2));
    TLOG("stale ipc file of a killed mpmd: reused");
}

/* ---- the step limit with automatic dt --------------------------------------------------- */

DTEST(daemon_max_steps_automatic_dt)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--max-steps", "100", NULL};
    char dir[300], st[64];
    td_daemon d;
    json_t *reply = NULL;
    snprintf(dir, sizeof dir, "%s/steps", tmp);
    if (td_start(&d, dir, extra)) return;

    /* c = 1.054 (E = rho = 1, nu = 0.2, plane strain), h = 0.1, C = 0.5: at
     * least endTime * 21.1 steps, whatever the particles do */
    CHECK(submit_patched(&d, "\"endTime\": 1", "\"endTime\": 1e9", &reply) == 0);
    CHECKF(!strcmp(td_err_code(reply), "TOO_LARGE") && !strcmp(td_err_field(reply), "endTime") &&
               strstr(td_err_msg(reply), "at least"),
           "endTime 1e9, automatic dt: %s field %s: %s", td_err_code(reply), td_err_field(reply),
           td_err_msg(reply));
    TLOG("%s", td_err_msg(reply));
    json_decref(reply);

    /* 4.6 * 21.1 = 97 steps at the least, but the box's speed 0.1 makes
     * dt smaller: 4.6 * 23.1 = 106 steps; stopped FAILED at the limit */
    CHECK(submit_patched(&d, "\"endTime\": 1", "\"endTime\": 4.6", &reply) == 0);
    CHECKF(json_object_get(reply, "submitOk"), "endTime 4.6: %s", td_err_msg(reply));
    json_decref(reply);
    CHECK(td_wait_status(&d, 1, "FINISHED|FAILED", 60, st, sizeof st) == 0);
    json_t *r = show_json(&d, 1);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "status"), "FAILED") && jint(r, "steps") == 100 &&
               strstr(jstr(r, "error"), "--max-steps"),
           "run 1: %s after %lld steps: %s", jstr(r, "status"), jint(r, "steps"), jstr(r, "error"));
    TLOG("run 1: %s at step %lld: %s", jstr(r, "status"), jint(r, "steps"), jstr(r, "error"));
    json_decref(r);
}
