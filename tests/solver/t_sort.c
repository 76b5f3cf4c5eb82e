/*
 * t_sort.c - when and how the particles are sorted by cell:
 * the sort follows the particles' runs of one cell (the moving passes'
 * count of cell changes, the same for every thread count, and a
 * checkpoint that carries the sort's state), and the two ways of moving
 * the arrays (a sweep through each thread's ring, the permutation's
 * cycles) give the same order.  The sort's other properties (creation
 * order kept, independent of the thread count) are in t_perf.c.
 */
#include "t.h"
#include "mpm.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_paper.h"
#include "mpm_sort.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The paper's disks, MPM USF, 1/120 cells (7,120 particles at 2 x 2 per
 * cell): all particles at one velocity, 1/32 of a cell per step, so the
 * lattice crosses cell lines all at once.  NULL when creation fails. */
static mpm_sim *crossing_disks(int threads)
{
    mpm_paper t;
    mpm_paper_disks(&t, MPM_METHOD_MPM, MPM_USF, 1.0 / 120);
    t.c.threads = threads;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    mpm_paper_free(&t);
    if (!s) fprintf(stderr, "    mpm_sim_new: %s\n", err.message);
    return s;
}

/* The cell changes along the particles counted here, serially, with the
 * clamped cell of box_add(). */
static size_t recount_cells(const mpm_sim *s)
{
    size_t n = 0, prev = SIZE_MAX;
    for (size_t p = 0; p < s->P.n; p++) {
        size_t k = 0;
        for (int d = 0; d < s->dim; d++) {
            double r = (s->P.x[d][p] - s->x0[d]) * s->inv_h[d];
            r = r >= 0 ? (r < s->rmax[d] ? r : s->rmax[d]) : 0.0;
            k += (size_t)(int)r * s->stride[d];
        }
        n += k != prev;
        prev = k;
    }
    return n;
}

/* The sort follows the particles' runs of one cell (begin_step()).  The
 * paper's disks at 2 x 2 per cell, 1/32 of a cell per step: the lattice
 * crosses cell lines together, which makes runs of one particle at once.
 * Over 160 steps on 1-3 threads: the count the moving passes record
 * (mpm_sort_cell_changes()) equals a serial recount at every step, the
 * same on every thread count; at most a quarter of the 160 steps start
 * with more than twice the cell changes the last sort left (19 do: the
 * lattice crosses in x one step and in y the next, and sorts are 4 steps
 * apart at least; fixed sorts every 16 steps left half of the steps so,
 * 8 in every 16 at 1/201 and 1/1425 cells); sorts come at steps that are
 * not multiples of 16; and a run saved at steps 70, 71 and 73 and loaded
 * into a fresh simulation sorts when the straight one does and ends bit
 * for bit the same (the sort's state is in the checkpoint). */
TEST(perf_sort_follows_cell_runs)
{
    size_t cnt[3][160];
    for (int T = 1; T <= 3; T++) {
        mpm_sim *s = crossing_disks(T);
        CHECK(s);
        size_t split = 0, off16 = 0, bad = 0, sorts = 0;
        long last = s->sort_last;
        for (int k = 0; k < 160; k++) {
            size_t r = mpm_sort_cell_changes(s);
            cnt[T - 1][k] = r;
            bad += r != recount_cells(s);
            split += r > MPM_SORT_SPLIT * s->runs0;
            CHECK(mpm_sim_run(s, 1) == 0);
            if (s->sort_last != last) {
                sorts++;
                off16 += s->sort_last % MPM_SORT_EVERY != 0;
                last = s->sort_last;
            }
        }
        TLOG("%d thread(s), %zu particles: %zu sorts (%zu off the 16-step grid), %zu of 160 steps "
             "started with the runs split; %zu counts differ from the recount",
             T, s->P.n, sorts, off16, split, bad);
        CHECK(bad == 0);
        CHECK(split <= 160 / 4);
        CHECK(off16 >= 3);
        CHECK(sorts <= 160 / MPM_SORT_MIN);
        if (T > 1) CHECK(memcmp(cnt[T - 1], cnt[0], sizeof cnt[0]) == 0);
        mpm_sim_destroy(&s);
    }
    /* checkpoints: straight to 100 steps, and saved at 70, 71, 73 then
     * loaded and run on to 100 (2 threads) */
    mpm_paper t;
    mpm_paper_disks(&t, MPM_METHOD_MPM, MPM_USF, 1.0 / 120);
    t.c.threads = 2;
    mpm_error err;
    mpm_sim *a = mpm_sim_new(&t.c, NULL, &err);
    CHECKF(a, "%s", TERR(&err));
    CHECK(mpm_sim_run(a, 100) == 0);
    size_t n = a->P.n;
    double *xa = calloc(2 * n, sizeof *xa), *xb = calloc(2 * n, sizeof *xb);
    double *sa = calloc(6 * n, sizeof *sa), *sb = calloc(6 * n, sizeof *sb);
    CHECK(xa && xb && sa && sb);
    mpm_sim_snapshot(a, &(mpm_snapshot){.x = xa, .stress = sa});
    static const int at[] = {70, 71, 73};
    for (int i = 0; i < 3; i++) {
        mpm_sim *b = mpm_sim_new(&t.c, NULL, &err), *c = mpm_sim_new(&t.c, NULL, &err);
        CHECK(b && c);
        CHECK(mpm_sim_run(b, at[i]) == 0);
        size_t sz = mpm_sim_checkpoint_size(b);
        void *blob = malloc(sz);
        CHECK(blob && mpm_sim_checkpoint_save(b, blob, sz) == 0);
        CHECKF(mpm_sim_checkpoint_load(c, blob, sz, &err) == 0, "%s", TERR(&err));
        CHECK(c->sort_last == b->sort_last && c->runs0 == b->runs0);
        long m0 = c->sort_moved;
        CHECK(mpm_sim_run(c, 100 - at[i]) == 0);
        CHECK(c->sort_last == a->sort_last && c->sort_moved > m0); /* it sorted after loading */
        mpm_sim_snapshot(c, &(mpm_snapshot){.x = xb, .stress = sb});
        TLOG("saved at step %d (last sort at %ld), loaded, run to 100: last sort at %ld as "
             "straight; x and stress %s",
             at[i], b->sort_last, c->sort_last,
             memcmp(xa, xb, 2 * n * sizeof *xa) || memcmp(sa, sb, 6 * n * sizeof *sa)
                 ? "DIFFER"
                 : "bit for bit equal");
        CHECK(memcmp(xa, xb, 2 * n * sizeof *xa) == 0 && memcmp(sa, sb, 6 * n * sizeof *sa) == 0);
        free(blob);
        mpm_sim_destroy(&b);
        mpm_sim_destroy(&c);
    }
    mpm_paper_free(&t);
    free(xa);
    free(xb);
    free(sa);
    free(sb);
    mpm_sim_destroy(&a);
}

/* The sort's two ways of moving the arrays give the same order: the sweep
 * through each thread's ring (every particle moves less than the ring's
 * entries) and the walk along the permutation's cycles (the others).  The
 * same disks and the same 160 steps, once as built and once with a ring
 * of 2 entries, so that every sort that moves a particle more than one
 * slot walks the cycles: x, v and sigma end bit for bit equal, on 1 and 2
 * threads, and the first run swept in all its moving sorts, the second in
 * none of those that moved a particle farther than one slot. */
TEST(perf_sort_sweep_equals_cycles)
{
    for (int T = 1; T <= 2; T++) {
        double *out[2][3] = {{NULL}};
        long moved[2] = {0, 0}, swept[2] = {0, 0};
        size_t n = 0;
        for (int k = 0; k < 2; k++) {
            mpm_sim *s = crossing_disks(T);
            CHECK(s);
            if (k) CHECK(mpm_sim_plan_override(s, "sort_ring=2", NULL) == 0);
            long m0 = s->sort_moved, w0 = s->sort_swept;
            CHECK(mpm_sim_run(s, 160) == 0);
            moved[k] = s->sort_moved - m0;
            swept[k] = s->sort_swept - w0;
            n = s->P.n;
            out[k][0] = calloc(2 * n, sizeof(double));
            out[k][1] = calloc(2 * n, sizeof(double));
            out[k][2] = calloc(6 * n, sizeof(double));
            CHECK(out[k][0] && out[k][1] && out[k][2]);
            mpm_sim_snapshot(s,
                             &(mpm_snapshot){.x = out[k][0], .v = out[k][1], .stress = out[k][2]});
            mpm_sim_destroy(&s);
        }
        int same = memcmp(out[0][0], out[1][0], 2 * n * sizeof(double)) == 0 &&
                   memcmp(out[0][1], out[1][1], 2 * n * sizeof(double)) == 0 &&
                   memcmp(out[0][2], out[1][2], 6 * n * sizeof(double)) == 0;
        TLOG("%d thread(s): sorts that moved particles %ld / %ld, swept %ld / %ld (ring as built / "
             "of 2); x, v, sigma %s",
             T, moved[0], moved[1], swept[0], swept[1], same ? "bit for bit equal" : "DIFFER");
        CHECK(same);
        CHECK(moved[0] >= 5 && moved[0] == moved[1]);
        CHECK(swept[0] == moved[0] && swept[1] == 0);
        for (int k = 0; k < 2; k++)
            for (int j = 0; j < 3; j++) free(out[k][j]);
    }
}
