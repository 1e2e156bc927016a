"""The plug-in code a scenario lists: loaded on trust, refused, or left unrun.

A scenario is data: the code of the plug-ins it lists (``plugins:``, files or modules)
is run only on an explicit opt-in, ``trust_plugins=True`` (the command line's
``--trust-plugins``, or ``SANDBOX_TRUST_PLUGINS=1`` in the environment); without it a
scenario that lists a plug-in not yet loaded is refused with one line naming the
entries. ``check_only=True`` (``sandbox validate``) never runs them: it checks the
listed paths and names, and reports the sections that select a name such a plug-in
may own as not checked (:class:`UncheckedScenario`). Plug-ins named on the command
line (``--plugin``) and installed entry points are trusted: the user named or
installed them.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from sandbox import plugins
from sandbox.errors import Problem, ScenarioError
from sandbox.plugins.registration import (
    KINDS,
    PluginError,
)
from sandbox.scenario.reader import (
    Reader,
    describe,
    says,
)

#: The environment variable that trusts the plug-in code scenarios list.
TRUST_ENV = "SANDBOX_TRUST_PLUGINS"
#: What the loader does with the plug-in code a scenario lists: run it, refuse the
#: scenario, or leave it unrun and its sections unchecked.
PLUGIN_CODE = ("load", "refuse", "skip")
#: The sections a plug-in can own (their names select a registered plug-in).
PLUGIN_OWNED = tuple(kind.section for kind in KINDS.values())


#: A dotted module name.
_MODULE_NAME = r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*"


def _under(path: str, section: str) -> bool:
    """Whether a field path lies in a section (or is it)."""
    return path == section or path.startswith((f"{section}.", f"{section}["))


def trusted_by_environment() -> bool:
    """Whether ``SANDBOX_TRUST_PLUGINS`` trusts the plug-ins scenarios list."""
    return os.environ.get(TRUST_ENV, "").strip().lower() in ("1", "true", "yes")


class UncheckedScenario(ScenarioError):
    """A scenario valid as far as it was checked, with sections left unchecked.

    Raised under ``check_only=True`` when a section selects a name that may belong to
    a listed plug-in whose code was not run. ``unchecked`` holds ``(path, what)`` of
    each such section; ``plugins`` the entries not loaded.
    """

    def __init__(
        self, unchecked: list[tuple[str, str]], plugins: tuple[str, ...], source: str
    ) -> None:
        self.unchecked = list(unchecked)
        self.plugins = tuple(plugins)
        sections = ", ".join(f"{path} ({what})" for path, what in self.unchecked)
        note = (
            f"not checked: {sections}: they name plug-ins whose code validate never "
            f"runs ({', '.join(self.plugins)}); --plugin "
            f"{' --plugin '.join(self.plugins)} loads what you trust and checks them"
        )
        super().__init__([Problem("", note)], source)


#: What unlocks the plug-in code of a scenario, by where it is loaded: anywhere (the
#: library), a command with ``--trust-plugins``, a command with ``--plugin`` only.
TRUST_ADVICE = {
    "any": f"--trust-plugins, {TRUST_ENV}=1 or load_scenario(..., trust_plugins=True) "
    "to run it",
    "option": f"--trust-plugins or {TRUST_ENV}=1 to run it",
    "plugin": "--plugin {entries} to run it (a plug-in named on the command line is "
    "trusted)",
}


class UntrustedScenario(ScenarioError):
    """A scenario that lists plug-in code, refused without trust.

    ``refused`` holds the entries of ``plugins:`` not run. The message advises
    ``advice`` (a key of :data:`TRUST_ADVICE`); :meth:`advised` gives the same
    refusal with the advice of the command that loaded it (only commands that run
    scenarios take ``--trust-plugins``).
    """

    def __init__(
        self,
        refused: tuple[str, ...],
        line: int | None,
        source: str | None,
        advice: str = "any",
    ) -> None:
        self.refused, self.line = tuple(refused), line
        entries = ", ".join(self.refused)
        options = " --plugin ".join(self.refused)
        expected = TRUST_ADVICE[advice].format(entries=options)
        problem = Problem(
            "plugins",
            says("plug-in code is not run without trust", entries, expected),
            line,
        )
        super().__init__([problem], source)

    def advised(self, advice: str) -> UntrustedScenario:
        """The same refusal advising ``advice`` (a key of :data:`TRUST_ADVICE`)."""
        return UntrustedScenario(self.refused, self.line, self.source, advice)


def load_listed_plugins(
    rd: Reader, listed: Any, source: str | None, plugin_code: str
) -> list[str]:
    """The plug-ins a scenario lists, as they reload from anywhere, loaded or not.

    Files are relative to the scenario's directory and returned as absolute paths;
    module names are returned as they are. Under ``load`` each is imported (once per
    process); under ``refuse`` a scenario listing one not yet loaded is refused with
    one problem naming them and the opt-in; under ``skip`` none is imported: files
    must exist, names must be module names, and the entries are kept in
    ``rd.unloaded``. A plug-in that fails to load is a problem of its ``plugins[i]``.
    """
    if listed is None:
        return []
    if not isinstance(listed, list):
        listed = [listed] if isinstance(listed, str) else listed
        if not isinstance(listed, list):
            rd.fail(
                "plugins",
                "not a list",
                describe(listed),
                "a list of plug-in files (.py) or module names",
            )
            return []
    base = Path(source).resolve().parent if source else None
    out = []
    try:
        plugins.load_entry_points()
    except PluginError as exc:
        rd.fail("plugins", str(exc), "a broken entry point", "plug-ins that import")
    refused, unloaded = [], []
    for i, spec in enumerate(listed):
        where = f"plugins[{i}]"
        if not isinstance(spec, str) or not spec.strip():
            rd.fail(
                where, "not a plug-in name", describe(spec), "a .py file or a module"
            )
            continue
        is_file = plugins.looks_like_file(spec)
        entry = str(plugins.resolve_file(spec, base)) if is_file else spec.strip()
        if plugins.is_loaded(spec, base):
            out.append(entry)
        elif plugin_code == "refuse":
            refused.append(spec.strip())
        elif plugin_code == "skip":
            if is_file and not (entry.endswith(".py") and Path(entry).is_file()):
                what = (
                    "no such plug-in file"
                    if not Path(entry).exists()
                    else "not a .py file"
                )
                rd.fail(where, what, entry, "a .py file that exists")
                continue
            if not is_file and not re.fullmatch(
                r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*", entry
            ):
                rd.fail(where, "not a module name", repr(entry), "a dotted module name")
                continue
            unloaded.append(spec.strip())
            out.append(entry)
        else:
            try:
                plugins.load_plugin(spec, base)
            except PluginError as exc:
                rd.fail(
                    where,
                    "plug-in cannot be loaded",
                    str(exc),
                    "a plug-in that imports",
                )
                continue
            out.append(entry)
    if refused:
        raise UntrustedScenario(tuple(refused), rd.line("plugins"), source)
    rd.unloaded = tuple(unloaded)
    return out
