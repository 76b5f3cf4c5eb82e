/*
 * t_reliab_bounds.c - the reliability suite's bounds (rel_*; quick sizes in
 * `make test`, full sizes with MPM_STRESS=full in `make stress`):
 *  - rel_watchers: a stalled watcher (subscribes, never reads) and a
 *    vanished one (a process that subscribes and is killed) on a
 *    snapshot-every-step job: the daemon's peak RSS (VmHWM, reset before
 *    each job) and the job's wall time against no watcher; the peak must
 *    stay within the no-watcher peak + --stream-buffer-mb + a margin;
 *  - rel_disk: a full disk (disk_full_scenario) and a read-only database
 *    (a read-only bind mount of its directory, or the files made
 *    immutable): mpmd refuses to start, naming the file;
 *  - rel_hostile: many hostile inputs through a real mpmd (control bytes,
 *    invalid UTF-8 and over-long case names, requests above the size
 *    limit, inflated protobuf, random frames): each gets its answer and
 *    the daemon answers a Ping after each; logs and listings carry no raw
 *    control byte.
 * Each prints one "reliability: ..." line for docs/reliability.md's table.
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"
#include "t_stress.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <zmq.h>

#include "mpp_case.h"

/* ---- watchers ----------------------------------------------------------------------- */

/* A watcher process: subscribes to job's stream (receiving at most one
 * message into its queue), never reads, and waits to be killed. */
static pid_t vanishing_watcher(const td_daemon *d, unsigned long long job)
{
    fflush(stdout);
    pid_t pid = fork();
    if (pid == 0) {
        void *zctx = zmq_ctx_new();
        void *sub = zctx ? subscribe(zctx, d, job, 1) : NULL;
        if (!sub) _exit(1);
        for (;;) pause();
    }
    return pid;
}

DTEST(rel_watchers)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--verbose", "--stream-buffer-mb", "64", NULL};
    const long stream_mb = 64;
    const int full = t_stress_full();
    const long long steps = full ? 200 : 40;
    char dir[300], path[400];
    td_daemon d;
    td_out o;
    void *zctx = NULL, *sub = NULL;
    pid_t watcher = 0;
    double wall[3] = {0};
    long hwm[3] = {0};
    const char *what[3] = {"none", "stalled", "vanished"};
    snprintf(dir, sizeof dir, "%s/watchers", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(snap_case("watched", steps), dir, "snap.json", path, sizeof path) == 0);
    int can_reset = reset_hwm(d.pid) == 0;

    for (unsigned long long job = 1; job <= 3; job++) {
        if (job == 2) {
            zctx = zmq_ctx_new();
            sub = zctx ? subscribe(zctx, &d, 2, 1) : NULL;
            if (!sub || wait_watched(&d, 2, 20)) {
                t_fail(__FILE__, __LINE__, "job 2's stream never watched");
                goto out;
            }
        }
        if (job == 3) {
            /* the stalled watcher leaves first: until it does, zmq holds
             * the messages queued for it (job 2's budget) */
            zmq_close(sub);
            sub = NULL;
            td_msleep(300);
            watcher = vanishing_watcher(&d, 3);
            if (watcher < 0 || wait_watched(&d, 3, 20)) {
                t_fail(__FILE__, __LINE__, "job 3's stream never watched");
                goto out;
            }
        }
        if (can_reset) reset_hwm(d.pid);
        if (td_ctl(&d, 30, &o, "submit", path, NULL) || o.status || job_of(o.out) != job) {
            t_fail(__FILE__, __LINE__, "submit %llu: %s%s", job, o.out, o.err);
            td_out_free(&o);
            goto out;
        }
        td_out_free(&o);
        if (job == 3) {
            /* it vanishes once the job streams */
            td_wait_steps(&d, 3, steps / 4, 60);
            kill(watcher, SIGKILL);
            waitpid(watcher, NULL, 0);
            watcher = 0;
        }
        if (td_job_peak(&d, job, &wall[job - 1], &hwm[job - 1])) goto out;
    }
    /* the bound: the peak with no watcher + --stream-buffer-mb + a margin
     * for one message in flight (5.5 MB) and the allocator; under ASan the
     * quarantine of freed blocks holds up to 256 MB more, TSan's shadow
     * several times what it watches */
#if defined(__SANITIZE_ADDRESS__)
    const long margin_mb = 256;
#elif defined(__SANITIZE_THREAD__)
    const long margin_mb = 512;
#else
    const long margin_mb = 32;
#endif
    long bound = hwm[0] + (stream_mb + margin_mb) * 1024;
    TLOG("57600 particles, %lld snapshots of 5.5 MB, --stream-buffer-mb %ld (peak reset before "
         "each job: %s):",
         steps, stream_mb, can_reset ? "yes" : "no, peaks since the start");
    for (int k = 0; k < 3; k++)
        TLOG("  watcher %-8s: job %.2f s (x%.2f), mpmd VmHWM %.1f MB", what[k], wall[k],
             wall[0] > 0 ? wall[k] / wall[0] : 0, hwm[k] / 1024.0);
    printf("reliability: watchers steps=%lld stream_buffer_mb=%ld none_s=%.2f none_hwm_mb=%.0f "
           "stalled_s=%.2f stalled_hwm_mb=%.0f vanished_s=%.2f vanished_hwm_mb=%.0f "
           "bound_mb=%.0f\n",
           steps, stream_mb, wall[0], hwm[0] / 1024.0, wall[1], hwm[1] / 1024.0, wall[2],
           hwm[2] / 1024.0, bound / 1024.0);
    for (int k = 1; k < 3; k++)
        if (!(hwm[k] > 0 && hwm[k] <= bound))
            t_fail(__FILE__, __LINE__, "watcher %s: mpmd VmHWM %ld kB above the bound %ld kB",
                   what[k], hwm[k], bound);
    if (!ping_ok(&d)) t_fail(__FILE__, __LINE__, "no Pong after the watchers");
out:
    if (watcher > 0) {
        kill(watcher, SIGKILL);
        waitpid(watcher, NULL, 0);
    }
    if (sub) zmq_close(sub);
    if (zctx) zmq_ctx_term(zctx);
}

/* ---- disk --------------------------------------------------------------------------- */

/* Makes dir read-only: a read-only bind mount of it on itself (root), else
 * its files and itself immutable (chattr +i).  Returns the way (1 mount, 2
 * chattr) or 0 when neither works here. */
static int make_readonly(const char *dir)
{
    char cmd[1200];
    snprintf(cmd, sizeof cmd,
             "mount --bind '%s' '%s' 2>/dev/null && mount -o remount,bind,ro '%s' 2>/dev/null", dir,
             dir, dir);
    if (system(cmd) == 0) return 1;
    snprintf(cmd, sizeof cmd, "umount '%s' 2>/dev/null; chattr +i '%s'/* '%s' 2>/dev/null", dir,
             dir, dir);
    if (system(cmd) == 0) return 2;
    return 0;
}

static void undo_readonly(const char *dir, int how)
{
    char cmd[1200];
    if (how == 1)
        snprintf(cmd, sizeof cmd, "umount '%s'", dir);
    else
        snprintf(cmd, sizeof cmd, "chattr -i '%s' '%s'/* 2>/dev/null", dir, dir);
    if (how && system(cmd) != 0) TLOG("could not undo: %s", cmd);
}

DTEST(rel_disk)
{
    const char *tmp = t_tmpdir();
    char dir[300], epdir[300], ep[400], path[400], st[32];
    td_daemon d;
    td_out o;

    /* the disk full, as daemon_disk_full */
    double t0 = td_now();
    disk_full_scenario("rel_full");
    int full_ok = !t_failed();
    TLOG("disk full: %s in %.1f s", full_ok ? "passed" : "FAILED", td_now() - t0);
    if (!full_ok) return;

    /* a read-only database: a finished run recorded, mpmd stopped */
    snprintf(dir, sizeof dir, "%s/ro", tmp);
    if (td_start(&d, dir, NULL)) return;
    CHECK(write_case(bar_steps(10, 1), dir, "bar.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "FINISHED", 30, st, sizeof st) == 0);
    CHECK(td_stop(&d) == 0);
    int how = make_readonly(dir);
    if (!how) {
        TLOG("SKIP read-only database: neither a read-only bind mount nor chattr +i works here");
        printf("reliability: disk full=ok readonly=skipped\n");
        return;
    }
    /* root writes through permission bits: the check that it is read-only */
    char probe[400];
    snprintf(probe, sizeof probe, "%s/probe", dir);
    FILE *pf = fopen(probe, "w");
    if (pf) {
        fclose(pf);
        remove(probe);
        undo_readonly(dir, how);
        CHECKF(0, "%s is still writable after %s", dir, how == 1 ? "the ro mount" : "chattr +i");
    }
    snprintf(epdir, sizeof epdir, "%s/ro_ep", tmp);
    CHECK(mkdir(epdir, 0700) == 0 || errno == EEXIST);
    snprintf(ep, sizeof ep, "ipc://%s/ctl", epdir);
    const char *argv[] = {"--endpoint", ep, "--db", d.db, NULL};
    int rc = td_run_mpmd(argv, 20, &o);
    undo_readonly(dir, how);
    CHECK(rc == 0);
    char first[300];
    snprintf(first, sizeof first, "%.*s", (int)strcspn(o.err, "\n"), o.err);
    int named = strstr(o.err, d.db) != NULL;
    TLOG("read-only database (%s): mpmd exit %d: %s", how == 1 ? "ro bind mount" : "chattr +i",
         o.status, first);
    printf("reliability: disk full=ok readonly=%s exit=%d named=%d\n",
           o.status > 0 && o.status < 128 && named ? "refused" : "NOT-REFUSED", o.status, named);
    CHECKF(o.status > 0 && o.status < 128 && named,
           "mpmd on a read-only database: exit %d (want a refusal naming %s): %s", o.status, d.db,
           o.err);
    td_out_free(&o);
    /* writable again: the run is there */
    if (td_start(&d, dir, NULL)) return;
    json_t *r = show_json(&d, 1);
    CHECKF(r && !strcmp(jstr(r, "status"), "FINISHED"), "run 1 after the read-only episode");
    json_decref(r);
}

/* ---- hostile names and oversized requests ---------------------------------------------- */

typedef struct {
    long inputs, answered, accepted, refused, dropped, pings;
} hostile_tally;

/* Submits the 1-step bar named by `name` (n bytes, any bytes: put into the
 * packed case as they are) as a raw request; the reply's code
 * ("" for SubmitOk, "-" without a reply) into code. */
static int submit_named(const td_daemon *d, const char *name, size_t n, char *code, size_t cn)
{
    char err[ERRLEN], *text = NULL, mark[300];
    Mpmd__Case *pb = NULL;
    uint8_t *buf = NULL;
    size_t len = 0;
    json_t *c = bar_steps(1, 1), *reply = NULL;
    int rc = -1;
    if (!c || n >= sizeof mark) goto out;
    /* a placeholder of the same length, replaced in the packed bytes */
    memset(mark, 'Q', n);
    mark[n] = 0;
    json_object_set_new(c, "name", json_string(mark));
    text = json_dumps(c, JSON_COMPACT);
    if (!text || td_case_from_json(text, strlen(text), &pb, err, sizeof err) ||
        mpp_case_pack(pb, &buf, &len))
        goto out;
    uint8_t *at = memmem(buf, len, mark, n);
    if (!at) goto out;
    memcpy(at, name, n);
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_bytes = buf, .case_len = len};
    rc = td_request(d->ep, &rq, 30, &reply);
    snprintf(code, cn, "%s",
             rc == 1                                ? "-"
             : json_object_get(reply, "submitOk")   ? ""
             : !strcmp(td_err_field(reply), "name") ? td_err_code(reply)
                                                    : "WRONG-FIELD");
out:
    json_decref(reply);
    json_decref(c);
    free(text);
    free(buf);
    mpp_case_pb_free(&pb);
    return rc;
}

DTEST(rel_hostile)
{
    const char *tmp = t_tmpdir();
    const int full = t_stress_full();
    char dir[300], code[64], name[300];
    td_daemon d;
    hostile_tally h = {0};
    snprintf(dir, sizeof dir, "%s/hostile", tmp);
    if (td_start(&d, dir, NULL)) return;

    /* names: every C0 control byte and DEL between two letters, C1 CSI,
     * invalid UTF-8 (a lone continuation byte, an overlong NUL, a
     * surrogate, a truncated sequence, 0xff), 256 and 257 bytes */
    struct {
        char s[300];
        size_t n;
        int want_ok; /* 1 accepted, 0 INVALID_CASE on name, -1 either */
    } names[64];
    int nn = 0;
    for (int b = 1; b < 32; b++) {
        names[nn].s[0] = 'a';
        names[nn].s[1] = (char)b;
        names[nn].s[2] = 'z';
        names[nn].n = 3;
        names[nn++].want_ok = 1;
    }
    memcpy(names[nn].s, "a\x7fz", 3), names[nn].n = 3, names[nn++].want_ok = 1;
    memcpy(names[nn].s,
           "a\xc2\x9b"
           "31mz",
           6),
        names[nn].n = 6, names[nn++].want_ok = 1;
    const char *bad[] = {"a\x80z", "a\xc0\x80z", "a\xed\xa0\x80z", "a\xe2\x82", "a\xffz"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        names[nn].n = strlen(bad[i]);
        memcpy(names[nn].s, bad[i], names[nn].n);
        names[nn++].want_ok = -1;
    }
    memset(names[nn].s, 'n', 256), names[nn].n = 256, names[nn++].want_ok = 1;
    memset(names[nn].s, 'n', 257), names[nn].n = 257, names[nn++].want_ok = 0;
    for (int i = 0; i < nn; i++) {
        h.inputs++;
        int rc = submit_named(&d, names[i].s, names[i].n, code, sizeof code);
        h.answered += rc == 0;
        h.accepted += rc == 0 && !code[0];
        h.refused += rc == 0 && code[0];
        int ok = rc == 0 && (names[i].want_ok == 1   ? !code[0]
                             : names[i].want_ok == 0 ? !strcmp(code, "INVALID_CASE")
                                                     : !code[0] || !strcmp(code, "INVALID_CASE"));
        snprintf(name, sizeof name, "%.*s", (int)(names[i].n < 8 ? names[i].n : 8), names[i].s);
        CHECKF(ok, "name %d (%zu bytes): %s", i, names[i].n, rc ? "no reply" : code);
        CHECKF(ping_ok(&d), "no Pong after name %d", i);
        h.pings++;
    }

    /* requests above --max-request-bytes (8 MiB): just above, a TOO_LARGE
     * answer; beyond the margin, the connection dropped unread */
    size_t lim = (size_t)8 << 20;
    size_t sizes[] = {lim + 1, lim + 4096, lim + 65536 + 1, lim * 2};
    int nsizes = full ? 4 : 3;
    for (int i = 0; i < nsizes; i++) {
        char *buf = calloc(1, sizes[i]);
        CHECK(buf);
        const void *f[2] = {"", buf};
        size_t l[2] = {0, sizes[i]};
        json_t *reply = NULL;
        int rc = td_frames(d.ep, f, l, 2, sizes[i] > lim + 65536 ? 5 : 30, &reply);
        free(buf);
        h.inputs++;
        h.answered += rc == 0;
        h.dropped += rc == 1;
        int ok = sizes[i] > lim + 65536 ? rc == 1 || !strcmp(td_err_code(reply), "TOO_LARGE")
                                        : rc == 0 && !strcmp(td_err_code(reply), "TOO_LARGE");
        CHECKF(ok, "%zu bytes: %s", sizes[i], rc == 0 ? td_err_code(reply) : "no reply");
        json_decref(reply);
        CHECKF(ping_ok(&d), "no Pong after %zu bytes", sizes[i]);
        h.pings++;
    }

    /* inflated protobuf: empty sub-messages by the hundred thousand */
    size_t bodies[] = {200000, 400000, 1000000, 3000000};
    for (int i = 0; i < (full ? 4 : 2); i++) {
        size_t n = 0;
        uint8_t *m = inflated_request(bodies[i], &n);
        CHECK(m);
        const void *f[2] = {"", m};
        size_t l[2] = {0, n};
        json_t *reply = NULL;
        int rc = td_frames(d.ep, f, l, 2, 30, &reply);
        free(m);
        h.inputs++;
        h.answered += rc == 0;
        CHECKF(rc == 0 && !strcmp(td_err_code(reply), "TOO_LARGE"), "%zu empty bodies: %s",
               bodies[i], rc == 0 ? td_err_code(reply) : "no reply");
        json_decref(reply);
        CHECKF(ping_ok(&d), "no Pong after %zu empty bodies", bodies[i]);
        h.pings++;
    }

    /* random frames, seeded: each answered with an error */
    unsigned seed = (unsigned)time(NULL);
    int nrand = full ? 2000 : 100;
    for (int i = 0; i < nrand; i++) {
        uint8_t frame[512];
        size_t n = 1 + (size_t)(rand_r(&seed) % sizeof frame);
        for (size_t k = 0; k < n; k++) frame[k] = (uint8_t)rand_r(&seed);
        const void *f[2] = {"", frame};
        size_t l[2] = {0, n};
        json_t *reply = NULL;
        int rc = td_frames(d.ep, f, l, 2, 30, &reply);
        h.inputs++;
        h.answered += rc == 0;
        int err = rc == 0 && td_err_code(reply)[0];
        json_decref(reply);
        CHECKF(err, "random frame %d (%zu bytes): %s", i, n, rc ? "no reply" : "not an error");
    }
    CHECK(ping_ok(&d));
    h.pings++;

    /* nothing raw reached the log or the listing */
    size_t len = 0;
    char *log = td_slurp(d.log, &len);
    CHECK(log);
    long raw = 0;
    for (size_t i = 0; i < len; i++) {
        unsigned char ch = (unsigned char)log[i];
        raw += (ch < 32 && ch != '\n') || ch == 0x7f;
    }
    free(log);
    td_out o;
    CHECK(td_ctl(&d, 60, &o, "runs", "--all", NULL) == 0);
    long raw_out = 0;
    for (const char *p = o.out; o.status == 0 && *p; p++) {
        unsigned char ch = (unsigned char)*p;
        raw_out += (ch < 32 && ch != '\n') || ch == 0x7f;
    }
    int listed_ok = o.status == 0;
    td_out_free(&o);
    TLOG("%ld hostile inputs: %ld answered (%ld names accepted, %ld refused), %ld dropped unread, "
         "%ld Pings answered after them; raw control bytes: %ld in the log, %ld in `runs`",
         h.inputs, h.answered, h.accepted, h.refused, h.dropped, h.pings, raw, raw_out);
    printf("reliability: hostile inputs=%ld answered=%ld dropped_unread=%ld pings_ok=%ld "
           "raw_control_bytes=%ld\n",
           h.inputs, h.answered, h.dropped, h.pings, raw + raw_out);
    CHECK(listed_ok && raw == 0 && raw_out == 0);
}
