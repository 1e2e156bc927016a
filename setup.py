"""Build configuration that ``pyproject.toml`` cannot state: scenarios and C loops.

The repository keeps its scenarios in the top-level ``scenarios/`` folder, their only
source. This maps that folder into the package as ``sandbox/scenarios/`` at build time
(package data), so a wheel or ``pip install .`` ships them and ``sandbox list`` and
``sandbox run paper/rotating_circle`` work from any directory; an editable install reads
the folder in place (see ``sandbox/scenario/bundled.py``). The replay page's
templates, style and script (``sandbox/render/replay/assets/``) are package data too.
Everything else is declared in ``pyproject.toml``.

The optional C extensions are the compiled paths of ``sandbox/accel.py``, the
registry that imports them (``ARCHITECTURE.md``, "Compiled paths"): ``_cstep``, which
steps a batch of pymunk worlds through a whole control period in one call through
pymunk's own functions' addresses (nothing of Chipmunk is linked); ``_draws``, which
draws every world's sensing noise through numpy's random C API (linked with the
``npyrandom`` library numpy ships for extensions); and the loops that share
``sandbox/accel.h``, which read an ndarray's data through numpy's C API
where numpy's headers are there at build time (``pyproject.toml`` asks for numpy in
the build), else through the buffer interface. They are optional: where one cannot
be compiled the install goes on without it (setuptools prints the error), its path
is off and ``sandbox info`` says so. An editable install (``pip install -e .``)
compiles them next to their sources.

Every build starts from an empty ``build/lib.*`` and ``build/temp.*`` of its own: a
later ``pip install .`` never ships a module or an object file that an earlier build
left there and the sources no longer have.
"""

import shutil
from pathlib import Path

from setuptools import Extension, find_packages, setup
from setuptools.command.build import build

#: The batch's stepping, which reads its named arguments with ``sandbox/accel.h``'s
#: parser (no numpy: its arguments are addresses and counts).
CSTEP = Extension(
    "sandbox.physics._cstep",
    ["sandbox/physics/_cstep.c"],
    include_dirs=["sandbox"],
    depends=["sandbox/accel.h"],
    optional=True,
)

#: The headers the loops include.
HEADERS = [
    "sandbox/accel.h",
    "sandbox/motor_model.h",
    "sandbox/behaviour/safety/qp_project.h",
]


def _numpy_api() -> dict:
    """The compile options for numpy's headers, where numpy is there at build time.

    With them the C loops read an ndarray's data through numpy's C API, much
    cheaper per array than the buffer interface (``sandbox/accel.h``); without
    them they read every array through the buffer interface.
    """
    try:
        import numpy
    except ImportError:
        return {"include_dirs": ["sandbox"]}
    return {
        "include_dirs": ["sandbox", numpy.get_include()],
        "define_macros": [("SANDBOX_NUMPY_API", "1")],
    }


def _loop(source: str) -> Extension:
    """The optional extension of the C loop ``source``."""
    name = source.removesuffix(".c").replace("/", ".")
    return Extension(name, [source], depends=HEADERS, optional=True, **_numpy_api())


#: The C loops that share ``sandbox/accel.h``.
LOOPS = tuple(
    _loop(source)
    for source in (
        "sandbox/model/_kernels.c",
        "sandbox/model/_laws.c",
        "sandbox/behaviour/_pair_field.c",
        "sandbox/physics/_motors.c",
        "sandbox/behaviour/safety/_filter.c",
        "sandbox/loop/_period.c",
        "sandbox/behaviour/_fits.c",
        "sandbox/behaviour/_residual.c",
    )
)


def _draws() -> list[Extension]:
    """The sensing draws' extension, which links numpy's random C API (npyrandom).

    None without numpy at build time (its headers and its library come with it).
    """
    try:
        import numpy.random
    except ImportError:
        return []
    return [
        Extension(
            "sandbox.behaviour._draws",
            ["sandbox/behaviour/_draws.c"],
            depends=HEADERS,
            optional=True,
            library_dirs=[str(Path(numpy.random.__file__).parent / "lib")],
            libraries=["npyrandom", "m"],
            **_numpy_api(),
        )
    ]


class FreshBuild(build):
    """``build`` from an empty build directory of its own (nothing stale reused)."""

    def run(self) -> None:
        """Remove this build's ``build_lib`` and ``build_temp``, then build."""
        for folder in (self.build_lib, self.build_temp):
            if folder and Path(folder).is_dir():
                shutil.rmtree(folder)
        super().run()


#: The scenarios' folders, each a package of data (``sandbox.scenarios.paper``, ...).
SCENARIO_PACKAGES = [
    f"sandbox.scenarios.{folder.name}"
    for folder in sorted(Path("scenarios").iterdir())
    if folder.is_dir()
]

setup(
    ext_modules=[CSTEP, *LOOPS, *_draws()],
    cmdclass={"build": FreshBuild},
    packages=[
        *find_packages(include=["sandbox", "sandbox.*"]),
        "sandbox.render.replay.assets",
        "sandbox.scenarios",
        *SCENARIO_PACKAGES,
    ],
    package_dir={"sandbox.scenarios": "scenarios"},
    package_data={
        "sandbox.scenarios": ["*.yaml"],
        **{name: ["*.yaml"] for name in SCENARIO_PACKAGES},
        "sandbox.render.replay.assets": ["*"],
    },
)
