"""The CBF filter's priority for its right-hand rule (``safety.priority``).

The order itself (hand-checked pairs), which vehicle holds its course at a stall, the
door passed both ways: exactly mirrored, it stays a standoff under ``priority: none``
(only rounding could decide it, and the mirror is exact enough that it does not) and
is passed under ``priority: index``; the default keeps every byte; bad input in one
line with the file and its line.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sandbox import load_scenario
from sandbox.behaviour.safety.cbf import PARAMS, CBFState
from sandbox.behaviour.safety.priority import SLOT_TIE, holding, holds, outranks
from sandbox.cli import main
from sandbox.loop.simulation import Simulation
from sandbox.model.obstacle_field import ObstacleField
from sandbox.plugins.contexts import FilterContext
from sandbox.run.metrics import compute_metrics

ROOT = Path(__file__).resolve().parents[1]
DOOR = ROOT / "scenarios" / "safety" / "door.yaml"
ROBOT = {"diameter": 0.5, "mass": 10.0, "v1_max": 2.0, "v2_max": 4.0, "max_accel": 5.0}
RECOMMENDED = {
    "strategy": "continuous",
    "beta": 1.0,
    "R": "3d",
    "r": "1.5d",
    "tangential": 1.0,
}


def _ctx(pos, slot, priority, failed=None, worlds=1) -> FilterContext:
    n = len(pos)
    values = {k: p.default for k, p in PARAMS.items()}
    values["priority"] = priority
    return FilterContext(
        t=0.0,
        dt=0.01,
        pos=np.asarray(pos, dtype=float),
        theta=np.zeros(n),
        vel=np.zeros((n, 2)),
        v1=np.ones(n),
        v2=np.zeros(n),
        diameter=np.full(n, 0.5),
        params=values,
        v1_max=2.0,
        v2_max=4.0,
        accel_max=5.0,
        known_failed=np.zeros(n, bool) if failed is None else np.asarray(failed),
        commanded=np.zeros(n, bool),
        obstacle_field=ObstacleField(()),
        slot=np.asarray(slot, dtype=float),
        worlds=worlds,
    )


def test_the_order_is_antisymmetric_and_ties_go_by_index() -> None:
    index = np.array([0, 1, 2])
    # slot distances 1, 1 + SLOT_TIE / 2 (a tie: index 0 first) and 3 (farthest)
    far = np.array([1.0, 1.0 + SLOT_TIE / 2, 3.0])
    i = np.array([0, 1, 0, 2, 1, 2])
    j = np.array([1, 0, 2, 0, 2, 1])
    assert outranks("slot_distance", i, j, index, far).tolist() == [
        True,
        False,
        False,
        True,
        False,
        True,
    ]
    assert outranks("index", i, j, index, far).tolist() == [
        True,
        False,
        True,
        False,
        True,
        False,
    ]


def test_the_vehicle_outranking_its_near_ones_holds() -> None:
    # Three on a line 1 m apart (within the automatic range); slots 1, 2, 5 m away.
    pos = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]
    slot = [[1.0, 0.0], [3.0, 0.0], [7.0, 0.0]]
    for kind, holder in (("index", 0), ("slot_distance", 2)):
        ctx = _ctx(pos, slot, kind)
        hold, _ = holding(CBFState(ctx), ctx, np.ones(3, bool))
        assert np.flatnonzero(hold).tolist() == [holder]
    # A failed vehicle does not yield: the one beside it does not hold.
    ctx = _ctx(pos, slot, "index", failed=[False, True, False])
    hold, _ = holding(CBFState(ctx), ctx, np.array([True, False, True]))
    assert not hold.any()


def test_the_index_is_counted_within_each_world() -> None:
    # Two worlds of two: each world's first vehicle holds, as it would alone.
    pos = [[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [1.0, 0.0]]
    slot = [[1.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 0.0]]
    ctx = _ctx(pos, slot, "index", worlds=2)
    hold, _ = holding(CBFState(ctx), ctx, np.ones(4, bool))
    assert hold.tolist() == [True, False, True, False]


def mirrored_door(priority: str | None, duration: float = 20.0) -> dict:
    """Two vehicles swap through a door one vehicle wide, exactly mirrored.

    The half turn about the door's centre maps a onto b: a's heading is
    ``-sin(pi)`` (the float ``pi``), so that its ``(cos, sin)`` is exactly minus
    b's. The walls are 30 m long, so that going round their ends is not a way out.
    """
    safety = {"filter": "cbf"}
    if priority is not None:
        safety["priority"] = priority
    return {
        "duration": duration,
        "dt": 0.01,
        "substeps": 4,
        "vehicle": ROBOT,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "recovery": RECOMMENDED,
        "metrics": {"deadlock_progress": 0.5},
        "vehicles": [
            {"name": "a", "pose": [-2, 0, -math.sin(math.pi)], "offset": [2, 0]},
            {"name": "b", "pose": [2, 0, math.pi], "offset": [-2, 0]},
        ],
        "obstacles": [
            {"type": "wall", "from": [0, 0.6], "to": [0, 30], "thickness": 0.2},
            {"type": "wall", "from": [0, -0.6], "to": [0, -30], "thickness": 0.2},
        ],
        "safety": safety,
    }


@pytest.mark.slow
def test_the_mirrored_door_is_a_standoff_without_priority_and_passed_with() -> None:
    assert np.cos(-math.sin(math.pi)) == -np.cos(math.pi)
    assert np.sin(-math.sin(math.pi)) == -np.sin(math.pi)
    run = Simulation(load_scenario(mirrored_door("none"))).run()
    m = compute_metrics(run)
    # Without an order both turn alike, slide apart along the wall and are trapped;
    # the mirror holds to within a micrometre all the way (as measured: 1e-6 m is
    # first exceeded at 7.7 s, 1e-3 m never in 20 s).
    xy = run.pose[:, :, :2]
    assert np.abs(xy[:, 0] + xy[:, 1]).max() < 1e-3
    assert not m["converged"] and m["collisions"]["total"] == 0
    assert {v for d in m["deadlocks"] for v in d["vehicles"]} == {"a", "b"}
    # With the index a goes first, through the door, and b after it: b waits (a
    # deadlock entry, as measured from 0.99 s for 4.53 s) and then passes.
    run = Simulation(load_scenario(mirrored_door("index"))).run()
    m = compute_metrics(run)
    assert m["converged"] and m["collisions"]["total"] == 0
    assert all(d["vehicles"] == ["b"] and d["t"] + d["duration"] < 6 for d in
               m["deadlocks"])  # fmt: skip
    through = np.abs(run.pose[:, :, 1]).max(axis=0)
    assert through.max() < 1.0  # within 1 m of the axis: through the door (b waits
    # at 0.84 m, as measured), not round the walls


@pytest.mark.slow
def test_the_door_file_passes_with_the_index() -> None:
    # The order decides the standoff at once: the half-turn mirror of the pairs a_k,
    # b_k is broken by more than 1 mm at 1.2 s (without an order, rounding breaks it
    # after about 15 s). Who passes the door, and when, follows from the whole
    # course, which rounding shapes too and which differs between CPUs (measured:
    # b0 by 12 s on one machine; a2, a0 and b2 at 8.7, 11.0 and 15.2 s on another);
    # what holds is that the door is passed early, with no contact and no deadlock.
    sets = ["safety.filter=cbf", "recovery.tangential=1", "safety.priority=index"]
    run = Simulation(load_scenario(DOOR, overrides=sets)).run()
    m = compute_metrics(run)
    assert m["converged"] and m["collisions"]["total"] == 0 and m["deadlocks"] == []
    a = [run.names.index(f"a{k}") for k in range(3)]
    b = [run.names.index(f"b{k}") for k in range(3)]
    mirror = np.abs(run.pose[:, a, :2] + run.pose[:, b, :2]).max(axis=(1, 2))
    assert run.t[np.flatnonzero(mirror > 1e-3)[0]] < 2.0
    k = int(round(16.0 / (run.t[1] - run.t[0])))
    x1, x2 = run.pose[: k + 1, :, 0], run.pose[: k + 1, :, 1]
    crossed = (np.sign(x1[1:]) != np.sign(x1[:-1])) & (np.abs(x2[1:]) < 0.5)
    assert crossed.any()  # some vehicle through the door by 16 s


def test_the_default_keeps_the_key_out_and_the_bytes(tmp_path) -> None:
    assert PARAMS["priority"].default is None
    sets = ["duration=0.5", "safety.filter=cbf"]
    a = Simulation(load_scenario(DOOR, overrides=sets)).run()
    b = Simulation(load_scenario(DOOR, overrides=[*sets, "safety.priority=none"])).run()
    for key in ("pose", "cmd", "chi"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    assert main(["run", str(DOOR), *[x for s in sets for x in ("--set", s)],
                 "--out", str(tmp_path / "r")]) == 0  # fmt: skip
    assert "priority" not in (tmp_path / "r" / "scenario.yaml").read_text()


def test_a_bad_priority_is_one_line_with_file_and_line(tmp_path, capsys) -> None:
    text = DOOR.read_text() + "safety: {filter: cbf, priority: rank}\n"
    path = tmp_path / "door.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    line = len(text.splitlines())
    assert f"door.yaml:{line}" in err[0] and "safety.priority" in err[0]
    assert "expected one of: none, slot_distance, index" in err[0]


def test_a_holder_pressed_on_an_obstacle_turns() -> None:
    # Two holders, each with a vehicle condition (row 0) and an obstacle's (row 1):
    # the first's filtered z lies on the obstacle's row, the second's does not.
    mat = np.array([[[1.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [0.0, 1.0]]])
    off = np.array([[0.0, 0.0], [0.0, 0.5]])
    z = np.zeros((2, 2))
    wall = np.array([[False, True], [False, True]])
    assert holds(np.array([True, True]), wall, mat, off, z).tolist() == [False, True]
