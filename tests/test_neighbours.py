"""The neighbour search of K stacked worlds: every pair of a world, never across.

:func:`~sandbox.geometry.neighbours.neighbour_search` gives every pair of each small
world (:class:`~sandbox.geometry.neighbours.AllPairsByWorld`) and a Verlet list of a
large fleet, which runs alone; the pairs of a world of a batch are those of its
single run, shifted to its rows.
"""

from __future__ import annotations

import numpy as np
import pytest

from sandbox.geometry.neighbours import (
    BRUTE_FORCE_MAX,
    AllPairsByWorld,
    NeighbourList,
    neighbour_search,
)


def test_small_worlds_take_every_pair_and_a_large_fleet_a_verlet_list():
    assert isinstance(neighbour_search(3, 4, 1.5), AllPairsByWorld)
    assert isinstance(neighbour_search(1, 4, 1.5), AllPairsByWorld)
    assert isinstance(neighbour_search(1, BRUTE_FORCE_MAX + 1, 1.5), NeighbourList)


def test_several_large_worlds_are_refused():
    with pytest.raises(ValueError, match="runs alone"):
        neighbour_search(2, BRUTE_FORCE_MAX + 1, 1.5)


def test_a_world_of_a_batch_has_the_pairs_of_its_single_run():
    rng = np.random.default_rng(3)
    K, n = 3, 5
    pos = rng.uniform(0.0, 2.0, (K * n, 2))
    i, j = AllPairsByWorld(K, n, 1.0).pairs(pos)
    for w in range(K):
        alone = AllPairsByWorld(1, n, 1.0).pairs(pos[w * n : (w + 1) * n])
        mine = (i >= w * n) & (i < (w + 1) * n)
        assert np.array_equal(i[mine] - w * n, alone[0])
        assert np.array_equal(j[mine] - w * n, alone[1])
    assert np.all(i // n == j // n)  # never a pair across worlds


def test_positions_of_another_size_give_the_pairs_of_that_many_rows():
    search = AllPairsByWorld(1, 3, 10.0)
    assert len(search.candidates(np.zeros((3, 2)))[0]) == 3  # 3 choose 2
    assert len(search.candidates(np.zeros((5, 2)))[0]) == 10  # 5 choose 2
    two = AllPairsByWorld(2, 3, 10.0)
    assert len(two.candidates(np.zeros((8, 2)))[0]) == 12  # two worlds of 4
    with pytest.raises(ValueError, match="7 positions for 2 worlds"):
        two.candidates(np.zeros((7, 2)))
