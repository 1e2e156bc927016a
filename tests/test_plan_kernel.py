"""The plan's C calls give the numpy path's bits (loop/plan_kernel.py).

A built-in law's targets (``model/law_kernel.py``, ``_laws.c``) and a weighted
strategy's shifted targets (``pair_field.ShiftKernel``) are optional C calls. Where
they are built, their checks must pass on this machine and fail on a changed bit;
whole runs of every law class (alone, batched, with the believed poses, with a
failure) must equal the numpy path's to the bit; the loop must choose them only
where they cover its configuration and fall back to numpy where a law or strategy
was replaced after the loop was built.
"""

from __future__ import annotations

import numpy as np
import pytest

from sandbox.behaviour import pair_field
from sandbox.loop.simulation import Simulation
from sandbox.model import law_kernel
from sandbox.scenario import load_scenario

BUILT = law_kernel._laws is not None and pair_field._pair_field is not None
needs_c = pytest.mark.skipif(not BUILT, reason="_laws or _pair_field not built")


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)


def _same_runs(a, b) -> None:
    for x, y in zip(a, b, strict=True):
        for name in ("pose", "target", "slot", "cmd", "chi"):
            assert np.array_equal(_bits(getattr(x, name)), _bits(getattr(y, name)))
        assert x.status == y.status and len(x.events) == len(y.events)


def _runs(name, overrides, use, monkeypatch, seeds=()):
    monkeypatch.setattr(law_kernel, "USE_KERNEL", use)
    monkeypatch.setattr(pair_field, "USE_KERNEL", use)
    if seeds:
        scenarios = [
            load_scenario(name, overrides=[*overrides, f"seed={s}"]) for s in seeds
        ]
        return Simulation.batch(scenarios)
    return [Simulation(load_scenario(name, overrides=overrides)).run()]


@needs_c
def test_the_checks_pass_on_this_machine():
    assert law_kernel.kernel_agrees()
    assert pair_field.shift_agrees()


@needs_c
def test_the_law_check_fails_on_one_changed_bit(monkeypatch):
    real = law_kernel._laws.law_targets

    def off_by_one_ulp(*args):
        slot, v_ref, a_ref, tangent = real(*args)
        slot[0, 0] = np.nextafter(slot[0, 0], np.inf)
        return slot, v_ref, a_ref, tangent

    class Patched:
        ALLOCATES = law_kernel._laws.ALLOCATES
        law_targets = staticmethod(off_by_one_ulp)

    monkeypatch.setattr(law_kernel, "_laws", Patched)
    monkeypatch.setattr(law_kernel, "_agreed", None)
    assert not law_kernel.kernel_agrees()


@needs_c
def test_the_shift_check_fails_on_one_changed_bit(monkeypatch):
    real = pair_field._pair_field

    def off_by_one_ulp(*args):
        target, shift, active, d2 = real.shifted_targets(*args)
        target[0, 1] = np.nextafter(target[0, 1], -np.inf)
        return target, shift, active, d2

    class Patched:
        ALLOCATES = real.ALLOCATES
        pair_field = staticmethod(real.pair_field)
        shifted_targets = staticmethod(off_by_one_ulp)

    monkeypatch.setattr(pair_field, "_pair_field", Patched)
    monkeypatch.setattr(pair_field, "_shift_agreed", None)
    assert not pair_field.shift_agrees()


@needs_c
@pytest.mark.parametrize("law", [law_kernel, pair_field])
def test_outputs_made_by_numpy_give_the_same_runs(monkeypatch, law):
    # A build without numpy's headers passes arrays it made: the same numbers.
    module = law._laws if law is law_kernel else law._pair_field
    name = "paper/fig15_continuous_beta1"
    made_by_c = _runs(name, ["duration=3"], True, monkeypatch)
    monkeypatch.setattr(module, "ALLOCATES", 0)
    made_by_numpy = _runs(name, ["duration=3"], True, monkeypatch)
    _same_runs(made_by_c, made_by_numpy)


@needs_c
@pytest.mark.parametrize(
    "name, overrides, seeds",
    [
        ("paper/fixed_circle", ["duration=4"], ()),
        ("paper/rotating_circle", ["duration=4"], ()),
        ("paper/virtual_fixed", ["duration=4"], ()),
        ("paper/virtual_rotating", ["duration=4"], ()),
        ("paper/leader_ref_drift", ["duration=4"], ()),
        ("paper/own_estimate_circle", ["duration=4"], ()),
        ("paper/circle_tracking", ["duration=4"], ()),
        ("paper/fig15_continuous_beta1", ["duration=6"], ()),
        ("paper/fig13_discontinuous_beta1", ["duration=6"], (0, 1, 2)),
        (
            "paper/virtual_rotating",
            ["duration=4", "sensing.position_noise=0.02"],
            (0, 1),
        ),
        ("failures/follower_stop", ["duration=5"], (0, 1, 2)),
        ("failures/follower_spin", ["duration=5", "sensing.position_noise=0.01"], ()),
        ("failures/leader_crash_virtual", ["duration=6"], ()),
    ],
)
def test_runs_with_the_plan_in_c_equal_numpy(monkeypatch, name, overrides, seeds):
    with_c = _runs(name, overrides, True, monkeypatch, seeds)
    numpy = _runs(name, overrides, False, monkeypatch, seeds)
    _same_runs(with_c, numpy)


@needs_c
def test_a_batch_of_two_betas_equals_numpy(monkeypatch):
    # Worlds of one structure with different aggressiveness: each row's beta.
    def runs(use):
        monkeypatch.setattr(pair_field, "USE_KERNEL", use)
        return Simulation.batch(
            [
                load_scenario(
                    "paper/fig15_continuous_beta1",
                    overrides=["duration=5", f"recovery.beta={beta}"],
                )
                for beta in (1.0, 5.0)
            ]
        )

    _same_runs(runs(True), runs(False))


def _built(name, overrides=()):
    return Simulation(load_scenario(name, overrides=list(overrides)))


@needs_c
def test_the_loop_chooses_the_c_calls_where_they_cover_it():
    def calls(sim):  # the law's and the strategy's C calls the loop chose
        return sim._formation.kernel, sim._avoidance.kernel

    law, shift = calls(_built("paper/fig15_continuous_beta1"))
    assert law is not None and shift is not None
    # obstacles to avoid, several platoons: the numpy path
    assert calls(_built("failures/obstacle_field"))[1] is None
    assert calls(_built("traffic/intersection_four")) == (None, None)
    # the tangential term is not in the C call
    tangential = _built("paper/fig15_continuous_beta1", ["recovery.tangential=0.5"])
    assert calls(tangential)[1] is None


@needs_c
def test_the_c_calls_run_and_numpy_stays_off(monkeypatch):
    calls = []
    real_law, real_field = law_kernel._laws, pair_field._pair_field

    class CountedLaws:
        ALLOCATES = real_law.ALLOCATES

        def law_targets(*args):
            calls.append("law")
            return real_law.law_targets(*args)  # an error: numpy's path, refused

    class CountedField:
        ALLOCATES = real_field.ALLOCATES
        pair_field = staticmethod(real_field.pair_field)

        def shifted_targets(*args):
            try:
                result = real_field.shifted_targets(*args)
            except Exception:  # the loop would take numpy's path
                calls.append("refused")
                raise
            calls.append("shift")
            return result

    monkeypatch.setattr(law_kernel, "_laws", CountedLaws)
    monkeypatch.setattr(pair_field, "_pair_field", CountedField)
    sim = _built("paper/fig15_continuous_beta1", ["duration=0.5"])

    def refuse(*args, **kwargs):
        raise AssertionError("the numpy law ran beside its C call")

    monkeypatch.setattr(type(sim.law), "targets", refuse)  # the class's, checked
    sim.run()
    assert calls.count("law") >= 50 and calls.count("shift") >= 50
    assert "refused" not in calls


@needs_c
def test_a_replaced_law_or_strategy_takes_the_numpy_path(monkeypatch):
    sim = _built("paper/fig15_continuous_beta1", ["duration=2"])
    seen = []
    original = sim.law.targets

    def spy(inputs):
        seen.append(1)
        return original(inputs)

    sim.law.targets = spy  # a wrapper on the law: the C call must not bypass it
    strategy_calls = []
    real_strategy = sim.strategy

    def strategy(ctx):
        strategy_calls.append(1)
        return real_strategy(ctx)

    sim.strategy = strategy
    run = sim.run()
    assert seen and strategy_calls
    monkeypatch.setattr(law_kernel, "USE_KERNEL", False)
    monkeypatch.setattr(pair_field, "USE_KERNEL", False)
    _same_runs([run], [_built("paper/fig15_continuous_beta1", ["duration=2"]).run()])
