"""``VehicleEnv``: a Gymnasium environment for one vehicle among the fleet.

The chosen vehicle follows the agent's actions; every other vehicle runs its own law,
recovery strategy and failures as the scenario says. Observation, action and reward
are those of :mod:`sandbox.envs.core`; ``info`` holds the step's unweighted reward
terms (``error``, ``collisions``, ``effort``) and the time ``t``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

from sandbox.envs.core import (
    SEED_RANGE,
    ScenarioSource,
    Task,
    Weights,
    action_row,
    default_agents,
)
from sandbox.scenario import Scenario


class VehicleEnv(gym.Env):
    """One vehicle of a scenario driven by a policy, the others by their laws.

    Parameters
    ----------
    scenario : str, Path, mapping or Scenario
        The scenario (a file or a document, so that :meth:`reset` re-draws its
        ``randomize:`` section with each seed).
    agent : str, optional
        Name of the vehicle to drive; default the first follower (neither the leader
        nor open-loop).
    action : {"commands", "shift"}
        What an action sets: the vehicle's ``(v1, v2)`` scaled by its limits, or a
        shift of its target (see :mod:`sandbox.envs.core`).
    neighbours : int
        Nearest other vehicles in the observation (``k``).
    repeat : int
        Control periods per step, the action held.
    weights : Weights, optional
        Reward weights; default ``Weights()`` (error 1, collision 10, effort 0.1).
    render_mode : {None, "rgb_array"}
        ``"rgb_array"``: :meth:`render` returns the current frame of the renderer.
    **bounds
        ``max_distance``, ``max_speed``, ``max_shift``, ``max_command``,
        ``render_size`` and ``observe`` (``("neighbours", "ranges")`` adds the range
        sensor's readings) of :class:`~sandbox.envs.core.Task`.

    Notes
    -----
    An episode lasts the scenario's ``duration`` and ends ``truncated``; a diverged
    state ends it ``terminated``. ``reset(seed=s)`` loads the scenario with
    ``seed: s``; ``reset()`` without a seed starts the first episode with the
    scenario's own seed and later ones with seeds drawn from the environment's
    generator (seeded by the last seed given, else by the scenario's).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}

    def __init__(
        self,
        scenario: str | Path | Mapping[str, Any] | Scenario,
        agent: str | None = None,
        *,
        action: str = "commands",
        neighbours: int = 3,
        repeat: int = 1,
        weights: Weights | None = None,
        render_mode: str | None = None,
        **bounds: Any,
    ) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(
                f"render_mode: expected None or 'rgb_array', got {render_mode!r}"
            )
        source = ScenarioSource(scenario)
        if agent is None:
            agent = (default_agents(source.scenario) or [None])[0]
        self.task = Task(
            source,
            agents=None if agent is None else [agent],
            action=action,
            neighbours=neighbours,
            repeat=repeat,
            weights=weights,
            **bounds,
        )
        self.agent = self.task.agents[0]
        low, high = self.task.bounds()
        self.observation_space = spaces.Box(
            low.astype(np.float32), high.astype(np.float32), dtype=np.float32
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.render_mode = render_mode
        h = self.task.source.scenario.dt * self.task.repeat
        self.metadata = {**self.metadata, "render_fps": 1.0 / h}
        self._episodes = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; see the class notes for the seed."""
        super().reset(seed=seed)
        if seed is not None:
            scenario_seed = int(seed)
        elif self._episodes == 0:
            scenario_seed = None
        else:
            if self._np_random is None:
                own = self.task.source.scenario.seed
                self._np_random, self._np_random_seed = seeding.np_random(own)
            scenario_seed = int(self.np_random.integers(SEED_RANGE))
        self._episodes += 1
        obs = self.task.start(scenario_seed)
        return self.task.features()[0], {"t": obs.t}

    def step(
        self, action: np.ndarray
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply ``action`` for ``repeat`` control periods."""
        reward = self.task.advance(action_row(action)[None, :])
        terminated = self.task.diverged
        truncated = self.task.over and not terminated
        info = self.task.info(0)
        return (
            self.task.features()[0],
            float(reward[0]),
            bool(terminated),
            bool(truncated),
            info,
        )

    def render(self) -> np.ndarray | None:
        """The current frame (``render_mode="rgb_array"``), else None."""
        if self.render_mode == "rgb_array":
            return self.task.frame()
        return None
