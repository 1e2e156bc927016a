"""The JSON Schema of the scenario format agrees with the loader."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

from sandbox.cli import main
from sandbox.scenario import YAMLLoader, load_scenario, parse_scenario
from sandbox.scenario.schema import (
    LENGTH_PATTERN,
    NAME_PATTERN,
    POSITIVE_LENGTH_PATTERN,
    build_schema,
    sections,
)

#: A far start without v1_max warns of tunnelling: not what these tests check.
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*per physics substep:sandbox.SandboxWarning"
)

REPO = Path(__file__).resolve().parent.parent
# Sweep files (scenarios/studies/, with a ``base:`` key) are not scenarios.
BUNDLED = sorted(
    p
    for p in (REPO / "scenarios").rglob("*.yaml")
    if "base" not in (yaml.safe_load(p.read_text()) or {})
)
VALIDATOR = jsonschema.Draft202012Validator(build_schema())


def read(path: Path) -> Any:
    return yaml.load(path.read_text(encoding="utf-8"), Loader=YAMLLoader)


def errors(doc: Any) -> list[str]:
    """Every message, including those inside anyOf/oneOf branches."""
    found: list[str] = []
    stack = list(VALIDATOR.iter_errors(doc))
    while stack:
        error = stack.pop()
        found.append(error.message)
        stack.extend(error.context or [])
    return found


def enum(prop: dict[str, Any]) -> list[str]:
    """The enum of a property, whether or not it also accepts null."""
    return next(alt["enum"] for alt in prop.get("anyOf", [prop]) if "enum" in alt)


def test_the_schema_is_a_valid_draft_2020_12_schema() -> None:
    schema = build_schema()
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["additionalProperties"] is False


def test_there_are_bundled_scenarios() -> None:
    assert len(BUNDLED) >= 2


@pytest.mark.parametrize("path", BUNDLED, ids=[p.name for p in BUNDLED])
def test_every_bundled_scenario_validates(path: Path) -> None:
    assert errors(read(path)) == []


@pytest.mark.parametrize("path", BUNDLED, ids=[p.name for p in BUNDLED])
def test_every_resolved_scenario_validates(path: Path) -> None:
    # The scenario.yaml a run writes (lengths in metres, platoon listed) is valid too.
    resolved = json.loads(json.dumps(load_scenario(path).to_dict()))
    assert errors(resolved) == []


MINIMAL = {
    "reference": {"type": "point", "position": [0, 0]},
    "vehicles": [{"name": "solo", "pose": [1, 0, 0]}],
}


def with_(doc: dict[str, Any], **changes: Any) -> dict[str, Any]:
    out = json.loads(json.dumps(doc))
    out.update(changes)
    return out


@pytest.mark.parametrize(
    ("doc", "fragment"),
    [
        (with_(MINIMAL, durration=5), "Additional properties are not allowed"),
        (with_(MINIMAL, dt="fast"), "is not valid under any of the given schemas"),
        (with_(MINIMAL, duration=0), "is not valid under any of the given schemas"),
        (with_(MINIMAL, vehicles=[{"name": "solo"}]), "'pose' is a required property"),
        (with_(MINIMAL, formation={"law": "rotatin"}), "is not valid under any"),
        (with_(MINIMAL, reference={"type": "spiral"}), "is not one of"),
        (with_(MINIMAL, reference={"type": "circle"}), "is not valid under any"),
        (
            with_(MINIMAL, vehicles=[{"pose": [1, 0, 0], "offset": ["3m", 0]}]),
            "is not valid under any",
        ),
        (
            with_(
                MINIMAL, failures=[{"vehicle": "solo", "at": 1, "kind": "uncontrolled"}]
            ),
            "'v1' is a required property",
        ),
        (
            with_(
                MINIMAL,
                failures=[{"vehicle": "solo", "at": 1, "kind": "crash", "until": 2}],
            ),
            "should not be valid",
        ),
        (
            with_(
                MINIMAL, vehicles=[{"pose": [0, 0, 0], "drive": {"type": "commands"}}]
            ),
            "'schedule' is a required property",
        ),
        (
            with_(
                MINIMAL,
                vehicles=[{"pose": [0, 0, 0], "drive": {"schedule": [[0, 1, 0]]}}],
            ),
            "should not be valid",
        ),
        (
            with_(MINIMAL, vehicles=[{"name": "a,b", "pose": [0, 0, 0]}]),
            "does not match",
        ),
        (["a", "list"], "is not of type 'object'"),
    ],
)
def test_bad_documents_are_rejected_by_schema_and_loader(
    doc: Any, fragment: str
) -> None:
    found = errors(doc)
    assert found, "the schema accepted it"
    assert any(fragment in e for e in found), found
    with pytest.raises(ValueError):  # ScenarioError is a ValueError
        parse_scenario(doc)


def test_every_declared_key_is_documented_and_in_the_schema() -> None:
    defs = build_schema()["$defs"]
    where = {
        "": build_schema()["properties"],
        "vehicle": defs["vehicleParams"]["properties"],
        "gains": defs["gains"]["properties"],
        "vehicles": defs["vehicle"]["properties"],
        "drive": defs["drive"]["properties"],
        "platoon": defs["platoon"]["properties"],
        "metrics": defs["metrics"]["properties"],
    }
    for section, params in sections().items():
        for key, p in params.items():
            assert p.doc.strip(), (section, key)
            if section in where:
                assert key in where[section], (section, key)
                assert p.doc.rstrip(".") in where[section][key].get(
                    "description", p.doc
                )


def test_the_schema_says_the_dt_bound_the_loader_enforces() -> None:
    # The drift this design removes: the schema once said 0.2 s, the loader 0.1 s.
    from sandbox.model.flatness import Gains, max_control_period

    bound = max_control_period(Gains().k1, Gains().k2)
    text = build_schema()["properties"]["dt"]["description"]
    assert f"dt < {bound:g} s" in text
    ok = with_(MINIMAL, dt=0.99 * bound, duration=10)
    parse_scenario(ok)
    with pytest.raises(ValueError, match=re.escape(f"dt < {bound:.4g} s")):
        parse_scenario(with_(MINIMAL, dt=1.01 * bound, duration=10))


def test_enums_come_from_the_loader_tables() -> None:
    from sandbox.plugins import names

    defs = build_schema()["$defs"]
    assert enum(defs["formation"]["properties"]["law"]) == list(names("law"))
    assert enum(defs["reference"]["properties"]["type"]) == list(names("reference"))
    assert enum(defs["obstacle"]["properties"]["type"]) == list(names("obstacle"))
    assert enum(defs["recovery"]["properties"]["strategy"]) == list(names("strategy"))
    assert enum(defs["failure"]["properties"]["kind"]) == list(names("failure"))
    assert names("law")[:5] == (
        "fixed",
        "rotating",
        "virtual",
        "leader_ref",
        "own_estimate",
    )
    assert names("strategy")[:4] == ("none", "discontinuous", "continuous", "smooth")


def test_defaults_in_the_schema_are_the_loaders() -> None:
    sc = load_scenario(
        with_(MINIMAL, formation={"law": "virtual"}, recovery={"strategy": "none"})
    )
    fields = sections()
    top = fields[""]
    assert top["duration"].default == sc.duration
    assert top["dt"].default == sc.dt
    assert top["substeps"].default == sc.substeps
    assert top["seed"].default == sc.seed
    assert top["record_every"].default == sc.record_every
    v = sc.vehicles[0]
    for key in ("diameter", "mass", "motor_accel"):
        assert fields["vehicle"][key].default == getattr(v, key)
    for key, field in fields["gains"].items():
        assert field.default == getattr(v.gains, key)
    assert v.offset == fields["vehicles"]["offset"].default
    assert v.leader is fields["vehicles"]["leader"].default
    rec = {**fields["recovery"], **fields["recovery.smooth"]}
    assert sc.recovery.R == pytest.approx(3 * sc.diameter) and rec["R"].default == "3d"
    for key in ("strategy", "leader_avoids", "target_derivatives"):
        assert rec[key].default == getattr(sc.recovery, key)
    smooth = load_scenario(
        with_(MINIMAL, formation={"law": "virtual"}, recovery={"strategy": "smooth"})
    ).recovery
    for key in ("beta", "steepness"):
        assert rec[key].default == smooth.params[key]
    assert smooth.r == pytest.approx(smooth.R / 2)  # the declared "default: R / 2"
    assert fields["metrics"]["settle_tol"].default == sc.metrics.settle_tol
    assert fields["formation.virtual"]["rotate"].default == sc.formation.rotate
    line = load_scenario(with_(MINIMAL, reference={"type": "line"})).reference
    for key in ("heading", "speed"):
        assert fields["reference.line"][key].default == getattr(line, key)
    assert fields["reference.line"]["start"].default == line.start
    wall = load_scenario(
        with_(MINIMAL, obstacles=[{"type": "wall", "from": [5, 5], "to": [6, 5]}])
    ).obstacles[0]
    assert fields["obstacles.wall"]["thickness"].default == wall.thickness
    platoon = load_scenario(
        with_(MINIMAL, formation={"law": "virtual"}, platoon={"count": 2})
    ).platoon
    assert platoon.spacing == pytest.approx(2 * 0.5)  # the schema's "2d"
    assert fields["platoon"]["pattern"].default == platoon.pattern


@pytest.mark.parametrize(
    ("text", "general", "positive"),
    [
        ("3d", True, True),
        ("1.5d", True, True),
        (" 2 d ", True, True),
        ("+.5d", True, True),
        ("1e1d", True, True),
        ("-1d", True, False),
        ("3", False, False),
        ("d", False, False),
        ("3dd", False, False),
        ("3m", False, False),
    ],
)
def test_length_pattern_matches_the_loader(
    text: str, general: bool, positive: bool
) -> None:
    assert bool(re.search(LENGTH_PATTERN, text)) is general
    assert bool(re.search(POSITIVE_LENGTH_PATTERN, text)) is positive
    doc = with_(MINIMAL, vehicles=[{"pose": [text, 0, 0]}])
    loads = True
    try:
        parse_scenario(doc)
    except ValueError:
        loads = False
    assert loads is general


@pytest.mark.parametrize(
    ("name", "ok"),
    [
        ("leader", True),
        ("v 1", True),
        ("a,b", False),
        ("a/b", False),
        ("'q'", False),
        ("   ", False),
        ("", False),
    ],
)
def test_name_pattern_matches_the_loader(name: str, ok: bool) -> None:
    assert bool(re.search(NAME_PATTERN, name)) is ok
    loads = True
    try:
        parse_scenario(with_(MINIMAL, name=name))
    except ValueError:
        loads = False
    assert loads is ok


def test_cli_prints_and_writes_the_schema(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["schema"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == build_schema()
    out = tmp_path / "scenario.schema.json"
    assert main(["schema", "--out", str(out)]) == 0
    assert json.loads(out.read_text(encoding="utf-8")) == printed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scenario.schema.json"]
    assert main(["schema", "--out", str(tmp_path / "missing" / "s.json")]) == 1
    assert "cannot be written" in capsys.readouterr().err


def test_an_optional_plugin_selector_accepts_null_as_the_loader_does():
    # recovery.strategy: null is the default strategy for the loader; the schema must
    # accept what the loader accepts (found by the loader property test).
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"name": "a", "pose": [1, 0, 0]}],
        "recovery": {"strategy": None},
    }
    load_scenario(doc)
    jsonschema.validate(doc, build_schema())
