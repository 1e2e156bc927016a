"""The stable-baselines3 adapter (``sandbox.envs.SB3VecEnv``, extra ``sb3``).

It must be what SB3's own ``DummyVecEnv`` over as many ``VehicleEnv`` gives (the same
observations, rewards, dones, infos and terminal observations through episode ends),
pass SB3's own checker on the single world it stacks, and train.
"""

from __future__ import annotations

import importlib.util
import os
import warnings

import numpy as np
import pytest
from helpers import REPO

from sandbox import load_scenario

#: Every test imports PyTorch (seconds): the slow tier, which CI runs.
pytestmark = [
    pytest.mark.skipif(
        importlib.util.find_spec("stable_baselines3") is None
        and not os.environ.get("CI"),
        reason="needs the sb3 extra",
    ),
    pytest.mark.slow,
]

SCENARIO = "failures/follower_stop"
#: Episodes of 4 s (the failure at 3 s), an action every 0.1 s: 40 steps.
KWARGS = {"agent": "orange", "action": "shift", "repeat": 10}


def short() -> dict:
    """follower_stop cut to 4 s, as a document (re-seeded at each reset)."""
    return load_scenario(SCENARIO, overrides=["duration=4"]).to_dict()


def test_sb3s_checker_passes_the_world_the_adapter_stacks() -> None:
    from stable_baselines3.common.env_checker import check_env

    from sandbox.envs import VehicleEnv

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no advice of SB3's either
        check_env(VehicleEnv(short(), **KWARGS), warn=True)
        check_env(VehicleEnv(short(), agent="red", action="commands"), warn=True)


def test_the_adapter_is_sb3s_dummy_vec_env_over_vehicle_envs() -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

    from sandbox.envs import SB3VecEnv, VehicleEnv

    n = 3
    ours = SB3VecEnv(short(), num_envs=n, **KWARGS)
    theirs = DummyVecEnv([lambda: VehicleEnv(short(), **KWARGS) for _ in range(n)])
    assert isinstance(ours, VecEnv)
    assert ours.observation_space == theirs.observation_space
    assert ours.action_space == theirs.action_space
    assert ours.seed(7) == theirs.seed(7) == [7, 8, 9]
    np.testing.assert_array_equal(ours.reset(), theirs.reset())
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(100):  # two episodes and a half
        action = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
        obs, reward, done, infos = ours.step(action)
        obs_, reward_, done_, infos_ = theirs.step(action)
        np.testing.assert_array_equal(obs, obs_)
        np.testing.assert_array_equal(reward, reward_)
        assert reward.dtype == reward_.dtype and done.dtype == done_.dtype
        np.testing.assert_array_equal(done, done_)
        for mine, sb3s in zip(infos, infos_, strict=True):
            assert mine.keys() == sb3s.keys()
            for key, value in sb3s.items():
                np.testing.assert_array_equal(mine[key], value)
        ends += int(done.all())
    assert ends == 2  # both episode ends were crossed, each reset at once


def test_seeds_are_sb3s_seed_plus_k_or_none() -> None:
    from sandbox.envs import SB3VecEnv

    env = SB3VecEnv(short(), num_envs=2, **KWARGS)
    env.seed(3)
    first = env.reset()
    env.seed(3)
    np.testing.assert_array_equal(env.reset(), first)
    env._seeds = [3, 5]  # what SB3 never sets: refused, not silently re-seeded
    with pytest.raises(ValueError, match=r"expected seed \+ k for world k"):
        env.reset()
    assert env.get_attr("num_envs") == [2, 2]
    assert env.get_attr("agent", indices=1) == ["orange"]
    assert env.env_is_wrapped(object) == [False, False]


def test_ppo_trains_on_the_adapter_and_acts_in_every_world() -> None:
    from stable_baselines3 import PPO

    from sandbox.envs import SB3VecEnv

    env = SB3VecEnv(short(), num_envs=4, **KWARGS)
    env.seed(0)
    model = PPO("MlpPolicy", env, n_steps=16, batch_size=32, n_epochs=1, seed=0)
    model.learn(total_timesteps=64)
    assert model.num_timesteps == 64
    obs = env.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (4, 2) and np.isfinite(action).all()


def test_the_ppo_example_prints_its_returns() -> None:
    import subprocess
    import sys

    script = REPO / "examples" / "ppo_vector_env.py"
    argv = ["--steps", "256", "--envs", "4", "--eval", "2", "--duration", "4"]
    out = subprocess.run(
        [sys.executable, str(script), *argv],
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
    ).stdout
    lines = dict(line.split(": ", 1) for line in out.splitlines()[1:])
    returns = {k: float(v.split()[0]) for k, v in lines.items()}
    assert len(returns) == 4 and all(np.isfinite(list(returns.values())))
