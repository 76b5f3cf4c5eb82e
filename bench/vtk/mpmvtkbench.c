/*
 * mpmvtkbench.c - the VTK writer's cost (`make bench-vtk`): a synthetic
 * snapshot of N particles (default 10^6; positions, velocities, stress,
 * pressure, volume, and with --all plastic strain, F and the yield flag)
 * written as .vtp in each encoding mpmctl offers (raw, base64, zlib,
 * ascii), with the file size, the wall time of each write (to the page
 * cache, as mpmctl writes) and its CPU time (all threads; on a shared
 * machine the steadier figure); the best of --repeat runs.  A benchmark,
 * not a test: the figures are printed, nothing is asserted.  The files go
 * to --dir (default build/bench) and are removed unless --keep.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include "ctl_vtk.h" /* mpmctl's writer, not a library */

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* CPU seconds of the process (every thread): what the write costs on a
 * machine shared with other work, where the wall time says little. */
static double cpu_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static void usage(void)
{
    printf("usage: mpmvtkbench [--n N] [--dim 2|3] [--all] [--dir DIR] [--repeat R] [--keep]\n"
           "       [--skip-ascii]\n");
}

int main(int argc, char **argv)
{
    size_t n = 1000000;
    int dim = 2, all = 0, keep = 0, repeat = 3, skip_ascii = 0;
    const char *dir = "build/bench";
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--n") && i + 1 < argc)
            n = (size_t)strtod(argv[++i], NULL);
        else if (!strcmp(argv[i], "--dim") && i + 1 < argc)
            dim = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--dir") && i + 1 < argc)
            dir = argv[++i];
        else if (!strcmp(argv[i], "--repeat") && i + 1 < argc)
            repeat = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--all"))
            all = 1;
        else if (!strcmp(argv[i], "--keep"))
            keep = 1;
        else if (!strcmp(argv[i], "--skip-ascii"))
            skip_ascii = 1;
        else {
            usage();
            return strcmp(argv[i], "--help") ? 2 : 0;
        }
    }
    if (n < 1 || n > 100000000 || dim < 1 || dim > 3 || repeat < 1) {
        usage();
        return 2;
    }
    size_t d = (size_t)dim;
    double *x = malloc(n * d * sizeof *x), *v = malloc(n * d * sizeof *v);
    double *st = malloc(n * 6 * sizeof *st), *p = malloc(n * sizeof *p),
           *vol = malloc(n * sizeof *vol);
    double *ep = all ? malloc(n * sizeof *ep) : NULL,
           *F = all ? malloc(n * d * d * sizeof *F) : NULL;
    int *y = all ? malloc(n * sizeof *y) : NULL;
    if (!x || !v || !st || !p || !vol || (all && (!ep || !F || !y))) {
        fprintf(stderr, "mpmvtkbench: out of memory\n");
        return 1;
    }
    /* values that do not compress to nothing: smooth fields with noise */
    unsigned long long r = 88172645463325252ull;
    for (size_t i = 0; i < n; i++) {
        for (size_t k = 0; k < d; k++) {
            r ^= r << 13, r ^= r >> 7, r ^= r << 17;
            x[i * d + k] = (double)(i % 1000) * 1e-3 + (double)(r >> 11) * 0x1p-53 * 1e-4;
            v[i * d + k] = sin((double)i * 1e-3 + (double)k);
        }
        for (size_t k = 0; k < 6; k++) st[i * 6 + k] = cos((double)i * 1e-4 * (double)(k + 1));
        p[i] = (st[i * 6] + st[i * 6 + 1] + st[i * 6 + 2]) / 3;
        vol[i] = 1e-6 * (1 + 1e-3 * sin((double)i));
        if (all) {
            ep[i] = i % 7 ? 0 : 1e-3 * (double)(i % 13);
            y[i] = i % 7 == 0;
            for (size_t k = 0; k < d * d; k++)
                F[i * d * d + k] = (k % (d + 1) == 0) + 1e-3 * v[i * d];
        }
    }
    mpp_snapshot s = {.step = 1000,
                      .t = 0.125,
                      .n = n,
                      .dim = dim,
                      .x = x,
                      .v = v,
                      .stress = st,
                      .pressure = p,
                      .volume = vol,
                      .plastic_strain = ep,
                      .deformation_gradient = F,
                      .yielded = y};
    mkdir(dir, 0777);
    printf("mpmvtkbench: %zu particles, %dD, fields x v stress pressure volume%s\n", n, dim,
           all ? " plastic_strain deformation_gradient yielded" : "");
    printf("%-8s %12s %10s %10s %10s\n", "format", "bytes", "MB", "write s", "cpu s");
    for (int e = 0; e < 4; e++) {
        char path[1024];
        double best = INFINITY, best_cpu = INFINITY;
        struct stat sb;
        if (e == CTL_VTK_ASCII && skip_ascii) continue;
        snprintf(path, sizeof path, "%s/vtkbench_%s.vtp", dir, ctl_vtk_enc_name((ctl_vtk_enc)e));
        for (int k = 0; k < (e == CTL_VTK_ASCII ? 1 : repeat); k++) {
            double t0 = now_s(), c0 = cpu_s();
            if (ctl_vtk_write_vtp(path, &s, (ctl_vtk_enc)e)) return 1;
            double dt = now_s() - t0, dc = cpu_s() - c0;
            if (dt < best) best = dt;
            if (dc < best_cpu) best_cpu = dc;
        }
        if (stat(path, &sb)) return 1;
        printf("%-8s %12lld %10.1f %10.3f %10.3f\n", ctl_vtk_enc_name((ctl_vtk_enc)e),
               (long long)sb.st_size, (double)sb.st_size / 1e6, best, best_cpu);
        if (!keep) remove(path);
    }
    free(x), free(v), free(st), free(p), free(vol), free(ep), free(F), free(y);
    return 0;
}
