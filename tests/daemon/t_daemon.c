/*
 * t_daemon.c - integration tests of mpmd and mpmctl: real daemons on ipc://
 * endpoints in the test's temporary directory with a real SQLite file, the
 * real client run as a process, raw requests on a DEALER for what the
 * client refuses to send.  Scenarios: the client's command line offline; a
 * basic run watched live and compared number for number with the in-process
 * solver; two jobs at once and a full queue; cancel; late watchers that
 * must still get every energy sample once and in order; restart on the same
 * database (and the one-daemon lock); a hard kill mid-run.  Bad input is
 * in t_daemon_input.c, streams and request order in t_daemon_stream.c,
 * what a run's record carries (angular momentum, defaults, transfer) in
 * t_daemon_record.c, the shared helpers in t_daemon_util.c.  Cases are shortened
 * copies of proto/examples (read relative to the repository root) so the
 * file stays within about two minutes under the sanitizers.
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <zmq.h>

#include "mpm.h"

/* ---- the client alone --------------------------------------------------------- */

DTEST(daemon_cli_offline)
{
    const char *tmp = t_tmpdir();
    char dead[300], bad[300], envep[320];
    td_out o;
    if (!td_bin("MPMCTL_BIN")) return;
    snprintf(dead, sizeof dead, "ipc://%s/nobody", tmp);
    EXPECT_CTL(NULL, 0, "usage: mpmctl", "--help");
    EXPECT_CTL(NULL, 0, "usage: mpmctl watch", "watch", "--help");
    EXPECT_CTL(NULL, 2, "no command", "--timeout", "3");
    EXPECT_CTL(NULL, 2, "unknown command 'frobnicate'", "frobnicate");
    EXPECT_CTL(NULL, 2, "unknown option '--bogus'", "runs", "--bogus");
    EXPECT_CTL(NULL, 2, "option --limit needs a value", "runs", "--limit");
    EXPECT_CTL(NULL, 2, "--limit: expected a positive integer", "runs", "--limit", "abc");
    EXPECT_CTL(NULL, 2, "--status: 'BOGUS' is not one of", "runs", "--status", "BOGUS");
    EXPECT_CTL(NULL, 2, "option --csv does not apply to 'runs'", "runs", "--csv");
    EXPECT_CTL(NULL, 2, "--csv and --json exclude each other", "energy", "1", "--csv", "--json");
    EXPECT_CTL(NULL, 2, "'abc' is not a job id", "watch", "abc");
    EXPECT_CTL(NULL, 2, "watch needs a job id", "watch");
    EXPECT_CTL(NULL, 2, "unexpected argument '2'", "cancel", "1", "2");
    EXPECT_CTL(NULL, 2, "-o FILE is required", "snapshot", "1");
    EXPECT_CTL(NULL, 2, "--timeout: expected seconds", "--timeout", "0", "ping");
    EXPECT_CTL(NULL, 2, "option --watch takes no value", "submit", "x.json", "--watch=1");

    /* no daemon: a bounded wait and the message the issue asks for */
    {
        const char *a[] = {"--endpoint", dead, "--timeout", "1", "ping", NULL};
        char want[400];
        CHECK(td_ctlv(NULL, 30, &o, a) == 0);
        snprintf(want, sizeof want, "no reply from %s within 1 s (is mpmd running?)", dead);
        CHECKF(o.status == 1 && strstr(o.err, want), "exit %d, stderr %s", o.status, o.err);
        CHECK_LT(o.secs, 6);
        TLOG("dead endpoint: exit 1 after %.2f s: %s", o.secs, o.err);
        td_out_free(&o);
    }
    /* MPMD_ENDPOINT is the default endpoint */
    snprintf(envep, sizeof envep, "ipc://%s/from-env", tmp);
    setenv("MPMD_ENDPOINT", envep, 1);
    {
        const char *a[] = {"--timeout", "0.5", "runs", NULL};
        int rc = td_ctlv(NULL, 30, &o, a);
        unsetenv("MPMD_ENDPOINT");
        CHECK(rc == 0);
        CHECKF(o.status == 1 && strstr(o.err, envep), "exit %d, stderr %s", o.status, o.err);
        td_out_free(&o);
    }
    /* a bad case is reported locally with the field's path; nothing is sent
     * (the endpoint is dead, yet the answer is immediate and names the field) */
    snprintf(bad, sizeof bad, "%s/bad.json", tmp);
    CHECK(td_write(bad,
                   "{\"grid\": {\"dim\": 1, \"spacing\": [0.1], \"nodes\": [11]},"
                   " \"materials\": [{\"youngsModulus\": -1, \"density\": 1}],"
                   " \"bodies\": [{\"box\": {\"lo\": [0.2], \"hi\": [0.4]}}], \"endTime\": 1}") ==
          0);
    {
        const char *a[] = {"--endpoint", dead, "--timeout", "5", "submit", bad, NULL};
        CHECK(td_ctlv(NULL, 30, &o, a) == 0);
        CHECKF(o.status == 1 && strstr(o.err, "materials[0].youngsModulus: must be > 0 (got -1)") &&
                   !strstr(o.err, "no reply"),
               "exit %d, stderr %s", o.status, o.err);
        CHECK_LT(o.secs, 4);
        TLOG("local case check: %s", o.err);
        td_out_free(&o);
    }
    CHECK(
        td_write(
            bad,
            "{\"grid\": {\"dim\": 1, \"spacing\": [0.1], \"nodes\": [11]}, \"method\": \"FOO\"}") ==
        0);
    {
        const char *a[] = {"--endpoint", dead, "--timeout", "5", "submit", bad, NULL};
        CHECK(td_ctlv(NULL, 30, &o, a) == 0);
        CHECKF(o.status == 1 && strstr(o.err, "method: unknown value"), "exit %d, stderr %s",
               o.status, o.err);
        td_out_free(&o);
    }
    {
        const char *a[] = {"--endpoint", dead, "submit", "/nonexistent/case.json", NULL};
        CHECK(td_ctlv(NULL, 30, &o, a) == 0);
        CHECKF(o.status == 1 && strstr(o.err, "cannot read /nonexistent/case.json"),
               "exit %d, stderr %s", o.status, o.err);
        td_out_free(&o);
    }
}

/* ---- a basic run ---------------------------------------------------------------- */

DTEST(daemon_basic_run)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "2", "--solver-threads", "1", NULL};
    char dir[300], path[400], snap_csv[400], snap_json[400], err[ERRLEN], want[400];
    td_daemon d;
    td_out o, e;
    series s;
    json_t *c, *r;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;

    /* the paper's MPM bar, until t = 0.5, energies every 10 steps, snapshots recorded */
    c = example("bar1d_mpm");
    CHECK(c);
    json_object_set_new(c, "endTime", json_real(0.5));
    set_output(c, "snapshotEvery", json_integer(100));
    set_output(c, "recordSnapshots", json_true());
    set_output(c, "snapshotFields", json_pack("[s,s]", "X", "V"));
    CHECK(write_case(c, dir, "bar.json", path, sizeof path) == 0);

    CHECK(td_ctl(&d, 120, &o, "submit", path, "--watch", "--csv", NULL) == 0);
    CHECKF(o.status == 0, "submit --watch --csv: exit %d, stderr: %s", o.status, o.err);
    CHECKF(job_of(o.err) == 1 && strstr(o.err, "FINISHED"), "stderr: %s", o.err);
    CHECK(parse_csv(o.out, &s) == 0);
    TLOG("watched job 1: %zu samples, steps %lld..%lld, total %.17g -> %.17g", s.n, s.step[0],
         s.step[s.n - 1], s.total[0], s.total[s.n - 1]);
    CHECK(consecutive(&s));
    CHECK(s.n >= 51 && s.step[0] == 0 && s.step[s.n - 1] == 500);
    for (size_t i = 1; i < s.n; i++) CHECK(s.step[i] > s.step[i - 1]);

    /* the same numbers as the solver in-process, to 1e-12 */
    {
        size_t len = 0;
        char *text = td_slurp(path, &len);
        mpp_case *sc = NULL;
        mpm_sim *sim = NULL;
        double worst = 0, worst_t = 0;
        CHECK(text);
        CHECKF(td_case_load(text, len, &sc, err, sizeof err) == 0, "%s", err);
        free(text);
        mpm_error me;
        sim = mpm_sim_new(&sc->c, &sc->info, &me);
        CHECKF(sim, "%s", TERR(&me));
        for (size_t i = 0; i < s.n; i++) {
            mpm_energy en;
            while (mpm_sim_steps(sim) < s.step[i]) CHECK(mpm_sim_step(sim) == 0);
            mpm_sim_energy(sim, &en);
            worst = fmax(worst, rel_diff(en.total, s.total[i]));
            worst = fmax(worst, rel_diff(en.kinetic, s.kinetic[i]));
            worst_t = fmax(worst_t, rel_diff(mpm_sim_time(sim), s.t[i]));
        }
        TLOG("daemon vs in-process over %zu samples: max relative difference %.3g (energies), "
             "%.3g (t)",
             s.n, worst, worst_t);
        CHECK_LT(worst, 1e-12);
        CHECK_LT(worst_t, 1e-12);

        /* the stored snapshot at the last step: positions and velocities */
        CHECK(td_ctl(&d, 30, &e, "snapshot", "1", "-o",
                     (snprintf(snap_csv, sizeof snap_csv, "%s/snap.csv", dir), snap_csv),
                     NULL) == 0);
        CHECKF(e.status == 0, "snapshot: exit %d: %s", e.status, e.err);
        td_out_free(&e);
        {
            size_t sl = 0, np = mpm_sim_particles(sim);
            char *st = td_slurp(snap_csv, &sl), **lines = NULL;
            double x[16], v[16], dmax = 0;
            size_t nl = st ? td_lines(st, &lines) : 0;
            mpm_snapshot ms = {.x = x, .v = v};
            CHECK(np == 7);
            mpm_sim_snapshot(sim, &ms);
            CHECKF(nl == np + 1 && lines && !strcmp(lines[0], "i,x,vx"),
                   "snapshot CSV: %zu lines, header %s", nl, nl ? lines[0] : "");
            for (size_t i = 0; i < np; i++) {
                size_t k;
                double xi, vi;
                CHECK(sscanf(lines[i + 1], "%zu,%lf,%lf", &k, &xi, &vi) == 3 && k == i);
                dmax = fmax(dmax, fmax(rel_diff(xi, x[i]), rel_diff(vi, v[i])));
            }
            TLOG("snapshot at step 500 vs in-process: max relative difference %.3g", dmax);
            CHECK_LT(dmax, 1e-12);
            free(lines);
            free(st);
        }
        mpm_sim_destroy(&sim);
        mpp_case_destroy(&sc);
    }
    {
        json_t *sn;
        snprintf(snap_json, sizeof snap_json, "%s/snap100.json", dir);
        CHECK(td_ctl(&d, 30, &e, "snapshot", "1", "--step", "100", "-o", snap_json, NULL) == 0);
        CHECKF(e.status == 0, "snapshot --step 100: exit %d: %s", e.status, e.err);
        td_out_free(&e);
        sn = td_json_file(snap_json);
        CHECK(sn);
        CHECKF(jint(sn, "step") == 100 && jint(sn, "n") == 7 &&
                   json_array_size(json_object_get(sn, "x")) == 7 &&
                   json_array_size(json_object_get(sn, "v")) == 7 && !json_object_get(sn, "stress"),
               "snapshot JSON: step %lld, n %lld", jint(sn, "step"), jint(sn, "n"));
        json_decref(sn);
    }
    EXPECT_CTL(&d, 1, "NOT_FOUND", "snapshot", "1", "--step", "7", "-o", snap_json);
    for (int k = 0; k < 2; k++) {
        /* the run exists, the step does not (7, or -1, which is no step
         * rather than "the latest"): the field is the step */
        mpp_request rq = {.kind = MPP_REQ_GET_SNAPSHOT, .id = 1, .has_step = 1, .step = k ? -1 : 7};
        json_t *reply = NULL;
        CHECK(td_request(d.ep, &rq, 10, &reply) == 0);
        CHECKF(!strcmp(td_err_code(reply), "NOT_FOUND") && !strcmp(td_err_field(reply), "step"),
               "getSnapshot{runId: 1, step: %lld}: %s, field \"%s\"", (long long)rq.step,
               td_err_code(reply), td_err_field(reply));
        json_decref(reply);
    }
    {
        /* energies from a seq beyond the end (even past INT64_MAX): none */
        mpp_request rq = {.kind = MPP_REQ_GET_ENERGY, .id = 1, .from_seq = UINT64_MAX};
        json_t *reply = NULL, *en;
        CHECK(td_request(d.ep, &rq, 10, &reply) == 0);
        en = json_object_get(reply, "energy");
        CHECKF(en && json_array_size(json_object_get(en, "samples")) == 0 &&
                   !json_is_true(json_object_get(en, "more")),
               "getEnergy{runId: 1, fromSeq: 2^64-1}: %zu samples",
               json_array_size(json_object_get(en, "samples")));
        json_decref(reply);
    }
    {
        /* RunInfo carries the method and update (decoded reply, raw request) */
        mpp_request rq = {.kind = MPP_REQ_GET_RUN, .id = 1};
        json_t *reply = NULL, *run;
        CHECK(td_request(d.ep, &rq, 10, &reply) == 0);
        run = json_object_get(reply, "run");
        CHECKF(run && !strcmp(jstr(run, "method"), "MPM") && !strcmp(jstr(run, "update"), "USF"),
               "getRun 1: method \"%s\", update \"%s\" (want MPM, USF as bar1d_mpm.json says)",
               jstr(run, "method"), jstr(run, "update"));
        json_decref(reply);
    }

    /* energy --csv gives the very series the watcher printed */
    CHECK(td_ctl(&d, 30, &e, "energy", "1", "--csv", NULL) == 0);
    CHECKF(e.status == 0 && !strcmp(e.out, o.out),
           "energy --csv differs from the watched series "
           "(exit %d, %zu vs %zu bytes)",
           e.status, strlen(e.out), strlen(o.out));
    td_out_free(&e);
    CHECK(td_ctl(&d, 30, &e, "energy", "1", "--json", NULL) == 0);
    CHECK(e.status == 0 && count_lines(e.out) == s.n);
    {
        char *nl = strrchr(e.out, '\n');
        json_t *last;
        *nl = 0;
        nl = strrchr(e.out, '\n');
        last = parse_line(nl ? nl + 1 : e.out);
        CHECK(last);
        CHECKF(jnum(last, "total") == s.total[s.n - 1] && jint(last, "seq") == (long long)s.n - 1,
               "last JSON sample: total %.17g, seq %lld", jnum(last, "total"), jint(last, "seq"));
        json_decref(last);
    }
    td_out_free(&e);
    CHECK(td_ctl(&d, 30, &e, "energy", "1", NULL) == 0);
    CHECK(e.status == 0 && count_lines(e.out) == s.n + 1);
    td_out_free(&e);

    /* a watcher arriving after the end gets the whole series too */
    CHECK(td_ctl(&d, 60, &e, "watch", "1", "--csv", NULL) == 0);
    CHECKF(e.status == 0 && !strcmp(e.out, o.out),
           "late watch --csv: exit %d, %zu bytes, stderr %s", e.status, strlen(e.out), e.err);
    td_out_free(&e);
    CHECK(td_ctl(&d, 60, &e, "watch", "1", NULL) == 0);
    CHECKF(e.status == 0 && strstr(e.out, "FINISHED") && strstr(e.out, "energy drift"),
           "watch (text): exit %d, stdout %s", e.status, e.out);
    td_out_free(&e);

    /* the same case again with --watch --json: bitwise the same energies */
    CHECK(td_ctl(&d, 120, &e, "submit", path, "--watch", "--json", NULL) == 0);
    CHECKF(e.status == 0 && job_of(e.err) == 2, "submit --watch --json: exit %d, stderr %s",
           e.status, e.err);
    {
        char **lines = NULL;
        size_t nl = td_lines(e.out, &lines);
        int same = nl == s.n;
        for (size_t i = 0; same && i < nl; i++) {
            json_t *j = parse_line(lines[i]);
            same = j && jint(j, "seq") == (long long)i && jnum(j, "total") == s.total[i] &&
                   jint(j, "step") == s.step[i];
            json_decref(j);
        }
        free(lines);
        CHECKF(same, "job 2's JSON series (%zu lines) differs from job 1's (%zu samples)", nl, s.n);
    }
    td_out_free(&e);

    /* listings */
    CHECK(td_ctl(&d, 30, &e, "runs", "--json", NULL) == 0);
    CHECK(e.status == 0 && count_lines(e.out) == 2);
    {
        char **lines = NULL;
        size_t nl = td_lines(e.out, &lines);
        json_t *r0 = nl == 2 ? parse_line(lines[0]) : NULL,
               *r1 = nl == 2 ? parse_line(lines[1]) : NULL;
        free(lines);
        CHECKF(r0 && r1 && jint(r0, "runId") == 2 && jint(r1, "runId") == 1 &&
                   !strcmp(jstr(r0, "status"), "FINISHED") &&
                   !strcmp(jstr(r1, "status"), "FINISHED") &&
                   !strcmp(jstr(r1, "name"), "bar1d_mpm") && jint(r1, "particles") == 7,
               "runs --json: %s", e.out);
        json_decref(r0);
        json_decref(r1);
    }
    td_out_free(&e);
    CHECK(td_ctl(&d, 30, &e, "runs", NULL) == 0);
    CHECKF(e.status == 0 && strstr(e.out, "METHOD   UPDATE TRANSFER") &&
               strstr(e.out, "bar1d_mpm") && strstr(e.out, "FINISHED    MPM      USF    FLIP"),
           "runs: %s", e.out);
    TLOG("runs:\n%s", e.out);
    td_out_free(&e);
    CHECK(td_ctl(&d, 30, &e, "runs", "--status", "failed", "--json", NULL) == 0);
    CHECK(e.status == 0 && !e.out[0]);
    td_out_free(&e);
    CHECK(td_ctl(&d, 30, &e, "runs", "--limit", "1", "--json", NULL) == 0);
    CHECK(e.status == 0 && count_lines(e.out) == 1);
    td_out_free(&e);

    r = show_json(&d, 1);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "status"), "FINISHED") && jint(r, "steps") == 500 &&
               jint(r, "energySamples") == (long long)s.n && jint(r, "jobId") == 1 &&
               json_object_get(r, "finishedAt") && !json_object_get(r, "case"),
           "show 1 --json: status %s, steps %lld, samples %lld", jstr(r, "status"),
           jint(r, "steps"), jint(r, "energySamples"));
    /* the solver's plan, recorded when the run started (RunInfo.plan) */
    CHECKF(strstr(jstr(r, "plan"), "dim=1 shape=tent ns=2") && strstr(jstr(r, "plan"), "fuse="),
           "show 1 --json: plan '%s'", jstr(r, "plan"));
    {
        json_t *ss = json_object_get(r, "snapshotSteps");
        size_t ns = json_array_size(ss);
        json_t *last = ns ? json_array_get(ss, ns - 1) : NULL;
        long long ls = json_is_string(last)    ? atoll(json_string_value(last))
                       : json_is_integer(last) ? json_integer_value(last)
                                               : -1;
        CHECKF(ns >= 5 && ls == 500, "snapshotSteps: %zu entries, last %lld", ns, ls);
    }
    json_decref(r);
    CHECK(td_ctl(&d, 30, &e, "show", "1", NULL) == 0);
    CHECKF(e.status == 0 && strstr(e.out, "status      FINISHED") &&
               strstr(e.out, "method      MPM, USF") && strstr(e.out, "plan        kernels="),
           "show 1: %s", e.out);
    td_out_free(&e);
    CHECK(td_ctl(&d, 30, &e, "show", "1", "--case", NULL) == 0);
    CHECK(e.status == 0);
    {
        mpp_case *sc = NULL;
        CHECKF(td_case_load(e.out, strlen(e.out), &sc, err, sizeof err) == 0, "show --case: %s",
               err);
        CHECK(!strcmp(sc->name, "bar1d_mpm") && sc->has_end_time && sc->end_time == 0.5 &&
              sc->record_snapshots);
        mpp_case_destroy(&sc);
    }
    td_out_free(&e);

    /* ping and version */
    snprintf(want, sizeof want, "stream %s.stream", d.ep);
    EXPECT_CTL(&d, 0, want, "ping");
    EXPECT_CTL(&d, 0, "protobuf-c", "version");
    EXPECT_CTL(&d, 1, "NOT_FOUND", "energy", "99");
    EXPECT_CTL(&d, 1, "NOT_FOUND", "show", "99");
    EXPECT_CTL(&d, 1, "NOT_FOUND", "watch", "99");

    /* a run that fails: the block leaves the grid; watch exits 3 with the error */
    CHECK(write_case(block2d(1000, 10, "runaway"), dir, "runaway.json", path, sizeof path) == 0);
    c = td_json_file(path);
    CHECK(c);
    json_array_set_new(json_object_get(json_array_get(json_object_get(c, "bodies"), 0), "velocity"),
                       0, json_real(5.0));
    CHECK(td_json_write(path, c) == 0);
    json_decref(c);
    CHECK(td_ctl(&d, 60, &e, "submit", path, "--watch", NULL) == 0);
    CHECKF(e.status == 3 && strstr(e.out, "FAILED") && strstr(e.out, "error: ") &&
               strstr(e.out, "left the grid"),
           "runaway block: exit %d, stdout %s, stderr %s", e.status, e.out, e.err);
    TLOG("failed run: %s", strstr(e.out, "error: "));
    td_out_free(&e);
    r = show_json(&d, 3);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "status"), "FAILED") && strstr(jstr(r, "error"), "left the grid"),
           "show 3: %s, error \"%s\"", jstr(r, "status"), jstr(r, "error"));
    json_decref(r);

    td_out_free(&o);
    series_free(&s);
    CHECKF(td_stop(&d) == 0, "mpmd did not exit 0 on SIGTERM (see its log)");
}

/* ---- concurrency and a full queue ------------------------------------------------ */

DTEST(daemon_concurrency)
{
    const char *tmp = t_tmpdir();
    const char *two[] = {"--workers", "2", "--solver-threads", "1", NULL};
    const char *one[] = {"--workers", "1", "--queue-max", "1", "--solver-threads", "1", NULL};
    char dir[300], path[400], longp[400], st[32];
    td_daemon d;
    td_out o;
    td_bg w1, w2;
    td_out o1, o2;
    json_t *r1, *r2;

    snprintf(dir, sizeof dir, "%s/two", tmp);
    if (td_start(&d, dir, two)) return;
    CHECK(write_case(block2d(4000, 100, "block"), dir, "block.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    CHECKF(o.status == 0 && !strcmp(o.out, "job 1\n"), "submit: exit %d, %s%s", o.status, o.out,
           o.err);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "submit", path, "--json", NULL) == 0);
    {
        json_t *j = parse_line(o.out);
        CHECKF(o.status == 0 && j && jint(j, "jobId") == 2 && jint(j, "runId") == 2,
               "submit --json: %s", o.out);
        json_decref(j);
    }
    td_out_free(&o);
    CHECK(td_ctl_bg(&d, &w1, "w1", "watch", "1", "--csv", NULL) == 0);
    CHECK(td_ctl_bg(&d, &w2, "w2", "watch", "2", "--csv", NULL) == 0);
    CHECK(td_bg_wait(&w1, 120, &o1) == 0);
    CHECK(td_bg_wait(&w2, 120, &o2) == 0);
    CHECKF(o1.status == 0 && o2.status == 0, "watchers: exit %d / %d: %s / %s", o1.status,
           o2.status, o1.err, o2.err);
    /* same case, same code: identical series; both complete */
    CHECK(count_lines(o1.out) == 42 && !strcmp(o1.out, o2.out));
    td_out_free(&o1);
    td_out_free(&o2);
    r1 = show_json(&d, 1);
    r2 = show_json(&d, 2);
    CHECK(r1 && r2);
    {
        double s1 = jnum(r1, "startedAt"), f1 = jnum(r1, "finishedAt");
        double s2 = jnum(r2, "startedAt"), f2 = jnum(r2, "finishedAt");
        TLOG("job 1 ran %.3f..%.3f s, job 2 %.3f..%.3f s (relative to job 1's start)", 0.0, f1 - s1,
             s2 - s1, f2 - s1);
        CHECKF(!strcmp(jstr(r1, "status"), "FINISHED") && !strcmp(jstr(r2, "status"), "FINISHED"),
               "statuses %s, %s", jstr(r1, "status"), jstr(r2, "status"));
    }
    json_decref(r1);
    json_decref(r2);
    /* the two workers run two jobs at once: two long jobs are RUNNING
     * together (whatever the machine's load: the first is far from its
     * end when the second starts), then cancelled */
    CHECK(write_case(long_case(100000), dir, "long.json", longp, sizeof longp) == 0);
    for (int j = 0; j < 2; j++) {
        CHECK(td_ctl(&d, 30, &o, "submit", longp, NULL) == 0);
        CHECK(o.status == 0 && job_of(o.out) == (unsigned long long)(3 + j));
        td_out_free(&o);
    }
    CHECK(td_wait_status(&d, 4, "RUNNING", 20, st, sizeof st) == 0);
    CHECK(td_job_status(&d, 3, st, sizeof st, NULL) == 0);
    CHECKF(!strcmp(st, "RUNNING"), "job 3 is %s while job 4 runs: not two at once", st);
    for (int j = 3; j <= 4; j++) {
        char id[16];
        snprintf(id, sizeof id, "%d", j);
        CHECK(td_ctl(&d, 30, &o, "cancel", id, NULL) == 0 && o.status == 0);
        td_out_free(&o);
        CHECK(td_wait_status(&d, (unsigned long long)j, "CANCELLED", 20, st, sizeof st) == 0);
    }
    CHECK(td_stop(&d) == 0);

    /* one worker, one queue slot: a third job is refused with QUEUE_FULL */
    snprintf(dir, sizeof dir, "%s/one", tmp);
    if (td_start(&d, dir, one)) return;
    CHECK(write_case(long_case(100000), dir, "long.json", longp, sizeof longp) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", longp, NULL) == 0);
    CHECK(o.status == 0 && job_of(o.out) == 1);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "RUNNING", 20, st, sizeof st) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", longp, NULL) == 0);
    CHECK(o.status == 0 && job_of(o.out) == 2);
    td_out_free(&o);
    CHECK(td_job_status(&d, 2, st, sizeof st, NULL) == 0);
    CHECKF(!strcmp(st, "QUEUED"), "job 2 is %s, not QUEUED", st);
    CHECK(td_ctl(&d, 30, &o, "submit", longp, NULL) == 0);
    CHECKF(o.status == 1 && strstr(o.err, "QUEUE_FULL"), "third submit: exit %d, stderr %s",
           o.status, o.err);
    TLOG("third submit: %s", o.err);
    td_out_free(&o);
    {
        /* the same through a raw request: the decoded code */
        size_t len = 0;
        char *text = td_slurp(longp, &len), err[ERRLEN];
        Mpmd__Case *pb = NULL;
        json_t *reply = NULL;
        CHECK(text && td_case_from_json(text, len, &pb, err, sizeof err) == 0);
        free(text);
        mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_pb = pb};
        CHECK(td_request(d.ep, &rq, 10, &reply) == 0);
        mpp_case_pb_free(&pb);
        CHECKF(!strcmp(td_err_code(reply), "QUEUE_FULL"), "raw submit: code %s",
               td_err_code(reply));
        json_decref(reply);
    }
    /* cancelling the queued job frees the slot at once; then the running one */
    CHECK(td_ctl(&d, 30, &o, "cancel", "2", NULL) == 0);
    CHECKF(o.status == 0 && strstr(o.out, "job 2: CANCELLED"), "cancel 2: %s%s", o.out, o.err);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "cancel", "1", NULL) == 0);
    CHECK(o.status == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "CANCELLED", 10, st, sizeof st) == 0);
    /* refused submissions left no record and used no id */
    CHECK(write_case(bar_steps(100, 10), dir, "short.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 3, "submit after the queue emptied: exit %d, %s%s",
           o.status, o.out, o.err);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "runs", "--json", NULL) == 0);
    CHECKF(o.status == 0 && count_lines(o.out) == 3, "runs --json: %s", o.out);
    td_out_free(&o);
    CHECK(td_stop(&d) == 0);
}

/* ---- cancel ------------------------------------------------------------------------ */

DTEST(daemon_cancel)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--solver-threads", "1", NULL};
    char dir[300], path[400], st[32];
    td_daemon d;
    td_out o, e;
    td_bg w;
    series s;
    double t0, dt;
    json_t *r;

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(long_case(1000), dir, "long.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    CHECK(o.status == 0 && job_of(o.out) == 1);
    td_out_free(&o);
    CHECK(td_ctl_bg(&d, &w, "watch", "watch", "1", "--csv", NULL) == 0);
    CHECK(td_wait_steps(&d, 1, 20000, 30) == 0);
    CHECK(td_ctl(&d, 30, &o, "cancel", "1", NULL) == 0);
    t0 = td_now();
    CHECKF(o.status == 0 && (strstr(o.out, "job 1: RUNNING (cancel requested") ||
                             strstr(o.out, "job 1: CANCELLED")),
           "cancel: exit %d, %s%s", o.status, o.out, o.err);
    TLOG("cancel: %s", o.out);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "CANCELLED|FINISHED|FAILED|INTERRUPTED", 5, st, sizeof st) == 0);
    dt = td_now() - t0;
    CHECKF(!strcmp(st, "CANCELLED"), "status after cancel: %s", st);
    TLOG("CANCELLED %.3f s after the cancel reply", dt);

    /* the watcher ends with the run, exit status 4, the series complete */
    CHECK(td_bg_wait(&w, 30, &o) == 0);
    CHECKF(o.status == 4 && strstr(o.err, "CANCELLED"), "watcher: exit %d, stderr %s", o.status,
           o.err);
    CHECK(parse_csv(o.out, &s) == 0);
    CHECK(consecutive(&s) && s.n >= 2);
    CHECK(td_ctl(&d, 30, &e, "energy", "1", "--csv", NULL) == 0);
    CHECKF(e.status == 0 && !strcmp(e.out, o.out),
           "energy --csv differs from the watcher's series");
    TLOG("cancelled at step %lld, %zu samples", s.step[s.n - 1], s.n);
    td_out_free(&e);
    td_out_free(&o);

    r = show_json(&d, 1);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "status"), "CANCELLED") && jint(r, "steps") < LONG_STEPS &&
               jint(r, "steps") == s.step[s.n - 1] && json_object_get(r, "finishedAt"),
           "show 1: status %s, steps %lld", jstr(r, "status"), jint(r, "steps"));
    json_decref(r);
    series_free(&s);
    CHECK(td_ctl(&d, 30, &o, "runs", "--status", "CANCELLED", "--json", NULL) == 0);
    CHECK(o.status == 0 && count_lines(o.out) == 1);
    td_out_free(&o);
    EXPECT_CTL(&d, 4, "CANCELLED", "watch", "1"); /* exit status of a cancelled run */
    EXPECT_CTL(&d, 1, "CONFLICT", "cancel", "1");
    EXPECT_CTL(&d, 1, "NOT_FOUND", "cancel", "42");
    CHECK(td_stop(&d) == 0);
}

/* ---- late watchers --------------------------------------------------------------- */

DTEST(daemon_late_watcher)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--solver-threads", "1", NULL};
    /* more samples than one GetEnergy page (10000 by default): paging too */
    enum { NSTEPS = 12000, NW = 4 };
    const long long start_at[NW] = {0, 0, 3000, 8000}; /* watcher 0 loses messages */
    char dir[300], path[400], tag[16], st[32];
    long long started[NW];
    td_daemon d;
    td_out o, e;
    td_bg w[NW];

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(block2d(NSTEPS, 1, "late"), dir, "late.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    CHECK(o.status == 0 && job_of(o.out) == 1);
    td_out_free(&o);
    for (int i = 0; i < NW; i++) {
        if (start_at[i]) CHECK(td_wait_steps(&d, 1, start_at[i], 60) == 0);
        CHECK(td_job_status(&d, 1, st, sizeof st, &started[i]) == 0);
        snprintf(tag, sizeof tag, "w%d", i);
        if (i == 0) {
            /* a lossy stream: every 7th energy message and Finished lost */
            setenv("MPMCTL_TEST_DROP_EVERY", "7", 1);
            setenv("MPMCTL_TEST_DROP_FINISHED", "1", 1);
        }
        int rc = td_ctl_bg(&d, &w[i], tag, "watch", "1", "--csv", NULL);
        unsetenv("MPMCTL_TEST_DROP_EVERY");
        unsetenv("MPMCTL_TEST_DROP_FINISHED");
        CHECK(rc == 0);
        TLOG("watcher %d started at step %lld (%s)%s", i, started[i], st,
             i == 0 ? ", losing every 7th energy message and Finished" : "");
    }
    memset(&e, 0, sizeof e);
    for (int i = 0; i < NW; i++) {
        series s;
        const char *gaps;
        CHECK(td_bg_wait(&w[i], 120, &o) == 0);
        CHECKF(o.status == 0, "watcher %d: exit %d, stderr %s", i, o.status, o.err);
        CHECK(parse_csv(o.out, &s) == 0);
        CHECKF(s.n == NSTEPS + 1 && consecutive(&s), "watcher %d: %zu samples", i, s.n);
        for (size_t k = 0; k < s.n; k++) CHECK(s.step[k] == (long long)k);
        series_free(&s);
        if (i == 0) {
            CHECK(td_ctl(&d, 30, &e, "energy", "1", "--csv", NULL) == 0);
            CHECK(e.status == 0);
        }
        CHECKF(!strcmp(o.out, e.out), "watcher %d's series differs from energy --csv", i);
        gaps = strstr(o.err, "stream:");
        if (i == 0 && started[i] < NSTEPS / 2) {
            unsigned long long lost = 0, filled = 0;
            CHECKF(gaps &&
                       sscanf(gaps, "stream: %llu messages dropped, %llu gaps filled", &lost,
                              &filled) == 2 &&
                       lost > 0 && filled > 0,
                   "lossy watcher: %s", o.err);
        }
        TLOG("watcher %d: %zu samples in order, %.2f s%s%.*s", i, (size_t)NSTEPS + 1, o.secs,
             gaps ? "; " : "", gaps ? (int)strcspn(gaps, "\n") : 0, gaps ? gaps : "");
        td_out_free(&o);
    }
    td_out_free(&e);
    CHECK(td_stop(&d) == 0);
}

/* ---- restart on the same database --------------------------------------------------- */

DTEST(daemon_restart)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--solver-threads", "1", "--verbose", NULL};
    char dir[300], path[400], longp[400], st[32], ep2[400], pid[32];
    td_daemon d;
    td_out o, before, watched3;
    td_bg w;
    json_t *r;
    long long last3 = -1;

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(bar_steps(305, 10), dir, "short.json", path, sizeof path) == 0);
    CHECK(write_case(long_case(10000), dir, "long.json", longp, sizeof longp) == 0);
    for (int i = 1; i <= 2; i++) {
        CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0);
        CHECKF(o.status == 0 && job_of(o.out) == (unsigned long long)i, "submit %d: %s%s", i, o.out,
               o.err);
        td_out_free(&o);
    }
    CHECK(td_ctl(&d, 30, &before, "energy", "1", "--csv", NULL) == 0 && before.status == 0);
    {
        /* samples at step 0, every 10 steps, and the final step (305) */
        series s;
        int ok;
        CHECK(parse_csv(before.out, &s) == 0);
        ok = s.n == 32 && consecutive(&s) && s.step[0] == 0 && s.step[30] == 300 &&
             s.step[31] == 305;
        series_free(&s);
        CHECKF(ok, "energy of a 305-step run, energyEvery 10: %s", before.out);
    }

    /* a second daemon on the same database is refused and names the holder */
    snprintf(ep2, sizeof ep2, "ipc://%s/ctl2", dir);
    snprintf(pid, sizeof pid, "%d", (int)d.pid);
    {
        const char *a[] = {"--endpoint", ep2, "--db", d.db, NULL};
        CHECK(td_run_mpmd(a, 30, &o) == 0);
        CHECKF(o.status != 0 && o.status < 128 && strstr(o.err, pid),
               "second mpmd: exit %d, stderr %s (want the holder's pid %s)", o.status, o.err, pid);
        TLOG("second mpmd refused (exit %d): %.*s", o.status,
             (int)strcspn(strstr(o.err, "mpmd") ? strstr(o.err, "mpmd") : o.err, "\n"),
             strstr(o.err, "mpmd") ? strstr(o.err, "mpmd") : o.err);
        td_out_free(&o);
    }
    /* the first one is unharmed */
    EXPECT_CTL(&d, 0, "mpmd", "ping");

    /* a running job at SIGTERM becomes INTERRUPTED; mpmd exits 0 promptly */
    CHECK(td_ctl(&d, 30, &o, "submit", longp, NULL) == 0);
    CHECK(o.status == 0 && job_of(o.out) == 3);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 3, "RUNNING", 20, st, sizeof st) == 0);
    CHECK(td_ctl_bg(&d, &w, "watch3", "watch", "3", "--csv", "--timeout", "3", NULL) == 0);
    CHECK(td_wait_steps(&d, 3, 30000, 30) == 0);
    /* the watcher is subscribed and past the history: what it gets from
     * now on comes from the stream */
    CHECK(wait_watched(&d, 3, 20) == 0);
    CHECK(wait_lines(&w, 2, 20) == 0);
    td_msleep(300);
    {
        double t0 = td_now();
        CHECKF(td_stop(&d) == 0, "mpmd did not exit 0 on SIGTERM with a job running");
        TLOG("SIGTERM with a job running: stopped in %.2f s", td_now() - t0);
    }
    /* its watcher learns it from the stream: Finished(INTERRUPTED) reaches
     * it although mpmd exits right after sending it (the stream socket
     * lingers), so it ends with exit status 5 and the series complete up to
     * the run's last step, the final sample included */
    CHECK(td_bg_wait(&w, 30, &o) == 0);
    CHECKF(o.status == 5 && strstr(o.err, "INTERRUPTED") && !strstr(o.err, "no reply") &&
               !strstr(o.err, "may lack"),
           "watcher at shutdown: exit %d, stderr %s", o.status, o.err);
    {
        series s;
        CHECK(parse_csv(o.out, &s) == 0);
        int ok = s.n >= 2 && consecutive(&s);
        last3 = s.n ? s.step[s.n - 1] : -1;
        TLOG("watcher at shutdown: exit 5 after %.2f s, %zu samples up to step %lld", o.secs, s.n,
             last3);
        series_free(&s);
        CHECK(ok);
    }
    watched3 = o;

    if (td_start(&d, dir, extra)) return;
    CHECK(td_ctl(&d, 30, &o, "runs", "--json", NULL) == 0);
    {
        char **lines = NULL;
        size_t n = td_lines(o.out, &lines);
        json_t *j0 = n == 3 ? parse_line(lines[0]) : NULL,
               *j2 = n == 3 ? parse_line(lines[2]) : NULL;
        free(lines);
        CHECKF(j0 && j2 && jint(j0, "runId") == 3 && !strcmp(jstr(j0, "status"), "INTERRUPTED") &&
                   jint(j2, "runId") == 1 && !strcmp(jstr(j2, "status"), "FINISHED"),
               "runs after restart: %zu lines", n);
        json_decref(j0);
        json_decref(j2);
    }
    td_out_free(&o);
    r = show_json(&d, 3);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "status"), "INTERRUPTED") && jstr(r, "error")[0] &&
               jint(r, "steps") == last3,
           "job 3: %s at step %lld (the watcher's last sample: %lld), error \"%s\"",
           jstr(r, "status"), jint(r, "steps"), last3, jstr(r, "error"));
    TLOG("job 3 after restart: INTERRUPTED at step %lld, \"%s\"", last3, jstr(r, "error"));
    json_decref(r);
    /* the watcher's series is the stored one */
    CHECK(td_ctl(&d, 30, &o, "energy", "3", "--csv", NULL) == 0);
    CHECKF(o.status == 0 && !strcmp(o.out, watched3.out),
           "job 3: the watcher's series differs from "
           "the stored one");
    td_out_free(&o);
    td_out_free(&watched3);
    CHECK(td_ctl(&d, 30, &o, "energy", "1", "--csv", NULL) == 0);
    CHECKF(o.status == 0 && !strcmp(o.out, before.out),
           "job 1's energies changed across the restart");
    td_out_free(&o);
    td_out_free(&before);
    /* ids continue */
    CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 4, "submit after restart: %s%s", o.out, o.err);
    td_out_free(&o);
    CHECK(td_stop(&d) == 0);
}

/* ---- the end of the streams at shutdown --------------------------------------------- */

/* SIGTERM with one job running and one queued, both watched: each watcher
 * gets its Finished(INTERRUPTED) from the stream before mpmd is gone. */
DTEST(daemon_shutdown_streams)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", "--verbose", NULL};
    char dir[300], longp[400], st[32];
    td_daemon d;
    td_out o;
    td_bg w1, w2;
    series s;
    json_t *r;
    long long last1;

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(long_case(5000), dir, "long.json", longp, sizeof longp) == 0);
    for (unsigned long long i = 1; i <= 2; i++) {
        CHECK(td_ctl(&d, 30, &o, "submit", longp, NULL) == 0);
        CHECKF(o.status == 0 && job_of(o.out) == i, "submit %llu: %s%s", i, o.out, o.err);
        td_out_free(&o);
    }
    CHECK(td_wait_status(&d, 1, "RUNNING", 20, st, sizeof st) == 0);
    CHECK(td_job_status(&d, 2, st, sizeof st, NULL) == 0 && !strcmp(st, "QUEUED"));
    CHECK(td_ctl_bg(&d, &w1, "w1", "watch", "1", "--csv", "--timeout", "3", NULL) == 0);
    CHECK(td_ctl_bg(&d, &w2, "w2", "watch", "2", "--csv", "--timeout", "3", NULL) == 0);
    CHECK(wait_watched(&d, 1, 20) == 0 && wait_watched(&d, 2, 20) == 0);
    CHECK(td_wait_steps(&d, 1, 20000, 30) == 0);
    CHECK(wait_lines(&w1, 3, 20) == 0); /* header and two samples: job 1's watcher is live */
    td_msleep(300);
    CHECKF(td_stop(&d) == 0, "mpmd did not exit 0 on SIGTERM");

    CHECK(td_bg_wait(&w1, 30, &o) == 0);
    CHECKF(o.status == 5 && strstr(o.err, "INTERRUPTED") && !strstr(o.err, "no reply") &&
               !strstr(o.err, "may lack"),
           "job 1's watcher: exit %d, stderr %s", o.status, o.err);
    CHECK(parse_csv(o.out, &s) == 0);
    last1 = s.n ? s.step[s.n - 1] : -1;
    {
        int ok = s.n >= 3 && consecutive(&s);
        series_free(&s);
        CHECK(ok);
    }
    TLOG("running job's watcher: exit 5 after %.2f s, last sample at step %lld", o.secs, last1);
    td_out_free(&o);
    CHECK(td_bg_wait(&w2, 30, &o) == 0);
    CHECKF(o.status == 5 && strstr(o.err, "INTERRUPTED") && !strstr(o.err, "no reply") && !o.out[0],
           "queued job's watcher: exit %d, stdout %s, stderr %s", o.status, o.out, o.err);
    TLOG("queued job's watcher: exit 5 after %.2f s: %.*s", o.secs, (int)strcspn(o.err, "\n"),
         o.err);
    td_out_free(&o);

    /* the record agrees with what the watchers were told */
    if (td_start(&d, dir, extra)) return;
    r = show_json(&d, 1);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "status"), "INTERRUPTED") && jint(r, "steps") == last1,
           "job 1: %s at step %lld (its watcher's last sample: %lld)", jstr(r, "status"),
           jint(r, "steps"), last1);
    json_decref(r);
    r = show_json(&d, 2);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "status"), "INTERRUPTED") && jint(r, "steps") == 0 &&
               strstr(jstr(r, "error"), "before the run started"),
           "job 2: %s at step %lld, error \"%s\"", jstr(r, "status"), jint(r, "steps"),
           jstr(r, "error"));
    json_decref(r);
    CHECK(td_stop(&d) == 0);
}

/* ---- hard kill --------------------------------------------------------------------- */

DTEST(daemon_hard_kill)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", NULL};
    char dir[300], path[400], longp[400], st[32];
    td_daemon d;
    td_out o;
    series s;
    json_t *r;

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(long_case(1000), dir, "long.json", longp, sizeof longp) == 0);
    CHECK(write_case(bar_steps(200, 10), dir, "short.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", longp, NULL) == 0 && o.status == 0 && job_of(o.out) == 1);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "submit", longp, NULL) == 0 && o.status == 0 && job_of(o.out) == 2);
    td_out_free(&o);
    CHECK(td_wait_steps(&d, 1, 20000, 30) == 0);
    CHECK(td_job_status(&d, 2, st, sizeof st, NULL) == 0 && !strcmp(st, "QUEUED"));
    td_kill9(&d);

    if (td_start(&d, dir, extra)) return;
    /* what was stored before the kill is readable and consecutive */
    CHECK(td_ctl(&d, 30, &o, "energy", "1", "--csv", NULL) == 0 && o.status == 0);
    CHECK(parse_csv(o.out, &s) == 0);
    td_out_free(&o);
    CHECK(s.n >= 1 && consecutive(&s));
    TLOG("job 1 kept %zu energy samples (up to step %lld)", s.n, s.step[s.n - 1]);
    /* the run stands where its last stored sample does: steps, t and the
     * last energies belong together (the row's progress figures lagged or
     * led them when the process died) */
    r = show_json(&d, 1);
    CHECK(r);
    {
        json_t *le = json_object_get(r, "lastEnergy");
        long long steps = jint(r, "steps"), last = s.step[s.n - 1];
        double t = jnum(r, "t"), tl = s.t[s.n - 1], total = s.total[s.n - 1];
        series_free(&s);
        CHECKF(!strcmp(jstr(r, "status"), "INTERRUPTED") && jstr(r, "error")[0],
               "job 1: %s, error \"%s\"", jstr(r, "status"), jstr(r, "error"));
        CHECKF(
            steps == last && steps > 0 && t == tl && le && jint(le, "step") == steps &&
                jnum(le, "total") == total,
            "job 1 after kill -9: steps %lld, t %.17g, lastEnergy.step %lld (want the last stored "
            "sample's step %lld > 0, t %.17g)",
            steps, t, le ? jint(le, "step") : -1, last, tl);
        TLOG(
            "job 1 after kill -9 and restart: INTERRUPTED at step %lld (its last sample), t %.6g, \"%s\"",
            steps, t, jstr(r, "error"));
    }
    json_decref(r);
    /* Status (by job id) says the same */
    {
        char buf[32];
        long long steps = -1;
        CHECK(td_job_status(&d, 1, buf, sizeof buf, &steps) == 0);
        r = show_json(&d, 1);
        CHECK(r);
        CHECKF(!strcmp(buf, "INTERRUPTED") && steps == jint(r, "steps"), "Status: %s, steps %lld",
               buf, steps);
        json_decref(r);
    }
    r = show_json(&d, 2);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "status"), "INTERRUPTED"), "job 2 (queued at the kill): %s",
           jstr(r, "status"));
    json_decref(r);
    CHECK(td_ctl(&d, 30, &o, "runs", "--status", "INTERRUPTED", "--json", NULL) == 0);
    CHECK(o.status == 0 && count_lines(o.out) == 2);
    td_out_free(&o);
    EXPECT_CTL(&d, 5, "INTERRUPTED", "watch", "1");
    CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 3, "submit after restart: %s%s", o.out, o.err);
    td_out_free(&o);
    CHECK(td_stop(&d) == 0);
}
