"""The module paths of v0.2 that moved into stage folders, kept for one release.

``import sandbox.simulation`` and the like still work: a finder on ``sys.meta_path``
maps each old path to the module now holding its code (the same module object, so a
name patched or read through either path is the same) and issues a
:class:`DeprecationWarning` naming the new path. The public paths are
:mod:`sandbox` itself and the packages :mod:`sandbox.plugins`, :mod:`sandbox.render`,
:mod:`sandbox.envs`, :mod:`sandbox.testing` and :mod:`sandbox.study`; this table goes
in the next release.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

#: Old module path -> the module that holds its code now.
MOVED: dict[str, str] = {
    "sandbox.analysis": "sandbox.run.analysis",
    "sandbox.bundled": "sandbox.scenario.bundled",
    "sandbox.compare": "sandbox.study.compare",
    "sandbox.contexts": "sandbox.plugins.contexts",
    "sandbox.control": "sandbox.model",
    "sandbox.control.flatness": "sandbox.model.flatness",
    "sandbox.control.formation": "sandbox.model.laws",
    "sandbox.deadlock": "sandbox.run.deadlock",
    "sandbox.detection": "sandbox.behaviour.detection",
    "sandbox.divergence": "sandbox.loop.divergence",
    "sandbox.dynamics": "sandbox.model.dynamics",
    "sandbox.expectations": "sandbox.run.expectations",
    "sandbox.failures": "sandbox.model.failures",
    "sandbox.gallery": "sandbox.render.gallery",
    "sandbox.gif_stream": "sandbox.render.gif_stream",
    "sandbox.ideal": "sandbox.study.ideal",
    "sandbox.metrics": "sandbox.run.metrics",
    "sandbox.observation": "sandbox.loop.observation",
    "sandbox.obstacles": "sandbox.model.obstacles",
    "sandbox.output": "sandbox.run.output",
    "sandbox.plot": "sandbox.render.figures",
    "sandbox.plot_marks": "sandbox.render.figure_marks",
    "sandbox.plot_parts": "sandbox.render.figure_parts",
    "sandbox.plugin_loading": "sandbox.plugins.loading",
    "sandbox.pytest_plugin": "sandbox.testing.pytest_plugin",
    "sandbox.randomize": "sandbox.scenario.randomize",
    "sandbox.reconfigure": "sandbox.behaviour.reconfigure",
    "sandbox.recovery": "sandbox.behaviour.recovery",
    "sandbox.references": "sandbox.model.references",
    "sandbox.render_camera": "sandbox.render.camera",
    "sandbox.render_overlay": "sandbox.render.overlay",
    "sandbox.render_palette": "sandbox.render.palette",
    "sandbox.run_info": "sandbox.loop.run_info",
    "sandbox.safety": "sandbox.behaviour.safety",
    "sandbox.safety.cbf": "sandbox.behaviour.safety.cbf",
    "sandbox.safety.qp": "sandbox.behaviour.safety.qp",
    "sandbox.schema": "sandbox.scenario.schema",
    "sandbox.sensing": "sandbox.behaviour.sensing",
    "sandbox.simulation": "sandbox.loop.simulation",
    "sandbox.state": "sandbox.loop.state",
    "sandbox.study.stepping": "sandbox.physics.stepping",
    "sandbox.tunnelling": "sandbox.model.tunnelling",
    "sandbox.video": "sandbox.render.video",
    "sandbox.world": "sandbox.physics.world",
}


def warn_moved(old: str, new: str, stacklevel: int = 3) -> None:
    """Issue the :class:`DeprecationWarning` of an old path."""
    warnings.warn(
        f"{old} moved to {new} in sandbox 0.3; the old path goes in the next "
        "release (public names: see sandbox.__all__)",
        DeprecationWarning,
        stacklevel=stacklevel,
    )


class _AliasLoader(importlib.abc.Loader):
    """Loads an old path as the module now holding its code."""

    def __init__(self, new: str) -> None:
        self.new = new
        self.module: ModuleType | None = None
        self.spec: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        """Warn, import the new module and hand it out under the old name."""
        warn_moved(spec.name, self.new, stacklevel=7)
        self.module = importlib.import_module(self.new)
        self.spec = self.module.__spec__
        return self.module

    def exec_module(self, module: ModuleType) -> None:
        """Give the module back its own spec (the import system set the alias's)."""
        module.__spec__ = self.spec


class MovedFinder(importlib.abc.MetaPathFinder):
    """Finds the old paths of :data:`MOVED` (and nothing else)."""

    def find_spec(self, fullname, path=None, target=None):  # noqa: ANN001, ANN201
        """The alias spec of an old path, else None."""
        new = MOVED.get(fullname)
        if new is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(new))


def install() -> None:
    """Put the finder on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, MovedFinder())
