"""What the vehicles see of each other: a noisy, delayed, lossy broadcast of the poses.

The ``sensing:`` section of a scenario sets four numbers: ``position_noise`` and
``heading_noise`` (standard deviations [m], [rad] of white Gaussian noise), ``delay``
(a latency [s], a whole number of control periods) and ``loss`` (the probability that
a packet is lost). The model is one broadcast per control period: every vehicle sends
its true pose plus noise; the copy arrives ``delay / dt`` periods later, unless it is
lost, in which case the receivers hold the last copy they received. Noise, delay and
loss are applied once per sender and period, so every receiver sees the same copy.
The formation law reads the leader's pose from it (the followers' backward
differences of eqs. (8)-(9) then see the noise), recovery the neighbours' positions;
each vehicle knows its own pose exactly and the physics keeps the truth.

The draws come from a generator of their own, ``numpy.random.default_rng([seed,
crc32("sensing")])``: adding sensing changes no other draw of a scenario, and the same
scenario and seed give the same copies. With every value 0 no broadcast is made at all
(:func:`make_broadcast` returns None) and runs are bit-identical to runs without the
section. The worlds of a batch (:class:`StackedBroadcast`) draw, each from its own
generator in the order it draws alone, into their rows of two stacked buffers: in one
C call for all of them where the compiled path ``draws`` is on (:mod:`sandbox.accel`;
numpy's random C API on each world's bit generator, the numbers of its Generator).
"""

from __future__ import annotations

import zlib
from collections import deque

import numpy as np

from sandbox import accel

#: The stream of the sensing draws, mixed with the scenario's seed.
SENSING_STREAM = zlib.crc32(b"sensing")


class Broadcast:
    """The pose copies the vehicles receive of each other, one update per period.

    Parameters
    ----------
    position_noise : float [m]
        Standard deviation of the noise added to each position coordinate.
    heading_noise : float [rad]
        Standard deviation of the noise added to each heading.
    delay_periods : int
        Latency in control periods (``delay / dt``).
    loss : float
        Probability, in [0, 1), that a vehicle's packet of a period is lost.
    seed : int
        The scenario's seed.

    Examples
    --------
    >>> b = Broadcast(0.0, 0.0, 2, 0.0, seed=0)
    >>> [float(b.update(np.array([[x, 0.0]]), np.zeros(1))[0, 0]) for x in range(4)]
    [0.0, 0.0, 0.0, 1.0]
    """

    def __init__(
        self,
        position_noise: float,
        heading_noise: float,
        delay_periods: int,
        loss: float,
        seed: int,
    ) -> None:
        self.sigma = np.array([position_noise, position_noise, heading_noise])
        self.loss = loss
        self.rng = np.random.default_rng([seed, SENSING_STREAM])
        self._sent: deque[np.ndarray] = deque(maxlen=delay_periods + 1)
        self._seen: np.ndarray | None = None
        self._fresh: np.ndarray | None = None
        #: Set by a :class:`StackedBroadcast`: it and this broadcast's rows of it.
        self.stack: tuple[StackedBroadcast, slice] | None = None

    @property
    def seen(self) -> np.ndarray | None:
        """The last received pose of each vehicle, shape (n, 3) [m, m, rad]."""
        if self.stack is not None:
            stacked, rows = self.stack
            return None if stacked.seen is None else stacked.seen[rows]
        return self._seen

    @seen.setter
    def seen(self, value: np.ndarray | None) -> None:
        self._seen = value

    @property
    def fresh(self) -> np.ndarray | None:
        """Whether each vehicle's packet of the last update arrived, shape (n,) bool."""
        if self.stack is not None:
            stacked, rows = self.stack
            return None if stacked.fresh is None else stacked.fresh[rows]
        return self._fresh

    @fresh.setter
    def fresh(self, value: np.ndarray | None) -> None:
        self._fresh = value

    def update(self, pos: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Broadcast the true poses of ``t_k``; return what is received at ``t_k``.

        Parameters
        ----------
        pos : ndarray, shape (n, 2) [m]
        theta : ndarray, shape (n,) [rad]
            The true poses now.

        Returns
        -------
        ndarray, shape (n, 3) [m, m, rad]
            The copy of each vehicle's pose the others hold now: the pose sent
            ``delay`` periods ago with its noise, or, where that packet is lost, the
            copy held before. Before ``delay`` periods have passed the first copy is
            held; the first copy is never lost.
        """
        n = len(pos)
        # Fixed-shape draws every period, so the stream does not depend on the values.
        noise = self.rng.standard_normal((n, 3)) * self.sigma
        lost = self.rng.random(n) < self.loss
        pose = np.column_stack((pos, theta)) + noise
        self._sent.append(pose)
        arrived = self._sent[0]
        if self.seen is None:
            self.seen = arrived.copy()
            self.fresh = np.ones(n, dtype=bool)
        else:
            self.seen = np.where(lost[:, None], self.seen, arrived)
            self.fresh = ~lost
        return self.seen


class StackedBroadcast:
    """The broadcasts of K worlds of ``n`` vehicles as one (their rows stacked).

    Each world draws from its own generator, in the order it draws alone (the
    noise, then the losses; into its rows of two stacked buffers, the numbers a
    draw of that shape gives), so that every world receives the copies it
    receives alone; the rest is elementwise over the stacked rows. The worlds share
    the delay (their structure). Every world's own :class:`Broadcast` shows its
    rows of the stacked copies (``seen``, ``fresh``).
    """

    def __init__(self, broadcasts: list[Broadcast], n: int) -> None:
        self.parts, self.n = broadcasts, n
        K = len(broadcasts)
        self.sigma = np.repeat(np.array([b.sigma for b in broadcasts]), n, axis=0)
        self.loss = np.repeat(np.array([b.loss for b in broadcasts]), n)
        self._sent: deque[np.ndarray] = deque(maxlen=broadcasts[0]._sent.maxlen)
        self.seen: np.ndarray | None = None
        self.fresh: np.ndarray | None = None
        self._noise, self._draws = np.empty((K, n, 3)), np.empty((K, n))
        # Each world's two draws, with the buffer rows they fill.
        self._calls = [
            (b.rng.standard_normal, self._noise[w], b.rng.random, self._draws[w])
            for w, b in enumerate(broadcasts)
        ]
        # Or every world's in one C call, on their bit generators' capsules.
        self._c = accel.module("draws")
        self._capsules = [b.rng.bit_generator.capsule for b in broadcasts]
        for w, b in enumerate(broadcasts):
            b.stack = (self, slice(w * n, (w + 1) * n))

    def update(self, pos: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """:meth:`Broadcast.update` of every world, shape (K n, 3)."""
        if self._c is not None:
            self._c.fill_worlds(self._capsules, self._noise, self._draws)
        else:
            for normal, noise, uniform, draws in self._calls:  # normals, uniforms
                normal(out=noise)
                uniform(out=draws)
        lost = self._draws.reshape(-1) < self.loss
        noise = self._noise.reshape(-1, 3) * self.sigma
        pose = np.column_stack((pos, theta)) + noise
        self._sent.append(pose)
        arrived = self._sent[0]
        if self.seen is None:
            self.seen = arrived.copy()
            self.fresh = np.ones(len(pos), dtype=bool)
        else:
            self.seen = np.where(lost[:, None], self.seen, arrived)
            self.fresh = ~lost
        return self.seen


def make_broadcast(spec, dt: float, seed: int) -> Broadcast | None:
    """The broadcast of a scenario's ``sensing`` section, or None when it is all 0.

    Parameters
    ----------
    spec : SensingSpec
        The section (see :class:`sandbox.scenario.SensingSpec`).
    dt : float [s]
        The control period; ``spec.delay`` is a whole number of them.
    seed : int
        The scenario's seed.
    """
    if not (spec.position_noise or spec.heading_noise or spec.delay or spec.loss):
        return None
    return Broadcast(
        spec.position_noise,
        spec.heading_noise,
        int(round(spec.delay / dt)),
        spec.loss,
        seed,
    )
