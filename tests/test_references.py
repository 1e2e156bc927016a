"""Reference trajectories: exact values and derivatives against finite differences."""

import math

import numpy as np
import pytest

from sandbox.model.references import (
    TABULATED_REFERENCES,
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


def test_lemniscate_start_and_direction() -> None:
    # As documented: starts at the centre heading +45 deg, the right lobe first and
    # clockwise (up, right, down: at a quarter lap it is at (c1 + a, c2) heading
    # straight down, dp = (a w cos(pi/2), a w cos(pi)) = (0, -a w)), back at the centre
    # at half a lap heading +135 deg, then the left lobe counter-clockwise, through
    # (c1 - a, c2) at three quarters, again heading straight down.
    ref = REFERENCES["lemniscate"]  # centre (0, 1), a = 6
    period = 2 * math.pi / ref.rate
    p, dp, _ = ref.evaluate(np.array([0.0, 0.25, 0.5, 0.75]) * period)
    np.testing.assert_allclose(p, [[0, 1], [6, 1], [0, 1], [-6, 1]], atol=1e-12)
    heading = np.degrees(np.arctan2(dp[:, 1], dp[:, 0]))
    np.testing.assert_allclose(heading, [45.0, -90.0, 135.0, -90.0], atol=1e-9)
    # the right lobe is run clockwise: the signed area swept about the centre is < 0
    # (the left lobe, the second half lap, counter-clockwise: > 0)
    for half, sign in ((0.0, -1.0), (0.5, 1.0)):
        t = np.linspace(half * period, (half + 0.5) * period, 2001)
        q, dq, _ = ref.evaluate(t)
        cross = q[:, 0] * dq[:, 1] - (q[:, 1] - 1) * dq[:, 0]  # about the centre (0, 1)
        assert sign * np.sum(cross[:-1] * np.diff(t)) > 0


def _dense_natural_spline(s: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The former dense n x n solve for the knots' second derivatives (reference)."""
    n = len(s)
    h = np.diff(s)
    a = np.zeros((n, n))
    rhs = np.zeros((n, 2))
    a[0, 0] = a[-1, -1] = 1.0
    for i in range(1, n - 1):
        a[i, i - 1] = h[i - 1]
        a[i, i] = 2.0 * (h[i - 1] + h[i])
        a[i, i + 1] = h[i]
        rhs[i] = 6.0 * ((y[i + 1] - y[i]) / h[i] - (y[i] - y[i - 1]) / h[i - 1])
    return np.linalg.solve(a, rhs)


def _dense_evaluate(s_all: np.ndarray, pts: np.ndarray, s: np.ndarray) -> tuple:
    """Position, d/ds and d2/ds2 of the dense-solve spline at arc positions ``s``."""
    m = _dense_natural_spline(s_all, pts)
    i = np.clip(np.searchsorted(s_all, s, side="right") - 1, 0, len(s_all) - 2)
    h = (s_all[i + 1] - s_all[i])[:, None]
    a = (s_all[i + 1] - s)[:, None]
    b = (s - s_all[i])[:, None]
    y0, y1, m0, m1 = pts[i], pts[i + 1], m[i], m[i + 1]
    p = (
        m0 * a**3 / (6 * h)
        + m1 * b**3 / (6 * h)
        + (y0 / h - m0 * h / 6) * a
        + (y1 / h - m1 * h / 6) * b
    )
    d1 = -m0 * a**2 / (2 * h) + m1 * b**2 / (2 * h) + (y1 - y0) / h - (m1 - m0) * h / 6
    d2 = m0 * a / h + m1 * b / h
    return p, d1, d2


@pytest.mark.parametrize("count", [3, 4, 40, 300])
def test_waypoints_spline_matches_the_dense_solve(count: int) -> None:
    rng = np.random.default_rng(count)
    pts = np.cumsum(rng.uniform(-1.0, 2.0, size=(count, 2)), axis=0)  # [m]
    speed = 1.5  # [m/s]
    ref = WaypointsReference(tuple(map(tuple, pts)), speed)
    t = np.linspace(0.0, 0.999 * ref.length / speed, 5001)
    p, dp, ddp = ref.evaluate(t)
    p0, d1, d2 = _dense_evaluate(ref.knots, pts, speed * t)
    scale = max(1.0, float(np.abs(pts).max()))
    np.testing.assert_allclose(p, p0, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(dp, d1 * speed, rtol=0, atol=1e-11 * scale)
    np.testing.assert_allclose(ddp, d2 * speed**2, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("name", sorted(REFERENCES))
def test_a_tabulated_reference_gives_the_bits_of_each_time_alone(name: str) -> None:
    # The loop evaluates these for many periods at once and reads row k at t = k h
    # (loop/simulation.py, loop/platoon_targets.py): every row must be the scalar
    # evaluation's bits, past the end of a waypoint path too.
    ref = REFERENCES[name]
    assert type(ref) in TABULATED_REFERENCES
    h = 0.01
    rows = ref.evaluate(np.array([k * h for k in range(2500)]))
    for k in range(0, 2500, 3):
        alone = ref.evaluate(k * h)
        for table, value in zip(rows, alone, strict=True):
            assert table[k].tobytes() == np.asarray(value, dtype=float).tobytes()
