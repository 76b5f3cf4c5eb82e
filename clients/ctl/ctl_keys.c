/*
 * ctl_keys.c - mpmctl's CURVE keys: `mpmctl keygen` (a keypair as Z85 text
 * files, the secret one mode 0600 and never overwritten), and the keys a
 * connection uses: the server's public key and the client's secret key
 * (its public key derived from it), from the environment (MPMD_SERVER_KEY:
 * a Z85 key or a file holding one; MPMD_CLIENT_KEY: the client's secret
 * key file) or from a key directory (--keys DIR, else $MPMD_KEYS, else
 * ~/.config/mpmd when it exists and the endpoint is not loopback or ipc://)
 * holding server.pub and mpmd.key.  With no
 * server key the connection goes without CURVE (loopback, ipc://).
 */
#include "ctl.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <zmq.h>

#define KEY_LEN 40

/* 1 if s[0..n) is a Z85 key. */
static int is_key(const char *s, size_t n)
{
    char tmp[KEY_LEN + 1];
    uint8_t bin[32];
    if (n != KEY_LEN) return 0;
    memcpy(tmp, s, n);
    tmp[n] = 0;
    return zmq_z85_decode(bin, tmp) != NULL;
}

/* Reads the key of a key file (the first line that is not blank or a '#'
 * comment; a comment may follow the key); secret: the file must not be
 * readable by group or others.  0, or CTL_ESYS with a message naming
 * what (e.g. "MPMD_CLIENT_KEY") and the file. */
static int read_key_file(const char *path, int secret, const char *what, char *z)
{
    FILE *f = fopen(path, "r");
    if (!f) {
        fprintf(stderr, "mpmctl: %s: cannot open %s: %s\n", what, path, strerror(errno));
        return CTL_ESYS;
    }
    struct stat sb;
    if (secret && fstat(fileno(f), &sb) == 0 && (sb.st_mode & 077)) {
        fprintf(stderr,
                "mpmctl: %s: the secret key file %s has mode %04o: it must be 0600 or "
                "stricter (chmod 600 %s)\n",
                what, path, (unsigned)(sb.st_mode & 07777), path);
        fclose(f);
        return CTL_ESYS;
    }
    char line[512];
    while (fgets(line, sizeof line, f)) {
        const char *s = line;
        while (*s == ' ' || *s == '\t') s++;
        if (!*s || *s == '#' || *s == '\n' || *s == '\r') continue;
        size_t n = strcspn(s, " \t\r\n");
        fclose(f);
        if (!is_key(s, n)) {
            fprintf(stderr, "mpmctl: %s: %s does not start with a 40-character Z85 key\n", what,
                    path);
            return CTL_ESYS;
        }
        memcpy(z, s, n);
        z[n] = 0;
        return 0;
    }
    fclose(f);
    fprintf(stderr, "mpmctl: %s: %s holds no key\n", what, path);
    return CTL_ESYS;
}

static int exists(const char *path)
{
    struct stat sb;
    return stat(path, &sb) == 0;
}

int ctl_keys_load(ctl_conn *c, const char *keys_dir)
{
    char dir[1024] = "", sp[1200], cp[1200];
    const char *env_srv = getenv("MPMD_SERVER_KEY"), *env_cli = getenv("MPMD_CLIENT_KEY");
    const char *home = getenv("HOME");
    int rc;
    c->curve = 0;
    if (keys_dir && *keys_dir)
        snprintf(dir, sizeof dir, "%s", keys_dir);
    else if (getenv("MPMD_KEYS") && *getenv("MPMD_KEYS"))
        snprintf(dir, sizeof dir, "%s", getenv("MPMD_KEYS"));
    else if (home && *home && !mpp_endpoint_is_local(c->endpoint)) {
        /* the default directory serves remote daemons only: a local one
         * (make demo) is reached without keys however the user's remote
         * servers are set up */
        snprintf(dir, sizeof dir, "%s/.config/mpmd", home);
        if (!exists(dir)) dir[0] = 0;
    }
    snprintf(sp, sizeof sp, "%s/server.pub", dir);
    snprintf(cp, sizeof cp, "%s/mpmd.key", dir);
    /* the server's public key */
    if (env_srv && *env_srv) {
        if (is_key(env_srv, strlen(env_srv)))
            memcpy(c->server_key, env_srv, KEY_LEN + 1);
        else if ((rc = read_key_file(env_srv, 0, "MPMD_SERVER_KEY", c->server_key)))
            return rc;
    } else if (dir[0] && exists(sp)) {
        if ((rc = read_key_file(sp, 0, "the server's public key", c->server_key))) return rc;
    } else {
        if (keys_dir && *keys_dir) {
            fprintf(stderr,
                    "mpmctl: --keys %s: no server.pub there (the server's public key: mpmd "
                    "logs it at start)\n",
                    keys_dir);
            return CTL_EUSAGE;
        }
        return 0; /* no CURVE */
    }
    /* the client's secret key */
    if (env_cli && *env_cli) {
        if ((rc = read_key_file(env_cli, 1, "MPMD_CLIENT_KEY", c->secret_key))) return rc;
    } else if (dir[0] && exists(cp)) {
        if ((rc = read_key_file(cp, 1, "the client's secret key", c->secret_key))) return rc;
    } else {
        fprintf(stderr,
                "mpmctl: a server key is set but no client key: set MPMD_CLIENT_KEY to your "
                "secret key file or put it in %s (mpmctl keygen makes one)\n",
                dir[0] ? cp : "KEYDIR/mpmd.key");
        return CTL_EUSAGE;
    }
    if (zmq_curve_public(c->public_key, c->secret_key)) {
        fprintf(stderr, "mpmctl: cannot derive the client's public key: %s\n", zmq_strerror(errno));
        return CTL_ESYS;
    }
    c->curve = 1;
    return 0;
}

int ctl_conn_secure(ctl_conn *c, void *sock)
{
    if (!c->curve) return 0;
    if (zmq_setsockopt(sock, ZMQ_CURVE_SERVERKEY, c->server_key, KEY_LEN + 1) ||
        zmq_setsockopt(sock, ZMQ_CURVE_PUBLICKEY, c->public_key, KEY_LEN + 1) ||
        zmq_setsockopt(sock, ZMQ_CURVE_SECRETKEY, c->secret_key, KEY_LEN + 1)) {
        fprintf(stderr, "mpmctl: CURVE options: %s\n", zmq_strerror(errno));
        return CTL_ESYS;
    }
    return 0;
}

/* Writes text to path, created with mode (O_EXCL: never overwrites). */
static int write_new(const char *path, mode_t mode, const char *text)
{
    int fd = open(path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, mode);
    if (fd < 0) {
        fprintf(stderr, "mpmctl: keygen: cannot create %s: %s%s\n", path, strerror(errno),
                errno == EEXIST ? " (keygen never overwrites a key; remove it first)" : "");
        return CTL_ESYS;
    }
    size_t n = strlen(text);
    ssize_t w = write(fd, text, n);
    if (fchmod(fd, mode) || w != (ssize_t)n || close(fd)) {
        fprintf(stderr, "mpmctl: keygen: cannot write %s: %s\n", path, strerror(errno));
        unlink(path);
        return CTL_ESYS;
    }
    return 0;
}

/* mkdir -p: dir and each missing parent, created mode 0700 (a key
 * directory such as ~/.config/mpmd where ~/.config is missing too; guarded
 * by docs_blocks_readme, whose security recipe starts from an empty home).
 * 0, or CTL_ESYS with a message naming the directory. */
static int make_dirs(const char *dir)
{
    char p[1024];
    size_t n = strlen(dir);
    if (n >= sizeof p) {
        fprintf(stderr, "mpmctl: keygen: --out: the path is longer than %zu bytes\n", sizeof p - 1);
        return CTL_ESYS;
    }
    memcpy(p, dir, n + 1);
    for (size_t i = 1; i <= n; i++) {
        if (p[i] != '/' && p[i] != 0) continue;
        if (p[i - 1] == '/') continue; /* "a//b", a trailing '/' */
        char c = p[i];
        p[i] = 0;
        if (mkdir(p, 0700) && errno != EEXIST) {
            fprintf(stderr, "mpmctl: keygen: cannot create %s: %s\n", p, strerror(errno));
            return CTL_ESYS;
        }
        p[i] = c;
    }
    struct stat sb;
    if (stat(dir, &sb) || !S_ISDIR(sb.st_mode)) {
        fprintf(stderr, "mpmctl: keygen: %s is not a directory\n", dir);
        return CTL_ESYS;
    }
    return 0;
}

int ctl_keygen(const char *dir, const char *name)
{
    char pub[KEY_LEN + 1], sec[KEY_LEN + 1], pp[1200], spth[1200], text[256];
    if (!zmq_has("curve")) {
        fprintf(stderr, "mpmctl: keygen: this libzmq has no CURVE support\n");
        return CTL_ESYS;
    }
    if (!dir || !*dir) dir = ".";
    if (!name || !*name) name = "mpmd";
    if (make_dirs(dir)) return CTL_ESYS;
    if (zmq_curve_keypair(pub, sec)) {
        fprintf(stderr, "mpmctl: keygen: %s\n", zmq_strerror(errno));
        return CTL_ESYS;
    }
    snprintf(spth, sizeof spth, "%s/%s.key", dir, name);
    snprintf(pp, sizeof pp, "%s/%s.pub", dir, name);
    if (exists(spth) || exists(pp)) {
        fprintf(stderr, "mpmctl: keygen: %s exists: keygen never overwrites a key\n",
                exists(spth) ? spth : pp);
        return CTL_ESYS;
    }
    snprintf(text, sizeof text, "%s\n", sec);
    int rc = write_new(spth, 0600, text);
    memset(sec, 0, sizeof sec);
    memset(text, 0, sizeof text);
    if (rc) return rc;
    snprintf(text, sizeof text, "%s %s\n", pub, name);
    if ((rc = write_new(pp, 0644, text))) {
        unlink(spth);
        return rc;
    }
    printf("secret key: %s (mode 0600: keep it private)\npublic key: %s\n%s\n", spth, pp, pub);
    return 0;
}
