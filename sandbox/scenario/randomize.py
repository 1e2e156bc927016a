"""Random draws in a scenario: the ``randomize:`` section.

``randomize`` maps dotted field paths (the ``--set`` syntax, e.g. ``vehicles[1].pose``
or ``recovery.beta``) to a distribution:

- ``{uniform: [low, high]}``: uniform on ``[low, high)``; ``low`` and ``high`` are
  numbers, or lists of numbers of equal length drawn elementwise (a pose
  ``[[-3, -3, -3.14], [3, 3, 3.14]]``);
- ``{normal: [mean, std]}``: normal, numbers or equal-length lists (``std >= 0``);
- ``{choice: [a, b, ...]}``: one of the listed values, each equally likely.

The draws come from the scenario's ``seed``, so a scenario with ``randomize`` is still
one deterministic scenario per seed. Each path has its own stream,
``numpy.random.default_rng([seed, attempt, crc32(path)])``: a value depends only on the
seed, the attempt and its own path, never on the order of the keys in the file or on
the other randomized paths. Paths are applied in sorted order. A path that ``--set``
assigned is not drawn (the value given on the command line is kept). Each path must
name a value the file writes (the draw replaces it), so that the file without
``randomize`` is a valid scenario too (the hand-picked case of the draws).

A draw whose vehicles start overlapping each other, or start inside a static obstacle,
is redrawn (``attempt`` 1, 2, ...) up to :data:`MAX_ATTEMPTS` times; after that it is a
problem of the scenario. The drawn values replace the ``randomize`` section in the
document before validation, so the resolved ``scenario.yaml`` of a run holds them and
reruns exactly without ``randomize``.
"""

from __future__ import annotations

import copy
import math
import re
import zlib
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from sandbox.errors import Problem, ScenarioError

#: Draws tried before overlapping starts are reported as a problem.
MAX_ATTEMPTS = 200
DISTRIBUTIONS = ("uniform", "normal", "choice")
_TOKEN = re.compile(r"[^.\[\]]+|\[\d+\]")


class _Bad(Exception):
    """A problem with one randomize entry (path, message)."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(message)
        self.path = path
        self.message = message


def resolve(
    doc: dict[str, Any],
    *,
    skip: set[str] | frozenset[str] = frozenset(),
    line: Callable[[str], int | None] = lambda path: None,
    check: Callable[[dict[str, Any]], Any] | None = None,
) -> tuple[dict[str, Any], list[Problem]]:
    """Replace ``doc["randomize"]`` by values drawn into their fields.

    Parameters
    ----------
    doc : dict
        A scenario document (not modified).
    skip : set of str
        Paths not to draw (set by ``--set``).
    line : callable
        Line of a field path in the file, for messages.
    check : callable, optional
        Parses a candidate document (without ``randomize``) to a
        :class:`~sandbox.scenario.Scenario`, raising
        :class:`~sandbox.errors.ScenarioError`; used to redraw overlapping starts.

    Returns
    -------
    doc : dict
        A new document without ``randomize``, holding the drawn values.
    problems : list of Problem
        Problems of the ``randomize`` section (empty when it is valid).
    """
    spec = doc.get("randomize")
    out = {k: v for k, v in doc.items() if k != "randomize"}
    if spec is None:
        return out, []
    seed = doc.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        return out, []  # the loader reports the seed
    if not isinstance(spec, Mapping):
        got = type(spec).__name__
        return out, [
            Problem(
                "randomize",
                f"not a mapping (got {got}; expected a mapping of field paths to "
                "{uniform: [low, high]}, {normal: [mean, std]} or {choice: [...]})",
                line("randomize"),
            )
        ]
    entries, problems = [], []
    named = {str(p): v for p, v in spec.items()}
    for path in sorted(named):
        where = f"randomize.{path}"
        try:
            entries.append((path, _distribution(named[path], where)))
            _tokens(path, where)
        except _Bad as bad:
            problems.append(Problem(bad.path, bad.message, line(where)))
    if problems:
        return out, problems
    entries = [(p, d) for p, d in entries if p not in skip]
    if check is not None:
        # The file without randomize must be a valid scenario but for where its
        # vehicles start (which the draws move): else the loader reports its problems.
        try:
            check(out)
        except ScenarioError as exc:
            if not all(_is_overlap(p) for p in exc.problems):
                return out, []
    for attempt in range(MAX_ATTEMPTS):
        candidate = copy.deepcopy(out)
        try:
            for path, (kind, args) in entries:
                rng = np.random.default_rng(
                    [seed, attempt, zlib.crc32(path.encode("utf-8"))]
                )
                _assign(candidate, path, _draw(rng, kind, args))
        except _Bad as bad:
            return out, [Problem(bad.path, bad.message, line(bad.path))]
        if check is None or _starts_clear(candidate, check):
            return candidate, []
    return out, [
        Problem(
            "randomize",
            f"no draw without overlapping starts in {MAX_ATTEMPTS} attempts (got "
            "vehicles overlapping each other or an obstacle in every draw; expected "
            "ranges wide enough for the vehicles to start apart)",
            line("randomize"),
        )
    ]


# ----------------------------------------------------------------- the distributions
def _number(value: Any, where: str) -> float:
    """A finite number, as a float."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        try:
            x = float(value)
        except OverflowError:
            x = math.inf
        if math.isfinite(x):
            return x
    raise _Bad(
        where,
        f"not a finite number or a list of them (got {_show(value)}; expected e.g. "
        "1.5 or [0, 0, 3.14])",
    )


def _numbers(value: Any, where: str) -> float | list[float]:
    """A number or a non-empty list of numbers, as floats."""
    if isinstance(value, list) and value:
        return [_number(v, where) for v in value]
    return _number(value, where)


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _distribution(entry: Any, where: str) -> tuple[str, tuple[Any, ...]]:
    """Validate one entry; return ``(kind, arguments)``."""
    expected = "{uniform: [low, high]}, {normal: [mean, std]} or {choice: [a, b, ...]}"
    if not isinstance(entry, Mapping) or len(entry) != 1:
        raise _Bad(
            where, f"not a distribution (got {_show(entry)}; expected {expected})"
        )
    kind, args = next(iter(entry.items()))
    if kind not in DISTRIBUTIONS:
        raise _Bad(
            f"{where}.{kind}",
            f"unknown distribution (got {kind!r}; expected one of "
            f"{', '.join(DISTRIBUTIONS)})",
        )
    where = f"{where}.{kind}"
    if kind == "choice":
        if not isinstance(args, list) or not args:
            raise _Bad(where, f"not a list (got {_show(args)}; expected [a, b, ...])")
        return kind, tuple(args)
    if not isinstance(args, list) or len(args) != 2:
        names = "[low, high]" if kind == "uniform" else "[mean, std]"
        raise _Bad(where, f"not a pair (got {_show(args)}; expected {names})")
    a, b = _numbers(args[0], where), _numbers(args[1], where)
    if np.shape(a) != np.shape(b):
        raise _Bad(
            where,
            f"the two bounds differ in shape (got {_show(args)}; expected two numbers "
            "or two lists of equal length)",
        )
    lo, hi = np.asarray(a), np.asarray(b)
    if kind == "uniform" and np.any(hi < lo):
        raise _Bad(where, f"high below low (got {_show(args)}; expected low <= high)")
    if kind == "normal" and np.any(hi < 0):
        raise _Bad(where, f"negative std (got {_show(args)}; expected std >= 0)")
    with np.errstate(over="ignore", invalid="ignore"):
        spread = hi - lo if kind == "uniform" else lo + 10 * hi
    if not np.all(np.isfinite(spread)):
        raise _Bad(
            where,
            f"the range overflows (got {_show(args)}; expected bounds whose "
            "difference is a finite number)",
        )
    return kind, (a, b)


def _draw(rng: np.random.Generator, kind: str, args: tuple[Any, ...]) -> Any:
    """One value of a distribution (plain Python floats or the chosen item)."""
    if kind == "choice":
        return copy.deepcopy(args[int(rng.integers(len(args)))])
    lo, hi = np.asarray(args[0], dtype=float), np.asarray(args[1], dtype=float)
    if kind == "uniform":
        value = lo + (hi - lo) * rng.random(lo.shape)
    else:
        value = lo + hi * rng.standard_normal(lo.shape)
    return value.tolist() if value.ndim else float(value)


# ------------------------------------------------------------------------ the paths
def _tokens(path: str, where: str) -> list[str]:
    tokens = _TOKEN.findall(path)
    if "".join(t if t.startswith("[") else f".{t}" for t in tokens).lstrip(".") != path:
        raise _Bad(
            where,
            f"names no field (got {path!r}; expected a dotted path like recovery.beta "
            "or vehicles[1].pose)",
        )
    return tokens


def _assign(doc: dict[str, Any], path: str, value: Any) -> None:
    """Replace the value at ``path`` in ``doc``; the field must be written there."""
    where = f"randomize.{path}"
    tokens = _tokens(path, where)
    target: Any = doc
    for k, tok in enumerate(tokens):
        last = k == len(tokens) - 1
        if tok.startswith("["):
            idx = int(tok[1:-1])
            found = isinstance(target, list) and idx < len(target)
        else:
            found = isinstance(target, dict) and target.get(tok) is not None
        if not found:
            raise _Bad(
                where,
                f"names no field written in the scenario (got {path!r}; expected the "
                "path of a value the file sets: randomize replaces it, so that the "
                "file is a valid scenario without randomize too)",
            )
        key = int(tok[1:-1]) if tok.startswith("[") else tok
        if last:
            target[key] = value
        else:
            target = target[key]


# ----------------------------------------------------------------------- the starts
def _is_overlap(problem: Problem) -> bool:
    """Whether a problem is a start overlapping another vehicle or an obstacle."""
    return "start" in problem.message and "overlapping" in problem.message


def _starts_clear(candidate: dict[str, Any], check: Callable[[dict], Any]) -> bool:
    """Whether no vehicle starts overlapping another or an obstacle (loader checks).

    A candidate with other problems counts as clear: redrawing would not help, and the
    loader reports those problems.
    """
    try:
        check(candidate)
    except ScenarioError as exc:
        return not any(_is_overlap(p) for p in exc.problems)
    return True
