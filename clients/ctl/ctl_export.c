/*
 * ctl_export.c - mpmctl's commands that turn a stored run into files for
 * other programs, through the public protocol only (GetRun with its case,
 * GetSnapshot, GetEnergy), as any third-party client would:
 *
 *  - `export ID DIR`: every recorded snapshot as DIR/<name>_<step>.vtp (the
 *    steps zero-padded to one width), the collection DIR/<name>.pvd with
 *    the simulation times (ParaView opens the run as a time series), or
 *    with --format hdf5 all of them in DIR/<name>.h5 with DIR/<name>.xdmf
 *    (ctl_h5.c), the energy series as DIR/energy.csv (the very
 *    CSV `mpmctl energy --csv` prints, by the same writer) and, with
 *    --grid, the case's background grid as DIR/grid.vti;
 *  - `plot ID -o FILE`: the energy curves drawn by gnuplot, run as a
 *    program (no shell) on a script and a data file in a private temporary
 *    directory; the run's name never enters the script.
 *
 * <name> is the run's name with every byte outside [A-Za-z0-9._-] replaced
 * by '_' (and "run<ID>" when that leaves nothing usable), so that no name
 * can reach outside DIR or need escaping in the .pvd.
 */
#include "ctl_vtk.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include "ctl.h"
#include "ctl_h5.h"

/* The file name stem of a run: its name made safe, or run<ID>. */
static void safe_stem(const char *name, uint64_t id, char *out, size_t n)
{
    size_t k = 0;
    for (const char *p = name; *p && k + 1 < n && k < 64; p++) {
        char ch = *p;
        int ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') ||
                 ch == '.' || ch == '_' || ch == '-';
        out[k++] = ok ? ch : '_';
    }
    out[k] = 0;
    /* nothing, or only dots and underscores: no name worth keeping */
    if (!k || strspn(out, "._") == k) snprintf(out, n, "run%llu", (unsigned long long)id);
}

/* DIR exists (created if missing, one level) and is a writable directory. */
static int prepare_dir(const char *dir)
{
    struct stat st;
    if (mkdir(dir, 0777) && errno != EEXIST) {
        fprintf(stderr, "mpmctl: export: cannot create the directory %s: %s\n", dir,
                strerror(errno));
        return CTL_ESYS;
    }
    if (stat(dir, &st) || !S_ISDIR(st.st_mode)) {
        fprintf(stderr, "mpmctl: export: %s is not a directory\n", dir);
        return CTL_ESYS;
    }
    if (access(dir, W_OK | X_OK)) {
        fprintf(stderr, "mpmctl: export: the directory %s is not writable: %s\n", dir,
                strerror(errno));
        return CTL_ESYS;
    }
    return 0;
}

static int csv_row(const mpm_energy_sample *s, void *arg)
{
    return ctl_energy_out_row(arg, s);
}

/* DIR/energy.csv, as `mpmctl energy --csv` writes it. */
static int export_energy(ctl_conn *c, uint64_t id, const char *path, size_t *rows)
{
    FILE *f = fopen(path, "w");
    ctl_energy_out eo;
    size_t count = 0;
    int rc;
    if (!f) {
        fprintf(stderr, "mpmctl: cannot write %s: %s\n", path, strerror(errno));
        return CTL_ESYS;
    }
    ctl_energy_out_init(&eo, CTL_OUT_CSV, 0, f);
    rc = ctl_fetch_energy(c, id, 0, csv_row, &eo);
    if (!rc) count = eo.header_done;
    if (fclose(f) && !rc) {
        fprintf(stderr, "mpmctl: cannot write %s: %s\n", path, strerror(errno));
        rc = CTL_ESYS;
    }
    if (rc) remove(path);
    *rows = count;
    return rc;
}

/* The case's grid from a RunInfo's "case" (JSON mapping). */
static int grid_of(const json_t *run, ctl_vtk_grid *g)
{
    const json_t *cs = json_object_get(run, "case"), *gr = json_object_get(cs, "grid");
    memset(g, 0, sizeof *g);
    if (!gr) {
        fprintf(stderr, "mpmctl: export --grid: the server sent the run without its case grid\n");
        return CTL_EPROTO;
    }
    g->dim = (int)cj_int(gr, "dim", 0);
    if (g->dim < 1 || g->dim > 3 || cj_len(gr, "spacing") < (size_t)g->dim ||
        cj_len(gr, "nodes") < (size_t)g->dim) {
        fprintf(stderr, "mpmctl: export --grid: the case's grid is incomplete (dim %d)\n", g->dim);
        return CTL_EPROTO;
    }
    for (int d = 0; d < g->dim; d++) {
        g->origin[d] = cj_at(gr, "origin", (size_t)d, 0);
        g->spacing[d] = cj_at(gr, "spacing", (size_t)d, 0);
        g->nodes[d] = (uint32_t)cj_at(gr, "nodes", (size_t)d, 1);
    }
    return 0;
}

int ctl_export(ctl_conn *c, uint64_t id, const char *dir, ctl_export_format fmt, ctl_vtk_enc enc,
               int grid)
{
    mpp_request rq = {.kind = MPP_REQ_GET_RUN, .id = id, .with_case = grid};
    json_t *reply = NULL, *run = NULL, *steps;
    char stem[80], *path = NULL, **files = NULL;
    double *times = NULL;
    size_t ns = 0, rows = 0, plen = strlen(dir) + 160, i;
    ctl_h5 *h5 = NULL;
    int rc = ctl_call(c, &rq, "run", &reply, &run), tty = isatty(2), width = 1;
    if (rc) goto out;
    steps = json_object_get(run, "snapshotSteps");
    ns = json_is_array(steps) ? json_array_size(steps) : 0;
    if (!ns) {
        fprintf(stderr,
                "mpmctl: export: run %llu has no recorded snapshots (submit the case with "
                "output.snapshotEvery > 0 and output.recordSnapshots: true to record them)\n",
                (unsigned long long)id);
        rc = CTL_ECASE;
        goto out;
    }
    if ((rc = prepare_dir(dir))) goto out;
    safe_stem(cj_str(run, "name", ""), id, stem, sizeof stem);
    path = malloc(plen);
    files = calloc(ns, sizeof *files);
    times = calloc(ns, sizeof *times);
    if (!path || !files || !times) {
        fprintf(stderr, "mpmctl: export: out of memory\n");
        rc = CTL_ESYS;
        goto out;
    }
    /* the steps' common width: the largest step's digits */
    for (i = 0; i < ns; i++) {
        char d[24];
        int w = snprintf(d, sizeof d, "%lld", (long long)cj_at(run, "snapshotSteps", i, 0));
        if (w > width) width = w;
    }
    if (fmt == CTL_EXPORT_HDF5) {
        snprintf(path, plen, "%s/%s.h5", dir, stem);
        if (!(h5 = ctl_h5_new(path, id, width))) {
            rc = CTL_ESYS;
            goto out;
        }
    }
    for (i = 0; i < ns; i++) {
        mpp_request sq = {.kind = MPP_REQ_GET_SNAPSHOT, .id = id, .has_step = 1};
        mpp_reply sr;
        sq.step = (int64_t)cj_at(run, "snapshotSteps", i, 0);
        if (tty)
            fprintf(stderr, "\rrun %llu: snapshot %zu of %zu (step %lld)...",
                    (unsigned long long)id, i + 1, ns, (long long)sq.step);
        rc = ctl_call_reply(c, &sq, MPP_REPLY_SNAPSHOT, &sr);
        if (!rc && h5) {
            rc = ctl_h5_add(h5, &sr.snapshot);
        } else if (!rc) {
            char name[120];
            snprintf(name, sizeof name, "%s_%0*lld.vtp", stem, width, (long long)sr.snapshot.step);
            files[i] = strdup(name);
            times[i] = sr.snapshot.t;
            snprintf(path, plen, "%s/%s", dir, name);
            if (files[i]) {
                rc = ctl_vtk_write_vtp(path, &sr.snapshot, enc);
            } else {
                fprintf(stderr, "mpmctl: export: out of memory\n");
                rc = CTL_ESYS;
            }
        }
        mpp_reply_clear(&sr);
        if (rc) {
            if (tty) fputc('\n', stderr);
            goto out;
        }
    }
    if (tty) fputc('\n', stderr);
    if (h5) {
        char h5name[100];
        snprintf(h5name, sizeof h5name, "%s.h5", stem);
        snprintf(path, plen, "%s/%s.xdmf", dir, stem);
        if ((rc = ctl_h5_finish(&h5, 1, path, h5name))) goto out;
    } else {
        snprintf(path, plen, "%s/%s.pvd", dir, stem);
        if ((rc = ctl_vtk_write_pvd(path, (const char *const *)files, times, ns))) goto out;
    }
    snprintf(path, plen, "%s/energy.csv", dir);
    if ((rc = export_energy(c, id, path, &rows))) goto out;
    if (grid) {
        ctl_vtk_grid g;
        snprintf(path, plen, "%s/grid.vti", dir);
        if ((rc = grid_of(run, &g)) || (rc = ctl_vtk_write_vti(path, &g, enc))) goto out;
    }
    if (fmt == CTL_EXPORT_HDF5)
        fprintf(stderr, "run %llu: %zu snapshots, %s.h5, %s.xdmf, energy.csv%s -> %s\n",
                (unsigned long long)id, ns, stem, stem, grid ? ", grid.vti" : "", dir);
    else
        fprintf(stderr, "run %llu: %zu snapshots (%s), %s.pvd, energy.csv%s -> %s\n",
                (unsigned long long)id, ns, ctl_vtk_enc_name(enc), stem, grid ? ", grid.vti" : "",
                dir);
out:
    if (h5) ctl_h5_finish(&h5, 0, NULL, NULL); /* a failure: removes the .h5 */
    for (i = 0; files && i < ns; i++) free(files[i]);
    free(files);
    free(times);
    free(path);
    json_decref(reply);
    return rc;
}

/* ---- plot -------------------------------------------------------------------- */

typedef struct {
    FILE *f;
    size_t n;
} plot_data;

static int plot_row(const mpm_energy_sample *s, void *arg)
{
    plot_data *p = arg;
    fprintf(p->f, "%.17g %.17g %.17g %.17g %.17g\n", cj_norm(s->t), cj_norm(s->e.kinetic),
            cj_norm(s->e.strain), cj_norm(s->e.total), 100 * cj_norm(s->e.balance_error));
    p->n++;
    return ferror(p->f) ? CTL_ESYS : 0;
}

/* s as a gnuplot single-quoted string (a quote doubled; nothing else is
 * special inside one). */
static void gp_quoted(FILE *f, const char *s)
{
    fputc('\'', f);
    for (; *s; s++) {
        if (*s == '\'') fputc('\'', f);
        fputc(*s, f);
    }
    fputc('\'', f);
}

/* 1 when an executable gnuplot is on PATH. */
static int have_gnuplot(void)
{
    const char *pathenv = getenv("PATH");
    char buf[4096];
    if (!pathenv || !*pathenv) pathenv = "/usr/bin:/bin";
    while (*pathenv) {
        size_t len = strcspn(pathenv, ":");
        if (len && len < sizeof buf - 16) {
            snprintf(buf, sizeof buf, "%.*s/gnuplot", (int)len, pathenv);
            if (!access(buf, X_OK)) return 1;
        }
        pathenv += len;
        if (*pathenv == ':') pathenv++;
    }
    return 0;
}

/* The gnuplot terminal for a file name: by its extension. */
static const char *terminal_for(const char *out)
{
    const char *dot = strrchr(out, '.');
    if (dot && !strcmp(dot, ".png")) return "pngcairo size 1000,750 noenhanced";
    if (dot && !strcmp(dot, ".svg")) return "svg size 1000,750 noenhanced";
    if (dot && !strcmp(dot, ".pdf")) return "pdfcairo size 10in,7.5in noenhanced";
    return NULL;
}

int ctl_plot(ctl_conn *c, uint64_t id, const char *out, const char *terminal)
{
    const char *tmp = getenv("TMPDIR");
    char dir[512], data[600], script[600];
    plot_data pd = {0};
    FILE *f;
    int rc = 0, status = 0;
    pid_t pid;
    if (!terminal) terminal = terminal_for(out);
    if (!terminal) {
        fprintf(stderr,
                "mpmctl: plot: cannot tell the format of %s: name it .png, .svg or .pdf, "
                "or give --terminal (a gnuplot terminal, e.g. \"pngcairo size 800,600\")\n",
                out);
        return CTL_EUSAGE;
    }
    if (strspn(terminal, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 ,._-") !=
        strlen(terminal)) {
        fprintf(stderr,
                "mpmctl: plot: --terminal '%s': only letters, digits, spaces and , . _ - "
                "are allowed\n",
                terminal);
        return CTL_EUSAGE;
    }
    if (!have_gnuplot()) {
        fprintf(stderr, "mpmctl: plot needs gnuplot, which is not on PATH: install the Debian "
                        "package gnuplot-nox (apt-get install gnuplot-nox)\n");
        return CTL_ESYS;
    }
    snprintf(dir, sizeof dir, "%s/mpmctl-plot.XXXXXX", tmp && *tmp ? tmp : "/tmp");
    if (!mkdtemp(dir)) {
        fprintf(stderr, "mpmctl: plot: cannot make a temporary directory %s: %s\n", dir,
                strerror(errno));
        return CTL_ESYS;
    }
    snprintf(data, sizeof data, "%s/energy.dat", dir);
    snprintf(script, sizeof script, "%s/plot.gp", dir);
    if (!(f = fopen(data, "w"))) {
        fprintf(stderr, "mpmctl: plot: cannot write %s: %s\n", data, strerror(errno));
        rc = CTL_ESYS;
        goto out;
    }
    pd.f = f;
    rc = ctl_fetch_energy(c, id, 0, plot_row, &pd);
    if (fclose(f) && !rc) {
        fprintf(stderr, "mpmctl: plot: cannot write %s: %s\n", data, strerror(errno));
        rc = CTL_ESYS;
    }
    if (rc) goto out;
    if (!pd.n) {
        fprintf(stderr, "mpmctl: plot: run %llu has no energy samples\n", (unsigned long long)id);
        rc = CTL_ECASE;
        goto out;
    }
    if (!(f = fopen(script, "w"))) {
        fprintf(stderr, "mpmctl: plot: cannot write %s: %s\n", script, strerror(errno));
        rc = CTL_ESYS;
        goto out;
    }
    fprintf(f, "set terminal %s\nset output ", terminal);
    gp_quoted(f, out);
    fprintf(f, "\nset multiplot layout 2,1 title 'run %llu: energies'\n", (unsigned long long)id);
    /* the same margins in both panels, so that their t axes line up */
    fputs("set grid\nset key outside right\nset lmargin at screen 0.1\n"
          "set rmargin at screen 0.78\nset xlabel 't'\nset ylabel 'energy'\n",
          f);
    fputs("plot ", f);
    gp_quoted(f, data);
    fputs(" using 1:2 with lines lw 2 title 'kinetic', '' using 1:3 with lines lw 2 title "
          "'strain', '' using 1:4 with lines lw 2 title 'total'\n",
          f);
    fputs("set ylabel 'balance error (%)'\nplot ", f);
    gp_quoted(f, data);
    fputs(" using 1:5 with lines lw 2 title 'balance error'\nunset multiplot\n", f);
    if (fclose(f)) {
        fprintf(stderr, "mpmctl: plot: cannot write %s: %s\n", script, strerror(errno));
        rc = CTL_ESYS;
        goto out;
    }
    fflush(stdout);
    pid = fork();
    if (pid < 0) {
        fprintf(stderr, "mpmctl: plot: fork: %s\n", strerror(errno));
        rc = CTL_ESYS;
        goto out;
    }
    if (pid == 0) {
        execlp("gnuplot", "gnuplot", script, (char *)NULL);
        _exit(127);
    }
    while (waitpid(pid, &status, 0) < 0)
        if (errno != EINTR) {
            status = -1;
            break;
        }
    if (status != 0) {
        fprintf(stderr, "mpmctl: plot: gnuplot failed (status %d) writing %s\n",
                WIFEXITED(status) ? WEXITSTATUS(status) : status, out);
        rc = CTL_ESYS;
        goto out;
    }
    fprintf(stderr, "run %llu: %zu energy samples plotted -> %s\n", (unsigned long long)id, pd.n,
            out);
out:
    remove(data);
    remove(script);
    rmdir(dir);
    return rc;
}
