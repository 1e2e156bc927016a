"""YAML text to a document: bounded reading, the safe loader, line numbers.

A scenario file is read only if it is a regular file of at most ``MAX_FILE_BYTES``; it
is parsed by the safe (libyaml when available) loader into nodes, from which the line
of every field and the keys given twice are found before the document is constructed.
Syntax errors become one problem with their line.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml

from sandbox.errors import Problem
from sandbox.scenario.reader import MAX_FILE_BYTES, MAX_NUMBER, describe, says


class YAMLLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """Safe YAML loader that also reads exponent floats like ``1e-3`` as numbers.

    YAML 1.1 (PyYAML's default) reads ``1e-3`` and ``2.5e3`` as text; YAML 1.2, JSON and
    the editors that check files against the JSON Schema read them as numbers. It is
    libyaml's C parser (``yaml.CSafeLoader``, about 20 times faster) when PyYAML was
    built with it, else the pure-Python ``yaml.SafeLoader``; both give the nodes with
    their lines, from which line numbers and duplicate keys are found.
    """


YAMLLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _base_60_as_text(tag: str) -> Any:
    """A constructor that reads YAML 1.1 base-60 numbers (``1:30`` = 90) as text.

    YAML 1.2, JSON and the editors that check files against the JSON Schema have no
    base-60 numbers; ``duration: 1:30`` is then reported as not a number instead of
    silently meaning 90 s.
    """
    base = yaml.constructor.SafeConstructor.yaml_constructors[tag]

    def construct(loader: Any, node: yaml.ScalarNode) -> Any:
        if ":" in str(node.value):
            return loader.construct_scalar(node)
        return base(loader, node)

    return construct


for _tag in ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float"):
    YAMLLoader.add_constructor(_tag, _base_60_as_text(_tag))


def line_map(node: yaml.Node | None, path: str, out: dict[str, int]) -> None:
    """Record the 1-based line of every field of a composed YAML node tree.

    A node reached again through an alias is mapped once (its first path): recursive or
    exponentially aliased documents stay linear. Iterative, so deep nesting cannot
    exhaust the stack.
    """
    seen: set[int] = set()
    stack: list[tuple[yaml.Node | None, str]] = [(node, path)]
    while stack:
        node, path = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        out.setdefault(path, node.start_mark.line + 1)
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                sub = f"{path}.{_key_text(key)}" if path else _key_text(key)
                out.setdefault(sub, key.start_mark.line + 1)
                stack.append((value, sub))
        elif isinstance(node, yaml.SequenceNode):
            for i, value in enumerate(node.value):
                stack.append((value, f"{path}[{i}]"))


def _key_text(key: yaml.Node) -> str:
    return str(key.value) if isinstance(key, yaml.ScalarNode) else "?"


def duplicate_keys(root: yaml.Node | None) -> list[Problem]:
    """Keys given twice in one mapping (PyYAML would silently keep the last one)."""
    problems = []
    seen: set[int] = set()
    stack: list[tuple[yaml.Node | None, str]] = [(root, "")]
    while stack:
        node, path = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            first: dict[tuple[str, str], int] = {}
            for key, value in node.value:
                text = _key_text(key)
                sub = f"{path}.{text}" if path else text
                stack.append((value, sub))
                if not isinstance(key, yaml.ScalarNode) or key.tag.endswith(":merge"):
                    continue
                line = key.start_mark.line + 1
                if (key.tag, key.value) in first:
                    problems.append(
                        Problem(
                            sub,
                            says(
                                "duplicate key",
                                f"{text!r} again on line {line}",
                                "each key once; first on line "
                                f"{first[key.tag, key.value]}",
                            ),
                            line,
                        )
                    )
                else:
                    first[key.tag, key.value] = line
        elif isinstance(node, yaml.SequenceNode):
            for i, value in enumerate(node.value):
                stack.append((value, f"{path}[{i}]"))
    return sorted(problems, key=lambda p: p.line or 0)


_YAML_HINTS = (
    ("'\\t'", "indentation with spaces (YAML does not allow tabs)"),
    ("mapping values are not allowed", "one 'key: value' per line, a space after ':'"),
    ("could not find expected ':'", "'key: value' pairs"),
    ("expected a single document", "one document (no second '---')"),
    ("constructor for the tag", "plain YAML without custom tags"),
    ("unhashable key", "keys that are plain names"),
    ("unacceptable character", "a text file"),
)


def yaml_problem(exc: yaml.YAMLError, text: str) -> Problem:
    """One problem for a YAML syntax error, with its line and the text found there."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    context = getattr(exc, "context", None)
    if context:
        what = f"{context}, {what}"
    if isinstance(exc, yaml.reader.ReaderError):
        line = text.count("\n", 0, exc.position) + 1
        char = exc.character
        code = char if isinstance(char, int) else ord(char)
        got, what = f"character {code:#x} at line {line}", "not text"
    elif mark is not None:
        line = mark.line + 1
        rows = text.splitlines()
        row = rows[mark.line] if mark.line < len(rows) else ""
        if "\t" in row[: len(row) - len(row.lstrip())]:
            what += " (a tab, '\\t', in the indentation)"
        got = (
            f"{row.strip()[:40]!r} at column {mark.column + 1}"
            if row.strip()
            else (f"the end of the file at column {mark.column + 1}")
        )
    else:
        line, got = None, "text that is not YAML"
    expected = next(
        (hint for key, hint in _YAML_HINTS if key in what), "well-formed YAML"
    )
    return Problem("", says(f"malformed YAML: {what}", got, expected), line)


class NotAFile(OSError):
    """A scenario path that is not a regular file of a readable size."""


def read_limited(path: Path) -> bytes:
    """The bytes of a regular file of at most :data:`MAX_FILE_BYTES` bytes.

    Devices, pipes and sockets are refused before they are opened (opening a pipe
    could block, reading /dev/zero would never end), and at most one byte beyond the
    limit is read, so a file that grows while it is read is refused too.
    """
    mode = path.stat().st_mode
    if stat.S_ISDIR(mode):
        raise IsADirectoryError(path)
    if not stat.S_ISREG(mode):
        raise NotAFile("not a regular file (a device, pipe or socket)")
    too_big = f"larger than {MAX_FILE_BYTES // 1_000_000} MB"
    if path.stat().st_size > MAX_FILE_BYTES:
        raise NotAFile(f"{path.stat().st_size:,} bytes, {too_big}")
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
            raise NotAFile("not a regular file (a device, pipe or socket)")
        data = f.read(MAX_FILE_BYTES + 1)
    if len(data) > MAX_FILE_BYTES:
        raise NotAFile(f"more than {MAX_FILE_BYTES:,} bytes, {too_big}")
    return data


def long_integer_problem(node: yaml.Node | None, exc: ValueError) -> Problem:
    """The problem of a value YAML cannot construct, like an over-long integer."""
    stack, seen = [node], set()
    while stack:
        n = stack.pop()
        if n is None or id(n) in seen:
            continue
        seen.add(id(n))
        if isinstance(n, yaml.ScalarNode):
            if n.tag.endswith(":int") and len(n.value) > 4000:
                return Problem(
                    "",
                    says(
                        "number too large",
                        "an integer of more than 4000 digits",
                        f"a number within +-{MAX_NUMBER:g}",
                    ),
                    n.start_mark.line + 1,
                )
        elif isinstance(n, yaml.MappingNode):
            stack.extend(v for kv in n.value for v in kv)
        elif isinstance(n, yaml.SequenceNode):
            stack.extend(n.value)
    return Problem(
        "",
        says("a value YAML cannot read", describe(str(exc)), "valid numbers and dates"),
        None,
    )


#: Most nodes a document read by :func:`read_yaml_file` may expand to through its
#: aliases (each alias counted as a copy of what it names): a sweep writes its values
#: out whole, so an alias bomb ("billion laughs") would be expanded there.
MAX_EXPANDED_NODES = 100_000


def expanded_nodes(root: yaml.Node | None, limit: int) -> int:
    """The nodes of a composed tree with every alias expanded, counted to ``limit``.

    Each node's expanded size is computed once (iteratively, so deep nesting cannot
    exhaust the stack), so the count costs time linear in the nodes as written; a
    recursive alias (a node inside itself) expands without end and counts as
    ``limit + 1``, as does any tree larger than ``limit``.

    >>> expanded_nodes(yaml.compose("a: &x [1, 2]" + chr(10) + "b: [*x, *x]"), 100)
    13
    """
    size: dict[int, int] = {}
    open_: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [] if root is None else [(root, False)]
    while stack:
        node, leaving = stack.pop()
        kids = _children(node)
        if leaving:
            open_.discard(id(node))
            size[id(node)] = min(limit + 1, 1 + sum(size[id(k)] for k in kids))
            continue
        if id(node) in size:
            continue
        if id(node) in open_:
            return limit + 1  # an alias of one of its own ancestors
        open_.add(id(node))
        stack.append((node, True))
        stack.extend((k, False) for k in kids if id(k) not in size)
    return 0 if root is None else size[id(root)]


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [n for kv in node.value for n in kv]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def read_yaml_file(
    path: str | Path,
    loader: type | None = None,
    max_nodes: int | None = MAX_EXPANDED_NODES,
) -> Any:
    """Read one YAML document from a file, within the limits of scenario files.

    The file must be a regular file of at most :data:`MAX_FILE_BYTES` bytes of UTF-8
    text (devices, pipes and directories are refused before they are read); the
    document must expand through its aliases to at most ``max_nodes`` nodes. It is
    composed by ``loader`` (default: the scenario loader) and then constructed.

    Parameters
    ----------
    path : str or Path
        The file.
    loader : type, optional
        A safe PyYAML loader class (default ``YAMLLoader``).
    max_nodes : int or None
        Most nodes the document may expand to (see :func:`expanded_nodes`); None
        for no limit (the document is constructed, sharing what aliases name).

    Raises
    ------
    ScenarioError
        One problem, formatted with ``path``: why the file cannot be read or used.
    """
    from sandbox.errors import ScenarioError

    name = str(path)

    def refuse(what: str, got: str, expected: str, line: int | None = None) -> None:
        raise ScenarioError([Problem("", says(what, got, expected), line)], name)

    expected = "a readable YAML file"
    try:
        data = read_limited(Path(path))
    except FileNotFoundError:
        refuse("cannot read the file", "no such file", expected)
    except IsADirectoryError:
        refuse("cannot read the file", "a directory", expected)
    except OSError as exc:  # NotAFile among them
        refuse("cannot read the file", exc.strerror or str(exc), expected)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        got = f"byte {data[exc.start]:#04x} at offset {exc.start}"
        refuse("not UTF-8 text", got, "a UTF-8 encoded YAML file", line)
    node = None
    try:
        reader = (loader or YAMLLoader)(text)
        try:
            node = reader.get_single_node()
            if max_nodes is not None and expanded_nodes(node, max_nodes) > max_nodes:
                refuse(
                    "aliases expand too far",
                    f"more than {max_nodes:,} values once expanded",
                    "a document without recursive or exponential aliases",
                )
            return reader.construct_document(node) if node is not None else None
        finally:
            reader.dispose()
    except ValueError as exc:  # an integer beyond Python's digit limit
        if isinstance(exc, ScenarioError):
            raise
        raise ScenarioError([long_integer_problem(node, exc)], name) from None
    except yaml.YAMLError as exc:
        raise ScenarioError([yaml_problem(exc, text)], name) from None
    except RecursionError:
        refuse("the document is nested too deeply", "hundreds of levels", "a few")
