"""Metrics of a run: pure functions of the recorded :class:`~sandbox.run.Run`.

Definitions (the keys of ``metrics.json``):

- ``collisions``: contact episodes counted from the physics (see
  :class:`~sandbox.run.CollisionEvent`): an episode of a pair starts at its first
  contact and ends once the gap between the surfaces has exceeded
  ``metrics.contact_release``; ``vehicle_vehicle`` and ``vehicle_obstacle`` apart;
  ``healthy``: the episodes in which no vehicle involved had an active failure at the
  first contact (two healthy vehicles, or a healthy vehicle and a static obstacle): what
  recovery is meant to prevent; ``events`` lists ``{t, end, a, b, kind, healthy,
  penetration}``.
- ``min_distance``: smallest centre-to-centre distance between two vehicles over the
  recorded samples [m] (null with a single vehicle).
- per vehicle, ``formation_error``: distance from the vehicle to its slot as its law
defines
  it (the leader's slot is the reference point) [m]: ``final`` (last sample), ``max``,
  and
  ``rms_last_quarter`` (RMS over the last quarter of the run);
  ``settling_time``: first time after which the error stays below ``settle_tol`` until
  the
  end [s], null if it never does (or the vehicle has no slot);
  ``control_effort``: total variation of the commands,
  ``sum |dv1| + (d/2) sum |dv2|`` over the recorded samples [m/s]: it grows with
  aggressive and chattering inputs, not with steady driving;
  ``mode_switches``: number of changes between ``formation`` and ``avoid`` mode;
  ``failed_at``: time of the first failure of the vehicle, or null.
- ``converged``: every healthy vehicle (no failure active at the end of the run, with a
  slot) has a settling time.

Metrics read the recorded samples; with ``record_every > 1`` they are computed at that
resolution.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.run import MODE_AVOID, MODE_FORMATION, Run

#: Above this many vehicles the minimum distance uses a KD-tree per sample.
BRUTE_FORCE_MAX = 200


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


def settling_time(t: np.ndarray, error: np.ndarray, tol: float) -> float | None:
    """First time after which ``error`` stays below ``tol`` until the end, or None.

    >>> settling_time(np.arange(5.0), np.array([1.0, 0.5, 0.01, 0.2, 0.01]), 0.05)
    4.0
    >>> settling_time(np.arange(3.0), np.array([1.0, 0.5, 0.2]), 0.05) is None
    True
    """
    if len(t) == 0 or not np.isfinite(error[-1]) or error[-1] >= tol:
        return None
    above = np.flatnonzero(~(error < tol))
    return float(t[0] if len(above) == 0 else t[above[-1] + 1])


def control_effort(cmd: np.ndarray, diameter: float) -> float:
    """Total variation of the commands: ``sum |dv1| + (d/2) sum |dv2|`` [m/s].

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


def healthy_events(run: Run) -> list[bool]:
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


def compute_metrics(run: Run, settle_tol: float | None = None) -> dict[str, Any]:
    """All metrics of a run, as written to ``metrics.json``.

    Parameters
    ----------
    run : Run
    settle_tol : float, optional
        Tolerance of the settling time [m]; default: the scenario's
        ``metrics.settle_tol``
        (0.05 m).
    """
    if settle_tol is None:
        settle_tol = (
            run.scenario.metrics.settle_tol if run.scenario is not None else 0.05
        )
    t = np.asarray(run.t)
    T = len(t)
    last_quarter = t >= t[-1] - 0.25 * (t[-1] - t[0]) if T else np.zeros(0, dtype=bool)
    failed_at = run.info.get("failed_at", {})
    vehicles: dict[str, Any] = {}
    healthy_settled = []
    # Vehicles in blocks of about a million samples: bounded temporaries whatever the
    # length of the run (the record may be memory-mapped from disk).
    block = max(1, 1_000_000 // max(T, 1))
    for i, name in enumerate(run.names):
        if i % block == 0:
            cols = slice(i, i + block)
            pose = np.asarray(run.pose[:, cols, :2])
            error = np.linalg.norm(pose - np.asarray(run.slot[:, cols]), axis=-1)
            cmd = np.asarray(run.cmd[:, cols])
            mode = np.asarray(run.mode[:, cols])
        e = error[:, i % block]
        has_slot = T > 0 and bool(np.all(np.isfinite(e)))
        settle = settling_time(t, e, settle_tol) if has_slot else None
        failed_end = bool(run.failed[-1, i]) if T else False
        vehicles[name] = {
            "formation_error": {
                "final": _finite(e[-1]) if has_slot else None,
                "rms_last_quarter": _finite(np.sqrt(np.mean(e[last_quarter] ** 2)))
                if has_slot
                else None,
                "max": _finite(np.max(e)) if has_slot else None,
            },
            "settling_time": settle,
            "control_effort": control_effort(cmd[:, i % block], float(run.diameter[i])),
            "mode_switches": mode_switches(mode[:, i % block]),
            "failed_at": failed_at.get(name),
        }
        if has_slot and not failed_end:
            healthy_settled.append(settle is not None)
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
        "min_distance": min_distance(run.pose),
        "converged": bool(healthy_settled) and all(healthy_settled),
        "settle_tol": settle_tol,
        "duration": float(t[-1]) if T else 0.0,
        "vehicles": vehicles,
    }
    for key in ("diverged", "interrupted"):
        if key in run.info:
            out[key] = run.info[key]
    return out


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
