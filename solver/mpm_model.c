/*
 * mpm_model.c - constitutive models behind the mpm_model_ops interface, and
 * the general block update that carries F, dispatches by material and
 * updates the volume.
 *
 * The kernels compute strain increments for a block of particles (Eq. 29,
 * Fig. 7) and hand them to the model's update for the job's dimension.
 * Linear elasticity (small-strain, incremental: uniaxial in 1D, plane
 * strain in 2D with sigma_zz kept for the mean pressure, isotropic in 3D)
 * keeps its own direct path, the one of every earlier release, when it is
 * the case's only model and the volume update is the default.  Every other
 * job goes through mpm_model_block(): F <- (I + dt L) F when a model or the
 * volume update reads F, then each run of particles of one model through
 * that model's block function, then the volume (strain increment, det F,
 * or constant).  The models:
 *   NEO_HOOKEAN  compressible hyperelastic from F (not rate form),
 *                sigma = mu/J (b - I) + lambda ln J / J I,
 *                W = mu/2 (tr b - 3) - mu ln J + lambda/2 (ln J)^2;
 *                2D plane strain (F_zz = 1), 1D F = diag(F_xx, 1, 1)
 *                (lateral stretches fixed; 1D has nu = 0, so lambda = 0,
 *                mu = E/2 and the small-strain limit is sigma = E eps).
 *   VON_MISES    J2 plasticity, linear isotropic hardening, closed-form
 *                radial return, after the Jaumann rotation of the stress;
 *                1D uniaxial stress with the same yield rule.
 *   DRUCKER_PRAGER, MOHR_COULOMB  perfectly plastic, non-associated, with
 *                a tension cut-off: mpm_plastic_update() (mpm_plastic.h)
 *                after the Jaumann rotation, with the parameters that
 *                mpm_plastic_init() derived once per material; 2D plane
 *                strain (deps_zz = 0, sigma_zz kept), 3D; refused in 1D.
 *                Their block also counts the integrator's substeps.
 * The rate-form models share the Jaumann rotation, then the model's point
 * update (J2: rate_block() calling point(); DP, MC: frictional_block()).
 */
#include "mpm_model.h"
#include "mpm_internal.h"
#include "mpm_material_ops.h"
#include "mpm_plastic_avx2.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static void elastic_1d(const mpm_mat_params *mats, mpm_particles *P, size_t p0, size_t n,
                       double *const deps[6])
{
    const uint16_t *mat = P->mat + p0;
    double *sxx = P->sig[0] + p0;
    for (size_t i = 0; i < n; i++) sxx[i] += mats[mat[i]].E * deps[0][i];
    if (P->eps[0]) /* the strain record, when kept (mpm_internal.h) */
        for (size_t i = 0; i < n; i++) P->eps[0][p0 + i] += deps[0][i];
}

/* Two doubles, eight material indices: the elastic blocks of one material
 * run two particles to an SSE2 operation (each lane the scalar loop's
 * operations, so the same bits; GCC -O2 does not vectorise loops of an
 * unknown count). */
typedef double m2d __attribute__((vector_size(16), aligned(8), may_alias));
typedef uint16_t m8u __attribute__((vector_size(16), aligned(2), may_alias));

/* Whether particles [0, n) are all of material mat[0] (n > 0). */
static int one_material(const uint16_t *mat, size_t n)
{
    const uint16_t m0 = mat[0];
    size_t i = 0;
    m8u d = {0, 0, 0, 0, 0, 0, 0, 0};
    for (; i + 8 <= n; i += 8) d |= *(const m8u *)(mat + i) ^ m0;
    unsigned diff = 0;
    for (int k = 0; k < 8; k++) diff |= d[k];
    for (; i < n; i++) diff |= (unsigned)(mat[i] ^ m0);
    return diff == 0;
}

static void elastic_2d(const mpm_mat_params *mats, mpm_particles *P, size_t p0, size_t n,
                       double *const deps[6])
{
    const uint16_t *mat = P->mat + p0;
    double *s0 = P->sig[0] + p0, *s1 = P->sig[1] + p0, *s3 = P->sig[3] + p0;
    double *s2 = P->sig[2] ? P->sig[2] + p0 : NULL; /* plane strain: eps_zz = 0 (else
                                                       derived, mpm_sig_zz()) */
    size_t i = 0;
    if (n && one_material(mat, n)) { /* two particles at a time, an odd one below */
        const double la = mats[mat[0]].lambda, m2 = 2.0 * mats[mat[0]].mu;
        for (; i + 2 <= n; i += 2) {
            m2d a = *(const m2d *)(deps[0] + i), b = *(const m2d *)(deps[1] + i);
            m2d lt = la * (a + b);
            *(m2d *)(s0 + i) += lt + m2 * a;
            *(m2d *)(s1 + i) += lt + m2 * b;
            *(m2d *)(s3 + i) += m2 * *(const m2d *)(deps[3] + i);
            if (s2) *(m2d *)(s2 + i) += lt;
        }
    }
    for (; i < n; i++) {
        const mpm_mat_params *mp = &mats[mat[i]];
        double dxx = deps[0][i], dyy = deps[1][i], dxy = deps[3][i];
        double lt = mp->lambda * (dxx + dyy), m2 = 2.0 * mp->mu;
        s0[i] += lt + m2 * dxx;
        s1[i] += lt + m2 * dyy;
        s3[i] += m2 * dxy;
        if (s2) s2[i] += lt;
    }
    if (P->eps[0]) { /* the strain record, when kept (mpm_internal.h) */
        double *e0 = P->eps[0] + p0, *e1 = P->eps[1] + p0, *e3 = P->eps[3] + p0;
        for (size_t k = 0; k < n; k++) {
            e0[k] += deps[0][k];
            e1[k] += deps[1][k];
            e3[k] += deps[3][k];
        }
    }
}

static void elastic_3d(const mpm_mat_params *mats, mpm_particles *P, size_t p0, size_t n,
                       double *const deps[6])
{
    const uint16_t *mat = P->mat + p0;
    double *restrict s[6];
    const double *restrict de[6];
    for (int c = 0; c < 6; c++) {
        s[c] = P->sig[c] + p0;
        de[c] = deps[c];
    }
    size_t i0 = 0;
    if (n && one_material(mat, n)) { /* two particles at a time, an odd one below */
        const double la = mats[mat[0]].lambda, m2 = 2.0 * mats[mat[0]].mu;
        for (; i0 + 2 <= n; i0 += 2) {
            m2d e[6];
            for (int c = 0; c < 6; c++) e[c] = *(const m2d *)(de[c] + i0);
            m2d lt = la * (e[0] + e[1] + e[2]);
            for (int c = 0; c < 3; c++) *(m2d *)(s[c] + i0) += lt + m2 * e[c];
            for (int c = 3; c < 6; c++) *(m2d *)(s[c] + i0) += m2 * e[c];
        }
    }
    for (size_t i = i0; i < n; i++) {
        const mpm_mat_params *mp = &mats[mat[i]];
        double d0 = de[0][i], d1 = de[1][i], d2 = de[2][i], d3 = de[3][i], d4 = de[4][i],
               d5 = de[5][i];
        double lt = mp->lambda * (d0 + d1 + d2), m2 = 2.0 * mp->mu;
        s[0][i] += lt + m2 * d0;
        s[1][i] += lt + m2 * d1;
        s[2][i] += lt + m2 * d2;
        s[3][i] += m2 * d3;
        s[4][i] += m2 * d4;
        s[5][i] += m2 * d5;
    }
    if (P->eps[0]) /* the strain record, when kept (mpm_internal.h) */
        for (int c = 0; c < 6; c++) {
            double *restrict e = P->eps[c] + p0;
            for (size_t i = 0; i < n; i++) e[i] += de[c][i];
        }
}

static double elastic_energy(const mpm_mat_params *mp, const mpm_particles *P, int dim, size_t p)
{
    if (!P->eps[0]) { /* no strain record: mpm_strain_density()'s bits */
        double sig[6];
        mpm_particle_stress(mp, P, dim, p, sig);
        return 0.5 * (2.0 * mpm_elastic_stored(mp, sig, dim)) * P->vol[p];
    }
    return 0.5 * mpm_strain_density(NULL, P, dim, p) * P->vol[p];
}

/* Block slots [i0, i1) of deps as arrays from slot i0. */
static void shift(double *const *deps, size_t i0, double *d[6])
{
    for (int c = 0; c < 6; c++) d[c] = deps[c] ? deps[c] + i0 : NULL;
}

static void elastic_block(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    double *d[6];
    shift(b->deps, i0, d);
    if (b->dim == 1)
        elastic_1d(b->mats, b->P, b0 + i0, i1 - i0, d);
    else if (b->dim == 2)
        elastic_2d(b->mats, b->P, b0 + i0, i1 - i0, d);
    else
        elastic_3d(b->mats, b->P, b0 + i0, i1 - i0, d);
}

/* ---- kinematics ---- */

static inline void jaumann_3d(double sig[6], const double w[3])
{
    double S[3][3] = {{sig[0], sig[3], sig[5]}, {sig[3], sig[1], sig[4]}, {sig[5], sig[4], sig[2]}};
    double W[3][3] = {{0, w[0], w[2]}, {-w[0], 0, w[1]}, {-w[2], -w[1], 0}};
    double R[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double a = 0;
            for (int k = 0; k < 3; k++) a += W[i][k] * S[k][j] - S[i][k] * W[k][j];
            R[i][j] = S[i][j] + a;
        }
    sig[0] = R[0][0];
    sig[1] = R[1][1];
    sig[2] = R[2][2];
    sig[3] = R[0][1];
    sig[4] = R[1][2];
    sig[5] = R[0][2];
}

void mpm_jaumann(double sig[6], const double w[3], int dim)
{
    if (dim == 1) return;
    if (dim == 2) {
        double wxy = w[0], xx = sig[0], yy = sig[1], xy = sig[3];
        /* (W s - s W) with W = [[0, w], [-w, 0]] */
        sig[0] = xx + 2.0 * wxy * xy;
        sig[1] = yy - 2.0 * wxy * xy;
        sig[3] = xy + wxy * (yy - xx);
        return;
    }
    jaumann_3d(sig, w);
}

/* dt L of block slot i from the increments and spins (mpm_pass.h). */
static void dtl_of(double *const *deps, size_t i, int D, double A[3][3])
{
    memset(A, 0, 9 * sizeof(double));
    A[0][0] = deps[0][i];
    if (D == 2) {
        double w = deps[2][i], e = deps[3][i];
        A[1][1] = deps[1][i];
        A[0][1] = e + w;
        A[1][0] = e - w;
    } else if (D == 3) {
        A[1][1] = deps[1][i];
        A[2][2] = deps[2][i];
        A[0][1] = deps[3][i] + deps[6][i];
        A[1][0] = deps[3][i] - deps[6][i];
        A[1][2] = deps[4][i] + deps[7][i];
        A[2][1] = deps[4][i] - deps[7][i];
        A[0][2] = deps[5][i] + deps[8][i];
        A[2][0] = deps[5][i] - deps[8][i];
    }
}

/* F <- (I + dt L) F for the block's particles. */
static void f_block(mpm_sim *s, double *const *deps, size_t b0, size_t nb, int D)
{
    double *const *F = s->P.F;
    for (size_t i = 0; i < nb; i++) {
        size_t p = b0 + i;
        double A[3][3], Fo[3][3];
        dtl_of(deps, i, D, A);
        for (int a = 0; a < D; a++)
            for (int b = 0; b < D; b++) Fo[a][b] = F[a * D + b][p];
        for (int a = 0; a < D; a++)
            for (int b = 0; b < D; b++) {
                double v = 0;
                for (int k = 0; k < D; k++) v += A[a][k] * Fo[k][b];
                F[a * D + b][p] = Fo[a][b] + v;
            }
    }
}

/* F of particle p as a 3x3 (2D: F_zz = 1; 1D: F_yy = F_zz = 1); returns
 * det F. */
static double f_of(const mpm_particles *P, int D, size_t p, double F[3][3])
{
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) F[a][b] = a < D && b < D ? P->F[a * D + b][p] : (a == b);
    return F[0][0] * (F[1][1] * F[2][2] - F[2][1] * F[1][2]) -
           F[0][1] * (F[1][0] * F[2][2] - F[2][0] * F[1][2]) +
           F[0][2] * (F[1][0] * F[2][1] - F[2][0] * F[1][1]);
}

double mpm_det_f(const mpm_particles *P, int D, size_t p)
{
    double F[3][3];
    return f_of(P, D, p, F);
}

/* ---- Neo-Hookean ---- */

void mpm_neo_hookean_stress(const mpm_mat_params *mp, const double Fm[3][3], double sig[6],
                            double *W)
{
    double b[3][3];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double a = 0;
            for (int k = 0; k < 3; k++) a += Fm[i][k] * Fm[j][k];
            b[i][j] = a;
        }
    double J = Fm[0][0] * (Fm[1][1] * Fm[2][2] - Fm[2][1] * Fm[1][2]) -
               Fm[0][1] * (Fm[1][0] * Fm[2][2] - Fm[2][0] * Fm[1][2]) +
               Fm[0][2] * (Fm[1][0] * Fm[2][1] - Fm[2][0] * Fm[1][1]);
    double lnJ = log(J), mj = mp->mu / J, vol = mp->lambda * lnJ / J;
    sig[0] = mj * (b[0][0] - 1.0) + vol;
    sig[1] = mj * (b[1][1] - 1.0) + vol;
    sig[2] = mj * (b[2][2] - 1.0) + vol;
    sig[3] = mj * b[0][1];
    sig[4] = mj * b[1][2];
    sig[5] = mj * b[0][2];
    if (W)
        *W = 0.5 * mp->mu * (b[0][0] + b[1][1] + b[2][2] - 3.0) - mp->mu * lnJ +
             0.5 * mp->lambda * lnJ * lnJ;
}

static void nh_block(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    mpm_particles *P = b->P;
    int D = b->dim, nc = MPM_NCOMP(D);
    for (size_t i = i0; i < i1; i++) {
        size_t p = b0 + i;
        const mpm_mat_params *mp = &b->mats[P->mat[p]];
        double F[3][3], sig[6];
        f_of(P, D, p, F);
        mpm_neo_hookean_stress(mp, F, sig, NULL);
        for (int c = 0; c < nc; c++) {
            P->sig[c][p] = sig[c];
            /* the small-strain record, as linear elasticity keeps it (2D:
             * deps[2] is the spin, eps_zz has no array) */
            if (P->eps[c]) P->eps[c][p] += b->deps[c][i];
        }
    }
}

/* W(F) V0, with V0 = V / det F (the volume update need not be det F) */
static double nh_energy(const mpm_mat_params *mp, const mpm_particles *P, int dim, size_t p)
{
    double F[3][3], sig[6], W;
    double J = f_of(P, dim, p, F);
    mpm_neo_hookean_stress(mp, F, sig, &W);
    return W * P->vol[p] / J;
}

/* ---- rate-form models: Jaumann rotation, then the point update ---- */

/* Block slot i (particle p) for a rate-form update: its stress rotated by
 * the Jaumann term, and its strain increment de (Voigt, 6 entries; plane
 * strain: de_zz = 0, sigma_zz kept; the spin from deps[2] in 2D,
 * deps[6..8] in 3D). */
static void rate_gather(const mpm_model_blk *b, size_t i, size_t p, double sig[6], double de[6])
{
    const mpm_particles *P = b->P;
    int D = b->dim, nc = MPM_NCOMP(D);
    double *const *deps = b->deps;
    double w[3] = {0, 0, 0};
    for (int c = 0; c < 6; c++) sig[c] = de[c] = 0;
    for (int c = 0; c < nc; c++) sig[c] = P->sig[c][p];
    if (D == 2) {
        w[0] = deps[2][i];
        de[0] = deps[0][i];
        de[1] = deps[1][i];
        de[3] = deps[3][i];
    } else {
        for (int c = 0; c < nc; c++) de[c] = deps[c][i];
        if (D == 3)
            for (int k = 0; k < 3; k++) w[k] = deps[6 + k][i];
    }
    mpm_jaumann(sig, w, D);
}

/* The updated stress of particle p, and its strain plus de. */
static void rate_put(const mpm_model_blk *b, size_t p, const double sig[6], const double de[6])
{
    mpm_particles *P = b->P;
    for (int c = 0; c < MPM_NCOMP(b->dim); c++) {
        P->sig[c][p] = sig[c];
        if (P->eps[c]) P->eps[c][p] += de[c];
    }
}

static void rate_block(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    mpm_particles *P = b->P;
    int D = b->dim;
    for (size_t i = i0; i < i1; i++) {
        size_t p = b0 + i;
        const mpm_mat_params *mp = &b->mats[P->mat[p]];
        double sig[6], de[6];
        rate_gather(b, i, p, sig, de);
        double ep = P->epsp ? P->epsp[p] : 0.0, dwp = 0;
        int y = 0;
        mp->ops->point(mp, D, sig, de, &ep, &y, &dwp);
        rate_put(b, p, sig, de);
        if (P->epsp) {
            P->epsp[p] = ep;
            P->yld[p] = y ? 1.0 : 0.0;
        }
        b->wp += dwp * P->vol[p];
    }
}

/* ---- von Mises (J2) ---- */

int mpm_j2_point(const mpm_mat_params *mp, int dim, double sig[6], const double de[6], double *epsp,
                 int *yielded, double *dwp)
{
    double sy = mp->sy0 + mp->H * *epsp;
    *yielded = 0;
    if (dim == 1) { /* uniaxial stress */
        double st = sig[0] + mp->E * de[0], f = fabs(st) - sy;
        if (f > 0) {
            double dg = f / (mp->E + mp->H), sg = st > 0 ? 1.0 : -1.0;
            st -= sg * mp->E * dg;
            *epsp += dg;
            *dwp += fabs(st) * dg;
            *yielded = 1;
        }
        sig[0] = st;
        return 0;
    }
    /* elastic trial (plane strain: de_zz = 0, sigma_zz follows) */
    double lt = mp->lambda * (de[0] + de[1] + de[2]), m2 = 2.0 * mp->mu;
    for (int c = 0; c < 3; c++) sig[c] += lt + m2 * de[c];
    for (int c = 3; c < 6; c++) sig[c] += m2 * de[c];
    double pm = (sig[0] + sig[1] + sig[2]) / 3.0, s[6];
    for (int c = 0; c < 6; c++) s[c] = c < 3 ? sig[c] - pm : sig[c];
    double ss =
        s[0] * s[0] + s[1] * s[1] + s[2] * s[2] + 2.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]);
    double q = sqrt(1.5 * ss), f = q - sy;
    if (f > 0) {
        double dg = f / (3.0 * mp->mu + mp->H), k = 1.0 - 3.0 * mp->mu * dg / q;
        for (int c = 0; c < 6; c++) sig[c] = c < 3 ? pm + k * s[c] : k * s[c];
        *epsp += dg;
        *dwp += (q - 3.0 * mp->mu * dg) * dg; /* sigma : d eps_p = q_new dg */
        *yielded = 1;
    }
    return 0;
}

/* 1/2 sigma : C^-1 : sigma V: s:s/(4 mu) + (tr sigma)^2/(18 K) per volume
 * (1D: sigma^2/(2E)); plane strain with sigma_zz tracked uses the 3D form.
 * es_lin4() (mpm_pass.h) is this formula in four lanes for the energy
 * sums (the energy pass and the step's in-pass sums), with the same
 * operations in the same order: a change here must go there too
 * (perf_energy_pass_matches_formulas compares the two bit for bit). */
double mpm_elastic_stored(const mpm_mat_params *mp, const double sig[6], int dim)
{
    if (dim == 1) return 0.5 * sig[0] * sig[0] / mp->E;
    double tr = sig[0] + sig[1] + sig[2], pm = tr / 3.0;
    double ss = (sig[0] - pm) * (sig[0] - pm) + (sig[1] - pm) * (sig[1] - pm) +
                (sig[2] - pm) * (sig[2] - pm) +
                2.0 * (sig[3] * sig[3] + sig[4] * sig[4] + sig[5] * sig[5]);
    return ss / (4.0 * mp->mu) + tr * tr / (18.0 * mp->K);
}

static double j2_energy(const mpm_mat_params *mp, const mpm_particles *P, int dim, size_t p)
{
    double sig[6] = {0, 0, 0, 0, 0, 0};
    for (int c = 0; c < MPM_NCOMP(dim); c++) sig[c] = P->sig[c][p];
    return mpm_elastic_stored(mp, sig, dim) * P->vol[p];
}

/* ---- Drucker-Prager and Mohr-Coulomb (mpm_plastic.h) ---- */

/* The point hook: the integrator with the material's parameters (1D is
 * refused at creation).  Returns its code (MPM_EDIVERGED: the stress and
 * state unchanged). */
static int frictional_point(const mpm_mat_params *mp, int dim, double sig[6], const double de[6],
                            double *epsp, int *yielded, double *dwp)
{
    (void)dim;
    mpm_plastic_state st = {*epsp, 0, 0};
    double d = 0;
    int rc = mpm_plastic_update(mp->pl, sig, de, &st, &d);
    if (rc) return rc;
    *epsp = st.eps_p;
    *yielded = st.yielded;
    *dwp += d;
    return 0;
}

/* The integrator's update of particle p from its rotated stress sig and
 * increment de (rate_gather()'s), counting the substeps
 * (mpm_sim_plastic_stats()) and keeping the first particle whose update
 * failed (its stress and state are left as they were). */
static void frictional_update(mpm_model_blk *b, const mpm_mat_params *mp, size_t p, double sig[6],
                              const double de[6])
{
    mpm_particles *P = b->P;
    mpm_plastic_state st = {P->epsp[p], 0, 0};
    double dwp = 0;
    if (mpm_plastic_update(mp->pl, sig, de, &st, &dwp)) {
        if (b->bad == SIZE_MAX) b->bad = p;
        return;
    }
    rate_put(b, p, sig, de);
    P->epsp[p] = st.eps_p;
    P->yld[p] = st.yielded ? 1.0 : 0.0;
    if (st.substeps) {
        b->nupd++;
        b->nsub += st.substeps;
        if (st.substeps > b->maxsub) b->maxsub = st.substeps;
    }
    b->wp += dwp * P->vol[p];
}

/* Drucker-Prager updates waiting for mpm_dp_lanes(): particles of one
 * material, in block order, with their rotated stress and increment.  A
 * queue is run (dp_flush()) when it is full, when the material changes,
 * before any other update of the block that adds to its sums, and at the
 * block's end, so the plastic work is summed in the particles' order and
 * every result has the bits of frictional_update(). */
typedef struct {
    const mpm_mat_params *mp;
    size_t n;
    size_t p[MPM_DP_LANES_MAX];
    double sig[6 * MPM_DP_LANES_MAX], de[6 * MPM_DP_LANES_MAX];
} dp_queue;

/* Runs the queue: the lanes' results stored as frictional_update() stores
 * its own; a particle the lanes leave goes through frictional_update(). */
static void dp_flush(mpm_model_blk *b, dp_queue *q)
{
    /* every caller sets q->n = 0 before its loop and dp_push() fills the
     * slots below q->n, the only ones read (cppcheck's cross-file check
     * sees the struct unset) */
    // cppcheck-suppress ctuuninitvar
    if (!q->n) return;
    mpm_particles *P = b->P;
    double epq[MPM_DP_LANES_MAX], dis[MPM_DP_LANES_MAX];
    int nsub[MPM_DP_LANES_MAX];
    unsigned char ok[MPM_DP_LANES_MAX];
    mpm_dp_lanes(q->mp->pl, b->dim == 3 ? 6 : 4, q->n, q->sig, q->de, epq, dis, nsub, ok);
    for (size_t k = 0; k < q->n; k++) {
        size_t p = q->p[k];
        double *sig = q->sig + 6 * k;
        const double *de = q->de + 6 * k;
        if (!ok[k]) {
            frictional_update(b, q->mp, p, sig, de);
            continue;
        }
        rate_put(b, p, sig, de);
        P->epsp[p] += epq[k];
        P->yld[p] = 1.0;
        if (nsub[k]) {
            b->nupd++;
            b->nsub += nsub[k];
            if (nsub[k] > b->maxsub) b->maxsub = nsub[k];
        }
        b->wp += dis[k] * P->vol[p];
    }
    q->n = 0;
}

/* The queue's next slot, for particle p of the Drucker-Prager material mp
 * (the queue run first when it is full or holds another material); the
 * caller fills the slot's rotated stress and increment. */
static size_t dp_slot(mpm_model_blk *b, dp_queue *q, const mpm_mat_params *mp, size_t p)
{
    if (q->n == MPM_DP_LANES_MAX || (q->n && q->mp != mp)) dp_flush(b, q);
    q->mp = mp;
    q->p[q->n] = p;
    return q->n++;
}

/* frictional_update() of particle p, or its place in the queue (a
 * Drucker-Prager particle, where the job has mpm_sim.plan.dp_lanes). */
static void dp_push(mpm_model_blk *b, dp_queue *q, const mpm_mat_params *mp, size_t p,
                    double sig[6], const double de[6])
{
    if (!b->dp_lanes || mp->pl->kind != MPM_PLASTIC_DRUCKER_PRAGER) {
        dp_flush(b, q);
        frictional_update(b, mp, p, sig, de);
        return;
    }
    size_t j = dp_slot(b, q, mp, p);
    memcpy(q->sig + 6 * j, sig, 6 * sizeof sig[0]);
    memcpy(q->de + 6 * j, de, 6 * sizeof de[0]);
}

/* rate_block() for the frictional models, with Drucker-Prager's elastic
 * case in the loop: the update's own first test, mpm_dp_trial(), and the
 * trial stress stored when it is admissible. */
static void frictional_block(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    mpm_particles *P = b->P;
    dp_queue q;
    q.n = 0;
    for (size_t i = i0; i < i1; i++) {
        size_t p = b0 + i;
        const mpm_mat_params *mp = &b->mats[P->mat[p]];
        double sig[6], de[6];
        rate_gather(b, i, p, sig, de);
        if (mp->pl->kind == MPM_PLASTIC_DRUCKER_PRAGER) {
            double De[6], tr[6], f;
            int on = 0;
            if (mpm_dp_trial(mp->pl, sig, de, De, tr, &f, &on) == MPM_DP_ELASTIC) {
                rate_put(b, p, tr, de);
                P->yld[p] = on ? 1.0 : 0.0;
                continue;
            }
        }
        dp_push(b, &q, mp, p, sig, de);
    }
    dp_flush(b, &q);
}

/* the Jaumann rotation (mpm_jaumann(), dim 2) of xx, yy, xy by the spin w */
static inline void jaumann_2d(double xx, double yy, double xy, double w, double *s0, double *s1,
                              double *s3)
{
    *s0 = xx + 2.0 * w * xy;
    *s1 = yy - 2.0 * w * xy;
    *s3 = xy + w * (yy - xx);
}

/* frictional_block() in 2D (plane strain, with sigma_zz and the strain
 * record, as the plastic models keep them).  A granular flow's particles
 * are mostly elastic at a step, and for them rate_gather(),
 * mpm_jaumann(), mpm_dp_trial() and rate_put() cost more than the rest of
 * the step's particle work: here they are written out for sig[4] =
 * sig[5] = 0 and de = (d0, d1, 0, d3, 0, 0), on the arrays' pointers
 * taken once, with the same operations in the same order (the zero terms
 * kept where they could turn a -0 into +0), so with the same bits.  A
 * particle that is not elastic, or not Drucker-Prager, goes to
 * frictional_update() (or the queue qp) with sig and de as rate_gather()
 * fills them.  frictional_block_2d() is this loop with a queue of its own;
 * mpm_dp_trial2d_lanes() (frictional_lanes_2d()) its elastic case four at
 * a time, with the same bits. */
static void frictional_2d(mpm_model_blk *b, size_t b0, size_t i0, size_t i1, dp_queue *qp)
{
    mpm_particles *P = b->P;
    const uint16_t *mat = P->mat + b0;
    const double *e0 = b->deps[0], *e1 = b->deps[1], *e2 = b->deps[2], *e3 = b->deps[3];
    double *x0 = P->sig[0] + b0, *x1 = P->sig[1] + b0, *x2 = P->sig[2] + b0, *x3 = P->sig[3] + b0;
    double *q0 = P->eps[0] + b0, *q1 = P->eps[1] + b0, *q3 = P->eps[3] + b0, *yld = P->yld + b0;
    for (size_t i = i0; i < i1; i++) {
        const mpm_mat_params *mp = &b->mats[mat[i]];
        const mpm_plastic_params *pl = mp->pl;
        double d0 = e0[i], d1 = e1[i], w = e2[i], d3 = e3[i];
        double xx = x0[i], yy = x1[i], zz = x2[i], xy = x3[i];
        double s0, s1, s3;
        jaumann_2d(xx, yy, xy, w, &s0, &s1, &s3);
        if (pl->kind == MPM_PLASTIC_DRUCKER_PRAGER) {
            /* the trial (mpm_dp_trial()) */
            double g2 = 2 * pl->G, let = pl->lam * (d0 + d1 + 0.0);
            double t0 = s0 + (let + g2 * d0), t1 = s1 + (let + g2 * d1), t2 = zz + (let + g2 * 0.0),
                   t3 = s3 + g2 * d3;
            /* all four finite (inf - inf and NaN give NaN) */
            if ((t0 - t0) + (t1 - t1) + (t2 - t2) + (t3 - t3) == 0) {
                double pm = (t0 + t1 + t2) / 3, a0 = t0 - pm, a1 = t1 - pm, a2 = t2 - pm;
                double dd = a0 * a0 + a1 * a1 + a2 * a2 + 2 * (t3 * t3 + 0.0 + 0.0);
                double r = sqrt(0.5 * dd), xc = pl->xi * pl->c;
                double scale = r + fabs(pl->eta * pm) + xc, f = r + pl->eta * pm - xc;
                if (!(pm > pl->pt + pl->ftol * (fabs(pl->pt) + fabs(pm))) &&
                    f <= pl->ftol * scale) {
                    x0[i] = t0;
                    x1[i] = t1;
                    x2[i] = t2;
                    x3[i] = t3;
                    q0[i] += d0;
                    q1[i] += d1;
                    q3[i] += d3;
                    yld[i] = f > -pl->ftol * scale ? 1.0 : 0.0;
                    continue;
                }
            }
        }
        double sig[6] = {s0, s1, zz, s3, 0, 0}, de[6] = {d0, d1, 0, d3, 0, 0};
        dp_push(b, qp, mp, b0 + i, sig, de);
    }
}

static void frictional_block_2d(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    dp_queue q;
    q.n = 0;
    frictional_2d(b, b0, i0, i1, &q);
    dp_flush(b, &q);
}

/* frictional_block_2d() for a block of one Drucker-Prager material where
 * the job has mpm_sim.plan.dp_lanes: the elastic trials four at a time
 * (mpm_dp_trial2d_lanes(), MPM_DP_TRIAL_LANES_MAX particles to a call), then the particles it
 * leaves, in order, to the queue (the rotation from their unchanged
 * stress, as frictional_2d() pushes them). */
static void frictional_lanes_2d(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    mpm_particles *P = b->P;
    const mpm_mat_params *mp = &b->mats[P->mat[b0 + i0]];
    const mpm_plastic_params *pl = mp->pl;
    const double *const *e = (const double *const *)b->deps;
    dp_queue q;
    q.n = 0;
    for (size_t c0 = i0; c0 < i1; c0 += MPM_DP_TRIAL_LANES_MAX) {
        size_t m = i1 - c0 < MPM_DP_TRIAL_LANES_MAX ? i1 - c0 : MPM_DP_TRIAL_LANES_MAX,
               p0 = b0 + c0;
        const double *ec[4] = {e[0] + c0, e[1] + c0, e[2] + c0, e[3] + c0};
        double *xc[4] = {P->sig[0] + p0, P->sig[1] + p0, P->sig[2] + p0, P->sig[3] + p0};
        double *qc[3] = {P->eps[0] + p0, P->eps[1] + p0, P->eps[3] + p0};
        uint64_t left = mpm_dp_trial2d_lanes(pl, m, ec, xc, qc, P->yld + p0);
        while (left) {
            size_t k = (size_t)__builtin_ctzll(left), j = dp_slot(b, &q, mp, p0 + k);
            left &= left - 1;
            /* written in the slot, a double at a time (a row built on the
             * stack and copied whole would wait on store forwarding) */
            double *sig = q.sig + 6 * j, *de = q.de + 6 * j;
            jaumann_2d(xc[0][k], xc[1][k], xc[3][k], ec[2][k], &sig[0], &sig[1], &sig[3]);
            sig[2] = xc[2][k];
            sig[4] = sig[5] = 0;
            de[0] = ec[0][k];
            de[1] = ec[1][k];
            de[3] = ec[3][k];
            de[2] = de[4] = de[5] = 0;
        }
    }
    dp_flush(b, &q);
}

/* frictional_block() in 3D with the strain record: rate_gather(),
 * mpm_jaumann() and rate_put() on the arrays' pointers taken once (the
 * same operations, so the same bits). */
static void frictional_block_3d(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    mpm_particles *P = b->P;
    const uint16_t *mat = P->mat + b0;
    const double *e[9];
    double *x[6], *q[6];
    for (int c = 0; c < 9; c++) e[c] = b->deps[c];
    for (int c = 0; c < 6; c++) {
        x[c] = P->sig[c] + b0;
        q[c] = P->eps[c] + b0;
    }
    dp_queue dq;
    dq.n = 0;
    for (size_t i = i0; i < i1; i++) {
        const mpm_mat_params *mp = &b->mats[mat[i]];
        double sig[6], de[6], w[3] = {e[6][i], e[7][i], e[8][i]};
        for (int c = 0; c < 6; c++) {
            sig[c] = x[c][i];
            de[c] = e[c][i];
        }
        jaumann_3d(sig, w);
        if (mp->pl->kind == MPM_PLASTIC_DRUCKER_PRAGER) {
            double De[6], tr[6], f;
            int on = 0;
            if (mpm_dp_trial(mp->pl, sig, de, De, tr, &f, &on) == MPM_DP_ELASTIC) {
                for (int c = 0; c < 6; c++) {
                    x[c][i] = tr[c];
                    q[c][i] += de[c];
                }
                P->yld[b0 + i] = on ? 1.0 : 0.0;
                continue;
            }
        }
        dp_push(b, &dq, mp, b0 + i, sig, de);
    }
    dp_flush(b, &dq);
}

/* frictional_block_3d() for a block of one Drucker-Prager material where
 * the job has mpm_sim.plan.dp_lanes, as frictional_lanes_2d() (the trials by
 * mpm_dp_trial3d_lanes()). */
static void frictional_lanes_3d(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    mpm_particles *P = b->P;
    const mpm_mat_params *mp = &b->mats[P->mat[b0 + i0]];
    dp_queue q;
    q.n = 0;
    for (size_t c0 = i0; c0 < i1; c0 += MPM_DP_TRIAL_LANES_MAX) {
        size_t m = i1 - c0 < MPM_DP_TRIAL_LANES_MAX ? i1 - c0 : MPM_DP_TRIAL_LANES_MAX,
               p0 = b0 + c0;
        const double *ec[9];
        double *xc[6], *qc[6];
        for (int c = 0; c < 9; c++) ec[c] = b->deps[c] + c0;
        for (int c = 0; c < 6; c++) {
            xc[c] = P->sig[c] + p0;
            qc[c] = P->eps[c] + p0;
        }
        uint64_t left = mpm_dp_trial3d_lanes(mp->pl, m, ec, xc, qc, P->yld + p0);
        while (left) {
            size_t k = (size_t)__builtin_ctzll(left), j = dp_slot(b, &q, mp, p0 + k);
            left &= left - 1;
            double *sig = q.sig + 6 * j, *de = q.de + 6 * j, w[3] = {ec[6][k], ec[7][k], ec[8][k]};
            for (int c = 0; c < 6; c++) {
                sig[c] = xc[c][k];
                de[c] = ec[c][k];
            }
            jaumann_3d(sig, w);
        }
    }
    dp_flush(b, &q);
}

/* The frictional models' block: frictional_block_2d() or _3d() where they
 * apply (the strain record kept, as the plastic models keep it), their
 * lanes (frictional_lanes_2d(), _3d()) for a block of one Drucker-Prager
 * material where the job has mpm_sim.plan.dp_lanes. */
static void frictional_any(mpm_model_blk *b, size_t b0, size_t i0, size_t i1)
{
    const mpm_particles *P = b->P;
    int rec = 1;
    for (int c = 0; c < MPM_NCOMP(b->dim); c++) rec &= P->sig[c] && (P->eps[c] || c == 2);
    int lanes = !b->general && b->dp_lanes && i1 > i0 &&
                b->mats[P->mat[b0 + i0]].pl->kind == MPM_PLASTIC_DRUCKER_PRAGER &&
                one_material(P->mat + b0 + i0, i1 - i0);
    if (b->general)
        frictional_block(b, b0, i0, i1);
    else if (b->dim == 2 && rec && !P->eps[2])
        (lanes ? frictional_lanes_2d : frictional_block_2d)(b, b0, i0, i1);
    else if (b->dim == 3 && rec && P->eps[2])
        (lanes ? frictional_lanes_3d : frictional_block_3d)(b, b0, i0, i1);
    else
        frictional_block(b, b0, i0, i1);
}

/* The models' operations (their rows: mpm_material_table.c). */
const mpm_model_ops mpm_ops_linear_elastic = {
    {elastic_1d, elastic_2d, elastic_3d}, elastic_block, NULL, elastic_energy};
const mpm_model_ops mpm_ops_neo_hookean = {{NULL, NULL, NULL}, nh_block, NULL, nh_energy};
const mpm_model_ops mpm_ops_von_mises = {{NULL, NULL, NULL}, rate_block, mpm_j2_point, j2_energy};
const mpm_model_ops mpm_ops_drucker_prager = {
    {NULL, NULL, NULL}, frictional_any, frictional_point, j2_energy};
const mpm_model_ops mpm_ops_mohr_coulomb = {
    {NULL, NULL, NULL}, frictional_any, frictional_point, j2_energy};

/* ---- the general block update ---- */

void mpm_model_block(mpm_sim *s, mpm_thread_out *o, size_t b0, size_t nb)
{
    int D = s->dim;
    double *const *deps = o->deps;
    mpm_particles *P = &s->P;
    if (s->f_block) f_block(s, deps, b0, nb, D);
    mpm_model_blk b = {s->mats, P, deps, D, 0.0, 0, 0, 0, SIZE_MAX, 0, s->plan.dp_lanes};
    if (!s->mixed) {
        s->model->block(&b, b0, 0, nb);
    } else { /* runs of particles of one model */
        size_t i = 0;
        while (i < nb) {
            const mpm_model_ops *m = s->mats[P->mat[b0 + i]].ops;
            size_t j = i + 1;
            while (j < nb && s->mats[P->mat[b0 + j]].ops == m) j++;
            m->block(&b, b0, i, j);
            i = j;
        }
    }
    o->wplast += b.wp;
    if (s->frictional) {
        o->plupd += b.nupd;
        o->plsub += b.nsub;
        if (b.maxsub > o->plmax) o->plmax = b.maxsub;
        if (b.bad < o->plbad) o->plbad = b.bad;
    }
    double *restrict vol = P->vol + b0;
    if (s->volmode == MPM_VOLUME_STRAIN_INCREMENT) {
        for (size_t i = 0; i < nb; i++) {
            double tr = deps[0][i];
            if (D == 2) tr += deps[1][i];
            if (D > 2) tr += deps[1][i] + deps[2][i];
            vol[i] *= 1.0 + tr;
        }
    } else if (s->volmode == MPM_VOLUME_DET_F) {
        for (size_t i = 0; i < nb; i++) vol[i] = P->vol0[b0 + i] * mpm_det_f(P, D, b0 + i);
    } /* CONSTANT: never changes */
}

int mpm_model_plastic(const mpm_material_desc *d, int dim, size_t i, mpm_plastic_params *pl,
                      mpm_error *err)
{
    static const mpm_dp_match match[] = {MPM_DP_COMPRESSION, MPM_DP_EXTENSION, MPM_DP_PLANE_STRAIN};
    const double rad = acos(-1.0) / 180.0;
    memset(pl, 0, sizeof *pl);
    pl->kind = d->model == MPM_MODEL_DRUCKER_PRAGER ? MPM_PLASTIC_DRUCKER_PRAGER
                                                    : MPM_PLASTIC_MOHR_COULOMB;
    pl->E = d->youngs_modulus;
    pl->nu = dim == 1 ? 0.0 : d->poisson_ratio;
    pl->phi = d->friction_angle * rad;
    pl->psi = d->dilatancy_angle * rad;
    pl->c = d->cohesion;
    pl->tension = d->tension_cutoff;
    pl->match = (unsigned)d->mc_match < 3 ? match[d->mc_match] : (mpm_dp_match)d->mc_match;
    pl->tol = d->substep_tolerance;
    int rc = mpm_plastic_init(pl, err);
    if (rc) {
        /* its field names are the schema's but for the matching */
        if (err && err->depth == 1 && !strcmp(err->path[0].name, "dp_match"))
            snprintf(err->path[0].name, sizeof err->path[0].name, "mc_match");
        mpm_error_prefix(err, "materials", (long)i);
    }
    return rc;
}

double mpm_material_wave_speed(const mpm_material_desc *m, int dim)
{
    if (dim == 1) return sqrt(m->youngs_modulus / m->density);
    double nu = m->poisson_ratio, E = m->youngs_modulus;
    double M = E * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)); /* lambda + 2 mu */
    return sqrt(M / m->density);
}
