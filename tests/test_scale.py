"""Functional tests of the large-fleet machinery (no timing: benchmarks/bench_scale.py).

- a 300-vehicle platoon runs with recovery active and records arrays of the right
  shapes, its recorded target shifts matching eqs. (22)-(27) computed from scratch;
- the Verlet neighbour list returns exactly the pairs of a brute-force search, whether
  or not it was rebuilt since the last call;
- a record streamed to disk (memory maps) holds the same arrays, metrics and CSV as one
  kept in memory;
- the bundled 1,000 and 10,000-vehicle scenarios load and run.
"""

from __future__ import annotations

import gc

import numpy as np
import pytest
from helpers import SCENARIOS

import sandbox.run.recorder as run_module
from sandbox import load_scenario
from sandbox.behaviour.recovery import avoidance_shift
from sandbox.geometry.neighbours import BRUTE_FORCE_MAX, NeighbourList, neighbour_pairs
from sandbox.loop.simulation import Simulation
from sandbox.model.obstacle_field import ObstacleField
from sandbox.run.metrics import compute_metrics
from sandbox.run.output import load_run_dir, write_run_dir
from sandbox.run.record import MODE_AVOID, MODE_FORMATION
from sandbox.run.recorder import Recorder

#: Dense platoons (slots within R) and far starts without v1_max (tunnelling) warn:
#: not what these tests check.
pytestmark = [
    pytest.mark.filterwarnings("ignore:.*within recovery.R:sandbox.SandboxWarning"),
    pytest.mark.filterwarnings("ignore:.*per physics substep:sandbox.SandboxWarning"),
]

RECORDED = ("t", "pose", "cmd", "chi", "slot", "target", "mode", "failed", "reference")


def platoon_doc(count: int, duration: float, **top: object) -> dict:
    """A grid platoon whose neighbours sit inside each other's safe zone.

    Spacing 1.25 m (2.5 d) with R = 1.5 m and r = 0.75 m: every vehicle has its 2 to 4
    grid neighbours within R, so the continuous strategy is active for all of them.
    """
    doc = {
        "name": f"platoon_{count}",
        "duration": duration,
        "dt": 0.01,
        "seed": 2,
        "reference": {"type": "line", "start": [0, 0], "heading": 0.0, "speed": 1.0},
        "formation": {"law": "virtual"},
        "vehicle": {"diameter": 0.5, "v1_max": 2.0, "max_accel": 2.0},
        "recovery": {"strategy": "continuous", "R": 1.5, "r": 0.75, "beta": 0.1},
        "platoon": {"count": count, "pattern": "grid", "spacing": 1.25, "jitter": 0.05},
    }
    doc.update(top)
    return doc


def brute_pairs(pos: np.ndarray, radius: float) -> set[tuple[int, int]]:
    """All pairs ``i < j`` closer than ``radius``, from the full distance matrix."""
    d = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
    i, j = np.nonzero(np.triu(d < radius, 1))
    return set(zip(i.tolist(), j.tolist(), strict=True))


# ---------------------------------------------------------------------------- a platoon
def test_300_vehicle_platoon_runs_with_recovery_and_correct_shapes() -> None:
    scenario = load_scenario(platoon_doc(300, 0.2, record_every=5))
    run = Simulation(scenario).run()
    T, n = 5, 300  # 20 steps, one sample every 5: t = 0, 0.05, ..., 0.2
    assert run.status == "ok"
    assert run.pose.shape == (T, n, 3)
    for name in ("cmd", "chi", "slot", "target"):
        assert getattr(run, name).shape == (T, n, 2), name
    assert run.mode.shape == run.failed.shape == (T, n)
    assert run.reference.shape == (T, 2)
    np.testing.assert_allclose(run.t, np.arange(T) * 0.05)
    assert np.isfinite(run.pose).all() and np.isfinite(run.target).all()
    assert len(run.names) == len(set(run.names)) == n
    # every vehicle has grid neighbours 1.25 m away, inside R = 1.5 m: all avoid
    assert np.all(run.mode[-1] == MODE_AVOID)
    assert run.events == []
    # The recorded shift (target - slot) is eqs. (22)-(27) from the recorded positions,
    # recomputed here over brute-force pairs with the plain continuous weight.
    rec = scenario.recovery
    for k in (0, T - 1):
        pos = run.pose[k, :, :2]
        want = np.zeros((n, 2))
        for i, j in brute_pairs(pos, rec.R):
            rel = pos[i] - pos[j]
            dist = np.hypot(*rel)
            alpha = min(1.0, max(0.0, 1 - (dist - rec.r) / (rec.R - rec.r)))  # (27)
            want[i] += alpha * rel / dist**2  # eqs. (23)-(24)
            want[j] -= alpha * rel / dist**2
        got = run.target[k] - run.slot[k]
        np.testing.assert_allclose(got, rec.beta * want, rtol=1e-9, atol=1e-12)
    # interior vehicles are pushed equally from both sides, edge vehicles outwards
    assert np.abs(got).max() > 1e-3


def test_recovery_off_switches_the_shift_off_at_scale() -> None:
    doc = platoon_doc(300, 0.05, recovery={"strategy": "none"})
    run = Simulation(load_scenario(doc)).run()
    assert np.array_equal(run.target, run.slot)
    assert np.all(run.mode == MODE_FORMATION)


# ------------------------------------------------------------------------ neighbours
@pytest.mark.slow
@pytest.mark.parametrize("n", [5, BRUTE_FORCE_MAX + 1, 400])
@pytest.mark.parametrize("seed", [0, 1])
def test_neighbour_list_matches_brute_force_while_vehicles_move(
    n: int, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    side = np.sqrt(n) * 1.2  # about one neighbour within R = 1.5 m on average
    pos = rng.uniform(0.0, side, size=(n, 2))
    velocity = rng.normal(0.0, 1.0, size=(n, 2))  # [m/s]
    nl = NeighbourList(1.5)
    total = 0
    for _ in range(60):
        i, j = nl.pairs(pos)
        assert np.all(i < j)
        got = set(zip(i.tolist(), j.tolist(), strict=True))
        assert len(got) == len(i)  # no duplicates
        assert got == brute_pairs(pos, 1.5)
        assert got == set(
            zip(*(a.tolist() for a in neighbour_pairs(pos, 1.5)), strict=True)
        )
        total += len(got)
        pos = pos + 0.05 * velocity  # up to ~0.15 m a step: some steps rebuild
    assert total > 0
    if n > BRUTE_FORCE_MAX:
        assert 1 < nl.rebuilds < 60  # both the reuse and the rebuild paths were taken


def test_neighbour_list_pairs_are_sorted_whatever_the_rebuild_history() -> None:
    rng = np.random.default_rng(5)
    pos = rng.uniform(0.0, 20.0, size=(300, 2))
    fresh = NeighbourList(1.5)
    aged = NeighbourList(1.5)
    aged.pairs(pos - 0.2)  # built elsewhere, reused: 0.2 sqrt(2) < skin / 2 = 0.375
    a, b = fresh.pairs(pos), aged.pairs(pos)
    assert aged.rebuilds == 1
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    key = a[0] * len(pos) + a[1]
    assert np.all(np.diff(key) > 0)


def test_neighbour_list_gives_the_same_avoidance_shift_as_a_fresh_search() -> None:
    rng = np.random.default_rng(3)
    pos = rng.uniform(0.0, 25.0, size=(500, 2))
    avoiders = rng.random(500) < 0.8
    field = ObstacleField(())
    args = (avoiders, "continuous", 2.0, 1.5, 0.75, 2.0, field)
    nl = NeighbourList(1.5)
    nl.pairs(pos + 0.1)  # a list built a step ago
    shift, active = avoidance_shift(pos, *args, nl)
    shift0, active0 = avoidance_shift(pos, *args)
    np.testing.assert_allclose(shift, shift0, rtol=1e-12, atol=1e-15)
    assert np.array_equal(active, active0)
    assert active.sum() > 50 and not np.any(shift[~avoiders])


def obstacle_field() -> ObstacleField:
    """Forty obstacles of every type in a 200 m x 50 m strip."""
    obstacles = []
    for k in range(10):
        x = 20.0 * k
        obstacles += [
            {"type": "circle", "center": [x, 25], "radius": 2},
            {"type": "box", "center": [x + 7, 30], "size": [3, 2], "angle": 0.3 * k},
            {"type": "wall", "from": [x, 40], "to": [x + 5, 44]},
            {
                "type": "polygon",
                "points": [[x, 10], [x + 4, 10], [x + 5, 13], [x + 2, 15], [x - 1, 13]],
            },
        ]
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"pose": [300, 300, 0]}],
        "obstacles": obstacles,
    }
    return ObstacleField(load_scenario(doc).obstacles)


@pytest.mark.parametrize("strategy", ["discontinuous", "continuous", "smooth"])
def test_obstacle_candidates_give_the_same_shift_as_every_obstacle(
    strategy: str,
) -> None:
    field = obstacle_field()
    rng = np.random.default_rng(7)
    pos = np.column_stack((rng.uniform(-5, 205, 3000), rng.uniform(0, 50, 3000)))
    dist, _ = field.nearest(pos)
    assert (dist < 0).any() and (dist < 1.5).sum() > 100  # inside, near and far
    within = set(zip(*np.nonzero(dist < 1.5), strict=True))
    assert within <= set(zip(*field.candidates(pos, 1.5), strict=True))
    avoiders = rng.random(3000) < 0.9
    nl = NeighbourList(1.5)
    nl.obstacle_pairs(pos + 0.1, field)  # candidates made a step ago, reused
    args = (avoiders, strategy, 1.0, 1.5, 0.75, 2.0, field)
    shift, active = avoidance_shift(pos, *args, nl)
    dense, dense_active = avoidance_shift(pos, *args)  # every obstacle, every vehicle
    assert np.array_equal(active, dense_active)
    np.testing.assert_allclose(shift, dense, rtol=1e-10, atol=1e-12)


# ---------------------------------------------------------------------------- recording
def test_disk_backed_record_equals_the_in_memory_record(
    monkeypatch: pytest.MonkeyPatch, tmp_path
) -> None:
    scenario = load_scenario(platoon_doc(120, 0.5, record_every=2))
    memory = Simulation(scenario).run()
    monkeypatch.setattr(run_module, "SPILL_BYTES", 0)  # every record goes to disk
    monkeypatch.setattr(run_module, "CHUNK_BYTES", 20_000)  # 2 samples per chunk:
    disk = Simulation(scenario).run()  # 26 samples = 13 flushes
    for name in RECORDED:
        a, b = getattr(memory, name), getattr(disk, name)
        assert isinstance(b, np.memmap), name
        assert a.dtype == b.dtype and a.shape == b.shape, name
        assert np.array_equal(a, b, equal_nan=True), name
    assert compute_metrics(memory) == compute_metrics(disk)
    for run, where in ((memory, "memory"), (disk, "disk")):
        write_run_dir(run, compute_metrics(run), tmp_path / where)
    csv = [(tmp_path / w / "trajectory.csv").read_bytes() for w in ("memory", "disk")]
    assert csv[0] == csv[1]
    back = load_run_dir(tmp_path / "disk")
    assert np.array_equal(back.pose, memory.pose)


def test_disk_backed_record_of_an_interrupted_run_keeps_the_samples_so_far(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(run_module, "SPILL_BYTES", 0)
    monkeypatch.setattr(run_module, "CHUNK_BYTES", 30_000)
    scenario = load_scenario(platoon_doc(60, 1.0))
    polls = iter(range(10_000))
    run = Simulation(scenario).run(should_stop=lambda: next(polls) >= 7)
    assert run.status == "interrupted"
    assert run.pose.shape == (8, 60, 3)  # samples at steps 0..7, then it stopped
    np.testing.assert_allclose(run.t, np.arange(8) * 0.01)
    assert np.isfinite(run.pose).all()


def test_recorder_switches_to_disk_above_the_threshold_only(tmp_path) -> None:
    small = Recorder(10, 5, spill_bytes=10**6)
    big = Recorder(10, 5, spill_bytes=100, directory=tmp_path)
    assert not small.on_disk and big.on_disk
    for rec in (small, big):
        for k in range(12):  # two more than the capacity: ignored
            rec.append(
                k * 0.1,
                np.full((5, 3), k),
                np.ones((5, 2)),
                np.ones((5, 2)),
                np.zeros((5, 2)),
                np.zeros((5, 2)),
                np.ones(5, np.int8),
                np.zeros(5, bool),
                np.array([k, 0.0]),
            )
    a, b = small.arrays(), big.arrays()
    for name in RECORDED:
        assert np.array_equal(a[name], b[name]), name
    assert b["pose"].shape == (10, 5, 3) and b["pose"][9, 0, 0] == 9
    assert list(tmp_path.iterdir()) == []  # the files are unlinked once mapped


def test_a_dropped_disk_record_leaves_no_files(tmp_path) -> None:
    rec = Recorder(50, 20, spill_bytes=0, directory=tmp_path)
    assert len(list(tmp_path.rglob("*.npy"))) == len(RECORDED)
    del rec  # a run that failed before its arrays were taken
    gc.collect()
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------- scenarios
def test_bundled_1000_vehicle_scenario_runs_a_few_steps() -> None:
    scenario = load_scenario(
        SCENARIOS / "scale" / "grid_1000.yaml", overrides=["duration=0.05"]
    )
    assert len(scenario.vehicles) == 1000
    run = Simulation(scenario).run()
    assert run.status == "ok" and run.pose.shape == (1, 1000, 3)


def test_bundled_10000_vehicle_scenario_loads_unique_and_apart() -> None:
    scenario = load_scenario(SCENARIOS / "scale" / "grid_10000.yaml")
    assert len(scenario.vehicles) == 10_000
    assert len({v.name for v in scenario.vehicles}) == 10_000
    pos = np.array([v.pose[:2] for v in scenario.vehicles])
    assert not neighbour_pairs(pos, 0.5)[0].size  # no two centres within a diameter
