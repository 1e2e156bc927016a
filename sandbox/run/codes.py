"""The codes of a record: each vehicle's mode at each sample, and a run's status.

The lowest module of :mod:`sandbox.run`: it imports nothing, so the modules that read a
record (metrics, analysis, run directories) and the record itself
(:mod:`sandbox.run.record`, which names them too) share them without an import circle.
"""

from __future__ import annotations

__all__ = [
    "MODE_AVOID",
    "MODE_EXTERNAL",
    "MODE_FAILED",
    "MODE_FORMATION",
    "MODE_NAMES",
    "STATUSES",
    "STATUS_DIVERGED",
    "STATUS_ERROR",
    "STATUS_INTERRUPTED",
    "STATUS_OK",
]

#: Integer codes of the ``mode`` array, and their names in ``trajectory.csv``.
MODE_FORMATION = 0
MODE_AVOID = 1
MODE_FAILED = 2
#: Driven this period by commands or targets given to ``Simulation.step``.
MODE_EXTERNAL = 3
MODE_NAMES = ("formation", "avoid", "failed", "external")

#: Status values of a run (``metrics.json`` key ``status``).
STATUS_OK = "ok"
STATUS_DIVERGED = "diverged"
STATUS_INTERRUPTED = "interrupted"
#: A plug-in raised or returned non-finite numbers (``Run.info["error"]``).
STATUS_ERROR = "error"
#: Every status a run can have.
STATUSES = (STATUS_OK, STATUS_DIVERGED, STATUS_INTERRUPTED, STATUS_ERROR)
