"""Sizes and shapes a sweep refuses before it runs: counts, files, repeated values.

Each case is one line naming the file or option, exit status 2, and nothing written.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import REPO, write_yaml
from test_sweep import base_doc, read_csv, sweep_file

from sandbox.cli import main
from sandbox.study.spec import build_spec


@pytest.fixture
def base(tmp_path: Path) -> Path:
    return write_yaml(tmp_path, base_doc(duration=0.5), "base.yaml")


def one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# ------------------------------------------------------------------ N2: run count
@pytest.mark.parametrize("dry", [[], ["--dry-run"]])
def test_a_trillion_seeds_are_refused_by_arithmetic(tmp_path, base, capsys, dry):
    out = tmp_path / "out"
    start = time.perf_counter()
    cmd = ["sweep", str(base), "--seeds", "0:1000000000000", "--out", str(out), *dry]
    assert main(cmd) == 2
    assert time.perf_counter() - start < 2  # counted, not built (was 5.8 GB)
    line = one_line(capsys)
    assert "1,000,000,000,000 runs (1 grid point x 1,000,000,000,000 seeds)" in line
    assert "at most 100,000" in line and str(base) in line
    assert not out.exists()


def test_a_billion_point_grid_is_refused_by_arithmetic(tmp_path, base, capsys):
    paths = ["recovery.beta", "recovery.steepness", "duration", "dt"]
    paths += [f"vehicle.{p}" for p in ("v1_max", "v2_max", "max_accel")]
    paths += [f"vehicles[{k}].offset" for k in (1, 2)]
    grid = {p: [1 + k for k in range(10)] for p in paths}  # 10^9 points
    study = sweep_file(tmp_path, base, grid=grid)
    assert build_spec(study).count() == 10**9
    start = time.perf_counter()
    assert main(["sweep", str(study), "--out", str(tmp_path / "o")]) == 2
    assert main(["validate", str(study)]) == 2
    assert time.perf_counter() - start < 5
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all("1,000,000,000 runs" in ln for ln in err), err


def test_max_runs_raises_and_lowers_the_bound(tmp_path, base, capsys):
    cmd = ["sweep", str(base), "--seeds", "0:3", "--out", str(tmp_path / "o")]
    assert main([*cmd, "--max-runs", "2"]) == 2
    assert "3 runs (1 grid point x 3 seeds); at most 2" in one_line(capsys)
    assert main([*cmd, "--max-runs", "3"]) == 0


def test_ctrl_c_while_a_large_sweep_is_prepared(tmp_path, base):
    # 4 x 10^7 runs allowed by --max-runs: preparing them (checking the grid points,
    # looking for stored runs) takes minutes; SIGINT must end it at once.
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "sandbox", "sweep", str(base), "--out", str(out)]
    cmd += ["--grid", "recovery.beta=" + ",".join(str(1 + k) for k in range(4))]
    cmd += ["--seeds", "0:10000000", "--max-runs", "100000000"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, env=env, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and not (out / "sweep.json").exists():
            time.sleep(0.05)
        assert (out / "sweep.json").exists()
        time.sleep(0.5)  # under way: counting the stored runs
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=10)
        assert time.monotonic() - sent < 2, "Ctrl-C took too long"
        assert proc.returncode == 130 and "Traceback" not in err, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


# ------------------------------------------------------------------ N3: sweep files
def test_sweep_of_dev_zero_is_refused(tmp_path, capsys):
    assert main(["sweep", "/dev/zero", "--out", str(tmp_path / "o")]) == 2
    line = one_line(capsys)
    assert "/dev/zero" in line and "not a regular file" in line


def laughs(base: Path) -> str:
    rows = [f"base: {base.name}", "a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    for k in range(1, 9):
        rows.append(f"a{k}: &a{k} [" + ", ".join([f"*a{k - 1}"] * 10) + "]")
    return "\n".join(rows)


@pytest.mark.parametrize(
    "tail",
    [
        "set: {description: *a8}",  # 10^9 values written out as one --set
        "grid: {recovery.beta: [*a8, *a7]}",
        "zip: {recovery.beta: [*a8], recovery.R: [*a8]}",
    ],
)
@pytest.mark.parametrize("command", ["sweep", "validate"])
def test_an_alias_bomb_is_refused_at_once(tmp_path, base, capsys, tail, command):
    study = tmp_path / "bomb.yaml"
    study.write_text(laughs(base) + "\n" + tail + "\n", encoding="utf-8")
    args = [command, str(study)]
    if command == "sweep":
        args += ["--out", str(tmp_path / "o")]
    start = time.perf_counter()
    assert main(args) == 2
    assert time.perf_counter() - start < 5  # was over 60 s
    line = one_line(capsys)
    assert str(study) in line and "aliases expand too far" in line


def test_a_recursive_alias_in_a_sweep_file_is_refused(tmp_path, base, capsys):
    study = tmp_path / "loop.yaml"
    study.write_text(f"base: {base.name}\nset: &a [*a]\n", encoding="utf-8")
    assert main(["sweep", str(study), "--out", str(tmp_path / "o")]) == 2
    assert "aliases expand too far" in one_line(capsys)


def test_a_large_sweep_file_is_refused_like_a_scenario(tmp_path, base, capsys):
    study = tmp_path / "big.yaml"
    study.write_text(f"base: {base.name}\n" + "#" * 5_000_000 + "\n")
    assert main(["sweep", str(study), "--out", str(tmp_path / "o")]) == 2
    assert "larger than 4 MB" in one_line(capsys)


# ------------------------------------------------------------------ N5: repeats
@pytest.mark.parametrize(
    ("grid", "text"),
    [
        ("recovery.beta=2,2", "2 is again"),
        ("recovery.beta=1,01", "01 is the same value as 1"),
        ("recovery.beta=1,1.0", "1.0 is the same value as 1"),
        ("recovery.beta=1e0,1", "1 is the same value as 1e0"),
        ("vehicles[1].offset=[-2, 1],[-2.0, 1.0]", "is the same value as [-2, 1]"),
    ],
)
def test_a_repeated_grid_value_is_refused(tmp_path, base, capsys, grid, text):
    out = tmp_path / "o"
    assert main(["sweep", str(base), "--grid", grid, "--out", str(out)]) == 2
    line = one_line(capsys)
    assert line.startswith(f"error: --grid {grid}: ") and text in line
    assert not out.exists()


def test_a_repeated_value_of_a_sweep_file_is_refused(tmp_path, base, capsys):
    study = sweep_file(tmp_path, base, grid={"recovery.beta": [1, 2, 1.0]})
    assert main(["sweep", str(study), "--out", str(tmp_path / "o")]) == 2
    line = one_line(capsys)
    assert f"{study}: grid.recovery.beta: 1.0 is the same value as 1" in line
    assert main(["validate", str(study)]) == 2
    assert "grid.recovery.beta" in one_line(capsys)


def test_a_repeated_zip_entry_is_refused_and_a_zip_column_may_repeat(
    tmp_path, base, capsys
):
    zipped = {
        "vehicles[1].offset": [[-2, 1], [-1, 1], [-2, 1]],
        "vehicles[2].offset": [[-2, -1], [-1, -1], [-2.0, -1]],
    }
    study = sweep_file(tmp_path, base, zip=zipped)
    assert main(["sweep", str(study), "--out", str(tmp_path / "o")]) == 2
    assert f"{study}: zip: entries 1 and 3 are the same values" in one_line(capsys)
    zipped["vehicles[2].offset"][2] = [-3, -1]  # column 1 repeats, the entries differ
    study = sweep_file(tmp_path, base, zip=zipped)
    assert main(["sweep", str(study), "--out", str(tmp_path / "o")]) == 0
    assert len(read_csv(tmp_path / "o" / "results.csv")) == 3


def test_distinct_values_are_kept_as_written(tmp_path, base):
    # true is not 1, "a" is not a; the rows show the values as written
    out = tmp_path / "o"
    cmd = ["sweep", str(base), "--grid", "recovery.beta=1,1.5,2e0", "--out", str(out)]
    assert main(cmd) == 0
    assert [r["recovery.beta"] for r in read_csv(out / "results.csv")] == [
        "1",
        "1.5",
        "2e0",
    ]


def test_the_default_of_max_runs_is_the_specs():
    from sandbox.cli import sweep as cli_sweep
    from sandbox.study import spec

    assert cli_sweep.MAX_RUNS == spec.MAX_RUNS == 100_000
