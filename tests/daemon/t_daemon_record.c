/*
 * t_daemon_record.c - integration tests of what a run's record carries from
 * the case and the solver through a real mpmd (ipc:// in the test's
 * temporary directory, a real SQLite file) to mpmctl: the angular momentum
 * of every energy sample, the schema's defaults for method and update, and
 * the velocity transfer (FLIP, APIC) in RunInfo, `runs` and `show`.  The
 * other daemon scenarios are in t_daemon.c, t_daemon_input.c and
 * t_daemon_stream.c; the shared helpers in t_daemon_util.c.
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

/* ---- method and update: the schema's defaults, RunInfo ------------------------- */

/* The angular momentum (EnergySample.angular_momentum, 2D: the z
 * component) from the solver through the stream, the store and mpmctl: two
 * disks in the 2D example, moving off the diagonal so that L_z about the
 * origin is not zero.  `submit --watch --csv` (the stream, merged with the
 * store), `energy --csv` (the store) and `energy --json` carry, sample for
 * sample, the very double the solver computes in-process (bitwise: CSV and
 * JSON print the shortest text that reads back exactly); the CSV has the
 * column after the momentum and the two CSV outputs are identical. */
DTEST(daemon_angular_momentum)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", NULL};
    char dir[300], path[400], err[ERRLEN];
    td_daemon d;
    td_out o, e, j;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    json_t *c = example("disks2d_coarse");
    CHECK(c);
    json_object_del(c, "endTime");
    json_object_set_new(c, "steps", json_integer(300));
    set_output(c, "energyEvery", json_integer(10));
    json_t *b = json_object_get(c, "bodies");
    json_object_set_new(json_array_get(b, 0), "velocity", json_pack("[f,f]", 0.1, 0.0));
    json_object_set_new(json_array_get(b, 1), "velocity", json_pack("[f,f]", -0.1, 0.05));
    CHECK(write_case(c, dir, "disks.json", path, sizeof path) == 0);

    CHECK(td_ctl(&d, 120, &o, "submit", path, "--watch", "--csv", NULL) == 0);
    CHECKF(o.status == 0, "submit --watch --csv: exit %d, stderr: %s", o.status, o.err);
    CHECK(td_ctl(&d, 30, &e, "energy", "1", "--csv", NULL) == 0);
    CHECKF(e.status == 0 && !strcmp(e.out, o.out), "energy --csv differs from watch --csv");
    CHECK(td_ctl(&d, 30, &j, "energy", "1", "--json", NULL) == 0 && j.status == 0);

    size_t len = 0;
    char *text = td_slurp(path, &len);
    mpp_case *sc = NULL;
    CHECK(text);
    CHECKF(td_case_load(text, len, &sc, err, sizeof err) == 0, "%s", err);
    free(text);
    mpm_error me;
    mpm_sim *sim = mpm_sim_new(&sc->c, &sc->info, &me);
    CHECKF(sim, "%s", TERR(&me));

    char **lines = NULL, **jl = NULL;
    size_t nl = td_lines(o.out, &lines), nj = td_lines(j.out, &jl), same = 0;
    /* angular_momentum_z follows the momentum; the energy balance's
     * columns (plastic_work .. balance_error) come after it */
    int ok = nl == 32 && nj == 31 &&
             strstr(lines[0], ",momentum_x,momentum_y,angular_momentum_z,plastic_work,") &&
             !strcmp(strrchr(lines[0], ','), ",balance_error");
    CHECKF(ok, "%zu CSV lines, %zu JSON lines, header %s", nl, nj, nl ? lines[0] : "");
    double lmin = INFINITY, lmax = -INFINITY;
    for (size_t i = 1; ok && i < nl; i++) {
        long long seq, step;
        CHECK(sscanf(lines[i], "%lld,%lld,", &seq, &step) == 2 && seq == (long long)i - 1);
        while (mpm_sim_steps(sim) < step) CHECK(mpm_sim_step(sim) == 0);
        mpm_energy en;
        mpm_sim_energy(sim, &en);
        const char *col = lines[i]; /* column 12: angular_momentum_z */
        for (int k = 0; k < 11 && col; k++) col = strchr(col, ',') ? strchr(col, ',') + 1 : NULL;
        CHECK(col);
        double lc = strtod(col, NULL);
        json_t *js = parse_line(jl[i - 1]), *ja = json_object_get(js, "angularMomentum");
        double lj = json_number_value(json_array_get(ja, 0));
        if (lc == en.angular_momentum[2] && lj == lc && json_array_size(ja) == 1 &&
            en.angular_momentum[0] == 0 && en.angular_momentum[1] == 0)
            same++;
        else
            TLOG("sample %zu (step %lld): solver %.17g, CSV %.17g, JSON %.17g", i - 1, step,
                 en.angular_momentum[2], lc, lj);
        lmin = fmin(lmin, lc);
        lmax = fmax(lmax, lc);
        json_decref(js);
    }
    TLOG("2D disks, 31 samples to step 300: L_z %.10g .. %.10g; streamed/stored (CSV), stored "
         "(JSON) and in-process equal bitwise in %zu of %zu samples",
         lmin, lmax, same, nl - 1);
    CHECK(ok && same == nl - 1 && lmax != 0);
    free(lines);
    free(jl);
    mpm_sim_destroy(&sim);
    mpp_case_destroy(&sc);
    td_out_free(&o);
    td_out_free(&e);
    td_out_free(&j);
}

DTEST(daemon_method_defaults)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--solver-threads", "1", NULL};
    char dir[300], path[400], err[ERRLEN];
    td_daemon d;
    td_out o;
    json_t *c, *r;

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    /* the block without method and update: BSPLINE2 with MUSL, the defaults */
    c = block2d(40, 10, "defaults");
    CHECK(c);
    json_object_del(c, "method");
    json_object_del(c, "update");
    CHECK(write_case(c, dir, "defaults.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 1, "submit --watch: exit %d, %s%s", o.status, o.out,
           o.err);
    td_out_free(&o);
    /* one that names a combination the verification policy refuses (MPM
     * with USL: mpm_verified.c): the daemon refuses it at submit, naming
     * the field and an alternative, and records nothing */
    c = block2d(40, 10, "refused");
    CHECK(c);
    json_object_set_new(c, "update", json_string("USL"));
    CHECK(write_case(c, dir, "refused.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 60, &o, "submit", path, NULL) == 0);
    TLOG("MPM with USL: exit %d, %s", o.status, o.err);
    CHECKF(o.status != 0 && strstr(o.err, "update: method MPM with update USL is refused") &&
               strstr(o.err, "; use MUSL"),
           "submit: exit %d, %s%s", o.status, o.out, o.err);
    td_out_free(&o);
    /* and one that names GIMP with USL */
    c = block2d(40, 10, "explicit");
    CHECK(c);
    json_object_set_new(c, "method", json_string("GIMP"));
    json_object_set_new(c, "update", json_string("USL"));
    CHECK(write_case(c, dir, "explicit.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 2, "submit --watch: exit %d, %s%s", o.status, o.out,
           o.err);
    td_out_free(&o);

    /* decoded replies: RunInfo.method / update, from the run record */
    {
        static const char *const want[3][2] = {{"", ""}, {"BSPLINE2", "MUSL"}, {"GIMP", "USL"}};
        for (unsigned long long id = 1; id <= 2; id++) {
            mpp_request rq = {.kind = MPP_REQ_GET_RUN, .id = id, .with_case = 1};
            json_t *reply = NULL, *run, *cs;
            CHECK(td_request(d.ep, &rq, 10, &reply) == 0);
            run = json_object_get(reply, "run");
            cs = json_object_get(run, "case");
            /* the stored case names them too: resubmitted anywhere, it runs the same */
            int ok = run && !strcmp(jstr(run, "method"), want[id][0]) &&
                     !strcmp(jstr(run, "update"), want[id][1]) && cs &&
                     !strcmp(jstr(cs, "method"), want[id][0]) &&
                     !strcmp(jstr(cs, "update"), want[id][1]);
            TLOG("run %llu: RunInfo method %s, update %s; its stored case: %s, %s", id,
                 jstr(run, "method"), jstr(run, "update"), jstr(cs, "method"), jstr(cs, "update"));
            json_decref(reply);
            CHECKF(ok, "run %llu: want %s, %s", id, want[id][0], want[id][1]);
        }
    }
    /* mpmctl runs (table and --json) and show print them */
    CHECK(td_ctl(&d, 30, &o, "runs", NULL) == 0);
    CHECKF(o.status == 0 && strstr(o.out, "METHOD   UPDATE TRANSFER") &&
               strstr(o.out, "FINISHED    BSPLINE2 MUSL   FLIP") &&
               strstr(o.out, "FINISHED    GIMP     USL    FLIP"),
           "runs: %s", o.out);
    TLOG("runs:\n%s", o.out);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "runs", "--json", NULL) == 0);
    {
        char **lines = NULL;
        size_t nl = td_lines(o.out, &lines);
        json_t *r2 = nl == 2 ? parse_line(lines[0]) : NULL,
               *r1 = nl == 2 ? parse_line(lines[1]) : NULL;
        free(lines);
        int ok = r1 && r2 && !strcmp(jstr(r1, "method"), "BSPLINE2") &&
                 !strcmp(jstr(r1, "update"), "MUSL") && !strcmp(jstr(r2, "method"), "GIMP") &&
                 !strcmp(jstr(r2, "update"), "USL");
        json_decref(r1);
        json_decref(r2);
        CHECKF(ok, "runs --json: %s", o.out);
    }
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "show", "1", NULL) == 0);
    CHECKF(o.status == 0 && strstr(o.out, "method      BSPLINE2, MUSL, dt 0.001"), "show 1: %s",
           o.out);
    td_out_free(&o);
    r = show_json(&d, 2);
    CHECK(r);
    CHECKF(!strcmp(jstr(r, "method"), "GIMP") && !strcmp(jstr(r, "update"), "USL"),
           "show 2 --json: %s, %s", jstr(r, "method"), jstr(r, "update"));
    json_decref(r);
    /* show --case gives a case that loads as BSPLINE2 + MUSL */
    CHECK(td_ctl(&d, 30, &o, "show", "1", "--case", NULL) == 0);
    {
        mpp_case *sc = NULL;
        CHECKF(o.status == 0 && td_case_load(o.out, strlen(o.out), &sc, err, sizeof err) == 0,
               "show 1 --case: %s", err);
        int ok = sc->c.method == MPM_METHOD_BSPLINE2 && sc->c.update == MPM_MUSL &&
                 strstr(o.out, "\"BSPLINE2\"");
        mpp_case_destroy(&sc);
        CHECKF(ok, "show 1 --case: %s", o.out);
    }
    td_out_free(&o);
    CHECK(td_stop(&d) == 0);
}

/* The run record carries the velocity transfer: an APIC case (the spinning
 * disk, shortened) and the same case under FLIP with a PIC fraction run
 * through a real mpmd; RunInfo.transfer (decoded reply, runs --json, show
 * --json), the runs table, show and the stored case say which is which. */
DTEST(daemon_transfer)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--solver-threads", "1", NULL};
    char dir[300], path[400], err[ERRLEN];
    td_daemon d;
    td_out o;
    json_t *c, *r;

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    /* job 1: APIC */
    c = example("disk2d_apic");
    CHECK(c && !strcmp(jstr(c, "transfer"), "APIC"));
    json_object_del(c, "endTime");
    json_object_set_new(c, "steps", json_integer(40));
    set_output(c, "energyEvery", json_integer(10));
    CHECK(write_case(json_deep_copy(c), dir, "apic.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 1, "submit --watch: exit %d, %s%s", o.status, o.out,
           o.err);
    td_out_free(&o);
    /* job 2: the same case under FLIP (absent) with a PIC fraction */
    json_object_del(c, "transfer");
    json_object_set_new(c, "name", json_string("disk2d_flip"));
    json_object_set_new(c, "picFraction", json_real(0.25));
    CHECK(write_case(c, dir, "flip.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 2, "submit --watch: exit %d, %s%s", o.status, o.out,
           o.err);
    td_out_free(&o);

    /* decoded replies: RunInfo.transfer and the case's, from the run record */
    {
        static const char *const want[3] = {"", "APIC", "FLIP"};
        for (unsigned long long id = 1; id <= 2; id++) {
            mpp_request rq = {.kind = MPP_REQ_GET_RUN, .id = id, .with_case = 1};
            json_t *reply = NULL, *run, *cs;
            CHECK(td_request(d.ep, &rq, 10, &reply) == 0);
            run = json_object_get(reply, "run");
            cs = json_object_get(run, "case");
            int ok = run && cs && !strcmp(jstr(run, "transfer"), want[id]) &&
                     !strcmp(jstr(cs, "transfer"), want[id]);
            TLOG("run %llu: RunInfo transfer %s; its case: %s", id, jstr(run, "transfer"),
                 jstr(cs, "transfer"));
            json_decref(reply);
            CHECKF(ok, "run %llu: want %s", id, want[id]);
        }
    }
    /* runs --json (and a status filter, unaffected) */
    for (int filtered = 0; filtered < 2; filtered++) {
        if (filtered)
            CHECK(td_ctl(&d, 30, &o, "runs", "--status", "FINISHED", "--json", NULL) == 0);
        else
            CHECK(td_ctl(&d, 30, &o, "runs", "--json", NULL) == 0);
        char **lines = NULL;
        size_t nl = td_lines(o.out, &lines);
        json_t *r2 = nl == 2 ? parse_line(lines[0]) : NULL,
               *r1 = nl == 2 ? parse_line(lines[1]) : NULL;
        free(lines);
        int ok = o.status == 0 && r1 && r2 && jint(r1, "runId") == 1 &&
                 !strcmp(jstr(r1, "transfer"), "APIC") && !strcmp(jstr(r1, "status"), "FINISHED") &&
                 jint(r2, "runId") == 2 && !strcmp(jstr(r2, "transfer"), "FLIP") &&
                 !strcmp(jstr(r2, "status"), "FINISHED");
        json_decref(r1);
        json_decref(r2);
        CHECKF(ok, "runs%s --json: %s", filtered ? " --status FINISHED" : "", o.out);
        td_out_free(&o);
    }
    CHECK(td_ctl(&d, 30, &o, "runs", "--status", "FAILED", "--json", NULL) == 0);
    CHECK(o.status == 0 && !o.out[0]);
    td_out_free(&o);
    /* the table */
    CHECK(td_ctl(&d, 30, &o, "runs", NULL) == 0);
    CHECKF(o.status == 0 && strstr(o.out, "METHOD   UPDATE TRANSFER") &&
               strstr(o.out, "disk2d_apic          FINISHED    GIMP     MUSL   APIC") &&
               strstr(o.out, "disk2d_flip          FINISHED    GIMP     MUSL   FLIP"),
           "runs: %s", o.out);
    TLOG("runs:\n%s", o.out);
    td_out_free(&o);
    /* show, text and JSON */
    CHECK(td_ctl(&d, 30, &o, "show", "1", NULL) == 0);
    CHECKF(o.status == 0 && strstr(o.out, "method      GIMP, MUSL, ") &&
               strstr(o.out, "\n  transfer    APIC\n"),
           "show 1: %s", o.out);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "show", "2", NULL) == 0);
    CHECKF(o.status == 0 && strstr(o.out, "\n  transfer    FLIP (PIC fraction 0.25)\n"),
           "show 2: %s", o.out);
    td_out_free(&o);
    r = show_json(&d, 1);
    CHECKF(r && !strcmp(jstr(r, "transfer"), "APIC"), "show 1 --json: %s", jstr(r, "transfer"));
    json_decref(r);
    /* show --case gives a case that loads as APIC again */
    CHECK(td_ctl(&d, 30, &o, "show", "1", "--case", NULL) == 0);
    {
        mpp_case *sc = NULL;
        CHECKF(o.status == 0 && td_case_load(o.out, strlen(o.out), &sc, err, sizeof err) == 0,
               "show 1 --case: %s", err);
        int ok = sc && sc->c.transfer == MPM_TRANSFER_APIC;
        mpp_case_destroy(&sc);
        CHECKF(ok, "show 1 --case: %s", o.out);
    }
    td_out_free(&o);
    CHECK(td_stop(&d) == 0);
}
