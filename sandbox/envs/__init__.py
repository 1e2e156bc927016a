"""Reinforcement-learning environments over the step-wise simulation (extra ``rl``).

- :class:`FormationEnv`: a PettingZoo ``ParallelEnv``, one agent per follower;
- :class:`VehicleEnv`: a Gymnasium ``Env`` for one vehicle among the fleet, also
  registered as ``gymnasium.make("sandbox/Vehicle-v0", scenario=..., agent=...)``;
- :class:`VehicleVectorEnv` and :class:`FormationVectorEnv`: ``num_envs`` worlds in
  the one loop (:mod:`sandbox.envs.vector`); ``gymnasium.make_vec("sandbox/Vehicle-v0",
  num_envs=K, vectorization_mode="vector_entry_point", scenario=...)`` builds the
  first;
- :class:`SB3VecEnv` (:mod:`sandbox.envs.sb3`, extra ``sb3``): the vector environment
  as a stable-baselines3 ``VecEnv``, to train SB3's algorithms on every world in one
  loop; imported on first use, so that the rest needs no stable-baselines3.

Observations, actions and rewards are defined in :mod:`sandbox.envs.core`. Install
with ``pip install 'platoon-sandbox[rl]'`` (gymnasium and pettingzoo), or
``'platoon-sandbox[sb3]'`` (those, stable-baselines3 and PyTorch).
"""

from __future__ import annotations

from typing import Any

from sandbox._about import install_hint

try:
    import gymnasium
    import pettingzoo  # noqa: F401
except ImportError as error:  # pragma: no cover - exercised without the extra
    raise ImportError(
        f"sandbox.envs needs the 'rl' extra ({error.name} is missing): "
        f"{install_hint('rl')}"
    ) from error

from sandbox.envs.core import Task, Weights
from sandbox.envs.formation import FormationEnv
from sandbox.envs.vector import FormationVectorEnv, VehicleVectorEnv
from sandbox.envs.vehicle import VehicleEnv

#: The Gymnasium id of :class:`VehicleEnv`.
VEHICLE_ENV_ID = "sandbox/Vehicle-v0"

if VEHICLE_ENV_ID not in gymnasium.registry:
    gymnasium.register(
        id=VEHICLE_ENV_ID,
        entry_point="sandbox.envs.vehicle:VehicleEnv",
        vector_entry_point="sandbox.envs.vector:VehicleVectorEnv",
    )


def __getattr__(name: str) -> Any:
    """``SB3VecEnv``, imported on first use (it needs the extra ``sb3``)."""
    if name == "SB3VecEnv":
        from sandbox.envs.sb3 import SB3VecEnv

        return SB3VecEnv
    raise AttributeError(f"module 'sandbox.envs' has no attribute {name!r}")


__all__ = [
    "VEHICLE_ENV_ID",
    "FormationEnv",
    "FormationVectorEnv",
    "Task",
    "VehicleEnv",
    "VehicleVectorEnv",
    "Weights",
]
