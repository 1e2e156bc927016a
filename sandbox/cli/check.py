"""``sandbox check FILE...``: run scenarios and check their ``expect:`` sections."""

from __future__ import annotations

import argparse
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from typing import TYPE_CHECKING

from sandbox.cli.common import (
    EXIT_FAILED,
    EXIT_INVALID,
    EXIT_OK,
    add_command,
    add_plugin_option,
    positive,
)
from sandbox.errors import ScenarioError

if TYPE_CHECKING:  # the testing layer imports numpy: only when a command runs
    from sandbox.testing.assertions import CheckResult


def _check(args: tuple[str, tuple[str, ...]]) -> CheckResult:
    """Check one file, without keeping its run (worker processes send results back)."""
    from sandbox.testing.assertions import check_scenario

    return check_scenario(args[0], args[1], keep_run=False)


def cmd_check(args: argparse.Namespace) -> int:
    """``sandbox check FILE...``: exit 0 if every expectation holds, 1 if one fails."""
    from sandbox.testing.assertions import load_checked

    overrides = tuple(args.set or ())
    invalid = False
    for name in args.files:  # every file is validated before the first run
        try:
            load_checked(name, overrides)
        except ScenarioError as exc:
            for line in exc.lines:
                print(line, file=sys.stderr)
            invalid = True
    if invalid:
        return EXIT_INVALID
    todo = [(name, overrides) for name in args.files]
    jobs = min(int(args.jobs), len(todo))
    if jobs <= 1:
        results = map(_check, todo)
    else:
        from sandbox.study.engine import die_with

        # workers die with this process, even when it is killed (SIGKILL)
        pool = ProcessPoolExecutor(
            max_workers=jobs, initializer=die_with, initargs=(os.getpid(),)
        )
        results = pool.map(_check, todo)
    failed = expectations = 0
    try:
        for result in results:
            expectations += len(result.outcomes)
            failed += len(result.failed)
            for outcome in result.outcomes:
                if not outcome.holds:
                    print(outcome.line(result.source))
                elif args.verbose:
                    print(f"{outcome.line(result.source)} [holds]")
    finally:
        if jobs > 1:
            pool.shutdown(cancel_futures=True)
    files = len(todo)
    print(
        f"{files} file{'s' if files != 1 else ''}, {expectations} expectations: "
        + (f"{failed} failed" if failed else "all hold"),
        file=sys.stderr,
    )
    return EXIT_FAILED if failed else EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``check`` command."""
    p = add_command(
        sub,
        "check",
        "run scenario files and check their expect: sections",
        [
            "sandbox check scenarios/paper/*.yaml --jobs 2",
            "sandbox check my.yaml --set recovery.beta=2.5 -v",
        ],
        description="Run each file and evaluate its expect: section. Prints one line "
        "per failed expectation (FILE: expectation: expected X, got Y). Exit status: "
        "0 every expectation holds, 1 one fails, 2 invalid input.",
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="scenario YAML files")
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="override a field of every file, e.g. --set recovery.beta=2.5",
    )
    p.add_argument(
        "--jobs",
        type=positive(int),
        default=1,
        help="files run in parallel worker processes (default 1)",
    )
    p.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="also print every expectation that holds, with its measured value",
    )
    add_plugin_option(p, trust=True)
    p.set_defaults(func=cmd_check)
