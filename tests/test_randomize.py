"""The ``randomize:`` section: draws from the seed, redraws, errors, exact reruns."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import yaml
from helpers import write_yaml

from sandbox.cli import main
from sandbox.errors import ScenarioError
from sandbox.scenario import load_scenario
from sandbox.scenario.randomize import MAX_ATTEMPTS

POSE = {"uniform": [[-3, -3, -3.14159], [3, 3, 3.14159]]}


def doc(**extra):
    base = {
        "name": "drawn",
        "duration": 0.5,
        "seed": 3,
        "vehicle": {"mass": 10.0},
        "reference": {"type": "line", "start": [0, 0], "heading": 0, "speed": 1},
        "formation": {"law": "rotating"},
        "recovery": {"strategy": "continuous", "beta": 1.0, "R": "3d", "r": "1.5d"},
        "vehicles": [
            {"name": "leader", "pose": [0, 0, 0], "leader": True},
            {"name": "red", "pose": [1, 1, 0], "offset": [-2, 1]},
            {"name": "green", "pose": [1, -1, 0], "offset": [-2, -1]},
        ],
    }
    base.update(extra)
    return base


def poses(scenario):
    return [v.pose for v in scenario.vehicles]


def test_uniform_pose_is_elementwise_within_bounds_and_repeatable():
    spec = {"vehicles[1].pose": POSE, "vehicles[2].pose": POSE}
    drawn = [poses(load_scenario(doc(seed=s, randomize=spec))) for s in range(20)]
    again = [poses(load_scenario(doc(seed=s, randomize=spec))) for s in range(20)]
    assert drawn == again
    follower = np.array([p[1:] for p in drawn]).reshape(-1, 3)
    assert np.all(np.abs(follower[:, :2]) <= 3) and np.all(
        np.abs(follower[:, 2]) <= 3.14159
    )
    # 40 draws per coordinate over the box: they spread (not a constant or one corner).
    assert np.all(follower.std(axis=0) > [1.0, 1.0, 1.0])
    assert len({p[1] for p in drawn}) == 20
    # The leader is not randomized.
    assert all(p[0] == (0.0, 0.0, 0.0) for p in drawn)


def test_draws_do_not_depend_on_key_order_or_on_other_paths():
    a = {"vehicles[1].pose": POSE, "recovery.beta": {"uniform": [1, 5]}}
    b = {"recovery.beta": {"uniform": [1, 5]}, "vehicles[1].pose": POSE}
    sa, sb = load_scenario(doc(randomize=a)), load_scenario(doc(randomize=b))
    assert poses(sa) == poses(sb) and sa.recovery.beta == sb.recovery.beta
    alone = load_scenario(doc(randomize={"recovery.beta": {"uniform": [1, 5]}}))
    assert alone.recovery.beta == sa.recovery.beta


def test_normal_and_choice():
    spec = {
        "vehicle.mass": {"normal": [10.0, 0.5]},
        "recovery.strategy": {"choice": ["discontinuous", "continuous"]},
    }
    drawn = [load_scenario(doc(seed=s, randomize=spec)) for s in range(40)]
    masses = np.array([s.vehicles[1].mass for s in drawn])
    assert abs(masses.mean() - 10.0) < 0.4 and 0.2 < masses.std() < 0.9
    assert {s.recovery.strategy for s in drawn} == {"discontinuous", "continuous"}


def test_overlapping_draws_are_redrawn():
    # Both followers drawn in a 0.8 m square next to each other: most draws overlap
    # (d = 0.5 m), yet every accepted draw has them apart.
    box = {"uniform": [[2, 2, 0], [2.8, 2.8, 0]]}
    spec = {"vehicles[1].pose": box, "vehicles[2].pose": box}
    for seed in range(15):
        s = load_scenario(doc(seed=seed, randomize=spec))
        gap = np.hypot(*np.subtract(s.vehicles[1].pose[:2], s.vehicles[2].pose[:2]))
        assert gap >= 0.5


def test_starts_inside_an_obstacle_are_redrawn():
    rock = [{"type": "circle", "name": "rock", "center": [2, 0], "radius": 1.0}]
    spec = {"vehicles[1].pose": {"uniform": [[0.5, -1.5, 0], [3.5, 1.5, 0]]}}
    for seed in range(15):
        s = load_scenario(doc(seed=seed, randomize=spec, obstacles=rock))
        x, y, _ = s.vehicles[1].pose
        assert np.hypot(x - 2, y) >= 1.0 + 0.25


def test_no_possible_draw_is_an_error():
    spec = {"vehicles[1].pose": {"uniform": [[0, 0, 0], [0.1, 0.1, 0]]}}
    with pytest.raises(ScenarioError, match=f"in {MAX_ATTEMPTS} attempts") as exc:
        load_scenario(doc(randomize=spec))
    assert exc.value.problems[0].path == "randomize"


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"uniform": [1]}, "randomize.recovery.beta.uniform: not a pair"),
        ({"uniform": [2, 1]}, "high below low"),
        ({"uniform": [[1, 2], [3]]}, "differ in shape"),
        ({"uniform": ["a", 1]}, "not a finite number or a list of them"),
        ({"uniform": [10**400, 1]}, "not a finite number"),
        ({"uniform": [[1, [2]], [3, 4]]}, "not a finite number"),
        ({"uniform": [-1e308, 1e308]}, "the range overflows"),
        ({"normal": [0, 1e308]}, "the range overflows"),
        ({"normal": [1, -1]}, "negative std"),
        ({"choice": []}, "not a list"),
        ({"gauss": [1, 2]}, "unknown distribution"),
        (3, "not a distribution"),
    ],
)
def test_bad_entries(tmp_path, entry, message):
    path = write_yaml(tmp_path, doc(randomize={"recovery.beta": entry}))
    with pytest.raises(ScenarioError, match=re.escape(message)) as exc:
        load_scenario(path)
    assert exc.value.lines[0].startswith(f"{path}:")  # file and line named


def test_a_key_that_is_not_text_names_no_field():
    with pytest.raises(ScenarioError, match="randomize"):
        load_scenario(doc(randomize={3: {"uniform": [1, 2]}}))


def test_bad_path():
    with pytest.raises(ScenarioError, match=re.escape("vehicles[7]")):
        load_scenario(doc(randomize={"vehicles[7].pose": POSE}))
    with pytest.raises(ScenarioError, match="names no field written"):
        load_scenario(doc(randomize={"recovery.bta": {"uniform": [1, 2]}}))
    # A field left at its default is not written: randomize replaces values only.
    with pytest.raises(ScenarioError, match="names no field written"):
        load_scenario(doc(randomize={"recovery.steepness": {"uniform": [1, 2]}}))


def test_a_path_given_by_set_is_not_drawn():
    spec = {"recovery.beta": {"uniform": [1, 5]}, "vehicles[1].pose": POSE}
    s = load_scenario(doc(randomize=spec), overrides=["recovery.beta=7"])
    assert s.recovery.beta == 7.0
    assert poses(s) == poses(load_scenario(doc(randomize=spec)))
    other = load_scenario(doc(randomize=spec), overrides=["seed=4"])
    assert poses(other) != poses(s)


def test_resolved_scenario_reruns_exactly_without_randomize(tmp_path):
    spec = {"vehicles[1].pose": POSE, "vehicles[2].pose": POSE}
    src = write_yaml(tmp_path, doc(randomize=spec))
    assert main(["run", str(src), "--out", str(tmp_path / "a")]) == 0
    resolved = yaml.safe_load((tmp_path / "a" / "scenario.yaml").read_text())
    assert "randomize" not in resolved
    assert (
        main(
            ["run", str(tmp_path / "a" / "scenario.yaml"), "--out", str(tmp_path / "b")]
        )
        == 0
    )
    for name in ("metrics.json", "trajectory.csv"):
        a = (tmp_path / "a" / name).read_text()
        assert a == (tmp_path / "b" / name).read_text()
    pose = json.loads(json.dumps(resolved["vehicles"][1]["pose"]))
    assert pose == list(load_scenario(src).vehicles[1].pose)
