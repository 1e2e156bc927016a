"""The tunnelling warning from the commands applied during the run, in metrics.json.

v0.2 warned only from the loader's estimate of the speeds the gains ask for, which can
be far below what a run commands (33 m/s estimated, 168.5 m/s applied, in a review).
"""

from __future__ import annotations

import pytest

from sandbox import compute_metrics, load_scenario, simulate
from sandbox.errors import SandboxWarning


def doc(distance: float, v1_max: float | None) -> dict:
    vehicle = {"diameter": 0.4}
    if v1_max is not None:
        vehicle["v1_max"] = v1_max
    return {
        "name": "fast",
        "duration": 0.5,
        "dt": 0.01,
        "substeps": 2,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "vehicle": vehicle,
        "vehicles": [{"name": "far", "pose": [-distance, 0, 0], "offset": [0, 0]}],
    }


def test_a_run_driven_beyond_the_bound_says_so() -> None:
    with pytest.warns(SandboxWarning, match="substeps"):  # the loader's estimate
        run = simulate(load_scenario(doc(12.0, None)))
    metrics = compute_metrics(run)
    fast = metrics["tunnelling"]
    peak = float(abs(run.cmd[:, 0, 0]).max())  # every period is recorded here
    assert fast["vehicle"] == "far" and fast["peak_v1"] == pytest.approx(peak)
    assert fast["per_substep"] == pytest.approx(peak * 0.01 / 2)
    assert fast["bound"] == pytest.approx(0.1)  # a quarter of 0.4 m
    assert fast["per_substep"] > fast["bound"]
    assert fast["substeps_needed"] * fast["bound"] >= peak * 0.01
    assert any("contacts may have been missed" in w for w in metrics["warnings"])


def test_a_run_within_the_bound_has_no_tunnelling_entry() -> None:
    metrics = compute_metrics(simulate(load_scenario(doc(12.0, 5.0))))
    assert "tunnelling" not in metrics
    assert not any("contacts may have been missed" in w for w in metrics["warnings"])
