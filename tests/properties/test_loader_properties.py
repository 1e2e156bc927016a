"""Properties of the scenario loader (hypothesis).

Any input gives a Scenario or a ScenarioError, never another exception; every problem of
a file names a line; what the loader accepts, the JSON Schema accepts; what the loader
accepts can be simulated. The documents start from the bundled scenarios and are
mutated: values replaced by junk of every type, keys deleted, unknown keys inserted,
containers swapped, YAML text garbled.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import warnings
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from sandbox.errors import SandboxWarning, ScenarioError
from sandbox.loop.simulation import Simulation
from sandbox.scenario import Scenario, YAMLLoader, load_scenario, parse_scenario
from sandbox.scenario.schema import build_schema

REPO = Path(__file__).resolve().parents[2]
#: Bundled scenarios small enough to be parsed hundreds of times (big platoons are not);
#: sweep files (scenarios/studies/, with a ``base:`` key) are not scenarios.
BUNDLED = [
    p
    for p in sorted((REPO / "scenarios").rglob("*.yaml"))
    if "base" not in (yaml.safe_load(p.read_text("utf-8")) or {})
    and len(parse_scenario(yaml.load(p.read_text("utf-8"), Loader=YAMLLoader)).vehicles)
    <= 50
]
DOCS = [yaml.load(p.read_text(encoding="utf-8"), Loader=YAMLLoader) for p in BUNDLED]
VALIDATOR = jsonschema.Draft202012Validator(build_schema())

SETTINGS = settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**6),
    st.integers().map(lambda k: k * 10**400),  # beyond the range of a float
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1e3, 1e3),
    st.text(max_size=8),
    st.sampled_from(
        ["3d", "-1d", "0d", "1e400", ".nan", "rotating", "circle", "leader"]
    ),
)
junk = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(
            st.one_of(st.text(max_size=6), st.integers(0, 3)), inner, max_size=3
        ),
    ),
    max_leaves=8,
)


def paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path to a value inside a document, as a tuple of keys and indices."""
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += paths(v, (*prefix, i))
    return out


def parent_of(doc: Any, path: tuple) -> Any:
    for key in path[:-1]:
        doc = doc[key]
    return doc


@st.composite
def mutated(draw: st.DrawFn, most: int = 4) -> Any:
    doc = copy.deepcopy(draw(st.sampled_from(DOCS)))
    for _ in range(draw(st.integers(1, most))):
        where = [p for p in paths(doc) if p]
        if not where:
            break
        path = draw(st.sampled_from(where))
        parent = parent_of(doc, path)
        action = draw(
            st.sampled_from(["replace", "delete", "insert", "wrap", "unwrap"])
        )
        key = path[-1]
        if action == "replace":
            parent[key] = draw(junk)
        elif action == "delete":
            del parent[key]
        elif action == "insert" and isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=8))] = draw(junk)
        elif action == "wrap":
            parent[key] = [parent[key]]
        elif (
            action == "unwrap" and isinstance(parent[key], list | dict) and parent[key]
        ):
            inner = parent[key]
            parent[key] = (
                inner[0] if isinstance(inner, list) else next(iter(inner.values()))
            )
    return doc


def accepts(doc: Any) -> Scenario | None:
    """The loader's verdict: a Scenario, or None after a ScenarioError (only those).

    A valid document may warn (slots too close, ...): a scenario all the same.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SandboxWarning)
            return parse_scenario(doc)
    except ScenarioError as exc:
        assert exc.problems, "a ScenarioError without problems"
        for p in exc.problems:
            assert "(got " in p.message and "; expected " in p.message, p.message
        return None


@pytest.mark.slow
@SETTINGS
@given(mutated())
def test_mutated_documents_give_a_scenario_or_a_scenario_error(doc: Any) -> None:
    accepts(doc)


@SETTINGS
@given(junk)
def test_any_junk_document_gives_a_scenario_or_a_scenario_error(doc: Any) -> None:
    accepts(doc)


def _json_safe(doc: Any) -> bool:
    """Whether the document is one a JSON/YAML 1.2 editor would see the same way."""
    try:
        text = json.dumps(doc, allow_nan=False)
    except (TypeError, ValueError):
        return False
    return json.loads(text) == doc and "1e400" not in text


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(mutated(most=1))
def test_what_the_loader_accepts_the_schema_accepts(doc: Any) -> None:
    scenario = accepts(doc)
    assume(scenario is not None and _json_safe(doc))
    assert [e.message for e in VALIDATOR.iter_errors(doc)] == []


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::sandbox.SandboxWarning")  # valid: warns
@settings(max_examples=30, deadline=None)
@given(mutated(most=1))
def test_an_accepted_scenario_can_be_simulated(doc: Any) -> None:
    scenario = accepts(doc)
    assume(scenario is not None and len(scenario.vehicles) <= 50)
    # Three periods: a merge or split timed later could never fire (a loader error),
    # so the short run goes without its events.
    short = dataclasses.replace(scenario, duration=3 * scenario.dt, events=())
    run = Simulation(short).run()
    assert run.status in ("ok", "diverged")
    assert len(run.t) >= 1


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::sandbox.SandboxWarning")  # valid: warns
@SETTINGS
@given(doc=mutated())
def test_problems_in_a_file_name_their_line(
    doc: Any, tmp_path_factory: pytest.TempPathFactory
) -> None:
    try:
        text = yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)
    except yaml.YAMLError:
        assume(False)
    path = tmp_path_factory.mktemp("doc") / "scenario.yaml"
    path.write_text(text, encoding="utf-8")
    try:
        load_scenario(path)
    except ScenarioError as exc:
        for p in exc.problems:
            assert p.line is not None and 1 <= p.line <= text.count("\n") + 1, p


@pytest.mark.filterwarnings("ignore::sandbox.SandboxWarning")  # valid: warns
@SETTINGS
@given(source=st.sampled_from(BUNDLED), data=st.data())
def test_garbled_yaml_text_never_raises_anything_else(
    source: Path, data: st.DataObject, tmp_path_factory: pytest.TempPathFactory
) -> None:
    raw = bytearray(source.read_bytes())
    for _ in range(data.draw(st.integers(1, 6))):
        at = data.draw(st.integers(0, len(raw)))
        what = data.draw(st.sampled_from(["insert", "delete", "flip"]))
        if what == "insert":
            raw[at:at] = data.draw(
                st.sampled_from(
                    [
                        b"\t",
                        b":",
                        b"- ",
                        b"[",
                        b"{",
                        b"&a ",
                        b"*a",
                        b"!!python/none ",
                        b"\x00",
                        b"\xff",
                        b"\n  ",
                        b"'",
                        b'"',
                        b"? ",
                        b"%YAML 1.1\n",
                        b"---\n",
                    ]
                )
            )
        elif what == "delete":
            del raw[at : at + data.draw(st.integers(1, 20))]
        elif at < len(raw):
            raw[at] = data.draw(st.integers(0, 255))
    path = tmp_path_factory.mktemp("garbled") / "scenario.yaml"
    path.write_bytes(bytes(raw))
    try:
        load_scenario(path)
    except ScenarioError as exc:
        assert all(line.startswith(str(path)) for line in exc.lines)


@pytest.mark.parametrize("doc", DOCS, ids=[p.name for p in BUNDLED])
def test_the_unmutated_documents_load(doc: Any) -> None:
    assert isinstance(parse_scenario(doc), Scenario)


def test_no_nan_sneaks_through() -> None:
    doc = copy.deepcopy(DOCS[0])
    doc["duration"] = math.nan
    assert accepts(doc) is None
