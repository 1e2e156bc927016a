"""Build configuration that ``pyproject.toml`` cannot state: scenarios and C loops.

The repository keeps its scenarios in the top-level ``scenarios/`` folder, their only
source. This maps that folder into the package as ``sandbox/scenarios/`` at build time
(package data), so a wheel or ``pip install .`` ships them and ``sandbox list`` and
``sandbox run paper/rotating_circle`` work from any directory; an editable install reads
the folder in place (see ``sandbox/scenario/bundled.py``). The replay page's
templates, style and script (``sandbox/render/replay/assets/``) are package data too.
Everything else is declared in ``pyproject.toml``.

Optional C extensions take the per-period work whose numpy calls are too small to
pay for themselves (``ARCHITECTURE.md``, "The optional C loops"): ``_cstep``, the loop
that steps a batch of pymunk worlds through a whole control period in one call, which
calls pymunk's functions through their addresses (nothing of Chipmunk is linked); and
the loops of ``EXACT`` below, which give numpy's numbers to the bit beside their numpy
definitions and share ``sandbox/numpy_rules.h``. They read an ndarray's data through
numpy's C API where numpy's headers are there at build time (``pyproject.toml`` asks
for numpy in the build), else through the buffer interface. They are optional: where
one cannot be compiled the install goes on without it (setuptools prints the error)
and the numpy path runs instead, with the same results. An editable install (``pip
install -e .``) compiles them next to their sources. The exact loops are compiled
without contracting a multiplication and an addition into one fused operation, which
rounds once instead of twice and would change the numbers.
"""

from setuptools import Extension, find_packages, setup
from setuptools.command.build_ext import build_ext

CSTEP = Extension("sandbox.physics._cstep", ["sandbox/physics/_cstep.c"], optional=True)


def _numpy_api() -> dict:
    """The compile options for numpy's headers, where numpy is there at build time.

    With them the C loops read an ndarray's data through numpy's C API, much
    cheaper per array than the buffer interface (``sandbox/numpy_rules.h``); without
    them they read every array through the buffer interface, with the same numbers.
    """
    try:
        import numpy
    except ImportError:
        return {"include_dirs": ["sandbox"]}
    return {
        "include_dirs": ["sandbox", numpy.get_include()],
        "define_macros": [("SANDBOX_NUMPY_API", "1")],
    }


def _exact(source: str) -> Extension:
    """An optional extension of the C loop ``source`` that gives numpy's numbers."""
    name = source.removesuffix(".c").replace("/", ".")
    return Extension(
        name,
        [source],
        depends=[
            "sandbox/numpy_rules.h",
            "sandbox/motor_model.h",
            "sandbox/behaviour/safety/qp_project.h",
        ],
        optional=True,
        **_numpy_api(),
    )


#: The extensions whose loops give numpy's numbers to the bit, compiled with no fused
#: multiply-add.
EXACT = tuple(
    _exact(source)
    for source in (
        "sandbox/model/_kernels.c",
        "sandbox/model/_laws.c",
        "sandbox/behaviour/_pair_field.c",
        "sandbox/physics/_motors.c",
        "sandbox/behaviour/safety/_qp.c",
        "sandbox/behaviour/safety/_filter.c",
        "sandbox/loop/_period.c",
        "sandbox/behaviour/_fits.c",
        "sandbox/behaviour/_draws.c",
        "sandbox/behaviour/_residual.c",
    )
)


class BuildExt(build_ext):
    """``build_ext`` with the kernels' floating-point flag where the compiler has it."""

    def build_extension(self, ext):
        """Compile ``ext``; the kernels with no contracted floating point."""
        if ext in EXACT and self.compiler.compiler_type == "unix":
            ext.extra_compile_args = ["-ffp-contract=off", "-fno-fast-math"]
        super().build_extension(ext)


setup(
    ext_modules=[CSTEP, *EXACT],
    cmdclass={"build_ext": BuildExt},
    packages=[*find_packages(include=["sandbox", "sandbox.*"]), "sandbox.scenarios"],
    package_dir={"sandbox.scenarios": "scenarios"},
    package_data={
        "sandbox.scenarios": ["*.yaml", "**/*.yaml"],
        "sandbox.render.replay": ["assets/*"],
    },
)
