"""The modules that register the built-in plug-ins, by name.

The registry (:mod:`sandbox.plugins.registration`) imports these by name the first
time one of its tables is read, so that it never imports, at module level or lazily, a
module that registers into it. Registration order within a kind is the order here.
"""

#: The modules whose decorators register the built-in laws, detectors, failures,
#: obstacles, strategies, references and filters, and contributions to the metrics.
BUILTIN_MODULES: tuple[str, ...] = (
    "sandbox.model.laws",
    "sandbox.behaviour.detection",
    "sandbox.behaviour.glr",
    "sandbox.model.failures",
    "sandbox.model.obstacles",
    "sandbox.behaviour.recovery",
    "sandbox.model.references",
    "sandbox.behaviour.safety",
    "sandbox.model.potential",
    "sandbox.model.flocking",
    "sandbox.behaviour.safety.orca",
    "sandbox.run.goals",
)
