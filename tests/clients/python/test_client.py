#!/usr/bin/python3
"""The Python client (clients/python/mpmd) against a real mpmd.

Run by tests/clients/t_python_client.c, which starts the daemon and passes, in the
environment: MPMD_TEST_ENDPOINT (its control socket), MPMD_TEST_DIR (a
scratch directory), MPMCTL_BIN (the real mpmctl, whose output the client's
arrays must equal bit for bit) and, for the CURVE phase, MPMD_TEST_KEYS (a
directory with the key directories made by mpmctl keygen: a/ authorized,
u/ unknown, srv/server.pub).  Usage: test_client.py PHASE, PHASE one of
api, stop, kill (the daemon, MPMD_TEST_PID, is stopped during a watch),
curve, pip (the package pip installed into a virtual environment:
MPMD_TEST_VENV; the conveniences: wait, the context manager, the error
classes, field paths, the notebook display, type hints, and the pressure
of a compressed particle).  Plain asserts; each check prints a line; exit
status 0 only if all passed.
"""

import json
import os
import signal
import stat
import subprocess
import sys
import time
import traceback

import numpy as np

import mpmd
from mpmd import MpmdError

EP = os.environ.get("MPMD_TEST_ENDPOINT", "")
DIR = os.environ.get("MPMD_TEST_DIR", "/tmp")
CTL = os.environ.get("MPMCTL_BIN", "bin/mpmctl")
BAR = "proto/examples/bar1d_gimp.json"


def log(*a):
    print("   ", *a, flush=True)


def bar_dict(name, steps=None, every=10, snapshot_every=0, record=False, at_rest=False):
    with open(BAR) as f:
        c = json.load(f)
    c["name"] = name
    if steps:
        del c["endTime"]
        c["steps"] = steps
    out = c.setdefault("output", {})
    out["energyEvery"] = every
    if snapshot_every:
        out["snapshotEvery"] = snapshot_every
    if record:
        out["recordSnapshots"] = True
    if at_rest:  # nothing moves, so it runs as long as asked
        del c["bodies"][0]["points"]["v"]
    return c


def ctl(*args):
    """mpmctl --endpoint EP ARGS: its stdout (fails the check on exit != 0)."""
    r = subprocess.run(
        [CTL, "--endpoint", EP, "--timeout", "30", *args],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, "mpmctl %s: exit %d: %s" % (" ".join(args), r.returncode, r.stderr)
    return r.stdout


def jnum(v):
    """A JSON-mapping number (floats as numbers or "NaN"/"Infinity", 64-bit
    integers as strings) as a Python number."""
    if isinstance(v, str):
        return float(v) if v in ("NaN", "Infinity", "-Infinity") else int(v)
    return v


def same(a, b):
    """Equal to the bit (NaN equal to NaN)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


def expect_error(code, field, fn, *args, **kw):
    try:
        fn(*args, **kw)
    except MpmdError as e:
        assert e.code == code, "expected %s, got %r" % (code, e)
        if field is not None:
            assert e.field == field, "expected field %r, got %r" % (field, e)
        assert e.message, "an error without a message: %r" % e
        return e
    raise AssertionError("%s did not raise %s" % (getattr(fn, "__name__", fn), code))


def check_series(events, run_samples=None):
    """The Energy events: seq 0, 1, 2, ... exactly once; one Finished, last."""
    seqs = [e.seq for e in events if isinstance(e, mpmd.Energy)]
    assert seqs == list(range(len(seqs))), "energy seqs not 0..n-1: %s" % seqs[:50]
    fins = [i for i, e in enumerate(events) if isinstance(e, mpmd.Finished)]
    assert fins == [len(events) - 1], "Finished at %s of %d events" % (fins, len(events))
    live = [e.stream_seq for e in events if e.stream_seq is not None]
    assert live == sorted(live) and len(set(live)) == len(live), "stream seqs out of order: %s" % live
    if run_samples is not None:
        assert len(seqs) == run_samples, "%d samples watched, the run has %d" % (len(seqs), run_samples)
    return seqs


# ---- phase api ------------------------------------------------------------------


def t_submit_watch(c, st):
    """submit a dict, a path and a message; watch the first to its end."""
    j1 = c.submit(bar_dict("py-dict", snapshot_every=500, record=True))
    j2 = c.submit(BAR)
    msg = mpmd.case_message(bar_dict("py-msg", steps=400, every=20))
    assert isinstance(msg, mpmd.pb.Case)
    j3 = c.submit(msg)
    assert j1.job_id > 0 and j2.job_id == j1.job_id + 1 and j3.job_id == j2.job_id + 1, (j1, j2, j3)
    log("submitted jobs %d (dict), %d (path), %d (message)" % (j1.job_id, j2.job_id, j3.job_id))
    events = list(c.watch(j1))
    fin = events[-1]
    assert isinstance(fin, mpmd.Finished) and fin.status == "FINISHED", fin
    run = c.run(j1)
    seqs = check_series(events, run.energy_samples)
    assert run.status == "FINISHED" and run.name == "py-dict", run
    kinds = {}
    for e in events:
        kinds[type(e).__name__] = kinds.get(type(e).__name__, 0) + 1
    log("watch %d: %d events %s, energy seq 0..%d, %s (from stream: %s)"
        % (j1.job_id, len(events), kinds, seqs[-1], fin.status, fin.from_stream))
    # the watched samples are the stored ones, to the bit
    e = c.energy(j1)
    w = [x for x in events if isinstance(x, mpmd.Energy)]
    assert len(e) == len(w)
    for name in ("t", "kinetic", "strain", "total", "mass"):
        assert same(e[name], [getattr(x, name) for x in w]), name
    assert same(e["momentum"], np.array([x.momentum for x in w]))
    assert (e["step"] == [x.step for x in w]).all()
    for j in (j2, j3):
        f = list(c.watch(j))[-1]
        assert f.status == "FINISHED", (j, f)
    r3 = c.run(j3)
    assert r3.name == "py-msg" and r3.steps == 400 and r3.energy_samples == 21, r3
    # watched from its start (most likely live: 150000 steps take about
    # 0.2 s, 3 s under the sanitizers): Progress and Snapshot events,
    # Finished FINISHED last
    j4 = c.submit(bar_dict("py-live", steps=150000, every=5000, snapshot_every=50000,
                           at_rest=True))
    events = list(c.watch(j4))
    fin = events[-1]
    assert fin.status == "FINISHED" and fin.steps == 150000, fin
    seqs = check_series(events, 31)
    for e in events:
        if isinstance(e, mpmd.Snapshot):
            assert e.step % 50000 == 0 and e.x.shape == (13, 1), e
        if isinstance(e, mpmd.Progress):
            assert 0 <= e.step <= 150000 and e.steps_total == 150000, e
    kinds = {}
    for e in events:
        kinds[type(e).__name__] = kinds.get(type(e).__name__, 0) + 1
    log("watch %d from its start: %s, energy seq 0..%d, %s (from stream: %s)"
        % (j4.job_id, kinds, seqs[-1], fin.status, fin.from_stream))
    st.update(j1=j1, j2=j2, j3=j3)


def t_energy_equals_mpmctl(c, st):
    """energy(id) equals `mpmctl energy ID --json` exactly."""
    j = st["j1"]
    e = c.energy(j)
    lines = ctl("energy", str(j.run_id), "--json").splitlines()
    assert len(lines) == len(e), "%d lines, %d rows" % (len(lines), len(e))
    camel = {
        "externalWork": "external_work", "plasticWork": "plastic_work",
        "dampingWork": "damping_work", "frictionWork": "friction_work",
        "prescribedWork": "prescribed_work", "balanceError": "balance_error",
        "angularMomentum": "angular_momentum",
    }
    scalars = ("t", "kinetic", "strain", "potential", "external_work", "total", "mass",
               "plastic_work", "damping_work", "friction_work", "prescribed_work", "balance_error")
    for i, line in enumerate(lines):
        js = json.loads(line)
        row = e[i]
        got = {camel.get(k, k): v for k, v in js.items()}
        assert jnum(got["seq"]) == row["seq"] and jnum(got.get("step", 0)) == row["step"], (i, js)
        for n in scalars:  # an absent field is 0 in both
            assert same(jnum(got.get(n, 0.0)), row[n]), (i, n, got.get(n), row[n])
        assert same([jnum(x) for x in got["momentum"]], row["momentum"]), (i, js)
        assert "angular_momentum" not in got and "angular_momentum" not in e.dtype.names  # 1D
    log("energy(%d): %d rows x %d fields, every one equal to mpmctl energy --json"
        % (j.run_id, len(e), len(e.dtype.names)))
    assert e["seq"].tolist() == list(range(len(e)))
    vcm = e["momentum"][:, 0] / e["mass"]
    assert np.isfinite(vcm).all() and abs(vcm[0]) > 0


def snapshot_json(run_id, step=None):
    path = os.path.join(DIR, "snap-%d-%s.json" % (run_id, step))
    args = ["snapshot", str(run_id), "-o", path]
    if step is not None:
        args += ["--step", str(step)]
    ctl(*args)
    with open(path) as f:
        return json.load(f)


def t_snapshot_equals_mpmctl(c, st):
    """snapshot(id[, step]) equals `mpmctl snapshot ID -o x.json` exactly."""
    j = st["j1"]
    run = c.run(j)
    assert run.snapshot_steps, "no recorded snapshots: %r" % run
    for step in (None, run.snapshot_steps[0]):
        s = c.snapshot(j, step)
        js = snapshot_json(j.run_id, step)
        n, dim = jnum(js["n"]), jnum(js["dim"])
        assert s.n == n == 13 and s.dim == dim == 1, (s.n, s.dim, js)
        assert s.step == jnum(js["step"]) and same(s.t, js["t"]), (s.step, js["step"])
        assert s.step == (run.snapshot_steps[-1] if step is None else step)
        assert s.x.shape == (n, dim) and s.v.shape == (n, dim) and s.stress.shape == (n, 6)
        assert s.pressure.shape == (n,) and s.volume.shape == (n,)
        assert same(s.x.ravel(), [jnum(x) for x in js["x"]])
        assert same(s.v.ravel(), [jnum(x) for x in js["v"]])
        assert same(s.stress.ravel(), [jnum(x) for x in js["stress"]])
        assert same(s.pressure, [jnum(x) for x in js["pressure"]])
        assert same(s.mean_stress, [jnum(x) for x in js["meanStress"]])
        assert (s.mean_stress == -s.pressure).all()
        assert same(s.volume, [jnum(x) for x in js["volume"]])
        assert s.F is None and s.plastic_strain is None and s.yielded is None
        log("snapshot(%d, %s): step %d, x %s v %s stress %s, equal to mpmctl snapshot -o .json"
            % (j.run_id, step, s.step, s.x.shape, s.v.shape, s.stress.shape))
    e = expect_error("NOT_FOUND", "step", c.snapshot, j, run.snapshot_steps[0] + 1)
    log("snapshot at a step without one: %s" % e)


def t_2d_arrays_equal_mpmctl(c, st):
    """2D, Neo-Hookean (the particles carry F): energy with the angular
    momentum, and a snapshot with F (n, 2, 2), equal to mpmctl's."""
    case = {
        "name": "py-2d",
        "grid": {"dim": 2, "spacing": [0.05, 0.05], "nodes": [21, 21]},
        "method": "MPM", "update": "USF", "dt": 0.001, "steps": 200,
        "materials": [{"model": "NEO_HOOKEAN", "youngsModulus": 1, "poissonRatio": 0.2,
                       "density": 1}],
        "bodies": [{"box": {"lo": [0.3, 0.3], "hi": [0.7, 0.7]}, "velocity": [0.01, 0.005],
                    "ppc": 2}],
        "output": {"energyEvery": 20, "snapshotEvery": 100, "recordSnapshots": True},
    }
    j = c.submit(case)
    fin = list(c.watch(j))[-1]
    assert fin.status == "FINISHED", fin
    e = c.energy(j)
    lines = [json.loads(x) for x in ctl("energy", str(j.run_id), "--json").splitlines()]
    assert len(lines) == len(e) == 11 and e["momentum"].shape == (11, 2), e.shape
    assert e["angular_momentum"].shape == (11, 1)
    for i, js in enumerate(lines):
        assert same([jnum(x) for x in js["momentum"]], e["momentum"][i])
        assert same([jnum(x) for x in js["angularMomentum"]], e["angular_momentum"][i])
        assert same(jnum(js["total"]), e["total"][i]) and same(jnum(js["strain"]), e["strain"][i])
    s = c.snapshot(j, 100)
    js = snapshot_json(j.run_id, 100)
    n = jnum(js["n"])
    assert s.dim == 2 and s.n == n == 256 and s.x.shape == (n, 2) and s.F.shape == (n, 2, 2)
    assert same(s.x.ravel(), [jnum(x) for x in js["x"]])
    assert same(s.F.ravel(), [jnum(x) for x in js["deformationGradient"]])
    assert same(s.stress.ravel(), [jnum(x) for x in js["stress"]])
    # F row-major: F[i] = [[Fxx, Fxy], [Fyx, Fyy]], near the identity here
    assert np.abs(s.F - np.eye(2)).max() < 0.1
    log("2D Neo-Hookean: energy (11 x momentum 2, angular momentum 1) and snapshot "
        "(x %s, F %s, stress %s) equal to mpmctl's" % (s.x.shape, s.F.shape, s.stress.shape))


def t_runs_run_cancel(c, st):
    j1, j2, j3 = st["j1"], st["j2"], st["j3"]
    rs = c.runs()
    ids = [r.run_id for r in rs]
    assert ids == [j3.run_id + 1, j3.run_id, j2.run_id, j1.run_id], ids
    assert rs.next_before_run_id is None
    page = c.runs(limit=2, before=j3.run_id + 1)
    assert [r.run_id for r in page] == [j3.run_id, j2.run_id] and page.next_before_run_id == j2.run_id, page
    rest = c.runs(before=page.next_before_run_id)
    assert [r.run_id for r in rest] == [j1.run_id], rest
    assert all(r.status == "FINISHED" for r in c.runs(status="FINISHED"))
    assert c.runs(status="RUNNING") == []
    expect_error("USAGE", "status", c.runs, status="DONE")
    r = c.run(j1, with_case=True)
    assert r.case["name"] == "py-dict" and r.case["method"] == "GIMP" and r.method == "GIMP", r.case
    assert r.owner == "local" and r.dim == 1 and r.particles == 13 and r.ended
    assert r.last_energy is not None and r.last_energy.seq == r.energy_samples - 1
    assert c.run(j1).case is None
    assert c.status(j1).status == "FINISHED"
    e = expect_error("CONFLICT", None, c.cancel, j1)
    log("cancel of a finished job: %s" % e)
    # long jobs cancelled while they run: once the watch has the Finished,
    # run() says CANCELLED (the worker enqueues the row's end before it
    # publishes Finished, and a read waits for its run's writes; the pool's
    # live status no longer overrides an ended row)
    for k in range(20):
        j = c.submit(bar_dict("py-long", steps=99000000, every=10000, at_rest=True))
        r = c.cancel(j)
        assert r.status in ("QUEUED", "RUNNING", "CANCELLED"), r
        fin = list(c.watch(j))[-1]
        assert fin.status == "CANCELLED", fin
        r = c.run(j)
        assert r.status == "CANCELLED" and r.finished_at, (k, r)
        assert c.status(j).status == "CANCELLED", k
    log("runs: %d listed, pages of 2 (%s), run/status/cancel ok" % (len(rs), page.next_before_run_id))


def wait_samples(c, job, n):
    end = time.monotonic() + 60
    while time.monotonic() < end:
        if c.run(job).energy_samples >= n:
            return
        time.sleep(0.05)
    raise AssertionError("job %d: fewer than %d samples after 60 s" % (job.job_id, n))


def t_late_join(c, st):
    """Joining a running job: its history, then the live tail, no gap, no
    duplicate; cancelled from the loop; the same series as the store."""
    for drop in (0, 3):
        c._drop_every = drop  # 3: the stream "loses" every third sample
        j = c.submit(bar_dict("py-late-%d" % drop, steps=99000000, every=5000,
                              snapshot_every=0 if drop else 10000, at_rest=True))
        wait_samples(c, j, 5)
        events, live, cancelled = [], 0, False
        for ev in c.watch(j):
            events.append(ev)
            if isinstance(ev, mpmd.Energy) and ev.stream_seq is not None:
                live += 1
                if live == 10 and not cancelled:
                    c.cancel(j)
                    cancelled = True
        c._drop_every = 0
        fin = events[-1]
        assert fin.status == "CANCELLED", fin
        seqs = check_series(events, c.run(j).energy_samples)
        hist = sum(1 for e in events if isinstance(e, mpmd.Energy) and e.stream_seq is None)
        assert hist >= 5 and live >= 10, (hist, live)
        e = c.energy(j)
        assert e["seq"].tolist() == seqs
        w = [x for x in events if isinstance(x, mpmd.Energy)]
        assert same(e["t"], [x.t for x in w]) and same(e["total"], [x.total for x in w])
        snaps = [x for x in events if isinstance(x, mpmd.Snapshot)]
        if not drop:  # snapshots stream while somebody watches
            assert snaps, "no snapshot streamed to a watcher"
            for k, s in enumerate(snaps):
                # every 10000 steps, and the end's (the cancel's step) last
                at = s.step % 10000 == 0 or (k == len(snaps) - 1 and s.step == fin.steps)
                assert at and s.x.shape == (13, 1) and s.stress.shape == (13, 6), s
                assert s.stream_seq is not None
        log("late join%s: %d from the history, %d live, seq 0..%d without gap, %d snapshots, %s"
            % (" (every 3rd streamed sample dropped)" if drop else "", hist, live, seqs[-1],
               len(snaps), fin.status))
    # a stream that never delivers (a wrong stream endpoint): the samples
    # come from the store at each quiet second, the end from Status
    with mpmd.Client(EP, timeout=30, stream="ipc://%s/no-stream" % DIR) as m:
        j = m.submit(bar_dict("py-mute", steps=99000000, every=5000, at_rest=True))
        events, cancelled = [], False
        for ev in m.watch(j):
            events.append(ev)
            if isinstance(ev, mpmd.Energy) and ev.seq >= 3 and not cancelled:
                m.cancel(j)
                cancelled = True
        fin = events[-1]
        assert fin.status == "CANCELLED" and not fin.from_stream, fin
        seqs = check_series(events, m.run(j).energy_samples)
        assert all(e.stream_seq is None for e in events)
        log("mute stream: %d samples from the store, then %s (from the record)"
            % (len(seqs), fin.status))
    # joining after the end: the history and a Finished made from the record
    events = list(c.watch(st["j2"]))
    fin = events[-1]
    assert fin.status == "FINISHED" and not fin.from_stream, fin
    check_series(events, c.run(st["j2"]).energy_samples)
    assert fin.energy is not None and fin.energy.seq == len(events) - 2
    log("watch of an ended job: %d samples, then Finished %s" % (len(events) - 1, fin.status))


def t_errors(c, st):
    bad = bar_dict("py-bad")
    bad["materials"][0]["youngsModulus"] = -1
    e = expect_error("INVALID_CASE", "materials[0].youngsModulus", c.submit, bad)
    assert "must be > 0" in e.message and "-1" in e.message, e
    log("bad case: %s" % e)
    assert isinstance(e, Exception) and str(e).startswith("INVALID_CASE: materials[0].youngsModulus")
    e = expect_error("INVALID_CASE", "grid.dimension", c.submit, {"grid": {"dimension": 2}})
    log("unparseable case: %s" % e)
    bad = bar_dict("py-bad")
    bad["bodies"].append({"ppc": -1})
    e = expect_error("INVALID_CASE", "bodies[1].ppc", c.submit, bad)
    log("unparseable case, a repeated message's field: %s" % e)
    e = expect_error("NOT_FOUND", "runId", c.run, 999999)
    assert "999999" in e.message
    log("unknown run: %s" % e)
    expect_error("NOT_FOUND", "runId", c.energy, 999999)
    expect_error("NOT_FOUND", "jobId", c.status, 999999)
    expect_error("NOT_FOUND", "jobId", c.cancel, 999999)
    e = expect_error("NOT_FOUND", "jobId", lambda: list(c.watch(999999)))
    log("watch of an unknown job: %s" % e)
    expect_error("USAGE", None, c.run, 0)
    expect_error("USAGE", None, c.run, "x")
    expect_error("USAGE", None, c.submit, 42)
    expect_error("USAGE", None, c.submit, os.path.join(DIR, "missing.json"))
    # the client still works after errors
    assert c.ping()["schema_version"] == mpmd.SCHEMA_VERSION


def t_timeout(c, st):
    """Nobody at the endpoint: TIMEOUT, for a request and for a watch."""
    ep = "ipc://%s/nobody" % DIR
    t0 = time.monotonic()
    with mpmd.Client(ep, timeout=1) as n:
        e = expect_error("TIMEOUT", None, n.ping)
        assert "is mpmd running" in e.message
        expect_error("TIMEOUT", None, lambda: list(n.watch(1)))
    log("no daemon at %s: %s (%.1f s)" % (ep, e, time.monotonic() - t0))
    expect_error("USAGE", None, mpmd.Client, EP, timeout=0)


def t_env_endpoint(c, st):
    """MPMD_ENDPOINT, and the stream endpoint derived as mpmctl does."""
    os.environ["MPMD_ENDPOINT"] = EP
    try:
        with mpmd.Client() as d:
            assert d.endpoint == EP and d.ping()["server_version"]
            assert d.stream_endpoint() == EP + ".stream", d.stream_endpoint()
    finally:
        del os.environ["MPMD_ENDPOINT"]
    from mpmd import endpoint as ep

    assert ep.derive_stream("tcp://h:5555") == "tcp://h:5556"
    assert ep.stream_for_client("tcp://0.0.0.0:7001", "tcp://far:7000") == "tcp://far:7001"
    assert ep.stream_for_client("tcp://10.1.2.3:7001", "tcp://far:7000") == "tcp://10.1.2.3:7001"
    assert ep.is_local("tcp://127.0.0.1:1") and not ep.is_local("tcp://example.org:1")


# ---- phases stop and kill: the daemon goes away during a watch -------------------


def watch_until_gone(c, sig):
    """Watches a long job and sends the daemon (MPMD_TEST_PID) sig after 3
    live samples; returns the events and the exception the watch ended
    with (None if it ended normally)."""
    pid = int(os.environ["MPMD_TEST_PID"])
    j = c.submit(bar_dict("py-gone-%d" % sig, steps=99000000, every=5000, at_rest=True))
    events, live, sent = [], 0, False
    try:
        for ev in c.watch(j):
            events.append(ev)
            if isinstance(ev, mpmd.Energy) and ev.stream_seq is not None:
                live += 1
                if live == 3 and not sent:
                    os.kill(pid, sig)
                    sent = True
    except MpmdError as e:
        return events, e
    return events, None


def until_timeout(c):
    """Pings until the daemon, shutting down, is gone: TIMEOUT.  Until then
    it may still answer, or drop the connection (DISCONNECTED)."""
    for _ in range(100):
        try:
            c.ping()
        except MpmdError as e:
            if e.code == "TIMEOUT":
                return e
            assert e.code in ("DISCONNECTED", "UNAVAILABLE"), e
        time.sleep(0.1)
    raise AssertionError("the daemon still answers")


def t_stop(c, st):
    """SIGTERM: the watch ends with Finished INTERRUPTED; then TIMEOUT."""
    events, err = watch_until_gone(c, signal.SIGTERM)
    assert err is None, "the watch raised %r" % err
    fin = events[-1]
    assert isinstance(fin, mpmd.Finished) and fin.status == "INTERRUPTED", fin
    seqs = check_series(events)
    log("SIGTERM during a watch: %d samples (seq 0..%d), then Finished %s: %s"
        % (len(seqs), seqs[-1], fin.status, fin.error))
    log("then: %s" % until_timeout(c))


def t_kill(c, st):
    """SIGKILL: the watch raises TIMEOUT (no hang), as does any request."""
    events, err = watch_until_gone(c, signal.SIGKILL)
    # TIMEOUT, or DISCONNECTED when the connection dropped while a request
    # was waiting: a clear error either way, and no hang
    assert err is not None and err.code in ("TIMEOUT", "DISCONNECTED"), \
        "the watch ended with %r" % (err or events[-1])
    seqs = [e.seq for e in events if isinstance(e, mpmd.Energy)]
    assert seqs == list(range(len(seqs))) and len(seqs) >= 3
    log("SIGKILL during a watch: %d samples, then %s" % (len(seqs), err))
    log("then: %s" % until_timeout(c))


# ---- phase curve ---------------------------------------------------------------------


def t_curve(c, st):
    keys = os.environ["MPMD_TEST_KEYS"]
    a, u = os.path.join(keys, "a"), os.path.join(keys, "u")
    with mpmd.Client(EP, keys=a, timeout=20) as ca:
        j = ca.submit(bar_dict("py-curve", steps=300, every=10))
        events = list(ca.watch(j))
        assert events[-1].status == "FINISHED"
        check_series(events, 31)
        pub = ca.curve.public_key
        assert ca.run(j).owner == pub, (ca.run(j).owner, pub)
        # the stream over CURVE: a long job, cancelled once a live sample came
        # (or, if the stream never delivers, after 40 from the store: failed)
        j = ca.submit(bar_dict("py-curve-long", steps=99000000, every=5000, at_rest=True))
        events, live, cancelled = [], 0, False
        for ev in ca.watch(j):
            events.append(ev)
            if isinstance(ev, mpmd.Energy):
                live += ev.stream_seq is not None
                if (live >= 3 or ev.seq >= 40) and not cancelled:
                    ca.cancel(j)
                    cancelled = True
        assert events[-1].status == "CANCELLED" and live >= 3, (live, events[-1])
        check_series(events, ca.run(j).energy_samples)
        log("authorized key %s: submit, watch (%d live samples over CURVE), owner ok"
            % (pub, live))
    with mpmd.Client(EP, keys=u, timeout=20) as cu:
        t0 = time.monotonic()
        e = expect_error("AUTH", None, cu.ping)
        assert "refused this client's key" in e.message and cu.curve.public_key in e.message, e
        log("unknown key: %s (%.2f s)" % (e, time.monotonic() - t0))
    # the environment, as mpmctl reads it
    with open(os.path.join(keys, "srv", "server.pub")) as f:
        spub = f.read().split()[0]
    env = {"MPMD_SERVER_KEY": spub, "MPMD_CLIENT_KEY": os.path.join(a, "mpmd.key")}
    os.environ.update(env)
    try:
        with mpmd.Client(EP, timeout=20) as ce:
            assert ce.curve and ce.ping()["schema_version"] == mpmd.SCHEMA_VERSION
    finally:
        for k in env:
            del os.environ[k]
    log("MPMD_SERVER_KEY (a key) + MPMD_CLIENT_KEY (a file): ok")
    # no key at all: the handshake fails, and the client says so
    home = os.environ.get("HOME")
    os.environ["HOME"] = DIR
    try:
        with mpmd.Client(EP, timeout=20) as cn:
            assert cn.curve is None
            e = expect_error("AUTH", None, cn.ping)
            assert "requires CURVE" in e.message, e
            log("no key: %s" % e)
    finally:
        if home is not None:
            os.environ["HOME"] = home
    # a secret key readable by others is refused before connecting
    loose = os.path.join(DIR, "loose")
    os.makedirs(loose, exist_ok=True)
    for name in ("server.pub", "mpmd.key"):
        src = os.path.join(keys, "srv" if name == "server.pub" else "a", name)
        with open(src) as f, open(os.path.join(loose, name), "w") as g:
            g.write(f.read())
    os.chmod(os.path.join(loose, "mpmd.key"), 0o644)
    e = expect_error("KEYS", None, mpmd.Client, EP, keys=loose)
    assert "0644" in e.message, e
    os.chmod(os.path.join(loose, "mpmd.key"), stat.S_IRUSR | stat.S_IWUSR)
    with mpmd.Client(EP, keys=loose, timeout=20) as cl:
        assert cl.ping()
    expect_error("USAGE", None, mpmd.Client, EP, keys=DIR)  # no server.pub there
    log("key files: mode 0644 refused, 0600 accepted; a directory without server.pub refused")


def t_pip_installed(c, st):
    """The package comes from the virtual environment pip installed it
    into, with its generated mpmd_pb2, type hints and py.typed."""
    import inspect
    import typing

    venv = os.environ["MPMD_TEST_VENV"]
    assert os.path.realpath(mpmd.__file__).startswith(os.path.realpath(venv)), mpmd.__file__
    assert os.path.realpath(mpmd.pb.__file__).startswith(os.path.realpath(venv)), mpmd.pb.__file__
    assert os.path.isfile(os.path.join(os.path.dirname(mpmd.__file__), "py.typed"))
    assert mpmd.SCHEMA_MINOR >= 1 and c.ping()["schema_minor"] == mpmd.SCHEMA_MINOR
    hints = typing.get_type_hints(mpmd.Client.wait)
    assert hints["return"] is mpmd.Run and "timeout" in hints, hints
    for name, fn in inspect.getmembers(mpmd.Client, inspect.isfunction):
        if not name.startswith("_"):
            assert "return" in fn.__annotations__, "Client.%s has no return type" % name
    log("mpmd %s from %s; Client.wait%s" % (mpmd.__name__, os.path.dirname(mpmd.__file__),
                                           inspect.signature(mpmd.Client.wait)))


def t_error_classes(c, st):
    """A class per wire code, each an MpmdError with its code and field."""
    codes = [n for n in mpmd.pb.Error.Code.keys()]
    for code in codes:
        cls = mpmd.ERROR_CLASSES[code]
        e = MpmdError(code, "m", "f")
        assert type(e) is cls and isinstance(e, MpmdError) and e.code == code and e.field == "f"
    e = expect_error("NOT_FOUND", "runId", c.run, 999999)
    assert isinstance(e, mpmd.NotFoundError), type(e)
    try:
        c.submit({"grid": {"dim": 1}, "bodies": [{"box": {"lo": [0, "a"]}}]})
        raise AssertionError("a case that does not parse was accepted")
    except mpmd.InvalidCaseError as e2:
        assert e2.field == "bodies[0].box.lo[1]", e2
        log("parse error: %r" % e2)
    bad = bar_dict("py-bad")
    bad["materials"][0]["density"] = -1
    try:
        c.submit(bad)
        raise AssertionError("a bad density was accepted")
    except mpmd.InvalidCaseError as e3:
        assert e3.field == "materials[0].density", e3
    log("%d wire codes, each its class; NotFoundError, InvalidCaseError with fields" % len(codes))


def t_wait_context_html(c, st):
    """wait() returns the finished run; a timeout says so; the context
    manager closes; a run and a run list render as HTML tables."""
    with mpmd.Client(EP, timeout=30) as cc:
        job = cc.submit(bar_dict("py-wait", steps=400, every=100))
        run = cc.wait(job, timeout=120)
        assert run.status == "FINISHED" and run.steps == 400 and run.run_id == job.run_id, run
        slow = cc.submit(bar_dict("py-slow", steps=99000000, every=10000, at_rest=True))
        t0 = time.monotonic()
        e = expect_error("TIMEOUT", "timeout", cc.wait, slow, timeout=0.3)
        assert isinstance(e, mpmd.RequestTimeout) and time.monotonic() - t0 < 10, e
        cc.cancel(slow)
        assert cc.wait(slow, timeout=60).status == "CANCELLED"
        h = run._repr_html_()
        assert h.startswith("<table") and "py-wait" in h and "FINISHED" in h, h
        hl = cc.runs(limit=2)._repr_html_()
        assert hl.count("<tr>") == 3, hl
        log("wait: %s in %d steps; a 0.3 s wait: %s; HTML %d bytes" % (run.status, run.steps, e,
                                                                      len(h)))
    assert cc._ctx is None  # closed by the with block
    expect_error("USAGE", None, cc.ping)


def t_pressure(c, st):
    """Two particles under uniaxial compression (sxx = -3000): pressure
    +1000 and mean stress -1000 at step 0, positive to the end."""
    case = {
        "name": "py-compressed", "grid": {"dim": 1, "spacing": [1], "nodes": [5]},
        "method": "MPM", "dt": 1e-5, "steps": 5,
        "materials": [{"youngsModulus": 1e6, "density": 1}],
        "bodies": [{"points": {"x": [1.5, 2.5], "volume": [1, 1],
                               "stress": [-3000, 0, 0, 0, 0, 0, -3000, 0, 0, 0, 0, 0]}}],
        "output": {"energyEvery": 1, "snapshotEvery": 2, "recordSnapshots": True},
    }
    run = c.wait(c.submit(case), timeout=60)
    assert run.status == "FINISHED" and run.snapshot_steps == [0, 2, 4, 5], run
    s0 = c.snapshot(run, 0)
    assert (s0.pressure == 1000.0).all() and (s0.mean_stress == -1000.0).all(), s0
    s5 = c.snapshot(run)
    assert s5.step == 5 and (abs(s5.pressure - 1000.0) < 10.0).all(), s5.pressure
    assert (s5.mean_stress == -s5.pressure).all()
    log("compressed: step 0 pressure %s mean_stress %s; step 5 pressure %s"
        % (s0.pressure.tolist(), s0.mean_stress.tolist(), s5.pressure.tolist()))


PHASES = {
    "api": [t_submit_watch, t_energy_equals_mpmctl, t_snapshot_equals_mpmctl, t_runs_run_cancel,
            t_2d_arrays_equal_mpmctl,
            t_late_join, t_errors, t_timeout, t_env_endpoint],
    "stop": [t_stop],
    "kill": [t_kill],
    "curve": [t_curve],
    "pip": [t_pip_installed, t_error_classes, t_wait_context_html, t_pressure],
}


def main():
    phase = sys.argv[1] if len(sys.argv) > 1 else "api"
    failed = 0
    st = {}
    with mpmd.Client(EP, timeout=2 if phase in ("stop", "kill") else 30) as c:
        for t in PHASES[phase]:
            t0 = time.monotonic()
            try:
                t(c, st)
                print("ok   %s (%.2f s)" % (t.__name__, time.monotonic() - t0), flush=True)
            except Exception:
                failed += 1
                print("FAIL %s" % t.__name__, flush=True)
                traceback.print_exc(file=sys.stdout)
                if phase == "api" and t.__name__ == "t_submit_watch":
                    break  # the others use its jobs
    print("%s: %d failed" % (phase, failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
