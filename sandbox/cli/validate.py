"""``sandbox validate``, ``list`` and ``schema``: the scenario format."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sandbox.cli.common import (
    EXIT_FAILED,
    EXIT_INVALID,
    EXIT_OK,
    add_plugin_option,
    bundled_scenarios_dir,
)
from sandbox.errors import ScenarioError
from sandbox.output import write_text_atomic
from sandbox.scenario import load_scenario


def cmd_validate(args: argparse.Namespace) -> int:
    """``sandbox validate FILE...``: check files without running them."""
    from sandbox.study.sweep import SweepError, check_sweep_file

    status = EXIT_OK
    for name in args.files:
        try:  # a sweep file (sandbox sweep): its base and every grid point
            sweep = check_sweep_file(name)
        except SweepError as exc:
            print(f"error: {exc}", file=sys.stderr)
            status = EXIT_INVALID
            continue
        except ScenarioError as exc:
            for line in exc.lines:
                print(line, file=sys.stderr)
            status = EXIT_INVALID
            continue
        if sweep is not None:
            print(f"{name}: ok ({sweep})")
            continue
        try:
            scenario = load_scenario(name, overrides=args.set)
        except ScenarioError as exc:
            for line in exc.lines:
                print(line, file=sys.stderr)
            status = EXIT_INVALID
            continue
        for line in scenario.warnings:
            print(f"warning: {line}", file=sys.stderr)
        print(
            f"{name}: ok ({len(scenario.vehicles)} vehicles, {scenario.duration:g} s)"
        )
    return status


def cmd_list(args: argparse.Namespace) -> int:
    """``sandbox list``: the bundled scenarios with their descriptions."""
    from sandbox.study.sweep import SweepError, check_sweep_file

    root = bundled_scenarios_dir()
    files = sorted(p for p in root.rglob("*.yaml") if p.name != "reference.yaml")
    if not files:
        print(f"no scenarios found under {root}", file=sys.stderr)
        return EXIT_FAILED
    for path in files:
        try:
            sweep = check_sweep_file(path)
            sc = load_scenario(path) if sweep is None else None
            desc = (sc.description.splitlines() or [""])[0] if sc else sweep
        except ScenarioError as exc:
            desc = f"(invalid: {exc.lines[0]})"
        except SweepError as exc:
            desc = f"(invalid: {exc})"
        print(f"{path.relative_to(root.parent)}\n    {desc}")
    return EXIT_OK


def cmd_schema(args: argparse.Namespace) -> int:
    """``sandbox schema [--out FILE]``: the JSON Schema of the scenario format."""
    from sandbox.schema import schema_json

    text = schema_json()
    if not args.out:
        sys.stdout.write(text)
        return EXIT_OK
    write_text_atomic(Path(args.out), text)
    print(f"schema: {args.out}")
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``validate``, ``list`` and ``schema`` commands."""
    p = sub.add_parser("validate", help="check scenario files without running them")
    p.add_argument("files", nargs="+")
    p.add_argument("--set", action="append", metavar="PATH=VALUE")
    add_plugin_option(p)
    p.set_defaults(func=cmd_validate)
    p = sub.add_parser("list", help="list the bundled scenarios")
    add_plugin_option(p)
    p.set_defaults(func=cmd_list)
    p = sub.add_parser("schema", help="print the JSON Schema of scenario files")
    p.add_argument("--out", help="write it to this file instead of printing it")
    add_plugin_option(p)
    p.set_defaults(func=cmd_schema)
