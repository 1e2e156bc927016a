"""Running the tasks of a sweep: in-process, on a local process pool, or on Dask.

Every engine simulates exactly what ``sandbox run BASE --set ...`` simulates (the same
loader, loop and metrics) and returns each run's row and metrics. Dask calls
:func:`run_task` for each run; in-process and on a local pool the runs go in groups to
:func:`run_tasks`, which steps the runs of one structure together as a batch of
independent worlds (:mod:`sandbox.study.batch`, bit-identical to single runs). Results
come back to the calling process, which alone writes the store
(:mod:`sandbox.study.store`): a worker that dies, or a task that some scheduler runs
twice, can never leave a run twice or half-written in it.
"""

from __future__ import annotations

import logging
import os
import signal
import traceback
import warnings
from collections.abc import Callable, Iterator
from typing import Any

from sandbox.errors import SandboxError, SandboxWarning, ScenarioError

#: Statuses of a row besides the run's own (ok, diverged): the scenario of the run
#: is invalid (e.g. no non-overlapping draw), or the run raised an error.
STATUS_INVALID = "invalid"
STATUS_ERROR = "error"
#: Statuses ``--retry-failed`` runs again.
FAILED_STATUSES = ("diverged", STATUS_INVALID, STATUS_ERROR)
#: Most runs stepped together in one batch of worlds (memory: about 0.4 MB per
#: run of three vehicles and 1,200 samples). The numpy pass of a step costs about
#: 0.25 ms for the whole batch plus a few microseconds per world: 128 worlds share
#: it at about half the cost per run of 32 (``benchmarks/bench_sweep.py``).
BATCH_WORLDS = 128
#: A sweep is cut into at least this many groups in-process, and per worker of a
#: pool, of at least :data:`MIN_WORLDS` runs each.
MIN_GROUPS = 2
MIN_GROUPS_PER_WORKER = 2
MIN_WORLDS = 8
#: Modules a local pool's fork server imports before it forks the workers.
PRELOAD = ["sandbox.study.batch", "sandbox.run.metrics", "sandbox.scenario"]
#: How long to wait for a Dask scheduler to answer.
CONNECT_TIMEOUT = "5s"


class EngineError(SandboxError):
    """The engine that runs the tasks failed (lost scheduler, missing extra)."""


def worst_settling(run: Any, metrics: dict[str, Any]) -> float | None:
    """The largest settling time of the healthy vehicles with a slot [s].

    Healthy: no failure active at the end of the run (as for ``converged``). None when
    one of them never settles, or there is none.
    """
    worst = None
    for i, name in enumerate(run.names):
        m = metrics["vehicles"][name]
        if m["formation_error"]["final"] is None:
            continue
        if len(run.t) and bool(run.failed[-1, i]):
            continue
        if m["settling_time"] is None:
            return None
        worst = m["settling_time"] if worst is None else max(worst, m["settling_time"])
    return worst


def row_of(run: Any, metrics: dict[str, Any]) -> dict[str, Any]:
    """The measured columns of a run's row in ``results.csv``."""
    col = metrics["collisions"]
    return {
        "status": metrics["status"],
        "collisions.total": col["total"],
        "collisions.vehicle_vehicle": col["vehicle_vehicle"],
        "collisions.healthy": col["healthy"],
        "min_distance": metrics["min_distance"],
        "converged": metrics["converged"],
        "settling_time": worst_settling(run, metrics),
        "effort": sum(m["control_effort"] for m in metrics["vehicles"].values()),
        "deadlocks": len(metrics.get("deadlocks", ())),
    }


def run_task(
    base_doc: dict[str, Any],
    source: str,
    overrides: list[str],
    should_stop: Callable[[], bool] | None = None,
    keep: str | None = None,
) -> dict[str, Any] | None:
    """Simulate one run of a sweep; return ``{"row": ..., "metrics": ...}``.

    Parameters
    ----------
    base_doc : dict
        The base scenario document (as loaded from its YAML file).
    source : str
        The base file's name (for messages and the default scenario name).
    overrides : list of str
        The run's ``--set`` assignments (fixed ones, its values, its seed).
    should_stop : callable, optional
        Polled every step; a run it stops returns None (nothing to store).
    keep : str, optional
        Also write the run's directory (as ``sandbox run --out``) there.
    """
    sim = _simulation(base_doc, source, overrides)
    if isinstance(sim, dict):
        return sim
    return _single(sim, should_stop, keep)


def _simulation(base_doc: dict[str, Any], source: str, overrides: list[str]) -> Any:
    """The run's fresh Simulation, or its row when the scenario is invalid."""
    from sandbox.loop.simulation import Simulation
    from sandbox.scenario import parse_scenario

    try:
        with warnings.catch_warnings():  # shown once, when the grid was checked
            warnings.simplefilter("ignore", SandboxWarning)
            scenario = parse_scenario(base_doc, source=source, overrides=overrides)
    except ScenarioError as exc:
        return {"row": {"status": STATUS_INVALID}, "error": "; ".join(exc.lines)}
    try:
        return Simulation(scenario)
    except Exception as exc:  # a row with its status, never a missing row
        return _error(exc)


def _error(exc: BaseException) -> dict[str, Any]:
    text = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    return {"row": {"status": STATUS_ERROR}, "error": text}


def _single(
    sim: Any, should_stop: Callable[[], bool] | None, keep: str | None = None
) -> dict[str, Any] | None:
    """Run one Simulation to its row and metrics (None when stopped)."""
    try:
        run = sim.run(should_stop=should_stop)
        if run.status == "interrupted":
            return None
        return _result(run, keep)
    except Exception as exc:  # a row with its status, never a missing row
        return _error(exc)


def _result(run: Any, keep: str | None = None) -> dict[str, Any]:
    from sandbox.run.metrics import compute_metrics

    metrics = compute_metrics(run)
    out = {"row": row_of(run, metrics), "metrics": metrics}
    if keep is not None:  # --keep-runs: the run directory, as sandbox run writes it
        from pathlib import Path

        from sandbox.run.output import write_run_dir

        try:
            write_run_dir(run, metrics, Path(keep))
            out["kept"] = Path(keep).name
        except SandboxError as exc:  # the run itself is fine: its row stays
            out["kept_error"] = str(exc)
    return out


def _keep(job: tuple[Any, ...]) -> str | None:
    """Where a job keeps its run directory (its optional fourth item), or None."""
    return job[3] if len(job) > 3 else None


def run_tasks(
    jobs: list[Job], should_stop: Callable[[], bool] | None = None
) -> list[tuple[str, dict[str, Any] | None]]:
    """Run a group of tasks in this process, as batches of independent worlds.

    The tasks whose runs share their structure (the same
    :func:`~sandbox.study.batchable.batch_key`) are stepped together
    (:class:`~sandbox.study.batch.Batch`, bit-identical to single runs); the others,
    and every run of a batch that raised, run alone. Returns ``(run id, result)`` for
    every task, the result None when ``should_stop`` stopped it.
    """
    from sandbox.study.batch import Batch
    from sandbox.study.batchable import batch_key, batch_reason

    out: dict[str, dict[str, Any] | None] = {}
    groups: dict[str, list[tuple[str, Any]]] = {}
    stopped = False
    keep = {run_id: _keep(job) for run_id, job in jobs}
    for run_id, job in jobs:
        sim = _simulation(*job[:3])
        if isinstance(sim, dict):
            out[run_id] = sim
        elif batch_reason(sim) is None:
            groups.setdefault(batch_key(sim), []).append((run_id, sim))
        elif stopped:
            out[run_id] = None
        else:
            out[run_id] = _single(sim, should_stop, keep[run_id])
            stopped = out[run_id] is None
    for members in groups.values():
        if stopped:
            out.update((run_id, None) for run_id, _ in members)
            continue
        try:
            runs = Batch([sim for _, sim in members]).run(should_stop)
        except Exception:  # each run again alone: its own row or error
            runs = [_rebuilt(sim).run(should_stop=should_stop) for _, sim in members]
            if any(r.status == "interrupted" for r in runs):
                runs = None
        if runs is None:
            stopped = True
            out.update((run_id, None) for run_id, _ in members)
            continue
        for (run_id, _), run in zip(members, runs, strict=True):
            try:
                out[run_id] = _result(run, keep[run_id])
            except Exception as exc:
                out[run_id] = _error(exc)
    return [(run_id, out[run_id]) for run_id, _ in jobs]


def _rebuilt(sim: Any) -> Any:
    from sandbox.loop.simulation import Simulation

    return Simulation(sim.scenario)


def _call(job: tuple[Any, ...]) -> dict[str, Any] | None:
    return run_task(*job[:3], keep=_keep(job))


def _call_group(jobs: list[Job]) -> list[tuple[str, dict[str, Any] | None]]:
    return run_tasks(jobs)


def _ignore_interrupts() -> None:
    """Pool workers leave Ctrl-C to the parent, which stops the sweep cleanly."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


#: ``(run id, (base document, source, overrides[, directory to keep the run in]))``.
Job = tuple[str, tuple[Any, ...]]


def usable_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def chunks(jobs: list[Job], workers: int, size: int | None = None) -> list[list[Job]]:
    """The tasks in groups of at most ``size`` (default :data:`BATCH_WORLDS`).

    Groups are smaller where needed so that a sweep comes in at least
    :data:`MIN_GROUPS` groups in-process (an interrupted sweep keeps the groups
    finished so far, and progress moves) or :data:`MIN_GROUPS_PER_WORKER` per worker
    of a pool, of at least :data:`MIN_WORLDS` runs each.
    """
    size = BATCH_WORLDS if size is None else size
    groups = MIN_GROUPS if workers <= 1 else MIN_GROUPS_PER_WORKER * workers
    share = -(-len(jobs) // groups)
    size = max(1, min(size, max(MIN_WORLDS, share)))
    return [jobs[k : k + size] for k in range(0, len(jobs), size)]


def run_local(
    jobs: list[Job], workers: int, should_stop: Callable[[], bool] | None = None
) -> Iterator[tuple[str, dict[str, Any] | None]]:
    """Yield ``(run id, result)`` as runs finish: in-process, or on a process pool.

    Tasks go in groups (:func:`chunks`) to :func:`run_tasks`, which steps compatible
    runs together. In-process, ``should_stop`` also stops the runs under way (their
    results are None).
    """
    if workers <= 1 or len(jobs) <= 1:
        for group in chunks(jobs, 1):
            yield from run_tasks(group, should_stop=should_stop)
            if should_stop is not None and should_stop():
                return
        return
    import concurrent.futures as cf
    import multiprocessing as mp

    ctx = mp.get_context(
        "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
    )
    if ctx.get_start_method() == "forkserver":
        # The server imports the simulation once; every worker forked from it starts
        # with it imported (instead of a third of a second each).
        ctx.set_forkserver_preload(PRELOAD)
    with cf.ProcessPoolExecutor(
        max_workers=workers, mp_context=ctx, initializer=_ignore_interrupts
    ) as pool:
        futures = [pool.submit(_call_group, group) for group in chunks(jobs, workers)]
        try:
            for fut in cf.as_completed(futures):
                yield from fut.result()
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def dask_client(address: str | None, scheduler_file: str | None) -> Any:
    """A ``distributed.Client`` connected to the scheduler, or a clear error."""
    try:
        from distributed import Client
    except ImportError:
        from sandbox._about import install_hint

        raise EngineError(
            f"--scheduler needs Dask: {install_hint('dask')} (dask and distributed)"
        ) from None
    # Our one-line messages replace distributed's own logging of a lost connection.
    for name in ["distributed", *logging.root.manager.loggerDict]:
        if name.startswith("distributed"):
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
    where = address or f"the scheduler of {scheduler_file}"
    try:
        if scheduler_file is not None:
            if not os.path.isfile(scheduler_file):
                raise EngineError(f"--scheduler-file {scheduler_file}: no such file")
            return Client(scheduler_file=scheduler_file, timeout=CONNECT_TIMEOUT)
        return Client(address, timeout=CONNECT_TIMEOUT)
    except EngineError:
        raise
    except (OSError, TimeoutError) as exc:
        raise EngineError(
            f"cannot reach the Dask scheduler at {where}: {exc}"
        ) from None


def run_dask(
    jobs: list[Job], client: Any, on_lost: Callable[[], str]
) -> Iterator[tuple[str, dict[str, Any]]]:
    """Yield ``(run id, result)`` as runs finish on a Dask cluster.

    Each task's key is its run id, so the scheduler never computes a run twice for one
    submission; a worker that dies has its tasks rescheduled on the others. A lost
    scheduler raises :class:`EngineError` with ``on_lost()``'s advice.
    """
    from distributed import as_completed

    futures = []
    for run_id, job in jobs:
        futures.append(
            client.submit(_call, job, key=f"sandbox-run-{run_id}", pure=False)
        )
    by_key = {f.key: run_id for f, (run_id, _) in zip(futures, jobs, strict=True)}
    lost = (OSError, TimeoutError, *_comm_errors())
    try:
        for fut in as_completed(futures):
            yield by_key[fut.key], fut.result()
    except lost as exc:
        raise EngineError(
            f"lost the Dask scheduler ({type(exc).__name__}): {on_lost()}"
        ) from None
    finally:
        try:
            client.close(timeout=2)
        except Exception:  # the scheduler is gone: nothing left to close
            pass


def _comm_errors() -> tuple[type[BaseException], ...]:
    from distributed.comm.core import CommClosedError

    errors: list[type[BaseException]] = [CommClosedError]
    try:
        from distributed.client import FutureCancelledError

        errors.append(FutureCancelledError)
    except ImportError:
        pass
    from concurrent.futures import CancelledError

    errors.append(CancelledError)
    return tuple(errors)
