"""Load-time validation: one line per problem, FILE:LINE: field: what (got; expected).

The corpus ``tests/bad_scenarios/*.yaml`` holds one file per kind of problem. Each file
states what it must produce in header lines::

    # expect: PATH @ LINE ~ TEXT

meaning: ``sandbox validate FILE`` exits with status 2 and prints a line
``FILE:LINE: PATH: ...TEXT...`` (``-`` for a problem of the whole document, which has no
field path). A file may list several expectations: all problems are reported at once.
"""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from sandbox.cli import main
from sandbox.errors import ScenarioError
from sandbox.loop.simulation import Simulation
from sandbox.scenario import load_scenario, parse_scenario
from sandbox.scenario.specs import from_loader

BAD = Path(__file__).parent / "bad_scenarios"
CORPUS = sorted(BAD.glob("*.yaml"))
EXPECT = re.compile(r"^# expect: (?P<path>\S+) @ (?P<line>\d+) ~ (?P<text>.+)$")
#: One problem line: FILE[:LINE]: [path:] what (got X; expected Y) [from --set ...]
FORM = re.compile(
    r"^(?P<file>.+?)(?::(?P<line>\d+))?: (?:(?P<path>[^\s:]+): )?(?P<what>.+?) "
    r"\(got (?P<got>.+); expected (?P<expected>.+)\)(?: \[from --set .+\])?$"
)

MINIMAL = {
    "name": "demo",
    "duration": 2,
    "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1},
    "formation": {"law": "rotating"},
    "vehicles": [
        {"name": "leader", "pose": [5, 0, 1.5708], "leader": True},
        {"name": "red", "pose": [4, -1, 1.5708], "offset": [-1, 1]},
        {"name": "green", "pose": [6, -1, 1.5708], "offset": [-1, -1]},
    ],
}


def expectations(path: Path) -> list[tuple[str, int, str]]:
    head = path.read_bytes().split(b"\n")[:12]
    found = []
    for raw in head:
        m = EXPECT.match(raw.decode("utf-8", "replace"))
        if m:
            found.append((m["path"], int(m["line"]), m["text"]))
    return found


def validate(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[str]]:
    code = main(["validate", *argv])
    err = capsys.readouterr().err
    return code, [line for line in err.splitlines() if line]


def test_the_corpus_has_one_file_per_problem_of_the_issue() -> None:
    names = {p.stem for p in CORPUS}
    assert len(CORPUS) >= 40
    for needed in (
        "malformed_yaml",
        "empty_file",
        "unknown_key_typo",
        "wrong_type",
        "missing_pose",
        "nan_pose",
        "inf_duration",
        "zero_diameter",
        "negative_mass",
        "zero_duration",
        "negative_dt",
        "zero_substeps",
        "small_r_not_below_R",
        "unknown_law",
        "unknown_reference_type",
        "unknown_strategy",
        "unknown_failure_kind",
        "unknown_obstacle_type",
        "failure_unknown_vehicle",
        "failure_after_end",
        "duplicate_names",
        "no_leader",
        "two_leaders",
        "overlapping_start",
        "control_period_too_long",
        "duplicate_key",
        "tab_indent",
        "non_string_key",
        "huge_number",
        "list_for_mapping",
        "top_level_list",
        "binary_garbage",
    ):
        assert needed in names
    for path in CORPUS:
        assert expectations(path), f"{path.name} has no '# expect:' header"


@pytest.mark.parametrize("path", CORPUS, ids=[p.stem for p in CORPUS])
def test_bad_scenario_is_reported_with_file_line_and_field(
    path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, lines = validate(capsys, str(path))
    assert code == 2
    assert lines, "no message"
    for line in lines:
        assert "Traceback" not in line
        m = FORM.match(line)
        assert m, f"not in the form FILE:LINE: field: what (got X; expected Y): {line}"
        assert m["file"] == str(path)
        assert m["line"] is not None, f"no line number: {line}"
    for field, number, text in expectations(path):
        prefix = f"{path}:{number}: " + ("" if field == "-" else f"{field}: ")
        hits = [ln for ln in lines if ln.startswith(prefix) and text in ln]
        assert hits, (
            f"expected a line starting {prefix!r} containing {text!r} in:\n"
            + ("\n".join(lines))
        )


@pytest.mark.parametrize(
    "name", ["overlapping_start", "malformed_yaml", "many_problems"]
)
def test_run_validates_first_and_writes_nothing(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    assert main(["run", str(BAD / f"{name}.yaml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{BAD / name}.yaml:" in err and "Traceback" not in err
    assert not out.exists()


def test_all_problems_of_a_file_at_once_sorted_by_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = BAD / "many_problems.yaml"
    code, lines = validate(capsys, str(path))
    assert code == 2
    assert len(lines) == len(expectations(path))  # no follow-on noise
    numbers = [int(FORM.match(ln)["line"]) for ln in lines]
    assert numbers == sorted(numbers)


def test_several_files_each_reported(
    capsys: pytest.CaptureFixture[str], tmp_path
) -> None:
    good = tmp_path / "good.yaml"
    good.write_text(yaml.safe_dump(MINIMAL), encoding="utf-8")
    code = main(
        [
            "validate",
            str(BAD / "zero_dt.yaml"),
            str(good),
            str(BAD / "unknown_law.yaml"),
        ]
    )
    captured = capsys.readouterr()
    assert code == 2
    assert "zero_dt.yaml: cannot read the scenario (got no such file" in captured.err
    assert "unknown_law.yaml:4: formation.law:" in captured.err
    assert f"{good}: ok (3 vehicles, 2 s)" in captured.out


# ------------------------------------------------------------ files that cannot be read
def test_missing_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, lines = validate(capsys, str(tmp_path / "nope.yaml"))
    assert code == 2
    assert lines == [
        f"{tmp_path / 'nope.yaml'}: cannot read the scenario (got no such "
        "file; expected a readable YAML scenario file)"
    ]


def test_directory(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, lines = validate(capsys, str(tmp_path))
    assert code == 2
    assert lines == [
        f"{tmp_path}: cannot read the scenario (got a directory; expected a "
        "readable YAML scenario file)"
    ]


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads any file")
def test_unreadable_file(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    path = tmp_path / "secret.yaml"
    path.write_text("duration: 1\n", encoding="utf-8")
    path.chmod(0)
    code, lines = validate(capsys, str(path))
    assert code == 2 and "cannot read the scenario (got Permission denied" in lines[0]


def test_utf16_file_is_not_utf8(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "utf16.yaml"
    path.write_bytes("duration: 5\n".encode("utf-16"))
    code, lines = validate(capsys, str(path))
    assert code == 2
    assert lines[0].startswith(f"{path}:1: not UTF-8 text (got byte 0xff at offset 0")


@pytest.mark.slow
def test_deeply_nested_document(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "deep.yaml"
    path.write_text("vehicles: " + "[" * 5000 + "]" * 5000 + "\n", encoding="utf-8")
    code, lines = validate(capsys, str(path))
    assert code == 2
    assert len(lines) == 1 and FORM.match(lines[0])


def test_exponential_aliases_stay_cheap(tmp_path: Path) -> None:
    # "billion laughs": 9 levels of 10 aliases each would expand to 10^9 items.
    rows = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    for k in range(1, 10):
        rows.append(f"a{k}: &a{k} [" + ", ".join([f"*a{k - 1}"] * 10) + "]")
    rows.append("vehicles: *a9")
    path = tmp_path / "laughs.yaml"
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    lines = info.value.lines
    assert any("a0: unknown key" in ln for ln in lines)
    assert sum("vehicles[" in ln for ln in lines) == 10  # one per item, not 10^9


# ---------------------------------------------------------------------------- overrides
@pytest.mark.parametrize(
    ("option", "text"),
    [
        (
            "recovery.bta=2",
            "--set recovery.bta=2: names no field; did you mean 'beta'? "
            "(got 'bta'; expected one of: strategy, R, leader_avoids, "
            "target_derivatives, obstacles, beta, tangential, r, steepness)",
        ),
        (
            "vehicles[7].pose=[0, 0, 0]",
            "--set vehicles[7].pose=[0, 0, 0]: names no field "
            "(got a list of 3 at vehicles; expected an index below 3)",
        ),
        (
            "vehicles[0].pose[1].x=2",
            "--set vehicles[0].pose[1].x=2: names no field "
            "(got 'x' under 0; expected a key under a mapping)",
        ),
        (
            "duration",
            "--set duration: not an assignment (got 'duration'; expected "
            "PATH=VALUE, e.g. recovery.beta=2.5)",
        ),
        ("a..b=1", "--set a..b=1: names no field (got 'a..b'; expected a dotted path"),
        (
            "failures[0].at=1",
            "--set failures[0].at=1: names no field (got no list at failures; expected "
            "an existing item of failures, or --set failures=[...])",
        ),
    ],
)
def test_set_naming_no_field(
    option: str, text: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "ok.yaml"
    path.write_text(yaml.safe_dump(MINIMAL), encoding="utf-8")
    code, lines = validate(capsys, str(path), "--set", option)
    assert code == 2
    assert lines == [f"{path}: {text}"] or (
        len(lines) == 1 and lines[0].startswith(f"{path}: {text}")
    )


def test_problem_from_an_override_points_at_the_option(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "ok.yaml"
    path.write_text(yaml.safe_dump(MINIMAL), encoding="utf-8")
    code, lines = validate(capsys, str(path), "--set", "recovery.R=-1")
    assert code == 2
    # No line number: the value is not in the file.
    assert lines == [
        f"{path}: recovery.R: must be greater than 0 (got -1; expected a "
        "length in metres or a multiple of d like '3d', greater than 0) "
        "[from --set recovery.R=-1]"
    ]


def test_shortened_run_turns_late_failures_into_warnings(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = dict(
        MINIMAL, duration=20, failures=[{"vehicle": "red", "at": 12, "kind": "stop"}]
    )
    path = tmp_path / "f.yaml"
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    assert main(["validate", str(path)]) == 0
    code = main(["run", str(path), "--out", str(tmp_path / "o"), "--duration", "1"])
    err = capsys.readouterr().err
    assert code == 0
    assert (
        "failures[0].at: failure at 12 s never starts: the run was shortened to 1 s"
        in err
    )
    # The resolved scenario leaves the failure out: it validates and reruns identically.
    assert main(["validate", str(tmp_path / "o" / "scenario.yaml")]) == 0


# ----------------------------------------------------------------------------- warnings
def test_doubtful_values_are_warnings_not_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = yaml.safe_load(yaml.safe_dump(MINIMAL))
    doc["vehicles"][2]["offset"] = [-1, 0.7]  # 0.3 m from red's slot, d = 0.5 m
    doc["recovery"] = {"strategy": "discontinuous", "R": 0.4}
    path = tmp_path / "doubt.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    code = main(["validate", str(path)])
    err = capsys.readouterr().err
    assert code == 0
    assert re.search(
        r"warning: .*doubt\.yaml:\d+: vehicles\[2\]\.offset: slots of red and "
        r"green are 0\.3 m apart, closer than a diameter",
        err,
    )
    assert re.search(
        r"warning: .*doubt\.yaml:\d+: recovery\.R: R = 0\.4 m is smaller than "
        r"the vehicle diameter 0\.5 m",
        err,
    )


def test_wrong_sign_gains_are_accepted_with_a_warning(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = dict(MINIMAL, vehicle={"gains": {"k1": 100, "k3": 100}})
    path = tmp_path / "g.yaml"
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    assert main(["validate", str(path)]) == 0
    err = capsys.readouterr().err
    assert (
        "vehicle.gains: gains k1 = k3 = 100, k2 = k4 = -20 of the vehicles do not "
        "stabilise eq. (6) for any control period" in err
    )


# ------------------------------------------------------------- the control-period bound
def test_the_bound_of_the_check_is_what_the_simulation_shows() -> None:
    """Report gains: the check refuses dt >= 0.1 s; the loop converges below, not above.

    Point stabilization from 1 m, run with validation bypassed (the loader's private
    ``from_loader``: a plain ``dataclasses.replace`` is validated):
    dt = 0.09 s converges; dt = 0.15 s, which the linear bound |z| < 1 (dt < 0.2 s)
    would allow, diverges (the unicycle cannot follow a chi that reverses every period).
    """
    doc = {
        "duration": 15.0,
        "substeps": 8,
        "reference": {"type": "point", "position": [1.0, 0.0]},
        "vehicles": [{"pose": [0, 0, 0]}],
    }
    base = load_scenario(doc)
    for dt in (0.09, 0.15):
        problems = []
        try:
            parse_scenario(dict(doc, dt=dt))
        except ScenarioError as exc:
            problems = exc.lines
        with from_loader():
            unchecked = dataclasses.replace(base, dt=dt)
        run = Simulation(unchecked).run()
        error = np.hypot(run.pose[-1, 0, 0] - 1.0, run.pose[-1, 0, 1])
        if dt < 0.1:
            assert problems == []
            assert run.status == "ok" and error < 0.01
        else:
            assert len(problems) == 1 and "dt < 0.1 s" in problems[0]
            assert run.status == "diverged"


# ------------------------------------------------------------------------------ details
def test_yaml_12_exponent_floats_are_numbers(tmp_path: Path) -> None:
    path = tmp_path / "exp.yaml"
    doc = yaml.safe_dump(MINIMAL).replace("duration: 2", "duration: 2e0\ndt: 5e-3")
    path.write_text(doc, encoding="utf-8")
    scenario = load_scenario(path)
    assert scenario.dt == 0.005 and scenario.duration == 2.0


def test_lengths_in_diameters_are_accepted_in_poses(tmp_path: Path) -> None:
    doc = yaml.safe_load(yaml.safe_dump(MINIMAL))
    doc["vehicle"] = {"diameter": 0.4}
    doc["vehicles"][1]["pose"] = ["10d", "-2.5d", 1.5708]
    scenario = parse_scenario(doc)
    assert scenario.vehicles[1].pose == pytest.approx((4.0, -1.0, 1.5708))


def test_a_mapping_without_a_file_names_fields_without_lines() -> None:
    with pytest.raises(ScenarioError) as info:
        load_scenario(dict(MINIMAL, dt="fast"))
    assert info.value.lines == [
        "<scenario>: dt: not a number (got 'fast'; expected a number, greater than 0)"
    ]
