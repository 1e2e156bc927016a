"""``sandbox sweep``: grids, zips, seeds, the results store, resuming, reproduction."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from helpers import REPO, write_yaml

import sandbox
from sandbox.cli import main
from sandbox.study import engine, groups
from sandbox.study.spec import build_spec, split_values
from sandbox.study.summary import wilson

POSE = {"uniform": [[-3, -3, -3.14159], [3, 3, 3.14159]]}


def base_doc(duration: float = 1.0) -> dict:
    return {
        "name": "tiny_formup",
        "duration": duration,
        "seed": 0,
        "vehicle": {"v1_max": 2.0, "max_accel": 5.0, "v2_max": 8.0},
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1},
        "formation": {"law": "rotating"},
        "recovery": {"strategy": "discontinuous", "beta": 1.0, "R": "3d"},
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [1, 1, 0], "offset": [-2, 1]},
            {"name": "green", "pose": [1, -1, 0], "offset": [-2, -1]},
        ],
        "randomize": {"vehicles[1].pose": POSE, "vehicles[2].pose": POSE},
    }


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


def sweep_file(tmp_path: Path, base: Path, name: str = "study.yaml", **doc) -> Path:
    text = {"base": base.name, **doc}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(text, sort_keys=False), encoding="utf-8")
    return path


@pytest.fixture
def base(tmp_path: Path) -> Path:
    return write_yaml(tmp_path, base_doc(), "base.yaml")


def test_grid_zip_seeds_make_the_product_on_common_seeds(tmp_path, base, capsys):
    out = tmp_path / "out"
    args = ["sweep", str(base), "--grid", "recovery.beta=1,5"]
    args += ["--zip", "vehicles[1].offset=[-2, 1],[-1.4, 0.8]"]
    args += ["--zip", "vehicles[2].offset=[-2, -1],[-1.4, -0.8]"]
    assert main([*args, "--seeds", "0:3", "--out", str(out)]) == 0
    rows = read_csv(out / "results.csv")
    assert list(rows[0]) == [
        "run_id",
        "recovery.beta",
        "vehicles[1].offset",
        "vehicles[2].offset",
        "seed",
        "status",
        "collisions.total",
        "collisions.vehicle_vehicle",
        "collisions.healthy",
        "min_distance",
        "converged",
        "settling_time",
        "effort",
        "deadlocks",
    ]
    assert len(rows) == 2 * 2 * 3
    assert len({r["run_id"] for r in rows}) == 12
    points = {
        (r["recovery.beta"], r["vehicles[1].offset"], r["vehicles[2].offset"])
        for r in rows
    }
    assert points == {
        (b, a, c)
        for b in ("1", "5")
        for a, c in (("[-2, 1]", "[-2, -1]"), ("[-1.4, 0.8]", "[-1.4, -0.8]"))
    }
    assert all(r["status"] == "ok" for r in rows)
    assert {r["converged"] for r in rows} <= {"true", "false"}
    # Seeds 0, 1, 2 at every grid point; the random starts differ between seeds.
    assert sorted({r["seed"] for r in rows}) == ["0", "1", "2"]
    assert len(list((out / "runs").glob("*.json"))) == 12
    stored = json.loads(next((out / "runs").glob("*.json")).read_text())
    assert "vehicles" in stored["metrics"]  # per-run metrics kept


def test_every_row_is_reproduced_by_sandbox_run(tmp_path, base):
    out = tmp_path / "out"
    assert (
        main(
            [
                "sweep",
                str(base),
                "--grid",
                "recovery.strategy=none,continuous",
                "--set",
                "recovery.r=1.5d",
                "--seeds",
                "4:6",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rows = read_csv(out / "results.csv")
    assert len(rows) == 4
    for r in rows[::3]:
        run_dir = tmp_path / f"run_{r['run_id']}"
        code = main(
            [
                "run",
                str(base),
                "--set",
                "recovery.r=1.5d",
                "--set",
                f"recovery.strategy={r['recovery.strategy']}",
                "--set",
                f"seed={r['seed']}",
                "--out",
                str(run_dir),
            ]
        )
        assert code == 0
        metrics = json.loads((run_dir / "metrics.json").read_text())
        stored = json.loads((out / "runs" / f"{r['run_id']}.json").read_text())
        # the same metrics; metrics.json also names the version, as the store does
        assert metrics.pop("version") == stored["sandbox"]
        assert stored["metrics"] == metrics
        assert r["collisions.total"] == str(metrics["collisions"]["total"])
        assert r["min_distance"] == repr(metrics["min_distance"])


def test_run_ids_do_not_depend_on_key_order_or_invocation(tmp_path, base):
    a = sweep_file(
        tmp_path,
        base,
        "a.yaml",
        grid={"recovery.beta": [1, 2], "recovery.R": [1.5, 2.0]},
        seeds="0:2",
    )
    b = sweep_file(
        tmp_path,
        base,
        "b.yaml",
        seeds="0:2",
        grid={"recovery.R": [1.5, 2.0], "recovery.beta": [1, 2]},
    )
    ids_a = {t.run_id for t in build_spec(a).tasks()}
    ids_b = {t.run_id for t in build_spec(b).tasks()}
    assert ids_a == ids_b and len(ids_a) == 8
    # The same runs given on the command line.
    c = build_spec(base, grid=["recovery.beta=1,2", "recovery.R=1.5,2.0"], seeds="0:2")
    assert {t.run_id for t in c.tasks()} == ids_a


def test_rerun_computes_only_what_is_missing(tmp_path, base, capsys):
    out = tmp_path / "out"
    cmd = ["sweep", str(base), "--grid", "recovery.beta=1,2", "--out", str(out)]
    assert main([*cmd, "--seeds", "0:2"]) == 0
    first = {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.json")}
    capsys.readouterr()
    assert main([*cmd, "--seeds", "0:3"]) == 0
    assert "2 runs computed, 4 already stored" in capsys.readouterr().out
    after = {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.json")}
    assert len(after) == 6 and all(after[k] == v for k, v in first.items())
    assert main([*cmd, "--seeds", "0:3"]) == 0
    assert "all 6 runs already done; nothing to compute" in capsys.readouterr().out
    assert len(read_csv(out / "results.csv")) == 6


def test_interrupted_sweep_resumes(tmp_path, base, monkeypatch, capsys):
    out = tmp_path / "out"
    cmd = ["sweep", str(base), "--seeds", "0:5", "--out", str(out)]
    real, calls = engine.run_tasks, []

    def flaky(*jobs, **kw):  # Ctrl-C while the second batch of runs is computed
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*jobs, **kw)

    monkeypatch.setattr(groups, "BATCH_WORLDS", 2)
    monkeypatch.setattr(engine, "run_tasks", flaky)
    assert main(cmd) == 130
    assert "2 of 5 runs stored" in capsys.readouterr().err
    assert len(read_csv(out / "results.csv")) == 2  # rows so far, whole
    monkeypatch.setattr(engine, "run_tasks", real)
    assert main(cmd) == 0
    assert "3 runs computed, 2 already stored" in capsys.readouterr().out


@pytest.mark.slow
def test_sigint_to_a_running_sweep_then_resume(tmp_path):
    # 200 runs of 30 s (several seconds: not a short sweep, which is one batch), the
    # first group of 25 about a second on an idle machine: the signal comes once it
    # is stored, long before the rest is done
    base = write_yaml(tmp_path, base_doc(duration=30.0), "base.yaml")
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "sandbox",
        "sweep",
        str(base),
        "--seeds",
        "0:200",
        "--out",
        str(out),
    ]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(list((out / "runs").glob("*.json"))) < 2:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    kept = len(read_csv(out / "results.csv"))
    assert 2 <= kept < 200
    assert not list((out / "runs").glob(".*.tmp"))  # nothing half-written
    done = subprocess.run(
        [*cmd, "--seeds", f"0:{kept}"], env=env, capture_output=True, text=True
    )
    assert "nothing to compute" in done.stdout


def test_a_changed_base_is_refused(tmp_path, base, capsys):
    out = tmp_path / "out"
    assert main(["sweep", str(base), "--out", str(out)]) == 0
    # Key order and comments do not change the base; a value does.
    doc = base_doc()
    base.write_text("# a comment\n" + yaml.safe_dump(doc, sort_keys=True))
    assert main(["sweep", str(base), "--out", str(out)]) == 0
    doc["recovery"]["beta"] = 2.0
    base.write_text(yaml.safe_dump(doc))
    capsys.readouterr()
    assert main(["sweep", str(base), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert (
        "holds a sweep of another base scenario" in err and len(err.splitlines()) == 1
    )
    assert (
        main(["sweep", str(base), "--set", "duration=2", "--out", str(tmp_path / "o2")])
        == 0
    )
    assert main(["sweep", str(base), "--out", str(tmp_path / "o2")]) == 2  # other --set


def test_a_store_of_another_sandbox_version_is_refused(tmp_path, base, capsys):
    out = tmp_path / "out"
    assert main(["sweep", str(base), "--seeds", "0:1", "--out", str(out)]) == 0
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["sandbox"] == sandbox.__version__
    (run,) = (out / "runs").glob("*.json")
    assert json.loads(run.read_text())["sandbox"] == sandbox.__version__
    meta["sandbox"] = "0.0.1"
    (out / "sweep.json").write_text(json.dumps(meta))
    capsys.readouterr()
    assert main(["sweep", str(base), "--seeds", "0:2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "computed by sandbox 0.0.1" in err and len(err.splitlines()) == 1
    assert len(list((out / "runs").glob("*.json"))) == 1  # nothing computed


@pytest.mark.slow
def test_failed_runs_are_rows_and_retry_failed_reruns_only_them(tmp_path, base, capsys):
    # With d = 4 m no three vehicles fit apart in the 6 m square: every draw overlaps,
    # so those runs are invalid rows, not missing ones.
    out = tmp_path / "out"
    cmd = [
        "sweep",
        str(base),
        "--grid",
        "vehicle.diameter=0.5,4",
        "--seeds",
        "0:2",
        "--out",
        str(out),
    ]
    assert main(cmd) == 0
    rows = read_csv(out / "results.csv")
    status = {(r["vehicle.diameter"], r["seed"]): r["status"] for r in rows}
    assert status == {
        ("0.5", "0"): "ok",
        ("0.5", "1"): "ok",
        ("4", "0"): "invalid",
        ("4", "1"): "invalid",
    }
    bad = next(r for r in rows if r["status"] == "invalid")
    assert (
        "no draw without overlapping starts"
        in json.loads((out / "runs" / f"{bad['run_id']}.json").read_text())["error"]
    )
    capsys.readouterr()
    assert main(cmd) == 0
    assert "nothing to compute" in capsys.readouterr().out
    assert main([*cmd, "--retry-failed"]) == 0
    assert "2 runs computed, 2 already stored" in capsys.readouterr().out


@pytest.mark.slow
def test_process_pool_gives_the_same_results(tmp_path, base):
    cmd = ["sweep", str(base), "--grid", "recovery.beta=1,3", "--seeds", "0:3"]
    assert main([*cmd, "--out", str(tmp_path / "one")]) == 0
    assert main([*cmd, "--jobs", "2", "--out", str(tmp_path / "two")]) == 0
    one = (tmp_path / "one" / "results.csv").read_bytes()
    assert one == (tmp_path / "two" / "results.csv").read_bytes()


def test_dry_run_writes_nothing(tmp_path, base, capsys):
    out = tmp_path / "out"
    assert (
        main(
            [
                "sweep",
                str(base),
                "--grid",
                "recovery.beta=1,2",
                "--seeds",
                "0:100",
                "--out",
                str(out),
                "--dry-run",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "2 grid points x 100 seeds (0:100) = 200 runs; 0 stored" in text
    assert "--set recovery.beta=1 --set seed=0" in text
    assert not out.exists()


def test_parquet_next_to_csv(tmp_path, base):
    pq = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "out"
    assert main(["sweep", str(base), "--seeds", "0:2", "--out", str(out)]) == 0
    table = pq.read_table(out / "results.parquet")
    assert table.num_rows == 2 and table.column("seed").to_pylist() == [0, 1]
    rows = read_csv(out / "results.csv")
    assert table.column("min_distance").to_pylist() == [
        float(r["min_distance"]) for r in rows
    ]


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--grid", "recovery.beta"], "expected PATH=v1,v2"),
        (["--grid", "recovery..beta=1"], "names no field"),
        (
            ["--zip", "recovery.beta=1,2", "--zip", "recovery.R=1,2,3"],
            "differ in length",
        ),
        (["--seeds", "5:2"], "empty or negative range"),
        (["--seeds", "a:b"], "not a seed range"),
        (["--grid", "recovery.beta=1", "--grid", "recovery.beta=2"], "varied twice"),
        (["--grid", "seed=1,2"], "vary seeds with --seeds"),
        (["--jobs", "0"], "--jobs 0"),
    ],
)
def test_bad_options(tmp_path, base, capsys, extra, message):
    assert main(["sweep", str(base), *extra, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_an_invalid_grid_value_is_refused_before_running(tmp_path, base, capsys):
    out = tmp_path / "o"
    assert (
        main(["sweep", str(base), "--grid", "recovery.beta=1,-2", "--out", str(out)])
        == 2
    )
    err = capsys.readouterr().err
    assert "recovery.beta" in err and "--set recovery.beta=-2" in err
    assert not out.exists()


def test_scheduler_without_dask_says_how_to_install(
    tmp_path, base, capsys, monkeypatch
):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails
    assert (
        main(
            [
                "sweep",
                str(base),
                "--scheduler",
                "tcp://127.0.0.1:1",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 1
    )
    assert "pip install 'platoon-sandbox[dask]'" in capsys.readouterr().err


def test_split_values():
    assert split_values("1,2") == ["1", "2"]
    assert split_values("[0, 1],[2, 3]") == ["[0, 1]", "[2, 3]"]


def test_wilson_interval():
    # p = 5/10, z = 1.96: centre 0.5, half-width 1.96 sqrt(0.025 + 0.0096) / 1.384.
    lo, hi = wilson(5, 10)
    assert lo == pytest.approx(0.2366, abs=1e-4) and hi == pytest.approx(
        0.7634, abs=1e-4
    )
    assert wilson(10, 10)[1] == 1.0


@pytest.mark.slow
def test_table_and_plot(tmp_path, base, capsys):
    out = tmp_path / "out"
    assert (
        main(
            [
                "sweep",
                str(base),
                "--grid",
                "recovery.beta=1,4",
                "--grid",
                "recovery.strategy=discontinuous,continuous",
                "--set",
                "recovery.r=1.5d",
                "--seeds",
                "0:3",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert (
        main(["sweep", "table", str(out), "--by", "recovery.beta", "--format", "csv"])
        == 0
    )
    table = list(csv.DictReader(capsys.readouterr().out.splitlines()))
    rows = read_csv(out / "results.csv")
    assert [t["recovery.beta"] for t in table] == ["1", "4"]
    assert [int(t["runs"]) for t in table] == [6, 6]
    for t in table:
        mine = [r for r in rows if r["recovery.beta"] == t["recovery.beta"]]
        hits = sum(int(r["collisions.healthy"]) > 0 for r in mine)
        assert float(t["collision_rate"]) == hits / 6
    assert main(["sweep", "table", str(out)]) == 0
    md, _, paired = capsys.readouterr().out.partition("\n\n")
    assert (
        md.startswith("| recovery.beta | recovery.strategy | runs |")
        and md.count("\n") == 5
    )
    # below the rates: the 4 settings compared pair by pair over their 3 seeds
    assert "exact McNemar test" in paired and paired.count("|     3 |") == 12
    assert (
        main(["sweep", "table", str(out), "--by", "recovery.beta", "--format", "json"])
        == 0
    )
    doc = json.loads(capsys.readouterr().out)
    assert [(d["recovery.beta"], d["runs"]) for d in doc] == [("1", 6), ("4", 6)]
    assert [d["collision_rate"] for d in doc] == [
        float(t["collision_rate"]) for t in table
    ]
    assert main(["sweep", "plot", str(out)]) == 0
    figs = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert figs == [
        "heatmap_recovery_beta_recovery_strategy.png",
        "rates_recovery_beta.png",
    ]
    assert main(["sweep", "table", str(tmp_path)]) == 1


@pytest.mark.slow
def test_zipped_paths_are_one_axis_of_the_figures(tmp_path, base):
    out = tmp_path / "out"
    argv = ["sweep", str(base), "--seeds", "0:1", "--set", "duration=0.2"]
    argv += ["--grid", "recovery.beta=1,2"]
    argv += ["--zip", "vehicles[1].offset=[-2,1],[-1.5,1]"]
    argv += ["--zip", "vehicles[2].offset=[-2,-1],[-1.5,-1]", "--out", str(out)]
    assert main(argv) == 0
    assert main(["sweep", "plot", str(out)]) == 0
    zipped = "vehicles_1_offset_vehicles_2_offset"
    figs = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert figs == [f"heatmap_recovery_beta_{zipped}.png", "rates_recovery_beta.png"]
    # a zipped path named by --by is an axis of its own
    assert main(["sweep", "plot", str(out), "--by", "vehicles[2].offset"]) == 0
    assert (out / "figures" / "rates_vehicles_2_offset.png").is_file()
    assert (out / "figures" / "heatmap_vehicles_2_offset_recovery_beta.png").is_file()


@pytest.mark.slow
def test_deadlocks_are_a_column_and_a_rate(tmp_path, capsys):
    swap = REPO / "scenarios" / "safety" / "head_on_swap.yaml"
    out = tmp_path / "out"
    argv = ["sweep", str(swap), "--set", "duration=6", "--seeds", "0:1"]
    argv += ["--grid", "recovery.tangential=0,1", "--out", str(out)]
    assert main(argv) == 0
    rows = read_csv(out / "results.csv")
    # measured: kappa 0 stalls nose to nose (one deadlock), kappa 1 passes
    assert [(r["recovery.tangential"], r["deadlocks"]) for r in rows] == [
        ("0", "1"),
        ("1", "0"),
    ]
    capsys.readouterr()
    assert main(["sweep", "table", str(out), "--format", "csv"]) == 0
    table = list(csv.DictReader(capsys.readouterr().out.splitlines()))
    assert [(t["deadlocked"], t["deadlocked_rate"]) for t in table] == [
        ("1", "1.0"),
        ("0", "0.0"),
    ]


def test_bundled_study_files_validate(capsys):
    studies = sorted((REPO / "scenarios" / "studies").glob("section4_*.yaml"))
    assert len(studies) >= 2
    assert main(["validate", *map(str, studies)]) == 0
    out = capsys.readouterr().out
    assert "sweep: 7 grid points x 200 seeds = 1400 runs" in out


def test_validate_reports_a_bad_sweep_file(tmp_path, base, capsys):
    bad = sweep_file(tmp_path, base, "bad.yaml", grid={"recovery.beta": [1, -1]})
    assert main(["validate", str(bad)]) == 2
    assert "--set recovery.beta=-1" in capsys.readouterr().err
