/*
 * ctl_vtk.h - VTK XML writers of mpmctl, for ParaView: a snapshot as
 * PolyData (.vtp: the particles as vertices, every field the snapshot has
 * as point data, its time and step as field data), a run's snapshots as a
 * collection (.pvd: one DataSet per snapshot with its simulation time) and
 * the background grid as ImageData (.vti).  Four encodings: appended raw
 * binary (the default; UInt64 headers, the machine's byte order, which the
 * file declares), appended base64, appended zlib-compressed blocks, and
 * ASCII (every double printed with 17 significant digits, so that it reads
 * back exactly).
 *
 * Plain C and zlib: no zmq, no protobuf, no jansson; a snapshot comes as
 * the protocol library's decoded mpp_snapshot.  Each writer returns 0 or a
 * negative CTL_E* code (ctl.h) after printing its diagnostic
 * ("mpmctl: cannot write PATH: ..."), and removes a file it could not
 * finish.
 */
#ifndef CTL_VTK_H
#define CTL_VTK_H

#include <stddef.h>
#include <stdint.h>

#include "ctl.h"
#include "mpp_msg.h"

/* How the arrays of a VTK XML file are stored. */
typedef enum {
    CTL_VTK_RAW = 0,    /* appended, encoding="raw" (default) */
    CTL_VTK_BASE64 = 1, /* appended, encoding="base64" */
    CTL_VTK_ZLIB = 2,   /* appended raw, zlib-compressed blocks */
    CTL_VTK_ASCII = 3   /* inline text */
} ctl_vtk_enc;

/* "raw", "base64", "zlib", "ascii". */
const char *ctl_vtk_enc_name(ctl_vtk_enc enc);

/* Writes snapshot s to path as VTK XML PolyData: Points (the positions
 * padded to 3D with zeros), one vertex per particle (Verts), PointData
 * velocity (3 components, padded), stress (the 3x3 symmetric tensor, 9
 * components row-major, from the Voigt sxx syy szz sxy syz sxz), pressure,
 * volume, plastic_strain, deformation_gradient (3x3 row-major; a 1D or 2D
 * F padded with the identity: F_zz = 1 in plane strain), yielded (UInt8),
 * each only when the snapshot has it; FieldData TIME (Float64) and STEP
 * (Int64).  A snapshot without positions is refused (CTL_ECASE, naming
 * output.snapshotFields). */
int ctl_vtk_write_vtp(const char *path, const mpp_snapshot *s, ctl_vtk_enc enc);

/* The background grid of a case. */
typedef struct {
    int dim;           /* 1..3 */
    double origin[3];  /* dim entries used */
    double spacing[3]; /* dim entries used, > 0 */
    uint32_t nodes[3]; /* nodes per axis, dim entries used, >= 1 */
} ctl_vtk_grid;

/* Writes the grid as VTK XML ImageData: WholeExtent 0..nodes-1 per axis
 * (0..0 on the axes the case lacks, whose spacing is the first axis'),
 * Origin and Spacing padded to 3D, and the point array "node" (Int64, the
 * node's index, x fastest). */
int ctl_vtk_write_vti(const char *path, const ctl_vtk_grid *g, ctl_vtk_enc enc);

/* Writes a ParaView collection: n DataSets, files[i] (relative to the
 * .pvd; written as given, so they must need no XML escaping: the caller
 * makes them from [A-Za-z0-9._-]) at timestep times[i] (17 digits). */
int ctl_vtk_write_pvd(const char *path, const char *const *files, const double *times, size_t n);

/* ---- the commands built on them (ctl_export.c) ------------------------ */

/* What `export` writes the snapshots as. */
typedef enum {
    CTL_EXPORT_VTK = 0, /* <name>_<step>.vtp and <name>.pvd (default) */
    CTL_EXPORT_HDF5 = 1 /* <name>.h5 and <name>.xdmf (ctl_h5.h) */
} ctl_export_format;

/* `mpmctl export ID DIR`: every recorded snapshot of run id as
 * DIR/<name>_<step>.vtp (enc; <step> zero-padded to the width of the
 * largest, so that the names sort in time order) and DIR/<name>.pvd with
 * their times, or (CTL_EXPORT_HDF5) DIR/<name>.h5 and DIR/<name>.xdmf;
 * DIR/energy.csv (as `energy --csv`), and with grid DIR/grid.vti; DIR is
 * created if missing.  Progress on stderr when it is a terminal, a summary
 * line at the end.  A run without recorded snapshots is CTL_ECASE with
 * the case fields that record them. */
int ctl_export(ctl_conn *c, uint64_t id, const char *dir, ctl_export_format fmt, ctl_vtk_enc enc,
               int grid);

/* `mpmctl plot ID -o FILE`: the energy curves (kinetic, strain, total; the
 * balance error in % in a second panel) drawn by gnuplot into out, with
 * terminal (NULL: from the extension, .png/.svg/.pdf; only letters,
 * digits, spaces and ",._-" allowed).  Without gnuplot on PATH: an error
 * naming the Debian package gnuplot-nox. */
int ctl_plot(ctl_conn *c, uint64_t id, const char *out, const char *terminal);

#endif
