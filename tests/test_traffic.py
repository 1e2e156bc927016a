"""The traffic scenes of ``scenarios/traffic/``: several platoons in one world.

Each scene is run as written (the recommended configuration: the continuous strategy
with the tangential term and the CBF filter) and its ``expect:`` claims must hold. The
crossing is also run without recovery, where the platoons touch: the counter of
inter-platoon contacts works, and the claims of the recommended configuration are
not vacuous. The rates over 100 seeds are in docs/concepts/platoons.md.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from sandbox import compute_metrics
from sandbox.testing import check_scenario

TRAFFIC = Path(__file__).resolve().parent.parent / "scenarios" / "traffic"
SCENES = sorted(p.stem for p in TRAFFIC.glob("*.yaml"))


def test_the_traffic_folder_holds_the_scenes_of_issue_25() -> None:
    assert SCENES == [
        "failure_crash",
        "failure_stop",
        "head_on_narrow",
        "intersection_four",
        "intersection_two",
        "merge_one_lane",
        "merge_split",
        "overtaking",
        "roundabout",
    ]


@pytest.mark.slow
@pytest.mark.parametrize("scene", SCENES)
def test_each_scene_shows_what_it_claims(scene: str) -> None:
    result = check_scenario(TRAFFIC / f"{scene}.yaml", keep_run=False)
    failed = [o.line(scene) for o in result.outcomes if not o.holds]
    assert not failed, failed


@pytest.mark.slow
def test_the_crossing_without_recovery_has_inter_platoon_contacts() -> None:
    result = check_scenario(
        TRAFFIC / "intersection_two.yaml",
        ["recovery.strategy=none", "safety.filter=none"],
    )
    metrics = compute_metrics(result.run)
    assert metrics["collisions"]["inter_platoon"] >= 1
    assert metrics["collisions"]["intra_platoon"] == 0
    failed = {o.key for o in result.outcomes if not o.holds}
    assert "collisions.inter_platoon" in failed
