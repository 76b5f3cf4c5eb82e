/*
 * mpm_plastic_avx2.c - Drucker-Prager's plastic updates four particles at
 * a time (mpm_dp_lanes(), mpm_plastic.h).  Sloan's substepping is a long
 * chain of dependent square roots and divisions per particle, so one
 * particle leaves the CPU waiting; here each lane of an AVX2 vector carries
 * its own particle through the same operations, in the same order, as
 * mpm_plastic.c's scalar update (no fused multiply-adds: this file is
 * built with -mavx2 -ffp-contract=off), so each particle's result has the
 * scalar bits.  A lane that finishes takes the next particle (the Pegasus
 * search and the substeps are loops of different lengths per particle).
 * The trial past the tension cut-off takes its closed form here too
 * (after the Pegasus search for its first yield point).  The rarer paths
 * (an unloading start, the normal drift correction, a divergence, a
 * cut-off met after the substeps) are not here: such a particle is
 * reported not done, its inputs untouched, for mpm_plastic_update().
 * The passes are built twice (dp_lanes6(), dp_lanes4()): for rows of six
 * components, and for rows whose yz and xz are zero (1D, 2D plane
 * strain), which stay zero through every pass and are left out; the two
 * zero terms they add to a sum change it only where it is a zero, from
 * -0 to +0, and nothing downstream tells those apart (vddot()).
 * Built only on x86-64 (MPM_HAVE_AVX2_KERNELS) and called only where the
 * CPU has AVX2.
 */
#include "mpm_plastic_avx2.h"
#include "mpm_plastic_tol.h"

#if defined(MPM_HAVE_AVX2_KERNELS) && defined(__AVX2__)
#include <assert.h>
#include <immintrin.h>
#include <string.h>

/* A vector of NL lanes: NH AVX2 vectors side by side, so that each
 * operation below is NH independent instructions (two chains of square
 * roots and divisions in flight, not one). */
#define NH 1
#define NL (4 * NH)
#define ALL ((1 << NL) - 1)
typedef struct {
    __m256d h[NH];
} V;
/* every helper inlined: a V passed to a call would go through memory */
#define VI static inline __attribute__((always_inline))

#define LANEWISE2(name, intr)                                       \
    VI V name(V a, V b)                                             \
    {                                                               \
        V r;                                                        \
        for (int i = 0; i < NH; i++) r.h[i] = intr(a.h[i], b.h[i]); \
        return r;                                                   \
    }
LANEWISE2(add, _mm256_add_pd)
LANEWISE2(sub, _mm256_sub_pd)
LANEWISE2(mul, _mm256_mul_pd)
LANEWISE2(dvd, _mm256_div_pd)
LANEWISE2(vand, _mm256_and_pd)
LANEWISE2(vor, _mm256_or_pd)

VI V vsqrt(V a)
{
    V r;
    for (int i = 0; i < NH; i++) r.h[i] = _mm256_sqrt_pd(a.h[i]);
    return r;
}
VI V k1(double x)
{
    V r;
    for (int i = 0; i < NH; i++) r.h[i] = _mm256_set1_pd(x);
    return r;
}
VI V vabs(V a)
{
    V r;
    for (int i = 0; i < NH; i++) r.h[i] = _mm256_andnot_pd(_mm256_set1_pd(-0.0), a.h[i]);
    return r;
}
/* m ? a : b, lane by lane (m: a comparison's all-ones lanes) */
VI V sel(V m, V a, V b)
{
    V r;
    for (int i = 0; i < NH; i++) r.h[i] = _mm256_blendv_pd(b.h[i], a.h[i], m.h[i]);
    return r;
}
#define COMPARE(name, pred)                                                        \
    VI V name(V a, V b)                                                            \
    {                                                                              \
        V r;                                                                       \
        for (int i = 0; i < NH; i++) r.h[i] = _mm256_cmp_pd(a.h[i], b.h[i], pred); \
        return r;                                                                  \
    }
COMPARE(gt, _CMP_GT_OQ)
COMPARE(lt, _CMP_LT_OQ)
COMPARE(le, _CMP_LE_OQ)
COMPARE(ge, _CMP_GE_OQ)
COMPARE(eq, _CMP_EQ_OQ)
VI V vnot(V a)
{
    V r;
    for (int i = 0; i < NH; i++)
        r.h[i] = _mm256_xor_pd(a.h[i], _mm256_castsi256_pd(_mm256_set1_epi64x(-1)));
    return r;
}
/* lane j = r[j][c]: built in registers from the rows r (a vector stored
 * a double at a time and loaded whole would wait on store forwarding) */
VI V vrows(const double *const r[NL], int c)
{
    V v;
    for (int i = 0; i < NH; i++)
        v.h[i] = _mm256_set_pd(r[4 * i + 3][c], r[4 * i + 2][c], r[4 * i + 1][c], r[4 * i][c]);
    return v;
}

/* the lanes' mask bits, lane j at bit j */
VI int bits(V m)
{
    int b = 0;
    for (int i = 0; i < NH; i++) b |= _mm256_movemask_pd(m.h[i]) << (4 * i);
    return b;
}

/* The material's constants as vectors (each the scalar code's product, in
 * its order). */
typedef struct {
    V lam, g2, G, K, eta, etag, xc, ftol, nftol, pt, half, two, three, zero, one;
    V keta;  /* K eta (dp_aDe()) */
    V kee;   /* K eta etag (dp_aDb()) */
    V ketag; /* K etag (dp_Db()) */
    V eq1;   /* 1 / sqrt3 (dp_eq()) */
    V stol;
    V fytol; /* first_yield()'s tolerance, max(ftol, FY_TOL) */
    V rt;    /* the cone's radius at the cut-off, xi c - eta pt, at least 0 (dp_tension()) */
    V kk;    /* 3 K (compliance()) */
    V twothirds;
    int pt_finite; /* the cut-off is a surface of its own (yield_any()) */
} kc;

static void k_init(kc *k, const mpm_plastic_params *P)
{
    k->lam = k1(P->lam);
    k->g2 = k1(2 * P->G);
    k->G = k1(P->G);
    k->K = k1(P->K);
    k->eta = k1(P->eta);
    k->etag = k1(P->etag);
    k->xc = k1(P->xi * P->c);
    k->ftol = k1(P->ftol);
    k->nftol = k1(-P->ftol);
    k->pt = k1(P->pt);
    k->half = k1(0.5);
    k->two = k1(2);
    k->three = k1(3);
    k->zero = k1(0);
    k->one = k1(1);
    k->keta = k1(P->K * P->eta);
    k->kee = k1(P->K * P->eta * P->etag);
    k->ketag = k1(P->K * P->etag);
    k->eq1 = k1(1 / SQRT3);
    k->stol = k1(P->tol);
    k->fytol = k1(P->ftol > FY_TOL ? P->ftol : FY_TOL);
    double rt = P->xi * P->c - P->eta * P->pt;
    k->rt = k1(rt < 0 ? 0 : rt);
    k->kk = k1(3 * P->K);
    k->twothirds = k1(2.0 / 3.0);
    k->pt_finite = isfinite(P->pt) != 0;
}

/* a : b (ddot()).  With nc = 4 (rows whose components 4 and 5 are
 * zero: 1D, 2D) the two zero products are left out: they change the sum
 * only where it is a zero, from -0 to +0, and no caller tells those apart
 * (the multiplier's num > 0 and the unloading's cos < -LTOL; the rest are
 * sums of squares, and the cut-off's dissipation adds its terms to +0). */
VI V vddot(const V a[6], const V b[6], const int nc)
{
    V n = add(add(mul(a[0], b[0]), mul(a[1], b[1])), mul(a[2], b[2]));
    V s = mul(a[3], b[3]);
    if (nc == 6) s = add(add(s, mul(a[4], b[4])), mul(a[5], b[5]));
    return add(n, mul(k1(2), s));
}

/* dp_inv, a lane each */
typedef struct {
    V p, r, inv, d[6];
} vinv;

/* meanp() */
VI V vmeanp(const kc *k, const V s[6])
{
    return dvd(add(add(s[0], s[1]), s[2]), k->three);
}

/* sqrt_j2_p() (nc = 4: the zero components' squares, +0, left out of a
 * sum that starts with a square) */
VI V vj2(const kc *k, const V s[6], V p, V d[6], const int nc)
{
    d[0] = sub(s[0], p);
    d[1] = sub(s[1], p);
    d[2] = sub(s[2], p);
    for (int c = 3; c < nc; c++) d[c] = s[c];
    V n = add(add(mul(d[0], d[0]), mul(d[1], d[1])), mul(d[2], d[2]));
    V sh = mul(d[3], d[3]);
    if (nc == 6) sh = add(add(sh, mul(d[4], d[4])), mul(d[5], d[5]));
    return vsqrt(mul(k->half, add(n, mul(k->two, sh))));
}

/* dp_invariants() */
VI void vinvariants(const kc *k, const V s[6], vinv *v, const int nc)
{
    V p = vmeanp(k, s);
    V r = vj2(k, s, p, v->d, nc);
    V scale = add(add(r, vabs(mul(k->eta, p))), k->xc);
    V on = vand(gt(r, mul(k1(TINY_REL), scale)), gt(r, k->zero));
    v->p = p;
    v->r = r;
    v->inv = sel(on, dvd(k->one, mul(k->two, r)), k->zero);
}

/* dp_f_inv() and its scale */
VI V vf_inv(const kc *k, const vinv *v, V *scale)
{
    V ep = mul(k->eta, v->p);
    *scale = add(add(v->r, vabs(ep)), k->xc);
    return sub(add(v->r, ep), k->xc);
}

/* dp_f() at s, and with cut (yield_fast()) where the cut-off is finite
 * the larger of it and p - pt (the larger scale too) */
VI V vf(const kc *k, const V s[6], int cut, V *scale, const int nc)
{
    V d[6], p = vmeanp(k, s), r = vj2(k, s, p, d, nc), ep = mul(k->eta, p);
    V sc = add(add(r, vabs(ep)), k->xc), f = sub(add(r, ep), k->xc);
    if (cut && k->pt_finite) {
        V ft = sub(p, k->pt), sct = add(vabs(p), vabs(k->pt));
        f = sel(gt(ft, f), ft, f);
        sc = sel(gt(sct, sc), sct, sc);
    }
    *scale = sc;
    return f;
}

/* vf() at s + al De (dp_f_at()) */
VI V vf_at(const kc *k, const V s[6], const V De[6], V al, int cut, V *scale, const int nc)
{
    V x[6];
    for (int c = 0; c < nc; c++) x[c] = add(s[c], mul(al, De[c]));
    return vf(k, x, cut, scale, nc);
}

/* fmax(0, x) as glibc's x86-64 fmax() gives it for a number: 0 > x ? 0 : x
 * (so -0 stays -0) */
VI V vmax0(V x)
{
    V r;
    for (int i = 0; i < NH; i++) r.h[i] = _mm256_max_pd(_mm256_setzero_pd(), x.h[i]);
    return r;
}

/* dp_aDe() */
VI V vaDe(const kc *k, const vinv *v, const V de[6], const int nc)
{
    V a = mul(mul(k->g2, v->inv), vddot(v->d, de, nc));
    return add(a, mul(k->keta, add(add(de[0], de[1]), de[2])));
}

/* dp_aDb() */
VI V vaDb(const kc *k, const vinv *v)
{
    return add(sel(gt(v->inv, k->zero), k->G, k->zero), k->kee);
}

/* dp_Db() */
VI void vDb(const kc *k, const vinv *v, V Db[6], const int nc)
{
    V g = mul(k->g2, v->inv);
    for (int c = 0; c < 3; c++) Db[c] = add(mul(g, v->d[c]), k->ketag);
    for (int c = 3; c < nc; c++) Db[c] = add(mul(g, v->d[c]), k->zero);
}

/* dp_eq() */
VI V veq(const kc *k, const vinv *v)
{
    return sel(gt(v->inv, k->zero), k->eq1, k->zero);
}

/* dp_sb() */
VI V vsb(const kc *k, const vinv *v)
{
    V x = add(v->r, mul(k->etag, v->p));
    return sel(gt(x, k->zero), x, k->zero);
}

/* dp_euler() */
VI V veuler(const kc *k, const vinv *v, const V de[6], const V De[6], V ds[6], const int nc)
{
    V num = vaDe(k, v, de, nc), den = vaDb(k, v);
    V dl = sel(vand(gt(num, k->zero), gt(den, k->zero)), dvd(num, den), k->zero);
    V Db[6];
    vDb(k, v, Db, nc);
    for (int c = 0; c < nc; c++) ds[c] = sub(De[c], mul(dl, Db[c]));
    return dl;
}

/* hooke() */
VI void vhooke(const kc *k, const V e[6], V s[6], const int nc)
{
    V lt_ = mul(k->lam, add(add(e[0], e[1]), e[2]));
    for (int c = 0; c < 3; c++) s[c] = add(lt_, mul(k->g2, e[c]));
    for (int c = 3; c < nc; c++) s[c] = mul(k->g2, e[c]);
}

/* mpm_dp_trial()'s first test, a lane each: from the stress s and the
 * increment e, De = D e, the trial tr = s + De, f(tr) and its scale, and
 * the masks of the finite trials, of those past the cut-off and of those
 * within the cone (f <= ftol scale).  The queue's first pass and the
 * blocks' elastic trials (mpm_dp_trial2d_lanes(), _3d()) both take it. */
typedef struct {
    V f, scale, finite, tens, adm;
} vtr;

VI void vtrial(const kc *k, const V s[6], const V e[6], V De[6], V tr[6], vtr *t, const int nc)
{
    V etr = add(add(e[0], e[1]), e[2]);
    for (int c = 0; c < 3; c++) De[c] = add(mul(k->lam, etr), mul(k->g2, e[c]));
    for (int c = 3; c < nc; c++) De[c] = mul(k->g2, e[c]);
    V fin = k->zero;
    for (int c = 0; c < nc; c++) {
        tr[c] = add(s[c], De[c]);
        fin = add(fin, sub(tr[c], tr[c])); /* NaN unless all are finite */
    }
    V p = vmeanp(k, tr), d[3];
    for (int c = 0; c < 3; c++) d[c] = sub(tr[c], p);
    V sh = mul(tr[3], tr[3]);
    if (nc == 6) sh = add(add(sh, mul(tr[4], tr[4])), mul(tr[5], tr[5]));
    V dd = add(add(add(mul(d[0], d[0]), mul(d[1], d[1])), mul(d[2], d[2])), mul(k->two, sh));
    V r = vsqrt(mul(k->half, dd));
    V ep = mul(k->eta, p);
    t->scale = add(add(r, vabs(ep)), k->xc);
    t->f = sub(add(r, ep), k->xc);
    t->finite = eq(fin, k->zero);
    t->tens = gt(p, add(k->pt, mul(k->ftol, add(vabs(k->pt), vabs(p)))));
    t->adm = le(t->f, mul(k->ftol, t->scale));
}

/* ---- per-particle staging between the three passes ---- */

/* what a particle takes: ST_OUT the scalar update; ST_INSIDE the Pegasus
 * search from inside the cone, then the substeps; ST_SURFACE the substeps
 * from the surface; ST_TENSION the cut-off's closed form after the first
 * yield point's search (first_yield()); ST_TENSION0 that form with the
 * start as the first yield point */
enum { ST_OUT = 0, ST_INSIDE = 1, ST_SURFACE = 2, ST_TENSION = 3, ST_TENSION0 = 4 };

typedef struct {
    double De[MPM_DP_LANES_MAX][6];
    double f0[MPM_DP_LANES_MAX], ftr[MPM_DP_LANES_MAX], al[MPM_DP_LANES_MAX];
    unsigned char kind[MPM_DP_LANES_MAX];
} stage;

/* lanes of a vector in memory */
typedef union {
    V v;
    double x[NL];
} lanes;

/* Pass 1, four particles at a time: the trial (mpm_dp_trial()), the
 * invariants of the start and f there, and the unloading check of a start
 * on the surface.  Particles that leave the cone's common path are marked
 * ST_OUT. */
VI void pass_trial(const kc *k, const int nc, size_t n, const double *sig, const double *de,
                   stage *g)
{
    for (size_t i0 = 0; i0 < n; i0 += NL) {
        size_t m = n - i0 < NL ? n - i0 : NL;
        const double *rs[NL], *re[NL];
        for (size_t j = 0; j < NL; j++) {
            size_t i = i0 + (j < m ? j : 0);
            rs[j] = sig + 6 * i;
            re[j] = de + 6 * i;
        }
        V S[6], E[6], De[6], tr[6];
        for (int c = 0; c < nc; c++) {
            S[c] = vrows(rs, c);
            E[c] = vrows(re, c);
        }
        /* De and the trial, as mpm_dp_trial() */
        vtr t;
        vtrial(k, S, E, De, tr, &t, nc);
        V finite = t.finite, tens = t.tens, f = t.f;
        V cone = vand(vand(finite, vnot(tens)), vnot(t.adm));
        /* the start's invariants and f (dp_update()) */
        vinv v;
        vinvariants(k, S, &v, nc);
        V sc0, f0 = vf_inv(k, &v, &sc0);
        V inside = lt(f0, mul(k->nftol, sc0));
        /* a start on the surface: does the increment first unload? */
        V na = vsqrt(
            add(mul(mul(v.inv, v.inv), vddot(v.d, v.d, nc)), dvd(mul(k->eta, k->eta), k->three)));
        V nd = vsqrt(vddot(De, De, nc));
        V cth = dvd(vaDe(k, &v, E, nc), mul(na, nd));
        V unload = vand(vand(gt(na, k->zero), gt(nd, k->zero)), lt(cth, k1(-LTOL)));
        int mc = bits(cone), mi = bits(inside), mu = bits(unload);
        /* past the cut-off: first_yield()'s first tests */
        V tfin = vand(finite, tens);
        int mt = bits(tfin), mt0 = 0;
        lanes FY0, FY1;
        FY0.v = FY1.v = k->zero;
        if (mt) {
            V sct0, sct1, fy0 = vf(k, S, 1, &sct0, nc), fy1 = vf(k, tr, 1, &sct1, nc);
            /* f0 >= -tol sc, or !(f1 > 0): the start is the first yield point */
            mt0 = bits(vor(ge(fy0, mul(sub(k->zero, k->fytol), sct0)), vnot(gt(fy1, k->zero))));
            FY0.v = fy0;
            FY1.v = fy1;
        }
        lanes D[6], F0, FT;
        for (int c = 0; c < nc; c++) D[c].v = De[c];
        F0.v = f0;
        FT.v = f;
        for (size_t j = 0; j < m; j++) {
            size_t i = i0 + j;
            for (int c = 0; c < nc; c++) g->De[i][c] = D[c].x[j];
            g->f0[i] = F0.x[j];
            g->ftr[i] = FT.x[j];
            g->al[i] = 0;
            if (mt >> j & 1) {
                g->kind[i] = (mt0 >> j & 1) ? ST_TENSION0 : ST_TENSION;
                g->f0[i] = FY0.x[j];
                g->ftr[i] = FY1.x[j];
            } else if (!(mc >> j & 1))
                g->kind[i] = ST_OUT;
            else if (mi >> j & 1)
                g->kind[i] = ST_INSIDE;
            else
                g->kind[i] = (mu >> j & 1) ? ST_OUT : ST_SURFACE;
        }
    }
}

/* Lane j's mask (all ones in lane j), for the lane masks lm[NL]. */
static void lane_masks(V lm[NL])
{
    for (int j = 0; j < NL; j++) {
        lanes u;
        for (int l = 0; l < NL; l++) u.x[l] = l == j ? -1.0 : 1.0;
        lm[j] = lt(u.v, k1(0)); /* all ones where -1 */
    }
}

/* x with lane j set to val (a blend in registers: a lane written through
 * memory would stall the next load of the whole vector) */
VI V put(V x, int j, double val, const V lm[NL])
{
    return sel(lm[j], k1(val), x);
}

/* lane j of x */
VI double get(V x, int j)
{
    lanes u;
    u.v = x;
    return u.x[j];
}

/* the mask of the lanes whose bits b has */
VI V mask_of(int b, const V lm[NL])
{
    V m = lt(k1(1), k1(0));
    for (int j = 0; j < NL; j++)
        if (b >> j & 1) m = vor(m, lm[j]);
    return m;
}

/* Pass 2: the elastic fraction of each start inside the cone, by the
 * Pegasus method on [0, 1] (pegasus() with dp_f(); kind ST_INSIDE), or the first
 * yield point on a trial past the cut-off (first_yield(); kind
 * ST_TENSION: yield_fast() and its tolerance), a lane per particle, a
 * lane that finishes taking the next. */
VI void pass_pegasus(const kc *k, const int nc, size_t n, const double *sig, stage *g, int kind)
{
    const V tol = kind == ST_TENSION ? k->fytol : k->ftol;
    V lm[NL], S[6], D[6], a0, a1, f0, f1, al;
    int who[NL], it[NL];
    size_t next = 0;
    lane_masks(lm);
    for (int j = 0; j < NL; j++) who[j] = it[j] = -1;
    for (int c = 0; c < nc; c++) S[c] = D[c] = k->zero;
    a0 = a1 = f0 = f1 = al = k->zero;
    for (;;) {
        int live = 0;
        for (int j = 0; j < NL; j++) {
            while (who[j] < 0 && next < n) {
                size_t i = next++;
                if (g->kind[i] != kind) continue;
                who[j] = (int)i;
                it[j] = 0;
                for (int c = 0; c < nc; c++) {
                    S[c] = put(S[c], j, sig[6 * i + c], lm);
                    D[c] = put(D[c], j, g->De[i][c], lm);
                }
                a0 = put(a0, j, 0, lm);
                a1 = put(a1, j, 1, lm);
                al = put(al, j, 1, lm);
                f0 = put(f0, j, g->f0[i], lm);
                f1 = put(f1, j, g->ftr[i], lm);
            }
            live |= (who[j] >= 0) << j;
        }
        if (!live) return;
        /* one iteration in every lane; a lane that stops keeps al */
        V stop = eq(f1, f0);
        V aln = sub(a1, dvd(mul(f1, sub(a1, a0)), sub(f1, f0)));
        V sc, fn = vf_at(k, S, D, aln, kind == ST_TENSION, &sc, nc);
        V conv = le(vabs(fn), mul(tol, sc));
        V flip = lt(mul(fn, f1), k->zero);
        al = sel(stop, al, aln);
        V go = vnot(vor(stop, conv));
        a0 = sel(vand(go, flip), a1, a0);
        f0 = sel(go, sel(flip, f1, dvd(mul(f0, f1), add(f1, fn))), f0);
        a1 = sel(go, aln, a1);
        f1 = sel(go, fn, f1);
        int done = ~bits(go);
        for (int j = 0; j < NL; j++) {
            if (who[j] < 0) continue;
            if ((done >> j & 1) || ++it[j] >= PEG_MAXIT) {
                g->al[who[j]] = get(al, j);
                who[j] = -1;
            }
        }
    }
}

/* Pass 3: Sloan's modified Euler substeps with error control and drift
 * correction (dp_substep(), dp_drift()), a lane per particle, from the
 * stress s on the surface with invariants v over the strain rest.  Writes
 * the results of the particles that stay on the common path. */
VI void pass_substeps(const kc *k, const int nc, const mpm_plastic_params *P, size_t n, double *sig,
                      const double *de, stage *g, double *epq, double *dis, int *nsub,
                      unsigned char *ok)
{
    V lm[NL], s[6], rest[6], src[6], T, dT, fail, dsum, eqp;
    vinv v;
    int nn[NL], acc[NL], who[NL];
    /* the particles this pass takes, in order (no branch per particle) */
    size_t idx[MPM_DP_LANES_MAX], nt = 0, next = 0;
    for (size_t i = 0; i < n; i++) {
        idx[nt] = i;
        nt += g->kind[i] == ST_INSIDE || g->kind[i] == ST_SURFACE;
    }
    lane_masks(lm);
    for (int c = 0; c < nc; c++) s[c] = rest[c] = src[c] = v.d[c] = k->zero;
    v.p = v.r = v.inv = T = dT = fail = dsum = eqp = k->zero;
    for (int j = 0; j < NL; j++) who[j] = nn[j] = acc[j] = -1;
    /* live: the lanes that carry a particle (bit j: lane j); the lanes'
     * bookkeeping walks mask bits, not a test per lane */
    int live = 0;
    for (;;) {
        int fresh = 0;
        for (int idle = ~live & ALL; idle && next < nt; idle &= idle - 1) {
            int j = __builtin_ctz((unsigned)idle);
            size_t i = idx[next++];
            who[j] = (int)i;
            fresh |= 1 << j;
            double al = g->al[i];
            for (int c = 0; c < nc; c++) {
                double sc = sig[6 * i + c] + al * g->De[i][c];
                s[c] = put(s[c], j, sc, lm);
                rest[c] = put(rest[c], j, (1 - al) * de[6 * i + c], lm);
                /* the invariants of s, or of sig when al is 0 (the
                 * scalar update keeps those) */
                src[c] = put(src[c], j, al != 0 ? sc : sig[6 * i + c], lm);
            }
            nn[j] = 0;
            acc[j] = 0;
        }
        live |= fresh;
        if (!live) return;
        if (fresh) {
            V m = mask_of(fresh, lm);
            vinv vr;
            vinvariants(k, src, &vr, nc);
            v.p = sel(m, vr.p, v.p);
            v.r = sel(m, vr.r, v.r);
            v.inv = sel(m, vr.inv, v.inv);
            for (int c = 0; c < nc; c++) v.d[c] = sel(m, vr.d[c], v.d[c]);
            T = sel(m, k->zero, T);
            dT = sel(m, k->one, dT);
            fail = sel(m, k->zero, fail);
            dsum = sel(m, k->zero, dsum);
            eqp = sel(m, k->zero, eqp);
        }
        /* n++ >= max_substeps: left to the scalar update (its implicit return) */
        int quit = 0;
        for (int j = 0; j < NL; j++) quit |= (nn[j]++ >= P->max_substeps) << j;
        quit &= live;
        V e[6], De[6], ds1[6], ds2[6], s1[6], sn[6], diff[6];
        vinv v1;
        for (int c = 0; c < nc; c++) e[c] = mul(dT, rest[c]);
        vhooke(k, e, De, nc);
        V dl1 = veuler(k, &v, e, De, ds1, nc);
        for (int c = 0; c < nc; c++) s1[c] = add(s[c], ds1[c]);
        vinvariants(k, s1, &v1, nc);
        V dl2 = veuler(k, &v1, e, De, ds2, nc);
        V fin = k->zero;
        for (int c = 0; c < nc; c++) {
            sn[c] = add(s[c], mul(k->half, add(ds1[c], ds2[c])));
            diff[c] = sub(ds2[c], ds1[c]);
            fin = add(fin, sub(sn[c], sn[c]));
        }
        V ref = vsqrt(vddot(sn, sn, nc));
        ref = sel(lt(ref, k->xc), k->xc, ref);
        V R = sel(gt(ref, k->zero), dvd(vsqrt(vddot(diff, diff, nc)), mul(k->two, ref)), k->zero);
        R = sel(lt(R, k1(R_MIN)), k1(R_MIN), R);
        quit |= ~bits(eq(fin, k->zero)) & ALL;
        V q0 = mul(k1(0.9), vsqrt(dvd(k->stol, R)));
        V reject = vand(gt(R, k->stol), gt(dT, k1(DT_MIN)));
        /* a rejected attempt: a smaller dT */
        V qr = sel(lt(q0, k1(0.1)), k1(0.1), q0);
        V dtr = sel(gt(mul(qr, dT), k1(DT_MIN)), mul(qr, dT), k1(DT_MIN));
        /* an accepted one */
        V sb0 = vsb(k, &v);
        V eqa = add(eqp, mul(k->half, add(mul(dl1, veq(k, &v)), mul(dl2, veq(k, &v1)))));
        vinv va;
        vinvariants(k, sn, &va, nc);
        V sa[6];
        for (int c = 0; c < nc; c++) sa[c] = sn[c];
        V disa = dsum;
        /* the drift correction, lanes that still drift */
        int bad = 0;
        V drifting = eq(k->one, k->one); /* every lane, until its f is admissible */
        for (int itd = 0; itd < DRIFT_MAXIT; itd++) {
            V sc, f = vf_inv(k, &va, &sc);
            drifting = vand(drifting, vnot(le(f, mul(k->ftol, sc))));
            if (!(bits(drifting) & ~bits(reject) & live & ~quit)) break;
            V den = vaDb(k, &va), Db[6], y[6];
            vDb(k, &va, Db, nc);
            V fd = dvd(f, den);
            for (int c = 0; c < nc; c++) y[c] = sub(sa[c], mul(fd, Db[c]));
            vinv vy;
            vinvariants(k, y, &vy, nc);
            V scy, fy = vf_inv(k, &vy, &scy);
            V consistent = vand(gt(den, k->zero), le(vabs(fy), vabs(f)));
            bad |= bits(vand(drifting, vnot(consistent)));
            drifting = vand(drifting, consistent);
            disa = sel(drifting, add(disa, mul(fd, vsb(k, &vy))), disa);
            eqa = sel(drifting, add(eqa, mul(fd, veq(k, &va))), eqa);
            for (int c = 0; c < nc; c++) sa[c] = sel(drifting, y[c], sa[c]);
            va.p = sel(drifting, vy.p, va.p);
            va.r = sel(drifting, vy.r, va.r);
            va.inv = sel(drifting, vy.inv, va.inv);
            for (int c = 0; c < nc; c++) va.d[c] = sel(drifting, vy.d[c], va.d[c]);
        }
        disa = add(disa, mul(k->half, add(mul(dl1, sb0), mul(dl2, vsb(k, &va)))));
        V qa = sel(gt(q0, k1(1.1)), k1(1.1), q0);
        qa = sel(lt(qa, k1(0.1)), k1(0.1), qa);
        qa = sel(vand(gt(fail, k->zero), gt(qa, k->one)), k->one, qa);
        V Ta = add(T, dT);
        V fin_a = ge(Ta, k1(1 - 1e-14));
        V dta = sel(gt(mul(qa, dT), k1(DT_MIN)), mul(qa, dT), k1(DT_MIN));
        V left = sub(k->one, Ta);
        dta = sel(gt(dta, left), left, dta);
        /* commit: rejected lanes take dtr and fail = 1, accepted ones the rest */
        V ac = vnot(reject);
        for (int c = 0; c < nc; c++) s[c] = sel(ac, sa[c], s[c]);
        v.p = sel(ac, va.p, v.p);
        v.r = sel(ac, va.r, v.r);
        v.inv = sel(ac, va.inv, v.inv);
        for (int c = 0; c < nc; c++) v.d[c] = sel(ac, va.d[c], v.d[c]);
        T = sel(ac, Ta, T);
        dT = sel(ac, dta, dtr);
        fail = sel(ac, k->zero, k->one);
        dsum = sel(ac, disa, dsum);
        eqp = sel(ac, eqa, eqp);
        int ma = bits(ac), mf = bits(fin_a), mt = bits(gt(va.p, k->pt));
        /* quit, or bad and accepted: left to the scalar update */
        int gone = (quit | (bad & ma)) & live, took = ma & live & ~gone;
        for (int j = 0; j < NL; j++) acc[j] += took >> j & 1;
        for (int b = gone; b; b &= b - 1) ok[who[__builtin_ctz((unsigned)b)]] = 0;
        /* done: a stress past the cut-off is left to the scalar update */
        int done = took & mf;
        for (int b = done; b; b &= b - 1) {
            int j = __builtin_ctz((unsigned)b);
            size_t i = (size_t)who[j];
            if (mt >> j & 1) {
                ok[i] = 0;
                continue;
            }
            for (int c = 0; c < nc; c++) sig[6 * i + c] = get(s[c], j);
            epq[i] = get(eqp, j);
            dis[i] = get(dsum, j);
            nsub[i] = acc[j];
            ok[i] = 1;
        }
        live &= ~(gone | done);
    }
}

/* Pass 4: the cut-off's closed form (dp_tension(), dp_update()) of the
 * particles whose trial is past it, four at a time: the trial's deviator
 * kept, scaled to the cone's radius at the cut-off when outside it, p =
 * pt; the plastic strain by the compliance, its dissipation by the
 * trapezoidal rule from the first yield point sa. */
VI void pass_tension(const kc *k, const int nc, size_t n, double *sig, const stage *g, double *epq,
                     double *dis, int *nsub, unsigned char *ok)
{
    size_t idx[MPM_DP_LANES_MAX], m = 0;
    for (size_t i = 0; i < n; i++)
        if (g->kind[i] == ST_TENSION || g->kind[i] == ST_TENSION0) idx[m++] = i;
    for (size_t q0 = 0; q0 < m; q0 += NL) {
        size_t mq = m - q0 < NL ? m - q0 : NL;
        const double *rs[NL], *rd[NL], *ra[NL];
        double same[NL];
        for (size_t j = 0; j < NL; j++) {
            size_t i = idx[q0 + (j < mq ? j : 0)];
            rs[j] = sig + 6 * i;
            rd[j] = g->De[i];
            ra[j] = &g->al[i];
            same[j] = g->kind[i] == ST_TENSION0 ? 1.0 : 0.0;
        }
        const double *rm[NL];
        for (size_t j = 0; j < NL; j++) rm[j] = &same[j];
        V S[6], D[6], sa[6], tr[6], d[6], y[6], dd[6], ep[6], e2[6];
        V keep = gt(vrows(rm, 0), k->zero), al = vrows(ra, 0);
        for (int c = 0; c < nc; c++) {
            S[c] = vrows(rs, c);
            D[c] = vrows(rd, c);
            sa[c] = sel(keep, S[c], add(S[c], mul(al, D[c])));
            tr[c] = add(S[c], D[c]);
        }
        V p = vmeanp(k, tr), r = vj2(k, tr, p, d, nc);
        V beta = sel(gt(r, k->rt), dvd(k->rt, r), k->one);
        for (int c = 0; c < nc; c++) y[c] = add(mul(beta, d[c]), c < 3 ? k->pt : k->zero);
        for (int c = 0; c < nc; c++) dd[c] = sub(tr[c], y[c]);
        /* compliance() */
        V pd = vmeanp(k, dd), pk = dvd(pd, k->kk);
        for (int c = 0; c < 3; c++) ep[c] = add(dvd(sub(dd[c], pd), k->g2), pk);
        for (int c = 3; c < nc; c++) ep[c] = dvd(dd[c], k->g2);
        /* trap_dis(), eqv_dev(), each added to 0 as dp_update() adds them */
        V ds = vddot(sa, ep, nc), dy = vddot(y, ep, nc);
        V me = vmeanp(k, ep);
        for (int c = 0; c < nc; c++) e2[c] = sub(ep[c], c < 3 ? me : k->zero);
        V dsum = add(k->zero, mul(k->half, add(vmax0(ds), vmax0(dy))));
        V esum = add(k->zero, vsqrt(mul(k->twothirds, vddot(e2, e2, nc))));
        for (size_t j = 0; j < mq; j++) {
            size_t i = idx[q0 + j];
            for (int c = 0; c < nc; c++) sig[6 * i + c] = get(y[c], (int)j);
            epq[i] = get(esum, (int)j);
            dis[i] = get(dsum, (int)j);
            nsub[i] = 1;
            ok[i] = 1;
        }
    }
}

/* the four passes on rows of nc components */
VI void dp_lanes(const mpm_plastic_params *P, const int nc, size_t n, double *sig, const double *de,
                 double *epq, double *dis, int *nsub, unsigned char *ok)
{
    kc k;
    stage g;
    k_init(&k, P);
    pass_trial(&k, nc, n, sig, de, &g);
    for (size_t i = 0; i < n; i++) ok[i] = 0;
    pass_pegasus(&k, nc, n, sig, &g, ST_INSIDE);
    pass_pegasus(&k, nc, n, sig, &g, ST_TENSION);
    pass_substeps(&k, nc, P, n, sig, de, &g, epq, dis, nsub, ok);
    pass_tension(&k, nc, n, sig, &g, epq, dis, nsub, ok);
}

/* dp_lanes() built for each row width */
static void dp_lanes6(const mpm_plastic_params *P, size_t n, double *sig, const double *de,
                      double *epq, double *dis, int *nsub, unsigned char *ok)
{
    dp_lanes(P, 6, n, sig, de, epq, dis, nsub, ok);
}

static void dp_lanes4(const mpm_plastic_params *P, size_t n, double *sig, const double *de,
                      double *epq, double *dis, int *nsub, unsigned char *ok)
{
    dp_lanes(P, 4, n, sig, de, epq, dis, nsub, ok);
}

void mpm_dp_lanes(const mpm_plastic_params *P, int nc, size_t n, double *sig, const double *de,
                  double *epq, double *dis, int *nsub, unsigned char *ok)
{
    assert(nc == 4 || nc == 6);
    (nc == 4 ? dp_lanes4 : dp_lanes6)(P, n, sig, de, epq, dis, nsub, ok);
}

/* n (1..NL) lanes of p: whole loads, or masked ones past the end */
VI V vld(const double *p, size_t n)
{
    V v;
    for (int i = 0; i < NH; i++) {
        long long r = (long long)n - 4 * i;
        __m256i m = _mm256_cmpgt_epi64(_mm256_set1_epi64x(r), _mm256_set_epi64x(3, 2, 1, 0));
        v.h[i] = r >= 4 ? _mm256_loadu_pd(p + 4 * i) : _mm256_maskload_pd(p + 4 * i, m);
    }
    return v;
}

VI void vst(double *p, size_t n, V v)
{
    for (int i = 0; i < NH; i++) {
        long long r = (long long)n - 4 * i;
        __m256i m = _mm256_cmpgt_epi64(_mm256_set1_epi64x(r), _mm256_set_epi64x(3, 2, 1, 0));
        if (r >= 4)
            _mm256_storeu_pd(p + 4 * i, v.h[i]);
        else
            _mm256_maskstore_pd(p + 4 * i, m, v.h[i]);
    }
}

VI V vneg(V a)
{
    V r;
    for (int i = 0; i < NH; i++) r.h[i] = _mm256_xor_pd(_mm256_set1_pd(-0.0), a.h[i]);
    return r;
}

/* A group of m (1..NL) particles' elastic trials from their rotated stress
 * r and increment d (vtrial()), stored where admissible: x the stresses (s
 * as loaded), q the strain record (its components' pointers; NULL where
 * the increment is 0), yld the flag.  Returns the bits of the particles
 * left. */
VI unsigned trial_group(const kc *k, const int nc, size_t m, const V r[6], const V d[6],
                        const V s[6], double *const x[6], double *const q[6], double *yld)
{
    V De[6], t[6];
    vtr v;
    vtrial(k, r, d, De, t, &v, nc);
    V el = vand(vand(v.finite, vnot(v.tens)), v.adm);
    unsigned all = (1u << (m < NL ? m : NL)) - 1, me = (unsigned)bits(el) & all;
    if (!me) return all;
    for (int c = 0; c < nc; c++) {
        if (x[c]) vst(x[c], m, sel(el, t[c], s[c]));
        if (q[c]) {
            V qc = vld(q[c], m);
            vst(q[c], m, sel(el, add(qc, d[c]), qc));
        }
    }
    V on = vand(k->one, gt(v.f, mul(k->nftol, v.scale))); /* 1.0 or +0 */
    vst(yld, m, sel(el, on, vld(yld, m)));
    return all & ~me;
}

uint64_t mpm_dp_trial2d_lanes(const mpm_plastic_params *P, size_t n, const double *const e[4],
                              double *const x[4], double *const q[3], double *yld)
{
    kc k;
    k_init(&k, P);
    uint64_t left = 0;
    for (size_t i = 0; i < n; i += NL) {
        size_t m = n - i;
        V d0 = vld(e[0] + i, m), d1 = vld(e[1] + i, m), w = vld(e[2] + i, m), d3 = vld(e[3] + i, m);
        V xx = vld(x[0] + i, m), yy = vld(x[1] + i, m), zz = vld(x[2] + i, m),
          xy = vld(x[3] + i, m);
        /* the Jaumann rotation (jaumann_2d()): xx + 2.0 * w * xy is
         * xx + ((2.0 * w) * xy); de_zz as a zero lane gives the
         * written-out 2D loop's + 0.0 terms, and yz and xz, zero, are left
         * out (nc = 4) */
        V w2 = mul(k.two, w);
        V r[6] = {add(xx, mul(w2, xy)),
                  sub(yy, mul(w2, xy)),
                  zz,
                  add(xy, mul(w, sub(yy, xx))),
                  k.zero,
                  k.zero};
        V d[6] = {d0, d1, k.zero, d3, k.zero, k.zero}, s[6] = {xx, yy, zz, xy, k.zero, k.zero};
        double *xi[6] = {x[0] + i, x[1] + i, x[2] + i, x[3] + i, NULL, NULL};
        double *qi[6] = {q[0] + i, q[1] + i, NULL, q[2] + i, NULL, NULL};
        left |= (uint64_t)trial_group(&k, 4, m, r, d, s, xi, qi, yld + i) << i;
    }
    return left;
}

uint64_t mpm_dp_trial3d_lanes(const mpm_plastic_params *P, size_t n, const double *const e[9],
                              double *const x[6], double *const q[6], double *yld)
{
    /* the Voigt slot of S[a][b] (jaumann_3d()'s matrix), and the entries
     * of R it stores, in Voigt order */
    static const int vo[3][3] = {{0, 3, 5}, {3, 1, 4}, {5, 4, 2}};
    static const int ra[6] = {0, 1, 2, 0, 1, 0}, rb[6] = {0, 1, 2, 1, 2, 2};
    kc k;
    k_init(&k, P);
    uint64_t left = 0;
    for (size_t i = 0; i < n; i += NL) {
        size_t m = n - i;
        V d[6], s[6], r[6], W[3][3];
        double *xi[6], *qi[6];
        for (int c = 0; c < 6; c++) {
            d[c] = vld(e[c] + i, m);
            s[c] = vld(x[c] + i, m);
            xi[c] = x[c] + i;
            qi[c] = q[c] + i;
        }
        V w0 = vld(e[6] + i, m), w1 = vld(e[7] + i, m), w2 = vld(e[8] + i, m);
        W[0][0] = k.zero, W[0][1] = w0, W[0][2] = w2;
        W[1][0] = vneg(w0), W[1][1] = k.zero, W[1][2] = w1;
        W[2][0] = vneg(w2), W[2][1] = vneg(w1), W[2][2] = k.zero;
        /* the Jaumann rotation (jaumann_3d()): R = S + (W S - S W), each
         * entry's sum from 0 over k in order, the zero products kept */
        for (int c = 0; c < 6; c++) {
            int a = ra[c], b = rb[c];
            V acc = k.zero;
            for (int j = 0; j < 3; j++)
                acc = add(acc, sub(mul(W[a][j], s[vo[j][b]]), mul(s[vo[a][j]], W[j][b])));
            r[c] = add(s[vo[a][b]], acc);
        }
        left |= (uint64_t)trial_group(&k, 6, m, r, d, s, xi, qi, yld + i) << i;
    }
    return left;
}

#else
/* no AVX2 in this build: every particle is left to mpm_plastic_update()
 * (mpm_sim.plan.dp_lanes is 0 then, so this is not called) */
void mpm_dp_lanes(const mpm_plastic_params *P, int nc, size_t n, double *sig, const double *de,
                  double *epq, double *dis, int *nsub, unsigned char *ok)
{
    (void)P, (void)nc, (void)sig, (void)de, (void)epq, (void)dis, (void)nsub;
    for (size_t i = 0; i < n; i++) ok[i] = 0;
}

uint64_t mpm_dp_trial2d_lanes(const mpm_plastic_params *P, size_t n, const double *const e[4],
                              double *const x[4], double *const q[3], double *yld)
{
    (void)P, (void)e, (void)x, (void)q, (void)yld;
    return n >= 64 ? ~(uint64_t)0 : ((uint64_t)1 << n) - 1;
}

uint64_t mpm_dp_trial3d_lanes(const mpm_plastic_params *P, size_t n, const double *const e[9],
                              double *const x[6], double *const q[6], double *yld)
{
    (void)P, (void)e, (void)x, (void)q, (void)yld;
    return n >= 64 ? ~(uint64_t)0 : ((uint64_t)1 << n) - 1;
}
#endif
