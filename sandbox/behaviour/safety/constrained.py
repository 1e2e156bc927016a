"""Which vehicles a safety filter constrained, and when (``metrics.json`` ``safety``).

Any filter that knows the vehicles whose commands it changed at a step (the CBF's
and ORCA's :class:`~sandbox.behaviour.safety.accounting.FilterStep` ``active``) adds
them here, and each world's counters get ``constrained``: its episodes
``[vehicle, start, end]``, the vehicle's index in the scenario, the time [s] of the
first period whose command the filter changed and the end of the last one (null:
to the end of the run). Episodes of a vehicle less than :data:`MERGE_GAP` apart are
one, so that a filter that acts every other period does not fill the file. The GIF and
the replay draw them (:mod:`sandbox.run.constrained`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Episodes of one vehicle separated by less than this are one [s].
MERGE_GAP = 0.1


def record_episodes(
    memory: dict[str, Any],
    world_stats: list[dict[str, Any]],
    t: float,
    active: np.ndarray,
    n: int,
) -> None:
    """Add one step's constrained vehicles to the episodes of each world.

    Parameters
    ----------
    memory : dict
        The filter's memory (keeps the last step's vehicles and open episodes).
    world_stats : list of dict
        The counters of the K worlds whose rows ``active`` holds, world after world.
    t : float [s]
        The step's time.
    active : ndarray, shape (K n,), bool
        The vehicles whose commands the filter changed at this step.
    n : int
        Vehicles per world.
    """
    last = memory.get("constrained_last")
    if last is None:
        last = np.zeros(len(active), dtype=bool)
    places = memory.setdefault("constrained_places", {})
    when = round(float(t), 9)
    for row in (active & ~last).nonzero()[0].tolist():
        world, i = divmod(row, n)
        episodes = world_stats[world].setdefault("constrained", [])
        place = places.get(row)
        if place is not None and when - episodes[place][2] < MERGE_GAP:
            episodes[place][2] = None  # the same episode, resumed
            continue
        places[row] = len(episodes)
        episodes.append([i, when, None])
    for row in (last & ~active).nonzero()[0].tolist():
        world, _ = divmod(row, n)
        world_stats[world]["constrained"][places[row]][2] = when
    memory["constrained_last"] = np.array(active, dtype=bool)
