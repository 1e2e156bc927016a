"""Build configuration that ``pyproject.toml`` cannot state: the bundled scenarios.

The repository keeps its scenarios in the top-level ``scenarios/`` folder, their only
source. This maps that folder into the package as ``sandbox/scenarios/`` at build time
(package data), so a wheel or ``pip install .`` ships them and ``sandbox list`` and
``sandbox run paper/rotating_circle`` work from any directory; an editable install reads
the folder in place (see ``sandbox/scenario/bundled.py``). The replay page's templates, style and
script (``sandbox/render/replay/assets/``) are package data too. Everything else is declared in
``pyproject.toml``.
"""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["sandbox", "sandbox.*"]), "sandbox.scenarios"],
    package_dir={"sandbox.scenarios": "scenarios"},
    package_data={
        "sandbox.scenarios": ["*.yaml", "**/*.yaml"],
        "sandbox.render.replay": ["assets/*"],
    },
)
