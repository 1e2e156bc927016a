"""No perpetual orbits, and eq. (15) at rest.

The turn-rate limit is part of the anti-windup: chi is kept within the directions the
vehicle can drive along by the next period (``flatness.limit_turn``) and the heading
loop turns the vehicle towards the direction the controller asked for. Without it a
vehicle whose heading falls behind a fast-rotating chi circles its target for ever with
v2 pinned at its limit. At a reference at rest, rotated slots keep the last tangent
direction instead of ``atan2(0, 0) = 0``.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import PAPER, run_scenario

from sandbox.model.dynamics import wrap_angle
from sandbox.model.flatness import limit_turn
from sandbox.model.laws import LAWS, REST_SPEED, LawInputs

#: The robot of the report's sections 2-3 files: 2 m/s, 3 rad/s, 10 m/s^2.
ROBOT = {"diameter": 0.5, "mass": 10.0, "v1_max": 2.0, "v2_max": 3.0, "max_accel": 10.0}
#: A waypoint path that ends after about 10 s at 1 m/s.
PATH = {"type": "waypoints", "points": [[0, 0], [5, 0], [8, 4]], "speed": 1.0}


def platoon_on_a_path_that_ends(rotate: bool, duration: float = 20.0) -> dict:
    return {
        "duration": duration,
        "vehicle": ROBOT,
        "reference": PATH,
        "formation": {"law": "virtual", "rotate": rotate},
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [-1, 1, 0], "offset": [-1, 1]},
            {"name": "green", "pose": [-1, -1, 0], "offset": [-1, -1]},
        ],
    }


@pytest.mark.slow
def test_the_platoon_parks_when_its_path_ends() -> None:
    # Without the turn limit in the anti-windup: orbits of 0.47 m, v2 = -3 rad/s, for
    # ever. With it every vehicle parks on its slot.
    run, m = run_scenario(platoon_on_a_path_that_ends(rotate=False))
    after = run.t > 15.0
    assert np.max(run.formation_error[after]) < 0.02
    # parked: no vehicle moves by more than a millimetre over the last 5 s (one may
    # still turn in place at a sub-millimetre error)
    assert np.ptp(run.pose[after, :, :2], axis=0).max() < 0.001
    assert np.abs(run.cmd[after, :, 1]).max() < 3.0  # no longer pinned at v2_max
    assert m["converged"] is True and m["collisions"]["total"] == 0


def test_stabilization_with_weak_brakes_parks_instead_of_orbiting() -> None:
    # stabilization.yaml's note: with max_accel = 4 m/s^2 the vehicle overshot and
    # circled the point at about 0.5 m. It now parks.
    run, m = run_scenario(PAPER / "stabilization.yaml", "vehicle.max_accel=4")
    blue = m["vehicles"]["blue"]
    assert blue["formation_error"]["final"] < 0.02
    assert blue["settling_time"] is not None and blue["settling_time"] < 6.0
    assert np.abs(run.cmd[-100:, 0, 1]).max() < 0.05


def test_limit_turn_keeps_chi_in_the_cone_of_the_heading() -> None:
    theta = np.array([0.0, 0.0, 0.0, 1.0])
    chi = np.array([[1.0, 0.05], [1.0, 1.0], [-1.0, 0.2], [0.0, 0.0]])
    out, aim = limit_turn(chi, theta, 0.1)
    # within the cone: unchanged
    np.testing.assert_array_equal(out[0], chi[0])
    assert np.isnan(aim[0])
    # 45 degrees off: its component along the cone's edge at 0.1 rad
    along = np.hypot(1.0, 1.0) * np.cos(np.pi / 4 - 0.1)
    np.testing.assert_allclose(out[1], along * np.array([np.cos(0.1), np.sin(0.1)]))
    assert aim[1] == pytest.approx(np.pi / 4)
    # pointing backwards: no motion, the vehicle turns towards it first
    np.testing.assert_array_equal(out[2], [0.0, 0.0])
    assert aim[2] == pytest.approx(np.arctan2(0.2, -1.0))
    # at rest: nothing to limit
    np.testing.assert_array_equal(out[3], [0.0, 0.0])
    assert np.isnan(aim[3])


@pytest.mark.slow
def test_rotated_slots_keep_the_last_tangent_when_the_path_ends() -> None:
    # Eq. (15) at rest was atan2(0, 0) = 0: red's slot jumped 1.5 m when the path
    # ended and the formation turned to the world frame.
    run, m = run_scenario(platoon_on_a_path_that_ends(rotate=True))
    steps = np.hypot(*np.diff(run.slot[:, 1], axis=0).T)
    assert steps.max() < 0.05  # no jump: at most the slot's own motion per period
    # final slots: the end point plus the offsets turned by the last tangent
    reference = run.scenario.reference.build()
    p, dp, _ = reference.evaluate(run.t)
    moving = np.flatnonzero(np.hypot(*dp.T) >= REST_SPEED)
    last = dp[moving[-1]]
    assert moving[-1] < len(run.t) - 100  # the path ended well before the run
    red = run.slot[-1, 1] - p[-1]
    angle = np.arctan2(red[1], red[0]) - np.arctan2(last[1], last[0])
    assert wrap_angle(angle) == pytest.approx(3 * np.pi / 4, abs=0.02)  # (-1, 1)
    assert np.max(run.formation_error[-1]) < 0.02


def test_a_reference_at_rest_from_the_start_uses_the_world_frame() -> None:
    law = LAWS["virtual"](np.array([[1.0, 0.0]]), 0.01, rotate=True)
    still = (np.zeros(2), np.zeros(2), np.zeros(2))
    slot, _, _ = law.targets(_inputs(still))
    np.testing.assert_allclose(slot, [[1.0, 0.0]])
    moving = (np.zeros(2), np.array([0.0, 1.0]), np.zeros(2))
    law.targets(_inputs(moving))
    slow = (np.zeros(2), np.array([0.5 * REST_SPEED, 0.0]), np.zeros(2))
    slot, _, _ = law.targets(_inputs(slow))
    np.testing.assert_allclose(slot, [[0.0, 1.0]], atol=1e-12)  # kept the last tangent


def _inputs(reference) -> LawInputs:
    return LawInputs(leader_pos=None, leader_theta=None, reference=reference)
