"""Collective-motion (formation) laws of sections 3.2-3.5, eqs. (7)-(20).

Each law turns the leader's measured state and/or the reference trajectory into, for
every
vehicle, a *slot* (the point it should occupy, [m]) and the velocity and acceleration
fed
to eq. (6) as ``x_ref'`` and ``x_ref''``. The flatness controller then tracks them; the
equations (7), (10), (13), (16) and (17) are eq. (6) with these three quantities.

Symbols: ``delta`` (n, 2) the offsets (delta1, delta2) [m]; ``Delta`` the offsets
projected
in the world frame (eqs. (11), (14), (20)); ``h`` the control period [s].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sandbox.plugins.registration import Param, RegistryView, register_law

Triple = tuple[np.ndarray, np.ndarray, np.ndarray]

#: Below this reference speed [m/s] the tangent angle of eq. (15) is undefined
#: (``atan2(0, 0)``): rotated offsets keep the last tangent direction, so that the
#: formation holds its orientation when a waypoint path ends or the reference stops
#: (a reference at rest from the start uses the world frame, angle 0).
REST_SPEED = 1e-3


def rotate_offsets(delta: np.ndarray, angle: float | np.ndarray) -> np.ndarray:
    """Project offsets given in a frame rotated by ``angle`` into the world frame.

    Implements eqs. (11), (14) and (20):
    ``Delta1 = d1 cos(a) - d2 sin(a)``, ``Delta2 = d2 cos(a) + d1 sin(a)``.

    >>> rotate_offsets(np.array([[1.0, 0.0]]), np.pi / 2).round(12).tolist()
    [[0.0, 1.0]]
    """
    c, s = np.cos(angle), np.sin(angle)
    d1, d2 = delta[..., 0], delta[..., 1]
    first, second = d1 * c - d2 * s, d2 * c + d1 * s  # eq. (11)
    out = np.empty((*first.shape, 2))
    out[..., 0], out[..., 1] = first, second
    return out


def spread(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` broadcast to ``shape``, as a new array (the values of ``broadcast_to``).

    >>> spread(np.array([1.0, 2.0]), (2, 2)).tolist()
    [[1.0, 2.0], [1.0, 2.0]]
    """
    out = np.empty(shape)
    out[...] = a
    return out


class BackwardDifference:
    """Backward-Euler estimates of a signal's first and second derivatives.

    Implements eqs. (8)-(9) (for the leader's position) and (18)-(19) (for each slot):
    ``x'(t) = (x(t) - x(t-h)) / h`` and ``x''(t) = (x'(t) - x'(t-h)) / h``.
    With no history the estimates start at zero: at the first update both are 0, at the
    second the velocity is the first difference and the acceleration is still 0 (a jump
    from the zero start would otherwise be read as a huge acceleration).

    Parameters
    ----------
    h : float [s]
        Control period.
    """

    def __init__(self, h: float) -> None:
        self.h = h
        self.count = 0
        self.prev_x: np.ndarray | None = None
        self.prev_v: np.ndarray | None = None

    def update(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Feed the signal's value at the current step; return ``(x', x'')``."""
        x = np.array(x, dtype=float)
        if self.count == 0:
            v = np.zeros_like(x)
            a = np.zeros_like(x)
        else:
            v = (x - self.prev_x) / self.h  # eq. (8) / (18)
            a = (
                (v - self.prev_v) / self.h if self.count >= 2 else np.zeros_like(x)
            )  # (9)
        self.prev_x, self.prev_v = x, v
        self.count += 1
        return v, a

    def reset(self) -> None:
        """Forget the history (the next update starts again from zero)."""
        self.count = 0
        self.prev_x = self.prev_v = None


class BatchDifference(BackwardDifference):
    """A :class:`BackwardDifference` of K worlds' signals, a history per world.

    The signal has a leading world axis; world ``w``'s estimates are the numbers a
    :class:`BackwardDifference` of that world alone gives, its history forgotten by
    :meth:`reset` or replaced by :meth:`restart` without the others'.

    Parameters
    ----------
    h : float [s]
        Control period.
    K : int
        The number of worlds.

    Examples
    --------
    >>> d = BatchDifference(0.5, 2)
    >>> _ = d.update(np.array([[0.0], [0.0]]))
    >>> d.reset(1)
    >>> d.update(np.array([[1.0], [1.0]]))[0].tolist()  # world 1 starts again
    [[2.0], [0.0]]
    """

    def __init__(self, h: float, K: int) -> None:
        super().__init__(h)
        self.count = np.zeros(K, dtype=np.int64)

    @classmethod
    def taking_over(cls, shared: BackwardDifference, K: int) -> BatchDifference:
        """The estimator of K worlds that shared ``shared``'s history so far."""
        made = cls(shared.h, K)
        made.count[:] = shared.count
        made.prev_x, made.prev_v = shared.prev_x, shared.prev_v
        return made

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

    def reset(self, w: int | None = None) -> None:
        """Forget world ``w``'s history (None: every world's)."""
        if w is None:
            self.count[:] = 0
        else:
            self.count[w] = 0

    def restart(self, w: int, alone: BackwardDifference) -> None:
        """Give world ``w`` the history of ``alone``, its estimator in a run alone.

        The arrays are replaced, not written into: the estimates handed out this
        period may view them.
        """
        self.count[w] = alone.count
        if alone.prev_x is None or self.prev_x is None:
            return
        for name in ("prev_x", "prev_v"):
            mine = np.array(getattr(self, name), dtype=float)
            mine[w] = getattr(alone, name)
            setattr(self, name, mine)


@dataclass
class LawInputs:
    """What a formation law may read at one control step.

    Attributes
    ----------
    leader_pos : ndarray, shape (2,) [m] or None
        Measured position of the real leader.
    leader_theta : float [rad] or None
        Measured heading x3 of the real leader.
    reference : tuple of ndarray (2,) or None
        ``(p, p', p'')`` of the reference trajectory at this time.
    """

    leader_pos: np.ndarray | None
    leader_theta: float | None
    reference: Triple | None


class FormationLaw:
    """Base class: computes ``(slot, x_ref', x_ref'')`` for every vehicle.

    Parameters
    ----------
    delta : ndarray, shape (n, 2) [m]
        Offsets of the vehicles.
    h : float [s]
        Control period (for the backward differences).
    rotate : bool
        For ``virtual`` and ``leader_ref``: project the offsets on the reference's
        tangent (the last one defined while the reference is at rest, see
        :data:`REST_SPEED`).
    """

    #: Whether the law needs a real leader / the reference's derivatives.
    needs_leader = True
    needs_reference = False

    def __init__(self, delta: np.ndarray, h: float, rotate: bool = False) -> None:
        self.delta = np.asarray(delta, dtype=float)
        self.h = h
        self.rotate = rotate
        self._tangent = 0.0  # angle of eq. (15) last defined [rad]

    def targets(self, inputs: LawInputs) -> Triple:
        """Return ``slot, v_ref, a_ref``, each of shape (n, 2)."""
        raise NotImplementedError

    def reseed(self) -> None:
        """Forget every estimate: each :class:`BackwardDifference` starts afresh.

        Called when another vehicle leads or the offsets change
        (:mod:`sandbox.behaviour.reconfigure`), whose jump eqs. (8)-(9) and (18)-(19)
        would otherwise read as a velocity and an acceleration (1 m in h = 0.01 s: 100
        m/s and 1e4 m/s^2).
        """
        for value in vars(self).values():
            if isinstance(value, BackwardDifference):
                value.reset()

    def _reference_offsets(self, reference: Triple) -> np.ndarray:
        """Offsets in the world frame, rotated by the reference's tangent if asked."""
        if not self.rotate:
            return self.delta
        dp = reference[1]
        if np.hypot(dp[0], dp[1]) >= REST_SPEED:
            self._tangent = float(np.arctan2(dp[1], dp[0]))  # eq. (15)
        # At rest eq. (15) is atan2(0, 0): the last tangent is kept (0 if none yet).
        return rotate_offsets(self.delta, self._tangent)  # eq. (14)


#: The registered laws by name (a live view of the plug-in registry).
LAWS = RegistryView("law")
#: The ``rotate`` key of the laws that place offsets along the reference.
ROTATE = Param(
    "boolean",
    False,
    doc="Turn the offsets with the reference's tangent, eqs. (14)-(15)",
)


@register_law("fixed", frame="world", batched=True)
class FixedFormation(FormationLaw):
    """Section 3.2, eqs. (7)-(9): world-frame offsets, leader derivatives estimated."""

    def __init__(self, delta: np.ndarray, h: float, rotate: bool = False) -> None:
        super().__init__(delta, h, rotate)
        self.leader_motion = BackwardDifference(h)

    def targets(self, inputs: LawInputs) -> Triple:
        """Slots ``x_leader + delta``; derivatives from eqs. (8)-(9)."""
        v, a = self.leader_motion.update(inputs.leader_pos)
        slot = inputs.leader_pos + self.delta  # eq. (7)
        return slot, spread(v, slot.shape), spread(a, slot.shape)


@register_law("rotating", batched=True)
class RotatingFormation(FixedFormation):
    """Section 3.3, eqs. (10)-(11): leader-frame offsets, estimated leader motion."""

    def targets(self, inputs: LawInputs) -> Triple:
        """Slots ``x_leader + Delta(t)`` with ``Delta`` from eq. (11)."""
        v, a = self.leader_motion.update(inputs.leader_pos)
        big_delta = rotate_offsets(self.delta, inputs.leader_theta)  # eq. (11)
        slot = inputs.leader_pos + big_delta  # eq. (10)
        return slot, spread(v, slot.shape), spread(a, slot.shape)


@register_law("virtual", {"rotate": ROTATE}, frame="reference", batched=True)
class VirtualLeaderFormation(FormationLaw):
    """Section 3.4, eqs. (13)-(15): each vehicle tracks the reference + its offset."""

    needs_leader = False
    needs_reference = True

    def targets(self, inputs: LawInputs) -> Triple:
        """Slots ``x_ref + Delta``; derivatives are the reference's own."""
        p, dp, ddp = inputs.reference
        slot = p + self._reference_offsets(inputs.reference)  # eq. (13)
        return slot, spread(dp, slot.shape), spread(ddp, slot.shape)


@register_law("leader_ref", {"rotate": ROTATE}, frame="leader_reference", batched=True)
class LeaderReferenceFormation(FormationLaw):
    """Section 3.4, eq. (16): around the real leader, reference derivatives."""

    needs_reference = True

    def targets(self, inputs: LawInputs) -> Triple:
        """Slots ``x_leader + Delta``; derivatives are the reference's own."""
        _, dp, ddp = inputs.reference
        slot = inputs.leader_pos + self._reference_offsets(inputs.reference)  # eq. (16)
        return slot, spread(dp, slot.shape), spread(ddp, slot.shape)


@register_law("own_estimate", batched=True)
class OwnEstimateFormation(FormationLaw):
    """Section 3.5, eqs. (17)-(20): each vehicle estimates its own slot's motion."""

    def __init__(self, delta: np.ndarray, h: float, rotate: bool = False) -> None:
        super().__init__(delta, h, rotate)
        self.slot_motion = BackwardDifference(h)

    def targets(self, inputs: LawInputs) -> Triple:
        """Slots ``x_leader + Delta(t)`` (eq. (20)); derivatives from eqs. (18)-(19)."""
        big_delta = rotate_offsets(self.delta, inputs.leader_theta)  # eq. (20)
        slot = inputs.leader_pos + big_delta
        v, a = self.slot_motion.update(slot)  # eqs. (18)-(19)
        return slot, v, a  # eq. (17)
