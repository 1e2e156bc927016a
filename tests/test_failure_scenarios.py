"""The bundled failure scenarios (``scenarios/failures/``): without and with recovery.

Each scenario file declares its recovery (the continuous approach, beta = 2.5); the
"without" run is the same file with ``recovery.strategy=none``. Without recovery the
failure (or the obstacles) causes collisions; with it no two healthy vehicles touch, no
healthy vehicle hits an obstacle, and the healthy vehicles' formation errors settle once
the danger has passed.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from helpers import SCENARIOS, run_scenario, window

from sandbox.testing import assert_expectations

#: Every test of this module takes seconds: the full suite only (not in -m "not slow").
pytestmark = pytest.mark.slow

FAILURES = SCENARIOS / "failures"
NONE = "recovery.strategy=none"


@cache
def result(name: str, *sets: str, **fields):
    """``(run, metrics)`` of ``scenarios/failures/<name>.yaml``, run once per module."""
    return run_scenario(FAILURES / f"{name}.yaml", *sets, **fields)


def collisions(name: str, *sets: str, **fields) -> dict:
    return result(name, *sets, **fields)[1]["collisions"]


def test_every_failure_kind_and_an_obstacle_field_are_covered():
    from sandbox import load_scenario

    kinds, leader_failure, obstacle_types = set(), False, set()
    for path in FAILURES.glob("*.yaml"):
        sc = load_scenario(path)
        assert sc.recovery.strategy != "none"
        for f in sc.failures:
            kinds.add(f.kind)
            leader_failure |= sc.vehicles[sc.leader_index].name == f.vehicle
        obstacle_types |= {o.type for o in sc.obstacles}
    assert kinds == {"stop", "stuck_steering", "spin", "uncontrolled", "crash"}
    assert leader_failure
    assert obstacle_types == {"circle", "box", "polygon", "wall"}


@pytest.mark.parametrize(
    ("name", "failed", "hit"),
    [
        # the failed vehicle red is run into by orange (healthy) from behind
        ("follower_stop", "red", "orange"),
        ("follower_spin", "red", "orange"),
        ("follower_crash", "red", "orange"),
        # red, stuck turning right, slows down and is run into by orange
        ("follower_stuck_steering", "red", "orange"),
    ],
)
def test_a_failed_follower_in_the_way(name, failed, hit):
    off = collisions(name, NONE)
    assert off["vehicle_vehicle"] >= 1
    assert {frozenset((e["a"], e["b"])) for e in off["events"]} == {
        frozenset((failed, hit))
    }
    assert off["healthy"] == 0  # every contact involves the failed vehicle
    run, m = result(name)
    # the file's expect: no contact (not even the failed vehicle is touched), no two
    # centres closer than d, the healthy vehicles re-form
    assert_expectations(run)
    assert m["vehicles"][failed]["failed_at"] == pytest.approx(3.0)


def test_a_crashed_vehicle_is_not_pushed_but_a_stopped_one_is():
    # Without recovery orange drives into red; a stopped red gets shoved along, a
    # wrecked one stays where it crashed.
    for name, moves in (("follower_stop", True), ("follower_crash", False)):
        run, _ = result(name, NONE)
        after = window(run, 3.5)
        drift = np.ptp(run.pose[after, 1, 0])
        assert bool(drift > 0.2) is moves, (name, drift)


def test_uncontrolled_follower_into_the_leader():
    off = collisions("uncontrolled_into_leader", NONE)
    assert ("leader", "green") in {(e["a"], e["b"]) for e in off["events"]}
    run, m = result("uncontrolled_into_leader")
    col = m["collisions"]
    # The leader (avoiding too) escapes the runaway; no two healthy vehicles touch, and
    # they re-form (the file's expect:).
    assert_expectations(run)
    assert all("leader" not in (e["a"], e["b"]) for e in col["events"])
    # What really happens: dodging the leader pushes red into the runaway's arc, and
    # the runaway, as fast as anyone, catches it once (a failed-healthy contact).
    assert [(e["a"], e["b"], e["healthy"]) for e in col["events"]] == [
        ("red", "green", False)
    ]


def test_leader_failure_whirls_the_formation():
    off = collisions("leader_spin", NONE)
    # the followers chasing their whirling slots collide among themselves
    assert off["healthy"] >= 1
    run, m = result("leader_spin")
    # with recovery the followers avoid the whirling leader; the one contact left is
    # after the spin clears (7 s): the leader, which does not avoid, resumes its
    # reference through orange, which is still turning out of its way
    events = m["collisions"]["events"]
    assert [(e["a"], e["b"]) for e in events] == [("leader", "orange")]
    assert events[0]["t"] > 7.0
    assert m["vehicles"]["leader"]["failed_at"] == pytest.approx(3.0)
    # the spin clears at 7 s: the leader resumes its reference; the file's expect:
    # everyone re-forms after 7 s
    assert not run.failed[window(run, 7.0), 0].any()
    assert_expectations(run)


def test_obstacle_field():
    off = collisions("obstacle_field", NONE, duration=30)
    hit = {e["b"] for e in off["events"] if e["kind"] == "vehicle_obstacle"}
    assert hit == {"wall_north", "wall_south", "post", "crate", "rock"}
    run, m = result("obstacle_field")
    assert_expectations(run)  # no contact at all, the platoon re-forms
    # the followers really were pushed off their slots, and re-formed afterwards
    for name in ("red", "green", "orange"):
        assert m["vehicles"][name]["formation_error"]["max"] > 1.0
        assert m["vehicles"][name]["mode_switches"] > 0
