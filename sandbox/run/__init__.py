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

The public names are ``sandbox.Run`` and ``sandbox.load_run``.
"""
