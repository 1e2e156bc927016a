"""The tangential term of the recovery field (``recovery.tangential``, kappa).

Checks that kappa = 0 is the report's field bit for bit (by hand and on a bundled
run), that the tangential term turns both vehicles of a head-on meeting to their right
and vanishes once an obstacle is abeam, that a wall's tangent is the one nearer the
slot, and the measured outcome of ``scenarios/safety/head_on_swap.yaml``: the radial
field stalls the symmetric swap, the tangential term lets it pass.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import PAPER, SCENARIOS, run_scenario

from sandbox import load_scenario
from sandbox.behaviour.recovery import avoidance_shift
from sandbox.errors import ScenarioError
from sandbox.model.obstacle_field import ObstacleField
from sandbox.scenario import ObstacleSpec

SWAP = SCENARIOS / "safety" / "head_on_swap.yaml"
NO_OBSTACLES = ObstacleField(())


def shift(pos, slot, kappa, strategy="discontinuous", obstacles=NO_OBSTACLES, R=1.5):
    """The shift of every vehicle (all avoid), beta = 1."""
    pos = np.asarray(pos, dtype=float)
    out, _ = avoidance_shift(
        pos,
        np.ones(len(pos), dtype=bool),
        strategy,
        1.0,
        R,
        0.75,
        2.0,
        obstacles,
        slot=np.asarray(slot, dtype=float),
        tangential=kappa,
    )
    return out


def test_kappa_zero_is_the_radial_field_by_hand() -> None:
    pos = np.array([[0.0, 0.0], [0.8, 0.3], [-0.4, 0.9]])
    slot = np.array([[3.0, 0.0], [-2.0, 0.0], [0.0, -3.0]])
    got = shift(pos, slot, 0.0)
    want = np.zeros((3, 2))
    for a in range(3):
        for b in range(3):
            if a != b:
                rel = pos[a] - pos[b]
                want[a] += rel / (rel @ rel)  # alpha = 1 within R, eqs. (23)-(24)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    assert not np.allclose(shift(pos, slot, 1.0), got)


def test_head_on_both_veer_to_their_right() -> None:
    # west at the origin heading to (3, 0); east at (1, 0) heading to (-2, 0).
    pos = [[0.0, 0.0], [1.0, 0.0]]
    slot = [[3.0, 0.0], [-2.0, 0.0]]
    radial = shift(pos, slot, 0.0)
    assert radial[:, 1] == pytest.approx([0.0, 0.0])
    s = shift(pos, slot, 2.0)
    # s = 1 (straight ahead), J u / dist with u = -/+x: west -y, east +y, both kappa.
    np.testing.assert_allclose(s[:, 1], [-2.0, 2.0], rtol=1e-12)
    np.testing.assert_allclose(s[:, 0], radial[:, 0], rtol=1e-12)


def test_no_tangential_push_once_the_obstacle_is_abeam_or_behind() -> None:
    slot = [[3.0, 0.0], [3.0, 1.0]]
    abeam = [[0.0, 0.0], [0.0, 1.0]]  # each is abeam of the other: g.u = 0
    np.testing.assert_allclose(shift(abeam, slot, 3.0), shift(abeam, slot, 0.0))
    behind = [[1.0, 0.0], [0.0, 0.0]]  # the second is behind the first...
    both = shift(behind, [[3.0, 0.0], [5.0, 0.0]], 3.0)
    radial = shift(behind, [[3.0, 0.0], [5.0, 0.0]], 0.0)
    assert both[0] == pytest.approx(radial[0])  # ...so the first gets no tangent
    assert both[1, 1] != pytest.approx(radial[1, 1])  # the second has it ahead


def test_a_wall_across_the_way_pushes_along_the_tangent_nearer_the_slot() -> None:
    wall = ObstacleSpec("wall", "w", start=(1.0, -5.0), end=(1.0, 5.0), thickness=0.1)
    field = ObstacleField((wall,))
    pos = [[0.0, 0.0]]
    for slot_y, sign in ((1.0, 1.0), (-1.0, -1.0)):
        s = shift(pos, [[3.0, slot_y]], 1.0, obstacles=field)
        r = shift(pos, [[3.0, slot_y]], 0.0, obstacles=field)
        assert r[0, 1] == pytest.approx(0.0)
        assert np.sign(s[0, 1]) == sign  # along the wall, towards the slot's side


def test_kappa_zero_leaves_a_bundled_run_bit_identical() -> None:
    path = PAPER / "fig15_continuous_beta1.yaml"
    base, _ = run_scenario(path, duration=3)
    zero, _ = run_scenario(path, "recovery.tangential=0", duration=3)
    some, _ = run_scenario(path, "recovery.tangential=1", duration=3)
    assert np.array_equal(base.pose, zero.pose) and np.array_equal(base.cmd, zero.cmd)
    assert not np.array_equal(base.pose, some.pose)


def test_tangential_is_declared_with_its_bound() -> None:
    sc = load_scenario(SWAP)
    assert sc.recovery.params["tangential"] == 1.0
    with pytest.raises(ScenarioError, match="tangential"):
        load_scenario(SWAP, overrides=["recovery.tangential=-1"])


@pytest.mark.slow
def test_head_on_swap_stalls_without_and_passes_with_the_tangential_term() -> None:
    _, stalled = run_scenario(SWAP, "recovery.tangential=0")
    _, passed = run_scenario(SWAP)
    for name in ("west", "east"):
        # measured: 2.249 m for ever without, 0.1 mm after 3.24 s with the term
        assert stalled["vehicles"][name]["formation_error"]["final"] > 2.0
        assert passed["vehicles"][name]["formation_error"]["final"] < 0.01
    assert not stalled["converged"] and passed["converged"]
    # the closing approach touches in both; only the tangential run lets go again
    (touch,) = stalled["collisions"]["events"]
    assert touch["end"] is None
    (brief,) = passed["collisions"]["events"]
    assert brief["end"] is not None and brief["end"] - brief["t"] < 0.5
