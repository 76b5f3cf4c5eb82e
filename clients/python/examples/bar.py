#!/usr/bin/python3
"""The paper's vibrating bar through mpmd, against its analytic solution.

Submits the bar of Buzzi, Pedroso & Giacomini (section 5: E = 10, rho = 1,
L = 1, fixed at x = 0, first mode v(x, 0) = v0 sin(beta1 x)) from
proto/examples/bar1d_gimp.json (GMPM, 13 points, 14 nodes, dt = 0.001, the
paper's Fig. 13), watches it to the end, fetches its energy series and
compares the centre-of-mass velocity, momentum / mass, with Eq. 34
averaged over the bar:

    v_cm(t) = v0 cos(omega1 t) * (1 - cos(beta1 L)) / (beta1 L)
            = v0 cos(omega1 t) * 2 / pi,   omega1 = pi / (2 L) sqrt(E / rho)

Prints the largest difference relative to the amplitude 2 v0 / pi and
saves a PNG of both curves (matplotlib, Agg backend).

    PYTHONPATH=clients/python:build/python /usr/bin/python3 \\
        clients/python/examples/bar.py [--endpoint EP] [--case FILE] [--out bar.png]
"""

import argparse
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import mpmd  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
CASE = os.path.join(HERE, "..", "..", "..", "proto", "examples", "bar1d_gimp.json")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--endpoint", help="mpmd's control socket (default $MPMD_ENDPOINT or tcp://127.0.0.1:5555)")
    ap.add_argument("--case", default=os.path.normpath(CASE), help="the bar's case file")
    ap.add_argument("--out", default="bar.png", help="the PNG to write")
    ap.add_argument("--timeout", type=float, default=mpmd.DEFAULT_TIMEOUT, help="seconds per request")
    a = ap.parse_args()

    case = mpmd.case_message(a.case)  # the case file as a message: its v0 and E, rho, L
    E = case.materials[0].youngs_modulus
    rho = case.materials[0].density
    pts = case.bodies[0].points
    x, v, vol = np.array(pts.x), np.array(pts.v), np.array(pts.volume)
    L = float(np.sum(vol))  # the bar's length: its points' volumes (1D)
    beta = math.pi / (2 * L)
    omega = beta * math.sqrt(E / rho)
    v0 = float(np.mean(v / np.sin(beta * x)))  # Eq. 36: v(x, 0) = v0 sin(beta x)
    amp = v0 * (1 - math.cos(beta * L)) / (beta * L)

    try:
        with mpmd.Client(a.endpoint, timeout=a.timeout) as c:
            job = c.submit(case)
            print("job %d: %s submitted (%d points, E = %g, v0 = %.6g)" % (job.job_id, case.name, len(x), E, v0))
            samples = 0
            for ev in c.watch(job, snapshots=False):
                if isinstance(ev, mpmd.Energy):
                    samples += 1
                elif isinstance(ev, mpmd.Finished):
                    print("job %d: %s after %d steps, t = %g, %d energy samples"
                          % (job.job_id, ev.status, ev.steps, ev.t, samples))
                    if ev.status != "FINISHED":
                        print("bar.py: the run did not finish: %s" % ev.error, file=sys.stderr)
                        return 1
            e = c.energy(job)
    except mpmd.MpmdError as err:
        print("bar.py: %s" % err, file=sys.stderr)
        return 1

    t = e["t"]
    vcm = e["momentum"][:, 0] / e["mass"]
    exact = amp * np.cos(omega * t)
    err = np.abs(vcm - exact) / amp
    k = int(np.argmax(err))
    print("centre-of-mass velocity vs Eq. 34 over %d samples, t in [%g, %g] (%.2f periods):"
          % (len(t), t[0], t[-1], t[-1] * omega / (2 * math.pi)))
    print("max |v_cm - Eq. 34| / (2 v0 / pi) = %.4e (at t = %g); RMS %.4e"
          % (err[k], t[k], math.sqrt(float(np.mean(err ** 2)))))

    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    tt = np.linspace(0, t[-1], 600)
    ax.plot(tt, amp * np.cos(omega * tt), "k-", lw=1.2, label="Eq. 34 (analytic)")
    ax.plot(t, vcm, "o", ms=3, mfc="none", color="tab:red", label="mpmd (%s)" % case.name)
    ax.set_xlabel("t")
    ax.set_ylabel("centre-of-mass velocity")
    ax.set_title("Vibrating bar, first mode: max error %.2f %% of the amplitude" % (100 * err[k]))
    ax.grid(True, alpha=0.3)
    ax.set_ylim(-1.4 * amp, 1.4 * amp)
    ax.legend(loc="upper right", ncol=2)
    fig.tight_layout()
    fig.savefig(a.out)
    print("wrote %s" % a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
