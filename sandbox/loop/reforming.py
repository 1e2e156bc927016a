"""One formation law for K worlds that re-form apart (reconfiguration and handover).

Without ``reconfigure:`` and ``on_leader_failure:`` the worlds of a loop share their
leader's index and their law's history, and the loop evaluates one law on the rows of
all worlds (``(K, n, 2)``). A reconfiguration (:mod:`sandbox.behaviour.reconfigure`)
changes one world's leader, offsets and estimators at that world's own events.
:class:`ReformingLaw` keeps the one law through them:

- each world has its own leader index, and the leader's pose is gathered world by
  world (:func:`leader_pose`);
- the law's offsets are the offsets of all worlds (a view of the fleet's), which the
  loop overwrites with each world's new ones after an event;
- each estimator of eqs. (8)-(9) and (18)-(19) keeps a history per world
  (:class:`~sandbox.model.laws.BatchDifference`), so that a world re-seeded at its
  event restarts its own history alone.

At an event the world's reconfiguration acts on the world's own law, evaluated on its
rows alone (:meth:`ReformingLaw.before_event` first gives that law the tangent angle
of eq. (15), the one state of the law's slots besides the offsets and the leader);
after it, the world's re-seeded estimators are spliced into the one law
(:meth:`ReformingLaw.after_event`). The worlds whose leader the virtual leader
replaced (``on_leader_failure: virtual``) follow a second law, the virtual leader's
of eq. (13), with each world's tangent angle where the reference rests. Only the
built-in laws are evaluated this way, since the loop knows their state (offsets,
estimators, tangent); a plug-in law is called world by world while its worlds can
re-form. Each world's numbers are those it has alone (``tests/test_one_loop.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.loop.layout import Layout
from sandbox.model.laws import (
    BackwardDifference,
    BatchDifference,
    LawInputs,
    VirtualLeaderFormation,
)
from sandbox.plugins.registration import LawContext, make_law


class ReformingLaw:
    """The built-in law of K worlds that re-form apart, as one (module docstring).

    Parameters
    ----------
    spec : FormationSpec
        The worlds' ``formation:`` (one law, one set of values).
    offset : ndarray, shape (K, n, 2) [m]
        The offsets of every world, a view of the fleet's (events write them).
    h : float [s]
    leaders : sequence of int
        Each world's leader at the start (-1: none).
    laws : list
        Each world's own law (the one its reconfiguration acts on).
    """

    def __init__(
        self, spec: Any, offset: np.ndarray, h: float, leaders: Any, laws: list
    ) -> None:
        self._offset = offset
        self._h = h
        self.law = make_law(spec.law, spec.params, offset, h)
        self.params = dict(spec.params)
        self.memory: dict = {}
        #: Each world's leader (-1: none), as its reconfiguration last set it.
        self.leaders = np.array(leaders, dtype=np.intp)
        K = len(self.leaders)
        #: The worlds whose leader the virtual leader replaced (they follow it).
        self.virtual = np.zeros(K, dtype=bool)
        #: The virtual leader's law of those worlds (eq. (13)), None before the first.
        self.virtual_law: Any = None
        self._laws = list(laws)  # each world's law object

    def targets(
        self,
        layout: Layout,
        pos: np.ndarray,
        theta: np.ndarray,
        believed: np.ndarray | None,
        ref: tuple | None,
    ) -> list:
        """Every world's slots, ``x_ref'`` and ``x_ref''``, each of shape (K n, 2)."""
        K, n, N = layout.K, layout.n, layout.N
        _, leader_pos, leader_theta = leader_pose(
            layout, pos, theta, believed, self.leaders
        )
        ctx = LawInputs(leader_pos, leader_theta, ref)  # built-in laws only
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

    def before_event(self, w: int) -> Any:
        """World ``w``'s own law, given its tangent angle of eq. (15) in the stack."""
        law = self._laws[w]
        if self.virtual[w]:
            tangent = np.broadcast_to(self.virtual_law._tangent, (len(self.virtual), 1))
            law._tangent = float(tangent[w, 0])
        else:
            law._tangent = self.law._tangent
        return law

    def after_event(self, w: int, law: Any, leader: int) -> None:
        """Take in world ``w``'s re-formed law (its leader and re-seeded estimators).

        Called after an event that changed the world's configuration: its own law
        was re-seeded on the new offsets and leader, or replaced by the virtual
        leader's (``on_leader_failure: virtual``), which it follows from now on in
        :attr:`virtual_law`.
        """
        if law is not self._laws[w]:  # the virtual leader took over
            self._laws[w] = law
            self._join_virtual(w, law)
        if self.virtual[w]:
            self._set_tangent(w, law._tangent)
            return
        self.leaders[w] = leader
        for name, value in vars(self.law).items():
            if not isinstance(value, BackwardDifference):
                continue
            if not isinstance(value, BatchDifference):
                value = BatchDifference.taking_over(value, len(self.leaders))
                setattr(self.law, name, value)
            value.restart(w, getattr(law, name))

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


def law_context(
    layout: Layout,
    t: float,
    pos: np.ndarray,
    theta: np.ndarray,
    vel: np.ndarray,
    offset: np.ndarray,
    believed: np.ndarray | None,
    ref: tuple | None,
    leaders: np.ndarray | int,
    params: dict[str, Any],
    memory: dict[str, Any],
    **extra: Any,
) -> LawContext:
    """What one law of K worlds sees: arrays with a leading world axis.

    ``leaders`` is the leader's index, one for every world (an int) or each world's
    (an array of K); the leader's pose, shape (K, 1, 2) and (K, 1), is the believed
    one (the truth without sensing); ``extra`` are further fields (the range
    readings).
    """
    K, n = layout.K, layout.n
    lead, leader_pos, leader_theta = leader_pose(layout, pos, theta, believed, leaders)
    return LawContext(
        t=t,
        dt=layout.h,
        pos=pos.reshape(K, n, 2),
        theta=theta.reshape(K, n),
        vel=vel.reshape(K, n, 2),
        offset=offset.reshape(K, n, 2),
        leader=lead,
        leader_pos=leader_pos,
        leader_theta=leader_theta,
        reference=ref,
        params=params,
        memory=memory,
        **extra,
    )


def leader_pose(
    layout: Layout,
    pos: np.ndarray,
    theta: np.ndarray,
    believed: np.ndarray | None,
    leaders: np.ndarray | int,
) -> tuple[np.ndarray | int, np.ndarray | None, np.ndarray | None]:
    """The leader's index, and every world's leader's believed position and heading.

    ``leaders`` as for :func:`law_context`; the pose None without a leader.
    """
    K, n = layout.K, layout.n
    src = pos if believed is None else believed[:, :2]
    heading = theta if believed is None else believed[:, 2]
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
