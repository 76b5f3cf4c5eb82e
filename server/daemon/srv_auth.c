/*
 * srv_auth.c - CURVE keys, the client allow-list and the ZAP handler (see
 * srv_auth.h).  The key lists live behind a mutex: the ZAP thread reads
 * them for every handshake, the main thread replaces them on SIGHUP and
 * reads the admin list for a Cancel.  A list is a file of lines
 * "KEY [max-jobs=N] [max-particles=N] [max-disk-mb=N] [comment]" ('#'
 * lines and blank lines skipped) or a directory whose *.pub files are such
 * files.  The settings are the key's own quotas (srv_auth_quota): the
 * tokens after the key that start with "max-"; the first other token
 * begins the comment.
 *
 * Revocation.  A key removed at SIGHUP loses its open connections too:
 * libzmq has no handle on one connection of a bound socket, but each
 * message says which descriptor it came in on (ZMQ_SRCFD), so the daemon
 * notes the descriptor and key of every request and stream subscription
 * (srv_auth_note_peer) and the reload shuts down those of removed keys
 * (close_revoked); each request's key is also checked against the current
 * lists (srv_auth_key_ok).  Guarded by daemon_revoke_open_connections.
 */
#include "srv_auth.h"

#include "srv_grow.h"
#include "srv_log.h"

#include <dirent.h>
#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>
#include <zmq.h>

#define ZAP_EP "inproc://zeromq.zap.01"
#define ZAP_DOMAIN "mpmd"
#define GATE_DOMAIN "mpmd-requests" /* the request socket's, with a gate */
#define KEYS_MAX 100000             /* keys per list */

/* A listed key and its quota settings (-1: not set). */
typedef struct {
    char z[SRV_KEY_Z85_SIZE]; /* first: the sort key */
    long long q[3];           /* max-jobs, max-particles, max-disk-mb */
} keyent;

typedef struct {
    keyent *z; /* sorted by key */
    size_t n;
} keylist;

static const struct {
    const char *name;
    double hi;
} settings[3] = {
    {"max-jobs", 1e6}, {"max-particles", (double)MPM_MAX_PARTICLES}, {"max-disk-mb", 1e12}};

/* A connection that sent a request or a subscription: its descriptor's
 * socket (device and inode: a descriptor closed and reused for another
 * socket has another) and the key it authenticated with ("" = none). */
typedef struct {
    dev_t dev;
    ino_t ino;
    char key[SRV_KEY_Z85_SIZE];
} peer;
/* Descriptors above this are not noted (the daemon's RLIMIT_NOFILE is
 * lower); the table grows to the highest descriptor seen. */
#define PEER_FD_MAX (1 << 20)

struct srv_auth {
    int curve;
    peer *peers; /* indexed by descriptor; main thread only */
    size_t npeers;
    char secret[SRV_KEY_Z85_SIZE], public_[SRV_KEY_Z85_SIZE];
    char authorized_path[1024], admin_path[1024];
    pthread_mutex_t mu;
    keylist allowed, admins; /* under mu */
    void *zap;               /* the handler's REP (its thread's after start) */
    pthread_t thread;
    int started;
    srv_auth_gate gate; /* the connection cap (srv_auth_set_gate); admit NULL: none */
};

static int is_z85_key(const char *s, size_t n)
{
    uint8_t bin[32];
    char tmp[SRV_KEY_Z85_SIZE];
    if (n != SRV_KEY_Z85_LEN) return 0;
    memcpy(tmp, s, n);
    tmp[n] = 0;
    return zmq_z85_decode(bin, tmp) != NULL;
}

/* The key of one line (first token) into z: 1, 0 for no key (blank or
 * comment), -1 for a line that is not a key.  *rest: what follows it. */
static int line_key(const char *line, char *z, const char **rest)
{
    while (*line == ' ' || *line == '\t') line++;
    if (!*line || *line == '#' || *line == '\n' || *line == '\r') return 0;
    size_t n = strcspn(line, " \t\r\n");
    if (!is_z85_key(line, n)) return -1;
    memcpy(z, line, n);
    z[n] = 0;
    if (rest) *rest = line + n;
    return 1;
}

/* The settings after a key ("max-NAME=N" tokens, up to the comment) into
 * q (-1 when absent): 0, or -1 with the bad token and why in err. */
static int line_settings(const char *s, long long q[3], char *err, size_t errlen)
{
    for (int i = 0; i < 3; i++) q[i] = -1;
    for (;;) {
        while (*s == ' ' || *s == '\t') s++;
        size_t n = strcspn(s, " \t\r\n");
        if (!n || strncmp(s, "max-", 4)) return 0; /* the comment, or nothing */
        char tok[128];
        snprintf(tok, sizeof tok, "%.*s", (int)(n < 127 ? n : 127), s);
        char *eq = strchr(tok, '=');
        int k = -1;
        for (int i = 0; eq && i < 3; i++)
            if ((size_t)(eq - tok) == strlen(settings[i].name) &&
                !strncmp(tok, settings[i].name, (size_t)(eq - tok)))
                k = i;
        if (k < 0) {
            snprintf(err, errlen,
                     "setting '%s': unknown (max-jobs=N, max-particles=N or max-disk-mb=N)", tok);
            return -1;
        }
        char *end;
        errno = 0;
        double v = strtod(eq + 1, &end);
        if (errno || end == eq + 1 || *end || !(v >= 0 && v <= settings[k].hi) ||
            v != (long long)v) {
            snprintf(err, errlen, "setting '%s': %s expects a whole number in [0, %.0f]", tok,
                     settings[k].name, settings[k].hi);
            return -1;
        }
        q[k] = (long long)v;
        s += n;
    }
}

int srv_key_file_read(const char *path, int secret, char *z85, char *err, size_t errlen)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        snprintf(err, errlen, "cannot open the key file %s: %s", path, strerror(errno));
        return -1;
    }
    struct stat sb;
    if (secret && fstat(fileno(f), &sb) == 0 && (sb.st_mode & 077)) {
        snprintf(err, errlen,
                 "the secret key file %s has mode %04o: it must be 0600 or stricter "
                 "(chmod 600 %s)",
                 path, (unsigned)(sb.st_mode & 07777), path);
        fclose(f);
        return -1;
    }
    char line[512];
    int ln = 0;
    while (fgets(line, sizeof line, f)) {
        ln++;
        int k = line_key(line, z85, NULL);
        if (k == 0) continue;
        fclose(f);
        if (k < 0) {
            snprintf(err, errlen, "%s:%d: not a 40-character Z85 key", path, ln);
            return -1;
        }
        return 0;
    }
    fclose(f);
    snprintf(err, errlen, "%s holds no key", path);
    return -1;
}

static int cmp_key(const void *a, const void *b)
{
    return memcmp(a, b, SRV_KEY_Z85_SIZE);
}

static int list_add(keylist *l, const char *z, const long long q[3], size_t *cap)
{
    keyent *p = srv_grow(l->z, cap, l->n + 1, sizeof *p, KEYS_MAX);
    if (!p) return -1;
    l->z = p;
    keyent *e = &l->z[l->n++];
    memset(e->z, 0, SRV_KEY_Z85_SIZE);
    memcpy(e->z, z, SRV_KEY_Z85_LEN);
    memcpy(e->q, q, sizeof e->q);
    return 0;
}

/* Adds the keys of one list file to l. */
static int load_file(const char *path, keylist *l, size_t *cap, char *err, size_t errlen)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        snprintf(err, errlen, "cannot open %s: %s", path, strerror(errno));
        return -1;
    }
    char line[4096], z[SRV_KEY_Z85_SIZE], e[256];
    int ln = 0, rc = 0;
    while (!rc && fgets(line, sizeof line, f)) {
        ln++;
        const char *rest = NULL;
        long long q[3];
        int k = line_key(line, z, &rest);
        if (k < 0) {
            snprintf(err, errlen, "%s:%d: not a 40-character Z85 key", path, ln);
            rc = -1;
        } else if (k > 0 && line_settings(rest, q, e, sizeof e)) {
            snprintf(err, errlen, "%s:%d: %s", path, ln, e);
            rc = -1;
        } else if (k > 0 && list_add(l, z, q, cap)) {
            snprintf(err, errlen, "%s: more than %d keys", path, KEYS_MAX);
            rc = -1;
        }
    }
    fclose(f);
    return rc;
}

/* Loads a list from a file or a directory of *.pub files. */
static int load_list(const char *path, keylist *out, char *err, size_t errlen)
{
    keylist l = {0};
    size_t cap = 0;
    int rc = 0;
    memset(out, 0, sizeof *out);
    if (!*path) return 0;
    struct stat sb;
    if (stat(path, &sb)) {
        snprintf(err, errlen, "cannot read %s: %s", path, strerror(errno));
        return -1;
    }
    if (S_ISDIR(sb.st_mode)) {
        DIR *d = opendir(path);
        if (!d) {
            snprintf(err, errlen, "cannot read the directory %s: %s", path, strerror(errno));
            return -1;
        }
        struct dirent *e;
        while (!rc && (e = readdir(d))) {
            size_t n = strlen(e->d_name);
            if (n < 5 || strcmp(e->d_name + n - 4, ".pub") || e->d_name[0] == '.') continue;
            char fp[2048];
            snprintf(fp, sizeof fp, "%s/%s", path, e->d_name);
            rc = load_file(fp, &l, &cap, err, errlen);
        }
        closedir(d);
    } else {
        rc = load_file(path, &l, &cap, err, errlen);
    }
    if (rc) {
        free(l.z);
        return -1;
    }
    if (l.n) qsort(l.z, l.n, sizeof *l.z, cmp_key);
    *out = l;
    return 0;
}

static const keyent *list_find(const keylist *l, const char *z)
{
    char k[SRV_KEY_Z85_SIZE] = {0};
    if (strlen(z) != SRV_KEY_Z85_LEN) return NULL;
    memcpy(k, z, SRV_KEY_Z85_LEN);
    return l->n ? bsearch(k, l->z, l->n, sizeof *l->z, cmp_key) : NULL;
}

static int list_has(const keylist *l, const char *z)
{
    return list_find(l, z) != NULL;
}

/* Logs the keys of b not in a with the verb. */
static size_t log_diff(const keylist *a, const keylist *b, const char *what, const char *verb)
{
    size_t n = 0;
    for (size_t i = 0; i < b->n; i++)
        if (!list_has(a, b->z[i].z)) {
            srv_log(0, "%s: key %s %s", what, b->z[i].z, verb);
            n++;
        }
    return n;
}

int srv_auth_new(const srv_config *cfg, srv_auth **out, char *err, size_t errlen)
{
    srv_auth *a = calloc(1, sizeof *a);
    *out = NULL;
    if (!a) {
        snprintf(err, errlen, "out of memory");
        return -1;
    }
    pthread_mutex_init(&a->mu, NULL);
    *out = a;
    if (!cfg->curve_secret[0]) {
        if (cfg->authorized_keys[0] || cfg->admin_keys[0]) {
            snprintf(err, errlen,
                     "--authorized-keys and --admin-keys need --curve-secret (the server's "
                     "CURVE secret key: mpmctl keygen makes one)");
            return -1;
        }
        return 0;
    }
    if (!zmq_has("curve")) {
        snprintf(err, errlen, "--curve-secret: this libzmq has no CURVE support (libsodium)");
        return -1;
    }
    char e[1200];
    if (srv_key_file_read(cfg->curve_secret, 1, a->secret, e, sizeof e)) {
        snprintf(err, errlen, "--curve-secret: %s", e);
        return -1;
    }
    if (zmq_curve_public(a->public_, a->secret)) {
        snprintf(err, errlen, "--curve-secret %s: cannot derive the public key: %s",
                 cfg->curve_secret, zmq_strerror(errno));
        return -1;
    }
    if (!cfg->authorized_keys[0] && !cfg->admin_keys[0]) {
        snprintf(err, errlen,
                 "--curve-secret needs --authorized-keys (or --admin-keys): without a list "
                 "any client that knows the server's public key would be accepted");
        return -1;
    }
    snprintf(a->authorized_path, sizeof a->authorized_path, "%s", cfg->authorized_keys);
    snprintf(a->admin_path, sizeof a->admin_path, "%s", cfg->admin_keys);
    if (load_list(a->authorized_path, &a->allowed, e, sizeof e)) {
        snprintf(err, errlen, "--authorized-keys: %s", e);
        return -1;
    }
    if (load_list(a->admin_path, &a->admins, e, sizeof e)) {
        snprintf(err, errlen, "--admin-keys: %s", e);
        return -1;
    }
    a->curve = 1;
    srv_log(0, "CURVE on: server public key %s; %zu authorized key(s), %zu admin key(s)",
            a->public_, a->allowed.n, a->admins.n);
    return 0;
}

int srv_auth_curve(const srv_auth *a)
{
    return a && a->curve;
}

const char *srv_auth_server_public(const srv_auth *a)
{
    return a && a->curve ? a->public_ : "";
}

int srv_auth_key_ok(srv_auth *a, const char *key)
{
    if (!a || !a->curve) return 1;
    if (!key) return 0;
    pthread_mutex_lock(&a->mu);
    int ok = list_has(&a->allowed, key) || list_has(&a->admins, key);
    pthread_mutex_unlock(&a->mu);
    return ok;
}

void srv_auth_note_peer(srv_auth *a, zmq_msg_t *m, const char *key)
{
    if (!a || !a->curve || !key || strlen(key) != SRV_KEY_Z85_LEN) return;
    int fd = zmq_msg_get(m, ZMQ_SRCFD);
    struct stat sb;
    if (fd < 0 || fd >= PEER_FD_MAX || fstat(fd, &sb) != 0) return;
    if ((size_t)fd >= a->npeers) {
        size_t n = a->npeers ? a->npeers : 64;
        while (n <= (size_t)fd) n *= 2;
        peer *p = realloc(a->peers, n * sizeof *p);
        if (!p) {
            srv_warn(0, "out of memory noting a connection: a revoked key keeps it until it "
                        "leaves (its requests are refused)");
            return;
        }
        memset(p + a->npeers, 0, (n - a->npeers) * sizeof *p);
        a->peers = p;
        a->npeers = n;
    }
    peer *e = &a->peers[fd];
    e->dev = sb.st_dev;
    e->ino = sb.st_ino;
    memcpy(e->key, key, SRV_KEY_Z85_SIZE);
}

/* Closes the connections of keys no longer listed (after a reload): the
 * noted descriptors whose socket is still the one noted are shut down
 * (shutdown(2)): libzmq sees the connection end, drops what it queued for
 * it and, on the stream socket, its subscriptions; the client's reconnect
 * meets the ZAP handler, which refuses the key.  A descriptor closed and
 * reused for another socket since has another inode and is left alone.
 * Returns the connections closed. */
static size_t close_revoked(srv_auth *a)
{
    size_t closed = 0;
    for (size_t fd = 0; fd < a->npeers; fd++) {
        peer *e = &a->peers[fd];
        struct stat sb;
        if (!e->key[0] || list_has(&a->allowed, e->key) || list_has(&a->admins, e->key)) continue;
        if (fstat((int)fd, &sb) == 0 && sb.st_dev == e->dev && sb.st_ino == e->ino &&
            S_ISSOCK(sb.st_mode) && shutdown((int)fd, SHUT_RDWR) == 0) {
            srv_log(0, "SIGHUP: closed a connection of the revoked key %s", e->key);
            closed++;
        }
        memset(e, 0, sizeof *e);
    }
    return closed;
}

void srv_auth_reload(srv_auth *a)
{
    if (!a || !a->curve) return;
    keylist al, ad;
    char e[1200];
    if (load_list(a->authorized_path, &al, e, sizeof e)) {
        srv_error(0, "SIGHUP: --authorized-keys: %s; the previous keys stay in force", e);
        return;
    }
    if (load_list(a->admin_path, &ad, e, sizeof e)) {
        srv_error(0, "SIGHUP: --admin-keys: %s; the previous keys stay in force", e);
        free(al.z);
        return;
    }
    pthread_mutex_lock(&a->mu);
    size_t add = log_diff(&a->allowed, &al, "--authorized-keys", "added");
    size_t del = log_diff(&al, &a->allowed, "--authorized-keys", "removed");
    add += log_diff(&a->admins, &ad, "--admin-keys", "added");
    del += log_diff(&ad, &a->admins, "--admin-keys", "removed");
    free(a->allowed.z);
    free(a->admins.z);
    a->allowed = al;
    a->admins = ad;
    size_t closed = del ? close_revoked(a) : 0;
    pthread_mutex_unlock(&a->mu);
    srv_log(0,
            "SIGHUP: keys re-read: %zu added, %zu removed; %zu authorized, %zu admin; %zu "
            "connection(s) of removed keys closed",
            add, del, al.n, ad.n, closed);
}

void srv_auth_quota(srv_auth *a, const srv_config *cfg, const char *owner, srv_quota *q)
{
    long long v[3] = {cfg->client_max_jobs, cfg->client_max_particles, cfg->client_max_disk_mb};
    if (a && a->curve && owner) {
        pthread_mutex_lock(&a->mu);
        /* the authorized list's settings first, then the admin list's */
        const keyent *e[2] = {list_find(&a->allowed, owner), list_find(&a->admins, owner)};
        for (int k = 0; k < 3; k++)
            for (int i = 1; i >= 0; i--)
                if (e[i] && e[i]->q[k] >= 0) v[k] = e[i]->q[k];
        pthread_mutex_unlock(&a->mu);
    }
    q->max_jobs = v[0];
    q->max_particles = v[1];
    q->max_disk_mb = v[2];
}

int srv_auth_is_admin(srv_auth *a, const char *owner)
{
    if (!a || !a->curve || !owner) return 0;
    pthread_mutex_lock(&a->mu);
    int r = list_has(&a->admins, owner);
    pthread_mutex_unlock(&a->mu);
    return r;
}

/* ---- the ZAP handler ---- */

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static int send_str(void *s, const char *str, int more)
{
    return zmq_send(s, str, strlen(str), more ? ZMQ_SNDMORE : 0) < 0 ? -1 : 0;
}

/* Answers one ZAP request (RFC 27): frames version, request id, domain,
 * address, identity, mechanism, credentials. */
static void zap_answer(srv_auth *a, zmq_msg_t *f, int n)
{
    char z[SRV_KEY_Z85_SIZE] = "";
    const char *status = "400", *text = "unknown key";
    int ok = 0, open = 0;
    if (n >= 6 && !a->curve && zmq_msg_size(&f[5]) == 4 &&
        !memcmp(zmq_msg_data(&f[5]), "NULL", 4)) {
        ok = 1; /* no CURVE: only the gate decides */
        status = "200", text = "OK";
    } else if (n >= 7 && zmq_msg_size(&f[5]) == 5 && !memcmp(zmq_msg_data(&f[5]), "CURVE", 5) &&
               zmq_msg_size(&f[6]) == 32 && zmq_z85_encode(z, zmq_msg_data(&f[6]), 32)) {
        pthread_mutex_lock(&a->mu);
        ok = list_has(&a->allowed, z) || list_has(&a->admins, z);
        pthread_mutex_unlock(&a->mu);
        if (ok) status = "200", text = "OK";
    } else {
        text = "CURVE only";
    }
    int gated = n >= 3 && zmq_msg_size(&f[2]) == strlen(GATE_DOMAIN) &&
                !memcmp(zmq_msg_data(&f[2]), GATE_DOMAIN, strlen(GATE_DOMAIN));
    if (ok && gated && a->gate.admit &&
        (a->gate.drain(a->gate.arg), !a->gate.admit(a->gate.arg, &open))) {
        /* past --max-connections: libzmq closes the connection (guarded
         * by daemon_conns_cap_holds); logged once a second at most */
        static double last;
        static unsigned long skipped;
        double now = now_s();
        ok = 0;
        status = "300", text = "too many connections";
        if (now - last >= 1.0) {
            srv_warn(0,
                     "connection refused: %d connections open (limit %d, --max-connections; "
                     "%lu more refused in the last second)",
                     open, a->gate.max, skipped);
            last = now;
            skipped = 0;
        } else {
            skipped++;
        }
        goto reply;
    }
    char addr[64] = "?";
    if (n >= 4) {
        size_t k = zmq_msg_size(&f[3]) < sizeof addr - 1 ? zmq_msg_size(&f[3]) : sizeof addr - 1;
        memcpy(addr, zmq_msg_data(&f[3]), k);
        addr[k] = 0;
    }
    if (ok)
        srv_debug(0, "ZAP: key %s from %s accepted", z[0] ? z : "(none)", addr);
    else
        srv_warn(0, "ZAP: refused %s from %s: %s", z[0] ? z : "a client", addr,
                 z[0] ? "key not in --authorized-keys or --admin-keys" : text);
reply:
    if (n < 2) return;
    if (send_str(a->zap, "1.0", 1) ||
        zmq_send(a->zap, zmq_msg_data(&f[1]), zmq_msg_size(&f[1]), ZMQ_SNDMORE) < 0 ||
        send_str(a->zap, status, 1) || send_str(a->zap, text, 1) ||
        send_str(a->zap, ok ? z : "", 1) || send_str(a->zap, "", 0))
        srv_warn(0, "ZAP reply: %s", zmq_strerror(errno));
}

static void *zap_thread(void *arg)
{
    srv_auth *a = arg;
    for (;;) {
        if (a->gate.side) {
            /* the gate's events as they come, so that they never pile up */
            zmq_pollitem_t it[2] = {{a->zap, 0, ZMQ_POLLIN, 0}, {a->gate.side, 0, ZMQ_POLLIN, 0}};
            if (zmq_poll(it, 2, -1) < 0) {
                if (errno == EINTR) continue;
                break;
            }
            if ((it[1].revents & ZMQ_POLLIN) && a->gate.drain(a->gate.arg)) break;
            if (!(it[0].revents & ZMQ_POLLIN)) continue;
        }
        zmq_msg_t f[8];
        int n = 0, more = 1, term = 0;
        while (more) {
            zmq_msg_t m;
            zmq_msg_init(&m);
            if (zmq_msg_recv(&m, a->zap, 0) < 0) {
                zmq_msg_close(&m);
                if (errno == EINTR) continue;
                term = 1;
                break;
            }
            more = zmq_msg_more(&m);
            if (n < 8)
                f[n++] = m;
            else
                zmq_msg_close(&m);
        }
        if (!term) zap_answer(a, f, n);
        for (int i = 0; i < n; i++) zmq_msg_close(&f[i]);
        if (term) break;
    }
    int zero = 0;
    zmq_setsockopt(a->zap, ZMQ_LINGER, &zero, sizeof zero);
    zmq_close(a->zap);
    if (a->gate.side) zmq_close(a->gate.side);
    return NULL;
}

void srv_auth_set_gate(srv_auth *a, const srv_auth_gate *g)
{
    a->gate = *g;
}

int srv_auth_zap_domain(void *sock)
{
    return zmq_setsockopt(sock, ZMQ_ZAP_DOMAIN, GATE_DOMAIN, strlen(GATE_DOMAIN));
}

int srv_auth_start(srv_auth *a, void *zctx, char *err, size_t errlen)
{
    if (!a->curve && !a->gate.admit) return 0;
    a->zap = zmq_socket(zctx, ZMQ_REP);
    if (!a->zap || zmq_bind(a->zap, ZAP_EP)) {
        snprintf(err, errlen, "ZAP handler: %s", zmq_strerror(errno));
        if (a->zap) zmq_close(a->zap);
        a->zap = NULL;
        return -1;
    }
    if (pthread_create(&a->thread, NULL, zap_thread, a)) {
        snprintf(err, errlen, "ZAP handler: cannot start its thread");
        zmq_close(a->zap);
        a->zap = NULL;
        return -1;
    }
    a->started = 1;
    return 0;
}

int srv_auth_secure(srv_auth *a, void *sock, char *err, size_t errlen)
{
    if (!a || !a->curve) return 0;
    int one = 1;
    uint8_t key[32];
    if (!zmq_z85_decode(key, a->secret) ||
        zmq_setsockopt(sock, ZMQ_ZAP_DOMAIN, ZAP_DOMAIN, strlen(ZAP_DOMAIN)) ||
        zmq_setsockopt(sock, ZMQ_CURVE_SERVER, &one, sizeof one) ||
        zmq_setsockopt(sock, ZMQ_CURVE_SECRETKEY, key, sizeof key)) {
        snprintf(err, errlen, "CURVE options: %s", zmq_strerror(errno));
        return -1;
    }
    return 0;
}

void srv_auth_destroy(srv_auth **pa)
{
    srv_auth *a = *pa;
    if (!a) return;
    if (a->started) pthread_join(a->thread, NULL);
    free(a->allowed.z);
    free(a->admins.z);
    free(a->peers);
    pthread_mutex_destroy(&a->mu);
    memset(a->secret, 0, sizeof a->secret);
    free(a);
    *pa = NULL;
}
