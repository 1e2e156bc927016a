"""The braking barrier under sensing: the estimate of the others' poses and its margin.

Equations: the drive's period (against the physics, and by hand), the estimate exact
without noise whatever the delay and the lost packets, its gains by hand, its error
within the stated bound on a long noisy stream, the sensing margin by hand. Scenario
level: a ring swap under a noisy, delayed broadcast and the residual detector keeps
clear, its barrier on the estimate within millimetres of 0; bad input in one line.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import ring_doc

from sandbox import load_scenario
from sandbox.behaviour.estimation import BroadcastEstimate, drive_period
from sandbox.behaviour.safety.cbf import PARAMS, CBFState
from sandbox.cli import main
from sandbox.loop.simulation import Simulation
from sandbox.model.barriers import ESTIMATE_GAIN, sensing_margin
from sandbox.model.dynamics import wrap_angle
from sandbox.plugins.contexts import FilterContext
from sandbox.run.metrics import compute_metrics

ROBOT = {"diameter": 0.5, "mass": 10.0, "v1_max": 2.0, "v2_max": 4.0, "max_accel": 5.0}


def _drive(commands: np.ndarray, dt: float, lag: float) -> np.ndarray:
    """The poses (T + 1, n, 3) of vehicles at rest at the origin under ``commands``."""
    n = commands.shape[1]
    pose, velocity, turn = np.zeros((n, 3)), np.zeros((n, 2)), np.zeros(n)
    out = [pose]
    for u in commands:
        pose, velocity = drive_period(pose, velocity, turn, u[:, 0], u[:, 1], dt, lag)
        turn = u[:, 1]
        out.append(pose)
    return np.array(out)


# ------------------------------------------------------------------ equations
def test_the_drive_period_by_hand() -> None:
    # From the origin heading +x, the last period at V = (1, 0) m/s and no turn; the
    # command (1 m/s, 2 rad/s) for dt = 0.1 s with a lag of 1/4: the control velocity
    # along the mid heading 2 * 0.1 / 2 = 0.1 rad; the period runs 0.1 (0.75 V +
    # 0.25 (1, 0)) and turns 0.1 (0.75 * 2 + 0.25 * 0) = 0.15 rad.
    out, v = drive_period(
        np.zeros((1, 3)),
        np.array([[1.0, 0.0]]),
        np.zeros(1),
        np.ones(1),
        np.full(1, 2.0),
        0.1,
        0.25,
    )
    np.testing.assert_allclose(v, [[np.cos(0.1), np.sin(0.1)]])
    expected = [0.1 * (0.75 * np.cos(0.1) + 0.25), 0.075 * np.sin(0.1), 0.15]
    np.testing.assert_allclose(out, [expected], atol=1e-15)


def test_the_drive_period_is_the_physics_of_a_free_vehicle() -> None:
    # The stabilization run: one vehicle accelerating and turning at up to 2 m/s and
    # 3 rad/s; every period of the physics (4 substeps) is the model's to rounding.
    r = Simulation(load_scenario("paper/stabilization", overrides=["duration=2"])).run()
    pose, cmd = r.pose[:, 0], r.cmd[:, 0]
    assert np.abs(cmd[:, 1]).max() > 2.0  # it turns
    velocity, turn = np.zeros((1, 2)), np.zeros(1)
    for k in range(len(pose) - 1):
        out, velocity = drive_period(
            pose[k : k + 1], velocity, turn, cmd[k : k + 1, 0], cmd[k : k + 1, 1],
            0.01, 0.25,
        )  # fmt: skip
        turn = cmd[k : k + 1, 1]
        assert np.hypot(*(out[0, :2] - pose[k + 1, :2])) < 1e-12
        assert abs(wrap_angle(out[0, 2] - pose[k + 1, 2])) < 1e-12


def test_exact_copies_give_the_poses_now_whatever_the_delay_and_losses() -> None:
    # Two vehicles driving and turning, copies 5 periods late, packets lost at
    # random (the held copy repeated): the estimate is each pose now, exactly.
    rng = np.random.default_rng(3)
    commands = np.stack(
        (rng.uniform(0.0, 2.0, (300, 2)), rng.uniform(-4.0, 4.0, (300, 2))), -1
    )
    truth = _drive(commands, 0.01, 0.25)
    est = BroadcastEstimate(5, 0.1, 0.01, 4)
    held = truth[0].copy()
    x = est.update(held, None, None)
    np.testing.assert_array_equal(x, truth[0])
    for k in range(1, 301):
        copy = truth[max(k - 5, 0)]
        lost = rng.random(2) < 0.3
        held = np.where(lost[:, None], held, copy)
        x = est.update(held, commands[k - 1, :, 0], commands[k - 1, :, 1])
        np.testing.assert_allclose(x, truth[k], atol=1e-12)


def test_the_gains_by_hand() -> None:
    # A vehicle at rest (no delay) whose copies read x = 1, 3, 8, 0, 8: with K = 0.25
    # the running mean of the first 1 / K = 4 copies, then x + K (copy - x):
    # 1; (1 + 3) / 2 = 2; (1 + 3 + 8) / 3 = 4; 4 + (0 - 4) / 4 = 3; 3 + (8 - 3) / 4.
    est = BroadcastEstimate(0, 0.25, 0.01, 4)
    got = [est.update(np.array([[1.0, 0.0, 0.0]]), None, None)[0, 0]]
    for y in (3.0, 8.0, 0.0, 8.0):
        x = est.update(np.array([[y, 0.0, 0.0]]), np.zeros(1), np.zeros(1))
        got.append(x[0, 0])
    np.testing.assert_allclose(got, [1.0, 2.0, 4.0, 3.0, 4.25])
    # A repeated copy is a lost packet: not used.
    again = est.update(np.array([[8.0, 0.0, 0.0]]), np.zeros(1), np.zeros(1))
    assert again[0, 0] == 4.25


@pytest.mark.slow
def test_the_error_is_within_the_stated_bound() -> None:
    # 20,000 periods of a vehicle weaving at 1-2 m/s, copies 5 periods late with
    # 2 cm / 0.02 rad of noise, K = 0.1: the error's standard deviation tends to
    # sigma sqrt(K / (2 - K)) = 0.02 * 0.2294 = 4.59 mm per coordinate (and the
    # heading's to 0.02 * 0.2294 rad), below the bound sigma sqrt(K) = 6.32 mm the
    # margin uses; no bias (the commands carry the mean).
    rng = np.random.default_rng(0)
    steps = 20_000
    t = 0.01 * np.arange(steps)
    commands = np.stack((1.5 + 0.5 * np.sin(t), 3.0 * np.sin(0.7 * t)), -1)[:, None]
    truth = _drive(commands, 0.01, 0.25)
    sigma = np.array([0.02, 0.02, 0.02])
    est = BroadcastEstimate(5, 0.1, 0.01, 4)
    est.update(truth[0] + rng.standard_normal((1, 3)) * sigma, None, None)
    errors = []
    for k in range(1, steps + 1):
        copy = truth[max(k - 5, 0)] + rng.standard_normal((1, 3)) * sigma
        x = est.update(copy, commands[k - 1, :, 0], commands[k - 1, :, 1])
        e = x[0] - truth[k, 0]
        e[2] = wrap_angle(e[2])
        errors.append(e)
    errors = np.array(errors[500:])
    expected = 0.02 * np.sqrt(0.1 / 1.9)
    np.testing.assert_allclose(errors.std(axis=0), expected, rtol=0.05)
    assert np.all(errors.std(axis=0) < 0.02 * np.sqrt(0.1))
    assert np.all(np.abs(errors.mean(axis=0)) < 0.1 * expected)


def test_the_sensing_margin_by_hand() -> None:
    # 3 sqrt(K) (sigma_p + (l + S) sigma_theta), S = v (v / a + dt) / 2 + v dt
    # = 2 (0.4 + 0.01) / 2 + 0.02 = 0.43 m: with sigma_p = 0.02 m, sigma_theta =
    # 0.01 rad, l = 0.1 m, K = 0.1: 3 * 0.316228 * (0.02 + 0.53 * 0.01) = 0.024002 m.
    margin = sensing_margin(0.02, 0.01, 0.1, 0.1, 2.0, 5.0, 0.01)
    assert margin == pytest.approx(3 * np.sqrt(0.1) * 0.0253)
    assert ESTIMATE_GAIN == 0.1
    values = {k: p.default for k, p in PARAMS.items()}
    values["barrier"] = "braking"
    ctx = FilterContext(
        t=0.0,
        dt=0.01,
        pos=np.zeros((1, 2)),
        theta=np.zeros(1),
        vel=np.zeros((1, 2)),
        v1=np.zeros(1),
        v2=np.zeros(1),
        diameter=np.full(1, 0.5),
        params=values,
        v1_max=2.0,
        v2_max=4.0,
        accel_max=5.0,
        sensing={"position_noise": 0.02, "heading_noise": 0.01, "delay": 0.05},
        substeps=4,
    )
    state = CBFState(ctx)
    assert state.sensed == pytest.approx(margin)
    assert state.estimate is not None and state.estimate.delay == 5
    ctx.params = {**values, "estimate_gain": 1.0}  # each copy alone: 3 sigma
    assert CBFState(ctx).sensed == pytest.approx(3 * 0.0253)
    ctx.params = {**values, "barrier": "velocity"}  # the velocity barrier: none
    state = CBFState(ctx)
    assert state.sensed == 0.0 and state.estimate is None


# ------------------------------------------------------------------ scenarios
def _ring(n: int, seed: int, radius: float) -> dict:
    return {
        **ring_doc(n, 0.05, seed, radius),
        "duration": 10,
        "seed": seed,
        "recovery": {"strategy": "continuous", "beta": 1.0, "tangential": 1.0},
        "safety": {"filter": "cbf", "barrier": "braking"},
        "sensing": {"position_noise": 0.02, "delay": 0.05},
        "detection": {"method": "residual"},
    }


@pytest.mark.slow
def test_a_ring_swap_under_sensing_keeps_clear() -> None:
    # Eight vehicles swap across a 4 m ring seeing each other through 2 cm of noise
    # and 50 ms of delay, the residual detector in place of the oracle. With the
    # copies as received (and a margin of 3 sigma + s_max tau = 0.16 m) the barrier
    # on the sensed poses fell to -0.132 m and the ring did not settle in 10 s; on
    # the estimate it stays within the swing of the estimate's error (3 sigma
    # sqrt(K) = 19 mm each way) of 0, as measured -0.018 m, and the ring settles.
    sc = load_scenario(_ring(8, 1, 4.0))
    m = compute_metrics(Simulation(sc).run())
    s = m["safety"]
    assert m["collisions"]["total"] == 0
    assert s["infeasible_steps"] == 0 and s["fallback_steps"] == 0
    assert s["min_barrier"] > -0.04  # [m]: two estimate errors of 3 sigma sqrt(K)
    assert m["min_distance"] > 0.5 + 0.05
    assert m["converged"]


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("value", ["0", "1.5", "-0.1", "fast"])
def test_a_bad_estimate_gain_is_one_line(value, capsys) -> None:
    argv = ["validate", "safety/head_on_swap", "--set", "safety.filter=cbf"]
    argv += ["--set", "safety.barrier=braking"]
    argv += ["--set", f"safety.estimate_gain={value}"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "safety.estimate_gain" in err[0] and "Traceback" not in err[0]


def test_the_law_and_the_recovery_see_the_estimate_under_the_braking_barrier() -> None:
    # Four vehicles crossing a 3 m ring, at 2 m/s after 0.8 s: under the braking
    # barrier the loop's `believed` poses (what the law and the recovery read) are
    # the estimate, within a few sigma sqrt(K) = 6.3 mm of the truth (as measured,
    # 3-8 mm), while the copies are 50 ms old (0.1 m behind at 2 m/s) and noisy
    # (0.12-0.14 m off); under the velocity barrier they are the copies themselves.
    doc = {**_ring(4, 0, 3.0), "duration": 0.8}
    sim = Simulation(load_scenario(doc))
    sim.run()
    truth = sim.fleet.pos
    estimate = np.hypot(*(sim.believed[:, :2] - truth).T)
    copies = np.hypot(*(sim.seen[:, :2] - truth).T)
    assert estimate.max() < 0.025 and copies.min() > 0.05
    doc["safety"] = {"filter": "cbf"}
    sim = Simulation(load_scenario(doc))
    sim.run()
    assert sim.believed is sim.seen


def test_a_lossy_broadcast_is_covered_and_not_warned_of(recwarn) -> None:
    # The estimate carries on through lost packets by the commands (the copies as
    # received were held, older than the delay, and the loader warned of it).
    sets = ["safety.filter=cbf", "safety.barrier=braking", "sensing.loss=0.1"]
    load_scenario("safety/head_on_swap", overrides=[*sets, "sensing.delay=0.05"])
    assert not [w for w in recwarn if "sensing.loss" in str(w.message)]
