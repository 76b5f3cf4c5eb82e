/*
 * mpm_kernels.c - the portable kernel families' selection, and what the
 * kernels export besides their families: one axis's shape weights
 * (mpm_shape_1d(), mpm_diag.h) and the size of a thread's weight scratch.
 *
 * The families themselves are the templates of mpm_kernels.inc,
 * instantiated by five translation units that compile in parallel:
 * mpm_kernels_1d.c (every 1D family), mpm_kernels_2d.c and
 * mpm_kernels_3d.c (tents and uGIMP), mpm_kernels_2d_bs.c and
 * mpm_kernels_3d_bs.c (B-splines); each is built again for AVX2+FMA
 * (mpm_kernels_<unit>_avx2.c), whose families mpm_kernels_avx2.c selects.
 * The plan (mpm_plan.h) says which family a job runs.
 */
#include "mpm_kernels.h"
#include "mpm_diag.h"
#include "mpm_internal.h"
#include "mpm_pass.h"
#include "mpm_shape.h"

int mpm_shape_1d(mpm_method method, double x, double x0, double h, double lp, int nodes, double *w,
                 double *g)
{
    double inv_h = 1.0 / h, r = (x - x0) * inv_h;
    if (method == MPM_METHOD_BSPLINE2 || method == MPM_METHOD_BSPLINE3) {
        int p = method == MPM_METHOD_BSPLINE2 ? 2 : 3;
        mpm_bspline_axis ax;
        mpm_bspline_axis_init(&ax, p, nodes - 1);
        return p == 2 ? bs_axis(&ax, r, inv_h, 3, w, g) : bs_axis(&ax, r, inv_h, 4, w, g);
    }
    if (method == MPM_METHOD_GIMP) return axis(r, inv_h, lp, 4, w, g);
    return axis(r, inv_h, lp, 2, w, g);
}

size_t mpm_kernels_scratch(void)
{
    return MPM_BLOCK * sizeof(pw);
}

const mpm_kernels *mpm_kernels_select(int dim, int ns, int bspline, int blend, int apic)
{
    static const mpm_kernel_unit *const units[3][2] = {
        {&mpm_ku_1d, &mpm_ku_1d}, {&mpm_ku_2d, &mpm_ku_2d_bs}, {&mpm_ku_3d, &mpm_ku_3d_bs}};
    return mpm_kernel_unit_pick(units[dim - 1][bspline != 0], ns, bspline, blend, apic);
}
