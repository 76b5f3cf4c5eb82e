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
#include "mpm.h"

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

/* BSPLINE3 with a friction face: not in the friction tests
 * (mpm_cond_sliding_long covers BSPLINE2, GIMP and CPDI) */
static int bspline3_friction(const mpm_case *c, const mpm_case_info *info, char *what, size_t n)
{
    (void)info;
    if (!friction_face(c) || c->method != MPM_METHOD_BSPLINE3) return 0;
    snprintf(what, n, "method BSPLINE3 with a friction face (boundary.friction, face %s)",
             friction_face(c));
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
    {"method", bspline3_friction,
     "refused: no test has shown the cubic B-splines right under friction; use BSPLINE2 (the "
     "default), GIMP or CPDI"},
};

int mpm_case_verified(const mpm_case *c, const mpm_case_info *info, mpm_error *err)
{
    char what[160];
    for (size_t i = 0; i < sizeof refusals / sizeof refusals[0]; i++)
        if (refusals[i].applies(c, info, what, sizeof what))
            return mpm_fail(err, MPM_EINVAL, refusals[i].field, "%s is %s", what, refusals[i].why);
    return 0;
}
