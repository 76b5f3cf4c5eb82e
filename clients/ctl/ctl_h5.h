/*
 * ctl_h5.h - mpmctl's HDF5 writer, for `mpmctl export ID DIR --format
 * hdf5`: a run's snapshots in one HDF5 file (Debian's serial libhdf5) and
 * an XDMF 3 file beside it that names every dataset with its simulation
 * time, so that ParaView (its XDMF reader) opens the run as a time series
 * of particles, and h5py or any HDF5 tool reads the arrays as they came.
 *
 * Layout of NAME.h5: the attributes run_id and dim; /steps (Int64) and
 * /times (Float64), one entry per snapshot; one group per snapshot,
 * /snapshots/STEP (STEP zero-padded to a common width), with the
 * attributes step and t and a dataset per field the snapshot has, the
 * values exactly as decoded: x, v (n x dim), stress (n x 6, Voigt xx yy
 * zz xy yz xz), pressure, mean_stress, volume, plastic_strain (n),
 * deformation_gradient (n x dim*dim, row-major), yielded (n, UInt8 0/1),
 * and for a 1D run points (n x 3, x padded with zeros) for XDMF, which
 * has no one-coordinate geometry.  Every HDF5 call is checked; a failure
 * names the call and the object, and the files are removed.
 */
#ifndef CTL_H5_H
#define CTL_H5_H

#include <stddef.h>
#include <stdint.h>

#include "mpp_msg.h"

typedef struct ctl_h5 ctl_h5;

/* Creates (truncates) the HDF5 file h5path for run id's snapshots, their
 * group names zero-padded to width digits.  NULL on failure (printed). */
ctl_h5 *ctl_h5_new(const char *h5path, uint64_t id, int width);

/* Adds snapshot s as its group.  A snapshot without positions, or of
 * another dimension than the first, is CTL_ECASE; an HDF5 failure
 * CTL_ESYS (printed). */
int ctl_h5_add(ctl_h5 *h, const mpp_snapshot *s);

/* Writes /steps and /times, closes the file and, when ok and no add
 * failed, writes the XDMF file xdmf_path (naming the HDF5 file by h5name,
 * relative to it).  Returns 0 or a negative CTL_E* code; on any failure
 * both files are removed.  Frees *h and sets it to NULL (accepts NULL). */
int ctl_h5_finish(ctl_h5 **h, int ok, const char *xdmf_path, const char *h5name);

#endif
