"""Lengths of planar vectors, computed as numpy's own norm computes them.

``np.linalg.norm(v, axis=-1)`` of vectors with two components squares them, adds the
two squares and takes the square root; it reaches them through a reduction over an
axis of length two, which on a record of a few thousand samples costs ten times the
arithmetic. :func:`norms` does the same three operations on the two columns, so its
values are the same to the bit (``tests/test_deadlock.py`` compares them, NaN
included).
"""

from __future__ import annotations

import numpy as np


def norms(v: np.ndarray) -> np.ndarray:
    """The Euclidean lengths of the vectors ``v[..., :2]``, shape ``v.shape[:-1]``.

    ``sqrt(x * x + y * y)``, the numbers of ``np.linalg.norm(v, axis=-1)`` for a last
    axis of length 2 (not those of ``np.hypot``, which rounds differently).

    >>> norms(np.array([[3.0, 4.0], [1.0, 0.0]])).tolist()
    [5.0, 1.0]
    """
    x, y = v[..., 0], v[..., 1]
    out = x * x
    out += y * y
    return np.sqrt(out, out=out)
