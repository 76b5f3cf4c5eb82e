/*
 * t_daemon_util.h - helpers shared by the daemon tests (t_daemon*.c): case
 * builders from the examples, energy CSV parsing, JSON field access, and
 * waits on a daemon's state.
 */
#ifndef T_DAEMON_UTIL_H
#define T_DAEMON_UTIL_H

#include <jansson.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <sys/types.h>

#include "mpp_msg.h"
#include "t_daemon.h"

/* An energy series read back from CSV. */
typedef struct {
    size_t n;
    long long *seq, *step;
    double *t, *kinetic, *strain, *total;
} series;

/* Steps of a case that runs until it is cancelled or interrupted. */
#define LONG_STEPS 99000000LL

void series_free(series *s);

/* Parses mpmctl's energy CSV (header + rows); 0 or -1 with the reason. */
int parse_csv(const char *text, series *s);

/* seq[i] == i for every row (complete, ordered, no duplicate). */
int consecutive(const series *s);

double rel_diff(double a, double b);

/* Case files: an example with a few members replaced. */
json_t *example(const char *name);

/* Sets output.<key> = v (creating output). */
void set_output(json_t *c, const char *key, json_t *v);

/* The 1D bar running `steps` steps (not endTime), energy every `every`. */
json_t *bar_steps(long long steps, int every);

/* A job that runs until cancelled: the bar at rest (nothing moves, so
 * nothing drifts out of the grid however long it runs), 99 million steps. */
json_t *long_case(int every);

/* A 2D elastic block drifting in a box: 256 particles. */
json_t *block2d(long long steps, int every, const char *name);

/* Two 1D particles under uniaxial compression: sxx = -3000 at rest, so
 * the pressure is 1000 (mean stress -1000) exactly at step 0 and stays
 * within 1 % of it over the 5 steps (dt 1e-5: measured 998.5 at step 5,
 * the free ends starting to unload); snapshots every 2 steps, recorded. */
#define COMPRESSED_PRESSURE 1000.0
json_t *compressed1d(const char *name);

/* Writes case c (consumed) to dir/file; path out. */
int write_case(json_t *c, const char *dir, const char *file, char *path, size_t n);

/* "job N" in text -> N (0 if absent). */
unsigned long long job_of(const char *text);

/* A member of a JSON text line (parsed), as text: string value or number. */
json_t *parse_line(const char *line);

long long jint(const json_t *o, const char *key);

const char *jstr(const json_t *o, const char *key);

double jnum(const json_t *o, const char *key);

/* Number of lines of a text. */
size_t count_lines(const char *t);

/* mpmctl show ID --json, parsed (NULL on failure). */
json_t *show_json(const td_daemon *d, unsigned long long id);

/* Waits up to timeout s until the daemon's log (mpmd --verbose) shows that
 * job's stream subscribed ("job N: stream watched"); 0 or -1. */
int wait_watched(const td_daemon *d, unsigned long long job, double timeout);

/* Waits up to timeout s until a background client's output file has at
 * least n lines; 0 or -1. */
int wait_lines(const td_bg *b, size_t n, double timeout);

/* The error of a raw request for id: 0 if it is NOT_FOUND naming `field`,
 * with a message naming the id; else fails the test. */
int expect_not_found(const td_daemon *d, mpp_request rq, const char *what, const char *field);

/* Expects mpmctl ARGS to exit with `status` and its stdout (or, for a
 * non-zero status, its stdout or stderr) to contain want. */
int expect_ctl(const td_daemon *d, int status, const char *want, const char *const *args);
#define EXPECT_CTL(d, st, want, ...)              \
    do {                                          \
        const char *a_[] = {__VA_ARGS__, NULL};   \
        if (!expect_ctl(d, st, want, a_)) return; \
    } while (0)

/* A line of /proc/PID/status ("VmHWM:", "VmRSS:") in kB, or -1. */
long proc_kb(pid_t pid, const char *key);
/* Waits (300 s at most) for job to end: 0 when it FINISHED, with its
 * RunInfo.wallS in *wall and mpmd's peak RSS so far (VmHWM, kB) in *hwm;
 * else a test failure naming the status it ended with, and -1. */
int td_job_peak(const td_daemon *d, unsigned long long job, double *wall, long *hwm);

/* A SUB on the daemon's stream subscribed to job's topic, receiving at
 * most hwm messages into its queue (a watcher that stalls stalls there);
 * NULL after failing the test. */
void *subscribe(void *zctx, const td_daemon *d, unsigned long long job, int hwm);

/* The snapshot-every-step job: a 2D block at rest, 57600 particles (h =
 * 0.005, 2x2 per cell), every field: 5.5 MB per snapshot, `steps` steps. */
json_t *snap_case(const char *name, long long steps);

/* Submits the good 2D case (td_good2d) with `from` patched into `to` as a
 * raw request; the reply in *reply (caller frees).  As td_request. */
int submit_patched(const td_daemon *d, const char *from, const char *to, json_t **reply);

/* 1 when the daemon answers a raw Ping with a Pong within 10 s. */
int ping_ok(const td_daemon *d);

/* A crafted Request { schema_version 1, submit { case { nbodies empty
 * bodies } } }: 2 bytes per Body on the wire, some 90 once unpacked (the
 * daemon's unpack budget refuses it).  malloc'd, *n bytes; NULL if out of
 * memory. */
uint8_t *inflated_request(size_t nbodies, size_t *n);

/* A full disk (t_daemon_bounds.c): a daemon in t_tmpdir()/name whose
 * file size is limited (RLIMIT_FSIZE) while a job records snapshots: the
 * job ends FAILED with the reason, its watcher is told, the finished run
 * stays intact and a restart finds it so.  Fails the test otherwise. */
void disk_full_scenario(const char *name);

/* Room for an error text in the daemon tests. */
#define ERRLEN 1024

/* 1 if the daemon's log contains s. */
int log_has(const td_daemon *d, const char *s);

/* ---- memory and responsiveness of a daemon under load ---- */

/* td_start; under ASan freed blocks wait in a quarantine (up to 256 MB)
 * before they are reused: the daemon gets 16 MB, so that its memory
 * measures what it holds, not what it freed. */
int td_start_measured(td_daemon *d, const char *dir, const char *const *extra);

/* Resets the daemon's VmHWM to its current RSS (Linux >= 4.0); 0 or -1. */
int reset_hwm(pid_t pid);
/* Waits until the daemon's RSS has not grown for `quiet` seconds (it has
 * digested what was sent), at most `limit` s. */
void settle(pid_t pid, double quiet, double limit);
/* Waits up to limit s for VmRSS to fall to at most kb; returns the last
 * VmRSS read. */
long wait_rss_below(pid_t pid, long kb, double limit);

/* A client connected before the attack that pings every 20 ms and keeps
 * the slowest answer (max_s, pings, lost: read after pinger_stop()). */
typedef struct {
    char ep[320];
    atomic_int stop;
    atomic_int state; /* 0 starting, 1 its first ping answered, -1 failed */
    double max_s;     /* slowest reply (a lost one counts as its 10 s wait) */
    int pings, lost;
    int fresh; /* each ping on a new connection (the handshake timed too) */
    pthread_t th;
} pinger;
/* Starts the pinger (fresh: a new connection for each ping, else one kept
 * open) and waits for its first answer: 0, or -1 (test
 * failed, reported). */
int pinger_start(pinger *p, const td_daemon *d, int fresh);
void pinger_stop(pinger *p);

#endif
