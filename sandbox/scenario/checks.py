"""Checks that involve several sections of a scenario.

They run on what the sections read validly, so a file's problems are all reported at
once without follow-on noise: vehicle names, leaders, the sections a law or a vehicle
needs, the stability bound of eq. (6) on the control period, vehicles that start
overlapping each other or an obstacle, and slots too close together.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from sandbox import plugins
from sandbox.model.flatness import (
    error_poles,
    max_control_period,
)
from sandbox.model.obstacles import ObstacleSpec
from sandbox.scenario.reader import (
    MAX_STEPS,
    Reader,
    describe,
    hint,
)
from sandbox.scenario.specs import (
    FailureSpec,
    FormationSpec,
    PlatoonSpec,
    RecoverySpec,
    ReferenceSpec,
    VehicleSpec,
)


def check_consistency(
    rd: Reader,
    doc: dict[Any, Any],
    duration: float | None,
    dt: float | None,
    vehicles: list[tuple[str, VehicleSpec]],
    reference: ReferenceSpec | None,
    formation: FormationSpec | None,
    failures: list[tuple[str, FailureSpec]],
    obstacles: list[tuple[str, ObstacleSpec]],
    platoon: PlatoonSpec | None,
    recovery: RecoverySpec | None = None,
) -> None:
    """Checks that involve several sections.

    They run even when some sections have problems, on what is valid: a field that
    could not be read is skipped here (its own problem is already reported), so every
    problem of a file is reported at once without follow-on noise.
    """
    declared = list(rd.declared)
    if platoon is not None:
        declared += [
            ("platoon", f"{platoon.prefix}{i}", False) for i in range(platoon.count)
        ]
    if (
        not declared
        and doc.get("platoon") is None
        and doc.get("vehicles") in (None, [])
    ):
        rd.fail(
            "vehicles",
            "required key is missing (no vehicles)",
            describe(doc.get("vehicles")),
            "a 'vehicles' list with at least one vehicle, or a 'platoon'",
        )
    if duration is not None and dt is not None:
        if dt >= duration:
            rd.fail(
                "dt",
                "must be shorter than the duration",
                f"dt = {dt:g} s, duration = {duration:g} s",
                "dt < duration",
            )
        elif duration / dt > MAX_STEPS:
            rd.fail(
                "dt",
                "too many control steps",
                f"duration / dt = {duration / dt:.3g} steps",
                f"at most {MAX_STEPS:g} steps: a longer dt or a shorter duration",
            )
    if dt is not None:
        _check_gains(rd, doc, dt, vehicles)

    names: dict[str, str] = {}
    for where, name, _ in declared:
        if name in names:
            if where == "platoon":
                rd.fail(
                    "platoon.prefix",
                    "generated names clash with listed vehicles",
                    f"{name!r} (also {names[name]})",
                    "a prefix no listed name uses",
                )
                break
            rd.fail(
                f"{where}.name",
                "duplicate vehicle name",
                f"{name!r} (also {names[name]})",
                "unique names",
            )
        names.setdefault(name, where)
    leaders = [(where, name) for where, name, leader in declared if leader]
    if len(leaders) > 1:
        rd.fail(
            f"{leaders[1][0]}.leader",
            "two leaders",
            f"{leaders[0][1]} and {leaders[1][1]}",
            "at most one vehicle with leader: true",
        )
    law = formation.law if formation else None
    if doc.get("formation") is None and len(declared) > 1:
        rd.fail(
            "formation",
            "required key is missing (several vehicles need a formation law)",
            "nothing",
            f"formation: {{law: one of {', '.join(plugins.names('law'))}}}",
        )
    law_options = plugins.get("law", law).options if law is not None else {}
    if law is not None and law_options["needs_leader"] and not leaders:
        rd.fail(
            "vehicles",
            f"the {law} law needs a leader",
            "no vehicle with leader: true",
            "exactly one vehicle with leader: true",
        )
    needs_ref = []
    for where, v in vehicles:
        tracks = v.drive.type == "reference"
        if tracks and (len(declared) == 1 or v.leader or law == "virtual"):
            needs_ref.append((where, v))
    needed = needs_ref or (law is not None and law_options["needs_reference"])
    if needed and doc.get("reference") is None:
        who = f"vehicle {needs_ref[0][1].name}" if needs_ref else f"the {law} law"
        rd.fail(
            "reference",
            f"required key is missing ({who} tracks the reference)",
            "nothing",
            "a reference trajectory, or drive: {type: commands, schedule: "
            "...} for the leader",
        )
    _check_geometry(rd, vehicles, law, recovery)
    _check_obstacle_starts(rd, vehicles, obstacles)
    for where, vehicle, at in rd.timed:
        if vehicle is not None and vehicle not in names:
            rd.fail(
                f"{where}.vehicle",
                f"no such vehicle{hint(vehicle, tuple(names))}",
                repr(vehicle),
                f"one of: {', '.join(list(names)[:10])}"
                + (", ..." if len(names) > 10 else ""),
            )
        if duration is not None and at is not None and at >= duration:
            if "duration" in rd.overridden:
                rd.warn(
                    f"{where}.at",
                    f"failure at {at:g} s never starts: the run was "
                    f"shortened to {duration:g} s",
                )
                continue
            rd.fail(
                f"{where}.at",
                "timed outside the run",
                f"at = {at:g} s",
                f"a time before the end of the run, duration = {duration:g} s",
            )
    seen: dict[str, str] = {}
    for where, o in obstacles:
        if o.name in names or o.name in seen:
            rd.fail(
                f"{where}.name",
                "duplicate name",
                f"{o.name!r} (also {names.get(o.name) or seen.get(o.name)})",
                "names unique among vehicles and obstacles",
            )
        seen.setdefault(o.name, where)


def _gains_path(doc: dict[Any, Any], where: str) -> str:
    """Where a vehicle's gains were set: its own ``gains``, else ``vehicle.gains``."""
    if where.startswith("vehicles["):
        index = int(where[len("vehicles[") : -1])
        item = doc["vehicles"][index]
        if isinstance(item, Mapping) and item.get("gains") is not None:
            return f"{where}.gains"
    shared = doc.get("vehicle")
    if isinstance(shared, Mapping) and shared.get("gains") is not None:
        return "vehicle.gains"
    return ""


def _check_gains(
    rd: Reader, doc: dict[Any, Any], dt: float, vehicles: list[tuple[str, VehicleSpec]]
) -> None:
    """Check that the discrete update of eq. (6) is stable with the gains and period.

    The loop advances chi by forward Euler once per period ``dt`` and the vehicle moves
    with the chi of the period's start, so the tracking error obeys ``e+ = e + dt c``,
    ``c+ = c + dt (k_pos e + k_vel c)``: its poles are ``z = 1 + dt s`` for the poles
    ``s`` of ``s^2 - k_vel s - k_pos``. The bound is
    :func:`~sandbox.model.flatness.max_control_period` (``|z| < 1`` and ``Re z > 0``;
    0.1 s for the report's gains). Gains unstable for every period are a warning (a
    deliberate experiment); stable gains with too long a period are an error. The
    heading loop ``e3+ = (1 - dt kp) e3`` needs ``dt kp < 2``.
    """
    checked: set[tuple[Any, ...]] = set()
    for where, v in vehicles:
        if v.drive.type != "reference":
            continue
        g = v.gains
        gains_path = _gains_path(doc, where)
        key = (g.k1, g.k2, g.k3, g.k4, g.kp, gains_path)
        if key in checked:
            continue
        checked.add(key)
        here = gains_path or "vehicle"
        who = v.name if gains_path.startswith("vehicles[") else "the vehicles"
        dt_path = "dt" if doc.get("dt") is not None else (gains_path or "dt")
        axes = [("1", g.k1, g.k2), ("2", g.k3, g.k4)]
        if (g.k1, g.k2) == (g.k3, g.k4):
            axes = axes[:1]
        for axis, k_pos, k_vel in axes:
            names = f"k{2 * int(axis) - 1} = {k_pos:g}, k{2 * int(axis)} = {k_vel:g}"
            if len(axes) == 1:
                names = f"k1 = k3 = {k_pos:g}, k2 = k4 = {k_vel:g}"
            bound = max_control_period(k_pos, k_vel)
            poles = error_poles(k_pos, k_vel)
            shown = ", ".join(_pole_text(s) for s in poles)
            if bound == 0.0:
                rd.warn(
                    here,
                    f"gains {names} of {who} do not stabilise eq. (6) for "
                    f"any control period: the error poles s = {shown} [1/s] (roots "
                    "of s^2 - k_vel s - k_pos) need k_pos < 0 and k_vel < 0, the "
                    "report's sign convention; expect the run to diverge",
                )
                continue
            if dt >= bound:
                z = 1.0 + dt * poles
                got_z = ", ".join(_pole_text(complex(v)) for v in z)
                rd.fail(
                    dt_path,
                    f"control period too long for the gains of {who} "
                    f"({names}): eq. (6) is advanced by forward Euler once per "
                    f"period, so its error poles s = {shown} [1/s] become "
                    "z = 1 + dt s; the loop needs |z| < 1 and, because a unicycle "
                    "cannot back up (v1 = |chi| >= 0) and so cannot follow a chi "
                    "that reverses every period, Re z > 0: dt < min(-2 Re s / "
                    f"|s|^2, 1 / max|Re s|) = {bound:.4g} s",
                    f"dt = {dt:g} s, z = {got_z}",
                    f"dt < {bound:.4g} s, and well below it; the report uses 0.01 s",
                )
                return
        if g.kp <= 0:
            rd.warn(
                here,
                f"kp = {g.kp:g} of {who} does not turn the vehicle toward chi "
                "(eq. (5) needs kp > 0): its heading error will not decay",
            )
        elif dt * g.kp >= 2.0:
            rd.fail(
                dt_path,
                f"control period too long for kp = {g.kp:g} of {who}: the "
                "heading error of eq. (5) evolves as e3+ = (1 - dt kp) e3, stable only "
                "while dt kp < 2",
                f"dt = {dt:g} s, dt kp = {dt * g.kp:.3g}",
                f"dt < {2.0 / g.kp:.4g} s",
            )
            return


def _pole_text(s: complex) -> str:
    if abs(s.imag) < 1e-12:
        return f"{s.real:.4g}"
    return f"{s.real:.4g}{s.imag:+.4g}j"


#: Up to this many discs the overlap checks compare every pair with numpy (80,000
#: pairs at most) instead of querying k-d trees: importing scipy.spatial costs about
#: 0.4 s, far more than checking a small fleet, and ``sandbox validate`` stays fast.
BRUTE_FORCE_PAIRS = 400


def _with_neighbours(
    tree: Any,
    pos: np.ndarray,
    rad: np.ndarray,
    small: np.ndarray,
    reach: float,
    same: bool,
) -> Iterator[int]:
    """The discs of ``small`` with any other disc of ``tree`` within reach.

    Counted in C a block at a time (no lists are built), so that only those discs are
    looked at one by one; a block in a dense crowd yields at once and the caller stops.
    """
    for lo in range(0, len(small), 1024):
        block = small[lo : lo + 1024]
        counts = tree.query_ball_point(
            pos[block], rad[block] + reach, return_length=True
        )
        yield from (int(a) for a in block[np.asarray(counts) > (1 if same else 0)])


def overlapping_pairs(
    pos: np.ndarray, rad: np.ndarray, limit: int
) -> Iterator[tuple[int, int, float]]:
    """Yield up to ``limit`` pairs ``(a, b, distance)`` of discs that overlap.

    Discs overlap when their centres are closer than the sum of their radii. The work
    is near-linear in the number of discs however many overlap: discs are grouped by
    radius in octaves, and each disc of a group looks for overlaps in each group of
    radii at least as large, within the sum of its radius and that group's largest. In
    that neighbourhood at most about 36 discs of the larger group fit without
    overlapping each other, so a query that returns more candidates holds an
    overlapping pair among its first 37, which is reported instead of reading on. Up to
    :data:`BRUTE_FORCE_PAIRS` discs, every pair is compared instead.
    """
    if len(pos) < 2:
        return
    if len(pos) <= BRUTE_FORCE_PAIRS:  # every pair, in (a, b) order
        i, j = np.triu_indices(len(pos), k=1)
        dist = np.hypot(*(pos[i] - pos[j]).T)
        for k in np.flatnonzero(dist < rad[i] + rad[j] - 1e-9)[:limit]:
            yield int(i[k]), int(j[k]), float(dist[k])
        return
    octave = np.floor(np.log2(rad)).astype(int)
    groups = [np.flatnonzero(octave == o) for o in np.unique(octave)]
    from scipy.spatial import cKDTree  # lazily: importing scipy costs ~0.5 s

    trees = [cKDTree(pos[g]) for g in groups]
    reported: set[tuple[int, int]] = set()

    def overlap(a: int, b: int) -> float | None:
        if a == b or (min(a, b), max(a, b)) in reported:
            return None
        dist = float(np.hypot(*(pos[a] - pos[b])))
        if dist < rad[a] + rad[b] - 1e-9:
            reported.add((min(a, b), max(a, b)))
            return dist
        return None

    for gi, small in enumerate(groups):
        for gj in range(gi, len(groups)):
            big, tree = groups[gj], trees[gj]
            reach = float(rad[big].max())
            for a in _with_neighbours(tree, pos, rad, small, reach, gi == gj):
                found = tree.query_ball_point(pos[a], rad[a] + reach)
                found = [int(big[k]) for k in found[:37]]
                if len(found) == 37:
                    pairs = [(a, b) for b in found]
                    pairs += [(c, b) for i, c in enumerate(found) for b in found[i:]]
                else:
                    pairs = [(a, b) for b in found]
                for c, b in pairs:
                    dist = overlap(c, b)
                    if dist is not None:
                        yield (min(c, b), max(c, b), dist)
                        limit -= 1
                        if limit <= 0:
                            return


def _check_geometry(
    rd: Reader,
    vehicles: list[tuple[str, VehicleSpec]],
    law: str | None,
    recovery: RecoverySpec | None = None,
) -> None:
    """Report vehicles that start overlapping, warn of slots too close together.

    Slots closer than a diameter cannot both be reached; with a recovery strategy on,
    slots closer than its radius R keep avoidance active for good, so the formation
    never settles (report section 3.3: avoidance acts inside R).
    """
    if len(vehicles) < 2:
        return
    pos = np.array([v.pose[:2] for _, v in vehicles])
    rad = np.array([v.diameter / 2 for _, v in vehicles])
    for shown, (a, b, dist) in enumerate(overlapping_pairs(pos, rad, 6)):
        if shown == 5:
            rd.fail(
                f"{vehicles[b][0]}.pose",
                "more vehicles start overlapping",
                "more than 5 overlapping pairs",
                "no overlap (first 5 shown)",
            )
            break
        where, vb = vehicles[b]
        path = f"{where}.pose" if where != "platoon" else "platoon.spacing"
        rd.fail(
            path,
            f"{vb.name} starts overlapping {vehicles[a][1].name}",
            f"centres {dist:.3g} m apart",
            f"at least {rad[a] + rad[b]:g} m, the sum of their radii",
        )
    if law is None:
        return
    # Slots of the vehicles a law drives; a leader the law follows sits at the origin
    # of the formation frame, whatever its offset.
    slotted = [i for i, (_, v) in enumerate(vehicles) if v.drive.type == "reference"]
    if len(slotted) < 2:
        return
    vehicles = [vehicles[i] for i in slotted]
    rad = rad[slotted]
    off = np.array([v.offset for _, v in vehicles], dtype=float)
    leads = np.array([v.leader for _, v in vehicles])
    if plugins.get("law", law).options["needs_leader"]:
        off[leads] = 0.0
    idx = np.flatnonzero(~leads)
    close = set()
    for a, b, gap in overlapping_pairs(off[idx], rad[idx], 3):
        a, b = int(idx[a]), int(idx[b])
        close.add((a, b))
        where = vehicles[b][0]
        rd.warn(
            f"{where}.offset" if where != "platoon" else "platoon.spacing",
            f"slots of {vehicles[a][1].name} and {vehicles[b][1].name} are "
            f"{gap:.3g} m apart, closer than a diameter: they cannot both reach "
            "them",
        )
    if recovery is None or recovery.strategy == "none":
        return
    # The leader's slot is its own offset (the origin of the formation frame).
    half = np.full(len(vehicles), recovery.R / 2.0)
    shown = 0
    for a, b, gap in overlapping_pairs(off, half, 6):
        if (a, b) in close:
            continue
        shown += 1
        if shown > 3:
            break
        where = vehicles[b][0]
        rd.warn(
            f"{where}.offset" if where != "platoon" else "platoon.spacing",
            f"slots of {vehicles[a][1].name} and {vehicles[b][1].name} are "
            f"{gap:.3g} m apart, within recovery.R = {recovery.R:g} m: avoidance "
            f"({recovery.strategy}) stays active between them and the formation "
            f"never settles (slots at least R apart, or a smaller R)",
        )


def _distance_to_obstacle(o: ObstacleSpec, p: np.ndarray) -> np.ndarray:
    """Distance [m] from points ``p`` (k, 2) to an obstacle's shape; 0 inside it.

    Circles and walls are measured as pymunk builds them (a wall is a segment with
    rounded ends, radius half its thickness); boxes and polygons by their outline.
    """
    if o.type == "circle":
        return np.maximum(np.hypot(*(p - np.asarray(o.center)).T) - o.radius, 0.0)
    if o.type == "wall":
        a, b = np.asarray(o.start), np.asarray(o.end)
        ab = b - a
        t = np.clip((p - a) @ ab / float(ab @ ab), 0.0, 1.0)
        near = a + t[:, None] * ab
        return np.maximum(np.hypot(*(p - near).T) - o.thickness / 2.0, 0.0)
    poly = np.asarray(o.outline(), dtype=float)
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a  # (m, 2)
    ap = p[:, None, :] - a[None]  # (k, m, 2)
    t = np.clip(np.einsum("kmi,mi->km", ap, ab) / np.einsum("mi,mi->m", ab, ab), 0, 1)
    edge = np.hypot(*(ap - t[..., None] * ab[None]).transpose(2, 0, 1)).min(axis=1)
    cross = ab[None, :, 0] * ap[..., 1] - ab[None, :, 1] * ap[..., 0]
    inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    return np.where(inside, 0.0, edge)


def _check_obstacle_starts(
    rd: Reader,
    vehicles: list[tuple[str, VehicleSpec]],
    obstacles: list[tuple[str, ObstacleSpec]],
) -> None:
    """Report vehicles that start inside or touching into an obstacle (first 5).

    Only the vehicles near each obstacle's bounding circle are measured, found with a
    k-d tree (every vehicle, up to :data:`BRUTE_FORCE_PAIRS`), and the search stops at
    the fifth problem.
    """
    if not vehicles or not obstacles:
        return
    pos = np.array([v.pose[:2] for _, v in vehicles])
    rad = np.array([v.diameter / 2 for _, v in vehicles])
    tree = None  # a small fleet is measured whole; a large one through a k-d tree
    if len(pos) > BRUTE_FORCE_PAIRS:
        from scipy.spatial import cKDTree

        tree = cKDTree(pos)
    shown = 0
    for where, o in obstacles:
        if o.type == "circle":
            centre, bound = np.asarray(o.center), o.radius
        elif o.type == "wall":
            a, b = np.asarray(o.start), np.asarray(o.end)
            centre = (a + b) / 2
            bound = float(np.hypot(*(b - a))) / 2 + o.thickness / 2
        else:
            pts = np.asarray(o.outline(), dtype=float)
            centre = pts.mean(axis=0)
            bound = float(np.hypot(*(pts - centre).T).max())
        near = (
            np.arange(len(pos))
            if tree is None
            else np.array(tree.query_ball_point(centre, bound + rad.max()), dtype=int)
        )
        for lo in range(0, len(near), 4096):
            chunk = near[lo : lo + 4096]
            gap = _distance_to_obstacle(o, pos[chunk])
            for k in np.flatnonzero(gap < rad[chunk] - 1e-9):
                i = int(chunk[k])
                shown += 1
                if shown > 5:
                    rd.fail(
                        f"{where}",
                        "more vehicles start overlapping obstacles",
                        "more than 5",
                        "vehicles clear of every obstacle (first 5 shown)",
                    )
                    return
                vw, v = vehicles[i]
                got = (
                    f"its centre {gap[k]:.3g} m from it, radius {rad[i]:g} m"
                    if gap[k] > 0
                    else "its centre inside it"
                )
                rd.fail(
                    f"{vw}.pose" if vw != "platoon" else "platoon",
                    f"{v.name} starts overlapping obstacle {o.name} "
                    f"({o.type}, {where})",
                    got,
                    "a start clear of every obstacle",
                )
