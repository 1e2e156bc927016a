"""The layout of a loop, fixed when it is built: K worlds of ``n`` vehicles each.

Every array of the loop holds the rows of all its worlds, ``N = K n`` rows, world
after world: world ``w``'s vehicles are rows ``w n`` to ``(w + 1) n - 1``
(:meth:`Layout.rows`). A single run is a loop of one world.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from sandbox.scenario import Scenario


@dataclass(frozen=True)
class Layout:
    """The worlds of a loop and its clock (see the module docstring).

    Attributes
    ----------
    scenarios : tuple of Scenario
        Each world's scenario, in world order (one structure,
        :func:`~sandbox.loop.plan.structure_key`).
    names : tuple of tuple of str
        Each world's vehicle names, in row order.
    K, n, N : int
        The worlds, the vehicles of each, and the rows of all (``K n``).
    h : float [s]
        The control period.
    steps : int
        The control periods of the whole duration.
    substeps, record_every : int
        The physics' steps a period; a sample recorded every ``record_every``
        periods.
    """

    scenarios: tuple[Scenario, ...]
    names: tuple[tuple[str, ...], ...]
    K: int
    n: int
    h: float
    steps: int
    substeps: int
    record_every: int
    N: int = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "N", self.K * self.n)

    @classmethod
    def of(cls, scenarios: list[Scenario]) -> Layout:
        """The layout of the worlds of ``scenarios`` (the first sets the clock)."""
        first = scenarios[0]
        return cls(
            scenarios=tuple(scenarios),
            names=tuple(tuple(v.name for v in sc.vehicles) for sc in scenarios),
            K=len(scenarios),
            n=len(first.vehicles),
            h=first.dt,
            steps=int(round(first.duration / first.dt)),
            substeps=first.substeps,
            record_every=first.record_every,
        )

    def rows(self, w: int) -> slice:
        """World ``w``'s rows of the loop's arrays."""
        return slice(w * self.n, (w + 1) * self.n)
