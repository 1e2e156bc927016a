"""``sandbox check``: run files, evaluate their ``expect:`` sections, exit 0 / 1 / 2."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from helpers import PAPER

from sandbox.cli import main

#: The bundled files whose expectations state the report's claims (every file of
#: scenarios/paper/), and the format's reference (its expect: section documents every
#: key and must hold).
CLAIMS = [*sorted(PAPER.glob("*.yaml")), PAPER.parent / "reference.yaml"]


def copy_with(tmp_path: Path, source: Path, expect: object, name: str) -> Path:
    doc = yaml.safe_load(source.read_text(encoding="utf-8"))
    doc["expect"] = expect
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def check(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(["check", *argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_the_bundled_claims_hold(capsys: pytest.CaptureFixture[str]) -> None:
    assert len(CLAIMS) >= 18
    code, out, err = check(capsys, *map(str, CLAIMS), "--jobs", "2")
    assert (code, out) == (0, ""), out
    assert re.search(r"\d+ files, \d+ expectations: all hold", err)


def test_a_failed_expectation_is_one_line_with_the_measured_value(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Fig. 12 without recovery: red cuts past the leader while the platoon forms.
    bad = copy_with(
        tmp_path,
        PAPER / "fig12_no_recovery.yaml",
        {"collisions": {"healthy": 0}, "converged": True},
        "fig12.yaml",
    )
    good = copy_with(
        tmp_path, PAPER / "stabilization.yaml", {"converged": True}, "park.yaml"
    )
    code, out, err = check(capsys, str(bad), str(good), "--set", "duration=8")
    assert code == 1
    lines = out.splitlines()
    assert len(lines) == 1, out
    m = re.fullmatch(
        r"(.+): collisions\.healthy: expected 0, got (\d+) \((\w+)-(\w+) at "
        r"(\d+\.\d\d) s.*\)",
        lines[0],
    )
    assert m and m[1] == str(bad) and int(m[2]) >= 1, lines[0]
    assert {m[3], m[4]} == {"leader", "red"}
    assert "2 files, 5 expectations: 1 failed" in err


def test_verbose_lists_every_expectation_with_its_value(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = copy_with(
        tmp_path,
        PAPER / "stabilization.yaml",
        {"settling_time": {"at_most": 2}},
        "s.yaml",
    )
    code, out, _ = check(capsys, str(path), "-v")
    assert code == 0
    assert re.search(
        r"s\.yaml: settling_time: expected at most 2 s, got 1\.\d\d s "
        r"\(blue\) \[holds\]",
        out,
    ), out


def test_set_changes_the_expectations_too(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = copy_with(
        tmp_path, PAPER / "stabilization.yaml", {"converged": True}, "s.yaml"
    )
    code, out, _ = check(capsys, str(path), "--set", "expect.converged=false")
    assert code == 1 and "converged: expected false, got true" in out


def test_invalid_input_exits_2_before_any_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    typo = copy_with(
        tmp_path, PAPER / "stabilization.yaml", {"convergd": True}, "typo.yaml"
    )
    none = copy_with(tmp_path, PAPER / "fig12_no_recovery.yaml", None, "none.yaml")
    code, out, err = check(capsys, str(typo), str(none), str(tmp_path / "missing.yaml"))
    assert (code, out) == (2, "")
    lines = err.splitlines()
    assert re.match(
        rf"{re.escape(str(typo))}:\d+: expect\.convergd: unknown key; did you mean "
        r"'converged'\?",
        lines[0],
    )
    assert lines[1] == (
        f"{none}: expect: no expectations to check (got nothing; expected an expect: "
        "section, see scenarios/reference.yaml)"
    )
    assert lines[2].startswith(f"{tmp_path / 'missing.yaml'}: cannot read")
    assert len(lines) == 3
