"""The safety filter's figures of a sweep's groups (``sandbox sweep table --safety``).

``results.csv`` keeps no column of the filter, so these are read from each run's file
``DIR/runs/<run id>.json`` (its ``metrics.json``'s ``safety`` entry). Per group of
measured runs:

- ``relaxed``, ``relaxed_rate``, ``relaxed_low``, ``relaxed_high``: the runs with a
  vehicle-step whose conditions had no common point (``safety.infeasible_steps > 0``:
  relaxed by the velocity barrier, braked by the braking barrier's fallback), their
  share and its Wilson 95 % interval;
- ``relaxed_steps``: those vehicle-steps summed over the group;
- ``fallback``, ``fallback_steps``: the runs where the braking barrier's fallback
  braked (``safety.fallback_steps > 0``), and its vehicle-steps summed;
- ``max_slack``: the largest slack [m/s]; ``unsafe_starts``: runs whose first step
  was unsafe (``safety.unsafe_start.unsafe``).

A run without the filter, or whose file cannot be read, counts as none of these.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sandbox.run.tables import Column
from sandbox.run.tables import format_table as write_table
from sandbox.study.store import read_run
from sandbox.study.summary import MEASURED_STATUSES, wilson

COLUMNS = (
    "runs",
    "relaxed",
    "relaxed_rate",
    "relaxed_low",
    "relaxed_high",
    "relaxed_steps",
    "fallback",
    "fallback_steps",
    "max_slack",
    "unsafe_starts",
)


def _safety_of(root: Path, run_id: str) -> dict[str, Any]:
    try:
        doc = read_run(root / "runs" / f"{run_id}.json")
    except (OSError, ValueError):
        return {}
    safety = (doc.get("metrics") or {}).get("safety")
    return safety if isinstance(safety, dict) else {}


def summarize_safety(root: Path, rows: Sequence[dict[str, str]]) -> dict[str, Any]:
    """The :data:`COLUMNS` of one group of rows of the sweep in ``root``."""
    found = [
        _safety_of(root, r["run_id"]) for r in rows if r["status"] in MEASURED_STATUSES
    ]
    n = len(found)
    steps = [int(s.get("infeasible_steps") or 0) for s in found]
    falls = [int(s.get("fallback_steps") or 0) for s in found]
    relaxed = sum(1 for k in steps if k > 0)
    lo, hi = wilson(relaxed, n)
    slack = [float(s.get("max_slack") or 0.0) for s in found]
    unsafe = sum(1 for s in found if (s.get("unsafe_start") or {}).get("unsafe"))
    return {
        "runs": n,
        "relaxed": relaxed,
        "relaxed_rate": relaxed / n if n else math.nan,
        "relaxed_low": lo,
        "relaxed_high": hi,
        "relaxed_steps": sum(steps),
        "fallback": sum(1 for k in falls if k > 0),
        "fallback_steps": sum(falls),
        "max_slack": max(slack) if slack else math.nan,
        "unsafe_starts": unsafe,
    }


def safety_table(
    root: Path, rows: Sequence[dict[str, str]], by: Sequence[str], fmt: str = "md"
) -> str:
    """The filter's figures of each group of ``by`` as a table.

    Groups in order of first appearance; ``fmt``: ``md``, ``csv`` or ``json``.
    """
    groups: dict[tuple[str, ...], list[dict[str, str]]] = {}
    for r in rows:
        groups.setdefault(tuple(r[p] for p in by), []).append(r)
    columns = [*(Column(p, text=True) for p in by), *(Column(c) for c in COLUMNS)]
    table = [
        {**dict(zip(by, key, strict=True)), **summarize_safety(root, members)}
        for key, members in groups.items()
    ]
    return write_table(columns, table, fmt)
