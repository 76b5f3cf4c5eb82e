/*
 * ctl_watch.c - `mpmctl watch`: the live view of a job, and the complete
 * energy series of a job however late the watcher arrives.
 * How it works: the notes after the includes.
 */
#include "ctl.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <time.h>
#include <unistd.h>

#include <zmq.h>

/*
 * The stream (an XPUB on the daemon) loses what was published before a
 * subscription took effect and may drop messages for a slow reader, so the
 * series is merged from two sources by the sample's own index
 * (EnergySample.seq, 0, 1, 2, ... without gaps in the store):
 *   1. subscribe to the job's topic first ("job:%016llx:");
 *   2. fetch the stored history with GetEnergy from seq 0, paging;
 *   3. consume live messages: a sample below the next expected seq is
 *      already known and skipped; one above it means samples were missed,
 *      so GetEnergy from the next expected seq fills the gap first (the
 *      daemon flushes its store before answering, so the gap is there);
 *   4. when nothing arrives for a second, ask Status: a terminal job (its
 *      Finished message may have gone out before the subscription took)
 *      gets the rest of its history from GetEnergy and the view ends.
 * After Finished the tail is fetched the same way.  Every sample is written
 * exactly once, in seq order.  The closing summary comes from Status.
 *
 * For the tests, MPMCTL_TEST_DROP_EVERY=N discards every Nth energy message
 * of the stream and MPMCTL_TEST_DROP_FINISHED=1 the Finished message, as a
 * lossy stream would; the series must come out complete all the same.
 *
 * Text mode on a terminal redraws one status line in place (step, t,
 * energies, |L| the magnitude of the angular momentum in 2D and 3D, a
 * progress bar with ETA); elsewhere it writes one line per
 * sample.  CSV / JSON modes write only the series on stdout (the summary
 * goes to stderr).
 */

#define WATCH_IDLE_S 1.0     /* quiet this long: ask Status */
#define WATCH_REDRAW_S 0.1   /* terminal line at most this often */
#define WATCH_SUB_HWM 100000 /* stream messages buffered before dropping */

typedef struct {
    ctl_conn *c;
    uint64_t job;
    ctl_out fmt;
    int tty; /* text mode on a terminal: one line redrawn */
    ctl_energy_out eo;
    FILE *info; /* where the summary goes */

    uint64_t next;        /* next energy seq expected */
    uint64_t samples;     /* samples written */
    uint64_t gaps_filled; /* times the stream skipped samples */
    double first_total, last_total;
    double kinetic, strain;
    double angmom;  /* |angular momentum| of the last sample (2D, 3D) */
    double balance; /* the last sample's energy balance error */
    int have_angmom;
    int have_first;

    int status; /* mpp_status as last known */
    char name[128];
    long long step, steps_total;
    double t, wall_s, dt;
    int have_progress;
    double last_draw;
    int line_shown;

    int have_stream_seq;
    uint64_t stream_seq;  /* last StreamMsg.seq seen */
    uint64_t stream_lost; /* messages the stream dropped */

    int finished;        /* Finished seen */
    char error[512];     /* Finished.error */
    char warning[512];   /* Finished.warning */
    int has_fin_balance; /* Finished.balance_error, at the run's end */
    double fin_balance;
    int has_fin;           /* Finished carried a final sample: */
    mpm_energy_sample fin; /* that sample */

    /* Fault injection for the tests (environment, see ctl_watch()):
     * discard every drop_every-th energy message, and/or the Finished
     * message, as if the stream had lost them. */
    unsigned drop_every, energy_seen;
    int drop_finished;
} watch_t;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static int terminal_status(int st)
{
    return MPP_STATUS_ENDED(st);
}

static int term_cols(void)
{
    struct winsize ws;
    if (!ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) && ws.ws_col >= 20) return ws.ws_col;
    return 80;
}

/* Appends to a bounded line (silently truncated). */
__attribute__((format(printf, 4, 5))) static void append(char *line, size_t cap, size_t *n,
                                                         const char *fmt, ...)
{
    va_list ap;
    int k;
    if (*n + 1 >= cap) return;
    va_start(ap, fmt);
    k = vsnprintf(line + *n, cap - *n, fmt, ap);
    va_end(ap);
    if (k > 0) *n = *n + (size_t)k < cap ? *n + (size_t)k : cap - 1;
}

/* The status line (terminal text mode): status, step, t, the energies, a
 * progress bar and the ETA.  When the terminal is too narrow for the full
 * line, a compact one keeps every item (3 digits, a percentage instead of
 * the bar) before anything is cut. */
static size_t status_line(const watch_t *w, int compact, char *line, size_t cap)
{
    size_t n = 0;
    const char *st = mpp_status_name(w->status);
    line[0] = 0;
    if (compact)
        append(line, cap, &n, "%s step %lld", st ? st : "?", w->step);
    else
        append(line, cap, &n, "job %llu %s  step %lld", (unsigned long long)w->job, st ? st : "?",
               w->step);
    if (w->steps_total > 0) append(line, cap, &n, "/%lld", w->steps_total);
    append(line, cap, &n, compact ? " t %.4g" : "  t %.6g", w->t);
    if (w->have_first)
        append(line, cap, &n, compact ? " K %.3e S %.3e E %.3e" : "  K %.4e  S %.4e  E %.6e",
               w->kinetic, w->strain, w->last_total);
    if (w->have_first && w->have_angmom)
        append(line, cap, &n, compact ? " |L| %.3e" : "  |L| %.6e", w->angmom);
    if (w->have_first)
        append(line, cap, &n, compact ? " bal %.2g%%" : "  bal %.3g%%", 100 * w->balance);
    if (w->steps_total > 0) {
        double frac = (double)w->step / (double)w->steps_total;
        if (frac < 0) frac = 0;
        if (frac > 1) frac = 1;
        if (compact) {
            append(line, cap, &n, " %.0f%%", 100 * frac);
        } else {
            char bar[32];
            int fill = (int)(frac * 20 + 0.5);
            for (int i = 0; i < 20; i++) bar[i] = i < fill ? '#' : '.';
            bar[20] = 0;
            append(line, cap, &n, "  [%s] %3.0f%%", bar, 100 * frac);
        }
        if (w->have_progress && w->wall_s > 0 && w->step > 0 && w->step < w->steps_total) {
            char eta[32];
            double rate = (double)w->step / w->wall_s;
            ctl_fmt_duration(eta, sizeof eta, (double)(w->steps_total - w->step) / rate);
            append(line, cap, &n, " ETA %s", eta);
        }
    }
    return n;
}

static void draw(watch_t *w, int force)
{
    char line[512];
    double t = now_s();
    if (!w->tty || (!force && t - w->last_draw < WATCH_REDRAW_S)) return;
    w->last_draw = t;
    size_t cols = (size_t)term_cols();
    size_t n = status_line(w, 0, line, sizeof line);
    if (n >= cols) n = status_line(w, 1, line, sizeof line);
    if (n >= cols) line[cols - 1] = 0;
    printf("\r\033[K%s", line);
    fflush(stdout);
    w->line_shown = 1;
}

/* Writes one accepted sample. */
static int emit(watch_t *w, const mpm_energy_sample *s)
{
    double total = cj_norm(s->e.total);
    if (!w->have_first) {
        w->first_total = total;
        w->have_first = 1;
    }
    w->last_total = total;
    w->kinetic = cj_norm(s->e.kinetic);
    w->strain = cj_norm(s->e.strain);
    w->balance = cj_norm(s->e.balance_error);
    w->have_angmom = s->dim >= 2;
    if (w->have_angmom) {
        const double *L = s->e.angular_momentum;
        w->angmom = cj_norm(sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2]));
    }
    if (!w->have_progress || s->step > w->step) {
        w->step = s->step;
        w->t = cj_norm(s->t);
    }
    w->samples++;
    w->next++;
    if (w->fmt == CTL_OUT_TEXT && w->tty) {
        draw(w, 0);
        return 0;
    }
    int rc = ctl_energy_out_row(&w->eo, s);
    if (!rc && fflush(stdout)) rc = CTL_ESYS;
    if (rc) fprintf(stderr, "mpmctl: cannot write the energy series: %s\n", strerror(errno));
    return rc;
}

/* A sample from the stored history: in order by construction. */
static int take_history(const mpm_energy_sample *s, void *arg)
{
    watch_t *w = arg;
    uint64_t seq = s->seq;
    if (seq < w->next) return 0;
    if (seq > w->next) {
        /* the store itself has a hole: report it, keep going */
        fprintf(stderr, "mpmctl: warning: energy history of job %llu jumps from seq %llu to %llu\n",
                (unsigned long long)w->job, (unsigned long long)w->next, (unsigned long long)seq);
        w->next = seq;
    }
    return emit(w, s);
}

static int fetch_rest(watch_t *w)
{
    return ctl_fetch_energy(w->c, w->job, w->next, take_history, w);
}

/* A sample from the live stream. */
static int take_live(watch_t *w, const mpm_energy_sample *s)
{
    uint64_t seq = s->seq;
    int rc;
    if (seq < w->next) return 0;
    if (seq > w->next) {
        w->gaps_filled++;
        if ((rc = fetch_rest(w))) return rc;
        if (seq < w->next) return 0;
        if (seq > w->next) {
            fprintf(stderr,
                    "mpmctl: warning: job %llu: sample seq %llu streamed but the history "
                    "ends at %llu\n",
                    (unsigned long long)w->job, (unsigned long long)seq,
                    (unsigned long long)w->next);
            w->next = seq;
        }
    }
    return emit(w, s);
}

/* Applies a RunInfo (Status reply) to the view. */
static void apply_run(watch_t *w, const mpp_run_info *run)
{
    w->status = run->status;
    if (run->steps_total > 0) w->steps_total = run->steps_total;
    if (run->steps > w->step) {
        w->step = run->steps;
        w->t = cj_norm(run->t);
    }
    if (!w->name[0]) ctl_esc(run->name, w->name, sizeof w->name);
}

/* Status(job) into *reply (release it with mpp_reply_clear()); its run is
 * reply->runs[0]. */
static int status(watch_t *w, mpp_reply *reply)
{
    mpp_request rq = {.kind = MPP_REQ_STATUS, .id = w->job};
    int rc = ctl_call_reply(w->c, &rq, MPP_REPLY_RUN, reply);
    if (!rc && reply->n_runs != 1) {
        fprintf(stderr, "mpmctl: a Status reply without its run\n");
        rc = CTL_EPROTO;
    }
    if (!rc) apply_run(w, &reply->runs[0]);
    return rc;
}

/* Counts what the stream lost from the gaps in StreamMsg.seq. */
static void stream_seq(watch_t *w, uint64_t seq)
{
    if (w->have_stream_seq && seq > w->stream_seq + 1) w->stream_lost += seq - w->stream_seq - 1;
    if (!w->have_stream_seq || seq > w->stream_seq) w->stream_seq = seq;
    w->have_stream_seq = 1;
}

/* After Finished: the samples still missing.  Finished carries the final
 * sample (with its seq), which is the last of the series: when it is the
 * next one expected it completes the series, when it is older nothing is
 * missing; otherwise the tail comes from the history.  Without a final
 * sample at step 0 the job never ran and has no samples.  A job INTERRUPTED
 * by a daemon shutting down may leave nobody to ask: then a short wait,
 * and what we have. */
static int finish_tail(watch_t *w)
{
    double saved = w->c->timeout_s;
    int rc;
    if (w->has_fin) {
        uint64_t seq = w->fin.seq;
        if (seq < w->next) return 0;
        if (seq == w->next) return emit(w, &w->fin);
    } else if (w->step == 0 && w->next == 0) {
        /* it ended before its first step (cancelled or interrupted while
         * queued, or refused by the solver): it has no samples at all */
        return 0;
    }
    if (w->status == MPP_STATUS_INTERRUPTED && saved > 3) w->c->timeout_s = 3;
    rc = fetch_rest(w);
    w->c->timeout_s = saved;
    if (rc == CTL_ETIMEOUT && w->status == MPP_STATUS_INTERRUPTED) {
        fprintf(stderr, "mpmctl: warning: the daemon stopped; the series may lack its last "
                        "samples\n");
        return 0;
    }
    return rc;
}

/* Handles one stream message (decoded once, into the protocol's struct);
 * sets w->finished on Finished. */
static int on_message(watch_t *w, const void *data, size_t len)
{
    char text[MPM_ERROR_MSG_MAX + 256];
    mpm_error e;
    mpp_stream m;
    int rc = 0;
    if (mpp_stream_decode(data, len, 0, &m, &e)) {
        fprintf(stderr, "mpmctl: warning: undecodable stream message: %s\n",
                mpm_error_text(&e, MPM_FIELD_JSON, text, sizeof text));
        return 0;
    }
    if (m.has_job_id && m.job_id != w->job) goto out;
    if (m.kind == MPP_STREAM_SNAPSHOT) {
        if (m.has_seq) stream_seq(w, m.seq);
        goto out;
    }
    if ((w->drop_every && m.kind == MPP_STREAM_ENERGY && ++w->energy_seen % w->drop_every == 0) ||
        (w->drop_finished && m.kind == MPP_STREAM_FINISHED))
        goto out; /* injected loss: as if the stream never delivered it */
    stream_seq(w, m.seq);
    switch (m.kind) {
    case MPP_STREAM_ENERGY:
        if (w->status != MPP_STATUS_RUNNING && !terminal_status(w->status))
            w->status = MPP_STATUS_RUNNING;
        rc = take_live(w, &m.energy);
        break;
    case MPP_STREAM_PROGRESS:
        w->status = MPP_STATUS_RUNNING;
        w->have_progress = 1;
        w->step = m.progress.step;
        w->t = cj_norm(m.progress.t);
        w->dt = cj_norm(m.progress.dt);
        w->wall_s = cj_norm(m.progress.wall_s);
        if (m.progress.steps_total > 0) w->steps_total = m.progress.steps_total;
        draw(w, 0);
        break;
    case MPP_STREAM_FINISHED:
        w->finished = 1;
        w->status = m.finished.status;
        snprintf(w->error, sizeof w->error, "%s", m.finished.error);
        w->step = m.finished.steps;
        w->t = cj_norm(m.finished.t);
        w->wall_s = cj_norm(m.finished.wall_s);
        w->has_fin = m.has_energy;
        w->fin = m.energy;
        snprintf(w->warning, sizeof w->warning, "%s", m.finished.warning);
        w->has_fin_balance = m.finished.has_balance;
        w->fin_balance = cj_norm(m.finished.balance_error);
        break;
    default: break;
    }
out:
    mpp_stream_clear(&m);
    return rc;
}

/* Receives one [topic][StreamMsg] message and handles it. */
static int recv_stream(watch_t *w, void *sub)
{
    zmq_msg_t topic, body;
    int more = 0, rc = 0;
    size_t ml = sizeof more;
    if (zmq_msg_init(&topic) || zmq_msg_init(&body)) return CTL_ESYS;
    if (zmq_msg_recv(&topic, sub, ZMQ_DONTWAIT) < 0) {
        zmq_msg_close(&topic);
        zmq_msg_close(&body);
        return (errno == EAGAIN || errno == EINTR) ? 0 : CTL_ESYS;
    }
    if (zmq_getsockopt(sub, ZMQ_RCVMORE, &more, &ml) || !more) goto out; /* malformed: drop */
    if (zmq_msg_recv(&body, sub, 0) < 0) {
        rc = CTL_ESYS;
        goto out;
    }
    if (zmq_getsockopt(sub, ZMQ_RCVMORE, &more, &ml)) more = 0;
    if (more) {
        /* more than two frames: drain and drop */
        ctl_drain_more(sub);
        goto out;
    }
    rc = on_message(w, zmq_msg_data(&body), zmq_msg_size(&body));
out:
    zmq_msg_close(&topic);
    zmq_msg_close(&body);
    if (rc == CTL_ESYS && errno) fprintf(stderr, "mpmctl: stream: %s\n", zmq_strerror(errno));
    return rc;
}

static void summary(watch_t *w, const mpp_run_info *run)
{
    FILE *f = w->info;
    char wall[32];
    const char *st = mpp_status_name(w->status);
    const char *error = run ? run->error : "";
    const mpm_energy_sample *le = run ? run->last_energy : w->has_fin ? &w->fin : NULL;
    if (!*error) error = w->error;
    if (w->tty && w->line_shown) {
        draw(w, 1);
        fputc('\n', stdout);
        fflush(stdout);
    }
    fprintf(f, "job %llu%s%s%s: %s\n", (unsigned long long)w->job, w->name[0] ? " (" : "", w->name,
            w->name[0] ? ")" : "", st ? st : "unknown status");
    ctl_fmt_duration(wall, sizeof wall, run ? cj_norm(run->wall_s) : w->wall_s);
    fprintf(f, "  steps %lld, t %.10g, wall %s\n", run ? (long long)run->steps : w->step,
            run ? cj_norm(run->t) : w->t, wall);
    if (le)
        fprintf(f, "  final energy: kinetic %.10e  strain %.10e  total %.10e\n",
                cj_norm(le->e.kinetic), cj_norm(le->e.strain), cj_norm(le->e.total));
    else if (w->have_first)
        fprintf(f, "  final energy: kinetic %.10e  strain %.10e  total %.10e\n", w->kinetic,
                w->strain, w->last_total);
    if (w->have_first) {
        double d = w->last_total - w->first_total;
        if (w->first_total != 0)
            fprintf(f, "  energy drift: %+.3e relative (%+.3e absolute) over %llu samples\n",
                    d / fabs(w->first_total), d, (unsigned long long)w->samples);
        else
            fprintf(f, "  energy drift: %+.3e absolute over %llu samples\n", d,
                    (unsigned long long)w->samples);
    }
    if (run && run->has_balance)
        fprintf(f, "  energy balance error: %.3g %% (at the end of the run)\n",
                100 * cj_norm(run->balance_error));
    else if (w->has_fin_balance)
        fprintf(f, "  energy balance error: %.3g %% (at the end of the run)\n",
                100 * w->fin_balance);
    const char *warning = run && *run->warning ? run->warning : w->warning;
    if (*warning) fprintf(f, "  warning: %s\n", warning);
    if (w->gaps_filled || w->stream_lost)
        fprintf(f, "  stream: %llu messages dropped, %llu gaps filled from the history\n",
                (unsigned long long)w->stream_lost, (unsigned long long)w->gaps_filled);
    if (*error) fprintf(f, "  error: %s\n", error);
    fflush(f);
}

static void on_signal(int sig)
{
    (void)sig;
    ctl_interrupted = 1;
}

/* The live phase: stream messages until the job ends. */
static int live(watch_t *w, void *sub)
{
    double last_msg = now_s();
    for (;;) {
        zmq_pollitem_t it = {sub, 0, ZMQ_POLLIN, 0};
        double idle = now_s() - last_msg;
        long wait_ms = (long)((WATCH_IDLE_S - idle) * 1000.0);
        int rc;
        if (ctl_interrupted) return CTL_EINTR;
        if (wait_ms < 0) wait_ms = 0;
        rc = zmq_poll(&it, 1, wait_ms);
        if (rc < 0) {
            if (errno == EINTR) continue;
            fprintf(stderr, "mpmctl: zmq_poll: %s\n", zmq_strerror(errno));
            return CTL_ESYS;
        }
        if (rc > 0) {
            /* drain what is there, then look at the clock again */
            for (int k = 0; k < 1000 && !w->finished; k++) {
                zmq_pollitem_t it2 = {sub, 0, ZMQ_POLLIN, 0};
                if ((rc = recv_stream(w, sub))) return rc;
                if (zmq_poll(&it2, 1, 0) <= 0) break;
            }
            last_msg = now_s();
            if (w->finished) return finish_tail(w);
            continue;
        }
        if (now_s() - last_msg >= WATCH_IDLE_S) {
            mpp_reply reply;
            rc = status(w, &reply);
            mpp_reply_clear(&reply);
            if (rc) return rc;
            draw(w, 1);
            if (terminal_status(w->status)) return fetch_rest(w);
            last_msg = now_s();
        }
    }
}

int ctl_watch(ctl_conn *c, uint64_t job, ctl_out fmt, int *final_status)
{
    watch_t w;
    char ep[512], topic[32];
    void *sub = NULL;
    mpp_reply reply = {0};
    int rc, hwm = WATCH_SUB_HWM, linger = 0;
    struct sigaction sa, old_int, old_term;

    memset(&w, 0, sizeof w);
    w.c = c;
    w.job = job;
    w.fmt = fmt;
    w.tty = fmt == CTL_OUT_TEXT && isatty(STDOUT_FILENO);
    w.info = fmt == CTL_OUT_TEXT ? stdout : stderr;
    *final_status = 0;
    {
        const char *de = getenv("MPMCTL_TEST_DROP_EVERY");
        const char *df = getenv("MPMCTL_TEST_DROP_FINISHED");
        w.drop_every = de ? (unsigned)strtoul(de, NULL, 10) : 0;
        w.drop_finished = df && *df && strcmp(df, "0");
    }

    if ((rc = ctl_stream_endpoint(c, ep, sizeof ep))) return rc;
    if (!c->zctx && (rc = ctl_conn_open(c))) return rc;
    sub = zmq_socket(c->zctx, ZMQ_SUB);
    snprintf(topic, sizeof topic, "job:%016llx:", (unsigned long long)job);
    if (!sub || zmq_setsockopt(sub, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_setsockopt(sub, ZMQ_RCVHWM, &hwm, sizeof hwm) ||
        zmq_setsockopt(sub, ZMQ_IPV6, &(int){1}, sizeof(int)) ||
        zmq_setsockopt(sub, ZMQ_SUBSCRIBE, topic, strlen(topic))) {
        fprintf(stderr, "mpmctl: stream socket: %s\n", zmq_strerror(errno));
        if (sub) zmq_close(sub);
        return CTL_ESYS;
    }
    if (ctl_conn_secure(c, sub)) {
        zmq_close(sub);
        return CTL_ESYS;
    }
    if (zmq_connect(sub, ep)) {
        fprintf(stderr, "mpmctl: cannot connect to the stream at %s: %s\n", ep,
                zmq_strerror(errno));
        zmq_close(sub);
        return CTL_ESYS;
    }

    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &old_int);
    sigaction(SIGTERM, &sa, &old_term);

    /* where the job stands (and whether it exists) */
    rc = status(&w, &reply);
    if (!rc) ctl_energy_out_init(&w.eo, fmt, reply.runs[0].dim, stdout);
    mpp_reply_clear(&reply);
    if (rc) goto out;
    if (w.fmt == CTL_OUT_TEXT && !w.tty)
        fprintf(stdout, "job %llu%s%s%s: %s\n", (unsigned long long)job, w.name[0] ? " (" : "",
                w.name, w.name[0] ? ")" : "",
                mpp_status_name(w.status) ? mpp_status_name(w.status) : "?");
    draw(&w, 1);
    {
        int was_terminal = terminal_status(w.status);
        if ((rc = fetch_rest(&w))) goto out;
        if (!was_terminal && (rc = live(&w, sub))) goto out;
    }
    /* the summary: Finished says all it needs (and the daemon may be gone
     * after an INTERRUPTED job); otherwise the daemon's record of the job */
    if (!w.finished && (rc = status(&w, &reply))) goto out;
    summary(&w, w.finished ? NULL : &reply.runs[0]);
    *final_status = w.status;
out:
    if (rc == CTL_EINTR) {
        if (w.line_shown) fputc('\n', stdout);
        fflush(stdout);
        fprintf(stderr,
                "mpmctl: stopped watching job %llu; it keeps running (mpmctl cancel %llu "
                "stops it)\n",
                (unsigned long long)job, (unsigned long long)job);
    }
    mpp_reply_clear(&reply);
    zmq_close(sub);
    sigaction(SIGINT, &old_int, NULL);
    sigaction(SIGTERM, &old_term, NULL);
    return rc;
}
