"""Error types raised by sandbox.

Every error the package raises on purpose derives from :class:`SandboxError`, so callers
(and the CLI) can tell a user mistake from a bug.
"""

from __future__ import annotations

from dataclasses import dataclass


class SandboxError(Exception):
    """Base class of every error raised on purpose by sandbox."""


@dataclass(frozen=True)
class Problem:
    """One problem found in a scenario document.

    Attributes
    ----------
    path : str
        Dotted path of the offending field, e.g. ``vehicles[2].offset`` (``""`` for the
        document itself).
    message : str
        What is wrong, with the value found and what is allowed.
    line : int or None
        1-based line of the field in the YAML file, when known.
    """

    path: str
    message: str
    line: int | None = None

    def format(self, source: str | None) -> str:
        """Return the one-line form ``FILE:LINE: path: message``."""
        where = source or "<scenario>"
        if self.line is not None:
            where = f"{where}:{self.line}"
        field = f" {self.path}:" if self.path else ""
        return f"{where}:{field} {self.message}"


class ScenarioError(SandboxError, ValueError):
    """A scenario document is invalid; carries every problem found in it.

    Parameters
    ----------
    problems : list of Problem
    source : str or None
        The file the document came from, used in messages.
    """

    def __init__(self, problems: list[Problem], source: str | None = None) -> None:
        self.problems = list(problems)
        self.source = source
        super().__init__("\n".join(p.format(source) for p in self.problems))

    @property
    def lines(self) -> list[str]:
        """One formatted line per problem."""
        return [p.format(self.source) for p in self.problems]


class SimulationError(SandboxError):
    """The simulation could not be set up or continued."""


class OutputError(SandboxError):
    """Outputs of a run could not be written."""


class SandboxWarning(UserWarning):
    """Something a user should know that does not stop the work (a scenario's warning).

    Issued with :func:`warnings.warn`, so the usual filters apply: ``python -W error``
    (or pytest's ``filterwarnings = error``) turns it into an error, and
    ``warnings.simplefilter("ignore", SandboxWarning)`` silences it. The loader also
    keeps a scenario's warnings in ``Scenario.warnings``; the command line prints each
    one as one line ``warning: ...``.
    """


class PluginError(SandboxError):
    """A plug-in could not be imported or registered (the message names it).

    Also importable as ``sandbox.plugins.PluginError``.
    """


class PluginRunError(SandboxError):
    """A plug-in raised, or returned non-finite numbers, while a run was going on.

    The loop ends the run with status ``error`` (its outputs are written, with the
    plug-in and this message in ``metrics.json``'s ``error``).

    Parameters
    ----------
    plugin : str
        Which plug-in: its kind, name and origin (``recovery strategy repel
        (my_plugins.py)``).
    message : str
        What went wrong, with the line of the plug-in where it happened.
    """

    def __init__(self, plugin: str, message: str) -> None:
        self.plugin = plugin
        self.message = message
        super().__init__(f"{plugin}: {message}")
