/*
 * srv_ckpt.c - checkpoint files of the daemon's runs (see srv_ckpt.h).
 *
 * The header is the host's layout (a checkpoint is read back by the same
 * build on the same machine type, as the solver's blob is), 64 bytes:
 * magic "MPMDCKP1", format, header size, run id, step, t, next energy seq,
 * blob length, checksum.  The checksum (FNV-1a over 8-byte words) covers
 * the header's first 56 bytes; the blob carries its own over all its bytes
 * (mpm_checkpoint_verify()), so a flipped bit anywhere, a truncated file
 * or another run's file renamed into place is refused at read, before a
 * simulation is built, and the hundreds of MB of a 10^6-particle run are
 * hashed once per save, by the solver.
 */
#include "srv_ckpt.h"

#include "srv_log.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define CK_MAGIC "MPMDCKP1"
#define CK_FORMAT 1u

typedef struct {
    char magic[8];
    uint32_t format, hlen;
    int64_t run, step;
    double t;
    int64_t energy_seq;
    uint64_t blob_len;
    uint64_t sum; /* of the 56 bytes before it and the blob */
} ck_header;

_Static_assert(sizeof(ck_header) == SRV_CKPT_HEADER, "the checkpoint header is 64 bytes");

static uint64_t mix(uint64_t h, const uint8_t *p, size_t n)
{
    const uint64_t prime = 0x100000001b3ULL;
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        uint64_t w;
        memcpy(&w, p + i, 8);
        h = (h ^ w) * prime;
        h ^= h >> 29;
    }
    for (; i < n; i++) h = (h ^ p[i]) * prime;
    return h;
}

static uint64_t checksum(const ck_header *h)
{
    return mix(0xcbf29ce484222325ULL, (const uint8_t *)h, offsetof(ck_header, sum));
}

static int dir_path(const char *db, char *buf, size_t len)
{
    int n = snprintf(buf, len, "%s.ckpt", db);
    return n < 0 || (size_t)n >= len ? -1 : 0;
}

int srv_ckpt_path(const char *db, int64_t run, int temp, char *buf, size_t len)
{
    int n = snprintf(buf, len, "%s.ckpt/run-%lld.ckpt%s", db, (long long)run, temp ? ".tmp" : "");
    return n < 0 || (size_t)n >= len ? -1 : 0;
}

int srv_ckpt_init(const char *db, char *err, size_t errlen)
{
    char dir[1200], path[1500];
    if (dir_path(db, dir, sizeof dir)) {
        snprintf(err, errlen, "checkpoint directory: the path of %s is too long", db);
        return -1;
    }
    if (mkdir(dir, 0700) && errno != EEXIST) {
        snprintf(err, errlen, "cannot create the checkpoint directory %s: %s", dir,
                 strerror(errno));
        return -1;
    }
    /* owner-only, also when an older mpmd made it (daemon_perms_files) */
    struct stat sb;
    if (lstat(dir, &sb) == 0 && S_ISDIR(sb.st_mode) && sb.st_uid == geteuid() &&
        (sb.st_mode & 077) && chmod(dir, 0700) != 0)
        srv_warn(0, "cannot make %s owner-only: %s", dir, strerror(errno));
    DIR *d = opendir(dir);
    if (!d) {
        snprintf(err, errlen, "cannot open the checkpoint directory %s: %s", dir, strerror(errno));
        return -1;
    }
    struct dirent *e;
    while ((e = readdir(d))) {
        size_t n = strlen(e->d_name);
        if (n > 9 && !strncmp(e->d_name, "run-", 4) && !strcmp(e->d_name + n - 9, ".ckpt.tmp")) {
            int k = snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
            if (k > 0 && (size_t)k < sizeof path) unlink(path);
        }
    }
    closedir(d);
    return 0;
}

/* Writes n bytes at p; 0 or -1 (errno). */
static int write_all(int fd, const uint8_t *p, size_t n)
{
    while (n) {
        ssize_t w = write(fd, p, n > ((size_t)1 << 30) ? (size_t)1 << 30 : n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            if (w == 0) errno = EIO;
            return -1;
        }
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

int srv_ckpt_write(const char *db, int64_t run, const mpm_sim *sim, int64_t energy_seq,
                   srv_ckpt_buf *b, store_checkpoint *rec, char *err, size_t errlen)
{
    char tmp[1500], path[1500], dir[1200];
    if (srv_ckpt_path(db, run, 1, tmp, sizeof tmp) ||
        srv_ckpt_path(db, run, 0, path, sizeof path) || dir_path(db, dir, sizeof dir)) {
        snprintf(err, errlen, "checkpoint: the path of %s is too long", db);
        return MPM_EINVAL;
    }
    size_t n = mpm_sim_checkpoint_size(sim), need = sizeof(ck_header) + n;
    if (need > b->cap) {
        uint8_t *nb = realloc(b->buf, need);
        if (!nb) {
            snprintf(err, errlen, "out of memory for a checkpoint of %zu bytes", need);
            return MPM_ENOMEM;
        }
        b->buf = nb;
        b->cap = need;
    }
    int rc = mpm_sim_checkpoint_save(sim, b->buf + sizeof(ck_header), n);
    if (rc) {
        snprintf(err, errlen, "the solver cannot save its state (%s)", mpm_strerror(rc));
        return rc;
    }
    ck_header h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, CK_MAGIC, 8);
    h.format = CK_FORMAT;
    h.hlen = sizeof h;
    h.run = run;
    h.step = mpm_sim_steps(sim);
    h.t = mpm_sim_time(sim);
    h.energy_seq = energy_seq;
    h.blob_len = n;
    h.sum = checksum(&h);
    memcpy(b->buf, &h, sizeof h);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) {
        snprintf(err, errlen, "cannot create %s: %s", tmp, strerror(errno));
        return MPM_EIO;
    }
    if (write_all(fd, b->buf, need) || fsync(fd)) {
        snprintf(err, errlen, "cannot write %s: %s", tmp, strerror(errno));
        close(fd);
        unlink(tmp);
        return MPM_EIO;
    }
    if (close(fd)) {
        snprintf(err, errlen, "cannot write %s: %s", tmp, strerror(errno));
        unlink(tmp);
        return MPM_EIO;
    }
    if (rename(tmp, path)) {
        snprintf(err, errlen, "cannot rename %s to %s: %s", tmp, path, strerror(errno));
        unlink(tmp);
        return MPM_EIO;
    }
    /* the rename itself is durable once the directory is */
    int dfd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd < 0 || fsync(dfd)) {
        snprintf(err, errlen, "cannot sync the directory %s: %s", dir, strerror(errno));
        if (dfd >= 0) close(dfd);
        return MPM_EIO;
    }
    close(dfd);
    rec->step = h.step;
    rec->t = h.t;
    rec->bytes = (int64_t)need;
    rec->energy_seq = energy_seq;
    return 0;
}

int srv_ckpt_read(const char *db, int64_t run, srv_ckpt_file *out, char *err, size_t errlen)
{
    char path[1500];
    memset(out, 0, sizeof *out);
    if (srv_ckpt_path(db, run, 0, path, sizeof path)) {
        snprintf(err, errlen, "checkpoint: the path of %s is too long", db);
        return MPM_EINVAL;
    }
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        int e = errno;
        snprintf(err, errlen, "run %lld has no checkpoint%s%s", (long long)run,
                 e == ENOENT ? "" : ": ", e == ENOENT ? "" : strerror(e));
        return e == ENOENT ? MPM_ENOTFOUND : MPM_EIO;
    }
    struct stat st;
    if (fstat(fd, &st) || !S_ISREG(st.st_mode)) {
        snprintf(err, errlen, "%s: not a regular file", path);
        close(fd);
        return MPM_EIO;
    }
    size_t size = (size_t)st.st_size;
    if ((off_t)size != st.st_size || size < sizeof(ck_header)) {
        snprintf(err, errlen, "%s is damaged: %lld bytes, shorter than its header", path,
                 (long long)st.st_size);
        close(fd);
        return MPM_ESYNTAX;
    }
    uint8_t *buf = malloc(size);
    if (!buf) {
        snprintf(err, errlen, "out of memory reading %s (%zu bytes)", path, size);
        close(fd);
        return MPM_ENOMEM;
    }
    size_t got = 0;
    while (got < size) {
        ssize_t r = read(fd, buf + got, size - got);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) break;
        got += (size_t)r;
    }
    close(fd);
    ck_header h;
    memcpy(&h, buf, sizeof h);
    const char *bad = NULL;
    if (got != size)
        bad = "it could not be read whole";
    else if (memcmp(h.magic, CK_MAGIC, 8) || h.hlen != sizeof h)
        bad = "not an mpmd checkpoint";
    else if (h.format != CK_FORMAT)
        bad = "another checkpoint format version";
    else if (h.blob_len != size - sizeof h)
        bad = "truncated (its length differs from its header's)";
    else if (h.run != run)
        bad = "it is another run's";
    else if (h.step < 0 || h.energy_seq < 0)
        bad = "its header is invalid";
    else if (checksum(&h) != h.sum)
        bad = "checksum mismatch (header)";
    mpm_error e;
    if (!bad && mpm_checkpoint_verify(buf + sizeof h, (size_t)h.blob_len, &e)) bad = e.message;
    if (bad) {
        snprintf(err, errlen, "run %lld's checkpoint %s is damaged: %s", (long long)run, path, bad);
        free(buf);
        return MPM_ESYNTAX;
    }
    out->rec.step = h.step;
    out->rec.t = h.t;
    out->rec.bytes = (int64_t)size;
    out->rec.energy_seq = h.energy_seq;
    out->buf = buf;
    out->blob = buf + sizeof h;
    out->blob_len = (size_t)h.blob_len;
    return 0;
}

void srv_ckpt_file_clear(srv_ckpt_file *f)
{
    if (!f) return;
    free(f->buf);
    memset(f, 0, sizeof *f);
}

int srv_ckpt_remove(const char *db, int64_t run)
{
    char path[1500];
    if (srv_ckpt_path(db, run, 0, path, sizeof path)) return -1;
    if (unlink(path) && errno != ENOENT) return -1;
    return 0;
}
