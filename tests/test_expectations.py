"""The ``expect:`` section: its grammar, its validation, and its evaluation on runs."""

from __future__ import annotations

import json
import math
import re
from functools import cache

import jsonschema
import pytest
from helpers import HEADON, PAPER

from sandbox import compute_metrics, load_scenario, simulate
from sandbox.errors import SandboxWarning, ScenarioError
from sandbox.run.expectations import closest_approach, evaluate
from sandbox.scenario.expectations import Bound, Expectations
from sandbox.scenario.schema import build_schema

FULL = {
    "status": "ok",
    "collisions": {"healthy": 0, "total": {"at_most": 3}, "vehicle_obstacle": 0},
    "converged": True,
    "min_distance": {"at_least": "0.9d"},
    "settling_time": {"at_most": 8, "red": {"at_most": 5, "at_least": 1}},
    "formation_error": {
        "red": {"rms_last_quarter": {"at_most": 0.06}, "final": {"at_most": 0.1}},
        "green": {"max": {"at_least": 1}},
    },
}


def doc_with(expect: object, base: str = "rotating_circle.yaml") -> dict:
    import yaml

    doc = yaml.safe_load((PAPER / base).read_text(encoding="utf-8"))
    doc["expect"] = expect
    return doc


@cache
def headon():
    run = simulate(load_scenario(HEADON))
    return run, compute_metrics(run)


# ---------------------------------------------------------------------------- grammar
def test_the_full_grammar_is_read() -> None:
    ex = load_scenario(doc_with(FULL)).expect
    assert ex.status == "ok"
    assert dict(ex.collisions) == {
        "healthy": Bound(0, 0),
        "total": Bound(None, 3),
        "vehicle_obstacle": Bound(0, 0),
    }
    assert ex.converged is True
    assert ex.min_distance == Bound(0.45, None)  # 0.9 d with d = 0.5 m
    assert ex.settling_time == Bound(None, 8.0)
    assert ex.settling_times == (("red", Bound(1.0, 5.0)),)
    assert set(ex.formation_error) == {
        ("red", "rms_last_quarter", Bound(None, 0.06)),
        ("red", "final", Bound(None, 0.1)),
        ("green", "max", Bound(1.0, None)),
    }


def test_no_section_or_an_empty_one_means_no_expectations() -> None:
    assert load_scenario(doc_with(None)).expect is None
    assert load_scenario(doc_with({})).expect is None


def test_the_resolved_scenario_keeps_its_expectations() -> None:
    sc = load_scenario(doc_with(FULL))
    doc = json.loads(json.dumps(sc.to_dict()))
    assert load_scenario(doc).expect == sc.expect
    assert doc["expect"]["collisions"]["healthy"] == 0  # an exact count stays a count
    jsonschema.validate(doc, build_schema())


def test_the_schema_accepts_the_grammar_and_rejects_what_the_loader_rejects() -> None:
    validator = jsonschema.Draft202012Validator(build_schema())
    assert list(validator.iter_errors(doc_with(FULL))) == []
    for bad in (
        {"colisions": {"healthy": 0}},
        {"collisions": {"healthy": -1}},
        {"min_distance": 0.45},
        {"formation_error": {"red": {"rms": {"at_most": 1}}}},
        {"settling_time": {"red": 3}},
        {"status": "fine"},
    ):
        assert list(validator.iter_errors(doc_with(bad))), bad
        with pytest.raises(ScenarioError):
            load_scenario(doc_with(bad))


@pytest.mark.parametrize(
    ("expect", "message"),
    [
        (
            {"colisions": {"healthy": 0}},
            "expect.colisions: unknown key; did you mean 'collisions'?",
        ),
        ({"collisions": {"heathy": 0}}, "did you mean 'healthy'?"),
        ({"collisions": {"total": 1.5}}, "expect.collisions.total: not a count"),
        ({"collisions": {"total": {"at_most": -1}}}, "total.at_most: not a count"),
        ({"converged": "yes"}, "expect.converged: not a boolean"),
        ({"status": "fine"}, "expect.status: unknown status"),
        ({"min_distance": 0.45}, "expect.min_distance: not a bound (got 0.45"),
        ({"min_distance": {}}, "expect.min_distance: no bound given"),
        (
            {"min_distance": {"at_least": 2, "at_most": 1}},
            "expect.min_distance: empty range (got at_least 2 > at_most 1",
        ),
        ({"min_distance": {"at_least": -1}}, "min_distance.at_least: must be at"),
        ({"settling_time": {"at_mots": 3}}, "did you mean 'at_most'?"),
        ({"settling_time": {}}, "expect.settling_time: empty"),
        (
            {"settling_time": {"gren": {"at_most": 3}}},
            "expect.settling_time.gren: unknown key; did you mean 'green'?",
        ),
        (
            {"formation_error": {"blue": {"final": {"at_most": 1}}}},
            "expect.formation_error.blue: no such vehicle",
        ),
        (
            {"formation_error": {"red": {"mean": {"at_most": 1}}}},
            "expect.formation_error.red.mean: unknown key",
        ),
        ({"formation_error": {"red": {"final": 0.1}}}, "red.final: not a bound"),
        # v0.2 accepted it and `sandbox check` then crashed
        ({"collisions": {"total": 10**400}}, "total: too large a count (got a number"),
        ({"deadlocks": {"at_most": 10**10}}, "deadlocks.at_most: too large a count"),
    ],
)
def test_bad_expectations_are_reported(expect: object, message: str) -> None:
    with pytest.raises(ScenarioError) as err:
        load_scenario(doc_with(expect))
    assert any(message in line for line in err.value.lines), err.value.lines


def test_set_reaches_into_the_section() -> None:
    sc = load_scenario(
        PAPER / "rotating_circle.yaml",
        overrides=[
            "expect.converged=false",
            "expect.collisions.vehicle_vehicle={at_least: 1}",
            "expect.formation_error.green.final.at_most=0.2",
            "expect.settling_time.red.at_most=4",
        ],
    )
    assert sc.expect.converged is False
    assert ("vehicle_vehicle", Bound(1, None)) in sc.expect.collisions
    assert ("green", "final", Bound(None, 0.2)) in sc.expect.formation_error
    assert ("red", Bound(None, 4.0)) in sc.expect.settling_times
    with pytest.raises(ScenarioError, match=re.escape("did you mean 'converged'?")):
        load_scenario(PAPER / "rotating_circle.yaml", overrides=["expect.convrged=1"])


def test_bounds_are_inclusive_and_read_as_words() -> None:
    assert Bound(0, 0).holds(0) and not Bound(0, 0).holds(1)
    assert Bound(None, 8).holds(8.0) and not Bound(None, 8).holds(8.01)
    assert Bound(0.45).holds(0.45) and not Bound(0.45).holds(0.4499)
    assert not Bound(None, 8).holds(None)  # an unmeasured value never holds
    assert not Bound(None, 8).holds(math.nan)
    assert Bound(1, 3).text() == "from 1 to 3"
    assert Bound(None, 0.06).text("m") == "at most 0.06 m"
    assert Bound(2, 2).text() == "2"


# ------------------------------------------------------------------------- evaluation
def test_a_collision_is_reported_with_its_pair_and_time() -> None:
    run, metrics = headon()
    ex = Expectations(collisions=(("healthy", Bound(0, 0)), ("total", Bound(1, 1))))
    status, healthy, total = evaluate(ex, run, metrics)
    assert (
        status.holds and status.line("h.yaml") == "h.yaml: status: expected ok, got ok"
    )
    assert not healthy.holds
    assert re.fullmatch(
        r"h\.yaml: collisions\.healthy: expected 0, got 1 \(east-west at 0\.7\d s\)",
        healthy.line("h.yaml"),
    ), healthy.line("h.yaml")
    assert total.holds


def test_min_distance_names_the_closest_pair_and_when() -> None:
    run, metrics = headon()
    d, t, a, b = closest_approach(run)
    assert d == pytest.approx(metrics["min_distance"])  # the metric's own minimum
    assert (a, b) == ("east", "west") and t > 0.75
    (_, out) = evaluate(Expectations(min_distance=Bound(0.6)), run, metrics)
    assert not out.holds
    assert out.got == f"{d:.4g} m (east-west at {t:.2f} s)"
    assert out.expected == "at least 0.6 m"


def test_unsettled_vehicles_are_named_with_their_error() -> None:
    # Parking from 2.5 m away takes about 1.5 s: after 0.5 s the vehicle is still far.
    sc = load_scenario(PAPER / "stabilization.yaml", overrides=["duration=0.5"])
    run = simulate(sc)
    metrics = compute_metrics(run)
    final = metrics["vehicles"]["blue"]["formation_error"]["final"]
    ex = Expectations(
        converged=True,
        settling_time=Bound(None, 2.0),
        settling_times=(("blue", Bound(None, 2.0)),),
        formation_error=(("blue", "final", Bound(None, 0.001)),),
    )
    _, conv, worst, own, error = evaluate(ex, run, metrics)
    why = f"blue never settles: final error {final:.4g} m, settle_tol 0.05 m"
    assert (conv.holds, conv.got) == (False, f"false ({why})")
    assert (worst.holds, worst.got) == (False, f"never ({why})")
    assert own.key == "settling_time.blue" and not own.holds
    assert error.line("s.yaml") == (
        "s.yaml: formation_error.blue.final: expected at most 0.001 m, "
        f"got {final:.4g} m"
    )


def test_a_diverged_run_fails_its_status() -> None:
    run, metrics = headon()
    diverged = dict(
        metrics,
        status="diverged",
        diverged={"t": 0.42, "vehicle": "east", "reason": "speed beyond 1e3 m/s"},
    )
    (status,) = evaluate(Expectations(), run, diverged)
    assert not status.holds
    assert status.got == "diverged (at 0.42 s, vehicle east: speed beyond 1e3 m/s)"
    assert evaluate(Expectations(status="diverged"), run, diverged)[0].holds


def test_null_means_not_given_for_the_loader_and_the_schema() -> None:
    validator = jsonschema.Draft202012Validator(build_schema())
    expect = {
        "collisions": {"total": None, "healthy": 0},
        "converged": None,
        "min_distance": None,
        "settling_time": {"red": None, "at_most": None, "green": {"at_most": 3}},
        "formation_error": {"red": None, "green": {"final": None}},
    }
    doc = doc_with(expect)
    assert list(validator.iter_errors(doc)) == []
    ex = load_scenario(doc).expect
    assert ex == Expectations(
        collisions=(("healthy", Bound(0, 0)),),
        settling_times=(("green", Bound(None, 3.0)),),
    )


@pytest.mark.parametrize(
    "expect",
    [
        {"collisions": {"healthy": {"at_least": 0}}},
        {"min_distance": {"at_least": 0}},
        {"min_distance": {"at_most": 1e6}},
        {"settling_time": {"red": {"at_least": 0, "at_most": 1e7}}},
    ],
)
def test_an_expectation_that_cannot_fail_is_warned_of(expect: dict) -> None:
    with pytest.warns(SandboxWarning, match="this expectation cannot fail"):
        scenario = load_scenario(doc_with(expect))
    assert any("cannot fail" in w for w in scenario.warnings), scenario.warnings


def test_an_expectation_that_can_fail_is_not_warned_of() -> None:
    assert not any("cannot fail" in w for w in load_scenario(doc_with(FULL)).warnings)
