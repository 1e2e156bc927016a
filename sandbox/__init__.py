"""sandbox: a physics-backed 2D sandbox for collective motion of unicycle vehicles.

Public API::

    from sandbox import load_scenario, Simulation, simulate, compute_metrics
"""

import sandbox._startup  # noqa: F401  (first: quiet Ctrl-C while the command starts)
from sandbox.errors import SandboxError, ScenarioError
from sandbox.metrics import compute_metrics
from sandbox.run import Run
from sandbox.scenario import Scenario, load_scenario
from sandbox.simulation import Simulation, simulate

__all__ = [
    "Run",
    "SandboxError",
    "Scenario",
    "ScenarioError",
    "Simulation",
    "compute_metrics",
    "load_scenario",
    "simulate",
]
__version__ = "0.1.0"
