"""The Python API for analysis: ``sandbox.load_run``, ``run.vehicle(name)``,
``run.to_dataframe()`` and ``trajectory.parquet`` (``sandbox run --format parquet``).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from helpers import PAPER

import sandbox
from sandbox.cli import main
from sandbox.run.analysis import COLUMNS
from sandbox.run.record import MODE_NAMES


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("analysis") / "follower_stop"
    args = ["run", "failures/follower_stop", "--duration", "4", "--out", str(out)]
    assert main(args) == 0
    return out


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


def test_load_run_is_exported_and_reads_a_run_directory(run_dir: Path) -> None:
    assert "load_run" in sandbox.__all__
    run = sandbox.load_run(run_dir)
    assert isinstance(run, sandbox.Run)
    assert run.scenario is not None and run.scenario.name == "follower_stop"
    assert len(run.t) == len(read_csv(run_dir / "trajectory.csv")) // run.n_vehicles


def test_vehicle_returns_that_vehicles_arrays(run_dir: Path) -> None:
    run = sandbox.load_run(run_dir)
    i = run.names.index("red")
    red = run.vehicle("red")
    assert (red.name, red.index, red.color) == ("red", i, run.colors[i])
    np.testing.assert_array_equal(red.pose, run.pose[:, i])
    np.testing.assert_array_equal(red.x2, run.pose[:, i, 1])
    np.testing.assert_array_equal(red.v1, run.cmd[:, i, 0])
    np.testing.assert_array_equal(red.failed, run.failed[:, i])
    np.testing.assert_array_equal(red.formation_error, run.formation_error[:, i])
    assert red.failed.any() and not red.failed[0]  # red's motors stop at t = 3 s
    assert run.vehicle(run.names[run.leader]).leader


def test_an_unknown_vehicle_names_the_ones_there_are(run_dir: Path) -> None:
    run = sandbox.load_run(run_dir)
    with pytest.raises(KeyError, match="no vehicle named 'purple'.*red"):
        run.vehicle("purple")


def test_to_dataframe_is_the_csv_in_long_format(run_dir: Path) -> None:
    pd = pytest.importorskip("pandas")
    run = sandbox.load_run(run_dir)
    df = run.to_dataframe()
    assert tuple(df.columns) == COLUMNS
    assert len(df) == len(run.t) * run.n_vehicles
    assert list(df.vehicle.cat.categories) == run.names
    csv_df = pd.read_csv(run_dir / "trajectory.csv")
    assert list(csv_df.columns) == list(df.columns)
    for c in ("t", "x1", "x2", "x3", "v1", "v2", "chi1", "chi2"):
        np.testing.assert_allclose(df[c], csv_df[c], rtol=1e-8, atol=1e-6)
    assert (df.vehicle.astype(str) == csv_df.vehicle).all()
    assert (df["mode"].astype(str) == csv_df["mode"]).all()
    assert (df.failed == csv_df.failed.astype(bool)).all()
    red = df[df.vehicle == "red"]
    np.testing.assert_array_equal(red.x1, run.vehicle("red").x1)


def test_parquet_holds_the_same_table_and_is_deterministic(
    run_dir: Path, tmp_path: Path
) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    pytest.importorskip("pandas")
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        args = ["run", "failures/follower_stop", "--duration", "4", "--out", str(out)]
        assert main([*args, "--format", "parquet"]) == 0
    files = sorted(p.name for p in outs[0].iterdir())
    assert files == [
        "manifest.json",
        "metrics.json",
        "run.npz",
        "scenario.yaml",
        "trajectory.parquet",
    ]
    data = [(o / "trajectory.parquet").read_bytes() for o in outs]
    assert data[0] == data[1]
    table = pq.read_table(outs[0] / "trajectory.parquet").to_pandas()
    expected = sandbox.load_run(run_dir).to_dataframe()
    assert tuple(table.columns) == COLUMNS
    for c in COLUMNS:
        if c in ("vehicle", "mode"):
            assert (table[c].astype(str) == expected[c].astype(str)).all()
        else:
            np.testing.assert_array_equal(table[c], expected[c])
    assert set(table["mode"].astype(str)) <= set(MODE_NAMES)


def test_parquet_in_several_row_groups(tmp_path: Path, monkeypatch) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    from sandbox.run import analysis

    run = sandbox.simulate(
        sandbox.load_scenario(PAPER / "rotating_circle.yaml", ["duration=1"])
    )
    monkeypatch.setattr(analysis, "PARQUET_GROUP_ROWS", 30)  # 10 samples per group
    analysis.write_parquet(run, tmp_path / "t.parquet")
    f = pq.ParquetFile(tmp_path / "t.parquet")
    assert f.metadata.num_row_groups == -(-len(run.t) // 10)
    np.testing.assert_array_equal(
        f.read().column("x1").to_numpy(), run.pose[:, :, 0].ravel()
    )


def test_without_the_extra_the_message_says_what_to_install(
    run_dir: Path, monkeypatch, capsys
) -> None:
    import builtins

    real = builtins.__import__

    def no_pyarrow(name, *args, **kwargs):
        if name.split(".")[0] in ("pyarrow", "pandas"):
            raise ImportError(f"No module named {name!r}")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_pyarrow)
    monkeypatch.setattr("importlib.import_module", _failing(no_pyarrow))
    out = run_dir.parent / "no_extra"
    assert main(
        ["run", "paper/rotating_circle", "--format", "parquet", "--out", str(out)]
    )
    err = capsys.readouterr().err.strip()
    assert err == (
        "error: --format parquet needs pyarrow, which is not installed: "
        "pip install 'platoon-sandbox[analysis]'"
    )
    assert not out.exists()  # refused before simulating
    with pytest.raises(
        sandbox.SandboxError, match=r"pip install 'platoon-sandbox\[analysis\]'"
    ):
        sandbox.load_run(run_dir).to_dataframe()


def _failing(hook):
    import importlib

    real = importlib.import_module

    def import_module(name, package=None):
        hook(name)
        return real(name, package)

    return import_module
