"""Run directories and GIFs are written whole or not at all, and read back safely."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from sandbox.cli import main
from sandbox.errors import OutputError
from sandbox.loop.simulation import Simulation
from sandbox.run import run_dir as output  # the writers
from sandbox.run.metrics import compute_metrics
from sandbox.run.output import load_run_dir, write_json, write_run_dir
from sandbox.run.record import Run
from sandbox.scenario import load_scenario

DOC = {
    "name": "small",
    "duration": 0.5,
    "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "leader", "pose": [5, 0, 1.5708], "leader": True},
        {"name": "red", "pose": [4, -1, 1.5708], "offset": [-1, 1]},
    ],
}
RUN_FILES = [
    "manifest.json",
    "metrics.json",
    "run.npz",
    "scenario.yaml",
    "trajectory.csv",
]


@pytest.fixture(scope="module")
def run() -> Run:
    return Simulation(load_scenario(DOC)).run()


def write(run: Run, out: Path) -> Path:
    return write_run_dir(run, compute_metrics(run), out)


def snapshot(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


def test_a_run_directory_has_its_files_and_ordinary_permissions(
    run: Run, tmp_path: Path
) -> None:
    out = write(run, tmp_path / "runs" / "small")
    assert sorted(p.name for p in out.iterdir()) == RUN_FILES
    umask = os.umask(0o022)
    os.umask(umask)
    assert out.stat().st_mode & 0o777 == 0o777 & ~umask  # not mkdtemp's 0700
    assert sorted(p.name for p in out.parent.iterdir()) == ["small"]  # no leftovers


def test_rewriting_replaces_the_run_files_and_keeps_the_others(
    run: Run, tmp_path: Path
) -> None:
    out = write(run, tmp_path / "out")
    (out / "note.png").write_bytes(b"a user's file")
    write(run, out)
    assert sorted(p.name for p in out.iterdir()) == sorted([*RUN_FILES, "note.png"])
    assert (out / "note.png").read_bytes() == b"a user's file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_the_fallback_swap_without_renameat2(
    run: Run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(output, "_exchange", lambda a, b: False)
    out = write(run, tmp_path / "out")
    (out / "note.png").write_bytes(b"old")
    write(run, out)
    assert sorted(p.name for p in out.iterdir()) == sorted([*RUN_FILES, "note.png"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_the_fallback_swap_puts_the_earlier_run_back_on_failure(
    run: Run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = write(run, tmp_path / "out")
    before = snapshot(out)
    monkeypatch.setattr(output, "_exchange", lambda a, b: False)
    real = os.replace
    calls = {"n": 0}

    def second_rename_fails(src: os.PathLike, dst: os.PathLike) -> None:
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError(28, "No space left on device")
        real(src, dst)

    monkeypatch.setattr(output.os, "replace", second_rename_fails)
    with pytest.raises(OutputError, match="No space left on device"):
        write(run, out)
    assert snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("failure", [KeyboardInterrupt, OSError])
def test_a_failure_while_writing_leaves_the_earlier_run(
    failure: type[BaseException],
    run: Run,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    out = write(run, tmp_path / "out")
    before = snapshot(out)

    def broken(self: Run, path: Path) -> None:
        Path(path).write_bytes(b"PK\x03\x04 half a zip")
        raise failure("disk trouble")

    monkeypatch.setattr(Run, "save_npz", broken)
    with pytest.raises(OutputError if failure is OSError else KeyboardInterrupt):
        write(run, out)
    assert snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_a_directory_that_is_not_a_run_is_never_replaced(
    run: Run, tmp_path: Path
) -> None:
    precious = tmp_path / "documents"
    precious.mkdir()
    (precious / "thesis.tex").write_text("years of work", encoding="utf-8")
    with pytest.raises(OutputError, match="is not a run directory"):
        write(run, precious)
    assert snapshot(precious) == {"thesis.tex": b"years of work"}
    afile = tmp_path / "afile"
    afile.write_text("x", encoding="utf-8")
    with pytest.raises(OutputError, match="is not a directory"):
        write(run, afile)


def test_the_working_directory_is_never_replaced(
    run: Run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = write(run, tmp_path / "out")
    monkeypatch.chdir(out)
    with pytest.raises(OutputError, match="is the working directory"):
        write(run, Path("."))
    assert sorted(p.name for p in out.iterdir()) == RUN_FILES


def test_cli_refuses_a_foreign_directory_before_simulating(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "s.yaml"
    src.write_text(json.dumps(DOC), encoding="utf-8")
    (tmp_path / "home").mkdir()
    (tmp_path / "home" / "notes.txt").write_text("keep", encoding="utf-8")
    assert main(["run", str(src), "--out", str(tmp_path / "home")]) == 1
    captured = capsys.readouterr()
    assert "is not a run directory" in captured.err and captured.out == ""
    assert (tmp_path / "home" / "notes.txt").read_text(encoding="utf-8") == "keep"


def test_leftovers_of_killed_runs_are_removed_by_the_next_write(
    run: Run, tmp_path: Path
) -> None:
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    pid = int(dead.stdout)  # that process has exited
    stale = tmp_path / f".out.tmp-{pid}-abc123"
    stale.mkdir()
    (stale / "trajectory.csv").write_text("t,vehicle\n0.0,", encoding="utf-8")
    alive = tmp_path / f".out.tmp-{os.getppid()}-def456"  # a live process's
    alive.mkdir()
    write(run, tmp_path / "out")
    assert not stale.exists()
    assert alive.exists()


KILLED_WHILE_WRITING = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    import sandbox.run.run_dir as output
    from sandbox.run.metrics import compute_metrics
    from sandbox.scenario import load_scenario
    from sandbox.loop.simulation import Simulation

    def half_then_hang(run, path):
        Path(path).write_text("t,vehicle,x1\\n0.000000,leader,", encoding="utf-8")
        Path(sys.argv[2]).write_text("writing", encoding="utf-8")
        time.sleep(600)

    output.write_csv = half_then_hang
    run = Simulation(load_scenario(sys.argv[3])).run()
    output.write_run_dir(run, compute_metrics(run), Path(sys.argv[1]))
    """
)


def test_sigkill_while_writing_leaves_the_earlier_run_whole(
    run: Run, tmp_path: Path
) -> None:
    out = write(run, tmp_path / "out")
    before = snapshot(out)
    src = tmp_path / "s.json"
    src.write_text(json.dumps(DOC | {"duration": 0.2}), encoding="utf-8")
    flag = tmp_path / "writing.flag"
    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED_WHILE_WRITING, str(out), str(flag), str(src)]
    )
    deadline = time.monotonic() + 60
    while not flag.exists():
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert snapshot(out) == before  # the half-written CSV never shows up in out/
    leftovers = [p for p in tmp_path.iterdir() if p.name.startswith(".out.tmp-")]
    assert len(leftovers) == 1 and (leftovers[0] / "trajectory.csv").exists()
    write(run, out)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "out",
        "s.json",
        "writing.flag",
    ]


def test_non_finite_numbers_are_written_as_null(tmp_path: Path) -> None:
    path = tmp_path / "m.json"
    write_json(
        {
            "a": float("nan"),
            "b": [1.0, float("inf"), np.float64("-inf")],
            "c": np.int64(3),
            "d": np.float64(0.5),
        },
        path,
    )
    assert json.loads(path.read_text(encoding="utf-8")) == {
        "a": None,
        "b": [1.0, None, None],
        "c": 3,
        "d": 0.5,
    }


def test_damaged_run_directories_give_clear_errors(
    run: Run, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(OutputError, match="not a valid run directory"):
        load_run_dir(tmp_path)
    out = write(run, tmp_path / "out")
    (out / "run.npz").write_bytes(b"\x89PNG not a zip")
    with pytest.raises(OutputError, match="damaged"):
        load_run_dir(out)
    assert main(["render", str(out), "--gif", str(tmp_path / "x.gif")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "damaged" in err and "Traceback" not in err
    half = out / "run.npz"
    write(run, out)
    half.write_bytes(half.read_bytes()[: len(half.read_bytes()) // 2])
    with pytest.raises(OutputError, match="damaged"):
        load_run_dir(out)


def test_a_gif_is_replaced_whole_or_not_at_all(
    run: Run, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from sandbox.render import animation as render

    gif = tmp_path / "run.gif"
    render.write_gif(run, gif, fps=10, size=64)
    before = gif.read_bytes()
    assert before.startswith(b"GIF89a")

    def fail(self: object, frames: list, delays: list) -> None:
        raise RuntimeError("encoder crashed")

    monkeypatch.setattr(render._GifStream, "add", fail)
    with pytest.raises(RuntimeError):
        render.write_gif(run, gif, fps=10, size=64)
    assert gif.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.gif"]


def test_bad_gif_options_are_errors_not_tracebacks(
    run: Run, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = write(run, tmp_path / "out")
    gif = str(tmp_path / "x.gif")
    for fps in ("100", "-1"):
        with pytest.raises(SystemExit) as info:
            main(["render", str(out), "--gif", gif, "--fps", fps])
        assert info.value.code == 2
        assert "argument --fps: expected a number from 0.5 to 50" in (
            capsys.readouterr().err
        )
