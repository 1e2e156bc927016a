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
  (see :mod:`sandbox.run.metrics`);
- ``converged``: every healthy vehicle settled (``yes``/``no`` in Markdown,
  ``true``/``false`` in CSV and JSON, which also have a ``status`` column), or, in
  Markdown, the run's status when it did not finish (``diverged``).

A law that hands the controller a moving target (``formation.law`` ``potential`` or
``flocking``) is judged against its goals: its settling, convergence and deadlocks are
those of ``metrics.json`` ``formation_goal`` (:mod:`sandbox.run.goals`).

``--grid PATH=v1,v2,...`` (repeatable) also varies fields for every strategy, e.g.
``recovery.tangential=0,1`` (a ``setting`` column; with strategy ``none`` the
``recovery.*`` paths take their first value only). ``--columns safety`` prints the
safety benchmark's columns instead: ``success`` (converged and no contact episode at
all), ``collisions`` (every episode), ``min separation - d`` [m], ``deadlocks``
(:mod:`sandbox.run.deadlock`), ``extra settle`` (the settling time minus that of the
same scenario without recovery on the ideal kinematics, where vehicles pass through each
other and the obstacles) [s], and the wall time of planning and acting per control step
[ms], a measurement that varies from run to run (the other columns are deterministic).

The strategy name ``file`` keeps each file's own recovery section (``sandbox compare
scenarios/paper/fig1*.yaml --strategies file`` tabulates the section-4 figures as
written). With strategy ``none`` the shift is zero, and so are its estimated
derivatives: that strategy is run once, with ``hold``. Runs are independent and
deterministic; with ``jobs > 1`` they are spread over worker processes and the rows keep
the same order.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import astuple, dataclass, fields, replace
from pathlib import Path
from typing import Any

from sandbox import plugins
from sandbox.loop.simulation import simulate
from sandbox.run.metrics import compute_metrics
from sandbox.run.record import STATUS_OK, Run
from sandbox.run.tables import Column, table_format
from sandbox.run.tables import format_table as write_table
from sandbox.scenario import RECOVERY, Scenario, load_scenario

#: The ``strategies`` entry that keeps each scenario file's own recovery strategy.
FILE_STRATEGY = "file"
#: The task of a scenario's baseline (:func:`ideal_settling`), not a strategy.
IDEAL = "<ideal>"


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
    setting : str
        The ``--grid`` values of the run, ``name=value`` by the last part of each
        path (``tangential=1``); empty without a grid.
    success : bool
        Converged, with status ``ok``, and no contact episode at all.
    deadlocks : int
        Entries of ``deadlocks`` in ``metrics.json``.
    separation : float or None [m]
        ``min_distance`` minus the vehicle diameter d (the largest, for mixed fleets):
        negative when two vehicles overlapped.
    extra_settle : float or None [s]
        Settling time minus that of the same scenario without recovery on the ideal
        kinematics (:class:`~sandbox.study.ideal.IdealKinematics`: vehicles pass through
        each other and the obstacles); None when either never settles.
    control_ms : float [ms]
        Wall time of planning and acting (law, recovery, controller, filters) per
        control step, measured in the run: not deterministic.
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
    setting: str = ""
    success: bool = False
    deadlocks: int = 0
    separation: float | None = None
    extra_settle: float | None = None
    control_ms: float = 0.0


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
    judged = judged_metrics(metrics)  # a moving-target law's: against its goals
    settle = [
        judged["vehicles"][name]["settling_time"]
        for name in healthy
        if judged["vehicles"][name]["formation_error"]["max"] is not None  # a slot
    ]
    total = int(metrics["collisions"]["total"])
    converged = bool(judged["converged"])
    return Row(
        scenario=scenario,
        strategy=strategy,
        derivatives=derivatives,
        collisions_healthy=int(metrics["collisions"]["healthy"]),
        collisions_total=total,
        min_distance=metrics["min_distance"],
        settling_time=None if not settle or None in settle else max(settle),
        mode_switches=sum(v["mode_switches"] for v in vehicles.values()),
        control_effort=sum(v["control_effort"] for v in vehicles.values()),
        converged=converged,
        status=metrics["status"],
        success=converged and total == 0 and metrics["status"] == STATUS_OK,
        deadlocks=len(judged.get("deadlocks", ())),
    )


def judged_metrics(metrics: dict) -> dict:
    """The block that says whether a run formed: the run's, or ``formation_goal``.

    A law that hands the controller a moving target (``potential``, ``flocking``) is
    judged against its goals (:mod:`sandbox.run.goals`): ``vehicles``, ``converged``
    and ``deadlocks`` of that block.
    """
    return metrics.get("formation_goal") or metrics


def latest_settling(run: Run, metrics: dict) -> float | None:
    """The latest settling time of the healthy vehicles with a slot [s], or None."""
    healthy = [
        n for i, n in enumerate(run.names) if len(run.t) and not run.failed[-1, i]
    ]
    vehicles = judged_metrics(metrics)["vehicles"]
    settle = [
        vehicles[n]["settling_time"]
        for n in healthy
        if vehicles[n]["formation_error"]["max"] is not None
    ]
    return None if not settle or None in settle else max(settle)


def ideal_settling(path: str, overrides: Sequence[str]) -> float | None:
    """Latest settling time [s] of a scenario without recovery on the ideal kinematics.

    The baseline of :attr:`Row.extra_settle`: the same vehicles, controller and
    slots, moving by eq. (1) exactly, through each other and the obstacles, with no
    safety filter either.
    """
    from sandbox.loop.simulation import Simulation
    from sandbox.study.ideal import IdealKinematics

    off = [*overrides, "recovery.strategy=none", "safety.filter=none"]
    scenario = load_scenario(path, overrides=off)
    run = Simulation(scenario, world=IdealKinematics(scenario)).run()
    return latest_settling(run, compute_metrics(run))


def run_case(
    path: str,
    strategy: str,
    derivatives: str,
    overrides: Sequence[str],
    setting: Sequence[str] = (),
) -> Row:
    """Run one scenario file under one recovery setting and summarize it.

    ``setting`` holds the grid's ``path=value`` assignments of this run (applied after
    ``overrides``).
    """
    scenario = _load(path, strategy, derivatives, [*overrides, *setting])
    strategy = scenario.recovery.strategy
    run = simulate(scenario)
    healthy = [
        n for i, n in enumerate(run.names) if len(run.t) and not run.failed[-1, i]
    ]
    row = row_from_metrics(
        scenario.name, strategy, derivatives, compute_metrics(run), healthy
    )
    steps = max(int(run.info.get("steps", 0)), 1)
    best = row.min_distance
    return replace(
        row,
        setting=setting_text(setting),
        separation=None if best is None else best - float(max(run.diameter)),
        control_ms=1000.0 * float(run.info.get("control_time", 0.0)) / steps,
    )


def setting_text(setting: Sequence[str]) -> str:
    """``name=value`` of each assignment by the last part of its path.

    >>> setting_text(["recovery.tangential=1", "safety.filter=cbf"])
    'tangential=1 filter=cbf'
    """
    out = []
    for item in setting:
        path, _, value = item.partition("=")
        out.append(f"{path.rsplit('.', 1)[-1]}={value}")
    return " ".join(out)


def grid_settings(grid: Sequence[str], strategy: str) -> list[tuple[str, ...]]:
    """The ``path=value`` assignments of every grid point, for one strategy.

    ``grid`` holds ``PATH=v1,v2,...`` items (as ``sandbox sweep --grid``); their
    Cartesian product, first path slowest. With strategy ``none`` the ``recovery.*``
    paths change nothing and take their first value only.

    >>> grid_settings(["recovery.tangential=0,1"], "smooth")
    [('recovery.tangential=0',), ('recovery.tangential=1',)]
    >>> grid_settings(["recovery.tangential=0,1"], "none")
    [('recovery.tangential=0',)]
    """
    from sandbox.study.spec import SweepError, axis_from_option

    axes = []
    for item in grid:
        try:
            axis = axis_from_option(item, "--grid")
        except SweepError as exc:
            raise ValueError(str(exc)) from None
        texts = axis.texts
        if strategy == "none" and axis.path.startswith("recovery."):
            texts = texts[:1]
        axes.append([f"{axis.path}={t}" for t in texts])
    return [tuple(c) for c in itertools.product(*axes)]


def _load(
    path: str, strategy: str, derivatives: str, overrides: Sequence[str]
) -> Scenario:
    sets = [*overrides, f"recovery.target_derivatives={derivatives}"]
    if strategy != FILE_STRATEGY:
        sets.append(f"recovery.strategy={strategy}")
    return load_scenario(path, overrides=sets)


def _run_case_args(args: tuple) -> Row | float | None:
    plugins.load_plugins(args[4])  # in a worker process too
    if args[1] == IDEAL:
        return ideal_settling(args[0], args[3])
    return run_case(*args[:4], setting=args[5])


def compare(
    paths: Sequence[str | Path],
    strategies: Sequence[str] | None = None,
    derivatives: Sequence[str] = ("hold",),
    overrides: Sequence[str] = (),
    jobs: int = 1,
    plugin_specs: Sequence[str] = (),
    progress: Callable[[int, int], None] | None = None,
    grid: Sequence[str] = (),
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
    grid : sequence of str
        ``PATH=v1,v2,...`` paths varied for every strategy (e.g.
        ``recovery.tangential=0,1``), see :func:`grid_settings`. Each scenario is also
        run once without recovery on the ideal kinematics, for
        :attr:`Row.extra_settle`.

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
    specs = tuple(plugin_specs)
    for path in paths:
        todo.append((str(path), IDEAL, "hold", tuple(overrides), specs, ()))
        for strategy, deriv in cases(strategies, derivatives):
            # validate everything before the first run
            scenario = _load(str(path), strategy, deriv, overrides)
            if scenario.recovery.strategy == "none" and deriv != "hold":
                continue
            for setting in grid_settings(grid, scenario.recovery.strategy):
                _load(str(path), strategy, deriv, [*overrides, *setting])
                todo.append(
                    (str(path), strategy, deriv, tuple(overrides), specs, setting)
                )
    if jobs <= 1 or len(todo) <= 1:
        done = _collect(map(_run_case_args, todo), len(todo), progress)
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            done = _collect(pool.map(_run_case_args, todo), len(todo), progress)
    rows, baseline = [], None
    for task, result in zip(todo, done, strict=True):
        if task[1] == IDEAL:
            baseline = result
            continue
        extra = None
        if baseline is not None and result.settling_time is not None:
            extra = result.settling_time - baseline
        rows.append(replace(result, extra_settle=extra))
    return rows


def _collect(
    rows: Iterator[Any], total: int, progress: Callable[[int, int], None] | None
) -> list[Any]:
    """The rows, in order, reporting ``progress(done, total)`` as each one arrives."""
    done: list[Any] = []
    if progress is not None:
        progress(0, total)
    for row in rows:
        done.append(row)
        if progress is not None:
            progress(len(done), total)
    return done


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


#: Columns of ``--columns safety``: the safety benchmark (README).
SAFETY_HEADERS = {
    "scenario": "scenario",
    "strategy": "strategy",
    "setting": "setting",
    "success": "success",
    "collisions_total": "collisions",
    "separation": "min separation - d [m]",
    "deadlocks": "deadlocks",
    "extra_settle": "extra settle [s]",
    "control_ms": "control [ms/step, measured]",
}
#: Column sets of :func:`format_table`.
COLUMNS = {"default": HEADERS, "safety": SAFETY_HEADERS}


def format_table(rows: Sequence[Row], fmt: str = "md", columns: str = "default") -> str:
    """The rows as a table text (:func:`sandbox.run.tables.format_table`).

    ``fmt`` is ``md`` (Markdown, 4 significant digits; ``markdown`` too), ``csv`` or
    ``json`` (full precision, with a ``status`` column; in Markdown a run that did not
    finish shows its status in place of ``converged`` or ``success``). ``columns`` is
    ``default`` (:data:`HEADERS`, plus ``setting`` when a row has one) or ``safety``
    (:data:`SAFETY_HEADERS`, with the measured control time: not deterministic).
    """
    fmt = table_format(fmt)
    if columns not in COLUMNS:
        raise ValueError(
            f"unknown columns {columns!r} (expected one of: {', '.join(COLUMNS)})"
        )
    headers = dict(COLUMNS[columns])
    if columns == "default" and any(r.setting for r in rows):
        headers = {"scenario": "scenario", "strategy": "strategy", "setting": "setting"}
        headers.update({k: v for k, v in HEADERS.items() if k not in headers})
    if fmt != "md":
        headers["status"] = "status"
    text = ("scenario", "strategy", "derivatives", "setting", "status")
    cols = [
        Column(k, title, text=k in text, signed=k in ("separation", "extra_settle"))
        for k, title in headers.items()
    ]
    table = []
    for row in rows:
        values = dict(zip([f.name for f in fields(Row)], astuple(row), strict=True))
        if fmt == "md" and row.status != STATUS_OK:
            values["converged" if "converged" in headers else "success"] = row.status
        table.append(values)
    return write_table(cols, table, fmt)
