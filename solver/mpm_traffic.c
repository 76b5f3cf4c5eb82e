/*
 * mpm_traffic.c - the modelled particle-array traffic of one step
 * (mpm_sim_traffic(), mpm.h): which particle arrays each particle pass of
 * the job's step reads and writes, as bytes per particle, and their sum
 * per particle-step.  bin/mpmbench multiplies it by the measured rate to
 * give the bandwidth a run achieves against a STREAM triad (docs/performance.md).
 *
 * The passes are a table, one static function per update scheme (usf(),
 * usl(), musl()), each pass a pair of field masks (read, written) built
 * from three pieces shared by the schemes: what the weights of a particle
 * read (wts(): x, and lp for uGIMP, F and lp for CPDI), what the stress
 * update reads and writes (upd(): the model's arrays and the volume
 * update's), and the fixed arrays of the scatters and gathers.  When the
 * passes of mpm_kernels.inc / mpm_cpdi.c change (fusing G2P with the next
 * P2G, narrower storage), the table here changes with them.  Fused jobs
 * (mpm_sim.plan.fuse, every family but CPDI): the pass that moves the particles
 * also makes the next step's first scatter, which then reads only what
 * that pass has not touched yet (mass, mostly), in every step: a step
 * that sorts does so after that scatter (mpm_sim.c sort_after_first()).
 *
 * The model (also in mpm.h and docs/performance.md):
 *   - a particle array counts once per pass that touches it: read when the
 *     pass loads its old value from memory, written when it stores one (an
 *     array read and written counts twice, one only written once: STREAM's
 *     counting, no write-allocate); an array a pass writes and then reads
 *     again (the USF stress pass's force scatter reading the stress a
 *     Neo-Hookean update just wrote) is not read again;
 *   - 8 bytes per double per particle, mat 2 and id 4; a field's width is
 *     what the job allocates (2D: three strain arrays, eps_zz has none;
 *     lp only for uGIMP and CPDI; F when a model, the volume update or CPDI
 *     needs it; B only with APIC; epsp and yld with a plastic model; vol0
 *     with the DET_F volume update), so an array the job lacks counts 0;
 *   - not counted: grid arrays (nodes), the per-thread scratch (the USF
 *     block's weights and strain increments), the sort of every
 *     MPM_SORT_EVERY steps, point loads and tractions, the energy sums of
 *     a step that wants energies (esum: m, v, x again).
 *   - several materials with different models: the union of their
 *     arrays (an upper bound).
 * Example, 2D MPM USF linear elastic, unfused and with a strain record
 * and sigma_zz stored (the releases before the fused steps): p2g_mq reads x v
 * m (40 B); stress_force reads x mat sig eps vol (16 + 2 + 32 + 24 + 8 =
 * 82) and writes sig eps vol (64); g2p_xv reads and writes x v (32 + 32):
 * 250 B.  Fused, without the strain record and sigma_zz (now):
 * stress_force reads x mat sig vol (16 + 2 + 24 + 8 = 50) and writes sig
 * vol (32); g2p_xv + next p2g_mq reads x v m (40) and writes x v (32); the
 * sort step's p2g_mq 40 / 16 = 2.5: 156.5 B.
 */
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_method.h"

#include <string.h>

/* particle fields (mpm_particles) */
enum {
    TF_X = 1 << 0,
    TF_V = 1 << 1,
    TF_M = 1 << 2,
    TF_VOL = 1 << 3,
    TF_LP = 1 << 4,
    TF_F = 1 << 5,
    TF_SIG = 1 << 6,
    TF_EPS = 1 << 7,
    TF_EPSP = 1 << 8,
    TF_YLD = 1 << 9,
    TF_VOL0 = 1 << 10,
    TF_MAT = 1 << 11,
    TF_ID = 1 << 12,
    TF_B = 1 << 13
};

typedef struct {
    const char *name;
    unsigned rd, wr;
} tpass;

/* arrays of a vector / matrix field the job allocated */
static int count9(double *const a[9])
{
    int n = 0;
    for (int i = 0; i < 9; i++) n += a[i] != NULL;
    return n;
}

/* bytes per particle of the fields in mask f */
static double field_bytes(const mpm_sim *s, unsigned f)
{
    const mpm_particles *P = &s->P;
    int n = 0;
    if (f & TF_X)
        for (int d = 0; d < 3; d++) n += P->x[d] != NULL;
    if (f & TF_V)
        for (int d = 0; d < 3; d++) n += P->v[d] != NULL;
    if (f & TF_LP)
        for (int d = 0; d < 3; d++) n += P->lp[d] != NULL;
    if (f & TF_SIG)
        for (int c = 0; c < 6; c++) n += P->sig[c] != NULL;
    if (f & TF_EPS)
        for (int c = 0; c < 6; c++) n += P->eps[c] != NULL;
    if (f & TF_F) n += count9(P->F);
    if (f & TF_B) n += count9(P->B);
    n += (f & TF_M) && P->m;
    n += (f & TF_VOL) && P->vol;
    n += (f & TF_EPSP) && P->epsp;
    n += (f & TF_YLD) && P->yld;
    n += (f & TF_VOL0) && P->vol0;
    double b = 8.0 * n;
    if ((f & TF_MAT) && P->mat) b += sizeof *P->mat;
    if ((f & TF_ID) && P->id) b += sizeof *P->id;
    return b;
}

/* What the weights of one particle read: x; uGIMP lp; CPDI its domain,
 * F and lp (mpm_kernels.inc weights_n0(), mpm_cpdi.c cweights()). */
static unsigned wts(const mpm_sim *s)
{
    unsigned f = mpm_method_props_of(s->method)->flags;
    return TF_X | (f & MPM_METH_HALF_WIDTHS ? TF_LP : 0) | (f & MPM_METH_DOMAIN_F ? TF_F : 0);
}

/* The stress update of a block (mpm_pass.h block_update(), mpm_model.c):
 * fields read into *rd, written into *wr. */
static void upd(const mpm_sim *s, unsigned *rd, unsigned *wr)
{
    if (!s->plan.general) { /* linear elasticity, V *= 1 + tr deps */
        *rd |= TF_MAT | TF_SIG | TF_EPS | TF_VOL;
        *wr |= TF_SIG | TF_EPS | TF_VOL;
        return;
    }
    if (s->f_block) { /* F <- (I + dt L) F */
        *rd |= TF_F;
        *wr |= TF_F;
    }
    unsigned needs = 0; /* the materials' models' (one model unless mixed) */
    for (size_t i = 0; i < s->nmat; i++) needs |= mpm_material_model_of(s->mdesc[i].model)->needs;
    *rd |= TF_MAT | TF_EPS; /* mat: the model's parameters (mixed: its runs) */
    *wr |= TF_SIG | TF_EPS;
    if (needs & MPM_NEED_PLASTIC) /* rate form: sig, the state, the work (V) */
        *rd |= TF_SIG | TF_EPSP | TF_VOL, *wr |= TF_EPSP | TF_YLD;
    if (!(needs & (MPM_NEED_PLASTIC | MPM_NEED_F)) || s->mixed)
        *rd |= TF_SIG; /* linear elasticity's increments (or a mixed job) */
    if (s->volmode == MPM_VOLUME_STRAIN_INCREMENT) {
        *rd |= TF_VOL;
        *wr |= TF_VOL;
    } else if (s->volmode == MPM_VOLUME_DET_F) {
        *rd |= TF_VOL0 | TF_F;
        *wr |= TF_VOL;
    }
}

/* fields the velocity update of a G2P reads (FLIP, or the PIC blend:
 * v += ...) and writes (APIC: v and B stored, v not read) */
static void vel(const mpm_sim *s, unsigned *rd, unsigned *wr)
{
    if (s->transfer == MPM_TRANSFER_APIC) {
        *wr |= TF_V | TF_B;
    } else {
        *rd |= TF_V;
        *wr |= TF_V;
    }
}

/* the momentum scatter: m v, APIC with B */
static unsigned mq(const mpm_sim *s)
{
    return TF_M | TF_V | (s->transfer == MPM_TRANSFER_APIC ? TF_B : 0u);
}

/* the pass that moves the particles: CPDI carries F there (mpm_cpdi.c
 * f_update()) */
static void moves(const mpm_sim *s, unsigned *rd, unsigned *wr)
{
    *rd |= TF_X;
    *wr |= TF_X;
    if (s->method == MPM_METHOD_CPDI) {
        *rd |= TF_F;
        *wr |= TF_F;
    }
}

/* the job's steps fuse (mpm_sim.plan.fuse: where it pays, or always) */
static int fused(const mpm_sim *s)
{
    return s->plan.fuse == MPM_FUSE_ALWAYS || (s->plan.fuse == MPM_FUSE_AUTO && s->fuse_pays);
}

/* The next step's first scatter, made by a fused pass (plan.fuse) at the
 * particles' new positions: it reads what its scatter needs (scat) that
 * the pass has not read or written already (mpm_kernels.inc p2g_one()). */
static void next_scatter(unsigned scat, unsigned *rd, unsigned wr)
{
    *rd |= scat & ~(*rd | wr);
}

/* USF: P2G (m, q); the stress pass (gather the strain increment, the
 * update, scatter the internal force with the new stress and volume);
 * G2P (x, v).  Fused: G2P also scatters the next step's m and q. */
static int usf(const mpm_sim *s, tpass *t)
{
    unsigned w = wts(s), rd = w, wr = 0;
    int n = 0;
    tpass first = {"p2g_mq", w | mq(s), 0};
    upd(s, &rd, &wr);
    rd |= (TF_SIG | TF_VOL) & ~wr; /* the force scatter: what the update left unread */
    tpass sf = {"stress_force", rd, wr};
    rd = w, wr = 0;
    moves(s, &rd, &wr);
    vel(s, &rd, &wr);
    if (fused(s)) next_scatter(w | mq(s), &rd, wr);
    tpass mv = {fused(s) ? "g2p_xv + next p2g_mq" : "g2p_xv", rd, wr};
    if (!fused(s)) t[n++] = first;
    t[n++] = sf;
    t[n++] = mv;
    return n;
}

/* USL: P2G (m, q, f with the old stress); G2P (x, v) with the strain
 * gather and the update.  Fused: one pass, the G2P scattering the next
 * step's m, q, f with the new stress. */
static int usl(const mpm_sim *s, tpass *t)
{
    unsigned w = wts(s), rd = w, wr = 0, scat = w | mq(s) | TF_SIG | TF_VOL;
    tpass first = {"p2g_mqf", scat, 0};
    moves(s, &rd, &wr);
    vel(s, &rd, &wr);
    upd(s, &rd, &wr);
    if (fused(s)) {
        next_scatter(scat, &rd, wr);
        t[0] = (tpass){"g2p_xv_stress + next p2g_mqf", rd, wr};
        return 1;
    }
    t[0] = first;
    t[1] = (tpass){"g2p_xv_stress", rd, wr};
    return 2;
}

/* MUSL: P2G (m, q, f); G2P v; P2G q2 (m v of the new velocities); G2P x
 * with the strain from q2 and the update (check_particle() reads v).
 * Fused: G2P v scatters q2 with its weights, and G2P x the next step's
 * m, q, f. */
static int musl(const mpm_sim *s, tpass *t)
{
    unsigned w = wts(s), rd = w, wr = 0, scat = w | mq(s) | TF_SIG | TF_VOL;
    tpass first = {"p2g_mqf", scat, 0};
    vel(s, &rd, &wr);
    if (fused(s)) {
        next_scatter(w | mq(s), &rd, wr);
        t[0] = (tpass){"g2p_v + p2g_q2", rd, wr};
    } else {
        t[0] = first;
        t[1] = (tpass){"g2p_v", rd, wr};
        t[2] = (tpass){"p2g_q2", w | mq(s), 0};
    }
    rd = w | TF_V, wr = 0;
    moves(s, &rd, &wr);
    upd(s, &rd, &wr);
    if (fused(s)) {
        next_scatter(scat, &rd, wr);
        t[1] = (tpass){"g2p_x_stress + next p2g_mqf", rd, wr};
        return 2;
    }
    t[3] = (tpass){"g2p_x_stress", rd, wr};
    return 4;
}

int mpm_sim_traffic(const mpm_sim *s, mpm_traffic *out)
{
    if (!s || !out) return MPM_EINVAL;
    tpass t[MPM_TRAFFIC_MAX_PASSES];
    int n = s->update == MPM_USL ? usl(s, t) : s->update == MPM_MUSL ? musl(s, t) : usf(s, t);
    memset(out, 0, sizeof *out);
    out->npass = n;
    for (int i = 0; i < n; i++) {
        out->pass[i].name = t[i].name;
        out->pass[i].read = field_bytes(s, t[i].rd);
        out->pass[i].write = field_bytes(s, t[i].wr);
        out->read += out->pass[i].read;
        out->write += out->pass[i].write;
    }
    out->total = out->read + out->write;
    return 0;
}
