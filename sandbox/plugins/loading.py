"""Importing plug-ins: from files, modules and the ``sandbox.plugins`` entry points.

A plug-in is imported once (by resolved path or module name), with one line
``loading plug-in code: PATH`` on stderr; its decorators register its names, each with
its origin (the file, the module, the entry point). Any error
while importing it becomes one :class:`~sandbox.plugins.PluginError` naming the
plug-in, the error and the line of the plug-in where it happened: never a traceback.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sandbox.plugins import registration as _plugins
from sandbox.plugins.registration import ENTRY_POINT_GROUP, PluginError


def _ensure_builtins() -> None:
    _plugins._ensure_builtins()


def load_plugin(spec: str, base: Path | None = None) -> Any:
    """Import a plug-in file or module once; its decorators register its names.

    Parameters
    ----------
    spec : str
        A ``.py`` file (relative to ``base``, else to the working directory) or a
        dotted module name.
    base : Path, optional
        The directory of the scenario that lists it.

    Raises
    ------
    PluginError
        The file or module cannot be found or fails to import; the message names it
        and gives the error (and the line of the plug-in where it happened).
    """
    text = str(spec).strip()
    if looks_like_file(text):
        path = resolve_file(text, base)
        key = str(path.resolve())
        if key in _plugins._LOADED:
            return _plugins._LOADED[key]
        if not path.is_file():
            raise PluginError(
                f"plug-in {text}: no such file (looked for {path})",
            )
        name = "sandbox_plugin_" + "".join(
            c if c.isalnum() else "_" for c in path.resolve().as_posix()
        )
        module_spec = importlib.util.spec_from_file_location(name, path)
        if module_spec is None or module_spec.loader is None:
            raise PluginError(f"plug-in {text}: not a Python file")
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        print(f"loading plug-in code: {path}", file=sys.stderr)
        _import(text, str(path), lambda: module_spec.loader.exec_module(module))
        _plugins._LOADED[key] = module
        return module
    if text in _plugins._LOADED:
        return _plugins._LOADED[text]
    print(f"loading plug-in code: {text}", file=sys.stderr)
    module = _import(text, text, lambda: importlib.import_module(text))
    _plugins._LOADED[text] = module
    return module


def is_loaded(spec: str, base: Path | None = None) -> bool:
    """Whether the plug-in file or module ``spec`` was imported in this process."""
    text = str(spec).strip()
    if looks_like_file(text):
        return str(resolve_file(text, base)) in _plugins._LOADED
    return text in _plugins._LOADED


def looks_like_file(spec: str) -> bool:
    """Whether a plug-in spec names a file (``.py`` or a path) rather than a module."""
    text = str(spec).strip()
    return text.endswith(".py") or "/" in text or "\\" in text


def resolve_file(spec: str, base: Path | None = None) -> Path:
    """The absolute path of a plug-in file, relative to ``base`` (else the cwd)."""
    path = Path(str(spec).strip()).expanduser()
    if not path.is_absolute():
        path = (base or Path.cwd()) / path
    return path.resolve()


def _import(label: str, origin: str, action: Callable[[], Any]) -> Any:
    _ensure_builtins()
    _plugins._ORIGIN.append(origin)
    try:
        result = action()
    except ModuleNotFoundError as exc:
        if exc.name and label.startswith(exc.name):
            raise PluginError(
                f"plug-in {label}: no such module (not a file ending in .py, and "
                "no importable module of that name)"
            ) from None
        raise PluginError(f"plug-in {label} failed to import: {_where(exc)}") from None
    except (Exception, SystemExit) as exc:  # any error of a user's file is reported
        raise PluginError(f"plug-in {label} failed to import: {_where(exc)}") from None
    finally:
        _plugins._ORIGIN.pop()
    return result


def _where(exc: BaseException) -> str:
    """``Type: message (file, line N)`` of the innermost frame of the plug-in."""
    frames = traceback.extract_tb(exc.__traceback__)
    own = [f for f in frames if "importlib" not in f.filename]
    where = f" ({own[-1].filename}, line {own[-1].lineno})" if own else ""
    if isinstance(exc, SyntaxError) and exc.lineno:
        where = f" ({exc.filename}, line {exc.lineno})"
    message = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {message}{where}"


def load_entry_points() -> list[str]:
    """Import every plug-in of the entry-point group ``sandbox.plugins`` (once).

    Returns the entry points' names. A broken one is a :class:`PluginError` naming
    it and its package.
    """
    if _plugins._ENTRY_POINTS_LOADED:
        return []
    _plugins._ENTRY_POINTS_LOADED.append(True)
    from importlib.metadata import entry_points

    loaded = []
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        label = f"{ep.name} (entry point {ep.value})"
        _import(label, f"entry point {ep.name}", ep.load)
        loaded.append(ep.name)
    return loaded


def load_plugins(specs: list[str] | tuple[str, ...], base: Path | None = None) -> None:
    """Load several plug-ins (see :func:`load_plugin`), and the entry points."""
    load_entry_points()
    for spec in specs:
        load_plugin(spec, base)
