/*
 * t_daemon_bind.c - the daemon's exposure on a real mpmd: the bind rule
 * (every spelling libzmq reads as something other than loopback - a
 * source address before ';', '*', an interface name, IPv6 wildcards and
 * mapped forms, other numbers, DNS names, transports without CURVE - is
 * refused at start from a flag, the environment and a config file, on the
 * request and the stream endpoint, with a message naming the endpoint,
 * where it was set and the fix; the loopback forms start and listen on
 * loopback only, read from /proc/net/tcp*); revocation (a key removed at
 * SIGHUP loses its open request connection and its stream, another key
 * keeps both); file permissions (database, -wal, -shm, lock file 0600,
 * checkpoint directory 0700; a reader's lock on the database or on an
 * older 0644 lock file no longer blocks a start; a hard link and a second
 * mpmd stay refused); names (a NUL refused naming the field, from JSON and
 * raw protobuf; bidirectional controls, line separators and backslashes
 * escaped in mpmctl runs/show and in the log while the name is stored
 * byte-exact; with --private-runs a refusal does not name another key).
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"

#include "mpp_case.h"
#include "mpp_endpoint.h"
#include "mpp_text.h"

#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zmq.h>

/* ---- helpers ------------------------------------------------------------------------------ */

static int write_file(const char *path, const char *text, mode_t mode)
{
    int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, mode);
    if (fd < 0) return -1;
    size_t n = strlen(text);
    int ok = write(fd, text, n) == (ssize_t)n && fchmod(fd, mode) == 0;
    return close(fd) == 0 && ok ? 0 : -1;
}

static unsigned file_mode(const char *path)
{
    struct stat sb;
    return stat(path, &sb) ? 07777 : (unsigned)(sb.st_mode & 07777);
}

/* The local addresses (hex, as /proc/net/tcp{,6} write them) of the
 * sockets listening on port, joined by ' ' into out; the count. */
static int listeners(int port, char *out, size_t n)
{
    static const char *const files[] = {"/proc/net/tcp", "/proc/net/tcp6"};
    int count = 0;
    out[0] = 0;
    for (int f = 0; f < 2; f++) {
        FILE *fp = fopen(files[f], "r");
        char line[512], addr[64];
        unsigned p, st;
        if (!fp) continue;
        while (fgets(line, sizeof line, fp))
            if (sscanf(line, " %*d: %63[0-9A-Fa-f]:%x %*[0-9A-Fa-f]:%*x %x", addr, &p, &st) == 3 &&
                (int)p == port && st == 0x0A /* LISTEN */) {
                size_t k = strlen(out);
                snprintf(out + k, n - k, "%s%s", k ? " " : "", addr);
                count++;
            }
        fclose(fp);
    }
    return count;
}

/* 1 if every address in the list is loopback: 127.x.y.z (little-endian
 * hex "....7F"), ::1, or ::ffff:127.x.y.z. */
static int all_loopback(const char *list)
{
    char buf[1024];
    snprintf(buf, sizeof buf, "%s", list);
    for (char *save = NULL, *a = strtok_r(buf, " ", &save); a; a = strtok_r(NULL, " ", &save)) {
        size_t len = strlen(a);
        int ok = (len == 8 && !strcasecmp(a + 6, "7F")) ||
                 !strcasecmp(a, "00000000000000000000000001000000") ||
                 (len == 32 && !strncasecmp(a, "0000000000000000FFFF0000", 24) &&
                  !strcasecmp(a + 30, "7F"));
        if (!ok) return 0;
    }
    return 1;
}

/* A CURVE keypair (Z85) as files dir/NAME.key (0600) and dir/NAME.pub. */
static int make_keys(const char *dir, const char *name, char *pub, char *sec)
{
    char path[500], line[64];
    if (zmq_curve_keypair(pub, sec)) return -1;
    snprintf(path, sizeof path, "%s/%s.key", dir, name);
    snprintf(line, sizeof line, "%s\n", sec);
    if (write_file(path, line, 0600)) return -1;
    snprintf(path, sizeof path, "%s/%s.pub", dir, name);
    snprintf(line, sizeof line, "%s\n", pub);
    return write_file(path, line, 0644);
}

/* A CURVE client socket of type with the given keys, connected to ep. */
static void *curve_socket(void *zctx, int type, const char *ep, const char *spub, const char *pub,
                          const char *sec)
{
    int zero = 0;
    void *s = zmq_socket(zctx, type);
    if (!s || zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) ||
        zmq_setsockopt(s, ZMQ_CURVE_SERVERKEY, spub, 41) ||
        zmq_setsockopt(s, ZMQ_CURVE_PUBLICKEY, pub, 41) ||
        zmq_setsockopt(s, ZMQ_CURVE_SECRETKEY, sec, 41) || zmq_connect(s, ep)) {
        t_fail(__FILE__, __LINE__, "socket on %s: %s", ep, zmq_strerror(errno));
        if (s) zmq_close(s);
        return NULL;
    }
    return s;
}

/* Sends rq on a DEALER (an open connection) and waits up to timeout s:
 * the reply as JSON, or NULL when none came. */
static json_t *dealer_request(void *s, const mpp_request *rq, double timeout)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    json_t *reply = NULL;
    if (mpp_request_encode(rq, &buf, &len)) return NULL;
    if (zmq_send(s, "", 0, ZMQ_SNDMORE | ZMQ_DONTWAIT) >= 0 &&
        zmq_send(s, buf, len, ZMQ_DONTWAIT) >= 0) {
        zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
        double end = td_now() + timeout;
        while (!reply && td_now() < end && zmq_poll(&it, 1, 100) >= 0) {
            if (!(it.revents & ZMQ_POLLIN)) continue;
            zmq_msg_t part[2];
            int n = td_recv_parts(s, part, 2);
            char *json = NULL, err[ERRLEN];
            if (n == 2 &&
                td_msg_bytes_to_json(MPP_MSG_REPLY, zmq_msg_data(&part[1]), zmq_msg_size(&part[1]),
                                     0, 0, &json, err, sizeof err) == 0)
                reply = json_loads(json, 0, NULL);
            free(json);
            for (int i = 0; i < n && i < 2; i++) zmq_msg_close(&part[i]);
        }
    }
    free(buf);
    return reply;
}

/* A CURVE daemon's directory: dir (made) and dir/keys with the keypairs
 * of the server, of a and of b (make_keys), the server's secret key file,
 * and dir/authorized_keys listing a and b. */
typedef struct {
    char dir[300], kdir[400], key[500], auth[500];
    char spub[41], ssec[41], apub[41], asec[41], bpub[41], bsec[41];
} curve_dir;

static int curve_dir_make(curve_dir *c, const char *name)
{
    char text[200];
    snprintf(c->dir, sizeof c->dir, "%s/%s", t_tmpdir(), name);
    snprintf(c->kdir, sizeof c->kdir, "%s/keys", c->dir);
    snprintf(c->key, sizeof c->key, "%s/server.key", c->kdir);
    snprintf(c->auth, sizeof c->auth, "%s/authorized_keys", c->dir);
    if ((mkdir(c->dir, 0700) && errno != EEXIST) || (mkdir(c->kdir, 0700) && errno != EEXIST) ||
        make_keys(c->kdir, "server", c->spub, c->ssec) ||
        make_keys(c->kdir, "a", c->apub, c->asec) || make_keys(c->kdir, "b", c->bpub, c->bsec)) {
        t_fail(__FILE__, __LINE__, "cannot make the keys in %s", c->kdir);
        return -1;
    }
    snprintf(text, sizeof text, "%s alice\n%s bob\n", c->apub, c->bpub);
    if (write_file(c->auth, text, 0600)) {
        t_fail(__FILE__, __LINE__, "cannot write %s", c->auth);
        return -1;
    }
    return 0;
}

/* The case that runs until cancelled (long_case, energy every `every`
 * steps), written to dir and read back as a Case message; NULL after
 * reporting a failure. */
static Mpmd__Case *long_case_pb(const char *dir, int every)
{
    char cpath[500], err[ERRLEN];
    size_t clen = 0;
    Mpmd__Case *pb = NULL;
    char *ctext = write_case(long_case(every), dir, "long.json", cpath, sizeof cpath) == 0
                      ? td_slurp(cpath, &clen)
                      : NULL;
    if (!ctext || td_case_from_json(ctext, clen, &pb, err, sizeof err))
        t_fail(__FILE__, __LINE__, "the long case: %s", ctext ? err : "not written");
    free(ctext);
    return pb;
}

/* 1 when a Ping on the open connection s gets its Pong within timeout s. */
static int dealer_pings(void *s, double timeout)
{
    mpp_request ping = {.kind = MPP_REQ_PING};
    json_t *r = dealer_request(s, &ping, timeout);
    int pong = json_object_get(r, "pong") != NULL;
    json_decref(r);
    return pong;
}

/* Stream messages that reach s within secs seconds. */
static long count_stream(void *s, double secs)
{
    long n = 0;
    double end = td_now() + secs;
    zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
    while (td_now() < end) {
        if (zmq_poll(&it, 1, 50) <= 0) continue;
        zmq_msg_t part[2];
        int k = td_recv_parts(s, part, 2);
        n += k > 0;
        for (int i = 0; i < k && i < 2; i++) zmq_msg_close(&part[i]);
    }
    return n;
}

/* ---- defect: the bind rule ---------------------------------------------------------------- */

/* The classes of the endpoint parser, libzmq's reading of each. */
TEST(daemon_bind_classes)
{
    static const struct {
        const char *ep;
        int cls;
    } eps[] = {
        {"ipc:///tmp/x", MPP_BIND_LOCAL},
        {"inproc://a", MPP_BIND_LOCAL},
        {"tcp://127.0.0.1:5555", MPP_BIND_LOCAL},
        {"tcp://127.255.1.9:1", MPP_BIND_LOCAL},
        {"tcp://localhost:5555", MPP_BIND_LOCAL},
        {"tcp://ip6-localhost:5555", MPP_BIND_LOCAL},
        {"tcp://[::1]:5555", MPP_BIND_LOCAL},
        {"tcp://::1:5555", MPP_BIND_LOCAL},
        {"tcp://127.0.0.1:*", MPP_BIND_LOCAL},
        {"tcp://127.0.0.1:0;0.0.0.0:5555", MPP_BIND_INVALID},
        {"tcp://127.0.0.1:0;127.0.0.1:5555", MPP_BIND_INVALID},
        {"tcp://*:5555", MPP_BIND_REMOTE},
        {"tcp://0.0.0.0:5555", MPP_BIND_REMOTE},
        {"tcp://[::]:5555", MPP_BIND_REMOTE},
        {"tcp://:::5555", MPP_BIND_REMOTE},
        {"tcp://[*]:5555", MPP_BIND_REMOTE},
        {"tcp://eth0:5555", MPP_BIND_REMOTE},
        {"tcp://lo:5555", MPP_BIND_REMOTE},
        {"tcp://127.1:5555", MPP_BIND_REMOTE},
        {"tcp://127.0.0.01:5555", MPP_BIND_REMOTE},
        {"tcp://2130706433:5555", MPP_BIND_REMOTE},
        {"tcp://0x7f.0.0.1:5555", MPP_BIND_REMOTE},
        {"tcp://127.0.0.256:5555", MPP_BIND_REMOTE},
        {"tcp://127.0.0.1.:5555", MPP_BIND_REMOTE},
        {"tcp://localhost.:5555", MPP_BIND_REMOTE},
        {"tcp://[::ffff:127.0.0.1]:5555", MPP_BIND_REMOTE},
        {"tcp://[fe80::1%lo]:5555", MPP_BIND_REMOTE},
        {"tcp://example.org:5555", MPP_BIND_REMOTE},
        {"ws://127.0.0.1:5555", MPP_BIND_REMOTE},
        {"wss://127.0.0.1:5555", MPP_BIND_REMOTE},
        {"tipc://{5560,0,0}", MPP_BIND_REMOTE},
        {"vmci://1:5555", MPP_BIND_REMOTE},
        {"pgm://eth0;239.192.1.1:5555", MPP_BIND_INVALID},
        {"epgm://127.0.0.1;239.192.1.1:5555", MPP_BIND_INVALID},
        {"udp://127.0.0.1:5555", MPP_BIND_INVALID},
        {"norm://127.0.0.1:5555", MPP_BIND_INVALID},
        {"tcp://127.0.0.1:x", MPP_BIND_INVALID},
        {"tcp://127.0.0.1:65536", MPP_BIND_INVALID},
        {"tcp://127.0.0.1", MPP_BIND_INVALID},
        {"bogus://x", MPP_BIND_INVALID},
        {"", MPP_BIND_INVALID},
    };
    for (size_t i = 0; i < sizeof eps / sizeof eps[0]; i++) {
        char why[400];
        int k = mpp_endpoint_bind_class(eps[i].ep, why, sizeof why);
        int local = mpp_endpoint_is_local(eps[i].ep);
        CHECKF(k == eps[i].cls && (k == MPP_BIND_LOCAL) == !why[0] &&
                   (k == MPP_BIND_INVALID || local == (k == MPP_BIND_LOCAL)),
               "%s: class %d (want %d), local %d: %s", eps[i].ep, k, eps[i].cls, local, why);
    }
    /* a client connecting with a source address goes where the part after
     * ';' says: not local */
    CHECK(!mpp_endpoint_is_local("tcp://127.0.0.1:0;10.0.0.5:5555"));
}

/* Every bypass form is refused at start: from --endpoint, MPMD_ENDPOINT and
 * a config file, and on the stream endpoint alone from its flag, its
 * variable and the file; the message names the endpoint, where it was set
 * and --curve-secret; the daemon exits at once and listens on nothing. */
DTEST(daemon_bind_bypass_refused)
{
    const char *tmp = t_tmpdir();
    char dir[300], db[400], conf[400], ipc[400];
    int port = td_tcp_port(4801);
    snprintf(dir, sizeof dir, "%s/bind", tmp);
    CHECK(mkdir(dir, 0700) == 0 || errno == EEXIST);
    snprintf(db, sizeof db, "%s/mpmd.db", dir);
    snprintf(conf, sizeof conf, "%s/mpmd.conf", dir);
    snprintf(ipc, sizeof ipc, "ipc://%s/ctl", dir);
    static const char *const forms[] = {
        "tcp://127.0.0.1:0;0.0.0.0:%d",
        "tcp://127.0.0.1:0;*:%d",
        "tcp://127.0.0.1:0;eth0:%d",
        "tcp://*:%d",
        "tcp://0.0.0.0:%d",
        "tcp://[::]:%d",
        "tcp://[*]:%d",
        "tcp://eth0:%d",
        "tcp://lo:%d",
        "tcp://127.1:%d",
        "tcp://2130706433:%d",
        "tcp://localhost.:%d",
        "tcp://[::ffff:127.0.0.1]:%d",
        "tcp://example.org:%d",
        "ws://127.0.0.1:%d",
        "udp://127.0.0.1:%d",
        "pgm://eth0;239.192.1.1:%d",
    };
    static const char *const srcs[] = {"flag", "env", "config"};
    int refused = 0, total = 0;
    double worst = 0;
    for (size_t f = 0; f < sizeof forms / sizeof forms[0]; f++)
        for (int stream = 0; stream < 2; stream++)
            for (int src = 0; src < 3; src++) {
                char ep[200], line[300], want_from[440];
                const char *flag = stream ? "--stream-endpoint" : "--endpoint";
                const char *var = stream ? "MPMD_STREAM_ENDPOINT" : "MPMD_ENDPOINT";
                snprintf(ep, sizeof ep, forms[f], port);
                const char *argv[10];
                int n = 0;
                argv[n++] = "--db";
                argv[n++] = db;
                if (stream) { /* the request endpoint loopback: the stream alone */
                    argv[n++] = "--endpoint";
                    argv[n++] = ipc;
                }
                if (src == 0) {
                    argv[n++] = flag;
                    argv[n++] = ep;
                    snprintf(want_from, sizeof want_from, "(set by %s)", flag);
                } else if (src == 1) {
                    setenv(var, ep, 1);
                    snprintf(want_from, sizeof want_from, "(set by %s)", var);
                } else {
                    snprintf(line, sizeof line, "# a config file\n%s = %s\n", flag + 2, ep);
                    CHECK(write_file(conf, line, 0600) == 0);
                    argv[n++] = "--config";
                    argv[n++] = conf;
                    snprintf(want_from, sizeof want_from, "(set by %s:2)", conf);
                }
                argv[n] = NULL;
                td_out o;
                int rc = td_run_mpmd(argv, 20, &o);
                unsetenv(var);
                CHECK(rc == 0);
                char lst[512];
                int nl = listeners(port, lst, sizeof lst);
                int ok = o.status == 2 && strstr(o.err, flag) && strstr(o.err, ep) &&
                         strstr(o.err, want_from) && strstr(o.err, "--curve-secret") &&
                         strstr(o.err, "refusing to bind") && nl == 0;
                total++;
                refused += ok;
                if (o.secs > worst) worst = o.secs;
                if (!ok || (stream == 0 && src == 0))
                    TLOG("%s %s from %s: exit %d in %.3f s, %d listener(s): %.300s", flag, ep,
                         srcs[src], o.status, o.secs, nl, o.err);
                CHECKF(ok, "%s %s from %s was not refused as it should be", flag, ep, srcs[src]);
                td_out_free(&o);
            }
    TLOG("%d of %d bypass starts refused (the slowest exit %.3f s)", refused, total, worst);
    CHECK(refused == total);
}

/* The loopback forms start, answer, and listen on loopback only (read back
 * from /proc/net/tcp and tcp6); with CURVE a wildcard bind is allowed. */
DTEST(daemon_bind_loopback_starts)
{
    const char *tmp = t_tmpdir();
    static const char *const hosts[] = {"127.0.0.1", "127.3.4.5", "localhost", "[::1]"};
    for (size_t k = 0; k < sizeof hosts / sizeof hosts[0]; k++) {
        char dir[300], ep[80], lst[512];
        int port = td_tcp_port(4811) + 2 * (int)k;
        td_daemon d;
        snprintf(dir, sizeof dir, "%s/lo%zu", tmp, k);
        snprintf(ep, sizeof ep, "tcp://%s:%d", hosts[k], port);
        if (td_start_ep(&d, dir, ep, NULL)) return;
        CHECK(ping_ok(&d));
        int n = listeners(port, lst, sizeof lst), n1 = 0;
        char lst1[512];
        n1 = listeners(port + 1, lst1, sizeof lst1);
        TLOG("%s: listening on %s (stream: %s)", ep, lst, lst1);
        CHECKF(n >= 1 && all_loopback(lst) && n1 >= 1 && all_loopback(lst1),
               "%s listens on %s, stream on %s", ep, lst, lst1);
        CHECK(td_stop(&d) == 0);
    }
    /* CURVE: tcp://0.0.0.0 is allowed, and is what it says */
    curve_dir c = {0};
    char ep[80], lst[512];
    if (curve_dir_make(&c, "lo-curve")) return;
    int port = td_tcp_port(4821);
    snprintf(ep, sizeof ep, "tcp://0.0.0.0:%d", port);
    const char *extra[] = {"--curve-secret", c.key, "--authorized-keys", c.auth, NULL};
    td_daemon d;
    td_set_curve(c.spub, c.apub, c.asec);
    if (td_start_ep(&d, c.dir, ep, extra)) return;
    int n = listeners(port, lst, sizeof lst);
    TLOG("with CURVE %s: listening on %s", ep, lst);
    CHECKF(n >= 1 && !all_loopback(lst), "%s with CURVE listens on %s", ep, lst);
    CHECK(td_stop(&d) == 0);
}

/* ---- defect: revocation ------------------------------------------------------------------- */

/* A key removed at SIGHUP: its open request connection gets no more
 * answers (no Pong, no SubmitOk), its stream stops within a second while
 * its job goes on, a new connection of it is refused; the other key keeps
 * its request connection and its stream. */
DTEST(daemon_revoke_open_connections)
{
    curve_dir c = {0};
    char ep[80], sep[80], text[200];
    if (curve_dir_make(&c, "revoke")) return;
    const char *spub = c.spub, *apub = c.apub, *asec = c.asec, *bpub = c.bpub, *bsec = c.bsec;
    int port = td_tcp_port(4831);
    snprintf(ep, sizeof ep, "tcp://127.0.0.1:%d", port);
    snprintf(sep, sizeof sep, "tcp://127.0.0.1:%d", port + 1);
    const char *extra[] = {"--curve-secret", c.key, "--authorized-keys", c.auth, "--verbose", NULL};
    td_daemon d;
    td_set_curve(spub, apub, asec);
    if (td_start_ep(&d, c.dir, ep, extra)) return;

    void *zctx = zmq_ctx_new();
    void *bd = NULL, *bs = NULL, *ad = NULL, *as = NULL;
    json_t *r = NULL;
    CHECK(zctx);
    /* one long job each, energy every 50 steps: a steady stream */
    Mpmd__Case *pb = long_case_pb(c.dir, 50);
    if (!pb) goto out;
    mpp_request sub = {.kind = MPP_REQ_SUBMIT, .case_pb = pb};
    mpp_request ping = {.kind = MPP_REQ_PING};
    bd = curve_socket(zctx, ZMQ_DEALER, ep, spub, bpub, bsec);
    ad = curve_socket(zctx, ZMQ_DEALER, ep, spub, apub, asec);
    if (!bd || !ad) goto out;
    unsigned long long jobs[2] = {0, 0};
    void *dealers[2] = {ad, bd};
    for (int k = 0; k < 2; k++) {
        r = dealer_request(dealers[k], &sub, 20);
        json_t *ok = json_object_get(r, "submitOk");
        const char *id = json_string_value(json_object_get(ok, "jobId"));
        jobs[k] = id ? strtoull(id, NULL, 10) : 0;
        json_decref(r);
        r = NULL;
        CHECKF(jobs[k] > 0, "submit as %s refused", k ? "b" : "a");
    }
    char topic[32];
    as = curve_socket(zctx, ZMQ_SUB, sep, spub, apub, asec);
    bs = curve_socket(zctx, ZMQ_SUB, sep, spub, bpub, bsec);
    if (!as || !bs) goto out;
    snprintf(topic, sizeof topic, "job:%016llx:", jobs[0]);
    CHECK(zmq_setsockopt(as, ZMQ_SUBSCRIBE, topic, strlen(topic)) == 0);
    snprintf(topic, sizeof topic, "job:%016llx:", jobs[1]);
    CHECK(zmq_setsockopt(bs, ZMQ_SUBSCRIBE, topic, strlen(topic)) == 0);
    CHECK(wait_watched(&d, jobs[0], 10) == 0 && wait_watched(&d, jobs[1], 10) == 0);
    long a0 = count_stream(as, 1.0), b0 = count_stream(bs, 1.0);
    int b_pong0 = dealer_pings(bd, 10);
    TLOG("before the revocation: b's open connection pings %s; in 1 s a's stream %ld, b's %ld "
         "messages",
         b_pong0 ? "ok" : "NOT", a0, b0);
    CHECK(b_pong0 && a0 > 0 && b0 > 0);

    /* b removed, SIGHUP */
    snprintf(text, sizeof text, "%s alice\n", apub);
    CHECK(write_file(c.auth, text, 0600) == 0);
    double t0 = td_now();
    CHECK(kill(d.pid, SIGHUP) == 0);
    while (!log_has(&d, "SIGHUP: keys re-read") && td_now() < t0 + 10) td_msleep(20);
    CHECK(log_has(&d, "1 removed"));
    count_stream(bs, 0.3); /* what was in flight at the reload */
    long b1 = count_stream(bs, 1.5), a1 = count_stream(as, 1.5);
    r = dealer_request(bd, &ping, 1.5);
    const char *b_ping = !r ? "no reply" : json_object_get(r, "pong") ? "Pong" : td_err_code(r);
    int b_ping_refused = !r || !json_object_get(r, "pong");
    TLOG("after: b's open connection's ping: %s", b_ping);
    json_decref(r);
    r = dealer_request(bd, &sub, 1.5);
    int b_submit_refused = !r || !json_object_get(r, "submitOk");
    TLOG("after: b's open connection's submit: %s", !r ? "no reply"
                                                    : json_object_get(r, "submitOk")
                                                        ? "SubmitOk"
                                                        : td_err_code(r));
    json_decref(r);
    r = NULL;
    int a_pong = dealer_pings(ad, 10);
    char st[32];
    CHECK(td_job_status(&d, jobs[1], st, sizeof st, NULL) == 0);
    TLOG("after: in 1.5 s b's stream %ld, a's %ld messages; a pings %s; b's job %s; log: %s", b1,
         a1, a_pong ? "ok" : "NOT", st,
         log_has(&d, "closed a connection of the revoked key") ? "connections closed"
                                                               : "nothing closed");
    CHECKF(b_ping_refused && b_submit_refused, "b's open connection is still served");
    CHECKF(b1 == 0, "b's stream still delivers after the revocation (%ld messages)", b1);
    CHECKF(a_pong && a1 > 0, "a lost its connection or stream (pong %d, %ld messages)", a_pong, a1);
    CHECKF(!strcmp(st, "RUNNING"), "b's job is %s: the revocation is about connections", st);
    /* a new connection of b: refused at the handshake */
    td_set_curve(spub, bpub, bsec);
    CHECK(td_request(d.ep, &ping, 2, &r) == 1 && !r);
    td_set_curve(spub, apub, asec);
out:
    json_decref(r);
    mpp_case_pb_free(&pb);
    if (bd) zmq_close(bd);
    if (bs) zmq_close(bs);
    if (ad) zmq_close(ad);
    if (as) zmq_close(as);
    if (zctx) zmq_ctx_term(zctx);
}

/* ---- defect: file permissions and the lock ------------------------------------------------ */

/* A child that takes a shared flock on each of paths (NULL-terminated) as
 * another user when the test runs as root (nobody), else as this user, and
 * holds them until killed.  Its pid, or -1. */
static pid_t hold_locks(const char *const *paths)
{
    int pfd[2];
    if (pipe(pfd)) return -1;
    pid_t pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        close(pfd[0]);
        if (geteuid() == 0 && (setgid(65534) || setuid(65534))) _exit(1);
        int held = 0;
        for (int i = 0; paths[i]; i++) {
            int fd = open(paths[i], O_RDONLY);
            held += fd >= 0 && flock(fd, LOCK_SH | LOCK_NB) == 0;
        }
        char c = (char)held;
        if (write(pfd[1], &c, 1) != 1) _exit(1);
        for (;;) pause();
    }
    close(pfd[1]);
    char c = 0;
    ssize_t n = read(pfd[0], &c, 1);
    close(pfd[0]);
    if (n != 1 || c == 0) {
        kill(pid, SIGKILL);
        waitpid(pid, NULL, 0);
        return -1;
    }
    return pid;
}

/* Lets another user walk into the test's directories (the temporary
 * directory is 0700) for a check as nobody; restore with open_dirs(NULL). */
static void open_dirs(const char *dir)
{
    static mode_t saved = 0700;
    if (!dir) {
        chmod(t_tmpdir(), saved);
        return;
    }
    saved = (mode_t)(file_mode(t_tmpdir()) & 07777);
    if (chmod(t_tmpdir(), 0711) || chmod(dir, 0755))
        t_fail(__FILE__, __LINE__, "chmod %s: %s", dir, strerror(errno));
}

static void reap(pid_t pid)
{
    if (pid <= 0) return;
    kill(pid, SIGKILL);
    waitpid(pid, NULL, 0);
}

/* The files mpmd makes are owner-only: the database, its -wal and -shm,
 * the lock file 0600, the checkpoint directory 0700 (with a checkpoint in
 * it, 0600); another user cannot open the database (as root: checked as
 * nobody). */
DTEST(daemon_perms_files)
{
    const char *tmp = t_tmpdir();
    char dir[300], p[500], cpath[500], st[32];
    td_daemon d;
    snprintf(dir, sizeof dir, "%s/perms", tmp);
    if (td_start(&d, dir, NULL)) return;
    json_t *c = long_case(100);
    json_t *ck = json_object();
    json_object_set_new(ck, "everySteps", json_integer(200));
    json_object_set_new(c, "checkpoint", ck);
    CHECK(write_case(c, dir, "long.json", cpath, sizeof cpath) == 0);
    td_out o;
    CHECK(td_ctl(&d, 30, &o, "submit", cpath, NULL) == 0);
    int ok = o.status == 0;
    td_out_free(&o);
    CHECK(ok);
    CHECK(td_wait_steps(&d, 1, 1000, 30) == 0);
    static const char *const suffix[] = {"", "-wal", "-shm", ".lock", ".ckpt/run-1.ckpt"};
    for (size_t k = 0; k < sizeof suffix / sizeof suffix[0]; k++) {
        snprintf(p, sizeof p, "%s%s", d.db, suffix[k]);
        unsigned m = file_mode(p);
        TLOG("%-22s mode %04o", suffix[k][0] ? suffix[k] : "mpmd.db", m);
        CHECKF(m == 0600, "%s has mode %04o", p, m);
    }
    snprintf(p, sizeof p, "%s.ckpt", d.db);
    TLOG("%-22s mode %04o", ".ckpt/", file_mode(p));
    CHECKF(file_mode(p) == 0700, "%s has mode %04o", p, file_mode(p));
    if (geteuid() == 0) {
        const char *paths[] = {d.db, NULL};
        open_dirs(dir);
        pid_t h = hold_locks(paths);
        open_dirs(NULL);
        TLOG("nobody opening and locking the database: %s", h > 0 ? "DID" : "refused");
        CHECKF(h < 0, "another user could open and lock the database");
        reap(h);
    }
    CHECK(td_ctl(&d, 30, &o, "cancel", "1", NULL) == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "CANCELLED", 20, st, sizeof st) == 0);
    CHECK(td_stop(&d) == 0);
}

/* A database and lock file an older mpmd left 0644, opened and locked
 * (shared) by another process - another user when the test runs as root -
 * no longer block a start: the files become owner-only (the lock file is
 * replaced) and the daemon answers.  Two daemons on one database and a
 * hard link to it stay refused. */
DTEST(daemon_perms_reader_lock_no_block)
{
    const char *tmp = t_tmpdir();
    char dir[300], lock[400], link2[400], ep2[400];
    td_daemon d, d2;
    td_out o;
    snprintf(dir, sizeof dir, "%s/rlock", tmp);
    if (td_start(&d, dir, NULL)) return;
    CHECK(td_stop(&d) == 0);
    snprintf(lock, sizeof lock, "%s.lock", d.db);
    /* as an older mpmd left them, and open to everyone's directory walk */
    CHECK(chmod(d.db, 0644) == 0 && chmod(lock, 0644) == 0);
    const char *paths[] = {d.db, lock, NULL};
    open_dirs(dir);
    pid_t h = hold_locks(paths);
    open_dirs(NULL);
    CHECKF(h > 0, "the reader could not lock the 0644 files");
    TLOG("a reader (%s) holds shared flocks on the database and the lock file",
         geteuid() == 0 ? "user nobody" : "this user: not root");
    int rc = td_start(&d, dir, NULL);
    reap(h);
    if (rc) return;
    CHECK(ping_ok(&d));
    TLOG("started; database %04o, lock file %04o; log: %s", file_mode(d.db), file_mode(lock),
         log_has(&d, "replaced by an owner-only one") ? "lock file replaced" : "-");
    CHECK(file_mode(d.db) == 0600 && file_mode(lock) == 0600);
    CHECK(log_has(&d, "replaced by an owner-only one"));

    /* a second mpmd on the same database: refused, naming the pid */
    snprintf(ep2, sizeof ep2, "ipc://%s/ctl2", dir);
    {
        const char *argv[] = {"--endpoint", ep2, "--db", d.db, NULL};
        CHECK(td_run_mpmd(argv, 20, &o) == 0);
        char want[64];
        snprintf(want, sizeof want, "in use by another mpmd (pid %d)", (int)d.pid);
        CHECKF(o.status != 0 && strstr(o.err, want), "second mpmd: status %d: %s", o.status, o.err);
        td_out_free(&o);
    }
    /* through a hard link: refused (a second name is a second WAL) */
    snprintf(link2, sizeof link2, "%s/link.db", dir);
    CHECK(link(d.db, link2) == 0);
    {
        const char *argv[] = {"--endpoint", ep2, "--db", link2, NULL};
        CHECK(td_run_mpmd(argv, 20, &o) == 0);
        TLOG("hard link: %s", o.err);
        CHECKF(o.status != 0 && strstr(o.err, "hard link"), "mpmd through a hard link: %d: %s",
               o.status, o.err);
        td_out_free(&o);
    }
    CHECK(unlink(link2) == 0);
    CHECK(ping_ok(&d));
    CHECK(td_stop(&d) == 0);
    /* a lock file that is a symlink, or another user's: refused, named */
    CHECK(unlink(lock) == 0 && symlink("/tmp/elsewhere", lock) == 0);
    {
        const char *argv[] = {"--endpoint", ep2, "--db", d.db, NULL};
        CHECK(td_run_mpmd(argv, 20, &o) == 0);
        CHECKF(o.status != 0 && strstr(o.err, lock), "a symlinked lock file: %d: %s", o.status,
               o.err);
        td_out_free(&o);
    }
    CHECK(unlink(lock) == 0);
    if (td_start(&d2, dir, NULL)) return;
    CHECK(ping_ok(&d2));
}

/* ---- defect: names ------------------------------------------------------------------------ */

/* The escape of text shown to a person. */
TEST(daemon_names_escape)
{
    static const struct {
        const char *in, *out;
    } cases[] = {
        {"plain name", "plain name"},
        {"a\\x1b[31m", "a\\\\x1b[31m"},
        {"a\x1b[31mb", "a\\x1b[31mb"},
        {"x\xe2\x80\xae"
         "cba",
         "x\\u202ecba"},
        {"\xe2\x80\xa8|\xe2\x80\xa9", "\\u2028|\\u2029"},
        {"\xe2\x80\x8e\xe2\x80\x8f\xe2\x80\xaa\xe2\x81\xa6\xe2\x81\xa9\xd8\x9c",
         "\\u200e\\u200f\\u202a\\u2066\\u2069\\u061c"},
        {"\xc2\x9b"
         "31m",
         "\\u009b31m"},
        {"\x9b"
         "31m",
         "\\x9b31m"},
        {"\xe2\x80", "\\xe2\\x80"},
        {"caf\xc3\xa9 \xe6\x97\xa5\xe6\x9c\xac \xf0\x9f\x98\x80",
         "caf\xc3\xa9 \xe6\x97\xa5\xe6\x9c\xac \xf0\x9f\x98\x80"},
        {"\xed\xa0\x80", "\\xed\\xa0\\x80"},
        {"tab\there\nnl\r\x7f", "tab\\there\\nnl\\r\\x7f"},
    };
    char buf[256];
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        mpp_text_escape(cases[i].in, buf, sizeof buf);
        CHECKF(!strcmp(buf, cases[i].out), "case %zu: got '%s', want '%s'", i, buf, cases[i].out);
    }
    /* cut short, never mid-escape */
    CHECK(mpp_text_escape("ab\xe2\x80\xae", buf, 7) == 2 && !strcmp(buf, "ab"));
    CHECK(mpp_text_escape(NULL, buf, sizeof buf) == 0 && !buf[0]);
}

/* A NUL in a name is refused naming the field: through mpmctl (JSON) and
 * as raw protobuf (where protobuf-c would have cut it); nothing is stored. */
DTEST(daemon_names_nul_refused)
{
    const char *tmp = t_tmpdir();
    char dir[300], path[500], err[ERRLEN];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/nul", tmp);
    if (td_start(&d, dir, NULL)) return;
    /* JSON through mpmctl */
    char *json = td_patch("{\"grid\"", "{\"name\": \"a\\u0000b\", \"grid\"");
    snprintf(path, sizeof path, "%s/nul.json", dir);
    CHECK(json && td_write(path, json) == 0);
    free(json);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    TLOG("mpmctl submit: exit %d: %s", o.status, o.err);
    int json_ok = o.status != 0 && strstr(o.err, "name") && strstr(o.err, "NUL");
    td_out_free(&o);

    /* raw protobuf: the case packed with "aXb", X made a NUL */
    json = td_patch("{\"grid\"", "{\"name\": \"a\\u0001b\", \"grid\"");
    Mpmd__Case *pb = NULL;
    CHECK(json && td_case_from_json(json, strlen(json), &pb, err, sizeof err) == 0);
    free(json);
    uint8_t *cb = NULL;
    size_t cn = 0;
    CHECK(mpp_case_pack(pb, &cb, &cn) == 0);
    mpp_case_pb_free(&pb);
    uint8_t *x = cb ? memmem(cb, cn,
                             "a\x01"
                             "b",
                             3)
                    : NULL;
    CHECK(x);
    if (x) x[1] = 0;
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_bytes = cb, .case_len = cn};
    json_t *reply = NULL;
    CHECK(td_request(d.ep, &rq, 20, &reply) == 0);
    TLOG("raw Submit: %s field %s: %s", td_err_code(reply), td_err_field(reply), td_err_msg(reply));
    int raw_ok = !json_object_get(reply, "submitOk") && !strcmp(td_err_field(reply), "name") &&
                 strstr(td_err_msg(reply), "NUL");
    if (json_object_get(reply, "submitOk")) {
        json_t *r = show_json(&d, 1);
        TLOG("accepted: stored as '%s' (%zu bytes)", r ? jstr(r, "name") : "?",
             r ? strlen(jstr(r, "name")) : 0);
        json_decref(r);
    }
    json_decref(reply);
    free(cb);
    CHECKF(json_ok, "mpmctl submit of a NUL name was not refused naming the field");
    CHECKF(raw_ok, "a NUL name as protobuf was not refused naming the field");
    CHECK(td_ctl(&d, 30, &o, "runs", NULL) == 0);
    CHECKF(o.status == 0 && count_lines(o.out) <= 1, "runs after the refusals:\n%s", o.out);
    td_out_free(&o);
}

/* Bidirectional controls, line separators and a literal backslash: stored
 * byte-exact (show --json gives the same bytes back), shown escaped by
 * mpmctl runs and show and in the log. */
DTEST(daemon_names_shown_escaped)
{
    const char *tmp = t_tmpdir();
    char dir[300], path[500], id[24], st[32];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/bidi", tmp);
    if (td_start(&d, dir, NULL)) return;
    /* the name: x U+202E evil U+2028 y U+2029 z, then \x1b[31m as text */
    const char *name = "x\xe2\x80\xae"
                       "evil\xe2\x80\xa8y\xe2\x80\xa9z\\x1b[31m";
    const char *shown = "x\\u202eevil\\u2028y\\u2029z\\\\x1b[31m";
    json_t *c = block2d(10, 5, name);
    CHECK(write_case(c, dir, "bidi.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    unsigned long long job = job_of(o.out);
    td_out_free(&o);
    CHECK(job > 0);
    CHECK(td_wait_status(&d, job, "FINISHED|FAILED", 60, st, sizeof st) == 0);
    snprintf(id, sizeof id, "%llu", job);
    json_t *r = show_json(&d, job);
    const char *stored = r ? jstr(r, "name") : "";
    int exact = !strcmp(stored, name);
    TLOG("stored byte-exact: %s", exact ? "yes" : "NO");
    CHECKF(exact, "the stored name differs: '%s'", stored);
    json_decref(r);
    /* runs cuts the name to its column: the escaped start of it */
    const char *cmds[2][3] = {{"runs", NULL, NULL}, {"show", id, NULL}};
    const char *want[2] = {"x\\u202eevil\\u2028y", shown};
    for (int k = 0; k < 2; k++) {
        CHECK(td_ctlv(&d, 30, &o, cmds[k]) == 0);
        int raw = strstr(o.out, "\xe2\x80\xae") || strstr(o.out, "\xe2\x80\xa8") ||
                  strstr(o.out, "\xe2\x80\xa9");
        TLOG("mpmctl %s: %s", cmds[k][0], strstr(o.out, want[k]) ? want[k] : "(not escaped)");
        CHECKF(o.status == 0 && !raw && strstr(o.out, want[k]), "mpmctl %s:\n%s", cmds[k][0],
               o.out);
        td_out_free(&o);
    }
    size_t len = 0;
    char *log = td_slurp(d.log, &len);
    CHECK(log);
    int raw = log && (memmem(log, len, "\xe2\x80\xae", 3) || memmem(log, len, "\xe2\x80\xa8", 3));
    int esc = log && strstr(log, shown);
    free(log);
    CHECKF(!raw && esc, "log: raw bidi %d, escaped name %d", raw, esc);
}

/* With --private-runs a refused cancel or resume does not name the owner's
 * key. */
DTEST(daemon_names_forbidden_no_key)
{
    curve_dir c = {0};
    char ep[80];
    if (curve_dir_make(&c, "private")) return;
    const char *spub = c.spub, *apub = c.apub, *asec = c.asec;
    snprintf(ep, sizeof ep, "tcp://127.0.0.1:%d", td_tcp_port(4841));
    const char *extra[] = {"--curve-secret", c.key, "--authorized-keys", c.auth,
                           "--private-runs", NULL};
    td_daemon d;
    td_set_curve(spub, apub, asec);
    if (td_start_ep(&d, c.dir, ep, extra)) return;
    Mpmd__Case *pb = long_case_pb(c.dir, 100);
    CHECK(pb);
    mpp_request sub = {.kind = MPP_REQ_SUBMIT, .case_pb = pb};
    json_t *r = NULL;
    CHECK(td_request(d.ep, &sub, 20, &r) == 0 && json_object_get(r, "submitOk"));
    json_decref(r);
    mpp_case_pb_free(&pb);
    mpp_request can = {.kind = MPP_REQ_CANCEL, .id = 1};
    mpp_request res = {.kind = MPP_REQ_RESUME, .id = 1};
    for (int k = 0; k < 2; k++) {
        char st[32];
        if (k) { /* a cancels its job; b may not resume it */
            r = NULL;
            CHECK(td_request(d.ep, &can, 20, &r) == 0 && !strcmp(td_err_code(r), ""));
            json_decref(r);
            CHECK(td_wait_status(&d, 1, "CANCELLED", 20, st, sizeof st) == 0);
        }
        td_set_curve(spub, c.bpub, c.bsec);
        r = NULL;
        CHECK(td_request(d.ep, k ? &res : &can, 20, &r) == 0);
        TLOG("b's %s of a's job: %s: %s", k ? "resume" : "cancel", td_err_code(r), td_err_msg(r));
        CHECKF(!strcmp(td_err_code(r), "FORBIDDEN") && !strstr(td_err_msg(r), apub) &&
                   strstr(td_err_msg(r), "another key"),
               "%s: %s", td_err_code(r), td_err_msg(r));
        json_decref(r);
        td_set_curve(spub, apub, asec);
    }
}
