"""Runs and run files made by hand for the tests: no simulation, any values.

:func:`crafted_run` fills the arrays a test does not care about; :func:`arrays_of`,
:func:`npy_bytes` and :func:`write_npz` read and rewrite a ``run.npz`` member by member
(to damage one).
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from sandbox.run.record import Run


def crafted_run(t: np.ndarray, pose: np.ndarray, **fields: Any) -> Run:
    """A run of the times ``t`` (T,) [s] and poses ``pose`` (T, n, 3).

    No slot, target or reference (NaN), zero commands, every vehicle in formation
    mode and healthy, names ``v0 ...``, blue, 0.5 m across, no leader; ``fields``
    replaces any of these.
    """
    T, n = pose.shape[:2]
    made: dict[str, Any] = {
        "cmd": np.zeros((T, n, 2)),
        "chi": np.zeros((T, n, 2)),
        "slot": np.full((T, n, 2), np.nan),
        "target": np.full((T, n, 2), np.nan),
        "mode": np.zeros((T, n), np.int8),
        "failed": np.zeros((T, n), bool),
        "reference": np.full((T, 2), np.nan),
        "names": [f"v{i}" for i in range(n)],
        "colors": ["blue"] * n,
        "diameter": np.full(n, 0.5),
        "leader": -1,
    }
    made.update(fields)
    return Run(t=t, pose=pose, **made)


def arrays_of(npz: Path) -> dict[str, np.ndarray]:
    """Every member of a ``run.npz``."""
    with np.load(npz) as data:
        return {k: data[k] for k in data.files}


def npy_bytes(array: np.ndarray) -> bytes:
    """The ``.npy`` bytes of ``array``."""
    buf = io.BytesIO()
    np.lib.format.write_array(buf, array)
    return buf.getvalue()


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` as the members of a ``.npz`` at ``path``."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, value in arrays.items():
            zf.writestr(f"{name}.npy", npy_bytes(value))
