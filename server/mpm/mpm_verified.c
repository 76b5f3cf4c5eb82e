/*
 * mpm_verified.c - the verification policy: the combinations of method,
 * update and conditions that a case submitted to mpmd may not use, because
 * a test shows them wrong, each with the field it names, why, and what to
 * use instead.  One table; docs/accuracy.md ("Verification matrix") shows
 * it beside the measured errors of what is accepted, and the guarding
 * tests are named per row.
 *
 * The solver itself runs any valid case (mpm_case_check()): its kernel,
 * checkpoint and bits tests reach every path.  mpmd and mpmctl call
 * mpm_case_verified() when a case arrives (protocol/mpp_case.c), so what a
 * user submits is refused here, with the reason, before it runs.
 */
#include "mpm_internal.h"

#include <stdio.h>

typedef struct {
    const char *field; /* the field the refusal names */
    /* 1 when case c (checked, with info) falls in the row; what (n bytes)
     * then says which part of the case does */
    int (*applies)(const mpm_case *c, const mpm_case_info *info, char *what, size_t n);
    const char *why; /* the reason and the alternative, after "what: " */
} refusal;

static const char *const face_names[6] = {"x_lo", "x_hi", "y_lo", "y_hi", "z_lo", "z_hi"};

/* The first friction face's name, or NULL without one. */
static const char *friction_face(const mpm_case *c)
{
    return c->bc.n_friction ? face_names[c->bc.friction[0].face] : NULL;
}

/* USF with a friction face: USF strains the body with the velocities the
 * particles bring, before friction acts on the grid, and a sliding block
 * slows to a stop (mpm_cond_refusals) */
static int usf_friction(const mpm_case *c, const mpm_case_info *info, char *what, size_t n)
{
    (void)info;
    if (!friction_face(c) || c->update != MPM_USF) return 0;
    snprintf(what, n, "USF with a friction face (boundary.friction, face %s)", friction_face(c));
    return 1;
}

/* MPM's tents with a friction face: a block dropped on the face and
 * sliding diverges with MUSL and USL (mpm_cond_refusals) */
static int tents_friction(const mpm_case *c, const mpm_case_info *info, char *what, size_t n)
{
    (void)info;
    if (!friction_face(c) || c->method != MPM_METHOD_MPM) return 0;
    snprintf(what, n, "method MPM with a friction face (boundary.friction, face %s)",
             friction_face(c));
    return 1;
}

/* MPM's tents with USL: a free block translating rigidly across cells
 * diverges (verified_rigid_translation): USL strains with the updated grid
 * velocity, whose error at a node that a particle has just reached grows
 * as the inverse of that node's small mass fraction */
static int tents_usl(const mpm_case *c, const mpm_case_info *info, char *what, size_t n)
{
    (void)info;
    if (c->method != MPM_METHOD_MPM || c->update != MPM_USL) return 0;
    snprintf(what, n, "method MPM with update USL");
    return 1;
}

/* BSPLINE3 where its clamped spans matter: a condition on a grid face, or
 * a particle within 2 cells of a grid end.  There the particles' sums of
 * the cubic basis' gradients miss the exact integrals (the gradients are
 * quadratic, which points at sub-cell centres do not integrate, and the
 * clamped spans lack the uniform spans' cancellation over the lattice), so
 * a uniform stress between rollers moves (bspline3_patch_refused) */
static int bspline3_edge(const mpm_case *c, const mpm_case_info *info, char *what, size_t n)
{
    if (c->method != MPM_METHOD_BSPLINE3) return 0;
    int face = -1;
    for (int f = 0; f < 2 * c->grid.dim && face < 0; f++)
        if (c->bc.face_mask[f]) face = f;
    for (size_t i = 0; i < c->bc.n_friction && face < 0; i++) face = c->bc.friction[i].face;
    for (size_t i = 0; i < c->n_prescribed && face < 0; i++)
        if (c->prescribed[i].face >= 0) face = c->prescribed[i].face;
    if (face >= 0 && face < 6) {
        snprintf(what, n, "method BSPLINE3 with a condition on face %s", face_names[face]);
        return 1;
    }
    if (info->edge_particle < 0) return 0;
    snprintf(what, n,
             "method BSPLINE3 with a particle within %g cells of a grid end (particle %ld, "
             "along %c)",
             MPM_EDGE_CELLS, info->edge_particle, "xyz"[info->edge_axis]);
    return 1;
}

static const refusal refusals[] = {
    {"update", usf_friction,
     "refused: USF strains the body with the particles' velocities before friction acts, and "
     "a block sliding on the face slows to a stop; use MUSL (the default) or USL"},
    {"method", tents_friction,
     "refused: the tents' cell-crossing noise under the face's normal force makes a block "
     "sliding on it diverge; use BSPLINE2 (the default), GIMP or CPDI"},
    {"update", tents_usl,
     "refused: a body that merely translates across cells diverges; use MUSL (the default) or "
     "USF with MPM, or method GIMP or BSPLINE2 with USL"},
    {"method", bspline3_edge,
     "refused: on the 2 clamped cells next to each grid end the particles do not integrate "
     "the cubic B-splines exactly, and a uniform stress there loses 10-27 % of itself at any "
     "resolution; use BSPLINE2 (the default), GIMP or CPDI, or keep a BSPLINE3 body 2 cells "
     "away from the grid's ends with no face conditions"},
};

int mpm_case_verified(const mpm_case *c, const mpm_case_info *info, mpm_error *err)
{
    char what[160];
    for (size_t i = 0; i < sizeof refusals / sizeof refusals[0]; i++)
        if (refusals[i].applies(c, info, what, sizeof what))
            return mpm_fail(err, MPM_EINVAL, refusals[i].field, "%s is %s", what, refusals[i].why);
    return 0;
}
