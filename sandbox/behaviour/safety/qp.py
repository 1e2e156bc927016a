"""Exact small quadratic programs in the plane, many at once, with a counted slack.

Each problem is ``min ||z - z0||^2`` subject to half-planes ``a_k . z <= b_k``, one
problem per row of the arrays (one vehicle), padded to a common number of half-planes
(padding rows are ``a = 0, b = 1``, always satisfied). The optimum of a strictly convex
quadratic over a convex polygon is ``z0`` itself, or the projection of ``z0`` onto one
edge line, or a vertex, the intersection of two edge lines. :func:`project` computes
all ``1 + m + m (m - 1) / 2`` candidates, keeps the feasible ones and returns the
nearest: the exact optimum, with no iteration and no tolerance other than the
feasibility test. Where the compiled path ``qp`` is on (:mod:`sandbox.accel`;
``project`` of ``_filter.c``), :func:`project` is one C loop over the problems,
within 1e-9 of :func:`project_numpy`, the reference (``tests/test_compiled_paths.py``).

When the half-planes have no common point, :func:`min_violation` finds the smallest
slack ``s`` for which the *soft* half-planes relaxed to ``a . z <= b + s`` meet the
*hard* ones (the input bounds), a linear program in ``(z, s)`` whose optimum is a vertex
with three active constraints; it enumerates the vertices. :func:`solve` then projects
``z0`` onto the relaxed set, so the slack is the largest violation of any soft
half-plane, minimised, and among the points with that slack the nearest to ``z0`` is
returned. Rows of ``a`` are expected to be unit vectors, which makes ``b`` and the slack
speeds [m/s] and :data:`TOLERANCE` an absolute speed.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from sandbox import accel
from sandbox.model.kernels import c_float64

#: Feasibility tolerance of a half-plane [m/s] (rows are unit vectors).
TOLERANCE = 1e-9
#: Below this |determinant| two or three constraints are taken as dependent.
SINGULAR = 1e-12


def _pairs(m: int) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.triu_indices(m, 1)
    return i, j


def project(
    z0: np.ndarray, a: np.ndarray, b: np.ndarray, tol: float = TOLERANCE
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest point to ``z0`` in each polygon ``{z : a_k . z <= b_k}``, exactly.

    Parameters
    ----------
    z0 : ndarray, shape (n, 2)
        The nominal points.
    a : ndarray, shape (n, m, 2)
        Half-plane normals (zero rows are padding).
    b : ndarray, shape (n, m)
        Half-plane offsets.
    tol : float
        A point violating a half-plane by at most ``tol`` counts as inside.

    Returns
    -------
    z : ndarray, shape (n, 2)
        The optimum (``z0`` where the polygon is empty).
    feasible : ndarray, shape (n,), bool
        Whether the polygon had a point.

    Examples
    --------
    The nearest point to (2, 2) with z1 <= 1 and z2 <= 1 is the corner (1, 1):

    >>> z, ok = project(np.array([[2.0, 2.0]]),
    ...                 np.array([[[1.0, 0.0], [0.0, 1.0]]]), np.array([[1.0, 1.0]]))
    >>> z.tolist(), ok.tolist()
    [[1.0, 1.0], [True]]
    """
    c = accel.module("qp")
    if c is not None:
        z0c, ac, bc = c_float64(z0), c_float64(a), c_float64(b)
        z, feasible = np.empty(z0c.shape), np.empty(len(z0c), dtype=bool)
        c.project(z0c, ac, bc, float(tol), z, feasible)
        return z, feasible
    return project_numpy(z0, a, b, tol)


def project_numpy(
    z0: np.ndarray, a: np.ndarray, b: np.ndarray, tol: float = TOLERANCE
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project` by numpy (the reference)."""
    m = b.shape[1]
    viol = a[..., 0] * z0[:, None, 0] + a[..., 1] * z0[:, None, 1] - b  # (n, m)
    inside = np.all(viol <= tol, axis=1)
    z = z0.copy()
    feasible = inside.copy()
    rows = np.flatnonzero(~inside)
    if len(rows) == 0:
        return z, feasible
    a, b, z0r, viol = a[rows], b[rows], z0[rows], viol[rows]
    norm2 = a[..., 0] * a[..., 0] + a[..., 1] * a[..., 1]
    step = np.where(norm2 > 0, viol / np.where(norm2 > 0, norm2, 1.0), np.nan)
    edge = z0r[:, None, :] - step[..., None] * a  # projections on each line (k, m, 2)
    i, j = _pairs(m)
    a1, a2, b1, b2 = a[:, i], a[:, j], b[:, i], b[:, j]
    det = a1[..., 0] * a2[..., 1] - a1[..., 1] * a2[..., 0]
    good = np.abs(det) > SINGULAR
    det = np.where(good, det, 1.0)
    vx = (b1 * a2[..., 1] - b2 * a1[..., 1]) / det
    vy = (a1[..., 0] * b2 - a2[..., 0] * b1) / det
    vertex = np.stack((np.where(good, vx, np.nan), np.where(good, vy, np.nan)), -1)
    cand = np.concatenate((edge, vertex), axis=1)  # (k, c, 2)
    lhs = np.einsum("kmd,kcd->kcm", a, cand)
    ok = np.all(lhs - b[:, None, :] <= tol, axis=2)  # NaN candidates are never ok
    dist = np.sum((cand - z0r[:, None, :]) ** 2, axis=2)
    dist = np.where(ok, dist, np.inf)
    best = np.argmin(dist, axis=1)
    found = np.isfinite(dist[np.arange(len(rows)), best])
    z[rows] = np.where(found[:, None], cand[np.arange(len(rows)), best], z0r)
    feasible[rows] = found
    return z, feasible


def min_violation(
    a: np.ndarray, b: np.ndarray, soft: np.ndarray, tol: float = TOLERANCE
) -> tuple[np.ndarray, np.ndarray]:
    """Smallest slack ``s >= 0`` making ``a . z <= b + s soft`` feasible, per problem.

    The linear program ``min s`` over ``(z, s)`` subject to ``a_k . z - s <= b_k``
    (soft rows) and ``a_k . z <= b_k`` (hard rows). The hard rows must bound ``z`` (the
    input bounds do), so the optimum is a vertex: three linearly independent active
    constraints. Every triple is solved and the feasible vertex of least ``s`` kept.

    Parameters
    ----------
    a : ndarray, shape (n, m, 2)
    b : ndarray, shape (n, m)
    soft : ndarray, shape (n, m), bool
        The rows that may be relaxed.
    tol : float

    Returns
    -------
    slack : ndarray, shape (n,)
        The least slack (0 where the problem is feasible as it is; ``inf`` where the
        hard rows alone have no point).
    z : ndarray, shape (n, 2)
        A point with that slack.
    """
    m = b.shape[1]
    n = len(b)
    triples = np.array(list(combinations(range(m), 3)), dtype=np.intp).reshape(-1, 3)
    s_col = -soft.astype(float)
    mat = np.concatenate((a, s_col[..., None]), axis=2)  # (n, m, 3)
    sys = mat[:, triples]  # (n, t, 3, 3)
    rhs = b[:, triples]  # (n, t, 3)
    det = np.linalg.det(sys)
    good = np.abs(det) > SINGULAR
    eye = np.broadcast_to(np.eye(3), sys.shape)
    sol = np.linalg.solve(np.where(good[..., None, None], sys, eye), rhs[..., None])
    sol = sol[..., 0]  # (n, t, 3)
    z, s = sol[..., :2], np.maximum(sol[..., 2], 0.0)
    lhs = np.einsum("nmd,ntd->ntm", a, z) + s_col[:, None, :] * s[..., None]
    ok = good & np.all(lhs - b[:, None, :] <= tol * (1.0 + np.abs(b[:, None, :])), 2)
    s = np.where(ok, s, np.inf)
    if not s.shape[1]:
        return np.full(n, np.inf), np.zeros((n, 2))
    best = np.argmin(s, axis=1)
    rows = np.arange(n)
    return s[rows, best], z[rows, best]


def solve(
    z0: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    soft: np.ndarray,
    tol: float = TOLERANCE,
) -> tuple[np.ndarray, np.ndarray]:
    """The nearest point to ``z0`` in the polygon, with the least slack if it is empty.

    Parameters
    ----------
    z0 : ndarray, shape (n, 2)
    a : ndarray, shape (n, m, 2)
        Unit normals (zero rows are padding).
    b : ndarray, shape (n, m)
    soft : ndarray, shape (n, m), bool
        Rows that may be relaxed when the problem is infeasible (the barrier
        conditions); the others (input bounds) are always kept.
    tol : float

    Returns
    -------
    z : ndarray, shape (n, 2)
        The exact optimum where feasible; else the nearest point to ``z0`` among
        those of least largest violation of a soft row.
    slack : ndarray, shape (n,)
        0 where feasible, else that least largest violation (> 0).
    """
    z, feasible = project(z0, a, b, tol)
    slack = np.zeros(len(z0))
    bad = np.flatnonzero(~feasible)
    if len(bad):
        sb, zb = min_violation(a[bad], b[bad], soft[bad], tol)
        finite = np.isfinite(sb)
        relaxed = b[bad] + soft[bad] * np.where(finite, sb, 0.0)[:, None]
        zr, ok = project(z0[bad], a[bad], relaxed, 10.0 * tol)
        z[bad] = np.where(ok[:, None], zr, zb)
        slack[bad] = sb
    return z, slack


def bounded_problems(
    box: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    owner: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    rank: np.ndarray,
    m: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The problems of ``k`` vehicles: their bounds, then ``m`` soft half-planes each.

    Parameters
    ----------
    box : tuple of ndarray, each shape (k,)
        ``lo1, hi1, lo2, hi2``: the bounds ``lo1 <= z1 <= hi1``, ``lo2 <= z2 <= hi2``.
    owner : ndarray, shape (r,) int
        The problem (in ``[0, k)``) of each half-plane.
    a : ndarray, shape (r, 2)
        Unit normals.
    b : ndarray, shape (r,)
    rank : ndarray, shape (r,) int
        Each half-plane's place among its problem's, in ``[0, m)``.
    m : int

    Returns
    -------
    mat : ndarray, shape (k, 4 + m, 2)
    off : ndarray, shape (k, 4 + m)
        The four bounds first; places without a half-plane are padding (``a = 0,
        b = 0``: kept by every ``z``).
    soft : ndarray, shape (k, 4 + m) bool
        The half-planes (not the bounds).
    """
    lo1, hi1, lo2, hi2 = box
    k = len(lo1)
    mat = np.zeros((k, 4 + m, 2))
    off = np.zeros((k, 4 + m))
    mat[:, 0, 0], off[:, 0] = 1.0, hi1
    mat[:, 1, 0], off[:, 1] = -1.0, -lo1
    mat[:, 2, 1], off[:, 2] = 1.0, hi2
    mat[:, 3, 1], off[:, 3] = -1.0, -lo2
    mat[owner, 4 + rank] = a
    off[owner, 4 + rank] = b
    soft = np.zeros((k, 4 + m), dtype=bool)
    soft[:, 4:] = True
    return mat, off, soft
