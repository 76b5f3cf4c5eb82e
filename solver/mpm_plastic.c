/*
 * mpm_plastic.c - the stress-point integrators of the perfectly plastic
 * Drucker-Prager and Mohr-Coulomb models (see mpm_plastic.h for the
 * surfaces, the sign convention and the papers' equations): Drucker-Prager
 * by Sloan, Abbo & Sheng 2001's explicit substepping with error control and
 * drift correction, its tension cut-off in closed form; Mohr-Coulomb by the
 * closed-form return in principal stress space to a plane, an edge or a
 * point.  Plain C and libm; no allocation, no global state.
 */
#include "mpm_plastic.h"

#include "mpm_plastic_tol.h"

#include <math.h>
#include <string.h>

/* ---- tensors in Voigt storage (tensor shear) ---- */

/* a : b for symmetric tensors stored xx yy zz xy yz xz */
static double ddot(const double a[6], const double b[6])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + 2 * (a[3] * b[3] + a[4] * b[4] + a[5] * b[5]);
}

static double tnorm(const double a[6])
{
    return sqrt(ddot(a, a));
}

static double meanp(const double s[6])
{
    return (s[0] + s[1] + s[2]) / 3;
}

/* D e: Hooke's law for a strain-like tensor e.  The hot helpers of the
 * substepping (hooke(), sqrt_j2(), dp_invariants(), dp_euler()) load
 * their inputs into locals before they store: a store through a double
 * pointer could otherwise alias the parameters and force their reloads.
 * Each keeps the operations and their order of the plain loops (x - 0
 * is x, and x + 0 is kept where x could be -0), so the same bits. */
static void hooke(const mpm_plastic_params *P, const double e[6], double s[6])
{
    const double e0 = e[0], e1 = e[1], e2 = e[2], e3 = e[3], e4 = e[4], e5 = e[5];
    const double lt = P->lam * (e0 + e1 + e2), g2 = 2 * P->G;
    s[0] = lt + g2 * e0;
    s[1] = lt + g2 * e1;
    s[2] = lt + g2 * e2;
    s[3] = g2 * e3;
    s[4] = g2 * e4;
    s[5] = g2 * e5;
}

/* C s: the compliance */
static void compliance(const mpm_plastic_params *P, const double s[6], double e[6])
{
    double p = meanp(s);
    for (int i = 0; i < 3; i++) e[i] = (s[i] - p) / (2 * P->G) + p / (3 * P->K);
    for (int i = 3; i < 6; i++) e[i] = s[i] / (2 * P->G);
}

/* sqrt(2/3 dev(e) : dev(e)) */
static double eqv_dev(const double e[6])
{
    double m = meanp(e), d[6];
    for (int i = 0; i < 6; i++) d[i] = e[i] - (i < 3 ? m : 0);
    return sqrt(2.0 / 3.0 * ddot(d, d));
}

/* sqrt(J2) and the deviator d, from the mean stress p */
static double sqrt_j2_p(const double s[6], double p, double d[6])
{
    const double d0 = s[0] - p, d1 = s[1] - p, d2 = s[2] - p, d3 = s[3], d4 = s[4], d5 = s[5];
    d[0] = d0;
    d[1] = d1;
    d[2] = d2;
    d[3] = d3;
    d[4] = d4;
    d[5] = d5;
    return sqrt(0.5 * (d0 * d0 + d1 * d1 + d2 * d2 + 2 * (d3 * d3 + d4 * d4 + d5 * d5)));
}

/* sqrt(J2) and the deviator d */
static double sqrt_j2(const double s[6], double d[6])
{
    return sqrt_j2_p(s, meanp(s), d);
}

/* all six finite: x - x is 0 for a finite x, NaN for an infinity or a NaN */
static int finite6(const double s[6])
{
    return (s[0] - s[0]) + (s[1] - s[1]) + (s[2] - s[2]) + (s[3] - s[3]) + (s[4] - s[4]) +
               (s[5] - s[5]) ==
           0;
}

/* ---- Drucker-Prager ---- */

/* the cone's f = sqrt(J2) + eta p - xi c and its scale (the sum of the
 * magnitudes of its terms) */
static double dp_f(const mpm_plastic_params *P, const double s[6], double *scale)
{
    double d[6], p = meanp(s), r = sqrt_j2(s, d);
    *scale = r + fabs(P->eta * p) + P->xi * P->c;
    return r + P->eta * p - P->xi * P->c;
}

/* The invariants of a stress the cone's formulas use.  Off the cone's
 * axis the gradient is a = inv d + eta/3 I and the flow b = inv d +
 * etag/3 I with inv = 1/(2 sqrt(J2)); on the axis (sqrt(J2) = 0 relative
 * to the surface's scale) inv = 0, the deviatoric part taken as 0.  Then
 * D b = 2G inv d + K etag I, a : D b = G + K eta etag (K eta etag on the
 * axis), a : D de = 2G inv d : de + K eta tr(de), and the equivalent
 * plastic strain per unit multiplier is |dev b| sqrt(2/3) = 1/sqrt3. */
typedef struct {
    double p, r, inv; /* mean stress, sqrt(J2), 1/(2 sqrt(J2)) or 0 */
    double d[6];      /* deviator */
} dp_inv;

static void dp_invariants(const mpm_plastic_params *P, const double s[6], dp_inv *v)
{
    const double p = meanp(s), eta = P->eta, xc = P->xi * P->c;
    const double r = sqrt_j2_p(s, p, v->d);
    const double scale = r + fabs(eta * p) + xc;
    v->p = p;
    v->r = r;
    v->inv = r > TINY_REL * scale && r > 0 ? 1 / (2 * r) : 0;
}

static double dp_f_inv(const mpm_plastic_params *P, const dp_inv *v, double *scale)
{
    *scale = v->r + fabs(P->eta * v->p) + P->xi * P->c;
    return v->r + P->eta * v->p - P->xi * P->c;
}

static double dp_aDb(const mpm_plastic_params *P, const dp_inv *v)
{
    return (v->inv > 0 ? P->G : 0) + P->K * P->eta * P->etag;
}

static double dp_aDe(const mpm_plastic_params *P, const dp_inv *v, const double de[6])
{
    return 2 * P->G * v->inv * ddot(v->d, de) + P->K * P->eta * (de[0] + de[1] + de[2]);
}

static void dp_Db(const mpm_plastic_params *P, const dp_inv *v, double Db[6])
{
    const double g = 2 * P->G * v->inv, k = P->K * P->etag;
    const double d0 = v->d[0], d1 = v->d[1], d2 = v->d[2], d3 = v->d[3], d4 = v->d[4], d5 = v->d[5];
    Db[0] = g * d0 + k;
    Db[1] = g * d1 + k;
    Db[2] = g * d2 + k;
    Db[3] = g * d3 + 0.0;
    Db[4] = g * d4 + 0.0;
    Db[5] = g * d5 + 0.0;
}

/* the equivalent plastic strain per unit multiplier */
static double dp_eq(const dp_inv *v)
{
    return v->inv > 0 ? 1 / SQRT3 : 0;
}

/* One forward-Euler estimate of the plastic increment from the stress
 * with invariants v for the strain de (De = D de): dlam = a:D de / a:D b
 * (0 when unloading), dsig = D de - dlam D b; returns dlam. */
static double dp_euler(const mpm_plastic_params *P, const dp_inv *v, const double de[6],
                       const double De[6], double ds[6])
{
    const double num = dp_aDe(P, v, de), den = dp_aDb(P, v);
    const double dl = num > 0 && den > 0 ? num / den : 0;
    double Db[6];
    dp_Db(P, v, Db);
    const double x0 = De[0] - dl * Db[0], x1 = De[1] - dl * Db[1], x2 = De[2] - dl * Db[2],
                 x3 = De[3] - dl * Db[3], x4 = De[4] - dl * Db[4], x5 = De[5] - dl * Db[5];
    ds[0] = x0;
    ds[1] = x1;
    ds[2] = x2;
    ds[3] = x3;
    ds[4] = x4;
    ds[5] = x5;
    return dl;
}

/* sigma : b(sigma) = sqrt(J2) + etag p, the dissipation per unit
 * multiplier; >= 0 on the surface when etag <= eta and p <= pt (clamped at
 * 0 off it, where it is a round-off estimate) */
static double dp_sb(const mpm_plastic_params *P, const dp_inv *v)
{
    double x = v->r + P->etag * v->p;
    return x > 0 ? x : 0;
}

/* f at s + al De, and its scale */
static double dp_f_at(const mpm_plastic_params *P, const double s[6], const double De[6], double al,
                      double *scale)
{
    double x[6];
    for (int i = 0; i < 6; i++) x[i] = s[i] + al * De[i];
    return dp_f(P, x, scale);
}

/* A yield function of a stress, with its scale (dp_f(), yield_fast()). */
typedef double (*yield_fn)(const mpm_plastic_params *P, const double s[6], double *scale);

static double yield_fast(const mpm_plastic_params *P, const double sig[6], double *scale);

/* The Pegasus method (Sloan 2001) for f(s + al De) = 0 on [a0, a1] with
 * f0 < 0 < f1, until |f| <= tol scale: the elastic fraction of an
 * increment (dp_f(), ftol) and the first yield point of a closed-form
 * return (first_yield()).  mpm_plastic_avx2.c's pass_pegasus() runs it a
 * lane per particle with the same operations. */
static inline double pegasus(const mpm_plastic_params *P, yield_fn f, double tol, const double s[6],
                             const double De[6], double a0, double a1, double f0, double f1)
{
    double al = a1, x[6];
    for (int it = 0; it < PEG_MAXIT && f1 != f0; it++) {
        double sc;
        al = a1 - f1 * (a1 - a0) / (f1 - f0);
        for (int i = 0; i < 6; i++) x[i] = s[i] + al * De[i];
        double fn = f(P, x, &sc);
        if (fabs(fn) <= tol * sc) break;
        if (fn * f1 < 0) {
            a0 = a1;
            f0 = f1;
        } else {
            f0 = f0 * f1 / (f1 + fn);
        }
        a1 = al;
        f1 = fn;
    }
    return al;
}

/* The elastic fraction of an increment that starts on the surface and
 * first unloads (Sloan 2001): [a0, a1] cut into NSUB pieces
 * until f turns positive, then Pegasus on the piece whose start is inside;
 * a piece that starts on the surface is cut again (3 rounds at most, then
 * the increment counts as plastic from the start). */
static double dp_unload_alpha(const mpm_plastic_params *P, const double s[6], const double De[6])
{
    double a0 = 0, a1 = 1;
    for (int round = 0; round < 3; round++) {
        double da = (a1 - a0) / NSUB, al = a0, sc, fa = dp_f_at(P, s, De, a0, &sc);
        double tola = P->ftol * sc;
        int found = 0;
        for (int i = 1; i <= NSUB; i++) {
            double an = a0 + i * da, scn, fn = dp_f_at(P, s, De, an, &scn);
            if (fn > P->ftol * scn) {
                if (fa < -tola) return pegasus(P, dp_f, P->ftol, s, De, al, an, fa, fn);
                a0 = al;
                a1 = an;
                found = 1;
                break;
            }
            al = an;
            fa = fn;
            tola = P->ftol * scn;
        }
        if (!found) return 1;
    }
    return 0;
}

/* Sloan's drift correction: while f > ftol, the consistent correction
 * s - f/(a:D b) D b, or the normal correction s - f/(a:a) a when that does
 * not reduce |f|; the plastic strain the correction implies is added to
 * the dissipation and eps_p.  v: the invariants of s on entry, of the
 * corrected s on return. */
static void dp_drift(const mpm_plastic_params *P, double s[6], dp_inv *v, double *dis, double *epq)
{
    for (int it = 0; it < DRIFT_MAXIT; it++) {
        double sc, f = dp_f_inv(P, v, &sc);
        if (f <= P->ftol * sc) return;
        double y[6] = {0}, Db[6], den = dp_aDb(P, v), scy;
        dp_inv vy = {0};
        int consistent = 0;
        if (den > 0) {
            dp_Db(P, v, Db);
            for (int i = 0; i < 6; i++) y[i] = s[i] - f / den * Db[i];
            dp_invariants(P, y, &vy);
            consistent = fabs(dp_f_inv(P, &vy, &scy)) <= fabs(f);
        }
        if (consistent) {
            *dis += f / den * dp_sb(P, &vy);
            *epq += f / den * dp_eq(v);
        } else {
            double a[6], d[6], ep[6];
            for (int i = 0; i < 6; i++) a[i] = v->inv * v->d[i] + (i < 3 ? P->eta / 3 : 0);
            double aa = ddot(a, a);
            if (!(aa > 0)) return;
            for (int i = 0; i < 6; i++) {
                y[i] = s[i] - f / aa * a[i];
                d[i] = s[i] - y[i];
            }
            compliance(P, d, ep);
            *dis += ddot(y, ep);
            *epq += eqv_dev(ep);
            dp_invariants(P, y, &vy);
        }
        memcpy(s, y, sizeof y);
        *v = vy;
    }
}

/* The first point of the elastic trial path s0 + al De on the model's
 * surface (the largest of its surfaces), by the Pegasus method; s0 itself
 * when s0 is on or outside it.  For the closed-form returns' dissipation. */
static void first_yield(const mpm_plastic_params *P, const double s0[6], const double De[6],
                        double out[6])
{
    double sc, f0 = yield_fast(P, s0, &sc), x[6];
    double tol = P->ftol > FY_TOL ? P->ftol : FY_TOL;
    memcpy(out, s0, 6 * sizeof s0[0]);
    if (f0 >= -tol * sc) return;
    for (int i = 0; i < 6; i++) x[i] = s0[i] + De[i];
    double f1 = yield_fast(P, x, &sc);
    if (!(f1 > 0)) return;
    double al = pegasus(P, yield_fast, tol, s0, De, 0, 1, f0, f1);
    for (int i = 0; i < 6; i++) out[i] = s0[i] + al * De[i];
}

/* The dissipation of a closed-form return by the trapezoidal rule between
 * the first yield point sa and the returned stress y, sa : dep and y : dep
 * each clamped at 0 (exact for one plane with fixed principal axes, where
 * the stress moves linearly and the multiplier uniformly). */
static double trap_dis(const double sa[6], const double y[6], const double dep[6])
{
    return 0.5 * (fmax(0, ddot(sa, dep)) + fmax(0, ddot(y, dep)));
}

/* The tension cut-off's closed-form return of s (whose mean stress is
 * above pt; sa the first yield point on the way to it): p = pt, the
 * deviator kept, scaled to the cone's radius at pt when outside it. */
static void dp_tension(const mpm_plastic_params *P, double s[6], const double sa[6], double *dis,
                       double *epq)
{
    double d[6], r = sqrt_j2(s, d), rt = P->xi * P->c - P->eta * P->pt, y[6];
    if (rt < 0) rt = 0;
    double beta = r > rt ? rt / r : 1;
    for (int i = 0; i < 6; i++) y[i] = beta * d[i] + (i < 3 ? P->pt : 0);
    double dd[6], ep[6];
    for (int i = 0; i < 6; i++) dd[i] = s[i] - y[i];
    compliance(P, dd, ep);
    *dis += trap_dis(sa, y, ep);
    *epq += eqv_dev(ep);
    memcpy(s, y, sizeof y);
}

/* The modified Euler scheme with local error control (Sloan 2001) over
 * the strain de from s (on the surface; v its invariants, updated with
 * it); |sig| in the relative error is floored at xi c, so that a state
 * near a cohesive apex does not force tiny substeps.  Returns 1 when
 * max_substeps did not reach the end (dp_update() then falls back on
 * dp_implicit()). */
static int dp_substep(const mpm_plastic_params *P, double s[6], dp_inv *v, const double de[6],
                      int *nacc, double *dis, double *epq)
{
    double T = 0, dT = 1, stol = P->tol;
    int fail = 0, n = 0, acc = 0;
    while (T < 1) {
        if (n++ >= P->max_substeps) return 1; /* exhausted: dp_update falls back */
        double e[6], De[6], ds1[6], s1[6], ds2[6], sn[6], diff[6];
        dp_inv v1;
        for (int i = 0; i < 6; i++) e[i] = dT * de[i];
        hooke(P, e, De);
        double dl1 = dp_euler(P, v, e, De, ds1);
        for (int i = 0; i < 6; i++) s1[i] = s[i] + ds1[i];
        dp_invariants(P, s1, &v1);
        double dl2 = dp_euler(P, &v1, e, De, ds2);
        for (int i = 0; i < 6; i++) {
            sn[i] = s[i] + 0.5 * (ds1[i] + ds2[i]);
            diff[i] = ds2[i] - ds1[i];
        }
        double ref = tnorm(sn);
        if (ref < P->xi * P->c) ref = P->xi * P->c;
        double R = ref > 0 ? tnorm(diff) / (2 * ref) : 0;
        if (R < R_MIN) R = R_MIN;
        if (!finite6(sn)) return MPM_EDIVERGED;
        if (R > stol && dT > DT_MIN) {
            double q = 0.9 * sqrt(stol / R);
            if (q < 0.1) q = 0.1;
            dT = q * dT > DT_MIN ? q * dT : DT_MIN;
            fail = 1;
            continue;
        }
        /* the dissipation and eps_p by the trapezoidal rule on the
         * multipliers, dlam sigma : b(sigma) at both ends (on the surface) */
        double sb0 = dp_sb(P, v);
        *epq += 0.5 * (dl1 * dp_eq(v) + dl2 * dp_eq(&v1));
        memcpy(s, sn, sizeof sn);
        dp_invariants(P, s, v);
        dp_drift(P, s, v, dis, epq);
        *dis += 0.5 * (dl1 * sb0 + dl2 * dp_sb(P, v));
        acc++;
        double q = 0.9 * sqrt(stol / R);
        if (q > 1.1) q = 1.1;
        if (q < 0.1) q = 0.1;
        if (fail && q > 1) q = 1;
        fail = 0;
        T += dT;
        if (T >= 1 - 1e-14) break;
        dT = q * dT > DT_MIN ? q * dT : DT_MIN;
        if (dT > 1 - T) dT = 1 - T;
    }
    *nacc = acc;
    return 0;
}

/* Backward Euler's return from the trial stress tr (the elastic predictor
 * sig + De), for an increment that Sloan's substepping could not resolve
 * within max_substeps: a stress near the apex (cohesionless sand at the
 * free surface) with a strain increment of many yield strains,
 * where the flow direction turns within a substep and the error estimate
 * stops shrinking with it.  For f = sqrt(J2) + eta p - xi c and g =
 * sqrt(J2) + etag p, perfectly plastic: dgamma = f(tr) / (G + K eta etag),
 * sqrt(J2) = r_tr - G dgamma, p = p_tr - K etag dgamma; when that overshoots
 * the axis, the apex p = xi c / eta with a zero deviator (de Souza Neto,
 * Peric & Owen 2008, 8.3).  One closed form, unconditionally stable; the
 * dissipation as the other closed forms' (trap_dis) (plastic_dp_near_apex). */
static void dp_implicit(const mpm_plastic_params *P, const double sig[6], const double De[6],
                        const double tr[6], double s[6], double *dis, double *epq)
{
    double d[6], p = meanp(tr), r = sqrt_j2_p(tr, p, d);
    double f = r + P->eta * p - P->xi * P->c;
    double dg = f > 0 ? f / (P->G + P->K * P->eta * P->etag) : 0;
    double rn = r - P->G * dg, pn = p - P->K * P->etag * dg;
    if (!(rn > 0)) {
        rn = 0;
        pn = P->eta > 0 ? P->xi * P->c / P->eta : pn;
    }
    double beta = r > 0 ? rn / r : 0, sa[6], dd[6], ep[6];
    for (int i = 0; i < 6; i++) s[i] = beta * d[i] + (i < 3 ? pn : 0);
    first_yield(P, sig, De, sa);
    for (int i = 0; i < 6; i++) dd[i] = tr[i] - s[i];
    compliance(P, dd, ep);
    *dis += trap_dis(sa, s, ep);
    *epq += eqv_dev(ep);
}

static int dp_update(const mpm_plastic_params *P, double sig[6], const double deps[6],
                     mpm_plastic_state *st, double *dissip)
{
    double De[6], tr[6], s[6], dis = 0, epq = 0, ftr;
    int on = 0, k = mpm_dp_trial(P, sig, deps, De, tr, &ftr, &on);
    if (k == MPM_DP_NONFINITE) return MPM_EDIVERGED;
    int nsub = 0;
    if (k == MPM_DP_TENSION) {
        /* the tension region (the cut-off, its corner with the cone, the apex) */
        double sa[6];
        first_yield(P, sig, De, sa);
        dp_tension(P, tr, sa, &dis, &epq);
        memcpy(s, tr, sizeof s);
        nsub = 1;
    } else if (k == MPM_DP_ELASTIC) {
        memcpy(sig, tr, sizeof tr);
        st->substeps = 0;
        st->yielded = on;
        if (dissip) *dissip = 0;
        return 0;
    } else {
        dp_inv v;
        dp_invariants(P, sig, &v);
        double sc0, f0 = dp_f_inv(P, &v, &sc0), al = 0;
        if (f0 < -P->ftol * sc0) {
            al = pegasus(P, dp_f, P->ftol, sig, De, 0, 1, f0, ftr);
        } else {
            /* on the surface: does the increment first unload? */
            double na = sqrt(v.inv * v.inv * ddot(v.d, v.d) + P->eta * P->eta / 3), nd = tnorm(De);
            if (na > 0 && nd > 0 && dp_aDe(P, &v, deps) / (na * nd) < -LTOL)
                al = dp_unload_alpha(P, sig, De);
        }
        double rest[6];
        for (int i = 0; i < 6; i++) {
            s[i] = sig[i] + al * De[i];
            rest[i] = (1 - al) * deps[i];
        }
        if (al != 0) dp_invariants(P, s, &v);
        int rc = dp_substep(P, s, &v, rest, &nsub, &dis, &epq);
        if (rc == 1) {
            dis = epq = 0;
            dp_implicit(P, sig, De, tr, s, &dis, &epq);
            dp_invariants(P, s, &v);
            nsub = P->max_substeps + 1;
        } else if (rc) {
            return rc;
        }
        if (v.p > P->pt) {
            double sa[6];
            memcpy(sa, s, sizeof sa);
            dp_tension(P, s, sa, &dis, &epq);
        }
    }
    memcpy(sig, s, sizeof s);
    st->eps_p += epq;
    st->substeps = nsub;
    st->yielded = 1;
    if (dissip) *dissip = dis;
    return 0;
}

/* ---- Mohr-Coulomb ---- */

void mpm_plastic_principal(const double sig[6], double val[3], double vec[3][3])
{
    double a[3][3] = {{sig[0], sig[3], sig[5]}, {sig[3], sig[1], sig[4]}, {sig[5], sig[4], sig[2]}};
    double v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    static const int pp[3] = {0, 0, 1}, qq[3] = {1, 2, 2};
    /* cyclic Jacobi rotations until the off-diagonal part is at round-off */
    for (int sweep = 0; sweep < 64; sweep++) {
        double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        double dia = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if (off == 0 || off <= 1e-36 * dia) break;
        for (int r = 0; r < 3; r++) {
            int p = pp[r], q = qq[r];
            /* an off-diagonal term below round-off of its diagonal is 0 (it
             * would move the eigenvalues by its square) */
            if (fabs(a[p][q]) <= 1e-18 * (fabs(a[p][p]) + fabs(a[q][q]))) {
                a[p][q] = a[q][p] = 0;
                continue;
            }
            double th = (a[q][q] - a[p][p]) / (2 * a[p][q]);
            double t = (th >= 0 ? 1.0 : -1.0) / (fabs(th) + sqrt(th * th + 1));
            if (!isfinite(th)) t = 0.5 / th; /* |th| huge: t = 1/(2 th) */
            double c = 1 / sqrt(t * t + 1), sn = t * c;
            for (int k = 0; k < 3; k++) {
                double akp = a[k][p], akq = a[k][q];
                a[k][p] = c * akp - sn * akq;
                a[k][q] = sn * akp + c * akq;
            }
            for (int k = 0; k < 3; k++) {
                double apk = a[p][k], aqk = a[q][k];
                a[p][k] = c * apk - sn * aqk;
                a[q][k] = sn * apk + c * aqk;
            }
            for (int k = 0; k < 3; k++) {
                double vkp = v[k][p], vkq = v[k][q];
                v[k][p] = c * vkp - sn * vkq;
                v[k][q] = sn * vkp + c * vkq;
            }
        }
    }
    int idx[3] = {0, 1, 2};
    for (int i = 0; i < 3; i++)
        for (int j = i + 1; j < 3; j++)
            if (a[idx[j]][idx[j]] > a[idx[i]][idx[i]]) {
                int t = idx[i];
                idx[i] = idx[j];
                idx[j] = t;
            }
    for (int i = 0; i < 3; i++) {
        val[i] = a[idx[i]][idx[i]];
        if (vec)
            for (int k = 0; k < 3; k++) vec[i][k] = v[k][idx[i]];
    }
}

/* The principal values of sig, descending, from the invariants (the
 * trigonometric solution of the characteristic cubic). */
static void mc_principal_fast(const double sig[6], double val[3])
{
    double d[6], m = meanp(sig), r2 = sqrt_j2(sig, d);
    double j2 = r2 * r2;
    if (!(j2 > 0)) {
        val[0] = val[1] = val[2] = m;
        return;
    }
    double j3 = d[0] * (d[1] * d[2] - d[4] * d[4]) - d[3] * (d[3] * d[2] - d[4] * d[5]) +
                d[5] * (d[3] * d[4] - d[1] * d[5]);
    double t3 = 3 / j2, c3 = 0.5 * j3 * t3 * sqrt(t3);
    if (c3 > 1) c3 = 1;
    if (c3 < -1) c3 = -1;
    double th = acos(c3) / 3, r = 2 * sqrt(j2 / 3), tp = 2.0943951023931955; /* 2 pi / 3 */
    val[0] = m + r * cos(th);
    val[1] = m + r * cos(th - tp);
    val[2] = m + r * cos(th + tp);
}

/* MC's yield function on ordered principal stresses: the larger of the
 * plane k s1 - s3 - sigc and the cut-off s1 - pt */
static double mc_f(const mpm_plastic_params *P, const double s[3], double *scale)
{
    double f = P->kphi * s[0] - s[2] - P->sgc;
    *scale = P->kphi * fabs(s[0]) + fabs(s[2]) + P->sgc;
    if (isfinite(P->pt)) {
        double ft = s[0] - P->pt, sct = fabs(s[0]) + fabs(P->pt);
        if (ft > f) f = ft;
        if (sct > *scale) *scale = sct;
    }
    return f;
}

/* Solves the n x n system M x = r (n <= 3) by Gaussian elimination with
 * partial pivoting; 0, or -1 when M is singular (relative to its size). */
static int solve_small(int n, double M[3][3], double r[3], double x[3])
{
    double big = 0;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++)
            if (fabs(M[i][j]) > big) big = fabs(M[i][j]);
    if (!(big > 0)) return -1;
    for (int k = 0; k < n; k++) {
        int piv = k;
        for (int i = k + 1; i < n; i++)
            if (fabs(M[i][k]) > fabs(M[piv][k])) piv = i;
        if (fabs(M[piv][k]) <= 1e-10 * big) return -1;
        if (piv != k) {
            for (int j = 0; j < n; j++) {
                double t = M[k][j];
                M[k][j] = M[piv][j];
                M[piv][j] = t;
            }
            double t = r[k];
            r[k] = r[piv];
            r[piv] = t;
        }
        for (int i = k + 1; i < n; i++) {
            double m = M[i][k] / M[k][k];
            for (int j = k; j < n; j++) M[i][j] -= m * M[k][j];
            r[i] -= m * r[k];
        }
    }
    for (int i = n - 1; i >= 0; i--) {
        double v = r[i];
        for (int j = i + 1; j < n; j++) v -= M[i][j] * x[j];
        x[i] = v / M[i][i];
    }
    return 0;
}

/* The return of the ordered trial principal stresses s to the surface:
 * the first set of 1, 2 or 3 active surfaces (of the sextant's plane k s1
 * - s3, its neighbours across the compression edge, k s2 - s3, and the
 * extension edge, k s1 - s2, and the cut-offs s_i <= pt) whose multipliers
 * are >= 0 and whose stress y = s - sum dlam_j D b_j is admissible and
 * still ordered.  0, or MPM_EINTERNAL when no set qualifies (a bug). */
static int mc_return(const mpm_plastic_params *P, const double s[3], double y[3])
{
    double k = P->kphi, m = P->mpsi;
    double A[6][3] = {{k, 0, -1}, {0, k, -1}, {k, -1, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    double B[6][3] = {{m, 0, -1}, {0, m, -1}, {m, -1, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    double r[6] = {P->sgc, P->sgc, P->sgc, P->pt, P->pt, P->pt};
    double DB[6][3];
    int nsurf = isfinite(P->pt) ? 6 : 3;
    for (int j = 0; j < 6; j++)
        for (int i = 0; i < 3; i++)
            DB[j][i] = P->lam * (B[j][0] + B[j][1] + B[j][2]) + 2 * P->G * B[j][i];
    double scale = fabs(s[0]) + fabs(s[1]) + fabs(s[2]) + P->sgc + (nsurf == 6 ? fabs(P->pt) : 0);
    double tol = MC_TOL * scale;
    for (int size = 1; size <= 3; size++)
        for (int mask = 1; mask < 1 << nsurf; mask++) {
            int set[3], n = 0;
            for (int j = 0; j < nsurf; j++)
                if (mask >> j & 1) {
                    if (n == 3) break;
                    set[n++] = j;
                }
            if (n != size || __builtin_popcount((unsigned)mask) != size) continue;
            double M[3][3], rhs[3], dl[3] = {0, 0, 0};
            for (int a = 0; a < size; a++) {
                const double *ga = A[set[a]];
                rhs[a] = ga[0] * s[0] + ga[1] * s[1] + ga[2] * s[2] - r[set[a]];
                for (int b = 0; b < size; b++) {
                    const double *db = DB[set[b]];
                    M[a][b] = ga[0] * db[0] + ga[1] * db[1] + ga[2] * db[2];
                }
            }
            if (solve_small(size, M, rhs, dl)) continue;
            double sum = 0;
            int neg = 0;
            for (int a = 0; a < size; a++) sum += fabs(dl[a]);
            for (int a = 0; a < size; a++) neg |= dl[a] < -RET_TOL * sum;
            if (neg) continue;
            double x[3];
            for (int i = 0; i < 3; i++) {
                x[i] = s[i];
                for (int a = 0; a < size; a++) x[i] -= dl[a] * DB[set[a]][i];
            }
            /* x carries the trial's round-off (the trial may be far larger than
             * the surface): project it onto the active surfaces, the least
             * change, x -= A^T (A A^T)^-1 (A x - r) */
            double AA[3][3], res[3], w[3] = {0, 0, 0};
            for (int a = 0; a < size; a++) {
                const double *ga = A[set[a]];
                res[a] = ga[0] * x[0] + ga[1] * x[1] + ga[2] * x[2] - r[set[a]];
                for (int b = 0; b < size; b++) {
                    const double *gb = A[set[b]];
                    AA[a][b] = ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2];
                }
            }
            if (solve_small(size, AA, res, w) == 0)
                for (int i = 0; i < 3; i++)
                    for (int a = 0; a < size; a++) x[i] -= w[a] * A[set[a]][i];
            if (x[0] < x[1] - tol || x[1] < x[2] - tol) continue;
            double hi = fmax(x[0], fmax(x[1], x[2])), lo = fmin(x[0], fmin(x[1], x[2]));
            if (k * hi - lo - P->sgc > tol) continue;
            if (nsurf == 6 && hi - P->pt > tol) continue;
            memcpy(y, x, sizeof x);
            return 0;
        }
    return MPM_EINTERNAL;
}

static int mc_update(const mpm_plastic_params *P, double sig[6], const double deps[6],
                     mpm_plastic_state *st, double *dissip)
{
    double De[6], tr[6], val[3], vec[3][3], sc;
    hooke(P, deps, De);
    for (int i = 0; i < 6; i++) tr[i] = sig[i] + De[i];
    if (!finite6(tr)) return MPM_EDIVERGED;
    /* a cheap elastic check first: the principal values from the
     * invariants (accurate to about sqrt(eps) relative near repeated
     * values, so only a clear margin counts) */
    mc_principal_fast(tr, val);
    double f = mc_f(P, val, &sc);
    if (f < -1e-6 * sc) {
        memcpy(sig, tr, sizeof tr);
        st->substeps = 0;
        st->yielded = 0;
        if (dissip) *dissip = 0;
        return 0;
    }
    mpm_plastic_principal(tr, val, vec);
    f = mc_f(P, val, &sc);
    if (f <= P->ftol * sc) {
        memcpy(sig, tr, sizeof tr);
        st->substeps = 0;
        st->yielded = f > -P->ftol * sc;
        if (dissip) *dissip = 0;
        return 0;
    }
    double y[3];
    int rc = mc_return(P, val, y);
    if (rc) return rc;
    /* the plastic strain C (trial - y) in the principal frame */
    double d[3] = {val[0] - y[0], val[1] - y[1], val[2] - y[2]}, dm = (d[0] + d[1] + d[2]) / 3;
    double ep[3], em = 0, dev2 = 0, y6[6], ep6[6], sa[6];
    for (int i = 0; i < 3; i++) {
        ep[i] = (d[i] - dm) / (2 * P->G) + dm / (3 * P->K);
        em += ep[i] / 3;
    }
    for (int i = 0; i < 3; i++) dev2 += (ep[i] - em) * (ep[i] - em);
    static const int vi[6] = {0, 1, 2, 0, 1, 0}, vj[6] = {0, 1, 2, 1, 2, 2};
    for (int c = 0; c < 6; c++) {
        double v = 0, w = 0;
        for (int i = 0; i < 3; i++) {
            double nn = vec[i][vi[c]] * vec[i][vj[c]];
            v += y[i] * nn;
            w += ep[i] * nn;
        }
        y6[c] = v;
        ep6[c] = w;
    }
    first_yield(P, sig, De, sa);
    double dis = trap_dis(sa, y6, ep6);
    memcpy(sig, y6, sizeof y6);
    st->eps_p += sqrt(2.0 / 3.0 * dev2);
    st->substeps = 1;
    st->yielded = 1;
    if (dissip) *dissip = dis;
    return 0;
}

/* ---- the public functions ---- */

int mpm_plastic_update(const mpm_plastic_params *p, double sig[6], const double deps[6],
                       mpm_plastic_state *st, double *dissip)
{
    return p->kind == MPM_PLASTIC_MOHR_COULOMB ? mc_update(p, sig, deps, st, dissip)
                                               : dp_update(p, sig, deps, st, dissip);
}

/* the yield function with MC's principal values from the invariants or by
 * Jacobi rotations */
static double yield_any(const mpm_plastic_params *p, const double sig[6], double *scale, int fast)
{
    double sc, f;
    if (p->kind == MPM_PLASTIC_MOHR_COULOMB) {
        double val[3];
        if (fast)
            mc_principal_fast(sig, val);
        else
            mpm_plastic_principal(sig, val, NULL);
        f = mc_f(p, val, &sc);
    } else {
        f = dp_f(p, sig, &sc);
        if (isfinite(p->pt)) {
            double pm = meanp(sig), ft = pm - p->pt, sct = fabs(pm) + fabs(p->pt);
            if (ft > f) f = ft;
            if (sct > sc) sc = sct;
        }
    }
    if (scale) *scale = sc;
    return f;
}

static double yield_fast(const mpm_plastic_params *P, const double sig[6], double *scale)
{
    return yield_any(P, sig, scale, 1);
}

double mpm_plastic_yield(const mpm_plastic_params *p, const double sig[6], double *scale)
{
    return yield_any(p, sig, scale, 0);
}

int mpm_plastic_init(mpm_plastic_params *p, mpm_error *err)
{
    const double half_pi = 1.5707963267948966;
    if (p->kind != MPM_PLASTIC_DRUCKER_PRAGER && p->kind != MPM_PLASTIC_MOHR_COULOMB)
        return mpm_fail(err, MPM_EINVAL, "model", "unknown plastic model %d", (int)p->kind);
    if (!(p->E > 0) || !isfinite(p->E))
        return mpm_fail(err, MPM_EINVAL, "youngs_modulus", "must be > 0 and finite, got %g", p->E);
    if (!(p->nu > -1 && p->nu < 0.5))
        return mpm_fail(err, MPM_EINVAL, "poisson_ratio", "must lie in (-1, 0.5), got %g", p->nu);
    if (!(p->phi >= 0 && p->phi < half_pi))
        return mpm_fail(err, MPM_EINVAL, "friction_angle", "must lie in [0, pi/2), got %g", p->phi);
    if (!(p->psi >= 0 && p->psi <= p->phi))
        return mpm_fail(err, MPM_EINVAL, "dilatancy_angle",
                        "must lie in [0, friction_angle = %g], got %g", p->phi, p->psi);
    if (!(p->c >= 0) || !isfinite(p->c))
        return mpm_fail(err, MPM_EINVAL, "cohesion", "must be >= 0 and finite, got %g", p->c);
    if (!(p->c > 0 || p->phi > 0))
        return mpm_fail(err, MPM_EINVAL, "cohesion",
                        "must be > 0 when friction_angle is 0 (no strength at all)");
    if (!(p->tension >= 0))
        return mpm_fail(err, MPM_EINVAL, "tension_cutoff", "must be >= 0, got %g", p->tension);
    if (p->kind == MPM_PLASTIC_DRUCKER_PRAGER && p->match != MPM_DP_COMPRESSION &&
        p->match != MPM_DP_EXTENSION && p->match != MPM_DP_PLANE_STRAIN)
        return mpm_fail(err, MPM_EINVAL, "dp_match", "unknown matching %d", (int)p->match);
    if (!(p->tol >= 0 && p->tol < 1))
        return mpm_fail(err, MPM_EINVAL, "substep_tolerance", "must lie in [0, 1), got %g", p->tol);
    if (!(p->ftol >= 0 && p->ftol < 1e-2))
        return mpm_fail(err, MPM_EINVAL, "yield_tolerance", "must lie in [0, 0.01), got %g",
                        p->ftol);
    if (p->max_substeps < 0 || p->max_substeps > 1000000)
        return mpm_fail(err, MPM_EINVAL, "max_substeps", "must lie in [0, 1000000], got %d",
                        p->max_substeps);
    if (p->tol == 0) p->tol = 1e-4;
    if (p->ftol == 0) p->ftol = 1e-8;
    if (p->max_substeps == 0) p->max_substeps = 1000;
    p->K = p->E / (3 * (1 - 2 * p->nu));
    p->G = p->E / (2 * (1 + p->nu));
    p->lam = p->K - 2 * p->G / 3;
    double sf = sin(p->phi), cf = cos(p->phi), sg = sin(p->psi);
    switch (p->match) {
    case MPM_DP_EXTENSION:
        p->eta = 6 * sf / (SQRT3 * (3 + sf));
        p->xi = 6 * cf / (SQRT3 * (3 + sf));
        p->etag = 6 * sg / (SQRT3 * (3 + sg));
        break;
    case MPM_DP_PLANE_STRAIN: {
        p->etag = SQRT3 * sg / sqrt(3 + sg * sg);
        double w = sqrt(1 - p->etag * p->etag / 3);
        p->eta = sf / (w + p->etag * sf / 3);
        p->xi = cf * (1 - p->eta * p->etag / 3) / w;
        break;
    }
    default:
        p->eta = 6 * sf / (SQRT3 * (3 - sf));
        p->xi = 6 * cf / (SQRT3 * (3 - sf));
        p->etag = 6 * sg / (SQRT3 * (3 - sg));
        break;
    }
    p->kphi = (1 + sf) / (1 - sf);
    p->mpsi = (1 + sg) / (1 - sg);
    p->sgc = 2 * p->c * sqrt(p->kphi);
    double apex;
    if (p->kind == MPM_PLASTIC_MOHR_COULOMB)
        apex = p->kphi > 1 ? p->sgc / (p->kphi - 1) : HUGE_VAL;
    else
        apex = p->eta > 0 ? p->xi * p->c / p->eta : HUGE_VAL;
    p->pt = p->tension < apex ? p->tension : apex;
    return 0;
}
