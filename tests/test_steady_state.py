"""Convergence to a law's own steady state (``steady_state`` of ``metrics.json``).

The rotating law keeps eq. (12)'s steady error on a circle; a platoon that does all
its law can must not be read as one that failed to converge without a word.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import PAPER

from sandbox import Simulation, compute_metrics, load_scenario
from sandbox.cli import main
from sandbox.run.metrics import convergence_summary
from sandbox.run.steady_state import turn_rate, turning_steady_error


def test_the_steady_error_is_eq12_with_the_error_dynamics() -> None:
    # |delta| = 2, w = 0.5 rad/s, k1 = -100, k2 = -20 (the report's gains):
    # eq. (12)'s first order: 2 * 0.5 * sqrt(400 + 0.25) / 100 = 0.2000625 m, divided
    # by sqrt((-100 + 0.25)^2 + (-20 * 0.5)^2) / 100 = sqrt(9950.06 + 100) / 100
    # = 1.0025 (the error's own turning, as tests/test_paper_sections_2_3 derives)
    first = 2 * 0.5 * math.sqrt(400.25) / 100
    exact = first / (math.sqrt((-100 + 0.25) ** 2 + 100) / 100)
    assert turning_steady_error(2.0, 0.5, -100.0, -20.0) == pytest.approx(exact)
    assert turning_steady_error(2.0, -0.5, -100.0, -20.0) == pytest.approx(exact)
    assert turning_steady_error(4.0, 0.5, -100.0, -20.0) == pytest.approx(2 * exact)


def test_turn_rate_of_a_line_is_zero_and_of_a_stop_none() -> None:
    t = np.linspace(0.0, 5.0, 501)
    line = np.stack((t, 2 * t), -1)
    assert turn_rate(t, line, 1.0) == pytest.approx(0.0, abs=1e-12)
    assert turn_rate(t, np.zeros((501, 2)), 1.0) is None


def rotating_circle(*overrides: str):
    names = ["duration=12", *overrides]
    return load_scenario(PAPER / "rotating_circle.yaml", overrides=names)


def test_a_rotating_platoon_converges_to_its_laws_steady_state() -> None:
    run = Simulation(rotating_circle("metrics.settle_tol=0.05")).run()
    m = compute_metrics(run)
    assert not m["converged"]  # 5.6 cm off its slot, settle_tol 5 cm
    steady = m["steady_state"]
    assert steady["law"] == "rotating" and steady["converged"]
    assert steady["turn_rate"] == pytest.approx(0.2, rel=1e-6)  # 1 m/s on 5 m
    for name in ("red", "green"):
        predicted = steady["errors"][name]
        assert predicted == pytest.approx(turning_steady_error(2**0.5, 0.2, -100, -20))
        measured = m["vehicles"][name]["formation_error"]["rms_last_quarter"]
        assert measured == pytest.approx(predicted, rel=0.01)
        assert steady["settling_time"][name] is not None
    assert "leader" not in steady["errors"]
    assert convergence_summary(m).startswith("no (to settle_tol 0.05 m); yes to the")


def test_the_run_summary_says_why_it_did_not_converge(tmp_path, capsys) -> None:
    argv = ["run", "paper/rotating_circle", "--duration", "12", "--out"]
    assert main([*argv, str(tmp_path / "r"), "--set", "metrics.settle_tol=0.05"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.endswith(
        "converged: no (to settle_tol 0.05 m); yes to the rotating law's own steady "
        "state (eq. (12): 0.057 m off the slots)"
    )


def test_no_steady_state_for_the_fixed_law_nor_an_unsettled_run() -> None:
    fixed = compute_metrics(Simulation(rotating_circle("formation.law=fixed")).run())
    assert "steady_state" not in fixed
    short = load_scenario(
        PAPER / "rotating_circle.yaml",
        overrides=["duration=0.5", "metrics.settle_dwell=1", "metrics.settle_tol=0.05"],
    )
    m = compute_metrics(Simulation(short).run())
    assert not m["converged"] and not m["steady_state"]["converged"]
    assert convergence_summary(m).startswith("no (to settle_tol 0.05 m); no to the")
