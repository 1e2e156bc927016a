"""The platoons' recovery and safety sections of K worlds, each called once for all.

In a world with ``platoons:`` the platoons that share a recovery section are shifted
by one call of its strategy, and those that share a safety section filtered by one
call of its filter, on the whole fleet with only the section's rows kept
(:meth:`~sandbox.loop.platoons.Platoons.strategy`,
:meth:`~sandbox.loop.platoons.Platoons.filter`). The worlds of a loop share their
platoons' structure (:func:`~sandbox.loop.plan.structure_key`), so section by
section the call can take the rows of all worlds instead of one world's:
:class:`PlatoonSections` makes one call of each section for K worlds, with that
section's parameters (``beta`` a row each where the worlds differ), its neighbour
pairs within each world (:class:`~sandbox.geometry.neighbours.AllPairsByWorld`), one
memory for the section, and each world's counters of the section, which it sums
into the world's filter counters as a world alone does.

It is taken when every world divides its platoons into the same sections (the same
values but ``beta``, on the same rows) and every section's strategy and filter are
registered with ``batched=True`` (the built-ins are); otherwise the sections are
called world by world. Each world's numbers are those it has alone
(``tests/test_one_loop.py``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from sandbox.geometry.neighbours import BRUTE_FORCE_MAX, AllPairsByWorld
from sandbox.loop.platoons import Platoons, sum_counters
from sandbox.plugins.registration import get


class PlatoonSections:
    """Each recovery and safety section of K worlds' platoons, one call for all.

    Build it with :meth:`build` (None where the worlds' sections differ or a
    section's plug-in is not batched).

    Parameters
    ----------
    platoons : list of Platoons
        Each world's platoons.
    world_stats : list of dict
        Each world's filter counters (the sections' are summed into them).
    """

    def __init__(self, platoons: list[Platoons], world_stats: list[dict]) -> None:
        self._platoons = platoons
        self._world_stats = world_stats
        K, n = len(platoons), platoons[0].n
        first = self._platoons[0]
        self._recoveries = []
        for j, (spec, (strategy, _), mask) in enumerate(first.recoveries):
            params = dict(spec.params)
            if "beta" in params:  # each world's beta on its rows where they differ
                betas = [p.recoveries[j][0].params["beta"] for p in self._platoons]
                if any(b != betas[0] for b in betas):
                    params["beta"] = np.repeat(np.array(betas, dtype=float), n)[:, None]
            rows = np.tile(mask, K)
            self._recoveries.append(
                (strategy, params, spec.R, AllPairsByWorld(K, n, spec.R), rows)
            )
        self._filters = [
            (flt, dict(spec.params), np.tile(mask, K), {})
            for spec, flt, mask in first.filters
        ]

    @classmethod
    def build(
        cls,
        platoons: list[Platoons],
        sensing: list[Any],
        world_stats: list[dict],
    ) -> PlatoonSections | None:
        """The sections of a loop's worlds, or None (called world by world).

        ``sensing`` is each world's ``sensing:`` values (None: no broadcast); the
        worlds' filters are called once for all only where they are the same.
        """
        first = platoons[0]
        if first.n > BRUTE_FORCE_MAX:
            return None
        for p in platoons[1:]:
            if not _same_sections(first.recoveries, p.recoveries, "beta"):
                return None
            if not _same_sections(first.filters, p.filters, None):
                return None
        if any(x != sensing[0] for x in sensing):
            return None
        for spec, _, _ in first.recoveries:
            if not get("strategy", spec.strategy).options.get("batched", False):
                return None
        for spec, flt, _ in first.filters:
            if flt is not None and not get("filter", spec.filter).options.get(
                "batched", False
            ):
                return None
        return cls(platoons, world_stats)

    @property
    def filtered(self) -> bool:
        """Whether some section has a safety filter."""
        return any(flt is not None for flt, _, _, _ in self._filters)

    def _index(self) -> np.ndarray:
        """Each vehicle's platoon in its world (merges and splits change it)."""
        return np.concatenate([p.index for p in self._platoons])

    def strategy(self, ctx: Any) -> tuple[np.ndarray, np.ndarray]:
        """The recovery shift of every vehicle of every world, a call per section.

        ``ctx`` is the loop's :class:`~sandbox.plugins.StrategyContext` of the rows
        of all worlds.
        """
        N = len(ctx.pos)
        shift, active = np.zeros((N, 2)), np.zeros(N, dtype=bool)
        index = self._index()
        for strategy, params, R, pairs, rows in self._recoveries:
            sub = dataclasses.replace(
                ctx,
                may_avoid=ctx.may_avoid & rows,
                params=dict(params),
                R=R,
                neighbours=pairs,
                platoon=index,
            )
            s, a = strategy(sub)
            shift[rows] = np.asarray(s, dtype=float)[rows]
            active[rows] = np.asarray(a, dtype=bool)[rows]
        return shift, active

    def filter(self, ctx: Any) -> tuple[np.ndarray, np.ndarray]:
        """The filtered commands of every world, a call per safety section.

        ``ctx`` is the loop's batched :class:`~sandbox.plugins.FilterContext`; each
        section's counters are kept per world, and summed into each world's.
        """
        N = len(ctx.pos)
        v1 = np.array(ctx.v1, dtype=float)
        v2 = np.array(ctx.v2, dtype=float)
        index = self._index()
        for j, (flt, params, rows, memory) in enumerate(self._filters):
            if flt is None:
                continue
            sub = dataclasses.replace(
                ctx,
                params=dict(params),
                memory=memory,
                platoon=index,
                stats=self._platoons[0].filter_stats[j],  # a filter of one world's
                world_stats=[p.filter_stats[j] for p in self._platoons],
            )
            out = flt(sub)
            v1[rows] = np.broadcast_to(np.asarray(out[0], dtype=float), (N,))[rows]
            v2[rows] = np.broadcast_to(np.asarray(out[1], dtype=float), (N,))[rows]
        for stats, p in zip(self._world_stats, self._platoons, strict=True):
            stats.update(sum_counters(p.filter_stats))
        return v1, v2


def _same_sections(mine: list, theirs: list, free: str | None) -> bool:
    """Whether two worlds' sections have the same values (but ``free``) and rows."""
    if len(mine) != len(theirs):
        return False
    for (a, _, mask_a), (b, _, mask_b) in zip(mine, theirs, strict=True):
        if free is not None and free in a.params:
            a = dataclasses.replace(a, params={**a.params, free: None})
            b = dataclasses.replace(b, params={**b.params, free: None})
        if a != b or not np.array_equal(mask_a, mask_b):
            return False
    return True
