"""The hostile corpus of outputs: no command replaces a file the user wrote.

v0.3: ``sandbox schema --out keep.yaml`` replaced a scenario with the schema, and
``plot --out``, ``sweep plot --out`` and ``gallery --out`` replaced files of the names
they write (``trajectories.png``, ``rates_*.png``, ``NAME.gif``). Every command now
goes through :mod:`sandbox.run.output_guard`: an earlier output of the same command is
replaced, anything else is refused in one line with exit status 2 and left as it was
(``--force`` replaces it). A scan of ``sandbox/cli/`` fails when a command writes a
file without the guard.
"""

from __future__ import annotations

import ast
import json
import os
from pathlib import Path

import pytest
from helpers import HEADON, write_yaml

from sandbox.cli import main
from sandbox.run import output_guard
from sandbox.run.output_guard import (
    MARKS,
    OutputRefused,
    check_target,
    staged,
    write_output,
)

PACKAGE = Path(__file__).resolve().parents[1] / "sandbox"


def one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


# ------------------------------------------------------------------ the guard itself
def test_only_an_unchanged_earlier_output_of_the_same_command_is_replaced(
    tmp_path: Path,
) -> None:
    target = tmp_path / "out" / "a.txt"
    target.parent.mkdir()
    write_output(target, "one\n", "demo")
    assert (
        json.loads((tmp_path / "out" / MARKS).read_text())["files"]["a.txt"]["command"]
        == "demo"
    )
    write_output(target, "two\n", "demo")  # an earlier output: replaced
    assert target.read_text() == "two\n"
    with pytest.raises(OutputRefused, match="not an earlier output of sandbox other"):
        write_output(target, "three\n", "other")  # another command's
    target.write_text("edited by hand\n")  # the user's now
    with pytest.raises(OutputRefused, match="a.txt: exists and is not an earlier"):
        write_output(target, "four\n", "demo")
    assert target.read_text() == "edited by hand\n"
    write_output(target, "five\n", "demo", force=True)
    assert target.read_text() == "five\n"


@pytest.mark.parametrize("kind", ["directory", "link", "crafted_marks"])
def test_what_is_never_an_earlier_output(tmp_path: Path, kind: str) -> None:
    target = tmp_path / "a.txt"
    if kind == "directory":
        target.mkdir()
    elif kind == "link":
        (tmp_path / "real.txt").write_text("mine")
        target.symlink_to(tmp_path / "real.txt")
    else:  # a record claiming the file, with another file's digest
        target.write_text("mine")
        marks = {"files": {"a.txt": {"command": "demo", "sha256": "0" * 64}}}
        (tmp_path / MARKS).write_text(json.dumps(marks))
    with pytest.raises(OutputRefused):
        check_target(target, "demo")
    if kind == "directory":
        with pytest.raises(OutputRefused, match="is a directory"):
            check_target(target, "demo", force=True)


def test_a_stage_puts_nothing_in_place_when_one_name_is_taken(tmp_path: Path) -> None:
    out = tmp_path / "figs"
    out.mkdir()
    (out / "b.png").write_text("mine")
    with pytest.raises(OutputRefused, match="b.png"):
        with staged(out, "demo") as stage:
            (stage.path / "a.png").write_text("new a")
            (stage.path / "b.png").write_text("new b")
    assert sorted(p.name for p in out.iterdir()) == ["b.png"]  # no a.png, no stage
    assert (out / "b.png").read_text() == "mine"


def test_a_stage_that_fails_removes_the_directories_it_made(tmp_path: Path) -> None:
    out = tmp_path / "new" / "deeper"
    with pytest.raises(RuntimeError):
        with staged(out, "demo") as stage:
            (stage.path / "a.png").write_text("half")
            raise RuntimeError("the drawing failed")
    assert list(tmp_path.iterdir()) == []


def test_a_killed_commands_stage_is_removed_by_the_next(tmp_path: Path) -> None:
    dead = tmp_path / f"{output_guard.STAGE_PREFIX}999999999-abc"
    dead.mkdir()
    (dead / "a.png").write_text("half")
    alive = tmp_path / f"{output_guard.STAGE_PREFIX}{os.getpid()}-abc"
    alive.mkdir()
    with staged(tmp_path, "demo"):
        pass
    assert not dead.exists() and alive.exists()


# ------------------------------------------------------------------ the commands
@pytest.fixture
def scenario(tmp_path: Path) -> Path:
    return write_yaml(tmp_path, {**HEADON, "duration": 0.5}, "mine.yaml")


def test_schema_never_replaces_a_users_file(
    tmp_path: Path, scenario: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = scenario.read_bytes()
    assert main(["schema", "--out", str(scenario)]) == 2
    line = one_line(capsys.readouterr().err)
    assert line.startswith(f"error: {scenario}: exists and is not an earlier output")
    assert "--force" in line
    assert scenario.read_bytes() == before
    schema = tmp_path / "s.json"
    assert main(["schema", "--out", str(schema)]) == 0
    assert main(["schema", "--out", str(schema)]) == 0  # its own: replaced
    assert not (tmp_path / MARKS).exists()  # the schema is its own mark
    assert main(["schema", "--out", str(scenario), "--force"]) == 0
    assert json.loads(scenario.read_text())["title"] == "sandbox scenario"


@pytest.fixture
def run_dir(tmp_path: Path, scenario: Path) -> Path:
    out = tmp_path / "run"
    assert main(["run", str(scenario), "--out", str(out)]) == 0
    return out


@pytest.mark.slow
def test_plot_never_replaces_a_users_figure(
    tmp_path: Path, run_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    figs = tmp_path / "figs"
    figs.mkdir()
    (figs / "trajectories.png").write_bytes(b"my own figure")
    capsys.readouterr()
    assert main(["plot", str(run_dir), "--out", str(figs)]) == 2
    line = one_line(capsys.readouterr().err)
    assert f"{figs / 'trajectories.png'}: exists and is not an earlier output" in line
    assert sorted(p.name for p in figs.iterdir()) == ["trajectories.png"]
    assert (figs / "trajectories.png").read_bytes() == b"my own figure"
    # into the run directory's figures/: twice (the second replaces the first)
    assert main(["plot", str(run_dir)]) == 0
    assert main(["plot", str(run_dir)]) == 0
    assert (run_dir / "figures" / "commands.png").read_bytes()[:4] == b"\x89PNG"
    # a figure edited by hand since is the user's
    (run_dir / "figures" / "commands.png").write_bytes(b"annotated")
    assert main(["plot", str(run_dir)]) == 2
    assert (run_dir / "figures" / "commands.png").read_bytes() == b"annotated"
    assert main(["plot", str(run_dir), "--out", str(figs), "--force"]) == 0
    assert (figs / "trajectories.png").read_bytes()[:4] == b"\x89PNG"


def test_sweep_plot_never_replaces_a_users_figure(
    tmp_path: Path, scenario: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    study = tmp_path / "study"
    argv = ["sweep", str(scenario), "--grid", "duration=0.3,0.5", "--out", str(study)]
    assert main(argv) == 0
    figs = tmp_path / "figs"
    assert main(["sweep", "plot", str(study), "--out", str(figs)]) == 0
    names = sorted(p.name for p in figs.iterdir() if p.name != MARKS)
    assert names and all(n.endswith(".png") for n in names)
    assert main(["sweep", "plot", str(study), "--out", str(figs)]) == 0  # again
    (figs / names[0]).write_bytes(b"mine")
    capsys.readouterr()
    assert main(["sweep", "plot", str(study), "--out", str(figs)]) == 2
    assert "is not an earlier output of sandbox sweep plot" in one_line(
        capsys.readouterr().err
    )
    assert (figs / names[0]).read_bytes() == b"mine"
    assert main(["sweep", "plot", str(study), "--out", str(figs), "--force"]) == 0
    assert (figs / names[0]).read_bytes()[:4] == b"\x89PNG"


def test_gallery_refuses_before_it_runs_anything(
    tmp_path: Path, scenario: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "mine"
    folder.mkdir()
    scenario.rename(folder / "headon.yaml")
    renders = tmp_path / "renders"
    renders.mkdir()
    (renders / "headon.gif").write_bytes(b"my own animation")
    assert main(["gallery", str(folder), "--out", str(renders)]) == 2
    assert "renders/headon.gif: exists and is not an earlier output" in one_line(
        capsys.readouterr().err
    )
    assert sorted(p.name for p in renders.iterdir()) == ["headon.gif"]
    (renders / "headon.gif").unlink()
    assert main(["gallery", str(folder), "--out", str(renders)]) == 0
    out = capsys.readouterr().out
    assert f"{renders / 'headon.gif'}:" in out and ".sandbox-stage" not in out
    assert (renders / "headon.gif").read_bytes()[:6] == b"GIF89a"
    assert main(["gallery", str(folder), "--out", str(renders)]) == 0  # its own


def test_pytest_gifs_never_replace_a_users_file(tmp_path: Path) -> None:
    """``pytest --sandbox-gifs DIR`` refuses a name taken by something not a GIF."""
    from sandbox.testing.pytest_plugin import _write_gifs

    class Item:
        nodeid = "test_x.py::test_y"
        stash = {}

    from sandbox import simulate
    from sandbox.scenario import load_scenario
    from sandbox.testing.pytest_plugin import RUNS_KEY

    item = Item()
    item.stash = {RUNS_KEY: [simulate(load_scenario(write_yaml(tmp_path, HEADON)))]}
    gif = tmp_path / "test_x.py_test_y.gif"
    gif.write_text("my notes")
    (line,) = _write_gifs(item, tmp_path)
    assert "not written" in line and "is not a GIF" in line
    assert gif.read_text() == "my notes"


# ------------------------------------------------------------------ the scan
#: Calls that write a file a user may name.
WRITERS = {
    "write_gif",
    "write_mp4",
    "write_csv",
    "write_json",
    "write_parquet",
    "write_text_atomic",
    "plot_run",
    "plot_sweep",
    "render_gallery",
    "save_figure",
    "savefig",
    "write_text",
    "write_bytes",
    "copyfile",
    "copy2",
    "copytree",
    "save",
    "savez",
    "savez_compressed",
}
#: Writers only as functions of these modules (``os.replace``, not ``str.replace``).
MODULE_WRITERS = {"os": {"replace", "rename", "link", "symlink"}, "shutil": {"move"}}
#: Calls that check with the guard before writing, or write through it.
GUARDS = {
    "check_target",
    "check_targets",
    "staged",
    "write_output",
    "check_mp4",  # --gif and --mp4: check_target
    "check_out_dir",  # run directories: their manifest
    "check_output",  # replay pages: check_target
}


def unguarded_writes(source: str, name: str = "<module>") -> list[str]:
    """``module:line function: call`` of each write without a guard.

    A function may write when it, or every function of the module that calls it,
    calls a guard. ``open(..., "w")`` (any mode but reading) counts as a write.
    """
    tree = ast.parse(source)
    calls: dict[str, set[str]] = {}
    writes: list[tuple[str, int, str]] = []
    for fn in ast.walk(tree):
        if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        called = calls.setdefault(fn.name, set())
        for node in ast.walk(fn):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            callee = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            called.add(callee)
            mode = ""
            if callee == "open":
                modes = [a for a in node.args[1:2] if isinstance(a, ast.Constant)]
                modes += [
                    k.value
                    for k in node.keywords
                    if k.arg == "mode" and isinstance(k.value, ast.Constant)
                ]
                mode = str(modes[0].value) if modes else "r"
            owner = getattr(getattr(f, "value", None), "id", "")
            if (
                callee in WRITERS
                or callee in MODULE_WRITERS.get(owner, ())
                or (callee == "open" and set(mode) & set("wxa+"))
            ):
                writes.append((fn.name, node.lineno, callee))
    bad = []
    for fn_name, line, callee in writes:
        if calls[fn_name] & GUARDS:
            continue
        callers = [f for f, c in calls.items() if fn_name in c and f != fn_name]
        if callers and all(calls[f] & GUARDS for f in callers):
            continue
        bad.append(f"{name}:{line} {fn_name}: {callee}")
    return bad


def test_every_command_writes_through_the_guard() -> None:
    found = []
    for path in sorted((PACKAGE / "cli").glob("*.py")):
        found += unguarded_writes(path.read_text(encoding="utf-8"), path.name)
    assert found == []


def test_the_scan_finds_a_command_that_forgets_the_guard() -> None:
    new = """
def cmd_export(args):
    Path(args.out).write_text(make())

def cmd_dump(args):
    with open(args.out, "w") as fh:
        fh.write("x")

def cmd_move(args):
    os.replace(args.src, args.out)
    args.name.replace("a", "b")

def cmd_checked(args):
    check_target(args.out, "export")
    Path(args.out).write_text(make())

def helper(run, out):
    write_gif(run, out)

def cmd_gif(args):
    check_mp4(args)
    helper(None, args.gif)
"""
    assert unguarded_writes(new, "new.py") == [
        "new.py:3 cmd_export: write_text",
        "new.py:6 cmd_dump: open",
        "new.py:10 cmd_move: replace",
    ]
