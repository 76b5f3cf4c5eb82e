/*
 * t_ctl_docs.c - what users read and type besides the programs: the man
 * pages docs/man/mpmd.1 and docs/man/mpmctl.1 render without a warning
 * (groff -man -ww -z, and mandoc -T lint when mandoc is installed) and
 * name every option `mpmd --help` lists and every command `mpmctl --help`
 * lists; the bash completion clients/mpmctl/completion/mpmctl.bash, sourced in a
 * real bash, completes commands, options, option values, case files, and
 * the run ids a real mpmd reports.  Files are read relative to the
 * repository root.
 */
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

/* Runs cmd (through sh) with stdout and stderr into dir/name; returns the
 * exit status (-1 if it could not run) and the output in *out. */
static int sh_out(const char *cmd, const char *dir, const char *name, char **out)
{
    char full[2048], path[512];
    size_t len = 0;
    snprintf(path, sizeof path, "%s/%s", dir, name);
    snprintf(full, sizeof full, "%s > '%s' 2>&1", cmd, path);
    int rc = system(full);
    *out = td_slurp(path, &len);
    return rc == -1 ? -1 : WEXITSTATUS(rc);
}

/* The roff spelling of an option name: every '-' as "\-". */
static void roff_dashes(const char *s, char *out, size_t n)
{
    size_t k = 0;
    for (; *s && k + 3 < n; s++) {
        if (*s == '-') out[k++] = '\\';
        out[k++] = *s;
    }
    out[k] = 0;
}

TEST(ctl_man_pages)
{
    static const char *const pages[2] = {"docs/man/mpmd.1", "docs/man/mpmctl.1"};
    const char *tmp = t_tmpdir();
    char cmd[512], *out = NULL;
    CHECKF(system("command -v groff >/dev/null 2>&1") == 0,
           "groff is not installed (groff-base, installed by make deps)");
    int mandoc = system("command -v mandoc >/dev/null 2>&1") == 0;
    for (int p = 0; p < 2; p++) {
        snprintf(cmd, sizeof cmd, "groff -man -ww -z %s", pages[p]);
        int rc = sh_out(cmd, tmp, "groff.out", &out);
        CHECKF(rc == 0 && out && !out[0], "%s: exit %d: %s", cmd, rc, out ? out : "");
        free(out);
        if (mandoc) {
            snprintf(cmd, sizeof cmd, "mandoc -T lint -W warning %s", pages[p]);
            rc = sh_out(cmd, tmp, "mandoc.out", &out);
            CHECKF(rc == 0 && out && !out[0], "%s: exit %d: %s", cmd, rc, out ? out : "");
            free(out);
        }
        TLOG("%s: no warning from groff -ww%s", pages[p], mandoc ? " nor mandoc -T lint" : "");
    }

    /* every option of `mpmd --help` is in mpmd.1, and its default (the
     * settings table's, which --help prints as "(default X)") is the one
     * mpmd.1's paragraph and the manual's table give */
    size_t len = 0;
    char *man = td_slurp(pages[0], &len), *help = NULL, **lines = NULL;
    char *manual = td_slurp("docs/manual.md", &len);
    CHECK(manual);
    const char *mpmd = td_bin("MPMD_BIN");
    CHECK(man && mpmd);
    snprintf(cmd, sizeof cmd, "%s --help", mpmd);
    CHECK(sh_out(cmd, tmp, "mpmd.help", &help) == 0 && help);
    size_t nl = td_lines(help, &lines), nopt = 0, ndef = 0, nconf = 0;
    char *conf = td_slurp("deploy/mpmd.conf", &len);
    CHECK(conf);
    for (size_t i = 0; i < nl; i++) {
        char name[64], roff[160];
        if (sscanf(lines[i], " --%63[a-z-]", name) != 1 || strncmp(lines[i], "  --", 4)) continue;
        char dashed[80];
        snprintf(dashed, sizeof dashed, "--%s", name);
        roff_dashes(dashed, roff, sizeof roff);
        const char *at = strstr(man, roff);
        CHECKF(at, "mpmd.1 does not describe %s (from mpmd --help)", dashed);
        nopt++;
        const char *dp = strstr(lines[i], "(default ");
        char def[96];
        if (!at || !manual || !dp || sscanf(dp, "(default %95[^)])", def) != 1) continue;
        /* mpmd.1: "(default X" within the option's paragraph (.BI or .B
         * line, up to the next .TP) */
        char head[200];
        snprintf(head, sizeof head, "\n.BI %s ", roff);
        const char *para = strstr(man, head);
        if (!para) {
            snprintf(head, sizeof head, "\n.B %s\n", roff);
            para = strstr(man, head);
        }
        CHECKF(para, "mpmd.1 has no paragraph for %s", dashed);
        if (!para) continue;
        at = para;
        const char *end = strstr(at + 1, "\n.TP");
        char want[128];
        snprintf(want, sizeof want, "(default %s", def);
        const char *got = strstr(at, want);
        CHECKF(got && (!end || got < end), "mpmd.1's %s paragraph does not say \"%s)\"", dashed,
               want);
        /* the manual's settings table: "| `--NAME ...` | env | X..." */
        char row[80];
        snprintf(row, sizeof row, "| `--%s", name);
        const char *r = manual;
        while ((r = strstr(r, row)) && r[strlen(row)] != ' ' && r[strlen(row)] != '`') r++;
        const char *c = r ? strchr(r + 1, '|') : NULL;
        c = c ? strchr(c + 1, '|') : NULL;
        while (c && (*++c == ' ' || *c == '`')) {
        }
        CHECKF(c && !strncmp(c, def, strlen(def)),
               "docs/manual.md's row of %s does not give the default %s", dashed, def);
        ndef++;
        /* deploy/mpmd.conf: a setting it gives is the default, but for the
         * places a site must choose (endpoints, database) */
        char key[80];
        snprintf(key, sizeof key, "\n%s = ", name);
        const char *kv = conf ? strstr(conf, key) : NULL;
        if (kv && strcmp(name, "endpoint") && strcmp(name, "stream-endpoint") &&
            strcmp(name, "db")) {
            kv += strlen(key);
            CHECKF(!strncmp(kv, def, strlen(def)) && (kv[strlen(def)] == '\n'),
                   "deploy/mpmd.conf gives %s = %.20s, the settings table's default is %s", name,
                   kv, def);
            nconf++;
        }
    }
    /* every key deploy/mpmd.conf names, given or commented out, is a
     * setting of mpmd --help */
    size_t nkeys = 0;
    for (const char *l = conf; l && *l; l = strchr(l, '\n') ? strchr(l, '\n') + 1 : "") {
        char key[64], opt[80];
        const char *k = l[0] == '#' && l[1] == ' ' ? l + 2 : l;
        if (sscanf(k, "%63[a-z-] = ", key) != 1 || !strstr(k, " = ") || strchr(key, ' ')) continue;
        if ((size_t)(strstr(k, " = ") - k) != strlen(key)) continue;
        snprintf(opt, sizeof opt, "  --%s ", key);
        int known = 0; /* help is split into lines by now */
        for (size_t i = 0; i < nl && !known; i++) known = !strncmp(lines[i], opt, strlen(opt));
        CHECKF(known, "deploy/mpmd.conf names %s, which mpmd --help does not know", key);
        nkeys++;
    }
    TLOG("deploy/mpmd.conf: %zu keys, each a setting; %zu given, each the default", nkeys, nconf);
    CHECK(nkeys >= 15 && nconf >= 10);
    free(conf);
    free(lines);
    free(help);
    free(man);
    free(manual);
    TLOG("mpmd --help: %zu defaults, each the same in mpmd.1 and docs/manual.md", ndef);
    CHECK(ndef >= 25);
    CHECK(nopt >= 20);

    /* every command of `mpmctl --help` is in mpmctl.1 */
    const char *ctl = td_bin("MPMCTL_BIN");
    CHECK(ctl);
    man = td_slurp(pages[1], &len);
    CHECK(man);
    snprintf(cmd, sizeof cmd, "%s --help", ctl);
    CHECK(sh_out(cmd, tmp, "mpmctl.help", &help) == 0 && help);
    nl = td_lines(help, &lines);
    size_t ncmd = 0, in_cmds = 0;
    for (size_t i = 0; i < nl; i++) {
        char name[32], want1[64], want2[64];
        if (!strcmp(lines[i], "Commands:")) in_cmds = 1;
        if (in_cmds && !lines[i][0] && ncmd) break; /* the end of the list */
        if (!in_cmds || sscanf(lines[i], "  %31[a-z]", name) != 1) continue;
        snprintf(want1, sizeof want1, "\n.BI \"%s ", name);
        snprintf(want2, sizeof want2, "\n.B %s ", name);
        CHECKF(strstr(man, want1) || strstr(man, want2),
               "mpmctl.1 has no entry for the command %s (from mpmctl --help)", name);
        ncmd++;
    }
    free(lines);
    free(help);
    free(man);
    TLOG("mpmd.1 names all %zu options of mpmd --help; mpmctl.1 all %zu commands of mpmctl "
         "--help",
         nopt, ncmd);
    CHECK(ncmd >= 12);
}

/* The completions bash gives for the words (the last one being completed),
 * with the completion script sourced; into out (a line). */
static int complete_line(const char *dir, const char *env, const char *words, const char *line,
                         char **out)
{
    char script[512], cmd[1024];
    snprintf(script, sizeof script, "%s/complete.sh", dir);
    FILE *f = fopen(script, "w");
    if (!f) return -1;
    fprintf(f,
            "source clients/mpmctl/completion/mpmctl.bash\n"
            "COMP_WORDS=(%s)\nCOMP_CWORD=$((${#COMP_WORDS[@]} - 1))\n%s%s%s"
            "_mpmctl\necho \"${COMPREPLY[*]}\"\n",
            words, line ? "COMP_LINE=\"" : "", line ? line : "", line ? "\"\n" : "");
    if (fclose(f)) return -1;
    snprintf(cmd, sizeof cmd, "%s bash --norc --noprofile %s", env, script);
    return sh_out(cmd, dir, "complete.out", out);
}

static int complete(const char *dir, const char *env, const char *words, char **out)
{
    return complete_line(dir, env, words, NULL, out);
}

DTEST(ctl_completion)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", NULL};
    char dir[300], path[400], words[1024], *out = NULL;
    td_daemon d;
    static const char *const cases[][3] = {
        /* words, the completions wanted (all of them, in order) */
        {"mpmctl sn", "snapshot"},
        {"mpmctl ex", "export"},
        {"mpmctl p", "plot ping"},
        {"mpmctl export 3 --",
         "--format --grid --ascii --base64 --compress --endpoint --stream --timeout "
         "--keys --help"},
        {"mpmctl runs --status FI", "FINISHED"},
        {"mpmctl --timeout 5 su", "submit"},
        {"mpmctl submit proto/examples/cube", "proto/examples/cube3d.json"},
        {"mpmctl plot 1 --terminal pn", "pngcairo png"},
        {"mpmctl snapshot 1 --c", "--compress"},
        {"mpmctl -", "--endpoint --stream --timeout --keys --help"},
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        int rc = complete(tmp, "MPMCTL_COMPLETE_RUNS=0", cases[k][0], &out);
        char *nl = out ? strchr(out, '\n') : NULL;
        if (nl) *nl = 0;
        CHECKF(rc == 0 && out && !strcmp(out, cases[k][1]),
               "complete '%s': exit %d, got '%s', want '%s'", cases[k][0], rc, out ? out : "",
               cases[k][1]);
        TLOG("%-34s -> %s", cases[k][0], out);
        free(out);
    }

    /* run ids from a real daemon, at the endpoint on the line */
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    for (int r = 0; r < 2; r++) {
        td_out o;
        CHECK(write_case(block2d(10, 5, "ids"), dir, "c.json", path, sizeof path) == 0);
        CHECK(td_ctl(&d, 60, &o, "submit", path, "--watch", NULL) == 0 && o.status == 0);
        td_out_free(&o);
    }
    const char *ctl = td_bin("MPMCTL_BIN");
    CHECK(ctl);
    snprintf(words, sizeof words, "'%s' --endpoint '%s' show ''", ctl, d.ep);
    int rc = complete(tmp, "", words, &out);
    char *nl = out ? strchr(out, '\n') : NULL;
    if (nl) *nl = 0;
    CHECKF(rc == 0 && out && !strcmp(out, "2 1"), "run ids: exit %d, got '%s', want '2 1'", rc,
           out ? out : "");
    TLOG("mpmctl --endpoint EP show <TAB> -> %s (runs --json of a real mpmd)", out);
    free(out);

    /* as bash gives them: the endpoint split at its colons in COMP_WORDS,
     * whole in COMP_LINE */
    char split[512], line[1024];
    size_t k = 0;
    for (const char *c = d.ep; *c && k + 8 < sizeof split; c++)
        if (*c == ':') {
            memcpy(split + k, "' ':' '", 7);
            k += 7;
        } else {
            split[k++] = *c;
        }
    split[k] = 0;
    snprintf(words, sizeof words, "'%s' --endpoint '%s' show ''", ctl, split);
    snprintf(line, sizeof line, "%s --endpoint %s show ", ctl, d.ep);
    rc = complete_line(tmp, "", words, line, &out);
    nl = out ? strchr(out, '\n') : NULL;
    if (nl) *nl = 0;
    CHECKF(rc == 0 && out && !strcmp(out, "2 1"),
           "run ids, endpoint split at its colons: exit %d, got '%s', want '2 1'", rc,
           out ? out : "");
    TLOG("the same, COMP_WORDS split at the endpoint's colons as bash does -> %s", out);
    free(out);
}
