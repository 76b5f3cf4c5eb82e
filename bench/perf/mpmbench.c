/*
 * mpmbench.c - bin/mpmbench, the throughput benchmark: the
 * command line, the report (an aligned table on the terminal, or CSV with
 * --csv; every row also appended to build/bench/throughput.csv) and
 * `--all`, which is what `make bench` runs: every in-process scene with MPM
 * and GIMP at 1 and 2 threads (1 -> 2 threads from the median of three
 * alternated pairs), the sparse-grid pairs, the lean build
 * against the normal one on disks2d (through bin/mpmbench-lean; the median
 * of three alternated pairs too), and the
 * daemon scene; then the ratios and a summary against the targets.
 * Timing assertions do not exist here: it measures and reports.
 */
#include "perf.h"

#include <errno.h>
#include <limits.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#define MAX_SUMMARY 96

static int csv_mode;
static int header_done;
static int collecting; /* --all: keep result lines for the summary */
static char *summary[MAX_SUMMARY];
static int nsummary;
static int progress_shown;
static pb_triad triads[MPM_MAX_THREADS + 1]; /* by thread count; gbs 0: not measured */

static const char usage[] =
    "usage: mpmbench --scene NAME [--particles N] [--steps S] [--threads T]\n"
    "                [--method mpm|gimp|bspline2|bspline3|cpdi] [--update usf|usl|musl]\n"
    "                [--pic F] [--transfer flip|apic|both] [--csv] [--no-triad]\n"
    "       mpmbench --all [--particles N] [--steps S] [--csv]\n"
    "       mpmbench --bspline [--particles N] [--steps S] [--csv]\n"
    "       mpmbench --cpdi-vs-gimp [--particles N] [--steps S] [--update U] [--csv]\n"
    "       mpmbench --checkpoint [--particles N] [--threads T]\n"
    "       mpmbench --triad [--threads T] [--csv]\n"
    "       mpmbench --hashes   (the same-bits harness: one hash per run of a fixed matrix)\n"
    "Throughput of the mpmd solver: millions of particle-steps per second,\n"
    "the median of 3 timed runs after a warm-up, and peak memory per particle.\n"
    "Scenes:\n"
    "  disks2d   the paper's two elastic disks, grid refined to ~N particles (2x2 per cell)\n"
    "  cube3d    an elastic cube of ~N particles (2x2x2 per cell) falling onto a fixed floor\n"
    "  bar1d     the paper's bar with N particles (2 per cell)\n"
    "  sparse2d  a spinning disk of N particles (default 10^4) in a 4096x4096 grid and in a\n"
    "            grid just large enough for it: both rows and the ratio\n"
    "  collapse2d  a granular column (a = 2, ~N particles, BSPLINE2 unless --method) falling\n"
    "            on a friction base: linear elastic and Drucker-Prager rows, twice each with\n"
    "            the same steps, and the DP / elastic time per particle-step (aim <= 2)\n"
    "  daemon    disks2d through a real bin/mpmd (ipc://, temporary database): no watcher,\n"
    "            and a watcher taking energies every step and snapshots every 100 steps,\n"
    "            against the same case in-process (default 100 steps, 2 threads)\n"
    "Options:\n"
    "  --particles N  particles to aim for (default 10^6; sparse2d 10^4), 1000..10^8\n"
    "  --steps S      steps per run, 1..10^9 (default: ~2 s at the issue's target speed,\n"
    "                 capped by the simulated time a scene stays valid for, and cut to ~2 s\n"
    "                 when the warm-up shows the solver 2x slower than the target)\n"
    "  --threads T    solver threads (default 2), 1..64\n"
    "  --method M     mpm | gimp | bspline2 | bspline3 | cpdi (default mpm; cpdi: not with\n"
    "                 the daemon scene)\n"
    "  --update U     usf | usl | musl (default usf)\n"
    "  --pic F        PIC fraction of the velocity update, 0..1 (default 0: pure FLIP);\n"
    "                 not with the daemon scene or --all\n"
    "  --transfer T   flip | apic | both (default flip): the velocity transfer; both measures\n"
    "                 FLIP and APIC interleaved (FLIP, APIC, FLIP, APIC) and prints the APIC /\n"
    "                 FLIP time per particle-step; APIC rows are scene+apic (disks2d, cube3d,\n"
    "                 bar1d; not with --pic, the daemon scene or --all)\n"
    "  --portable-kernels  run on the portable kernels (default: AVX2+FMA where the CPU has\n"
    "                 them; the header names the kernels)\n"
    "  --csv          print CSV rows instead of the table\n"
    "  --no-triad     skip the STREAM triad (the roof columns stay empty)\n"
    "  --triad        only the triad (and the CPU model), on T threads or on 1 and 2; with\n"
    "                 --csv: triad_threads,triad_gbs,lo_gbs,hi_gbs,array_mib,reps rows\n"
    "  --all          every scene, MPM and GIMP, 1 and 2 threads (1 -> 2 threads: the median\n"
    "                 of 3 alternated pairs); the lean build (the same); the daemon\n"
    "  --bspline      disks2d and cube3d at 1 and 2 threads, GIMP, BSPLINE2 and BSPLINE3\n"
    "                 interleaved (two rounds): the B-splines' speed as ratios to GIMP\n"
    "  --checkpoint   the solver's checkpoints: bytes per particle, save and load times\n"
    "                 (median of 3, in memory) of a 2D GIMP elastic, a 2D Drucker-Prager and\n"
    "                 a 3D CPDI block of ~N particles, against one step\n"
    "  --cpdi-vs-gimp disks2d and cube3d at 1 and 2 threads, GIMP and CPDI interleaved\n"
    "                 (GIMP, CPDI, GIMP, CPDI, the same steps), then CPDI / GIMP throughput\n"
    "                 (target >= 0.4) and CPDI's bytes per particle (<= 300 2D, 450 3D)\n"
    "  -h, --help     this text\n"
    "Rows are appended to build/bench/throughput.csv:\n  " PB_CSV_HEADER "\n"
    "bytes_per_particle is the peak RSS of a forked child that builds and runs the one\n"
    "configuration (ru_maxrss from wait4), over the particle count; for daemon rows, the\n"
    "peak RSS of that row's mpmd process.  Environment: MPMD_BIN (default: mpmd next to\n"
    "this program), MPMBENCH_LEAN (default: mpmbench-lean next to it).\n"
    "The roof: before the scenes, a STREAM triad a = b + s c on each thread\n"
    "count the rows use (the threads first-touch their slices; median of 7 passes, 24 B\n"
    "per element; each array max(4 x last-level cache, 64 MiB), at most a twelfth of\n"
    "the RAM; MPMBENCH_TRIAD_MIB sets MiB per array).  model_bytes_per_pstep is\n"
    "mpm_sim_traffic(): the particle-array bytes the step's passes read and write per\n"
    "particle (grid traffic not counted); achieved_gbs = Mpsteps/s x that; roof_fraction\n"
    "= achieved_gbs / triad_gbs (docs/performance.md).\n";

/* ---- output ---- */

static void vline(FILE *f, const char *fmt, va_list ap)
{
    if (progress_shown) {
        fputs("\r\033[K", stderr);
        progress_shown = 0;
    }
    vfprintf(f, fmt, ap);
    fputc('\n', f);
    fflush(f);
}

void pb_note(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vline(csv_mode ? stderr : stdout, fmt, ap);
    va_end(ap);
}

void pb_result(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vline(csv_mode ? stderr : stdout, fmt, ap);
    va_end(ap);
    if (collecting && nsummary < MAX_SUMMARY) {
        char buf[512];
        va_start(ap, fmt);
        vsnprintf(buf, sizeof buf, fmt, ap);
        va_end(ap);
        summary[nsummary] = strdup(buf);
        if (summary[nsummary]) nsummary++;
    }
}

void pb_progress(const char *fmt, ...)
{
    if (!isatty(STDERR_FILENO)) return;
    va_list ap;
    va_start(ap, fmt);
    fputs("\r\033[K  ... ", stderr);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fflush(stderr);
    progress_shown = 1;
}

/* Achieved GB/s of a row (its rate times the modelled bytes; 0: no model)
 * and its fraction of the triad (0: either unknown). */
static double achieved_gbs(const pb_row *r)
{
    return r->traffic_b > 0 ? r->mpsteps * r->traffic_b / 1e3 : 0;
}

static double roof_fraction(const pb_row *r)
{
    return r->triad_gbs > 0 ? achieved_gbs(r) / r->triad_gbs : 0;
}

static void csv_line(FILE *f, const pb_row *r)
{
    char roof[128] = ",,,";
    if (r->traffic_b > 0 && r->triad_gbs > 0)
        snprintf(roof, sizeof roof, "%.0f,%.3f,%.3f,%.4f", r->traffic_b, achieved_gbs(r),
                 r->triad_gbs, roof_fraction(r));
    else if (r->traffic_b > 0)
        snprintf(roof, sizeof roof, "%.0f,%.3f,,", r->traffic_b, achieved_gbs(r));
    fprintf(f, "%s,%s,%s,%d,%zu,%zu,%ld,%d,%.4f,%.3f,%.1f,%s\n", r->scene,
            pb_method_name(r->method), pb_update_name(r->update), r->dim, r->particles, r->nodes,
            r->steps, r->threads, r->wall_s, r->mpsteps, r->bytes_pp, roof);
}

static void append_csv(const pb_row *r)
{
    static int warned;
    if ((mkdir("build", 0777) && errno != EEXIST) || (mkdir(PB_CSV_DIR, 0777) && errno != EEXIST)) {
        if (!warned++)
            fprintf(stderr, "mpmbench: cannot create %s: %s\n", PB_CSV_DIR, strerror(errno));
        return;
    }
    FILE *f = fopen(PB_CSV_PATH, "a");
    if (!f) {
        if (!warned++)
            fprintf(stderr, "mpmbench: cannot open %s: %s\n", PB_CSV_PATH, strerror(errno));
        return;
    }
    if (ftell(f) == 0) fprintf(f, "%s\n", PB_CSV_HEADER);
    csv_line(f, r);
    if (fclose(f) && !warned++)
        fprintf(stderr, "mpmbench: writing %s: %s\n", PB_CSV_PATH, strerror(errno));
}

/* A row already written to the CSV file by another process (the lean
 * binary): printed only. */
static void show_row(const pb_row *r0)
{
    pb_row rr = *r0;
    const pb_row *r = &rr;
    if (rr.threads > 0 && rr.threads <= MPM_MAX_THREADS) rr.triad_gbs = triads[rr.threads].gbs;
    if (csv_mode) {
        if (!header_done++) printf("%s\n", PB_CSV_HEADER);
        csv_line(stdout, r);
        fflush(stdout);
        return;
    }
    if (!header_done++)
        pb_note("%-15s %-4s %-4s %3s %9s %9s %6s %3s %8s %10s %8s %7s %6s %5s  %s", "scene", "meth",
                "upd", "dim", "particles", "nodes", "steps", "thr", "wall_s", "Mpsteps/s", "B/part",
                "B/pstep", "GB/s", "roof", "runs (Mpsteps/s), notes");
    char notes[200] = "";
    if (r->runs > 1) snprintf(notes, sizeof notes, "%.3g..%.3g", r->rate_lo, r->rate_hi);
    if (r->cpus > 0) {
        size_t k = strlen(notes);
        snprintf(notes + k, sizeof notes - k, "%scpu %.2f", k ? "; " : "", r->cpus);
    }
    if (r->tcapped) {
        size_t k = strlen(notes);
        snprintf(notes + k, sizeof notes - k, "%ssteps capped by the scene's simulated time",
                 k ? "; " : "");
    }
    if (r->reduced) {
        size_t k = strlen(notes);
        snprintf(notes + k, sizeof notes - k, "%ssteps cut from %ld (slow warm-up)", k ? "; " : "",
                 r->default_steps);
    }
    char tb[16] = "-", gb[16] = "-", rf[16] = "-";
    if (r->traffic_b > 0) {
        snprintf(tb, sizeof tb, "%.0f", r->traffic_b);
        snprintf(gb, sizeof gb, "%.2f", achieved_gbs(r));
    }
    if (roof_fraction(r) > 0) snprintf(rf, sizeof rf, "%.0f%%", 100 * roof_fraction(r));
    pb_note("%-15s %-4s %-4s %3d %9zu %9zu %6ld %3d %8.3f %10.3f %8.1f %7s %6s %5s  %s", r->scene,
            pb_method_name(r->method), pb_update_name(r->update), r->dim, r->particles, r->nodes,
            r->steps, r->threads, r->wall_s, r->mpsteps, r->bytes_pp, tb, gb, rf, notes);
}

void pb_emit(const pb_row *r0)
{
    pb_row r = *r0;
    if (r.threads > 0 && r.threads <= MPM_MAX_THREADS) r.triad_gbs = triads[r.threads].gbs;
    show_row(&r);
    append_csv(&r);
}

static void row_failed(const pb_row *r)
{
    if (progress_shown) {
        fputs("\r\033[K", stderr);
        progress_shown = 0;
    }
    fprintf(stderr, "mpmbench: %s %s %s, %d thread%s: %s\n", r->scene, pb_method_name(r->method),
            pb_update_name(r->update), r->threads, r->threads > 1 ? "s" : "", r->msg);
}

const char *pb_exe_dir(void)
{
    static char dir[PATH_MAX];
    if (!dir[0]) {
        ssize_t n = readlink("/proc/self/exe", dir, sizeof dir - 1);
        if (n <= 0) {
            snprintf(dir, sizeof dir, ".");
        } else {
            dir[n] = 0;
            char *s = strrchr(dir, '/');
            if (s && s != dir)
                *s = 0;
            else
                snprintf(dir, sizeof dir, "%s", s ? "/" : ".");
        }
    }
    return dir;
}

/* ---- the command line ---- */

typedef struct {
    int all, bspline, csv, have_scene, cpdi_vs_gimp, checkpoint, no_triad, triad_only;
    const char *scene;
    long particles, steps;
    int threads, have_threads, have_method, have_update;
    mpm_method method;
    mpm_update update;
    double pic;
    int have_pic;
    int transfer; /* 0 flip, 1 apic, 2 both */
    int have_transfer;
} opts;

static int parse_long(const char *flag, const char *s, long lo, long hi, long *out)
{
    char *end;
    errno = 0;
    double d = strtod(s, &end); /* accepts 1e6 */
    if (errno || end == s || *end || d < (double)lo || d > (double)hi || d != (double)(long)d) {
        fprintf(stderr, "mpmbench: %s: expected a whole number in [%ld, %ld], got '%s'\n", flag, lo,
                hi, s);
        return -1;
    }
    *out = (long)d;
    return 0;
}

static int parse_args(int argc, char **argv, opts *o)
{
    memset(o, 0, sizeof *o);
    o->threads = 2;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            fputs(usage, stdout);
            return 1;
        }
        if (!strcmp(a, "--csv")) {
            o->csv = 1;
            continue;
        }
        if (!strcmp(a, "--all")) {
            o->all = 1;
            continue;
        }
        if (!strcmp(a, "--no-triad")) {
            o->no_triad = 1;
            continue;
        }
        if (!strcmp(a, "--portable-kernels")) {
            pb_set_kernels(MPM_KERNELS_PORTABLE);
            continue;
        }
        if (!strcmp(a, "--triad")) {
            o->triad_only = 1;
            continue;
        }
        if (!strcmp(a, "--bspline")) {
            o->bspline = 1;
            continue;
        }
        if (!strcmp(a, "--cpdi-vs-gimp")) {
            o->cpdi_vs_gimp = 1;
            continue;
        }
        if (!strcmp(a, "--checkpoint")) {
            o->checkpoint = 1;
            continue;
        }
        int known = !strcmp(a, "--scene") || !strcmp(a, "--particles") || !strcmp(a, "--steps") ||
                    !strcmp(a, "--threads") || !strcmp(a, "--method") || !strcmp(a, "--update") ||
                    !strcmp(a, "--pic") || !strcmp(a, "--transfer");
        if (!known) {
            fprintf(stderr, "mpmbench: unknown option '%s' (see --help)\n", a);
            return -1;
        }
        if (i + 1 >= argc) {
            fprintf(stderr, "mpmbench: %s needs a value (see --help)\n", a);
            return -1;
        }
        const char *v = argv[++i];
        long x;
        if (!strcmp(a, "--scene")) {
            static const char *const names[] = {"disks2d",  "cube3d", "bar1d",
                                                "sparse2d", "daemon", "collapse2d"};
            int ok = 0;
            for (size_t k = 0; k < sizeof names / sizeof names[0]; k++) ok |= !strcmp(v, names[k]);
            if (!ok) {
                fprintf(stderr,
                        "mpmbench: --scene: expected disks2d, cube3d, bar1d, sparse2d, "
                        "collapse2d or daemon, got '%s'\n",
                        v);
                return -1;
            }
            o->scene = v;
            o->have_scene = 1;
        } else if (!strcmp(a, "--particles")) {
            if (parse_long(a, v, PB_MIN_PARTICLES, PB_MAX_PARTICLES, &o->particles)) return -1;
        } else if (!strcmp(a, "--steps")) {
            if (parse_long(a, v, 1, PB_MAX_STEPS, &o->steps)) return -1;
        } else if (!strcmp(a, "--threads")) {
            if (parse_long(a, v, 1, MPM_MAX_THREADS, &x)) return -1;
            o->threads = (int)x;
            o->have_threads = 1;
        } else if (!strcmp(a, "--method")) {
            if (!strcmp(v, "mpm"))
                o->method = MPM_METHOD_MPM;
            else if (!strcmp(v, "gimp"))
                o->method = MPM_METHOD_GIMP;
            else if (!strcmp(v, "bspline2"))
                o->method = MPM_METHOD_BSPLINE2;
            else if (!strcmp(v, "bspline3"))
                o->method = MPM_METHOD_BSPLINE3;
            else if (!strcmp(v, "cpdi"))
                o->method = MPM_METHOD_CPDI;
            else {
                fprintf(stderr,
                        "mpmbench: --method: expected mpm, gimp, bspline2, bspline3 or cpdi, got "
                        "'%s'\n",
                        v);
                return -1;
            }
            o->have_method = 1;
        } else if (!strcmp(a, "--transfer")) {
            if (!strcmp(v, "flip"))
                o->transfer = 0;
            else if (!strcmp(v, "apic"))
                o->transfer = 1;
            else if (!strcmp(v, "both"))
                o->transfer = 2;
            else {
                fprintf(stderr, "mpmbench: --transfer: expected flip, apic or both, got '%s'\n", v);
                return -1;
            }
            o->have_transfer = 1;
        } else if (!strcmp(a, "--pic")) {
            char *end;
            errno = 0;
            o->pic = strtod(v, &end);
            if (errno || end == v || *end || !(o->pic >= 0 && o->pic <= 1)) {
                fprintf(stderr, "mpmbench: --pic: expected a number in [0, 1], got '%s'\n", v);
                return -1;
            }
            o->have_pic = 1;
        } else {
            if (!strcmp(v, "usf"))
                o->update = MPM_USF;
            else if (!strcmp(v, "usl"))
                o->update = MPM_USL;
            else if (!strcmp(v, "musl"))
                o->update = MPM_MUSL;
            else {
                fprintf(stderr, "mpmbench: --update: expected usf, usl or musl, got '%s'\n", v);
                return -1;
            }
            o->have_update = 1;
        }
    }
    if ((o->all || o->bspline) && (o->have_scene || o->have_threads || o->have_method ||
                                   o->have_update || o->have_pic || o->have_transfer)) {
        fprintf(stderr, "mpmbench: --all runs every scene, method and thread count; it takes "
                        "only --particles, --steps and --csv\n");
        return -1;
    }
    if (o->cpdi_vs_gimp && (o->all || o->have_scene || o->have_threads || o->have_method)) {
        fprintf(stderr, "mpmbench: --cpdi-vs-gimp runs its own scenes, methods and threads; it "
                        "takes only --particles, --steps, --update and --csv\n");
        return -1;
    }
    if (o->checkpoint && (o->all || o->bspline || o->cpdi_vs_gimp || o->have_scene ||
                          o->have_method || o->have_update || o->have_pic || o->have_transfer)) {
        fprintf(stderr, "mpmbench: --checkpoint runs its own scenes; it takes only --particles "
                        "and --threads\n");
        return -1;
    }
    if (o->triad_only && (o->all || o->bspline || o->cpdi_vs_gimp || o->checkpoint ||
                          o->have_scene || o->no_triad)) {
        fprintf(stderr, "mpmbench: --triad measures only the triad; it takes only --threads and "
                        "--csv\n");
        return -1;
    }
    if (o->cpdi_vs_gimp || o->checkpoint || o->triad_only) return 0;
    if (!o->all && !o->bspline && !o->have_scene) {
        fprintf(stderr, "mpmbench: give --scene NAME or --all (see --help)\n");
        return -1;
    }
    if (o->transfer && (o->pic > 0 || (o->have_scene && (!strcmp(o->scene, "daemon") ||
                                                         !strcmp(o->scene, "sparse2d"))))) {
        fprintf(stderr, "mpmbench: --transfer apic/both: not with --pic, the daemon or the "
                        "sparse2d scene\n");
        return -1;
    }
    if (o->have_pic && o->have_scene && !strcmp(o->scene, "daemon")) {
        fprintf(stderr, "mpmbench: --pic: not with the daemon scene\n");
        return -1;
    }
    if (o->have_scene && !strcmp(o->scene, "daemon") && o->particles > 10000000L) {
        fprintf(stderr,
                "mpmbench: --particles: the daemon scene takes at most 10000000 "
                "(the daemon's case limit), got %ld\n",
                o->particles);
        return -1;
    }
    return 0;
}

/* ---- running ---- */

static int measure(const pb_cfg *c, pb_row *r)
{
    pb_progress("%s%s %s %s, %d thread%s", pb_scene_name(c->scene), PB_SUFFIX,
                pb_method_name(c->method), pb_update_name(c->update), c->threads,
                c->threads > 1 ? "s" : "");
    if (pb_measure(c, r)) {
        row_failed(r);
        return -1;
    }
    pb_emit(r);
    return 0;
}

static const char *verdict(int ok)
{
    return ok ? "ok" : "MISSED";
}

static void sparse_ratio(const pb_row *wide, const pb_row *tight)
{
    double q = tight->mpsteps > 0 ? wide->mpsteps / tight->mpsteps : 0;
    pb_result("sparse2d %s %s, %d thread%s: 4096^2 grid / tight grid = %.3f (target >= 0.8): %s",
              pb_method_name(wide->method), pb_update_name(wide->update), wide->threads,
              wide->threads > 1 ? "s" : "", q, verdict(q >= 0.8));
}

/* --transfer both: FLIP, APIC, FLIP, APIC (the same steps in all four, so
 * that a drift of the machine's speed falls on both alike), then the APIC /
 * FLIP time per particle-step from the summed medians, and the memory. */
static int transfer_pair(pb_cfg *c)
{
    pb_row r[4];
    for (int k = 0; k < 4; k++) {
        c->transfer = k % 2 ? MPM_TRANSFER_APIC : MPM_TRANSFER_FLIP;
        if (measure(c, &r[k])) return 1;
        if (k == 0) c->steps = r[0].steps;
    }
    double tf = 0, ta = 0;
    for (int k = 0; k < 4; k++) *(k % 2 ? &ta : &tf) += 1.0 / r[k].mpsteps;
    double q = ta / tf;
    pb_result("%s %s %s, %d thread%s: APIC / FLIP time per particle-step = %.3f (%.3f, %.3f; "
              "target <= 1.3): %s; B/particle FLIP %.0f, APIC %.0f",
              pb_scene_name(c->scene), pb_method_name(c->method), pb_update_name(c->update),
              c->threads, c->threads > 1 ? "s" : "", q, r[0].mpsteps / r[1].mpsteps,
              r[2].mpsteps / r[3].mpsteps, verdict(q <= 1.3), 0.5 * (r[0].bytes_pp + r[2].bytes_pp),
              0.5 * (r[1].bytes_pp + r[3].bytes_pp));
    return 0;
}

/* The collapse scenes: elastic, Drucker-Prager, elastic, Drucker-Prager
 * with the same steps (a drift of the machine's speed falls on both
 * alike), then the DP / elastic time per particle-step from the summed
 * medians (the aim: <= 2). */
static int collapse_pair(pb_cfg *c)
{
    pb_row r[4];
    for (int k = 0; k < 4; k++) {
        c->scene = k % 2 ? PB_COLLAPSE_DP : PB_COLLAPSE_EL;
        if (measure(c, &r[k])) return 1;
        if (k == 0) c->steps = r[0].steps;
    }
    double te = 0, td = 0;
    for (int k = 0; k < 4; k++) *(k % 2 ? &td : &te) += 1.0 / r[k].mpsteps;
    double q = td / te;
    pb_result("collapse2d %s %s, %d thread%s: Drucker-Prager / linear elastic time per "
              "particle-step = %.3f (%.3f, %.3f; aim <= 2): %s",
              pb_method_name(c->method), pb_update_name(c->update), c->threads,
              c->threads > 1 ? "s" : "", q, r[0].mpsteps / r[1].mpsteps,
              r[2].mpsteps / r[3].mpsteps, verdict(q <= 2.0));
    return 0;
}

static int run_one(const opts *o)
{
    pb_cfg c = {PB_DISKS2D, o->method,
                o->update,  o->particles,
                o->steps,   o->threads,
                o->pic,     o->transfer == 1 ? MPM_TRANSFER_APIC : MPM_TRANSFER_FLIP};
    pb_row r, r2;
    if (!strcmp(o->scene, "daemon")) {
#if PB_LEAN
        fprintf(stderr,
                "mpmbench: the daemon scene is not in the lean build (bin/mpmbench has it)\n");
        return 1;
#else
        return pb_daemon_scene(o->method, o->update, o->particles, o->steps, o->threads) ? 1 : 0;
#endif
    }
    if (!strcmp(o->scene, "collapse2d")) {
        c.method = o->have_method ? o->method : MPM_METHOD_BSPLINE2;
        return collapse_pair(&c) ? 1 : 0;
    }
    if (!strcmp(o->scene, "sparse2d")) {
        c.scene = PB_SPARSE_WIDE;
        if (measure(&c, &r)) return 1;
        c.scene = PB_SPARSE_TIGHT;
        c.steps = r.steps; /* the same work in both */
        if (measure(&c, &r2)) return 1;
        sparse_ratio(&r, &r2);
        return 0;
    }
    c.scene = !strcmp(o->scene, "cube3d")  ? PB_CUBE3D
              : !strcmp(o->scene, "bar1d") ? PB_BAR1D
                                           : PB_DISKS2D;
    if (o->transfer == 2) return transfer_pair(&c);
    return measure(&c, &r) ? 1 : 0;
}

/* Runs bin/mpmbench-lean on one disks2d configuration and reads its CSV
 * row (it appends the row to the CSV file itself).  Returns 0, -1 on
 * failure, 1 when the lean binary is not there. */
static int run_lean(const pb_cfg *c, long steps, pb_row *r)
{
    char path[PATH_MAX + 32];
    const char *env = getenv("MPMBENCH_LEAN");
    if (env && *env)
        snprintf(path, sizeof path, "%s", env);
    else
        snprintf(path, sizeof path, "%s/mpmbench-lean", pb_exe_dir());
    if (access(path, X_OK)) return 1;
    char sthreads[16], ssteps[32], sparts[32];
    snprintf(sthreads, sizeof sthreads, "%d", c->threads);
    snprintf(ssteps, sizeof ssteps, "%ld", steps);
    snprintf(sparts, sizeof sparts, "%ld", c->particles ? c->particles : 1000000L);
    char *argv[] = {path,
                    "--scene",
                    "disks2d",
                    "--method",
                    c->method == MPM_METHOD_GIMP       ? "gimp"
                    : c->method == MPM_METHOD_BSPLINE2 ? "bspline2"
                    : c->method == MPM_METHOD_BSPLINE3 ? "bspline3"
                                                       : "mpm",
                    "--update",
                    c->update == MPM_USL    ? "usl"
                    : c->update == MPM_MUSL ? "musl"
                                            : "usf",
                    "--threads",
                    sthreads,
                    "--steps",
                    ssteps,
                    "--particles",
                    sparts,
                    "--csv",
                    "--no-triad",
                    NULL};
    int fds[2];
    if (pipe(fds)) {
        snprintf(r->msg, sizeof r->msg, "pipe: %.200s", strerror(errno));
        return -1;
    }
    fflush(NULL);
    pid_t pid = fork();
    if (pid < 0) {
        snprintf(r->msg, sizeof r->msg, "fork: %.200s", strerror(errno));
        close(fds[0]);
        close(fds[1]);
        return -1;
    }
    if (pid == 0) {
        close(fds[0]);
        if (dup2(fds[1], STDOUT_FILENO) < 0) _exit(127);
        close(fds[1]);
        execv(path, argv);
        fprintf(stderr, "mpmbench: cannot run %s: %s\n", path, strerror(errno));
        _exit(127);
    }
    close(fds[1]);
    char out[4096];
    size_t n = 0;
    for (;;) {
        ssize_t k = read(fds[0], out + n, sizeof out - 1 - n);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) break;
        n += (size_t)k;
        if (n == sizeof out - 1) break;
    }
    out[n] = 0;
    close(fds[0]);
    int st = 0;
    while (waitpid(pid, &st, 0) < 0 && errno == EINTR) {
    }
    if (!WIFEXITED(st) || WEXITSTATUS(st)) {
        snprintf(r->msg, sizeof r->msg, "%.200s failed (status %d)", path,
                 WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st));
        return -1;
    }
    for (char *line = strtok(out, "\n"); line; line = strtok(NULL, "\n")) {
        char scene[40], meth[12], upd[8];
        memset(r, 0, sizeof *r);
        int k = sscanf(line, "%39[^,],%11[^,],%7[^,],%d,%zu,%zu,%ld,%d,%lf,%lf,%lf,%lf", scene,
                       meth, upd, &r->dim, &r->particles, &r->nodes, &r->steps, &r->threads,
                       &r->wall_s, &r->mpsteps, &r->bytes_pp, &r->traffic_b);
        if (k < 12) r->traffic_b = 0;
        if (k >= 11 && strcmp(scene, "scene")) {
            snprintf(r->scene, sizeof r->scene, "%s", scene);
            r->method = !strcmp(meth, "GIMP")       ? MPM_METHOD_GIMP
                        : !strcmp(meth, "BSPLINE2") ? MPM_METHOD_BSPLINE2
                        : !strcmp(meth, "BSPLINE3") ? MPM_METHOD_BSPLINE3
                                                    : MPM_METHOD_MPM;
            r->update = !strcmp(upd, "USL") ? MPM_USL : !strcmp(upd, "MUSL") ? MPM_MUSL : MPM_USF;
            r->runs = 1; /* the spread is not in the CSV */
            return 0;
        }
    }
    snprintf(r->msg, sizeof r->msg, "%.200s printed no CSV row", path);
    return -1;
}

static double load_avg(void)
{
    double l = -1;
    FILE *f = fopen("/proc/loadavg", "r");
    if (f) {
        if (fscanf(f, "%lf", &l) != 1) l = -1;
        fclose(f);
    }
    return l;
}

static void machine_info(void)
{
    static int done;
    if (done++) return;
    char model[256] = "unknown CPU", line[512];
    FILE *f = fopen("/proc/cpuinfo", "r");
    if (f) {
        while (fgets(line, sizeof line, f))
            if (!strncmp(line, "model name", 10)) {
                char *c = strchr(line, ':');
                if (c) {
                    c++;
                    while (*c == ' ') c++;
                    c[strcspn(c, "\n")] = 0;
                    snprintf(model, sizeof model, "%s", c);
                }
                break;
            }
        fclose(f);
    }
    long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
    time_t now = time(NULL);
    char when[64];
    strftime(when, sizeof when, "%Y-%m-%d %H:%M", localtime(&now));
    pb_note("mpmbench%s: %s, %ld CPU(s) online, load average %.2f, %s; %s kernels", PB_SUFFIX,
            model, ncpu, load_avg(), when,
            pb_kernels() != MPM_KERNELS_PORTABLE && mpm_kernels_avx2_available() ? "avx2-fma"
                                                                                 : "portable");
}

/* The triads of the thread counts the rows will use, measured before the
 * scenes (triad.c). */
static int measure_triads(const opts *o)
{
    int ts[2] = {o->threads, 0}, n = 1;
    if (o->no_triad || o->checkpoint) return 0;
    if (o->have_scene && !strcmp(o->scene, "daemon")) return 0; /* no model in the daemon */
    if (o->all || o->bspline || o->cpdi_vs_gimp || (o->triad_only && !o->have_threads)) {
        ts[0] = 1;
        ts[1] = 2;
        n = 2;
    }
    int bad = 0;
    for (int i = 0; i < n; i++) {
        pb_triad *t = &triads[ts[i]];
        pb_progress("STREAM triad, %d thread%s", ts[i], ts[i] > 1 ? "s" : "");
        if (pb_triad_measure(ts[i], t)) {
            fprintf(stderr, "mpmbench: triad on %d threads: %s\n", ts[i], t->msg);
            t->gbs = 0;
            bad = 1;
        }
    }
    return bad;
}

/* The triad lines of the report's header. */
static void triad_notes(void)
{
    static int done;
    if (done++) return;
    double llc = pb_llc_bytes() / (1024.0 * 1024.0);
    for (int t = 1; t <= MPM_MAX_THREADS; t++) {
        const pb_triad *x = &triads[t];
        if (x->gbs <= 0) continue;
        pb_note("STREAM triad a = b + s c, %d thread%s: %.2f GB/s (median of %d, %.2f..%.2f; 3 "
                "arrays of %.0f MiB, last-level cache %.0f MiB)",
                t, t > 1 ? "s" : "", x->gbs, x->reps, x->lo, x->hi, x->array_mib, llc);
    }
}

static void preamble(void)
{
    machine_info();
    triad_notes();
    long base = pb_baseline_rss_kb();
    pb_note("Mpsteps/s: millions of particle-steps per second, the median of %d timed runs after a "
            "warm-up run of",
            PB_RUNS);
    pb_note("  the same length (the range of the timed runs follows the row); steps default to "
            "~%.0f s per run at",
            PB_RUN_S);
    pb_note(
        "  the issue's target speed (2D MPM 30, GIMP 12; 3D MPM 16, GIMP 3; 1D assumed 60/30).");
    pb_note("B/part: peak RSS of a forked child that builds and runs only that configuration "
            "(ru_maxrss via");
    pb_note("  wait4), divided by the particles; a child that exits at once peaks at %ld KB. "
            "Daemon rows: the peak",
            base);
    pb_note("  RSS of that row's own mpmd process.");
    pb_note("B/pstep: the particle-array bytes per particle-step the step's passes read and "
            "write (mpm_sim_traffic();");
    pb_note("  grid traffic not counted); GB/s: Mpsteps/s x B/pstep; roof: GB/s over the "
            "triad of the row's threads.");
    pb_note("cpu: CPU time over wall time of the timed runs (all threads; daemon rows: the whole "
            "mpmd), i.e. the");
    pb_note("  CPUs kept busy: below the thread count when the solver waits in serial parts, or "
            "when other");
    pb_note("  processes take the CPUs (the load average above counts them).");
}

/* Pairs of 1- and 2-thread rows behind --all's 1 -> 2 threads verdict. */
#define PB_SCALING_PAIRS 3
_Static_assert(PB_SCALING_PAIRS <= PB_MAX_RUNS, "pb_median() takes at most PB_MAX_RUNS");

/* The speed of row a over that of row b (0 when b's is 0). */
static double speed_ratio(const pb_row *a, const pb_row *b)
{
    return b->mpsteps > 0 ? a->mpsteps / b->mpsteps : 0;
}

/* "a, b, c": the n ratios with the given decimals, for a verdict line. */
static void list_ratios(char *out, size_t len, const double *r, int n, int decimals)
{
    out[0] = '\0';
    for (int k = 0, at = 0; k < n && at < (int)len - 12; k++)
        at += snprintf(out + at, len - (size_t)at, "%s%.*f", k ? ", " : "", decimals, r[k]);
}

/* One pair of disks2d rows for the lean comparison: the normal build (this
 * process) and bin/mpmbench-lean with the same steps, the lean one first
 * when lean_first (which needs c->steps set: the first pair, normal first,
 * fixes them from its normal row).  *q = lean / normal speed.  Returns 0,
 * 1 when the lean binary is not there, -1 when a row failed (reported). */
static int lean_pair(pb_cfg *c, int lean_first, double *q)
{
    pb_row nr = {0}, lr = {0};
    for (int j = 0; j < 2; j++) {
        if ((j == 0) != (lean_first != 0)) { /* the normal build's turn */
            if (measure(c, &nr)) return -1;
            if (!c->steps) c->steps = nr.steps;
            continue;
        }
        pb_progress("disks2d-lean %s USF, 1 thread", pb_method_name(c->method));
        int rc = run_lean(c, c->steps, &lr);
        if (rc == 1) return 1;
        if (rc) {
            fprintf(stderr, "mpmbench: lean run: %s\n", lr.msg);
            return -1;
        }
        show_row(&lr);
    }
    *q = speed_ratio(&lr, &nr);
    return 0;
}

static int run_all(const opts *o)
{
    static const pb_scene scenes[] = {PB_DISKS2D, PB_CUBE3D, PB_BAR1D};
    static const mpm_method methods[] = {MPM_METHOD_MPM, MPM_METHOD_GIMP};
    int failures = 0;
    pb_row rows[3][2][2]; /* scene, method, threads-1 */
    int ok[3][2][2];
    memset(ok, 0, sizeof ok);
    collecting = 1;
    preamble();
    for (int s = 0; s < 3; s++)
        for (int m = 0; m < 2; m++)
            for (int t = 0; t < 2; t++) {
                pb_cfg c = {scenes[s], methods[m], MPM_USF, o->particles,
                            o->steps,  t + 1,      0.0,     MPM_TRANSFER_FLIP};
                ok[s][m][t] = measure(&c, &rows[s][m][t]) == 0;
                failures += !ok[s][m][t];
            }
    pb_note("%s", "");
    /* 1 -> 2 threads: one pair of rows is at the mercy of a shared machine
     * (a neighbour taking a CPU for a few seconds), so each scene and method
     * runs PB_SCALING_PAIRS - 1 more pairs with the same steps as the rows
     * above (which ran 1 thread first), 2 threads first in the second pair
     * and 1 thread first in the third, and the verdict takes the median of
     * the pairs' own ratios. */
    double ratio[3][2][PB_SCALING_PAIRS];
    int npairs[3][2];
    memset(npairs, 0, sizeof npairs);
    for (int s = 0; s < 3; s++)
        for (int m = 0; m < 2; m++) {
            if (!ok[s][m][0] || !ok[s][m][1]) continue;
            ratio[s][m][npairs[s][m]++] = speed_ratio(&rows[s][m][1], &rows[s][m][0]);
        }
    pb_note("1 -> 2 threads: %d more pairs of rows of each scene and method, alternated",
            PB_SCALING_PAIRS - 1);
    for (int k = 1; k < PB_SCALING_PAIRS; k++)
        for (int s = 0; s < 3; s++)
            for (int m = 0; m < 2; m++) {
                if (!npairs[s][m]) continue;
                pb_row pr[2];
                int pok = 1;
                for (int j = 0; j < 2; j++) {
                    int t = k % 2 ? 1 - j : j; /* threads - 1 */
                    pb_cfg c = {scenes[s],           methods[m], MPM_USF, o->particles,
                                rows[s][m][t].steps, t + 1,      0.0,     MPM_TRANSFER_FLIP};
                    pok &= measure(&c, &pr[t]) == 0;
                }
                failures += !pok;
                if (pok) ratio[s][m][npairs[s][m]++] = speed_ratio(&pr[1], &pr[0]);
            }
    for (int s = 0; s < 3; s++)
        for (int m = 0; m < 2; m++) {
            int n = npairs[s][m];
            if (!n) continue;
            double q = pb_median(ratio[s][m], n);
            char each[96];
            list_ratios(each, sizeof each, ratio[s][m], n, 2);
            pb_result("%s %s: 1 -> 2 threads %.2fx (median of %d alternated pairs: %s; target >= "
                      "1.7x): %s",
                      pb_scene_name(scenes[s]), pb_method_name(methods[m]), q, n, each,
                      verdict(q >= 1.7));
        }
    for (int s = 0; s < 2; s++) /* disks2d, cube3d: speed and memory targets */
        for (int m = 0; m < 2; m++) {
            int dim = pb_scene_dim(scenes[s]);
            double target = pb_target_rate(dim, methods[m]), limit = dim == 3 ? 300 : 200;
            if (ok[s][m][1]) {
                const pb_row *r = &rows[s][m][1];
                pb_result("%s %s, 2 threads: %.2f M particle-steps/s (target >= %.0f): %s (%.2f of "
                          "target)",
                          pb_scene_name(scenes[s]), pb_method_name(methods[m]), r->mpsteps, target,
                          verdict(r->mpsteps >= target), r->mpsteps / target);
            }
            double worst = 0;
            for (int t = 0; t < 2; t++)
                if (ok[s][m][t] && rows[s][m][t].bytes_pp > worst) worst = rows[s][m][t].bytes_pp;
            if (worst > 0)
                pb_result("%s %s: %.0f bytes/particle at most (limit %.0f in %dD): %s",
                          pb_scene_name(scenes[s]), pb_method_name(methods[m]), worst, limit, dim,
                          verdict(worst <= limit));
        }
    pb_note("%s", "");

    /* sparse2d: the wide grid, then the tight one with the same steps */
    for (int m = 0; m < 2; m++)
        for (int t = 1; t <= 2; t++) {
            pb_row w, ti;
            pb_cfg c = {PB_SPARSE_WIDE, methods[m], MPM_USF, 0,
                        o->steps,       t,          0.0,     MPM_TRANSFER_FLIP};
            if (o->particles && o->particles <= 1000000L) c.particles = o->particles;
            if (measure(&c, &w)) {
                failures++;
                continue;
            }
            c.scene = PB_SPARSE_TIGHT;
            c.steps = w.steps;
            if (measure(&c, &ti)) {
                failures++;
                continue;
            }
            sparse_ratio(&w, &ti);
        }
    pb_note("%s", "");

    /* the granular collapse: Drucker-Prager against linear elasticity */
    for (int t = 1; t <= 2; t++) {
        pb_cfg c = {PB_COLLAPSE_EL,   MPM_METHOD_BSPLINE2, MPM_USF, o->particles, o->steps, t, 0.0,
                    MPM_TRANSFER_FLIP};
        failures += collapse_pair(&c) != 0;
    }
    pb_note("%s", "");

    /* the lean build on disks2d against the normal one: PB_SCALING_PAIRS
     * pairs of rows with the first normal row's steps, the lean build first
     * in the second pair; the median of the pairs' own ratios (a single
     * pair moved between 0.98 and 1.10 on a shared VM) */
    for (int m = 0; m < 2; m++) {
        pb_cfg c = {PB_DISKS2D, methods[m], MPM_USF, o->particles,
                    o->steps,   1,          0.0,     MPM_TRANSFER_FLIP};
        double q[PB_SCALING_PAIRS];
        int n = 0, rc = 0;
        for (int k = 0; k < PB_SCALING_PAIRS; k++) {
            rc = lean_pair(&c, k % 2, &q[n]);
            if (rc == 1 || (rc && !c.steps)) break; /* no lean binary; no steps to pair */
            if (rc)
                failures++;
            else
                n++;
        }
        if (rc == 1) {
            pb_result("lean build: bin/mpmbench-lean not found next to this program (or in "
                      "MPMBENCH_LEAN); `make bin/mpmbench-lean` builds it");
            break;
        }
        if (!n) continue;
        char each[96];
        list_ratios(each, sizeof each, q, n, 3);
        pb_result("disks2d %s, 1 thread: lean / normal = %.3f (median of %d alternated pairs: "
                  "%s; a feature unused should cost nothing: ~1.0)",
                  pb_method_name(methods[m]), pb_median(q, n), n, each);
    }
    pb_note("%s", "");

    /* the daemon */
#if PB_LEAN
    pb_note("daemon scene: not in the lean build");
#else
    if (pb_daemon_scene(MPM_METHOD_MPM, MPM_USF,
                        o->particles > 10000000L ? 10000000L : o->particles, o->steps, 2))
        failures++;
#endif

    pb_note("%s", "");
    pb_note("Summary against the issue's targets (load average now %.2f on %ld CPUs):", load_avg(),
            sysconf(_SC_NPROCESSORS_ONLN));
    for (int i = 0; i < nsummary; i++) pb_note("  %s", summary[i]);
    if (failures) pb_note("  %d configuration(s) failed (see the messages above)", failures);
    return failures ? 1 : 0;
}

/* --bspline: the B-splines against GIMP in the same run, interleaved (GIMP,
 * BSPLINE2, BSPLINE3 for each configuration, two rounds, the better of the
 * two kept), as speed ratios (targets: quadratic >= 0.9 of GIMP's speed,
 * cubic >= 0.5) and bytes per particle. */
static int run_bspline(const opts *o)
{
    static const pb_scene scenes[] = {PB_DISKS2D, PB_CUBE3D};
    static const mpm_method methods[] = {MPM_METHOD_GIMP, MPM_METHOD_BSPLINE2, MPM_METHOD_BSPLINE3};
    static const double target[] = {1.0, 0.9, 0.5};
    pb_row best[2][2][3];
    int ok[2][2][3], failures = 0;
    memset(ok, 0, sizeof ok);
    memset(best, 0, sizeof best);
    collecting = 1;
    preamble();
    for (int round = 0; round < 2; round++)
        for (int s = 0; s < 2; s++)
            for (int t = 0; t < 2; t++)
                for (int m = 0; m < 3; m++) {
                    pb_cfg c = {scenes[s], methods[m], MPM_USF, o->particles,
                                o->steps,  t + 1,      0.0,     MPM_TRANSFER_FLIP};
                    pb_row r;
                    if (measure(&c, &r)) {
                        failures++;
                        continue;
                    }
                    if (!ok[s][t][m] || r.mpsteps > best[s][t][m].mpsteps) best[s][t][m] = r;
                    ok[s][t][m] = 1;
                }
    pb_note("%s", "");
    for (int s = 0; s < 2; s++)
        for (int t = 0; t < 2; t++)
            for (int m = 1; m < 3; m++) {
                if (!ok[s][t][0] || !ok[s][t][m]) continue;
                const pb_row *g = &best[s][t][0], *b = &best[s][t][m];
                double q = g->mpsteps > 0 ? b->mpsteps / g->mpsteps : 0;
                pb_result("%s %s, %d thread%s: %.2f M particle-steps/s = %.2fx GIMP's %.2f "
                          "(target >= %.1fx): %s; %.0f B/particle (GIMP %.0f)",
                          pb_scene_name(scenes[s]), pb_method_name(methods[m]), t + 1, t ? "s" : "",
                          b->mpsteps, q, g->mpsteps, target[m], verdict(q >= target[m]),
                          b->bytes_pp, g->bytes_pp);
            }
    return failures ? 1 : 0;
}

/* --cpdi-vs-gimp: per scene and thread count, GIMP and CPDI rows
 * interleaved (G, C, G, C; CPDI runs the steps GIMP's first row chose, so
 * both cover the same simulated time), then the throughput ratio (the
 * mean of the two CPDI rows over the mean of the two GIMP rows) and CPDI's
 * peak bytes per particle against their targets (>= 0.4; <= 300 B in 2D,
 * 450 B in 3D). */
static int run_cpdi_vs_gimp(const opts *o)
{
    static const pb_scene scenes[] = {PB_DISKS2D, PB_CUBE3D};
    int failures = 0;
    collecting = 1;
    preamble();
    for (int si = 0; si < 2; si++)
        for (int T = 1; T <= 2; T++) {
            pb_row r[4];
            double rate[2] = {0, 0}, bpp = 0;
            long steps = o->steps;
            int bad = 0;
            for (int k = 0; k < 4 && !bad; k++) {
                pb_cfg c = {scenes[si],
                            k % 2 ? MPM_METHOD_CPDI : MPM_METHOD_GIMP,
                            o->have_update ? o->update : MPM_USF,
                            o->particles,
                            steps,
                            T,
                            0.0,
                            MPM_TRANSFER_FLIP};
                if (measure(&c, &r[k])) {
                    bad = 1;
                    break;
                }
                if (!steps) steps = r[k].steps;
                rate[k % 2] += 0.5 * r[k].mpsteps;
                if (k % 2 && r[k].bytes_pp > bpp) bpp = r[k].bytes_pp;
            }
            if (bad) {
                failures++;
                continue;
            }
            int dim = pb_scene_dim(scenes[si]);
            double q = rate[0] > 0 ? rate[1] / rate[0] : 0, lim = dim == 3 ? 450 : 300;
            pb_result("%s %s, %d thread%s: CPDI / GIMP throughput %.3f (%.2f / %.2f Mpsteps/s; "
                      "target >= 0.4): %s; CPDI %.0f B/particle (target <= %.0f): %s",
                      pb_scene_name(scenes[si]), pb_update_name(r[0].update), T, T > 1 ? "s" : "",
                      q, rate[1], rate[0], verdict(q >= 0.4), bpp, lim, verdict(bpp <= lim));
        }
    if (nsummary) {
        pb_note("\nSummary:");
        for (int i = 0; i < nsummary; i++) pb_note("  %s", summary[i]);
    }
    return failures ? 1 : 0;
}

int main(int argc, char **argv)
{
    opts o;
    signal(SIGPIPE, SIG_IGN); /* a dead child's pipe is an error, not a death */
    if (argc == 2 && !strcmp(argv[1], "--hashes")) return pb_hashes();
    int rc = parse_args(argc, argv, &o);
    if (rc) return rc > 0 ? 0 : 2;
    csv_mode = o.csv;
    int tbad = measure_triads(&o);
    if (o.triad_only) {
        machine_info();
        if (!csv_mode) {
            triad_notes();
            return tbad;
        }
        printf("triad_threads,triad_gbs,lo_gbs,hi_gbs,array_mib,reps\n");
        for (int t = 1; t <= MPM_MAX_THREADS; t++)
            if (triads[t].gbs > 0)
                printf("%d,%.3f,%.3f,%.3f,%.0f,%d\n", t, triads[t].gbs, triads[t].lo, triads[t].hi,
                       triads[t].array_mib, triads[t].reps);
        return tbad;
    }
    if (csv_mode) {
        machine_info(); /* on stderr with --csv */
        triad_notes();
    }
    if (o.all) {
        rc = run_all(&o);
    } else if (o.bspline) {
        rc = run_bspline(&o);
    } else if (o.checkpoint) {
        rc = pb_checkpoint_bench(o.particles ? o.particles : 1000000L, o.threads);
    } else if (o.cpdi_vs_gimp) {
        rc = run_cpdi_vs_gimp(&o);
    } else {
        if (!csv_mode) preamble();
        rc = run_one(&o);
    }
    for (int i = 0; i < nsummary; i++) free(summary[i]);
    return rc;
}
