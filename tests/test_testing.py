"""``sandbox.testing``: assertions that say what happened, on real runs.

The runs come from the ``sandbox_run`` fixture of the plugin (cached for the session).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import PAPER

from sandbox.run.metrics import compute_metrics
from sandbox.testing import (
    assert_converged,
    assert_expectations,
    assert_formation_error,
    assert_min_distance,
    assert_no_collisions,
    check_scenario,
)

FIG12 = PAPER / "fig12_no_recovery.yaml"  # no recovery: red cuts past the leader
FIG14 = PAPER / "fig14_discontinuous_beta5.yaml"  # beta = 5: no contact
SHORT = ["duration=8"]


def test_a_collision_names_its_time_pair_and_kind(sandbox_run) -> None:
    run = sandbox_run(FIG12, set=SHORT)
    first = run.events[0]
    with pytest.raises(AssertionError) as err:
        assert_no_collisions(run)
    text = str(err.value)
    n = len(run.events)
    assert text.startswith(
        f"fig12_no_recovery: {n} collision{'s' if n > 1 else ''} among healthy "
        "vehicles (vehicle_vehicle, vehicle_obstacle): "
        f"t = {first.t:.2f} s {first.a}-{first.b} (vehicle_vehicle)"
    ), text
    with pytest.raises(AssertionError, match="among all vehicles"):
        assert_no_collisions(run, among="all", kinds="vehicle_vehicle")
    assert_no_collisions(run, kinds=["vehicle_obstacle"])  # none with an obstacle
    assert_no_collisions(sandbox_run(FIG14, set=SHORT))


def test_collisions_of_a_failed_vehicle_count_only_among_all(sandbox_run) -> None:
    run = sandbox_run(
        PAPER.parent / "failures" / "follower_stop.yaml",
        set=["recovery.strategy=none", "duration=8"],
    )
    assert run.events, "the healthy followers run into the stopped one"
    assert_no_collisions(run, among="healthy")
    with pytest.raises(AssertionError, match=r"among all vehicles .*\(vehicle_vehic"):
        assert_no_collisions(run, among="all")


def test_bad_arguments_are_errors_not_failures(sandbox_run) -> None:
    run = sandbox_run(FIG14, set=SHORT)
    with pytest.raises(ValueError, match="among: expected 'healthy' or 'all'"):
        assert_no_collisions(run, among="some")
    with pytest.raises(ValueError, match="kinds: expected one or more of"):
        assert_no_collisions(run, kinds=["vehicle_wall"])
    with pytest.raises(ValueError, match="vehicle: expected one of leader, red, green"):
        assert_formation_error(run, "blue", at_most=1)
    with pytest.raises(ValueError, match="after: 9 s is beyond the end of the run"):
        assert_formation_error(run, "red", at_most=1, after=9)


def test_converged_names_the_last_vehicle_and_its_time(sandbox_run) -> None:
    run = sandbox_run(FIG14, set=SHORT)
    assert_converged(run)
    times = {n: v["settling_time"] for n, v in compute_metrics(run)["vehicles"].items()}
    last = max(times, key=times.get)
    assert_converged(run, within=times[last])
    with pytest.raises(AssertionError) as err:
        assert_converged(run, within=times[last] - 0.5)
    assert str(err.value) == (
        f"fig14_discontinuous_beta5: converged at {times[last]:.2f} s ({last} settles "
        f"last, to settle_tol 0.05 m), later than within={times[last] - 0.5:g} s"
    )


@pytest.mark.slow
def test_not_converged_names_the_unsettled_vehicles(sandbox_run) -> None:
    run = sandbox_run(PAPER / "leader_ref_drift.yaml")
    with pytest.raises(
        AssertionError,
        match=r"not converged: red never settles "
        r"\(final error 0\.\d+ m, settle_tol 0\.05 m\); green never",
    ):
        assert_converged(run)


def test_min_distance_names_the_pair_and_time(sandbox_run) -> None:
    run = sandbox_run(FIG14, set=SHORT)
    pos = run.pose[:, :, :2]
    d = np.linalg.norm(pos[:, :, None] - pos[:, None, :], axis=-1)
    d[:, np.arange(3), np.arange(3)] = np.inf
    smallest = float(d.min())
    assert_min_distance(run, at_least=smallest)
    with pytest.raises(AssertionError) as err:
        assert_min_distance(run, at_least=smallest + 0.01)
    assert re.fullmatch(
        rf"fig14_discontinuous_beta5: min distance {smallest:.4g} m < "
        rf"{smallest + 0.01:g} m: \w+-\w+ at t = \d+\.\d\d s",
        str(err.value),
    ), str(err.value)


@pytest.mark.slow
def test_formation_error_names_the_vehicle_its_error_and_when(sandbox_run) -> None:
    run = sandbox_run(PAPER / "rotating_circle.yaml")
    # eq. (12): the red follower's steady error is 5.657 cm; the start-up is larger.
    assert_formation_error(run, "red", at_most=0.0571, after=8.0)
    e = run.formation_error[:, 1]
    k = int(np.argmax(e))
    with pytest.raises(AssertionError) as err:
        assert_formation_error(run, "red", at_most=0.0571)
    assert str(err.value) == (
        f"rotating_circle: red: formation error {e[k]:.4g} m at t = {run.t[k]:.2f} s "
        f"exceeds 0.0571 m (final {e[-1]:.4g} m)"
    )
    with pytest.raises(AssertionError, match=r"after 8 s \(final 0\.056"):
        assert_formation_error(run, "red", at_most=0.05, after=8.0)


def test_the_fixture_caches_runs_for_identical_arguments(sandbox_run) -> None:
    a = sandbox_run(FIG14, set=SHORT)
    assert sandbox_run(str(FIG14), set=list(SHORT)) is a
    assert sandbox_run(FIG14, set=["duration=4"]) is not a
    with pytest.raises(ValueError, match="read-only"):
        a.pose[0, 0, 0] = 1.0  # shared by every test: it cannot be changed


@pytest.mark.slow
def test_a_scenarios_own_expectations(sandbox_run, tmp_path) -> None:
    assert_expectations(sandbox_run(PAPER / "rotating_circle.yaml"))
    short = sandbox_run(PAPER / "stabilization.yaml", set=["duration=0.5"])
    with pytest.raises(
        AssertionError,
        match=r"stabilization\.yaml: converged: "
        r"expected true, got false \(blue never settles",
    ):
        assert_expectations(short)
    plain = tmp_path / "plain.yaml"
    plain.write_text(
        "reference: {type: point, position: [0, 0]}\n"
        "vehicles: [{pose: [1, 0, 0]}]\nduration: 0.1\n",
        "utf-8",
    )
    with pytest.raises(ValueError, match="has no expect: section"):
        assert_expectations(sandbox_run(plain))


def test_check_scenario_returns_the_outcomes_and_the_run() -> None:
    result = check_scenario(PAPER / "stabilization.yaml", ["duration=0.5"])
    assert not result.holds and result.run is not None
    assert [o.key for o in result.failed] == [
        "converged",
        "settling_time",
        "formation_error.blue.final",
    ]
    assert all(
        line.startswith(f"{PAPER / 'stabilization.yaml'}: ") for line in result.lines()
    )
