"""A recorded run: the arrays a simulation produced, read by metrics and rendering.

The simulation loop never draws and never computes metrics; it appends one sample every
``record_every`` control steps to a :class:`Recorder`, and :meth:`Recorder.finish` returns a
:class:`Run`. Everything downstream (``metrics.py``, ``render.py``, ``plot.py``, the CSV
writer) reads a ``Run`` only, so it can also be loaded back from a run directory
(``run.npz`` + ``scenario.yaml``) without simulating again.

Array shapes use ``T`` for recorded samples and ``n`` for vehicles.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: Integer codes of the ``mode`` array, and their names in ``trajectory.csv``.
MODE_FORMATION = 0
MODE_AVOID = 1
MODE_FAILED = 2
MODE_NAMES = ("formation", "avoid", "failed")

#: Status values of a run (``metrics.json`` key ``status``).
STATUS_OK = "ok"
STATUS_DIVERGED = "diverged"
STATUS_INTERRUPTED = "interrupted"


@dataclass(frozen=True)
class CollisionEvent:
    """One contact episode between two bodies (a pymunk ``begin`` callback).

    Attributes
    ----------
    t : float [s]
        Simulated time of the contact onset.
    a, b : str
        Names of the two bodies: vehicle names, or obstacle names (``obstacle[k]`` unless the
        scenario names them). For vehicle-vehicle events ``a`` precedes ``b`` in scenario order.
    kind : str
        ``"vehicle_vehicle"`` or ``"vehicle_obstacle"``.
    """

    t: float
    a: str
    b: str
    kind: str


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
        Each vehicle's place as its formation law defines it (the leader's: the reference
        point); NaN where undefined (a commanded leader, a failed vehicle's unused slot is
        still given).
    target : ndarray, shape (T, n, 2) [m]
        The point the controller actually tracked: the slot shifted by recovery.
    mode : ndarray, shape (T, n), int8
        ``MODE_FORMATION``, ``MODE_AVOID`` or ``MODE_FAILED``.
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
        Free-form facts about the run (``diverged`` details, failure times, wall time, ...).
    scenario : Any
        The resolved :class:`sandbox.scenario.Scenario` the run came from.
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

    @property
    def n_vehicles(self) -> int:
        """Number of vehicles ``n``."""
        return len(self.names)

    @property
    def formation_error(self) -> np.ndarray:
        """Distance from each vehicle to its slot, shape (T, n) [m] (NaN where no slot)."""
        return np.linalg.norm(self.pose[:, :, :2] - self.slot, axis=-1)

    def leader_frame(self) -> np.ndarray:
        """Positions of every vehicle in the leader's frame, shape (T, n, 2) [m].

        The leader frame has its origin at the leader and its first axis along the leader's
        heading x3 (report Figs. 5 and 8). Raises ``ValueError`` when the run has no leader.
        """
        if self.leader < 0:
            raise ValueError("the run has no leader")
        lead = self.pose[:, self.leader, :]
        rel = self.pose[:, :, :2] - lead[:, None, :2]
        c = np.cos(lead[:, 2])[:, None]
        s = np.sin(lead[:, 2])[:, None]
        return np.stack((c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1]), -1)

    # ------------------------------------------------------------------ persistence
    def save_npz(self, path: Path) -> None:
        """Write the arrays and the event log to ``path`` (a ``.npz``)."""
        meta = {
            "names": self.names,
            "colors": self.colors,
            "leader": self.leader,
            "status": self.status,
            "info": self.info,
            "events": [[e.t, e.a, e.b, e.kind] for e in self.events],
        }
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
            )

    @classmethod
    def load_npz(cls, path: Path, scenario: Any = None) -> Run:
        """Read a run written by :meth:`save_npz`."""
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            arrays = {k: data[k] for k in data.files if k != "meta"}
        return cls(
            names=list(meta["names"]),
            colors=list(meta["colors"]),
            leader=int(meta["leader"]),
            status=meta["status"],
            info=meta["info"],
            events=[CollisionEvent(float(t), a, b, k) for t, a, b, k in meta["events"]],
            scenario=scenario,
            **arrays,
        )


class Recorder:
    """Preallocated storage that the simulation loop fills one sample at a time.

    Parameters
    ----------
    n_samples : int
        Upper bound on the number of samples (the run may stop early).
    n_vehicles : int
    """

    def __init__(self, n_samples: int, n_vehicles: int) -> None:
        T, n = n_samples, n_vehicles
        self.t = np.zeros(T)
        self.pose = np.zeros((T, n, 3))
        self.cmd = np.zeros((T, n, 2))
        self.chi = np.zeros((T, n, 2))
        self.slot = np.zeros((T, n, 2))
        self.target = np.zeros((T, n, 2))
        self.mode = np.zeros((T, n), dtype=np.int8)
        self.failed = np.zeros((T, n), dtype=bool)
        self.reference = np.zeros((T, 2))
        self.count = 0

    def append(
        self,
        t: float,
        pose: np.ndarray,
        cmd: np.ndarray,
        chi: np.ndarray,
        slot: np.ndarray,
        target: np.ndarray,
        mode: np.ndarray,
        failed: np.ndarray,
        reference: np.ndarray,
    ) -> None:
        """Copy one sample in (arrays are copied, so callers may reuse theirs)."""
        k = self.count
        if k >= len(self.t):
            return
        self.t[k] = t
        self.pose[k] = pose
        self.cmd[k] = cmd
        self.chi[k] = chi
        self.slot[k] = slot
        self.target[k] = target
        self.mode[k] = mode
        self.failed[k] = failed
        self.reference[k] = reference
        self.count = k + 1

    def arrays(self) -> dict[str, np.ndarray]:
        """The filled part of every array."""
        k = self.count
        return {
            "t": self.t[:k],
            "pose": self.pose[:k],
            "cmd": self.cmd[:k],
            "chi": self.chi[:k],
            "slot": self.slot[:k],
            "target": self.target[:k],
            "mode": self.mode[:k],
            "failed": self.failed[:k],
            "reference": self.reference[:k],
        }
