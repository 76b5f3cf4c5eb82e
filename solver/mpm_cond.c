/*
 * mpm_cond.c - prescribed velocities and Coulomb friction on grid faces
 * (docs/solver.md, "Conditions").
 *
 * A prescribed velocity v(t) = value * f(t) on a direction of a node
 * follows the BC1/BC2 logic of a fixed one (Eqs. 27-28) with a non-zero
 * value: at grid initialisation the node's momentum component becomes
 * m v(t^n) (BC1), before the nodal update its rate of momentum becomes
 * m (v(t^{n+1}) - v(t^n)) / dt (BC2), so that q^{n+1} = m v(t^{n+1});
 * MUSL's remapped momentum q2 gets m v(t^{n+1}) too.  The reaction, BC2's
 * value minus the free one, does the work (f_set - f_free) (v(t^n) +
 * v(t^{n+1})) / 2 dt on the node over the step: prescribed_work.
 *
 * Friction acts on the nodes of a face made a roller in its normal
 * direction (Bardenhagen et al. 2000; York 1999): before the nodal update,
 * a node whose free normal rate of momentum f_n pushes into the face takes
 * the normal force N = |f_n| (the roller's reaction); its tangential trial
 * momentum q_t* = q_t + f_t dt sticks (q_t^{n+1} = 0) when |q_t*| <=
 * mu N dt, and else slides with f_t reduced by mu N q_t* / |q_t*|.  A node
 * that does not press is free tangentially.  The friction force df does
 * -df . (q^n + q^{n+1}) / (2 m) dt of work: friction_work, the energy it
 * dissipates.  MUSL's remap q2 takes, at every node that pressed, the
 * tangential momentum friction left on the grid (q^{n+1}_t, 0 where it
 * stuck): the remap of the particles' velocities knows nothing of the
 * face, and straining and moving the body with it let an elastic block's
 * sliding feed a growing vibration that stopped it (mpm_cond_sliding_long
 * guards it).  A friction face's nodes may carry prescribed tangential
 * directions (a driven edge on a frictional base): those nodes have no
 * friction.
 *
 * Both lists are sorted by node and visited by segment, as the fixed DOFs
 * are (mpm_loads.c); a scene without them runs none of this.
 */
#include "mpm_cond.h"
#include "mpm_internal.h"
#include "mpm_method.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const face_name[6] = {"x_lo", "x_hi", "y_lo", "y_hi", "z_lo", "z_hi"};

/* ---- checking ---- */

/* faces f and g share nodes: the same face, or faces of different axes */
static int faces_share(int f, int g)
{
    return f == g || f / 2 != g / 2;
}

/* node ijk (real indices) lies on face f */
static int ijk_on_face(const mpm_case *c, const int *ijk, int f)
{
    int d = f / 2;
    return f % 2 ? ijk[d] == c->grid.nodes[d] - 1 : ijk[d] == 0;
}

static int same_ijk(const int *a, const int *b, int dim)
{
    for (int d = 0; d < dim; d++)
        if (a[d] != b[d]) return 0;
    return 1;
}

static int friction_on(const mpm_case *c, int f)
{
    for (size_t i = 0; i < c->bc.n_friction; i++)
        if (c->bc.friction[i].face == f) return 1;
    return 0;
}

static int check_friction(const mpm_case *c, mpm_error *err)
{
    int dim = c->grid.dim;
    unsigned all = (1u << dim) - 1;
    char path[64];
    if (c->bc.n_friction && !c->bc.friction)
        return mpm_fail(err, MPM_EINVAL, "boundary.friction", "%zu entries given without data",
                        c->bc.n_friction);
    for (size_t i = 0; i < c->bc.n_friction; i++) {
        const mpm_friction_desc *fr = &c->bc.friction[i];
        if (fr->face < 0 || fr->face >= 2 * dim) {
            snprintf(path, sizeof path, "boundary.friction[%zu].face", i);
            return mpm_fail(err, MPM_EINVAL, path,
                            "face %d does not exist on a %dD grid (0..%d: x_lo, x_hi%s)", fr->face,
                            dim, 2 * dim - 1,
                            dim == 1   ? ""
                            : dim == 2 ? ", y_lo, y_hi"
                                       : ", y_lo, y_hi, z_lo, z_hi");
        }
        if (!(fr->mu >= 0) || !isfinite(fr->mu)) {
            snprintf(path, sizeof path, "boundary.friction[%zu].mu", i);
            return mpm_fail(err, MPM_EINVAL, path, "must be finite and >= 0 (got %g)", fr->mu);
        }
        for (size_t j = 0; j < i; j++)
            if (c->bc.friction[j].face == fr->face) {
                snprintf(path, sizeof path, "boundary.friction[%zu].face", i);
                return mpm_fail(err, MPM_EINVAL, path,
                                "face %s already has friction (friction[%zu])", face_name[fr->face],
                                j);
            }
        unsigned tang = c->bc.face_mask[fr->face] & all & ~(1u << (fr->face / 2));
        if (tang) {
            snprintf(path, sizeof path, "boundary.friction[%zu].face", i);
            return mpm_fail(err, MPM_EINVAL, path,
                            "boundary.%s fixes tangential directions (mask %u): friction needs "
                            "them free (make the face a roller, mask %u, or absent)",
                            face_name[fr->face], c->bc.face_mask[fr->face], 1u << (fr->face / 2));
        }
    }
    return 0;
}

/* the first conflict of direction mask m at node ijk (real indices; a
 * face's nodes when face >= 0, then ijk is not read) with the fixed DOFs, the
 * friction faces and prescribed[0..upto); 0 or MPM_EINVAL */
static int check_conflicts(const mpm_case *c, size_t pi, int face, const int *ijk, unsigned m,
                           const char *path, mpm_error *err)
{
    int dim = c->grid.dim;
    unsigned all = (1u << dim) - 1;
    for (int f = 0; f < 2 * dim; f++) {
        int share = face >= 0 ? faces_share(face, f) : ijk_on_face(c, ijk, f);
        if (!share) continue;
        if (c->bc.face_mask[f] & m & all)
            return mpm_fail(err, MPM_EINVAL, path,
                            "a prescribed direction (mask %u) is also fixed by boundary.%s (mask "
                            "%u) on the nodes they share",
                            m, face_name[f], c->bc.face_mask[f]);
        if (friction_on(c, f) && (m & (1u << (f / 2))))
            return mpm_fail(err, MPM_EINVAL, path,
                            "a prescribed direction (mask %u) is the normal of face %s, which "
                            "friction makes a roller (boundary.friction)",
                            m, face_name[f]);
    }
    for (size_t i = 0; i < c->bc.n_nodes; i++) {
        const int *b = c->bc.node_ijk + 3 * i;
        int share = face >= 0 ? ijk_on_face(c, b, face) : same_ijk(b, ijk, dim);
        if (share && (c->bc.node_mask[i] & m))
            return mpm_fail(err, MPM_EINVAL, path,
                            "a prescribed direction (mask %u) is also fixed by boundary.nodes[%zu]",
                            m, i);
    }
    for (size_t j = 0; j < pi; j++) {
        const mpm_prescribed_desc *o = &c->prescribed[j];
        if (!(o->mask & m)) continue;
        int share = 0;
        if (o->face >= 0 && face >= 0) share = faces_share(o->face, face);
        if (o->face >= 0 && face < 0) share = ijk_on_face(c, ijk, o->face);
        for (size_t k = 0; o->face < 0 && k < o->n_nodes && !share; k++)
            share = face >= 0 ? ijk_on_face(c, o->node_ijk + 3 * k, face)
                              : same_ijk(o->node_ijk + 3 * k, ijk, dim);
        if (share)
            return mpm_fail(err, MPM_EINVAL, path,
                            "a direction (mask %u) is prescribed twice (also by prescribed[%zu])",
                            m & o->mask, j);
    }
    return 0;
}

int mpm_cond_check(const mpm_case *c, mpm_error *err)
{
    int dim = c->grid.dim, rc;
    unsigned all = (1u << dim) - 1;
    char path[96];
    if ((rc = check_friction(c, err))) return rc;
    if (c->n_prescribed && !c->prescribed)
        return mpm_fail(err, MPM_EINVAL, "prescribed", "%zu entries given without data",
                        c->n_prescribed);
    if (c->n_prescribed > 1024)
        return mpm_fail(err, MPM_EINVAL, "prescribed", "at most 1024 (got %zu)", c->n_prescribed);
    int bsp = mpm_method_props_of(c->method)->bspline != 0;
    for (size_t i = 0; i < c->n_prescribed; i++) {
        const mpm_prescribed_desc *p = &c->prescribed[i];
        if (p->face >= 2 * dim) {
            snprintf(path, sizeof path, "prescribed[%zu].face", i);
            return mpm_fail(err, MPM_EINVAL, path, "face %d does not exist on a %dD grid (0..%d)",
                            p->face, dim, 2 * dim - 1);
        }
        if (p->face >= 0 && p->n_nodes) {
            snprintf(path, sizeof path, "prescribed[%zu].ijk", i);
            return mpm_fail(err, MPM_EINVAL, path, "give either a face or nodes, not both");
        }
        if (p->face < 0 && !p->n_nodes) {
            snprintf(path, sizeof path, "prescribed[%zu]", i);
            return mpm_fail(err, MPM_EINVAL, path, "needs a face or at least one node (ijk)");
        }
        if (p->face < 0 && bsp) {
            snprintf(path, sizeof path, "prescribed[%zu].ijk", i);
            return mpm_fail(
                err, MPM_EINVAL, path,
                "node sets are not supported with BSPLINE2/BSPLINE3 (B-spline "
                "control points are not grid nodes; BSPLINE2 is the default method); prescribe "
                "whole faces instead, or set method to MPM, GIMP or CPDI");
        }
        if (p->face < 0 && !p->node_ijk) {
            snprintf(path, sizeof path, "prescribed[%zu].ijk", i);
            return mpm_fail(err, MPM_EINVAL, path, "%zu nodes given without indices", p->n_nodes);
        }
        if (!p->mask || (p->mask & ~all)) {
            snprintf(path, sizeof path, "prescribed[%zu].mask", i);
            return mpm_fail(err, MPM_EINVAL, path,
                            "must be a non-zero direction mask within %u (got %u)", all, p->mask);
        }
        for (int d = 0; d < dim; d++)
            if (!isfinite(p->value[d])) {
                snprintf(path, sizeof path, "prescribed[%zu].velocity[%d]", i, d);
                return mpm_fail(err, MPM_EINVAL, path, "must be finite (got %g)", p->value[d]);
            }
        snprintf(path, sizeof path, "prescribed[%zu].time_function", i);
        if ((rc = mpm_timefn_check(p->time_function, path, err))) return rc;
        if (p->face >= 0) {
            snprintf(path, sizeof path, "prescribed[%zu].face", i);
            static const int no_ijk[3] = {0, 0, 0}; /* unused with a face */
            if ((rc = check_conflicts(c, i, p->face, no_ijk, p->mask, path, err))) return rc;
            continue;
        }
        for (size_t k = 0; k < p->n_nodes; k++) {
            const int *ijk = p->node_ijk + 3 * k;
            for (int d = 0; d < dim; d++)
                if (ijk[d] < 0 || ijk[d] >= c->grid.nodes[d]) {
                    snprintf(path, sizeof path, "prescribed[%zu].ijk[%zu]", i, k * (size_t)dim + d);
                    return mpm_fail(err, MPM_EINVAL, path, "%d is outside [0, %d)", ijk[d],
                                    c->grid.nodes[d]);
                }
            snprintf(path, sizeof path, "prescribed[%zu].ijk[%zu]", i, k * (size_t)dim);
            for (size_t j = 0; j < k; j++)
                if (same_ijk(p->node_ijk + 3 * j, ijk, dim))
                    return mpm_fail(err, MPM_EINVAL, path, "node %zu repeats node %zu", k, j);
            if ((rc = check_conflicts(c, i, -1, ijk, p->mask, path, err))) return rc;
        }
    }
    return 0;
}

/* ---- building ---- */

static size_t lower(const size_t *node, size_t cnt, size_t first);

int mpm_node_on_face(const mpm_sim *s, size_t n, int face)
{
    int d = face / 2;
    int r = (int)((n / s->stride[d]) % (size_t)s->np[d]) - s->pad; /* real index along d */
    return face % 2 ? r >= s->nreal[d] - 1 : r <= 0;
}

typedef struct {
    size_t node;
    unsigned mask;
    uint32_t src;
    double mu;
} cond_ent;

static int ent_cmp(const void *a, const void *b)
{
    const cond_ent *x = a, *y = b;
    if (x->node != y->node) return x->node < y->node ? -1 : 1;
    return x->src < y->src ? -1 : x->src > y->src;
}

/* entries of prescribed source k (out NULL: count only) */
static size_t pres_entries(const mpm_sim *s, const mpm_prescribed_desc *p, uint32_t k,
                           cond_ent *out)
{
    size_t cnt = 0;
    unsigned all = (1u << s->dim) - 1;
    if (p->face >= 0) {
        for (size_t n = 0; n < s->nn; n++)
            if (mpm_node_on_face(s, n, p->face)) {
                if (out) out[cnt] = (cond_ent){n, p->mask & all, k, 0};
                cnt++;
            }
        return cnt;
    }
    for (size_t i = 0; i < p->n_nodes; i++) {
        int ijk[3] = {0, 0, 0};
        for (int d = 0; d < s->dim; d++) ijk[d] = p->node_ijk[3 * i + d];
        if (out) out[cnt] = (cond_ent){mpm_node_index(s, ijk), p->mask & all, k, 0};
        cnt++;
    }
    return cnt;
}

int mpm_cond_build(mpm_sim *s, const mpm_case *c)
{
    size_t np = 0, nf = 0;
    for (size_t k = 0; k < c->n_prescribed; k++)
        np += pres_entries(s, &c->prescribed[k], (uint32_t)k, NULL);
    for (size_t i = 0; i < c->bc.n_friction; i++)
        for (size_t n = 0; n < s->nn; n++) nf += mpm_node_on_face(s, n, c->bc.friction[i].face);
    if (!np && !nf) return 0;
    size_t nmax = np > nf ? np : nf;
    cond_ent *e = malloc(nmax * sizeof *e);
    if (!e) return MPM_ENOMEM;
    int rc = MPM_ENOMEM;
    if (np) {
        size_t k3 = 3 * c->n_prescribed;
        s->npsrc = c->n_prescribed;
        if (!(s->pres_node = malloc(np * sizeof *s->pres_node)) || !(s->pres_mask = malloc(np)) ||
            !(s->pres_src = malloc(np * sizeof *s->pres_src)) || !(s->pres_val = mpm_dalloc(k3)) ||
            !(s->pres_v0 = mpm_dalloc(k3)) || !(s->pres_v1 = mpm_dalloc(k3)) ||
            !(s->pres_tf = calloc(c->n_prescribed, sizeof *s->pres_tf)) ||
            !(s->pres_face = malloc(c->n_prescribed * sizeof *s->pres_face)) ||
            !(s->pres_fmask = malloc(c->n_prescribed)))
            goto out;
        size_t w = 0;
        for (size_t k = 0; k < c->n_prescribed; k++) {
            w += pres_entries(s, &c->prescribed[k], (uint32_t)k, e + w);
            for (int d = 0; d < s->dim; d++) s->pres_val[3 * k + d] = c->prescribed[k].value[d];
            s->pres_face[k] = c->prescribed[k].face;
            s->pres_fmask[k] = (unsigned char)c->prescribed[k].mask;
            if (mpm_timefn_copy_make(&s->pres_tf[k], c->prescribed[k].time_function)) goto out;
        }
        qsort(e, np, sizeof *e, ent_cmp);
        for (size_t i = 0; i < np; i++) {
            s->pres_node[i] = e[i].node;
            s->pres_mask[i] = (unsigned char)e[i].mask;
            s->pres_src[i] = e[i].src;
        }
        s->npres = np;
    }
    if (nf) {
        if (!(s->fric_node = malloc(nf * sizeof *s->fric_node)) || !(s->fric_face = malloc(nf)) ||
            !(s->fric_stick = calloc(nf, 1)) || !(s->fric_mu = mpm_dalloc(nf)))
            goto out;
        size_t w = 0;
        for (size_t i = 0; i < c->bc.n_friction; i++)
            for (size_t n = 0; n < s->nn; n++)
                if (mpm_node_on_face(s, n, c->bc.friction[i].face))
                    e[w++] = (cond_ent){n, (unsigned)c->bc.friction[i].face, (uint32_t)i,
                                        c->bc.friction[i].mu};
        qsort(e, nf, sizeof *e, ent_cmp);
        /* a node with a prescribed (tangential) direction has no friction */
        for (size_t i = 0; i < nf; i++) {
            size_t k = lower(s->pres_node, s->npres, e[i].node);
            if (k < s->npres && s->pres_node[k] == e[i].node) continue;
            s->fric_node[s->nfric] = e[i].node;
            s->fric_face[s->nfric] = (unsigned char)e[i].mask;
            s->fric_mu[s->nfric++] = e[i].mu;
        }
    }
    s->has_cond = 1;
    rc = 0;
out:
    free(e);
    return rc;
}

void mpm_cond_free(mpm_sim *s)
{
    free(s->pres_node);
    free(s->pres_mask);
    free(s->pres_src);
    free(s->pres_val);
    free(s->pres_v0);
    free(s->pres_v1);
    for (size_t k = 0; s->pres_tf && k < s->npsrc; k++) mpm_timefn_copy_free(&s->pres_tf[k]);
    free(s->pres_tf);
    free(s->pres_face);
    free(s->pres_fmask);
    free(s->fric_node);
    free(s->fric_face);
    free(s->fric_stick);
    free(s->fric_mu);
}

/* ---- the step ---- */

void mpm_cond_begin_step(mpm_sim *s)
{
    for (size_t k = 0; k < s->npsrc; k++) {
        double f0 = mpm_timefn_copy_eval(&s->pres_tf[k], s->t);
        double f1 = mpm_timefn_copy_eval(&s->pres_tf[k], s->t + s->dt);
        for (int d = 0; d < s->dim; d++) {
            s->pres_v0[3 * k + d] = s->pres_val[3 * k + d] * f0;
            s->pres_v1[3 * k + d] = s->pres_val[3 * k + d] * f1;
        }
    }
    for (int t = 0; t < s->nthreads; t++) s->tout[t].wpres = s->tout[t].wfric = 0;
}

void mpm_cond_end_step(mpm_sim *s)
{
    for (int t = 0; t < s->nthreads; t++) {
        s->prescribed_work += s->tout[t].wpres;
        s->prescribed_work_abs += fabs(s->tout[t].wpres);
        s->friction_work += s->tout[t].wfric;
    }
}

/* index of the first entry of the sorted list with node >= first */
static size_t lower(const size_t *node, size_t cnt, size_t first)
{
    size_t a = 0, b = cnt;
    while (a < b) {
        size_t mid = a + (b - a) / 2;
        if (node[mid] < first)
            a = mid + 1;
        else
            b = mid;
    }
    return a;
}

void mpm_cond_bc1(const mpm_sim *s, size_t first, size_t last)
{
    for (size_t i = lower(s->pres_node, s->npres, first); i < s->npres && s->pres_node[i] <= last;
         i++) {
        size_t n = s->pres_node[i];
        const double *v0 = s->pres_v0 + 3 * s->pres_src[i];
        for (int d = 0; d < s->dim; d++)
            if (s->pres_mask[i] & (1u << d)) s->g.q[d][n] = s->g.m[n] * v0[d];
    }
}

void mpm_cond_bc1q2(const mpm_sim *s, size_t first, size_t last)
{
    for (size_t i = lower(s->pres_node, s->npres, first); i < s->npres && s->pres_node[i] <= last;
         i++) {
        size_t n = s->pres_node[i];
        const double *v1 = s->pres_v1 + 3 * s->pres_src[i];
        for (int d = 0; d < s->dim; d++)
            if (s->pres_mask[i] & (1u << d)) s->g.q2[d][n] = s->g.m[n] * v1[d];
    }
    /* a node that pressed keeps the tangential momentum friction gave it
     * (q holds v^{n+1} when the family gathers velocities) */
    for (size_t i = lower(s->fric_node, s->nfric, first); i < s->nfric && s->fric_node[i] <= last;
         i++) {
        if (s->fric_stick[i] == MPM_FRIC_FREE) continue;
        size_t n = s->fric_node[i];
        int a = s->fric_face[i] / 2;
        for (int d = 0; d < s->dim; d++)
            if (d != a) s->g.q2[d][n] = s->gvel ? s->g.q[d][n] * s->g.m[n] : s->g.q[d][n];
    }
}

void mpm_cond_bc2(mpm_sim *s, int tid, size_t first, size_t last)
{
    double dt = s->dt, wf = 0, wp = 0;
    for (size_t i = lower(s->fric_node, s->nfric, first); i < s->nfric && s->fric_node[i] <= last;
         i++) {
        size_t n = s->fric_node[i];
        int a = s->fric_face[i] / 2, hi = s->fric_face[i] % 2;
        double minv = s->minv[n], fn = s->g.f[a][n];
        s->fric_stick[i] = MPM_FRIC_FREE;
        /* phantom, or not pressing on the face (the roller zeroes f_n) */
        if (minv == 0 || !(hi ? fn > 0 : fn < 0)) continue;
        double N = fabs(fn), qt[3] = {0, 0, 0}, q2 = 0;
        for (int d = 0; d < s->dim; d++)
            if (d != a) {
                qt[d] = s->g.q[d][n] + s->g.f[d][n] * dt;
                q2 += qt[d] * qt[d];
            }
        double qn = sqrt(q2), lim = s->fric_mu[i] * N * dt;
        int stick = qn <= lim;
        for (int d = 0; d < s->dim; d++) {
            if (d == a) continue;
            double q = s->g.q[d][n], f = s->g.f[d][n];
            double fnew = stick ? -q / dt : f - s->fric_mu[i] * N * (qt[d] / qn);
            /* the friction force's work with the mean of q^n and q^{n+1} */
            wf -= (fnew - f) * dt * (q + 0.5 * fnew * dt) * minv;
            s->g.f[d][n] = fnew;
        }
        s->fric_stick[i] = stick ? MPM_FRIC_STICK : MPM_FRIC_SLIDE;
    }
    for (size_t i = lower(s->pres_node, s->npres, first); i < s->npres && s->pres_node[i] <= last;
         i++) {
        size_t n = s->pres_node[i];
        const double *v0 = s->pres_v0 + 3 * s->pres_src[i], *v1 = s->pres_v1 + 3 * s->pres_src[i];
        double m = s->g.m[n];
        for (int d = 0; d < s->dim; d++) {
            if (!(s->pres_mask[i] & (1u << d))) continue;
            double fset = m * (v1[d] - v0[d]) / dt;
            wp += (fset - s->g.f[d][n]) * 0.5 * (v0[d] + v1[d]) * dt;
            s->g.f[d][n] = fset;
        }
    }
    s->tout[tid].wpres += wp;
    s->tout[tid].wfric += wf;
}

/* ---- warnings ---- */

/* The largest |travel| of prescribed face k along its normal over [0, t]:
 * value * the integral of its time function, by the midpoint rule on 4096
 * pieces (the functions are piecewise linear), so that no state is kept
 * and checkpoints stay as they are (mpm_cond_face_travel_warning). */
static double face_travel(const mpm_sim *s, size_t k, double t)
{
    int a = s->pres_face[k] / 2;
    double v = s->pres_val[3 * k + a], x = 0, big = 0, dt = t / 4096;
    if (v == 0 || !(t > 0)) return 0;
    for (int i = 0; i < 4096; i++) {
        x += v * mpm_timefn_copy_eval(&s->pres_tf[k], (i + 0.5) * dt) * dt;
        if (fabs(x) > big) big = fabs(x);
    }
    return big;
}

/* An elastic body on a friction face outside the verified envelope:
 * BSPLINE2 with mu <= MPM_FRICTION_ELASTIC_MU (docs/accuracy.md, "Friction
 * faces"); a sliding elastic body may feed a friction-driven vibration
 * there on fine grids (mpm_cond_friction_fine_grids). */
static int friction_elastic(const mpm_sim *s, char *msg, size_t n)
{
    double mu = 0;
    int elastic = 0;
    for (size_t i = 0; i < s->nfric; i++) mu = fmax(mu, s->fric_mu[i]);
    for (size_t m = 0; m < s->nmat; m++) elastic |= !s->mats[m].pl && !(s->mats[m].sy0 > 0);
    if (!s->nfric || !elastic) return 0;
    if (s->method == MPM_METHOD_BSPLINE2 && mu <= MPM_FRICTION_ELASTIC_MU) return 0;
    if (msg && n)
        snprintf(msg, n,
                 "an elastic body on a friction face (mu %g, method %s) is outside what the "
                 "tests verify (BSPLINE2 with mu <= %g): on grids of 4 or more cells across "
                 "the body, its sliding can feed a friction-driven vibration that adds "
                 "friction (a block's acceleration 4-33 %% low, docs/accuracy.md, \"Friction "
                 "faces\"); compare with a coarser grid",
                 mu, mpm_method_name(s->method), MPM_FRICTION_ELASTIC_MU);
    return 1;
}

/* The first prescribed face that moved more than MPM_FACE_TRAVEL_MAX cells
 * along its normal. */
static int face_left(const mpm_sim *s, char *msg, size_t n)
{
    for (size_t k = 0; k < s->npsrc; k++) {
        int f = s->pres_face[k];
        if (f < 0 || !(s->pres_fmask[k] & (1u << (f / 2)))) continue;
        double h = s->h[f / 2], tr = face_travel(s, k, s->t);
        if (!(tr > MPM_FACE_TRAVEL_MAX * h)) continue;
        if (msg && n)
            snprintf(msg, n,
                     "prescribed[%zu] moved face %s %.3g cells along its normal by t = %.6g: a "
                     "prescribed face acts at the grid's face, not at the body's boundary once "
                     "the body has left it, and beyond %g of a cell the stress next to it is off "
                     "by more than 5 %% (docs/accuracy.md, \"Prescribed faces\"); keep a face's "
                     "normal travel below that, prescribe tangential velocities only, or load "
                     "the body with a traction",
                     k, face_name[f], tr / h, s->t, MPM_FACE_TRAVEL_MAX);
        return 1;
    }
    return 0;
}

int mpm_sim_warnings(const mpm_sim *s, char *msg, size_t n)
{
    char a[600] = "", b[600] = "";
    int wa = friction_elastic(s, a, sizeof a), wb = face_left(s, b, sizeof b);
    if (msg && n) snprintf(msg, n, "%s%s%s", a, wa && wb ? "; " : "", b);
    return wa || wb;
}
