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
    """``sandbox gallery``: run and render every scenario of the given folders."""
    from sandbox.render.gallery import render_gallery, scenario_files

    folders = [_gallery_folder(f) for f in (args.folders or ["paper", "failures"])]
    missing = [str(f) for f in folders if not f.is_dir()]
    if missing:
        print(f"error: no such folder: {', '.join(missing)}", file=sys.stderr)
        return EXIT_FAILED
    with progress(len(scenario_files(folders)), "gallery", unit="gif") as bar:

        def log(line: str) -> None:
            bar.write(line)
            bar.advance()

        render_gallery(folders, Path(args.out), zones=args.zones, log=log)
    return EXIT_OK


def cmd_plot(args: argparse.Namespace) -> int:
    """``sandbox plot RUN_DIR``: the four report figures, in ``RUN_DIR/figures/``."""
    from sandbox.render.figures import plot_run
    from sandbox.run.output import load_run_dir

    run = load_run_dir(Path(args.run_dir))
    out = Path(args.out) if args.out else Path(args.run_dir) / "figures"
    if args.scan is not None:
        return _plot_scan(run, out, args)
    with progress(4, "plotting", unit="figure") as bar:
        paths = plot_run(run, out, dpi=args.dpi, fmt=args.format, progress=bar)
    for path in paths:
        print(path)
    return EXIT_OK


def _plot_scan(run: object, out: Path, args: argparse.Namespace) -> int:
    """``sandbox plot RUN_DIR --scan T``: the figure of one scan, ``scan_T.FMT``."""
    from sandbox.render.figure_parts import save_figure
    from sandbox.render.scan_figure import scan_figure

    try:
        fig = scan_figure(run, args.scan, args.vehicle)
    except ValueError as exc:
        print(f"error: sandbox plot --scan: {exc}", file=sys.stderr)
        return EXIT_INVALID
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"scan_{args.scan:g}.{args.format}"
    save_figure(fig, path, args.dpi, args.format)
    print(path)
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
    p.add_argument("--out", default="renders", help="output folder (default renders/)")
    p.add_argument("--zones", action="store_true", help="draw the R (and r) safe zones")
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
        "--out", help="directory for the figures (default: RUN_DIR/figures/)"
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
