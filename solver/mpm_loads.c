/*
 * mpm_loads.c - essential boundary conditions and loads.
 *
 * Fixed degrees of freedom are a sorted list of (padded node, direction
 * mask), built once from the face masks and the node set; BC1 (Eq. 27)
 * and BC2 (Eq. 28) zero their components of the momentum and of the rate
 * of momentum inside the node passes (mpm_bc_zero()).  Tractions and point
 * forces become per-particle forces on the particles in their regions,
 * shared by volume, scattered each step like a point load by the kernels
 * (scatter_loads); their work is summed after each step from the loaded
 * particles' displacements.  mpm_sim_set_particle_forces() switches to one
 * load slot per particle, keeping the tractions' shares apart.  Built with
 * -DMPM_LEAN, the boundary conditions compile out.  A traction with a time
 * function keeps its shares apart (tv_*) and mpm_loads_update() sets the
 * loads' forces before each step to the constant part plus f(t^n + dt/2)
 * times those shares.  Prescribed velocities and face friction:
 * mpm_cond.c.
 */
#include "mpm_loads.h"
#include "mpm_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* BC1 (Eq. 27) on a momentum field, BC2 (Eq. 28) on the rate of momentum,
 * over the flat nodes first..last (one segment of a row; the field is zero
 * outside the active rows' extents, and its untouched pages stay so).
 * The list of fixed nodes is in increasing node order. */
void mpm_bc_zero(const mpm_sim *s, double *const field[3], size_t first, size_t last)
{
#ifndef MPM_LEAN
    size_t a = 0, b = s->nfixed;
    if (!b) return;
    while (a < b) { /* first entry >= first */
        size_t mid = a + (b - a) / 2;
        if (s->fixed_node[mid] < first)
            a = mid + 1;
        else
            b = mid;
    }
    for (size_t i = a; i < s->nfixed && s->fixed_node[i] <= last; i++) {
        size_t n = s->fixed_node[i];
        unsigned m = s->fixed_mask[i];
        for (int d = 0; d < s->dim; d++)
            if (m & (1u << d)) field[d][n] = 0.0;
    }
#else
    (void)s;
    (void)field;
    (void)first;
    (void)last;
#endif
}

/* Builds the list of fixed nodes from the face masks and the node set.  In
 * GMPM a particle's support reaches the ghost layers, so a face condition
 * covers the whole plane of the face including its ghost extension (a
 * roller wall does not end where the real grid does) and the ghost nodes
 * behind it (material cannot flow through a wall by way of nodes outside
 * the grid).  A node set names real nodes. */
int mpm_bc_build(mpm_sim *s, const mpm_bc_desc *bc)
{
    int any = bc->n_nodes > 0 || bc->n_friction > 0;
    unsigned fmask[2 * MPM_MAX_DIM];
    for (int f = 0; f < 2 * s->dim; f++) {
        any |= bc->face_mask[f] != 0;
        fmask[f] = bc->face_mask[f];
    }
    /* a face with friction is a roller in its normal direction */
    for (size_t i = 0; i < bc->n_friction; i++)
        fmask[bc->friction[i].face] |= 1u << (bc->friction[i].face / 2);
    if (!any) return 0;
    unsigned char *mask = calloc(s->nn, 1);
    unsigned all = (1u << s->dim) - 1;
    if (!mask) return MPM_ENOMEM;
    for (size_t n = 0; n < s->nn; n++) {
        size_t rest = n;
        for (int d = 0; d < s->dim; d++) {
            int r = (int)(rest % (size_t)s->np[d]) - s->pad; /* real index along d */
            rest /= (size_t)s->np[d];
            if (r <= 0) mask[n] |= fmask[2 * d] & all;
            if (r >= s->nreal[d] - 1) mask[n] |= fmask[2 * d + 1] & all;
        }
    }
    for (size_t i = 0; i < bc->n_nodes; i++) {
        int ijk[3] = {0, 0, 0};
        for (int d = 0; d < s->dim; d++) ijk[d] = bc->node_ijk[3 * i + d];
        mask[mpm_node_index(s, ijk)] |= (unsigned char)bc->node_mask[i];
    }
    size_t cnt = 0;
    for (size_t n = 0; n < s->nn; n++) cnt += mask[n] != 0;
    s->fixed_node = malloc((cnt ? cnt : 1) * sizeof *s->fixed_node);
    s->fixed_mask = malloc(cnt ? cnt : 1);
    if (!s->fixed_node || !s->fixed_mask) {
        free(mask);
        return MPM_ENOMEM;
    }
    for (size_t n = 0; n < s->nn; n++) {
        if (!mask[n]) continue;
        s->fixed_node[s->nfixed] = n;
        s->fixed_mask[s->nfixed++] = mask[n];
    }
    free(mask);
    return 0;
}

int mpm_loads_build(mpm_sim *s, const mpm_case *c)
{
    if (!c->n_tractions) return 0;
    int dim = s->dim;
    size_t cnt = 0;
    for (size_t p = 0; p < s->P.n; p++)
        for (size_t t = 0; t < c->n_tractions; t++) {
            int in = 1;
            for (int d = 0; d < dim; d++)
                in &=
                    s->P.x[d][p] >= c->tractions[t].lo[d] && s->P.x[d][p] <= c->tractions[t].hi[d];
            if (in) {
                cnt++;
                break;
            }
        }
    s->load_p = malloc(cnt * sizeof *s->load_p);
    if (!s->load_p) return MPM_ENOMEM;
    /* time-varying tractions: one entry per (particle, traction) */
    size_t ntv = 0;
    for (size_t t = 0; t < c->n_tractions; t++) {
        if (!c->tractions[t].time_function) continue;
        for (size_t p = 0; p < s->P.n; p++) {
            int in = 1;
            for (int d = 0; d < dim; d++)
                in &=
                    s->P.x[d][p] >= c->tractions[t].lo[d] && s->P.x[d][p] <= c->tractions[t].hi[d];
            ntv += (size_t)in;
        }
    }
    if (ntv) {
        s->ntrac = c->n_tractions;
        if (!(s->tv_slot = malloc(ntv * sizeof *s->tv_slot)) ||
            !(s->tv_trac = malloc(ntv * sizeof *s->tv_trac)) ||
            !(s->trac_tf = calloc(c->n_tractions, sizeof *s->trac_tf)))
            return MPM_ENOMEM;
        for (int d = 0; d < dim; d++)
            if (!(s->tv_f[d] = mpm_dalloc(ntv)) || !(s->load_f0[d] = mpm_dalloc(cnt)))
                return MPM_ENOMEM;
        for (size_t t = 0; t < c->n_tractions; t++)
            if (mpm_timefn_copy_make(&s->trac_tf[t], c->tractions[t].time_function))
                return MPM_ENOMEM;
    }
    /* gcc 12's -fanalyzer forgets s->load_xold[0] when the next pass stores at
     * a symbolic d, and calls it leaked; on failure mpm_sim_destroy frees all */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wanalyzer-malloc-leak"
#endif
    for (int d = 0; d < dim; d++)
        if (!(s->load_f[d] = mpm_dalloc(cnt)) || !(s->load_xold[d] = mpm_dalloc(cnt)))
            return MPM_ENOMEM;
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
    /* per traction: total volume inside, then shares */
    for (size_t t = 0; t < c->n_tractions; t++) {
        const mpm_traction_desc *tr = &c->tractions[t];
        double vsum = 0, area = 1;
        for (int d = 0; d < dim; d++)
            if (d != tr->normal) area *= tr->hi[d] - tr->lo[d];
        for (int pass = 0; pass < 2; pass++) {
            for (size_t p = 0; p < s->P.n; p++) {
                int in = 1;
                for (int d = 0; d < dim; d++)
                    in &= s->P.x[d][p] >= tr->lo[d] && s->P.x[d][p] <= tr->hi[d];
                if (!in) continue;
                if (pass == 0) {
                    vsum += s->P.vol[p];
                    continue;
                }
                size_t i = 0;
                while (i < s->nload && s->load_p[i] != p) i++;
                if (i == s->nload) s->load_p[s->nload++] = p;
                double share = s->P.vol[p] / vsum * (tr->is_force ? 1.0 : area);
                if (tr->time_function) {
                    s->tv_slot[s->ntv] = i;
                    s->tv_trac[s->ntv] = (uint32_t)t;
                    for (int d = 0; d < dim; d++) s->tv_f[d][s->ntv] = tr->value[d] * share;
                    s->ntv++;
                    continue;
                }
                for (int d = 0; d < dim; d++) s->load_f[d][i] += tr->value[d] * share;
            }
        }
    }
    if (s->ntv)
        for (int d = 0; d < dim; d++)
            memcpy(s->load_f0[d], s->load_f[d], s->nload * sizeof *s->load_f0[d]);
    return 0;
}

/* The loads' forces over the coming step: the constant part plus each
 * time-varying traction's share times f(t^n + dt/2), the force held over
 * the whole step (its work is that force times the displacement). */
void mpm_loads_update(mpm_sim *s)
{
    double fac[64], tm = s->t + 0.5 * s->dt;
    if (!s->ntv) return;
    for (size_t t = 0; t < s->ntrac && t < 64; t++)
        fac[t] = mpm_timefn_copy_eval(&s->trac_tf[t], tm);
    for (int d = 0; d < s->dim; d++) {
        memcpy(s->load_f[d], s->load_f0[d], s->nload * sizeof *s->load_f[d]);
        for (size_t e = 0; e < s->ntv; e++)
            s->load_f[d][s->tv_slot[e]] += fac[s->tv_trac[e]] * s->tv_f[d][e];
    }
}

void mpm_loads_begin_step(mpm_sim *s)
{
    for (size_t i = 0; i < s->nload; i++)
        for (int d = 0; d < s->dim; d++) s->load_xold[d][i] = s->P.x[d][s->load_p[i]];
}

void mpm_loads_end_step(mpm_sim *s)
{
    for (size_t i = 0; i < s->nload; i++)
        for (int d = 0; d < s->dim; d++) {
            double w = s->load_f[d][i] * (s->P.x[d][s->load_p[i]] - s->load_xold[d][i]);
            s->external_work += w;
            s->external_work_abs += fabs(w);
        }
}

int mpm_loads_per_particle(mpm_sim *s)
{
    size_t n = s->P.n;
    int dim = s->dim;
    if (!s->pforces) {
        /* one slot per particle; the tractions' shares move to trac_f */
        size_t *lp = malloc((n ? n : 1) * sizeof *lp);
        double *tf[3] = {0}, *xo[3] = {0}, *lf[3] = {0};
        int ok = lp != NULL;
        for (int d = 0; d < dim; d++) {
            tf[d] = mpm_dalloc(n ? n : 1);
            xo[d] = mpm_dalloc(n ? n : 1);
            lf[d] = mpm_dalloc(n ? n : 1);
            ok &= tf[d] && xo[d] && lf[d];
        }
        if (!ok) {
            free(lp);
            for (int d = 0; d < dim; d++) {
                free(tf[d]);
                free(xo[d]);
                free(lf[d]);
            }
            return MPM_ENOMEM;
        }
        for (size_t i = 0; i < n; i++) lp[i] = i;
        for (size_t i = 0; i < s->nload; i++)
            for (int d = 0; d < dim; d++) tf[d][s->load_p[i]] = s->load_f[d][i];
        free(s->load_p);
        s->load_p = lp;
        for (int d = 0; d < dim; d++) {
            free(s->load_f[d]);
            free(s->load_xold[d]);
            s->load_f[d] = lf[d];
            s->load_xold[d] = xo[d];
            s->trac_f[d] = tf[d];
        }
        s->nload = n;
        s->pforces = 1;
    }
    return 0;
}

int mpm_loads_set_forces(mpm_sim *s, const double *f)
{
    size_t n = s->P.n;
    int dim = s->dim;
    if (!s->pforces && !f) return 0;
    if (mpm_loads_per_particle(s)) return MPM_ENOMEM;
    for (size_t i = 0; i < n; i++)
        for (int d = 0; d < dim; d++)
            s->load_f[d][i] =
                s->trac_f[d][i] + (f ? f[(size_t)s->P.id[s->load_p[i]] * (size_t)dim + d] : 0);
    return 0;
}
