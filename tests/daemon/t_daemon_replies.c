/*
 * t_daemon_replies.c - the request socket's bounds against one hostile
 * client, each measured on a real mpmd (VmRSS/VmHWM from /proc) while a
 * second client, connected before the attack, pings it every 20 ms:
 *  - unread replies: a client asks for many pages of a long energy series
 *    and never reads; the bytes queued for it stay within
 *    --connection-reply-buffer-mb, the rest is answered UNAVAILABLE naming
 *    the setting, and memory returns near its baseline when it leaves;
 *  - large requests: several connections pipeline requests just below
 *    --max-request-bytes; the daemon holds at most three per connection;
 *  - listings: ListRuns and GetEnergy pages are cut at --page-max-bytes
 *    (mpmctl still gets every sample) and many large listings at once
 *    leave the pinger answered;
 *  - connections: idle connections beyond --max-connections are refused
 *    (the log names the setting), connections that never greet are closed
 *    after --handshake-timeout-s, so new clients are answered again.
 * daemon_* run at quick size in `make test`; rel_replies_* are the same
 * probes at full size under MPM_STRESS=full (quick size otherwise).
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"
#include "t_stress.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>
#include <zmq.h>

/* ---- measuring ------------------------------------------------------------------- */

/* A DEALER that reads nothing: its receive queue holds one message and a
 * small socket buffer, so that what it does not read stays in the
 * daemon. */
static void *deaf_dealer(void *ctx, const char *ep)
{
    void *s = zmq_socket(ctx, ZMQ_DEALER);
    int zero = 0, one = 1, hwm = 100000, rcvbuf = 4096;
    if (!s) return NULL;
    if (zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) ||
        zmq_setsockopt(s, ZMQ_RCVHWM, &one, sizeof one) ||
        zmq_setsockopt(s, ZMQ_SNDHWM, &hwm, sizeof hwm) ||
        zmq_setsockopt(s, ZMQ_RCVBUF, &rcvbuf, sizeof rcvbuf) || zmq_connect(s, ep)) {
        zmq_close(s);
        return NULL;
    }
    return s;
}

static int send_request(void *s, const mpp_request *rq)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    if (mpp_request_encode(rq, &buf, &len)) return -1;
    int rc = zmq_send(s, "", 0, ZMQ_SNDMORE) < 0 || zmq_send(s, buf, len, 0) < 0 ? -1 : 0;
    free(buf);
    return rc;
}

/* Sanitizers multiply the daemon's own memory (shadow, quarantine): the
 * margins over a bound are wider there. */
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define SLACK_MB 96
#else
#define SLACK_MB 32
#endif

/* What "near its baseline" allows after the hostile client left: SQLite's
 * page caches and what glibc keeps after malloc_trim. */
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define LEAVE_MB 48
#else
#define LEAVE_MB 24
#endif

/* The stated ping bound under each attack (docs/manual.md). */
#define PING_BOUND_S 1.0

/* ---- unread replies --------------------------------------------------------------- */

/* A finished run with `samples` energy samples (the 1D bar, energy every
 * step): 0, or -1 after failing the test. */
static int energy_run(td_daemon *d, long long samples)
{
    char path[400];
    td_out o;
    if (write_case(bar_steps(samples - 1, 1), d->dir, "long.json", path, sizeof path)) {
        t_fail(__FILE__, __LINE__, "cannot write the case");
        return -1;
    }
    if (td_ctl(d, 60, &o, "submit", path, NULL) || o.status || job_of(o.out) != 1) {
        t_fail(__FILE__, __LINE__, "submit: %s%s", o.out, o.err);
        td_out_free(&o);
        return -1;
    }
    td_out_free(&o);
    char got[64];
    if (td_wait_status(d, 1, "FINISHED", 300, got, sizeof got)) {
        t_fail(__FILE__, __LINE__, "the energy run ended %s", got);
        return -1;
    }
    return 0;
}

/* Counts what a hostile client finally reads: energy pages and errors
 * naming the per-connection reply buffer. */
static void read_back(void *s, int want, int *pages, int *refused, char *last_err, size_t n)
{
    *pages = *refused = 0;
    for (int i = 0; i < want; i++) {
        zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, 5000) != 1) break;
        zmq_msg_t part[2];
        int np = td_recv_parts(s, part, 2);
        if (np == 2) {
            mpp_reply r;
            mpm_error e;
            if (mpp_reply_decode(zmq_msg_data(&part[1]), zmq_msg_size(&part[1]), 1u << 30, &r,
                                 &e) == 0) {
                if (r.kind == MPP_REPLY_ENERGY)
                    (*pages)++;
                else if (r.kind == MPP_REPLY_ERROR && r.err_message &&
                         strstr(r.err_message, "--connection-reply-buffer-mb")) {
                    (*refused)++;
                    snprintf(last_err, n, "%s", r.err_message);
                }
                mpp_reply_clear(&r);
            }
        }
        for (int k = 0; k < np; k++) zmq_msg_close(&part[k]);
    }
}

static void unread_replies(const char *name, long long samples, int requests)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--connection-reply-buffer-mb", "8", NULL};
    const long buffer_mb = 8;
    char dir[300];
    td_daemon d;
    pinger p;
    void *ctx = NULL, *s = NULL;
    snprintf(dir, sizeof dir, "%s/%s", tmp, name);
    if (td_start_measured(&d, dir, extra) || energy_run(&d, samples)) return;
    /* the reads warmed up: one whole series read the ordinary way */
    td_out o;
    CHECK(td_ctl(&d, 120, &o, "energy", "1", NULL) == 0 && o.status == 0);
    size_t rows = count_lines(o.out);
    td_out_free(&o);
    CHECKF(rows == (size_t)samples + 1, "mpmctl energy printed %zu lines for %lld samples", rows,
           samples);
    long base = proc_kb(d.pid, "VmRSS:");
    CHECK(reset_hwm(d.pid) == 0);
    if (pinger_start(&p, &d, 0)) return;
    ctx = zmq_ctx_new();
    s = ctx ? deaf_dealer(ctx, d.ep) : NULL;
    if (!s) {
        t_fail(__FILE__, __LINE__, "cannot open the hostile client");
        goto out;
    }
    {
        mpp_request rq = {.kind = MPP_REQ_GET_ENERGY, .id = 1, .limit = 100000};
        for (int i = 0; i < requests; i++)
            if (send_request(s, &rq)) {
                t_fail(__FILE__, __LINE__, "sending request %d: %s", i, zmq_strerror(errno));
                goto out;
            }
    }
    settle(d.pid, 2.0, 120);
    long hwm = proc_kb(d.pid, "VmHWM:"), held = proc_kb(d.pid, "VmRSS:");
    pinger_stop(&p);
    int pages = 0, refused = 0;
    char err[512] = "";
    read_back(s, requests, &pages, &refused, err, sizeof err);
    zmq_close(s);
    s = NULL;
    long after = wait_rss_below(d.pid, base + LEAVE_MB * 1024, 15);
    size_t len = 0;
    char *log = td_slurp(d.log, &len);
    int named = log && strstr(log, "--connection-reply-buffer-mb");
    free(log);
    zmq_ctx_term(ctx);
    ctx = NULL;
    TLOG("%d unread GetEnergy of %lld samples: mpmd VmRSS %ld kB before, VmHWM %ld kB, %ld kB "
         "held while unread, %ld kB after the client left; ping max %.3f s over %d pings (%d "
         "lost); read back %d pages, %d refused: %s",
         requests, samples, base, hwm, held, after, p.max_s, p.pings, p.lost, pages, refused, err);
    printf("reliability: unread replies (%d x GetEnergy of %lld samples): mpmd peak +%ld MB "
           "(bound %ld MB), +%ld MB after the client left, ping max %.2f s\n",
           requests, samples, (hwm - base) / 1024, buffer_mb, (after - base) / 1024, p.max_s);
    CHECKF(hwm - base < (buffer_mb + SLACK_MB) * 1024,
           "mpmd grew by %ld kB with unread replies (bound %ld MB + %d MB)", hwm - base, buffer_mb,
           SLACK_MB);
    CHECKF(p.lost == 0 && p.max_s < PING_BOUND_S, "ping max %.3f s, %d lost (bound %.1f s)",
           p.max_s, p.lost, PING_BOUND_S);
    CHECKF(refused > 0 && pages > 0, "read back %d pages and %d refusals", pages, refused);
    CHECKF(after < base + LEAVE_MB * 1024, "mpmd still holds %ld kB over its %ld kB baseline",
           after - base, base);
    CHECKF(named, "the log does not name --connection-reply-buffer-mb");
    return;
out:
    pinger_stop(&p);
    if (s) zmq_close(s);
    if (ctx) zmq_ctx_term(ctx);
}

DTEST(daemon_replies_unread_bounded)
{
    unread_replies("unread", 20000, 60);
}

DTEST(rel_replies_unread)
{
    int full = t_stress_full();
    unread_replies("rel_unread", full ? 100000 : 20000, full ? 200 : 60);
}

/* ---- large requests --------------------------------------------------------------- */

static void no_free(void *data, void *hint)
{
    (void)data;
    (void)hint;
}

/* A Request { submit { case { name: n bytes } } } of about `size` bytes
 * (the daemon reads it whole, then refuses the name); malloc'd. */
static uint8_t *big_request(size_t size, size_t *len)
{
    size_t n = size - 64;
    uint8_t *cs = malloc(n + 16);
    if (!cs) return NULL;
    size_t k = 0;
    cs[k++] = 0x0a; /* Case.name, length-delimited */
    for (size_t v = n;; v >>= 7) {
        cs[k++] = (uint8_t)((v & 0x7f) | (v >= 0x80 ? 0x80 : 0));
        if (v < 0x80) break;
    }
    memset(cs + k, 'x', n);
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_bytes = cs, .case_len = k + n};
    uint8_t *buf = NULL;
    int rc = mpp_request_encode(&rq, &buf, len);
    free(cs);
    return rc ? NULL : buf;
}

static void large_requests(const char *name, int conns, int each, long long max_bytes)
{
    const char *tmp = t_tmpdir();
    char mb[32];
    snprintf(mb, sizeof mb, "%lld", max_bytes);
    const char *extra[] = {"--max-request-bytes", mb, NULL};
    char dir[300];
    td_daemon d;
    pinger p;
    void *ctx = NULL, **s = calloc((size_t)conns, sizeof *s);
    size_t len = 0;
    uint8_t *req = big_request((size_t)max_bytes - 1024, &len);
    snprintf(dir, sizeof dir, "%s/%s", tmp, name);
    if (!s || !req) {
        t_fail(__FILE__, __LINE__, "out of memory");
        free(s);
        free(req);
        return;
    }
    if (td_start_measured(&d, dir, extra)) {
        free(s);
        free(req);
        return;
    }
    long base = proc_kb(d.pid, "VmRSS:");
    int sent = 0;
    if (reset_hwm(d.pid) || pinger_start(&p, &d, 0)) {
        t_fail(__FILE__, __LINE__, "no measure");
        free(s);
        free(req);
        return;
    }
    ctx = zmq_ctx_new();
    for (int i = 0; ctx && i < conns; i++) s[i] = deaf_dealer(ctx, d.ep);
    for (int k = 0; k < each; k++)
        for (int i = 0; i < conns; i++) {
            zmq_msg_t m;
            if (!s[i] || zmq_msg_init_data(&m, req, len, no_free, NULL)) continue;
            if (zmq_send(s[i], "", 0, ZMQ_SNDMORE) < 0 || zmq_msg_send(&m, s[i], 0) < 0)
                zmq_msg_close(&m);
            else
                sent++;
        }
    settle(d.pid, 2.0, 120);
    long hwm = proc_kb(d.pid, "VmHWM:");
    pinger_stop(&p);
    for (int i = 0; i < conns; i++)
        if (s[i]) zmq_close(s[i]);
    if (ctx) zmq_ctx_term(ctx); /* the sends are done: req is no longer read */
    long after = wait_rss_below(d.pid, base + LEAVE_MB * 1024, 15);
    free(s);
    free(req);
    long bound_kb = (long)conns * 3 * (long)(max_bytes >> 10) + SLACK_MB * 1024;
    TLOG("%d connections x %d requests of %zu bytes (%d sent): mpmd VmRSS %ld kB before, "
         "VmHWM %ld kB, %ld kB after they left; ping max %.3f s over %d pings (%d lost)",
         conns, each, len, sent, base, hwm, after, p.max_s, p.pings, p.lost);
    printf("reliability: large requests (%d connections x %d x %lld MiB): mpmd peak +%ld MB "
           "(bound %ld MB), +%ld MB after they left, ping max %.2f s\n",
           conns, each, max_bytes >> 20, (hwm - base) / 1024, bound_kb / 1024,
           (after - base) / 1024, p.max_s);
    CHECKF(sent == conns * each, "sent %d of %d", sent, conns * each);
    CHECKF(hwm - base < bound_kb, "mpmd grew by %ld kB (bound %ld kB: 3 requests a connection)",
           hwm - base, bound_kb);
    CHECKF(p.lost == 0 && p.max_s < PING_BOUND_S, "ping max %.3f s, %d lost (bound %.1f s)",
           p.max_s, p.lost, PING_BOUND_S);
    CHECKF(after < base + LEAVE_MB * 1024, "mpmd still holds %ld kB over its %ld kB baseline",
           after - base, base);
}

DTEST(daemon_replies_large_requests_bounded)
{
    large_requests("large", 4, 8, 4LL << 20);
}

DTEST(rel_replies_large_requests)
{
    int full = t_stress_full();
    /* many connections, then one that pipelines (the default
     * --max-request-bytes at full size) */
    long long max = full ? 8LL << 20 : 4LL << 20;
    large_requests("rel_large", full ? 40 : 4, full ? 4 : 8, max);
    if (!t_failed()) large_requests("rel_pipelined", 1, full ? 30 : 8, max);
}

/* ---- connections ------------------------------------------------------------------ */

/* A raw connection to the daemon's ipc:// socket that never greets; -1
 * when it cannot be made. */
static int raw_connect(const char *ep)
{
    struct sockaddr_un a;
    const char *path = ep + strlen("ipc://");
    if (strlen(path) >= sizeof a.sun_path) return -1;
    int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    if (fd < 0) return -1;
    memset(&a, 0, sizeof a);
    a.sun_family = AF_UNIX;
    memcpy(a.sun_path, path, strlen(path) + 1);
    if (connect(fd, (struct sockaddr *)&a, sizeof a)) {
        close(fd);
        return -1;
    }
    return fd;
}

/* Idle ZeroMQ connections (they finish their handshake and stay, and
 * reconnect when refused) past --max-connections, and raw ones that never
 * greet, on a daemon started with a low soft descriptor limit: the daemon
 * holds about the cap, the connected pinger stays answered, the log names
 * the cap, and a new client is answered within --handshake-timeout-s + a
 * margin while the raw ones go on (before: the descriptors ran out, the
 * daemon spun on accept and answered no new client for 30 s). */
static void conns_cap(const char *name, int idle, int raw, int soft)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--max-connections", "50", "--handshake-timeout-s", "2", NULL};
    char dir[300];
    td_daemon d;
    pinger p;
    void *ctx = NULL, **s = calloc((size_t)idle, sizeof *s);
    int *fds = malloc((size_t)(raw ? raw : 1) * sizeof *fds);
    int nraw = 0;
    snprintf(dir, sizeof dir, "%s/%s", tmp, name);
    /* the daemon starts with a soft descriptor limit of `soft` (systemd's
     * default is 1024) and this process's hard limit, which it raises
     * the soft one to */
    struct rlimit keep, rl;
    int started = -1;
    if (s && fds && getrlimit(RLIMIT_NOFILE, &keep) == 0) {
        rl = keep;
        rl.rlim_cur = (rlim_t)soft < keep.rlim_cur ? (rlim_t)soft : keep.rlim_cur;
        if (setrlimit(RLIMIT_NOFILE, &rl) == 0) {
            started = td_start_measured(&d, dir, extra);
            setrlimit(RLIMIT_NOFILE, &keep);
        }
    }
    if (started) {
        if (!s || !fds) t_fail(__FILE__, __LINE__, "out of memory");
        free(s);
        free(fds);
        return;
    }
    if (keep.rlim_cur <= (rlim_t)soft || keep.rlim_cur < (rlim_t)(3 * (idle + raw) + 100)) {
        t_fail(__FILE__, __LINE__, "this process may open %llu descriptors, fewer than it needs",
               (unsigned long long)keep.rlim_cur);
        free(s);
        free(fds);
        return;
    }
    if (pinger_start(&p, &d, 0)) {
        free(s);
        free(fds);
        return;
    }
    ctx = zmq_ctx_new();
    for (int i = 0; ctx && i < idle; i++) s[i] = deaf_dealer(ctx, d.ep);
    for (int i = 0; i < raw; i++) {
        int fd = raw_connect(d.ep);
        if (fd >= 0) fds[nraw++] = fd;
    }
    /* each idle client asked one Ping as it connected: those answered
     * got in (at most the cap) */
    int answered = 0;
    {
        mpp_request rq = {.kind = MPP_REQ_PING};
        for (int i = 0; i < idle; i++)
            if (s[i]) send_request(s[i], &rq);
        td_msleep(3000);
        for (int i = 0; i < idle; i++) {
            zmq_pollitem_t it = {s[i], 0, ZMQ_POLLIN, 0};
            if (s[i] && zmq_poll(&it, 1, 0) == 1) answered++;
        }
    }
    long soft_now = -1;
    {
        char path[64], line[256];
        snprintf(path, sizeof path, "/proc/%ld/limits", (long)d.pid);
        FILE *f = fopen(path, "r");
        while (f && fgets(line, sizeof line, f))
            if (!strncmp(line, "Max open files", 14)) soft_now = strtol(line + 14, NULL, 10);
        if (f) fclose(f);
    }
    /* a new client while the attack goes on: the raw connections are
     * closed after --handshake-timeout-s (the idle ones keep the cap
     * reached: a new connection is refused until they leave) */
    double t0 = td_now(), newest = -1;
    while (raw && !idle && td_now() - t0 < 20 && newest < 0) {
        json_t *r = NULL;
        mpp_request rq = {.kind = MPP_REQ_PING};
        if (td_request(d.ep, &rq, 2, &r) == 0) newest = td_now() - t0;
        json_decref(r);
    }
    pinger_stop(&p);
    for (int i = 0; i < nraw; i++) close(fds[i]);
    for (int i = 0; i < idle; i++)
        if (s[i]) zmq_close(s[i]);
    if (ctx) zmq_ctx_term(ctx);
    free(s);
    free(fds);
    size_t len = 0;
    char *log = td_slurp(d.log, &len);
    int named = log && strstr(log, "--max-connections");
    free(log);
    int after = ping_ok(&d);
    TLOG("%d idle and %d raw connections (cap 50, soft descriptor limit %d at start, %ld "
         "after): %d idle clients answered; a new client answered after %.2f s; the "
         "connected pinger max %.3f s over %d pings (%d lost)",
         idle, nraw, soft, soft_now, answered, newest, p.max_s, p.pings, p.lost);
    printf("reliability: connections (%d idle, %d never greeting; cap 50, soft limit %d): %d "
           "idle clients got in, a new client answered after %.1f s, a connected one within "
           "%.2f s\n",
           idle, nraw, soft, answered, newest, p.max_s);
    CHECKF(soft_now > soft, "mpmd kept its soft descriptor limit of %ld", soft_now);
    if (raw && !idle)
        CHECKF(newest >= 0 && newest < 2 + 5.0, "no new client answered within 7 s (%.2f)", newest);
    if (idle) {
        CHECKF(answered <= 50, "%d idle clients got in (cap 50)", answered);
        CHECKF(named, "the log does not name --max-connections");
    }
    CHECKF(p.lost == 0 && p.max_s < PING_BOUND_S, "ping max %.3f s, %d lost (bound %.1f s)",
           p.max_s, p.lost, PING_BOUND_S);
    CHECKF(after, "no answer after the attack");
}

DTEST(daemon_conns_cap_holds)
{
    conns_cap("conns", 300, 0, 256);
}

DTEST(daemon_conns_handshake_timeout)
{
    conns_cap("handshake", 0, 300, 256);
}

DTEST(rel_replies_connections)
{
    int full = t_stress_full();
    conns_cap("rel_conns", full ? 1100 : 300, full ? 1100 : 300, full ? 1024 : 256);
}

/* ---- CURVE and a pipe of one or two requests -------------------------------------- */

/* A CURVE client that pipelines many requests gets every answer: the
 * request socket's receive pipe is short (two requests), and libzmq must
 * stop and restart reading the connection without losing it. */
DTEST(daemon_replies_curve_pipelined)
{
    const char *tmp = t_tmpdir();
    char dir[300], sec_path[400], keys_path[400];
    char spub[41], ssec[41], cpub[41], csec[41], line[128];
    snprintf(dir, sizeof dir, "%s/curve", tmp);
    CHECK(zmq_curve_keypair(spub, ssec) == 0 && zmq_curve_keypair(cpub, csec) == 0);
    CHECK(mkdir(dir, 0700) == 0 || errno == EEXIST);
    snprintf(sec_path, sizeof sec_path, "%s/server.key", dir);
    snprintf(keys_path, sizeof keys_path, "%s/clients.pub", dir);
    snprintf(line, sizeof line, "%s\n", ssec);
    CHECK(td_write(sec_path, line) == 0 && chmod(sec_path, 0600) == 0);
    snprintf(line, sizeof line, "%s client\n", cpub);
    CHECK(td_write(keys_path, line) == 0);
    const char *extra[] = {"--curve-secret", sec_path, "--authorized-keys", keys_path, NULL};
    td_daemon d;
    td_set_curve(spub, cpub, csec);
    if (td_start(&d, dir, extra)) return;
    void *ctx = zmq_ctx_new(), *s = ctx ? zmq_socket(ctx, ZMQ_DEALER) : NULL;
    int zero = 0, got = 0;
    const int n = 300;
    if (!s || zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) ||
        zmq_setsockopt(s, ZMQ_CURVE_SERVERKEY, spub, 41) ||
        zmq_setsockopt(s, ZMQ_CURVE_PUBLICKEY, cpub, 41) ||
        zmq_setsockopt(s, ZMQ_CURVE_SECRETKEY, csec, 41) || zmq_connect(s, d.ep)) {
        t_fail(__FILE__, __LINE__, "CURVE client: %s", zmq_strerror(errno));
        goto out;
    }
    for (int i = 0; i < n; i++) {
        mpp_request rq = {.kind = i % 2 ? MPP_REQ_PING : MPP_REQ_GET_ENERGY, .id = 7};
        if (send_request(s, &rq)) {
            t_fail(__FILE__, __LINE__, "send %d: %s", i, zmq_strerror(errno));
            goto out;
        }
    }
    for (; got < n; got++) {
        zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, 10000) != 1) break;
        zmq_msg_t part[2];
        int np = td_recv_parts(s, part, 2);
        for (int k = 0; k < np; k++) zmq_msg_close(&part[k]);
    }
    CHECKF(got == n, "%d of %d pipelined requests answered over CURVE", got, n);
out:
    if (s) zmq_close(s);
    if (ctx) zmq_ctx_term(ctx);
}

/* ---- listings --------------------------------------------------------------------- */

/* Submits n short runs (raw Submits of td_good2d cut to a few steps);
 * 0, or -1 after failing the test. */
static int many_runs(const td_daemon *d, int n)
{
    char *json = td_patch("\"endTime\": 1", "\"endTime\": 0.01");
    uint8_t *cb = NULL;
    size_t cl = 0;
    char err[ERRLEN];
    if (!json ||
        td_msg_json_to_bytes(MPP_MSG_CASE, json, strlen(json), &cb, &cl, err, sizeof err)) {
        t_fail(__FILE__, __LINE__, "the case: %s", json ? err : "out of memory");
        free(json);
        return -1;
    }
    free(json);
    int rc = 0;
    for (int i = 0; i < n && !rc; i++) {
        json_t *r = NULL;
        mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_bytes = cb, .case_len = cl};
        if (td_request(d->ep, &rq, 20, &r) || !json_object_get(r, "submitOk")) {
            char *t = r ? json_dumps(r, 0) : NULL;
            t_fail(__FILE__, __LINE__, "submit %d: %s", i, t ? t : "no reply");
            free(t);
            rc = -1;
        }
        json_decref(r);
    }
    free(cb);
    return rc;
}

/* Energy pages and listings are cut at --page-max-bytes (the reply says
 * there is more), and mpmctl, which follows the cursors, still gets every
 * sample and every run. */
DTEST(daemon_replies_pages_by_bytes)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--page-max-bytes", "8192", "--queue-max", "1000", NULL};
    char dir[300];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/pages", tmp);
    if (td_start(&d, dir, extra) || energy_run(&d, 2000) || many_runs(&d, 60)) return;
    char got[64];
    CHECK(td_wait_status(&d, 61, "FINISHED", 60, got, sizeof got) == 0);
    /* one page of energies: at most 8192 bytes on the wire, more = 1 */
    mpp_request rq = {.kind = MPP_REQ_GET_ENERGY, .id = 1, .limit = 100000};
    uint8_t *buf = NULL;
    size_t len = 0;
    CHECK(mpp_request_encode(&rq, &buf, &len) == 0);
    free(buf);
    json_t *r = NULL;
    CHECK(td_request(d.ep, &rq, 20, &r) == 0);
    json_t *e = json_object_get(r, "energy");
    size_t ns = json_array_size(json_object_get(e, "samples"));
    int more = json_is_true(json_object_get(e, "more"));
    json_decref(r);
    CHECKF(ns > 10 && ns < 2000 && more, "a page of %zu samples (more %d)", ns, more);
    CHECK(td_ctl(&d, 60, &o, "energy", "1", NULL) == 0 && o.status == 0);
    size_t rows = count_lines(o.out);
    td_out_free(&o);
    CHECKF(rows == 2001, "mpmctl energy printed %zu lines for 2000 samples", rows);
    /* a listing of 1000 runs: cut, with a cursor */
    mpp_request lr = {.kind = MPP_REQ_LIST_RUNS, .limit = 1000};
    CHECK(td_request(d.ep, &lr, 20, &r) == 0);
    json_t *runs = json_object_get(r, "runs");
    size_t nr = json_array_size(json_object_get(runs, "runs"));
    int cursor = json_object_get(runs, "nextBeforeRunId") != NULL;
    json_decref(r);
    CHECKF(nr > 1 && nr < 61 && cursor, "a listing of %zu runs (cursor %d)", nr, cursor);
    CHECK(td_ctl(&d, 60, &o, "runs", "--all", "--json", NULL) == 0 && o.status == 0);
    size_t lines = count_lines(o.out);
    td_out_free(&o);
    CHECKF(lines == 61, "mpmctl runs --all printed %zu runs of 61", lines);
}

/* Many large listings at once (every connection asks for 10000 runs, again
 * and again): the connected pinger is answered within the bound. */
static void listings(const char *name, int nruns, int conns, int each)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--queue-max", "100000", NULL};
    char dir[300];
    td_daemon d;
    pinger p;
    snprintf(dir, sizeof dir, "%s/%s", tmp, name);
    if (td_start(&d, dir, extra) || many_runs(&d, nruns)) return;
    char got[64];
    CHECK(td_wait_status(&d, (unsigned long long)nruns, "FINISHED", 120, got, sizeof got) == 0);
    void *ctx = zmq_ctx_new(), **s = calloc((size_t)conns, sizeof *s);
    if (!ctx || !s || pinger_start(&p, &d, 0)) {
        free(s);
        if (ctx) zmq_ctx_term(ctx);
        return;
    }
    mpp_request lr = {.kind = MPP_REQ_LIST_RUNS, .limit = 10000};
    double t0 = td_now();
    for (int i = 0; i < conns; i++) {
        s[i] = deaf_dealer(ctx, d.ep);
        for (int k = 0; s[i] && k < each; k++) send_request(s[i], &lr);
    }
    /* until every listing is answered (read, so that none waits) */
    int answered = 0;
    while (answered < conns * each && td_now() - t0 < 120) {
        for (int i = 0; i < conns; i++) {
            zmq_pollitem_t it = {s[i], 0, ZMQ_POLLIN, 0};
            while (s[i] && zmq_poll(&it, 1, 0) == 1) {
                zmq_msg_t part[2];
                int np = td_recv_parts(s[i], part, 2);
                for (int k = 0; k < np; k++) zmq_msg_close(&part[k]);
                answered++;
            }
        }
        td_msleep(5);
    }
    double took = td_now() - t0;
    pinger_stop(&p);
    for (int i = 0; i < conns; i++)
        if (s[i]) zmq_close(s[i]);
    free(s);
    zmq_ctx_term(ctx);
    TLOG("%d connections x %d ListRuns of 10000 over %d runs: answered %d in %.2f s; ping max "
         "%.3f s over %d pings (%d lost)",
         conns, each, nruns, answered, took, p.max_s, p.pings, p.lost);
    printf("reliability: listings (%d x %d ListRuns of 10000 over %d runs): ping max %.2f s\n",
           conns, each, nruns, p.max_s);
    CHECKF(answered == conns * each, "%d of %d listings answered", answered, conns * each);
    CHECKF(p.lost == 0 && p.max_s < PING_BOUND_S, "ping max %.3f s, %d lost (bound %.1f s)",
           p.max_s, p.lost, PING_BOUND_S);
}

DTEST(daemon_replies_listings_keep_loop)
{
    listings("lists", 300, 20, 2);
}

DTEST(rel_replies_listings)
{
    int full = t_stress_full();
    listings("rel_lists", full ? 1289 : 300, 20, full ? 5 : 2);
}
