"""Running a sweep into its store: what is missing, on the chosen engine, with progress.

:func:`run_sweep` is what ``sandbox sweep`` calls: it counts the runs (refusing more
than ``max_runs`` before any is built), validates every grid point, opens and locks
the store (refusing a changed base), computes the runs without a stored result (and,
with ``retry_failed``, those whose status is a failure), stores each as it finishes,
and rebuilds ``results.csv`` at the end, also when interrupted.

Signals: until the runs start, SIGINT and SIGTERM act as they do around the call
(under ``sandbox`` they raise ``KeyboardInterrupt``: exit status 130, nothing
written but whole files); while runs are computed the first stops the sweep, which
keeps every finished run and returns at once, and a second stops it where it is (a
group under way in this process, a blocking plug-in), the finished runs kept
(:class:`~sandbox._startup.StopOnSignal`).
"""

from __future__ import annotations

import shlex
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from sandbox._startup import StopOnSignal
from sandbox.errors import ScenarioError
from sandbox.study import engine
from sandbox.study.spec import (
    MAX_RUNS,
    SweepError,
    SweepSpec,
    Task,
    build_spec,
    is_sweep_file,
    read_sweep_document,
)
from sandbox.study.store import Store, digest

#: What the first SIGINT/SIGTERM of a sweep says.
STOP_NOTICE = (
    "stopping: the runs under way end, the finished ones are stored (a second "
    "Ctrl-C stops at once; the store keeps every run finished)"
)
#: Most rejected run files named one by one (then their count).
SHOW_REJECTED = 5
#: With ``keep_runs``, each computed run's directory is ``DIR/run_dirs/<run id>/``.
KEPT_RUNS = "run_dirs"


@dataclass
class SweepReport:
    """What an invocation did."""

    total: int
    already: int
    computed: int
    failed: int
    rows: int
    interrupted: bool = False


def read_base(spec: SweepSpec, trust_plugins: bool | None = None) -> dict[str, Any]:
    """The base scenario document, read exactly as ``sandbox run`` reads it.

    ``trust_plugins`` as :func:`~sandbox.scenario.load_scenario` takes it (False:
    never run the code the base lists, as ``sandbox validate``).
    """
    from sandbox.scenario import YAMLLoader, load_scenario

    # its problems, with lines
    load_scenario(spec.base, overrides=list(spec.fixed), trust_plugins=trust_plugins)
    text = Path(spec.base).read_text(encoding="utf-8")
    return yaml.load(text, Loader=YAMLLoader)  # noqa: S506 (a SafeLoader)


def check_points(
    spec: SweepSpec, base_doc: dict[str, Any], plugin_code: str | None = None
) -> None:
    """Validate every grid point on the first seed (before anything runs).

    ``plugin_code`` as :func:`~sandbox.scenario.parse_scenario` takes it
    (``refuse``: never run the code the base lists).

    Raises
    ------
    ScenarioError
        The first grid point whose scenario is invalid, its problems marked with the
        ``--set`` that caused them.
    """
    from sandbox.scenario import YAMLLoader, line_map, parse_scenario

    # the file's lines: a warning of the base reads as when the base was loaded (and
    # is shown once), those of a grid point at their --set
    lines: dict[str, int] = {}
    try:
        loader = YAMLLoader(Path(spec.base).read_text(encoding="utf-8"))
        try:
            line_map(loader.get_single_node(), "", lines)
        finally:
            loader.dispose()
    except (OSError, ValueError, yaml.YAMLError):
        lines = {}
    first = spec.seeds.start
    for point in spec.iter_points():
        task = Task("", 0, tuple((p, t) for p, t, _ in point), first)
        try:
            parse_scenario(
                base_doc,
                source=str(spec.base),
                lines=lines,
                overrides=task.overrides(spec.fixed),
                plugin_code=plugin_code,
            )
        except ScenarioError as exc:
            if any(p.path == "randomize" for p in exc.problems):
                continue  # a draw of one seed: that run's row says so
            raise


def to_compute(
    tasks: Iterable[Task], done: dict[str, str], retry_failed: bool
) -> list[Task]:
    """The tasks without a stored run (and the failed ones with ``retry_failed``)."""
    out = []
    for t in tasks:
        status = done.get(t.run_id)
        if status is None or (retry_failed and status in engine.FAILED_STATUSES):
            out.append(t)
    return out


def run_sweep(
    spec: SweepSpec,
    out: Path,
    *,
    jobs: int = 1,
    scheduler: str | None = None,
    scheduler_file: str | None = None,
    retry_failed: bool = False,
    progress: Callable[[int, int], None] | None = None,
    max_runs: int = MAX_RUNS,
    warn: Callable[[str], None] | None = None,
    keep_runs: bool = False,
) -> SweepReport:
    """Compute the missing runs of ``spec`` into the store ``out``.

    Parameters
    ----------
    spec : SweepSpec
    out : Path
        The results directory.
    jobs : int
        Local processes (1: in-process).
    scheduler, scheduler_file : str, optional
        A Dask scheduler's address, or its scheduler file: run on that cluster.
    retry_failed : bool
        Also rerun the stored runs whose status is a failure.
    progress : callable, optional
        Called as ``progress(stored, total)`` when the runs start and after each run
        stored (``stored`` counts the runs stored before, ``total`` every run of the
        sweep: what the store holds).
    max_runs : int
        Most runs the sweep may have (:data:`~sandbox.study.spec.MAX_RUNS`).
    warn : callable, optional
        Told, one line each, of the stored run files that are not taken (default:
        printed to standard error as ``warning: ...``).
    keep_runs : bool
        Also write the run directory of every run computed now (as ``sandbox run``
        does) into ``out/run_dirs/<run id>/``, for ``sandbox view`` and ``sandbox
        sweep view``. A Dask worker writes it where it runs (a shared ``out``).

    Returns
    -------
    SweepReport
        An interrupted sweep (SIGINT, SIGTERM) returns with ``interrupted`` set, its
        finished runs stored and ``results.csv`` written.

    Raises
    ------
    SweepError
        Too many runs, or ``out`` cannot hold this sweep (another base, another
        sweep writing into it).
    """
    spec.check_size(max_runs)
    if jobs > 1 and not (scheduler or scheduler_file):
        engine.pool_context(start=True)  # a fork server, if one is used, imports now
    base_doc = read_base(spec)
    check_points(spec, base_doc)
    store = Store(out)
    store.open(spec, digest(base_doc, spec.fixed))
    try:
        done = store.done(spec.iter_tasks())
        _warn_rejected(store, warn)
        todo = to_compute(spec.iter_tasks(), done, retry_failed)
        with StopOnSignal(STOP_NOTICE) as stop:
            engines = (jobs, scheduler, scheduler_file)
            return _compute(
                spec, store, base_doc, todo, engines, progress, stop, keep_runs
            )
    finally:
        store.close()


def _warn_rejected(store: Store, warn: Callable[[str], None] | None) -> None:
    say = warn or (lambda line: print(f"warning: {line}", file=sys.stderr))
    for line in store.rejected[:SHOW_REJECTED]:
        say(line)
    if len(store.rejected) > SHOW_REJECTED:
        more = len(store.rejected) - SHOW_REJECTED
        say(f"{store.runs}: {more} more run files not taken; computed again")
    store.rejected.clear()


def _compute(
    spec: SweepSpec,
    store: Store,
    base_doc: dict[str, Any],
    todo: list[Task],
    engines: tuple[int, str | None, str | None],
    progress: Callable[[int, int], None] | None,
    stop: StopOnSignal,
    keep_runs: bool = False,
) -> SweepReport:
    jobs, scheduler, scheduler_file = engines
    out = store.root
    total = spec.count()
    report = SweepReport(total, total - len(todo), 0, 0, 0)
    if todo:
        by_id = {t.run_id: t for t in todo}
        kept = Path(out).resolve() / KEPT_RUNS
        jobs_list = [
            (
                t.run_id,
                (base_doc, str(spec.base), t.overrides(spec.fixed))
                + ((str(kept / t.run_id),) if keep_runs else ()),
            )
            for t in todo
        ]
        if scheduler or scheduler_file:
            try:
                client = engine.dask_client(scheduler, scheduler_file)
            except engine.EngineError as exc:
                raise engine.EngineError(
                    f"{exc}; nothing was computed ({report.already} of {total} runs "
                    f"are stored in {out}): run the same command again with a "
                    "scheduler that answers, or without --scheduler to compute here"
                ) from None
            results = engine.run_dask(
                jobs_list,
                client,
                lambda: (
                    f"the finished runs are kept in {out}; run the same command "
                    "again once the scheduler is back to compute only the missing ones"
                ),
                should_stop=stop,
            )
        else:
            results = engine.run_local(jobs_list, jobs, should_stop=stop)
        if progress is not None:
            progress(report.already, total)
        try:  # every run the engine yields is stored; it stops when asked to
            for run_id, result in results:
                if result is not None:
                    store.put(by_id[run_id], result)
                    report.computed += 1
                    if progress is not None:
                        progress(report.already + report.computed, total)
        except KeyboardInterrupt:
            stop.raised = True
        except engine.EngineError as exc:
            if scheduler or scheduler_file:
                raise  # the engine's own line says what was kept and how to resume
            kept = report.already + report.computed
            raise engine.EngineError(
                f"{exc}; the {kept} of {total} runs finished are stored in {out}: run "
                "the same command again to compute the rest (with fewer --jobs if "
                "memory ran out)"
            ) from None
        finally:
            results.close()
            report.rows = store.write_results(spec, spec.iter_tasks())
        report.interrupted = stop.raised
    else:
        report.rows = store.write_results(spec, spec.iter_tasks())
    statuses = store.done(spec.iter_tasks()).values()
    store.rejected.clear()
    report.failed = sum(1 for s in statuses if s in engine.FAILED_STATUSES)
    return report


def describe_dry_run(
    spec: SweepSpec, out: Path, retry_failed: bool, max_runs: int = MAX_RUNS
) -> list[str]:
    """The lines ``--dry-run`` prints: sizes, what is stored, what would run.

    The runs are counted before any is built (more than ``max_runs`` are refused
    with :class:`SweepError`), then looked at one at a time.
    """
    spec.check_size(max_runs)
    total = spec.count()
    store = Store(out)
    if store.runs.is_dir():
        store.digest = digest(read_base(spec), spec.fixed)
    first: list[Task] = []
    todo = 0
    for task in spec.iter_tasks():
        status = store.verified(task) if store.runs.is_dir() else None
        status = None if status is None else status["row"]["status"]
        if status is None or (retry_failed and status in engine.FAILED_STATUSES):
            todo += 1
            if len(first) < 5:
                first.append(task)
    points = spec.n_points()
    lines = [
        f"{spec.source}: {points} grid point{'s' if points != 1 else ''} x "
        f"{len(spec.seeds)} seed{'s' if len(spec.seeds) != 1 else ''} "
        f"({spec.seeds.start}:{spec.seeds.stop}) = {total} runs; "
        f"{total - todo} stored in {out}, {todo} to compute",
    ]
    for t in first:
        sets = " ".join(f"--set {shlex.quote(o)}" for o in t.overrides(spec.fixed))
        lines.append(f"  {t.run_id}: sandbox run {shlex.quote(str(spec.base))} {sets}")
    if todo > 5:
        lines.append(f"  ... and {todo - 5} more")
    return lines


__all__ = ["SweepError", "SweepReport", "run_sweep"]


def check_sweep_file(path: str | Path) -> str | None:
    """Validate a sweep file (``sandbox validate``); None if ``path`` is not one.

    Returns a one-line summary (``N grid points x S seeds = R runs of BASE``).

    Raises
    ------
    SweepError, ScenarioError
        The sweep file, its base scenario or one of its grid points is invalid.
    """
    try:  # what cannot be read is left to the scenario loader, which says why
        doc = read_sweep_document(path)
    except SweepError:
        try:  # ... unless it is a sweep file beyond the limits of one
            unlimited = read_sweep_document(path, limited=False)
        except SweepError:
            return None
        if is_sweep_file(unlimited):
            raise
        return None
    if not is_sweep_file(doc):
        return None
    spec = build_spec(path)
    spec.check_size()
    # never the code the base lists (a plug-in named with --plugin is loaded already)
    check_points(spec, read_base(spec, trust_plugins=False), plugin_code="refuse")
    points = spec.n_points()
    return (
        f"sweep: {points} grid points x {len(spec.seeds)} seeds = "
        f"{points * len(spec.seeds)} runs of {spec.base}"
    )
