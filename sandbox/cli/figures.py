"""``sandbox render``, ``sandbox plot`` and ``sandbox gallery``: pictures of runs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sandbox.cli.common import EXIT_FAILED, EXIT_OK, add_gif_options, render_gif
from sandbox.output import load_run_dir


def cmd_render(args: argparse.Namespace) -> int:
    """``sandbox render RUN_DIR --gif PATH``: a GIF from a saved run."""
    run = load_run_dir(Path(args.run_dir))
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
    """``sandbox plot RUN_DIR``: the four report-style figures."""
    from sandbox.plot import plot_run

    run = load_run_dir(Path(args.run_dir))
    for path in plot_run(run, Path(args.out) if args.out else Path(args.run_dir)):
        print(path)
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``render``, ``gallery`` and ``plot`` commands."""
    p = sub.add_parser("render", help="render a saved run to a GIF")
    p.add_argument("run_dir")
    p.add_argument("--gif", required=True, help="output GIF file")
    add_gif_options(p)
    p.set_defaults(func=cmd_render)
    p = sub.add_parser("gallery", help="run and render every scenario of some folders")
    p.add_argument(
        "folders",
        nargs="*",
        help="scenario folders (default scenarios/paper scenarios/failures)",
    )
    p.add_argument("--out", default="renders", help="output folder (default renders/)")
    p.add_argument("--zones", action="store_true", help="draw the R (and r) safe zones")
    p.set_defaults(func=cmd_gallery)
    p = sub.add_parser("plot", help="write report-style figures of a saved run")
    p.add_argument("run_dir")
    p.add_argument("--out", help="directory for the PNGs (default: the run directory)")
    p.set_defaults(func=cmd_plot)
