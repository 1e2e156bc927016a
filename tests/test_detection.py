"""Detection without an oracle: the ``residual`` detector and ``detection:``."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from helpers import SCENARIOS, run_scenario

from sandbox import Simulation, compute_metrics, load_scenario, simulate
from sandbox.behaviour.detection import llr
from sandbox.behaviour.tracks import stop_fits
from sandbox.errors import ScenarioError

FAILURES = SCENARIOS / "failures"
ORACLE = "detection.method=oracle"

#: scenario, failed vehicle, the kind the residual detector names (the measured one).
BUNDLED = [
    ("detect_follower_stop", "red", "stop"),
    ("detect_follower_spin", "red", "spin"),
    ("detect_follower_stuck_steering", "red", "stuck_steering"),
    ("detect_leader_spin", "leader", "spin"),
    ("detect_uncontrolled_into_leader", "green", "uncontrolled"),
    # A crash stops within a substep; a stop brakes at max_accel = 5 m/s^2.
    ("detect_follower_crash", "red", "crash"),
]


@cache
def result(name: str, *sets: str, **fields):
    """``(run, metrics)`` of ``scenarios/failures/<name>.yaml``, run once."""
    return run_scenario(FAILURES / f"{name}.yaml", *sets, **fields)


@pytest.mark.slow
@pytest.mark.parametrize(("name", "vehicle", "kind"), BUNDLED)
def test_every_bundled_failure_is_detected_within_half_a_second(name, vehicle, kind):
    _, m = result(name)
    (failure,) = m["detection"]["failures"]
    assert failure["vehicle"] == vehicle
    assert failure["delay"] is not None and 0.0 <= failure["delay"] <= 0.5
    assert failure["detected_kind"] == kind
    assert failure["kind_right"] == (kind == failure["kind"])
    first = m["detections"][0]
    assert (first["vehicle"], first["kind"], first["false_alarm"]) == (
        vehicle,
        kind,
        False,
    )
    assert m["detection"]["false_alarms"] == 0


@pytest.mark.slow
@pytest.mark.parametrize(("name", "vehicle", "kind"), BUNDLED)
def test_no_more_healthy_collisions_than_under_the_oracle(name, vehicle, kind):
    residual = result(name)[1]["collisions"]["healthy"]
    oracle = result(name, ORACLE)[1]["collisions"]["healthy"]
    assert residual <= oracle


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "kind"),
    [("detect_follower_stop", "stop"), ("detect_follower_crash", "crash")],
)
def test_a_crash_is_told_from_a_stop_by_its_deceleration(name, kind):
    # A stop brakes at max_accel = 5 m/s^2, a crash within a substep: told apart on
    # other seeds' noise too (20 of 20 seeds each measured, docs/concepts/detection.md).
    for seed in (1, 2, 3, 4):
        _, m = result(name, seed=seed, duration=4)
        (failure,) = m["detection"]["failures"]
        assert failure["detected_kind"] == kind, seed
        assert failure["delay"] <= 0.5


def test_without_an_acceleration_limit_a_crash_moves_as_a_stop():
    # No max_accel: the drive stops within a substep as a wreck does; with no contact
    # nothing tells them apart and the detector says stop.
    _, m = result("detect_follower_crash", "vehicle.max_accel=null", duration=4)
    (failure,) = m["detection"]["failures"]
    assert failure["detected_kind"] == "stop" and failure["delay"] <= 0.5


def test_the_stop_and_crash_fits():
    # A track braked at 5 m/s^2 fits the stop, one stopped at once the crash.
    t = np.arange(0.0, 1.0, 0.01)
    rng = np.random.default_rng(0)
    ramp = np.clip(t - 0.4, 0.0, 0.2)
    braked = np.minimum(t, 0.4) + ramp - 2.5 * ramp**2
    noise = rng.normal(0.0, 0.01, t.size)
    crash, stop = stop_fits(t, braked + noise, 5.0)
    assert stop < crash
    crash, stop = stop_fits(t, np.minimum(t, 0.5) + noise, 5.0)
    assert crash < stop


@pytest.mark.slow
def test_a_runaway_is_told_from_a_stuck_steering_by_its_speed():
    # At the alarm green's runaway looks like a stuck steering (its speed is near what
    # its controller asks for); read on through the isolation time its speed departs
    # too, and the detection's kind becomes uncontrolled.
    sim = Simulation(load_scenario(FAILURES / "detect_uncontrolled_into_leader.yaml"))
    (events,) = sim.detection.events  # one world
    while not events:
        sim.step()
    assert events[0]["kind"] == "stuck_steering"
    assert result("detect_uncontrolled_into_leader")[1]["detections"][0]["kind"] == (
        "uncontrolled"
    )


@pytest.mark.slow
def test_a_cleared_failure_is_withdrawn():
    # The leader spins from 3 s to 7 s; once it drives as commanded again the
    # detection is withdrawn.
    _, m = result("detect_leader_spin")
    (d,) = m["detections"]
    assert 7.0 < d["cleared"] < 8.0


@pytest.mark.slow
def test_fault_free_runs_give_no_false_alarm():
    # 4 vehicles x 30 s of another seed's noise (the vehicle-hours:
    # docs/concepts/detection.md).
    run, m = result("detect_fault_free", seed=7, duration=30)
    assert m["detections"] == []
    assert m["detection"]["false_alarms"] == 0
    assert run.info["detection"]["method"] == "residual"


def test_only_detected_failures_change_behaviour():
    # known_failed is the detector's, not the truth: red fails at 3 s and is believed
    # failed only once detected (0.07 s later); the oracle knows at once.
    sim = Simulation(load_scenario(FAILURES / "detect_follower_stop.yaml"))
    oracle = Simulation(
        load_scenario(FAILURES / "detect_follower_stop.yaml", overrides=[ORACLE])
    )
    while sim.t < 3.005:
        sim.step()
        oracle.step()
    assert sim.plan.failing[1] and not sim.known_failed[1]
    assert oracle.known_failed[1]
    while sim.t < 3.2:
        sim.step()
    assert sim.known_failed.tolist() == [False, True, False, False]


def test_the_oracle_is_the_default_to_the_bit():
    doc = FAILURES / "follower_stop.yaml"
    default = simulate(load_scenario(doc, overrides=["duration=4"]))
    oracle = simulate(load_scenario(doc, overrides=["duration=4", ORACLE]))
    assert load_scenario(doc).detection.method == "oracle"
    for key in ("pose", "cmd", "chi", "target", "mode", "failed"):
        assert np.array_equal(getattr(default, key), getattr(oracle, key)), key
    assert "detection" not in default.info


def test_detection_without_noise_uses_the_floor():
    # No sensing: the truth is seen; a stop is still found at once, and a healthy
    # platoon's model error stays far inside the 1 mm floor (no false alarm).
    _, m = run_scenario(
        FAILURES / "follower_stop.yaml", "detection.method=residual", duration=6
    )
    (failure,) = m["detection"]["failures"]
    assert failure["delay"] <= 0.2 and failure["detected_kind"] == "stop"
    assert m["detection"]["false_alarms"] == 0


def test_the_llr_is_a_likelihood_ratio():
    # E0[exp(l)] = 1 under no fault (what Lorden's bound e^lambda rests on).
    rng = np.random.default_rng(0)
    r = np.linalg.norm(rng.standard_normal((400_000, 3)), axis=1)
    assert np.mean(np.exp(llr(r, 2.0))) == pytest.approx(1.0, abs=0.03)
    assert np.mean(llr(r, 4.0)) < 0


@pytest.mark.parametrize(
    ("sets", "field"),
    [
        (["detection.method=residual", "detection.window=0.015"], "detection.window"),
        (["detection.method=residual", "detection.lambda=0"], "detection.lambda"),
        (["detection.method=psychic"], "detection.method"),
        (["detection.threshold=3"], "detection"),
    ],
)
def test_bad_detection_values_name_the_field(sets, field):
    with pytest.raises(ScenarioError, match=field.replace(".", r"\.")):
        load_scenario(FAILURES / "follower_stop.yaml", overrides=sets)


@pytest.mark.parametrize(
    ("sets", "least"),
    [(["sensing.delay=0.05"], 0.05), (["sensing.loss=0.2"], 0.0)],
)
def test_delayed_and_lost_packets(sets, least):
    # The commands travel with the poses: a delayed broadcast is compared with the
    # commands of its own time (the detection comes the delay later); a lost packet
    # stretches the window to the next one received.
    _, m = run_scenario(FAILURES / "detect_follower_stop.yaml", *sets, duration=4.5)
    (failure,) = m["detection"]["failures"]
    assert failure["detected_kind"] == "stop"
    assert least + 0.05 <= failure["delay"] <= least + 0.25
    assert m["detection"]["false_alarms"] == 0


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "vehicle"),
    [
        ("column_close", "red"),
        ("leader_crash_elect", "leader"),
        ("leader_crash_virtual", "leader"),
    ],
)
def test_reconfiguration_reacts_to_the_detection(name, vehicle):
    # The reconfiguration scenarios under 1 cm / 0.005 rad noise: the failure is
    # detected within 0.5 s, the platoon re-forms as under the oracle, with no more
    # collisions between healthy vehicles; a leader change waits for the detection.
    noise = ("sensing.position_noise=0.01", "sensing.heading_noise=0.005")
    _, m = result(name, *noise, "detection.method=residual")
    _, o = result(name, *noise, ORACLE)
    (failure,) = m["detection"]["failures"]
    assert failure["vehicle"] == vehicle and failure["delay"] <= 0.5
    assert failure["kind_right"]  # the stop a stop, the crashes crashes
    assert m["detection"]["false_alarms"] == 0
    assert m["collisions"]["healthy"] <= o["collisions"]["healthy"]
    assert m["converged"] and o["converged"]
    for change in m.get("leader_changes", []):
        assert change["t"] == pytest.approx(failure["detected_at"])


@pytest.mark.slow
@pytest.mark.parametrize("barrier", ["velocity", "braking"])
def test_a_safety_filter_does_not_delay_a_detection(barrier):
    # The filter's rate bound starts from the commands red sent, not from what its
    # failed drive did: red's broadcast commands do not follow its own braking, and a
    # filtered run finds the stop as soon as an unfiltered one (within one period).
    sets = [
        "detection.method=glr",
        "detection.lambda=null",
        "sensing.position_noise=0.02",
        "sensing.heading_noise=0.01",
        "sensing.delay=0.05",
        "duration=6",
    ]
    seeds = range(6)
    delays = {}
    for filt in ("none", "cbf"):
        scs = [
            load_scenario(
                FAILURES / "detect_follower_stop.yaml",
                overrides=[*sets, f"safety.filter={filt}", f"seed={s}"]
                + ([f"safety.barrier={barrier}"] if filt == "cbf" else []),
            )
            for s in seeds
        ]
        runs = Simulation.batch(scs)
        failures = [compute_metrics(r)["detection"]["failures"][0] for r in runs]
        assert all(f["detected_kind"] == "stop" for f in failures), failures
        delays[filt] = np.array([f["delay"] for f in failures])
    assert np.all(delays["cbf"] <= delays["none"] + 0.01 + 1e-9), delays
