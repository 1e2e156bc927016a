"""A vehicle crossing its slot slowly is not settled (``metrics.settle_speed``).

v0.2 reported a follower drifting through its slot at 3 cm/s settled and converged, as
long as the run ended while it was within ``settle_tol``.
"""

from __future__ import annotations

import numpy as np
import pytest

from sandbox import compute_metrics, load_scenario
from sandbox.run.record import Run


def crafted(drift: float, settle_speed: float | None = None) -> Run:
    """A 4 s run of one vehicle whose slot is the origin, moving at ``drift`` m/s.

    It crosses the slot at t = 3 s: within settle_tol (5 cm) from t = 1.34 s on.
    """
    doc = {
        "name": "drift",
        "duration": 4.0,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "vehicles": [{"name": "red", "pose": [0, 0, 0], "offset": [0, 0]}],
    }
    if settle_speed is not None:
        doc["metrics"] = {"settle_speed": settle_speed}
    scenario = load_scenario(doc)
    t = np.arange(0.0, 4.0001, 0.01)
    T = len(t)
    x = drift * (t - 3.0) if drift else np.where(t < 1.0, 1.0 - t, 0.0)
    pose = np.zeros((T, 1, 3))
    pose[:, 0, 0] = x
    return Run(
        t=t,
        pose=pose,
        cmd=np.zeros((T, 1, 2)),
        chi=np.zeros((T, 1, 2)),
        slot=np.zeros((T, 1, 2)),
        target=np.zeros((T, 1, 2)),
        mode=np.zeros((T, 1), np.int8),
        failed=np.zeros((T, 1), bool),
        reference=np.zeros((T, 2)),
        names=["red"],
        colors=["red"],
        diameter=np.array([0.5]),
        leader=-1,
        events=[],
        scenario=scenario,
    )


def test_a_vehicle_drifting_through_its_slot_has_not_settled() -> None:
    metrics = compute_metrics(crafted(0.03))  # 3 cm/s
    assert metrics["vehicles"]["red"]["formation_error"]["final"] < 0.05
    assert metrics["vehicles"]["red"]["settling_time"] is None
    assert metrics["converged"] is False


def test_a_vehicle_at_rest_on_its_slot_has_settled() -> None:
    metrics = compute_metrics(crafted(0.0))
    assert metrics["vehicles"]["red"]["settling_time"] == pytest.approx(0.96, abs=0.02)
    assert metrics["converged"] is True


def test_the_drift_tolerance_is_the_scenarios() -> None:
    metrics = compute_metrics(crafted(0.03, settle_speed=0.05))
    assert metrics["vehicles"]["red"]["settling_time"] == pytest.approx(1.34, abs=0.02)
