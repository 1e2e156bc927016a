"""A sweep's base parsed once per grid point (``engine.Parses``): the same scenarios.

Runs that differ only in ``seed=N`` take the first run's scenario with their seed
where the seed changes nothing else; a ``randomize:`` section, a jittered platoon or
another override parse every run, as ``sandbox run`` does.
"""

from __future__ import annotations

import json

import pytest
from test_sweep import base_doc

from sandbox.scenario import parse_scenario
from sandbox.study import engine


def fixed_doc() -> dict:
    """The sweep tests' form-up without its ``randomize:`` section."""
    doc = base_doc(duration=0.5)
    del doc["randomize"]
    return doc


def platoon_doc() -> dict:
    """A leader and a jittered platoon of three: the seed moves the platoon's starts."""
    doc = fixed_doc()
    doc["vehicles"] = doc["vehicles"][:1]
    doc["platoon"] = {"count": 3, "pattern": "line", "spacing": "4d", "jitter": 0.2}
    return doc


def parsed(doc: dict, overrides: list[str]):
    return parse_scenario(doc, source="base.yaml", overrides=overrides)


def scenarios(doc: dict, runs: list[list[str]]) -> tuple[list, engine.Parses]:
    parses = engine.Parses()
    sims = [parses.scenario(doc, "base.yaml", o) for o in runs]
    return sims, parses


def test_runs_differing_in_their_seed_share_one_parse():
    doc = fixed_doc()
    runs = [["recovery.beta=4", f"seed={s}"] for s in range(6)]
    got, parses = scenarios(doc, runs)
    # the first run parsed, the second parsed to check it, the other four shared
    assert (parses.parses, parses.shared) == (2, 4)
    for sc, overrides in zip(got, runs, strict=True):
        assert sc == parsed(doc, overrides)
    assert [sc.seed for sc in got] == list(range(6))
    assert got[3].recovery.beta == 4.0


def test_each_grid_point_is_parsed_apart():
    doc = fixed_doc()
    runs = [[f"recovery.beta={b}", f"seed={s}"] for b in (1, 4) for s in range(3)]
    got, parses = scenarios(doc, runs)
    assert (parses.parses, parses.shared) == (4, 2)
    assert [sc.recovery.beta for sc in got] == [1.0] * 3 + [4.0] * 3
    for sc, overrides in zip(got, runs, strict=True):
        assert sc == parsed(doc, overrides)


@pytest.mark.parametrize(
    ("doc", "runs"),
    [
        (base_doc(duration=0.5), [[f"seed={s}"] for s in range(4)]),  # randomize
        (platoon_doc(), [[f"seed={s}"] for s in range(4)]),  # jitter from the seed
        (fixed_doc(), [[f"seed={s}", "recovery.beta=2"] for s in range(4)]),
        (fixed_doc(), [["seed=5", f"seed={s}"] for s in range(4)]),
        (fixed_doc(), [[f"seed={s}"] for s in ("1", "01", "1.0", "-1")]),
    ],
    ids=["randomize", "platoon", "seed-not-last", "seed-twice", "odd-seeds"],
)
def test_runs_the_seed_may_change_are_each_parsed(doc, runs):
    parses = engine.Parses()
    for overrides in runs:
        sim = parses.scenario(doc, "base.yaml", overrides)
        if isinstance(sim, dict):  # "-1": invalid, as sandbox run says
            assert sim == engine.run_task(doc, "base.yaml", overrides)
            continue
        assert sim == parsed(doc, overrides)
    assert parses.shared == 0


def test_randomized_and_jittered_runs_differ_per_seed():
    for doc in (base_doc(duration=0.5), platoon_doc()):
        got, _ = scenarios(doc, [[f"seed={s}"] for s in range(3)])
        poses = {json.dumps([v.pose for v in sc.vehicles]) for sc in got}
        assert len(poses) == 3


def test_a_derived_scenario_that_disagrees_stops_the_sharing(monkeypatch):
    # Claim that the seed changes nothing in a jittered platoon: the second run's own
    # parse disagrees, so every run is parsed and each has its own jitter.
    monkeypatch.setattr(engine, "_seed_free", lambda scenario: True)
    doc = platoon_doc()
    runs = [[f"seed={s}"] for s in range(4)]
    got, parses = scenarios(doc, runs)
    assert (parses.parses, parses.shared) == (4, 0)
    for sc, overrides in zip(got, runs, strict=True):
        assert sc == parsed(doc, overrides)


def test_a_group_of_shared_parses_gives_the_bytes_of_single_runs():
    doc = fixed_doc()
    jobs = [(str(s), (doc, "base.yaml", [f"seed={s}"])) for s in range(4)]
    got = dict(engine.run_tasks(jobs))
    for run_id, job in jobs:
        assert got[run_id]["row"]["status"] == "ok"
        assert json.dumps(got[run_id]) == json.dumps(engine.run_task(*job))
