"""Sensing: the noisy, delayed, lossy broadcast the vehicles see of each other."""

from __future__ import annotations

import numpy as np
import pytest

from sandbox import load_scenario
from sandbox.behaviour.sensing import Broadcast
from sandbox.errors import ScenarioError
from sandbox.loop.simulation import Simulation
from sandbox.model.laws import BackwardDifference

#: The test formation's slots lie within recovery.R (avoidance on, as wanted): the
#: loader's warning of it is not what these tests check.
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*within recovery.R:sandbox.SandboxWarning"
)


def _doc(**sensing: float) -> dict:
    doc = {
        "duration": 1.0,
        "dt": 0.01,
        "seed": 3,
        "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1.0},
        "formation": {"law": "rotating"},
        "vehicles": [
            {"name": "leader", "pose": [5, 0, 1.5707963], "leader": True},
            {"name": "red", "pose": [4, -1, 1.5707963], "offset": [-1, 1]},
            {"name": "green", "pose": [6, -1, 1.5707963], "offset": [-1, -1]},
        ],
        "recovery": {"strategy": "continuous"},
    }
    if sensing:
        doc["sensing"] = sensing
    return doc


def _run(doc: dict) -> np.ndarray:
    run = Simulation(load_scenario(doc)).run()
    return np.concatenate((run.pose.ravel(), run.cmd.ravel(), run.target.ravel()))


def test_zero_sensing_is_bit_identical_to_no_section() -> None:
    zero = dict(position_noise=0.0, heading_noise=0.0, delay=0.0, loss=0.0)
    assert Simulation(load_scenario(_doc(**zero))).broadcast is None
    assert np.array_equal(_run(_doc()), _run(_doc(**zero)), equal_nan=True)


def test_nonzero_sensing_is_deterministic_and_depends_on_the_seed() -> None:
    doc = _doc(position_noise=0.01, heading_noise=0.005, loss=0.1)
    first, again = _run(doc), _run(doc)
    assert np.array_equal(first, again, equal_nan=True)
    assert not np.array_equal(first, _run(_doc()), equal_nan=True)
    other = dict(doc, seed=4)
    assert not np.array_equal(first, _run(other), equal_nan=True)


def test_the_physics_and_the_own_pose_keep_the_truth() -> None:
    sim = Simulation(load_scenario(_doc(position_noise=0.05)))
    for _ in range(5):
        sim.step()
    assert not np.allclose(sim.seen[:, :2], sim.fleet.pos)
    state = sim.world.read_state()
    assert np.array_equal(state.pos, sim.fleet.pos)


def test_the_delay_shifts_the_seen_leader_pose_by_whole_periods() -> None:
    k = 7
    sim = Simulation(load_scenario(_doc(delay=k * 0.01)))
    true, seen, law_pos = [], [], []
    original = sim.law.targets

    def spy(inputs):
        law_pos.append(np.array(inputs.leader_pos).reshape(2))  # (K, 1, 2), K = 1
        return original(inputs)

    sim.law.targets = spy
    for _ in range(40):
        true.append(np.append(sim.fleet.pos[0], sim.fleet.theta[0]))
        seen.append(sim.seen[0].copy())
        sim.step()
    true, seen = np.array(true), np.array(seen)
    assert np.array_equal(seen[k:], true[:-k])
    assert np.array_equal(seen[:k], np.repeat(true[:1], k, axis=0))
    assert np.abs(true[k:, :2] - true[:-k, :2]).max() > 0.05  # the leader moved
    # The law read exactly the delayed copy (its first call was in the constructor).
    assert np.array_equal(np.array(law_pos[:39]), seen[1:, :2])


def test_a_lost_packet_holds_the_last_received_copy() -> None:
    b = Broadcast(0.0, 0.0, 0, 0.5, seeds=[1], n=4)
    theta = np.zeros(4)
    received = [b.update(np.full((4, 2), float(s)), theta).copy() for s in range(200)]
    received = np.array(received)[:, :, 0]  # (steps, vehicles): sent value = step
    changed = np.diff(received, axis=0) != 0
    # Either the current value arrived, or the previous copy was held.
    steps = np.arange(1, 200)[:, None]
    assert np.all((received[1:] == steps) | ~changed)
    assert np.all(received[1:] <= steps)
    held = 1 - changed.mean()
    assert 0.4 < held < 0.6  # about the loss probability


@pytest.mark.slow
def test_the_estimators_noise_follows_the_backward_difference_formulas() -> None:
    sigma, h, steps = 0.01, 0.01, 200_000
    rng = np.random.default_rng(0)
    x = rng.standard_normal((steps, 2)) * sigma
    est = BackwardDifference(h)
    out = [est.update(row) for row in x]
    v = np.array([o[0] for o in out[2:]])
    a = np.array([o[1] for o in out[2:]])
    assert v.std() == pytest.approx(np.sqrt(2) * sigma / h, rel=0.02)
    assert a.std() == pytest.approx(np.sqrt(6) * sigma / h**2, rel=0.02)


@pytest.mark.parametrize(
    ("sensing", "field"),
    [
        ({"position_noise": -0.1}, "sensing.position_noise"),
        ({"heading_noise": -1}, "sensing.heading_noise"),
        ({"delay": -0.01}, "sensing.delay"),
        ({"delay": 0.015}, "sensing.delay"),
        ({"loss": 1.0}, "sensing.loss"),
        ({"loss": -0.1}, "sensing.loss"),
        ({"noise": 0.1}, "sensing"),
    ],
)
def test_bad_sensing_values_name_the_field(sensing: dict, field: str) -> None:
    with pytest.raises(ScenarioError) as err:
        load_scenario(_doc(**sensing))
    assert field in str(err.value)


def test_recovery_uses_the_own_true_and_the_others_seen_positions() -> None:
    from sandbox.behaviour.recovery import continuous, weighted_shift
    from sandbox.model.obstacle_field import ObstacleField
    from sandbox.plugins import StrategyContext

    pos = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]])

    def shift(seen):
        ctx = StrategyContext(
            t=0.0,
            dt=0.01,
            pos=pos,
            theta=np.zeros(3),
            vel=np.zeros((3, 2)),
            slot=pos,
            diameter=np.full(3, 0.5),
            may_avoid=np.ones(3, bool),
            failed=np.zeros(3, bool),
            params={},
            R=1.5,
            obstacle_field=ObstacleField(()),
            seen_pos=seen,
        )
        return weighted_shift(ctx, continuous, 1.0, 0.5, 2.0)[0]

    truth = shift(None)
    assert np.array_equal(shift(pos.copy()), truth)
    # vehicle 1 seen 0.2 m further right: 0 pushed less, 1 (its own position true,
    # vehicle 0's true too) exactly as before
    moved = shift(pos + [[0.0, 0.0], [0.2, 0.0], [0.0, 0.0]])
    assert 0 > moved[0, 0] > truth[0, 0]
    assert moved[1] == pytest.approx(truth[1])
