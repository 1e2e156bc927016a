"""Views of a recorded run for analysis: one vehicle's arrays, a long table, Parquet.

- :meth:`sandbox.run.record.Run.vehicle` (:func:`vehicle_track`): one vehicle's arrays
  by name, ``run.vehicle("red").x1``;
- :meth:`sandbox.run.record.Run.to_dataframe` (:func:`to_dataframe`): a pandas DataFrame
  in long format, one row per vehicle per recorded sample, with the columns of
  ``trajectory.csv`` (:data:`COLUMNS`);
- :func:`write_parquet`: ``trajectory.parquet``, the same table as ``trajectory.csv``
  in a compressed columnar file (``sandbox run --format parquet``).

pandas and pyarrow are the optional extra ``analysis`` (``pip install
'platoon-sandbox[analysis]'``); without them the two table functions raise
:class:`MissingExtraError`, a one-line message that says what to install.

The functions read a run through its attributes only (``run: Any``, a
:class:`~sandbox.run.record.Run`): the record imports this module, never the other way.

Example (after ``sandbox run paper/rotating_circle``)::

    from sandbox import load_run

    run = load_run("runs/rotating_circle")
    red = run.vehicle("red")                  # red.t, red.x1, red.formation_error
    df = run.to_dataframe()                   # columns t, vehicle, x1, ..., failed
    df.groupby("vehicle", observed=True).x1.max()
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from sandbox._about import install_hint
from sandbox.errors import SandboxError
from sandbox.run.codes import MODE_NAMES

if TYPE_CHECKING:
    import pandas

#: Columns of the long table, as in ``trajectory.csv``: time [s], vehicle name, pose
#: (x1, x2 [m], x3 [rad]), commands (v1 [m/s], v2 [rad/s]), extension states chi1,
#: chi2 [m/s], mode (``formation``, ``avoid``, ``failed``) and whether a failure is
#: active.
COLUMNS = (
    *("t", "vehicle", "x1", "x2", "x3"),
    *("v1", "v2", "chi1", "chi2", "mode", "failed"),
)

#: The optional extra that holds pandas and pyarrow.
EXTRA = "analysis"

#: Rows per Parquet row group (memory while writing stays about that many rows).
PARQUET_GROUP_ROWS = 1_000_000


class MissingExtraError(SandboxError, ImportError):
    """A feature needs a package of an optional extra that is not installed."""


def require(module: str, feature: str) -> ModuleType:
    """Import ``module`` for ``feature``, or raise :class:`MissingExtraError`."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f"{feature} needs {module.split('.')[0]}, which is not installed: "
            f"{install_hint(EXTRA)}"
        ) from None


@dataclass(frozen=True)
class VehicleTrack:
    """The recorded arrays of one vehicle (a slice of a :class:`~sandbox.Run`).

    Attributes
    ----------
    name, color : str
    index : int
        Position of the vehicle in the run (scenario order).
    leader : bool
        Whether it is the run's leader.
    diameter : float [m]
    t : ndarray, shape (T,) [s]
    pose : ndarray, shape (T, 3)
        ``(x1, x2, x3)`` [m, m, rad], x3 unwrapped.
    cmd : ndarray, shape (T, 2)
        Applied ``(v1, v2)`` [m/s, rad/s].
    chi : ndarray, shape (T, 2) [m/s]
        Extension states of eqs (4)/(6).
    slot, target : ndarray, shape (T, 2) [m]
        The formation slot and the point actually tracked (see :class:`Run`).
    mode : ndarray, shape (T,), int8
        ``MODE_FORMATION``, ``MODE_AVOID`` or ``MODE_FAILED``
        (:data:`sandbox.run.record.MODE_NAMES` names them).
    failed : ndarray, shape (T,), bool
    """

    name: str
    color: str
    index: int
    leader: bool
    diameter: float
    t: np.ndarray
    pose: np.ndarray
    cmd: np.ndarray
    chi: np.ndarray
    slot: np.ndarray
    target: np.ndarray
    mode: np.ndarray
    failed: np.ndarray

    @property
    def x1(self) -> np.ndarray:
        """First position coordinate, shape (T,) [m]."""
        return self.pose[:, 0]

    @property
    def x2(self) -> np.ndarray:
        """Second position coordinate, shape (T,) [m]."""
        return self.pose[:, 1]

    @property
    def x3(self) -> np.ndarray:
        """Heading, unwrapped, shape (T,) [rad]."""
        return self.pose[:, 2]

    @property
    def v1(self) -> np.ndarray:
        """Applied forward speed, shape (T,) [m/s]."""
        return self.cmd[:, 0]

    @property
    def v2(self) -> np.ndarray:
        """Applied turn rate, shape (T,) [rad/s]."""
        return self.cmd[:, 1]

    @property
    def formation_error(self) -> np.ndarray:
        """Distance to the slot, shape (T,) [m]; NaN where there is no slot."""
        return np.linalg.norm(self.pose[:, :2] - self.slot, axis=-1)


def vehicle_track(run: Any, name: str) -> VehicleTrack:
    """The arrays of the vehicle called ``name`` in ``run``.

    Raises
    ------
    KeyError
        No vehicle has that name; the message lists the names there are.
    """
    try:
        i = run.names.index(name)
    except ValueError:
        shown = ", ".join(run.names[:10]) + (" ..." if len(run.names) > 10 else "")
        raise KeyError(
            f"no vehicle named {name!r} in the run (vehicles: {shown})"
        ) from None
    return VehicleTrack(
        name=name,
        color=run.colors[i],
        index=i,
        leader=i == run.leader,
        diameter=float(run.diameter[i]),
        t=run.t,
        pose=run.pose[:, i],
        cmd=run.cmd[:, i],
        chi=run.chi[:, i],
        slot=run.slot[:, i],
        target=run.target[:, i],
        mode=run.mode[:, i],
        failed=run.failed[:, i],
    )


def table_columns(run: Any, start: int = 0, stop: int | None = None) -> dict:
    """The long table of samples ``start:stop`` as one array per column.

    Rows run sample by sample, vehicles in scenario order within a sample (the order
    of ``trajectory.csv``). ``vehicle`` and ``mode`` are integer codes into
    ``run.names`` and :data:`sandbox.run.codes.MODE_NAMES`.

    Returns
    -------
    dict
        :data:`COLUMNS` -> ndarray of shape ``((stop - start) * n,)``.
    """
    stop = len(run.t) if stop is None else min(stop, len(run.t))
    n = run.n_vehicles
    k = max(stop - start, 0)
    pose = np.asarray(run.pose[start:stop]).reshape(k * n, 3)
    cmd = np.asarray(run.cmd[start:stop]).reshape(k * n, 2)
    chi = np.asarray(run.chi[start:stop]).reshape(k * n, 2)
    return {
        "t": np.repeat(np.asarray(run.t[start:stop], dtype=np.float64), n),
        "vehicle": np.tile(np.arange(n, dtype=np.int32), k),
        "x1": pose[:, 0],
        "x2": pose[:, 1],
        "x3": pose[:, 2],
        "v1": cmd[:, 0],
        "v2": cmd[:, 1],
        "chi1": chi[:, 0],
        "chi2": chi[:, 1],
        "mode": np.asarray(run.mode[start:stop]).reshape(k * n).astype(np.int32),
        "failed": np.asarray(run.failed[start:stop]).reshape(k * n).astype(bool),
    }


def to_dataframe(run: Any) -> pandas.DataFrame:
    """The run as a pandas DataFrame in long format, the columns :data:`COLUMNS`.

    ``vehicle`` and ``mode`` are categoricals (vehicles in scenario order), ``failed``
    is boolean, the rest float64 in SI units. Needs pandas (extra ``analysis``).
    """
    pd = require("pandas", "run.to_dataframe()")
    cols = table_columns(run)
    cols["vehicle"] = pd.Categorical.from_codes(cols["vehicle"], categories=run.names)
    cols["mode"] = pd.Categorical.from_codes(cols["mode"], categories=MODE_NAMES)
    return pd.DataFrame(cols, columns=list(COLUMNS))


def write_parquet(run: Any, path: Path) -> None:
    """Write the long table to a Parquet file (zstd-compressed), row group by group.

    The columns are those of ``trajectory.csv`` at full precision; ``vehicle`` and
    ``mode`` are dictionary-encoded strings. Memory stays that of
    :data:`PARQUET_GROUP_ROWS` rows whatever the run's size. The bytes depend only on
    the run (and the pyarrow version). Needs pyarrow (extra ``analysis``).
    """
    pa = require("pyarrow", "trajectory.parquet")
    pq = require("pyarrow.parquet", "trajectory.parquet")
    names = pa.array(run.names, type=pa.string())
    modes = pa.array(MODE_NAMES, type=pa.string())
    dictionary = pa.dictionary(pa.int32(), pa.string())
    fields: list[Any] = [pa.field("t", pa.float64()), pa.field("vehicle", dictionary)]
    fields += [pa.field(c, pa.float64()) for c in COLUMNS[2:9]]
    fields += [pa.field("mode", dictionary), pa.field("failed", pa.bool_())]
    schema = pa.schema(fields)
    per_group = max(1, PARQUET_GROUP_ROWS // max(run.n_vehicles, 1))
    with pq.ParquetWriter(str(path), schema, compression="zstd") as writer:
        for start in range(0, max(len(run.t), 1), per_group):
            cols = table_columns(run, start, start + per_group)
            codes = {"vehicle": names, "mode": modes}
            arrays = [
                pa.DictionaryArray.from_arrays(cols[c], codes[c])
                if c in codes
                else pa.array(cols[c])
                for c in COLUMNS
            ]
            writer.write_table(pa.Table.from_arrays(arrays, schema=schema))
