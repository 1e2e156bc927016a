"""Safety filters on the commands (the ``safety:`` section of a scenario).

A safety filter is a plug-in (:func:`sandbox.plugins.register_filter`) that sees the
commands the controller is about to apply and returns the ones to apply; the loop calls
it after the flatness controller and before the open-loop schedules, the step API's
command overrides and the failures. ``none`` (the default) is not called at all: runs
without a filter are the same bytes as before the section existed.

Built in: ``cbf`` (:mod:`sandbox.behaviour.safety.cbf`), a control-barrier-function
filter through the look-ahead point of each unicycle, solved per vehicle by the exact
planar quadratic program of :mod:`sandbox.behaviour.safety.qp`.
"""

from sandbox.behaviour.safety import cbf  # noqa: F401  (registers the filter)
