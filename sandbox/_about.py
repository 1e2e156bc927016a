"""What the package is called and which version it is (one place; everything reads it).

The version comes from git through setuptools-scm, which writes ``sandbox/_version.py``
(not tracked) when the package is installed or built. A source tree used without an
install (no ``_version.py``) asks the installed distribution's metadata, and failing
that says ``0+unknown``: a version no release has, so a sweep store it writes is never
mistaken for one of a release.
"""

from __future__ import annotations

#: The distribution's name on the package index (``pip install platoon-sandbox``); the
#: import package and the command are ``sandbox``.
DISTRIBUTION = "platoon-sandbox"
#: The version of a source tree with neither ``_version.py`` nor metadata.
UNKNOWN_VERSION = "0+unknown"


def _find_version() -> str:
    try:
        from sandbox._version import __version__ as found
    except ImportError:
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version(DISTRIBUTION)
        except PackageNotFoundError:
            return UNKNOWN_VERSION
    return str(found)


__version__ = _find_version()


def install_hint(extra: str) -> str:
    """The command that installs one optional extra.

    >>> install_hint("video")
    "pip install 'platoon-sandbox[video]'"
    """
    return f"pip install '{DISTRIBUTION}[{extra}]'"
