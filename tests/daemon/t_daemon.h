/*
 * t_daemon.h - the harness of the daemon's integration tests
 * (t_daemon*.c): real `mpmd` processes on ipc:// endpoints in the test's
 * temporary directory with a real SQLite file there, the real `mpmctl` run
 * as a process with its output captured, and raw requests on a DEALER for
 * what mpmctl would refuse to send.  The binaries come from MPMD_BIN and
 * MPMCTL_BIN (make test / make test-quick set them); a missing one fails
 * the test.  Every wait is bounded; DTEST() wraps a test so that whatever
 * CHECK returns early, the daemons and background clients it started are
 * stopped (SIGTERM, then SIGKILL) and their logs shown on failure.
 */
#ifndef T_DAEMON_H
#define T_DAEMON_H

#include <stddef.h>
#include <sys/types.h>

#include <jansson.h>
#include <zmq.h>

#include "mpp_msg.h"
#include "t.h"

/* A test whose daemons and clients are cleaned up however it returns. */
#define DTEST(name)             \
    static void d_##name(void); \
    TEST(name)                  \
    {                           \
        d_##name();             \
        td_cleanup();           \
    }                           \
    static void d_##name(void)

/* A running mpmd. */
typedef struct {
    pid_t pid;     /* 0 when not running */
    char dir[256]; /* its directory (endpoint, database, log) */
    char ep[320];  /* ipc://DIR/ctl */
    char db[320];  /* DIR/mpmd.db */
    char log[320]; /* DIR/mpmd.log: its stdout and stderr, appended */
} td_daemon;

/* Captured output of an mpmctl run. */
typedef struct {
    int status;      /* exit status; 128 + signal if killed; -1 if it timed out */
    char *out, *err; /* NUL-terminated stdout / stderr */
    double secs;     /* how long it ran */
} td_out;

/* A background mpmctl writing to files. */
typedef struct {
    pid_t pid;
    char out_path[320], err_path[320];
    double t0;
} td_bg;

/* Kills and reaps everything this test started; prints daemon logs if the
 * test failed; forgets the CURVE keys.  Called by DTEST. */
void td_cleanup(void);

/* CURVE for the raw requests (td_request, td_frames, and so td_start's
 * Ping): the server's public key and the client's keypair in Z85; NULL
 * server_pub: none (the default). */
void td_set_curve(const char *server_pub, const char *client_pub, const char *client_sec);

/* The binary named by an environment variable; fails the test (NULL) if it
 * is unset or not executable. */
const char *td_bin(const char *env);

/* Starts mpmd in dir (created if needed) on ipc://dir/ctl with --db
 * dir/mpmd.db, the extra arguments (NULL-terminated list, may be NULL) and
 * waits until it answers Ping (up to 20 s).  Returns 0, or -1 after
 * failing the test (with the log). */
int td_start(td_daemon *d, const char *dir, const char *const *extra);
/* The same on endpoint ep (NULL: ipc://dir/ctl). */
int td_start_ep(td_daemon *d, const char *dir, const char *ep, const char *const *extra);
/* A loopback TCP port for a test's daemon, from the test process's pid and
 * salt: even, in 21000..31998, so that it and the few ports above it (a
 * second endpoint, a second daemon) stay below
 * the kernel's ephemeral range (32768 and up), where a client connection's
 * local port, bound without SO_REUSEADDR, made a daemon's bind fail with
 * "Address already in use". */
int td_tcp_port(int salt);
/* SIGTERM, then waits up to 20 s: returns the exit status (128 + signal if
 * killed by one), or -1 after SIGKILL on timeout. */
int td_stop(td_daemon *d);
/* SIGKILL and reap. */
void td_kill9(td_daemon *d);
/* Runs mpmd with exactly these arguments (NULL-terminated) and waits up to
 * timeout s for it to exit (for refused starts). */
int td_run_mpmd(const char *const *argv, double timeout, td_out *o);

/* Runs mpmctl --endpoint d->ep --timeout 20 ARGS... (NULL-terminated;
 * d may be NULL: no --endpoint/--timeout added) with a deadline. */
int td_ctl(const td_daemon *d, double timeout, td_out *o, ...);
/* The same from an argv array (NULL-terminated). */
int td_ctlv(const td_daemon *d, double timeout, td_out *o, const char *const *args);
void td_out_free(td_out *o);

/* Starts mpmctl --endpoint d->ep ARGS... in the background, output into
 * files in d->dir named after tag. */
int td_ctl_bg(const td_daemon *d, td_bg *b, const char *tag, ...);
/* Waits up to timeout s for it and reads its output. */
int td_bg_wait(td_bg *b, double timeout, td_out *o);

/* The protocol library's case calls with the error rendered as a user
 * reads it ("field: message", JSON spelling) into err (n bytes).
 * td_case_load uses the default particle limit. */
int td_case_load(const char *json, size_t len, mpp_case **out, char *err, size_t n);
int td_case_from_json(const char *json, size_t len, Mpmd__Case **out, char *err, size_t n);
int td_case_unpack(const void *buf, size_t len, size_t max, Mpmd__Case **out, char *err, size_t n);
int td_msg_json_to_bytes(mpp_msg_kind kind, const char *json, size_t len, uint8_t **buf,
                         size_t *nbytes, char *err, size_t n);
int td_msg_bytes_to_json(mpp_msg_kind kind, const void *buf, size_t nbytes, size_t max,
                         unsigned flags, char **json, char *err, size_t n);

/* One raw request: packs rq, sends [empty][bytes] on a fresh DEALER and
 * waits up to timeout s.  *reply is the decoded Reply as JSON (NULL if no
 * reply came: returns 1).  Returns 0 with a reply, 1 without, -1 on error. */
int td_request(const char *ep, const mpp_request *rq, double timeout, json_t **reply);
/* Raw frames (n of them, lens[i] bytes each) on a fresh DEALER; as above. */
int td_frames(const char *ep, const void *const *frames, const size_t *lens, int n, double timeout,
              json_t **reply);

/* Reply helpers.  The error code name of a reply ("" if none). */
const char *td_err_code(const json_t *reply);
const char *td_err_field(const json_t *reply);
const char *td_err_msg(const json_t *reply);
/* Status(job) through a raw request: the RunStatus name in buf ("" on
 * error), steps so far in *steps (may be NULL). */
int td_job_status(const td_daemon *d, unsigned long long job, char *buf, size_t n,
                  long long *steps);
/* Polls Status until the job's status is one of those listed
 * ("A|B|..."), up to timeout s; 0 when reached, -1 otherwise. */
int td_wait_status(const td_daemon *d, unsigned long long job, const char *want, double timeout,
                   char *got, size_t n);
/* Polls Status until the job has taken at least steps steps (or ended). */
int td_wait_steps(const td_daemon *d, unsigned long long job, long long steps, double timeout);

/* Receives one multipart message from s (blocking): up to max frames into
 * part (the caller closes them), any further frames dropped.  Returns the
 * frames kept (0 when the receive failed). */
int td_recv_parts(void *s, zmq_msg_t *part, int max);

/* Files. */
char *td_slurp(const char *path, size_t *len);

/* A valid 2D case (JSON) that the bad-input tests break by patching. */
extern const char *const td_good2d;
/* td_good2d with the first occurrence of `from` replaced by `to` (malloc'd;
 * NULL when `from` does not occur or memory runs out). */
char *td_patch(const char *from, const char *to);
int td_write(const char *path, const char *text);
/* Loads a JSON file (e.g. proto/examples/x.json) into a jansson object. */
json_t *td_json_file(const char *path);
/* Writes a jansson object as a case file (every double exact). */
int td_json_write(const char *path, const json_t *o);

/* Seconds on the monotonic clock. */
double td_now(void);
/* Sleeps ms milliseconds. */
void td_msleep(int ms);

/* Splits text into lines in place: returns the count, pointers in *lines
 * (malloc'd array; free it).  A trailing empty line is dropped. */
size_t td_lines(char *text, char ***lines);

#endif
