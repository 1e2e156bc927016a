"""The assertions of :mod:`sandbox.testing` and the check of a scenario's ``expect:``.

Each ``assert_*`` function raises :class:`AssertionError` with a message that says what
happened (the first collision events with their time, pair and kind; the vehicle, its
error and when). :func:`check_scenario` runs a file and evaluates its ``expect:``
section (:mod:`sandbox.run.expectations`); ``sandbox check`` and the pytest plugin
(:mod:`sandbox.testing.pytest_plugin`) call it. The public names and an example are in
:mod:`sandbox.testing`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sandbox.errors import Problem, ScenarioError
from sandbox.run.expectations import Outcome, closest_approach, evaluate
from sandbox.run.metrics import compute_metrics, healthy_events
from sandbox.run.record import Run

__all__ = [
    "CheckResult",
    "assert_converged",
    "assert_expectations",
    "assert_formation_error",
    "assert_min_distance",
    "assert_no_collisions",
    "assert_platoon",
    "check_scenario",
]

#: Collision kinds of :class:`sandbox.run.record.CollisionEvent`.
KINDS = ("vehicle_vehicle", "vehicle_obstacle")
#: Events named in a message before "... and N more".
SHOWN = 3


def _label(run: Run) -> str:
    return run.scenario.name if run.scenario is not None else "run"


def _kinds(kinds: str | Iterable[str]) -> tuple[str, ...]:
    chosen = (kinds,) if isinstance(kinds, str) else tuple(kinds)
    bad = [k for k in chosen if k not in KINDS]
    if bad or not chosen:
        raise ValueError(
            f"kinds: expected one or more of {', '.join(KINDS)}, got {kinds!r}"
        )
    return chosen


def assert_no_collisions(
    run: Run, among: str = "healthy", kinds: str | Iterable[str] = KINDS
) -> None:
    """Assert that the run has no collision of the given kinds.

    Parameters
    ----------
    run : Run
    among : {"healthy", "all"}
        ``healthy``: only contacts in which no vehicle had an active failure count
        (what recovery is meant to prevent); ``all``: every contact.
    kinds : str or iterable of str
        ``vehicle_vehicle`` and/or ``vehicle_obstacle`` (default both).

    Raises
    ------
    AssertionError
        Naming the number of collisions and the first ones (time, pair, kind).
    ValueError
        An unknown ``among`` or kind.
    """
    __tracebackhide__ = True  # pytest shows the caller's line, not this one
    if among not in ("healthy", "all"):
        raise ValueError(f"among: expected 'healthy' or 'all', got {among!r}")
    chosen = _kinds(kinds)
    healthy = healthy_events(run)
    found = [
        e
        for e, h in zip(run.events, healthy, strict=True)
        if e.kind in chosen and (h or among == "all")
    ]
    if not found:
        return
    first = "; ".join(f"t = {e.t:.2f} s {e.a}-{e.b} ({e.kind})" for e in found[:SHOWN])
    more = f"; and {len(found) - SHOWN} more" if len(found) > SHOWN else ""
    who = "healthy vehicles" if among == "healthy" else "all vehicles"
    s = "s" if len(found) != 1 else ""
    raise AssertionError(
        f"{_label(run)}: {len(found)} collision{s} among {who} "
        f"({', '.join(chosen)}): {first}{more}"
    )


def assert_platoon(
    run: Run,
    name: str,
    *,
    converged: bool | None = None,
    within: float | None = None,
    inter_platoon: int | None = None,
    intra_platoon: int | None = None,
) -> None:
    """Assert what ``metrics.json`` says of one platoon (a run with ``platoons:``).

    Parameters
    ----------
    run : Run
    name : str
        The platoon's name.
    converged : bool, optional
        Whether every healthy vehicle of the platoon must settle (or not).
    within : float, optional [s]
        Latest settling time allowed for the platoon's healthy vehicles.
    inter_platoon, intra_platoon : int, optional
        Largest number of contacts of the platoon's vehicles with another platoon's,
        and among themselves.

    Raises
    ------
    AssertionError
        Naming the platoon, the quantity, what was expected and what was measured.
    KeyError
        An unknown platoon (or a run without ``platoons:``).
    """
    __tracebackhide__ = True
    entry = compute_metrics(run).get("platoons", {})
    if name not in entry:
        raise KeyError(f"no platoon {name!r} in {_label(run)}: {', '.join(entry)}")
    got = entry[name]
    problems = []
    if converged is not None and got["converged"] is not converged:
        problems.append(f"converged {got['converged']}, expected {converged}")
    st = got["settling_time"]
    if within is not None and (st is None or st > within):
        problems.append(
            f"settling time {'never' if st is None else f'{st:.2f} s'}, expected at "
            f"most {within:g} s"
        )
    for key, bound in (
        ("inter_platoon", inter_platoon),
        ("intra_platoon", intra_platoon),
    ):
        if bound is not None and got["collisions"][key] > bound:
            problems.append(
                f"{got['collisions'][key]} {key} contacts, expected at most {bound}"
            )
    if problems:
        raise AssertionError(f"{_label(run)}: platoon {name}: {'; '.join(problems)}")


def assert_converged(run: Run, within: float | None = None) -> None:
    """Assert that every healthy vehicle settles (``converged`` of ``metrics.json``).

    Parameters
    ----------
    run : Run
    within : float, optional [s]
        Also require the latest settling time of the healthy vehicles to be at most
        this. Settling uses the scenario's ``metrics.settle_tol``.

    Raises
    ------
    AssertionError
        Naming the vehicles that never settle (with their final error) or the one
        that settles last (with its settling time).
    """
    __tracebackhide__ = True  # pytest shows the caller's line, not this one
    m = compute_metrics(run)
    tol = m["settle_tol"]
    healthy = [
        (name, m["vehicles"][name])
        for k, name in enumerate(run.names)
        if m["vehicles"][name]["formation_error"]["final"] is not None
        and not (len(run.t) and run.failed[-1, k])
    ]
    if not healthy:
        raise AssertionError(f"{_label(run)}: no healthy vehicle with a slot to settle")
    never = [(n, v) for n, v in healthy if v["settling_time"] is None]
    if never:
        what = "; ".join(
            f"{n} never settles (final error {v['formation_error']['final']:.4g} m, "
            f"settle_tol {tol:g} m)"
            for n, v in never
        )
        raise AssertionError(f"{_label(run)}: not converged: {what}")
    name, last = max(healthy, key=lambda item: item[1]["settling_time"])
    if within is not None and last["settling_time"] > within:
        raise AssertionError(
            f"{_label(run)}: converged at {last['settling_time']:.2f} s ({name} "
            f"settles last, to settle_tol {tol:g} m), later than within={within:g} s"
        )


def assert_min_distance(run: Run, at_least: float) -> None:
    """Assert that no two vehicles come closer than ``at_least`` [m] (centre distance).

    Raises
    ------
    AssertionError
        Naming the smallest distance, the pair and the time; or the run has fewer than
        two vehicles.
    """
    __tracebackhide__ = True  # pytest shows the caller's line, not this one
    closest = closest_approach(run)
    if closest is None:
        raise AssertionError(f"{_label(run)}: fewer than two vehicles, no distance")
    d, t, a, b = closest
    if d < at_least:
        raise AssertionError(
            f"{_label(run)}: min distance {d:.4g} m < {at_least:g} m: {a}-{b} at "
            f"t = {t:.2f} s"
        )


def assert_formation_error(
    run: Run, vehicle: str, at_most: float, after: float | None = None
) -> None:
    """Assert that a vehicle's formation error stays at most ``at_most`` [m].

    Parameters
    ----------
    run : Run
    vehicle : str
        The vehicle's name.
    at_most : float [m]
    after : float, optional [s]
        Only the samples at ``t >= after`` count (default: the whole run).

    Raises
    ------
    AssertionError
        Naming the vehicle, its largest error and when, and its final error.
    ValueError
        An unknown vehicle, or ``after`` beyond the end of the run.
    """
    __tracebackhide__ = True  # pytest shows the caller's line, not this one
    if vehicle not in run.names:
        raise ValueError(
            f"vehicle: expected one of {', '.join(run.names)}, got {vehicle!r}"
        )
    k = run.names.index(vehicle)
    t = np.asarray(run.t)
    mask = np.ones(len(t), bool) if after is None else t >= after
    if not mask.any():
        end = f"{t[-1]:.2f}" if len(t) else "0"
        raise ValueError(f"after: {after:g} s is beyond the end of the run ({end} s)")
    error = np.asarray(run.formation_error[:, k])
    if not np.all(np.isfinite(error[mask])):
        raise AssertionError(
            f"{_label(run)}: {vehicle} has no slot (no formation error)"
        )
    worst = int(np.argmax(np.where(mask, error, -np.inf)))
    if error[worst] > at_most:
        since = "" if after is None else f" after {after:g} s"
        raise AssertionError(
            f"{_label(run)}: {vehicle}: formation error {error[worst]:.4g} m at "
            f"t = {t[worst]:.2f} s exceeds {at_most:g} m{since} (final "
            f"{error[-1]:.4g} m)"
        )


def assert_expectations(run: Run) -> None:
    """Assert that the run meets its scenario's ``expect:`` section.

    Raises
    ------
    AssertionError
        With one ``sandbox check`` line per failed expectation.
    ValueError
        The scenario has no expectations.
    """
    __tracebackhide__ = True  # pytest shows the caller's line, not this one
    expect = getattr(run.scenario, "expect", None)
    if expect is None:
        raise ValueError(f"{_label(run)}: the scenario has no expect: section")
    failed = [o for o in evaluate(expect, run) if not o.holds]
    if failed:
        source = run.scenario.source or run.scenario.name
        raise AssertionError("\n".join(o.line(source) for o in failed))


@dataclass
class CheckResult:
    """The expectations of one scenario file evaluated on its run.

    Attributes
    ----------
    source : str
        The file, as given.
    outcomes : list of Outcome
        One per expectation (the status first).
    run : Run or None
        The run (None when it was not kept, e.g. from a worker process).
    """

    source: str
    outcomes: list[Outcome] = field(default_factory=list)
    run: Run | None = None

    @property
    def failed(self) -> list[Outcome]:
        """The expectations that do not hold."""
        return [o for o in self.outcomes if not o.holds]

    @property
    def holds(self) -> bool:
        """Whether every expectation holds."""
        return not self.failed

    def lines(self) -> list[str]:
        """One ``sandbox check`` line per failed expectation."""
        return [o.line(self.source) for o in self.failed]


def load_checked(
    path: str | Path,
    overrides: Sequence[str] = (),
    trust_plugins: bool | None = None,
) -> Any:
    """Load a scenario that must have expectations (a ``ScenarioError`` if not)."""
    from sandbox.scenario import load_scenario

    scenario = load_scenario(
        path, overrides=list(overrides), trust_plugins=trust_plugins
    )
    if scenario.expect is None:
        raise ScenarioError(
            [
                Problem(
                    "expect",
                    "no expectations to check (got nothing; expected an expect: "
                    "section, see scenarios/reference.yaml)",
                )
            ],
            str(path),
        )
    return scenario


def check_scenario(
    path: str | Path,
    overrides: Sequence[str] = (),
    keep_run: bool = True,
    trust_plugins: bool | None = None,
) -> CheckResult:
    """Run a scenario file and evaluate its ``expect:`` section.

    Parameters
    ----------
    path : str or Path
        A scenario file with an ``expect:`` section.
    overrides : sequence of str
        ``path=value`` assignments, as ``--set``.
    keep_run : bool
        Keep the run in the result (False saves memory and pickling).
    trust_plugins : bool, optional
        Run the code of the plug-ins the file lists (see
        :func:`sandbox.load_scenario`); default ``SANDBOX_TRUST_PLUGINS``.

    Raises
    ------
    ScenarioError
        The file is invalid, or has no expectations.
    """
    from sandbox.loop.simulation import simulate

    scenario = load_checked(path, overrides, trust_plugins)
    run = simulate(scenario)
    outcomes = evaluate(scenario.expect, run, compute_metrics(run))
    return CheckResult(str(path), outcomes, run if keep_run else None)
