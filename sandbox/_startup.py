"""Signals of the ``sandbox`` command: quiet at start-up, and the stop of a long run.

Importing numpy, scipy and pymunk takes the command's first half second or so; a
Ctrl-C then would print a ``KeyboardInterrupt`` traceback from the middle of an import.
When this package is imported as the ``sandbox`` command (its console script, or
``python -m sandbox``), SIGINT and SIGTERM exit at once with status 130 and one line
until :func:`sandbox.cli.main` installs its own handlers. Nothing has been written
then, so there is nothing to clean up. Imported as a library, nothing is changed.

While a run or a sweep computes, :class:`StopOnSignal` turns the first SIGINT or
SIGTERM into a request, read between steps, so that what was computed is kept and
written whole; a second one stops the command at once.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from types import FrameType
from typing import Any


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


class StopOnSignal:
    """SIGINT/SIGTERM ask the work under way to stop; a second signal stops it now.

    The first signal raises the flag (``stop()`` is then True), which the work reads
    where it can stop cleanly (between a run's steps, between a sweep's runs), and
    prints ``notice`` on standard error. The second raises ``KeyboardInterrupt``
    where the main thread is, even inside code that never reads the flag (a long
    build, a trusted plug-in that blocks in a sleep, a lock or a socket), and gives
    both signals back their default action: a third ends the process by that action
    even where Python cannot run a handler. The handlers before are restored on exit.
    Only in the main thread (elsewhere signals cannot be caught; the flag stays down).

    Parameters
    ----------
    notice : str
        What the first signal prints (a line; empty: nothing).
    """

    def __init__(self, notice: str = "") -> None:
        self.raised = False
        self.notice = notice
        self._old: dict[int, Any] = {}

    def __call__(self) -> bool:
        """Whether a stop was asked for."""
        return self.raised

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if not self.raised:
            self.raised = True
            if self.notice:
                os.write(2, f"{self.notice}\n".encode())
            return
        for sig in self._old:
            signal.signal(sig, signal.SIG_DFL)
        raise KeyboardInterrupt

    def __enter__(self) -> StopOnSignal:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


if _started_as_command():
    for _sig in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(_sig, _exit_interrupted)
        except (ValueError, OSError):  # not the main thread
            pass
