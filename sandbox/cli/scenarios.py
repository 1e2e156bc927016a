"""``sandbox list`` and ``sandbox copy``: the scenarios that ship with the package."""

from __future__ import annotations

import argparse
import sys
import warnings

from sandbox.cli.common import EXIT_FAILED, EXIT_OK, add_command, add_plugin_option
from sandbox.errors import SandboxWarning, ScenarioError


def cmd_list(args: argparse.Namespace) -> int:
    """``sandbox list``: the bundled scenarios' names, each with its description."""
    from sandbox.scenario import load_scenario
    from sandbox.scenario.bundled import REFERENCE, names, scenarios_dir
    from sandbox.study.sweep import SweepError, check_sweep_file

    root = scenarios_dir()
    shown = [n for n in names() if n != REFERENCE]
    if not shown:
        print(f"no scenarios found under {root}", file=sys.stderr)
        return EXIT_FAILED
    for name in shown:
        path = root / f"{name}.yaml"
        try:  # a sweep file (sandbox sweep) is described by its grid
            with warnings.catch_warnings():  # a list, not a check: validate warns
                warnings.simplefilter("ignore", SandboxWarning)
                sweep = check_sweep_file(path)
                sc = load_scenario(path, check_only=True) if sweep is None else None
            desc = (sc.description.splitlines() or [""])[0] if sc else sweep
        except ScenarioError as exc:
            desc = f"(invalid: {exc.lines[0]})"
        except SweepError as exc:
            desc = f"(invalid: {exc})"
        print(f"{name}\n    {desc}")
    print(
        f"\n{len(shown)} scenarios in {root}; 'sandbox run NAME' runs one, "
        f"'sandbox copy NAME' writes an editable copy ('sandbox copy {REFERENCE}': "
        "every key of the format, documented)"
    )
    return EXIT_OK


def cmd_copy(args: argparse.Namespace) -> int:
    """``sandbox copy NAME [DEST]``: an editable copy of a bundled scenario."""
    from sandbox.scenario.bundled import copy

    target = copy(args.name, args.dest)
    print(f"{target} (edit it, then: sandbox run {target})")
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``list`` and ``copy`` commands."""
    p = add_command(
        sub,
        "list",
        "list the bundled scenarios by the names that run accepts",
        ["sandbox list", "sandbox list | grep fig1"],
    )
    add_plugin_option(p)
    p.set_defaults(func=cmd_list)
    p = add_command(
        sub,
        "copy",
        "write an editable copy of a bundled scenario",
        [
            "sandbox copy paper/rotating_circle            # ./rotating_circle.yaml",
            "sandbox copy paper/rotating_circle mine.yaml  # edit, then run it",
            "sandbox copy reference                        # every key, documented",
        ],
        description=(
            "Write an editable copy of a bundled scenario. An existing file is never "
            "replaced."
        ),
    )
    p.add_argument("name", help="bundled scenario name, as 'sandbox list' prints it")
    p.add_argument(
        "dest",
        nargs="?",
        help="file or existing directory to write to (default ./<name>.yaml)",
    )
    add_plugin_option(p)
    p.set_defaults(func=cmd_copy)
