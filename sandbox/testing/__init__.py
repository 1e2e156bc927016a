"""Assertions on runs for users' tests, and the pytest plugin.

Each ``assert_*`` function raises :class:`AssertionError` with a message that says what
happened (the first collision events with their time, pair and kind; the vehicle, its
error and when), so a failing test explains itself without a debugger::

    from sandbox import load_scenario, simulate
    from sandbox.testing import assert_converged, assert_no_collisions

    run = simulate(load_scenario("paper/fig14_discontinuous_beta5"))
    assert_no_collisions(run)            # no contact among healthy vehicles
    assert_converged(run, within=8.0)    # every healthy vehicle settled by 8 s

:func:`check_scenario` runs a file and evaluates its ``expect:`` section; it is what
``sandbox check`` and the pytest plugin (:mod:`sandbox.testing.pytest_plugin`) call.
"""

from sandbox.testing.assertions import (
    CheckResult,
    assert_converged,
    assert_expectations,
    assert_formation_error,
    assert_min_distance,
    assert_no_collisions,
    assert_platoon,
    check_scenario,
    load_checked,
)

__all__ = [
    "CheckResult",
    "assert_converged",
    "assert_expectations",
    "assert_formation_error",
    "assert_min_distance",
    "assert_no_collisions",
    "assert_platoon",
    "check_scenario",
    "load_checked",
]
