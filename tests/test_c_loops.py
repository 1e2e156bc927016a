"""The QP projection, the motor sizing and the divergence test in C agree with numpy.

The extensions are optional (``sandbox.behaviour.safety._qp``,
``sandbox.physics._motors``, ``sandbox.loop._period``): where one is built, its
check must pass on this machine, a changed bit must fail it, and the C function must
equal the numpy one to the bit on problems of its own; where it is not built, those
assertions are skipped.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from sandbox.behaviour import sensing, tracks
from sandbox.behaviour.safety import filter_kernel, qp
from sandbox.loop import divergence, tally
from sandbox.loop.simulation import Simulation
from sandbox.physics import world
from sandbox.run.metrics import compute_metrics
from sandbox.scenario import load_scenario

needs_qp = pytest.mark.skipif(qp._qp is None, reason="safety._qp not built")
needs_motors = pytest.mark.skipif(world._motors is None, reason="_motors not built")


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)


@needs_qp
def test_the_qp_check_passes_on_this_machine():
    assert qp.kernel_agrees()


@needs_qp
def test_the_qp_check_fails_on_one_changed_bit(monkeypatch):
    real = qp._qp.project

    def off_by_one_ulp(z0, a, b, tol, z, feasible):
        real(z0, a, b, tol, z, feasible)
        moved = np.flatnonzero(feasible & np.any(z != z0, axis=1))
        if len(moved):
            z[moved[0], 0] = np.nextafter(z[moved[0], 0], np.inf)

    monkeypatch.setattr(qp, "_qp", SimpleNamespace(project=off_by_one_ulp))
    monkeypatch.setattr(qp, "_agreed", None)
    assert not qp.kernel_agrees()


@needs_qp
@pytest.mark.parametrize("m", [1, 3, 6, 12])
def test_project_in_c_equals_numpy_on_bounded_problems(m):
    rng = np.random.default_rng(m)
    k = 300
    lo = rng.uniform(-1.0, 0.0, (k, 2))
    hi = lo + rng.uniform(0.0, 2.0, (k, 2))
    box = (lo[:, 0], hi[:, 0], lo[:, 1], hi[:, 1])
    owner = np.repeat(np.arange(k), m)
    angle = rng.uniform(-np.pi, np.pi, k * m)
    a = np.column_stack((np.cos(angle), np.sin(angle)))
    b = rng.normal(0.2, 0.5, k * m)
    rank = np.tile(np.arange(m), k)
    mat, off, soft = qp.bounded_problems(box, owner, a, b, rank, m)
    z0 = rng.normal(0.0, 1.5, (k, 2))
    assert qp.kernel_agrees()
    z, ok = qp.project(z0, mat, off)
    zn, okn = qp.project_numpy(z0, mat, off)
    assert np.array_equal(ok, okn) and np.array_equal(_bits(z), _bits(zn))
    assert not ok.all() and ok.any()  # empty polygons and optima on edges and corners


@needs_qp
def test_filtered_runs_with_the_c_projection_equal_numpy(monkeypatch):
    # the filter's numpy path, whose QPs go through qp.project (the C filter's own
    # projection is tested in test_filter_kernel.py)
    monkeypatch.setattr(filter_kernel, "USE_KERNEL", False)
    scenarios = [
        load_scenario(
            "failures/follower_stop",
            overrides=["duration=5", "safety.filter=cbf", f"seed={s}"],
        )
        for s in range(3)
    ]
    with_c = Simulation.batch(scenarios)
    monkeypatch.setattr(qp, "USE_KERNEL", False)
    numpy = Simulation.batch(scenarios)
    for a, b in zip(with_c, numpy, strict=True):
        assert np.array_equal(_bits(a.pose), _bits(b.pose))
        assert np.array_equal(_bits(a.cmd), _bits(b.cmd))


@needs_motors
def test_the_motor_check_passes_on_this_machine():
    assert world.motor_kernel_agrees()


@needs_motors
def test_the_motor_check_fails_on_one_changed_bit(monkeypatch):
    real = world._motors.motor_limits

    def off_by_one_ulp(*args):
        real(*args)
        force = args[12]
        force[0] = np.nextafter(force[0], np.inf)

    monkeypatch.setattr(world, "_motors", SimpleNamespace(motor_limits=off_by_one_ulp))
    monkeypatch.setattr(world, "_motors_agreed", None)
    assert not world.motor_kernel_agrees()


@needs_motors
def test_runs_with_the_c_motors_equal_numpy(monkeypatch):
    # a platoon without recovery: a collision within the first second
    sc = load_scenario("paper/fig12_no_recovery", overrides=["duration=3"])
    with_c = Simulation(sc).run()
    monkeypatch.setattr(world, "USE_MOTOR_KERNEL", False)
    numpy = Simulation(sc).run()
    assert np.array_equal(_bits(with_c.pose), _bits(numpy.pose))
    assert with_c.events == numpy.events and with_c.events


@pytest.mark.skipif(divergence._period is None, reason="_period not built")
def test_the_divergence_fast_path_in_c_says_what_numpy_says(monkeypatch):
    rng = np.random.default_rng(3)
    seen = set()
    for trial in range(400):
        n = int(rng.integers(1, 9))
        fleet = SimpleNamespace(
            pos=rng.normal(0.0, 10.0, (n, 2)),
            theta=rng.normal(0.0, 3.0, n),
            vel=rng.normal(0.0, 1.0, (n, 2)),
            chi=rng.normal(0.0, 1.0, (n, 2)),
        )
        name = ("pos", "theta", "vel", "chi")[trial % 4]
        bad = (np.nan, np.inf, -np.inf, 2e6, 999.0, 1e3)[trial % 6]
        if trial % 3:  # one element beyond a bound, or at it
            getattr(fleet, name).reshape(-1)[int(rng.integers(0, n))] = bad
        with_c = divergence.healthy(fleet)
        monkeypatch.setattr(divergence, "_period", None)
        assert divergence.healthy(fleet) is with_c
        monkeypatch.undo()
        seen.add(with_c)
    assert seen == {True, False}


@pytest.mark.skipif(tracks._fits is None, reason="_fits not built")
def test_the_stop_estimates_in_c_stay_within_the_margin_and_fit_the_same(monkeypatch):
    rng = np.random.default_rng(4)
    for k in range(120):
        m = int(rng.integers(10, 150))
        t = np.sort(rng.uniform(0.0, 1.5, m))
        t -= t[0]
        onset, v0 = rng.uniform(0.0, 1.2), rng.uniform(0.1, 2.0)
        brake = float(rng.choice([0.5, 2.0, 5.0, 50.0]))
        braked = v0 * v0 / (2.0 * brake) * (1.0 - np.exp(-3.0 * (t - onset)))
        s = np.where(t < onset, v0 * t, v0 * onset + (braked if k % 2 else 0.0))
        s = s + rng.normal(0.0, 0.01 * (k % 3), m)
        v = np.linspace(0.0, 1.8 * v0, tracks.SPEEDS)
        est, margin = tracks._stop_estimates_c(t, s, v, brake)
        want, want_margin = tracks.stop_estimates_numpy(t, s, v, brake)
        assert np.array_equal(margin, want_margin)
        assert np.all(np.abs(est - want) <= 1e-6 * margin)  # far inside the margin
        with_c = tracks.stop_fits(t, s, brake)
        monkeypatch.setattr(tracks, "USE_KERNEL", False)
        assert tracks.stop_fits(t, s, brake) == with_c  # the very same numbers
        monkeypatch.undo()


@pytest.mark.skipif(tally._period is None, reason="_period not built")
@pytest.mark.parametrize("batch", [0, 3])
def test_the_loop_metrics_buffers_in_c_equal_numpy(monkeypatch, batch):
    calls = []
    real = tally._period.buffer_period

    def counted(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(tally._period, "buffer_period", counted)
    names = ["paper/fig12_no_recovery", "failures/follower_crash"]

    def metrics():
        out = []
        for name in names:
            overrides = ["duration=4"]
            if batch:
                scenarios = [
                    load_scenario(name, overrides=[*overrides, f"seed={s}"])
                    for s in range(batch)
                ]
                runs = Simulation.batch(scenarios)
            else:
                runs = [Simulation(load_scenario(name, overrides=overrides)).run()]
            out += [json.dumps(compute_metrics(r), sort_keys=True) for r in runs]
        return out

    with_c = metrics()
    assert calls
    monkeypatch.setattr(tally, "USE_KERNEL", False)
    assert metrics() == with_c


@pytest.mark.skipif(sensing._draws is None, reason="_draws not built")
def test_the_worlds_draws_in_c_equal_each_generators(monkeypatch):
    def runs():
        scenarios = [
            load_scenario(
                "failures/follower_stop",
                overrides=[
                    "duration=4",
                    "sensing.position_noise=0.02",
                    "sensing.loss=0.3",
                    f"seed={s}",
                ],
            )
            for s in range(4)
        ]
        return [
            r.pose.tobytes() + r.target.tobytes() for r in Simulation.batch(scenarios)
        ]

    draw = sensing.stacked_draws([np.random.default_rng(s) for s in range(3)], 5)
    assert draw is not None
    noise, lost = np.empty((3, 5, 3)), np.empty((3, 5))
    for _ in range(2):  # two periods: each stream goes on where it stopped
        draw(noise, lost)
    for w in range(3):
        g = np.random.default_rng(w)
        g.standard_normal((5, 3)), g.random(5)
        assert np.array_equal(noise[w], g.standard_normal((5, 3)))
        assert np.array_equal(lost[w], g.random(5))
    with_c = runs()
    monkeypatch.setattr(sensing, "USE_KERNEL", False)
    assert sensing.stacked_draws([np.random.default_rng(0)], 5) is None
    assert runs() == with_c


@pytest.mark.skipif(sensing._draws is None, reason="_draws not built")
def test_the_draws_check_refuses_other_numbers(monkeypatch):
    real = sensing._draws.fill_rows

    def off_by_one_ulp(fill, bitgens, out):
        real(fill, bitgens, out)
        out.reshape(-1)[0] = np.nextafter(out.reshape(-1)[0], np.inf)

    monkeypatch.setattr(sensing, "_draws", SimpleNamespace(fill_rows=off_by_one_ulp))
    assert sensing.stacked_draws([np.random.default_rng(0)], 4) is None
