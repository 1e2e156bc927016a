"""The tunnelling guard: whether a vehicle can move too far in one physics substep.

pymunk has no continuous collision detection: two shapes that pass through each other
within one substep never touch, and no contact is reported. A vehicle that moves more
than a quarter of its diameter per substep can pass a thin obstacle or another vehicle
(measured: d = 0.2 m pairs at 100 m/s each, h / substeps = 2.5 ms, pass through each
other with no event). :func:`tunnelling_warning` bounds the fastest motion a scenario
allows and, when it is too fast, says which ``substeps`` would be safe. The scenario
loader adds the warning (``sandbox validate`` and ``sandbox run`` print it).

The speed of a vehicle is:

- its ``v1_max`` when it has one (chi, hence v1, is clamped to it);
- otherwise the speed the gains ask for: the peak of ``|chi|`` of eq. (6) advanced by
  forward Euler at ``dt`` from rest with the vehicle's initial distance to its target
  (the reference's start or the leader's position, plus its offset), plus the
  reference's largest speed; an estimate from the linear error dynamics (turning and
  the rotating laws can ask for more);
- for a vehicle driven by a command schedule, its largest ``|v1|``;
- the ``v1`` of an ``uncontrolled`` failure, when larger.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: A vehicle may move at most this fraction of its diameter per physics substep.
SUBSTEP_FRACTION = 0.25
#: Samples of the reference over the run to find its largest speed.
REFERENCE_SAMPLES = 400


def peak_gain_speed(
    k_pos: float, k_vel: float, dt: float, error: float | np.ndarray, v_ref: float
) -> float | np.ndarray:
    """Largest ``|chi|`` [m/s] eq. (6) asks for from rest at ``error`` [m].

    Forward Euler of the error dynamics, as the loop advances them: ``e+ = e + dt c``,
    ``c+ = c + dt (k_pos e + k_vel c)`` from ``e = error``, ``c = -v_ref`` (chi = 0),
    for ten time constants; returns ``max |c| + v_ref``. ``error`` may be an array of
    initial errors (one per vehicle): they are advanced together, one numpy step per
    period, and an array of peaks is returned.

    >>> round(peak_gain_speed(-100.0, -20.0, 0.01, 1.0, 0.0), 2)
    3.87
    """
    errors = np.atleast_1d(np.asarray(error, dtype=float))
    peak = np.full(errors.shape, abs(v_ref))
    if k_pos < 0 and k_vel < 0:
        poles = np.roots([1.0, -k_vel, -k_pos])
        steps = int(min(100_000, 10.0 / max(1e-9, np.min(-poles.real)) / dt) + 1)
        live = errors > 0.0
        e, c = errors[live], np.full(int(live.sum()), -abs(v_ref))
        top = peak[live]
        for _ in range(steps if len(e) else 0):
            e, c = e + dt * c, c + dt * (k_pos * e + k_vel * c)
            np.maximum(top, np.abs(c), out=top)
        peak[live] = top
    out = peak + abs(v_ref)
    return float(out[0]) if np.ndim(error) == 0 else out


def fastest_speeds(
    vehicles: Sequence,
    failures: Sequence,
    reference,
    law: str | None,
    dt: float,
    duration: float,
    frame: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """Fastest speed [m/s] each vehicle can reach in the scenario, shape (n,).

    ``frame`` is ``(x, y, angle)``, where the formation law puts the slots at t = 0
    (the point offsets are added to [m], the angle they are turned by [rad]): a
    follower's initial error is then its distance to its own slot. Without it, the
    error is bounded by its distance to the anchor plus the length of its offset.
    """
    ref_speed, ref_start = 0.0, None
    if reference is not None:
        built = reference.build()
        times = np.linspace(0.0, duration, REFERENCE_SAMPLES)
        p, dp, _ = built.evaluate(times)
        ref_speed = float(np.max(np.hypot(dp[:, 0], dp[:, 1])))
        ref_start = np.asarray(p[0], dtype=float)
    leader = next((v for v in vehicles if v.leader), None)
    out = np.zeros(len(vehicles))
    # Vehicles driven by their gains, grouped by gains: one vectorised peak per group.
    groups: dict[tuple[float, float], list[tuple[int, float]]] = {}
    for i, v in enumerate(vehicles):
        if v.drive.type == "commands":
            out[i] = max((abs(row[1]) for row in v.drive.schedule), default=0.0)
        elif v.v1_max is not None:
            out[i] = v.v1_max
        else:
            pos = np.asarray(v.pose[:2], dtype=float)
            own_reference = v.leader or law == "virtual" or leader is None
            if own_reference and ref_start is not None:
                anchor = ref_start
            elif leader is not None:
                anchor = np.asarray(leader.pose[:2], dtype=float)
            else:
                anchor = pos
            if frame is not None and not own_reference:
                c, sn = math.cos(frame[2]), math.sin(frame[2])
                d1, d2 = v.offset
                slot = (frame[0] + c * d1 - sn * d2, frame[1] + sn * d1 + c * d2)
                error = float(np.hypot(pos[0] - slot[0], pos[1] - slot[1]))
            else:
                error = float(np.hypot(*(pos - anchor)) + np.hypot(*v.offset))
            g = v.gains
            for gains in ((g.k1, g.k2), (g.k3, g.k4)):
                groups.setdefault(gains, []).append((i, error))
    for (k_pos, k_vel), members in groups.items():
        rows = np.array([i for i, _ in members], dtype=np.intp)
        peaks = peak_gain_speed(
            k_pos, k_vel, dt, np.array([e for _, e in members]), ref_speed
        )
        np.maximum.at(out, rows, peaks)
    names = [v.name for v in vehicles]
    for f in failures:
        if f.kind == "uncontrolled" and f.v1 is not None and f.vehicle in names:
            i = names.index(f.vehicle)
            out[i] = max(out[i], abs(f.v1))
    return out


def tunnelling_warning(
    vehicles: Sequence,
    failures: Sequence,
    reference,
    law: str | None,
    dt: float,
    substeps: int,
    duration: float,
    frame: tuple[float, float, float] | None = None,
) -> str | None:
    """A warning when some vehicle can move more than a quarter diameter per substep.

    Returns None when every vehicle is slow enough; otherwise one sentence naming the
    fastest such vehicle, its motion per substep, and the smallest safe ``substeps``.
    """
    if not vehicles:
        return None
    speed = fastest_speeds(vehicles, failures, reference, law, dt, duration, frame)
    diameter = np.array([v.diameter for v in vehicles], dtype=float)
    h = dt / substeps
    ratio = speed * h / diameter
    worst = int(np.argmax(ratio))
    if ratio[worst] <= SUBSTEP_FRACTION:
        return None
    safe = max(
        math.ceil(s * dt / (SUBSTEP_FRACTION * d) - 1e-9)
        for s, d in zip(speed, diameter, strict=True)
    )
    v = vehicles[worst]
    how = (
        "its v1_max"
        if v.v1_max is not None and v.drive.type != "commands"
        else "its command schedule"
        if v.drive.type == "commands"
        else "the speed the gains ask for from its initial error (no v1_max)"
    )
    return (
        f"vehicle {v.name!r} can move {speed[worst] * h:.3g} m per physics substep "
        f"({speed[worst]:.3g} m/s, {how}, x dt/substeps = {h:.3g} s), more than a "
        f"quarter of its diameter ({SUBSTEP_FRACTION * diameter[worst]:.3g} m): "
        "contacts can be missed (tunnelling; pymunk has no continuous collision "
        f"detection). substeps >= {safe} would be safe, or a lower vehicle.v1_max"
    )
