/*
 * t_daemon_util.c - helpers shared by the daemon tests (see
 * t_daemon_util.h).
 */
#include "t_daemon_util.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zmq.h>

#include "mpp_case.h"

void series_free(series *s)
{
    free(s->seq);
    free(s->step);
    free(s->t);
    free(s->kinetic);
    free(s->strain);
    free(s->total);
    memset(s, 0, sizeof *s);
}

/* Parses mpmctl's energy CSV (header + rows); 0 or -1 with the reason. */
int parse_csv(const char *text, series *s)
{
    char *copy = strdup(text), **lines = NULL;
    size_t n = copy ? td_lines(copy, &lines) : 0;
    int rc = -1;
    memset(s, 0, sizeof *s);
    if (n < 1 || strncmp(lines[0],
                         "seq,step,t,kinetic,strain,potential,external_work,total,mass,"
                         "momentum_x",
                         71)) {
        TLOG("not an energy CSV: first line \"%.80s\"", n ? lines[0] : "");
        goto out;
    }
    s->seq = calloc(n, sizeof *s->seq);
    s->step = calloc(n, sizeof *s->step);
    s->t = calloc(n, sizeof *s->t);
    s->kinetic = calloc(n, sizeof *s->kinetic);
    s->strain = calloc(n, sizeof *s->strain);
    s->total = calloc(n, sizeof *s->total);
    if (!s->seq || !s->step || !s->t || !s->kinetic || !s->strain || !s->total) goto out;
    for (size_t i = 1; i < n; i++) {
        double pot, work;
        if (sscanf(lines[i], "%lld,%lld,%lf,%lf,%lf,%lf,%lf,%lf", &s->seq[s->n], &s->step[s->n],
                   &s->t[s->n], &s->kinetic[s->n], &s->strain[s->n], &pot, &work,
                   &s->total[s->n]) != 8) {
            TLOG("bad CSV row %zu: \"%.80s\"", i, lines[i]);
            goto out;
        }
        s->n++;
    }
    rc = 0;
out:
    free(lines);
    free(copy);
    if (rc) series_free(s);
    return rc;
}

/* seq[i] == i for every row (complete, ordered, no duplicate). */
int consecutive(const series *s)
{
    for (size_t i = 0; i < s->n; i++)
        if (s->seq[i] != (long long)i) {
            TLOG("row %zu has seq %lld", i, s->seq[i]);
            return 0;
        }
    return 1;
}

double rel_diff(double a, double b)
{
    double m = fmax(fabs(a), fabs(b));
    return m > 0 ? fabs(a - b) / m : 0;
}

/* Case files: an example with a few members replaced. */
json_t *example(const char *name)
{
    char path[128];
    snprintf(path, sizeof path, "proto/examples/%s.json", name);
    return td_json_file(path);
}

/* Sets output.<key> = v (creating output). */
void set_output(json_t *c, const char *key, json_t *v)
{
    json_t *out = json_object_get(c, "output");
    if (!out) {
        out = json_object();
        json_object_set_new(c, "output", out);
    }
    json_object_set_new(out, key, v);
}

/* The 1D bar running `steps` steps (not endTime), energy every `every`. */
json_t *bar_steps(long long steps, int every)
{
    json_t *c = example("bar1d_mpm");
    if (!c) return NULL;
    json_object_del(c, "endTime");
    json_object_set_new(c, "steps", json_integer(steps));
    set_output(c, "energyEvery", json_integer(every));
    return c;
}

/* A job that runs until cancelled: the bar at rest (nothing moves, so
 * nothing drifts out of the grid however long it runs), 99 million steps. */
json_t *long_case(int every)
{
    json_t *c = bar_steps(LONG_STEPS, every);
    if (c)
        json_object_del(json_object_get(json_array_get(json_object_get(c, "bodies"), 0), "points"),
                        "v");
    return c;
}

/* A 2D elastic block drifting in a box: 256 particles. */
json_t *block2d(long long steps, int every, const char *name)
{
    json_error_t je;
    json_t *c = json_loads(
        "{\"grid\": {\"dim\": 2, \"spacing\": [0.05, 0.05], \"nodes\": [21, 21]},"
        " \"method\": \"MPM\", \"update\": \"USF\", \"dt\": 0.001,"
        " \"materials\": [{\"youngsModulus\": 1, \"poissonRatio\": 0.2, \"density\": 1}],"
        " \"bodies\": [{\"box\": {\"lo\": [0.3, 0.3], \"hi\": [0.7, 0.7]},"
        "               \"velocity\": [0.01, 0.005], \"ppc\": 2}]}",
        0, &je);
    if (!c) return NULL;
    json_object_set_new(c, "name", json_string(name));
    json_object_set_new(c, "steps", json_integer(steps));
    set_output(c, "energyEvery", json_integer(every));
    return c;
}

json_t *compressed1d(const char *name)
{
    json_error_t je;
    json_t *c = json_loads(
        "{\"grid\": {\"dim\": 1, \"spacing\": [1], \"nodes\": [5]},"
        " \"method\": \"MPM\", \"dt\": 1e-5, \"steps\": 5,"
        " \"materials\": [{\"youngsModulus\": 1e6, \"density\": 1}],"
        " \"bodies\": [{\"points\": {\"x\": [1.5, 2.5], \"volume\": [1, 1],"
        "   \"stress\": [-3000, 0, 0, 0, 0, 0, -3000, 0, 0, 0, 0, 0]}}],"
        " \"output\": {\"energyEvery\": 1, \"snapshotEvery\": 2, \"recordSnapshots\": true}}",
        0, &je);
    if (c) json_object_set_new(c, "name", json_string(name));
    return c;
}

/* Writes case c (consumed) to dir/file; path out. */
int write_case(json_t *c, const char *dir, const char *file, char *path, size_t n)
{
    int rc;
    if (!c) return -1;
    snprintf(path, n, "%s/%s", dir, file);
    rc = td_json_write(path, c);
    json_decref(c);
    return rc;
}

/* "job N" in text -> N (0 if absent). */
unsigned long long job_of(const char *text)
{
    const char *p = text ? strstr(text, "job ") : NULL;
    return p ? strtoull(p + 4, NULL, 10) : 0;
}

/* A member of a JSON text line (parsed), as text: string value or number. */
json_t *parse_line(const char *line)
{
    return json_loads(line, 0, NULL);
}

long long jint(const json_t *o, const char *key)
{
    const json_t *v = json_object_get(o, key);
    if (json_is_integer(v)) return json_integer_value(v);
    if (json_is_string(v)) return atoll(json_string_value(v));
    return -1;
}

const char *jstr(const json_t *o, const char *key)
{
    const json_t *v = json_object_get(o, key);
    return json_is_string(v) ? json_string_value(v) : "";
}

double jnum(const json_t *o, const char *key)
{
    const json_t *v = json_object_get(o, key);
    if (json_is_number(v)) return json_number_value(v);
    if (json_is_string(v)) return strtod(json_string_value(v), NULL);
    return NAN;
}

/* Number of lines of a text. */
size_t count_lines(const char *t)
{
    size_t n = 0;
    for (; t && *t; t++) n += *t == '\n';
    return n;
}

/* mpmctl show ID --json, parsed (NULL on failure). */
json_t *show_json(const td_daemon *d, unsigned long long id)
{
    char ids[32];
    td_out o;
    json_t *r = NULL;
    snprintf(ids, sizeof ids, "%llu", id);
    if (td_ctl(d, 30, &o, "show", ids, "--json", NULL) == 0 && o.status == 0)
        r = parse_line(o.out);
    else
        TLOG("show %s --json: exit %d, stderr %s", ids, o.status, o.err ? o.err : "");
    td_out_free(&o);
    return r;
}

/* Waits up to timeout s until the daemon's log (mpmd --verbose) shows that
 * job's stream subscribed ("job N: stream watched"); 0 or -1. */
int wait_watched(const td_daemon *d, unsigned long long job, double timeout)
{
    char want[64];
    double end = td_now() + timeout;
    snprintf(want, sizeof want, "job %llu: stream watched", job);
    do {
        size_t len = 0;
        char *log = td_slurp(d->log, &len);
        int found = log && strstr(log, want);
        free(log);
        if (found) return 0;
        td_msleep(20);
    } while (td_now() < end);
    TLOG("no \"%s\" in %s after %.0f s", want, d->log, timeout);
    return -1;
}

/* Waits up to timeout s until a background client's output file has at
 * least n lines; 0 or -1. */
int wait_lines(const td_bg *b, size_t n, double timeout)
{
    double end = td_now() + timeout;
    do {
        size_t len = 0;
        char *out = td_slurp(b->out_path, &len);
        size_t have = count_lines(out);
        free(out);
        if (have >= n) return 0;
        td_msleep(20);
    } while (td_now() < end);
    return -1;
}

/* The error of a raw request for id: 0 if it is NOT_FOUND naming `field`,
 * with a message naming the id; else fails the test. */
int expect_not_found(const td_daemon *d, mpp_request rq, const char *what, const char *field)
{
    json_t *reply = NULL;
    char id[32];
    int ok;
    snprintf(id, sizeof id, "%llu", (unsigned long long)rq.id);
    if (td_request(d->ep, &rq, 10, &reply) != 0) {
        t_fail(__FILE__, __LINE__, "%s: no reply", what);
        json_decref(reply);
        return -1;
    }
    ok = !strcmp(td_err_code(reply), "NOT_FOUND") && !strcmp(td_err_field(reply), field) &&
         strstr(td_err_msg(reply), id);
    if (!ok)
        t_fail(__FILE__, __LINE__,
               "%s: %s, field \"%s\", message \"%s\" (want NOT_FOUND, field %s, "
               "the id %s in the message)",
               what, td_err_code(reply), td_err_field(reply), td_err_msg(reply), field, id);
    else
        TLOG("%-30s NOT_FOUND, field %-6s %s", what, field, td_err_msg(reply));
    json_decref(reply);
    return ok ? 0 : -1;
}

/* Expects mpmctl ARGS to exit with `status` and its stdout (or, for a
 * non-zero status, its stdout or stderr) to contain want. */
int expect_ctl(const td_daemon *d, int status, const char *want, const char *const *args)
{
    td_out o;
    int ok;
    if (td_ctlv(d, 30, &o, args)) {
        t_fail(__FILE__, __LINE__, "cannot run mpmctl %s", args[0]);
        td_out_free(&o);
        return 0;
    }
    ok = o.status == status && (strstr(o.out, want) || (status && strstr(o.err, want)));
    if (!ok) {
        char line[256] = "";
        for (int i = 0; args[i]; i++)
            snprintf(line + strlen(line), sizeof line - strlen(line), " %s", args[i]);
        t_fail(__FILE__, __LINE__,
               "mpmctl%s: exit %d (want %d), stdout \"%.300s\", stderr \"%.300s\" "
               "(want \"%s\")",
               line, o.status, status, o.out, o.err, want);
    } else {
        const char *msg = status && o.err[0] ? o.err : o.out;
        const char *nl = strchr(msg, '\n');
        TLOG("%-34.34s exit %d: %.*s", args[0] ? args[0] : "", o.status,
             (int)(nl ? nl - msg : (long)strlen(msg)), msg);
    }
    td_out_free(&o);
    return ok;
}

/* ---- the daemon's memory and its stream ---- */

/* A line of /proc/PID/status ("VmHWM:", "VmRSS:") in kB, or -1. */
long proc_kb(pid_t pid, const char *key)
{
    char path[64], line[256];
    long v = -1;
    snprintf(path, sizeof path, "/proc/%ld/status", (long)pid);
    FILE *f = fopen(path, "r");
    if (!f) return -1;
    while (fgets(line, sizeof line, f))
        if (!strncmp(line, key, strlen(key))) v = strtol(line + strlen(key), NULL, 10);
    fclose(f);
    return v;
}

/* A SUB on the daemon's stream subscribed to job's topic, receiving at
 * most hwm messages into its queue (a watcher that stalls stalls there). */
void *subscribe(void *zctx, const td_daemon *d, unsigned long long job, int hwm)
{
    char sep[420], topic[32];
    int linger = 0, rcvbuf = 4096;
    snprintf(sep, sizeof sep, "%s.stream", d->ep);
    snprintf(topic, sizeof topic, "job:%016llx:", job);
    void *sub = zmq_socket(zctx, ZMQ_SUB);
    if (!sub || zmq_setsockopt(sub, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_setsockopt(sub, ZMQ_RCVHWM, &hwm, sizeof hwm) ||
        zmq_setsockopt(sub, ZMQ_RCVBUF, &rcvbuf, sizeof rcvbuf) ||
        zmq_setsockopt(sub, ZMQ_SUBSCRIBE, topic, strlen(topic)) || zmq_connect(sub, sep)) {
        t_fail(__FILE__, __LINE__, "SUB on %s: %s", sep, zmq_strerror(errno));
        if (sub) zmq_close(sub);
        return NULL;
    }
    return sub;
}

/* The snapshot-every-step job: a 2D block at rest, 57600 particles (h =
 * 0.005, 2x2 per cell), every field: 5.5 MB per snapshot, `steps` steps. */
json_t *snap_case(const char *name, long long steps)
{
    json_t *c = block2d(steps, 0, name);
    if (!c) return NULL;
    json_object_set_new(json_object_get(c, "grid"), "spacing", json_pack("[f,f]", 0.005, 0.005));
    json_object_set_new(json_object_get(c, "grid"), "nodes", json_pack("[i,i]", 201, 201));
    json_t *b = json_array_get(json_object_get(c, "bodies"), 0);
    json_object_set_new(json_object_get(b, "box"), "lo", json_pack("[f,f]", 0.2, 0.2));
    json_object_set_new(json_object_get(b, "box"), "hi", json_pack("[f,f]", 0.8, 0.8));
    json_object_del(b, "velocity");
    set_output(c, "snapshotEvery", json_integer(1));
    return c;
}

/* ---- raw requests ---- */

/* Submits the good 2D case with `from` patched into `to` as a raw request;
 * the reply in *reply (caller frees). */
int submit_patched(const td_daemon *d, const char *from, const char *to, json_t **reply)
{
    char err[ERRLEN];
    char *json = td_patch(from, to);
    Mpmd__Case *pb = NULL;
    *reply = NULL;
    if (!json || td_case_from_json(json, strlen(json), &pb, err, sizeof err)) {
        t_fail(__FILE__, __LINE__, "patch %s -> %s: %s", from, to, json ? err : "not in the case");
        free(json);
        return -1;
    }
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_pb = pb};
    int rc = td_request(d->ep, &rq, 20, reply);
    mpp_case_pb_free(&pb);
    free(json);
    return rc;
}

int ping_ok(const td_daemon *d)
{
    mpp_request rq = {.kind = MPP_REQ_PING};
    json_t *reply = NULL;
    int ok = td_request(d->ep, &rq, 10, &reply) == 0 && json_object_get(reply, "pong");
    json_decref(reply);
    return ok;
}

/* Appends a varint. */
static size_t varint(uint8_t *p, uint64_t v)
{
    size_t k = 0;
    do {
        p[k++] = (uint8_t)((v & 0x7f) | (v > 0x7f ? 0x80 : 0));
        v >>= 7;
    } while (v);
    return k;
}

uint8_t *inflated_request(size_t nbodies, size_t *n)
{
    /* Request { schema_version = 1, submit { case { bodies: nbodies empty } } }:
     * 2 bytes on the wire per Body (tag 0x5a, length 0), some 90 in memory
     * (45x) */
    size_t caselen = 2 * nbodies, k = 0;
    uint8_t *m = malloc(caselen + 32), tmpv[10];
    if (!m) return NULL;
    size_t clen = varint(tmpv, caselen);
    m[k++] = 0x08; /* schema_version */
    m[k++] = 1;
    m[k++] = 0x12; /* submit */
    k += varint(m + k, 1 + clen + caselen);
    m[k++] = 0x0a; /* case */
    k += varint(m + k, caselen);
    for (size_t i = 0; i < nbodies; i++) {
        m[k++] = 0x5a; /* Case.bodies = 11, length-delimited */
        m[k++] = 0;
    }
    *n = k;
    return m;
}

int td_job_peak(const td_daemon *d, unsigned long long job, double *wall, long *hwm)
{
    char st[32];
    if (td_wait_status(d, job, "FINISHED|FAILED|CANCELLED|INTERRUPTED", 300, st, sizeof st) ||
        strcmp(st, "FINISHED")) {
        t_fail(__FILE__, __LINE__, "job %llu: %s", job, st);
        return -1;
    }
    json_t *r = show_json(d, job);
    *wall = r ? jnum(r, "wallS") : -1;
    json_decref(r);
    *hwm = proc_kb(d->pid, "VmHWM:");
    return 0;
}

/* ---- memory and responsiveness of a daemon under load ---- */

int reset_hwm(pid_t pid)
{
    char path[64];
    snprintf(path, sizeof path, "/proc/%ld/clear_refs", (long)pid);
    FILE *f = fopen(path, "w");
    if (!f) return -1;
    int ok = fputs("5", f) >= 0;
    return fclose(f) == 0 && ok ? 0 : -1;
}

static void *pinger_main(void *arg)
{
    pinger *p = arg;
    void *ctx = zmq_ctx_new(), *s = ctx ? zmq_socket(ctx, ZMQ_DEALER) : NULL;
    uint8_t *buf = NULL;
    size_t len = 0;
    mpp_request rq = {.kind = MPP_REQ_PING};
    int zero = 0;
    if (!s || zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) || zmq_connect(s, p->ep) ||
        mpp_request_encode(&rq, &buf, &len))
        goto out;
    for (int first = 1; first || !atomic_load(&p->stop); first = 0) {
        double t0 = td_now();
        if (zmq_send(s, "", 0, ZMQ_SNDMORE) < 0 || zmq_send(s, buf, len, 0) < 0) break;
        zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
        int pr = zmq_poll(&it, 1, 10000);
        double dt = td_now() - t0;
        if (pr == 1) {
            zmq_msg_t part[3];
            int n = td_recv_parts(s, part, 3);
            for (int i = 0; i < n; i++) zmq_msg_close(&part[i]);
        }
        if (first) {
            if (pr != 1) break;
            atomic_store(&p->state, 1);
        } else {
            p->pings++;
            p->lost += pr != 1;
            if (dt > p->max_s) p->max_s = dt;
        }
        if (pr != 1 || p->fresh) {
            /* a DEALER whose reply never came: start afresh so that a late
             * reply is not taken for the next one's (fresh: every ping on
             * a new connection) */
            zmq_close(s);
            s = zmq_socket(ctx, ZMQ_DEALER);
            if (!s || zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) || zmq_connect(s, p->ep))
                break;
        }
        td_msleep(20);
    }
out:
    if (atomic_load(&p->state) == 0) atomic_store(&p->state, -1);
    free(buf);
    if (s) zmq_close(s);
    if (ctx) zmq_ctx_term(ctx);
    return NULL;
}

int pinger_start(pinger *p, const td_daemon *d, int fresh)
{
    memset(p, 0, sizeof *p);
    p->fresh = fresh;
    snprintf(p->ep, sizeof p->ep, "%s", d->ep);
    atomic_init(&p->stop, 0);
    atomic_init(&p->state, 0);
    if (pthread_create(&p->th, NULL, pinger_main, p)) {
        t_fail(__FILE__, __LINE__, "cannot start the pinger thread");
        return -1;
    }
    for (double t0 = td_now(); td_now() - t0 < 15 && atomic_load(&p->state) == 0;) td_msleep(10);
    if (atomic_load(&p->state) != 1) {
        atomic_store(&p->stop, 1);
        pthread_join(p->th, NULL);
        t_fail(__FILE__, __LINE__, "the pinger got no first answer");
        return -1;
    }
    return 0;
}

void pinger_stop(pinger *p)
{
    atomic_store(&p->stop, 1);
    pthread_join(p->th, NULL);
}

void settle(pid_t pid, double quiet, double limit)
{
    long last = proc_kb(pid, "VmRSS:");
    double t0 = td_now(), since = t0;
    while (td_now() - t0 < limit && td_now() - since < quiet) {
        td_msleep(100);
        long now = proc_kb(pid, "VmRSS:");
        if (now > last + 1024) since = td_now();
        if (now > last) last = now;
    }
}

long wait_rss_below(pid_t pid, long kb, double limit)
{
    long now = proc_kb(pid, "VmRSS:");
    for (double t0 = td_now(); now > kb && td_now() - t0 < limit; now = proc_kb(pid, "VmRSS:"))
        td_msleep(100);
    return now;
}

int log_has(const td_daemon *d, const char *s)
{
    size_t len = 0;
    char *log = td_slurp(d->log, &len);
    int r = log && strstr(log, s);
    free(log);
    return r;
}

int td_start_measured(td_daemon *d, const char *dir, const char *const *extra)
{
#if defined(__SANITIZE_ADDRESS__)
    const char *old = getenv("ASAN_OPTIONS");
    char *keep = old ? strdup(old) : NULL;
    char opt[512];
    snprintf(opt, sizeof opt, "%s%squarantine_size_mb=16", keep ? keep : "",
             keep && *keep ? ":" : "");
    setenv("ASAN_OPTIONS", opt, 1);
    int rc = td_start(d, dir, extra);
    if (keep)
        setenv("ASAN_OPTIONS", keep, 1);
    else
        unsetenv("ASAN_OPTIONS");
    free(keep);
    return rc;
#else
    return td_start(d, dir, extra);
#endif
}
