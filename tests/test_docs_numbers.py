"""Numbers of the docs checked against the runs they come from.

Each test re-runs what a sentence or a cell of ``docs/`` claims (where that is cheap)
and checks both the run and the text, so that a number that goes stale fails here.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import REPO, SCENARIOS

from sandbox import Simulation, compute_metrics, load_scenario

DOCS = REPO / "docs"


def sensing_platoon(seed: int) -> dict:
    """Two vehicles with range sensors on a line past a post, jittered by ``seed``."""
    return {
        "name": "sensing",
        "duration": 1.0,
        "seed": seed,
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1.0},
        "formation": {"law": "rotating"},
        "recovery": {"strategy": "continuous", "obstacles": "sensed"},
        "sensors": {"range": {"beams": 8, "max_range": 3.0, "noise": 0.01}},
        "obstacles": [
            {"type": "circle", "name": "post", "center": [1.5, 0.6], "radius": 0.3}
        ],
        "vehicles": [
            {"name": "lead", "pose": [0, 0, 0], "leader": True},
            {"name": "tail", "pose": [-2, 0, 0], "offset": [-2, 0]},
        ],
        "randomize": {"vehicles[1].pose[1]": {"uniform": [-0.2, 0.2]}},
    }


@pytest.mark.slow
def test_scenarios_with_sensors_are_batched_each_world_as_alone() -> None:
    scenarios = [load_scenario(sensing_platoon(seed)) for seed in (1, 2, 3)]
    batched = Simulation.batch(scenarios)
    for scenario, run in zip(scenarios, batched, strict=True):
        alone = Simulation(scenario).run()
        assert run.ranges is not None and np.isfinite(run.ranges).any()
        np.testing.assert_array_equal(run.ranges, alone.ranges)
        np.testing.assert_array_equal(run.pose, alone.pose)
    assert not np.array_equal(batched[0].ranges, batched[1].ranges)  # noise, starts
    text = (DOCS / "concepts" / "sensors.md").read_text()
    assert "Scenarios with sensors are batched like any other" in text
    assert "refuses" not in text


@pytest.mark.parametrize(
    ("pass_right", "closest", "final"),
    [(None, "1.670", "0.0000, 0.0000"), (0, "0.808", "0.0000, 0.0000")],
)
def test_head_on_swap_under_the_filter_keeps_the_documented_distance(
    pass_right: int | None, closest: str, final: str
) -> None:
    overrides = ["recovery.strategy=none", "safety.filter=cbf"]
    if pass_right is not None:
        overrides.append(f"safety.pass_right={pass_right}")
    scenario = load_scenario(SCENARIOS / "safety" / "head_on_swap.yaml", overrides)
    metrics = compute_metrics(Simulation(scenario).run())
    assert metrics["collisions"]["total"] == 0
    assert f"{metrics['min_distance']:.3f}" == closest
    finals = [v["formation_error"]["final"] for v in metrics["vehicles"].values()]
    assert ", ".join(f"{e:.4f}" for e in finals) == final  # parked within 0.05 mm
    row = "| `safety.filter: cbf` (defaults) | 0 | "
    if pass_right is not None:
        row = "| `safety.filter: cbf`, `safety.pass_right: 0` | 0 | "
    text = (DOCS / "results" / "recovery.md").read_text()
    assert f"{row}{closest} | {final} |" in text


def test_random_start_table_counts_the_deadlocks_of_its_named_seeds() -> None:
    # safety_random_formup.yaml's setting without recovery nor filter, on the three
    # seeds docs/results/safety-benchmark.md names as its deadlocked runs
    overrides = [
        "duration=10",
        "vehicle.v2_max=4.0",
        "recovery.beta=1.0",
        "recovery.strategy=none",
        "recovery.tangential=0",
        "safety.filter=none",
    ]
    base = SCENARIOS / "studies" / "random_formup.yaml"
    seeds = (72, 115, 118)
    scenarios = [load_scenario(base, [*overrides, f"seed={s}"]) for s in seeds]
    for run in Simulation.batch(scenarios):
        metrics = compute_metrics(run)
        assert metrics["deadlocks"] and not metrics["converged"]
        assert metrics["deadlocks"][0]["t"] < 2.0  # from about 1 s
    text = (DOCS / "results" / "safety-benchmark.md").read_text()
    assert "| none | 0 | none | 56 / 200 | 34.6 % | 62 | 3 | 3 |" in text
    assert "3 starts (seeds 72,\n115, 118)" in text


def test_the_readme_demo_settles_without_a_warning(tmp_path) -> None:
    readme = (REPO / "README.md").read_text()
    start = readme.index("<!-- runnable: file demo.yaml -->\n```yaml\n")
    body = readme[start:].split("```yaml\n", 1)[1].split("```", 1)[0]
    path = tmp_path / "demo.yaml"
    path.write_text(body)
    # as the README runs it: 5 s, the continuous strategy
    overrides = ["duration=5", "recovery.strategy=continuous"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the loader's warnings (SandboxWarning)
        scenario = load_scenario(path, overrides)
    metrics = compute_metrics(Simulation(scenario).run())
    assert metrics["converged"] and metrics["collisions"]["total"] == 0
    assert not metrics["warnings"]
    settle = max(v["settling_time"] for v in metrics["vehicles"].values())
    assert f"{settle:.2f}" == "1.32"
    assert "(by 1.32 s)" in readme
    errors = [v["formation_error"]["final"] for v in metrics["vehicles"].values()]
    assert f"{max(errors):.3f}" == "0.036"
    assert "each follower 3.6 cm off its slot" in readme
