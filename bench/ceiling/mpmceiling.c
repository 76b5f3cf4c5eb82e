/*
 * mpmceiling.c - bin/mpmceiling, the solver's ceiling.  How fast does a 2D
 * MPM USF step in double precision run on this CPU when it does nothing
 * but the step's arithmetic?  It runs the lean step of ceiling.c (the
 * disks2d scene of bin/mpmbench, the solver's fused USF step without its
 * checks, energies, conditions and threads) with the four-lane kernels
 * where the CPU has AVX2 and FMA, else the portable ones, and prints the
 * median rate of its rounds.  So it bounds from above what a kernel of
 * the solver's design reaches on one thread, and bin/mpmbench's rate
 * against it is the price of the solver's generality
 * (bench/ceiling/ceiling.sh, `make bench-ceiling`, prints both, alternated).
 * --check runs both kernel sets from one start and compares them.
 */
#include "ceiling.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* --check's limit on the kernels' differences (of each field's scale),
 * at t = CL_CHECK_T (the disks touch at t = 2.1) */
#define CL_CHECK_TOL 1e-10
#define CL_CHECK_T 2.6

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* --check: both kernels from the same start to t = 2.6 (the disks touch
 * at t = 2.1: half a unit of time in contact, stresses of order 0.01),
 * the particles' largest differences; the sorts come at the same steps
 * when both kernels count the same runs */
static int check(long want)
{
    const cl_kernels *k4 = cl_kernels_avx2();
    if (!k4) {
        printf("check: no four-lane kernels on this CPU or build; nothing to compare\n");
        return 0;
    }
    cl_diff d;
    if (cl_compare(cl_kernels_portable(), k4, want, CL_CHECK_T, &d)) {
        fprintf(stderr, "mpmceiling: out of memory for %ld particles\n", want);
        return 1;
    }
    /* round-off (fused multiply-adds, the lanes' sums in another order)
     * grown over the steps: CL_CHECK_TOL of each field's scale */
    int ok = d.dx <= CL_CHECK_TOL && d.dv <= CL_CHECK_TOL && d.ds <= CL_CHECK_TOL &&
             d.sorts[0] == d.sorts[1] && d.sorts[0] > 0;
    printf("check: %zu particles, %ld steps (t = %.2f), portable against %s: largest difference "
           "in x %.2e, in v %.2e of |v|max, in sigma %.2e of |sigma|max (limit %.0e each); sorts "
           "%ld and %ld; E_k %.12e and %.12e: %s\n",
           d.n, d.steps, d.t, k4->name, d.dx, d.dv, d.ds, CL_CHECK_TOL, d.sorts[0], d.sorts[1],
           d.ek[0], d.ek[1], ok ? "ok" : "FAILED");
    return !ok;
}

static void usage(FILE *f)
{
    fprintf(
        f,
        "usage: mpmceiling [--particles N | --cells N] [--steps S] [--rounds R] [--portable] [--csv]\n"
        "       mpmceiling --check [--particles N]\n"
        "The solver's ceiling: bin/mpmbench's disks2d (2D MPM USF, FLIP, linear elastic) with a\n"
        "step that does nothing but its arithmetic (no checks, energies, boundary conditions or\n"
        "threads): how fast a double-precision step of the solver's design can run on this CPU.\n"
        "Options:\n"
        "  --particles N  particles to aim for, 1000..10^8 (default 10^6)\n"
        "  --cells N      the grid's cells per axis instead, 8..10^5 (mpmrun's disks-fine: 40)\n"
        "  --steps S      steps per timed round, 1..10^6 (default: 60 at 10^6 particles, more\n"
        "                 below, as long as the disks stay apart from the walls)\n"
        "  --rounds R     timed rounds after one warm-up round, 1..100 (default 5)\n"
        "  --portable     the portable kernels even where AVX2 and FMA are there\n"
        "  --csv          one CSV row: particles,kernels,steps,rounds,median_mpsteps,min,max,sort_share\n"
        "  --check        the portable and four-lane kernels from one start to t = 2.6 (the\n"
        "                 disks in contact): the largest differences (exit 1 beyond round-off);\n"
        "                 with --particles (default 10^4 here)\n"
        "The rate is particle-steps per second, the median of the rounds; 1 thread.\n");
}

static int arg_long(const char *opt, const char *s, long lo, long hi, long *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (errno || end == s || *end || v != floor(v) || v < (double)lo || v > (double)hi) {
        fprintf(stderr, "mpmceiling: %s must be a whole number in %ld..%ld, not '%s'\n", opt, lo,
                hi, s);
        return -1;
    }
    *out = (long)v;
    return 0;
}

int main(int argc, char **argv)
{
    long want = 1000000, steps = 0, rounds = 5, cells = 0;
    int use_portable = 0, csv = 0, do_check = 0, want_set = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            usage(stdout);
            return 0;
        } else if (!strcmp(a, "--portable")) {
            use_portable = 1;
        } else if (!strcmp(a, "--csv")) {
            csv = 1;
        } else if (!strcmp(a, "--check")) {
            do_check = 1;
        } else if (i + 1 < argc && !strcmp(a, "--particles")) {
            if (arg_long(a, argv[++i], 1000, 100000000, &want)) return 2;
            want_set = 1;
        } else if (i + 1 < argc && !strcmp(a, "--cells")) {
            if (arg_long(a, argv[++i], 8, 100000, &cells)) return 2;
        } else if (i + 1 < argc && !strcmp(a, "--steps")) {
            if (arg_long(a, argv[++i], 1, 1000000, &steps)) return 2;
        } else if (i + 1 < argc && !strcmp(a, "--rounds")) {
            if (arg_long(a, argv[++i], 1, 100, &rounds)) return 2;
        } else {
            fprintf(stderr, "mpmceiling: unknown or incomplete option '%s' (--help lists them)\n",
                    a);
            return 2;
        }
    }
    if (do_check) return check(want_set ? want : 10000);
    const cl_kernels *k = use_portable ? NULL : cl_kernels_avx2();
    if (!k) k = cl_kernels_portable();
    cl_case c;
    if (cl_case_new(&c, want, (int)cells)) {
        fprintf(stderr, "mpmceiling: out of memory for %ld particles\n", want);
        cl_case_free(&c);
        return 1;
    }
    if (!steps) { /* about 6 * 10^7 particle-steps a round (2 s at 30 M
                   * p-steps/s), and every round before t = 3.5: the disks,
                   * 0.43 apart and closing at 0.2, bounce at t = 2.1 and
                   * reach the walls after t = 4 */
        steps = (long)(6e7 / (double)c.P.n);
        long cap = (long)(3.5 / (c.g.dt * (double)(rounds + 1)));
        if (steps > cap) steps = cap;
        if (steps < 1) steps = 1;
    }
    double ek0, px, py;
    cl_totals(&c.P, &ek0, &px, &py);
    cl_run(&c, k, steps); /* warm-up */
    double rate[100] = {0}, t_all = 0, sort0 = c.t_sort;
    for (long r = 0; r < rounds; r++) {
        double t0 = cl_now();
        cl_run(&c, k, steps);
        double t = cl_now() - t0;
        t_all += t;
        rate[r] = (double)c.P.n * (double)steps / t / 1e6;
    }
    double sort_share = (c.t_sort - sort0) / t_all;
    qsort(rate, (size_t)rounds, sizeof rate[0], cmp_d);
    double med = rounds % 2 ? rate[rounds / 2] : 0.5 * (rate[rounds / 2 - 1] + rate[rounds / 2]);
    double ek1;
    cl_totals(&c.P, &ek1, &px, &py);
    if (csv)
        printf("%zu,%s,%ld,%ld,%.3f,%.3f,%.3f,%.4f\n", c.P.n, k->name, steps, rounds, med, rate[0],
               rate[rounds - 1], sort_share);
    else
        printf("mpmceiling: %zu particles, %s kernels, %ld steps x %ld rounds (dt %.6g, t = %.4f): "
               "%.2f M p-steps/s (%.2f..%.2f), sorts %.1f %% of the time; E_k %.9e -> %.9e, "
               "momentum (%.1e, %.1e)\n",
               c.P.n, k->name, steps, rounds, c.g.dt, (double)(steps * (rounds + 1)) * c.g.dt, med,
               rate[0], rate[rounds - 1], 100 * sort_share, ek0, ek1, px, py);
    cl_case_free(&c);
    return 0;
}
