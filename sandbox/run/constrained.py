"""The vehicles a safety filter constrained at each recorded sample of a run.

A filter's episodes (``metrics.json`` ``safety.constrained``, written by
:mod:`sandbox.behaviour.safety.constrained`) as a mask over the record, for the
pictures: the GIF's and the replay's ring around a constrained vehicle.
"""

from __future__ import annotations

import numpy as np

from sandbox.run.record import Run


def filter_name(run: Run) -> str | None:
    """The run's safety filter (``safety.filter``), None without one."""
    safety = run.info.get("safety") if isinstance(run.info, dict) else None
    name = safety.get("filter") if isinstance(safety, dict) else None
    return str(name) if name else None


def constrained_mask(run: Run) -> np.ndarray | None:
    """Whether the filter changed each vehicle's command at each sample, (T, n) bool.

    None when the run has no episodes (no filter, or one that does not say) or has
    ``platoons:`` (whose sections number their vehicles apart).

    >>> from types import SimpleNamespace
    >>> run = SimpleNamespace(t=np.arange(4) * 0.5, n_vehicles=2, scenario=None,
    ...     info={"safety": {"filter": "orca", "constrained": [[1, 0.5, 1.0]]}})
    >>> constrained_mask(run).astype(int).tolist()
    [[0, 0], [0, 1], [0, 0], [0, 0]]
    """
    safety = run.info.get("safety") if isinstance(run.info, dict) else None
    episodes = safety.get("constrained") if isinstance(safety, dict) else None
    if not episodes or getattr(run.scenario, "platoons", None):
        return None
    t = np.asarray(run.t, dtype=float)
    mask = np.zeros((len(t), run.n_vehicles), dtype=bool)
    for entry in episodes:
        try:
            i, start, end = int(entry[0]), float(entry[1]), entry[2]
        except (TypeError, ValueError, IndexError):
            continue  # a hand-made record: only what can be read
        if not 0 <= i < run.n_vehicles:
            continue
        first = int(np.searchsorted(t, start - 1e-9))
        stop = len(t) if end is None else int(np.searchsorted(t, float(end) - 1e-9))
        mask[first:stop, i] = True
    return mask
