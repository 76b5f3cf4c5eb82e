/*
 * side.h - the entry points of the two sides of `make bench-inproc`
 * (side.c): pbi_new_* on this tree's solver, pbi_ref_* on REF's.  Plain C
 * types only, so that the driver (inproc.c) needs neither tree's headers.
 */
#ifndef PBI_SIDE_H
#define PBI_SIDE_H

#include <stddef.h>

/* One configuration, by the bench's own names (bin/mpmbench --help). */
typedef struct {
    const char *scene;  /* disks2d, cube3d, bar1d, sparse2d-4096, sparse2d-tight,
                           collapse2d-dp, collapse2d-el */
    const char *method; /* mpm, gimp, bspline2, ... (any case) */
    const char *update; /* usf, usl, musl */
    int apic;           /* 1: the APIC transfer (trees that have it) */
    int threads;
    long particles; /* aimed count; 0: the scene's default */
} pbi_cfg;

/* Builds the scene and its simulation; NULL with err filled on failure
 * (*lacks 1: the tree has no such scene, method, update or transfer;
 * else out of memory or a case the tree rejects).  run: nsteps steps, 0, or -1 when the simulation
 * stopped short of them (diverged, failed).  close: frees and nulls *h. */
#define PBI_DECLARE(side)                                                       \
    void *pbi_##side##_open(const pbi_cfg *q, int *lacks, char *err, size_t n); \
    int pbi_##side##_run(void *h, long nsteps);                                 \
    size_t pbi_##side##_particles(const void *h);                               \
    long pbi_##side##_steps(const void *h);                                     \
    void pbi_##side##_close(void **h);
PBI_DECLARE(new)
PBI_DECLARE(ref)

#endif
