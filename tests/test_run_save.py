"""``Run.save(path)``: a run saved from Python is the directory ``sandbox run`` writes.

Also the import graph of :mod:`sandbox.run`: the record names the modules that read it
(analysis, the run directory's writer, the metrics) and none of them imports it back.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
from helpers import HEADON, write_yaml

from sandbox import Simulation, load_run, load_scenario, simulate
from sandbox.cli import main
from sandbox.errors import OutputError
from sandbox.run.run_dir import MANIFEST

RUN = Path(__file__).resolve().parents[1] / "sandbox" / "run"


def test_a_saved_run_is_the_directory_sandbox_run_writes(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path, HEADON)
    assert main(["run", str(scenario), "--out", str(tmp_path / "cli")]) == 0
    saved = simulate(load_scenario(scenario)).save(tmp_path / "py")
    assert saved == tmp_path / "py"
    names = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert names == sorted(p.name for p in saved.iterdir())
    assert {"metrics.json", "run.npz", "trajectory.csv", MANIFEST} <= set(names)
    for name in names:  # the same bytes, metrics included
        assert (saved / name).read_bytes() == (tmp_path / "cli" / name).read_bytes()


def test_a_stepped_run_saved_is_viewed_and_loaded_back(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = Simulation(load_scenario(write_yaml(tmp_path, HEADON)))
    while not sim.done:
        sim.step(commands={"east": (0.5, 0.2)})
    run = sim.result()
    out = run.save(tmp_path / "stepped")
    assert main(["view", str(out)]) == 0
    assert (out / "replay.html").is_file()
    back = load_run(out)
    assert np.array_equal(back.pose, run.pose)
    assert (back.mode[1:-1, 0] == 3).all()  # external: driven through step()
    out = run.save(tmp_path / "stepped")  # an earlier run directory: replaced
    assert (out / "replay.html").is_file()  # what the manifest does not list stays


def test_save_never_replaces_a_users_directory(tmp_path: Path) -> None:
    run = simulate(load_scenario(write_yaml(tmp_path, HEADON)))
    mine = tmp_path / "notes"
    mine.mkdir()
    (mine / "todo.txt").write_text("mine")
    with pytest.raises(OutputError, match="is not a run directory"):
        run.save(mine)
    assert sorted(p.name for p in mine.iterdir()) == ["todo.txt"]
    with pytest.raises(OutputError, match="is not a directory"):
        run.save(mine / "todo.txt")


def imports(path: Path) -> set[str]:
    """The ``sandbox.run`` modules a file imports, in functions and type checks too."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
            "sandbox.run."
        ):
            found.add(node.module)
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("sandbox.run.")}
    return found


def test_no_import_circle_in_the_run_package() -> None:
    graph = {f"sandbox.run.{p.stem}": imports(p) for p in RUN.glob("*.py")}
    for start in graph:
        seen, todo = set(), list(graph[start])
        while todo:
            m = todo.pop()
            assert m != start, f"{start} imports itself back (through {sorted(seen)})"
            if m not in seen:
                seen.add(m)
                todo += graph.get(m, ())
