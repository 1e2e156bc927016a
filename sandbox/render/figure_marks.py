"""Marks of a run's events on the time axis of the formation-error figure.

The figure is :func:`sandbox.render.figures.formation_error_figure`.
Detections (``detection: residual``) are triangles on the bottom edge, in the detected
vehicle's colour; reassignments (``reconfigure``) and leader changes
(``on_leader_failure``) are marks just above the top edge at the event's time, the
time the platoon decided (the new slots are held from the next period): a diamond in
the new leader's colour (grey for the virtual leader) where the lead changed, else a
grey down-triangle, labelled with the new leader (``lead: red``) and the slots that
changed (``green→1`` for green now in slot 1, ``red→none`` for red without a slot).
Like :mod:`sandbox.render.figures`, this module never imports ``pyplot``.
"""

from __future__ import annotations

from matplotlib.axes import Axes
from matplotlib.transforms import offset_copy

from sandbox.run.record import Run

__all__ = ["MAX_LISTED", "TITLE_PAD", "detection_marks", "reconfiguration_marks"]

#: Most slot changes a reassignment's label lists (then "+k more").
MAX_LISTED = 4
#: How far above the top edge the reconfiguration marks sit [points].
MARK_RISE = 6.0
#: The title's distance above the axes when they are drawn [points].
TITLE_PAD = 16.0
#: Colour of the marks that belong to no vehicle (reassignments, the virtual leader).
NEUTRAL = "0.35"


def _info(run: Run, key: str) -> object:
    """Return ``run.info[key]``, or ``None``."""
    return run.info.get(key) if isinstance(run.info, dict) else None


def detection_marks(ax: Axes, run: Run, colors: list[str]) -> None:
    """Detections (``detection: residual``) as triangles on the time axis.

    A filled triangle in the vehicle's colour where it was detected (labelled with the
    kind detected), a hollow one where the detection was withdrawn, a black cross on
    the triangle where a detection was a false alarm (the vehicle had no active
    failure then).
    """
    block = _info(run, "detection")
    if not isinstance(block, dict) or not block.get("events"):
        return
    from sandbox.behaviour.detection import detection_metrics

    listed = _info(run, "failures")
    marked = detection_metrics(run.info, listed if isinstance(listed, list) else [])
    index = {name: k for k, name in enumerate(run.names)}
    axis = ax.get_xaxis_transform()  # x in data, y in axes fraction
    mark = {"transform": axis, "clip_on": False, "ls": "none", "ms": 9}
    seen = {"detected": False, "false alarm": False, "detection cleared": False}
    for d in marked["detections"]:
        i = index.get(d["vehicle"])
        if i is None:
            continue
        ax.plot(d["t"], 0.0, marker="^", color=colors[i], zorder=6, **mark)
        seen["detected"] = True
        what = "false alarm" if d["false_alarm"] else "detected"
        if d["false_alarm"]:
            ax.plot(d["t"], 0.0, marker="x", color="black", zorder=7, **mark)
            seen["false alarm"] = True
        ax.annotate(
            f"{d['vehicle']} {what}: {d['kind']}",
            (d["t"], 0.04),
            xycoords=axis,
            xytext=(3, 3),
            textcoords="offset points",
            va="bottom",
            fontsize=7,
            rotation=90,
        )
        if d.get("cleared") is not None:
            ax.plot(d["cleared"], 0.0, marker="^", mfc="none", color=colors[i], **mark)
            seen["detection cleared"] = True
    # Legend entries in grey: the colour is the vehicle's.
    styles = {
        "detected": {"marker": "^"},
        "false alarm": {"marker": "x"},
        "detection cleared": {"marker": "^", "mfc": "none"},
    }
    for label, shown in seen.items():
        if shown:
            ax.plot([], [], ls="none", ms=9, color="0.35", label=label, **styles[label])


def changed_slots(run: Run, event: dict) -> list[str]:
    """``"NAME→SLOT"`` of every vehicle whose slot an assignment changed."""
    slots = _info(run, "slots")
    out = []
    for name, slot in event.get("assignment", {}).items():
        steps = slots.get(name) if isinstance(slots, dict) else None
        before = None
        if steps:  # the slot held just before the event
            held = [s for t, s in steps if t <= event["t"] + 1e-9]
            before = held[-1] if held else None
        if steps is None or before != slot:
            out.append(f"{name}\u2192{'none' if slot is None else slot}")
    return out


def reconfiguration_marks(ax: Axes, run: Run, colors: list[str]) -> bool:
    """Reassignments and leader changes as marks above the top edge of ``ax``.

    One mark per event time: a diamond where the lead changed (the reassignment that
    goes with it is in its label), else a down-triangle. See the module docstring.

    Returns
    -------
    bool
        Whether anything was drawn (the title then needs room above the marks).
    """
    moves = _info(run, "reassignments") or []
    leads = _info(run, "leader_changes") or []
    if not moves and not leads:
        return False
    index = {name: k for k, name in enumerate(run.names)}
    axis = ax.get_xaxis_transform()  # x in data, y in axes fraction
    above = offset_copy(axis, fig=ax.figure, y=MARK_RISE, units="points")
    mark = {"transform": above, "clip_on": False, "ls": "none", "ms": 8, "zorder": 6}
    labels: dict[float, list[str]] = {}
    for event in moves:
        changed = changed_slots(run, event)
        if len(changed) > MAX_LISTED:
            extra = len(changed) - MAX_LISTED
            changed = changed[:MAX_LISTED] + [f"+{extra} more"]
        labels.setdefault(event["t"], []).append("slots: " + ", ".join(changed))
    led = set()
    for change in leads:
        heir = change.get("to")
        color = NEUTRAL if heir not in index else colors[index[heir]]
        ax.plot(change["t"], 1.0, marker="D", color=color, mec="black", **mark)
        led.add(change["t"])
        name = "reference" if heir is None else heir
        labels.setdefault(change["t"], []).insert(0, f"lead: {name}")
    for t in labels:
        if t not in led:
            ax.plot(t, 1.0, marker="v", color=NEUTRAL, **mark)
    for t, lines in labels.items():
        ax.annotate(
            "; ".join(lines),
            (t, 1.0),
            xycoords=axis,
            xytext=(-4, -3),
            textcoords="offset points",
            ha="right",
            va="top",
            fontsize=7,
            rotation=90,
            color="0.2",
        )
    if set(labels) - led:
        ax.plot([], [], ls="none", ms=8, marker="v", color=NEUTRAL, label="reassigned")
    if led:
        ax.plot(
            [],
            [],
            ls="none",
            ms=8,
            marker="D",
            color=NEUTRAL,
            mec="black",
            label="leader change",
        )
    return True
