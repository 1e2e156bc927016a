"""Run directories never destroy a user's files, through the command line.

A run directory carries ``manifest.json`` (the product, its version, the files it
wrote). Only a directory with a valid manifest is replaced, and only the files it
lists: figures, notes and runs nested in it survive a re-run. Leftovers of killed runs
are cleaned up file by file, never as a whole tree. Two runs writing the same new
directory at once both succeed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from sandbox import __version__
from sandbox.cli import main
from sandbox.run.output import MANIFEST, read_manifest

SCENARIO = {
    "name": "tiny",
    "duration": 0.2,
    "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "leader", "pose": [5, 0, 1.5708], "leader": True},
        {"name": "red", "pose": [4, -1, 1.5708], "offset": [-1, 1]},
    ],
}
PRODUCT = [
    "manifest.json",
    "metrics.json",
    "run.npz",
    "scenario.yaml",
    "trajectory.csv",
]


@pytest.fixture
def src(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(json.dumps(SCENARIO), encoding="utf-8")
    return path


def tree(root: Path) -> dict[str, bytes | None]:
    """Every path under ``root`` with its bytes (None for directories)."""
    return {
        str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes())
        for p in sorted(root.rglob("*"))
    }


def run_cli(src: Path, out: Path, *extra: str) -> int:
    return main(["run", str(src), "--out", str(out), *extra])


def test_the_issue_case_a_fake_run_is_refused_and_nothing_is_deleted(
    src: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = tmp_path / "d"
    (d / "sub").mkdir(parents=True)
    (d / "metrics.json").write_text("{}\n", encoding="utf-8")
    (d / "thesis.tex").write_text("x\n", encoding="utf-8")
    before = tree(d)
    assert run_cli(src, d) == 1
    err = capsys.readouterr().err
    assert f"{d}: exists and is not a run directory (no valid manifest.json)" in err
    assert tree(d) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d", "tiny.yaml"]


@pytest.mark.parametrize(
    "manifest",
    [
        {"product": "other", "files": ["run.npz"]},
        {"product": "sandbox", "files": ["thesis.tex"]},
        {"product": "sandbox", "files": ["../x"]},
        {"product": "sandbox"},
        ["sandbox"],
        "not json",
    ],
)
def test_a_crafted_manifest_does_not_make_a_run_directory(
    manifest: object, src: Path, tmp_path: Path
) -> None:
    d = tmp_path / "d"
    d.mkdir()
    text = manifest if isinstance(manifest, str) else json.dumps(manifest)
    (d / MANIFEST).write_text(text, encoding="utf-8")
    (d / "thesis.tex").write_text("x\n", encoding="utf-8")
    before = tree(d)
    assert run_cli(src, d) == 1
    assert tree(d) == before


def test_the_manifest_lists_the_files_and_the_version(
    src: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    assert run_cli(src, out) == 0
    doc = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
    assert doc["product"] == "sandbox" and doc["version"] == __version__
    assert doc["files"] == [f for f in PRODUCT if f != MANIFEST]
    assert read_manifest(out) == set(PRODUCT)
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert next(iter(metrics)) == "version" and metrics["version"] == __version__


@pytest.mark.slow
def test_a_rerun_keeps_figures_notes_and_nested_runs(src: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert run_cli(src, out) == 0
    assert main(["plot", str(out)]) == 0
    figures = tree(out / "figures")
    assert figures, "sandbox plot wrote nothing into DIR/figures/"
    (out / "notes.md").write_text("what I saw\n", encoding="utf-8")
    assert run_cli(src, out / "nested") == 0
    nested = tree(out / "nested")
    assert run_cli(src, out, "--duration", "0.1") == 0
    assert tree(out / "figures") == figures
    assert (out / "notes.md").read_text(encoding="utf-8") == "what I saw\n"
    assert tree(out / "nested") == nested
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["duration"] == pytest.approx(0.1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "tiny.yaml"]


def test_an_unlisted_file_with_a_product_name_is_refused_by_name(
    src: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert run_cli(src, out) == 0
    (out / "trajectory.parquet").write_bytes(b"the user's own")
    before = tree(out)
    assert run_cli(src, out) == 1
    assert "holds trajectory.parquet, which the run would write" in (
        capsys.readouterr().err
    )
    assert tree(out) == before


def dead_pid() -> int:
    done = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(done.stdout)


def test_leftover_cleanup_deletes_only_product_files_and_restores_the_rest(
    src: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    assert run_cli(src, out) == 0
    pid = dead_pid()
    # Killed after the swap, while carrying the user's file back.
    caught = tmp_path / f".out.tmp-{pid}-a1"
    caught.mkdir()
    (caught / "run.npz").write_bytes(b"old run")
    (caught / "notes.md").write_text("mine\n", encoding="utf-8")
    # A look-alike that holds a directory named like a product file: not ours.
    odd = tmp_path / f".out.old-{pid}-b2"
    (odd / "run.npz").mkdir(parents=True)
    (odd / "run.npz" / "data").write_text("unknown\n", encoding="utf-8")
    odd_before = tree(odd)
    assert run_cli(src, out) == 0
    assert not caught.exists()
    assert (out / "notes.md").read_text(encoding="utf-8") == "mine\n"
    assert tree(odd) == odd_before


def test_an_old_run_left_between_the_two_renames_is_put_back(
    src: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    assert run_cli(src, out) == 0
    (out / "notes.md").write_text("mine\n", encoding="utf-8")
    moved = tmp_path / f".out.old-{dead_pid()}-c3"
    os.replace(out, moved)  # as a run killed between the fallback's renames leaves it
    assert run_cli(src, out) == 0
    assert not moved.exists()
    assert (out / "notes.md").read_text(encoding="utf-8") == "mine\n"
    assert read_manifest(out) == set(PRODUCT)


@pytest.mark.slow
def test_two_processes_creating_the_same_new_directory_both_succeed(
    src: Path, tmp_path: Path
) -> None:
    """Both runs write the same new --out at once; the lock serialises the swaps."""
    # Each process holds its final rename into --out for a while, so that without
    # the lock both find --out missing and the second rename meets a full directory.
    code = (
        "import os, sys, time\n"
        "from pathlib import Path\n"
        "from sandbox.cli import main\n"
        "real = os.replace\n"
        "def slow(src, dst):\n"
        "    if Path(dst) == Path(sys.argv[2]):\n"
        "        time.sleep(float(sys.argv[3]))\n"
        "    real(src, dst)\n"
        "os.replace = slow\n"
        "sys.exit(main(['run', sys.argv[1], '--out', sys.argv[2]]))\n"
    )
    for attempt in range(1):
        out = tmp_path / f"new{attempt}" / "out"
        procs = [
            subprocess.Popen(
                [sys.executable, "-c", code, str(src), str(out), delay],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            for delay in ("1.0", "1.0")
        ]
        results = [p.communicate(timeout=120) for p in procs]
        for p, (_, err) in zip(procs, results, strict=True):
            assert p.returncode == 0, err
        assert read_manifest(out) == set(PRODUCT)
        assert sorted(p.name for p in out.parent.iterdir()) == ["out"]
