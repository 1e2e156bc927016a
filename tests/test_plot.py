"""Tests of ``sandbox.render.figures``: the four report figures, headless and atomic.

Runs are synthetic, so these tests need no simulator.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from PIL import Image

from sandbox.render import figure_parts as plot_parts
from sandbox.render import figures as plot
from sandbox.run.record import CollisionEvent, Run

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


@pytest.mark.slow
def test_plot_run_writes_four_pngs_deterministically(tmp_path: Path) -> None:
    run = make_run()
    paths = plot.plot_run(run, tmp_path / "out", dpi=DPI)
    assert list(plot.FIGURES) == [
        "trajectories",
        "leader_frame",
        "formation_error",
        "commands",
    ]
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
            assert abs(im.size[0] - w) <= 1 and abs(im.size[1] - h) <= 1
            # not a blank canvas: many distinct colours are drawn
            assert len(im.convert("RGB").getcolors(maxcolors=1 << 16) or []) > 20
        assert p.stat().st_size > 8_000
    again = tmp_path / "again.png"
    plot.save_figure(plot.trajectories_figure(run), again, DPI)
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
    legend = [t.get_text() for t in traj.figure.legends[0].get_texts()]
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
        labels = {t.get_text() for leg in fig.legends for t in leg.get_texts()}
        assert all(ax.get_legend() is None for ax in fig.axes)
        assert not labels & set(run.names)
    FigureCanvasAgg(fig).draw()  # and it draws


@pytest.mark.parametrize("module", [plot, plot_parts])
def test_plot_does_not_import_pyplot(module) -> None:
    tree = ast.parse(Path(module.__file__).read_text())
    imported = {
        alias.name if isinstance(node, ast.Import) else f"{node.module}.{alias.name}"
        for node in ast.walk(tree)
        if isinstance(node, (ast.Import, ast.ImportFrom))
        for alias in node.names
    }
    assert not any("pyplot" in name for name in imported)
    assert "matplotlib.backends.backend_agg.FigureCanvasAgg" in imported


@pytest.mark.slow
@pytest.mark.parametrize("fmt, magic", [("pdf", b"%PDF"), ("svg", b"<?xml")])
def test_vector_formats_are_deterministic(tmp_path: Path, fmt: str, magic: bytes):
    run = make_run(duration=2.0, dt=0.1)
    first = plot.plot_run(run, tmp_path / "a", dpi=DPI, fmt=fmt)
    second = plot.plot_run(run, tmp_path / "b", dpi=DPI, fmt=fmt)
    assert [p.name for p in first] == [f"{stem}.{fmt}" for stem in plot.FIGURES]
    for a, b in zip(first, second, strict=True):
        assert a.read_bytes().startswith(magic)
        assert a.read_bytes() == b.read_bytes()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"fmt": "jpg"}, "format: expected one of png, pdf, svg, got 'jpg'"),
        ({"dpi": 5}, "dpi: expected a whole number from 10 to 1200, got 5"),
        ({"dpi": 72.5}, "dpi: expected a whole number"),
    ],
)
def test_bad_format_or_dpi_is_refused(tmp_path: Path, kwargs: dict, match: str):
    with pytest.raises(ValueError, match=re.escape(match)):
        plot.plot_run(make_run(), tmp_path, **kwargs)
    assert not list(tmp_path.iterdir())


def _stopped_run() -> Run:
    """Two vehicles: ``a`` drives along x1 at 1 m/s, ``b`` stands still all along."""
    run = make_run(n=2, duration=15.0, dt=0.05)
    t = run.t
    run.pose[:, 0] = np.column_stack((t, np.zeros_like(t), np.zeros_like(t)))
    run.pose[:, 1] = [0.0, 1.0, 0.0]
    run.slot[:] = run.pose[:, :, :2]
    run.slot[:, 1, 0] += np.maximum(t - 3.0, 0.0)  # b stops at 3 s: error grows to 12 m
    run.failed[:] = False
    run.failed[t >= 3.0, 1] = True
    run.info["failures"] = [{"vehicle": "v1", "kind": "stop", "at": 3.0}]
    run.info["obstacles"] = []
    run.reference[:] = run.pose[:, 0, :2]
    return run


def test_snapshot_time_labels_never_overlap() -> None:
    run = _stopped_run()
    run.pose[:, 0] = run.pose[:, 1]  # both stand still: every snapshot in one place
    fig = plot.trajectories_figure(run)
    ax = fig.axes[0]
    labels = [t for t in ax.texts if t.get_text().endswith(" s")]
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in labels]
    for j, a in enumerate(boxes):
        for b in boxes[j + 1 :]:
            assert not a.overlaps(b)
    shown = ", ".join(t.get_text() for t in labels)
    # six snapshots at 0, 3, 6, 9, 12, 15 s: all named, in a single merged label
    assert len(labels) == 1
    assert shown == "0, 3, 6, 9, 12, 15 s"


def test_snapshot_labels_go_to_free_vehicles_first() -> None:
    fig = plot.trajectories_figure(_stopped_run())
    labels = [t for t in fig.axes[0].texts if t.get_text().endswith(" s")]
    # the stopped b is the highest vehicle: it takes 0 s; later snapshots, whose label
    # on b would overlap, go to the moving a (at x1 = t)
    assert sorted(t.get_text() for t in labels) == sorted(
        f"{v} s" for v in (0, 3, 6, 9, 12, 15)
    )
    xs = sorted(t.xy[0] for t in labels)
    np.testing.assert_allclose(xs[1:], [3, 6, 9, 12, 15])


def test_trajectory_bounds_fit_a_straight_run() -> None:
    run = _stopped_run()
    fig = plot.trajectories_figure(run)
    ax = fig.axes[0]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    # content: x1 from -0.25 to 15.25 m, x2 from -0.25 to 1.25 m (vehicle radius 0.25)
    assert x0 < -0.25 and x1 > 15.25 and y0 < -0.25 and y1 > 1.25
    assert (x1 - x0) < 1.2 * 15.5  # the long side is not padded much
    w, h = fig.get_size_inches()
    assert w > 1.8 * h  # a wide figure, not a square one
    box = ax.get_position()
    # the drawn box has the limits' aspect ratio (one metre as long on both axes)
    assert (box.height * h) / (box.width * w) == pytest.approx(
        (y1 - y0) / (x1 - x0), rel=0.02
    )


def test_a_failed_vehicle_is_drawn_apart_and_does_not_set_the_scale() -> None:
    run = _stopped_run()
    run.slot[:, 0, 1] += 0.3 * np.exp(-run.t)  # a's small error (0.3 m, decaying)
    fig = plot.formation_error_figure(run)
    top, low = fig.axes
    assert top.get_ylim()[1] < 1.0  # set by a's error, not by b's 12 m
    b_top = next(line for line in top.get_lines() if line.get_label() == "v1")
    t_top = np.asarray(b_top.get_xdata())[np.isfinite(b_top.get_ydata())]
    assert t_top.max() < 3.0  # b on the upper panel only while it works
    y_low = np.concatenate([np.asarray(line.get_ydata()) for line in low.get_lines()])
    assert np.nanmax(y_low) == pytest.approx(12.0, abs=0.01)
    assert low.get_ylim()[1] >= 12.0


def test_no_lower_panel_without_failures() -> None:
    run = make_run(n=3)
    run.failed[:] = False
    run.info["failures"] = []
    assert len(plot.formation_error_figure(run).axes) == 1


def test_large_fleet_draws_median_and_percentile_bands() -> None:
    n = 60
    run = make_run(n=n, duration=2.0, dt=0.1)
    run.failed[:] = False
    run.info["failures"] = []
    err = np.linspace(0.0, 1.0, n)  # vehicle i is err[i] m from its slot, always
    run.slot[:] = run.pose[:, :, :2] + np.stack((err, np.zeros(n)), -1)
    ax = plot.formation_error_figure(run).axes[0]
    lines = {line.get_label(): line for line in ax.get_lines()}
    assert len(ax.get_lines()) < 10  # not one line per vehicle
    np.testing.assert_allclose(lines["median"].get_ydata(), np.median(err))
    np.testing.assert_allclose(lines["max"].get_ydata(), 1.0)
    assert len(ax.collections) >= 2  # the 25-75 and 5-95 bands
    top, _ = plot.commands_figure(run).axes
    assert len(top.get_lines()) < 10


@pytest.mark.slow
def test_cli_plot_writes_into_the_run_directory_figures_that_a_rerun_keeps(
    tmp_path: Path,
) -> None:
    from helpers import PAPER

    from sandbox.cli import main

    out = tmp_path / "run"
    scenario = str(PAPER / "rotating_circle.yaml")
    assert main(["run", scenario, "--out", str(out), "--duration", "1"]) == 0
    assert main(["plot", str(out), "--format", "pdf", "--dpi", "50"]) == 0
    assert sorted(p.name for p in (out / "figures").iterdir()) == sorted(
        [*(f"{stem}.pdf" for stem in plot.FIGURES), ".sandbox-outputs.json"]
    )  # the figures, and the record that sandbox plot wrote them
    # a re-run into the directory keeps the figures (they are not the run's files)
    before = (out / "figures" / "trajectories.pdf").read_bytes()
    assert main(["run", scenario, "--out", str(out), "--duration", "0.5"]) == 0
    assert (out / "figures" / "trajectories.pdf").read_bytes() == before
    # and sandbox plot replaces them again: they are still its own
    assert main(["plot", str(out), "--format", "pdf", "--dpi", "50"]) == 0


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--dpi", "5"], "--dpi: expected a whole number from 10 to 1200, got '5'"),
        (["--dpi", "x"], "--dpi: expected a whole number, got 'x'"),
        (["--format", "gif"], "--format: invalid choice: 'gif'"),
    ],
)
def test_cli_plot_bad_options(tmp_path: Path, capsys, argv: list, message: str):
    from sandbox.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["plot", str(tmp_path), *argv])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_cli_dpi_bounds_are_the_plot_module_s() -> None:
    from sandbox.cli import figures

    assert figures.DPI_RANGE == plot.DPI_RANGE


@pytest.mark.slow
def test_plot_run_reports_progress_after_each_figure(tmp_path: Path) -> None:
    run = make_run()
    calls: list[tuple[int, int]] = []
    paths = plot.plot_run(run, tmp_path, dpi=DPI, progress=lambda *a: calls.append(a))
    assert calls == [(1, 4), (2, 4), (3, 4), (4, 4)]
    assert len(paths) == 4


def test_formation_error_marks_detections_and_false_alarms() -> None:
    run = make_run()
    run.info["detection"] = {
        "method": "residual",
        "params": {},
        "events": [
            {"vehicle": "v0", "t": 1.5, "kind": "spin", "cleared": 1.8},
            {"vehicle": "v2", "t": 2.1, "kind": "stop", "cleared": None},
        ],
    }
    ax = plot.formation_error_figure(run).axes[0]
    filled = [
        line.get_xdata()[0]
        for line in ax.get_lines()
        if line.get_marker() == "^"
        and len(line.get_xdata())
        and line.get_markerfacecolor() != "none"
    ]
    hollow = [
        line.get_xdata()[0]
        for line in ax.get_lines()
        if line.get_marker() == "^"
        and len(line.get_xdata())
        and line.get_markerfacecolor() == "none"
    ]
    crosses = [
        line.get_xdata()[0]
        for line in ax.get_lines()
        if line.get_marker() == "x" and len(line.get_xdata())
    ]
    assert sorted(filled) == [1.5, 2.1] and hollow == [1.8]
    assert crosses == [1.5]  # v0 never failed: a false alarm
    texts = [t.get_text() for t in ax.texts]
    assert "v0 false alarm: spin" in texts and "v2 detected: stop" in texts
    labels = ax.get_legend_handles_labels()[1]
    assert {"detected", "false alarm", "detection cleared"} <= set(labels)
    # without detection (the oracle) nothing is marked
    plain = plot.formation_error_figure(make_run()).axes[0]
    assert not [line for line in plain.get_lines() if line.get_marker() == "^"]


def test_formation_error_marks_reassignments_and_leader_changes() -> None:
    # v2 fails at 2 s: at 2.0 s v0 (the leader) hands over to v1, and v2 loses its
    # slot; at 3.0 s a reassignment alone (v1 and v2 swap back, say)
    run = make_run()
    run.info["reassignments"] = [
        {"t": 2.0, "assignment": {"v0": None, "v1": 0, "v2": None}},
        {"t": 3.0, "assignment": {"v0": None, "v1": 0, "v2": 2}},
    ]
    run.info["leader_changes"] = [{"t": 2.0, "from": "v0", "to": "v1", "mode": "elect"}]
    run.info["slots"] = {
        "v0": [[0.0, 0], [2.05, None]],
        "v1": [[0.0, 1], [2.05, 0]],
        "v2": [[0.0, 2], [2.05, None], [3.05, 2]],
    }
    fig = plot.formation_error_figure(run)
    ax = fig.axes[0]

    def at(marker: str) -> list[float]:
        return [
            float(line.get_xdata()[0])
            for line in ax.get_lines()
            if line.get_marker() == marker and len(line.get_xdata())
        ]

    assert at("D") == [2.0] and at("v") == [3.0]  # one mark per event time
    diamond = next(line for line in ax.get_lines() if line.get_marker() == "D")
    assert diamond.get_color() == "red"  # the new leader's colour
    texts = [t.get_text() for t in ax.texts]
    assert "lead: v1; slots: v0\u2192none, v1\u21920, v2\u2192none" in texts
    assert "slots: v2\u21922" in texts  # only what changed
    labels = ax.get_legend_handles_labels()[1]
    assert {"reassigned", "leader change"} <= set(labels)
    FigureCanvasAgg(fig).draw()
    # the virtual leader: a grey diamond labelled "lead: reference"
    run.info["leader_changes"][0]["to"] = None
    ax = plot.formation_error_figure(run).axes[0]
    assert "lead: reference; slots: v0\u2192none, v1\u21920, v2\u2192none" in [
        t.get_text() for t in ax.texts
    ]
    # without reconfiguration nothing is marked
    plain = plot.formation_error_figure(make_run()).axes[0]
    assert not [line for line in plain.get_lines() if line.get_marker() in "Dv"]


def test_a_failed_vehicle_without_a_slot_gets_no_lower_panel() -> None:
    # Reconfiguration takes the failed vehicle's slot away: nothing to draw while
    # failed, so one panel; with its slot kept, the lower panel shows its distance.
    run = make_run()
    assert len(plot.formation_error_figure(run).axes) == 2
    run.slot[run.t >= 2.0 + 0.05, 2] = np.nan
    assert len(plot.formation_error_figure(run).axes) == 1
