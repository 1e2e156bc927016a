"""Running the tasks of a sweep: in-process, on a local process pool, or on Dask.

Every engine simulates exactly what ``sandbox run BASE --set ...`` simulates (the same
loader, loop and metrics) and returns each run's row and metrics. On every engine the
runs go in groups (:mod:`sandbox.study.groups`) to :func:`run_tasks`, which parses a
grid point's base once for its seeds where that gives the same scenario
(:class:`Parses`) and steps the runs of one structure together as a batch of
independent worlds (the one loop, each run the bytes of the run alone); on Dask a
task is one such group. Results come back to the calling process, which alone writes
the store (:mod:`sandbox.study.store`): a worker that dies, or a task that some
scheduler runs twice, can never leave a run twice or half-written in it.

A local pool's workers die with the process that started them, even by SIGKILL
(:func:`die_with`), and its fork server with them. Groups start small and are sized
by how long the last took (:class:`Groups`); every group's runs are handed over as
soon as it finishes; and a stop asked for while groups are under way kills the
workers at once (:func:`stop_pool`) instead of waiting for them.
"""

from __future__ import annotations

import ctypes
import itertools
import logging
import os
import re
import signal
import sys
import threading
import time
import traceback
import warnings
from collections.abc import Callable, Iterator
from typing import Any

from sandbox.errors import SandboxError, SandboxWarning, ScenarioError
from sandbox.study.groups import (  # noqa: F401 (the engine's names, kept)
    BATCH_WORLDS,
    FIRST_GROUP,
    FIRST_WORK,
    GROUP_SECONDS,
    MIN_WORLDS,
    Groups,
    Job,
    chunks,
    first_group,
)

#: Statuses of a row besides the run's own (ok, diverged): the scenario of the run
#: is invalid (e.g. no non-overlapping draw), or the run raised an error.
STATUS_INVALID = "invalid"
STATUS_ERROR = "error"
#: Statuses ``--retry-failed`` runs again.
FAILED_STATUSES = ("diverged", STATUS_INVALID, STATUS_ERROR)
#: Modules a local pool's fork server imports before it forks the workers.
PRELOAD = ["sandbox.loop.simulation", "sandbox.run.metrics", "sandbox.scenario"]
#: How long to wait for a Dask scheduler to answer.
CONNECT_TIMEOUT = "5s"


class EngineError(SandboxError):
    """The engine that runs the tasks failed (lost scheduler, missing extra)."""


def worst_settling(run: Any, metrics: dict[str, Any]) -> float | None:
    """The largest settling time of the healthy vehicles with a slot [s].

    Healthy: no failure active at the end of the run (as for ``converged``). None when
    one of them never settles, or there is none. A law that hands the controller a
    moving target is judged against its goals (``metrics.json`` ``formation_goal``).
    """
    worst = None
    judged = metrics.get("formation_goal") or metrics  # a moving-target law's goals
    for i, name in enumerate(run.names):
        m = judged["vehicles"][name]
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
    judged = metrics.get("formation_goal") or metrics  # a moving-target law's goals
    return {
        "status": metrics["status"],
        "collisions.total": col["total"],
        "collisions.vehicle_vehicle": col["vehicle_vehicle"],
        "collisions.healthy": col["healthy"],
        "min_distance": metrics["min_distance"],
        "converged": judged["converged"],
        "settling_time": worst_settling(run, metrics),
        "effort": sum(m["control_effort"] for m in metrics["vehicles"].values()),
        "deadlocks": len(judged.get("deadlocks", ())),
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
    sc = _scenario(base_doc, source, overrides)
    if isinstance(sc, dict):
        return sc
    return _single(sc, should_stop, keep)


def _scenario(base_doc: dict[str, Any], source: str, overrides: list[str]) -> Any:
    """The run's scenario, or its row when the scenario is invalid."""
    from sandbox.scenario import parse_scenario

    try:
        with warnings.catch_warnings():  # shown once, when the grid was checked
            warnings.simplefilter("ignore", SandboxWarning)
            return parse_scenario(base_doc, source=source, overrides=overrides)
    except ScenarioError as exc:
        return {"row": {"status": STATUS_INVALID}, "error": "; ".join(exc.lines)}
    except Exception as exc:  # a row with its status, never a missing row
        return _error(exc)


#: A run's seed as :meth:`~sandbox.study.spec.Task.overrides` writes it, last.
SEED_OVERRIDE = re.compile(r"seed=(0|[1-9][0-9]{0,18})")


class Parses:
    """The runs' Simulations of a group, each base parsed once for runs of other seeds.

    The runs of a sweep's grid point differ only in their last override,
    ``seed=N``. Where the seed changes nothing the loader makes of the document but
    the ``seed`` field itself (no ``randomize:`` section, whose draws depend on the
    seed, in the base or an override; no ``platoon:``, whose jitter does; no
    plug-ins, whose sections the core cannot vouch for), the first run of a grid
    point is parsed and the others are its scenario with their seed. The second run
    is parsed too, and sharing goes on only if its scenario equals the one derived
    for it: a scenario that differs in anything else is parsed for every run, as
    :func:`run_task` does. A shared scenario is equal, field by field, to the one
    the loader makes, so the run and its bytes are the same.
    """

    def __init__(self) -> None:
        #: Per (base, source, overrides but the seed): the scenario parsed first,
        #: False when the runs of that key are each parsed.
        self.parsed: dict[tuple[Any, ...], Any] = {}
        #: The keys whose second run's own parse has agreed.
        self.checked: set[tuple[Any, ...]] = set()
        #: Runs parsed, and runs that took a shared scenario (for the tests).
        self.parses = 0
        self.shared = 0

    def scenario(
        self, base_doc: dict[str, Any], source: str, overrides: list[str]
    ) -> Any:
        """The run's scenario, or its row when it is invalid."""
        key, seed = self._key(base_doc, source, overrides)
        first = self.parsed.get(key) if key is not None else False
        if key is None or first is False:
            return self._parse(base_doc, source, overrides)
        if first is None:  # the first run of the key
            sc = self._parse(base_doc, source, overrides)
            ok = not isinstance(sc, dict) and _seed_free(sc)
            self.parsed[key] = sc if ok else False
            return sc
        derived = _with_seed(first, seed)
        if key not in self.checked:  # the second: its own parse must agree
            sc = self._parse(base_doc, source, overrides)
            self.checked.add(key)
            if isinstance(sc, dict) or not _same(sc, derived):
                self.parsed[key] = False
            return sc
        self.shared += 1
        return derived

    def _parse(
        self, base_doc: dict[str, Any], source: str, overrides: list[str]
    ) -> Any:
        self.parses += 1
        return _scenario(base_doc, source, overrides)

    @staticmethod
    def _key(
        base_doc: Any, source: str, overrides: list[str]
    ) -> tuple[tuple[Any, ...] | None, int]:
        """The run's key and seed; key None when its scenario is parsed anyway."""
        from sandbox.scenario import MAX_SEED

        if not overrides or not isinstance(base_doc, dict):
            return None, 0
        found = SEED_OVERRIDE.fullmatch(overrides[-1].strip())
        if found is None or int(found.group(1)) > MAX_SEED:
            return None, 0
        rest = tuple(overrides[:-1])
        if base_doc.get("randomize") is not None or any(
            o.strip().startswith(("randomize", "plugins", "platoon", "seed"))
            for o in rest
        ):
            return None, 0
        return (id(base_doc), source, rest), int(found.group(1))


def _seed_free(scenario: Any) -> bool:
    """Whether the loader used the scenario's seed for its ``seed`` field only."""
    return scenario.platoon is None and not scenario.plugins


def _with_seed(scenario: Any, seed: int) -> Any:
    """The loader's scenario with another seed, built as the loader builds it."""
    import dataclasses

    from sandbox.scenario.specs import from_loader

    with from_loader():
        return dataclasses.replace(scenario, seed=seed)


def _same(a: Any, b: Any) -> bool:
    try:
        return bool(a == b)
    except Exception:  # e.g. arrays in a field: not shown to be equal
        return False


def _error(exc: BaseException) -> dict[str, Any]:
    text = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    return {"row": {"status": STATUS_ERROR}, "error": text}


def _single(
    scenario: Any, should_stop: Callable[[], bool] | None, keep: str | None = None
) -> dict[str, Any] | None:
    """Run one scenario alone to its row and metrics (None when stopped)."""
    from sandbox.loop.simulation import Simulation

    try:
        run = Simulation(scenario).run(should_stop=should_stop)
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
    """Run a group of tasks in this process, in the one loop, K worlds at once.

    The tasks whose runs share their structure (the same
    :func:`~sandbox.loop.plan.structure_key`) are stepped together
    (:meth:`Simulation.stacked <sandbox.loop.simulation.Simulation.stacked>`, each
    run byte for byte the run alone); a group that raised runs again world by world,
    each run its own row or error. Returns ``(run id, result)`` for every task, the
    result None when ``should_stop`` stopped it.
    """
    from sandbox.loop.collector import frozen_heap

    with frozen_heap():  # the collector skips the group's objects (loop/collector.py)
        return _run_group(jobs, should_stop)


def _run_group(
    jobs: list[Job], should_stop: Callable[[], bool] | None
) -> list[tuple[str, dict[str, Any] | None]]:
    from sandbox.loop.plan import structure_key
    from sandbox.loop.simulation import Simulation

    out: dict[str, dict[str, Any] | None] = {}
    groups: dict[str, list[tuple[str, Any]]] = {}
    stopped = False
    keep = {run_id: _keep(job) for run_id, job in jobs}
    parses = Parses()
    for run_id, job in jobs:
        sc = parses.scenario(*job[:3])
        if isinstance(sc, dict):
            out[run_id] = sc
        else:
            groups.setdefault(structure_key(sc), []).append((run_id, sc))
    for members in groups.values():
        if stopped:
            out.update((run_id, None) for run_id, _ in members)
            continue
        try:
            sim = Simulation.stacked([sc for _, sc in members])
            runs = sim.run_all(should_stop)
        except Exception:  # each run again alone: its own row or error
            runs = []
            for run_id, sc in members:
                result = _single(sc, should_stop, keep[run_id])
                if result is None:
                    runs = None
                    break
                out[run_id] = result
            else:
                continue
        if runs is None:
            stopped = True
            out.update((run_id, None) for run_id, _ in members if run_id not in out)
            continue
        for (run_id, _), run in zip(members, runs, strict=True):
            try:
                out[run_id] = _result(run, keep[run_id])
            except Exception as exc:
                out[run_id] = _error(exc)
    return [(run_id, out.get(run_id)) for run_id, _ in jobs]


def _ignore_interrupts(parent: int | None = None) -> None:
    """Pool workers leave Ctrl-C to the parent, and die with it.

    A forked worker also drops the parent's SIGTERM handler (it stops the sweep,
    not a worker): SIGTERM ends the worker.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if parent is not None:
        die_with(parent)


#: ``prctl`` option of Linux: the signal a process gets when its parent dies.
PR_SET_PDEATHSIG = 1
#: How often [s] a worker without ``PR_SET_PDEATHSIG`` checks that its parent lives.
PARENT_POLL = 0.5


def die_with(parent: int) -> None:
    """Make this worker process die when the process ``parent`` dies, even by SIGKILL.

    On Linux the kernel sends SIGKILL when the worker's parent dies
    (``PR_SET_PDEATHSIG``, through ctypes); elsewhere, or if ``prctl`` fails, a daemon
    thread polls ``parent`` every :data:`PARENT_POLL` seconds. A worker forked by a
    fork server has the server as its parent, and the server stops only when every
    holder of its "alive" pipe is gone: the worker, which never starts processes of
    its own, closes its copy, so the server exits when ``parent`` does and takes its
    workers with it.
    """
    _release_fork_server()
    armed = False
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if not _alive(parent):
        os._exit(1)  # the parent died before the signal was armed
    if not armed:
        threading.Thread(target=_watch, args=(parent,), daemon=True).start()


def _release_fork_server() -> None:
    """Close this worker's copy of the fork server's "alive" pipe, if it has one."""
    server = getattr(sys.modules.get("multiprocessing.forkserver"), "_forkserver", None)
    fd = getattr(server, "_forkserver_alive_fd", None)
    if server is None or fd is None:
        return
    try:
        os.close(fd)
    except OSError:
        pass
    server._forkserver_alive_fd = None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: it exists
        return True
    return True


def _watch(parent: int) -> None:
    while _alive(parent):
        time.sleep(PARENT_POLL)
    os._exit(1)


def usable_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _timed_group(jobs: list[Job]) -> tuple[float, list[tuple[str, Any]]]:
    start = time.perf_counter()
    out = run_tasks(jobs)
    return time.perf_counter() - start, out


def pool_context(start: bool = False) -> Any:
    """The start method of a local pool: fork where it is safe, else a fork server.

    On Linux, from a process with no thread but its main one, the workers are
    forked from this process: they start at once, with the simulation imported
    (a fork server takes about 0.3 s to import it before the first worker starts,
    a tenth of a 1,024-run sweep on two cores). Elsewhere, or with threads running
    (a fork copies a lock another thread may hold), a fork server imports the
    simulation once (:data:`PRELOAD`) and every worker forked from it starts with
    it imported; without one, spawn. With ``start``, the server is started now, so
    that it imports while the sweep reads its store
    (:func:`sandbox.study.sweep.run_sweep` asks before it opens it).
    """
    import multiprocessing as mp

    methods = mp.get_all_start_methods()
    if sys.platform.startswith("linux") and threading.active_count() == 1:
        return mp.get_context("fork")
    ctx = mp.get_context("forkserver" if "forkserver" in methods else "spawn")
    if ctx.get_start_method() == "forkserver":
        ctx.set_forkserver_preload(PRELOAD)
        if start:
            from multiprocessing import forkserver

            forkserver.ensure_running()
    return ctx


def run_local(
    jobs: list[Job], workers: int, should_stop: Callable[[], bool] | None = None
) -> Iterator[tuple[str, dict[str, Any] | None]]:
    """Yield ``(run id, result)`` as runs finish: in-process, or on a process pool.

    Tasks go in groups (:class:`Groups`) to :func:`run_tasks`, which steps compatible
    runs together; every group's results are yielded as soon as it is finished.
    ``should_stop`` stops the runs under way at once: in-process their results are
    None; on a pool the groups that finished are yielded and the workers killed.
    """
    if workers <= 1 or len(jobs) <= 1:
        groups = Groups(jobs, 1)
        for group in groups:
            start = time.perf_counter()
            results = run_tasks(group, should_stop=should_stop)
            groups.timed(len(group), time.perf_counter() - start)
            yield from results
            if should_stop is not None and should_stop():
                return
        return
    import concurrent.futures as cf
    from concurrent.futures.process import BrokenProcessPool

    ctx = pool_context()
    pool = cf.ProcessPoolExecutor(
        max_workers=workers,
        mp_context=ctx,
        initializer=_ignore_interrupts,
        initargs=(os.getpid(),),
    )
    groups = Groups(jobs, workers)
    try:
        # a few groups queued per worker: the rest are cut as the pool takes them
        pending = {
            pool.submit(_timed_group, g)
            for g in itertools.islice(groups, QUEUED_PER_WORKER * workers)
        }
        while pending:
            done, pending = cf.wait(
                pending, timeout=STOP_POLL, return_when=cf.FIRST_COMPLETED
            )
            for fut in done:
                try:
                    seconds, results = fut.result()
                except BrokenProcessPool:
                    raise EngineError(
                        f"a worker process of --jobs {workers} ended abruptly (killed, "
                        "e.g. by the out-of-memory killer, or crashed)"
                    ) from None
                groups.timed(len(results), seconds)
                yield from results
            if should_stop is not None and should_stop():
                for fut in pending:  # the groups that finished meanwhile
                    if fut.done() and not fut.cancelled() and not fut.exception():
                        yield from fut.result()[1]
                return
            for g in itertools.islice(groups, len(done)):
                pending.add(pool.submit(_timed_group, g))
    finally:
        stop_pool(pool)


#: How often [s] the parent of a pool checks for a stop while groups are under way.
STOP_POLL = 0.1
#: Groups submitted to a pool ahead, per worker.
QUEUED_PER_WORKER = 2


def stop_pool(pool: Any) -> None:
    """Shut a process pool down at once: cancel its queue, kill its workers.

    The runs under way in the workers are lost (they are not finished); what the
    workers had finished has been taken from them already. Returns without waiting for
    the groups in flight.
    """
    kill = getattr(pool, "kill_workers", None)  # Python 3.14
    if kill is not None:
        kill()
    else:  # the workers, taken before shutdown() lets go of them
        workers = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in workers:
            try:
                proc.kill()
                proc.join(timeout=1)
            except (OSError, ValueError, AttributeError, AssertionError):
                pass
    pool.shutdown(wait=True, cancel_futures=True)


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
            scheduler_address(scheduler_file)  # a clear line for a file that is not one
            return Client(scheduler_file=scheduler_file, timeout=CONNECT_TIMEOUT)
        return Client(address, timeout=CONNECT_TIMEOUT)
    except EngineError:
        raise
    except (OSError, TimeoutError) as exc:
        raise EngineError(
            f"cannot reach the Dask scheduler at {where}: {exc}"
        ) from None
    except Exception as exc:  # distributed's own errors for an address it cannot use
        raise EngineError(
            f"cannot use the Dask scheduler at {where}: {type(exc).__name__}: {exc}"
        ) from None


def scheduler_address(path: str) -> str:
    """The address a Dask scheduler file holds (``{"address": "tcp://..."}``).

    Raises
    ------
    EngineError
        No such file, not JSON, or no address string in it.
    """
    import json

    try:
        with open(path, encoding="utf-8") as fh:
            info = json.load(fh)
    except FileNotFoundError:
        raise EngineError(f"--scheduler-file {path}: no such file") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise EngineError(
            f"--scheduler-file {path}: not a Dask scheduler file ({exc})"
        ) from None
    address = info.get("address") if isinstance(info, dict) else None
    if not isinstance(address, str) or "://" not in address:
        shown = repr(address)[:60]
        raise EngineError(
            f"--scheduler-file {path}: not a Dask scheduler file (its address is "
            f"{shown}; expected a mapping with an address such as "
            "'tcp://host:8786', as 'dask scheduler --scheduler-file' writes)"
        )
    return address


def run_dask(
    jobs: list[Job],
    client: Any,
    on_lost: Callable[[], str],
    should_stop: Callable[[], bool] | None = None,
) -> Iterator[tuple[str, dict[str, Any]]]:
    """Yield ``(run id, result)`` as groups of runs finish on a Dask cluster.

    Each Dask task is a group of runs (:class:`Groups`, as on a local pool: sized by
    how long the last group took, about :data:`GROUP_SECONDS` of work, at most
    :data:`BATCH_WORLDS` runs) that :func:`run_tasks` computes on the worker, stepping
    the runs of one structure together; :data:`QUEUED_PER_WORKER` groups per worker
    thread are under way, the next one cut and submitted as one finishes, and each
    group's runs are yielded as it finishes (``distributed.as_completed``). A task's
    key names its runs, so the scheduler never computes a group twice for one
    submission; a worker that dies has its groups rescheduled on the others (it
    loses the groups it held, no finished one). A lost scheduler raises
    :class:`EngineError` with ``on_lost()``'s advice. Once ``should_stop`` returns
    True (it is asked every :data:`STOP_POLL` seconds), the groups finished
    meanwhile are yielded and the others cancelled.
    """
    from distributed import as_completed

    groups = Groups(jobs, _threads(client))
    lost = (OSError, TimeoutError, *_comm_errors())
    futures: dict[str, Any] = {}  # key -> future, of the groups not yet yielded

    def submit(n: int) -> list[Any]:
        made = []
        for group in itertools.islice(groups, n):
            key = "sandbox-group-" + _group_key(group)
            fut = client.submit(_timed_group, group, key=key, pure=False)
            futures[fut.key] = fut
            made.append(fut)
        return made

    try:
        ready = as_completed(submit(QUEUED_PER_WORKER * _threads(client)))
        while not ready.is_empty():
            done = ready.next_batch(block=False)
            if not done:
                if should_stop is not None and should_stop():
                    for fut in list(futures.values()):  # finished meanwhile
                        if fut.status == "finished":
                            del futures[fut.key]
                            yield from fut.result()[1]
                    return
                time.sleep(STOP_POLL)
                continue
            for fut in done:
                seconds, results = fut.result()
                del futures[fut.key]
                groups.timed(len(results), seconds)
                yield from results
            if should_stop is not None and should_stop():
                continue  # the groups under way: yielded if done, else cancelled
            wanted = QUEUED_PER_WORKER * _threads(client) - len(futures)
            for fut in submit(max(len(done), wanted)):
                ready.add(fut)
    except lost as exc:
        raise EngineError(
            f"lost the Dask scheduler ({type(exc).__name__}): {on_lost()}"
        ) from None
    finally:
        try:
            if futures:
                client.cancel(list(futures.values()))
        except Exception:  # the scheduler is gone: nothing left to cancel
            pass
        try:
            client.close(timeout=2)
        except Exception:  # the scheduler is gone: nothing left to close
            pass


def _threads(client: Any) -> int:
    """The worker threads of a Dask cluster (at least 1)."""
    return max(1, sum(client.nthreads().values()))


def _group_key(group: list[Job]) -> str:
    """A name for a group of runs: a digest of their ids, and the first id."""
    import hashlib

    ids = "\n".join(run_id for run_id, _ in group)
    return f"{group[0][0]}-{len(group)}-{hashlib.sha256(ids.encode()).hexdigest()[:16]}"


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
