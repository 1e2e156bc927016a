"""``sandbox info``: the versions, and which compiled paths run here and why not."""

from __future__ import annotations

import argparse
import platform

from sandbox.cli.common import EXIT_OK, add_command, add_plugin_option


def cmd_info(args: argparse.Namespace) -> int:
    """``sandbox info``: the versions, then one line per compiled path."""
    import numpy
    import pymunk

    from sandbox import accel
    from sandbox._about import DISTRIBUTION, __version__

    print(f"{DISTRIBUTION} {__version__}")
    print(f"python {platform.python_version()} ({platform.python_implementation()})")
    print(f"numpy {numpy.__version__}")
    print(f"pymunk {pymunk.version}")
    rows = accel.status()
    print(f"compiled paths ({accel.ENV}=0 turns them off):")
    width = max(len(name) for name, _, _ in rows)
    for name, on, why in rows:
        print(f"  {name:<{width}}  {'on' if on else f'off ({why})'}")
    return EXIT_OK


def not_built_warnings() -> list[str]:
    """The warning ``sandbox run`` prints where compiled paths were not built.

    One line naming them, or none: where every extension was built, or where
    ``SANDBOX_ACCEL=0`` turned the paths off (the user's own choice).
    """
    from sandbox import accel

    missing = accel.not_built()
    if not missing:
        return []
    return [
        f"compiled paths not built ({', '.join(missing)}): this install runs their "
        "numpy forms, several times slower for small fleets; reinstall with a C "
        "compiler (sandbox info)"
    ]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``info`` command."""
    p = add_command(
        sub,
        "info",
        "print the versions and which compiled paths are on",
        ["sandbox info", "sandbox info | grep off   # the paths that do not run"],
        description=(
            "Print the package's version, Python's, numpy's and pymunk's, and one "
            "line per compiled path (the C loops of the stages, sandbox/accel.py): "
            "its name, then on, or off and why: not built (no C compiler at "
            "install), SANDBOX_ACCEL=0, or the error its import raised. "
            "SANDBOX_ACCEL=0 in the environment turns every compiled path off."
        ),
    )
    add_plugin_option(p)
    p.set_defaults(func=cmd_info)
