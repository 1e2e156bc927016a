"""The flatness controller's C loops give the numpy functions' bits (model/kernels.py).

The extension is optional: where it is built, its self-check must pass on this
machine and whole controller steps must equal the numpy path's to the bit, over
random states, limits that bind and do not, NaN targets and row-wise gains; where it
is not built, only those assertions are skipped and the numpy path is checked to run.
"""

from __future__ import annotations

import numpy as np
import pytest

from sandbox.model import kernels
from sandbox.model.flatness import Gains
from sandbox.model.kernels import Controller

BUILT = kernels._kernels is not None
needs_c = pytest.mark.skipif(not BUILT, reason="sandbox.model._kernels not built")


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)


def _state(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    pos = rng.uniform(-5.0, 5.0, (n, 2))
    chi = rng.normal(0.0, 1.0, (n, 2))
    chi[rng.random(n) < 0.1] = 0.0  # standing vehicles: chi's angle undefined
    theta = rng.uniform(-np.pi, np.pi, n)
    target = pos + rng.normal(0.0, 2.0, (n, 2))
    target[rng.random((n, 2)) < 0.1] = np.nan  # a NaN coordinate aims at pos
    v_ref = rng.normal(0.0, 1.0, (n, 2))
    a_ref = rng.normal(0.0, 1.0, (n, 2))
    return pos, chi, theta, target, v_ref, a_ref


def _controllers(rng: np.random.Generator, n: int) -> list[Controller]:
    scalar = Gains(k1=4.0, k2=4.0, k3=4.0, k4=4.0, kp=1.0)
    rows = Gains(*(rng.uniform(0.5, 6.0, n) for _ in range(5)))
    v2_rows = rng.uniform(0.5, 4.0, n)
    return [
        Controller(scalar, 0.01, np.inf, np.inf, np.inf, None),
        Controller(scalar, 0.01, 1.0, 2.0, 3.0, 3.0),
        Controller(scalar, 0.02, 0.5, 0.5, 1.0, None),
        Controller(rows, 0.01, rng.uniform(0.3, 2.0, n), 1.5, v2_rows, v2_rows),
        Controller(rows, 0.01, 2.0, rng.uniform(0.3, 3.0, n), 2.0, None),
    ]


@needs_c
def test_the_self_check_passes_on_this_machine():
    assert kernels.kernels_agree()


@needs_c
@pytest.mark.parametrize("op", [0, 1, 2, 3, 4, 5, 6, 7])
def test_the_self_check_fails_on_one_changed_bit(monkeypatch, op):
    real = kernels._kernels

    class OneUlpOff:
        """The extension with one result of one operation moved by one ulp."""

        def elementwise(self, code, a, b, out):
            real.elementwise(code, a, b, out)
            if code == op:
                out[7] = np.nextafter(out[7], np.inf)

    monkeypatch.setattr(kernels, "_kernels", OneUlpOff())
    with np.errstate(all="ignore"):
        assert not kernels._agrees(*kernels._samples())


@needs_c
@pytest.mark.parametrize("n", [1, 3, 10, 64])
def test_a_controller_step_in_c_equals_numpy_to_the_bit(n):
    rng = np.random.default_rng(n)
    for controller in _controllers(rng, n):
        for _ in range(40):
            args = _state(rng, n)
            got = controller._step_c(*args)
            want = controller.step_numpy(*args)
            for g, w in zip(got, want, strict=True):
                assert g.shape == w.shape
                np.testing.assert_array_equal(_bits(g), _bits(w))


@needs_c
@pytest.mark.parametrize("n", [1, 3, 10, 64])
def test_the_period_in_one_call_equals_two_calls_and_numpy(monkeypatch, n):
    # the one call takes the angles of chi from the C library's atan2; two calls
    # take them from numpy's arctan2 between them: every bit the same
    assert kernels.atan2_agrees()
    rng = np.random.default_rng(100 + n)
    for controller in _controllers(rng, n):
        for _ in range(40):
            args = _state(rng, n)
            one = controller._step_c(*args)
            monkeypatch.setattr(kernels, "_atan2_agreed", False)
            two = controller._step_c(*args)
            monkeypatch.setattr(kernels, "_atan2_agreed", True)
            want = controller.step_numpy(*args)
            for a, b, w in zip(one, two, want, strict=True):
                np.testing.assert_array_equal(_bits(a), _bits(w))
                np.testing.assert_array_equal(_bits(b), _bits(w))


@needs_c
def test_the_atan2_check_fails_on_one_changed_bit(monkeypatch):
    real = kernels._kernels

    class OneUlpOff:
        """The extension with one arctangent moved by one ulp."""

        def elementwise(self, code, a, b, out):
            real.elementwise(code, a, b, out)
            if code == 8:
                out[11] = np.nextafter(out[11], np.inf)

    monkeypatch.setattr(kernels, "_kernels", OneUlpOff())
    assert not kernels._atan2_check()


@needs_c
def test_the_loop_takes_the_c_path(monkeypatch):
    calls = []
    original = Controller._step_c

    def counted(self, *args):
        calls.append(1)
        return original(self, *args)

    monkeypatch.setattr(Controller, "_step_c", counted)
    rng = np.random.default_rng(1)
    controller = _controllers(rng, 4)[1]
    controller.step(*_state(rng, 4))
    assert calls


def test_use_kernels_false_forces_numpy(monkeypatch):
    monkeypatch.setattr(kernels, "USE_KERNELS", False)

    def refuse(self, *args):
        raise AssertionError("the C path ran with USE_KERNELS False")

    monkeypatch.setattr(Controller, "_step_c", refuse)
    rng = np.random.default_rng(2)
    controller = _controllers(rng, 5)[3]
    chi_next, v1, v2 = controller.step(*_state(rng, 5))
    assert chi_next.shape == (5, 2) and v1.shape == v2.shape == (5,)
    assert np.all(np.abs(v2) <= controller.v2_max)


@needs_c
@pytest.mark.parametrize("substeps", [1, 4])
def test_the_motor_model_in_c_equals_numpy_to_the_bit(monkeypatch, substeps):
    from types import SimpleNamespace

    from sandbox.behaviour import detection

    rng = np.random.default_rng(substeps)
    n = 64
    accel = np.where(rng.random(n) < 0.3, np.inf, rng.uniform(0.5, 20.0, n))
    ctx = SimpleNamespace(
        dt=0.01,
        substeps=substeps,
        commands=rng.normal(0.0, 1.0, (n, 2)),
        motor_accel=accel,
        turn_accel=4.0 * accel / 0.15,
    )

    def state():
        r = np.random.default_rng(7)
        return SimpleNamespace(
            pose=r.normal(0.0, 2.0, (n, 3)),
            vel=r.normal(0.0, 1.0, (n, 2)),
            rate=r.normal(0.0, 1.0, n),
            travel=r.uniform(0.0, 1.0, n),
        )

    with_c, numpy = state(), state()
    calls = []
    real = kernels._kernels.motor_model
    monkeypatch.setattr(
        kernels._kernels, "motor_model", lambda *a: (calls.append(1), real(*a))[1]
    )
    for _ in range(5):
        detection._advance_model(with_c, ctx)
    assert len(calls) == 5
    monkeypatch.setattr(kernels, "USE_KERNELS", False)
    for _ in range(5):
        detection._advance_model(numpy, ctx)
    for name in ("pose", "vel", "rate", "travel"):
        assert np.array_equal(
            _bits(getattr(with_c, name)), _bits(getattr(numpy, name))
        ), name
