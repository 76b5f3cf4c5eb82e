/*
 * t_docs_blocks.c - the front door stays working.  docs_blocks_readme and
 * docs_blocks_manual run every shell block (```sh) of README.md and
 * docs/manual.md as written, in order, each in its own `bash -e` (the first
 * failing command fails the test), unless the line before the block is
 * `<!-- doc-test: skip (reason) -->`.  A document's blocks share a
 * temporary directory that looks like a built checkout (bin/ holds the
 * harness's mpmd, mpmctl and mpmweb from MPMD_BIN, MPMCTL_BIN and
 * MPMWEB_BIN; proto/ is the repository's) with an empty HOME inside it and
 * bin/ first on PATH.  So that it can run beside a live daemon, the literal
 * ports 5555, 5556 and 8080 of a block become free ones, which
 * MPMD_ENDPOINT and MPMWEB_LISTEN also name for the commands that take the
 * defaults.  Each block must leave no process behind (20 s after its last
 * command), and no sanitizer report in its output.
 * docs_demo runs deploy/demo.sh, the script of `make demo`, to the end on
 * loopback with a short run (DEMO_STEPS), then reads the run it recorded
 * through a fresh mpmd on the demo's database.
 */
#include "t_daemon.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <arpa/inet.h>

#define SKIP_MARK "<!-- doc-test: skip"
#define BLOCK_TIMEOUT_S 180

/* 1 when a TCP port on 127.0.0.1 can be bound now. */
static int port_free(int port)
{
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
    inet_pton(AF_INET, "127.0.0.1", &a.sin_addr);
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) return 0;
    int ok = bind(fd, (struct sockaddr *)&a, sizeof a) == 0;
    close(fd);
    return ok;
}

/* A daemon port p (with p + 1 for its streams) and p + 2 for mpmweb, all
 * free; 0 if none was found. */
static int free_ports(int salt)
{
    for (int k = 0; k < 50; k++) {
        int p = td_tcp_port(salt + 3 * k);
        if (port_free(p) && port_free(p + 1) && port_free(p + 2)) return p;
    }
    return 0;
}

/* s with every "from" replaced by "to" (malloc'd). */
static char *replace_all(const char *s, const char *from, const char *to)
{
    size_t nf = strlen(from), nt = strlen(to), n = 0;
    for (const char *p = s; (p = strstr(p, from)); p += nf) n++;
    char *out = malloc(strlen(s) + n * (nt > nf ? nt - nf : 0) + 1), *w = out;
    if (!out) return NULL;
    for (const char *p = s;;) {
        const char *q = strstr(p, from);
        if (!q) {
            strcpy(w, p);
            break;
        }
        memcpy(w, p, (size_t)(q - p));
        w += q - p;
        memcpy(w, to, nt);
        w += nt;
        p = q + nf;
    }
    return out;
}

/* An executable script at path: exec's target with extra arguments. */
static int write_wrapper(const char *path, const char *target, const char *extra)
{
    char text[PATH_MAX * 3];
    snprintf(text, sizeof text, "#!/bin/sh\nexec '%s' %s\"$@\"\n", target, extra);
    if (td_write(path, text)) return -1;
    return chmod(path, 0755);
}

/* The absolute path of the binary an environment variable names (mpmweb:
 * MPMWEB_BIN, else beside MPMD_BIN) into out; -1 when it is missing. */
static int bin_path(const char *env, char *out)
{
    const char *b = getenv(env);
    char guess[PATH_MAX];
    if ((!b || !*b) && !strcmp(env, "MPMWEB_BIN") && getenv("MPMD_BIN")) {
        snprintf(guess, sizeof guess, "%s", getenv("MPMD_BIN"));
        char *slash = strrchr(guess, '/');
        snprintf(slash ? slash + 1 : guess, 16, "mpmweb");
        b = guess;
    }
    return b && realpath(b, out) && access(out, X_OK) == 0 ? 0 : -1;
}

/* The checkout a document's blocks run in: dir/bin (wrappers of the
 * harness's binaries), dir/proto, dir/clients, dir/protocol, dir/home.  0 or -1 (test failed). */
static int make_checkout(const char *dir)
{
    char mpmd[PATH_MAX], ctl[PATH_MAX], web[PATH_MAX], root[PATH_MAX], p[PATH_MAX + 64],
        extra[PATH_MAX + 32];
    if (bin_path("MPMD_BIN", mpmd) || bin_path("MPMCTL_BIN", ctl) || bin_path("MPMWEB_BIN", web)) {
        t_fail(__FILE__, __LINE__, "MPMD_BIN, MPMCTL_BIN or MPMWEB_BIN is missing");
        return -1;
    }
    if (!getcwd(root, sizeof root)) return -1;
    snprintf(p, sizeof p, "%s/bin", dir);
    if (mkdir(dir, 0700) || mkdir(p, 0700)) return -1;
    snprintf(p, sizeof p, "%s/home", dir);
    if (mkdir(p, 0700)) return -1;
    snprintf(p, sizeof p, "%s/bin/mpmd", dir);
    if (write_wrapper(p, mpmd, "")) return -1;
    snprintf(p, sizeof p, "%s/bin/mpmctl", dir);
    if (write_wrapper(p, ctl, "")) return -1;
    /* the ASan build's mpmweb does not sit beside clients/web/static */
    snprintf(extra, sizeof extra, "--static '%s/clients/web/static' ", root);
    snprintf(p, sizeof p, "%s/bin/mpmweb", dir);
    if (write_wrapper(p, web, extra)) return -1;
    /* the example cases, and what `pip install clients/python` reads (the
     * package, the schema, the version in mpp.h) */
    static const char *const linked[] = {"proto", "clients", "protocol"};
    for (size_t i = 0; i < sizeof linked / sizeof linked[0]; i++) {
        char target[PATH_MAX + 16];
        snprintf(target, sizeof target, "%s/%s", root, linked[i]);
        snprintf(p, sizeof p, "%s/%s", dir, linked[i]);
        if (symlink(target, p)) return -1;
    }
    return 0;
}

/* Runs one block as dir/blockN.sh in dir, its process group killed at the
 * end; 0 when it passed. */
static int run_block(const char *dir, int n, const char *doc, int line, const char *text, int port)
{
    char script[1024], logp[1024], ep[64], web[64], home[1024], path[PATH_MAX * 2];
    char p0[16], p1[16], pw[16], q0[16], q1[16], qw[16];
    snprintf(p0, sizeof p0, "%d", port);
    snprintf(p1, sizeof p1, "%d", port + 1);
    snprintf(pw, sizeof pw, "%d", port + 2);
    /* one pass per port, through placeholders, so that a substituted port
     * is never substituted again */
    snprintf(q0, sizeof q0, "\001P0\001");
    snprintf(q1, sizeof q1, "\001P1\001");
    snprintf(qw, sizeof qw, "\001PW\001");
    char *a = replace_all(text, "5555", q0), *b = a ? replace_all(a, "5556", q1) : NULL,
         *c = b ? replace_all(b, "8080", qw) : NULL, *d = c ? replace_all(c, q0, p0) : NULL,
         *e = d ? replace_all(d, q1, p1) : NULL, *body = e ? replace_all(e, qw, pw) : NULL;
    free(a);
    free(b);
    free(c);
    free(d);
    free(e);
    if (!body) return -1;
    snprintf(script, sizeof script, "%s/block%d.sh", dir, n);
    snprintf(logp, sizeof logp, "%s/block%d.log", dir, n);
    FILE *f = fopen(script, "w");
    if (!f) {
        free(body);
        return -1;
    }
    /* the block as written; `wait` lets what it started in the background
     * and stopped (kill %1) finish its shutdown */
    fprintf(f, "# %s, line %d\nset -ex\n%s\nwait\n", doc, line, body);
    free(body);
    if (fclose(f)) return -1;
    snprintf(ep, sizeof ep, "tcp://127.0.0.1:%d", port);
    snprintf(web, sizeof web, "127.0.0.1:%d", port + 2);
    snprintf(home, sizeof home, "%s/home", dir);
    snprintf(path, sizeof path, "%s/bin:%s", dir,
             getenv("PATH") ? getenv("PATH") : "/usr/bin:/bin");
    double t0 = td_now();
    pid_t pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        setpgid(0, 0);
        int in = open("/dev/null", O_RDONLY), out = open(logp, O_WRONLY | O_CREAT | O_TRUNC, 0600);
        if (in < 0 || out < 0 || chdir(dir)) _exit(126);
        dup2(in, 0);
        dup2(out, 1);
        dup2(out, 2);
        setenv("HOME", home, 1);
        setenv("PATH", path, 1);
        setenv("MPMD_ENDPOINT", ep, 1);
        setenv("MPMWEB_LISTEN", web, 1);
        unsetenv("MPMD_DB");
        unsetenv("MPMD_STREAM");
        unsetenv("MPMD_KEYS");
        unsetenv("MPMD_SERVER_KEY");
        unsetenv("MPMD_CLIENT_KEY");
        execl("/bin/bash", "bash", "--norc", "--noprofile", script, (char *)NULL);
        _exit(127);
    }
    setpgid(pid, pid);
    int st = -1, rc = -1;
    while (td_now() - t0 < BLOCK_TIMEOUT_S) {
        pid_t w = waitpid(pid, &st, WNOHANG);
        if (w == pid) {
            rc = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
            break;
        }
        td_msleep(50);
    }
    if (rc < 0) {
        kill(-pid, SIGKILL);
        waitpid(pid, &st, 0);
    }
    /* what the block left running */
    int left = 0;
    for (double t1 = td_now(); kill(-pid, 0) == 0; td_msleep(100)) {
        if (td_now() - t1 > 20) {
            left = 1;
            kill(-pid, SIGKILL);
            td_msleep(200);
            break;
        }
    }
    size_t len = 0;
    char *log = td_slurp(logp, &len);
    int sanitizer = log && (strstr(log, "ERROR: AddressSanitizer") ||
                            strstr(log, "runtime error:") || strstr(log, "ERROR: LeakSanitizer"));
    int ok = rc == 0 && !left && !sanitizer;
    TLOG("%s, block at line %d: %s in %.1f s%s%s", doc, line,
         rc < 0    ? "timed out"
         : rc == 0 ? "passed"
                   : "FAILED",
         td_now() - t0, left ? ", left a process running" : "",
         sanitizer ? ", a sanitizer report" : "");
    if (!ok) {
        /* the end of its log: the failing command and what it said */
        const char *tail = log && len > 3000 ? log + len - 3000 : log;
        t_fail(__FILE__, __LINE__, "%s line %d: exit %d%s%s; the end of %s:\n%s", doc, line, rc,
               left ? ", left a process running" : "", sanitizer ? ", sanitizer report" : "", logp,
               tail ? tail : "(no log)");
    }
    free(log);
    return ok ? 0 : -1;
}

/* Runs the shell blocks of doc; *ran, *skipped counted. */
static void run_doc(const char *doc, int salt, int *ran, int *skipped)
{
    char dir[512];
    size_t len = 0;
    char *text = td_slurp(doc, &len), **lines = NULL;
    *ran = *skipped = 0;
    CHECKF(text, "cannot read %s", doc);
    snprintf(dir, sizeof dir, "%s/checkout", t_tmpdir());
    if (make_checkout(dir)) {
        free(text);
        CHECKF(0, "cannot set up %s", dir);
    }
    int port = free_ports(salt);
    if (!port) free(text);
    CHECKF(port, "no free loopback ports");
    size_t nl = td_lines(text, &lines);
    int failed = 0;
    for (size_t i = 0; i < nl && !failed; i++) {
        const char *l = lines[i];
        if (strncmp(l, "```", 3)) continue;
        const char *info = l + 3;
        int shell = !strcmp(info, "sh") || !strcmp(info, "bash") || !strcmp(info, "shell");
        /* the block's end */
        size_t j = i + 1;
        while (j < nl && strncmp(lines[j], "```", 3)) j++;
        if (shell) {
            int skip = i > 0 && !strncmp(lines[i - 1], SKIP_MARK, strlen(SKIP_MARK));
            if (skip) {
                const char *why = lines[i - 1] + strlen(SKIP_MARK), *end = strstr(why, " -->");
                TLOG("%s, block at line %zu: skipped%.*s", doc, i + 1,
                     (int)(end ? (size_t)(end - why) : strlen(why)), why);
                (*skipped)++;
            } else {
                size_t n = 0;
                for (size_t k = i + 1; k < j; k++) n += strlen(lines[k]) + 1;
                char *body = malloc(n + 1), *w = body;
                if (!body) break;
                for (size_t k = i + 1; k < j; k++) w += sprintf(w, "%s\n", lines[k]);
                *w = 0;
                failed = run_block(dir, *ran, doc, (int)i + 1, body, port) != 0;
                free(body);
                (*ran)++;
            }
        }
        i = j;
    }
    free(lines);
    free(text);
}

TEST(docs_blocks_readme)
{
    int ran = 0, skipped = 0;
    run_doc("README.md", 6101, &ran, &skipped);
    TLOG("README.md: %d shell block(s) run as written, %d skipped", ran, skipped);
    CHECK(ran >= 1);
    CHECK(skipped <= 1);
}

TEST(docs_blocks_manual)
{
    int ran = 0, skipped = 0;
    run_doc("docs/manual.md", 6211, &ran, &skipped);
    TLOG("docs/manual.md: %d shell block(s) run as written, %d skipped", ran, skipped);
    CHECK(ran >= 3);
    CHECK(skipped <= 3);
}

/* The particles in a screenshot of the monitor: the pixels of the particle
 * panel (CSS 645..1085 x 257..697 in a 1200 x 820 page) whose colour is
 * saturated (max - min channel > 60: the colour map's; the page is white
 * and grey there without particles), counted by Debian's Python after
 * decoding the PNG (zlib, the row filters).  -1 if it cannot read it. */
static long long png_particle_pixels(const char *png)
{
    static const char script[] =
        "import sys,zlib,struct\n"
        "d=open(sys.argv[1],'rb').read()\n"
        "assert d[:8]==b'\\x89PNG\\r\\n\\x1a\\n'\n"
        "i=8;idat=b''\n"
        "while i<len(d):\n"
        " n,t=struct.unpack('>I4s',d[i:i+8]);c=d[i+8:i+8+n];i+=12+n\n"
        " if t==b'IHDR':W,H,bd,ct=struct.unpack('>IIBB',c[:10]);assert bd==8 and ct in(2,6)\n"
        " if t==b'IDAT':idat+=c\n"
        "bpp=3 if ct==2 else 4;raw=zlib.decompress(idat);s=W*bpp;prev=bytearray(s);p=0;hits=0\n"
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
        " if 257*H//820<=y<697*H//820:\n"
        "  for x in range(645*W//1200,1085*W//1200):\n"
        "   px=line[x*bpp:x*bpp+3]\n"
        "   if max(px)-min(px)>60:hits+=1\n"
        "print(hits)\n";
    char sp[600], cmd[1400];
    snprintf(sp, sizeof sp, "%s/png_particles.py", t_tmpdir());
    if (td_write(sp, script)) return -1;
    snprintf(cmd, sizeof cmd, "/usr/bin/python3 '%s' '%s' 2>&1", sp, png);
    FILE *f = popen(cmd, "r");
    long long n = -1;
    if (!f) return -1;
    if (fscanf(f, "%lld", &n) != 1) n = -1;
    return pclose(f) == 0 ? n : -1;
}

/* An int64 field of a JSON mapping (written as a string) or an int. */
static long long jint64(const json_t *o, const char *key)
{
    const json_t *v = json_object_get(o, key);
    return json_is_string(v) ? strtoll(json_string_value(v), NULL, 10) : json_integer_value(v);
}

/* deploy/demo.sh to the end (a short run), then its record read back. */
DTEST(docs_demo)
{
    const char *tmp = t_tmpdir();
    char dir[512], db[600], ep[64], web[64], cmd[3000], outp[600], png[600], pic[700] = "";
    int port = free_ports(6307);
    CHECKF(port, "no free loopback ports");
    snprintf(dir, sizeof dir, "%s/d", tmp);
    CHECK(mkdir(dir, 0700) == 0);
    snprintf(db, sizeof db, "%s/mpmd.db", dir);
    snprintf(ep, sizeof ep, "tcp://127.0.0.1:%d", port);
    snprintf(web, sizeof web, "127.0.0.1:%d", port + 2);
    snprintf(outp, sizeof outp, "%s/demo.out", tmp);
    /* with Chromium, the demo also takes the monitor's picture of its run,
     * as make docs-picture does */
    int chromium = access("/usr/bin/chromium", X_OK) == 0;
    snprintf(png, sizeof png, "%s/monitor.png", tmp);
    if (chromium) snprintf(pic, sizeof pic, "DEMO_PICTURE='%s' DEMO_PICTURE_STEP=500 ", png);
    /* the binaries come from the harness's MPMD_BIN, MPMCTL_BIN, MPMWEB_BIN */
    snprintf(cmd, sizeof cmd,
             "%sMPMD_ENDPOINT='%s' MPMWEB_LISTEN='%s' MPMD_DB='%s' DEMO_LOGS='%s' DEMO_STEPS=500 "
             "DEMO_PAUSE=0 timeout 300 bash deploy/demo.sh < /dev/null > '%s' 2>&1",
             pic, ep, web, db, tmp, outp);
    double t0 = td_now();
    int st = system(cmd), rc = st == -1 ? -1 : WEXITSTATUS(st);
    size_t len = 0;
    char *out = td_slurp(outp, &len);
    CHECK(out);
    TLOG("deploy/demo.sh: exit %d in %.1f s, %zu bytes of output", rc, td_now() - t0, len);
    char want[128];
    snprintf(want, sizeof want, "http://%s/#run=1", web);
    int url = strstr(out, want) != NULL;
    int finished = strstr(out, "FINISHED") != NULL;
    int answered = strstr(out, "the web monitor's answer for run 1: HTTP/1.1 200") != NULL;
    int next = strstr(out, "bin/mpmctl export 1 out/") != NULL;
    int stopped = strstr(out, "demo: mpmd stopped") && strstr(out, "demo: mpmweb stopped");
    int sanitizer = strstr(out, "ERROR: AddressSanitizer") || strstr(out, "runtime error:");
    CHECKF(rc == 0 && url && finished && answered && next && stopped && !sanitizer,
           "exit %d, url %d, finished %d, monitor %d, next commands %d, stopped %d, sanitizer "
           "%d:\n%s",
           rc, url, finished, answered, next, stopped, sanitizer, out);
    free(out);
    if (chromium) {
        long long px = png_particle_pixels(png);
        TLOG("the monitor's picture of the run at step 500: %lld coloured pixels in the "
             "particle panel",
             px);
        CHECKF(px > 2000, "%s shows no particles (%lld coloured pixels)", png, px);
    } else {
        TLOG("SKIPPED the picture: /usr/bin/chromium is not installed (install-deps.sh test)");
    }

    /* the run in the demo's database: the collapse's 8192 particles, its
     * snapshots recorded */
    td_daemon d;
    CHECK(td_start(&d, dir, NULL) == 0);
    td_out o;
    CHECK(td_ctl(&d, 30, &o, "show", "1", "--json", NULL) == 0 && o.status == 0);
    json_t *run = json_loads(o.out, 0, NULL);
    td_out_free(&o);
    CHECK(run);
    const char *status = json_string_value(json_object_get(run, "status"));
    long long particles = jint64(run, "particles"), steps = jint64(run, "steps");
    int ok = status && !strcmp(status, "FINISHED") && particles == 8192 && steps == 500;
    TLOG("run 1: %s, %lld particles, %lld steps", status ? status : "?", particles, steps);
    json_decref(run);
    CHECK(ok);
    char csv[600];
    snprintf(csv, sizeof csv, "%s/last.csv", tmp);
    CHECK(td_ctl(&d, 30, &o, "snapshot", "1", "-o", csv, NULL) == 0 && o.status == 0);
    td_out_free(&o);
    char *rows = td_slurp(csv, &len), **lines = NULL;
    CHECK(rows);
    size_t n = td_lines(rows, &lines);
    free(lines);
    free(rows);
    TLOG("its last recorded snapshot: %zu particles (CSV rows)", n ? n - 1 : 0);
    CHECK(n == 8192 + 1);
    CHECK(td_stop(&d) == 0);
}
