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
 * is made at creation and is one 32-bit word per particle (sperm) and the
 * histogram: the keys, turned in place into each particle's new slot, and
 * the particles then swapped into their slots along the permutation's
 * cycles, every array at once, in place (no second copy of any array).
 * The keys and the check that they are in order already (then nothing
 * moves: the common case between cell crossings) run on the team; the
 * histogram and the permutation are serial.  The order does not depend on
 * the thread count.
 */
#include "mpm_internal.h"

#include <string.h>

/* Keys of the thread's slice, and whether the slice is in key order. */
static void ph_keys(mpm_sim *s, int tid)
{
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    uint32_t *key = s->sperm;
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
        if (P->sig[c]) arr[na++] = &P->sig[c];
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

/* Swaps the fields of particles i and k (na double arrays a, material,
 * creation index). */
static inline void swap_particles(double *const *a, int na, mpm_particles *P, size_t i, size_t k)
{
    for (int f = 0; f < na; f++) {
        double t = a[f][i];
        a[f][i] = a[f][k];
        a[f][k] = t;
    }
    uint16_t m = P->mat[i];
    P->mat[i] = P->mat[k];
    P->mat[k] = m;
    uint32_t id = P->id[i];
    P->id[i] = P->id[k];
    P->id[k] = id;
}

/* Moves every particle p to slot dest[p], in place, by swaps along the
 * permutation's cycles: dest[j] is always the slot the particle now in
 * slot j belongs to, and a particle that reached its slot k leaves
 * dest[k] = k.  At most n - 1 swaps of whole particles; only copies, so
 * the result is that of any other way of applying the permutation.
 * dest ends as the identity. */
static void permute_in_place(mpm_sim *s, uint32_t *restrict dest)
{
    mpm_particles *P = &s->P;
    double **arr[NARR], *a[NARR];
    int na = sort_arrays(s, arr);
    for (int f = 0; f < na; f++) a[f] = *arr[f];
    for (size_t i = 0; i < P->n; i++)
        while (dest[i] != i) {
            size_t k = dest[i];
            swap_particles(a, na, P, i, k);
            dest[i] = dest[k];
            dest[k] = (uint32_t)k;
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
    /* counting sort: each key becomes its particle's new slot, in place */
    uint32_t *key = s->sperm, *h = s->shist;
    memset(h, 0, (nk + 1) * sizeof *h);
    for (size_t p = 0; p < n; p++) h[key[p] + 1]++;
    for (size_t k = 0; k < nk; k++) h[k + 1] += h[k];
    for (size_t p = 0; p < n; p++) key[p] = h[key[p]]++;
    for (size_t i = 0; i < s->nload; i++) s->load_p[i] = key[s->load_p[i]];
    permute_in_place(s, key);
}
