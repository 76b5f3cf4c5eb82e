"""What the client hands back: plain dataclasses and NumPy arrays built from
the protobuf messages, with the schema's snake_case names.

* ``Submitted``: a queued job (``job_id``, ``run_id``); usable wherever an id
  is expected (``int(s)`` is the job id).
* ``Run``: a run record (RunInfo).  ``status`` and the enums are names
  (``"FINISHED"``, ``"BSPLINE2"``); an absent optional field is ``None``.
* Stream events, yielded by ``Client.watch``: ``Progress``, ``Energy`` (one
  energy sample), ``Snapshot`` and ``Finished`` (always the last).
* ``energy_array(samples)``: a NumPy structured array, one row per sample.
* ``Snapshot``: particle fields as arrays shaped (n, dim) (x, v), (n, 6)
  (stress, Voigt xx yy zz xy yz xz), (n,) (pressure, positive in
  compression; mean_stress = -pressure; volume, plastic_strain, yielded),
  (n, dim, dim) (F, row-major); a field the snapshot lacks is ``None``.
* ``Run`` and ``RunList`` show as tables in a notebook (``_repr_html_``).
"""

import html
import time as _time
from dataclasses import dataclass, field
from typing import Any, Iterable, List, Optional

import numpy as np

from ._pb import pb

# ---- enum names -------------------------------------------------------------


def status_name(v):
    """RunStatus number -> name ("FINISHED"); unknown numbers as text."""
    try:
        return pb.RunStatus.Name(v)
    except ValueError:
        return str(v)


def _enum_name(enum, v):
    try:
        return enum.Name(v)
    except ValueError:
        return str(v)


def _opt(msg, name):
    """msg.name if present, else None."""
    return getattr(msg, name) if msg.HasField(name) else None


# ---- energies ---------------------------------------------------------------

# The scalar columns of an energy sample, in mpmctl's CSV order.
ENERGY_SCALARS = (
    "t",
    "kinetic",
    "strain",
    "potential",
    "external_work",
    "total",
    "mass",
    "plastic_work",
    "damping_work",
    "friction_work",
    "prescribed_work",
    "balance_error",
)


def energy_dtype(dim, nang):
    """The structured dtype of an energy series: seq, step, the scalars,
    momentum (dim,) and angular_momentum (nang,) (3 in 3D, 1 in 2D, none
    in 1D)."""
    fields = [("seq", "<u8"), ("step", "<i8")]
    fields += [(n, "<f8") for n in ENERGY_SCALARS]
    fields.append(("momentum", "<f8", (dim,)))
    if nang:
        fields.append(("angular_momentum", "<f8", (nang,)))
    return np.dtype(fields)


def energy_array(samples):
    """EnergySample messages -> a structured array (one row per sample).
    Absent scalars read 0 (as the schema says); the momentum has as many
    entries as the first sample's (its dim); angular_momentum is present in
    2D (1 entry, z) and 3D (3 entries)."""
    samples = list(samples)
    dim = len(samples[0].momentum) if samples else 1
    dim = min(max(dim, 1), 3)
    nang = 3 if dim == 3 else 1 if dim == 2 else 0
    a = np.zeros(len(samples), dtype=energy_dtype(dim, nang))
    for i, s in enumerate(samples):
        row = a[i]
        row["seq"] = s.seq
        row["step"] = s.step
        for n in ENERGY_SCALARS:
            row[n] = getattr(s, n)
        m = list(s.momentum)[:dim]
        row["momentum"][: len(m)] = m
        if nang:
            L = list(s.angular_momentum)[:nang]
            row["angular_momentum"][: len(L)] = L
            if not L:
                row["angular_momentum"] = np.nan  # not recorded
    return a


@dataclass
class Energy:
    """An energy sample (a stream event, and the rows of Client.energy).

    seq: its index in the run (0, 1, 2, ... without gaps); step, t; the
    energies; momentum (dim entries) and angular_momentum (2D: z; 3D: x,
    y, z) as NumPy arrays; the energy balance's works and balance_error.
    stream_seq: the StreamMsg.seq it came with, None when it came from the
    stored history."""

    seq: int
    step: int
    t: float
    kinetic: float
    strain: float
    potential: float
    external_work: float
    total: float
    mass: float
    momentum: np.ndarray
    angular_momentum: np.ndarray
    plastic_work: float = 0.0
    damping_work: float = 0.0
    friction_work: float = 0.0
    prescribed_work: float = 0.0
    balance_error: float = 0.0
    stream_seq: Optional[int] = None

    @classmethod
    def from_pb(cls, s, stream_seq=None):
        return cls(
            seq=s.seq,
            step=s.step,
            t=s.t,
            kinetic=s.kinetic,
            strain=s.strain,
            potential=s.potential,
            external_work=s.external_work,
            total=s.total,
            mass=s.mass,
            momentum=np.array(s.momentum, dtype=float),
            angular_momentum=np.array(s.angular_momentum, dtype=float),
            plastic_work=s.plastic_work,
            damping_work=s.damping_work,
            friction_work=s.friction_work,
            prescribed_work=s.prescribed_work,
            balance_error=s.balance_error,
            stream_seq=stream_seq,
        )


# ---- snapshots --------------------------------------------------------------


@dataclass
class Snapshot:
    """Particle fields at one step (Client.snapshot, and a stream event).

    x, v: (n, dim); stress: (n, 6) Voigt (xx, yy, zz, xy, yz, xz);
    pressure: (n,), -(sxx + syy + szz)/3, positive in compression;
    mean_stress: (n,), the mean stress, -pressure (negative in
    compression); volume, plastic_strain: (n,); F (the deformation gradient):
    (n, dim, dim), row-major; yielded: (n,) bool.  A field the snapshot
    does not carry is None.  stream_seq: the StreamMsg.seq of a streamed
    snapshot (None for a stored one)."""

    step: int
    t: float
    n: int
    dim: int
    x: Optional[np.ndarray] = None
    v: Optional[np.ndarray] = None
    stress: Optional[np.ndarray] = None
    pressure: Optional[np.ndarray] = None
    mean_stress: Optional[np.ndarray] = None
    volume: Optional[np.ndarray] = None
    plastic_strain: Optional[np.ndarray] = None
    F: Optional[np.ndarray] = None
    yielded: Optional[np.ndarray] = None
    stream_seq: Optional[int] = None

    @classmethod
    def from_pb(cls, s: Any, stream_seq: Optional[int] = None) -> "Snapshot":
        """Checks every array against n and dim (a PROTOCOL error otherwise).
        A daemon before schema 1.1 sends only the mean stress (the field an
        older schema named pressure): the pressure is then its negative."""
        from .errors import PROTOCOL, MpmdError

        n, dim = int(s.n), int(s.dim)

        def arr(values, shape, what, dtype=float):
            if len(values) == 0:
                return None
            want = int(np.prod(shape))
            if len(values) != want:
                raise MpmdError(
                    PROTOCOL,
                    "snapshot.%s: %d values, expected %d (n = %d, dim = %d)"
                    % (what, len(values), want, n, dim),
                )
            return np.array(values, dtype=dtype).reshape(shape)

        p = arr(s.pressure, (n,), "pressure")
        m = arr(s.mean_stress, (n,), "meanStress")
        # 0.0 - x as the daemon does it: +0 for a stress-free particle
        if p is None and m is not None:
            p = 0.0 - m
        elif m is None and p is not None:
            m = 0.0 - p
        return cls(
            step=s.step,
            t=s.t,
            n=n,
            dim=dim,
            x=arr(s.x, (n, dim), "x"),
            v=arr(s.v, (n, dim), "v"),
            stress=arr(s.stress, (n, 6), "stress"),
            pressure=p,
            mean_stress=m,
            volume=arr(s.volume, (n,), "volume"),
            plastic_strain=arr(s.plastic_strain, (n,), "plasticStrain"),
            F=arr(s.deformation_gradient, (n, dim, dim), "deformationGradient"),
            yielded=arr(s.yielded, (n,), "yielded", dtype=bool),
            stream_seq=stream_seq,
        )


# ---- stream events ----------------------------------------------------------


@dataclass
class Progress:
    """Periodic progress of a running job (about every 0.2 s of wall time)."""

    step: int
    t: float
    dt: float
    steps_total: int
    wall_s: float
    stream_seq: Optional[int] = None


@dataclass
class Finished:
    """The end of a job: always the last event of Client.watch.

    status: "FINISHED", "FAILED", "CANCELLED" or "INTERRUPTED"; error: why
    it did not finish ("" if it did); energy: the final sample (an Energy,
    or None when the job never ran); balance_error and warning as the run
    record's.  from_stream: False when the Finished message was not seen
    (the job ended before the subscription took) and this was made from
    the run record."""

    status: str
    error: str
    steps: int
    t: float
    wall_s: float
    energy: Optional[Energy] = None
    balance_error: Optional[float] = None
    warning: str = ""
    stream_seq: Optional[int] = None
    from_stream: bool = True


# ---- runs -------------------------------------------------------------------


@dataclass
class Submitted:
    """A queued job: its job id (for cancel, status and the stream) and the
    id of its run record (today the same number)."""

    job_id: int
    run_id: int

    def __int__(self):
        return self.job_id

    def __index__(self):
        return self.job_id


@dataclass
class Run:
    """A run record (RunInfo).  Times are Unix seconds; an absent optional
    field is None; method, update, transfer and status are names.
    case: the case as a dict (JSON mapping), when asked for with
    run(id, with_case=True).  message: the RunInfo message itself."""

    run_id: int
    job_id: int
    name: str
    status: str
    error: str
    submitted_at: Optional[float]
    started_at: Optional[float]
    finished_at: Optional[float]
    steps: int
    steps_total: Optional[int]
    t: float
    wall_s: float
    particles: int
    nodes: int
    dim: int
    method: Optional[str]
    update: Optional[str]
    transfer: Optional[str]
    last_energy: Optional[Energy]
    energy_samples: int
    snapshot_steps: List[int]
    warning: str
    balance_error: Optional[float]
    owner: Optional[str]
    case: Optional[dict] = None
    message: Any = field(default=None, repr=False)

    def __int__(self) -> int:
        return self.run_id

    def __index__(self) -> int:
        return self.run_id

    @property
    def ended(self) -> bool:
        """True once the run is FINISHED, FAILED, CANCELLED or INTERRUPTED."""
        return self.status in ("FINISHED", "FAILED", "CANCELLED", "INTERRUPTED")

    def _repr_html_(self) -> str:
        """The run as a small table (Jupyter shows it for a Run value)."""
        return _runs_table([self])

    @classmethod
    def from_pb(cls, r: Any) -> "Run":
        from google.protobuf import json_format

        case = None
        if r.HasField("case"):
            case = json_format.MessageToDict(r.case)
        return cls(
            run_id=r.run_id,
            job_id=r.job_id,
            name=r.name,
            status=status_name(r.status),
            error=r.error,
            submitted_at=_opt(r, "submitted_at"),
            started_at=_opt(r, "started_at"),
            finished_at=_opt(r, "finished_at"),
            steps=r.steps,
            steps_total=_opt(r, "steps_total"),
            t=r.t,
            wall_s=r.wall_s,
            particles=r.particles,
            nodes=r.nodes,
            dim=r.dim,
            method=_enum_name(pb.Case.Method, r.method) if r.HasField("method") else None,
            update=_enum_name(pb.Case.Update, r.update) if r.HasField("update") else None,
            transfer=_enum_name(pb.Case.Transfer, r.transfer) if r.HasField("transfer") else None,
            last_energy=Energy.from_pb(r.last_energy) if r.HasField("last_energy") else None,
            energy_samples=r.energy_samples,
            snapshot_steps=list(r.snapshot_steps),
            warning=r.warning,
            balance_error=_opt(r, "balance_error"),
            owner=_opt(r, "owner"),
            case=case,
            message=r,
        )


class RunList(list):
    """A page of runs, newest first; next_before_run_id is set when the
    limit cut the listing (pass it as before= for the next page)."""

    next_before_run_id: Optional[int] = None

    def _repr_html_(self) -> str:
        """The runs as one table, a row each (Jupyter shows it)."""
        more = ""
        if self.next_before_run_id:
            more = "<p>more: runs(before=%d)</p>" % self.next_before_run_id
        return _runs_table(self) + more


# the columns of a run table: header, and the cell of a Run
_RUN_COLUMNS = (
    ("run", lambda r: str(r.run_id)),
    ("name", lambda r: r.name),
    ("status", lambda r: r.status + (" (%s)" % r.error if r.error else "")),
    ("method", lambda r: "/".join(x for x in (r.method, r.update, r.transfer) if x)),
    ("particles", lambda r: "%d (%dD)" % (r.particles, r.dim)),
    ("steps", lambda r: "%d / %s" % (r.steps, r.steps_total if r.steps_total is not None else "?")),
    ("t", lambda r: "%.6g" % r.t),
    ("wall", lambda r: "%.3g s" % r.wall_s),
    ("balance error", lambda r: "-" if r.balance_error is None else "%.2e" % r.balance_error),
    ("snapshots", lambda r: str(len(r.snapshot_steps))),
    (
        "submitted",
        lambda r: _time.strftime("%Y-%m-%d %H:%M:%S", _time.localtime(r.submitted_at))
        if r.submitted_at
        else "-",
    ),
    ("warning", lambda r: r.warning or ""),
)


def _runs_table(runs: Iterable["Run"]) -> str:
    """An HTML table of runs, every text escaped."""
    head = "".join("<th>%s</th>" % html.escape(h) for h, _ in _RUN_COLUMNS)
    rows = "".join(
        "<tr>%s</tr>" % "".join("<td>%s</td>" % html.escape(f(r)) for _, f in _RUN_COLUMNS)
        for r in runs
    )
    return '<table class="mpmd-runs"><thead><tr>%s</tr></thead><tbody>%s</tbody></table>' % (
        head,
        rows,
    )
