"""``sandbox plugins``: every registered plug-in, its kind, origin and parameters."""

from __future__ import annotations

import argparse
import json
import sys

from sandbox.cli.common import EXIT_OK, add_command, add_plugin_option


def _param_text(key: str, p) -> str:  # noqa: ANN001 - a sandbox.plugins.Param
    from sandbox.plugins.registration import REQUIRED

    default = "REQUIRED" if p.default is REQUIRED else p.default
    if isinstance(default, tuple):
        default = list(default)
    bits = [f"{key}: {p.type}"]
    if p.default is REQUIRED:
        bits.append("required")
    else:
        bits.append("optional" if default is None else f"default {default}")
    if p.unit:
        bits.append(f"[{p.unit}]")
    if p.bounds_text():
        bits.append(p.bounds_text())
    if p.choices:
        bits.append("one of " + "|".join(p.choices))
    text = ", ".join(bits[:2]) + (" " + " ".join(bits[2:]) if bits[2:] else "")
    return f"{text}; {p.doc}" if p.doc else text


def _kind(text: str) -> str:
    """An argparse type: a plug-in kind (the registry is imported only here)."""
    from sandbox.plugins.registration import KINDS

    if text not in KINDS:
        raise argparse.ArgumentTypeError(
            f"unknown kind {text!r} (expected one of: {', '.join(KINDS)})"
        )
    return text


def cmd_plugins(args: argparse.Namespace) -> int:
    """``sandbox plugins [--kind KIND] [--json]``: list the registered names."""
    from sandbox import plugins

    kinds = [args.kind] if args.kind else list(plugins.KINDS)
    if args.json:
        out = {
            kind: [
                {
                    "name": p.name,
                    "origin": p.origin,
                    "doc": p.doc,
                    "params": {k: _param_text(k, v) for k, v in p.params.items()},
                }
                for p in plugins.registry(kind).values()
            ]
            for kind in kinds
        }
        sys.stdout.write(json.dumps(out, indent=2) + "\n")
        return EXIT_OK
    for kind in kinds:
        info = plugins.KINDS[kind]
        where = (
            f"{info.section}.{info.selector}"
            if info.section
            else "(no scenario section yet)"
        )
        print(f"{kind} ({info.title}; {where}): {info.context}")
        for p in plugins.registry(kind).values():
            print(f"  {p.name:<16} {p.origin}")
            if p.doc:
                print(f"      {p.doc}")
            for key, param in p.params.items():
                print(f"      - {_param_text(key, param)}")
    return EXIT_OK


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``plugins`` command."""
    p = add_command(
        sub,
        "plugins",
        "list the registered laws, strategies, failures, references, ...",
        [
            "sandbox plugins",
            "sandbox plugins --kind law --json",
            "sandbox plugins --plugin my_law.py     # with a plug-in file of yours",
        ],
    )
    p.add_argument("--kind", type=_kind, help="only this kind (law, strategy, ...)")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    add_plugin_option(p)
    p.set_defaults(func=cmd_plugins)
