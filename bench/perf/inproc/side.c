/*
 * side.c - one side of `make bench-inproc REF=<commit>` (inproc.sh): a
 * tree's own bench scenes (its bench/perf/scenes.c, included here for its
 * static build()) behind five entry points that take and return plain C
 * types only, so that two trees whose solver APIs differ can run in one
 * process.  Compiled twice: against this tree (PBI_SIDE new, the default)
 * and against REF's headers and scenes.c (PBI_SIDE ref, PBI_SCENES naming
 * REF's file).  inproc.sh links REF's side with REF's solver into one
 * object whose symbols are all local but pbi_ref_*, so the two solvers
 * never see each other's symbols.
 *
 * The side adapts to the solver APIs the project has had: mpm_sim_new()
 * with an error buffer (before mpm_error.h) or with an mpm_error, and a
 * case with or without a transfer (APIC) field.  The collapse2d pair
 * (collapse2d-dp, collapse2d-el) is built by the tree's own
 * collapse_case() (scenes.c, PB_COLLAPSE_CASE), or, in a tree from before
 * it that has the pair, by the rule its work_collapse() kept inline.
 */
#ifndef PBI_SIDE
#define PBI_SIDE new
#endif
#ifndef PBI_SCENES
#define PBI_SCENES "../scenes.c"
#endif
#include PBI_SCENES

#include <strings.h>

#include "side.h"

#define PBI_CAT2(a, b) pbi_##a##_##b
#define PBI_CAT(a, b) PBI_CAT2(a, b)
#define PBI(name) PBI_CAT(PBI_SIDE, name)

typedef struct {
    mpm_paper t;
    mpm_sim *sim;
#ifdef MPM_COLLAPSE_H
    mpm_collapse_case cc;
    int collapse; /* cc holds the case (not t) */
#endif
} pbi_side;

#if defined(MPM_COLLAPSE_H) && !defined(PB_COLLAPSE_CASE)
/* A tree whose scenes.c builds the collapse pair inside its
 * work_collapse() (before PB_COLLAPSE_CASE): the case as those trees
 * build it, a rule unchanged from the scene's first commit (feee44e) to
 * them.  A tree with PB_COLLAPSE_CASE builds it with its own
 * collapse_case(). */
static int collapse_case(const pb_cfg *c, mpm_collapse_case *cc, char *err, size_t n)
{
    long np = c->particles ? c->particles : pb_scene_default_particles(c->scene);
    mpm_collapse_cfg cfg = {.a = 2,
                            .cells = (int)lround(sqrt((double)np / 8.0)),
                            .method = c->method,
                            .model = c->scene == PB_COLLAPSE_DP ? MPM_MODEL_DRUCKER_PRAGER
                                                                : MPM_MODEL_LINEAR_ELASTIC,
                            .threads = c->threads};
    if (cfg.cells < 4) cfg.cells = 4;
    if (mpm_collapse_setup(&cfg, cc)) {
        snprintf(err, n, "out of memory for %ld particles", np);
        return -1;
    }
    cc->c.update = c->update;
    return 0;
}
#endif

/* Frees the side's case (the paper's scenes or the collapse). */
static void pbi_free_case(pbi_side *h)
{
#ifdef MPM_COLLAPSE_H
    if (h->collapse) {
        mpm_collapse_free(&h->cc);
        return;
    }
#endif
    mpm_paper_free(&h->t);
}

/* The enum value whose bench name is `name` (any case), or -1. */
static int pbi_method_of(const char *name)
{
    for (int m = 0; m < 16; m++)
        if (!strcasecmp(pb_method_name((mpm_method)m), name)) return m;
    return -1;
}

static int pbi_update_of(const char *name)
{
    for (int u = 0; u < 3; u++)
        if (!strcasecmp(pb_update_name((mpm_update)u), name)) return u;
    return -1;
}

void *PBI(open)(const pbi_cfg *q, int *lacks, char *err, size_t n)
{
    *lacks = 0;
    pb_cfg c;
    memset(&c, 0, sizeof c);
    int sc = -1;
    for (int i = 0; i < PB_NSCENES; i++)
        if (!strcmp(pb_scene_name((pb_scene)i), q->scene)) sc = i;
    int m = pbi_method_of(q->method), u = pbi_update_of(q->update);
    if (sc < 0 || m < 0 || u < 0) {
        snprintf(err, n, "this tree's bench has no %s '%s'",
                 sc < 0  ? "scene"
                 : m < 0 ? "method"
                         : "update",
                 sc < 0  ? q->scene
                 : m < 0 ? q->method
                         : q->update);
        *lacks = 1;
        return NULL;
    }
    c.scene = (pb_scene)sc;
    c.method = (mpm_method)m;
    c.update = (mpm_update)u;
    c.particles = q->particles;
    c.threads = q->threads;
#ifdef MPM_APIC_MPM_MAX_CFL /* a tree with APIC: mpm_case.transfer, pb_cfg.transfer */
    c.transfer = q->apic ? MPM_TRANSFER_APIC : MPM_TRANSFER_FLIP;
#else
    if (q->apic) {
        snprintf(err, n, "this tree has no APIC transfer");
        *lacks = 1;
        return NULL;
    }
#endif
    pbi_side *h = calloc(1, sizeof *h);
    if (!h) {
        snprintf(err, n, "out of memory");
        return NULL;
    }
#ifdef MPM_COLLAPSE_H
    int col = c.scene == PB_COLLAPSE_DP || c.scene == PB_COLLAPSE_EL;
    if (col ? collapse_case(&c, &h->cc, err, n) : build(&c, &h->t, err, n)) {
        free(h);
        return NULL;
    }
    h->collapse = col;
    mpm_case *cs = col ? &h->cc.c : &h->t.c;
#else
    if (build(&c, &h->t, err, n)) {
        free(h);
        return NULL;
    }
    mpm_case *cs = &h->t.c;
#endif
#ifdef MPM_ERROR_H
    mpm_error me;
    h->sim = mpm_sim_new(cs, NULL, &me);
    if (!h->sim) {
        char buf[MPM_ERROR_MSG_MAX + 200];
        snprintf(err, n, "mpm_sim_new: %s", mpm_error_text(&me, MPM_FIELD_PROTO, buf, sizeof buf));
    }
#else
    h->sim = mpm_sim_new(cs, err, n);
#endif
    if (!h->sim) {
        pbi_free_case(h);
        free(h);
        return NULL;
    }
    return h;
}

int PBI(run)(void *h, long steps)
{
    pbi_side *s = h;
    long k0 = mpm_sim_steps(s->sim);
    int rc = mpm_sim_run(s->sim, steps);
    return rc == 0 && mpm_sim_steps(s->sim) == k0 + steps ? 0 : -1;
}

size_t PBI(particles)(const void *h)
{
    return mpm_sim_particles(((const pbi_side *)h)->sim);
}

long PBI(steps)(const void *h)
{
    return mpm_sim_steps(((const pbi_side *)h)->sim);
}

void PBI(close)(void **h)
{
    if (!h || !*h) return;
    pbi_side *s = *h;
    mpm_sim_destroy(&s->sim);
    pbi_free_case(s);
    free(s);
    *h = NULL;
}
