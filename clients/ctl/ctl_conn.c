/*
 * ctl_conn.c - mpmctl's side of the control socket.  A DEALER connects to
 * the daemon's ROUTER and exchanges [empty][Request] / [empty][Reply]
 * frames, one request at a time, each bounded by the --timeout.  Requests
 * are packed with mpp_request_encode(); each reply is decoded once: into
 * the protocol library's mpp_reply (ctl_call_reply: energy pages,
 * snapshots, Status and Ping for `watch`), or, for the commands that print
 * a record with the field names the --json output shows, by the JSON
 * bridge into jansson (ctl_call).  Also here: where the job streams are
 * published (the stream endpoint) and paging through a run's energy
 * samples.
 */
#include "ctl.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <zmq.h>

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int ctl_conn_open(ctl_conn *c)
{
    int linger = 0, one = 1, ms;
    c->zctx = zmq_ctx_new();
    if (!c->zctx) {
        fprintf(stderr, "mpmctl: zmq_ctx_new: %s\n", zmq_strerror(errno));
        return CTL_ESYS;
    }
    c->dealer = zmq_socket(c->zctx, ZMQ_DEALER);
    if (!c->dealer) {
        fprintf(stderr, "mpmctl: zmq_socket: %s\n", zmq_strerror(errno));
        ctl_conn_close(c);
        return CTL_ESYS;
    }
    ms = (int)(c->timeout_s * 1000.0);
    /* ZMQ_IPV6: tcp://[::1]:PORT connects too (IPv4 addresses still do) */
    if (zmq_setsockopt(c->dealer, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_setsockopt(c->dealer, ZMQ_IPV6, &one, sizeof one) ||
        zmq_setsockopt(c->dealer, ZMQ_SNDTIMEO, &ms, sizeof ms)) {
        fprintf(stderr, "mpmctl: zmq_setsockopt: %s\n", zmq_strerror(errno));
        ctl_conn_close(c);
        return CTL_ESYS;
    }
    /* the monitor tells when the server drops the connection: a request
     * above its --max-request-bytes is refused so, unread, and no reply
     * would ever come */
    char mep[64];
    snprintf(mep, sizeof mep, "inproc://mpmctl-monitor-%p", (void *)c);
    if (ctl_conn_secure(c, c->dealer)) {
        ctl_conn_close(c);
        return CTL_ESYS;
    }
    /* ... and when a handshake fails (a CURVE key refused, or CURVE on one
     * side only): libzmq would retry silently until the timeout */
    if (zmq_socket_monitor(c->dealer, mep,
                           ZMQ_EVENT_DISCONNECTED | ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL |
                               ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                               ZMQ_EVENT_HANDSHAKE_FAILED_AUTH) == 0) {
        c->mon = zmq_socket(c->zctx, ZMQ_PAIR);
        if (c->mon && (zmq_setsockopt(c->mon, ZMQ_LINGER, &linger, sizeof linger) ||
                       zmq_connect(c->mon, mep))) {
            zmq_close(c->mon);
            c->mon = NULL;
        }
    }
    if (zmq_connect(c->dealer, c->endpoint)) {
        fprintf(stderr, "mpmctl: cannot connect to %s: %s\n", c->endpoint, zmq_strerror(errno));
        ctl_conn_close(c);
        return CTL_ESYS;
    }
    return 0;
}

/* What the monitor saw. */
enum { MON_NONE = 0, MON_DROPPED = 1, MON_HANDSHAKE = 2, MON_REFUSED = 3 };

/* Reads the monitor's pending events: the worst of MON_*. */
static int drain_monitor(ctl_conn *c)
{
    int seen = MON_NONE;
    for (;;) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        if (!c->mon || zmq_msg_recv(&m, c->mon, ZMQ_DONTWAIT) < 0) {
            zmq_msg_close(&m);
            return seen;
        }
        uint16_t ev = 0;
        if (zmq_msg_size(&m) >= 2 && zmq_msg_more(&m)) memcpy(&ev, zmq_msg_data(&m), 2);
        int k = ev == ZMQ_EVENT_DISCONNECTED            ? MON_DROPPED
                : ev == ZMQ_EVENT_HANDSHAKE_FAILED_AUTH ? MON_REFUSED
                : ev == ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL ||
                        ev == ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL
                    ? MON_HANDSHAKE
                    : MON_NONE;
        if (k > seen) seen = k;
        zmq_msg_close(&m);
    }
}

/* Says why the handshake failed; returns CTL_EAUTH. */
static int report_handshake(ctl_conn *c, int what)
{
    if (what == MON_REFUSED)
        fprintf(stderr,
                "mpmctl: %s refused this client's key (public key %s): it is not in the "
                "server's --authorized-keys, or was removed from it\n",
                c->endpoint, c->public_key);
    else if (c->curve)
        fprintf(stderr,
                "mpmctl: the CURVE handshake with %s failed (client public key %s): is %s the "
                "server's public key (MPMD_SERVER_KEY), and does the server use CURVE?\n",
                c->endpoint, c->public_key, c->server_key);
    else
        fprintf(stderr,
                "mpmctl: the handshake with %s failed: the server requires CURVE and this "
                "client has no key (set MPMD_SERVER_KEY and MPMD_CLIENT_KEY, or --keys DIR; "
                "docs/manual.md: Security)\n",
                c->endpoint);
    return CTL_EAUTH;
}

void ctl_conn_close(ctl_conn *c)
{
    if (c->mon) zmq_close(c->mon);
    c->mon = NULL;
    if (c->dealer) zmq_close(c->dealer);
    c->dealer = NULL;
    if (c->zctx) {
        while (zmq_ctx_term(c->zctx) && errno == EINTR) {
        }
    }
    c->zctx = NULL;
}

/* Receives one whole multipart message into parts (at most max), with the
 * total count in *nparts.  Returns 0 or CTL_ESYS. */
static int recv_multi(void *sock, zmq_msg_t *parts, int max, int *nparts)
{
    int more = 1, n = 0;
    size_t ml = sizeof more;
    while (more) {
        zmq_msg_t m;
        if (zmq_msg_init(&m)) return CTL_ESYS;
        while (zmq_msg_recv(&m, sock, 0) < 0) {
            if (errno != EINTR) {
                fprintf(stderr, "mpmctl: zmq_msg_recv: %s\n", zmq_strerror(errno));
                zmq_msg_close(&m);
                for (int i = 0; i < n && i < max; i++) zmq_msg_close(&parts[i]);
                return CTL_ESYS;
            }
        }
        if (zmq_getsockopt(sock, ZMQ_RCVMORE, &more, &ml)) more = 0;
        if (n < max)
            parts[n] = m;
        else
            zmq_msg_close(&m);
        n++;
    }
    *nparts = n;
    return 0;
}

/* Sends the request and receives the Reply: its frame moved into *body
 * (initialised by the caller, who closes it in every case). */
static int exchange_raw(ctl_conn *c, const mpp_request *rq, zmq_msg_t *body)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    zmq_msg_t parts[2];
    int n = 0, rc;
    double deadline = now_s() + c->timeout_s;
    if (!c->dealer && (rc = ctl_conn_open(c))) return rc;
    rc = mpp_request_encode(rq, &buf, &len);
    if (rc) {
        fprintf(stderr, "mpmctl: cannot encode the request (%d)\n", rc);
        return CTL_ESYS;
    }
    int before = drain_monitor(c); /* what happened before this request */
    if (before >= MON_HANDSHAKE) {
        free(buf);
        return report_handshake(c, before);
    }
    if (zmq_send(c->dealer, "", 0, ZMQ_SNDMORE) < 0 || zmq_send(c->dealer, buf, len, 0) < 0) {
        int e = errno;
        free(buf);
        if (e == EAGAIN) {
            fprintf(stderr, "mpmctl: no reply from %s within %g s (is mpmd running?)\n",
                    c->endpoint, c->timeout_s);
            return CTL_ETIMEOUT;
        }
        fprintf(stderr, "mpmctl: cannot send to %s: %s\n", c->endpoint, zmq_strerror(e));
        return CTL_ESYS;
    }
    free(buf);
    for (;;) {
        zmq_pollitem_t it[2] = {{c->dealer, 0, ZMQ_POLLIN, 0}, {c->mon, 0, ZMQ_POLLIN, 0}};
        double left = deadline - now_s();
        if (left <= 0) {
            fprintf(stderr, "mpmctl: no reply from %s within %g s (is mpmd running?)\n",
                    c->endpoint, c->timeout_s);
            return CTL_ETIMEOUT;
        }
        rc = zmq_poll(it, c->mon ? 2 : 1, (long)(left * 1000.0) + 1);
        if (rc < 0 && errno == EINTR) {
            if (ctl_interrupted) return CTL_EINTR;
            continue;
        }
        if (rc < 0) {
            fprintf(stderr, "mpmctl: zmq_poll: %s\n", zmq_strerror(errno));
            return CTL_ESYS;
        }
        if (rc > 0 && (it[0].revents & ZMQ_POLLIN)) break;
        int ev = rc > 0 ? drain_monitor(c) : MON_NONE;
        if (ev >= MON_HANDSHAKE) return report_handshake(c, ev);
        if (ev == MON_DROPPED) {
            fprintf(stderr,
                    "mpmctl: %s closed the connection without a reply: the request (%zu bytes) "
                    "may exceed the server's limit (mpmd --max-request-bytes), or the server "
                    "stopped\n",
                    c->endpoint, len);
            return CTL_ESYS;
        }
    }
    if ((rc = recv_multi(c->dealer, parts, 2, &n))) return rc;
    if (n != 2 || zmq_msg_size(&parts[0]) != 0) {
        fprintf(stderr, "mpmctl: malformed reply from %s (%d frames)\n", c->endpoint, n);
        rc = CTL_EPROTO;
    } else if (zmq_msg_move(body, &parts[1])) {
        rc = CTL_ESYS;
    }
    for (int i = 0; i < n && i < 2; i++) zmq_msg_close(&parts[i]);
    return rc;
}

/* Reply bytes -> a jansson object in *reply. */
static int reply_json(ctl_conn *c, const void *data, size_t size, json_t **reply)
{
    char *text = NULL, err[MPM_ERROR_MSG_MAX + 256];
    mpm_error e;
    *reply = NULL;
    if (mpp_msg_bytes_to_json(MPP_MSG_REPLY, data, size, 0, 0, &text, &e)) {
        fprintf(stderr, "mpmctl: undecodable reply from %s: %s\n", c->endpoint,
                mpm_error_text(&e, MPM_FIELD_JSON, err, sizeof err));
        return CTL_EPROTO;
    }
    json_error_t je;
    *reply = json_loads(text, 0, &je);
    free(text);
    if (!*reply) {
        fprintf(stderr, "mpmctl: reply: %s\n", je.text);
        return CTL_ESYS;
    }
    return 0;
}

/* Sends the request and receives the Reply bytes, decoded to a jansson
 * object in *reply. */
static int exchange(ctl_conn *c, const mpp_request *rq, json_t **reply)
{
    zmq_msg_t body;
    int rc;
    *reply = NULL;
    if (zmq_msg_init(&body)) return CTL_ESYS;
    rc = exchange_raw(c, rq, &body);
    if (!rc) rc = reply_json(c, zmq_msg_data(&body), zmq_msg_size(&body), reply);
    zmq_msg_close(&body);
    return rc;
}

/* What ctl_call_quiet() makes of a decoded reply. */
static int interpret(ctl_conn *c, json_t *reply, const char *want, json_t **body,
                     const char **err_code, const char **err_msg)
{
    json_t *e;
    *body = NULL;
    if (err_code) *err_code = "";
    if (err_msg) *err_msg = "";
    e = json_object_get(reply, "error");
    if (e) {
        if (err_code) *err_code = cj_str(e, "code", "INTERNAL");
        if (err_msg) *err_msg = cj_str(e, "message", "");
        return CTL_ESERVER;
    }
    *body = json_object_get(reply, want);
    if (!*body) {
        const char *key, *got = "nothing";
        json_t *v;
        json_object_foreach(reply, key, v)
        {
            if (strcmp(key, "schemaVersion")) {
                got = key;
                break;
            }
        }
        fprintf(stderr, "mpmctl: unexpected reply from %s: %s instead of %s\n", c->endpoint, got,
                want);
        return CTL_EPROTO;
    }
    return 0;
}

int ctl_call_quiet(ctl_conn *c, const mpp_request *rq, const char *want, json_t **reply,
                   json_t **body, const char **err_code, const char **err_msg)
{
    int rc = exchange(c, rq, reply);
    if (rc) {
        *body = NULL;
        if (err_code) *err_code = "";
        if (err_msg) *err_msg = "";
        return rc;
    }
    return interpret(c, *reply, want, body, err_code, err_msg);
}

/* Prints a Reply.error: "mpmctl: CODE: message", with " (field F)" when
 * the message does not already start with "F: " (an mpmd renders every
 * error as "field: message"; an older one did not always). */
static void print_error(const char *code, const char *message, const char *field)
{
    size_t n = field ? strlen(field) : 0;
    char text[4096];
    fprintf(stderr, "mpmctl: %s: %s", code, ctl_esc(message, text, sizeof text));
    if (n && !(strncmp(message, field, n) == 0 && message[n] == ':'))
        fprintf(stderr, " (field %s)", field);
    fputc('\n', stderr);
}

static void print_server_error(json_t *reply)
{
    json_t *e = json_object_get(reply, "error");
    print_error(cj_str(e, "code", "INTERNAL"), cj_str(e, "message", ""), cj_str(e, "field", NULL));
}

int ctl_call(ctl_conn *c, const mpp_request *rq, const char *want, json_t **reply, json_t **body)
{
    int rc = ctl_call_quiet(c, rq, want, reply, body, NULL, NULL);
    if (rc == CTL_ESERVER) print_server_error(*reply);
    return rc;
}

int ctl_call_reply(ctl_conn *c, const mpp_request *rq, mpp_reply_kind want, mpp_reply *out)
{
    zmq_msg_t body;
    mpm_error e;
    char text[MPM_ERROR_MSG_MAX + 256];
    int rc;
    memset(out, 0, sizeof *out);
    if (zmq_msg_init(&body)) return CTL_ESYS;
    rc = exchange_raw(c, rq, &body);
    if (!rc && (rc = mpp_reply_decode(zmq_msg_data(&body), zmq_msg_size(&body), 0, out, &e))) {
        fprintf(stderr, "mpmctl: undecodable reply from %s: %s\n", c->endpoint,
                mpm_error_text(&e, MPM_FIELD_JSON, text, sizeof text));
        rc = rc == MPM_ENOMEM ? CTL_ESYS : CTL_EPROTO;
    }
    zmq_msg_close(&body);
    if (rc) return rc;
    if (out->kind == MPP_REPLY_ERROR) {
        const char *code = mpp_err_code_name(out->err_code);
        print_error(code ? code : "INTERNAL", out->err_message, out->err_field);
        return CTL_ESERVER;
    }
    if (out->kind != want) {
        fprintf(stderr, "mpmctl: unexpected reply from %s: %s instead of %s\n", c->endpoint,
                mpp_reply_kind_name(out->kind), mpp_reply_kind_name(want));
        return CTL_EPROTO;
    }
    return 0;
}

/* ---- stream endpoint ----------------------------------------------------- */

int ctl_stream_endpoint(ctl_conn *c, char *out, size_t n)
{
    mpp_request rq = {.kind = MPP_REQ_PING};
    mpp_reply pong;
    int rc;
    if (c->stream && *c->stream) {
        if ((size_t)snprintf(out, n, "%s", c->stream) >= n) return CTL_EUSAGE;
        return 0;
    }
    rc = ctl_call_reply(c, &rq, MPP_REPLY_PONG, &pong);
    if (!rc && mpp_stream_endpoint_for_client(pong.stream_endpoint, c->endpoint, out, n)) {
        fprintf(stderr, "mpmctl: cannot derive the stream endpoint from %s; give --stream EP\n",
                c->endpoint);
        rc = CTL_EUSAGE;
    }
    mpp_reply_clear(&pong);
    return rc;
}

/* ---- energy paging --------------------------------------------------------- */

int ctl_fetch_energy(ctl_conn *c, uint64_t run_id, uint64_t from, ctl_sample_fn fn, void *arg)
{
    for (;;) {
        mpp_request rq = {.kind = MPP_REQ_GET_ENERGY, .id = run_id, .from_seq = from};
        mpp_reply page;
        size_t i;
        uint64_t last = from;
        int rc = ctl_call_reply(c, &rq, MPP_REPLY_ENERGY, &page);
        for (i = 0; !rc && i < page.n_samples; i++) {
            last = page.samples[i].seq;
            rc = fn(&page.samples[i], arg);
        }
        size_t ns = page.n_samples;
        int more = page.more;
        mpp_reply_clear(&page);
        if (rc) return rc;
        if (!more) return 0;
        if (!ns || last + 1 <= from) {
            fprintf(stderr,
                    "mpmctl: energy of run %llu: the server says there is more after seq "
                    "%llu but sent nothing new\n",
                    (unsigned long long)run_id, (unsigned long long)from);
            return CTL_EPROTO;
        }
        from = last + 1;
    }
}

void ctl_drain_more(void *sock)
{
    int more = 1;
    size_t ml = sizeof more;
    while (more) {
        zmq_msg_t x;
        if (zmq_msg_init(&x)) break;
        if (zmq_msg_recv(&x, sock, 0) < 0 || zmq_getsockopt(sock, ZMQ_RCVMORE, &more, &ml))
            more = 0;
        zmq_msg_close(&x);
    }
}
