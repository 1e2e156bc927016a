"""The step-wise API of the loop: one period at a time, with overrides, and views.

:class:`StepAPI` is a part of :class:`~sandbox.loop.simulation.Simulation`, kept
apart for its length: :meth:`~StepAPI.step` (overrides of commands, targets and
shifts, for one world or K), :meth:`~StepAPI.observe`, and the names a single run's
loop always had (``names``, ``world``, ``status``, ``info``, ...), which read the
first world of a loop of K.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sandbox.behaviour.detection import Detection
from sandbox.behaviour.ranges import observation_fields
from sandbox.behaviour.reconfigure import Reconfiguration
from sandbox.loop.observation import Observation, Overrides, override_rows
from sandbox.physics.interface import Physics
from sandbox.plugins.registration import LawContext


class StepAPI:
    """The step API of :class:`~sandbox.loop.simulation.Simulation`."""

    # ------------------------------------------------------------------ the API
    @property
    def t(self) -> float:
        """Current simulated time ``t_k = k h`` [s]."""
        return self.k * self.h

    @property
    def done(self) -> bool:
        """Whether the run has reached its duration, diverged or been stopped."""
        return self._closed or self.k >= self.steps or not self._n_live

    @property
    def names(self) -> list[str]:
        """Vehicle names, in row order (of each world)."""
        return self.states[0].names

    @property
    def world(self) -> Physics:
        """The physics of the (first) world."""
        return self.physics.worlds[0]

    @property
    def status(self) -> str:
        """The (first) world's status: ``ok``, ``diverged``, ``error``, ..."""
        return self.states[0].status

    @property
    def info(self) -> dict:
        """The (first) world's description (``Run.info`` in the making)."""
        return self.states[0].info

    @property
    def detection(self) -> Detection | None:
        """The (first) world's detector (None: the oracle)."""
        return self.states[0].detection

    @property
    def reconfiguration(self) -> Reconfiguration | None:
        """The (first) world's reconfiguration (None: slots kept)."""
        return self.states[0].reconfiguration

    @property
    def broadcast(self):
        """The (first) world's broadcast (None without sensing)."""
        return self.states[0].broadcast

    @property
    def failed_at(self) -> dict[str, float]:
        """When each failed vehicle of the (first) world failed [s]."""
        return self.states[0].failed_at

    def law_context(self, t: float, ref, offset=None, memory=None) -> LawContext:
        """What the (first) world's law sees at ``t`` (see ``WorldState``)."""
        self._view_worlds()
        return self.states[0].law_context(t, ref, offset, memory)

    def observe(self, world: int = 0) -> Observation:
        """World ``world`` now, and what the built-in stack plans for this period."""
        fleet, plan, rows = self.fleet, self.plan, self._rows(world)
        ended = not self.live[world] or self._closed
        return Observation(
            t=self.k * self.h,
            names=tuple(self.names),
            pose=np.concatenate((fleet.pos[rows], fleet.theta[rows, None]), axis=1),
            vel=fleet.vel[rows].copy(),
            chi=fleet.chi[rows].copy(),
            slot=np.array(plan.slot[rows], dtype=float),
            target=np.array(plan.target[rows], dtype=float),
            mode=fleet.mode[rows].copy() if ended else plan.mode(self.N)[rows],
            failed=plan.failing[rows].copy(),
            **observation_fields(
                self.states[world].range_sensor,
                self.obstacles,
                self.scenario,
                fleet.pos[rows],
            ),
            platoon=(
                None
                if self.states[world].platoons is None
                else self.states[world].platoons.of_vehicles()
            ),
        )

    def step(
        self,
        commands: Overrides | Sequence[Overrides] = None,
        targets: Overrides | Sequence[Overrides] = None,
        shifts: Overrides | Sequence[Overrides] = None,
        observe: bool = True,
    ) -> Observation | list[Observation] | None:
        """Advance one control period ``h = dt``, with optional overrides.

        Parameters
        ----------
        commands : mapping of str to (v1, v2), or ndarray (n, 2), optional
            Commands [m/s, rad/s] replacing the controller's for the named vehicles
            this period, within the vehicle's ``v1_max``, ``v2_max`` and (on v1)
            ``max_accel``. Failures still act on top of them.
        targets : mapping of str to (x1, x2), or ndarray (n, 2), optional
            Points [m] the controller tracks this period instead of the planned
            target, as set-points (no feed-forward velocity); recovery does not shift
            them. An array takes NaN rows for "no override".
        shifts : mapping of str to (dx1, dx2), or ndarray (n, 2), optional
            Displacements [m] added to the planned target (slot plus recovery) this
            period, the law's feed-forward motion kept: a zero shift drives as the
            built-in stack does. ``targets`` win where both are given.

        observe : bool
            Whether to return the observation (False: None, the arrays untouched
            in :attr:`fleet` and :attr:`plan`).

        Returns
        -------
        Observation, or list of Observation (one per world)
            At the next step ``t_k+1``.

        Raises
        ------
        RuntimeError
            When the run is :attr:`done`.
        ValueError
            An unknown vehicle name or a malformed value.

        Notes
        -----
        With K worlds (:meth:`stacked`) each override is an array ``(K, n, 2)`` or a
        sequence of K of the above (None for none), and a list of K observations is
        returned.
        """
        if self.done:
            raise RuntimeError(
                f"the run is over (status {self.status!r} at t = {self.t:g} s); "
                "call result()"
            )
        cmd = self._override_rows(commands, "commands")
        tgt = self._override_rows(targets, "targets")
        shf = self._override_rows(shifts, "shifts")
        self._step(cmd, tgt, shifts=shf)
        if not observe:
            return None
        if self.K == 1:
            return self.observe()
        return [self.observe(w) for w in range(self.K)]

    def _override_rows(self, values, what: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The stacked ``(N, 2)`` rows and ``(N,)`` mask of one kind of override."""
        if self.K == 1 or values is None:
            return override_rows(values, self.names, what)
        if isinstance(values, np.ndarray):
            if values.shape != (self.K, self.n, 2):
                raise ValueError(
                    f"{what}: expected an array of shape ({self.K}, {self.n}, 2) or "
                    f"a sequence of {self.K} overrides, got shape {values.shape}"
                )
            names = getattr(self, "_row_names", None)
            if names is None:  # every row named by its world, for the errors
                names = [f"world {w} {v}" for w in range(self.K) for v in self.names]
                self._row_names = names
            return override_rows(values.reshape(self.N, 2), names, what)
        if len(values) != self.K:
            raise ValueError(f"{what}: expected {self.K} overrides, got {len(values)}")
        rows, mask = np.full((self.N, 2), np.nan), np.zeros(self.N, dtype=bool)
        for w, part in enumerate(values):
            got = override_rows(part, self.names, what)
            if got is not None:
                rows[self._rows(w)], mask[self._rows(w)] = got
        return (rows, mask) if mask.any() else None
