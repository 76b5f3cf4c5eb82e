/*
 * mpm_timefn.c - time functions: CONSTANT f = value; RAMP f = value *
 * clamp((t - t0) / (t1 - t0), 0, 1); TABLE piecewise linear through (t_i,
 * v_i), t strictly increasing, constant beyond the ends.  Evaluated once per
 * step per condition (a binary search over the table), never per node.
 */
#include "mpm_timefn.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

double mpm_timefn_eval(const mpm_timefn *f, double t)
{
    if (!f) return 1.0;
    switch (f->kind) {
    case MPM_TF_RAMP: {
        if (t <= f->t0) return 0.0;
        if (t >= f->t1) return f->value;
        return f->value * ((t - f->t0) / (f->t1 - f->t0));
    }
    case MPM_TF_TABLE: {
        size_t n = f->n;
        if (n == 0) return 0.0;
        if (t <= f->t[0]) return f->v[0];
        if (t >= f->t[n - 1]) return f->v[n - 1];
        size_t a = 0, b = n - 1; /* t[a] < t < t[b] */
        while (b - a > 1) {
            size_t m = a + (b - a) / 2;
            if (f->t[m] <= t)
                a = m;
            else
                b = m;
        }
        double w = (t - f->t[a]) / (f->t[b] - f->t[a]);
        return f->v[a] + w * (f->v[b] - f->v[a]);
    }
    case MPM_TF_CONSTANT:
    default: return f->value;
    }
}

int mpm_timefn_check(const mpm_timefn *f, const char *path, mpm_error *err)
{
    char p[128];
    if (!f) return 0;
    if (f->kind != MPM_TF_CONSTANT && f->kind != MPM_TF_RAMP && f->kind != MPM_TF_TABLE) {
        snprintf(p, sizeof p, "%s.kind", path);
        return mpm_fail(err, MPM_EINVAL, p, "unknown value %d (CONSTANT, RAMP or TABLE)",
                        (int)f->kind);
    }
    if (f->kind != MPM_TF_TABLE && !isfinite(f->value)) {
        snprintf(p, sizeof p, "%s.value", path);
        return mpm_fail(err, MPM_EINVAL, p, "must be finite (got %g)", f->value);
    }
    if (f->kind == MPM_TF_RAMP) {
        snprintf(p, sizeof p, "%s.t0", path);
        if (!isfinite(f->t0)) return mpm_fail(err, MPM_EINVAL, p, "must be finite (got %g)", f->t0);
        snprintf(p, sizeof p, "%s.t1", path);
        if (!isfinite(f->t1) || !(f->t1 > f->t0))
            return mpm_fail(err, MPM_EINVAL, p, "must be finite and > t0 = %g (got %g)", f->t0,
                            f->t1);
    }
    if (f->kind == MPM_TF_TABLE) {
        if (f->n < 1 || !f->t || !f->v) {
            snprintf(p, sizeof p, "%s.t", path);
            return mpm_fail(err, MPM_EINVAL, p,
                            "a TABLE needs at least 1 point, t and v of equal length (got %zu)",
                            f->n);
        }
        for (size_t i = 0; i < f->n; i++) {
            if (!isfinite(f->t[i])) {
                snprintf(p, sizeof p, "%s.t[%zu]", path, i);
                return mpm_fail(err, MPM_EINVAL, p, "must be finite (got %g)", f->t[i]);
            }
            if (i > 0 && !(f->t[i] > f->t[i - 1])) {
                snprintf(p, sizeof p, "%s.t[%zu]", path, i);
                return mpm_fail(err, MPM_EINVAL, p, "must be > t[%zu] = %.17g (got %.17g)", i - 1,
                                f->t[i - 1], f->t[i]);
            }
            if (!isfinite(f->v[i])) {
                snprintf(p, sizeof p, "%s.v[%zu]", path, i);
                return mpm_fail(err, MPM_EINVAL, p, "must be finite (got %g)", f->v[i]);
            }
        }
    }
    return 0;
}

int mpm_timefn_copy_make(mpm_timefn_copy *dst, const mpm_timefn *src)
{
    memset(dst, 0, sizeof *dst);
    if (!src) return 0;
    dst->set = 1;
    dst->f = *src;
    if (src->kind == MPM_TF_TABLE) {
        if (!(dst->buf = malloc(2 * src->n * sizeof *dst->buf))) return MPM_ENOMEM;
        memcpy(dst->buf, src->t, src->n * sizeof *dst->buf);
        memcpy(dst->buf + src->n, src->v, src->n * sizeof *dst->buf);
        dst->f.t = dst->buf;
        dst->f.v = dst->buf + src->n;
    } else {
        dst->f.n = 0;
        dst->f.t = dst->f.v = NULL;
    }
    return 0;
}

void mpm_timefn_copy_free(mpm_timefn_copy *c)
{
    free(c->buf);
    memset(c, 0, sizeof *c);
}

double mpm_timefn_copy_eval(const mpm_timefn_copy *c, double t)
{
    return c->set ? mpm_timefn_eval(&c->f, t) : 1.0;
}
