/*
 * mpm_checkpoint.c - the solver state a case does not determine, as one
 * self-checking blob (mpm.h, "Checkpoints"; docs/solver.md, "Checkpoints").
 *
 * A blob is a fixed header and a payload.  The header: a magic, the format
 * version, its own size, a byte-order mark (the blob is the host's
 * little-endian memory layout: it is read back by the same build on the
 * same machine type), the payload's size, a 64-bit checksum of the header
 * (this field zeroed) and the payload, a 64-bit fingerprint of the case
 * (its layout below and its numeric parameters: grid, time step,
 * materials, gravity, damping), and the layout itself in words (dim,
 * method, update, transfer, particle and node counts, which per-particle
 * arrays exist, the counts of materials, fixed, prescribed and friction
 * nodes, ...), so that a refusal names what differs.  The payload, in
 * 8-byte aligned sections: the scalars (time, step, dt, the largest speed,
 * the cumulative works and their absolute sums, the guard's and the
 * balance's references, the frictional models' counters, the particle
 * forces' switch, the number of load slots, the failure and its error,
 * the step of the last sort and the particles' cell changes then),
 * then every particle array that exists, in storage order (the particles
 * are kept sorted by cell: mass, half-widths, material and creation index
 * move with them and are saved too), then the load slots (their particles,
 * forces, and the tractions' shares once mpm_sim_set_particle_forces() was
 * called) and the friction nodes' states (free, stuck, sliding).
 *
 * What is not saved is rebuilt by mpm_sim_new() from the case (the grid,
 * the fixed and prescribed nodes, the tractions' shares and time
 * functions, the material constants) or recomputed at load from the
 * particles with the functions the step uses: the threads' support boxes
 * and row extents (mpm_ph_bbox(), what the last particle pass of a step
 * records) and the active rows (mpm_rows_update()).  The grid's values are
 * not state: every step rebuilds them over the active rows before reading
 * them.  The prescribed velocities at t^n, t^{n+1} and the time-varying
 * loads are evaluated at each step's start.  The thread count is not part
 * of the layout: a blob loads into a simulation with another count (the
 * sums then differ in round-off); with the same count the run goes on with
 * the same bits.
 *
 * The checksum: four interleaved FNV-1a lanes over 8-byte words, combined
 * through a bijective mix, so that any change confined to one word is
 * always detected (a few ms for 10^6 particles).
 */
#include "mpm_internal.h"
#include "mpm_loads.h"
#include "mpm_rows.h"
#include "mpm_team.h"

#include <stdio.h>
#include <string.h>

/* 2: the strain record is optional (A_EPS); 3: when the particles were
 * last sorted and their cell changes then (the sort follows them) */
#define CK_VERSION 3u
#define CK_ORDER 0x0102030405060708ull
static const char ck_magic[8] = {'M', 'P', 'M', 'C', 'K', 'P', 'T', '\n'};

/* The layout words, compared one by one at load (ck_name: how a refusal
 * names them). */
enum {
    L_DIM,
    L_METHOD,
    L_UPDATE,
    L_TRANSFER,
    L_VOLUME,
    L_NS,
    L_NPX,
    L_NPY,
    L_NPZ,
    L_PARTICLES,
    L_MATERIALS,
    L_ARRAYS,
    L_FIXED,
    L_PRES_NODES,
    L_PRES_SRC,
    L_FRIC,
    L_TRAC,
    L_TV,
    L_GENERAL,
    L_FRICTIONAL,
    L_DAMPING,
    L_GRAVITY,
    L_BLEND,
    L_COUNT
};
static const char *const ck_name[L_COUNT] = {"dim",
                                             "method",
                                             "update",
                                             "transfer",
                                             "volume_update",
                                             "nodes per axis of a particle's support",
                                             "padded nodes along x",
                                             "padded nodes along y",
                                             "padded nodes along z",
                                             "particles",
                                             "materials",
                                             "per-particle arrays",
                                             "fixed nodes",
                                             "prescribed-velocity nodes",
                                             "prescribed velocities",
                                             "friction nodes",
                                             "tractions with time functions",
                                             "time-varying traction shares",
                                             "general material update",
                                             "frictional materials",
                                             "damping",
                                             "gravity",
                                             "PIC blend"};

typedef struct {
    char magic[8];
    uint32_t version, header_size;
    uint64_t order;
    uint64_t payload_size;
    uint64_t checksum;
    uint64_t fingerprint;
    uint64_t layout[L_COUNT];
} ck_header;
_Static_assert(sizeof(ck_header) == 48 + 8 * L_COUNT, "the header has no padding");

/* The scalars: doubles, then integers (int64). */
enum {
    S_T,
    S_DT,
    S_VMAX,
    S_WEXT,
    S_WEXT_ABS,
    S_WPRES,
    S_WPRES_ABS,
    S_WFRIC,
    S_WPLAST,
    S_WDAMP,
    S_ETOT0,
    S_EFLOOR,
    S_GUARD_V2,
    S_BAL_TOTAL0,
    S_BAL_REF0,
    S_BAL_POT0,
    S_BAL_LAST,
    S_BAL_WORST,
    S_COUNT
};
enum {
    I_STEPS,
    I_PLUPD,
    I_PLSUB,
    I_PLMAX,
    I_PFORCES,
    I_NLOAD,
    I_FAILED,
    I_SORTLAST,
    I_RUNS0,
    I_COUNT
};

/* bit of each optional particle array in L_ARRAYS */
enum { A_LP = 1, A_F = 2, A_B = 4, A_EPSP = 8, A_YLD = 16, A_VOL0 = 32, A_EPS = 64, A_SZZ = 128 };

#define CK_NARR (3 * 3 + 9 + 2 * 6 + 9 + 5)

static size_t pad8(size_t n)
{
    return (n + 7) / 8 * 8;
}

/* ---- the checksum ---- */

#define FNV_PRIME 0x100000001b3ull

static uint64_t mix64(uint64_t x)
{
    x ^= x >> 33;
    x *= 0xff51afd7ed558ccdull;
    x ^= x >> 33;
    x *= 0xc4ceb9fe1a85ec53ull;
    x ^= x >> 33;
    return x;
}

/* n bytes at p, continuing from seed: four FNV-1a lanes over 8-byte words
 * (each a bijection of its state for a given word), the tail zero-padded,
 * combined by bijective steps with the length */
static uint64_t hash_bytes(const void *p, size_t n, uint64_t seed)
{
    const unsigned char *b = p;
    uint64_t h[4];
    for (int k = 0; k < 4; k++) h[k] = 0xcbf29ce484222325ull ^ mix64(seed + (uint64_t)k);
    size_t i = 0;
    for (; i + 32 <= n; i += 32) {
        uint64_t w[4];
        memcpy(w, b + i, sizeof w);
        for (int k = 0; k < 4; k++) h[k] = (h[k] ^ w[k]) * FNV_PRIME;
    }
    for (int k = 0; i + 8 <= n; i += 8, k++) {
        uint64_t w;
        memcpy(&w, b + i, sizeof w);
        h[k] = (h[k] ^ w) * FNV_PRIME;
    }
    if (i < n) {
        uint64_t w = 0;
        memcpy(&w, b + i, n - i);
        h[3] = (h[3] ^ w) * FNV_PRIME;
    }
    uint64_t x = mix64(h[0] ^ (uint64_t)n);
    for (int k = 1; k < 4; k++) x = mix64(x ^ h[k]);
    return x;
}

/* ---- what a case's simulation holds ---- */

/* The particle arrays of doubles that exist, in a fixed order. */
static int part_arrays(const mpm_particles *P, int dim, double *arr[CK_NARR])
{
    int na = 0;
    for (int d = 0; d < dim; d++) {
        arr[na++] = P->x[d];
        arr[na++] = P->v[d];
        if (P->lp[d]) arr[na++] = P->lp[d];
    }
    for (int c = 0; c < 9; c++)
        if (P->F[c]) arr[na++] = P->F[c];
    for (int c = 0; c < MPM_NCOMP(dim); c++) {
        if (P->sig[c]) arr[na++] = P->sig[c];
        if (P->eps[c]) arr[na++] = P->eps[c];
    }
    for (int c = 0; c < 9; c++)
        if (P->B[c]) arr[na++] = P->B[c];
    arr[na++] = P->m;
    arr[na++] = P->vol;
    if (P->epsp) arr[na++] = P->epsp;
    if (P->yld) arr[na++] = P->yld;
    if (P->vol0) arr[na++] = P->vol0;
    return na;
}

static void layout_of(const mpm_sim *s, uint64_t L[L_COUNT])
{
    const mpm_particles *P = &s->P;
    L[L_DIM] = (uint64_t)s->dim;
    L[L_METHOD] = (uint64_t)s->method;
    L[L_UPDATE] = (uint64_t)s->update;
    L[L_TRANSFER] = (uint64_t)s->transfer;
    L[L_VOLUME] = (uint64_t)s->volmode;
    L[L_NS] = (uint64_t)s->plan.ns;
    for (int d = 0; d < 3; d++) L[L_NPX + d] = (uint64_t)s->np[d];
    L[L_PARTICLES] = P->n;
    L[L_MATERIALS] = s->nmat;
    L[L_ARRAYS] = (P->lp[0] ? A_LP : 0) | (P->F[0] ? A_F : 0) | (P->B[0] ? A_B : 0) |
                  (P->epsp ? A_EPSP : 0) | (P->yld ? A_YLD : 0) | (P->vol0 ? A_VOL0 : 0) |
                  (P->eps[0] ? A_EPS : 0) | (P->sig[2] ? A_SZZ : 0);
    L[L_FIXED] = s->nfixed;
    L[L_PRES_NODES] = s->npres;
    L[L_PRES_SRC] = s->npsrc;
    L[L_FRIC] = s->nfric;
    L[L_TRAC] = s->ntrac;
    L[L_TV] = s->ntv;
    L[L_GENERAL] = (uint64_t)s->plan.general;
    L[L_FRICTIONAL] = (uint64_t)s->frictional;
    L[L_DAMPING] = (uint64_t)s->damp;
    L[L_GRAVITY] = (uint64_t)s->has_gravity;
    L[L_BLEND] = s->pic != 0;
}

/* The layout and the case's numeric parameters, hashed. */
static uint64_t fingerprint_of(const mpm_sim *s, const uint64_t L[L_COUNT])
{
    double v[64];
    int k = 0;
    for (int d = 0; d < 3; d++) {
        v[k++] = s->h[d];
        v[k++] = s->x0[d];
        v[k++] = s->lo[d];
        v[k++] = s->hi[d];
        v[k++] = s->gravity[d];
    }
    v[k++] = s->dt_fixed;
    v[k++] = s->cfl;
    v[k++] = s->pic;
    v[k++] = s->mtol;
    v[k++] = s->cmax;
    v[k++] = s->damp_coef;
    v[k++] = s->damp_until;
    uint64_t h = hash_bytes(L, L_COUNT * sizeof *L, 1);
    h = hash_bytes(v, (size_t)k * sizeof *v, h);
    for (size_t i = 0; i < s->nmat; i++) {
        const mpm_mat_params *m = &s->mats[i];
        double mv[9] = {m->E, m->nu, m->rho, m->lambda, m->mu, m->c, m->K, m->sy0, m->H};
        h = hash_bytes(mv, sizeof mv, h);
        /* the model and every parameter its row of the material table
         * reads, in the table's order (ckpt_fingerprint_every_material
         * _param); linear elastic materials hash the constants above
         * alone, as blobs of earlier releases did */
        const mpm_material_desc *d = &s->mdesc[i];
        const mpm_material_model *row = mpm_material_model_of(d->model);
        if (d->model == MPM_MODEL_LINEAR_ELASTIC) continue;
        double pv[33];
        int np = 0;
        pv[np++] = (double)d->model;
        for (int j = 0; j < mpm_material_n_params(); j++)
            if (row->params >> j & 1u) pv[np++] = mpm_material_get(d, mpm_material_param_at(j));
        h = hash_bytes(pv, (size_t)np * sizeof *pv, h);
    }
    return h;
}

/* payload bytes of simulation s holding nload load slots (pforces: with the
 * tractions' shares) */
static size_t payload_size(const mpm_sim *s, size_t nload, int pforces)
{
    double *arr[CK_NARR];
    size_t n = s->P.n, d = (size_t)s->dim;
    size_t b = 8 * (S_COUNT + I_COUNT) + pad8(sizeof(mpm_error));
    b += (size_t)part_arrays(&s->P, s->dim, arr) * n * 8;
    b += pad8(n * sizeof *s->P.mat) + pad8(n * sizeof *s->P.id);
    b += nload * 8 + d * nload * 8 * (pforces ? 2 : 1);
    b += pad8(s->nfric);
    return b;
}

/* ---- writing and reading sections ---- */

typedef struct {
    unsigned char *p;
    size_t off;
} wcur;

static void put(wcur *w, const void *src, size_t n)
{
    if (n) memcpy(w->p + w->off, src, n);
    w->off += n;
    size_t e = pad8(n) - n;
    if (e) memset(w->p + w->off, 0, e);
    w->off += e;
}

typedef struct {
    const unsigned char *p;
    size_t off;
} rcur;

static void get(rcur *r, void *dst, size_t n)
{
    if (n) memcpy(dst, r->p + r->off, n);
    r->off += pad8(n);
}

size_t mpm_sim_checkpoint_size(const mpm_sim *s)
{
    return sizeof(ck_header) + payload_size(s, s->nload, s->pforces);
}

int mpm_sim_checkpoint_save(const mpm_sim *s, void *buf, size_t n)
{
    size_t need = mpm_sim_checkpoint_size(s);
    if (!buf || n < need) return MPM_ETOOBIG;
    ck_header h;
    memset(&h, 0, sizeof h);
    memcpy(h.magic, ck_magic, sizeof h.magic);
    h.version = CK_VERSION;
    h.header_size = (uint32_t)sizeof h;
    h.order = CK_ORDER;
    h.payload_size = need - sizeof h;
    layout_of(s, h.layout);
    h.fingerprint = fingerprint_of(s, h.layout);

    const mpm_particles *P = &s->P;
    wcur w = {(unsigned char *)buf + sizeof h, 0};
    double sv[S_COUNT];
    int64_t iv[I_COUNT];
    sv[S_T] = s->t;
    sv[S_DT] = s->dt;
    sv[S_VMAX] = s->vmax;
    sv[S_WEXT] = s->external_work;
    sv[S_WEXT_ABS] = s->external_work_abs;
    sv[S_WPRES] = s->prescribed_work;
    sv[S_WPRES_ABS] = s->prescribed_work_abs;
    sv[S_WFRIC] = s->friction_work;
    sv[S_WPLAST] = s->plastic_work;
    sv[S_WDAMP] = s->damping_work;
    sv[S_ETOT0] = s->e_total0;
    sv[S_EFLOOR] = s->e_floor;
    sv[S_GUARD_V2] = s->guard_v2;
    sv[S_BAL_TOTAL0] = s->bal_total0;
    sv[S_BAL_REF0] = s->bal_ref0;
    sv[S_BAL_POT0] = s->bal_pot0;
    sv[S_BAL_LAST] = s->bal_last;
    sv[S_BAL_WORST] = s->bal_worst;
    iv[I_STEPS] = s->steps;
    iv[I_PLUPD] = s->plstats.updates;
    iv[I_PLSUB] = s->plstats.substeps;
    iv[I_PLMAX] = s->plstats.max_substeps;
    iv[I_PFORCES] = s->pforces;
    iv[I_NLOAD] = (int64_t)s->nload;
    iv[I_FAILED] = s->failed;
    iv[I_SORTLAST] = s->sort_last;
    iv[I_RUNS0] = (int64_t)s->runs0;
    put(&w, sv, sizeof sv);
    put(&w, iv, sizeof iv);
    put(&w, &s->err, sizeof s->err);
    double *arr[CK_NARR];
    int na = part_arrays(P, s->dim, arr);
    for (int i = 0; i < na; i++) put(&w, arr[i], P->n * sizeof(double));
    put(&w, P->mat, P->n * sizeof *P->mat);
    put(&w, P->id, P->n * sizeof *P->id);
    for (size_t i = 0; i < s->nload; i++) {
        uint64_t lp = s->load_p[i];
        memcpy(w.p + w.off, &lp, sizeof lp);
        w.off += sizeof lp;
    }
    for (int d = 0; d < s->dim; d++) put(&w, s->load_f[d], s->nload * sizeof(double));
    for (int d = 0; s->pforces && d < s->dim; d++) put(&w, s->trac_f[d], s->nload * sizeof(double));
    put(&w, s->fric_stick, s->nfric);

    uint64_t ck = hash_bytes(&h, sizeof h, 0);
    h.checksum = hash_bytes(w.p, w.off, ck);
    memcpy(buf, &h, sizeof h);
    return 0;
}

/* ---- loading ---- */

#define CK_FIELD "checkpoint"

/* Layout word i's value v as a refusal names it: the schema's enum names,
 * the arrays by name, counts as numbers. */
static const char *layout_value(int i, uint64_t v, char *buf, size_t n)
{
    static const char *const volume[] = {"STRAIN_INCREMENT", "DET_F", "CONSTANT"};
    static const char *const damping[] = {"NONE", "LOCAL", "VISCOUS"};
    static const char *const arrays[] = {"half-widths",    "F",        "APIC B",
                                         "plastic strain", "yielded",  "initial volume",
                                         "strain",         "stress zz"};
    const char *const *names = NULL;
    size_t nn = 0;
    switch (i) { /* the choices' names from their table (mpm_names.c) */
    case L_METHOD:
        if (v < MPM_N_METHODS) return snprintf(buf, n, "%s", mpm_method_name((mpm_method)v)), buf;
        break;
    case L_UPDATE:
        if (v < MPM_N_UPDATES) return snprintf(buf, n, "%s", mpm_update_name((mpm_update)v)), buf;
        break;
    case L_TRANSFER:
        if (v < MPM_N_TRANSFERS)
            return snprintf(buf, n, "%s", mpm_transfer_name((mpm_transfer)v)), buf;
        break;
    case L_VOLUME: names = volume, nn = 3; break;
    case L_DAMPING: names = damping, nn = 3; break;
    default: break;
    }
    if (names && v < nn) {
        snprintf(buf, n, "%s", names[v]);
    } else if (i == L_ARRAYS) {
        size_t w = (size_t)snprintf(buf, n, "(");
        for (int b = 0; b < 8; b++)
            if ((v & (1u << b)) && w < n)
                w += (size_t)snprintf(buf + w, n - w, "%s%s", w > 1 ? ", " : "", arrays[b]);
        if (w < n) snprintf(buf + w, n - w, ")");
    } else {
        snprintf(buf, n, "%llu", (unsigned long long)v);
    }
    return buf;
}

/* The checks that need no simulation: header, sizes, checksum. */
static int verify_blob(const unsigned char *b, size_t n, ck_header *h, mpm_error *err)
{
    if (!b || n < sizeof *h)
        return mpm_fail(err, MPM_ESYNTAX, CK_FIELD,
                        "not a checkpoint: %zu bytes, shorter than its %zu-byte header", b ? n : 0,
                        sizeof *h);
    memcpy(h, b, sizeof *h);
    if (memcmp(h->magic, ck_magic, sizeof h->magic))
        return mpm_fail(err, MPM_ESYNTAX, CK_FIELD, "not a checkpoint (no checkpoint magic)");
    if (h->version != CK_VERSION)
        return mpm_fail(err, MPM_EVERSION, CK_FIELD,
                        "checkpoint format version %u, this solver reads version %u",
                        (unsigned)h->version, CK_VERSION);
    if (h->order != CK_ORDER)
        return mpm_fail(err, MPM_EVERSION, CK_FIELD,
                        "the checkpoint was written on a machine of another byte order");
    if (h->header_size != sizeof *h)
        return mpm_fail(err, MPM_ESYNTAX, CK_FIELD, "header size %u, expected %zu",
                        (unsigned)h->header_size, sizeof *h);
    if (h->payload_size != n - sizeof *h)
        return mpm_fail(err, MPM_ESYNTAX, CK_FIELD,
                        "truncated or padded: the header announces %llu payload bytes, the "
                        "blob has %zu",
                        (unsigned long long)h->payload_size, n - sizeof *h);
    if (h->payload_size < 8 * (S_COUNT + I_COUNT))
        return mpm_fail(err, MPM_ESYNTAX, CK_FIELD, "a payload of %llu bytes has no state",
                        (unsigned long long)h->payload_size);
    ck_header z = *h;
    z.checksum = 0;
    uint64_t ck = hash_bytes(b + sizeof z, n - sizeof z, hash_bytes(&z, sizeof z, 0));
    if (ck != h->checksum)
        return mpm_fail(err, MPM_ESYNTAX, CK_FIELD,
                        "checksum mismatch: the checkpoint is corrupted (%016llx stored, "
                        "%016llx computed)",
                        (unsigned long long)h->checksum, (unsigned long long)ck);
    return 0;
}

int mpm_checkpoint_verify(const void *buf, size_t n, mpm_error *err)
{
    ck_header h;
    mpm_error_clear(err);
    return verify_blob(buf, n, &h, err);
}

/* Everything checked before anything is written. */
static int check_blob(const mpm_sim *s, const unsigned char *b, size_t n, ck_header *h,
                      mpm_error *err)
{
    int rc = verify_blob(b, n, h, err);
    if (rc) return rc;
    uint64_t L[L_COUNT];
    layout_of(s, L);
    for (int i = 0; i < L_COUNT; i++)
        if (L[i] != h->layout[i]) {
            char a[96], c[96];
            return mpm_fail(err, MPM_EINVAL, CK_FIELD,
                            "saved from a case of another layout: %s %s in the checkpoint, %s in "
                            "this case",
                            ck_name[i], layout_value(i, h->layout[i], a, sizeof a),
                            layout_value(i, L[i], c, sizeof c));
        }
    if (fingerprint_of(s, L) != h->fingerprint)
        return mpm_fail(err, MPM_EINVAL, CK_FIELD,
                        "saved from another case of the same layout: the grid's spacing or "
                        "origin, the time step, the materials (their parameters), gravity, "
                        "the PIC fraction or the damping differ");
    return 0;
}

int mpm_sim_checkpoint_load(mpm_sim *s, const void *buf, size_t n, mpm_error *err)
{
    const unsigned char *b = buf;
    ck_header h;
    mpm_error_clear(err);
    int rc = check_blob(s, b, n, &h, err);
    if (rc) return rc;
    rcur r = {b + sizeof h, 0};
    double sv[S_COUNT];
    int64_t iv[I_COUNT];
    get(&r, sv, sizeof sv);
    get(&r, iv, sizeof iv);
    size_t np = s->P.n;
    int pf = iv[I_PFORCES] != 0;
    size_t nload = (size_t)iv[I_NLOAD];
    if (iv[I_PFORCES] < 0 || iv[I_PFORCES] > 1 || iv[I_NLOAD] < 0 || iv[I_STEPS] < 0 ||
        iv[I_FAILED] > 0 || iv[I_FAILED] < MPM_E_LAST || (pf && nload != np) ||
        (!pf && nload > np) || iv[I_SORTLAST] < 0 || iv[I_SORTLAST] > iv[I_STEPS] ||
        iv[I_RUNS0] < 0 || (uint64_t)iv[I_RUNS0] > np)
        return mpm_fail(err, MPM_ESYNTAX, CK_FIELD, "inconsistent state counters");
    if (payload_size(s, nload, pf) != h.payload_size)
        return mpm_fail(err, MPM_ESYNTAX, CK_FIELD, "the payload's size does not match its layout");
    if (!pf && s->pforces)
        return mpm_fail(err, MPM_EINVAL, CK_FIELD,
                        "this simulation has particle forces set and the checkpoint has none: "
                        "load into a fresh simulation");
    if (!pf && nload != s->nload)
        return mpm_fail(err, MPM_EINVAL, CK_FIELD,
                        "saved from a case of another layout: %zu particles under tractions or "
                        "point forces in the checkpoint, %zu in this case",
                        nload, s->nload);
    /* the particles' sections: the materials and creation indices checked
     * (the creation indices a permutation: the scratch marks them) */
    double *arr[CK_NARR];
    int na = part_arrays(&s->P, s->dim, arr);
    size_t off_err = r.off, off_arr = off_err + pad8(sizeof(mpm_error));
    size_t off_mat = off_arr + (size_t)na * np * 8;
    size_t off_id = off_mat + pad8(np * sizeof *s->P.mat);
    size_t off_load = off_id + pad8(np * sizeof *s->P.id);
    const unsigned char *pl = r.p;
    for (size_t p = 0; p < np; p++) {
        uint16_t m;
        memcpy(&m, pl + off_mat + p * sizeof m, sizeof m);
        if (m >= s->nmat)
            return mpm_fail(err, MPM_ESYNTAX, CK_FIELD, "particle slot %zu has material %u of %zu",
                            p, (unsigned)m, s->nmat);
    }
    unsigned char *seen = (unsigned char *)s->sperm; /* scratch between sorts: 4 np bytes */
    memset(seen, 0, np);
    for (size_t p = 0; p < np; p++) {
        uint32_t id;
        memcpy(&id, pl + off_id + p * sizeof id, sizeof id);
        if (id >= np || seen[id])
            return mpm_fail(err, MPM_ESYNTAX, CK_FIELD,
                            "the particles' creation indices are not a permutation (slot %zu)", p);
        seen[id] = 1;
    }
    for (size_t i = 0; i < nload; i++) {
        uint64_t lp;
        memcpy(&lp, pl + off_load + i * sizeof lp, sizeof lp);
        if (lp >= np)
            return mpm_fail(err, MPM_ESYNTAX, CK_FIELD,
                            "load slot %zu names particle slot %llu of %zu", i,
                            (unsigned long long)lp, np);
    }
    /* the one allocation: the particle forces' slots */
    if (pf && !s->pforces && mpm_loads_per_particle(s))
        return mpm_fail(err, MPM_ENOMEM, NULL, "out of memory for %zu particle forces", np);

    /* ---- nothing fails from here ---- */
    s->t = sv[S_T];
    s->dt = sv[S_DT];
    s->vmax = sv[S_VMAX];
    s->external_work = sv[S_WEXT];
    s->external_work_abs = sv[S_WEXT_ABS];
    s->prescribed_work = sv[S_WPRES];
    s->prescribed_work_abs = sv[S_WPRES_ABS];
    s->friction_work = sv[S_WFRIC];
    s->plastic_work = sv[S_WPLAST];
    s->damping_work = sv[S_WDAMP];
    s->e_total0 = sv[S_ETOT0];
    s->e_floor = sv[S_EFLOOR];
    s->guard_v2 = sv[S_GUARD_V2];
    s->bal_total0 = sv[S_BAL_TOTAL0];
    s->bal_ref0 = sv[S_BAL_REF0];
    s->bal_pot0 = sv[S_BAL_POT0];
    s->bal_last = sv[S_BAL_LAST];
    s->bal_worst = sv[S_BAL_WORST];
    s->steps = (long)iv[I_STEPS];
    s->plstats.updates = iv[I_PLUPD];
    s->plstats.substeps = iv[I_PLSUB];
    s->plstats.max_substeps = (int)iv[I_PLMAX];
    s->failed = (int)iv[I_FAILED];
    s->sort_last = (long)iv[I_SORTLAST];
    s->runs0 = (size_t)iv[I_RUNS0];
    get(&r, &s->err, sizeof s->err);
    s->err.message[MPM_ERROR_MSG_MAX - 1] = 0; /* kept a valid string */
    if (s->err.depth < 0 || s->err.depth > MPM_PATH_MAX) s->err.depth = 0;
    for (int i = 0; i < MPM_PATH_MAX; i++) s->err.path[i].name[MPM_PATH_NAME_MAX - 1] = 0;
    for (int i = 0; i < na; i++) get(&r, arr[i], np * sizeof(double));
    get(&r, s->P.mat, np * sizeof *s->P.mat);
    get(&r, s->P.id, np * sizeof *s->P.id);
    for (size_t i = 0; i < nload; i++) {
        uint64_t lp;
        memcpy(&lp, r.p + r.off, sizeof lp);
        r.off += sizeof lp;
        s->load_p[i] = (size_t)lp;
    }
    for (int d = 0; d < s->dim; d++) get(&r, s->load_f[d], nload * sizeof(double));
    for (int d = 0; pf && d < s->dim; d++) get(&r, s->trac_f[d], nload * sizeof(double));
    get(&r, s->fric_stick, s->nfric);

    /* the step's per-thread sums start empty; the energies are summed anew */
    for (int t = 0; t < s->nthreads; t++) {
        mpm_thread_out *o = &s->tout[t];
        o->wplast = o->edamp = o->wpres = o->wfric = 0;
        o->plupd = o->plsub = 0;
        o->plmax = 0;
        o->plbad = SIZE_MAX;
    }
    s->ecache_ok = 0;
    s->step_energy = 0;
    /* a fused scatter of the next step belongs to the particles replaced:
     * dropped (the next step scatters anew); then what the last particle
     * pass recorded: the slices' support boxes and row extents of the
     * particles as they are; then the active rows */
    mpm_rows_drop_next(s);
    mpm_team_run(s, mpm_ph_bbox);
    mpm_rows_update(s);
    return 0;
}
