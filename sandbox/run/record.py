"""A recorded run: the arrays a simulation produced, read by metrics and rendering.

The simulation loop never draws and never computes metrics; it appends one sample every
``record_every`` control steps to a :class:`~sandbox.run.recorder.Recorder`, whose
arrays become a :class:`Run` (in memory, or memory-mapped from disk for big records).
Everything downstream (the metrics, the pictures, the CSV writer) reads a ``Run``
only, so it can also be loaded back from a run directory (``run.npz`` +
``scenario.yaml``) without simulating again.

Array shapes use ``T`` for recorded samples and ``n`` for vehicles.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas

    from sandbox.run.analysis import VehicleTrack

#: Integer codes of the ``mode`` array, and their names in ``trajectory.csv``.
MODE_FORMATION = 0
MODE_AVOID = 1
MODE_FAILED = 2
#: Driven this period by commands or targets given to ``Simulation.step``.
MODE_EXTERNAL = 3
MODE_NAMES = ("formation", "avoid", "failed", "external")

#: Status values of a run (``metrics.json`` key ``status``).
STATUS_OK = "ok"
STATUS_DIVERGED = "diverged"
STATUS_INTERRUPTED = "interrupted"
#: A plug-in raised or returned non-finite numbers (``Run.info["error"]``).
STATUS_ERROR = "error"


@dataclass
class CollisionEvent:
    """One contact episode between two bodies.

    An episode starts at the pair's first contact (a pymunk ``begin`` callback) and
    ends once the pair has really separated: pymunk's ``separate`` has fired and the
    gap between the two surfaces has grown beyond ``metrics.contact_release``. A pair
    pressed together, grinding or bouncing back within that gap is one episode.

    Attributes
    ----------
    t : float [s]
        Simulated time of the first contact (start of the physics substep it occurs in).
    a, b : str
        Names of the two bodies: vehicle names, or obstacle names (``obstacle[k]``
        unless the scenario names them). For vehicle-vehicle events ``a`` precedes ``b``
        in scenario order.
    kind : str
        ``"vehicle_vehicle"`` or ``"vehicle_obstacle"``.
    end : float or None [s]
        Simulated time at which the gap first exceeded the release distance (end of
        that substep); None while the pair was still within it when the run ended.
    healthy : bool or None
        Whether no vehicle involved had an active failure at the first contact; None
        when not known (an event built by hand).
    penetration : float [m]
        Largest overlap of the two shapes during the episode, checked every physics
        substep (0 when they only touched).
    """

    t: float
    a: str
    b: str
    kind: str
    end: float | None = None
    healthy: bool | None = None
    penetration: float = 0.0


@dataclass
class Run:
    """Recorded arrays of one simulation run.

    Attributes
    ----------
    t : ndarray, shape (T,) [s]
        Sample times.
    pose : ndarray, shape (T, n, 3)
        ``(x1, x2, x3)`` of each vehicle [m, m, rad]; x3 is unwrapped (continuous).
    cmd : ndarray, shape (T, n, 2)
        Applied commands ``(v1, v2)`` [m/s, rad/s] after limits and failures.
    chi : ndarray, shape (T, n, 2) [m/s]
        Extension states of eqs (4)/(6).
    slot : ndarray, shape (T, n, 2) [m]
        Each vehicle's place as its formation law defines it (the leader's: the
        reference
        point); NaN where undefined (a commanded leader, a failed vehicle's unused slot
        is
        still given).
    target : ndarray, shape (T, n, 2) [m]
        The point the controller actually tracked: the slot shifted by recovery.
    mode : ndarray, shape (T, n), int8
        ``MODE_FORMATION``, ``MODE_AVOID``, ``MODE_FAILED`` or ``MODE_EXTERNAL``
        (overridden through :meth:`sandbox.loop.simulation.Simulation.step`).
    failed : ndarray, shape (T, n), bool
        Whether a failure is active on the vehicle.
    reference : ndarray, shape (T, 2) [m]
        The reference trajectory's point, NaN when the scenario has none.
    names, colors : list of str, length n
    diameter : ndarray, shape (n,) [m]
    leader : int
        Index of the leader, or -1.
    events : list of CollisionEvent
    status : str
        ``ok``, ``diverged`` or ``interrupted``.
    info : dict
        Free-form facts about the run (``diverged`` details, failure times, wall time,
        ...).
    scenario : Any
        The resolved :class:`sandbox.scenario.Scenario` the run came from.
    ranges : ndarray, shape (T, n, B) [m], float32, or None
        The range sensors' readings at each sample (``sensors.range``; NaN for a
        vehicle or beam without one); None: the run had no range sensor.
    beam_angles : ndarray, shape (n, B) [rad], or None
        Each beam's angle about the vehicle's heading.
    steer : ndarray, shape (T, n) [rad], or None
        Each car's steering angle delta (``model: bicycle``) during the period from
        each sample, NaN on a unicycle's row; None: the run had no car.
    """

    t: np.ndarray
    pose: np.ndarray
    cmd: np.ndarray
    chi: np.ndarray
    slot: np.ndarray
    target: np.ndarray
    mode: np.ndarray
    failed: np.ndarray
    reference: np.ndarray
    names: list[str]
    colors: list[str]
    diameter: np.ndarray
    leader: int
    events: list[CollisionEvent] = field(default_factory=list)
    status: str = STATUS_OK
    info: dict[str, Any] = field(default_factory=dict)
    scenario: Any = None
    ranges: np.ndarray | None = None
    beam_angles: np.ndarray | None = None
    steer: np.ndarray | None = None

    @property
    def n_vehicles(self) -> int:
        """Number of vehicles ``n``."""
        return len(self.names)

    @property
    def formation_error(self) -> np.ndarray:
        """Distance of each vehicle to its slot, shape (T, n) [m]; NaN: no slot."""
        return np.linalg.norm(self.pose[:, :, :2] - self.slot, axis=-1)

    def leader_frame(self) -> np.ndarray:
        """Positions of every vehicle in the leader's frame, shape (T, n, 2) [m].

        The leader frame has its origin at the leader and its first axis along the
        leader's
        heading x3 (report Figs. 5 and 8). Raises ``ValueError`` when the run has no
        leader.
        """
        if self.leader < 0:
            raise ValueError("the run has no leader")
        lead = self.pose[:, self.leader, :]
        rel = self.pose[:, :, :2] - lead[:, None, :2]
        c = np.cos(lead[:, 2])[:, None]
        s = np.sin(lead[:, 2])[:, None]
        return np.stack(
            (c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1]), -1
        )

    @property
    def slot_index(self) -> np.ndarray:
        """The formation slot each vehicle holds at each sample, shape (T, n), int.

        Slot ``k`` is ``vehicles[k].offset`` (the formation order); -1: no slot. With
        ``reconfigure`` or ``on_leader_failure`` it follows the reassignments and
        leader changes (``info["slots"]``: each vehicle's ``[[t, slot], ...]``, held
        from ``t``); without them vehicle ``k`` holds slot ``k`` throughout (one driven
        by a command schedule none). After a merge or split (``events:``) slot ``k``
        of the platoon it formed is the offset vehicle ``k`` held then;
        :meth:`formation_at` gives the offsets themselves.
        """
        T, n = len(self.t), self.n_vehicles
        timeline = self.info.get("slots")
        if timeline is None:
            out = np.broadcast_to(np.arange(n), (T, n)).copy()
            if self.scenario is not None:
                for i, v in enumerate(self.scenario.vehicles):
                    if v.drive.type == "commands":
                        out[:, i] = -1
            return out
        out = np.full((T, n), -1, dtype=int)
        for i, name in enumerate(self.names):
            for start, slot in timeline[name]:
                out[self.t >= start - 1e-9, i] = -1 if slot is None else slot
        return out

    def slot_changes(self) -> list[dict[str, Any]]:
        """Every change of slot, in time order: ``{t, vehicle, from, to}``.

        ``t`` [s] is the first period the vehicle holds slot ``to`` (None: no slot);
        empty without reconfiguration.
        """
        timeline = self.info.get("slots") or {}
        changes = []
        for name in self.names:
            steps = timeline.get(name, [])
            changes += [
                {"t": b[0], "vehicle": name, "from": a[1], "to": b[1]}
                for a, b in zip(steps[:-1], steps[1:], strict=True)
            ]
        order = {name: i for i, name in enumerate(self.names)}
        return sorted(changes, key=lambda c: (c["t"], order[c["vehicle"]]))

    def vehicle(self, name: str) -> VehicleTrack:
        """One vehicle's arrays by name: ``run.vehicle("red").x1``.

        See :class:`sandbox.run.analysis.VehicleTrack`; raises ``KeyError`` (listing the
        names) for an unknown vehicle.
        """
        from sandbox.run.analysis import vehicle_track

        return vehicle_track(self, name)

    def formation_at(self) -> tuple[list[str], np.ndarray, np.ndarray]:
        """Each vehicle's platoon and formation offset at each sample.

        ``(names, platoon, offset)``: the platoons' names, each vehicle's platoon
        (T, n) as an index into them, and its offset (T, n, 2) [m] (NaN: no slot),
        through merges, splits and reassignments; see
        :func:`sandbox.run.platoons.formation_at`.
        """
        from sandbox.run.platoons import formation_at

        return formation_at(self)

    def platoon(self, name: str) -> Run:
        """The run of one platoon's vehicles (with ``platoons:``), by its name.

        See :func:`sandbox.run.platoons.platoon_view`: the platoon's rows, its own
        reference and scenario, the events involving its vehicles.
        """
        from sandbox.run.platoons import platoon_view

        return platoon_view(self, name)

    def to_dataframe(self) -> pandas.DataFrame:
        """The run as a long pandas DataFrame: t, vehicle, x1, ..., mode, failed.

        One row per vehicle per sample, the columns of ``trajectory.csv``; needs the
        ``analysis`` extra. See :func:`sandbox.run.analysis.to_dataframe`.
        """
        from sandbox.run.analysis import to_dataframe

        return to_dataframe(self)

    # ------------------------------------------------------------------ persistence
    def save_npz(self, path: Path) -> None:
        """Write the arrays and the event log to ``path`` (a ``.npz``).

        Identical runs give identical bytes: the wall-clock time a run took (in
        ``info``, for the console) is left out, and numpy stamps every member of the
        archive with the same fixed date.
        """
        meta = {
            "names": self.names,
            "colors": self.colors,
            "leader": self.leader,
            "status": self.status,
            "info": {k: v for k, v in self.info.items() if k not in _NOT_SAVED},
            "events": [
                [e.t, e.a, e.b, e.kind, e.end, e.healthy, e.penetration]
                for e in self.events
            ],
        }
        # The scans only of a run that had range sensors (others keep their bytes).
        scans = {}
        if self.ranges is not None and self.beam_angles is not None:
            scans = {"ranges": self.ranges, "beam_angles": self.beam_angles}
        if self.steer is not None:  # the steering angles only of a run with cars
            scans["steer"] = self.steer
        with open(path, "wb") as fh:
            np.savez_compressed(
                fh,
                t=self.t,
                pose=self.pose,
                cmd=self.cmd,
                chi=self.chi,
                slot=self.slot,
                target=self.target,
                mode=self.mode,
                failed=self.failed,
                reference=self.reference,
                diameter=self.diameter,
                meta=np.array(json.dumps(meta)),
                **scans,
            )

    @classmethod
    def load_npz(cls, path: Any, scenario: Any = None) -> Run:
        """Read a run written by :meth:`save_npz`, checking every array first.

        Raises :class:`RunFileError` (a ``ValueError``) naming what is wrong when the
        file is not such a run: a missing or unknown member, a wrong dtype or shape, an
        array whose stored size does not match its header, a member that would inflate
        beyond what DEFLATE can produce from its compressed size (a compression bomb),
        zero samples, or metadata that does not match the arrays. Sizes are checked
        from the zip directory and the ``.npy`` headers before anything is inflated.
        """
        meta, arrays = _read_checked(path)
        return cls(
            names=list(meta["names"]),
            colors=list(meta["colors"]),
            leader=int(meta["leader"]),
            status=meta["status"],
            info=meta["info"],
            events=[CollisionEvent(*row) for row in meta["events"]],
            scenario=scenario,
            **arrays,
        )


class RunFileError(ValueError):
    """A ``run.npz`` that is not a run written by :meth:`Run.save_npz`."""


#: Members of ``run.npz``: name -> (dtype kind, shape in terms of T samples and n
#: vehicles).
_MEMBERS: dict[str, tuple[str, tuple[str | int, ...]]] = {
    "t": ("f", ("T",)),
    "pose": ("f", ("T", "n", 3)),
    "cmd": ("f", ("T", "n", 2)),
    "chi": ("f", ("T", "n", 2)),
    "slot": ("f", ("T", "n", 2)),
    "target": ("f", ("T", "n", 2)),
    "mode": ("i", ("T", "n")),
    "failed": ("b", ("T", "n")),
    "reference": ("f", ("T", 2)),
    "diameter": ("f", ("n",)),
}
#: Members of a run with range sensors (``B``: the most beams of a vehicle).
_OPTIONAL: dict[str, tuple[str, tuple[str | int, ...]]] = {
    "ranges": ("f", ("T", "n", "B")),
    "beam_angles": ("f", ("n", "B")),
}
#: Largest metadata string of a run.npz [bytes] (names, colours, events, info).
_META_MAX_BYTES = 256 * 2**20
#: DEFLATE inflates at most about 1032 times; a member claiming more is a bomb.
_MAX_INFLATION = 1100


def _read_checked(path: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The metadata and arrays of a ``run.npz``, each checked before it is read."""
    import zipfile

    with zipfile.ZipFile(path) as zf:
        infos = {i.filename: i for i in zf.infolist()}
        names = {k[: -len(".npy")] for k in infos if k.endswith(".npy")}
        expected = {*_MEMBERS, "meta"}
        members = dict(_MEMBERS)
        if names & set(_OPTIONAL):  # both or neither
            expected |= set(_OPTIONAL)
            members.update(_OPTIONAL)
        if "steer" in names:  # a run with cars
            expected.add("steer")
            members["steer"] = ("f", ("T", "n"))
        missing = sorted(expected - names)
        extra = sorted(set(infos) - {f"{k}.npy" for k in expected})
        if missing or extra:
            what = f"no {', '.join(missing)}" if missing else f"unknown {extra[0]!r}"
            raise RunFileError(f"not the members of a run ({what})")
        headers = {}
        for key in sorted(expected):
            info = infos[f"{key}.npy"]
            if info.file_size > _MAX_INFLATION * max(info.compress_size, 1) + 4096:
                raise RunFileError(
                    f"{key}: claims {info.file_size:,} bytes from "
                    f"{info.compress_size:,} compressed (a compression bomb)"
                )
            with zf.open(info) as fh:
                try:
                    version = np.lib.format.read_magic(fh)
                    read_header = (
                        np.lib.format.read_array_header_1_0
                        if version == (1, 0)
                        else np.lib.format.read_array_header_2_0
                    )
                    shape, _, dtype = read_header(fh, max_header_size=10000)
                except (ValueError, SyntaxError, EOFError, TypeError) as exc:
                    raise RunFileError(f"{key}: not an array ({exc})") from None
                header = fh.tell() if fh.seekable() else None
            if dtype.hasobject:
                raise RunFileError(f"{key}: holds Python objects")
            size = int(np.prod(shape, dtype=object)) * dtype.itemsize
            if header is not None and size != info.file_size - header:
                raise RunFileError(
                    f"{key}: its header claims {size:,} bytes, it holds "
                    f"{info.file_size - header:,}"
                )
            headers[key] = (shape, dtype)
        m_shape, m_dtype = headers["meta"]
        if m_shape != () or m_dtype.kind != "U":
            raise RunFileError("meta: not a text")
        if infos["meta.npy"].file_size > _META_MAX_BYTES:
            raise RunFileError("meta: too large")
        t_shape = headers["t"][0]
        d_shape = headers["diameter"][0]
        if len(t_shape) != 1 or len(d_shape) != 1:
            raise RunFileError("t and diameter: not one-dimensional")
        dims = {"T": t_shape[0], "n": d_shape[0]}
        if "beam_angles" in headers:
            b_shape = headers["beam_angles"][0]
            dims["B"] = b_shape[-1] if len(b_shape) == 2 else -1
        if dims["T"] < 1:
            raise RunFileError("no recorded samples")
        if dims["n"] < 1:
            raise RunFileError("no vehicles")
        for key, (kind, form) in members.items():
            shape, dtype = headers[key]
            want = tuple(dims[d] if isinstance(d, str) else d for d in form)
            if tuple(shape) != want:
                raise RunFileError(f"{key}: shape {tuple(shape)}, expected {want}")
            if dtype.kind != kind:
                raise RunFileError(f"{key}: dtype {dtype}, expected kind {kind!r}")
        with zf.open("meta.npy") as fh:
            text = str(np.lib.format.read_array(fh, allow_pickle=False))
        arrays = {}
        for key in members:
            with zf.open(f"{key}.npy") as fh:
                arrays[key] = np.lib.format.read_array(fh, allow_pickle=False)
    try:
        meta = json.loads(text)
    except (ValueError, RecursionError):
        raise RunFileError("meta: not JSON") from None
    _check_meta(meta, dims["n"])
    return meta, arrays


def _check_meta(meta: Any, n: int) -> None:
    """Check the metadata of a run against its ``n`` vehicles."""
    if not isinstance(meta, dict):
        raise RunFileError("meta: not a mapping")
    for key in ("names", "colors"):
        value = meta.get(key)
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise RunFileError(f"meta: {key} is not a list of texts")
        if len(value) != n:
            raise RunFileError(f"meta: {len(value)} {key} for {n} vehicles")
    leader = meta.get("leader")
    if isinstance(leader, bool) or not isinstance(leader, int) or not -1 <= leader < n:
        raise RunFileError(f"meta: leader {leader!r} is not a vehicle index or -1")
    if meta.get("status") not in (
        STATUS_OK,
        STATUS_DIVERGED,
        STATUS_INTERRUPTED,
        STATUS_ERROR,
    ):
        raise RunFileError(f"meta: unknown status {meta.get('status')!r}")
    if not isinstance(meta.get("info"), dict):
        raise RunFileError("meta: info is not a mapping")
    events = meta.get("events")
    if not isinstance(events, list):
        raise RunFileError("meta: events is not a list")
    for row in events:
        ok = (
            isinstance(row, list)
            and len(row) == 7
            and isinstance(row[0], int | float)
            and isinstance(row[1], str)
            and isinstance(row[2], str)
            and isinstance(row[3], str)
            and (row[4] is None or isinstance(row[4], int | float))
            and (row[5] is None or isinstance(row[5], bool))
            and isinstance(row[6], int | float)
        )
        if not ok:
            raise RunFileError(
                f"meta: an event is not [t, a, b, kind, ...]: {row!r:.60}"
            )


#: Keys of ``Run.info`` that differ between identical runs and are not saved.
_NOT_SAVED = ("wall_time", "control_time")
