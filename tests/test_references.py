"""Reference trajectories: exact values and derivatives against finite differences."""

import math

import numpy as np
import pytest

from sandbox.references import (
    CircleReference,
    LemniscateReference,
    LineReference,
    PointReference,
    WaypointsReference,
)

REFERENCES = {
    "point": PointReference((1.0, -2.0)),
    "line": LineReference((1.0, 2.0), 0.5, 1.5),
    "circle": CircleReference((1.0, -1.0), 5.0, 1.0, 0.3),
    "circle_cw": CircleReference((0.0, 0.0), 3.0, -2.0, 0.0),
    "lemniscate": LemniscateReference((0.0, 1.0), 6.0, 1.2),
    "waypoints": WaypointsReference(
        ((0.0, 0.0), (5.0, 0.0), (8.0, 4.0), (8.0, 10.0)), 1.0
    ),
}


@pytest.mark.parametrize("name", sorted(REFERENCES))
def test_derivatives_match_finite_differences(name: str) -> None:
    ref = REFERENCES[name]
    t = np.linspace(0.3, 12.0, 37)  # inside the waypoint path (length ~16 m at 1 m/s)
    eps = 1e-5
    p_plus, dp_plus, _ = ref.evaluate(t + eps)
    p_minus, dp_minus, _ = ref.evaluate(t - eps)
    _, dp, ddp = ref.evaluate(t)
    assert dp.shape == ddp.shape == (len(t), 2)
    np.testing.assert_allclose((p_plus - p_minus) / (2 * eps), dp, atol=1e-6)
    np.testing.assert_allclose((dp_plus - dp_minus) / (2 * eps), ddp, atol=1e-5)


def test_point_is_still() -> None:
    p, dp, ddp = REFERENCES["point"].evaluate(7.0)
    assert p.tolist() == [1.0, -2.0]
    assert not dp.any() and not ddp.any()


def test_line_values() -> None:
    # start (1, 2), heading 0.5 rad, 1.5 m/s: after 2 s, 3 m along (cos 0.5, sin 0.5)
    # = (0.877583, 0.479426) -> (1 + 2.632748, 2 + 1.438277)
    p, dp, ddp = REFERENCES["line"].evaluate(2.0)
    np.testing.assert_allclose(p, [3.632748, 3.438277], atol=1e-6)
    np.testing.assert_allclose(dp, [1.5 * math.cos(0.5), 1.5 * math.sin(0.5)])
    assert not ddp.any()


def test_circle_values() -> None:
    # radius 5, 1 m/s: w = 0.2 rad/s; at t = 0 with phase 0.3 the point is
    # c + 5 (cos .3, sin .3), the velocity 1 m/s along the tangent (-sin .3, cos .3) and
    # the acceleration V^2/R = 0.2 m/s^2 towards the centre.
    p, dp, ddp = REFERENCES["circle"].evaluate(0.0)
    c, s = math.cos(0.3), math.sin(0.3)
    np.testing.assert_allclose(p, [1 + 5 * c, -1 + 5 * s])
    np.testing.assert_allclose(dp, [-s, c])
    np.testing.assert_allclose(ddp, [-0.2 * c, -0.2 * s])
    # negative speed: clockwise; a quarter lap (pi/2 * 3 m at 2 m/s) ends at (0, -3)
    p, _, _ = REFERENCES["circle_cw"].evaluate(math.pi * 3 / 4)
    np.testing.assert_allclose(p, [0.0, -3.0], atol=1e-12)


def test_lemniscate_mean_speed_over_a_lap() -> None:
    ref = REFERENCES["lemniscate"]
    period = 2 * math.pi / ref.rate
    t = np.linspace(0.0, period, 20001)
    _, dp, _ = ref.evaluate(t)
    speed = np.hypot(dp[:, 0], dp[:, 1])
    mean = float(np.sum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t)) / period)
    assert mean == pytest.approx(1.2, rel=1e-4)
    p0, _, _ = ref.evaluate(0.0)
    np.testing.assert_allclose(p0, [0.0, 1.0])  # starts at its centre


def test_waypoints_pass_through_points_and_stop_at_the_end() -> None:
    ref = REFERENCES["waypoints"]
    pts = np.array(ref.points)
    times = ref.knots / ref.speed  # chord-length parameter at 1 m/s
    p, _, _ = ref.evaluate(times)
    np.testing.assert_allclose(p, pts, atol=1e-12)
    p_end, dp_end, ddp_end = ref.evaluate(times[-1] + 5.0)
    np.testing.assert_allclose(p_end, pts[-1], atol=1e-12)
    assert not dp_end.any() and not ddp_end.any()


def test_waypoints_speed_close_to_nominal() -> None:
    ref = WaypointsReference(((0.0, 0.0), (10.0, 0.0)), 2.0)  # a straight segment
    _, dp, ddp = ref.evaluate(np.linspace(0.1, 4.9, 9))
    np.testing.assert_allclose(dp, [[2.0, 0.0]] * 9, atol=1e-12)
    np.testing.assert_allclose(ddp, 0.0, atol=1e-12)
