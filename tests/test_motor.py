"""The motor makes eq. (1) true: a free body follows its commanded velocity.

By default (``motor_accel`` left out) the joints that drive a vehicle are sized every
period for the command: a free body reaches the commanded unicycle velocity within the
first substep, however large the command, while in contact the motor pushes with
200 m/s^2 only (contacts win). A user-set ``motor_accel`` is a fixed motor that may be
too weak: the run then reports the fraction of saturated periods and warns.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import PAPER, run_scenario, write_yaml

from sandbox.cli import main
from sandbox.physics.world import World
from sandbox.scenario import VehicleSpec

H = 0.01  # [s]
#: The report's idealization: no speed, acceleration or turn-rate limit.
UNBOUNDED = ("vehicle.v1_max=null", "vehicle.max_accel=null", "vehicle.v2_max=null")


def test_free_body_follows_any_command_within_a_substep() -> None:
    # Speed steps 0 -> 60 -> 5 -> 40 m/s and turn-rate steps of +-50 rad/s: at the end
    # of every period the body moves exactly as commanded (eq. (1), no lateral slip).
    world = World((VehicleSpec("a", (0.0, 0.0, 0.0)),), ())
    schedule = [(60.0, 0.0), (5.0, 50.0), (40.0, -50.0), (0.0, 0.0), (60.0, 10.0)]
    worst = 0.0
    for v1, v2 in schedule:
        for _ in range(3):
            state = world.read_state()
            heading = state.theta[0] + 0.5 * v2 * H
            world.write_commands(state.theta, np.array([v1]), np.array([v2]), H)
            world.step(H, 4, 0.0)
            after = world.read_state()
            want = v1 * np.array([np.cos(heading), np.sin(heading)])
            worst = max(worst, float(np.hypot(*(after.vel[0] - want))))
            assert after.omega[0] == pytest.approx(v2, abs=1e-9)
    assert worst < 1e-9


def test_unlimited_robot_obeys_eq_1_while_free() -> None:
    # The report's unbounded robot, Fig. 14 beta = 5: commands of several m/s change
    # by metres per second every period. A 200 m/s^2 motor (the former default) lags by
    # up to 23 m/s; the default motor follows to within 1 % or 1 cm/s.
    _, m = run_scenario(
        PAPER / "fig14_discontinuous_beta5.yaml", *UNBOUNDED, duration=3
    )
    motor = m["motor"]
    assert motor["free_periods"] > 800
    assert motor["max_velocity_error_free"] < 0.01
    assert motor["max_speed_error_free"] < 0.01
    assert motor["saturated_fraction"] == 0.0
    assert m["warnings"] == []


def test_weak_motor_is_reported_and_warned(tmp_path, capsys) -> None:
    sets = [*UNBOUNDED, "vehicle.motor_accel=200", "duration=3"]
    _, m = run_scenario(PAPER / "fig14_discontinuous_beta5.yaml", *sets)
    motor = m["motor"]
    assert 0.0 < motor["saturated_fraction"] < 0.2
    assert motor["max_speed_error_free"] > 5.0  # m/s
    assert len(m["warnings"]) == 1 and "motor" in m["warnings"][0]
    argv = ["run", str(PAPER / "fig14_discontinuous_beta5.yaml"), "--out"]
    argv += [str(tmp_path / "out")] + [a for s in sets for a in ("--set", s)]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "warning: the motor could not follow the commands" in err


def test_contacts_still_win_over_the_tracking_motor(tmp_path) -> None:
    # A vehicle with the tracking motor commanded at 5 m/s into a braking vehicle
    # whose fixed motor is 400 m/s^2 cannot move it: blocked, the tracking motor pushes
    # with 200 m/s^2 (plus the change of its command), however far its body lags.
    doc = {
        "duration": 2.0,
        "formation": {"law": "fixed"},
        "vehicles": [
            {
                "name": "pusher",
                "pose": [0, 0, 0],
                "drive": {"type": "commands", "schedule": [[0, 1.0, 0.0], [1, 5.0, 0]]},
            },
            {
                "name": "brake",
                "pose": [1.0, 0, 0],
                "leader": True,
                "motor_accel": 400.0,
                "drive": {"type": "commands", "schedule": [[0, 0.0, 0.0]]},
            },
        ],
    }
    run, m = run_scenario(write_yaml(tmp_path, doc))
    assert m["collisions"]["total"] == 1
    assert abs(run.pose[-1, 1, 0] - 1.0) < 1e-3
    assert run.pose[-1, 0, 0] == pytest.approx(0.5, abs=0.005)  # pressed against it
