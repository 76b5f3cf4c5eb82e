/*
 * ctl_conn.c - mpmctl's side of the control socket.  A DEALER connects to
 * the daemon's ROUTER and exchanges [empty][Request] / [empty][Reply]
 * frames, one request at a time, each bounded by the --timeout.  Requests
 * are packed with srv_request_encode(); replies are turned into JSON by the
 * codec's bridge and parsed with jansson, so every command reads the same
 * field names the --json output shows.  Also here: where the job streams
 * are published (the stream endpoint) and paging through a run's energy
 * samples, which are decoded straight into structs (srv_reply_energy_decode)
 * and go through JSON only for --json output.
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
    int linger = 0, ms;
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
    if (zmq_setsockopt(c->dealer, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_setsockopt(c->dealer, ZMQ_SNDTIMEO, &ms, sizeof ms)) {
        fprintf(stderr, "mpmctl: zmq_setsockopt: %s\n", zmq_strerror(errno));
        ctl_conn_close(c);
        return CTL_ESYS;
    }
    if (zmq_connect(c->dealer, c->endpoint)) {
        fprintf(stderr, "mpmctl: cannot connect to %s: %s\n", c->endpoint, zmq_strerror(errno));
        ctl_conn_close(c);
        return CTL_ESYS;
    }
    return 0;
}

void ctl_conn_close(ctl_conn *c)
{
    if (c->dealer) zmq_close(c->dealer);
    c->dealer = NULL;
    if (c->zctx) {
        while (zmq_ctx_term(c->zctx) && errno == EINTR) {}
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
        if (n < max) parts[n] = m;
        else zmq_msg_close(&m);
        n++;
    }
    *nparts = n;
    return 0;
}

/* Sends the request and receives the Reply: its frame moved into *body
 * (initialised by the caller, who closes it in every case). */
static int exchange_raw(ctl_conn *c, const srv_request *rq, zmq_msg_t *body)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    zmq_msg_t parts[2];
    int n = 0, rc;
    double deadline = now_s() + c->timeout_s;
    if (!c->dealer && (rc = ctl_conn_open(c))) return rc;
    rc = srv_request_encode(rq, &buf, &len);
    if (rc) {
        fprintf(stderr, "mpmctl: cannot encode the request (%d)\n", rc);
        return CTL_ESYS;
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
        zmq_pollitem_t it = {c->dealer, 0, ZMQ_POLLIN, 0};
        double left = deadline - now_s();
        if (left <= 0) {
            fprintf(stderr, "mpmctl: no reply from %s within %g s (is mpmd running?)\n",
                    c->endpoint, c->timeout_s);
            return CTL_ETIMEOUT;
        }
        rc = zmq_poll(&it, 1, (long)(left * 1000.0) + 1);
        if (rc < 0 && errno == EINTR) {
            if (ctl_interrupted) return CTL_EINTR;
            continue;
        }
        if (rc < 0) {
            fprintf(stderr, "mpmctl: zmq_poll: %s\n", zmq_strerror(errno));
            return CTL_ESYS;
        }
        if (rc > 0) break;
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
    char *text = NULL, err[512];
    *reply = NULL;
    if (srv_msg_bytes_to_json(SRV_MSG_REPLY, data, size, 0, 0, &text, err, sizeof err)) {
        fprintf(stderr, "mpmctl: undecodable reply from %s: %s\n", c->endpoint, err);
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
static int exchange(ctl_conn *c, const srv_request *rq, json_t **reply)
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
        json_object_foreach(reply, key, v) {
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

int ctl_call_quiet(ctl_conn *c, const srv_request *rq, const char *want, json_t **reply,
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

/* Prints a Reply.error as ctl_call() does. */
static void print_server_error(json_t *reply)
{
    json_t *e = json_object_get(reply, "error");
    const char *field = cj_str(e, "field", NULL);
    fprintf(stderr, "mpmctl: %s: %s", cj_str(e, "code", "INTERNAL"), cj_str(e, "message", ""));
    if (field && *field) fprintf(stderr, " (field %s)", field);
    fputc('\n', stderr);
}

int ctl_call(ctl_conn *c, const srv_request *rq, const char *want, json_t **reply, json_t **body)
{
    int rc = ctl_call_quiet(c, rq, want, reply, body, NULL, NULL);
    if (rc == CTL_ESERVER) print_server_error(*reply);
    return rc;
}

/* ---- stream endpoint ----------------------------------------------------- */

int ctl_derive_stream(const char *ep, char *out, size_t n)
{
    if (!strncmp(ep, "tcp://", 6)) {
        const char *colon = strrchr(ep + 6, ':');
        char *end;
        long port;
        if (colon) {
            errno = 0;
            port = strtol(colon + 1, &end, 10);
            if (!errno && end != colon + 1 && !*end && port > 0 && port < 65535) {
                int w = snprintf(out, n, "%.*s:%ld", (int)(colon - ep), ep, port + 1);
                if (w > 0 && (size_t)w < n) return 0;
            }
        }
    } else if (!strncmp(ep, "ipc://", 6)) {
        int w = snprintf(out, n, "%s.stream", ep);
        if (w > 0 && (size_t)w < n) return 0;
    }
    fprintf(stderr, "mpmctl: cannot derive the stream endpoint from %s; give --stream EP\n", ep);
    return CTL_EUSAGE;
}

/* Whether a tcp endpoint's host is a wildcard or loopback address, which
 * only means something on the daemon's machine. */
static int host_is_local(const char *ep)
{
    static const char *const hosts[] = {"*", "0.0.0.0", "[::]", "::", "[*]", "localhost",
                                        "[::1]", "::1", "ip6-localhost"};
    const char *h = ep + 6, *colon = strrchr(h, ':');
    size_t len = colon ? (size_t)(colon - h) : strlen(h);
    if (len >= 4 && !strncmp(h, "127.", 4)) return 1;
    for (size_t i = 0; i < sizeof hosts / sizeof hosts[0]; i++)
        if (strlen(hosts[i]) == len && !strncmp(h, hosts[i], len)) return 1;
    return 0;
}

int ctl_stream_endpoint(ctl_conn *c, char *out, size_t n)
{
    srv_request rq = {.kind = SRV_REQ_PING};
    json_t *reply = NULL, *pong = NULL;
    const char *ep;
    int rc;
    if (c->stream && *c->stream) {
        if ((size_t)snprintf(out, n, "%s", c->stream) >= n) return CTL_EUSAGE;
        return 0;
    }
    rc = ctl_call(c, &rq, "pong", &reply, &pong);
    if (rc) {
        json_decref(reply);
        return rc;
    }
    ep = cj_str(pong, "streamEndpoint", "");
    if (*ep && !(strncmp(ep, "tcp://", 6) == 0 && host_is_local(ep)) &&
        (size_t)snprintf(out, n, "%s", ep) < n) {
        json_decref(reply);
        return 0;
    }
    json_decref(reply);
    return ctl_derive_stream(c->endpoint, out, n);
}

/* ---- energy paging --------------------------------------------------------- */

/* One page of GetEnergy: the samples decoded straight from the bytes
 * (srv_reply_energy_decode: no JSON round trip, which cost about half the
 * time of `mpmctl energy`), and with want_json also the JSON samples for
 * the --json output; anything but an EnergySeries goes the ctl_call() way
 * (a Reply.error printed, a wrong body reported). */
static int energy_page(ctl_conn *c, const srv_request *rq, int want_json, srv_energy_sample **s,
                       size_t *ns, int *more, json_t **reply, json_t **samples)
{
    zmq_msg_t body;
    uint64_t run_id;
    char err[512];
    int rc;
    *s = NULL;
    *ns = 0;
    *more = 0;
    *reply = *samples = NULL;
    if (zmq_msg_init(&body)) return CTL_ESYS;
    rc = exchange_raw(c, rq, &body);
    if (!rc) {
        rc = srv_reply_energy_decode(zmq_msg_data(&body), zmq_msg_size(&body), 0, &run_id, s, ns,
                                     more, err, sizeof err);
        if (rc == SRV_CODEC_ENOMEM) {
            fprintf(stderr, "mpmctl: out of memory decoding energy samples\n");
            rc = CTL_ESYS;
        } else if (rc || want_json) {
            /* not an energy series (or undecodable), or --json: the JSON
             * form, as every other reply */
            json_t *series = NULL;
            int bad = rc != 0;
            rc = reply_json(c, zmq_msg_data(&body), zmq_msg_size(&body), reply);
            if (!rc) rc = interpret(c, *reply, "energy", &series, NULL, NULL);
            if (rc == CTL_ESERVER) print_server_error(*reply);
            if (!rc && bad) rc = CTL_EPROTO;  /* JSON could read what the decoder could not */
            if (!rc) {
                json_t *a = json_object_get(series, "samples");
                size_t na = json_is_array(a) ? json_array_size(a) : 0;
                if (na != *ns) {
                    fprintf(stderr, "mpmctl: energy page: %zu samples decoded, %zu in JSON\n", *ns, na);
                    rc = CTL_EPROTO;
                }
                *samples = a;
            }
        }
    }
    zmq_msg_close(&body);
    if (rc) {
        free(*s);
        *s = NULL;
        *ns = 0;
    }
    return rc;
}

int ctl_fetch_energy(ctl_conn *c, uint64_t run_id, uint64_t from, int want_json, ctl_sample_fn fn,
                     void *arg)
{
    for (;;) {
        srv_request rq = {.kind = SRV_REQ_GET_ENERGY, .id = run_id, .from_seq = from};
        json_t *reply = NULL, *samples = NULL;
        srv_energy_sample *s = NULL;
        size_t i, ns = 0;
        int more = 0;
        uint64_t last = from;
        int rc = energy_page(c, &rq, want_json, &s, &ns, &more, &reply, &samples);
        for (i = 0; !rc && i < ns; i++) {
            last = s[i].seq;
            rc = fn(&s[i], samples ? json_array_get(samples, i) : NULL, arg);
        }
        free(s);
        json_decref(reply);
        if (rc) return rc;
        if (!more) return 0;
        if (!ns || last + 1 <= from) {
            fprintf(stderr, "mpmctl: energy of run %llu: the server says there is more after seq "
                            "%llu but sent nothing new\n",
                    (unsigned long long)run_id, (unsigned long long)from);
            return CTL_EPROTO;
        }
        from = last + 1;
    }
}
