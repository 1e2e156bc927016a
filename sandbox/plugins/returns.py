"""What each kind of plug-in must return, checked on every call of a user's plug-in.

The guard of :func:`sandbox.plugins.registration.runnable` calls the check of the
plug-in's kind (:data:`RETURNS`) on what the plug-in returned, before the loop reads
it: a wrong type or shape (None, a text, an ``(n, 3)`` array where ``(n, 2)`` is
asked) then ends the run with status ``error`` naming the plug-in and saying what it
returned and what was expected, instead of a traceback deep in the loop or, for a
detector, a silent wrong answer (numpy reads ``None`` as "nobody failed" and a text as
"everyone"). Each check takes the value and the call's positional arguments (the
context, or the times of a reference's ``evaluate(t)``) and returns None when the
value is right, else what is wrong, as one line. Numbers may be given as anything
numpy reads as numbers of the right shape (a list, a scalar that broadcasts); the
values' finiteness is the guard's other check.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["RETURNS", "Returned", "describe"]

#: A check of a returned value: ``check(value, args) -> None or what is wrong``.
Returned = Callable[[Any, tuple], "str | None"]
#: dtype kinds read as numbers (booleans are numbers to numpy).
NUMBERS = "biuf"


def describe(value: Any) -> str:
    """A short description of a returned value, for a message.

    >>> describe(None), describe("abc"), describe(np.zeros((3, 3)))
    ('None', "the text 'abc'", 'an array of shape (3, 3) (float64)')
    """
    if value is None:
        return "None"
    if isinstance(value, str):
        return f"the text {value[:20]!r}"
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} ({value.dtype})"
    if isinstance(value, tuple | list):
        return f"a {type(value).__name__} of {len(value)}"
    return f"a {type(value).__name__}"


def _numbers(value: Any, shape: tuple[int, ...], what: str) -> str | None:
    """None if ``value`` is numbers that broadcast to ``shape``, else what is wrong."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):  # a ragged list
        return f"{what}: {describe(value)}, not numbers of shape {shape}"
    if array.dtype.kind not in NUMBERS:
        return f"{what}: {describe(value)}, not numbers of shape {shape}"
    try:
        np.broadcast_to(array, shape)
    except ValueError:
        return f"{what}: {describe(array)}, not of shape {shape}"
    return None


def _parts(value: Any, names: Sequence[str]) -> str | None:
    """None if ``value`` is a tuple (or list) of ``len(names)`` items."""
    if not isinstance(value, tuple | list) or len(value) != len(names):
        return f"returned {describe(value)}, expected ({', '.join(names)})"
    return None


def _first(
    parts: Sequence[Any], shapes: Sequence[tuple], names: Sequence[str]
) -> str | None:
    """The first message of the parts' checks, or None."""
    for part, shape, name in zip(parts, shapes, names, strict=True):
        wrong = _numbers(part, shape, name)
        if wrong:
            return f"returned {wrong}"
    return None


def _rows(ctx: Any) -> int:
    """The number of vehicle rows a context holds (the worlds' rows when batched)."""
    return len(np.asarray(ctx.pos))


def law(value: Any, args: tuple) -> str | None:
    """``(slot, v_ref, a_ref)``, each of the offsets' shape [m], [m/s], [m/s^2]."""
    names = ("slot", "v_ref", "a_ref")
    shape = np.shape(args[0].offset)
    return _parts(value, names) or _first(value, [shape] * 3, names)


def strategy(value: Any, args: tuple) -> str | None:
    """``(shift, active)``: shapes (n, 2) [m] and (n,)."""
    names = ("shift", "active")
    n = _rows(args[0])
    return _parts(value, names) or _first(value, [(n, 2), (n,)], names)


def failure(value: Any, args: tuple) -> str | None:
    """``(v1, v2)`` of the failed vehicle: two numbers [m/s], [rad/s]."""
    names = ("v1", "v2")
    wrong = _parts(value, names)
    if wrong:
        return wrong
    for part, name in zip(value, names, strict=True):
        if np.ndim(part) != 0 or _numbers(part, (), name):
            return f"returned {name}: {describe(part)}, not one number"
    return None


def reference(value: Any, args: tuple) -> str | None:
    """``(p, dp, ddp)``, each of shape ``t.shape + (2,)`` [m], [m/s], [m/s^2]."""
    names = ("p", "dp", "ddp")
    t = getattr(args[0], "t", args[0])  # a function's context, or evaluate(t)
    shape = (*np.shape(t), 2)
    return _parts(value, names) or _first(value, [shape] * 3, names)


def safety_filter(value: Any, args: tuple) -> str | None:
    """``(v1, v2)``: the commands to apply, shapes (n,) [m/s], [rad/s]."""
    names = ("v1", "v2")
    n = _rows(args[0])
    return _parts(value, names) or _first(value, [(n,), (n,)], names)


def detector(value: Any, args: tuple) -> str | None:
    """``suspected`` (n,) bool, or ``(suspected, kinds)`` with n texts (or None)."""
    n = _rows(args[0])
    kinds = None
    if isinstance(value, tuple):
        wrong = _parts(value, ("suspected", "kinds"))
        if wrong:
            return wrong
        value, kinds = value
    try:
        array = np.asarray(value)
    except (TypeError, ValueError):
        array = np.asarray(None)
    if array.dtype.kind not in NUMBERS or array.shape != (n,):
        return (
            f"returned suspected: {describe(value)}, expected an array of {n} "
            "booleans (one per vehicle)"
        )
    if kinds is not None and (
        isinstance(kinds, str)
        or not isinstance(kinds, Sequence | np.ndarray)
        or len(kinds) != n
        or not all(k is None or isinstance(k, str) for k in kinds)
    ):
        return f"returned kinds: {describe(kinds)}, expected {n} texts (or None)"
    return None


#: The check of each kind that runs during a run (an obstacle type runs at load time,
#: where the loader checks what it returns).
RETURNS: dict[str, Returned] = {
    "law": law,
    "strategy": strategy,
    "failure": failure,
    "reference": reference,
    "filter": safety_filter,
    "detector": detector,
}
