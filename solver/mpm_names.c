/*
 * mpm_names.c - the one table of the names of the solver's choices: each
 * shape function (method), update scheme and transfer has its name, the
 * case schema's enum spelling (BSPLINE2, MUSL, APIC: what JSON cases,
 * messages, logs and mpmctl print), and its key, the lower-case spelling
 * the run store records and mpmrun's options take (bspline2, musl, apic).
 * Parsing takes either spelling, in any case.  The rows are indexed by the
 * enums of mpm.h; names_match_proto checks them against the protocol's
 * enum descriptors, so that the wire, the store, the log and the
 * checkpoint's messages say the same.
 */
#include "mpm.h"

#include <strings.h>

typedef struct {
    const char *name, *key;
} name_row;

static const name_row methods[] = {{"MPM", "mpm"},
                                   {"GIMP", "gimp"},
                                   {"BSPLINE2", "bspline2"},
                                   {"BSPLINE3", "bspline3"},
                                   {"CPDI", "cpdi"}};
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

static const char *pick(const name_row *t, int n, int v, int key)
{
    if (v < 0 || v >= n) return "?";
    return key ? t[v].key : t[v].name;
}

static int find(const name_row *t, int n, const char *s)
{
    for (int i = 0; s && i < n; i++)
        if (!strcasecmp(s, t[i].name)) return i;
    return -1;
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
