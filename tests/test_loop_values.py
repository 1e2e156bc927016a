"""The loop's values and batch-first parts, one at a time (loop/, model/).

The layout of K worlds, the worlds' liveness, the reference read a chunk of periods at
a time, the backward differences with a history per world, the failures and the
command schedules of K worlds: each gives, for any K (one included), the numbers
each world has alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import PAPER

from sandbox import load_scenario
from sandbox.loop import reference_rows
from sandbox.loop.layout import Layout
from sandbox.loop.liveness import Liveness
from sandbox.loop.reference_rows import ReferenceRows
from sandbox.loop.schedules import CommandSchedules
from sandbox.model.failures import Failures
from sandbox.model.laws import BackwardDifference, BatchDifference
from sandbox.model.references import CircleReference
from sandbox.run.record import Run


def fig15(*extra: str):
    return load_scenario(PAPER / "fig15_continuous_beta1.yaml", overrides=list(extra))


def test_the_layout_of_k_worlds_puts_world_w_at_rows_w_n():
    layout = Layout.of([fig15("seed=1"), fig15("seed=2")])
    assert (layout.K, layout.n, layout.N) == (2, 3, 6)
    assert layout.rows(1) == slice(3, 6)
    assert layout.steps == 1500 and layout.h == 0.01  # 15 s of 10 ms
    assert layout.names[1] == ("leader", "red", "green")


def test_liveness_ends_one_world_and_keeps_the_others_in_order():
    live = Liveness([{}, {}, {}])
    before = live.worlds()
    assert before == (0, 1, 2) and live.count == 3
    run = Run.__new__(Run)  # the run itself is not read here
    live.end(1, run, undefined=True)
    assert live.worlds() == (0, 2) and live.count == 2
    assert before == (0, 1, 2)  # a caller's worlds stay as they were
    assert live.live.tolist() == [True, False, True]
    assert live.undefined.tolist() == [False, True, False]
    assert live.runs == {1: run}


@pytest.mark.parametrize("chunk", [1, 7, 1024])
def test_reference_rows_are_the_evaluation_at_each_time_alone(monkeypatch, chunk):
    # A chunk of periods at a time (here of 1, 7 and 1,024), each row the bits of the
    # scalar evaluation at t = k h, across the chunks' ends.
    monkeypatch.setattr(reference_rows, "CHUNK", chunk)
    ref = CircleReference((0.0, 0.0), 2.0, 0.5)
    h, steps = 0.01, 30
    rows = ReferenceRows(ref, h, steps, K=2)
    for k in range(steps + 1):
        alone = ref.evaluate(k * h)
        for got, want in zip(rows.row(k), alone, strict=True):
            assert got.tobytes() == np.asarray(want, dtype=float).tobytes()
        points = rows.points(k)
        assert points.shape == (2, 2)
        assert points[1].tobytes() == np.asarray(alone[0], dtype=float).tobytes()
    assert len(rows.table[0]) <= chunk  # one chunk held, never the whole run


def test_a_batch_difference_is_each_worlds_backward_difference():
    # Two worlds of one signal; world 1 restarts at the third step: its estimates
    # are those of a BackwardDifference started there, world 0's run on.
    h = 0.1
    xs = [np.array([[0.0, 1.0], [2.0, 0.5]]) * k**2 for k in range(6)]
    batch = BatchDifference(h, 2)
    alone = [BackwardDifference(h), BackwardDifference(h)]
    for k, x in enumerate(xs):
        if k == 3:
            batch.reset(1)
            alone[1].reset()
        v, a = batch.update(x)
        for w in range(2):
            v_w, a_w = alone[w].update(x[w])
            assert v[w].tobytes() == v_w.tobytes() and a[w].tobytes() == a_w.tobytes()
    # restart: world 0 takes a history of its own
    other = BackwardDifference(h)
    other.update(np.array([5.0, 5.0]))
    batch.restart(0, other)
    v, _ = batch.update(np.array([[6.0, 5.0], [0.0, 0.0]]))
    assert v[0].tolist() == pytest.approx([10.0, 0.0])  # (6 - 5) / 0.1


def test_failures_of_k_worlds_are_each_worlds_rows():
    a = fig15("seed=1", "failures=[{vehicle: red, at: 0.5, kind: stop}]")
    b = fig15("seed=2", "failures=[{vehicle: green, at: 0.2, kind: spin, v2: 2}]")
    fs = Failures([(sc.failures, [v.name for v in sc.vehicles]) for sc in (a, b)], 3)
    assert fs.vehicle.tolist() == [1, 5] and fs.world.tolist() == [0, 1]
    live = np.ones(2, dtype=bool)
    assert fs.active_vehicles(0.3, live).tolist() == [0, 0, 0, 0, 0, 1]
    live[1] = False  # an ended world's failures are not applied
    assert not fs.active_vehicles(0.6, live)[5] and fs.active_vehicles(0.6, live)[1]
    v1, v2 = np.ones(6), np.zeros(6)
    out1, out2, failed, _, errors = fs.apply(0.6, np.ones(2, bool), v1, v2, v1, 1.0)
    assert errors == [] and failed.tolist() == [0, 1, 0, 0, 0, 1]
    assert out1[1] == 0.0 and out2[5] == 2.0  # stop, spin at 2 rad/s
    assert out1[0] == 1.0 and v1[1] == 1.0  # the others, and the input, untouched


def test_command_schedules_of_k_worlds_hold_each_row_until_the_next():
    drive = "vehicles[0].drive={type: commands, schedule: %s}"
    a = fig15(drive % "[[0.0, 1.0, 0.1], [0.5, 2.0, 0.0]]")
    b = fig15(drive % "[[0.3, 0.5, -0.2]]")
    schedules = CommandSchedules([a, b], 3)
    assert schedules.rows.tolist() == [0, 3]
    for t, want in [(0.0, [1.0, 0.0]), (0.3, [1.0, 0.5]), (0.7, [2.0, 0.5])]:
        v1, v2 = np.full(6, 9.0), np.full(6, 9.0)
        schedules.apply(t, v1, v2)
        assert v1[[0, 3]].tolist() == want
        assert v1[[1, 2, 4, 5]].tolist() == [9.0] * 4  # the controllers' rows
