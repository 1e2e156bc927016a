"""sandbox: a physics-backed 2D sandbox for collective motion of unicycle vehicles.

Public API::

    from sandbox import load_scenario, Simulation, simulate, compute_metrics, load_run

    run = load_run("runs/rotating_circle")   # a run directory written by `sandbox run`
    run.vehicle("red").x1                    # one vehicle's arrays
    run.to_dataframe()                       # long table (needs the 'analysis' extra)

The names are imported on first use (``import sandbox`` alone loads neither numpy nor
the physics engine), so the command line starts fast.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

import sandbox._startup  # noqa: F401  (first: quiet Ctrl-C while the command starts)
from sandbox._about import __version__ as __version__

#: Public name -> (module, attribute) it is imported from on first use.
_EXPORTS = {
    "Observation": ("sandbox.loop.observation", "Observation"),
    "Run": ("sandbox.run.record", "Run"),
    "SandboxError": ("sandbox.errors", "SandboxError"),
    "SandboxWarning": ("sandbox.errors", "SandboxWarning"),
    "Scenario": ("sandbox.scenario", "Scenario"),
    "ScenarioError": ("sandbox.errors", "ScenarioError"),
    "Simulation": ("sandbox.loop.simulation", "Simulation"),
    "VehicleTrack": ("sandbox.run.analysis", "VehicleTrack"),
    "compute_metrics": ("sandbox.run.metrics", "compute_metrics"),
    "load_run": ("sandbox.run.output", "load_run_dir"),
    "load_scenario": ("sandbox.scenario", "load_scenario"),
    "simulate": ("sandbox.loop.simulation", "simulate"),
}

__all__ = [
    "Observation",
    "Run",
    "SandboxError",
    "SandboxWarning",
    "Scenario",
    "ScenarioError",
    "Simulation",
    "VehicleTrack",
    "compute_metrics",
    "load_run",
    "load_scenario",
    "simulate",
]

if TYPE_CHECKING:  # what static tools see; at run time __getattr__ imports lazily
    from sandbox.errors import SandboxError, SandboxWarning, ScenarioError
    from sandbox.loop.observation import Observation
    from sandbox.loop.simulation import Simulation, simulate
    from sandbox.run.analysis import VehicleTrack
    from sandbox.run.metrics import compute_metrics
    from sandbox.run.output import load_run_dir as load_run
    from sandbox.run.record import Run
    from sandbox.scenario import Scenario, load_scenario


def __getattr__(name: str) -> Any:
    """Import a public name on first use (PEP 562)."""
    try:
        module, attribute = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'sandbox' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The module's names, the lazily imported ones included."""
    return sorted({*globals(), *_EXPORTS})
