/*
 * t_web_cdp.c - headless Chromium over the DevTools pipe (see
 * t_web_cdp.h).  Every wait is bounded; events the browser sends are
 * skipped, only the answer with the command's id is kept.
 */
#include "t_web_cdp.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "t_daemon.h"

int cdp_open(cdp_t *c, const char *browser, const char *profile_dir, const char *errlog)
{
    int to[2], from[2];
    char prof[400];
    memset(c, 0, sizeof *c);
    c->wfd = c->rfd = -1;
    if (pipe(to)) return -1;
    if (pipe(from)) {
        close(to[0]);
        close(to[1]);
        return -1;
    }
    snprintf(prof, sizeof prof, "--user-data-dir=%s", profile_dir);
    pid_t pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        setpgid(0, 0);
        int in = open("/dev/null", O_RDONLY);
        int err = open(errlog, O_WRONLY | O_CREAT | O_APPEND, 0600);
        if (in < 0 || err < 0) _exit(126);
        /* fd 3 and 4 may be taken by the pipes themselves: move them up */
        int r = fcntl(to[0], F_DUPFD, 10), w = fcntl(from[1], F_DUPFD, 10);
        if (r < 0 || w < 0 || dup2(r, 3) < 0 || dup2(w, 4) < 0) _exit(126);
        dup2(in, 0);
        dup2(err, 1);
        dup2(err, 2);
        for (int fd = 5; fd < 1024; fd++) close(fd);
        execl(browser, browser, "--headless=new", "--no-sandbox", "--disable-gpu",
              "--hide-scrollbars", "--no-first-run", "--no-default-browser-check",
              "--remote-debugging-pipe", prof, "about:blank", (char *)NULL);
        _exit(127);
    }
    close(to[0]);
    close(from[1]);
    c->pid = pid;
    c->wfd = to[1];
    c->rfd = from[0];
    c->next_id = 1;
    return 0;
}

/* The next whole message (malloc'd, NUL-terminated) within timeout s. */
static char *next_message(cdp_t *c, double timeout)
{
    double end = td_now() + timeout;
    for (;;) {
        char *z = c->n ? memchr(c->buf, 0, c->n) : NULL;
        if (z) {
            size_t k = (size_t)(z - c->buf) + 1;
            char *m = malloc(k);
            if (!m) return NULL;
            memcpy(m, c->buf, k);
            memmove(c->buf, c->buf + k, c->n - k);
            c->n -= k;
            return m;
        }
        double left = end - td_now();
        if (left <= 0) return NULL;
        struct pollfd p = {c->rfd, POLLIN, 0};
        int r = poll(&p, 1, (int)(left * 1000) + 1);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) return NULL;
        if (c->n + 65536 > c->cap) {
            size_t cap = c->cap ? c->cap * 2 : 1 << 20;
            while (cap < c->n + 65536) cap *= 2;
            char *b = realloc(c->buf, cap);
            if (!b) return NULL;
            c->buf = b;
            c->cap = cap;
        }
        ssize_t got = read(c->rfd, c->buf + c->n, c->cap - c->n);
        if (got <= 0) return NULL;
        c->n += (size_t)got;
    }
}

json_t *cdp_call(cdp_t *c, int page, const char *method, json_t *params, double timeout)
{
    int id = c->next_id++;
    json_t *m = json_pack("{s:i,s:s,s:o}", "id", id, "method", method, "params",
                          params ? params : json_object());
    if (!m) return NULL;
    if (page) json_object_set_new(m, "sessionId", json_string(c->session));
    char *text = json_dumps(m, JSON_COMPACT);
    json_decref(m);
    if (!text) return NULL;
    size_t len = strlen(text) + 1; /* with the NUL */
    size_t off = 0;
    while (off < len) {
        ssize_t w = write(c->wfd, text + off, len - off);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            free(text);
            return NULL;
        }
        off += (size_t)w;
    }
    free(text);
    double end = td_now() + timeout;
    for (;;) {
        double left = end - td_now();
        char *msg = left > 0 ? next_message(c, left) : NULL;
        if (!msg) {
            TLOG("cdp: no answer to %s within %g s", method, timeout);
            return NULL;
        }
        json_t *r = json_loads(msg, 0, NULL);
        free(msg);
        json_t *rid = r ? json_object_get(r, "id") : NULL;
        if (!rid || json_integer_value(rid) != id) {
            json_decref(r);
            continue; /* an event, or an old answer */
        }
        json_t *res = json_object_get(r, "result");
        if (!res) {
            char *e = json_dumps(json_object_get(r, "error"), JSON_COMPACT);
            TLOG("cdp: %s failed: %s", method, e ? e : "?");
            free(e);
            json_decref(r);
            return NULL;
        }
        json_incref(res);
        json_decref(r);
        return res;
    }
}

int cdp_page(cdp_t *c, const char *url, int w, int h)
{
    json_t *r = cdp_call(c, 0, "Target.createTarget", json_pack("{s:s}", "url", "about:blank"), 30);
    const char *tid = r ? json_string_value(json_object_get(r, "targetId")) : NULL;
    if (!tid) {
        json_decref(r);
        return -1;
    }
    json_t *a = cdp_call(c, 0, "Target.attachToTarget",
                         json_pack("{s:s,s:b}", "targetId", tid, "flatten", 1), 30);
    json_decref(r);
    const char *sid = a ? json_string_value(json_object_get(a, "sessionId")) : NULL;
    if (!sid) {
        json_decref(a);
        return -1;
    }
    snprintf(c->session, sizeof c->session, "%s", sid);
    json_decref(a);
    json_t *m = cdp_call(c, 1, "Emulation.setDeviceMetricsOverride",
                         json_pack("{s:i,s:i,s:i,s:b}", "width", w, "height", h,
                                   "deviceScaleFactor", 1, "mobile", 0),
                         30);
    if (!m) return -1;
    json_decref(m);
    json_t *n = cdp_call(c, 1, "Page.navigate", json_pack("{s:s}", "url", url), 30);
    if (!n) return -1;
    json_decref(n);
    return 0;
}

int cdp_eval(cdp_t *c, const char *expr, char *out, size_t n)
{
    json_t *r = cdp_call(c, 1, "Runtime.evaluate",
                         json_pack("{s:s,s:b}", "expression", expr, "returnByValue", 1), 30);
    json_t *v = r ? json_object_get(json_object_get(r, "result"), "value") : NULL;
    int rc = -1;
    if (v && json_is_string(v)) {
        snprintf(out, n, "%s", json_string_value(v));
        rc = 0;
    } else if (v) {
        char *t = json_dumps(v, JSON_COMPACT | JSON_ENCODE_ANY);
        if (t) {
            snprintf(out, n, "%s", t);
            rc = 0;
        }
        free(t);
    }
    json_decref(r);
    return rc;
}

static int b64(int ch)
{
    if (ch >= 'A' && ch <= 'Z') return ch - 'A';
    if (ch >= 'a' && ch <= 'z') return ch - 'a' + 26;
    if (ch >= '0' && ch <= '9') return ch - '0' + 52;
    if (ch == '+') return 62;
    if (ch == '/') return 63;
    return -1;
}

int cdp_screenshot(cdp_t *c, const char *path)
{
    json_t *r = cdp_call(c, 1, "Page.captureScreenshot", json_pack("{s:s}", "format", "png"), 60);
    const char *d = r ? json_string_value(json_object_get(r, "data")) : NULL;
    int rc = -1;
    if (d) {
        size_t len = strlen(d), k = 0;
        unsigned char *bin = malloc(len / 4 * 3 + 3);
        unsigned acc = 0;
        int bits = 0;
        for (size_t i = 0; bin && i < len; i++) {
            int v = b64((unsigned char)d[i]);
            if (v < 0) continue; /* padding */
            acc = (acc << 6) | (unsigned)v;
            bits += 6;
            if (bits >= 8) {
                bits -= 8;
                bin[k++] = (unsigned char)(acc >> bits);
            }
        }
        FILE *f = bin ? fopen(path, "wb") : NULL;
        if (f) {
            rc = fwrite(bin, 1, k, f) == k ? 0 : -1;
            if (fclose(f)) rc = -1;
        }
        free(bin);
    }
    json_decref(r);
    return rc;
}

void cdp_close(cdp_t *c)
{
    if (c->pid > 0) {
        json_t *r = cdp_call(c, 0, "Browser.close", NULL, 5);
        json_decref(r);
        double end = td_now() + 10;
        int ws;
        while (waitpid(c->pid, &ws, WNOHANG) == 0 && td_now() < end) td_msleep(50);
        if (waitpid(c->pid, &ws, WNOHANG) == 0) {
            kill(-c->pid, SIGKILL);
            kill(c->pid, SIGKILL);
            waitpid(c->pid, &ws, 0);
        }
    }
    if (c->wfd >= 0) close(c->wfd);
    if (c->rfd >= 0) close(c->rfd);
    free(c->buf);
    memset(c, 0, sizeof *c);
    c->wfd = c->rfd = -1;
}
