"""The pytest plugin of sandbox, active wherever sandbox is installed (``pytest11``).

- Fixture ``sandbox_run``: a factory; ``sandbox_run("path.yaml", set=[...])`` returns
  the :class:`~sandbox.run.record.Run` of that scenario. Runs are cached for the whole
  session: identical arguments simulate once (the cached arrays are read-only). A
  relative path is looked up next to the test file first, then in the working directory.
- In a project that asks for it with the ini option ``sandbox_yaml = true`` (in
  ``[tool.pytest.ini_options]`` of ``pyproject.toml``, or ``pytest.ini``; or
  ``-o sandbox_yaml=true`` on the command line), files named ``test_*.yaml`` (or
  ``.yml``) with an ``expect:`` section, under the paths pytest collects, are test
  items, one per file (``test_x.yaml::expect``): the item runs the scenario and fails
  with one ``sandbox check`` line per failed expectation. Without the option no YAML
  file is collected, so installing sandbox changes no other project's test session.
- ``--sandbox-gifs DIR``: every failing test that ran a scenario (a ``test_*.yaml``
  item, or a test that used ``sandbox_run``) gets a GIF of its run in ``DIR``, and the
  failure report names the file (a file there that is not such a GIF is never
  replaced: the report says so instead).
- Plug-in code: a scenario is data, so the code of the plug-ins a scenario lists
  (``plugins:``) is run only on an explicit opt-in, as on the command line: pytest's
  ``--trust-plugins``, the ini option ``sandbox_trust_plugins = true``, or
  ``SANDBOX_TRUST_PLUGINS=1`` in the environment (:func:`trusted`). Without one, such a
  scenario fails its test with the loader's one line naming the entries. Plug-ins the
  test session imports itself (a ``conftest.py`` that imports them) are loaded already
  and need no trust.

Nothing of sandbox is imported until a scenario is run, so the plugin costs nothing in a
session that does not use it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest

#: The runs a test used, for its GIF.
RUNS_KEY = pytest.StashKey[list]()
_EXPECT_LINE = re.compile(r"^expect\s*:", re.MULTILINE)
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--sandbox-gifs DIR``, ``--trust-plugins`` and the ini options."""
    group = parser.getgroup("sandbox", "sandbox scenarios")
    group.addoption(
        "--sandbox-gifs",
        metavar="DIR",
        default=None,
        help="write a GIF of the run of every failing sandbox test into DIR",
    )
    group.addoption(
        "--trust-plugins",
        action="store_true",
        default=False,
        help="run the code of the plug-ins that sandbox scenarios list under plugins: "
        "(without it, the ini option sandbox_trust_plugins or SANDBOX_TRUST_PLUGINS=1, "
        "such a scenario fails its test)",
    )
    parser.addini(
        "sandbox_yaml",
        type="bool",
        default=False,
        help="collect test_*.yaml scenario files with an expect: section as tests",
    )
    parser.addini(
        "sandbox_trust_plugins",
        type="bool",
        default=False,
        help="run the code of the plug-ins that sandbox scenarios list under plugins:",
    )


def trusted(config: pytest.Config) -> bool | None:
    """Whether the session trusts the plug-in code scenarios list.

    True with ``--trust-plugins`` or the ini option ``sandbox_trust_plugins``; else
    None, which leaves it to ``SANDBOX_TRUST_PLUGINS`` (see
    :func:`sandbox.scenario.load_scenario`).
    """
    if config.getoption("trust_plugins", False) or config.getini(
        "sandbox_trust_plugins"
    ):
        return True
    return None


# ---------------------------------------------------------------------------- fixture
def _freeze(run: Any) -> Any:
    """Make a run's arrays read-only (it is shared by every test that asks for it)."""
    for value in vars(run).values():
        if hasattr(value, "flags") and hasattr(value.flags, "writeable"):
            value.flags.writeable = False
    return run


@pytest.fixture(scope="session")
def sandbox_run_cache() -> dict[tuple[str, tuple[str, ...]], Any]:
    """The session's runs by ``(resolved path, overrides)``."""
    return {}


@pytest.fixture
def sandbox_run(
    request: pytest.FixtureRequest,
    sandbox_run_cache: dict[tuple[str, tuple[str, ...]], Any],
) -> Callable[..., Any]:
    """A factory: ``sandbox_run("path.yaml", set=["recovery.beta=2"])`` -> Run.

    Identical arguments return the same (read-only) run for the whole session.
    """
    used = request.node.stash.setdefault(RUNS_KEY, [])
    here = Path(request.node.path).parent
    trust = trusted(request.config)

    def factory(path: str | Path, set: str | Sequence[str] = ()) -> Any:  # noqa: A002
        from sandbox.loop.simulation import simulate
        from sandbox.scenario import load_scenario

        overrides = (set,) if isinstance(set, str) else tuple(set)
        p = Path(path)
        if not p.is_absolute() and (here / p).exists():
            p = here / p
        key = (str(p.resolve()), overrides)
        if key not in sandbox_run_cache:
            scenario = load_scenario(p, overrides=list(overrides), trust_plugins=trust)
            run = simulate(scenario)
            sandbox_run_cache[key] = _freeze(run)
        run = sandbox_run_cache[key]
        used.append(run)
        return run

    return factory


# ------------------------------------------------------------------ test_*.yaml items
def _has_expect(path: Path) -> bool:
    """Whether a YAML file has a top-level ``expect:`` key (unparsable: by its text)."""
    import yaml

    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return False
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError:
        return bool(_EXPECT_LINE.search(text))
    return isinstance(doc, dict) and "expect" in doc


def pytest_collect_file(
    file_path: Path, parent: pytest.Collector
) -> pytest.Collector | None:
    """Collect ``test_*.yaml`` files that have an ``expect:`` section (if asked)."""
    if (
        parent.config.getini("sandbox_yaml")
        and file_path.suffix in (".yaml", ".yml")
        and file_path.name.startswith("test_")
        and _has_expect(file_path)
    ):
        return ScenarioFile.from_parent(parent, path=file_path)
    return None


class ExpectationsFailed(Exception):
    """Expectations of a scenario file that do not hold (one line each)."""

    def __init__(self, lines: list[str]) -> None:
        super().__init__("\n".join(lines))
        self.lines = lines


class ScenarioFile(pytest.File):
    """A ``test_*.yaml`` scenario file: one item, its ``expect:`` section."""

    def collect(self) -> Iterator[pytest.Item]:
        """The file's single item."""
        yield ScenarioItem.from_parent(self, name="expect")


class ScenarioItem(pytest.Item):
    """Runs a scenario file and checks its expectations, as ``sandbox check``."""

    def _source(self) -> str:
        try:
            return str(self.path.relative_to(self.config.rootpath))
        except ValueError:
            return str(self.path)

    def runtest(self) -> None:
        """Run the scenario; raise :class:`ExpectationsFailed` if one fails."""
        from sandbox.errors import ScenarioError
        from sandbox.testing.assertions import check_scenario

        try:
            result = check_scenario(self.path, trust_plugins=trusted(self.config))
        except ScenarioError as exc:  # named as in the report: relative to rootdir
            raise ScenarioError(exc.problems, self._source()) from None
        result.source = self._source()
        self.stash[RUNS_KEY] = [result.run]
        if not result.holds:
            raise ExpectationsFailed(result.lines())

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException]) -> Any:
        """The ``sandbox check`` lines, or the scenario's problems, one per line."""
        from sandbox.errors import ScenarioError

        if isinstance(excinfo.value, ExpectationsFailed | ScenarioError):
            return "\n".join(excinfo.value.lines)
        return super().repr_failure(excinfo)

    def reportinfo(self) -> tuple[Path, int | None, str]:
        """Where the item is: the file, and what it checks."""
        return self.path, None, f"{self.path.name}::expect (sandbox check)"


# -------------------------------------------------------------------------- GIFs
def _write_gifs(item: pytest.Item, folder: Path) -> list[str]:
    from sandbox.render.animation import write_gif
    from sandbox.run.output_guard import OutputRefused, check_target, is_gif

    runs = [r for r in item.stash.get(RUNS_KEY, []) if r is not None]
    unique = list({id(r): r for r in runs}.values())
    stem = _UNSAFE.sub("_", item.nodeid).strip("_")
    lines = []
    for k, run in enumerate(unique):
        name = run.scenario.name if run.scenario is not None else f"run{k}"
        target = folder / (f"{stem}.gif" if len(unique) == 1 else f"{stem}-{name}.gif")
        try:
            check_target(
                target,
                "pytest --sandbox-gifs",
                recognise=is_gif,
                what="a GIF",
                hint="choose another --sandbox-gifs DIR",
            )
            write_gif(run, target)
        except OutputRefused as exc:
            lines.append(f"sandbox: GIF of {name} not written: {exc}")
        except Exception as exc:  # a failing GIF must not hide the test's failure
            lines.append(f"sandbox: GIF of {name} not written: {exc}")
        else:
            lines.append(f"sandbox: GIF of the run of {name}: {target}")
    return lines


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Iterator[None]:
    """With ``--sandbox-gifs``, render the runs of a failed test and name the GIFs."""
    outcome = yield
    report = outcome.get_result()
    folder = item.config.getoption("sandbox_gifs", None)
    if not folder or report.when != "call" or not report.failed:
        return
    lines = _write_gifs(item, Path(folder))
    if not lines:
        return
    text = "\n".join(lines)
    if isinstance(report.longrepr, str):
        report.longrepr = f"{report.longrepr}\n{text}"
    elif hasattr(report.longrepr, "addsection"):
        report.longrepr.addsection("sandbox GIF", text)
    else:
        report.sections.append(("sandbox GIF", text))
