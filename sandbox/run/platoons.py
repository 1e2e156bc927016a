"""Metrics and views of a run of several platoons (``platoons:``).

:func:`platoon_metrics` gives the entries ``metrics.json`` gains with ``platoons:``:

- ``collisions.intra_platoon`` and ``collisions.inter_platoon``: the vehicle-vehicle
  contact episodes (counted as every episode is, see :mod:`sandbox.run.metrics`)
  between two vehicles of one platoon, and of two platoons;
- ``platoons: {NAME: {vehicles, formation_error, settling_time, converged,
  collisions}}``: per platoon, the worst ``final`` and ``max`` formation error of its
  vehicles and the RMS over its vehicles of their ``rms_last_quarter`` [m]; the
  latest settling time of its healthy vehicles [s] (null if one never settles);
  whether every healthy vehicle of it settles; and the contacts involving it
  (``intra_platoon``, ``inter_platoon``, ``vehicle_obstacle``);
- ``platoon_events`` (with ``events:``): each merge or split that fired, ``{t, merge
  | split, platoons}`` with the platoons' vehicles after it (a merge also gives each
  vehicle's new offset). The per-platoon entries and the intra/inter split of the
  contacts keep the platoons of the file (the membership at the start);
- ``formation_timeline`` (with ``events:``): the fleet's slots through merges, splits
  and reassignments, each vehicle's ``[[t, platoon, offset], ...]`` held from ``t``
  (offset null: no slot); :func:`formation_at` gives it per sample.

:func:`platoon_view` is :meth:`sandbox.run.record.Run.platoon`: the run of one
platoon's vehicles only.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np


def membership(run: Any) -> tuple[list[str], dict[str, int]] | None:
    """The platoons' names and each vehicle's platoon index, or None (one platoon)."""
    sc = run.scenario
    if sc is None or not getattr(sc, "platoons", ()):
        return None
    names = [p.name for p in sc.platoons]
    of = {}
    for k, p in enumerate(sc.platoons):
        for i in p.rows:
            of[run.names[i]] = k
    return names, of


def platoon_metrics(run: Any, out: dict[str, Any]) -> None:
    """Add the per-platoon entries to ``out`` (``compute_metrics``'s dict) in place."""
    found = membership(run)
    if found is None:
        return
    names, of = found
    events = [e for e in out["collisions"]["events"] if e["kind"] == "vehicle_vehicle"]
    intra = [e for e in events if of.get(e["a"]) == of.get(e["b"])]
    out["collisions"]["intra_platoon"] = len(intra)
    out["collisions"]["inter_platoon"] = len(events) - len(intra)
    T = len(run.t)
    per: dict[str, Any] = {}
    for k, name in enumerate(names):
        members = [v for v in run.names if of[v] == k]
        rows = [run.names.index(v) for v in members]
        stats = [out["vehicles"][v] for v in members]
        errors = [s["formation_error"] for s in stats]
        with_slot = [e for e in errors if e["final"] is not None]
        healthy = [
            s
            for v, s, i in zip(members, stats, rows, strict=True)
            if s["formation_error"]["final"] is not None
            and not (T and bool(run.failed[-1, i]))
        ]
        times = [s["settling_time"] for s in healthy]
        mine = [
            e
            for e in out["collisions"]["events"]
            if k in (of.get(e["a"]), of.get(e["b"]))
        ]
        per[name] = {
            "vehicles": members,
            "formation_error": {
                "final": max((e["final"] for e in with_slot), default=None),
                "rms_last_quarter": float(
                    np.sqrt(np.mean([e["rms_last_quarter"] ** 2 for e in with_slot]))
                )
                if with_slot
                else None,
                "max": max((e["max"] for e in with_slot), default=None),
            },
            "settling_time": None
            if not times or any(t is None for t in times)
            else max(times),
            "converged": bool(times) and all(t is not None for t in times),
            "collisions": {
                "intra_platoon": sum(
                    1 for e in mine if e in intra and of.get(e["a"]) == k
                ),
                "inter_platoon": sum(
                    1 for e in mine if e["kind"] == "vehicle_vehicle" and e not in intra
                ),
                "vehicle_obstacle": sum(
                    1 for e in mine if e["kind"] == "vehicle_obstacle"
                ),
            },
        }
    out["platoons"] = per
    if "platoon_events" in run.info:
        out["platoon_events"] = run.info["platoon_events"]
    if "formation_timeline" in run.info:
        out["formation_timeline"] = run.info["formation_timeline"]


def platoon_view(run: Any, name: str) -> Any:
    """The run of platoon ``name``'s vehicles only (a :class:`Run` of its rows).

    The arrays are those of the platoon's rows, its reference the platoon's own
    (evaluated at the samples), its events those involving one of its vehicles;
    ``scenario`` is the platoon's own scenario. Raises ``KeyError`` listing the
    platoons for an unknown name, and ``ValueError`` for a run of one platoon.
    """
    found = membership(run)
    if found is None:
        raise ValueError("the run has one platoon (no platoons: section)")
    names, _ = found
    if name not in names:
        raise KeyError(f"no platoon {name!r}; the platoons: {', '.join(names)}")
    spec = run.scenario.platoons[names.index(name)]
    rows = list(spec.rows)
    mine = {run.names[i] for i in rows}
    sub = spec.scenario
    if sub.reference is not None:
        reference = np.asarray(sub.reference.build().evaluate(run.t)[0], dtype=float)
        reference = np.broadcast_to(reference, (len(run.t), 2)).copy()
    else:
        reference = np.full((len(run.t), 2), np.nan)
    return dataclasses.replace(
        run,
        pose=run.pose[:, rows],
        cmd=run.cmd[:, rows],
        chi=run.chi[:, rows],
        slot=run.slot[:, rows],
        target=run.target[:, rows],
        mode=run.mode[:, rows],
        failed=run.failed[:, rows],
        steer=None if run.steer is None else run.steer[:, rows],
        reference=reference,
        names=[run.names[i] for i in rows],
        colors=[run.colors[i] for i in rows],
        diameter=run.diameter[rows],
        leader=sub.leader_index,
        events=[e for e in run.events if e.a in mine or e.b in mine],
        info={k: v for k, v in run.info.items() if k != "loop_metrics"},
        scenario=sub,
    )


def formation_at(run: Any) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Each vehicle's platoon and offset at each sample: :meth:`Run.formation_at`.

    Returns ``names`` (every platoon that existed, in the order they appeared),
    ``platoon`` (T, n) int (an index into ``names``; -1 for a vehicle that has left
    every formation, which does not happen) and ``offset`` (T, n, 2) [m] (NaN: no
    slot). Without ``info["formation_timeline"]`` (no ``events:``) the platoons are
    those of the file and each offset is the one of the slot the vehicle holds
    (:attr:`Run.slot_index` into the vehicles' offsets).
    """
    t = np.asarray(run.t, dtype=float)
    T, n = len(t), run.n_vehicles
    platoon = np.full((T, n), -1, dtype=int)
    offset = np.full((T, n, 2), np.nan)
    timeline = run.info.get("formation_timeline")
    if timeline is None:
        found = membership(run)
        names = found[0] if found else ["platoon"]
        for i, name in enumerate(run.names):
            platoon[:, i] = found[1][name] if found else 0
        sc = run.scenario
        if sc is not None:
            slots = np.array([v.offset for v in sc.vehicles], dtype=float)
            held = run.slot_index
            offset = np.where(
                (held >= 0)[..., None], slots[np.maximum(held, 0)], np.nan
            )
        return names, platoon, offset
    first: dict[str, tuple[float, int]] = {}
    for i, vehicle in enumerate(run.names):
        for start, name, _ in timeline[vehicle]:
            first[name] = min(first.get(name, (start, i)), (start, i))
    names = sorted(first, key=first.__getitem__)
    for i, vehicle in enumerate(run.names):
        for start, name, held in timeline[vehicle]:
            after = t >= start - 1e-9
            platoon[after, i] = names.index(name)
            offset[after, i] = np.nan if held is None else held
    return names, platoon, offset
