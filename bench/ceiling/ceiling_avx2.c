/*
 * ceiling_avx2.c - bin/mpmceiling's four-lane kernels (AVX2+FMA, built
 * with -mavx2 -mfma and taken only where the CPU has both): a run of up
 * to four particles of one cell as the lanes of a vector, the cell's
 * corners loaded once and broadcast, and the run's grid sums kept as
 * vectors across consecutive runs of the same cell and summed across the
 * lanes once, when the cell changes.  Lanes past a run add 0 to the sums
 * and store back what they loaded (a blend and a whole-vector store,
 * not a masked store, vmaskmovpd, which AMD Zen cores take slowly).  A
 * moved run whose particles land in different cells is scattered
 * lane by lane.  Free of the solver's bit-for-bit constraints (fused
 * multiply-adds anywhere, the lanes summed in a horizontal order): within
 * round-off of ceiling.c's portable kernels,
 * which `bin/mpmceiling --check` measures.
 */
#include "ceiling.h"

#include <stdint.h>

#if defined(__x86_64__) && defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>

typedef __m256d V;

/* {sum of a's lanes, b's, c's, d's} */
static inline V hsum4(V a, V b, V c, V d)
{
    V ab = _mm256_hadd_pd(a, b), cd = _mm256_hadd_pd(c, d);
    return _mm256_add_pd(_mm256_permute2f128_pd(ab, cd, 0x20),
                         _mm256_permute2f128_pd(ab, cd, 0x31));
}

static const long long lane_masks[5][4] = {
    {0, 0, 0, 0}, {-1, 0, 0, 0}, {-1, -1, 0, 0}, {-1, -1, -1, 0}, {-1, -1, -1, -1}};

static inline __m256i kmask(unsigned k)
{
    return _mm256_loadu_si256((const __m256i *)lane_masks[k]);
}

/* Stores the run's lanes of v at a (k lanes; the others keep old, the
 * values loaded at a for this run): a whole-vector store, which AMD's
 * Zen cores take far faster than a masked one (vmaskmovpd). */
static inline void store_run(double *a, __m256i km, V v, V old)
{
    _mm256_storeu_pd(a, _mm256_blendv_pd(old, v, _mm256_castsi256_pd(km)));
}

/* four lanes' cell node indices and the fractions within the cell */
static inline __m128i cells4(V x, V y, V ih, int nx, V *fx, V *fy)
{
    V rx = _mm256_mul_pd(x, ih), ry = _mm256_mul_pd(y, ih);
    __m128i ci = _mm256_cvttpd_epi32(rx), cj = _mm256_cvttpd_epi32(ry);
    *fx = _mm256_sub_pd(rx, _mm256_cvtepi32_pd(ci));
    *fy = _mm256_sub_pd(ry, _mm256_cvtepi32_pd(cj));
    return _mm_add_epi32(_mm_mullo_epi32(cj, _mm_set1_epi32(nx)), ci);
}

/* how many leading lanes share lane 0's cell (1..4), at most left */
static inline unsigned run4(__m128i n, size_t left)
{
    __m128i b = _mm_shuffle_epi32(n, 0);
    unsigned msk = (unsigned)_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(n, b)));
    unsigned k = (unsigned)__builtin_ctz(~msk & 0x1fu);
    return k > left ? (unsigned)left : k;
}

/* adds four sums to the corners of cell n: (n, n + 1, n + nx, n + nx + 1) */
static inline void add4(double *restrict a, size_t n, int nx, V s)
{
    a[n] += s[0];
    a[n + 1] += s[1];
    a[n + (size_t)nx] += s[2];
    a[n + (size_t)nx + 1] += s[3];
}

static size_t sf4(cl_parts *P, cl_grid *g)
{
    const int nx = g->nx;
    const V ih = _mm256_set1_pd(g->ih), one = _mm256_set1_pd(1.0), la = _mm256_set1_pd(g->lambda),
            m2 = _mm256_set1_pd(g->mu2), ihdt = _mm256_set1_pd(g->ih * g->dt),
            hihdt = _mm256_set1_pd(0.5 * g->ih * g->dt);
    const double *restrict qx = g->qx, *restrict qy = g->qy, *restrict mi = g->mi;
    V F[8];
    for (int c = 0; c < 8; c++) F[c] = _mm256_setzero_pd();
    long rn = -1;
    size_t runs = 0;
    for (size_t p = 0; p < P->n;) {
        V fx, fy;
        __m128i n4 = cells4(_mm256_loadu_pd(P->x + p), _mm256_loadu_pd(P->y + p), ih, nx, &fx, &fy);
        unsigned k = run4(n4, P->n - p);
        long n = _mm_cvtsi128_si32(n4);
        if (n != rn) { /* the cell's sums: node 00 (fx, fy), 10, 01, 11 */
            if (rn >= 0) {
                V s0 = hsum4(F[0], F[2], F[4], F[6]), s1 = hsum4(F[1], F[3], F[5], F[7]);
                add4(g->fx, (size_t)rn, nx, s0);
                add4(g->fy, (size_t)rn, nx, s1);
            }
            for (int c = 0; c < 8; c++) F[c] = _mm256_setzero_pd();
            rn = n;
            runs++;
        }
        __m256i km = kmask(k);
        size_t a = (size_t)n, b = a + 1, c = a + (size_t)nx, d = c + 1;
        V wx0 = _mm256_sub_pd(one, fx), wy0 = _mm256_sub_pd(one, fy);
        V u00 = _mm256_set1_pd(qx[a] * mi[a]), u10 = _mm256_set1_pd(qx[b] * mi[b]),
          u01 = _mm256_set1_pd(qx[c] * mi[c]), u11 = _mm256_set1_pd(qx[d] * mi[d]);
        V v00 = _mm256_set1_pd(qy[a] * mi[a]), v10 = _mm256_set1_pd(qy[b] * mi[b]),
          v01 = _mm256_set1_pd(qy[c] * mi[c]), v11 = _mm256_set1_pd(qy[d] * mi[d]);
        /* strain increments: the velocity gradient's differences of the corners */
        V exx = _mm256_mul_pd(ihdt, _mm256_fmadd_pd(wy0, _mm256_sub_pd(u10, u00),
                                                    _mm256_mul_pd(fy, _mm256_sub_pd(u11, u01))));
        V eyy = _mm256_mul_pd(ihdt, _mm256_fmadd_pd(wx0, _mm256_sub_pd(v01, v00),
                                                    _mm256_mul_pd(fx, _mm256_sub_pd(v11, v10))));
        V dudy = _mm256_fmadd_pd(wx0, _mm256_sub_pd(u01, u00),
                                 _mm256_mul_pd(fx, _mm256_sub_pd(u11, u10)));
        V dvdx = _mm256_fmadd_pd(wy0, _mm256_sub_pd(v10, v00),
                                 _mm256_mul_pd(fy, _mm256_sub_pd(v11, v01)));
        V exy = _mm256_mul_pd(hihdt, _mm256_add_pd(dudy, dvdx));
        V tr = _mm256_add_pd(exx, eyy), lt = _mm256_mul_pd(la, tr);
        V sxx0 = _mm256_loadu_pd(P->sxx + p), syy0 = _mm256_loadu_pd(P->syy + p),
          sxy0 = _mm256_loadu_pd(P->sxy + p), vol0 = _mm256_loadu_pd(P->vol + p);
        V sxx = _mm256_add_pd(sxx0, _mm256_fmadd_pd(m2, exx, lt));
        V syy = _mm256_add_pd(syy0, _mm256_fmadd_pd(m2, eyy, lt));
        V sxy = _mm256_fmadd_pd(m2, exy, sxy0);
        V vol = _mm256_mul_pd(vol0, _mm256_add_pd(one, tr));
        store_run(P->sxx + p, km, sxx, sxx0);
        store_run(P->syy + p, km, syy, syy0);
        store_run(P->sxy + p, km, sxy, sxy0);
        store_run(P->vol + p, km, vol, vol0);
        /* f_I -= V sigma grad S_I; grad S_x = (-wy0, wy0, -fy, fy) / h,
         * grad S_y = (-wx0, -fx, wx0, fx) / h; lanes past the run add 0 */
        V s = _mm256_and_pd(_mm256_mul_pd(vol, ih), _mm256_castsi256_pd(km));
        V gx0 = _mm256_mul_pd(wy0, s), gx1 = _mm256_mul_pd(fy, s), gy0 = _mm256_mul_pd(wx0, s),
          gy1 = _mm256_mul_pd(fx, s);
        V A = _mm256_mul_pd(sxx, gx0), B = _mm256_mul_pd(sxy, gx0), C = _mm256_mul_pd(sxx, gx1),
          D = _mm256_mul_pd(sxy, gx1);
        F[0] = _mm256_add_pd(F[0], _mm256_fmadd_pd(sxy, gy0, A));
        F[1] = _mm256_add_pd(F[1], _mm256_fmadd_pd(syy, gy0, B));
        F[2] = _mm256_add_pd(F[2], _mm256_fmsub_pd(sxy, gy1, A));
        F[3] = _mm256_add_pd(F[3], _mm256_fmsub_pd(syy, gy1, B));
        F[4] = _mm256_add_pd(F[4], _mm256_fnmadd_pd(sxy, gy0, C));
        F[5] = _mm256_add_pd(F[5], _mm256_fnmadd_pd(syy, gy0, D));
        F[6] = _mm256_sub_pd(F[6], _mm256_fmadd_pd(sxy, gy1, C));
        F[7] = _mm256_sub_pd(F[7], _mm256_fmadd_pd(syy, gy1, D));
        p += k;
    }
    if (rn >= 0) {
        add4(g->fx, (size_t)rn, nx, hsum4(F[0], F[2], F[4], F[6]));
        add4(g->fy, (size_t)rn, nx, hsum4(F[1], F[3], F[5], F[7]));
    }
    return runs;
}

/* S v of a field at the corners of cell n, four lanes */
static inline V interp(V wx0, V fx, V wy0, V fy, const double *restrict u, size_t n, int nx)
{
    size_t n2 = n + (size_t)nx;
    V r0 = _mm256_fmadd_pd(wx0, _mm256_set1_pd(u[n]), _mm256_mul_pd(fx, _mm256_set1_pd(u[n + 1])));
    V r1 =
        _mm256_fmadd_pd(wx0, _mm256_set1_pd(u[n2]), _mm256_mul_pd(fx, _mm256_set1_pd(u[n2 + 1])));
    return _mm256_fmadd_pd(wy0, r0, _mm256_mul_pd(fy, r1));
}

static void flush_mq(cl_grid *g, long rn, const V M[12])
{
    if (rn < 0) return;
    add4(g->nm, (size_t)rn, g->nx, hsum4(M[0], M[1], M[2], M[3]));
    add4(g->nqx, (size_t)rn, g->nx, hsum4(M[4], M[5], M[6], M[7]));
    add4(g->nqy, (size_t)rn, g->nx, hsum4(M[8], M[9], M[10], M[11]));
    cl_extent(g, (size_t)rn);
}

static size_t mv4(cl_parts *P, cl_grid *g)
{
    const int nx = g->nx;
    const V ih = _mm256_set1_pd(g->ih), dt = _mm256_set1_pd(g->dt), one = _mm256_set1_pd(1.0);
    V M[12];
    for (int c = 0; c < 12; c++) M[c] = _mm256_setzero_pd();
    long rn = -1;
    size_t runs = 0, last = SIZE_MAX; /* runs: changes of cell, as the portable kernel counts */
    for (size_t p = 0; p < P->n;) {
        V fx, fy, x0 = _mm256_loadu_pd(P->x + p), y0 = _mm256_loadu_pd(P->y + p);
        __m128i n4 = cells4(x0, y0, ih, nx, &fx, &fy);
        unsigned k = run4(n4, P->n - p);
        size_t n = (size_t)_mm_cvtsi128_si32(n4);
        __m256i km = kmask(k);
        runs += n != last;
        last = n;
        V wx0 = _mm256_sub_pd(one, fx), wy0 = _mm256_sub_pd(one, fy);
        /* x += dt S v_I, v += dt S a_I (the node pass left velocities and accelerations) */
        V vx0 = _mm256_loadu_pd(P->vx + p), vy0 = _mm256_loadu_pd(P->vy + p);
        V x = _mm256_fmadd_pd(dt, interp(wx0, fx, wy0, fy, g->qx, n, nx), x0);
        V y = _mm256_fmadd_pd(dt, interp(wx0, fx, wy0, fy, g->qy, n, nx), y0);
        V vx = _mm256_fmadd_pd(dt, interp(wx0, fx, wy0, fy, g->fx, n, nx), vx0);
        V vy = _mm256_fmadd_pd(dt, interp(wx0, fx, wy0, fy, g->fy, n, nx), vy0);
        store_run(P->x + p, km, x, x0);
        store_run(P->y + p, km, y, y0);
        store_run(P->vx + p, km, vx, vx0);
        store_run(P->vy + p, km, vy, vy0);
        /* the next step's mass and momentum, from the new cells */
        __m128i m4 = cells4(x, y, ih, nx, &fx, &fy);
        V mp = _mm256_and_pd(_mm256_loadu_pd(P->m + p), _mm256_castsi256_pd(km));
        V px = _mm256_mul_pd(mp, vx), py = _mm256_mul_pd(mp, vy);
        wx0 = _mm256_sub_pd(one, fx);
        wy0 = _mm256_sub_pd(one, fy);
        V w[4] = {_mm256_mul_pd(wx0, wy0), _mm256_mul_pd(fx, wy0), _mm256_mul_pd(wx0, fy),
                  _mm256_mul_pd(fx, fy)};
        if (run4(m4, k) == k) { /* one new cell: into the run's sums */
            long nn = _mm_cvtsi128_si32(m4);
            if (nn != rn) {
                flush_mq(g, rn, M);
                for (int c = 0; c < 12; c++) M[c] = _mm256_setzero_pd();
                rn = nn;
            }
            for (int c = 0; c < 4; c++) {
                M[c] = _mm256_fmadd_pd(w[c], mp, M[c]);
                M[4 + c] = _mm256_fmadd_pd(w[c], px, M[4 + c]);
                M[8 + c] = _mm256_fmadd_pd(w[c], py, M[8 + c]);
            }
        } else { /* the lanes in different cells: one by one into the grid */
            int cell[4];
            _mm_storeu_si128((__m128i *)cell, m4);
            for (unsigned l = 0; l < k; l++) {
                size_t q = (size_t)cell[l];
                V W = {w[0][l], w[1][l], w[2][l], w[3][l]};
                add4(g->nm, q, nx, _mm256_mul_pd(W, _mm256_set1_pd(mp[l])));
                add4(g->nqx, q, nx, _mm256_mul_pd(W, _mm256_set1_pd(px[l])));
                add4(g->nqy, q, nx, _mm256_mul_pd(W, _mm256_set1_pd(py[l])));
                cl_extent(g, q);
            }
        }
        p += k;
    }
    flush_mq(g, rn, M);
    return runs;
}

static const cl_kernels avx2 = {"avx2-fma four lanes", sf4, mv4};

const cl_kernels *cl_kernels_avx2(void)
{
    return &avx2;
}

#else
const cl_kernels *cl_kernels_avx2(void)
{
    return NULL;
}
#endif
