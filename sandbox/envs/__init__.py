"""Reinforcement-learning environments over the step-wise simulation (extra ``rl``).

- :class:`FormationEnv`: a PettingZoo ``ParallelEnv``, one agent per follower;
- :class:`VehicleEnv`: a Gymnasium ``Env`` for one vehicle among the fleet, also
  registered as ``gymnasium.make("sandbox/Vehicle-v0", scenario=..., agent=...)``;
- :class:`VehicleVectorEnv` and :class:`FormationVectorEnv`: ``num_envs`` worlds in
  the one loop (:mod:`sandbox.envs.vector`); ``gymnasium.make_vec("sandbox/Vehicle-v0",
  num_envs=K, vectorization_mode="vector_entry_point", scenario=...)`` builds the
  first.

Observations, actions and rewards are defined in :mod:`sandbox.envs.core`. Install
with ``pip install 'platoon-sandbox[rl]'`` (gymnasium and pettingzoo).
"""

from __future__ import annotations

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

__all__ = [
    "VEHICLE_ENV_ID",
    "FormationEnv",
    "FormationVectorEnv",
    "Task",
    "VehicleEnv",
    "VehicleVectorEnv",
    "Weights",
]
