"""``sandbox sweep FILE`` runs a study; ``sandbox sweep plot|table|view DIR`` shows it.

``FILE`` is a scenario or a sweep file (``base:`` plus ``grid``, ``zip``, ``seeds``);
see :mod:`sandbox.study.spec`. ``sandbox sweep view DIR`` writes the HTML page of the
results (:mod:`sandbox.study.sweep_page`). A file literally named ``plot``, ``table`` or
``view`` is given as ``./plot``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sandbox.cli.common import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_INVALID,
    EXIT_OK,
    add_command,
    add_plugin_option,
    positive,
    progress,
    scenario_file,
)
from sandbox.errors import SandboxError

#: Default of ``--max-runs`` (``sandbox.study.spec.MAX_RUNS``, not imported here so
#: that ``sandbox --help`` stays cheap).
MAX_RUNS = 100_000


def cmd_sweep(args: argparse.Namespace) -> int:
    """Dispatch ``sandbox sweep FILE`` / ``plot DIR`` / ``table DIR`` / ``view DIR``."""
    target = args.target
    if target[0] == "view" and len(target) == 2:
        return _view(args, Path(target[1]))
    if target[0] in ("plot", "table", "view"):
        if len(target) != 2:
            print(
                f"error: sandbox sweep {target[0]} DIR: expected one DIR",
                file=sys.stderr,
            )
            return EXIT_INVALID
        return (
            _plot(args, Path(target[1]))
            if target[0] == "plot"
            else _table(args, Path(target[1]))
        )
    if len(target) != 1:
        print(
            "error: sandbox sweep FILE: expected one scenario or sweep file (or "
            "plot DIR, table DIR)",
            file=sys.stderr,
        )
        return EXIT_INVALID
    return _run(args, target[0])


def _run(args: argparse.Namespace, file: str) -> int:
    from sandbox.study import engine
    from sandbox.study.spec import SweepError, build_spec
    from sandbox.study.sweep import describe_dry_run, run_sweep

    if args.out is None:
        print("error: sandbox sweep FILE: --out DIR is required", file=sys.stderr)
        return EXIT_INVALID
    if args.scheduler and args.scheduler_file:
        print("error: give --scheduler or --scheduler-file, not both", file=sys.stderr)
        return EXIT_INVALID
    try:
        # a bundled scenario's name (failures/follower_stop) works as in sandbox run
        spec = build_spec(
            str(scenario_file(file)), args.grid, args.zip, args.seeds, args.set
        )
    except SweepError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    out = Path(args.out)
    try:
        spec.check_size(args.max_runs)  # counted, before anything is built
    except SweepError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    if args.dry_run:
        try:
            lines = describe_dry_run(spec, out, args.retry_failed, args.max_runs)
        except SweepError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_INVALID
        for line in lines:
            print(line)
        return EXIT_OK
    if (args.scheduler or args.scheduler_file) and args.jobs is not None:
        print(
            f"error: --jobs {args.jobs} with a Dask scheduler: the cluster's workers "
            "run the runs there (give --jobs for local processes, or the scheduler)",
            file=sys.stderr,
        )
        return EXIT_INVALID
    jobs = 1 if args.jobs is None else args.jobs
    if jobs < 1:
        print(f"error: --jobs {jobs}: expected at least 1", file=sys.stderr)
        return EXIT_INVALID
    cores = engine.usable_cores()
    if jobs > cores:
        print(
            f"warning: --jobs {jobs} capped at the {cores} usable cores",
            file=sys.stderr,
        )
        jobs = cores
    try:  # the progress bar of every command (tqdm, on a terminal only)
        with progress(0, "sweep", unit="run") as bar:
            report = run_sweep(
                spec,
                out,
                jobs=jobs,
                scheduler=args.scheduler,
                scheduler_file=args.scheduler_file,
                retry_failed=args.retry_failed,
                progress=bar,
                max_runs=args.max_runs,
                keep_runs=args.keep_runs,
            )
    except SweepError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except engine.EngineError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    if report.interrupted:
        print(
            f"interrupted: {report.already + report.computed} of {report.total} runs "
            f"stored in {out}; run the same command again to compute the rest",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    if report.computed == 0:
        print(f"{out}: all {report.total} runs already done; nothing to compute")
    else:
        print(
            f"{out}: {report.computed} runs computed, {report.already} already stored, "
            f"{report.total} in all"
        )
    if report.failed:
        print(
            f"{report.failed} runs failed or diverged (rows with their status; "
            "--retry-failed reruns them)"
        )
    print(f"results: {out / 'results.csv'}")
    return EXIT_OK


def _table(args: argparse.Namespace, root: Path) -> int:
    from sandbox.study.paired import PAIRED_TITLE
    from sandbox.study.spec import SweepError
    from sandbox.study.store import read_results, varied_paths
    from sandbox.study.summary import format_table, group_rows, paired_table

    try:
        _, rows = read_results(root)
        paths = varied_paths(root)
    except (SweepError, OSError) as exc:
        print(f"error: {root}: not a sweep directory ({exc})", file=sys.stderr)
        return EXIT_FAILED
    by = args.by or paths
    unknown = [p for p in by if p not in paths]
    if unknown:
        print(
            f"error: --by {unknown[0]}: not a varied path of {root} (one of: "
            f"{', '.join(paths) or 'none'})",
            file=sys.stderr,
        )
        return EXIT_INVALID
    if args.safety:  # the filter's figures instead, from the runs' files
        from sandbox.study.safety_summary import safety_table

        sys.stdout.write(safety_table(root, rows, by, args.format))
        return EXIT_OK
    paired = paired_table(rows, by, paths, args.format)
    if args.paired:
        sys.stdout.write(paired or "")
        return EXIT_OK
    sys.stdout.write(format_table(group_rows(rows, by), by, args.format))
    if paired and args.format in ("md", "markdown"):
        sys.stdout.write(f"\n{PAIRED_TITLE}\n\n{paired}")
    return EXIT_OK


def _plot(args: argparse.Namespace, root: Path) -> int:
    """``sandbox sweep plot DIR``: the figures, replacing only earlier ones.

    They are drawn into a stage in the output directory and put in place together:
    a file there that ``sweep plot`` did not write is replaced only with ``--force``.
    """
    from sandbox.run.output_guard import staged
    from sandbox.study.figures import plot_sweep
    from sandbox.study.spec import SweepError

    out = Path(args.out) if args.out else root / "figures"
    try:
        with staged(out, "sweep plot", args.force) as stage:
            drawn = plot_sweep(root, stage.path, args.by)
    except (SweepError, SandboxError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    for path in drawn:
        print(f"figure: {out / path.name}")
    return EXIT_OK


def _view(args: argparse.Namespace, root: Path) -> int:
    """``sandbox sweep view DIR``: the page of the results, linking kept replays."""
    from sandbox.render.replay import ReplayError
    from sandbox.study.sweep_page import write_sweep_html

    try:
        done = write_sweep_html(
            root,
            Path(args.out) if args.out else None,
            log=lambda line: print(line, file=sys.stderr),
        )
    except ReplayError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    print(
        f"sweep page: {done['path']} ({done['rows']} runs, {done['replays']} with a "
        "replay); open it in a browser"
    )
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``sweep`` command."""
    p = add_command(
        sub,
        "sweep",
        "run a study (grid x seeds) into a results directory; plot or tabulate it",
        [
            "sandbox sweep failures/follower_stop --grid recovery.beta=1,2,5 "
            "--seeds 0:20 --out study/",
            "sandbox sweep table study/ --by recovery.beta",
            "sandbox sweep plot study/",
            "sandbox sweep view study/        # study/sweep.html, linking replays",
        ],
        description=(
            "sandbox sweep FILE --out DIR [...] runs a study; sandbox sweep plot DIR, "
            "sandbox sweep table DIR and sandbox sweep view DIR (an HTML page of the "
            "results, linking each kept run's replay) look at one."
        ),
    )
    p.add_argument(
        "target",
        nargs="+",
        metavar="FILE | plot DIR | table DIR | view DIR",
        help="a scenario or sweep file; or 'plot DIR' / 'table DIR' / 'view DIR'",
    )
    p.add_argument(
        "--grid",
        action="append",
        metavar="PATH=v1,v2,...",
        help="vary a field over these values (Cartesian product; repeatable)",
    )
    p.add_argument(
        "--zip",
        action="append",
        metavar="PATH=v1,v2,...",
        help="vary fields together (equal-length lists; repeatable)",
    )
    p.add_argument("--seeds", metavar="A:B", help="seeds A to B-1 (default 0:1)")
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="a fixed override (repeatable)",
    )
    p.add_argument(
        "--out",
        help="results directory (sweep); figures directory (plot, default "
        "DIR/figures); the page (view, default DIR/sweep.html)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="plot: replace files of the --out directory that sweep plot did not write",
    )
    p.add_argument(
        "--keep-runs",
        action="store_true",
        help="also keep each computed run's directory in DIR/run_dirs/<run id>/ (for "
        "sandbox view and sweep view)",
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="local processes (default 1: in-process; at most the cores; not with "
        "--scheduler)",
    )
    p.add_argument(
        "--scheduler", metavar="ADDR", help="Dask scheduler, tcp://host:port"
    )
    p.add_argument("--scheduler-file", metavar="F", help="Dask scheduler file")
    p.add_argument(
        "--dry-run", action="store_true", help="say what would run, run nothing"
    )
    p.add_argument(
        "--max-runs",
        type=positive(int),
        default=MAX_RUNS,
        metavar="N",
        help=f"refuse a sweep of more than N runs (default {MAX_RUNS:,})",
    )
    p.add_argument(
        "--retry-failed",
        action="store_true",
        help="rerun the stored runs that failed or diverged",
    )
    p.add_argument(
        "--by",
        action="append",
        metavar="PATH",
        help="plot/table: group by these varied paths (default: all of them)",
    )
    p.add_argument(
        "--format",
        choices=("md", "csv", "json", "markdown"),
        default="md",
        help="table: md (Markdown, 4 significant digits; the default; 'markdown' is "
        "the same), or csv / json (full precision)",
    )
    p.add_argument(
        "--paired",
        action="store_true",
        help="table: only the paired comparisons of the settings over the same seeds "
        "(exact McNemar test; a Markdown table also shows them below the rates)",
    )
    p.add_argument(
        "--safety",
        action="store_true",
        help="table: the safety filter's figures instead (runs with relaxed steps, "
        "with Wilson intervals; fallback steps; the largest slack), from the runs' "
        "files",
    )
    add_plugin_option(p, trust=True)
    p.set_defaults(func=cmd_sweep)
