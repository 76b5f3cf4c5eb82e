/*
 * scenes.c - the in-process scenes of bin/mpmbench and how one
 * configuration is measured.  Every scene is built through the public
 * solver API (mpm.h, and the paper's cases of mpm_paper.h):
 *   disks2d  the paper's two elastic disks (E = 1, nu = 0.2, rho = 1,
 *            radius 0.14, speed 0.1 towards each other) with the grid of
 *            the unit square refined until 2 x 2 particles per cell give
 *            about the particles asked for (10^6: 1425 cells per axis);
 *   cube3d   an elastic cube (E = 1 MPa, nu = 0.3, rho = 1000) of n^3
 *            cells at 2 x 2 x 2 particles per cell, dropped at 2 m/s from
 *            one cell above a fixed floor (the z-low face a wall) under
 *            gravity, so it hits the floor within the first steps;
 *   bar1d    the paper's bar (E = 10, rho = 1, fixed at x = 0, first-mode
 *            velocity v0 sin(pi x / 2)) at 2 particles per cell, v0 = 1e-5:
 *            with fewer particles the default steps cover more simulated
 *            time, and with the paper's v0 = 0.1 (or even 1e-3) MPM USF's
 *            cell-crossing noise makes such runs diverge;
 *   sparse2d a spinning elastic disk of explicit particles (2 x 2 per cell,
 *            E = 1, nu = 0.2, rho = 1, 0.15 rad per unit time) in a 4096 x
 *            4096 node grid, and the same disk, placed identically relative
 *            to the cells, in a grid just large enough for it (4 cells of
 *            margin).
 * The time step is automatic (C = 0.5) everywhere.  Each scene also has a
 * span of simulated time it stays valid for (the disks separate and head
 * for the walls after t = 4; the spinning disk's small-strain stresses
 * drift after many radians; MPM's cell-crossing noise grows in long runs):
 * default steps are capped so that the warm-up and the timed runs together
 * stay within it, which matters only for small particle counts.
 *
 * Measuring: a configuration runs in a forked child (pb_in_child), so its
 * peak RSS is its own: the parent reads the child's ru_maxrss with wait4().
 * The child builds the case and the simulation, runs a warm-up of the same
 * length as a timed run, then PB_RUNS timed mpm_sim_run() calls that
 * continue the same simulation.  When the steps are the defaults and the
 * warm-up takes longer than PB_WARM_CAP_S, the warm-up stops there and the
 * timed runs use the steps that fit PB_RUN_S at the speed of its second
 * half (the row says so); steps given with --steps are always run in full.
 * The row also gets the CPU time over the wall time of the timed runs
 * (getrusage), which shows when other processes took the CPUs.
 */
#include "perf.h"

#include "mpm_collapse.h"
#include "mpm_paper.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#define DISK_R 0.14
#define SPARSE_WIDE_NODES 4096
#define SPARSE_MARGIN 4 /* cells around the tight grid's disk */
#define SPARSE_H 0.001
#define SPARSE_OMEGA 0.15 /* rad per unit time: <= 1.8 rad in the scene's TMAX */
#define BAR_V0 1e-5       /* amplitude v0 / omega_1 = 2e-6: no cell crossing below 10^6 particles */
#define CUBE_MARGIN 3     /* cells beside the cube */
#define CUBE_TOP 14       /* cells above it: room for the rebound (v0^2 / 2g ~ 10 cells) */

static const char *const scene_names[PB_NSCENES] = {
    "disks2d",        "cube3d",        "bar1d",        "sparse2d-4096",
    "sparse2d-tight", "collapse2d-dp", "collapse2d-el"};

static mpm_kernels_isa kernels_isa; /* set once from the command line */
void pb_set_kernels(mpm_kernels_isa k)
{
    kernels_isa = k;
}
mpm_kernels_isa pb_kernels(void)
{
    return kernels_isa;
}

const char *pb_scene_name(pb_scene s)
{
    return (unsigned)s < PB_NSCENES ? scene_names[s] : "?";
}

int pb_scene_dim(pb_scene s)
{
    return s == PB_CUBE3D ? 3 : s == PB_BAR1D ? 1 : 2;
}

long pb_scene_default_particles(pb_scene s)
{
    return s == PB_SPARSE_WIDE || s == PB_SPARSE_TIGHT ? 10000L : 1000000L;
}

const char *pb_method_name(mpm_method m)
{
    return m == MPM_METHOD_GIMP       ? "GIMP"
           : m == MPM_METHOD_BSPLINE2 ? "BSPLINE2"
           : m == MPM_METHOD_BSPLINE3 ? "BSPLINE3"
           : m == MPM_METHOD_CPDI     ? "CPDI"
                                      : "MPM";
}

const char *pb_update_name(mpm_update u)
{
    return u == MPM_USL ? "USL" : u == MPM_MUSL ? "MUSL" : "USF";
}

double pb_target_rate(int dim, mpm_method m)
{
    int g = m != MPM_METHOD_MPM; /* B-splines: GIMP's (step counts only) */
    if (m == MPM_METHOD_CPDI)
        return 0.4 * pb_target_rate(dim, MPM_METHOD_GIMP); /* --cpdi-vs-gimp */
    if (dim == 3) return g ? 3.0 : 16.0;
    if (dim == 2) return g ? 12.0 : 30.0;
    return g ? 30.0 : 60.0; /* 1D: no target; for step counts only */
}

long pb_default_steps(int dim, mpm_method m, size_t particles)
{
    double s = pb_target_rate(dim, m) * 1e6 * PB_RUN_S / (double)(particles ? particles : 1);
    long k = (long)ceil(s);
    return k < 5 ? 5 : k > PB_MAX_STEPS ? PB_MAX_STEPS : k;
}

/* The simulated time a scene stays valid for (see the top). */
static double scene_tmax(pb_scene s)
{
    switch (s) {
    case PB_DISKS2D: return 4.0;
    case PB_CUBE3D: return 0.5;
    case PB_BAR1D: return 10.0;
    case PB_COLLAPSE_DP:
    case PB_COLLAPSE_EL: return 0.3; /* the column is still falling */
    default: return 12.0;
    }
}

int pb_disks_cells(long particles)
{
    double area = 2 * M_PI * DISK_R * DISK_R;
    long c = lround(sqrt((double)particles / (4 * area)));
    return c < 10 ? 10 : c > 200000 ? 200000 : (int)c;
}

double pb_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

double pb_cpu_self(void)
{
    struct rusage ru;
    if (getrusage(RUSAGE_SELF, &ru)) return 0;
    return (double)ru.ru_utime.tv_sec + 1e-6 * (double)ru.ru_utime.tv_usec +
           (double)ru.ru_stime.tv_sec + 1e-6 * (double)ru.ru_stime.tv_usec;
}

double pb_median(const double *v, int n)
{
    double s[PB_MAX_RUNS];
    if (n <= 0) return 0;
    if (n > PB_MAX_RUNS) n = PB_MAX_RUNS;
    memcpy(s, v, (size_t)n * sizeof *s);
    for (int i = 1; i < n; i++)
        for (int j = i; j > 0 && s[j - 1] > s[j]; j--) {
            double x = s[j];
            s[j] = s[j - 1];
            s[j - 1] = x;
        }
    return n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
}

/* ---- building the scenes ---- */

static int build_cube(const pb_cfg *c, mpm_paper *t, char *err, size_t errlen)
{
    memset(t, 0, sizeof *t);
#ifdef MPM_LEAN
    (void)c;
    snprintf(err, errlen,
             "cube3d needs gravity and a fixed floor, which MPM_LEAN compiles out "
             "(run it with bin/mpmbench)");
    return -1;
#else
    long np = c->particles ? c->particles : pb_scene_default_particles(PB_CUBE3D);
    int n = (int)lround(cbrt((double)np / 8.0));
    if (n < 2) n = 2;
    double h = 1.0 / n; /* a 1 m cube */
    (void)err;
    (void)errlen;
    t->mat[0] = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                    .youngs_modulus = 1e6,
                                    .poisson_ratio = 0.3,
                                    .density = 1000.0};
    mpm_body_desc *b = &t->body[0];
    b->shape = MPM_SHAPE_BOX;
    b->ppc = 2;
    for (int d = 0; d < 3; d++) {
        b->lo[d] = d < 2 ? CUBE_MARGIN * h : h;
        b->hi[d] = b->lo[d] + 1.0;
    }
    b->velocity[2] = -2.0;
    int nxy = n + 2 * CUBE_MARGIN + 1, nz = 1 + n + CUBE_TOP + 1;
    t->c.grid = (mpm_grid_desc){3, {0, 0, 0}, {h, h, h}, {nxy, nxy, nz}};
    t->c.gravity[2] = -9.81;
    t->c.bc.face_mask[4] = 7; /* the floor: z-low face, a wall */
    t->c.n_materials = 1;
    t->c.materials = t->mat;
    t->c.n_bodies = 1;
    t->c.bodies = t->body;
    return 0;
#endif
}

/* The spinning disk's particles (2 x 2 per cell of h within radius R of
 * (xc, xc), angular speed w): their count, and, t->x set, their positions,
 * velocities and volumes written into t. */
static size_t sparse_points(mpm_paper *t, int rc, double h, double R, double xc, double w)
{
    size_t k = 0;
    for (int i = -2 * rc; i < 2 * rc; i++)
        for (int j = -2 * rc; j < 2 * rc; j++) {
            double px = (i + 0.5) * h / 2, py = (j + 0.5) * h / 2;
            if (px * px + py * py > R * R) continue;
            if (t && t->x) {
                t->x[2 * k] = xc + px;
                t->x[2 * k + 1] = xc + py;
                t->v[2 * k] = -w * py;
                t->v[2 * k + 1] = w * px;
                t->vol[k] = h * h / 4;
            }
            k++;
        }
    return k;
}

static int build_sparse(const pb_cfg *c, int wide, mpm_paper *t, char *err, size_t errlen)
{
    memset(t, 0, sizeof *t);
    long want = c->particles ? c->particles : pb_scene_default_particles(PB_SPARSE_WIDE);
    double h = SPARSE_H;
    double R = sqrt((double)want / (4 * M_PI)) * h;
    int rc = (int)ceil(R / h);
    int tight = 2 * rc + 2 * SPARSE_MARGIN + 1;
    if (tight > SPARSE_WIDE_NODES) {
        snprintf(err, errlen,
                 "--particles: sparse2d takes at most %ld particles (a disk that "
                 "fits its %d x %d grid), got %ld",
                 (long)(M_PI * pow((SPARSE_WIDE_NODES - 1) / 2.0 - SPARSE_MARGIN, 2) * 4) - 1,
                 SPARSE_WIDE_NODES, SPARSE_WIDE_NODES, want);
        return -1;
    }
    int nodes = wide ? SPARSE_WIDE_NODES : tight;
    int ci = wide ? SPARSE_WIDE_NODES / 2 : rc + SPARSE_MARGIN; /* centre on a node */
    double xc = ci * h, w = SPARSE_OMEGA;
    /* counted first, then allocated once and filled */
    size_t n = sparse_points(NULL, rc, h, R, xc, w);
    t->x = malloc(2 * n * sizeof(double));
    t->v = malloc(2 * n * sizeof(double));
    t->vol = malloc(n * sizeof(double));
    if (!t->x || !t->v || !t->vol) {
        mpm_paper_free(t);
        snprintf(err, errlen, "out of memory for %zu particles", n);
        return -1;
    }
    sparse_points(t, rc, h, R, xc, w);
    t->mat[0] = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                    .youngs_modulus = 1.0,
                                    .poisson_ratio = 0.2,
                                    .density = 1.0};
    mpm_body_desc *b = &t->body[0];
    b->n_points = n;
    b->x = t->x;
    b->volume = t->vol;
    b->v = t->v;
    t->c.grid = (mpm_grid_desc){2, {0, 0}, {h, h}, {nodes, nodes}};
    t->c.n_materials = 1;
    t->c.materials = t->mat;
    t->c.n_bodies = 1;
    t->c.bodies = t->body;
    return 0;
}

/* Builds the case of a configuration into t (free with mpm_paper_free). */
static int build(const pb_cfg *c, mpm_paper *t, char *err, size_t errlen)
{
    long np = c->particles ? c->particles : pb_scene_default_particles(c->scene);
    int rc = 0;
    switch (c->scene) {
    case PB_DISKS2D: mpm_paper_disks(t, c->method, c->update, 1.0 / pb_disks_cells(np)); break;
    case PB_CUBE3D: rc = build_cube(c, t, err, errlen); break;
    case PB_BAR1D: {
        int ncell = (int)(np / 2 > 1 ? np / 2 : 1);
        int extra = (int)ceil(0.01 * ncell) + 2; /* the free end moves by up to v0 / omega */
        if (mpm_paper_bar(t, c->method, c->update, ncell, 2, extra, 0.0, BAR_V0)) {
            snprintf(err, errlen, "out of memory for %ld particles", np);
            rc = -1;
        }
        break;
    }
    case PB_SPARSE_WIDE:
    case PB_SPARSE_TIGHT: rc = build_sparse(c, c->scene == PB_SPARSE_WIDE, t, err, errlen); break;
    default: snprintf(err, errlen, "unknown scene %d", (int)c->scene); rc = -1;
    }
    if (!rc) {
        t->c.method = c->method;
        t->c.update = c->update;
        t->c.threads = c->threads;
        t->c.pic_fraction = c->pic;
        t->c.transfer = c->transfer;
        t->c.kernels = kernels_isa;
    }
    return rc;
}

/* ---- measuring ---- */

/* The warm-up and the timed runs of a built simulation (see the top). */
static int timed_runs(mpm_sim *sim, const pb_cfg *c, pb_row *r)
{
    long given = c->steps;
    long def = pb_default_steps(r->dim, r->method, r->particles);
    double dt = mpm_sim_dt(sim);
    if (dt > 0) { /* 1.25: room for dt to shrink as the speeds grow */
        double fit = scene_tmax(c->scene) / (1.25 * dt * (PB_RUNS + 1));
        if (fit < (double)def) {
            def = fit < 1 ? 1 : (long)fit;
            r->tcapped = 1;
        }
    }
    long steps = given ? given : def, k = 0;
    if (given) r->tcapped = 0;
    double w0 = pb_now(), wh = 0, wall[PB_RUNS], rate[PB_RUNS];
    long kh = 0;
    r->default_steps = def;
    while (k < steps) {
        int rc = mpm_sim_step(sim);
        if (rc) {
            snprintf(r->msg, sizeof r->msg, "warm-up step %ld: %s (%.200s)", k + 1,
                     mpm_strerror(rc), mpm_sim_error(sim)->message);
            return -1;
        }
        k++;
        double el = pb_now() - w0;
        if (!kh && el > PB_WARM_CAP_S / 2) { /* the speed is read from the second half */
            kh = k;
            wh = el;
        }
        if (!given && el > PB_WARM_CAP_S) break;
    }
    if (k < steps) {
        double el = pb_now() - w0;
        double rate_steps = k > kh && el > wh ? (double)(k - kh) / (el - wh) : (double)k / el;
        long s2 = (long)(rate_steps * PB_RUN_S);
        steps = s2 < 1 ? 1 : s2;
        r->reduced = 1;
    }
    r->steps = steps;
    double c0 = pb_cpu_self(), wsum = 0;
    for (int i = 0; i < PB_RUNS; i++) {
        double t0 = pb_now();
        int rc = mpm_sim_run(sim, steps);
        wall[i] = pb_now() - t0;
        wsum += wall[i];
        if (rc) {
            snprintf(r->msg, sizeof r->msg, "timed run %d: %s (%.200s)", i + 1, mpm_strerror(rc),
                     mpm_sim_error(sim)->message);
            return -1;
        }
        rate[i] = (double)r->particles * (double)steps / (wall[i] > 0 ? wall[i] : 1e-9) / 1e6;
    }
    r->cpus = wsum > 0 ? (pb_cpu_self() - c0) / wsum : 0;
    r->runs = PB_RUNS;
    r->wall_s = pb_median(wall, PB_RUNS);
    r->mpsteps = pb_median(rate, PB_RUNS);
    r->rate_lo = r->rate_hi = rate[0];
    for (int i = 1; i < PB_RUNS; i++) {
        r->rate_lo = fmin(r->rate_lo, rate[i]);
        r->rate_hi = fmax(r->rate_hi, rate[i]);
    }
    return 0;
}

/* The collapse scenes' case (scenes/include/mpm_collapse.h) for c, in *cc: a =
 * 2, 2 x 2 particles per cell, cells across the column for about the
 * aimed particle count (4 a cells^2 particles), Drucker-Prager
 * (plane-strain match, phi 30) or linear elasticity with the same
 * geostatic start, base friction mu = tan 30 and the x_lo roller in both.
 * Also bench-inproc's side.c (which includes this file) builds the pair
 * with it where the tree defines PB_COLLAPSE_CASE.  Returns 0, or -1 with
 * err filled (out of memory). */
#define PB_COLLAPSE_CASE 1
static int collapse_case(const pb_cfg *c, mpm_collapse_case *cc, char *err, size_t n)
{
    long np = c->particles ? c->particles : pb_scene_default_particles(c->scene);
    mpm_collapse_cfg cfg = {.a = 2,
                            .cells = (int)lround(sqrt((double)np / 8.0)),
                            .method = c->method,
                            .model = c->scene == PB_COLLAPSE_DP ? MPM_MODEL_DRUCKER_PRAGER
                                                                : MPM_MODEL_LINEAR_ELASTIC,
                            .threads = c->threads};
    if (cfg.cells < 4) cfg.cells = 4;
    if (mpm_collapse_setup(&cfg, cc)) {
        snprintf(err, n, "out of memory for %ld particles", np);
        return -1;
    }
    cc->c.update = c->update;
    cc->c.pic_fraction = c->pic;
    cc->c.transfer = c->transfer;
    cc->c.kernels = kernels_isa;
    return 0;
}

/* The collapse scenes' row: collapse_case(), then the timed runs. */
static int work_collapse(const pb_cfg *c, pb_row *r)
{
    mpm_collapse_case cc;
    double t0 = pb_now();
    if (collapse_case(c, &cc, r->msg, sizeof r->msg)) return -1;
    mpm_error me;
    mpm_sim *sim = mpm_sim_new(&cc.c, NULL, &me);
    if (!sim) {
        char err[256];
        snprintf(r->msg, sizeof r->msg, "mpm_sim_new: %.200s",
                 mpm_error_text(&me, MPM_FIELD_PROTO, err, sizeof err));
        mpm_collapse_free(&cc);
        return -1;
    }
    r->setup_s = pb_now() - t0;
    r->dim = mpm_sim_dim(sim);
    r->particles = mpm_sim_particles(sim);
    r->nodes = mpm_sim_nodes(sim);
    mpm_traffic tr;
    r->traffic_b = mpm_sim_traffic(sim, &tr) ? 0 : tr.total;
    int rc = timed_runs(sim, c, r);
    mpm_sim_destroy(&sim);
    mpm_collapse_free(&cc);
    return rc;
}

/* The child's work for one in-process configuration. */
static int work_scene(void *arg, pb_row *r)
{
    const pb_cfg *c = arg;
    if (c->scene == PB_COLLAPSE_DP || c->scene == PB_COLLAPSE_EL) return work_collapse(c, r);
    mpm_paper t;
    char err[256] = "";
    double t0 = pb_now();
    if (build(c, &t, err, sizeof err)) {
        snprintf(r->msg, sizeof r->msg, "%s", err);
        return -1;
    }
    mpm_error me;
    mpm_sim *sim = mpm_sim_new(&t.c, NULL, &me);
    if (!sim) {
        snprintf(r->msg, sizeof r->msg, "mpm_sim_new: %.200s",
                 mpm_error_text(&me, MPM_FIELD_PROTO, err, sizeof err));
        mpm_paper_free(&t);
        return -1;
    }
    r->setup_s = pb_now() - t0;
    r->dim = mpm_sim_dim(sim);
    r->particles = mpm_sim_particles(sim);
    r->nodes = mpm_sim_nodes(sim);
    mpm_traffic tr;
    r->traffic_b = mpm_sim_traffic(sim, &tr) ? 0 : tr.total;
    int rc = timed_runs(sim, c, r);
    mpm_sim_destroy(&sim);
    mpm_paper_free(&t);
    return rc;
}

int pb_measure(const pb_cfg *c, pb_row *row)
{
    memset(row, 0, sizeof *row);
    snprintf(row->scene, sizeof row->scene, "%s%s%s", pb_scene_name(c->scene),
             c->transfer == MPM_TRANSFER_APIC ? "+apic" : "", PB_SUFFIX);
    row->method = c->method;
    row->update = c->update;
    row->threads = c->threads;
    row->dim = pb_scene_dim(c->scene);
    return pb_in_child(work_scene, (void *)c, row);
}

/* ---- the forked child ---- */

int pb_write_all(int fd, const void *buf, size_t n)
{
    const char *p = buf;
    while (n) {
        ssize_t w = write(fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return -1;
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

size_t pb_read_all(int fd, void *buf, size_t n)
{
    char *p = buf;
    size_t got = 0;
    while (got < n) {
        ssize_t r = read(fd, p + got, n - got);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) break;
        got += (size_t)r;
    }
    return got;
}

int pb_in_child(pb_work_fn fn, void *arg, pb_row *row)
{
    int fds[2];
    if (pipe(fds)) {
        snprintf(row->msg, sizeof row->msg, "pipe: %s", strerror(errno));
        return row->rc = -1;
    }
    fflush(NULL); /* nothing buffered may be written twice */
    pid_t pid = fork();
    if (pid < 0) {
        snprintf(row->msg, sizeof row->msg, "fork: %s", strerror(errno));
        close(fds[0]);
        close(fds[1]);
        return row->rc = -1;
    }
    if (pid == 0) {
        close(fds[0]);
        pb_row r = *row;
        r.rc = fn ? fn(arg, &r) : 0;
        int bad = pb_write_all(fds[1], &r, sizeof r);
        close(fds[1]);
        _exit(bad ? 1 : 0);
    }
    close(fds[1]);
    pb_row got;
    size_t n = pb_read_all(fds[0], &got, sizeof got);
    close(fds[0]);
    int st = 0;
    struct rusage ru;
    memset(&ru, 0, sizeof ru);
    pid_t w;
    while ((w = wait4(pid, &st, 0, &ru)) < 0 && errno == EINTR) {
    }
    if (w < 0) {
        snprintf(row->msg, sizeof row->msg, "wait4: %s", strerror(errno));
        return row->rc = -1;
    }
    if (n != sizeof got) {
        if (WIFSIGNALED(st))
            snprintf(row->msg, sizeof row->msg, "the measuring child was killed by signal %d (%s)",
                     WTERMSIG(st), strsignal(WTERMSIG(st)));
        else
            snprintf(row->msg, sizeof row->msg,
                     "the measuring child exited with status %d "
                     "without a result",
                     WIFEXITED(st) ? WEXITSTATUS(st) : -1);
        return row->rc = -1;
    }
    *row = got;
    row->rss_kb = ru.ru_maxrss;
    row->bytes_pp = row->particles ? (double)ru.ru_maxrss * 1024.0 / (double)row->particles : 0;
    return row->rc;
}

long pb_baseline_rss_kb(void)
{
    pb_row r;
    memset(&r, 0, sizeof r);
    if (pb_in_child(NULL, NULL, &r)) return -1;
    return r.rss_kb;
}
