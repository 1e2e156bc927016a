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
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox.run.analysis import VehicleTrack, to_dataframe, vehicle_track
from sandbox.run.codes import (
    MODE_AVOID,
    MODE_EXTERNAL,
    MODE_FAILED,
    MODE_FORMATION,
    MODE_NAMES,
    STATUS_DIVERGED,
    STATUS_ERROR,
    STATUS_INTERRUPTED,
    STATUS_OK,
)
from sandbox.run.run_file import RunFileError, read_checked

if TYPE_CHECKING:
    import pandas

__all__ = [
    "MODE_AVOID",
    "MODE_EXTERNAL",
    "MODE_FAILED",
    "MODE_FORMATION",
    "MODE_NAMES",
    "STATUS_DIVERGED",
    "STATUS_ERROR",
    "STATUS_INTERRUPTED",
    "STATUS_OK",
    "CollisionEvent",
    "Run",
    "RunFileError",
]


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
        return to_dataframe(self)

    def save(self, path: str | os.PathLike[str], trajectory: str = "csv") -> Path:
        """Write the run's directory, as ``sandbox run`` does: metrics included.

        ``trajectory.csv`` (or ``trajectory.parquet`` with ``trajectory="parquet"``,
        the ``analysis`` extra), ``metrics.json`` (computed here, as ``sandbox run``
        computes it), ``scenario.yaml``, ``run.npz`` and the manifest, written whole
        (see :func:`sandbox.run.run_dir.write_run_dir`). ``sandbox view``, ``render``
        and ``plot`` read the directory, and :func:`sandbox.load_run` gives the run
        back. A stepped run (``Simulation.step``, then ``result()``) is saved the same
        way.

        Parameters
        ----------
        path : str or os.PathLike
            The directory: missing, empty, or an earlier run directory (its manifest
            lists what is replaced; other entries, such as ``figures/``, are kept).
            Anything else is never replaced.

        Returns
        -------
        Path
            ``path``.

        Raises
        ------
        OutputError
            ``path`` is not a directory that may be replaced, or cannot be written.
        """
        from sandbox.run.metrics import compute_metrics
        from sandbox.run.run_dir import check_out_dir, write_run_dir

        out = Path(path)
        check_out_dir(out)  # before the metrics, which a long run takes a while for
        return write_run_dir(self, compute_metrics(self), out, trajectory=trajectory)

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
        meta, arrays = read_checked(path)
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


#: Keys of ``Run.info`` that differ between identical runs and are not saved.
_NOT_SAVED = ("wall_time", "control_time")
