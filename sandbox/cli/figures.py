"""``sandbox render``, ``sandbox plot`` and ``sandbox gallery``: pictures of runs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sandbox.cli.common import (
    EXIT_FAILED,
    EXIT_INVALID,
    EXIT_OK,
    add_gif_options,
    add_plugin_option,
    check_gif_frames,
    check_mp4,
    nonempty,
    render_gif,
)
from sandbox.output import load_run_dir


def cmd_render(args: argparse.Namespace) -> int:
    """``sandbox render RUN_DIR --gif PATH [--mp4 PATH]``: a GIF (and/or MP4)."""
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


def cmd_gallery(args: argparse.Namespace) -> int:
    """``sandbox gallery``: run and render every scenario of the given folders."""
    from sandbox.gallery import render_gallery

    folders = [
        Path(f) for f in (args.folders or ["scenarios/paper", "scenarios/failures"])
    ]
    missing = [str(f) for f in folders if not f.is_dir()]
    if missing:
        print(f"error: no such folder: {', '.join(missing)}", file=sys.stderr)
        return EXIT_FAILED
    render_gallery(folders, Path(args.out), zones=args.zones)
    return EXIT_OK


def cmd_plot(args: argparse.Namespace) -> int:
    """``sandbox plot RUN_DIR``: the four report figures, in ``RUN_DIR/figures/``."""
    from sandbox.plot import plot_run

    run = load_run_dir(Path(args.run_dir))
    out = Path(args.out) if args.out else Path(args.run_dir) / "figures"
    for path in plot_run(run, out, dpi=args.dpi, fmt=args.format):
        print(path)
    return EXIT_OK


#: Resolutions ``--dpi`` accepts, as :data:`sandbox.plot.DPI_RANGE` (a test checks
#: they agree; not imported from there, since matplotlib is slow to import).
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
    p = sub.add_parser("render", help="render a saved run to a GIF or an MP4")
    p.add_argument("run_dir", help="a run directory written by sandbox run")
    p.add_argument("--gif", type=nonempty, help="output GIF file")
    add_gif_options(p)
    add_plugin_option(p)
    p.set_defaults(func=cmd_render)
    p = sub.add_parser("gallery", help="run and render every scenario of some folders")
    p.add_argument(
        "folders",
        nargs="*",
        help="scenario folders (default scenarios/paper scenarios/failures)",
    )
    p.add_argument("--out", default="renders", help="output folder (default renders/)")
    p.add_argument("--zones", action="store_true", help="draw the R (and r) safe zones")
    add_plugin_option(p)
    p.set_defaults(func=cmd_gallery)
    p = sub.add_parser("plot", help="write report-style figures of a saved run")
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
    add_plugin_option(p)
    p.set_defaults(func=cmd_plot)
