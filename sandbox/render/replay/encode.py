"""The data a replay page embeds: a run's arrays packed compactly, marks and summary.

:func:`replay_data` turns a :class:`~sandbox.run.record.Run` into one JSON-ready mapping
that the page's script reads. Every recorded array is quantised to whole multiples of a
step (:data:`STEPS`: 0.1 mm for lengths, 0.1 mrad for angles, 1 us for times),
differenced along time (twice for the smooth quantities: what is left is mostly a few
units), its ``int32`` bytes regrouped by significance (all lowest bytes first, then the
next; the high ones are then nearly all zeros), compressed with zlib and written in
base64 (:func:`pack`). The browser undoes it with its built-in
``DecompressionStream("deflate")``; no library is needed. A 60 s run of 10 vehicles
recorded every 10 ms makes a page of about 140 kB this way (at most 2 MB is asked).

A record of more than :data:`MAX_VEHICLE_SAMPLES` vehicle-samples (samples times
vehicles) is decimated in time: every ``stride``-th sample is kept (and the last one),
and the page says so. The events marked on the page's timeline are read with the
functions the figures and the GIF use
(:func:`sandbox.behaviour.detection.detection_metrics`,
:func:`sandbox.render.figure_marks.changed_slots`; a collision's health from the
metrics), the obstacles and the reference path as the GIF draws them
(``drawn_obstacles`` and ``reference_path`` of :mod:`sandbox.render.camera`), the first
view as the GIF frames it (``content_bounds``,
:func:`~sandbox.render.camera.auto_follow` and
:meth:`~sandbox.render.camera.Camera.for_run`), and the colours with the GIF's palette
(:func:`sandbox.render.palette.color_rgb`).

With ``platoons:`` the mapping also has ``platoons`` (each platoon's ``name``,
``color``, ``since`` and ``until``: those of
:func:`sandbox.render.platoons.platoon_tracks`, a platoon formed by a split included)
and ``arrays.platoon_reference``, their reference points packed as one (T, P, 2)
array, NaN while a platoon does not exist; the page draws each reference path through
the finite samples. A run of one platoon has neither key: its mapping is as before.

Everything is a pure function of the run: the same run gives the same mapping, and the
same bytes once written.
"""

from __future__ import annotations

import base64
import math
import zlib
from typing import Any

import numpy as np

from sandbox.run.constrained import constrained_mask, filter_name
from sandbox.run.record import MODE_NAMES, Run

__all__ = [
    "FORMAT",
    "LARGE_FLEET",
    "MAX_BEAM_READINGS",
    "MAX_VEHICLE_SAMPLES",
    "STEPS",
    "beam_data",
    "pack",
    "replay_data",
    "unpack",
]

#: Version of the embedded data (the page's script checks it).
FORMAT = 1
#: Most vehicle-samples (recorded samples times vehicles) a page embeds whole; a
#: longer record is decimated in time. About 40 bytes of page per vehicle-sample at
#: most, and 36 bytes of browser memory.
MAX_VEHICLE_SAMPLES = 1_500_000
#: Most range readings (recorded samples times vehicles times beams) a page with the
#: beams (``--show-beams``) embeds; a longer record is decimated in time the same way.
#: About 2 to 4 bytes of page per reading, and 4 bytes of browser memory.
MAX_BEAM_READINGS = 2_000_000
#: Fleets larger than this are drawn without trails, slot marks and names (as the GIF).
LARGE_FLEET = 100
#: Fleets up to this size get a closest-approach mark (pairwise distances per sample).
CLOSEST_MAX = 200
#: Quantisation step of each packed array [m], [rad], [m/s], [rad/s], [s] or 1.
STEPS = {
    "t": 1e-6,
    "pose": 1e-4,
    "cmd": 1e-4,
    "slot": 1e-4,
    "target": 1e-4,
    "reference": 1e-4,
    "platoon_reference": 1e-4,
    "state": 1.0,
    "slot_index": 1.0,
}
#: How many times each packed array is differenced along time.
ORDERS = {"state": 1, "slot_index": 1}
#: The packed code of a value that is not finite (NaN, an undefined slot).
MISSING = -(2**31)
_LIMIT = 2**31 - 2  # largest magnitude of a quantised value
#: Order of the kinds of marks at one time (the timeline draws them in this order).
KINDS = ("failure", "detection", "leader_change", "reassignment", "collision")


# ---------------------------------------------------------------------------- packing
def pack(
    values: np.ndarray, step: float, order: int = 2, level: int = 9
) -> dict[str, Any]:
    """Pack an array whose first axis is time into a compact JSON-ready mapping.

    Parameters
    ----------
    values : ndarray, shape (T, ...)
        Finite values, or NaN/inf where undefined (decoded as NaN).
    step : float
        Quantisation step, in the array's units; widened so that the largest finite
        magnitude still fits in an ``int32``.
    order : int
        How many times to difference along the first axis (0, 1 or 2).
    level : int
        zlib's compression level (9: the smallest; 6 for noisy data such as range
        readings, where 9 searches for matches up to 30 times longer for about 1 %).

    Returns
    -------
    dict
        ``shape``, ``step`` (the one used), ``order`` and ``data``: base64 of the zlib
        stream of the differences' ``int32`` little-endian bytes, grouped by byte
        position.

    Examples
    --------
    >>> p = pack(np.array([0.0, 0.5, 1.0, np.nan]), 0.5)
    >>> p["shape"], p["step"], unpack(p).tolist()
    ([4], 0.5, [0.0, 0.5, 1.0, nan])
    """
    arr = np.asarray(values, dtype=float)
    finite = np.isfinite(arr)
    top = float(np.max(np.abs(arr[finite]), initial=0.0))
    step = float(max(step, top / _LIMIT)) if top > 0 else float(step)
    q = np.full(arr.shape, MISSING, dtype=np.int64)
    q[finite] = np.clip(np.round(arr[finite] / step), -_LIMIT, _LIMIT).astype(np.int64)
    for _ in range(order):  # modular differences: exact whatever the values
        q = np.concatenate((q[:1], np.diff(q, axis=0)), axis=0) if len(q) else q
        q = q.astype(np.int32).astype(np.int64)  # wrap to 32 bits
    raw = q.astype("<i4").tobytes()
    planes = np.frombuffer(raw, dtype=np.uint8).reshape(-1, 4).T.tobytes()
    data = base64.b64encode(zlib.compress(planes, level)).decode("ascii")
    return {"shape": list(arr.shape), "step": step, "order": int(order), "data": data}


def unpack(packed: dict[str, Any]) -> np.ndarray:
    """Decode a mapping made by :func:`pack` (as the page's script does).

    Returns
    -------
    ndarray, of ``packed["shape"]``, float64
        The quantised values, NaN where the packed values were not finite.
    """
    shape = tuple(packed["shape"])
    planes = np.frombuffer(zlib.decompress(base64.b64decode(packed["data"])), np.uint8)
    raw = planes.reshape(4, -1).T.copy().tobytes()
    q = np.frombuffer(raw, dtype="<i4").astype(np.int64).reshape(shape)
    for _ in range(int(packed["order"])):
        q = np.cumsum(q, axis=0).astype(np.int32).astype(np.int64)
    out = q.astype(float) * float(packed["step"])
    out[q == MISSING] = np.nan
    return out


# ---------------------------------------------------------------------------- content
def _hex(color: str, k: int) -> str:
    """``#rrggbb`` of a vehicle colour, as the GIF's palette resolves it."""
    from sandbox.render.palette import color_rgb

    return "#{:02x}{:02x}{:02x}".format(*color_rgb(color, k))


def _rounded(x: Any, digits: int = 6) -> float | None:
    """A finite float rounded to ``digits`` decimals, or None."""
    try:
        value = float(x)
    except (TypeError, ValueError):
        return None
    return round(value, digits) if math.isfinite(value) else None


def _info(run: Run, key: str) -> Any:
    return run.info.get(key) if isinstance(run.info, dict) else None


def _obstacles(run: Run) -> list[dict[str, Any]]:
    """Obstacles as the GIF draws them, walls told apart by the scenario."""
    from sandbox.render.camera import drawn_obstacles as drawn

    raw = _info(run, "obstacles") or []
    names = [ob.get("name") if isinstance(ob, dict) else None for ob in raw]
    walls = set()
    if run.scenario is not None:
        walls = {o.name for o in run.scenario.obstacles if o.type == "wall"}
    out = []
    for k, (kind, geom) in enumerate(drawn(run)):
        name = names[k] if k < len(names) and names[k] else f"obstacle[{k}]"
        if kind == "circle":
            (cx, cy), r = geom
            out.append(
                {
                    "type": "circle",
                    "name": name,
                    "center": [_rounded(cx), _rounded(cy)],
                    "radius": _rounded(r),
                }
            )
        else:
            pts = [[_rounded(x), _rounded(y)] for x, y in np.asarray(geom).tolist()]
            out.append(
                {
                    "type": "polygon",
                    "name": name,
                    "points": pts,
                    "wall": name in walls,
                }
            )
    return out


def _events(run: Run, pos: np.ndarray, metrics: dict[str, Any]) -> list[dict[str, Any]]:
    """The marked events in time order: ``{t, kind, ...}`` (see the module doc).

    ``pos`` is the full record's positions (T, n, 2) [m]; a collision's ``x1, x2`` is
    the middle of its parties at the recorded sample nearest to it. Whether a
    collision involved only healthy vehicles is read from ``metrics``.
    """
    t = np.asarray(run.t, dtype=float)
    index = {name: i for i, name in enumerate(run.names)}
    end = float(t[-1])
    listed = (metrics.get("collisions") or {}).get("events") or []
    health = [e.get("healthy") for e in listed]
    if len(health) != len(run.events):
        health = [None] * len(run.events)
    out: list[dict[str, Any]] = []
    for ev, healthy in zip(run.events, health, strict=True):
        k = int(np.clip(np.searchsorted(t, ev.t), 0, len(t) - 1))
        if k > 0 and abs(t[k - 1] - ev.t) <= abs(t[k] - ev.t):
            k -= 1
        bodies = [index[x] for x in (ev.a, ev.b) if x in index]
        mid = pos[k, bodies].mean(axis=0) if bodies else np.full(2, np.nan)
        out.append(
            {
                "t": _rounded(ev.t),
                "kind": "collision",
                "a": ev.a,
                "b": ev.b,
                "contact": ev.kind,
                "end": _rounded(ev.end),
                "healthy": healthy,
                "penetration": _rounded(ev.penetration),
                "x1": _rounded(mid[0]),
                "x2": _rounded(mid[1]),
            }
        )
    failures = _info(run, "failures") or []
    for f in failures:
        at = _rounded(f.get("at"))
        if at is None or at > end + 1e-9:
            continue  # scheduled after the run ended: never happened
        out.append(
            {
                "t": at,
                "kind": "failure",
                "vehicle": f.get("vehicle"),
                "failure": f.get("kind"),
                "until": _rounded(f.get("until")),
            }
        )
    if isinstance(_info(run, "detection"), dict):
        from sandbox.behaviour.detection import detection_metrics

        marked = detection_metrics(run.info, failures) or {}
        for d in marked.get("detections", []):
            out.append(
                {
                    "t": _rounded(d["t"]),
                    "kind": "detection",
                    "vehicle": d["vehicle"],
                    "detected": d.get("kind"),
                    "false_alarm": bool(d.get("false_alarm")),
                    "cleared": _rounded(d.get("cleared")),
                }
            )
    moves = _info(run, "reassignments") or []
    if moves:
        from sandbox.render.figure_marks import changed_slots

        for event in moves:
            out.append(
                {
                    "t": _rounded(event["t"]),
                    "kind": "reassignment",
                    "changes": changed_slots(run, event),
                }
            )
    for change in _info(run, "leader_changes") or []:
        out.append(
            {
                "t": _rounded(change["t"]),
                "kind": "leader_change",
                "from": change.get("from"),
                "to": change.get("to"),
                "mode": change.get("mode"),
            }
        )
    rank = {k: i for i, k in enumerate(KINDS)}
    out = [e for e in out if e["t"] is not None]
    out.sort(key=lambda e: (e["t"], rank[e["kind"]]))
    return out


def _closest(run: Run, pos: np.ndarray) -> dict[str, Any] | None:
    """The closest approach of two vehicles' surfaces: ``{t, a, b, gap}``.

    None above :data:`CLOSEST_MAX` vehicles or with fewer than two.
    """
    n = run.n_vehicles
    if n < 2 or n > CLOSEST_MAX:
        return None
    radius = np.asarray(run.diameter, dtype=float) / 2.0
    reach = radius[:, None] + radius[None, :]
    iu = np.triu_indices(n, 1)
    best = (np.inf, 0, 0, 0)
    block = max(1, 2_000_000 // (n * n))
    for start in range(0, len(pos), block):
        p = pos[start : start + block]
        d = np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1)
        gap = (d - reach)[:, iu[0], iu[1]]
        gap = np.where(np.isfinite(gap), gap, np.inf)
        k, j = np.unravel_index(int(np.argmin(gap)), gap.shape)
        if gap[k, j] < best[0]:
            best = (float(gap[k, j]), start + int(k), int(iu[0][j]), int(iu[1][j]))
    if not math.isfinite(best[0]):
        return None
    gap, k, i, j = best
    return {
        "t": _rounded(run.t[k]),
        "a": run.names[i],
        "b": run.names[j],
        "gap": _rounded(gap),
    }


def _summary(run: Run, metrics: dict[str, Any]) -> dict[str, Any]:
    """Status, collisions and settling of the run, from its metrics."""
    col = metrics.get("collisions", {})
    settle = []
    never = []
    for name in run.names:
        m = metrics.get("vehicles", {}).get(name, {})
        if (m.get("formation_error") or {}).get("final") is None:
            continue  # no slot: nothing to settle
        if m.get("settling_time") is None:
            never.append(name)
        else:
            settle.append(float(m["settling_time"]))
    out = {
        "status": metrics.get("status", run.status),
        "collisions": int(col.get("total", len(run.events))),
        "vehicle_vehicle": int(col.get("vehicle_vehicle", 0)),
        "vehicle_obstacle": int(col.get("vehicle_obstacle", 0)),
        "healthy_collisions": int(col.get("healthy", 0)),
        "converged": bool(metrics.get("converged", False)),
        "settled": len(settle),
        "never_settled": never,
        "settling_time": _rounded(max(settle)) if settle else None,
        "min_distance": _rounded(metrics.get("min_distance")),
        "duration": _rounded(metrics.get("duration", float(run.t[-1]))),
    }
    if isinstance(metrics.get("diverged"), dict):
        d = metrics["diverged"]
        out["diverged"] = {
            "t": _rounded(d.get("t")),
            "vehicle": d.get("vehicle"),
            "reason": d.get("reason"),
        }
    return out


def decimation(
    samples: int, vehicles: int, budget: int | None = None, beams: int = 0
) -> int:
    """The stride in time that keeps a record within the page's budgets.

    Within ``budget`` vehicle-samples (default :data:`MAX_VEHICLE_SAMPLES`) and, with
    ``beams`` beams a vehicle embedded, within :data:`MAX_BEAM_READINGS` readings.

    >>> decimation(6001, 10), decimation(18001, 1000), decimation(6001, 16, beams=1024)
    (1, 13, 50)
    """
    limit = MAX_VEHICLE_SAMPLES if budget is None else int(budget)
    stride = -(-samples * vehicles // max(limit, 1))
    if beams > 0:
        stride = max(stride, -(-samples * vehicles * beams // MAX_BEAM_READINGS))
    return max(1, stride)


def replay_data(
    run: Run,
    metrics: dict[str, Any] | None = None,
    *,
    title: str | None = None,
    max_vehicle_samples: int | None = None,
    beams: int = 0,
) -> dict[str, Any]:
    """The mapping a replay page embeds (see the module docstring).

    Parameters
    ----------
    run : Run
    metrics : dict, optional
        The run's metrics (``metrics.json``); computed when not given.
    title : str, optional
        The name shown; default the scenario's name.
    max_vehicle_samples : int, optional
        Decimation budget; default :data:`MAX_VEHICLE_SAMPLES`.
    beams : int
        The beams a vehicle the page will embed (:func:`beam_data`), counted in the
        decimation against :data:`MAX_BEAM_READINGS`; 0: none.

    Returns
    -------
    dict
        JSON-ready; keys ``format``, ``scenario``, ``names``, ``colors``,
        ``diameter``, ``leader``, ``arrays`` (packed ``t``, ``pose``, ``cmd``,
        ``slot``, ``target``, ``reference``, ``state``, ``slot_index``), ``events``,
        ``closest``, ``summary``, ``obstacles``, ``reference_path``, ``bounds``,
        ``recovery``, ``camera``, ``leaders`` (``[t, name]``: who leads from ``t``;
        None: the reference), ``modes``, ``samples``, ``stride``, ``notes``; with
        ``platoons:`` also ``platoons`` and ``arrays.platoon_reference`` (see the
        module docstring); with a safety filter also ``filter``, its name (bit 3
        of ``state``: the filter changed the vehicle's command).
    """
    if metrics is None:
        from sandbox.run.metrics import compute_metrics

        metrics = compute_metrics(run)
    from sandbox.render.camera import (
        Camera,
        auto_follow,
        content_bounds,
        reference_path,
    )

    t = np.asarray(run.t, dtype=float)
    T, n = len(t), run.n_vehicles
    pos = np.asarray(run.pose[:, :, :2], dtype=float)
    stride = decimation(T, n, max_vehicle_samples, beams)
    keep = np.arange(0, T, stride)
    if keep[-1] != T - 1:
        keep = np.append(keep, T - 1)
    mode = np.asarray(run.mode, dtype=np.int64)[keep]
    failed = np.asarray(run.failed, dtype=bool)[keep]
    constrained = constrained_mask(run)
    filtered = np.zeros_like(failed) if constrained is None else constrained[keep]
    arrays = {
        "t": pack(t[keep], STEPS["t"]),
        "pose": pack(np.asarray(run.pose, dtype=float)[keep], STEPS["pose"]),
        "cmd": pack(np.asarray(run.cmd, dtype=float)[keep], STEPS["cmd"]),
        "slot": pack(np.asarray(run.slot, dtype=float)[keep], STEPS["slot"]),
        "target": pack(np.asarray(run.target, dtype=float)[keep], STEPS["target"]),
        "reference": pack(
            np.asarray(run.reference, dtype=float).reshape(T, 2)[keep],
            STEPS["reference"],
        ),
        # mode in the low bits, the failure flag in bit 2, the safety filter's in 3
        "state": pack(mode + 4 * failed + 8 * filtered, 1.0, ORDERS["state"]),
        "slot_index": pack(run.slot_index[keep], 1.0, ORDERS["slot_index"]),
    }
    platoons = _platoons(run, keep, arrays)
    reach = float(np.max(run.diameter, initial=0.0)) / 2.0
    lo, hi = content_bounds(run, reach)
    path = reference_path(run)
    notes = []
    if stride > 1:
        notes.append(
            f"Decimated in time: every {stride}th of the {T:,} recorded samples is "
            f"shown ({len(keep):,} samples; a page holds at most "
            f"{max_vehicle_samples or MAX_VEHICLE_SAMPLES:,} vehicle-samples"
            + (f" and {MAX_BEAM_READINGS:,} range readings" if beams > 0 else "")
            + ")."
        )
    if n > LARGE_FLEET:
        notes.append(
            f"{n:,} vehicles: trails, slots, targets and names are not drawn (as in "
            "the GIF); the chart shows the largest and the mean formation error."
        )
    # The first view: the GIF's automatic camera (the leader of a run spread along a
    # line, with the GIF's window; else the whole run).
    camera: dict[str, Any] = {"follow": None, "width": None}
    if auto_follow(run) == "leader" and run.leader >= 0:
        size = 640
        scale = Camera.for_run(run, size, "leader", legend=False).scale
        camera = {"follow": run.names[run.leader], "width": _rounded(size / scale)}
    # Who leads when: ``Run.leader`` is the leader at the end; before the first leader
    # change the lead is that change's ``from``.
    changes = _info(run, "leader_changes") or []
    first = changes[0].get("from") if changes else None
    if not changes and run.leader >= 0:
        first = run.names[run.leader]
    leaders = [[_rounded(t[0]), first]] + [
        [_rounded(c["t"]), c.get("to")] for c in changes
    ]
    rec = _info(run, "recovery")
    rec = rec if isinstance(rec, dict) else {}
    label = _info(run, "scenario_name")
    scenario = run.scenario
    data = {
        "format": FORMAT,
        "scenario": str(title or label or getattr(scenario, "name", "") or "run"),
        "description": str(getattr(scenario, "description", "") or ""),
        "names": list(run.names),
        "colors": [_hex(c, k) for k, c in enumerate(run.colors)],
        "diameter": [_rounded(d) for d in np.asarray(run.diameter, dtype=float)],
        "leader": int(run.leader),
        "arrays": arrays,
        "samples": int(len(keep)),
        "recorded_samples": int(T),
        "stride": int(stride),
        "events": _events(run, pos, metrics),
        "closest": _closest(run, pos) if not run.events else None,
        "summary": _summary(run, metrics),
        "obstacles": _obstacles(run),
        "reference_path": None
        if path is None
        else [[_rounded(x, 4), _rounded(y, 4)] for x, y in path.tolist()],
        "bounds": [_rounded(v) for v in (*lo, *hi)],
        "recovery": {
            "strategy": str(rec.get("strategy", "-")),
            "R": _rounded(rec.get("R")),
            "r": _rounded(rec.get("r")),
        },
        "camera": camera,
        "leaders": leaders,
        "modes": list(MODE_NAMES),
        "large": n > LARGE_FLEET,
        "notes": notes,
    }
    if platoons is not None:
        data["platoons"] = platoons
    if filter_name(run) is not None:  # the safety filter (state bit 3: it acts)
        data["filter"] = filter_name(run)
    return data


def _platoons(
    run: Run, keep: np.ndarray, arrays: dict[str, Any]
) -> list[dict[str, Any]] | None:
    """Each platoon's entry of the page; packs their references into ``arrays``.

    None (and ``arrays`` untouched) for a run of one platoon.
    """
    from sandbox.render.platoons import platoon_tracks

    tracks = platoon_tracks(run)
    if tracks is None:
        return None
    refs = np.stack([tr.reference for tr in tracks], axis=1)  # (T, P, 2) [m]
    arrays["platoon_reference"] = pack(refs[keep], STEPS["platoon_reference"])
    return [
        {
            "name": tr.name,
            "color": _hex(tr.color, k),
            "since": _rounded(tr.since),
            "until": _rounded(tr.until),
        }
        for k, tr in enumerate(tracks)
    ]


def beam_data(run: Run, data: dict[str, Any]) -> dict[str, Any] | None:
    """The range sensors' scans for the page, on its samples; None without scans.

    ``ranges`` packed like the other arrays (0.1 mm steps, differenced once, zlib's
    level 6: readings are noisy; NaN for a vehicle or beam without a sensor), ``angles``
    each beam's angle about the heading (n, B) [rad], ``reach`` each vehicle's
    ``max_range`` [m] (a reading there hit nothing; None without a sensor).
    """
    if run.ranges is None or run.beam_angles is None:
        return None
    T = len(run.t)
    keep = np.arange(0, T, int(data["stride"]))
    if keep[-1] != T - 1:
        keep = np.append(keep, T - 1)
    ranges = np.asarray(run.ranges)[keep].astype(float)  # the samples kept only
    specs = None
    if run.scenario is not None and hasattr(run.scenario, "range_specs"):
        specs = run.scenario.range_specs()
    if specs is None or len(specs) != run.n_vehicles:
        with np.errstate(all="ignore"):
            reach = [_rounded(v) for v in np.nanmax(ranges, axis=(0, 2))]
    else:
        reach = [None if s is None else _rounded(s.max_range) for s in specs]
    return {
        "ranges": pack(ranges, STEPS["pose"], order=1, level=6),
        "angles": [[_rounded(a) for a in row] for row in run.beam_angles.tolist()],
        "reach": reach,
        "width": int(run.beam_angles.shape[1]),
    }
