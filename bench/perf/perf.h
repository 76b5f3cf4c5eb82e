/*
 * perf.h - the throughput benchmark bin/mpmbench, shared between
 * its files: mpmbench.c (command line, the table and CSV rows, `--all` and
 * the ratio lines), scenes.c (the in-process scenes built through the
 * public solver API, and the forked-child measurement that gives each
 * configuration its own peak RSS) and daemon.c (the `daemon` scene: a real
 * bin/mpmd on an ipc:// endpoint, timed from the client side).
 *
 * A row is one configuration: a warm-up run, then PB_RUNS timed runs of the
 * same number of steps; the row reports the median.  bin/mpmbench-lean is
 * the same sources compiled with -DMPM_LEAN against a solver library built
 * with -DMPM_LEAN; its rows carry the scene name with a "-lean" suffix.
 */
#ifndef PERF_H
#define PERF_H

#include <stddef.h>
#include <sys/types.h>

#include "mpm.h"
#include "mpm_diag.h"

#define PB_CSV_DIR "build/bench"
#define PB_CSV_PATH PB_CSV_DIR "/throughput.csv"
#define PB_CSV_HEADER                                                             \
    "scene,method,update,dim,particles,nodes,steps,threads,wall_s,mpsteps_per_s," \
    "bytes_per_particle,model_bytes_per_pstep,achieved_gbs,triad_gbs,roof_fraction"

#define PB_RUNS 3 /* timed runs per row (the median is reported) */
#define PB_MAX_RUNS 8
#define PB_RUN_S 2.0      /* aimed length of one timed run at the target speed */
#define PB_WARM_CAP_S 6.0 /* a default-length warm-up longer than this cuts the steps */

#define PB_MIN_PARTICLES 1000L
#define PB_MAX_PARTICLES 100000000L
#define PB_MAX_STEPS 1000000000L

#ifdef MPM_LEAN
#define PB_LEAN 1
#define PB_SUFFIX "-lean"
#else
#define PB_LEAN 0
#define PB_SUFFIX ""
#endif

/* The in-process scenes.  The two sparse2d grids are separate scenes so
 * that each has its own row; the daemon scene's in-process reference is in
 * daemon.c. */
typedef enum {
    PB_DISKS2D = 0,
    PB_CUBE3D,
    PB_BAR1D,
    PB_SPARSE_WIDE,  /* the sparse2d body in a 4096 x 4096 node grid */
    PB_SPARSE_TIGHT, /* the same body in a grid just large enough for it */
    PB_COLLAPSE_DP,  /* the granular column collapse (a = 2, Drucker-Prager, friction base) */
    PB_COLLAPSE_EL,  /* the same column, linear elastic (the reference of the DP cost) */
    PB_NSCENES
} pb_scene;

/* One configuration to measure. */
typedef struct {
    pb_scene scene;
    mpm_method method;
    mpm_update update;
    long particles; /* aimed particle count; 0: the scene's default */
    long steps;     /* steps per run; 0: the default for the target speed */
    int threads;
    double pic;            /* mpm_case.pic_fraction (0: pure FLIP) */
    mpm_transfer transfer; /* mpm_case.transfer; APIC rows carry "+apic" in the scene */
} pb_cfg;

/* The kernels every in-process scene and the daemon scene's mpmd run on
 * (mpm_case.kernels; default AUTO). */
void pb_set_kernels(mpm_kernels_isa k);
mpm_kernels_isa pb_kernels(void);

/* One measured row. */
typedef struct {
    char scene[40];
    mpm_method method;
    mpm_update update;
    int dim, threads;
    size_t particles, nodes;
    long steps;
    double wall_s;           /* median wall time of one timed run */
    double mpsteps;          /* median millions of particle-steps per second */
    double rate_lo, rate_hi; /* slowest and fastest timed run, M particle-steps/s */
    double bytes_pp;         /* peak RSS / particles */
    long rss_kb;             /* the peak RSS behind it */
    double traffic_b;        /* mpm_sim_traffic() total, bytes per particle-step (0: none) */
    double triad_gbs;        /* the triad of the row's thread count (0: not measured) */
    double setup_s;          /* building the case and the simulation */
    double cpus;             /* CPU time / wall time of the timed runs: CPUs kept busy */
    long default_steps;      /* what the defaults asked for */
    int reduced;             /* 1: the default steps were cut (slow warm-up) */
    int tcapped;             /* 1: the default steps were capped by the scene's simulated time */
    int runs;
    int rc; /* 0, or -1 with msg */
    char msg[256];
} pb_row;

/* ---- scenes.c ---- */

const char *pb_scene_name(pb_scene s);
int pb_scene_dim(pb_scene s);
long pb_scene_default_particles(pb_scene s);
const char *pb_method_name(mpm_method m);
const char *pb_update_name(mpm_update u);

/* The target speed of a dimension and method (M particle-steps/s, 2
 * threads; 1D has no target in the issue: an assumed figure for the step
 * counts only), and the default steps that make one run last about
 * PB_RUN_S at that speed. */
double pb_target_rate(int dim, mpm_method m);
long pb_default_steps(int dim, mpm_method m, size_t particles);

/* Disks of the paper: the cells per unit length that give about
 * `particles` particles at 2 x 2 per cell. */
int pb_disks_cells(long particles);

/* Measures one in-process configuration in a forked child (see
 * pb_in_child).  Returns 0 with the row filled, or -1 with row->msg. */
int pb_measure(const pb_cfg *c, pb_row *row);

/* Runs fn(arg, row) in a forked child and copies the row back through a
 * pipe; row->rss_kb and row->bytes_pp come from the child's ru_maxrss
 * (wait4).  Returns fn's result, or -1 with row->msg if the child died. */
typedef int (*pb_work_fn)(void *arg, pb_row *row);
int pb_in_child(pb_work_fn fn, void *arg, pb_row *row);

/* write() all n bytes (0, or -1); read() up to n bytes, fewer only at EOF
 * or on an error (returns the count). */
int pb_write_all(int fd, const void *buf, size_t n);
size_t pb_read_all(int fd, void *buf, size_t n);

/* ru_maxrss (KB) of a forked child that exits at once: what every child
 * starts with (the parent's resident pages). */
long pb_baseline_rss_kb(void);

/* Seconds on the monotonic clock; CPU seconds (user + system) of this
 * process, all threads. */
double pb_now(void);
double pb_cpu_self(void);

/* The median of n values (n <= PB_MAX_RUNS; the array is left alone). */
double pb_median(const double *v, int n);

/* ---- triad.c ---- */

#define PB_TRIAD_REPS 7 /* timed triad passes (the median is reported) */

/* A STREAM-style triad a = b + s c on `threads` threads (see triad.c). */
typedef struct {
    int threads, reps;
    double gbs, lo, hi; /* median, slowest and fastest pass, GB/s (24 B per element) */
    double array_mib;   /* MiB per array */
    char msg[160];
} pb_triad;

/* The largest cache of cpu0 (bytes; 0 when unknown). */
double pb_llc_bytes(void);
/* Elements per triad array: max(4 x LLC, 64 MiB), capped so that three
 * arrays fit in a quarter of the RAM; MPMBENCH_TRIAD_MIB overrides. */
size_t pb_triad_elements(void);
/* Measures the triad; 0, or -1 with out->msg. */
int pb_triad_measure(int threads, pb_triad *out);

/* ---- daemon.c ---- */

/* The daemon scene: disks2d through a real mpmd (found through MPMD_BIN,
 * else next to this executable) against the same case in-process.  Emits
 * its rows with pb_emit() and its ratio lines with pb_note().  particles
 * and steps 0: the defaults.  Returns 0, or -1 after printing why. */
int pb_daemon_scene(mpm_method m, mpm_update u, long particles, long steps, int threads);

/* ---- mpmbench.c ---- */

/* Prints a row (table or CSV) and appends it to PB_CSV_PATH. */
void pb_emit(const pb_row *r);
/* A line of the report (stdout in table mode, stderr with --csv). */
void pb_note(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* A result line (a ratio, a target met or missed): printed like pb_note()
 * and repeated in the closing summary of --all. */
void pb_result(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* "running ..." on stderr when it is a terminal (overwritten by the next
 * line of output). */
void pb_progress(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* The directory of this executable (for bin/mpmd, bin/mpmbench-lean). */
const char *pb_exe_dir(void);

/* mpmbench --checkpoint (checkpoint.c): the checkpoints' bytes per
 * particle and save and load times for ~particles particles on threads
 * threads; 0, or 1 when a scene failed or a loaded simulation did not save
 * the same blob. */
int pb_checkpoint_bench(long particles, int threads);

/* `mpmbench --hashes` (hashes.c): the same-bits harness, one line per run
 * of a fixed matrix (name and hash) on stdout.  Returns 0. */
int pb_hashes(void);

#endif
