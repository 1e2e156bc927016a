"""K worlds in the one loop (Simulation.stacked, .batch): each the bytes alone."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from helpers import PAPER, write_yaml

from sandbox import SandboxWarning, compute_metrics, load_scenario
from sandbox.cli import main
from sandbox.loop import plan as planning
from sandbox.loop.plan import structure_key
from sandbox.loop.simulation import Simulation
from sandbox.loop.tally import row_reduce, row_sum
from sandbox.physics.stepping import BatchStepper
from sandbox.run.output import load_run_dir
from sandbox.study import engine, store

#: The form-up's slots lie within recovery.R of each other (so avoidance stays on, as
#: wanted here): the loader's warning of it is not what these tests check.
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*within recovery.R:sandbox.SandboxWarning"
)
FIELDS = ("t", "pose", "cmd", "chi", "slot", "target", "mode", "failed", "reference")
POSE = {"uniform": [[-2.5, -2.5, -3.14159], [2.5, 2.5, 3.14159]]}


def formup_doc() -> dict:
    """Random form-ups without recovery (they collide), a crash, an obstacle."""
    return {
        "name": "batch_formup",
        "duration": 2.5,
        "seed": 0,
        "vehicle": {"v1_max": 2.0, "max_accel": 5.0, "v2_max": 8.0},
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1},
        "formation": {"law": "rotating"},
        "recovery": {"strategy": "continuous", "beta": 1.0, "R": "3d"},
        "obstacles": [{"type": "circle", "center": [2.0, 2.0], "radius": 0.5}],
        "failures": [{"vehicle": "green", "kind": "crash", "at": 1.0}],
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [1, 1, 0], "offset": [-1, 0.5]},
            {"name": "green", "pose": [1, -1, 0], "offset": [-1, -0.5]},
        ],
        "randomize": {"vehicles[1].pose": POSE, "vehicles[2].pose": POSE},
    }


def assert_same_run(alone, batched) -> None:
    for name in FIELDS:
        a, b = getattr(alone, name), getattr(batched, name)
        assert a.shape == b.shape and a.tobytes() == b.tobytes(), name
    assert batched.status == alone.status
    assert batched.events == alone.events
    assert json.dumps(compute_metrics(batched)) == json.dumps(compute_metrics(alone))


@pytest.mark.slow
def test_a_batched_sweep_stores_the_bytes_of_single_runs(tmp_path, monkeypatch):
    base = write_yaml(tmp_path, formup_doc(), "base.yaml")
    cmd = ["sweep", str(base), "--grid", "recovery.beta=0,2", "--seeds", "0:4"]
    batches = []
    real = Simulation.stacked.__func__

    def counted(cls, scenarios, worlds=None):
        batches.append(len(scenarios))
        return real(cls, scenarios, worlds)

    monkeypatch.setattr(Simulation, "stacked", classmethod(counted))
    assert main([*cmd, "--out", str(tmp_path / "batched")]) == 0
    assert batches == [8]  # one batch: beta is a value, not structure
    monkeypatch.setattr(planning, "structure_key", lambda sc: str(id(sc)))
    assert main([*cmd, "--out", str(tmp_path / "alone")]) == 0
    assert batches == [8, 1, 1, 1, 1, 1, 1, 1, 1]
    files = sorted(p.name for p in (tmp_path / "alone" / "runs").glob("*.json"))
    assert len(files) == 8
    collided = crashed = 0
    for name in files:
        alone = (tmp_path / "alone" / "runs" / name).read_bytes()
        assert (tmp_path / "batched" / "runs" / name).read_bytes() == alone
        metrics = json.loads(alone)["metrics"]
        collided += metrics["collisions"]["total"] > 0
        crashed += metrics["vehicles"]["green"]["failed_at"] == 1.0
    assert collided >= 2  # contacts happened in the batch, and matched
    assert crashed == 8
    assert (tmp_path / "batched" / "results.csv").read_bytes() == (
        tmp_path / "alone" / "results.csv"
    ).read_bytes()


def test_a_diverging_world_stops_alone(tmp_path):
    doc = formup_doc()
    # No max_accel: the failed drive reaches its speed at once (else at 5 m/s^2).
    doc["vehicle"] = {"v1_max": 2.0, "v2_max": 8.0}
    scenarios = []
    for seed, v1 in enumerate([1.0, 2000.0, 0.5]):  # 2000 m/s: beyond 1e3, diverges
        failure = {"vehicle": "red", "kind": "uncontrolled", "v1": v1, "at": 0.3}
        path = write_yaml(tmp_path, {**doc, "failures": [failure]}, f"s{seed}.yaml")
        if v1 > 100:  # so fast that the loader warns of tunnelling
            with pytest.warns(SandboxWarning, match="per physics substep"):
                scenarios.append(load_scenario(path, overrides=[f"seed={seed}"]))
        else:
            scenarios.append(load_scenario(path, overrides=[f"seed={seed}"]))
    assert len({structure_key(sc) for sc in scenarios}) == 1
    runs = Simulation.batch(scenarios)
    assert [r.status for r in runs] == ["ok", "diverged", "ok"]
    assert runs[1].t[-1] < runs[0].t[-1]
    for sc, run in zip(scenarios, runs, strict=True):
        assert_same_run(Simulation(sc).run(), run)


@pytest.mark.parametrize(
    "law",
    [
        {"law": "own_estimate"},
        {"law": "virtual", "rotate": True},
        {"law": "fixed"},
    ],
)
def test_other_laws_and_strategies_match(tmp_path, law):
    doc = {
        **formup_doc(),
        "duration": 1.5,
        "formation": law,
        "recovery": {
            "strategy": "smooth",
            "beta": 1.0,
            "R": "3d",
            "leader_avoids": True,
            "target_derivatives": "estimate",
        },
        "reference": {"type": "circle", "center": [0, 0], "radius": 3, "speed": 1},
    }
    path = write_yaml(tmp_path, doc)
    scenarios = [load_scenario(path, overrides=[f"seed={s}"]) for s in range(3)]
    runs = Simulation.stacked(scenarios).run_all()
    for sc, run in zip(scenarios, runs, strict=True):
        assert_same_run(Simulation(sc).run(), run)


@pytest.mark.slow
def test_structures_are_grouped_never_refused(tmp_path):
    sc = load_scenario(PAPER / "fig15_continuous_beta1.yaml", overrides=["duration=1"])
    noisy = sc.with_overrides("sensing.position_noise=0.01")
    cart = {"type": "commands", "schedule": [[0.0, 0.5, 0.0]]}
    driven = sc.with_overrides(f"vehicles[2].drive={json.dumps(cart)}")
    keys = {structure_key(x) for x in (sc, noisy, driven)}
    assert len(keys) == 3
    assert structure_key(sc.with_overrides("seed=5")) == structure_key(sc)
    with pytest.raises(ValueError, match="differ in structure"):
        Simulation.stacked([sc, noisy])
    # The engine groups them, with the rows of single runs.
    base = write_yaml(tmp_path, {**formup_doc(), "duration": 1.5}, "base.yaml")
    doc = {**formup_doc(), "duration": 1.5}
    jobs = [
        ("a", (doc, str(base), ["seed=1"])),
        ("b", (doc, str(base), ["seed=2", "sensing.position_noise=0.01"])),
        ("c", (doc, str(base), ["seed=3"])),
        ("d", (doc, str(base), ["seed=4", "vehicles[1].pose=[0, 0, 0]"])),  # overlaps
    ]
    got = dict(engine.run_tasks(jobs))
    for run_id, job in jobs:
        assert json.dumps(got[run_id]) == json.dumps(engine.run_task(*job))
    assert [got[k]["row"]["status"] for k in "abcd"] == ["ok", "ok", "ok", "invalid"]


def test_a_stopped_batch_returns_nothing():
    sc = load_scenario(PAPER / "fig15_continuous_beta1.yaml", overrides=["duration=1"])
    polls = []

    def stop() -> bool:
        polls.append(1)
        return len(polls) > 10

    assert Simulation.stacked([sc, sc]).run_all(should_stop=stop) is None
    assert Simulation.batch([sc, sc], should_stop=lambda: True) is None
    jobs = [("a", ({"duration": 1}, "x.yaml", []))]
    assert engine.chunks(jobs * 100, 1) == [jobs * 50] * 2
    assert [len(c) for c in engine.chunks(jobs * 300, 1)] == [128, 128, 44]
    assert [len(c) for c in engine.chunks(jobs * 300, 2)] == [75] * 4
    assert [len(c) for c in engine.chunks(jobs * 1000, 2)] == [128] * 7 + [104]
    assert [len(c) for c in engine.chunks(jobs * 10, 2)] == [8, 2]


def test_stacked_motor_arrays_stay_the_worlds_own():
    sc = load_scenario(PAPER / "fig15_continuous_beta1.yaml", overrides=["duration=1"])
    sim = Simulation.stacked([sc, sc])
    sim.physics.worlds[1].immobilize(0)
    assert not sim.physics._tracking[3] and sim.physics._tracking[0]


def test_a_batch_that_raises_gives_the_single_runs(tmp_path, monkeypatch):
    base = write_yaml(tmp_path, {**formup_doc(), "duration": 1.5}, "base.yaml")
    doc = {**formup_doc(), "duration": 1.5}
    jobs = [(str(k), (doc, str(base), [f"seed={k}"])) for k in (1, 2, 3)]

    def broken(self, should_stop=None):
        raise RuntimeError("a bug in the batch")

    monkeypatch.setattr(Simulation, "run_all", broken)
    got = dict(engine.run_tasks(jobs))
    for run_id, job in jobs:
        assert got[run_id]["row"]["status"] == "ok"
        assert json.dumps(got[run_id]) == json.dumps(engine.run_task(*job))


def test_stepping_together_gives_the_bytes_of_world_by_world(tmp_path, monkeypatch):
    # Without recovery the form-ups collide: contact episodes open and close while
    # every world is stepped substep by substep (the static body of the obstacle
    # reorders the bulk read).
    doc = {**formup_doc(), "recovery": {"strategy": "none"}}
    path = write_yaml(tmp_path, doc)
    scenarios = [load_scenario(path, overrides=[f"seed={s}"]) for s in range(6)]
    fast = Simulation.stacked(scenarios)
    fast_runs = fast.run_all()
    stepper = fast.physics._stepper
    assert stepper is not None and stepper._order is not None
    monkeypatch.setattr(BatchStepper, "build", classmethod(lambda cls, *a: None))
    slow = Simulation.stacked(scenarios)
    slow_runs = slow.run_all()
    assert slow.physics._stepper is None
    assert sum(len(r.events) for r in fast_runs) >= 3
    for a, b in zip(slow_runs, fast_runs, strict=True):
        assert_same_run(a, b)
    assert_same_run(Simulation(scenarios[0]).run(), fast_runs[0])


@pytest.mark.parametrize("m", [1, 2, 3, 8, 9])
def test_column_reductions_equal_numpys(m):
    rng = np.random.default_rng(m)
    a = rng.normal(size=(50, m))
    a[rng.random(a.shape) < 0.1] = np.nan
    a[rng.random(a.shape) < 0.1] = -np.inf
    for ufunc in (np.minimum, np.maximum):
        got, want = row_reduce(ufunc, a), ufunc.reduce(a, axis=1)
        assert got.tobytes() == want.tobytes()
    mask = rng.random((50, m)) < 0.5
    assert row_reduce(np.logical_or, mask).tolist() == mask.any(axis=1).tolist()
    assert row_sum(mask).tolist() == mask.sum(axis=1).tolist()


def test_results_parquet_holds_the_rows_python_values(tmp_path):
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    header = ["run_id", "recovery.beta", "seed", *store.MEASURED]
    rows = [
        ["a1", "1", 0, "ok", 3, 2, 1, 0.1 + 0.2, True, 3.21, 1e-300, 0],
        ["b2", '[1, "x"]', 1, "invalid", *[None] * 8],
        ["c3", "", 2, "diverged", 0, 0, 0, 5e-324, False, None, 1.7e308, 2],
    ]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for r in rows:
        writer.writerow([store.cell_text(v) for v in r])
    path = tmp_path / "results.parquet"
    store._write_parquet(path, header, buf.getvalue(), 1)
    types = store.parquet_types(1)
    columns = zip(header, zip(*rows, strict=True), types, strict=True)
    want = pa.table({h: pa.array(list(c), type=t) for h, c, t in columns})
    assert pq.read_table(path).equals(want)
    store._write_parquet(path, header, buf.getvalue().splitlines()[0] + "\n", 1)
    assert pq.read_table(path).num_rows == 0


def test_buffered_loop_metrics_match_with_weak_motors(tmp_path):
    # Weak fixed motors (2 m/s^2) fall behind the commands: the motor check counts
    # saturated periods; the buffered loop metrics of the batch (several chunks of
    # periods) give the single runs' values.
    doc = {**formup_doc(), "duration": 2.0, "recovery": {"strategy": "none"}}
    doc["vehicle"] = {**doc["vehicle"], "motor_accel": 2.0}
    path = write_yaml(tmp_path, doc)
    scenarios = [load_scenario(path, overrides=[f"seed={s}"]) for s in range(3)]
    runs = Simulation.stacked(scenarios).run_all()
    for sc, run in zip(scenarios, runs, strict=True):
        assert_same_run(Simulation(sc).run(), run)
    motors = [r.info["loop_metrics"]["motor"] for r in runs]
    assert all(m["saturated_fraction"] > 0 for m in motors)
    assert all(m["max_velocity_error_free"] > 0.01 for m in motors)


def test_a_world_of_a_structure_of_its_own_is_a_batch_of_one(monkeypatch):
    # Three worlds of one structure and one of another: the batch steps a loop of
    # three and a loop of one, and every run is the run alone.
    sc = load_scenario(PAPER / "fig15_continuous_beta1.yaml", overrides=["duration=1"])
    scenarios = [sc.with_overrides(f"seed={s}") for s in range(3)]
    scenarios.insert(1, sc.with_overrides("sensing.position_noise=0.01"))
    sizes = []
    real = Simulation.stacked.__func__

    def counted(cls, group, worlds=None):
        sizes.append(len(group))
        return real(cls, group, worlds)

    monkeypatch.setattr(Simulation, "stacked", classmethod(counted))
    runs = Simulation.batch(scenarios)
    assert sorted(sizes) == [1, 3]
    monkeypatch.undo()
    for one, run in zip(scenarios, runs, strict=True):
        assert_same_run(Simulation(one).run(), run)


def test_a_stack_of_one_world_takes_and_gives_the_batch_shapes():
    fig15 = PAPER / "fig15_continuous_beta1.yaml"
    sc = load_scenario(fig15, overrides=["duration=0.5"])
    stack, alone = Simulation.stacked([sc]), Simulation(sc)
    first = stack.observe()
    assert isinstance(first, list) and len(first) == 1
    assert first[0].pose.tobytes() == alone.observe().pose.tobytes()
    rng = np.random.default_rng(3)
    while not alone.done:
        speeds = rng.uniform(-0.4, 0.4, size=(1, 3, 2))
        speeds[:, 0] = np.nan  # the leader keeps its controller
        shifts = [{"red": (0.05, 0.0)}]
        got = stack.step(commands=speeds, shifts=shifts)
        want = alone.step(commands=speeds[0], shifts=shifts[0])
        assert isinstance(got, list) and len(got) == 1
        assert got[0].pose.tobytes() == want.pose.tobytes()
        assert got[0].mode.tobytes() == want.mode.tobytes()
    assert stack.done and stack.statuses == ["ok"]
    assert_same_run(alone.result(), stack.results()[0])
    with pytest.raises(ValueError, match=r"shape \(1, 3, 2\)"):
        Simulation.stacked([sc]).step(commands=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="expected 1 overrides, got 2"):
        Simulation.stacked([sc]).step(commands=[None, None])


def test_a_sweep_group_of_one_world_stores_its_run_alone(tmp_path, monkeypatch):
    base = write_yaml(tmp_path, {**formup_doc(), "duration": 1.5}, "base.yaml")
    sizes = []
    real = Simulation.stacked.__func__

    def counted(cls, group, worlds=None):
        sizes.append(len(group))
        return real(cls, group, worlds)

    monkeypatch.setattr(Simulation, "stacked", classmethod(counted))
    out = tmp_path / "sweep"
    grid = ["--grid", "recovery.strategy=continuous,smooth", "--seeds", "1:2"]
    assert main(["sweep", str(base), *grid, "--keep-runs", "--out", str(out)]) == 0
    assert sizes == [1, 1]  # the strategy is structure: two groups of one world
    monkeypatch.undo()
    kept = sorted((out / "run_dirs").iterdir())
    assert len(kept) == 2
    for run_dir in kept:
        stored = load_run_dir(run_dir)
        alone = Simulation(load_scenario(run_dir / "scenario.yaml")).run()
        assert_same_run(alone, stored)
