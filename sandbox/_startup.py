"""Quiet Ctrl-C and SIGTERM while the ``sandbox`` command is starting up.

Importing numpy, scipy and pymunk takes the command's first half second or so; a
Ctrl-C then would print a ``KeyboardInterrupt`` traceback from the middle of an import.
When this package is imported as the ``sandbox`` command (its console script, or
``python -m sandbox``), SIGINT and SIGTERM exit at once with status 130 and one line
until :func:`sandbox.cli.main` installs its own handlers. Nothing has been written
then, so there is nothing to clean up. Imported as a library, nothing is changed.
"""

from __future__ import annotations

import os
import signal
import sys


def _started_as_command() -> bool:
    main = sys.modules.get("__main__")
    script = os.path.basename(getattr(main, "__file__", None) or "")
    if script in ("sandbox", "sandbox.exe", "sandbox-script.py"):
        return True
    argv = list(getattr(sys, "orig_argv", []))
    return any(
        a == "-m" and b == "sandbox" for a, b in zip(argv, argv[1:], strict=False)
    )


def _exit_interrupted(signum: int, frame: object) -> None:
    os.write(2, b"interrupted\n")
    os._exit(130)


if _started_as_command():
    for _sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(_sig, _exit_interrupted)
        except (ValueError, OSError):  # not the main thread
            pass
