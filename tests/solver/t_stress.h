/*
 * t_stress.h - what the stress suite's files share (t_stress.c,
 * t_stress_extremes.c).
 */
#ifndef T_STRESS_H
#define T_STRESS_H

#include <stdlib.h>
#include <string.h>

/* MPM_STRESS=full (`make stress`): the whole sweep, not the quick form. */
static inline int t_stress_full(void)
{
    const char *e = getenv("MPM_STRESS");
    return e && !strcmp(e, "full");
}

#endif
