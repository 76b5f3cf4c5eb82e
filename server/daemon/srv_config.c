/*
 * srv_config.c - parses the daemon's settings (see srv_config.h).  One table
 * lists every setting with its type and limits; the command line, the
 * config file ("key = value" lines, '#' comments, keys as the long flags
 * without dashes) and the environment all go through it.
 */
#include "srv_config.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { T_STR, T_INT, T_LL, T_DBL, T_FLAG };

typedef struct {
    const char *key; /* long flag without "--", config key */
    const char *env; /* environment variable or NULL */
    int type;
    size_t off, size; /* field in srv_config; size for strings */
    double lo, hi;
    const char *def;  /* the default, as it would be written (NULL: none, or 0 / off) */
    const char *help; /* --help prints "(default DEF)" after it */
} setting;

#define F(field) offsetof(srv_config, field), sizeof(((srv_config *)0)->field)
static const setting settings[] = {
    {"endpoint", "MPMD_ENDPOINT", T_STR, F(endpoint), 0, 0, "tcp://127.0.0.1:5555",
     "control socket"},
    {"stream-endpoint", "MPMD_STREAM_ENDPOINT", T_STR, F(stream_endpoint), 0, 0, NULL,
     "job stream socket (default: tcp port + 1, or ipc path + .stream)"},
    {"db", "MPMD_DB", T_STR, F(db), 0, 0, "mpmd.db", "SQLite file of run records"},
    {"workers", NULL, T_INT, F(workers), 1, 256, "2", "jobs that run at once"},
    {"solver-threads", NULL, T_INT, F(solver_threads), 1, 64, "1", "solver threads per job"},
    {"queue-max", NULL, T_INT, F(queue_max), 0, 1000000, "16",
     "queued jobs beyond the running ones"},
    {"max-particles", NULL, T_LL, F(max_particles), 1, (double)MPM_MAX_PARTICLES, "10000000",
     "particles per job"},
    {"max-steps", NULL, T_LL, F(max_steps), 1, 1e15, "100000000", "steps per job"},
    {"max-wall-s", NULL, T_DBL, F(max_wall_s), 0, 1e9, "0", "wall seconds per job, 0 = no limit"},
    {"checkpoint-every-s", NULL, T_DBL, F(checkpoint_every_s), 0, 1e9, "300",
     "wall seconds between checkpoints of a run whose case sets none (files in <db>.ckpt/, "
     "for mpmctl resume), 0 = none"},
    {"checkpoint-share", NULL, T_DBL, F(checkpoint_share), 0.001, 1, "0.1",
     "share of a job's wall time its checkpoints may take: one due sooner after the last "
     "than (1 - share) / share times the last one's duration is skipped, 1 = none skipped"},
    {"disk-reserve-mb", NULL, T_INT, F(disk_reserve_mb), 0, 1024, "1",
     "MiB kept allocated beside the database for its own writes on a full disk; new runs are "
     "refused while it cannot be kept, 0 = none"},
    {"max-request-bytes", NULL, T_LL, F(max_request_bytes), 1024, 1 << 30, "8388608",
     "largest request accepted; each request connection may hold two while they arrive"},
    {"connection-reply-buffer-mb", NULL, T_INT, F(connection_reply_buffer_mb), 1, 1 << 20, "16",
     "MiB of replies one connection may leave unread; a reply past it is answered "
     "UNAVAILABLE (one larger reply may go alone)"},
    {"reply-buffer-mb", NULL, T_INT, F(reply_buffer_mb), 1, 1 << 20, "256",
     "MiB of unread replies over all connections; past it replies are answered UNAVAILABLE"},
    {"page-max-bytes", NULL, T_LL, F(page_max_bytes), 4096, 1 << 30, "1048576",
     "largest energy page or runs listing in bytes; the rest comes in the next page"},
    {"page-max-ms", NULL, T_INT, F(page_max_ms), 1, 60000, "20",
     "milliseconds a runs listing is made for; the rest comes in the next page"},
    {"max-connections", NULL, T_INT, F(max_connections), 0, 1000000, "64",
     "request connections at once; more are refused at the handshake, 0 = no cap"},
    {"handshake-timeout-s", NULL, T_INT, F(handshake_timeout_s), 1, 3600, "10",
     "seconds a new connection has to finish its handshake before it is closed"},
    {"stream-buffer-mb", NULL, T_INT, F(stream_buffer_mb), 0, 1 << 20, "64",
     "MB of stream messages queued for one watcher (one connection), across all its jobs; a "
     "watcher further behind misses messages until it catches up, 0 = no bound"},
    {"stream-total-mb", NULL, T_INT, F(stream_total_mb), 0, 1 << 20, "256",
     "MB of snapshot messages queued for all watchers together; past it snapshots are not "
     "streamed, 0 = no bound"},
    {"stream-max-subscriptions", NULL, T_INT, F(stream_max_subscriptions), 1, 1000000, "4096",
     "stream subscriptions held for all watchers (a 21-byte job topic each); past it the "
     "stream socket drops every connection and watchers reconnect"},
    {"stream-subscribe-ahead", NULL, T_INT, F(stream_subscribe_ahead), 0, 1000000, "16",
     "job ids past the newest that a watcher may subscribe to before they exist"},
    {"curve-secret", "MPMD_CURVE_SECRET", T_STR, F(curve_secret), 0, 0, NULL,
     "the server's CURVE secret key file (mode 0600; mpmctl keygen): CURVE on both sockets"},
    {"authorized-keys", NULL, T_STR, F(authorized_keys), 0, 0, NULL,
     "client public keys allowed in (a file of 'KEY [comment]' lines or a directory of .pub "
     "files; re-read on SIGHUP)"},
    {"admin-keys", NULL, T_STR, F(admin_keys), 0, 0, NULL,
     "keys that may also cancel anyone's jobs (same format; re-read on SIGHUP)"},
    {"client-max-jobs", NULL, T_INT, F(client_max_jobs), 0, 1000000, "0",
     "queued and running jobs per client key (or local user), 0 = no limit"},
    {"client-max-particles", NULL, T_LL, F(client_max_particles), 0, (double)MPM_MAX_PARTICLES, "0",
     "particles per job of one client, 0 = only --max-particles"},
    {"client-max-disk-mb", NULL, T_LL, F(client_max_disk_mb), 0, 1e12, "0",
     "MiB of recorded snapshots and energy samples per client: a submission whose estimate "
     "would pass it is refused, a job that would pass it ends FAILED, 0 = no limit"},
    {"job-max-disk-mb", NULL, T_LL, F(job_max_disk_mb), 0, 1e12, "4096",
     "MiB of recorded snapshots and energy samples per job (estimated at submit, counted "
     "while it runs), 0 = no limit"},
    {"max-disk-mb", NULL, T_LL, F(max_disk_mb), 0, 1e12, "0",
     "MiB of recorded snapshots and energy samples in the whole database (estimated at "
     "submit, counted while jobs run), 0 = no limit"},
    {"private-runs", NULL, T_FLAG, F(private_runs), 0, 1, NULL,
     "a client key may read (show, runs, energy, snapshot, watch) only its own runs; admin "
     "keys read all (default: every authorized key reads every run)"},
    {"insecure-allow-remote-without-auth", NULL, T_FLAG, F(insecure_remote), 0, 1, NULL,
     "bind non-loopback addresses WITHOUT CURVE: anyone who reaches them may submit, cancel "
     "and read (trusted networks only)"},
    {"allow-remote", NULL, T_FLAG, F(allow_remote), 0, 1, NULL,
     "obsolete: a non-loopback bind needs --curve-secret (or the insecure flag above)"},
    {"portable-kernels", "MPMD_PORTABLE_KERNELS", T_FLAG, F(portable_kernels), 0, 1, NULL,
     "run every job on the portable kernels, whose bits are the same on every x86-64 machine "
     "(default: the AVX2+FMA kernels where the CPU has them; they differ in round-off)"},
    {"verbose", NULL, T_FLAG, F(verbose), 0, 1, NULL, "debug log lines"},
};
#define NSET (sizeof settings / sizeof settings[0])

static const setting *find(const char *key)
{
    for (size_t i = 0; i < NSET; i++)
        if (!strcmp(settings[i].key, key)) return &settings[i];
    return NULL;
}

/* Sets one value; `src` names where it came from, for the message. */
static int set(srv_config *c, const setting *s, const char *val, const char *src, char *err,
               size_t errlen)
{
    char *p = (char *)c + s->off, *end;
    if (s->type == T_STR) {
        if (strlen(val) >= s->size || !*val) {
            snprintf(err, errlen, "%s: %s must be 1 to %zu characters", src, s->key, s->size - 1);
            return -1;
        }
        memcpy(p, val, strlen(val) + 1);
        if (s->off == offsetof(srv_config, endpoint))
            snprintf(c->endpoint_from, sizeof c->endpoint_from, "%s", src);
        else if (s->off == offsetof(srv_config, stream_endpoint))
            snprintf(c->stream_endpoint_from, sizeof c->stream_endpoint_from, "%s", src);
        return 0;
    }
    if (s->type == T_FLAG) {
        int v;
        if (!strcmp(val, "1") || !strcmp(val, "true") || !strcmp(val, "yes"))
            v = 1;
        else if (!strcmp(val, "0") || !strcmp(val, "false") || !strcmp(val, "no"))
            v = 0;
        else {
            snprintf(err, errlen, "%s: %s expects true or false, got '%s'", src, s->key, val);
            return -1;
        }
        memcpy(p, &v, sizeof v);
        return 0;
    }
    errno = 0;
    double d = strtod(val, &end);
    if (errno || end == val || *end || !isfinite(d) || d < s->lo || d > s->hi ||
        (s->type != T_DBL && d != floor(d))) {
        if (s->type == T_DBL)
            snprintf(err, errlen, "%s: %s expects a number in [%g, %g], got '%s'", src, s->key,
                     s->lo, s->hi, val);
        else
            snprintf(err, errlen, "%s: %s expects a whole number in [%.0f, %.0f], got '%s'", src,
                     s->key, s->lo, s->hi, val);
        return -1;
    }
    if (s->type == T_INT) {
        int v = (int)d;
        memcpy(p, &v, sizeof v);
    } else if (s->type == T_LL) {
        long long v = (long long)d;
        memcpy(p, &v, sizeof v);
    } else {
        memcpy(p, &d, sizeof d);
    }
    return 0;
}

static char *trim(char *s)
{
    while (*s == ' ' || *s == '\t') s++;
    size_t n = strlen(s);
    while (n && (s[n - 1] == ' ' || s[n - 1] == '\t' || s[n - 1] == '\n' || s[n - 1] == '\r'))
        s[--n] = 0;
    return s;
}

static int load_file(srv_config *c, const char *path, char *err, size_t errlen)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        snprintf(err, errlen, "--config: cannot open %s: %s", path, strerror(errno));
        return -1;
    }
    char line[2048], src[1200];
    int ln = 0, rc = 0;
    while (!rc && fgets(line, sizeof line, f)) {
        ln++;
        char *s = trim(line);
        if (!*s || *s == '#') continue;
        char *eq = strchr(s, '=');
        snprintf(src, sizeof src, "%s:%d", path, ln);
        if (!eq) {
            snprintf(err, errlen, "%s: expected 'key = value', got '%s'", src, s);
            rc = -1;
            break;
        }
        *eq = 0;
        char *key = trim(s), *val = trim(eq + 1);
        const setting *st = find(key);
        if (!st) {
            snprintf(err, errlen, "%s: unknown key '%s' (see mpmd --help)", src, key);
            rc = -1;
            break;
        }
        rc = set(c, st, val, src, err, errlen);
    }
    fclose(f);
    return rc;
}

/* The defaults: every setting's def through set(), so that the table's
 * column is the one place a default is written (--help prints it). */
static void defaults(srv_config *c)
{
    char err[256];
    memset(c, 0, sizeof *c);
    snprintf(c->endpoint_from, sizeof c->endpoint_from, "the default");
    for (size_t i = 0; i < NSET; i++)
        if (settings[i].def &&
            set(c, &settings[i], settings[i].def, "the default", err, sizeof err))
            abort(); /* a default outside its own limits: config_defaults_from_table */
}

static void usage(void)
{
    printf("usage: mpmd [options]\n"
           "The mpmd simulation daemon: accepts MPM/GMPM jobs over ZeroMQ, runs them in worker\n"
           "threads, streams energies and snapshots, and records every run in SQLite.\n\n");
    for (size_t i = 0; i < NSET; i++) {
        char flag[64];
        snprintf(flag, sizeof flag, "--%s%s", settings[i].key,
                 settings[i].type == T_FLAG ? "" : " V");
        printf("  %-24s %s%s%s%s%s%s%s\n", flag, settings[i].help,
               settings[i].def ? " (default " : "", settings[i].def ? settings[i].def : "",
               settings[i].def ? ")" : "", settings[i].env ? " [env " : "",
               settings[i].env ? settings[i].env : "", settings[i].env ? "]" : "");
    }
    printf("  %-24s %s\n  %-24s %s\n  %-24s %s\n\n", "--config FILE",
           "read settings from FILE (key = value lines)", "--version", "print the version",
           "-h, --help", "this text");
    printf("Order: defaults < --config file < environment < flags.  Binding anywhere but\n"
           "loopback, ipc:// or inproc:// needs --curve-secret and --authorized-keys (or,\n"
           "on a trusted network, --insecure-allow-remote-without-auth).  SIGHUP re-reads\n"
           "the key lists.\n");
}

/* The bind rule (mpp_endpoint_bind_class) for --endpoint (stream 0) or
 * --stream-endpoint (1): anything not provably loopback needs CURVE; the
 * message names the endpoint, where it was set and the fix.
 * srv_socket_open() checks it again at the bind (daemon_bind_* tests). */
static int bind_rule(const srv_config *c, int stream, char *err, size_t errlen)
{
    const char *ep = stream ? c->stream_endpoint : c->endpoint;
    const char *from = stream ? c->stream_endpoint_from : c->endpoint_from;
    const char *flag = stream ? "--stream-endpoint" : "--endpoint";
    char why[400];
    int k = mpp_endpoint_bind_class(ep, why, sizeof why);
    if (k == MPP_BIND_INVALID) {
        snprintf(err, errlen,
                 "%s %s (set by %s): refusing to bind it: %s; use tcp://127.0.0.1:PORT or "
                 "ipc://PATH (other tcp addresses with --curve-secret and --authorized-keys)",
                 flag, ep, from, why);
        return -1;
    }
    if (k == MPP_BIND_REMOTE && !c->curve_secret[0] && !c->insecure_remote) {
        snprintf(err, errlen,
                 "%s %s (set by %s): refusing to bind a non-loopback address without "
                 "authentication: %s; give --curve-secret FILE and --authorized-keys PATH "
                 "(docs/manual.md: Security), use tcp://127.0.0.1:PORT or ipc://PATH, or, on a "
                 "trusted network only, --insecure-allow-remote-without-auth%s",
                 flag, ep, from, why,
                 c->allow_remote ? " (--allow-remote no longer binds without authentication)" : "");
        return -1;
    }
    return 0;
}

int srv_config_load(srv_config *c, int argc, char **argv, char *err, size_t errlen)
{
    defaults(c);
    /* pass 1: --help, --version, --config */
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
            usage();
            return 1;
        }
        if (!strcmp(argv[i], "--version")) {
            printf("mpmd %s\n", MPP_VERSION);
            return 1;
        }
    }
    for (int i = 1; i < argc; i++)
        if (!strcmp(argv[i], "--config")) {
            if (i + 1 >= argc) {
                snprintf(err, errlen, "--config needs a file name");
                return -1;
            }
            if (load_file(c, argv[i + 1], err, errlen)) return -1;
        }
    for (size_t i = 0; i < NSET; i++) {
        const char *v = settings[i].env ? getenv(settings[i].env) : NULL;
        if (v && *v && set(c, &settings[i], v, settings[i].env, err, errlen)) return -1;
    }
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "--config")) {
            i++;
            continue;
        }
        const setting *s = strncmp(a, "--", 2) ? NULL : find(a + 2);
        if (!s) {
            snprintf(err, errlen, "unknown option '%s' (see mpmd --help)", a);
            return -1;
        }
        if (s->type == T_FLAG) {
            if (set(c, s, "1", a, err, errlen)) return -1;
            continue;
        }
        if (i + 1 >= argc) {
            snprintf(err, errlen, "%s needs a value", a);
            return -1;
        }
        if (set(c, s, argv[++i], a, err, errlen)) return -1;
    }
    if (bind_rule(c, 0, err, errlen)) return -1;
    if (!c->stream_endpoint[0]) {
        if (mpp_stream_endpoint_derive(c->endpoint, c->stream_endpoint,
                                       sizeof c->stream_endpoint)) {
            snprintf(err, errlen,
                     "--endpoint %s: cannot derive the stream endpoint (tcp://HOST:PORT "
                     "or ipc://PATH); give --stream-endpoint",
                     c->endpoint);
            return -1;
        }
        snprintf(c->stream_endpoint_from, sizeof c->stream_endpoint_from,
                 "derivation from --endpoint, set by %.100s", c->endpoint_from);
    }
    if (bind_rule(c, 1, err, errlen)) return -1;
    if (!strcmp(c->endpoint, c->stream_endpoint)) {
        snprintf(err, errlen, "--stream-endpoint: must differ from --endpoint (%s)", c->endpoint);
        return -1;
    }
    return 0;
}
