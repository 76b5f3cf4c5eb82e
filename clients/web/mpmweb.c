/*
 * mpmweb.c - the live web monitor: a gateway that is a client of mpmd
 * (the same endpoint, stream and CURVE key rules and flags as mpmctl) and
 * serves one page over HTTP with Debian's libmicrohttpd (one thread per
 * connection, at most WEB_MAX_CONNECTIONS).  This file holds the command
 * line, the server, the routing, the static files and the limits:
 * How it works: the notes after the includes.
 */
#include "web.h"

#include <arpa/inet.h>
#include <errno.h>
#include <limits.h>
#include <netdb.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include <microhttpd.h>

/*
 *   GET  /, /app.js, /style.css  the page (clients/web/static/, read from
 *                                --static DIR, else ../clients/web/static
 *                                next to the binary, else
 *                                /usr/share/mpmd/web)
 *   GET  /api/config             {"allowControl", "version", "endpoint"}
 *   GET  /api/runs?status=&before=&limit=&name=   a page of runs
 *   GET  /api/run/ID[?case=1], /api/job/JOB, /api/energy/ID?from=SEQ
 *   GET  /api/snapshot/ID?step=N a recorded snapshot (compact JSON)
 *   GET  /api/live/JOB           the latest streamed snapshot of a watched job
 *   GET  /api/events/JOB         Server-Sent Events: run, history, progress,
 *                                energy, snapshot (a notice), finished
 *   POST /api/submit, /api/cancel/JOB   only with --allow-control, and only
 *                                with the header X-Mpmweb: 1 (a cross-site
 *                                form cannot set it)
 *
 * Safe by default: it binds loopback unless --allow-remote is given (and
 * then says so), answers only requests whose Host is this machine's
 * loopback name when bound to loopback (no DNS rebinding), is read-only
 * unless --allow-control, sends every string as JSON through jansson and a
 * Content-Security-Policy that forbids inline script, and bounds URLs,
 * bodies, connections and each browser's event queue.
 */

volatile sig_atomic_t ctl_interrupted;

static web_ctx W = {.mu = PTHREAD_MUTEX_INITIALIZER};
static char static_dir[PATH_MAX];
static int bound_loopback;

static const char CSP[] = "default-src 'self'; img-src 'self' data:; object-src 'none'; "
                          "base-uri 'none'; frame-ancestors 'none'; form-action 'none'";

/* ---- responses ----------------------------------------------------------- */

static void headers(struct MHD_Response *rs, const char *ctype, int cache)
{
    MHD_add_response_header(rs, "Content-Type", ctype);
    MHD_add_response_header(rs, "X-Content-Type-Options", "nosniff");
    MHD_add_response_header(rs, "Content-Security-Policy", CSP);
    MHD_add_response_header(rs, "Referrer-Policy", "no-referrer");
    MHD_add_response_header(rs, "X-Frame-Options", "DENY");
    MHD_add_response_header(rs, "Cache-Control", cache ? "no-cache" : "no-store");
}

/* Queues r (its body handed to MHD, which frees it). */
static enum MHD_Result send_resp(struct MHD_Connection *conn, web_resp *r)
{
    struct MHD_Response *rs;
    if (!r->body) web_error(r, 500, "INTERNAL", "no answer");
    rs = MHD_create_response_from_buffer(r->len, r->body, MHD_RESPMEM_MUST_FREE);
    if (!rs) {
        free(r->body);
        return MHD_NO;
    }
    headers(rs, r->ctype ? r->ctype : "application/json", 0);
    enum MHD_Result ok = MHD_queue_response(conn, r->status, rs);
    MHD_destroy_response(rs);
    return ok;
}

static enum MHD_Result send_error(struct MHD_Connection *conn, unsigned status, const char *code,
                                  const char *msg)
{
    web_resp r = {0};
    web_error(&r, status, code, msg);
    return send_resp(conn, &r);
}

/* ---- static files ------------------------------------------------------------- */

static enum MHD_Result send_static(struct MHD_Connection *conn, const char *name, const char *ctype)
{
    char path[PATH_MAX + 64];
    snprintf(path, sizeof path, "%s/%s", static_dir, name);
    FILE *f = fopen(path, "rb");
    if (!f) return send_error(conn, 404, "NOT_FOUND", "no such file in the page's directory");
    char *buf = NULL;
    size_t n = 0, cap = 0;
    for (;;) {
        if (n + 65536 > cap) {
            char *p = realloc(buf, cap = n + 65536);
            if (!p) {
                free(buf);
                fclose(f);
                return send_error(conn, 500, "INTERNAL", "out of memory");
            }
            buf = p;
        }
        size_t k = fread(buf + n, 1, 65536, f);
        n += k;
        if (k < 65536) break;
    }
    fclose(f);
    web_resp r = {200, buf, n, ctype};
    struct MHD_Response *rs = MHD_create_response_from_buffer(r.len, r.body, MHD_RESPMEM_MUST_FREE);
    if (!rs) {
        free(buf);
        return MHD_NO;
    }
    headers(rs, ctype, 1);
    enum MHD_Result ok = MHD_queue_response(conn, 200, rs);
    MHD_destroy_response(rs);
    return ok;
}

/* Finds the page: --static DIR, else ../clients/web/static beside the
 * binary (bin/mpmweb in the source tree), else /usr/share/mpmd/web. */
static int find_static(const char *given)
{
    char exe[PATH_MAX], probe[PATH_MAX + 64];
    const char *cands[3] = {given, NULL, "/usr/share/mpmd/web"};
    ssize_t k = readlink("/proc/self/exe", exe, sizeof exe - 1);
    char rel[PATH_MAX + 64];
    if (k > 0) {
        exe[k] = 0;
        char *slash = strrchr(exe, '/');
        if (slash) *slash = 0;
        snprintf(rel, sizeof rel, "%s/../clients/web/static", exe);
        cands[1] = rel;
    }
    for (int i = given ? 0 : 1; i < 3; i++) {
        if (!cands[i]) continue;
        snprintf(probe, sizeof probe, "%s/index.html", cands[i]);
        if (access(probe, R_OK) == 0) {
            snprintf(static_dir, sizeof static_dir, "%s", cands[i]);
            return 0;
        }
        if (given) break;
    }
    fprintf(stderr,
            "mpmweb: cannot find the page (index.html) %s%s; give --static DIR "
            "(clients/web/static in the source tree)\n",
            given ? "in " : "beside the binary or in /usr/share/mpmd/web", given ? given : "");
    return -1;
}

/* ---- the event stream ------------------------------------------------------------- */

static ssize_t sse_read(void *cls, uint64_t pos, char *buf, size_t max)
{
    (void)pos;
    long n = web_hub_read(cls, buf, max);
    return n < 0 ? MHD_CONTENT_READER_END_OF_STREAM : (ssize_t)n;
}

static void sse_free(void *cls)
{
    web_hub_leave(cls);
}

/* "event: NAME\ndata: DATA\n\n" (malloc'd). */
static char *event_text(const char *name, const char *data, size_t *len)
{
    size_t n = strlen(name) + strlen(data) + 32;
    char *t = malloc(n);
    if (t) *len = (size_t)snprintf(t, n, "event: %s\ndata: %s\n\n", name, data);
    return t;
}

/* GET /api/events/JOB: subscribe first, then the job's record and its
 * energy history go in front of whatever the stream brings meanwhile (the
 * page drops the samples it already has, by seq, and fills gaps). */
static enum MHD_Result send_events(struct MHD_Connection *conn, const char *job_s)
{
    uint64_t job = web_parse_id(job_s);
    web_resp st = {0};
    if (!job) return send_error(conn, 400, "BAD_REQUEST", "job id: must be a number >= 1");
    web_api_status(&W, job_s, &st);
    if (st.status != 200) return send_resp(conn, &st);
    json_t *run = json_loads(st.body, 0, NULL);
    uint64_t run_id = run ? cj_u64(run, "runId", 0) : 0;
    json_decref(run);
    if (!run_id) {
        free(st.body);
        return send_error(conn, 502, "INTERNAL", "the job's record has no run id");
    }
    if (web_stream_endpoint(&W)) {
        free(st.body);
        return send_error(conn, 502, "UNAVAILABLE", "cannot find mpmd's stream endpoint");
    }
    web_client *c = web_hub_join(job, NULL);
    if (!c) {
        free(st.body);
        return send_error(conn, 503, "UNAVAILABLE", "too many event streams open (at most 32)");
    }
    char *hist = NULL;
    size_t l1 = 0, l2 = 0;
    char *e1 = NULL, *e2 = NULL;
    if (web_energy_history(&W, run_id, &hist) == 0 && (e2 = event_text("history", hist, &l2)))
        web_hub_push_front(c, e2, l2);
    if ((e1 = event_text("run", st.body, &l1))) web_hub_push_front(c, e1, l1);
    free(e1);
    free(e2);
    free(hist);
    free(st.body);
    struct MHD_Response *rs =
        MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 16384, sse_read, c, sse_free);
    if (!rs) {
        web_hub_leave(c);
        return MHD_NO;
    }
    headers(rs, "text/event-stream", 0);
    MHD_add_response_header(rs, "X-Accel-Buffering", "no");
    enum MHD_Result ok = MHD_queue_response(conn, 200, rs);
    MHD_destroy_response(rs);
    return ok;
}

/* ---- requests ----------------------------------------------------------------- */

typedef struct {
    char *body;
    size_t n;
    int too_big;
} upload_t;

static const char *arg(struct MHD_Connection *conn, const char *key)
{
    return MHD_lookup_connection_value(conn, MHD_GET_ARGUMENT_KIND, key);
}

/* When bound to loopback, the Host must name it (a page of another site
 * whose name resolves to 127.0.0.1 is refused: no DNS rebinding). */
static int host_ok(struct MHD_Connection *conn)
{
    if (!bound_loopback) return 1;
    const char *h = MHD_lookup_connection_value(conn, MHD_HEADER_KIND, "Host");
    if (!h) return 0;
    static const char *ok[] = {"127.0.0.1", "localhost", "[::1]"};
    for (size_t i = 0; i < 3; i++) {
        size_t k = strlen(ok[i]);
        if (!strncmp(h, ok[i], k) && (h[k] == 0 || h[k] == ':')) return 1;
    }
    return 0;
}

/* The id after a prefix ("/api/run/" + "12"), or NULL when url lacks it. */
static const char *after(const char *url, const char *prefix)
{
    size_t k = strlen(prefix);
    return strncmp(url, prefix, k) ? NULL : url + k;
}

static enum MHD_Result route_get(struct MHD_Connection *conn, const char *url)
{
    web_resp r = {0};
    const char *id;
    if (!strcmp(url, "/") || !strcmp(url, "/index.html"))
        return send_static(conn, "index.html", "text/html; charset=utf-8");
    if (!strcmp(url, "/app.js")) return send_static(conn, "app.js", "text/javascript");
    if (!strcmp(url, "/style.css")) return send_static(conn, "style.css", "text/css");
    if (!strcmp(url, "/api/config")) {
        json_t *o = json_pack("{s:b,s:s,s:s}", "allowControl", W.allow_control, "version",
                              MPP_VERSION, "endpoint", W.conn.endpoint);
        char *t = o ? json_dumps(o, JSON_COMPACT) : NULL;
        json_decref(o);
        if (!t) return send_error(conn, 500, "INTERNAL", "out of memory");
        web_json(&r, 200, t);
    } else if (!strcmp(url, "/api/runs")) {
        web_api_runs(&W, arg(conn, "status"), arg(conn, "before"), arg(conn, "limit"),
                     arg(conn, "name"), &r);
    } else if ((id = after(url, "/api/run/"))) {
        const char *wc = arg(conn, "case");
        web_api_run(&W, id, wc && !strcmp(wc, "1"), &r);
    } else if ((id = after(url, "/api/job/"))) {
        web_api_status(&W, id, &r);
    } else if ((id = after(url, "/api/energy/"))) {
        web_api_energy(&W, id, arg(conn, "from"), &r);
    } else if ((id = after(url, "/api/snapshot/"))) {
        web_api_snapshot(&W, id, arg(conn, "step"), &r);
    } else if ((id = after(url, "/api/live/"))) {
        uint64_t job = web_parse_id(id);
        char *t;
        size_t n;
        if (!job) return send_error(conn, 400, "BAD_REQUEST", "job id: must be a number >= 1");
        if (web_hub_latest(job, &t, &n))
            return send_error(conn, 404, "NOT_FOUND",
                              "no live snapshot of this job yet (open its event stream first)");
        web_json(&r, 200, t);
    } else if ((id = after(url, "/api/events/"))) {
        return send_events(conn, id);
    } else {
        return send_error(conn, 404, "NOT_FOUND", "no such page");
    }
    return send_resp(conn, &r);
}

static enum MHD_Result route_post(struct MHD_Connection *conn, const char *url, upload_t *u)
{
    web_resp r = {0};
    const char *id;
    const char *mark = MHD_lookup_connection_value(conn, MHD_HEADER_KIND, "X-Mpmweb");
    if (!W.allow_control)
        return send_error(conn, 403, "FORBIDDEN",
                          "control is disabled: start mpmweb with --allow-control");
    if (!mark || strcmp(mark, "1"))
        return send_error(conn, 403, "FORBIDDEN", "a control request needs the header X-Mpmweb: 1");
    if (u->too_big) return send_error(conn, 413, "TOO_LARGE", "the body is over 8 MB");
    if (!strcmp(url, "/api/submit"))
        web_api_submit(&W, u->body ? u->body : "", u->n, &r);
    else if ((id = after(url, "/api/cancel/")))
        web_api_cancel(&W, id, &r);
    else
        return send_error(conn, 404, "NOT_FOUND", "no such control endpoint");
    return send_resp(conn, &r);
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *conn, const char *url,
                                  const char *method, const char *version, const char *upload_data,
                                  size_t *upload_size, void **con_cls)
{
    (void)cls;
    (void)version;
    upload_t *u = *con_cls;
    if (!u) {
        u = calloc(1, sizeof *u);
        if (!u) return MHD_NO;
        *con_cls = u;
        return MHD_YES;
    }
    if (*upload_size) {
        if (!u->too_big && u->n + *upload_size <= WEB_MAX_BODY) {
            char *p = realloc(u->body, u->n + *upload_size + 1);
            if (!p) {
                u->too_big = 1;
            } else {
                u->body = p;
                memcpy(u->body + u->n, upload_data, *upload_size);
                u->n += *upload_size;
                u->body[u->n] = 0;
            }
        } else {
            u->too_big = 1;
        }
        *upload_size = 0;
        return MHD_YES;
    }
    if (strlen(url) > WEB_MAX_URL) return send_error(conn, 414, "TOO_LARGE", "URL too long");
    if (!host_ok(conn))
        return send_error(conn, 403, "FORBIDDEN",
                          "Host is not this machine's loopback name (127.0.0.1, localhost)");
    if (!strcmp(method, "GET") || !strcmp(method, "HEAD")) return route_get(conn, url);
    if (!strcmp(method, "POST")) return route_post(conn, url, u);
    return send_error(conn, 405, "BAD_REQUEST", "method not allowed");
}

static void on_completed(void *cls, struct MHD_Connection *conn, void **con_cls,
                         enum MHD_RequestTerminationCode toe)
{
    (void)cls;
    (void)conn;
    (void)toe;
    upload_t *u = *con_cls;
    if (u) {
        free(u->body);
        free(u);
    }
    *con_cls = NULL;
}

/* ---- command line ------------------------------------------------------------------ */

static void usage(FILE *f)
{
    fprintf(f,
            "usage: mpmweb [options]\n"
            "The live web monitor of mpmd: serves one page over HTTP showing the runs,\n"
            "a running job's progress, energy curves and particles, live, and past runs\n"
            "with a time slider.\n\n"
            "  --listen ADDR:PORT  where to serve (default $MPMWEB_LISTEN, else\n"
            "                      127.0.0.1:8080; [::1]:PORT for IPv6; port 0 picks a free\n"
            "                      one, printed on start)\n"
            "  --allow-remote      needed to listen on an address that is not loopback:\n"
            "                      the page has no login of its own\n"
            "  --allow-control     lets the page submit and cancel jobs (off: read-only);\n"
            "                      the daemon's CURVE authorization of this gateway's key\n"
            "                      still applies\n"
            "  --endpoint EP       mpmd's control socket (default $MPMD_ENDPOINT, else %s)\n"
            "  --stream EP         its stream socket (default $MPMD_STREAM, else what mpmd\n"
            "                      reports)\n"
            "  --keys DIR          CURVE keys as mpmctl: DIR/server.pub, DIR/mpmd.key\n"
            "                      (also MPMD_SERVER_KEY, MPMD_CLIENT_KEY, $MPMD_KEYS)\n"
            "  --timeout S         per mpmd request (default %g)\n"
            "  --static DIR        the page's files (default ../clients/web/static beside\n"
            "                      the binary, else /usr/share/mpmd/web)\n"
            "  --help              this text\n",
            CTL_DEFAULT_ENDPOINT, WEB_REQUEST_TIMEOUT);
}

/* Parses ADDR:PORT into *ss; loopback in *lo.  0 or -1 with a message. */
static int parse_listen(const char *s, struct sockaddr_storage *ss, socklen_t *sl, int *lo)
{
    char host[256];
    const char *colon;
    if (s[0] == '[') {
        const char *end = strchr(s, ']');
        if (!end || end[1] != ':' || (size_t)(end - s - 1) >= sizeof host) goto bad;
        memcpy(host, s + 1, (size_t)(end - s - 1));
        host[end - s - 1] = 0;
        colon = end + 1;
    } else {
        colon = strrchr(s, ':');
        if (!colon || (size_t)(colon - s) >= sizeof host) goto bad;
        memcpy(host, s, (size_t)(colon - s));
        host[colon - s] = 0;
    }
    char *end;
    errno = 0;
    long port = strtol(colon + 1, &end, 10);
    if (!colon[1] || *end || errno || port < 0 || port > 65535) {
        fprintf(stderr, "mpmweb: --listen %s: the port must be 0 .. 65535\n", s);
        return -1;
    }
    if (!strcmp(host, "localhost")) snprintf(host, sizeof host, "127.0.0.1");
    memset(ss, 0, sizeof *ss);
    struct sockaddr_in *a4 = (struct sockaddr_in *)ss;
    struct sockaddr_in6 *a6 = (struct sockaddr_in6 *)ss;
    if (inet_pton(AF_INET, host, &a4->sin_addr) == 1) {
        a4->sin_family = AF_INET;
        a4->sin_port = htons((uint16_t)port);
        *sl = sizeof *a4;
        *lo = (ntohl(a4->sin_addr.s_addr) >> 24) == 127;
        return 0;
    }
    if (inet_pton(AF_INET6, host, &a6->sin6_addr) == 1) {
        a6->sin6_family = AF_INET6;
        a6->sin6_port = htons((uint16_t)port);
        *sl = sizeof *a6;
        *lo = IN6_IS_ADDR_LOOPBACK(&a6->sin6_addr);
        return 0;
    }
bad:
    fprintf(stderr,
            "mpmweb: --listen %s: expected ADDR:PORT with a numeric address "
            "(127.0.0.1:8080, [::1]:8080, localhost:8080)\n",
            s);
    return -1;
}

int main(int argc, char **argv)
{
    const char *listen = getenv("MPMWEB_LISTEN"), *keys = NULL, *stat = NULL;
    if (!listen || !*listen) listen = "127.0.0.1:8080";
    int allow_remote = 0;
    W.conn.endpoint = getenv("MPMD_ENDPOINT");
    W.conn.stream = getenv("MPMD_STREAM");
    W.conn.timeout_s = WEB_REQUEST_TIMEOUT;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        int takes = !strcmp(a, "--listen") || !strcmp(a, "--endpoint") || !strcmp(a, "--stream") ||
                    !strcmp(a, "--keys") || !strcmp(a, "--timeout") || !strcmp(a, "--static");
        if (takes && !v) {
            fprintf(stderr, "mpmweb: %s needs a value (mpmweb --help)\n", a);
            return CTL_EXIT_USAGE;
        }
        if (!v) v = ""; /* not used by the flags without a value */
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(a, "--listen")) {
            listen = v;
        } else if (!strcmp(a, "--endpoint")) {
            W.conn.endpoint = v;
        } else if (!strcmp(a, "--stream")) {
            W.conn.stream = v;
        } else if (!strcmp(a, "--keys")) {
            keys = v;
        } else if (!strcmp(a, "--static")) {
            stat = v;
        } else if (!strcmp(a, "--timeout")) {
            char *end;
            W.conn.timeout_s = strtod(v, &end);
            if (*end || !(W.conn.timeout_s > 0 && W.conn.timeout_s <= 3600)) {
                fprintf(stderr, "mpmweb: --timeout %s: must be a number of seconds in (0, 3600]\n",
                        v);
                return CTL_EXIT_USAGE;
            }
        } else if (!strcmp(a, "--allow-remote")) {
            allow_remote = 1;
        } else if (!strcmp(a, "--allow-control")) {
            W.allow_control = 1;
        } else {
            fprintf(stderr, "mpmweb: unknown argument %s (mpmweb --help)\n", a);
            return CTL_EXIT_USAGE;
        }
        if (takes) i++;
    }
    if (!W.conn.endpoint || !*W.conn.endpoint) W.conn.endpoint = CTL_DEFAULT_ENDPOINT;

    struct sockaddr_storage ss;
    socklen_t sl = 0;
    if (parse_listen(listen, &ss, &sl, &bound_loopback)) return CTL_EXIT_USAGE;
    if (!bound_loopback && !allow_remote) {
        fprintf(stderr,
                "mpmweb: --listen %s is not a loopback address: the monitor has no login of "
                "its own, so serving it beyond this machine needs --allow-remote\n",
                listen);
        return CTL_EXIT_USAGE;
    }
    if (!bound_loopback)
        fprintf(stderr,
                "mpmweb: warning: serving on %s, beyond this machine: anyone who reaches it "
                "reads every run%s\n",
                listen, W.allow_control ? " and may submit and cancel jobs" : "");
    if (find_static(stat)) return CTL_EXIT_ERROR;
    if (ctl_keys_load(&W.conn, keys)) return CTL_EXIT_ERROR;

    /* the signals go to the main thread's sigwait only */
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &set, NULL);
    signal(SIGPIPE, SIG_IGN);

    if (web_hub_start(&W)) return CTL_EXIT_ERROR;
    unsigned flags = MHD_USE_THREAD_PER_CONNECTION | MHD_USE_INTERNAL_POLLING_THREAD |
                     (ss.ss_family == AF_INET6 ? MHD_USE_IPv6 : 0);
    struct MHD_Daemon *d = MHD_start_daemon(
        flags, 0, NULL, NULL, on_request, NULL, MHD_OPTION_SOCK_ADDR, (struct sockaddr *)&ss,
        MHD_OPTION_CONNECTION_LIMIT, (unsigned)WEB_MAX_CONNECTIONS, MHD_OPTION_CONNECTION_TIMEOUT,
        (unsigned)60, MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)65536,
        MHD_OPTION_NOTIFY_COMPLETED, on_completed, NULL, MHD_OPTION_END);
    if (!d) {
        fprintf(stderr, "mpmweb: cannot listen on %s: %s\n", listen, strerror(errno));
        web_hub_stop();
        return CTL_EXIT_ERROR;
    }
    const union MHD_DaemonInfo *di = MHD_get_daemon_info(d, MHD_DAEMON_INFO_BIND_PORT);
    unsigned port = di ? di->port : 0;
    char host[INET6_ADDRSTRLEN];
    if (ss.ss_family == AF_INET6)
        inet_ntop(AF_INET6, &((struct sockaddr_in6 *)&ss)->sin6_addr, host, sizeof host);
    else
        inet_ntop(AF_INET, &((struct sockaddr_in *)&ss)->sin_addr, host, sizeof host);
    printf("mpmweb: serving http://%s%s%s:%u/ (mpmd at %s; %s)\n",
           ss.ss_family == AF_INET6 ? "[" : "", host, ss.ss_family == AF_INET6 ? "]" : "", port,
           W.conn.endpoint, W.allow_control ? "submit and cancel enabled" : "read-only");
    fflush(stdout);

    int sig = 0;
    while (sigwait(&set, &sig)) {
    }
    fprintf(stderr, "mpmweb: stopping (signal %d); %llu events dropped for slow browsers\n", sig,
            web_hub_dropped());
    web_hub_stop();
    MHD_stop_daemon(d);
    pthread_mutex_lock(&W.mu);
    ctl_conn_close(&W.conn);
    pthread_mutex_unlock(&W.mu);
    return 0;
}
