"""ORCA's linear programs in the plane, one per vehicle, for many vehicles at once.

Each vehicle's admissible velocities are the intersection of half-planes (its ORCA
lines, :class:`HalfPlanes`) and of the disc of its largest speed. ORCA (van den Berg,
Guy, Lin and Manocha, "Reciprocal n-body collision avoidance", 2011, section 5.2)
picks the admissible velocity nearest to the preferred one with an incremental
algorithm, and when the half-planes have no common point, the velocity that least
violates the soft ones (the vehicles') while keeping the hard ones (the obstacles'),
a program in three dimensions solved as a sequence of planar ones:

- :func:`line_program` (``linearProgram1`` of the RVO2 library): the best point on one
  line, within the disc and the lines before it;
- :func:`planar_program` (``linearProgram2``): the lines one after another; while the
  current optimum keeps a line it stays optimal, else the new optimum lies on that line
  (the incremental algorithm of Seidel's randomised linear programming, in the lines'
  order here, which is deterministic);
- :func:`relaxed_program` (``linearProgram3``): the least largest violation ``delta``
  of the soft lines, each soft line ``i`` in turn projected on the lines before it
  (their bisectors) and the direction ``delta`` decreases optimised (a planar program
  with ``directionOpt``).

The arrays carry one row per vehicle, padded to a common number of lines
(:attr:`HalfPlanes.valid`); every step is elementwise over the rows, and each row's
lines are read in their order, so a vehicle's velocity is the number it gets alone,
whatever the other rows (the worlds of a batch). A line is ``point + t direction``, its
admissible side the left one: ``det(direction, v - point) >= 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Two lines whose unit directions have ``|det| <= EPSILON`` are taken as parallel
#: (RVO2's ``RVO_EPSILON``, for doubles).
EPSILON = 1e-9
#: Below this length [m/s] a direction is not normalised (it is left as it is).
TINY = 1e-300


@dataclass
class HalfPlanes:
    """The ORCA lines of ``n`` vehicles, padded to ``m`` lines each.

    Attributes
    ----------
    point : ndarray, shape (n, m, 2) [m/s]
        A point of each line, in velocity space.
    direction : ndarray, shape (n, m, 2) [1]
        Its unit direction; the admissible side is on the left.
    valid : ndarray, shape (n, m), bool
        Which entries are lines (the rest pad the rows).
    hard : ndarray, shape (n,), int
        How many of a row's first lines are hard: never relaxed by
        :func:`relaxed_program` (the obstacles' and the drive's lines).
    """

    point: np.ndarray
    direction: np.ndarray
    valid: np.ndarray
    hard: np.ndarray


def det(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The 2-D cross product ``a_x b_y - a_y b_x`` over the last axis.

    >>> float(det(np.array([1.0, 0.0]), np.array([0.0, 2.0])))
    2.0
    """
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The dot product over the last axis."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def normalized(a: np.ndarray) -> np.ndarray:
    """``a`` divided by its length over the last axis (a zero vector stays zero)."""
    length = np.sqrt(dot(a, a))
    return a / np.maximum(length, TINY)[..., None]


def line_program(
    lines: HalfPlanes,
    rows: np.ndarray,
    i: int,
    radius: np.ndarray,
    opt: np.ndarray,
    direction_opt: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """The best point of line ``i`` of each of ``rows`` (RVO2's ``linearProgram1``).

    On the line, within the disc of ``radius`` and on the admissible side of the
    row's lines before ``i``: nearest to ``opt``, or with ``direction_opt`` the
    farthest along the unit vector ``opt``.

    Parameters
    ----------
    lines : HalfPlanes
    rows : ndarray, shape (k,), int
        The rows to solve.
    i : int
        The line's index.
    radius : ndarray, shape (k,) [m/s]
        Each row's largest speed.
    opt : ndarray, shape (k, 2) [m/s]
        The optimisation velocity (a unit direction with ``direction_opt``).
    direction_opt : bool

    Returns
    -------
    ok : ndarray, shape (k,), bool
        Whether the row's line has an admissible point.
    result : ndarray, shape (k, 2) [m/s]
        That point (meaningless where not ``ok``).
    """
    p, d = lines.point[rows, i], lines.direction[rows, i]
    along = dot(p, d)
    disc = along * along + radius * radius - dot(p, p)
    ok = disc >= 0.0  # else the disc misses the line
    root = np.sqrt(np.maximum(disc, 0.0))
    left, right = -along - root, -along + root
    if i:
        pj, dj = lines.point[rows, :i], lines.direction[rows, :i]
        valid = lines.valid[rows, :i]
        den = det(d[:, None, :], dj)
        num = det(dj, p[:, None, :] - pj)
        parallel = valid & (np.abs(den) <= EPSILON)
        ok &= ~np.any(parallel & (num < 0.0), axis=1)  # on the wrong side of it
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / den
        bounds_right = valid & (den > EPSILON)
        bounds_left = valid & (den < -EPSILON)
        right = np.minimum(right, np.where(bounds_right, t, np.inf).min(axis=1))
        left = np.maximum(left, np.where(bounds_left, t, -np.inf).max(axis=1))
        ok &= left <= right
    if direction_opt:
        t = np.where(dot(opt, d) > 0.0, right, left)
    else:
        t = dot(d, opt - p)
        t = np.where(t < left, left, np.where(t > right, right, t))
    return ok, p + t[:, None] * d


def planar_program(
    lines: HalfPlanes, radius: np.ndarray, opt: np.ndarray, direction_opt: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The admissible velocity of each row (RVO2's ``linearProgram2``).

    Nearest to ``opt`` within the disc and the row's half-planes, or with
    ``direction_opt`` the farthest along the unit vector ``opt``. A row whose lines
    have no common point stops at the first line it cannot keep, with the optimum of
    the lines before it.

    Parameters
    ----------
    lines : HalfPlanes
        ``n`` rows.
    radius : ndarray, shape (n,) [m/s]
    opt : ndarray, shape (n, 2) [m/s]
    direction_opt : bool

    Returns
    -------
    result : ndarray, shape (n, 2) [m/s]
    failed : ndarray, shape (n,), int
        The index of the line each row could not keep; ``m`` (the padded count) for a
        row that kept them all.
    """
    n, m = lines.valid.shape
    if direction_opt:
        result = opt * radius[:, None]
    else:
        speed_sq = dot(opt, opt)
        outside = speed_sq > radius * radius
        scale = np.where(outside, radius / np.sqrt(np.maximum(speed_sq, TINY)), 1.0)
        result = opt * scale[:, None]
    failed = np.full(n, m, dtype=np.intp)
    live = np.ones(n, dtype=bool)
    for i in range(m):
        p, d = lines.point[:, i], lines.direction[:, i]
        broken = live & lines.valid[:, i] & (det(d, p - result) > 0.0)
        rows = broken.nonzero()[0]
        if not len(rows):
            continue
        ok, found = line_program(lines, rows, i, radius[rows], opt[rows], direction_opt)
        result[rows[ok]] = found[ok]
        stuck = rows[~ok]
        failed[stuck] = i
        live[stuck] = False
    return result, failed


def relaxed_program(
    lines: HalfPlanes, radius: np.ndarray, result: np.ndarray, begin: np.ndarray
) -> np.ndarray:
    """The velocity of least largest violation of the soft lines (``linearProgram3``).

    For each row, from the line ``begin`` at which :func:`planar_program` stopped:
    every line that the current result violates by more than the violation ``delta``
    reached so far is taken as the new reference; the lines before it are replaced
    by the bisectors of each with it (the velocities equally far outside both), the
    hard lines kept as they are, and the velocity farthest along the line's inward
    normal is found by a planar program with ``directionOpt``. The hard lines are
    kept throughout: if they alone have no common point the result of the last
    program is kept (RVO2 does the same).

    Parameters
    ----------
    lines : HalfPlanes
        ``n`` rows.
    radius : ndarray, shape (n,) [m/s]
    result : ndarray, shape (n, 2) [m/s]
        :func:`planar_program`'s result (not changed).
    begin : ndarray, shape (n,), int
        :func:`planar_program`'s ``failed``.

    Returns
    -------
    ndarray, shape (n, 2) [m/s]
    """
    n, m = lines.valid.shape
    result = result.copy()
    distance = np.zeros(n)
    hard = lines.hard
    for i in range(m):
        p, d = lines.point[:, i], lines.direction[:, i]
        over = (begin <= i) & lines.valid[:, i] & (det(d, p - result) > distance)
        rows = over.nonzero()[0]
        if not len(rows):
            continue
        pi, di = p[rows], d[rows]
        width = max(i, int(hard[rows].max()))
        j = np.arange(width)
        pj, dj = lines.point[rows, :width], lines.direction[rows, :width]
        kept = j[None, :] < hard[rows, None]  # the hard lines, all of them
        den = det(di[:, None, :], dj)
        parallel = np.abs(den) <= EPSILON
        same = parallel & (dot(di[:, None, :], dj) > 0.0)
        num = det(dj, pi[:, None, :] - pj)
        with np.errstate(divide="ignore", invalid="ignore"):
            cross = pi[:, None, :] + (num / den)[..., None] * di[:, None, :]
        middle = 0.5 * (pi[:, None, :] + pj)
        bisector = np.where(parallel[..., None], middle, cross)
        turned = normalized(dj - di[:, None, :])
        projected = HalfPlanes(
            np.where(kept[..., None], pj, bisector),
            np.where(kept[..., None], dj, turned),
            lines.valid[rows, :width] & (kept | ((j[None, :] < i) & ~same)),
            hard[rows],
        )
        inward = np.empty((len(rows), 2))
        inward[:, 0], inward[:, 1] = -di[:, 1], di[:, 0]
        found, failed = planar_program(projected, radius[rows], inward, True)
        ok = failed == width  # else rounding: the result is kept (as RVO2)
        result[rows[ok]] = found[ok]
        distance[rows] = det(di, pi - result[rows])
    return result


def solve(
    lines: HalfPlanes, radius: np.ndarray, preferred: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """ORCA's new velocity of each row, and the violation it had to accept.

    :func:`planar_program` toward the preferred velocity; the rows whose lines have no
    common point within the disc go on to :func:`relaxed_program`.

    Parameters
    ----------
    lines : HalfPlanes
        ``n`` rows.
    radius : ndarray, shape (n,) [m/s]
        Each row's largest speed.
    preferred : ndarray, shape (n, 2) [m/s]

    Returns
    -------
    velocity : ndarray, shape (n, 2) [m/s]
    slack : ndarray, shape (n,) [m/s]
        The largest violation of a soft line by ``velocity`` (0 where the program was
        feasible).

    Examples
    --------
    One line ``v_x >= 1`` (direction (0, -1) through (1, 0)), the preferred velocity
    (0, 0.5) and a largest speed of 2: the nearest admissible velocity is (1, 0.5).

    >>> lines = HalfPlanes(np.array([[[1.0, 0.0]]]), np.array([[[0.0, -1.0]]]),
    ...                    np.array([[True]]), np.array([0]))
    >>> v, s = solve(lines, np.array([2.0]), np.array([[0.0, 0.5]]))
    >>> v.tolist(), s.tolist()
    ([[1.0, 0.5]], [0.0])
    """
    n, m = lines.valid.shape
    velocity, failed = planar_program(lines, radius, preferred, False)
    slack = np.zeros(n)
    rows = (failed < m).nonzero()[0]
    if not len(rows):
        return velocity, slack
    sub = HalfPlanes(
        lines.point[rows], lines.direction[rows], lines.valid[rows], lines.hard[rows]
    )
    relaxed = relaxed_program(sub, radius[rows], velocity[rows], failed[rows])
    velocity[rows] = relaxed
    soft = sub.valid & (np.arange(m)[None, :] >= sub.hard[:, None])
    gap = det(sub.direction, sub.point - relaxed[:, None, :])
    slack[rows] = np.maximum(np.where(soft, gap, 0.0).max(axis=1), 0.0)
    return velocity, slack
