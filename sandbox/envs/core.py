"""What both environments share: episodes, observations, actions, rewards, frames.

Pure numpy over the step-wise API of :class:`~sandbox.loop.simulation.Simulation`; the
Gymnasium and PettingZoo classes (``vehicle.py``, ``formation.py``) only wrap it in
their interfaces.

Observation of an agent (vehicle ``i``), a float32 vector of ``7 + 6 k`` entries, all
in the world frame:

- ``[0:2]`` the pose error to its slot, ``slot_i - pos_i`` [m] (zero without a slot);
- ``[2:4]`` its heading, ``(cos x3, sin x3)``;
- ``[4:6]`` its velocity [m/s];
- ``[6]`` its failed flag (1 while a failure is active);
- then for each of the ``k`` nearest other vehicles, nearest first: relative position
  ``pos_j - pos_i`` [m] (2), relative velocity ``vel_j - vel_i`` [m/s] (2), failed flag
  (1), present flag (1; zeros pad the list when there are fewer than ``k`` others);
- with ``platoons:`` only, then ``k`` entries: for each of those neighbours, 1 if it
  belongs to the agent's platoon (0 otherwise, or absent). The agent's platoon's name
  is ``info["platoon"]``.
- with ``observe=("neighbours", "ranges")``, last, the agent's range-sensor readings
  ``Observation.ranges[i]`` [m] (``B`` entries, beams from ``-fov/2`` (right) to
  ``+fov/2`` (left) about the heading; ``max_range`` where nothing is hit), in
  ``[0, max_range]``; every agent needs a ``sensors.range``. ``observe=("ranges",)``
  leaves the neighbours out (``7 + B`` entries).

The single and the vector environments build them alike (:meth:`Task.of_worlds`).

Positions are clipped to ``[-max_distance, max_distance]`` and velocities to
``[-max_speed, max_speed]``, the bounds of the observation space.

Action of an agent, two numbers in ``[-1, 1]``:

- ``action="commands"``: ``(v1, v2) = (a0 v1_max, a1 v2_max)`` [m/s, rad/s], the
  vehicle's own limits (or ``max_command``), given to
  :meth:`~sandbox.loop.simulation.Simulation.step` as ``commands``; for a car
  (``model: bicycle``) the speed and the steering angle, ``(v1, delta) = (a0 v1_max,
  a1 max_steer)`` [m/s, rad], given as the turn rate ``v1 tan(delta) / L`` (at rest
  the wheels stay where they are: :func:`~sandbox.model.bicycle.steer_commands`);
- ``action="shift"``: a displacement ``max_shift (a0, a1)`` [m] of the target the
  built-in law and recovery computed, given as ``shifts`` (the law's feed-forward is
  kept, so the zero action drives exactly as the scenario's own controller).

Reward of an agent for one environment step (``repeat`` control periods of ``h``):

``r_i = -w_error sum_periods h ||slot_i - pos_i|| - w_collision c_i - w_effort u_i``

with the distance to the slot after each period [m], ``c_i`` the contact onsets that
vehicle ``i`` took part in (each vehicle-vehicle contact counts for both vehicles) and
``u_i = sum |dv1| + (d/2) |dv2|`` the total variation of its applied commands [m/s].
Over an episode the return is therefore minus the weighted sum of the time integral of
the formation error [m s], the collisions and the ``control_effort`` of
``metrics.json``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sandbox.loop.observation import Observation
from sandbox.loop.simulation import Simulation
from sandbox.render.animation import render_frame
from sandbox.run.record import (
    MODE_EXTERNAL,
    MODE_FAILED,
    STATUS_DIVERGED,
    STATUS_ERROR,
    Run,
)
from sandbox.scenario import Scenario, load_scenario

#: Action kinds, the ``action`` argument of both environments.
ACTIONS = ("commands", "shift")
#: What an observation may hold beyond the agent's own state (``observe``).
OBSERVE = ("neighbours", "ranges")
#: Entries of an agent's own part of the observation, and per neighbour.
OWN_FEATURES = 7
NEIGHBOUR_FEATURES = 6
#: Largest scenario seed drawn for an unseeded reset.
SEED_RANGE = 2**31


@dataclass(frozen=True)
class Weights:
    """Reward weights (see the module docstring).

    Attributes
    ----------
    error : float [1/(m s)]
        Per metre of distance to the slot and second.
    collision : float
        Per contact onset.
    effort : float [s/m]
        Per m/s of total variation of the commands.
    """

    error: float = 1.0
    collision: float = 10.0
    effort: float = 0.1


class ScenarioSource:
    """A scenario that can be loaded again with another seed.

    Parameters
    ----------
    scenario : str, Path, mapping or Scenario
        A YAML file or a document: reloaded with ``seed`` set, so that the
        ``randomize:`` section draws again. A loaded :class:`Scenario` is reloaded
        from its :meth:`~sandbox.scenario.Scenario.to_dict` (its draws are already
        made; the seed still moves a platoon's jitter).
    """

    def __init__(self, scenario: str | Path | Mapping[str, Any] | Scenario) -> None:
        if isinstance(scenario, Scenario):
            self.doc: Mapping[str, Any] | None = scenario.to_dict()
            self.path: Path | None = None
            self.scenario = scenario
        elif isinstance(scenario, Mapping):
            self.doc, self.path = dict(scenario), None
            self.scenario = load_scenario(self.doc)
        else:
            self.doc, self.path = None, Path(scenario)
            self.scenario = load_scenario(self.path)

    def load(self, seed: int | None) -> Scenario:
        """The scenario with ``seed`` (its own seed when None)."""
        if seed is None:
            return self.scenario
        if self.path is not None:
            return load_scenario(self.path, overrides=[f"seed={int(seed)}"])
        return load_scenario({**self.doc, "seed": int(seed)})


def action_row(value: Any, who: str = "action") -> np.ndarray:
    """An agent's action as 2 finite numbers, shape (2,); ``ValueError`` otherwise.

    The environments clip actions to ``[-1, 1]``; anything that is not two finite
    numbers (None, a scalar, a string, a NaN) is an error, as the step API gives.
    """
    expected = "2 finite numbers in [-1, 1]"
    if value is None:
        raise ValueError(f"{who}: expected {expected}, got None")
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{who}: expected {expected}, got {value!r:.60}") from None
    if a.shape != (2,):
        raise ValueError(f"{who}: expected {expected}, shape (2,), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{who}: expected {expected}, got {a.tolist()}")
    return a


def _weights(weights: Any) -> Weights:
    """Reward weights from a :class:`Weights` or a mapping, each finite and >= 0."""
    if weights is None:
        return Weights()
    if isinstance(weights, Mapping):
        unknown = set(weights) - {"error", "collision", "effort"}
        if unknown:
            raise ValueError(
                f"weights: unknown keys {sorted(map(str, unknown))} "
                "(expected error, collision, effort)"
            )
        weights = Weights(**weights)
    if not isinstance(weights, Weights):
        raise ValueError(
            "weights: expected a sandbox.envs.Weights or a mapping of error, "
            f"collision and effort, got {type(weights).__name__}"
        )
    for name in ("error", "collision", "effort"):
        value = getattr(weights, name)
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not np.isfinite(value)
            or value < 0
        ):
            raise ValueError(
                f"weights.{name}: expected a finite number >= 0, got {value!r}"
            )
    return weights


def default_agents(scenario: Scenario) -> list[str]:
    """Every vehicle that is neither the leader nor open-loop, in scenario order."""
    return [
        v.name for v in scenario.vehicles if not v.leader and v.drive.type != "commands"
    ]


class Task:
    """One episode after another of a scenario, seen by a set of agents.

    Parameters
    ----------
    scenario : str, Path, mapping, Scenario or ScenarioSource
        See :class:`ScenarioSource`.
    agents : sequence of str, optional
        Vehicles driven by actions; default every vehicle that is neither the leader
        nor open-loop (``drive: commands``).
    action : {"commands", "shift"}
    neighbours : int
        ``k``, the nearest other vehicles in each observation.
    repeat : int
        Control periods per environment step (the action is held).
    weights : Weights
    max_distance : float [m]
        Bound of the relative positions in observations.
    max_speed : float [m/s], optional
        Bound of the velocities; default twice the largest finite ``v1_max`` (5 m/s
        without one).
    max_shift : float [m], optional
        Shift of a full action with ``action="shift"``; default twice the diameter.
    max_command : (float, float), optional
        ``(v1, v2)`` [m/s, rad/s] of a full action with ``action="commands"``;
        default each vehicle's ``v1_max`` and ``v2_max``.
    render_size : int [px]
        Width and height of ``rgb_array`` frames.
    observe : sequence of str
        What follows the agent's own state: ``neighbours`` (the ``k`` nearest other
        vehicles) and/or ``ranges`` (its range-sensor readings); default
        ``("neighbours",)``.

    Raises
    ------
    ValueError
        An unknown agent or action kind, a bad number, or commands without limits.
    """

    def __init__(
        self,
        scenario: str | Path | Mapping[str, Any] | Scenario | ScenarioSource,
        *,
        agents: Sequence[str] | None = None,
        action: str = "commands",
        neighbours: int = 3,
        repeat: int = 1,
        weights: Weights | None = None,
        max_distance: float = 10.0,
        max_speed: float | None = None,
        max_shift: float | None = None,
        max_command: tuple[float, float] | None = None,
        render_size: int = 400,
        observe: Sequence[str] = ("neighbours",),
    ) -> None:
        self.source = (
            scenario
            if isinstance(scenario, ScenarioSource)
            else ScenarioSource(scenario)
        )
        sc = self.source.scenario
        names = [v.name for v in sc.vehicles]
        self.names = names
        if agents is None:
            agents = default_agents(sc)
        for a in agents:
            if a not in names:
                raise ValueError(
                    f"agent: unknown vehicle {a!r} (vehicles: {', '.join(names)})"
                )
        if not agents:
            raise ValueError("agents: the scenario has no vehicle to drive")
        twice = sorted({a for a in agents if list(agents).count(a) > 1})
        if twice:
            raise ValueError(f"agents: listed twice: {', '.join(twice)}")
        if action not in ACTIONS:
            raise ValueError(f"action: expected one of {ACTIONS}, got {action!r}")
        if int(neighbours) != neighbours or neighbours < 0:
            raise ValueError(
                f"neighbours: expected an integer >= 0, got {neighbours!r}"
            )
        if int(repeat) != repeat or repeat < 1:
            raise ValueError(f"repeat: expected an integer >= 1, got {repeat!r}")
        self.agents = list(agents)
        self.rows = np.array([names.index(a) for a in self.agents], dtype=np.intp)
        self.action = action
        self.k = int(neighbours)
        self.repeat = int(repeat)
        self.weights = _weights(weights)
        self.max_distance = _positive(max_distance, "max_distance")
        v1_limits = [v.v1_max for v in sc.vehicles if v.v1_max is not None]
        self.max_speed = _positive(
            max_speed if max_speed is not None else 2.0 * max(v1_limits, default=2.5),
            "max_speed",
        )
        self.max_shift = _positive(
            max_shift if max_shift is not None else 2.0 * sc.diameter, "max_shift"
        )
        #: Each agent's wheelbase [m] where it is a car, else NaN, shape (m,).
        self.wheelbase = np.array(
            [
                v.wheelbase if v.model == "bicycle" else np.nan
                for v in (sc.vehicles[i] for i in self.rows)
            ],
            dtype=float,
        )
        self.scale = self._command_scale(sc, max_command)
        self.render_size = int(render_size)
        observe = (observe,) if isinstance(observe, str) else tuple(observe)
        unknown = [o for o in observe if o not in OBSERVE]
        if unknown:
            raise ValueError(f"observe: expected some of {OBSERVE}, got {unknown[0]!r}")
        self.observe = observe
        if "neighbours" not in observe:
            self.k = 0
        self.size = OWN_FEATURES + NEIGHBOUR_FEATURES * self.k
        #: The range readings' bound per entry (max_range), shape (B,); None: none.
        self.reach: np.ndarray | None = None
        if "ranges" in observe:
            self.reach = self._reach(sc)
            self.size += len(self.reach)
        # With platoons: k "same platoon" flags at the end (after the neighbours).
        self.platooned = bool(sc.platoons)
        self.size += self.k if self.platooned else 0
        self.diameter = np.array([v.diameter for v in sc.vehicles], dtype=float)
        self.sim: Simulation | None = None
        self.obs: Observation | None = None
        self.history: list[tuple[Observation, np.ndarray]] = []
        self.terms = np.zeros((len(self.agents), 3))

    def _reach(self, sc: Scenario) -> np.ndarray:
        """The bound of each range entry: the agents' largest ``max_range`` [m]."""
        specs = sc.range_specs()
        blind = [a for a in self.agents if specs[self.names.index(a)] is None]
        if blind:
            raise ValueError(
                f"observe='ranges': vehicle {blind[0]!r} has no range sensor; give "
                "the scenario a sensors: {range: {...}} section"
            )
        mine = [specs[self.names.index(a)] for a in self.agents]
        width = max(s.beams for s in mine)
        reach = np.zeros(width)
        for spec in mine:
            reach[: spec.beams] = np.maximum(reach[: spec.beams], spec.max_range)
        return np.where(reach > 0, reach, max(s.max_range for s in mine))

    def _command_scale(
        self, sc: Scenario, max_command: tuple[float, float] | None
    ) -> np.ndarray | None:
        """``(v1, v2)`` of a full action for each agent, shape (m, 2)."""
        if self.action != "commands":
            return None
        if max_command is not None:
            v1, v2 = (_positive(x, "max_command") for x in max_command)
            return np.tile([v1, v2], (len(self.agents), 1))
        scale = []
        for a in self.agents:
            v = sc.vehicles[self.names.index(a)]
            if v.model == "bicycle":  # a car: its speed and steering angle
                if v.v1_max is None:
                    raise ValueError(
                        f"action='commands': car {a!r} has no v1_max to scale actions "
                        "by; set it in the scenario or pass max_command"
                    )
                scale.append((v.v1_max, v.max_steer))
                continue
            if v.v1_max is None or v.v2_max is None:
                raise ValueError(
                    f"action='commands': vehicle {a!r} has no v1_max or v2_max to "
                    "scale actions by; set them in the scenario or pass max_command"
                )
            scale.append((v.v1_max, v.v2_max))
        return np.array(scale, dtype=float)

    # ------------------------------------------------------------------ episodes
    def start(self, seed: int | None) -> Observation:
        """Begin an episode of the scenario with ``seed`` (its own when None)."""
        self.sim = Simulation(self.source.load(seed))
        self.terms = np.zeros((len(self.agents), 3))
        self.obs = self.sim.observe()
        self.history = [(self.obs, reference_point(self.sim))]
        return self.obs

    def advance(self, actions: np.ndarray) -> np.ndarray:
        """Apply the agents' actions, (m, 2) in [-1, 1], NaN rows for none.

        Returns the agents' rewards, shape (m,).
        """
        sim, w = self.sim, self.weights
        if sim is None:
            raise RuntimeError("step() before reset(): call reset() first")
        if sim.done:
            raise RuntimeError(
                f"the episode is over (status {sim.status!r} at t = {sim.t:g} s): "
                "call reset() to start another"
            )
        a = np.clip(
            np.asarray(actions, dtype=float).reshape(len(self.agents), 2), -1, 1
        )
        rows = np.full((len(self.names), 2), np.nan)
        if self.action == "commands":
            rows[self.rows] = driven_commands(a, self.scale, self.wheelbase)
            kwargs = {"commands": rows}
        else:
            rows[self.rows] = a * self.max_shift
            kwargs = {"shifts": rows}
        terms = np.zeros((len(self.agents), 3))
        for _ in range(self.repeat):
            if sim.done:
                break
            before = len(sim.world.events)
            last = np.stack((sim.fleet.v1, sim.fleet.v2), -1)
            started = sim.k
            self.obs = sim.step(**kwargs)
            applied = np.stack((sim.fleet.v1, sim.fleet.v2), -1)
            error = np.linalg.norm(self.obs.slot - self.obs.pose[:, :2], axis=-1)
            error = np.where(np.isfinite(error), error, 0.0)
            hits = np.zeros(len(self.names))
            index = {name: i for i, name in enumerate(self.names)}
            for e in sim.world.events[before:]:
                for who in (e.a, e.b):
                    if who in index:
                        hits[index[who]] += 1
            change = np.abs(applied - last) if started > 0 else np.zeros_like(last)
            effort = change[:, 0] + 0.5 * self.diameter * change[:, 1]
            step_terms = np.stack((sim.h * error, hits, effort), -1)
            terms += step_terms[self.rows]
            self.history.append((self.obs, reference_point(sim)))
        self.terms = terms
        return -terms @ np.array([w.error, w.collision, w.effort])

    def info(self, j: int) -> dict[str, float]:
        """The last step's reward terms of agent ``j``, unweighted, and the time.

        ``error`` [m s]: the formation error integrated over the step; ``collisions``:
        contact onsets; ``effort`` [m/s]: total variation of the commands.
        """
        error, hits, effort = self.terms[j]
        out = {
            "t": self.obs.t,
            "error": float(error),
            "collisions": int(hits),
            "effort": float(effort),
        }
        if self.obs.platoon is not None:  # with platoons: the agent's own
            out["platoon"] = self.obs.platoon[self.rows[j]]
        return out

    @property
    def over(self) -> bool:
        """Whether the episode has ended (duration, divergence)."""
        return self.sim is None or self.sim.done

    @property
    def diverged(self) -> bool:
        """Whether the episode ended because the state diverged."""
        return self.sim is not None and self.sim.status == "diverged"

    # ------------------------------------------------------------------ features
    def features(self) -> np.ndarray:
        """Observations of every agent, shape (m, size), float32 (:meth:`of_worlds`)."""
        obs = self.obs
        return self.of_worlds(
            obs.pose[None, :, :2],
            obs.pose[None, :, 2],
            obs.vel[None],
            obs.slot[None],
            obs.failed[None],
            None if obs.platoon is None else np.array([obs.platoon], dtype=object),
            None if obs.ranges is None else obs.ranges[None],
        )[0]

    def of_worlds(
        self,
        pos: np.ndarray,
        theta: np.ndarray,
        vel: np.ndarray,
        slot: np.ndarray,
        failed: np.ndarray,
        platoon: np.ndarray | None = None,
        ranges: np.ndarray | None = None,
    ) -> np.ndarray:
        """Observations of every agent of W worlds, shape (W, m, size), float32.

        The one builder of the single and the vector environments. ``size`` is
        ``7 + 6 k``, plus ``k`` same-platoon flags with ``platoons:``, plus ``B``
        range readings with ``observe`` ranges (see the module docstring).

        Parameters
        ----------
        pos, vel, slot : ndarray, shape (W, n, 2) [m, m/s, m]
        theta : ndarray, shape (W, n) [rad]
        failed : ndarray, shape (W, n), bool
        platoon : ndarray of str, shape (W, n), optional
            Each vehicle's platoon (:attr:`Observation.platoon`); needed with
            ``platoons:``.
        ranges : ndarray, shape (W, n, B') [m], optional
            The range readings (:attr:`Observation.ranges`); needed with ``observe``
            ranges.
        """
        low, high = self.bounds()
        base = OWN_FEATURES + NEIGHBOUR_FEATURES * self.k
        parts = [
            features_of(
                pos,
                theta,
                vel,
                slot,
                failed,
                self.rows,
                self.k,
                low[:base],
                high[:base],
            )
        ]
        if self.platooned:  # 1: the neighbour is in the agent's platoon
            parts.append(same_platoon(pos, platoon, self.rows, self.k))
        if self.reach is not None:
            W, m, width = len(pos), len(self.rows), len(self.reach)
            got = ranges[:, self.rows, :width]  # a beam a vehicle lacks reads its bound
            block = np.broadcast_to(self.reach, (W, m, width)).copy()
            block[..., : got.shape[2]] = np.where(
                np.isfinite(got), got, block[..., : got.shape[2]]
            )
            lo, hi = low[-width:], high[-width:]
            parts.append(np.clip(block, lo, hi).astype(np.float32))
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=2)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of an observation, shape (size,) each (features)."""
        d, v = self.max_distance, self.max_speed
        own = [d, d, 1, 1, v, v, 1]
        per = [d, d, 2 * v, 2 * v, 1, 1]
        flags = [1] * (self.k if self.platooned else 0)
        high = np.array(own + per * self.k + flags, dtype=float)
        low = -high
        low[6] = 0.0
        for j in range(self.k):
            base = OWN_FEATURES + NEIGHBOUR_FEATURES * j
            low[base + 4 : base + 6] = 0.0
        if self.reach is not None:
            high = np.concatenate((high, self.reach))
            low = np.concatenate((low, np.zeros(len(self.reach))))
        low[OWN_FEATURES + NEIGHBOUR_FEATURES * self.k :] = 0.0
        return low, high

    # ------------------------------------------------------------------ frames
    def frame(self) -> np.ndarray:
        """The current state drawn by the renderer, shape (size, size, 3), uint8."""
        run = self.episode_run()
        follow = "leader" if run.leader >= 0 else None
        return render_frame(run, size=self.render_size, follow=follow)

    def episode_run(self) -> Run:
        """The episode so far as a :class:`~sandbox.Run` of its observations."""
        sim = self.sim
        obs = [o for o, _ in self.history]
        n = len(self.names)
        # Agents are driven by their actions after the first sample (external mode).
        mode = np.stack([o.mode for o in obs])
        driven = mode[1:, self.rows]
        driven[driven != MODE_FAILED] = MODE_EXTERNAL
        mode[1:, self.rows] = driven
        return Run(
            t=np.array([o.t for o in obs]),
            pose=np.stack([o.pose for o in obs]),
            cmd=np.zeros((len(obs), n, 2)),
            chi=np.stack([o.chi for o in obs]),
            slot=np.stack([o.slot for o in obs]),
            target=np.stack([o.target for o in obs]),
            mode=mode,
            failed=np.stack([o.failed for o in obs]),
            reference=np.stack([p for _, p in self.history]),
            names=list(self.names),
            colors=[v.color for v in sim.scenario.vehicles],
            diameter=self.diameter.copy(),
            leader=sim.leader,
            events=list(sim.world.events),
            info=dict(sim.info),
            scenario=sim.scenario,
        )


def driven_commands(
    actions: np.ndarray, scale: np.ndarray, wheelbase: np.ndarray
) -> np.ndarray:
    """The ``(v1, v2)`` [m/s, rad/s] of the agents' actions with ``action="commands"``.

    Parameters
    ----------
    actions : ndarray, shape (..., m, 2)
        In ``[-1, 1]``.
    scale : ndarray, shape (m, 2)
        A full action: ``(v1_max, v2_max)``, or a car's ``(v1_max, max_steer)``.
    wheelbase : ndarray, shape (m,) [m]
        A car's wheelbase, NaN for a unicycle.

    Returns
    -------
    ndarray, shape (..., m, 2)
        A car's second number, a steering angle, made the turn rate ``v1 tan(delta)
        / L`` [rad/s] the loop executes.

    >>> driven_commands(np.array([[1.0, 1.0]]), np.array([[2.0, 0.5]]),
    ...                 np.array([1.0])).round(4).tolist()
    [[2.0, 1.0926]]
    """
    rows = actions * scale
    car = np.flatnonzero(np.isfinite(wheelbase))
    if len(car):
        v1, delta = rows[..., car, 0], rows[..., car, 1]
        rows[..., car, 1] = v1 * np.tan(delta) / wheelbase[car]
    return rows


def reference_point(sim: Simulation) -> np.ndarray:
    """The reference point [m] the run plans with now, (2,) (NaN: none, or undefined).

    A run that ended with its plan undefined (diverged, a plug-in that failed) has
    none.
    """
    if sim.status in (STATUS_DIVERGED, STATUS_ERROR):
        return np.full(2, np.nan)
    return sim.plan.point[0].copy()


def features_of(
    pos: np.ndarray,
    theta: np.ndarray,
    vel: np.ndarray,
    slot: np.ndarray,
    failed: np.ndarray,
    agents: np.ndarray,
    k: int,
    low: np.ndarray,
    high: np.ndarray,
) -> np.ndarray:
    """Observations of the agents of W worlds, shape (W, m, 7 + 6 k), float32.

    ``pos``, ``vel``, ``slot`` are (W, n, 2), ``theta`` and ``failed`` (W, n), and
    ``agents`` the agents' rows (m,); see the module docstring for the layout.
    """
    W, n = theta.shape
    m, i = len(agents), agents
    out = np.zeros((W, m, OWN_FEATURES + NEIGHBOUR_FEATURES * k))
    error = slot[:, i] - pos[:, i]
    out[..., 0:2] = np.where(np.isfinite(error), error, 0.0)
    out[..., 2] = np.cos(theta[:, i])
    out[..., 3] = np.sin(theta[:, i])
    out[..., 4:6] = vel[:, i]
    out[..., 6] = failed[:, i]
    if k and n > 1:
        rel = pos[:, None, :, :] - pos[:, i, None, :]  # (W, m, n, 2)
        dist = np.hypot(rel[..., 0], rel[..., 1])
        dist[:, np.arange(m), i] = np.inf  # not one's own neighbour
        take = min(k, n - 1)
        near = np.argsort(dist, axis=2, kind="stable")[..., :take]  # (W, m, take)
        w_ = np.arange(W)[:, None, None]
        a_ = np.arange(m)[None, :, None]
        block = np.zeros((W, m, take, NEIGHBOUR_FEATURES))
        block[..., 0:2] = rel[w_, a_, near]
        block[..., 2:4] = vel[w_, near] - vel[:, i][:, :, None, :]
        block[..., 4] = failed[w_, near]
        block[..., 5] = 1.0
        out[..., OWN_FEATURES : OWN_FEATURES + NEIGHBOUR_FEATURES * take] = (
            block.reshape(W, m, -1)
        )
    out = np.where(np.isfinite(out), out, 0.0)
    return np.clip(out, low, high).astype(np.float32)


def same_platoon(
    pos: np.ndarray, platoon: np.ndarray, agents: np.ndarray, k: int
) -> np.ndarray:
    """For each agent's ``k`` nearest others: 1 when in its platoon, (W, m, k) float32.

    ``pos`` is (W, n, 2) [m], ``platoon`` (W, n) the platoons' names and ``agents``
    the agents' rows (m,); the neighbours are those of :func:`features_of` (0 pads
    the list when there are fewer than ``k`` others).
    """
    W, n = platoon.shape
    m, i = len(agents), agents
    out = np.zeros((W, m, k), dtype=np.float32)
    if k and n > 1:
        rel = pos[:, None, :, :] - pos[:, i, None, :]  # (W, m, n, 2)
        dist = np.hypot(rel[..., 0], rel[..., 1])
        dist[:, np.arange(m), i] = np.inf
        take = min(k, n - 1)
        near = np.argsort(dist, axis=2, kind="stable")[..., :take]  # (W, m, take)
        w_ = np.arange(W)[:, None, None]
        out[..., :take] = platoon[w_, near] == platoon[:, i][..., None]
    return out


def _positive(value: Any, what: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a positive number, got {value!r}") from None
    if not (np.isfinite(x) and x > 0):
        raise ValueError(f"{what}: expected a positive number, got {value!r}")
    return x
