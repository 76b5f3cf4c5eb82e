/*
 * mpm_timefn.h - time functions f(t) (mpm.h's mpm_timefn: CONSTANT, RAMP,
 * TABLE) that scale prescribed velocities and tractions: their check, their
 * evaluation, and the copy a simulation keeps of them.
 */
#ifndef MPM_TIMEFN_H
#define MPM_TIMEFN_H

#include "mpm.h"

/* f(t); f NULL is the constant 1. */
double mpm_timefn_eval(const mpm_timefn *f, double t);

/* Checks f (NULL: valid).  path is the field of the function in the .proto
 * ("prescribed[0].time_function"); an error names the member below it
 * ("prescribed[0].time_function.t[3]: must be > t[2] (got ...)").  Returns
 * 0 or MPM_EINVAL. */
int mpm_timefn_check(const mpm_timefn *f, const char *path, mpm_error *err);

/* A simulation's own copy of a time function (the table's points in buf). */
typedef struct {
    int set; /* 0: none (f = 1) */
    mpm_timefn f;
    double *buf;
} mpm_timefn_copy;

/* Copies src (NULL: none) into dst.  0 or MPM_ENOMEM. */
int mpm_timefn_copy_make(mpm_timefn_copy *dst, const mpm_timefn *src);
void mpm_timefn_copy_free(mpm_timefn_copy *c);
/* f(t) of a copy (1 when none is set). */
double mpm_timefn_copy_eval(const mpm_timefn_copy *c, double t);

#endif
