/*
 * ctl_h5.c - the HDF5 + XDMF writer of `mpmctl export --format hdf5`
 * (ctl_h5.h): each snapshot becomes a group of datasets in one HDF5 file,
 * written as it arrives, so memory holds one snapshot at a time; what the
 * XDMF file needs of each (step, time, particle count, the fields present)
 * is kept in a small list and the XDMF file is written last, from it.
 * Every HDF5 call is checked: HDF5's own error printing is turned off, and
 * a failure is reported once, naming the call, the object and HDF5's
 * innermost reason.  Guarded by ctl_export_hdf5 (h5py reads the values
 * back, the XDMF is parsed and its every reference resolved).
 */
#include "ctl_h5.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <hdf5.h>

#include "ctl.h"

/* The fields of a snapshot, as bits (which the XDMF file lists). */
enum {
    F_V = 1,
    F_STRESS = 2,
    F_P = 4,
    F_MEAN = 8,
    F_VOL = 16,
    F_EP = 32,
    F_F = 64,
    F_Y = 128,
    F_POINTS = 256 /* 1D: the padded positions */
};

typedef struct {
    int64_t step;
    double t;
    uint64_t n;
    unsigned fields;
} h5_entry;

struct ctl_h5 {
    hid_t file, snaps;
    char *path;
    uint64_t id;
    int width, dim, failed;
    h5_entry *e;
    size_t ne, cap;
};

/* HDF5's innermost error description, for the message. */
static herr_t first_error(unsigned n, const H5E_error2_t *err, void *arg)
{
    if (n == 0 && err->desc) snprintf(arg, 200, "%s", err->desc);
    return 0;
}

/* Reports a failed HDF5 call on object what; returns CTL_ESYS. */
static int h5_fail(ctl_h5 *h, const char *call, const char *what)
{
    char why[200] = "";
    H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, first_error, why);
    H5Eclear2(H5E_DEFAULT);
    fprintf(stderr, "mpmctl: cannot write %s: HDF5 %s failed on %s%s%s\n", h->path, call, what,
            why[0] ? ": " : "", why);
    h->failed = 1;
    return CTL_ESYS;
}

ctl_h5 *ctl_h5_new(const char *h5path, uint64_t id, int width)
{
    ctl_h5 *h = calloc(1, sizeof *h);
    if (!h || !(h->path = strdup(h5path))) {
        fprintf(stderr, "mpmctl: export: out of memory\n");
        free(h);
        return NULL;
    }
    h->file = h->snaps = H5I_INVALID_HID;
    h->id = id;
    h->width = width < 1 ? 1 : width > 19 ? 19 : width;
    /* our messages name the call; HDF5's stack print would repeat it */
    if (H5Eset_auto2(H5E_DEFAULT, NULL, NULL) < 0) {
        h5_fail(h, "H5Eset_auto2", "the error stack");
    } else if ((h->file = H5Fcreate(h5path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT)) < 0) {
        h5_fail(h, "H5Fcreate", "the file");
    } else if ((h->snaps =
                    H5Gcreate2(h->file, "snapshots", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT)) < 0) {
        h5_fail(h, "H5Gcreate2", "/snapshots");
    }
    if (h->failed) {
        if (h->file >= 0) H5Fclose(h->file);
        remove(h5path);
        free(h->path);
        free(h);
        return NULL;
    }
    return h;
}

/* A scalar attribute of type t (memory and file alike) on loc. */
static int attr(ctl_h5 *h, hid_t loc, const char *name, hid_t t, const void *v, const char *where)
{
    char what[160];
    snprintf(what, sizeof what, "attribute %s of %s", name, where);
    hid_t sp = H5Screate(H5S_SCALAR), a;
    if (sp < 0) return h5_fail(h, "H5Screate", what);
    if ((a = H5Acreate2(loc, name, t, sp, H5P_DEFAULT, H5P_DEFAULT)) < 0) {
        H5Sclose(sp);
        return h5_fail(h, "H5Acreate2", what);
    }
    int rc = H5Awrite(a, t, v) < 0 ? h5_fail(h, "H5Awrite", what) : 0;
    if (H5Aclose(a) < 0 && !rc) rc = h5_fail(h, "H5Aclose", what);
    if (H5Sclose(sp) < 0 && !rc) rc = h5_fail(h, "H5Sclose", what);
    return rc;
}

/* Dataset name under loc (shown as where/name) of rank 1 or 2 (cols 0:
 * rank 1), file type ft, from buf of memory type mt. */
static int dataset(ctl_h5 *h, hid_t loc, const char *where, const char *name, uint64_t rows,
                   uint64_t cols, hid_t ft, hid_t mt, const void *buf)
{
    static const double none = 0;
    char what[160];
    hsize_t dims[2] = {rows, cols};
    snprintf(what, sizeof what, "%s/%s", where, name);
    hid_t sp = H5Screate_simple(cols ? 2 : 1, dims, NULL), d;
    if (sp < 0) return h5_fail(h, "H5Screate_simple", what);
    if ((d = H5Dcreate2(loc, name, ft, sp, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT)) < 0) {
        H5Sclose(sp);
        return h5_fail(h, "H5Dcreate2", what);
    }
    int rc = H5Dwrite(d, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf ? buf : &none) < 0
                 ? h5_fail(h, "H5Dwrite", what)
                 : 0;
    if (H5Dclose(d) < 0 && !rc) rc = h5_fail(h, "H5Dclose", what);
    if (H5Sclose(sp) < 0 && !rc) rc = h5_fail(h, "H5Sclose", what);
    return rc;
}

static int doubles(ctl_h5 *h, hid_t g, const char *where, const char *name, uint64_t rows,
                   uint64_t cols, const double *v)
{
    return dataset(h, g, where, name, rows, cols, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, v);
}

int ctl_h5_add(ctl_h5 *h, const mpp_snapshot *s)
{
    char where[64], gname[32];
    uint64_t n = s->n, dim = (uint64_t)s->dim;
    unsigned f = 0;
    int rc = 0;
    if (!s->x || s->dim < 1 || s->dim > 3) {
        fprintf(stderr,
                "mpmctl: %s: the snapshot at step %lld has no particle positions (dim %d): "
                "record X (output.snapshotFields empty or listing X) to export it\n",
                h->path, (long long)s->step, s->dim);
        h->failed = 1;
        return CTL_ECASE;
    }
    if (h->ne && s->dim != h->dim) {
        fprintf(stderr, "mpmctl: %s: the snapshot at step %lld has dim %d, the first had %d\n",
                h->path, (long long)s->step, s->dim, h->dim);
        h->failed = 1;
        return CTL_EPROTO;
    }
    if (h->ne == h->cap) {
        size_t cap = h->cap ? 2 * h->cap : 16;
        h5_entry *e = realloc(h->e, cap * sizeof *e);
        if (!e) {
            fprintf(stderr, "mpmctl: export: out of memory\n");
            h->failed = 1;
            return CTL_ESYS;
        }
        h->e = e;
        h->cap = cap;
    }
    h->dim = s->dim;
    snprintf(gname, sizeof gname, "%0*lld", h->width, (long long)s->step);
    snprintf(where, sizeof where, "/snapshots/%s", gname);
    hid_t g = H5Gcreate2(h->snaps, gname, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (g < 0) return h5_fail(h, "H5Gcreate2", where);
    int64_t step = s->step;
    double t = s->t;
    if (!rc) rc = attr(h, g, "step", H5T_NATIVE_INT64, &step, where);
    if (!rc) rc = attr(h, g, "t", H5T_NATIVE_DOUBLE, &t, where);
    if (!rc) rc = doubles(h, g, where, "x", n, dim, s->x);
    if (!rc && dim == 1) {
        double *p = calloc(n ? 3 * n : 1, sizeof *p);
        if (!p) {
            fprintf(stderr, "mpmctl: export: out of memory\n");
            rc = CTL_ESYS;
        } else {
            for (uint64_t i = 0; i < n; i++) p[3 * i] = s->x[i];
            rc = doubles(h, g, where, "points", n, 3, p);
            f |= F_POINTS;
            free(p);
        }
    }
    const struct {
        const char *name;
        const double *v;
        uint64_t cols;
        unsigned bit;
    } a[] = {{"v", s->v, dim, F_V},
             {"stress", s->stress, 6, F_STRESS},
             {"pressure", s->pressure, 0, F_P},
             {"mean_stress", s->mean_stress, 0, F_MEAN},
             {"volume", s->volume, 0, F_VOL},
             {"plastic_strain", s->plastic_strain, 0, F_EP},
             {"deformation_gradient", s->deformation_gradient, dim * dim, F_F}};
    for (size_t k = 0; !rc && k < sizeof a / sizeof a[0]; k++)
        if (a[k].v && !(rc = doubles(h, g, where, a[k].name, n, a[k].cols, a[k].v))) f |= a[k].bit;
    if (!rc && s->yielded) {
        uint8_t *y = malloc(n ? n : 1);
        if (!y) {
            fprintf(stderr, "mpmctl: export: out of memory\n");
            rc = CTL_ESYS;
        } else {
            for (uint64_t i = 0; i < n; i++) y[i] = s->yielded[i] ? 1 : 0;
            rc = dataset(h, g, where, "yielded", n, 0, H5T_STD_U8LE, H5T_NATIVE_UINT8, y);
            f |= F_Y;
            free(y);
        }
    }
    if (H5Gclose(g) < 0 && !rc) rc = h5_fail(h, "H5Gclose", where);
    if (rc) {
        h->failed = 1;
        return rc;
    }
    h->e[h->ne++] = (h5_entry){s->step, s->t, n, f};
    return 0;
}

/* One DataItem naming dataset name of snapshot e. */
static void item(FILE *x, const ctl_h5 *h, const char *h5name, const h5_entry *e, const char *name,
                 uint64_t cols, int u8)
{
    fprintf(x, "          <DataItem Dimensions=\"%llu", (unsigned long long)e->n);
    if (cols) fprintf(x, " %llu", (unsigned long long)cols);
    fprintf(x, "\" NumberType=\"%s\" Precision=\"%d\" Format=\"HDF\">%s:/snapshots/%0*lld/%s",
            u8 ? "UChar" : "Float", u8 ? 1 : 8, h5name, h->width, (long long)e->step, name);
    fputs("</DataItem>\n", x);
}

/* An attribute named as the VTK files name it ("velocity" for the
 * dataset v, else the dataset's name). */
static void attribute(FILE *x, const ctl_h5 *h, const char *h5name, const h5_entry *e,
                      const char *name, const char *type, uint64_t cols, int u8)
{
    fprintf(x, "        <Attribute Name=\"%s\" AttributeType=\"%s\" Center=\"Node\">\n",
            strcmp(name, "v") ? name : "velocity", type);
    item(x, h, h5name, e, name, cols, u8);
    fputs("        </Attribute>\n", x);
}

/* The XDMF 3 file: a temporal collection of one uniform grid (the
 * particles as a polyvertex) per snapshot. */
static int write_xdmf(const ctl_h5 *h, const char *path, const char *h5name)
{
    FILE *x = fopen(path, "w");
    uint64_t d = (uint64_t)h->dim;
    if (!x) {
        fprintf(stderr, "mpmctl: cannot write %s: %s\n", path, strerror(errno));
        return CTL_ESYS;
    }
    fputs("<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n  <Domain>\n", x);
    fprintf(x, "    <Grid Name=\"run%llu\" GridType=\"Collection\" CollectionType=\"Temporal\">\n",
            (unsigned long long)h->id);
    for (size_t i = 0; i < h->ne; i++) {
        const h5_entry *e = &h->e[i];
        fprintf(x, "      <Grid Name=\"step%0*lld\" GridType=\"Uniform\">\n", h->width,
                (long long)e->step);
        fprintf(x, "        <Time Value=\"%.17g\"/>\n", cj_norm(e->t));
        fprintf(x,
                "        <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"%llu\" "
                "NodesPerElement=\"1\"/>\n",
                (unsigned long long)e->n);
        /* XDMF has XYZ and XY geometries; 1D uses the padded points */
        fprintf(x, "        <Geometry GeometryType=\"%s\">\n", d == 2 ? "XY" : "XYZ");
        fputs("  ", x);
        item(x, h, h5name, e, d == 1 ? "points" : "x", d == 1 ? 3 : d, 0);
        fputs("        </Geometry>\n", x);
        if (e->fields & F_V) attribute(x, h, h5name, e, "v", d == 3 ? "Vector" : "Matrix", d, 0);
        if (e->fields & F_STRESS) attribute(x, h, h5name, e, "stress", "Matrix", 6, 0);
        if (e->fields & F_P) attribute(x, h, h5name, e, "pressure", "Scalar", 0, 0);
        if (e->fields & F_MEAN) attribute(x, h, h5name, e, "mean_stress", "Scalar", 0, 0);
        if (e->fields & F_VOL) attribute(x, h, h5name, e, "volume", "Scalar", 0, 0);
        if (e->fields & F_EP) attribute(x, h, h5name, e, "plastic_strain", "Scalar", 0, 0);
        if (e->fields & F_F)
            attribute(x, h, h5name, e, "deformation_gradient", d == 3 ? "Tensor" : "Matrix", d * d,
                      0);
        if (e->fields & F_Y) attribute(x, h, h5name, e, "yielded", "Scalar", 0, 1);
        fputs("      </Grid>\n", x);
    }
    fputs("    </Grid>\n  </Domain>\n</Xdmf>\n", x);
    int werr = ferror(x), e = errno;
    if (fclose(x) && !werr) {
        werr = 1;
        e = errno;
    }
    if (werr) {
        fprintf(stderr, "mpmctl: cannot write %s: %s\n", path, strerror(e ? e : EIO));
        remove(path);
        return CTL_ESYS;
    }
    return 0;
}

int ctl_h5_finish(ctl_h5 **ph, int ok, const char *xdmf_path, const char *h5name)
{
    ctl_h5 *h = ph ? *ph : NULL;
    int rc = 0;
    if (!h) return 0;
    if (ok && !h->failed) {
        int64_t *steps = malloc((h->ne ? h->ne : 1) * sizeof *steps);
        double *times = malloc((h->ne ? h->ne : 1) * sizeof *times);
        if (!steps || !times) {
            fprintf(stderr, "mpmctl: export: out of memory\n");
            rc = CTL_ESYS;
        } else {
            for (size_t i = 0; i < h->ne; i++) {
                steps[i] = h->e[i].step;
                times[i] = h->e[i].t;
            }
            int dim = h->dim;
            rc = attr(h, h->file, "run_id", H5T_NATIVE_UINT64, &h->id, "/");
            if (!rc) rc = attr(h, h->file, "dim", H5T_NATIVE_INT, &dim, "/");
            if (!rc)
                rc = dataset(h, h->file, "", "steps", h->ne, 0, H5T_STD_I64LE, H5T_NATIVE_INT64,
                             steps);
            if (!rc) rc = doubles(h, h->file, "", "times", h->ne, 0, times);
        }
        free(steps);
        free(times);
    } else if (ok) {
        rc = CTL_ESYS; /* an add failed (and said so) */
    }
    if (H5Gclose(h->snaps) < 0 && !rc) rc = h5_fail(h, "H5Gclose", "/snapshots");
    /* the file is complete only once closed (its metadata written) */
    if (H5Fclose(h->file) < 0 && !rc) rc = h5_fail(h, "H5Fclose", "the file");
    if (!rc && ok && xdmf_path && h5name) rc = write_xdmf(h, xdmf_path, h5name);
    if (rc || !ok) {
        remove(h->path);
        if (xdmf_path) remove(xdmf_path);
    }
    free(h->e);
    free(h->path);
    free(h);
    *ph = NULL;
    return rc;
}
