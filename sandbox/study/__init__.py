"""Studies: sweeps of a scenario over grids of values and seeds, and their results.

- :mod:`sandbox.study.spec`: what a sweep runs (grid, zip, seeds, run ids);
- :mod:`sandbox.study.engine`: running the runs (in-process, process pool, Dask);
- :mod:`sandbox.study.store`: the results directory (``results.csv``, one file per run);
- :mod:`sandbox.study.sweep`: computing what is missing into the store;
- :mod:`sandbox.study.summary`: grouped rates with Wilson intervals;
- :mod:`sandbox.study.figures`: the figures of ``sandbox sweep plot``.
"""
