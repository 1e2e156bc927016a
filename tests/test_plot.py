"""Tests of ``sandbox.plot``: the four report figures, headless and atomic.

Runs are synthetic, so these tests need no simulator.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from PIL import Image

from sandbox import plot
from sandbox.run import CollisionEvent, Run

DPI = 40  # small figures keep the tests fast


def make_run(
    n: int = 3, duration: float = 4.0, dt: float = 0.05, leader: int = 0
) -> Run:
    """Build ``n`` vehicles circling the origin, one failing at 2 s, one collision."""
    t = np.arange(0.0, duration + dt / 2, dt)
    T = len(t)
    ang = 0.5 * t[:, None] + 2 * np.pi * np.arange(n) / n
    pose = np.stack((3 * np.cos(ang), 3 * np.sin(ang), ang + np.pi / 2), -1)
    cmd = np.stack((np.full((T, n), 1.5), np.full((T, n), 0.5)), -1)
    slot = pose[:, :, :2] + 0.2 * np.sin(t)[:, None, None]
    failed = np.zeros((T, n), dtype=bool)
    failed[t >= 2.0, n - 1] = True
    return Run(
        t=t,
        pose=pose,
        cmd=cmd,
        chi=cmd.copy(),
        slot=slot,
        target=slot.copy(),
        mode=np.zeros((T, n), dtype=np.int8),
        failed=failed,
        reference=np.stack((0.1 * t, np.zeros(T)), -1),
        names=[f"v{i}" for i in range(n)],
        colors=(["blue", "red", "#2ca02c"] * n)[:n],
        diameter=np.full(n, 0.5),
        leader=leader,
        events=[CollisionEvent(1.0, "v0", "v1", "vehicle_vehicle")],
        info={
            "obstacles": [
                {"type": "circle", "center": [5.0, 0.0], "radius": 0.5, "name": "c"},
                {
                    "type": "polygon",
                    "points": [[-5, -5], [-4, -5], [-4, -4]],
                    "name": "p",
                },
            ],
            "failures": [
                {"vehicle": f"v{n - 1}", "kind": "stop", "at": 2.0, "until": None}
            ],
            "scenario_name": "test",
        },
    )


def test_plot_run_writes_four_pngs_deterministically(tmp_path: Path) -> None:
    run = make_run()
    paths = plot.plot_run(run, tmp_path / "out", dpi=DPI)
    names = [
        "trajectories.png",
        "leader_frame.png",
        "formation_error.png",
        "commands.png",
    ]
    assert [p.name for p in paths] == names
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(names)
    for p, build in zip(paths, plot.FIGURES.values(), strict=True):
        w, h = build(run).get_size_inches() * DPI
        with Image.open(p) as im:
            assert im.format == "PNG"
            assert im.size == (round(w), round(h))
            # not a blank canvas: many distinct colours are drawn
            assert len(im.convert("RGB").getcolors(maxcolors=1 << 16) or []) > 20
        assert p.stat().st_size > 8_000
    again = tmp_path / "again.png"
    plot._save(plot.trajectories_figure(run), again, DPI)
    assert again.read_bytes() == paths[0].read_bytes()


def test_axes_are_labelled_with_units_and_spatial_axes_equal() -> None:
    run = make_run()
    traj = plot.trajectories_figure(run).axes[0]
    assert (traj.get_xlabel(), traj.get_ylabel()) == ("x1 [m]", "x2 [m]")
    assert traj.get_aspect() == 1.0
    assert plot.leader_frame_figure(run).axes[0].get_aspect() == 1.0
    top, bottom = plot.commands_figure(run).axes
    assert (top.get_ylabel(), bottom.get_ylabel()) == ("v1 [m/s]", "v2 [rad/s]")
    assert bottom.get_xlabel() == "t [s]"
    legend = [t.get_text() for t in traj.get_legend().get_texts()]
    assert {"v0", "v1", "v2", "reference", "collision", "failure"} <= set(legend)


def test_formation_error_marks_failures_and_collisions() -> None:
    ax = plot.formation_error_figure(make_run()).axes[0]
    vertical = [
        line.get_xdata()[0] for line in ax.get_lines() if line.get_linestyle() == "--"
    ]
    assert vertical == [pytest.approx(2.0)]
    stars = [line for line in ax.get_lines() if line.get_marker() == "*"]
    # one collision between v0 and v1 -> a star on each of their curves, at t = 1 s
    assert len(stars) == 1 and stars[0].get_xdata().tolist() == [1.0, 1.0]
    assert ax.get_ylabel() == "formation error [m]"


def test_leader_frame_without_leader_uses_the_centroid() -> None:
    run = make_run(leader=-1)
    ax = plot.leader_frame_figure(run).axes[0]
    assert "centroid" in ax.get_title()
    assert ax.get_xlabel() == "x1 - centroid [m]"
    v0 = next(line for line in ax.get_lines() if line.get_label() == "v0")
    # three vehicles 120 degrees apart on a 3 m circle: centroid at the origin until
    # v2 fails at 2 s and leaves the centroid
    before = run.t < 2.0
    r = np.hypot(v0.get_xdata(), v0.get_ydata())
    np.testing.assert_allclose(r[before], 3.0)
    assert np.all(np.abs(r[~before] - 3.0) > 0.1)


def test_leader_frame_shows_followers_where_they_stand() -> None:
    run = make_run(n=3)
    ax = plot.leader_frame_figure(run).axes[0]
    v1 = next(line for line in ax.get_lines() if line.get_label() == "v1")
    # vehicles on a circle 120 degrees apart stay fixed in the leader's frame
    xy = np.column_stack((v1.get_xdata(), v1.get_ydata()))
    np.testing.assert_allclose(xy, np.broadcast_to(xy[0], xy.shape), atol=1e-9)
    np.testing.assert_allclose(xy[0], run.leader_frame()[0, 1])


def test_large_fleet_has_no_per_vehicle_legend() -> None:
    run = make_run(n=plot.LEGEND_MAX + 8, duration=1.0, dt=0.1)
    for build in plot.FIGURES.values():
        fig = build(run)
        assert all(ax.get_legend() is None for ax in fig.axes)
    FigureCanvasAgg(fig).draw()  # and it draws


def test_plot_does_not_import_pyplot() -> None:
    tree = ast.parse(Path(plot.__file__).read_text())
    imported = {
        alias.name if isinstance(node, ast.Import) else f"{node.module}.{alias.name}"
        for node in ast.walk(tree)
        if isinstance(node, (ast.Import, ast.ImportFrom))
        for alias in node.names
    }
    assert not any("pyplot" in name for name in imported)
    assert "matplotlib.backends.backend_agg.FigureCanvasAgg" in imported
