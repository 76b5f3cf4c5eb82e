/*
 * daemon.c - the `daemon` scene of bin/mpmbench: the paper's disks (the
 * disks2d scene's case, written as a JSON case) run through a real mpmd
 * and compared with the same case in-process.
 * How it works: the notes after the includes.
 */
#include "perf.h"

#include <stdio.h>

/*
 * The bench starts bin/mpmd itself (MPMD_BIN, else mpmd next to this
 * program) on ipc://DIR/ctl with a database DIR/mpmd.db, DIR a fresh
 * temporary directory, one worker and --solver-threads T; it talks to it
 * like mpmctl does (a DEALER on the control ROUTER, a SUB on the stream
 * XPUB) and stops it with SIGTERM, reading its peak RSS from wait4().
 * Each row has a process of its own: the reference and two daemons, all
 * started first; each runs a short warm-up job (WARM_STEPS: every job
 * builds its own simulation, so the warm-up only warms the process), then
 * the PB_RUNS timed jobs go round the three in turn, so that a change in
 * the load of the (shared) machine hits all three alike.
 *  - daemon-inproc: the reference, a forked process that stays up between
 *    its jobs like the daemon: the case converted by the same codec
 *    (mpp_case_load), then mpm_sim_new() + mpm_sim_run() timed together,
 *    since the daemon's worker does both between a Submit and its Finished
 *    message.
 *  - daemon-nowatch: no output section (energies only at the start and the
 *    end).  The client's SUB subscribes to the prefix "job:" before the
 *    first Submit: it sees every job's Finished, but the daemon counts a
 *    job as watched only on a subscription to its exact topic, so none is.
 *  - daemon-watch: the output section asks for energies every step and
 *    snapshots (X, V, PRESSURE) every 100 steps, and the client also
 *    subscribes to the job's exact topic right after SubmitOk (the daemon
 *    packs snapshots only for watched jobs); it decodes every stream
 *    message of the job once with mpp_stream_decode() (protobuf-c's unpack;
 *    a snapshot's arrays are copied once by it) and counts energies,
 *    snapshots and seq gaps.
 * The bench goes through the protocol library (mpp_msg.h) only: replies
 * are read with mpp_reply_decode(), and each case is kept as packed Case
 * bytes, submitted as they are (mpp_request.case_bytes).
 * Time per job: from just before the Submit is sent to the arrival of the
 * job's Finished message, on the client.  Finished.wall_s (the worker's own
 * loop, from before mpm_sim_new) splits it into daemon work around the
 * solver and per-step costs.
 */

#ifdef MPM_LEAN

int pb_daemon_scene(mpm_method m, mpm_update u, long particles, long steps, int threads)
{
    (void)m;
    (void)u;
    (void)particles;
    (void)steps;
    (void)threads;
    fprintf(stderr, "mpmbench: the daemon scene is not in the lean build (bin/mpmbench has it)\n");
    return -1;
}

#else

#include "mpp_msg.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zmq.h>

#define DEFAULT_STEPS \
    100 /* ~3 s at the target speed; the watched job's one snapshot is its last step */
#define SNAPSHOT_EVERY 100
#define WARM_STEPS 20 /* the warm-up job: every job builds a fresh simulation anyway */
#define READY_S 20.0  /* mpmd must answer a Ping within this */
#define STOP_S 20.0   /* and exit this long after SIGTERM */
#define CALL_S 30.0   /* a reply within this */
#define IDLE_S 1.0    /* no stream message this long: ask Status */
#define TOPIC_LEN 21  /* "job:%016llx:" */

typedef struct {
    pid_t pid;
    char dir[128], ep[160], sep[176], db[160], log[160];
    void *zctx, *dealer, *sub;
    long rss_kb;
} dmn;

typedef struct {
    double wall;        /* client: Submit sent -> Finished received */
    double worker_wall; /* Finished.wall_s */
    long energies, snapshots, progress, lost;
    long snap_bad; /* snapshots whose size is not what was asked */
    double cpu;    /* CPU seconds mpmd used meanwhile (all its threads) */
} job_res;

/* ---- the daemon process ---- */

static void log_tail(const dmn *d, int lines)
{
    FILE *f = fopen(d->log, "r");
    if (!f) return;
    char *ring[64] = {0}, buf[1024];
    int n = 0;
    if (lines > 64) lines = 64;
    while (fgets(buf, sizeof buf, f)) {
        free(ring[n % lines]);
        ring[n % lines] = strdup(buf);
        n++;
    }
    fclose(f);
    fprintf(stderr, "mpmbench: last lines of %s:\n", d->log);
    for (int i = n > lines ? n - lines : 0; i < n; i++)
        if (ring[i % lines]) fprintf(stderr, "    %s", ring[i % lines]);
    for (int i = 0; i < lines; i++) free(ring[i]);
}

/* The bench's temporary directory and what the daemon left in it: its
 * database files and the checkpoint directory beside the database
 * (mpmd.db.ckpt, emptied by the daemon; removed here with what is left). */
static void remove_dir(const char *dir, int depth)
{
    DIR *dp = opendir(dir);
    if (dp) {
        struct dirent *e;
        char path[PATH_MAX];
        while ((e = readdir(dp)))
            if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) {
                snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
                if (unlink(path) && depth < 2) remove_dir(path, depth + 1);
            }
        closedir(dp);
    }
    rmdir(dir);
}

static void close_zmq(dmn *d)
{
    if (d->sub) zmq_close(d->sub);
    if (d->dealer) zmq_close(d->dealer);
    d->sub = d->dealer = NULL;
    if (d->zctx)
        while (zmq_ctx_term(d->zctx) && errno == EINTR) {
        }
    d->zctx = NULL;
}

/* Reaps mpmd (SIGTERM, then SIGKILL after STOP_S) and records its peak
 * RSS.  Returns 0 when it exited cleanly. */
static int stop_daemon(dmn *d)
{
    int st = 0, rc = 0;
    struct rusage ru;
    close_zmq(d);
    if (d->pid <= 0) return -1;
    kill(d->pid, SIGTERM);
    double end = pb_now() + STOP_S;
    for (;;) {
        memset(&ru, 0, sizeof ru);
        pid_t w = wait4(d->pid, &st, WNOHANG, &ru);
        if (w == d->pid) break;
        if (w < 0 && errno != EINTR) {
            rc = -1;
            break;
        }
        if (pb_now() > end) {
            fprintf(stderr, "mpmbench: mpmd (pid %d) ignored SIGTERM for %.0f s; killing it\n",
                    (int)d->pid, STOP_S);
            kill(d->pid, SIGKILL);
            while (wait4(d->pid, &st, 0, &ru) < 0 && errno == EINTR) {
            }
            rc = -1;
            break;
        }
        usleep(10000);
    }
    d->pid = 0;
    d->rss_kb = ru.ru_maxrss;
    if (!rc && (!WIFEXITED(st) || WEXITSTATUS(st))) {
        fprintf(stderr, "mpmbench: mpmd exited with status %d\n",
                WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st));
        rc = -1;
    }
    return rc;
}

/* One request, one reply (decoded into *out by mpp_reply_decode; release
 * it with mpp_reply_clear() in every case).  A Reply.error becomes -1 with
 * its text. */
static int call(dmn *d, const mpp_request *rq, mpp_reply *out, double timeout, char *err,
                size_t errlen)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    memset(out, 0, sizeof *out);
    if (mpp_request_encode(rq, &buf, &len)) {
        snprintf(err, errlen, "cannot encode a request");
        return -1;
    }
    int sent =
        zmq_send(d->dealer, "", 0, ZMQ_SNDMORE) >= 0 && zmq_send(d->dealer, buf, len, 0) >= 0;
    free(buf);
    if (!sent) {
        snprintf(err, errlen, "zmq_send: %s", zmq_strerror(errno));
        return -1;
    }
    double end = pb_now() + timeout;
    for (;;) {
        zmq_pollitem_t it = {d->dealer, 0, ZMQ_POLLIN, 0};
        double left = end - pb_now();
        if (left <= 0) {
            snprintf(err, errlen, "no reply from mpmd within %.0f s", timeout);
            return -1;
        }
        int n = zmq_poll(&it, 1, (long)(left * 1000) + 1);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) {
            snprintf(err, errlen, "zmq_poll: %s", zmq_strerror(errno));
            return -1;
        }
        if (n > 0) break;
        if (d->pid > 0 && waitpid(d->pid, NULL, WNOHANG) == d->pid) {
            d->pid = 0;
            snprintf(err, errlen, "mpmd exited");
            return -1;
        }
    }
    zmq_msg_t part[2];
    int nparts = 0, more = 1, rc = 0;
    while (more) {
        zmq_msg_t m;
        if (zmq_msg_init(&m)) {
            rc = -1;
            break;
        }
        if (zmq_msg_recv(&m, d->dealer, 0) < 0) {
            zmq_msg_close(&m);
            rc = -1;
            break;
        }
        more = zmq_msg_more(&m);
        if (nparts < 2)
            part[nparts++] = m;
        else {
            zmq_msg_close(&m);
            rc = -1;
        }
    }
    if (rc || nparts != 2 || zmq_msg_size(&part[0]) != 0) {
        snprintf(err, errlen, "malformed reply from mpmd");
        rc = -1;
    } else {
        char why[MPM_ERROR_MSG_MAX + 256];
        mpm_error e;
        if (mpp_reply_decode(zmq_msg_data(&part[1]), zmq_msg_size(&part[1]), 0, out, &e)) {
            snprintf(err, errlen, "undecodable reply from mpmd: %.300s",
                     mpm_error_text(&e, MPM_FIELD_JSON, why, sizeof why));
            rc = -1;
        } else if (out->kind == MPP_REPLY_ERROR) {
            snprintf(err, errlen, "mpmd: error %d: %.300s%s%.100s%s", out->err_code,
                     out->err_message, *out->err_field ? " (field " : "", out->err_field,
                     *out->err_field ? ")" : "");
            rc = -1;
        }
    }
    for (int i = 0; i < nparts; i++) zmq_msg_close(&part[i]);
    return rc;
}

static int mpmd_path(char *out, size_t n)
{
    const char *env = getenv("MPMD_BIN");
    if (env && *env)
        snprintf(out, n, "%s", env);
    else
        snprintf(out, n, "%s/mpmd", pb_exe_dir());
    if (access(out, X_OK)) {
        fprintf(stderr,
                "mpmbench: daemon scene: %s is not an executable (make bin/mpmd, or set "
                "MPMD_BIN)\n",
                out);
        return -1;
    }
    return 0;
}

/* Starts mpmd in a new temporary directory and waits for its Pong. */
static int start_daemon(dmn *d, const char *bin, int threads)
{
    memset(d, 0, sizeof *d);
    const char *tmp = getenv("TMPDIR");
    if (!tmp || !*tmp || strlen(tmp) > 60) tmp = "/tmp";
    snprintf(d->dir, sizeof d->dir, "%s/mpmbench.XXXXXX", tmp);
    if (!mkdtemp(d->dir)) {
        fprintf(stderr, "mpmbench: mkdtemp %s: %s\n", d->dir, strerror(errno));
        d->dir[0] = 0;
        return -1;
    }
    char dir[sizeof d->dir];
    memcpy(dir, d->dir, sizeof dir); /* (a copy: gcc sees d's members as overlapping) */
    snprintf(d->ep, sizeof d->ep, "ipc://%s/ctl", dir);
    snprintf(d->sep, sizeof d->sep, "ipc://%s/ctl.stream", dir);
    snprintf(d->db, sizeof d->db, "%s/mpmd.db", dir);
    snprintf(d->log, sizeof d->log, "%s/mpmd.log", dir);
    char sthreads[16];
    snprintf(sthreads, sizeof sthreads, "%d", threads);
    char *argv[] = {(char *)bin, "--endpoint",       d->ep,    "--db",        d->db, "--workers",
                    "1",         "--solver-threads", sthreads, "--queue-max", "4",   NULL,
                    NULL};
    if (pb_kernels() == MPM_KERNELS_PORTABLE) argv[11] = "--portable-kernels";
    fflush(NULL);
    d->pid = fork();
    if (d->pid < 0) {
        fprintf(stderr, "mpmbench: fork: %s\n", strerror(errno));
        d->pid = 0;
        return -1;
    }
    if (d->pid == 0) {
        int fd = open(d->log, O_WRONLY | O_CREAT | O_APPEND, 0600);
        if (fd < 0 || dup2(fd, STDOUT_FILENO) < 0 || dup2(fd, STDERR_FILENO) < 0) _exit(127);
        close(fd);
        execv(bin, argv);
        fprintf(stderr, "cannot run %s: %s\n", bin, strerror(errno));
        _exit(127);
    }
    int linger = 0, hwm = 100000;
    d->zctx = zmq_ctx_new();
    if (!d->zctx || !(d->dealer = zmq_socket(d->zctx, ZMQ_DEALER)) ||
        !(d->sub = zmq_socket(d->zctx, ZMQ_SUB)) ||
        zmq_setsockopt(d->dealer, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_setsockopt(d->sub, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_setsockopt(d->sub, ZMQ_RCVHWM, &hwm, sizeof hwm) ||
        zmq_setsockopt(d->sub, ZMQ_SUBSCRIBE, "job:", 4) || zmq_connect(d->dealer, d->ep) ||
        zmq_connect(d->sub, d->sep)) {
        fprintf(stderr, "mpmbench: zmq: %s\n", zmq_strerror(errno));
        return -1;
    }
    /* one Ping, queued until mpmd binds: the DEALER connects by itself */
    mpp_request rq = {.kind = MPP_REQ_PING};
    mpp_reply rep;
    char err[512];
    if (call(d, &rq, &rep, READY_S, err, sizeof err)) {
        mpp_reply_clear(&rep);
        fprintf(stderr, "mpmbench: mpmd did not start: %s\n", err);
        log_tail(d, 20);
        return -1;
    }
    mpp_reply_kind kind = rep.kind;
    mpp_reply_clear(&rep);
    if (kind != MPP_REPLY_PONG) {
        fprintf(stderr, "mpmbench: mpmd did not start: unexpected reply to Ping (body %d)\n",
                (int)kind);
        log_tail(d, 20);
        return -1;
    }
    return 0;
}

/* ---- one job ---- */

/* CPU seconds (user + system) a process has used, from /proc; 0 if unknown. */
static double proc_cpu(pid_t pid)
{
    char path[64], buf[1024];
    snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
    FILE *f = fopen(path, "r");
    if (!f) return 0;
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = 0;
    char *p = strrchr(buf, ')'); /* the command name may hold spaces */
    unsigned long long ut = 0, st = 0;
    if (!p ||
        sscanf(p + 1, " %*c %*d %*d %*d %*d %*d %*u %*u %*u %*u %*u %llu %llu", &ut, &st) != 2)
        return 0;
    long tck = sysconf(_SC_CLK_TCK);
    return (double)(ut + st) / (double)(tck > 0 ? tck : 100);
}

static int job_status(dmn *d, uint64_t job, int *status, char *err, size_t errlen)
{
    mpp_request rq = {.kind = MPP_REQ_STATUS, .id = job};
    mpp_reply rep;
    int rc = call(d, &rq, &rep, CALL_S, err, errlen);
    *status = !rc && rep.kind == MPP_REPLY_RUN && rep.n_runs == 1 ? rep.runs[0].status : 0;
    mpp_reply_clear(&rep);
    return rc ? -1 : 0;
}

/* Receives one [topic][StreamMsg] message into *msg (mpp_stream_decode;
 * release it with mpp_stream_clear()); *ok 0 when it is not one. */
static int recv_stream(void *sub, mpp_stream *msg, int *ok)
{
    zmq_msg_t part[2];
    int nparts = 0, more = 1, rc = 0;
    *ok = 0;
    while (more) {
        zmq_msg_t m;
        if (zmq_msg_init(&m)) return -1;
        if (zmq_msg_recv(&m, sub, 0) < 0) {
            zmq_msg_close(&m);
            rc = errno == EINTR ? 0 : -1;
            break;
        }
        more = zmq_msg_more(&m);
        if (nparts < 2)
            part[nparts++] = m;
        else
            zmq_msg_close(&m);
    }
    if (!rc && nparts == 2 && zmq_msg_size(&part[0]) == TOPIC_LEN)
        *ok = mpp_stream_decode(zmq_msg_data(&part[1]), zmq_msg_size(&part[1]), 0, msg, NULL) == 0;
    for (int i = 0; i < nparts; i++) zmq_msg_close(&part[i]);
    return rc;
}

/* Submits the case (packed bytes) and follows the job's stream until its
 * Finished. */
static int run_job(dmn *d, const uint8_t *case_bytes, size_t case_len, int watch, int warmup,
                   size_t particles, double cap_s, job_res *jr, char *err, size_t errlen)
{
    memset(jr, 0, sizeof *jr);
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_bytes = case_bytes, .case_len = case_len};
    mpp_reply rep;
    double t0 = pb_now(), c0 = proc_cpu(d->pid);
    int crc = call(d, &rq, &rep, CALL_S, err, errlen);
    int sub_ok = !crc && rep.kind == MPP_REPLY_SUBMIT_OK && rep.has_job_id;
    uint64_t job = rep.job_id;
    mpp_reply_clear(&rep);
    if (crc) return -1;
    if (!sub_ok) {
        snprintf(err, errlen, "unexpected reply to Submit");
        return -1;
    }
    char topic[TOPIC_LEN + 1];
    snprintf(topic, sizeof topic, "job:%016llx:", (unsigned long long)job);
    if (watch && zmq_setsockopt(d->sub, ZMQ_SUBSCRIBE, topic, TOPIC_LEN)) {
        snprintf(err, errlen, "subscribe: %s", zmq_strerror(errno));
        return -1;
    }
    uint64_t next = 0;
    int rc = 1;
    double last = pb_now();
    while (rc > 0) {
        zmq_pollitem_t it = {d->sub, 0, ZMQ_POLLIN, 0};
        int n = zmq_poll(&it, 1, 250);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) {
            snprintf(err, errlen, "zmq_poll: %s", zmq_strerror(errno));
            rc = -1;
            break;
        }
        if (n == 0) {
            double now = pb_now();
            if (now - t0 > cap_s) {
                snprintf(err, errlen, "job %llu: no Finished within %.0f s",
                         (unsigned long long)job, cap_s);
                rc = -1;
            } else if (now - last > IDLE_S) {
                int st = 0;
                if (job_status(d, job, &st, err, errlen))
                    rc = -1;
                else if (st == MPP_STATUS_FINISHED && warmup) {
                    /* the SUB of a fresh daemon may connect after a short
                     * first job is over; only the warm-up can be that one */
                    jr->wall = pb_now() - t0;
                    rc = 0;
                } else if (st >= MPP_STATUS_FINISHED) {
                    snprintf(err, errlen,
                             "job %llu ended (%s) but its Finished message never "
                             "arrived",
                             (unsigned long long)job, mpp_status_name(st));
                    rc = -1;
                }
                last = pb_now();
            }
            continue;
        }
        mpp_stream m = {0};
        int ok = 0;
        if (recv_stream(d->sub, &m, &ok)) {
            snprintf(err, errlen, "stream: %s", zmq_strerror(errno));
            rc = -1;
            break;
        }
        last = pb_now();
        if (!ok || m.job_id != job) {
            mpp_stream_clear(&m);
            continue;
        }
        if (m.seq > next) jr->lost += (long)(m.seq - next);
        if (m.seq >= next) next = m.seq + 1;
        switch (m.kind) {
        case MPP_STREAM_ENERGY: jr->energies++; break;
        case MPP_STREAM_SNAPSHOT: {
            /* the decoder checked that each array present holds n times
             * its width */
            const mpp_snapshot *s = &m.snapshot;
            jr->snapshots++;
            if (s->n != particles || s->dim != 2 || !s->x || !s->v || !s->pressure) jr->snap_bad++;
            break;
        }
        case MPP_STREAM_PROGRESS: jr->progress++; break;
        case MPP_STREAM_FINISHED:
            jr->wall = pb_now() - t0;
            jr->cpu = proc_cpu(d->pid) - c0;
            jr->worker_wall = m.finished.wall_s;
            if (m.finished.status != MPP_STATUS_FINISHED) {
                snprintf(err, errlen, "job %llu ended %s%s%.300s", (unsigned long long)job,
                         mpp_status_name(m.finished.status) ? mpp_status_name(m.finished.status)
                                                            : "without a status",
                         m.finished.error[0] ? ": " : "", m.finished.error);
                rc = -1;
            } else {
                rc = 0;
            }
            break;
        default: break;
        }
        mpp_stream_clear(&m);
    }
    if (watch) zmq_setsockopt(d->sub, ZMQ_UNSUBSCRIBE, topic, TOPIC_LEN);
    return rc;
}

/* ---- the scene ---- */

/* One in-process job of the reference: the case from its JSON, then
 * mpm_sim_new() + mpm_sim_run(); the row gets the time of both (wall_s)
 * and of mpm_sim_new() (setup_s). */
static int ref_job(const char *json, pb_row *r)
{
    mpp_case *sc = NULL;
    char err[512];
    mpm_error e;
    if (mpp_case_load(json, strlen(json), 0, &sc, &e)) {
        snprintf(r->msg, sizeof r->msg, "the bench's own case: %.200s",
                 mpm_error_text(&e, MPM_FIELD_JSON, err, sizeof err));
        return -1;
    }
    double t0 = pb_now(), c0 = pb_cpu_self();
    mpm_error me;
    sc->c.kernels = pb_kernels();                       /* as the daemon's flag does */
    mpm_sim *sim = mpm_sim_new(&sc->c, &sc->info, &me); /* checked by mpp_case_load */
    if (!sim) {
        snprintf(r->msg, sizeof r->msg, "mpm_sim_new: %.200s",
                 mpm_error_text(&me, MPM_FIELD_PROTO, err, sizeof err));
        mpp_case_destroy(&sc);
        return -1;
    }
    double t1 = pb_now();
    int rc = mpm_sim_run(sim, (long)sc->steps);
    double t2 = pb_now();
    r->cpus = pb_cpu_self() - c0; /* CPU seconds of this job */
    r->particles = mpm_sim_particles(sim);
    r->nodes = mpm_sim_nodes(sim);
    r->dim = mpm_sim_dim(sim);
    r->steps = (long)sc->steps;
    if (rc)
        snprintf(r->msg, sizeof r->msg, "%s (%.200s)", mpm_strerror(rc),
                 mpm_sim_error(sim)->message);
    mpm_sim_destroy(&sim);
    mpp_case_destroy(&sc);
    r->wall_s = t2 - t0;
    r->setup_s = t1 - t0;
    return rc ? -1 : 0;
}

/* The disks2d case as JSON (the grid, bodies and material of
 * mpm_paper_disks() with h = 1 / cells), stopping after `steps` steps;
 * output: energies every step and snapshots every SNAPSHOT_EVERY. */
static char *case_json(int cells, mpm_method m, mpm_update u, long steps, int threads, int output)
{
    double h = 1.0 / cells, s = 0.1 / sqrt(2.0);
    const char *fmt =
        "{\"name\":\"mpmbench-disks2d%s\",\"grid\":{\"dim\":2,\"origin\":[0,0],"
        "\"spacing\":[%.17g,%.17g],\"nodes\":[%d,%d]},\"method\":\"%s\",\"update\":\"%s\","
        "\"materials\":[{\"model\":\"LINEAR_ELASTIC\",\"youngsModulus\":1,\"poissonRatio\":0.2,"
        "\"density\":1}],\"bodies\":["
        "{\"material\":0,\"velocity\":[%.17g,%.17g],\"sphere\":{\"center\":[0.25,0.25],"
        "\"radius\":0.14},\"ppc\":2},"
        "{\"material\":0,\"velocity\":[%.17g,%.17g],\"sphere\":{\"center\":[0.75,0.75],"
        "\"radius\":0.14},\"ppc\":2}],"
        "\"steps\":%ld,\"threads\":%d%s}";
    char out_sec[160] = "";
    if (output)
        snprintf(out_sec, sizeof out_sec,
                 ",\"output\":{\"energyEvery\":1,\"snapshotEvery\":%d,"
                 "\"snapshotFields\":[\"X\",\"V\",\"PRESSURE\"]}",
                 SNAPSHOT_EVERY);
    const char *mn = m == MPM_METHOD_GIMP ? "GIMP" : "MPM";
    const char *un = u == MPM_USL ? "USL" : u == MPM_MUSL ? "MUSL" : "USF";
    int n = snprintf(NULL, 0, fmt, output ? "-watched" : "", h, h, cells + 1, cells + 1, mn, un, s,
                     s, -s, -s, steps, threads, out_sec);
    char *buf = n > 0 ? malloc((size_t)n + 1) : NULL;
    if (!buf) return NULL;
    snprintf(buf, (size_t)n + 1, fmt, output ? "-watched" : "", h, h, cells + 1, cells + 1, mn, un,
             s, s, -s, -s, steps, threads, out_sec);
    return buf;
}

/* The cases of the scene: [watched][warm-up], as JSON (the in-process
 * reference loads it) and as packed Case bytes (submitted as they are). */
typedef struct {
    char *json[2][2];
    uint8_t *bytes[2][2];
    size_t len[2][2];
} cases;

static void cases_free(cases *c)
{
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
            free(c->json[i][j]);
            free(c->bytes[i][j]);
            c->json[i][j] = NULL;
            c->bytes[i][j] = NULL;
        }
}

static int cases_make(cases *c, int cells, mpm_method m, mpm_update u, long steps, int threads)
{
    char err[MPM_ERROR_MSG_MAX + 256];
    mpm_error e;
    long wsteps = steps < WARM_STEPS ? steps : WARM_STEPS;
    memset(c, 0, sizeof *c);
    for (int w = 0; w < 2; w++)
        for (int j = 0; j < 2; j++) {
            const char *js = c->json[w][j] = case_json(cells, m, u, j ? wsteps : steps, threads, w);
            if (!js) {
                fprintf(stderr, "mpmbench: out of memory\n");
                return -1;
            }
            if (mpp_msg_json_to_bytes(MPP_MSG_CASE, js, strlen(js), &c->bytes[w][j], &c->len[w][j],
                                      &e)) {
                fprintf(stderr, "mpmbench: the bench's own case: %s\n",
                        mpm_error_text(&e, MPM_FIELD_JSON, err, sizeof err));
                return -1;
            }
        }
    return 0;
}

/* The in-process reference runs in a process of its own that stays up
 * between its jobs, as the daemon does (its peak RSS is the row's): it
 * runs one job per command byte ('w' warm-up, 'r' timed, 'q' quit) and
 * answers with the job's row. */
typedef struct {
    pid_t pid;
    int cmd, res;
    long rss_kb;
} refproc;

static void cloexec(int fd)
{
    int f = fcntl(fd, F_GETFD);
    if (f >= 0) fcntl(fd, F_SETFD, f | FD_CLOEXEC);
}

static int ref_start(refproc *p, const cases *cs)
{
    int a[2], b[2];
    memset(p, 0, sizeof *p);
    p->cmd = p->res = -1;
    if (pipe(a)) {
        fprintf(stderr, "mpmbench: pipe: %s\n", strerror(errno));
        return -1;
    }
    if (pipe(b)) {
        fprintf(stderr, "mpmbench: pipe: %s\n", strerror(errno));
        close(a[0]);
        close(a[1]);
        return -1;
    }
    for (int i = 0; i < 2; i++) {
        cloexec(a[i]);
        cloexec(b[i]);
    }
    fflush(NULL);
    p->pid = fork();
    if (p->pid < 0) {
        fprintf(stderr, "mpmbench: fork: %s\n", strerror(errno));
        p->pid = 0;
        close(a[0]);
        close(a[1]);
        close(b[0]);
        close(b[1]);
        return -1;
    }
    if (p->pid == 0) {
        char c;
        close(a[1]);
        close(b[0]);
        while (pb_read_all(a[0], &c, 1) == 1 && c != 'q') {
            pb_row r;
            memset(&r, 0, sizeof r);
            r.rc = ref_job(cs->json[0][c == 'w'], &r);
            if (pb_write_all(b[1], &r, sizeof r)) break;
        }
        _exit(0);
    }
    close(a[0]);
    close(b[1]);
    p->cmd = a[1];
    p->res = b[0];
    return 0;
}

static int ref_run(refproc *p, int warm, pb_row *r)
{
    char c = warm ? 'w' : 'r';
    pb_row got;
    if (pb_write_all(p->cmd, &c, 1) || pb_read_all(p->res, &got, sizeof got) != sizeof got) {
        fprintf(stderr, "mpmbench: daemon-inproc: the reference process died\n");
        return -1;
    }
    if (got.rc) {
        fprintf(stderr, "mpmbench: daemon-inproc: %s\n", got.msg);
        return -1;
    }
    r->particles = got.particles;
    r->nodes = got.nodes;
    r->dim = got.dim;
    r->steps = got.steps;
    r->wall_s = got.wall_s;
    r->setup_s = got.setup_s;
    r->cpus = got.cpus;
    return 0;
}

static void ref_stop(refproc *p)
{
    if (p->cmd >= 0) {
        char q = 'q';
        if (pb_write_all(p->cmd, &q, 1)) {
        }
        close(p->cmd);
    }
    if (p->res >= 0) close(p->res);
    p->cmd = p->res = -1;
    if (p->pid > 0) {
        struct rusage ru;
        int st;
        memset(&ru, 0, sizeof ru);
        while (wait4(p->pid, &st, 0, &ru) < 0 && errno == EINTR) {
        }
        p->rss_kb = ru.ru_maxrss;
    }
    p->pid = 0;
}

/* Fills a row from the timed figures (wall and CPU seconds per job). */
static void fill_row(pb_row *r, const double *wall, const double *cpu, long rss_kb)
{
    double rate[PB_RUNS], ws = 0, cs = 0;
    for (int i = 0; i < PB_RUNS; i++) {
        ws += wall[i];
        cs += cpu[i];
    }
    r->cpus = ws > 0 ? cs / ws : 0;
    for (int i = 0; i < PB_RUNS; i++)
        rate[i] = (double)r->particles * (double)r->steps / (wall[i] > 0 ? wall[i] : 1e-9) / 1e6;
    r->runs = PB_RUNS;
    r->wall_s = pb_median(wall, PB_RUNS);
    r->mpsteps = pb_median(rate, PB_RUNS);
    r->rate_lo = r->rate_hi = rate[0];
    for (int i = 1; i < PB_RUNS; i++) {
        r->rate_lo = fmin(r->rate_lo, rate[i]);
        r->rate_hi = fmax(r->rate_hi, rate[i]);
    }
    r->rss_kb = rss_kb;
    r->bytes_pp = r->particles ? (double)rss_kb * 1024.0 / (double)r->particles : 0;
}

/* Sums the stream counts of the timed jobs. */
static void totals(const job_res *jr, job_res *sum)
{
    memset(sum, 0, sizeof *sum);
    for (int i = 0; i < PB_RUNS; i++) {
        sum->energies += jr[i].energies;
        sum->snapshots += jr[i].snapshots;
        sum->progress += jr[i].progress;
        sum->lost += jr[i].lost;
        sum->snap_bad += jr[i].snap_bad;
    }
}

int pb_daemon_scene(mpm_method m, mpm_update u, long particles, long steps, int threads)
{
    static const char *const row_name[2] = {"daemon-nowatch", "daemon-watch"};
    char bin[PATH_MAX + 16], err[512];
    if (mpmd_path(bin, sizeof bin)) return -1;
    if (!particles) particles = 1000000L;
    if (!steps) steps = DEFAULT_STEPS;
    int cells = pb_disks_cells(particles), rc = -1;
    cases cs;
    dmn d[2];
    refproc rp;
    memset(d, 0, sizeof d);
    memset(&rp, 0, sizeof rp);
    rp.cmd = rp.res = -1;
    pb_row ref, tmp, rows[2];
    job_res jr[2][PB_RUNS], warm, sum[2];
    double ref_wall[PB_RUNS], ref_build[PB_RUNS], ref_cpu[PB_RUNS], dm_wall[2][PB_RUNS],
        dm_cpu[2][PB_RUNS], worker[2][PB_RUNS];

    memset(&ref, 0, sizeof ref);
    snprintf(ref.scene, sizeof ref.scene, "daemon-inproc");
    ref.method = m;
    ref.update = u;
    ref.threads = threads;
    ref.dim = 2;
    if (cases_make(&cs, cells, m, u, steps, threads) || ref_start(&rp, &cs)) goto out;
    /* the reference's warm-up gives the particle count the daemon jobs check */
    pb_progress("daemon: warm-up jobs");
    if (ref_run(&rp, 1, &tmp)) goto out;
    ref.particles = tmp.particles;
    ref.nodes = tmp.nodes;
    double cap = 120.0 + 40.0 * tmp.wall_s * (double)steps / (double)tmp.steps;
    for (int w = 0; w < 2; w++) {
        if (start_daemon(&d[w], bin, threads)) goto out;
        if (run_job(&d[w], cs.bytes[w][1], cs.len[w][1], w, 1, ref.particles, cap, &warm, err,
                    sizeof err)) {
            fprintf(stderr, "mpmbench: %s (warm-up job): %s\n", row_name[w], err);
            log_tail(&d[w], 20);
            goto out;
        }
    }
    /* interleaved, so that a change in the machine's load hits all three */
    for (int i = 0; i < PB_RUNS; i++) {
        pb_progress("daemon: in-process job %d of %d", i + 1, PB_RUNS);
        if (ref_run(&rp, 0, &tmp)) goto out;
        ref_wall[i] = tmp.wall_s;
        ref_build[i] = tmp.setup_s;
        ref_cpu[i] = tmp.cpus;
        for (int w = 0; w < 2; w++) {
            pb_progress("daemon: %s job %d of %d", row_name[w], i + 1, PB_RUNS);
            if (run_job(&d[w], cs.bytes[w][0], cs.len[w][0], w, 0, ref.particles, cap, &jr[w][i],
                        err, sizeof err)) {
                fprintf(stderr, "mpmbench: %s: %s\n", row_name[w], err);
                log_tail(&d[w], 20);
                goto out;
            }
            dm_wall[w][i] = jr[w][i].wall;
            worker[w][i] = jr[w][i].worker_wall;
            dm_cpu[w][i] = jr[w][i].cpu;
        }
    }
    rc = 0;
out:
    ref_stop(&rp);
    for (int w = 0; w < 2; w++) {
        if (d[w].pid > 0 && stop_daemon(&d[w]) && !rc) {
            log_tail(&d[w], 20);
            rc = -1;
        }
        close_zmq(&d[w]);
        if (d[w].dir[0]) remove_dir(d[w].dir, 0);
    }
    cases_free(&cs);
    if (rc) return rc;

    ref.steps = steps;
    fill_row(&ref, ref_wall, ref_cpu, rp.rss_kb);
    ref.setup_s = pb_median(ref_build, PB_RUNS);
    pb_emit(&ref);
    for (int w = 0; w < 2; w++) {
        rows[w] = ref;
        snprintf(rows[w].scene, sizeof rows[w].scene, "%s", row_name[w]);
        fill_row(&rows[w], dm_wall[w], dm_cpu[w], d[w].rss_kb);
        totals(jr[w], &sum[w]);
        pb_emit(&rows[w]);
    }
    double qa = rows[0].wall_s / ref.wall_s, qb = rows[1].wall_s / ref.wall_s;
    double wa = pb_median(worker[0], PB_RUNS), wb = pb_median(worker[1], PB_RUNS);
    pb_note("daemon: jobs interleaved (in-process, no watcher, watcher) x %d; medians:", PB_RUNS);
    pb_note("daemon: in-process %.3f s per job (mpm_sim_new %.3f s + %ld steps), %d thread%s, "
            "%zu particles",
            ref.wall_s, ref.setup_s, steps, threads, threads > 1 ? "s" : "", ref.particles);
    pb_note("daemon: no watcher: client %.3f s = worker loop %.3f s (Finished.wallS) + %.3f s "
            "submit/queue/stream",
            rows[0].wall_s, wa, rows[0].wall_s - wa);
    pb_note("daemon: watcher:    client %.3f s = worker loop %.3f s + %.3f s; received %ld "
            "energies, %ld snapshots (expected %ld, %ld), %ld stream messages lost%s",
            rows[1].wall_s, wb, rows[1].wall_s - wb, sum[1].energies, sum[1].snapshots,
            (steps + 1) * PB_RUNS, steps / SNAPSHOT_EVERY * PB_RUNS, sum[1].lost,
            sum[1].snap_bad ? " (some snapshots had the wrong size!)" : "");
    if (steps < SNAPSHOT_EVERY)
        pb_note("daemon: note: %ld steps take no snapshot (one every %d steps)", steps,
                SNAPSHOT_EVERY);
    pb_result("daemon, no watcher: %.3fx in-process wall (overhead %+.1f%%, target <= 5%%): %s", qa,
              100 * (qa - 1), qa <= 1.05 ? "ok" : "MISSED");
    pb_result("daemon, watcher (energies every step, snapshots every %d): %.3fx in-process wall "
              "(overhead %+.1f%%, target <= 10%%): %s",
              SNAPSHOT_EVERY, qb, 100 * (qb - 1), qb <= 1.10 ? "ok" : "MISSED");
    return 0;
}

#endif
