/*
 * mpm_names.c - the one table of the names of the solver's choices: each
 * shape function (method), update scheme and transfer has its name, the
 * case schema's enum spelling (BSPLINE2, MUSL, APIC: what JSON cases,
 * messages, logs and mpmctl print), and its key, the lower-case spelling
 * the run store records and mpmrun's options take (bspline2, musl, apic).
 * Parsing takes either spelling, in any case.  The rows are indexed by the
 * enums of mpm.h; names_match_proto checks them against the protocol's
 * enum descriptors, so that the wire, the store, the log and the
 * checkpoint's messages say the same.  A method's row also holds its
 * properties (mpm_method.h): support, ghost layers, B-spline degree,
 * fewest nodes, features.
 */
#include "mpm.h"

#include "mpm_method.h"

#include <stdio.h>
#include <string.h>
#include <strings.h>

typedef struct {
    const char *name, *key;
} name_row;

typedef struct {
    name_row n;
    mpm_method_props p;
} method_row;

#define NODAL (MPM_METH_AVX2 | MPM_METH_APIC | MPM_METH_NODE_BC)

/* name, key; support, ghost layers, B-spline degree, fewest nodes, APIC's
 * Courant factor, flags */
static const method_row methods[] = {
    {{"MPM", "mpm"}, {2, 0, 0, 2, MPM_APIC_MPM_MAX_CFL, NODAL}},
    /* uGIMP: 4 nodes (3 when every particle fits, mpm_sim.c) */
    {{"GIMP", "gimp"}, {4, 2, 0, 2, 0, NODAL | MPM_METH_HALF_WIDTHS}},
    {{"BSPLINE2", "bspline2"}, {3, 0, 2, 2, 0, MPM_METH_AVX2 | MPM_METH_APIC}},
    /* the natural end basis needs 4 nodes per axis (mpm_bspline.c) */
    {{"BSPLINE3", "bspline3"}, {4, 0, 3, 4, 0, MPM_METH_AVX2 | MPM_METH_APIC}},
    /* the corners may reach one cell outside the grid */
    {{"CPDI", "cpdi"},
     {2, 1, 0, 2, 0, MPM_METH_HALF_WIDTHS | MPM_METH_DOMAIN_F | MPM_METH_NODE_BC}}};
static const name_row updates[] = {{"USF", "usf"}, {"USL", "usl"}, {"MUSL", "musl"}};
static const name_row transfers[] = {{"FLIP", "flip"}, {"APIC", "apic"}};

_Static_assert(MPM_METHOD_MPM == 0 && MPM_METHOD_GIMP == 1 && MPM_METHOD_BSPLINE2 == 2 &&
                   MPM_METHOD_BSPLINE3 == 3 && MPM_METHOD_CPDI == 4 &&
                   sizeof methods / sizeof methods[0] == MPM_N_METHODS,
               "methods[] follows mpm_method");
_Static_assert(MPM_USF == 0 && MPM_USL == 1 && MPM_MUSL == 2 &&
                   sizeof updates / sizeof updates[0] == MPM_N_UPDATES,
               "updates[] follows mpm_update");
_Static_assert(MPM_TRANSFER_FLIP == 0 && MPM_TRANSFER_APIC == 1 &&
                   sizeof transfers / sizeof transfers[0] == MPM_N_TRANSFERS,
               "transfers[] follows mpm_transfer");

/* Row v (0 <= v) of a table of rows of `size` bytes that start with a
 * name_row. */
static const name_row *row_at(const void *t, size_t size, int v)
{
    return (const name_row *)(const void *)((const char *)t + (size_t)v * size);
}

static const char *pick_rows(const void *t, size_t size, int n, int v, int key)
{
    if (v < 0 || v >= n) return "?";
    const name_row *r = row_at(t, size, v);
    return key ? r->key : r->name;
}

static int find_rows(const void *t, size_t size, int n, const char *s)
{
    for (int i = 0; s && i < n; i++)
        if (!strcasecmp(s, row_at(t, size, i)->name)) return i;
    return -1;
}

#define pick(t, n, v, key) pick_rows(t, sizeof t[0], n, v, key)
#define find(t, n, s) find_rows(t, sizeof t[0], n, s)

void mpm_names_append(char *list, size_t n, const char *name, int k, int count)
{
    size_t used = strlen(list);
    if (used < n)
        snprintf(list + used, n - used, "%s%s", k == 0 ? "" : k == count - 1 ? " or " : ", ", name);
}

const mpm_method_props *mpm_method_props_of(mpm_method m)
{
    return (unsigned)m < MPM_N_METHODS ? &methods[m].p : NULL;
}

const char *mpm_method_name(mpm_method m)
{
    return pick(methods, MPM_N_METHODS, (int)m, 0);
}

const char *mpm_method_key(mpm_method m)
{
    return pick(methods, MPM_N_METHODS, (int)m, 1);
}

int mpm_method_parse(const char *s)
{
    return find(methods, MPM_N_METHODS, s);
}

const char *mpm_update_name(mpm_update u)
{
    return pick(updates, MPM_N_UPDATES, (int)u, 0);
}

const char *mpm_update_key(mpm_update u)
{
    return pick(updates, MPM_N_UPDATES, (int)u, 1);
}

int mpm_update_parse(const char *s)
{
    return find(updates, MPM_N_UPDATES, s);
}

const char *mpm_transfer_name(mpm_transfer t)
{
    return pick(transfers, MPM_N_TRANSFERS, (int)t, 0);
}

const char *mpm_transfer_key(mpm_transfer t)
{
    return pick(transfers, MPM_N_TRANSFERS, (int)t, 1);
}

int mpm_transfer_parse(const char *s)
{
    return find(transfers, MPM_N_TRANSFERS, s);
}
