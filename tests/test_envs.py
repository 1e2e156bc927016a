"""The RL environments (extra ``rl``): API checks, observations, rewards, seeds."""

from __future__ import annotations

import os
import re

import numpy as np
import pytest
import yaml
from helpers import SCENARIOS

if not os.environ.get("CI"):  # CI installs the extra: there the tests must run
    pytest.importorskip("gymnasium")
    pytest.importorskip("pettingzoo")

import gymnasium  # noqa: E402
from gymnasium.utils.env_checker import check_env  # noqa: E402
from pettingzoo.test import parallel_api_test  # noqa: E402

from sandbox import load_scenario  # noqa: E402
from sandbox.envs import FormationEnv, VehicleEnv, Weights  # noqa: E402
from sandbox.loop.simulation import Simulation  # noqa: E402

#: The failures platoon (leader, red, green, orange), 1 s long, red stopping at 0.5 s.
PLATOON = yaml.safe_load((SCENARIOS / "failures" / "follower_stop.yaml").read_text())
PLATOON["duration"] = 1.0
PLATOON["failures"] = [{"vehicle": "red", "at": 0.5, "kind": "stop"}]


@pytest.mark.parametrize("action", ["commands", "shift"])
def test_vehicle_env_passes_the_gymnasium_checker(action: str) -> None:
    env = gymnasium.make(
        "sandbox/Vehicle-v0",
        scenario=PLATOON,
        agent="green",
        action=action,
        render_mode="rgb_array",
    )
    check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("action", ["commands", "shift"])
def test_formation_env_passes_the_parallel_api_test(action: str) -> None:
    env = FormationEnv(PLATOON, action=action, repeat=5)
    parallel_api_test(env, num_cycles=1000)  # 20 steps an episode, then truncated
    assert env.possible_agents == ["red", "green", "orange"]  # not the leader
    assert env.agents == []


def test_the_observation_holds_the_slot_error_and_the_nearest_neighbours() -> None:
    env = FormationEnv(PLATOON, neighbours=2)
    obs, _ = env.reset()
    red = obs["red"]
    assert red.shape == (7 + 6 * 2,) and red.dtype == np.float32
    # red starts on its slot, heading +x1, at rest, healthy.
    np.testing.assert_allclose(red[:7], [0, 0, 1, 0, 0, 0, 0], atol=1e-6)
    # From red (-1.5, 0.9): leader (0, 0) at 1.749 m, green (-1.5, -0.9) at 1.8 m,
    # orange (-3.5, 0.75) at 2.006 m; the two nearest, nearest first.
    np.testing.assert_allclose(red[7:13], [1.5, -0.9, 0, 0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(red[13:19], [0.0, -1.8, 0, 0, 0, 1], atol=1e-6)
    assert obs["red"] in env.observation_space("red")
    # After red's failure (0.5 s) its flag shows, in its own and its neighbours' views.
    env = FormationEnv(PLATOON, neighbours=3, repeat=10, action="shift")
    env.reset()
    for _ in range(7):
        obs, *_ = env.step({})
    assert obs["red"][6] == 1.0 and obs["green"][6] == 0.0
    green = obs["green"].reshape(-1)[7:].reshape(3, 6)
    assert green[:, 4].sum() == 1.0  # one failed neighbour, red


def test_the_zero_shift_is_the_scenario_and_the_return_its_error_integral() -> None:
    w = Weights(error=1.0, collision=0.0, effort=0.0)
    env = FormationEnv(PLATOON, action="shift", weights=w)
    env.reset()
    returns = dict.fromkeys(env.possible_agents, 0.0)
    while env.agents:
        zero = {a: np.zeros(2, np.float32) for a in env.agents}
        _, rewards, *_ = env.step(zero)
        for a, r in rewards.items():
            returns[a] += r
    ref = Simulation(load_scenario(PLATOON)).run()
    run = env.task.sim.result()
    np.testing.assert_array_equal(run.pose, ref.pose)  # zero action: the plain law
    error = np.linalg.norm(ref.pose[1:, :, :2] - ref.slot[1:], axis=-1)  # after steps
    for a in env.possible_agents:
        i = ref.names.index(a)
        assert returns[a] == pytest.approx(-0.01 * error[:, i].sum(), rel=1e-9)
        assert returns[a] < 0


def test_collisions_and_effort_are_charged_to_the_vehicles_involved() -> None:
    # green drives at full speed straight into red beside it (1.8 m to its left).
    doc = dict(PLATOON, duration=3.0)
    doc["vehicles"] = [dict(v) for v in PLATOON["vehicles"]]
    doc["vehicles"][2]["pose"] = [-1.5, -0.9, np.pi / 2]
    # red is wrecked where it is at 0.5 s (a stop would brake on past green's path)
    doc["failures"] = [{"vehicle": "red", "at": 0.5, "kind": "crash"}]
    hits = VehicleEnv(doc, agent="green", weights=Weights(0.0, 1.0, 0.0))
    effort = VehicleEnv(doc, agent="green", weights=Weights(0.0, 0.0, 1.0))
    totals = []
    for env in (hits, effort):
        env.reset()
        total, done = 0.0, False
        while not done:
            _, r, term, trunc, _ = env.step(np.array([1.0, 0.0], np.float32))
            total += r
            done = term or trunc
        totals.append(total)
    run = hits.task.sim.result()
    involved = [e for e in run.events if "green" in (e.a, e.b)]
    assert len(involved) >= 1 and ("green", "red") in {(e.b, e.a) for e in involved}
    assert totals[0] == -len(involved)
    # Effort: green's commands ramp from 0 to v1_max = 2 m/s at max_accel, v2 = 0:
    # total variation 2 m/s (less the first step's 0.05, not a change of commands).
    assert totals[1] == pytest.approx(-(2.0 - 0.05))


def test_reset_with_a_seed_redraws_the_randomized_starts() -> None:
    doc = dict(PLATOON)
    doc["randomize"] = {"vehicles[2].pose": {"uniform": [[-2, -1.5, 0], [-1, -0.5, 0]]}}
    env = VehicleEnv(doc, agent="green")
    a, _ = env.reset(seed=1)
    b, _ = env.reset(seed=2)
    c, _ = env.reset(seed=1)
    assert not np.array_equal(a, b) and np.array_equal(a, c)
    start = env.task.sim.observe().pose[2]
    drawn = load_scenario(dict(doc, seed=1)).vehicles[2].pose
    np.testing.assert_array_equal(start, drawn)
    # Unseeded resets follow the last seed given: the same sequence each time.
    env.reset(seed=7)
    first = [env.reset()[0] for _ in range(2)]
    env.reset(seed=7)
    again = [env.reset()[0] for _ in range(2)]
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first[0], first[1])


def test_rgb_array_frames_come_from_the_renderer() -> None:
    env = FormationEnv(PLATOON, render_mode="rgb_array", render_size=240)
    env.reset(seed=0)
    env.step({a: np.array([0.5, 0.0], np.float32) for a in env.agents})
    frame = env.render()
    assert frame.shape == (240, 240, 3) and frame.dtype == np.uint8
    # The agents are drawn in external mode (blue rings), the leader is not.
    assert np.all(frame == (0, 120, 255), axis=-1).sum() > 20
    assert FormationEnv(PLATOON).render() is None


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"agent": "gren"}, "agent: unknown vehicle 'gren'"),
        ({"action": "torque"}, "action: expected one of ('commands', 'shift')"),
        ({"repeat": 0}, "repeat: expected an integer >= 1, got 0"),
        ({"render_mode": "human"}, "render_mode: expected None or 'rgb_array'"),
    ],
)
def test_bad_arguments_are_clear_errors(kwargs, message) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        VehicleEnv(PLATOON, **kwargs)


def test_commands_need_limits_to_scale_actions_by() -> None:
    doc = dict(PLATOON, vehicle={"diameter": 0.5})
    with pytest.raises(ValueError, match="has no v1_max or v2_max"):
        FormationEnv(doc)
    env = FormationEnv(doc, max_command=(1.0, 2.0))
    env.reset()
    env.step({"red": np.array([1.0, -1.0], np.float32)})
    assert env.task.sim.fleet.v2[1] == -2.0
