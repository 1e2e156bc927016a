"""One formation law for K worlds that re-form apart (reconfiguration and handover).

Without ``reconfigure:`` and ``on_leader_failure:`` the worlds of a loop share their
leader's index and their law's history, and the loop evaluates one law on the stacked
arrays (``(K, n, 2)``). A reconfiguration (:mod:`sandbox.behaviour.reconfigure`)
changes one world's leader, offsets and estimators at that world's own events.
:class:`StackedLaw` keeps the one law through them:

- each world has its own leader index, and the leader's pose is gathered world by
  world (:func:`stacked_law_context`);
- the law's offsets are the stacked offsets of all worlds, which the loop overwrites
  with each world's new ones after an event;
- each estimator of eqs. (8)-(9) and (18)-(19) keeps a history per world
  (:class:`WorldsDifference`), so that a world re-seeded at its event restarts its
  own history alone.

At an event the world's reconfiguration acts on the world's own law as a single run
does (:meth:`StackedLaw.before_event` first gives that law the tangent angle of eq.
(15), the one state of the law's slots besides the offsets and the leader); after it,
the world's re-seeded estimators are spliced into the stacked law
(:meth:`StackedLaw.after_event`). The worlds whose leader the virtual leader replaced
(``on_leader_failure: virtual``) follow a second stacked law, the virtual leader's of
eq. (13), with each world's tangent angle where the reference rests. Only the
built-in laws are stacked this way, since the loop knows their state (offsets,
estimators, tangent); a plug-in law is called world by world while its worlds can
re-form. Each world's numbers are those it has alone (``tests/test_one_loop.py``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox.behaviour.ranges import context_fields
from sandbox.model.laws import BackwardDifference, LawInputs, VirtualLeaderFormation
from sandbox.plugins.registration import LawContext, make_law

if TYPE_CHECKING:
    from sandbox.loop.simulation import Simulation
    from sandbox.loop.worlds import WorldState


class WorldsDifference(BackwardDifference):
    """A :class:`~sandbox.model.laws.BackwardDifference` of K worlds, a history each.

    The signal has a leading world axis; world ``w``'s estimates are the numbers a
    :class:`~sandbox.model.laws.BackwardDifference` of that world alone gives, its
    history restarted by :meth:`restart`.

    Parameters
    ----------
    shared : BackwardDifference
        The estimator of all worlds so far (one history), whose state is taken over.
    K : int
        The number of worlds.
    """

    def __init__(self, shared: BackwardDifference, K: int) -> None:
        super().__init__(shared.h)
        self.count = np.full(K, shared.count, dtype=np.int64)
        self.prev_x, self.prev_v = shared.prev_x, shared.prev_v

    def update(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Feed every world's value at the current step; return ``(x', x'')``."""
        x = np.array(x, dtype=float)
        if self.prev_x is None:  # no world has a history yet
            v, a = np.zeros_like(x), np.zeros_like(x)
        else:
            count = self.count.reshape((-1,) + (1,) * (x.ndim - 1))
            v = np.where(count >= 1, (x - self.prev_x) / self.h, 0.0)  # eq. (8)
            a = np.where(count >= 2, (v - self.prev_v) / self.h, 0.0)  # eq. (9)
        self.prev_x, self.prev_v = x, v
        self.count += 1
        return v, a

    def reset(self) -> None:
        """Forget every world's history."""
        self.count[:] = 0

    def restart(self, w: int, alone: BackwardDifference) -> None:
        """Give world ``w`` the history of ``alone``, its estimator in a run alone.

        The arrays are replaced, not written into: the estimates handed out this
        period (the plan's ``x_ref'``, ``x_ref''``) may view them.
        """
        self.count[w] = alone.count
        # The stacked law has been evaluated before any event (the plan comes first).
        if alone.prev_x is None or self.prev_x is None:
            return
        for name in ("prev_x", "prev_v"):
            mine = np.array(getattr(self, name), dtype=float)
            mine[w] = getattr(alone, name)
            setattr(self, name, mine)


class StackedLaw:
    """The built-in law of K re-forming worlds as one (see the module docstring).

    Parameters
    ----------
    sim : Simulation
        The loop of K > 1 worlds; its stacked offsets are the law's.
    """

    def __init__(self, sim: Simulation) -> None:
        spec = sim.scenario.formation
        self._offset = sim.fleet.offset.reshape(sim.K, sim.n, 2)  # a view: events write
        self._h = sim.h
        self.law = make_law(spec.law, spec.params, self._offset, sim.h)
        self.params = dict(spec.params)
        self.memory: dict = {}
        #: Each world's leader (-1: none), as its reconfiguration last set it.
        self.leaders = np.array([s.leader for s in sim.states], dtype=np.intp)
        #: The worlds whose leader the virtual leader replaced (they follow it).
        self.virtual = np.zeros(sim.K, dtype=bool)
        #: The virtual leader's law of those worlds (eq. (13)), None before the first.
        self.virtual_law: Any = None
        self._laws = [s.law for s in sim.states]  # each world's law object

    def targets(self, sim: Simulation, t: float, ref: tuple | None) -> list:
        """Every world's slots, ``x_ref'`` and ``x_ref''``, each of shape (K n, 2)."""
        K, n, N = sim.K, sim.n, sim.N
        ctx = stacked_law_inputs(sim, ref, self.leaders)  # built-in laws only
        triple = [
            np.broadcast_to(a, (K, n, 2)).reshape(N, 2) for a in self.law.targets(ctx)
        ]
        if self.virtual_law is None:
            return triple
        # The virtual leader's slots of every world, taken where it leads.
        rows = np.repeat(self.virtual, n)[:, None]
        virtual = self.virtual_law.targets(ctx)
        return [
            np.where(rows, np.broadcast_to(v, (K, n, 2)).reshape(N, 2), a)
            for v, a in zip(virtual, triple, strict=True)
        ]

    def before_event(self, w: int, state: WorldState) -> None:
        """Give world ``w``'s own law its tangent angle of eq. (15) in the stack."""
        if self.virtual[w]:
            tangent = np.broadcast_to(self.virtual_law._tangent, (len(self.virtual), 1))
            state.law._tangent = float(tangent[w, 0])
        else:
            state.law._tangent = self.law._tangent

    def after_event(self, w: int, state: WorldState) -> None:
        """Take in world ``w``'s re-formed law (its leader and re-seeded estimators).

        Called after an event that changed the world's configuration: its own law
        was re-seeded on the new offsets and leader, or replaced by the virtual
        leader's (``on_leader_failure: virtual``), which it follows from now on in
        :attr:`virtual_law`.
        """
        if state.law is not self._laws[w]:  # the virtual leader took over
            self._laws[w] = state.law
            self._join_virtual(w, state.law)
        if self.virtual[w]:
            self._set_tangent(w, state.law._tangent)
            return
        self.leaders[w] = state.leader
        for name, value in vars(self.law).items():
            if not isinstance(value, BackwardDifference):
                continue
            if not isinstance(value, WorldsDifference):
                value = WorldsDifference(value, len(self.leaders))
                setattr(self.law, name, value)
            value.restart(w, getattr(state.law, name))

    def _join_virtual(self, w: int, law: Any) -> None:
        """World ``w`` follows the virtual leader (its law ``law``, without history)."""
        if not isinstance(law, VirtualLeaderFormation) or (
            self.virtual_law is not None and law.rotate != self.virtual_law.rotate
        ):
            raise RuntimeError(f"a handover to an unexpected law: {law!r}")
        if self.virtual_law is None:
            params = {"rotate": law.rotate}
            self.virtual_law = make_law("virtual", params, self._offset, self._h)
        self.virtual[w] = True

    def _set_tangent(self, w: int, angle: float) -> None:
        """World ``w``'s tangent angle [rad] in the virtual leader's law.

        One float while the reference moves (eq. (15) gives every world the same), a
        column of each world's at rest (each keeps its own last one).
        """
        law, K = self.virtual_law, len(self.virtual)
        tangent = np.array(np.broadcast_to(law._tangent, (K, 1)), dtype=float)
        tangent[w, 0] = angle
        law._tangent = tangent


def stacked_law_context(
    sim: Simulation,
    t: float,
    ref: tuple | None,
    leaders: np.ndarray | int,
    params: dict[str, Any],
    memory: dict[str, Any],
) -> LawContext:
    """What the one law of K worlds sees: arrays with a leading world axis.

    ``leaders`` is the leader's index, one for every world (an int) or each world's
    (an array of K); the leader's pose, shape (K, 1, 2) and (K, 1), is the believed
    one (:attr:`~sandbox.loop.simulation.Simulation.believed`), the truth without
    sensing.
    """
    K, n, fl = sim.K, sim.n, sim.fleet
    lead, leader_pos, leader_theta = leader_pose(sim, leaders)
    return LawContext(
        t=t,
        dt=sim.h,
        pos=fl.pos.reshape(K, n, 2),
        theta=fl.theta.reshape(K, n),
        vel=fl.vel.reshape(K, n, 2),
        offset=fl.offset.reshape(K, n, 2),
        leader=lead,
        leader_pos=leader_pos,
        leader_theta=leader_theta,
        reference=ref,
        params=params,
        memory=memory,
        **context_fields(sim.range_sensor),
    )


def stacked_law_inputs(
    sim: Simulation, ref: tuple | None, leaders: np.ndarray | int
) -> LawInputs:
    """The part of :func:`stacked_law_context` a built-in law reads, as LawInputs.

    The leader's pose and the reference (:class:`~sandbox.model.laws.LawInputs`),
    the same arrays: a built-in law reads nothing else, and the loop spares it the
    rest of the context every period.
    """
    _, leader_pos, leader_theta = leader_pose(sim, leaders)
    return LawInputs(leader_pos, leader_theta, ref)


def leader_pose(
    sim: Simulation, leaders: np.ndarray | int
) -> tuple[np.ndarray | int, np.ndarray | None, np.ndarray | None]:
    """The leader's index, and every world's leader's believed position and heading.

    ``leaders`` as for :func:`stacked_law_context`; the pose None without a leader.
    """
    K, n, fl = sim.K, sim.n, sim.fleet
    src = fl.pos if sim.believed is None else sim.believed[:, :2]
    heading = fl.theta if sim.believed is None else sim.believed[:, 2]
    if not isinstance(leaders, np.ndarray) or leaders.ndim == 0:
        lead = int(leaders)
        if lead < 0:
            return lead, None, None
        leader_pos = np.ascontiguousarray(src.reshape(K, n, 2)[:, lead : lead + 1])
        leader_theta = np.ascontiguousarray(heading.reshape(K, n)[:, lead : lead + 1])
        return lead, leader_pos, leader_theta
    # each world's own leader (-1, for a law without one: any row)
    worlds, rows = np.arange(K), np.maximum(leaders, 0)
    leader_pos = src.reshape(K, n, 2)[worlds, rows][:, None, :]
    leader_theta = heading.reshape(K, n)[worlds, rows][:, None]
    return leaders, leader_pos, leader_theta
