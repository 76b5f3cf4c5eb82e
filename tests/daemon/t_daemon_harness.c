/*
 * t_daemon_harness.c - processes, files and raw requests for the daemon's
 * integration tests (see t_daemon.h).  Children are started with fork and
 * exec, their output read through pipes (mpmctl) or appended to a log file
 * (mpmd); every wait has a deadline after which the child is killed, so a
 * hung daemon or client fails its test instead of hanging the runner.  The
 * pids of what a test started are remembered so that td_cleanup() can stop
 * whatever is left when a CHECK returns early.
 */
#define _GNU_SOURCE
#include "t_daemon.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <zmq.h>

#define TD_MAX_PROCS 32
#define TD_MAX_ARGS 64
#define TD_READY_S 20.0
#define TD_STOP_S 20.0

/* ---- registry of children ---------------------------------------------- */

static struct {
    pid_t pid;
    int daemon;
    char log[320];
} procs[TD_MAX_PROCS];
static int nprocs;

/* Output buffers handed out in td_out (freed by td_out_free, or by
 * td_cleanup when a CHECK returned before that). */
#define TD_MAX_BUFS 256
static char *bufs[TD_MAX_BUFS];

static void buf_own(char *p)
{
    for (int i = 0; p && i < TD_MAX_BUFS; i++)
        if (!bufs[i]) {
            bufs[i] = p;
            return;
        }
}

static void buf_free(char *p)
{
    for (int i = 0; p && i < TD_MAX_BUFS; i++)
        if (bufs[i] == p) bufs[i] = NULL;
    free(p);
}

static void reg_add(pid_t pid, int daemon, const char *log)
{
    for (int i = 0; i < nprocs; i++)
        if (!procs[i].pid) {
            procs[i].pid = pid;
            procs[i].daemon = daemon;
            snprintf(procs[i].log, sizeof procs[i].log, "%s", log ? log : "");
            return;
        }
    if (nprocs < TD_MAX_PROCS) {
        procs[nprocs].pid = pid;
        procs[nprocs].daemon = daemon;
        snprintf(procs[nprocs].log, sizeof procs[nprocs].log, "%s", log ? log : "");
        nprocs++;
    }
}

/* Marks a pid reaped (keeps daemon logs for the failure report). */
static void reg_done(pid_t pid)
{
    for (int i = 0; i < nprocs; i++)
        if (procs[i].pid == pid) procs[i].pid = -1;
}

double td_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

void td_msleep(int ms)
{
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    while (nanosleep(&ts, &ts) && errno == EINTR) {
    }
}

static int decode_status(int ws)
{
    if (WIFEXITED(ws)) return WEXITSTATUS(ws);
    if (WIFSIGNALED(ws)) return 128 + WTERMSIG(ws);
    return -1;
}

/* waitpid with a deadline: the decoded status, or -2 if still running. */
static int wait_deadline(pid_t pid, double timeout)
{
    double end = td_now() + timeout;
    for (;;) {
        int ws;
        pid_t r = waitpid(pid, &ws, WNOHANG);
        if (r == pid) {
            reg_done(pid);
            return decode_status(ws);
        }
        if (r < 0 && errno != EINTR) {
            reg_done(pid);
            return -1;
        }
        if (td_now() > end) return -2;
        td_msleep(10);
    }
}

static void kill_reap(pid_t pid)
{
    kill(pid, SIGKILL);
    if (wait_deadline(pid, 10) == -2)
        fprintf(stderr, "harness: pid %d survives SIGKILL\n", (int)pid);
}

static void print_tail(const char *path, int lines)
{
    size_t len = 0;
    char *t = td_slurp(path, &len);
    if (!t) return;
    size_t start = len;
    int n = 0;
    while (start > 0 && n <= lines) {
        start--;
        if (t[start] == '\n') n++;
    }
    printf("    --- last lines of %s ---\n%s%s", path, t + start + (start > 0),
           len && t[len - 1] != '\n' ? "\n" : "");
    free(t);
}

/* CURVE keys of the raw requests (td_set_curve); "" = none. */
static char curve_srv[41], curve_pub[41], curve_sec[41];

void td_set_curve(const char *server_pub, const char *client_pub, const char *client_sec)
{
    curve_srv[0] = curve_pub[0] = curve_sec[0] = 0;
    if (!server_pub) return;
    snprintf(curve_srv, sizeof curve_srv, "%s", server_pub);
    snprintf(curve_pub, sizeof curve_pub, "%s", client_pub);
    snprintf(curve_sec, sizeof curve_sec, "%s", client_sec);
}

void td_cleanup(void)
{
    td_set_curve(NULL, NULL, NULL);
    for (int i = 0; i < nprocs; i++) {
        if (procs[i].pid > 0) {
            if (procs[i].daemon) {
                kill(procs[i].pid, SIGTERM);
                if (wait_deadline(procs[i].pid, 10) == -2) kill_reap(procs[i].pid);
            } else {
                kill_reap(procs[i].pid);
            }
        }
        if (t_failed() && procs[i].daemon && procs[i].log[0]) {
            int dup = 0;
            for (int j = 0; j < i; j++)
                dup |= procs[j].daemon && !strcmp(procs[j].log, procs[i].log);
            if (!dup) print_tail(procs[i].log, 25);
        }
    }
    nprocs = 0;
    for (int i = 0; i < TD_MAX_BUFS; i++) {
        free(bufs[i]);
        bufs[i] = NULL;
    }
}

/* ---- processes ------------------------------------------------------------ */

const char *td_bin(const char *env)
{
    const char *p = getenv(env);
    if (!p || !*p) {
        t_fail(__FILE__, __LINE__,
               "%s is not set: run the daemon tests through `make test` or "
               "`make test-quick` (they set MPMD_BIN and MPMCTL_BIN)",
               env);
        return NULL;
    }
    if (access(p, X_OK)) {
        t_fail(__FILE__, __LINE__, "%s=%s is not an executable: %s (build it first)", env, p,
               strerror(errno));
        return NULL;
    }
    return p;
}

/* fork + exec argv with stdin from /dev/null and stdout/stderr on the
 * given fds.  Returns the pid or -1. */
static pid_t spawn(const char *const *argv, int out_fd, int err_fd)
{
    pid_t pid;
    fflush(stdout);
    fflush(stderr);
    pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        int nul = open("/dev/null", O_RDONLY);
        if (nul >= 0) dup2(nul, 0);
        dup2(out_fd, 1);
        dup2(err_fd, 2);
        for (int fd = 3; fd < 1024; fd++) close(fd);
        execv(argv[0], (char *const *)argv);
        dprintf(2, "harness: cannot exec %s: %s\n", argv[0], strerror(errno));
        _exit(127);
    }
    return pid;
}

/* Renders e into err when rc is an error; returns rc. */
static int td_err(int rc, const mpm_error *e, char *err, size_t n)
{
    if (rc && err && n) mpm_error_text(e, MPM_FIELD_JSON, err, n);
    return rc;
}

int td_case_load(const char *json, size_t len, mpp_case **out, char *err, size_t n)
{
    mpm_error e;
    return td_err(mpp_case_load(json, len, 0, out, &e), &e, err, n);
}

int td_case_from_json(const char *json, size_t len, Mpmd__Case **out, char *err, size_t n)
{
    mpm_error e;
    return td_err(mpp_case_from_json(json, len, out, &e), &e, err, n);
}

int td_case_unpack(const void *buf, size_t len, size_t max, Mpmd__Case **out, char *err, size_t n)
{
    mpm_error e;
    return td_err(mpp_case_unpack(buf, len, max, out, &e), &e, err, n);
}

int td_msg_json_to_bytes(mpp_msg_kind kind, const char *json, size_t len, uint8_t **buf,
                         size_t *nbytes, char *err, size_t n)
{
    mpm_error e;
    return td_err(mpp_msg_json_to_bytes(kind, json, len, buf, nbytes, &e), &e, err, n);
}

int td_msg_bytes_to_json(mpp_msg_kind kind, const void *buf, size_t nbytes, size_t max,
                         unsigned flags, char **json, char *err, size_t n)
{
    mpm_error e;
    return td_err(mpp_msg_bytes_to_json(kind, buf, nbytes, max, flags, json, &e), &e, err, n);
}

int td_recv_parts(void *s, zmq_msg_t *part, int max)
{
    int n = 0, more = 1;
    while (more) {
        zmq_msg_t m;
        zmq_msg_init(&m);
        if (zmq_msg_recv(&m, s, 0) < 0) {
            zmq_msg_close(&m);
            break;
        }
        more = zmq_msg_more(&m);
        if (n < max)
            part[n++] = m;
        else
            zmq_msg_close(&m);
    }
    return n;
}

int td_request(const char *ep, const mpp_request *rq, double timeout, json_t **reply)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    int rc;
    *reply = NULL;
    if (mpp_request_encode(rq, &buf, &len)) return -1;
    const void *frames[2] = {"", buf};
    size_t lens[2] = {0, len};
    rc = td_frames(ep, frames, lens, 2, timeout, reply);
    free(buf);
    return rc;
}

int td_frames(const char *ep, const void *const *frames, const size_t *lens, int n, double timeout,
              json_t **reply)
{
    void *ctx = zmq_ctx_new(), *s = NULL;
    int zero = 0, rc = -1;
    zmq_msg_t parts[3];
    int np = 0;
    *reply = NULL;
    if (!ctx) return -1;
    s = zmq_socket(ctx, ZMQ_DEALER);
    if (!s || zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) ||
        zmq_setsockopt(s, ZMQ_IPV6, &(int){1}, sizeof(int)) ||
        (curve_srv[0] && (zmq_setsockopt(s, ZMQ_CURVE_SERVERKEY, curve_srv, 41) ||
                          zmq_setsockopt(s, ZMQ_CURVE_PUBLICKEY, curve_pub, 41) ||
                          zmq_setsockopt(s, ZMQ_CURVE_SECRETKEY, curve_sec, 41))) ||
        zmq_connect(s, ep))
        goto out;
    for (int i = 0; i < n; i++)
        if (zmq_send(s, frames[i], lens[i], i + 1 < n ? ZMQ_SNDMORE : 0) < 0) goto out;
    {
        zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
        int pr;
        while ((pr = zmq_poll(&it, 1, (long)(timeout * 1000))) < 0 && errno == EINTR) {
        }
        if (pr < 0) goto out;
        if (pr == 0) {
            rc = 1;
            goto out;
        }
    }
    np = td_recv_parts(s, parts, 3);
    if (!np) goto out;
    if (np == 2 && zmq_msg_size(&parts[0]) == 0) {
        char *json = NULL, err[256];
        if (!td_msg_bytes_to_json(MPP_MSG_REPLY, zmq_msg_data(&parts[1]), zmq_msg_size(&parts[1]),
                                  0, 0, &json, err, sizeof err)) {
            *reply = json_loads(json, 0, NULL);
            rc = *reply ? 0 : -1;
        } else {
            printf("    harness: undecodable reply: %s\n", err);
        }
        free(json);
    } else {
        printf("    harness: reply of %d frames\n", np);
    }
    for (int i = 0; i < np; i++) zmq_msg_close(&parts[i]);
out:
    if (s) zmq_close(s);
    zmq_ctx_term(ctx);
    return rc;
}

int td_start(td_daemon *d, const char *dir, const char *const *extra)
{
    return td_start_ep(d, dir, NULL, extra);
}

int td_tcp_port(int salt)
{
    return 21000 + (int)(((long)getpid() + salt) % 5500) * 2;
}

int td_start_ep(td_daemon *d, const char *dir, const char *ep, const char *const *extra)
{
    const char *bin = td_bin("MPMD_BIN");
    const char *argv[TD_MAX_ARGS];
    int n = 0, fd;
    double end;
    if (!bin) return -1;
    mkdir(dir, 0700);
    memset(d, 0, sizeof *d);
    snprintf(d->dir, sizeof d->dir, "%s", dir);
    if (ep)
        snprintf(d->ep, sizeof d->ep, "%s", ep);
    else
        snprintf(d->ep, sizeof d->ep, "ipc://%s/ctl", dir);
    snprintf(d->db, sizeof d->db, "%s/mpmd.db", dir);
    snprintf(d->log, sizeof d->log, "%s/mpmd.log", dir);
    argv[n++] = bin;
    argv[n++] = "--endpoint";
    argv[n++] = d->ep;
    argv[n++] = "--db";
    argv[n++] = d->db;
    for (int i = 0; extra && extra[i] && n < TD_MAX_ARGS - 1; i++) argv[n++] = extra[i];
    argv[n] = NULL;
    fd = open(d->log, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0600);
    if (fd < 0) {
        t_fail(__FILE__, __LINE__, "cannot create %s: %s", d->log, strerror(errno));
        return -1;
    }
    {
        char line[600];
        int k = snprintf(line, sizeof line, "=== harness: starting mpmd in %s\n", dir);
        if (write(fd, line, (size_t)k) < 0) {
        }
    }
    d->pid = spawn(argv, fd, fd);
    close(fd);
    if (d->pid < 0) {
        d->pid = 0;
        t_fail(__FILE__, __LINE__, "fork: %s", strerror(errno));
        return -1;
    }
    reg_add(d->pid, 1, d->log);
    end = td_now() + TD_READY_S;
    while (td_now() < end) {
        mpp_request rq = {.kind = MPP_REQ_PING};
        json_t *reply = NULL;
        int st = wait_deadline(d->pid, 0);
        if (st != -2) {
            d->pid = 0;
            print_tail(d->log, 25);
            t_fail(__FILE__, __LINE__, "mpmd exited with status %d before answering a ping", st);
            return -1;
        }
        if (td_request(d->ep, &rq, 0.5, &reply) == 0) {
            int ok = json_object_get(reply, "pong") != NULL;
            json_decref(reply);
            if (ok) return 0;
        }
        json_decref(reply);
        td_msleep(20);
    }
    print_tail(d->log, 25);
    t_fail(__FILE__, __LINE__, "mpmd did not answer a ping within %.0f s", TD_READY_S);
    kill_reap(d->pid);
    d->pid = 0;
    return -1;
}

int td_stop(td_daemon *d)
{
    int st;
    if (d->pid <= 0) return -1;
    kill(d->pid, SIGTERM);
    st = wait_deadline(d->pid, TD_STOP_S);
    if (st == -2) {
        printf("    harness: mpmd (pid %d) ignored SIGTERM for %.0f s; killing it\n", (int)d->pid,
               TD_STOP_S);
        kill_reap(d->pid);
        st = -1;
    }
    d->pid = 0;
    return st;
}

void td_kill9(td_daemon *d)
{
    if (d->pid > 0) kill_reap(d->pid);
    d->pid = 0;
}

/* Reads both pipes until EOF or the deadline; then reaps the child. */
static int collect(pid_t pid, int ofd, int efd, double t0, double timeout, td_out *o)
{
    char *buf[2] = {NULL, NULL};
    size_t len[2] = {0, 0}, cap[2] = {0, 0};
    int fds[2] = {ofd, efd}, open_[2] = {1, 1}, timed_out = 0;
    double end = t0 + timeout;
    while (open_[0] || open_[1]) {
        struct pollfd p[2];
        int np = 0, map[2];
        double left = end - td_now();
        if (left <= 0) {
            timed_out = 1;
            break;
        }
        for (int i = 0; i < 2; i++)
            if (open_[i]) {
                p[np].fd = fds[i];
                p[np].events = POLLIN;
                map[np++] = i;
            }
        int r = poll(p, (nfds_t)np, (int)(left * 1000) + 1);
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) break;
        for (int k = 0; k < np; k++) {
            int i = map[k];
            if (!(p[k].revents & (POLLIN | POLLHUP | POLLERR))) continue;
            if (len[i] + 65536 + 1 > cap[i]) {
                size_t nc = cap[i] ? 2 * cap[i] : 131072;
                char *nb = realloc(buf[i], nc);
                if (!nb) {
                    open_[i] = 0;
                    continue;
                }
                buf[i] = nb;
                cap[i] = nc;
            }
            ssize_t got = read(fds[i], buf[i] + len[i], cap[i] - len[i] - 1);
            if (got > 0)
                len[i] += (size_t)got;
            else if (got == 0 || errno != EINTR)
                open_[i] = 0;
        }
    }
    close(ofd);
    close(efd);
    for (int i = 0; i < 2; i++) {
        if (!buf[i]) buf[i] = malloc(1);
        if (buf[i]) buf[i][len[i]] = 0;
    }
    o->out = buf[0];
    o->err = buf[1];
    buf_own(o->out);
    buf_own(o->err);
    if (timed_out) {
        kill_reap(pid);
        o->status = -1;
    } else {
        int st = wait_deadline(pid, end - td_now() > 1 ? end - td_now() : 1);
        if (st == -2) {
            kill_reap(pid);
            st = -1;
        }
        o->status = st;
    }
    o->secs = td_now() - t0;
    return (o->out && o->err) ? 0 : -1;
}

static int run_capture(const char *const *argv, double timeout, td_out *o)
{
    int po[2], pe[2];
    pid_t pid;
    double t0 = td_now();
    memset(o, 0, sizeof *o);
    o->status = -1;
    if (pipe2(po, O_CLOEXEC)) return -1;
    if (pipe2(pe, O_CLOEXEC)) {
        close(po[0]);
        close(po[1]);
        return -1;
    }
    pid = spawn(argv, po[1], pe[1]);
    close(po[1]);
    close(pe[1]);
    if (pid < 0) {
        close(po[0]);
        close(pe[0]);
        return -1;
    }
    reg_add(pid, 0, NULL);
    return collect(pid, po[0], pe[0], t0, timeout, o);
}

int td_run_mpmd(const char *const *args, double timeout, td_out *o)
{
    const char *bin = td_bin("MPMD_BIN");
    const char *argv[TD_MAX_ARGS];
    int n = 0;
    memset(o, 0, sizeof *o);
    if (!bin) return -1;
    argv[n++] = bin;
    for (int i = 0; args[i] && n < TD_MAX_ARGS - 1; i++) argv[n++] = args[i];
    argv[n] = NULL;
    return run_capture(argv, timeout, o);
}

/* argv of an mpmctl run: binary, --endpoint, --timeout, args. */
static int ctl_argv(const td_daemon *d, const char *const *args, const char **argv)
{
    const char *bin = td_bin("MPMCTL_BIN");
    int n = 0;
    if (!bin) return -1;
    argv[n++] = bin;
    if (d) {
        argv[n++] = "--endpoint";
        argv[n++] = d->ep;
        argv[n++] = "--timeout";
        argv[n++] = "20";
    }
    for (int i = 0; args[i] && n < TD_MAX_ARGS - 1; i++) argv[n++] = args[i];
    argv[n] = NULL;
    return 0;
}

int td_ctlv(const td_daemon *d, double timeout, td_out *o, const char *const *args)
{
    const char *argv[TD_MAX_ARGS];
    memset(o, 0, sizeof *o);
    o->status = -1;
    if (ctl_argv(d, args, argv)) return -1;
    return run_capture(argv, timeout, o);
}

int td_ctl(const td_daemon *d, double timeout, td_out *o, ...)
{
    const char *args[TD_MAX_ARGS];
    int n = 0;
    va_list ap;
    va_start(ap, o);
    while (n < TD_MAX_ARGS - 1 && (args[n] = va_arg(ap, const char *))) n++;
    va_end(ap);
    args[n] = NULL;
    return td_ctlv(d, timeout, o, args);
}

void td_out_free(td_out *o)
{
    buf_free(o->out);
    buf_free(o->err);
    o->out = o->err = NULL;
}

int td_ctl_bg(const td_daemon *d, td_bg *b, const char *tag, ...)
{
    const char *args[TD_MAX_ARGS], *argv[TD_MAX_ARGS];
    int n = 0, of, ef;
    va_list ap;
    memset(b, 0, sizeof *b);
    va_start(ap, tag);
    while (n < TD_MAX_ARGS - 1 && (args[n] = va_arg(ap, const char *))) n++;
    va_end(ap);
    args[n] = NULL;
    if (ctl_argv(d, args, argv)) return -1;
    snprintf(b->out_path, sizeof b->out_path, "%s/%s.out", d->dir, tag);
    snprintf(b->err_path, sizeof b->err_path, "%s/%s.err", d->dir, tag);
    of = open(b->out_path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    ef = open(b->err_path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (of < 0 || ef < 0) {
        if (of >= 0) close(of);
        if (ef >= 0) close(ef);
        return -1;
    }
    b->t0 = td_now();
    b->pid = spawn(argv, of, ef);
    close(of);
    close(ef);
    if (b->pid < 0) return -1;
    reg_add(b->pid, 0, NULL);
    return 0;
}

int td_bg_wait(td_bg *b, double timeout, td_out *o)
{
    size_t len;
    int st;
    memset(o, 0, sizeof *o);
    if (b->pid <= 0) return -1;
    st = wait_deadline(b->pid, timeout);
    if (st == -2) {
        kill_reap(b->pid);
        st = -1;
    }
    b->pid = 0;
    o->status = st;
    o->secs = td_now() - b->t0;
    o->out = td_slurp(b->out_path, &len);
    o->err = td_slurp(b->err_path, &len);
    buf_own(o->out);
    buf_own(o->err);
    return (o->out && o->err) ? 0 : -1;
}

/* ---- replies ---------------------------------------------------------------- */

const char *td_err_code(const json_t *reply)
{
    const json_t *e = json_object_get(reply, "error");
    const json_t *c = json_object_get(e, "code");
    if (e && !c) return "INTERNAL"; /* the schema's default */
    return json_is_string(c) ? json_string_value(c) : "";
}

const char *td_err_field(const json_t *reply)
{
    const json_t *f = json_object_get(json_object_get(reply, "error"), "field");
    return json_is_string(f) ? json_string_value(f) : "";
}

const char *td_err_msg(const json_t *reply)
{
    const json_t *f = json_object_get(json_object_get(reply, "error"), "message");
    return json_is_string(f) ? json_string_value(f) : "";
}

int td_job_status(const td_daemon *d, unsigned long long job, char *buf, size_t n, long long *steps)
{
    mpp_request rq = {.kind = MPP_REQ_STATUS, .id = job};
    json_t *reply = NULL, *run;
    buf[0] = 0;
    if (td_request(d->ep, &rq, 10, &reply)) {
        json_decref(reply);
        return -1;
    }
    run = json_object_get(reply, "run");
    if (run) {
        const json_t *st = json_object_get(run, "status");
        const json_t *sp = json_object_get(run, "steps");
        snprintf(buf, n, "%s", json_is_string(st) ? json_string_value(st) : "");
        if (steps) *steps = json_is_string(sp) ? atoll(json_string_value(sp)) : 0;
    }
    json_decref(reply);
    return run ? 0 : -1;
}

static int status_in(const char *st, const char *want)
{
    size_t n = strlen(st);
    const char *p = want;
    if (!n) return 0;
    while ((p = strstr(p, st))) {
        if ((p == want || p[-1] == '|') && (p[n] == 0 || p[n] == '|')) return 1;
        p += n;
    }
    return 0;
}

int td_wait_status(const td_daemon *d, unsigned long long job, const char *want, double timeout,
                   char *got, size_t n)
{
    double end = td_now() + timeout;
    char buf[32] = "";
    do {
        if (td_job_status(d, job, buf, sizeof buf, NULL) == 0 && status_in(buf, want)) break;
        td_msleep(20);
    } while (td_now() < end);
    if (got) snprintf(got, n, "%s", buf);
    return status_in(buf, want) ? 0 : -1;
}

int td_wait_steps(const td_daemon *d, unsigned long long job, long long steps, double timeout)
{
    double end = td_now() + timeout;
    do {
        char buf[32];
        long long s = 0;
        if (td_job_status(d, job, buf, sizeof buf, &s) == 0 &&
            (s >= steps || status_in(buf, "FINISHED|FAILED|CANCELLED|INTERRUPTED")))
            return 0;
        td_msleep(10);
    } while (td_now() < end);
    return -1;
}

/* ---- files -------------------------------------------------------------------- */

char *td_slurp(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    char *buf = NULL;
    size_t cap = 0, n = 0;
    if (!f) return NULL;
    for (;;) {
        if (n + 65536 + 1 > cap) {
            size_t nc = cap ? 2 * cap : 131072;
            char *nb = realloc(buf, nc);
            if (!nb) {
                free(buf);
                fclose(f);
                return NULL;
            }
            buf = nb;
            cap = nc;
        }
        size_t r = fread(buf + n, 1, cap - n - 1, f);
        n += r;
        if (!r) break;
    }
    fclose(f);
    buf[n] = 0;
    *len = n;
    return buf;
}

int td_write(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    if (!f) return -1;
    fputs(text, f);
    return fclose(f) ? -1 : 0;
}

json_t *td_json_file(const char *path)
{
    json_error_t je;
    json_t *o = json_load_file(path, 0, &je);
    if (!o) printf("    harness: %s: %s (line %d)\n", path, je.text, je.line);
    return o;
}

int td_json_write(const char *path, const json_t *o)
{
    return json_dump_file(o, path, JSON_INDENT(1) | JSON_REAL_PRECISION(17));
}

size_t td_lines(char *text, char ***lines)
{
    size_t n = 0, cap = 0;
    char **v = NULL, *p = text;
    *lines = NULL;
    while (p && *p) {
        char *nl = strchr(p, '\n');
        if (n == cap) {
            size_t nc = cap ? 2 * cap : 256;
            char **nv = realloc(v, nc * sizeof *v);
            if (!nv) break;
            v = nv;
            cap = nc;
        }
        v[n++] = p;
        if (!nl) break;
        *nl = 0;
        p = nl + 1;
    }
    *lines = v;
    return n;
}

const char *const td_good2d =
    "{\"grid\": {\"dim\": 2, \"spacing\": [0.1, 0.1], \"nodes\": [11, 11]},"
    " \"materials\": [{\"youngsModulus\": 1, \"poissonRatio\": 0.2, \"density\": 1}],"
    " \"bodies\": [{\"sphere\": {\"center\": [0.3, 0.3], \"radius\": 0.1}},"
    "              {\"box\": {\"lo\": [0.6, 0.6], \"hi\": [0.8, 0.8]}, \"velocity\": [-0.1, 0]}],"
    " \"endTime\": 1}";

char *td_patch(const char *from, const char *to)
{
    const char *p = strstr(td_good2d, from);
    size_t n = strlen(td_good2d) - strlen(from) + strlen(to) + 1;
    char *s = malloc(n);
    if (!p || !s) {
        free(s);
        return NULL;
    }
    snprintf(s, n, "%.*s%s%s", (int)(p - td_good2d), td_good2d, to, p + strlen(from));
    return s;
}
