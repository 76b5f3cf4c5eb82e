/*
 * mpm.h - public API of the mpmd solver library (explicit MPM and GMPM).
 *
 * The solver implements the explicit algorithm of Buzzi, Pedroso & Giacomini,
 * "Caveats on the implementation of the generalized material point method"
 * (Figs. 5-7): linear tent shape functions (MPM) or uGIMP weighting functions
 * (GMPM, Eqs. 17-20), direct momentum extrapolation (Eq. 26), the "correct"
 * essential boundary conditions (BC1: zero momentum at grid initialisation,
 * Eq. 27; BC2: zero rate of momentum before the nodal update, Eq. 28), and
 * phantom nodes below M_TOL that never divide by a tiny mass (Eqs. 30-31).
 *
 * Usage: fill an mpm_case (plain data, owned by the caller), call
 * mpm_sim_new(), then mpm_sim_run() or mpm_sim_step(), and read results with
 * mpm_sim_energy() and mpm_sim_snapshot() only when they are wanted.
 * This library is plain C11 + libm + pthreads: no I/O, no sockets, no
 * database.  All functions return 0 or a negative MPM_E* code; a failure is
 * described by an mpm_error (mpm_error.h): the field it concerns, as a path
 * of the .proto's names ("bodies[0].points.half_length[3]"), and a message.
 * The last error of a simulation is mpm_sim_error().
 */
#ifndef MPM_H
#define MPM_H

#include <stddef.h>
#include <stdint.h>

#include "mpm_error.h"

#define MPM_MAX_DIM 3

/* Error codes: the shared MPM_E* codes of mpm_error.h (MPM_EINVAL,
 * MPM_ENOMEM, MPM_ELEFTGRID, MPM_EDIVERGED, MPM_ECANCELLED, MPM_ECFL,
 * MPM_ESTATE and MPM_ETOOBIG from the solver). */

/* Shape functions: linear tents (MPM), uGIMP (GMPM), B-splines of degree 2
 * (C1, 3 nodes per axis) or 3 (C2, 4 nodes per axis) on an open (clamped)
 * knot vector with knots at the grid nodes, or CPDI1, the convected
 * particle domain of Sadeghirad et al. 2011 (the particle domain follows a
 * per-particle deformation gradient F; 1D is its two-corner, cpGIMP-like
 * form); docs/solver.md. */
typedef enum {
    MPM_METHOD_MPM = 0,
    MPM_METHOD_GIMP = 1,
    MPM_METHOD_BSPLINE2 = 2,
    MPM_METHOD_BSPLINE3 = 3,
    MPM_METHOD_CPDI = 4
} mpm_method;
typedef enum { MPM_USF = 0, MPM_USL = 1, MPM_MUSL = 2 } mpm_update;
#define MPM_N_METHODS 5
#define MPM_N_UPDATES 3
/* Constitutive models (docs/solver.md, "Material models").  LINEAR_ELASTIC:
 * small-strain incremental elasticity (today's, bit for bit).  NEO_HOOKEAN:
 * compressible hyperelastic, sigma = mu/J (b - I) + lambda ln J / J I from
 * the deformation gradient.  VON_MISES: J2 plasticity with linear isotropic
 * hardening, radial return, Jaumann stress rate.  DRUCKER_PRAGER and
 * MOHR_COULOMB: perfectly plastic, non-associated, with a tension cut-off
 * (solver/mpm_plastic.h; Sloan's substepping for DP, a closed-form
 * principal-space return for MC), Jaumann stress rate; 2D and 3D only. */
typedef enum {
    MPM_MODEL_LINEAR_ELASTIC = 0,
    MPM_MODEL_NEO_HOOKEAN = 1,
    MPM_MODEL_VON_MISES = 2,
    MPM_MODEL_DRUCKER_PRAGER = 3,
    MPM_MODEL_MOHR_COULOMB = 4
} mpm_model_kind;
/* Drucker-Prager's matching to Mohr-Coulomb (the cone through the
 * compression corners, the extension corners, or the plane-strain fit). */
typedef enum { MPM_MC_COMPRESSION = 0, MPM_MC_EXTENSION = 1, MPM_MC_PLANE_STRAIN = 2 } mpm_mc_match;
/* Particle volume update.  STRAIN_INCREMENT (the default, every earlier
 * release): V <- V (1 + tr deps).  DET_F: V = det F V0 (the particles carry
 * F).  CONSTANT: the volume (and so the density) never changes, as the
 * paper's analytic comparisons assume. */
typedef enum {
    MPM_VOLUME_STRAIN_INCREMENT = 0,
    MPM_VOLUME_DET_F = 1,
    MPM_VOLUME_CONSTANT = 2
} mpm_volume_update;
typedef enum { MPM_SHAPE_BOX = 0, MPM_SHAPE_SPHERE = 1 } mpm_shape;
/* Particle-grid velocity transfer.  FLIP: the update of Eq. 31 (blended
 * with PIC by mpm_case.pic_fraction).  APIC: the affine particle-in-cell
 * transfer of Jiang et al. 2015 (docs/solver.md, "APIC"): each particle
 * carries an affine matrix B_p = sum_i S_ip v_i (x_i - x_p)^T besides its
 * velocity, which takes the PIC value sum_i S_ip v_i; the scatter adds
 * m_p C_p (x_i - x_p) to the momentum, C_p = B_p D_p^-1 (uGIMP; D_p =
 * sum_i S_ip (x_i - x_p)(x_i - x_p)^T, diagonal per axis), or
 * m_p B_p grad S_ip (MPM tents, Jiang's multilinear form, the same where
 * D_p is invertible and defined on grid lines too).  APIC conserves the
 * angular momentum exactly (to round-off) and keeps affine velocity fields
 * without the dissipation of PIC. */
typedef enum { MPM_TRANSFER_FLIP = 0, MPM_TRANSFER_APIC = 1 } mpm_transfer;
#define MPM_N_TRANSFERS 2

/* The names of the choices above (mpm_names.c, one table): _name is the
 * case schema's enum spelling ("BSPLINE2", "MUSL", "APIC"), _key the
 * lower-case spelling the run store records ("bspline2"); "?" for a value
 * outside the enum.  _parse takes either, in any case, and returns the
 * value or -1. */
const char *mpm_method_name(mpm_method m);
const char *mpm_method_key(mpm_method m);
int mpm_method_parse(const char *s);
const char *mpm_update_name(mpm_update u);
const char *mpm_update_key(mpm_update u);
int mpm_update_parse(const char *s);
const char *mpm_transfer_name(mpm_transfer t);
const char *mpm_transfer_key(mpm_transfer t);
int mpm_transfer_parse(const char *s);

/* The particle kernels' instruction set (mpm_case.kernels).  AUTO takes
 * the AVX2+FMA kernels where the CPU has both (x86-64) and the portable
 * ones elsewhere; PORTABLE always the portable (SSE2 on x86-64) kernels,
 * whose bits are the same on every machine of the architecture; AVX2
 * insists (MPM_EINVAL on a CPU without them).  FMA rounds a * b + c once,
 * so the two kernels' results differ in round-off (docs/solver.md,
 * "Kernels"): each is reproducible bit for bit for a given thread count.
 * CPDI has portable kernels only. */
typedef enum {
    MPM_KERNELS_AUTO = 0,
    MPM_KERNELS_PORTABLE = 1,
    MPM_KERNELS_AVX2 = 2
} mpm_kernels_isa;

/* The kernel family a job runs (mpm_case.kernel_family).  FAST (the
 * default): the optimised families, chosen by dimension, method, update,
 * transfer and mpm_case.kernels, on mpm_case.threads threads.  REFERENCE:
 * the plain scalar family of mpm_ref.c, the step as the papers write it
 * (node by node, one grid, one thread, no sorting): slower, for checking
 * the fast families (tests/solver/t_reference.c) and for reading.  It
 * runs every case the fast families run, on one thread whatever
 * mpm_case.threads says; its results differ from theirs in round-off
 * (docs/solver.md, "Reference kernels"). */
typedef enum { MPM_KERNEL_FAMILY_FAST = 0, MPM_KERNEL_FAMILY_REFERENCE = 1 } mpm_kernel_family;

/* Structured grid: nodes[d] nodes along axis d, spacing h[d], first node at
 * origin[d].  Only the first `dim` entries are used. */
typedef struct {
    int dim; /* 1, 2 or 3 */
    double origin[MPM_MAX_DIM];
    double h[MPM_MAX_DIM];
    int nodes[MPM_MAX_DIM]; /* >= 2 per axis */
} mpm_grid_desc;

/* Material.  1D: uniaxial (E only); 2D: plane strain; 3D: isotropic.
 * The plastic parameters are read by the models that use them (the others
 * ignore them); angles in degrees. */
typedef struct {
    mpm_model_kind model;
    double youngs_modulus;    /* E > 0 */
    double poisson_ratio;     /* -1 < nu < 0.5 (ignored in 1D) */
    double density;           /* rho > 0 */
    double yield_stress;      /* VON_MISES: initial yield stress sigma_y0 > 0 */
    double hardening_modulus; /* VON_MISES: isotropic H >= 0, sigma_y = sigma_y0 + H eps_p */
    double friction_angle;    /* DP/MC: phi in (0, 90) degrees */
    double dilatancy_angle;   /* DP/MC: psi in [0, phi] degrees */
    double cohesion;          /* DP/MC: c >= 0 */
    double tension_cutoff;    /* DP/MC: tension cut-off >= 0 (DP: the largest mean stress, MC:
                                 the largest principal stress), capped at the apex; HUGE_VAL
                                 (the codec's value when the field is absent): the apex only */
    mpm_mc_match mc_match;    /* DP: matching to Mohr-Coulomb */
    double substep_tolerance; /* DP/MC: Sloan's substepping tolerance, 0 (default) or in (0, 1) */
} mpm_material_desc;

/* A time function f(t), scaling a prescribed velocity or a traction
 * (docs/solver.md, "Conditions"):
 *   CONSTANT  f(t) = value
 *   RAMP      f(t) = value * clamp((t - t0) / (t1 - t0), 0, 1): 0 up to t0,
 *             rising linearly to `value` at t1, `value` after (t0 < t1;
 *             t0 = t1 is refused)
 *   TABLE     piecewise linear through the n >= 1 points (t[i], v[i]), t
 *             strictly increasing, constant beyond the ends (v[0] before
 *             t[0], v[n-1] after t[n-1]); `value` is ignored */
typedef enum { MPM_TF_CONSTANT = 0, MPM_TF_RAMP = 1, MPM_TF_TABLE = 2 } mpm_timefn_kind;
typedef struct {
    mpm_timefn_kind kind;
    double value;
    double t0, t1;
    size_t n;
    const double *t, *v;
} mpm_timefn;

/* Coulomb friction on a face of the grid box (face 2 d + s as in
 * mpm_bc_desc.face_mask).  The face is made a roller in its normal
 * direction (whatever its face_mask says about it) and its tangential
 * motion is resisted with coefficient mu >= 0 while the body presses on it
 * (docs/solver.md, "Friction on grid faces"). */
typedef struct {
    int face;  /* 0..5 = x_lo, x_hi, y_lo, y_hi, z_lo, z_hi (< 2 dim) */
    double mu; /* >= 0 */
} mpm_friction_desc;

/* A prescribed velocity on a face of the grid box (face >= 0: the same
 * nodes a face_mask fixes, ghost layers included for GIMP) or on a node
 * set (face < 0: n_nodes nodes, node_ijk[3 i + d] as mpm_bc_desc's; MPM,
 * GIMP and CPDI only).  Direction d (bit d of mask) of each node gets the
 * velocity value[d] * f(t), f the time function (NULL: 1).  BC1 sets the
 * node's momentum to m v(t^n), BC2 its rate of momentum to
 * m (v(t^{n+1}) - v(t^n)) / dt (docs/solver.md). */
typedef struct {
    int face;
    size_t n_nodes;
    const int *node_ijk;
    unsigned mask;
    double value[MPM_MAX_DIM];
    const mpm_timefn *time_function;
} mpm_prescribed_desc;

/* Essential boundary conditions.  Direction masks: bit d fixes axis d. */
typedef struct {
    /* face_mask[2*d + s]: fixed directions on the face of the grid box with
     * normal axis d, s = 0 the low face, s = 1 the high face.  A wall is
     * all directions (7), a roller only the normal one (1 << d).  Bits of
     * axes the grid lacks are ignored; faces of such axes must be 0. */
    unsigned face_mask[2 * MPM_MAX_DIM];
    /* An explicit node set: node_ijk[3*i + d] is the grid index of node i
     * along axis d; node_mask[i] its fixed directions.  MPM and GIMP only
     * (B-spline control points are not grid nodes: refused). */
    size_t n_nodes;
    const int *node_ijk;
    const unsigned *node_mask;
    /* Coulomb friction on faces (at most one entry per face) */
    size_t n_friction;
    const mpm_friction_desc *friction;
} mpm_bc_desc;

/* A body: a material filled into a shape, or an explicit list of points.
 * Stress and strain use 6 Voigt components: xx, yy, zz, xy, yz, xz. */
typedef struct {
    int material;                 /* index into mpm_case.materials */
    double velocity[MPM_MAX_DIM]; /* uniform initial velocity */

    /* Generated particles (used when n_points == 0). */
    mpm_shape shape;
    double lo[MPM_MAX_DIM], hi[MPM_MAX_DIM]; /* box */
    double center[MPM_MAX_DIM], radius;      /* sphere (disk in 2D) */
    int ppc;                                 /* particles per cell per axis (1..8) */

    /* Explicit particles (used when n_points > 0).  Arrays of n_points
     * entries (x, v: n_points * dim; stress: n_points * 6); volume is
     * required; mass, v and stress are optional (NULL: rho*V, the body's
     * uniform velocity, zero).  half_length: GIMP particle half-width per
     * axis (NULL: V^(1/dim)/2 in every axis). */
    size_t n_points;
    const double *x, *volume, *mass, *v, *stress, *half_length;

    /* Geostatic initial stress, added to any given stress at
     * creation: with gravity along one axis a (the case's gravity must
     * have no other component) and depth = the distance below free_surface
     * (the level of the free surface along a, on the side gravity points
     * away from; 0 above it), sigma_aa = -rho |g| depth (compression
     * negative) and every other normal component sigma_bb = k0 sigma_aa
     * (2D plane strain: sigma_zz too), shears 0; rho the body's material
     * density.  k0 >= 0; has_k0 0: nu / (1 - nu), the at-rest ratio of a
     * laterally confined linear elastic body (1D: only sigma_xx). */
    int geostatic;
    double free_surface, k0;
    int has_k0;
} mpm_body_desc;

/* Damping, applied to the nodal forces after the loads and BC2,
 * before the nodal update (docs/solver.md, "Damping"):
 *   LOCAL   (Cundall) f_d = -alpha |f| sign(v) per component, alpha in
 *           [0, 1), f the unbalanced nodal force and v = q / m the nodal
 *           velocity at the step's start (after BC1);
 *   VISCOUS f_d = -c m v = -c q (c >= 0, a rate in 1/s; mass-proportional).
 * Phantom nodes (m <= M_TOL) are not damped.  The energy removed, sum
 * -f_d . v_mid dt with v_mid the mean of the nodal velocity before and
 * after the update, is mpm_energy.damping_work. */
typedef enum {
    MPM_DAMPING_NONE = 0,
    MPM_DAMPING_LOCAL = 1,
    MPM_DAMPING_VISCOUS = 2
} mpm_damping_kind;

/* A traction on the particles whose centres lie in a box region: the total
 * force traction * area is shared among them in proportion to their volume.
 * area is the product of the region's extents across the normal axis (1 in
 * 1D, per unit thickness in 2D).  A point force is a region holding one
 * particle with `force` given instead of `traction` (is_force = 1). */
typedef struct {
    double lo[MPM_MAX_DIM], hi[MPM_MAX_DIM];
    int normal;                /* axis of the surface normal */
    int is_force;              /* 1: `value` is a total force */
    double value[MPM_MAX_DIM]; /* traction (force / area) or force */
    /* NULL: constant.  Otherwise the force is value * f(t), applied over a
     * step at the step's midpoint time t^n + dt/2 (its work counted with
     * that force; docs/solver.md).  Not combinable with
     * mpm_sim_set_particle_forces(). */
    const mpm_timefn *time_function;
} mpm_traction_desc;

/* A whole simulation case.  The library copies what it needs in
 * mpm_sim_new(); the caller keeps ownership of every array here. */
typedef struct {
    mpm_grid_desc grid;
    mpm_method method;
    mpm_update update;

    double dt;             /* > 0: fixed time step; 0: automatic (CFL) */
    double cfl;            /* Courant factor C for automatic dt (0: default) */
    int allow_unstable_dt; /* accept a given dt above the CFL limit */
    double mass_tol;       /* M_TOL relative to the mean particle mass (0: default) */
    /* PIC/FLIP blend of the particle velocity update, alpha in [0, 1]:
     * v_p <- (1 - alpha) (v_p + dt sum S a_I) + alpha sum S v_I^{n+1}, with
     * a_I = qdot_I/m_I and v_I^{n+1} = q_I/m_I after the nodal update (both
     * 0 at phantom nodes).  0: pure FLIP (the default, Eq. 31); 1: pure
     * PIC, which damps the velocity modes the grid cannot represent.
     * Must be 0 with APIC, itself a PIC transfer (refused otherwise). */
    double pic_fraction;
    /* FLIP (0, the default: every earlier release) or APIC */
    mpm_transfer transfer;
    /* particle volume update (STRAIN_INCREMENT, the default: every earlier
     * release) */
    mpm_volume_update volume_update;

    double gravity[MPM_MAX_DIM];

    size_t n_materials;
    const mpm_material_desc *materials;
    size_t n_bodies;
    const mpm_body_desc *bodies;
    size_t n_tractions;
    const mpm_traction_desc *tractions;
    mpm_bc_desc bc;
    /* prescribed velocities (a prescribed direction must not be fixed by
     * bc, nor lie on a friction face, nor be prescribed twice) */
    size_t n_prescribed;
    const mpm_prescribed_desc *prescribed;

    /* damping (mpm_damping_kind above): coefficient alpha (LOCAL) or c
     * (VISCOUS); damping_until > 0: damping acts only while t <
     * damping_until (geostatic initialisation, then release); 0: always */
    mpm_damping_kind damping;
    double damping_coef, damping_until;
    /* energy budget: the largest balance error (mpm_energy.balance_error)
     * a run may end with, relative (0: no check; the .proto's default is
     * 0.05); fail_on_budget: exceeding it fails the run instead of only
     * warning.  The solver reports (mpm_sim_budget()); whoever runs the
     * case acts on it. */
    double energy_budget;
    int fail_on_budget;

    int threads;                     /* solver threads (0 or 1: serial) */
    mpm_kernels_isa kernels;         /* the kernels' instruction set (default AUTO) */
    mpm_kernel_family kernel_family; /* FAST (default) or REFERENCE */
    size_t max_particles;            /* most particles the case may make (0:
                                      * MPM_MAX_PARTICLES, which also caps it) */
} mpm_case;

#define MPM_DEFAULT_CFL 0.5
/* Largest Courant factor accepted without allow_unstable_dt: 1 for USF and
 * MUSL; 0.5 for USL, which the CFL sweep (make stress) finds blowing up from
 * C = 0.6 (GIMP 1D) and 0.8 (MPM 1D, MPM and GIMP 2D).  A given dt is held
 * to the same fraction of h_min / (c + |v|max). */
#define MPM_MAX_CFL 1.0
#define MPM_USL_MAX_CFL 0.5
/* APIC with MPM tents (any update scheme): the largest Courant factor
 * accepted, and the default.  APIC keeps the grid's velocity modes that
 * FLIP's and PIC's transfers smooth away, and with tents a node that only
 * the edge of a particle's support reaches has a tiny mass but the full
 * gradient 1/h: the spinning disk and the disks' impact (tests/
 * t_apic.c) blow up from C = 0.25 (USL) and 0.3 (USF, MUSL), and run
 * at 0.2 and below.  uGIMP, whose gradients vanish with the weights, keeps
 * the general limits. */
#define MPM_APIC_MPM_MAX_CFL 0.2
#define MPM_DEFAULT_MASS_TOL 1e-12
#define MPM_MAX_PARTICLES ((size_t)1 << 31)
#define MPM_MAX_NODES ((size_t)1 << 31)
#define MPM_MAX_THREADS 64

/* Energies and conserved quantities at the current time. */
typedef struct {
    double kinetic;       /* sum 1/2 m v.v */
    double strain;        /* sum 1/2 sigma:eps V */
    double potential;     /* -sum m g.x (gravity), 0 without gravity */
    double external_work; /* work done by tractions so far */
    /* kinetic + strain + potential - external_work - prescribed_work +
     * plastic_work + damping_work + friction_work: constant in the
     * continuum (the one place it is summed: mpm_sim_energy()) */
    double total;
    double mass;
    double momentum[MPM_MAX_DIM];
    /* sum m x × v about the origin of coordinates (x = 0, not the centre of
     * mass): x, y, z components.  2D (motion in the x-y plane): only [2],
     * the z component, is non-zero; 1D: all zero.  MPM and GIMP with the
     * FLIP update do not conserve it exactly (the grid transfers lose the
     * particles' rotation within a cell): its drift is the loss.  With APIC
     * each particle also carries the spin of its affine velocity field:
     * l_p = m_p x_p × v_p + m_p eps : B_p^T, i.e. (l_p)_a = m_p (x_p × v_p)_a
     * + m_p eps_abc B_p,cb (2D: m_p (B_yx - B_xy); 3D: m_p (B_zy - B_yz,
     * B_xz - B_zx, B_yx - B_xy)), the angular momentum the particle gives
     * the grid in the scatter (sum_i x_i × m_p C_p (x_i - x_p) S_ip =
     * m_p eps : (C_p D_p)^T = m_p eps : B_p^T).  It is what APIC conserves,
     * and what is reported. */
    double angular_momentum[3];
    /* Dissipated and supplied energies, cumulative from the start of the
     * run, each >= 0 except prescribed_work (signed), and 0 in a scene
     * without the feature (filled by the models and conditions
     * that have them):
     *   plastic_work    sum over steps of sigma : d eps_p V (plastic models)
     *   damping_work    energy removed by local or viscous damping
     *   friction_work   energy dissipated by Coulomb friction on faces
     *                   (sum of -df . (q^n + q^{n+1}) / (2 m) dt over the
     *                   friction nodes, df the friction force)
     *   prescribed_work work done on the body by prescribed velocities
     *                   (the reaction forces at the driven nodes: sum of
     *                   (f_BC2 - f_free) (v^n + v^{n+1}) / 2 dt)
     * (docs/solver.md, "Conditions").  total leaves them out. */
    double plastic_work, damping_work, friction_work, prescribed_work;
    /* The energy balance error |total - total_0| / E_ref, total_0 the total
     * at creation and E_ref the energy scale of the run (docs/solver.md,
     * "Energy balance"): E_ref = K_0 + |S_0| + U_0 + |P - P_0| + sum |f.dx|
     * of the loads + |prescribed_work| + plastic_work + damping_work +
     * friction_work, at least e_floor = 1e-9 * 1/2 M c_max^2. */
    double balance_error;
} mpm_energy;

/* One energy sample, the one shape it has from the solver to the store to
 * the wire (mpmd.EnergySample): the energies at a step and time.  seq
 * numbers the samples of a run 0, 1, 2, ... (set by whoever records them;
 * the solver leaves it 0); dim says how many momentum entries count. */
typedef struct {
    uint64_t seq;
    int64_t step;
    double t;
    int dim;
    mpm_energy e;
} mpm_energy_sample;

/* Snapshot request: the caller passes arrays of n_particles entries
 * (times dim for position and velocity, times 6 for stress, times dim*dim
 * for the deformation gradient, row-major); a NULL array is not filled.
 * The last three exist only when the run's particles carry them
 * (mpm_sim_has_field()); otherwise they are left untouched. */
typedef struct {
    double *x, *v, *stress, *volume;
    double *mean_stress;          /* (sxx + syy + szz) / 3, negative in compression */
    double *plastic_strain;       /* equivalent plastic strain (plastic models) */
    double *deformation_gradient; /* F (NEO_HOOKEAN, DET_F volume, CPDI) */
    uint8_t *yielded;             /* 1: the particle flowed plastically in the last step */
} mpm_snapshot;

/* Per-particle fields a run may lack (mpm_sim_has_field()). */
typedef enum {
    MPM_FIELD_PLASTIC_STRAIN = 0,
    MPM_FIELD_DEFORMATION_GRADIENT = 1,
    MPM_FIELD_YIELDED = 2
} mpm_field;

typedef struct mpm_sim mpm_sim;

/* What mpm_case_check() learnt about a valid case: enough for
 * mpm_sim_new() to build it without checking it again. */
typedef struct {
    size_t particles; /* particles the case makes */
    size_t nodes;     /* real grid nodes */
    int dim;
    double vmax; /* largest initial particle speed */
    double cmax; /* largest p-wave speed of the materials */
} mpm_case_info;

/* Validates every field of a case and counts its particles, in one pass
 * over them, allocating nothing.  Returns 0 and fills *info (info may be
 * NULL), or MPM_EINVAL / MPM_ECFL (a dt or cfl above the stability limit
 * without allow_unstable_dt) / MPM_ETOOBIG (more particles than
 * max_particles; the counting stops there) with err naming the field. */
int mpm_case_check(const mpm_case *c, mpm_case_info *info, mpm_error *err);

/* The verification policy (solver/mpm_verified.c; docs/accuracy.md,
 * "Verification matrix"): 0 when a checked case (info from
 * mpm_case_check()) uses only combinations that the tests show right, else
 * MPM_EINVAL with err naming the field, the combination, why, and an
 * alternative.  Called at submit (protocol/mpp_case.c); the solver itself
 * runs any valid case, so its own tests reach every path. */
int mpm_case_verified(const mpm_case *c, const mpm_case_info *info, mpm_error *err);

/* Creates a simulation from a case.  checked NULL: the case is checked
 * first (mpm_case_check()).  checked not NULL: the case passed
 * mpm_case_check() with that info and has not changed since, except for
 * `threads` (checked again here); it is built in one pass without checking
 * again.  Returns NULL on failure with err (may be NULL) filled in:
 * MPM_ENOMEM, or the check's codes. */
mpm_sim *mpm_sim_new(const mpm_case *c, const mpm_case_info *checked, mpm_error *err);
void mpm_sim_destroy(mpm_sim **sim);

/* Advances one step.  Returns 0, or MPM_ELEFTGRID / MPM_EDIVERGED (after
 * which the state is frozen and every further step returns MPM_ESTATE). */
int mpm_sim_step(mpm_sim *sim);

/* Advances up to nsteps steps, stopping early on error or cancellation. */
int mpm_sim_run(mpm_sim *sim, long nsteps);

/* Runs the divergence guard now (the steps run it every 16 steps and when
 * the largest speed jumps): returns 0, or MPM_EDIVERGED with the reason in
 * mpm_sim_error() and the simulation frozen, when the kinetic + strain
 * energy exceeds twice what the initial state, the loads and gravity can
 * supply.  Call it before reporting a run as finished. */
int mpm_sim_check(mpm_sim *sim);

/* The energy budget (mpm_case.energy_budget): *final (may be NULL) gets the
 * balance error of the last mpm_sim_energy() call -- the run's, when that
 * was its last sample -- and *worst (may be NULL) the largest any call
 * found.  Returns 1 when a budget is set and the final error exceeds it,
 * with a message in msg (n bytes; may be NULL), else 0.  The budget judges
 * the final error, the energy a run created or lost in all: within a run
 * the particles' strain energy lags their kinetic energy during impacts
 * (the paper's disks: 8 % at the impact, 0.13 % at the end), which is no
 * loss.  Cheap: no pass over the particles. */
int mpm_sim_budget(const mpm_sim *sim, double *final, double *worst, char *msg, size_t n);

/* The solver's warnings about the run so far, for a result it cannot
 * vouch for (docs/accuracy.md): an elastic body on a friction face outside
 * BSPLINE2 with mu <= MPM_FRICTION_ELASTIC_MU, a prescribed face that has
 * moved more than MPM_FACE_TRAVEL_MAX cells along its normal (the body has
 * left the grid face it acts at).  Returns 1 with the text in msg (n
 * bytes; may be NULL), or 0.  Whoever runs the job records it with the run
 * (as the budget's). */
#define MPM_FACE_TRAVEL_MAX 0.05
#define MPM_FRICTION_ELASTIC_MU 0.15
int mpm_sim_warnings(const mpm_sim *sim, char *msg, size_t n);

/* Asks a running mpm_sim_run() to stop before its next step.  Safe to call
 * from any thread. */
void mpm_sim_cancel(mpm_sim *sim);

long mpm_sim_steps(const mpm_sim *sim);
double mpm_sim_time(const mpm_sim *sim);
double mpm_sim_dt(const mpm_sim *sim);       /* dt of the next step */
double mpm_sim_dt_limit(const mpm_sim *sim); /* CFL limit (C = 1) now */
/* The Courant factor a simulation of case c steps with (its cfl, else the
 * default, or APIC with MPM's cap). */
double mpm_case_cfl(const mpm_case *c);
/* The largest time step a simulation of case c (checked: info) can take:
 * its fixed dt, or with automatic dt the CFL step of particles at rest,
 * C min(h) / c_max (the daemon's fewest-steps estimate at submit). */
double mpm_case_dt_max(const mpm_case *c, const mpm_case_info *info);

/* Per-particle external forces for the following steps: f[p*dim + d] is the
 * force (not per unit mass) on particle p, in the order the particles were
 * created (bodies in order; explicit points in order, generated ones in the
 * generator's order).  Scattered like a point load, f_n += S_np f_p (Eq. 14),
 * added to the tractions, counted in the external work, and kept until the
 * next call; NULL sets them to zero.  The array is copied.  Returns 0, or
 * MPM_EINVAL (a non-finite value, or a case whose tractions have time
 * functions; mpm_sim_error() names it), MPM_ENOMEM.
 * Not to be called while mpm_sim_run() runs. */
int mpm_sim_set_particle_forces(mpm_sim *sim, const double *f);
size_t mpm_sim_particles(const mpm_sim *sim);
size_t mpm_sim_nodes(const mpm_sim *sim); /* real grid nodes */
int mpm_sim_dim(const mpm_sim *sim);
/* The kernels the simulation runs: "avx2-fma", "portable" or "reference". */
const char *mpm_sim_kernels(const mpm_sim *sim);
/* The plan of the job: the fast paths the simulation runs, chosen once at
 * creation from the case and the CPU, as one line of key=value pairs
 * ("kernels=avx2 fma=1 dim=2 shape=tent ns=2 ... sort_ring=8192";
 * docs/solver.md, "The plan").  Writes at most n bytes (NUL included) and
 * returns the length of the whole text, as snprintf().  MPM_PLAN_LEN
 * bytes always hold it. */
#define MPM_PLAN_LEN 256
int mpm_sim_plan(const mpm_sim *sim, char *buf, size_t n);
/* 1 when this build has the AVX2+FMA kernels and this CPU runs them. */
int mpm_kernels_avx2_available(void);
/* The error that stopped the simulation or refused the last call (code 0
 * when none).  Valid as long as the simulation. */
const mpm_error *mpm_sim_error(const mpm_sim *sim);

/* Computes energies (one pass over the particles, only when called, on the
 * simulation's threads; the sums are reproducible for a given thread count).
 * Right after a step that mpm_sim_want_energy() asked for, it returns the
 * sums that step made instead (the same values), with no pass.  Not to be
 * called while a step runs. */
void mpm_sim_energy(const mpm_sim *sim, mpm_energy *e);

/* mpm_sim_energy() as a sample: step, time, dim and the energies (seq 0,
 * for whoever records it to number). */
void mpm_sim_energy_sample(const mpm_sim *sim, mpm_energy_sample *out);

/* The next step also computes the energies, summed inside the particle
 * passes it runs anyway (per thread, combined in thread order: the same
 * sums as mpm_sim_energy()'s pass, with either kernels); mpm_sim_energy() right after that step
 * then costs nothing.  The request holds for one step; the physics is
 * unchanged.  Not to be called while a step runs. */
void mpm_sim_want_energy(mpm_sim *sim);

/* The work of the frictional models' stress-point integrators
 * (DRUCKER_PRAGER: Sloan's substepping; MOHR_COULOMB: a closed-form
 * return, which counts one substep), cumulative from the start of the run
 * and summed per thread in thread order (the same for any thread count):
 * updates is the number of plastic particle-updates (a particle that
 * yielded in a step counts once), substeps the substeps they took, and
 * max_substeps the most that one update took.  All 0 when no material is
 * DRUCKER_PRAGER or MOHR_COULOMB (no counting is done then). */
typedef struct {
    long long updates;
    long long substeps;
    int max_substeps;
} mpm_plastic_stats;
void mpm_sim_plastic_stats(const mpm_sim *sim, mpm_plastic_stats *out);

/* Checkpoints (mpm_checkpoint.c): the solver state a case does not
 * determine -- the particles (in their current, sorted order), time, step,
 * dt, the cumulative works and counters, the balance and guard references
 * -- as one self-checking blob (a header with a format version, a
 * fingerprint of the case's layout and a checksum of the payload).
 *
 * mpm_sim_checkpoint_size() is the blob's exact size in bytes.
 * mpm_sim_checkpoint_save() writes it into buf (n >= that size); returns
 * 0, or MPM_ETOOBIG when n is too small.  Only between steps.
 * mpm_sim_checkpoint_load() restores a blob into sim, a fresh simulation
 * from mpm_sim_new() on the same case; returns 0, or MPM_ESYNTAX (not a
 * checkpoint, truncated, checksum mismatch), MPM_EVERSION (another format
 * version) or MPM_EINVAL (a blob of another case's layout), with err
 * filled.  After a load, the run goes on exactly as the saved one would
 * have: with the same thread count it gives the same bits.
 *
 * Details (docs/solver.md, "Checkpoints"): the blob is the host's memory
 * layout (little-endian on the machines we build for) and is read back by
 * the same build on the same machine type; another byte order is
 * MPM_EVERSION.  The thread count is not part of the layout: a blob loads
 * into a simulation with another count (the run then differs in
 * round-off).  The case's numeric parameters (grid, time step, materials,
 * gravity, damping) are fingerprinted: another value of one is MPM_EINVAL
 * too; the loads' and conditions' values are not (keep the case with its
 * checkpoint).  A refused load leaves sim as it was.  The load also
 * returns MPM_ENOMEM (a blob saved after mpm_sim_set_particle_forces()
 * needs one slot per particle) and MPM_ESYNTAX for counters or indices
 * that cannot belong to this case.  A failed run's blob keeps its failure:
 * after the load every step returns MPM_ESTATE. */
size_t mpm_sim_checkpoint_size(const mpm_sim *sim);
int mpm_sim_checkpoint_save(const mpm_sim *sim, void *buf, size_t n);
int mpm_sim_checkpoint_load(mpm_sim *sim, const void *buf, size_t n, mpm_error *err);
/* The checks of mpm_sim_checkpoint_load() that need no simulation: the
 * header, the sizes and the checksum (for a caller that stores blobs and
 * wants to refuse a damaged one before building a simulation).  Returns 0,
 * MPM_ESYNTAX or MPM_EVERSION with err filled. */
int mpm_checkpoint_verify(const void *buf, size_t n, mpm_error *err);

/* Copies the requested particle fields into caller arrays, each particle
 * at its creation number's place, on the simulation's threads (each its
 * slice of the particles).  Not to be called while a step runs. */
void mpm_sim_snapshot(const mpm_sim *sim, const mpm_snapshot *out);
/* 1 when the run's particles carry field f (the plastic strain and the
 * yield flag: a plastic model in the case; F: a model or the volume update
 * that needs it, or CPDI), else 0. */
int mpm_sim_has_field(const mpm_sim *sim, mpm_field f);
/* The same answer for the run a checked case c would make, without
 * building it (the daemon's estimate of a job's recorded bytes). */
int mpm_case_has_field(const mpm_case *c, mpm_field f);

/* p-wave speed of a material: sqrt(E/rho) in 1D, sqrt((lambda+2mu)/rho)
 * otherwise. */
double mpm_material_wave_speed(const mpm_material_desc *m, int dim);

#endif
