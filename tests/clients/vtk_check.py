#!/usr/bin/python3
"""vtk_check.py - reads mpmctl's VTK files with a real VTK reader (Debian's
python3-vtk9) and compares every value with the snapshot fetched over the
protocol (the JSON `mpmctl snapshot -o F.json` writes: the Snapshot in the
protobuf JSON mapping, doubles in their shortest exact form).

Usage: vtk_check.py MANIFEST, one check a line:
  vtp exact|ascii SNAP.json FILE.vtp  vtkXMLPolyDataReader; every field
  pvd exact|ascii FILE.pvd JSONDIR    the collection (xml.etree and
                                      vtkXMLGenericDataObjectReader for each
                                      DataSet); timestep == TimeValue == the
                                      snapshot's t; data == JSONDIR/STEP.json;
                                      the file names sort in step order
  vti exact|ascii FILE.vti CASE.json  vtkXMLImageDataReader: origin, spacing,
                                      dimensions of the case's grid
  pressure P TOL FILE.vtp             every particle's pressure is P within
                                      TOL relative (compression positive)
                                      and mean_stress is -pressure exactly
Prints one "ok ..." line per check; exit 1 with the first difference.
"exact": bitwise equal doubles (binary encodings); "ascii": equal to the
printed 17 digits, which read back exactly too, so also compared with ==.
"""
import json
import os
import sys
import xml.etree.ElementTree as ET

import vtk
from vtk.util import numpy_support as ns


class Mismatch(Exception):
    pass


def arr(a):
    return ns.vtk_to_numpy(a)


def same(name, got, want):
    got = [float(v) for v in got]
    want = [float(v) for v in want]
    if len(got) != len(want):
        raise Mismatch("%s: %d values, the snapshot has %d" % (name, len(got), len(want)))
    for i, (g, w) in enumerate(zip(got, want)):
        if not (g == w or (g != g and w != w)):
            raise Mismatch("%s[%d]: VTK %r, snapshot %r" % (name, i, g, w))
    return len(got)


def pad3(vals, n, dim):
    out = []
    for i in range(n):
        row = vals[i * dim:(i + 1) * dim]
        out.extend(list(row) + [0.0] * (3 - dim))
    return out


def voigt9(vals, n):
    m = [0, 3, 5, 3, 1, 4, 5, 4, 2]
    out = []
    for i in range(n):
        out.extend(vals[i * 6 + k] for k in m)
    return out


def f9(vals, n, dim):
    out = []
    for i in range(n):
        for r in range(3):
            for c in range(3):
                if r < dim and c < dim:
                    out.append(vals[i * dim * dim + r * dim + c])
                else:
                    out.append(1.0 if r == c else 0.0)
    return out


def check_polydata(pd, snap, label):
    n = int(snap.get("n", 0))
    dim = int(snap.get("dim", 0))
    if pd.GetNumberOfPoints() != n or pd.GetNumberOfVerts() != n:
        raise Mismatch("%s: %d points, %d verts, the snapshot has %d particles"
                       % (label, pd.GetNumberOfPoints(), pd.GetNumberOfVerts(), n))
    fd = pd.GetFieldData()
    t = fd.GetArray("TimeValue").GetValue(0)
    step = fd.GetArray("STEP").GetValue(0)
    # the reader itself takes TimeValue as the data set's time step
    if READER_TIMES.get(id(pd)) != (t,):
        raise Mismatch("%s: the reader's TIME_STEPS %r, TimeValue %r"
                       % (label, READER_TIMES.get(id(pd)), t))
    if t != float(snap.get("t", 0)) or step != int(snap.get("step", 0)):
        raise Mismatch("%s: TimeValue %r STEP %r, snapshot t %r step %r"
                       % (label, t, step, snap.get("t"), snap.get("step")))
    count = same(label + " Points", arr(pd.GetPoints().GetData()).ravel(), pad3(snap["x"], n, dim))
    # every vertex is its particle
    conn = pd.GetVerts().GetConnectivityArray()
    offs = pd.GetVerts().GetOffsetsArray()
    same(label + " connectivity", arr(conn), range(n))
    same(label + " offsets", arr(offs), range(n + 1))
    want = {}
    if "v" in snap:
        want["velocity"] = (3, pad3(snap["v"], n, dim))
    if "stress" in snap:
        want["stress"] = (9, voigt9(snap["stress"], n))
    for key, name in (("pressure", "pressure"), ("meanStress", "mean_stress"), ("volume", "volume"),
                      ("plasticStrain", "plastic_strain")):
        if key in snap:
            want[name] = (1, snap[key])
    if "deformationGradient" in snap:
        want["deformation_gradient"] = (9, f9(snap["deformationGradient"], n, dim))
    if "yielded" in snap:
        want["yielded"] = (1, [1.0 if b else 0.0 for b in snap["yielded"]])
    ptd = pd.GetPointData()
    have = sorted(ptd.GetArrayName(k) for k in range(ptd.GetNumberOfArrays()))
    if have != sorted(want):
        raise Mismatch("%s: point data %s, the snapshot has %s" % (label, have, sorted(want)))
    for name, (nc, vals) in want.items():
        a = ptd.GetArray(name)
        if a.GetNumberOfComponents() != nc:
            raise Mismatch("%s %s: %d components, want %d"
                           % (label, name, a.GetNumberOfComponents(), nc))
        count += same(label + " " + name, arr(a).ravel(), vals)
    if "stress" in snap and ptd.GetTensors() is None:
        raise Mismatch("%s: stress is not the active tensor" % label)
    plastic = sum(1 for v in snap.get("plasticStrain", []) if v != 0)
    return "%d particles, %dD, %d values, plastic %d, fields %s" % (
        n, dim, count, plastic, " ".join(sorted(want)))


# the TIME_STEPS each reader announced, by its output (id)
READER_TIMES = {}


def read_with(reader_cls, path):
    r = reader_cls()
    r.SetFileName(path)
    errs = vtk.vtkStringOutputWindow()
    vtk.vtkOutputWindow.SetInstance(errs)
    r.Update()
    if r.GetErrorCode() or "ERROR" in errs.GetOutput():
        raise Mismatch("%s: the reader failed: %s" % (path, errs.GetOutput().strip()))
    out = r.GetOutput()
    ts = r.GetOutputInformation(0).Get(vtk.vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    READER_TIMES[id(out)] = tuple(ts) if ts is not None else None
    READER_KEEP.append(r)  # the output's id stays its own while the reader lives
    return out


READER_KEEP = []


def check_vtp(snap_path, path):
    snap = json.load(open(snap_path))
    pd = read_with(vtk.vtkXMLPolyDataReader, path)
    return check_polydata(pd, snap, os.path.basename(path))


def check_pvd(path, jsondir):
    root = ET.parse(path).getroot()
    if root.get("type") != "Collection":
        raise Mismatch("%s: VTKFile type %r" % (path, root.get("type")))
    sets = root.find("Collection").findall("DataSet")
    if not sets:
        raise Mismatch("%s: no DataSet" % path)
    base = os.path.dirname(path)
    steps = []
    for ds in sets:
        f = os.path.join(base, ds.get("file"))
        obj = read_with(vtk.vtkXMLGenericDataObjectReader, f)
        if not obj.IsA("vtkPolyData"):
            raise Mismatch("%s: %s is a %s" % (path, f, obj.GetClassName()))
        step = int(obj.GetFieldData().GetArray("STEP").GetValue(0))
        snap = json.load(open(os.path.join(jsondir, "%d.json" % step)))
        ts = float(ds.get("timestep"))
        if ts != float(snap["t"]) or ts != obj.GetFieldData().GetArray("TimeValue").GetValue(0):
            raise Mismatch("%s: timestep %r of %s, snapshot t %r" % (path, ts, f, snap["t"]))
        check_polydata(obj, snap, ds.get("file"))
        steps.append(step)
    if steps != sorted(steps):
        raise Mismatch("%s: steps out of order %s" % (path, steps))
    names = [ds.get("file") for ds in sets]
    if names != sorted(names) or len(set(len(n) for n in names)) != 1:
        raise Mismatch("%s: file names not zero-padded to one width: %s" % (path, names))
    return "%d datasets, steps %s, times equal the snapshots'" % (len(sets), steps)


def check_vti(path, case_path):
    case = json.load(open(case_path))
    g = case["grid"]
    dim = int(g["dim"])
    im = read_with(vtk.vtkXMLImageDataReader, path)
    origin = list(g.get("origin", [0] * dim)) + [0.0] * (3 - dim)
    spacing = list(g["spacing"]) + [float(g["spacing"][0])] * (3 - dim)
    dims = [int(v) for v in g["nodes"]] + [1] * (3 - dim)
    same(path + " origin", im.GetOrigin(), origin)
    same(path + " spacing", im.GetSpacing(), spacing)
    if list(im.GetDimensions()) != dims:
        raise Mismatch("%s: dimensions %s, the case's nodes %s" % (path, im.GetDimensions(), dims))
    same(path + " node", arr(im.GetPointData().GetArray("node")), range(dims[0] * dims[1] * dims[2]))
    # a node position: the last node sits at origin + (nodes - 1) spacing
    p = im.GetPoint(im.GetNumberOfPoints() - 1)
    same(path + " last node", p, [origin[k] + (dims[k] - 1) * spacing[k] for k in range(3)])
    return "grid %s nodes, origin %s, spacing %s" % (dims, origin, spacing)


def check_pressure(want, tol, path):
    pd = read_with(vtk.vtkXMLPolyDataReader, path)
    p = arr(pd.GetPointData().GetArray("pressure"))
    m = arr(pd.GetPointData().GetArray("mean_stress"))
    for i, (pi, mi) in enumerate(zip(p, m)):
        if not abs(pi - want) <= tol * abs(want) or mi != -pi:
            raise Mismatch("%s: particle %d: pressure %r, mean_stress %r, want %r and its negative"
                           % (path, i, pi, mi, want))
    return "%d particles: pressure %r, mean_stress %r" % (len(p), float(p[0]), float(m[0]))


def main():
    ok = True
    for line in open(sys.argv[1]):
        w = line.split()
        if not w:
            continue
        try:
            if w[0] == "vtp":
                what = check_vtp(w[2], w[3])
            elif w[0] == "pvd":
                what = check_pvd(w[2], w[3])
            elif w[0] == "pressure":
                what = check_pressure(float(w[1]), float(w[2]), w[3])
            elif w[0] == "vti":
                what = check_vti(w[3], w[2]) if w[2].endswith(".json") else check_vti(w[2], w[3])
            else:
                raise Mismatch("unknown check %r" % w[0])
            f = w[2] if w[0] == "pvd" else w[-1] if w[0] == "pressure" else w[3]
            print("ok %s %s %s: %s" % (w[0], w[1], os.path.basename(f), what))
        except Mismatch as e:
            print("MISMATCH %s: %s" % (" ".join(w), e))
            ok = False
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
