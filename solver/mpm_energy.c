/*
 * mpm_energy.c - the energy sums and the divergence guard.
 *
 * The energies are summed per thread over its slice of the particles and
 * combined in thread order, so they are reproducible for a given thread
 * count; the guard compares them with what the initial state and the loads
 * can supply.
 */
#include "mpm_energy.h"
#include "mpm_internal.h"
#include "mpm_model.h"
#include "mpm_pass.h"
#include "mpm_team.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* The divergence guard.  A blow-up need not produce a NaN: an unstable
 * scheme (USL above C = 0.5, MPM when points cross cells) can multiply the
 * energy by 1e4 and still finish.  Every MPM_GUARD_EVERY steps the kinetic
 * plus strain energy is compared with what the loads can have supplied,
 * E0 + 2 U0 (U0: the energy stored by an initial stress, see
 * mpm_initial_stress_energy()) + (the loads' work, summed as |f . dx|) -
 * (change of gravity's potential) + |the prescribed velocities' work|
 * (dissipation only lowers what is there, so it is left out: a bound, not
 * the balance); it never
 * exceeds that in the continuum, and the discrete schemes stay within a few
 * per cent of it on every problem of the stress suite (make stress), the
 * worst +29 % (MPM USF, one particle per cell).  Twice the available energy
 * is a blow-up, recorded as MPM_EDIVERGED.  Cost: the step that ends every
 * MPM_GUARD_EVERY steps sums its energies in its own particle passes
 * (mpm_sim_step(), as for mpm_sim_want_energy(): the same sums), and a
 * pass over the particles whenever the largest particle speed (known
 * every step) has doubled its square since the last check, so a fast
 * blow-up is caught within a step or two; mpm_sim_check() runs it on
 * demand (at the end of a run). */
#define MPM_GUARD_FACTOR 2.0

/* The energy sums of thread tid's slice, in blocks: the kinematic terms
 * and the strain energy with the in-pass sums' functions (mpm_pass.h,
 * esum_block() and esum_strain(): four particles at a time in 2D and 3D),
 * each sum taken particle after particle in the slice's order.  A step
 * that asked for its energies (mpm_sim_want_energy()) makes the same sums
 * inside its passes, and the guard then uses those; the partial sums are
 * added in thread order, so the result is reproducible for a given thread
 * count (and with one thread equals the serial mpm_sim_energy()'s). */
INLINE void energy_blocks(mpm_sim *s, esum *e, size_t a, size_t b, int D, int AP, int ANG)
{
    for (size_t b0 = a; b0 < b; b0 += MPM_BLOCK) {
        size_t b1 = b - b0 < MPM_BLOCK ? b : b0 + MPM_BLOCK;
        esum_strain(s, e, b0, b1 - b0, D);
        esum_block(s, e, b0, b1, D, AP, ANG);
    }
}

/* the dimension and the angular momentum's terms chosen once per slice */
#define ENERGY_BLOCKS(D)                         \
    do {                                         \
        if (ang && apic)                         \
            energy_blocks(s, &e, a, b, D, 1, 1); \
        else if (ang)                            \
            energy_blocks(s, &e, a, b, D, 0, 1); \
        else                                     \
            energy_blocks(s, &e, a, b, D, 0, 0); \
    } while (0)

static void energy_slice(mpm_sim *s, int tid, int ang)
{
    int apic = s->transfer == MPM_TRANSFER_APIC;
    size_t a, b;
    mpm_particle_slice(s, tid, &a, &b);
    esum e;
    esum_init(s, &e);
    if (s->dim == 1)
        ENERGY_BLOCKS(1);
    else if (s->dim == 2)
        ENERGY_BLOCKS(2);
    else
        ENERGY_BLOCKS(3);
    esum_store(&e, &s->tout[tid], 1, 1);
}

void mpm_ph_energy(mpm_sim *s, int tid)
{
    energy_slice(s, tid, 1);
}

/* The guard's own pass: the same sums without the angular momentum, which
 * the guard does not read (a step's guard costs nothing more for it). */
static void ph_guard_energy(mpm_sim *s, int tid)
{
    energy_slice(s, tid, 0);
}

/* The partial sums in tout combined in thread order (external work and
 * total left out). */
void mpm_energy_sum(const mpm_sim *s, mpm_energy *e)
{
    memset(e, 0, sizeof *e);
    for (int t = 0; t < s->nthreads; t++) {
        const mpm_thread_out *o = &s->tout[t];
        e->kinetic += o->ekin;
        e->strain += o->estr;
        e->potential += o->epot;
        e->mass += o->emass;
        for (int d = 0; d < s->dim; d++) e->momentum[d] += o->emom[d];
        for (int d = 0; d < 3; d++) e->angular_momentum[d] += o->eang[d];
    }
}

int mpm_guard(mpm_sim *s)
{
    mpm_energy e;
    if (s->ecache_ok) { /* summed by the step just taken: the same sums */
        e = s->ecache;
    } else {
        mpm_team_run(s, ph_guard_energy);
        mpm_energy_sum(s, &e);
    }
    mpm_energy_finish(s, &e);
    double have = e.kinetic + fabs(e.strain); /* a blow-up can drive 1/2 sigma:eps negative */
    s->guard_v2 = s->vmax * s->vmax;
    /* the loads' work counted as its absolute value: a bound that holds
     * however a coarse solution mis-integrates a force that does work
     * back and forth (the manufactured solutions do) */
    double avail = s->e_total0 - e.potential + s->external_work_abs + s->prescribed_work_abs;
    if (isfinite(have) && have <= MPM_GUARD_FACTOR * fmax(avail, 0) + s->e_floor) return 0;
    mpm_fail(&s->err, MPM_EDIVERGED, NULL,
             "diverged at step %ld, time %.9g: kinetic + strain energy %.6g is more than %g "
             "times the energy the initial state and the loads supply (%.6g)",
             s->steps, s->t, have, MPM_GUARD_FACTOR, avail);
    s->failed = MPM_EDIVERGED;
    return s->failed;
}

/* The energy balance (docs/solver.md, "Energy balance"):
 *   total = K + S + P - W_ext - W_prescribed + D_plastic + D_damping
 *           + D_friction,
 * constant in the continuum, and its error |total - total_0| / E_ref with
 *   E_ref = K_0 + |S_0| + U_0 + |P - P_0| + sum |f.dx| (loads)
 *           + |W_prescribed| + D_plastic + D_damping + D_friction,
 * the energy the initial state holds plus all that has flowed in or out
 * through each channel so far: every term of the balance is bounded by it
 * in the continuum, it does not vanish when total_0 does (a body released
 * from rest under gravity: |P - P_0|), it depends on the state now only
 * (not on how often it is evaluated), and a scheme that makes energy from
 * nothing (the bar of tests/solver/t_energy.c) is measured against what there
 * was.  Floored by e_floor (1e-9 of 1/2 M c_max^2) for a scene at rest. */
void mpm_energy_finish(const mpm_sim *s, mpm_energy *e)
{
    e->external_work = s->external_work;
    e->damping_work = s->damping_work;
    e->friction_work = s->friction_work;
    e->prescribed_work = s->prescribed_work;
    e->plastic_work = s->plastic_work;
    e->total = e->kinetic + e->strain + e->potential - e->external_work - e->prescribed_work +
               e->plastic_work + e->damping_work + e->friction_work;
    double ref = s->bal_ref0 + fabs(e->potential - s->bal_pot0) + s->external_work_abs +
                 fabs(e->prescribed_work) + e->plastic_work + e->damping_work + e->friction_work;
    if (!(ref > s->e_floor)) ref = s->e_floor;
    e->balance_error = ref > 0 ? fabs(e->total - s->bal_total0) / ref : 0;
}

int mpm_sim_budget(const mpm_sim *s, double *final, double *worst, char *msg, size_t n)
{
    if (final) *final = s->bal_last;
    if (worst) *worst = s->bal_worst;
    if (msg && n) msg[0] = 0;
    if (!(s->budget > 0) || !(s->bal_last > s->budget)) return 0;
    if (msg && n)
        snprintf(msg, n,
                 "energy balance error %.3g%% at the end exceeds the budget %.3g%% "
                 "(energy_budget): the total energy (%.6g at the start) is not conserved to "
                 "that tolerance, so the results are doubtful; refine the grid or the time step, "
                 "or change the method",
                 100 * s->bal_last, 100 * s->budget, s->bal_total0);
    return 1;
}

/* The elastic energy stored by the initial stress, sum 1/2 sigma0 : C^-1 :
 * sigma0 V0 (isotropic linear elasticity; 2D is plane strain with sigma_zz
 * stored).  The reported strain energy 1/2 sigma : eps counts strain from
 * the initial state, so a body released from an initial stress shows
 * kinetic + strain energy up to 2 U0 with E0 = 0; the divergence guard
 * counts 2 U0 as available (see mpm_guard()). */
double mpm_initial_stress_energy(const mpm_sim *s)
{
    const mpm_particles *P = &s->P;
    int dim = s->dim;
    double u = 0;
    for (size_t p = 0; p < P->n; p++) {
        const mpm_mat_params *mp = &s->mats[P->mat[p]];
        double E = mp->E, nu = mp->nu, w;
        if (dim == 1) {
            w = P->sig[0][p] * P->sig[0][p] / E;
        } else {
            double xx = P->sig[0][p], yy = P->sig[1][p],
                   zz = dim == 2 ? mpm_sig_zz(mp, P, p) : P->sig[2][p],
                   sh = P->sig[3][p] * P->sig[3][p];
            if (dim == 3) sh += P->sig[4][p] * P->sig[4][p] + P->sig[5][p] * P->sig[5][p];
            w = (xx * xx + yy * yy + zz * zz - 2 * nu * (xx * yy + yy * zz + zz * xx) +
                 2 * (1 + nu) * sh) /
                E;
        }
        u += 0.5 * w * P->vol[p];
    }
    return u;
}
