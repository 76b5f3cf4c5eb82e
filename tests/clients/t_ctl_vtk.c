/*
 * t_ctl_vtk.c - mpmctl's files for other programs, end to end: a real mpmd
 * (ipc:// in the test's directory, a real SQLite file) runs a 2D elastic
 * block, the 3D cube and the J2 impact with CPDI (plastic strain, the yield
 * flag and F present) with recorded snapshots, and a 25600-particle block
 * (zlib arrays of several 1 MiB blocks); the real mpmctl writes
 * `snapshot -o F.vtp` in each encoding (raw, base64, zlib, ASCII) and
 * `export ID DIR --grid`; Debian's python3-vtk9 (/usr/bin/python3,
 * tests/clients/vtk_check.py) reads every .vtp with vtkXMLPolyDataReader, each
 * DataSet of the .pvd with vtkXMLGenericDataObjectReader and the .vti with
 * vtkXMLImageDataReader, and compares every value with the snapshot
 * fetched over the protocol (`snapshot -o F.json`): equal doubles, the .pvd's
 * times equal to the snapshots'.  Then the errors (no recorded snapshots,
 * no positions, no such run, a directory that cannot be made, bad options),
 * and `plot` (a PNG from gnuplot; without gnuplot an error naming
 * gnuplot-nox).
 */
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* A JSON int64 (a string in the JSON mapping) or number. */
static long long jll(const json_t *v)
{
    return json_is_string(v) ? atoll(json_string_value(v)) : (long long)json_integer_value(v);
}

/* Submits the case file path and watches it to the end; 0 or -1. */
static int run_case(const td_daemon *d, const char *path)
{
    td_out o;
    int ok = td_ctl(d, 180, &o, "submit", path, "--watch", NULL) == 0 && o.status == 0;
    if (!ok) TLOG("submit %s --watch: exit %d: %s%s", path, o.status, o.out, o.err);
    td_out_free(&o);
    return ok ? 0 : -1;
}

/* mpmctl ARGS... must exit 0. */
static int ctl_ok(const td_daemon *d, const char *const *args)
{
    td_out o;
    int ok = td_ctlv(d, 60, &o, args) == 0 && o.status == 0;
    if (!ok) TLOG("mpmctl %s %s: exit %d: %s", args[0], args[1], o.status, o.err);
    td_out_free(&o);
    return ok;
}
#define CTL_OK(d, ...)                                                \
    do {                                                              \
        const char *a_[] = {__VA_ARGS__, NULL};                       \
        CHECKF(ctl_ok(d, a_), "mpmctl %s failed (log above)", a_[0]); \
    } while (0)

/* Runs tests/clients/vtk_check.py on the manifest; its output in *out (malloc'd). */
static int vtk_check(const char *manifest, const char *dir, char **out)
{
    char cmd[1024], path[512];
    size_t len = 0;
    snprintf(path, sizeof path, "%s/vtk_check.out", dir);
    snprintf(cmd, sizeof cmd, "/usr/bin/python3 tests/clients/vtk_check.py %s > %s 2>&1", manifest,
             path);
    int rc = system(cmd);
    *out = td_slurp(path, &len);
    return rc;
}

DTEST(ctl_vtk_paraview)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "2", "--solver-threads", "1", NULL};
    char dir[300], manifest[400], path[3][400];
    /* the stems export makes of the names: bytes outside [A-Za-z0-9._-] -> _ */
    static const char *const stems[3] = {"block_.._2d__x____", "cube3d", "impact2d_j2"};
    static const char *const enc_opt[3] = {NULL, "--base64", "--compress"};
    td_daemon d;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;

    /* 1: a 2D elastic block whose name would reach out of DIR unescaped */
    json_t *c = block2d(40, 10, "block/../2d \"x\"<&>");
    CHECK(c);
    set_output(c, "snapshotEvery", json_integer(10));
    set_output(c, "recordSnapshots", json_true());
    CHECK(write_case(c, dir, "c1.json", path[0], sizeof path[0]) == 0);
    /* 2: the 3D cube, 30 steps */
    c = example("cube3d");
    CHECK(c);
    json_object_del(c, "endTime");
    json_object_set_new(c, "steps", json_integer(30));
    set_output(c, "snapshotEvery", json_integer(10));
    set_output(c, "recordSnapshots", json_true());
    CHECK(write_case(c, dir, "c2.json", path[1], sizeof path[1]) == 0);
    /* 3: the J2 impact with CPDI: plastic strain, yielded and F */
    c = example("impact2d_j2");
    CHECK(c);
    json_object_del(c, "endTime");
    json_object_set_new(c, "steps", json_integer(200));
    json_object_set_new(c, "method", json_string("CPDI"));
    json_object_del(c, "output");
    set_output(c, "energyEvery", json_integer(10));
    set_output(c, "snapshotEvery", json_integer(50));
    set_output(c, "recordSnapshots", json_true());
    CHECK(write_case(c, dir, "c3.json", path[2], sizeof path[2]) == 0);
    /* 4: 25600 particles, so that the zlib arrays span several 1 MiB blocks */
    char big[400];
    c = block2d(2, 1, "big");
    CHECK(c);
    json_object_set_new(json_object_get(c, "grid"), "spacing", json_pack("[f,f]", 0.005, 0.005));
    json_object_set_new(json_object_get(c, "grid"), "nodes", json_pack("[i,i]", 201, 201));
    set_output(c, "snapshotEvery", json_integer(2));
    set_output(c, "recordSnapshots", json_true());
    CHECK(write_case(c, dir, "c4.json", big, sizeof big) == 0);
    for (int r = 0; r < 3; r++) CHECK(run_case(&d, path[r]) == 0);
    CHECK(run_case(&d, big) == 0);

    snprintf(manifest, sizeof manifest, "%s/manifest.txt", dir);
    FILE *mf = fopen(manifest, "w");
    CHECK(mf);
    int checks = 0;
    for (int r = 0; r < 3; r++) {
        char ids[16], rd[400], js[460], f[600], last[600] = "";
        snprintf(ids, sizeof ids, "%d", r + 1);
        snprintf(rd, sizeof rd, "%s/r%d", dir, r + 1);
        snprintf(js, sizeof js, "%s/js", rd);
        CHECK(mkdir(rd, 0777) == 0 && mkdir(js, 0777) == 0);
        json_t *ri = show_json(&d, (unsigned long long)(r + 1));
        json_t *steps = json_object_get(ri, "snapshotSteps");
        size_t ns = json_array_size(steps);
        CHECKF(ns >= 3, "run %d: %zu snapshots recorded", r + 1, ns);
        /* every snapshot over the protocol, as JSON */
        for (size_t i = 0; i < ns; i++) {
            char st[32];
            snprintf(st, sizeof st, "%lld", jll(json_array_get(steps, i)));
            snprintf(f, sizeof f, "%s/%s.json", js, st);
            CTL_OK(&d, "snapshot", ids, "--step", st, "-o", f);
            snprintf(last, sizeof last, "%s", f);
        }
        json_decref(ri);
        /* the latest as .vtp in each encoding */
        static const char *const encs[4][2] = {
            {"raw", NULL}, {"base64", "--base64"}, {"zlib", "--compress"}, {"ascii", "--ascii"}};
        for (int e = 0; e < 4; e++) {
            snprintf(f, sizeof f, "%s/%s.vtp", rd, encs[e][0]);
            if (encs[e][1])
                CTL_OK(&d, "snapshot", ids, "-o", f, encs[e][1]);
            else
                CTL_OK(&d, "snapshot", ids, "-o", f);
            fprintf(mf, "vtp %s %s %s\n", e == 3 ? "ascii" : "exact", last, f);
            checks++;
        }
        /* the whole run */
        char out[500];
        snprintf(out, sizeof out, "%s/out", rd);
        if (enc_opt[r])
            CTL_OK(&d, "export", ids, out, "--grid", enc_opt[r]);
        else
            CTL_OK(&d, "export", ids, out, "--grid");
        snprintf(f, sizeof f, "%s/%s.pvd", out, stems[r]);
        CHECKF(access(f, R_OK) == 0, "export wrote no %s", f);
        fprintf(mf, "pvd %s %s %s\n", enc_opt[r] ? enc_opt[r] + 2 : "raw", f, js);
        snprintf(f, sizeof f, "%s/grid.vti", out);
        fprintf(mf, "vti exact %s %s\n", path[r], f);
        checks += 2;
        /* energy.csv: what `energy --csv` prints */
        td_out o;
        size_t el = 0;
        snprintf(f, sizeof f, "%s/energy.csv", out);
        char *csv = td_slurp(f, &el);
        CHECK(td_ctl(&d, 30, &o, "energy", ids, "--csv", NULL) == 0 && o.status == 0);
        int same = csv && !strcmp(csv, o.out) && count_lines(csv) > 2;
        TLOG("run %d: %zu snapshots; energy.csv %zu lines, %s `energy --csv`", r + 1, ns,
             csv ? count_lines(csv) : 0, same ? "identical to" : "DIFFERENT from");
        free(csv);
        td_out_free(&o);
        CHECK(same);
    }
    {
        char js[400], f[400];
        snprintf(js, sizeof js, "%s/big.json", dir);
        CTL_OK(&d, "snapshot", "4", "-o", js);
        static const char *const encs[3] = {"--compress", "--base64", "--ascii"};
        for (int e = 0; e < 3; e++) {
            snprintf(f, sizeof f, "%s/big%d.vtp", dir, e);
            CTL_OK(&d, "snapshot", "4", "-o", f, encs[e]);
            fprintf(mf, "vtp %s %s %s\n", e == 2 ? "ascii" : "exact", js, f);
            checks++;
        }
    }
    /* nothing escaped DIR: the name's "/.." became "_.." */
    CHECK(access("block", F_OK) != 0);
    CHECK(fclose(mf) == 0);

    char *out = NULL;
    int rc = vtk_check(manifest, dir, &out);
    CHECKF(out, "no output from tests/clients/vtk_check.py");
    char **lines = NULL;
    size_t nl = td_lines(out, &lines), nok = 0;
    int plastic = 0;
    for (size_t i = 0; i < nl; i++) {
        TLOG("%s", lines[i]);
        nok += !strncmp(lines[i], "ok ", 3);
        plastic |= !strncmp(lines[i], "ok vtp exact raw.vtp: 1820 particles", 36) &&
                   !strstr(lines[i], " plastic 0,");
    }
    free(lines);
    /* the impact has yielded by step 200: plastic strain is not all zero */
    CHECKF(plastic, "no plastic strain in the J2 impact's last snapshot");
    CHECKF(rc == 0 && (int)nok == checks,
           "vtk_check.py: exit %d, %zu of %d checks ok (python3-vtk9 comes with make deps)", rc,
           nok, checks);
    free(out);
}

DTEST(ctl_vtk_errors)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", NULL};
    char dir[300], p1[400], p2[400], blocker[400], sub[500], vtp[400], png[400];
    td_daemon d;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    /* 1: no snapshots recorded; 2: snapshots without positions */
    json_t *c = block2d(20, 5, "plain");
    CHECK(c && write_case(c, dir, "c1.json", p1, sizeof p1) == 0);
    c = block2d(20, 5, "velocities only");
    CHECK(c);
    set_output(c, "snapshotEvery", json_integer(10));
    set_output(c, "recordSnapshots", json_true());
    set_output(c, "snapshotFields", json_pack("[s]", "V"));
    CHECK(write_case(c, dir, "c2.json", p2, sizeof p2) == 0);
    CHECK(run_case(&d, p1) == 0 && run_case(&d, p2) == 0);
    snprintf(vtp, sizeof vtp, "%s/x.vtp", dir);
    snprintf(png, sizeof png, "%s/energy.png", dir);

    EXPECT_CTL(&d, 1, "output.recordSnapshots: true", "export", "1", dir);
    EXPECT_CTL(&d, 1, "record X", "snapshot", "2", "-o", vtp);
    CHECK(access(vtp, F_OK) != 0);
    EXPECT_CTL(&d, 1, "record X", "export", "2", dir);
    EXPECT_CTL(&d, 1, "NOT_FOUND", "export", "99", dir);
    /* DIR below a regular file cannot be made */
    snprintf(blocker, sizeof blocker, "%s/file", dir);
    CHECK(td_write(blocker, "x\n") == 0);
    snprintf(sub, sizeof sub, "%s/out", blocker);
    EXPECT_CTL(&d, 1, "cannot create the directory", "export", "2", sub);
    EXPECT_CTL(&d, 2, "a run id and a directory", "export", "2");
    EXPECT_CTL(&d, 2, "exclude each other", "export", "2", dir, "--ascii", "--compress");
    EXPECT_CTL(&d, 2, "for a .vtp file", "snapshot", "2", "-o", "-", "--base64");
    EXPECT_CTL(&d, 2, "does not apply", "plot", "1", "-o", png, "--grid");
    EXPECT_CTL(&d, 2, "-o FILE is required", "plot", "1");
    EXPECT_CTL(&d, 2, "only letters", "plot", "1", "-o", png, "--terminal", "png\nsystem 'id'");
    EXPECT_CTL(&d, 2, "name it .png", "plot", "1", "-o", "energy.gif");

    /* plot: without gnuplot on PATH, the package to install */
    const char *oldpath = getenv("PATH");
    char *saved = oldpath ? strdup(oldpath) : NULL;
    setenv("PATH", "/nonexistent", 1);
    td_out o;
    int rc = td_ctl(&d, 30, &o, "plot", "1", "-o", png, NULL);
    if (saved) setenv("PATH", saved, 1);
    free(saved);
    CHECK(rc == 0);
    CHECKF(o.status == 1 && strstr(o.err, "gnuplot-nox"), "plot without gnuplot: exit %d: %s",
           o.status, o.err);
    td_out_free(&o);
    /* with gnuplot: a PNG */
    if (system("command -v gnuplot >/dev/null 2>&1") != 0) {
        TLOG("gnuplot is not installed (bash deploy/install-deps.sh plot): the PNG is not checked");
        return;
    }
    EXPECT_CTL(&d, 0, "", "plot", "1", "-o", png);
    size_t len = 0;
    unsigned char *img = (unsigned char *)td_slurp(png, &len);
    static const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    CHECKF(img && len > 5000 && len < 5000000 && !memcmp(img, sig, 8),
           "plot: %zu bytes, %s the PNG signature", len,
           img && len >= 8 && !memcmp(img, sig, 8) ? "with" : "without");
    /* the IHDR: 1000 x 750 */
    unsigned w =
        (unsigned)img[16] << 24 | (unsigned)img[17] << 16 | (unsigned)img[18] << 8 | img[19];
    unsigned h =
        (unsigned)img[20] << 24 | (unsigned)img[21] << 16 | (unsigned)img[22] << 8 | img[23];
    TLOG("plot: %s, %zu bytes, %u x %u", png, len, w, h);
    CHECK(w == 1000 && h == 750);
    free(img);
}
