"""The vector environment as a stable-baselines3 ``VecEnv`` (extra ``sb3``).

stable-baselines3 (SB3) trains on its own vector interface, ``VecEnv``, whose
environments reset *in the same step* as their episodes end: the observation returned
with ``done`` is the first of the next episode, and the last one of the ended episode
is in ``info["terminal_observation"]``. :class:`~sandbox.envs.VehicleVectorEnv`
resets in the *next* step (Gymnasium 1.x). :class:`SB3VecEnv` adapts the one to the
other: the worlds whose episodes end in a step (all of them at the scenario's
duration, or one alone with a diverged state) start their next episodes at once
(:meth:`VehicleVectorEnv.reset_ended <sandbox.envs.VehicleVectorEnv.reset_ended>`)
and their first observations are returned, so SB3 sees exactly what its own
``DummyVecEnv`` over as many :class:`~sandbox.envs.VehicleEnv` would give, one loop
stepping every world.

Seeds follow SB3's convention, which is the vector environment's: ``seed(s)`` makes
the next :meth:`SB3VecEnv.reset` start world ``k`` with ``s + k``.

Example
-------
>>> from stable_baselines3 import PPO  # doctest: +SKIP
>>> env = SB3VecEnv("failures/follower_stop", num_envs=16, agent="orange",
...                 action="shift", repeat=10)  # doctest: +SKIP
>>> PPO("MlpPolicy", env).learn(10_000)  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sandbox._about import install_hint
from sandbox.envs.vector import VehicleVectorEnv
from sandbox.scenario import Scenario

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError as error:  # pragma: no cover - exercised without the extra
    raise ImportError(
        f"sandbox.envs.sb3 needs the 'sb3' extra ({error.name} is missing): "
        f"{install_hint('sb3')}"
    ) from error

__all__ = ["SB3VecEnv"]


class SB3VecEnv(VecEnv):
    """``num_envs`` worlds of a scenario as a stable-baselines3 ``VecEnv``.

    Parameters
    ----------
    scenario : str, Path, mapping, Scenario or VehicleVectorEnv
        A scenario as for :class:`~sandbox.envs.VehicleVectorEnv`, or such an
        environment already built (then ``num_envs`` and the keywords are unused).
    num_envs : int
        Worlds stepped together.
    agent : str, optional
        The vehicle the policy drives in every world; default the first follower.
    **kwargs
        The keyword arguments of :class:`~sandbox.envs.VehicleEnv` (``action``,
        ``neighbours``, ``repeat``, ``weights`` and the bounds).

    Attributes
    ----------
    env : VehicleVectorEnv
        The vector environment stepped.
    """

    def __init__(
        self,
        scenario: str | Path | Mapping[str, Any] | Scenario | VehicleVectorEnv,
        num_envs: int = 1,
        agent: str | None = None,
        **kwargs: Any,
    ) -> None:
        if isinstance(scenario, VehicleVectorEnv):
            self.env = scenario
        else:
            self.env = VehicleVectorEnv(scenario, num_envs, agent, **kwargs)
        self.actions: np.ndarray | None = None
        super().__init__(
            self.env.num_envs,
            self.env.single_observation_space,
            self.env.single_action_space,
        )

    # ------------------------------------------------------------------ stepping
    def reset(self) -> np.ndarray:
        """Start every world's episode; world ``k`` with ``seed + k`` after seed()."""
        seeds = list(self._seeds)
        first = seeds[0]
        if first is None and any(s is not None for s in seeds):
            raise ValueError(
                f"seeds: every world seeded or none, got {seeds!r}: SB3VecEnv seeds "
                "world k with seed + k (seed(s))"
            )
        if first is not None and seeds != [int(first) + k for k in range(len(seeds))]:
            raise ValueError(
                f"seeds: expected seed + k for world k (seed(s)), got {seeds!r}"
            )
        obs, info = self.env.reset(seed=first)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{"t": float(t)} for t in info["t"]]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Keep the actions, shape (num_envs, 2) in [-1, 1], for :meth:`step_wait`."""
        self.actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, 2)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        """Step every world; reset those whose episode ended (see the module notes).

        Returns
        -------
        obs : ndarray, shape (num_envs, features), float32
        rewards : ndarray, shape (num_envs,), float32
        dones : ndarray, shape (num_envs,), bool
        infos : list of dict
            Per world: ``t``, ``error``, ``collisions``, ``effort`` (as
            :class:`~sandbox.envs.VehicleEnv`), ``TimeLimit.truncated``, and at an
            episode's end ``terminal_observation``.
        """
        if self.actions is None:
            raise RuntimeError("step_wait() without step_async(): call step() instead")
        obs, reward, terminated, truncated, info = self.env.step(self.actions)
        self.actions = None
        done = terminated | truncated
        infos = [
            {
                "t": float(info["t"][k]),
                "error": float(info["error"][k]),
                "collisions": int(info["collisions"][k]),
                "effort": float(info["effort"][k]),
                "TimeLimit.truncated": bool(truncated[k] and not terminated[k]),
            }
            for k in range(self.num_envs)
        ]
        for k in np.flatnonzero(done):
            infos[k]["terminal_observation"] = obs[k].copy()
        if done.any():  # the ended episodes' next ones start at once (SB3's reset)
            obs, _ = self.env.reset_ended()
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        """Nothing to release: the worlds live in this process."""

    # ------------------------------------------------------------------ attributes
    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """An attribute of the vector environment, once per world asked."""
        value = getattr(self.env, attr_name)
        return [value] * len(self.world_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Set an attribute of the vector environment (shared by every world)."""
        setattr(self.env, attr_name, value)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: Any = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        """Call a method of the vector environment once; its result per world asked."""
        result = getattr(self.env, method_name)(*method_args, **method_kwargs)
        return [result] * len(self.world_indices(indices))

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        """No world is wrapped in a Gymnasium wrapper."""
        return [False] * len(self.world_indices(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        """No frames: render a recorded run with :mod:`sandbox.render` instead."""
        return [None] * self.num_envs

    def world_indices(self, indices: None | int | Iterable[int]) -> list[int]:
        """The worlds ``indices`` names: all (None), one, or several."""
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int | np.integer):
            return [int(indices)]
        return [int(k) for k in indices]
