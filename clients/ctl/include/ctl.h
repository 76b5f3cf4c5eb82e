/*
 * ctl.h - the parts of mpmctl shared between its files: the connection to
 * mpmd (a DEALER on the control socket, requests encoded with the protocol
 * library; each reply decoded once, either into the library's structs
 * (energy pages, snapshots, Status and Ping in `watch`) or, for the
 * commands that print a record as the JSON mapping shows it, through the
 * JSON bridge into jansson values), the JSON
 * helpers (field access that understands the protobuf JSON mapping, and a
 * printer that writes doubles in their shortest exact form), the output
 * formats and the live view of a job (`watch`).
 *
 * Every function returns 0 or a negative CTL_E* code and has already
 * written its diagnostic to stderr ("mpmctl: ...") when it fails, so
 * callers only map the code to an exit status.
 */
#ifndef CTL_H
#define CTL_H

#include <signal.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include <jansson.h>

#include "mpp_endpoint.h"
#include "mpp_msg.h"
#include "mpp_text.h"

/* Return codes (negative). */
enum {
    CTL_OK = 0,
    CTL_EUSAGE = -1,   /* bad command line */
    CTL_ESERVER = -2,  /* the server answered with Reply.error */
    CTL_ETIMEOUT = -3, /* no reply within the timeout */
    CTL_EPROTO = -4,   /* a reply that is not what was asked for */
    CTL_ESYS = -5,     /* zmq, file or allocation failure */
    CTL_ECASE = -6,    /* the case file is unreadable or invalid */
    CTL_EINTR = -7,    /* interrupted by a signal */
    CTL_EAUTH = -8     /* the server refused the handshake (key) */
};

/* Exit statuses of mpmctl. */
enum {
    CTL_EXIT_OK = 0,
    CTL_EXIT_ERROR = 1,       /* any error */
    CTL_EXIT_USAGE = 2,       /* bad command line */
    CTL_EXIT_FAILED = 3,      /* watched run ended FAILED */
    CTL_EXIT_CANCELLED = 4,   /* ... CANCELLED */
    CTL_EXIT_INTERRUPTED = 5, /* ... INTERRUPTED (or still not finished) */
    CTL_EXIT_SIGNAL = 130     /* watch stopped by Ctrl-C */
};

/* Set by the SIGINT/SIGTERM handler of `watch`; a wait interrupted by a
 * signal returns CTL_EINTR once it is set. */
extern volatile sig_atomic_t ctl_interrupted;

#define CTL_DEFAULT_ENDPOINT "tcp://127.0.0.1:5555"
#define CTL_DEFAULT_TIMEOUT 10.0

/* Output format of listings. */
typedef enum { CTL_OUT_TEXT = 0, CTL_OUT_CSV = 1, CTL_OUT_JSON = 2 } ctl_out;

/* ---- connection (ctl_conn.c) --------------------------------------- */

typedef struct {
    const char *endpoint; /* control socket */
    const char *stream;   /* stream socket override (--stream / MPMD_STREAM) or NULL */
    double timeout_s;     /* per request */
    void *zctx;           /* zmq context, NULL until ctl_conn_open */
    void *dealer;         /* control socket */
    void *mon;            /* PAIR on the DEALER's monitor: disconnections,
                             failed handshakes */
    int curve;            /* CURVE keys loaded (ctl_keys_load) */
    char server_key[41], public_key[41], secret_key[41]; /* Z85 */
} ctl_conn;

/* ---- CURVE keys (ctl_keys.c) ------------------------------------------ */

/* Loads the CURVE keys: the server's public key from MPMD_SERVER_KEY (a Z85
 * key or a file) or KEYDIR/server.pub, the client's secret key from the
 * file MPMD_CLIENT_KEY or KEYDIR/mpmd.key (mode 0600 or stricter), where
 * KEYDIR is keys_dir (--keys), else $MPMD_KEYS, else ~/.config/mpmd if it
 * exists and c->endpoint is not local (loopback, ipc://).  No server key: c->curve stays 0 (no
 * CURVE).  A server key without a client key is an error. */
int ctl_keys_load(ctl_conn *c, const char *keys_dir);
/* Sets the CURVE client options on sock when keys are loaded. */
int ctl_conn_secure(ctl_conn *c, void *sock);
/* `mpmctl keygen`: writes DIR/NAME.key (the secret key, mode 0600) and
 * DIR/NAME.pub (the public key), refusing to overwrite either; prints the
 * public key.  DIR "" or NULL: "."; NAME "" or NULL: "mpmd". */
int ctl_keygen(const char *dir, const char *name);

/* Creates the context and connects the DEALER (linger 0). */
int ctl_conn_open(ctl_conn *c);
/* Closes the sockets and terminates the context (safe on a closed one). */
void ctl_conn_close(ctl_conn *c);

/* Sends rq, waits up to timeout_s for the reply and decodes it.  On
 * success *reply owns the decoded Reply object and *body borrows its member
 * `want` ("run", "energy", ...).  A Reply.error is printed ("mpmctl: CODE:
 * message (field F)") and gives CTL_ESERVER; if err_code is not NULL it
 * receives the error's code name (static storage, "" otherwise). */
int ctl_call(ctl_conn *c, const mpp_request *rq, const char *want, json_t **reply, json_t **body);
/* As ctl_call(), without printing a server error: *err_code gets the code
 * name and *err_msg the message (both owned by *reply, which is set). */
int ctl_call_quiet(ctl_conn *c, const mpp_request *rq, const char *want, json_t **reply,
                   json_t **body, const char **err_code, const char **err_msg);

/* As ctl_call(), decoding the reply into *out (the protocol library's
 * struct; release it with mpp_reply_clear() in every case): a body other
 * than `want` is reported and gives CTL_EPROTO, a Reply.error is printed
 * and gives CTL_ESERVER. */
int ctl_call_reply(ctl_conn *c, const mpp_request *rq, mpp_reply_kind want, mpp_reply *out);

/* The stream endpoint to subscribe to: the --stream override, else the
 * protocol's rule (mpp_stream_endpoint_for_client) applied to what Pong
 * reports and the control endpoint. */
int ctl_stream_endpoint(ctl_conn *c, char *out, size_t n);

/* Reads and drops the rest of a multipart message on sock (a stream
 * message with more frames than [topic][body]), once its last frame read
 * had ZMQ_RCVMORE set. */
void ctl_drain_more(void *sock);

/* Fetches every energy sample of a run with seq >= from (paging while the
 * server says `more`) and calls fn for each in order with the decoded
 * sample; fn returns 0 to go on, negative to stop with that code. */
typedef int (*ctl_sample_fn)(const mpm_energy_sample *s, void *arg);
int ctl_fetch_energy(ctl_conn *c, uint64_t run_id, uint64_t from, ctl_sample_fn fn, void *arg);

/* ---- JSON helpers (ctl_json.c) -------------------------------------- */

/* Member key of o as a number: JSON numbers, and strings holding a number,
 * "NaN", "Infinity" or "-Infinity" (the protobuf JSON mapping); dflt when
 * absent or not numeric. */
double cj_num(const json_t *o, const char *key, double dflt);
/* ... as a 64-bit integer (numbers or decimal strings). */
long long cj_int(const json_t *o, const char *key, long long dflt);
uint64_t cj_u64(const json_t *o, const char *key, uint64_t dflt);
/* ... as a string (dflt when absent or not a string). */
const char *cj_str(const json_t *o, const char *key, const char *dflt);
/* Element i of the array member key as a number (dflt when absent). */
double cj_at(const json_t *o, const char *key, size_t i, double dflt);
/* Length of the array member key (0 when absent). */
size_t cj_len(const json_t *o, const char *key);

/* v as it reads back from the daemon's JSON form: a zero without its sign
 * ("-0" parses as the integer 0), NaN as the unsigned NaN "NaN" gives. */
double cj_norm(double v);
/* Shortest text that reads back as exactly v ("NaN", "Infinity" and
 * "-Infinity" for the non-finite values); buf of at least 32 bytes. */
void cj_fmt_double(char *buf, size_t n, double v);
/* Writes v as JSON with doubles in their shortest exact form; pretty:
 * indented, arrays of scalars kept on one line.  No newline at the end. */
int cj_print(FILE *f, const json_t *v, int pretty);

/* Status value of a RunInfo/Finished "status" member (RunStatus name). */
int cj_status(const json_t *o, const char *key);

/* ---- output helpers (ctl_out.c) ------------------------------------- */

/* Energy sample writers: a header (text table / CSV), then one row per
 * sample.  dim: number of momentum components in CSV (0: from the sample).
 * JSON rows are the sample in the protobuf JSON mapping (made here, from
 * the decoded sample, only for that format). */
typedef struct {
    ctl_out fmt;
    int dim;
    int header_done;
    FILE *f;
} ctl_energy_out;
void ctl_energy_out_init(ctl_energy_out *o, ctl_out fmt, int dim, FILE *f);
int ctl_energy_out_row(ctl_energy_out *o, const mpm_energy_sample *s);

/* s escaped by mpp_text_escape (a backslash, control characters,
 * bidirectional controls, line separators, bytes that are not UTF-8) into
 * buf (n bytes, cut short when full); returns buf.  For every
 * server-supplied text printed as text. */
const char *ctl_esc(const char *s, char *buf, size_t n);
/* Room ctl_esc needs for a text of n bytes, for a buffer of the caller. */
#define CTL_ESC_LEN(n) MPP_TEXT_ESC_LEN(n)
/* The server's cap on runs per listing (ListRuns.limit). */
#define CTL_LIST_MAX 10000u

/* Local time of a Unix time as "YYYY-MM-DD HH:MM:SS" ("-" when <= 0). */
void ctl_fmt_time(char *buf, size_t n, double unix_s);
/* A RunInfo's balance error (JSON object run) as "0.123%", with "!" when
 * the run carries a budget warning; "-" when none is recorded. */
void ctl_fmt_balance(char *buf, size_t n, const json_t *run);
/* A duration as "12.3 s", "4m05s", "2h03m". */
void ctl_fmt_duration(char *buf, size_t n, double s);

/* ---- watch (ctl_watch.c) -------------------------------------------- */

/* The live view of a job until it ends (see mpmctl watch --help); stores
 * the run's final status (mpp_status, 0 if unknown) in *final_status.
 * Returns 0 when the job ended (whatever its status), negative on error or
 * CTL_EINTR when interrupted. */
int ctl_watch(ctl_conn *c, uint64_t job, ctl_out fmt, int *final_status);

#endif
