"""How a sweep's runs are cut into groups: the unit of work of every engine.

A group is a list of runs that one process computes in
:func:`~sandbox.study.engine.run_tasks`, the runs of one structure stepped together
as one batch of worlds. Its size trades the batch's efficiency (a batch shares each
period's fixed cost: 32 worlds cost about 1.5 times as much per run as 128) against
how soon finished runs are stored and how much an interrupt loses (the groups under
way). The engines (in process, a local pool, Dask) take their groups from
:class:`Groups`.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from typing import Any

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
#: ``(run id, (base document, source, overrides[, directory to keep the run in]))``.
Job = tuple[str, tuple[Any, ...]]


def chunks(
    jobs: list[Job], workers: int, size: int | None = None, short: bool = False
) -> list[list[Job]]:
    """The tasks in groups of at most ``size`` (default :data:`BATCH_WORLDS`).

    Groups are smaller where needed so that a sweep comes in at least
    :data:`MIN_GROUPS` groups in-process (an interrupted sweep keeps the groups
    finished so far, and progress moves) or :data:`MIN_GROUPS_PER_WORKER` per worker
    of a pool, of at least :data:`MIN_WORLDS` runs each; not a ``short`` sweep
    in-process (:func:`short_sweep`: over within one group's time).
    """
    size = BATCH_WORLDS if size is None else size
    if short and workers <= 1:
        return [jobs[k : k + size] for k in range(0, len(jobs), size)]
    groups = MIN_GROUPS if workers <= 1 else MIN_GROUPS_PER_WORKER * workers
    share = -(-len(jobs) // groups)
    size = max(1, min(size, max(MIN_WORLDS, share)))
    return [jobs[k : k + size] for k in range(0, len(jobs), size)]


#: Work [s] a group of runs should take: an interrupt loses at most about this much
#: per process (the groups under way), and groups are as large as it allows. A batch
#: of K worlds shares each step's fixed cost, so on a loaded machine, where a run
#: takes several times its idle time, a smaller target kept groups of 10-30 worlds
#: and the sweep at half the speed of its own batches.
GROUP_SECONDS = 5.0
#: Runs in the first groups, before any group has been timed, where the first run's
#: scenario cannot be read (else :func:`first_group`).
FIRST_GROUP = 32
#: Work of the first groups [vehicle-periods: vehicles x control periods a run]: 64
#: runs of the three-vehicle Fig. 15 platoon of 12 s (about 0.7 s in one process;
#: below 64 worlds a batch's fixed cost a period weighs: 32 worlds ran at 1.5 times
#: the cost per run of 128).
FIRST_WORK = 64 * 3 * 1200
#: What :data:`FIRST_WORK` takes in one process on an idle machine [s].
FIRST_SECONDS = 0.7
#: Most a group grows from one timed group to the next.
MAX_GROWTH = 8


class Groups:
    """The groups of a sweep's tasks, sized by how long the last ones took.

    A short sweep in-process (:func:`short_sweep`: expected to be over within one
    group's time) comes in groups of :data:`BATCH_WORLDS` from the start, as equal as
    they can be. Otherwise the first groups have :func:`first_group` runs; then each
    group is as large as the last timed group says fits in :data:`GROUP_SECONDS` (the
    time per run of a small group overestimates that of a larger one, whose batch shares
    the step's fixed cost: the estimate errs on the small side), from :data:`MIN_WORLDS`
    up to the size :func:`chunks` gives and at most :data:`MAX_GROWTH` times the last.
    Runs of a few milliseconds reach the full batch size with the second group; runs of
    seconds stay in small groups, so that finished runs are stored early and an
    interrupt loses little. The runs left are cut into whole rounds of one group per
    worker, of about equal sizes up to that size (so the last round keeps every worker
    busy, and no small group trails), and a remainder smaller than :data:`MIN_WORLDS`
    joins the group before it. Cutting groups changes no result (a batch is
    bit-identical to single runs).

    Parameters
    ----------
    jobs : list
        The tasks, in order.
    workers : int
        Processes taking groups (1: in-process).
    """

    def __init__(self, jobs: list[Job], workers: int) -> None:
        self.jobs = jobs
        self.workers = max(1, workers)
        self.next_at = 0
        work = run_work(jobs)
        short = workers <= 1 and short_sweep(len(jobs), work)
        full = chunks(jobs, workers, short=short) if jobs else [[]]
        self.cap = max(1, len(full[0]))
        self.size = self.cap if short else min(self.cap, first_group(jobs, work))
        self._round_size = self.size  # the size of the groups of the current round
        self._round_left = 0  # groups still to cut in the current round

    def __iter__(self) -> Iterator[list[Job]]:
        return self

    def __next__(self) -> list[Job]:
        left = len(self.jobs) - self.next_at
        if left <= 0:
            raise StopIteration
        if self._round_left == 0:  # a round: one group per worker, of one size
            # the runs left, cut into whole rounds of equal groups up to ``size``:
            # no small group at the end, and the last round keeps every worker busy
            groups = -(-left // (self.size * self.workers)) * self.workers
            self._round_size = max(-(-left // groups), MIN_WORLDS)
            self._round_left = self.workers
        self._round_left -= 1
        n = min(self._round_size, self.size, left)
        if left - n < MIN_WORLDS and left <= self.cap:
            n = left  # no small group left at the end
        group = self.jobs[self.next_at : self.next_at + n]
        self.next_at += n
        return group

    def timed(self, runs: int, seconds: float) -> None:
        """Size the next groups after a group of ``runs`` took ``seconds`` [s]."""
        if runs <= 0:
            return
        per_run = max(seconds, 1e-6) / runs
        fits = int(GROUP_SECONDS / per_run)
        self.size = max(MIN_WORLDS, min(self.cap, fits, MAX_GROWTH * runs))
        self.size = min(self.size, self.cap)


def first_group(jobs: list[Job], work: int | None = None) -> int:
    """Runs in the first groups: :data:`FIRST_WORK` over the first run's work.

    The work of a run is its vehicles times its control periods (``work``, or read
    by :func:`run_work`); at least :data:`MIN_WORLDS`, and :data:`FIRST_GROUP` where
    the scenario cannot be read or lists plug-ins.
    """
    if work is None:
        work = run_work(jobs)
    if work is None:
        return FIRST_GROUP
    return max(MIN_WORLDS, FIRST_WORK // work)


def run_work(jobs: list[Job]) -> int | None:
    """The work of a sweep's run [vehicle-periods], read from its first run.

    Its vehicles times its control periods, from the first run's scenario (all
    runs of a sweep share the base; a grid may change their size, which the timed
    groups then follow); None where there is no run, the scenario cannot be read,
    or it lists plug-ins (their code is loaded where the runs run only).
    """
    if not jobs:
        return None
    base_doc, _, overrides = jobs[0][1][:3]
    if not isinstance(base_doc, dict) or "plugins" in base_doc:
        return None
    if any(o.strip().startswith("plugins") for o in overrides):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = _first_scenario(base_doc, jobs[0][1][1], overrides)
    if sc is None:
        return None
    return len(sc.vehicles) * max(1, round(sc.duration / sc.dt))


def short_sweep(runs: int, work: int | None) -> bool:
    """Whether ``runs`` runs of ``work`` each take less than a group's time in all.

    At the rate of :data:`FIRST_WORK` in :data:`FIRST_SECONDS`, a sweep expected to
    be over within :data:`GROUP_SECONDS` is not cut into more groups for its progress
    or an interrupt's sake: an interrupt loses no more than one group's time, and a
    batch of more worlds shares each period's fixed cost among more runs.
    """
    if work is None:
        return False
    return runs * work * FIRST_SECONDS <= GROUP_SECONDS * FIRST_WORK


def _first_scenario(base_doc: Any, source: str, overrides: list[str]) -> Any:
    """The scenario of a sweep's first run, or None when it cannot be read."""
    from sandbox.scenario import parse_scenario

    try:
        return parse_scenario(base_doc, source=source, overrides=overrides)
    except Exception:  # invalid, or an error: its row comes when it runs
        return None
