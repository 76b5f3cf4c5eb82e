/*
 * t_triaxial.c - Drucker-Prager and Mohr-Coulomb through the solver
 * (docs/accuracy.md): a single-element drained triaxial
 * compression in 3D and a plane-strain biaxial compression in 2D.  One
 * grid cell [0, 1]^dim (MPM tents, MUSL), 2^dim particles at the quarter
 * points, rollers on the low faces, the top face (the high face of the
 * last axis, "axial") driven down by a prescribed velocity with a RAMP
 * time function, the other high faces loaded by a constant confining
 * traction, and the particles starting at the isotropic stress -p0 with
 * which that traction is in equilibrium (a tent gives a particle at 3/4
 * of the cell 3/4 of its force on the face nodes, so the traction is
 * p0 / 0.75).  Quasi-static: the loading time is about 600 periods of the
 * element.  Checked: the peak deviatoric stress q = sigma_lat - sigma_ax
 * against Mohr-Coulomb's failure stress at the measured lateral stress
 * (compression positive sigma_1 = sigma_3 N + 2 c sqrt(N), N = (1 + sin
 * phi) / (1 - sin phi); DP matched at the compression corners in 3D, in
 * plane strain in 2D, where its failure stress is MC's) and at the
 * nominal confinement p0; the volumetric strain rate in the plastic flow
 * against the dilatancy, d eps_v / d(-eps_ax) = 2 sin psi / (1 - sin psi)
 * (both models, both tests: the flow rules' ratio at failure); and the
 * energy balance, work of the prescribed velocity and the tractions =
 * change of the stored elastic energy + plastic work + kinetic energy.
 * The substep counts of the runs are logged.
 */
#include "mpm.h"
#include "mpm_internal.h"
#include "t.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    double q_peak;    /* the largest q over the run (particle mean) */
    double s3_peak;   /* the lateral stress then (compression positive) */
    double q_end;     /* q at the end */
    double q_y, s3_y; /* q and the lateral stress when every particle first yielded */
    double s3;        /* the lateral stress at the end */
    double dil;       /* d eps_v^p / d(-eps_ax^p) over the last quarter of the run */
    double dil_tot;   /* the same of the total strains */
    double ein, edu;  /* work input; change of stored + plastic + kinetic */
    double kin;       /* kinetic energy at the end */
    double ax_end;    /* -eps_ax at the end */
    mpm_plastic_stats st;
} triax_res;

/* The run: material m, dimension dim, confinement p0, axial strain rate
 * v (the top's speed; cell size 1) for time t_end, ramped over t_ramp. */
static int triax_run(const mpm_material_desc *m, int dim, double p0, double v, double t_ramp,
                     double t_end, int threads, int poison, mpm_error *fail, triax_res *r)
{
    int np = 1 << dim, ax = dim - 1;
    double x[8 * 3], vol[8], sig[8 * 6];
    for (int p = 0; p < np; p++) {
        vol[p] = 1.0 / np;
        for (int d = 0; d < dim; d++) x[p * dim + d] = (p >> d) & 1 ? 0.75 : 0.25;
        for (int c = 0; c < 6; c++) sig[p * 6 + c] = c < 3 ? -p0 : 0.0;
    }
    mpm_body_desc b = {0};
    b.n_points = (size_t)np;
    b.x = x;
    b.volume = vol;
    b.stress = sig;
    mpm_timefn ramp = {MPM_TF_RAMP, 1.0, 0.0, t_ramp, 0, NULL, NULL};
    mpm_prescribed_desc pr = {0};
    pr.face = 2 * ax + 1;
    pr.mask = 1u << ax;
    pr.value[ax] = -v;
    pr.time_function = &ramp;
    mpm_traction_desc tr[2];
    memset(tr, 0, sizeof tr);
    for (int d = 0; d < ax; d++) {
        for (int e = 0; e < dim; e++) tr[d].hi[e] = 1.0;
        tr[d].lo[d] = 0.5;
        tr[d].normal = d;
        tr[d].value[d] = -p0 / 0.75;
    }
    mpm_case c = {0};
    c.grid.dim = dim;
    for (int d = 0; d < dim; d++) {
        c.grid.h[d] = 1.0;
        c.grid.nodes[d] = 2;
        c.bc.face_mask[2 * d] = 1u << d; /* rollers on the low faces */
    }
    c.method = MPM_METHOD_MPM;
    c.update = MPM_MUSL;
    c.n_materials = 1;
    c.materials = m;
    c.n_bodies = 1;
    c.bodies = &b;
    c.n_tractions = (size_t)ax;
    c.tractions = tr;
    c.n_prescribed = 1;
    c.prescribed = &pr;
    c.threads = threads;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&c, NULL, &err);
    if (!s) {
        TLOG("%s", TERR(&err));
        return -1;
    }
    memset(r, 0, sizeof *r);
    mpm_energy e0, e;
    mpm_sim_energy(s, &e0);
    double qmax = -HUGE_VAL, q = 0, ev_a = 0, ea_a = 0, pv_a = 0, pa_a = 0;
    const mpm_mat_params *mp = &s->mats[0];
    int mark = 0;
    const mpm_particles *P = &s->P;
    if (poison) s->P.sig[0][3] = NAN; /* a non-finite stress, for the failure path */
    while (mpm_sim_time(s) < t_end) {
        if (mpm_sim_step(s)) {
            TLOG("%s", TERR(mpm_sim_error(s)));
            if (fail) *fail = *mpm_sim_error(s);
            mpm_sim_plastic_stats(s, &r->st);
            mpm_sim_destroy(&s);
            return -1;
        }
        /* means over the particles; the plastic strains are the strain
         * record less the elastic strains of the stress (plane strain:
         * sigma_zz's too) */
        double slat = 0, sax = 0, ev = 0, ea = 0, pv = 0, pa = 0;
        for (int p = 0; p < np; p++) {
            double ts = P->sig[0][p] + P->sig[1][p] + P->sig[2][p];
            for (int d = 0; d < ax; d++) slat -= P->sig[d][p] / (ax * np);
            sax -= P->sig[ax][p] / np;
            for (int d = 0; d < dim; d++) {
                double el = (P->sig[d][p] - mp->nu * (ts - P->sig[d][p])) / mp->E;
                ev += P->eps[d][p] / np;
                pv += (P->eps[d][p] - el) / np;
                if (d == ax) pa -= (P->eps[d][p] - el) / np;
            }
            ea -= P->eps[ax][p] / np;
        }
        q = sax - slat;
        int ny = 0;
        for (int p = 0; p < np; p++) ny += P->yld[p] == 1.0;
        if (ny == np && r->q_y == 0) {
            r->q_y = q;
            r->s3_y = slat;
        }
        if (q > qmax) {
            qmax = q;
            r->s3_peak = slat;
        }
        r->s3 = slat;
        if (!mark && mpm_sim_time(s) >= 0.75 * t_end) {
            mark = 1;
            ev_a = ev;
            ea_a = ea;
            pv_a = pv;
            pa_a = pa;
        }
        r->dil = (pv - pv_a) / (pa - pa_a);
        r->dil_tot = (ev - ev_a) / (ea - ea_a);
        r->ax_end = ea;
    }
    mpm_sim_energy(s, &e);
    r->q_peak = qmax;
    r->q_end = q;
    r->ein = e.prescribed_work + e.external_work - (e0.prescribed_work + e0.external_work);
    r->edu = (e.strain - e0.strain) + e.plastic_work + e.kinetic - e0.kinetic;
    r->kin = e.kinetic;
    mpm_sim_plastic_stats(s, &r->st);
    mpm_sim_destroy(&s);
    return 0;
}

static int triax(const mpm_material_desc *m, int dim, double p0, double v, double t_ramp,
                 double t_end, triax_res *r)
{
    return triax_run(m, dim, p0, v, t_ramp, t_end, 1, 0, NULL, r);
}

/* Mohr-Coulomb's failure deviator at the lateral stress s3 (compression
 * positive): sigma_1 - sigma_3 = s3 (N - 1) + 2 c sqrt(N). */
static double mc_q(double phi_deg, double c, double s3)
{
    double sp = sin(phi_deg * acos(-1.0) / 180.0), N = (1 + sp) / (1 - sp);
    return s3 * (N - 1) + 2 * c * sqrt(N);
}

static double dil_ratio(double psi_deg)
{
    double sp = sin(psi_deg * acos(-1.0) / 180.0);
    return 2 * sp / (1 - sp);
}

/* E = 1e4, nu = 0.3, rho = 1, phi = 30, c = 2; p0 = 10 (failure at an
 * axial strain of about 0.3 %), loaded at 1e-3 per unit time (ramped over
 * 2) to 3 % (3D) or 5 % (2D: DP's sigma_zz reaches its failure value
 * asymptotically).  The lateral stress drifts from p0 with the lateral
 * strain (the tent's share of the traction, x_p / h, grows as the
 * particles move out: +1.6 % in 3D, +5 % in 2D), so q is checked at the
 * measured lateral stress (tolerance 1e-3) and against p0's within 6 %;
 * when the whole element first yields (axial strain about 0.3 %, the
 * drift still small) q is checked against p0's within 0.5 % (not DP in
 * plane strain, which first yields below its plane-strain failure
 * deviator: 16-19 % here). */
static void run_set(int dim, const char *name, mpm_model_kind kind, mpm_mc_match match, double psi)
{
    const double phi = 30, coh = 2, p0 = 10, v = 1e-3;
    double t_end = dim == 3 ? 30.0 : 50.0;
    mpm_material_desc m = {.model = kind,
                           .youngs_modulus = 1e4,
                           .poisson_ratio = 0.3,
                           .density = 1.0,
                           .friction_angle = phi,
                           .dilatancy_angle = psi,
                           .cohesion = coh,
                           .tension_cutoff = HUGE_VAL,
                           .mc_match = match};
    triax_res r;
    CHECK(triax(&m, dim, p0, v, 2.0, t_end, &r) == 0);
    double qa = mc_q(phi, coh, r.s3_peak), qe = mc_q(phi, coh, r.s3), qn = mc_q(phi, coh, p0);
    double da = dil_ratio(psi);
    double eq = fabs(r.q_peak - qa) / qa, eqn = fabs(r.q_peak - qn) / qn;
    double eqy = fabs(r.q_y - qn) / qn;
    double eqe = fabs(r.q_end - qe) / qe, ed = fabs(r.dil - da), ebal = fabs(r.ein - r.edu) / r.ein;
    TLOG("%s psi %2g: q peak %.6g (MC at its sigma3 %.6g: %.6g, err %.2e), end %.6g (err %.2e; "
         "tol 1e-3), vs p0's %.6g: %.2e (tol 6e-2); at first yield q %.6g (sigma3 %.6g) vs p0's: "
         "%.2e (tol 5e-3); plastic dilatancy %.6f vs %.6f: %.1e (tol "
         "2e-3; total strains %.6f); energy in %.6g, stored+plastic+kinetic %.6g: %.2e (tol "
         "5e-3), kinetic/in %.1e; %lld plastic updates, %lld substeps (%.2f each, max %d)",
         name, psi, r.q_peak, r.s3_peak, qa, eq, r.q_end, eqe, qn, eqn, r.q_y, r.s3_y, eqy, r.dil,
         da, ed, r.dil_tot, r.ein, r.edu, ebal, r.kin / r.ein, r.st.updates, r.st.substeps,
         r.st.updates ? (double)r.st.substeps / (double)r.st.updates : 0.0, r.st.max_substeps);
    CHECK_LT(eq, 1e-3);
    CHECK_LT(eqe, 1e-3);
    CHECK_LT(eqn, 6e-2);
    /* DP in plane strain first yields below the failure deviator and
     * reaches it as sigma_zz moves to its failure value */
    if (kind == MPM_MODEL_MOHR_COULOMB || dim == 3) CHECK_LT(eqy, 5e-3);
    CHECK_LT(ed, 2e-3);
    CHECK_LT(ebal, 5e-3);
    CHECK_LT(r.kin / r.ein, 1e-4);
    CHECK(r.st.updates > 0 && r.st.substeps >= r.st.updates);
}

TEST(mpm_triaxial_3d_mc)
{
    run_set(3, "3D MC", MPM_MODEL_MOHR_COULOMB, MPM_MC_COMPRESSION, 0);
    run_set(3, "3D MC", MPM_MODEL_MOHR_COULOMB, MPM_MC_COMPRESSION, 10);
}

TEST(mpm_triaxial_3d_dp)
{
    run_set(3, "3D DP", MPM_MODEL_DRUCKER_PRAGER, MPM_MC_COMPRESSION, 0);
    run_set(3, "3D DP", MPM_MODEL_DRUCKER_PRAGER, MPM_MC_COMPRESSION, 10);
}

TEST(mpm_biaxial_2d)
{
    run_set(2, "2D MC", MPM_MODEL_MOHR_COULOMB, MPM_MC_COMPRESSION, 0);
    run_set(2, "2D MC", MPM_MODEL_MOHR_COULOMB, MPM_MC_COMPRESSION, 10);
    run_set(2, "2D DP", MPM_MODEL_DRUCKER_PRAGER, MPM_MC_PLANE_STRAIN, 0);
    run_set(2, "2D DP", MPM_MODEL_DRUCKER_PRAGER, MPM_MC_PLANE_STRAIN, 10);
}

/* Two threads (4 particles each in 3D): the substep counters are summed in
 * thread order and equal the serial run's; the stress and energies agree
 * to 1e-12 (the grid's scatter sums in another order). */
TEST(mpm_triaxial_threads)
{
    mpm_material_desc m = {.model = MPM_MODEL_DRUCKER_PRAGER,
                           .youngs_modulus = 1e4,
                           .poisson_ratio = 0.3,
                           .density = 1.0,
                           .friction_angle = 30,
                           .dilatancy_angle = 10,
                           .cohesion = 2,
                           .tension_cutoff = HUGE_VAL,
                           .substep_tolerance = 1e-6};
    triax_res r1, r2;
    CHECK(triax_run(&m, 3, 10, 1e-2, 0.2, 3.0, 1, 0, NULL, &r1) == 0);
    CHECK(triax_run(&m, 3, 10, 1e-2, 0.2, 3.0, 2, 0, NULL, &r2) == 0);
    TLOG("1 thread: %lld updates, %lld substeps, max %d, q %.17g, plastic+stored %.17g; 2 "
         "threads: %lld, %lld, %d, %.17g, %.17g",
         r1.st.updates, r1.st.substeps, r1.st.max_substeps, r1.q_end, r1.edu, r2.st.updates,
         r2.st.substeps, r2.st.max_substeps, r2.q_end, r2.edu);
    CHECK(r1.st.updates == r2.st.updates && r1.st.substeps == r2.st.substeps &&
          r1.st.max_substeps == r2.st.max_substeps);
    CHECK_NEAR(r1.q_end, r2.q_end, 1e-12 * r1.q_end);
    CHECK_NEAR(r1.edu, r2.edu, 1e-12 * r1.edu);
}

/* A stress-point update that fails (here a non-finite stress put into
 * particle 3, whose forces reach every particle's strain) fails the run
 * with MPM_EDIVERGED naming the particle and the material, for both
 * models.  (Exhausting DP's substeps needs an increment
 * of about a thousand yield strains, which the CFL step does not give.) */
TEST(mpm_triaxial_update_fails)
{
    mpm_material_desc m = {.model = MPM_MODEL_DRUCKER_PRAGER,
                           .youngs_modulus = 1e4,
                           .poisson_ratio = 0.3,
                           .density = 1.0,
                           .friction_angle = 30,
                           .dilatancy_angle = 10,
                           .cohesion = 2,
                           .tension_cutoff = HUGE_VAL,
                           .substep_tolerance = 1e-9};
    for (int k = 0; k < 2; k++) {
        triax_res r;
        mpm_error e = {0};
        m.model = k ? MPM_MODEL_MOHR_COULOMB : MPM_MODEL_DRUCKER_PRAGER;
        int rc = triax_run(&m, 3, 10, 1e-1, 0.02, 1.0, 1, 1, &e, &r);
        TLOG("%s", e.message);
        CHECKF(rc == -1 && e.code == MPM_EDIVERGED &&
                   strstr(e.message, k ? "MOHR_COULOMB update of particle "
                                       : "DRUCKER_PRAGER update of particle ") &&
                   strstr(e.message, " (materials[0]) failed"),
               "%d %s", rc, e.message);
    }
}
