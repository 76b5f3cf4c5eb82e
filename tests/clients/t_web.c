/*
 * t_web.c - the live web monitor, mpmweb, tested end to end: a real mpmd
 * (t_daemon.h) running the paper's bouncing disks, a real mpmweb on a free
 * loopback port, plain HTTP over a socket for the API and its safety rules
 * (JSON-escaped names, control refused without --allow-control and without
 * its header, foreign Host refused, non-loopback --listen refused without
 * --allow-remote), and Debian's headless Chromium (driven over the
 * DevTools pipe, t_web_cdp.c: --dump-dom with --virtual-time-budget never
 * returns while an event stream is open, virtual time waiting for it) on
 * the page of the running job: what the page records on its canvases must
 * show the energy plot's points and all the job's particles drawn, both
 * advancing while the same page stays open, its screenshots must be PNGs
 * with more than one colour, and after the job ends the record must come
 * with its time slider.  The screenshots
 * are kept in build/test-web/.  Without chromium the browser part is
 * skipped, saying so (deploy/install-deps.sh installs it).
 *
 * mpmweb comes from MPMWEB_BIN (the Makefile sets it), else beside
 * MPMD_BIN; it serves the page from clients/web/static (the tests run from
 * the source tree).
 */
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <unistd.h>

#include "t_daemon_util.h"
#include "t_web_cdp.h"

#define CHROMIUM "/usr/bin/chromium"

/* A file's text (malloc'd), NULL when unreadable. */
static char *slurp(const char *path)
{
    size_t n;
    return td_slurp(path, &n);
}

/* ---- processes ------------------------------------------------------------ */

/* fork + exec argv in its own process group, stdout/stderr into files. */
static pid_t spawn_to(const char *const *argv, const char *out, const char *err)
{
    pid_t pid = fork();
    if (pid != 0) return pid;
    setpgid(0, 0);
    int in = open("/dev/null", O_RDONLY);
    int fo = open(out, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    int fe = open(err, O_WRONLY | O_CREAT | O_APPEND, 0600);
    if (in < 0 || fo < 0 || fe < 0) _exit(126);
    dup2(in, 0);
    dup2(fo, 1);
    dup2(fe, 2);
    execv(argv[0], (char *const *)argv);
    _exit(127);
}

/* Waits up to timeout s: the exit status (128 + signal), or -1 after
 * killing the whole group on timeout. */
static int wait_for(pid_t pid, double timeout)
{
    double end = td_now() + timeout;
    int ws;
    for (;;) {
        pid_t r = waitpid(pid, &ws, WNOHANG);
        if (r == pid) return WIFEXITED(ws) ? WEXITSTATUS(ws) : 128 + WTERMSIG(ws);
        if (r < 0) return -1;
        if (td_now() > end) {
            kill(-pid, SIGKILL);
            kill(pid, SIGKILL);
            waitpid(pid, &ws, 0);
            return -1;
        }
        td_msleep(20);
    }
}

/* A running mpmweb. */
typedef struct {
    pid_t pid;
    int port;
    char out[320], err[320];
} web_t;

static const char *web_bin(void)
{
    static char path[512];
    const char *b = getenv("MPMWEB_BIN");
    if (b && *b) return b;
    const char *d = getenv("MPMD_BIN");
    if (!d) return NULL;
    snprintf(path, sizeof path, "%s", d);
    char *slash = strrchr(path, '/');
    snprintf(slash ? slash + 1 : path, sizeof path - (size_t)(slash ? slash + 1 - path : 0),
             "mpmweb");
    return path;
}

/* Starts mpmweb with the arguments (NULL-terminated) and waits for the
 * line that names its port; 0, or -1 with the reason logged. */
static int web_start(web_t *w, const char *tag, const char *const *args)
{
    const char *argv[24];
    int n = 0;
    const char *bin = web_bin();
    memset(w, 0, sizeof *w);
    if (!bin || access(bin, X_OK)) {
        TLOG("mpmweb not found (MPMWEB_BIN, or beside MPMD_BIN): %s", bin ? bin : "(unset)");
        return -1;
    }
    argv[n++] = bin;
    argv[n++] = "--static";
    argv[n++] = "clients/web/static";
    for (; *args && n < 22; args++) argv[n++] = *args;
    argv[n] = NULL;
    snprintf(w->out, sizeof w->out, "%s/%s.out", t_tmpdir(), tag);
    snprintf(w->err, sizeof w->err, "%s/%s.err", t_tmpdir(), tag);
    w->pid = spawn_to(argv, w->out, w->err);
    if (w->pid < 0) return -1;
    double end = td_now() + 20;
    while (td_now() < end) {
        char *text = slurp(w->out);
        const char *p = text ? strstr(text, "serving http://") : NULL;
        const char *q = p ? strchr(p + strlen("serving http://"), '/') : NULL;
        while (q && q > p && q[-1] != ':') q--;
        if (q && q > p) w->port = atoi(q);
        free(text);
        if (w->port > 0) return 0;
        int ws;
        if (waitpid(w->pid, &ws, WNOHANG) == w->pid) {
            char *e = slurp(w->err);
            TLOG("mpmweb exited at start: %s", e ? e : "");
            free(e);
            w->pid = 0;
            return -1;
        }
        td_msleep(50);
    }
    TLOG("mpmweb did not say where it serves within 20 s");
    return -1;
}

/* SIGTERM; its exit status (0 for a clean stop). */
static int web_stop(web_t *w)
{
    if (w->pid <= 0) return -1;
    kill(w->pid, SIGTERM);
    int st = wait_for(w->pid, 20);
    w->pid = 0;
    return st;
}

/* ---- HTTP over a plain socket --------------------------------------------------- */

typedef struct {
    int status;
    char *head, *body; /* NUL-terminated; head: the status line and headers */
} http_t;

static void http_free(http_t *h)
{
    free(h->head);
    h->head = h->body = NULL;
}

/* One request (HTTP/1.0, connection closed by the server after the
 * answer); extra: more header lines ("Name: value\r\n"), may be "". */
static int http(int port, const char *method, const char *path, const char *extra, const char *body,
                http_t *h)
{
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
    struct timeval tv = {10, 0};
    char req[4096];
    memset(h, 0, sizeof *h);
    inet_pton(AF_INET, "127.0.0.1", &a.sin_addr);
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) return -1;
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    if (connect(fd, (struct sockaddr *)&a, sizeof a)) {
        close(fd);
        return -1;
    }
    size_t bl = body ? strlen(body) : 0;
    int k = snprintf(req, sizeof req,
                     "%s %s HTTP/1.0\r\nHost: 127.0.0.1:%d\r\n%sContent-Length: %zu\r\n\r\n",
                     method, path, port, extra, bl);
    if (write(fd, req, (size_t)k) != k || (bl && write(fd, body, bl) != (ssize_t)bl)) {
        close(fd);
        return -1;
    }
    size_t n = 0, cap = 65536;
    char *buf = malloc(cap);
    for (;;) {
        if (!buf) break;
        if (n + 4096 > cap) {
            char *p = realloc(buf, cap *= 2);
            if (!p) {
                free(buf);
                buf = NULL;
                break;
            }
            buf = p;
        }
        ssize_t r = read(fd, buf + n, cap - n - 1);
        if (r <= 0) break;
        n += (size_t)r;
    }
    close(fd);
    if (!buf) return -1;
    buf[n] = 0;
    char *sep = strstr(buf, "\r\n\r\n");
    if (!sep || sscanf(buf, "HTTP/1.%*d %d", &h->status) != 1) {
        free(buf);
        return -1;
    }
    *sep = 0;
    h->head = buf;
    h->body = sep + 4;
    return 0;
}

/* ---- what the browser drew ------------------------------------------------------ */

/* The page's record of what it drew, read in the browser. */
typedef struct {
    long long energy, particles, step;
    char status[32];
} drawn_t;

static int page_state(cdp_t *b, drawn_t *d)
{
    char out[256];
    memset(d, 0, sizeof *d);
    d->energy = d->particles = d->step = -1;
    if (cdp_eval(b,
                 "(() => { const e = document.getElementById('energy'), "
                 "p = document.getElementById('particles'); return [e.dataset.energyPoints, "
                 "p.dataset.particlesDrawn, p.dataset.snapshotStep, "
                 "document.body.dataset.runStatus || '-'].join(' '); })()",
                 out, sizeof out))
        return -1;
    return sscanf(out, "%lld %lld %lld %31s", &d->energy, &d->particles, &d->step, d->status) == 4
               ? 0
               : -1;
}

/* Polls the page up to timeout s until ok(d, arg) holds; 0 or -1. */
static int page_wait(cdp_t *b, drawn_t *d, int (*ok)(const drawn_t *, const void *),
                     const void *arg, double timeout)
{
    double end = td_now() + timeout;
    while (td_now() < end) {
        if (page_state(b, d) == 0 && ok(d, arg)) return 0;
        td_msleep(200);
    }
    return -1;
}

/* The screenshot: a PNG whose pixels are not all one colour, decoded by
 * Debian's Python (zlib, the filters) rather than trusted by its size. */
static int png_check(const char *path, int *w, int *h, int *colours)
{
    static const char script[] =
        "import sys,zlib,struct\n"
        "d=open(sys.argv[1],'rb').read()\n"
        "assert d[:8]==b'\\x89PNG\\r\\n\\x1a\\n'\n"
        "i=8;idat=b'';W=H=0\n"
        "while i<len(d):\n"
        " n,t=struct.unpack('>I4s',d[i:i+8]);c=d[i+8:i+8+n];i+=12+n\n"
        " if t==b'IHDR':W,H,bd,ct=struct.unpack('>IIBB',c[:10]);assert bd==8 and ct in(2,6)\n"
        " if t==b'IDAT':idat+=c\n"
        "bpp=3 if ct==2 else 4;raw=zlib.decompress(idat);s=W*bpp;prev=bytearray(s);cols=set();p=0\n"
        "for y in range(H):\n"
        " f=raw[p];line=bytearray(raw[p+1:p+1+s]);p+=1+s\n"
        " for x in range(s):\n"
        "  a=line[x-bpp] if x>=bpp else 0;b=prev[x];cc=prev[x-bpp] if x>=bpp else 0\n"
        "  if f==1:line[x]=(line[x]+a)&255\n"
        "  elif f==2:line[x]=(line[x]+b)&255\n"
        "  elif f==3:line[x]=(line[x]+(a+b)//2)&255\n"
        "  elif f==4:\n"
        "   q=a+b-cc;pa=abs(q-a);pb=abs(q-b);pc=abs(q-cc)\n"
        "   line[x]=(line[x]+(a if pa<=pb and pa<=pc else b if pb<=pc else cc))&255\n"
        " prev=line\n"
        " if y%4==0:cols.update(bytes(line[k:k+3]) for k in range(0,s,bpp*4))\n"
        "print(W,H,len(cols))\n";
    char sp[320], out[320], err[320];
    snprintf(sp, sizeof sp, "%s/png_check.py", t_tmpdir());
    snprintf(out, sizeof out, "%s/png_check.out", t_tmpdir());
    snprintf(err, sizeof err, "%s/png_check.err", t_tmpdir());
    if (td_write(sp, script)) return -1;
    const char *argv[] = {"/usr/bin/python3", sp, path, NULL};
    pid_t pid = spawn_to(argv, out, err);
    int st = pid > 0 ? wait_for(pid, 60) : -1;
    char *text = slurp(out);
    int ok = st == 0 && text && sscanf(text, "%d %d %d", w, h, colours) == 3;
    if (!ok) {
        char *e = slurp(err);
        TLOG("png check of %s failed (%d): %s", path, st, e ? e : "");
        free(e);
    }
    free(text);
    return ok ? 0 : -1;
}

/* ---- the tests --------------------------------------------------------------------- */

/* The disks of the paper (fine), slowed to a run of ~10 s of wall time
 * (dt / 4), recording and streaming a snapshot every 100 steps, with a
 * name a page must not interpret. */
#define HOSTILE_NAME "disks <script>alert(1)</script> & \"q\" <img src=x onerror=alert(2)>"

static json_t *disks_case(void)
{
    json_t *c = example("disks2d_fine");
    if (!c) return NULL;
    json_object_set_new(c, "name", json_string(HOSTILE_NAME));
    json_object_set_new(c, "dt", json_real(0.00025));
    json_object_set_new(c, "endTime", json_real(6.5));
    set_output(c, "energyEvery", json_integer(20));
    set_output(c, "snapshotEvery", json_integer(100));
    set_output(c, "recordSnapshots", json_true());
    return c;
}

static web_t live_web;
static cdp_t browser = {.wfd = -1, .rfd = -1};

static int drew_all(const drawn_t *d, const void *arg)
{
    return d->energy > 0 && d->particles == *(const long long *)arg && d->step >= 0;
}

static int advanced(const drawn_t *d, const void *arg)
{
    const long long *a = arg; /* energy points, snapshot step */
    return d->energy > a[0] && d->step >= a[1];
}

static int ended(const drawn_t *d, const void *arg)
{
    (void)arg;
    return strcmp(d->status, "RUNNING") && strcmp(d->status, "QUEUED") && strcmp(d->status, "-");
}

static int at_step(const drawn_t *d, const void *arg)
{
    return d->step == *(const long long *)arg;
}

static void web_cleanup(void)
{
    cdp_close(&browser);
    if (live_web.pid > 0) {
        kill(live_web.pid, SIGKILL);
        waitpid(live_web.pid, NULL, 0);
        live_web.pid = 0;
    }
}

/* A test whose mpmweb and browser are stopped however it returns (and its
 * daemons, by DTEST). */
#define WTEST(name)             \
    static void w_##name(void); \
    DTEST(name)                 \
    {                           \
        w_##name();             \
        web_cleanup();          \
    }                           \
    static void w_##name(void)

WTEST(web_browser_live)
{
    td_daemon d;
    char dir[300], path[400], url[256], ids[32];
    snprintf(dir, sizeof dir, "%s/d", t_tmpdir());
    CHECK(td_start(&d, dir, NULL) == 0);
    const char *wargs[] = {"--endpoint", d.ep, "--listen", "127.0.0.1:0", NULL};
    CHECK(web_start(&live_web, "web", wargs) == 0);
    int port = live_web.port;

    CHECK(write_case(disks_case(), t_tmpdir(), "disks.json", path, sizeof path) == 0);
    td_out o;
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0);
    unsigned long long job = job_of(o.out);
    td_out_free(&o);
    CHECK(job > 0);
    CHECK(td_wait_steps(&d, job, 300, 60) == 0);

    /* the API: the runs listing, the name exact after JSON decoding, its
     * quotes escaped in the text */
    http_t h;
    CHECK(http(port, "GET", "/api/runs?limit=5", "", NULL, &h) == 0);
    CHECKF(h.status == 200, "GET /api/runs: %d %s", h.status, h.body);
    CHECK(strstr(h.head, "Content-Type: application/json") != NULL);
    CHECK(strstr(h.body, "\\\"q\\\"") != NULL);
    json_t *list = json_loads(h.body, 0, NULL);
    http_free(&h);
    CHECK(list != NULL);
    json_t *run0 = json_array_get(json_object_get(list, "runs"), 0);
    int name_ok = run0 && !strcmp(jstr(run0, "name"), HOSTILE_NAME);
    unsigned long long run_id = run0 ? (unsigned long long)jint(run0, "runId") : 0;
    long long particles = run0 ? jint(run0, "particles") : 0;
    json_decref(list);
    CHECK(name_ok);
    CHECK(run_id > 0 && particles > 0);
    TLOG("job %llu, run %llu: %lld particles", job, run_id, particles);

    /* the name filter */
    CHECK(http(port, "GET", "/api/runs?name=nomatch", "", NULL, &h) == 0);
    CHECKF(h.status == 200 && !strstr(h.body, "disks"), "%d %s", h.status, h.body);
    http_free(&h);
    CHECK(http(port, "GET", "/api/runs?status=BOGUS", "", NULL, &h) == 0);
    CHECKF(h.status == 400 && strstr(h.body, "status"), "%d %s", h.status, h.body);
    http_free(&h);

    /* the page: shipped with a CSP that forbids inline script; the script
     * never uses innerHTML */
    CHECK(http(port, "GET", "/", "", NULL, &h) == 0);
    CHECK(h.status == 200 && strstr(h.body, "app.js"));
    CHECK(strstr(h.head, "Content-Security-Policy: default-src 'self'") != NULL);
    CHECK(strstr(h.head, "X-Content-Type-Options: nosniff") != NULL);
    http_free(&h);
    char *js = slurp("clients/web/static/app.js");
    CHECK(js != NULL);
    int no_inner = !strstr(js, "innerHTML") && !strstr(js, "outerHTML") &&
                   !strstr(js, "insertAdjacentHTML") && !strstr(js, "document.write");
    free(js);
    CHECK(no_inner);

    /* read-only: control refused, the job untouched */
    snprintf(url, sizeof url, "/api/cancel/%llu", job);
    CHECK(http(port, "POST", url, "X-Mpmweb: 1\r\n", "", &h) == 0);
    CHECKF(h.status == 403 && strstr(h.body, "--allow-control"), "%d %s", h.status, h.body);
    http_free(&h);
    CHECK(http(port, "POST", "/api/submit", "X-Mpmweb: 1\r\n", "{}", &h) == 0);
    CHECKF(h.status == 403, "%d %s", h.status, h.body);
    http_free(&h);
    char st[32];
    CHECK(td_job_status(&d, job, st, sizeof st, NULL) == 0 && !strcmp(st, "RUNNING"));

    /* a page of another site that resolves to 127.0.0.1 (DNS rebinding) */
    {
        struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
        inet_pton(AF_INET, "127.0.0.1", &a.sin_addr);
        int fd = socket(AF_INET, SOCK_STREAM, 0);
        CHECK(fd >= 0);
        struct timeval tv = {10, 0};
        setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
        CHECK(connect(fd, (struct sockaddr *)&a, sizeof a) == 0);
        const char rq[] = "GET /api/runs HTTP/1.0\r\nHost: evil.example:80\r\n\r\n";
        CHECK(write(fd, rq, sizeof rq - 1) == (ssize_t)(sizeof rq - 1));
        char buf[256] = {0};
        ssize_t r = read(fd, buf, sizeof buf - 1);
        close(fd);
        CHECKF(r > 0 && strstr(buf, " 403 "), "foreign Host: %s", buf);
    }

    /* errors: a run that does not exist, a bad id */
    CHECK(http(port, "GET", "/api/run/999999", "", NULL, &h) == 0);
    CHECKF(h.status == 404 && strstr(h.body, "NOT_FOUND"), "%d %s", h.status, h.body);
    http_free(&h);
    CHECK(http(port, "GET", "/api/snapshot/abc", "", NULL, &h) == 0);
    CHECKF(h.status == 400, "%d %s", h.status, h.body);
    http_free(&h);

    if (access(CHROMIUM, X_OK)) {
        TLOG("SKIPPED the browser part: %s is not installed (deploy/install-deps.sh installs "
             "chromium)",
             CHROMIUM);
        td_stop(&d);
        return;
    }

    /* the browser: the page of the running job, drawn, then drawn again as
     * the stream brings more (the same page, live) */
    char prof[320], errlog[320], png[64], buf[512];
    snprintf(prof, sizeof prof, "%s/chromium", t_tmpdir());
    snprintf(errlog, sizeof errlog, "%s/chromium.err", t_tmpdir());
    snprintf(url, sizeof url, "http://127.0.0.1:%d/#run=%llu", port, run_id);
    CHECK(cdp_open(&browser, CHROMIUM, prof, errlog) == 0);
    CHECK(cdp_page(&browser, url, 1200, 820) == 0);
    drawn_t d1, d2, d3;
    CHECKF(page_wait(&browser, &d1, drew_all, &particles, 40) == 0,
           "the page drew %lld energy points and %lld of %lld particles (status %s)", d1.energy,
           d1.particles, particles, d1.status);
    TLOG("first look: %lld energy points, %lld particles drawn, snapshot step %lld, %s", d1.energy,
         d1.particles, d1.step, d1.status);
    CHECKF(!strcmp(d1.status, "RUNNING"), "the job is %s: the test needs it live", d1.status);
    /* the name as text: no element made of it */
    CHECK(cdp_eval(&browser,
                   "[document.getElementById('r-title').textContent, "
                   "document.querySelectorAll('img').length, document.scripts.length].join('|')",
                   buf, sizeof buf) == 0);
    CHECKF(!strncmp(buf, HOSTILE_NAME, strlen(HOSTILE_NAME)) && strstr(buf, "|0|1"),
           "title, images, scripts: %s", buf);
    mkdir("build", 0755);
    mkdir("build/test-web", 0755);
    CHECK(cdp_screenshot(&browser, "build/test-web/live1.png") == 0);
    long long after[2] = {d1.energy, d1.step + 1000};
    CHECKF(page_wait(&browser, &d2, advanced, after, 40) == 0,
           "the page did not update: energy points %lld -> %lld, snapshot step %lld -> %lld",
           d1.energy, d2.energy, d1.step, d2.step);
    TLOG("later, same page: %lld energy points, %lld particles drawn, snapshot step %lld",
         d2.energy, d2.particles, d2.step);
    CHECK(d2.particles == particles);
    CHECK(cdp_screenshot(&browser, "build/test-web/live2.png") == 0);
    for (int i = 1; i <= 2; i++) {
        int pw = 0, ph = 0, cols = 0;
        snprintf(png, sizeof png, "build/test-web/live%d.png", i);
        CHECK(png_check(png, &pw, &ph, &cols) == 0);
        TLOG("%s: %dx%d PNG, %d colours (sampled)", png, pw, ph, cols);
        CHECK(pw == 1200 && ph == 820);
        CHECKF(cols > 16, "the screenshot has %d colours", cols);
    }

    /* the end reaches the page; then the run as a record: the slider */
    snprintf(ids, sizeof ids, "%llu", job);
    CHECK(td_ctl(&d, 30, &o, "cancel", ids, NULL) == 0);
    td_out_free(&o);
    CHECK(td_wait_status(&d, job, "CANCELLED|FINISHED|FAILED", 30, st, sizeof st) == 0);
    CHECKF(page_wait(&browser, &d3, ended, NULL, 20) == 0, "the page still says %s", d3.status);
    snprintf(buf, sizeof buf, "location.hash = '#run=%llu&step=200'", run_id);
    CHECK(cdp_eval(&browser, buf, buf, sizeof buf) == 0);
    long long want = 200;
    CHECKF(page_wait(&browser, &d3, at_step, &want, 20) == 0, "the slider shows step %lld",
           d3.step);
    CHECK(cdp_eval(&browser, "String(document.getElementById('slider-box').hidden)", buf,
                   sizeof buf) == 0);
    CHECK(!strcmp(buf, "false"));
    TLOG("the record: %s, %lld energy points, snapshot step %lld on the slider", d3.status,
         d3.energy, d3.step);
    CHECK(d3.energy >= d2.energy && d3.particles == particles);
    cdp_close(&browser);

    CHECK(web_stop(&live_web) == 0);
    CHECK(td_stop(&d) == 0);
}

/* Control from the page, when enabled: only with the header, and then the
 * daemon cancels the job. */
WTEST(web_control_enabled)
{
    td_daemon d;
    web_t w;
    char dir[300], path[400], url[64];
    http_t h;
    snprintf(dir, sizeof dir, "%s/d", t_tmpdir());
    CHECK(td_start(&d, dir, NULL) == 0);
    const char *wargs[] = {"--endpoint", d.ep, "--listen", "127.0.0.1:0", "--allow-control", NULL};
    CHECK(web_start(&w, "webc", wargs) == 0);
    live_web = w;
    CHECK(write_case(long_case(10), t_tmpdir(), "long.json", path, sizeof path) == 0);
    char *text = slurp(path);
    CHECK(text != NULL);
    /* without the header: refused (a cross-site form cannot add it) */
    int rc = http(w.port, "POST", "/api/submit", "Content-Type: application/json\r\n", text, &h);
    if (!rc) {
        int refused = h.status == 403;
        http_free(&h);
        if (!refused) free(text);
        CHECK(refused);
    }
    rc = http(w.port, "POST", "/api/submit", "X-Mpmweb: 1\r\n", text, &h);
    free(text);
    CHECK(rc == 0);
    CHECKF(h.status == 200, "submit: %d %s", h.status, h.body);
    json_t *ok = json_loads(h.body, 0, NULL);
    http_free(&h);
    unsigned long long job = ok ? (unsigned long long)jint(ok, "jobId") : 0;
    json_decref(ok);
    CHECK(job > 0);
    char st[32];
    CHECK(td_wait_status(&d, job, "RUNNING", 30, st, sizeof st) == 0);
    /* a bad case: the field named */
    CHECK(http(w.port, "POST", "/api/submit", "X-Mpmweb: 1\r\n", "{\"dt\": \"x\"}", &h) == 0);
    CHECKF(h.status == 400 && strstr(h.body, "dt"), "%d %s", h.status, h.body);
    http_free(&h);
    snprintf(url, sizeof url, "/api/cancel/%llu", job);
    CHECK(http(w.port, "POST", url, "X-Mpmweb: 1\r\n", "", &h) == 0);
    CHECKF(h.status == 200, "cancel: %d %s", h.status, h.body);
    http_free(&h);
    CHECK(td_wait_status(&d, job, "CANCELLED", 30, st, sizeof st) == 0);
    CHECK(web_stop(&live_web) == 0);
    CHECK(td_stop(&d) == 0);
}

/* --listen beyond loopback needs --allow-remote; bad addresses are named. */
WTEST(web_listen_rules)
{
    web_t w;
    const char *a1[] = {"--listen", "0.0.0.0:0", NULL};
    CHECK(web_start(&w, "remote", a1) == -1);
    char *e = slurp(w.err);
    int named = e && strstr(e, "--allow-remote") && strstr(e, "0.0.0.0:0");
    free(e);
    CHECK(named);
    const char *a2[] = {"--listen", "127.0.0.1:99999", NULL};
    CHECK(web_start(&w, "port", a2) == -1);
    e = slurp(w.err);
    named = e && strstr(e, "0 .. 65535");
    free(e);
    CHECK(named);
    const char *a3[] = {"--listen", "0.0.0.0:0", "--allow-remote", NULL};
    /* allowed with the flag, and said so */
    CHECK(web_start(&w, "remote2", a3) == 0);
    live_web = w;
    char *out = slurp(w.out);
    e = slurp(w.err);
    int warned = e && strstr(e, "warning") && out && strstr(out, "serving http://0.0.0.0:");
    free(e);
    free(out);
    int st = web_stop(&live_web);
    CHECK(warned);
    CHECK(st == 0);
}

/* A browser that opens a job's event stream and never reads: the job runs
 * to its end all the same, its record is whole, the gateway keeps
 * answering others meanwhile, and it stops cleanly with the stalled
 * connection still open. */
WTEST(web_slow_browser)
{
    td_daemon d;
    char dir[300], path[400], rq[256];
    snprintf(dir, sizeof dir, "%s/d", t_tmpdir());
    CHECK(td_start(&d, dir, NULL) == 0);
    const char *wargs[] = {"--endpoint", d.ep, "--listen", "127.0.0.1:0", NULL};
    CHECK(web_start(&live_web, "webs", wargs) == 0);
    json_t *c = example("disks2d_fine");
    CHECK(c != NULL);
    set_output(c, "energyEvery", json_integer(1));
    set_output(c, "snapshotEvery", json_integer(10));
    CHECK(write_case(c, t_tmpdir(), "disks.json", path, sizeof path) == 0);
    td_out o;
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0 && o.status == 0);
    unsigned long long job = job_of(o.out);
    td_out_free(&o);
    CHECK(job > 0);

    /* the stalled browser: a tiny receive buffer, never read */
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)live_web.port)};
    inet_pton(AF_INET, "127.0.0.1", &a.sin_addr);
    int fd = socket(AF_INET, SOCK_STREAM, 0), small = 2048;
    CHECK(fd >= 0);
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
    if (connect(fd, (struct sockaddr *)&a, sizeof a)) {
        close(fd);
        CHECK(0);
    }
    int k =
        snprintf(rq, sizeof rq, "GET /api/events/%llu HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", job);
    int sent = write(fd, rq, (size_t)k) == k;
    if (!sent) close(fd);
    CHECK(sent);

    /* the job ends; others are served meanwhile */
    char st[32];
    http_t h;
    int listed = http(live_web.port, "GET", "/api/runs", "", NULL, &h) == 0 && h.status == 200;
    http_free(&h);
    int ended = td_wait_status(&d, job, "FINISHED", 120, st, sizeof st) == 0;
    json_t *run = ended ? show_json(&d, job) : NULL;
    long long samples = run ? jint(run, "energySamples") : -1,
              steps = run ? jint(run, "steps") : -1;
    json_decref(run);
    int listed2 = http(live_web.port, "GET", "/api/runs", "", NULL, &h) == 0 && h.status == 200;
    http_free(&h);
    int stopped = web_stop(&live_web);
    close(fd);
    CHECK(listed && listed2);
    CHECKF(ended, "the job is %s", st);
    TLOG("job %llu: %lld steps, %lld energy samples recorded with a stalled browser", job, steps,
         samples);
    CHECK(steps > 0 && samples == steps + 1);
    CHECKF(stopped == 0, "mpmweb stopped with status %d", stopped);
    char *e = slurp(live_web.err);
    const char *dropped = e ? strstr(e, "events dropped") : NULL;
    while (dropped && dropped > e && dropped[-1] != ';') dropped--;
    TLOG("mpmweb at its stop:%.40s", dropped ? dropped : " (no count)");
    free(e);
    CHECK(td_stop(&d) == 0);
}

/* The colour field a user picks as "pressure" is positive in compression:
 * two 1D particles under uniaxial compression (sxx = -3000) read +1000 in
 * /api/snapshot at step 0 (7 significant digits) and stay within 1 % of
 * it at the end. */
WTEST(web_pressure_compressed)
{
    td_daemon d;
    web_t w;
    char dir[300], path[400], url[64];
    http_t h;
    snprintf(dir, sizeof dir, "%s/d", t_tmpdir());
    CHECK(td_start(&d, dir, NULL) == 0);
    CHECK(write_case(compressed1d("compressed"), dir, "c.json", path, sizeof path) == 0);
    EXPECT_CTL(&d, 0, "", "submit", path, "--watch");
    const char *wargs[] = {"--endpoint", d.ep, "--listen", "127.0.0.1:0", NULL};
    CHECK(web_start(&w, "webp", wargs) == 0);
    live_web = w;
    static const char *const steps[2] = {"0", "5"};
    for (int k = 0; k < 2; k++) {
        snprintf(url, sizeof url, "/api/snapshot/1?step=%s", steps[k]);
        CHECK(http(w.port, "GET", url, "", NULL, &h) == 0);
        json_error_t je;
        json_t *s = h.status == 200 ? json_loads(h.body, 0, &je) : NULL;
        json_t *p = json_object_get(json_object_get(s, "fields"), "pressure");
        TLOG("GET %s: %d, pressure %s", url, h.status,
             h.body && strstr(h.body, "\"pressure\"") ? strstr(h.body, "\"pressure\"") : "-");
        int ok = json_array_size(p) == 2;
        for (size_t i = 0; ok && i < 2; i++) {
            double v = json_number_value(json_array_get(p, i));
            ok = k ? fabs(v - COMPRESSED_PRESSURE) < 1e-2 * COMPRESSED_PRESSURE
                   : v == COMPRESSED_PRESSURE;
        }
        json_decref(s);
        http_free(&h);
        CHECKF(ok, "%s: the pressure is not +%g", url, COMPRESSED_PRESSURE);
    }
    CHECK(web_stop(&w) == 0);
    live_web.pid = 0;
}
