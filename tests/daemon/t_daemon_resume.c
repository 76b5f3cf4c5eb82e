/*
 * t_daemon_resume.c - integration tests of resumable runs
 * through a real mpmd (ipc:// in the test's temporary directory, a real
 * SQLite file, checkpoint files beside it) and the real mpmctl: a run cut
 * by kill -9, and one by a clean shutdown (SIGTERM), each resumed with
 * `mpmctl resume ID --watch` on a restarted daemon, give the very energy
 * series and snapshots of an uninterrupted run with the same solver
 * threads (compared as decoded doubles, bitwise); and the refusals: a
 * finished run, no such run, a run without a checkpoint, a damaged
 * checkpoint file (the run stays INTERRUPTED), a bad Case.checkpoint, and
 * the temp file a crash mid-write leaves (removed at start).
 */
#define _GNU_SOURCE
#include "mpm_kernels_avx2.h"
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* Steps of the test case, its snapshot and checkpoint intervals. */
#define R_STEPS 6000 /* a multiple of R_SNAP */
#define R_SNAP 2000
#define R_CKPT 200

/* The 2D block on two solver threads: energy every 10 steps, a recorded
 * snapshot every 2000 (and so at the end), a checkpoint every R_CKPT
 * steps (ck_steps < 0: Case.checkpoint left out; 0: checkpoints off). */
static json_t *resume_case(const char *name, int ck_steps)
{
    json_t *c = block2d(R_STEPS, 10, name);
    if (!c) return NULL;
    json_t *b = json_array_get(json_object_get(c, "bodies"), 0);
    json_object_set_new(b, "velocity", json_pack("[f,f]", 0.004, 0.002));
    json_object_set_new(b, "ppc", json_integer(4));
    json_object_set_new(c, "threads", json_integer(2));
    set_output(c, "snapshotEvery", json_integer(R_SNAP));
    set_output(c, "recordSnapshots", json_true());
    if (ck_steps >= 0)
        json_object_set_new(c, "checkpoint",
                            json_pack("{s:i, s:f}", "everySteps", ck_steps, "everyWallS", 0.0));
    return c;
}

/* Waits until run `id` shows a checkpoint at step >= step (while it runs);
 * its step, or -1 (the run ended first, or the wait timed out). */
static long long wait_checkpoint(const td_daemon *d, unsigned long long id, long long step,
                                 double timeout)
{
    double end = td_now() + timeout;
    while (td_now() < end) {
        json_t *r = show_json(d, id);
        long long k = r && json_object_get(r, "checkpointStep") ? jint(r, "checkpointStep") : -1;
        int live =
            r && (!strcmp(jstr(r, "status"), "RUNNING") || !strcmp(jstr(r, "status"), "QUEUED"));
        json_decref(r);
        if (k >= step) return k;
        if (!live && k < 0 && r) return -1;
        td_msleep(20);
    }
    return -1;
}

/* `mpmctl energy ID --csv`, parsed too; 0 or -1. */
static int energy_of(const td_daemon *d, unsigned long long id, char **csv, series *s)
{
    char ids[32];
    td_out o;
    snprintf(ids, sizeof ids, "%llu", id);
    if (td_ctl(d, 60, &o, "energy", ids, "--csv", NULL) || o.status) {
        td_out_free(&o);
        return -1;
    }
    /* (the harness owns o's buffers) */
    int rc = parse_csv(o.out, s);
    *csv = strdup(o.out);
    td_out_free(&o);
    return rc || !*csv ? -1 : 0;
}

/* `mpmctl snapshot ID --step STEP -o -` (CSV, exact doubles); NULL on failure. */
static char *snapshot_of(const td_daemon *d, unsigned long long id, long long step)
{
    char ids[32], st[32];
    td_out o;
    snprintf(ids, sizeof ids, "%llu", id);
    snprintf(st, sizeof st, "%lld", step);
    if (td_ctl(d, 60, &o, "snapshot", ids, "--step", st, "-o", "-", NULL) || o.status) {
        td_out_free(&o);
        return NULL;
    }
    char *t = strdup(o.out); /* (the harness owns o's buffers) */
    td_out_free(&o);
    return t;
}

/* Parses the doubles of a CSV text (after its header) into a malloc'd
 * array; the count in *n. */
static double *csv_doubles(const char *text, size_t *n)
{
    size_t cap = 1024, k = 0;
    double *v = malloc(cap * sizeof *v);
    *n = 0;
    if (!v) return NULL;
    /* p: at the separator before the next value */
    const char *p = strchr(text, '\n');
    while (p && p[1]) {
        char *end;
        double x = strtod(p + 1, &end);
        if (end == p + 1 || (*end && *end != ',' && *end != '\n')) break;
        if (k == cap) {
            double *nv = realloc(v, (cap *= 2) * sizeof *v);
            if (!nv) break;
            v = nv;
        }
        v[k++] = x;
        p = *end ? end : NULL;
    }
    *n = k;
    return v;
}

/* Run `id`'s energy series and its snapshots at 2000, 4000, 6000 equal the
 * reference run's bit for bit: every row (seq, step, t, every energy) as
 * text and the decoded doubles compared with memcmp. */
static int same_bits(const td_daemon *d, unsigned long long ref, unsigned long long id)
{
    char *ca = NULL, *cb = NULL;
    series a = {0}, b = {0};
    int ok = energy_of(d, ref, &ca, &a) == 0 && energy_of(d, id, &cb, &b) == 0;
    ok = ok && a.n == b.n && a.n == R_STEPS / 10 + 1 && consecutive(&b);
    size_t n = ok ? a.n : 0;
    ok = ok && !memcmp(a.step, b.step, n * sizeof *a.step) && !memcmp(a.t, b.t, n * sizeof *a.t) &&
         !memcmp(a.kinetic, b.kinetic, n * sizeof *a.kinetic) &&
         !memcmp(a.strain, b.strain, n * sizeof *a.strain) &&
         !memcmp(a.total, b.total, n * sizeof *a.total) && !strcmp(ca, cb);
    if (!ok)
        t_fail(__FILE__, __LINE__,
               "run %llu's energy series (%zu samples) differs from run %llu's (%zu)", id, b.n, ref,
               a.n);
    else
        TLOG("run %llu: %zu energy samples, bitwise equal to run %llu's (last: step %lld, t %.17g, "
             "total %.17g)",
             id, n, ref, b.step[n - 1], b.t[n - 1], b.total[n - 1]);
    series_free(&a);
    series_free(&b);
    free(ca);
    free(cb);
    for (long long step = R_SNAP; ok && step <= R_STEPS; step += R_SNAP) {
        char *sa = snapshot_of(d, ref, step), *sb = snapshot_of(d, id, step);
        size_t na = 0, nb = 0;
        double *va = sa ? csv_doubles(sa, &na) : NULL, *vb = sb ? csv_doubles(sb, &nb) : NULL;
        ok = va && vb && na == nb && na > 1000 && !memcmp(va, vb, na * sizeof *va) &&
             !strcmp(sa, sb);
        if (!ok)
            t_fail(__FILE__, __LINE__,
                   "run %llu's snapshot at step %lld differs (%zu / %zu values)", id, step, nb, na);
        else if (step == R_STEPS)
            TLOG("run %llu: snapshots every %d steps to %lld bitwise equal (%zu values at the end)",
                 id, R_SNAP, step, na);
        free(va);
        free(vb);
        free(sa);
        free(sb);
    }
    return ok;
}

/* The path of run id's checkpoint file (temp: its temp file). */
static void ckpt_path(const td_daemon *d, unsigned long long id, int temp, char *buf, size_t n)
{
    snprintf(buf, n, "%s.ckpt/run-%llu.ckpt%s", d->db, id, temp ? ".tmp" : "");
}

/* A run cut by kill -9 mid-run and one cut by SIGTERM, each resumed on a
 * restarted daemon, end bitwise equal to an uninterrupted run of the same
 * case (two solver threads). */
DTEST(daemon_resume_bits)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "2", NULL};
    char dir[300], path[400], ck[700];
    td_daemon d;
    td_out o;
    struct stat st;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(resume_case("resume", R_CKPT), dir, "case.json", path, sizeof path) == 0);

    /* 1: the reference, uninterrupted: its checkpoint is gone at the end */
    CHECK(td_ctl(&d, 300, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 1, "reference: exit %d, %s%s", o.status, o.out, o.err);
    td_out_free(&o);
    json_t *r = show_json(&d, 1);
    CHECK(r);
    int ok = !json_object_get(r, "checkpointStep") && !json_object_get(r, "resumes");
    json_decref(r);
    ckpt_path(&d, 1, 0, ck, sizeof ck);
    CHECKF(ok && stat(ck, &st) && errno == ENOENT,
           "a finished run keeps its checkpoint (record or file %s)", ck);

    /* 2: kill -9 once a checkpoint past 5 intervals is recorded */
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0 && job_of(o.out) == 2);
    td_out_free(&o);
    long long k = wait_checkpoint(&d, 2, 5 * R_CKPT, 120);
    CHECKF(k > 0, "run 2 recorded no checkpoint past step %d while it ran", 5 * R_CKPT);
    td_kill9(&d);
    if (td_start(&d, dir, extra)) return;
    r = show_json(&d, 2);
    CHECK(r);
    long long kk = jint(r, "checkpointStep"), steps = jint(r, "steps");
    double wall0 = jnum(r, "wallS");
    ok = !strcmp(jstr(r, "status"), "INTERRUPTED") && kk >= k && kk % R_CKPT == 0 && kk < R_STEPS &&
         jnum(r, "checkpointT") > 0;
    json_decref(r);
    {
        char want[64];
        snprintf(want, sizeof want, "checkpoint  step %lld, t ", kk);
        EXPECT_CTL(&d, 0, want, "show", "2");
    }
    CHECKF(ok, "run 2 after kill -9: checkpoint at %lld (seen %lld), steps %lld", kk, k, steps);
    TLOG("run 2 killed (-9) after its checkpoint at step %lld; restarted: INTERRUPTED at step "
         "%lld (its last stored sample), the recorded checkpoint at step %lld",
         k, steps, kk);
    CHECK(td_ctl(&d, 300, &o, "resume", "2", "--watch", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 2, "resume 2 --watch: exit %d, %s%s", o.status, o.out,
           o.err);
    td_out_free(&o);
    if (!same_bits(&d, 1, 2)) return;
    r = show_json(&d, 2);
    CHECK(r);
    ok = !strcmp(jstr(r, "status"), "FINISHED") && jint(r, "resumes") == 1 &&
         jint(r, "steps") == R_STEPS && !json_object_get(r, "checkpointStep") &&
         json_array_size(json_object_get(r, "snapshotSteps")) ==
             R_STEPS / R_SNAP + 1 && /* and step 0 */
         jnum(r, "wallS") > wall0;
    json_decref(r);
    CHECKF(ok, "run 2 after its resume is not FINISHED with one resume, no checkpoint and its "
               "wall time added up");
    EXPECT_CTL(&d, 0, "resumed     1 time", "show", "2");
    ckpt_path(&d, 2, 0, ck, sizeof ck);
    CHECKF(stat(ck, &st) && errno == ENOENT, "run 2's checkpoint file remains");
    EXPECT_CTL(&d, 1, "run 2 is FINISHED", "resume", "2");

    /* 3: a clean shutdown checkpoints the running job at its last step */
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0 && job_of(o.out) == 3);
    td_out_free(&o);
    CHECK(wait_checkpoint(&d, 3, 2 * R_CKPT, 120) > 0);
    CHECK(td_stop(&d) == 0);
    if (td_start(&d, dir, extra)) return;
    r = show_json(&d, 3);
    CHECK(r);
    kk = jint(r, "checkpointStep");
    steps = jint(r, "steps");
    ok = !strcmp(jstr(r, "status"), "INTERRUPTED") && kk == steps && kk > 0 && kk < R_STEPS;
    json_decref(r);
    CHECKF(ok, "run 3 after SIGTERM: checkpoint at %lld, steps %lld (want equal)", kk, steps);
    TLOG("run 3 stopped by SIGTERM at step %lld, its checkpoint there", kk);
    CHECK(td_ctl(&d, 300, &o, "resume", "3", NULL) == 0);
    CHECKF(o.status == 0 && job_of(o.out) == 3, "resume 3: exit %d, %s%s", o.status, o.out, o.err);
    td_out_free(&o);
    EXPECT_CTL(&d, 0, "FINISHED", "watch", "3");
    if (!same_bits(&d, 1, 3)) return;
    CHECK(td_stop(&d) == 0);
}

/* What Resume refuses, and what a crash mid-write leaves. */
DTEST(daemon_resume_refused)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "2", "--solver-threads", "1", NULL};
    char dir[300], path[400] = "", offp[400] = "", bad[400], ck[700], tmpf[700];
    td_daemon d;
    td_out o;
    struct stat st;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;

    /* a bad schedule is refused with its field */
    json_t *c = resume_case("bad", R_CKPT);
    CHECK(c);
    json_object_set_new(c, "checkpoint", json_pack("{s:f}", "everyWallS", -1.0));
    CHECK(write_case(c, dir, "bad.json", bad, sizeof bad) == 0);
    EXPECT_CTL(&d, 1, "checkpoint.everyWallS", "submit", bad);

    /* no such run */
    mpp_request rq = {.kind = MPP_REQ_RESUME, .id = 99};
    if (expect_not_found(&d, rq, "Resume of run 99", "runId")) return;
    EXPECT_CTL(&d, 1, "no run 99", "resume", "99");

    /* run 1 takes checkpoints, run 2 none (Case.checkpoint all 0); both
     * at rest, until stopped */
    for (int i = 0; i < 2; i++) {
        c = resume_case(i ? "off" : "long", i ? 0 : R_CKPT);
        CHECK(c);
        json_object_set_new(c, "steps", json_integer(LONG_STEPS));
        set_output(c, "snapshotEvery", json_integer(0));
        json_object_set_new(json_array_get(json_object_get(c, "bodies"), 0), "velocity",
                            json_pack("[f,f]", 0.0, 0.0));
        CHECK(write_case(c, dir, i ? "off.json" : "long.json", i ? offp : path, 400) == 0);
    }
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0 && job_of(o.out) == 1);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "submit", offp, NULL) == 0 && o.status == 0 && job_of(o.out) == 2);
    td_out_free(&o);
    CHECK(wait_checkpoint(&d, 1, R_CKPT, 60) > 0);
    CHECK(td_wait_steps(&d, 2, 500, 60) == 0);
    /* a running run is not resumed */
    EXPECT_CTL(&d, 1, "run 1 is RUNNING", "resume", "1");
    CHECK(td_stop(&d) == 0);

    /* a crash in the middle of a checkpoint's write leaves its temp file:
     * the next start removes it, and the last whole checkpoint is used */
    ckpt_path(&d, 1, 1, tmpf, sizeof tmpf);
    CHECK(td_write(tmpf, "half a checkpoint") == 0);
    if (td_start(&d, dir, extra)) return;
    CHECKF(stat(tmpf, &st) && errno == ENOENT, "the stray temp file %s remains", tmpf);
    ckpt_path(&d, 2, 0, ck, sizeof ck);
    CHECKF(stat(ck, &st) && errno == ENOENT, "run 2 (checkpoints off) has a checkpoint file");
    EXPECT_CTL(&d, 1, "run 2 has no checkpoint", "resume", "2");

    /* a damaged checkpoint: refused, the run stays INTERRUPTED with it */
    ckpt_path(&d, 1, 0, ck, sizeof ck);
    FILE *f = fopen(ck, "r+b");
    CHECKF(f, "run 1 has no checkpoint file %s", ck);
    CHECK(fseek(f, 100, SEEK_SET) == 0);
    int ch = fgetc(f);
    CHECK(ch != EOF && fseek(f, 100, SEEK_SET) == 0 && fputc(ch ^ 0x10, f) != EOF);
    CHECK(fclose(f) == 0);
    EXPECT_CTL(&d, 1, "checksum mismatch", "resume", "1");
    json_t *r = show_json(&d, 1);
    CHECK(r);
    int ok = !strcmp(jstr(r, "status"), "INTERRUPTED") && jint(r, "checkpointStep") > 0 &&
             !json_object_get(r, "resumes");
    json_decref(r);
    CHECKF(ok, "run 1 changed after a refused resume");
    /* a truncated one too */
    CHECK(truncate(ck, 40) == 0);
    EXPECT_CTL(&d, 1, "damaged", "resume", "1");
    CHECK(td_stop(&d) == 0);
}

/* mpmd --portable-kernels: every job runs on the portable
 * kernels.  The same case (the coarse disks, 4000 steps) through a
 * default daemon and through one with the flag; each run's last energy
 * sample equals, bit for bit, an in-process run of the same case on the
 * kernels the daemon names in its ready line (AVX2+FMA where the CPU has
 * them, else portable; portable with the flag); where the CPU has AVX2 and
 * the build's AVX2 kernels fuse multiply-adds the two runs' bits differ
 * (the flag took effect). */
DTEST(daemon_portable_kernels)
{
    const char *tmp = t_tmpdir();
    json_t *c = example("disks2d_coarse");
    CHECK(c);
    set_output(c, "energyEvery", json_integer(100));
    char *text = json_dumps(c, JSON_COMPACT);
    CHECK(text);
    double last[2][2] = {{0}};
    long long step[2] = {0, 0};
    int ok = 1;
    for (int k = 0; ok && k < 2; k++) {
        char dir[300], path[400], *csv = NULL;
        const char *extra[] = {"--workers", "1", k ? "--portable-kernels" : NULL, NULL};
        td_daemon d;
        td_out o;
        series s = {0};
        snprintf(dir, sizeof dir, "%s/d%d", tmp, k);
        if (td_start(&d, dir, extra)) {
            ok = 0;
            break;
        }
        ok = write_case(json_incref(c), dir, "case.json", path, sizeof path) == 0 &&
             td_ctl(&d, 120, &o, "submit", path, "--watch", NULL) == 0;
        ok = ok && o.status == 0 && job_of(o.out) == 1;
        if (ok) td_out_free(&o);
        ok = ok && energy_of(&d, 1, &csv, &s) == 0 && s.n > 10;
        if (ok) {
            step[k] = s.step[s.n - 1];
            last[k][0] = s.kinetic[s.n - 1];
            last[k][1] = s.strain[s.n - 1];
        }
        series_free(&s);
        free(csv);
        /* the ready line names the kernels */
        const char *want =
            k || !mpm_kernels_avx2_available() ? "portable kernels" : "avx2-fma kernels";
        size_t loglen = 0;
        char *log = td_slurp(d.log, &loglen);
        int named = log && strstr(log, want);
        free(log);
        ok = td_stop(&d) == 0 && ok;
        CHECKF(ok, "daemon %d: the run failed", k);
        CHECKF(named, "daemon %d's log does not say '%s'", k, want);
        TLOG("daemon %s: %s; step %lld: kinetic %.17g, strain %.17g",
             k ? "--portable-kernels" : "(default)", want, step[k], last[k][0], last[k][1]);
    }
    CHECK(ok);
    /* the same case in-process, on each daemon's kernels */
    for (int k = 0; k < 2; k++) {
        mpp_case *sc = NULL;
        char err[256];
        CHECKF(td_case_load(text, strlen(text), &sc, err, sizeof err) == 0, "%s", err);
        sc->c.kernels = k ? MPM_KERNELS_PORTABLE : MPM_KERNELS_AUTO;
        mpm_error me;
        mpm_sim *sim = mpm_sim_new(&sc->c, &sc->info, &me);
        /* as the daemon samples: the energies asked for ahead of the step
         * (summed in its passes) */
        int rc = sim ? mpm_sim_run(sim, step[k] - 1) : -1;
        if (!rc) {
            mpm_sim_want_energy(sim);
            rc = mpm_sim_step(sim);
        }
        mpm_energy e = {0};
        if (sim) mpm_sim_energy(sim, &e);
        mpm_sim_destroy(&sim);
        mpp_case_destroy(&sc);
        CHECKF(rc == 0, "in-process run %d: %d", k, rc);
        CHECKF(!memcmp(&e.kinetic, &last[k][0], sizeof e.kinetic) &&
                   !memcmp(&e.strain, &last[k][1], sizeof e.strain),
               "in-process %s: kinetic %.17g, strain %.17g; the daemon's %.17g, %.17g",
               k ? "portable" : "auto", e.kinetic, e.strain, last[k][0], last[k][1]);
    }
    free(text);
    json_decref(c);
    TLOG("each daemon's last sample equals the in-process run on its kernels, bit for bit");
    /* (the sanitizer builds' AVX2 families form no FMAs: the same bits) */
    if (mpm_kernels_avx2_available() && mpm_kernels_avx2_fuses())
        CHECKF(memcmp(last[0], last[1], sizeof last[0]),
               "the AVX2 and the portable daemons gave the same bits");
}
