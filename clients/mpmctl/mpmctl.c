/*
 * mpmctl.c - the command-line client of mpmd: submit cases, watch jobs
 * live, list and inspect runs, export energy series and snapshots, cancel
 * jobs, check the server.  This file holds the command line (global
 * options anywhere, per-command options checked against the command, every
 * error naming the option) and one function per command; the connection,
 * the JSON helpers, the output formats and the live view are in ctl_*.c
 * (ctl.h).  A case is loaded and checked with the protocol library (the
 * daemon's own conversion and the solver's check, under the default
 * particle limit) before
 * it is sent, so a bad case is reported with the JSON path of the field
 * without a round trip (the server checks it again).
 */
#include "ctl.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "ctl_vtk.h"
#include "mpp.h" /* MPP_VERSION: mpmctl and mpmd share the version */

volatile sig_atomic_t ctl_interrupted;

/* ---- command line ------------------------------------------------------- */

enum {
    C_SUBMIT = 1u << 0,
    C_WATCH = 1u << 1,
    C_RUNS = 1u << 2,
    C_SHOW = 1u << 3,
    C_ENERGY = 1u << 4,
    C_SNAPSHOT = 1u << 5,
    C_CANCEL = 1u << 6,
    C_PING = 1u << 7,
    C_VERSION = 1u << 8,
    C_KEYGEN = 1u << 9,
    C_EXPORT = 1u << 10,
    C_PLOT = 1u << 11,
    C_RESUME = 1u << 12,
    C_GLOBAL = 0x1fffu
};

typedef struct {
    const char *name; /* e.g. "submit" */
    unsigned bit;
    const char *args; /* synopsis */
    const char *help; /* one line */
    const char *more; /* details for `mpmctl CMD --help` */
} command;

static const command commands[] = {
    {"submit", C_SUBMIT, "CASE.json [--watch] [--csv|--json|--quiet]", "queue a simulation case",
     "Loads CASE.json (\"-\": standard input) and checks it locally with the daemon's codec:\n"
     "a bad case is reported with the JSON path of the field and nothing is sent.\n"
     "A case without \"method\" / \"update\" runs BSPLINE2 (quadratic B-splines) with MUSL,\n"
     "the schema's defaults since 0.4.0 (GIMP with MUSL before; docs/accuracy.md); both are\n"
     "sent explicitly, so any mpmd runs the same.  boundary.nodes needs MPM, GIMP or CPDI.\n"
     "Methods: MPM, GIMP, BSPLINE2 (quadratic B-splines), BSPLINE3 (cubic), CPDI (CPDI1:\n"
     "the particle domain follows its deformation gradient, for large deformation;\n"
     "docs/solver.md); updates: USF, USL, MUSL.\n"
     "\"transfer\": \"APIC\" selects the affine particle-in-cell transfer (angular momentum\n"
     "kept; \"picFraction\" must then be 0), absent or \"FLIP\" the FLIP update\n"
     "(docs/solver.md; example: proto/examples/disk2d_apic.json).\n"
     "Prints \"job N\" (--json: the SubmitOk object; --quiet: N alone, for a script:\n"
     "id=$(mpmctl submit case.json --quiet)).  --watch continues as `watch N`\n"
     "(with --csv/--json the job line goes to stderr and stdout carries the series).\n"},
    {"watch", C_WATCH, "ID [--csv|--json]", "live view of a job until it ends",
     "Subscribes to the job's stream, fetches the energy history, then follows the\n"
     "live samples; the series is complete and in order however late you start.\n"
     "On a terminal one status line (step, t, energies, progress bar, ETA) is redrawn;\n"
     "otherwise one line per energy sample.  A summary ends the view (stderr with\n"
     "--csv/--json, which print only the series: CSV rows / JSON lines).\n"
     "Exit status: 0 FINISHED, 3 FAILED, 4 CANCELLED, 5 INTERRUPTED, 1 error,\n"
     "130 stopped by Ctrl-C (the job keeps running).\n"},
    {"runs", C_RUNS, "[--status S] [--limit N] [--before ID | --all] [--json]",
     "list runs, newest first",
     "Columns: id, name, status, method, stress update, velocity transfer (FLIP or\n"
     "APIC), dim, particles, steps, wall seconds, the energy balance error (at the\n"
     "run's end, in %; '!' when it exceeded the case's budget, '-' while running or\n"
     "for runs stored before it was recorded), submission time.  --status: QUEUED,\n"
     "RUNNING, FINISHED, FAILED, CANCELLED or INTERRUPTED.  --limit: at most N runs,\n"
     "up to 10000 (the server's cap; default: the server's, 100) per page.  A cut\n"
     "listing ends with the command for the next page (--before ID: runs older than\n"
     "run ID); --all pages through every run.  --json: one RunInfo object per line.\n"
     "Control characters in names and errors are shown escaped (\\n, \\x1b).\n"},
    {"show", C_SHOW, "ID [--json] [--case]", "one run in detail",
     "Prints the status, times, counts, method and update, the velocity transfer (FLIP,\n"
     "with the PIC fraction when the case sets one, or APIC), the last energies, the\n"
     "energy balance error and the budget's warning, if any.\n"
     "--json prints the RunInfo object; --case prints the run's case as JSON (alone:\n"
     "pretty, ready to submit again; with --json: inside the RunInfo).\n"},
    {"energy", C_ENERGY, "ID [--csv|--json]", "the complete energy series of a run",
     "Pages through GetEnergy.  Default: a table; --csv: a header and one row per\n"
     "sample (exact doubles); --json: one EnergySample object per line.\n"},
    {"snapshot", C_SNAPSHOT, "ID [--step N] -o FILE [--ascii|--base64|--compress]",
     "a stored snapshot to a file",
     "Only snapshots the run recorded (output.recordSnapshots).  Without --step, the\n"
     "latest.  FILE ending in .json gets the Snapshot object; .vtp VTK XML PolyData for\n"
     "ParaView (particles as vertices; velocity, stress as a 3x3 tensor, pressure, volume,\n"
     "plastic_strain, deformation_gradient, yielded as point data, as recorded; TIME and\n"
     "STEP as field data), appended raw binary unless --ascii, --base64 or --compress\n"
     "(zlib); anything else CSV with a header (one row per particle); \"-o -\" writes CSV\n"
     "to stdout.\n"},
    {"export", C_EXPORT, "ID DIR [--format vtk|hdf5] [--grid] [--ascii|--base64|--compress]",
     "a run's snapshots for ParaView",
     "Writes every recorded snapshot as DIR/NAME_STEP.vtp (as `snapshot -o F.vtp`; STEP\n"
     "zero-padded to the largest step's width), the collection DIR/NAME.pvd with the\n"
     "simulation times (paraview DIR/NAME.pvd opens the run as a time series) and the\n"
     "energy series as DIR/energy.csv (as `energy --csv`).  --format hdf5: the snapshots\n"
     "in DIR/NAME.h5 (a group /snapshots/STEP per snapshot, one dataset per field) with\n"
     "DIR/NAME.xdmf (XDMF 3: paraview DIR/NAME.xdmf) instead of .vtp and .pvd.\n"
     "--grid adds the case's background grid as DIR/grid.vti (ImageData).  NAME is the\n"
     "run's name with bytes other than A-Z a-z 0-9 . _ - replaced by _ (\"runID\" when\n"
     "empty).  DIR is created if missing.  The run must have recorded snapshots\n"
     "(output.snapshotEvery > 0 and output.recordSnapshots: true).\n"},
    {"plot", C_PLOT, "ID -o FILE [--terminal T]", "draw the energy curves with gnuplot",
     "Kinetic, strain and total energy against t, and the energy balance error (%) in a\n"
     "second panel.  The format follows FILE's extension (.png, .svg, .pdf) unless\n"
     "--terminal names a gnuplot terminal (e.g. \"pngcairo size 1600,1000\").  Needs\n"
     "gnuplot (Debian: gnuplot-nox).\n"},
    {"resume", C_RESUME, "ID [--watch] [--csv|--json|--quiet]",
     "continue an interrupted run from its checkpoint",
     "A run INTERRUPTED by a crash (kill -9, power loss) or a daemon restart goes on\n"
     "from the last checkpoint mpmd saved of it (Case.checkpoint, or the daemon's\n"
     "--checkpoint-every-s; at a clean shutdown always): the energy samples and\n"
     "snapshots recorded after it are computed again, identically with the same\n"
     "solver threads.  Refused (exit 1) for a run that is not INTERRUPTED, has no\n"
     "checkpoint, or whose checkpoint file is damaged (it stays INTERRUPTED).\n"
     "Prints \"job N\" (N: the run's id; --json: the SubmitOk object; --quiet: N).  --watch\n"
     "continues as `watch N`, with its exit status.\n"},
    {"cancel", C_CANCEL, "ID [--json]", "stop a queued or running job",
     "Prints the job's status after the request; a running job stops within one step.\n"},
    {"ping", C_PING, "[--json]", "check the server",
     "Prints the server version, schema version, stream endpoint and round-trip time.\n"},
    {"version", C_VERSION, "[--json]", "versions of mpmctl and of the server", ""},
    {"keygen", C_KEYGEN, "[--out DIR] [--name NAME]", "make a CURVE keypair",
     "Writes DIR/NAME.key (the secret key, mode 0600) and DIR/NAME.pub (the public\n"
     "key) as Z85 text; DIR defaults to the current directory (made with any\n"
     "missing parents, mode 0700), NAME to \"mpmd\".  Never overwrites a key.\n"
     "Prints the public key.\n"
     "A client: keygen --out ~/.config/mpmd, then put the server's public key in\n"
     "~/.config/mpmd/server.pub and give your mpmd.pub to the server's admin (manual:\n"
     "Security).  A server: keygen --out /etc/mpmd --name server, then mpmd\n"
     "--curve-secret /etc/mpmd/server.key --authorized-keys FILE|DIR.\n"},
};
#define NCOMMANDS (sizeof commands / sizeof commands[0])

typedef enum {
    O_ENDPOINT,
    O_STREAM,
    O_TIMEOUT,
    O_HELP,
    O_WATCH,
    O_CSV,
    O_JSON,
    O_STATUS,
    O_LIMIT,
    O_BEFORE,
    O_ALL,
    O_CASE,
    O_STEP,
    O_OUT,
    O_KEYS,
    O_NAME,
    O_GRID,
    O_ASCII,
    O_BASE64,
    O_COMPRESS,
    O_VTK_COMPRESS,
    O_TERMINAL,
    O_FORMAT,
    O_QUIET,
    O_COUNT
} opt_id;

typedef struct {
    const char *name; /* long name */
    char shortname;   /* 0: none */
    int has_arg;
    unsigned cmds; /* commands that take it (C_GLOBAL: all) */
} option;

static const option options[O_COUNT] = {
    [O_ENDPOINT] = {"endpoint", 0, 1, C_GLOBAL},
    [O_STREAM] = {"stream", 0, 1, C_GLOBAL},
    [O_TIMEOUT] = {"timeout", 0, 1, C_GLOBAL},
    [O_HELP] = {"help", 'h', 0, C_GLOBAL},
    [O_WATCH] = {"watch", 0, 0, C_SUBMIT | C_RESUME},
    [O_CSV] = {"csv", 0, 0, C_SUBMIT | C_RESUME | C_WATCH | C_ENERGY},
    [O_JSON] = {"json", 0, 0, C_GLOBAL & ~(C_SNAPSHOT | C_EXPORT | C_PLOT)},
    [O_STATUS] = {"status", 0, 1, C_RUNS},
    [O_LIMIT] = {"limit", 0, 1, C_RUNS},
    [O_BEFORE] = {"before", 0, 1, C_RUNS},
    [O_ALL] = {"all", 0, 0, C_RUNS},
    [O_CASE] = {"case", 0, 0, C_SHOW},
    [O_STEP] = {"step", 0, 1, C_SNAPSHOT},
    [O_OUT] = {"out", 'o', 1, C_SNAPSHOT | C_KEYGEN | C_PLOT},
    [O_KEYS] = {"keys", 0, 1, C_GLOBAL & ~C_KEYGEN},
    [O_NAME] = {"name", 0, 1, C_KEYGEN},
    [O_GRID] = {"grid", 0, 0, C_EXPORT},
    [O_ASCII] = {"ascii", 0, 0, C_SNAPSHOT | C_EXPORT},
    [O_BASE64] = {"base64", 0, 0, C_SNAPSHOT | C_EXPORT},
    [O_COMPRESS] = {"compress", 0, 0, C_SNAPSHOT | C_EXPORT},
    [O_VTK_COMPRESS] = {"vtk-compress", 0, 0, C_SNAPSHOT | C_EXPORT}, /* = --compress */
    [O_TERMINAL] = {"terminal", 0, 1, C_PLOT},
    [O_FORMAT] = {"format", 0, 1, C_EXPORT},
    [O_QUIET] = {"quiet", 'q', 0, C_SUBMIT | C_RESUME},
};

typedef struct {
    const command *cmd;
    int given[O_COUNT];
    const char *val[O_COUNT];
    const char *pos[8];
    int npos;
    /* parsed values */
    double timeout;
    ctl_out fmt;
    int status;
    unsigned limit;
    uint64_t before;
    long long step;
} cli;

static void usage(FILE *f)
{
    fprintf(f, "usage: mpmctl [OPTIONS] COMMAND [ARGS] [OPTIONS]\n\nCommands:\n");
    for (size_t i = 0; i < NCOMMANDS; i++) {
        char syn[96];
        snprintf(syn, sizeof syn, "%s %s", commands[i].name, commands[i].args);
        fprintf(f, "  %-48s %s\n", syn, commands[i].help);
    }
    fprintf(f,
            "\nOptions (anywhere on the line):\n"
            "  --endpoint EP   control socket (env MPMD_ENDPOINT; default %s)\n"
            "  --stream EP     stream socket (env MPMD_STREAM; default: as the server reports,\n"
            "                  or derived from the endpoint: tcp port + 1, ipc path + .stream)\n"
            "  --timeout S     seconds to wait for each reply (default %g)\n"
            "  --keys DIR      CURVE keys: DIR/server.pub (the server's public key) and\n"
            "                  DIR/mpmd.key (yours; env MPMD_KEYS; default ~/.config/mpmd\n"
            "                  if it exists, for a non-loopback endpoint); env\n"
            "                  MPMD_SERVER_KEY (a key or a file) and\n"
            "                  MPMD_CLIENT_KEY (your secret key file) override them\n"
            "  -h, --help      this help; `mpmctl COMMAND --help` for one command\n"
            "\nExit status: 0 success, 1 error, 2 bad command line; watch, submit --watch and\n"
            "resume --watch:\n"
            "3 FAILED, 4 CANCELLED, 5 INTERRUPTED.\n",
            CTL_DEFAULT_ENDPOINT, CTL_DEFAULT_TIMEOUT);
}

static void command_usage(const command *c)
{
    printf("usage: mpmctl %s %s\n  %s\n\n%s", c->name, c->args, c->help, c->more);
    printf("\nGlobal options: --endpoint EP, --stream EP, --timeout S, --keys DIR (see mpmctl "
           "--help).\n");
}

__attribute__((format(printf, 1, 2))) static int bad_usage(const char *fmt, ...)
{
    va_list ap;
    fputs("mpmctl: ", stderr);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fputc('\n', stderr);
    return CTL_EUSAGE;
}

static const option *find_long(const char *name, size_t len, opt_id *id)
{
    for (int i = 0; i < O_COUNT; i++)
        if (strlen(options[i].name) == len && !strncmp(options[i].name, name, len)) {
            *id = (opt_id)i;
            return &options[i];
        }
    return NULL;
}

static const option *find_short(char c, opt_id *id)
{
    for (int i = 0; i < O_COUNT; i++)
        if (options[i].shortname == c) {
            *id = (opt_id)i;
            return &options[i];
        }
    return NULL;
}

/* A positive decimal id. */
static int parse_id(const char *s, const char *what, uint64_t *id)
{
    char *end;
    unsigned long long v;
    errno = 0;
    if (*s < '0' || *s > '9') goto bad;
    v = strtoull(s, &end, 10);
    if (errno || *end || v == 0) goto bad;
    *id = v;
    return 0;
bad:
    return bad_usage("%s: '%s' is not a %s (a positive integer)", what, s, "job id");
}

static int parse_args(int argc, char **argv, cli *a)
{
    int only_pos = 0;
    memset(a, 0, sizeof *a);
    for (int i = 1; i < argc; i++) {
        const char *s = argv[i];
        const option *o = NULL;
        opt_id id = O_HELP;
        const char *val = NULL;
        if (!only_pos && !strcmp(s, "--")) {
            only_pos = 1;
            continue;
        }
        if (!only_pos && s[0] == '-' && s[1]) {
            if (s[1] == '-') {
                const char *eq = strchr(s + 2, '=');
                size_t len = eq ? (size_t)(eq - s - 2) : strlen(s + 2);
                o = find_long(s + 2, len, &id);
                if (!o)
                    return bad_usage("unknown option '%.*s' (see mpmctl --help)", (int)(len + 2),
                                     s);
                if (eq && !o->has_arg) return bad_usage("option --%s takes no value", o->name);
                if (eq) val = eq + 1;
            } else {
                o = s[2] ? NULL : find_short(s[1], &id);
                if (!o) return bad_usage("unknown option '%s' (see mpmctl --help)", s);
            }
            if (o->has_arg && !val) {
                if (i + 1 >= argc) return bad_usage("option --%s needs a value", o->name);
                val = argv[++i];
            }
            /* given twice: the last one counts (scripts may append overrides) */
            a->given[id] = 1;
            a->val[id] = val;
            continue;
        }
        if (!a->cmd) {
            for (size_t k = 0; k < NCOMMANDS; k++)
                if (!strcmp(commands[k].name, s)) a->cmd = &commands[k];
            if (!a->cmd) return bad_usage("unknown command '%s' (see mpmctl --help)", s);
            continue;
        }
        if (a->npos == (int)(sizeof a->pos / sizeof a->pos[0]))
            return bad_usage("%s: too many arguments", a->cmd->name);
        a->pos[a->npos++] = s;
    }
    if (a->given[O_HELP]) return 0;
    if (!a->cmd) return bad_usage("no command given (see mpmctl --help)");
    for (int i = 0; i < O_COUNT; i++)
        if (a->given[i] && !(options[i].cmds & a->cmd->bit))
            return bad_usage("option --%s does not apply to '%s' (see mpmctl %s --help)",
                             options[i].name, a->cmd->name, a->cmd->name);

    /* values */
    a->timeout = CTL_DEFAULT_TIMEOUT;
    if (a->given[O_TIMEOUT]) {
        char *end;
        errno = 0;
        a->timeout = strtod(a->val[O_TIMEOUT], &end);
        if (errno || end == a->val[O_TIMEOUT] || *end || !(a->timeout > 0) || a->timeout > 86400)
            return bad_usage("--timeout: expected seconds in (0, 86400], got '%s'",
                             a->val[O_TIMEOUT]);
    }
    if (a->given[O_CSV] && a->given[O_JSON])
        return bad_usage("--csv and --json exclude each other");
    a->fmt = a->given[O_CSV] ? CTL_OUT_CSV : a->given[O_JSON] ? CTL_OUT_JSON : CTL_OUT_TEXT;
    if (a->given[O_QUIET] && (a->given[O_CSV] || a->given[O_JSON] || a->given[O_WATCH]))
        return bad_usage("%s: --quiet excludes --watch, --csv and --json", a->cmd->name);
    if ((a->cmd->bit & (C_SUBMIT | C_RESUME)) && a->given[O_CSV] && !a->given[O_WATCH])
        return bad_usage("%s: --csv needs --watch", a->cmd->name);
    if (a->given[O_STATUS]) {
        char up[32];
        size_t k;
        for (k = 0; k + 1 < sizeof up && a->val[O_STATUS][k]; k++) {
            char ch = a->val[O_STATUS][k];
            up[k] = (ch >= 'a' && ch <= 'z') ? (char)(ch - 32) : ch;
        }
        up[k] = 0;
        a->status = mpp_status_from_name(up);
        if (!a->status)
            return bad_usage("--status: '%s' is not one of QUEUED, RUNNING, FINISHED, FAILED, "
                             "CANCELLED, INTERRUPTED",
                             a->val[O_STATUS]);
    }
    if (a->given[O_LIMIT]) {
        char *end;
        unsigned long v;
        errno = 0;
        v = strtoul(a->val[O_LIMIT], &end, 10);
        if (errno || end == a->val[O_LIMIT] || *end || v == 0 || v > CTL_LIST_MAX ||
            a->val[O_LIMIT][0] == '-')
            return bad_usage("--limit: expected a positive integer up to %u (the server's cap), "
                             "got '%s'",
                             CTL_LIST_MAX, a->val[O_LIMIT]);
        a->limit = (unsigned)v;
    }
    if (a->given[O_BEFORE] && a->given[O_ALL])
        return bad_usage("runs: --before and --all exclude each other");
    if (a->given[O_BEFORE] && parse_id(a->val[O_BEFORE], "--before", &a->before))
        return CTL_EXIT_USAGE;
    if (a->given[O_STEP]) {
        char *end;
        errno = 0;
        a->step = strtoll(a->val[O_STEP], &end, 10);
        if (errno || end == a->val[O_STEP] || *end || a->step < 0)
            return bad_usage("--step: expected a step number (>= 0), got '%s'", a->val[O_STEP]);
    }
    if (a->cmd->bit == C_SNAPSHOT && !a->given[O_OUT])
        return bad_usage("snapshot: -o FILE is required (\"-o -\": CSV to stdout)");
    if (a->cmd->bit == C_PLOT && !a->given[O_OUT])
        return bad_usage("plot: -o FILE is required (e.g. -o energy.png)");
    if (a->given[O_VTK_COMPRESS]) a->given[O_COMPRESS] = 1;
    if (a->given[O_ASCII] + a->given[O_BASE64] + a->given[O_COMPRESS] > 1)
        return bad_usage("%s: --ascii, --base64 and --compress exclude each other", a->cmd->name);
    if (a->given[O_FORMAT] && strcmp(a->val[O_FORMAT], "vtk") && strcmp(a->val[O_FORMAT], "hdf5"))
        return bad_usage("export: --format: expected vtk or hdf5, got '%s'", a->val[O_FORMAT]);
    if (a->given[O_FORMAT] && !strcmp(a->val[O_FORMAT], "hdf5") &&
        (a->given[O_ASCII] || a->given[O_BASE64] || a->given[O_COMPRESS]))
        return bad_usage("export: --ascii, --base64 and --compress are for --format vtk");
    if (a->cmd->bit == C_SNAPSHOT &&
        (a->given[O_ASCII] || a->given[O_BASE64] || a->given[O_COMPRESS])) {
        size_t pl = strlen(a->val[O_OUT]);
        if (pl <= 4 || strcmp(a->val[O_OUT] + pl - 4, ".vtp"))
            return bad_usage("snapshot: --ascii, --base64 and --compress are for a .vtp file");
    }

    /* positional arguments */
    {
        int want = (a->cmd->bit & (C_RUNS | C_PING | C_VERSION | C_KEYGEN)) ? 0
                   : a->cmd->bit == C_EXPORT                                ? 2
                                                                            : 1;
        if (a->npos < want)
            return bad_usage("%s needs %s (see mpmctl %s --help)", a->cmd->name,
                             a->cmd->bit == C_SUBMIT   ? "a case file"
                             : a->cmd->bit == C_EXPORT ? "a run id and a directory"
                             : a->cmd->bit == C_RESUME ? "a run id"
                                                       : "a job id",
                             a->cmd->name);
        if (a->npos > want)
            return bad_usage("%s: unexpected argument '%s'", a->cmd->name, a->pos[want]);
    }
    return 0;
}

/* ---- helpers ---------------------------------------------------------------- */

static char *slurp(const char *path, size_t *len)
{
    FILE *f = strcmp(path, "-") ? fopen(path, "rb") : stdin;
    char *buf = NULL;
    size_t cap = 0, n = 0;
    if (!f) return NULL;
    for (;;) {
        if (n + 65536 + 1 > cap) {
            size_t nc = cap ? cap * 2 : 131072;
            char *nb = realloc(buf, nc);
            if (!nb) {
                free(buf);
                buf = NULL;
                errno = ENOMEM;
                break;
            }
            buf = nb;
            cap = nc;
        }
        size_t r = fread(buf + n, 1, cap - n - 1, f);
        n += r;
        if (r == 0) {
            if (ferror(f)) {
                free(buf);
                buf = NULL;
            }
            break;
        }
    }
    if (f != stdin) fclose(f);
    if (buf) {
        buf[n] = 0;
        *len = n;
    }
    return buf;
}

static int out_json_line(const json_t *v)
{
    if (cj_print(stdout, v, 0)) return CTL_ESYS;
    fputc('\n', stdout);
    return 0;
}

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

/* Exit status for a watched run's final status. */
static int exit_for_status(int st)
{
    switch (st) {
    case MPP_STATUS_FINISHED: return CTL_EXIT_OK;
    case MPP_STATUS_FAILED: return CTL_EXIT_FAILED;
    case MPP_STATUS_CANCELLED: return CTL_EXIT_CANCELLED;
    default: return CTL_EXIT_INTERRUPTED;
    }
}

static int exit_for_rc(int rc)
{
    if (rc == CTL_EUSAGE) return CTL_EXIT_USAGE;
    if (rc == CTL_EINTR) return CTL_EXIT_SIGNAL;
    return rc ? CTL_EXIT_ERROR : CTL_EXIT_OK;
}

/* ---- commands ------------------------------------------------------------------ */

static int do_watch(ctl_conn *c, uint64_t job, ctl_out fmt)
{
    int st = 0, rc = ctl_watch(c, job, fmt, &st);
    if (rc) return exit_for_rc(rc);
    return exit_for_status(st);
}

static int submitted(ctl_conn *c, json_t *ok, const cli *a);

static int cmd_submit(ctl_conn *c, const cli *a)
{
    const char *path = a->pos[0];
    size_t len = 0;
    char err[MPM_ERROR_MSG_MAX + 256];
    mpm_error e;
    char *text = slurp(path, &len);
    Mpmd__Case *pb = NULL;
    mpp_case *sc = NULL;
    mpp_request rq = {.kind = MPP_REQ_SUBMIT};
    json_t *reply = NULL, *ok = NULL;
    int rc;
    if (!text) {
        fprintf(stderr, "mpmctl: cannot read %s: %s\n", path, strerror(errno));
        return CTL_EXIT_ERROR;
    }
    rc = mpp_case_from_json(text, len, &pb, &e);
    free(text);
    if (!rc) rc = mpp_case_from_pb(pb, 0, &sc, &e);
    mpp_case_destroy(&sc);
    if (rc) {
        fprintf(stderr, "mpmctl: %s: %s\n", path,
                mpm_error_text(&e, MPM_FIELD_JSON, err, sizeof err));
        mpp_case_pb_free(&pb);
        return CTL_EXIT_ERROR;
    }
    /* the case means what this client's schema says, whatever the server's
     * defaults */
    mpp_case_pin_defaults(pb);
    rq.case_pb = pb;
    rc = ctl_call(c, &rq, "submitOk", &reply, &ok);
    mpp_case_pb_free(&pb);
    if (rc) {
        json_decref(reply);
        return exit_for_rc(rc);
    }
    rc = submitted(c, ok, a);
    json_decref(reply);
    return rc;
}

/* The rest of submit and resume: prints the SubmitOk (or, with --watch,
 * watches the job); an exit status. */
static int submitted(ctl_conn *c, json_t *ok, const cli *a)
{
    int rc = 0;
    uint64_t job = cj_u64(ok, "jobId", 0);
    if (!job) {
        fprintf(stderr, "mpmctl: the server's SubmitOk has no job id\n");
        return CTL_EXIT_ERROR;
    }
    if (a->given[O_WATCH] && a->fmt != CTL_OUT_TEXT) {
        fprintf(stderr, "job %llu\n", (unsigned long long)job);
    } else if (a->fmt == CTL_OUT_JSON) {
        rc = out_json_line(ok);
    } else if (a->given[O_QUIET]) {
        printf("%llu\n", (unsigned long long)job);
    } else {
        printf("job %llu\n", (unsigned long long)job);
    }
    fflush(stdout);
    if (rc) return CTL_EXIT_ERROR;
    if (a->given[O_WATCH]) return do_watch(c, job, a->fmt);
    return CTL_EXIT_OK;
}

static int cmd_resume(ctl_conn *c, const cli *a)
{
    mpp_request rq = {.kind = MPP_REQ_RESUME};
    json_t *reply = NULL, *ok = NULL;
    if (parse_id(a->pos[0], "resume", &rq.id)) return CTL_EXIT_USAGE;
    int rc = ctl_call(c, &rq, "submitOk", &reply, &ok);
    if (!rc)
        rc = submitted(c, ok, a);
    else
        rc = exit_for_rc(rc);
    json_decref(reply);
    return rc;
}

static int cmd_watch(ctl_conn *c, const cli *a)
{
    uint64_t job;
    if (parse_id(a->pos[0], "watch", &job)) return CTL_EXIT_USAGE;
    return do_watch(c, job, a->fmt);
}

/* One page of `runs`: prints it (the header once, on the first page that
 * has runs) and stores the cursor of the next page in *next (0: none). */
static int runs_page(ctl_conn *c, const cli *a, uint64_t before, int *header, size_t *shown,
                     uint64_t *next)
{
    mpp_request rq = {
        .kind = MPP_REQ_LIST_RUNS, .status = a->status, .limit = a->limit, .before_id = before};
    json_t *reply = NULL, *list = NULL, *runs;
    int rc = ctl_call(c, &rq, "runs", &reply, &list);
    size_t i, n;
    *next = 0;
    if (rc) {
        json_decref(reply);
        return exit_for_rc(rc);
    }
    runs = json_object_get(list, "runs");
    n = json_is_array(runs) ? json_array_size(runs) : 0;
    *next = cj_u64(list, "nextBeforeRunId", 0);
    if (a->fmt == CTL_OUT_JSON) {
        for (i = 0; i < n && !rc; i++) rc = out_json_line(json_array_get(runs, i));
    } else if (n) {
        if (!*header)
            printf("%6s  %-20s %-11s %-8s %-6s %-8s %3s %10s %12s %9s %9s  %s\n", "ID", "NAME",
                   "STATUS", "METHOD", "UPDATE", "TRANSFER", "DIM", "PARTICLES", "STEPS", "WALL S",
                   "BALANCE", "SUBMITTED");
        *header = 1;
        for (i = 0; i < n; i++) {
            json_t *r = json_array_get(runs, i);
            char when[32], name[128], bal[32];
            ctl_fmt_time(when, sizeof when, cj_num(r, "submittedAt", 0));
            ctl_fmt_balance(bal, sizeof bal, r);
            printf("%6llu  %-20.20s %-11s %-8s %-6s %-8s %3lld %10llu %12lld %9.2f %9s  %s\n",
                   (unsigned long long)cj_u64(r, "runId", 0),
                   ctl_esc(cj_str(r, "name", ""), name, sizeof name), cj_str(r, "status", "?"),
                   cj_str(r, "method", "?"), cj_str(r, "update", "?"), cj_str(r, "transfer", "?"),
                   cj_int(r, "dim", 0), (unsigned long long)cj_u64(r, "particles", 0),
                   cj_int(r, "steps", 0), cj_num(r, "wallS", 0), bal, when);
        }
    }
    *shown += n;
    json_decref(reply);
    return rc ? CTL_EXIT_ERROR : CTL_EXIT_OK;
}

static int cmd_runs(ctl_conn *c, const cli *a)
{
    int header = 0, rc;
    size_t shown = 0;
    uint64_t before = a->before, next = 0;
    for (;;) {
        rc = runs_page(c, a, before, &header, &shown, &next);
        if (rc || !next || !a->given[O_ALL]) break;
        before = next;
    }
    if (rc) return rc;
    if (a->fmt != CTL_OUT_JSON && !shown)
        printf("no runs%s%s\n", a->status ? " with status " : "",
               a->status ? mpp_status_name(a->status) : "");
    /* a cut listing says how to go on (stderr: stdout keeps the table) */
    if (next && !a->given[O_ALL])
        fprintf(stderr, "mpmctl: more runs: mpmctl runs --before %llu (or --all)\n",
                (unsigned long long)next);
    return CTL_EXIT_OK;
}

/* The steps a run planned, from its case: the step count, or endTime / dt
 * with a fixed dt; 0 when unknown (automatic dt). */
static long long planned_steps(const json_t *cs)
{
    if (!cs) return 0;
    if (cj_int(cs, "steps", 0) > 0) return cj_int(cs, "steps", 0);
    double dt = cj_num(cs, "dt", 0), end = cj_num(cs, "endTime", 0);
    if (dt > 0 && end > 0 && end / dt < 9e18) return (long long)ceil(end / dt - 0.5);
    return 0;
}

static void show_text(const json_t *r)
{
    char b[64];
    const json_t *cs = json_object_get(r, "case");
    const json_t *le = json_object_get(r, "lastEnergy");
    const json_t *snaps = json_object_get(r, "snapshotSteps");
    const char *err = cj_str(r, "error", "");
    char name[2048], etext[4096];
    printf("run %llu (job %llu)%s%s\n", (unsigned long long)cj_u64(r, "runId", 0),
           (unsigned long long)cj_u64(r, "jobId", 0), *cj_str(r, "name", "") ? ": " : "",
           ctl_esc(cj_str(r, "name", ""), name, sizeof name));
    printf("  status      %s\n", cj_str(r, "status", "?"));
    if (*err) printf("  error       %s\n", ctl_esc(err, etext, sizeof etext));
    ctl_fmt_time(b, sizeof b, cj_num(r, "submittedAt", 0));
    printf("  submitted   %s\n", b);
    if (*cj_str(r, "owner", "")) {
        char ob[256];
        printf("  owner       %s\n", ctl_esc(cj_str(r, "owner", ""), ob, sizeof ob));
    }
    ctl_fmt_time(b, sizeof b, cj_num(r, "startedAt", 0));
    printf("  started     %s\n", b);
    ctl_fmt_time(b, sizeof b, cj_num(r, "finishedAt", 0));
    printf("  finished    %s\n", b);
    /* steps done, then planned: the server's figure (a live or finished
     * run), else the case's (a run that stopped early) */
    long long plan = cj_int(r, "stepsTotal", 0);
    if (plan <= 0) plan = planned_steps(cs);
    printf("  steps       %lld", cj_int(r, "steps", 0));
    if (plan > 0) printf(" of %lld", plan);
    printf("\n  t           %.10g\n", cj_num(r, "t", 0));
    ctl_fmt_duration(b, sizeof b, cj_num(r, "wallS", 0));
    printf("  wall        %s\n", b);
    printf("  particles   %llu\n  nodes       %llu\n  dim         %lld\n",
           (unsigned long long)cj_u64(r, "particles", 0), (unsigned long long)cj_u64(r, "nodes", 0),
           cj_int(r, "dim", 0));
    printf("  method      %s, %s", cj_str(r, "method", "?"), cj_str(r, "update", "?"));
    if (cs) {
        double dt = cj_num(cs, "dt", 0);
        if (dt > 0)
            printf(", dt %.10g%s\n", dt,
                   json_is_true(json_object_get(cs, "allowUnstableDt")) ? " (unstable allowed)"
                                                                        : "");
        else
            printf(", automatic dt (CFL %g)\n",
                   cj_num(cs, "cfl", 0) > 0 ? cj_num(cs, "cfl", 0) : 0.5);
    } else {
        putchar('\n');
    }
    printf("  transfer    %s", cj_str(r, "transfer", "?"));
    if (cs && !strcmp(cj_str(r, "transfer", ""), "FLIP") && cj_num(cs, "picFraction", 0) > 0)
        printf(" (PIC fraction %g)", cj_num(cs, "picFraction", 0));
    putchar('\n');
    if (cs) {
        if (json_object_get(cs, "endTime"))
            printf("  stop        at t = %.10g\n", cj_num(cs, "endTime", 0));
        else
            printf("  stop        after %lld steps\n", cj_int(cs, "steps", 0));
    }
    if (json_object_get(r, "checkpointStep"))
        printf("  checkpoint  step %lld, t %.10g\n", cj_int(r, "checkpointStep", 0),
               cj_num(r, "checkpointT", 0));
    if (cj_u64(r, "resumes", 0))
        printf("  resumed     %llu time%s\n", (unsigned long long)cj_u64(r, "resumes", 0),
               cj_u64(r, "resumes", 0) > 1 ? "s" : "");
    printf("  energy      %llu samples\n", (unsigned long long)cj_u64(r, "energySamples", 0));
    if (le) {
        printf("  last energy step %lld, t %.10g: kinetic %.10e, strain %.10e, potential %.10e, "
               "external work %.10e, total %.10e\n",
               cj_int(le, "step", 0), cj_num(le, "t", 0), cj_num(le, "kinetic", NAN),
               cj_num(le, "strain", NAN), cj_num(le, "potential", NAN),
               cj_num(le, "externalWork", NAN), cj_num(le, "total", NAN));
        static const char *const works[][2] = {{"plasticWork", "plastic work"},
                                               {"dampingWork", "damping work"},
                                               {"frictionWork", "friction work"},
                                               {"prescribedWork", "prescribed work"}};
        int any = 0;
        for (size_t k = 0; k < sizeof works / sizeof works[0]; k++)
            if (cj_num(le, works[k][0], 0) != 0)
                printf("%s%s %.10e", any++ ? ", " : "              ", works[k][1],
                       cj_num(le, works[k][0], 0));
        if (any) putchar('\n');
    }
    {
        char bal[32];
        ctl_fmt_balance(bal, sizeof bal, r);
        if (json_object_get(r, "balanceError"))
            printf("  balance     error %s (at the end of the run; each sample carries its own)\n",
                   bal);
        else if (le && json_object_get(le, "balanceError"))
            printf("  balance     error %.3g %% (last sample)\n",
                   100 * cj_num(le, "balanceError", 0));
        if (*cj_str(r, "warning", "")) printf("  warning     %s\n", cj_str(r, "warning", ""));
    }
    if (*cj_str(r, "plan", "")) printf("  plan        %s\n", cj_str(r, "plan", ""));
    if (json_is_array(snaps) && json_array_size(snaps)) {
        size_t n = json_array_size(snaps);
        printf("  snapshots   %zu stored, steps", n);
        for (size_t i = 0; i < n && i < 20; i++)
            printf(" %lld", (long long)cj_at(r, "snapshotSteps", i, 0));
        printf("%s\n", n > 20 ? " ..." : "");
    } else {
        printf("  snapshots   none stored\n");
    }
}

static int cmd_show(ctl_conn *c, const cli *a)
{
    mpp_request rq = {.kind = MPP_REQ_GET_RUN};
    json_t *reply = NULL, *run = NULL;
    uint64_t id;
    int rc;
    if (parse_id(a->pos[0], "show", &id)) return CTL_EXIT_USAGE;
    rq.id = id;
    rq.with_case = a->given[O_CASE] || a->fmt == CTL_OUT_TEXT;
    rc = ctl_call(c, &rq, "run", &reply, &run);
    if (rc) {
        json_decref(reply);
        return exit_for_rc(rc);
    }
    if (a->fmt == CTL_OUT_JSON) {
        rc = out_json_line(run);
    } else if (a->given[O_CASE]) {
        json_t *cs = json_object_get(run, "case");
        if (!cs) {
            fprintf(stderr, "mpmctl: the server sent run %llu without its case\n",
                    (unsigned long long)id);
            rc = CTL_EPROTO;
        } else if (!(rc = cj_print(stdout, cs, 1))) {
            fputc('\n', stdout);
        }
    } else {
        show_text(run);
    }
    json_decref(reply);
    return rc ? CTL_EXIT_ERROR : CTL_EXIT_OK;
}

static int energy_row(const mpm_energy_sample *s, void *arg)
{
    return ctl_energy_out_row(arg, s);
}

static int cmd_energy(ctl_conn *c, const cli *a)
{
    ctl_energy_out eo;
    uint64_t id;
    int rc;
    if (parse_id(a->pos[0], "energy", &id)) return CTL_EXIT_USAGE;
    ctl_energy_out_init(&eo, a->fmt, 0, stdout);
    rc = ctl_fetch_energy(c, id, 0, energy_row, &eo);
    if (!rc && !eo.header_done && a->fmt == CTL_OUT_TEXT)
        fprintf(stderr, "run %llu has no energy samples\n", (unsigned long long)id);
    if (fflush(stdout) || ferror(stdout)) {
        fprintf(stderr, "mpmctl: cannot write the series: %s\n", strerror(errno));
        rc = CTL_ESYS;
    }
    return exit_for_rc(rc);
}

/* CSV of a snapshot: a header naming the fields present, a row per
 * particle (the decoder has checked that every array holds n times its
 * width). */
static int snapshot_csv(FILE *f, const mpp_snapshot *s)
{
    static const char *const ax[3] = {"x", "y", "z"};
    static const char *const voigt[6] = {"sxx", "syy", "szz", "sxy", "syz", "sxz"};
    size_t n = s->n, dim = s->dim > 0 ? (size_t)s->dim : 0;
    char b[40];
    if ((s->x || s->v || s->deformation_gradient) && (dim < 1 || dim > 3)) {
        fprintf(stderr, "mpmctl: the snapshot's arrays do not match n = %zu, dim = %zu\n", n, dim);
        return CTL_EPROTO;
    }
    fputs("i", f);
    if (s->x)
        for (size_t d = 0; d < dim; d++) fprintf(f, ",%s", ax[d]);
    if (s->v)
        for (size_t d = 0; d < dim; d++) fprintf(f, ",v%s", ax[d]);
    if (s->stress)
        for (int k = 0; k < 6; k++) fprintf(f, ",%s", voigt[k]);
    if (s->pressure) fputs(",pressure", f);
    if (s->mean_stress) fputs(",mean_stress", f);
    if (s->volume) fputs(",volume", f);
    if (s->plastic_strain) fputs(",plastic_strain", f);
    if (s->deformation_gradient)
        for (size_t a = 0; a < dim; a++)
            for (size_t d = 0; d < dim; d++) fprintf(f, ",F%s%s", ax[a], ax[d]);
    if (s->yielded) fputs(",yielded", f);
    fputc('\n', f);
#define CELL(v)                                 \
    do {                                        \
        cj_fmt_double(b, sizeof b, cj_norm(v)); \
        fputc(',', f);                          \
        fputs(b, f);                            \
    } while (0)
    for (size_t i = 0; i < n; i++) {
        fprintf(f, "%zu", i);
        if (s->x)
            for (size_t d = 0; d < dim; d++) CELL(s->x[i * dim + d]);
        if (s->v)
            for (size_t d = 0; d < dim; d++) CELL(s->v[i * dim + d]);
        if (s->stress)
            for (size_t k = 0; k < 6; k++) CELL(s->stress[i * 6 + k]);
        if (s->pressure) CELL(s->pressure[i]);
        if (s->mean_stress) CELL(s->mean_stress[i]);
        if (s->volume) CELL(s->volume[i]);
        if (s->plastic_strain) CELL(s->plastic_strain[i]);
        if (s->deformation_gradient)
            for (size_t k = 0; k < dim * dim; k++) CELL(s->deformation_gradient[i * dim * dim + k]);
        if (s->yielded) fprintf(f, ",%d", s->yielded[i] ? 1 : 0);
        fputc('\n', f);
    }
#undef CELL
    return ferror(f) ? CTL_ESYS : 0;
}

/* A snapshot as one JSON line: the JSON mapping's Snapshot, printed as
 * every other JSON output (shortest exact doubles). */
static int snapshot_json(FILE *f, const mpp_snapshot *s)
{
    char *text = NULL;
    json_error_t je;
    json_t *js = NULL;
    int rc = CTL_ESYS;
    if (mpp_snapshot_to_json(s, &text, NULL)) {
        fprintf(stderr, "mpmctl: cannot write the snapshot as JSON\n");
    } else if (!(js = json_loads(text, 0, &je))) {
        fprintf(stderr, "mpmctl: snapshot JSON: %s\n", je.text);
    } else if (!cj_print(f, js, 0)) {
        fputc('\n', f);
        rc = 0;
    }
    json_decref(js);
    free(text);
    return rc;
}

/* The VTK encoding the options ask for (default: appended raw). */
static ctl_vtk_enc vtk_enc(const cli *a)
{
    return a->given[O_ASCII]      ? CTL_VTK_ASCII
           : a->given[O_BASE64]   ? CTL_VTK_BASE64
           : a->given[O_COMPRESS] ? CTL_VTK_ZLIB
                                  : CTL_VTK_RAW;
}

static int cmd_snapshot(ctl_conn *c, const cli *a)
{
    mpp_request rq = {.kind = MPP_REQ_GET_SNAPSHOT, .has_step = a->given[O_STEP], .step = a->step};
    mpp_reply reply;
    const char *path = a->val[O_OUT];
    size_t pl = strlen(path);
    int as_json = pl > 5 && !strcmp(path + pl - 5, ".json");
    int as_vtp = pl > 4 && !strcmp(path + pl - 4, ".vtp");
    uint64_t id;
    FILE *f;
    int rc;
    if (parse_id(a->pos[0], "snapshot", &id)) return CTL_EXIT_USAGE;
    rq.id = id;
    rc = ctl_call_reply(c, &rq, MPP_REPLY_SNAPSHOT, &reply);
    if (rc) {
        mpp_reply_clear(&reply);
        return exit_for_rc(rc);
    }
    const mpp_snapshot *snap = &reply.snapshot;
    if (as_vtp) {
        rc = ctl_vtk_write_vtp(path, snap, vtk_enc(a));
        if (!rc)
            fprintf(stderr, "run %llu: snapshot at step %lld (t %.10g, %llu particles) -> %s\n",
                    (unsigned long long)id, (long long)snap->step, cj_norm(snap->t),
                    (unsigned long long)snap->n, path);
        mpp_reply_clear(&reply);
        return exit_for_rc(rc);
    }
    f = strcmp(path, "-") ? fopen(path, "w") : stdout;
    if (!f) {
        fprintf(stderr, "mpmctl: cannot write %s: %s\n", path, strerror(errno));
        mpp_reply_clear(&reply);
        return CTL_EXIT_ERROR;
    }
    rc = as_json ? snapshot_json(f, snap) : snapshot_csv(f, snap);
    if ((f == stdout ? fflush(f) : fclose(f)) || rc) {
        if (!rc) fprintf(stderr, "mpmctl: cannot write %s: %s\n", path, strerror(errno));
        if (f != stdout) remove(path);
        mpp_reply_clear(&reply);
        return CTL_EXIT_ERROR;
    }
    if (f != stdout)
        fprintf(stderr, "run %llu: snapshot at step %lld (t %.10g, %llu particles) -> %s\n",
                (unsigned long long)id, (long long)snap->step, cj_norm(snap->t),
                (unsigned long long)snap->n, path);
    mpp_reply_clear(&reply);
    return CTL_EXIT_OK;
}

static int cmd_export(ctl_conn *c, const cli *a)
{
    uint64_t id;
    if (parse_id(a->pos[0], "export", &id)) return CTL_EXIT_USAGE;
    ctl_export_format fmt =
        a->given[O_FORMAT] && !strcmp(a->val[O_FORMAT], "hdf5") ? CTL_EXPORT_HDF5 : CTL_EXPORT_VTK;
    return exit_for_rc(ctl_export(c, id, a->pos[1], fmt, vtk_enc(a), a->given[O_GRID]));
}

static int cmd_plot(ctl_conn *c, const cli *a)
{
    uint64_t id;
    if (parse_id(a->pos[0], "plot", &id)) return CTL_EXIT_USAGE;
    return exit_for_rc(ctl_plot(c, id, a->val[O_OUT], a->val[O_TERMINAL]));
}

static int cmd_cancel(ctl_conn *c, const cli *a)
{
    mpp_request rq = {.kind = MPP_REQ_CANCEL};
    json_t *reply = NULL, *run = NULL;
    uint64_t id;
    int rc;
    if (parse_id(a->pos[0], "cancel", &id)) return CTL_EXIT_USAGE;
    rq.id = id;
    rc = ctl_call(c, &rq, "run", &reply, &run);
    if (!rc) {
        if (a->fmt == CTL_OUT_JSON) {
            rc = out_json_line(run);
        } else {
            int st = cj_status(run, "status");
            printf("job %llu: %s%s\n", (unsigned long long)id, cj_str(run, "status", "?"),
                   st == MPP_STATUS_RUNNING ? " (cancel requested: it stops within one step)" : "");
        }
    }
    json_decref(reply);
    return exit_for_rc(rc);
}

static int cmd_ping(ctl_conn *c, const cli *a)
{
    mpp_request rq = {.kind = MPP_REQ_PING};
    json_t *reply = NULL, *pong = NULL;
    double t0 = now_s(), ms;
    int rc = ctl_call(c, &rq, "pong", &reply, &pong);
    ms = 1e3 * (now_s() - t0);
    if (!rc) {
        if (a->fmt == CTL_OUT_JSON) {
            json_t *rt = json_real(ms);
            if (!rt || json_object_set_new(pong, "roundTripMs", rt))
                rc = CTL_ESYS;
            else
                rc = out_json_line(pong);
        } else {
            printf("mpmd %s at %s: schema %lld, stream %s, round trip %.2f ms\n",
                   cj_str(pong, "serverVersion", "?"), c->endpoint,
                   cj_int(pong, "schemaVersion", 0), cj_str(pong, "streamEndpoint", "?"), ms);
        }
    }
    json_decref(reply);
    return exit_for_rc(rc);
}

static int cmd_version(ctl_conn *c, const cli *a)
{
    mpp_request rq = {.kind = MPP_REQ_VERSION};
    json_t *reply = NULL, *vi = NULL;
    int rc;
    if (a->fmt != CTL_OUT_JSON) {
        printf("mpmctl %s (schema %d)\n", MPP_VERSION, MPP_SCHEMA_VERSION);
        fflush(stdout);
    }
    rc = ctl_call(c, &rq, "version", &reply, &vi);
    if (!rc) {
        if (a->fmt == CTL_OUT_JSON) {
            json_t *o = json_pack("{s:{s:s,s:i},s:O}", "client", "version", MPP_VERSION,
                                  "schemaVersion", MPP_SCHEMA_VERSION, "server", vi);
            rc = o ? out_json_line(o) : CTL_ESYS;
            json_decref(o);
        } else {
            json_t *comps = json_object_get(vi, "components");
            printf("mpmd %s (schema %lld) at %s\n", cj_str(vi, "serverVersion", "?"),
                   cj_int(vi, "schemaVersion", 0), c->endpoint);
            for (size_t i = 0; json_is_array(comps) && i < json_array_size(comps); i++) {
                json_t *k = json_array_get(comps, i);
                printf("  %-12s %s\n", cj_str(k, "name", "?"), cj_str(k, "version", "?"));
            }
        }
    }
    json_decref(reply);
    return exit_for_rc(rc);
}

int main(int argc, char **argv)
{
    cli a;
    ctl_conn c;
    int rc;
    if (parse_args(argc, argv, &a)) return CTL_EXIT_USAGE;
    if (a.given[O_HELP]) {
        if (a.cmd)
            command_usage(a.cmd);
        else
            usage(stdout);
        return CTL_EXIT_OK;
    }
    memset(&c, 0, sizeof c);
    c.endpoint = a.given[O_ENDPOINT] ? a.val[O_ENDPOINT] : getenv("MPMD_ENDPOINT");
    if (!c.endpoint || !*c.endpoint) c.endpoint = CTL_DEFAULT_ENDPOINT;
    c.stream = a.given[O_STREAM] ? a.val[O_STREAM] : getenv("MPMD_STREAM");
    c.timeout_s = a.timeout;
    if (a.cmd->bit == C_KEYGEN) return exit_for_rc(ctl_keygen(a.val[O_OUT], a.val[O_NAME]));
    if ((rc = ctl_keys_load(&c, a.given[O_KEYS] ? a.val[O_KEYS] : NULL))) return exit_for_rc(rc);
    switch (a.cmd->bit) {
    case C_SUBMIT: rc = cmd_submit(&c, &a); break;
    case C_WATCH: rc = cmd_watch(&c, &a); break;
    case C_RUNS: rc = cmd_runs(&c, &a); break;
    case C_SHOW: rc = cmd_show(&c, &a); break;
    case C_ENERGY: rc = cmd_energy(&c, &a); break;
    case C_SNAPSHOT: rc = cmd_snapshot(&c, &a); break;
    case C_CANCEL: rc = cmd_cancel(&c, &a); break;
    case C_EXPORT: rc = cmd_export(&c, &a); break;
    case C_PLOT: rc = cmd_plot(&c, &a); break;
    case C_RESUME: rc = cmd_resume(&c, &a); break;
    case C_PING: rc = cmd_ping(&c, &a); break;
    default: rc = cmd_version(&c, &a); break;
    }
    ctl_conn_close(&c);
    if (fflush(stdout) && !rc) {
        fprintf(stderr, "mpmctl: cannot write the output: %s\n", strerror(errno));
        rc = CTL_EXIT_ERROR;
    }
    return rc;
}
