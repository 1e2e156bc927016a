"""Small helpers shared by the tests: write a scenario, run it, get its metrics.

Import them with ``from helpers import run_scenario, write_yaml, PAPER`` (pytest
puts ``tests/`` on the import path through ``conftest.py``).

>>> run, metrics = run_scenario(PAPER / "rotating_circle.yaml", duration=2)
>>> run, metrics = run_scenario({"reference": {"type": "point", "position": [0, 0]},
...                              "vehicles": [{"pose": [1, 0, 0]}]}, "vehicle.v1_max=1")
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sandbox import Run, compute_metrics, load_scenario, simulate

#: The repository root and its bundled scenarios.
REPO = Path(__file__).resolve().parent.parent
SCENARIOS = REPO / "scenarios"
PAPER = SCENARIOS / "paper"

#: Two vehicles driven open loop head-on at 1 m/s each from 2 m apart: contact when
#: their centres are d = 0.5 m apart, at t = (2 - 0.5) / 2 = 0.75 s.
HEADON: dict[str, Any] = {
    "name": "headon",
    "duration": 1.5,
    "formation": {"law": "virtual"},
    "reference": {"type": "point", "position": [0, 5]},
    "vehicles": [
        {
            "name": "east",
            "pose": [-1, 0, 0],
            "drive": {"type": "commands", "schedule": [[0, 1.0, 0]]},
        },
        {
            "name": "west",
            "pose": [1, 0, math.pi],
            "drive": {"type": "commands", "schedule": [[0, 1.0, 0]]},
        },
    ],
}


def write_yaml(
    tmp_path: Path, doc: Mapping[str, Any], name: str = "scenario.yaml"
) -> Path:
    """Write a scenario document to ``tmp_path / name`` and return the path."""
    path = Path(tmp_path) / name
    path.write_text(yaml.safe_dump(dict(doc), sort_keys=False), encoding="utf-8")
    return path


def run_scenario(
    source: str | Path | Mapping[str, Any], *sets: str, **fields: Any
) -> tuple[Run, dict[str, Any]]:
    """Load, run and measure a scenario; return ``(run, metrics)``.

    Parameters
    ----------
    source : path or mapping
        A scenario file or document.
    *sets : str
        ``path=value`` overrides, as the CLI's ``--set`` (``"recovery.beta=2.5"``).
    **fields
        Top-level overrides, e.g. ``duration=5`` or ``seed=3``.
    """
    overrides = list(sets) + [f"{k}={json.dumps(v)}" for k, v in fields.items()]
    run = simulate(load_scenario(source, overrides=overrides))
    return run, compute_metrics(run)


def window(run: Run, start: float, stop: float = np.inf) -> np.ndarray:
    """Boolean mask of the recorded samples with ``start <= t < stop`` [s]."""
    return (run.t >= start) & (run.t < stop)


def collisions(
    source: str | Path | Mapping[str, Any], *sets: str, **fields: Any
) -> dict[str, Any]:
    """Run a scenario (as :func:`run_scenario`) and return its ``collisions`` metrics.

    Keys ``total``, ``vehicle_vehicle``, ``vehicle_obstacle``, ``healthy`` (episodes
    among vehicles without an active failure) and ``events``:

    >>> assert collisions(PAPER / "fig12_no_recovery.yaml")["total"] > 0
    >>> assert collisions(PAPER / "fig14_discontinuous_beta5.yaml")["total"] == 0
    """
    return run_scenario(source, *sets, **fields)[1]["collisions"]


#: The robot of the safety benchmark (``scenarios/safety/``): d = 0.5 m, 10 kg,
#: 2 m/s, 4 rad/s, 5 m/s^2.
SAFETY_ROBOT = {
    "diameter": 0.5,
    "mass": 10.0,
    "v1_max": 2.0,
    "v2_max": 4.0,
    "max_accel": 5.0,
}


def ring_doc(n: int, jitter: float, seed: int, radius: float = 4.0) -> dict:
    """A ring swap: ``n`` vehicles on a circle, each bound for the antipodal slot.

    The starts are spread evenly and jittered by up to ``jitter`` [rad] (drawn from
    ``seed``), every vehicle facing the centre; no recovery, 12 s.
    """
    rng = np.random.default_rng(seed)
    angle = 2 * np.pi * np.arange(n) / n + rng.uniform(-jitter, jitter, n)
    vehicles = []
    for k, a in enumerate(angle):
        x, y = radius * np.cos(a), radius * np.sin(a)
        vehicles.append(
            {"name": f"v{k}", "pose": [x, y, a + np.pi], "offset": [-x, -y]}
        )
    return {
        "duration": 12,
        "dt": 0.01,
        "substeps": 4,
        "vehicle": SAFETY_ROBOT,
        "reference": {"type": "point", "position": [0, 0]},
        "formation": {"law": "virtual"},
        "recovery": {"strategy": "none"},
        "vehicles": vehicles,
    }
