"""Metrics that cannot be fooled by the sampling or by a lucky last sample.

Settling needs the error to stay in band to the end and the run to last
``metrics.settle_dwell`` after it; control effort and the closest approach are
accumulated every control period inside the loop, whatever ``record_every``.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import PAPER, run_scenario, write_yaml

from sandbox import load_scenario
from sandbox.errors import ScenarioError
from sandbox.run.metrics import ClosestApproach, settling_time


def test_an_oscillation_ending_at_a_zero_crossing_has_not_settled() -> None:
    # an undamped 1 m oscillation sampled every 10 ms, ending at a zero crossing
    t = np.linspace(0.0, 15.0, 1501)
    error = np.abs(np.sin(np.pi * t))
    assert error[-1] < 0.05 and error[-3] > 0.05 and error.max() > 0.99
    assert settling_time(t, error, 0.05) == pytest.approx(14.99)  # the old reading
    assert settling_time(t, error, 0.05, dwell=1.0) is None


def test_settling_needs_the_dwell_after_it() -> None:
    # stabilization parks at about 1.5 s: settled in a 10 s run, not when the run ends
    # 0.5 s after the settling time
    _, full = run_scenario(PAPER / "stabilization.yaml", duration=4.0)
    settled = full["vehicles"]["blue"]["settling_time"]
    assert settled is not None and 1.0 < settled < 2.5
    assert full["settle_dwell"] == 1.0 and full["converged"] is True
    cut = settled + 0.5
    _, short = run_scenario(PAPER / "stabilization.yaml", duration=cut)
    assert short["vehicles"]["blue"]["settling_time"] is None
    assert short["converged"] is False
    _, lax = run_scenario(
        PAPER / "stabilization.yaml", "metrics.settle_dwell=0.25", duration=cut
    )
    assert lax["vehicles"]["blue"]["settling_time"] == pytest.approx(settled)


def test_settle_dwell_must_not_be_negative(tmp_path) -> None:
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"pose": [0, 0, 0]}],
        "metrics": {"settle_dwell": -1},
    }
    with pytest.raises(ScenarioError, match="metrics.settle_dwell"):
        load_scenario(write_yaml(tmp_path, doc))


def chatter(tmp_path, record_every: int) -> dict:
    """One open-loop vehicle whose turn rate flips between +8 and -8 rad/s."""
    schedule = [[round(0.01 * k, 2), 0.5, 8.0 * (-1) ** k] for k in range(100)]
    doc = {
        "duration": 1.0,
        "record_every": record_every,
        "vehicles": [
            {
                "name": "a",
                "pose": [0, 0, 0],
                "drive": {"type": "commands", "schedule": schedule},
            }
        ],
    }
    return run_scenario(write_yaml(tmp_path, doc))[1]["vehicles"]["a"]


def test_control_effort_is_computed_every_period(tmp_path) -> None:
    # 99 flips of 16 rad/s at a steady 0.5 m/s: whatever is recorded
    every = chatter(tmp_path, 1)
    sparse = chatter(tmp_path, 2)
    assert every["effort_v2"] == pytest.approx(99 * 16.0)  # [rad/s]
    assert every["effort_v1"] == 0.0  # [m/s]
    assert sparse["effort_v2"] == every["effort_v2"]
    assert sparse["control_effort"] == every["control_effort"]
    assert every["control_effort"] == pytest.approx(0.25 * 99 * 16.0)  # (d/2) v2


def test_min_distance_is_tracked_every_period(tmp_path) -> None:
    # two carts pass each other 0.6 m apart at 2 m/s each, at t = 1.125 s: between the
    # samples of record_every = 25 (0.25 s, 1 m of relative motion)
    def carts(record_every: int) -> dict:
        doc = {
            "duration": 2.0,
            "record_every": record_every,
            "formation": {"law": "fixed"},
            "vehicles": [
                {
                    "name": "a",
                    "pose": [-2.25, 0, 0],
                    "leader": True,
                    "drive": {"type": "commands", "schedule": [[0, 2.0, 0.0]]},
                },
                {
                    "name": "b",
                    "pose": [2.25, 0.6, 3.141592653589793],
                    "drive": {"type": "commands", "schedule": [[0, 2.0, 0.0]]},
                },
            ],
        }
        return run_scenario(write_yaml(tmp_path, doc))[1]

    assert carts(25)["min_distance"] == pytest.approx(0.6, abs=0.02)
    assert carts(25)["min_distance"] == carts(1)["min_distance"]


def test_closest_approach_with_many_vehicles_matches_all_pairs() -> None:
    # the Verlet list (above 64 vehicles) against every pair, on random walks
    rng = np.random.default_rng(3)
    pos = rng.uniform(0, 30, size=(150, 2))
    ca, best = ClosestApproach(), np.inf
    i, j = np.triu_indices(len(pos), 1)
    for _ in range(60):
        pos = pos + rng.normal(0, 0.1, size=pos.shape)
        ca.update(pos)
        best = min(best, float(np.hypot(*(pos[i] - pos[j]).T).min()))
    assert ca.best == pytest.approx(best, abs=1e-12)
