"""``sandbox sweep --scheduler``: a real Dask scheduler and two workers on 127.0.0.1.

Each test starts ``dask scheduler`` and ``dask worker`` processes (no nanny, one thread
each) in their own process group and kills the whole group at the end, so no Dask
process survives the tests.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import REPO, write_yaml
from test_sweep import base_doc, read_csv

#: Every test of this module takes seconds: the full suite only (not in -m "not slow").
pytestmark = pytest.mark.slow

pytest.importorskip("distributed")

DASK = Path(sys.executable).parent / "dask"
RUNS = 24


class Cluster:
    """A scheduler and workers started as processes; :meth:`stop` kills them all."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.file = root / "scheduler.json"
        self.procs: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, object] = {}

    def _start(self, name: str, *args: str) -> subprocess.Popen:
        log = open(self.root / f"{name}.log", "a")  # noqa: SIM115 (closed in kill)
        self.logs[name] = log
        proc = subprocess.Popen(
            [str(DASK), *args],
            stdout=log,
            stderr=subprocess.STDOUT,
            cwd=self.root,
            start_new_session=True,
        )
        self.procs[name] = proc
        return proc

    def start_scheduler(self) -> None:
        self.file.unlink(missing_ok=True)
        self._start(
            "scheduler",
            "scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--no-dashboard",
            "--scheduler-file",
            str(self.file),
        )
        wait_for(lambda: self.file.is_file() and "address" in self.file.read_text())

    def start_worker(self, name: str) -> None:
        self._start(
            name,
            "worker",
            "--scheduler-file",
            str(self.file),
            "--nthreads",
            "1",
            "--no-nanny",
            "--no-dashboard",
            "--death-timeout",
            "20",
            "--local-directory",
            str(self.root),
        )

    def wait_workers(self, n: int) -> None:
        from distributed import Client

        with Client(scheduler_file=str(self.file), timeout="20s") as client:
            client.wait_for_workers(n, timeout=60)

    def kill(self, name: str) -> None:
        proc = self.procs.pop(name)
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        finally:
            proc.wait(timeout=10)
            self.logs.pop(name).close()

    def stop(self) -> None:
        for name in list(self.procs):
            try:
                self.kill(name)
            except ProcessLookupError:
                pass


def wait_for(cond, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise TimeoutError("condition not met in time")
        time.sleep(0.05)


@pytest.fixture
def cluster(tmp_path: Path):
    c = Cluster(tmp_path)
    try:
        c.start_scheduler()
        c.start_worker("w1")
        c.start_worker("w2")
        c.wait_workers(2)
        yield c
    finally:
        c.stop()


@pytest.fixture
def base(tmp_path: Path) -> Path:
    return write_yaml(tmp_path, base_doc(duration=2.0), "base.yaml")


def sweep(base: Path, out: Path, *extra: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "sandbox", "sweep", str(base), "--grid"]
    cmd += ["recovery.beta=1,4", "--seeds", f"0:{RUNS // 2}", "--out", str(out), *extra]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen(
        cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def stored(out: Path) -> int:
    return len(list((out / "runs").glob("*.json"))) if (out / "runs").is_dir() else 0


def test_dask_gives_the_local_results_and_survives_a_killed_worker(
    tmp_path, cluster, base
):
    local = sweep(base, tmp_path / "local")
    _, err = local.communicate(timeout=120)
    assert local.returncode == 0, err
    proc = sweep(base, tmp_path / "dask", "--scheduler-file", str(cluster.file))
    wait_for(lambda: stored(tmp_path / "dask") >= 3)
    cluster.kill("w1")  # SIGKILL mid-sweep; its tasks go to w2
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    rows = read_csv(tmp_path / "dask" / "results.csv")
    ids = [r["run_id"] for r in rows]
    assert len(ids) == RUNS and len(set(ids)) == RUNS  # every run exactly once
    assert stored(tmp_path / "dask") == RUNS
    local_csv = (tmp_path / "local" / "results.csv").read_bytes()
    assert (tmp_path / "dask" / "results.csv").read_bytes() == local_csv
    for run_id in ids[:3]:
        a = json.loads((tmp_path / "dask" / "runs" / f"{run_id}.json").read_text())
        b = json.loads((tmp_path / "local" / "runs" / f"{run_id}.json").read_text())
        assert a == b


def test_a_lost_scheduler_is_a_clear_error_and_the_rerun_computes_the_rest(
    tmp_path, cluster
):
    # Three groups of 8 runs of 60 s (about a second each on an idle machine): the
    # scheduler dies once the first group is stored, long before the third is done.
    base = write_yaml(tmp_path, base_doc(duration=60.0), "base.yaml")
    out = tmp_path / "dask"
    proc = sweep(base, out, "--scheduler-file", str(cluster.file))
    wait_for(lambda: stored(out) >= 3)
    cluster.kill("scheduler")
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 1
    assert "error: lost the Dask scheduler" in err
    assert "run the same command again" in err
    assert "Traceback" not in err
    kept = stored(out)
    assert 3 <= kept < RUNS
    # Restart the cluster; the same command computes only the missing runs.
    cluster.stop()
    cluster.start_scheduler()
    cluster.start_worker("w3")
    cluster.start_worker("w4")
    cluster.wait_workers(2)
    again = sweep(base, out, "--scheduler-file", str(cluster.file))
    text, err = again.communicate(timeout=120)
    assert again.returncode == 0, err
    assert f"{RUNS - kept} runs computed, {kept} already stored" in text
    assert len(read_csv(out / "results.csv")) == RUNS


def test_an_unreachable_scheduler(tmp_path, base):
    proc = sweep(base, tmp_path / "o", "--scheduler", "tcp://127.0.0.1:9")
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in err


class CountingClient:
    """A ``distributed.Client`` whose ``submit`` calls are recorded."""

    def __init__(self, client) -> None:
        self.client = client
        self.submitted: list = []

    def submit(self, func, *args, **kwargs):
        self.submitted.append(args[0])
        return self.client.submit(func, *args, **kwargs)

    def __getattr__(self, name: str):
        return getattr(self.client, name)


def seed_jobs(runs: int, duration: float = 2.0) -> list:
    doc = base_doc(duration=duration)
    del doc["randomize"]  # runs differing only in their seed: one parse per group
    return [(f"r{s:03d}", (doc, "base.yaml", [f"seed={s}"])) for s in range(runs)]


def test_a_dask_task_is_a_group_of_runs(cluster):
    from distributed import Client

    from sandbox.study import engine

    jobs = seed_jobs(40)
    client = CountingClient(Client(scheduler_file=str(cluster.file), timeout="20s"))
    got = list(engine.run_dask(jobs, client, lambda: "gone"))
    sizes = [len(group) for group in client.submitted]
    # 40 runs on 2 worker threads: groups of at most 10 (2 per thread), 8 or more
    assert len(sizes) < len(jobs) and sum(sizes) == len(jobs)
    assert all(8 <= n <= 10 for n in sizes[:-1]), sizes
    assert all(isinstance(job, tuple) for group in client.submitted for job in group)
    assert sorted(run_id for run_id, _ in got) == [run_id for run_id, _ in jobs]
    local = dict(engine.run_local(jobs, 1))
    for run_id, result in got:
        assert json.dumps(result) == json.dumps(local[run_id])


def test_a_stopped_dask_sweep_yields_whole_groups_and_cancels_the_rest(cluster):
    from distributed import Client

    from sandbox.study import engine

    jobs = seed_jobs(64, duration=20.0)  # groups of 16 runs, about a second each
    client = CountingClient(Client(scheduler_file=str(cluster.file), timeout="20s"))
    got: list = []

    def stop() -> bool:
        return bool(got)  # as soon as the first group is in

    for item in engine.run_dask(jobs, client, lambda: "gone", should_stop=stop):
        got.append(item)
    sizes = [len(group) for group in client.submitted]
    assert len(sizes) == 4  # 2 per worker thread, none after the stop
    ids = {run_id for run_id, _ in got}
    whole = [g for g in client.submitted if {r for r, _ in g} <= ids]
    assert sum(len(g) for g in whole) == len(ids)  # only whole groups
    assert len(ids) < len(jobs)  # the queued groups were cancelled


def test_ctrl_c_of_a_dask_sweep_keeps_the_finished_groups(tmp_path, cluster):
    # 80 runs of 20 s: four groups of 20 (two per worker, about a second each on an
    # idle machine), all under way. A SIGINT once the first group is stored returns
    # at once with the finished groups stored and in the table, and the queued
    # groups cancelled.
    base = write_yaml(tmp_path, base_doc(duration=20.0), "base.yaml")
    out = tmp_path / "dask"
    cmd = [sys.executable, "-m", "sandbox", "sweep", str(base), "--grid"]
    cmd += ["recovery.beta=1,4", "--seeds", "0:40", "--out", str(out)]
    cmd += ["--scheduler-file", str(cluster.file)]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    wait_for(lambda: stored(out) >= 1)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    took = time.monotonic() - sent
    assert proc.returncode == 130, err
    kept = stored(out)
    assert kept % 20 == 0 and 20 <= kept < 80  # whole groups, not all of them
    assert len(read_csv(out / "results.csv")) == kept  # every stored run a row
    assert took < 5
