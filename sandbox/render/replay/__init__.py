"""Interactive replay of a run in the browser: one self-contained HTML file.

:func:`write_html` writes a page that shows a recorded run as the GIF does (vehicles as
discs of their diameter with their heading, slots, targets, obstacles and walls,
trails, contact marks) and lets one play it, scrub a timeline on which every
collision, failure, detection, reassignment and leader change is marked, zoom, pan,
follow a vehicle and read its state beside a formation-error chart. The page needs no
network: its data (:mod:`sandbox.render.replay.encode`), style and plain-JavaScript
script are inlined, and it opens from disk in current Chromium and Firefox. ``sandbox
view RUN_DIR`` and ``sandbox run FILE --html`` call it; the page of a sweep (``sandbox
sweep view DIR``) is :func:`sandbox.study.sweep_page.write_sweep_html`'s. See
``docs/replay.md``.

Tests drive a page through ``window.sandboxReplay`` (``seek(t)``, ``play()``,
``pause()``, ``state()``, ``events()``; documented in ``docs/replay.md``).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from sandbox.render.replay.page import (
    GENERATOR,
    ReplayError,
    asset,
    build_page,
    check_output,
)
from sandbox.render.replay.page import write_page as _write_page

__all__ = [
    "GENERATOR",
    "ReplayError",
    "check_output",
    "replay_html",
    "write_html",
]


def replay_html(
    run: Any,
    metrics: dict[str, Any] | None = None,
    *,
    title: str | None = None,
    max_vehicle_samples: int | None = None,
    show_beams: bool = False,
) -> str:
    """The HTML text of the replay page of ``run`` (see :func:`write_html`)."""
    from sandbox.render.replay.encode import replay_data

    width = 0  # the beams a vehicle, counted in the page's budget
    if show_beams and run.ranges is not None and run.beam_angles is not None:
        width = int(run.beam_angles.shape[-1])
    data = replay_data(
        run,
        metrics,
        title=title,
        max_vehicle_samples=max_vehicle_samples,
        beams=width,
    )
    transforms = []
    if width:
        from sandbox.render.replay.encode import beam_data

        beams = beam_data(run, data)
        if beams is not None:
            data["beams"] = beams
            transforms.append(with_beams)
    if "platoons" in data:  # several platoons: their references
        transforms.append(with_platoons)
    from sandbox.render.replay.encode import car_data

    cars = car_data(run, data)
    if cars is not None:  # cars: their chassis and steered wheels
        data["cars"] = cars
        transforms.append(with_cars)

    def transform(script: str) -> str:
        for step in transforms:
            script = step(script)
        return script

    return build_page(
        "replay.html",
        data["scenario"],
        data,
        ["replay.js"],
        transform=transform if transforms else None,
    )


def with_pieces(script: str, name: str) -> str:
    """``replay.js`` with the pieces of the asset ``name`` inserted.

    Each piece follows a line ``// @@ after: ANCHOR``, ``// @@ before: ANCHOR`` or
    ``// @@ instead: ANCHOR`` and goes right after or before the line ``ANCHOR`` of
    the script, or replaces it (a page without the feature keeps the script as it
    is, so its bytes do not change).

    Raises
    ------
    ValueError
        An anchor is not exactly once in the script.
    """
    pieces = asset(name).split("// @@ ")[1:]
    for piece in pieces:
        head, _, body = piece.partition("\n")
        where, _, anchor = head.partition(": ")
        line = anchor + "\n"
        if script.count(line) != 1:
            raise ValueError(f"{name}: anchor {anchor!r} not once in the page")
        new = {"after": line + body, "before": body + line, "instead": body}[where]
        script = script.replace(line, new)
    return script


def with_beams(script: str) -> str:
    """``replay.js`` with the pieces of ``replay_beams.js`` that draw the beams."""
    return with_pieces(script, "replay_beams.js")


def with_platoons(script: str) -> str:
    """``replay.js`` with the pieces of ``replay_platoons.js`` (``platoons:``).

    They draw every platoon's reference path and point in its colour, instead of
    the one reference of a run of one platoon, and name them in the legend.
    """
    return with_pieces(script, "replay_platoons.js")


def with_cars(script: str) -> str:
    """``replay.js`` with the pieces of ``replay_cars.js`` (``model: bicycle``).

    They draw each car's chassis and wheels, the front one turned by its steering
    angle at the sample.
    """
    return with_pieces(script, "replay_cars.js")


def write_html(
    run: Any,
    path: str | os.PathLike[str],
    *,
    metrics: dict[str, Any] | None = None,
    title: str | None = None,
    max_vehicle_samples: int | None = None,
    show_beams: bool = False,
) -> Path:
    """Write the interactive replay page of ``run`` to ``path``.

    Parameters
    ----------
    run : Run
        A recorded run (``sandbox.load_run(DIR)`` or ``Simulation.run()``).
    path : str or os.PathLike
        An ``.html`` file: missing, or an earlier replay page (any other file is never
        overwritten). Written atomically; its directory is created if needed.
    metrics : dict, optional
        The run's metrics (``metrics.json``); computed when not given.
    title : str, optional
        The name shown; default the scenario's name.
    max_vehicle_samples : int, optional
        Most vehicle-samples embedded before the record is decimated in time
        (default :data:`sandbox.render.replay.encode.MAX_VEHICLE_SAMPLES`).
    show_beams : bool
        Embed the range sensors' scans of a run recorded with ``sensors.range`` and
        draw them (a "beams" toggle on the page); without scans, nothing changes.

    Returns
    -------
    Path
        ``path``. The same run gives the same bytes.

    Raises
    ------
    ReplayError
        ``path`` must not be written, or cannot be.
    """
    path = Path(path)
    check_output(path)  # before the work, not after it
    text = replay_html(
        run,
        metrics,
        title=title,
        max_vehicle_samples=max_vehicle_samples,
        show_beams=show_beams,
    )
    return _write_page(path, text)
