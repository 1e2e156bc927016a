"""Failures: each kind's effect on the applied commands and on the physical motion.

Kinds: ``stop`` (brakes; a stronger push can shove it), ``crash`` (immovable), ``spin``
(turns in place at v2), ``stuck_steering`` (v2 frozen, v1 controlled), ``uncontrolled``
(constant commands); ``until`` clears a fault and the vehicle resumes its law. The
drive reaches a failure's speed within the vehicle's ``max_accel`` (5 m/s^2 here: from
the platoon's 1 m/s to rest in 0.2 s); a crash stops within a substep.
"""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from sandbox import load_scenario, simulate
from sandbox.plugins import names, register_failure
from sandbox.run.metrics import compute_metrics
from sandbox.run.output import write_run_dir
from sandbox.run.record import MODE_FAILED

# d = 0.5 m; wheel speeds up to 2 m/s: v1 <= 2 m/s and v2 <= 2 * 2 / 0.5 = 8 rad/s.
LIMITS = {"diameter": 0.5, "v1_max": 2.0, "max_accel": 5.0, "v2_max": 8.0}


def platoon(
    failures: list, duration: float = 8.0, reference: dict | None = None
) -> dict:
    """A leader on a line at 1 m/s with two followers already on their slots."""
    return {
        "name": "platoon",
        "duration": duration,
        "dt": 0.01,
        "reference": reference
        or {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "formation": {"law": "rotating"},
        "vehicle": LIMITS,
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [-2, 1, 0], "offset": [-2, 1]},
            {"name": "green", "pose": [-2, -1, 0], "offset": [-2, -1]},
        ],
        "failures": failures,
    }


def run_doc(doc: dict):
    run = simulate(load_scenario(doc))
    return run, compute_metrics(run)


def rows(run, t0: float, t1: float = math.inf) -> np.ndarray:
    return (run.t >= t0 - 1e-9) & (run.t < t1 - 1e-9)


def speed(run, i: int) -> np.ndarray:
    """Measured speed from consecutive recorded positions [m/s], shape (T-1,)."""
    step = np.diff(run.pose[:, i, :2], axis=0)
    return np.hypot(step[:, 0], step[:, 1]) / np.diff(run.t)


def test_stop_brakes_to_rest_and_marks_the_vehicle_failed(tmp_path):
    run, m = run_doc(platoon([{"vehicle": "red", "at": 2.0, "kind": "stop"}]))
    failing = rows(run, 2.0)
    assert run.failed[failing, 1].all() and not run.failed[~failing, 1].any()
    assert (run.mode[failing, 1] == MODE_FAILED).all()
    assert not run.cmd[failing, 1, 1].any()  # v2 = 0 applied from the onset
    # v1 brakes at max_accel = 5 m/s^2 (0.05 m/s a period) from the 1 m/s before
    v1 = run.cmd[failing, 1, 0]
    before = run.cmd[np.flatnonzero(failing)[0] - 1, 1, 0]
    assert before == pytest.approx(1.0, abs=0.01)
    assert v1[0] == pytest.approx(before - 0.05)
    assert np.all(np.diff(v1) >= -0.05 - 1e-12) and np.all(np.diff(v1) <= 0.0)
    assert v1[19] == pytest.approx(max(0.0, before - 1.0), abs=1e-9)
    assert not v1[20:].any()  # at rest command from 2.2 s
    assert speed(run, 1)[195] > 0.9  # driving at the platoon's 1 m/s just before
    at_rest = rows(run, 2.21)[1:]
    assert np.max(speed(run, 1)[at_rest]) < 1e-3  # at rest 0.2 s after the onset
    assert m["vehicles"]["red"]["failed_at"] == pytest.approx(2.0)
    assert m["vehicles"]["green"]["failed_at"] is None
    # red no longer follows, but it is failed: convergence is judged on the healthy
    assert m["vehicles"]["red"]["settling_time"] is None
    assert m["converged"] is True
    # trajectory.csv marks it too
    write_run_dir(run, m, tmp_path / "out")
    with open(tmp_path / "out" / "trajectory.csv", newline="") as fh:
        marked = [
            (float(r["t"]), r["mode"], r["failed"])
            for r in csv.DictReader(fh)
            if r["vehicle"] == "red"
        ]
    assert all((mode, flag) == ("failed", "1") for t, mode, flag in marked if t >= 2.0)
    assert all(flag == "0" and mode != "failed" for t, mode, flag in marked if t < 2.0)


def shove(kind: str, pusher_motor: float) -> np.ndarray:
    """A pusher driven at 0.5 m/s into a vehicle that fails with ``kind`` at t = 0.

    Returns the failed vehicle's recorded positions, shape (T, 2).
    """
    doc = {
        "duration": 4.0,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "vehicle": LIMITS,
        "vehicles": [
            {"name": "wreck", "pose": [0, 0, 0]},
            {
                "name": "pusher",
                "pose": [-1.0, 0, 0],
                "motor_accel": pusher_motor,
                "drive": {"type": "commands", "schedule": [[0.0, 0.5, 0.0]]},
            },
        ],
        "failures": [{"vehicle": "wreck", "at": 0.0, "kind": kind}],
    }
    run, m = run_doc(doc)
    assert m["collisions"]["vehicle_vehicle"] >= 1  # they really touch
    return run.pose[:, 0, :2]


def test_a_stopped_vehicle_is_shoved_by_a_stronger_motor():
    # Motor force is mass x motor_accel. A pusher twice as strong as the brakes moves
    # the stopped vehicle as if it were free: contact at t = 0.5 s, then 3 s at 0.5 m/s.
    pos = shove("stop", pusher_motor=400.0)
    assert pos[-1, 0] == pytest.approx(1.5, abs=0.05)
    # one half as strong does not move it
    pos = shove("stop", pusher_motor=100.0)
    assert abs(pos[-1, 0]) < 1e-3


def test_a_crashed_vehicle_does_not_move_even_when_pushed():
    # five times stronger than the brakes of a stopped vehicle, and still: a wreck
    pos = shove("crash", pusher_motor=1000.0)
    assert np.max(np.abs(pos - pos[0])) < 1e-3


@pytest.mark.slow
def test_spin_keeps_the_position_and_turns_at_v2():
    run, m = run_doc(
        platoon([{"vehicle": "red", "at": 2.0, "kind": "spin", "v2": 1.5}])
    )
    spinning = rows(run, 2.21)
    assert np.all(run.cmd[rows(run, 2.0), 1, 1] == 1.5)  # turning from the onset
    v1 = run.cmd[rows(run, 2.0), 1, 0]  # braking at 5 m/s^2 from 1 m/s
    assert v1[0] == pytest.approx(0.95, abs=0.01) and not v1[20:].any()
    pos = run.pose[spinning, 1, :2]
    assert np.max(np.abs(pos - pos[0])) < 1e-3  # stays in place
    theta = run.pose[spinning, 1, 2]  # unwrapped heading
    rate = np.polyfit(run.t[spinning], theta, 1)[0]
    assert rate == pytest.approx(1.5, rel=1e-3)
    assert theta[-1] - theta[0] > 8.0  # several radians: more than a full turn


def test_stuck_steering_freezes_v2_at_its_onset_value():
    # On a circle of radius 5 m at 1 m/s, the follower on the inside turns at about
    # 0.2 rad/s when the steering sticks.
    circle = {
        "type": "circle",
        "center": [0, 5],
        "radius": 5,
        "speed": 1.0,
        "phase": -1.5708,
    }
    doc = platoon(
        [{"vehicle": "red", "at": 4.0, "kind": "stuck_steering"}], reference=circle
    )
    run, m = run_doc(doc)
    onset = int(np.flatnonzero(rows(run, 4.0))[0])
    v2_onset = run.cmd[onset - 1, 1, 1]  # the command applied just before the onset
    assert abs(v2_onset) > 0.1
    stuck = rows(run, 4.0)
    assert np.all(run.cmd[stuck, 1, 1] == v2_onset)
    assert run.failed[stuck, 1].all()


def test_stuck_steering_at_a_given_v2_keeps_v1_controlled():
    # Steering stuck to the right on a straight line: the follower turns away from its
    # slot, and its controller keeps driving v1: down to a stop as the heading turns
    # away (the turn-rate anti-windup keeps chi along what the vehicle can drive).
    doc = platoon([{"vehicle": "red", "at": 2.0, "kind": "stuck_steering", "v2": -0.4}])
    run, _ = run_doc(doc)
    stuck = rows(run, 2.0)
    assert np.all(run.cmd[stuck, 1, 1] == -0.4)
    v1 = run.cmd[stuck, 1, 0]
    assert v1[0] == pytest.approx(1.0, abs=0.01) and v1.min() == 0.0  # controlled


def test_uncontrolled_applies_constant_commands_and_drives_an_arc():
    doc = platoon(
        [{"vehicle": "red", "at": 2.0, "kind": "uncontrolled", "v1": 1.5, "v2": 0.3}]
    )
    run, _ = run_doc(doc)
    loose = rows(run, 2.0)
    assert np.all(run.cmd[loose, 1, 1] == 0.3)
    # from 1 m/s to 1.5 m/s at max_accel = 5 m/s^2: 0.1 s
    assert run.cmd[loose, 1, 0][0] == pytest.approx(1.05, abs=0.01)
    assert np.all(run.cmd[rows(run, 2.1), 1, 0] == 1.5)
    # the motion is the unicycle arc of radius v1/v2 = 5 m: heading turns at 0.3 rad/s
    settled = rows(run, 2.3)
    rate = np.polyfit(run.t[settled], run.pose[settled, 1, 2], 1)[0]
    assert rate == pytest.approx(0.3, rel=1e-3)
    assert np.median(speed(run, 1)[settled[1:]]) == pytest.approx(1.5, rel=1e-3)


def test_a_cleared_fault_resumes_the_law_and_resettles():
    doc = platoon(
        [{"vehicle": "red", "at": 2.0, "kind": "stop", "until": 3.0}], duration=10.0
    )
    run, m = run_doc(doc)
    assert run.failed[rows(run, 2.0, 3.0), 1].all()
    assert not run.failed[rows(run, 3.0), 1].any()
    err = run.formation_error[:, 1]
    assert err[rows(run, 2.9, 3.0)].min() > 0.5  # left ~1 m behind its slot
    red = m["vehicles"]["red"]
    assert red["failed_at"] == pytest.approx(2.0)
    assert red["settling_time"] is not None and red["settling_time"] > 3.0
    assert m["converged"] is True


def test_a_leader_failure_leaves_the_followers_in_formation_around_it():
    run, m = run_doc(platoon([{"vehicle": "leader", "at": 2.0, "kind": "stop"}]))
    assert m["vehicles"]["leader"]["failed_at"] == pytest.approx(2.0)
    assert np.max(speed(run, 0)[rows(run, 2.21)[1:]]) < 1e-3  # braked in 0.2 s
    # the followers' slots are defined around the stopped leader: they settle there
    for name in ("red", "green"):
        assert m["vehicles"][name]["settling_time"] is not None
    assert m["converged"] is True
    assert m["collisions"]["total"] == 0


def test_registering_a_failure_kind_twice_is_refused():
    assert set(names("failure")) >= {
        "stuck_steering",
        "stop",
        "spin",
        "uncontrolled",
        "crash",
    }
    with pytest.raises(ValueError, match="already registered"):
        register_failure("stop")(lambda ctx: (0.0, 0.0))


def test_the_built_in_kinds_at_once_give_the_numbers_of_their_functions():
    # The loop applies the built-in kinds elementwise (model/failures.py, rule_of and
    # ruled_commands); each entry must be what the kind's function returns, and the
    # drive's limit what within_drive gives, signed zeros and infinities included.
    from sandbox.model import failures as fm
    from sandbox.plugins.registration import FailureContext

    rng = np.random.default_rng(7)
    cases = [
        (fm.stuck_steering, {"v2": None}),
        (fm.stuck_steering, {"v2": -0.8}),
        (fm.stop, {}),
        (fm.spin, {"v2": 3}),
        (fm.spin, {"v2": 0}),
        (fm.uncontrolled, {"v1": 2, "v2": None}),
        (fm.uncontrolled, {"v1": None, "v2": 0.5}),
        (fm.crash, {}),
    ] * 8
    rules = [fm.rule_of(f, p) for f, p in cases]
    assert all(r[0] > 0 for r in rules)
    v1 = rng.choice([0.0, -0.0, 1.5, -2.0, 0.3], size=len(cases))
    onset = rng.choice([0.0, -0.0, 0.7, -1.1], size=len(cases))
    got_v1, got_v2 = fm.ruled_commands(
        np.array([r[0] for r in rules]),
        np.array([r[1] for r in rules]),
        np.array([r[2] for r in rules]),
        v1,
        onset,
    )
    for k, (func, params) in enumerate(cases):
        ctx = FailureContext(0.0, 0.0, "red", 1, v1[k], 0.0, onset[k], params)
        want = np.array(func(ctx), dtype=float)
        got = np.array([got_v1[k], got_v2[k]])
        assert got.tobytes() == want.tobytes(), (func, params)
    last = rng.choice([0.0, -0.0, 1.0, -1.0, 0.05], size=200)
    asked = rng.choice([0.0, -0.0, 2.0, -2.0, 1.0, 0.02], size=200)
    step = rng.choice([0.05, 0.0, np.inf], size=200)
    limited = fm.within_drives(asked, last, step)
    alone = [
        fm.within_drive(float(a), float(b), float(c))
        for a, b, c in zip(asked, last, step, strict=True)
    ]
    assert limited.tobytes() == np.array(alone).tobytes()
    assert fm.rule_of(lambda ctx: (0.0, 0.0), {})[0] == 0  # a plug-in is called
