"""Compare recovery strategies: run scenarios under each strategy and tabulate metrics.

``sandbox compare FILE... [--strategies ...] [--derivatives ...]`` runs every scenario
once per recovery strategy (``recovery.strategy``) and target-derivative mode
(``recovery.target_derivatives``), everything else as in the file (``--set`` overrides
apply to every run), and prints one row per run:

- ``collisions``: contact episodes among healthy vehicles (no active failure; a healthy
  vehicle hitting a static obstacle counts too) and in total;
- ``min distance``: smallest centre distance between two vehicles [m];
- ``settling``: the latest settling time over the healthy vehicles [s], ``-`` if one of
  them never settles;
- ``switches`` and ``effort``: mode switches and control effort summed over all vehicles
  (see :mod:`sandbox.metrics`);
- ``converged``: every healthy vehicle settled (``yes``/``no``), or the run's status
  when it did not finish (``diverged``).

The strategy name ``file`` keeps each file's own recovery section (``sandbox compare
scenarios/paper/fig1*.yaml --strategies file`` tabulates the section-4 figures as
written). With strategy ``none`` the shift is zero, and so are its estimated
derivatives: that strategy is run once, with ``hold``. Runs are independent and
deterministic; with ``jobs > 1`` they are spread over worker processes and the rows keep
the same order.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import astuple, dataclass, fields
from pathlib import Path

from sandbox import plugins
from sandbox.metrics import compute_metrics
from sandbox.run import STATUS_OK
from sandbox.scenario import RECOVERY, Scenario, load_scenario
from sandbox.simulation import simulate

FORMATS = ("markdown", "csv")
#: The ``strategies`` entry that keeps each scenario file's own recovery strategy.
FILE_STRATEGY = "file"


@dataclass(frozen=True)
class Row:
    """Metrics of one scenario under one recovery setting.

    Attributes
    ----------
    scenario, strategy, derivatives : str
    collisions_healthy, collisions_total : int
        Contact episodes among healthy vehicles / all of them.
    min_distance : float or None [m]
    settling_time : float or None [s]
        Latest settling time of the healthy vehicles; None if one never settles.
    mode_switches : int
        Summed over the vehicles.
    control_effort : float [m/s]
        Summed over the vehicles.
    converged : bool
    status : str
        ``ok``, ``diverged`` or ``interrupted``.
    """

    scenario: str
    strategy: str
    derivatives: str
    collisions_healthy: int
    collisions_total: int
    min_distance: float | None
    settling_time: float | None
    mode_switches: int
    control_effort: float
    converged: bool
    status: str


def cases(
    strategies: Sequence[str], derivatives: Sequence[str]
) -> list[tuple[str, str]]:
    """The ``(strategy, derivatives)`` pairs to run, ``none`` only with ``hold``.

    >>> cases(["none", "continuous"], ["hold", "estimate"])
    [('none', 'hold'), ('continuous', 'hold'), ('continuous', 'estimate')]
    """
    out = []
    for s in strategies:
        for d in derivatives:
            pair = (s, "hold" if s == "none" else d)
            if pair not in out:
                out.append(pair)
    return out


def row_from_metrics(
    scenario: str,
    strategy: str,
    derivatives: str,
    metrics: dict,
    healthy: Sequence[str],
) -> Row:
    """Summarize a ``metrics.json`` dictionary into a :class:`Row`.

    ``healthy`` names the vehicles without an active failure at the end of the run.
    """
    vehicles = metrics["vehicles"]
    settle = [
        vehicles[name]["settling_time"]
        for name in healthy
        if vehicles[name]["formation_error"]["max"] is not None  # it has a slot
    ]
    return Row(
        scenario=scenario,
        strategy=strategy,
        derivatives=derivatives,
        collisions_healthy=int(metrics["collisions"]["healthy"]),
        collisions_total=int(metrics["collisions"]["total"]),
        min_distance=metrics["min_distance"],
        settling_time=None if not settle or None in settle else max(settle),
        mode_switches=sum(v["mode_switches"] for v in vehicles.values()),
        control_effort=sum(v["control_effort"] for v in vehicles.values()),
        converged=bool(metrics["converged"]),
        status=metrics["status"],
    )


def run_case(
    path: str, strategy: str, derivatives: str, overrides: Sequence[str]
) -> Row:
    """Run one scenario file under one recovery setting and summarize it."""
    scenario = _load(path, strategy, derivatives, overrides)
    strategy = scenario.recovery.strategy
    run = simulate(scenario)
    healthy = [
        n for i, n in enumerate(run.names) if len(run.t) and not run.failed[-1, i]
    ]
    return row_from_metrics(
        scenario.name, strategy, derivatives, compute_metrics(run), healthy
    )


def _load(
    path: str, strategy: str, derivatives: str, overrides: Sequence[str]
) -> Scenario:
    sets = [*overrides, f"recovery.target_derivatives={derivatives}"]
    if strategy != FILE_STRATEGY:
        sets.append(f"recovery.strategy={strategy}")
    return load_scenario(path, overrides=sets)


def _run_case_args(args: tuple[str, str, str, tuple[str, ...], tuple[str, ...]]) -> Row:
    plugins.load_plugins(args[4])  # in a worker process too
    return run_case(*args[:4])


def compare(
    paths: Sequence[str | Path],
    strategies: Sequence[str] | None = None,
    derivatives: Sequence[str] = ("hold",),
    overrides: Sequence[str] = (),
    jobs: int = 1,
    plugin_specs: Sequence[str] = (),
    progress: Callable[[int, int], None] | None = None,
) -> list[Row]:
    """Run every scenario under every recovery setting; rows in (file, case) order.

    Parameters
    ----------
    paths : sequence of path
        Scenario files.
    strategies : sequence of str, optional
        Registered recovery strategies (``sandbox plugins``), or ``file``; default:
        every registered strategy, after loading the files' plug-ins.
    derivatives : sequence of str
        ``hold`` and/or ``estimate`` (``recovery.target_derivatives``).
    overrides : sequence of str
        ``path=value`` assignments applied to every run (before the strategy's).
    jobs : int
        Worker processes (1: run in this process).
    plugin_specs : sequence of str
        Plug-in files or modules to load first (also in the worker processes).
    progress : callable, optional
        Called as ``progress(done, total)`` after each run (``total`` runs in all).

    Raises
    ------
    ValueError
        An unknown strategy or derivative mode.
    ScenarioError
        A file (with the overrides) is not a valid scenario; checked before any run.
    """
    plugins.load_plugins(tuple(plugin_specs))
    for path in paths:  # loads the plug-ins each file lists
        _load(str(path), FILE_STRATEGY, "hold", overrides)
    if strategies is None:
        strategies = plugins.names("strategy")
    for name, valid, kind in (
        (strategies, (*plugins.names("strategy"), FILE_STRATEGY), "strategy"),
        (derivatives, RECOVERY["target_derivatives"].choices, "target_derivatives"),
    ):
        bad = [s for s in name if s not in valid]
        if bad or not name:
            raise ValueError(
                f"unknown {kind} {', '.join(map(repr, bad)) or '(none given)'} "
                f"(expected one or more of: {', '.join(valid)})"
            )
    todo = []
    for path in paths:
        for strategy, deriv in cases(strategies, derivatives):
            # validate everything before the first run
            scenario = _load(str(path), strategy, deriv, overrides)
            if scenario.recovery.strategy == "none" and deriv != "hold":
                continue
            todo.append(
                (str(path), strategy, deriv, tuple(overrides), tuple(plugin_specs))
            )
    if jobs <= 1 or len(todo) <= 1:
        return _collect(map(_run_case_args, todo), len(todo), progress)
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        return _collect(pool.map(_run_case_args, todo), len(todo), progress)


def _collect(
    rows: Iterator[Row], total: int, progress: Callable[[int, int], None] | None
) -> list[Row]:
    """The rows, in order, reporting ``progress(done, total)`` as each one arrives."""
    done: list[Row] = []
    if progress is not None:
        progress(0, total)
    for row in rows:
        done.append(row)
        if progress is not None:
            progress(len(done), total)
    return done


def _cell(value: object, column: str) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if column == "min_distance":
        return f"{value:.3f}"
    if column == "settling_time":
        return f"{value:.2f}"
    if column == "control_effort":
        return f"{value:.1f}"
    return str(value)


HEADERS = {
    "scenario": "scenario",
    "strategy": "strategy",
    "derivatives": "derivatives",
    "collisions_healthy": "collisions healthy",
    "collisions_total": "collisions total",
    "min_distance": "min distance [m]",
    "settling_time": "settling [s]",
    "mode_switches": "switches",
    "control_effort": "effort [m/s]",
    "converged": "converged",
}


def format_table(rows: Sequence[Row], fmt: str = "markdown") -> str:
    """The rows as a Markdown table or CSV text (ending with a newline)."""
    if fmt not in FORMATS:
        raise ValueError(
            f"unknown format {fmt!r} (expected one of: {', '.join(FORMATS)})"
        )
    columns = list(HEADERS)
    cells = []
    for row in rows:
        values = dict(zip([f.name for f in fields(Row)], astuple(row), strict=True))
        line = [_cell(values[c], c) for c in columns]
        if row.status != STATUS_OK:
            line[columns.index("converged")] = row.status
        cells.append(line)
    if fmt == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(cells)
        return buf.getvalue()
    header = [HEADERS[c] for c in columns]
    widths = [max(len(r[i]) for r in [header, *cells]) for i in range(len(columns))]
    numeric = range(3, len(columns))  # right-aligned: counts and measures

    def line(items: list[str]) -> str:
        return "| " + " | ".join(items) + " |"

    rule = [
        ("-" * (w - 1) + ":") if i in numeric else "-" * w for i, w in enumerate(widths)
    ]
    lines = [
        line([h.ljust(w) for h, w in zip(header, widths, strict=True)]),
        line(rule),
    ]
    for r in cells:
        lines.append(
            line(
                [
                    c.rjust(w) if i in numeric else c.ljust(w)
                    for i, (c, w) in enumerate(zip(r, widths, strict=True))
                ]
            )
        )
    return "\n".join(lines) + "\n"
