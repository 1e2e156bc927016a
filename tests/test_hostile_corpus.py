"""A hostile corpus: files and paths an attacker (or a careless user) could hand us.

Every case goes through the command line in-process and must end with the expected
exit status and one-line messages that start with the user's file, never a traceback.
The cases are grouped by what they attack: encodings, numbers, YAML structure, names,
sizes and paths. The single-file corpus of ``tests/bad_scenarios/`` names the field
and line of each problem; this one is about surviving, and about what is accepted.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from sandbox.cli import main

POINT = "reference: {type: point, position: [0, 0]}\n"
ONE = POINT + "vehicles:\n  - {pose: [1, 0, 0]}\n"


def lines_of(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln]


#: id -> (file content, expected exit status of validate, text expected in stderr)
CASES: dict[str, tuple[bytes | str, int, str]] = {
    # ---- encodings
    "utf8_bom": ("\ufeff" + ONE, 0, ""),
    "utf16": (ONE.encode("utf-16"), 2, "not UTF-8 text"),
    "latin1_name": (
        POINT.encode() + b"vehicles:\n  - {name: caf\xe9, pose: [1, 0, 0]}\n",
        2,
        "not UTF-8 text",
    ),
    "nul_byte": (ONE.encode() + b"\x00\n", 2, "not text"),
    "overlong_utf8": (ONE.encode() + b"# \xc0\xaf\n", 2, "not UTF-8 text"),
    "lone_surrogate_escape": (
        POINT + 'vehicles:\n  - {name: "\\ud800", pose: [1, 0, 0]}\n',
        2,
        "malformed YAML",
    ),
    "emoji_name_is_fine": (
        POINT + "vehicles:\n  - {name: 🚗, pose: [1, 0, 0]}\n",
        0,
        "",
    ),
    "zero_width_joiner_is_fine": (
        POINT + 'vehicles:\n  - {name: "a\u200db", pose: [1, 0, 0]}\n',
        0,
        "",
    ),
    "bidi_override_name": (
        POINT + 'vehicles:\n  - {name: "abc\u202edef", pose: [1, 0, 0]}\n',
        2,
        "unusable name",
    ),
    "crlf_line_ends": (ONE.replace("\n", "\r\n"), 0, ""),
    "only_a_comment": ("# nothing here\n", 2, "the file is empty"),
    # ---- numbers
    "inf_literal": (ONE + "duration: .inf\n", 2, "not a finite number"),
    "nan_literal": (ONE + "dt: .nan\n", 2, "not a finite number"),
    "float_overflow": (ONE + "duration: 1e309\n", 2, "not a finite number"),
    "float_underflow": (ONE + "dt: 1e-400\n", 2, "must be greater than 0"),
    "base_60": (ONE + "duration: 1:30\n", 2, "not a number (got '1:30'"),
    "bool_for_number": (ONE + "duration: yes\n", 2, "not a number"),
    "date_for_number": (ONE + "duration: 2020-01-01\n", 2, "not a number"),
    "float_for_integer": (ONE + "substeps: 2.5\n", 2, "not a whole number"),
    "negative_zero_duration": (ONE + "duration: -0.0\n", 2, "greater than 0"),
    "huge_float_integer": (ONE + "record_every: 1e300\n", 2, "out of range"),
    "hex_seed_is_a_number": (ONE + "seed: 0x1F\n", 0, ""),
    "long_digit_string": (ONE + "dt: 0." + "0" * 5000 + "1\n", 2, "greater than 0"),
    "million_digit_integer": (ONE + "seed: " + "9" * 100_000 + "\n", 2, "too large"),
    # ---- structure
    "deep_lists": (ONE + "description: " + "[" * 5000 + "]" * 5000 + "\n", 2, ""),
    "deep_mappings": (
        ONE + "metrics: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n",
        2,
        "",
    ),
    "recursive_alias": ("a: &a [*a]\n" + ONE, 2, "unknown key"),
    "billion_laughs": (
        "a: &a [x, x, x, x, x, x, x, x, x]\n"
        + "".join(
            f"{c}: &{c} [{', '.join(['*' + p] * 9)}]\n"
            for p, c in zip("abcdefgh", "bcdefghi", strict=True)
        )
        + ONE,
        2,
        "unknown key",
    ),
    "python_tag": (
        ONE + "seed: !!python/object/apply:os.system [echo]\n",
        2,
        "custom tags",
    ),
    "local_tag": (ONE + "seed: !mytag 3\n", 2, "custom tags"),
    "binary_tag": (ONE + "description: !!binary aGk=\n", 2, "not a string"),
    "set_for_list": (POINT + "vehicles: !!set {a, b}\n", 2, "not a list"),
    "complex_key": (ONE + "? [1, 2]\n: x\n", 2, "unhashable"),
    "two_documents": (ONE + "---\n" + ONE, 2, "one document"),
    "many_unknown_keys": (
        ONE + "".join(f"k{i}: {i}\n" for i in range(3000)),
        2,
        "unknown key",
    ),
    "megabyte_key": (ONE + "k" * 1_000_000 + ": 1\n", 2, ""),
    "top_level_scalar": ("42\n", 2, "not a mapping"),
    "merge_of_a_list": (POINT + "base: &b [1]\nvehicles:\n  - {<<: *b}\n", 2, ""),
    # ---- names
    "name_100_chars": (ONE + "name: " + "n" * 100 + "\n", 0, ""),
    "name_spaces_only": (ONE + "name: '   '\n", 2, "not a non-empty string"),
    "name_leading_space": (ONE + "name: ' x'\n", 2, "unusable name"),
    "name_tab": (ONE + 'name: "a\\tb"\n', 2, "unusable name"),
    "name_nel": (ONE + 'name: "a\\x85b"\n', 2, "unusable name"),
    "name_at_formula": (ONE + "name: '@SUM(A1)'\n", 2, "starts with '@'"),
    "name_plus_formula": (ONE + "name: '+1'\n", 2, "starts with '+'"),
    "name_not_text": (ONE + "name: [a]\n", 2, "not a non-empty string"),
    "vehicle_name_number": (
        POINT + "vehicles:\n  - {name: 12, pose: [1, 0, 0]}\n",
        2,
        "not a non-empty string",
    ),
    "color_escape": (
        POINT + 'vehicles:\n  - {pose: [1, 0, 0], color: "\\e[0m"}\n',
        2,
        "control character",
    ),
    "description_bell": (ONE + 'description: "ding\\a"\n', 2, "control character"),
    "obstacle_name_slash": (
        ONE + "obstacles:\n  - {type: circle, name: a/b, center: [9, 9], radius: 1}\n",
        2,
        "unusable name",
    ),
    # ---- sizes
    "a_million_vehicles": (POINT + "platoon: {count: 1000000}\n", 2, "out of range"),
    "wide_platoon_columns": (
        POINT + "vehicles: [{pose: [0, 0, 0], leader: true}]\n"
        "formation: {law: fixed}\nplatoon: {count: 3, columns: 100001}\n",
        2,
        "out of range",
    ),
    "run_too_long": (ONE + "duration: 1e9\ndt: 1e-3\n", 2, "control steps"),
    # ---- plug-in code listed in a data file: validate never runs it
    "plugin_not_python": (ONE + "plugins: [/etc/hostname]\n", 2, "not a .py file"),
    "plugin_missing_file": (ONE + "plugins: [/nowhere/x.py]\n", 2, "no such plug-in"),
    "plugin_module_not_imported": (ONE + "plugins: [antigravity]\n", 0, ""),
    "plugin_bad_module_name": (ONE + "plugins: ['os; rm']\n", 2, "not a module name"),
    "plugins_not_a_list": (ONE + "plugins: 5\n", 2, "not a list"),
    "plugin_empty_name": (ONE + "plugins: ['']\n", 2, "not a plug-in name"),
    "plugin_section_unchecked": (
        ONE + "plugins: [antigravity]\nrecovery: {strategy: fly, height: 9}\n",
        0,
        "",
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(CASES))
def test_validate_survives_the_hostile_file(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    content, status, text = CASES[case]
    path = tmp_path / f"{case}.yaml"
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8", newline="")
    else:
        path.write_bytes(content)
    assert main(["validate", str(path)]) == status
    err = capsys.readouterr().err
    assert "Traceback" not in err
    problems = [ln for ln in lines_of(err) if not ln.startswith("warning: ")]
    for line in problems:
        assert line.startswith(f"{path}"), line
        assert len(line) < 2000, "a message must not echo a huge value"
    assert text in err
    assert "antigravity" not in sys.modules  # a listed module is never imported


# --------------------------------------------------------------------------- paths
SCENARIO = {
    "name": "tiny",
    "duration": 0.1,
    "reference": {"type": "point", "position": [0, 0]},
    "vehicles": [{"name": "solo", "pose": [1, 0, 0]}],
}


def setup_path(kind: str, tmp_path: Path) -> tuple[list[str], int, str]:
    """Arguments after ``sandbox run SRC``, the exit status and a text of stderr."""
    if kind == "out_is_a_file":
        (tmp_path / "f").write_text("mine", encoding="utf-8")
        return ["--out", str(tmp_path / "f")], 1, "is not a directory"
    if kind == "out_under_a_file":
        (tmp_path / "f").write_text("mine", encoding="utf-8")
        return ["--out", str(tmp_path / "f" / "sub")], 1, "cannot create"
    if kind == "out_is_a_symlink":
        (tmp_path / "real").mkdir()
        (tmp_path / "link").symlink_to(tmp_path / "real")
        return ["--out", str(tmp_path / "link")], 1, "is not a directory"
    if kind == "out_is_dev_null":
        return ["--out", "/dev/null"], 1, "is not a directory"
    if kind == "out_holds_the_scenario":
        return ["--out", str(tmp_path)], 1, "not a run directory"
    if kind == "out_is_root":
        return ["--out", "/"], 1, ""
    if kind == "gif_is_a_directory":
        (tmp_path / "g").mkdir()
        return (
            ["--out", str(tmp_path / "o"), "--gif", str(tmp_path / "g")],
            1,
            (f"{tmp_path / 'g'}: cannot write the GIF"),
        )
    if kind == "gif_name_too_long_for_its_temporary_file":
        gif = tmp_path / ("g" * 240 + ".gif")
        return (
            ["--out", str(tmp_path / "o"), "--gif", str(gif)],
            1,
            (f"{gif}: cannot write the GIF (File name too long)"),
        )
    raise AssertionError(kind)


PATHS = [
    "out_is_a_file",
    "out_under_a_file",
    "out_is_a_symlink",
    "out_is_dev_null",
    "out_holds_the_scenario",
    "out_is_root",
    "gif_is_a_directory",
    "gif_name_too_long_for_its_temporary_file",
]


@pytest.mark.parametrize("kind", PATHS)
def test_run_survives_a_hostile_path(
    kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "tiny.yaml"
    src.write_text(json.dumps(SCENARIO), encoding="utf-8")
    extra, status, text = setup_path(kind, tmp_path)
    before = sorted(str(p) for p in tmp_path.rglob("*"))
    assert main(["run", str(src), *extra]) == status
    err = capsys.readouterr().err
    assert "Traceback" not in err and text in err
    assert all(".tmp" not in ln for ln in lines_of(err)), err
    after = sorted(str(p) for p in tmp_path.rglob("*"))
    created = set(after) - set(before)
    assert all(
        Path(p).is_relative_to(tmp_path / "o") or p == str(tmp_path / "o")
        for p in created
    ), created


@pytest.mark.parametrize(
    ("target", "text"),
    [
        ("/dev/zero", "not a regular file"),
        ("/dev/stdin", "not a regular file"),
        ("/", "a directory"),
        ("missing.yaml", "no such file"),
        ("", "cannot read the scenario"),
        ("/proc/self/status", "unknown key"),  # a regular file of procfs: read, bounded
    ],
)
def test_validate_survives_a_hostile_scenario_path(
    target: str, text: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["validate", target]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and text in err
