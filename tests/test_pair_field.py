"""The avoidance field's pair terms in C give the numpy path's bits (pair_field.py).

The extension is optional: where it is built, its check must pass on this machine, a
changed bit must fail it, and whole runs (alone and batched, with the true and the
broadcast positions, both weights the C loop computes) must equal the numpy path's to
the bit; where it is not built, only those assertions are skipped.
"""

from __future__ import annotations

import numpy as np
import pytest

from sandbox.behaviour import pair_field
from sandbox.loop.simulation import Simulation
from sandbox.scenario import load_scenario

BUILT = pair_field._pair_field is not None
needs_c = pytest.mark.skipif(not BUILT, reason="_pair_field not built")


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)


@needs_c
def test_the_check_passes_on_this_machine():
    assert pair_field.kernel_agrees()


@needs_c
def test_the_check_fails_on_one_changed_bit(monkeypatch):
    real = pair_field._pair_field.pair_field

    def off_by_one_ulp(*args):
        real(*args)
        shift = args[8]
        moved = np.flatnonzero(shift[:, 0])
        if len(moved):
            shift[moved[0], 0] = np.nextafter(shift[moved[0], 0], np.inf)

    class Patched:
        pair_field = staticmethod(off_by_one_ulp)

    monkeypatch.setattr(pair_field, "_pair_field", Patched)
    monkeypatch.setattr(pair_field, "_agreed", None)
    assert not pair_field.kernel_agrees()


def _run(name: str, overrides: list[str], use: bool, monkeypatch, batch: int = 0):
    monkeypatch.setattr(pair_field, "USE_KERNEL", use)
    if batch:
        scenarios = [
            load_scenario(name, overrides=[*overrides, f"seed={s}"])
            for s in range(batch)
        ]
        return Simulation.batch(scenarios)
    return [Simulation(load_scenario(name, overrides=overrides)).run()]


@needs_c
@pytest.mark.parametrize(
    "name, overrides, batch",
    [
        ("paper/fig15_continuous_beta1", ["duration=6"], 0),
        ("paper/fig13_discontinuous_beta1", ["duration=6"], 0),
        (
            "paper/fig15_continuous_beta1",
            ["duration=6", "sensing.position_noise=0.02"],
            0,
        ),
        ("failures/follower_stop", ["duration=5", "sensing.position_noise=0.01"], 3),
        ("failures/obstacle_field", ["duration=5"], 2),
    ],
)
def test_runs_with_the_c_terms_equal_numpy(monkeypatch, name, overrides, batch):
    with_c = _run(name, overrides, True, monkeypatch, batch)
    numpy = _run(name, overrides, False, monkeypatch, batch)
    for a, b in zip(with_c, numpy, strict=True):
        assert np.array_equal(_bits(a.pose), _bits(b.pose))
        assert np.array_equal(_bits(a.target), _bits(b.target))


@needs_c
@pytest.mark.parametrize(
    "name", ["paper/fig15_continuous_beta1", "failures/obstacle_field"]
)
def test_the_strategy_takes_the_c_path(monkeypatch, name):
    # Without obstacles the loop calls the C loop for the whole shift
    # (ShiftKernel); with them, weighted_shift calls it for the pairs' terms.
    calls = []
    real = pair_field._pair_field

    class Counted:
        ALLOCATES = real.ALLOCATES

        def pair_field(*args):
            calls.append("pair_field")
            return real.pair_field(*args)

        def shifted_targets(*args):
            calls.append("shifted_targets")
            return real.shifted_targets(*args)

    monkeypatch.setattr(pair_field, "_pair_field", Counted)
    Simulation(load_scenario(name, overrides=["duration=0.5"])).run()
    assert calls
    expected = "pair_field" if "obstacle" in name else "shifted_targets"
    assert set(calls) == {expected}


def test_use_kernel_false_forces_numpy(monkeypatch):
    monkeypatch.setattr(pair_field, "USE_KERNEL", False)

    def refuse(*args):
        raise AssertionError("the C path ran with USE_KERNEL False")

    monkeypatch.setattr(pair_field, "add_pair_terms", refuse)
    monkeypatch.setattr(pair_field.ShiftKernel, "shifted", refuse)
    run = Simulation(
        load_scenario("paper/fig15_continuous_beta1", overrides=["duration=0.5"])
    ).run()
    assert np.all(np.isfinite(run.pose))
