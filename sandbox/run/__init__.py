"""A recorded run and what is read from it: metrics, expectations, files, tables.

- :mod:`~sandbox.run.record`: :class:`~sandbox.run.record.Run` (the arrays a simulation
  produced), the collision events, modes and statuses, and the recorder the loop fills;
- :mod:`~sandbox.run.metrics`: the loop metrics and ``metrics.json``;
- :mod:`~sandbox.run.deadlock`: vehicles trapped short of their slots;
- :mod:`~sandbox.run.expectations`: a scenario's ``expect:`` evaluated on a run;
- :mod:`~sandbox.run.codes`: the modes and statuses, shared without an import circle;
- :mod:`~sandbox.run.run_dir`: run directories, written atomically (``Run.save``);
- :mod:`~sandbox.run.output`: run directories read back, every member of ``run.npz``
  checked by :mod:`~sandbox.run.run_file`;
- :mod:`~sandbox.run.output_guard`: what an output may replace (only an earlier output
  of the same command);
- :mod:`~sandbox.run.analysis`: one vehicle's arrays, long tables, Parquet.

``from sandbox.run import Run`` (the v0.2 module) still works for one release, with a
:class:`DeprecationWarning`: the public names are ``sandbox.Run`` and
``sandbox.load_run``.
"""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    """The names of the v0.2 module ``sandbox.run``, with a deprecation warning."""
    import sandbox.run.record as record
    from sandbox._moved import warn_moved

    if name.startswith("__") or not hasattr(record, name):
        raise AttributeError(f"module 'sandbox.run' has no attribute {name!r}")
    warn_moved(f"sandbox.run.{name}", f"sandbox.run.record.{name}")
    return getattr(record, name)
