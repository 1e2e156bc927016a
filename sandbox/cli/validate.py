"""``sandbox validate`` and ``schema``: the scenario format."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from sandbox.cli.common import (
    EXIT_INVALID,
    EXIT_OK,
    add_command,
    add_plugin_option,
    scenario_file,
    trust_advice,
)
from sandbox.errors import SandboxWarning, ScenarioError


def cmd_validate(args: argparse.Namespace) -> int:
    """``sandbox validate FILE...``: check files without running them."""
    from sandbox.scenario import load_scenario
    from sandbox.scenario.trust import UncheckedScenario
    from sandbox.study.sweep import SweepError, check_sweep_file

    status = EXIT_OK
    if args.trust_noted:
        print(
            "note: --trust-plugins changes nothing here: validate never runs the code "
            "a scenario lists; --plugin PATH_OR_MODULE loads a plug-in you trust, and "
            "the sections that use it are then checked",
            file=sys.stderr,
        )
    for name in args.files:
        try:  # a sweep file (sandbox sweep): its base and every grid point
            path = scenario_file(name)
            with warnings.catch_warnings():  # the base alone shows its warnings
                warnings.simplefilter("ignore", SandboxWarning)
                sweep = check_sweep_file(path)
        except SweepError as exc:
            print(f"error: {exc}", file=sys.stderr)
            status = EXIT_INVALID
            continue
        except ScenarioError as exc:
            for line in trust_advice(exc, args).lines:
                print(line, file=sys.stderr)
            status = EXIT_INVALID
            continue
        if sweep is not None:
            print(f"{name}: ok ({sweep})")
            continue
        try:  # never runs the code of the plug-ins a file lists
            scenario = load_scenario(path, overrides=args.set, check_only=True)
        except UncheckedScenario as exc:
            print(f"{name}: ok, {exc.problems[0].message}")
            continue
        except ScenarioError as exc:
            for line in exc.lines:
                print(line, file=sys.stderr)
            status = EXIT_INVALID
            continue
        n = len(scenario.vehicles)
        print(
            f"{name}: ok ({n} vehicle{'s' if n != 1 else ''}, {scenario.duration:g} s)"
        )
    return status


def cmd_schema(args: argparse.Namespace) -> int:
    """``sandbox schema [--out FILE]``: the JSON Schema of the scenario format.

    ``--out`` replaces only an earlier schema (its ``$id`` is the format's), else the
    command refuses in one line (``--force`` replaces it all the same).
    """
    from sandbox.run.output_guard import write_output
    from sandbox.scenario.schema import schema_json

    text = schema_json()
    if not args.out:
        sys.stdout.write(text)
        return EXIT_OK
    write_output(
        Path(args.out),
        text,
        "schema",
        force=args.force,
        recognise=is_schema,
        mark=False,
    )
    print(f"schema: {args.out}")
    return EXIT_OK


#: The largest file read to recognise an earlier schema [bytes] (it is about 100 kB).
SCHEMA_MAX_BYTES = 2**22


def is_schema(path: Path) -> bool:
    """Whether ``path`` is a schema ``sandbox schema`` wrote (by its ``$id``)."""
    import json

    from sandbox.scenario.schema import SCHEMA_ID

    try:
        if path.stat().st_size > SCHEMA_MAX_BYTES:
            return False
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(doc, dict) and doc.get("$id") == SCHEMA_ID


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``validate`` and ``schema`` commands."""
    p = add_command(
        sub,
        "validate",
        "check scenario files without running them",
        [
            "sandbox validate my.yaml other.yaml",
            "sandbox validate paper/rotating_circle --set recovery.beta=0",
        ],
        description=(
            "Check scenario files without running them: one line per problem "
            "(FILE:LINE: field: what is wrong), exit status 2 if any is invalid."
        ),
    )
    p.add_argument(
        "files",
        nargs="+",
        metavar="SCENARIO",
        help="scenario YAML files, or bundled names such as paper/rotating_circle",
    )
    p.add_argument(
        "--set",
        action="append",
        metavar="PATH=VALUE",
        help="override a field before checking, e.g. --set dt=0.01 (repeatable)",
    )
    add_plugin_option(p)
    p.add_argument(
        "--trust-plugins",
        dest="trust_noted",
        action="store_true",
        help="accepted, but validate never runs the code a scenario lists: "
        "--plugin loads a plug-in you trust, and its sections are then checked",
    )
    p.set_defaults(func=cmd_validate)
    p = add_command(
        sub,
        "schema",
        "print the JSON Schema of scenario files",
        [
            "sandbox schema --out scenario.schema.json  # for an editor's YAML support",
            "sandbox schema | head",
        ],
    )
    p.add_argument(
        "--out",
        help="write it to this file instead of printing it (an existing file is "
        "replaced only if it is an earlier schema)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace the --out file even if it is not an earlier schema",
    )
    add_plugin_option(p)
    p.set_defaults(func=cmd_schema)
