"""The RL environments answer bad input with one clear error, as the step API does.

v0.2 gave tracebacks for ``step(None)``, a scalar action, ``step`` before ``reset`` and
tuple weights (at the first step), read NaN actions as "no override", turned NaN
weights into NaN rewards, accepted an agent listed twice and stepped on after the end.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("gymnasium")
pytest.importorskip("pettingzoo")

from sandbox.envs import FormationEnv, VehicleEnv, Weights  # noqa: E402

SCENARIO = {
    "name": "rl",
    "duration": 0.3,
    "reference": {"type": "line", "speed": 0.5},
    "formation": {"law": "rotating"},
    "vehicle": {"v1_max": 2.0, "v2_max": 4.0},
    "vehicles": [
        {"name": "leader", "pose": [0, 0, 0], "leader": True},
        {"name": "red", "pose": [-1, 0.5, 0], "offset": [-1, 0.5]},
        {"name": "green", "pose": [-1, -0.5, 0], "offset": [-1, -0.5]},
    ],
}


@pytest.mark.parametrize(
    ("action", "message"),
    [
        (None, "got None"),
        (0.5, "got shape ()"),
        ([0.1, 0.2, 0.3], "got shape (3,)"),
        ("fast", "got 'fast'"),
        ([np.nan, 0.0], "got [nan, 0.0]"),
        ([0.0, math.inf], "got [0.0, inf]"),
    ],
)
def test_a_bad_action_is_one_clear_error(action: object, message: str) -> None:
    env = VehicleEnv(SCENARIO, agent="red")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action: expected 2 finite numbers") as info:
        env.step(action)
    assert message in str(info.value)


def test_a_formation_agents_bad_action_names_the_agent() -> None:
    env = FormationEnv(SCENARIO)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"actions\['green'\]: expected 2 finite"):
        env.step({"red": [0.0, 0.0], "green": [np.nan, 0.0]})


def test_step_before_reset_and_after_the_end() -> None:
    env = VehicleEnv(SCENARIO, agent="red")
    with pytest.raises(RuntimeError, match=r"step\(\) before reset\(\)"):
        env.step([0.0, 0.0])
    env.reset(seed=0)
    truncated = False
    while not truncated:
        *_, truncated, _ = env.step([0.0, 0.0])
    with pytest.raises(RuntimeError, match="the episode is over"):
        env.step([0.0, 0.0])


@pytest.mark.parametrize(
    ("weights", "message"),
    [
        ((1.0, 10.0, 0.1), "weights: expected a sandbox.envs.Weights"),
        (Weights(error=math.nan), "weights.error: expected a finite number >= 0"),
        (Weights(collision=-1.0), "weights.collision: expected a finite number"),
        ({"eror": 1.0}, "weights: unknown keys ['eror']"),
    ],
)
def test_bad_weights_are_refused_at_construction(weights: object, message: str) -> None:
    with pytest.raises(ValueError) as info:
        VehicleEnv(SCENARIO, agent="red", weights=weights)
    assert message in str(info.value)


def test_weights_as_a_mapping_are_read() -> None:
    env = VehicleEnv(SCENARIO, agent="red", weights={"collision": 5.0})
    assert env.task.weights == Weights(collision=5.0)


def test_an_agent_listed_twice_is_refused() -> None:
    with pytest.raises(ValueError, match="agents: listed twice: red"):
        FormationEnv(SCENARIO, agents=["red", "red"])
