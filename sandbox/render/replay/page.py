"""Assembling a self-contained HTML page, and writing it without overwriting others.

A page is one of the templates of ``sandbox/render/replay/assets/`` (package data, read
with :mod:`importlib.resources`) with its style sheet, its script and its data inlined:
no request of any kind leaves the file (its content security policy forbids them too).
Every page carries :data:`GENERATOR` in its first line; :func:`check_output` lets a page
replace only a file that carries it (an earlier replay), never another file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

from sandbox.errors import SandboxError

__all__ = ["GENERATOR", "ReplayError", "build_page", "check_output", "write_page"]

#: The mark of a page written here (a ``<meta name="generator">`` of its head).
GENERATOR = "sandbox-replay"
#: How much of an existing file is read to recognise an earlier page [bytes].
_HEAD_BYTES = 4096


class ReplayError(SandboxError, ValueError):
    """A replay page cannot be made: bad input or an output path it must not replace."""


def asset(name: str) -> str:
    """The text of ``sandbox/render/replay/assets/NAME``."""
    return (resources.files("sandbox.render.replay") / "assets" / name).read_text(
        "utf-8"
    )


def _json_for_script(data: Any) -> str:
    """JSON that can sit inside a ``<script>`` element (no ``</``)."""
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return text.replace("</", "<\\/").replace("<!--", "<\\!--")


def _escape(text: str) -> str:
    """Text for HTML content or an attribute."""
    return (
        str(text)
        .replace("&", "&amp;")
        .replace("<", "&lt;")
        .replace(">", "&gt;")
        .replace('"', "&quot;")
    )


def build_page(
    template: str,
    title: str,
    data: Any,
    scripts: list[str],
    transform: Callable[[str], str] | None = None,
) -> str:
    """The HTML of a page: ``template`` with title, style, data and scripts inlined.

    Parameters
    ----------
    template : str
        Name of an asset holding ``{{TITLE}}``, ``{{STYLE}}``, ``{{DATA}}`` and
        ``{{SCRIPT}}``.
    title : str
    data : JSON-ready
        Embedded as ``<script id="replay-data" type="application/json">``.
    scripts : list of str
        Names of the script assets, inlined in this order.
    transform : callable, optional
        Applied to the joined scripts before they are inlined (an optional feature's
        pieces, see :func:`sandbox.render.replay.with_beams`).
    """
    page = asset(template)
    script = "\n".join(asset(s) for s in scripts)
    if transform is not None:
        script = transform(script)
    script = script.replace("</script", "<\\/script")
    parts = {
        "{{TITLE}}": _escape(title),
        "{{STYLE}}": asset("replay.css"),
        "{{DATA}}": _json_for_script(data),
        "{{SCRIPT}}": script,
        "{{GENERATOR}}": GENERATOR,
    }
    for key in ("{{GENERATOR}}", "{{TITLE}}", "{{STYLE}}", "{{SCRIPT}}", "{{DATA}}"):
        page = page.replace(key, parts[key])  # the data last: it is never searched
    return page


def is_page(path: Path) -> bool:
    """Whether ``path`` is a page written here (it carries :data:`GENERATOR`)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEAD_BYTES)
    except OSError:
        return False
    return f'<meta name="generator" content="{GENERATOR}'.encode() in head


def check_output(path: Path) -> None:
    """Raise :class:`ReplayError` unless ``path`` may be written.

    It may be missing, or a regular file that is an earlier page; not a directory, a
    link or any other file, which are never overwritten.
    """
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise ReplayError(f"{path}: the output must be an .html file")
    if not path.exists() and not path.is_symlink():
        return
    if path.is_symlink() or not path.is_file():
        raise ReplayError(f"{path}: exists and is not a file; nothing was written")
    if not is_page(path):
        raise ReplayError(
            f"{path}: exists and is not a replay page written by sandbox, so it is not "
            "overwritten; choose another output"
        )


def write_page(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (a temporary file, then a rename).

    Checks :func:`check_output` first; creates the parent directory.
    """
    path = Path(path)
    check_output(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "x", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise ReplayError(
            f"{path}: cannot be written ({exc.strerror or type(exc).__name__})"
        ) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
