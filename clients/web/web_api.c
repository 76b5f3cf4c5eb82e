/*
 * web_api.c - mpmweb's JSON API: each call is one mpmd request (two for
 * the event stream's history) over the gateway's one DEALER, taken under
 * a mutex by whichever HTTP thread asks.  Replies are decoded by the
 * protocol library's JSON bridge (the RunInfo, RunList and energy pages
 * go to the browser as the JSON mapping writes them, re-serialised by
 * jansson, which escapes every string) or into its structs (snapshots,
 * made compact by web_snap.c).  A daemon error becomes an HTTP status
 * (NOT_FOUND 404, FORBIDDEN 403, the request's own faults 400, a full
 * queue 503, others 502) with {"error":{"code","message"}}; a connection
 * that timed out or broke is closed and opened again on the next call, so
 * a late reply is never taken for the next one.
 */
#include "web.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

#include <jansson.h>

void web_json(web_resp *r, unsigned status, char *text)
{
    r->status = status;
    r->body = text;
    r->len = text ? strlen(text) : 0;
    r->ctype = "application/json";
}

void web_error(web_resp *r, unsigned status, const char *code, const char *msg)
{
    json_t *o = json_pack("{s:{s:s,s:s}}", "error", "code", code, "message", msg);
    char *t = o ? json_dumps(o, JSON_COMPACT) : NULL;
    json_decref(o);
    if (!t) t = strdup("{\"error\":{\"code\":\"INTERNAL\",\"message\":\"out of memory\"}}");
    web_json(r, status, t);
}

uint64_t web_parse_id(const char *s)
{
    char *end;
    if (!s || *s < '0' || *s > '9') return 0;
    errno = 0;
    unsigned long long v = strtoull(s, &end, 10);
    if (errno || *end || v == 0 || v > (1ull << 63)) return 0;
    return v;
}

static unsigned http_for(const char *code)
{
    if (!strcmp(code, "NOT_FOUND")) return 404;
    if (!strcmp(code, "FORBIDDEN")) return 403;
    if (!strcmp(code, "INVALID_CASE") || !strcmp(code, "BAD_REQUEST") ||
        !strcmp(code, "TOO_LARGE") || !strcmp(code, "BAD_SCHEMA"))
        return 400;
    if (!strcmp(code, "QUEUE_FULL") || !strcmp(code, "UNAVAILABLE")) return 503;
    return 502;
}

/* After a failure that was not the daemon's answer: a fresh connection
 * next time (a reply still on its way must not answer the next request). */
static void reset_conn(web_ctx *w, int rc, web_resp *r)
{
    ctl_conn_close(&w->conn);
    web_error(r, rc == CTL_EAUTH ? 403 : 502, rc == CTL_EAUTH ? "FORBIDDEN" : "UNAVAILABLE",
              rc == CTL_EAUTH ? "mpmd refused the gateway's key"
                              : "mpmd did not answer (see mpmweb's log)");
}

/* One request whose reply body `want` goes to the browser (after edit,
 * when given). */
static void call_json(web_ctx *w, const mpp_request *rq, const char *want,
                      void (*edit)(json_t *, const void *), const void *arg, web_resp *r)
{
    json_t *reply = NULL, *body = NULL;
    const char *code = "", *msg = "";
    pthread_mutex_lock(&w->mu);
    int rc = ctl_call_quiet(&w->conn, rq, want, &reply, &body, &code, &msg);
    if (rc == CTL_ESERVER)
        web_error(r, http_for(code), code, msg);
    else if (rc)
        reset_conn(w, rc, r);
    pthread_mutex_unlock(&w->mu);
    if (!rc) {
        if (edit) edit(body, arg);
        char *t = json_dumps(body, JSON_COMPACT);
        if (t)
            web_json(r, 200, t);
        else
            web_error(r, 500, "INTERNAL", "out of memory");
    }
    json_decref(reply);
}

/* Keeps the runs whose name contains the substring arg. */
static void filter_name(json_t *list, const void *arg)
{
    const char *sub = arg;
    json_t *runs = json_object_get(list, "runs");
    for (size_t i = json_array_size(runs); i-- > 0;) {
        const char *name = cj_str(json_array_get(runs, i), "name", "");
        if (!strstr(name, sub)) json_array_remove(runs, i);
    }
}

void web_api_runs(web_ctx *w, const char *status, const char *before, const char *limit,
                  const char *name, web_resp *r)
{
    mpp_request rq = {.kind = MPP_REQ_LIST_RUNS, .limit = 50};
    if (status && *status) {
        rq.status = mpp_status_from_name(status);
        if (!rq.status) {
            web_error(r, 400, "BAD_REQUEST", "status: not a run status (QUEUED, RUNNING, ...)");
            return;
        }
    }
    if (before && *before && !(rq.before_id = web_parse_id(before))) {
        web_error(r, 400, "BAD_REQUEST", "before: must be a run id >= 1");
        return;
    }
    if (limit && *limit) {
        uint64_t l = web_parse_id(limit);
        if (!l || l > WEB_RUNS_MAX) {
            web_error(r, 400, "BAD_REQUEST", "limit: must be 1 .. 500");
            return;
        }
        rq.limit = (uint32_t)l;
    }
    if (name && strlen(name) > 256) {
        web_error(r, 400, "BAD_REQUEST", "name: at most 256 bytes");
        return;
    }
    call_json(w, &rq, "runs", name && *name ? filter_name : NULL, name, r);
}

void web_api_run(web_ctx *w, const char *id, int with_case, web_resp *r)
{
    mpp_request rq = {.kind = MPP_REQ_GET_RUN, .id = web_parse_id(id), .with_case = with_case};
    if (!rq.id) {
        web_error(r, 400, "BAD_REQUEST", "run id: must be a number >= 1");
        return;
    }
    call_json(w, &rq, "run", NULL, NULL, r);
}

void web_api_status(web_ctx *w, const char *job, web_resp *r)
{
    mpp_request rq = {.kind = MPP_REQ_STATUS, .id = web_parse_id(job)};
    if (!rq.id) {
        web_error(r, 400, "BAD_REQUEST", "job id: must be a number >= 1");
        return;
    }
    call_json(w, &rq, "run", NULL, NULL, r);
}

void web_api_energy(web_ctx *w, const char *id, const char *from, web_resp *r)
{
    mpp_request rq = {.kind = MPP_REQ_GET_ENERGY, .id = web_parse_id(id)};
    if (!rq.id) {
        web_error(r, 400, "BAD_REQUEST", "run id: must be a number >= 1");
        return;
    }
    if (from && *from && strcmp(from, "0")) {
        if (!(rq.from_seq = web_parse_id(from))) {
            web_error(r, 400, "BAD_REQUEST", "from: must be a sample index >= 0");
            return;
        }
    }
    call_json(w, &rq, "energy", NULL, NULL, r);
}

void web_api_snapshot(web_ctx *w, const char *id, const char *step, web_resp *r)
{
    mpp_request rq = {.kind = MPP_REQ_GET_SNAPSHOT, .id = web_parse_id(id)};
    mpp_reply rep;
    if (!rq.id) {
        web_error(r, 400, "BAD_REQUEST", "run id: must be a number >= 1");
        return;
    }
    if (step && *step) {
        char *end;
        errno = 0;
        long long s = strtoll(step, &end, 10);
        if (errno || *end || s < 0) {
            web_error(r, 400, "BAD_REQUEST", "step: must be a step number >= 0");
            return;
        }
        rq.has_step = 1;
        rq.step = s;
    }
    pthread_mutex_lock(&w->mu);
    int rc = ctl_call_reply(&w->conn, &rq, MPP_REPLY_SNAPSHOT, &rep);
    if (rc == CTL_ESERVER) {
        const char *code = mpp_err_code_name(rep.err_code);
        web_error(r, http_for(code ? code : "INTERNAL"), code ? code : "INTERNAL", rep.err_message);
    } else if (rc) {
        reset_conn(w, rc, r);
    }
    pthread_mutex_unlock(&w->mu);
    if (!rc) {
        char *t;
        size_t n;
        if (web_snap_json(&rep.snapshot, &t, &n))
            web_error(r, 500, "INTERNAL", "out of memory");
        else
            web_json(r, 200, t);
    }
    mpp_reply_clear(&rep);
}

void web_api_submit(web_ctx *w, const char *body, size_t len, web_resp *r)
{
    uint8_t *bytes = NULL;
    size_t n = 0;
    mpm_error e;
    char text[MPM_ERROR_MSG_MAX + 256];
    if (!w->allow_control) {
        web_error(r, 403, "FORBIDDEN", "control is disabled: start mpmweb with --allow-control");
        return;
    }
    if (mpp_msg_json_to_bytes(MPP_MSG_CASE, body, len, &bytes, &n, &e)) {
        web_error(r, 400, "INVALID_CASE", mpm_error_text(&e, MPM_FIELD_JSON, text, sizeof text));
        return;
    }
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_bytes = bytes, .case_len = n};
    call_json(w, &rq, "submitOk", NULL, NULL, r);
    free(bytes);
}

void web_api_cancel(web_ctx *w, const char *job, web_resp *r)
{
    mpp_request rq = {.kind = MPP_REQ_CANCEL, .id = web_parse_id(job)};
    if (!w->allow_control) {
        web_error(r, 403, "FORBIDDEN", "control is disabled: start mpmweb with --allow-control");
        return;
    }
    if (!rq.id) {
        web_error(r, 400, "BAD_REQUEST", "job id: must be a number >= 1");
        return;
    }
    call_json(w, &rq, "run", NULL, NULL, r);
}

int web_stream_endpoint(web_ctx *w)
{
    int rc = 0;
    pthread_mutex_lock(&w->mu);
    if (!w->has_stream) {
        rc = ctl_stream_endpoint(&w->conn, w->stream_ep, sizeof w->stream_ep);
        if (!rc)
            w->has_stream = 1;
        else if (rc != CTL_EUSAGE)
            ctl_conn_close(&w->conn);
    }
    pthread_mutex_unlock(&w->mu);
    return rc;
}

/* ---- the event stream's history ------------------------------------------ */

typedef struct {
    char *p;
    size_t n, cap;
    size_t count;
} hist_t;

#define HIST_FULL (-100)

static int hist_add(const mpm_energy_sample *s, void *arg)
{
    hist_t *h = arg;
    char *t = NULL;
    mpm_error e;
    if (h->count >= WEB_HISTORY_MAX) return HIST_FULL;
    if (mpp_energy_to_json(s, &t, &e)) return CTL_ESYS;
    size_t k = strlen(t);
    if (h->n + k + 3 > h->cap) {
        size_t cap = h->cap ? h->cap * 2 : 65536;
        while (cap < h->n + k + 3) cap *= 2;
        char *p = realloc(h->p, cap);
        if (!p) {
            free(t);
            return CTL_ESYS;
        }
        h->p = p;
        h->cap = cap;
    }
    h->p[h->n++] = h->count ? ',' : '[';
    memcpy(h->p + h->n, t, k);
    h->n += k;
    h->p[h->n] = 0;
    h->count++;
    free(t);
    return 0;
}

int web_energy_history(web_ctx *w, uint64_t run_id, char **out)
{
    hist_t h = {0};
    pthread_mutex_lock(&w->mu);
    int rc = ctl_fetch_energy(&w->conn, run_id, 0, hist_add, &h);
    if (rc && rc != HIST_FULL && rc != CTL_ESERVER) ctl_conn_close(&w->conn);
    pthread_mutex_unlock(&w->mu);
    if (rc == HIST_FULL) rc = 0;
    if (!rc && !h.p) {
        h.p = strdup("[]");
        if (!h.p) rc = CTL_ESYS;
    } else if (!rc) {
        h.p[h.n++] = ']';
        h.p[h.n] = 0;
    }
    if (rc) {
        free(h.p);
        h.p = NULL;
    }
    *out = h.p;
    return rc;
}
