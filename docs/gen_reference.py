"""The generated parts of the docs: the scenario keys and the command line.

Both are written from the code at build time, so they cannot drift from it:

- :func:`scenario_reference` walks the ``Param`` declarations the loader reads with
  (the section tables of :mod:`sandbox.scenario` and every built-in plug-in's
  ``params``, through :func:`sandbox.scenario.schema.sections`, the walk the JSON
  Schema is built from) and writes one table per section: key, type, unit, default,
  bounds or allowed values, meaning;
- :func:`cli_reference` writes the help of every command and subcommand of
  ``sandbox.cli.build_parser()``, as ``sandbox COMMAND --help`` prints it.

``docs/hooks.py`` puts them in place of the markers ``<!-- generated:
scenario-reference -->`` and ``<!-- generated: cli-reference -->`` of the pages.
``python docs/gen_reference.py scenario|cli`` prints one of them.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

#: Section name -> (heading, where it lives in a file, what it is), in page order.
SECTION_TITLES = {
    "": ("Top level", "the document's own keys"),
    "vehicle": ("`vehicle:`", "defaults for every vehicle (each may override them)"),
    "gains": ("`vehicle.gains:`", "the controller's gains, eqs. (5)-(6)"),
    "vehicles": (
        "`vehicles: [...]`",
        "one item per vehicle, plus any key of `vehicle:`",
    ),
    "drive": ("`vehicles[i].drive:`", "how a vehicle is driven"),
    "platoon": ("`platoon:`", "followers generated behind a listed leader"),
    "reference": ("`reference:`", "the path the leader tracks"),
    "formation": ("`formation:`", "the formation law"),
    "recovery": ("`recovery:`", "the recovery strategy (report section 4)"),
    "failures": ("`failures: [...]`", "injected failures, one item each"),
    "obstacles": ("`obstacles: [...]`", "static shapes, one item each"),
    "metrics": ("`metrics:`", "how the metrics are computed"),
    "sensing": ("`sensing:`", "what the vehicles see of each other"),
    "detection": ("`detection:`", "how the platoon learns of a failure"),
    "safety": ("`safety:`", "a safety filter on the commands"),
    "reconfigure": ("`reconfigure:`", "slot reassignment after a failure"),
    "sensors": (
        "`sensors:`",
        "the fleet's sensors (also `vehicles[i].sensors:`, merged over them)",
    ),
    "range": ("`sensors.range:`", "a planar range sensor (LiDAR)"),
    "platoons": (
        "`platoons: [...]`",
        "several platoons in one world, one item each (the top-level sections are "
        "their defaults)",
    ),
    "events": ("`events: [...]`", "merges and splits of platoons, one item each"),
}


def _cell(text: Any) -> str:
    """Text safe inside a Markdown table cell."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def _default(p: Any) -> str:
    from sandbox.plugins import REQUIRED

    if p.default is REQUIRED:
        return "**required**"
    if p.default is None:
        return "none"
    if isinstance(p.default, bool):
        return f"`{str(p.default).lower()}`"
    if isinstance(p.default, tuple | list):
        return (
            "`["
            + ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in p.default)
            + "]`"
        )
    if isinstance(p.default, float):
        return f"`{p.default:g}`"
    if p.default == "":
        return '`""`'
    return f"`{p.default}`"


def _number(value: float, integer: bool) -> str:
    """A bound as written: whole numbers of an integer key exactly (``2^63-1``)."""
    if integer and float(value).is_integer():
        whole = int(value)
        return "2^63-1" if whole == 2**63 - 1 else f"{whole:,}"
    return f"{value:g}"


def _allowed(p: Any) -> str:
    if p.choices:
        return ", ".join(f"`{c}`" for c in p.choices)
    integer = p.type == "integer"
    lo, hi = p.minimum, p.maximum
    if lo is not None and hi is not None:
        return f"{_number(lo, integer)} to {_number(hi, integer)}"
    if lo is not None:
        return f"{'>' if p.exclusive else '>='} {_number(lo, integer)}"
    if hi is not None:
        return f"<= {_number(hi, integer)}"
    return ""


def _table(params: dict[str, Any]) -> list[str]:
    rows = [
        "| key | type | unit | default | bounds / allowed | meaning |",
        "|---|---|---|---|---|---|",
    ]
    for key, p in params.items():
        kind = {"custom": "section", "text": "string"}.get(p.type, p.type)
        rows.append(
            f"| `{key}` | {kind} | {_cell(p.unit) or '-'} | {_default(p)} "
            f"| {_allowed(p) or '-'} | {_cell(p.doc)} |"
        )
    return rows


def scenario_reference() -> str:
    """Markdown: every declared key of the scenario format, one table per section."""
    from sandbox import plugins
    from sandbox.plugins.registration import KINDS
    from sandbox.scenario import PLUGIN_SECTIONS
    from sandbox.scenario.schema import sections

    found = sections()
    selector = {KINDS[kind].section: KINDS[kind] for kind in PLUGIN_SECTIONS}
    out: list[str] = []
    for section, (title, what) in SECTION_TITLES.items():
        if section not in found:
            continue
        out += [f"### {title}", "", f"{what[0].upper()}{what[1:]}.", ""]
        own = found[section]
        if own:
            out += _table(own) + [""]
        kind = selector.get(section)
        if kind is None:
            continue
        registered = plugins.registry(kind.name)
        names = ", ".join(f"`{n}`" for n in registered)
        out += [
            f"`{kind.selector}` selects the {kind.title}: one of {names}. The keys "
            f"of each (`sandbox plugins --kind {kind.name}` lists them with their "
            "origin):",
            "",
        ]
        for name, plugin in registered.items():
            doc = (plugin.doc or "").strip().splitlines()
            summary = f" {_cell(doc[0])}" if doc else ""
            out += [
                f"#### `{kind.selector}: {name}`",
                "",
                f"*{plugin.origin}.*{summary}",
                "",
            ]
            out += _table(plugin.params) if plugin.params else ["No keys of its own."]
            out += [""]
    missing = (
        set(found)
        - set(SECTION_TITLES)
        - {f"{s}.{n}" for s in selector for n in plugins.registry(selector[s].name)}
    )
    if missing:  # a new section gets its heading here, or the build says so
        raise RuntimeError(f"docs/gen_reference.py: no title for {sorted(missing)}")
    return "\n".join(out)


def _commands(
    parser: argparse.ArgumentParser, prefix: str
) -> list[tuple[str, argparse.ArgumentParser]]:
    out = [(prefix, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += _commands(sub, f"{prefix} {name}")
    return out


def cli_reference() -> str:
    """Markdown: the ``--help`` of every command of ``sandbox``, as it prints it."""
    from sandbox.cli import build_parser

    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "88"  # argparse wraps at the terminal's width
    try:
        commands = _commands(build_parser(), "sandbox")
        out: list[str] = []
        for name, parser in commands:
            level = "###" if name.count(" ") <= 1 else "####"
            out += [
                f"{level} `{name}`",
                "",
                "```text",
                parser.format_help().rstrip(),
                "```",
                "",
            ]
    finally:
        if columns is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = columns
    return "\n".join(out)


GENERATORS = {"scenario-reference": scenario_reference, "cli-reference": cli_reference}

if __name__ == "__main__":
    print(GENERATORS[f"{sys.argv[1]}-reference"]())
