/*
 * t_cpdi.c - CPDI1 (mpm_cpdi.c) and the deformation gradient F.
 *
 * The weights at random centres and random F (shear and stretch up to a
 * domain a few cells wide): partition of unity, gradient sum, linear
 * precision, and the 2D gradients against the paper's formula; a single
 * particle's transfer to the grid; F after a step in a uniform velocity
 * gradient; momentum of a free deforming body under every update scheme
 * and the PIC/FLIP blend; the active rows under strong stretch (no mass
 * lost or left behind, two threads); a bar hanging under gravity that
 * stretches its top particles over more than a cell, with a stress-noise
 * metric against MPM and GIMP; and the errors.  (The rigid translation
 * with crossing, sigma/E <= 1e-12, is in t_phantom.c, and the step's
 * in-pass energies in t_perf.c, both for CPDI too.)  Two threads are
 * bitwise reproducible.
 */
#include "mpm.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_rows.h"
#include "mpm_team.h"
#include "t.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static uint64_t rng = 0x2545F4914F6CDD1Dull;
static double urand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) / 9007199254740992.0;
}

static double det3(const double F[9], int D)
{
    if (D == 1) return F[0];
    if (D == 2) return F[0] * F[4] - F[1] * F[3];
    return F[0] * (F[4] * F[8] - F[7] * F[5]) - F[1] * (F[3] * F[8] - F[6] * F[5]) +
           F[2] * (F[3] * F[7] - F[6] * F[4]);
}

/* a random F with det F > 0.2: diagonal in [0.4, 3], shears in [-1.2, 1.2] */
static void random_F(double F[9], int D)
{
    do {
        for (int i = 0; i < 9; i++) F[i] = 0;
        for (int i = 0; i < D; i++)
            for (int j = 0; j < D; j++)
                F[3 * i + j] = i == j ? 0.4 + 2.6 * urand() : -1.2 + 2.4 * urand();
    } while (!(det3(F, D) > 0.2));
}

static double tent(double s)
{
    double a = 1.0 - fabs(s);
    return a > 0 ? a : 0;
}

TEST(cpdi_partition_of_unity_and_linear_precision)
{
    const double h[3] = {0.1, 0.25, 0.07};
    double wS = 0, wG = 0, wI = 0, wX = 0, wP = 0;
    int trials = 0;
    for (int D = 1; D <= 3; D++) {
        mpm_grid_desc g = {D, {-0.3, 0.2, 0.1}, {h[0], h[1], h[2]}, {80, 80, 80}};
        for (int t = 0; t < 3000; t++) {
            double x[3] = {0, 0, 0}, F[9], lp[3] = {0, 0, 0};
            random_F(F, D);
            for (int d = 0; d < D; d++) {
                x[d] = g.origin[d] + (20 + 40 * urand()) * h[d];
                lp[d] = h[d] * (0.05 + 0.45 * urand());
            }
            int ijk[64][3];
            double S[64], G[64][3];
            int n = mpm_cpdi_shape(&g, x, F, lp, ijk, S, G);
            CHECK(n == 1 << (2 * D));
            double sum = 0, gs[3] = {0, 0, 0}, gx[3][3] = {{0}}, sx[3] = {0, 0, 0};
            for (int k = 0; k < n; k++) {
                sum += S[k];
                for (int a = 0; a < D; a++) {
                    double xa = g.origin[a] + ijk[k][a] * h[a];
                    gs[a] += G[k][a];
                    sx[a] += S[k] * xa;
                    for (int b = 0; b < D; b++) gx[b][a] += G[k][b] * xa;
                }
            }
            wS = fmax(wS, fabs(sum - 1));
            for (int a = 0; a < D; a++) {
                wG = fmax(wG, fabs(gs[a]) * h[a]);
                wX = fmax(wX, fabs(sx[a] - x[a]) / h[a]);
                for (int b = 0; b < D; b++) wI = fmax(wI, fabs(gx[b][a] - (a == b)));
            }
            if (D == 2) {
                /* the paper's CPDI1 gradient (corners 1..4 = x - r1 - r2,
                 * x + r1 - r2, x + r1 + r2, x - r1 + r2; V = 4 |r1 x r2|)
                 * summed per node against ours */
                double r1[2] = {F[0] * lp[0], F[3] * lp[0]}, r2[2] = {F[1] * lp[1], F[4] * lp[1]};
                double V = 4 * (r1[0] * r2[1] - r1[1] * r2[0]);
                double cx[4][2];
                const int s1[4] = {-1, 1, 1, -1}, s2[4] = {-1, -1, 1, 1};
                for (int c = 0; c < 4; c++)
                    for (int d = 0; d < 2; d++) cx[c][d] = x[d] + s1[c] * r1[d] + s2[c] * r2[d];
                for (int k = 0; k < n; k++) {
                    double Sn = 0, Gn[2] = {0, 0};
                    for (int j = 0; j < n; j++)
                        if (ijk[j][0] == ijk[k][0] && ijk[j][1] == ijk[k][1]) {
                            Sn += S[j];
                            Gn[0] += G[j][0];
                            Gn[1] += G[j][1];
                        }
                    double N[4];
                    for (int c = 0; c < 4; c++)
                        N[c] = tent((cx[c][0] - g.origin[0]) / h[0] - ijk[k][0]) *
                               tent((cx[c][1] - g.origin[1]) / h[1] - ijk[k][1]);
                    double Sp = 0.25 * (N[0] + N[1] + N[2] + N[3]);
                    double Gp0 =
                        ((N[0] - N[2]) * (r1[1] - r2[1]) + (N[1] - N[3]) * (r1[1] + r2[1])) / V;
                    double Gp1 =
                        ((N[0] - N[2]) * (r2[0] - r1[0]) - (N[1] - N[3]) * (r1[0] + r2[0])) / V;
                    wP = fmax(wP, fabs(Sn - Sp));
                    wP = fmax(wP, fabs(Gn[0] - Gp0) * h[0]);
                    wP = fmax(wP, fabs(Gn[1] - Gp1) * h[1]);
                }
            }
            trials++;
        }
    }
    TLOG("%d random (x, F, lp), 1D/2D/3D, F shear and stretch to 3x: max |sum S - 1| = %.1e, "
         "max |sum G| h = %.1e, max |sum G x^T - I| = %.1e, max |sum S x - x_p| / h = %.1e; "
         "2D against the paper's formula: %.1e",
         trials, wS, wG, wI, wX, wP);
    CHECK(wS <= 1e-14 && wG <= 1e-12 && wI <= 1e-11 && wX <= 1e-12 && wP <= 1e-12);
    /* a corner outside the grid, or an inverted domain, is refused */
    mpm_grid_desc g = {2, {0, 0, 0}, {0.1, 0.1, 0}, {11, 11, 0}};
    int ijk[64][3];
    double S[64], G[64][3], F[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, lp[3] = {0.05, 0.05, 0};
    CHECK(mpm_cpdi_shape(&g, (double[3]){0.04, 0.5, 0}, F, lp, ijk, S, G) == -1);
    CHECK(mpm_cpdi_shape(&g, (double[3]){0.06, 0.5, 0}, F, lp, ijk, S, G) == 16);
    F[0] = -1;
    CHECK(mpm_cpdi_shape(&g, (double[3]){0.5, 0.5, 0}, F, lp, ijk, S, G) == -1);
}

/* A case of explicit points on a lattice: n[d] points per axis at spacing
 * a starting at x0, half-width a/2, velocity v0 + L0 (x - xc). */
typedef struct {
    mpm_case c;
    mpm_body_desc b;
    mpm_material_desc mat;
    double *x, *vol, *v;
} lat_case;

static int lattice(lat_case *t, int D, const int n[3], double a, const double x0[3],
                   const double v0[3], const double L0[3][3], const double xc[3])
{
    memset(t, 0, sizeof *t);
    size_t np = (size_t)n[0] * (size_t)(D > 1 ? n[1] : 1) * (size_t)(D > 2 ? n[2] : 1);
    t->x = malloc(np * 3 * sizeof(double));
    t->v = malloc(np * 3 * sizeof(double));
    t->vol = malloc(np * sizeof(double));
    if (!t->x || !t->v || !t->vol) return -1;
    size_t p = 0;
    for (int k = 0; k < (D > 2 ? n[2] : 1); k++)
        for (int j = 0; j < (D > 1 ? n[1] : 1); j++)
            for (int i = 0; i < n[0]; i++) {
                int ijk[3] = {i, j, k};
                for (int d = 0; d < D; d++) t->x[p * D + d] = x0[d] + (ijk[d] + 0.5) * a;
                for (int d = 0; d < D; d++) {
                    double vv = v0[d];
                    for (int e = 0; e < D; e++) vv += L0[d][e] * (t->x[p * D + e] - xc[e]);
                    t->v[p * D + d] = vv;
                }
                t->vol[p] = pow(a, D);
                p++;
            }
    t->mat = (mpm_material_desc){.model = MPM_MODEL_LINEAR_ELASTIC,
                                 .youngs_modulus = 100.0,
                                 .poisson_ratio = 0.3,
                                 .density = 1.0};
    t->b.n_points = np;
    t->b.x = t->x;
    t->b.v = t->v;
    t->b.volume = t->vol;
    t->c.method = MPM_METHOD_CPDI;
    t->c.n_materials = 1;
    t->c.materials = &t->mat;
    t->c.n_bodies = 1;
    t->c.bodies = &t->b;
    return 0;
}

static void lattice_free(lat_case *t)
{
    free(t->x);
    free(t->v);
    free(t->vol);
}

/* the sums over every padded node of the main grid */
static void grid_sums(const mpm_sim *s, double *m, double q[3], double mx[3])
{
    *m = 0;
    for (int d = 0; d < 3; d++) q[d] = mx[d] = 0;
    for (size_t n = 0; n < s->nn; n++) {
        size_t rest = n;
        *m += s->g.m[n];
        for (int d = 0; d < s->dim; d++) {
            int i = (int)(rest % (size_t)s->np[d]);
            rest /= (size_t)s->np[d];
            q[d] += s->g.q[d][n];
            mx[d] += s->g.m[n] * (s->x0[d] + i * s->h[d]);
        }
    }
}

/* One particle with a sheared and stretched domain: its mass, momentum and
 * first mass moment on the grid after the transfer. */
TEST(cpdi_one_particle_p2g)
{
    for (int D = 2; D <= 3; D++) {
        lat_case t;
        const int n[3] = {1, 1, 1};
        const double L0[3][3] = {{0}}, x0[3] = {0.537, 0.4213, 0.5091}, v0[3] = {0.3, -0.2, 0.7};
        CHECK(lattice(&t, D, n, 0.1, x0, v0, L0, x0) == 0);
        t.c.grid = (mpm_grid_desc){D, {0, 0, 0}, {0.1, 0.1, 0.1}, {13, 13, 13}};
        t.c.update = MPM_USL;
        t.c.dt = 1e-4;
        mpm_error err;
        mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
        lattice_free(&t);
        CHECKF(s, "%s", TERR(&err));
        /* F: stretch 2.5, shear 1.3 (the domain spans about 4 cells) */
        const double F[3][3] = {{2.5, 1.3, 0.2}, {-0.4, 1.7, 0.5}, {0.3, -0.6, 1.4}};
        for (int i = 0; i < D; i++)
            for (int j = 0; j < D; j++) s->P.F[i * D + j][0] = F[i][j];
        mpm_team_run(s, mpm_ph_bbox);
        double mp = s->P.m[0], xp[3], vp[3];
        for (int d = 0; d < D; d++) {
            xp[d] = s->P.x[d][0];
            vp[d] = s->P.v[d][0];
        }
        CHECKF(mpm_sim_step(s) == 0, "%s", TERR(mpm_sim_error(s)));
        double m, q[3], mx[3], worst = 0;
        grid_sums(s, &m, q, mx);
        worst = fabs(m - mp) / mp;
        for (int d = 0; d < D; d++) {
            worst = fmax(worst, fabs(q[d] - mp * vp[d]) / mp);
            worst = fmax(worst, fabs(mx[d] - mp * xp[d]) / (mp * 0.1));
        }
        TLOG("%dD, one particle, F stretch 2.5 / shear 1.3: |sum m_i - m_p|, |sum q_i - m_p v_p|, "
             "|sum m_i x_i - m_p x_p| / h, relative: %.1e",
             D, worst);
        mpm_sim_destroy(&s);
        CHECK(worst <= 1e-13);
    }
}

/* In a uniform velocity gradient L0 (points on a lattice filling the grid,
 * v = L0 x), the interior points' F after one step is I + dt L0 to
 * round-off, for every update scheme: shear and stretch. */
TEST(cpdi_uniform_velocity_gradient_gives_F)
{
    static const char *const un[3] = {"USF", "USL", "MUSL"};
    double worst = 0;
    for (int D = 2; D <= 3; D++)
        for (int up = 0; up < 3; up++) {
            lat_case t;
            int cells = D == 2 ? 12 : 8;
            const int n[3] = {2 * cells, 2 * cells, 2 * cells};
            const double L0[3][3] = {{0.3, 0.8, -0.2}, {-0.25, -0.1, 0.4}, {0.15, 0.5, 0.2}};
            const double z[3] = {0, 0, 0};
            CHECK(lattice(&t, D, n, 0.05, z, z, L0, z) == 0);
            t.c.grid =
                (mpm_grid_desc){D, {0, 0, 0}, {0.1, 0.1, 0.1}, {cells + 1, cells + 1, cells + 1}};
            t.c.update = (mpm_update)up;
            t.c.dt = 1e-3;
            t.mat.youngs_modulus = 1e-6;
            mpm_error err;
            mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
            lattice_free(&t);
            CHECKF(s, "%s", TERR(&err));
            CHECKF(mpm_sim_step(s) == 0, "%s", TERR(mpm_sim_error(s)));
            int checked = 0;
            for (size_t p = 0; p < s->P.n; p++) {
                int inner = 1;
                for (int d = 0; d < D; d++) {
                    double x = s->P.x[d][p];
                    inner &= x > 0.3 && x < cells * 0.1 - 0.3;
                }
                if (!inner) continue;
                for (int i = 0; i < D; i++)
                    for (int j = 0; j < D; j++)
                        worst =
                            fmax(worst, fabs(s->P.F[i * D + j][p] - ((i == j) + 1e-3 * L0[i][j])));
                checked++;
            }
            TLOG("%dD %-4s: F = I + dt L0 at %d interior points to %.1e", D, un[up], checked,
                 worst);
            mpm_sim_destroy(&s);
            CHECK(checked > 0);
            CHECK(worst <= 1e-13);
        }
}

/* A free body (no gravity, no boundary) with a non-uniform initial
 * velocity (translation, stretch, shear, spin) deforms for 400 steps:
 * momentum conserved to round-off, the energy within a few per cent, F
 * stays invertible; every update scheme, FLIP and a PIC/FLIP blend, one
 * and two threads. */
TEST(cpdi_free_body_conserves_momentum)
{
    static const char *const un[3] = {"USF", "USL", "MUSL"};
    for (int D = 2; D <= 3; D++)
        for (int up = 0; up < 3; up++)
            for (int bl = 0; bl < 2; bl++) {
                lat_case t;
                int k = D == 2 ? 12 : 6;
                const int n[3] = {k, k, k};
                const double L0[3][3] = {{1.5, 1.0, 0.2}, {-0.5, -0.8, 0.6}, {0.3, -0.4, 0.9}};
                const double x0[3] = {0.8, 0.8, 0.8}, v0[3] = {0.4, -0.3, 0.2};
                const double xc[3] = {0.8 + 0.025 * k, 0.8 + 0.025 * k, 0.8 + 0.025 * k};
                CHECK(lattice(&t, D, n, 0.05, x0, v0, L0, xc) == 0);
                t.c.grid = (mpm_grid_desc){D, {0, 0, 0}, {0.1, 0.1, 0.1}, {25, 25, 25}};
                t.c.update = (mpm_update)up;
                t.c.pic_fraction = bl ? 0.3 : 0.0;
                t.c.threads = 1 + bl;
                t.c.cfl = 0.4;
                mpm_error err;
                mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
                lattice_free(&t);
                CHECKF(s, "%s", TERR(&err));
                mpm_energy e0, e1;
                mpm_sim_energy(s, &e0);
                int rc = mpm_sim_run(s, 400);
                CHECKF(rc == 0, "%dD %s: %s", D, un[up], TERR(mpm_sim_error(s)));
                mpm_sim_energy(s, &e1);
                double dq = 0, Fmax = 0;
                for (int d = 0; d < D; d++)
                    dq = fmax(dq, fabs(e1.momentum[d] - e0.momentum[d]) / e0.mass);
                for (size_t p = 0; s->P.F[0] && p < s->P.n; p++)
                    for (int c = 0; c < D * D; c++) Fmax = fmax(Fmax, fabs(s->P.F[c][p]));
                double de = (e1.total - e0.total) / e0.total;
                TLOG("%dD %-4s %s, %zu points, t = %.3f: |dp|/M = %.1e (v0 %.1f), "
                     "E/E0 - 1 = %+.2e, max |F_ij| = %.2f",
                     D, un[up], bl ? "PIC 0.3, 2 threads" : "FLIP, 1 thread  ", s->P.n,
                     mpm_sim_time(s), dq, v0[0], de, Fmax);
                mpm_sim_destroy(&s);
                CHECK(dq <= 1e-13);
                /* USL with FLIP loses energy here: GIMP the same, -22 % in
                 * 2D (measured; MPM USL diverges) */
                CHECK(bl || up == MPM_USL || fabs(de) <= 0.05);
                CHECK(de <= 0.01);
            }
}

/* Strong stretch and shear (v = L0 (x - xc), the body grows to about 3x
 * along x while shearing), two threads: after every step the main grid
 * holds exactly the particles' mass (nothing lost outside the row extents
 * the passes recorded, nothing stale left behind), across the sorts. */
TEST(cpdi_active_rows_follow_domains)
{
    for (int D = 2; D <= 3; D++)
        for (int T = 1; T <= 2; T++) {
            lat_case t;
            const int n[3] = {8, 8, 8};
            const double L0[3][3] = {{4.0, 2.0, 0}, {0, -0.5, 1.0}, {0, 0, 0.5}};
            const double x0[3] = {1.0, 1.0, 1.0}, v0[3] = {0, 0.5, 0};
            const double xc[3] = {1.2, 1.2, 1.2};
            CHECK(lattice(&t, D, n, 0.05, x0, v0, L0, xc) == 0);
            t.c.grid = (mpm_grid_desc){D, {0, 0, 0}, {0.1, 0.1, 0.1}, {25, 25, 25}};
            t.c.update = MPM_MUSL;
            t.c.threads = T;
            t.c.dt = 1e-3;
            t.mat.youngs_modulus = 1e-3;
            mpm_error err;
            mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
            lattice_free(&t);
            CHECKF(s, "%s", TERR(&err));
            mpm_energy e;
            mpm_sim_energy(s, &e);
            double worst = 0, fx = 0;
            int rc = 0;
            for (int k = 0; k < 500 && !rc; k++) {
                rc = mpm_sim_step(s);
                double m, q[3], mx[3];
                grid_sums(s, &m, q, mx);
                worst = fmax(worst, fabs(m - e.mass) / e.mass);
            }
            for (size_t p = 0; p < s->P.n; p++) fx = fmax(fx, s->P.F[0][p]);
            TLOG("%dD, %d thread(s), 500 steps, F_xx up to %.2f (domains %.1f cells wide): "
                 "|sum of grid mass - mass| / mass = %.1e",
                 D, T, fx, fx * 0.05 / 0.1, worst);
            CHECKF(rc == 0, "%s", TERR(mpm_sim_error(s)));
            mpm_sim_destroy(&s);
            CHECK(fx > 2.0);
            CHECK(worst <= 1e-13);
        }
}

/* Stress noise along a column: the particles of the middle column of
 * points, ordered by their initial height (creation order), give
 * sigma_yy(depth); its roughness is the RMS of the second differences,
 * over rho g H.  A smooth profile has ~ (spacing/H)^2, cell-crossing noise
 * makes it O(0.1). */
static double roughness(const double *sig, int nx, int ny, double scale)
{
    double r2 = 0;
    int i = nx / 2, k = 0;
    for (int j = 1; j < ny - 1; j++) {
        double a = sig[((j - 1) * nx + i) * 6 + 1], b = sig[(j * nx + i) * 6 + 1],
               c = sig[((j + 1) * nx + i) * 6 + 1];
        double d2 = (a - 2 * b + c) / scale;
        r2 += d2 * d2;
        k++;
    }
    return sqrt(r2 / k);
}

/* A bar hanging from the ceiling under its own weight (plane strain,
 * rollers on the sides, the top fixed, nu = 0), soft enough (rho g H / E =
 * 1) to stretch its top to F_yy ~ e = 2.7: its top points' domains grow
 * over more than a cell and its lower part crosses many cells.  The weight
 * is ramped up over two periods of the first mode (particle forces m g
 * t / t_r) and held for one more, so that the exact response is close to
 * the smooth static profile sigma_yy = rho g (depth in the reference
 * configuration).  Measured: the stress roughness along the bar, the max
 * over 30 snapshots, and whether the run stays stable. */
static int hanging_bar(mpm_method m, mpm_update up, double E, double *rough, double *fyy)
{
    const double h = 0.05, H = 1.0, g = 10.0, a = 0.5 * h;
    mpm_material_desc mat = {.model = MPM_MODEL_LINEAR_ELASTIC,
                             .youngs_modulus = E,
                             .poisson_ratio = 0.0,
                             .density = 1.0};
    mpm_body_desc b = {0};
    b.shape = MPM_SHAPE_BOX;
    b.ppc = 2;
    b.lo[0] = 0;
    b.hi[0] = 0.2;
    b.lo[1] = 2.5 - H;
    b.hi[1] = 2.5;
    mpm_case c = {0};
    c.grid = (mpm_grid_desc){2, {0, 0, 0}, {h, h, 0}, {5, 51, 0}};
    c.method = m;
    c.update = up;
    c.cfl = 0.4;
    c.bc.face_mask[0] = 1; /* rollers */
    c.bc.face_mask[1] = 1;
    c.bc.face_mask[3] = 3; /* the ceiling */
    c.n_materials = 1;
    c.materials = &mat;
    c.n_bodies = 1;
    c.bodies = &b;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    if (!s) return -1;
    size_t n = mpm_sim_particles(s);
    int nx = 8, ny = (int)(n / 8);
    double *sig = malloc(n * 6 * sizeof *sig), *f = calloc(n * 2, sizeof *f);
    double T = 4 * H / sqrt(E), tr = 2 * T, worst = 0;
    int rc = sig && f ? 0 : -1;
    *fyy = 0;
    for (int k = 1; k <= 30 && !rc; k++) {
        while (!rc && mpm_sim_time(s) < k * 3 * T / 30) {
            double ramp = fmin(mpm_sim_time(s) / tr, 1.0);
            for (size_t p = 0; p < n; p++) f[2 * p + 1] = -1.0 * a * a * g * ramp;
            rc = mpm_sim_set_particle_forces(s, f);
            if (!rc) rc = mpm_sim_step(s);
        }
        if (rc) break;
        mpm_sim_snapshot(s, &(mpm_snapshot){.stress = sig});
        worst = fmax(worst, roughness(sig, nx, ny, 1.0 * g * H));
        if (s->P.F[0])
            for (size_t p = 0; p < n; p++) *fyy = fmax(*fyy, s->P.F[3][p]);
    }
    if (rc) TLOG("%s", TERR(mpm_sim_error(s)));
    *rough = rc ? INFINITY : worst;
    free(sig);
    free(f);
    mpm_sim_destroy(&s);
    return rc;
}

/* Measured (cfl 0.4): USL, rho g H / E = 1: MPM diverges (step 192) and
 * GIMP tears the bar apart (its lower part falls out of the grid at step
 * 481), CPDI holds it with the top
 * points at F_yy = 3.0 (domains 1.5 cells tall), roughness 0.056.
 * MUSL, rho g H / E = 1/6, where all three run: roughness MPM 1.77, GIMP
 * 0.245, CPDI 0.066.  (CPDI + MUSL at rho g H / E >= 1/3 is not asserted:
 * its top point, stretched next to the fixed ceiling, oscillates (roughness
 * 0.94 at 1/3) and at 1/2 the bar tears; USL holds.) */
TEST(cpdi_hanging_bar_large_stretch_is_smooth)
{
    static const mpm_method ms[3] = {MPM_METHOD_MPM, MPM_METHOD_GIMP, MPM_METHOD_CPDI};
    static const char *const mn[3] = {"MPM", "GIMP", "CPDI"};
    static const struct {
        mpm_update up;
        double E;
        const char *what;
    } cs[2] = {{MPM_USL, 10.0, "USL,  rho g H / E = 1  "},
               {MPM_MUSL, 60.0, "MUSL, rho g H / E = 1/6"}};
    double r[2][3], f[2][3];
    int rc[2][3];
    for (int k = 0; k < 2; k++)
        for (int m = 0; m < 3; m++) {
            rc[k][m] = hanging_bar(ms[m], cs[k].up, cs[k].E, &r[k][m], &f[k][m]);
            TLOG("hanging bar, %s, %-4s: %s, stress roughness (RMS second difference of "
                 "sigma_yy along the bar / rho g H, max of 30 snapshots) %.3g%s",
                 cs[k].what, mn[m], rc[k][m] ? "FAILED" : "stable", r[k][m], m == 2 ? "" : "");
            if (m == 2)
                TLOG("  CPDI: largest F_yy %.2f (a top point's domain %.2f cells tall)", f[k][2],
                     f[k][2] * 0.5);
        }
    CHECK(rc[0][2] == 0 && f[0][2] > 2.5 && r[0][2] < 0.1);
    CHECK(rc[1][2] == 0 && rc[1][0] == 0 && r[1][2] < 0.1 * r[1][0]);
}

TEST(cpdi_errors)
{
    /* an explicit point whose domain reaches beyond the ghost cell */
    lat_case t;
    const int n[3] = {2, 2, 1};
    const double L0[3][3] = {{0}}, x0[3] = {0.2, 0.2, 0}, z[3] = {0, 0, 0};
    CHECK(lattice(&t, 2, n, 0.1, x0, z, L0, z) == 0);
    t.c.grid = (mpm_grid_desc){2, {0, 0, 0}, {0.1, 0.1, 0}, {11, 11, 0}};
    double hl[8] = {0.05, 0.05, 0.05, 0.05, 0.05, 0.9, 0.05, 0.05};
    t.b.half_length = hl;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    CHECK(!s && err.code == MPM_EINVAL);
    TLOG("%s", TERR(&err));
    CHECK(strcmp(mpm_error_field(&err, MPM_FIELD_PROTO, (char[128]){0}, 128),
                 "bodies[0].points.half_length[5]") == 0);
    hl[5] = 0.05;
    /* a stretched domain drifting towards the wall at x = 0: a corner leaves
     * the ghost cell while every centre is still inside */
    for (int i = 0; i < 4; i++) t.x[2 * i] -= 0.15;
    t.b.v = NULL;
    t.b.velocity[0] = -0.2;
    s = mpm_sim_new(&t.c, NULL, &err);
    CHECKF(s, "%s", TERR(&err));
    for (size_t p = 0; p < s->P.n; p++) s->P.F[0][p] = 2.9;
    mpm_team_run(s, mpm_ph_bbox);
    int rc = mpm_sim_run(s, 2000);
    TLOG("%s", TERR(mpm_sim_error(s)));
    CHECK(rc == MPM_ELEFTGRID);
    double xs[8] = {0};
    mpm_sim_snapshot(s, &(mpm_snapshot){.x = xs});
    CHECK(xs[0] > 0 && xs[4] > 0);
    mpm_sim_destroy(&s);
    lattice_free(&t);
}

/* The same CPDI case on two threads twice: bitwise the same positions,
 * velocities and stresses (sorting included: 200 steps). */
TEST(cpdi_two_threads_reproducible)
{
    enum { N = 12 * 12 };
    static double xa[N * 2], xb[N * 2], va[N * 2], vb[N * 2], sa[N * 6], sb[N * 6];
    double *xs[2] = {xa, xb}, *vs[2] = {va, vb}, *ss[2] = {sa, sb};
    for (int run = 0; run < 2; run++) {
        lat_case t;
        const int n[3] = {12, 12, 1};
        const double L0[3][3] = {{1.5, 1.0, 0}, {-0.5, -0.8, 0}, {0, 0, 0}};
        const double x0[3] = {0.8, 0.8, 0}, v0[3] = {0.4, -0.3, 0}, xc[3] = {1.1, 1.1, 0};
        CHECK(lattice(&t, 2, n, 0.05, x0, v0, L0, xc) == 0);
        t.c.grid = (mpm_grid_desc){2, {0, 0, 0}, {0.1, 0.1, 0}, {25, 25, 0}};
        t.c.update = MPM_MUSL;
        t.c.threads = 2;
        mpm_error err;
        mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
        lattice_free(&t);
        CHECKF(s, "%s", TERR(&err));
        CHECK(mpm_sim_particles(s) == N);
        int rc = mpm_sim_run(s, 200);
        mpm_sim_snapshot(s, &(mpm_snapshot){.x = xs[run], .v = vs[run], .stress = ss[run]});
        mpm_sim_destroy(&s);
        CHECK(rc == 0);
    }
    CHECK(memcmp(xa, xb, sizeof xa) == 0);
    CHECK(memcmp(va, vb, sizeof va) == 0);
    CHECK(memcmp(sa, sb, sizeof sa) == 0);
}
