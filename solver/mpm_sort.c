/*
 * mpm_sort.c - keeps the particles sorted by cell.
 *
 * At creation, and then when their runs of one cell have fallen apart or
 * MPM_SORT_EVERY steps after the last sort (mpm_sim.c begin_step()), the
 * particles are put in the order of their cells, row-major over the
 * active rows, by a stable
 * counting sort, so that consecutive particles share nodes and each
 * thread's slice covers a compact region.  The cells are numbered over the
 * rows' extents only (the histogram follows the particles, not the box).
 * P.id keeps each particle's creation index: everything public (snapshots,
 * error messages, per-particle inputs) speaks creation order.  The scratch
 * is made at creation and is one 32-bit word per particle (sperm) and the
 * histogram: the keys, turned in place into each particle's new slot, and
 * the particles then moved into their slots in place (no second copy of
 * any array): by a sweep through a ring of MPM_SORT_RING saved slots per
 * thread when no particle moves that far (the disks' crossings: 10^6
 * particles sorted in 16 ms instead of 25-29 on 1 thread, the same
 * order), else along the permutation's cycles.  The keys and the check
 * that they are in order already (then nothing moves: the common case
 * between cell crossings) run on the team; the histogram, the farthest
 * move and the marking of the cycles are serial, and the moves run on the team again, the
 * arrays dealt out to the threads (faster than the serial swaps of every
 * array at once that they replace: docs/performance.md).  The order does not
 * depend on the thread count.
 */
#include "mpm_sort.h"
#include "mpm_internal.h"
#include "mpm_rows.h"
#include "mpm_team.h"

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

/* Marks the permutation's cycles in dest: every slot of a cycle but its
 * first (its lowest slot, the leader) gets VISITED; fixed points
 * (dest[i] == i) stay as they are.  Serial, on the 32-bit slots alone. */
#define VISITED 0x80000000u /* slots < MPM_MAX_PARTICLES = 2^31: bit 31 is free */
static void mark_cycles(uint32_t *restrict dest, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        if ((dest[i] & VISITED) || dest[i] == i) continue;
        size_t k = dest[i];
        while (k != i) {
            uint32_t t = dest[k];
            dest[k] = t | VISITED;
            k = t & ~VISITED;
        }
    }
}

/* The sweep of one array (elements of type T) to the slots dest[i], when
 * no particle moves as far as the ring's R entries: in slot order, slot
 * i's old value (from the ring if a particle before it has already taken
 * its place, else from the array) goes to slot dest[i], whose old value,
 * when that slot is still to come, is saved in the ring first (entry
 * dest[i] mod R, tagged with its slot).  An entry is read before another
 * slot can reuse it: a slot d is saved at the soonest at i = d - W and
 * read at i = d, and the next slot of its entry, d + R, not before i =
 * d + R - W > d.  Each slot is written once and its old value read once,
 * so the result is the cycles' result; the reads and writes sweep the
 * array instead of jumping along the cycles. */
#define RING_SWEEP(NAME, T)                                                     \
    static void NAME(T *restrict a, const uint32_t *restrict dest, size_t n,    \
                     uint64_t *restrict val, uint32_t *restrict tag, size_t R)  \
    {                                                                           \
        memset(tag, 0xff, R * sizeof *tag); /* no slot: slots are below 2^31 */ \
        for (size_t i = 0; i < n; i++) {                                        \
            size_t r = i & (R - 1), d = dest[i];                                \
            T v;                                                                \
            if (tag[r] == i)                                                    \
                memcpy(&v, &val[r], sizeof v);                                  \
            else                                                                \
                v = a[i];                                                       \
            if (d == i) continue;                                               \
            if (d > i) {                                                        \
                size_t rd = d & (R - 1);                                        \
                tag[rd] = (uint32_t)d;                                          \
                memcpy(&val[rd], &a[d], sizeof a[d]);                           \
            }                                                                   \
            a[d] = v;                                                           \
        }                                                                       \
    }
RING_SWEEP(sweep_f64, double)
RING_SWEEP(sweep_u32, uint32_t)
RING_SWEEP(sweep_u16, uint16_t)

/* Moves the fields of thread tid's share to their slots along the marked
 * cycles: from each leader i, the carried particle goes to slot dest[k],
 * and the one there is carried on, until the cycle is back at i.  The
 * fields are dealt out to the threads (the double arrays, then the
 * material and creation index as one more), so that each moves its own
 * arrays whole and the result does not depend on the thread count. */
static void ph_permute(mpm_sim *s, int tid)
{
    mpm_particles *P = &s->P;
    const uint32_t *restrict dest = s->sperm;
    double **arr[NARR], *a[NARR];
    int na = sort_arrays(s, arr), nm = 0, T = s->nthreads;
    for (int f = tid; f < na; f += T) a[nm++] = *arr[f];
    int ids = na % T == tid; /* mat and id: the (na + 1)-th field */
    if (!nm && !ids) return;
    if (s->sort_win) {
        mpm_thread_out *o = &s->tout[tid];
        size_t R = (size_t)s->plan.sort_ring;
        for (int f = 0; f < nm; f++) sweep_f64(a[f], dest, P->n, o->rval, o->rtag, R);
        if (ids) {
            sweep_u16(P->mat, dest, P->n, o->rval, o->rtag, R);
            sweep_u32(P->id, dest, P->n, o->rval, o->rtag, R);
        }
        return;
    }
    for (size_t i = 0; i < P->n; i++) {
        if ((dest[i] & VISITED) || dest[i] == i) continue;
        double c[NARR];
        for (int f = 0; f < nm; f++) c[f] = a[f][i];
        uint16_t cm = ids ? P->mat[i] : 0;
        uint32_t cid = ids ? P->id[i] : 0;
        for (size_t k = dest[i]; k != i; k = dest[k] & ~VISITED) {
            for (int f = 0; f < nm; f++) {
                double t = a[f][k];
                a[f][k] = c[f];
                c[f] = t;
            }
            if (ids) {
                uint16_t tm = P->mat[k];
                P->mat[k] = cm;
                cm = tm;
                uint32_t ti = P->id[k];
                P->id[k] = cid;
                cid = ti;
            }
        }
        for (int f = 0; f < nm; f++) a[f][i] = c[f];
        if (ids) {
            P->mat[i] = cm;
            P->id[i] = cid;
        }
    }
}

/* Numbers the cells over the active rows' extents (rowoff), serial.
 * Returns 0 when there is nothing to sort. */
static int sort_rows(mpm_sim *s)
{
    size_t nr = mpm_box_rows(s->blo, s->bhi);
    if (s->P.n < 2 || !nr) return 0;
    size_t nk = 0;
    for (size_t r = 0; r < nr; r++) {
        size_t row = mpm_box_row(s, s->blo, s->bhi, r);
        s->rowoff[row] = nk;
        if (s->ulo[row] <= s->uhi[row]) nk += (size_t)(s->uhi[row] - s->ulo[row] + 1);
    }
    s->rowoff[s->nrows] = nk;
    return 1;
}

/* After the keys: whether the particles are in key order already, and if
 * not, the keys turned into the new slots (counting sort), the load slots
 * moved with their particles and the cycles marked.  Serial.  Returns 1
 * when particles move. */
static int sort_slots(mpm_sim *s)
{
    size_t n = s->P.n, nk = s->rowoff[s->nrows];
    int sorted = 1;
    uint32_t last = 0;
    for (int t = 0; t < s->nthreads; t++) {
        size_t a, b;
        mpm_particle_slice(s, t, &a, &b);
        if (a == b) continue;
        sorted &= s->tout[t].ksorted && s->tout[t].kfirst >= last;
        last = s->tout[t].klast;
    }
    if (sorted) return 0;
    /* counting sort: each key becomes its particle's new slot, in place */
    uint32_t *key = s->sperm, *h = s->shist;
    memset(h, 0, (nk + 1) * sizeof *h);
    for (size_t p = 0; p < n; p++) h[key[p] + 1]++;
    for (size_t k = 0; k < nk; k++) h[k + 1] += h[k];
    size_t far = 0; /* the farthest move */
    for (size_t p = 0; p < n; p++) {
        size_t d = key[p] = h[key[p]]++;
        d = d > p ? d - p : p - d;
        far = d > far ? d : far;
    }
    for (size_t i = 0; i < s->nload; i++) s->load_p[i] = key[s->load_p[i]];
    s->sort_win = far < (size_t)s->plan.sort_ring;
    s->sort_swept += s->sort_win;
    if (!s->sort_win) mark_cycles(key, n);
    s->sort_moved++;
    return 1;
}

/* The cell of particle p as box_add() finds it (clamped to the padded
 * grid), flattened. */
static size_t flat_cell(const mpm_sim *s, size_t p)
{
    size_t k = 0;
    for (int d = 0; d < s->dim; d++) {
        double r = (s->P.x[d][p] - s->x0[d]) * s->inv_h[d];
        r = r >= 0 ? (r < s->rmax[d] ? r : s->rmax[d]) : 0.0;
        k += (size_t)(int)r * s->stride[d];
    }
    return k;
}

/* each slice's first particle counted one (box_add()), taken back here
 * where it shares the cell of the particle before it */
size_t mpm_sort_cell_changes(const mpm_sim *s)
{
    size_t n = 0;
    for (int t = 0; t < s->nthreads; t++) n += s->tout[t].ncell;
    for (int t = 1; t < s->nthreads; t++) {
        size_t a, b;
        mpm_particle_slice(s, t, &a, &b);
        if (a < b && a > 0 && n > 0 && flat_cell(s, a) == flat_cell(s, a - 1)) n--;
    }
    return n;
}

void mpm_sort_particles(mpm_sim *s)
{
    if (!sort_rows(s)) return;
    mpm_team_run(s, ph_keys);
    if (sort_slots(s)) mpm_team_run(s, ph_permute);
}

void mpm_sort_team(mpm_sim *s, int tid)
{
    if (tid == 0) s->sort_go = sort_rows(s);
    mpm_team_sync(s);
    if (s->sort_go) {
        ph_keys(s, tid);
        mpm_team_sync(s);
        if (tid == 0) s->sort_go = sort_slots(s);
        mpm_team_sync(s);
        if (s->sort_go) ph_permute(s, tid);
        mpm_team_sync(s);
    }
    mpm_ph_bbox(s, tid);
    mpm_team_sync(s);
    if (tid == 0) s->runs0 = mpm_sort_cell_changes(s); /* before anything moves */
    mpm_team_sync(s);
}
