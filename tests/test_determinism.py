"""Same scenario and seed: identical outputs, in one process or two."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import PAPER, REPO, SCENARIOS, run_scenario

from sandbox.cli import main

#: reference.yaml shortened to 3 s with its failures moved inside: a jittered platoon
#: (seeded), failures, obstacles, recovery and a commanded vehicle.
REFERENCE_SETS = [
    "duration=3",
    "failures[0].at=1",
    "failures[0].until=2",
    "failures[1].at=1.5",
    "failures[1].until=2.5",
]
#: The rotating platoon with red and green started on each other's slots: they cross
#: and collide (three contacts), so the contact solver is exercised too.
CROSSING_SETS = [
    "duration=3",
    "vehicles[1].pose=[6, -1, 1.5707963]",
    "vehicles[2].pose=[4, -1, 1.5707963]",
]


def cli_run(path: Path, out: Path, sets: list[str]) -> None:
    argv = ["run", str(path), "--out", str(out)]
    assert main(argv + [a for s in sets for a in ("--set", s)]) == 0


@pytest.mark.slow
def test_two_cli_runs_write_identical_files(tmp_path: Path) -> None:
    for case, (path, sets) in {
        "reference": (SCENARIOS / "reference.yaml", REFERENCE_SETS),
        "crossing": (PAPER / "rotating_circle.yaml", CROSSING_SETS),
    }.items():
        a, b = tmp_path / f"{case}_a", tmp_path / f"{case}_b"
        cli_run(path, a, sets)
        cli_run(path, b, sets)
        names = sorted(p.name for p in a.iterdir())
        assert names == sorted(p.name for p in b.iterdir())
        assert {"trajectory.csv", "metrics.json", "scenario.yaml", "run.npz"} <= set(
            names
        )
        for name in names:  # every output, run.npz too (no wall time in it)
            assert (a / name).read_bytes() == (b / name).read_bytes(), (case, name)


def test_crossing_case_really_collides() -> None:
    _, metrics = run_scenario(PAPER / "rotating_circle.yaml", *CROSSING_SETS)
    assert metrics["collisions"]["vehicle_vehicle"] >= 1


@pytest.mark.slow
def test_identical_across_processes(tmp_path: Path) -> None:
    here, there = tmp_path / "here", tmp_path / "there"
    cli_run(PAPER / "rotating_circle.yaml", here, CROSSING_SETS)
    argv = [
        sys.executable,
        "-m",
        "sandbox",
        "run",
        str(PAPER / "rotating_circle.yaml"),
        "--out",
        str(there),
    ]
    proc = subprocess.run(
        argv + [a for s in CROSSING_SETS for a in ("--set", s)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    for name in ("trajectory.csv", "metrics.json"):
        assert (here / name).read_bytes() == (there / name).read_bytes()


def test_same_seed_same_arrays_other_seed_other_start() -> None:
    a, _ = run_scenario(SCENARIOS / "reference.yaml", *REFERENCE_SETS)
    b, _ = run_scenario(SCENARIOS / "reference.yaml", *REFERENCE_SETS)
    for field in ("t", "pose", "cmd", "chi", "slot", "target", "mode", "failed"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert a.events == b.events
    # the seed drives the platoon's jitter: another seed, other start positions
    c, _ = run_scenario(SCENARIOS / "reference.yaml", *REFERENCE_SETS, seed=8)
    generated = [i for i, name in enumerate(a.names) if name.startswith("p")]
    assert not np.array_equal(a.pose[0, generated], c.pose[0, generated])
    listed = [i for i in range(a.n_vehicles) if i not in generated]
    np.testing.assert_array_equal(a.pose[0, listed], c.pose[0, listed])
