"""The pytest plugin: ``test_*.yaml`` items, the ``sandbox_run`` fixture, failure GIFs.

Each test runs an inner pytest session (``pytester``) in a temporary folder, where the
plugin is active because sandbox is installed (entry point ``pytest11``).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from helpers import HEADON as HEADON_RUN
from PIL import Image

pytest_plugins = ["pytester"]
#: Options of the inner sessions: no cache folder, none of the plugins they do not need.
QUIET = ("-p", "no:cacheprovider", "-p", "no:hypothesispytest")
#: The ini option that makes test_*.yaml files test items, given on the command line.
YAML = ("-o", "sandbox_yaml=true")

#: The head-on pair of the helpers, shorter: they touch at 0.75 s.
HEADON = dict(HEADON_RUN, duration=1.2)


@pytest.fixture(autouse=True, scope="module")
def _warm_imports(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Import, in this process, everything an inner session imports lazily.

    pytester runs each inner session in this process and unloads the modules it
    imported afterwards; numpy's and scipy's extension modules cannot be loaded twice,
    so they must be loaded before the first inner session.
    """
    from sandbox.render import write_gif
    from sandbox.testing import check_scenario

    folder = tmp_path_factory.mktemp("warm")
    result = check_scenario(write(folder, "warm.yaml", {"collisions": {"total": 1}}))
    write_gif(result.run, folder / "warm.gif")


def write(folder: Path, name: str, expect: object = None) -> Path:
    doc = dict(HEADON)
    if expect is not None:
        doc["expect"] = expect
    path = folder / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def test_yaml_files_with_expectations_are_test_items(pytester: pytest.Pytester) -> None:
    write(pytester.path, "test_collides.yaml", {"collisions": {"total": 1}})
    write(pytester.path, "test_clean.yaml", {"collisions": {"healthy": 0}})
    write(pytester.path, "test_plain.yaml")  # no expect: section: not a test
    write(pytester.path, "headon.yaml", {"collisions": {"total": 0}})  # not test_*
    (pytester.path / "test_data.yaml").write_text("[1, 2, 3]\n", encoding="utf-8")
    pytester.makepyprojecttoml("[tool.pytest.ini_options]\nsandbox_yaml = true\n")
    result = pytester.runpytest(*QUIET, "-rf")
    result.assert_outcomes(passed=1, failed=1)
    result.stdout.fnmatch_lines(
        [
            "*test_clean.yaml::expect*",
            "test_clean.yaml: collisions.healthy: expected 0, got 1 "
            "(east-west at 0.7? s)",
        ]
    )
    assert "test_collides.yaml::expect FAILED" not in result.stdout.str()


def test_yaml_files_are_collected_only_in_a_project_that_asks(
    pytester: pytest.Pytester,
) -> None:
    # Without sandbox_yaml, another project's test_*.yaml files stay data; the fixture
    # and the assertions work all the same.
    write(pytester.path, "test_collides.yaml", {"collisions": {"total": 0}})
    write(pytester.path, "headon.yaml")
    pytester.makepyfile(
        test_fixture="""
        def test_fixture(sandbox_run):
            assert sandbox_run("headon.yaml").events
        """
    )
    result = pytester.runpytest(*QUIET, "-v")
    result.assert_outcomes(passed=1)
    assert "test_collides.yaml" not in result.stdout.str()
    pytester.makeini("[pytest]\nsandbox_yaml = false\n")
    pytester.runpytest(*QUIET).assert_outcomes(passed=1)
    pytester.makeini("[pytest]\nsandbox_yaml = true\n")
    pytester.runpytest(*QUIET).assert_outcomes(passed=1, failed=1)


def test_an_invalid_yaml_test_fails_with_the_loaders_message(
    pytester: pytest.Pytester,
) -> None:
    write(pytester.path, "test_typo.yaml", {"colisions": {"total": 0}})
    result = pytester.runpytest(*QUIET, *YAML)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(
        ["test_typo.yaml:*: expect.colisions: unknown key; did you mean 'collisions'?*"]
    )


def test_the_fixture_runs_once_per_session_for_identical_arguments(
    pytester: pytest.Pytester,
) -> None:
    write(pytester.path, "headon.yaml")
    pytester.makepyfile(
        test_runs="""
        from sandbox.testing import assert_no_collisions
        seen = []

        def test_a(sandbox_run):
            seen.append(sandbox_run("headon.yaml"))
            assert seen[0].events

        def test_b(sandbox_run):
            assert sandbox_run("headon.yaml") is seen[0]
            assert sandbox_run("headon.yaml", set=["duration=0.5"]) is not seen[0]
            assert_no_collisions(sandbox_run("headon.yaml", set="duration=0.5"))
        """
    )
    result = pytester.runpytest(*QUIET)
    result.assert_outcomes(passed=2)


def test_gifs_of_failing_tests_are_written_and_named(pytester: pytest.Pytester) -> None:
    write(pytester.path, "headon.yaml")
    write(pytester.path, "test_headon.yaml", {"collisions": {"total": 0}})
    pytester.makepyfile(
        test_headon_py="""
        from sandbox.testing import assert_no_collisions

        def test_no_contact(sandbox_run):
            assert_no_collisions(sandbox_run("headon.yaml"))

        def test_passes(sandbox_run):
            assert sandbox_run("headon.yaml").events
        """
    )
    gifs = pytester.path / "gifs"
    result = pytester.runpytest(*QUIET, *YAML, "--sandbox-gifs", str(gifs))
    result.assert_outcomes(passed=1, failed=2)
    written = sorted(p.name for p in gifs.iterdir())
    assert written == [
        "test_headon.yaml_expect.gif",
        "test_headon_py.py_test_no_contact.gif",
    ]
    result.stdout.fnmatch_lines(
        [
            "*AssertionError: headon: 1 collision among healthy vehicles*east-west*",
            f"sandbox: GIF of the run of headon: {gifs / written[1]}",
        ]
    )
    result.stdout.fnmatch_lines(
        [
            "test_headon.yaml: collisions.total: expected 0, got 1 (east-west at *)",
            f"sandbox: GIF of the run of headon: {gifs / written[0]}",
        ]
    )
    with Image.open(gifs / written[0]) as gif:
        assert gif.n_frames > 10


def test_without_the_option_no_gif_is_written(pytester: pytest.Pytester) -> None:
    write(pytester.path, "test_headon.yaml", {"collisions": {"total": 0}})
    result = pytester.runpytest(*QUIET, *YAML)
    result.assert_outcomes(failed=1)
    assert "GIF" not in result.stdout.str()
    assert sorted(p.name for p in pytester.path.iterdir()) == ["test_headon.yaml"]


@pytest.mark.slow
def test_the_testing_tutorials_examples_pass(pytester: pytest.Pytester) -> None:
    # The testing tutorial's user test file and test_*.yaml (docs/tutorials/testing.md),
    # run as a user would: the Python test uses platoon.yaml, the same platoon without
    # its expect: section.
    docs = Path(__file__).resolve().parent.parent / "docs"
    readme = (docs / "tutorials" / "testing.md").read_text("utf-8")
    test_py = re.search(
        r"```python\n(# tests/test_my_strategy\.py\n.*?)```", readme, re.S
    )
    test_yaml = re.search(
        r"```yaml\n# tests/(test_\w+\.yaml).*?\n(.*?)```", readme, re.S
    )
    assert test_py and test_yaml
    assert len(test_py[1].strip().splitlines()) <= 12
    (pytester.path / "test_my_strategy.py").write_text(test_py[1], "utf-8")
    (pytester.path / test_yaml[1]).write_text(test_yaml[2], "utf-8")
    platoon = yaml.safe_load(test_yaml[2])
    del platoon["expect"]
    (pytester.path / "platoon.yaml").write_text(yaml.safe_dump(platoon), "utf-8")
    result = pytester.runpytest(*QUIET, *YAML, "-v")
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines([f"*{test_yaml[1]}::expect PASSED*"])


def test_no_bundled_scenario_is_collected_as_a_test() -> None:
    # Only test_*.yaml files are items; the bundled scenarios are examples, not tests
    # of the user's code (they are checked by tests/test_check.py instead).
    root = Path(__file__).resolve().parent.parent
    named = [p for p in (root / "scenarios").rglob("test_*.y*ml")]
    assert named == []
    assert [p for p in (root / "tests").rglob("test_*.y*ml")] == []
