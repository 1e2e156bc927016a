"""``sandbox view RUN_DIR``: the interactive replay of a saved run, one HTML file.

Also :func:`write_run_html`, which ``sandbox run FILE --html`` calls. Every mistake (not
a run directory, a damaged ``run.npz``, an output that exists and is not an earlier
replay) is one line on stderr and exit status 2; nothing is overwritten.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from sandbox.cli.common import (
    EXIT_INVALID,
    EXIT_OK,
    add_command,
    add_plugin_option,
    nonempty,
    trust_advice,
)

#: The page's name in the run directory.
DEFAULT_NAME = "replay.html"


def cmd_view(args: argparse.Namespace) -> int:
    """``sandbox view RUN_DIR [-o FILE.html]``: write the replay page of a run."""
    from sandbox.errors import SandboxError
    from sandbox.render.replay import check_output
    from sandbox.run.output import load_run_dir

    run_dir = Path(args.run_dir)
    out = Path(args.output) if args.output else run_dir / DEFAULT_NAME
    try:
        check_output(out)  # before reading a large run
        run = load_run_dir(run_dir)
        written = write_run_html(run, out)
    except SandboxError as exc:
        print(f"error: {trust_advice(exc, args)}", file=sys.stderr)
        return EXIT_INVALID
    print_written(written)
    return EXIT_OK


def html_problem(out_dir: Path) -> str | None:
    """Why ``OUT_DIR/replay.html`` must not be written (``run --html``), or None."""
    from sandbox.render.replay import ReplayError, check_output

    try:
        check_output(Path(out_dir) / DEFAULT_NAME)
    except ReplayError as exc:
        return str(exc)
    return None


def print_written(path: Path) -> None:
    """Say where the page is, and how large."""
    print(f"replay: {path} ({_size(path)}); open it in a browser")


def write_run_html(
    run: Any,
    out: Path,
    metrics: dict[str, Any] | None = None,
    show_beams: bool = False,
) -> Path:
    """Write the replay page of ``run`` to ``out`` (``view``, ``run --html``).

    ``show_beams`` embeds the range sensors' scans (``run --html --show-beams``).
    """
    from sandbox.render.replay import write_html

    if show_beams:
        return write_html(run, out, metrics=metrics, show_beams=True)
    return write_html(run, out, metrics=metrics)


def _size(path: Path) -> str:
    """The size of a file in kB or MB."""
    size = path.stat().st_size
    return f"{size / 1e6:.1f} MB" if size >= 1e6 else f"{size / 1e3:.0f} kB"


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``view`` command."""
    p = add_command(
        sub,
        "view",
        "write an interactive replay of a saved run (one HTML file)",
        [
            "sandbox view runs/fig13_discontinuous_beta1   # RUN_DIR/replay.html",
            "sandbox view runs/door -o door.html",
        ],
        description=(
            "Write one self-contained HTML file that replays a run directory written "
            "by sandbox run: play, scrub a timeline of its collisions, failures, "
            "detections, reassignments and leader changes, zoom, follow a vehicle. "
            "It needs no network; open it from disk in Chromium or Firefox. "
            "sandbox run FILE --html writes it right after a run."
        ),
    )
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run directory")
    p.add_argument(
        "-o",
        "--output",
        type=nonempty,
        metavar="FILE.html",
        help=f"output file (default RUN_DIR/{DEFAULT_NAME}); an existing file is "
        "replaced only if it is an earlier replay",
    )
    add_plugin_option(p)  # a run of a plug-in's obstacle or strategy reads it back
    p.set_defaults(func=cmd_view)
