/*
 * t_ctl_export.c - the conventions users bring, end to end through a real
 * mpmd (ipc://, a real SQLite file) and the real mpmctl:
 *
 *  - ctl_compressed_outputs: two 1D particles under uniaxial compression
 *    (sxx = -3000: pressure 1000, mean stress -1000) read a positive
 *    pressure and a negative mean stress in every output: the snapshot
 *    over the protocol (JSON), the CSV, the .vtp files (Debian's VTK,
 *    tests/clients/vtk_check.py) and the HDF5 file (h5py, tests/clients/h5_check.py); the
 *    run records a snapshot at step 0 and at its end (5 steps, one every
 *    2: steps 0 2 4 5);
 *  - ctl_export_hdf5: `export --format hdf5` of a 2D elastic block and of
 *    the J2 impact with CPDI (plastic strain, yield flags, F) read back with
 *    h5py, every value equal to the snapshot's, and the XDMF parsed with
 *    every reference resolved; the sizes beside the VTK export's; the
 *    option errors.
 */
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* Submits the case file and watches it to the end; 0 or -1. */
static int run_case(const td_daemon *d, const char *path)
{
    td_out o;
    int ok = td_ctl(d, 180, &o, "submit", path, "--watch", NULL) == 0 && o.status == 0;
    if (!ok) TLOG("submit %s --watch: exit %d: %s%s", path, o.status, o.out, o.err);
    td_out_free(&o);
    return ok ? 0 : -1;
}

/* mpmctl ARGS... exits 0 (else logged, -1). */
static int ctl_ok(const td_daemon *d, const char *const *args)
{
    td_out o;
    int ok = td_ctlv(d, 60, &o, args) == 0 && o.status == 0;
    if (!ok) TLOG("mpmctl %s %s: exit %d: %s", args[0], args[1], o.status, o.err);
    td_out_free(&o);
    return ok ? 0 : -1;
}
#define CTL_OK(d, ...)                                                     \
    do {                                                                   \
        const char *a_[] = {__VA_ARGS__, NULL};                            \
        CHECKF(ctl_ok(d, a_) == 0, "mpmctl %s failed (log above)", a_[0]); \
    } while (0)

/* Runs /usr/bin/python3 tests/SCRIPT ARGS, logs its output; its exit. */
static int py_check(const char *dir, const char *script, const char *args, char **out)
{
    char cmd[2400], path[512];
    size_t len = 0;
    snprintf(path, sizeof path, "%s/%s.out", dir, script);
    snprintf(cmd, sizeof cmd, "/usr/bin/python3 tests/clients/%s %s > %s 2>&1", script, args, path);
    int rc = system(cmd);
    *out = td_slurp(path, &len);
    char **lines = NULL, *copy = *out ? strdup(*out) : NULL; /* td_lines splits in place */
    size_t nl = copy ? td_lines(copy, &lines) : 0;
    for (size_t i = 0; i < nl; i++) TLOG("%s", lines[i]);
    free(lines);
    free(copy);
    return rc;
}

/* Every recorded snapshot of run id as dir/STEP.json; their count. */
static int snapshots_json(const td_daemon *d, int id, const char *dir, long long *steps, int max)
{
    char ids[16], f[600], st[32];
    snprintf(ids, sizeof ids, "%d", id);
    json_t *ri = show_json(d, (unsigned long long)id);
    json_t *a = json_object_get(ri, "snapshotSteps");
    int n = (int)json_array_size(a);
    mkdir(dir, 0777);
    for (int i = 0; i < n && i < max; i++) {
        json_t *v = json_array_get(a, (size_t)i);
        steps[i] = json_is_string(v) ? atoll(json_string_value(v)) : json_integer_value(v);
        snprintf(st, sizeof st, "%lld", steps[i]);
        snprintf(f, sizeof f, "%s/%s.json", dir, st);
        const char *args[] = {"snapshot", ids, "--step", st, "-o", f, NULL};
        if (ctl_ok(d, args)) n = -1;
    }
    json_decref(ri);
    return n;
}

/* The bytes of every file in dir whose name ends in suffix. */
static long long dir_bytes(const char *dir, const char *suffix)
{
    char cmd[700];
    snprintf(cmd, sizeof cmd, "cd %s && cat -- *%s 2>/dev/null | wc -c", dir, suffix);
    FILE *p = popen(cmd, "r");
    long long n = -1;
    if (p) {
        if (fscanf(p, "%lld", &n) != 1) n = -1;
        pclose(p);
    }
    return n;
}

DTEST(ctl_compressed_outputs)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", NULL};
    char dir[300], path[400], js[400], f[600], args[1500], vtk[500], h5[500];
    long long steps[8];
    td_daemon d;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(write_case(compressed1d("compressed"), dir, "c.json", path, sizeof path) == 0);
    CHECK(run_case(&d, path) == 0);

    /* the schedule: every 2 steps, and the initial state and the end */
    snprintf(js, sizeof js, "%s/js", dir);
    int ns = snapshots_json(&d, 1, js, steps, 8);
    TLOG("recorded snapshot steps: %d: %lld %lld %lld %lld", ns, steps[0], steps[1], steps[2],
         steps[3]);
    CHECKF(ns == 4 && steps[0] == 0 && steps[1] == 2 && steps[2] == 4 && steps[3] == 5,
           "the snapshots are not at steps 0 2 4 5 (%d of them)", ns);

    /* over the protocol (decoded and printed as the JSON mapping) */
    snprintf(f, sizeof f, "%s/0.json", js);
    json_error_t je;
    json_t *s0 = json_load_file(f, 0, &je);
    CHECK(s0);
    json_t *p = json_object_get(s0, "pressure"), *m = json_object_get(s0, "meanStress");
    CHECKF(json_array_size(p) == 2 && json_array_size(m) == 2, "step 0: no pressure/meanStress");
    for (size_t i = 0; i < 2; i++) {
        double pv = json_number_value(json_array_get(p, i));
        double mv = json_number_value(json_array_get(m, i));
        TLOG("protocol, step 0, particle %zu: pressure %.17g, meanStress %.17g", i, pv, mv);
        CHECK(pv == COMPRESSED_PRESSURE && mv == -COMPRESSED_PRESSURE);
    }
    json_decref(s0);

    /* the CSV (`snapshot -o -`): the end's pressure positive, within 1 % */
    td_out o;
    CHECK(td_ctl(&d, 30, &o, "snapshot", "1", "-o", "-", NULL) == 0 && o.status == 0);
    char **lines = NULL;
    size_t nl = td_lines(o.out, &lines);
    TLOG("CSV: %s | %s", nl ? lines[0] : "", nl > 1 ? lines[1] : "");
    CHECKF(nl == 3 && strstr(lines[0], ",pressure,mean_stress,"), "the CSV's header: %s",
           nl ? lines[0] : "(none)");
    for (size_t i = 1; i < nl; i++) {
        /* i,x,vx,sxx..sxz,pressure,mean_stress,volume */
        double v[12];
        int k = sscanf(lines[i], "%*d,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf", &v[0], &v[1],
                       &v[2], &v[3], &v[4], &v[5], &v[6], &v[7], &v[8], &v[9], &v[10]);
        CHECKF(k == 11 && v[8] > 0 &&
                   fabs(v[8] - COMPRESSED_PRESSURE) < 1e-2 * COMPRESSED_PRESSURE && v[9] == -v[8],
               "CSV row %zu: %s", i, lines[i]);
    }
    free(lines);
    td_out_free(&o);

    /* VTK */
    snprintf(vtk, sizeof vtk, "%s/vtk", dir);
    CTL_OK(&d, "export", "1", vtk);
    snprintf(f, sizeof f, "%s/manifest.txt", dir);
    FILE *mf = fopen(f, "w");
    CHECK(mf);
    fprintf(mf, "pressure %.17g 0 %s/compressed_0.vtp\n", COMPRESSED_PRESSURE, vtk);
    fprintf(mf, "pressure %.17g 1e-2 %s/compressed_5.vtp\n", COMPRESSED_PRESSURE, vtk);
    fprintf(mf, "pvd raw %s/compressed.pvd %s\n", vtk, js);
    CHECK(fclose(mf) == 0);
    char *out = NULL;
    snprintf(args, sizeof args, "%s", f);
    int rc = py_check(dir, "vtk_check.py", args, &out);
    CHECKF(rc == 0 && out && strstr(out, "ok pressure") && strstr(out, "ok pvd"),
           "vtk_check.py: exit %d", rc);
    free(out);

    /* HDF5 */
    snprintf(h5, sizeof h5, "%s/h5", dir);
    CTL_OK(&d, "export", "1", h5, "--format", "hdf5");
    snprintf(args, sizeof args, "%s/compressed.h5 %s/compressed.xdmf %s %.17g", h5, h5, js,
             COMPRESSED_PRESSURE);
    rc = py_check(dir, "h5_check.py", args, &out);
    CHECKF(rc == 0 && out && strstr(out, "ok pressure") && strstr(out, "ok xdmf"),
           "h5_check.py: exit %d (python3-h5py comes with make deps)", rc);
    free(out);
}

DTEST(ctl_export_hdf5)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "2", "--solver-threads", "1", NULL};
    char dir[300], path[2][400], args[1500];
    static const char *const stems[2] = {"block2d", "impact2d_j2"};
    long long steps[64];
    td_daemon d;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    json_t *c = block2d(40, 10, "block2d");
    CHECK(c);
    set_output(c, "snapshotEvery", json_integer(10));
    set_output(c, "recordSnapshots", json_true());
    CHECK(write_case(c, dir, "c1.json", path[0], sizeof path[0]) == 0);
    c = example("impact2d_j2");
    CHECK(c);
    json_object_del(c, "endTime");
    json_object_set_new(c, "steps", json_integer(200));
    json_object_set_new(c, "method", json_string("CPDI"));
    json_object_del(c, "output");
    set_output(c, "energyEvery", json_integer(10));
    set_output(c, "snapshotEvery", json_integer(50));
    set_output(c, "recordSnapshots", json_true());
    CHECK(write_case(c, dir, "c2.json", path[1], sizeof path[1]) == 0);
    for (int r = 0; r < 2; r++) CHECK(run_case(&d, path[r]) == 0);
    for (int r = 0; r < 2; r++) {
        char ids[16], js[400], h5[400], vt[400];
        snprintf(ids, sizeof ids, "%d", r + 1);
        snprintf(js, sizeof js, "%s/js%d", dir, r + 1);
        int ns = snapshots_json(&d, r + 1, js, steps, 64);
        CHECKF(ns >= 3 && steps[0] == 0, "run %d: %d snapshots, the first at %lld", r + 1, ns,
               steps[0]);
        snprintf(h5, sizeof h5, "%s/h5_%d", dir, r + 1);
        snprintf(vt, sizeof vt, "%s/vtk_%d", dir, r + 1);
        CTL_OK(&d, "export", ids, h5, "--format", "hdf5");
        CTL_OK(&d, "export", ids, vt, "--format", "vtk");
        snprintf(args, sizeof args, "%s/%s.h5 %s/%s.xdmf %s", h5, stems[r], h5, stems[r], js);
        char *out = NULL;
        int rc = py_check(dir, "h5_check.py", args, &out);
        CHECKF(rc == 0 && out && strstr(out, "ok h5") && strstr(out, "ok xdmf"),
               "h5_check.py on run %d: exit %d", r + 1, rc);
        free(out);
        TLOG("run %d (%s): %d snapshots: HDF5 %lld bytes (+ .xdmf %lld), VTK .vtp %lld bytes (+ "
             ".pvd %lld)",
             r + 1, stems[r], ns, dir_bytes(h5, ".h5"), dir_bytes(h5, ".xdmf"),
             dir_bytes(vt, ".vtp"), dir_bytes(vt, ".pvd"));
    }
    EXPECT_CTL(&d, 2, "expected vtk or hdf5", "export", "1", dir, "--format", "netcdf");
    EXPECT_CTL(&d, 2, "are for --format vtk", "export", "1", dir, "--format", "hdf5", "--ascii");
    EXPECT_CTL(&d, 2, "does not apply", "snapshot", "1", "-o", "-", "--format", "hdf5");
}
