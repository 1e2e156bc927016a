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
section. One :class:`Broadcast` holds the copies of K worlds (one for a single run):
each world draws from its own generator in the order it draws alone, into its rows
of two stacked buffers, in one C call for all of them where the compiled path
``draws`` is on (:mod:`sandbox.accel`; numpy's random C API on each world's bit
generator, the numbers of its Generator).
"""

from __future__ import annotations

import zlib
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from sandbox import accel

#: The stream of the sensing draws, mixed with the scenario's seed.
SENSING_STREAM = zlib.crc32(b"sensing")


class Broadcast:
    """The pose copies the vehicles of K worlds receive of each other, once a period.

    Every world draws from its own generator, in the order it draws alone (each
    period its noise, then its losses), into its rows of two stacked buffers: a
    world of a batch receives the copies it receives alone. The rest is elementwise
    over the stacked rows, ``n`` a world, world after world. The worlds share the
    delay (their structure).

    Parameters
    ----------
    position_noise : float or sequence of K floats [m]
        Standard deviation of the noise added to each position coordinate.
    heading_noise : float or sequence of K floats [rad]
        Standard deviation of the noise added to each heading.
    delay_periods : int
        Latency in control periods (``delay / dt``).
    loss : float or sequence of K floats
        Probability, in [0, 1), that a vehicle's packet of a period is lost.
    seeds : sequence of int
        Each world's scenario seed (K of them).
    n : int
        Vehicles per world.

    Examples
    --------
    >>> b = Broadcast(0.0, 0.0, 2, 0.0, seeds=[0], n=1)
    >>> [float(b.update(np.array([[x, 0.0]]), np.zeros(1))[0, 0]) for x in range(4)]
    [0.0, 0.0, 0.0, 1.0]
    """

    def __init__(
        self,
        position_noise: float | Sequence[float],
        heading_noise: float | Sequence[float],
        delay_periods: int,
        loss: float | Sequence[float],
        seeds: Sequence[int],
        n: int,
    ) -> None:
        K = len(seeds)
        position, heading, lost = (
            np.broadcast_to(np.asarray(value, dtype=float), (K,))
            for value in (position_noise, heading_noise, loss)
        )
        self.worlds, self.n = K, n
        #: The noise's standard deviations of every row, shape (K n, 3) [m, m, rad].
        self.sigma = np.repeat(np.column_stack((position, position, heading)), n, 0)
        #: The loss probability of every row, shape (K n,).
        self.loss = np.repeat(lost, n)
        #: Each world's generator of the draws.
        self.rngs = [np.random.default_rng([seed, SENSING_STREAM]) for seed in seeds]
        self._sent: deque[np.ndarray] = deque(maxlen=delay_periods + 1)
        #: The last received pose of every row, shape (K n, 3) [m, m, rad].
        self.seen: np.ndarray | None = None
        #: Whether each row's packet of the last update arrived, shape (K n,) bool.
        self.fresh: np.ndarray | None = None
        self._noise, self._draws = np.empty((K, n, 3)), np.empty((K, n))
        # Each world's two draws, with the buffer rows they fill.
        self._calls = [
            (rng.standard_normal, self._noise[w], rng.random, self._draws[w])
            for w, rng in enumerate(self.rngs)
        ]
        # Or every world's in one C call, on their bit generators' capsules.
        self._c = accel.module("draws")
        self._capsules = [rng.bit_generator.capsule for rng in self.rngs]

    def update(self, pos: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Broadcast the true poses of ``t_k``; return what is received at ``t_k``.

        Parameters
        ----------
        pos : ndarray, shape (K n, 2) [m]
        theta : ndarray, shape (K n,) [rad]
            The true poses now.

        Returns
        -------
        ndarray, shape (K n, 3) [m, m, rad]
            The copy of each vehicle's pose the others hold now: the pose sent
            ``delay`` periods ago with its noise, or, where that packet is lost, the
            copy held before. Before ``delay`` periods have passed the first copy is
            held; the first copy is never lost.
        """
        # Fixed-shape draws every period, so the stream does not depend on the values.
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


def make_broadcast(
    specs: Sequence[Any], dt: float, seeds: Sequence[int], n: int
) -> Broadcast | None:
    """The broadcast of K worlds' ``sensing`` sections, or None when they are all 0.

    Parameters
    ----------
    specs : sequence of SensingSpec
        Each world's section (see :class:`sandbox.scenario.SensingSpec`); their
        delays are equal, and either every section or none makes a broadcast
        (their structure).
    dt : float [s]
        The control period; ``spec.delay`` is a whole number of them.
    seeds : sequence of int
        Each world's scenario seed.
    n : int
        Vehicles per world.
    """
    first = specs[0]
    if not (first.position_noise or first.heading_noise or first.delay or first.loss):
        return None
    return Broadcast(
        [spec.position_noise for spec in specs],
        [spec.heading_noise for spec in specs],
        int(round(first.delay / dt)),
        [spec.loss for spec in specs],
        seeds,
        n,
    )
