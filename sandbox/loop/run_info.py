"""What a run records of its scenario for the figures and the GIF: ``Run.info``.

The law and recovery settings, the obstacles as drawn, the failures, the period and
the reference path sampled over the run, as plain JSON-ready values.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sandbox.scenario import Scenario

#: Samples of the reference path kept for drawing.
REFERENCE_PATH_SAMPLES = 400


def run_description(scenario: Scenario, reference: Any) -> dict[str, Any]:
    """The description of ``scenario`` that starts a run's ``info``.

    Parameters
    ----------
    scenario : Scenario
    reference : built reference or None
        ``scenario.reference.build()``: its ``evaluate(times)`` gives the path.
    """
    sc = scenario
    obstacles = []
    for o in sc.obstacles:
        if o.type == "circle":
            obstacles.append(
                {
                    "type": "circle",
                    "center": list(o.center),
                    "radius": o.radius,
                    "name": o.name,
                }
            )
        else:
            obstacles.append({"type": "polygon", "points": o.outline(), "name": o.name})
    info = {
        "scenario_name": sc.name,
        "law": sc.formation.law if sc.formation else None,
        "recovery": {
            "strategy": sc.recovery.strategy,
            "beta": sc.recovery.beta,
            "R": sc.recovery.R,
            "r": sc.recovery.r,
            "leader_avoids": sc.recovery.leader_avoids,
            "target_derivatives": sc.recovery.target_derivatives,
        },
        "obstacles": obstacles,
        "failures": [
            {"vehicle": f.vehicle, "kind": f.kind, "at": f.at, "until": f.until}
            for f in sc.failures
        ],
        "dt": sc.dt,
        "record_every": sc.record_every,
    }
    if reference is not None:
        times = np.linspace(0.0, sc.duration, REFERENCE_PATH_SAMPLES)
        info["reference_path"] = reference.evaluate(times)[0].round(6).tolist()
    return info
