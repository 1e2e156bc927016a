"""The grouped summary of a sweep: rates with Wilson intervals, settling quartiles.

Rows of ``results.csv`` are grouped by the values of some varied paths (default: all of
them, i.e. one group per grid point). Per group:

- ``runs``: rows with metrics (status ``ok`` or ``diverged``); ``failed``: rows with
  status ``invalid`` or ``error`` (no metrics; left out of every rate);
- ``collision_rate``: the share of runs with at least one healthy collision episode
  (``collisions.healthy > 0``: contacts that recovery is meant to prevent), with its
  Wilson 95 % interval ``collision_low``, ``collision_high``;
- ``unsettled_rate``: the share of runs not converged (some healthy vehicle never
  settles; a diverged run is unsettled), with its Wilson interval;
- ``settling_median``, ``settling_q1``, ``settling_q3``: quartiles of the worst healthy
  settling time over the settled runs [s];
- ``min_distance_min``: the smallest centre distance over the group's runs [m];
  ``effort_median``: median total effort [m/s];
- ``deadlocked``, ``deadlocked_rate``: the runs with at least one deadlock (see
  :mod:`sandbox.run.deadlock`), and their share.

Groups run over the same seeds are also compared pair by pair with the exact McNemar
test (:func:`paired_table`, :mod:`sandbox.study.paired`): the starts where only one of
the two settings collided, or stayed unsettled, and the p-value of so lopsided a split.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from sandbox.run.tables import Column
from sandbox.run.tables import format_table as write_table
from sandbox.study.paired import paired_text, sweep_settings

#: z of a two-sided 95 % interval.
Z95 = 1.959963984540054
COLUMNS = (
    "runs",
    "failed",
    "collisions",
    "collision_rate",
    "collision_low",
    "collision_high",
    "unsettled",
    "unsettled_rate",
    "unsettled_low",
    "unsettled_high",
    "settling_median",
    "settling_q1",
    "settling_q3",
    "min_distance_min",
    "effort_median",
    "deadlocked",
    "deadlocked_rate",
)
MEASURED_STATUSES = ("ok", "diverged")


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a proportion ``k / n`` (95 % by default).

    >>> lo, hi = wilson(0, 10)
    >>> (lo, round(hi, 4))
    (0.0, 0.2775)
    >>> wilson(0, 0)
    (nan, nan)
    """
    if n == 0:
        return math.nan, math.nan
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    lo = 0.0 if k == 0 else max(0.0, centre - half)
    hi = 1.0 if k == n else min(1.0, centre + half)
    return lo, hi


def _float(text: str) -> float | None:
    return float(text) if text not in ("", None) else None


def group_rows(
    rows: Sequence[dict[str, str]], by: Sequence[str]
) -> list[tuple[tuple[str, ...], dict[str, Any]]]:
    """Summary of each group of rows, in order of first appearance.

    Parameters
    ----------
    rows : list of dict
        Rows of ``results.csv`` (text cells).
    by : list of str
        The varied paths to group by.
    """
    groups: dict[tuple[str, ...], list[dict[str, str]]] = {}
    for r in rows:
        groups.setdefault(tuple(r[p] for p in by), []).append(r)
    return [(key, summarize(members)) for key, members in groups.items()]


def summarize(rows: Sequence[dict[str, str]]) -> dict[str, Any]:
    """The summary columns (:data:`COLUMNS`) of one group of rows."""
    measured = [r for r in rows if r["status"] in MEASURED_STATUSES]
    n = len(measured)
    hits = sum(1 for r in measured if int(r["collisions.healthy"] or 0) > 0)
    unsettled = sum(1 for r in measured if r["converged"] != "true")
    # Runs with a deadlock (stores written before the column existed count none).
    stuck = sum(1 for r in measured if int(r.get("deadlocks") or 0) > 0)
    settle = np.array(
        [float(r["settling_time"]) for r in measured if r["settling_time"] != ""]
    )
    dmin = [_float(r["min_distance"]) for r in measured]
    dmin = [d for d in dmin if d is not None]
    effort = [float(r["effort"]) for r in measured if r["effort"] != ""]
    c_lo, c_hi = wilson(hits, n)
    u_lo, u_hi = wilson(unsettled, n)
    q = np.quantile(settle, [0.5, 0.25, 0.75]) if len(settle) else [math.nan] * 3
    return {
        "runs": n,
        "failed": len(rows) - n,
        "collisions": hits,
        "collision_rate": hits / n if n else math.nan,
        "collision_low": c_lo,
        "collision_high": c_hi,
        "unsettled": unsettled,
        "unsettled_rate": unsettled / n if n else math.nan,
        "unsettled_low": u_lo,
        "unsettled_high": u_hi,
        "settling_median": float(q[0]),
        "settling_q1": float(q[1]),
        "settling_q3": float(q[2]),
        "min_distance_min": min(dmin) if dmin else math.nan,
        "effort_median": float(np.median(effort)) if effort else math.nan,
        "deadlocked": stuck,
        "deadlocked_rate": stuck / n if n else math.nan,
    }


def format_table(
    groups: list[tuple[tuple[str, ...], dict[str, Any]]],
    by: Sequence[str],
    fmt: str = "md",
) -> str:
    """The grouped summary as a table (:func:`sandbox.run.tables.format_table`).

    ``fmt``: ``md`` (Markdown, 4 significant digits), ``csv`` or ``json`` (full
    precision; no value is rounded).
    """
    columns = [*(Column(p, text=True) for p in by), *(Column(c) for c in COLUMNS)]
    rows = [{**dict(zip(by, key, strict=True)), **s} for key, s in groups]
    return write_table(columns, rows, fmt)


def paired_table(
    rows: Sequence[dict[str, str]],
    by: Sequence[str],
    varied: Sequence[str],
    fmt: str = "md",
) -> str | None:
    """The McNemar comparisons of the groups of ``by`` over their shared starts.

    None when fewer than two groups share a start, or more than
    :data:`~sandbox.study.paired.MAX_SETTINGS` groups would be compared.
    """
    return paired_text(sweep_settings(rows, by, varied, MEASURED_STATUSES), fmt)
