"""``sandbox compare FILE...``: a table of recovery strategies against metrics."""

from __future__ import annotations

import argparse
import sys

from sandbox.cli.common import (
    EXIT_INVALID,
    EXIT_OK,
    add_command,
    add_plugin_option,
    cap_jobs,
    jobs,
    progress,
    scenario_file,
)
from sandbox.errors import ScenarioError


def cmd_compare(args: argparse.Namespace) -> int:
    """``sandbox compare FILE...``: a table of metrics per scenario and strategy."""
    from sandbox.study.compare import compare, format_table
    from sandbox.study.paired import PAIRED_TITLE, compare_settings, paired_text

    def names(text: str) -> list[str]:
        return [x.strip() for x in text.split(",") if x.strip()]

    files = [scenario_file(f) for f in args.files]
    try:
        with progress(0, "comparing", unit="run") as bar:
            rows = compare(
                files,
                names(args.strategies) if args.strategies is not None else None,
                names(args.derivatives),
                args.set or [],
                jobs=cap_jobs(args.jobs),
                plugin_specs=args.plugin or [],
                progress=bar,
                grid=args.grid or [],
            )
    except ValueError as exc:
        if isinstance(exc, ScenarioError):
            raise
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    paired = paired_text(compare_settings(rows), args.format)
    if args.paired:
        sys.stdout.write(paired or "")
        return EXIT_OK
    sys.stdout.write(format_table(rows, args.format, args.columns))
    if paired and args.format in ("md", "markdown"):
        sys.stdout.write(f"\n{PAIRED_TITLE}\n\n{paired}")
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``compare`` command."""
    p = add_command(
        sub,
        "compare",
        "compare recovery strategies on scenario files",
        [
            "sandbox compare failures/follower_stop failures/obstacle_field",
            "sandbox compare scenarios/paper/fig1*.yaml --strategies file",
            "sandbox compare my.yaml --derivatives hold,estimate --jobs 2 --format csv",
            "sandbox compare scenarios/safety/*.yaml --grid recovery.tangential=0,1 "
            "--columns safety",
        ],
        description=(
            "Run every scenario once per recovery strategy and target-derivative mode "
            "and print a table of collisions, minimum distance, settling, switches "
            "and effort (one row per run)."
        ),
    )
    p.add_argument(
        "files",
        nargs="+",
        metavar="SCENARIO",
        help="scenario YAML files, or bundled names such as failures/follower_stop",
    )
    p.add_argument(
        "--strategies",
        default=None,
        help="comma-separated strategies, or file for each file's own "
        "(default: every registered strategy, see sandbox plugins)",
    )
    p.add_argument(
        "--derivatives",
        default="hold",
        help="comma-separated target_derivatives modes: hold, estimate (default hold)",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="override a field in every run (repeatable)",
    )
    p.add_argument(
        "--grid",
        action="append",
        metavar="PATH=v1,v2,...",
        help="also vary a field over these values for every strategy, e.g. "
        "recovery.tangential=0,1 (repeatable: the Cartesian product; a setting column)",
    )
    p.add_argument(
        "--columns",
        choices=("default", "safety"),
        default="default",
        help="default, or safety: success, collisions, min separation - d, "
        "deadlocks, extra settle and the measured control time per step",
    )
    p.add_argument(
        "--format",
        choices=("md", "csv", "json", "markdown"),
        default="md",
        help="table format: md (Markdown, 4 significant digits; the default; "
        "'markdown' is the same), or csv / json (full precision)",
    )
    p.add_argument(
        "--paired",
        action="store_true",
        help="only the paired comparisons of the settings over the same scenarios and "
        "seeds (--grid seed=...; exact McNemar test; a Markdown table also shows them "
        "below the metrics)",
    )
    p.add_argument(
        "--jobs",
        type=jobs,
        default=1,
        help="worker processes, >= 1, capped at the usable cores (default 1); the "
        "table is the same",
    )
    add_plugin_option(p, trust=True)
    p.set_defaults(func=cmd_compare)
