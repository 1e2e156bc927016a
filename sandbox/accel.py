"""The compiled paths: which are on, why one is off, and the one switch.

Some stages have a compiled form beside their numpy form: a C extension that does a
period's work for every vehicle of every world in one call, where numpy would make
dozens of small calls whose fixed cost is most of a small fleet's time. Each is the
stage's fast path, not a second definition: the numpy form is the reference, and
the tests compare the two within the tolerances below. This module is the only one
that imports the extensions; a stage asks it for its module with :func:`module` and
takes the numpy form where the answer is None.

Every path is on wherever its extension was built (the install compiles them where
it finds a C compiler, and goes on without the ones it cannot build). The
environment variable ``SANDBOX_ACCEL`` is read once, at the first use: ``0`` turns
every compiled path off, ``1`` (or unset) leaves them on. ``sandbox info`` prints
each path with ``on`` or ``off`` and why; :func:`switched_off` turns them all off
for a block of code (the tests' numpy reference).

Determinism is per build and machine: the same inputs give the same bytes. A run with
the compiled paths off may differ from one with them on in the last bits of its
numbers (the C library's ``atan2``, ``exp`` or ``log`` and numpy's may round a last
bit apart, and a C loop adds in its own order), and over a long run such a difference
may grow where a contact grazes or not. Outside contacts the paths agree with their
numpy forms within (the tests' bounds, ``tests/test_compiled_paths.py``):

==========  ==========================================================================
path        tolerance against the numpy form (rtol and atol)
==========  ==========================================================================
laws        1e-12 on a period's slots and their derivatives, and the tangent of (15)
pair_field  1e-12 on the shift and the targets; the same avoiding vehicles
draws       the numbers of each world's Generator (numpy's own functions): exact
controller  1e-12 on ``chi`` and the commands of a period, and on the motor model
filter      1e-9 [m/s] on ``v1`` and the slack, 1e-8 [rad/s] on ``v2``, 1e-9 on the
            barrier values; the same filtered vehicles and rows
qp          1e-9 [m/s] on the projections; the same feasible problems
motors      1e-12 on the force limits; the same joints changed
stepping    1e-9 on whole runs with contacts (the same calls of pymunk's functions)
period      the divergence check's verdict; the loop metrics and the record within
            the whole runs' bound
residual    1e-9 on the detector's state and trace; the same alarms and kinds
fits        1e-9 on the two least sums of squares
==========  ==========================================================================

and whole runs without contacts agree within 1e-9 on every recorded number and
metric, with the same events and detections.
"""

from __future__ import annotations

import importlib
import os
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import ModuleType

#: The environment variable of the one switch.
ENV = "SANDBOX_ACCEL"
#: Why a path is off where its extension was not built.
NOT_BUILT = "not built (no C compiler at install)"


@dataclass(frozen=True)
class CompiledPath:
    """One compiled path: its name, its extension module and what it computes."""

    name: str
    module: str
    computes: str


#: Every compiled path, in the order of the loop's period.
PATHS: tuple[CompiledPath, ...] = (
    CompiledPath(
        "laws",
        "sandbox.model._laws",
        "a built-in formation law's targets of a period (eqs. 7-20)",
    ),
    CompiledPath(
        "pair_field",
        "sandbox.behaviour._pair_field",
        "the avoidance field's pair terms and a weighted strategy's targets",
    ),
    CompiledPath(
        "draws",
        "sandbox.behaviour._draws",
        "every world's sensing draws from its own generator (numpy's random C API)",
    ),
    CompiledPath(
        "controller",
        "sandbox.model._kernels",
        "the flatness controller's period (eqs. 5-6) and the detector's motor model",
    ),
    CompiledPath(
        "filter",
        "sandbox.behaviour.safety._filter",
        "the CBF filter's velocity-barrier step and its counters",
    ),
    CompiledPath(
        "qp",
        "sandbox.behaviour.safety._filter",
        "the safety filter's exact projections (in the filter's extension)",
    ),
    CompiledPath(
        "motors",
        "sandbox.physics._motors",
        "the motors' force limits of a period",
    ),
    CompiledPath(
        "stepping",
        "sandbox.physics._cstep",
        "a period of pymunk's stepping for every world in one call",
    ),
    CompiledPath(
        "period",
        "sandbox.loop._period",
        "the loop's copies, metrics and record of a period",
    ),
    CompiledPath(
        "residual",
        "sandbox.behaviour._residual",
        "the residual detector's pass of a period",
    ),
    CompiledPath(
        "fits",
        "sandbox.behaviour._fits",
        "the detectors' crash-or-stop fits",
    ),
)

_BY_NAME = {p.name: p for p in PATHS}


class _Found(dict):
    """Each path's module once looked up (None: off); a name not yet asked is."""

    def __missing__(self, name: str) -> ModuleType | None:
        return _look_up(_BY_NAME[name])


_modules = _Found()
_reasons: dict[str, str] = {}
_setting: str | None = None

#: ``module(name)``: the extension module of the compiled path ``name``, or None
#: where it is off; KeyError where ``name`` is not one of :data:`PATHS`' names (e.g.
#: ``"controller"``). The lookup of the dict itself, a call without a Python frame:
#: the loop asks it several times a period.
module: Callable[[str], ModuleType | None] = _modules.__getitem__


def _look_up(path: CompiledPath) -> ModuleType | None:
    """Import ``path``'s extension (once), unless the switch is off."""
    setting = _switch()
    if setting == "0":
        found, why = None, f"{ENV}=0"
    else:
        found, why = _import(path.module)
    _modules[path.name] = found
    _reasons[path.name] = why
    return found


def _import(name: str) -> tuple[ModuleType | None, str]:
    """The module ``name``, or None and why it cannot be imported."""
    try:
        return importlib.import_module(name), ""
    except ModuleNotFoundError as exc:
        if exc.name == name:
            return None, NOT_BUILT
        return None, f"cannot be imported: {exc}"
    except ImportError as exc:  # built for another Python or numpy, a missing symbol
        return None, f"cannot be imported: {exc}"


def _switch() -> str:
    """``SANDBOX_ACCEL`` as read at the first use: ``"0"`` or ``"1"``."""
    global _setting
    if _setting is None:
        text = os.environ.get(ENV, "").strip()
        if text not in ("", "0", "1"):
            from sandbox.errors import SandboxWarning

            warnings.warn(
                f"{ENV}={text!r} is neither 0 (every compiled path off) nor 1 (on): "
                "taken as 1",
                SandboxWarning,
                stacklevel=3,
            )
        _setting = "0" if text == "0" else "1"
    return _setting


def status() -> list[tuple[str, bool, str]]:
    """Every compiled path's name, whether it is on, and why not (``""`` when on).

    The reason is :data:`NOT_BUILT`, ``"SANDBOX_ACCEL=0"``, or the text of the error
    that its import raised.
    """
    out = []
    for path in PATHS:
        on = module(path.name) is not None
        out.append((path.name, on, _reasons.get(path.name, "")))
    return out


def not_built() -> list[str]:
    """The compiled paths that are off because their extension was not built.

    Empty where ``SANDBOX_ACCEL=0`` (the user's own choice says nothing of the build).
    """
    return [name for name, on, why in status() if not on and why == NOT_BUILT]


@contextmanager
def switched_off(*names: str) -> Iterator[None]:
    """The compiled paths ``names`` (default: every one) off within the block.

    What the loop and its stages build within the block takes the numpy forms of
    those paths (a stage asks for its module when it is built or called). Used by
    the tests to compare each compiled path with its numpy form, and by the
    benchmarks to time both.

    Parameters
    ----------
    *names : str
        Names of :data:`PATHS`; none: all of them.

    >>> with switched_off():
    ...     module("controller") is None
    True
    """
    off = names or tuple(_BY_NAME)
    unknown = [name for name in off if name not in _BY_NAME]
    if unknown:
        raise KeyError(f"not compiled paths: {', '.join(unknown)}")
    for name in _BY_NAME:
        if name not in off:
            module(name)  # looked up now, as it stands outside the block
    saved = dict(_modules), dict(_reasons)
    for name in off:
        _modules[name] = None
        _reasons[name] = "switched off (sandbox.accel.switched_off)"
    try:
        yield
    finally:  # in place: ``module`` is bound to this very dict
        _modules.clear()
        _modules.update(saved[0])
        _reasons.clear()
        _reasons.update(saved[1])
