"""How the worlds of the loop end: at their duration, diverged, failed or stopped.

A world ends alone (a diverged state, a plug-in that failed): its last sample is
recorded with the plan undefined and its :class:`~sandbox.Run` is made at once, while
the other worlds go on. At the duration, or when the caller asks for the results
early, every live world records its last sample with the controller's own commands.
:class:`Ending` is a part of :class:`~sandbox.loop.simulation.Simulation`, kept apart
for its length.
"""

from __future__ import annotations

import time

import numpy as np

from sandbox.errors import PluginRunError
from sandbox.loop.plan import Plan
from sandbox.run.record import STATUS_ERROR, STATUS_INTERRUPTED, Run


class Ending:
    """How the worlds of :class:`~sandbox.loop.simulation.Simulation` end."""

    def _plugin_failed(self, w: int, exc: PluginRunError) -> None:
        """End world ``w`` with status ``error``: a plug-in raised or returned NaN.

        The sample of the time it happened is recorded as a diverged state's is (the
        plan undefined, the last commands), and ``info["error"]`` names the plug-in.
        """
        self.states[w].info["error"] = {
            "t": self.k * self.h,
            "plugin": exc.plugin,
            "message": exc.message,
        }
        self._end_world(w, STATUS_ERROR)

    def _end_world(self, w: int, status: str, last: bool = True) -> None:
        """World ``w`` ends now with ``status``; its run is made at once.

        ``last``: record its sample of now first, with the plan undefined.
        """
        if not self.live[w]:
            return
        state, fleet = self.states[w], self.fleet
        state.status = status
        if last:
            if self._cars is not None:
                self._cars.record(self.recorder.count, fleet.steer, w)
            nan = np.full((self.N, 2), np.nan)
            arrays = self.recorder.append_last(
                w,
                self.k * self.h,
                fleet.pos,
                fleet.theta,
                fleet.v1,
                fleet.v2,
                fleet.chi,
                nan,
                nan,
                fleet.mode,
                fleet.failed,
                np.full(2, np.nan),
            )
            self.tally.update(self, self.physics.in_contact(), np.array([w]))
        else:
            arrays = self.recorder.arrays(w)
        self.live[w] = False
        self._n_live -= 1
        self.physics.stop(w)
        self._runs[w] = self._make_run(w, arrays)
        if self.K == 1:
            self.plan = Plan.undefined(self.n, fleet.failed) if last else self.plan
            self._closed = True

    def _finish_all(self) -> None:
        """End the live worlds at ``t_k``: the last sample, the controller's commands.

        Before the duration the worlds end ``interrupted``.
        """
        live = self._live_worlds()
        if not live:
            self._closed = True
            return
        for w in live:
            if self.k < self.steps:
                self.states[w].status = STATUS_INTERRUPTED
                self.states[w].info["interrupted"] = {"t": self.k * self.h}
        self._recorded_target = None
        try:
            self._act(None, None)
        except PluginRunError as exc:
            for w in self._live_worlds():
                self._plugin_failed(w, exc)
        else:
            self._record(self.plan)
        for w in self._live_worlds():
            status = self.states[w].status
            self.live[w] = False
            self._n_live -= 1
            self._runs[w] = self._make_run(w, self.recorder.arrays(w), status)
        self._closed = True

    def result(self, world: int = 0) -> Run:
        """The recorded run so far (the whole run once :attr:`done`).

        The sample of the last time is recorded with the controller's own commands.
        Called before the run is done, the run ends here with status ``interrupted``.
        Further calls return the same :class:`~sandbox.run.record.Run`.
        """
        if world not in self._runs:
            self._finish_all()
        return self._runs[world]

    def results(self) -> list[Run]:
        """One :class:`~sandbox.run.record.Run` per world (see :meth:`result`)."""
        return [self.result(w) for w in range(self.K)]

    def _make_run(self, w: int, arrays: dict, status: str | None = None) -> Run:
        s, rows = self.states[w], self._rows(w)
        sc, info = s.scenario, s.info
        info["failed_at"] = s.failed_at
        if s.detection is not None:
            info["detection"] = s.detection.summary()
        info["loop_metrics"] = self.tally.result(w)
        info["wall_time"] = (time.perf_counter() - self._wall) / self.K
        info["control_time"] = self._control_time / self.K
        if self._filter is not None:
            info["safety"] = {
                "filter": sc.safety.filter,
                "infeasible_steps": 0,
                "active_steps": 0,
                **s.filter_stats,
            }
        info["steps"] = self.k
        return Run(
            names=list(s.names),
            colors=[v.color for v in sc.vehicles],
            diameter=self.fleet.diameter[rows].copy(),
            leader=s.leader,
            events=list(s.world.events),
            status=status or s.status,
            info=info,
            scenario=sc,
            **arrays,
            **({} if s.range_sensor is None else s.range_sensor.arrays()),
            **({} if self._cars is None else self._cars.arrays(w, len(arrays["t"]))),
        )
