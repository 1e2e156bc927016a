"""Metrics of a run: what the loop accumulates, and functions of the recorded run.

Definitions (the keys of ``metrics.json``):

- ``collisions``: contact episodes counted from the physics (see
  :class:`~sandbox.run.record.CollisionEvent`): an episode of a pair starts at its first
  contact and ends once the gap between the surfaces has exceeded
  ``metrics.contact_release``; ``vehicle_vehicle`` and ``vehicle_obstacle`` apart;
  ``healthy``: the episodes in which no vehicle involved had an active failure at the
  first contact (two healthy vehicles, or a healthy vehicle and a static obstacle): what
  recovery is meant to prevent; ``events`` lists ``{t, end, a, b, kind, healthy,
  penetration}``.
- ``min_distance``: smallest centre-to-centre distance between two vehicles [m], checked
  every control period by :class:`LoopMetrics` (null with a single vehicle).
- ``motor``: the check that eq. (1) holds while a vehicle is free of contact
  (:class:`LoopMetrics`): largest velocity and speed errors [m/s], the vehicle-periods
  checked, and the fraction of them in which the motor could not follow.
- per vehicle, ``formation_error``: distance from the vehicle to its slot as its law
  defines it (the leader's slot is the reference point) [m]: ``final`` (last sample),
  ``max``, and ``rms_last_quarter`` (RMS over the last quarter of the run);
  ``settling_time``: first time after which the error stays below ``settle_tol`` until
  the end [s], null if it never does, if the vehicle drifts more than ``settle_speed``
  relative to its slot over the run's last ``settle_dwell``, if the run does not last
  ``settle_dwell`` after it, or if the vehicle has no slot; ``effort_v1`` [m/s] and
  ``effort_v2`` [rad/s]: the total variation of each command over every control
  period, and ``control_effort = effort_v1 + (d/2) effort_v2`` [m/s]: they grow with
  aggressive and chattering inputs, not with steady driving; ``mode_switches``: number
  of changes between ``formation`` and ``avoid`` mode; ``failed_at``: time of the
  first failure of the vehicle, or null.
- ``deadlocks``: ``{vehicles, t, duration}`` for each time healthy vehicles were
  trapped farther than ``metrics.deadlock_distance`` from their slots: stopped (below
  ``metrics.deadlock_speed``) for ``metrics.deadlock_time``, or making less headway
  than ``metrics.deadlock_progress`` of that distance over it, whatever their speed,
  to the end of the run (``metrics.deadlock_creeping: to_end``; ``any``: at any time)
  (:mod:`sandbox.run.deadlock`).
- ``converged``: every healthy vehicle (no failure active at the end of the run, with a
  slot) has a settling time.
- ``steady_state`` (only for a law that keeps a steady error on a turning reference,
  ``rotating`` and ``virtual`` with ``rotate``, see :mod:`sandbox.run.steady_state`):
  the law, the reference's turn rate over the last ``settle_dwell`` [rad/s], each
  follower's steady error by eq. (12) [m] (``errors``), its settling time to within
  ``settle_tol`` of that error [s] (``settling_time``), and ``converged``, whether every
  healthy follower has one: convergence to the law's own steady state, which
  ``converged`` misses when the steady error exceeds ``settle_tol``.
- ``detections`` and ``detection`` (with ``detection: {method: residual}`` only, added
  by the detector through :func:`sandbox.plugins.register_metrics`, see
  :func:`sandbox.behaviour.detection.detection_metrics`): every detection ``{vehicle,
  t, kind, cleared, false_alarm}``, and per failure the detection delay [s] and whether
  the kind was right; ``false_alarms`` counts detections on a vehicle without an active
  failure.
- ``warnings``: what a user should know about the numbers (a saturated motor).
- ``reassignments`` and ``leader_changes`` (only with ``reconfigure`` or
  ``on_leader_failure``, see :mod:`sandbox.behaviour.reconfigure`): ``{t, assignment}``,
  the formation slot each vehicle tracks from then on (null: none), and ``{t, from, to,
  mode}`` (``to`` null: the virtual leader); ``slots``, each vehicle's slots over time
  (``{vehicle: [[t, slot], ...]}``, held from ``t``; see
  :attr:`sandbox.run.record.Run.slot_index`).
- ``platoons``, ``collisions.intra_platoon`` and ``collisions.inter_platoon`` (only
  with ``platoons:``, see :mod:`sandbox.run.platoons`): per platoon its formation
  error, settling time, convergence and contacts; the vehicle-vehicle contacts within
  one platoon and between two.

Formation errors, settling and mode switches read the recorded samples (at the
resolution of ``record_every``); the rest comes from the loop (``Run.info
["loop_metrics"]``) and the physics. A run without loop metrics (built by hand) falls
back to the recorded samples.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.geometry.planar import norms
from sandbox.model.tunnelling import SUBSTEP_FRACTION
from sandbox.plugins.registration import metric_contributions
from sandbox.run.codes import MODE_AVOID, MODE_FORMATION
from sandbox.run.deadlock import find_deadlocks
from sandbox.run.platoons import platoon_metrics
from sandbox.run.steady_state import steady_state

#: Above this many vehicles the minimum distance uses a KD-tree per sample.
BRUTE_FORCE_MAX = 200
#: A free body follows its command when the velocity error is within this fraction of
#: the commanded speed, or within :data:`MOTOR_ABS_TOL` [m/s], whichever is larger.
MOTOR_REL_TOL = 0.01
MOTOR_ABS_TOL = 0.01
#: Up to this many vehicles the in-loop closest approach checks every pair.
ALL_PAIRS_MAX = 64


class ClosestApproach:
    """Smallest centre distance between two vehicles, updated every control period.

    Up to :data:`ALL_PAIRS_MAX` vehicles every pair is checked. Beyond, a Verlet list:
    the pairs closer than ``best + skin`` (KD-tree) are the candidates until some
    vehicle has moved more than ``skin / 2``; a pair closer than the smallest distance
    so far (which only decreases) is then always a candidate, so the result is exact.

    >>> ca = ClosestApproach()
    >>> ca.update(np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 1.0]]))
    >>> ca.best
    1.0
    """

    def __init__(self) -> None:
        self.best = np.inf
        self._anchor: np.ndarray | None = None
        self._skin = 0.0
        self._i = self._j = np.zeros(0, dtype=np.intp)

    def update(self, pos: np.ndarray) -> None:
        """Take the positions (n, 2) [m] of one period into account."""
        n = len(pos)
        if n < 2 or not np.all(np.isfinite(pos)):
            return
        if n <= ALL_PAIRS_MAX:
            if len(self._i) == 0:
                self._i, self._j = np.triu_indices(n, 1)
        else:
            anchor = self._anchor
            if anchor is None:
                self._rebuild(pos)
            else:
                moved = pos - anchor
                worst = np.max(moved[:, 0] * moved[:, 0] + moved[:, 1] * moved[:, 1])
                if worst > 0.25 * self._skin * self._skin:
                    self._rebuild(pos)
        if len(self._i):
            d = pos[self._i] - pos[self._j]
            best = float(np.sqrt(np.min(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])))
            self.best = min(self.best, best)

    def _rebuild(self, pos: np.ndarray) -> None:
        from scipy.spatial import cKDTree

        tree = cKDTree(pos)
        if not np.isfinite(self.best):
            d, _ = tree.query(pos, k=2)
            self.best = float(d[:, 1].min())
        self._skin = max(0.5 * self.best, 0.05)
        pairs = tree.query_pairs(self.best + self._skin, output_type="ndarray")
        self._i, self._j = pairs[:, 0], pairs[:, 1]
        self._anchor = pos.copy()


def min_distance(pose: np.ndarray) -> float | None:
    """Smallest centre distance between two vehicles over all samples [m].

    Parameters
    ----------
    pose : ndarray, shape (T, n, >=2)
    """
    T, n = pose.shape[:2]
    if n < 2 or T == 0:
        return None
    pos = pose[..., :2]
    if n <= BRUTE_FORCE_MAX:
        i, j = np.triu_indices(n, 1)
        best = np.inf
        for chunk in np.array_split(np.arange(T), max(1, T * len(i) // 2_000_000)):
            d = np.linalg.norm(pos[chunk][:, i] - pos[chunk][:, j], axis=-1)
            best = min(best, float(d.min()))
        return best
    from scipy.spatial import cKDTree

    best = np.inf
    for k in range(T):
        d, _ = cKDTree(pos[k]).query(pos[k], k=2)
        best = min(best, float(d[:, 1].min()))
    return best


def settling_time(
    t: np.ndarray, error: np.ndarray, tol: float, dwell: float = 0.0
) -> float | None:
    """First time after which ``error`` stays below ``tol`` until the end, or None.

    The run must also go on for at least ``dwell`` [s] after that time (a last sample
    that happens to fall in band is not settling): otherwise None.

    >>> settling_time(np.arange(5.0), np.array([1.0, 0.5, 0.01, 0.2, 0.01]), 0.05)
    4.0
    >>> settling_time(np.arange(5.0), np.array([1.0, 0.5, 0.01, 0.2, 0.01]), 0.05, 1.0)
    >>> settling_time(np.arange(5.0), np.array([1.0, 0.01, 0.01, 0.01, 0.0]), 0.05, 1.0)
    1.0
    >>> settling_time(np.arange(3.0), np.array([1.0, 0.5, 0.2]), 0.05) is None
    True
    """
    if len(t) == 0 or not np.isfinite(error[-1]) or error[-1] >= tol:
        return None
    above = np.flatnonzero(~(error < tol))
    settled = float(t[0] if len(above) == 0 else t[above[-1] + 1])
    return settled if t[-1] - settled >= dwell - 1e-9 else None


def control_effort(cmd: np.ndarray, diameter: float) -> float:
    """Total variation of recorded commands: ``sum |dv1| + (d/2) sum |dv2|`` [m/s].

    The per-period value of a simulated run comes from :class:`LoopMetrics`; this
    reads samples (every ``record_every`` periods only).

    Parameters
    ----------
    cmd : ndarray, shape (T, 2)
        ``(v1, v2)`` samples of one vehicle.
    diameter : float [m]
    """
    if len(cmd) < 2:
        return 0.0
    d = np.abs(np.diff(cmd, axis=0))
    return float(d[:, 0].sum() + 0.5 * diameter * d[:, 1].sum())


def mode_switches(mode: np.ndarray) -> int:
    """Number of changes between ``formation`` and ``avoid`` in a mode sequence."""
    m = mode[(mode == MODE_FORMATION) | (mode == MODE_AVOID)]
    return int(np.count_nonzero(np.diff(m) != 0))


def healthy_events(run: Any) -> list[bool]:
    """Whether each collision event involved only vehicles without an active failure.

    A vehicle's failure state at an event is the one recorded for the control period the
    event falls in (exact with ``record_every = 1``). Obstacle names are not vehicles.
    """
    index = {name: i for i, name in enumerate(run.names)}
    out = []
    for e in run.events:
        if e.healthy is not None:  # stamped by the physics at the first contact
            out.append(bool(e.healthy))
            continue
        k = max(int(np.searchsorted(run.t, e.t + 1e-9, side="right")) - 1, 0)
        ids = [index[x] for x in (e.a, e.b) if x in index]
        out.append(len(run.t) == 0 or not any(bool(run.failed[k, i]) for i in ids))
    return out


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def compute_metrics(run: Any, settle_tol: float | None = None) -> dict[str, Any]:
    """All metrics of a run, as written to ``metrics.json``.

    Parameters
    ----------
    run : Run
    settle_tol : float, optional
        Tolerance of the settling time [m]; default: the scenario's
        ``metrics.settle_tol`` (0.05 m).
    """
    spec = run.scenario.metrics if run.scenario is not None else None
    if settle_tol is None:
        settle_tol = spec.settle_tol if spec is not None else 0.05
    dwell = spec.settle_dwell if spec is not None else 1.0
    settle_speed = spec.settle_speed if spec is not None else 0.02
    loop = run.info.get("loop_metrics")
    t = np.asarray(run.t)
    T = len(t)
    # The last settle_dwell of the run: a settled vehicle drifts less than
    # settle_speed relative to its slot over it (first and last sample of the window).
    window = int(np.searchsorted(t, t[-1] - dwell - 1e-9)) if T else 0
    span = float(t[-1] - t[window]) if T else 0.0
    last_quarter = t >= t[-1] - 0.25 * (t[-1] - t[0]) if T else np.zeros(0, dtype=bool)
    failed_at = run.info.get("failed_at", {})
    vehicles: dict[str, Any] = {}
    healthy_settled = []
    steady = steady_state(run, dwell) if T else None
    steady_settle: dict[str, float | None] = {}
    healthy_steady = []
    # Vehicles in blocks of about a million samples: bounded temporaries whatever the
    # length of the run (the record may be memory-mapped from disk).
    block = max(1, 1_000_000 // max(T, 1))
    for i, name in enumerate(run.names):
        if i % block == 0:
            cols = slice(i, i + block)
            pose = np.asarray(run.pose[:, cols, :2])
            offset = pose - np.asarray(run.slot[:, cols])
            error = norms(offset)
            cmd = np.asarray(run.cmd[:, cols])
            mode = np.asarray(run.mode[:, cols])
            # a slot at every sample; the largest error (exact in any order)
            slotted = np.isfinite(error).all(axis=0) if T else np.zeros(0, bool)
            largest = error.max(axis=0) if T else np.zeros(0)
        e = error[:, i % block]
        has_slot = T > 0 and bool(slotted[i % block])
        # In band but moving relative to its slot over the last settle_dwell: still
        # crossing it, not settled.
        moved = offset[-1, i % block] - offset[window, i % block] if T else 0.0
        drifting = span > 0 and float(np.hypot(*moved)) > settle_speed * span
        can_settle = has_slot and not drifting
        settle = settling_time(t, e, settle_tol, dwell) if can_settle else None
        failed_end = bool(run.failed[-1, i]) if T else False
        if steady is not None and name in steady["errors"]:
            tol = settle_tol + steady["errors"][name]
            got = settling_time(t, e, tol, dwell) if can_settle else None
            steady_settle[name] = got
            if has_slot and not failed_end:
                healthy_steady.append(got is not None)
        vehicles[name] = {
            "formation_error": {
                "final": _finite(e[-1]) if has_slot else None,
                "rms_last_quarter": _finite(np.sqrt(np.mean(e[last_quarter] ** 2)))
                if has_slot
                else None,
                "max": _finite(largest[i % block]) if has_slot else None,
            },
            "settling_time": settle,
            **_effort(loop, i, cmd[:, i % block], float(run.diameter[i])),
            "mode_switches": mode_switches(mode[:, i % block]),
            "failed_at": failed_at.get(name),
        }
        if has_slot and not failed_end:
            healthy_settled.append(settle is not None)
    for name, block in steering_metrics(run).items():  # cars only
        vehicles[name]["steering"] = block
    vv = [e for e in run.events if e.kind == "vehicle_vehicle"]
    vo = [e for e in run.events if e.kind == "vehicle_obstacle"]
    healthy = healthy_events(run)
    out: dict[str, Any] = {
        "status": run.status,
        "collisions": {
            "total": len(run.events),
            "vehicle_vehicle": len(vv),
            "vehicle_obstacle": len(vo),
            "healthy": int(sum(healthy)),
            "events": [
                {
                    "t": round(e.t, 6),
                    "end": None if e.end is None else round(e.end, 6),
                    "a": e.a,
                    "b": e.b,
                    "kind": e.kind,
                    "healthy": h,
                    "penetration": round(e.penetration, 6),
                }
                for e, h in zip(run.events, healthy, strict=True)
            ],
        },
        "min_distance": loop["min_distance"] if loop else min_distance(run.pose),
        "deadlocks": _deadlocks(run, spec),
        "converged": bool(healthy_settled) and all(healthy_settled),
        "settle_tol": settle_tol,
        "settle_dwell": dwell,
        "duration": float(t[-1]) if T else 0.0,
        "vehicles": vehicles,
    }
    if loop:
        out["motor"] = loop["motor"]
        fast = _tunnelling(run, loop.get("peak_v1"))
        if fast is not None:
            out["tunnelling"] = fast
    keys = (
        "safety",
        "diverged",
        "interrupted",
        "error",
        "reassignments",
        "leader_changes",
    )
    for key in (*keys, "slots"):
        if key in run.info:
            out[key] = run.info[key]
    if steady is not None:
        out["steady_state"] = {
            **steady,
            "settling_time": steady_settle,
            "converged": bool(healthy_steady) and all(healthy_steady),
        }
    platoon_metrics(run, out)  # with platoons: only (run/platoons.py)
    for contribute in metric_contributions().values():  # e.g. the detector's blocks
        out.update(contribute(run))
    out["warnings"] = run_warnings(out)
    return out


def steering_metrics(run: Any) -> dict[str, dict[str, Any]]:
    """Each car's steering (``model: bicycle``): how long it was at its limit.

    ``saturated_time`` [s] is the time the steering angle was at ``max_steer``
    (each sample held until the next), ``saturated_fraction`` that time over the
    run's, ``max_abs`` [rad] the largest angle and ``max_steer`` [rad] the limit.
    Empty for a run without cars, or loaded without its scenario.

    Parameters
    ----------
    run : Run

    Returns
    -------
    dict
        Vehicle name to its block.
    """
    vehicles = getattr(run.scenario, "vehicles", None)
    if run.steer is None or vehicles is None or len(vehicles) != run.n_vehicles:
        return {}
    t = np.asarray(run.t, dtype=float)
    held = np.diff(t)  # each sample's period, the last one none
    total = float(t[-1] - t[0]) if len(t) else 0.0
    out = {}
    for i, v in enumerate(vehicles):
        if v.model != "bicycle" or v.max_steer is None:
            continue
        angle = np.abs(np.asarray(run.steer[:, i], dtype=float))
        at_limit = angle >= v.max_steer * (1.0 - 1e-9)
        time = float(np.sum(held[at_limit[:-1]])) if len(t) > 1 else 0.0
        out[run.names[i]] = {
            "saturated_time": round(time, 6),
            "saturated_fraction": round(time / total, 6) if total > 0 else 0.0,
            "max_abs": _finite(np.nanmax(angle)) if len(t) else None,
            "max_steer": v.max_steer,
        }
    return out


def _deadlocks(run: Any, spec: Any) -> list[dict[str, Any]]:
    """The ``deadlocks`` of ``metrics.json``: :func:`find_deadlocks` of the run."""
    keys = {}
    if spec is not None:
        keys = {
            "speed": spec.deadlock_speed,
            "duration": spec.deadlock_time,
            "distance": spec.deadlock_distance,
            "progress": spec.deadlock_progress,
            "creeping": spec.deadlock_creeping,
        }
    return find_deadlocks(
        np.asarray(run.t),
        np.ascontiguousarray(run.pose[:, :, :2]),
        np.asarray(run.slot),
        np.asarray(run.failed, dtype=bool),
        list(run.names),
        **keys,
    )


def _effort(
    loop: dict[str, Any] | None, i: int, cmd: np.ndarray, diameter: float
) -> dict[str, float]:
    """``control_effort``, ``effort_v1``, ``effort_v2`` of vehicle ``i``.

    From the loop's per-period totals when the run has them, else from the recorded
    commands (a run built by hand, or saved by an earlier version).
    """
    if loop:
        e1, e2 = loop["effort_v1"][i], loop["effort_v2"][i]
    elif len(cmd) >= 2:
        d = np.abs(np.diff(cmd, axis=0))
        e1, e2 = float(d[:, 0].sum()), float(d[:, 1].sum())
    else:
        e1 = e2 = 0.0
    return {
        "control_effort": e1 + 0.5 * diameter * e2,
        "effort_v1": e1,
        "effort_v2": e2,
    }


def _tunnelling(run: Any, peak_v1: list[float] | None) -> dict[str, Any] | None:
    """The vehicle that moved farthest beyond the tunnelling bound in one substep.

    From the commands applied during the run (``LoopMetrics.peak_v1``), not from the
    loader's estimate: a vehicle moving more than :data:`SUBSTEP_FRACTION` of its
    diameter in one physics substep can pass through a thin obstacle or another
    vehicle with no contact. None when every vehicle stayed within the bound.
    """
    sc = run.scenario
    if sc is None or not peak_v1:
        return None
    step = sc.dt / sc.substeps
    per_substep = np.asarray(peak_v1, dtype=float) * step
    bound = SUBSTEP_FRACTION * np.asarray(run.diameter, dtype=float)
    over = per_substep - bound
    worst = int(np.argmax(over))
    if not over[worst] > 0:
        return None
    needed = int(np.ceil(peak_v1[worst] * sc.dt / bound[worst]))
    return {
        "vehicle": run.names[worst],
        "peak_v1": float(peak_v1[worst]),
        "per_substep": float(per_substep[worst]),
        "bound": float(bound[worst]),
        "substeps_needed": needed,
    }


def run_warnings(metrics: dict[str, Any]) -> list[str]:
    """What a user should know about a run's numbers (printed by ``sandbox run``)."""
    out = []
    fast = metrics.get("tunnelling")
    if fast:
        out.append(
            f"vehicle {fast['vehicle']} was driven at up to {fast['peak_v1']:.4g} m/s: "
            f"{fast['per_substep']:.3g} m per physics substep, beyond the "
            f"{fast['bound']:.3g} m (a quarter diameter) within which every contact is "
            f"seen: contacts may have been missed; set vehicle.v1_max, or substeps "
            f">= {fast['substeps_needed']}"
        )
    motor = metrics.get("motor")
    if motor and motor["saturated_fraction"] > 0:
        out.append(
            f"the motor could not follow the commands in "
            f"{100 * motor['saturated_fraction']:.2g} % of the free vehicle-periods "
            f"(velocity error up to {motor['max_velocity_error_free']:.3g} m/s): the "
            "vehicles did not move as eq. (1) says; leave vehicle.motor_accel out "
            "for a motor that follows every command"
        )
    return out


def convergence_summary(metrics: dict[str, Any]) -> str:
    """The summary's word on convergence: ``yes``, or ``no`` and why.

    When the law keeps a steady error on a turning reference (``steady_state``) and
    ``converged`` says no, it also says whether the followers converged to that
    steady state, and its size (eq. (12)).

    >>> convergence_summary({"converged": True})
    'yes'
    >>> steady = {"law": "rotating", "converged": True, "errors": {"red": 0.0566}}
    >>> convergence_summary({"converged": False, "settle_tol": 0.05,
    ...                      "steady_state": steady})
    "no (to settle_tol 0.05 m); yes to the rotating law's own steady state (eq. (12): 0.057 m off the slots)"
    """  # noqa: E501
    if metrics["converged"]:
        return "yes"
    steady = metrics.get("steady_state")
    if not steady or not steady["errors"]:
        return "no"
    sizes = sorted(steady["errors"].values())
    size = (
        f"{sizes[0]:.3f}"
        if sizes[-1] - sizes[0] < 5e-4
        else (f"{sizes[0]:.3f}-{sizes[-1]:.3f}")
    )
    return (
        f"no (to settle_tol {metrics['settle_tol']:g} m); "
        f"{'yes' if steady['converged'] else 'no'} to the {steady['law']} law's own "
        f"steady state (eq. (12): {size} m off the slots)"
    )


#: The terminal summary names at most this many deadlocks (metrics.json has them all).
SUMMARY_DEADLOCKS = 3


def deadlock_summary(metrics: dict[str, Any]) -> str:
    """The summary's line of the ``deadlocks`` of ``metrics.json``.

    Each deadlock by its vehicles, its start and its length [s] ("to the end" when it
    lasts to the end of the run), at most :data:`SUMMARY_DEADLOCKS` of them.

    >>> deadlock_summary({"deadlocks": [], "duration": 10.0})
    'deadlocks: 0'
    >>> entry = {"vehicles": ["red", "green"], "t": 4.0, "duration": 6.0}
    >>> deadlock_summary({"deadlocks": [entry], "duration": 10.0})
    'deadlocks: 1 (red, green from 4.00 s to the end)'
    """
    found = metrics.get("deadlocks") or []
    end = float(metrics.get("duration", 0.0))
    parts = []
    for d in found[:SUMMARY_DEADLOCKS]:
        stop = d["t"] + d["duration"]
        span = "to the end" if stop >= end - 1e-6 else f"for {d['duration']:.2f} s"
        parts.append(f"{', '.join(d['vehicles'])} from {d['t']:.2f} s {span}")
    if len(found) > SUMMARY_DEADLOCKS:
        parts.append(f"{len(found) - SUMMARY_DEADLOCKS} more in metrics.json")
    return f"deadlocks: {len(found)}" + (f" ({'; '.join(parts)})" if parts else "")


def summary_rows(metrics: dict[str, Any]) -> list[tuple[str, str, str, str, str, str]]:
    """Rows ``(vehicle, final error, rms last quarter, settling, effort, switches)``."""

    def fmt(x: float | None, spec: str = ".4f") -> str:
        return "-" if x is None else format(x, spec)

    rows = []
    for name, m in metrics["vehicles"].items():
        fe = m["formation_error"]
        rows.append(
            (
                name,
                fmt(fe["final"]),
                fmt(fe["rms_last_quarter"]),
                fmt(m["settling_time"], ".2f"),
                fmt(m["control_effort"], ".2f"),
                str(m["mode_switches"]),
            )
        )
    return rows
