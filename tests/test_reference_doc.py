"""scenarios/reference.yaml and the scenario page say what the declarations say.

Every key of the format is declared once (a ``Param``: type, default, unit, bounds).
These tests read the documented example ``scenarios/reference.yaml`` and check its
comments against those declarations: every key is mentioned, and a key's comment that
states a default, a unit, a bound or REQUIRED states the declared one. The numbers
the scenario reference page (``docs/reference/scenario.md``) quotes about the format
(the dt bound, the limits) are checked against the code's constants; its tables of
keys are generated from the declarations (``docs/gen_reference.py``).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from sandbox import plugins
from sandbox import scenario as sc
from sandbox.plugins import REQUIRED, Param
from sandbox.scenario import (
    FAILURE,
    GAINS,
    MAX_FILE_BYTES,
    MAX_NAME,
    MAX_VEHICLES,
    METRICS,
    PLATOON,
    RANGE,
    RECONFIGURE,
    RECOVERY,
    REPORT_DT_BOUND,
    SAFETY,
    SENSING,
    SENSORS,
    TOP,
    VEHICLE,
    VEHICLE_PARAMS,
    load_scenario,
)
from sandbox.scenario.vehicles import DRIVE

REPO = Path(__file__).resolve().parent.parent
REFERENCE = REPO / "scenarios" / "reference.yaml"
TEXT = REFERENCE.read_text(encoding="utf-8")
ROWS = TEXT.splitlines()


def key_lines() -> dict[str, int]:
    """The 1-based line of every key path of the document (as the loader maps them)."""
    from sandbox.scenario.yamlfile import line_map

    lines: dict[str, int] = {}
    line_map(yaml.compose(TEXT), "", lines)
    return lines


def comment(line: int) -> str:
    """The comment of a key's line, with the comment-only lines that continue it."""
    row = ROWS[line - 1]
    if "#" not in row:
        return ""
    col = row.index("#")
    parts = [row[col + 1 :].strip()]
    for nxt in ROWS[line:]:
        if nxt.strip().startswith("#") and nxt.index("#") == col:
            parts.append(nxt[col + 1 :].strip())
        else:
            break
    return " ".join(parts)


def declaration(path: str, doc: dict[str, Any]) -> Param | None:
    """The declaration of a key path of the reference document."""
    parts = re.sub(r"\[\d+\]", "", path).split(".")
    head, key = parts[0], parts[-1]
    if len(parts) == 1:
        return TOP.get(key)
    section = {
        "vehicle": VEHICLE_PARAMS,
        "platoon": PLATOON,
        "metrics": METRICS,
        "sensing": SENSING,
        "reconfigure": RECONFIGURE,
        "sensors": SENSORS,
    }.get(head)
    if parts[-2] == "range":
        return RANGE.get(key)
    if parts[-2] == "gains":
        return GAINS.get(key)
    if parts[-2] == "drive":
        return DRIVE.get(key)
    if head == "vehicles":
        return VEHICLE.get(key) or VEHICLE_PARAMS.get(key)
    if section is not None:
        return section.get(key)
    kind = {
        "recovery": ("strategy", RECOVERY, doc["recovery"].get("strategy")),
        "reference": ("reference", {}, doc["reference"]["type"]),
        "formation": ("law", {}, doc["formation"]["law"]),
        "safety": ("filter", SAFETY, "cbf"),
    }.get(head)
    if kind is not None:
        name, own, selected = kind
        return own.get(key) or plugins.get(name, selected).params.get(key)
    return None


def default_matches(stated: str, p: Param) -> bool:
    stated = stated.strip().strip("\"'")
    d = p.default
    if d is None:
        try:
            float(stated)
        except ValueError:
            return True  # free text: "none", "about sqrt(count)", "R / 2", ...
        return False
    if isinstance(d, bool):
        return stated == str(d).lower()
    if isinstance(d, int | float):
        return math.isclose(float(stated), float(d))
    if isinstance(d, tuple):
        return [float(v) for v in yaml.safe_load(stated)] == list(d)
    return stated == str(d)


def test_every_declared_key_is_documented() -> None:
    tables = [TOP, VEHICLE_PARAMS, GAINS, VEHICLE, DRIVE, PLATOON, METRICS, RECOVERY]
    tables.append(SENSING)
    tables.append(RECONFIGURE)
    tables.append(SENSORS)
    tables.append(RANGE)
    tables.append(FAILURE)
    tables.append(SAFETY)
    kinds = ("law", "strategy", "failure", "reference", "obstacle", "filter")
    for kind in (*kinds, "detector"):
        for plugin in plugins.registry(kind).values():
            if plugin.origin.startswith("built-in"):
                tables.append(plugin.params)
                assert re.search(rf"\b{plugin.name}\b", TEXT), (kind, plugin.name)
    for table in tables:
        for key in table:
            assert re.search(rf"\b{key}\b", TEXT), key


def test_every_stated_default_unit_bound_and_required_is_the_declared_one() -> None:
    doc = yaml.safe_load(TEXT)
    checked = 0
    for path, line in key_lines().items():
        if not path or "[" in path.rsplit(".", 1)[-1]:
            continue
        if re.search(r"\[[1-9]\d*\]", path):
            continue  # the first item of a list documents its keys
        p = declaration(path, doc)
        text = comment(line)
        if p is None or not text:
            continue
        found = re.search(r"\bdefault: ([^;]+?)(?:[.;]\s|[.;]?$)", text)
        if found and not text.startswith("default."):
            assert default_matches(found.group(1), p), (path, found.group(1), p)
            checked += 1
        assert ("REQUIRED" in text) == (p.default is REQUIRED), (path, text)
        units = [u.split(" or ")[0] for u in re.findall(r"\[([^\[\]]+)\]", text)]
        if p.unit and units:
            assert p.unit in units, (path, p.unit, units)
        for op, value in re.findall(r"(>=|>) (-?\d+(?:\.\d+)?)\b", text):
            assert p.minimum == float(value), (path, op, value, p)
            assert p.exclusive == (op == ">"), (path, op, p)
            checked += 1
    assert checked > 30


def test_the_reference_example_loads_and_states_the_dt_bound() -> None:
    load_scenario(REFERENCE)
    dt = comment(key_lines()["dt"])
    assert f"{REPORT_DT_BOUND:g} s" in dt
    stated = [float(x) for x in re.findall(r"under (\d+(?:\.\d+)?) s", dt)]
    assert stated == [REPORT_DT_BOUND]


SCENARIO_PAGE = REPO / "docs" / "reference" / "scenario.md"
PAGE = " ".join(SCENARIO_PAGE.read_text(encoding="utf-8").split())


def _int(text: str) -> int:
    """``10,000``, ``10^9``, ``2^63-1`` as integers."""
    text = text.replace(",", "")
    if "^" in text:
        base, _, rest = text.partition("^")
        exp, _, minus = rest.partition("-")
        return int(base) ** int(exp) - (int(minus) if minus else 0)
    return int(text)


@pytest.mark.parametrize(
    ("pattern", "value"),
    [
        (
            r"The bound is the smaller of the two: (\S+) s for the report's gains",
            lambda: REPORT_DT_BOUND,
        ),
        (r"a regular file of at most (\d+) MB", lambda: MAX_FILE_BYTES / 1e6),
        (r"lengths lie within \+-(\S+) m", lambda: sc.MAX_LENGTH),
        (r"other numbers within \+-([\d.e]+)", lambda: sc.MAX_NUMBER),
        (r"`substeps` 1-([\d,]+)", lambda: sc.MAX_SUBSTEPS),
        (r"`record_every` 1-([\d^]+)", lambda: sc.MAX_RECORD_EVERY),
        (r"`seed` 0-([\d^-]+)", lambda: sc.MAX_SEED),
        (r"`platoon.columns` 1-([\d,]+)", lambda: MAX_VEHICLES),
        (r"at most ([\d,]+) vehicles in all", lambda: MAX_VEHICLES),
        (r"are at most (\d+) characters", lambda: MAX_NAME),
    ],
)
def test_the_scenario_page_states_the_codes_numbers(pattern: str, value: Any) -> None:
    found = re.findall(pattern, PAGE)
    assert found, f"{SCENARIO_PAGE.name} no longer says {pattern!r}: update this test"
    for text in found:
        text = text.rstrip(".,;")
        number = _int(text) if re.fullmatch(r"[\d,^-]+", text) else float(text)
        assert number == value(), (pattern, text, value())
