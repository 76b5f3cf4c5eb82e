/*
 * ctl_out.c - how mpmctl writes energy series and times.  An energy series
 * goes out as a readable table, as CSV (a header, then one row per sample,
 * numbers in their shortest exact form so a reader gets the very doubles
 * the daemon computed) or as JSON lines (one EnergySample object per line,
 * in the protobuf JSON mapping).  The same writer serves `energy` and
 * `watch`, so both print identical rows for identical samples.
 */
#include "ctl.h"

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

int ctl_energy_out_row(ctl_energy_out *o, const json_t *s)
{
    static const char axis[3] = {'x', 'y', 'z'};
    FILE *f = o->f;
    if (o->dim <= 0) {
        size_t n = cj_len(s, "momentum");
        o->dim = n < 1 ? 1 : n > 3 ? 3 : (int)n;
    }
    switch (o->fmt) {
    case CTL_OUT_JSON:
        if (cj_print(f, s, 0)) return CTL_ESYS;
        fputc('\n', f);
        break;
    case CTL_OUT_CSV:
        if (!o->header_done) {
            fputs("seq,step,t,kinetic,strain,potential,external_work,total,mass", f);
            for (int d = 0; d < o->dim; d++) fprintf(f, ",momentum_%c", axis[d]);
            fputc('\n', f);
        }
        fprintf(f, "%llu,%lld", (unsigned long long)cj_u64(s, "seq", 0), cj_int(s, "step", 0));
        csv_num(f, cj_num(s, "t", 0));
        csv_num(f, cj_num(s, "kinetic", 0));
        csv_num(f, cj_num(s, "strain", 0));
        csv_num(f, cj_num(s, "potential", 0));
        csv_num(f, cj_num(s, "externalWork", 0));
        csv_num(f, cj_num(s, "total", 0));
        csv_num(f, cj_num(s, "mass", 0));
        for (int d = 0; d < o->dim; d++) csv_num(f, cj_at(s, "momentum", (size_t)d, 0));
        fputc('\n', f);
        break;
    case CTL_OUT_TEXT:
        if (!o->header_done)
            fprintf(f, "%8s %10s %14s %15s %15s %15s %15s\n", "seq", "step", "t", "kinetic",
                    "strain", "potential-work", "total");
        fprintf(f, "%8llu %10lld %14.6g %15.8e %15.8e %15.8e %15.8e\n",
                (unsigned long long)cj_u64(s, "seq", 0), cj_int(s, "step", 0), cj_num(s, "t", 0),
                cj_num(s, "kinetic", 0), cj_num(s, "strain", 0),
                cj_num(s, "potential", 0) - cj_num(s, "externalWork", 0), cj_num(s, "total", 0));
        break;
    }
    o->header_done = 1;
    return ferror(f) ? CTL_ESYS : 0;
}

void ctl_fmt_time(char *buf, size_t n, double unix_s)
{
    struct tm tm;
    time_t t = (time_t)unix_s;
    if (unix_s <= 0 || !localtime_r(&t, &tm) || !strftime(buf, n, "%Y-%m-%d %H:%M:%S", &tm))
        snprintf(buf, n, "-");
}

void ctl_fmt_duration(char *buf, size_t n, double s)
{
    if (!(s >= 0)) snprintf(buf, n, "?");
    else if (s < 60) snprintf(buf, n, "%.1f s", s);
    else if (s < 3600) snprintf(buf, n, "%dm%02ds", (int)(s / 60), (int)s % 60);
    else if (s < 1e7) snprintf(buf, n, "%dh%02dm", (int)(s / 3600), (int)(s / 60) % 60);
    else snprintf(buf, n, "%.3g s", s);
}
