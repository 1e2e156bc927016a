"""Assembling a self-contained HTML page, and writing it without overwriting others.

A page is one of the templates of ``sandbox/render/replay/assets/`` (package data, read
with :mod:`importlib.resources`) with its style sheet, its script and its data inlined:
no request of any kind leaves the file (its content security policy forbids them too).
The template's placeholders are filled in one pass, so a name or a description that
looks like one stays text; the data's JSON cannot end its ``<script>`` element
(:func:`json_for_script`); and the policy runs the page's own script only, named by its
hash (:func:`script_hash`), never an inline event handler. Every page carries
:data:`GENERATOR` in its first line; :func:`check_output` lets a page replace only a
file that carries it (an earlier replay), never another file.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import re
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

from sandbox.errors import SandboxError
from sandbox.run.output_guard import OutputRefused, check_target

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


#: How JSON text is made safe inside a ``<script>`` element: every character that could
#: end the element, open a comment or end a JavaScript line becomes its ``\uXXXX``
#: form (legal JSON, the same value once parsed).
SCRIPT_ESCAPES = {
    "<": "\\u003c",
    ">": "\\u003e",
    "&": "\\u0026",
    "\u2028": "\\u2028",
    "\u2029": "\\u2029",
}
_SCRIPT_UNSAFE = re.compile("[<>&\u2028\u2029]")
#: The template's own placeholders, each replaced once, in one pass.
PLACEHOLDERS = ("GENERATOR", "CSP_SCRIPT", "TITLE", "STYLE", "SCRIPT", "DATA")
_PLACEHOLDER = re.compile(r"\{\{(" + "|".join(PLACEHOLDERS) + r")\}\}")


def json_for_script(data: Any) -> str:
    r"""JSON text that can sit inside a ``<script>`` element as it is.

    ``<``, ``>``, ``&``, U+2028 and U+2029 are written in their ``\uXXXX`` forms, so
    no string of the data can close the element (``</script>``), open an HTML comment
    (``<!--``) or break a line of script; the text is still JSON, and parses to
    ``data``.

    >>> json_for_script({"name": "</script><!--"})
    '{"name":"\\u003c/script\\u003e\\u003c!--"}'
    """
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return _SCRIPT_UNSAFE.sub(lambda m: SCRIPT_ESCAPES[m.group(0)], text)


def script_hash(script: str) -> str:
    """The content security policy's source of one inline script, by its hash.

    With it (and no ``'unsafe-inline'``) the browser runs that script and nothing else:
    no other inline script and no inline event handler (``onerror=...``) a text of the
    data might smuggle in.
    """
    digest = hashlib.sha256(script.encode("utf-8")).digest()
    return f"'sha256-{base64.b64encode(digest).decode('ascii')}'"


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
        "GENERATOR": GENERATOR,
        "CSP_SCRIPT": script_hash(script),
        "TITLE": _escape(title),
        "STYLE": asset("replay.css"),
        "SCRIPT": script,
        "DATA": json_for_script(data),
    }
    # One pass over the template: a value is never searched for placeholders.
    return _PLACEHOLDER.sub(lambda m: parts[m.group(1)], page)


def is_page(path: Path) -> bool:
    """Whether ``path`` is a page written here (it carries :data:`GENERATOR`).

    A link is not, whatever it points to.
    """
    if Path(path).is_symlink():
        return False
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEAD_BYTES)
    except OSError:
        return False
    return f'<meta name="generator" content="{GENERATOR}'.encode() in head


def check_output(path: Path) -> None:
    """Raise :class:`ReplayError` unless ``path`` may be written.

    It may be missing, or a regular file that is an earlier page; not a directory, a
    link or any other file, which are never overwritten (the rule of every output,
    :func:`sandbox.run.output_guard.check_target`).
    """
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise ReplayError(f"{path}: the output must be an .html file")
    try:
        check_target(
            path,
            "view",
            recognise=is_page,
            what="a replay page written by sandbox",
            hint="choose another output",
        )
    except OutputRefused as exc:
        raise ReplayError(str(exc)) from None


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
