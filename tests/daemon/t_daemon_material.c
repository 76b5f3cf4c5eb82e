/*
 * t_daemon_material.c - the material models' per-particle snapshot fields through
 * the daemon: the example impact2d_j2 (an elastic disk into a von Mises
 * block) run by mpmd with recorded snapshots of X, PLASTIC_STRAIN and
 * YIELDED (and PRESSURE), read back with `mpmctl snapshot` as CSV: the columns are
 * there, the plastic strains equal the solver's in-process ones, only the
 * J2 body's particles carry plastic strain, and a DEFORMATION_GRADIENT the
 * run lacks is left out.
 */
#include "mpm.h"
#include "t.h"
#include "t_daemon.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mpp_case.h"

DTEST(daemon_material_snapshot_fields)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", NULL};
    char dir[300], path[400], csv[400], err[T_ERRLEN];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    snprintf(path, sizeof path, "%s/j2.json", tmp);
    snprintf(csv, sizeof csv, "%s/snap.csv", tmp);
    size_t len = 0;
    char *text = td_slurp("proto/examples/impact2d_j2.json", &len);
    CHECK(text);
    /* 200 steps, the last snapshot recorded; F asked for but absent */
    char *p = strstr(text, "\"endTime\": 0.1");
    CHECK(p);
    memcpy(p, "\"steps\": \"200\"", 14);
    char *q = strstr(text, "\"YIELDED\"");
    CHECK(q);
    size_t nt = strlen(text) + 64;
    char *t2 = malloc(nt);
    CHECK(t2);
    snprintf(t2, nt, "%.*s\"DEFORMATION_GRADIENT\", %s", (int)(q - text), text, q);
    free(text);
    int wr = td_write(path, t2);
    mpp_case *sc = NULL;
    int lr = td_case_load(t2, strlen(t2), &sc, err, sizeof err);
    free(t2);
    CHECK(wr == 0);
    CHECKF(lr == 0, "%s", err);
    mpm_error me;
    mpm_sim *sim = mpm_sim_new(&sc->c, &sc->info, &me);
    mpp_case_destroy(&sc);
    CHECK(sim);
    int rc = mpm_sim_run(sim, 200);
    size_t n = mpm_sim_particles(sim);
    double *ep = calloc(n, sizeof(double));
    if (!rc && ep) mpm_sim_snapshot(sim, &(mpm_snapshot){.plastic_strain = ep});
    mpm_sim_destroy(&sim);
    if (rc || !ep) free(ep);
    CHECK(rc == 0 && ep);

    if (td_start(&d, dir, extra)) {
        free(ep);
        return;
    }
    int ok = td_ctl(&d, 120, &o, "submit", path, "--watch", NULL) == 0 && o.status == 0;
    td_out_free(&o);
    ok = ok && td_ctl(&d, 30, &o, "snapshot", "1", "-o", csv, NULL) == 0 && o.status == 0;
    td_out_free(&o);
    td_stop(&d);
    size_t sl = 0;
    char *st = ok ? td_slurp(csv, &sl) : NULL;
    char **lines = NULL;
    size_t nl = st ? td_lines(st, &lines) : 0;
    double worst = 0;
    size_t plastic = 0, bad = 0, nb = 0;
    char head[64] = "";
    if (nl) snprintf(head, sizeof head, "%s", lines[0]);
    int header = !strcmp(head, "i,x,y,pressure,mean_stress,plastic_strain,yielded");
    for (size_t i = 0; header && i + 1 < nl && i < n; i++) {
        size_t k;
        double x, y, pr, mean, e;
        int yl;
        if (sscanf(lines[i + 1], "%zu,%lf,%lf,%lf,%lf,%lf,%d", &k, &x, &y, &pr, &mean, &e, &yl) !=
                7 ||
            k != i || (yl != 0 && yl != 1) || mean != -pr) {
            bad++;
            continue;
        }
        worst = fmax(worst, fabs(e - ep[i]));
        plastic += e > 0;
        /* the block's 64 x 24 particles come first (bodies in order); the
         * disk's are elastic */
        if (i >= 64 * 24 && e != 0) nb++;
    }
    free(lines);
    free(st);
    free(ep);
    CHECKF(ok, "submit or snapshot failed");
    CHECKF(header && nl == n + 1, "CSV: %zu lines for %zu particles, header %s", nl, n, head);
    TLOG("snapshot of %zu particles: %zu with plastic strain, max difference from in-process "
         "%.3g",
         n, plastic, worst);
    CHECK(bad == 0 && nb == 0);
    CHECK(plastic > 0);
    CHECK(worst <= 1e-12);
}
