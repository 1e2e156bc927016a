"""``sandbox render``, ``sandbox plot`` and ``sandbox gallery``: pictures of runs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sandbox.cli.common import (
    EXIT_FAILED,
    EXIT_INVALID,
    EXIT_OK,
    add_command,
    add_force_option,
    add_gif_options,
    add_plugin_option,
    check_gif_frames,
    check_mp4,
    nonempty,
    progress,
    render_gif,
)


def cmd_render(args: argparse.Namespace) -> int:
    """``sandbox render RUN_DIR --gif PATH [--mp4 PATH]``: a GIF (and/or MP4)."""
    from sandbox.run.output import load_run_dir

    if not (args.gif or args.mp4):
        print(
            "error: sandbox render: give --gif OUT.gif, --mp4 OUT.mp4 or both",
            file=sys.stderr,
        )
        return EXIT_INVALID
    check_mp4(args)
    run = load_run_dir(Path(args.run_dir))
    if args.gif:
        check_gif_frames(float(run.t[-1] - run.t[0]), args)
    render_gif(run, args)
    return EXIT_OK


def _gallery_folder(text: str) -> Path:
    """A gallery folder argument: the folder if it exists, else a bundled one."""
    from sandbox.scenario.bundled import scenarios_dir

    given = Path(text)
    if given.is_dir():
        return given
    bundled = scenarios_dir() / text.removeprefix("scenarios/")
    return bundled if bundled.is_dir() else given


def cmd_gallery(args: argparse.Namespace) -> int:
    """``sandbox gallery``: run and render every scenario of the given folders.

    Each ``OUT/NAME.gif`` replaces only an earlier GIF of the gallery (``--force``:
    any file); all of them are checked before the first run, and each is put in
    place as soon as it is rendered.
    """
    from sandbox.render.gallery import render_gallery, scenario_files
    from sandbox.run.output_guard import check_targets, staged

    folders = [_gallery_folder(f) for f in (args.folders or ["paper", "failures"])]
    missing = [str(f) for f in folders if not f.is_dir()]
    if missing:
        print(f"error: no such folder: {', '.join(missing)}", file=sys.stderr)
        return EXIT_FAILED
    out = Path(args.out)
    files = scenario_files(folders)
    check_targets([out / f"{f.stem}.gif" for f in files], "gallery", force=args.force)
    with (
        staged(out, "gallery", args.force) as stage,
        progress(len(files), "gallery", unit="gif") as bar,
    ):

        def log(line: str) -> None:
            stage.commit()  # the GIF just rendered, in place at once
            bar.write(line.replace(str(stage.path), str(out)))
            bar.advance()

        render_gallery(folders, stage.path, zones=args.zones, log=log)
    return EXIT_OK


def cmd_plot(args: argparse.Namespace) -> int:
    """``sandbox plot RUN_DIR``: the four report figures, in ``RUN_DIR/figures/``.

    A figure replaces only an earlier figure of ``sandbox plot`` (``--force``: any
    file); every name is checked before the run is read, the figures are drawn into a
    stage and put in place together.
    """
    from sandbox.render.figures import FIGURES, plot_run
    from sandbox.run.output import load_run_dir
    from sandbox.run.output_guard import check_targets, staged

    out = Path(args.out) if args.out else Path(args.run_dir) / "figures"
    if args.scan is not None:
        names = [scan_name(args.scan, args.format)]
    else:
        names = [f"{stem}.{args.format}" for stem in FIGURES]
    check_targets([out / name for name in names], "plot", force=args.force)
    run = load_run_dir(Path(args.run_dir))
    with staged(out, "plot", args.force) as stage:
        if args.scan is not None:
            status = _plot_scan(run, stage.path, args)
            if status != EXIT_OK:
                return status
        else:
            with progress(4, "plotting", unit="figure") as bar:
                plot_run(run, stage.path, dpi=args.dpi, fmt=args.format, progress=bar)
    for name in names:  # in the figures' order
        print(out / name)
    return EXIT_OK


def scan_name(t: float, fmt: str) -> str:
    """The file of the figure of the scan nearest ``t`` [s]: ``scan_T.FMT``."""
    return f"scan_{t:g}.{fmt}"


def _plot_scan(run: object, out: Path, args: argparse.Namespace) -> int:
    """``sandbox plot RUN_DIR --scan T``: the figure of one scan, ``scan_T.FMT``."""
    from sandbox.render.figure_parts import save_figure
    from sandbox.render.scan_figure import scan_figure

    try:
        fig = scan_figure(run, args.scan, args.vehicle)
    except ValueError as exc:
        print(f"error: sandbox plot --scan: {exc}", file=sys.stderr)
        return EXIT_INVALID
    save_figure(fig, out / scan_name(args.scan, args.format), args.dpi, args.format)
    return EXIT_OK


#: Resolutions ``--dpi`` accepts, as :data:`sandbox.render.figures.DPI_RANGE` (a test
#: checks they agree; not imported from there, since matplotlib is slow to import).
DPI_RANGE = (10, 1200)


def _dpi(text: str) -> int:
    """An argparse type: a whole number of dots per inch within the plot's bounds."""
    low, high = DPI_RANGE
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a whole number, got {text!r}"
        ) from None
    if not low <= value <= high:
        raise argparse.ArgumentTypeError(
            f"expected a whole number from {low} to {high}, got {text!r}"
        )
    return value


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``render``, ``gallery`` and ``plot`` commands."""
    p = add_command(
        sub,
        "render",
        "render a saved run to a GIF or an MP4",
        [
            "sandbox render runs/rotating_circle --gif rotating.gif",
            "sandbox render runs/obstacle_field --gif o.gif --size 480 --zones",
            "sandbox render runs/grid_1000 --mp4 grid.mp4     # needs the video extra",
        ],
    )
    p.add_argument("run_dir", help="a run directory written by sandbox run")
    p.add_argument("--gif", type=nonempty, help="output GIF file")
    add_gif_options(p)
    add_plugin_option(p, trust=True)
    p.set_defaults(func=cmd_render)
    p = add_command(
        sub,
        "gallery",
        "run and render every scenario of some folders",
        [
            "sandbox gallery                        # bundled paper/ and failures/",
            "sandbox gallery my_scenarios/ --out my_renders/",
        ],
    )
    p.add_argument(
        "folders",
        nargs="*",
        help="scenario folders, or bundled ones such as paper (default: the bundled "
        "paper and failures)",
    )
    p.add_argument(
        "--out",
        default="renders",
        help="output folder (default renders/); a GIF there is replaced only if the "
        "gallery wrote it",
    )
    p.add_argument("--zones", action="store_true", help="draw the R (and r) safe zones")
    add_force_option(p, "a GIF of the --out folder that the gallery did not write")
    add_plugin_option(p)
    p.set_defaults(func=cmd_gallery)
    p = add_command(
        sub,
        "plot",
        "write report-style figures of a saved run",
        [
            "sandbox plot runs/rotating_circle            # PNGs in RUN_DIR/figures/",
            "sandbox plot runs/rotating_circle --format pdf --out paper/figures/",
            "sandbox plot runs/rotating_circle --format png --dpi 300",
            "sandbox plot runs/obstacle_field --scan 12   # one range-sensor scan",
        ],
    )
    p.add_argument("run_dir", help="a run directory written by sandbox run")
    p.add_argument(
        "--out",
        help="directory for the figures (default: RUN_DIR/figures/); a file there is "
        "replaced only if sandbox plot wrote it",
    )
    add_force_option(
        p, "a figure of the --out directory that sandbox plot did not write"
    )
    p.add_argument(
        "--format",
        choices=("png", "pdf", "svg"),
        default="png",
        help="file format: png, or pdf or svg (vector) for a paper (default png)",
    )
    p.add_argument(
        "--dpi",
        type=_dpi,
        default=120,
        help=f"resolution of PNG figures, {DPI_RANGE[0]} to {DPI_RANGE[1]} dots per "
        "inch (default 120)",
    )
    p.add_argument(
        "--scan",
        type=float,
        metavar="T",
        help="instead, the figure of the range-sensor scan nearest T [s] "
        "(scan_T.png; a run with sensors.range)",
    )
    p.add_argument(
        "--vehicle",
        help="with --scan: whose readings to plot (default the first with a sensor)",
    )
    add_plugin_option(p, trust=True)
    p.set_defaults(func=cmd_plot)
