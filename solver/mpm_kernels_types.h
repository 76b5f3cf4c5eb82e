/*
 * mpm_kernels_types.h - the kernel families' types: a family's passes
 * (struct mpm_kernels), each thread's results of a particle pass
 * (mpm_thread_out) and the families one translation unit instantiates
 * (mpm_kernel_unit).  struct mpm_sim points at them (mpm_internal.h); the
 * functions that pick a family are in mpm_kernels.h (portable builds),
 * mpm_kernels_avx2.h (AVX2 builds) and mpm_cpdi.h.  This header declares
 * no function, so that mpm_internal.h can include it without a circle.
 */
#ifndef MPM_KERNELS_TYPES_H
#define MPM_KERNELS_TYPES_H

#include "mpm.h"
#include "mpm_grid.h"

#include <stddef.h>
#include <stdint.h>

typedef struct mpm_kernels mpm_kernels;

/* Per-thread results of a particle pass, padded to a cache line. */
typedef struct mpm_thread_out mpm_thread_out;
struct mpm_thread_out {
    double vmax2;            /* max |v|^2 seen */
    size_t bad;              /* first particle that left the grid or blew up */
    double *deps[9];         /* MPM_BLOCK strain increments (scratch): the
                              * Voigt components of dt sym(L); 2D: deps[2]
                              * holds the spin dt W_xy = dt (L_xy - L_yx)/2
                              * (eps_zz is 0 in plane strain); 3D with
                              * mpm_sim.spin3: deps[6..8] the spins dt W_xy,
                              * dt W_yz, dt W_xz (mpm_pass.h strain_of()) */
    double wplast;           /* plastic work of the step's updates so far
                              * (summed into mpm_sim.plastic_work after it) */
    void *wblk;              /* MPM_BLOCK per-axis weights (mpm_kernels_scratch bytes) */
    int blo[3], bhi[3];      /* padded nodes touched by the slice's supports
                              * (inclusive; empty: blo > bhi) */
    int *rlo, *rhi;          /* per row (y + z np[1]): first and last x node
                              * touched (empty: rlo > rhi); rows outside the
                              * box blo..bhi are always empty */
    double ekin, estr, epot; /* partial energies (guard, mpm_sim_energy, and
                              * the step's passes when energies are wanted) */
    double emom[3], emass;   /* partial momentum and mass (mpm_sim_energy) */
    double eang[3];          /* partial angular momentum (mpm_sim_energy) */
    double edamp;            /* damping work of the thread's nodes this step */
    int ksorted;             /* sort keys of the slice non-decreasing */
    uint64_t *rval;          /* the sort's ring of saved slots (sort_ring */
    uint32_t *rtag;          /* entries: values, and their slots) */
    size_t ncell;            /* cell changes along the slice, as the last
                              * moving pass (or mpm_ph_bbox()) recorded the
                              * supports: its first particle counts one */
    uint32_t kfirst, klast;  /* the slice's first and last sort key */
    /* this step's work of the prescribed velocities' reactions and of the
     * face friction on the thread's share of the nodes (mpm_cond.c) */
    double wpres, wfric;
    /* DRUCKER_PRAGER / MOHR_COULOMB updates of the step (mpm_model_block()):
     * plastic point-updates, their substeps (a closed-form return counts
     * 1), the most in one update, and the first particle whose integrator
     * failed (SIZE_MAX: none); summed and reset by mpm_sim_step() */
    long long plupd, plsub;
    int plmax;
    size_t plbad;
    char pad[64];
};

/* Kernel family for one (dimension, method).  Each runs over the particles
 * [p0, p1) with scatter target gb and per-thread output o.  The passes that
 * write a particle field's last value of the step take en: nonzero, they
 * also sum the slice's energies into o (the pass writing the final stress,
 * strain and volume: o->estr; the one writing the final position and
 * velocity: o->ekin, epot, emom, eang, emass), exactly as the energy pass does.
 * en is tested once per call (two instantiations), never per particle. */
struct mpm_kernels {
    void (*p2g_mq)(mpm_sim *, mpm_gridbuf *gb, size_t p0, size_t p1);
    void (*p2g_mqf)(mpm_sim *, mpm_gridbuf *gb, size_t p0, size_t p1);
    void (*p2g_q2)(mpm_sim *, mpm_gridbuf *gb, size_t p0, size_t p1);
    /* USF: strain from grid velocity, stress update, then internal forces */
    void (*stress_force)(mpm_sim *, mpm_gridbuf *gb, mpm_thread_out *o, size_t p0, size_t p1,
                         int en);
    /* position and velocity update (Eqs. 30-31) */
    void (*g2p_xv)(mpm_sim *, mpm_thread_out *o, size_t p0, size_t p1, int en);
    /* USL: position and velocity update, then strain and stress */
    void (*g2p_xv_stress)(mpm_sim *, mpm_thread_out *o, size_t p0, size_t p1, int en);
    /* MUSL: velocity only, then position + strain from q2 */
    void (*g2p_v)(mpm_sim *, mpm_thread_out *o, size_t p0, size_t p1);
    void (*g2p_x_stress)(mpm_sim *, mpm_thread_out *o, size_t p0, size_t p1, int en);
    /* point forces of the loaded particles, scattered into the main grid */
    void (*scatter_loads)(mpm_sim *);
    /* support box and row extents of particles [p0, p1) into o->blo/bhi
     * and o->rlo/rhi, without moving them */
    void (*bbox)(mpm_sim *, mpm_thread_out *o, size_t p0, size_t p1);
    /* sort keys: cell (x, row) of each particle numbered row-major over
     * the rows' extents, rowoff[row] + x - ulo[row] */
    void (*cell_keys)(const mpm_sim *, uint32_t *key, size_t p0, size_t p1);
    /* A family has either the plain moving passes above and p2g_q2
     * (CPDI) or, NULL there, the fused ones below (every other family).
     * The fused passes (G2P2G): the
     * pass that moves the particles also scatters the next step's P2G
     * fields of each particle it moved, at its new position, into nb
     * (nb NULL: not this step), exactly as p2g_mq (USF) or p2g_mqf (USL,
     * MUSL) would scatter them at the start of the next step; a particle
     * is scattered only while the thread has met no bad particle (a step
     * that fails scatters nothing beyond the grid). */
    void (*g2p_xv_nx)(mpm_sim *, mpm_gridbuf *nb, mpm_thread_out *o, size_t p0, size_t p1, int en);
    void (*g2p_xv_stress_nx)(mpm_sim *, mpm_gridbuf *nb, mpm_thread_out *o, size_t p0, size_t p1,
                             int en);
    void (*g2p_x_stress_nx)(mpm_sim *, mpm_gridbuf *nb, mpm_thread_out *o, size_t p0, size_t p1,
                            int en);
    /* MUSL: the velocity update and, with the same weights, the momentum
     * of the updated velocity into q2b (g2p_v then p2g_q2, in one pass) */
    void (*g2p_v_q2)(mpm_sim *, mpm_gridbuf *q2b, size_t p0, size_t p1);
};

/* The families one translation unit of the kernels instantiates
 * (mpm_kernels.inc): fam[bspline][variant][ns - 2], variant 0 FLIP, 1 the
 * PIC/FLIP blend, 2 APIC; NULL where the unit has none.  The portable
 * units are mpm_kernels_<unit>.c, their AVX2 builds
 * mpm_kernels_<unit>_avx2.c. */
typedef struct {
    const mpm_kernels *fam[2][3][3];
} mpm_kernel_unit;
/* unit u's family (mpm_kernels_select()'s arguments) */
static inline const mpm_kernels *mpm_kernel_unit_pick(const mpm_kernel_unit *u, int ns, int bspline,
                                                      int blend, int apic)
{
    return u->fam[bspline != 0][apic ? 2 : blend ? 1 : 0][ns - 2];
}

#endif
