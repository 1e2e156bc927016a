"""The residual detector's pass and the stop fits in C give numpy's numbers.

The extensions are optional (``sandbox.behaviour._residual``, ``_fits``): where one is
built, its first-use check must pass on this machine and fail on one changed bit, and
whole runs, single and batched, of the bundled ``detect_*`` scenarios (broadcast
noise, with delay and loss) must equal the numpy path's to the bit, their detections,
kinds and clearings included; where it is not built, those assertions are skipped and
the numpy path is checked to run.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from helpers import SCENARIOS

from sandbox import Simulation, load_scenario
from sandbox.behaviour import detection, residual_kernel, tracks
from sandbox.model import kernels

FAILURES = SCENARIOS / "failures"
needs_residual = pytest.mark.skipif(
    residual_kernel._residual is None, reason="behaviour._residual not built"
)
needs_fits = pytest.mark.skipif(
    tracks._fits is None, reason="behaviour._fits not built"
)
#: The ops of _residual.elementwise the check compares (8: the llr).
OPS = range(10)


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.uint64)


class Counted:
    """The C pass of the residual detector, counting its calls and rows."""

    def __init__(self, monkeypatch):
        self.calls, self.rows = 0, 0
        real = residual_kernel._residual
        if real is None:
            return
        residual_kernel.kernel_agrees()  # its check's passes are not counted

        def period(*args):
            self.calls += 1
            self.rows = max(self.rows, len(args[0].rate))
            return real.residual_period(*args)

        fake = SimpleNamespace(residual_period=period, elementwise=real.elementwise)
        monkeypatch.setattr(residual_kernel, "_residual", fake)


def _numpy_only(monkeypatch) -> None:
    monkeypatch.setattr(residual_kernel, "USE_KERNEL", False)
    monkeypatch.setattr(tracks, "USE_KERNEL", False)
    monkeypatch.setattr(kernels, "USE_KERNELS", False)


def _run(scenarios) -> tuple[list, detection.DetectorState]:
    """The runs of the scenarios stepped at once, and their detector's last state."""
    sim = Simulation.stacked(scenarios)
    runs = sim.run_all()
    detector = sim.detection
    return runs, detector.memory["state"]


def _assert_same(with_c, numpy) -> None:
    """The same runs, detections and detector state, bit for bit."""
    (runs_c, state_c), (runs_n, state_n) = with_c, numpy
    for a, b in zip(runs_c, runs_n, strict=True):
        for name in ("pose", "cmd", "chi", "target", "failed"):
            x, y = _bits(getattr(a, name)), _bits(getattr(b, name))
            assert np.array_equal(x, y), name
        assert a.events == b.events
        assert a.info["detection"] == b.info["detection"]
    assert state_c.kinds == state_n.kinds
    for name, value in vars(state_c).items():
        if isinstance(value, np.ndarray):
            other = getattr(state_n, name)
            if value.dtype == np.float64:
                assert residual_kernel.same_numbers(value, other), name
            else:
                assert np.array_equal(value, other), name


def _scenarios(name: str, seeds: range, *sets: str, duration: float = 4.5):
    return [
        load_scenario(
            FAILURES / f"{name}.yaml",
            overrides=[*sets, f"duration={duration}", f"seed={seed}"],
        )
        for seed in seeds
    ]


# ------------------------------------------------------------------ the checks
@needs_residual
def test_the_check_passes_on_this_machine():
    assert residual_kernel.kernel_agrees()


@needs_residual
@pytest.mark.parametrize("op", OPS)
def test_the_check_fails_on_one_changed_bit_of_a_function(monkeypatch, op):
    real = residual_kernel._residual

    def off_by_one_ulp(k, a, b, out):
        real.elementwise(k, a, b, out)
        if k == op:
            j = int(np.flatnonzero(np.isfinite(out) & (out != 0.0))[0])
            out[j] = np.nextafter(out[j], np.inf)

    fake = SimpleNamespace(
        elementwise=off_by_one_ulp, residual_period=real.residual_period
    )
    monkeypatch.setattr(residual_kernel, "_residual", fake)
    monkeypatch.setattr(residual_kernel, "_agreed", None)
    assert not residual_kernel.kernel_agrees()


@needs_residual
@pytest.mark.parametrize("field", ["travel", "g", "acc_rot0"])
def test_the_check_fails_on_one_changed_bit_of_the_pass(monkeypatch, field):
    real = residual_kernel._residual

    def off_by_one_ulp(*args):
        out = real.residual_period(*args)
        values = getattr(args[0], field)
        j = int(np.flatnonzero(values)[0]) if np.any(values) else 0
        values[j] = np.nextafter(values[j], np.inf)
        return out

    fake = SimpleNamespace(elementwise=real.elementwise, residual_period=off_by_one_ulp)
    monkeypatch.setattr(residual_kernel, "_residual", fake)
    monkeypatch.setattr(residual_kernel, "_agreed", None)
    assert not residual_kernel.kernel_agrees()


def test_the_checks_platoon_reads_every_branch():
    # The synthetic platoon of the check alarms, reads kinds on while isolating,
    # clears, skips windows in contact and carries a NaN observation.
    state, trace, events = residual_kernel.synthetic_run(False)
    read = sum(len(e[0]) for e in events if e)
    cleared = sum(len(e[1]) for e in events if e)
    alarms = sum(len(e[2]) for e in events if e)
    assert read > 10 and cleared > 5 and alarms > 5
    assert any(np.isnan(x) for _, _, x in trace)


def test_same_numbers_compares_bits_and_not_a_nans_sign():
    a = np.array([1.0, -0.0, np.nan])
    assert residual_kernel.same_numbers(a, np.array([1.0, -0.0, -np.nan]))
    assert not residual_kernel.same_numbers(a, np.array([1.0, 0.0, np.nan]))
    b = a.copy()
    b[0] = np.nextafter(1.0, 2.0)
    assert not residual_kernel.same_numbers(a, b)


@needs_fits
def test_the_fits_check_passes_on_this_machine():
    assert tracks.fits_agree()


@needs_fits
@pytest.mark.parametrize("which", [0, 1])
def test_the_fits_check_fails_on_one_changed_bit(monkeypatch, which):
    real = tracks._fits

    def off_by_one_ulp(*args):
        out = list(real.fits(*args))
        out[which] = np.nextafter(out[which], np.inf)
        return tuple(out)

    fake = SimpleNamespace(fits=off_by_one_ulp, stop_estimates=real.stop_estimates)
    monkeypatch.setattr(tracks, "_fits", fake)
    monkeypatch.setattr(tracks, "_fits_agreed", None)
    assert not tracks.fits_agree()


@needs_fits
def test_the_fits_in_c_equal_numpy_on_many_tracks():
    rng = np.random.default_rng(11)
    with np.errstate(all="ignore"):
        for k in range(96):
            t, s, brake = tracks.sample_track(rng, k)
            got = tracks.stop_fits(t, s, brake)
            want = tracks.fits_numpy(*tracks._numpy_grid(t, s), brake)
            assert residual_kernel.same_numbers(np.array(got), np.array(want)), k


@pytest.mark.skipif(kernels._kernels is None, reason="model._kernels not built")
def test_the_motor_models_norm_is_skipped_only_below_the_limit(monkeypatch):
    # Velocities at, just inside and just outside the motor's reach of the command,
    # and tiny limits: the C model takes the norm only where it may bind.
    n = 400
    rng = np.random.default_rng(5)
    accel = rng.choice([1e-99, 1e-96, 1e-3, 2.0, 40.0, np.inf], n)
    commands = rng.normal(0.0, 1.0, (n, 2))
    heading = rng.uniform(-3.0, 3.0, n)
    mid = heading + 0.5 * commands[:, 1] * 0.01
    target = commands[:, :1] * np.column_stack((np.cos(mid), np.sin(mid)))
    reach = accel * 0.01 / 4.0 * rng.choice([0.499, 0.5, 0.501, 1.0, 2.0], n)
    angle = rng.uniform(-np.pi, np.pi, n)
    vel = target - np.where(np.isfinite(reach), reach, 1.0)[:, None] * np.column_stack(
        (np.cos(angle), np.sin(angle))
    )
    ctx = SimpleNamespace(
        dt=0.01,
        substeps=4,
        commands=commands,
        motor_accel=accel,
        turn_accel=4.0 * accel / 0.15,
    )

    def state():
        pose = np.column_stack((rng.normal(0.0, 1.0, (n, 2)), heading))
        return SimpleNamespace(
            pose=pose, vel=vel.copy(), rate=np.zeros(n), travel=np.zeros(n)
        )

    with_c, numpy = state(), state()
    numpy.pose[:] = with_c.pose
    detection._advance_model(with_c, ctx)
    monkeypatch.setattr(kernels, "USE_KERNELS", False)
    detection._advance_model(numpy, ctx)
    for name in ("pose", "vel", "rate", "travel"):
        assert np.array_equal(_bits(getattr(with_c, name)), _bits(getattr(numpy, name)))


# ------------------------------------------------------------------ whole runs
@needs_residual
@pytest.mark.parametrize(
    "sets",
    [
        (),
        ("sensing.delay=0.02", "sensing.loss=0.1"),
        ("vehicle.motor_accel=6", "detection.lambda=6"),
    ],
)
def test_a_single_run_in_c_equals_numpy(monkeypatch, sets):
    (sc,) = _scenarios("detect_follower_stop", range(1), *sets)
    counted = Counted(monkeypatch)
    with_c = _run([sc])
    assert counted.calls > 400 and counted.rows == 4
    if not sets:
        (event,) = with_c[0][0].info["detection"]["events"]
        assert event["vehicle"] == "red" and event["kind"] == "stop"
    _numpy_only(monkeypatch)
    calls = counted.calls
    numpy = _run([sc])
    assert counted.calls == calls  # the numpy path alone
    _assert_same(with_c, numpy)


@needs_residual
@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "duration"),
    [
        ("detect_follower_stop", 5.0),
        ("detect_follower_spin", 5.0),
        ("detect_follower_stuck_steering", 5.0),
        ("detect_follower_crash", 5.0),
        ("detect_leader_spin", 8.0),  # cleared at 7.36 s
        ("detect_uncontrolled_into_leader", 15.2),  # cleared at 14.95 s
        ("detect_fault_free", 6.0),
    ],
)
@pytest.mark.parametrize("sets", [(), ("sensing.delay=0.03", "sensing.loss=0.2")])
def test_batched_runs_in_c_equal_numpy(monkeypatch, name, duration, sets):
    scenarios = _scenarios(name, range(4), *sets, duration=duration)
    counted = Counted(monkeypatch)
    with_c = _run(scenarios)
    assert counted.rows == 4 * len(scenarios[0].vehicles)  # every world at once
    _numpy_only(monkeypatch)
    numpy = _run(scenarios)
    _assert_same(with_c, numpy)
    events = [e for run in with_c[0] for e in run.info["detection"]["events"]]
    if name == "detect_fault_free":
        assert not events
    else:
        assert events and all(e["kind"] for e in events)
    if name in ("detect_leader_spin", "detect_uncontrolled_into_leader") and not sets:
        assert any(e["cleared"] is not None for e in events)


@needs_residual
def test_a_batch_with_a_clearing_in_c_equals_numpy(monkeypatch):
    # A short isolation and a low threshold: alarms, readings and clearings within
    # four seconds, in four worlds at once, with delayed and lost packets.
    sets = (
        "detection.lambda=4",
        "detection.isolation=0.1",
        "sensing.delay=0.01",
        "sensing.loss=0.1",
    )
    scenarios = _scenarios("detect_leader_spin", range(4), *sets, duration=4.0)
    counted = Counted(monkeypatch)
    with_c = _run(scenarios)
    assert counted.rows == 4 * len(scenarios[0].vehicles)
    _numpy_only(monkeypatch)
    numpy = _run(scenarios)
    _assert_same(with_c, numpy)
    events = [e for run in with_c[0] for e in run.info["detection"]["events"]]
    assert any(e["cleared"] is not None for e in events)
    assert len({e["kind"] for e in events}) > 1


@needs_residual
def test_the_trace_in_c_equals_numpy(monkeypatch):
    (sc,) = _scenarios("detect_follower_spin", range(1), "sensing.loss=0.2")

    def traced():
        sim = Simulation(sc)
        sim.detection.memory["trace"] = trace = []
        sim.run()
        return trace

    with_c = traced()
    _numpy_only(monkeypatch)
    numpy = traced()
    assert [x[:2] for x in with_c] == [x[:2] for x in numpy] and len(with_c) > 100
    assert np.array_equal(_bits([x[2] for x in with_c]), _bits([x[2] for x in numpy]))


def test_without_the_extension_the_numpy_pass_runs(monkeypatch):
    (sc,) = _scenarios("detect_follower_crash", range(1), duration=3.6)
    monkeypatch.setattr(residual_kernel, "_residual", None)
    monkeypatch.setattr(residual_kernel, "_agreed", None)
    monkeypatch.setattr(tracks, "_fits", None)
    monkeypatch.setattr(tracks, "_fits_agreed", None)
    assert not residual_kernel.usable() and not tracks.fits_agree()
    calls = []
    real = detection.residual_pass
    monkeypatch.setattr(
        detection, "residual_pass", lambda *a: (calls.append(1), real(*a))[1]
    )
    run = Simulation(sc).run()
    (event,) = run.info["detection"]["events"]
    assert event["kind"] == "crash" and len(calls) > 300


@needs_residual
def test_a_changed_bit_of_the_pass_shows_in_the_comparison(monkeypatch):
    # The comparison of whole runs sees one unit in the last place of the predicted
    # travel (which no output shows).
    (sc,) = _scenarios("detect_follower_stop", range(1), duration=3.2)
    real = residual_kernel._residual

    def off_by_one_ulp(*args):
        out = real.residual_period(*args)
        travel = args[0].travel
        travel[0] = np.nextafter(travel[0], np.inf)
        return out

    with_c = _run([sc])
    fake = SimpleNamespace(elementwise=real.elementwise, residual_period=off_by_one_ulp)
    monkeypatch.setattr(residual_kernel, "_residual", fake)
    with pytest.raises(AssertionError, match="travel"):
        _assert_same(with_c, _run([sc]))
