"""What every ``sandbox`` command shares: exit codes, signals, progress, GIF options.

Importing this module (as every command module does) stays cheap: nothing here imports
numpy, the simulation or matplotlib at module level, so ``sandbox --help`` starts fast.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from sandbox.errors import OutputError, SandboxError

if TYPE_CHECKING:  # the CLI imports numpy and the simulation only when a command runs
    from sandbox.run.record import Run

EXIT_OK, EXIT_FAILED, EXIT_INVALID, EXIT_INTERRUPTED = 0, 1, 2, 130


def scenario_file(text: str) -> Path:
    """A scenario argument as a file: the file if it exists, else the bundled one.

    ``sandbox run paper/rotating_circle`` (with or without ``.yaml``) therefore works
    from any directory; see :mod:`sandbox.scenario.bundled`. Raises
    :class:`~sandbox.errors.ScenarioError` (one line, exit status 2) for neither.
    """
    from sandbox.scenario.bundled import resolve

    return resolve(text)


#: Environment variable that forces the progress bars on (``1``) or off (``0``).
PROGRESS_ENV = "SANDBOX_PROGRESS"


def progress_enabled() -> bool:
    """Whether progress bars are drawn: on a terminal, and not under CI.

    Off when standard error is not a terminal (a pipe, a file, a test), when ``CI`` is
    set (to anything but ``""``, ``0`` or ``false``) or ``TERM=dumb``;
    ``SANDBOX_PROGRESS=1`` or ``0`` forces them on or off.
    """
    forced = os.environ.get(PROGRESS_ENV, "").strip()
    if forced in ("0", "1"):
        return forced == "1"
    if os.environ.get("CI", "").strip().lower() not in ("", "0", "false"):
        return False
    if os.environ.get("TERM") == "dumb":
        return False
    stream = sys.stderr
    return stream is not None and hasattr(stream, "isatty") and stream.isatty()


class Progress:
    """A progress bar with an ETA on standard error, drawn only where someone watches.

    Every command that can take more than a second shows one; other command modules
    use it the same way::

        with progress(len(files), "running", unit="run") as bar:
            for f in files:
                ...
                bar.advance()          # one more done
                bar.write(f"{f}: ok")  # a line printed above the bar

    ``bar(done, total)`` sets the position instead, so a ``Progress`` can be passed as
    the ``progress`` callback of :meth:`sandbox.loop.simulation.Simulation.run`. The bar
    is drawn by tqdm while :func:`progress_enabled` holds; otherwise every call does
    nothing (and tqdm is not even imported). Leaving the ``with`` block erases the bar
    line, so what the command prints next starts on a clean line.

    Parameters
    ----------
    total : int
        Units of work (steps, runs, figures).
    desc : str
        What is being done, shown before the bar.
    unit : str
        Name of one unit of work.
    """

    def __init__(self, total: int, desc: str, unit: str = "step") -> None:
        self.total = int(total)
        self.desc = desc
        self.unit = unit
        self._bar: Any = None

    def __enter__(self) -> Progress:
        if progress_enabled():
            from tqdm import tqdm

            self._bar = tqdm(
                total=self.total,
                desc=self.desc,
                unit=self.unit,
                leave=False,
                file=sys.stderr,
                dynamic_ncols=True,
                mininterval=0.2,
            )
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.close()  # leave=False: the bar's line is erased
            self._bar = None

    def __call__(self, done: int, total: int | None = None) -> None:
        """Set the position to ``done`` units (of ``total``, when it is given)."""
        bar = self._bar
        if bar is None:
            return
        if total is not None and total != bar.total:
            bar.total = total
        bar.update(done - bar.n)

    def advance(self, units: int = 1) -> None:
        """Count ``units`` more units of work done."""
        if self._bar is not None:
            self._bar.update(units)

    def write(self, line: str) -> None:
        """Print ``line`` on standard output, above the bar."""
        if self._bar is None:
            print(line)
        else:
            self._bar.write(line, file=sys.stdout)


def progress(total: int, desc: str, unit: str = "step") -> Progress:
    """A :class:`Progress` bar of ``total`` units: ``with progress(n, "running"):``."""
    return Progress(total, desc, unit)


class command_signals:  # noqa: N801 - used as a context manager, like a function
    """SIGINT and SIGTERM raise ``KeyboardInterrupt`` while a command runs.

    The same at every phase (loading, writing a GIF, ...): whatever is being written
    is removed or left whole by its ``except``/``finally``, and ``main`` exits with
    status 130. A run's simulation and output writing use
    :class:`sandbox._startup.StopOnSignal` instead (a first signal asks them to stop).
    The earlier handlers are restored on exit.

    An interrupt that lands where Python cannot raise it (a ``__del__`` method, a
    weakref callback) would otherwise be printed as "Exception ignored" and lost; it
    is recorded instead (:attr:`lost`), and ``main`` then exits with status 130 too.
    So it does when the interrupt, on its way out, turned into another error (a module
    left half imported raises ``ImportError`` at its next import): whatever a command
    ends with once a signal has arrived (:attr:`received`) is the interrupt.
    """

    def __enter__(self) -> command_signals:
        self._old: dict[int, Any] = {}
        self.lost = False
        #: Whether SIGINT or SIGTERM arrived while the command ran.
        self.received = False
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[sig] = signal.signal(sig, self._interrupt)
            except (ValueError, OSError):  # not the main thread
                pass
        self._old_hook = sys.unraisablehook
        sys.unraisablehook = self._unraisable
        return self

    def _interrupt(self, signum: int, frame: FrameType | None) -> None:
        self.received = True
        raise KeyboardInterrupt

    def _unraisable(self, info: Any) -> None:
        if isinstance(info.exc_value, KeyboardInterrupt):
            self.lost = True
        else:
            self._old_hook(info)

    def __exit__(self, *exc: object) -> None:
        sys.unraisablehook = self._old_hook
        for sig, old in self._old.items():
            signal.signal(sig, old)


def forget_caught_interrupt() -> None:
    """Make a caught ``KeyboardInterrupt`` leave the exit status alone.

    CPython remembers a ``KeyboardInterrupt`` that ended a string ``exec`` (as
    ``dataclasses`` and ``collections.namedtuple`` run while a module is imported)
    even when a caller catches it; under ``python -m sandbox`` the interpreter then
    kills itself with SIGINT at exit, so the status is -2 instead of the 130 that
    :func:`sandbox.cli.main` returned. Every string ``exec`` clears that memory when
    it starts, so an empty one, run once the command is over, does.
    """
    exec("pass", {})  # a constant string: it only clears the flag


def render_gif(run: Run, args: argparse.Namespace) -> None:
    """Render ``run`` to ``args.gif`` and/or ``args.mp4`` (each atomically).

    The camera is ``args.follow``: ``auto`` (the default: the gallery's automatic
    camera, following what happens in a run spread along a line), ``leader`` or
    ``whole`` (frame the whole run); the frames' aspect is ``args.aspect``.
    """
    from sandbox.render.animation import write_gif

    follow = None if args.follow == "whole" else args.follow
    options = {
        "fps": args.fps,
        "size": args.size,
        "speed": args.speed,
        "zones": args.zones,
        "follow": follow,
        "aspect": getattr(args, "aspect", "run"),
    }
    if getattr(args, "show_beams", False):
        options["show_beams"] = True
    outputs = [("gif", args.gif, write_gif)]
    if getattr(args, "mp4", None):
        from sandbox.render.video import write_mp4

        outputs.append(("mp4", args.mp4, write_mp4))
    for kind, target, write in outputs:
        if not target:
            continue
        try:
            with progress(0, f"rendering {kind.upper()}", unit="frame") as bar:
                info = write(run, Path(target), progress=bar, **options)
        except ValueError as exc:  # an option the renderer refuses (fps, size, ...)
            raise GifOptionError(f"--{kind} {target}: {exc}") from None
        except OSError as exc:  # named by the user's path, never the temporary file's
            reason = exc.strerror or type(exc).__name__
            raise OutputError(
                f"{target}: cannot write the {kind.upper()} ({reason})"
            ) from None
        print(
            f"{kind}: {info['path']} ({info['frames']} frames, "
            f"{info['duration']:.1f} s)"
        )


def check_mp4(args: argparse.Namespace) -> None:
    """Before a run: refuse ``--mp4`` when MP4 output cannot work here.

    Also refuses a ``--gif`` or ``--mp4`` target that exists and is not an earlier
    output of the same kind (a GIF, an MP4 file), unless ``--force``: a typo such as
    ``--gif mine.yaml`` never replaces what a user wrote.
    """
    for kind in ("gif", "mp4"):
        check_target(getattr(args, kind, None), kind, getattr(args, "force", False))
    if getattr(args, "mp4", None):
        from sandbox.render.video import require_video

        require_video()


def check_target(target: str | None, kind: str, force: bool) -> None:
    """Refuse to replace a file that is not an earlier ``kind`` output (``--force``).

    ``kind`` is ``gif`` or ``mp4``: an earlier output is recognised by its first
    bytes (:func:`sandbox.run.output_guard.is_gif`, ``is_mp4``).
    """
    if not target or (Path(target).is_dir() and not Path(target).is_symlink()):
        return  # a directory: the write names it (exit status 1)
    from sandbox.run import output_guard as guard

    guard.check_target(
        target,
        kind,
        force=force,
        recognise={"gif": guard.is_gif, "mp4": guard.is_mp4}[kind],
        what=f"a {kind.upper()} file",
        hint="give another path, or --force to replace it",
        label=f"--{kind} {target}",
    )


class GifOptionError(SandboxError):
    """A GIF option the renderer refuses."""


def positive(kind: type) -> Callable[[str], float]:
    """An argparse type: a finite number greater than 0."""

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            message = f"expected a number, got {text!r}"
            raise argparse.ArgumentTypeError(message) from None
        if not (0 < value < float("inf")):
            raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
        return value

    return parse


#: Bounds of the GIF options, checked when the command line is read (before any
#: run): frames per second (GIF delays are whole hundredths of a second, and viewers
#: slow down delays under 2), frame size [px], playback speed (simulated seconds per
#: second), and the most frames a GIF may have.
GIF_FPS = (0.5, 50.0)
GIF_SIZE = (64, 4096)
GIF_SPEED = (0.01, 1000.0)
MAX_GIF_FRAMES = 20_000


def bounded(kind: type, low: float, high: float) -> Callable[[str], float]:
    """An argparse type: a number of ``kind`` from ``low`` to ``high``.

    argparse names the option in its message (``argument --size: expected ...``).
    """
    what = "a whole number" if kind is int else "a number"

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except (ValueError, OverflowError):
            raise argparse.ArgumentTypeError(
                f"expected {what} from {low:g} to {high:g}, got {text!r}"
            ) from None
        if not (low <= value <= high):  # NaN fails too
            raise argparse.ArgumentTypeError(
                f"expected {what} from {low:g} to {high:g}, got {text!r}"
            )
        return value

    return parse


def frame_aspect(text: str) -> float | str:
    """An argparse type for ``--aspect``: ``run``, ``square``, ``W:H`` or a number.

    Returns ``"run"`` or the width over height, from 1/4 to 4.
    """
    from sandbox.render.camera import MAX_FRAME_ASPECT

    words = {"run": "run", "square": 1.0}
    if text in words:
        return words[text]
    try:
        parts = [float(x) for x in text.split(":")]
        value = parts[0] / parts[1] if len(parts) == 2 else parts[0]
        if len(parts) > 2:
            raise ValueError(text)
    except (ValueError, ZeroDivisionError):
        value = float("nan")
    if not (1.0 / MAX_FRAME_ASPECT <= value <= MAX_FRAME_ASPECT):  # NaN fails too
        raise argparse.ArgumentTypeError(
            f"expected run, square, W:H or a number from {1 / MAX_FRAME_ASPECT:g} "
            f"to {MAX_FRAME_ASPECT:g} (width over height), got {text!r}"
        )
    return value


def nonempty(text: str) -> str:
    """An argparse type: a path that is not empty."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r}")
    return text


def jobs(text: str) -> int:
    """An argparse type for ``--jobs``: a whole number >= 1 (see :func:`cap_jobs`)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a whole number >= 1, got {text!r}"
        ) from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


def cap_jobs(value: int) -> int:
    """``--jobs`` capped at the usable cores, with a warning when it is more."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    if value > cores:
        print(
            f"warning: --jobs {value} capped at the {cores} usable cores",
            file=sys.stderr,
        )
        return cores
    return value


def check_gif_frames(duration: float, args: argparse.Namespace) -> None:
    """Refuse GIF options that would make more than :data:`MAX_GIF_FRAMES` frames.

    ``duration`` [s] is the simulated time to animate; checked before a run starts.
    """
    frames = duration * args.fps / args.speed
    if frames > MAX_GIF_FRAMES:
        raise GifOptionError(
            f"--gif {args.gif}: {duration:g} s at --fps {args.fps:g} and --speed "
            f"{args.speed:g} would make {frames:,.0f} frames (at most "
            f"{MAX_GIF_FRAMES:,}: a higher --speed or a lower --fps)"
        )


def add_gif_options(p: argparse.ArgumentParser) -> None:
    """Add the options of GIF rendering to a command's parser."""
    p.add_argument(
        "--fps",
        type=bounded(float, *GIF_FPS),
        default=25.0,
        help=f"frames per second, {GIF_FPS[0]:g} to {GIF_FPS[1]:g} (default 25)",
    )
    p.add_argument(
        "--size",
        type=bounded(int, *GIF_SIZE),
        default=640,
        help=f"frame width in pixels, {GIF_SIZE[0]} to {GIF_SIZE[1]} (default 640)",
    )
    p.add_argument(
        "--speed",
        type=bounded(float, *GIF_SPEED),
        default=1.0,
        help="playback speed relative to simulated time, "
        f"{GIF_SPEED[0]:g} to {GIF_SPEED[1]:g} (default 1)",
    )
    p.add_argument("--zones", action="store_true", help="draw the R (and r) safe zones")
    p.add_argument(
        "--show-beams",
        action="store_true",
        help="draw the range sensors' beams and hits (runs with sensors.range; also "
        "in the --html replay)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace a --gif / --mp4 target even if it is not an earlier output",
    )
    p.add_argument(
        "--follow",
        choices=("auto", "leader", "whole"),
        default="auto",
        help="camera: auto (default: for a run spread along a line, a window that "
        "follows what happens, the healthy vehicles, a failed vehicle near them and "
        "the obstacles near them; else the whole run, as the gallery does), leader, "
        "or whole",
    )
    p.add_argument(
        "--aspect",
        type=frame_aspect,
        default="run",
        help="frame width over height: run (default: the framed area's own when the "
        "whole run is framed, square when the camera moves), square, W:H such as "
        "16:9, or a number from 0.25 to 4; --size is the width",
    )
    p.add_argument(
        "--mp4",
        type=nonempty,
        metavar="OUT.mp4",
        help="also write an MP4 video of the same frames (needs the extra 'video')",
    )


def add_force_option(p: argparse.ArgumentParser, what: str) -> None:
    """Add ``--force``: replace ``what``, which the command otherwise refuses to.

    Without it an output replaces only an earlier output of the same command (see
    :mod:`sandbox.run.output_guard`).
    """
    p.add_argument("--force", action="store_true", help=f"replace {what} all the same")


def add_plugin_option(p: argparse.ArgumentParser, trust: bool = False) -> None:
    """Add ``--plugin PATH_OR_MODULE`` (repeatable) to a command reading scenarios.

    With ``trust``, also ``--trust-plugins``: a command that runs scenarios may then
    run the code of the plug-ins they list (``plugins:``); without the flag (or
    ``SANDBOX_TRUST_PLUGINS=1``) such a scenario is refused with one line.
    """
    p.add_argument(
        "--plugin",
        action="append",
        metavar="PATH_OR_MODULE",
        help="import a plug-in file (.py) or module first (repeatable, trusted: you "
        "named it); scenarios can also list theirs under plugins:",
    )
    if trust:
        p.add_argument(
            "--trust-plugins",
            action="store_true",
            help="run the code of the plug-ins the scenarios list under plugins: "
            "(a scenario is data: without this, or SANDBOX_TRUST_PLUGINS=1, one "
            "that lists plug-in code is refused)",
        )


def trust_advice(exc: Exception, args: argparse.Namespace) -> Exception:
    """A refusal of plug-in code, advising what this command takes to run it.

    Commands that run scenarios take ``--trust-plugins``; the others (``validate``,
    ``view``, ``gallery``, ...) never run the code a file lists, but load a plug-in
    named with ``--plugin``. Any other error is returned as it is (and nothing is
    imported for it).
    """
    advised = getattr(exc, "advised", None)  # an UntrustedScenario's
    if advised is None:
        return exc
    runs = getattr(args, "trust_plugins", None) is not None
    return advised("option" if runs else "plugin")


def load_cli_plugins(args: argparse.Namespace) -> None:
    """Import the ``--plugin`` plug-ins and the installed entry points.

    Raises
    ------
    PluginError
        One fails to import (``main`` prints it and exits 2).
    """
    from sandbox.plugins import load_plugins

    if getattr(args, "trust_plugins", False):  # this process and its workers
        os.environ["SANDBOX_TRUST_PLUGINS"] = "1"
    load_plugins(tuple(getattr(args, "plugin", None) or ()))


def add_command(
    sub: argparse._SubParsersAction,
    name: str,
    summary: str,
    examples: list[str],
    description: str | None = None,
) -> argparse.ArgumentParser:
    """Add the subparser of command ``name``, with an epilog of examples.

    Parameters
    ----------
    sub : argparse._SubParsersAction
        What :func:`sandbox.cli.build_parser` hands to each module's ``register``.
    name : str
        The command, e.g. ``"run"``.
    summary : str
        One line for ``sandbox --help``; also the description unless one is given.
    examples : list of str
        Command lines, each optionally followed by ``  # what it does``, shown under
        ``examples:`` at the end of ``sandbox NAME --help``.
    description : str, optional
        A longer description for ``sandbox NAME --help``.
    """
    epilog = "examples:\n" + "\n".join(f"  {line}" for line in examples)
    text = description or f"{summary[:1].upper()}{summary[1:]}."
    width = min(shutil.get_terminal_size().columns - 2, 78)
    parser = sub.add_parser(
        name,
        help=summary,
        description=textwrap.fill(text, width),
        epilog=epilog,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    # an unknown option is reported with this command's usage (sandbox.cli.main)
    parser.set_defaults(command_parser=parser)
    return parser
