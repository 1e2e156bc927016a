"""Processes of ``sandbox sweep`` and ``sandbox check``: killed, interrupted, cleaned.

Each test starts the command in a session of its own, so that every process it
starts (the pool's workers, a fork server where there is one) is found by its
session id, and killed at the end whatever happens.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import REPO, write_yaml
from test_sweep import base_doc

pytestmark = pytest.mark.skipif(
    not Path("/proc/self/stat").exists(), reason="needs Linux's /proc"
)

ENV = {**os.environ, "PYTHONPATH": str(REPO), "SANDBOX_PROGRESS": "0"}


def session(sid: int) -> list[int]:
    """The pids of the live processes of session ``sid`` (zombies left out)."""
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        if fields[0] != "Z" and int(fields[3]) == sid:
            out.append(int(entry.name))
    return out


def start(args: list[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "sandbox", *args],
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def wait_for(condition, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


def cleanup(proc: subprocess.Popen[str]) -> None:
    for pid in session(proc.pid):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    try:
        proc.kill()
    except ProcessLookupError:
        pass
    proc.communicate(timeout=10)


def kill_and_count_orphans(proc: subprocess.Popen[str], least: int) -> list[int]:
    """SIGKILL ``proc`` once it has ``least`` processes; the orphans after 5 s."""
    assert wait_for(lambda: len(session(proc.pid)) >= least, 30), session(proc.pid)
    time.sleep(0.5)  # the workers' start-up under way
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)
    wait_for(lambda: not session(proc.pid), 5)
    return session(proc.pid)


@pytest.mark.slow
def test_sigkill_of_a_sweep_leaves_no_worker(tmp_path):
    base = write_yaml(tmp_path, base_doc(duration=30.0), "base.yaml")
    proc = start(
        ["sweep", str(base), "--seeds", "0:16", "--jobs", "2"]
        + ["--out", str(tmp_path / "out")]
    )
    try:
        # the sweep and its two workers (forked from it on Linux)
        assert kill_and_count_orphans(proc, 3) == []
    finally:
        cleanup(proc)


@pytest.mark.slow
def test_sigkill_of_check_leaves_no_worker(tmp_path):
    doc = {**base_doc(duration=60.0), "expect": {"status": "ok"}}
    files = [str(write_yaml(tmp_path, doc, f"s{k}.yaml")) for k in range(2)]
    proc = start(["check", *files, "--jobs", "2"])
    try:
        assert kill_and_count_orphans(proc, 3) == []
    finally:
        cleanup(proc)


def interrupt_when_stored(
    proc: subprocess.Popen[str], out: Path
) -> tuple[float, int, str]:
    """SIGINT ``proc`` once a run is stored; (seconds to exit, runs stored, stderr)."""
    runs = out / "runs"
    assert wait_for(lambda: runs.is_dir() and any(runs.glob("*.json")), 60)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    took = time.monotonic() - sent
    assert proc.returncode == 130, err
    return took, len(list(runs.glob("*.json"))), err


def rows(out: Path) -> int:
    with open(out / "results.csv", encoding="utf-8", newline="") as fh:
        return len(list(csv.DictReader(fh)))


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
def test_ctrl_c_returns_at_once_and_keeps_every_finished_run(tmp_path, jobs):
    # 512 runs of 12 s (a sweep of several seconds: not a short one, which would be
    # one batch) in first groups of 64 (--jobs 1) or 32 (--jobs 2), each about half
    # a second or more: the first runs are stored after the first group, and a
    # Ctrl-C returns within 2 s with every finished run stored and in the table.
    base = write_yaml(tmp_path, base_doc(duration=12.0), "base.yaml")
    out = tmp_path / "out"
    seeds = "0:512"
    proc = start(
        ["sweep", str(base), "--seeds", seeds, "--jobs", str(jobs), "--out", str(out)]
    )
    try:
        took, kept, err = interrupt_when_stored(proc, out)
        assert took < 2, f"Ctrl-C took {took:.1f} s"
        assert kept == rows(out) and f"{kept} of 512 runs stored" in err
        # whole groups of 16 or more, finished before the signal and all kept
        assert 16 <= kept < 512 and kept % 8 == 0, kept
        assert wait_for(lambda: session(proc.pid) == [], 1), session(proc.pid)
        assert not list((out / "runs").glob(".*.tmp"))
    finally:
        cleanup(proc)


def test_groups_start_small_and_are_sized_by_their_time():
    from sandbox.study import engine

    jobs = [(f"r{k}", ({}, "", [])) for k in range(1000)]
    groups = engine.Groups(jobs, 1)
    # Fast runs: after the first group (32), groups of at most 128 (chunks' size):
    # the 968 runs left in 8 equal groups (968 / 8 = 121), none small at the end.
    first = next(groups)
    groups.timed(len(first), 0.01)
    sizes = [len(first), *(len(g) for g in groups)]
    assert sizes == [engine.FIRST_GROUP] + [121] * 8
    # Runs of 0.1 s each: groups of up to 5 s / 0.1 s = 50 runs; of 1 s: 8
    # (MIN_WORLDS); of 1 ms: 128. On two workers a round is one group each, of one
    # size: the 936 runs left after the first round (2 x 32) in rounds of two equal
    # groups, 20 groups of 936 / 20 -> 47; 117 groups of 8; 8 groups of 117.
    assert engine.GROUP_SECONDS == 5.0 and engine.MIN_WORLDS == 8
    for per_run, size in [(0.1, 47), (1.0, 8), (0.001, 117)]:
        groups = engine.Groups(jobs, 2)
        g = next(groups)
        assert len(next(groups)) == len(g) == engine.FIRST_GROUP  # the first round
        groups.timed(len(g), per_run * len(g))
        assert len(next(groups)) == len(next(groups)) == size
    # every run once, in order, and no group under MIN_WORLDS at the end: 75 runs
    # in rounds of equal groups (25, then 50 in groups of at most 20: 17, 17, 16)
    groups = engine.Groups(jobs[:75], 1)
    out = []
    for g in groups:
        out.append(g)
        groups.timed(len(g), 0.25 * len(g))  # 20 runs fit in 5 s
    assert [len(g) for g in out] == [25, 17, 17, 16]
    assert [j for g in out for j in g] == jobs[:75]


def test_the_first_group_is_sized_by_the_work_of_a_run():
    import yaml

    from sandbox.study import engine

    def first(path: str, *sets: str) -> int:
        doc = yaml.safe_load((REPO / "scenarios" / path).read_text())
        return engine.first_group([("r0", (doc, path, [*sets, "seed=0"]))])

    # FIRST_WORK = 64 x 3 x 1200 vehicle-periods: 64 Fig. 15 runs of 12 s (three
    # vehicles, 1,200 periods), 48 of 16 s, and the floor of 8 for 20 vehicles of
    # 15 s (230,400 / 30,000 = 7)
    fig15 = "paper/fig15_continuous_beta1.yaml"
    assert first(fig15, "duration=12") == 64
    assert first(fig15, "duration=16") == 48
    assert first("safety/circle_swap_20_jittered.yaml") == engine.MIN_WORLDS
    # unreadable, or with plug-ins (their code is loaded where the runs run only)
    assert engine.first_group([("r0", ({}, "", []))]) == engine.FIRST_GROUP
    doc = yaml.safe_load((REPO / "scenarios" / fig15).read_text())
    plugged = [("r0", ({**doc, "plugins": ["x.py"]}, fig15, ["seed=0"]))]
    assert engine.first_group(plugged) == engine.FIRST_GROUP


def test_a_stop_while_a_group_is_stored_keeps_the_whole_group(
    tmp_path, monkeypatch, capsys
):
    # SIGINT arrives just as the second group of 4 finishes: all 8 runs finished so
    # far are stored (not 4 and then 1 of the group, as before), and nothing more.
    from sandbox.cli import main
    from sandbox.study import engine, groups

    base = write_yaml(tmp_path, base_doc(duration=0.5), "base.yaml")
    real, calls = engine.run_tasks, []

    def then_interrupted(jobs, should_stop=None):
        out = real(jobs, should_stop=should_stop)
        calls.append(len(jobs))
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGINT)
        return out

    monkeypatch.setattr(groups, "BATCH_WORLDS", 4)
    monkeypatch.setattr(engine, "run_tasks", then_interrupted)
    out = tmp_path / "out"
    assert main(["sweep", str(base), "--seeds", "0:20", "--out", str(out)]) == 130
    assert "8 of 20 runs stored" in capsys.readouterr().err
    assert calls == [4, 4] and rows(out) == 8
    assert len(list((out / "runs").glob("*.json"))) == 8


POOL_SCRIPT = """
import json, threading
from sandbox.study import engine
from test_sweep import base_doc

JOBS = [(f"r{s}", (base_doc(0.5), "base.yaml", [f"seed={s}"])) for s in range(4)]

def main():
    alone = engine.pool_context().get_start_method()
    forked = dict(engine.run_local(JOBS, 2))
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()  # a thread beside the main one: no fork of this process
    beside = engine.pool_context().get_start_method()
    served = dict(engine.run_local(JOBS, 2))
    stop.set()
    thread.join()
    serial = dict(engine.run_local(JOBS, 1))
    print(json.dumps([alone, beside, forked == serial, served == serial]))

if __name__ == "__main__":  # a fork server's workers import this file
    main()
"""


@pytest.mark.slow
def test_a_pool_forks_a_single_thread_and_serves_a_threaded_parent(tmp_path):
    # A single-threaded sweep forks its workers (they start at once); a parent
    # with threads running gets its workers from a fork server. Both give the
    # results of the runs in-process.
    script = tmp_path / "pool.py"
    script.write_text(POOL_SCRIPT, encoding="utf-8")
    env = {**ENV, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tests")])}
    done = subprocess.run(
        [sys.executable, str(script)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == ["fork", "forkserver", True, True]


def test_a_short_sweep_is_one_batch_in_process():
    import yaml

    from sandbox.study import engine, groups

    path = "failures/follower_stop.yaml"
    doc = yaml.safe_load((REPO / "scenarios" / path).read_text())

    def sizes(runs: int, seconds: float, workers: int = 1) -> list[int]:
        jobs = [
            (f"r{s}", (doc, path, [f"duration={seconds}", f"seed={s}"]))
            for s in range(runs)
        ]
        return [len(g) for g in engine.Groups(jobs, workers)]

    # four vehicles for 8 s: 3,200 vehicle-periods a run. 128 runs, 409,600 in
    # all, take about 1.2 s at FIRST_WORK in FIRST_SECONDS: one batch, not the two
    # halves a longer sweep starts with for its progress
    assert groups.short_sweep(128, 3200)
    assert sizes(128, 8) == [128]
    assert sizes(200, 8) == [100, 100]  # as equal as BATCH_WORLDS allows
    # 600 of them (about 5.8 s): groups of at most FIRST_WORK (72 runs) until timed,
    # the 600 in nine equal ones of 67
    assert not groups.short_sweep(600, 3200)
    assert engine.FIRST_WORK // 3200 == 72 and sizes(600, 8)[0] == 67
    # a pool keeps its rounds of groups per worker
    assert sizes(128, 8, workers=2) == [32, 32, 32, 32]
    # the work unknown (an unreadable scenario): never short
    assert not groups.short_sweep(10, None)
