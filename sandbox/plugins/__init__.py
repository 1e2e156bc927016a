"""Plug-ins: formation laws, recovery strategies, failures, references, obstacles, ...

Everything a scenario selects by name is a plug-in registered here, the built-ins
included: :mod:`sandbox.model.laws` registers the five laws,
:mod:`sandbox.behaviour.recovery` the four strategies, :mod:`sandbox.model.failures`
the five failure kinds, :mod:`sandbox.model.references` the five reference types and
:mod:`sandbox.model.obstacles` the four obstacle types, all with the same public
decorators a user's file calls::

    from sandbox.plugins import register_strategy

    @register_strategy("push_apart", params={"gain": 1.0})
    def push_apart(ctx):
        i, j, dist = ctx.pairs(1.0)
        ...
        return shift, active

Each registration declares its YAML parameters once (:class:`Param`: type or default,
unit, bounds, a one-line doc). From that declaration the loader reads and validates the
keys (unknown key with did-you-mean, type, bounds, the line of the field), the JSON
Schema describes them, and ``sandbox plugins`` lists them.

Plug-ins are imported from the ``plugins:`` list of a scenario (files relative to it,
or module names), from ``--plugin PATH_OR_MODULE`` on the command line, and from the
entry-point group ``sandbox.plugins`` of installed packages (:func:`load_plugin`,
:func:`load_entry_points`). The contexts passed to plug-ins are documented in the
README's "Plug-ins" section.
"""

from sandbox.plugins.contexts import (
    DetectorContext,
    FailureContext,
    FilterContext,
    LawContext,
    ObstacleContext,
    ReferenceContext,
    StrategyContext,
)
from sandbox.plugins.loading import (
    is_loaded,
    load_entry_points,
    load_plugin,
    load_plugins,
    looks_like_file,
    resolve_file,
)
from sandbox.plugins.registration import (
    ENTRY_POINT_GROUP,
    KINDS,
    REQUIRED,
    Param,
    Plugin,
    PluginError,
    RegistryView,
    all_params,
    get,
    make_law,
    metric_contributions,
    names,
    register,
    register_detector,
    register_failure,
    register_filter,
    register_law,
    register_metrics,
    register_obstacle,
    register_reference,
    register_strategy,
    registry,
    runnable,
    unregister,
)

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
    "RegistryView",
    "StrategyContext",
    "all_params",
    "get",
    "is_loaded",
    "load_entry_points",
    "load_plugin",
    "load_plugins",
    "looks_like_file",
    "make_law",
    "metric_contributions",
    "names",
    "register",
    "register_detector",
    "register_failure",
    "register_filter",
    "register_law",
    "register_metrics",
    "register_obstacle",
    "register_reference",
    "register_strategy",
    "registry",
    "resolve_file",
    "runnable",
    "unregister",
]
