#!/usr/bin/python3
"""h5_check.py - reads `mpmctl export --format hdf5`'s files with Debian's
python3-h5py and xml.etree, and compares them with the snapshots fetched
over the protocol (the JSON `mpmctl snapshot -o F.json` writes, one
JSONDIR/STEP.json per recorded step).

Usage: h5_check.py FILE.h5 FILE.xdmf JSONDIR [PRESSURE]
  * every group /snapshots/STEP holds the snapshot of that step: its
    attributes step and t, and each field the snapshot has as a dataset of
    the documented shape with bitwise equal values (x, v: n x dim; stress:
    n x 6; pressure, mean_stress, volume, plastic_strain: n;
    deformation_gradient: n x dim*dim; yielded: n, 0/1), and no other;
  * /steps and /times list them in order; the groups' names have one width;
  * the XDMF parses, is a temporal collection with one grid per snapshot,
    each with Time equal to the snapshot's t, a Polyvertex topology of n
    elements, and every DataItem naming a dataset of this file that exists
    with the Dimensions the item states;
  * PRESSURE: the first snapshot's pressure is exactly PRESSURE at every
    particle, and mean_stress its negative in every snapshot.
Prints "ok ..." lines; exit 1 at the first difference.  No XDMF reader is
used: Debian's python3-vtk9 has none (vtkXdmfReader, vtkXdmf3Reader).
"""
import json
import os
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np


class Mismatch(Exception):
    pass


def same(name, got, want):
    got = np.asarray(got, dtype=float).ravel()
    want = np.asarray(want, dtype=float).ravel()
    if got.shape != want.shape:
        raise Mismatch("%s: %d values, the snapshot has %d" % (name, got.size, want.size))
    bad = ~((got == want) | (np.isnan(got) & np.isnan(want)))
    if bad.any():
        i = int(np.argmax(bad))
        raise Mismatch("%s[%d]: HDF5 %r, snapshot %r" % (name, i, got[i], want[i]))
    return got.size


# JSON key -> (dataset, columns as a function of dim; 0: a vector of n)
FIELDS = {
    "x": ("x", lambda d: d),
    "v": ("v", lambda d: d),
    "stress": ("stress", lambda d: 6),
    "pressure": ("pressure", lambda d: 0),
    "meanStress": ("mean_stress", lambda d: 0),
    "volume": ("volume", lambda d: 0),
    "plasticStrain": ("plastic_strain", lambda d: 0),
    "deformationGradient": ("deformation_gradient", lambda d: d * d),
}


def check_h5(h5, jsondir, pressure):
    snaps = h5["snapshots"]
    names = list(snaps.keys())
    if len(set(len(n) for n in names)) != 1:
        raise Mismatch("group names of several widths: %s" % names)
    steps = list(h5["steps"][()])
    times = list(h5["times"][()])
    if [int(n) for n in names] != steps or steps != sorted(steps):
        raise Mismatch("/steps %s, groups %s" % (steps, names))
    values = 0
    for k, name in enumerate(names):
        g = snaps[name]
        snap = json.load(open(os.path.join(jsondir, "%d.json" % int(name))))
        n, dim = int(snap["n"]), int(snap["dim"])
        if int(g.attrs["step"]) != int(snap["step"]) or float(g.attrs["t"]) != float(snap["t"]):
            raise Mismatch("%s: step %r t %r, snapshot %r %r"
                           % (name, g.attrs["step"], g.attrs["t"], snap["step"], snap["t"]))
        if times[k] != float(snap["t"]):
            raise Mismatch("/times[%d] %r, snapshot t %r" % (k, times[k], snap["t"]))
        want = set()
        for key, (ds, cols) in FIELDS.items():
            if key not in snap:
                continue
            want.add(ds)
            c = cols(dim)
            shape = (n, c) if c else (n,)
            if g[ds].shape != shape or g[ds].dtype != np.float64:
                raise Mismatch("%s/%s: %s %s, want %s float64"
                               % (name, ds, g[ds].shape, g[ds].dtype, shape))
            values += same("%s/%s" % (name, ds), g[ds][()], [float(v) for v in snap[key]])
        if "yielded" in snap:
            want.add("yielded")
            values += same(name + "/yielded", g["yielded"][()],
                           [1.0 if b else 0.0 for b in snap["yielded"]])
        if dim == 1:
            want.add("points")
            pts = np.zeros((n, 3))
            pts[:, 0] = [float(v) for v in snap["x"]]
            values += same(name + "/points", g["points"][()], pts)
        if set(g.keys()) != want:
            raise Mismatch("%s: datasets %s, the snapshot has %s"
                           % (name, sorted(g.keys()), sorted(want)))
        if "pressure" in g and not (g["mean_stress"][()] == -g["pressure"][()]).all():
            raise Mismatch("%s: mean_stress is not -pressure" % name)
        if pressure is not None and k == 0 and not (g["pressure"][()] == pressure).all():
            raise Mismatch("%s: pressure %s, want %r" % (name, g["pressure"][()], pressure))
    return names, values


def check_xdmf(path, h5, h5path):
    root = ET.parse(path).getroot()
    if root.tag != "Xdmf" or root.get("Version") != "3.0":
        raise Mismatch("%s: root %s version %r" % (path, root.tag, root.get("Version")))
    coll = root.find("Domain/Grid")
    if coll is None or coll.get("GridType") != "Collection" or \
            coll.get("CollectionType") != "Temporal":
        raise Mismatch("%s: no temporal collection" % path)
    grids = coll.findall("Grid")
    names = list(h5["snapshots"].keys())
    if len(grids) != len(names):
        raise Mismatch("%s: %d grids, %d snapshots" % (path, len(grids), len(names)))
    items = 0
    for grid, name in zip(grids, names):
        g = h5["snapshots"][name]
        t = float(grid.find("Time").get("Value"))
        if t != float(g.attrs["t"]):
            raise Mismatch("%s: grid %s Time %r, snapshot t %r" % (path, name, t, g.attrs["t"]))
        topo = grid.find("Topology")
        n = g["x"].shape[0]
        if topo.get("TopologyType") != "Polyvertex" or int(topo.get("NumberOfElements")) != n:
            raise Mismatch("%s: grid %s topology %s" % (path, name, topo.attrib))
        if grid.find("Geometry") is None:
            raise Mismatch("%s: grid %s has no geometry" % (path, name))
        for item in grid.iter("DataItem"):
            ref = item.text.strip()
            fname, _, ds = ref.partition(":")
            if fname != os.path.basename(h5path) or ds not in h5:
                raise Mismatch("%s: %s names no dataset of %s" % (path, ref, h5path))
            dims = tuple(int(v) for v in item.get("Dimensions").split())
            if h5[ds].shape != dims:
                raise Mismatch("%s: %s Dimensions %s, the dataset is %s"
                               % (path, ref, dims, h5[ds].shape))
            items += 1
    return len(grids), items


def main():
    h5path, xdmf, jsondir = sys.argv[1:4]
    pressure = float(sys.argv[4]) if len(sys.argv) > 4 else None
    try:
        with h5py.File(h5path, "r") as h5:
            names, values = check_h5(h5, jsondir, pressure)
            print("ok h5 %s: %d snapshots (%s .. %s), %d values equal to the snapshots'"
                  % (os.path.basename(h5path), len(names), names[0], names[-1], values))
            if pressure is not None:
                p = h5["snapshots"][names[0]]["pressure"][()]
                m = h5["snapshots"][names[0]]["mean_stress"][()]
                print("ok pressure: step %s pressure %s mean_stress %s"
                      % (names[0], p.tolist(), m.tolist()))
            grids, items = check_xdmf(xdmf, h5, h5path)
            print("ok xdmf %s: %d grids, %d data items, each an existing dataset"
                  % (os.path.basename(xdmf), grids, items))
    except (Mismatch, KeyError, OSError) as e:
        print("MISMATCH: %s" % e)
        sys.exit(1)


if __name__ == "__main__":
    main()
