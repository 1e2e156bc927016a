"""What the automatic camera frames (``sandbox.render.camera``), and frame aspects.

The automatic camera of a run spread along a line follows what happens: the healthy
vehicles, a failed vehicle while the others are near it (and its contacts), the
obstacles near them; a lone vehicle is not framed at its own size; a run framed whole
can have a frame of its own aspect.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_render import make_run

from sandbox.cli import main
from sandbox.render import camera
from sandbox.render.scene import Scene, recovery_label
from sandbox.run.record import CollisionEvent
from sandbox.scenario import load_scenario


def platoon_with_a_stop() -> object:
    """Three vehicles along x1 at 1 m/s for 20 s; the middle one stops at 4 s.

    leader x = t, middle x = t - 2 (stopped at x = 2 from t = 4), tail x = t - 4,
    every one on x2 = 0 but the middle, at x2 = 0.6 (the tail passes it at t = 6);
    the tail touches it at t = 6.
    """
    run = make_run(n=3, duration=20.0, speed=1.0)
    t = run.t
    run.pose[:, :, 1] = 0.0
    run.pose[:, 0, 0] = t
    run.pose[:, 1, 0] = np.minimum(t, 4.0) - 2.0
    run.pose[:, 1, 1] = 0.6
    run.pose[:, 2, 0] = t - 4.0
    run.failed[t >= 4.0, 1] = True
    run.events = [CollisionEvent(t=6.0, a="v1", b="v2", kind="vehicle_vehicle")]
    return run


def in_view(scene: Scene, k: int, point: np.ndarray) -> bool:
    """Whether ``point`` [m] is drawn inside the frame of sample ``k``."""
    cam = scene.camera.centered_on(scene.track[k])
    u, v = cam.world_to_pixel(point)
    top, bottom = scene.bands.top, scene.height - scene.bands.bottom
    return 0 <= u <= scene.size and top <= v <= bottom


def test_the_automatic_camera_keeps_a_stopped_vehicle_in_view_while_others_pass_it():
    run = platoon_with_a_stop()
    assert camera.auto_follow(run) == "leader"
    scene = Scene(run, size=320, zones=False, follow="auto", trail_seconds=0, step=0.1)
    k = {s: int(np.searchsorted(run.t, s)) for s in (6.0, 9.0, 12.0, 19.0)}
    # at the contact, and while the tail is 3 and 6 m past it, the stopped vehicle is
    # seen
    for s in (6.0, 9.0, 12.0):
        assert in_view(scene, k[s], run.pose[k[s], 1, :2]), s
        assert in_view(scene, k[s], run.pose[k[s], 0, :2]), s  # and the leader
    # once the platoon is far beyond (15 m), the window has moved on with it
    assert not in_view(scene, k[19.0], run.pose[k[19.0], 1, :2])
    assert in_view(scene, k[19.0], run.pose[k[19.0], 0, :2])
    # the leader-centred window leaves it out at 12 s
    leader = Scene(
        run, size=320, zones=False, follow="leader", trail_seconds=0, step=0.1
    )
    assert not in_view(leader, k[12.0], run.pose[k[12.0], 1, :2])


def test_a_lone_vehicle_is_framed_in_a_window_of_ten_diameters() -> None:
    run = make_run(n=1, duration=30.0, speed=1.0)  # 30 m along x1, d = 0.5 m
    run.pose[:, 0, 0] = run.t  # make_run's last vehicle stands still: drive it
    assert camera.auto_follow(run) == "leader"
    _, window = camera.camera_track(run, "auto")
    assert window.min() >= 10 * 0.5
    scene = Scene(run, size=320, zones=False, follow="auto", trail_seconds=0, step=0.1)
    assert scene.bar >= 1.0  # the scale bar: 0.5 m before, at 2.5 m across


def test_a_long_run_framed_whole_gets_a_frame_of_its_aspect() -> None:
    run = make_run(n=2, duration=35.0, speed=1.0)  # 35 m x 3 m
    square = Scene(run, size=320, zones=False, follow=None, trail_seconds=0, step=0.1)
    wide = Scene(
        run, size=320, zones=False, follow=None, trail_seconds=0, step=0.1, aspect="run"
    )
    assert square.height == 320
    assert 320 / camera.MAX_FRAME_ASPECT <= wide.height < 0.7 * 320
    assert wide.bands.rows  # high enough for the legend
    assert wide.camera.scale >= square.camera.scale
    assert wide.draw(0).shape == (wide.height, 320)
    assert Scene(run, size=320, zones=False, follow=None, trail_seconds=0, step=0.1,
                 aspect=2.0).height == 160  # fmt: skip
    with pytest.raises(ValueError, match="aspect: expected 'run' or a number"):
        camera.frame_height(run, 320, None, 9.0)


@pytest.mark.parametrize("bad", ["wide", "16:0", "1:9", "0", "nan"])
def test_a_bad_aspect_is_one_line_and_exit_2(bad: str, tmp_path, capsys) -> None:
    argv = ["run", "paper/stabilization", "--out", str(tmp_path / "r")]
    with pytest.raises(SystemExit) as stop:
        main([*argv, "--gif", str(tmp_path / "g.gif"), "--aspect", bad])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "argument --aspect: expected run, square, W:H or a number" in err
    assert not (tmp_path / "r").exists()


def test_the_heads_up_line_names_each_platoons_strategy() -> None:
    doc = load_scenario("traffic/failure_crash").to_dict()
    same = SimpleNamespace(scenario=load_scenario(doc))
    assert recovery_label(same, "continuous") == "continuous"
    doc["platoons"][1]["recovery"] = {"strategy": "none"}
    mixed = SimpleNamespace(scenario=load_scenario(doc))
    assert recovery_label(mixed, "continuous") == "east: continuous, north: none"
    alone = SimpleNamespace(scenario=None)
    assert recovery_label(alone, "smooth") == "smooth"
