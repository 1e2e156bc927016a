"""Registration: :class:`Param`, the kinds of plug-in, the decorators and the tables.

The lowest layer of the package beside :mod:`sandbox.errors`: it imports nothing that
registers into it. The built-in plug-ins are imported by name, once, the first time a
table is read (:data:`sandbox.plugins.builtin.BUILTIN_MODULES`); the public face of
this module is :mod:`sandbox.plugins`.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sandbox.errors import PluginError, PluginRunError
from sandbox.plugins.builtin import BUILTIN_MODULES
from sandbox.plugins.contexts import (
    DetectorContext,
    FailureContext,
    FilterContext,
    LawContext,
    ObstacleContext,
    ReferenceContext,
    StrategyContext,
)
from sandbox.plugins.params import REQUIRED, Param, declare
from sandbox.plugins.returns import RETURNS, Returned

__all__ = [
    "ENTRY_POINT_GROUP",
    "KINDS",
    "REQUIRED",
    "DetectorContext",
    "FailureContext",
    "FilterContext",
    "LawContext",
    "ObstacleContext",
    "Param",
    "Plugin",
    "PluginError",
    "ReferenceContext",
    "StrategyContext",
    "get",
    "make_law",
    "names",
    "register_detector",
    "register_failure",
    "register_filter",
    "metric_contributions",
    "register_law",
    "register_metrics",
    "register_obstacle",
    "register_reference",
    "register_strategy",
    "registry",
    "runnable",
]

#: Where a law lays out a generated platoon's offsets (``register_law(frame=...)``).
LAW_FRAMES = ("leader", "world", "reference", "leader_reference")
#: Entry-point group of installed plug-in packages.
ENTRY_POINT_GROUP = "sandbox.plugins"


# ------------------------------------------------------------------------ the kinds
@dataclass(frozen=True)
class Kind:
    """A kind of plug-in: where a scenario selects it and how.

    Attributes
    ----------
    name : str
        ``law``, ``strategy``, ...
    section : str
        The YAML section that selects it (empty: none yet).
    selector : str
        The key of that section holding the plug-in's name.
    title : str
        What one is called in messages (``recovery strategy``).
    lenient : bool
        Whether the section accepts, and ignores, keys declared by another plug-in of
        the kind (so that switching e.g. the strategy with ``--set`` keeps a file
        valid); otherwise such a key is an error naming the plug-ins it applies to.
    context : str
        One line on what the plug-in receives and returns.
    """

    name: str
    section: str
    selector: str
    title: str
    lenient: bool
    context: str


KINDS: dict[str, Kind] = {
    k.name: k
    for k in (
        Kind(
            "law",
            "formation",
            "law",
            "formation law",
            False,
            "a FormationLaw subclass, or f(ctx: LawContext) -> (slot, v_ref, a_ref)",
        ),
        Kind(
            "strategy",
            "recovery",
            "strategy",
            "recovery strategy",
            True,
            "f(ctx: StrategyContext) -> (shift (n, 2) [m], active (n,) bool)",
        ),
        Kind(
            "failure",
            "failures",
            "kind",
            "failure kind",
            True,
            "f(ctx: FailureContext) -> (v1 [m/s], v2 [rad/s]) of the failed vehicle",
        ),
        Kind(
            "reference",
            "reference",
            "type",
            "reference type",
            False,
            "a class built with the params, with evaluate(t) -> (p, dp, ddp), or "
            "f(ctx: ReferenceContext) -> (p, dp, ddp)",
        ),
        Kind(
            "obstacle",
            "obstacles",
            "type",
            "obstacle type",
            False,
            "f(ctx: ObstacleContext) -> ObstacleSpec (a circle, box, polygon or wall)",
        ),
        Kind(
            "filter",
            "safety",
            "filter",
            "safety filter",
            True,
            "f(ctx: FilterContext) -> (v1 (n,) [m/s], v2 (n,) [rad/s])",
        ),
        Kind(
            "detector",
            "detection",
            "method",
            "failure detector",
            True,
            "f(ctx: DetectorContext) -> suspected (n,) bool, or (suspected, kinds)",
        ),
    )
}


@dataclass(frozen=True)
class Plugin:
    """One registered name.

    Attributes
    ----------
    kind, name : str
    obj : object
        The registered function or class.
    params : dict of str to Param
        Its YAML parameters.
    doc : str
        The first line of its docstring.
    origin : str
        Where it comes from: ``built-in (module)``, a file path, a module name or an
        entry point.
    options : dict
        Kind-specific flags (a law's ``needs_leader``, a failure's ``immovable``, ...).
    check : callable, optional
        ``check(values, section) -> [(key, what, got, expected), ...]``: checks across
        the plug-in's values (which it may complete, e.g. a default that depends on
        another key); ``section`` is the whole YAML section, read.
    """

    kind: str
    name: str
    obj: Any
    params: dict[str, Param]
    doc: str
    origin: str
    options: dict[str, Any] = field(default_factory=dict)
    check: Callable[[dict[str, Any], dict[str, Any]], list[tuple]] | None = None


_REGISTRY: dict[str, dict[str, Plugin]] = {kind: {} for kind in KINDS}
#: Plug-in sources already imported (resolved path or module name -> module).
_LOADED: dict[str, Any] = {}
#: Whether the entry points were imported (once per process).
_ENTRY_POINTS_LOADED: list[bool] = []
#: Whether the built-in plug-ins were imported (once per process).
_BUILTINS_LOADED: list[bool] = []
#: Where plug-ins registered now come from (set while a plug-in module is imported).
_ORIGIN: list[str] = []


def _ensure_builtins() -> None:
    """Import the modules that register the built-in plug-ins, once.

    They are named in :data:`sandbox.plugins.builtin.BUILTIN_MODULES`, imported by
    name: this module imports nothing that registers into it.
    """
    if _BUILTINS_LOADED:
        return
    _BUILTINS_LOADED.append(True)
    for module in BUILTIN_MODULES:
        importlib.import_module(module)


def registry(kind: str) -> dict[str, Plugin]:
    """The registered plug-ins of a kind, name to :class:`Plugin`, in order."""
    if kind not in KINDS:
        raise KeyError(f"no plug-in kind {kind!r}; kinds: {', '.join(KINDS)}")
    _ensure_builtins()
    return _REGISTRY[kind]


def names(kind: str) -> tuple[str, ...]:
    """The registered names of a kind, in registration order (built-ins first)."""
    return tuple(registry(kind))


def get(kind: str, name: str) -> Plugin:
    """The plug-in registered under ``name`` (``KeyError`` if none)."""
    return registry(kind)[name]


def all_params(kind: str) -> dict[str, list[str]]:
    """Every parameter name of a kind, with the plug-ins that declare it."""
    out: dict[str, list[str]] = {}
    for plugin in registry(kind).values():
        for key in plugin.params:
            out.setdefault(key, []).append(plugin.name)
    return out


class RegistryView(Mapping):
    """A read-only, live mapping name -> registered object of one kind.

    ``sandbox.model.laws.LAWS`` is ``RegistryView("law")``: code that looked
    laws up by name keeps working, and sees plug-ins registered later.
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind

    def __getitem__(self, name: str) -> Any:
        return registry(self.kind)[name].obj

    def __iter__(self) -> Iterator[str]:
        return iter(registry(self.kind))

    def __len__(self) -> int:
        return len(registry(self.kind))


def _first_line(obj: Any) -> str:
    text = inspect.getdoc(obj) or ""
    return text.strip().splitlines()[0] if text.strip() else ""


def register(
    kind: str,
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    doc: str | None = None,
    check: Callable | None = None,
    **options: Any,
) -> Callable[[Any], Any]:
    """Decorator registering ``obj`` as the plug-in ``name`` of ``kind``.

    The ``register_*`` functions are this with their kind filled in.

    Raises
    ------
    ValueError
        The name is already registered for this kind, is not a plain name, or a
        parameter declaration is invalid, or clashes with a key of the section.
    """
    if kind not in KINDS:
        raise ValueError(f"no plug-in kind {kind!r}; kinds: {', '.join(KINDS)}")
    if not isinstance(name, str) or not name or not name.replace("_", "a").isalnum():
        raise ValueError(f"{kind} name {name!r}: use letters, digits and _ only")
    declared = declare(params)
    reserved = _SECTION_KEYS.get(kind, ())
    clash = [k for k in declared if k in reserved]
    if clash:
        raise ValueError(
            f"{kind} {name!r}: parameter {clash[0]!r} is a key of the "
            f"{KINDS[kind].section} section itself; choose another name"
        )

    def add(obj: Any) -> Any:
        table = _REGISTRY[kind]
        if name in table:
            raise ValueError(
                f"{KINDS[kind].title} {name!r} is already registered "
                f"(by {table[name].origin})"
            )
        module = getattr(obj, "__module__", "") or ""
        origin = _ORIGIN[-1] if _ORIGIN else ""
        if not origin:
            origin = f"built-in ({module})" if module.startswith("sandbox.") else module
        table[name] = Plugin(
            kind,
            name,
            obj,
            declared,
            doc if doc is not None else _first_line(obj),
            origin,
            dict(options),
            check,
        )
        return obj

    return add


#: Keys of each kind's YAML section that are not plug-in parameters (set by the
#: scenario layer, which declares those sections).
_SECTION_KEYS: dict[str, tuple[str, ...]] = {}


def reserve_section_keys(kind: str, keys: tuple[str, ...]) -> None:
    """Record the section's own keys of a kind (a plug-in may not declare them)."""
    _SECTION_KEYS[kind] = tuple(keys)


def unregister(kind: str, name: str) -> None:
    """Remove a registration (for tests and interactive sessions)."""
    _REGISTRY[kind].pop(name, None)


#: What a behaviour adds to ``metrics.json``: name -> ``f(run) -> dict`` of blocks.
_METRICS: dict[str, Callable[[Any], dict[str, Any]]] = {}


def register_metrics(name: str) -> Callable[[Any], Any]:
    """Register what a behaviour adds to ``metrics.json``: ``f(run) -> dict``.

    :func:`sandbox.compute_metrics` calls every registered function with the recorded
    run and adds the blocks it returns (an empty dict adds nothing), after the
    blocks of the run itself and before ``warnings``, in registration order. This is
    how a stage above the metrics (the detector, for one) contributes to them without
    the metrics importing it.

    Raises
    ------
    ValueError
        The name is already registered.
    """

    def add(func: Callable[[Any], dict[str, Any]]) -> Callable[[Any], dict[str, Any]]:
        if name in _METRICS:
            raise ValueError(f"metrics {name!r} are already registered")
        _METRICS[name] = func
        return func

    return add


def metric_contributions() -> dict[str, Callable[[Any], dict[str, Any]]]:
    """The registered contributions to ``metrics.json``, in registration order."""
    _ensure_builtins()
    return dict(_METRICS)


def register_law(
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    needs_leader: bool | None = None,
    needs_reference: bool | None = None,
    frame: str = "leader",
    batched: bool = False,
    doc: str | None = None,
    check: Callable | None = None,
) -> Callable[[Any], Any]:
    """Register a formation law (``formation: {law: NAME, ...}``).

    The law is a :class:`~sandbox.model.laws.FormationLaw` subclass, built as
    ``cls(delta, h, **params)``, or a function ``f(ctx: LawContext) -> (slot, v_ref,
    a_ref)``, each of shape (n, 2) [m], [m/s], [m/s^2].

    Parameters
    ----------
    needs_leader, needs_reference : bool, optional
        Whether the law needs a vehicle with ``leader: true`` / a ``reference``
        (default: the class's attributes; for a function, a leader and no reference).
        A law without a leader has every vehicle follow its slot; with one, the
        leader tracks the reference itself.
    frame : str
        Where the offsets of a generated ``platoon`` are laid out at t = 0:
        ``leader`` (around the leader, in its frame), ``world`` (around the leader,
        in the world frame), ``reference`` (around the reference's start, turned by
        its tangent with ``rotate``) or ``leader_reference`` (around the leader,
        turned by the reference's tangent with ``rotate``).
    batched : bool
        Whether the law takes the worlds of a batch at once (default False: it is
        called world by world). A batched law is built with the offsets of all
        worlds, shape (K, n, 2), and sees ``pos``, ``vel``, ``offset`` of shape
        (K, n, 2), ``theta`` (K, n), ``leader_pos`` (K, 1, 2) and ``leader_theta``
        (K, 1); what it returns must broadcast to (K, n, 2), each world's rows the
        numbers the law gives that world alone (elementwise code over the last axes
        is). The built-in laws are batched.
    """
    if frame not in LAW_FRAMES:
        raise ValueError(f"law {name!r}: frame {frame!r} is not one of {LAW_FRAMES}")

    def add(obj: Any) -> Any:
        lead = needs_leader
        ref = needs_reference
        if lead is None:
            lead = bool(getattr(obj, "needs_leader", True))
        if ref is None:
            ref = bool(getattr(obj, "needs_reference", False))
        if inspect.isclass(obj):
            obj.name = name
            obj.needs_leader, obj.needs_reference = lead, ref
        return register(
            "law",
            name,
            params,
            doc=doc,
            check=check,
            needs_leader=lead,
            needs_reference=ref,
            frame=frame,
            batched=batched,
        )(obj)

    return add


def register_strategy(
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    batched: bool = False,
    doc: str | None = None,
    check: Callable | None = None,
) -> Callable[[Any], Any]:
    """Register a recovery strategy (``recovery: {strategy: NAME, ...}``).

    The strategy is ``f(ctx: StrategyContext) -> (shift, active)``: the shift of each
    vehicle's target, shape (n, 2) [m], and whether each vehicle is avoiding (mode
    ``avoid``), shape (n,) bool. Vehicles that may not avoid (``ctx.may_avoid``
    false) keep a zero shift whatever it returns.

    With ``batched=True`` the strategy is called once for all worlds of a batch: the
    context's arrays hold the rows of K worlds, world after world (``K n`` rows),
    ``params["beta"]`` may be a column of rows, and ``ctx.neighbours`` never pairs
    vehicles of two worlds; each world's rows must be the numbers it gets alone.
    Without it (the default) the strategy is called world by world. The built-in
    strategies are batched.
    """
    return register("strategy", name, params, doc=doc, check=check, batched=batched)


def register_failure(
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    controlled_speed: bool = False,
    immovable: bool = False,
    permanent: bool = False,
    doc: str | None = None,
    check: Callable | None = None,
) -> Callable[[Any], Any]:
    """Register a failure kind (``failures: [{kind: NAME, vehicle: ..., at: ...}]``).

    The kind is ``f(ctx: FailureContext) -> (v1, v2)``: the commands the failed
    vehicle really applies [m/s], [rad/s], called once per control period while the
    failure is active.

    Parameters
    ----------
    controlled_speed : bool
        Whether the controller still drives v1 (its states keep integrating).
    immovable : bool
        Whether the vehicle becomes a fixed obstacle at onset.
    permanent : bool
        Whether the failure cannot end (``until`` is refused).
    """
    return register(
        "failure",
        name,
        params,
        doc=doc,
        check=check,
        controlled_speed=controlled_speed,
        immovable=immovable,
        permanent=permanent,
    )


def register_reference(
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    doc: str | None = None,
    check: Callable | None = None,
) -> Callable[[Any], Any]:
    """Register a reference type (``reference: {type: NAME, ...}``).

    Either a class built once as ``cls(**params)`` with ``evaluate(t) -> (p, dp,
    ddp)``, or a function ``f(ctx: ReferenceContext) -> (p, dp, ddp)``; ``t`` is a
    float or an array of times [s], and each result has shape ``t.shape + (2,)``
    [m], [m/s], [m/s^2].
    """
    return register("reference", name, params, doc=doc, check=check)


def register_obstacle(
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    doc: str | None = None,
    check: Callable | None = None,
) -> Callable[[Any], Any]:
    """Register an obstacle type (``obstacles: [{type: NAME, ...}]``).

    The type is ``f(ctx: ObstacleContext) -> ObstacleSpec``: the shape it occupies,
    as a circle, box, polygon or wall (:class:`~sandbox.scenario.ObstacleSpec`),
    built once at load time.
    """
    return register("obstacle", name, params, doc=doc, check=check)


def register_filter(
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    batched: bool = False,
    doc: str | None = None,
    check: Callable | None = None,
) -> Callable[[Any], Any]:
    """Register a safety filter (``safety: {filter: NAME, ...}``).

    The filter is ``f(ctx: FilterContext) -> (v1, v2)``, each of shape (n,) [m/s],
    [rad/s]: it sees the commands about to be applied and returns the ones to apply,
    once per control period, after the controller and before the failures. Built in:
    ``none`` (never called) and ``cbf`` (:mod:`sandbox.behaviour.safety.cbf`).

    With ``batched=True`` a loop of K worlds calls the filter once, on the rows of
    all worlds (``ctx.worlds`` is K, each world's counters in ``ctx.world_stats``);
    each world's rows must be the commands it gets alone, its pairs never across
    worlds (:class:`~sandbox.geometry.neighbours.AllPairsByWorld`). Without it (the
    default) the filter is called world by world. ``cbf`` is batched.
    """
    return register("filter", name, params, doc=doc, check=check, batched=batched)


def register_detector(
    name: str,
    params: Mapping[str, Any] | None = None,
    *,
    batched: bool = False,
    doc: str | None = None,
    check: Callable | None = None,
) -> Callable[[Any], Any]:
    """Register a failure detector (``detection: {method: NAME, ...}``).

    The detector is ``f(ctx: DetectorContext) -> suspected``, shape (n,) bool: the
    vehicles the platoon believes failed now (it keeps its state in ``ctx.memory``),
    or ``(suspected, kinds)`` with ``kinds`` a list of n strings naming the kind of
    each suspicion. Built in: ``oracle`` (the truth, at once), ``residual``
    (:mod:`sandbox.behaviour.detection`) and ``none`` (nothing is ever detected).

    With ``batched=True`` a loop of K worlds calls the detector once, on the rows of
    all worlds (``K n`` rows, world after world; the declared noise and the
    detector's values are the same in every world of one loop): each vehicle's
    decision must depend on its own rows only. Without it (the default) the
    detector is called world by world. ``residual`` and ``glr`` are batched.
    """
    return register("detector", name, params, doc=doc, check=check, batched=batched)


@register_filter("none")
def no_filter(ctx: FilterContext) -> tuple[np.ndarray, np.ndarray]:
    """No safety filter: the commands pass unchanged."""
    return ctx.v1, ctx.v2


@register_detector("none")
def no_detector(ctx: DetectorContext) -> np.ndarray:
    """No failure detection: no vehicle is ever believed failed."""
    return np.zeros(len(ctx.pos), dtype=bool)


# ------------------------------------------------------------- guarding plug-in code
#: The kinds whose plug-ins run during a run (an obstacle type runs at load time).
RUNTIME_KINDS = ("law", "strategy", "failure", "reference", "filter", "detector")
#: The methods of a plug-in class that the loop calls.
_METHODS = {"law": "targets", "reference": "evaluate"}


def _non_finite(value: Any) -> bool:
    """Whether a plug-in's result holds a NaN or an infinity (numbers only)."""
    if isinstance(value, tuple | list):
        return any(_non_finite(v) for v in value)
    if isinstance(value, np.ndarray | float | int) and not isinstance(value, bool):
        array = np.asarray(value)
        return array.dtype.kind in "fc" and not bool(np.isfinite(array).all())
    return False


def _law_non_finite(out: Any, ctx: Any) -> bool:
    """Whether a law's targets hold a NaN or an infinity for a vehicle with a slot.

    A vehicle without a slot (a NaN offset: a reconfiguration left it none) may have
    NaN targets, as the built-in laws give it.
    """
    offset = np.asarray(getattr(ctx, "offset", None), dtype=float)
    if offset.ndim < 2 or not isinstance(out, tuple | list):
        return _non_finite(out)
    slotted = np.isfinite(offset).all(axis=-1)
    for part in out:
        try:
            rows = np.broadcast_to(np.asarray(part, dtype=float), offset.shape)
        except (TypeError, ValueError):
            return _non_finite(out)
        if not np.isfinite(rows[slotted]).all():
            return True
    return False


def _guard_call(
    func: Callable[..., Any],
    label: str,
    law: bool = False,
    returned: Returned | None = None,
) -> Callable[..., Any]:
    """``func`` guarded: what it raises or returns wrong ends its run, naming it.

    ``returned`` checks the type and shape of what it returns (see
    :mod:`sandbox.plugins.returns`; None: not checked, a class being built); ``law``
    allows NaN targets where a vehicle has no slot.
    """

    def guarded(*args: Any, **kwargs: Any) -> Any:
        try:
            out = func(*args, **kwargs)
        except PluginRunError:  # a guard inside this one named the plug-in already
            raise
        except (Exception, SystemExit) as exc:  # a user's code may raise anything
            raise PluginRunError(label, _raised(exc)) from None
        wrong = returned(out, args) if returned is not None and args else None
        if wrong:
            raise PluginRunError(label, wrong)
        bad = _law_non_finite(out, args[0]) if law and args else _non_finite(out)
        if bad:
            raise PluginRunError(label, "returned a NaN or an infinity")
        return out

    return guarded


class _GuardedInstance:
    """A plug-in class's instance whose method the loop calls, guarded.

    Its other attributes are the instance's, read and written through (a
    reconfiguration sets a law's ``delta``). A deep copy (a reconfiguration evaluates
    a copy of the law) guards the copy's own method.
    """

    _OWN = ("_inner", "_method", "_label", "_kind")

    def __init__(self, inner: Any, method: str, label: str, kind: str) -> None:
        for name, value in zip(self._OWN, (inner, method, label, kind), strict=True):
            object.__setattr__(self, name, value)
        law = kind == "law"  # NaN targets allowed where no slot is
        guarded = _guard_call(getattr(inner, method), label, law, RETURNS[kind])
        object.__setattr__(self, method, guarded)

    def __getattr__(self, name: str) -> Any:
        if name in self._OWN:  # not set yet: being built
            raise AttributeError(name)
        return getattr(self._inner, name)

    def __setattr__(self, name: str, value: Any) -> None:
        setattr(self._inner, name, value)

    def __deepcopy__(self, memo: dict) -> _GuardedInstance:
        import copy

        inner = copy.deepcopy(self._inner, memo)
        return _GuardedInstance(inner, self._method, self._label, self._kind)


def _raised(exc: BaseException) -> str:
    """``Type: message (file, line N)`` of the innermost frame that raised."""
    import traceback

    frames = traceback.extract_tb(exc.__traceback__)
    where = f" ({frames[-1].filename}, line {frames[-1].lineno})" if frames else ""
    text = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {text}{where}"


def _label(plugin: Plugin) -> str:
    return f"{KINDS[plugin.kind].title} {plugin.name} ({plugin.origin})"


def runnable(plugin: Plugin) -> Any:
    """The plug-in's object as the loop calls it: a user's code guarded.

    A built-in is returned as it is. A user's function (or, for a class, the
    instance's ``targets`` / ``evaluate``) is wrapped so that an exception it raises,
    ``SystemExit`` included, a value of the wrong type or shape for its kind
    (:data:`sandbox.plugins.returns.RETURNS`: None, a text, an ``(n, 3)`` array) or a
    NaN or infinity among the numbers it returns becomes a
    :class:`~sandbox.errors.PluginRunError` naming the plug-in: the run ends with
    status ``error`` instead of a traceback (or a silent ``ok``).
    """
    obj = plugin.obj
    if plugin.origin.startswith("built-in") or plugin.kind not in RUNTIME_KINDS:
        return obj
    label = _label(plugin)
    kind = plugin.kind
    if inspect.isclass(obj):
        method = _METHODS.get(kind)

        def build(*args: Any, **kwargs: Any) -> Any:
            made = _guard_call(obj, label)(*args, **kwargs)
            if method is None:
                return made
            return _GuardedInstance(made, method, label, kind)

        return build
    return _guard_call(obj, label, kind == "law", RETURNS[kind])


# ------------------------------------------------------------------ building plug-ins
class FunctionLaw:
    """A formation law registered as a function ``f(ctx) -> (slot, v_ref, a_ref)``."""

    def __init__(self, func: Callable[[LawContext], Any]) -> None:
        self.func = func

    def targets(self, ctx: LawContext) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Call the law; each result is broadcast to the fleet's shape (n, 2)."""
        shape = np.shape(ctx.offset)
        return tuple(
            np.broadcast_to(np.asarray(a, dtype=float), shape) for a in self.func(ctx)
        )


def make_law(name: str, params: Mapping[str, Any], delta: np.ndarray, h: float) -> Any:
    """Build the registered law ``name`` for offsets ``delta`` (n, 2) and period h.

    A class is built as ``cls(delta, h, **params)``; a function is wrapped in a
    :class:`FunctionLaw`. Either has ``targets(ctx: LawContext)``.
    """
    plugin = get("law", name)
    if inspect.isclass(plugin.obj):
        return runnable(plugin)(delta, h, **dict(params))
    law = FunctionLaw(runnable(plugin))  # a user's function: what it returns checked
    if plugin.origin.startswith("built-in"):
        return law
    return _GuardedInstance(law, "targets", _label(plugin), "law")  # its broadcast
