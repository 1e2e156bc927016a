"""Build configuration that ``pyproject.toml`` cannot state: scenarios and a C loop.

The repository keeps its scenarios in the top-level ``scenarios/`` folder, their only
source. This maps that folder into the package as ``sandbox/scenarios/`` at build time
(package data), so a wheel or ``pip install .`` ships them and ``sandbox list`` and
``sandbox run paper/rotating_circle`` work from any directory; an editable install reads
the folder in place (see ``sandbox/scenario/bundled.py``). The replay page's
templates, style and script (``sandbox/render/replay/assets/``) are package data too.
Everything else is declared in ``pyproject.toml``.

One optional C extension, ``sandbox.physics._cstep``: the loop that steps a batch of
pymunk worlds through a whole control period in one call (see
``sandbox/physics/stepping.py``). It needs a C compiler and Python's headers, nothing
of Chipmunk (it calls pymunk's functions through their addresses). It is optional:
where it cannot be compiled the install goes on without it (setuptools prints the
error) and the worlds are stepped by the Python path, with the same results. An
editable install (``pip install -e .``) compiles it next to its source.
"""

from setuptools import Extension, find_packages, setup

CSTEP = Extension("sandbox.physics._cstep", ["sandbox/physics/_cstep.c"], optional=True)

setup(
    ext_modules=[CSTEP],
    packages=[*find_packages(include=["sandbox", "sandbox.*"]), "sandbox.scenarios"],
    package_dir={"sandbox.scenarios": "scenarios"},
    package_data={
        "sandbox.scenarios": ["*.yaml", "**/*.yaml"],
        "sandbox.render.replay": ["assets/*"],
    },
)
