"""A hostile corpus for sweeps and their stores: what an attacker could hand us.

Sweep files (encodings, numbers, YAML structure, sizes) go through ``sandbox sweep``
and ``sandbox validate``; damaged or planted stores through ``sandbox sweep`` and
``sandbox sweep table``. Every case ends with its exit status and one-line messages
naming the user's file, never a traceback, and nothing written outside the store.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers import write_yaml
from test_sweep import base_doc

from sandbox.cli import main

BASE = "base: base.yaml\n"

#: id -> (sweep file content, text expected in the one line of stderr)
FILES: dict[str, tuple[bytes | str, str]] = {
    # ---- encodings
    "utf16": ((BASE + "seeds: 0:2\n").encode("utf-16"), "not UTF-8 text"),
    "latin1": (BASE.encode() + b"set: {name: caf\xe9}\n", "not UTF-8 text"),
    "nul_byte": (BASE.encode() + b"\x00\n", "not text"),
    # ---- numbers
    "million_digit_seed": (BASE + "seeds: " + "9" * 100_000 + "\n", "too large"),
    "seed_range_of_floats": (BASE + "seeds: 0.5:2\n", "not a seed range"),
    "negative_seeds": (BASE + "seeds: -5:2\n", "empty or negative range"),
    "huge_seed_range": (BASE + "seeds: 0:99999999999999999999\n", "at most 100,000"),
    "inf_grid_value": (BASE + "grid: {recovery.beta: [.inf]}\n", "not a number"),
    # ---- structure
    "list_at_top": ("- base.yaml\n", "not a mapping"),
    "grid_a_list": (BASE + "grid: [1, 2]\n", "grid: expected a mapping"),
    "grid_values_a_mapping": (BASE + "grid: {recovery.beta: {a: 1}}\n", "non-empty"),
    "empty_grid_values": (BASE + "grid: {recovery.beta: []}\n", "non-empty list"),
    "unknown_key": (BASE + "grids: {}\n", "unknown key of a sweep file"),
    "python_tag": (BASE + "set: !!python/object/apply:os.system [ls]\n", "tag"),
    "two_documents": (BASE + "---\n" + BASE, "one document"),
    "deep_nesting": (BASE + "set: {x: " + "[" * 5000 + "]" * 5000 + "}\n", ""),
    "recursive_alias": (BASE + "set: &a {x: *a}\n", "aliases expand too far"),
    "billion_laughs": (
        BASE
        + "a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
        + "".join(
            f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 10)}]\n" for k in range(1, 9)
        )
        + "set: {description: *a8}\n",
        "aliases expand too far",
    ),
    "base_is_missing": ("base: nowhere.yaml\n", "no such scenario file"),
    "base_is_a_directory": ("base: .\n", "no such scenario file"),
    "base_is_dev_zero": ("base: /dev/zero\n", "no such scenario file"),
    "bad_grid_path": (BASE + "grid: {'recovery..beta': [1]}\n", "names no field"),
    "path_injection": (BASE + "grid: {'a=1 --set b': [1]}\n", "names no field"),
    "repeated_values": (BASE + "grid: {recovery.beta: [1, 1.0]}\n", "same value"),
    # ---- sizes
    "five_megabytes": (BASE + "#" * 5_000_000 + "\n", "larger than 4 MB"),
    "billion_points": (
        BASE
        + "grid:\n"
        + "".join(f"  vehicles[{k}].pose: {list(range(10))}\n" for k in range(3))
        + "".join(
            f"  {p}: {list(range(1, 11))}\n"
            for p in ("recovery.beta", "recovery.R", "duration", "dt", "vehicle.v1_max")
        )
        + "  vehicle.v2_max: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]\n",
        "1,000,000,000 runs",
    ),
}


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    write_yaml(tmp_path, base_doc(duration=0.2), "base.yaml")
    return tmp_path


def write(path: Path, content: bytes | str) -> None:
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8", newline="")
    else:
        path.write_bytes(content)


@pytest.mark.parametrize("command", ["sweep", "validate"])
@pytest.mark.parametrize("case", list(FILES))
def test_a_hostile_sweep_file_is_one_line(folder, capsys, case, command):
    content, text = FILES[case]
    study = folder / f"{case}.yaml"
    write(study, content)
    args = [command, str(study)]
    if command == "sweep":
        args += ["--out", str(folder / "out")]
    before = sorted(folder.iterdir())
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln and not ln.startswith("warning: ")]
    assert lines, err
    if case not in ("list_at_top", "deep_nesting"):  # read as a scenario: its lines
        assert len(lines) == 1, lines
    for line in lines:
        assert str(study) in line or "--set" in line, line
        assert len(line) < 2000
    assert text in err
    assert sorted(folder.iterdir()) == before  # nothing written


# --------------------------------------------------------------------------- stores
def plant(kind: str, out: Path) -> tuple[list[str], int, str]:
    """Damage the store ``out``; the command's extra arguments, status and text."""
    runs = out / "runs"
    first = sorted(runs.glob("*.json"))[0]
    if kind == "run_file_is_a_fifo":
        first.unlink()
        os.mkfifo(first)
        return [], 0, f"{first}: not a regular file; computed again"
    if kind == "run_file_links_to_dev_zero":
        first.unlink()
        first.symlink_to("/dev/zero")
        return [], 0, f"{first}: not a regular file; computed again"
    if kind == "run_file_is_a_directory":
        first.unlink()
        first.mkdir()
        return [], 1, f"{first}: cannot write"
    if kind == "run_file_is_huge":
        with open(first, "wb") as fh:
            fh.truncate(100_000_000)  # sparse: 100 MB of zeros, never read
        return [], 0, f"{first}: larger than 64,000,000 bytes; computed again"
    if kind == "runs_is_a_file":
        for p in runs.iterdir():
            p.unlink()
        runs.rmdir()
        runs.write_text("mine", encoding="utf-8")
        return [], 1, f"{runs}: cannot create"
    if kind == "sweep_json_is_a_directory":
        (out / "sweep.json").unlink()
        (out / "sweep.json").mkdir()
        return [], 2, "sweep.json"
    if kind == "sweep_json_is_huge":
        with open(out / "sweep.json", "wb") as fh:
            fh.truncate(50_000_000)
        return [], 2, f"{out / 'sweep.json'}: cannot read (larger than"
    if kind == "results_csv_is_a_directory":
        (out / "results.csv").unlink()
        (out / "results.csv").mkdir()
        return [], 1, f"{out / 'results.csv'}: cannot write"
    if kind == "lock_is_a_symlink":
        victim = out.parent / "victim.txt"
        victim.write_text("precious", encoding="utf-8")
        (out / ".lock").unlink()
        (out / ".lock").symlink_to(victim)
        return [], 1, f"{out / '.lock'}: cannot write"
    if kind == "temporary_is_a_planted_symlink":
        victim = out.parent / "victim.txt"
        victim.write_text("precious", encoding="utf-8")
        # the name this process gives its temporary results.csv
        (out / f".results.csv.{os.getpid()}.tmp").symlink_to(victim)
        return [], 0, ""
    if kind == "stray_temporary_files":
        (runs / ".x.json.1.tmp").write_text("half", encoding="utf-8")
        return [], 0, ""
    raise AssertionError(kind)


STORES = [
    "run_file_is_a_fifo",
    "run_file_links_to_dev_zero",
    "run_file_is_a_directory",
    "run_file_is_huge",
    "runs_is_a_file",
    "sweep_json_is_a_directory",
    "sweep_json_is_huge",
    "results_csv_is_a_directory",
    "lock_is_a_symlink",
    "temporary_is_a_planted_symlink",
    "stray_temporary_files",
]


@pytest.mark.parametrize("kind", STORES)
def test_a_hostile_store_is_one_line(folder, capsys, kind):
    out = folder / "out"
    cmd = ["sweep", str(folder / "base.yaml"), "--seeds", "0:2", "--out", str(out)]
    assert main(cmd) == 0
    capsys.readouterr()
    extra, status, text = plant(kind, out)
    assert main([*cmd, *extra]) == status
    err = capsys.readouterr().err
    assert "Traceback" not in err and text in err, err
    lines = [ln for ln in err.splitlines() if ln]
    # at most the warning about the file found and the error writing it
    assert len(lines) <= (2 if kind == "run_file_is_a_directory" else 1), lines
    assert all(".tmp" not in ln for ln in lines), lines
    victim = folder / "victim.txt"
    assert not victim.exists() or victim.read_text() == "precious"


@pytest.mark.parametrize(
    ("kind", "text"),
    [
        ("sweep_json_is_a_directory", "sweep.json: cannot read"),
        ("results_csv_is_a_directory", "results.csv: does not match the run files"),
        ("run_file_is_a_fifo", "not a readable run file; left out"),
    ],
)
def test_sweep_table_of_a_hostile_store_is_one_line(folder, capsys, kind, text):
    out = folder / "out"
    cmd = ["sweep", str(folder / "base.yaml"), "--seeds", "0:2", "--out", str(out)]
    assert main(cmd) == 0
    plant(kind, out)
    capsys.readouterr()
    status = main(["sweep", "table", str(out)])
    err = capsys.readouterr().err
    assert "Traceback" not in err and text in err, err
    assert status in (0, 1)
