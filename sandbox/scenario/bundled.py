"""The scenarios that ship with sandbox: where they are, their names, and copies.

The repository's top-level ``scenarios/`` folder is their only source. A wheel (``pip
install .``) carries it as package data under ``sandbox/scenarios/`` (``setup.py`` maps
the folder into the package at build time); an editable install, or a clone on the
import path, reads the source folder itself. A bundled scenario is named by its path
below that folder, without ``.yaml``: ``paper/rotating_circle``. The commands that read
a scenario file accept such a name wherever a file is expected (a file that exists
under the name given always wins), so ``sandbox run paper/rotating_circle`` works from
any directory.

>>> from sandbox.scenario.bundled import names, path
>>> "paper/rotating_circle" in names()
True
>>> path("paper/rotating_circle.yaml").name
'rotating_circle.yaml'
"""

from __future__ import annotations

import difflib
import os
import re
from pathlib import Path, PurePosixPath

from sandbox.errors import OutputError, Problem, ScenarioError

#: The suffix of scenario files.
SUFFIX = ".yaml"
#: The bundled file that documents every key of the format (a runnable scenario too).
REFERENCE = "reference"


def scenarios_dir() -> Path:
    """The folder of the bundled scenarios.

    ``sandbox/scenarios/`` inside an installed package, else the ``scenarios/`` folder
    of the source tree the package is imported from.
    """
    package = Path(__file__).resolve().parent.parent  # sandbox/
    installed = package / "scenarios"
    if installed.is_dir():
        return installed
    return package.parent / "scenarios"


def names() -> list[str]:
    """Every bundled scenario's name (``paper/rotating_circle``), sorted."""
    root = scenarios_dir()
    if not root.is_dir():
        return []
    return sorted(
        p.relative_to(root).with_suffix("").as_posix()
        for p in root.rglob(f"*{SUFFIX}")
        if p.is_file()
    )


def find(name: str) -> Path | None:
    """The file of the bundled scenario ``name``, or None if there is none.

    ``name`` may end in ``.yaml`` and may start with ``scenarios/`` (the folder's
    name in the repository); it never reaches outside the folder.
    """
    parts = PurePosixPath(str(name).replace(os.sep, "/")).parts
    if parts[:1] == ("scenarios",):
        parts = parts[1:]
    if not parts or any(p in ("", ".", "..") or p.startswith("/") for p in parts):
        return None
    stem = "/".join(parts)
    if stem.endswith(SUFFIX):
        stem = stem[: -len(SUFFIX)]
    candidate = scenarios_dir() / f"{stem}{SUFFIX}"
    return candidate if candidate.is_file() else None


def path(name: str) -> Path:
    """The file of the bundled scenario ``name``.

    Raises
    ------
    ScenarioError
        No bundled scenario has that name; the message suggests the closest names.
    """
    found = find(name)
    if found is not None:
        return found
    raise ScenarioError([Problem("", _unknown(name))], str(name))


def resolve(text: str | os.PathLike[str]) -> Path:
    """A scenario argument as a file: the file itself if it exists, else a bundled one.

    An absolute path is returned as it is (the loader then says why it cannot be read).

    Raises
    ------
    ScenarioError
        ``text`` is neither an existing file nor a bundled scenario's name.
    """
    given = Path(text)
    if given.exists() or given.is_absolute():
        return given
    found = find(str(text))
    if found is not None:
        return found
    raise ScenarioError([Problem("", _unknown(str(text)))], str(text))


def copy(name: str, dest: str | os.PathLike[str] | None = None) -> Path:
    """Write an editable copy of the bundled scenario ``name``; return its path.

    Parameters
    ----------
    name : str
        A bundled name (``paper/rotating_circle``).
    dest : path, optional
        A file, or an existing directory to copy into; default: ``<stem>.yaml`` in the
        working directory.

    The copy's top-level ``name:`` becomes the new file's stem (when that is a usable
    run name), so its runs go to ``runs/<stem>/``, never over the bundled scenario's.

    Raises
    ------
    ScenarioError
        ``name`` is not a bundled scenario.
    OutputError
        The destination exists (nothing a user wrote is replaced) or cannot be written.
    """
    source = path(name)
    target = Path(dest) if dest is not None else Path(source.name)
    if target.is_dir():
        target = target / source.name
    data = _renamed(source.read_bytes(), target.stem)
    try:
        # Mode "x" creates a new file and never opens an existing one; a write that
        # fails removes the new file, so no half-written copy is left.
        with open(target, "xb") as fh:
            try:
                fh.write(data)
            except BaseException:
                fh.close()
                target.unlink(missing_ok=True)
                raise
    except FileExistsError:
        raise OutputError(
            f"{target}: exists, not replaced; give another destination"
        ) from None
    except OSError as exc:
        raise OutputError(
            f"{target}: cannot be written ({exc.strerror or exc})"
        ) from None
    return target


def _unknown(name: str) -> str:
    """The message for a scenario that is neither a file nor a bundled name."""
    stem = name[: -len(SUFFIX)] if name.endswith(SUFFIX) else name
    known = names()
    close = difflib.get_close_matches(stem, known, n=3, cutoff=0.6)
    base = {n.rsplit("/", 1)[-1]: n for n in known}
    for b in difflib.get_close_matches(stem.rsplit("/", 1)[-1], list(base), n=3):
        if base[b] not in close:
            close.append(base[b])
    close = close[:3]
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    return (
        "cannot read the scenario (got no such file, nor a bundled scenario of that "
        "name; expected a readable YAML scenario file or a name that 'sandbox list' "
        f"prints{hint})"
    )


def _renamed(data: bytes, stem: str) -> bytes:
    """The file's text with its top-level ``name:`` line naming ``stem`` instead."""
    from sandbox.scenario.reader import name_problem

    if name_problem(stem, run=True):
        return data  # the loader will name a usable run name for the user to choose
    lines = data.decode("utf-8").splitlines(keepends=True)
    for i, line in enumerate(lines):
        match = re.match(r"(name:\s*)(\S+)(.*)", line, re.DOTALL)
        if match:
            lines[i] = f"{match.group(1)}{stem}{match.group(3)}"
            break
    return "".join(lines).encode("utf-8")
