/*
 * t_stress_extremes.c - the extreme cases of the stability stress suite
 * (t_stress.c has the CFL sweep, the long runs and the cell crossing); the
 * same rule: every case ends within tolerance or with a failure the solver
 * or the daemon recorded with a clear reason, never a crash, a hang or a
 * NaN.
 * How it works: the notes after the includes.
 */
#include "mpm.h"
#include "mpp_msg.h"
#include "t.h"
#include "t_daemon.h"
#include "t_stress.h"

#include <errno.h>
#include <fcntl.h>
#include <jansson.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <zmq.h>

/*
 *  stress_extremes         E 1e-3..1e9, nu 0.499, density contrast 1e3,
 *                          1..6 ppc, a one-particle-thick plate, impact near
 *                          the wave speed, a body thrown out of the grid;
 *                          automatic dt; cases written as JSON and loaded by
 *                          the daemon's own codec, run in-process with the
 *                          daemon's stop rule.
 *  stress_daemon_extremes  the same cases submitted to a real mpmd (MPMD_BIN)
 *                          over ZeroMQ: each run's status and reason in the
 *                          run records match the in-process outcome, the
 *                          refusal of cfl > 1 comes back as INVALID_CASE,
 *                          and the daemon answers Ping and exits cleanly.
 *
 *
 * `make test` runs the quick form; `make stress` (MPM_STRESS=full) the
 * whole set.
 */

/* ---- extreme cases, written as JSON ---- */

typedef struct {
    char name[48];
    char *json; /* malloc'd case */
    int expect; /* X_FINISH, X_EITHER or X_LEAVE */
    double tol; /* a finished run's energy may not exceed (1 + tol) E0 */
} xcase;

enum {
    X_FINISH = 0, /* must finish within tolerance */
    X_LEAVE = 1,  /* must fail: a particle leaves the grid */
    X_EITHER = 2  /* finish within tolerance, or a recorded failure */
};

/* Energy tolerances of a finished run: the paper's disks at C = 0.5 on
 * h = 0.05 gain up to 4% with MPM + USF (the scheme's error at that
 * resolution, measured); the harsh cases (1 ppc, nu = 0.499, a one-point
 * plate, near-sonic impact) up to 29%.  Above these it is a blow-up. */
#define TOL_STD 0.05
#define TOL_HARSH 0.5

typedef struct {
    int rc; /* 0 finished, else MPM_E* (or 1: the step limit) */
    long steps;
    double t, e0, emax, eend, pmax;
    char msg[512];
} xout;

#define X_MAX_STEPS 400000

static char *xjson(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
static char *xjson(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    char *s = n >= 0 ? malloc((size_t)n + 1) : NULL;
    if (!s) return NULL;
    va_start(ap, fmt);
    vsnprintf(s, (size_t)n + 1, fmt, ap);
    va_end(ap);
    return s;
}

/* Two disks of radius 0.14 on the unit square (h = 0.05), moving towards
 * each other along the diagonal at speed v each. */
static char *disks_json(const char *method, const char *update, double E, double nu, double rho2,
                        double v, int ppc, double tend)
{
    double s = v / sqrt(2.0);
    return xjson(
        "{\"name\":\"stress\",\"grid\":{\"dim\":2,\"origin\":[0,0],\"spacing\":[0.05,0.05],"
        "\"nodes\":[21,21]},\"method\":\"%s\",\"update\":\"%s\","
        "\"materials\":[{\"youngsModulus\":%.17g,\"poissonRatio\":%.17g,\"density\":1},"
        "{\"youngsModulus\":%.17g,\"poissonRatio\":%.17g,\"density\":%.17g}],"
        "\"bodies\":[{\"material\":0,\"velocity\":[%.17g,%.17g],\"sphere\":{\"center\":"
        "[0.25,0.25],\"radius\":0.14},\"ppc\":%d},{\"material\":1,\"velocity\":[%.17g,%.17g],"
        "\"sphere\":{\"center\":[0.75,0.75],\"radius\":0.14},\"ppc\":%d}],"
        "\"endTime\":%.17g,\"output\":{\"energyEvery\":50}}",
        method, update, E, nu, E, nu, rho2, s, s, ppc, -s, -s, ppc, tend);
}

static int add_case(xcase *xs, int *n, int max, const char *name, char *json, int expect,
                    double tol)
{
    if (!json || *n >= max) {
        free(json);
        return -1;
    }
    snprintf(xs[*n].name, sizeof xs[*n].name, "%s", name);
    xs[*n].json = json;
    xs[*n].expect = expect;
    xs[*n].tol = tol;
    (*n)++;
    return 0;
}

static void free_cases(xcase *xs, int n)
{
    for (int i = 0; i < n; i++) free(xs[i].json);
}

/* The extreme cases for one method and update.  Returns the count, or -1
 * when out of memory (cases made so far are in xs). */
static int extreme_cases(xcase *xs, int max, const char *me, const char *up, int full)
{
    int n = 0, err = 0;
    /* the wave speed at E = 1, nu = 0.2 (plane strain) */
    double c1 = sqrt(1.0 * 0.8 / (1.2 * 0.6));
    static const double Es_full[] = {1e-3, 1e-1, 1, 1e3, 1e6, 1e9}, Es_quick[] = {1e-3, 1, 1e9};
    const double *Es = full ? Es_full : Es_quick;
    int nE = full ? 6 : 3;
    char name[48];
    /* E from 1e-3 to 1e9 at a fixed Mach number (v = 0.1 c / c1) and a
     * scaled end time: the same problem in other units, so the relative
     * energy error must not depend on E */
    for (int i = 0; i < nE; i++) {
        double c = c1 * sqrt(Es[i]);
        snprintf(name, sizeof name, "E=%g (Mach fixed)", Es[i]);
        err |= add_case(xs, &n, max, name,
                        disks_json(me, up, Es[i], 0.2, 1, 0.1 * c / c1, 2, 4 * c1 / c), X_FINISH,
                        TOL_STD);
    }
    /* E = 1e-3 at the paper's speed 0.1: Mach 3 */
    err |= add_case(xs, &n, max, "E=1e-3 v=0.1 (Mach 3)",
                    disks_json(me, up, 1e-3, 0.2, 1, 0.1, 2, 4), X_EITHER, TOL_HARSH);
    err |= add_case(xs, &n, max, "nu=0.499", disks_json(me, up, 1, 0.499, 1, 0.1, 2, 4), X_FINISH,
                    TOL_HARSH);
    err |= add_case(xs, &n, max, "density 1:1000", disks_json(me, up, 1, 0.2, 1000, 0.1, 2, 4),
                    X_FINISH, TOL_STD);
    for (int ppc = 1; ppc <= 6; ppc++) {
        if (!full && ppc != 1 && ppc != 6) continue;
        snprintf(name, sizeof name, "ppc=%d", ppc);
        err |= add_case(xs, &n, max, name, disks_json(me, up, 1, 0.2, 1, 0.1, ppc, 4), X_FINISH,
                        ppc == 1 ? TOL_HARSH : TOL_STD);
    }
    err |= add_case(xs, &n, max, "impact 0.9c each",
                    disks_json(me, up, 1, 0.2, 1, 0.9 * c1, 2, 1.0), X_EITHER, TOL_HARSH);
    /* a plate one particle thick dropping at 0.5 onto a frictionless floor */
    err |= add_case(xs, &n, max, "one-particle-thick plate",
                    xjson("{\"grid\":{\"dim\":2,\"spacing\":[0.05,0.05],\"nodes\":[21,21]},"
                          "\"method\":\"%s\",\"update\":\"%s\",\"materials\":[{\"youngsModulus\":1,"
                          "\"poissonRatio\":0.3,\"density\":1}],\"bodies\":[{\"velocity\":[0,-0.5],"
                          "\"box\":{\"lo\":[0.2,0.3],\"hi\":[0.8,0.35]},\"ppc\":1}],"
                          "\"boundary\":{\"yLo\":2},\"endTime\":2,\"output\":{\"energyEvery\":50}}",
                          me, up),
                    X_EITHER, TOL_HARSH);
    /* a block thrown out of a grid without walls */
    err |= add_case(xs, &n, max, "thrown out of the grid",
                    xjson("{\"grid\":{\"dim\":2,\"spacing\":[0.05,0.05],\"nodes\":[21,21]},"
                          "\"method\":\"%s\",\"update\":\"%s\",\"materials\":[{\"youngsModulus\":1,"
                          "\"poissonRatio\":0.3,\"density\":1}],\"bodies\":[{\"velocity\":[2,0.5],"
                          "\"box\":{\"lo\":[0.3,0.3],\"hi\":[0.5,0.5]},\"ppc\":2}],\"endTime\":2,"
                          "\"output\":{\"energyEvery\":50}}",
                          me, up),
                    X_LEAVE, 0);
    if (err) {
        free_cases(xs, n);
        return -1;
    }
    return n;
}

/* Runs a case the way the daemon's worker does (srv_job.c): stop when
 * t >= end_time - dt/2 (or after `steps`), fail at a step limit. */
static int run_case(const char *json, xout *o)
{
    memset(o, 0, sizeof *o);
    mpp_case *sc = NULL;
    char err[512];
    int rc = td_case_load(json, strlen(json), &sc, err, sizeof err);
    if (rc) {
        snprintf(o->msg, sizeof o->msg, "%s", err);
        return rc;
    }
    mpm_error me;
    mpm_sim *s = mpm_sim_new(&sc->c, &sc->info, &me);
    if (!s) {
        snprintf(o->msg, sizeof o->msg, "%s", TERR(&me));
        mpp_case_destroy(&sc);
        return -1;
    }
    mpm_energy e;
    mpm_sim_energy(s, &e);
    o->e0 = o->emax = o->eend = e.total;
    for (;;) {
        long k = mpm_sim_steps(s);
        if (sc->has_end_time ? mpm_sim_time(s) >= sc->end_time - 0.5 * mpm_sim_dt(s)
                             : k >= (long)sc->steps)
            break;
        if (k >= X_MAX_STEPS) {
            o->rc = 1;
            snprintf(o->msg, sizeof o->msg, "step limit %d of this server reached (--max-steps)",
                     X_MAX_STEPS);
            break;
        }
        if ((o->rc = mpm_sim_step(s))) {
            snprintf(o->msg, sizeof o->msg, "%s", TERR(mpm_sim_error(s)));
            break;
        }
        if ((k + 1) % 10 == 0) {
            mpm_sim_energy(s, &e);
            o->emax = fmax(o->emax, e.total);
            o->eend = e.total;
            o->pmax = fmax(o->pmax, fabs(e.momentum[0] + e.momentum[1]));
        }
    }
    if (!o->rc && (o->rc = mpm_sim_check(s)))
        snprintf(o->msg, sizeof o->msg, "%s", TERR(mpm_sim_error(s)));
    if (!o->rc) {
        mpm_sim_energy(s, &e);
        o->emax = fmax(o->emax, e.total);
        o->eend = e.total;
    }
    o->steps = mpm_sim_steps(s);
    o->t = mpm_sim_time(s);
    mpm_sim_destroy(&s);
    mpp_case_destroy(&sc);
    return 0;
}

/* The verdict on an outcome: NULL when it is one the case allows. */
static const char *judge(const xcase *x, const xout *o)
{
    static char why[160];
    if (o->rc == 0) {
        if (x->expect == X_LEAVE) return "finished, but the body should have left the grid";
        if (!isfinite(o->eend) || !isfinite(o->emax)) return "finished with a non-finite energy";
        if (o->emax > o->e0 * (1 + x->tol)) {
            snprintf(why, sizeof why,
                     "finished, but the total energy grew by %.3g%% (tolerance "
                     "%g%%)",
                     100 * (o->emax / o->e0 - 1), 100 * x->tol);
            return why;
        }
        return NULL;
    }
    if (x->expect == X_FINISH) return "failed, but it should finish";
    if (x->expect == X_LEAVE && o->rc != MPM_ELEFTGRID) return "should fail by leaving the grid";
    if (o->rc == MPM_ELEFTGRID && !strstr(o->msg, "left the grid at step")) return "unclear reason";
    if (o->rc == MPM_EDIVERGED && !strstr(o->msg, "diverged at step")) return "unclear reason";
    if (o->rc == 1 && !strstr(o->msg, "step limit")) return "unclear reason";
    return NULL;
}

TEST(stress_extremes)
{
    int full = t_stress_full();
    static const char *const me[] = {"MPM", "GIMP"}, *const up[] = {"USF", "USL", "MUSL"};
    TLOG("automatic dt (C = 0.5), two disks (h = 0.05) unless said; E: max over the run and "
         "end of E/E0 - 1; a finish must keep E <= (1 + tol) E0, tol %g (standard) or %g (harsh: "
         "Mach 3, nu 0.499, 1 ppc, plate, impact); MPM + USL is run in full mode and reported, "
         "not asserted (docs/features.md: unstable)",
         TOL_STD, TOL_HARSH);
    double ref_scaled = NAN;
    char first_bad[2048] = "";
    for (int m = 0; m < 2; m++)
        for (int u = 0; u < 3; u++) {
            /* quick: MPM + USF (the cheapest) and GIMP + MUSL (the daemon's defaults) */
            if (!full && !((m == 0 && u == 0) || (m == 1 && u == 2))) continue;
            xcase xs[24];
            int n = extreme_cases(xs, 24, me[m], up[u], full);
            CHECKF(n > 0, "out of memory");
            TLOG("%s %s:", me[m], up[u]);
            ref_scaled = NAN;
            for (int i = 0; i < n; i++) {
                xout o;
                int rc = run_case(xs[i].json, &o);
                if (rc) {
                    free_cases(xs, n);
                    CHECKF(0, "%s: the case did not load: %s", xs[i].name, o.msg);
                }
                /* MPM + USL (docs/features.md: unstable when material enters new
                 * cells) may fail, and its silent blow-ups are reported,
                 * not asserted */
                int known = m == 0 && u == 1;
                if (known && xs[i].expect == X_FINISH) xs[i].expect = X_EITHER;
                const char *bad = judge(&xs[i], &o);
                TLOG("  %-26s %7ld steps t=%-9.4g %s E max %+.2e end %+.2e%s%.150s", xs[i].name,
                     o.steps, o.t, o.rc ? "FAILED" : "ok    ", o.emax / o.e0 - 1, o.eend / o.e0 - 1,
                     o.rc ? ": " : "", o.msg);
                if (bad && known) {
                    TLOG("    ^ KNOWN ISSUE (MPM + USL, not asserted): %s", bad);
                    bad = NULL;
                }
                if (bad && !first_bad[0])
                    snprintf(first_bad, sizeof first_bad, "%s %s %.47s: %.300s (%.200s)", me[m],
                             up[u], xs[i].name, bad, o.msg);
                /* the Mach-fixed family is one problem in other units */
                if (strstr(xs[i].name, "(Mach fixed)") && o.rc == 0) {
                    double rel = (o.eend - o.e0) / o.e0;
                    if (isnan(ref_scaled)) ref_scaled = rel;
                    if (!(fabs(rel - ref_scaled) <= 1e-6 * fmax(fabs(ref_scaled), 1e-3))) {
                        free_cases(xs, n);
                        CHECKF(0, "%s: relative energy change %.9g differs from E=1e-3's %.9g",
                               xs[i].name, rel, ref_scaled);
                    }
                }
            }
            free_cases(xs, n);
        }
    CHECKF(!first_bad[0], "%s", first_bad);
}

/* ---- the same through a real daemon ---- */

/* One request (JSON) -> reply (jansson object, NULL if none in time). */
static json_t *request(void *zctx, const char *ep, const char *req, double timeout)
{
    uint8_t *buf = NULL;
    size_t len = 0;
    char err[256];
    if (td_msg_json_to_bytes(MPP_MSG_REQUEST, req, strlen(req), &buf, &len, err, sizeof err)) {
        printf("    request not encodable: %s\n", err);
        return NULL;
    }
    void *sock = zmq_socket(zctx, ZMQ_DEALER);
    int zero = 0;
    json_t *out = NULL;
    if (!sock) {
        free(buf);
        return NULL;
    }
    zmq_setsockopt(sock, ZMQ_LINGER, &zero, sizeof zero);
    if (zmq_connect(sock, ep) == 0 && zmq_send(sock, "", 0, ZMQ_SNDMORE) == 0 &&
        zmq_send(sock, buf, len, 0) == (int)len) {
        zmq_pollitem_t it = {sock, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, (long)(timeout * 1000)) == 1) {
            zmq_msg_t part;
            zmq_msg_init(&part);
            if (zmq_msg_recv(&part, sock, 0) == 0 && zmq_msg_more(&part)) {
                zmq_msg_close(&part);
                zmq_msg_init(&part);
                if (zmq_msg_recv(&part, sock, 0) >= 0) {
                    char *js = NULL;
                    if (td_msg_bytes_to_json(MPP_MSG_REPLY, zmq_msg_data(&part),
                                             zmq_msg_size(&part), 0, 0, &js, err, sizeof err) == 0)
                        out = json_loads(js, 0, NULL);
                    free(js);
                }
            }
            zmq_msg_close(&part);
        }
    }
    zmq_close(sock);
    free(buf);
    return out;
}

static int ping(void *zctx, const char *ep)
{
    json_t *r = request(zctx, ep, "{\"schemaVersion\":1,\"ping\":{}}", 2.0);
    int ok = r && json_object_get(r, "pong");
    json_decref(r);
    return ok;
}

static long long json_id(const json_t *v)
{
    if (json_is_string(v)) return atoll(json_string_value(v));
    if (json_is_integer(v)) return json_integer_value(v);
    return -1;
}

typedef struct {
    xcase x;
    xout o;
    long long job, run;
} djob;

/* Fails the test with a message and jumps to `out` (so replies are freed). */
#define DFAIL(...)                               \
    do {                                         \
        t_fail(__FILE__, __LINE__, __VA_ARGS__); \
        goto out;                                \
    } while (0)

static void daemon_extremes(void *zctx, const td_daemon *d, djob *jobs, int nj)
{
    char req[256], *txt = NULL;
    json_t *r = NULL;
    /* submit every case */
    for (int i = 0; i < nj; i++) {
        char *sub = xjson("{\"schemaVersion\":1,\"submit\":{\"case\":%s}}", jobs[i].x.json);
        if (!sub) DFAIL("out of memory");
        r = request(zctx, d->ep, sub, 20);
        free(sub);
        json_t *ok = r ? json_object_get(r, "submitOk") : NULL;
        if (!ok) {
            txt = r ? json_dumps(r, 0) : NULL;
            DFAIL("%s: no SubmitOk: %s", jobs[i].x.name, txt ? txt : "no reply");
        }
        jobs[i].job = json_id(json_object_get(ok, "jobId"));
        jobs[i].run = json_id(json_object_get(ok, "runId"));
        json_decref(r);
        r = NULL;
    }
    /* wait for each to end, with the daemon answering throughout */
    for (int i = 0; i < nj; i++) {
        const char *st = NULL;
        for (double t0 = td_now(); td_now() - t0 < 180; td_msleep(50)) {
            json_decref(r);
            snprintf(req, sizeof req, "{\"schemaVersion\":1,\"status\":{\"jobId\":\"%lld\"}}",
                     jobs[i].job);
            r = request(zctx, d->ep, req, 10);
            if (!r) DFAIL("the daemon stopped answering Status (%s)", jobs[i].x.name);
            json_t *run = json_object_get(r, "run");
            st = run ? json_string_value(json_object_get(run, "status")) : NULL;
            if (st && strcmp(st, "QUEUED") && strcmp(st, "RUNNING")) break;
        }
        if (!st || !strcmp(st, "QUEUED") || !strcmp(st, "RUNNING"))
            DFAIL("%s: still %s after 180 s", jobs[i].x.name, st ? st : "?");
        json_decref(r);
        r = NULL;
    }
    /* the runs table (ListRuns reads the store) against the in-process outcome */
    r = request(zctx, d->ep, "{\"schemaVersion\":1,\"listRuns\":{\"limit\":100}}", 20);
    json_t *runs = r ? json_object_get(json_object_get(r, "runs"), "runs") : NULL;
    if (!runs || !json_is_array(runs)) {
        txt = r ? json_dumps(r, 0) : NULL;
        DFAIL("no run list: %s", txt ? txt : "no reply");
    }
    for (int i = 0; i < nj; i++) {
        json_t *found = NULL;
        for (size_t k = 0; k < json_array_size(runs); k++)
            if (json_id(json_object_get(json_array_get(runs, k), "runId")) == jobs[i].run)
                found = json_array_get(runs, k);
        if (!found) DFAIL("run %lld (%s) is not in the list", jobs[i].run, jobs[i].x.name);
        const char *st = json_string_value(json_object_get(found, "status"));
        const char *er = json_string_value(json_object_get(found, "error"));
        const char *want = jobs[i].o.rc ? "FAILED" : "FINISHED";
        long long steps = json_id(json_object_get(found, "steps"));
        TLOG("  run %2lld %-26s %-8s steps %7lld%s%.110s", jobs[i].run, jobs[i].x.name,
             st ? st : "?", steps, er ? ": " : "", er ? er : "");
        if (!st || strcmp(st, want))
            DFAIL("%s: status %s, in-process %s (%s)", jobs[i].x.name, st ? st : "?", want,
                  jobs[i].o.msg);
        if (jobs[i].o.rc && (!er || strcmp(er, jobs[i].o.msg)))
            DFAIL("%s: reason '%s', in-process '%s'", jobs[i].x.name, er ? er : "", jobs[i].o.msg);
        if (steps != jobs[i].o.steps)
            DFAIL("%s: %lld steps, in-process %ld", jobs[i].x.name, steps, jobs[i].o.steps);
        /* no NaN stored: the last energy sample is a finite number */
        json_t *le = json_object_get(found, "lastEnergy");
        json_t *tot = le ? json_object_get(le, "total") : NULL;
        if (!tot || !json_is_number(tot) || !isfinite(json_number_value(tot)))
            DFAIL("%s: the stored last energy is not a finite number", jobs[i].x.name);
    }
out:
    free(txt);
    json_decref(r);
}

DTEST(stress_daemon_extremes)
{
    const char *bin = getenv("MPMD_BIN");
    CHECKF(bin && access(bin, X_OK) == 0,
           "MPMD_BIN (%s) is not an executable mpmd; make test "
           "and make stress set it",
           bin ? bin : "unset");
    int full = t_stress_full();
    xcase xs[48];
    int n = extreme_cases(xs, 24, "MPM", "USF", full);
    CHECKF(n > 0, "out of memory");
    if (full) {
        int k = extreme_cases(xs + n, 24, "GIMP", "MUSL", full);
        if (k < 0) free_cases(xs, n);
        CHECKF(k > 0, "out of memory");
        n += k;
    }
    djob *jobs = calloc((size_t)n, sizeof *jobs);
    if (!jobs) free_cases(xs, n);
    CHECKF(jobs, "out of memory");
    for (int i = 0; i < n; i++) {
        jobs[i].x = xs[i];
        run_case(xs[i].json, &jobs[i].o);
    }
    void *zctx = zmq_ctx_new();
    td_daemon d = {0};
    static const char *const extra[] = {"--workers",    "2",           "--queue-max",
                                        "100",          "--max-steps", "400000",
                                        "--max-wall-s", "120",         NULL};
    int started = zctx && td_start(&d, t_tmpdir(), extra) == 0;
    if (started) {
        TLOG("mpmd %s; %d cases (MPM USF%s), 2 workers", d.ep, n, full ? "; GIMP MUSL" : "");
        daemon_extremes(zctx, &d, jobs, n);
        if (!t_failed()) {
            /* the refusal of cfl > 1 without allow_unstable_dt */
            json_t *r =
                request(zctx, d.ep,
                        "{\"schemaVersion\":1,\"submit\":{\"case\":{\"grid\":{\"dim\":1,"
                        "\"spacing\":[0.1],\"nodes\":[11]},\"cfl\":1.2,\"materials\":"
                        "[{\"youngsModulus\":1,\"density\":1}],\"bodies\":[{\"box\":{\"lo\":"
                        "[0.2],\"hi\":[0.8]}}],\"steps\":10}}}",
                        20);
            json_t *e = r ? json_object_get(r, "error") : NULL;
            const char *code = e ? json_string_value(json_object_get(e, "code")) : NULL;
            const char *msg = e ? json_string_value(json_object_get(e, "message")) : NULL;
            const char *field = e ? json_string_value(json_object_get(e, "field")) : NULL;
            TLOG("  cfl 1.2 refused: %s, field '%s': %s", code ? code : "?", field ? field : "",
                 msg ? msg : "");
            int refused = code && !strcmp(code, "INVALID_CASE") && msg && strstr(msg, "cfl") &&
                          field && !strcmp(field, "cfl");
            json_decref(r);
            if (!refused) t_fail(__FILE__, __LINE__, "cfl 1.2 was not refused as INVALID_CASE/cfl");
        }
        int alive = ping(zctx, d.ep);
        int st = td_stop(&d);
        if (!alive) t_fail(__FILE__, __LINE__, "the daemon does not answer Ping after the cases");
        if (st != 0)
            t_fail(__FILE__, __LINE__, "mpmd exited with %d on SIGTERM", st);
        else
            TLOG("  the daemon answered Ping after them and exited 0 on SIGTERM");
    } else {
        t_fail(__FILE__, __LINE__, "mpmd did not start");
    }
    if (zctx) zmq_ctx_term(zctx);
    free_cases(xs, n);
    free(jobs);
}
