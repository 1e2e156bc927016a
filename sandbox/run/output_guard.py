"""What an output may replace: nothing but an earlier output of the same command.

Every command that writes files a user names (``sandbox schema --out``, ``plot --out``,
``sweep plot --out``, ``gallery --out``, the replay pages, ``--gif`` and ``--mp4``, run
directories) checks each target here first. A target may be written when it is
missing, or when it is an earlier output of that command, recognised

- by its content, where the format carries a mark of its own (a replay page's
  ``<meta name="generator">``, a GIF's or an MP4's first bytes, the JSON Schema's
  ``$id``, a run directory's manifest): the command passes a ``recognise`` predicate;
- or by the directory's record of what sandbox wrote there, :data:`MARKS`: each file's
  name, the command that wrote it and the SHA-256 of its bytes. A file the user changed
  since (or wrote under the same name) no longer matches, and is the user's again.

Anything else (a user's file, a directory, a link) is refused with one line naming it
(:class:`OutputRefused`, exit status 2), before any work is done where the names are
known in advance, and again when the files are put in place; ``force=True`` (the
commands' ``--force``) replaces a regular file all the same. Files are written whole
or not at all: :func:`write_output` through a temporary file and a rename, several
files through a :class:`Stage` (a hidden directory inside the output directory whose
files are checked, then moved into place one by one, as each is complete).
``tests/test_hostile_outputs.py`` fails when a command module writes a file without
this module.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from sandbox.errors import OutputError

__all__ = [
    "MARKS",
    "OutputRefused",
    "Stage",
    "check_target",
    "check_targets",
    "first_bytes",
    "is_earlier",
    "is_gif",
    "is_mp4",
    "mark_written",
    "process_alive",
    "remove_dead_dirs",
    "remove_dead_stages",
    "staged",
    "write_output",
]

#: The record, in each directory sandbox writes outputs into, of what it wrote there.
MARKS = ".sandbox-outputs.json"
#: The largest record read [bytes]; a larger one (crafted) is read as empty.
MARKS_MAX_BYTES = 2**20
#: The prefix of a stage directory (``.sandbox-stage-<pid>-...``) and of a temporary
#: file (``.<name>.sandbox-<pid>.tmp``).
STAGE_PREFIX = ".sandbox-stage-"
#: A predicate on an existing path: whether it is an earlier output by its content.
Recognise = Callable[[Path], bool]


class OutputRefused(OutputError):
    """A target exists and is not an earlier output of the command; nothing written.

    The command line prints the message as one line and exits with status 2.
    """

    #: The command line's exit status: invalid input.
    exit_status = 2


def _digest(path: Path) -> str | None:
    """The SHA-256 of a regular file's bytes, or None if it cannot be read."""
    sha = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(2**20), b""):
                sha.update(block)
    except OSError:
        return None
    return sha.hexdigest()


def _read_marks(directory: Path) -> dict[str, dict[str, str]]:
    """The record of :data:`MARKS` in ``directory``: name -> ``{command, sha256}``.

    A missing, linked, oversized or malformed record reads as empty (every file of
    the directory is then the user's).
    """
    path = Path(directory) / MARKS
    try:
        if path.is_symlink() or not path.is_file():
            return {}
        if path.stat().st_size > MARKS_MAX_BYTES:
            return {}
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return {}
    files = doc.get("files") if isinstance(doc, dict) else None
    if not isinstance(files, dict):
        return {}
    return {
        name: entry
        for name, entry in files.items()
        if isinstance(entry, dict)
        and isinstance(entry.get("command"), str)
        and isinstance(entry.get("sha256"), str)
    }


def is_earlier(path: Path, command: str, recognise: Recognise | None = None) -> bool:
    """Whether the existing ``path`` is an earlier output of ``command``.

    By ``recognise`` (the format's own mark), or by the directory's :data:`MARKS`: a
    regular file (not a link) that ``command`` wrote, with the same bytes.
    """
    path = Path(path)
    if path.is_symlink():
        return False
    if recognise is not None and recognise(path):
        return True
    if not path.is_file():
        return False
    entry = _read_marks(path.parent).get(path.name)
    if entry is None or entry["command"] != command:
        return False
    return _digest(path) == entry["sha256"]


def first_bytes(path: Path, count: int = 16) -> bytes:
    """The first ``count`` bytes of a regular file (empty if it cannot be read)."""
    try:
        if Path(path).is_symlink() or not Path(path).is_file():
            return b""
        with open(path, "rb") as fh:
            return fh.read(count)
    except OSError:
        return b""


def is_gif(path: Path) -> bool:
    """Whether ``path`` is a GIF file (by its first bytes, as every GIF starts)."""
    return first_bytes(path, 6) in (b"GIF87a", b"GIF89a")


def is_mp4(path: Path) -> bool:
    """Whether ``path`` is an MP4 file (an ISO media file: ``ftyp`` at byte 4)."""
    return first_bytes(path, 8)[4:8] == b"ftyp"


def check_target(
    path: str | os.PathLike[str],
    command: str,
    *,
    force: bool = False,
    recognise: Recognise | None = None,
    what: str | None = None,
    hint: str = "choose another --out, or --force to replace it",
    label: str | None = None,
) -> None:
    """Raise :class:`OutputRefused` unless ``command`` may write ``path``.

    Parameters
    ----------
    path : path-like
        The target: missing, or an earlier output of ``command`` (see
        :func:`is_earlier`); with ``force``, any regular file or link.
    command : str
        The command writing it (``"plot"``, ``"sweep plot"``), as its marks name it.
    force : bool
        Replace a file that is not an earlier output (never a directory).
    recognise : callable, optional
        Whether an existing path is an earlier output by its content.
    what : str, optional
        What an earlier output is, for the message (default ``an earlier output of
        sandbox COMMAND``).
    hint : str
        What the user can do instead, ending the message.
    label : str, optional
        How the message names the target (default the path; ``--gif OUT.gif``).
    """
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return
    is_dir = path.is_dir() and not path.is_symlink()
    if is_earlier(path, command, recognise) or (force and not is_dir):
        return
    kind = "a directory" if is_dir else f"not {what or _earlier(command)}"
    raise OutputRefused(
        f"{label or path}: exists and is {kind}, so it is not replaced; {hint}"
    )


def _earlier(command: str) -> str:
    return f"an earlier output of sandbox {command}"


def check_targets(
    paths: Iterable[str | os.PathLike[str]],
    command: str,
    *,
    force: bool = False,
    recognise: Recognise | None = None,
) -> None:
    """:func:`check_target` of every path, before anything is written."""
    for path in paths:
        check_target(path, command, force=force, recognise=recognise)


def mark_written(paths: Iterable[str | os.PathLike[str]], command: str) -> None:
    """Record in each directory's :data:`MARKS` that ``command`` wrote ``paths``.

    The record is rewritten whole (a temporary file, then a rename); entries of
    files that no longer exist are dropped. A record that cannot be written leaves
    the files unmarked (a later run then asks for ``--force``), never an error.
    """
    by_dir: dict[Path, list[Path]] = {}
    for p in paths:
        p = Path(p)
        by_dir.setdefault(p.parent, []).append(p)
    for directory, files in by_dir.items():
        marks = _read_marks(directory)
        for p in files:
            digest = _digest(p)
            if digest is not None:
                marks[p.name] = {"command": command, "sha256": digest}
        marks = {k: v for k, v in sorted(marks.items()) if (directory / k).is_file()}
        doc = {"product": "sandbox", "format": 1, "files": marks}
        text = json.dumps(doc, indent=1, sort_keys=True) + "\n"
        try:
            _write_atomic(directory / MARKS, text.encode("utf-8"))
        except OSError:
            pass


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file beside it and a rename."""
    tmp = path.with_name(f".{path.name}.sandbox-{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_output(
    path: str | os.PathLike[str],
    data: str | bytes,
    command: str,
    *,
    force: bool = False,
    recognise: Recognise | None = None,
    mark: bool = True,
) -> Path:
    r"""Write one output file whole, if ``command`` may (see :func:`check_target`).

    Parameters
    ----------
    path : path-like
        The target, in a directory that exists.
    data : str or bytes
        The content (text is written as UTF-8, its line ends as they are).
    command : str
    force : bool
    recognise : callable, optional
        As for :func:`check_target`.
    mark : bool
        Record the file in the directory's :data:`MARKS` (off for a format that
        carries its own mark, so no record is left beside a single file).

    Raises
    ------
    OutputRefused
        The target must not be replaced.
    OutputError
        It cannot be written (the reason, never a temporary name).
    """
    path = Path(path)
    check_target(path, command, force=force, recognise=recognise)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    try:
        _write_atomic(path, raw)
    except OSError as exc:
        raise OutputError(f"{path}: cannot be written ({_reason(exc)})") from None
    if mark:
        mark_written([path], command)
    return path


def _reason(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


class Stage:
    """A hidden directory inside ``out`` where a command writes its files first.

    :meth:`commit` moves every complete file of the stage into ``out``, each checked
    with :func:`check_target` first (all of them before the first is moved) and
    recorded in :data:`MARKS`; names starting with ``.`` (a writer's temporary files)
    stay. :func:`staged` makes one and removes it.
    """

    def __init__(self, out: Path, command: str, force: bool = False) -> None:
        self.out = Path(out)
        self.command = command
        self.force = force
        #: The directories this stage makes (``out`` and missing parents), innermost
        #: first: removed again if nothing was put in them.
        self.created = [p for p in (self.out, *self.out.parents) if not p.exists()]
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            remove_dead_stages(self.out)
            self.path = Path(
                tempfile.mkdtemp(prefix=f"{STAGE_PREFIX}{os.getpid()}-", dir=self.out)
            )
        except OSError as exc:
            raise OutputError(
                f"{self.out}: cannot be written ({_reason(exc)})"
            ) from None
        self.written: list[Path] = []

    def commit(self) -> list[Path]:
        """Put the stage's complete files in place; the paths put there now."""
        names = sorted(
            p.name
            for p in self.path.iterdir()
            if not p.name.startswith(".") and p.is_file() and not p.is_symlink()
        )
        targets = [self.out / name for name in names]
        check_targets(targets, self.command, force=self.force)
        try:
            for name, target in zip(names, targets, strict=True):
                os.replace(self.path / name, target)
        except OSError as exc:
            raise OutputError(
                f"{self.out}: cannot be written ({_reason(exc)})"
            ) from None
        mark_written(targets, self.command)
        self.written += targets
        return targets

    def remove(self) -> None:
        """Remove the stage, and the directories it made if they are empty."""
        shutil.rmtree(self.path, ignore_errors=True)
        for directory in self.created:
            try:
                directory.rmdir()
            except OSError:
                break


def remove_dead_stages(directory: Path) -> None:
    """Remove the stages that killed commands left in ``directory``."""
    remove_dead_dirs(directory, STAGE_PREFIX)


def remove_dead_dirs(
    directory: Path, prefix: str, names: frozenset[str] | None = None
) -> None:
    """Remove the directories ``<prefix><pid>-*`` of dead processes in ``directory``.

    One is removed only if it holds nothing but regular files (of ``names``, when
    given), which are deleted with it; a link, a subdirectory or another file keeps
    it (a SIGKILL leaves them behind; a user's file is never deleted).
    """
    for path in Path(directory).glob(f"{glob.escape(prefix)}*-*"):
        pid = path.name[len(prefix) :].split("-", 1)[0]
        if not pid.isdigit() or process_alive(int(pid)):
            continue
        try:
            if path.is_symlink() or not path.is_dir():
                continue
            entries = list(path.iterdir())
            if any(e.is_symlink() or not e.is_file() for e in entries):
                continue
            if names is not None and not {e.name for e in entries} <= names:
                continue
            for e in entries:
                e.unlink()
            path.rmdir()
        except OSError:
            continue


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (or may: it belongs to another user)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


@contextmanager
def staged(
    out: str | os.PathLike[str], command: str, force: bool = False
) -> Iterator[Stage]:
    """A :class:`Stage` in ``out``, committed when the block ends without an error.

    Whatever happens, the stage is removed afterwards: files not committed (an
    interrupted command's) never reach ``out``.
    """
    stage = Stage(Path(out), command, force)
    try:
        yield stage
        stage.commit()
    finally:
        stage.remove()
