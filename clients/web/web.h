/*
 * web.h - the parts of mpmweb, the live web monitor, shared between its
 * files.  mpmweb is a client of mpmd (the same connection code, keys and
 * flags as mpmctl: clients/ctl/ctl_conn.c, ctl_keys.c) and an HTTP server
 * (Debian's libmicrohttpd, one thread per connection) that serves one page
 * (clients/web/static/) and a small JSON API over it:
 *
 *  - web_api.c:  the API calls that become one mpmd request each (runs,
 *                run, energy, snapshot, and submit / cancel when control is
 *                enabled), through one DEALER shared under a mutex;
 *  - web_hub.c:  the live side: one thread owns the SUB socket, holds at
 *                most one subscription per job, and fans each message out
 *                to the browsers' Server-Sent Event queues (bounded; a slow
 *                browser loses old snapshot notices, never slows the
 *                thread) and keeps each job's latest snapshot;
 *  - web_snap.c: a snapshot as the page's compact JSON;
 *  - mpmweb.c:   flags, the HTTP server, routing, static files, limits.
 */
#ifndef WEB_H
#define WEB_H

#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

#include "ctl.h"

/* Limits. */
#define WEB_MAX_CONNECTIONS 64   /* HTTP connections at once */
#define WEB_MAX_SSE 32           /* of which event streams */
#define WEB_MAX_BODY (8u << 20)  /* a POSTed case, bytes */
#define WEB_MAX_URL 2048         /* a request's URL, bytes */
#define WEB_SSE_QUEUE 512        /* events queued per browser */
#define WEB_RUNS_MAX 500u        /* runs per /api/runs page */
#define WEB_HISTORY_MAX 50000u   /* energy samples in an event stream's history */
#define WEB_REQUEST_TIMEOUT 10.0 /* s, per mpmd request */

/* An HTTP answer made by the API: status, body (malloc'd) and its type. */
typedef struct {
    unsigned status;
    char *body;
    size_t len;
    const char *ctype;
} web_resp;

/* The gateway's state shared by the HTTP threads. */
typedef struct {
    ctl_conn conn;      /* the DEALER to mpmd, used under mu */
    pthread_mutex_t mu; /* one request at a time */
    char stream_ep[512];
    int allow_control; /* --allow-control */
    int has_stream;    /* stream_ep known */
} web_ctx;

/* Fills r with a JSON body (takes text, malloc'd). */
void web_json(web_resp *r, unsigned status, char *text);
/* Fills r with {"error":{"code":code,"message":msg}} (JSON-escaped). */
void web_error(web_resp *r, unsigned status, const char *code, const char *msg);

/* ---- the API (web_api.c) ----------------------------------------------- */

/* GET /api/runs?status=S&before=ID&limit=N&name=SUB: one page of runs
 * (the RunList as the JSON mapping writes it, the runs whose name holds
 * SUB kept).  Every handler fills r in every case. */
void web_api_runs(web_ctx *w, const char *status, const char *before, const char *limit,
                  const char *name, web_resp *r);
/* GET /api/run/ID[?case=1]: the RunInfo (with its case). */
void web_api_run(web_ctx *w, const char *id, int with_case, web_resp *r);
/* GET /api/job/JOB: the job's RunInfo (Status). */
void web_api_status(web_ctx *w, const char *job, web_resp *r);
/* GET /api/energy/ID?from=SEQ: one page of samples {runId, samples, more}. */
void web_api_energy(web_ctx *w, const char *id, const char *from, web_resp *r);
/* GET /api/snapshot/ID?step=N: a recorded snapshot (the latest without
 * step) as web_snap_json() writes it. */
void web_api_snapshot(web_ctx *w, const char *id, const char *step, web_resp *r);
/* POST /api/submit (body: a case as JSON) and POST /api/cancel/JOB, only
 * with --allow-control (403 otherwise). */
void web_api_submit(web_ctx *w, const char *body, size_t len, web_resp *r);
void web_api_cancel(web_ctx *w, const char *job, web_resp *r);
/* The stream endpoint into w->stream_ep (asks mpmd once); 0 or CTL_E*. */
int web_stream_endpoint(web_ctx *w);
/* The whole energy history of a run from seq 0 as a JSON array text
 * (malloc'd, into *out), at most WEB_HISTORY_MAX samples; 0 or CTL_E*. */
int web_energy_history(web_ctx *w, uint64_t run_id, char **out);
/* Parses a decimal id (1 .. 2^63); 0 for anything else. */
uint64_t web_parse_id(const char *s);

/* ---- the live side (web_hub.c) -------------------------------------------- */

typedef struct web_client web_client;

/* Starts the stream thread (its own zmq context; keys from w->conn).  0 or
 * CTL_ESYS. */
int web_hub_start(web_ctx *w);
/* Wakes every event stream (they end) and stops the thread. */
void web_hub_stop(void);
/* A browser's event stream for job (subscribing to it when it is the
 * first), with `first` queued ahead of everything (may be NULL; copied).
 * NULL when WEB_MAX_SSE streams are open or memory is short. */
web_client *web_hub_join(uint64_t job, const char *first);
/* Puts an event in front of what is queued (the late-join history). */
void web_hub_push_front(web_client *c, const char *event, size_t len);
/* The SSE bytes for the browser: blocks up to ~10 s for an event (a
 * keep-alive comment otherwise); copies at most max bytes into buf.
 * Returns the count, or -1 when the stream is over (shutdown). */
long web_hub_read(web_client *c, char *buf, size_t max);
/* The browser went away: unsubscribes after the last one of a job. */
void web_hub_leave(web_client *c);
/* The latest live snapshot of job as web_snap_json() text (malloc'd copy
 * into *out), 0; or CTL_EPROTO when none has arrived. */
int web_hub_latest(uint64_t job, char **out, size_t *len);
/* Counters for tests and logs: events dropped for slow browsers. */
unsigned long long web_hub_dropped(void);

/* ---- snapshots (web_snap.c) ------------------------------------------------ */

/* A snapshot as compact JSON: {"step","t","n","dim","x":[n*dim],
 * "fields":{"pressure":[n],"speed":[n],"plasticStrain":[n]}} with the
 * fields it carries, numbers in 7 significant digits (non-finite -> null).
 * 0 or CTL_ESYS (memory). */
int web_snap_json(const mpp_snapshot *s, char **out, size_t *len);

#endif
