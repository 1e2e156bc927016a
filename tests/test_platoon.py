"""Generated platoons: offsets per pattern, starting poses, jitter, names, composition.

A ``platoon: {count, pattern, spacing, jitter, columns, prefix}`` section creates
vehicles after the listed ones, named ``<prefix>0, <prefix>1, ...``, with leader-frame
offsets from :func:`sandbox.scenario.platoon_offsets`, starting on the slots their
formation law gives at t = 0 (plus a uniform jitter drawn from ``seed``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from scipy.spatial.distance import pdist

from sandbox import load_scenario
from sandbox.errors import ScenarioError
from sandbox.loop.simulation import Simulation
from sandbox.scenario import (
    PLATOON_PATTERNS,
    PlatoonSpec,
    parse_scenario,
    platoon_offsets,
)

LINE_REF = {"type": "line", "start": [0, 0], "heading": 0.0, "speed": 1.0}


def doc(platoon: dict, law: str = "virtual", **top: object) -> dict:
    """A scenario with a generated platoon (and a straight reference)."""
    out = {
        "name": "platoon",
        "duration": 1.0,
        "reference": dict(LINE_REF),
        "formation": {"law": law},
        "platoon": platoon,
    }
    out.update(top)
    return out


# ---------------------------------------------------------------------------- offsets
def test_grid_offsets_by_hand() -> None:
    # 5 vehicles, 2 columns, spacing 1: rows 0, 0, 1, 1, 2 behind the leader at
    # -(row + 1); columns centred sideways at (col - (2 - 1) / 2) = -0.5, +0.5.
    got = platoon_offsets(PlatoonSpec(5, "grid", 1.0, columns=2))
    want = [[-1, -0.5], [-1, 0.5], [-2, -0.5], [-2, 0.5], [-3, -0.5]]
    np.testing.assert_allclose(got, want)


def test_grid_default_columns_is_ceil_sqrt() -> None:
    # 10 vehicles: ceil(sqrt(10)) = 4 columns, so 3 rows (4 + 4 + 2).
    got = platoon_offsets(PlatoonSpec(10, "grid", 2.0))
    assert sorted(set(got[:, 1].tolist())) == [-3.0, -1.0, 1.0, 3.0]
    assert sorted(set(got[:, 0].tolist())) == [-6.0, -4.0, -2.0]


def test_line_offsets_by_hand() -> None:
    # single file behind the leader: -(k + 1) * s.
    got = platoon_offsets(PlatoonSpec(3, "line", 1.5))
    np.testing.assert_allclose(got, [[-1.5, 0], [-3.0, 0], [-4.5, 0]])


def test_wedge_offsets_by_hand() -> None:
    # a V: vehicle k on rank k // 2 + 1, left arm for even k, right arm for odd k.
    got = platoon_offsets(PlatoonSpec(4, "wedge", 1.0))
    np.testing.assert_allclose(got, [[-1, 1], [-1, -1], [-2, 2], [-2, -2]])


def test_ring_offsets_by_hand() -> None:
    # 4 vehicles, spacing 1: radius max(1 * 4 / (2 pi), 2 * 1) = 2; at 0, 90, 180, 270°.
    got = platoon_offsets(PlatoonSpec(4, "ring", 1.0))
    np.testing.assert_allclose(got, [[2, 0], [0, 2], [-2, 0], [0, -2]], atol=1e-12)
    # many vehicles: the circumference is count * spacing.
    got = platoon_offsets(PlatoonSpec(300, "ring", 1.0))
    np.testing.assert_allclose(np.hypot(*got.T), 300 / (2 * math.pi))


@pytest.mark.parametrize("pattern", PLATOON_PATTERNS)
@pytest.mark.parametrize("count", [1, 2, 3, 7, 50, 301])
def test_offsets_keep_a_spacing_from_each_other_and_the_leader(
    pattern: str, count: int
) -> None:
    s = 0.8
    off = platoon_offsets(PlatoonSpec(count, pattern, s))
    assert off.shape == (count, 2)
    with_leader = np.vstack(([0.0, 0.0], off))  # the leader sits at the origin
    # A ring's chord is (count s / pi) sin(pi / count), a hair under s for large counts.
    assert pdist(with_leader).min() >= 0.999 * s


# ---------------------------------------------------------------------------- vehicles
def test_generated_vehicles_have_unique_names_offsets_and_parameters() -> None:
    sc = load_scenario(
        doc(
            {"count": 12, "pattern": "grid", "spacing": "3d", "prefix": "car"},
            vehicle={"diameter": 0.4, "v1_max": 2.0, "mass": 7.0},
        )
    )
    names = [v.name for v in sc.vehicles]
    assert names == [f"car{i}" for i in range(12)]
    spec = PlatoonSpec(12, "grid", 3 * 0.4, prefix="car")  # "3d" with d = 0.4 m
    np.testing.assert_allclose([v.offset for v in sc.vehicles], platoon_offsets(spec))
    assert {(v.diameter, v.v1_max, v.mass) for v in sc.vehicles} == {(0.4, 2.0, 7.0)}
    assert not any(v.leader for v in sc.vehicles)


def test_platoon_composes_with_a_listed_leader_and_followers() -> None:
    leader = {"name": "boss", "pose": [3, 4, math.pi / 2], "leader": True}
    follower = {"name": "wing", "pose": [1, 4, math.pi / 2], "offset": [0, 2]}
    sc = load_scenario(
        doc(
            {"count": 6, "pattern": "line", "spacing": 1.0},
            law="rotating",
            vehicles=[leader, follower],
        )
    )
    assert [v.name for v in sc.vehicles] == ["boss", "wing"] + [
        f"v{i}" for i in range(6)
    ]
    assert sc.leader_index == 0
    # rotating law: offsets in the leader's frame; the leader faces +x2, so "behind"
    # (-delta1) is -x2: v_k starts at (3, 4 - (k + 1)).
    starts = np.array([v.pose for v in sc.vehicles[2:]])
    np.testing.assert_allclose(starts[:, 0], 3.0, atol=1e-12)
    np.testing.assert_allclose(starts[:, 1], 4.0 - np.arange(1, 7))
    np.testing.assert_allclose(starts[:, 2], math.pi / 2)


@pytest.mark.parametrize(
    ("law", "rotate", "leader"),
    [
        ("virtual", False, False),
        ("virtual", True, False),
        ("virtual", True, True),
        ("fixed", False, True),
        ("rotating", False, True),
        ("leader_ref", True, True),
        ("own_estimate", False, True),
    ],
)
# Far from their slots with no v1_max, some platoons warn of tunnelling: not the point.
@pytest.mark.filterwarnings("ignore:.*per physics substep:sandbox.SandboxWarning")
def test_an_unjittered_platoon_starts_exactly_on_its_slots(
    law: str, rotate: bool, leader: bool
) -> None:
    # A circle reference: its tangent at t = 0 is +x2, the leader heads 0.3 rad, so
    # every law's frame differs from the world frame and from the others.
    scenario = {
        "duration": 0.02,
        "reference": {"type": "circle", "center": [0, 0], "radius": 40, "speed": 1},
        "formation": {"law": law, **({"rotate": True} if rotate else {})},
        "platoon": {"count": 9, "pattern": "wedge", "spacing": 1.5},
    }
    if leader:
        scenario["vehicles"] = [{"name": "lead", "pose": [40, 0, 0.3], "leader": True}]
    run = Simulation(load_scenario(scenario)).run()
    first = 1 if leader else 0
    # slot recorded at t = 0 (the law's own equation) vs the pose read from the physics
    np.testing.assert_allclose(run.pose[0, first:, :2], run.slot[0, first:], atol=1e-9)


@pytest.mark.filterwarnings("ignore:.*per physics substep:sandbox.SandboxWarning")
def test_jitter_is_bounded_and_set_by_the_seed() -> None:
    base = doc({"count": 40, "pattern": "grid", "spacing": 2.0, "jitter": 0.25})
    exact = load_scenario({**base, "platoon": {**base["platoon"], "jitter": 0.0}})
    a = load_scenario({**base, "seed": 3})
    b = load_scenario({**base, "seed": 3})
    c = load_scenario({**base, "seed": 4})
    pose = {
        k: np.array([v.pose for v in s.vehicles])
        for k, s in {"exact": exact, "a": a, "b": b, "c": c}.items()
    }
    assert np.array_equal(pose["a"], pose["b"])  # same seed, same starts
    assert not np.allclose(
        pose["a"][:, :2], pose["c"][:, :2]
    )  # another seed moves them
    shift = pose["a"][:, :2] - pose["exact"][:, :2]
    assert np.abs(shift).max() <= 0.25
    assert np.abs(shift).max() > 0.1  # it really jitters (40 x 2 uniform draws)
    assert np.array_equal(pose["a"][:, 2], pose["exact"][:, 2])  # headings untouched


def test_generated_names_that_clash_with_listed_ones_are_an_error() -> None:
    listed = [{"name": "v2", "pose": [50, 50, 0]}]
    with pytest.raises(ScenarioError, match=r"platoon\.prefix"):
        load_scenario(doc({"count": 4, "pattern": "line"}, vehicles=listed))


def test_overlapping_starts_are_found_in_a_large_platoon() -> None:
    # 3,000 vehicles 0.4 m apart with a 0.5 m diameter: every neighbour overlaps. The
    # check uses a KD-tree, so it runs at this size (it was skipped above 2,000).
    with pytest.raises(ScenarioError, match=r"platoon\.spacing.*starts overlapping"):
        load_scenario(doc({"count": 3000, "pattern": "grid", "spacing": 0.4}))


def test_to_dict_writes_the_platoon_section_and_reads_back_identically() -> None:
    sc = load_scenario(
        doc(
            {"count": 500, "pattern": "ring", "spacing": "3d", "jitter": 0.1},
            law="rotating",
            seed=11,
            vehicle={"diameter": 0.5, "v1_max": 2.5, "gains": {"kp": 3.0}},
            vehicles=[{"name": "lead", "pose": [0, 0, 0], "leader": True}],
        )
    )
    out = sc.to_dict()
    assert out["platoon"]["count"] == 500
    assert [v["name"] for v in out["vehicles"]] == ["lead"]  # generated ones not listed
    text = yaml.safe_dump(out, sort_keys=False)
    assert len(text) < 3000  # a few lines, not 500 vehicles
    again = parse_scenario(yaml.safe_load(text))
    assert again.vehicles == sc.vehicles
    assert again.platoon == sc.platoon
