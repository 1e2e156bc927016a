"""``FormationEnv``: a PettingZoo parallel environment, one agent per follower.

Every vehicle that is neither the leader nor open-loop is an agent; the leader (and
any open-loop vehicle) runs as the scenario says. Observation, action and reward are
those of :mod:`sandbox.envs.core`. An agent missing from the actions of a step runs
its own law for that step. Each agent's ``info`` holds the step's unweighted reward
terms (``error``, ``collisions``, ``effort``) and the time ``t``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from sandbox.envs.core import SEED_RANGE, Task, Weights, action_row
from sandbox.scenario import Scenario


class FormationEnv(ParallelEnv):
    """A formation of vehicles, each follower an agent.

    Parameters
    ----------
    scenario : str, Path, mapping or Scenario
        The scenario (a file or a document, so that :meth:`reset` re-draws its
        ``randomize:`` section with each seed).
    action : {"commands", "shift"}
        What an action sets: the vehicle's ``(v1, v2)`` scaled by its limits, or a
        shift of its target (see :mod:`sandbox.envs.core`).
    neighbours : int
        Nearest other vehicles in each observation (``k``).
    repeat : int
        Control periods per step, the actions held.
    weights : Weights, optional
        Reward weights; default ``Weights()`` (error 1, collision 10, effort 0.1).
    render_mode : {None, "rgb_array"}
        ``"rgb_array"``: :meth:`render` returns the current frame of the renderer.
    agents : sequence of str, optional
        The vehicles to drive; default every follower.
    **bounds
        ``max_distance``, ``max_speed``, ``max_shift``, ``max_command``,
        ``render_size`` and ``observe`` (``("neighbours", "ranges")`` adds the range
        sensor's readings) of :class:`~sandbox.envs.core.Task`.

    Notes
    -----
    An episode lasts the scenario's ``duration`` and ends ``truncated`` for every
    agent; a diverged state ends it ``terminated``. Seeds work as in
    :class:`~sandbox.envs.vehicle.VehicleEnv`.
    """

    metadata = {
        "render_modes": ["rgb_array"],
        "name": "sandbox_formation_v0",
        "render_fps": 25,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str | Path | Mapping[str, Any] | Scenario,
        *,
        action: str = "commands",
        neighbours: int = 3,
        repeat: int = 1,
        weights: Weights | None = None,
        render_mode: str | None = None,
        agents: Sequence[str] | None = None,
        **bounds: Any,
    ) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(
                f"render_mode: expected None or 'rgb_array', got {render_mode!r}"
            )
        self.task = Task(
            scenario,
            agents=agents,
            action=action,
            neighbours=neighbours,
            repeat=repeat,
            weights=weights,
            **bounds,
        )
        self.possible_agents = list(self.task.agents)
        self.agents: list[str] = []
        low, high = self.task.bounds()
        box = (low.astype(np.float32), high.astype(np.float32))
        self._observation_spaces = {
            a: spaces.Box(*box, dtype=np.float32) for a in self.possible_agents
        }
        self._action_spaces = {
            a: spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
            for a in self.possible_agents
        }
        self.render_mode = render_mode
        h = self.task.source.scenario.dt * self.task.repeat
        self.metadata = {**self.metadata, "render_fps": 1.0 / h}
        self._rng: np.random.Generator | None = None
        self._episodes = 0

    def observation_space(self, agent: str) -> spaces.Box:
        """The observation space of ``agent`` (the same object every call)."""
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """The action space of ``agent`` (the same object every call)."""
        return self._action_spaces[agent]

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode; see :class:`~sandbox.envs.vehicle.VehicleEnv` on seeds."""
        if seed is not None:
            self._rng = np.random.default_rng(int(seed))
            scenario_seed = int(seed)
        elif self._episodes == 0:
            scenario_seed = None
        else:
            if self._rng is None:
                self._rng = np.random.default_rng(self.task.source.scenario.seed)
            scenario_seed = int(self._rng.integers(SEED_RANGE))
        self._episodes += 1
        obs = self.task.start(scenario_seed)
        self.agents = list(self.possible_agents)
        features = self.task.features()
        return (
            {a: features[j] for j, a in enumerate(self.agents)},
            {a: {"t": obs.t} for a in self.agents},
        )

    def step(self, actions: Mapping[str, np.ndarray]) -> tuple[dict, ...]:
        """Apply the agents' actions for ``repeat`` control periods."""
        unknown = set(actions) - set(self.agents)
        if unknown:
            raise ValueError(
                f"actions: not live agents: {', '.join(sorted(map(str, unknown)))} "
                f"(agents: {', '.join(self.agents)})"
            )
        rows = np.full((len(self.possible_agents), 2), np.nan)
        for j, a in enumerate(self.possible_agents):
            if a in actions:
                rows[j] = action_row(actions[a], f"actions[{a!r}]")
        reward = self.task.advance(rows)
        features = self.task.features()
        live = list(self.agents)
        terminated = self.task.diverged
        truncated = self.task.over and not terminated
        out = (
            {a: features[self.possible_agents.index(a)] for a in live},
            {a: float(reward[self.possible_agents.index(a)]) for a in live},
            {a: bool(terminated) for a in live},
            {a: bool(truncated) for a in live},
            {a: self.task.info(self.possible_agents.index(a)) for a in live},
        )
        if terminated or truncated:
            self.agents = []
        return out

    def render(self) -> np.ndarray | None:
        """The current frame (``render_mode="rgb_array"``), else None."""
        if self.render_mode == "rgb_array":
            return self.task.frame()
        return None

    def close(self) -> None:
        """Nothing to release (the episode's arrays go with the environment)."""
