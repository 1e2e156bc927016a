"""How a world of the loop ends: its description completed, its :class:`~sandbox.Run`.

A world ends alone (a diverged state, a plug-in that failed: its last sample is
recorded with the plan undefined) or with the others (at the duration, when stopped,
or when the caller asks for the results early: the last sample with the
controller's own commands). Either way :func:`make_run` completes the world's
description (``Run.info``) and makes its run from its recorded arrays.

A stage of the loop that fails (a defect, or the record's spill on a full disk) ends
the worlds with status ``error`` as a plug-in does, their samples up to then kept:
:func:`stage_error` is the ``info["error"]`` that says which stage and what failed.
"""

from __future__ import annotations

import traceback
from pathlib import Path
from typing import Any

import numpy as np

from sandbox.loop.layout import Layout
from sandbox.run.record import Run


def make_run(
    layout: Layout,
    w: int,
    info: dict[str, Any],
    status: str,
    arrays: dict[str, np.ndarray],
    *,
    failed_at: dict[str, float],
    detection: dict[str, Any] | None,
    loop_metrics: dict[str, Any],
    wall_time: float,
    control_time: float,
    safety: dict[str, Any] | None,
    steps: int,
    diameter: np.ndarray,
    leader: int,
    events: list,
    ranges: dict[str, np.ndarray],
) -> Run:
    """World ``w``'s run: its description completed, its recorded arrays.

    Parameters
    ----------
    layout : Layout
    w : int
    info : dict
        The world's description so far (completed in place: it is the run's).
    status : str
        The world's status.
    arrays : dict of ndarray
        Its recorded samples (``t``, ``pose``, ...).
    failed_at : dict
        When each failed vehicle failed [s].
    detection : dict or None
        Its detector's summary (None: the oracle;
        :meth:`~sandbox.behaviour.detection.BatchDetection.summary`).
    loop_metrics : dict
        The loop metrics of the world (:meth:`~sandbox.loop.tally.LoopTally.result`).
    wall_time, control_time : float [s]
        The loop's wall time and time planning and acting, per world.
    safety : dict or None
        The safety filter's counters (None: no filter).
    steps : int
        The periods stepped.
    diameter : ndarray, shape (n,) [m]
    leader : int
        The vehicle that leads at the end (-1: none).
    events : list
        The world's collision events.
    ranges : dict of ndarray
        The range sensors' record (empty without).
    """
    sc = layout.scenarios[w]
    info["failed_at"] = failed_at
    if detection is not None:
        info["detection"] = detection
    info["loop_metrics"] = loop_metrics
    info["wall_time"] = wall_time
    info["control_time"] = control_time
    if safety is not None:
        info["safety"] = {
            "filter": sc.safety.filter,
            "infeasible_steps": 0,
            "active_steps": 0,
            **safety,
        }
    info["steps"] = steps
    return Run(
        names=list(layout.names[w]),
        colors=[v.color for v in sc.vehicles],
        diameter=diameter,
        leader=leader,
        events=events,
        status=status,
        info=info,
        scenario=sc,
        **arrays,
        **ranges,
    )


#: The package's folder: a failure's place is told relative to it.
_PACKAGE = Path(__file__).resolve().parents[1]


def stage_error(t: float, stage: str, what: BaseException | str) -> dict[str, Any]:
    """The ``info["error"]`` of a run that ended because a stage of the loop failed.

    Parameters
    ----------
    t : float [s]
        When it failed.
    stage : str
        The stage: ``plan``, ``platoons``, ``act``, ``record``, ``physics`` or
        ``sense``.
    what : exception or str
        What failed: an exception (told as its type, its message and the innermost
        place in the package that raised it), or a one-line message.

    Returns
    -------
    dict
        ``{"t": t, "stage": stage, "message": ...}``.

    >>> stage_error(1.5, "record", "disk full")
    {'t': 1.5, 'stage': 'record', 'message': 'disk full'}
    """
    if isinstance(what, BaseException):
        message = f"{type(what).__name__}: {what}".rstrip(": ")
        place = None
        for frame in traceback.extract_tb(what.__traceback__):
            path = Path(frame.filename).resolve()
            if path.is_relative_to(_PACKAGE):
                place = f"{path.relative_to(_PACKAGE.parent).as_posix()}, line "
                place += str(frame.lineno)
        if place is not None:
            message += f" ({place})"
    else:
        message = what
    return {"t": round(t, 9), "stage": stage, "message": " ".join(message.split())}
