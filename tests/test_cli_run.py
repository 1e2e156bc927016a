"""The command line: ``sandbox run`` outputs and overrides, ``list``, ``validate``."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers import PAPER, REPO, SCENARIOS

from sandbox.cli import main
from sandbox.run.output import load_run_dir

HEADER = "t,vehicle,x1,x2,x3,v1,v2,chi1,chi2,mode,failed"
BUNDLED = sorted(SCENARIOS.rglob("*.yaml"))


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def rotating_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli") / "rotating"
    assert (
        main(
            [
                "run",
                str(PAPER / "rotating_circle.yaml"),
                "--out",
                str(out),
                "--duration",
                "2",
            ]
        )
        == 0
    )
    return out


def test_run_writes_the_four_files(rotating_out: Path) -> None:
    for name in ("trajectory.csv", "metrics.json", "scenario.yaml", "run.npz"):
        assert (rotating_out / name).is_file()


def test_trajectory_csv_header_and_rows(rotating_out: Path) -> None:
    text = (rotating_out / "trajectory.csv").read_text(encoding="utf-8")
    assert text.splitlines()[0] == HEADER
    rows = read_csv(rotating_out / "trajectory.csv")
    # 2 s at dt = 0.01 recorded every step: 201 samples (t = 0 included) x 3 vehicles
    assert len(rows) == 201 * 3
    assert [r["vehicle"] for r in rows[:6]] == ["leader", "red", "green"] * 2
    times = np.array([float(r["t"]) for r in rows]).reshape(201, 3)
    np.testing.assert_allclose(times[:, 0], np.arange(201) * 0.01, atol=1e-9)
    assert np.all(times == times[:, :1])
    assert {r["mode"] for r in rows} == {"formation"}
    assert {r["failed"] for r in rows} == {"0"}
    # the first row is the leader's start pose, at rest
    first = rows[0]
    assert (float(first["x1"]), float(first["x2"])) == (5.0, 0.0)
    assert float(first["v1"]) == 0.0
    # the CSV is the recorded run
    run = load_run_dir(rotating_out)
    x1 = np.array([float(r["x1"]) for r in rows]).reshape(201, 3)
    np.testing.assert_allclose(x1, run.pose[:, :, 0], rtol=1e-8)


def test_metrics_json_binding_keys(rotating_out: Path) -> None:
    m = json.loads((rotating_out / "metrics.json").read_text(encoding="utf-8"))
    assert m["status"] == "ok"
    assert set(m["collisions"]) >= {
        "total",
        "vehicle_vehicle",
        "vehicle_obstacle",
        "events",
    }
    assert m["collisions"]["total"] == 0 and m["collisions"]["events"] == []
    assert m["min_distance"] == pytest.approx(
        np.sqrt(2), abs=0.05
    )  # offsets 1.41 m apart
    assert isinstance(m["converged"], bool)
    assert list(m["vehicles"]) == ["leader", "red", "green"]
    for v in m["vehicles"].values():
        assert set(v) >= {
            "formation_error",
            "settling_time",
            "control_effort",
            "mode_switches",
            "failed_at",
        }
        assert set(v["formation_error"]) >= {"final", "rms_last_quarter", "max"}
        assert v["failed_at"] is None and v["mode_switches"] == 0


def test_scenario_yaml_validates_and_reruns_identically(tmp_path: Path) -> None:
    # reference.yaml has every feature: generated platoon (jittered by the seed),
    # failures, obstacles, a commanded vehicle, recovery. Shortened to 3 s, with its
    # failures moved into that time, it runs, and its resolved scenario.yaml reruns to
    # the same bytes.
    first, second = tmp_path / "first", tmp_path / "second"
    src = SCENARIOS / "reference.yaml"
    sets = [
        "failures[0].at=1",
        "failures[0].until=2",
        "failures[1].at=1.5",
        "failures[1].until=2.5",
    ]
    argv = ["run", str(src), "--out", str(first), "--duration", "3"]
    assert main(argv + [a for s in sets for a in ("--set", s)]) == 0
    m = json.loads((first / "metrics.json").read_text(encoding="utf-8"))
    assert m["status"] == "ok" and len(m["vehicles"]) == 8
    assert m["vehicles"]["p2"]["failed_at"] == pytest.approx(1.0)
    assert m["vehicles"]["p3"]["failed_at"] == pytest.approx(1.5)
    resolved = first / "scenario.yaml"
    assert main(["validate", str(resolved)]) == 0
    doc = yaml.safe_load(resolved.read_text(encoding="utf-8"))
    assert doc["duration"] == 3.0 and doc["failures"][1]["until"] == 2.5
    # the listed vehicles, and the platoon that regenerates the same four (same seed)
    assert len(doc["vehicles"]) == 4 and doc["platoon"]["count"] == 4
    assert main(["run", str(resolved), "--out", str(second)]) == 0
    for name in ("trajectory.csv", "metrics.json"):
        assert (first / name).read_bytes() == (second / name).read_bytes()


def test_set_and_duration_override(tmp_path: Path) -> None:
    out = tmp_path / "out"
    code = main(
        [
            "run",
            str(PAPER / "rotating_circle.yaml"),
            "--out",
            str(out),
            "--duration",
            "1.5",
            "--set",
            "record_every=5",
            "--set",
            "vehicles[1].offset=[-1.5, 1]",
            "--set",
            "vehicles[1].pose=[3.5, -1.5, 1.5707963]",
            "--set",
            "formation.law=own_estimate",
        ]
    )
    assert code == 0
    rows = read_csv(out / "trajectory.csv")
    # 1.5 s / (0.01 s * 5) = 30 periods of 5 steps: 31 samples x 3 vehicles
    assert len(rows) == 31 * 3
    assert float(rows[-1]["t"]) == pytest.approx(1.5)
    doc = yaml.safe_load((out / "scenario.yaml").read_text(encoding="utf-8"))
    assert doc["record_every"] == 5
    assert doc["formation"] == {"law": "own_estimate"}
    assert doc["vehicles"][1]["offset"] == [-1.5, 1.0]
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["duration"] == pytest.approx(1.5)


def test_bad_set_is_an_input_error(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    code = main(
        [
            "run",
            str(PAPER / "rotating_circle.yaml"),
            "--out",
            str(tmp_path / "o"),
            "--set",
            "formation.lawz=rotating",
        ]
    )
    assert code == 2
    assert "did you mean 'law'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_list_shows_the_bundled_scenarios(capsys: pytest.CaptureFixture) -> None:
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in (
        "stabilization",
        "circle_tracking",
        "fixed_circle",
        "rotating_circle",
        "own_estimate_circle",
        "virtual_fixed",
        "virtual_rotating",
        "leader_ref_drift",
    ):
        assert f"paper/{name}\n" in out  # the name `sandbox run` accepts
    # each with the first line of its description
    assert "Section 3.3, Figs. 7-8: rotating formation" in out
    assert "reference.yaml" not in out  # the format's documentation is not a scenario


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: str(p.relative_to(SCENARIOS)))
def test_every_bundled_scenario_validates(
    path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["validate", str(path)]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith(f"{path}: ok")
    assert "warning" not in captured.err


def test_python_dash_m_sandbox(tmp_path: Path) -> None:
    out = tmp_path / "m"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "sandbox",
            "run",
            str(PAPER / "circle_tracking.yaml"),
            "--out",
            str(out),
            "--duration",
            "1",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "circle_tracking: status ok" in proc.stdout
    assert len(read_csv(out / "trajectory.csv")) == 101
    proc = subprocess.run(
        [sys.executable, "-m", "sandbox", "--help"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0 and "validate" in proc.stdout


def test_the_summary_lists_the_deadlocks_of_metrics_json(tmp_path, capsys) -> None:
    # head-on without recovery: the two stall face to face from 0.96 s to the end
    argv = ["run", "safety/head_on_swap", "--set", "recovery.strategy=none"]
    assert main([*argv, "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out.splitlines()
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    (entry,) = metrics["deadlocks"]
    assert out[2] == (
        f"deadlocks: 1 ({', '.join(entry['vehicles'])} from {entry['t']:.2f} s to the "
        "end)"
    )
    assert out[2] == "deadlocks: 1 (west, east from 0.96 s to the end)"
