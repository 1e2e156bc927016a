"""The scenario loader under hostile input: bounded work, no traceback, no bad name.

Each test guards one class of file a hostile or careless user could write: sizes and
kinds of file, the YAML parser, huge integers, crowded starts, starts inside
obstacles, self-intersecting polygons, merge keys and names that are not plain text.
The single-file cases are in ``tests/bad_scenarios/``; these are the ones that need a
generated file, a comparison or a command.
"""

from __future__ import annotations

import itertools
import os
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import yaml

from sandbox import scenario as sc
from sandbox.cli import main
from sandbox.errors import SandboxWarning, ScenarioError
from sandbox.scenario import (
    MAX_FILE_BYTES,
    MAX_NAME,
    load_scenario,
    name_problem,
    overlapping_pairs,
    parse_scenario,
)

POINT = "reference: {type: point, position: [0, 0]}\n"


def problems(path: Path, *sets: str) -> list[str]:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, overrides=list(sets))
    return info.value.lines


def write(tmp_path: Path, text: str, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------- crowded starts
@pytest.mark.slow
def test_20000_vehicles_on_one_spot_are_rejected_with_little_memory(
    tmp_path: Path,
) -> None:
    """The overlap check stops at the first pairs (it once built 2e8 pairs, 6 GB)."""
    path = write(tmp_path, "platoon: {count: 20000, spacing: 0.001}\n" + POINT)
    tracemalloc.start()
    try:
        lines = problems(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    overlaps = [ln for ln in lines if "starts overlapping" in ln]
    assert len(overlaps) == 5
    assert any("more vehicles start overlapping" in ln for ln in lines)
    assert peak < 200e6, f"{peak / 1e6:.0f} MB"


@pytest.mark.parametrize("seed", range(6))
def test_overlapping_pairs_are_those_a_brute_force_finds(seed: int) -> None:
    """Mixed radii over several octaves: every reported pair overlaps, none missed."""
    rng = np.random.default_rng(seed)
    n = 120
    pos = rng.uniform(0, 12, size=(n, 2))
    rad = rng.choice([0.01, 0.1, 0.25, 0.4, 1.5], size=n) * rng.uniform(0.8, 1.2, n)
    truth = {
        (a, b)
        for a, b in itertools.combinations(range(n), 2)
        if np.hypot(*(pos[a] - pos[b])) < rad[a] + rad[b] - 1e-9
    }
    found = {(a, b) for a, b, _ in overlapping_pairs(pos, rad, 10**6)}
    assert found == truth
    few = list(overlapping_pairs(pos, rad, 3))
    assert len(few) == min(3, len(truth))
    assert {(a, b) for a, b, _ in few} <= truth


# ---------------------------------------------------------------- files and parsers
def test_a_device_a_pipe_and_an_oversized_file_are_refused(tmp_path: Path) -> None:
    assert "not a regular file" in problems(Path("/dev/zero"))[0]
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    assert "not a regular file" in problems(fifo)[0]
    big = tmp_path / "big.yaml"
    with big.open("wb") as f:
        f.truncate(MAX_FILE_BYTES + 1)
    line = problems(big)[0]
    assert line.startswith(f"{big}: cannot read the scenario") and "4 MB" in line


def test_validate_of_dev_zero_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["validate", "/dev/zero"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "/dev/zero: cannot read the scenario (got not a regular file (a device, pipe "
        "or socket); expected a readable YAML scenario file)"
    ]


@pytest.mark.skipif(not yaml.__with_libyaml__, reason="PyYAML without libyaml")
def test_the_c_parser_is_used_and_gives_the_same_lines_and_duplicates(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    assert issubclass(sc.YAMLLoader, yaml.CSafeLoader)
    root = Path(__file__).parent.parent / "scenarios"
    files = [
        *sorted(root.rglob("*.yaml"))[:6],
        Path(__file__).parent / "bad_scenarios" / "duplicate_key.yaml",
    ]

    def read(loader: type) -> list[tuple[dict[str, int], list[str]]]:
        out = []
        for path in files:
            node = loader(path.read_text()).get_single_node()
            lines: dict[str, int] = {}
            sc.line_map(node, "", lines)
            out.append((lines, [str(p) for p in sc.duplicate_keys(node)]))
        return out

    class Pure(yaml.SafeLoader):
        yaml_implicit_resolvers = sc.YAMLLoader.yaml_implicit_resolvers

    fast, slow = read(sc.YAMLLoader), read(Pure)
    assert fast == slow
    assert any(dups for _, dups in fast)


def test_merge_keys_are_read_and_duplicates_still_found(tmp_path: Path) -> None:
    text = (
        "duration: 2\n"
        "reference: {type: circle, center: [0, 0], radius: 5, speed: 1}\n"
        "formation: {law: rotating}\n"
        "vehicles:\n"
        "  - &lead {name: leader, pose: [5, 0, 1.5708], leader: true, mass: 12}\n"
        "  - {<<: *lead, name: red, leader: false, pose: [4, -1, 1.5708],"
        " offset: [-1, 1]}\n"
    )
    s = load_scenario(write(tmp_path, text))
    assert [v.name for v in s.vehicles] == ["leader", "red"]
    assert s.vehicles[1].mass == 12 and not s.vehicles[1].leader
    dup = write(tmp_path, text + "  - {<<: *lead, name: a, name: b}\n", "dup.yaml")
    assert any("duplicate key" in ln and ":7:" in ln for ln in problems(dup))


# -------------------------------------------------------------------- huge integers
BIG = "1" + "0" * 400


@pytest.mark.parametrize(
    "item",
    [
        f"record_every={BIG}",
        f"seed={BIG}",
        f"substeps={BIG}",
        f"platoon.columns={BIG}",
        f"platoon.count={BIG}",
        "platoon.columns=1e20",
        f"duration={BIG}",
        "seed=1" + "0" * 5000,
    ],
)
def test_a_huge_integer_from_set_is_a_message(
    item: str, capsys: pytest.CaptureFixture[str]
) -> None:
    path = Path(__file__).parent.parent / "scenarios/paper/rotating_circle.yaml"
    extra = ["--set", "platoon={count: 2}"] if item.startswith("platoon.c") else []
    assert main(["validate", str(path), *extra, "--set", item]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"[from --set {item[:20]}" in err


@pytest.mark.parametrize("command", ["validate", "run", "compare"])
def test_a_huge_integer_file_is_a_message_in_every_command(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write(
        tmp_path, f"record_every: {BIG}\n" + POINT + "vehicles: [{pose: [1, 0, 0]}]\n"
    )
    argv = [command, str(path)]
    if command == "run":
        argv += ["--out", str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "record_every: out of range" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_list_shows_a_huge_integer_file_as_invalid(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "scenarios"
    root.mkdir()
    write(root, f"record_every: {BIG}\n" + POINT + "vehicles: [{pose: [1, 0, 0]}]\n")
    monkeypatch.setattr("sandbox.scenario.bundled.scenarios_dir", lambda: root)
    assert main(["list"]) == 0
    assert "(invalid: " in capsys.readouterr().out


# -------------------------------------------------------------------------- names
@pytest.mark.parametrize(
    "char", ["\x1b", "\u2028", "\u2029", "\x85", "\v", "\f", "\x7f", "\u202e", "\t"]
)
def test_names_with_control_or_line_separator_characters_are_rejected(
    char: str, tmp_path: Path
) -> None:
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"name": f"red{char}x", "pose": [1, 0, 0]}],
    }
    with pytest.raises(ScenarioError) as info:
        parse_scenario(doc)
    assert "vehicles[0].name: unusable name" in str(info.value)
    assert char not in str(info.value), "the raw character reached the message"


@pytest.mark.parametrize("prefix", ["=", "+", "-", "@"])
@pytest.mark.parametrize("field", ["name", "vehicle", "obstacle", "prefix"])
def test_formula_prefixes_are_rejected_in_every_name(prefix: str, field: str) -> None:
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"name": "a", "pose": [1, 0, 0]}],
    }
    bad = f"{prefix}cmd"
    if field == "name":
        doc["name"] = bad
    elif field == "vehicle":
        doc["vehicles"][0]["name"] = bad
    elif field == "obstacle":
        doc["obstacles"] = [
            {"type": "circle", "name": bad, "center": [9, 9], "radius": 1}
        ]
    else:
        doc["vehicles"][0]["leader"] = True
        doc["formation"] = {"law": "fixed"}
        doc["platoon"] = {"count": 1, "prefix": bad}
    with pytest.raises(ScenarioError) as info:
        parse_scenario(doc)
    assert f"which starts with {prefix!r}" in str(info.value)


def test_run_names_are_single_path_components() -> None:
    for bad in (".", "..", ".hidden", "a/b", "a\\b", "x" * (MAX_NAME + 1), " a"):
        assert name_problem(bad, run=True), bad
    for good in ("rotating_circle", "ring 12", "x" * MAX_NAME, "café", "a.b"):
        assert name_problem(good, run=True) is None, good
    assert name_problem(".x") is None  # a vehicle may be called .x


def test_a_file_name_that_is_no_run_name_needs_a_name_key(tmp_path: Path) -> None:
    path = write(tmp_path, POINT + "vehicles: [{pose: [1, 0, 0]}]\n", "..yaml")
    assert "the file name gives an unusable run name" in problems(path)[0]
    path.write_text("name: fine\n" + path.read_text())
    assert load_scenario(path).name == "fine"


def test_a_description_with_an_escape_sequence_is_rejected() -> None:
    doc = {
        "description": "ok\n\x1b[2Jwiped",
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"pose": [1, 0, 0]}],
    }
    with pytest.raises(ScenarioError, match="description: holds the control"):
        parse_scenario(doc)


# ------------------------------------------------------------ obstacles and slots
def test_a_platoon_inside_a_huge_wall_is_reported_once_per_vehicle_up_to_5() -> None:
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "platoon": {"count": 5000, "spacing": 1},
        "obstacles": [
            {
                "type": "wall",
                "name": "slab",
                "from": [-1e5, 0],
                "to": [1e5, 0],
                "thickness": 1e6,
            }
        ],
    }
    with pytest.raises(ScenarioError) as info:
        parse_scenario(doc)
    lines = info.value.lines
    assert (
        sum(
            "starts overlapping obstacle slab (wall, obstacles[0])" in ln
            for ln in lines
        )
        == 5
    )
    assert any("more vehicles start overlapping obstacles" in ln for ln in lines)


def test_a_vehicle_touching_an_obstacle_from_outside_is_accepted() -> None:
    doc = {
        "reference": {"type": "point", "position": [0, 0]},
        "vehicles": [{"pose": [0, 0, 0]}],
        "obstacles": [
            {"type": "circle", "center": [1.25, 0], "radius": 1.0},
            {"type": "box", "center": [0, -1.25], "size": [2, 2]},
            {"type": "wall", "from": [-3, 0.3], "to": [3, 0.3], "thickness": 0.1},
        ],
    }
    assert len(parse_scenario(doc).obstacles) == 3


def slot_doc(gap: float, strategy: str) -> dict:
    """A leader and a follower whose slot is ``gap`` to the leader's left."""
    return {
        "duration": 2,
        "reference": {"type": "circle", "center": [0, 0], "radius": 5, "speed": 1},
        "formation": {"law": "rotating"},
        "recovery": {"strategy": strategy, "R": 1.5},
        "vehicles": [
            {"name": "leader", "pose": [5, 0, 1.5708], "leader": True},
            {"name": "red", "pose": [5 - gap, 0, 1.5708], "offset": [0, gap]},
        ],
    }


@pytest.mark.parametrize(
    ("gap", "strategy", "warned"),
    [
        (0.5, "continuous", True),
        (1.0, "discontinuous", True),
        (1.0, "none", False),
        (1.6, "continuous", False),
    ],
)
def test_a_slot_within_R_of_the_leaders_warns_while_recovery_is_on(
    gap: float, strategy: str, warned: bool
) -> None:
    if warned:
        with pytest.warns(SandboxWarning, match="within recovery.R = 1.5 m"):
            warnings = parse_scenario(slot_doc(gap, strategy)).warnings
    else:
        warnings = parse_scenario(
            slot_doc(gap, strategy)
        ).warnings  # a warning: an error
    hits = [w for w in warnings if "within recovery.R = 1.5 m" in w]
    assert bool(hits) == warned, warnings
    if warned:
        assert f"slots of leader and red are {gap:.3g} m apart" in hits[0]


@pytest.mark.slow
def test_the_reference_example_converges_and_its_lag_is_the_one_it_states() -> None:
    """reference.yaml states its steady lag, 0.025 |delta| m, and settles within it."""
    from helpers import SCENARIOS, run_scenario

    scenario = load_scenario(SCENARIOS / "reference.yaml")
    _, metrics = run_scenario(SCENARIOS / "reference.yaml")
    assert metrics["converged"] is True
    omega = 1.0 / 8.0  # speed / radius [rad/s]
    gains = scenario.vehicles[0].gains
    for v in scenario.vehicles:
        if v.drive.type != "reference" or v.name == "p3":
            continue
        lag = np.hypot(*v.offset) * omega * abs(gains.k2 / gains.k1)
        final = metrics["vehicles"][v.name]["formation_error"]["final"]
        assert final == pytest.approx(lag, rel=0.05, abs=1e-3), v.name
