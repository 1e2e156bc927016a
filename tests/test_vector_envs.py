"""Vector RL environments on the one loop: shapes, autoreset, world k = a single env."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

from sandbox.envs import (  # noqa: E402
    VEHICLE_ENV_ID,
    FormationEnv,
    FormationVectorEnv,
    VehicleEnv,
    VehicleVectorEnv,
)
from sandbox.envs.core import default_agents  # noqa: E402
from sandbox.scenario import load_scenario  # noqa: E402

#: A short episode (1 s, 3 periods a step: 34 steps) so that episodes end often.
DOC = {
    "duration": 1.0,
    "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 0.5},
    "formation": {"law": "rotating"},
    "recovery": {"strategy": "continuous", "beta": 1.0, "R": "3d"},
    "vehicle": {"v1_max": 1.0, "v2_max": 2.0, "max_accel": 4.0},
    "vehicles": [
        {"name": "lead", "pose": [0, 0, 0], "leader": True},
        {"name": "red", "pose": [-1.6, 1.2, 0], "offset": [-1.6, 1.2]},
        {"name": "blue", "pose": [-1.6, -1.2, 0], "offset": [-1.6, -1.2]},
    ],
    "randomize": {"vehicles[1].pose": {"uniform": [[-3, 1, -1], [-1.5, 2.5, 1]]}},
}


def test_world_k_of_the_vector_is_the_single_env_with_seed_plus_k():
    K = 3
    env = VehicleVectorEnv(DOC, num_envs=K, agent="red", repeat=3)
    assert env.observation_space.shape == (K, 25)
    obs, info = env.reset(seed=10)
    singles = [VehicleEnv(DOC, agent="red", repeat=3) for _ in range(K)]
    firsts = [s.reset(seed=10 + k)[0] for k, s in enumerate(singles)]
    assert all(np.array_equal(obs[k], firsts[k]) for k in range(K))
    rng = np.random.default_rng(0)
    ended = [False] * K
    endings = 0
    for _ in range(80):  # two episodes and more: autoresets
        a = rng.uniform(-1, 1, size=(K, 2)).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(a)
        assert obs.shape == (K, 25) and obs.dtype == np.float32
        assert reward.shape == (K,) and truncated.shape == (K,)
        for k, single in enumerate(singles):
            if ended[k]:  # next-step autoreset: the new episode's first observation
                want, r, te, tr = single.reset()[0], 0.0, False, False
            else:
                want, r, te, tr, _ = single.step(a[k])
            assert np.array_equal(obs[k], want)
            assert reward[k] == r and terminated[k] == te and truncated[k] == tr
            ended[k] = te or tr
            endings += te or tr
    assert endings >= 2 * K


def test_make_vec_builds_the_native_vector_env():
    env = gym.make_vec(
        VEHICLE_ENV_ID,
        num_envs=2,
        vectorization_mode="vector_entry_point",
        scenario=DOC,
    )
    assert isinstance(env.unwrapped, VehicleVectorEnv)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2, 25)
    obs, *_ = env.step(env.action_space.sample())
    assert obs.shape == (2, 25)


def test_the_formation_vector_env_steps_every_agent_of_every_world():
    K = 2
    env = FormationVectorEnv(DOC, num_envs=K, repeat=3)
    obs, _ = env.reset(seed=4)
    assert obs.shape == (K, 2, 25)
    single = FormationEnv(DOC, repeat=3)
    want, _ = single.reset(seed=5)
    assert np.array_equal(obs[1], np.stack([want[a] for a in single.agents]))
    truncations = 0
    for _ in range(40):
        obs, rewards, terms, truncs, info = env.step(np.zeros((K, 2, 2)))
        assert obs.shape == (K, 2, 25)
        assert rewards.shape == terms.shape == truncs.shape == (K, 2)
        truncations += truncs.all(axis=1).sum()
    assert truncations == K  # one episode each ended within 40 steps of 34


@pytest.mark.parametrize(
    "bad, match",
    [
        (0, "num_envs"),
        (10**9, "num_envs"),
        (2.5, "num_envs"),
    ],
)
def test_bad_num_envs(bad, match):
    with pytest.raises(ValueError, match=match):
        VehicleVectorEnv(DOC, num_envs=bad)


def test_bad_actions_and_stepping_before_reset():
    env = VehicleVectorEnv(DOC, num_envs=2)
    with pytest.raises(RuntimeError, match="before reset"):
        env.step(np.zeros((2, 2)))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        env.step(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.array([[np.nan, 0.0], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([["a", "b"], ["c", "d"]]))


@pytest.mark.parametrize("agent", ["red", "blue"])
def test_a_vector_env_of_one_world_is_the_single_env(agent):
    # num_envs=1 is a batch of one: its world steps as the single env does
    env = VehicleVectorEnv(DOC, num_envs=1, agent=agent, repeat=3)
    single = VehicleEnv(DOC, agent=agent, repeat=3)
    obs, _ = env.reset(seed=7)
    want, _ = single.reset(seed=7)
    assert obs.shape == (1, 25) and np.array_equal(obs[0], want)
    rng = np.random.default_rng(1)
    ended = False
    for _ in range(40):  # past the end of the first episode: an autoreset
        a = rng.uniform(-1, 1, size=(1, 2)).astype(np.float32)
        obs, reward, terminated, truncated, _ = env.step(a)
        if ended:
            want, r, te, tr = single.reset()[0], 0.0, False, False
        else:
            want, r, te, tr, _ = single.step(a[0])
        assert np.array_equal(obs[0], want)
        assert reward[0] == r and terminated[0] == te and truncated[0] == tr
        ended = te or tr


def test_a_formation_vector_env_of_one_world_steps_every_agent():
    env = FormationVectorEnv(DOC, num_envs=1, repeat=3)
    obs, _ = env.reset(seed=2)
    single = FormationEnv(DOC, repeat=3)
    want, _ = single.reset(seed=2)
    assert np.array_equal(obs[0], np.stack([want[a] for a in single.agents]))
    actions = np.full((1, 2, 2), 0.25)
    obs, rewards, terms, truncs, _ = env.step(actions)
    got = single.step({a: actions[0, k] for k, a in enumerate(single.agents)})
    assert np.array_equal(obs[0], np.stack([got[0][a] for a in single.agents]))
    assert rewards.shape == terms.shape == truncs.shape == (1, 2)
    assert rewards[0].tolist() == [got[1][a] for a in single.agents]


def test_make_vec_of_one_world_steps():
    env = gym.make_vec(
        VEHICLE_ENV_ID,
        num_envs=1,
        vectorization_mode="vector_entry_point",
        scenario=DOC,
    )
    assert isinstance(env.unwrapped, VehicleVectorEnv)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (1, 25)
    for _ in range(3):
        obs, reward, *_ = env.step(env.action_space.sample())
        assert obs.shape == (1, 25) and reward.shape == (1,)


#: Every bundled traffic scenario (several platoons, merges, splits, failures).
TRAFFIC = sorted(
    p.stem for p in (Path(__file__).parents[1] / "scenarios" / "traffic").glob("*.yaml")
)


def lockstep(doc: dict, agent: str, steps: int, **kwargs: object) -> None:
    """The vector env's worlds observe as single envs do, step for step."""
    K = 2
    env = VehicleVectorEnv(doc, num_envs=K, agent=agent, repeat=2, **kwargs)
    singles = [VehicleEnv(doc, agent=agent, repeat=2, **kwargs) for _ in range(K)]
    obs, _ = env.reset(seed=3)
    assert obs.shape == (K, *env.single_observation_space.shape)
    for k, single in enumerate(singles):
        np.testing.assert_array_equal(obs[k], single.reset(seed=3 + k)[0])
    rng = np.random.default_rng(1)
    ended = [False] * K
    for _ in range(steps):
        a = rng.uniform(-1, 1, size=(K, 2)).astype(np.float32)
        obs, reward, terminated, truncated, _ = env.step(a)
        for k, single in enumerate(singles):
            want = single.reset()[0] if ended[k] else single.step(a[k])[0]
            np.testing.assert_array_equal(obs[k], want)
            assert env.single_observation_space.contains(obs[k])
            ended[k] = bool(terminated[k] or truncated[k])


@pytest.mark.parametrize("name", TRAFFIC)
def test_the_vector_env_observes_every_traffic_scenario_as_the_single_env(name):
    # v0.3: every platoons: scenario crashed at reset() (no same-platoon flags in
    # the vector env's observations: shapes (3, 1, 25) against (28,)).
    doc = load_scenario(f"traffic/{name}").to_dict()  # its own events and failures
    agent = default_agents(load_scenario(doc))[-1]
    lockstep(doc, agent, steps=40)


def test_the_vector_env_observes_the_range_readings_as_the_single_env():
    # v0.3: observe=("neighbours", "ranges") crashed the vector env at reset().
    doc = load_scenario("traffic/merge_split").to_dict()
    doc["sensors"] = {"range": {"beams": 8, "max_range": 5.0}}
    lockstep(doc, "b1", steps=40, observe=("neighbours", "ranges"))
    lockstep(doc, "b1", steps=5, observe=("ranges",))


def test_reset_ended_starts_the_next_episodes_the_next_step_would_start():
    # Two copies of one vector env run to the end of their episodes (1 s): one resets
    # by the next step (Gymnasium's next-step autoreset), the other by reset_ended()
    # at once (SB3's same-step reset); they then go on alike.
    K = 3
    step_env, now_env = (
        VehicleVectorEnv(DOC, num_envs=K, agent="red", repeat=3) for _ in range(2)
    )
    step_env.reset(seed=4)
    obs, _ = now_env.reset(seed=4)
    same, reset = now_env.reset_ended()  # nothing ended yet: nothing reset
    assert not reset.any() and np.array_equal(same, obs)
    rng = np.random.default_rng(2)
    done = np.zeros(K, dtype=bool)
    while not done.any():
        a = rng.uniform(-1, 1, size=(K, 2)).astype(np.float32)
        step_env.step(a)
        _, _, terminated, truncated, _ = now_env.step(a)
        done = terminated | truncated
    assert done.all()  # every world at the duration
    want, reward, *_ = step_env.step(np.zeros((K, 2), dtype=np.float32))
    got, reset = now_env.reset_ended()
    assert reset.all() and not reward.any()
    np.testing.assert_array_equal(got, want)
    for _ in range(5):
        a = rng.uniform(-1, 1, size=(K, 2)).astype(np.float32)
        one, two = step_env.step(a), now_env.step(a)
        for x, y in zip(one[:4], two[:4], strict=True):
            np.testing.assert_array_equal(x, y)
