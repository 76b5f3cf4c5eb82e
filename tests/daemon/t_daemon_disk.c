/*
 * t_daemon_disk.c - a real mpmd on a full disk, and its checkpoints under
 * the disk budgets.  The database lives on a small tmpfs mounted in the
 * test's directory (its log and sockets outside it), filled to the last
 * byte by a filler file and freed by deleting it; without the right to
 * mount (not root) the tests say so and pass without running.
 *  - daemon_disk_submit_full: submits onto a full disk (no reserve): every
 *    acknowledged job is found and ends, every other submission gets an
 *    error naming the cause, never a job id; once space is freed they are
 *    accepted again;
 *  - daemon_disk_end_kept: a run the full disk stops ends FAILED with the
 *    reason, which survives a kill -9 and a restart on the still-full disk
 *    (the side file of kept ends), and is written once space returns;
 *  - daemon_disk_restart_full: a restart on a disk full to the last byte
 *    (the reserve makes room for SQLite's index) serves reads and refuses
 *    submits with a clear error until space is freed;
 *  - daemon_disk_checkpoint_budget: checkpoints count against
 *    --job-max-disk-mb (the bytes of the checkpoint directory measured),
 *    and --checkpoint-share spaces a case's every-step checkpoints.
 * rel_disk_submits is the probe at full size (MPM_STRESS=full).
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"
#include "t_stress.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

/* ---- a small disk ------------------------------------------------------------------ */

/* Mounts a tmpfs of kib KiB at mnt (created): 0; 1 when mounting is not
 * allowed here (the caller skips); -1 after failing the test. */
static int disk_mount(const char *mnt, int kib)
{
    char opt[64];
    mkdir(mnt, 0700);
    snprintf(opt, sizeof opt, "size=%dk,mode=0700", kib);
    if (mount("tmpfs", mnt, "tmpfs", 0, opt) == 0) return 0;
    if (errno == EPERM) {
        TLOG("skipped: mounting a tmpfs needs root (%s)", strerror(errno));
        return 1;
    }
    t_fail(__FILE__, __LINE__, "mount tmpfs at %s: %s", mnt, strerror(errno));
    return -1;
}

/* Detaches the tmpfs (a daemon may still hold files on it). */
static void disk_umount(const char *mnt)
{
    if (umount2(mnt, MNT_DETACH)) TLOG("umount %s: %s", mnt, strerror(errno));
}

/* Fills the file system of dir to its last byte with dir/filler (grown if
 * it exists): the bytes added. */
static long long disk_fill(const char *dir)
{
    char path[400];
    static char buf[65536];
    long long n = 0;
    snprintf(path, sizeof path, "%s/filler", dir);
    int fd = open(path, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0600);
    if (fd < 0) return 0;
    for (size_t chunk = sizeof buf; chunk >= 1; chunk /= 16) {
        ssize_t w;
        while ((w = write(fd, buf, chunk)) > 0) n += w;
    }
    close(fd);
    return n;
}

/* Gives back the last `bytes` of the filler (a nearly full disk). */
static void disk_slack(const char *dir, long long bytes)
{
    char path[400];
    struct stat st;
    snprintf(path, sizeof path, "%s/filler", dir);
    if (stat(path, &st) == 0 && truncate(path, st.st_size > bytes ? st.st_size - bytes : 0))
        TLOG("truncate %s: %s", path, strerror(errno));
}

static void disk_free(const char *dir)
{
    char path[400];
    snprintf(path, sizeof path, "%s/filler", dir);
    unlink(path);
}

/* Bytes allocated to the files of a directory. */
static long long dir_bytes(const char *dir)
{
    DIR *d = opendir(dir);
    long long n = 0;
    if (!d) return 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        char p[600];
        struct stat st;
        snprintf(p, sizeof p, "%s/%s", dir, e->d_name);
        if (e->d_name[0] != '.' && stat(p, &st) == 0 && S_ISREG(st.st_mode))
            n += (long long)st.st_blocks * 512;
    }
    closedir(d);
    return n;
}

/* Starts mpmd in dir with its database on the disk mounted at dir/disk. */
static int start_on_disk(td_daemon *d, const char *dir, const char *const *more)
{
    char db[300];
    const char *args[24];
    int n = 0;
    if (snprintf(db, sizeof db, "%s/disk/mpmd.db", dir) >= (int)sizeof db) return -1;
    args[n++] = "--db";
    args[n++] = db;
    args[n++] = "--workers";
    args[n++] = "1";
    args[n++] = "--verbose";
    for (int i = 0; more && more[i] && n < 23; i++) args[n++] = more[i];
    args[n] = NULL;
    if (td_start(d, dir, args)) return -1;
    snprintf(d->db, sizeof d->db, "%s", db);
    return 0;
}

/* Counts the lines of the daemon's log containing s. */
static int log_count(const td_daemon *d, const char *s)
{
    size_t len = 0;
    char *text = td_slurp(d->log, &len);
    int n = 0;
    for (const char *p = text; p && (p = strstr(p, s)); p += strlen(s)) n++;
    free(text);
    return n;
}

/* Waits up to timeout s for the daemon's log to contain s. */
static int log_wait(const td_daemon *d, const char *s, double timeout)
{
    for (double end = td_now() + timeout; td_now() < end; td_msleep(50))
        if (log_count(d, s) > 0) return 0;
    return -1;
}

/* "a run's record lost" or "no new work": what a refused submission says. */
static int names_disk(const char *msg)
{
    return strstr(msg, "could not be recorded") || strstr(msg, "cannot take new work");
}

/* ---- submissions on a full disk ----------------------------------------------------- */

/* Submits `tries` jobs onto a nearly full disk (no reserve: each may
 * reach the commit); *acked and *refused count the outcomes, *lost the acknowledged
 * jobs not found (must be 0).  Fails the test otherwise. */
static void submit_probe(const char *name, int tries, int *acked, int *refused, int *lost)
{
    char dir[300], disk[320], path[400], st[32];
    const char *more[] = {"--disk-reserve-mb", "0", NULL};
    unsigned long long ids[200];
    td_daemon d;
    td_out o;
    *acked = *refused = *lost = 0;
    snprintf(dir, sizeof dir, "%s/%s", t_tmpdir(), name);
    snprintf(disk, sizeof disk, "%s/disk", dir);
    mkdir(dir, 0700);
    int m = disk_mount(disk, 4096);
    if (m) return;
    if (start_on_disk(&d, dir, more)) goto out;
    if (write_case(bar_steps(20, 1), dir, "bar.json", path, sizeof path)) goto out;
    if (td_ctl(&d, 30, &o, "submit", path, NULL) || o.status) {
        t_fail(__FILE__, __LINE__, "first submit: %s%s", o.out, o.err);
        td_out_free(&o);
        goto out;
    }
    td_out_free(&o);
    if (td_wait_status(&d, 1, "FINISHED", 30, st, sizeof st)) {
        t_fail(__FILE__, __LINE__, "run 1: %s", st);
        goto out;
    }
    /* nearly full: the first submissions fit, the disk fills under the
     * next ones and their jobs */
    long long filled = disk_fill(disk);
    disk_slack(disk, 128 * 1024);
    TLOG("disk filled: %lld bytes added, 128 KiB left", filled);
    int n_ids = 0;
    for (int i = 0; i < tries && i < 200; i++) {
        if (td_ctl(&d, 30, &o, "submit", path, NULL) || o.status < 0) {
            t_fail(__FILE__, __LINE__, "try %d: mpmctl did not answer", i);
            td_out_free(&o);
            goto out;
        }
        unsigned long long id = job_of(o.out);
        if (o.status == 0 && id) {
            ids[n_ids++] = id;
            (*acked)++;
        } else if (!id && names_disk(o.err)) {
            (*refused)++;
        } else {
            t_fail(__FILE__, __LINE__, "try %d: status %d, out '%s', err '%s'", i, o.status, o.out,
                   o.err);
            td_out_free(&o);
            goto out;
        }
        if (i == 0 && !id) TLOG("try 0 refused: %s", o.err);
        td_out_free(&o);
    }
    /* every job acknowledged is there and ends (its writes may fail: a
     * run the disk stops ends FAILED, with the reason) */
    for (int i = 0; i < n_ids; i++) {
        if (td_wait_status(&d, ids[i], "FINISHED|FAILED", 60, st, sizeof st)) {
            TLOG("acknowledged job %llu: '%s'", ids[i], st);
            (*lost)++;
        }
    }
    /* space freed: submissions are accepted again within a few seconds */
    disk_free(disk);
    int ok = 0;
    for (double end = td_now() + 15; !ok && td_now() < end; td_msleep(200)) {
        if (td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0 && job_of(o.out)) ok = 1;
        td_out_free(&o);
    }
    if (!ok) t_fail(__FILE__, __LINE__, "no submission accepted after the disk was freed");
    /* and after a restart every acknowledged run is in the database */
    td_stop(&d);
    if (start_on_disk(&d, dir, more)) goto out;
    for (int i = 0; i < n_ids; i++) {
        json_t *r = show_json(&d, ids[i]);
        if (!r) {
            TLOG("acknowledged run %llu not in the database after a restart", ids[i]);
            (*lost)++;
        }
        json_decref(r);
    }
out:
    disk_umount(disk);
}

DTEST(daemon_disk_submit_full)
{
    int acked, refused, lost;
    submit_probe("probe", 10, &acked, &refused, &lost);
    TLOG("10 submissions on a full disk: %d acknowledged, %d refused with the cause, %d "
         "acknowledged but lost",
         acked, refused, lost);
    CHECKF(lost == 0, "%d acknowledged jobs lost", lost);
    CHECKF(t_failed() || acked + refused == 10, "%d + %d answers", acked, refused);
}

DTEST(rel_disk_submits)
{
    int tries = t_stress_full() ? 100 : 5, acked, refused, lost;
    submit_probe("rel", tries, &acked, &refused, &lost);
    printf("reliability: fulldisk submits=%d acked=%d refused=%d lost=%d\n", tries, acked, refused,
           lost);
    CHECKF(lost == 0, "%d acknowledged jobs lost", lost);
}

/* ---- a run's end on a full disk ------------------------------------------------------ */

/* The run's status and error from `show` (status "" when not readable). */
static void show_status(const td_daemon *d, unsigned long long id, char *st, size_t n, char *err,
                        size_t en)
{
    json_t *r = show_json(d, id);
    snprintf(st, n, "%s", r ? jstr(r, "status") : "");
    snprintf(err, en, "%s", r ? jstr(r, "error") : "");
    json_decref(r);
}

static void end_kept(const char *dir, const char *disk)
{
    const char *more[] = {"--disk-reserve-mb", "0", "--job-max-disk-mb", "0", NULL};
    char path[400], st[32], err[600];
    td_daemon d;
    td_out o;
    if (start_on_disk(&d, dir, more)) return;
    CHECK(write_case(long_case(1), dir, "long.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0);
    td_out_free(&o);
    CHECK(td_wait_steps(&d, 1, 50, 30) == 0);
    TLOG("disk filled under a running job: %lld bytes", disk_fill(disk));
    CHECKF(td_wait_status(&d, 1, "FAILED", 30, st, sizeof st) == 0, "job 1: %s", st);
    /* its end could not be written: kept, and shown */
    CHECK(log_wait(&d, "the end of run 1 (failed) is kept", 10) == 0);
    show_status(&d, 1, st, sizeof st, err, sizeof err);
    TLOG("on the full disk: run 1 %s (%s)", st, err);
    CHECKF(!strcmp(st, "FAILED") && strstr(err, "disk full"), "show 1: %s '%s'", st, err);
    /* the worst case: killed, restarted on the still-full disk */
    td_kill9(&d);
    CHECK(start_on_disk(&d, dir, more) == 0);
    show_status(&d, 1, st, sizeof st, err, sizeof err);
    TLOG("restarted on the full disk: run 1 %s (%s)", st, err);
    CHECKF(!strcmp(st, "FAILED") && strstr(err, "disk full"), "show 1: %s '%s'", st, err);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    TLOG("a submission on the full disk: exit %d: %s", o.status, o.err);
    int clear = o.status != 0 && !job_of(o.out) && names_disk(o.err);
    td_out_free(&o);
    CHECKF(clear, "submission on a full disk not refused clearly");
    /* space returns: the end is written (a restart reads it from the
     * database, the side file empty) */
    disk_free(disk);
    CHECK(log_wait(&d, "recorded 1 run end(s) kept", 10) == 0);
    td_stop(&d);
    int kept = log_count(&d, "run end(s) a full disk kept");
    CHECK(start_on_disk(&d, dir, more) == 0);
    CHECK(log_count(&d, "run end(s) a full disk kept") == kept);
    show_status(&d, 1, st, sizeof st, err, sizeof err);
    TLOG("after space was freed and a restart: run 1 %s (%s)", st, err);
    CHECKF(!strcmp(st, "FAILED") && strstr(err, "disk full"), "show 1: %s '%s'", st, err);
}

DTEST(daemon_disk_end_kept)
{
    char dir[300], disk[320];
    snprintf(dir, sizeof dir, "%s/end", t_tmpdir());
    snprintf(disk, sizeof disk, "%s/disk", dir);
    mkdir(dir, 0700);
    if (disk_mount(disk, 4096)) return;
    end_kept(dir, disk);
    disk_umount(disk);
}

/* ---- a restart on a full disk -------------------------------------------------------- */

static void restart_full(const char *dir, const char *disk)
{
    char path[400], st[32], err[600];
    td_daemon d;
    td_out o;
    if (start_on_disk(&d, dir, NULL)) return;
    CHECK(write_case(bar_steps(20, 1), dir, "bar.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 1, "FINISHED", 30, st, sizeof st) == 0);
    td_stop(&d);
    TLOG("disk filled while mpmd was stopped: %lld bytes", disk_fill(disk));
    CHECK(start_on_disk(&d, dir, NULL) == 0);
    /* reads are served */
    show_status(&d, 1, st, sizeof st, err, sizeof err);
    CHECKF(!strcmp(st, "FINISHED"), "show 1 on a full disk: '%s'", st);
    CHECK(td_ctl(&d, 30, &o, "runs", NULL) == 0 && o.status == 0 && strstr(o.out, "FINISHED"));
    td_out_free(&o);
    /* submissions are refused, naming the cause, never given an id */
    for (int i = 0; i < 3; i++) {
        CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
        int clear = o.status != 0 && !job_of(o.out) && names_disk(o.err) && strstr(o.err, "disk");
        if (i == 0) TLOG("a submission on the full disk: %s", o.err);
        td_out_free(&o);
        CHECKF(clear, "submission %d on a full disk not refused clearly", i);
    }
    /* space returns: accepted again, within the store's retry */
    disk_free(disk);
    int ok = 0;
    double t0 = td_now();
    for (double end = t0 + 15; !ok && td_now() < end; td_msleep(200)) {
        if (td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0 && job_of(o.out)) ok = 1;
        td_out_free(&o);
    }
    TLOG("space freed: a submission accepted after %.1f s", td_now() - t0);
    CHECK(ok);
}

DTEST(daemon_disk_restart_full)
{
    char dir[300], disk[320];
    snprintf(dir, sizeof dir, "%s/restart", t_tmpdir());
    snprintf(disk, sizeof disk, "%s/disk", dir);
    mkdir(dir, 0700);
    if (disk_mount(disk, 4096)) return;
    restart_full(dir, disk);
    disk_umount(disk);
}

/* ---- checkpoints and the disk budgets ------------------------------------------------ */

DTEST(daemon_disk_checkpoint_budget)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--verbose", "--job-max-disk-mb", "1", NULL};
    char dir[300], path[400], ckdir[400], st[32];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/ckpt", tmp);
    if (td_start(&d, dir, extra)) return;
    snprintf(ckdir, sizeof ckdir, "%s.ckpt", d.db);
    /* job 1: a checkpoint of about 5 MB every step, under a 1 MiB budget:
     * refused before it is written, the job FAILED naming the budget */
    json_t *c = snap_case("big", 200);
    CHECK(c);
    json_object_del(c, "output");
    set_output(c, "energyEvery", json_integer(10));
    json_object_set_new(c, "checkpoint",
                        json_pack("{s:i, s:f}", "everySteps", 1, "everyWallS", 0.0));
    CHECK(write_case(c, dir, "big.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0);
    td_out_free(&o);
    long long peak = 0;
    for (double end = td_now() + 60; td_now() < end; td_msleep(20)) {
        long long b = dir_bytes(ckdir);
        if (b > peak) peak = b;
        if (td_job_status(&d, 1, st, sizeof st, NULL) == 0 && strcmp(st, "RUNNING") &&
            strcmp(st, "QUEUED"))
            break;
    }
    json_t *r = show_json(&d, 1);
    CHECK(r);
    TLOG("job 1 (5 MB checkpoints, --job-max-disk-mb 1): %s after %lld steps, checkpoint bytes "
         "on disk at most %lld: %s",
         jstr(r, "status"), jint(r, "steps"), peak, jstr(r, "error"));
    int ok = !strcmp(jstr(r, "status"), "FAILED") && strstr(jstr(r, "error"), "checkpoint") &&
             strstr(jstr(r, "error"), "--job-max-disk-mb");
    json_decref(r);
    CHECKF(ok, "job 1 not stopped by the budget");
    CHECKF(peak <= 1048576, "%lld checkpoint bytes on disk, budget 1 MiB", peak);

    /* job 2: small checkpoints every step for about 3 s: within the
     * budget, and taking at most --checkpoint-share (10 %) of the wall
     * time (the durations the daemon logs, summed) */
    c = long_case(100000);
    CHECK(c);
    json_object_set_new(c, "checkpoint",
                        json_pack("{s:i, s:f}", "everySteps", 1, "everyWallS", 0.0));
    CHECK(write_case(c, dir, "small.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0);
    td_out_free(&o);
    CHECK(td_wait_steps(&d, 2, 100, 30) == 0);
    double t0 = td_now();
    peak = 0;
    while (td_now() < t0 + 3) {
        long long b = dir_bytes(ckdir);
        if (b > peak) peak = b;
        td_msleep(20);
    }
    long long steps = 0;
    CHECK(td_job_status(&d, 2, st, sizeof st, &steps) == 0);
    CHECK(td_ctl(&d, 30, &o, "cancel", "2", NULL) == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, 2, "CANCELLED", 30, st, sizeof st) == 0);
    double wall = td_now() - t0 + 0.5, spent = 0, longest = 0;
    int written = 0, close = 0;
    size_t len = 0;
    char *text = td_slurp(d.log, &len);
    /* each line "<date>T<hh:mm:ss.mmm>Z ... job 2: checkpoint at step K:
     * B bytes in S s" is logged as the checkpoint ends; the rule is that
     * the next one starts at least (1 - F) / F = 9 times the last one's
     * duration after it ended (F = --checkpoint-share, 0.1), checked on
     * the timestamps pair by pair (their rounding to 1 ms and the
     * durations' to 0.5 ms allowed for), so that it holds however loaded
     * the machine is */
    double prev_end = -1, prev_secs = 0;
    for (const char *q = text; q && (q = strstr(q, "job 2: checkpoint at step ")); q++) {
        long long k, bytes;
        double secs;
        if (sscanf(q, "job 2: checkpoint at step %lld: %lld bytes in %lf s", &k, &bytes, &secs) !=
            3)
            continue;
        const char *ln = q;
        while (ln > text && ln[-1] != '\n') ln--;
        int hh, mm;
        double ss, end = -1;
        if (sscanf(ln, "%*10[0-9-]T%d:%d:%lfZ", &hh, &mm, &ss) == 3) end = hh * 3600 + mm * 60 + ss;
        if (end >= 0 && prev_end >= 0) {
            double gap = end - secs - prev_end;
            if (gap < 0) gap += 86400; /* past midnight */
            if (gap < 9 * (prev_secs - 0.0005) - 0.002) close++;
        }
        prev_end = end;
        prev_secs = secs;
        written++;
        spent += secs;
        if (secs > longest) longest = secs;
    }
    free(text);
    TLOG("job 2 (checkpoint every step): %lld steps, %d checkpoints written in about %.1f s, "
         "taking %.3f s (longest %.4f s), checkpoint bytes on disk at most %lld",
         steps, written, wall, spent, longest, peak);
    CHECKF(written >= 1 && (double)written < (double)steps / 100, "%d checkpoints", written);
    CHECKF(close == 0,
           "%d of %d checkpoints started sooner than 9 times the last one's "
           "duration after it",
           close, written);
    CHECKF(peak <= 1048576, "%lld checkpoint bytes on disk", peak);
    CHECKF(dir_bytes(ckdir) == 0, "the cancelled run's checkpoint left %lld bytes",
           dir_bytes(ckdir));
}
