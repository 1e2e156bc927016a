"""Properties of the control helpers (hypothesis): ranges, norms, finiteness."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sandbox.model.dynamics import wrap_angle
from sandbox.model.flatness import (
    CHI_REST,
    Gains,
    advance_extension,
    extension_rate,
    flat_inputs,
)
from sandbox.model.laws import BackwardDifference, rotate_offsets

#: Physically meaningful magnitudes (no overflow of squares: warnings are errors).
BIG = 1e6
finite = st.floats(-BIG, BIG, allow_nan=False, allow_infinity=False)
#: Speeds that include exact zero and values just around the rest threshold.
tiny = st.one_of(
    st.just(0.0),
    st.floats(-10 * CHI_REST, 10 * CHI_REST, allow_nan=False),
    st.sampled_from(
        [CHI_REST, -CHI_REST, np.nextafter(CHI_REST, 0.0), 1e-300, -1e-300]
    ),
)
speed = st.one_of(tiny, finite)
vec = st.tuples(finite, finite).map(lambda p: np.array([p], dtype=float))
chi_vec = st.tuples(speed, speed).map(lambda p: np.array([p], dtype=float))
angle = st.floats(-1e12, 1e12, allow_nan=False)


@settings(deadline=None)
@given(
    st.one_of(
        angle,
        st.sampled_from(
            [
                math.pi,
                -math.pi,
                np.nextafter(-math.pi, -4.0),
                np.nextafter(math.pi, 4.0),
                0.0,
                -0.0,
            ]
        ),
    )
)
def test_wrapped_angles_stay_in_range(a: float) -> None:
    w = float(wrap_angle(a))
    assert -math.pi <= w < math.pi
    if abs(a) < 1e6:  # the same direction (precision of a itself permitting)
        assert abs(math.cos(w) - math.cos(a)) < 1e-6
        assert abs(math.sin(w) - math.sin(a)) < 1e-6


@settings(deadline=None)
@given(st.lists(angle, min_size=1, max_size=20))
def test_wrapped_arrays_stay_in_range(values: list[float]) -> None:
    w = wrap_angle(np.array(values))
    assert w.shape == (len(values),)
    assert np.all((w >= -math.pi) & (w < math.pi))


@settings(deadline=None)
@given(st.lists(st.tuples(finite, finite), min_size=1, max_size=10), angle)
def test_rotating_offsets_preserves_norms(offsets: list, a: float) -> None:
    delta = np.array(offsets, dtype=float)
    out = rotate_offsets(delta, a)
    np.testing.assert_allclose(
        np.hypot(*out.T), np.hypot(*delta.T), rtol=1e-12, atol=1e-9
    )
    # and it is a rotation: turning back restores the offsets
    np.testing.assert_allclose(rotate_offsets(out, -a), delta, rtol=1e-9, atol=1e-6)


@settings(deadline=None)
@given(finite, chi_vec, vec, st.floats(0.0, 100.0))
def test_eq5_finite_for_finite_inputs(
    theta: float, chi: np.ndarray, chi_dot: np.ndarray, kp: float
) -> None:
    v1, v2 = flat_inputs(np.array([theta]), chi, chi_dot, kp)
    assert np.isfinite(v1).all() and np.isfinite(v2).all()
    c1, c2 = chi[0]
    if c1 * c1 + c2 * c2 >= CHI_REST * CHI_REST:
        assert v1[0] == pytest.approx(math.hypot(c1, c2), rel=1e-14)
    else:  # no direction: hold the heading, move along it
        along = c1 * math.cos(theta) + c2 * math.sin(theta)
        assert v1[0] == pytest.approx(along, rel=1e-12, abs=1e-300)
        assert v2[0] == 0.0


@settings(deadline=None)
@given(vec, chi_vec, vec, vec, vec)
def test_eq6_finite_for_finite_inputs(pos, chi, p_ref, v_ref, a_ref) -> None:
    out = extension_rate(pos, chi, p_ref, v_ref, a_ref, Gains())
    assert out.shape == (1, 2) and np.isfinite(out).all()


@settings(deadline=None)
@given(
    st.floats(0.0, 1.0).flatmap(
        lambda frac: st.tuples(st.just(frac), st.floats(0.0, 2 * math.pi))
    ),
    vec,
    st.floats(1e-3, 0.1),
    st.floats(0.01, 50.0),
    st.floats(0.1, 100.0),
)
def test_advance_extension_respects_its_limits(
    start, chi_dot, dt, v1_max, accel
) -> None:
    frac, direction = start
    chi = frac * v1_max * np.array([[math.cos(direction), math.sin(direction)]])
    nxt, applied = advance_extension(
        chi, chi_dot, dt, np.array([v1_max]), np.array([accel])
    )
    assert np.isfinite(nxt).all() and np.isfinite(applied).all()
    assert np.hypot(*nxt[0]) <= v1_max * (1 + 1e-12)
    assert np.hypot(*(nxt - chi)[0]) <= accel * dt * (1 + 1e-9) + 1e-15
    np.testing.assert_allclose(applied * dt, nxt - chi, atol=1e-12)


@settings(deadline=None)
@given(vec, vec, st.floats(1e-3, 1.0), st.integers(3, 8))
def test_backward_differences_exact_on_straight_motion(x0, vel, h, steps) -> None:
    est = BackwardDifference(h)
    for k in range(steps):
        v, a = est.update(x0 + vel * (k * h))
    scale = 1.0 + np.abs(x0).max() / h + np.abs(vel).max()
    np.testing.assert_allclose(v, vel, atol=1e-9 * scale)
    np.testing.assert_allclose(a, 0.0, atol=1e-9 * scale / h)
