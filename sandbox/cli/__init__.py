"""Command-line interface: ``sandbox COMMAND ...``.

No simulation logic lives here: the commands call the same API as Python users. Every
user mistake ends in one line per problem on stderr and a non-zero exit, never a
traceback. Each command lives in a module of this package with a ``register(sub)``
function that adds its subparser (with :func:`sandbox.cli.common.add_command`: help text
and an epilog of examples); :data:`COMMANDS` lists them in help order. A new command is
a new module and one entry there. Command modules import numpy, the simulation and
matplotlib inside their command functions, never at module level, so that building the
parser (``sandbox --help``) stays fast; ``tests/test_cli_help.py`` checks it.

Exit status: 0 success; 1 a run diverged or a command failed; 2 invalid input;
130 a run was interrupted (its outputs so far are written, flagged ``interrupted``).

Warnings of the package (:class:`~sandbox.errors.SandboxWarning`, e.g. a scenario's)
are printed as one line each, ``warning: ...``, on stderr. Python started with warning
options decides instead: ``python -W error -m sandbox ...`` (or ``PYTHONWARNINGS``)
makes each one an error (exit 2), ``-W ignore::sandbox.SandboxWarning`` hides them.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from sandbox._about import __version__
from sandbox.cli import (
    check,
    compare,
    figures,
    info,
    plugins,
    run,
    scenarios,
    sweep,
    validate,
    view,
)
from sandbox.cli.common import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_INVALID,
    EXIT_OK,
    GifOptionError,
    command_signals,
    forget_caught_interrupt,
    load_cli_plugins,
    trust_advice,
)
from sandbox.errors import PluginError, SandboxError, SandboxWarning, ScenarioError

#: The command modules, in the order their commands appear in ``sandbox --help``.
COMMANDS = (
    run,
    validate,
    check,
    scenarios,
    figures,
    view,
    compare,
    sweep,
    plugins,
    info,
)

EPILOG = """\
examples:
  sandbox list                                   the bundled scenarios
  sandbox run paper/rotating_circle --gif r.gif  run one, write runs/<name>/ and a GIF
  sandbox plot runs/rotating_circle              figures of a saved run
  sandbox COMMAND --help                         the options of one command
"""

__all__ = ["EXIT_FAILED", "EXIT_INTERRUPTED", "EXIT_INVALID", "EXIT_OK", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``sandbox`` command."""
    parser = argparse.ArgumentParser(
        prog="sandbox",
        description=(
            "Physics-backed 2D sandbox for collective motion of unicycle vehicles."
        ),
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"sandbox {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in COMMANDS:
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status."""
    with command_signals() as signals:
        try:
            status = _dispatch(argv)
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            status = EXIT_INTERRUPTED
        except Exception:
            if not signals.received:
                raise
            status = None  # an error the interrupt caused on its way out
        if status != EXIT_INTERRUPTED and (
            signals.received or (signals.lost and status == EXIT_OK)
        ):
            print("interrupted", file=sys.stderr)
            status = EXIT_INTERRUPTED
    forget_caught_interrupt()
    return status


@contextmanager
def _one_line_warnings() -> Iterator[None]:
    """Show each :class:`SandboxWarning` as one line ``warning: ...`` on stderr.

    Other warnings are shown as Python shows them. Without ``-W`` or
    ``PYTHONWARNINGS`` options each distinct warning is shown once (whatever filters
    the caller set, e.g. a test session's); with them, their filters decide.
    """
    with warnings.catch_warnings():
        if not sys.warnoptions:
            warnings.simplefilter("default", SandboxWarning)
        shown = warnings.showwarning

        def show(message: Any, category: type[Warning], *args: Any, **kw: Any) -> None:
            if issubclass(category, SandboxWarning):
                print(f"warning: {message}", file=sys.stderr)
            else:
                shown(message, category, *args, **kw)

        warnings.showwarning = show
        yield


def _dispatch(argv: list[str] | None) -> int:
    """Parse the command line and run the command; errors become messages."""
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # with the usage of the command given, not the top level's
        command = getattr(args, "command_parser", None) or parser
        command.error(f"unrecognized arguments: {' '.join(unknown)}")
    if args.command is None:  # plain `sandbox`: say what it can do
        parser.print_help()
        return EXIT_OK
    try:
        with _one_line_warnings():
            load_cli_plugins(args)
            return args.func(args)
    except SandboxWarning as exc:  # -W error
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except ScenarioError as exc:
        for line in trust_advice(exc, args).lines:
            print(line, file=sys.stderr)
        return EXIT_INVALID
    except PluginError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except GifOptionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except SandboxError as exc:  # bad input (a user's file in the way, ...) says so
        print(f"error: {exc}", file=sys.stderr)
        return getattr(exc, "exit_status", EXIT_FAILED)
    except BrokenPipeError:
        # The reader of our output went away (e.g. `sandbox schema | head`).
        sys.stderr.close()
        return EXIT_FAILED
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
