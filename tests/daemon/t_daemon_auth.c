/*
 * t_daemon_auth.c - authentication and authorization on a real mpmd with
 * CURVE on loopback tcp: keys made by `mpmctl keygen` (their files' modes,
 * no overwrite); an authorized key submits, watches (the stream over
 * CURVE), shows its run with itself as the owner; an unknown key and a
 * missing key are refused at the handshake, quickly and with mpmctl naming
 * the key; a subscriber without a key never reaches the stream; another
 * authorized key cannot cancel a job (FORBIDDEN), or resume its run, while
 * an admin key and the owner can cancel it; a key removed from the list is
 * refused after SIGHUP; a non-loopback bind without CURVE, a secret key
 * file readable by others and CURVE without a key list are refused at
 * start; the per-client quotas (queued jobs, particles per job, recorded
 * bytes: the estimate at submit) refuse with QUEUE_FULL and TOO_LARGE
 * naming the quota; under CURVE a job's stream reaches only its owner and
 * the admin keys.
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zmq.h>

/* The key (first token) of a key file into z (41 bytes); 0 or -1. */
static int read_key(const char *path, char *z)
{
    size_t len = 0;
    char *t = td_slurp(path, &len);
    if (!t || len < 40) {
        free(t);
        return -1;
    }
    memcpy(z, t, 40);
    z[40] = 0;
    free(t);
    return 0;
}

/* mpmctl keygen --out dir/sub [--name name]; the keys into pub / sec. */
static int keygen(const char *dir, const char *sub, const char *name, char *pub, char *sec)
{
    char out[400], p[500];
    td_out o;
    snprintf(out, sizeof out, "%s/%s", dir, sub);
    if (td_ctl(NULL, 20, &o, "keygen", "--out", out, "--name", name, NULL) || o.status) {
        t_fail(__FILE__, __LINE__, "keygen %s: %s", out, o.err ? o.err : "");
        td_out_free(&o);
        return -1;
    }
    td_out_free(&o);
    snprintf(p, sizeof p, "%s/%s.pub", out, name);
    if (read_key(p, pub)) return -1;
    snprintf(p, sizeof p, "%s/%s.key", out, name);
    return sec ? read_key(p, sec) : 0;
}

static int write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    if (!f) return -1;
    fputs(text, f);
    return fclose(f);
}

/* Copies the server's public key file into a client's key directory. */
static int give_server_key(const char *dir, const char *sub, const char *srv_pub)
{
    char p[500], line[100];
    snprintf(p, sizeof p, "%s/%s/server.pub", dir, sub);
    snprintf(line, sizeof line, "%s\n", srv_pub);
    return write_text(p, line);
}

/* mpmctl --keys dir/sub ARGS: the output in o (caller frees). */
static int ctl_as(const td_daemon *d, const char *dir, const char *sub, td_out *o,
                  const char *const *args)
{
    const char *argv[16];
    char kd[400];
    int n = 0;
    snprintf(kd, sizeof kd, "%s/%s", dir, sub);
    argv[n++] = "--keys";
    argv[n++] = kd;
    for (int i = 0; args[i] && n < 15; i++) argv[n++] = args[i];
    argv[n] = NULL;
    return td_ctlv(d, 30, o, argv);
}
#define CTL_AS(d, dir, sub, o, ...)             \
    do {                                        \
        const char *a_[] = {__VA_ARGS__, NULL}; \
        CHECK(ctl_as(d, dir, sub, o, a_) == 0); \
    } while (0)

DTEST(daemon_auth_curve)
{
    const char *tmp = t_tmpdir();
    char dir[300], srvkey[400], auth[400], admins[400], ep[64], path[500], text[600];
    char spub[41], ssec[41], apub[41], asec[41], bpub[41], dpub[41], upub[41];
    snprintf(dir, sizeof dir, "%s/auth", tmp);
    mkdir(dir, 0700);

    /* keygen: a secret key mode 0600, a public one 0644, never overwritten */
    if (keygen(dir, "srv", "server", spub, ssec) || keygen(dir, "a", "mpmd", apub, asec) ||
        keygen(dir, "b", "mpmd", bpub, NULL) || keygen(dir, "adm", "mpmd", dpub, NULL) ||
        keygen(dir, "u", "mpmd", upub, NULL))
        return;
    struct stat sk, sp;
    snprintf(srvkey, sizeof srvkey, "%s/srv/server.key", dir);
    snprintf(path, sizeof path, "%s/srv/server.pub", dir);
    CHECK(stat(srvkey, &sk) == 0 && stat(path, &sp) == 0);
    CHECKF((sk.st_mode & 0777) == 0600 && (sp.st_mode & 0777) == 0644,
           "keygen modes: secret %04o, public %04o", (unsigned)(sk.st_mode & 0777),
           (unsigned)(sp.st_mode & 0777));
    {
        td_out o;
        char out[400];
        snprintf(out, sizeof out, "%s/srv", dir);
        CHECK(td_ctl(NULL, 20, &o, "keygen", "--out", out, "--name", "server", NULL) == 0);
        int ok = o.status == 1 && strstr(o.err, "never overwrites") && strstr(o.err, srvkey);
        td_out_free(&o);
        CHECKF(ok, "a second keygen into the same files is not refused");
        char now[41];
        CHECK(read_key(path, now) == 0 && !strcmp(now, spub));
    }
    CHECK(give_server_key(dir, "a", spub) == 0 && give_server_key(dir, "b", spub) == 0 &&
          give_server_key(dir, "adm", spub) == 0 && give_server_key(dir, "u", spub) == 0);

    /* the lists: a file with a and b (comments, a blank line), admin in a
     * directory of .pub files */
    snprintf(auth, sizeof auth, "%s/authorized_keys", dir);
    snprintf(text, sizeof text, "# clients\n%s alice\n\n  %s bob\n", apub, bpub);
    CHECK(write_text(auth, text) == 0);
    snprintf(admins, sizeof admins, "%s/admins", dir);
    mkdir(admins, 0700);
    snprintf(path, sizeof path, "%s/root.pub", admins);
    snprintf(text, sizeof text, "%s root\n", dpub);
    CHECK(write_text(path, text) == 0);

    int port = td_tcp_port(0);
    snprintf(ep, sizeof ep, "tcp://127.0.0.1:%d", port);
    const char *extra[] = {"--curve-secret", srvkey, "--authorized-keys", auth,
                           "--admin-keys",   admins, "--verbose",         NULL};
    td_daemon d;
    char ddir[400];
    snprintf(ddir, sizeof ddir, "%s/d", dir);
    td_set_curve(spub, apub, asec); /* the harness's Ping goes as a */
    if (td_start_ep(&d, ddir, ep, extra)) return;
    CHECK(log_has(&d, "CURVE on: server public key") && log_has(&d, spub));

    /* a: submit a long job and a short one with --watch (the stream over
     * CURVE: its subscription reaches the daemon) */
    char cpath[500];
    CHECK(write_case(long_case(100), dir, "long.json", cpath, sizeof cpath) == 0);
    td_out o;
    CTL_AS(&d, dir, "a", &o, "submit", cpath);
    unsigned long long job1 = job_of(o.out);
    td_out_free(&o);
    CHECKF(job1 > 0, "a's submit gave no job");
    /* the bar at rest for 120,000 steps (about 0.5 s in the sanitizer
     * build): still running when mpmctl first asks, so that it watches the
     * stream; a job that has already ended is read from the store, and its
     * subscription may never reach the daemon (a 600-step bar ended in 3 ms
     * once, and this check failed) */
    char bpath[500];
    json_t *bc = long_case(2000);
    if (bc) json_object_set_new(bc, "steps", json_integer(120000));
    CHECK(write_case(bc, dir, "bar.json", bpath, sizeof bpath) == 0);
    CTL_AS(&d, dir, "a", &o, "submit", bpath, "--watch", "--csv");
    int ok = o.status == 0;
    series s = {0};
    ok = ok && parse_csv(o.out, &s) == 0 && s.n == 61 && consecutive(&s);
    series_free(&s);
    td_out_free(&o);
    CHECKF(ok, "a's submit --watch over CURVE did not give the 61 samples");
    CHECK(wait_watched(&d, job1 + 1, 5) == 0);
    CTL_AS(&d, dir, "a", &o, "show", "1", "--json");
    json_t *r = o.status == 0 ? parse_line(o.out) : NULL;
    td_out_free(&o);
    ok = r && !strcmp(jstr(r, "owner"), apub);
    json_decref(r);
    CHECKF(ok, "run %llu's owner is not a's key", job1);
    TLOG("a's run %llu is owned by %s", job1, apub);

    /* a subscriber without keys never reaches the stream */
    {
        void *zctx = zmq_ctx_new(), *sub = zmq_socket(zctx, ZMQ_SUB);
        char sep[64], topic[32], want[64];
        int zero = 0;
        snprintf(sep, sizeof sep, "tcp://127.0.0.1:%d", port + 1);
        snprintf(topic, sizeof topic, "job:%016llx:", job1);
        CHECK(sub && zmq_setsockopt(sub, ZMQ_LINGER, &zero, sizeof zero) == 0 &&
              zmq_setsockopt(sub, ZMQ_SUBSCRIBE, topic, strlen(topic)) == 0 &&
              zmq_connect(sub, sep) == 0);
        zmq_pollitem_t it = {sub, 0, ZMQ_POLLIN, 0};
        int n = zmq_poll(&it, 1, 1000);
        snprintf(want, sizeof want, "job %llu: stream watched", job1);
        ok = n == 0 && !log_has(&d, want);
        zmq_close(sub);
        zmq_ctx_term(zctx);
        CHECKF(ok, "a SUB without CURVE keys got %d messages or subscribed", n);
    }

    /* an unknown key: refused at the handshake, mpmctl names the key */
    CTL_AS(&d, dir, "u", &o, "ping");
    ok = o.status == 1 && strstr(o.err, "refused this client's key") && strstr(o.err, upub) &&
         o.secs < 10;
    TLOG("unknown key: exit %d in %.2f s: %.200s", o.status, o.secs, o.err);
    td_out_free(&o);
    CHECKF(ok, "the unknown key was not refused with its key named");
    snprintf(text, sizeof text, "ZAP: refused %s", upub);
    CHECKF(log_has(&d, text), "the daemon did not log the refused key");

    /* no key at all (HOME without ~/.config/mpmd, no MPMD_* keys) */
    {
        char *home = getenv("HOME") ? strdup(getenv("HOME")) : NULL;
        setenv("HOME", dir, 1);
        unsetenv("MPMD_KEYS");
        unsetenv("MPMD_SERVER_KEY");
        unsetenv("MPMD_CLIENT_KEY");
        int rc = td_ctl(&d, 30, &o, "ping", NULL);
        if (home) {
            setenv("HOME", home, 1);
            free(home);
        }
        CHECK(rc == 0);
        ok = o.status == 1 && strstr(o.err, "requires CURVE and this client has no key") &&
             o.secs < 10;
        TLOG("no key: exit %d in %.2f s: %.200s", o.status, o.secs, o.err);
        td_out_free(&o);
        CHECKF(ok, "a client without a key was not told so");
    }

    /* b may not cancel a's job; the admin may */
    CTL_AS(&d, dir, "b", &o, "cancel", "1");
    char want[200];
    snprintf(want, sizeof want, "job %llu was submitted by %s", job1, apub);
    ok = o.status == 1 && strstr(o.err, "FORBIDDEN") && strstr(o.err, want);
    TLOG("b cancels a's job: exit %d: %.200s", o.status, o.err);
    td_out_free(&o);
    CHECKF(ok, "b's cancel of a's job was not FORBIDDEN");
    char st[32];
    CHECK(td_job_status(&d, job1, st, sizeof st, NULL) == 0 && !strcmp(st, "RUNNING"));
    CTL_AS(&d, dir, "adm", &o, "cancel", "1");
    ok = o.status == 0;
    td_out_free(&o);
    CHECKF(ok, "the admin's cancel failed");
    CHECK(td_wait_status(&d, job1, "CANCELLED", 20, st, sizeof st) == 0);
    /* nor resume it; its owner is told why it cannot */
    CTL_AS(&d, dir, "b", &o, "resume", "1");
    snprintf(want, sizeof want, "run %llu was submitted by %s", job1, apub);
    ok = o.status == 1 && strstr(o.err, "FORBIDDEN") && strstr(o.err, want);
    td_out_free(&o);
    CHECKF(ok, "b's resume of a's run was not FORBIDDEN");
    CTL_AS(&d, dir, "a", &o, "resume", "1");
    ok = o.status == 1 && strstr(o.err, "CONFLICT") && strstr(o.err, "run 1 is CANCELLED");
    td_out_free(&o);
    CHECKF(ok, "a's resume of its cancelled run was not a CONFLICT naming why");
    /* the owner may cancel its own */
    CTL_AS(&d, dir, "a", &o, "submit", cpath);
    unsigned long long job3 = job_of(o.out);
    td_out_free(&o);
    CHECK(job3 > 0);
    CTL_AS(&d, dir, "a", &o, "cancel", "3");
    ok = o.status == 0 && job3 == 3;
    td_out_free(&o);
    CHECKF(ok, "a could not cancel its own job");
    CHECK(td_wait_status(&d, job3, "CANCELLED", 20, st, sizeof st) == 0);

    /* b revoked: removed from the file, SIGHUP; refused afterwards, a not */
    CTL_AS(&d, dir, "b", &o, "ping");
    ok = o.status == 0;
    td_out_free(&o);
    CHECKF(ok, "b could not ping before its key was revoked");
    snprintf(text, sizeof text, "%s alice\n", apub);
    CHECK(write_text(auth, text) == 0);
    CHECK(kill(d.pid, SIGHUP) == 0);
    double end = td_now() + 10;
    while (!log_has(&d, "SIGHUP: keys re-read") && td_now() < end) td_msleep(20);
    snprintf(text, sizeof text, "key %s removed", bpub);
    CHECKF(log_has(&d, "SIGHUP: keys re-read: 0 added, 1 removed") && log_has(&d, text),
           "the reload did not log b's removal");
    CTL_AS(&d, dir, "b", &o, "ping");
    ok = o.status == 1 && strstr(o.err, "refused this client's key") && strstr(o.err, bpub);
    td_out_free(&o);
    CHECKF(ok, "b was not refused after SIGHUP");
    CTL_AS(&d, dir, "a", &o, "ping");
    ok = o.status == 0;
    td_out_free(&o);
    CHECKF(ok, "a was refused after the reload");
    CHECK(td_stop(&d) == 0);
}

/* Refused starts: a non-loopback bind without CURVE (also with the old
 * --allow-remote), a secret key file readable by others, CURVE without a
 * key list; and keys that do not parse. */
DTEST(daemon_auth_refused_starts)
{
    const char *tmp = t_tmpdir();
    const char *mpmd = td_bin("MPMD_BIN");
    char dir[300], db[400], key[400], pub[41], sec[41], auth[400];
    if (!mpmd) return;
    snprintf(dir, sizeof dir, "%s/refuse", tmp);
    mkdir(dir, 0700);
    snprintf(db, sizeof db, "%s/mpmd.db", dir);
    if (keygen(dir, "srv", "server", pub, sec)) return;
    snprintf(key, sizeof key, "%s/srv/server.key", dir);
    snprintf(auth, sizeof auth, "%s/srv/server.pub", dir); /* any list of keys */
    td_out o;
    struct {
        const char *argv[12];
        const char *want1, *want2;
        int status;
    } cases[] = {
        {{"--endpoint", "tcp://0.0.0.0:7", "--db", db, NULL},
         "refusing to bind a non-loopback address without authentication",
         "--insecure-allow-remote-without-auth",
         2},
        {{"--endpoint", "tcp://0.0.0.0:7", "--db", db, "--allow-remote", NULL},
         "--allow-remote no longer binds without authentication",
         "--curve-secret",
         2},
        {{"--endpoint", "ipc://x", "--db", db, "--curve-secret", key, NULL},
         "--curve-secret needs --authorized-keys",
         "any client",
         1},
        {{"--endpoint", "ipc://x", "--db", db, "--authorized-keys", auth, NULL},
         "need --curve-secret",
         "",
         1},
        {{"--endpoint", "ipc://x", "--db", db, "--curve-secret", key, "--authorized-keys", db,
          NULL},
         "not a 40-character Z85 key",
         "mpmd.db",
         1},
    };
    /* the database for the last case: any text that is no key */
    CHECK(write_text(db, "not a key\n") == 0);
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        CHECK(td_run_mpmd(cases[i].argv, 20, &o) == 0);
        int ok = o.status == cases[i].status &&
                 (strstr(o.err, cases[i].want1) || strstr(o.out, cases[i].want1)) &&
                 (strstr(o.err, cases[i].want2) || strstr(o.out, cases[i].want2));
        TLOG("refused start %zu: exit %d: %.160s", i, o.status, o.err[0] ? o.err : o.out);
        if (!ok)
            t_fail(__FILE__, __LINE__, "case %zu: exit %d (want %d), \"%.400s%.400s\"", i, o.status,
                   cases[i].status, o.err, o.out);
        td_out_free(&o);
    }
    unlink(db);
    /* the secret key file must be 0600 or stricter */
    CHECK(chmod(key, 0640) == 0);
    const char *argv[] = {"--endpoint", "ipc://x",           "--db", db,  "--curve-secret",
                          key,          "--authorized-keys", auth,   NULL};
    CHECK(td_run_mpmd(argv, 20, &o) == 0);
    int ok = o.status == 1 && (strstr(o.err, "mode 0640") || strstr(o.out, "mode 0640")) &&
             (strstr(o.err, key) || strstr(o.out, key));
    TLOG("secret key mode 0640: exit %d: %.200s", o.status, o.err[0] ? o.err : o.out);
    td_out_free(&o);
    CHECKF(ok, "a secret key file of mode 0640 was not refused with its name and mode");
}

/* Per-client quotas, without CURVE (every request is "local"'s): the
 * second live job, a case above the particle quota and a case whose
 * estimated records pass the client's disk quota are refused, naming the
 * quota. */
DTEST(daemon_auth_quotas)
{
    const char *tmp = t_tmpdir();
    char dir[300], cpath[500], bpath[500];
    snprintf(dir, sizeof dir, "%s/quota", tmp);
    const char *extra[] = {"--client-max-jobs",
                           "1",
                           "--client-max-particles",
                           "300",
                           "--client-max-disk-mb",
                           "1",
                           NULL};
    td_daemon d;
    if (td_start(&d, dir, extra)) return;
    /* a sample every 100000 steps: 990 samples, well within the disk quota */
    CHECK(write_case(long_case(100000), dir, "long.json", cpath, sizeof cpath) == 0);
    td_out o;
    CHECK(td_ctl(&d, 30, &o, "submit", cpath, NULL) == 0);
    unsigned long long job = job_of(o.out);
    td_out_free(&o);
    CHECK(job > 0);
    json_t *r = show_json(&d, job);
    int ok = r && !strcmp(jstr(r, "owner"), "local");
    json_decref(r);
    CHECKF(ok, "a run submitted without CURVE is not owned by \"local\"");
    EXPECT_CTL(&d, 1, "QUEUE_FULL", "submit", cpath);
    EXPECT_CTL(&d, 1, "--client-max-jobs 1", "submit", cpath);
    /* the disks: 784 particles, above 300 */
    CHECK(write_case(example("disks2d_fine"), dir, "big.json", bpath, sizeof bpath) == 0);
    EXPECT_CTL(&d, 1, "TOO_LARGE", "submit", bpath);
    EXPECT_CTL(&d, 1, "per-client quota of 300 (--client-max-particles)", "submit", bpath);
    /* once the job has ended there is room again */
    /* "RUNNING (cancel requested ...)", or CANCELLED at once when a loaded
     * machine has not started it yet */
    EXPECT_CTL(&d, 0, "job 1: ", "cancel", "1");
    char st[32];
    CHECK(td_wait_status(&d, job, "CANCELLED", 20, st, sizeof st) == 0);
    /* 400 recorded snapshots of 256 particles: 9.4 MiB estimated, above
     * 1 MiB (the quota while a job runs: t_daemon_budget.c) */
    json_t *rec = block2d(400, 10, "recorded");
    set_output(rec, "snapshotEvery", json_integer(1));
    set_output(rec, "recordSnapshots", json_true());
    CHECK(write_case(rec, dir, "rec.json", bpath, sizeof bpath) == 0);
    EXPECT_CTL(&d, 1, "per-client quota of 1 MiB (--client-max-disk-mb)", "submit", bpath);
    EXPECT_CTL(&d, 1, "local's recorded runs take 0.00 MiB", "submit", bpath);
    CHECK(td_stop(&d) == 0);
}

/* A CURVE SUB on sep as the client key (pub, sec), subscribed to the
 * topics (NULL-terminated; "" is everything); NULL on failure. */
static void *curve_sub(void *zctx, const char *sep, const char *spub, const char *pub,
                       const char *sec, const char *const *topics)
{
    void *s = zmq_socket(zctx, ZMQ_SUB);
    int zero = 0;
    if (!s || zmq_setsockopt(s, ZMQ_LINGER, &zero, sizeof zero) ||
        zmq_setsockopt(s, ZMQ_CURVE_SERVERKEY, spub, 40) ||
        zmq_setsockopt(s, ZMQ_CURVE_PUBLICKEY, pub, 40) ||
        zmq_setsockopt(s, ZMQ_CURVE_SECRETKEY, sec, 40)) {
        if (s) zmq_close(s);
        return NULL;
    }
    for (int i = 0; topics[i]; i++)
        if (zmq_setsockopt(s, ZMQ_SUBSCRIBE, topics[i], strlen(topics[i]))) {
            zmq_close(s);
            return NULL;
        }
    if (zmq_connect(s, sep)) {
        zmq_close(s);
        return NULL;
    }
    return s;
}

/* Messages waiting on s (multipart: counted once), read within ms. */
static int drain(void *s, int ms)
{
    int n = 0;
    double end = td_now() + ms / 1000.0;
    for (;;) {
        zmq_pollitem_t it = {s, 0, ZMQ_POLLIN, 0};
        double left = end - td_now();
        if (zmq_poll(&it, 1, left > 0 ? (long)(left * 1000) : 0) <= 0) return n;
        zmq_msg_t part[4];
        int np = td_recv_parts(s, part, 4);
        for (int i = 0; i < np; i++) zmq_msg_close(&part[i]);
        n += np > 0;
    }
}

/* Waits up to timeout s until the daemon's log has text; 0 or -1. */
static int wait_log(const td_daemon *d, const char *text, double timeout)
{
    double end = td_now() + timeout;
    while (td_now() < end) {
        if (log_has(d, text)) return 0;
        td_msleep(50);
    }
    return -1;
}

/* Stream privacy under CURVE: a's job streams to a and to the admin key,
 * while another authorized key (b) subscribing to that job's topic and to
 * everything ("") receives nothing; a's late `watch` of its own job still
 * gives the whole series.  Read privacy (--private-runs): b's show,
 * energy, snapshot and watch of a's run are FORBIDDEN and its listing
 * holds its own run only; the admin reads and lists every run. */
DTEST(daemon_auth_stream_private)
{
    const char *tmp = t_tmpdir();
    char dir[300], srvkey[400], auth[400], admins[400], ep[64], sep[64], text[600];
    char spub[41], ssec[41], apub[41], asec[41], bpub[41], bsec[41], dpub[41], dsec[41];
    snprintf(dir, sizeof dir, "%s/private", tmp);
    mkdir(dir, 0700);
    if (keygen(dir, "srv", "server", spub, ssec) || keygen(dir, "a", "mpmd", apub, asec) ||
        keygen(dir, "b", "mpmd", bpub, bsec) || keygen(dir, "adm", "mpmd", dpub, dsec))
        return;
    snprintf(srvkey, sizeof srvkey, "%s/srv/server.key", dir);
    CHECK(give_server_key(dir, "a", spub) == 0 && give_server_key(dir, "b", spub) == 0 &&
          give_server_key(dir, "adm", spub) == 0);
    snprintf(auth, sizeof auth, "%s/authorized_keys", dir);
    snprintf(text, sizeof text, "%s alice\n%s bob\n", apub, bpub);
    CHECK(write_text(auth, text) == 0);
    snprintf(admins, sizeof admins, "%s/admins", dir);
    snprintf(text, sizeof text, "%s root\n", dpub);
    CHECK(write_text(admins, text) == 0);
    int port = td_tcp_port(2011);
    snprintf(ep, sizeof ep, "tcp://127.0.0.1:%d", port);
    snprintf(sep, sizeof sep, "tcp://127.0.0.1:%d", port + 1);
    const char *extra[] = {"--curve-secret", srvkey,      "--authorized-keys", auth, "--admin-keys",
                           admins,           "--verbose", "--private-runs",    NULL};
    td_daemon d;
    char ddir[400];
    snprintf(ddir, sizeof ddir, "%s/d", dir);
    td_set_curve(spub, apub, asec);
    if (td_start_ep(&d, ddir, ep, extra)) return;

    /* a's job 1 runs until cancelled: progress several times a second */
    char cpath[500];
    CHECK(write_case(long_case(100), dir, "long.json", cpath, sizeof cpath) == 0);
    td_out o;
    CTL_AS(&d, dir, "a", &o, "submit", cpath);
    unsigned long long job = job_of(o.out);
    td_out_free(&o);
    CHECKF(job == 1, "a's submit gave no job 1");
    char st[32];
    CHECK(td_wait_status(&d, job, "RUNNING", 20, st, sizeof st) == 0);

    void *zctx = zmq_ctx_new();
    CHECK(zctx);
    const char *topic = "job:0000000000000001:";
    const char *b_topics[] = {topic, "", NULL}, *one[] = {topic, NULL};
    /* b first: its subscriptions are refused before a's are applied */
    void *sb = curve_sub(zctx, sep, spub, bpub, bsec, b_topics);
    int ok = sb != NULL;
    snprintf(text, sizeof text, "job 1: stream subscription by %s refused: the job is %s's", bpub,
             apub);
    ok = ok && wait_log(&d, text, 20) == 0;
    snprintf(text, sizeof text, "stream subscription to a 0-byte prefix by %s not applied", bpub);
    ok = ok && wait_log(&d, text, 20) == 0;
    void *sa = ok ? curve_sub(zctx, sep, spub, apub, asec, one) : NULL;
    void *sd = ok ? curve_sub(zctx, sep, spub, dpub, dsec, one) : NULL;
    int na = 0, nd = 0, nb = 0;
    double end = td_now() + 30;
    while (sa && sd && (na < 3 || nd < 3) && td_now() < end) {
        na += drain(sa, 100);
        nd += drain(sd, 100);
    }
    /* b had every chance to get the same messages as a and the admin */
    if (sb) nb = drain(sb, 500);
    TLOG("stream of a's job: a got %d messages, the admin %d, b %d", na, nd, nb);
    if (sa) zmq_close(sa);
    if (sd) zmq_close(sd);
    if (sb) zmq_close(sb);
    zmq_ctx_term(zctx);
    CHECKF(ok, "b's subscriptions were not refused (daemon log)");
    CHECKF(na >= 3 && nd >= 3, "the owner (%d) or the admin (%d) did not receive the stream", na,
           nd);
    CHECKF(nb == 0, "b received %d messages of a's job", nb);

    /* --private-runs: b reads none of a's run, nor sees it listed; b's own
     * run it reads; the admin reads and lists both */
    static const char *const reads[][5] = {{"show", "1", NULL},
                                           {"energy", "1", "--csv", NULL},
                                           {"snapshot", "1", "-o", "-", NULL},
                                           {"watch", "1", NULL}};
    for (size_t i = 0; i < sizeof reads / sizeof reads[0]; i++) {
        const char *args[8] = {"--keys", NULL};
        char kd[400];
        snprintf(kd, sizeof kd, "%s/b", dir);
        args[1] = kd;
        for (int k = 0; reads[i][k]; k++) args[2 + k] = reads[i][k];
        CHECK(td_ctlv(&d, 30, &o, args) == 0);
        ok = o.status == 1 && strstr(o.err, "FORBIDDEN") && strstr(o.err, "--private-runs");
        TLOG("b: %s 1: exit %d: %.200s", reads[i][0], o.status, o.err);
        td_out_free(&o);
        CHECKF(ok, "b's %s of a's run was not FORBIDDEN", reads[i][0]);
    }
    char bpath[500];
    CHECK(write_case(bar_steps(600, 10), dir, "bar.json", bpath, sizeof bpath) == 0);
    CTL_AS(&d, dir, "b", &o, "submit", bpath);
    unsigned long long jb = job_of(o.out);
    td_out_free(&o);
    CHECK(jb == 2);
    CTL_AS(&d, dir, "b", &o, "runs", "--json");
    ok = o.status == 0 && count_lines(o.out) == 1 && strstr(o.out, bpub) && !strstr(o.out, apub);
    td_out_free(&o);
    CHECKF(ok, "b's listing is not its own run alone");
    CTL_AS(&d, dir, "adm", &o, "runs", "--json");
    ok = o.status == 0 && count_lines(o.out) == 2 && strstr(o.out, bpub) && strstr(o.out, apub);
    td_out_free(&o);
    CHECKF(ok, "the admin's listing does not show both runs");
    CTL_AS(&d, dir, "adm", &o, "show", "1");
    ok = o.status == 0;
    td_out_free(&o);
    CHECKF(ok, "the admin cannot read a's run");

    CTL_AS(&d, dir, "a", &o, "cancel", "1");
    td_out_free(&o);
    CHECK(td_wait_status(&d, job, "CANCELLED", 20, st, sizeof st) == 0);

    /* a's `watch` of its own job, after it started: the whole series */
    CTL_AS(&d, dir, "a", &o, "submit", bpath);
    unsigned long long job2 = job_of(o.out);
    td_out_free(&o);
    CHECK(job2 == 3);
    CTL_AS(&d, dir, "a", &o, "watch", "3", "--csv");
    series s = {0};
    ok = o.status == 0 && parse_csv(o.out, &s) == 0 && s.n == 61 && consecutive(&s);
    series_free(&s);
    td_out_free(&o);
    CHECKF(ok, "a's late watch of its job did not give the 61 samples");
    CHECK(td_stop(&d) == 0);
}

/* Per-key quotas: the allow-list's "KEY max-jobs=N max-particles=N
 * max-disk-mb=N comment" settings override the --client-max-* flags for
 * that key only; a bad setting refuses the start naming the file, line and
 * setting (and on SIGHUP leaves the previous list in force); SIGHUP
 * applies new settings. */
DTEST(daemon_auth_key_quotas)
{
    const char *tmp = t_tmpdir();
    char dir[300], srvkey[400], auth[400], ep[64], text[600];
    char spub[41], ssec[41], apub[41], asec[41], bpub[41];
    snprintf(dir, sizeof dir, "%s/keyquota", tmp);
    mkdir(dir, 0700);
    if (keygen(dir, "srv", "server", spub, ssec) || keygen(dir, "a", "mpmd", apub, asec) ||
        keygen(dir, "b", "mpmd", bpub, NULL))
        return;
    snprintf(srvkey, sizeof srvkey, "%s/srv/server.key", dir);
    CHECK(give_server_key(dir, "a", spub) == 0 && give_server_key(dir, "b", spub) == 0);
    snprintf(auth, sizeof auth, "%s/authorized_keys", dir);
    int port = td_tcp_port(3571);
    snprintf(ep, sizeof ep, "tcp://127.0.0.1:%d", port);

    /* bad settings: the start is refused naming file, line and setting */
    static const char *const bad[] = {"max-jobz=3", "max-jobs=-1", "max-disk-mb=1.5",
                                      "max-particles=x"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(text, sizeof text, "# clients\n%s max-jobs=1 %s alice\n", apub, bad[i]);
        CHECK(write_text(auth, text) == 0);
        char db[400];
        snprintf(db, sizeof db, "%s/bad.db", dir);
        const char *argv[] = {"--endpoint",        ep,   "--db", db, "--curve-secret", srvkey,
                              "--authorized-keys", auth, NULL};
        td_out o;
        CHECK(td_run_mpmd(argv, 20, &o) == 0);
        char want[600];
        snprintf(want, sizeof want, "%s:2: setting '%s'", auth, bad[i]);
        int ok = o.status != 0 && (strstr(o.err, want) || strstr(o.out, want));
        TLOG("%s: exit %d: %.200s", bad[i], o.status, o.err[0] ? o.err : o.out);
        td_out_free(&o);
        CHECKF(ok, "the setting %s was not refused naming the file, line and setting", bad[i]);
    }

    /* a: one job, 300 particles, 1 MiB; b: the flags' quotas (none) */
    snprintf(text, sizeof text, "%s max-jobs=1 max-particles=300 max-disk-mb=1 alice\n%s bob\n",
             apub, bpub);
    CHECK(write_text(auth, text) == 0);
    const char *extra[] = {"--curve-secret", srvkey, "--authorized-keys", auth, NULL};
    td_daemon d;
    char ddir[400];
    snprintf(ddir, sizeof ddir, "%s/d", dir);
    td_set_curve(spub, apub, asec);
    if (td_start_ep(&d, ddir, ep, extra)) return;
    char cpath[500], bigp[500], recp[500];
    CHECK(write_case(long_case(100000), dir, "long.json", cpath, sizeof cpath) == 0);
    CHECK(write_case(example("disks2d_fine"), dir, "big.json", bigp, sizeof bigp) == 0);
    json_t *rec = block2d(400, 10, "recorded");
    set_output(rec, "snapshotEvery", json_integer(1));
    set_output(rec, "recordSnapshots", json_true());
    CHECK(write_case(rec, dir, "rec.json", recp, sizeof recp) == 0);
    td_out o;
    /* (the job quota is checked before the disk's: this one first) */
    CTL_AS(&d, dir, "a", &o, "submit", recp);
    int ok = o.status == 1 && strstr(o.err, "per-client quota of 1 MiB (max-disk-mb of its key)");
    TLOG("a: rec: exit %d: %.200s", o.status, o.err);
    td_out_free(&o);
    CHECKF(ok, "a's 9.4 MiB case was not refused by its key's max-disk-mb");
    CTL_AS(&d, dir, "a", &o, "submit", cpath);
    ok = o.status == 0 && job_of(o.out) == 1;
    td_out_free(&o);
    CHECKF(ok, "a's first job was refused");
    static const struct {
        const char *path_of, *want;
    } refused[] = {{"long", "(max-jobs of its key 1)"},
                   {"big", "per-client quota of 300 (max-particles of its key)"}};
    for (size_t i = 0; i < 2; i++) {
        const char *p = i == 0 ? cpath : bigp;
        CTL_AS(&d, dir, "a", &o, "submit", p);
        ok = o.status == 1 && strstr(o.err, refused[i].want);
        TLOG("a: %s: exit %d: %.200s", refused[i].path_of, o.status, o.err);
        td_out_free(&o);
        CHECKF(ok, "a's %s case was not refused with \"%s\"", refused[i].path_of, refused[i].want);
    }
    /* b is bound by the flags only */
    for (int i = 0; i < 3; i++) {
        CTL_AS(&d, dir, "b", &o, "submit", i == 2 ? recp : i ? bigp : cpath);
        ok = o.status == 0 && job_of(o.out) > 1;
        td_out_free(&o);
        CHECKF(ok, "b's submission %d was refused", i);
    }
    /* SIGHUP with a bad setting: the previous list stays (a: one job) */
    snprintf(text, sizeof text, "%s max-jobs=two alice\n%s bob\n", apub, bpub);
    CHECK(write_text(auth, text) == 0);
    CHECK(kill(d.pid, SIGHUP) == 0);
    snprintf(text, sizeof text, "%s:1: setting 'max-jobs=two'", auth);
    CHECK(wait_log(&d, text, 20) == 0);
    CTL_AS(&d, dir, "a", &o, "submit", cpath);
    ok = o.status == 1 && strstr(o.err, "max-jobs of its key 1");
    TLOG("a after a bad SIGHUP: exit %d in %.1f s: %.200s", o.status, o.secs, o.err);
    td_out_free(&o);
    CHECKF(ok, "after a bad SIGHUP a's quota is not the previous one");
    /* SIGHUP with two jobs for a */
    snprintf(text, sizeof text, "%s max-jobs=2 alice\n%s bob\n", apub, bpub);
    CHECK(write_text(auth, text) == 0);
    CHECK(kill(d.pid, SIGHUP) == 0);
    CHECK(wait_log(&d, "SIGHUP: keys re-read", 20) == 0);
    CTL_AS(&d, dir, "a", &o, "submit", cpath);
    ok = o.status == 0 && job_of(o.out) > 1;
    TLOG("a after SIGHUP: exit %d: %.200s%.200s", o.status, o.out, o.err);
    td_out_free(&o);
    CHECKF(ok, "after SIGHUP a's second job was refused");
    CTL_AS(&d, dir, "a", &o, "submit", cpath);
    ok = o.status == 1 && strstr(o.err, "max-jobs of its key 2");
    td_out_free(&o);
    CHECKF(ok, "after SIGHUP a's third job was not refused");
    CHECK(td_stop(&d) == 0);
}
