/*
 * mpmrun.c - runs one of the GMPM paper's verification cases in-process
 * with the solver library and shows it live: a progress line with ETA, the
 * energies every N steps, and a summary that compares with the analytic
 * solution where there is one.  It needs no daemon; it is the quickest way
 * to see the solver work and to try a method, update scheme or time step.
 */
#include "mpm.h"
#include "mpm_diag.h"
#include "mpm_paper.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static const char *usage =
    "usage: mpmrun [options]\n"
    "Runs a verification case of the GMPM paper in-process and shows it live.\n"
    "  --case NAME     point | bar-mpm | bar-gimp | disks-coarse | disks-fine\n"
    "                  (default disks-fine)\n"
    "  --method M      mpm | gimp | bspline2 | bspline3 | cpdi (default: the case's)\n"
    "  --update U      usf | usl | musl (default usf)\n"
    "  --transfer T    flip | apic (default flip)\n"
    "  --dt DT         fixed time step (default 0.001; 0 = automatic from CFL)\n"
    "  --cfl C         Courant factor for automatic dt (default 0.5)\n"
    "  --t-end T       end time (default: the case's)\n"
    "  --every N       print energies every N steps (default: 20 lines a run)\n"
    "  --threads T     solver threads (default 1)\n"
    "  --plan TEXT     force fast-path variants: key=value pairs of the plan's text\n"
    "                  (printed at the start; e.g. 'kernels=portable fuse=off')\n"
    "  --csv           print the energy series as CSV (step,t,kinetic,strain,total)\n"
    "  -h, --help      this text\n";

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static int parse_double(const char *opt, const char *s, double lo, double *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (errno || end == s || *end || !isfinite(v) || v < lo) {
        fprintf(stderr, "mpmrun: %s: expected a number >= %g, got '%s'\n", opt, lo, s);
        return -1;
    }
    *out = v;
    return 0;
}

int main(int argc, char **argv)
{
    const char *cname = "disks-fine", *method = NULL, *update = "usf", *transfer = "flip";
    const char *plan = NULL;
    double dt = 1e-3, cfl = 0, tend = -1, every = 0, threads = 1;
    int csv = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            fputs(usage, stdout);
            return 0;
        }
        if (!strcmp(a, "--csv")) {
            csv = 1;
            continue;
        }
        if (i + 1 >= argc) {
            fprintf(stderr, "mpmrun: %s needs a value (see --help)\n", a);
            return 2;
        }
        const char *v = argv[++i];
        int rc = 0;
        if (!strcmp(a, "--case"))
            cname = v;
        else if (!strcmp(a, "--method"))
            method = v;
        else if (!strcmp(a, "--update"))
            update = v;
        else if (!strcmp(a, "--transfer"))
            transfer = v;
        else if (!strcmp(a, "--plan"))
            plan = v;
        else if (!strcmp(a, "--dt"))
            rc = parse_double(a, v, 0, &dt);
        else if (!strcmp(a, "--cfl"))
            rc = parse_double(a, v, 0, &cfl);
        else if (!strcmp(a, "--t-end"))
            rc = parse_double(a, v, 0, &tend);
        else if (!strcmp(a, "--every"))
            rc = parse_double(a, v, 1, &every);
        else if (!strcmp(a, "--threads"))
            rc = parse_double(a, v, 1, &threads);
        else {
            fprintf(stderr, "mpmrun: unknown option '%s' (see --help)\n", a);
            return 2;
        }
        if (rc) return 2;
    }
    int upi = mpm_update_parse(update);
    if (upi < 0) {
        fprintf(stderr, "mpmrun: --update: expected usf, usl or musl, got '%s'\n", update);
        return 2;
    }
    mpm_update up = (mpm_update)upi;

    mpm_paper P;
    int kind; /* 0 point, 1 bar, 2 disks */
    double v0 = 0.1;
    if (!strcmp(cname, "point")) {
        kind = 0;
        mpm_paper_point(&P, up, dt, v0);
        if (tend < 0) tend = 3.0;
    } else if (!strcmp(cname, "bar-mpm") || !strcmp(cname, "bar-gimp")) {
        kind = 1;
        int gimp = !strcmp(cname, "bar-gimp");
        if (mpm_paper_bar(&P, gimp ? MPM_METHOD_GIMP : MPM_METHOD_MPM, up, gimp ? 13 : 7, 1, 0, dt,
                          v0)) {
            fprintf(stderr, "mpmrun: out of memory\n");
            return 1;
        }
        if (tend < 0) tend = 2 * 2 * M_PI / mpm_paper_bar_omega();
    } else if (!strcmp(cname, "disks-coarse") || !strcmp(cname, "disks-fine")) {
        kind = 2;
        mpm_paper_disks(&P, MPM_METHOD_GIMP, up, strcmp(cname, "disks-fine") ? 0.1 : 0.025);
        P.c.dt = dt;
        if (tend < 0) tend = 4.0;
    } else {
        fprintf(stderr,
                "mpmrun: --case: unknown case '%s' (point, bar-mpm, bar-gimp, "
                "disks-coarse, disks-fine)\n",
                cname);
        return 2;
    }
    int mm = method ? mpm_method_parse(method) : (int)P.c.method;
    if (mm < 0) {
        fprintf(stderr,
                "mpmrun: --method: expected mpm, gimp, bspline2, bspline3 or cpdi, got '%s'\n",
                method);
        mpm_paper_free(&P);
        return 2;
    }
    P.c.method = (mpm_method)mm;
    int tr = mpm_transfer_parse(transfer);
    if (tr < 0) {
        fprintf(stderr, "mpmrun: --transfer: expected flip or apic, got '%s'\n", transfer);
        mpm_paper_free(&P);
        return 2;
    }
    P.c.transfer = (mpm_transfer)tr;
    P.c.cfl = cfl;
    P.c.threads = (int)threads;

    char err[512];
    mpm_error me;
    const char *mname = mpm_method_name(P.c.method);
    mpm_sim *s = mpm_sim_new(&P.c, NULL, &me);
    mpm_paper_free(&P);
    if (!s) {
        fprintf(stderr, "mpmrun: invalid case: %s\n",
                mpm_error_text(&me, MPM_FIELD_PROTO, err, sizeof err));
        return 1;
    }
    if (plan && mpm_sim_plan_override(s, plan, &me)) {
        fprintf(stderr, "mpmrun: --plan: %s\n",
                mpm_error_text(&me, MPM_FIELD_PROTO, err, sizeof err));
        mpm_sim_destroy(&s);
        return 2;
    }
    long nsteps = (long)ceil(tend / mpm_sim_dt(s) - 1e-9);
    long step_every = every > 0 ? (long)every : (nsteps / 20 > 0 ? nsteps / 20 : 1);
    int tty = isatty(STDERR_FILENO);
    printf("# case %s: %s %s, %zu particles, %zu nodes, dt %g, t_end %g (%ld steps)\n", cname,
           mname, update, mpm_sim_particles(s), mpm_sim_nodes(s), mpm_sim_dt(s), tend, nsteps);
    char ptext[MPM_PLAN_LEN];
    mpm_sim_plan(s, ptext, sizeof ptext);
    printf("# plan: %s\n", ptext);
    if (csv)
        printf("step,t,kinetic,strain,total\n");
    else
        printf("%8s %10s %13s %13s %13s\n", "step", "t", "kinetic", "strain", "total");

    mpm_energy e0, e;
    mpm_sim_energy(s, &e0);
    double err_max = 0, t0 = now(), last_draw = 0;
    int rc = 0;
    while (mpm_sim_time(s) < tend - 1e-12) {
        if ((rc = mpm_sim_step(s))) break;
        long k = mpm_sim_steps(s);
        double t = mpm_sim_time(s);
        if (kind != 2) {
            mpm_sim_energy(s, &e);
            double vn = e.momentum[0] / e.mass;
            double va = kind == 0 ? mpm_paper_point_v(v0, t) : mpm_paper_bar_vcm(v0, t);
            err_max = fmax(err_max, fabs(va - vn) / (1 + fabs(va))); /* Eq. 38 */
        }
        if (csv || k % step_every == 0) {
            mpm_sim_energy(s, &e);
            if (tty && !csv) fputs("\r\033[K", stderr);
            if (csv)
                printf("%ld,%.9g,%.9e,%.9e,%.9e\n", k, t, e.kinetic, e.strain, e.total);
            else
                printf("%8ld %10.4f %13.6e %13.6e %13.6e\n", k, t, e.kinetic, e.strain, e.total);
            fflush(stdout);
        }
        double w = now() - t0;
        if (tty && !csv && w - last_draw > 0.1) {
            last_draw = w;
            double frac = t / tend, eta = frac > 0 ? w * (1 - frac) / frac : 0;
            int bar = (int)(30 * frac);
            fprintf(stderr, "\r\033[K[%.*s%*s] %5.1f%%  step %ld  t %.4f  ETA %.1f s", bar,
                    "##############################", 30 - bar, "", 100 * frac, k, t, eta);
        }
    }
    double wall = now() - t0;
    if (tty && !csv) fputs("\r\033[K", stderr);
    mpm_sim_energy(s, &e);
    long k = mpm_sim_steps(s);
    printf("# %s after %ld steps, t = %.6g, wall %.3f s, %.3g particle-steps/s\n",
           rc ? "stopped" : "finished", k, mpm_sim_time(s), wall,
           wall > 0 ? (double)k * mpm_sim_particles(s) / wall : 0.0);
    printf("# total energy %.6e -> %.6e (%+.3f%%), momentum (%.2e, %.2e)\n", e0.total, e.total,
           100 * (e.total - e0.total) / e0.total, e.momentum[0], e.momentum[1]);
    if (kind != 2) printf("# max Eq. 38 error of the centre-of-mass velocity: %.3e\n", err_max);
    mpm_plastic_stats ps; /* the paper's cases are elastic: printed only if a case yields */
    mpm_sim_plastic_stats(s, &ps);
    if (ps.updates)
        printf(
            "# plastic updates %lld, substeps %lld (%.3g per update, max %d), plastic work %.6e\n",
            ps.updates, ps.substeps, (double)ps.substeps / (double)ps.updates, ps.max_substeps,
            e.plastic_work);
    if (rc)
        fprintf(stderr, "mpmrun: %s\n",
                mpm_error_text(mpm_sim_error(s), MPM_FIELD_PROTO, err, sizeof err));
    mpm_sim_destroy(&s);
    return rc ? 1 : 0;
}
