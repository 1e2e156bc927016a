"""The tunnelling guard of ``sandbox validate``: motion per substep vs the diameter."""

from __future__ import annotations

import pytest
from helpers import PAPER, SCENARIOS, write_yaml

from sandbox import SandboxWarning, load_scenario
from sandbox.cli import main
from sandbox.model.tunnelling import peak_gain_speed


def head_on(speed: float, diameter: float = 0.2) -> dict:
    """Two open-loop carts driving at each other at ``speed`` [m/s] each."""
    drive = {"type": "commands", "schedule": [[0, speed, 0.0]]}
    return {
        "duration": 0.1,
        "formation": {"law": "fixed"},
        "vehicle": {"diameter": diameter},
        "vehicles": [
            {"name": "a", "pose": [-2.0, 0, 0], "leader": True, "drive": drive},
            {"name": "b", "pose": [2.0, 0.05, 3.14159], "drive": drive},
        ],
    }


def tunnelling(sc) -> list[str]:
    return [w for w in sc.warnings if "per physics substep" in w]


def test_fast_small_vehicles_are_warned_with_the_safe_substeps(tmp_path, capsys):
    # 100 m/s x 2.5 ms = 0.25 m per substep for d = 0.2 m: 4 x 100 x 0.01 / 0.2 = 20
    path = write_yaml(tmp_path, head_on(100.0))
    with pytest.warns(SandboxWarning, match="per physics substep") as caught:
        (warning,) = tunnelling(load_scenario(path))
    assert [str(w.message) for w in caught] == [warning]
    assert "vehicle 'a' can move 0.25 m per physics substep" in warning
    assert "substeps >= 20 would be safe" in warning
    assert tunnelling(load_scenario(path, overrides=["substeps=20"])) == []
    with pytest.warns(SandboxWarning, match="per physics substep"):
        assert tunnelling(load_scenario(path, overrides=["substeps=19"])) != []
    assert main(["validate", str(path)]) == 0
    assert "warning:" in capsys.readouterr().err and "substeps >= 20" in warning


def test_slow_vehicles_and_the_bundled_scenarios_are_not_warned(tmp_path):
    assert tunnelling(load_scenario(write_yaml(tmp_path, head_on(1.0)))) == []
    for path in [*PAPER.glob("*.yaml"), *(SCENARIOS / "failures").glob("*.yaml")]:
        assert tunnelling(load_scenario(path)) == [], path


def test_without_v1_max_the_speed_the_gains_ask_for_is_used(tmp_path):
    # 100 m from the point, no limits: the gains ask for about 380 m/s (0.95 m per
    # substep for d = 0.5 m): warned; v1_max = 2 m/s is not
    doc = {
        "reference": {"type": "point", "position": [100, 0]},
        "vehicles": [{"name": "far", "pose": [0, 0, 0]}],
    }
    with pytest.warns(SandboxWarning, match="per physics substep"):
        (warning,) = tunnelling(load_scenario(write_yaml(tmp_path, doc)))
    assert "the speed the gains ask for" in warning and "far" in warning
    limited = load_scenario(write_yaml(tmp_path, doc), overrides=["vehicle.v1_max=2"])
    assert tunnelling(limited) == []


def test_peak_gain_speed_is_the_linear_error_peak():
    # critically damped at -10 rad/s: |e'| peaks at 10 e0 / e = 3.68 e0 (continuous);
    # forward Euler at 10 ms a little more
    assert peak_gain_speed(-100.0, -20.0, 0.001, 1.0, 0.0) == pytest.approx(
        3.68, rel=0.01
    )
    assert peak_gain_speed(-100.0, -20.0, 0.01, 2.0, 1.0) == pytest.approx(
        2 * peak_gain_speed(-100.0, -20.0, 0.01, 1.0, 0.0) + 1.0, rel=0.05
    )


def test_a_platoon_that_starts_on_its_slots_is_not_warned_of_its_offsets():
    # 400 followers on their slots behind a 1 m/s leader: no initial error, so the
    # gains ask for about the reference's speed, far below a quarter diameter per
    # substep. (Bounding the error by |pos - leader| + |offset| warned here.)
    scenario = load_scenario(
        {
            "reference": {"type": "line", "speed": 1.0},
            "formation": {"law": "rotating"},
            "vehicles": [{"name": "lead", "pose": [0, 0, 0], "leader": True}],
            "platoon": {"count": 400, "spacing": 0.6},
        }
    )
    assert not any("substep" in w for w in scenario.warnings)
