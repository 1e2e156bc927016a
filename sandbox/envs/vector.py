"""Vector environments on the one loop: ``num_envs`` worlds stepped at once.

:class:`VehicleVectorEnv` is a ``gymnasium.vector.VectorEnv`` (one learning vehicle
per world) and :class:`FormationVectorEnv` gives every agent of every world, with
observations ``(num_envs, agents, features)``, actions ``(num_envs, agents, 2)`` and
rewards, terminations and truncations ``(num_envs, agents)``, as VMAS does. Both step
their worlds in :meth:`Simulation.stacked <sandbox.loop.simulation.Simulation.stacked>`:
one pass of the loop per control period for all worlds. Observations, actions and
rewards are those of :mod:`sandbox.envs.core`, computed for all worlds at once.

Autoreset is Gymnasium 1.x's ``next-step`` mode: the step after a world's episode
ends returns that world's first observation of a new episode (reward 0, neither
terminated nor truncated) and ignores its action. Worlds whose episodes start at the
same step share one stacked simulation (a *cohort*); a world that ends early (a
diverged state) starts again in a cohort of its own. World ``k`` of
``reset(seed=s)`` is the episode a single :class:`~sandbox.envs.VehicleEnv` gives
for ``reset(seed=s + k)``, and later episodes draw their seeds as that environment
does.
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
    default_agents,
    driven_commands,
)
from sandbox.loop.simulation import Simulation
from sandbox.scenario import Scenario

#: Most worlds of one vector environment.
MAX_ENVS = 65_536


class VectorTask:
    """``num_envs`` episodes of a :class:`~sandbox.envs.core.Task`, stepped together."""

    def __init__(self, task: Task, num_envs: int) -> None:
        if (
            isinstance(num_envs, bool)
            or not isinstance(num_envs, int | np.integer)
            or not 1 <= num_envs <= MAX_ENVS
        ):
            raise ValueError(
                f"num_envs: expected an integer from 1 to {MAX_ENVS}, got {num_envs!r}"
            )
        self.task, self.K = task, int(num_envs)
        self.m, self.n = len(task.agents), len(task.names)
        self.cohorts: list[tuple[Simulation, np.ndarray]] = []
        self.where = np.zeros((self.K, 2), dtype=np.intp)  # (cohort, world in it)
        self.ended = np.zeros(self.K, dtype=bool)
        self.rngs: list[Any] = [None] * self.K
        self.episodes = np.zeros(self.K, dtype=np.int64)
        self.last_terms = np.zeros((self.K, self.m, 3))
        self._index = {name: i for i, name in enumerate(task.names)}

    # ------------------------------------------------------------------ episodes
    def reset(self, seed: int | None) -> None:
        """Start every world's episode; world ``k`` with ``seed + k`` (if given)."""
        for k in range(self.K):
            if seed is not None:
                self.rngs[k], _ = seeding.np_random(int(seed) + k)
            self.episodes[k] = 0
        self.cohorts = []
        self._start(np.arange(self.K), seed)

    def _seed(self, k: int, seed: int | None) -> int | None:
        """World ``k``'s scenario seed for its next episode (as ``VehicleEnv``)."""
        first = self.episodes[k] == 0
        self.episodes[k] += 1
        if seed is not None and first:
            return int(seed) + k
        if first and self.rngs[k] is None:
            return None
        if self.rngs[k] is None:
            own = self.task.source.scenario.seed
            self.rngs[k], _ = seeding.np_random(own)
        return int(self.rngs[k].integers(SEED_RANGE))

    def _start(self, worlds: np.ndarray, seed: int | None = None) -> None:
        """New episodes of ``worlds``, in one new cohort."""
        scenarios = [self.task.source.load(self._seed(int(k), seed)) for k in worlds]
        sim = Simulation.stacked(scenarios)
        c = len(self.cohorts)
        self.cohorts.append((sim, np.array(worlds, dtype=np.intp)))
        self.where[worlds, 0] = c
        self.where[worlds, 1] = np.arange(len(worlds))
        self.ended[worlds] = False
        self.last_terms[worlds] = 0.0
        self._compact()

    def _compact(self) -> None:
        """Drop cohorts that no world is in any more; renumber the others."""
        alive = [
            c
            for c, (_, worlds) in enumerate(self.cohorts)
            if np.any(self.where[worlds, 0] == c)
        ]
        if len(alive) == len(self.cohorts):
            return
        number = {old: new for new, old in enumerate(alive)}
        self.cohorts = [self.cohorts[c] for c in alive]
        self.where[:, 0] = [number[int(c)] for c in self.where[:, 0]]

    # ------------------------------------------------------------------ stepping
    def step(self, actions: np.ndarray) -> tuple[np.ndarray, ...]:
        """Apply actions ``(K, m, 2)``; rewards ``(K, m)``, reset flags ``(K,)``.

        Worlds whose episode had ended are reset instead (their action ignored).
        """
        if not self.cohorts:
            raise RuntimeError("step() before reset(): call reset() first")
        a = _float_actions(actions)
        if a.shape != (self.K, self.m, 2) or not np.isfinite(a).all():
            raise ValueError(
                f"actions: expected {self.K * self.m * 2} finite numbers, shape "
                f"({self.K}, {self.m}, 2), got shape {a.shape}"
                + ("" if a.shape != (self.K, self.m, 2) else " with NaN or inf")
            )
        a = np.clip(a, -1.0, 1.0)
        restarted = self.ended.copy()
        rewards = np.zeros((self.K, self.m))
        for c, (sim, worlds) in enumerate(self.cohorts):
            mine = worlds[(self.where[worlds, 0] == c) & ~restarted[worlds]]
            if len(mine):
                rewards[mine] = self._advance(sim, worlds, mine, a)
        self.reset_ended(restarted)
        return rewards, restarted

    def reset_ended(self, worlds: np.ndarray | None = None) -> np.ndarray:
        """Start the next episodes of the worlds whose episode has ended, now.

        ``worlds`` (a mask, ``(K,)``) limits it to those; returns the mask of the
        worlds reset (in one new cohort). The next :meth:`step` steps them.
        """
        ended = self.ended.copy() if worlds is None else worlds & self.ended
        if ended.any():
            self.where[ended, 0] = -1
            self._start(np.flatnonzero(ended))
        return ended

    def _advance(
        self, sim: Simulation, worlds: np.ndarray, mine: np.ndarray, a: np.ndarray
    ) -> np.ndarray:
        """``repeat`` periods of one cohort; the rewards of its worlds ``mine``."""
        task, n, Kc = self.task, self.n, len(worlds)
        rows = np.full((Kc, n, 2), np.nan)
        local = self.where[mine, 1]
        if task.action == "commands":  # a car's: speed and steering angle
            part = driven_commands(a[mine], task.scale, task.wheelbase)
        else:
            part = a[mine] * task.max_shift
        rows[local[:, None], task.rows[None, :]] = part
        kwargs = {"commands" if task.action == "commands" else "shifts": rows}
        terms = np.zeros((Kc, self.m, 3))
        fleet, physics = sim.fleet, sim.physics.worlds
        for _ in range(task.repeat):
            if sim.done:
                break
            before = [len(world.events) for world in physics]
            last = np.stack((fleet.v1, fleet.v2), -1).reshape(Kc, n, 2)
            started = sim.k
            sim.step(**kwargs, observe=False)
            fleet = sim.fleet
            applied = np.stack((fleet.v1, fleet.v2), -1).reshape(Kc, n, 2)
            pos = fleet.pos.reshape(Kc, n, 2)
            slot = sim.plan.slot.reshape(Kc, n, 2)
            error = np.linalg.norm(slot - pos, axis=-1)
            error = np.where(np.isfinite(error), error, 0.0)
            hits = np.zeros((Kc, n))
            for j, world in enumerate(physics):
                for e in world.events[before[j] :]:
                    for who in (e.a, e.b):
                        if who in self._index:
                            hits[j, self._index[who]] += 1
            change = np.abs(applied - last) if started > 0 else np.zeros_like(last)
            effort = change[..., 0] + 0.5 * task.diameter * change[..., 1]
            step_terms = np.stack((sim.h * error, hits, effort), -1)
            terms += step_terms[:, task.rows]
        self.last_terms[mine] = terms[local]
        live, done = sim.live, sim.done
        for j, k in zip(local, mine, strict=True):
            if not live[j] or done:
                self.ended[k] = True
        w = task.weights
        return -terms[local] @ np.array([w.error, w.collision, w.effort])

    # ------------------------------------------------------------------ reading
    def features(self) -> np.ndarray:
        """Observations of every agent of every world, ``(K, m, size)`` float32.

        Built by :meth:`Task.of_worlds <sandbox.envs.core.Task.of_worlds>`, the
        single environment's builder, from each cohort's arrays (and, with
        ``platoons:`` or range readings, from its worlds' observations).
        """
        task = self.task
        out = np.zeros((self.K, self.m, task.size), dtype=np.float32)
        for c, (sim, worlds) in enumerate(self.cohorts):
            mine = worlds[self.where[worlds, 0] == c]
            if not len(mine):
                continue
            Kc, n, fl = len(worlds), self.n, sim.fleet
            local = self.where[mine, 1]
            platoon = ranges = None
            if task.platooned or task.reach is not None:
                seen = [sim.observe(int(j)) for j in local]
                if task.platooned:
                    platoon = np.array([o.platoon for o in seen], dtype=object)
                if task.reach is not None:
                    ranges = np.stack([o.ranges for o in seen])
            out[mine] = task.of_worlds(
                fl.pos.reshape(Kc, n, 2)[local],
                fl.theta.reshape(Kc, n)[local],
                fl.vel.reshape(Kc, n, 2)[local],
                sim.plan.slot.reshape(Kc, n, 2)[local],
                sim.plan.failing.reshape(Kc, n)[local],
                platoon,
                ranges,
            )
        return out

    def status(self) -> tuple[np.ndarray, np.ndarray]:
        """Per world: whether its episode terminated (diverged), truncated (ended)."""
        terminated = np.zeros(self.K, dtype=bool)
        for c, (sim, worlds) in enumerate(self.cohorts):
            statuses = None
            for j, k in enumerate(worlds):
                if self.where[k, 0] == c and self.ended[k]:
                    statuses = sim.statuses if statuses is None else statuses
                    terminated[k] = statuses[j] == "diverged"
        return terminated, self.ended & ~terminated

    def times(self) -> np.ndarray:
        """Each world's episode time [s]."""
        t = np.zeros(self.K)
        for c, (sim, worlds) in enumerate(self.cohorts):
            mine = worlds[self.where[worlds, 0] == c]
            t[mine] = sim.t
        return t


def _float_actions(actions: Any) -> np.ndarray:
    """Actions as a float array; ``ValueError`` for what is not numbers."""
    try:
        return np.asarray(actions, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"actions: expected finite numbers in [-1, 1], got {actions!r:.60}"
        ) from None


def _task(scenario, agents, kwargs) -> Task:
    source = ScenarioSource(scenario)
    return Task(source, agents=agents, **kwargs)


class VehicleVectorEnv(gym.vector.VectorEnv):
    """``num_envs`` worlds of a scenario, one vehicle of each driven by the policy.

    Parameters
    ----------
    scenario : str, Path, mapping or Scenario
        As for :class:`~sandbox.envs.VehicleEnv` (a bundled name too).
    num_envs : int
        Worlds stepped together, 1 to :data:`MAX_ENVS`.
    agent : str, optional
        The vehicle driven in every world; default the first follower.
    **kwargs
        The keyword arguments of :class:`~sandbox.envs.VehicleEnv` (``action``,
        ``neighbours``, ``repeat``, ``weights`` and the bounds).

    Examples
    --------
    >>> env = VehicleVectorEnv("paper/fig15_continuous_beta1", num_envs=4)
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape
    (4, 25)
    >>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    >>> reward.shape, truncated.dtype
    ((4,), dtype('bool'))
    """

    metadata = {"autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        scenario: str | Path | Mapping[str, Any] | Scenario,
        num_envs: int = 1,
        agent: str | None = None,
        *,
        weights: Weights | None = None,
        **kwargs: Any,
    ) -> None:
        kwargs.pop("render_mode", None)
        source = ScenarioSource(scenario)
        if agent is None:
            agent = (default_agents(source.scenario) or [None])[0]
        task = Task(
            source, agents=None if agent is None else [agent], weights=weights, **kwargs
        )
        self.vector = VectorTask(task, num_envs)
        self.num_envs = self.vector.K
        self.agent = task.agents[0]
        low, high = task.bounds()
        self.single_observation_space = spaces.Box(
            low.astype(np.float32), high.astype(np.float32), dtype=np.float32
        )
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = gym.vector.utils.batch_space(
            self.single_observation_space, self.num_envs
        )
        self.action_space = gym.vector.utils.batch_space(
            self.single_action_space, self.num_envs
        )

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode in every world; world ``k`` with ``seed + k``."""
        self.vector.reset(seed)
        return self.vector.features()[:, 0], {"t": self.vector.times()}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, ...]:
        """One step of every world (see the module docstring for autoreset)."""
        a = _float_actions(actions)
        if a.shape != (self.num_envs, 2):
            raise ValueError(
                f"actions: expected shape ({self.num_envs}, 2), got shape {a.shape}"
            )
        rewards, restarted = self.vector.step(a[:, None, :])
        terminated, truncated = self.vector.status()
        terms = self.vector.last_terms[:, 0]
        info = {
            "t": self.vector.times(),
            "error": np.where(restarted, 0.0, terms[:, 0]),
            "collisions": np.where(restarted, 0, terms[:, 1]).astype(np.int64),
            "effort": np.where(restarted, 0.0, terms[:, 2]),
        }
        return (
            self.vector.features()[:, 0],
            np.where(restarted, 0.0, rewards[:, 0]),
            terminated & ~restarted,
            truncated & ~restarted,
            info,
        )

    def reset_ended(self) -> tuple[np.ndarray, np.ndarray]:
        """Start the next episode of every world whose episode ended, at once.

        Gymnasium's next-step autoreset resets such a world in the next :meth:`step`
        (its action ignored, reward 0). Called after the step that ended them, this
        resets them now instead, as a same-step autoreset does (the adapter
        :class:`~sandbox.envs.sb3.SB3VecEnv` uses it): the next step then steps
        them. Their new episodes are those the next step would have started.

        Returns
        -------
        obs : ndarray, shape (num_envs, features), float32
            Every world's observation now: the reset worlds' first of their new
            episode.
        reset : ndarray, shape (num_envs,), bool
            The worlds reset.
        """
        reset = self.vector.reset_ended()
        return self.vector.features()[:, 0], reset


class FormationVectorEnv:
    """Every agent of ``num_envs`` worlds: arrays with a leading world axis.

    ``reset(seed)`` returns ``(obs, info)`` with ``obs`` of shape ``(num_envs,
    agents, features)``; ``step(actions)`` takes ``(num_envs, agents, 2)`` and returns
    ``(obs, rewards, terminations, truncations, info)``, the last three of shape
    ``(num_envs, agents)``. Parameters as :class:`VehicleVectorEnv`, with the keyword
    arguments of :class:`~sandbox.envs.FormationEnv` (``agents``, ``action``, ...).
    """

    def __init__(
        self,
        scenario: str | Path | Mapping[str, Any] | Scenario,
        num_envs: int = 1,
        *,
        agents: list[str] | None = None,
        **kwargs: Any,
    ) -> None:
        kwargs.pop("render_mode", None)
        self.vector = VectorTask(_task(scenario, agents, kwargs), num_envs)
        self.num_envs = self.vector.K
        self.agents = list(self.vector.task.agents)
        low, high = self.vector.task.bounds()
        self.observation_space = spaces.Box(
            low.astype(np.float32), high.astype(np.float32), dtype=np.float32
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode in every world; world ``k`` with ``seed + k``."""
        self.vector.reset(seed)
        return self.vector.features(), {"t": self.vector.times()}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, ...]:
        """One step of every agent of every world (``next-step`` autoreset)."""
        rewards, restarted = self.vector.step(actions)
        terminated, truncated = self.vector.status()
        m = len(self.agents)
        every = np.ones((1, m), dtype=bool)
        return (
            self.vector.features(),
            np.where(restarted[:, None], 0.0, rewards),
            (terminated & ~restarted)[:, None] & every,
            (truncated & ~restarted)[:, None] & every,
            {"t": self.vector.times()},
        )
