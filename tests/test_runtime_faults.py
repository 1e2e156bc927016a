"""Runtime faults: divergence, interruption, and numerical trouble at the equations.

A run that diverges or is interrupted stops with a flagged status, and its outputs up to
then are complete, readable files. Signals are tested on a real subprocess
``python -m sandbox run``, signalled once its SIGTERM handler is installed (read from
``/proc/PID/status``), i.e. once the simulation is running.
"""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from sandbox import SandboxWarning
from sandbox.cli import main
from sandbox.loop.simulation import Simulation
from sandbox.loop.stepping import LoopPhysics
from sandbox.model.dynamics import wrap_angle
from sandbox.run.metrics import compute_metrics
from sandbox.run.output import CSV_HEADER, load_run_dir, write_run_dir
from sandbox.scenario import load_scenario

# Gains of the wrong sign, given explicitly, with the report's dt = 0.01 s: the error
# poles are s = 4.14 and -24.1 [1/s], so the error grows like exp(4.14 t). Validation
# accepts it with a warning (a deliberate experiment); chi passes 1e3 m/s after ~2.5 s.
DIVERGING = """\
name: diverging
description: k1 = k3 = +100, the wrong sign; eq. (6) is unstable for any period.
duration: 10
dt: 0.01
reference: {type: point, position: [1, 0]}
vehicle:
  gains: {k1: 100, k2: -20, k3: 100, k4: -20, kp: 2}
vehicles:
  - {name: runaway, pose: [0, 0, 0]}
"""

# A run far longer than any test waits for: it is always stopped by a signal.
LONG = """\
name: long
duration: 3600
dt: 0.01
reference: {type: circle, center: [0, 0], radius: 5, speed: 1}
formation: {law: rotating}
vehicles:
  - {name: leader, pose: [5, 0, 1.5708], leader: true}
  - {name: red, pose: [4, -1, 1.5708], offset: [-1, 1]}
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def strict_json(path: Path) -> dict:
    """Parse JSON refusing NaN/Infinity (which are not JSON)."""

    def refuse(token: str) -> None:
        raise ValueError(f"non-JSON constant {token}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


def read_csv(path: Path) -> list[dict[str, str]]:
    """Rows of trajectory.csv, checking that the file is whole (every row complete)."""
    text = path.read_text(encoding="utf-8")
    assert text.endswith("\n"), "the last row is cut"
    rows = list(csv.reader(text.splitlines()))
    assert ",".join(rows[0]) == CSV_HEADER
    assert all(len(r) == len(rows[0]) for r in rows[1:]), "a truncated row"
    return [dict(zip(rows[0], r, strict=True)) for r in rows[1:]]


# --------------------------------------------------------------------------- divergence
def test_a_diverging_run_stops_flagged_with_time_and_vehicle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = write(tmp_path, "diverging.yaml", DIVERGING)
    out = tmp_path / "out"
    code = main(["run", str(src), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1
    assert "do not stabilise eq. (6) for any control period" in err  # the warning
    metrics = strict_json(out / "metrics.json")
    assert metrics["status"] == "diverged"
    info = metrics["diverged"]
    assert info["vehicle"] == "runaway"
    assert 0.5 < info["t"] < 10.0
    assert f"error: the run diverged at t = {info['t']:.3f} s (vehicle runaway" in err
    # The trajectory up to the divergence is kept, complete and finite.
    rows = read_csv(out / "trajectory.csv")
    times = [float(r["t"]) for r in rows]
    assert times == sorted(times)
    assert times[-1] == pytest.approx(info["t"])
    assert len(rows) == round(info["t"] / 0.01) + 1
    assert all(math.isfinite(float(r["x1"])) for r in rows)
    run = load_run_dir(out)
    assert run.status == "diverged" and len(run.t) == len(rows)
    # Its scenario.yaml reproduces the divergence, identically.
    again = tmp_path / "again"
    assert main(["run", str(out / "scenario.yaml"), "--out", str(again)]) == 1
    assert (again / "trajectory.csv").read_bytes() == (
        out / "trajectory.csv"
    ).read_bytes()


def test_a_non_finite_state_is_caught_and_named(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # A NaN appearing in the physics (injected at t = 0.5 s for the second vehicle).
    sc = load_scenario(yaml.safe_load(LONG) | {"duration": 2.0})
    read = LoopPhysics.read
    calls = {"n": 0}

    def poisoned(self: LoopPhysics):
        pos, theta, vel = read(self)
        calls["n"] += 1
        if calls["n"] > 50:
            pos[1, 0] = np.nan
        return pos, theta, vel

    monkeypatch.setattr(LoopPhysics, "read", poisoned)
    run = Simulation(sc).run()
    assert run.status == "diverged"
    assert run.info["diverged"] == {
        "t": 0.5,
        "vehicle": "red",
        "reason": "non-finite state",
    }
    assert np.isfinite(run.pose[:-1]).all() and np.isnan(run.pose[-1, 1, 0])
    metrics = compute_metrics(run)
    out = write_run_dir(run, metrics, tmp_path / "nanrun")
    data = strict_json(out / "metrics.json")  # NaN written as null, valid JSON
    assert data["status"] == "diverged"


# ------------------------------------------------------------------------- interruption
def test_should_stop_ends_the_run_flagged_with_complete_outputs(tmp_path: Path) -> None:
    sc = load_scenario(yaml.safe_load(LONG))
    polls = {"n": 0}

    def stop() -> bool:
        polls["n"] += 1
        return polls["n"] > 120

    run = Simulation(sc).run(should_stop=stop)
    assert run.status == "interrupted"
    assert run.info["interrupted"] == {"t": pytest.approx(1.2)}
    assert len(run.t) == 121
    out = write_run_dir(run, compute_metrics(run), tmp_path / "out")
    assert strict_json(out / "metrics.json")["status"] == "interrupted"
    assert len(read_csv(out / "trajectory.csv")) == 121 * 2


def simulating(record_dir: Path) -> bool:
    """Whether the run has started simulating: its disk-backed record exists.

    LONG records 360,001 samples, more than the in-memory limit, so the recorder
    makes its ``sandbox-record-*`` directory in the run's TMPDIR as the loop starts
    (signals are caught from start-up on, so the handlers tell nothing).
    """
    return any(record_dir.glob("sandbox-record-*"))


def start_run(src: Path, out: Path) -> subprocess.Popen:
    record_dir = out.parent / "tmp"
    record_dir.mkdir(exist_ok=True)
    proc = subprocess.Popen(
        [sys.executable, "-m", "sandbox", "run", str(src), "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "CI": "1", "TMPDIR": str(record_dir)},
    )
    deadline = time.monotonic() + 60
    while not simulating(record_dir):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the run never started"
        time.sleep(0.02)
    time.sleep(0.3)  # a few dozen control steps
    return proc


needs_proc = pytest.mark.skipif(
    not Path("/proc/self/status").exists(),
    reason="needs /proc to see when the run has started",
)


@pytest.mark.slow
@needs_proc
@pytest.mark.parametrize(
    "sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"]
)
def test_a_signal_stops_the_run_with_outputs_so_far(
    sig: signal.Signals, tmp_path: Path
) -> None:
    src = write(tmp_path, "long.yaml", LONG)
    out = tmp_path / "out"
    proc = start_run(src, out)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted: outputs so far are in" in err and "Traceback" not in err
    metrics = strict_json(out / "metrics.json")
    assert metrics["status"] == "interrupted"
    t_stop = metrics["interrupted"]["t"]
    assert 0 < t_stop < 3600
    rows = read_csv(out / "trajectory.csv")
    assert float(rows[-1]["t"]) == pytest.approx(t_stop)
    assert len(rows) == 2 * (round(t_stop / 0.01) + 1)
    run = load_run_dir(out)
    assert run.status == "interrupted" and run.pose.shape == (len(rows) // 2, 2, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.yaml", "out", "tmp"]
    assert not list((tmp_path / "tmp").iterdir())  # the record went with the run


@pytest.mark.slow
@needs_proc
def test_sigkill_mid_run_leaves_the_earlier_run_whole(tmp_path: Path) -> None:
    src = write(tmp_path, "long.yaml", LONG)
    out = tmp_path / "out"
    assert main(["run", str(src), "--out", str(out), "--duration", "0.5"]) == 0
    (out / "notes.txt").write_text("from the earlier run\n", encoding="utf-8")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    proc = start_run(src, out)
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.yaml", "out", "tmp"]
    # Re-running replaces the earlier run's files; the user's note is kept.
    assert main(["run", str(src), "--out", str(out), "--duration", "0.3"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "manifest.json",
        "metrics.json",
        "notes.txt",
        "run.npz",
        "scenario.yaml",
        "trajectory.csv",
    ]
    assert strict_json(out / "metrics.json")["duration"] == pytest.approx(0.3)


# ------------------------------------------------------------ numerical guards in a run
FAR = {
    "name": "far",
    "duration": 55.0,
    "reference": {"type": "point", "position": [100.0, 0.0]},
    "vehicles": [{"name": "solo", "pose": [0.0, 0.0, 0.0]}],
}


@pytest.mark.slow
def test_huge_initial_error_with_limits_gives_bounded_commands() -> None:
    # 100 m from its point, v1_max = 2 m/s and max_accel = 10 m/s^2: chi is clamped
    # (no wind-up), the vehicle drives there at 2 m/s: 100 m / 2 m/s = 50 s.
    doc = FAR | {"vehicle": {"v1_max": 2.0, "max_accel": 10.0}}
    run = Simulation(load_scenario(doc)).run()
    assert run.status == "ok"
    v1 = run.cmd[:, 0, 0]
    assert v1.max() <= 2.0 + 1e-12
    assert np.abs(np.diff(v1)).max() <= 10.0 * 0.01 + 1e-12
    assert np.hypot(*run.chi[:, 0].T).max() <= 2.0 + 1e-12
    assert np.abs(run.cmd[:, 0, 1]).max() < 1e-9  # already facing it: no turning
    error = np.hypot(run.pose[:, 0, 0] - 100.0, run.pose[:, 0, 1])
    assert error[-1] < 0.01
    arrived = run.t[np.argmax(error < 0.05)]
    assert 49.0 < arrived < 52.0  # 0.2 s of ramp at 10 m/s^2, then 2 m/s


def test_huge_initial_error_without_limits_asks_for_unphysical_speeds() -> None:
    # With the report's gains the error is critically damped, e(t) = e0 (1 + 10 t)
    # exp(-10 t): chi peaks at 100 e0 t exp(-10 t) at t = 0.1 s, 100 * 100 * 0.1 / e =
    # 368 m/s for e0 = 100 m (more, as the heading has to turn first), and the body
    # follows it. The run still converges: no divergence is flagged (chi stays below
    # 1e3 m/s).
    with pytest.warns(SandboxWarning, match="per physics substep"):  # 387 m/s
        run = Simulation(load_scenario(FAR | {"duration": 10.0})).run()
    assert run.status == "ok"
    chi_peak = np.hypot(*run.chi[:, 0].T).max()
    assert 368.0 < chi_peak < 1000.0
    speed = np.hypot(*np.diff(run.pose[:, 0, :2], axis=0).T) / 0.01
    assert speed.max() == pytest.approx(chi_peak, rel=0.01)  # the motor follows
    assert np.abs(run.pose[:, 0, 1]).max() < 1e-6  # straight at it, as eq. (1) says
    assert np.hypot(run.pose[-1, 0, 0] - 100.0, run.pose[-1, 0, 1]) < 0.01


def test_a_vehicle_at_rest_on_its_point_never_produces_nan() -> None:
    # chi = 0 for the whole run: eq. (5) divides by |chi|^2, guarded (v1 = v2 = 0).
    doc = {
        "duration": 2.0,
        "reference": {"type": "point", "position": [3.0, 4.0]},
        "vehicles": [{"pose": [3.0, 4.0, 2.5]}],
    }
    run = Simulation(load_scenario(doc)).run()
    assert run.status == "ok"
    assert np.all(run.cmd == 0.0) and np.all(run.chi == 0.0)
    assert np.all(run.pose[:, 0] == [3.0, 4.0, 2.5])


def spin_then_track(x3: float) -> np.ndarray:
    doc = {
        "duration": 20.0,
        "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1},
        "vehicles": [{"name": "s", "pose": [5, 0, x3]}],
        "failures": [
            {"vehicle": "s", "at": 0.0, "kind": "spin", "v2": 10.0, "until": 10.0}
        ],
    }
    run = Simulation(load_scenario(doc)).run()
    assert run.status == "ok"
    return run.pose[:, 0]


@pytest.mark.slow
def test_an_unbounded_body_angle_keeps_the_controller_exact() -> None:
    # pymunk never wraps body.angle, and x3 is recorded unwrapped (continuous). A body
    # that has spun for the equivalent of 10^4 s at 1 rad/s has |x3| ~ 1e4 rad: starting
    # there (+ a 10 s spin at 10 rad/s, then tracking) must give the run that starts at
    # x3 mod 2 pi, up to the float spacing at 1e4 (1.8e-12 rad per operation).
    base = 1.5707963
    turns = 1592  # 2 pi * 1592 = 10003 rad
    ref = spin_then_track(base)
    far = spin_then_track(base + 2 * math.pi * turns)
    assert far[-1, 2] - ref[-1, 2] == pytest.approx(2 * math.pi * turns, abs=1e-6)
    assert np.abs(far[:, :2] - ref[:, :2]).max() < 1e-6  # measured 6.8e-8 m
    assert np.abs(wrap_angle(far[:, 2] - ref[:, 2])).max() < 1e-5  # measured 2.3e-7 rad
    assert ref[-1, 2] > 100.0  # the recorded x3 is unwrapped: 10 s at 10 rad/s


def test_wrap_angle_of_large_angles_is_exact_to_float_spacing() -> None:
    a = np.linspace(-3.0, 3.0, 13)
    for turns in (1, 10**3, 10**5):
        big = a + 2 * math.pi * turns
        tol = 4 * np.spacing(2 * math.pi * turns)
        assert np.abs(wrap_angle(big) - a).max() <= tol
