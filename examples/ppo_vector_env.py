"""PPO from stable-baselines3 on the vector environment: 64 worlds in one loop.

Trains one follower of ``failures/follower_stop`` (orange, which must get past the
stopped red) with ``action="shift"``, whose zero action is the scenario's own
controller: the policy learns a correction of the built-in target. Prints the mean
return of the zero policy and of the trained policy over the same evaluation seeds.

Needs stable-baselines3 (and torch), which are not dependencies of sandbox::

    pip install stable-baselines3
    python examples/ppo_vector_env.py                 # 200,000 steps, a few minutes
    python examples/ppo_vector_env.py --steps 20000   # quicker

stable-baselines3 resets a finished environment in the same step and keeps the last
observation in ``info["terminal_observation"]``; the vector environment resets in the
next step (Gymnasium 1.x). :class:`SameStepReset` adapts the one to the other: when
the episodes end (they all last the scenario's duration, so they end together) it
makes the environment's reset step at once, so that stable-baselines3 sees no step
of the reset.
"""

from __future__ import annotations

import argparse

import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecEnv

from sandbox.envs import VehicleVectorEnv

SCENARIO = "failures/follower_stop"
AGENT = "orange"


class SameStepReset(VecEnv):
    """A :class:`~sandbox.envs.VehicleVectorEnv` as a stable-baselines3 ``VecEnv``."""

    def __init__(self, env: VehicleVectorEnv) -> None:
        self.env = env
        super().__init__(
            env.num_envs, env.single_observation_space, env.single_action_space
        )
        self._actions: np.ndarray | None = None
        self._seed: int | None = None

    def reset(self) -> np.ndarray:
        """Start every world's episode (seeded once by :meth:`seed`)."""
        obs, _ = self.env.reset(seed=self._seed)
        self._seed = None
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Keep the actions for :meth:`step_wait`."""
        self._actions = np.asarray(actions, dtype=np.float32)

    def step_wait(self):
        """Step every world; at the episodes' end, reset them in the same step."""
        obs, reward, terminated, truncated, info = self.env.step(self._actions)
        done = terminated | truncated
        infos = [
            {"TimeLimit.truncated": bool(truncated[k])} for k in range(self.num_envs)
        ]
        if done.any():
            if not done.all():
                raise RuntimeError(
                    "a world ended before the others (a diverged state): this example "
                    "assumes episodes of the scenario's duration"
                )
            for k in range(self.num_envs):
                infos[k]["terminal_observation"] = obs[k]
            obs, *_ = self.env.step(np.zeros_like(self._actions))  # the reset step
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        """Nothing to close."""
        pass

    def seed(self, seed: int | None = None) -> list:
        """The seed of the next reset (world k: seed + k)."""
        self._seed = seed
        return [None] * self.num_envs

    def get_attr(self, name, indices=None):
        """An attribute of the vector environment, once per world asked."""
        return [getattr(self.env, name)] * len(self._indices(indices))

    def set_attr(self, name, value, indices=None) -> None:
        """Set an attribute of the vector environment."""
        setattr(self.env, name, value)

    def env_method(self, name, *args, indices=None, **kwargs):
        """Call a method of the vector environment, once."""
        result = getattr(self.env, name)(*args, **kwargs)
        return [result] * len(self._indices(indices))

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        """No world is wrapped."""
        return [False] * len(self._indices(indices))

    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)


def mean_return(env: VehicleVectorEnv, act, seed: int) -> float:
    """The mean return of one episode in every world, actions from ``act(obs)``."""
    obs, _ = env.reset(seed=seed)
    total = np.zeros(env.num_envs)
    done = np.zeros(env.num_envs, dtype=bool)
    while not done.all():
        obs, reward, terminated, truncated, _ = env.step(act(obs))
        total += np.where(done, 0.0, reward)
        done |= terminated | truncated
    return float(total.mean())


def main(argv: list[str] | None = None) -> int:
    """Train, and print the returns before and after."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=200_000, help="training env steps")
    p.add_argument("--envs", type=int, default=64, help="worlds in the vector env")
    args = p.parse_args(argv)
    kwargs = {"agent": AGENT, "action": "shift", "repeat": 10}
    train = VehicleVectorEnv(SCENARIO, num_envs=args.envs, **kwargs)
    test = VehicleVectorEnv(SCENARIO, num_envs=16, **kwargs)

    def zero(obs: np.ndarray) -> np.ndarray:
        return np.zeros((len(obs), 2), dtype=np.float32)

    baseline = mean_return(test, zero, seed=10_000)
    venv = SameStepReset(train)
    venv.seed(0)
    # Small initial actions: the zero action is the scenario's own controller, so
    # exploration starts near it rather than with shifts of a whole max_shift.
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=64,
        batch_size=256,
        seed=0,
        verbose=0,
        policy_kwargs={"log_std_init": -1.5},
    )

    def policy(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    before = mean_return(test, policy, seed=10_000)
    model.learn(total_timesteps=args.steps)
    after = mean_return(test, policy, seed=10_000)
    print(f"mean return over 16 evaluation episodes (seeds 10000-10015), {SCENARIO}:")
    print(f"  zero policy (the scenario's own controller): {baseline:.3f}")
    print(f"  PPO before training:                         {before:.3f}")
    print(f"  PPO after {args.steps:,} env steps:             {after:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
