/*
 * mpm_sort.c - keeps the particles sorted by cell.
 *
 * Every MPM_SORT_EVERY steps (and at creation) the particles are put in the
 * order of their cells, row-major over the active rows, by a stable
 * counting sort, so that consecutive particles share nodes and each
 * thread's slice covers a compact region.  The cells are numbered over the
 * rows' extents only (the histogram follows the particles, not the box).
 * P.id keeps each particle's creation index: everything public (snapshots,
 * error messages, per-particle inputs) speaks creation order.  The scratch
 * is made at creation: the keys and the integer fields go through the
 * double scratch array.  The keys, the check that they are in order
 * already (then nothing moves: the common case between cell crossings)
 * and the permutation of the arrays run on the team; the histogram and the
 * permutation itself are serial.  The order does not depend on the thread
 * count.
 */
#include "mpm_internal.h"

#include <string.h>

/* Keys of the thread's slice, and whether the slice is in key order. */
static void ph_keys(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    uint32_t *key = (uint32_t *)(void *)s->sscr;
    s->k->cell_keys(s, key, a, b);
    mpm_thread_out *o = &s->tout[tid];
    int sorted = 1;
    for (size_t p = a + 1; p < b; p++) sorted &= key[p] >= key[p - 1];
    o->ksorted = sorted;
    o->kfirst = a < b ? key[a] : 0;
    o->klast = a < b ? key[b - 1] : 0;
}

/* The particle arrays of doubles, in a fixed order. */
#define NARR (3 * 3 + 2 * 6 + 9 + 9 + 2 + 3)
static int sort_arrays(mpm_sim *s, double **arr[NARR])
{
    mpm_particles *P = &s->P;
    int na = 0;
    for (int d = 0; d < s->dim; d++) {
        arr[na++] = &P->x[d];
        arr[na++] = &P->v[d];
        if (P->lp[d]) arr[na++] = &P->lp[d];
    }
    for (int c = 0; c < MPM_NCOMP(s->dim); c++) {
        arr[na++] = &P->sig[c];
        if (P->eps[c]) arr[na++] = &P->eps[c];
    }
    for (int c = 0; c < 9; c++)
        if (P->F[c]) arr[na++] = &P->F[c];
    for (int c = 0; c < 9; c++)
        if (P->B[c]) arr[na++] = &P->B[c]; /* APIC */
    arr[na++] = &P->m;
    arr[na++] = &P->vol;
    if (P->epsp) arr[na++] = &P->epsp; /* model state (mpm_model_ops.needs) */
    if (P->yld) arr[na++] = &P->yld;
    if (P->vol0) arr[na++] = &P->vol0; /* volume update DET_F */
    return na;
}

/* The permutation applied on the team, each thread gathering its slice of
 * slots (slot p takes particle perm[p]) of one array at a time through the
 * scratch: the integer fields are copied back, and each double array's
 * permuted copy goes into the scratch, the old array then being the
 * scratch of the next (mpm_sort_particles() swaps the pointers after).  Only
 * copies: the result does not depend on the thread count. */
static void ph_permute(mpm_sim *s, int tid)
{
    mpm_particles *P = &s->P;
    const uint32_t *restrict perm = s->sperm;
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    uint16_t *m16 = (uint16_t *)(void *)s->sscr;
    for (size_t p = a; p < b; p++) m16[p] = P->mat[perm[p]];
    mpm_team_sync(s);
    memcpy(P->mat + a, m16 + a, (b - a) * sizeof *P->mat);
    mpm_team_sync(s);
    uint32_t *u32 = (uint32_t *)(void *)s->sscr;
    for (size_t p = a; p < b; p++) u32[p] = P->id[perm[p]];
    mpm_team_sync(s);
    memcpy(P->id + a, u32 + a, (b - a) * sizeof *P->id);
    mpm_team_sync(s);
    if (s->nload) { /* the inverse map for the loaded particles */
        for (size_t p = a; p < b; p++) u32[perm[p]] = (uint32_t)p;
        mpm_team_sync(s);
        size_t i0, i1;
        mpm_slice(s->nload, s->nthreads, tid, &i0, &i1);
        for (size_t i = i0; i < i1; i++) s->load_p[i] = u32[s->load_p[i]];
        mpm_team_sync(s);
    }
    double **arr[NARR];
    int na = sort_arrays(s, arr);
    double *dst = s->sscr;
    for (int i = 0; i < na; i++) {
        const double *restrict src = *arr[i];
        double *restrict d = dst;
        for (size_t p = a; p < b; p++) d[p] = src[perm[p]];
        mpm_team_sync(s);
        dst = *arr[i];
    }
}

void mpm_sort_particles(mpm_sim *s)
{
    mpm_particles *P = &s->P;
    size_t n = P->n;
    size_t nr = mpm_box_rows(s->blo, s->bhi);
    if (n < 2 || !nr) return;
    size_t nk = 0;
    for (size_t r = 0; r < nr; r++) {
        size_t row = mpm_box_row(s, s->blo, s->bhi, r);
        s->rowoff[row] = nk;
        if (s->ulo[row] <= s->uhi[row]) nk += (size_t)(s->uhi[row] - s->ulo[row] + 1);
    }
    s->rowoff[s->nrows] = nk;
    mpm_team_run(s, ph_keys);
    int sorted = 1;
    uint32_t last = 0;
    for (int t = 0; t < s->nthreads; t++) {
        size_t a, b;
        mpm_particle_slice(s, t, &a, &b);
        if (a == b) continue;
        sorted &= s->tout[t].ksorted && s->tout[t].kfirst >= last;
        last = s->tout[t].klast;
    }
    if (sorted) return;
    uint32_t *key = (uint32_t *)(void *)s->sscr, *perm = s->sperm, *h = s->shist;
    memset(h, 0, (nk + 1) * sizeof *h);
    for (size_t p = 0; p < n; p++) h[key[p] + 1]++;
    for (size_t k = 0; k < nk; k++) h[k + 1] += h[k];
    for (size_t p = 0; p < n; p++) perm[h[key[p]]++] = (uint32_t)p;
    /* the keys are spent: the scratch carries the permuted copies */
    mpm_team_run(s, ph_permute);
    double **arr[NARR];
    int na = sort_arrays(s, arr);
    for (int i = 0; i < na; i++) {
        double *old = *arr[i];
        *arr[i] = s->sscr;
        s->sscr = old;
    }
}
