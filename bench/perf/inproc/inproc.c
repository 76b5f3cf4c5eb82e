/*
 * inproc.c - the driver of `make bench-inproc REF=<commit>` (inproc.sh):
 * one configuration of the bench's scenes built twice in one process, on
 * REF's solver and on this tree's (side.c), and run in alternation: after
 * `skip` untimed steps of each (the collapse column's flowing phase) and a
 * warm-up run of each, `rounds` rounds of `steps` steps, REF first in the
 * even rounds and this tree first in the odd ones.  Both simulations
 * stay resident, on the same CPUs, caches and memory, so a drift of the
 * machine over seconds falls on both sides of a round alike, which
 * processes run one after the other (make bench-compare) cannot promise.
 * How it works: the notes after the includes.
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "perf/perf.h" /* the STREAM triad (triad.c) */
#include "side.h"

/*
 * One process is not enough: a build can run at one speed for a process's
 * whole life and at a clearly different one in the next (sometimes for
 * several processes in a row), with a triad measured beside it that does
 * not tell the two apart (docs/performance.md).  So the rounds run in
 * `procs` forked children one after the other, each building both
 * simulations afresh; the row pools the rounds of all of them and gives
 * each process's median ratio with the STREAM triad (triad.c) measured
 * before and after its rounds, so that a reader sees the spread.
 *
 * Prints one row: each side's median M particle-steps/s, the median of the
 * rounds' own ratios new / ref, their quartiles and extremes, in how many
 * rounds the new side was faster, and each process's median ratio @ its
 * triad (GB/s, the mean of before and after).  Exits 0; 3 when REF's tree has
 * no such scene, method, update or transfer; 2 on a bad option; 1 otherwise.
 */

#define MAX_ROUNDS 200 /* per process */
#define MAX_PROCS 16

static const char *usage_text =
    "usage: inproc [options]   (run by make bench-inproc REF=<commit>; see bench/perf/inproc/inproc.sh)\n"
    "  --scene S       disks2d (default), cube3d, bar1d, sparse2d-4096, sparse2d-tight,\n"
    "                  collapse2d-dp, collapse2d-el (the granular column: Drucker-Prager, or\n"
    "                  linear elasticity with the same start)\n"
    "  --method M      mpm (default), gimp, bspline2, bspline3, ...\n"
    "  --update U      usf (default), usl, musl\n"
    "  --transfer T    flip (default) or apic\n"
    "  --threads N     worker threads of both simulations (default 2)\n"
    "  --particles N   aimed particles (default: the scene's, 10^6)\n"
    "  --steps K       steps per round and side (default 10)\n"
    "  --skip K        steps each side runs untimed before its warm-up (default 0; e.g. 300\n"
    "                  for the collapse2d column once it flows)\n"
    "  --rounds R      rounds per process (default 7, 3 to 200)\n"
    "  --procs P       processes, one after the other (default 3, 1 to 16)\n"
    "  --header        print the table's header line first\n"
    "  --header-only   print only the header line (no run)\n"
    "  --csv           one CSV row instead of the table row\n"
    "  --help          this text\n";

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* Quantile q of n sorted values (linear between neighbours). */
static double quant(const double *v, int n, double q)
{
    double k = q * (n - 1);
    int i = (int)k;
    return i + 1 < n ? v[i] + (k - i) * (v[i + 1] - v[i]) : v[n - 1];
}

/* A whole positive number from an option's value, within [lo, hi]. */
static int parse_long(const char *opt, const char *s, long lo, long hi, long *out)
{
    char *end;
    errno = 0;
    long v = s ? strtol(s, &end, 10) : 0;
    if (!s || errno || end == s || *end || v < lo || v > hi) {
        fprintf(stderr, "inproc: %s wants a whole number in [%ld, %ld], got '%s'\n", opt, lo, hi,
                s ? s : "");
        return -1;
    }
    *out = v;
    return 0;
}

/* Times one run of k steps of a side; < 0 when it stopped short. */
static double timed(int (*run)(void *, long), void *h, long k)
{
    double t0 = now();
    if (run(h, k)) return -1.0;
    return now() - t0;
}

/* What one process measured: the rounds it kept, the sides' rates. */
typedef struct {
    int rc, done;
    size_t np, npr;
    double triad; /* GB/s on the configuration's threads, before and after the rounds (mean; 0:
                     none) */
    double rr[MAX_ROUNDS], rn[MAX_ROUNDS];
} proc_out;

/* The triad on q's threads (GB/s; 0 when it could not run). */
static double triad(const pbi_cfg *q)
{
    pb_triad t;
    return pb_triad_measure(q->threads, &t) ? 0.0 : t.gbs;
}

/* One process's work: both sides built, skip untimed steps of each, a
 * warm-up of each, the rounds, with the triad before and after them. */
static void measure(const pbi_cfg *q, long skip, long steps, long rounds, proc_out *o)
{
    double t0 = triad(q);
    char err[512] = "";
    int lacks = 0;
    void *r = pbi_ref_open(q, &lacks, err, sizeof err);
    if (!r) {
        fprintf(stderr, "inproc: REF's side (%s %s %s): %s\n", q->scene, q->method, q->update, err);
        o->rc = lacks ? 3 : 1;
        return;
    }
    void *n = pbi_new_open(q, &lacks, err, sizeof err);
    if (!n) {
        fprintf(stderr, "inproc: this tree's side (%s %s %s): %s\n", q->scene, q->method, q->update,
                err);
        pbi_ref_close(&r);
        o->rc = 1;
        return;
    }
    o->np = pbi_new_particles(n);
    o->npr = pbi_ref_particles(r);
    if (skip && (pbi_ref_run(r, skip) || pbi_new_run(n, skip))) {
        fprintf(stderr, "inproc: the %ld skipped steps stopped short (steps: REF %ld, new %ld)\n",
                skip, pbi_ref_steps(r), pbi_new_steps(n));
        o->rc = 1;
    }
    if (!o->rc && (timed(pbi_ref_run, r, steps) < 0 || timed(pbi_new_run, n, steps) < 0)) {
        fprintf(stderr, "inproc: the warm-up run of %ld steps stopped short (diverged?)\n", steps);
        o->rc = 1;
    }
    for (long k = 0; !o->rc && k < rounds; k++) {
        double tr, tn;
        if (k & 1) {
            tn = timed(pbi_new_run, n, steps);
            tr = tn < 0 ? -1 : timed(pbi_ref_run, r, steps);
        } else {
            tr = timed(pbi_ref_run, r, steps);
            tn = tr < 0 ? -1 : timed(pbi_new_run, n, steps);
        }
        if (tr <= 0 || tn <= 0) {
            fprintf(stderr,
                    "inproc: round %ld stopped short (steps: REF %ld, new %ld); %d rounds kept\n",
                    k + 1, pbi_ref_steps(r), pbi_new_steps(n), o->done);
            break;
        }
        o->rr[o->done] = (double)o->npr * (double)steps / tr / 1e6;
        o->rn[o->done] = (double)o->np * (double)steps / tn / 1e6;
        o->done++;
    }
    pbi_ref_close(&r);
    pbi_new_close(&n);
    double t1 = triad(q);
    o->triad = t0 > 0 && t1 > 0 ? 0.5 * (t0 + t1) : 0.0;
}

/* measure() in a forked child, its result back through a pipe
 * (pb_write_all() / pb_read_all(), from the bench's scenes.c that this
 * tree's side includes): each process maps both simulations afresh.
 * 0, or the exit code to give. */
static int one_process(const pbi_cfg *q, long skip, long steps, long rounds, proc_out *o)
{
    int fd[2];
    memset(o, 0, sizeof *o);
    if (pipe(fd)) {
        perror("inproc: pipe");
        return 1;
    }
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0) {
        perror("inproc: fork");
        close(fd[0]);
        close(fd[1]);
        return 1;
    }
    if (pid == 0) {
        close(fd[0]);
        measure(q, skip, steps, rounds, o);
        _exit(pb_write_all(fd[1], o, sizeof *o) ? 1 : 0);
    }
    close(fd[1]);
    size_t got = pb_read_all(fd[0], o, sizeof *o);
    close(fd[0]);
    int st = 0;
    while (waitpid(pid, &st, 0) < 0 && errno == EINTR) {
    }
    if (got != sizeof *o || !WIFEXITED(st) || WEXITSTATUS(st)) {
        fprintf(stderr, "inproc: the measuring process %s\n",
                WIFSIGNALED(st) ? strsignal(WTERMSIG(st)) : "failed");
        return 1;
    }
    if (o->rc) return o->rc;
    if (o->np != o->npr)
        fprintf(stderr,
                "inproc: note: the sides built %zu (REF) and %zu particles; rates are per "
                "particle-step\n",
                o->npr, o->np);
    return 0;
}

int main(int argc, char **argv)
{
    pbi_cfg q = {"disks2d", "mpm", "usf", 0, 2, 0};
    long steps = 10, rounds = 7, procs = 3, threads = 2, particles = 0, skip = 0;
    int header = 0, csv = 0, only = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--help") || !strcmp(a, "-h")) {
            fputs(usage_text, stdout);
            return 0;
        } else if (!strcmp(a, "--header")) {
            header = 1;
        } else if (!strcmp(a, "--header-only")) {
            header = only = 1;
        } else if (!strcmp(a, "--csv")) {
            csv = 1;
        } else if (!v) {
            fprintf(stderr, "inproc: %s needs a value\n%s", a, usage_text);
            return 2;
        } else if (!strcmp(a, "--scene")) {
            q.scene = v, i++;
        } else if (!strcmp(a, "--method")) {
            q.method = v, i++;
        } else if (!strcmp(a, "--update")) {
            q.update = v, i++;
        } else if (!strcmp(a, "--transfer")) {
            if (strcmp(v, "flip") && strcmp(v, "apic")) {
                fprintf(stderr, "inproc: --transfer is flip or apic, got '%s'\n", v);
                return 2;
            }
            q.apic = !strcmp(v, "apic"), i++;
        } else if (!strcmp(a, "--threads")) {
            if (parse_long(a, v, 1, 64, &threads)) return 2;
            i++;
        } else if (!strcmp(a, "--particles")) {
            if (parse_long(a, v, 1000, 100000000, &particles)) return 2;
            i++;
        } else if (!strcmp(a, "--steps")) {
            if (parse_long(a, v, 1, 1000000, &steps)) return 2;
            i++;
        } else if (!strcmp(a, "--skip")) {
            if (parse_long(a, v, 0, 1000000, &skip)) return 2;
            i++;
        } else if (!strcmp(a, "--rounds")) {
            if (parse_long(a, v, 3, MAX_ROUNDS, &rounds)) return 2;
            i++;
        } else if (!strcmp(a, "--procs")) {
            if (parse_long(a, v, 1, MAX_PROCS, &procs)) return 2;
            i++;
        } else {
            fprintf(stderr, "inproc: unknown option '%s'\n%s", a, usage_text);
            return 2;
        }
    }
    q.threads = (int)threads;
    q.particles = particles;
    if (header && !csv)
        printf("%-15s %-8s %-4s %-4s %3s %9s %5s %6s %9s %9s %8s %13s %13s %7s  %s\n", "scene",
               "method", "upd", "xfer", "thr", "particles", "steps", "rounds", "ref Mp/s",
               "new Mp/s", "new/ref", "q1-q3", "min-max", "new>ref",
               "per process: ratio@triad GB/s");
    if (header && csv)
        printf(
            "scene,method,update,transfer,threads,particles,steps,rounds,ref_mpsteps,new_mpsteps,"
            "ratio,ratio_q1,ratio_q3,ratio_min,ratio_max,new_faster,process_ratios_at_triad\n");
    if (only) return 0;

    /* each process's rounds go to the end of the arrays */
    static double rr[MAX_ROUNDS * MAX_PROCS], rn[MAX_ROUNDS * MAX_PROCS],
        ratio[MAX_ROUNDS * MAX_PROCS], pmed[MAX_PROCS], ptri[MAX_PROCS];
    static proc_out po;
    size_t np = 0;
    int done = 0;
    for (long pi = 0; pi < procs; pi++) {
        int rc = one_process(&q, skip, steps, rounds, &po);
        if (rc) return rc;
        if (po.done < 3) {
            fprintf(stderr, "inproc: process %ld kept %d rounds: too few for a median\n", pi + 1,
                    po.done);
            return 1;
        }
        np = po.np;
        for (int k = 0; k < po.done; k++) {
            rr[done + k] = po.rr[k];
            rn[done + k] = po.rn[k];
            ratio[done + k] = po.rn[k] / po.rr[k];
        }
        double pr[MAX_ROUNDS];
        memcpy(pr, ratio + done, (size_t)po.done * sizeof *pr);
        qsort(pr, (size_t)po.done, sizeof *pr, cmp_d);
        pmed[pi] = quant(pr, po.done, 0.5);
        ptri[pi] = po.triad;
        done += po.done;
    }
    int faster = 0;
    for (int k = 0; k < done; k++) faster += ratio[k] > 1.0;
    qsort(rr, (size_t)done, sizeof *rr, cmp_d);
    qsort(rn, (size_t)done, sizeof *rn, cmp_d);
    qsort(ratio, (size_t)done, sizeof *ratio, cmp_d);
    const char *xf = q.apic ? "apic" : "flip";
    char pm[16 * MAX_PROCS] = ""; /* the processes' median ratios @ their triads */
    for (long pi = 0; pi < procs; pi++)
        snprintf(pm + strlen(pm), sizeof pm - strlen(pm), "%s%.2f@%.1f", pi ? " " : "", pmed[pi],
                 ptri[pi]);
    if (csv) {
        printf("%s,%s,%s,%s,%d,%zu,%ld,%d,%.3f,%.3f,%.4f,%.4f,%.4f,%.4f,%.4f,%d,%s\n", q.scene,
               q.method, q.update, xf, q.threads, np, steps, done, quant(rr, done, 0.5),
               quant(rn, done, 0.5), quant(ratio, done, 0.5), quant(ratio, done, 0.25),
               quant(ratio, done, 0.75), ratio[0], ratio[done - 1], faster, pm);
    } else {
        char iq[32], mm[32], fs[16];
        snprintf(iq, sizeof iq, "%.3f-%.3f", quant(ratio, done, 0.25), quant(ratio, done, 0.75));
        snprintf(mm, sizeof mm, "%.3f-%.3f", ratio[0], ratio[done - 1]);
        snprintf(fs, sizeof fs, "%d/%d", faster, done);
        printf("%-15s %-8s %-4s %-4s %3d %9zu %5ld %6d %9.2f %9.2f %7.3fx %13s %13s %7s  %s\n",
               q.scene, q.method, q.update, xf, q.threads, np, steps, done, quant(rr, done, 0.5),
               quant(rn, done, 0.5), quant(ratio, done, 0.5), iq, mm, fs, pm);
    }
    fflush(stdout);
    return 0;
}
