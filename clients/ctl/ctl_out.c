/*
 * ctl_out.c - how mpmctl writes energy series and times.  An energy series
 * goes out as a readable table, as CSV (a header, then one row per sample,
 * numbers in their shortest exact form so a reader gets the very doubles
 * the daemon computed; the angular momentum columns come last, after the
 * momentum: angular_momentum_x, _y, _z in 3D, angular_momentum_z in 2D,
 * none in 1D) or as JSON lines (one EnergySample object per line,
 * in the protobuf JSON mapping).  The CSV's last columns are the energy
 * balance's: plastic_work, damping_work, friction_work, prescribed_work,
 * balance_error (0 from a daemon older than them).  The same writer serves `energy` and
 * `watch`, so both print identical rows for identical samples.
 */
#include "ctl.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

void ctl_energy_out_init(ctl_energy_out *o, ctl_out fmt, int dim, FILE *f)
{
    o->fmt = fmt;
    o->dim = dim;
    o->header_done = 0;
    o->f = f;
}

static void csv_num(FILE *f, double v)
{
    char b[40];
    cj_fmt_double(b, sizeof b, v);
    fputc(',', f);
    fputs(b, f);
}

/* One sample as a JSON line: the protocol's JSON mapping of the sample,
 * printed as every other JSON output (shortest exact doubles). */
static int json_row(FILE *f, const mpm_energy_sample *s)
{
    char *text = NULL;
    json_error_t je;
    json_t *js = NULL;
    int rc = CTL_ESYS;
    if (!mpp_energy_to_json(s, &text, NULL) && (js = json_loads(text, 0, &je)) &&
        !cj_print(f, js, 0)) {
        fputc('\n', f);
        rc = 0;
    }
    json_decref(js);
    free(text);
    return rc;
}

/* The first angular momentum component a dimension has (the wire's and
 * the CSV's columns): 3D x (0), 2D z alone (2), 1D none (3). */
static int ang_first(int dim)
{
    return dim == 3 ? 0 : dim == 2 ? 2 : 3;
}

int ctl_energy_out_row(ctl_energy_out *o, const mpm_energy_sample *s)
{
    static const char axis[3] = {'x', 'y', 'z'};
    FILE *f = o->f;
    if (o->dim <= 0) o->dim = s->dim < 1 ? 1 : s->dim > 3 ? 3 : s->dim;
    switch (o->fmt) {
    case CTL_OUT_JSON:
        if (json_row(f, s)) return CTL_ESYS;
        break;
    case CTL_OUT_CSV:
        if (!o->header_done) {
            fputs("seq,step,t,kinetic,strain,potential,external_work,total,mass", f);
            for (int d = 0; d < o->dim; d++) fprintf(f, ",momentum_%c", axis[d]);
            for (int d = ang_first(o->dim); d < 3; d++) fprintf(f, ",angular_momentum_%c", axis[d]);
            fputs(",plastic_work,damping_work,friction_work,prescribed_work,balance_error\n", f);
        }
        fprintf(f, "%llu,%lld", (unsigned long long)s->seq, (long long)s->step);
        csv_num(f, cj_norm(s->t));
        csv_num(f, cj_norm(s->e.kinetic));
        csv_num(f, cj_norm(s->e.strain));
        csv_num(f, cj_norm(s->e.potential));
        csv_num(f, cj_norm(s->e.external_work));
        csv_num(f, cj_norm(s->e.total));
        csv_num(f, cj_norm(s->e.mass));
        for (int d = 0; d < o->dim; d++) csv_num(f, d < s->dim ? cj_norm(s->e.momentum[d]) : 0);
        for (int d = ang_first(o->dim); d < 3; d++) csv_num(f, cj_norm(s->e.angular_momentum[d]));
        csv_num(f, cj_norm(s->e.plastic_work));
        csv_num(f, cj_norm(s->e.damping_work));
        csv_num(f, cj_norm(s->e.friction_work));
        csv_num(f, cj_norm(s->e.prescribed_work));
        csv_num(f, cj_norm(s->e.balance_error));
        fputc('\n', f);
        break;
    case CTL_OUT_TEXT:
        if (!o->header_done)
            fprintf(f, "%8s %10s %14s %15s %15s %15s %15s %9s\n", "seq", "step", "t", "kinetic",
                    "strain", "potential-work", "total", "balance");
        fprintf(f, "%8llu %10lld %14.6g %15.8e %15.8e %15.8e %15.8e %8.3g%%\n",
                (unsigned long long)s->seq, (long long)s->step, cj_norm(s->t),
                cj_norm(s->e.kinetic), cj_norm(s->e.strain),
                cj_norm(s->e.potential) - cj_norm(s->e.external_work), cj_norm(s->e.total),
                100 * cj_norm(s->e.balance_error));
        break;
    }
    o->header_done = 1;
    return ferror(f) ? CTL_ESYS : 0;
}

const char *ctl_esc(const char *s, char *buf, size_t n)
{
    mpp_text_escape(s, buf, n);
    return buf;
}

void ctl_fmt_time(char *buf, size_t n, double unix_s)
{
    struct tm tm;
    time_t t = (time_t)unix_s;
    if (unix_s <= 0 || !localtime_r(&t, &tm) || !strftime(buf, n, "%Y-%m-%d %H:%M:%S", &tm))
        snprintf(buf, n, "-");
}

void ctl_fmt_balance(char *buf, size_t n, const json_t *run)
{
    const json_t *b = json_object_get(run, "balanceError");
    if (!b)
        snprintf(buf, n, "-");
    else
        snprintf(buf, n, "%.3g%%%s", 100 * cj_num(run, "balanceError", 0),
                 *cj_str(run, "warning", "") ? "!" : "");
}

void ctl_fmt_duration(char *buf, size_t n, double s)
{
    if (!(s >= 0))
        snprintf(buf, n, "?");
    else if (s < 60)
        snprintf(buf, n, "%.1f s", s);
    else if (s < 3600)
        snprintf(buf, n, "%dm%02ds", (int)(s / 60), (int)s % 60);
    else if (s < 1e7)
        snprintf(buf, n, "%dh%02dm", (int)(s / 3600), (int)(s / 60) % 60);
    else
        snprintf(buf, n, "%.3g s", s);
}
