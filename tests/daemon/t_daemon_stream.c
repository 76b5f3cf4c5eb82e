/*
 * t_daemon_stream.c - a real mpmd's streams and request order: snapshots
 * streamed to a watcher equal the in-process solver's, and one client's
 * pipelined requests are answered in the order asked while reads wait for
 * their run's commit off the event loop.
 */
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <stdlib.h>
#include <string.h>
#include <zmq.h>

#include "mpm.h"

/* gcc 12's -fanalyzer reports a double free of x at the single free(x)
 * below, with its "first free" at the declaration: a false path through
 * the CHECK() early returns that it took only once this test moved out of
 * t_daemon.c (x is malloc'd once and freed once, at out:).  ASan runs this
 * test in make test and would catch a real double free. */
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wanalyzer-double-free"
DTEST(daemon_stream_snapshots)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", "--verbose", NULL};
    char dir[300], longp[400], path[400], sep[420], topic[32], err[ERRLEN], st[32];
    td_daemon d;
    td_out o;
    void *zctx = NULL, *sub = NULL;
    mpp_case *sc = NULL;
    mpm_sim *sim = NULL;
    double *x = NULL, *v = NULL;
    /* a receive queue of one message: what the watcher has not read stays
     * queued in mpmd (its XPUB keeps up to 10000 messages per watcher) */
    int hwm = 1, linger = 0, rc = -1;
    enum { STEPS = 120, SNAP_EVERY = 20 };

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    /* job 1 keeps the one worker busy while job 2 waits, watched */
    CHECK(write_case(long_case(5000), dir, "long.json", longp, sizeof longp) == 0);
    json_t *c = block2d(STEPS, 1, "snapshots");
    CHECK(c);
    /* 25600 particles: h = 0.005 */
    json_object_set_new(json_object_get(c, "grid"), "spacing", json_pack("[f,f]", 0.005, 0.005));
    json_object_set_new(json_object_get(c, "grid"), "nodes", json_pack("[i,i]", 201, 201));
    set_output(c, "snapshotEvery", json_integer(SNAP_EVERY));
    set_output(c, "snapshotFields", json_pack("[s,s]", "X", "V"));
    CHECK(write_case(c, dir, "snap.json", path, sizeof path) == 0);
    for (unsigned long long i = 1; i <= 2; i++) {
        CHECK(td_ctl(&d, 30, &o, "submit", i == 1 ? longp : path, NULL) == 0);
        CHECKF(o.status == 0 && job_of(o.out) == i, "submit %llu: %s%s", i, o.out, o.err);
        td_out_free(&o);
    }
    CHECK(td_wait_status(&d, 1, "RUNNING", 20, st, sizeof st) == 0);

    snprintf(sep, sizeof sep, "%s.stream", d.ep);
    snprintf(topic, sizeof topic, "job:%016llx:", 2ULL);
    zctx = zmq_ctx_new();
    CHECK(zctx);
    sub = zmq_socket(zctx, ZMQ_SUB);
    if (!sub || zmq_setsockopt(sub, ZMQ_LINGER, &linger, sizeof linger) ||
        zmq_setsockopt(sub, ZMQ_RCVHWM, &hwm, sizeof hwm) ||
        zmq_setsockopt(sub, ZMQ_SUBSCRIBE, topic, strlen(topic)) || zmq_connect(sub, sep)) {
        t_fail(__FILE__, __LINE__, "SUB on %s: %s", sep, zmq_strerror(errno));
        goto out;
    }
    if (wait_watched(&d, 2, 20)) {
        t_fail(__FILE__, __LINE__, "job 2 never watched");
        goto out;
    }
    if (td_ctl(&d, 30, &o, "cancel", "1", NULL)) {
        t_fail(__FILE__, __LINE__, "mpmctl cancel 1 failed");
        goto out;
    }
    td_out_free(&o);
    if (td_wait_status(&d, 2, "FINISHED|FAILED|CANCELLED|INTERRUPTED", 120, st, sizeof st) ||
        strcmp(st, "FINISHED")) {
        t_fail(__FILE__, __LINE__, "job 2: %s", st);
        goto out;
    }

    /* the same case in-process, stepped along with the snapshots */
    {
        size_t len = 0;
        char *text = td_slurp(path, &len);
        int lrc = text ? td_case_load(text, len, &sc, err, sizeof err) : -1;
        free(text);
        mpm_error me = {0};
        if (lrc || !(sim = mpm_sim_new(&sc->c, &sc->info, &me))) {
            t_fail(__FILE__, __LINE__, "in-process case: %s", lrc ? err : TERR(&me));
            goto out;
        }
    }
    size_t np = mpm_sim_particles(sim);
    x = malloc(4 * np * sizeof *x); /* x, then v, in one block */
    v = x ? x + 2 * np : NULL;
    if (!x) {
        t_fail(__FILE__, __LINE__, "out of memory");
        goto out;
    }

    uint64_t next_seq = 0, next_sample = 0;
    long snaps = 0;
    double worst = 0, end = td_now() + 120;
    int finished = 0;
    while (!finished) {
        zmq_pollitem_t it = {sub, 0, ZMQ_POLLIN, 0};
        if (td_now() > end) {
            t_fail(__FILE__, __LINE__, "no Finished within 120 s (seq %llu)",
                   (unsigned long long)next_seq);
            goto out;
        }
        if (zmq_poll(&it, 1, 200) <= 0) continue;
        zmq_msg_t part[2];
        int nparts = td_recv_parts(sub, part, 2);
        mpp_stream si = {0};
        mpm_error pe;
        int prc = nparts == 2 ? mpp_stream_decode(zmq_msg_data(&part[1]), zmq_msg_size(&part[1]), 0,
                                                  &si, &pe)
                              : -1;
        if (nparts == 2 && prc) mpm_error_text(&pe, MPM_FIELD_JSON, err, sizeof err);
        int ok = prc == 0 && si.job_id == 2 && si.seq == next_seq;
        if (ok && si.kind == MPP_STREAM_ENERGY) {
            ok = si.energy.seq == next_sample && si.energy.step == (int64_t)next_sample;
            next_sample++;
        } else if (ok && si.kind == MPP_STREAM_SNAPSHOT) {
            const mpp_snapshot *s = &si.snapshot;
            /* the decoder checked that x and v hold n*dim values each */
            ok = s->n == np && s->dim == 2 && s->x && s->v && !s->stress && !s->pressure &&
                 !s->volume && s->step == (int64_t)snaps * SNAP_EVERY; /* step 0 first */
            /* its values, decoded once, against the solver */
            if (ok) {
                while (mpm_sim_steps(sim) < s->step) ok = ok && mpm_sim_step(sim) == 0;
                mpm_sim_snapshot(sim, &(mpm_snapshot){.x = x, .v = v});
                for (size_t i = 0; ok && i < 2 * np; i++)
                    worst = fmax(worst, fmax(rel_diff(s->x[i], x[i]), rel_diff(s->v[i], v[i])));
            }
            snaps++;
        } else if (ok && si.kind == MPP_STREAM_FINISHED) {
            ok = si.finished.status == MPP_STATUS_FINISHED && si.finished.steps == STEPS &&
                 si.has_energy && si.energy.seq == STEPS && next_sample == STEPS + 1;
            finished = 1;
        }
        uint64_t got_seq = si.seq;
        int got_kind = (int)si.kind;
        mpp_stream_clear(&si);
        for (int i = 0; i < nparts; i++) zmq_msg_close(&part[i]);
        if (!ok) {
            t_fail(__FILE__, __LINE__,
                   "stream message seq %llu (expected %llu), kind %d, peek %d "
                   "%s, samples %llu, snapshots %ld",
                   (unsigned long long)got_seq, (unsigned long long)next_seq, got_kind, prc,
                   prc ? err : "", (unsigned long long)next_sample, snaps);
            goto out;
        }
        next_seq++;
    }
    TLOG("job 2: %llu stream messages, %llu energy samples, %ld snapshots of %zu particles; "
         "snapshots vs in-process: max relative difference %.3g",
         (unsigned long long)next_seq, (unsigned long long)next_sample, snaps, np, worst);
    if (snaps != STEPS / SNAP_EVERY + 1 || worst > 1e-12) {
        t_fail(__FILE__, __LINE__, "%ld snapshots, max difference %.3g", snaps, worst);
        goto out;
    }
    rc = 0;
out:
    free(x); /* v lies in the same block */
    mpm_sim_destroy(&sim);
    mpp_case_destroy(&sc);
    if (sub) zmq_close(sub);
    if (zctx) zmq_ctx_term(zctx);
    if (!rc) CHECKF(td_stop(&d) == 0, "mpmd did not exit 0 on SIGTERM");
}

/* ---- one client's pipelined requests ------------------------------------------- */

#pragma GCC diagnostic pop

/* A client that sends several requests without waiting (a DEALER) gets its
 * replies in the order it asked, while reads wait for their run's writes
 * off the event loop: each energy page it gets is a gap-free prefix of the
 * run's series that includes every sample written before it asked, and a
 * Ping between two reads is answered in its place. */
DTEST(daemon_pipelined_reads_keep_order)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--solver-threads", "1", NULL};
    char dir[300], path[400];
    td_daemon d;
    td_out o;
    void *ctx = NULL, *s = NULL;
    int zero = 0;
    static const char *const want[] = {"energy", "pong", "run", "energy", "runs", "version", "run"};
    enum { NREQ = 7 };
    json_t *rep[NREQ] = {0};

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(long_case(1000), dir, "long.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    CHECK(o.status == 0 && job_of(o.out) == 1);
    td_out_free(&o);
    CHECK(td_wait_steps(&d, 1, 20000, 30) == 0);

    ctx = zmq_ctx_new();
    CHECK(ctx);
    s = zmq_socket(ctx, ZMQ_DEALER);
    if (!s || zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) || zmq_connect(s, d.ep)) {
        if (s) zmq_close(s);
        zmq_ctx_term(ctx);
        CHECK(!"DEALER connect");
    }
    mpp_request rq[NREQ];
    memset(rq, 0, sizeof rq);
    rq[0].kind = MPP_REQ_GET_ENERGY, rq[0].id = 1;
    rq[1].kind = MPP_REQ_PING;
    rq[2].kind = MPP_REQ_STATUS, rq[2].id = 1;
    rq[3].kind = MPP_REQ_GET_ENERGY, rq[3].id = 1;
    rq[4].kind = MPP_REQ_LIST_RUNS;
    rq[5].kind = MPP_REQ_VERSION;
    rq[6].kind = MPP_REQ_CANCEL, rq[6].id = 1;
    int sent = 1;
    for (int i = 0; i < NREQ && sent; i++) {
        uint8_t *buf = NULL;
        size_t len = 0;
        sent = mpp_request_encode(&rq[i], &buf, &len) == 0 &&
               zmq_send(s, "", 0, ZMQ_SNDMORE) == 0 && zmq_send(s, buf, len, 0) == (int)len;
        free(buf);
    }
    int got = 0;
    for (; sent && got < NREQ; got++) {
        zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
        if (zmq_poll(&it, 1, 20000) != 1) break;
        zmq_msg_t m[2];
        int np = td_recv_parts(s, m, 2);
        char *json = NULL, err[256];
        if (np == 2 && !td_msg_bytes_to_json(MPP_MSG_REPLY, zmq_msg_data(&m[1]),
                                             zmq_msg_size(&m[1]), 0, 0, &json, err, sizeof err))
            rep[got] = json_loads(json, 0, NULL);
        free(json);
        for (int k = 0; k < np; k++) zmq_msg_close(&m[k]);
        if (!rep[got]) break;
    }
    zmq_close(s);
    zmq_ctx_term(ctx);

    int in_order = got == NREQ;
    for (int i = 0; i < got && in_order; i++) in_order = json_object_get(rep[i], want[i]) != NULL;
    CHECKF(sent && in_order, "sent %d, %d replies in the asked order of %d", sent, got, NREQ);
    /* both energy pages: seq 0, 1, 2, ... with no gap; the later one no shorter */
    size_t n[2] = {0, 0};
    for (int k = 0; k < 2; k++) {
        json_t *smp = json_object_get(json_object_get(rep[k ? 3 : 0], "energy"), "samples");
        n[k] = json_array_size(smp);
        for (size_t i = 0; i < n[k]; i++)
            CHECKF(jint(json_array_get(smp, i), "seq") == (long long)i,
                   "page %d: sample %zu has seq %lld", k, i, jint(json_array_get(smp, i), "seq"));
    }
    /* the first page was read before the Status, the second after it */
    json_t *run = json_object_get(rep[2], "run");
    json_t *last0 = json_array_get(json_object_get(json_object_get(rep[0], "energy"), "samples"),
                                   n[0] ? n[0] - 1 : 0);
    CHECKF(n[0] >= 1 && n[1] >= n[0] && jint(last0, "step") <= jint(run, "steps") &&
               !strcmp(jstr(run, "status"), "RUNNING"),
           "pages of %zu and %zu samples (first ends at step %lld), Status %s at step %lld", n[0],
           n[1], jint(last0, "step"), jstr(run, "status"), jint(run, "steps"));
    TLOG("7 pipelined requests answered in order: pages of %zu and %zu samples around Status at "
         "step %lld",
         n[0], n[1], jint(run, "steps"));
    for (int i = 0; i < NREQ; i++) json_decref(rep[i]);
    char st[32];
    CHECK(td_wait_status(&d, 1, "CANCELLED", 10, st, sizeof st) == 0);
    CHECK(td_stop(&d) == 0);
}
